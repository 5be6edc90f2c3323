r"""Single-object localisation (the first detector of the course's object-detection
chapter): one class and one box per image, and its figures.

:class:`SingleObjectLocalizer`: backbone, global average pooling, a classification head
(``num_classes`` logits) and a box head giving the box as **normalized cxcywh**
(centre and size divided by the image's width and height, in [0, 1] through a
sigmoid). Loss :math:`L = \mathrm{CE}(p, y) + \lambda\,\mathrm{smoothL1}_\beta(\hat b, b)`.
:func:`evaluate_localizer` measures the mean IoU and the label accuracy
(:class:`LocalizationResult`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.core.backbones import DetectionBackbone
from robopercept.nn.detection.base import Detector, clip_boxes
from robopercept.nn.detection.train import check_detection_dataset, detections_per_image
from robopercept.nn.ops.boxes import box_convert, box_iou

__all__ = [
    "LocalizationResult",
    "SingleObjectLocalizer",
    "evaluate_localizer",
]


class SingleObjectLocalizer(Detector):
    r"""Single-object localisation: a class and one box per image.

    Backbone (:class:`DetectionBackbone`, stride 16), global average pooling, then a
    linear classification head (``num_classes`` logits for labels 1..num_classes) and a
    linear box head whose sigmoid gives the box as normalized ``cxcywh``:
    :math:`(c_x / W, c_y / H, w / W, h / H)` of the (unpadded) image. Loss:

    .. math:: L = \mathrm{CE}(z, y - 1) + \lambda\,\mathrm{smoothL1}_{\beta}(\hat b, b)

    (smooth-L1 averaged over the 4 coordinates and the batch, :math:`\beta` = ``beta``).
    Train mode returns ``{"loss_classifier", "loss_box"}`` (``loss_box`` already times
    ``lam``); eval mode one detection per image (score = softmax probability of the
    label). Each target must hold exactly one box.

    Parameters
    ----------
    num_classes : int
    width : int
        Backbone width.
    lam : float
        :math:`\lambda`, >= 0.
    beta : float
        Smooth-L1 transition, > 0 (in normalized units).

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = SingleObjectLocalizer(3, width=8).eval()
    >>> out = m([torch.rand(3, 32, 48)])
    >>> tuple(out[0]["boxes"].shape), tuple(out[0]["labels"].shape)
    ((1, 4), (1,))
    """

    def __init__(
        self, num_classes: int, width: int = 16, lam: float = 1.0, beta: float = 0.05
    ) -> None:
        super().__init__()
        self._init_common(num_classes, 16)
        self.lam = check_real(lam, "lam", 0.0)
        self.beta = check_real(beta, "beta", 0.0, low_inclusive=False)
        self.backbone = DetectionBackbone(width, strides=(16,))
        c = self.backbone.out_channels[-1]
        self.classifier = nn.Linear(c, self.num_classes)
        self.box_head = nn.Sequential(nn.Linear(c, c), nn.ReLU(), nn.Linear(c, 4))

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
        hp, wp = batch.shape[-2:]
        # pool over each image's own (unpadded) extent
        pooled = []
        s = self.backbone.strides[-1]
        for i, (h, w) in enumerate(sizes):
            fh, fw = max(1, -(-h // s)), max(1, -(-w // s))
            pooled.append(feats[i, :, :fh, :fw].mean(dim=(1, 2)))
        z = torch.stack(pooled)
        logits = self.classifier(z)
        box = torch.sigmoid(self.box_head(z))
        scale = torch.tensor([[w, h, w, h] for h, w in sizes], dtype=box.dtype, device=box.device)
        if self.training:
            assert tgts is not None
            for i, t in enumerate(tgts):
                if t["boxes"].shape[0] != 1:
                    raise InputError(
                        f"targets[{i}] must hold exactly one box for single-object localisation; "
                        f"got {t['boxes'].shape[0]}: use FasterRCNN or FCOS for several"
                    )
            gt = torch.cat([t["boxes"] for t in tgts]).to(box.dtype)
            gt_n = box_convert(gt, "xyxy", "cxcywh") / scale
            labels = torch.cat([t["labels"] for t in tgts]) - 1
            return {
                "loss_classifier": F.cross_entropy(logits, labels),
                "loss_box": self.lam * F.smooth_l1_loss(box, gt_n, beta=self.beta),
            }
        prob = F.softmax(logits, dim=1)
        scores, lab = prob.max(dim=1)
        xyxy = clip_boxes(box_convert(box * scale, "cxcywh", "xyxy"), (int(hp), int(wp)))
        out = []
        for i, (h, w) in enumerate(sizes):
            out.append(
                {
                    "boxes": clip_boxes(xyxy[i : i + 1], (h, w)),
                    "labels": lab[i : i + 1] + 1,
                    "scores": scores[i : i + 1],
                }
            )
        return out


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """Single-object localisation figures (:func:`evaluate_localizer`).

    Attributes
    ----------
    iou : numpy.ndarray
        ``(N,)`` IoU of each image's predicted box with its one ground-truth box.
    correct : numpy.ndarray
        ``(N,)`` bool, predicted label equals the true one.
    mean_iou : float
    accuracy : float
        Fraction of correct labels.
    """

    iou: Any
    correct: Any
    mean_iou: float
    accuracy: float


@torch.inference_mode()
def evaluate_localizer(
    model: nn.Module, dataset: Any, *, batch_size: int = 32
) -> LocalizationResult:
    r"""Mean IoU and label accuracy of a single-object localizer (one box per image).

    For image :math:`i` with its one ground-truth box :math:`b_i` and the model's
    highest-scoring detection :math:`\hat b_i` (an image without a detection counts IoU
    0 and a wrong label),

    .. math:: \mathrm{mIoU} = \frac1N \sum_i \mathrm{IoU}(\hat b_i, b_i).

    Parameters
    ----------
    model : torch.nn.Module
        A :class:`SingleObjectLocalizer` or any model of the detection contract.
    dataset : DetectionDataset
        Exactly one box per image (:func:`~robopercept.nn.detection.synthetic.single_digit_set`).
    batch_size : int

    Returns
    -------
    LocalizationResult

    Raises
    ------
    InputError
        An image without exactly one ground-truth box.
    """
    model = check_module(model)
    ds = check_detection_dataset(dataset)
    bs = check_count(batch_size, "batch_size", 1, 1 << 16)
    counts = [len(b) for b in ds.boxes]
    if any(c != 1 for c in counts):
        bad = next(i for i, c in enumerate(counts) if c != 1)
        raise InputError(
            f"localisation needs exactly one box per image; image {bad} has {counts[bad]} "
            "(use single_digit_set or evaluate_detector)"
        )
    p = next(model.parameters(), None)
    dev = p.device if p is not None else torch.device("cpu")
    ious, correct = [], []
    for t, d in detections_per_image(model, ds, bs, dev):
        if len(d["boxes"]) == 0:
            ious.append(0.0)
            correct.append(False)
            continue
        k = int(torch.argmax(d["scores"]))
        pred = d["boxes"][k : k + 1].detach().cpu().double()
        ious.append(float(box_iou(pred, t["boxes"].double())[0, 0]))
        correct.append(int(d["labels"][k]) == int(t["labels"][0]))
    iou, ok = np.asarray(ious), np.asarray(correct, dtype=bool)
    return LocalizationResult(iou, ok, float(iou.mean()), float(ok.mean()))
