r"""Fast R-CNN (Girshick 2015): a shared backbone, **external** proposals per image
(``proposal_fn``, e.g. selective search; the ground-truth boxes are added to them in
training), RoI max pooling (:func:`~robopercept.nn.ops.roi.roi_pool`) and the
per-region head of :class:`~robopercept.nn.detection.roi_heads.RoIHeads`.
Training samples 25 % foreground regions (IoU >= 0.5 with a ground-truth box) and
background ones (IoU in [0.1, 0.5)), as the paper. The parts are ``backbone`` and
``roi_heads``; checkpoints with the keys of the box head before it was composed
(``roi.*``) load.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from robopercept._checks import plain_repr
from robopercept.errors import InputError
from robopercept.nn.core.backbones import DetectionBackbone
from robopercept.nn.detection.base import Detector, check_images, check_proposals
from robopercept.nn.detection.roi_heads import (
    LEGACY_BOX_KEYS,
    FastRCNNPredictor,
    RoIHeads,
    TwoMLPHead,
)
from robopercept.nn.ops.roi import RoIPool

__all__ = [
    "FastRCNN",
]


class FastRCNN(Detector):
    r"""Fast R-CNN (Girshick 2015): a shared backbone (stride 8), RoI max pooling of
    external proposals, two fully connected layers, then class logits (background and
    ``num_classes``) and class-specific deltas (:class:`~robopercept.nn.ops.anchors.BoxCoder`
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

    renamed_keys = LEGACY_BOX_KEYS

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
        self.backbone = DetectionBackbone(width, strides=(8,))
        box_head = TwoMLPHead(self.backbone.out_channels[-1], pool_size, hidden)
        self.roi_heads = RoIHeads(
            RoIPool(box_head.pool_size, 1.0 / self.backbone.strides[-1]),
            box_head,
            FastRCNNPredictor(box_head.fc7.out_features, self.num_classes),
            self.num_classes,
            bg_low=0.1,
            box_batch_size=box_batch_size,
            box_positive_fraction=box_positive_fraction,
            score_thresh=score_thresh,
            nms_thresh=nms_thresh,
            detections_per_img=detections_per_img,
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
            proposals = [self.proposal_fn(im) for im in check_images(images)]
        props = [p.to(batch.device) for p in check_proposals(proposals, sizes)]
        feats = self.backbone(batch)[-1]
        return self.roi_heads(feats, props, sizes, tgts)
