r"""Test-time augmentation of any detector: detections on mirrored, turned and rescaled
copies of each image (:data:`TTA_VIEWS`, ``scales``), mapped back and fused by
clustering, box voting and a score averaged over the views
(:class:`TestTimeAugmentation`); the configuration a model ships with, chosen on its
validation images (:func:`choose_tta`) and overridden option by option
(:func:`resolve_tta`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from numbers import Real
from typing import Any

import torch
from torch import nn

from robopercept._checks import check_choice, check_real
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.detection.base import check_images
from robopercept.nn.detection.train import evaluate_detector
from robopercept.nn.ops.boxes import box_iou, dihedral_boxes
from robopercept.nn.ops.nms import batched_nms

__all__ = [
    "TTA_CHOICES",
    "TTA_GRID",
    "TTA_SCALE_RANGE",
    "TTA_VIEWS",
    "TestTimeAugmentation",
    "check_scales",
    "check_tta_config",
    "choose_tta",
    "rescale_image",
    "resolve_tta",
    "wrap_tta",
]


#: the views of :class:`TestTimeAugmentation`: (hflip, vflip, quarter turns) per view
TTA_VIEWS: dict[str, tuple[tuple[bool, bool, int], ...]] = {
    "identity": ((False, False, 0),),  # the image itself (its rescaled copies: ``scales``)
    "hflip": ((False, False, 0), (True, False, 0)),
    "flips": ((False, False, 0), (True, False, 0), (False, True, 0), (True, True, 0)),
    "dihedral": tuple((h, v, k) for h in (False, True) for v in (False, True) for k in (0, 1)),
    # hflip + vflip is a half turn, so these 8 are the whole dihedral group
}


#: what ``--tta`` takes: a view set of :data:`TTA_VIEWS`, or ``"none"`` (no augmentation,
#: not even the one the model ships with)
TTA_CHOICES = ("none", *TTA_VIEWS)

#: the configurations :func:`choose_tta` tries (with no augmentation at all): each view
#: set at one scale, three (+-10 %) and five (+-20 %), each fused at the model's
#: ``nms_thresh`` and at 0.55 (weighted boxes fusion's default)
TTA_GRID: tuple[dict[str, Any], ...] = tuple(
    {"views": views, "scales": scales, "iou_thresh": iou}
    for views in TTA_VIEWS
    for scales in ((1.0,), (0.9, 1.0, 1.1), (0.8, 0.9, 1.0, 1.1, 1.2))
    for iou in (None, 0.55)
    if (views, scales) != ("identity", (1.0,))
)

#: the scales :class:`TestTimeAugmentation` accepts (image side factors)
TTA_SCALE_RANGE = (0.25, 4.0)


def check_scales(scales: Any) -> tuple[float, ...]:
    """``scales`` as a tuple of distinct floats in :data:`TTA_SCALE_RANGE` (at least one).

    Raises
    ------
    InputError
        Empty, not numbers, out of range or repeated (``--tta-scales``).
    """
    try:
        if not all(isinstance(s, Real) and not isinstance(s, bool) for s in scales):
            raise TypeError
        out = tuple(float(s) for s in scales)
    except (TypeError, ValueError):
        raise InputError(
            f"scales (--tta-scales) must be numbers such as 0.9 1 1.1; got {scales!r}"
        ) from None
    lo, hi = TTA_SCALE_RANGE
    if not out or len(set(out)) != len(out) or not all(lo <= s <= hi for s in out):
        raise InputError(
            f"scales (--tta-scales) must be distinct factors in [{lo:g}, {hi:g}], at least "
            f"one; got {list(out)}"
        )
    return out


def check_tta_config(config: Any) -> dict[str, Any]:
    """A test-time augmentation configuration (a checkpoint's ``tta``, a row of
    :data:`TTA_GRID`) checked: a mapping of exactly ``views`` (a name of
    :data:`TTA_VIEWS`), ``scales`` (:func:`check_scales`) and ``iou_thresh`` (None, the
    model's ``nms_thresh``, or a number in [0, 1]).

    Returns
    -------
    dict
        The same with ``scales`` a tuple of floats.

    Raises
    ------
    InputError
        Anything else.
    """
    keys = {"views", "scales", "iou_thresh"}
    if not isinstance(config, Mapping) or set(config) != keys:
        raise InputError(
            "a test-time augmentation must be a dict of exactly views, scales and "
            f"iou_thresh; got {type(config).__name__}"
        )
    views, iou = config["views"], config["iou_thresh"]
    if not isinstance(views, str):
        raise InputError(f"views must be one of {', '.join(TTA_VIEWS)}; got {views!r}")
    check_choice(views, "views (--tta)", tuple(TTA_VIEWS))
    return {
        "views": views,
        "scales": check_scales(config["scales"]),
        "iou_thresh": None if iou is None else check_real(iou, "iou_thresh", 0.0, 1.0),
    }


def rescale_image(image: torch.Tensor, scale: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``(C, H, W)`` ``image`` resized by ``scale`` (bilinear, half-pixel centres,
    antialiased when shrinking: PIL's and ``torchvision.transforms.v2.Resize``'s
    rule) to ``round(H * scale), round(W * scale)`` (at least 1), and the factors
    ``(sx, sy, sx, sy)`` that take its xyxy boxes back to the image's: divide by them.
    Scale 1 returns the image itself.

    Raises
    ------
    InputError
        Not a non-empty ``(C, H, W)`` float tensor, or a scale outside
        :data:`TTA_SCALE_RANGE`.
    """
    if (
        not isinstance(image, torch.Tensor)
        or image.ndim != 3
        or image.numel() == 0
        or not image.is_floating_point()
    ):
        raise InputError(
            f"image must be a non-empty (C, H, W) float tensor; got {type(image).__name__}"
            + (f" of shape {tuple(image.shape)}" if isinstance(image, torch.Tensor) else "")
        )
    lo, hi = TTA_SCALE_RANGE
    scale = check_real(scale, "scale (--tta-scales)", lo, hi)
    h, w = int(image.shape[-2]), int(image.shape[-1])
    if scale == 1.0:
        return image, torch.ones(4)
    nh, nw = max(1, round(h * scale)), max(1, round(w * scale))
    x = torch.nn.functional.interpolate(
        image[None].float(), size=(nh, nw), mode="bilinear", align_corners=False,
        antialias=scale < 1.0,
    )[0]  # fmt: skip
    return x.to(image.dtype), torch.tensor([nw / w, nh / h, nw / w, nh / h])


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
        scales: Sequence[float] = (1.0,),
        iou_thresh: float | None = None,
        detections_per_img: int | None = None,
    ) -> None:
        super().__init__()
        self.model = check_module(model)
        check_choice(views, "views (--tta)", tuple(TTA_VIEWS))
        self.views = views
        self.scales = check_scales(scales)
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
        views = [(*view, scale) for scale in self.scales for view in TTA_VIEWS[self.views]]
        pooled: list[list[dict[str, torch.Tensor]]] = [[] for _ in ims]
        scaled: dict[float, list[tuple[torch.Tensor, torch.Tensor]]] = {}
        with torch.no_grad():
            for v, (hflip, vflip, k, scale) in enumerate(views):
                if scale not in scaled:  # each image resized once per scale
                    scaled = {scale: [rescale_image(im, scale) for im in ims]}
                seen, factors = [], []
                for x, f in scaled[scale]:
                    dims = [d for d, on in ((-1, hflip), (-2, vflip)) if on]
                    x = torch.flip(x, dims) if dims else x
                    seen.append(torch.rot90(x, k, (-2, -1)) if k else x)
                    factors.append(f)
                out = self.model(seen)
                for i, (x, det) in enumerate(zip(seen, out, strict=True)):
                    h, w = (int(x.shape[-2]), int(x.shape[-1]))
                    size = (w, h) if k % 2 else (h, w)  # the rescaled image, before the turn
                    b = dihedral_boxes(
                        det["boxes"].float(),
                        size,
                        hflip=hflip,
                        vflip=vflip,
                        quarter_turns=k,
                        inverse=True,
                    )
                    b = b / factors[i]
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


