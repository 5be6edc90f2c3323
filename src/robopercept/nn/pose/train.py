r"""Training pose networks: the augmentation of image batches with their keypoints,
:func:`train_pose` for heatmap networks and DeepPose, :func:`train_refiner` and
:func:`train_cascade` for DeepPose's cascade stages, and :class:`PoseHistory`.

Heatmap networks minimize :func:`~robopercept.nn.ops.heatmaps.heatmap_loss` against
:func:`~robopercept.nn.ops.heatmaps.gaussian_heatmaps` targets; DeepPose the squared
error of the normalized coordinates; a cascade stage the squared error of the
displacement to the truth in window units. All run on the one training loop,
:func:`~robopercept.nn.train.loop.epoch_loop`, and keep the epoch of the best
validation PCK (:func:`~robopercept.nn.pose.metrics.pck`).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn.ops.heatmaps import (
    check_float_tensor,
    check_permutation,
    gaussian_heatmaps,
    heatmap_loss,
)
from robopercept.nn.pose.inference import (
    check_input_size,
    pose_data_arrays,
    predict_keypoints,
    refine_keypoints,
)
from robopercept.nn.pose.metrics import bbox_diagonal, pck
from robopercept.nn.pose.networks import DeepPoseRefiner, crop_patches
from robopercept.nn.skeleton import Skeleton
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.loop import EpochHistory, epoch_loop

__all__ = [
    "PoseHistory",
    "augment_pose_batch",
    "train_cascade",
    "train_pose",
    "train_refiner",
]


# ----------------------------------------------------------------------------- augmentation
def augment_pose_batch(
    images: torch.Tensor,
    keypoints: torch.Tensor,
    flip_permutation: npt.ArrayLike | None,
    generator: torch.Generator,
    *,
    rotation: float = 30.0,
    scale: tuple[float, float] = (0.75, 1.25),
    shift: float = 0.1,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Random flips, rotations, scalings and shifts of images and their keypoints.

    Each image gets the map (pixels, about the image centre :math:`c`)
    :math:`p' = c + s R_\theta (F(p) - c) + t`, with :math:`F` a horizontal flip
    :math:`x \mapsto W - x` (probability 1/2, when ``flip_permutation`` is given; the
    joints then swap sides by the permutation), :math:`\theta \sim U(\pm` ``rotation``
    :math:`)` degrees, :math:`s \sim U(` ``scale`` :math:`)`, :math:`t \sim U(\pm`
    ``shift`` :math:`\cdot (W, H))`. The image is resampled bilinearly (zeros outside);
    keypoints mapped outside the image get ``v = 0``.

    Returns
    -------
    images : (N, C, H, W) tensor
    keypoints : (N, J, 3) tensor
    """
    check_float_tensor(images, "images", 4, "(N, C, H, W)")
    check_float_tensor(keypoints, "keypoints", 3, "(N, J, 3) of (x, y, v)")
    if keypoints.shape[0] != images.shape[0] or keypoints.shape[2] != 3:
        raise InputError(
            f"keypoints must be ({images.shape[0]}, J, 3) for the images; got "
            f"{tuple(keypoints.shape)}"
        )
    if not isinstance(generator, torch.Generator):
        raise InputError(f"generator must be a torch.Generator; got {plain_repr(generator)}")
    rotation = check_real(rotation, "rotation", 0.0, 180.0)
    shift = check_real(shift, "shift", 0.0, 1.0)
    try:
        s_lo, s_hi = (check_real(v, "scale", 0.01, 100.0) for v in scale)
    except (TypeError, ValueError):
        raise InputError(f"scale must be (low, high); got {plain_repr(scale)}") from None
    if s_lo > s_hi:
        raise InputError(f"scale must be (low, high) with low <= high; got {(s_lo, s_hi)}")
    scale = (s_lo, s_hi)
    n, _c, h, w = images.shape
    dt = images.dtype
    u = torch.rand((n, 5), generator=generator, dtype=torch.float64)
    theta = torch.deg2rad((2 * u[:, 0] - 1) * rotation)
    s = scale[0] + (scale[1] - scale[0]) * u[:, 1]
    tx = (2 * u[:, 2] - 1) * shift * w
    ty = (2 * u[:, 3] - 1) * shift * h
    flip = (u[:, 4] < 0.5) if flip_permutation is not None else torch.zeros(n, dtype=torch.bool)
    cx, cy = w / 2.0, h / 2.0
    cos, sin = torch.cos(theta), torch.sin(theta)
    # forward map p' = A p + a
    fx = torch.where(flip, -1.0, 1.0).to(torch.float64)
    a11, a12 = s * cos * fx, -s * sin
    a21, a22 = s * sin * fx, s * cos
    x0 = torch.where(flip, w - cx, -cx).to(torch.float64)  # F(p) - c, x part offset
    a1 = s * (cos * x0 - sin * (-cy)) + cx + tx
    a2 = s * (sin * x0 + cos * (-cy)) + cy + ty
    kp = keypoints.clone().to(torch.float64)
    if flip_permutation is not None:
        perm = torch.as_tensor(check_permutation(flip_permutation, int(kp.shape[1])))
        kp[flip] = kp[flip][:, perm]
    x, y = kp[..., 0], kp[..., 1]
    nx = a11[:, None] * x + a12[:, None] * y + a1[:, None]
    ny = a21[:, None] * x + a22[:, None] * y + a2[:, None]
    inside = (nx >= 0) & (nx < w) & (ny >= 0) & (ny < h)
    kp[..., 0], kp[..., 1] = nx, ny
    kp[..., 2] = torch.where(inside, kp[..., 2], torch.zeros_like(kp[..., 2]))
    # inverse map for sampling, in normalized coordinates n = D p - 1, D = diag(2/W, 2/H)
    det = a11 * a22 - a12 * a21
    b11, b12, b21, b22 = a22 / det, -a12 / det, -a21 / det, a11 / det
    b1 = -(b11 * a1 + b12 * a2)
    b2 = -(b21 * a1 + b22 * a2)
    dx, dy = 2.0 / w, 2.0 / h
    m = torch.zeros((n, 2, 3), dtype=torch.float64)
    m[:, 0, 0], m[:, 0, 1] = b11, b12 * dx / dy
    m[:, 1, 0], m[:, 1, 1] = b21 * dy / dx, b22
    m[:, 0, 2] = dx * (b11 / dx + b12 / dy + b1) - 1
    m[:, 1, 2] = dy * (b21 / dx + b22 / dy + b2) - 1
    grid = F.affine_grid(m.to(dt), list(images.shape), align_corners=False)
    out = F.grid_sample(images, grid, mode="bilinear", align_corners=False)
    return out, kp.to(keypoints.dtype)


