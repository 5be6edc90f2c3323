"""Tests of robopercept.viz.detection: boxes, masks and captions drawn by class, and
the grid of such pictures."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.detection import detections_grid, draw_detections


def test_draw_detections():
    img = np.zeros((40, 40, 3), np.float32)
    out = draw_detections(img, [[5, 20, 15, 35]], [3], ["a", "b", "c"], scores=[0.5])
    colour = label_colors(np.array([3]))[0]
    np.testing.assert_array_equal(out[34, 14], colour)  # the box's bottom-right pixel
    np.testing.assert_array_equal(out[27, 10], 0)  # inside: untouched


def test_detections_grid_cells_and_gaps():
    # cells of the largest image (20 x 30), 2-pixel white gaps, smaller images top-left
    images = [np.zeros((20, 30)), np.zeros((10, 12, 3), np.uint8), np.zeros((16, 16))]
    boxes = [[[2, 2, 8, 8]], np.zeros((0, 4)), [[0, 0, 16, 16]]]
    masks = [np.ones((1, 20, 30), bool), np.zeros((0, 10, 12)), np.zeros((1, 16, 16))]
    pic = detections_grid(images, boxes, [[1], [], [2]], ["a", "b"], masks=masks, columns=2)
    assert pic.shape == (2 * 20 + 2, 2 * 30 + 2, 3) and pic.dtype == np.uint8
    assert (pic[:, 30:32] == 255).all() and (pic[20:22] == 255).all()
    assert (pic[10:20, 32:] == 255).all() and (pic[:10, 32 + 12 :] == 255).all()
    first = draw_detections(images[0], boxes[0], [1], ["a", "b"], masks=masks[0])
    np.testing.assert_array_equal(pic[:20, :30], first)
    third = draw_detections(images[2], boxes[2], [2], ["a", "b"], masks=masks[2])
    np.testing.assert_array_equal(pic[22:38, :16], third)


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: draw_detections(np.zeros((8, 8)), [[0, 0, 4, 4]], scores=[1, 2]),
            r"scores must have one value per box",
        ),
        (lambda: detections_grid([], []), r"images must be a non-empty list"),
        (lambda: detections_grid([np.zeros((4, 4))], []), r"boxes must be a list with one"),
        (lambda: detections_grid([np.zeros((4, 4))], None), r"boxes must be a list with one"),
        (lambda: draw_detections(np.zeros((8, 8)), [[0, 0, 4, 4]], [0]), r"integers in \[1,"),
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()
