r"""Triangulation of 3-D points from two views.

Given projection matrices :math:`P_1, P_2` (3x4) and corresponding image points
:math:`x_1, x_2`, the linear (DLT) method stacks, per point,

.. math::

    A X = 0, \qquad A = \begin{pmatrix} x_1 p^{3T}_1 - p^{1T}_1 \\
    y_1 p^{3T}_1 - p^{2T}_1 \\ x_2 p^{3T}_2 - p^{1T}_2 \\ y_2 p^{3T}_2 - p^{2T}_2
    \end{pmatrix},

(:math:`p^{iT}` the rows of P) and takes the right singular vector of the smallest
singular value, as ``cv2.triangulatePoints`` does. The midpoint method takes the point
halfway along the shortest segment between the two back-projected rays.

Scale: a projection matrix is defined up to scale, each point's :math:`A` too (its null
vector does not change), and a ray's direction has no length; each is divided by the
power of two nearest its largest entry before the SVD or the normal equations. Dividing
by a power of two is exact in floating point, so the result is the one of the unscaled
arithmetic wherever that did not overflow, and projection matrices with entries near
1e300 or 1e-300 (whose squares overflow or underflow) give finite, correct points
instead of a ``LinAlgError`` or NaN. Image points are refused beyond 1e150 in magnitude
(a point that far from the principal point lies on the camera's principal plane, where
the DLT's rows of the other camera vanish in rounding).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_choice, check_finite, check_magnitude, squeeze_point_axis
from robopercept.errors import DegenerateError, InputError

__all__ = ["triangulate"]


def _pow2_scale(a: np.ndarray, axis: int | tuple[int, ...] | None = None) -> np.ndarray:
    """``a`` divided by a power of two near its largest absolute entry (along ``axis``;
    exact in floating point; all-zero slices are left alone)."""
    m = np.abs(a).max(axis=axis, keepdims=True)
    _, e = np.frexp(np.where(m > 0, m, 1.0))
    return np.ldexp(a, -e)


def _projection(P: npt.ArrayLike, name: str) -> np.ndarray:
    p = np.asarray(P)
    if p.shape != (3, 4) or p.dtype.kind not in "iuf" or not np.isfinite(p).all():
        raise InputError(
            f"{name} must be a finite numeric 3x4 projection matrix; got shape {p.shape}, "
            f"dtype {p.dtype}"
        )
    p = _pow2_scale(p.astype(np.float64))  # P is defined up to scale
    if not np.abs(p).max() > 0 or np.linalg.matrix_rank(p[:, :3]) < 3:
        raise InputError(f"{name}'s left 3x3 block is singular: not a finite camera")
    return p


def triangulate(
    P1: npt.ArrayLike,
    P2: npt.ArrayLike,
    x1: npt.ArrayLike,
    x2: npt.ArrayLike,
    *,
    method: str = "dlt",
) -> np.ndarray:
    r"""3-D points ``(N, 3)`` seen at ``x1`` by ``P1`` and at ``x2`` by ``P2``.

    Parameters
    ----------
    P1, P2 : (3, 4) array_like
        Projection matrices :math:`K [R \mid t]` (or :math:`[R \mid t]` for normalized
        coordinates).
    x1, x2 : (N, 2) array_like
        Corresponding image points.
    method : {"dlt", "midpoint"}
        Linear least squares on :math:`A X = 0` (``cv2.triangulatePoints``), or the
        midpoint of the common perpendicular of the two rays.

    Returns
    -------
    (N, 3) ndarray
        Inhomogeneous points; inf where the DLT solution lies at infinity (parallel
        rays).

    Raises
    ------
    InputError
        A projection matrix that is not a finite 3x4 matrix with an invertible left
        block, points that are not ``(N, 2)``, hold NaN/inf or values beyond 1e150 (the
        message names ``x1`` or ``x2``), or an unknown ``method``.
    DegenerateError
        Parallel rays with ``method="midpoint"``.
    """
    check_choice(method, "method", ("dlt", "midpoint"))
    p1, p2 = _projection(P1, "P1"), _projection(P2, "P2")
    a = squeeze_point_axis(np.asarray(x1), 2)  # OpenCV's (N, 1, 2) too
    b = squeeze_point_axis(np.asarray(x2), 2)
    if a.ndim != 2 or a.shape[1] != 2 or b.shape != a.shape:
        raise InputError(f"x1 and x2 must both be (N, 2); got shapes {a.shape} and {b.shape}")
    for arr, name in ((a, "x1"), (b, "x2")):
        if arr.dtype.kind not in "iuf":
            raise InputError(f"{name} must be numeric image points; got dtype {arr.dtype}")
        check_finite(arr, name)
        check_magnitude(arr, name, 1e150)
    a, b = a.astype(np.float64), b.astype(np.float64)
    if method == "dlt":
        A = np.empty((len(a), 4, 4))
        A[:, 0] = a[:, :1] * p1[2] - p1[0]
        A[:, 1] = a[:, 1:] * p1[2] - p1[1]
        A[:, 2] = b[:, :1] * p2[2] - p2[0]
        A[:, 3] = b[:, 1:] * p2[2] - p2[1]
        # (|entries of P| < 1 after scaling: x * P cannot overflow)
        _, _, vt = np.linalg.svd(_pow2_scale(A, axis=(1, 2)))  # each A up to scale
        X = vt[:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            return X[:, :3] / X[:, 3:]
    c1, d1 = _rays(p1, a)
    c2, d2 = _rays(p2, b)
    # closest points c1 + s d1 and c2 + u d2: solve the 2x2 normal equations per point
    w = c1 - c2
    aa = (d1 * d1).sum(axis=1)
    bb = (d1 * d2).sum(axis=1)
    cc = (d2 * d2).sum(axis=1)
    dd = (d1 * w).sum(axis=1)
    ee = (d2 * w).sum(axis=1)
    den = aa * cc - bb * bb
    if (np.abs(den) <= 1e-14 * aa * cc).any():
        raise DegenerateError("parallel rays: the midpoint of the two rays is not defined")
    s = (bb * ee - cc * dd) / den
    u = (aa * ee - bb * dd) / den
    return 0.5 * ((c1 + s[:, None] * d1) + (c2 + u[:, None] * d2))


def _rays(P: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre :math:`C = -M^{-1} p_4` and ray directions :math:`M^{-1} x`."""
    M_inv = np.linalg.inv(P[:, :3])
    centre = -M_inv @ P[:, 3]
    d = _pow2_scale(np.c_[x, np.ones(len(x))] @ M_inv.T, axis=1)  # lengths do not matter
    return np.broadcast_to(centre, d.shape), d
