"""Motion analysis: background subtraction, image differencing, optical flow, KLT point
tracking."""

from robopercept.motion.background import (
    AveragedBackground,
    GaussianBackground,
    StaticBackground,
    clean_mask,
)
from robopercept.motion.detections import MaskDetections, detections_from_mask, moving_blobs
from robopercept.motion.differencing import FrameDifference, ThreeFrameDifference
from robopercept.motion.flow import (
    FlowStatus,
    MotionClass,
    SparseFlow,
    classify_motion,
    dense_flow,
    good_features_to_track,
    lucas_kanade,
)
from robopercept.motion.klt import KLTTracker, PointTracks

__all__ = [
    "AveragedBackground",
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
    "good_features_to_track",
    "lucas_kanade",
    "moving_blobs",
]
