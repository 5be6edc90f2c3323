"""Drawing and colour maps."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import (
    colorize_depth,
    colorize_signed,
    draw_boxes,
    draw_lines,
    draw_mask,
    draw_points,
    draw_text,
    label_colors,
)


def test_draw_functions_paint_where_asked_and_copy():
    img = np.zeros((40, 60), np.uint8)
    out = draw_points(img, [[30, 20]], color=(255, 0, 0), radius=3, filled=True)
    assert out.shape == (40, 60, 3) and tuple(out[20, 30]) == (255, 0, 0)
    assert out[0, 0].sum() == 0 and img.sum() == 0  # input untouched
    out = draw_lines(img, [[0, 10, 59, 10]], color=(0, 255, 0))
    assert (out[10, :, 1] == 255).all()
    out = draw_boxes(img, [[5, 5, 10, 8]], color=(0, 0, 255), width=1)
    assert tuple(out[5, 8]) == (0, 0, 255) and tuple(out[12, 14]) == (0, 0, 255)
    assert out[8, 8].sum() == 0  # outline only
    captioned = draw_boxes(img, [[5, 20, 10, 8]], color=(0, 0, 255), width=1, labels=["a"])
    assert captioned[8:20, 5:20].sum() > 0  # the caption above the box
    out = draw_text(img, "hello", (2, 2))
    assert out[:20, :50].sum() > 0
    mask = np.zeros((40, 60), bool)
    mask[:10] = True
    out = draw_mask(np.full((40, 60, 3), 100, np.uint8), mask, color=(200, 0, 0), alpha=0.5)
    assert tuple(out[0, 0]) == (150, 50, 50) and tuple(out[20, 0]) == (100, 100, 100)
    assert draw_points(np.ones((4, 4), np.float32), [[1, 1]]).dtype == np.uint8


def test_colormaps():
    depth = np.array([[0, 1500, 2000], [3000, 0, 4000]], np.uint16)
    rgb = colorize_depth(depth, 1000, 4000)
    assert rgb.shape == (2, 3, 3) and rgb[0, 0].sum() == 0  # invalid is black
    assert rgb[0, 1, 2] > rgb[0, 1, 0] and rgb[1, 2, 0] > rgb[1, 2, 2]  # near blue, far red
    s = colorize_signed(np.array([[-1.0, 0.0, 1.0]]), 1.0)
    assert tuple(s[0, 1]) == (255, 255, 255) and s[0, 0, 2] > s[0, 0, 0] and s[0, 2, 0] > s[0, 2, 2]
    lab = label_colors(np.array([[0, 1, 2]]))
    assert lab[0, 0].sum() == 0 and not np.array_equal(lab[0, 1], lab[0, 2])
    assert colorize_depth(np.zeros((3, 3))).sum() == 0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: draw_points(np.zeros((4, 4)), [[1, 1]], color=(300, 0, 0)), "0..255"),
        (lambda: draw_boxes(np.zeros((4, 4)), [[0, 0, 1, 1]], labels=["a", "b"]), "one entry"),
        (lambda: draw_mask(np.zeros((4, 4)), np.zeros((3, 3), bool)), "shape"),
        (lambda: draw_mask(np.zeros((4, 4)), np.zeros((4, 4), bool), alpha=2), "alpha"),
        (lambda: label_colors(np.zeros((2, 2))), "integers"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_render_points_projects_with_a_pinhole_and_zbuffer():
    from robopercept.viz import render_points

    # a point on the optical axis lands at the image centre; a nearer point on the same
    # ray hides a farther one; points behind the camera are skipped
    pts = np.array([[0, 0, 2.0], [0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 1.0]])
    cols = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]], dtype=np.uint8)
    img = render_points(pts, cols, size=(100, 80), fov_deg=90, point_size=1)
    assert img.shape == (80, 100, 3)
    assert img[40, 50].tolist() == [0, 255, 0]
    # x/z = 1 at 90 degrees -> the right edge (u = f + W/2 = 100): outside
    assert (img == [9, 9, 9]).all(axis=2).sum() == 0
    assert (img != 255).any(axis=2).sum() == 1
    with pytest.raises(InputError, match="colors"):
        render_points(pts, cols[:2])


def test_check_color_and_pil_canvas():
    from robopercept.errors import InputError
    from robopercept.viz.draw import check_color, pil_canvas

    assert check_color(np.array([1, 2, 3])) == (1, 2, 3)
    with pytest.raises(InputError, match=r"three integers in 0\.\.255"):
        check_color((0, 0, 256))
    pil, draw = pil_canvas(np.zeros((4, 6), np.uint8))
    draw.point((2, 1), fill=(255, 0, 0))
    out = np.asarray(pil)
    assert out.shape == (4, 6, 3) and tuple(out[1, 2]) == (255, 0, 0) and out.sum() == 255
