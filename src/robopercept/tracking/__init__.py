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
)
from robopercept.tracking.meanshift import MeanShiftResult, MeanShiftTracker
from robopercept.tracking.mot_io import MotRows, read_mot, write_mot
from robopercept.tracking.multi_object import MultiObjectTracker, Track

__all__ = [
    "ExtendedKalmanFilter",
    "GatedTrack",
    "GatedTrackConfig",
    "IMMEstimator",
    "KalmanFilter",
    "MeanShiftResult",
    "MeanShiftTracker",
    "MotRows",
    "MultiObjectTracker",
    "Track",
    "TrackStatus",
    "TrackStep",
    "UpdateResult",
    "constant_acceleration",
    "constant_position",
    "constant_velocity",
    "kf_predict",
    "kf_update",
    "lagged_model",
    "read_mot",
    "write_mot",
]
