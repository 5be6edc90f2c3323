"""Tests of robopercept.nn.detection.roi_heads: region sampling fractions and IoU bands."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from tests.nn.detection.detectors import build, grid_proposals  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_roi_sampling_fractions_and_bands():
    m = build("fast", box_batch_size=32).train()
    torch.manual_seed(0)
    gt = {"boxes": torch.tensor([[8.0, 8, 40, 40]]), "labels": torch.tensor([4])}
    props = [grid_proposals(torch.zeros(3, 64, 64))]
    rois, labels, deltas = m.select_training_samples(props, [gt])
    iou = box_iou(gt["boxes"], rois[0])[0]
    fg = labels[0] > 0
    assert rois[0].shape[0] == 32 and int(fg.sum()) == 8  # 25 % of 32
    assert bool((labels[0][fg] == 4).all()) and bool((iou[fg] >= 0.5).all())
    assert bool(((iou[~fg] >= 0.1) & (iou[~fg] < 0.5)).all())  # Fast R-CNN's background band
    assert bool((deltas[0][~fg] == 0).all())
