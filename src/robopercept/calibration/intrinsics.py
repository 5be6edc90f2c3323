r"""Camera calibration from views of a planar target (Zhang 2000), with OpenCV's lens model.

A board point :math:`X = (X, Y, 0)` seen in view :math:`i` projects to

.. math::

    u = f_x x_d + c_x, \quad v = f_y y_d + c_y, \qquad
    (x_d, y_d) = \operatorname{dist}\!\left(\frac{(R_i X + t_i)_{xy}}{(R_i X + t_i)_z}\right)

with the Brown-Conrady distortion of :mod:`robopercept.geometry.camera`
(:math:`k_1, k_2, p_1, p_2, k_3`). Calibration runs in three steps:

1. **A homography per view.** Because the board is the plane :math:`Z = 0`,
   :math:`s\,(u, v, 1)^T = K [r_1\ r_2\ t] (X, Y, 1)^T = H (X, Y, 1)^T`; H comes from the
   normalized DLT.
2. **Closed form for K.** With :math:`B = K^{-T} K^{-1}` (the image of the absolute
   conic), :math:`r_1 \perp r_2` and :math:`|r_1| = |r_2|` give two linear equations per
   view, :math:`h_1^T B h_2 = 0` and :math:`h_1^T B h_1 - h_2^T B h_2 = 0`, in the six
   unknowns of the symmetric B (plus :math:`B_{12} = 0` for zero skew). The null vector
   of the stacked system gives B, and K follows by Cholesky-like closed forms; then
   :math:`r_1 = \lambda K^{-1} h_1`, :math:`r_2 = \lambda K^{-1} h_2`,
   :math:`r_3 = r_1 \times r_2`, :math:`t = \lambda K^{-1} h_3`,
   :math:`\lambda = 1 / |K^{-1} h_1|`, and R is made orthonormal by SVD. Radial
   distortion starts from the linear least-squares fit of :math:`k_1, k_2`.
3. **Levenberg-Marquardt** over all parameters (intrinsics, distortion, a rotation
   vector and translation per view) minimizing the reprojection error
   :math:`\sum_{i, j} \|\pi(K, d, R_i, t_i, X_j) - x_{ij}\|^2`
   (``scipy.optimize.least_squares``).

The reported RMS is OpenCV's: :math:`\sqrt{\sum \|e\|^2 / N}` over all N points, and a
view's error is the same over its own points.

:func:`stereo_calibrate` then finds the pose :math:`(R, T)` of camera 2 relative to
camera 1 (:math:`X_2 = R X_1 + T`) from simultaneous views, and :func:`undistort` resamples
an image through the inverse lens model.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_file,
    check_image,
    check_int,
    check_magnitude,
    check_numeric,
    plain_repr,
)
from robopercept.calibration.filestorage import read_opencv_storage, write_opencv_storage
from robopercept.calibration.ros import camera_info, write_ros_yaml
from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.estimation.models import homography_dlt
from robopercept.fileio import parse_json
from robopercept.geometry.camera import (
    CameraIntrinsics,
    check_distortion,
    distort,
    undistort_points,
)
from robopercept.geometry.epipolar import essential_from_pose, fundamental_from_essential
from robopercept.geometry.rectification import rectify_stereo, undistort_rectify_map
from robopercept.geometry.transforms import (
    check_matrix3,
    nearest_rotation,
    rotation_from_rotvec,
    rotvec_from_rotation,
)
from robopercept.imaging.warp import remap

__all__ = [
    "CALIBRATION_ALIASES",
    "CALIBRATION_FORMATS",
    "CalibrationResult",
    "StereoCalibration",
    "board_pose",
    "calibrate_camera",
    "calibration_format",
    "load_calibration",
    "rectify_pair",
    "reprojection_errors",
    "save_calibration",
    "stereo_calibrate",
    "undistort",
]


@dataclass(frozen=True)
class CalibrationResult:
    """Result of :func:`calibrate_camera` (``cv2.calibrateCamera``'s outputs).

    Attributes
    ----------
    K : (3, 3) ndarray
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.
    dist : (5,) ndarray
        ``(k1, k2, p1, p2, k3)``.
    rvecs, tvecs : (V, 3) ndarray
        Pose of the board in each view (board frame to camera frame), as OpenCV's.
    rms : float
        Root-mean-square reprojection error over all points, pixels.
    per_view_errors : (V,) ndarray
        The same per view.
    image_size : (int, int)
        ``(width, height)``.
    """

    K: np.ndarray
    dist: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    rms: float
    per_view_errors: np.ndarray
    image_size: tuple[int, int]

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """The camera as :class:`~robopercept.geometry.CameraIntrinsics` (Brown-Conrady)."""
        w, h = self.image_size
        return CameraIntrinsics.from_matrix(self.K, w, h, "brown_conrady", tuple(self.dist))

    @property
    def poses(self) -> np.ndarray:
        """``(V, 4, 4)`` board-to-camera transforms ``T_camera_board``."""
        out = np.tile(np.eye(4), (len(self.rvecs), 1, 1))
        for i, (r, t) in enumerate(zip(self.rvecs, self.tvecs, strict=True)):
            out[i, :3, :3] = rotation_from_rotvec(r)
            out[i, :3, 3] = t
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (read back by :func:`load_calibration`)."""
        return {
            "image_size": list(self.image_size),
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "rms": self.rms,
            "per_view_errors": self.per_view_errors.tolist(),
            "rvecs": self.rvecs.tolist(),
            "tvecs": self.tvecs.tolist(),
        }


@dataclass(frozen=True)
class StereoCalibration:
    """Result of :func:`stereo_calibrate` (``cv2.stereoCalibrate``'s outputs).

    Attributes
    ----------
    K1, dist1, K2, dist2 : ndarray
        The two cameras.
    R, T : ndarray
        Camera 2 relative to camera 1: :math:`X_2 = R X_1 + T`.
    E, F : (3, 3) ndarray
        Essential :math:`[T]_\\times R` and fundamental matrices.
    rms : float
        RMS reprojection error over both cameras' points.
    per_view_errors : (V, 2) ndarray
        RMS per view and camera.
    image_size : (int, int)
    """

    K1: np.ndarray
    dist1: np.ndarray
    K2: np.ndarray
    dist2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    rms: float
    per_view_errors: np.ndarray
    image_size: tuple[int, int]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (read back by :func:`load_calibration`)."""
        return {
            "image_size": list(self.image_size),
            "K1": self.K1.tolist(),
            "dist1": self.dist1.tolist(),
            "K2": self.K2.tolist(),
            "dist2": self.dist2.tolist(),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "E": self.E.tolist(),
            "F": self.F.tolist(),
            "rms": self.rms,
            "per_view_errors": self.per_view_errors.tolist(),
        }


# --------------------------------------------------------------------------- inputs


#: largest coordinate of board and image points: the projection and the homographies
#: square them (products beyond about 1e308 overflow)
_MAX_COORDINATE = 1e150
_MAX_ITERATIONS = 100_000  # Levenberg-Marquardt iterations (scipy's max_nfev is a C long)
_LM_STEPS = 100  # Levenberg-Marquardt steps of a board pose (twice that for a stereo pair)


def _views(points: Sequence[npt.ArrayLike] | np.ndarray, name: str, dim: int) -> list[np.ndarray]:
    if isinstance(points, np.ndarray) and points.ndim == 3:
        points = list(points)
    if isinstance(points, (str, bytes)) or (
        not isinstance(points, Sequence) and not isinstance(points, np.ndarray)
    ):
        raise InputError(
            f"{name} must be a list with one (N, {dim}) array per view; got {type(points).__name__}"
        )
    out = []
    for i, p in enumerate(points):
        a = check_numeric(p, f"{name}[{i}]")
        if a.ndim == 3 and a.shape[1] == 1:  # OpenCV's (N, 1, 2) corners
            a = a[:, 0]
        if a.ndim != 2 or a.shape[1] != dim or not np.isfinite(a).all():
            raise InputError(f"{name}[{i}] must be a finite (N, {dim}) array; got {a.shape}")
        out.append(check_magnitude(a, f"{name}[{i}]", _MAX_COORDINATE))
    return out


def _camera_matrix(K: npt.ArrayLike, name: str) -> np.ndarray:
    """``K`` as a float64 camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with
    ``fx, fy > 0`` (finite, entries within 1e150), or InputError naming ``name``."""
    k = check_matrix3(K, name)
    if not (k[0, 0] > 0 and k[1, 1] > 0 and k[1, 0] == 0 and np.array_equal(k[2], [0, 0, 1])):
        raise InputError(
            f"{name} must be a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with "
            f"fx, fy > 0; got {k.tolist()}: take it from a calibration (calibrate_camera, "
            "cv2.calibrateCamera)"
        )
    return check_magnitude(k, name, _MAX_COORDINATE)


def _pose_vectors(value: Any, name: str, n_views: int) -> np.ndarray:
    """Rotation or translation vectors, one per view: ``(V, 3)`` (OpenCV's list of
    ``(3, 1)`` columns too), finite."""
    a = check_numeric(value, name)
    if a.ndim == 3 and a.shape[1:] == (3, 1):
        a = a[:, :, 0]
    if a.shape != (n_views, 3) or not np.isfinite(a).all():
        raise InputError(
            f"{name} must be {n_views} finite 3-vectors, one per view, shape ({n_views}, 3); "
            f"got shape {a.shape}"
        )
    return check_magnitude(a, name, _MAX_COORDINATE)


def _inputs(
    object_points: Sequence[npt.ArrayLike] | np.ndarray,
    image_points: Sequence[npt.ArrayLike] | np.ndarray,
    name: str = "image_points",
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    img = _views(image_points, name, 2)
    if len(img) < 3:
        raise InputError(
            f"calibration needs at least 3 views of the board; got {len(img)}: "
            "capture more images with the board at different tilts"
        )
    obj = object_points
    if isinstance(obj, np.ndarray) and obj.ndim == 2:
        obj = [obj] * len(img)
    objs = _views(obj, "object_points", 3)
    if len(objs) != len(img):
        raise InputError(
            f"object_points has {len(objs)} views but {name} has {len(img)}; give one "
            "board array per view (or a single (N, 3) array for all)"
        )
    for i, (o, p) in enumerate(zip(objs, img, strict=True)):
        _check_view(o, p, i)
    return objs, img


def _check_view(o: np.ndarray, p: np.ndarray, i: int) -> None:
    if o.shape[0] != p.shape[0]:
        raise InputError(f"view {i}: {o.shape[0]} object points but {p.shape[0]} image points")
    if o.shape[0] < 4:
        raise InputError(f"view {i}: a view needs at least 4 points; got {o.shape[0]}")
    if np.abs(o[:, 2]).max() > 1e-9 * max(1.0, np.abs(o).max()):
        raise InputError(
            f"object_points[{i}] must lie on the plane z = 0 (a planar target such as "
            "the output of chessboard_points)"
        )


def _size(image_size: tuple[int, int]) -> tuple[int, int]:
    """``(width, height)``, each an integer in ``[1, 2^31 - 1]`` (OpenCV's ``cv::Size``
    holds ints); integral floats such as ``640.0`` are taken, ``640.5``, infinities,
    NaN, booleans and strings are refused."""
    try:
        w, h = image_size
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"image_size must be (width, height); got {plain_repr(image_size)}"
        ) from exc
    for v in (w, h):
        if (
            isinstance(v, (bool, np.bool_))
            or not isinstance(v, (int, float, np.integer, np.floating))
            or not (math.isfinite(v) and v == int(v) and 1 <= v <= 2**31 - 1)
        ):
            raise InputError(
                "image_size must be (width, height), two whole numbers of pixels from 1 to "
                f"2^31 - 1; got {plain_repr(image_size)}"
            )
    return int(w), int(h)


# --------------------------------------------------------------------------- model


def _project(
    obj: np.ndarray,
    view: np.ndarray,
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray,
) -> np.ndarray:
    """Pixels of board points ``obj`` (M, 3) seen in views ``view`` (M,)."""
    R = rotation_from_rotvec(rvecs)
    pc = np.einsum("mij,mj->mi", R[view], obj) + tvecs[view]
    z = pc[:, 2]
    xd, yd = distort(pc[:, 0] / z, pc[:, 1] / z, dist)
    return np.c_[K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]]


def reprojection_errors(
    object_points: Sequence[npt.ArrayLike] | np.ndarray,
    image_points: Sequence[npt.ArrayLike] | np.ndarray,
    K: npt.ArrayLike,
    dist: npt.ArrayLike,
    rvecs: Sequence[npt.ArrayLike] | np.ndarray,
    tvecs: Sequence[npt.ArrayLike] | np.ndarray,
) -> tuple[float, np.ndarray]:
    """RMS reprojection error overall and per view, in pixels (OpenCV's definitions).

    Returns
    -------
    rms : float
        :math:`\\sqrt{\\sum_{i,j} \\|e_{ij}\\|^2 / N}` (inf when a point lies on or
        behind the camera plane of its view).
    per_view : (V,) ndarray

    Raises
    ------
    InputError
        Views as in :func:`calibrate_camera`, a ``K`` that is not a camera matrix,
        ``dist`` that is not 4 or 5 finite numbers, or ``rvecs``/``tvecs`` that are not
        one finite 3-vector per view.
    """
    objs, img = _inputs(object_points, image_points)
    obj = np.concatenate(objs)
    view = np.repeat(np.arange(len(objs)), [len(o) for o in objs])
    r = _pose_vectors(rvecs, "rvecs", len(objs))
    t = _pose_vectors(tvecs, "tvecs", len(objs))
    d = check_distortion(dist, "dist")
    with np.errstate(all="ignore"):  # points behind or on the camera plane: inf below
        e = _project(obj, view, r, t, _camera_matrix(K, "K"), d) - np.concatenate(img)
        e = np.where(np.isfinite(e), e, np.inf)
    sq = (e**2).sum(axis=1)
    per = np.sqrt(np.bincount(view, sq) / np.bincount(view))
    return float(np.sqrt(sq.mean())), per


# --------------------------------------------------------------------------- Zhang


def _v(h: np.ndarray, i: int, j: int) -> np.ndarray:
    a, b = h[:, :, i], h[:, :, j]
    return np.stack(
        [
            a[:, 0] * b[:, 0],
            a[:, 0] * b[:, 1] + a[:, 1] * b[:, 0],
            a[:, 1] * b[:, 1],
            a[:, 2] * b[:, 0] + a[:, 0] * b[:, 2],
            a[:, 2] * b[:, 1] + a[:, 1] * b[:, 2],
            a[:, 2] * b[:, 2],
        ],
        axis=1,
    )


def _zhang_K(H: np.ndarray) -> np.ndarray:
    """Closed-form K (zero skew) from ``(V, 3, 3)`` homographies board -> pixels."""
    v = np.concatenate([_v(H, 0, 1), _v(H, 0, 0) - _v(H, 1, 1), [[0, 1e3, 0, 0, 0, 0]]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    _, s, vt = np.linalg.svd(v)
    b11, b12, b22, b13, b23, b33 = vt[-1] * np.sign(vt[-1][0])
    den = b11 * b22 - b12 * b12
    if s[-2] < 1e-9 * s[0] or b11 <= 0 or den <= 0:
        raise DegenerateError(
            "the views do not determine the camera matrix (the board is at nearly the same "
            "orientation in every view): tilt the board differently between images"
        )
    v0 = (b12 * b13 - b11 * b23) / den
    lam = b33 - (b13 * b13 + v0 * (b12 * b13 - b11 * b23)) / b11
    if lam / b11 <= 0:
        raise DegenerateError(
            "the closed-form camera matrix is not real (views too similar or points "
            "mislabelled): tilt the board differently between images"
        )
    alpha = np.sqrt(lam / b11)
    beta = np.sqrt(lam * b11 / den)
    u0 = -b13 * alpha * alpha / lam
    return np.array([[alpha, 0.0, u0], [0.0, beta, v0], [0.0, 0.0, 1.0]])


def _pose_from_homography(K: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Board pose from ``H = K [r1 r2 t]`` (rotation vector, translation)."""
    m = np.linalg.solve(K, H)
    norm = np.linalg.norm(m[:, 0])
    if not (np.isfinite(m).all() and norm > 0):
        raise DegenerateError(
            "the board's homography is degenerate (points on a line, or coinciding): "
            "check that the points match the board"
        )
    lam = 1.0 / norm
    if m[2, 2] * lam < 0:  # the board must lie in front of the camera
        lam = -lam
    r1, r2, t = lam * m[:, 0], lam * m[:, 1], lam * m[:, 2]
    return rotvec_from_rotation(nearest_rotation(np.c_[r1, r2, np.cross(r1, r2)])), t


def _view_pose(K: np.ndarray, dist: np.ndarray, obj: np.ndarray, img: np.ndarray):
    from scipy.optimize import least_squares

    with np.errstate(all="ignore"):  # non-finite values are refused below
        xy = undistort_points(img, K, dist)
        h = homography_dlt(obj[None, :, :2], xy[None])[0]
    r, t = _pose_from_homography(np.eye(3), h)
    view = np.zeros(len(obj), dtype=np.intp)

    def fun(p: np.ndarray) -> np.ndarray:
        return (_project(obj, view, p[None, :3], p[None, 3:], K, dist) - img).ravel()

    with np.errstate(all="ignore"):
        start_ok = np.isfinite(fun(np.r_[r, t])).all()
    if not start_ok:
        raise DegenerateError(
            "the board pose cannot be started: a board point projects to infinity (on the "
            "camera plane); check that the points match the board and K is this camera's"
        )
    # (a bound on the steps: valid views converge in a few; absurd distortion or K
    # would otherwise spend the default budget of 100 * n * (n + 1) evaluations)
    sol = least_squares(fun, np.r_[r, t], method="lm", max_nfev=_LM_STEPS)
    return sol.x[:3], sol.x[3:]


def board_pose(
    object_points: npt.ArrayLike,
    image_points: npt.ArrayLike,
    K: npt.ArrayLike,
    dist: npt.ArrayLike | None = None,
) -> np.ndarray:
    r"""Pose of a planar target seen by a calibrated camera (``cv2.solvePnP`` for a
    board): ``T_camera_board`` as a 4x4 matrix.

    The undistorted normalized points and the board plane are related by the homography
    :math:`[r_1\ r_2\ t]`, which gives the starting pose; Levenberg-Marquardt then
    minimizes the reprojection error.

    Parameters
    ----------
    object_points : (N, 3) array_like
        Board points with z = 0 (N >= 4).
    image_points : (N, 2) array_like
    K : (3, 3) array_like
    dist : array_like, optional
        ``(k1, k2, p1, p2[, k3])``.

    Returns
    -------
    (4, 4) float64 ndarray

    Raises
    ------
    InputError
        Points that are not finite ``(N, 3)``/``(N, 2)`` arrays of one length (N >= 4)
        within 1e150, non-planar board points, a ``K`` that is not a camera matrix
        ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with ``fx, fy > 0``.
    DegenerateError
        Points that do not determine the pose (collinear, coinciding).
    """
    obj = _views([object_points], "object_points", 3)[0]
    img = _views([image_points], "image_points", 2)[0]
    _check_view(obj, img, 0)
    Km = _camera_matrix(K, "K")
    r, t = _view_pose(Km, check_distortion(dist, "dist"), obj, img)
    T = np.eye(4)
    T[:3, :3] = rotation_from_rotvec(r)
    T[:3, 3] = t
    return T


def _free_mask(n_radial: int, tangential: bool) -> np.ndarray:
    free = np.zeros(5, dtype=bool)
    free[[0, 1, 4][:n_radial]] = True
    free[2:4] = tangential
    return free


def calibrate_camera(
    object_points: Sequence[npt.ArrayLike] | np.ndarray,
    image_points: Sequence[npt.ArrayLike] | np.ndarray,
    image_size: tuple[int, int],
    *,
    n_radial: int = 3,
    tangential: bool = True,
    fix_principal_point: bool = False,
    max_iterations: int = 100,
) -> CalibrationResult:
    """Intrinsics, distortion and board poses from three or more views of a planar target.

    Parameters
    ----------
    object_points : (N, 3) array_like or list of (N_i, 3)
        Board points with z = 0 (one array shared by all views, or one per view), e.g.
        :func:`~robopercept.calibration.chessboard_points`.
    image_points : list of (N_i, 2) array_like
        Detected pixels per view, in the order of the object points (OpenCV's
        ``(N, 1, 2)`` corner arrays are accepted).
    image_size : (int, int)
        ``(width, height)``.
    n_radial : {0, 1, 2, 3}
        Radial coefficients estimated (:math:`k_1`, :math:`k_2`, :math:`k_3`); the rest are
        held at 0. The default 3 with tangential terms is ``cv2.calibrateCamera``'s
        default model.
    tangential : bool
        Estimate :math:`p_1, p_2`.
    fix_principal_point : bool
        Hold the principal point at the image centre (``cv2.CALIB_FIX_PRINCIPAL_POINT``).
    max_iterations : int
        Bound on Levenberg-Marquardt steps (evaluations of the residuals, each with its
        finite-difference Jacobian), 1 to 100000; calibrations converge in a few.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    InputError
        Fewer than 3 views, counts that differ, non-planar object points, points that
        are not finite numbers within 1e150, or a parameter of the wrong type or range
        (``max_iterations`` up to 100000).
    DegenerateError
        Views that do not determine K (the board at one orientation throughout).
    """
    from scipy.optimize import least_squares

    objs, img = _inputs(object_points, image_points)
    w, h = _size(image_size)
    n_radial = check_int(n_radial, "n_radial", 0)
    if n_radial > 3:
        raise InputError(f"n_radial must be 0, 1, 2 or 3; got {n_radial!r}")
    tangential = check_bool(tangential, "tangential")
    fix_principal_point = check_bool(fix_principal_point, "fix_principal_point")
    max_iterations = check_int(max_iterations, "max_iterations", 1)
    if max_iterations > _MAX_ITERATIONS:
        raise InputError(f"max_iterations must be at most {_MAX_ITERATIONS}; got {max_iterations}")
    n_views = len(objs)
    # 1. homographies in a normalized pixel frame (conditioning), 2. closed-form K
    s = 1.0 / max(w, h)
    N = np.array([[s, 0, -s * (w - 1) / 2], [0, s, -s * (h - 1) / 2], [0, 0, 1]])
    Hn = np.stack(
        [homography_dlt(o[None, :, :2], (p * s - s * np.array([(w - 1) / 2, (h - 1) / 2]))[None])[0]
         for o, p in zip(objs, img, strict=True)]
    )  # fmt: skip
    K = np.linalg.solve(N, _zhang_K(Hn))
    if fix_principal_point:
        K[0, 2], K[1, 2] = (w - 1) / 2, (h - 1) / 2
    H = np.linalg.solve(N, Hn)
    poses = [_pose_from_homography(K, Hi) for Hi in H]
    rvecs = np.array([p[0] for p in poses])
    tvecs = np.array([p[1] for p in poses])
    obj = np.concatenate(objs)
    pix = np.concatenate(img)
    view = np.repeat(np.arange(n_views), [len(o) for o in objs])
    # initial radial distortion: linear least squares in k1, k2 (Zhang, section 3.3)
    free = _free_mask(n_radial, tangential)
    dist = np.zeros(5)
    if n_radial:
        ideal = _project(obj, view, rvecs, tvecs, K, dist)
        R = rotation_from_rotvec(rvecs)[view]
        pc = np.einsum("mij,mj->mi", R, obj) + tvecs[view]
        r2 = (pc[:, 0] ** 2 + pc[:, 1] ** 2) / pc[:, 2] ** 2
        d = ideal - K[:2, 2]
        A = np.stack([np.r_[d[:, 0] * r2, d[:, 1] * r2], np.r_[d[:, 0] * r2**2, d[:, 1] * r2**2]])
        A = A[: min(n_radial, 2)].T
        k = np.linalg.lstsq(A, np.r_[pix[:, 0] - ideal[:, 0], pix[:, 1] - ideal[:, 1]])[0]
        if np.isfinite(k).all() and np.abs(k).max() < 10:
            dist[[0, 1][: len(k)]] = k
    # 3. Levenberg-Marquardt on everything
    n_k = 2 if fix_principal_point else 4

    def unpack(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        Kp = K.copy()
        Kp[0, 0], Kp[1, 1] = p[0], p[1]
        if not fix_principal_point:
            Kp[0, 2], Kp[1, 2] = p[2], p[3]
        dp = np.zeros(5)
        dp[free] = p[n_k : n_k + free.sum()]
        q = p[n_k + free.sum() :].reshape(n_views, 6)
        return Kp, dp, q[:, :3], q[:, 3:]

    def fun(p: np.ndarray) -> np.ndarray:
        Kp, dp, r, t = unpack(p)
        return (_project(obj, view, r, t, Kp, dp) - pix).ravel()

    centre = [] if fix_principal_point else K[:2, 2]
    p0 = np.r_[K[0, 0], K[1, 1], centre, dist[free], np.c_[rvecs, tvecs].ravel()]
    sol = least_squares(fun, p0, method="lm", x_scale="jac", max_nfev=max_iterations)
    K, dist, rvecs, tvecs = unpack(sol.x)
    if not (np.isfinite(sol.x).all() and K[0, 0] > 0 and K[1, 1] > 0):
        raise DegenerateError("the refinement diverged: check that the points match the board")
    e = (sol.fun.reshape(-1, 2) ** 2).sum(axis=1)
    per_view = np.sqrt(np.bincount(view, e) / np.bincount(view))
    return CalibrationResult(K, dist, rvecs, tvecs, float(np.sqrt(e.mean())), per_view, (w, h))


def stereo_calibrate(
    object_points: Sequence[npt.ArrayLike] | np.ndarray,
    image_points1: Sequence[npt.ArrayLike] | np.ndarray,
    image_points2: Sequence[npt.ArrayLike] | np.ndarray,
    image_size: tuple[int, int],
    *,
    K1: npt.ArrayLike | None = None,
    dist1: npt.ArrayLike | None = None,
    K2: npt.ArrayLike | None = None,
    dist2: npt.ArrayLike | None = None,
    fix_intrinsics: bool = True,
) -> StereoCalibration:
    """Relative pose of two cameras from simultaneous views of a planar target.

    Each camera is calibrated with :func:`calibrate_camera` unless its ``K`` and
    ``dist`` are given. The initial :math:`(R, T)` is the chordal mean over views of
    :math:`R_{2,i} R_{1,i}^T` and the median of :math:`t_{2,i} - R t_{1,i}`; then
    Levenberg-Marquardt minimizes both cameras' reprojection errors over :math:`(R, T)`
    and the board pose per view (and the intrinsics unless ``fix_intrinsics``, which is
    ``cv2.CALIB_FIX_INTRINSIC``).

    Parameters
    ----------
    object_points : (N, 3) array_like or list of (N_i, 3)
    image_points1, image_points2 : list of (N_i, 2) array_like
        The same board points in camera 1 and camera 2, view by view.
    image_size : (int, int)
    K1, dist1, K2, dist2 : array_like, optional
        Camera matrices ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` (``fx, fy > 0``) and
        distortion ``(k1, k2, p1, p2[, k3])``.
    fix_intrinsics : bool

    Returns
    -------
    StereoCalibration

    Raises
    ------
    InputError
        Views as in :func:`calibrate_camera`, a ``K1``/``K2`` that is not a camera
        matrix, or distortion that is not 4 or 5 finite numbers.
    DegenerateError
        Views that determine neither camera nor the relative pose.
    """
    from scipy.optimize import least_squares

    objs, img1 = _inputs(object_points, image_points1, "image_points1")
    _, img2 = _inputs(objs, image_points2, "image_points2")
    size = _size(image_size)
    fix_intrinsics = check_bool(fix_intrinsics, "fix_intrinsics")
    for i, (a, b) in enumerate(zip(img1, img2, strict=True)):
        if a.shape != b.shape:
            raise InputError(f"view {i}: camera 1 has {len(a)} points but camera 2 {len(b)}")
    cams = []
    for K, d, img in ((K1, dist1, img1), (K2, dist2, img2)):
        if K is None:
            c = calibrate_camera(objs, img, size)
            cams.append((c.K, c.dist))
        else:
            Km = _camera_matrix(K, "K1" if img is img1 else "K2")
            cams.append((Km, check_distortion(d, "dist1" if img is img1 else "dist2")))
    (k1, d1), (k2, d2) = cams
    poses1 = [_view_pose(k1, d1, o, p) for o, p in zip(objs, img1, strict=True)]
    poses2 = [_view_pose(k2, d2, o, p) for o, p in zip(objs, img2, strict=True)]
    rel = [rotation_from_rotvec(b[0]) @ rotation_from_rotvec(a[0]).T
           for a, b in zip(poses1, poses2, strict=True)]  # fmt: skip
    R = nearest_rotation(np.sum(rel, axis=0))
    T = np.median([b[1] - R @ a[1] for a, b in zip(poses1, poses2, strict=True)], axis=0)
    obj = np.concatenate(objs)
    pix = np.r_[np.concatenate(img1), np.concatenate(img2)]
    view = np.repeat(np.arange(len(objs)), [len(o) for o in objs])
    n = len(objs)

    def unpack(p: np.ndarray):
        r, t = p[:3], p[3:6]
        q = p[6 : 6 + 6 * n].reshape(n, 6)
        rest = p[6 + 6 * n :]
        if fix_intrinsics:
            return r, t, q, (k1, d1, k2, d2)
        ks = []
        for c in range(2):
            f = rest[9 * c : 9 * c + 9]
            ks += [np.array([[f[0], 0, f[2]], [0, f[1], f[3]], [0, 0, 1]]), f[4:9]]
        return r, t, q, tuple(ks)

    def fun(p: np.ndarray) -> np.ndarray:
        r, t, q, (ka, da, kb, db) = unpack(p)
        Rr = rotation_from_rotvec(r)
        R1 = rotation_from_rotvec(q[:, :3])
        r2 = np.array([rotvec_from_rotation(Rr @ Ri) for Ri in R1])
        t2 = q[:, 3:] @ Rr.T + t
        e1 = _project(obj, view, q[:, :3], q[:, 3:], ka, da)
        e2 = _project(obj, view, r2, t2, kb, db)
        return (np.r_[e1, e2] - pix).ravel()

    p0 = np.r_[rotvec_from_rotation(R), T, np.array([np.r_[a[0], a[1]] for a in poses1]).ravel()]
    if not fix_intrinsics:
        for K, d in cams:
            p0 = np.r_[p0, K[0, 0], K[1, 1], K[0, 2], K[1, 2], d]
    sol = least_squares(fun, p0, method="lm", x_scale="jac", max_nfev=2 * _LM_STEPS)
    r, t, _, (k1, d1, k2, d2) = unpack(sol.x)
    R, T = rotation_from_rotvec(r), t.copy()
    e = (sol.fun.reshape(-1, 2) ** 2).sum(axis=1)
    m = len(obj)
    per = np.c_[
        np.sqrt(np.bincount(view, e[:m]) / np.bincount(view)),
        np.sqrt(np.bincount(view, e[m:]) / np.bincount(view)),
    ]
    E = essential_from_pose(R, T)
    F = fundamental_from_essential(E, k1, k2)
    return StereoCalibration(
        k1, d1, k2, d2, R, T, E, F / F[2, 2], float(np.sqrt(e.mean())), per, size
    )


def undistort(
    image: np.ndarray, K: npt.ArrayLike, dist: npt.ArrayLike, new_K: npt.ArrayLike | None = None
) -> np.ndarray:
    """The image as a distortion-free camera would see it (``cv2.undistort``).

    Each output pixel :math:`p` is the ray :math:`K_{new}^{-1} p`, distorted and projected
    with ``K``; the input is sampled there bilinearly (outside: 0).

    Parameters
    ----------
    image : (H, W[, C]) ndarray
    K : (3, 3) array_like
    dist : array_like
        ``(k1, k2, p1, p2[, k3])``.
    new_K : (3, 3) array_like, optional
        Camera matrix of the output (default ``K``).

    Returns
    -------
    ndarray
        Of the shape and dtype of ``image``.

    Raises
    ------
    InputError
        An image that :func:`~robopercept.imaging.remap` does not take, a ``K`` or
        ``new_K`` that is not a camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``
        with ``fx, fy > 0``, or ``dist`` that is not 4 or 5 finite numbers.
    """
    img = check_image(image, "image")
    h, w = img.shape[:2]
    k = _camera_matrix(K, "K")
    nk = k if new_K is None else _camera_matrix(new_K, "new_K")
    mx, my = undistort_rectify_map(k, dist, None, nk, (w, h))
    return remap(img, mx, my)


def rectify_pair(
    left: np.ndarray, right: np.ndarray, calibration: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rectify a stereo pair with a stereo calibration, so that epipolar lines are rows.

    Bouguet's rotations (:func:`~robopercept.geometry.rectify_stereo`, as
    ``cv2.stereoRectify``), then each image is undistorted and remapped through
    :func:`~robopercept.geometry.undistort_rectify_map` (as ``cv2.initUndistortRectifyMap``
    + ``cv2.remap``, bilinear).

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3) ndarray
        The raw images, of one size.
    calibration : dict
        A stereo calibration as :func:`load_calibration` returns it: ``K1, dist1, K2,
        dist2, R, T`` (the ``dist`` entries may be missing: no distortion).

    Returns
    -------
    left_rect, right_rect : ndarray
        The rectified images, same shape and dtype as the inputs.
    Q : (4, 4) ndarray
        The disparity-to-depth matrix for :func:`~robopercept.depth.disparity_to_points`.

    Raises
    ------
    InputError
        Not a stereo calibration (a dict with ``K1, K2, R, T`` whose entries
        :func:`~robopercept.geometry.rectify_stereo` takes), or images that are not
        images of one size.
    """
    if not isinstance(calibration, Mapping):
        raise InputError(
            "calibration must be a dict as load_calibration returns it (K1, dist1, K2, "
            f"dist2, R, T); got {type(calibration).__name__}"
        )
    if not {"K1", "K2", "R", "T"} <= calibration.keys():
        raise InputError("not a stereo calibration: it needs K1 dist1 K2 dist2 R T")
    left, right = check_image(left, "left"), check_image(right, "right")
    if left.shape != right.shape:
        raise InputError(f"the images differ in size: {left.shape} and {right.shape}")
    size = (left.shape[1], left.shape[0])
    cal = calibration
    r = rectify_stereo(
        cal["K1"], cal.get("dist1"), cal["K2"], cal.get("dist2"), cal["R"], cal["T"], size
    )
    left_r = remap(left, *undistort_rectify_map(cal["K1"], cal.get("dist1"), r.R1, r.P1, size))
    right_r = remap(right, *undistort_rectify_map(cal["K2"], cal.get("dist2"), r.R2, r.P2, size))
    return left_r, right_r, r.Q


# --------------------------------------------------------------------------- files


#: the calibration file formats of :func:`save_calibration`
CALIBRATION_FORMATS = ("json", "opencv", "ros")
_FORMAT_OF_SUFFIX = {".json": "json", ".yml": "opencv", ".yaml": "opencv"}


def calibration_format(path: str | Path, format: str | None = None) -> str:
    """The format :func:`save_calibration` writes to ``path``: ``format`` if given
    (checked against the extension), else told by the extension: ``.json`` JSON,
    ``.yml`` / ``.yaml`` OpenCV FileStorage YAML (give ``format="ros"`` for a ROS
    ``camera_info`` YAML).

    Parameters
    ----------
    path : str or Path
    format : {"json", "opencv", "ros"}, optional

    Returns
    -------
    str

    Raises
    ------
    InputError
        Another extension (``.xml`` is read but not written), another format, or a
        format whose files have another extension (JSON in ``.yaml``).

    Examples
    --------
    >>> calibration_format("cam.yaml"), calibration_format("cam.yaml", "ros")
    ('opencv', 'ros')
    """
    p = as_path(path, "path")
    suffix = p.suffix.lower()
    by_ext = _FORMAT_OF_SUFFIX.get(suffix)
    if format is None:
        if by_ext is None:
            raise InputError(
                f"a calibration file is .json (robopercept), .yml or .yaml (OpenCV "
                f"FileStorage, or ROS camera_info with format='ros'); got {p.name!r}"
            )
        return by_ext
    fmt = check_choice(format, "format", CALIBRATION_FORMATS)
    if by_ext is None or (fmt == "json") != (by_ext == "json"):
        want = ".json" if fmt == "json" else ".yaml or .yml"
        raise InputError(f"format {fmt!r} writes {want} files; got {p.name!r}: rename the output")
    return fmt


def _opencv_fields(result: CalibrationResult | StereoCalibration) -> dict[str, Any]:
    """The entries OpenCV's ``calibration`` and ``stereo_calib`` samples write."""
    w, h = result.image_size
    if isinstance(result, CalibrationResult):
        return {
            "image_width": w,
            "image_height": h,
            "camera_matrix": result.K,
            "distortion_coefficients": result.dist.reshape(5, 1),
            "avg_reprojection_error": float(result.rms),
            "per_view_reprojection_errors": result.per_view_errors.reshape(-1, 1),
            "extrinsic_parameters": np.c_[result.rvecs, result.tvecs].reshape(-1, 6),
        }
    r = rectify_stereo(result.K1, result.dist1, result.K2, result.dist2, result.R, result.T, (w, h))
    return {
        "image_width": w,
        "image_height": h,
        "M1": result.K1,
        "D1": result.dist1.reshape(1, 5),
        "M2": result.K2,
        "D2": result.dist2.reshape(1, 5),
        "R": result.R,
        "T": result.T.reshape(3, 1),
        "E": result.E,
        "F": result.F,
        "R1": r.R1,
        "R2": r.R2,
        "P1": r.P1,
        "P2": r.P2,
        "Q": r.Q,
        "rms": float(result.rms),
        "per_view_reprojection_errors": result.per_view_errors.reshape(-1, 2),
    }


def save_calibration(
    path: str | Path,
    result: CalibrationResult | StereoCalibration,
    format: str | None = None,
    *,
    extra: Mapping[str, Any] | None = None,
    camera_name: str = "camera",
) -> list[Path]:
    """Write a calibration as JSON, OpenCV FileStorage YAML or ROS ``camera_info`` YAML;
    :func:`load_calibration` reads all three back.

    - ``"json"``: :meth:`CalibrationResult.to_dict` / :meth:`StereoCalibration.to_dict`
      (``K``, ``dist``, ``image_size``, ...).
    - ``"opencv"``: ``%YAML:1.0`` with ``!!opencv-matrix`` entries, as OpenCV's
      ``calibration`` sample writes them: ``image_width``, ``image_height``,
      ``camera_matrix``, ``distortion_coefficients`` (5x1),
      ``avg_reprojection_error``, ``per_view_reprojection_errors`` (Vx1) and
      ``extrinsic_parameters`` (Vx6: rotation vector, translation per view); a stereo
      pair as the ``stereo_calib`` sample: ``M1, D1, M2, D2, R, T, E, F`` plus
      Bouguet's rectification ``R1, R2, P1, P2, Q``
      (:func:`~robopercept.geometry.rectify_stereo`, as ``cv2.stereoRectify``),
      ``rms`` and ``per_view_reprojection_errors`` (Vx2). ``cv2.FileStorage`` reads
      it: ``fs.getNode("camera_matrix").mat()``.
    - ``"ros"``: :func:`~robopercept.calibration.ros.camera_info` (``plumb_bob``;
      rectification I and projection ``[K | 0]`` for one camera). A stereo pair gives
      two files, ``<stem>_left<suffix>`` and ``<stem>_right<suffix>``, with the
      rectification ``R1, P1`` and ``R2, P2`` as the ROS ``camera_calibration`` node
      writes them (the right projection holds :math:`T_x = -f' B`).

    Parameters
    ----------
    path : str or Path
        The file to write (replaced if it exists; its folder must exist).
    result : CalibrationResult or StereoCalibration
    format : {"json", "opencv", "ros"}, optional
        Default by the extension (:func:`calibration_format`): ``.json`` JSON, ``.yml``
        / ``.yaml`` OpenCV.
    extra : mapping, optional
        More entries for JSON and OpenCV files (numbers, strings, lists of them, lists
        of mappings: the images used, the board); not written to ROS files, whose
        fields are the message's.
    camera_name : str
        ``camera_name`` of a ROS file (``<name>/left`` and ``<name>/right`` for a pair).

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    InputError
        ``result`` of another type, an unknown format or one that does not match the
        extension, ``extra`` that is not a mapping, names an entry of the calibration,
        or holds a value the format cannot store, or ``path`` that is not a usable
        file path (None, empty, a NUL byte, a name too long, a folder).
    FileFormatError
        The file cannot be written (no such folder, no permission).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> res = CalibrationResult(K, np.zeros(5), np.zeros((3, 3)), np.ones((3, 3)), 0.2,
    ...                         np.full(3, 0.2), (640, 480))
    >>> with tempfile.TemporaryDirectory() as d:
    ...     [p] = save_calibration(pathlib.Path(d) / "cam.yaml", res, "ros")
    ...     print(p.read_text().splitlines()[3:6])
    ...     load_calibration(p)["K"][0]
    ['camera_matrix:', '  rows: 3', '  cols: 3']
    array([500.,   0., 320.])
    """
    if not isinstance(result, (CalibrationResult, StereoCalibration)):
        raise InputError(
            "result must be a CalibrationResult (calibrate_camera) or StereoCalibration "
            f"(stereo_calibrate); got {type(result).__name__}"
        )
    p = as_path(path, "path")
    if p.is_dir():
        raise InputError(f"path {p} is a folder; give a file name such as {p / 'camera.json'}")
    fmt = calibration_format(p, format)
    if extra is not None and not isinstance(extra, Mapping):
        raise InputError(f"extra must be a mapping of names to values; got {type(extra).__name__}")
    more = dict(extra or {})
    if fmt == "ros":
        if isinstance(result, CalibrationResult):
            info = camera_info(result.K, result.dist, result.image_size, camera_name=camera_name)
            return [write_ros_yaml(p, info)]
        r = rectify_stereo(
            result.K1, result.dist1, result.K2, result.dist2, result.R, result.T,
            result.image_size,
        )  # fmt: skip
        out = []
        for side, K, d, R, P in (
            ("left", result.K1, result.dist1, r.R1, r.P1),
            ("right", result.K2, result.dist2, r.R2, r.P2),
        ):
            info = camera_info(
                K, d, result.image_size, camera_name=f"{camera_name}/{side}", R=R, P=P
            )
            out.append(write_ros_yaml(p.with_name(f"{p.stem}_{side}{p.suffix}"), info))
        return out
    fields = result.to_dict() if fmt == "json" else _opencv_fields(result)
    clash = sorted(set(more) & set(fields))
    if clash:
        raise InputError(f"extra names entries of the calibration itself: {', '.join(clash)}")
    fields.update(more)
    if fmt == "opencv":
        return [write_opencv_storage(p, fields)]
    try:
        text = json.dumps(fields, indent=2, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise InputError(f"extra holds a value JSON cannot store ({exc})") from exc
    try:
        p.write_text(text)
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot write the calibration ({exc.strerror or exc})") from exc
    return [p]


#: other names of the fields, as OpenCV's samples, cv2.FileStorage users and ROS write them
CALIBRATION_ALIASES: dict[str, tuple[str, ...]] = {
    "K": ("camera_matrix", "cameraMatrix"),
    "dist": ("distortion_coefficients", "distCoeffs", "dist_coeffs", "D"),
    "K1": ("M1", "cameraMatrix1"),
    "dist1": ("D1", "distCoeffs1"),
    "K2": ("M2", "cameraMatrix2"),
    "dist2": ("D2", "distCoeffs2"),
    "image_size": ("imageSize",),
}


def load_calibration(path: str | Path) -> dict[str, Any]:
    """Read a camera calibration: the JSON of :func:`save_calibration` (or by hand), or
    an OpenCV ``FileStorage`` YAML / XML file (``cv2.FileStorage``, OpenCV's
    ``calibration`` and ``stereo_calib`` samples, ROS ``camera_info`` YAML).

    A mono file has ``K`` and ``dist``; a stereo file ``K1, dist1, K2, dist2, R, T``.
    The names OpenCV users write are read as these (:data:`CALIBRATION_ALIASES`):
    ``camera_matrix`` / ``cameraMatrix`` for ``K``, ``distortion_coefficients`` /
    ``distCoeffs`` / ``D`` for ``dist``, ``M1``, ``D1``, ``M2``, ``D2`` for the stereo
    pair, and ``image_width`` with ``image_height`` for ``image_size``. Matrices may be
    ``!!opencv-matrix`` nodes or ``{rows, cols, data}`` mappings (ROS). Matrices come
    back as float64 arrays, ``dist`` as the five ``(k1, k2, p1, p2, k3)`` (4 are padded
    with ``k3 = 0``; OpenCV's 8, 12 or 14 are accepted only when the coefficients past
    ``k3`` are zero), ``image_size`` as ``(width, height)``; other entries are kept
    as read.

    Parameters
    ----------
    path : str or Path
        A ``.json`` file, or a YAML / XML file (told by the content: ``{`` starts
        JSON, ``<`` XML, ``%YAML`` or anything else YAML).

    Returns
    -------
    dict

    Raises
    ------
    FileFormatError
        Unreadable, or missing/ill-shaped fields (named in the message). Every
        numeric field is checked: matrices hold finite numbers only (no strings,
        booleans or null), ``K`` is ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with
        ``fx, fy > 0``, ``R`` a rotation to 1e-6, ``image_size`` two whole numbers of
        pixels in ``[1, 2^31 - 1]`` (``640.0`` reads as 640; ``640.5``, ``Infinity``
        and ``NaN`` are refused).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> yml = '''%YAML:1.0
    ... camera_matrix: !!opencv-matrix
    ...    rows: 3
    ...    cols: 3
    ...    dt: d
    ...    data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]
    ... distortion_coefficients: !!opencv-matrix
    ...    rows: 1
    ...    cols: 5
    ...    dt: d
    ...    data: [ -0.2, 0.05, 0., 0., 0. ]
    ... image_width: 640
    ... image_height: 480
    ... '''
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = pathlib.Path(d) / "camera.yml"
    ...     _ = p.write_text(yml)
    ...     cam = load_calibration(p)
    >>> cam["K"][0], cam["dist"], cam["image_size"]
    (array([500.,   0., 320.]), array([-0.2 ,  0.05,  0.  ,  0.  ,  0.  ]), (640, 480))
    """
    p = check_file(path, "a camera file (.json from `robopercept calibrate`, or OpenCV .yml/.xml)")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{p}: not a readable calibration file ({exc})") from exc
    if text.lstrip().startswith("{"):
        data = parse_json(text, str(p))  # bounded nesting; FileFormatError if not JSON
        if not isinstance(data, dict):
            raise FileFormatError(f"{p}: expected a JSON object")
    else:
        data = read_opencv_storage(p)
    found = ", ".join(sorted(data)) or "nothing"
    data = _canonical_fields(data, p)
    shapes = {"K": (3, 3), "K1": (3, 3), "K2": (3, 3), "R": (3, 3), "E": (3, 3), "F": (3, 3),
              "T": (3,), "dist": None, "dist1": None, "dist2": None}  # fmt: skip
    if "K" not in data and not {"K1", "K2", "R", "T"} <= data.keys():
        raise FileFormatError(
            f"{p}: needs a camera matrix 'K' (or 'camera_matrix', 'cameraMatrix') and "
            "'dist' (or 'distortion_coefficients', 'distCoeffs', 'D') for one camera, or "
            f"'K1', 'K2', 'R', 'T' (or 'M1', 'M2', 'R', 'T') for a stereo pair; found {found}"
        )
    out: dict[str, Any] = dict(data)
    for key, shape in shapes.items():
        if key not in data:
            continue
        try:
            if not _numbers_only(data[key]):  # strings, booleans, None, mappings
                raise TypeError("not all numbers")
            a = np.asarray(data[key])
            if a.dtype.kind not in "iuf":  # ints past 64 bits, ragged nesting
                raise TypeError(f"elements of type {a.dtype}")
            a = a.astype(np.float64)
        except (TypeError, ValueError, OverflowError) as exc:
            raise FileFormatError(
                f"{p}: field {key!r} must hold numbers; got {plain_repr(data[key])[:80]}"
            ) from exc
        if shape is None:
            a = _five_coefficients(a.ravel(), key, p)
        elif a.size == np.prod(shape) and a.shape != shape:
            a = a.reshape(shape)  # T as a 3 x 1 column, as OpenCV writes it
        if shape is not None and a.shape != shape:
            raise FileFormatError(f"{p}: field {key!r} must have shape {shape}; got {a.shape}")
        if not np.isfinite(a).all():
            raise FileFormatError(f"{p}: field {key!r} is not finite")
        if key in ("K", "K1", "K2"):
            _check_camera_matrix(a, key, p)
        if key == "R" and not (np.allclose(a.T @ a, np.eye(3), atol=1e-6) and np.linalg.det(a) > 0):
            raise FileFormatError(
                f"{p}: field 'R' must be a rotation (R^T R = I, det R = +1, to 1e-6); "
                f"got det {np.linalg.det(a):.6g}: write the stereo rotation as "
                "stereo_calibrate / cv2.stereoCalibrate return it"
            )
        out[key] = a
    if "image_size" in data:
        try:
            out["image_size"] = _size(data["image_size"])
        except InputError as exc:
            raise FileFormatError(f"{p}: field 'image_size': {exc}") from exc
    return out


def _numbers_only(value: Any) -> bool:
    """True when ``value`` is a number, or (nested) lists or arrays of numbers only:
    no strings, booleans, None or mappings (JSON ``true`` would become 1)."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, np.ndarray):
            if v.dtype.kind not in "iuf":
                return False
        elif isinstance(v, (list, tuple)):
            stack.extend(v)
        elif isinstance(v, (bool, np.bool_)) or not isinstance(
            v, (int, float, np.integer, np.floating)
        ):
            return False
    return True


def _check_camera_matrix(K: np.ndarray, key: str, p: Path) -> None:
    """Refuse a camera matrix that is not ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``
    with ``fx, fy > 0`` (the form every calibration writes)."""
    if not (K[0, 0] > 0 and K[1, 1] > 0 and K[1, 0] == 0 and np.array_equal(K[2], [0, 0, 1])):
        raise FileFormatError(
            f"{p}: field {key!r} must be a camera matrix [[fx, s, cx], [0, fy, cy], "
            f"[0, 0, 1]] with fx, fy > 0; got {K.tolist()}: take it from a calibration "
            "(robopercept calibrate, cv2.calibrateCamera)"
        )


def _canonical_fields(data: dict[str, Any], p: Path) -> dict[str, Any]:
    """Rename the aliases of :data:`CALIBRATION_ALIASES` (the first name present wins),
    join ``image_width`` and ``image_height`` into ``image_size``, and turn
    ``{rows, cols, data}`` mappings (ROS) into arrays."""
    out = dict(data)
    for key, names in CALIBRATION_ALIASES.items():
        if key not in out:
            alias = next((n for n in names if n in out), None)
            if alias is not None:
                out[key] = out[alias]
    if "image_size" not in out and {"image_width", "image_height"} <= out.keys():
        out["image_size"] = (out["image_width"], out["image_height"])
    for key in ("K", "K1", "K2", "R", "T", "E", "F", "dist", "dist1", "dist2"):
        v = out.get(key)
        if isinstance(v, dict) and "data" in v:
            try:
                if not _numbers_only(v["data"]):
                    raise ValueError("data must hold numbers only")
                a = np.asarray(v["data"], dtype=np.float64)
                if "rows" in v:
                    rows, cols = v["rows"], v["cols"]
                    if not all(
                        isinstance(n, int) and not isinstance(n, bool) and n >= 0
                        for n in (rows, cols)
                    ):
                        raise ValueError(f"rows {rows!r}, cols {cols!r} are not whole numbers")
                    a = a.reshape(rows, cols)
                out[key] = a
            except (KeyError, TypeError, ValueError, OverflowError) as exc:
                raise FileFormatError(f"{p}: field {key!r}: rows x cols != data ({exc})") from exc
    model = out.get("distortion_model")
    if isinstance(model, str) and model not in ("plumb_bob", "rational_polynomial"):
        raise FileFormatError(
            f"{p}: distortion_model {model!r} is not OpenCV's radial-tangential model "
            "(plumb_bob), the one robopercept uses; recalibrate with that model"
        )
    return out


def _five_coefficients(a: np.ndarray, key: str, p: Path) -> np.ndarray:
    """``(k1, k2, p1, p2, k3)`` from OpenCV's 4, 5, 8, 12 or 14 coefficients."""
    if a.size not in (4, 5, 8, 12, 14):
        raise FileFormatError(
            f"{p}: field {key!r} must hold 4 or 5 distortion coefficients "
            f"(k1 k2 p1 p2 [k3]); got {a.size}"
        )
    if a.size > 5 and np.any(a[5:] != 0):
        raise FileFormatError(
            f"{p}: field {key!r} holds {a.size} coefficients with nonzero k4 and beyond "
            "(OpenCV's rational, thin-prism or tilted model); robopercept's lens model has "
            "k1 k2 p1 p2 k3: recalibrate without CALIB_RATIONAL_MODEL, "
            "CALIB_THIN_PRISM_MODEL and CALIB_TILTED_MODEL"
        )
    return np.r_[a, np.zeros(5)][:5]
