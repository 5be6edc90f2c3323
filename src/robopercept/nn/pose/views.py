r"""3-D poses seen from cameras: the root joint, random views of 3-D poses and the
translation- and scale-free 2-D normalization, with the input checks the lifters
(:mod:`.library`, :mod:`.lifting`) share.

Frames and units
----------------
3-D library poses are ``(N, J, 3)`` arrays in the figure's own frame (x to the figure's
left, y up, z the way it faces, metres; :func:`robopercept.nn.pose.data.random_poses_3d`).
Lifted poses are in the camera frame of OpenCV (x right, y down, z forward), **rooted**
at the root joint (the pelvis, joint 6 of :data:`~robopercept.nn.skeleton.MPII_16`):
:math:`P_j - P_{root}`. Neither lifter recovers the distance to the camera (a 2-D pose
is the same up to translation and scale, so the 2-D normalization discards both): the
depth is relative to the root, and the scale is the library's (or the training data's):
a child seen by a lifter built from adult figures comes out adult-sized.

Random views
------------
:func:`random_views` turns each figure by a yaw :math:`\psi \sim U(-\pi, \pi)` about its
vertical (the whole way round: front, sides and back), raises the camera by an
elevation :math:`\varepsilon \sim U(\text{elevation})` and places it at a distance
:math:`d \sim U(\text{distance})` from the root, looking at the root:

.. math::

    P^{cam}_j = R_x(\varepsilon)\, \mathrm{diag}(1, -1, -1)\, R_y(\psi)\,
    (P_j - P_{root}) + (0, 0, d)^T

with the right-handed rotations :math:`R_x(\varepsilon) = \begin{pmatrix} 1 & 0 & 0
\\ 0 & \cos\varepsilon & -\sin\varepsilon \\ 0 & \sin\varepsilon & \cos\varepsilon
\end{pmatrix}` and :math:`R_y(\psi) = \begin{pmatrix} \cos\psi & 0 & \sin\psi \\ 0 & 1
& 0 \\ -\sin\psi & 0 & \cos\psi \end{pmatrix}`. At :math:`\psi = \varepsilon = 0`
the figure faces the camera, upright (its left is the image's right); a joint a height
:math:`h` above the root lands at :math:`(0, -h\cos\varepsilon, d - h\sin\varepsilon)`
(nearer to a raised camera); a joint a distance :math:`a` in front of the root at
:math:`(a\sin\psi, 0, d - a\cos\psi)` for :math:`\varepsilon = 0`. The camera then
projects through the pinhole ``K``
(:func:`~robopercept.nn.pose.data.project_points`; default the identity, normalized
image coordinates :math:`(X/Z, Y/Z)`).

2-D normalization
-----------------
:func:`normalize_pose2d` removes translation and scale: with centre :math:`c` (the
root joint, or the mean of the joints) and :math:`s = \sqrt{\frac{1}{J}\sum_j
\lVert p_j - c\rVert^2}` (the RMS distance to the centre), :math:`\hat p_j = (p_j - c)
/ s`. With joints missing (``visible``), the sums run over the visible joints only, and
the centre is their mean when the root is missing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    as_rng,
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    plain_repr,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.pose.data import project_points
from robopercept.nn.skeleton import MPII_16

__all__ = [
    "CENTERS",
    "DEFAULT_ELEVATION",
    "PELVIS",
    "PoseViews",
    "check_keypoints2d",
    "check_poses3d",
    "check_root",
    "check_scales",
    "check_seed",
    "normalize_joints",
    "normalize_pose2d",
    "random_views",
    "visibility_mask",
]

#: the root joint of :data:`~robopercept.nn.skeleton.MPII_16` (the pelvis)
PELVIS = MPII_16.index("pelvis")
#: the centres of :func:`normalize_pose2d`
CENTERS = ("root", "mean")
#: the largest coordinate magnitude accepted (squares stay finite in float64)
_LIMIT = 1e150


# ============================================================================== checks


def check_root(root: Any, num_joints: int, name: str = "root") -> int:
    """The index of a root joint among ``num_joints``, or InputError.

    Parameters
    ----------
    root : int
    num_joints : int
    name : str
        The argument's name in the error.

    Returns
    -------
    int

    Examples
    --------
    >>> check_root(PELVIS, 16)
    6
    """
    r = check_int(root, name, 0)
    if r >= num_joints:
        raise InputError(
            f"{name} must index a joint, 0..{num_joints - 1}; got {r} (the pelvis of "
            f"MPII_16 is {PELVIS})"
        )
    return r


def check_seed(value: Any, name: str) -> int | None:
    """A seed for torch or NumPy: None, or an int in ``[0, 2**63)``.

    Parameters
    ----------
    value : int or None
    name : str
        The argument's name in the error.

    Returns
    -------
    int or None

    Examples
    --------
    >>> check_seed(7, "rng")
    7
    """
    if value is None:
        return None
    seed = check_int(value, name, 0)
    if seed >= 2**63:
        raise InputError(f"{name} must be below 2**63; got {seed}")
    return seed


# ============================================================================ 2-D poses


def check_keypoints2d(value: Any, name: str = "keypoints2d") -> tuple[np.ndarray, bool]:
    """2-D poses as float64 ``(M, J, 2)`` and whether a single ``(J, 2)`` pose came
    (NaN allowed: the caller decides; magnitudes checked).

    Parameters
    ----------
    value : (J, 2) or (M, J, 2) array_like
    name : str
        The argument's name in the error.

    Returns
    -------
    keypoints : (M, J, 2) float64 ndarray
    single : bool

    Examples
    --------
    >>> kp, single = check_keypoints2d([[0.0, 1.0], [2.0, 3.0]])
    >>> kp.shape, single
    ((1, 2, 2), True)
    """
    a = check_numeric(value, name)
    if a.ndim not in (2, 3) or a.shape[-1] != 2 or a.shape[-2] < 1:
        hint = ""
        if a.ndim in (2, 3) and a.shape[-1] == 3:
            hint = f": (x, y, v) keypoints? pass {name}[..., :2] and visible={name}[..., 2] > 0"
        raise InputError(f"{name} must be (J, 2) or (M, J, 2) image joints; got {a.shape}{hint}")
    check_magnitude(a, name, _LIMIT)
    if a.ndim == 2:
        return a[None], True
    return a, False


def visibility_mask(
    visible: Any, kp: np.ndarray, single: bool, name: str = "keypoints2d"
) -> np.ndarray:
    """The ``(M, J)`` visibility mask of poses ``kp`` (nonzero = visible; all visible
    when ``visible`` is None); NaN/inf coordinates are refused where visible.

    Parameters
    ----------
    visible : (J,) or (M, J) array_like or None
        ``(J,)`` when ``single``.
    kp : (M, J, 2) ndarray
        From :func:`check_keypoints2d`.
    single : bool
    name : str
        The poses' argument name in the error.

    Returns
    -------
    (M, J) bool ndarray

    Examples
    --------
    >>> visibility_mask([1, 0], np.zeros((1, 2, 2)), True).tolist()
    [[True, False]]
    """
    if visible is None:
        mask = np.ones(kp.shape[:2], bool)
    else:
        v = check_numeric(visible, "visible")
        want = kp.shape[1:2] if single else kp.shape[:2]
        if v.shape != want:
            raise InputError(f"visible must be one flag per joint, shape {want}; got {v.shape}")
        if not np.isfinite(v).all():
            raise InputError("visible must be finite flags (nonzero = visible); got NaN/inf")
        mask = (v != 0).reshape(kp.shape[:2])
    bad = mask & ~np.isfinite(kp).all(-1)
    if bad.any():
        raise InputError(
            f"{name} has NaN/inf at {int(bad.sum())} visible joint(s): mark missing joints "
            f"with visible=np.isfinite({name}).all(-1)"
        )
    return mask


def normalize_joints(
    kp: np.ndarray, mask: np.ndarray | None, center: str, root: int
) -> tuple[np.ndarray, np.ndarray]:
    r"""The unchecked arithmetic of :func:`normalize_pose2d`: normalized joints
    ``(M, J, 2)`` (0 where masked) and the scales ``(M,)`` (0 marks a degenerate pose).

    Parameters
    ----------
    kp : (M, J, 2) float64 ndarray
        Finite where ``mask`` is set.
    mask : (M, J) bool ndarray or None
        None: every joint visible.
    center : {"root", "mean"}
    root : int

    Returns
    -------
    normalized : (M, J, 2) ndarray
    scales : (M,) ndarray

    Examples
    --------
    >>> out, s = normalize_joints(np.array([[[0.0, 0.0], [2.0, 0.0]]]), None, "mean", 0)
    >>> out.tolist(), s.tolist()
    ([[[-1.0, 0.0], [1.0, 0.0]]], [1.0])
    """
    if mask is None:
        c = kp[:, root] if center == "root" else kp.mean(1)
        d = kp - c[:, None]
        s = np.sqrt((d**2).sum(-1).mean(-1))
        big = np.abs(kp).max((1, 2))
    else:
        m = mask[..., None]
        n = np.maximum(mask.sum(1), 1)
        z = np.where(m, kp, 0.0)
        mean = z.sum(1) / n[:, None]
        use_root = mask[:, root] if center == "root" else np.zeros(len(kp), bool)
        c = np.where(use_root[:, None], z[:, root], mean)
        d = np.where(m, kp - c[:, None], 0.0)
        s = np.sqrt((d**2).sum((1, 2)) / n)
        s = np.where(mask.sum(1) >= 2, s, 0.0)
        big = np.abs(z).max((1, 2))
    s = np.where(s > 1e-12 * np.maximum(big, 1e-300), s, 0.0)
    return d / np.where(s > 0, s, 1.0)[:, None, None], s


def check_scales(scales: np.ndarray, name: str) -> None:
    """Refuse the poses whose :func:`normalize_joints` scale is 0.

    Parameters
    ----------
    scales : (M,) ndarray
    name : str
        What the poses are, for the error (``"pose(s)"``).

    Raises
    ------
    DegenerateError
        Naming the first (up to 8) degenerate poses.
    """
    bad = np.flatnonzero(scales == 0)
    if bad.size:
        raise DegenerateError(
            f"{name} {bad[:8].tolist()} cannot be normalized: fewer than 2 visible joints, "
            "or all visible joints at one point; drop those poses"
        )


def normalize_pose2d(
    keypoints2d: npt.ArrayLike,
    visible: npt.ArrayLike | None = None,
    *,
    center: str = "root",
    root: int = PELVIS,
) -> np.ndarray:
    r"""Translation- and scale-free 2-D poses: :math:`\hat p_j = (p_j - c) / s`.

    :math:`c` is the root joint (``center="root"``) or the mean of the joints
    (``"mean"``), and :math:`s = \sqrt{\frac{1}{J}\sum_j \lVert p_j - c\rVert^2}` the
    RMS distance to it. With ``visible``, both run over the visible joints only (the
    centre is their mean where the root is not visible); the missing joints come out
    as NaN.

    Parameters
    ----------
    keypoints2d : (J, 2) or (M, J, 2) array_like
        Image joints (pixels or any unit).
    visible : (J,) or (M, J) array_like, optional
        Nonzero where the joint is known; default all. Missing joints may hold NaN.
    center : {"root", "mean"}
    root : int
        The root joint (6, the pelvis, for :data:`~robopercept.nn.skeleton.MPII_16`).

    Returns
    -------
    ndarray, the shape of ``keypoints2d``

    Raises
    ------
    InputError
        Wrong shapes, NaN/inf at a visible joint, a bad ``center`` or ``root``.
    DegenerateError
        A pose with fewer than 2 visible joints, or with all of them at one point.

    Examples
    --------
    >>> p = normalize_pose2d([[10.0, 10.0], [12.0, 10.0], [10.0, 14.0]], center="root", root=0)
    >>> np.round(p * np.sqrt(20 / 3), 6).tolist()
    [[0.0, 0.0], [2.0, 0.0], [0.0, 4.0]]
    """
    kp, single = check_keypoints2d(keypoints2d)
    center = check_choice(center, "center", CENTERS)
    root = check_root(root, kp.shape[1])
    mask = visibility_mask(visible, kp, single)
    full = bool(mask.all())
    out, s = normalize_joints(
        np.where(mask[..., None], kp, 0.0), None if full else mask, center, root
    )
    check_scales(s, "pose(s)")
    out = np.where(mask[..., None], out, np.nan)
    return out[0] if single else out


# ============================================================================== views


@dataclass(frozen=True)
class PoseViews:
    """Poses seen from random cameras (:func:`random_views`).

    Attributes
    ----------
    keypoints2d : (M, J, 2) ndarray
        The projections through the camera matrix.
    joints3d : (M, J, 3) ndarray
        The joints in the camera frame (metres; the root at ``(0, 0, distance)``).
    pose_index : (M,) int64 ndarray
        The library pose each view shows (views of a pose are consecutive).
    yaw, elevation, distance : (M,) ndarray
        The view: the figure's turn about its vertical and the camera's elevation
        (radians), the camera's distance to the root.
    """

    keypoints2d: np.ndarray
    joints3d: np.ndarray
    pose_index: np.ndarray
    yaw: np.ndarray
    elevation: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.keypoints2d)

    def rooted(self, root: int = PELVIS) -> np.ndarray:
        """The camera-frame joints relative to the root, ``(M, J, 3)``.

        Examples
        --------
        >>> v = random_views([[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]], rng=0, root=0)
        >>> v.rooted(0)[0, 0].tolist()
        [0.0, 0.0, 0.0]
        """
        r = check_root(root, self.joints3d.shape[1])
        return self.joints3d - self.joints3d[:, r : r + 1]


def check_poses3d(value: Any, name: str = "poses3d") -> np.ndarray:
    """3-D poses as a finite float64 ``(N, J, 3)`` array (at least one pose of one
    joint), or InputError.

    Parameters
    ----------
    value : (N, J, 3) array_like
    name : str
        The argument's name in the error.

    Returns
    -------
    (N, J, 3) float64 ndarray

    Examples
    --------
    >>> check_poses3d(np.zeros((1, 2, 3))).shape
    (1, 2, 3)
    """
    a = check_numeric(value, name)
    if a.ndim == 2 and a.shape[-1] == 3:
        raise InputError(f"{name} must be (N, J, 3); got {a.shape}: one pose? use {name}[None]")
    if a.ndim != 3 or a.shape[-1] != 3:
        raise InputError(f"{name} must be (N, J, 3) 3-D poses; got shape {a.shape}")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise InputError(f"{name} is empty (shape {a.shape}): give at least one pose of 1+ joints")
    if not np.isfinite(a).all():
        raise InputError(
            f"{name} must be finite; got NaN/inf: keep the complete poses, "
            f"{name}[np.isfinite({name}).all((1, 2))]"
        )
    return check_magnitude(a, name, 1e6)


def _range(value: Any, name: str, low: float, high: float) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in value)
        ok = not any(isinstance(v, (bool, np.bool_, str)) for v in value)
    except (TypeError, ValueError):
        ok = False
    if not ok or not (math.isfinite(a) and math.isfinite(b) and low <= a <= b <= high):
        raise InputError(
            f"{name} must be (low, high) with {low:g} <= low <= high <= {high:g}; "
            f"got {plain_repr(value)}"
        )
    return a, b


def _rotations(yaw: np.ndarray, elev: np.ndarray) -> np.ndarray:
    """R_cam_fig (M, 3, 3) = R_x(elev) diag(1, -1, -1) R_y(yaw)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    ce, se = np.cos(elev), np.sin(elev)
    o, z = np.ones_like(yaw), np.zeros_like(yaw)
    ry = np.stack(
        [np.stack([cy, z, sy], -1), np.stack([z, o, z], -1), np.stack([-sy, z, cy], -1)], -2
    )
    rx = np.stack(
        [np.stack([o, z, z], -1), np.stack([z, ce, -se], -1), np.stack([z, se, ce], -1)], -2
    )
    return rx @ (np.array([1.0, -1.0, -1.0])[:, None] * ry)


