r"""3-D human pose from 2-D joints: the metrics (MPJPE, Procrustes-aligned MPJPE), lifting
by matching against a library of projected 3-D poses, and the lifting network of Martinez
et al. (2017).

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

Lifting by matching (the course's recipe)
-----------------------------------------
:class:`PoseLibrary` projects every library pose from ``views_per_pose`` random views,
normalizes each projection and keeps the pairs (normalized 2-D pose, rooted camera-frame
3-D pose). :meth:`PoseLibrary.lift` normalizes a query the same way, finds the nearest
library 2-D pose (Euclidean distance between the flattened ``(2J,)`` vectors,
:class:`scipy.spatial.cKDTree`) and returns its 3-D pose, or the mean of the ``k``
nearest. A query with missing joints is matched on its visible joints only: the library
poses are normalized again over the same joints and searched by brute force.

The lifting network
-------------------
:class:`LiftingMLP` is the baseline of Martinez, Hossain, Romero and Little (2017), "A
simple yet effective baseline for 3d human pose estimation" (ICCV): the normalized 2-D
joints, standardized per coordinate, pass through ``Linear(2J, w)``, BatchNorm, ReLU and
dropout, then ``blocks`` residual blocks :math:`x + f_2(f_1(x))` with :math:`f_i` =
Linear, BatchNorm1d, ReLU, Dropout, then ``Linear(w, 3J)``; the output is the
standardized rooted 3-D pose. :func:`train_lifter` fits it with Adam on the mean squared
error of the standardized coordinates; the standardization statistics are buffers of
the model, so :meth:`LiftingMLP.lift` is self-contained. Deviations from the paper:
width 256 (1024 there), dropout 0.2 (0.5), no max-norm constraint on the weights, no
learning-rate decay, short training (a few epochs on tens of thousands of pairs instead
of 200 epochs on Human3.6M).

Metrics
-------
MPJPE is the mean Euclidean distance between corresponding joints, PA-MPJPE the same
after the similarity transform (scale, rotation, translation) that best aligns the
prediction to the truth, found in closed form (:func:`procrustes_align`, Umeyama 1991);
the rotation is proper (:math:`\det R = +1`), so a mirrored prediction is not forgiven.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from scipy.spatial import cKDTree
from torch import nn

from robopercept._checks import (
    as_rng,
    check_bool,
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.nn._guards import MAX_LAYERS, check_allocation, check_count
from robopercept.nn.pose.data import project_points, random_poses_3d
from robopercept.nn.skeleton import MPII_16, Skeleton
from robopercept.nn.train.loop import deterministic_algorithms

__all__ = [
    "PELVIS",
    "LiftingMLP",
    "PoseLibrary",
    "PoseViews",
    "SimilarityTransform",
    "default_pose_library",
    "mpjpe",
    "normalize_pose2d",
    "pa_mpjpe",
    "procrustes_align",
    "random_views",
    "train_lifter",
]

#: the root joint of :data:`~robopercept.nn.skeleton.MPII_16` (the pelvis)
PELVIS = MPII_16.index("pelvis")
#: the most epochs :func:`train_lifter` runs
MAX_EPOCHS = 100_000
#: the largest coordinate magnitude accepted (squares stay finite in float64)
_LIMIT = 1e150
_CENTERS = ("root", "mean")


# =============================================================================== metrics


@dataclass(frozen=True)
class SimilarityTransform:
    r"""A similarity transform :math:`x \mapsto c R x + t` per sample.

    Attributes
    ----------
    scale : float or (N,) ndarray
        :math:`c \ge 0`.
    rotation : (D, D) or (N, D, D) ndarray
        :math:`R`, proper (:math:`\det R = +1`).
    translation : (D,) or (N, D) ndarray
        :math:`t`.
    """

    scale: float | np.ndarray
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: npt.ArrayLike) -> np.ndarray:
        r"""Map points: :math:`c R x + t` (per sample for a batch).

        Parameters
        ----------
        points : (J, D) or (N, J, D) array_like

        Returns
        -------
        ndarray
            Same shape as ``points``.

        Examples
        --------
        >>> t = SimilarityTransform(2.0, np.eye(2), np.array([1.0, 0.0]))
        >>> t.apply([[1.0, 1.0]]).tolist()
        [[3.0, 2.0]]
        """
        p = check_numeric(points, "points")
        r = np.asarray(self.rotation, dtype=np.float64)
        if p.ndim != r.ndim or p.shape[-1] != r.shape[-1]:
            raise InputError(
                f"points must be (J, {r.shape[-1]}) (or (N, J, {r.shape[-1]}) for a batch of "
                f"transforms); got shape {p.shape}"
            )
        c = np.asarray(self.scale, dtype=np.float64)
        t = np.asarray(self.translation, dtype=np.float64)
        return c[..., None, None] * (p @ np.swapaxes(r, -1, -2)) + t[..., None, :]


def _pair(pred: Any, truth: Any) -> tuple[np.ndarray, np.ndarray]:
    """Both pose arrays as float64 ``(N, J, D)`` (a single pose gets N = 1), checked."""
    arrays = []
    for name, value in (("pred", pred), ("truth", truth)):
        a = check_numeric(value, name)
        if a.ndim not in (2, 3) or a.shape[-1] < 1 or a.shape[-2] < 1:
            raise InputError(
                f"{name} must be (J, D) or (N, J, D) joint positions; got shape {a.shape}"
            )
        if not np.isfinite(a).all():
            raise InputError(
                f"{name} must be finite; got {int(a.size - np.isfinite(a).sum())} NaN/inf "
                "value(s): drop the poses or joints that have them"
            )
        arrays.append(check_magnitude(a, name, _LIMIT))
    p, t = arrays
    if p.shape != t.shape:
        raise InputError(f"pred and truth must have the same shape; got {p.shape} and {t.shape}")
    if p.ndim == 2:
        return p[None], t[None]
    return p, t


def _umeyama(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scale (N,), rotation (N, D, D), translation (N, D) taking x to y (both (N, J, D))."""
    mx, my = x.mean(1), y.mean(1)
    x0, y0 = x - mx[:, None], y - my[:, None]
    var_x = (x0**2).sum((1, 2)) / x.shape[1]
    cov = np.einsum("nji,njk->nik", y0, x0) / x.shape[1]  # Sigma_xy = E[(y - my)(x - mx)^T]
    u, d, vt = np.linalg.svd(cov)
    sign = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    sign[sign == 0] = 1.0
    s = np.ones_like(d)
    s[:, -1] = sign
    rot = (u * s[:, None, :]) @ vt
    trace = (d * s).sum(1)
    ok = var_x > 0
    scale = np.where(ok, trace / np.where(ok, var_x, 1.0), 0.0)
    trans = my - scale[:, None] * np.einsum("nij,nj->ni", rot, mx)
    return scale, rot, trans


