r"""R-CNN (Girshick et al. 2014), the "slow" R-CNN: each proposal (selective search,
:func:`selective_search_proposals`, or given) warped with context padding to a fixed
size and classified by a small CNN of its own (background included), with a linear
per-class box regressor on its features; positives IoU >= 0.5, negatives < 0.3;
``last_timing`` measures the seconds per image (:class:`RCNN`). Composed of
:class:`~robopercept.nn.detection.roi_heads.RoIHeads` (``roi_heads``) whose pooler warps
the regions out of the image, whose box head is the CNN and whose predictor the linear
classifier and box regressor; checkpoints with the keys of before (``roi.*``) load.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import torch
from torch import nn

from robopercept._checks import plain_repr
from robopercept.errors import InputError
from robopercept.features import selective_search
from robopercept.nn._guards import check_count
from robopercept.nn.core.blocks import ConvBNAct
from robopercept.nn.detection.base import Detector, check_images, check_proposals
from robopercept.nn.detection.roi_heads import FastRCNNPredictor, RoIHeads
from robopercept.nn.ops.roi import roi_align

__all__ = [
    "RCNN",
    "selective_search_proposals",
]


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
    im = check_images([image])[0]
    k = check_count(max_proposals, "max_proposals", 1, 1 << 20)
    arr = im.detach().cpu().permute(1, 2, 0).double().clamp(0, 1).numpy()
    xywh = selective_search(arr, mode, rng=0, max_proposals=k)  # type: ignore[arg-type]
    b = torch.as_tensor(xywh, dtype=torch.float32).reshape(-1, 4)
    return torch.cat((b[:, :2], b[:, :2] + b[:, 2:]), dim=1).to(im.device)


def _warp_cnn(width: int, hidden: int) -> nn.Sequential:
    """The region CNN of R-CNN: three ConvBNAct + max-pool stages, global average pooling,
    one fully connected layer (the features)."""
    return nn.Sequential(
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


class _LinearOnFixedFeatures(FastRCNNPredictor):
    """Class logits and a linear per-class box regressor on the (detached) features."""

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        # the box regressor is a linear model of fixed CNN features (as the paper's
        # ridge regressor on pool5): its gradient does not reach the CNN
        return self.cls_score(x), self.bbox_pred(x.detach())


def _warp(image: torch.Tensor, boxes: torch.Tensor, s: int, p: int) -> torch.Tensor:
    cx, cy = (boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2
    f = s / (s - 2 * p)
    hw = (boxes[:, 2] - boxes[:, 0]) * f / 2
    hh = (boxes[:, 3] - boxes[:, 1]) * f / 2
    big = torch.stack((cx - hw, cy - hh, cx + hw, cy + hh), dim=1)
    return roi_align(image[None], [big], s, 1.0, sampling_ratio=2, aligned=True)


class _ContextWarp(nn.Module):
    """The "pooler" of R-CNN: each image's regions warped with context padding to
    ``(P, 3, S, S)`` (:meth:`RCNN.warp`), all images' concatenated."""

    def __init__(self, warp_size: int, context: int) -> None:
        super().__init__()
        self.warp_size, self.context = warp_size, context

    def forward(self, batch: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        s, p = self.warp_size, self.context
        return torch.cat([_warp(batch[i], r, s, p) for i, r in enumerate(rois)])


class RCNN(Detector):
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
    The warp samples bilinearly (:func:`~robopercept.nn.ops.roi.roi_align`, 2 x 2 samples
    per output pixel) the normalized image; outside the image the value is 0, i.e. the
    mean colour, as the paper's mean padding.

    Training (the paper's fine-tuning stage): the ground-truth boxes join the
    proposals; IoU >= 0.5 with a ground-truth box is foreground (its class), < 0.3
    background, between ignored; ``box_batch_size`` regions per image with at most
    ``box_positive_fraction`` foreground. Losses: ``loss_classifier`` (cross-entropy
    over background + classes) and ``loss_box`` (smooth-L1, :math:`\beta = 1/9`, on
    the true class's :class:`~robopercept.nn.ops.anchors.BoxCoder` deltas, weights
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

    #: checkpoints written before the region head was composed (``roi`` of the model)
    renamed_keys: ClassVar[Mapping[str, str]] = {
        "roi.features.": "roi_heads.box_head.",
        "roi.cls_score.": "roi_heads.box_predictor.cls_score.",
        "roi.bbox_pred.": "roi_heads.box_predictor.bbox_pred.",
    }

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
        width = check_count(width, "width", 1, 1024)
        hidden = check_count(hidden, "hidden", 1, 1 << 14)
        box_head = _warp_cnn(width, hidden)
        self.roi_heads = RoIHeads(
            _ContextWarp(self.warp_size, self.context),
            box_head,
            _LinearOnFixedFeatures(hidden, self.num_classes),
            self.num_classes,
            bg_threshold=0.3,
            box_batch_size=box_batch_size,
            box_positive_fraction=box_positive_fraction,
            score_thresh=score_thresh,
            nms_thresh=nms_thresh,
            detections_per_img=detections_per_img,
            chunk=chunk,
        )
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
        im = check_images([image])[0]
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
        return _warp(im, boxes.to(im.device, im.dtype), self.warp_size, self.context)

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
            proposals = [fn(im) for im in check_images(images)]
        props = [p.to(batch.device) for p in check_proposals(proposals, sizes)]
        t1 = time.perf_counter()
        if self.training:
            return self.roi_heads(batch, props, sizes, tgts)
        out = self.roi_heads(batch, props, sizes)
        t2 = time.perf_counter()
        n = len(sizes)
        self.last_timing = {
            "proposals": (t1 - t0) / n,
            "cnn": (t2 - t1) / n,
            "total": (t2 - t0) / n,
        }
        return out
