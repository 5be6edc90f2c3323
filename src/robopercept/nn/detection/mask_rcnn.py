r"""Mask R-CNN (He et al. 2017): :class:`~robopercept.nn.detection.faster_rcnn.FasterRCNN`
with a mask branch (:class:`MaskHead`) plugged into its RoI heads beside the box head,
trained with the per-pixel binary cross entropy of the true class's mask
(``loss_mask``); at inference the masks are pasted into the image
(:func:`~robopercept.nn.ops.roi.paste_masks`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import MAX_CHANNELS
from robopercept.nn.detection.faster_rcnn import FasterRCNN
from robopercept.nn.ops.roi import paste_masks, roi_align

__all__ = [
    "MaskHead",
    "MaskRCNN",
]


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


class MaskHead(nn.Module):
    r"""The mask branch of Mask R-CNN, a part of
    :class:`~robopercept.nn.detection.roi_heads.RoIHeads` (its ``mask_head``).

    Each region is pooled with RoI Align (``aligned=True``, pixel centres at
    half-integers) to ``mask_pool_size`` cells of the features, then ``mask_convs``
    3 x 3 convolutions of ``mask_channels`` with ReLU, a 2 x 2 stride-2 transposed
    convolution with ReLU and a 1 x 1 convolution give :math:`C` logit maps of side
    :math:`M = 2\,` ``mask_pool_size`` (28 by default): one mask per class, decoupled
    from the classification (no competition between classes); torchvision's
    ``MaskRCNNHeads`` + ``MaskRCNNPredictor``, with fewer channels. Convolutions are
    initialized He-normal (``fan_out``) with zero bias.

    Training (:meth:`losses`): for each sampled foreground region :math:`r` with
    ground-truth class :math:`k` and matched instance mask :math:`G`, the target
    :math:`T` is :math:`G` RoI-aligned to :math:`M \times M` over the region (soft
    values in [0, 1], as torchvision's ``project_masks_on_boxes``), and ``loss_mask``
    is the mean per-pixel binary cross entropy
    :math:`-\overline{T \log \sigma(z_k) + (1 - T) \log(1 - \sigma(z_k))}` of the
    class-:math:`k` map only (0 without foreground regions). Inference
    (:meth:`outputs`): the map of each box's predicted class through the sigmoid,
    pasted into the image (:func:`~robopercept.nn.ops.roi.paste_masks`).

    Parameters
    ----------
    in_channels : int
        Channels of the features.
    num_classes : int
        :math:`C`.
    mask_pool_size : int
        RoI Align side (14: 28 x 28 masks).
    mask_channels, mask_convs : int
        Width and depth (torchvision: 256 and 4).
    spatial_scale : float
        Features per image pixel (1/8 on a stride-8 map).

    Examples
    --------
    >>> import torch
    >>> head = MaskHead(8, 2, mask_pool_size=4, mask_channels=8, mask_convs=1)
    >>> head.mask_logits(torch.rand(1, 8, 8, 8), [torch.tensor([[0.0, 0, 32, 32]])]).shape
    torch.Size([1, 2, 8, 8])
    """

    def __init__(
        self,
        in_channels: int,
        num_classes: int,
        *,
        mask_pool_size: int = 14,
        mask_channels: int = 64,
        mask_convs: int = 4,
        spatial_scale: float = 0.125,
    ) -> None:
        super().__init__()
        c = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        k = check_count(num_classes, "num_classes", 1, 1 << 16)
        self.mask_pool_size = check_count(mask_pool_size, "mask_pool_size", 1, 64)
        self.mask_resolution = 2 * self.mask_pool_size
        channels = check_count(mask_channels, "mask_channels", 1, MAX_CHANNELS)
        convs = check_count(mask_convs, "mask_convs", 0, 16)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )
        layers: list[nn.Module] = []
        for _ in range(convs):
            layers += [nn.Conv2d(c, channels, 3, padding=1), nn.ReLU()]
            c = channels
        self.convs = nn.Sequential(*layers)
        self.up = nn.ConvTranspose2d(c, channels, 2, stride=2)
        self.logits = nn.Conv2d(channels, k, 1)
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                nn.init.zeros_(m.bias)  # type: ignore[arg-type]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(R, C, M, M)`` mask logits of pooled regions ``(R, in_channels, P, P)``."""
        return self.logits(F.relu(self.up(self.convs(x))))

    def mask_logits(self, features: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        """``(R, C, M, M)`` mask logits of the regions ``rois`` (one list entry per image,
        ``xyxy`` pixels) on ``features``."""
        pooled = roi_align(
            features,
            rois,
            self.mask_pool_size,
            self.spatial_scale,
            sampling_ratio=2,
            aligned=True,
        )
        return self(pooled)

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

    def losses(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        targets: Sequence[Mapping[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        """``{"loss_mask": ...}`` on the sampled foreground regions (the class
        docstring); ``targets`` carry ``"masks"`` ``(K, H, W)`` per image.

        Raises
        ------
        InputError
            A target without ``"masks"``, or masks not ``(K, H, W)`` of the image's
            size, or with NaN or inf.
        """
        gt_masks = [
            _check_masks_target(t, i, s)
            for i, (t, s) in enumerate(zip(targets, sizes, strict=True))
        ]
        fg = [lab > 0 for lab in labels]
        fg_labels = torch.cat([lab[f] for lab, f in zip(labels, fg, strict=True)])
        if fg_labels.numel() == 0:
            # zero, with a graph through the mask branch (as torchvision's)
            zero = torch.stack([p.sum() for p in self.parameters()]).sum() * 0.0
            return {"loss_mask": zero}
        z = self.mask_logits(features, [r[f] for r, f in zip(rois, fg, strict=True)])
        z = z[torch.arange(z.shape[0], device=z.device), fg_labels - 1]
        target = torch.cat(
            [
                self.mask_targets(r[f], gm, mt[f])
                for r, f, gm, mt in zip(rois, fg, gt_masks, matched, strict=True)
            ]
        )
        return {"loss_mask": F.binary_cross_entropy_with_logits(z, target)}

    def outputs(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        detections: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        """``detections`` with ``"masks"`` ``(D, 1, H, W)`` probabilities: each box's
        predicted-class map through the sigmoid, pasted into its image."""
        boxes = [d["boxes"] for d in detections]
        if not sum(b.shape[0] for b in boxes):
            for d, size in zip(detections, sizes, strict=True):
                d["masks"] = features.new_zeros((0, 1, *size))
            return detections
        z = self.mask_logits(features, boxes)
        start = 0
        for d, size in zip(detections, sizes, strict=True):
            k = d["boxes"].shape[0]
            zi = z[start : start + k]
            start += k
            probs = torch.sigmoid(zi[torch.arange(k, device=zi.device), d["labels"] - 1])
            d["masks"] = paste_masks(probs, d["boxes"].detach(), size)[:, None]
        return detections


class MaskRCNN(FasterRCNN):
    r"""Mask R-CNN (He et al. 2017): :class:`FasterRCNN` whose RoI heads carry a mask
    branch (:class:`MaskHead`) beside the box head.

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
    (:func:`~robopercept.nn.ops.roi.paste_masks`).

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
        if "mask_head" in settings or "keypoint_head" in settings:
            raise InputError("MaskRCNN builds its own mask_head; give its mask_* settings")

        def mask_head(in_channels: int, spatial_scale: float) -> MaskHead:
            return MaskHead(
                in_channels,
                num_classes,
                mask_pool_size=mask_pool_size,
                mask_channels=mask_channels,
                mask_convs=mask_convs,
                spatial_scale=spatial_scale,
            )

        super().__init__(num_classes, mask_head=mask_head, **settings)