# ----------------------------------------------------------------------------- training
class PoseHistory(EpochHistory):
    """What :func:`train_pose` and :func:`train_refiner` measured: mean training loss
    and seconds per epoch, the validation PCK by epoch, the epoch kept."""

    val_name = "val_pck"


def _pck(pred: np.ndarray, keypoints: np.ndarray, boxes: np.ndarray, alpha: float) -> float:
    return float(pck(pred, keypoints, None, alpha, bbox_diagonal(boxes, "xyxy")).mean)


def train_pose(
    model: nn.Module,
    train: Any,
    config: Any = None,
    *,
    val: Any = None,
    skeleton: Skeleton | None = None,
    sigma: float = 2.0,
    augment: bool = True,
    pck_alpha: float = 0.1,
    progress: bool = True,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
) -> PoseHistory:
    r"""Train a heatmap network or DeepPose on a :class:`~robopercept.nn.pose.data.PoseDataset`.

    Each step takes ``config.batch_size`` images of a seeded shuffle, augmented
    (:func:`augment_pose_batch`, flips only when ``skeleton`` gives the flip pairs).
    Heatmap networks minimize :func:`~robopercept.nn.ops.heatmaps.heatmap_loss` of
    their kind (``model.heatmap``, ``"softmax"`` or ``"mse"``) against
    :func:`~robopercept.nn.ops.heatmaps.gaussian_heatmaps` targets (``sigma`` cells) over
    labelled joints;
    DeepPose minimizes the squared error of the normalized coordinates over labelled
    joints, :math:`\sum w_{nk} \lVert \hat y_{nk} - y_{nk} \rVert^2 / \sum w_{nk}`.
    Optimizer and per-step schedule from
    :func:`~robopercept.nn.train.loop.step_optimizer`. With ``val``, the PCK@``pck_alpha``
    (of the box diagonal) is measured after every epoch and the best epoch's weights
    are kept.

    Parameters
    ----------
    model : torch.nn.Module
        A network of :func:`~robopercept.nn.pose.networks.build_pose_model`.
    train : PoseDataset
    config : TrainConfig, optional
    val : PoseDataset, optional
    skeleton : Skeleton, optional
        Its flip pairs allow mirrored training images.
    sigma : float
        The Gaussian targets' standard deviation (heatmap cells).
    augment : bool
    pck_alpha : float
        The PCK threshold (fraction of the box diagonal) that selects the epoch kept.
    progress : bool
    checkpoint : path, optional
        Written after every epoch (:func:`~robopercept.nn.train.loop.epoch_loop`'s
        checkpoint); the best weights go to ``<stem>.best.pt``.
    resume : bool
        Continue the run of ``checkpoint`` (same model, data and settings): it ends with
        the weights of an uninterrupted run.

    Returns
    -------
    PoseHistory
    """
    if not isinstance(model, nn.Module) or getattr(model, "output", None) not in (
        "heatmaps",
        "coordinates",
    ):
        raise InputError(
            f"model must be a pose network (build_pose_model); got {plain_repr(model)}"
        )
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    x, kp, _boxes = pose_data_arrays(train, "train")
    if kp.shape[1] != model.num_joints:
        raise InputError(
            f"the network predicts {model.num_joints} joints; the data has {kp.shape[1]}"
        )
    check_input_size(model, x)
    if val is not None:
        vx, vkp, vboxes = pose_data_arrays(val, "val")
    sigma = check_real(sigma, "sigma", 0.0, 1e3, low_inclusive=False)
    pck_alpha = check_real(pck_alpha, "pck_alpha", 0.0, low_inclusive=False)
    check_bool(augment, "augment")
    if skeleton is not None and (
        not isinstance(skeleton, Skeleton) or skeleton.num_joints != kp.shape[1]
    ):
        raise InputError(
            f"skeleton must be a Skeleton of the data's {kp.shape[1]} joints (e.g. "
            f"robopercept.nn.skeleton.MPII_16) or None; got {plain_repr(skeleton)[:60]}"
        )
    perm = None if skeleton is None else skeleton.flip_permutation()
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    n, _, h, w = x.shape
    stride = int(getattr(model, "stride", 4))

    def batch(idx: torch.Tensor) -> torch.Tensor:
        xb, kb = x[idx], kp[idx]
        if augment:
            xb, kb = augment_pose_batch(xb, kb, perm, gen)
        out = model(xb.to(dev))
        if model.output == "heatmaps":
            target, weight = gaussian_heatmaps(kb, (w, h), stride, sigma)
            kind = getattr(model, "heatmap", "mse")
            return heatmap_loss(out, target.to(dev), weight.to(dev), kind)
        size = torch.tensor([w, h], dtype=torch.float32)
        y = kb[..., :2] / size - 0.5
        lab = (kb[..., 2] > 0).float().to(dev)
        err = ((out - y.to(dev)) ** 2).sum(-1)
        return (err * lab).sum() / lab.sum().clamp_min(1.0)

    def validate() -> float:
        pred, _ = predict_keypoints(model, vx)
        return _pck(pred, vkp.numpy(), vboxes, pck_alpha)

    hist = PoseHistory()
    epoch_loop(
        model,
        n,
        cfg,
        gen,
        batch,
        validate if val is not None else None,
        desc="training pose network",
        progress=progress,
        history=hist,
        checkpoint=checkpoint,
        resume=check_bool(resume, "resume"),
        checkpoint_extra={"architecture": type(model).__name__},
    )
    return hist


