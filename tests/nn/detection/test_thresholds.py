"""The score threshold chosen on validation and the domain rule (issue 46): F1 by
hand, ties, classes, empty cases, and the warning's two conditions."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.detection.thresholds import (
    choose_score_threshold,
    domain_warning,
    f1_threshold,
)


def _det(boxes, labels, scores):
    return {
        "boxes": np.asarray(boxes, float).reshape(-1, 4),
        "labels": np.asarray(labels),
        "scores": np.asarray(scores, float),
    }


def _truth(boxes, labels):
    return {"boxes": np.asarray(boxes, float).reshape(-1, 4), "labels": np.asarray(labels)}


def test_threshold_by_hand_over_two_images():
    # image 1: truths A, B; detections A (0.9, right), C (0.7, wrong), B (0.4, right)
    # image 2: truth D; detections D' (0.8, IoU 0.5 exactly: right), D again (0.6: a
    # duplicate, wrong)
    a, b, c = [0, 0, 10, 10], [20, 0, 30, 10], [50, 50, 60, 60]
    d, d_half = [0, 0, 10, 10], [0, 0, 10, 20]  # IoU 100 / 200 = 0.5
    dets = [_det([a, c, b], [1, 1, 1], [0.9, 0.7, 0.4]), _det([d_half, d], [1, 1], [0.8, 0.6])]
    truths = [_truth([a, b], [1, 1]), _truth([d], [1])]
    t = choose_score_threshold(dets, truths)
    # in score order: 0.9 hit, 0.8 hit, 0.7 miss, 0.6 miss, 0.4 hit; G = 3
    # F1 at k = 1..5: 2/4, 4/5, 4/6, 4/7, 6/8 -> the best keeps the top two
    assert t.score_thresh == 0.8
    assert t.f1 == pytest.approx(0.8) and t.precision == 1.0 and t.recall == pytest.approx(2 / 3)
    assert t.match_median == pytest.approx(0.8)  # median of 0.9, 0.8, 0.4
    assert (t.images, t.truths) == (2, 3)


def test_a_detection_of_another_class_does_not_match():
    dets = [_det([[0, 0, 10, 10]], [2], [0.9])]
    t = choose_score_threshold(dets, [_truth([[0, 0, 10, 10]], [1])])
    assert t.f1 == 0.0 and t.match_median == 0.0


def test_tied_scores_are_kept_or_dropped_together():
    # two detections at 0.5 (one right, one wrong) and a right one at 0.9: cutting
    # between the tied pair is not a threshold "score >= s" can express
    box = [0, 0, 10, 10]
    dets = [_det([box, [30, 30, 40, 40], [60, 0, 70, 10]], [1, 1, 1], [0.9, 0.5, 0.5])]
    t = choose_score_threshold(dets, [_truth([box, [60, 0, 70, 10]], [1, 1])])
    # top one: F1 2/3; all three: P 2/3, R 1, F1 0.8
    assert t.score_thresh == 0.5 and t.f1 == pytest.approx(0.8)


def test_f1_threshold_by_hand():
    t = f1_threshold(np.array([0.9, 0.8, 0.7, 0.6]), np.array([True, False, True, False]), 2)
    # k=1: 2/3, k=3: 4/5, k=2: 2/4, k=4: 4/6 -> 0.7 alone is best
    assert t.score_thresh == 0.7
    t = f1_threshold(np.array([0.9, 0.8]), np.array([True, True]), 4)
    assert t.score_thresh == 0.8  # more recall, no precision lost


def test_no_detection_and_no_truth():
    t = choose_score_threshold([_det([], [], [])], [_truth([[0, 0, 1, 1]], [1])])
    assert (t.score_thresh, t.f1) == (1.0, 0.0)
    with pytest.raises(InputError, match="no true box"):
        choose_score_threshold([_det([[0, 0, 1, 1]], [1], [0.5])], [_truth([], [])])
    with pytest.raises(InputError, match="pair up"):
        choose_score_threshold([], [_truth([], [])])
    with pytest.raises(InputError, match="same length"):
        f1_threshold(np.zeros(2), np.zeros(3, bool), 1)


@pytest.mark.parametrize(
    ("best", "warns"),
    [(0.9, False), (0.41, False), (0.39, True), (0.0, True)],
)
def test_domain_warning_below_the_threshold(best, warns):
    cal = {"score_thresh": 0.4, "match_median": 0.6}
    assert (domain_warning(best, cal, "m", "x") is not None) is warns


def test_domain_warning_far_below_the_validation_matches():
    # above the threshold but under half the validation matches' median
    cal = {"score_thresh": 0.1, "match_median": 0.9}
    line = domain_warning(0.3, cal, "trees", "aerial tree crowns")
    assert line is not None and "trees" in line and "aerial tree crowns" in line
    assert "\n" not in line
    assert domain_warning(0.46, cal, "trees", "x") is None
    assert domain_warning(0.0, None, "trees", "x") is None  # an uncalibrated model
