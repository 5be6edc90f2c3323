"""Tests of robopercept.nn.detection.targets: anchor and region matching by IoU with
its bands and low-quality matches, and balanced sampling, by hand."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.targets import match_boxes, sample_balanced  # noqa: E402
from robopercept.nn.ops.boxes import box_iou  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


class TestMatchBoxes:
    def test_anchor_equal_to_gt_is_positive(self):
        gt = torch.tensor([[10.0, 10, 30, 30]])
        anchors = torch.tensor([[10.0, 10, 30, 30], [0, 0, 8, 8], [12, 10, 32, 30]])
        labels, matched = match_boxes(box_iou(gt, anchors), 0.7, 0.3)
        # IoU 1, 0 and 18*20 / (20*20 + 2*20) = 0.818
        assert labels.tolist() == [1, 0, 1]
        assert matched.tolist() == [0, 0, 0]

    def test_best_anchor_per_gt_is_positive_below_threshold(self):
        gt = torch.tensor([[0.0, 0, 10, 10], [50, 50, 60, 60]])
        anchors = torch.tensor(
            [[0.0, 0, 20, 10], [0, 0, 40, 40], [50, 50, 70, 70], [80, 80, 90, 90]]
        )
        iou = box_iou(gt, anchors)  # [[0.5, 1/16, 0, 0], [0, 0, 0.25, 0]]
        labels, matched = match_boxes(iou, 0.7, 0.3, allow_low_quality=True)
        assert labels.tolist() == [1, 0, 1, 0]
        assert matched[2] == 1
        labels, _ = match_boxes(iou, 0.7, 0.3)
        assert labels.tolist() == [-1, 0, 0, 0]  # 0.5 in the ignored band

    def test_low_quality_needs_some_overlap(self):
        # a ground-truth box that overlaps no anchor promotes nothing
        iou = torch.tensor([[0.0, 0.0], [0.8, 0.1]])
        assert match_boxes(iou, 0.7, 0.3, allow_low_quality=True)[0].tolist() == [1, 0]

    def test_low_quality_ties_all_positive(self):
        iou = torch.tensor([[0.4, 0.4, 0.1]])
        assert match_boxes(iou, 0.7, 0.3, allow_low_quality=True)[0].tolist() == [1, 1, 0]

    def test_background_band_of_fast_rcnn(self):
        iou = torch.tensor([[0.05, 0.1, 0.49, 0.5]])
        assert match_boxes(iou, 0.5, 0.5, 0.1)[0].tolist() == [-1, 0, 0, 1]

    def test_no_ground_truth(self):
        labels, matched = match_boxes(torch.zeros(0, 3), 0.7, 0.3)
        assert labels.tolist() == [0, 0, 0] and matched.tolist() == [0, 0, 0]
        assert match_boxes(torch.zeros(0, 2), 0.5, 0.5, 0.1)[0].tolist() == [-1, -1]

    @pytest.mark.parametrize(
        ("args", "msg"),
        [
            ((torch.zeros(3), 0.7, 0.3), "iou must be a \\(G, N\\)"),
            ((torch.tensor([[math.nan]]), 0.7, 0.3), "finite"),
            ((torch.zeros(1, 1), 0.3, 0.7), "bg_threshold"),
            ((torch.zeros(1, 1), 1.5, 0.3), "fg_threshold"),
        ],
    )
    def test_bad_input(self, args, msg):
        with pytest.raises(InputError, match=msg):
            match_boxes(*args)


class TestSampleBalanced:
    def test_counts_and_fractions(self):
        torch.manual_seed(0)
        labels = torch.tensor([1] * 10 + [0] * 1000 + [-1] * 50)
        pos, neg = sample_balanced(labels, 256, 0.5)
        assert int(pos.sum()) == 10 and int(neg.sum()) == 246  # few positives: negatives fill
        assert not bool((pos | neg)[-50:].any())  # ignored never drawn
        assert bool((labels[pos] == 1).all()) and bool((labels[neg] == 0).all())
        labels = torch.tensor([1] * 300 + [0] * 1000)
        pos, neg = sample_balanced(labels, 256, 0.5)
        assert int(pos.sum()) == 128 and int(neg.sum()) == 128
        pos, neg = sample_balanced(labels, 512, 0.25)  # Fast R-CNN's 25 % foreground
        assert int(pos.sum()) == 128 and int(neg.sum()) == 384

    def test_few_candidates(self):
        pos, neg = sample_balanced(torch.tensor([1, 0, -1]), 256, 0.5)
        assert pos.tolist() == [True, False, False] and neg.tolist() == [False, True, False]

    def test_seeded(self):
        labels = torch.tensor([1] * 50 + [0] * 50)
        torch.manual_seed(3)
        a = sample_balanced(labels, 20, 0.5)
        torch.manual_seed(3)
        b = sample_balanced(labels, 20, 0.5)
        assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])

    def test_bad_input(self):
        with pytest.raises(InputError, match=r"integer torch\.Tensor"):
            sample_balanced(torch.zeros(3), 4, 0.5)
        with pytest.raises(InputError, match="batch_size"):
            sample_balanced(torch.zeros(3, dtype=torch.int64), 0, 0.5)
        with pytest.raises(InputError, match="positive_fraction"):
            sample_balanced(torch.zeros(3, dtype=torch.int64), 4, 2.0)
