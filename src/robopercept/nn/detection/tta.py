r"""Test-time augmentation of any detector: detections on mirrored and turned copies of
each image (:data:`TTA_VIEWS`), mapped back and fused by clustering, box voting and a
score averaged over the views (:class:`TestTimeAugmentation`).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from robopercept._checks import check_choice, check_real
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.detection.base import check_images
from robopercept.nn.ops.boxes import box_iou, dihedral_boxes
from robopercept.nn.ops.nms import batched_nms

__all__ = [
    "TTA_VIEWS",
    "TestTimeAugmentation",
]


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
    >>> from robopercept.nn.detection.fcos import FCOS
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
        ims = check_images(images)
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
