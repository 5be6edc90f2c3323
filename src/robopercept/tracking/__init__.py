"""Tracking: Kalman filters (linear and extended), the IMM estimator and motion models."""

from robopercept.tracking.gated import (
    GatedTrack,
    GatedTrackConfig,
    TrackStatus,
    TrackStep,
    lagged_model,
)
from robopercept.tracking.imm import IMMEstimator
from robopercept.tracking.kalman import (
    ExtendedKalmanFilter,
    KalmanFilter,
    UpdateResult,
    constant_acceleration,
    constant_position,
    constant_velocity,
    kf_predict,
    kf_update,
    rts_smooth,
)
from robopercept.tracking.meanshift import MeanShiftResult, MeanShiftTracker
from robopercept.tracking.metrics import (
    OTB_THRESHOLDS,
    MotAccumulator,
    MotEvents,
    MotMetrics,
    SuccessScores,
    evaluate_mot,
    evaluate_single_object,
    paired_iou,
    polygons_to_boxes,
    read_vot_groundtruth,
    select_ground_truth,
    success_plot,
)
from robopercept.tracking.mot_io import MotRows, read_mot, write_mot
from robopercept.tracking.multi_object import MultiObjectTracker, Track

__all__ = [
    "OTB_THRESHOLDS",
    "ExtendedKalmanFilter",
    "GatedTrack",
    "GatedTrackConfig",
    "IMMEstimator",
    "KalmanFilter",
    "MeanShiftResult",
    "MeanShiftTracker",
    "MotAccumulator",
    "MotEvents",
    "MotMetrics",
    "MotRows",
    "MultiObjectTracker",
    "SuccessScores",
    "Track",
    "TrackStatus",
    "TrackStep",
    "UpdateResult",
    "constant_acceleration",
    "constant_position",
    "constant_velocity",
    "evaluate_mot",
    "evaluate_single_object",
    "kf_predict",
    "kf_update",
    "lagged_model",
    "paired_iou",
    "polygons_to_boxes",
    "read_mot",
    "read_vot_groundtruth",
    "rts_smooth",
    "select_ground_truth",
    "success_plot",
    "write_mot",
]
