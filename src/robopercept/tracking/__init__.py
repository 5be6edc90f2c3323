"""Tracking: Kalman filters (linear and extended) and motion models."""

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
    "KalmanFilter",
    "MeanShiftResult",
    "MeanShiftTracker",
    "MotRows",
    "MultiObjectTracker",
    "Track",
    "UpdateResult",
    "constant_acceleration",
    "constant_position",
    "constant_velocity",
    "kf_predict",
    "kf_update",
    "read_mot",
    "write_mot",
]
