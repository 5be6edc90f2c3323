"""Segmentation scores (issue 27): the confusion matrix equals scikit-learn's, mIoU
equals one computed from ``sklearn.metrics.confusion_matrix``, hand-computed scores and
boundary F-scores, instance matching against hand cases and a brute-force oracle,
refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.segmentation.metrics import (
    boundary_f_score,
    match_instances,
    segmentation_confusion,
    segmentation_scores,
)

sk = pytest.importorskip("sklearn.metrics")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_confusion_and_miou_equal_sklearn(seed):
    rng = np.random.default_rng(seed)
    k = 5
    t = rng.integers(0, k, (3, 40, 50))
    p = np.where(rng.random(t.shape) < 0.7, t, rng.integers(0, k, t.shape))
    t[rng.random(t.shape) < 0.1] = 255  # void pixels
    p[t == 4] = 0  # class 4 never predicted; and drop class 3 from both sides
    t[t == 3] = 2
    p[p == 3] = 1
    keep = t != 255
    ref = sk.confusion_matrix(t[keep], p[keep], labels=range(k))
    c = segmentation_confusion(t, p, k, ignore_index=255)
    np.testing.assert_array_equal(c, ref)
    s = segmentation_scores(c)
    # mIoU from scikit-learn's matrix, the classes present on either side
    inter = np.diag(ref).astype(float)
    union = ref.sum(0) + ref.sum(1) - inter
    present = union > 0
    assert s.miou == pytest.approx(np.mean(inter[present] / union[present]), abs=1e-12)
    assert np.isnan(s.iou[3]) and s.iou[4] == 0.0  # absent vs never predicted
    assert s.pixel_accuracy == pytest.approx(sk.accuracy_score(t[keep], p[keep]), abs=1e-12)
    # mean accuracy = balanced accuracy over the true classes present
    assert s.mean_accuracy == pytest.approx(sk.balanced_accuracy_score(t[keep], p[keep]), abs=1e-12)


def test_hand_computed_scores():
    # 8 pixels: class 0 true 4 (3 right, 1 -> 1), class 1 true 4 (all right)
    s = segmentation_scores([[3, 1], [0, 4]])
    assert s.pixel_accuracy == 7 / 8
    assert s.accuracy.tolist() == [0.75, 1.0] and s.mean_accuracy == 0.875
    assert s.iou.tolist() == [3 / 4, 4 / 5]  # 3 / (4 + 3 - 3), 4 / (4 + 5 - 4)
    assert s.miou == pytest.approx(0.775)
    assert s.fwiou == pytest.approx(0.5 * 0.75 + 0.5 * 0.8)
    d = segmentation_scores([[2, 0, 0], [0, 0, 0], [0, 0, 0]]).as_dict()
    assert d["iou"] == [1.0, None, None] and d["miou"] == 1.0


def test_boundary_f_score_hand_cases():
    t = np.zeros((10, 10), int)
    t[2:6, 2:6] = 1
    # the same mask: 1 for both classes
    assert boundary_f_score(t, t, 2).tolist() == [1.0, 1.0]
    # shifted one pixel: at tolerance 0, 6 of the 12 ring pixels are shared on each side
    p = np.roll(t, 1, axis=1)
    assert boundary_f_score(t, p, 2, tolerance=0.0)[1] == pytest.approx(0.5)
    assert boundary_f_score(t, p, 2, tolerance=1.0)[1] == 1.0
    # a class in the truth only scores 0; one in neither scores 1
    f = boundary_f_score(t, np.zeros_like(t), 3)
    assert f[1] == 0.0 and f[2] == 1.0
    # a mask touching the image border has its border pixels as boundary
    full = np.ones((5, 5), int)
    assert boundary_f_score(full, full, 2).tolist() == [1.0, 1.0]
    # ignored pixels count for no class
    v = t.copy()
    v[:, 8:] = 255
    q = t.copy()
    q[:, 8:] = 1  # wrong, but ignored
    assert boundary_f_score(v, q, 2, ignore_index=255)[1] == 1.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: segmentation_confusion([[0, 1]], [[0]], 2), "must match"),
        (lambda: segmentation_confusion([[0, 5]], [[0, 1]], 2), "label 5, outside"),
        (lambda: segmentation_confusion([[0, 1]], [[0, -1]], 2), "y_pred holds label -1"),
        (lambda: segmentation_confusion([[0.5]], [[0]], 2), "integer label map"),
        (lambda: segmentation_confusion([], [], 2), "non-empty"),
        (lambda: segmentation_scores([[0, 0], [0, 0]]), "no pixel"),
        (lambda: segmentation_scores([[1, 2, 3]]), r"\(K, K\)"),
        (lambda: segmentation_scores([[1, -1], [0, 1]]), ">= 0"),
        (lambda: boundary_f_score(np.zeros((2, 2, 2), int), np.zeros((2, 2, 2), int), 2), "(H, W)"),
        (lambda: boundary_f_score([[0]], [[0]], 2, tolerance=-1), "tolerance"),
        (lambda: match_instances([[0, 1]], [[0, 1, 1]]), "one shape"),
        (lambda: match_instances([[0, -1]], [[0, 1]]), "ids >= 0"),
        (lambda: match_instances([[0, 1]], [[0.5, 1]]), "integer label map"),
        (lambda: match_instances([[0, 1]], [[0, 1]], 1.5), "iou_threshold"),
        (lambda: match_instances(np.zeros((2, 2, 2), int), np.zeros((2, 2, 2), int)), "one shape"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


# ------------------------------------------------------------------------ instances
def test_match_instances_hand_case():
    # true: a 4-pixel square (id 3) and a 2-pixel bar (id 9); predicted: the square
    # shifted by one column (id 1: IoU 2/6), the bar exactly (id 2) and a stray pixel (4)
    t = np.zeros((4, 6), int)
    t[0:2, 0:2] = 3
    t[3, 4:6] = 9
    p = np.zeros((4, 6), int)
    p[0:2, 1:3] = 1
    p[3, 4:6] = 2
    p[2, 0] = 4
    r = match_instances(t, p)
    assert (r.tp, r.fp, r.fn) == (1, 2, 1)
    assert r.pairs.tolist() == [[9, 2]] and r.mean_matched_iou == 1.0
    assert r.precision == 1 / 3 and r.recall == 0.5 and r.f1 == 2 / 5
    r = match_instances(t, p, 0.3)  # 2/6 >= 0.3: the square matches too
    assert (r.tp, r.fp, r.fn) == (2, 1, 0)
    assert abs(r.mean_matched_iou - (1 + 1 / 3) / 2) < 1e-12


def test_match_instances_empty_sides():
    z = np.zeros((3, 3), int)
    one = z.copy()
    one[1, 1] = 5
    both = match_instances(z, z)
    assert (both.tp, both.fp, both.fn, both.f1) == (0, 0, 0, 1.0)
    assert np.isnan(both.mean_matched_iou) and both.pairs.shape == (0, 2)
    miss = match_instances(one, z)
    assert (miss.fn, miss.recall, miss.precision, miss.f1) == (1, 0.0, 0.0, 0.0)
    extra = match_instances(z, one)
    assert (extra.fp, extra.f1) == (1, 0.0)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("thr", [0.1, 0.3, 0.5, 0.7])
def test_match_instances_equals_a_brute_force_oracle(seed, thr):
    # random rectangles painted over each other on both sides, then every one-to-one
    # matching enumerated: the count of pairs with IoU >= thr is maximal, and among
    # maximal ones the summed IoU is (the assignment's tie rule)
    import itertools

    g = np.random.default_rng(seed)

    def paint():
        lab = np.zeros((12, 12), int)
        for k in range(1, g.integers(1, 5) + 1):
            y, x = g.integers(0, 9, 2)
            h, w = g.integers(2, 6, 2)
            lab[y : y + h, x : x + w] = k * 10 + int(g.integers(0, 3))
        return lab

    t, p = paint(), paint()
    ti, pi = [i for i in np.unique(t) if i], [j for j in np.unique(p) if j]
    iou = np.array(
        [[((t == i) & (p == j)).sum() / ((t == i) | (p == j)).sum() for j in pi] for i in ti]
    ).reshape(len(ti), len(pi))
    best = (0, 0.0)
    small, big = (ti, pi) if len(ti) <= len(pi) else (pi, ti)
    for perm in itertools.permutations(range(len(big)), len(small)):
        pairs = [(a, b) if len(ti) <= len(pi) else (b, a) for a, b in enumerate(perm)]
        hits = [iou[a, b] for a, b in pairs if iou[a, b] >= thr]
        best = max(best, (len(hits), float(np.sum(hits))))
    r = match_instances(t, p, thr)
    assert r.tp == best[0]
    assert r.fp == len(pi) - r.tp and r.fn == len(ti) - r.tp
    if r.tp:
        assert abs(r.mean_matched_iou * r.tp - best[1]) < 1e-9
