"""Motion analysis: background subtraction, image differencing, optical flow."""

from robopercept.motion.flow import (
    FlowStatus,
    SparseFlow,
    dense_flow,
    good_features_to_track,
    lucas_kanade,
)

__all__ = ["FlowStatus", "SparseFlow", "dense_flow", "good_features_to_track", "lucas_kanade"]
