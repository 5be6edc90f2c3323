"""Tests of robopercept.nn.detection.localizer: the single-object localizer overfits, and
its metric equals the hand IoU and label check."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.localizer import evaluate_localizer  # noqa: E402
from robopercept.nn.detection.synthetic import digits_detection_set  # noqa: E402
from robopercept.nn.detection.train import evaluate_detector  # noqa: E402
from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from tests.nn.detection.detectors import build, overfit  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_localizer_overfits_to_high_iou():
    m, ds, _ = overfit("loc", 60, 3e-3)
    out = m.predict([ds[i][0] for i in range(len(ds))])
    for i, o in enumerate(out):
        gt = torch.from_numpy(ds.boxes[i]).float()
        assert float(box_iou(o["boxes"], gt)[0, 0]) >= 0.8
        assert int(o["labels"][0]) == int(ds.labels[i][0])
    assert evaluate_detector(m, ds).stats[1] == pytest.approx(1.0)


def test_localizer_metric_equals_hand_iou_and_label_check():
    m, ds, _ = overfit("loc", 60, 3e-3)
    res = evaluate_localizer(m, ds)
    out = m.predict([ds[i][0] for i in range(len(ds))])
    for i, o in enumerate(out):
        gt = torch.from_numpy(ds.boxes[i]).double()
        assert res.iou[i] == pytest.approx(float(box_iou(o["boxes"].double(), gt)[0, 0]), abs=1e-6)
        assert res.correct[i] == (int(o["labels"][0]) == int(ds.labels[i][0]))
    assert res.mean_iou == pytest.approx(res.iou.mean()) and res.mean_iou >= 0.8
    assert res.accuracy == 1.0


def test_localizer_metric_refuses_several_boxes_per_image():
    ds = digits_detection_set(2, (64, 64), (2, 2), rng=0, scale=(12, 16))
    with pytest.raises(InputError, match="exactly one box per image; image 0 has 2"):
        evaluate_localizer(build("loc"), ds)
