r"""3-D human pose from 2-D joints by a network, and how 3-D poses are scored: the
lifting network of Martinez et al. (2017) and its trainer, MPJPE and the
Procrustes-aligned PA-MPJPE.

Poses, views and the 2-D normalization are those of :mod:`robopercept.nn.pose.views`;
lifting by matching is :mod:`robopercept.nn.pose.library`.

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

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
from torch import nn

from robopercept._checks import (
    check_bool,
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
)
from robopercept.errors import InputError
from robopercept.nn._guards import MAX_LAYERS, check_allocation, check_count, check_tensor_dtype
from robopercept.nn.pose.views import (
    CENTERS,
    PELVIS,
    check_keypoints2d,
    check_poses3d,
    check_root,
    check_scales,
    check_seed,
    normalize_joints,
)
from robopercept.nn.train.loop import train_loop

__all__ = [
    "MAX_EPOCHS",
    "LiftingMLP",
    "SimilarityTransform",
    "mpjpe",
    "pa_mpjpe",
    "procrustes_align",
    "train_lifter",
]

#: the most epochs :func:`train_lifter` runs
MAX_EPOCHS = 100_000
#: the largest coordinate magnitude accepted (squares stay finite in float64)
_LIMIT = 1e150


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
        r = check_root(root, x.shape[1])
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
        The 2-D normalization's centre (:func:`~.views.normalize_pose2d`).
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
        self.center = check_choice(center, "center", CENTERS)
        self.root = check_root(root, self.num_joints)
        seed = check_seed(random_state, "random_state")
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
        check_tensor_dtype(x, self)
        return self.head(self.blocks(self.stem(x)))

    def _inputs(self, kp: np.ndarray) -> torch.Tensor:
        norm, s = normalize_joints(kp, None, self.center, self.root)
        check_scales(s, "pose(s)")
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
            of them: use :class:`~robopercept.nn.pose.library.PoseLibrary` for incomplete
            poses).
        DegenerateError
            A pose with all joints at one point.

        Examples
        --------
        >>> net = LiftingMLP(16, width=16, blocks=1)
        >>> net.lift(np.random.default_rng(0).normal(size=(3, 16, 2))).shape
        (3, 16, 3)
        """
        kp, single = check_keypoints2d(keypoints2d)
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

    The 2-D poses are normalized (:func:`~.views.normalize_pose2d`) and both sides standardized
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
    >>> from robopercept.nn.pose.views import random_views
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
    kp, single = check_keypoints2d(keypoints2d)
    if single:
        raise InputError(f"keypoints2d must be (N, J, 2), many poses; got {kp.shape[1:]}")
    j3 = check_poses3d(joints3d, "joints3d")
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
    seed = check_seed(random_state, "random_state")
    if seed is None:
        raise InputError("random_state must be an int seed >= 0; got None")
    noise = check_real(noise, "noise", 0.0, 1e6)
    weight_decay = check_real(weight_decay, "weight_decay", 0.0, 1.0)

    root, n = model.root, len(kp)
    norm, s = normalize_joints(kp, None, model.center, root)
    check_scales(s, "training pose(s)")
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
    sums = [0.0, 0]  # the epoch's loss sum and pair count

    def step(idx: torch.Tensor, epoch: int, b: int) -> torch.Tensor:
        if noise > 0:
            xb = _normalize_torch(raw[idx] + noise * torch.randn(len(idx), j, 2), model)
            xb = (xb - in_m) / in_s
        else:
            xb = x_clean[idx]
        loss = nn.functional.mse_loss(model(xb.to(dev)), y_std[idx].to(dev))
        if bool(torch.isfinite(loss)):
            sums[0] += loss.item() * len(idx)
            sums[1] += len(idx)
        return loss

    def end_epoch(epoch: int, seconds: float) -> None:
        losses[epoch] = sums[0] / max(sums[1], 1)
        sums[:] = [0.0, 0]

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        shuffle = torch.Generator().manual_seed(seed)

        def batches(epoch: int) -> Iterator[torch.Tensor]:
            perm = torch.randperm(n, generator=shuffle)
            for a in range(0, n, batch_size):
                if len(perm[a : a + batch_size]) >= 2:  # BatchNorm needs two
                    yield perm[a : a + batch_size]

        train_loop(
            model, opt, batches, step, epochs=epochs, lr=lr, end_epoch=end_epoch, progress=False
        )
    model.eval()
    if not all(bool(torch.isfinite(p).all()) for p in model.parameters()):
        raise InputError(
            f"training diverged (the weights became NaN or infinite): lower lr ({lr:g}) or "
            f"weight_decay ({weight_decay:g})"
        )
    return losses


def _normalize_torch(x: torch.Tensor, model: LiftingMLP) -> torch.Tensor:
    """:func:`~.views.normalize_pose2d` of a batch (B, J, 2), flattened to (B, 2J)."""
    c = x[:, model.root] if model.center == "root" else x.mean(1)
    d = x - c[:, None]
    s = d.pow(2).sum(-1).mean(-1).sqrt().clamp_min(1e-12)
    return (d / s[:, None, None]).reshape(len(x), -1)
