"""OpenCV's float32 ``atan2`` (``cv::fastAtan2``, used by ``cv::cartToPolar``, HOG and
SIFT), so that descriptors built on it agree with OpenCV's beyond rounding."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["atan2_deg"]

# an odd minimax polynomial for atan(c) on [0, 1], scaled to degrees
_P1 = np.float32(0.9997878412794807 * 180 / math.pi)
_P3 = np.float32(-0.3258083974640975 * 180 / math.pi)
_P5 = np.float32(0.1555786518463281 * 180 / math.pi)
_P7 = np.float32(-0.04432655554792128 * 180 / math.pi)
_EPS = np.float32(2.220446049250313e-16)


@njit(cache=True, nogil=True)
def atan2_deg(y, x):  # pragma: no cover - compiled
    """atan2(y, x) in degrees in [0, 360), float32, within 0.01 degrees: the polynomial
    in c = min(|x|, |y|) / max(|x|, |y|), unfolded by octant."""
    ax = abs(x)
    ay = abs(y)
    if ax >= ay:
        c = np.float32(ay / (ax + _EPS))
        c2 = c * c
        a = (((_P7 * c2 + _P5) * c2 + _P3) * c2 + _P1) * c
    else:
        c = np.float32(ax / (ay + _EPS))
        c2 = c * c
        a = np.float32(90.0) - (((_P7 * c2 + _P5) * c2 + _P3) * c2 + _P1) * c
    if x < 0:
        a = np.float32(180.0) - a
    if y < 0:
        a = np.float32(360.0) - a
    return np.float32(a)