def procrustes_align(
    pred: npt.ArrayLike, truth: npt.ArrayLike, *, return_transform: bool = False
) -> np.ndarray | tuple[np.ndarray, SimilarityTransform]:
    r"""Align ``pred`` to ``truth`` by the least-squares similarity transform.

    Per sample, the scale :math:`c`, proper rotation :math:`R` (:math:`\det R = +1`) and
    translation :math:`t` minimizing :math:`\sum_j \lVert y_j - (c R x_j + t)\rVert^2`
    (Umeyama 1991, "Least-squares estimation of transformation parameters between two
    point patterns"): with :math:`\mu_x, \mu_y` the centroids, :math:`\sigma_x^2 =
    \frac{1}{J}\sum_j \lVert x_j - \mu_x\rVert^2`, :math:`\Sigma = \frac{1}{J}\sum_j
    (y_j - \mu_y)(x_j - \mu_x)^T = U D V^T` and :math:`S = \mathrm{diag}(1, \dots, 1,
    \det U \det V)`,

    .. math::

        R = U S V^T, \quad c = \mathrm{tr}(D S) / \sigma_x^2, \quad
        t = \mu_y - c R \mu_x.

    :math:`S` flips the last singular direction when the best orthogonal matrix would
    be a reflection, so a mirrored prediction keeps an error. A prediction whose joints
    all coincide (:math:`\sigma_x = 0`) is mapped to the truth's centroid
    (:math:`c = 0`, the least-squares answer). The residual matches
    :func:`scipy.spatial.procrustes`' disparity (which standardizes both sets and allows
    reflections) when no reflection is involved: ``sum |aligned - truth|^2 / sum |truth
    - mean|^2`` equals it.

    Parameters
    ----------
    pred, truth : (J, D) or (N, J, D) array_like
        Predicted and true joints (any dimension D: 3 for poses, 2 for image joints).
    return_transform : bool
        Also return the :class:`SimilarityTransform`.

    Returns
    -------
    aligned : ndarray, the shape of ``pred``
        :math:`c R x_j + t`.
    transform : SimilarityTransform
        Only with ``return_transform``.

    Raises
    ------
    InputError
        Not ``(J, D)`` / ``(N, J, D)``, different shapes, NaN or infinite values.

    Examples
    --------
    >>> truth = np.array([[0.0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    >>> rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 degrees about z
    >>> pred = 0.5 * truth @ rz.T + [1.0, 2.0, 3.0]
    >>> aligned, tr = procrustes_align(pred, truth, return_transform=True)
    >>> bool(np.allclose(aligned, truth)), round(float(tr.scale), 6)
    (True, 2.0)
    """
    return_transform = check_bool(return_transform, "return_transform")
    single = np.ndim(pred) == 2
    x, y = _pair(pred, truth)
    scale, rot, trans = _umeyama(x, y)
    aligned = scale[:, None, None] * (x @ np.swapaxes(rot, 1, 2)) + trans[:, None]
    if single:
        aligned = aligned[0]
    if not return_transform:
        return aligned
    if single:
        return aligned, SimilarityTransform(float(scale[0]), rot[0], trans[0])
    return aligned, SimilarityTransform(scale, rot, trans)


