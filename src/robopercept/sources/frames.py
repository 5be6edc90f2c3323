"""The frame every RGB-D source yields."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept._checks import check_int, check_real
from robopercept.depth.rgbd import check_intrinsics
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import check_transform

__all__ = ["RGBDFrame"]


@dataclass(frozen=True)
class RGBDFrame:
    """One depth image and one colour image with their calibration.

    Attributes
    ----------
    index : int
        Position in the sequence (0-based).
    timestamp : float
        Seconds.
    depth : (Hd, Wd) uint16 ndarray
        Raw depth; metres = ``depth * depth_scale``; 0 = no measurement.
    color : (Hc, Wc, 3) uint8 ndarray
        RGB.
    depth_intrinsics, color_intrinsics : CameraIntrinsics
    T_color_depth : (4, 4) ndarray
        Depth frame to colour frame.
    depth_scale : float
        Metres per depth unit.
    ground_truth : dict
        Optional per-frame truth, e.g. ``{"plane": (n, d), "board_mask": mask}``.
    """

    index: int
    timestamp: float
    depth: np.ndarray
    color: np.ndarray
    depth_intrinsics: CameraIntrinsics
    color_intrinsics: CameraIntrinsics
    T_color_depth: np.ndarray
    depth_scale: float
    ground_truth: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "index", check_int(self.index, "index", 0))
        kd = check_intrinsics(self.depth_intrinsics, "depth_intrinsics")
        kc = check_intrinsics(self.color_intrinsics, "color_intrinsics")
        for name in ("depth", "color"):
            if not isinstance(getattr(self, name), np.ndarray):
                raise InputError(
                    f"frame {self.index}: {name} must be a numpy array; got "
                    f"{type(getattr(self, name)).__name__}"
                )
        if self.depth.ndim != 2 or self.depth.shape != (kd.height, kd.width):
            raise InputError(
                f"frame {self.index}: depth is {self.depth.shape[::-1]} but the depth "
                f"intrinsics say {kd.width}x{kd.height}: check camera.json"
            )
        if self.color.shape != (kc.height, kc.width, 3):
            raise InputError(
                f"frame {self.index}: colour is {self.color.shape[1::-1]} but the colour "
                f"intrinsics say {kc.width}x{kc.height}: check camera.json"
            )
        object.__setattr__(self, "T_color_depth", check_transform(self.T_color_depth))
        object.__setattr__(
            self,
            "depth_scale",
            check_real(self.depth_scale, "depth_scale (metres per unit)", 0.0, low_inclusive=False),
        )