def train_refiner(
    refiner: DeepPoseRefiner,
    train: Any,
    estimates: npt.ArrayLike,
    config: Any = None,
    *,
    val: Any = None,
    val_estimates: npt.ArrayLike | None = None,
    progress: bool = True,
    pck_alpha: float = 0.1,
) -> PoseHistory:
    r"""Train one DeepPose cascade stage on the previous stage's estimates.

    As in Toshev & Szegedy (2014), section 3.2, the windows are centred on the
    previous stage's estimate of each joint on the training images and, as
    augmentation, on the truth displaced by a draw from a normal distribution fitted
    to that stage's displacements (their mean and covariance per joint); the target is
    the displacement to the truth in window units,
    :math:`\delta_k = (p_k - \hat p_k) / \text{crop}`, its squared error averaged over
    the labelled joints.

    Parameters
    ----------
    refiner : DeepPoseRefiner
    train : PoseDataset
    estimates : (N, J, 2) array_like
        The previous stage's estimates on ``train`` (pixels).
    config : TrainConfig, optional
    val, val_estimates : optional
        Validation data and its previous-stage estimates: the PCK after refinement is
        measured every epoch and the best epoch kept.

    Returns
    -------
    PoseHistory
    """
    if not isinstance(refiner, DeepPoseRefiner):
        raise InputError(f"refiner must be a DeepPoseRefiner; got {plain_repr(refiner)}")
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    x, kp, _ = pose_data_arrays(train, "train")
    est = torch.as_tensor(np.asarray(estimates, dtype=np.float32))
    if est.shape != kp[..., :2].shape:
        raise InputError(
            f"estimates must be (N, J, 2) = {tuple(kp[..., :2].shape)}; got {tuple(est.shape)}"
        )
    if val is not None:
        vx, vkp, vboxes = pose_data_arrays(val, "val")
        if val_estimates is None:
            raise InputError("val needs val_estimates (the previous stage's output on it)")
        vest = np.asarray(val_estimates, dtype=np.float64)
    lab = kp[..., 2] > 0
    resid = (kp[..., :2] - est).double()
    mu = torch.stack([resid[:, k][lab[:, k]].mean(0) for k in range(kp.shape[1])])
    cov = torch.stack(
        [
            torch.cov(resid[:, k][lab[:, k]].T) + 1e-3 * torch.eye(2, dtype=torch.float64)
            for k in range(kp.shape[1])
        ]
    )
    chol = torch.linalg.cholesky(cov)
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    refiner.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    n, j = kp.shape[:2]

    def batch(idx: torch.Tensor) -> torch.Tensor:
        m = len(idx)
        truth = kp[idx, :, :2].double()
        z = torch.randn((m, j, 2), generator=gen, dtype=torch.float64)
        sim = truth - mu - torch.einsum("jab,mjb->mja", chol, z)
        use_est = torch.rand((m, 1, 1), generator=gen) < 0.5
        centres = torch.where(use_est, est[idx].double(), sim).float()
        patches = crop_patches(x[idx], centres, refiner.crop, refiner.patch)
        joints = torch.arange(j).repeat(m)
        target = ((truth.float() - centres) / refiner.crop).reshape(-1, 2)
        weight = lab[idx].reshape(-1).float().to(dev)
        out = refiner(patches.to(dev), joints.to(dev))
        err = ((out - target.to(dev)) ** 2).sum(-1)
        return (err * weight).sum() / weight.sum().clamp_min(1.0)

    def validate() -> float:
        pred = refine_keypoints(vx, vest, [refiner])
        return _pck(pred, vkp.numpy(), vboxes, pck_alpha)

    hist = PoseHistory()
    epoch_loop(
        refiner,
        n,
        cfg,
        gen,
        batch,
        validate if val is not None else None,
        desc="training DeepPose stage",
        progress=progress,
        history=hist,
    )
    return hist