#: the camera elevations of :func:`random_views` (radians): -10 to 30 degrees
DEFAULT_ELEVATION = (math.radians(-10.0), math.radians(30.0))


def random_views(
    poses3d: npt.ArrayLike,
    views_per_pose: int = 1,
    rng: int | np.random.Generator | None = None,
    *,
    elevation: tuple[float, float] = DEFAULT_ELEVATION,
    distance: tuple[float, float] = (3.0, 6.0),
    camera_matrix: npt.ArrayLike | None = None,
    root: int = PELVIS,
) -> PoseViews:
    r"""Project each 3-D pose from ``views_per_pose`` random cameras.

    See the module docstring for the camera: yaw :math:`U(-\pi, \pi)`, elevation
    :math:`U(\text{elevation})`, distance :math:`U(\text{distance})`, the camera looking
    at the root joint; points through
    :func:`~robopercept.nn.pose.data.project_points`.

    Parameters
    ----------
    poses3d : (N, J, 3) array_like
        Poses in their own frame (x left, y up, z facing; metres), e.g.
        :func:`~robopercept.nn.pose.data.random_poses_3d`.
    views_per_pose : int
        Views of each pose (>= 1).
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same views.
    elevation : (float, float)
        Range of the camera's elevation, radians, within [-pi/2, pi/2]; default -10 to
        30 degrees (as :func:`~robopercept.nn.pose.data.procedural_pose_set`).
    distance : (float, float)
        Range of the camera's distance to the root (metres, > 0); every joint must end
        up in front of the camera.
    camera_matrix : (3, 3) array_like, optional
        ``K``; default the identity (normalized image coordinates).
    root : int
        The joint the camera looks at.

    Returns
    -------
    PoseViews
        ``N * views_per_pose`` views, the views of each pose consecutive.

    Raises
    ------
    InputError
        Bad shapes or ranges, NaN poses, a camera so close that a joint lies behind it
        (poses in millimetres? convert to metres), too many views.

    Examples
    --------
    >>> from robopercept.nn.pose.data import random_poses_3d
    >>> v = random_views(random_poses_3d(2, rng=0), 3, rng=0)
    >>> v.keypoints2d.shape, v.joints3d.shape, v.pose_index.tolist()
    ((6, 16, 2), (6, 16, 3), [0, 0, 0, 1, 1, 1])
    """
    poses = check_poses3d(poses3d)
    n, j = poses.shape[:2]
    views = check_int(views_per_pose, "views_per_pose", 1)
    m = n * views
    check_allocation(m * j * 18, 8, f"{m} views of {j} joints", "lower views_per_pose")
    lo_e, hi_e = _range(elevation, "elevation (radians)", -math.pi / 2, math.pi / 2)
    lo_d, hi_d = _range(distance, "distance", 1e-6, 1e6)
    root = check_root(root, j)
    if camera_matrix is None:
        k = np.eye(3)
    else:
        k = check_numeric(camera_matrix, "camera_matrix")
        if k.shape != (3, 3) or not np.isfinite(k).all() or not np.array_equal(k[2], [0, 0, 1]):
            raise InputError(
                "camera_matrix must be a finite (3, 3) K = [[fx, s, cx], [0, fy, cy], "
                f"[0, 0, 1]]; got {plain_repr(k) if k.size <= 16 else k.shape}"
            )
    gen = as_rng(rng)
    yaw = gen.uniform(-math.pi, math.pi, m)
    elev = gen.uniform(lo_e, hi_e, m)
    dist = gen.uniform(lo_d, hi_d, m)
    index = np.repeat(np.arange(n, dtype=np.int64), views)
    rooted = poses - poses[:, root : root + 1]
    rot = _rotations(yaw, elev)
    cam = np.einsum("mij,mkj->mki", rot, rooted[index])
    cam[..., 2] += dist[:, None]
    if np.any(cam[..., 2] <= 1e-3 * dist[:, None]):
        reach = float(np.linalg.norm(rooted, axis=-1).max())
        raise InputError(
            f"a camera at distance {lo_d:g} puts joints behind it (the poses reach {reach:g} "
            "from the root): raise distance, or give the poses in metres"
        )
    kp = project_points(cam, k)
    return PoseViews(kp, cam, index, yaw, elev, dist)
