"""Drawing and colour maps."""

from __future__ import annotations

import time

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import (
    colorize_depth,
    colorize_signed,
    draw_boxes,
    draw_chessboard,
    draw_lines,
    draw_mask,
    draw_matches,
    draw_points,
    draw_text,
    hog_picture,
    label_colors,
    render_points,
)
from robopercept.viz.draw import check_color, clip_segments


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


# issue 25: colours, widths, radii, sizes and texts are checked; far coordinates are clipped
_RGB = np.zeros((40, 60, 3), np.uint8)
_PTS = np.array([[10.0, 10.0], [30.0, 20.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: check_color((0, 255, np.inf)), r"color must be three integers in 0\.\.255"),
        (lambda: check_color(([1, 2], 255, 0)), "color must be three integers"),
        (lambda: check_color((0, 255, None)), "color must be three integers"),
        (lambda: check_color(7), "color must be three integers"),
        (lambda: check_color((0.5, 0.5, 0.5)), "color must be three integers"),
        (lambda: check_color((-5e16, 0, 0)), "color must be three integers"),
        (lambda: draw_points(_RGB, _PTS, color=None), "color must be three integers"),
        (lambda: draw_points(_RGB, _PTS, radius="3"), "radius must be a real number"),
        (lambda: draw_points(_RGB, _PTS, radius=1e7), "radius must be at most 10000"),
        (lambda: draw_points(_RGB, _PTS, radius=-1), r"radius must be in \[0, inf\]"),
        (lambda: draw_lines(_RGB, [[0, 0, 5, 5]], width=[1, 2]), "width must be an integer"),
        (lambda: draw_lines(_RGB, [[0, 0, 5, 5]], width=2**40), "width must be at most"),
        (lambda: draw_lines(_RGB, [[0, 0, 5, 5]], color=(np.inf,) * 3), "color must be"),
        (lambda: draw_lines(_RGB, np.ones((2, 1))), r"segments must have shape \(N, 4\)"),
        (lambda: draw_boxes(_RGB, [[1, 1, 5, 5]], width=np.nan), "width must be an integer"),
        (lambda: draw_boxes(_RGB, [[1, 1, 5, 5]], labels=np.nan), "labels must be a sequence"),
        (lambda: draw_boxes(_RGB, [[1, 1, 5, 5]], labels=["a", "b"]), "one entry per box"),
        (lambda: draw_text(_RGB, "x", background=(np.nan,) * 3), "background must be three"),
        (lambda: draw_text(_RGB, "x", size=8.3e15), "size must be an integer"),
        (lambda: draw_text(_RGB, "x", size=2**40), "size must be at most"),
        (lambda: draw_text(_RGB, 3), "text must be a string"),
        (lambda: draw_text(_RGB, "x", (1, None)), "origin must be 2 finite real numbers"),
        (lambda: draw_mask(_RGB, np.ones((40, 60), bool), color=(0, np.inf, 0)), "color must"),
        (lambda: draw_mask(_RGB, np.ones((40, 60), bool), alpha=np.nan), "alpha must be finite"),
        (lambda: draw_chessboard(_RGB, _PTS, (2, None)), r"pattern_size\[1\] must be"),
        (lambda: label_colors(np.arange(3), background=None), "background must be three"),
        (lambda: label_colors(np.arange(3), background=(np.nan,) * 3), "background must be"),
        (lambda: label_colors(np.arange(3), background=(-5e16, 0, 0)), "background must be"),
        (lambda: colorize_depth(np.ones((4, 4)), min_depth="0"), "min_depth must be a real"),
        (lambda: colorize_signed(np.ones((4, 4)), limit=np.nan), "limit must be finite"),
        (lambda: render_points(np.ones((5, 3)), background=None), "background must be three"),
        (lambda: render_points(np.ones((5, 3)), size=(2**40, 2**40)), "at most 67108864"),
        (lambda: render_points(np.ones((5, 3)), point_size=2**20), "point_size must be at most"),
        (lambda: render_points(np.ones((5, 3)), fov_deg=180), r"fov_deg must be in \(0, 180\)"),
        (lambda: hog_picture(np.ones((2, 2, 9)), cell_size=2**40), "at most 67108864"),
        (lambda: hog_picture(np.ones((2, 2, 9)), scale=np.nan), "scale must be an integer"),
        (lambda: draw_matches(_RGB, _PTS, _RGB, _PTS, max_lines="3"), "max_lines must be an"),
    ],
)
def test_issue25_bad_arguments_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_integral_colors_are_accepted():
    assert check_color((0, 255.0, np.uint8(7))) == (0, 255, 7)
    assert check_color(label_colors(np.array([3]))[0]) == tuple(
        int(v) for v in label_colors(np.array([3]))[0]
    )
    out = label_colors(np.array([0, 1]), background=(np.int64(9), 8.0, 7))
    assert tuple(out[0]) == (9, 8, 7)


