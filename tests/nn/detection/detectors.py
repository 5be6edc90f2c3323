"""Tiny detectors and batches shared by the detection tests (not a test module)."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.nn.detection.fast_rcnn import FastRCNN  # noqa: E402
from robopercept.nn.detection.faster_rcnn import FasterRCNN  # noqa: E402
from robopercept.nn.detection.fcos import FCOS  # noqa: E402
from robopercept.nn.detection.localizer import SingleObjectLocalizer  # noqa: E402
from robopercept.nn.detection.synthetic import digits_detection_set, single_digit_set  # noqa: E402
from robopercept.nn.detection.train import train_detector  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402


def grid_proposals(image: torch.Tensor) -> torch.Tensor:
    """Sliding-window proposals (squares of 16, 24, 32 px every 8 px): a stand-in for
    selective search, so Fast R-CNN's tests do not depend on it."""
    h, w = image.shape[1:]
    rows = [
        [x, y, x + s, y + s]
        for s in (16, 24, 32)
        for y in range(0, h - s + 1, 8)
        for x in range(0, w - s + 1, 8)
    ]
    return torch.tensor(rows, dtype=torch.float32)


def build(kind: str, num_classes: int = 10, **kw):
    torch.manual_seed(0)
    if kind == "loc":
        return SingleObjectLocalizer(num_classes, width=8, **kw)
    if kind == "fast":
        kw = {"width": 8, "hidden": 64, "box_batch_size": 64, **kw}
        return FastRCNN(num_classes, grid_proposals, **kw)
    if kind == "faster":
        kw = {"width": 8, "hidden": 64, "box_batch_size": 64, "rpn_batch_size": 64, **kw}
        return FasterRCNN(num_classes, **kw)
    return FCOS(num_classes, width=8, head_channels=32, **kw)


LOSSES = {
    "loc": {"loss_classifier", "loss_box"},
    "fast": {"loss_classifier", "loss_box"},
    "faster": {"loss_rpn_objectness", "loss_rpn_box", "loss_classifier", "loss_box"},
    "fcos": {"classification", "bbox_regression", "bbox_ctrness"},
}


KINDS = tuple(LOSSES)


def tiny_batch(one_box: bool = False):
    g = torch.Generator().manual_seed(1)
    images = [torch.rand(3, 64, 64, generator=g), torch.rand(3, 48, 56, generator=g)]
    targets = [
        {"boxes": torch.tensor([[8.0, 10, 40, 50]]), "labels": torch.tensor([3])},
        {"boxes": torch.tensor([[20.0, 4, 50, 30]]), "labels": torch.tensor([7])},
    ]
    if not one_box:
        targets[0] = {
            "boxes": torch.tensor([[8.0, 10, 40, 50], [44, 40, 62, 62]]),
            "labels": torch.tensor([3, 1]),
        }
    return images, targets


def overfit(kind: str, epochs: int, lr: float):
    if kind == "loc":
        ds = single_digit_set(2, (64, 64), rng=0, scale=(20, 40))
    else:
        ds = digits_detection_set(2, (64, 64), (1, 1), rng=0, scale=(16, 32))
    m = build(kind)
    cfg = TrainConfig(
        epochs=epochs, batch_size=2, lr=lr, device="cpu", schedule="constant", weight_decay=0.0
    )
    hist = train_detector(m, ds, cfg, progress=False)
    return m, ds, hist
