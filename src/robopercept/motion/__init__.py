"""Motion analysis: background subtraction, image differencing, optical flow, KLT point
tracking."""

from robopercept.motion.background import (
    AveragedBackground,
    GaussianBackground,
    StaticBackground,
    clean_mask,
)
from robopercept.motion.detections import MaskDetections, detections_from_mask, moving_blobs
from robopercept.motion.differencing import FrameDifference, ThreeFrameDifference, fill_holes
from robopercept.motion.flow import (
    FlowStatus,
    MotionClass,
    SparseFlow,
    classify_motion,
    dense_flow,
    good_features_to_track,
    lucas_kanade,
)
from robopercept.motion.flow_truth import (
    EndpointError,
    endpoint_error,
    known_flow,
    read_flo,
    write_flo,
)
from robopercept.motion.klt import KLTTracker, PointTracks

__all__ = [
    "AveragedBackground",
    "EndpointError",
    "FlowStatus",
    "FrameDifference",
    "GaussianBackground",
    "KLTTracker",
    "MaskDetections",
    "MotionClass",
    "PointTracks",
    "SparseFlow",
    "StaticBackground",
    "ThreeFrameDifference",
    "classify_motion",
    "clean_mask",
    "dense_flow",
    "detections_from_mask",
    "endpoint_error",
    "fill_holes",
    "good_features_to_track",
    "known_flow",
    "lucas_kanade",
    "moving_blobs",
    "read_flo",
    "write_flo",
]
