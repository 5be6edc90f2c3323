r"""Rigid transforms in SE(3) as 4x4 homogeneous matrices.

``T_a_b`` maps points from frame b into frame a: :math:`p_a = R p_b + t` with
:math:`T = \begin{bmatrix} R & t \\ 0 & 1 \end{bmatrix}`, and
``T_a_b @ T_b_c == T_a_c``. The inverse is :math:`\begin{bmatrix} R^\top & -R^\top t
\\ 0 & 1 \end{bmatrix}`.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_numeric
from robopercept.errors import InputError

__all__ = [
    "apply",
    "check_matrix3",
    "check_transform",
    "compose",
    "invert",
    "nearest_rotation",
    "rotation_from_rotvec",
    "rotvec_from_rotation",
    "se3",
]


def check_transform(T: npt.ArrayLike, name: str = "T") -> np.ndarray:
    """``T`` as a float64 4x4 array after checking its dtype (real numbers), shape and
    last row."""
    m = check_numeric(T, name)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise InputError(f"{name} must be a finite 4x4 matrix; got shape {m.shape}")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise InputError(f"{name}'s last row must be [0, 0, 0, 1]; got {m[3].tolist()}")
    return m


def check_matrix3(M: npt.ArrayLike, name: str = "M", *, invertible: bool = False) -> np.ndarray:
    """``M`` as a float64 3x3 array after checking its dtype (real numbers), its shape
    and that it is finite (and, with ``invertible``, that it has rank 3).

    Parameters
    ----------
    M : (3, 3) array_like
        A camera matrix, rotation, essential or fundamental matrix, homography.
    name : str
        The argument's name in the error message.
    invertible : bool
        Also refuse a singular matrix (numerical rank below 3, from its singular values
        as ``numpy.linalg.matrix_rank``): a camera matrix or a homography that will be
        inverted.

    Returns
    -------
    (3, 3) float64 ndarray

    Raises
    ------
    InputError
        Not real numbers, another shape, NaN/inf, or (``invertible``) singular.

    Examples
    --------
    >>> check_matrix3(np.eye(3), "K").dtype
    dtype('float64')
    """
    m = check_numeric(M, name)
    if m.shape != (3, 3) or not np.isfinite(m).all():
        raise InputError(f"{name} must be a finite 3x3 matrix; got shape {m.shape}")
    if invertible and np.linalg.matrix_rank(m) < 3:
        raise InputError(
            f"{name} is singular (rank {np.linalg.matrix_rank(m)}) and cannot be inverted; "
            f"got {m.tolist()}: give a rank-3 matrix (a camera matrix is [[fx, 0, cx], "
            "[0, fy, cy], [0, 0, 1]] with fx, fy > 0)"
        )
    return m


def se3(rotation: np.ndarray | None = None, translation: np.ndarray | None = None) -> np.ndarray:
    """4x4 transform from a rotation matrix (or rotation vector, 3 elements) and a
    translation; either defaults to the identity / zero.

    Raises :class:`InputError` if the rotation is not orthonormal with determinant +1
    (tolerance 1e-6).
    """
    T = np.eye(4)
    if rotation is not None:
        r = check_numeric(rotation, "rotation")
        if not np.isfinite(r).all():
            raise InputError("rotation must be finite; got NaN/inf")
        if r.shape == (3,):
            r = rotation_from_rotvec(r)
        if r.shape != (3, 3):
            raise InputError(f"rotation must be 3x3 or a 3-vector; got shape {r.shape}")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError("rotation must be orthonormal with determinant +1")
        T[:3, :3] = r
    if translation is not None:
        t = check_numeric(translation, "translation").reshape(-1)
        if t.shape != (3,) or not np.isfinite(t).all():
            raise InputError(f"translation must be 3 finite numbers; got {t.tolist()}")
        T[:3, 3] = t
    return T


def rotation_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    r"""Rodrigues' formula (``cv2.Rodrigues`` on a vector), for one rotation vector or many.

    .. math:: R = I + \sin\theta\, [k]_\times + (1 - \cos\theta)\, [k]_\times^2

    for the rotation by :math:`\theta = \|r\|` about :math:`k = r / \theta`; below
    :math:`\theta = 10^{-12}` the first-order :math:`R = I + [r]_\times`.

    Parameters
    ----------
    rotvec : (3,) or (..., 3) array_like
        Rotation vectors in radians (OpenCV's ``(3, 1)`` column too).

    Returns
    -------
    (3, 3) or (..., 3, 3) float64 ndarray
        A ``(3,)`` or ``(3, 1)`` input gives one matrix, a ``(..., 3)`` stack a stack
        (``(1, 3)`` gives ``(1, 3, 3)``). Matches ``cv2.Rodrigues`` and
        ``scipy.spatial.transform.Rotation.from_rotvec(r).as_matrix()`` to rounding.

    Raises
    ------
    InputError
        A shape other than those.

    Examples
    --------
    >>> np.round(rotation_from_rotvec([0.0, 0.0, np.pi / 2]), 12).tolist()
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    r = check_numeric(rotvec, "rotvec")
    single = r.shape in ((3,), (3, 1))
    if single:
        r = r.reshape(1, 3)
    elif r.ndim < 2 or r.shape[-1] != 3:
        raise InputError(f"rotvec must have shape (3,), (3, 1) or (..., 3); got {r.shape}")
    theta = np.linalg.norm(r, axis=-1)
    small = theta < 1e-12
    k = r / np.where(small, 1.0, theta)[..., None]
    kx = np.zeros((*r.shape[:-1], 3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    s = np.where(small, 1.0, np.sin(theta))[..., None, None]  # small: k = r, R = I + [r]x
    c = np.where(small, 1.0, np.cos(theta))[..., None, None]
    R = np.eye(3) + s * kx + (1 - c) * (kx @ kx)
    return R[0] if single else R


def rotvec_from_rotation(R: np.ndarray) -> np.ndarray:
    r"""The inverse of :func:`rotation_from_rotvec` (``cv2.Rodrigues`` on a matrix):
    :math:`\theta = \arccos((\operatorname{tr} R - 1) / 2)` and the axis from the
    antisymmetric part :math:`(R - R^T) / (2 \sin\theta)`; near :math:`\theta = \pi`
    (where that part vanishes) the axis comes from :math:`(R + I) / 2 = k k^T`."""
    r = check_numeric(R, "R")
    if r.shape != (3, 3) or not np.isfinite(r).all():
        raise InputError(f"R must be a finite 3x3 rotation matrix; got shape {r.shape}")
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2.0
    c = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    s = float(np.linalg.norm(v))
    theta = float(np.arctan2(s, c))
    if s > 1e-6:
        return v / s * theta
    if c > 0:  # theta ~ 0: R ~ I + [theta k]x
        return v
    B = (r + np.eye(3)) / 2.0  # theta ~ pi: B = k k^T
    i = int(np.argmax(np.diag(B)))
    k = B[:, i] / np.sqrt(max(B[i, i], 1e-300))
    if k @ v < 0:
        k = -k
    return k * theta


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    r"""The rotation closest to a 3x3 matrix in the Frobenius norm (orthogonal
    Procrustes): :math:`U \operatorname{diag}(1, 1, \det U V^T) V^T` from
    :math:`M = U S V^T`. Orthonormalizes a noisy rotation, and averages rotations when M
    is their sum (the chordal mean).

    Raises :class:`InputError` if ``M`` is not a finite real 3x3 matrix."""
    u, _, vt = np.linalg.svd(check_matrix3(M, "M"))
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (exact: transpose of the rotation)."""
    m = check_transform(T)
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def compose(*transforms: np.ndarray) -> np.ndarray:
    """``compose(T_a_b, T_b_c, ...) == T_a_b @ T_b_c @ ...``."""
    out = np.eye(4)
    for i, t in enumerate(transforms):
        out = out @ check_transform(t, f"transform {i}")
    return out


def apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map ``(..., 3)`` points by ``T``: :math:`R p + t`."""
    m = check_transform(T)
    p = check_numeric(points, "points")
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have shape (..., 3); got {p.shape}")
    return p @ m[:3, :3].T + m[:3, 3]