def train_cascade(
    model: nn.Module,
    train: Any,
    stages: int,
    config: Any = None,
    *,
    val: Any = None,
    crop: float | None = None,
    width: int = 16,
    progress: bool = True,
) -> tuple[list[DeepPoseRefiner], list[PoseHistory]]:
    """DeepPose's cascade: ``stages``
    :class:`~robopercept.nn.pose.networks.DeepPoseRefiner` stages, each trained by
    :func:`train_refiner` on the estimates of the network and the stages before it
    (on ``train``, and on ``val`` for picking each stage's epoch).

    Parameters
    ----------
    model : nn.Module
        The trained first stage (a :class:`~robopercept.nn.pose.networks.DeepPose`, or
        any pose network).
    train, val : PoseDataset
    stages : int
        0 to 8.
    config : TrainConfig, optional
    crop : float, optional
        The window side in pixels (default a quarter of the shorter image side).
    width : int

    Returns
    -------
    refiners : list of DeepPoseRefiner
    histories : list of PoseHistory
    """
    stages = check_int(stages, "stages", 0)
    if stages > 8:
        raise InputError(f"stages must be 0 to 8 cascade stages; got {stages}")
    x, kp, _ = pose_data_arrays(train, "train")
    vx = pose_data_arrays(val, "val")[0] if val is not None else None
    side = crop if crop is not None else 0.25 * min(x.shape[-2:])
    est, _ = predict_keypoints(model, x)
    vest = predict_keypoints(model, vx)[0] if vx is not None else None
    refiners: list[DeepPoseRefiner] = []
    histories: list[PoseHistory] = []
    for _ in range(stages):
        stage = DeepPoseRefiner(int(kp.shape[1]), crop=side, width=width)
        h = train_refiner(stage, train, est, config, val=val, val_estimates=vest, progress=progress)
        refiners.append(stage)
        histories.append(h)
        est = refine_keypoints(x, est, [stage])
        if vx is not None and vest is not None:
            vest = refine_keypoints(vx, vest, [stage])
    return refiners, histories
