r"""The region proposal network of Faster R-CNN (Ren et al. 2015):
:class:`RegionProposalNetwork`, torchvision's ``models.detection.rpn`` (looked up, not
imported).

On one feature map: a 3 x 3 convolution and ReLU, then per anchor of
:class:`~robopercept.nn.ops.anchors.AnchorGenerator` an objectness logit and deltas
(:class:`~robopercept.nn.ops.anchors.BoxCoder` weights (1, 1, 1, 1)). Training labels
the anchors positive at IoU >= 0.7 with a ground-truth box (and the best anchor of each
ground-truth box, even below), negative below 0.3, the rest ignored
(:func:`~robopercept.nn.detection.targets.match_boxes`), and samples 256 per image,
at most half positive (:func:`~robopercept.nn.detection.targets.sample_balanced`);
``loss_rpn_objectness`` is the binary cross-entropy of the sampled anchors' logits,
``loss_rpn_box`` the smooth-L1 (:math:`\beta = 1/9`) of the positives' deltas, summed
and divided by the number sampled. Proposals: the best anchors by objectness (top-k),
decoded, clipped, small boxes removed, NMS, the best kept (top-k before and after
NMS, fewer in eval); they are detached, as in the approximate joint training of the
paper.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_tensor_dtype
from robopercept.nn.core.backbones import MAX_CHANNELS
from robopercept.nn.detection.base import clip_boxes, init_conv
from robopercept.nn.detection.targets import match_boxes, sample_balanced
from robopercept.nn.ops.anchors import AnchorGenerator, BoxCoder
from robopercept.nn.ops.boxes import box_iou
from robopercept.nn.ops.nms import nms

__all__ = [
    "RegionProposalNetwork",
]


def _pair(value: Any, name: str) -> tuple[int, int]:
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"{name} must be a (train, eval) pair of ints; got {plain_repr(value)}")
    a, b = (check_count(v, name, 1, 1 << 20) for v in value)
    return a, b


def _check_sizes(sizes: Any, n: int) -> list[tuple[int, int]]:
    if not isinstance(sizes, (list, tuple)) or len(sizes) != n:
        raise InputError(
            f"sizes must be a list of {n} (H, W) image sizes, one per image of the batch; "
            f"got {plain_repr(sizes)}"
        )
    out = []
    for i, s in enumerate(sizes):
        if not isinstance(s, (list, tuple)) or len(s) != 2:
            raise InputError(f"sizes[{i}] must be (H, W); got {plain_repr(s)}")
        h, w = (check_count(v, f"sizes[{i}]", 1, 1 << 20) for v in s)
        out.append((h, w))
    return out


def _check_box_targets(targets: Any, n: int) -> list[Mapping[str, torch.Tensor]]:
    if not isinstance(targets, (list, tuple)) or len(targets) != n:
        raise InputError(
            f"targets must be a list of {n} dicts with 'boxes' (one per image) in train mode; "
            f"got {plain_repr(targets)}: call .eval() to propose without training"
        )
    for i, t in enumerate(targets):
        b = t.get("boxes") if isinstance(t, Mapping) else None
        if (
            not isinstance(b, torch.Tensor)
            or not b.is_floating_point()
            or b.ndim != 2
            or b.shape[1] != 4
        ):
            raise InputError(
                f"targets[{i}] must be a dict with 'boxes', a (K, 4) float torch.Tensor, xyxy "
                f"pixels; got {plain_repr(t)}"
            )
    return list(targets)


class RegionProposalNetwork(nn.Module):
    r"""The region proposal network of Faster R-CNN (Ren et al. 2015) on one feature map.

    Head: a 3 x 3 convolution and ReLU (``conv``), then per anchor an objectness logit
    (``cls_logits``, 1 x 1) and deltas (``bbox_pred``, 1 x 1;
    :class:`~robopercept.nn.ops.anchors.BoxCoder` weights (1, 1, 1, 1)); the three
    convolutions are initialized from :math:`N(0, 0.01^2)` with zero bias, as
    torchvision's ``RPNHead``. Anchors
    (:class:`~robopercept.nn.ops.anchors.AnchorGenerator`, ordered cell-major) are
    positive at IoU >= ``fg_iou`` with a ground-truth box or when they are a box's best
    anchor (:func:`~robopercept.nn.detection.targets.match_boxes` with
    ``allow_low_quality``), negative below ``bg_iou``, else ignored; ``batch_size``
    are sampled per image, at most ``positive_fraction`` positive
    (:func:`~robopercept.nn.detection.targets.sample_balanced`). ``loss_rpn_objectness``
    is the binary cross-entropy of the sampled anchors' logits; ``loss_rpn_box`` the
    smooth-L1 (:math:`\beta = 1/9`) of the positives' deltas, summed and divided by the
    number sampled (0 without positives). Proposals: the ``pre_nms_top_n`` best
    anchors by objectness, decoded, clipped, boxes under ``min_size`` dropped, NMS at
    ``nms_thresh``, the ``post_nms_top_n`` best kept (train / eval counts separately,
    as torchvision); they are detached, as in the approximate joint training of the
    paper.

    Parameters
    ----------
    in_channels : int
        Channels of the feature map.
    anchor_generator : AnchorGenerator
        With one feature map (one tuple of sizes).
    fg_iou, bg_iou : float
        Anchor labelling thresholds, ``bg_iou <= fg_iou``.
    batch_size, positive_fraction
        Anchors sampled per image and their positive cap.
    pre_nms_top_n, post_nms_top_n : (train, eval) pairs of int
    nms_thresh, min_size : float
        Proposal NMS IoU, smallest proposal side in pixels.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.ops.anchors import AnchorGenerator
    >>> _ = torch.manual_seed(0)
    >>> rpn = RegionProposalNetwork(8, AnchorGenerator((16.0,), (1.0,), offset=0.5)).eval()
    >>> boxes, losses = rpn(torch.rand(1, 8, 4, 4), (32, 32), [(32, 32)])
    >>> boxes[0].shape[1], losses
    (4, {})
    """

    def __init__(
        self,
        in_channels: int,
        anchor_generator: AnchorGenerator,
        *,
        fg_iou: float = 0.7,
        bg_iou: float = 0.3,
        batch_size: int = 256,
        positive_fraction: float = 0.5,
        pre_nms_top_n: tuple[int, int] = (1000, 500),
        post_nms_top_n: tuple[int, int] = (500, 300),
        nms_thresh: float = 0.7,
        min_size: float = 1e-3,
    ) -> None:
        super().__init__()
        c = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        if not isinstance(anchor_generator, AnchorGenerator):
            raise InputError(
                "anchor_generator must be an AnchorGenerator, e.g. AnchorGenerator((16.0, 32.0), "
                f"(0.5, 1.0, 2.0)); got {plain_repr(anchor_generator)}"
            )
        per_level = anchor_generator.num_anchors_per_location()
        if len(per_level) != 1:
            raise InputError(
                f"anchor_generator must have one feature map (one tuple of sizes); got "
                f"{len(per_level)}"
            )
        a = per_level[0]
        check_count(a, "anchors per cell", 1, 4096)
        self.anchor_generator = anchor_generator
        self.conv = nn.Conv2d(c, c, 3, padding=1)
        self.cls_logits = nn.Conv2d(c, a, 1)
        self.bbox_pred = nn.Conv2d(c, 4 * a, 1)
        for layer in (self.conv, self.cls_logits, self.bbox_pred):
            init_conv(layer, 0.0)
        self.box_coder = BoxCoder((1.0, 1.0, 1.0, 1.0))
        self.fg_iou = check_real(fg_iou, "fg_iou", 0.0, 1.0)
        self.bg_iou = check_real(bg_iou, "bg_iou", 0.0, self.fg_iou)
        self.batch_size = check_count(batch_size, "batch_size", 1, 1 << 20)
        self.positive_fraction = check_real(positive_fraction, "positive_fraction", 0.0, 1.0)
        self.pre_nms_top_n = _pair(pre_nms_top_n, "pre_nms_top_n")
        self.post_nms_top_n = _pair(post_nms_top_n, "post_nms_top_n")
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.min_size = check_real(min_size, "min_size", 0.0)

    def anchor_outputs(
        self, features: torch.Tensor, image_shape: tuple[int, int]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The head on ``features`` ``(N, C, h, w)``: objectness logits ``(N, A_total)``,
        deltas ``(N, A_total, 4)`` and the anchors ``(A_total, 4)`` of an ``image_shape``
        ``(H, W)`` batch, ``A_total = h w A``, ordered cell-major (cell ``(r, c)``,
        anchor ``a`` is row ``(r w + c) A + a``, as
        :class:`~robopercept.nn.ops.anchors.AnchorGenerator`)."""
        h = F.relu(self.conv(features))
        n, _, fh, fw = h.shape
        obj = self.cls_logits(h).permute(0, 2, 3, 1).reshape(n, -1)
        reg = self.bbox_pred(h).reshape(n, -1, 4, fh, fw).permute(0, 3, 4, 1, 2).reshape(n, -1, 4)
        anchors = self.anchor_generator(image_shape, [(fh, fw)], dtype=h.dtype).to(h.device)
        return obj, reg, anchors

    def losses(
        self,
        objectness: torch.Tensor,
        deltas: torch.Tensor,
        anchors: torch.Tensor,
        targets: Sequence[Mapping[str, torch.Tensor]],
    ) -> dict[str, torch.Tensor]:
        """``loss_rpn_objectness`` and ``loss_rpn_box`` over the anchors sampled from each
        image (:meth:`anchor_outputs`' tensors, ``targets`` with ``"boxes"`` per image).
        Sampling draws from torch's global generator."""
        sel_obj, sel_lab, sel_reg, sel_tgt, n_sampled = [], [], [], [], 0
        for i, t in enumerate(targets):
            gt = t["boxes"].to(anchors.dtype)
            lab, matched = match_boxes(
                box_iou(gt, anchors), self.fg_iou, self.bg_iou, allow_low_quality=True
            )
            pos, neg = sample_balanced(lab, self.batch_size, self.positive_fraction)
            keep = pos | neg
            n_sampled += int(keep.sum())
            sel_obj.append(objectness[i][keep])
            sel_lab.append(pos[keep].to(objectness.dtype))
            if bool(pos.any()):
                sel_reg.append(deltas[i][pos])
                sel_tgt.append(self.box_coder.encode(gt[matched[pos]], anchors[pos]))
        o = torch.cat(sel_obj)
        loss_obj = (
            F.binary_cross_entropy_with_logits(o, torch.cat(sel_lab))
            if o.numel()
            else objectness.sum() * 0
        )
        if sel_reg:
            loss_box = F.smooth_l1_loss(
                torch.cat(sel_reg), torch.cat(sel_tgt), beta=1.0 / 9, reduction="sum"
            ) / max(n_sampled, 1)
        else:
            loss_box = deltas.sum() * 0.0
        return {"loss_rpn_objectness": loss_obj, "loss_rpn_box": loss_box}

    def filter_proposals(
        self,
        objectness: torch.Tensor,
        deltas: torch.Tensor,
        anchors: torch.Tensor,
        sizes: Sequence[tuple[int, int]],
    ) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Per image of ``sizes`` ``(H, W)``: the top ``pre_nms_top_n`` anchors by
        objectness, decoded, clipped, boxes under ``min_size`` removed, NMS, the top
        ``post_nms_top_n`` (train or eval count by the module's mode); returns the
        ``(P, 4)`` proposals and their ``(P,)`` objectness logits, best first, detached."""
        mode = 0 if self.training else 1
        pre, post = self.pre_nms_top_n[mode], self.post_nms_top_n[mode]
        obj, reg = objectness.detach(), deltas.detach()
        boxes_out, scores_out = [], []
        for i, size in enumerate(sizes):
            k = min(pre, obj.shape[1])
            s, idx = obj[i].topk(k)
            b = clip_boxes(self.box_coder.decode(reg[i][idx], anchors[idx]), size)
            keep = (b[:, 2] - b[:, 0] >= self.min_size) & (b[:, 3] - b[:, 1] >= self.min_size)
            b, s = b[keep], s[keep]
            kept = nms(b, s, self.nms_thresh)[:post]
            boxes_out.append(b[kept])
            scores_out.append(s[kept])
        return boxes_out, scores_out

    def forward(
        self,
        features: torch.Tensor,
        image_shape: tuple[int, int],
        sizes: Sequence[tuple[int, int]],
        targets: Sequence[Mapping[str, torch.Tensor]] | None = None,
    ) -> tuple[list[torch.Tensor], dict[str, torch.Tensor]]:
        """Proposals of a batch and, in train mode, the RPN's losses.

        Parameters
        ----------
        features : (N, C, h, w) float torch.Tensor
            The feature map of the padded batch.
        image_shape : (int, int)
            ``(H, W)`` of the padded batch (the anchors' image).
        sizes : list of (int, int)
            ``(H, W)`` of each image (the proposals are clipped to it).
        targets : list of dict, optional
            ``"boxes"`` ``(K, 4)`` float ``"xyxy"`` per image; required in train mode,
            ignored in eval mode.

        Returns
        -------
        proposals : list of (P, 4) torch.Tensor
            Detached, best first, at most ``post_nms_top_n`` per image.
        losses : dict of str to scalar torch.Tensor
            ``loss_rpn_objectness`` and ``loss_rpn_box`` (train mode), else empty.

        Raises
        ------
        InputError
            ``features`` not ``(N, in_channels, h, w)`` floating point, ``sizes`` not
            one ``(H, W)`` per image, a feature map larger than ``image_shape``, or
            missing or malformed targets in train mode.
        """
        c = self.conv.in_channels
        if (
            not isinstance(features, torch.Tensor)
            or features.ndim != 4
            or features.shape[1] != c
            or not features.is_floating_point()
        ):
            raise InputError(
                f"features must be an (N, {c}, h, w) float torch.Tensor; got "
                + plain_repr(features)
            )
        check_tensor_dtype(features, self, "features")
        if features.shape[2] < 1 or features.shape[3] < 1:
            raise InputError(
                "features must have at least one cell (h, w >= 1); got a "
                f"{tuple(features.shape)} map: the images are smaller than the backbone's "
                "stride"
            )
        n = int(features.shape[0])
        checked = _check_sizes(sizes, n)
        tgts = _check_box_targets(targets, n) if self.training else None
        obj, reg, anchors = self.anchor_outputs(features, image_shape)
        proposals, _ = self.filter_proposals(obj, reg, anchors, checked)
        if tgts is None:
            return proposals, {}
        return proposals, self.losses(obj, reg, anchors, tgts)
