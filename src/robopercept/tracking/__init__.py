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

__all__ = [
    "ExtendedKalmanFilter",
    "KalmanFilter",
    "MeanShiftResult",
    "MeanShiftTracker",
    "UpdateResult",
    "constant_acceleration",
    "constant_position",
    "constant_velocity",
    "kf_predict",
    "kf_update",
]