def _passes(config: Mapping[str, Any] | None) -> int:
    """How many times ``config`` runs the model on an image (1 without augmentation)."""
    if config is None:
        return 1
    return len(TTA_VIEWS[config["views"]]) * len(config["scales"])


def resolve_tta(
    stored: Mapping[str, Any] | None,
    views: str | None = None,
    scales: Sequence[float] | None = None,
) -> dict[str, Any] | None:
    """The test-time augmentation to run: the one a model ships with (``stored``, its
    checkpoint's ``tta``: ``{"views", "scales", "iou_thresh"}``), each option the user
    gives replacing the stored one. None: no augmentation.

    Parameters
    ----------
    stored : mapping or None
        The checkpoint's configuration (chosen on validation, :func:`choose_tta`).
    views : str, optional
        A name of :data:`TTA_CHOICES` (``--tta``): ``"none"`` turns every augmentation
        off; default the stored views, else ``"identity"``.
    scales : sequence of float, optional
        ``--tta-scales``; default the stored scales, else ``(1.0,)``.

    Returns
    -------
    dict or None
        ``{"views": str, "scales": tuple, "iou_thresh": float or None}`` (None: the
        model's ``nms_thresh``), or None when nothing is augmented (``"none"``, or the
        identity at scale 1).

    Raises
    ------
    InputError
        An unknown view set, bad scales, or scales with ``--tta none``.

    Examples
    --------
    >>> stored = {"views": "flips", "scales": [0.9, 1.0, 1.1], "iou_thresh": 0.55}
    >>> resolve_tta(stored)["scales"]
    (0.9, 1.0, 1.1)
    >>> resolve_tta(stored, "hflip")["views"], resolve_tta(stored, "none")
    ('hflip', None)
    >>> resolve_tta(None, scales=[1.0]) is None
    True
    """
    base = {} if stored is None else check_tta_config(stored)
    if views is not None:
        check_choice(views, "tta (--tta)", TTA_CHOICES)
    if views == "none":
        if scales is not None:
            raise InputError("--tta-scales needs test-time augmentation: drop --tta none")
        return None
    chosen: str = views or base.get("views", "identity")
    check_choice(chosen, "tta (--tta)", tuple(TTA_VIEWS))
    config: dict[str, Any] = {
        "views": chosen,
        "scales": check_scales(scales if scales is not None else base.get("scales", (1.0,))),
        "iou_thresh": base.get("iou_thresh"),
    }
    if chosen == "identity" and config["scales"] == (1.0,):
        return None
    return config


