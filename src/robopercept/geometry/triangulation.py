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
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept.errors import DegenerateError, InputError

__all__ = ["triangulate"]


def _projection(P: npt.ArrayLike, name: str) -> np.ndarray:
    p = np.asarray(P, dtype=np.float64)
    if p.shape != (3, 4) or not np.isfinite(p).all():
        raise InputError(f"{name} must be a finite 3x4 projection matrix; got shape {p.shape}")
    if np.linalg.matrix_rank(p[:, :3]) < 3:
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
    """
    p1, p2 = _projection(P1, "P1"), _projection(P2, "P2")
    a = np.asarray(x1, dtype=np.float64)
    b = np.asarray(x2, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 2 or b.shape != a.shape:
        raise InputError(f"x1 and x2 must both be (N, 2); got shapes {a.shape} and {b.shape}")
    if method == "dlt":
        A = np.empty((len(a), 4, 4))
        A[:, 0] = a[:, :1] * p1[2] - p1[0]
        A[:, 1] = a[:, 1:] * p1[2] - p1[1]
        A[:, 2] = b[:, :1] * p2[2] - p2[0]
        A[:, 3] = b[:, 1:] * p2[2] - p2[1]
        _, _, vt = np.linalg.svd(A)
        X = vt[:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            return X[:, :3] / X[:, 3:]
    if method != "midpoint":
        raise InputError(f"method must be 'dlt' or 'midpoint'; got {method!r}")
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
    d = np.c_[x, np.ones(len(x))] @ M_inv.T
    return np.broadcast_to(centre, d.shape), d