def _check_root(root: Any, num_joints: int, name: str = "root") -> int:
    r = check_int(root, name, 0)
    if r >= num_joints:
        raise InputError(
            f"{name} must index a joint, 0..{num_joints - 1}; got {r} (the pelvis of "
            f"MPII_16 is {PELVIS})"
        )
    return r


def mpjpe(
    pred: npt.ArrayLike,
    truth: npt.ArrayLike,
    *,
    root: int | None = None,
    per_sample: bool = False,
) -> float | np.ndarray:
    r"""Mean per-joint position error: :math:`\frac{1}{NJ}\sum_{n,j} \lVert \hat
    P_{nj} - P_{nj}\rVert` (in the units of the input; Human3.6M's protocol 1 when
    both are rooted, ``root``).

    Parameters
    ----------
    pred, truth : (J, D) or (N, J, D) array_like
    root : int, optional
        Subtract this joint from each pose of both first (root-relative error).
    per_sample : bool
        Return the mean over the joints of each pose, ``(N,)``, instead of the overall
        mean (a single pose gives a float either way).

    Returns
    -------
    float or (N,) ndarray

    Raises
    ------
    InputError
        Not ``(J, D)`` / ``(N, J, D)``, different shapes, NaN or infinite values, a
        ``root`` outside the joints.

    Examples
    --------
    >>> mpjpe([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0.0, 0.0, 1.0], [1.0, 3.0, 4.0]])
    3.0
    >>> mpjpe([[[0.0, 0.0], [1.0, 1.0]]], [[[1.0, 0.0], [2.0, 1.0]]], root=0)
    0.0
    """
    per_sample = check_bool(per_sample, "per_sample")
    single = np.ndim(pred) == 2
    x, y = _pair(pred, truth)
    if root is not None:
        r = _check_root(root, x.shape[1])
        x = x - x[:, r : r + 1]
        y = y - y[:, r : r + 1]
    err = np.linalg.norm(x - y, axis=-1).mean(-1)
    if per_sample and not single:
        return err
    return float(err.mean())


def pa_mpjpe(
    pred: npt.ArrayLike, truth: npt.ArrayLike, *, per_sample: bool = False
) -> float | np.ndarray:
    r"""Procrustes-aligned MPJPE (Human3.6M's protocol 2): :func:`mpjpe` of each
    prediction after :func:`procrustes_align` to its truth (scale, proper rotation and
    translation removed, per sample).

    Parameters
    ----------
    pred, truth : (J, D) or (N, J, D) array_like
    per_sample : bool
        Return ``(N,)`` per-pose errors instead of the mean.

    Returns
    -------
    float or (N,) ndarray

    Raises
    ------
    InputError
        As :func:`procrustes_align`.

    Examples
    --------
    >>> truth = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> round(pa_mpjpe(3 * truth + 5, truth), 12)
    0.0
    """
    per_sample = check_bool(per_sample, "per_sample")
    aligned = procrustes_align(pred, truth)
    assert isinstance(aligned, np.ndarray)  # without return_transform
    return mpjpe(aligned, truth, per_sample=per_sample)


# ============================================================================ 2-D poses


def _keypoints(value: Any, name: str = "keypoints2d") -> tuple[np.ndarray, bool]:
    """``value`` as float64 ``(M, J, 2)`` (NaN allowed: the caller decides) and whether
    it was a single ``(J, 2)`` pose."""
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


def _visible(visible: Any, kp: np.ndarray, single: bool, name: str = "keypoints2d") -> np.ndarray:
    """The (M, J) visibility mask (nonzero = visible); NaN/inf refused where visible."""
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


def _normalize(
    kp: np.ndarray, mask: np.ndarray | None, center: str, root: int
) -> tuple[np.ndarray, np.ndarray]:
    """Normalized joints (M, J, 2) (0 where masked) and the scales (M,) (0: degenerate)."""
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


def _degenerate(scales: np.ndarray, name: str) -> None:
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
    kp, single = _keypoints(keypoints2d)
    center = check_choice(center, "center", _CENTERS)
    root = _check_root(root, kp.shape[1])
    mask = _visible(visible, kp, single)
    full = bool(mask.all())
    out, s = _normalize(np.where(mask[..., None], kp, 0.0), None if full else mask, center, root)
    _degenerate(s, "pose(s)")
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
        r = _check_root(root, self.joints3d.shape[1])
        return self.joints3d - self.joints3d[:, r : r + 1]


def _poses3d(value: Any, name: str = "poses3d") -> np.ndarray:
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


_DEFAULT_ELEVATION = (math.radians(-10.0), math.radians(30.0))