def wrap_tta(model: nn.Module, config: Mapping[str, Any] | None) -> nn.Module:
    """``model`` under the test-time augmentation ``config`` (:func:`resolve_tta`'s
    form), or ``model`` itself for None."""
    if config is None:
        return model
    config = check_tta_config(config)
    return TestTimeAugmentation(
        model, config["views"], scales=config["scales"], iou_thresh=config["iou_thresh"]
    )


def choose_tta(
    model: nn.Module,
    dataset: Any,
    grid: Sequence[Mapping[str, Any]] = TTA_GRID,
) -> tuple[dict[str, Any] | None, list[dict[str, Any]]]:
    """The test-time augmentation ``model`` should ship with: the configuration of
    ``grid`` (or none at all) with the best COCO AP (the mean over IoU 0.5:0.95,
    COCO's default of 100 detections per image) on the validation images of
    ``dataset``: COCO's primary figure, which rewards well-placed boxes (what fusing
    views improves) and, averaged over ten IoU thresholds, moves less from one small
    validation set to another than AP50 alone. Ties go to the better AP50, then to the
    one that runs the model fewest times. The score threshold is chosen after it, on the same
    images through the chosen augmentation
    (:func:`~robopercept.nn.detection.zoo.calibrate_detector` of
    :func:`wrap_tta`'s model), since fusion changes the scores.

    Parameters
    ----------
    model : torch.nn.Module
        A detector of this package.
    dataset : DetectionDataset
        Validation images with their boxes (each image run whole).
    grid : sequence of mapping
        ``{"views", "scales", "iou_thresh"}`` configurations (default :data:`TTA_GRID`).

    Returns
    -------
    config : dict or None
        The chosen configuration (None: no augmentation), as stored in a checkpoint's
        ``tta``.
    table : list of dict
        Every configuration tried with its ``AP``, ``AP50`` and ``passes``, best first.
    """
    model = check_module(model)
    if not all(hasattr(dataset, a) for a in ("images", "boxes", "labels", "to_coco")):
        raise InputError(f"dataset must be a DetectionDataset; got {type(dataset).__name__}")
    candidates: list[dict[str, Any] | None] = [None, *(check_tta_config(g) for g in grid)]
    table: list[dict[str, Any]] = []
    was = model.training
    try:
        for config in candidates:
            summary = evaluate_detector(wrap_tta(model, config).eval(), dataset).summary()
            table.append(
                {
                    "config": config,
                    "AP": round(float(summary["AP"]), 4),
                    "AP50": round(float(summary["AP50"]), 4),
                    "passes": _passes(config),
                }
            )
    finally:
        model.train(was)
    table.sort(key=lambda r: (-r["AP"], -r["AP50"], r["passes"]))
    best = table[0]["config"]
    return (None if best is None else {**best, "scales": list(best["scales"])}), table
