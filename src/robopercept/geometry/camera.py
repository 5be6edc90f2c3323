r"""Pinhole cameras with lens distortion: :class:`CameraIntrinsics`, :func:`project`,
:func:`deproject`, with librealsense's conventions.

A camera-frame point :math:`(X, Y, Z)` (x right, y down, z forward) has normalized
coordinates :math:`x = X / Z`, :math:`y = Y / Z` and pixel
:math:`u = f_x x_d + c_x`, :math:`v = f_y y_d + c_y`, where :math:`(x_d, y_d)` is
:math:`(x, y)` after the lens model with coefficients :math:`(k_1, k_2, p_1, p_2, k_3)`
and :math:`r^2 = x^2 + y^2`:

- ``"none"``: :math:`x_d = x`.
- ``"brown_conrady"`` (OpenCV's model): :math:`x_d = x f + 2 p_1 x y + p_2 (r^2 + 2 x^2)`,
  :math:`y_d = y f + 2 p_2 x y + p_1 (r^2 + 2 y^2)`, :math:`f = 1 + k_1 r^2 + k_2 r^4 +
  k_3 r^6`. Deprojection inverts it by fixed-point iteration.
- ``"modified_brown_conrady"``: the tangential terms act on the radially distorted point
  (project only, as in librealsense).
- ``"inverse_brown_conrady"``: the coefficients describe the *undistortion*: deprojection
  inverts the modified model by iteration, projection applies it.

As in librealsense's ``rs2_project_point_to_pixel`` / ``rs2_deproject_pixel_to_point``,
the iterative inversions run a fixed 10 iterations.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from robopercept._checks import check_choice
from robopercept.errors import InputError

__all__ = ["MODELS", "CameraIntrinsics", "deproject", "project"]

Model = Literal["none", "brown_conrady", "modified_brown_conrady", "inverse_brown_conrady"]
MODELS = ("none", "brown_conrady", "modified_brown_conrady", "inverse_brown_conrady")
_ITERATIONS = 10


@dataclass(frozen=True)
class CameraIntrinsics:
    """Image size, focal lengths and principal point in pixels, and the lens model.

    Attributes
    ----------
    width, height : int
    fx, fy, cx, cy : float
    model : {'none', 'brown_conrady', 'modified_brown_conrady', 'inverse_brown_conrady'}
    coeffs : (5,) tuple of float
        ``(k1, k2, p1, p2, k3)`` (OpenCV's and librealsense's order).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    model: Model = "none"
    coeffs: tuple[float, float, float, float, float] = field(default=(0.0,) * 5)

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"{name} must be a positive integer; got {v!r}")
        for name in ("fx", "fy", "cx", "cy"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or (name in ("fx", "fy") and v <= 0):
                raise InputError(f"{name} must be finite (and > 0 for focal lengths); got {v}")
            object.__setattr__(self, name, v)
        check_choice(self.model, "model", MODELS)
        c = tuple(float(v) for v in self.coeffs)
        if len(c) != 5 or not np.isfinite(c).all():
            raise InputError(f"coeffs must be 5 finite numbers (k1, k2, p1, p2, k3); got {c}")
        object.__setattr__(self, "coeffs", c)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_matrix(
        cls,
        K: np.ndarray,
        width: int,
        height: int,
        model: Model = "none",
        coeffs: Sequence[float] = (0.0,) * 5,
    ) -> CameraIntrinsics:
        """From a 3x3 camera matrix (skew must be 0)."""
        k = np.asarray(K, dtype=np.float64)
        if k.shape != (3, 3) or k[0, 1] != 0 or not np.allclose(k[2], [0, 0, 1]):
            raise InputError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]; got {k.tolist()}")
        return cls(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], model, tuple(coeffs))  # type: ignore[arg-type]

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera at another resolution (focal lengths and principal point scale;
        pixel centres stay pixel centres)."""
        sx, sy = width / self.width, height / self.height
        return CameraIntrinsics(
            width,
            height,
            self.fx * sx,
            self.fy * sy,
            (self.cx + 0.5) * sx - 0.5,
            (self.cy + 0.5) * sy - 0.5,
            self.model,
            self.coeffs,
        )


def _distort(x: np.ndarray, y: np.ndarray, c: tuple, modified: bool) -> tuple:
    k1, k2, p1, p2, k3 = c
    r2 = x * x + y * y
    f = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    if modified:  # tangential terms on the radially distorted point
        x, y = x * f, y * f
        return (
            x + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y + 2 * p2 * x * y + p1 * (r2 + 2 * y * y),
        )
    return (
        x * f + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * f + 2 * p2 * x * y + p1 * (r2 + 2 * y * y),
    )


def _undistort(xo: np.ndarray, yo: np.ndarray, c: tuple, modified: bool) -> tuple:
    """Fixed-point inversion of :func:`_distort` (10 iterations, as librealsense)."""
    k1, k2, p1, p2, k3 = c
    x, y = xo, yo
    for _ in range(_ITERATIONS):
        r2 = x * x + y * y
        icdist = 1.0 / (1 + ((k3 * r2 + k2) * r2 + k1) * r2)
        if modified:
            xq, yq = x / icdist, y / icdist
        else:
            xq, yq = x, y
        dx = 2 * p1 * xq * yq + p2 * (r2 + 2 * xq * xq)
        dy = 2 * p2 * xq * yq + p1 * (r2 + 2 * yq * yq)
        x = (xo - dx) * icdist
        y = (yo - dy) * icdist
    return x, y


def project(points: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Pixel coordinates ``(u, v)`` of camera-frame points.

    Parameters
    ----------
    points : (..., 3) array_like
        Points with ``Z > 0`` (others give NaN).
    intrinsics : CameraIntrinsics

    Returns
    -------
    (..., 2) float64 ndarray
        Matches ``pyrealsense2.rs2_project_point_to_pixel`` for every model.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have shape (..., 3); got {p.shape}")
    k = intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(p[..., 2] > 0, p[..., 2], np.nan)
        x, y = p[..., 0] / z, p[..., 1] / z
    if k.model != "none":
        # librealsense projects the inverse model with the modified (forward) formula
        x, y = _distort(x, y, k.coeffs, modified=k.model != "brown_conrady")
    return np.stack([x * k.fx + k.cx, y * k.fy + k.cy], axis=-1)


def deproject(
    pixels: np.ndarray, depth: np.ndarray | float, intrinsics: CameraIntrinsics
) -> np.ndarray:
    """Camera-frame points at ``depth`` (the Z coordinate) behind pixels ``(u, v)``.

    Parameters
    ----------
    pixels : (..., 2) array_like
    depth : (...) array_like or float
        Z in metres, broadcast against the pixels.
    intrinsics : CameraIntrinsics
        Any model but ``"modified_brown_conrady"`` (a forward-only model, as in
        librealsense).

    Returns
    -------
    (..., 3) float64 ndarray
        Matches ``pyrealsense2.rs2_deproject_pixel_to_point``.
    """
    px = np.asarray(pixels, dtype=np.float64)
    if px.shape[-1:] != (2,):
        raise InputError(f"pixels must have shape (..., 2); got {px.shape}")
    k = intrinsics
    if k.model == "modified_brown_conrady":
        raise InputError(
            "cannot deproject with model 'modified_brown_conrady' (a forward-only model, as "
            "in librealsense); use 'inverse_brown_conrady' or 'brown_conrady'"
        )
    x = (px[..., 0] - k.cx) / k.fx
    y = (px[..., 1] - k.cy) / k.fy
    if k.model != "none":
        x, y = _undistort(x, y, k.coeffs, modified=k.model == "inverse_brown_conrady")
    d = np.asarray(depth, dtype=np.float64)
    return np.stack(np.broadcast_arrays(d * x, d * y, d * np.ones_like(x)), axis=-1)
