r"""Object detectors in pure torch: single-object localisation, R-CNN, Fast R-CNN,
Faster R-CNN and FCOS, on small backbones built from :mod:`robopercept.nn.core.blocks`.

Every detector keeps torchvision's detection-model contract:
``model(images, targets=None)`` with ``images`` a list of ``(3, H, W)`` float tensors
in [0, 1] (sizes may differ: they are zero-padded to one batch whose sides are
multiples of the largest stride) and ``targets`` a list of dicts with ``"boxes"``
(``(K, 4)`` float ``"xyxy"`` pixels) and ``"labels"`` (``(K,)`` int64, 1-based; 0 is
the background). In train mode the call returns a dict of scalar losses, in eval mode
a list of ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}``, one per image, boxes
in the input image's pixels. The input normalization
:math:`(x - \mu) / \sigma` (ImageNet's mean and std) happens inside the model.

The detectors (the course's object-detection chapter):

- :class:`SingleObjectLocalizer`: one object per image. Backbone, global average
  pooling, a classification head (``num_classes`` logits) and a box head giving the box
  as **normalized cxcywh** (centre and size divided by the image's width and height,
  in [0, 1] through a sigmoid). Loss
  :math:`L = \mathrm{CE}(p, y) + \lambda\,\mathrm{smoothL1}_\beta(\hat b, b)`.
- :class:`RCNN` (Girshick et al. 2014), the "slow" R-CNN: each proposal (selective
  search, :func:`selective_search_proposals`, or given) warped with context padding to
  a fixed size and classified by a small CNN of its own (background included), with a
  linear per-class box regressor on its features; positives IoU >= 0.5, negatives
  < 0.3; ``last_timing`` measures the seconds per image.
- :class:`FastRCNN` (Girshick 2015): shared backbone, **external** proposals per image
  (``proposal_fn``, e.g. selective search; the ground-truth boxes are added to them in
  training), RoI max pooling (:func:`~robopercept.nn.ops.boxes.roi_pool`) and a per-region
  head (class logits and class-specific deltas, :class:`~robopercept.nn.ops.boxes.BoxCoder`
  weights (10, 10, 5, 5)). Training samples 25 % foreground regions (IoU >= 0.5 with a
  ground-truth box) and background ones (IoU in [0.1, 0.5)), as the paper.
- :class:`FasterRCNN` (Ren et al. 2015): a region proposal network (3 x 3 conv,
  objectness logit and deltas per anchor of
  :class:`~robopercept.nn.ops.boxes.AnchorGenerator`), anchors labelled positive at
  IoU >= 0.7 (and the best anchor of each ground-truth box, even below), negative
  below 0.3, 256 sampled per image, half positive; proposals by decoding, clipping,
  removing small boxes and NMS (top-k before and after, fewer in eval); RoI Align
  (:func:`~robopercept.nn.ops.boxes.roi_align`) and the per-region head of Fast R-CNN.
  The four losses are reported separately under torchvision's names:
  ``loss_rpn_objectness``, ``loss_rpn_box``, ``loss_classifier``, ``loss_box``.
- :class:`FCOS` (Tian et al. 2019), the single-stage detector. **Why FCOS** rather
  than an anchor-based RetinaNet: it has no anchor sizes or ratios to tune (each
  feature-map location inside a ground-truth box's centre region regresses its
  distances to the four sides), which suits small objects of varying shape such as the
  tree crowns of :func:`~robopercept.nn.detection.data.deepforest_tiles`, and it is the
  single-stage detector of the notes. Per location: classification with the sigmoid
  focal loss (:func:`sigmoid_focal_loss`), ``ltrb`` regression (divided by the
  level's stride) with the GIoU loss, and centerness with binary cross-entropy;
  losses ``classification``, ``bbox_regression``, ``bbox_ctrness`` (torchvision's).

:func:`build_detector`, :func:`save_detector` and :func:`load_detector` rebuild any of
them by name from a checkpoint (the ``robopercept nn detect`` CLI), and
:func:`detect_arrays` runs one on NumPy images.

Shared training pieces, public and tested by hand: :func:`match_boxes` (IoU
thresholds with ignored bands and low-quality matches) and :func:`sample_balanced`
(a fixed number of examples with a cap on the positive fraction). Conventions follow
torchvision's ``models.detection`` (looked up, not imported: torchvision is not a
dependency); smooth-L1 with :math:`\beta = 1/9` summed and divided by the number of
sampled examples, as there.

Determinism: sampling draws from torch's global generator, so a run seeded by
:func:`train_detector` (``TrainConfig.seed``) gives identical losses and weights on the
CPU for the same thread count. Models run on CUDA when moved there (``config.device``).
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.core.blocks import ConvBNAct, ResidualBlock
from robopercept.nn.ops.boxes import (
    AnchorGenerator,
    BoxCoder,
    batched_nms,
    box_convert,
    box_iou,
    dihedral_boxes,
    generalized_box_iou,
    nms,
    paste_masks,
    roi_align,
    roi_pool,
)

__all__ = [
    "DETECTORS",
    "FCOS",
    "FPN",
    "RCNN",
    "TTA_VIEWS",
    "VAL_METRICS",
    "DetectionBackbone",
    "DetectionHistory",
    "FastRCNN",
    "FasterRCNN",
    "KeypointRCNN",
    "LocalizationResult",
    "MaskRCNN",
    "SingleObjectLocalizer",
    "TestTimeAugmentation",
    "build_detector",
    "detect_arrays",
    "evaluate_detector",
    "evaluate_localizer",
    "load_detector",
    "match_boxes",
    "sample_balanced",
    "save_detector",
    "selective_search_proposals",
    "sigmoid_focal_loss",
    "train_detector",
]

#: the most channels a detector's FPN or head may have (a 3 x 3 convolution of 4096 to
#: 4096 channels holds 600 MB of weights)
MAX_CHANNELS = 4096

#: ImageNet mean and std: the normalization inside every detector
IMAGE_MEAN = (0.485, 0.456, 0.406)
IMAGE_STD = (0.229, 0.224, 0.225)

_STRIDES = (4, 8, 16, 32)


# --------------------------------------------------------------------------- backbone
class FPN(nn.Module):
    r"""Feature pyramid network (Lin et al. 2017): lateral 1 x 1 convolutions to
    ``out_channels``, a top-down pathway adding the nearest-upsampled coarser level,
    and a 3 x 3 convolution on each sum: :math:`P_l = \mathrm{conv}_{3}(\mathrm{lat}(C_l)
    + \mathrm{up}(P'_{l+1}))`.

    Parameters
    ----------
    in_channels : sequence of int
        Channels of the input maps, finest first.
    out_channels : int

    Examples
    --------
    >>> import torch
    >>> fpn = FPN([8, 16], 12)
    >>> [tuple(p.shape) for p in fpn([torch.zeros(1, 8, 8, 8), torch.zeros(1, 16, 4, 4)])]
    [(1, 12, 8, 8), (1, 12, 4, 4)]
    """

    def __init__(self, in_channels: Sequence[int], out_channels: int) -> None:
        super().__init__()
        if not isinstance(in_channels, (list, tuple)) or not in_channels:
            raise InputError(
                f"in_channels must be a non-empty list of ints; got {plain_repr(in_channels)}"
            )
        chans = [check_count(c, "in_channels", 1, 1 << 16) for c in in_channels]
        out_channels = check_count(out_channels, "out_channels", 1, MAX_CHANNELS)
        self.lateral = nn.ModuleList(nn.Conv2d(c, out_channels, 1) for c in chans)
        self.output = nn.ModuleList(
            nn.Conv2d(out_channels, out_channels, 3, padding=1) for _ in chans
        )
        self.out_channels = out_channels

    def forward(self, features: list[torch.Tensor]) -> list[torch.Tensor]:
        if not isinstance(features, (list, tuple)) or len(features) != len(self.lateral):
            raise InputError(
                f"features must be a list of {len(self.lateral)} (N, C, H, W) maps, finest "
                f"first; got {plain_repr(features)}"
            )
        inner = self.lateral[-1](features[-1])
        out = [self.output[-1](inner)]
        for i in range(len(features) - 2, -1, -1):
            lat = self.lateral[i](features[i])
            inner = lat + F.interpolate(inner, size=lat.shape[-2:], mode="nearest")
            out.insert(0, self.output[i](inner))
        return out


class DetectionBackbone(nn.Module):
    """A small ResNet-style feature extractor from the foundation's blocks, with an
    optional :class:`FPN`.

    Layout: a stride-2 3 x 3 :class:`~robopercept.nn.core.blocks.ConvBNAct` stem of ``width``
    channels and a :class:`~robopercept.nn.core.blocks.ResidualBlock`, then one stride-2
    residual block per further stride (4, 8, 16, 32), doubling the channels up to
    ``8 width``. The maps at ``strides`` are returned, finest first (through the FPN
    when ``fpn_channels`` is given).

    Parameters
    ----------
    width : int
        Channels of the stem.
    strides : sequence of int
        Output strides, increasing, from {4, 8, 16, 32}.
    fpn_channels : int, optional
        Build an FPN with this many channels on the outputs.
    blocks : int
        Residual blocks per stride-2 stage (1 by default; ResNet-18 has 2): each extra
        block (stride 1, same channels) adds two 3 x 3 convolutions, so :math:`4 s`
        pixels of receptive field at the stage's stride :math:`s`.

    Attributes
    ----------
    out_channels : list of int
        Channels of each output map.

    Examples
    --------
    >>> import torch
    >>> bb = DetectionBackbone(8, strides=(8, 16), fpn_channels=16)
    >>> [tuple(f.shape) for f in bb(torch.zeros(1, 3, 64, 64))]
    [(1, 16, 8, 8), (1, 16, 4, 4)]
    """

    def __init__(
        self,
        width: int = 16,
        strides: Sequence[int] = (8,),
        fpn_channels: int | None = None,
        blocks: int = 1,
    ) -> None:
        super().__init__()
        width = check_count(width, "width", 1, 1024)
        self.blocks = check_count(blocks, "blocks", 1, 16)
        if (
            not isinstance(strides, (list, tuple))
            or not strides
            or any(s not in _STRIDES for s in strides)
            or list(strides) != sorted(set(strides))
        ):
            raise InputError(
                f"strides must be increasing values from {_STRIDES}, e.g. (8, 16); got "
                f"{plain_repr(strides)}"
            )
        self.strides = tuple(int(s) for s in strides)
        self.stem = nn.Sequential(ConvBNAct(3, width, 3, stride=2), ResidualBlock(width, width))
        stages = []
        chans = {2: width}
        c = width
        for s in _STRIDES:
            if s > max(self.strides):
                break
            c_out = min(2 * c, 8 * width)
            stage: nn.Module = ResidualBlock(c, c_out, stride=2)
            if self.blocks > 1:  # (one block alone keeps the shipped checkpoints' keys)
                more = [ResidualBlock(c_out, c_out) for _ in range(self.blocks - 1)]
                stage = nn.Sequential(stage, *more)
            stages.append(stage)
            c = c_out
            chans[s] = c
        self.stages = nn.ModuleList(stages)
        channels = [chans[s] for s in self.strides]
        if fpn_channels is not None:
            fpn_channels = check_count(fpn_channels, "fpn_channels", 1, MAX_CHANNELS)
        self.fpn = FPN(channels, fpn_channels) if fpn_channels is not None else None
        self.out_channels = [self.fpn.out_channels] * len(channels) if self.fpn else channels

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.stem(x)
        out = []
        s = 2
        for stage in self.stages:
            x = stage(x)
            s *= 2
            if s in self.strides:
                out.append(x)
        return self.fpn(out) if self.fpn is not None else out


# --------------------------------------------------------------------------- matching
def match_boxes(
    iou: torch.Tensor,
    fg_threshold: float,
    bg_threshold: float,
    bg_low: float = 0.0,
    allow_low_quality: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Label each candidate (anchor or proposal) from its IoU with the ground truth.

    With :math:`q_j = \max_i \mathrm{IoU}(g_i, c_j)`: label 1 (foreground) when
    :math:`q_j \ge` ``fg_threshold``, 0 (background) when ``bg_low`` :math:`\le q_j <`
    ``bg_threshold``, -1 (ignored) otherwise. With ``allow_low_quality``, every
    candidate whose IoU with some :math:`g_i` equals that box's best IoU
    :math:`\max_j \mathrm{IoU}(g_i, c_j) > 0` is foreground too (the Faster R-CNN RPN
    rule: every ground-truth box gets at least one anchor), matched to that
    :math:`g_i` (as torchvision's ``Matcher``). Without ground truth every candidate
    with ``bg_low == 0`` is background.

    Parameters
    ----------
    iou : (G, N) torch.Tensor
        IoU of G ground-truth boxes (rows) with N candidates.
    fg_threshold, bg_threshold : float
        In [0, 1], ``bg_threshold <= fg_threshold``.
    bg_low : float
        Lowest IoU of a background candidate (0.1 in Fast R-CNN).
    allow_low_quality : bool

    Returns
    -------
    labels : (N,) int64 torch.Tensor
        1, 0 or -1.
    matched : (N,) int64 torch.Tensor
        Index of the matched ground-truth box (0 where there is none).

    Examples
    --------
    >>> import torch
    >>> iou = torch.tensor([[0.9, 0.5, 0.2, 0.05]])
    >>> match_boxes(iou, 0.7, 0.3)[0].tolist()
    [1, -1, 0, 0]
    >>> match_boxes(torch.tensor([[0.6, 0.2]]), 0.7, 0.3, allow_low_quality=True)[0].tolist()
    [1, 0]
    """
    if not isinstance(iou, torch.Tensor) or iou.ndim != 2 or not iou.is_floating_point():
        raise InputError(
            "iou must be a (G, N) floating torch.Tensor (box_iou(gt, candidates)); got "
            + plain_repr(iou)
        )
    if iou.numel() and not bool(torch.isfinite(iou).all()):
        raise InputError("iou must be finite; got NaN or inf: check the boxes for NaN")
    fg = check_real(fg_threshold, "fg_threshold", 0.0, 1.0)
    bg = check_real(bg_threshold, "bg_threshold", 0.0, fg)
    lo = check_real(bg_low, "bg_low", 0.0, bg)
    low_q = check_bool(allow_low_quality, "allow_low_quality")
    n = iou.shape[1]
    if iou.shape[0] == 0:
        labels = torch.full((n,), 0 if lo <= 0.0 else -1, dtype=torch.int64, device=iou.device)
        return labels, torch.zeros(n, dtype=torch.int64, device=iou.device)
    q, matched = iou.max(dim=0)
    labels = torch.full((n,), -1, dtype=torch.int64, device=iou.device)
    labels[(q >= lo) & (q < bg)] = 0
    labels[q >= fg] = 1
    if low_q and n:
        best = iou.max(dim=1).values
        g_idx, c_idx = torch.nonzero((iou == best[:, None]) & (best[:, None] > 0), as_tuple=True)
        labels[c_idx] = 1
        matched[c_idx] = g_idx
    return labels, matched


