r"""The per-region part of the two-stage detectors (R-CNN, Fast and Faster R-CNN and
their Mask and Keypoint branches): :class:`TwoStageDetector`.

Given region proposals, training adds the ground-truth boxes to them, labels each
region by its IoU with the ground truth (:func:`~robopercept.nn.detection.targets.match_boxes`:
IoU >= 0.5 foreground, ``[bg_low, bg_high)`` background, the rest ignored) and samples
``box_batch_size`` regions with at most ``box_positive_fraction`` foreground
(:func:`~robopercept.nn.detection.targets.sample_balanced`). The regions are pooled
(RoI max pooling, :func:`~robopercept.nn.ops.roi.roi_pool`, or RoI Align,
:func:`~robopercept.nn.ops.roi.roi_align`) and a head of two fully connected layers
gives class logits (background and the classes) and class-specific deltas
(:class:`~robopercept.nn.ops.anchors.BoxCoder` weights (10, 10, 5, 5)); torchvision's
``TwoMLPHead`` + ``FastRCNNPredictor``. Losses ``loss_classifier`` (cross-entropy) and
``loss_box`` (smooth-L1 with :math:`\beta = 1/9` on the true class's deltas, summed and
divided by the number of sampled regions, as torchvision's). Eval: per class, decode,
clip, score threshold, NMS, the ``detections_per_img`` best.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import DetectionBackbone
from robopercept.nn.detection.base import Detector, clip_boxes
from robopercept.nn.detection.targets import match_boxes, sample_balanced
from robopercept.nn.ops.anchors import BoxCoder
from robopercept.nn.ops.boxes import box_iou
from robopercept.nn.ops.nms import batched_nms
from robopercept.nn.ops.roi import roi_align, roi_pool

__all__ = [
    "TwoStageDetector",
]


def _empty_detections(device: torch.device) -> dict[str, torch.Tensor]:
    return {
        "boxes": torch.zeros((0, 4), device=device),
        "labels": torch.zeros((0,), dtype=torch.int64, device=device),
        "scores": torch.zeros((0,), device=device),
    }


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


class TwoStageDetector(Detector):
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
            boxes = clip_boxes(self.box_coder.decode(d, r).reshape(k, c + 1, 4)[:, 1:], size)
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
