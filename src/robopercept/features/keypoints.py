"""The keypoint set every detector returns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robopercept._checks import check_numeric
from robopercept.errors import InputError

__all__ = ["Keypoints"]


@dataclass(frozen=True)
class Keypoints:
    """Detected keypoints, one row per keypoint, strongest first.

    Attributes
    ----------
    xy : (N, 2) float64 ndarray
        Position ``(x, y)`` = (column, row), origin at the centre of the top-left pixel.
    scale : (N,) float64 ndarray
        Size of the neighbourhood that defines the keypoint, in pixels (the window of a
        corner detector, the diameter OpenCV's ``KeyPoint.size`` reports for SIFT).
    orientation : (N,) float64 ndarray
        Dominant orientation in radians, measured from +x towards +y (image down); NaN
        when the detector assigns none (corners).
    response : (N,) float64 ndarray
        Detector response (Harris measure, minimum eigenvalue, |DoG|).
    octave : (N,) int64 ndarray
        Pyramid octave the keypoint was found in (0 for single-scale detectors).
    """

    xy: np.ndarray
    scale: np.ndarray
    orientation: np.ndarray
    response: np.ndarray
    octave: np.ndarray

    def __post_init__(self) -> None:
        xy = check_numeric(self.xy, "Keypoints.xy")
        if xy.shape == (2,) or xy.shape == (0,):
            xy = xy.reshape(-1, 2)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise InputError(f"Keypoints.xy must be (N, 2) positions (x, y); got shape {xy.shape}")
        n = xy.shape[0]
        cols = {"xy": xy}
        for name in ("scale", "orientation", "response", "octave"):
            arr = check_numeric(getattr(self, name), f"Keypoints.{name}").reshape(-1)
            if name == "octave":
                if not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
                    raise InputError(f"Keypoints.octave must hold integers; got {arr.tolist()[:5]}")
                arr = arr.astype(np.int64)
            if arr.shape[0] != n:
                raise InputError(f"Keypoints.{name} has {arr.shape[0]} entries for {n} points")
            cols[name] = arr
        for name, arr in cols.items():
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @classmethod
    def empty(cls) -> Keypoints:
        """No keypoints."""
        z = np.zeros(0)
        return cls(np.zeros((0, 2)), z, z, z, np.zeros(0, dtype=np.int64))

    def select(self, index: np.ndarray) -> Keypoints:
        """The keypoints at ``index`` (integer positions or a boolean mask)."""
        return Keypoints(
            self.xy[index],
            self.scale[index],
            self.orientation[index],
            self.response[index],
            self.octave[index],
        )
