r"""The per-region part of the two-stage detectors (R-CNN, Fast and Faster R-CNN and
their Mask and Keypoint branches): :class:`RoIHeads`, composed as torchvision's
``models.detection.roi_heads.RoIHeads`` of a pooler, a box head
(:class:`TwoMLPHead`), a box predictor (:class:`FastRCNNPredictor`) and optional
per-region branches (:class:`RegionBranch`: Mask R-CNN's
:class:`~robopercept.nn.detection.mask_rcnn.MaskHead`, Keypoint R-CNN's
:class:`~robopercept.nn.detection.keypoint_rcnn.KeypointHead`).

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
clip, score threshold, NMS, the ``detections_per_img`` best. The branches add their
losses on the sampled regions and their outputs on the final detections.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import MAX_CHANNELS
from robopercept.nn.detection.base import clip_boxes
from robopercept.nn.detection.targets import match_boxes, sample_balanced
from robopercept.nn.ops.anchors import BoxCoder
from robopercept.nn.ops.boxes import box_iou
from robopercept.nn.ops.nms import batched_nms

__all__ = [
    "LEGACY_BOX_KEYS",
    "FastRCNNPredictor",
    "RegionBranch",
    "RoIHeads",
    "TwoMLPHead",
]

#: state-dict prefixes of the box head before it was composed (``roi`` of the detector,
#: checkpoints written before issue 45) -> today's; the detectors rename them on load
LEGACY_BOX_KEYS: dict[str, str] = {
    "roi.fc.1.": "roi_heads.box_head.fc6.",
    "roi.fc.3.": "roi_heads.box_head.fc7.",
    "roi.cls_score.": "roi_heads.box_predictor.cls_score.",
    "roi.bbox_pred.": "roi_heads.box_predictor.bbox_pred.",
}


def _empty_detections(device: torch.device) -> dict[str, torch.Tensor]:
    return {
        "boxes": torch.zeros((0, 4), device=device),
        "labels": torch.zeros((0,), dtype=torch.int64, device=device),
        "scores": torch.zeros((0,), device=device),
    }


class TwoMLPHead(nn.Module):
    """Two fully connected layers with ReLU on the flattened pooled regions
    (torchvision's ``TwoMLPHead``): ``(R, C, P, P)`` -> ``(R, hidden)``.

    Parameters
    ----------
    in_channels : int
        Channels :math:`C` of the pooled features.
    pool_size : int
        Side :math:`P` of the pooled regions.
    hidden : int
        Width of both layers.

    Examples
    --------
    >>> import torch
    >>> TwoMLPHead(4, 2, 8)(torch.zeros(3, 4, 2, 2)).shape
    torch.Size([3, 8])
    """

    def __init__(self, in_channels: int, pool_size: int, hidden: int) -> None:
        super().__init__()
        c = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        p = check_count(pool_size, "pool_size", 1, 64)
        h = check_count(hidden, "hidden", 1, 1 << 14)
        self.pool_size = p
        self.fc6 = nn.Linear(c * p * p, h)
        self.fc7 = nn.Linear(h, h)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``relu(fc7(relu(fc6(flatten(x)))))``."""
        return F.relu(self.fc7(F.relu(self.fc6(x.flatten(1)))))


class FastRCNNPredictor(nn.Module):
    """Class logits (background and ``num_classes``) and class-specific deltas of each
    region's features (torchvision's ``FastRCNNPredictor``).

    Parameters
    ----------
    in_features : int
    num_classes : int
        Without the background.

    Examples
    --------
    >>> import torch
    >>> logits, deltas = FastRCNNPredictor(8, 2)(torch.zeros(3, 8))
    >>> tuple(logits.shape), tuple(deltas.shape)
    ((3, 3), (3, 12))
    """

    def __init__(self, in_features: int, num_classes: int) -> None:
        super().__init__()
        f = check_count(in_features, "in_features", 1, 1 << 14)
        k = check_count(num_classes, "num_classes", 1, 1 << 16)
        self.cls_score = nn.Linear(f, k + 1)
        self.bbox_pred = nn.Linear(f, 4 * (k + 1))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(R, K + 1)`` logits and ``(R, 4 (K + 1))`` deltas of ``(R, in_features)``."""
        return self.cls_score(x), self.bbox_pred(x)


class RegionBranch(Protocol):
    """A per-region branch of :class:`RoIHeads` beside the box head (an
    ``nn.Module``: Mask R-CNN's masks, Keypoint R-CNN's keypoints)."""

    def losses(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        targets: Sequence[Mapping[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        """The branch's losses on the sampled regions ``rois`` (per image), their class
        ``labels`` (0 background) and the index of the ground-truth box each is
        ``matched`` to (:meth:`RoIHeads.sample_regions`)."""
        ...

    def outputs(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        detections: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        """``detections`` (per image ``"boxes"``, ``"labels"``, ``"scores"``) with the
        branch's outputs added."""
        ...


def _check_branch(branch: Any, name: str) -> Any:
    if branch is None:
        return None
    if not isinstance(branch, nn.Module) or not all(
        callable(getattr(branch, m, None)) for m in ("losses", "outputs")
    ):
        raise InputError(
            f"{name} must be None or an nn.Module with losses() and outputs() (a "
            f"RegionBranch such as MaskHead); got {plain_repr(branch)}"
        )
    return branch


class RoIHeads(nn.Module):
    r"""The per-region part of the two-stage detectors: pool the regions, run the box
    head and predictor, and any per-region branches (torchvision's ``RoIHeads``).

    Training (:meth:`sample_regions`): the ground-truth boxes join the proposals;
    regions with IoU >= ``fg_threshold`` are foreground (the matched box's class),
    those in ``[bg_low, bg_threshold)`` background, the rest ignored (in an image
    without objects every proposal is background); ``box_batch_size`` regions per
    image are sampled with at most ``box_positive_fraction`` foreground. Losses
    (:meth:`box_losses`): ``loss_classifier`` (cross-entropy) and ``loss_box``
    (smooth-L1, :math:`\beta = 1/9`, on the true class's deltas of foreground regions,
    :class:`~robopercept.nn.ops.anchors.BoxCoder` weights ``bbox_reg_weights``, summed
    and divided by the number of sampled regions), then each branch's. Eval
    (:meth:`postprocess_detections`): per class, decode, clip, score threshold, NMS,
    the ``detections_per_img`` best, then each branch's outputs.

    Parameters
    ----------
    box_pooler : torch.nn.Module
        ``(features, rois) -> (R, ...)`` pooled regions, ``rois`` a list of ``(P, 4)``
        ``"xyxy"`` tensors per image (e.g. :class:`~robopercept.nn.ops.roi.RoIAlign`).
    box_head : torch.nn.Module
        Pooled regions -> ``(R, F)`` features (e.g. :class:`TwoMLPHead`).
    box_predictor : torch.nn.Module
        Features -> ``(R, K + 1)`` logits and ``(R, 4 (K + 1))`` deltas (e.g.
        :class:`FastRCNNPredictor`).
    num_classes : int
        :math:`K`, without the background.
    fg_threshold, bg_threshold, bg_low : float
        The IoU bands of :func:`~robopercept.nn.detection.targets.match_boxes`.
    box_batch_size, box_positive_fraction
        Regions sampled per image and their foreground cap.
    score_thresh, nms_thresh, detections_per_img
        Post-processing.
    bbox_reg_weights : 4 floats
        Of the :class:`~robopercept.nn.ops.anchors.BoxCoder`.
    chunk : int, optional
        Regions through the head at once in eval mode (memory bound); None: all.
    mask_head, keypoint_head : RegionBranch, optional
        Per-region branches (losses in training, outputs in eval), run in this order.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.ops.roi import RoIAlign
    >>> _ = torch.manual_seed(0)
    >>> heads = RoIHeads(RoIAlign(2, 0.5, 2), TwoMLPHead(4, 2, 8), FastRCNNPredictor(8, 2), 2)
    >>> out = heads.eval()(torch.rand(1, 4, 8, 8), [torch.tensor([[0.0, 0, 8, 8]])], [(16, 16)])
    >>> sorted(out[0])
    ['boxes', 'labels', 'scores']
    """

    def __init__(
        self,
        box_pooler: nn.Module,
        box_head: nn.Module,
        box_predictor: nn.Module,
        num_classes: int,
        *,
        fg_threshold: float = 0.5,
        bg_threshold: float = 0.5,
        bg_low: float = 0.0,
        box_batch_size: int = 128,
        box_positive_fraction: float = 0.25,
        score_thresh: float = 0.05,
        nms_thresh: float = 0.5,
        detections_per_img: int = 100,
        bbox_reg_weights: tuple[float, float, float, float] = (10.0, 10.0, 5.0, 5.0),
        chunk: int | None = None,
        mask_head: RegionBranch | None = None,
        keypoint_head: RegionBranch | None = None,
    ) -> None:
        super().__init__()
        for name, part in (
            ("box_pooler", box_pooler),
            ("box_head", box_head),
            ("box_predictor", box_predictor),
        ):
            if not isinstance(part, nn.Module):
                raise InputError(f"{name} must be a torch.nn.Module; got {plain_repr(part)}")
        self.num_classes = check_count(num_classes, "num_classes", 1, 1 << 16)
        self.fg_threshold = check_real(fg_threshold, "fg_threshold", 0.0, 1.0)
        self.bg_threshold = check_real(bg_threshold, "bg_threshold", 0.0, self.fg_threshold)
        self.bg_low = check_real(bg_low, "bg_low", 0.0, self.bg_threshold)
        self.box_batch_size = check_count(box_batch_size, "box_batch_size", 1, 1 << 20)
        self.box_positive_fraction = check_real(
            box_positive_fraction, "box_positive_fraction", 0.0, 1.0
        )
        self.score_thresh = check_real(score_thresh, "score_thresh", 0.0, 1.0)
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.detections_per_img = check_count(detections_per_img, "detections_per_img", 1, 1 << 20)
        self.box_coder = BoxCoder(bbox_reg_weights)
        self.chunk = None if chunk is None else check_count(chunk, "chunk", 1, 1 << 20)
        self.box_pooler = box_pooler
        self.box_head = box_head
        self.box_predictor = box_predictor
        self.mask_head = _check_branch(mask_head, "mask_head")
        self.keypoint_head = _check_branch(keypoint_head, "keypoint_head")

    def branches(self) -> list[RegionBranch]:
        """The per-region branches present, in the order they run (mask, keypoint)."""
        return [b for b in (self.mask_head, self.keypoint_head) if b is not None]

    def select_training_samples(
        self, proposals: list[torch.Tensor], targets: Sequence[Mapping[str, torch.Tensor]]
    ) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Tensor]]:
        """Add the ground truth to the proposals, label them (IoU >= ``fg_threshold``
        foreground, [``bg_low``, ``bg_threshold``) background) and sample
        ``box_batch_size`` with at most ``box_positive_fraction`` foreground; returns
        the regions, their class labels (0 background) and their regression targets."""
        rois, labels, deltas, _ = self.sample_regions(proposals, targets)
        return rois, labels, deltas

    def sample_regions(
        self, proposals: list[torch.Tensor], targets: Sequence[Mapping[str, torch.Tensor]]
    ) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Tensor], list[torch.Tensor]]:
        """:meth:`select_training_samples` and, per image, the index of the ground-truth
        box each sampled region is matched to (meaningful for the foreground ones; the
        targets of the branches)."""
        rois, labels, deltas, matches = [], [], [], []
        for p, t in zip(proposals, targets, strict=True):
            gt = t["boxes"].to(p.dtype)
            cand = torch.cat((p, gt))
            iou = box_iou(gt, cand)
            # an image without objects: every proposal is background (no IoU band)
            lab, matched = match_boxes(
                iou, self.fg_threshold, self.bg_threshold, self.bg_low if gt.shape[0] else 0.0
            )
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

    def box_outputs(
        self, features: torch.Tensor, rois: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Pool ``rois`` (per image) from ``features`` and run the box head and
        predictor: ``(R, K + 1)`` logits and ``(R, 4 (K + 1))`` deltas (in eval mode
        ``chunk`` regions at a time)."""
        pooled = self.box_pooler(features, rois)
        if self.training or self.chunk is None or pooled.shape[0] <= self.chunk:
            return self.box_predictor(self.box_head(pooled))
        c = self.chunk
        parts = [
            self.box_predictor(self.box_head(pooled[i : i + c]))
            for i in range(0, pooled.shape[0], c)
        ]
        return torch.cat([a for a, _ in parts]), torch.cat([b for _, b in parts])

    def box_losses(
        self,
        logits: torch.Tensor,
        box_reg: torch.Tensor,
        labels: list[torch.Tensor],
        deltas: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        """``loss_classifier`` and ``loss_box`` of the sampled regions (torchvision's
        ``fastrcnn_loss``)."""
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

    def postprocess_detections(
        self,
        logits: torch.Tensor,
        box_reg: torch.Tensor,
        rois: list[torch.Tensor],
        sizes: list[tuple[int, int]],
    ) -> list[dict[str, torch.Tensor]]:
        """Per image: per class decode, clip, keep scores above ``score_thresh`` and boxes
        of side >= 0.01, NMS per class, the ``detections_per_img`` best."""
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

    def forward(
        self,
        features: torch.Tensor,
        proposals: list[torch.Tensor],
        sizes: list[tuple[int, int]],
        targets: Sequence[Mapping[str, torch.Tensor]] | None = None,
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of the regions ``proposals``.

        Parameters
        ----------
        features : torch.Tensor
            What ``box_pooler`` pools from (the feature map of the padded batch).
        proposals : list of (P, 4) float torch.Tensor
            ``"xyxy"`` proposals per image.
        sizes : list of (int, int)
            ``(H, W)`` of each image.
        targets : list of dict, optional
            ``"boxes"``, ``"labels"`` (and what the branches need) per image; required
            in train mode.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` (and the
            branches' outputs) per image.

        Raises
        ------
        InputError
            ``proposals`` or ``targets`` not one per image of ``sizes``, or missing
            targets in train mode.
        """
        if not isinstance(proposals, (list, tuple)) or len(proposals) != len(sizes):
            raise InputError(
                f"proposals must be a list of {len(sizes)} (P, 4) tensors, one per image; got "
                + plain_repr(proposals)
            )
        if self.training:
            if not isinstance(targets, (list, tuple)) or len(targets) != len(sizes):
                raise InputError(
                    f"targets must be a list of {len(sizes)} dicts (one per image) in train "
                    f"mode; got {plain_repr(targets)}: call .eval() to detect"
                )
            rois, labels, deltas, matched = self.sample_regions(list(proposals), targets)
            logits, reg = self.box_outputs(features, rois)
            losses = self.box_losses(logits, reg, labels, deltas)
            for branch in self.branches():
                losses.update(branch.losses(features, sizes, targets, rois, labels, matched))
            return losses
        logits, reg = self.box_outputs(features, list(proposals))
        dets = self.postprocess_detections(logits, reg, list(proposals), sizes)
        for branch in self.branches():
            dets = branch.outputs(features, sizes, dets)
        return dets
