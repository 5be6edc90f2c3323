r"""Faster R-CNN (Ren et al. 2015), composed as torchvision's ``FasterRCNN``: a stride-8
backbone, a region proposal network
(:class:`~robopercept.nn.detection.rpn.RegionProposalNetwork`: 3 x 3 conv, objectness
logit and deltas per anchor of :class:`~robopercept.nn.ops.anchors.AnchorGenerator`;
anchors labelled positive at IoU >= 0.7 (and the best anchor of each ground-truth box,
even below), negative below 0.3, 256 sampled per image, half positive
(:mod:`robopercept.nn.detection.targets`); proposals by decoding, clipping, removing
small boxes and NMS, top-k before and after, fewer in eval), RoI Align
(:func:`~robopercept.nn.ops.roi.roi_align`) and the per-region head of Fast R-CNN
(:class:`~robopercept.nn.detection.roi_heads.RoIHeads`), with optional per-region
branches (Mask and Keypoint R-CNN pass theirs).
The four losses are reported separately under torchvision's names:
``loss_rpn_objectness``, ``loss_rpn_box``, ``loss_classifier``, ``loss_box``.

The parts are ``backbone``, ``roi_heads`` and ``rpn`` (in that order, the order of the
parameters). Checkpoints written before the parts were composed (keys ``roi.*``,
``rpn_conv``, ``rpn_cls``, ``rpn_bbox``, ``mask_head``, ``keypoint_head``: the shipped
detector and segmenter) load: :data:`LEGACY_KEYS` renames them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import torch

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import DetectionBackbone
from robopercept.nn.detection.base import Detector
from robopercept.nn.detection.roi_heads import (
    LEGACY_BOX_KEYS,
    FastRCNNPredictor,
    RegionBranch,
    RoIHeads,
    TwoMLPHead,
)
from robopercept.nn.detection.rpn import RegionProposalNetwork
from robopercept.nn.ops.anchors import AnchorGenerator
from robopercept.nn.ops.roi import RoIAlign

__all__ = [
    "LEGACY_KEYS",
    "FasterRCNN",
]

#: state-dict prefixes of checkpoints written before the parts were composed (the RPN
#: as layers of the detector, the branches beside the box head) -> today's
LEGACY_KEYS: dict[str, str] = {
    **LEGACY_BOX_KEYS,
    "rpn_conv.": "rpn.conv.",
    "rpn_cls.": "rpn.cls_logits.",
    "rpn_bbox.": "rpn.bbox_pred.",
    "mask_head.": "roi_heads.mask_head.",
    "keypoint_head.": "roi_heads.keypoint_head.",
}

#: ``(in_channels, spatial_scale) -> branch``: builds a per-region branch on the
#: backbone's features
_BranchFactory = Callable[[int, float], RegionBranch]


def _sequence(value: Any, name: str) -> tuple[Any, ...]:
    if not isinstance(value, (tuple, list)) or not value:
        raise InputError(
            f"{name} must be a non-empty tuple of positive numbers; got {plain_repr(value)}"
        )
    return tuple(value)


def _factory(value: Any, name: str) -> _BranchFactory | None:
    if value is not None and not callable(value):
        raise InputError(
            f"{name} must be None or a callable (in_channels, spatial_scale) -> branch, e.g. "
            f"lambda c, s: MaskHead(c, num_classes, spatial_scale=s); got {plain_repr(value)}"
        )
    return value


class FasterRCNN(Detector):
    r"""Faster R-CNN (Ren et al. 2015): a region proposal network on a stride-8
    backbone, RoI Align, and the per-region head of :class:`FastRCNN`.

    RPN (:class:`~robopercept.nn.detection.rpn.RegionProposalNetwork`): a 3 x 3
    convolution and ReLU, then per anchor an objectness logit and deltas
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
    (:class:`~robopercept.nn.detection.roi_heads.RoIHeads`, ``loss_classifier``,
    ``loss_box``) samples regions with IoU >= 0.5 foreground and [0, 0.5) background.

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
    mask_head, keypoint_head : callable, optional
        ``(in_channels, spatial_scale) -> branch``: per-region branches of the
        :class:`~robopercept.nn.detection.roi_heads.RoIHeads` (:class:`MaskRCNN` and
        :class:`KeypointRCNN` pass theirs), built after the RPN so that seeded weights
        are drawn in a fixed order.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = FasterRCNN(2, width=8, hidden=32)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1])}]
    >>> sorted(m([torch.rand(3, 32, 32)], t))
    ['loss_box', 'loss_classifier', 'loss_rpn_box', 'loss_rpn_objectness']
    """

    renamed_keys = LEGACY_KEYS

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
        mask_head: _BranchFactory | None = None,
        keypoint_head: _BranchFactory | None = None,
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 8)
        mask_factory = _factory(mask_head, "mask_head")
        keypoint_factory = _factory(keypoint_head, "keypoint_head")
        # the weights are drawn in this order (seeded runs): backbone, box head, RPN,
        # then the branches
        backbone = DetectionBackbone(width, strides=(8,))
        c = backbone.out_channels[-1]
        scale = 1.0 / backbone.strides[-1]
        box_head = TwoMLPHead(c, pool_size, hidden)
        box_predictor = FastRCNNPredictor(box_head.fc7.out_features, self.num_classes)
        anchor_generator = AnchorGenerator(
            _sequence(anchor_sizes, "anchor_sizes"),
            _sequence(aspect_ratios, "aspect_ratios"),
            offset=0.5,
        )
        # checked here to name the arguments of this class
        fg = check_real(rpn_fg_iou, "rpn_fg_iou", 0.0, 1.0)
        check_real(rpn_bg_iou, "rpn_bg_iou", 0.0, fg)
        check_count(rpn_batch_size, "rpn_batch_size", 1, 1 << 20)
        check_real(rpn_positive_fraction, "rpn_positive_fraction", 0.0, 1.0)
        check_real(rpn_nms_thresh, "rpn_nms_thresh", 0.0, 1.0)
        rpn = RegionProposalNetwork(
            c,
            anchor_generator,
            fg_iou=rpn_fg_iou,
            bg_iou=rpn_bg_iou,
            batch_size=rpn_batch_size,
            positive_fraction=rpn_positive_fraction,
            pre_nms_top_n=pre_nms_top_n,
            post_nms_top_n=post_nms_top_n,
            nms_thresh=rpn_nms_thresh,
            min_size=min_size,
        )
        self.backbone = backbone
        self.roi_heads = RoIHeads(
            RoIAlign(box_head.pool_size, scale, sampling_ratio=2),
            box_head,
            box_predictor,
            self.num_classes,
            box_batch_size=box_batch_size,
            box_positive_fraction=box_positive_fraction,
            score_thresh=score_thresh,
            nms_thresh=nms_thresh,
            detections_per_img=detections_per_img,
            mask_head=mask_factory(c, scale) if mask_factory is not None else None,
            keypoint_head=keypoint_factory(c, scale) if keypoint_factory is not None else None,
        )
        self.rpn = rpn

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
            obj, reg, anchors = self.rpn.anchor_outputs(
                feats, (int(batch.shape[2]), int(batch.shape[3]))
            )
            props, scores = self.rpn.filter_proposals(obj, reg, anchors, sizes)
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
        shape = (int(batch.shape[2]), int(batch.shape[3]))
        if self.training:
            assert tgts is not None
            props, losses = self.rpn(feats, shape, sizes, tgts)
            head = self.roi_heads(feats, props, sizes, tgts)
            assert isinstance(head, dict)
            losses.update(head)
            return losses
        props, _ = self.rpn(feats, shape, sizes)
        return self.roi_heads(feats, props, sizes)
