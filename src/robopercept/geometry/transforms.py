r"""Rigid transforms in SE(3) as 4x4 homogeneous matrices.

``T_a_b`` maps points from frame b into frame a: :math:`p_a = R p_b + t` with
:math:`T = \begin{bmatrix} R & t \\ 0 & 1 \end{bmatrix}`, and
``T_a_b @ T_b_c == T_a_c``. The inverse is :math:`\begin{bmatrix} R^\top & -R^\top t
\\ 0 & 1 \end{bmatrix}`.
"""

from __future__ import annotations

import numpy as np

from robopercept.errors import InputError

__all__ = [
    "apply",
    "check_transform",
    "compose",
    "invert",
    "nearest_rotation",
    "rotation_from_rotvec",
    "rotvec_from_rotation",
    "se3",
]


def check_transform(T: np.ndarray, name: str = "T") -> np.ndarray:
    """``T`` as a float64 4x4 array after checking its shape and last row."""
    m = np.asarray(T, dtype=np.float64)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise InputError(f"{name} must be a finite 4x4 matrix; got shape {m.shape}")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise InputError(f"{name}'s last row must be [0, 0, 0, 1]; got {m[3].tolist()}")
    return m


def se3(rotation: np.ndarray | None = None, translation: np.ndarray | None = None) -> np.ndarray:
    """4x4 transform from a rotation matrix (or rotation vector, 3 elements) and a
    translation; either defaults to the identity / zero.

    Raises :class:`InputError` if the rotation is not orthonormal with determinant +1
    (tolerance 1e-6).
    """
    T = np.eye(4)
    if rotation is not None:
        r = np.asarray(rotation, dtype=np.float64)
        if r.shape == (3,):
            r = rotation_from_rotvec(r)
        if r.shape != (3, 3):
            raise InputError(f"rotation must be 3x3 or a 3-vector; got shape {r.shape}")
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
            raise InputError("rotation must be orthonormal with determinant +1")
        T[:3, :3] = r
    if translation is not None:
        t = np.asarray(translation, dtype=np.float64).reshape(-1)
        if t.shape != (3,):
            raise InputError(f"translation must have 3 elements; got {t.shape}")
        T[:3, 3] = t
    return T


def rotation_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    r"""Rodrigues: :math:`R = I + \sin\theta [k]_\times + (1 - \cos\theta) [k]_\times^2`
    for the rotation by :math:`\theta = \|r\|` about :math:`k = r / \theta`."""
    r = np.asarray(rotvec, dtype=np.float64).reshape(3)
    theta = float(np.linalg.norm(r))
    if theta < 1e-15:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * kx @ kx


def rotvec_from_rotation(R: np.ndarray) -> np.ndarray:
    r"""The inverse of :func:`rotation_from_rotvec` (``cv2.Rodrigues`` on a matrix):
    :math:`\theta = \arccos((\operatorname{tr} R - 1) / 2)` and the axis from the
    antisymmetric part :math:`(R - R^T) / (2 \sin\theta)`; near :math:`\theta = \pi`
    (where that part vanishes) the axis comes from :math:`(R + I) / 2 = k k^T`."""
    r = np.asarray(R, dtype=np.float64)
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
    is their sum (the chordal mean)."""
    u, _, vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
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
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-1:] != (3,):
        raise InputError(f"points must have shape (..., 3); got {p.shape}")
    return p @ m[:3, :3].T + m[:3, 3]