def test_issue25_clip_segments_by_hand():
    """The part of a segment inside the canvas (grown by the margin) is kept exactly;
    outside or non-finite segments go; ends near 1e308 do not overflow."""
    seg = np.array(
        [
            [-10.0, 5.0, 20.0, 5.0],  # crosses the left edge: from x = -1
            [2.0, 2.0, 4.0, 6.0],  # inside: unchanged
            [-50.0, -50.0, -20.0, -20.0],  # outside
            [np.nan, 0.0, 1.0, 1.0],  # not finite
            [-1.7e308, 3.0, 1.7e308, 3.0],  # its half-difference stays finite
            [5.0, -1e300, 5.0, 1e300],  # vertical, far ends
        ]
    )
    out = clip_segments(seg, 10, 8, 1.0)
    np.testing.assert_allclose(
        out,
        [[-1.0, 5.0, 10.0, 5.0], [2.0, 2.0, 4.0, 6.0], [-1.0, 3.0, 10.0, 3.0], [5, -1, 5, 8]],
    )


def test_issue25_far_coordinates_draw_the_visible_part_quickly():
    """Pillow rasterized a 1e9-pixel line pixel by pixel (5 s), a circle of radius 1e6 in
    a minute, and overflowed beyond C int: far coordinates are clipped, so the picture
    shows the visible part at once."""
    t0 = time.perf_counter()
    out = draw_lines(_RGB, [[0.0, 10.0, 1e9, 10.0], [0, 0, 1e300, 1e300]], color=(0, 255, 0))
    assert (out[10, :, 1] == 255).all()
    ref = draw_lines(_RGB, [[0.0, 10.0, 200.0, 10.0]], color=(0, 255, 0))
    np.testing.assert_array_equal(out[:, :, 1] >= ref[:, :, 1], True)
    far = draw_points(_RGB, [[1e300, 5.0], [-1e12, 3.0], [30, 20]], color=(255, 0, 0))
    np.testing.assert_array_equal(far, draw_points(_RGB, [[30, 20]], color=(255, 0, 0)))
    boxes = draw_boxes(_RGB, [[5, 5, 1e300, 1e300], [1e300, 0, 5, 5]], width=1)
    assert tuple(boxes[5, 30]) == (255, 255, 0) and boxes[30, 30].sum() == 0
    text = draw_text(_RGB, "far", (1e300, -1e300))
    np.testing.assert_array_equal(text, _RGB)
    chess = draw_chessboard(_RGB, [[5, 5], [1e300, 5], [20, 20]], (3, 1))
    assert chess.any()
    assert time.perf_counter() - t0 < 5.0


def test_issue25_render_points_edge_cases():
    """An empty cloud (or one wholly behind the camera) gave NumPy's "zero-size array to
    reduction operation"; it is the background picture. Far points project outside."""
    empty = render_points(np.zeros((0, 3)), size=(8, 6), background=(1, 2, 3))
    assert empty.shape == (6, 8, 3) and (empty == (1, 2, 3)).all()
    behind = render_points([[0.0, 0.0, -1.0]], size=(8, 6))
    assert (behind == 255).all()
    far = render_points([[1e300, 0.0, 1.0], [0.0, 0.0, 1.0]], size=(8, 6), point_size=1)
    assert (far != 255).any(axis=2).sum() == 1  # only the centre point


def test_issue25_colorize_depth_handles_extreme_ranges():
    """Depths near 1e308 made the range inf and the colours NaN (cast to 0: black);
    max_depth <= min_depth is a step at min_depth."""
    d = np.array([[-1.7e308, 0.0], [1.0, 1.7e308]])
    out = colorize_depth(d, invalid=np.nan)
    ends = colorize_depth(np.array([[0.0, 1.0]]), invalid=-1.0)
    np.testing.assert_array_equal(out[0, 0], ends[0, 0])
    np.testing.assert_array_equal(out[1, 1], ends[0, 1])
    step = colorize_depth(np.array([[1.0, 3.0]]), min_depth=2.0, max_depth=2.0)
    np.testing.assert_array_equal(step, ends)


def test_voc_palette_bits():
    from robopercept.viz import voc_palette

    pal = voc_palette()
    assert pal.shape == (256, 3) and pal.dtype == np.uint8
    # label 5 = 0b101: bit 0 -> R bit 7, bit 2 -> B bit 7; 255: all bits
    assert pal[5].tolist() == [128, 0, 128] and pal[255].tolist() == [224, 224, 192]
    assert len({tuple(c) for c in pal}) == 256  # every label its own colour
    with pytest.raises(InputError, match="at most 256"):
        voc_palette(257)
