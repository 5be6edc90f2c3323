"""Box IoU: a hand case and symmetry."""

from __future__ import annotations

import numpy as np

from robopercept.geometry import box_iou_matrix


def test_box_iou_matrix_hand_case():
    a = np.array([[0, 0, 10, 10], [20, 20, 0, 0.0]])  # a 10x10 box and an empty one
    b = np.array([[5, 0, 10, 10], [0, 0, 10, 10], [100, 100, 5, 5.0]])
    iou = box_iou_matrix(a, b)
    np.testing.assert_allclose(iou, [[50 / 150, 1.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(box_iou_matrix(b, a), iou.T)
    assert box_iou_matrix(np.zeros((0, 4)), b).shape == (0, 3)
