"""Boxes: the IoU matrix (a hand case, symmetry, pycocotools, its formats), conversions,
and greedy NMS (a hand case with ties and the threshold; the kernel vs its reference)."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.geometry import box_convert, box_iou_matrix


def test_box_iou_matrix_hand_case():
    a = np.array([[0, 0, 10, 10], [20, 20, 0, 0.0]])  # a 10x10 box and an empty one
    b = np.array([[5, 0, 10, 10], [0, 0, 10, 10], [100, 100, 5, 5.0]])
    iou = box_iou_matrix(a, b)
    np.testing.assert_allclose(iou, [[50 / 150, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(box_iou_matrix(b, a), iou.T)
    assert box_iou_matrix(np.zeros((0, 4)), b).shape == (0, 3)


# issue 25: a scalar or a wrong shape raised NumPy's reshape ValueError, and NaN or
# boxes near 1e300 (whose areas overflow) gave NaN IoUs; each is now an InputError
@pytest.mark.parametrize(
    ("a", "match"),
    [
        (np.nan, r"a must be \(N, 4\) boxes"),
        (np.ones((2, 3)), r"a must be \(N, 4\) boxes"),
        ([["a", "b", "c", "d"]], "a must hold real numbers"),
        ([[0, 0, np.nan, 1]], "a must be finite"),
        ([[0, 0, 1e300, 1e300]], "a has values up to 1e\\+300"),
    ],
)
def test_issue25_hostile_boxes_are_input_errors(a, match):
    with pytest.raises(InputError, match=match):
        box_iou_matrix(a, [[0, 0, 1, 1]])


def test_issue25_one_box_and_large_finite_boxes_still_work():
    np.testing.assert_allclose(box_iou_matrix([0, 0, 2, 2], [[1, 0, 2, 2]]), [[1 / 3]])
    big = np.array([[0, 0, 1e150, 1e150]])
    np.testing.assert_allclose(box_iou_matrix(big, big), [[1.0]])


def test_box_iou_matrix_equals_pycocotools():
    # pycocotools' bbox IoU (iscrowd 0) in double: equal up to rounding (1e-9); the
    # torch box_iou of robopercept.nn.ops.boxes is pinned to the same reference
    mask = pytest.importorskip("pycocotools.mask")
    rng = np.random.default_rng(0)
    a = np.concatenate([rng.uniform(0, 100, (40, 2)), rng.uniform(0, 30, (40, 2))], 1)
    b = np.concatenate([rng.uniform(0, 100, (30, 2)), rng.uniform(0, 30, (30, 2))], 1)
    b[:6] = a[:6] + rng.uniform(-1, 1, (6, 4))  # heavy overlaps
    b[6, 2] = 0.0  # a zero-width box
    ours = box_iou_matrix(a, b)
    ref = np.asarray(mask.iou(a.tolist(), b.tolist(), [0] * len(b)))
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)
    assert (ours > 0.5).sum() >= 6 and (ours[:, 6] == 0).all()


def test_box_convert_hand_case_and_round_trips():
    from robopercept.geometry import BOX_FORMATS, box_convert

    b = [10.0, 20.0, 4.0, 6.0]  # xywh
    assert box_convert(b, "xywh", "xyxy").tolist() == [[10.0, 20.0, 14.0, 26.0]]
    assert box_convert(b, "xywh", "cxcywh").tolist() == [[12.0, 23.0, 4.0, 6.0]]
    assert box_convert([[12.0, 23.0, 4.0, 6.0]], "cxcywh", "xyxy").tolist() == [
        [10.0, 20.0, 14.0, 26.0]
    ]
    x = np.random.default_rng(1).uniform(0, 50, (10, 4))
    for a in BOX_FORMATS:
        for c in BOX_FORMATS:
            back = box_convert(box_convert(x, a, c), c, a)
            np.testing.assert_allclose(back, x, rtol=0, atol=1e-12)
    # the IoU of converted boxes does not depend on the route (xywh -> xyxy -> xywh)
    np.testing.assert_allclose(
        box_iou_matrix(x, x),
        box_iou_matrix(box_convert(box_convert(x, "xywh", "cxcywh"), "cxcywh", "xywh"), x),
        atol=1e-12,
    )
    with pytest.raises(InputError, match="out_fmt must be one of"):
        box_convert(x, "xyxy", "yxyx")
    with pytest.raises(InputError, match=r"boxes must be \(N, 4\) boxes in the format 'xyxy'"):
        box_convert(np.ones((2, 3)), "xyxy", "xywh")
    with pytest.raises(InputError, match="boxes must be finite"):
        box_convert([[0, 0, np.nan, 1]], "xyxy", "xywh")


# ------------------------------------------------------------------ greedy NMS
def test_greedy_suppression_kernel_equals_numpy_reference():
    from robopercept.geometry.boxes import (
        corners_and_areas,
        greedy_suppression,
        greedy_suppression_reference,
    )

    rng = np.random.default_rng(10)
    xy = rng.uniform(0, 50.0, (200, 2))
    b = np.concatenate([xy, xy + rng.uniform(1, 50.0 / 3, (200, 2))], 1)
    b[:10, 2] = b[:10, 0]  # zero-width boxes
    corners, areas = corners_and_areas(b, "xyxy")
    for cls in (np.zeros(200, np.int64), rng.integers(0, 4, 200)):
        for thr in (0.0, 0.3, 0.6, 1.0):
            want = greedy_suppression_reference(corners, areas, cls, thr)
            np.testing.assert_array_equal(greedy_suppression(corners, areas, cls, thr), want)
            assert 0 < want.sum() < 200 or thr == 1.0


@pytest.mark.parametrize("seed", range(6))
def test_greedy_suppression_grid_equals_the_reference(seed):
    # from 64 boxes of a class the kernel compares only pairs that share a grid cell:
    # detector-like clusters, several classes, zero-size, huge and repeated boxes, and a
    # non-finite coordinate (the plain loop) must all give the reference's decisions
    from robopercept.geometry.boxes import greedy_suppression, greedy_suppression_reference

    rng = np.random.default_rng(seed)
    n = int(rng.integers(64, 1500)) if seed % 2 else 2600  # two classes of >= 64 boxes
    centres = rng.uniform(50, 950, (max(1, n // 10), 2))
    c = centres[rng.integers(0, centres.shape[0], n)] + rng.normal(0, 8, (n, 2))
    sizes, odds = [0.0, 0.5, 5.0, 40.0, 90.0, 2000.0], [0.03, 0.02, 0.2, 0.4, 0.34, 0.01]
    wh = rng.choice(sizes, (n, 2), p=odds)
    corners = np.concatenate([c - wh / 2, c + wh / 2], 1)
    corners[rng.random(n) < 0.05] = corners[0]  # repeats of the best box
    if seed == 5:
        corners[7, 2] = np.inf
    areas = (corners[:, 2] - corners[:, 0]) * (corners[:, 3] - corners[:, 1])
    spread = (rng.integers(0, 3, n) - 1) * 2**61  # ids too far apart for a counting sort
    for cls in (np.zeros(n, np.int64), rng.integers(0, 2, n), rng.integers(-2, 40, n), spread):
        for thr in (0.0, 0.3, 0.5, 0.7, 1.0):
            want = greedy_suppression_reference(corners, areas, cls, thr)
            got = greedy_suppression(np.ascontiguousarray(corners), areas, cls, thr)
            np.testing.assert_array_equal(got, want)


def test_greedy_nms_hand_case_ties_and_threshold():
    from robopercept.geometry import greedy_nms

    # (x, y, w, h): IoU(0, 1) = 90 / 110, IoU(0, 2) = 0.5 exactly, box 3 far away
    b = np.array([[0, 0, 10, 10], [1, 0, 10, 10], [0, 0, 10, 5], [50, 50, 10, 10.0]])
    assert greedy_nms(b, [0.9, 0.95, 0.5, 0.1], 0.3).tolist() == [1, 3]
    # equal scores rank by index; an IoU equal to the threshold does not suppress
    s = np.full(4, 0.5)
    assert greedy_nms(b, s, 0.5).tolist() == [0, 2, 3]
    assert greedy_nms(b, s, 0.49).tolist() == [0, 3]
    # the same boxes as corners; per class, a box suppresses only its own class
    xyxy = box_convert(b, "xywh", "xyxy")
    assert greedy_nms(xyxy, s, 0.5, fmt="xyxy").tolist() == [0, 2, 3]
    assert greedy_nms(b, s, 0.3, classes=[0, 1, 0, 0]).tolist() == [0, 1, 3]
    assert greedy_nms(np.zeros((0, 4)), [], 0.5).dtype == np.int64
    with pytest.raises(InputError, match="scores must not hold NaN"):
        greedy_nms(b, [0.1, np.nan, 0.2, 0.3], 0.5)
    with pytest.raises(InputError, match="one score per box"):
        greedy_nms(b, [0.1], 0.5)
    with pytest.raises(InputError, match="classes must be"):
        greedy_nms(b, s, 0.5, classes=[0.5, 1, 0, 0])
    with pytest.raises(InputError, match="x1 <= x2"):
        greedy_nms([[5, 0, 1, 1]], [1.0], 0.5, fmt="xyxy")


def test_box_iou_matrix_formats_agree():
    x = np.random.default_rng(4).uniform(0, 50, (12, 4))
    want = box_iou_matrix(x, x)
    for fmt in ("xyxy", "cxcywh"):
        y = box_convert(x, "xywh", fmt)
        np.testing.assert_allclose(box_iou_matrix(y, y, fmt=fmt), want, rtol=0, atol=1e-12)
