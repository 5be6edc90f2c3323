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

Projection is closed-form for every model. Deprojection inverts the lens model (for
``"brown_conrady"`` and ``"inverse_brown_conrady"``) by iteration: first librealsense's
fixed 10 fixed-point iterations (``rs2_deproject_pixel_to_point``; the result is
librealsense's wherever those converged), then, for the pixels whose forward residual
:math:`\|d(x, y) - (x_d, y_d)\|_\infty` still exceeds :math:`10^{-12} (1 + |x_d| +
|y_d|)` (strong coefficients at the image corners, where the fixed-point map stops
contracting and used to diverge to wrong points or NaN), damped Newton steps on the
forward model with its analytic Jacobian, up to 100. A pixel is accepted only where the
residual meets the tolerance, the undistorted radius is below :func:`fold_radius`
(where the radial distortion :math:`r f(r^2)` stops growing: beyond it the model folds
over, and solutions there are not the lens's) and the Jacobian's determinant is
positive; any other pixel makes :func:`deproject` raise
:class:`~robopercept.errors.DegenerateError` naming the coefficients, the pixels and the
fix, never return NaN or a wrong point silently. :func:`undistort` and
:func:`undistort_points` keep the fixed iteration counts of librealsense and OpenCV.

This module owns the one lens model of the library: :func:`distort_point` (compiled, per
point, for numba kernels such as the RGB-D ones) is the only implementation of the
forward formulas, and :func:`distort` applies it to arrays; :func:`undistort` and
:func:`undistort_points` invert it. An unknown model name is an :class:`InputError`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_choice,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
    squeeze_point_axis,
)
from robopercept.errors import DegenerateError, InputError

__all__ = [
    "MODELS",
    "CameraIntrinsics",
    "check_distortion",
    "compiled_params",
    "deproject",
    "distort",
    "distort_point",
    "fold_radius",
    "invert_lens",
    "lens_model_code",
    "project",
    "undistort",
    "undistort_points",
]

Model = Literal["none", "brown_conrady", "modified_brown_conrady", "inverse_brown_conrady"]
MODELS = ("none", "brown_conrady", "modified_brown_conrady", "inverse_brown_conrady")
_ITERATIONS = 10
_NEWTON_ITERATIONS = 100
_TOLERANCE = 1e-12  # forward residual, normalized units, relative to 1 + |x_d| + |y_d|
_MAX_SIDE = 65536  # pixels per image side
_MAX_UNDISTORT_ITERATIONS = 10_000


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
            if v > _MAX_SIDE:
                raise InputError(
                    f"{name} must be at most {_MAX_SIDE} pixels; got {v}: give the image "
                    "size in pixels (not in bytes or in pixels squared)"
                )
            object.__setattr__(self, name, int(v))
        for name in ("fx", "fy", "cx", "cy"):
            v = check_real(getattr(self, name), name)
            if name in ("fx", "fy") and v <= 0:
                raise InputError(f"{name} must be > 0 (a focal length in pixels); got {v}")
            object.__setattr__(self, name, v)
        check_choice(self.model, "model", MODELS)
        try:
            c = tuple(check_real(v, "coeffs") for v in self.coeffs)
        except TypeError:  # not iterable
            c = ()
        if len(c) != 5:
            raise InputError(
                f"coeffs must be 5 finite numbers (k1, k2, p1, p2, k3); got {self.coeffs!r}"
            )
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
        k = check_numeric(K, "K")
        if k.shape != (3, 3) or k[0, 1] != 0 or not np.allclose(k[2], [0, 0, 1]):
            raise InputError(f"K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]; got {k.tolist()}")
        return cls(width, height, k[0, 0], k[1, 1], k[0, 2], k[1, 2], model, tuple(coeffs))  # type: ignore[arg-type]

    def scaled(self, width: int, height: int) -> CameraIntrinsics:
        """The same camera at another resolution (focal lengths and principal point scale;
        pixel centres stay pixel centres).

        Raises :class:`InputError` if ``width`` or ``height`` is not a positive integer
        (at most 65536)."""
        width, height = check_int(width, "width", 1), check_int(height, "height", 1)
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


def _check_intrinsics(intrinsics: object) -> None:
    if not isinstance(intrinsics, CameraIntrinsics):
        raise InputError(
            f"intrinsics must be a CameraIntrinsics; got {type(intrinsics).__name__}: build "
            "one with robopercept.geometry.CameraIntrinsics(width, height, fx, fy, cx, cy) "
            "or CameraIntrinsics.from_matrix(K, width, height)"
        )


def compiled_params(intrinsics: CameraIntrinsics) -> tuple[np.ndarray, int, np.ndarray]:
    """A camera as the plain arrays that compiled kernels take.

    Parameters
    ----------
    intrinsics : CameraIntrinsics

    Returns
    -------
    k : (4,) float64 ndarray
        ``(fx, fy, cx, cy)``.
    code : int
        :func:`lens_model_code` of its model.
    coeffs : (5,) float64 ndarray
        ``(k1, k2, p1, p2, k3)``, the ``c`` of :func:`distort_point`.

    Examples
    --------
    >>> k, code, c = compiled_params(CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0))
    >>> k.tolist(), code
    ([500.0, 500.0, 320.0, 240.0], 0)
    """
    _check_intrinsics(intrinsics)
    k = intrinsics
    return (
        np.array([k.fx, k.fy, k.cx, k.cy]),
        lens_model_code(k.model),
        np.array(k.coeffs, dtype=np.float64),
    )


_MODEL_CODE = {
    "none": 0,
    "brown_conrady": 1,
    "modified_brown_conrady": 2,
    "inverse_brown_conrady": 2,
}


def lens_model_code(model: str) -> int:
    """Integer code of a lens model for the compiled per-point functions.

    ``"none"`` is 0, ``"brown_conrady"`` 1, and ``"modified_brown_conrady"`` and
    ``"inverse_brown_conrady"`` 2: librealsense projects the inverse model with the
    modified (forward) formula, so both distort the same way.

    Parameters
    ----------
    model : str
        One of :data:`MODELS`.

    Returns
    -------
    int
        The ``code`` argument of :func:`distort_point`.

    Raises
    ------
    InputError
        If ``model`` is not one of :data:`MODELS` (never a silent fallback).

    Examples
    --------
    >>> lens_model_code("brown_conrady"), lens_model_code("inverse_brown_conrady")
    (1, 2)
    """
    code = _MODEL_CODE.get(model) if isinstance(model, str) else None
    if code is None:
        raise InputError(f"model must be one of {', '.join(map(repr, MODELS))}; got {model!r}")
    return code


@njit(cache=True, nogil=True, inline="always")
def distort_point(x, y, c, code):  # pragma: no cover - compiled
    r"""The lens model on one normalized point, compiled (callable from numba kernels).

    With :math:`r^2 = x^2 + y^2` and :math:`f = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6`,
    ``code`` 1 (Brown-Conrady, OpenCV's) gives
    :math:`x_d = x f + 2 p_1 x y + p_2 (r^2 + 2 x^2)`,
    :math:`y_d = y f + 2 p_2 x y + p_1 (r^2 + 2 y^2)`; ``code`` 2 (modified, and
    librealsense's projection of the inverse model) applies the same tangential terms to
    the radially distorted point :math:`(x f, y f)` (with the undistorted :math:`r^2`);
    ``code`` 0 returns the point unchanged. This is the one implementation of the
    formula: :func:`distort`, :func:`project` and the RGB-D kernels all call it.

    Parameters
    ----------
    x, y : float
        Normalized coordinates :math:`X / Z`, :math:`Y / Z`.
    c : (5,) float64 ndarray
        ``(k1, k2, p1, p2, k3)``.
    code : int
        From :func:`lens_model_code` (not checked here: the caller validates once).

    Returns
    -------
    xd, yd : float
    """
    if code == 0:
        return x, y
    k1 = c[0]
    k2 = c[1]
    p1 = c[2]
    p2 = c[3]
    k3 = c[4]
    r2 = x * x + y * y
    f = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    if code == 2:  # tangential terms on the radially distorted point
        x = x * f
        y = y * f
        return (
            x + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y + 2 * p2 * x * y + p1 * (r2 + 2 * y * y),
        )
    return (
        x * f + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
        y * f + 2 * p2 * x * y + p1 * (r2 + 2 * y * y),
    )


@njit(cache=True, nogil=True)
def _distort_kernel(x, y, c, code, xd, yd):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        xd[i], yd[i] = distort_point(x[i], y[i], c, code)


def distort(
    x: np.ndarray, y: np.ndarray, coeffs: npt.ArrayLike, model: Model = "brown_conrady"
) -> tuple[np.ndarray, np.ndarray]:
    r"""Apply the lens model to normalized coordinates: :math:`(x, y) \mapsto (x_d, y_d)`.

    The formulas are those of :func:`distort_point` (and of the module docstring):
    ``"brown_conrady"`` is OpenCV's model (``cv2.projectPoints`` with
    ``distCoeffs = (k1, k2, p1, p2, k3)``), ``"modified_brown_conrady"`` and
    ``"inverse_brown_conrady"`` the formula librealsense's
    ``rs2_project_point_to_pixel`` uses for them, ``"none"`` the identity.

    Parameters
    ----------
    x, y : array_like
        Normalized coordinates :math:`X / Z`, :math:`Y / Z`, broadcast together.
    coeffs : (5,) sequence of float
        ``(k1, k2, p1, p2, k3)``.
    model : {'none', 'brown_conrady', 'modified_brown_conrady', 'inverse_brown_conrady'}

    Returns
    -------
    xd, yd : float64 ndarray
        Of the broadcast shape of ``x`` and ``y``.

    Raises
    ------
    InputError
        An unknown ``model`` (the message names the valid ones), or ``coeffs`` that are not
        5 numbers.

    Examples
    --------
    >>> xd, yd = distort(0.1, 0.0, (0.5, 0.0, 0.0, 0.0, 0.0))  # x (1 + k1 r^2)
    >>> round(float(xd), 6), float(yd)
    (0.1005, 0.0)
    """
    code = lens_model_code(model)
    c = _coeffs(coeffs)
    bx, by = _xy(x, y, "x", "y")
    fx, fy = np.ascontiguousarray(bx).reshape(-1), np.ascontiguousarray(by).reshape(-1)
    xd, yd = np.empty_like(fx), np.empty_like(fy)
    _distort_kernel(fx, fy, c, code, xd, yd)
    return xd.reshape(bx.shape), yd.reshape(bx.shape)


def undistort(
    xd: np.ndarray,
    yd: np.ndarray,
    coeffs: Sequence[float],
    model: Model = "brown_conrady",
    iterations: int = _ITERATIONS,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Invert the lens model on normalized coordinates by fixed-point iteration.

    Starting from :math:`(x, y) = (x_d, y_d)`, each iteration sets
    :math:`x \leftarrow (x_d - \delta_x) / f`, :math:`y \leftarrow (y_d - \delta_y) / f`
    with :math:`f = 1 + k_1 r^2 + k_2 r^4 + k_3 r^6` and the tangential terms
    :math:`\delta` of the current estimate (of :math:`(x f, y f)` for
    ``"inverse_brown_conrady"``, whose coefficients describe the undistortion in
    librealsense). With ``iterations=10`` this is ``rs2_deproject_pixel_to_point``'s
    loop; with 5 and ``"brown_conrady"`` that of ``cv2.undistortPoints``.

    Parameters
    ----------
    xd, yd : array_like
        Distorted normalized coordinates, broadcast together.
    coeffs : (5,) sequence of float
        ``(k1, k2, p1, p2, k3)``.
    model : {'none', 'brown_conrady', 'inverse_brown_conrady'}
        ``"modified_brown_conrady"`` is forward-only (as in librealsense).
    iterations : int
        Fixed-point rounds, 0 to 10000 (no convergence test: :func:`invert_lens`
        iterates to convergence and flags the points that do not converge).

    Returns
    -------
    x, y : float64 ndarray

    Raises
    ------
    InputError
        An unknown model, ``"modified_brown_conrady"``, or ``iterations`` not an integer
        in [0, 10000].

    Examples
    --------
    >>> c = (0.1, -0.05, 0.001, 0.002, 0.0)
    >>> x, y = undistort(*distort(0.2, -0.1, c), c)
    >>> round(float(x), 6), round(float(y), 6)
    (0.2, -0.1)
    """
    lens_model_code(model)
    if model == "modified_brown_conrady":
        raise InputError(
            "cannot undistort with model 'modified_brown_conrady' (a forward-only model, as "
            "in librealsense); use 'inverse_brown_conrady' or 'brown_conrady'"
        )
    iterations = _check_iterations(iterations)
    xo, yo = _xy(xd, yd, "xd", "yd")
    if model == "none":
        return xo.copy(), yo.copy()
    return _undistort(xo, yo, tuple(_coeffs(coeffs)), model == "inverse_brown_conrady",
                      iterations)  # fmt: skip


def _check_iterations(iterations: int) -> int:
    n = check_int(iterations, "iterations", 0)
    check_real(n, "iterations", 0, _MAX_UNDISTORT_ITERATIONS)
    return n


def _coeffs(coeffs: npt.ArrayLike) -> np.ndarray:
    c = check_numeric(coeffs, "coeffs").reshape(-1)
    if c.shape != (5,):
        raise InputError(f"coeffs must be 5 numbers (k1, k2, p1, p2, k3); got {c.size}")
    if not np.isfinite(c).all():
        raise InputError(f"coeffs must be finite; got {c.tolist()}")
    return c


def _xy(x: npt.ArrayLike, y: npt.ArrayLike, xname: str, yname: str) -> tuple:
    """``x`` and ``y`` as float64 arrays broadcast to one shape (views)."""
    bx, by = check_numeric(x, xname), check_numeric(y, yname)
    try:
        return np.broadcast_arrays(bx, by)
    except ValueError:
        raise InputError(
            f"{xname} of shape {bx.shape} and {yname} of shape {by.shape} do not broadcast "
            f"together: give one {yname} per {xname} (the same shape) or a single number"
        ) from None


def _undistort(xo: np.ndarray, yo: np.ndarray, c: tuple, modified: bool, iterations: int) -> tuple:
    k1, k2, p1, p2, k3 = c
    x, y = xo, yo
    for _ in range(iterations):
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


def check_distortion(D: npt.ArrayLike | None, name: str = "D") -> np.ndarray:
    """OpenCV-style distortion coefficients as a float64 ``(k1, k2, p1, p2, k3)`` array.

    Parameters
    ----------
    D : array_like or None
        4 or 5 finite numbers ``(k1, k2, p1, p2[, k3])`` in any shape (OpenCV's ``(1, 5)``
        included); a missing ``k3`` is 0, and None means no distortion.
    name : str
        The argument's name in the error message.

    Returns
    -------
    (5,) float64 ndarray

    Raises
    ------
    InputError
        Another number of coefficients, or NaN/inf.

    Examples
    --------
    >>> check_distortion([0.1, -0.2, 0.0, 0.0]).tolist()
    [0.1, -0.2, 0.0, 0.0, 0.0]
    """
    if D is None:
        return np.zeros(5)
    d = check_numeric(D, name).ravel()
    if d.size not in (4, 5) or not np.isfinite(d).all():
        raise InputError(
            f"{name} must hold 4 or 5 coefficients (k1, k2, p1, p2[, k3]); got {d.size}"
        )
    return np.r_[d, np.zeros(5 - d.size)]


def undistort_points(
    pixels: npt.ArrayLike, K: npt.ArrayLike, dist: npt.ArrayLike | None = None, iterations: int = 5
) -> np.ndarray:
    r"""Normalized undistorted coordinates of distorted pixels (``cv2.undistortPoints``
    without R and P).

    The pixel is taken to normalized distorted coordinates through :math:`K^{-1}` (skew
    included), :math:`y_d = (v - c_y) / f_y`, :math:`x_d = (u - c_x - s\, y_d) / f_x`, and
    Brown-Conrady is inverted by :func:`undistort`'s fixed-point iteration, 5 rounds by
    default as in OpenCV.

    Parameters
    ----------
    pixels : (N, 2) array_like
    K : (3, 3) array_like
        Camera matrix.
    dist : array_like or None
        ``(k1, k2, p1, p2[, k3])``.
    iterations : int

    Returns
    -------
    (N, 2) float64 ndarray
        ``cv2.undistortPoints(pixels, K, dist)[:, 0]`` to rounding (the same 5-round
        iteration) when K has no skew; OpenCV ignores a skew ``K[0, 1]``, this applies it.

    Examples
    --------
    >>> K = [[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]
    >>> undistort_points([[370.0, 140.0]], K).tolist()
    [[0.1, -0.2]]
    """
    xy = squeeze_point_axis(check_numeric(pixels, "pixels"), 2)  # OpenCV's (N, 1, 2) too
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise InputError(f"pixels must be (N, 2); got shape {xy.shape}")
    k = check_numeric(K, "K")
    if k.shape != (3, 3) or not np.isfinite(k).all():
        raise InputError(f"K must be a finite 3x3 matrix; got shape {k.shape}")
    if not (k[0, 0] != 0 and k[1, 1] != 0):
        raise InputError(f"K must have non-zero focal lengths K[0, 0], K[1, 1]; got {k.tolist()}")
    d = check_distortion(dist, "dist")
    iterations = _check_iterations(iterations)
    x0 = (xy[:, 0] - k[0, 2] - k[0, 1] * (xy[:, 1] - k[1, 2]) / k[1, 1]) / k[0, 0]
    y0 = (xy[:, 1] - k[1, 2]) / k[1, 1]
    x, y = _undistort(x0, y0, tuple(d), False, iterations)
    return np.c_[x, y]


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

    Raises
    ------
    InputError
        ``intrinsics`` that is not a :class:`CameraIntrinsics`, or points that are not
        real ``(..., 3)`` numbers.
    """
    _check_intrinsics(intrinsics)
    p = check_numeric(points, "points")
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have shape (..., 3); got {p.shape}")
    k = intrinsics
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(p[..., 2] > 0, p[..., 2], np.nan)
        x, y = p[..., 0] / z, p[..., 1] / z
    if k.model != "none":
        # librealsense projects the inverse model with the modified (forward) formula
        x, y = distort(x, y, k.coeffs, k.model)
    return np.stack([x * k.fx + k.cx, y * k.fy + k.cy], axis=-1)


def deproject(
    pixels: np.ndarray, depth: np.ndarray | float, intrinsics: CameraIntrinsics
) -> np.ndarray:
    r"""Camera-frame points at ``depth`` (the Z coordinate) behind pixels ``(u, v)``.

    The pixel's normalized distorted coordinates :math:`x_d = (u - c_x) / f_x`,
    :math:`y_d = (v - c_y) / f_y` are undistorted by :func:`invert_lens` (librealsense's
    10 fixed-point iterations, then damped Newton steps until the forward model
    reproduces them to :math:`10^{-12}`), and the point is :math:`Z (x, y, 1)`.

    Parameters
    ----------
    pixels : (..., 2) array_like
        Finite pixel coordinates.
    depth : (...) array_like or float
        Z in metres, broadcast against the pixels' leading shape (NaN gives NaN points).
    intrinsics : CameraIntrinsics
        Any model but ``"modified_brown_conrady"`` (a forward-only model, as in
        librealsense).

    Returns
    -------
    (..., 3) float64 ndarray
        Matches ``pyrealsense2.rs2_deproject_pixel_to_point`` wherever librealsense's 10
        iterations converge; elsewhere (strong coefficients, image corners) the converged
        inverse, so that ``project(deproject(p, z, k), k) == p`` to rounding.

    Raises
    ------
    InputError
        Pixels that are not ``(..., 2)`` or not finite, a depth that is not numeric or
        does not broadcast against the pixels, or the forward-only model.
    DegenerateError
        Pixels that no undistorted point maps to under the lens model (it folds over
        before reaching them): the message names the coefficients, the pixels and the
        fix.

    Examples
    --------
    >>> k = CameraIntrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
    >>> deproject([[345.0, 190.0]], 2.0, k).tolist()
    [[0.1, -0.2, 2.0]]
    """
    try:
        px = np.asarray(pixels)
    except ValueError:  # ragged
        px = check_numeric(pixels, "pixels")
    if px.shape[-1:] != (2,):
        raise InputError(f"pixels must have shape (..., 2); got {px.shape}")
    if px.dtype.kind not in "iuf":
        raise InputError(f"pixels must be numeric; got dtype {px.dtype}")
    px = px.astype(np.float64, copy=False)
    if not np.isfinite(px).all():
        n_bad = int(np.count_nonzero(~np.isfinite(px).all(axis=-1)))
        raise InputError(
            f"pixels must be finite; got {n_bad} with NaN/inf: drop them first, "
            "pixels[np.isfinite(pixels).all(-1)]"
        )
    d = np.asarray(depth) if not isinstance(depth, (list, tuple)) else check_numeric(depth, "depth")
    if d.dtype.kind not in "iuf":
        raise InputError(
            f"depth must be a number or a numeric array of metres; got {plain_repr(depth)}"
            if d.ndim == 0
            else f"depth must be a numeric array of metres; got dtype {d.dtype}"
        )
    try:
        np.broadcast_shapes(d.shape, px.shape[:-1])
    except ValueError:
        raise InputError(
            f"depth of shape {d.shape} does not match pixels of shape {px.shape}: give one "
            "depth per pixel (shape pixels.shape[:-1]) or a single depth"
        ) from None
    d = d.astype(np.float64, copy=False)
    k = intrinsics
    _check_intrinsics(k)
    if k.model == "modified_brown_conrady":
        raise InputError(
            "cannot deproject with model 'modified_brown_conrady' (a forward-only model, as "
            "in librealsense); use 'inverse_brown_conrady' or 'brown_conrady'"
        )
    x = (px[..., 0] - k.cx) / k.fx
    y = (px[..., 1] - k.cy) / k.fy
    if k.model != "none":
        x, y, ok = invert_lens(x, y, k.coeffs, k.model)
        if not ok.all():
            bad = np.flatnonzero(~ok.reshape(-1))
            first = px.reshape(-1, 2)[bad[:3]]
            raise DegenerateError(
                f"{bad.size} of {ok.size} pixel(s) have no undistorted ray under the "
                f"{k.model!r} lens model with coeffs (k1, k2, p1, p2, k3) = {k.coeffs}, e.g. "
                f"(u, v) = {plain_repr([tuple(p) for p in first.tolist()])}: the model folds "
                f"over (stops growing) at normalized radius {fold_radius(k.coeffs):.4g}, "
                f"about {fold_radius(k.coeffs) * k.fx:.4g} px from the principal point, "
                "before reaching them. Check that "
                "the coefficients and the model are this camera's (order k1, k2, p1, p2, "
                "k3), or deproject only pixels inside the lens model's valid radius"
            )
    return np.stack(np.broadcast_arrays(d * x, d * y, d * np.ones_like(x)), axis=-1)


def invert_lens(
    xd: npt.ArrayLike, yd: npt.ArrayLike, coeffs: npt.ArrayLike, model: Model = "brown_conrady"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Invert the lens model to convergence, with a per-point flag.

    Solves :math:`d(x, y) = (x_d, y_d)` for the undistorted normalized point, where
    :math:`d` is :func:`distort` with ``model`` (for ``"inverse_brown_conrady"`` the
    forward formula librealsense projects it with). First librealsense's 10 fixed-point
    iterations (:func:`undistort`), then, where the forward residual
    :math:`\|d(x, y) - (x_d, y_d)\|_\infty` exceeds :math:`10^{-12}(1 + |x_d| + |y_d|)`,
    damped Newton steps :math:`(x, y) \leftarrow (x, y) - t J^{-1} (d(x, y) - (x_d, y_d))`
    with the analytic Jacobian :math:`J` of :math:`d` and :math:`t` halved until the
    residual drops, up to 100 steps. OpenCV's ``cv2.undistortPointsIter`` likewise
    iterates to a criterion.

    Parameters
    ----------
    xd, yd : array_like
        Distorted normalized coordinates, broadcast together.
    coeffs : (5,) sequence of float
        ``(k1, k2, p1, p2, k3)``.
    model : {'brown_conrady', 'inverse_brown_conrady', 'none'}

    Returns
    -------
    x, y : float64 ndarray
        The undistorted coordinates (the last iterate where not converged).
    converged : bool ndarray
        Where the residual meets the tolerance, the undistorted radius is below
        :func:`fold_radius` (the solution lies on the branch through the origin, not
        beyond the radius where the model folds over) and :math:`\det J > 0`.

    Raises
    ------
    InputError
        An unknown model, ``"modified_brown_conrady"``, or ``coeffs`` that are not 5
        numbers.

    Examples
    --------
    >>> c = (-0.3, 0.1, 0.0, 0.0, 0.0)
    >>> x, y, ok = invert_lens(*distort(0.9, 0.5, c), c)  # 10 fixed-point steps diverge
    >>> round(float(x), 9), round(float(y), 9), bool(ok)
    (0.9, 0.5, True)
    """
    code = lens_model_code(model)
    if model == "modified_brown_conrady":
        raise InputError(
            "cannot undistort with model 'modified_brown_conrady' (a forward-only model, as "
            "in librealsense); use 'inverse_brown_conrady' or 'brown_conrady'"
        )
    c = _coeffs(coeffs)
    bx, by = _xy(xd, yd, "xd", "yd")
    shape = bx.shape
    xo, yo = bx.reshape(-1), by.reshape(-1)
    if code == 0:
        return bx.copy(), by.copy(), np.ones(shape, dtype=bool)
    with np.errstate(all="ignore"):  # diverging fixed-point iterates are handled below
        x, y = _undistort(xo, yo, tuple(c), code == 2, _ITERATIONS)
        tol = _TOLERANCE * (1.0 + np.abs(xo) + np.abs(yo))
        rx, ry = _residual(x, y, xo, yo, c, code)
        todo = np.flatnonzero(~(np.maximum(np.abs(rx), np.abs(ry)) <= tol))
        if todo.size:
            x, y = x.copy(), y.copy()
            # from the fixed-point iterate where it is finite and closer, else from x_d
            sx, sy = x[todo], y[todo]
            start = ~np.isfinite(sx + sy)
            start |= ~(np.hypot(rx[todo], ry[todo]) < np.hypot(*_residual(
                xo[todo], yo[todo], xo[todo], yo[todo], c, code)))  # fmt: skip
            sx[start], sy[start] = xo[todo][start], yo[todo][start]
            x[todo], y[todo] = _newton(sx, sy, xo[todo], yo[todo], tol[todo], c, code)
        rx, ry = _residual(x, y, xo, yo, c, code)
        ok = (np.maximum(np.abs(rx), np.abs(ry)) <= tol) & (x * x + y * y < fold_radius(c) ** 2)
        if c[2] or c[3]:  # (radial only: det J = f h > 0 below the fold radius)
            jxx, jxy, jyx, jyy = _jacobian(x, y, c, code)
            ok &= jxx * jyy - jxy * jyx > 0
    return x.reshape(shape), y.reshape(shape), ok.reshape(shape)


def fold_radius(coeffs: npt.ArrayLike) -> float:
    r"""Undistorted normalized radius where the radial distortion folds over.

    The distorted radius :math:`r f(r^2)`, :math:`f(s) = 1 + k_1 s + k_2 s^2 + k_3 s^3`,
    grows with :math:`r` while :math:`h(s) = \frac{d}{dr}\big(r f(r^2)\big) =
    1 + 3 k_1 s + 5 k_2 s^2 + 7 k_3 s^3 > 0`; the fold radius is :math:`\sqrt{s^*}` for
    the smallest positive root :math:`s^*` of :math:`h`, and ``inf`` when :math:`h` has
    none (the model is invertible at every radius). Points beyond it are not imaged by
    a lens with these coefficients.

    Parameters
    ----------
    coeffs : (5,) sequence of float
        ``(k1, k2, p1, p2, k3)``.

    Returns
    -------
    float

    Examples
    --------
    >>> round(fold_radius((-0.3, 0.0, 0.0, 0.0, 0.0)), 6)  # 1 - 0.9 r^2 = 0
    1.054093
    >>> fold_radius((0.1, 0.0, 0.0, 0.0, 0.0))
    inf
    """
    k1, k2, _, _, k3 = _coeffs(coeffs)
    roots: np.ndarray = (
        np.roots([7 * k3, 5 * k2, 3 * k1, 1.0]) if (k1, k2, k3) != (0, 0, 0) else np.zeros(0)
    )
    s = [r.real for r in roots if abs(r.imag) <= 1e-12 * max(1.0, abs(r)) and r.real > 0]
    return float(np.sqrt(min(s))) if s else float("inf")


def _residual(x, y, xo, yo, c, code):  # type: ignore[no-untyped-def]
    xd, yd = np.empty_like(x), np.empty_like(y)
    _distort_kernel(x, y, c, code, xd, yd)
    return xd - xo, yd - yo


def _jacobian(x, y, c, code):  # type: ignore[no-untyped-def]
    """Analytic partial derivatives of :func:`distort_point` (code 1 or 2)."""
    k1, k2, p1, p2, k3 = c
    r2 = x * x + y * y
    f = 1 + k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
    df = k1 + 2 * k2 * r2 + 3 * k3 * r2 * r2  # df / d(r^2)
    # derivatives of the radially distorted point (x f, y f)
    qxx, qxy, qyy = f + 2 * x * x * df, 2 * x * y * df, f + 2 * y * y * df
    if code == 1:
        return (
            qxx + 2 * p1 * y + 6 * p2 * x,
            qxy + 2 * p1 * x + 2 * p2 * y,
            qxy + 2 * p2 * y + 2 * p1 * x,
            qyy + 2 * p2 * x + 6 * p1 * y,
        )
    xq, yq = x * f, y * f
    ax, bx = 1 + 2 * p1 * yq + 4 * p2 * xq, 2 * p1 * xq
    ay, by = 1 + 2 * p2 * xq + 4 * p1 * yq, 2 * p2 * yq
    return (
        qxx * ax + qxy * bx + 2 * p2 * x,
        qxy * ax + qyy * bx + 2 * p2 * y,
        qxy * ay + qxx * by + 2 * p1 * x,
        qyy * ay + qxy * by + 2 * p1 * y,
    )


def _newton(x, y, xo, yo, tol, c, code):  # type: ignore[no-untyped-def]
    """Damped Newton on d(x, y) = (xo, yo); arrays are 1-D, modified in place."""
    rx, ry = _residual(x, y, xo, yo, c, code)
    for _ in range(_NEWTON_ITERATIONS):
        act = np.flatnonzero(~(np.maximum(np.abs(rx), np.abs(ry)) <= tol) & np.isfinite(rx + ry))
        if not act.size:
            break
        ax, ay, arx, ary = x[act], y[act], rx[act], ry[act]
        jxx, jxy, jyx, jyy = _jacobian(ax, ay, c, code)
        det = jxx * jyy - jxy * jyx
        dx = (jyy * arx - jxy * ary) / det
        dy = (jxx * ary - jyx * arx) / det
        norm = np.hypot(arx, ary)
        t = np.ones_like(ax)
        pending = np.isfinite(dx + dy)
        for _ in range(40):  # halve the step until the residual drops
            if not pending.any():
                break
            nx, ny = ax - t * dx, ay - t * dy
            nrx, nry = _residual(nx, ny, xo[act], yo[act], c, code)
            better = pending & (np.hypot(nrx, nry) < norm)
            idx = act[better]
            x[idx], y[idx], rx[idx], ry[idx] = nx[better], ny[better], nrx[better], nry[better]
            pending &= ~better
            t[pending] *= 0.5
        stuck = act[pending]
        if stuck.size == act.size:
            break
        rx[stuck] = np.nan  # no step lowers the residual: give up on these
    return x, y
