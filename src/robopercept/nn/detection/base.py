r"""The detector contract and the input checks every detector shares.

Every detector keeps torchvision's detection-model contract:
``model(images, targets=None)`` with ``images`` a list of ``(3, H, W)`` float tensors
in [0, 1] (sizes may differ: they are zero-padded to one batch whose sides are
multiples of the largest stride) and ``targets`` a list of dicts with ``"boxes"``
(``(K, 4)`` float ``"xyxy"`` pixels) and ``"labels"`` (``(K,)`` int64, 1-based; 0 is
the background). In train mode the call returns a dict of scalar losses, in eval mode
a list of ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}``, one per image, boxes
in the input image's pixels. The input normalization
:math:`(x - \mu) / \sigma` (ImageNet's mean and std,
:data:`~robopercept.nn.core.backbones.IMAGE_MEAN`) happens inside the model.

:class:`Detector` is the base class that does this plumbing (checks, normalization,
padding, :meth:`Detector.predict`); :func:`check_images`, :func:`check_targets` and
:func:`check_proposals` are its boundary checks, :func:`clip_boxes` clips boxes to an
image and :func:`init_conv` initializes head convolutions as torchvision does. A detector
whose module layout changed lists its old state-dict key prefixes in
:attr:`Detector.renamed_keys`, and checkpoints with the old keys still load.
Conventions follow torchvision's ``models.detection`` (looked up, not imported:
torchvision is not a dependency).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import torch
from torch import nn

from robopercept._checks import plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import IMAGE_MEAN, IMAGE_STD

__all__ = [
    "Detector",
    "check_images",
    "check_proposals",
    "check_targets",
    "clip_boxes",
    "init_conv",
]


def check_images(images: Any) -> list[torch.Tensor]:
    """Check a detector's ``images`` argument and return it as a list.

    Parameters
    ----------
    images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W) torch.Tensor
        RGB in [0, 1]; sizes may differ.

    Returns
    -------
    list of (3, H, W) torch.Tensor
        The images, unchanged (a batch is split into its images).

    Raises
    ------
    InputError
        Not a non-empty list of tensors, an image not ``(3, H, W)`` (channels-last is
        named), not floating point, empty, or with NaN or inf pixels.

    Examples
    --------
    >>> import torch
    >>> [tuple(im.shape) for im in check_images(torch.zeros(2, 3, 8, 6))]
    [(3, 8, 6), (3, 8, 6)]
    """
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


def check_targets(
    targets: Any, images: list[torch.Tensor], num_classes: int
) -> list[dict[str, torch.Tensor]]:
    """Check a detector's training ``targets``, one per image.

    Parameters
    ----------
    targets : list of dict
        ``"boxes"`` ``(K, 4)`` float ``"xyxy"`` pixels (``x2 > x1``, ``y2 > y1``, finite)
        and ``"labels"`` ``(K,)`` int64 in ``1..num_classes``; ``"masks"`` and
        ``"keypoints"`` are passed through (checked by the models that use them).
    images : list of (3, H, W) torch.Tensor
        The checked images (:func:`check_images`).
    num_classes : int

    Returns
    -------
    list of dict
        ``{"boxes", "labels"}`` and the passed-through entries, per image.

    Raises
    ------
    InputError
        Not one dict per image, boxes or labels of the wrong type, shape or range, NaN,
        or a degenerate box.

    Examples
    --------
    >>> import torch
    >>> t = [{"boxes": torch.tensor([[1.0, 2, 5, 6]]), "labels": torch.tensor([1])}]
    >>> sorted(check_targets(t, [torch.zeros(3, 8, 8)], 2)[0])
    ['boxes', 'labels']
    """
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


def clip_boxes(boxes: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    r"""Clip ``xyxy`` boxes to an image of ``size`` ``(H, W)``: :math:`x \in [0, W]`,
    :math:`y \in [0, H]` (torchvision's ``clip_boxes_to_image``).

    Parameters
    ----------
    boxes : (..., 4) torch.Tensor
    size : (int, int)
        ``(H, W)``.

    Returns
    -------
    (..., 4) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> clip_boxes(torch.tensor([[-2.0, 1, 12, 30]]), (20, 10)).tolist()
    [[0.0, 1.0, 10.0, 20.0]]
    """
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


def check_proposals(proposals: Any, sizes: list[tuple[int, int]]) -> list[torch.Tensor]:
    """Check external region proposals, one ``(P, 4)`` tensor per image, clip them to
    their image and drop the empty ones.

    Parameters
    ----------
    proposals : list of (P, 4) float torch.Tensor
        ``"xyxy"`` pixels, finite.
    sizes : list of (int, int)
        ``(H, W)`` of each image.

    Returns
    -------
    list of (P', 4) float32 torch.Tensor

    Raises
    ------
    InputError
        Not one ``(P, 4)`` float tensor per image, or NaN or inf.

    Examples
    --------
    >>> import torch
    >>> check_proposals([torch.tensor([[-1.0, 0, 4, 4], [5, 5, 5, 9]])], [(8, 8)])[0].tolist()
    [[0.0, 0.0, 4.0, 4.0]]
    """
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
        p = clip_boxes(p.float(), size)
        keep = (p[:, 2] - p[:, 0] > 0) & (p[:, 3] - p[:, 1] > 0)
        out.append(p[keep])
    return out


def init_conv(layer: nn.Conv2d, bias: float) -> None:
    r"""Initialize a head convolution in place: weights drawn from :math:`N(0, 0.01^2)`
    (torch's global generator) and a constant bias, as torchvision's RPN and FCOS heads.

    Parameters
    ----------
    layer : torch.nn.Conv2d
    bias : float
        The constant of the bias (e.g. the focal-loss prior
        :math:`-\log((1 - \pi) / \pi)` of a classification head).

    Examples
    --------
    >>> import torch
    >>> conv = torch.nn.Conv2d(4, 2, 3)
    >>> init_conv(conv, -1.0)
    >>> conv.bias.tolist()
    [-1.0, -1.0]
    """
    nn.init.normal_(layer.weight, std=0.01)
    if layer.bias is not None:
        nn.init.constant_(layer.bias, bias)


class Detector(nn.Module):
    """Shared plumbing: input checks, normalization, padding to one batch, and the
    renaming of old state-dict keys on load (:attr:`renamed_keys`)."""

    num_classes: int
    size_divisible: int
    mean: torch.Tensor
    std: torch.Tensor
    #: old state-dict key prefix -> new one: checkpoints written before a change of the
    #: module layout load (``load_state_dict`` renames their keys first)
    renamed_keys: ClassVar[Mapping[str, str]] = {}

    def _load_from_state_dict(self, state_dict: Any, prefix: str, *args: Any) -> None:
        # torch calls this on each module, parents first, before checking for unexpected
        # keys: renaming here lets the children find theirs
        for key in [k for k in state_dict if k.startswith(prefix)]:
            rest = key[len(prefix) :]
            for old, new in self.renamed_keys.items():
                if rest.startswith(old) and prefix + new + rest[len(old) :] not in state_dict:
                    state_dict[prefix + new + rest[len(old) :]] = state_dict.pop(key)
                    break
        super()._load_from_state_dict(state_dict, prefix, *args)

    def _init_common(self, num_classes: int, size_divisible: int) -> None:
        self.num_classes = check_count(num_classes, "num_classes", 1, 1 << 16)
        self.size_divisible = size_divisible
        self.register_buffer("mean", torch.tensor(IMAGE_MEAN).view(3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGE_STD).view(3, 1, 1), persistent=False)

    def _prepare(
        self, images: Any, targets: Any
    ) -> tuple[torch.Tensor, list[tuple[int, int]], list[dict[str, torch.Tensor]] | None]:
        ims = check_images(images)
        tgts = None
        if self.training:
            if targets is None:
                raise InputError(
                    "targets are required in train mode (a list of dicts with 'boxes' and "
                    "'labels'): pass them, or call model.eval() to predict"
                )
            tgts = check_targets(targets, ims, self.num_classes)
        elif targets is not None:
            tgts = check_targets(targets, ims, self.num_classes)
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