def random_views(
    poses3d: npt.ArrayLike,
    views_per_pose: int = 1,
    rng: int | np.random.Generator | None = None,
    *,
    elevation: tuple[float, float] = _DEFAULT_ELEVATION,
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
    poses = _poses3d(poses3d)
    n, j = poses.shape[:2]
    views = check_int(views_per_pose, "views_per_pose", 1)
    m = n * views
    check_allocation(m * j * 18, 8, f"{m} views of {j} joints", "lower views_per_pose")
    lo_e, hi_e = _range(elevation, "elevation (radians)", -math.pi / 2, math.pi / 2)
    lo_d, hi_d = _range(distance, "distance", 1e-6, 1e6)
    root = _check_root(root, j)
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


# ============================================================================ matching


class PoseLibrary:
    r"""Lift 2-D poses to 3-D by matching against a library of projected 3-D poses.

    The library holds, for every pose of ``poses3d`` seen from ``views_per_pose``
    random views (:func:`random_views`), the pair (normalized 2-D projection,
    :func:`normalize_pose2d`; the 3-D pose in that camera's frame, relative to the
    root). :meth:`lift` returns the 3-D pose of the nearest 2-D pose (or the mean of the
    ``k`` nearest).

    The 3-D output is root-relative (its depth is relative to the root joint, the
    distance to the camera is not recovered) and at the library's scale (metres of the
    library poses, whatever the size of the person in the image).

    Parameters
    ----------
    poses3d : (N, J, 3) array_like
        Library poses in their own frame (x left, y up, z facing; metres).
    views_per_pose : int
        Random views of each pose (>= 1); the library has ``N * views_per_pose``
        entries.
    rng : int, numpy.random.Generator or None
        Seed of the views.
    elevation, distance : (float, float)
        Ranges of the views, as :func:`random_views` (radians, metres).
    center : {"root", "mean"}
        The 2-D normalization's centre.
    root : int
        The root joint (the pelvis, 6, for :data:`~robopercept.nn.skeleton.MPII_16`).
    k : int
        Default number of nearest entries averaged by :meth:`lift`.

    Attributes
    ----------
    keypoints2d : (M, J, 2) ndarray
        Normalized 2-D poses.
    joints3d : (M, J, 3) ndarray
        Their rooted camera-frame 3-D poses.
    pose_index : (M,) ndarray
        The library pose of each entry.

    Raises
    ------
    InputError
        Empty or NaN poses, bad parameters.
    DegenerateError
        A pose whose projection collapses to a point.

    Examples
    --------
    >>> from robopercept.nn.pose.data import random_poses_3d
    >>> lib = PoseLibrary(random_poses_3d(50, rng=0), views_per_pose=4, rng=0)
    >>> len(lib), lib.lift(lib.keypoints2d[:2] * 100 + 7).shape
    (200, (2, 16, 3))
    """

    def __init__(
        self,
        poses3d: npt.ArrayLike,
        *,
        views_per_pose: int = 16,
        rng: int | np.random.Generator | None = 0,
        elevation: tuple[float, float] = _DEFAULT_ELEVATION,
        distance: tuple[float, float] = (3.0, 6.0),
        center: str = "root",
        root: int = PELVIS,
        k: int = 1,
    ) -> None:
        self.center = check_choice(center, "center", _CENTERS)
        self.k = check_int(k, "k", 1)
        views = random_views(
            poses3d, views_per_pose, rng, elevation=elevation, distance=distance, root=root
        )
        self.root = int(root)
        norm, s = _normalize(views.keypoints2d, None, self.center, self.root)
        _degenerate(s, "library views")
        self.keypoints2d = norm
        self.joints3d = views.rooted(self.root)
        self.pose_index = views.pose_index
        if self.k > len(norm):
            raise InputError(f"k must be at most the library size, {len(norm)}; got {self.k}")
        self._tree = cKDTree(norm.reshape(len(norm), -1))

    def __len__(self) -> int:
        return len(self.keypoints2d)

    @property
    def num_joints(self) -> int:
        """J, the joints of each pose."""
        return int(self.keypoints2d.shape[1])

    def lift(
        self,
        keypoints2d: npt.ArrayLike,
        visible: npt.ArrayLike | None = None,
        *,
        k: int | None = None,
    ) -> np.ndarray:
        r"""The 3-D poses of the nearest library 2-D poses.

        Each query is normalized (:func:`normalize_pose2d`, the library's ``center``
        and ``root``) and compared with every library entry by the Euclidean distance
        of the flattened normalized joints; with joints missing, over the visible
        joints only, both sides normalized over them. The ``k`` nearest entries' 3-D
        poses are averaged.

        Parameters
        ----------
        keypoints2d : (J, 2) or (M, J, 2) array_like
            Detected image joints (pixels: translation and scale do not matter).
        visible : (J,) or (M, J) array_like, optional
            Nonzero where the joint was detected; default all. Missing joints may hold
            NaN.
        k : int, optional
            Entries averaged (default the library's ``k``).

        Returns
        -------
        (J, 3) or (M, J, 3) ndarray
            Root-relative joints in the camera frame, at the library's scale (metres).

        Raises
        ------
        InputError
            Wrong joint count or shape, NaN/inf at a visible joint (mark it missing in
            ``visible``), ``k`` beyond the library size.
        DegenerateError
            A query with fewer than 2 visible joints, or all at one point.

        Examples
        --------
        >>> from robopercept.nn.pose.data import random_poses_3d
        >>> lib = PoseLibrary(random_poses_3d(20, rng=1), views_per_pose=2, rng=0)
        >>> q = lib.keypoints2d[5] * 40 + [320, 240]  # an entry, moved and scaled
        >>> bool(np.allclose(lib.lift(q), lib.joints3d[5]))
        True
        """
        kp, single = _keypoints(keypoints2d)
        if kp.shape[1] != self.num_joints:
            raise InputError(
                f"keypoints2d must have the library's {self.num_joints} joints; got "
                f"{kp.shape[1]} (shape {kp.shape})"
            )
        kk = self.k if k is None else check_int(k, "k", 1)
        if kk > len(self):
            raise InputError(f"k must be at most the library size, {len(self)}; got {kk}")
        mask = _visible(visible, kp, single)
        kp = np.where(mask[..., None], kp, 0.0)
        index = np.empty((len(kp), kk), np.int64)
        full = mask.all(1)
        if full.any():
            q, s = _normalize(kp[full], None, self.center, self.root)
            _degenerate(s, "query pose(s)")
            _, idx = self._tree.query(q.reshape(len(q), -1), k=kk)
            index[full] = np.asarray(idx).reshape(len(q), kk)
        rows = np.flatnonzero(~full)
        if rows.size:
            patterns, inverse = np.unique(mask[rows], axis=0, return_inverse=True)
            for p, pattern in enumerate(patterns):
                group = rows[inverse.ravel() == p]
                index[group] = self._masked(kp[group], pattern, kk)
        out = self.joints3d[index].mean(1)
        return out[0] if single else out

    def _masked(self, kp: np.ndarray, pattern: np.ndarray, k: int) -> np.ndarray:
        """Nearest entries (Q, k) over the joints of ``pattern`` (brute force)."""
        qmask = np.broadcast_to(pattern, kp.shape[:2])
        q, s = _normalize(kp, qmask, self.center, self.root)
        _degenerate(s, "query pose(s)")
        lmask = np.broadcast_to(pattern, self.keypoints2d.shape[:2])
        lib, _ = _normalize(self.keypoints2d, lmask, self.center, self.root)
        qv = q[:, pattern].reshape(len(q), -1)
        lv = lib[:, pattern].reshape(len(lib), -1)
        l2 = (lv**2).sum(1)
        out = np.empty((len(qv), k), np.int64)
        step = max(1, 2**22 // len(lv))
        for a in range(0, len(qv), step):
            qa = qv[a : a + step]
            d2 = (qa**2).sum(1)[:, None] + l2[None] - 2.0 * qa @ lv.T
            if k < len(lv):
                cand = np.argpartition(d2, k - 1, axis=1)[:, :k]
            else:
                cand = np.broadcast_to(np.arange(len(lv)), d2.shape)
            dc = np.take_along_axis(d2, cand, 1)
            order = np.lexsort((cand, dc), axis=-1)
            out[a : a + step] = np.take_along_axis(cand, order, 1)[:, :k]
        return out


# ============================================================================ the network


def _as_int_seed(value: Any, name: str) -> int | None:
    if value is None:
        return None
    seed = check_int(value, name, 0)
    if seed >= 2**63:
        raise InputError(f"{name} must be below 2**63; got {seed}")
    return seed


class _Block(nn.Module):
    """Two (Linear, BatchNorm1d, ReLU, Dropout) with a skip: x + f2(f1(x))."""

    def __init__(self, width: int, dropout: float) -> None:
        super().__init__()
        self.body = nn.Sequential(
            nn.Linear(width, width),
            nn.BatchNorm1d(width),
            nn.ReLU(),
            nn.Dropout(dropout),
            nn.Linear(width, width),
            nn.BatchNorm1d(width),
            nn.ReLU(),
            nn.Dropout(dropout),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.body(x)


class LiftingMLP(nn.Module):
    r"""The 2-D-to-3-D lifting network of Martinez et al. (2017).

    ``Linear(2J, width)``, BatchNorm1d, ReLU, Dropout; ``blocks`` residual blocks
    :math:`x + f_2(f_1(x))`, each :math:`f_i` = Linear(width, width), BatchNorm1d,
    ReLU, Dropout; ``Linear(width, 3J)``. :meth:`forward` maps standardized normalized
    2-D joints ``(B, 2J)`` to standardized rooted 3-D joints ``(B, 3J)``;
    :meth:`lift` does the whole way from image joints, with the standardization
    statistics that :func:`train_lifter` stores in the buffers ``input_mean``,
    ``input_std``, ``output_mean``, ``output_std`` (saved with ``state_dict``; before
    training they are 0 and 1).

    The output is root-relative, camera frame, at the training data's scale (see the
    module docstring).

    Parameters
    ----------
    num_joints : int
        J (16 for :data:`~robopercept.nn.skeleton.MPII_16`).
    width : int
        Hidden width (1024 in the paper).
    blocks : int
        Residual blocks (2 in the paper; 0 allowed).
    dropout : float
        Dropout probability in [0, 1) (0.5 in the paper; 0.2 does better in the short
        trainings here: 92 against 109 mm PA-MPJPE after 5 epochs on 20 000 pairs).
    center : {"root", "mean"}
        The 2-D normalization's centre (:func:`normalize_pose2d`).
    root : int
        The root joint.
    random_state : int or None
        Seed of the initial weights (a forked torch generator: the global one is left
        alone); None draws from torch's global generator.

    Examples
    --------
    >>> net = LiftingMLP(16, width=32, blocks=1)
    >>> net(torch.zeros(4, 32)).shape
    torch.Size([4, 48])
    """

    input_mean: torch.Tensor
    input_std: torch.Tensor
    output_mean: torch.Tensor
    output_std: torch.Tensor

    def __init__(
        self,
        num_joints: int = 16,
        width: int = 256,
        blocks: int = 2,
        dropout: float = 0.2,
        *,
        center: str = "root",
        root: int = PELVIS,
        random_state: int | None = 0,
    ) -> None:
        super().__init__()
        self.num_joints = check_count(num_joints, "num_joints", 1, 4096)
        width = check_count(width, "width", 1, 16384)
        blocks = check_count(blocks, "blocks", 0, MAX_LAYERS)
        j = self.num_joints
        params = 5 * j * width + 2 * blocks * width * width
        check_allocation(params, 4, f"a width-{width} network", "lower width or blocks")
        dropout = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        self.center = check_choice(center, "center", _CENTERS)
        self.root = _check_root(root, self.num_joints)
        seed = _as_int_seed(random_state, "random_state")
        with torch.random.fork_rng(devices=[], enabled=seed is not None):
            if seed is not None:
                torch.manual_seed(seed)
            self.stem = nn.Sequential(
                nn.Linear(2 * j, width), nn.BatchNorm1d(width), nn.ReLU(), nn.Dropout(dropout)
            )
            self.blocks = nn.Sequential(*(_Block(width, dropout) for _ in range(blocks)))
            self.head = nn.Linear(width, 3 * j)
        self.register_buffer("input_mean", torch.zeros(2 * j))
        self.register_buffer("input_std", torch.ones(2 * j))
        self.register_buffer("output_mean", torch.zeros(3 * j))
        self.register_buffer("output_std", torch.ones(3 * j))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Standardized 3-D joints ``(B, 3J)`` from standardized 2-D joints ``(B, 2J)``."""
        if not isinstance(x, torch.Tensor) or x.ndim != 2 or x.shape[1] != 2 * self.num_joints:
            got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise InputError(
                f"x must be a (B, {2 * self.num_joints}) tensor of standardized 2-D joints; "
                f"got {got}: for image joints use lift()"
            )
        return self.head(self.blocks(self.stem(x)))

    def _inputs(self, kp: np.ndarray) -> torch.Tensor:
        norm, s = _normalize(kp, None, self.center, self.root)
        _degenerate(s, "pose(s)")
        x = torch.from_numpy(norm.reshape(len(norm), 2 * self.num_joints)).float()
        return (x - self.input_mean.cpu()) / self.input_std.cpu()

    def lift(self, keypoints2d: npt.ArrayLike, *, batch_size: int = 4096) -> np.ndarray:
        """3-D poses from image joints, in eval mode.

        Parameters
        ----------
        keypoints2d : (J, 2) or (M, J, 2) array_like
            Image joints, all visible (translation and scale do not matter).
        batch_size : int
            Poses per forward pass.

        Returns
        -------
        (J, 3) or (M, J, 3) float64 ndarray
            Root-relative joints in the camera frame, at the training data's scale.

        Raises
        ------
        InputError
            Wrong joint count or shape, NaN or infinite joints (the network needs all
            of them: use :class:`PoseLibrary` for incomplete poses).
        DegenerateError
            A pose with all joints at one point.

        Examples
        --------
        >>> net = LiftingMLP(16, width=16, blocks=1)
        >>> net.lift(np.random.default_rng(0).normal(size=(3, 16, 2))).shape
        (3, 16, 3)
        """
        kp, single = _keypoints(keypoints2d)
        if kp.shape[1] != self.num_joints:
            raise InputError(
                f"keypoints2d must have the network's {self.num_joints} joints; got "
                f"{kp.shape[1]} (shape {kp.shape})"
            )
        if not np.isfinite(kp).all():
            raise InputError(
                "keypoints2d must be finite: the network needs every joint; lift incomplete "
                "poses with PoseLibrary(...).lift(keypoints2d, visible=...)"
            )
        bs = check_int(batch_size, "batch_size", 1)
        x = self._inputs(kp)
        was = self.training
        dev = self.input_mean.device
        self.eval()
        try:
            with torch.no_grad():
                y = (
                    torch.cat([self(x[a : a + bs].to(dev)).cpu() for a in range(0, len(x), bs)])
                    if len(x)
                    else torch.zeros(0, 3 * self.num_joints)
                )
        finally:
            self.train(was)
        out = y.double() * self.output_std.cpu().double() + self.output_mean.cpu().double()
        res = out.numpy().reshape(len(kp), self.num_joints, 3)
        res = res - res[:, self.root : self.root + 1]
        return res[0] if single else res


def train_lifter(
    model: LiftingMLP,
    keypoints2d: npt.ArrayLike,
    joints3d: npt.ArrayLike,
    *,
    epochs: int = 10,
    batch_size: int = 256,
    lr: float = 1e-3,
    random_state: int = 0,
    noise: float = 0.0,
    weight_decay: float = 0.0,
) -> np.ndarray:
    r"""Fit a :class:`LiftingMLP` to (2-D, 3-D) pairs: Adam on the mean squared error of
    the standardized rooted 3-D joints.

    The 2-D poses are normalized (:func:`normalize_pose2d`) and both sides standardized
    per coordinate, :math:`(v - \mu) / \sigma` with the training set's mean and standard
    deviation (Martinez et al.; a constant coordinate, as the root's, gets
    :math:`\sigma = 1` on the input side and is predicted as its mean); the statistics
    go into the model's buffers. Each epoch visits the pairs in a random order (a
    ``torch.Generator`` seeded with ``random_state``); with ``noise``, every batch's
    2-D joints get fresh Gaussian noise of that standard deviation (in the units of
    ``keypoints2d``) before the normalization. Dropout and noise draw from torch's
    generator forked and seeded with ``random_state``: the same model, data and seed
    give the same weights (on one thread count), and the global torch state is left
    alone. A final batch of one pair is dropped (BatchNorm needs two).

    Parameters
    ----------
    model : LiftingMLP
        Trained in place (left in eval mode).
    keypoints2d : (N, J, 2) array_like
        Image joints, all visible.
    joints3d : (N, J, 3) array_like
        The matching 3-D joints in the camera frame (rooted here: the root joint is
        subtracted).
    epochs, batch_size : int
    lr : float
        Adam's learning rate.
    random_state : int
    noise : float
        Standard deviation of the 2-D noise augmentation (0: none).
    weight_decay : float
        Adam's L2 penalty.

    Returns
    -------
    (epochs,) ndarray
        The mean training loss of each epoch.

    Raises
    ------
    InputError
        Not a LiftingMLP, wrong shapes or joint counts, NaN values, fewer than 2 pairs,
        bad hyper-parameters, a loss that became NaN (lower ``lr``).
    DegenerateError
        A 2-D pose with all joints at one point.

    Examples
    --------
    >>> from robopercept.nn.pose.data import random_poses_3d
    >>> v = random_views(random_poses_3d(64, rng=0), 2, rng=0)
    >>> net = LiftingMLP(16, width=32, blocks=1)
    >>> losses = train_lifter(net, v.keypoints2d, v.joints3d, epochs=2, batch_size=32)
    >>> losses.shape, net.lift(v.keypoints2d[:3]).shape
    ((2,), (3, 16, 3))
    """
    if not isinstance(model, LiftingMLP):
        raise InputError(
            f"model must be a LiftingMLP (e.g. LiftingMLP(16)); got {type(model).__name__}"
        )
    kp, single = _keypoints(keypoints2d)
    if single:
        raise InputError(f"keypoints2d must be (N, J, 2), many poses; got {kp.shape[1:]}")
    j3 = _poses3d(joints3d, "joints3d")
    j = model.num_joints
    if kp.shape[1] != j or j3.shape[1] != j:
        raise InputError(
            f"keypoints2d and joints3d must have the model's {j} joints; got shapes "
            f"{kp.shape} and {j3.shape}"
        )
    if len(kp) != len(j3):
        raise InputError(
            f"keypoints2d and joints3d must hold the same poses; got {len(kp)} and {len(j3)}"
        )
    if len(kp) < 2:
        raise InputError(f"training needs at least 2 pairs (BatchNorm); got {len(kp)}")
    if not np.isfinite(kp).all():
        raise InputError(
            "keypoints2d must be finite: drop the poses with NaN joints, "
            "keypoints2d[np.isfinite(keypoints2d).all((1, 2))]"
        )
    epochs = check_count(epochs, "epochs", 1, MAX_EPOCHS)
    batch_size = check_int(batch_size, "batch_size", 2)
    lr = check_real(lr, "lr", 0.0, 10.0, low_inclusive=False)
    seed = _as_int_seed(random_state, "random_state")
    if seed is None:
        raise InputError("random_state must be an int seed >= 0; got None")
    noise = check_real(noise, "noise", 0.0, 1e6)
    weight_decay = check_real(weight_decay, "weight_decay", 0.0, 1.0)

    root, n = model.root, len(kp)
    norm, s = _normalize(kp, None, model.center, root)
    _degenerate(s, "training pose(s)")
    x_all = norm.reshape(n, -1)
    y_all = (j3 - j3[:, root : root + 1]).reshape(n, -1)
    in_mean, in_std = x_all.mean(0), x_all.std(0)
    in_std = np.where(in_std > 1e-8, in_std, 1.0)
    out_mean, out_std = y_all.mean(0), y_all.std(0)
    dev = model.input_mean.device
    with torch.no_grad():
        model.input_mean.copy_(torch.from_numpy(in_mean))
        model.input_std.copy_(torch.from_numpy(in_std))
        model.output_mean.copy_(torch.from_numpy(out_mean))
        model.output_std.copy_(torch.from_numpy(out_std))
    raw = torch.from_numpy(kp).float()
    x_clean = torch.from_numpy((x_all - in_mean) / in_std).float()
    y_std = torch.from_numpy((y_all - out_mean) / np.where(out_std > 1e-8, out_std, 1.0)).float()
    in_m = torch.from_numpy(in_mean).float()
    in_s = torch.from_numpy(in_std).float()
    opt = torch.optim.Adam(model.parameters(), lr=lr, weight_decay=weight_decay)
    losses = np.zeros(epochs)
    with torch.random.fork_rng(devices=[]), deterministic_algorithms():
        torch.manual_seed(seed)
        shuffle = torch.Generator().manual_seed(seed)
        model.train()
        for epoch in range(epochs):
            perm = torch.randperm(n, generator=shuffle)
            total, count = 0.0, 0
            for a in range(0, n, batch_size):
                idx = perm[a : a + batch_size]
                if len(idx) < 2:
                    continue
                if noise > 0:
                    xb = _normalize_torch(raw[idx] + noise * torch.randn(len(idx), j, 2), model)
                    xb = (xb - in_m) / in_s
                else:
                    xb = x_clean[idx]
                yb = y_std[idx]
                loss = nn.functional.mse_loss(model(xb.to(dev)), yb.to(dev))
                if not torch.isfinite(loss):
                    raise InputError(
                        f"the loss became {loss.item()} at epoch {epoch + 1}: lower lr ({lr:g})"
                    )
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                total += loss.item() * len(idx)
                count += len(idx)
            losses[epoch] = total / max(count, 1)
    model.eval()
    if not all(bool(torch.isfinite(p).all()) for p in model.parameters()):
        raise InputError(
            f"training diverged (the weights became NaN or infinite): lower lr ({lr:g}) or "
            f"weight_decay ({weight_decay:g})"
        )
    return losses


def _normalize_torch(x: torch.Tensor, model: LiftingMLP) -> torch.Tensor:
    """:func:`normalize_pose2d` of a batch (B, J, 2), flattened to (B, 2J)."""
    c = x[:, model.root] if model.center == "root" else x.mean(1)
    d = x - c[:, None]
    s = d.pow(2).sum(-1).mean(-1).sqrt().clamp_min(1e-12)
    return (d / s[:, None, None]).reshape(len(x), -1)


def default_pose_library(
    skeleton: Skeleton | None = None,
    *,
    poses: int = 2000,
    views_per_pose: int = 16,
    k: int = 5,
    rng: int | None = 0,
) -> PoseLibrary:
    """The library the ``robopercept nn pose --lift3d`` command matches against:
    ``poses`` random poses of the procedural figure
    (:func:`~robopercept.nn.pose.data.random_poses_3d`, seeded) seen from
    ``views_per_pose`` random views, the mean of the ``k`` nearest returned.

    Parameters
    ----------
    skeleton : Skeleton, optional
        The layout of the 2-D poses to lift; it must be
        :data:`~robopercept.nn.skeleton.MPII_16`'s (the figure's).
    poses, views_per_pose, k : int
    rng : int or None

    Raises
    ------
    InputError
        Another layout than MPII's 16 joints.

    Examples
    --------
    >>> lib = default_pose_library(poses=20, views_per_pose=2)
    >>> len(lib), lib.num_joints
    (40, 16)
    """
    if skeleton is not None and (
        not isinstance(skeleton, Skeleton) or skeleton.joints != MPII_16.joints
    ):
        raise InputError(
            "the pose library holds the procedural figure's 3-D poses in MPII's 16-joint "
            f"layout; got {plain_repr(skeleton)}: lift poses of a model trained on MPII's "
            "joints (robopercept nn pose train --data figures)"
        )
    n = check_int(poses, "poses", 1)
    seed = _as_int_seed(rng, "rng")
    return PoseLibrary(random_poses_3d(n, rng=seed), views_per_pose=views_per_pose, rng=seed, k=k)
