"""Box IoU: a hand case and symmetry."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.geometry import box_iou_matrix


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