def sample_balanced(
    labels: torch.Tensor, batch_size: int, positive_fraction: float
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Sample at most ``batch_size`` candidates with at most a ``positive_fraction`` of
    positives: :math:`n_+ = \min(\#\{l = 1\}, \lfloor b f \rfloor)`,
    :math:`n_- = \min(\#\{l = 0\}, b - n_+)`, each drawn uniformly without replacement
    (torch's global generator: seed it with :func:`torch.manual_seed`); ignored (-1)
    candidates are never drawn. torchvision's ``BalancedPositiveNegativeSampler``.

    Parameters
    ----------
    labels : (N,) int torch.Tensor
        1 positive, 0 negative, -1 ignored.
    batch_size : int
        >= 1 (256 anchors in the RPN, 512 or 128 regions in the head).
    positive_fraction : float
        In [0, 1] (0.5 in the RPN, 0.25 in the head).

    Returns
    -------
    positive, negative : (N,) bool torch.Tensor
        The sampled candidates.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> pos, neg = sample_balanced(torch.tensor([1, 1, 1, 0, 0, 0, 0, -1]), 4, 0.25)
    >>> int(pos.sum()), int(neg.sum()), bool(pos[7] or neg[7])
    (1, 3, False)
    """
    if (
        not isinstance(labels, torch.Tensor)
        or labels.ndim != 1
        or labels.is_floating_point()
        or labels.is_complex()
    ):
        raise InputError(
            "labels must be a (N,) integer torch.Tensor of 1 / 0 / -1; got " + plain_repr(labels)
        )
    b = check_int(batch_size, "batch_size", 1)
    f = check_real(positive_fraction, "positive_fraction", 0.0, 1.0)
    pos_idx = torch.nonzero(labels == 1).flatten()
    neg_idx = torch.nonzero(labels == 0).flatten()
    n_pos = min(pos_idx.numel(), int(b * f))
    n_neg = min(neg_idx.numel(), b - n_pos)
    pos_pick = pos_idx[torch.randperm(pos_idx.numel())[:n_pos].to(labels.device)]
    neg_pick = neg_idx[torch.randperm(neg_idx.numel())[:n_neg].to(labels.device)]
    pos = torch.zeros_like(labels, dtype=torch.bool)
    neg = torch.zeros_like(labels, dtype=torch.bool)
    pos[pos_pick] = True
    neg[neg_pick] = True
    return pos, neg


def sigmoid_focal_loss(
    inputs: torch.Tensor,
    targets: torch.Tensor,
    alpha: float = 0.25,
    gamma: float = 2.0,
    reduction: str = "none",
) -> torch.Tensor:
    r"""Focal loss (Lin et al. 2017, RetinaNet) on logits, per element:

    .. math::
        p_t = p y + (1 - p)(1 - y),\quad
        \mathrm{FL} = -\alpha_t (1 - p_t)^\gamma \log p_t,\quad
        \alpha_t = \alpha y + (1 - \alpha)(1 - y)

    with :math:`p = \sigma(x)` (no :math:`\alpha_t` when ``alpha < 0``), the BCE term
    computed stably from the logits. Matches torchvision's ``ops.sigmoid_focal_loss``.

    Parameters
    ----------
    inputs : torch.Tensor
        Logits, any shape.
    targets : torch.Tensor
        Same shape, in [0, 1].
    alpha : float
        In [0, 1], or negative for no weighting.
    gamma : float
        >= 0; 0 gives (alpha-weighted) binary cross-entropy.
    reduction : {"none", "mean", "sum"}

    Returns
    -------
    torch.Tensor

    Examples
    --------
    >>> import torch
    >>> round(float(sigmoid_focal_loss(torch.tensor([0.0]), torch.tensor([1.0]))), 6)
    0.043322
    """
    if not isinstance(inputs, torch.Tensor) or not inputs.is_floating_point():
        raise InputError(
            f"inputs must be a floating torch.Tensor of logits; got {plain_repr(inputs)}"
        )
    if not isinstance(targets, torch.Tensor) or targets.shape != inputs.shape:
        raise InputError(
            f"targets must be a torch.Tensor of the shape of inputs {tuple(inputs.shape)}; got "
            + plain_repr(targets)
        )
    a = check_real(alpha, "alpha", None, 1.0)
    g = check_real(gamma, "gamma", 0.0, 1e3)
    if reduction not in ("none", "mean", "sum"):
        raise InputError(f"reduction must be 'none', 'mean' or 'sum'; got {plain_repr(reduction)}")
    t = targets.to(inputs.dtype)
    p = torch.sigmoid(inputs)
    ce = F.binary_cross_entropy_with_logits(inputs, t, reduction="none")
    p_t = p * t + (1 - p) * (1 - t)
    loss = ce * (1 - p_t) ** g
    if a >= 0:
        loss = (a * t + (1 - a) * (1 - t)) * loss
    if reduction == "mean":
        return loss.mean()
    if reduction == "sum":
        return loss.sum()
    return loss


# --------------------------------------------------------------------------- inputs
def _check_images(images: Any) -> list[torch.Tensor]:
    if isinstance(images, torch.Tensor) and images.ndim == 4:
        images = list(images)
    if not isinstance(images, (list, tuple)) or not images:
        raise InputError(
            "images must be a non-empty list of (3, H, W) float tensors in [0, 1] (or a "
            f"(N, 3, H, W) batch); got {plain_repr(images)}"
        )
    out = []
    for i, im in enumerate(images):
        if not isinstance(im, torch.Tensor):
            raise InputError(
                f"images[{i}] must be a (3, H, W) torch.Tensor; got {type(im).__name__}: "
                "use torch.from_numpy(image.transpose(2, 0, 1))"
            )
        if im.ndim != 3 or im.shape[0] != 3:
            fix = (
                ": channels-last? use image.permute(2, 0, 1)"
                if im.ndim == 3 and im.shape[-1] == 3
                else ": give RGB images channels first"
            )
            raise InputError(f"images[{i}] must be (3, H, W); got {tuple(im.shape)}{fix}")
        if not im.is_floating_point():
            raise InputError(
                f"images[{i}] must be floating point in [0, 1]; got {im.dtype}: use "
                "image.float() / 255 for uint8"
            )
        if im.shape[1] < 1 or im.shape[2] < 1:
            raise InputError(f"images[{i}] is empty: {tuple(im.shape)}")
        if not bool(torch.isfinite(im).all()):
            raise InputError(f"images[{i}] has NaN or inf pixels: replace them first")
        out.append(im)
    return out


def _check_targets(
    targets: Any, images: list[torch.Tensor], num_classes: int
) -> list[dict[str, torch.Tensor]]:
    if not isinstance(targets, (list, tuple)) or len(targets) != len(images):
        raise InputError(
            f"targets must be a list of {len(images)} dicts (one per image) with 'boxes' and "
            f"'labels' in train mode; got {plain_repr(targets)}: call model.eval() to predict"
        )
    out = []
    for i, t in enumerate(targets):
        if not isinstance(t, Mapping) or "boxes" not in t or "labels" not in t:
            raise InputError(
                f"targets[{i}] must be a dict with 'boxes' and 'labels'; got {plain_repr(t)}"
            )
        b, lab = t["boxes"], t["labels"]
        if (
            not isinstance(b, torch.Tensor)
            or not b.is_floating_point()
            or b.ndim != 2
            or b.shape[1] != 4
        ):
            raise InputError(
                f"targets[{i}]['boxes'] must be a (K, 4) float torch.Tensor, xyxy pixels; got "
                f"{plain_repr(b)}: use torch.as_tensor(boxes, dtype=torch.float32)"
            )
        if (
            not isinstance(lab, torch.Tensor)
            or lab.dtype != torch.int64
            or lab.shape != (b.shape[0],)
        ):
            raise InputError(
                f"targets[{i}]['labels'] must be a ({b.shape[0]},) int64 torch.Tensor; got "
                f"{plain_repr(lab)}: use torch.as_tensor(labels, dtype=torch.int64)"
            )
        if b.numel():
            if not bool(torch.isfinite(b).all()):
                raise InputError(f"targets[{i}]['boxes'] has NaN or inf: drop those boxes")
            if bool(((b[:, 2] <= b[:, 0]) | (b[:, 3] <= b[:, 1])).any()):
                raise InputError(
                    f"targets[{i}]['boxes'] has a degenerate box (x2 <= x1 or y2 <= y1): drop "
                    "them, e.g. keep = (b[:, 2] > b[:, 0]) & (b[:, 3] > b[:, 1])"
                )
            if int(lab.min()) < 1 or int(lab.max()) > num_classes:
                raise InputError(
                    f"targets[{i}]['labels'] must be in 1..{num_classes} (0 is the background); "
                    f"got {int(lab.min())}..{int(lab.max())}"
                )
        checked = {"boxes": b, "labels": lab}
        for extra in ("masks", "keypoints"):
            # checked where a model uses them (MaskRCNN, KeypointRCNN)
            if extra in t:
                checked[extra] = t[extra]
        out.append(checked)
    return out


def _clip(boxes: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    h, w = size
    return torch.stack(
        (
            boxes[..., 0].clamp(0, w),
            boxes[..., 1].clamp(0, h),
            boxes[..., 2].clamp(0, w),
            boxes[..., 3].clamp(0, h),
        ),
        dim=-1,
    )


def _empty_detections(device: torch.device) -> dict[str, torch.Tensor]:
    return {
        "boxes": torch.zeros((0, 4), device=device),
        "labels": torch.zeros((0,), dtype=torch.int64, device=device),
        "scores": torch.zeros((0,), device=device),
    }


class _Detector(nn.Module):
    """Shared plumbing: input checks, normalization, padding to one batch."""

    num_classes: int
    size_divisible: int
    mean: torch.Tensor
    std: torch.Tensor

    def _init_common(self, num_classes: int, size_divisible: int) -> None:
        self.num_classes = check_count(num_classes, "num_classes", 1, 1 << 16)
        self.size_divisible = size_divisible
        self.register_buffer("mean", torch.tensor(IMAGE_MEAN).view(3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGE_STD).view(3, 1, 1), persistent=False)

    def _prepare(
        self, images: Any, targets: Any
    ) -> tuple[torch.Tensor, list[tuple[int, int]], list[dict[str, torch.Tensor]] | None]:
        ims = _check_images(images)
        tgts = None
        if self.training:
            if targets is None:
                raise InputError(
                    "targets are required in train mode (a list of dicts with 'boxes' and "
                    "'labels'): pass them, or call model.eval() to predict"
                )
            tgts = _check_targets(targets, ims, self.num_classes)
        elif targets is not None:
            tgts = _check_targets(targets, ims, self.num_classes)
        dev = self.mean.device
        sizes = [(int(im.shape[1]), int(im.shape[2])) for im in ims]
        d = self.size_divisible
        hp = max(h for h, _ in sizes)
        wp = max(w for _, w in sizes)
        hp, wp = -(-hp // d) * d, -(-wp // d) * d
        batch = torch.zeros((len(ims), 3, hp, wp), device=dev)
        for i, im in enumerate(ims):
            batch[i, :, : im.shape[1], : im.shape[2]] = (
                im.to(dev, torch.float32) - self.mean
            ) / self.std
        if tgts is not None:
            tgts = [{k: v.to(dev) for k, v in t.items()} for t in tgts]
        return batch, sizes, tgts

    def predict(self, images: Any) -> list[dict[str, torch.Tensor]]:
        """Detections of ``images`` (eval mode, no gradients; the mode is restored)."""
        was = self.training
        self.eval()
        try:
            with torch.no_grad():
                return self(images)
        finally:
            self.train(was)


# --------------------------------------------------------------------------- (a) localizer
class SingleObjectLocalizer(_Detector):
    r"""Single-object localisation: a class and one box per image.

    Backbone (:class:`DetectionBackbone`, stride 16), global average pooling, then a
    linear classification head (``num_classes`` logits for labels 1..num_classes) and a
    linear box head whose sigmoid gives the box as normalized ``cxcywh``:
    :math:`(c_x / W, c_y / H, w / W, h / H)` of the (unpadded) image. Loss:

    .. math:: L = \mathrm{CE}(z, y - 1) + \lambda\,\mathrm{smoothL1}_{\beta}(\hat b, b)

    (smooth-L1 averaged over the 4 coordinates and the batch, :math:`\beta` = ``beta``).
    Train mode returns ``{"loss_classifier", "loss_box"}`` (``loss_box`` already times
    ``lam``); eval mode one detection per image (score = softmax probability of the
    label). Each target must hold exactly one box.

    Parameters
    ----------
    num_classes : int
    width : int
        Backbone width.
    lam : float
        :math:`\lambda`, >= 0.
    beta : float
        Smooth-L1 transition, > 0 (in normalized units).

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = SingleObjectLocalizer(3, width=8).eval()
    >>> out = m([torch.rand(3, 32, 48)])
    >>> tuple(out[0]["boxes"].shape), tuple(out[0]["labels"].shape)
    ((1, 4), (1,))
    """

    def __init__(
        self, num_classes: int, width: int = 16, lam: float = 1.0, beta: float = 0.05
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 16)
        self.lam = check_real(lam, "lam", 0.0)
        self.beta = check_real(beta, "beta", 0.0, low_inclusive=False)
        self.backbone = DetectionBackbone(width, strides=(16,))
        c = self.backbone.out_channels[-1]
        self.classifier = nn.Linear(c, self.num_classes)
        self.box_head = nn.Sequential(nn.Linear(c, c), nn.ReLU(), nn.Linear(c, 4))

    def forward(
        self, images: Any, targets: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing targets in train
            mode; boxes not (K, 4) float, with NaN or of zero width or height; labels not
            int64 or out of range.
        """
        batch, sizes, tgts = self._prepare(images, targets)
        feats = self.backbone(batch)[-1]
        hp, wp = batch.shape[-2:]
        # pool over each image's own (unpadded) extent
        pooled = []
        s = self.backbone.strides[-1]
        for i, (h, w) in enumerate(sizes):
            fh, fw = max(1, -(-h // s)), max(1, -(-w // s))
            pooled.append(feats[i, :, :fh, :fw].mean(dim=(1, 2)))
        z = torch.stack(pooled)
        logits = self.classifier(z)
        box = torch.sigmoid(self.box_head(z))
        scale = torch.tensor([[w, h, w, h] for h, w in sizes], dtype=box.dtype, device=box.device)
        if self.training:
            assert tgts is not None
            for i, t in enumerate(tgts):
                if t["boxes"].shape[0] != 1:
                    raise InputError(
                        f"targets[{i}] must hold exactly one box for single-object localisation; "
                        f"got {t['boxes'].shape[0]}: use FasterRCNN or FCOS for several"
                    )
            gt = torch.cat([t["boxes"] for t in tgts]).to(box.dtype)
            gt_n = box_convert(gt, "xyxy", "cxcywh") / scale
            labels = torch.cat([t["labels"] for t in tgts]) - 1
            return {
                "loss_classifier": F.cross_entropy(logits, labels),
                "loss_box": self.lam * F.smooth_l1_loss(box, gt_n, beta=self.beta),
            }
        prob = F.softmax(logits, dim=1)
        scores, lab = prob.max(dim=1)
        xyxy = _clip(box_convert(box * scale, "cxcywh", "xyxy"), (int(hp), int(wp)))
        out = []
        for i, (h, w) in enumerate(sizes):
            out.append(
                {
                    "boxes": _clip(xyxy[i : i + 1], (h, w)),
                    "labels": lab[i : i + 1] + 1,
                    "scores": scores[i : i + 1],
                }
            )
        return out


# --------------------------------------------------------------------------- RoI head
class _RoIHead(nn.Module):
    """Two fully connected layers on pooled regions, then class logits (background + C)
    and class-specific deltas (torchvision's TwoMLPHead + FastRCNNPredictor)."""

    def __init__(self, in_channels: int, pool: int, hidden: int, num_classes: int) -> None:
        super().__init__()
        self.fc = nn.Sequential(
            nn.Flatten(),
            nn.Linear(in_channels * pool * pool, hidden),
            nn.ReLU(),
            nn.Linear(hidden, hidden),
            nn.ReLU(),
        )
        self.cls_score = nn.Linear(hidden, num_classes + 1)
        self.bbox_pred = nn.Linear(hidden, 4 * (num_classes + 1))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.fc(x)
        return self.cls_score(h), self.bbox_pred(h)


class _TwoStage(_Detector):
    """The per-region part shared by Fast and Faster R-CNN."""

    box_coder: BoxCoder
    roi: _RoIHead
    backbone: DetectionBackbone
    pooler: str
    pool_size: int
    bg_low: float
    #: background is IoU in [bg_low, bg_high) (Fast R-CNN: 0.5; R-CNN: 0.3)
    bg_high: float = 0.5
    box_batch_size: int
    box_positive_fraction: float
    score_thresh: float
    nms_thresh: float
    detections_per_img: int

    def _init_heads(
        self,
        width: int,
        hidden: int,
        pool_size: int,
        box_batch_size: int,
        box_positive_fraction: float,
        score_thresh: float,
        nms_thresh: float,
        detections_per_img: int,
    ) -> None:
        self.backbone = DetectionBackbone(width, strides=(8,))
        self.pool_size = check_count(pool_size, "pool_size", 1, 64)
        hidden = check_count(hidden, "hidden", 1, 1 << 14)
        self.roi = _RoIHead(
            self.backbone.out_channels[-1], self.pool_size, hidden, self.num_classes
        )
        self.box_coder = BoxCoder((10.0, 10.0, 5.0, 5.0))
        self.box_batch_size = check_count(box_batch_size, "box_batch_size", 1, 1 << 20)
        self.box_positive_fraction = check_real(
            box_positive_fraction, "box_positive_fraction", 0.0, 1.0
        )
        self.score_thresh = check_real(score_thresh, "score_thresh", 0.0, 1.0)
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.detections_per_img = check_count(detections_per_img, "detections_per_img", 1, 1 << 20)

    def _pool(self, feats: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        scale = 1.0 / self.backbone.strides[-1]
        if self.pooler == "align":
            return roi_align(feats, rois, self.pool_size, scale, sampling_ratio=2)
        return roi_pool(feats, rois, self.pool_size, scale)

    def select_training_samples(
        self, proposals: list[torch.Tensor], targets: list[dict[str, torch.Tensor]]
    ) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Tensor]]:
        """Add the ground truth to the proposals, label them (IoU >= 0.5 foreground,
        [bg_low, 0.5) background) and sample ``box_batch_size`` with at most
        ``box_positive_fraction`` foreground; returns the regions, their class labels
        (0 background) and their regression targets."""
        rois, labels, deltas, _ = self.sample_regions(proposals, targets)
        return rois, labels, deltas

    def sample_regions(
        self, proposals: list[torch.Tensor], targets: list[dict[str, torch.Tensor]]
    ) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Tensor], list[torch.Tensor]]:
        """:meth:`select_training_samples` and, per image, the index of the ground-truth
        box each sampled region is matched to (meaningful for the foreground ones; the
        mask targets of :class:`MaskRCNN`)."""
        rois, labels, deltas, matches = [], [], [], []
        for p, t in zip(proposals, targets, strict=True):
            gt = t["boxes"].to(p.dtype)
            cand = torch.cat((p, gt))
            iou = box_iou(gt, cand)
            # an image without objects: every proposal is background (no IoU band)
            lab, matched = match_boxes(iou, 0.5, self.bg_high, self.bg_low if gt.shape[0] else 0.0)
            pos, neg = sample_balanced(lab, self.box_batch_size, self.box_positive_fraction)
            keep = torch.nonzero(pos | neg).flatten()
            cls = torch.zeros(keep.numel(), dtype=torch.int64, device=p.device)
            fg = pos[keep]
            if gt.shape[0]:
                cls[fg] = t["labels"][matched[keep][fg]]
                d = torch.zeros((keep.numel(), 4), dtype=p.dtype, device=p.device)
                if bool(fg.any()):
                    d[fg] = self.box_coder.encode(gt[matched[keep][fg]], cand[keep][fg])
            else:
                d = torch.zeros((keep.numel(), 4), dtype=p.dtype, device=p.device)
            rois.append(cand[keep])
            labels.append(cls)
            deltas.append(d)
            matches.append(matched[keep])
        return rois, labels, deltas, matches

    def _head_losses(
        self,
        logits: torch.Tensor,
        box_reg: torch.Tensor,
        labels: list[torch.Tensor],
        deltas: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        lab = torch.cat(labels)
        tgt = torch.cat(deltas)
        if lab.numel() == 0:
            z = logits.sum() * 0.0
            return {"loss_classifier": z, "loss_box": box_reg.sum() * 0.0}
        loss_cls = F.cross_entropy(logits, lab)
        fg = torch.nonzero(lab > 0).flatten()
        reg = box_reg.reshape(box_reg.shape[0], -1, 4)[fg, lab[fg]]
        loss_box = F.smooth_l1_loss(reg, tgt[fg], beta=1.0 / 9, reduction="sum") / lab.numel()
        return {"loss_classifier": loss_cls, "loss_box": loss_box}

    def _postprocess(
        self,
        logits: torch.Tensor,
        box_reg: torch.Tensor,
        rois: list[torch.Tensor],
        sizes: list[tuple[int, int]],
    ) -> list[dict[str, torch.Tensor]]:
        out = []
        start = 0
        c = self.num_classes
        probs = F.softmax(logits, dim=1)
        for r, size in zip(rois, sizes, strict=True):
            k = r.shape[0]
            if k == 0:
                out.append(_empty_detections(logits.device))
                continue
            p = probs[start : start + k, 1:]
            d = box_reg[start : start + k]
            start += k
            boxes = _clip(self.box_coder.decode(d, r).reshape(k, c + 1, 4)[:, 1:], size)
            labels = torch.arange(1, c + 1, device=r.device).expand(k, c)
            boxes, scores, labels = boxes.reshape(-1, 4), p.reshape(-1), labels.reshape(-1)
            keep = (
                (scores > self.score_thresh)
                & (boxes[:, 2] - boxes[:, 0] >= 1e-2)
                & (boxes[:, 3] - boxes[:, 1] >= 1e-2)
            )
            boxes, scores, labels = boxes[keep], scores[keep], labels[keep]
            kept = batched_nms(boxes.detach(), scores.detach(), labels, self.nms_thresh)
            kept = kept[: self.detections_per_img]
            out.append({"boxes": boxes[kept], "labels": labels[kept], "scores": scores[kept]})
        return out

    def _run_heads(
        self,
        feats: torch.Tensor,
        proposals: list[torch.Tensor],
        sizes: list[tuple[int, int]],
        tgts: list[dict[str, torch.Tensor]] | None,
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        if self.training:
            assert tgts is not None
            rois, labels, deltas, matched = self.sample_regions(proposals, tgts)
            logits, reg = self.roi(self._pool(feats, rois))
            losses = self._head_losses(logits, reg, labels, deltas)
            losses.update(self._region_losses(feats, sizes, tgts, rois, labels, matched))
            return losses
        logits, reg = self.roi(self._pool(feats, proposals))
        return self._region_outputs(feats, sizes, self._postprocess(logits, reg, proposals, sizes))

    def _region_losses(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        tgts: list[dict[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        """Losses of further per-region branches on the sampled regions (Mask R-CNN's)."""
        return {}

    def _region_outputs(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        dets: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        """Outputs of further per-region branches on the final detections."""
        return dets


def _check_proposals(proposals: Any, sizes: list[tuple[int, int]]) -> list[torch.Tensor]:
    if not isinstance(proposals, (list, tuple)) or len(proposals) != len(sizes):
        raise InputError(
            f"proposals must be a list of {len(sizes)} (P, 4) float tensors (xyxy), one per "
            f"image; got {plain_repr(proposals)}"
        )
    out = []
    for i, (p, size) in enumerate(zip(proposals, sizes, strict=True)):
        if (
            not isinstance(p, torch.Tensor)
            or not p.is_floating_point()
            or p.ndim != 2
            or p.shape[1] != 4
        ):
            raise InputError(
                f"proposals[{i}] must be a (P, 4) float torch.Tensor, xyxy pixels; got "
                + plain_repr(p)
            )
        if p.numel() and not bool(torch.isfinite(p).all()):
            raise InputError(f"proposals[{i}] has NaN or inf: drop those boxes")
        p = _clip(p.float(), size)
        keep = (p[:, 2] - p[:, 0] > 0) & (p[:, 3] - p[:, 1] > 0)
        out.append(p[keep])
    return out


# --------------------------------------------------------------------------- (b) Fast R-CNN
class FastRCNN(_TwoStage):
    r"""Fast R-CNN (Girshick 2015): a shared backbone (stride 8), RoI max pooling of
    external proposals, two fully connected layers, then class logits (background and
    ``num_classes``) and class-specific deltas (:class:`~robopercept.nn.ops.boxes.BoxCoder`
    weights (10, 10, 5, 5)).

    Training: the ground-truth boxes join the proposals; regions with IoU >= 0.5 are
    foreground (the matched box's class), those in [0.1, 0.5) background, the rest
    ignored (in an image without objects every proposal is background);
    ``box_batch_size`` regions per image are sampled with at most 25 % foreground.
    Losses: ``loss_classifier`` (cross-entropy) and ``loss_box`` (smooth-L1,
    :math:`\beta = 1/9`, on the true class's deltas of foreground regions, summed and
    divided by the number of sampled regions). Eval: per class, decode, clip, score
    threshold, NMS, the ``detections_per_img`` best.

    Proposals come from ``proposal_fn(image) -> (P, 4)`` (e.g. selective search) or the
    ``proposals`` argument of the call, which wins.

    Parameters
    ----------
    num_classes : int
    proposal_fn : callable, optional
        ``(3, H, W)`` image in [0, 1] -> ``(P, 4)`` float ``"xyxy"`` proposals.
    width, hidden, pool_size
        Backbone width, fully connected width, RoI pooling output side.
    box_batch_size, box_positive_fraction
        Regions sampled per image and their foreground cap.
    score_thresh, nms_thresh, detections_per_img
        Post-processing.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = FastRCNN(2, width=8, hidden=32).eval()
    >>> out = m([torch.rand(3, 32, 32)], proposals=[torch.tensor([[2.0, 2, 20, 20]])])
    >>> sorted(out[0])
    ['boxes', 'labels', 'scores']
    """

    def __init__(
        self,
        num_classes: int,
        proposal_fn: Callable[[torch.Tensor], torch.Tensor] | None = None,
        *,
        width: int = 16,
        hidden: int = 256,
        pool_size: int = 7,
        box_batch_size: int = 128,
        box_positive_fraction: float = 0.25,
        score_thresh: float = 0.05,
        nms_thresh: float = 0.5,
        detections_per_img: int = 100,
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 8)
        if proposal_fn is not None and not callable(proposal_fn):
            raise InputError(f"proposal_fn must be callable or None; got {plain_repr(proposal_fn)}")
        self.proposal_fn = proposal_fn
        self.pooler = "pool"
        self.bg_low = 0.1
        self._init_heads(
            width,
            hidden,
            pool_size,
            box_batch_size,
            box_positive_fraction,
            score_thresh,
            nms_thresh,
            detections_per_img,
        )

    def forward(
        self, images: Any, targets: Any = None, proposals: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.
        proposals : list of (P, 4) float torch.Tensor, optional
            ``"xyxy"`` proposals per image (clipped; empty ones dropped); None: from
            ``proposal_fn``.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing targets in train
            mode; boxes not (K, 4) float, with NaN or of zero width or height; labels not
            int64 or out of range.
        """
        batch, sizes, tgts = self._prepare(images, targets)
        if proposals is None:
            if self.proposal_fn is None:
                raise InputError(
                    "Fast R-CNN needs proposals: pass proposals=[(P, 4) tensor per image] or "
                    "build the model with proposal_fn (e.g. selective search)"
                )
            proposals = [self.proposal_fn(im) for im in _check_images(images)]
        props = [p.to(batch.device) for p in _check_proposals(proposals, sizes)]
        feats = self.backbone(batch)[-1]
        return self._run_heads(feats, props, sizes, tgts)


# --------------------------------------------------------------------------- (c) Faster R-CNN
class FasterRCNN(_TwoStage):
    r"""Faster R-CNN (Ren et al. 2015): a region proposal network on a stride-8
    backbone, RoI Align, and the per-region head of :class:`FastRCNN`.

    RPN: a 3 x 3 convolution and ReLU, then per anchor an objectness logit and deltas
    (:class:`~robopercept.nn.ops.boxes.BoxCoder` weights (1, 1, 1, 1)). Anchors
    (:class:`~robopercept.nn.ops.boxes.AnchorGenerator`, centred on cells) are positive at
    IoU >= 0.7 with a ground-truth box or when they are a box's best anchor
    (:func:`match_boxes` with ``allow_low_quality``), negative below 0.3, else
    ignored; ``rpn_batch_size`` are sampled per image, at most half positive
    (:func:`sample_balanced`). ``loss_rpn_objectness`` is the binary cross-entropy of
    the sampled anchors' logits; ``loss_rpn_box`` the smooth-L1 (:math:`\beta = 1/9`)
    of the positives' deltas, summed and divided by the number sampled (0 without
    positives). Proposals: the ``pre_nms_top_n`` best anchors by objectness, decoded,
    clipped, boxes under ``min_size`` dropped, NMS at ``rpn_nms_thresh``, the
    ``post_nms_top_n`` best kept (train / eval counts separately, as torchvision);
    they are detached, as in the approximate joint training of the paper. The head
    (``loss_classifier``, ``loss_box``) samples regions with IoU >= 0.5 foreground and
    [0, 0.5) background.

    Parameters
    ----------
    num_classes : int
    width, hidden, pool_size
        Backbone width, fully connected width, RoI Align output side.
    anchor_sizes, aspect_ratios
        Of the :class:`~robopercept.nn.ops.boxes.AnchorGenerator`, pixels and h / w.
    rpn_fg_iou, rpn_bg_iou, rpn_batch_size, rpn_positive_fraction
        Anchor labelling and sampling.
    pre_nms_top_n, post_nms_top_n : (train, eval) pairs of int
    rpn_nms_thresh, min_size
        Proposal NMS IoU, smallest proposal side in pixels.
    box_batch_size, box_positive_fraction, score_thresh, nms_thresh, detections_per_img
        As in :class:`FastRCNN`.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = FasterRCNN(2, width=8, hidden=32)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1])}]
    >>> sorted(m([torch.rand(3, 32, 32)], t))
    ['loss_box', 'loss_classifier', 'loss_rpn_box', 'loss_rpn_objectness']
    """

    def __init__(
        self,
        num_classes: int,
        *,
        width: int = 16,
        hidden: int = 256,
        pool_size: int = 7,
        anchor_sizes: Sequence[float] = (16.0, 32.0, 64.0),
        aspect_ratios: Sequence[float] = (0.5, 1.0, 2.0),
        rpn_fg_iou: float = 0.7,
        rpn_bg_iou: float = 0.3,
        rpn_batch_size: int = 256,
        rpn_positive_fraction: float = 0.5,
        pre_nms_top_n: tuple[int, int] = (1000, 500),
        post_nms_top_n: tuple[int, int] = (500, 300),
        rpn_nms_thresh: float = 0.7,
        min_size: float = 1e-3,
        box_batch_size: int = 128,
        box_positive_fraction: float = 0.25,
        score_thresh: float = 0.05,
        nms_thresh: float = 0.5,
        detections_per_img: int = 100,
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 8)
        self.pooler = "align"
        self.bg_low = 0.0
        self._init_heads(
            width,
            hidden,
            pool_size,
            box_batch_size,
            box_positive_fraction,
            score_thresh,
            nms_thresh,
            detections_per_img,
        )
        self.anchor_generator = AnchorGenerator(
            _sequence(anchor_sizes, "anchor_sizes"),
            _sequence(aspect_ratios, "aspect_ratios"),
            offset=0.5,
        )
        a = self.anchor_generator.num_anchors_per_location()[0]
        c = self.backbone.out_channels[-1]
        self.rpn_conv = nn.Conv2d(c, c, 3, padding=1)
        self.rpn_cls = nn.Conv2d(c, a, 1)
        self.rpn_bbox = nn.Conv2d(c, 4 * a, 1)
        for layer in (self.rpn_conv, self.rpn_cls, self.rpn_bbox):
            _init_conv(layer, 0.0)
        self.rpn_coder = BoxCoder((1.0, 1.0, 1.0, 1.0))
        self.rpn_fg_iou = check_real(rpn_fg_iou, "rpn_fg_iou", 0.0, 1.0)
        self.rpn_bg_iou = check_real(rpn_bg_iou, "rpn_bg_iou", 0.0, self.rpn_fg_iou)
        self.rpn_batch_size = check_count(rpn_batch_size, "rpn_batch_size", 1, 1 << 20)
        self.rpn_positive_fraction = check_real(
            rpn_positive_fraction, "rpn_positive_fraction", 0.0, 1.0
        )
        self.pre_nms_top_n = _pair(pre_nms_top_n, "pre_nms_top_n")
        self.post_nms_top_n = _pair(post_nms_top_n, "post_nms_top_n")
        self.rpn_nms_thresh = check_real(rpn_nms_thresh, "rpn_nms_thresh", 0.0, 1.0)
        self.min_size = check_real(min_size, "min_size", 0.0)

    def rpn(
        self, feats: torch.Tensor, image_shape: tuple[int, int]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Objectness logits ``(N, A_total)``, deltas ``(N, A_total, 4)`` and the anchors
        ``(A_total, 4)`` (ordered cell-major, as :class:`AnchorGenerator`)."""
        h = F.relu(self.rpn_conv(feats))
        n, _, fh, fw = h.shape
        obj = self.rpn_cls(h).permute(0, 2, 3, 1).reshape(n, -1)
        reg = self.rpn_bbox(h).reshape(n, -1, 4, fh, fw).permute(0, 3, 4, 1, 2).reshape(n, -1, 4)
        anchors = self.anchor_generator(image_shape, [(fh, fw)], dtype=h.dtype).to(h.device)
        return obj, reg, anchors

    @torch.no_grad()
    def rpn_outputs(self, images: Any) -> list[dict[str, torch.Tensor]]:
        """What the region proposal network makes of ``images`` (eval-mode counts):
        per image, ``"objectness"`` ``(h, w, A)`` sigmoid probabilities of the ``A``
        anchors at each cell of the stride-8 feature map (of the padded batch),
        ``"anchors"`` ``(h, w, A, 4)`` ``xyxy``, and ``"proposals"`` ``(P, 4)`` with
        their ``"proposal_scores"`` ``(P,)`` (logits) after NMS, best first.
        """
        was = self.training
        self.eval()
        try:
            batch, sizes, _ = self._prepare(images, None)
            feats = self.backbone(batch)[-1]
            obj, reg, anchors = self.rpn(feats, (int(batch.shape[2]), int(batch.shape[3])))
            props, scores = self.proposals(obj, reg, anchors, sizes)
        finally:
            self.train(was)
        fh, fw = int(feats.shape[2]), int(feats.shape[3])
        return [
            {
                "objectness": torch.sigmoid(obj[i]).reshape(fh, fw, -1),
                "anchors": anchors.reshape(fh, fw, -1, 4),
                "proposals": props[i],
                "proposal_scores": scores[i],
            }
            for i in range(len(sizes))
        ]

    def rpn_losses(
        self,
        obj: torch.Tensor,
        reg: torch.Tensor,
        anchors: torch.Tensor,
        targets: list[dict[str, torch.Tensor]],
    ) -> dict[str, torch.Tensor]:
        """The RPN's two losses over the anchors sampled from each image."""
        sel_obj, sel_lab, sel_reg, sel_tgt, n_sampled = [], [], [], [], 0
        for i, t in enumerate(targets):
            gt = t["boxes"].to(anchors.dtype)
            lab, matched = match_boxes(
                box_iou(gt, anchors), self.rpn_fg_iou, self.rpn_bg_iou, allow_low_quality=True
            )
            pos, neg = sample_balanced(lab, self.rpn_batch_size, self.rpn_positive_fraction)
            keep = pos | neg
            n_sampled += int(keep.sum())
            sel_obj.append(obj[i][keep])
            sel_lab.append(pos[keep].to(obj.dtype))
            if bool(pos.any()):
                sel_reg.append(reg[i][pos])
                sel_tgt.append(self.rpn_coder.encode(gt[matched[pos]], anchors[pos]))
        o = torch.cat(sel_obj)
        loss_obj = (
            F.binary_cross_entropy_with_logits(o, torch.cat(sel_lab))
            if o.numel()
            else obj.sum() * 0
        )
        if sel_reg:
            loss_box = F.smooth_l1_loss(
                torch.cat(sel_reg), torch.cat(sel_tgt), beta=1.0 / 9, reduction="sum"
            ) / max(n_sampled, 1)
        else:
            loss_box = reg.sum() * 0.0
        return {"loss_rpn_objectness": loss_obj, "loss_rpn_box": loss_box}

    def proposals(
        self,
        obj: torch.Tensor,
        reg: torch.Tensor,
        anchors: torch.Tensor,
        sizes: list[tuple[int, int]],
    ) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Per image: top ``pre_nms_top_n`` anchors by objectness, decoded, clipped,
        small boxes removed, NMS, top ``post_nms_top_n``; returns the proposals and
        their objectness logits (detached)."""
        mode = 0 if self.training else 1
        pre, post = self.pre_nms_top_n[mode], self.post_nms_top_n[mode]
        obj, reg = obj.detach(), reg.detach()
        boxes_out, scores_out = [], []
        for i, size in enumerate(sizes):
            k = min(pre, obj.shape[1])
            s, idx = obj[i].topk(k)
            b = _clip(self.rpn_coder.decode(reg[i][idx], anchors[idx]), size)
            keep = (b[:, 2] - b[:, 0] >= self.min_size) & (b[:, 3] - b[:, 1] >= self.min_size)
            b, s = b[keep], s[keep]
            kept = nms(b, s, self.rpn_nms_thresh)[:post]
            boxes_out.append(b[kept])
            scores_out.append(s[kept])
        return boxes_out, scores_out

    def forward(
        self, images: Any, targets: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing targets in train
            mode; boxes not (K, 4) float, with NaN or of zero width or height; labels not
            int64 or out of range.
        """
        batch, sizes, tgts = self._prepare(images, targets)
        feats = self.backbone(batch)[-1]
        obj, reg, anchors = self.rpn(feats, (int(batch.shape[2]), int(batch.shape[3])))
        props, _ = self.proposals(obj, reg, anchors, sizes)
        if self.training:
            assert tgts is not None
            losses = self.rpn_losses(obj, reg, anchors, tgts)
            head = self._run_heads(feats, props, sizes, tgts)
            assert isinstance(head, dict)
            losses.update(head)
            return losses
        return self._run_heads(feats, props, sizes, None)


# --------------------------------------------------------------------------- Mask R-CNN
class _MaskHead(nn.Module):
    """``convs`` 3 x 3 convolutions with ReLU, a 2 x 2 stride-2 transposed convolution
    with ReLU, and a 1 x 1 convolution to one mask logit map per class (torchvision's
    MaskRCNNHeads + MaskRCNNPredictor, with fewer channels)."""

    def __init__(self, in_channels: int, channels: int, convs: int, num_classes: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        c = in_channels
        for _ in range(convs):
            layers += [nn.Conv2d(c, channels, 3, padding=1), nn.ReLU()]
            c = channels
        self.convs = nn.Sequential(*layers)
        self.up = nn.ConvTranspose2d(c, channels, 2, stride=2)
        self.logits = nn.Conv2d(channels, num_classes, 1)
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                nn.init.zeros_(m.bias)  # type: ignore[arg-type]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logits(F.relu(self.up(self.convs(x))))


def _check_masks_target(t: Mapping[str, Any], i: int, size: tuple[int, int]) -> torch.Tensor:
    m = t.get("masks")
    k = int(t["boxes"].shape[0])
    if m is None:
        raise InputError(
            f"targets[{i}] has no 'masks': Mask R-CNN trains on instance masks, a (K, H, W) "
            "uint8 or bool tensor per image (e.g. procedural_detection_set's)"
        )
    if not isinstance(m, torch.Tensor) or tuple(m.shape) != (k, *size):
        raise InputError(
            f"targets[{i}]['masks'] must be ({k}, {size[0]}, {size[1]}): one mask of the "
            f"image's size per box; got {plain_repr(m)}"
        )
    if m.is_floating_point() and not bool(torch.isfinite(m).all()):
        raise InputError(f"targets[{i}]['masks'] has NaN or inf")
    return m


class MaskRCNN(FasterRCNN):
    r"""Mask R-CNN (He et al. 2017): :class:`FasterRCNN` with a mask branch beside its
    box head.

    The mask branch pools each region with RoI Align (``aligned=True``, pixel centres
    at half-integers) to ``mask_pool_size`` cells of the stride-8 features, runs
    ``mask_convs`` 3 x 3 convolutions of ``mask_channels``, a 2 x 2 stride-2 transposed
    convolution and a 1 x 1 convolution to :math:`C` logit maps of side
    :math:`M = 2\,` ``mask_pool_size`` (28 by default): one mask per class, decoupled
    from the classification (no competition between classes).

    Training adds ``loss_mask`` to the four losses of :class:`FasterRCNN`: for each
    sampled foreground region :math:`r` with ground-truth class :math:`k` and matched
    instance mask :math:`G`, the target :math:`T` is :math:`G` RoI-aligned to
    :math:`M \times M` over the region (soft values in [0, 1], as torchvision's
    ``project_masks_on_boxes``), and the loss is the mean per-pixel binary cross
    entropy :math:`-\overline{T \log \sigma(z_k) + (1 - T) \log(1 - \sigma(z_k))}` of
    the class-:math:`k` map only (0 without foreground regions).

    At inference the final boxes go through the mask branch, the map of each box's
    predicted class is passed through the sigmoid and pasted into the image
    (:func:`~robopercept.nn.ops.boxes.paste_masks`).

    Parameters
    ----------
    num_classes : int
    mask_pool_size : int
        RoI Align side of the mask branch (14: 28 x 28 masks).
    mask_channels, mask_convs : int
        Width and depth of the mask branch (torchvision: 256 and 4).
    **settings
        Those of :class:`FasterRCNN`.

    Returns (eval mode)
    -------------------
    Per image ``{"boxes", "labels", "scores", "masks"}``, ``"masks"`` ``(D, 1, H, W)``
    float probabilities (torchvision's layout: threshold at 0.5 for binary masks).

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = MaskRCNN(2, width=8, hidden=32, mask_channels=8, mask_convs=1)
    >>> masks = torch.zeros(1, 32, 32, dtype=torch.uint8); masks[0, 4:28, 4:20] = 1
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1]),
    ...       "masks": masks}]
    >>> sorted(m([torch.rand(3, 32, 32)], t))[:2]
    ['loss_box', 'loss_classifier']
    >>> "loss_mask" in m([torch.rand(3, 32, 32)], t)
    True
    """

    def __init__(
        self,
        num_classes: int,
        *,
        mask_pool_size: int = 14,
        mask_channels: int = 64,
        mask_convs: int = 4,
        **settings: Any,
    ) -> None:
        super().__init__(num_classes, **settings)
        self.mask_pool_size = check_count(mask_pool_size, "mask_pool_size", 1, 64)
        self.mask_resolution = 2 * self.mask_pool_size
        channels = check_count(mask_channels, "mask_channels", 1, MAX_CHANNELS)
        convs = check_count(mask_convs, "mask_convs", 0, 16)
        self.mask_head = _MaskHead(self.backbone.out_channels[-1], channels, convs, num_classes)

    def mask_logits(self, feats: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        """``(R, C, M, M)`` mask logits of the regions ``rois`` (one list entry per image,
        ``xyxy`` pixels) on the stride-8 features."""
        pooled = roi_align(
            feats,
            rois,
            self.mask_pool_size,
            1.0 / self.backbone.strides[-1],
            sampling_ratio=2,
            aligned=True,
        )
        return self.mask_head(pooled)

    def mask_targets(
        self, rois: torch.Tensor, masks: torch.Tensor, matched: torch.Tensor
    ) -> torch.Tensor:
        """``(R, M, M)`` soft targets: instance mask ``masks[matched[r]]`` RoI-aligned over
        region ``rois[r]`` (``aligned=True``, 2 x 2 samples per cell)."""
        if rois.shape[0] == 0:
            return rois.new_zeros((0, self.mask_resolution, self.mask_resolution))
        rows = torch.cat((matched.to(rois.dtype)[:, None], rois), dim=1)
        m = masks.to(rois.dtype)[:, None]
        return roi_align(m, rows, self.mask_resolution, 1.0, sampling_ratio=2, aligned=True)[:, 0]

    def _region_losses(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        tgts: list[dict[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        gt_masks = [
            _check_masks_target(t, i, s) for i, (t, s) in enumerate(zip(tgts, sizes, strict=True))
        ]
        fg = [lab > 0 for lab in labels]
        fg_labels = torch.cat([lab[f] for lab, f in zip(labels, fg, strict=True)])
        if fg_labels.numel() == 0:
            # zero, with a graph through the mask branch (as torchvision's)
            zero = torch.stack([p.sum() for p in self.mask_head.parameters()]).sum() * 0.0
            return {"loss_mask": zero}
        z = self.mask_logits(feats, [r[f] for r, f in zip(rois, fg, strict=True)])
        z = z[torch.arange(z.shape[0], device=z.device), fg_labels - 1]
        target = torch.cat(
            [
                self.mask_targets(r[f], gm, mt[f])
                for r, f, gm, mt in zip(rois, fg, gt_masks, matched, strict=True)
            ]
        )
        return {"loss_mask": F.binary_cross_entropy_with_logits(z, target)}

    def _region_outputs(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        dets: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        boxes = [d["boxes"] for d in dets]
        if not sum(b.shape[0] for b in boxes):
            for d, size in zip(dets, sizes, strict=True):
                d["masks"] = feats.new_zeros((0, 1, *size))
            return dets
        z = self.mask_logits(feats, boxes)
        start = 0
        for d, size in zip(dets, sizes, strict=True):
            k = d["boxes"].shape[0]
            zi = z[start : start + k]
            start += k
            probs = torch.sigmoid(zi[torch.arange(k, device=zi.device), d["labels"] - 1])
            d["masks"] = paste_masks(probs, d["boxes"].detach(), size)[:, None]
        return dets


class _KeypointHead(nn.Module):
    """``convs`` 3 x 3 convolutions with ReLU and a 4 x 4 stride-2 transposed convolution
    to one logit map per keypoint (torchvision's KeypointRCNNHeads +
    KeypointRCNNPredictor, with fewer channels and without the final 2x bilinear
    upsampling)."""

    def __init__(self, in_channels: int, channels: int, convs: int, num_keypoints: int) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        c = in_channels
        for _ in range(convs):
            layers += [nn.Conv2d(c, channels, 3, padding=1), nn.ReLU()]
            c = channels
        self.convs = nn.Sequential(*layers)
        self.logits = nn.ConvTranspose2d(c, num_keypoints, 4, stride=2, padding=1)
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                nn.init.zeros_(m.bias)  # type: ignore[arg-type]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logits(self.convs(x))


def _check_keypoints_target(t: Mapping[str, Any], i: int, j: int) -> torch.Tensor:
    kp = t.get("keypoints")
    k = int(t["boxes"].shape[0])
    if kp is None:
        raise InputError(
            f"targets[{i}] has no 'keypoints': Keypoint R-CNN trains on a (K, J, 3) float "
            "tensor of (x, y, v) per box (e.g. procedural_pose_scenes')"
        )
    if not isinstance(kp, torch.Tensor) or tuple(kp.shape) != (k, j, 3):
        raise InputError(
            f"targets[{i}]['keypoints'] must be ({k}, {j}, 3): {j} keypoints (x, y, v) per "
            f"box; got {plain_repr(kp)}"
        )
    return kp


class KeypointRCNN(FasterRCNN):
    r"""Keypoint R-CNN (He et al. 2017, section 5): :class:`FasterRCNN` with a keypoint
    branch beside its box head, for several people per image.

    The branch pools each region with RoI Align (``aligned=True``) to
    ``keypoint_pool_size`` cells of the stride-8 features, runs ``keypoint_convs``
    3 x 3 convolutions of ``keypoint_channels`` and a 4 x 4 stride-2 transposed
    convolution to :math:`J` logit maps of side :math:`M = 2\,` ``keypoint_pool_size``.
    Each keypoint is a *one-hot mask*: its target is the single cell of the
    :math:`M \times M` grid over the region that contains it,
    :math:`(\lfloor (x - x_1) M / w \rfloor, \lfloor (y - y_1) M / h \rfloor)` (as
    torchvision's ``keypoints_to_heatmap``), and ``loss_keypoint`` is the cross
    entropy of the softmax over the :math:`M^2` cells, averaged over the labelled
    keypoints (``v > 0``) that fall inside their sampled foreground region (0 when
    there are none).

    At inference each final box's maps go through a softmax over the cells and are
    decoded by :func:`~robopercept.nn.pose.networks.decode_heatmaps` (the argmax cell refined by
    the parabola through the log-probabilities), mapped back into the box:
    :math:`x = x_1 + \hat u\, w / M` with :math:`\hat u` the decoded position in cell
    units (cell centres at :math:`j + \tfrac12`).

    Parameters
    ----------
    num_classes : int
    num_keypoints : int
    keypoint_pool_size : int
        RoI Align side (14: 28 x 28 maps).
    keypoint_channels, keypoint_convs : int
        Width and depth of the branch (torchvision: 512 and 8).
    **settings
        Those of :class:`FasterRCNN`.

    Returns (eval mode)
    -------------------
    Per image ``{"boxes", "labels", "scores", "keypoints", "keypoints_scores"}``:
    ``"keypoints"`` ``(D, J, 3)`` rows ``(x, y, 1)`` (torchvision's layout),
    ``"keypoints_scores"`` ``(D, J)`` the peak softmax probability.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = KeypointRCNN(1, num_keypoints=2, width=8, hidden=32, keypoint_channels=8,
    ...                  keypoint_convs=1)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1]),
    ...       "keypoints": torch.tensor([[[8.0, 9, 2], [15, 20, 2]]])}]
    >>> "loss_keypoint" in m([torch.rand(3, 32, 32)], t)
    True
    """

    def __init__(
        self,
        num_classes: int,
        *,
        num_keypoints: int = 16,
        keypoint_pool_size: int = 14,
        keypoint_channels: int = 64,
        keypoint_convs: int = 4,
        **settings: Any,
    ) -> None:
        super().__init__(num_classes, **settings)
        self.num_keypoints = check_count(num_keypoints, "num_keypoints", 1, 1024)
        self.keypoint_pool_size = check_count(keypoint_pool_size, "keypoint_pool_size", 1, 64)
        self.keypoint_resolution = 2 * self.keypoint_pool_size
        channels = check_count(keypoint_channels, "keypoint_channels", 1, MAX_CHANNELS)
        convs = check_count(keypoint_convs, "keypoint_convs", 0, 16)
        self.keypoint_head = _KeypointHead(
            self.backbone.out_channels[-1], channels, convs, self.num_keypoints
        )

    def keypoint_logits(self, feats: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        """``(R, J, M, M)`` keypoint logits of the regions ``rois`` (one list entry per
        image, ``xyxy`` pixels)."""
        pooled = roi_align(
            feats,
            rois,
            self.keypoint_pool_size,
            1.0 / self.backbone.strides[-1],
            sampling_ratio=2,
            aligned=True,
        )
        return self.keypoint_head(pooled)

    def keypoint_targets(
        self, rois: torch.Tensor, keypoints: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The one-hot targets of keypoints ``(R, J, 3)`` in regions ``rois`` ``(R, 4)``:
        the flat cell index ``(R, J)`` (row ``M + column``) and whether it counts
        (labelled and inside the region)."""
        m = self.keypoint_resolution
        x1, y1 = rois[:, 0:1], rois[:, 1:2]
        w = (rois[:, 2:3] - x1).clamp_min(1e-6)
        h = (rois[:, 3:4] - y1).clamp_min(1e-6)
        cx = torch.floor((keypoints[..., 0] - x1) * m / w)
        cy = torch.floor((keypoints[..., 1] - y1) * m / h)
        valid = (keypoints[..., 2] > 0) & (cx >= 0) & (cx < m) & (cy >= 0) & (cy < m)
        index = (cy.clamp(0, m - 1) * m + cx.clamp(0, m - 1)).long()
        return index, valid

    def _region_losses(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        tgts: list[dict[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        gt = [_check_keypoints_target(t, i, self.num_keypoints) for i, t in enumerate(tgts)]
        fg = [lab > 0 for lab in labels]
        idx, val = [], []
        for r, f, g, mt in zip(rois, fg, gt, matched, strict=True):
            i, v = self.keypoint_targets(r[f], g.to(r.dtype)[mt[f]])
            idx.append(i)
            val.append(v)
        index, valid = torch.cat(idx), torch.cat(val)
        if not bool(valid.any()):
            zero = torch.stack([p.sum() for p in self.keypoint_head.parameters()]).sum() * 0.0
            return {"loss_keypoint": zero}
        z = self.keypoint_logits(feats, [r[f] for r, f in zip(rois, fg, strict=True)])
        z = z.flatten(2)  # (R, J, M^2)
        return {"loss_keypoint": F.cross_entropy(z[valid], index[valid])}

    def _region_outputs(
        self,
        feats: torch.Tensor,
        sizes: list[tuple[int, int]],
        dets: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        from robopercept.nn.pose.networks import decode_heatmaps

        j, m = self.num_keypoints, self.keypoint_resolution
        boxes = [d["boxes"] for d in dets]
        if not sum(b.shape[0] for b in boxes):
            for d in dets:
                d["keypoints"] = feats.new_zeros((0, j, 3))
                d["keypoints_scores"] = feats.new_zeros((0, j))
            return dets
        z = self.keypoint_logits(feats, boxes)
        probs = torch.softmax(z.flatten(2), -1).reshape(z.shape)
        cells, score = decode_heatmaps(probs.detach(), 1, "quadratic")
        cells_t = torch.as_tensor(cells, dtype=feats.dtype, device=feats.device)
        score_t = torch.as_tensor(score, dtype=feats.dtype, device=feats.device)
        start = 0
        for d in dets:
            b = d["boxes"].detach()
            k = b.shape[0]
            c = cells_t[start : start + k]
            w = (b[:, 2] - b[:, 0])[:, None]
            h = (b[:, 3] - b[:, 1])[:, None]
            x = b[:, 0:1] + c[..., 0] * w / m
            y = b[:, 1:2] + c[..., 1] * h / m
            d["keypoints"] = torch.stack([x, y, torch.ones_like(x)], -1)
            d["keypoints_scores"] = score_t[start : start + k]
            start += k
        return dets


def _init_conv(layer: nn.Conv2d, bias: float) -> None:
    """Weights ~ N(0, 0.01^2) and a constant bias (torchvision's RPN and FCOS heads)."""
    nn.init.normal_(layer.weight, std=0.01)
    if layer.bias is not None:
        nn.init.constant_(layer.bias, bias)


def _sequence(value: Any, name: str) -> tuple[Any, ...]:
    if not isinstance(value, (tuple, list)) or not value:
        raise InputError(
            f"{name} must be a non-empty tuple of positive numbers; got {plain_repr(value)}"
        )
    return tuple(value)


def _pair(value: Any, name: str) -> tuple[int, int]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"{name} must be a (train, eval) pair of ints; got {plain_repr(value)}")
    a, b = (check_count(v, name, 1, 1 << 20) for v in value)
    return a, b


# --------------------------------------------------------------------------- (d) FCOS
class FCOS(_Detector):
    r"""FCOS (Tian et al. 2019): anchor-free single-stage detection on an FPN (strides 8
    and 16 by default).

    A location :math:`(x, y) = ((j + \tfrac12) s, (i + \tfrac12) s)` of a level of
    stride :math:`s` is assigned to a ground-truth box when it lies inside the box and
    within ``center_radius`` :math:`\cdot s` of its centre (centre sampling), and when
    :math:`m = \max(l, t, r, b)` of its distances to the sides is in the level's range
    :math:`[4 s, 8 s]` (0 below the first level, no upper bound on the last); among
    several boxes, the one of smallest area (torchvision's FCOS rules). Per location
    the head predicts class logits (sigmoid focal loss, summed over all locations and
    divided by the number of foreground ones), :math:`(l, t, r, b) / s` through a ReLU
    (torchvision's) or the paper's :math:`\exp(s_l x)` with a learnable scale
    :math:`s_l` per level (``box_activation``; GIoU loss of the decoded box, foreground
    only) and a centerness logit with target
    :math:`\sqrt{\frac{\min(l, r)}{\max(l, r)} \frac{\min(t, b)}{\max(t, b)}}`
    (binary cross-entropy, foreground only). Eval: score
    :math:`\sqrt{\sigma(c) \sigma(o)}`, threshold, top ``topk_candidates`` per level,
    clip, per-class NMS, the ``detections_per_img`` best.

    Parameters
    ----------
    num_classes : int
    width : int
        Backbone width.
    strides : sequence of int
        FPN levels.
    head_channels : int
        FPN and head width.
    blocks : int
        Residual blocks per backbone stage (:class:`DetectionBackbone`).
    num_convs : int
        3 x 3 convolution + GroupNorm + ReLU layers in each of the two towers (class
        and box) before their outputs: 2 here by default, 4 in torchvision's
        ``FCOSHead`` and the paper.
    center_radius : float
    box_activation : {"relu", "exp"}
        ``"relu"`` (the default, torchvision's) can die: once every pre-activation of
        the box branch is negative, every box has zero size and no gradient flows back
        (seen with flips and quarter turns on the shapes set). ``"exp"`` cannot (its
        gradient is never zero) and starts every side at one stride.
    centerness_weighted : bool
        Weight each foreground location's GIoU loss by its centerness target and
        divide by their sum (FCOS v2, Tian et al. 2020), instead of the plain mean:
        the box is learnt best where the score (which includes the centerness) makes
        it survive NMS.
    quality : {"centerness", "iou"}
        The target of the third branch: the centerness above (the paper's), or the IoU
        of the location's decoded box with its ground-truth box, detached (the IoU
        prediction of IoU-aware detectors, Wu et al. 2020, and of YOLOX's objectness):
        the score then ranks boxes by how well they are placed, not by where the
        location sits in the box. Eval is the same for both.
    score_thresh, nms_thresh, topk_candidates, detections_per_img
        Post-processing.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = FCOS(2, width=8, head_channels=16)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1])}]
    >>> sorted(m([torch.rand(3, 32, 32)], t))
    ['bbox_ctrness', 'bbox_regression', 'classification']
    """

    def __init__(
        self,
        num_classes: int,
        *,
        width: int = 16,
        strides: Sequence[int] = (8, 16),
        head_channels: int = 64,
        blocks: int = 1,
        num_convs: int = 2,
        center_radius: float = 1.5,
        box_activation: str = "relu",
        centerness_weighted: bool = False,
        quality: str = "centerness",
        score_thresh: float = 0.2,
        nms_thresh: float = 0.6,
        topk_candidates: int = 1000,
        detections_per_img: int = 100,
    ) -> None:
        super().__init__()
        head_channels = check_count(head_channels, "head_channels", 2, MAX_CHANNELS)
        self.backbone = DetectionBackbone(width, strides, fpn_channels=head_channels, blocks=blocks)
        self._init_common(num_classes, max(self.backbone.strides))
        c = head_channels
        # GroupNorm with 8 groups (fewer where the channels do not divide), each of at
        # least 2 channels: a group of one channel on a 1 x 1 map (a tiny image at the
        # coarsest stride) has one value and no variance, and torch refuses it
        groups = math.gcd(c, 8)
        while groups > 1 and c // groups < 2:
            groups //= 2

        self.num_convs = check_count(num_convs, "num_convs", 1, 16)

        def tower() -> nn.Sequential:
            layers: list[nn.Module] = []
            for _ in range(self.num_convs):
                layers += [nn.Conv2d(c, c, 3, padding=1), nn.GroupNorm(groups, c), nn.ReLU()]
            return nn.Sequential(*layers)

        self.cls_tower = tower()
        self.reg_tower = tower()
        self.cls_logits = nn.Conv2d(c, self.num_classes, 3, padding=1)
        self.bbox_reg = nn.Conv2d(c, 4, 3, padding=1)
        self.bbox_ctrness = nn.Conv2d(c, 1, 3, padding=1)
        for layer in (self.bbox_reg, self.bbox_ctrness):
            _init_conv(layer, 0.0)
        # the prior: every location starts at foreground probability 0.01 (RetinaNet)
        _init_conv(self.cls_logits, -math.log((1 - 0.01) / 0.01))
        self.center_radius = check_real(center_radius, "center_radius", 0.0, low_inclusive=False)
        if box_activation not in ("relu", "exp"):
            raise InputError(
                f"box_activation must be 'relu' or 'exp'; got {plain_repr(box_activation)}"
            )
        self.box_activation = box_activation
        self.centerness_weighted = check_bool(centerness_weighted, "centerness_weighted")
        check_choice(quality, "quality", ("centerness", "iou"))
        self.quality = quality
        if box_activation == "exp":
            # the paper's exp(s_l x): one learnable scale per level, starting at 1
            self.scales = nn.Parameter(torch.ones(len(self.backbone.strides)))
        self.score_thresh = check_real(score_thresh, "score_thresh", 0.0, 1.0)
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.topk_candidates = check_count(topk_candidates, "topk_candidates", 1, 1 << 20)
        self.detections_per_img = check_count(detections_per_img, "detections_per_img", 1, 1 << 20)

    def head(
        self, feats: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, list[int]]:
        """Per location of all levels (concatenated): class logits ``(N, L, C)``, ltrb /
        stride ``(N, L, 4)``, centerness logits ``(N, L)``, the locations ``(L, 2)``,
        their strides ``(L,)`` and the number of locations per level."""
        cls, reg, ctr, locs, strides, counts = [], [], [], [], [], []
        for level, (f, s) in enumerate(zip(feats, self.backbone.strides, strict=True)):
            n, _, fh, fw = f.shape
            ct, rt = self.cls_tower(f), self.reg_tower(f)
            cls.append(self.cls_logits(ct).permute(0, 2, 3, 1).reshape(n, -1, self.num_classes))
            r = self.bbox_reg(rt)
            if self.box_activation == "exp":
                # clamped so that exp cannot overflow: ltrb <= e^8 strides
                r = torch.exp((self.scales[level] * r).clamp(max=8.0))
            else:
                r = F.relu(r)
            reg.append(r.permute(0, 2, 3, 1).reshape(n, -1, 4))
            ctr.append(self.bbox_ctrness(rt).reshape(n, -1))
            ys = (torch.arange(fh, device=f.device, dtype=f.dtype) + 0.5) * s
            xs = (torch.arange(fw, device=f.device, dtype=f.dtype) + 0.5) * s
            yy, xx = torch.meshgrid(ys, xs, indexing="ij")
            locs.append(torch.stack((xx, yy), dim=-1).reshape(-1, 2))
            strides.append(torch.full((fh * fw,), float(s), device=f.device, dtype=f.dtype))
            counts.append(fh * fw)
        return (
            torch.cat(cls, 1),
            torch.cat(reg, 1),
            torch.cat(ctr, 1),
            torch.cat(locs),
            torch.cat(strides),
            counts,
        )

    def assign(
        self, locs: torch.Tensor, strides: torch.Tensor, counts: list[int], gt: torch.Tensor
    ) -> torch.Tensor:
        """Index of the ground-truth box of each location, -1 for background."""
        n = locs.shape[0]
        if gt.shape[0] == 0:
            return torch.full((n,), -1, dtype=torch.int64, device=locs.device)
        x, y = locs[:, 0, None], locs[:, 1, None]
        ltrb = torch.stack((x - gt[:, 0], y - gt[:, 1], gt[:, 2] - x, gt[:, 3] - y), dim=-1)
        inside = ltrb.min(dim=-1).values > 0
        cx, cy = (gt[:, 0] + gt[:, 2]) / 2, (gt[:, 1] + gt[:, 3]) / 2
        r = self.center_radius * strides[:, None]
        center = ((x - cx).abs() < r) & ((y - cy).abs() < r)
        m = ltrb.max(dim=-1).values
        lower = strides * 4
        upper = strides * 8
        lower[: counts[0]] = 0
        upper[n - counts[-1] :] = math.inf
        ok = inside & center & (m >= lower[:, None]) & (m <= upper[:, None])
        area = ((gt[:, 2] - gt[:, 0]) * (gt[:, 3] - gt[:, 1]))[None].expand(n, -1)
        area = torch.where(ok, area, torch.full_like(area, math.inf))
        best, idx = area.min(dim=1)
        idx[torch.isinf(best)] = -1
        return idx

    def forward(
        self, images: Any, targets: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing targets in train
            mode; boxes not (K, 4) float, with NaN or of zero width or height; labels not
            int64 or out of range.
        """
        batch, sizes, tgts = self._prepare(images, targets)
        feats = self.backbone(batch)
        cls, reg, ctr, locs, strides, counts = self.head(feats)
        if self.training:
            assert tgts is not None
            return self._losses(cls, reg, ctr, locs, strides, counts, tgts)
        return self._postprocess(cls, reg, ctr, locs, strides, counts, sizes)

    def _decode(self, reg: torch.Tensor, locs: torch.Tensor, strides: torch.Tensor) -> torch.Tensor:
        d = reg * strides[:, None]
        return torch.stack(
            (
                locs[:, 0] - d[:, 0],
                locs[:, 1] - d[:, 1],
                locs[:, 0] + d[:, 2],
                locs[:, 1] + d[:, 3],
            ),
            dim=1,
        )

    def _losses(
        self,
        cls: torch.Tensor,
        reg: torch.Tensor,
        ctr: torch.Tensor,
        locs: torch.Tensor,
        strides: torch.Tensor,
        counts: list[int],
        tgts: list[dict[str, torch.Tensor]],
    ) -> dict[str, torch.Tensor]:
        cls_t = torch.zeros_like(cls)
        fg_pred, fg_gt, fg_ctr, fg_ctr_t = [], [], [], []
        for i, t in enumerate(tgts):
            gt = t["boxes"].to(locs.dtype)
            idx = self.assign(locs, strides, counts, gt)
            fg = idx >= 0
            if not bool(fg.any()):
                continue
            g = gt[idx[fg]]
            cls_t[i, fg, t["labels"][idx[fg]] - 1] = 1.0
            fg_pred.append(self._decode(reg[i][fg], locs[fg], strides[fg]))
            fg_gt.append(g)
            lo = locs[fg]
            l_, t_ = lo[:, 0] - g[:, 0], lo[:, 1] - g[:, 1]
            r_, b_ = g[:, 2] - lo[:, 0], g[:, 3] - lo[:, 1]
            ctr_t = torch.sqrt(
                (torch.minimum(l_, r_) / torch.maximum(l_, r_))
                * (torch.minimum(t_, b_) / torch.maximum(t_, b_))
            )
            fg_ctr.append(ctr[i][fg])
            fg_ctr_t.append(ctr_t)
        n_fg = max(1, sum(p.shape[0] for p in fg_pred))
        loss_cls = sigmoid_focal_loss(cls, cls_t, reduction="sum") / n_fg
        if fg_pred:
            pred, gtb = torch.cat(fg_pred), torch.cat(fg_gt)
            giou = torch.diagonal(generalized_box_iou(pred, gtb)) if pred.shape[0] else pred.sum(1)
            centerness = torch.cat(fg_ctr_t)
            if self.centerness_weighted:
                w = centerness
                loss_reg = ((1 - giou) * w).sum() / w.sum().clamp(min=1e-6)
            else:
                loss_reg = (1 - giou).sum() / n_fg
            if self.quality == "iou":
                target = torch.diagonal(box_iou(pred.detach(), gtb))
            else:
                target = centerness
            loss_ctr = (
                F.binary_cross_entropy_with_logits(torch.cat(fg_ctr), target, reduction="sum")
                / n_fg
            )
        else:
            loss_reg = reg.sum() * 0.0
            loss_ctr = ctr.sum() * 0.0
        return {"classification": loss_cls, "bbox_regression": loss_reg, "bbox_ctrness": loss_ctr}

    def _postprocess(
        self,
        cls: torch.Tensor,
        reg: torch.Tensor,
        ctr: torch.Tensor,
        locs: torch.Tensor,
        strides: torch.Tensor,
        counts: list[int],
        sizes: list[tuple[int, int]],
    ) -> list[dict[str, torch.Tensor]]:
        out = []
        c = self.num_classes
        for i, size in enumerate(sizes):
            scores_all = torch.sqrt(torch.sigmoid(cls[i]) * torch.sigmoid(ctr[i])[:, None])
            boxes_l, scores_l, labels_l = [], [], []
            start = 0
            for n in counts:
                sc = scores_all[start : start + n].reshape(-1)
                keep = torch.nonzero(sc > self.score_thresh).flatten()
                sc = sc[keep]
                if sc.numel() > self.topk_candidates:
                    sc, top = sc.topk(self.topk_candidates)
                    keep = keep[top]
                loc_idx = keep // c + start
                boxes_l.append(self._decode(reg[i][loc_idx], locs[loc_idx], strides[loc_idx]))
                scores_l.append(sc)
                labels_l.append(keep % c + 1)
                start += n
            boxes = _clip(torch.cat(boxes_l), size)
            scores, labels = torch.cat(scores_l), torch.cat(labels_l)
            ok = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
            boxes, scores, labels = boxes[ok], scores[ok], labels[ok]
            kept = batched_nms(boxes.detach(), scores.detach(), labels, self.nms_thresh)
            kept = kept[: self.detections_per_img]
            out.append({"boxes": boxes[kept], "labels": labels[kept], "scores": scores[kept]})
        return out


# --------------------------------------------------------------------------- test-time augmentation
#: the views of :class:`TestTimeAugmentation`: (hflip, vflip, quarter turns) per view
TTA_VIEWS: dict[str, tuple[tuple[bool, bool, int], ...]] = {
    "hflip": ((False, False, 0), (True, False, 0)),
    "flips": ((False, False, 0), (True, False, 0), (False, True, 0), (True, True, 0)),
    "dihedral": tuple((h, v, k) for h in (False, True) for v in (False, True) for k in (0, 1)),
    # hflip + vflip is a half turn, so these 8 are the whole dihedral group
}


class TestTimeAugmentation(nn.Module):
    r"""Test-time augmentation of any detector here: its detections on mirrored and
    turned copies of each image, mapped back and fused (ultralytics' ``augment=True``
    and mmdetection's TTA, with the fusion below).

    Each image is seen in :math:`V` views (:data:`TTA_VIEWS`: ``"hflip"`` the image and
    its mirror, ``"flips"`` the four mirrorings, ``"dihedral"`` those and their quarter
    turns, 8 views: for top-down images whose orientation means nothing). The wrapped
    model detects in every view (its own NMS included); the boxes are mapped back with
    :func:`~robopercept.nn.ops.boxes.dihedral_boxes` and pooled. Per class, greedy NMS at
    ``iou_thresh`` on the pool picks cluster heads; every pooled box joins the
    highest-scoring head it overlaps with IoU > ``iou_thresh`` (the head that
    suppressed it). A cluster :math:`C` gives one detection: the score-weighted mean
    box (box voting, Gidaris and Komodakis 2015) and the score

    .. math:: s_C = \frac{1}{V} \sum_{v=1}^{V} \max_{i \in C,\ \mathrm{view}(i) = v} s_i

    (0 for a view with no member): the mean over the views of the best score each gave,
    so an object seen in one view only is ranked down (as weighted boxes fusion does,
    Solovyev et al. 2021). The ``detections_per_img`` best are kept. The wrapper is
    built in eval mode (it refuses train mode); it puts the wrapped model in eval mode.

    Parameters
    ----------
    model : torch.nn.Module
        A detector of this module (any model with the torchvision eval contract).
    views : {"hflip", "flips", "dihedral"}
    iou_thresh : float, optional
        Clustering IoU in [0, 1]; default the model's ``nms_thresh`` (0.5 without one).
    detections_per_img : int, optional
        Default the model's (100 without one).

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> tta = TestTimeAugmentation(FCOS(2, width=8, head_channels=16), "flips").eval()
    >>> sorted(tta([torch.rand(3, 32, 48)])[0])
    ['boxes', 'labels', 'scores']
    """

    def __init__(
        self,
        model: nn.Module,
        views: str = "dihedral",
        *,
        iou_thresh: float | None = None,
        detections_per_img: int | None = None,
    ) -> None:
        super().__init__()
        self.model = check_module(model)
        check_choice(views, "views (--tta)", tuple(TTA_VIEWS))
        self.views = views
        thr = iou_thresh if iou_thresh is not None else getattr(model, "nms_thresh", 0.5)
        self.iou_thresh = check_real(thr, "iou_thresh", 0.0, 1.0)
        top = detections_per_img or getattr(model, "detections_per_img", 100)
        self.detections_per_img = check_count(top, "detections_per_img", 1, 1 << 20)
        self.eval()  # it only predicts

    def forward(self, images: Any, targets: Any = None) -> list[dict[str, torch.Tensor]]:
        """Fused detections of ``images`` (eval mode only).

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
        targets : None
            Refused: train the wrapped model, not this wrapper.

        Returns
        -------
        list of dict
            ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.
        """
        if self.training or targets is not None:
            raise InputError(
                "TestTimeAugmentation only predicts: train the wrapped model "
                "(tta.model), then call tta.eval()"
            )
        ims = _check_images(images)
        views = TTA_VIEWS[self.views]
        pooled: list[list[dict[str, torch.Tensor]]] = [[] for _ in ims]
        with torch.no_grad():
            for v, (hflip, vflip, k) in enumerate(views):
                seen = []
                for im in ims:
                    dims = [d for d, on in ((-1, hflip), (-2, vflip)) if on]
                    x = torch.flip(im, dims) if dims else im
                    seen.append(torch.rot90(x, k, (-2, -1)) if k else x)
                out = self.model(seen)
                for i, (im, det) in enumerate(zip(ims, out, strict=True)):
                    size = (int(im.shape[-2]), int(im.shape[-1]))
                    b = dihedral_boxes(
                        det["boxes"].float(),
                        size,
                        hflip=hflip,
                        vflip=vflip,
                        quarter_turns=k,
                        inverse=True,
                    )
                    view = torch.full_like(det["labels"], v)
                    pooled[i].append({**det, "boxes": b, "view": view})
        return [self._fuse(p, len(views)) for p in pooled]

    def predict(self, images: Any) -> list[dict[str, torch.Tensor]]:
        """Fused detections of ``images`` (eval mode; the mode is restored)."""
        was = self.training
        self.eval()
        try:
            return self(images)
        finally:
            self.train(was)

    def _fuse(self, dets: list[dict[str, torch.Tensor]], n_views: int) -> dict[str, torch.Tensor]:
        boxes = torch.cat([d["boxes"] for d in dets])
        scores = torch.cat([d["scores"] for d in dets]).float()
        labels = torch.cat([d["labels"] for d in dets])
        view = torch.cat([d["view"] for d in dets])
        if boxes.shape[0] == 0:
            return {"boxes": boxes, "labels": labels, "scores": scores}
        heads = batched_nms(boxes, scores, labels, self.iou_thresh)
        over = box_iou(boxes[heads], boxes) > self.iou_thresh
        over &= labels[heads][:, None] == labels[None]
        over[torch.arange(heads.numel()), heads] = True
        member = over.any(0)
        # heads are in decreasing score: the first overlapping head is the best one
        cluster = over.to(torch.uint8).argmax(0)[member]
        b, s, vw = boxes[member], scores[member], view[member]
        k = heads.numel()
        w = torch.zeros(k, dtype=s.dtype).index_add_(0, cluster, s)
        fused = torch.zeros(k, 4, dtype=b.dtype).index_add_(0, cluster, b * s[:, None])
        fused = torch.where(w[:, None] > 0, fused / w.clamp(min=1e-12)[:, None], boxes[heads])
        best = torch.zeros(k * n_views, dtype=s.dtype).scatter_reduce(
            0, cluster * n_views + vw, s, "amax"
        )
        score = best.view(k, n_views).sum(1) / n_views
        order = torch.argsort(score, descending=True, stable=True)[: self.detections_per_img]
        return {"boxes": fused[order], "labels": labels[heads][order], "scores": score[order]}


# --------------------------------------------------------------------------- train / evaluate
@dataclass
class DetectionHistory:
    """What :func:`train_detector` measured: per epoch, the mean of each loss over the
    batches (and of their sum, ``"loss"``), and the seconds it took; with a validation
    set, the validation figure at each evaluated epoch and the epoch that was kept.

    Attributes
    ----------
    losses : list of dict of str to float
    seconds : list of float
        Training seconds per epoch (validation not included).
    val : dict of int to float
        Epoch (1-based) -> validation ``val_metric`` (empty without ``val``).
    best_epoch : int
        The epoch whose weights the model holds at the end (the last epoch without
        ``val``).
    val_seconds : float
        Seconds spent evaluating the validation set.
    """

    losses: list[dict[str, float]] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    val: dict[int, float] = field(default_factory=dict)
    best_epoch: int = 0
    val_seconds: float = 0.0


#: validation figures :func:`train_detector` can select on: index into the COCO stats
VAL_METRICS = {"AP": 0, "AP50": 1, "AP75": 2}


def _detection_dataset(dataset: Any) -> Any:
    from robopercept.nn.detection.data import DetectionDataset

    if not isinstance(dataset, DetectionDataset):
        raise InputError(
            "dataset must be a DetectionDataset (procedural_detection_set, digits_detection_set, "
            f"deepforest_tiles, ...); got {type(dataset).__name__}"
        )
    if len(dataset) == 0:
        raise InputError("dataset is empty: give at least one image")
    return dataset


def train_detector(
    model: nn.Module,
    dataset: Any,
    config: Any = None,
    *,
    checkpoint: str | os.PathLike[str] | None = None,
    progress: bool = True,
    val: Any = None,
    val_every: int = 1,
    val_metric: str = "AP",
    augment: Callable[[torch.Tensor, dict[str, Any]], tuple[torch.Tensor, dict[str, Any]]]
    | None = None,
    ema: float | None = None,
    val_iou_type: str = "bbox",
    val_sigmas: Any = None,
) -> DetectionHistory:
    r"""Train a detector of this module (or any model keeping the torchvision detection
    contract) on a :class:`~robopercept.nn.detection.data.DetectionDataset`.

    Each step: a shuffled mini-batch of ``config.batch_size`` images (a generator seeded
    by ``config.seed``), the model's loss dict in train mode, their sum back-propagated,
    an optimizer step (``config.optimizer``, ``lr``, ``weight_decay``; gradient clipping
    with ``clip_grad_norm``) and, per epoch, the schedule of ``config.schedule``. Torch's
    global generator is seeded with ``config.seed`` first (weights are not re-initialized:
    build the model after your own ``torch.manual_seed`` for a fully seeded run) and
    deterministic algorithms are on, so the same seed gives identical losses on the CPU.

    With ``val``, the model is evaluated on it (:func:`evaluate_detector`, COCO) every
    ``val_every`` epochs and after the last, and at the end holds the weights of the
    evaluated epoch with the highest ``val_metric`` (the earliest on ties), as
    :func:`~robopercept.nn.train.loop.fit` keeps its best epoch; the schedule still runs
    its full ``config.epochs`` (no early stopping).

    Parameters
    ----------
    model : torch.nn.Module
    dataset : DetectionDataset
    config : TrainConfig, optional
        :class:`~robopercept.nn.train.loop.TrainConfig` (``patience``, ``monitor`` and
        the learning-rate multipliers are not used here).
    checkpoint : path, optional
        Written after every epoch (:func:`~robopercept.nn.train.loop.save_checkpoint`:
        ``{"model", "epoch", "losses", "architecture"}``, the class name); read it back
        with :func:`~robopercept.nn.train.loop.load_checkpoint` ``(path, model)``.
    progress : bool
        A bar per epoch on stderr.
    val : DetectionDataset, optional
        Validation set that selects the epoch kept.
    val_every : int
        Evaluate every this many epochs (>= 1).
    val_metric : {"AP", "AP50", "AP75"}
        mAP@[.5:.95], mAP@0.5 or mAP@0.75 (:data:`VAL_METRICS`).
    augment : callable, optional
        ``(image, target) -> (image, target)`` applied to each training sample as it
        is drawn, e.g. :class:`~robopercept.nn.detection.data.FlipRotate` (seed it for a
        repeatable run).
    ema : float, optional
        Keep an exponential moving average of the weights and buffers (Polyak
        averaging, as ultralytics' ``ModelEMA``), updated after every optimizer step
        ``n = 1, 2, ...`` as :math:`\bar\theta \leftarrow d_n \bar\theta + (1 - d_n)
        \theta` with :math:`d_n = \min(\texttt{ema}, \frac{1 + n}{10 + n})` (the
        warm-up of ``tf.train.ExponentialMovingAverage``'s ``num_updates``, so the
        random initial weights are forgotten early), through
        :class:`torch.optim.swa_utils.AveragedModel`. The averaged weights are the ones
        validated, kept and returned in ``model``. In (0, 1); None: no averaging.
    val_iou_type : {"bbox", "segm", "keypoints"}
        What validation scores (:func:`evaluate_detector`'s ``iou_type``): the masks
        of a :class:`MaskRCNN` with ``"segm"``, the keypoints of a
        :class:`KeypointRCNN` with ``"keypoints"`` (OKS with ``val_sigmas``).
    val_sigmas : (J,) array_like, optional
        The OKS constants for ``"keypoints"``.

    Returns
    -------
    DetectionHistory

    Raises
    ------
    InputError
        Not a detection dataset or model, an unknown ``val_metric``, or a loss that
        became NaN or infinite.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.detection.data import digits_detection_set
    >>> from robopercept.nn.train.loop import TrainConfig
    >>> _ = torch.manual_seed(0)
    >>> ds = digits_detection_set(2, (32, 32), (1, 1), rng=0, scale=(12, 16))
    >>> h = train_detector(FCOS(10, width=8, head_channels=16), ds,
    ...                    TrainConfig(epochs=1, batch_size=2, device="cpu"), progress=False)
    >>> sorted(h.losses[0])
    ['bbox_ctrness', 'bbox_regression', 'classification', 'loss']
    """
    from robopercept.nn.detection.data import collate_detection
    from robopercept.nn.train.loop import (
        TrainConfig,
        deterministic_algorithms,
        optimizer_step,
        resolve_device,
        save_checkpoint,
        step_optimizer,
    )
    from robopercept.progress import progress_bar

    model = check_module(model)
    ds = _detection_dataset(dataset)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    progress = check_bool(progress, "progress")
    ckpt = as_path(checkpoint, "checkpoint") if checkpoint is not None else None
    val_ds = _detection_dataset(val) if val is not None else None
    if augment is not None and not callable(augment):
        raise InputError(
            f"augment must be a callable (image, target) -> (image, target), e.g. "
            f"FlipRotate(); got {plain_repr(augment)}"
        )
    val_every = check_count(val_every, "val_every", 1, 1 << 30)
    check_choice(val_metric, "val_metric", VAL_METRICS)
    check_choice(val_iou_type, "val_iou_type", ("bbox", "segm", "keypoints"))
    if ema is not None:
        ema = check_real(ema, "ema (--ema)", 0.0, 1.0, low_inclusive=False, high_inclusive=False)
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    params = [p for p in model.parameters() if p.requires_grad]
    n = len(ds)
    steps = -(-n // cfg.batch_size)
    opt, sched = step_optimizer(params, cfg, steps)
    hist = DetectionHistory()
    best_state: dict[str, torch.Tensor] | None = None
    best_value = -math.inf
    averaged = _weight_average(model, ema) if ema is not None else None
    # the model validated and kept: the average when there is one
    kept = averaged.module if averaged is not None else model
    bar = progress_bar(
        total=cfg.epochs, desc="training detector", unit="epoch", disable=not progress
    )
    try:
        with deterministic_algorithms():
            for epoch in range(cfg.epochs):
                t0 = time.perf_counter()
                model.train()
                sums: dict[str, float] = {}
                order = torch.randperm(n, generator=gen).tolist()
                for b in range(steps):
                    items = [ds[j] for j in order[b * cfg.batch_size : (b + 1) * cfg.batch_size]]
                    if augment is not None:
                        items = [augment(im, t) for im, t in items]
                    images, targets = collate_detection(items)
                    images = [im.to(dev) for im in images]
                    targets = [
                        {
                            k: t[k].to(dev)
                            for k in ("boxes", "labels", "masks", "keypoints")
                            if k in t
                        }
                        for t in targets
                    ]
                    losses = model(images, targets)
                    if not isinstance(losses, dict) or not losses:
                        raise InputError(
                            "the model must return a dict of losses in train mode (the "
                            f"torchvision detection contract); got {type(losses).__name__}"
                        )
                    loss = sum(losses.values())
                    assert isinstance(loss, torch.Tensor)
                    optimizer_step(
                        loss, opt, sched, params, cfg, f"epoch {epoch + 1}, batch {b + 1}"
                    )
                    if averaged is not None:
                        averaged.update_parameters(model)
                    for k, v in losses.items():
                        sums[k] = sums.get(k, 0.0) + float(v.detach())
                    sums["loss"] = sums.get("loss", 0.0) + float(loss.detach())
                hist.losses.append({k: v / steps for k, v in sums.items()})
                hist.seconds.append(time.perf_counter() - t0)
                last = epoch + 1 == cfg.epochs
                if val_ds is not None and ((epoch + 1) % val_every == 0 or last):
                    t1 = time.perf_counter()
                    value = float(
                        evaluate_detector(
                            kept, val_ds, iou_type=val_iou_type, sigmas=val_sigmas
                        ).stats[VAL_METRICS[val_metric]]
                    )
                    hist.val_seconds += time.perf_counter() - t1
                    hist.val[epoch + 1] = value
                    if best_state is None or value > best_value:
                        best_value, hist.best_epoch = value, epoch + 1
                        best_state = copy.deepcopy(kept.state_dict())
                elif val_ds is None:
                    hist.best_epoch = epoch + 1
                if ckpt is not None:
                    save_checkpoint(
                        ckpt,
                        {
                            "model": kept.state_dict(),
                            "epoch": epoch + 1,
                            "losses": hist.losses,
                            "architecture": type(model).__name__,
                        },
                    )
                bar.update(1)
                post = {"loss": f"{hist.losses[-1]['loss']:.3f}"}
                if hist.val:
                    post[f"val {val_metric}"] = f"{hist.val[max(hist.val)]:.3f}"
                bar.set_postfix(**post)
    finally:
        bar.close()
    if best_state is not None:
        model.load_state_dict(best_state)
    elif averaged is not None:
        model.load_state_dict(kept.state_dict())
    return hist


def _weight_average(model: nn.Module, decay: float) -> Any:
    """``AveragedModel`` of ``model`` (weights and buffers) with the warmed-up EMA of
    :func:`train_detector`'s ``ema``."""
    from torch.optim.swa_utils import AveragedModel

    def ema_step(avg: torch.Tensor, new: torch.Tensor, n: torch.Tensor | int) -> torch.Tensor:
        d = min(decay, (1.0 + float(n)) / (10.0 + float(n)))
        return d * avg + (1.0 - d) * new

    return AveragedModel(model, avg_fn=ema_step, use_buffers=True)


@torch.no_grad()
def evaluate_detector(
    model: nn.Module,
    dataset: Any,
    *,
    batch_size: int = 8,
    device: str | None = None,
    iou_type: str = "bbox",
    sigmas: Any = None,
) -> Any:
    """COCO evaluation (:func:`~robopercept.nn.coco.formats.evaluate_detections`, equal to
    pycocotools) of ``model``'s eval-mode detections on ``dataset``: of the boxes, or
    with ``iou_type="segm"`` of the instance masks (a :class:`MaskRCNN`'s
    probabilities thresholded at 0.5, run-length encoded by
    :func:`~robopercept.nn.coco.rle.rle_encode`, against the dataset's masks), or
    with ``iou_type="keypoints"`` of a :class:`KeypointRCNN`'s keypoints by OKS with
    the per-joint ``sigmas`` (required unless the set has COCO's 17 keypoints).

    Parameters
    ----------
    model : torch.nn.Module
        Eval mode returns ``[{"boxes", "labels", "scores"}]`` per image (and
        ``"masks"`` ``(D, 1, H, W)`` for ``"segm"``).
    dataset : DetectionDataset
        With masks for ``"segm"``.
    batch_size : int
    device : str, optional
        None: the device of the model's parameters.
    iou_type : {"bbox", "segm", "keypoints"}
    sigmas : (J,) array_like, optional
        The OKS constants of ``"keypoints"`` (e.g. ``MPII_16.sigmas``).

    Returns
    -------
    CocoEvaluation
        ``.stats[0]`` is mAP@[.5:.95], ``.stats[1]`` mAP@0.5.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.detection.data import digits_detection_set
    >>> _ = torch.manual_seed(0)
    >>> ds = digits_detection_set(2, (32, 32), (1, 1), rng=0, scale=(12, 16))
    >>> ev = evaluate_detector(FCOS(10, width=8, head_channels=16), ds)
    >>> ev.stats.shape
    (12,)
    """
    from robopercept.nn.coco.formats import evaluate_detections
    from robopercept.nn.coco.rle import rle_encode
    from robopercept.nn.train.loop import resolve_device

    model = check_module(model)
    ds = _detection_dataset(dataset)
    bs = check_count(batch_size, "batch_size", 1, 1 << 16)
    kind = check_choice(iou_type, "iou_type", ("bbox", "segm", "keypoints"))
    segm = kind == "segm"
    keypoints = kind == "keypoints"
    if keypoints and ds.keypoints is None:
        raise InputError(
            "iou_type='keypoints' scores keypoints, and this dataset has none: use a set "
            "with keypoints (procedural_pose_scenes)"
        )
    if segm and ds.masks is None:
        raise InputError(
            "iou_type='segm' scores masks, and this dataset has none: use a set with "
            "instance masks (procedural_detection_set, digits_detection_set)"
        )
    if device is None:
        p = next(model.parameters(), None)
        dev = p.device if p is not None else torch.device("cpu")
    else:
        dev = resolve_device(device)
        model.to(dev)
    results: list[Mapping[str, Any]] = []
    for t, d in _detections_per_image(model, ds, bs, dev):
        b = d["boxes"].detach().cpu().double().numpy()
        if segm and "masks" not in d:
            raise InputError(
                f"iou_type='segm' needs masks, and {type(model).__name__} gives none: use "
                "a MaskRCNN, or iou_type='bbox'"
            )
        if keypoints and "keypoints" not in d:
            raise InputError(
                f"iou_type='keypoints' needs keypoints, and {type(model).__name__} gives none: "
                "use a KeypointRCNN, or iou_type='bbox'"
            )
        masks = (d["masks"][:, 0] > 0.5).cpu().numpy() if segm else None
        kps = d["keypoints"].detach().cpu().double().numpy() if keypoints else None
        for j, (box, lab, sc) in enumerate(
            zip(b, d["labels"].cpu().numpy(), d["scores"].cpu().double().numpy(), strict=True)
        ):
            res: dict[str, Any] = {
                "image_id": int(t["image_id"]),
                "category_id": int(lab),
                "bbox": [
                    float(box[0]),
                    float(box[1]),
                    float(box[2] - box[0]),
                    float(box[3] - box[1]),
                ],
                "score": float(sc),
            }
            if masks is not None:
                res["segmentation"] = rle_encode(masks[j])
            if kps is not None:
                res["keypoints"] = kps[j].ravel().tolist()
            results.append(res)
    return evaluate_detections(ds.to_coco(masks=segm), results, iou_type=kind, sigmas=sigmas)


def _detections_per_image(
    model: nn.Module, ds: Any, batch_size: int, dev: torch.device
) -> list[tuple[dict[str, Any], dict[str, torch.Tensor]]]:
    """(target, eval-mode detections) of every image of ``ds``, in batches; the model's
    train/eval mode is restored after."""
    from robopercept.nn.detection.data import collate_detection

    was = model.training
    model.eval()
    out: list[tuple[dict[str, Any], dict[str, torch.Tensor]]] = []
    try:
        for start in range(0, len(ds), batch_size):
            images, targets = collate_detection(
                [ds[j] for j in range(start, min(len(ds), start + batch_size))]
            )
            out.extend(zip(targets, model([im.to(dev) for im in images]), strict=True))
    finally:
        model.train(was)
    return out


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """Single-object localisation figures (:func:`evaluate_localizer`).

    Attributes
    ----------
    iou : numpy.ndarray
        ``(N,)`` IoU of each image's predicted box with its one ground-truth box.
    correct : numpy.ndarray
        ``(N,)`` bool, predicted label equals the true one.
    mean_iou : float
    accuracy : float
        Fraction of correct labels.
    """

    iou: Any
    correct: Any
    mean_iou: float
    accuracy: float


@torch.no_grad()
def evaluate_localizer(
    model: nn.Module, dataset: Any, *, batch_size: int = 32
) -> LocalizationResult:
    r"""Mean IoU and label accuracy of a single-object localizer (one box per image).

    For image :math:`i` with its one ground-truth box :math:`b_i` and the model's
    highest-scoring detection :math:`\hat b_i` (an image without a detection counts IoU
    0 and a wrong label),

    .. math:: \mathrm{mIoU} = \frac1N \sum_i \mathrm{IoU}(\hat b_i, b_i).

    Parameters
    ----------
    model : torch.nn.Module
        A :class:`SingleObjectLocalizer` or any model of the detection contract.
    dataset : DetectionDataset
        Exactly one box per image (:func:`~robopercept.nn.detection.data.single_digit_set`).
    batch_size : int

    Returns
    -------
    LocalizationResult

    Raises
    ------
    InputError
        An image without exactly one ground-truth box.
    """
    import numpy as np

    model = check_module(model)
    ds = _detection_dataset(dataset)
    bs = check_count(batch_size, "batch_size", 1, 1 << 16)
    counts = [len(b) for b in ds.boxes]
    if any(c != 1 for c in counts):
        bad = next(i for i, c in enumerate(counts) if c != 1)
        raise InputError(
            f"localisation needs exactly one box per image; image {bad} has {counts[bad]} "
            "(use single_digit_set or evaluate_detector)"
        )
    p = next(model.parameters(), None)
    dev = p.device if p is not None else torch.device("cpu")
    ious, correct = [], []
    for t, d in _detections_per_image(model, ds, bs, dev):
        if len(d["boxes"]) == 0:
            ious.append(0.0)
            correct.append(False)
            continue
        k = int(torch.argmax(d["scores"]))
        pred = d["boxes"][k : k + 1].detach().cpu().double()
        ious.append(float(box_iou(pred, t["boxes"].double())[0, 0]))
        correct.append(int(d["labels"][k]) == int(t["labels"][0]))
    iou, ok = np.asarray(ious), np.asarray(correct, dtype=bool)
    return LocalizationResult(iou, ok, float(iou.mean()), float(ok.mean()))


# --------------------------------------------------------------------------- R-CNN (2014)
def selective_search_proposals(
    image: torch.Tensor, max_proposals: int = 300, mode: str = "fast"
) -> torch.Tensor:
    """Selective-search proposals of a ``(3, H, W)`` image in [0, 1], as ``xyxy``.

    :func:`~robopercept.features.selective_search` (seeded with 0, so deterministic) on
    the image as an ``(H, W, 3)`` float array; its ``(x, y, w, h)`` boxes become
    :math:`(x, y, x + w, y + h)`. The default ``proposal_fn`` of :class:`RCNN` and the
    one the CLI gives :class:`FastRCNN`.

    Parameters
    ----------
    image : (3, H, W) float torch.Tensor
    max_proposals : int
        The best-ranked proposals kept.
    mode : {"fast", "quality"}

    Returns
    -------
    (P, 4) float32 torch.Tensor
        On the image's device.

    Raises
    ------
    InputError
        Not a ``(3, H, W)`` float finite image, or ``max_proposals`` < 1.

    Examples
    --------
    >>> import torch
    >>> im = torch.zeros(3, 24, 24)
    >>> im[:, 4:12, 4:12] = 1.0
    >>> p = selective_search_proposals(im, 50)
    >>> p.shape[1], bool((p[:, 2:] > p[:, :2]).all())
    (4, True)
    """
    from robopercept.features import selective_search

    im = _check_images([image])[0]
    k = check_count(max_proposals, "max_proposals", 1, 1 << 20)
    arr = im.detach().cpu().permute(1, 2, 0).double().clamp(0, 1).numpy()
    xywh = selective_search(arr, mode, rng=0, max_proposals=k)  # type: ignore[arg-type]
    b = torch.as_tensor(xywh, dtype=torch.float32).reshape(-1, 4)
    return torch.cat((b[:, :2], b[:, :2] + b[:, 2:]), dim=1).to(im.device)


class _WarpCNN(nn.Module):
    """The region classifier of R-CNN: three ConvBNAct + max-pool stages, global average
    pooling, one fully connected layer (the features), then class logits and a linear
    per-class box regressor on the (detached) features."""

    def __init__(self, width: int, hidden: int, num_classes: int) -> None:
        super().__init__()
        self.features = nn.Sequential(
            ConvBNAct(3, width),
            nn.MaxPool2d(2),
            ConvBNAct(width, 2 * width),
            nn.MaxPool2d(2),
            ConvBNAct(2 * width, 4 * width),
            nn.AdaptiveAvgPool2d(1),
            nn.Flatten(),
            nn.Linear(4 * width, hidden),
            nn.ReLU(),
        )
        self.cls_score = nn.Linear(hidden, num_classes + 1)
        self.bbox_pred = nn.Linear(hidden, 4 * (num_classes + 1))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.features(x)
        # the box regressor is a linear model of fixed CNN features (as the paper's
        # ridge regressor on pool5): its gradient does not reach the CNN
        return self.cls_score(h), self.bbox_pred(h.detach())


class RCNN(_TwoStage):
    r"""R-CNN (Girshick et al. 2014), the course's "slow" R-CNN: every region proposal
    is cut out of the image, warped to a fixed size and classified by a CNN of its own.

    Pipeline per image: proposals (``proposal_fn``, default
    :func:`selective_search_proposals`, or the ``proposals`` argument) -> each box
    enlarged for context and warped -> a small CNN (:class:`~robopercept.nn.core.blocks.
    ConvBNAct` stages) -> class logits (background and ``num_classes``) and a linear
    per-class box regressor on the CNN features -> per class: decode, clip, score
    threshold, NMS, the ``detections_per_img`` best.

    **Warp with context padding** (the paper's Appendix A, ``p = 16`` pixels of context
    around a 227-pixel warp): with warp side :math:`S` = ``warp_size`` and
    :math:`p = \mathrm{round}(S \cdot 16 / 227)` = ``context``, the box
    :math:`(c_x, c_y, w, h)` is enlarged to :math:`(c_x, c_y, w S / (S - 2p),
    h S / (S - 2p))`, so after the anisotropic warp to :math:`S \times S` the original
    box fills the central :math:`(S - 2p)^2` and ``p`` pixels of context surround it.
    The warp samples bilinearly (:func:`~robopercept.nn.ops.boxes.roi_align`, 2 x 2 samples
    per output pixel) the normalized image; outside the image the value is 0, i.e. the
    mean colour, as the paper's mean padding.

    Training (the paper's fine-tuning stage): the ground-truth boxes join the
    proposals; IoU >= 0.5 with a ground-truth box is foreground (its class), < 0.3
    background, between ignored; ``box_batch_size`` regions per image with at most
    ``box_positive_fraction`` foreground. Losses: ``loss_classifier`` (cross-entropy
    over background + classes) and ``loss_box`` (smooth-L1, :math:`\beta = 1/9`, on
    the true class's :class:`~robopercept.nn.ops.boxes.BoxCoder` deltas, weights
    (10, 10, 5, 5), of foreground regions; the regressor is linear in the detached
    features, so it is a linear regression trained jointly, as the paper's separate
    ridge regressor). The paper's per-class SVMs are replaced by the softmax, as in
    its own fine-tuned variant and in Fast R-CNN.

    **Slow by design**: the CNN runs once per region (no shared features), and
    selective search costs seconds per image. After each eval-mode call
    ``last_timing`` holds the seconds per image of ``"proposals"``, ``"cnn"`` (warp
    and CNN) and ``"total"``.

    Parameters
    ----------
    num_classes : int
    proposal_fn : callable, optional
        ``(3, H, W)`` image in [0, 1] -> ``(P, 4)`` ``"xyxy"`` proposals; None:
        :func:`selective_search_proposals`.
    warp_size : int
        Side :math:`S` of the warped region (>= 8).
    context : int, optional
        Context pixels :math:`p` in the warp, ``0 <= 2p < S``; None:
        :math:`\mathrm{round}(16 S / 227)`.
    width, hidden
        CNN width (channels of the first stage) and feature size.
    box_batch_size, box_positive_fraction
        Regions sampled per image and their foreground cap.
    score_thresh, nms_thresh, detections_per_img
        Post-processing.
    chunk : int
        Regions through the CNN at once in eval mode (memory bound).

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = RCNN(2, warp_size=16, width=4, hidden=16).eval()
    >>> out = m([torch.rand(3, 32, 32)], proposals=[torch.tensor([[2.0, 2, 20, 20]])])
    >>> sorted(out[0]), sorted(m.last_timing)
    (['boxes', 'labels', 'scores'], ['cnn', 'proposals', 'total'])
    """

    def __init__(
        self,
        num_classes: int,
        proposal_fn: Callable[[torch.Tensor], torch.Tensor] | None = None,
        *,
        warp_size: int = 32,
        context: int | None = None,
        width: int = 16,
        hidden: int = 128,
        box_batch_size: int = 64,
        box_positive_fraction: float = 0.25,
        score_thresh: float = 0.05,
        nms_thresh: float = 0.5,
        detections_per_img: int = 100,
        chunk: int = 256,
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 1)
        if proposal_fn is not None and not callable(proposal_fn):
            raise InputError(f"proposal_fn must be callable or None; got {plain_repr(proposal_fn)}")
        self.proposal_fn = proposal_fn
        self.warp_size = check_count(warp_size, "warp_size", 8, 1024)
        if context is None:
            context = round(self.warp_size * 16 / 227)
        self.context = check_count(context, "context", 0, (self.warp_size - 1) // 2)
        self.roi = _WarpCNN(  # type: ignore[assignment]
            check_count(width, "width", 1, 1024),
            check_count(hidden, "hidden", 1, 1 << 14),
            self.num_classes,
        )
        self.box_coder = BoxCoder((10.0, 10.0, 5.0, 5.0))
        self.bg_low, self.bg_high = 0.0, 0.3
        self.box_batch_size = check_count(box_batch_size, "box_batch_size", 1, 1 << 20)
        self.box_positive_fraction = check_real(
            box_positive_fraction, "box_positive_fraction", 0.0, 1.0
        )
        self.score_thresh = check_real(score_thresh, "score_thresh", 0.0, 1.0)
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.detections_per_img = check_count(detections_per_img, "detections_per_img", 1, 1 << 20)
        self.chunk = check_count(chunk, "chunk", 1, 1 << 20)
        self.last_timing: dict[str, float] = {}

    def warp(self, image: torch.Tensor, boxes: torch.Tensor) -> torch.Tensor:
        """Warp the ``(P, 4)`` ``xyxy`` ``boxes`` of one ``(3, H, W)`` float image to
        ``(P, 3, S, S)`` with the context padding of the class docstring (the model
        warps the normalized image; outside the image the value is 0).

        Raises
        ------
        InputError
            ``image`` not a finite ``(3, H, W)`` float tensor, ``boxes`` not a finite
            ``(P, 4)`` float tensor.
        """
        im = _check_images([image])[0]
        if (
            not isinstance(boxes, torch.Tensor)
            or not boxes.is_floating_point()
            or boxes.ndim != 2
            or boxes.shape[1] != 4
            or not bool(torch.isfinite(boxes).all())
        ):
            raise InputError(
                f"boxes must be a finite (P, 4) float torch.Tensor, xyxy; got {plain_repr(boxes)}"
            )
        return self._warp(im, boxes.to(im.device, im.dtype))

    def _warp(self, image: torch.Tensor, boxes: torch.Tensor) -> torch.Tensor:
        s, p = self.warp_size, self.context
        cx, cy = (boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2
        f = s / (s - 2 * p)
        hw = (boxes[:, 2] - boxes[:, 0]) * f / 2
        hh = (boxes[:, 3] - boxes[:, 1]) * f / 2
        big = torch.stack((cx - hw, cy - hh, cx + hw, cy + hh), dim=1)
        return roi_align(image[None], [big], s, 1.0, sampling_ratio=2, aligned=True)

    def _classify(
        self, batch: torch.Tensor, rois: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        crops = torch.cat([self._warp(batch[i], r) for i, r in enumerate(rois)])
        if self.training or crops.shape[0] <= self.chunk:
            return self.roi(crops)
        parts = [self.roi(crops[i : i + self.chunk]) for i in range(0, crops.shape[0], self.chunk)]
        return torch.cat([a for a, _ in parts]), torch.cat([b for _, b in parts])

    def forward(
        self, images: Any, targets: Any = None, proposals: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.
        proposals : list of (P, 4) float torch.Tensor, optional
            ``"xyxy"`` proposals per image (clipped; empty ones dropped); None: from
            ``proposal_fn`` (selective search by default).

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            ``{"loss_classifier", "loss_box"}``, or ``{"boxes": (D, 4), "labels":
            (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing or malformed
            targets; proposals not a list of (P, 4) float tensors or with NaN.
        """
        t0 = time.perf_counter()
        batch, sizes, tgts = self._prepare(images, targets)
        if proposals is None:
            fn = self.proposal_fn or selective_search_proposals
            proposals = [fn(im) for im in _check_images(images)]
        props = [p.to(batch.device) for p in _check_proposals(proposals, sizes)]
        t1 = time.perf_counter()
        if self.training:
            assert tgts is not None
            rois, labels, deltas = self.select_training_samples(props, tgts)
            logits, reg = self._classify(batch, rois)
            return self._head_losses(logits, reg, labels, deltas)
        logits, reg = self._classify(batch, props)
        out = self._postprocess(logits, reg, props, sizes)
        t2 = time.perf_counter()
        n = len(sizes)
        self.last_timing = {
            "proposals": (t1 - t0) / n,
            "cnn": (t2 - t1) / n,
            "total": (t2 - t0) / n,
        }
        return out


# --------------------------------------------------------------------------- build / save / load
#: the detectors by the names the CLI uses
DETECTORS: dict[str, type[nn.Module]] = {
    "fcos": FCOS,
    "faster": FasterRCNN,
    "maskrcnn": MaskRCNN,
    "keypointrcnn": KeypointRCNN,
    "fast": FastRCNN,
    "rcnn": RCNN,
    "localizer": SingleObjectLocalizer,
}


def build_detector(
    kind: str, num_classes: int, *, seed: int | None = None, **settings: Any
) -> nn.Module:
    """A detector of :data:`DETECTORS` by name, with its constructor ``settings``.

    ``"fast"`` gets :func:`selective_search_proposals` as ``proposal_fn`` (``"rcnn"``
    uses it by default), so every kind rebuilt from a checkpoint runs on bare images.

    Parameters
    ----------
    kind : {"fcos", "faster", "fast", "rcnn", "localizer"}
    num_classes : int
    seed : int, optional
        Seeds torch's global generator (:func:`torch.manual_seed`) before the weights
        are drawn.
    **settings
        Keyword arguments of the class (e.g. ``width=8``): plain ints, floats, strings
        and tuples, so :func:`save_detector` can store them.

    Returns
    -------
    torch.nn.Module

    Raises
    ------
    InputError
        Unknown ``kind`` or a setting the class does not take (or out of range).

    Examples
    --------
    >>> type(build_detector("fcos", 3, width=8)).__name__
    'FCOS'
    """
    if not isinstance(kind, str) or kind not in DETECTORS:
        raise InputError(f"kind must be one of {sorted(DETECTORS)}; got {plain_repr(kind)}")
    cls = DETECTORS[kind]
    if kind == "fast":
        settings = {"proposal_fn": selective_search_proposals, **settings}
    if seed is not None:
        torch.manual_seed(check_int(seed, "seed", 0))
    try:
        return cls(num_classes, **settings)
    except TypeError as exc:
        raise InputError(f"{cls.__name__}: {exc}; give keyword settings of the class") from None


def save_detector(
    path: str | os.PathLike[str],
    model: nn.Module,
    kind: str,
    settings: Mapping[str, Any],
    classes: Sequence[str],
    **extra: Any,
) -> Any:
    """Write ``model``'s weights with what rebuilds it (``kind``, ``settings``,
    ``classes``) to ``path`` (:func:`~robopercept.nn.train.loop.save_checkpoint`);
    ``extra`` plain values (the data, the epochs ...) are stored beside them. Returns
    the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> m = build_detector("fcos", 2, width=8)
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "m.pt"
    >>> _ = save_detector(p, m, "fcos", {"width": 8}, ["a", "b"])
    >>> m2, info = load_detector(p)
    >>> info["classes"], type(m2).__name__
    (['a', 'b'], 'FCOS')
    """
    from robopercept.nn.train.loop import save_built_model

    if not isinstance(kind, str) or kind not in DETECTORS:
        raise InputError(f"kind must be one of {sorted(DETECTORS)}; got {plain_repr(kind)}")
    return save_built_model(path, model, kind, settings, classes, **extra)


def load_detector(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a detector written by :func:`save_detector` (eval mode, on the CPU).

    Returns
    -------
    model : torch.nn.Module
    info : dict
        The checkpoint without the weights (``kind``, ``settings``, ``classes``, ...).

    Raises
    ------
    FileFormatError
        Missing or unreadable file, or a checkpoint without ``kind``/``classes``
        (e.g. a classifier's).
    """
    from robopercept.nn.train.loop import load_built_model

    return load_built_model(
        path,
        tuple(DETECTORS),
        build_detector,
        "detector",
        "save_detector or `robopercept nn detect train`",
    )


def detect_arrays(model: nn.Module, images: Sequence[Any]) -> list[dict[str, Any]]:
    """Eval-mode detections of NumPy images, as NumPy arrays.

    Each image, ``(H, W, 3)`` ``uint8``, ``uint16`` or float in [0, 1], is scaled to
    [0, 1] (:func:`~robopercept.nn.data.datasets.to_unit_float`), made a ``(3, H, W)`` tensor
    on the model's device and run through ``model.predict`` one at a time.

    Parameters
    ----------
    model : torch.nn.Module
        A detector of this module (it has ``predict``).
    images : sequence of (H, W, 3) ndarray

    Returns
    -------
    list of dict
        ``{"boxes": (D, 4) float64 xyxy, "labels": (D,) int64, "scores": (D,) float64}``,
        and for a :class:`MaskRCNN` ``"masks"`` ``(D, H, W)`` bool (probability > 0.5),
        for a :class:`KeypointRCNN` ``"keypoints"`` ``(D, J, 3)`` float64 rows
        ``(x, y, score)``.

    Raises
    ------
    InputError
        Not a detector, or an image that is not ``(H, W, 3)``.

    Examples
    --------
    >>> import numpy as np
    >>> m = build_detector("fcos", 2, width=4)
    >>> d = detect_arrays(m, [np.zeros((32, 32, 3), np.uint8)])
    >>> sorted(d[0]), d[0]["boxes"].shape[1]
    (['boxes', 'labels', 'scores'], 4)
    """
    import numpy as np

    from robopercept.nn.data.datasets import to_unit_float

    model = check_module(model)
    if not callable(getattr(model, "predict", None)):
        raise InputError(f"model must be a detector with predict(); got {type(model).__name__}")
    if isinstance(images, np.ndarray) or not isinstance(images, Sequence):
        raise InputError(
            f"images must be a list of (H, W, 3) arrays; got {plain_repr(images)}: wrap one "
            "image in a list"
        )
    p = next(model.parameters(), None)
    dev = p.device if p is not None else torch.device("cpu")
    out = []
    for i, im in enumerate(images):
        if not isinstance(im, np.ndarray) or im.ndim != 3 or im.shape[2] != 3:
            raise InputError(
                f"images[{i}] must be an (H, W, 3) RGB ndarray; got {plain_repr(im)}: read it "
                "with read_image(path, mode='rgb')"
            )
        x = np.ascontiguousarray(to_unit_float(im).astype(np.float32).transpose(2, 0, 1))
        d = model.predict([torch.from_numpy(x).to(dev)])[0]  # type: ignore[operator]
        res = {
            "boxes": d["boxes"].detach().cpu().double().numpy(),
            "labels": d["labels"].cpu().numpy(),
            "scores": d["scores"].detach().cpu().double().numpy(),
        }
        if "masks" in d:
            res["masks"] = (d["masks"][:, 0] > 0.5).cpu().numpy()
        if "keypoints" in d:
            kp = d["keypoints"].detach().cpu().double().numpy().copy()
            kp[..., 2] = d["keypoints_scores"].detach().cpu().double().numpy()
            res["keypoints"] = kp
        out.append(res)
    return out
