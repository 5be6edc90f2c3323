r"""Stereo rectification: make the two image planes coplanar and their rows aligned, so
that corresponding points share a row and stereo matching is a 1-D search.

Calibrated (Bouguet's algorithm, ``cv2.stereoRectify``): with
:math:`X_2 = R X_1 + T`, each camera is first turned by half of the relative rotation,
:math:`r = \operatorname{rodrigues}(-\tfrac12 \operatorname{rodrigues}^{-1}(R))`
(camera 1 by :math:`r^T`, camera 2 by :math:`r`), which makes them parallel; then both
by the rotation :math:`W` that takes the baseline :math:`t = r T` onto the x axis (or
the y axis for a vertical rig). :math:`R_1 = W r^T`, :math:`R_2 = W r`. The new
cameras share a focal length (the mean of the two vertical ones, as OpenCV 4) and, with
``zero_disparity``, a principal point placed so that the undistorted image corners are
centred; :math:`P_2` carries the baseline, :math:`P_2[0, 3] = f\,t'_x`, and

.. math::

    Q = \begin{pmatrix} 1 & 0 & 0 & -c_x \\ 0 & 1 & 0 & -c_y \\ 0 & 0 & 0 & f \\
    0 & 0 & -1/T'_x & (c_x - c'_x)/T'_x \end{pmatrix}

maps :math:`(x, y, d, 1)` to homogeneous 3-D points (``cv2.reprojectImageTo3D``).

Uncalibrated (Hartley 1999): from F and correspondences, a homography :math:`H_2`
sends the second epipole to infinity along x, and :math:`H_1` is the one of the
compatible family that brings the points of image 1 closest to their partners' rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_bool,
    check_magnitude,
    check_numeric,
    check_size,
    squeeze_point_axis,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.geometry.camera import check_distortion, distort, undistort_points
from robopercept.geometry.transforms import (
    check_matrix3,
    rotation_from_rotvec,
    rotvec_from_rotation,
)

__all__ = [
    "StereoRectification",
    "rectify_stereo",
    "rectify_uncalibrated",
    "undistort_rectify_map",
]

#: largest ``width * height`` of :func:`undistort_rectify_map` (2**28, 16384 x 16384:
#: its two float32 maps take 2 GiB at this bound)
_MAX_MAP_PIXELS = 1 << 28
_BLOCK_PIXELS = 1 << 20  # pixels per block of the maps' float64 intermediates


@dataclass(frozen=True)
class StereoRectification:
    """Result of :func:`rectify_stereo` (``cv2.stereoRectify``'s outputs).

    Attributes
    ----------
    R1, R2 : (3, 3) ndarray
        Rotations from each original camera frame to its rectified frame.
    P1, P2 : (3, 4) ndarray
        Projection matrices in the rectified frame of camera 1.
    Q : (4, 4) ndarray
        Disparity-to-depth matrix.
    vertical : bool
        True for a vertical rig (rows become columns).
    """

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    vertical: bool


def rectify_stereo(
    K1: npt.ArrayLike,
    D1: npt.ArrayLike | None,
    K2: npt.ArrayLike,
    D2: npt.ArrayLike | None,
    R: npt.ArrayLike,
    T: npt.ArrayLike,
    size: tuple[int, int],
    *,
    zero_disparity: bool = True,
) -> StereoRectification:
    """Bouguet rectification of a calibrated pair (``cv2.stereoRectify`` with its
    default ``alpha=-1``: no extra zoom).

    Parameters
    ----------
    K1, K2 : (3, 3) array_like
        Camera matrices.
    D1, D2 : array_like or None
        Distortion ``(k1, k2, p1, p2[, k3])``.
    R, T : (3, 3), (3,) array_like
        Pose of camera 2 relative to camera 1: :math:`X_2 = R X_1 + T`.
    size : (width, height)
    zero_disparity : bool
        Give both cameras the same principal point (``cv2.CALIB_ZERO_DISPARITY``, the
        default there too), so points at infinity have disparity 0.

    Returns
    -------
    StereoRectification

    Raises
    ------
    InputError
        Matrices that are not finite, real and 3x3 (or a singular camera matrix),
        distortion that is not 4 or 5 finite numbers, a zero ``T`` or one beyond 1e150,
        or ``size`` not two whole numbers in [2, 65536].
    """
    k1 = check_matrix3(K1, "K1", invertible=True)
    k2 = check_matrix3(K2, "K2", invertible=True)
    d1, d2 = check_distortion(D1, "D1"), check_distortion(D2, "D2")
    Rm = check_matrix3(R, "R")
    t_in = check_numeric(T, "T").ravel()
    if t_in.size != 3 or not np.isfinite(t_in).all() or not np.abs(t_in).max() > 0:
        raise InputError(f"T must be a non-zero 3-vector; got {T!r}")
    check_magnitude(t_in, "T", 1e150)
    nx, ny = check_size(size, "size", minimum=2)
    zero_disparity = check_bool(zero_disparity, "zero_disparity")
    r_r = rotation_from_rotvec(-0.5 * rotvec_from_rotation(Rm))
    t = r_r @ t_in
    idx = 0 if abs(t[0]) > abs(t[1]) else 1
    uu = np.zeros(3)
    uu[idx] = 1.0 if t[idx] > 0 else -1.0
    ww = np.cross(t, uu)
    nw = np.linalg.norm(ww)
    if nw > 0:
        ww *= np.arccos(abs(t[idx]) / np.linalg.norm(t)) / nw
    wR = rotation_from_rotvec(ww)
    R1 = wR @ r_r.T
    R2 = wR @ r_r
    t = R2 @ t_in
    fc = (k1[idx ^ 1, idx ^ 1] + k2[idx ^ 1, idx ^ 1]) / 2.0  # as OpenCV 4: the mean
    corners = np.array([[0, 0], [nx - 1, 0], [0, ny - 1], [nx - 1, ny - 1]], dtype=np.float64)
    cc = []
    for K, D, Rk in ((k1, d1, R1), (k2, d2, R2)):
        n = undistort_points(corners, K, D)
        ray = np.c_[n, np.ones(4)] @ Rk.T
        avg = (fc * ray[:, :2] / ray[:, 2:]).mean(axis=0)
        cc.append(np.array([(nx - 1) / 2.0 - avg[0], (ny - 1) / 2.0 - avg[1]]))
    if zero_disparity:
        cc[0] = cc[1] = (cc[0] + cc[1]) / 2.0
    else:
        cc[0][idx ^ 1] = cc[1][idx ^ 1] = (cc[0][idx ^ 1] + cc[1][idx ^ 1]) / 2.0
    P1 = np.array([[fc, 0, cc[0][0], 0], [0, fc, cc[0][1], 0], [0, 0, 1, 0]])
    P2 = np.array([[fc, 0, cc[1][0], 0], [0, fc, cc[1][1], 0], [0, 0, 1, 0]])
    P2[idx, 3] = t[idx] * fc
    Q = np.zeros((4, 4))
    Q[0, 0] = Q[1, 1] = 1.0
    Q[0, 3], Q[1, 3] = -cc[0][0], -cc[0][1]
    Q[2, 3] = fc
    Q[3, 2] = -1.0 / t[idx]
    Q[3, 3] = (cc[0][idx] - cc[1][idx]) / t[idx]
    return StereoRectification(R1, R2, P1, P2, Q, idx == 1)


def rectify_uncalibrated(
    F: npt.ArrayLike, x1: npt.ArrayLike, x2: npt.ArrayLike, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    r"""Hartley's rectification from F: homographies ``H1, H2`` (3x3) such that
    :math:`H_1 x_1` and :math:`H_2 x_2` lie on the same row.

    :math:`H_2 = G R T` moves the image centre to the origin (T), turns the epipole
    :math:`e_2` onto the x axis (R) and sends it to infinity with
    :math:`G = \begin{pmatrix} 1&0&0\\0&1&0\\-1/f&0&1 \end{pmatrix}`.
    :math:`H_1 = H_A H_2 M` with :math:`M = [e_2]_\times F + e_2 (1, 1, 1)` (any
    :math:`M` with :math:`F = [e_2]_\times M` maps image 1 compatibly) and
    :math:`H_A = \begin{pmatrix} a&b&c\\0&1&0\\0&0&1 \end{pmatrix}` fitted by linear
    least squares to minimize :math:`\sum (a \hat x_1 + b \hat y_1 + c - \hat x_2)^2`.

    Parameters
    ----------
    F : (3, 3) array_like
        With :math:`x_2^T F x_1 = 0`.
    x1, x2 : (N, 2) array_like
        Correspondences (inliers), N >= 3.
    size : (width, height) of the images.

    Raises
    ------
    InputError
        ``F`` not a finite real 3x3 matrix of rank 2 or more, points that are not
        finite ``(N, 2)`` arrays of one shape within 1e150, or ``size`` not two whole
        numbers in [1, 65536].
    DegenerateError
        The epipole lies inside the image (a forward motion cannot be rectified by
        homographies without tearing the picture), too few correspondences, or
        correspondences that the homographies send to infinity.
    """
    from robopercept.geometry.epipolar import epipoles, skew

    Fm = check_matrix3(F, "F")
    p1 = squeeze_point_axis(check_numeric(x1, "x1"), 2)  # OpenCV's (N, 1, 2) too
    p2 = squeeze_point_axis(check_numeric(x2, "x2"), 2)
    if p1.ndim != 2 or p1.shape[1] != 2 or p2.shape != p1.shape:
        raise InputError(f"x1 and x2 must both be (N, 2); got {p1.shape} and {p2.shape}")
    for p, name in ((p1, "x1"), (p2, "x2")):
        if not np.isfinite(p).all():
            raise InputError(f"{name} contains NaN or inf; drop those correspondences first")
        check_magnitude(p, name, 1e150)
    if len(p1) < 3:
        raise DegenerateError(f"rectify_uncalibrated needs >= 3 correspondences; got {len(p1)}")
    Fm = Fm / max(np.abs(Fm).max(), 1e-300)  # F is defined up to scale
    sv = np.linalg.svd(Fm, compute_uv=False)
    if not sv[1] > 1e-12 * sv[0]:
        raise InputError(
            f"F must be a fundamental matrix (rank 2); got singular values {sv.tolist()}: "
            "estimate it with find_fundamental"
        )
    w, h = (float(v) for v in check_size(size, "size"))
    _, e2 = epipoles(Fm)
    if abs(e2[2]) > 1e-12:
        ex, ey = e2[0] / e2[2], e2[1] / e2[2]
        if 0 <= ex < w and 0 <= ey < h:
            raise DegenerateError(
                f"the epipole ({ex:.0f}, {ey:.0f}) lies inside the image: the motion is "
                "mostly forward and cannot be rectified by homographies"
            )
    T = np.array([[1.0, 0, -(w - 1) / 2], [0, 1.0, -(h - 1) / 2], [0, 0, 1.0]])
    e = T @ e2
    if abs(e[2]) < 1e-12 * np.hypot(e[0], e[1]):  # already at infinity
        angle = np.arctan2(e[1], e[0])
        finf = np.inf
    else:
        e = e / e[2]
        angle = np.arctan2(e[1], e[0])
        finf = np.hypot(e[0], e[1])
    c, s = np.cos(-angle), np.sin(-angle)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    G = np.eye(3)
    if np.isfinite(finf):
        G[2, 0] = -1.0 / finf
    H2 = G @ Rz @ T
    e2n = e2 / np.linalg.norm(e2)
    M = skew(e2n) @ Fm + np.outer(e2n, np.ones(3))
    H0 = H2 @ M
    a = np.c_[p1, np.ones(len(p1))] @ H0.T
    b = np.c_[p2, np.ones(len(p2))] @ H2.T
    with np.errstate(divide="ignore", invalid="ignore"):
        a = a[:, :2] / a[:, 2:]
        b = b[:, :2] / b[:, 2:]
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise DegenerateError(
            "the rectifying homographies send some correspondences to infinity (points on "
            "the line through the epipole that they map to the line at infinity): check "
            "that F belongs to x1 and x2, or drop the points far outside the image"
        )
    abc, *_ = np.linalg.lstsq(np.c_[a, np.ones(len(a))], b[:, 0], rcond=None)
    HA = np.array([[abc[0], abc[1], abc[2]], [0, 1.0, 0], [0, 0, 1.0]])
    H1 = HA @ H0
    return H1 / H1[2, 2], H2 / H2[2, 2]


def undistort_rectify_map(
    K: npt.ArrayLike,
    D: npt.ArrayLike | None,
    R: npt.ArrayLike | None,
    P: npt.ArrayLike,
    size: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray]:
    r"""Per-pixel source positions that undistort (and rectify) an image
    (``cv2.initUndistortRectifyMap``).

    For an output pixel :math:`(u, v)` the ray :math:`(X, Y, W)^T = (P_{3 \times 3} R)^{-1}
    (u, v, 1)^T` is taken back to the original camera, distorted,
    :math:`(x_d, y_d) = \operatorname{dist}(X / W, Y / W)`, and projected with K:
    ``map_x = fx * x_d + cx``, ``map_y = fy * y_d + cy``. Feed the maps to
    :func:`robopercept.imaging.remap`.

    Parameters
    ----------
    K : (3, 3) array_like
        Original camera matrix.
    D : array_like or None
        ``(k1, k2, p1, p2[, k3])``.
    R : (3, 3) array_like or None
        Rectifying rotation (``R1`` or ``R2`` of :func:`rectify_stereo`); None for the
        identity (plain undistortion).
    P : (3, 3) or (3, 4) array_like
        New camera (``P1``/``P2``, or a camera matrix).
    size : (width, height)
        Output size.

    Returns
    -------
    map_x, map_y : (height, width) float32 ndarray

    Raises
    ------
    InputError
        Matrices that are not finite and real, of the wrong shape, a singular
        :math:`P_{3 \times 3} R`, distortion that is not 4 or 5 finite numbers, or a
        ``size`` that is not two whole numbers in [1, 65536] with at most
        2**28 pixels in all (the maps take 8 bytes per pixel; they are
        computed in blocks of rows).
    """
    k = check_matrix3(K, "K")
    d = check_distortion(D, "D")
    r = np.eye(3) if R is None else check_matrix3(R, "R")
    p = check_numeric(P, "P")
    if p.shape not in ((3, 3), (3, 4)) or not np.isfinite(p).all():
        raise InputError(f"P must be a finite 3x3 or 3x4 matrix; got shape {p.shape}")
    w, h = check_size(size, "size", max_pixels=_MAX_MAP_PIXELS)
    pr = p[:, :3] @ r
    if not np.isfinite(pr).all() or np.linalg.matrix_rank(pr) < 3:
        raise InputError(
            "P[:, :3] @ R is singular (or overflows): give the new camera matrix "
            "[[f, 0, cx], [0, f, cy], [0, 0, 1]] (P1 or P2 of rectify_stereo) and a rotation R"
        )
    ir = np.linalg.inv(pr)
    map_x = np.empty((h, w), dtype=np.float32)
    map_y = np.empty((h, w), dtype=np.float32)
    u = np.arange(w, dtype=np.float64)
    step = max(1, _BLOCK_PIXELS // w)  # rows per block: bounded intermediates
    for top in range(0, h, step):
        uu, vv = np.meshgrid(u, np.arange(top, min(h, top + step), dtype=np.float64))
        ray = np.stack([uu, vv, np.ones_like(uu)], axis=-1) @ ir.T
        xd, yd = distort(ray[..., 0] / ray[..., 2], ray[..., 1] / ray[..., 2], d)
        map_x[top : top + step] = k[0, 0] * xd + k[0, 1] * yd + k[0, 2]
        map_y[top : top + step] = k[1, 1] * yd + k[1, 2]
    return map_x, map_y
