r"""Faster R-CNN (Ren et al. 2015): a region proposal network (3 x 3 conv, objectness
logit and deltas per anchor of :class:`~robopercept.nn.ops.anchors.AnchorGenerator`),
anchors labelled positive at IoU >= 0.7 (and the best anchor of each ground-truth box,
even below), negative below 0.3, 256 sampled per image, half positive
(:mod:`robopercept.nn.detection.targets`); proposals by decoding, clipping, removing
small boxes and NMS (top-k before and after, fewer in eval); RoI Align
(:func:`~robopercept.nn.ops.roi.roi_align`) and the per-region head of Fast R-CNN
(:class:`~robopercept.nn.detection.roi_heads.TwoStageDetector`).
The four losses are reported separately under torchvision's names:
``loss_rpn_objectness``, ``loss_rpn_box``, ``loss_classifier``, ``loss_box``.

The region proposal network lives in :class:`FasterRCNN` itself (``rpn_conv``,
``rpn_cls``, ``rpn_bbox`` and the methods ``rpn``, ``rpn_losses``, ``proposals``,
``rpn_outputs``): the shipped checkpoints' state-dict keys depend on that layout.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.detection.base import clip_boxes, init_conv
from robopercept.nn.detection.roi_heads import TwoStageDetector
from robopercept.nn.detection.targets import match_boxes, sample_balanced
from robopercept.nn.ops.anchors import AnchorGenerator, BoxCoder
from robopercept.nn.ops.boxes import box_iou
from robopercept.nn.ops.nms import nms

__all__ = [
    "FasterRCNN",
]


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


class FasterRCNN(TwoStageDetector):
    r"""Faster R-CNN (Ren et al. 2015): a region proposal network on a stride-8
    backbone, RoI Align, and the per-region head of :class:`FastRCNN`.

    RPN: a 3 x 3 convolution and ReLU, then per anchor an objectness logit and deltas
    (:class:`~robopercept.nn.ops.anchors.BoxCoder` weights (1, 1, 1, 1)). Anchors
    (:class:`~robopercept.nn.ops.anchors.AnchorGenerator`, centred on cells) are positive at
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
        Of the :class:`~robopercept.nn.ops.anchors.AnchorGenerator`, pixels and h / w.
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
            init_conv(layer, 0.0)
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
            b = clip_boxes(self.rpn_coder.decode(reg[i][idx], anchors[idx]), size)
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
