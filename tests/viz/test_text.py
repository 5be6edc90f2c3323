"""Text on images (issue 30): a TrueType font, a size that follows the picture's height,
a filled box behind labels, labels kept inside the picture."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import draw
from robopercept.viz.draw import (
    draw_boxes,
    draw_label,
    draw_text,
    label_font,
    label_size_for,
)

GREY = 90  # a mid-grey 1080p frame: neither black nor white text vanishes on it
FRAME = np.full((1080, 1920, 3), GREY, np.uint8)


def _changed(out: np.ndarray, before: np.ndarray = FRAME) -> tuple[int, int, int, int]:
    """Bounding box (x0, y0, x1, y1), inclusive, of the pixels that changed."""
    ys, xs = np.nonzero((out != before).any(axis=2))
    return int(xs.min()), int(ys.min()), int(xs.max()), int(ys.max())


def test_size_follows_the_height():
    # max(12, round(h / 45)): hand-computed
    assert [label_size_for(h) for h in (100, 480, 720, 1080, 2160)] == [12, 12, 16, 24, 48]
    assert label_size_for(10**9) == draw.MAX_STROKE


def test_font_is_dejavu_from_matplotlib():
    import matplotlib

    font = label_font(24)
    assert font.path.endswith("DejaVuSans.ttf")
    assert font.path.startswith(matplotlib.get_data_path())
    assert font.size == 24


def test_font_falls_back_to_pillow(monkeypatch):
    monkeypatch.setattr(draw, "_font_file", lambda: None)
    draw._load_font.cache_clear()
    try:
        font = label_font(24)
        assert "DejaVu" not in str(getattr(font, "path", ""))
        out = draw_label(FRAME, "ID 7", (500, 500))
        y0, y1 = _changed(out)[1::2]
        assert 20 <= y1 - y0 + 1 <= 40  # still about the same size
    finally:
        draw._load_font.cache_clear()


def test_label_height_at_1080p():
    """Before issue 30 a box caption at 1080p was 8 px of bitmap text with no
    background; now a 24 px font on a filled box."""
    out = draw_label(FRAME, "ID 17", (800, 500), color=(255, 255, 0))
    x0, y0, x1, y1 = _changed(out)
    # the box: ink from cap top to descender (~0.96 * 24 = 23 px) + 2 * 3 px padding
    assert 26 <= y1 - y0 + 1 <= 34
    assert (x0, y1) == (800, 499)  # anchor "lb": the box's bottom-left at xy, above it
    box = out[y0 : y1 + 1, x0 : x1 + 1]
    yellow = (box == (255, 255, 0)).all(axis=2)
    ink = (box < 60).all(axis=2)  # black text on yellow (luma 226 > 150)
    assert yellow.mean() > 0.6  # the background is filled
    assert ink.any() and not ((box == GREY).all(axis=2)).any()  # nothing of the frame shows
    rows = np.flatnonzero(ink.any(axis=1))
    assert 16 <= rows.max() - rows.min() + 1 <= 24  # the text itself: "ID 17" cap height 18


def test_dark_label_gets_white_text():
    out = draw_label(FRAME, "car 0.93", (300, 300), color=(0, 0, 128))
    x0, y0, x1, y1 = _changed(out)
    box = out[y0 : y1 + 1, x0 : x1 + 1]
    assert ((box > 200).all(axis=2)).any()  # white ink
    assert not ((box < 60).all(axis=2) & (box[..., 2:] < 60).all(axis=2)).any()


def test_label_is_the_same_anywhere_and_stays_inside():
    centre = draw_label(FRAME, "ID 3", (900, 500))
    cx0, cy0, cx1, cy1 = _changed(centre)
    patch = centre[cy0 : cy1 + 1, cx0 : cx1 + 1]
    h, w = patch.shape[:2]
    for xy, anchor in [
        ((1915, 5), "lb"),
        ((-50, 1200), "lt"),
        ((0, 0), "mm"),
        ((1919, 1079), "rt"),
    ]:
        out = draw_label(FRAME, "ID 3", xy, anchor=anchor)
        x0, y0, x1, y1 = _changed(out)
        assert (x1 - x0 + 1, y1 - y0 + 1) == (w, h)  # whole, not cut at the border
        np.testing.assert_array_equal(out[y0 : y1 + 1, x0 : x1 + 1], patch)
    corner = draw_label(FRAME, "ID 3", (1915, 5))
    assert _changed(corner)[2] == 1919 and _changed(corner)[1] == 0


@pytest.mark.parametrize(
    ("anchor", "where"),
    [("lt", (400, 300)), ("rb", (400 - 1, 300 - 1)), ("mm", None)],
)
def test_anchors(anchor, where):
    out = draw_label(FRAME, "x", (400, 300), anchor=anchor)
    x0, y0, x1, y1 = _changed(out)
    if anchor == "lt":
        assert (x0, y0) == where
    elif anchor == "rb":
        assert (x1, y1) == where
    else:
        assert abs((x0 + x1) / 2 - 400) <= 1 and abs((y0 + y1) / 2 - 300) <= 1


def test_box_captions_scale_with_the_picture():
    box = [[600, 400, 200, 300]]
    big = draw_boxes(FRAME, box, color=(0, 255, 0), width=2, labels=["ID 12"])
    x0, y0, x1, y1 = _changed(big[:400], FRAME[:400])  # the caption above the box
    assert 26 <= y1 - y0 + 1 <= 34 and (x0, y1) == (600, 399)
    assert ((big[y0 : y1 + 1, x0 : x1 + 1] == (0, 255, 0)).all(axis=2)).mean() > 0.6
    small = np.full((240, 320, 3), GREY, np.uint8)
    out = draw_boxes(small, [[50, 100, 40, 40]], color=(0, 255, 0), labels=["ID 12"])
    sy0, sy1 = _changed(out[:100], small[:100])[1::2]
    assert 14 <= sy1 - sy0 + 1 <= 20  # the 12 px minimum
    # no room above a box at the top: the caption goes inside it, below its top edge
    top = draw_boxes(FRAME, [[600, 3, 200, 300]], color=(0, 255, 0), labels=["ID 12"])
    assert tuple(top[3 + 10, 601]) == (0, 255, 0) and tuple(top[0, 700]) == (GREY,) * 3
    sized = draw_boxes(FRAME, box, color=(0, 255, 0), labels=["ID 12"], label_size=48)
    assert _changed(sized[:400], FRAME[:400])[3] - _changed(sized[:400], FRAME[:400])[1] > 50


def test_draw_text_scales_by_default():
    out = draw_text(FRAME, "frame 12: 3 tracks", (5, 5))
    ink = np.flatnonzero((out == 255).all(axis=2).any(axis=1))
    assert 15 <= ink.max() - ink.min() + 1 <= 26  # 24 px DejaVu (was 14 px at any size)
    two = draw_text(FRAME, "a\nb", (5, 5), size=20)
    rows = np.flatnonzero((two == 255).all(axis=2).any(axis=1))
    assert rows.max() - rows.min() > 30  # two lines


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: draw_label(FRAME, "a\nb", (1, 1)), "one line"),
        (lambda: draw_label(FRAME, 7, (1, 1)), "text must be a string"),
        (lambda: draw_label(FRAME, "a", (1, 1), anchor="xx"), "anchor must be one of"),
        (lambda: draw_label(FRAME, "a", (np.nan, 1)), "xy must be 2 finite"),
        (lambda: draw_label(FRAME, "a", (1, 1), size=0), "size must be"),
        (lambda: draw_label(FRAME, "a", (1, 1), color=(300, 0, 0)), "color must be three"),
        (lambda: draw_label(FRAME, "a", (1, 1), text_color=(1, 2)), "text_color must be"),
        (lambda: label_size_for(0), "height must be"),
        (lambda: label_font(2**40), "size must be at most"),
        (lambda: draw_boxes(FRAME, [[1, 1, 5, 5]], labels=["a"], label_size=0), "label_size"),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(InputError, match=match):
        call()
