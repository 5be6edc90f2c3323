"""HOG + linear SVM detector: NMS, persistence, cross-validated accuracy on lfw_subset."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError, NotFittedError
from robopercept.learning.hog_detector import (
    HogDetector,
    box_iou,
    face_training_data,
    non_max_suppression,
)
from robopercept.learning.model_selection import cross_val_score
from robopercept.learning.svm import LinearSVC


def test_iou_and_nms_hand_case():
    boxes = np.array([[0, 0, 10, 10], [1, 0, 10, 10], [20, 20, 5, 5], [0, 0, 10, 10.0]])
    np.testing.assert_allclose(box_iou(boxes[0], boxes[:3]), [1, 90 / 110, 0])
    keep = non_max_suppression(boxes, [0.9, 0.95, 0.5, 0.1], iou=0.3)
    np.testing.assert_array_equal(keep, [1, 2])  # 0 and 3 overlap the better box 1
    assert non_max_suppression(np.zeros((0, 4)), []).size == 0
    with pytest.raises(InputError, match="scores"):
        non_max_suppression(boxes, [1.0])


def test_hog_svm_cross_validated_accuracy_on_lfw_subset():
    """Real faces vs non-faces (scikit-image's lfw_subset): 5-fold accuracy >= 0.9."""
    patches, labels = face_training_data()
    X = HogDetector().describe(patches)
    scores = cross_val_score(LinearSVC(C=0.1, rng=0), X, labels, cv=5)
    assert scores.mean() >= 0.9, scores
    precision = cross_val_score(LinearSVC(C=0.1, rng=0), X, labels, cv=5, scoring="precision")
    recall = cross_val_score(LinearSVC(C=0.1, rng=0), X, labels, cv=5, scoring="recall")
    assert precision.mean() > 0.85 and recall.mean() > 0.85


def test_detector_finds_a_trained_pattern_and_round_trips(tmp_path):
    """A bright disc on noise: trained on 24x24 discs, it finds a 48-px disc placed in a
    larger image at the right place and size; save/load gives the same scores."""
    gen = np.random.default_rng(0)
    yy, xx = np.mgrid[:24, :24]
    disc = ((yy - 11.5) ** 2 + (xx - 11.5) ** 2 < 8**2).astype(float)
    pos = np.clip(disc * 0.8 + gen.normal(0.1, 0.05, (60, 24, 24)), 0, 1)
    neg = np.clip(gen.normal(0.3, 0.15, (60, 24, 24)), 0, 1)
    det = HogDetector().fit(np.r_[pos, neg], np.r_[np.ones(60), np.zeros(60)])
    image = np.clip(gen.normal(0.3, 0.05, (160, 200)), 0, 1)
    big = np.kron(disc, np.ones((2, 2)))
    image[60:108, 100:148] = np.clip(image[60:108, 100:148] + big * 0.6, 0, 1)
    found = det.detect(image, threshold=0.0)
    assert len(found) >= 1
    assert box_iou(np.array([100, 60, 48, 48.0]), found.boxes[:1])[0] > 0.5
    path = tmp_path / "model.npz"
    det.save(path)
    again = HogDetector.load(path)
    np.testing.assert_allclose(again.score_patches(pos[:5]), det.score_patches(pos[:5]))


def test_detector_bad_input(tmp_path):
    with pytest.raises(NotFittedError):
        HogDetector().detect(np.zeros((50, 50)))
    with pytest.raises(InputError, match="patches"):
        HogDetector().describe(np.zeros((3, 20, 20)))
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(FileFormatError, match="HOG model"):
        HogDetector.load(bad)
