"""Pictures readable at 1080p (issue 48, item 7): captions that never overlap, sample
sheets laid out as grids, "nothing detected", prediction and ground truth told apart
with a legend, a legend beside a rendered cloud, blob overlays that keep the image
visible, and 3-D pose panels whose tick labels stay apart."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz.cloud import render_points
from robopercept.viz.colormap import label_colors
from robopercept.viz.detection import (
    PREDICTION_COLOR,
    TRUTH_COLOR,
    detection_samples_picture,
)
from robopercept.viz.draw import caption_boxes, draw_boxes, label_size_for, legend_panel
from robopercept.viz.pose import skeleton_3d_figure
from robopercept.viz.segmentation import blob_overlay, panels_picture


def _intersect(a, b) -> bool:
    return not (a[2] < b[0] or b[2] < a[0] or a[3] < b[1] or b[3] < a[1])


# --------------------------------------------------------------------------- captions


def test_captions_of_boxes_close_together_never_overlap():
    # ten boxes 6 px apart: every caption at the top-left corner (the old placement)
    # would cover its neighbours'
    boxes = [[100 + 6 * i, 200 + 3 * i, 60, 50] for i in range(10)]
    texts = [f"circle 0.{90 - i}" for i in range(10)]
    rects = caption_boxes(texts, boxes, (640, 480))
    placed = [r for r in rects if r is not None]
    assert len(placed) >= 6  # stacked above, inside, below, beside
    for a, b in itertools.combinations(placed, 2):
        assert not _intersect(a, b), (a, b)
    for r in placed:  # inside the picture
        assert 0 <= r[0] <= r[2] < 640 and 0 <= r[1] <= r[3] < 480
    # the first caption sits where a lone caption does: above the box's corner
    assert (rects[0][0], rects[0][3]) == (100, 199)
    # draw_boxes writes the captions there: each filled with its box's colour
    colors = label_colors(np.arange(1, 11))
    out = draw_boxes(np.zeros((480, 640, 3), np.uint8), boxes, color=colors, labels=texts)
    for k, r in enumerate(rects):
        if r is not None:
            patch = out[r[1] : r[3] + 1, r[0] : r[2] + 1]
            share = (patch == colors[k]).all(axis=2).mean()
            assert share > 0.5, (k, share)


def test_a_lone_caption_and_empty_captions():
    rects = caption_boxes(["7", "", None], [[50, 5, 30, 30]] * 3, (200, 100))
    assert rects[1] is None and rects[2] is None
    # no room above a box at the top: inside, below its top edge (as before)
    assert rects[0][1] == 5
    out = draw_boxes(np.zeros((100, 200)), [[50, 5, 30, 30], [120, 40, 20, 20]], labels=["", "x"])
    assert tuple(out[5, 60]) == (255, 255, 0) and tuple(out[20, 60]) == (0, 0, 0)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: caption_boxes("ab", [[0, 0, 4, 4]] * 2, (10, 10)), "texts must be a sequence"),
        (lambda: caption_boxes(["a"], [[0, 0, 4, 4]] * 2, (10, 10)), "one per box"),
        (lambda: caption_boxes(["a"], [[0, 0, 4, 4]], 10), "canvas must be"),
        (
            lambda: draw_boxes(np.zeros((8, 8)), [[0, 0, 4, 4]] * 2, color=[[1, 2, 3]]),
            r"one row per box \(2\)",
        ),
        (
            lambda: draw_boxes(np.zeros((8, 8)), [[0, 0, 4, 4]], color=[[1, 2, 300]]),
            r"color\[0\]",
        ),
        (lambda: legend_panel(np.zeros((8, 8)), ["a"]), r"entries\[0\] must be"),
        (lambda: legend_panel(np.zeros((8, 8)), [("a", (1, 2))]), r"entries\[0\]\[1\]"),
        (lambda: legend_panel(np.zeros((8, 8)), "ab"), "entries must be"),
    ],
)
def test_caption_and_legend_refusals(call, match):
    with pytest.raises(InputError, match=match):
        call()


# --------------------------------------------------------------------------- detection sheet


def _scene(seed: int = 0) -> np.ndarray:
    return np.full((128, 128, 3), 90 + 10 * seed, np.uint8)


PRED = {"boxes": [[10, 10, 60, 60], [64, 64, 100, 110]], "labels": [1, 2], "scores": [0.9, 0.6]}
TRUE = {"boxes": [[12, 12, 62, 62]], "labels": [1]}
NONE = {"boxes": np.zeros((0, 4)), "labels": np.zeros(0, int), "scores": np.zeros(0)}


def _near(pic: np.ndarray, color) -> np.ndarray:
    return (pic.astype(int) == np.asarray(color)).all(axis=2)


def test_detection_samples_are_a_square_grid_readable_at_1080p():
    # the issue: four 128 x 128 samples side by side made a 528 x 128 strip
    pic = detection_samples_picture([_scene(i) for i in range(4)], [PRED] * 4, [TRUE] * 4)
    h, w = pic.shape[:2]
    assert 1000 <= w <= 1900 and 0.7 <= h / w <= 1.4
    # two columns of 768 px (6 x 128) with a white gap between them
    assert w == 2 * 768 + 8 and (pic[200:, 768:776] == 255).all()
    nine = detection_samples_picture([_scene()] * 9, [PRED] * 9)
    assert 1000 <= nine.shape[1] <= 1900  # 3 x 3
    big = detection_samples_picture([np.zeros((400, 400, 3), np.uint8)] * 4, [NONE] * 4)
    assert big.shape[1] == 2 * 800 + 8  # 400 px tiles doubled


def test_predictions_and_ground_truth_in_two_colours_with_a_legend():
    pic = detection_samples_picture([_scene()], [PRED], [TRUE], ["a", "b"], threshold=0.3)
    band = int(max(16, label_size_for(pic.shape[0])) * 2.2)
    legend, cells = pic[:band], pic[band:]
    for color in (PREDICTION_COLOR, TRUTH_COLOR):
        assert _near(legend, color).sum() > 50  # a swatch of each
        assert _near(cells, color).sum() > 500  # outlines and captions of each
    alone = detection_samples_picture([_scene()], [PRED])  # no ground truth: one colour
    assert _near(alone, TRUTH_COLOR).sum() == 0 and _near(alone, PREDICTION_COLOR).sum() > 500


def test_nothing_detected_is_written_on_an_empty_sample():
    low = {"boxes": [[10, 10, 60, 60]], "labels": [1], "scores": [0.1]}
    pic = detection_samples_picture([_scene(), _scene()], [PRED, low], [TRUE, TRUE], threshold=0.3)
    size = max(16, label_size_for(pic.shape[0]))
    top = int(size * 2.2) + int(size * 1.6)  # under the legend and the title
    first, second = pic[top : top + 3 * size, :768], pic[top : top + 3 * size, 776:]
    # the note's black box and white ink on the empty one; nothing like it on the other
    assert _near(second, (0, 0, 0)).sum() > 2000 and _near(second, (255, 255, 255)).sum() > 50
    assert _near(first, (0, 0, 0)).sum() < 200  # (black caption text only)
    # the low-scored box is left out: no prediction colour in the second cell
    assert _near(pic[top:, 776:], PREDICTION_COLOR).sum() == 0


def test_detection_sheet_captions_do_not_overlap_on_crowded_boxes():
    boxes = np.array([[20 + 3 * i, 30 + 2 * i, 50 + 3 * i, 60 + 2 * i] for i in range(8)], float)
    pred = {"boxes": boxes, "labels": np.ones(8, int), "scores": np.linspace(0.9, 0.4, 8)}
    # the same placement rule on the enlarged cell (6 x): rectangles apart
    size = max(16, label_size_for(768))
    xywh = np.column_stack([boxes[:, :2], boxes[:, 2:] - boxes[:, :2]]) * 6
    rects = [r for r in caption_boxes(["0.90"] * 8, xywh, (768, 768), size=size) if r]
    assert all(not _intersect(a, b) for a, b in itertools.combinations(rects, 2))
    assert detection_samples_picture([_scene()], [pred]).shape[1] == 768


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: detection_samples_picture([], []), "images must be a non-empty list"),
        (lambda: detection_samples_picture([_scene()], []), "predictions must be a list"),
        (lambda: detection_samples_picture([_scene()], [PRED], []), "targets must be a list"),
        (lambda: detection_samples_picture([_scene()], [[1, 2]]), r"predictions\[0\] must be"),
        (
            lambda: detection_samples_picture([_scene()], [{**PRED, "scores": [1.0]}]),
            r"predictions\[0\]\['scores'\] must have one value per box",
        ),
        (
            lambda: detection_samples_picture([_scene()], [{"boxes": [[1, 2, 3]]}]),
            r"\(K, 4\)",
        ),
    ],
)
def test_detection_sheet_refusals(call, match):
    with pytest.raises(InputError, match=match):
        call()


# --------------------------------------------------------------------------- panels


def test_panels_in_a_grid_instead_of_a_strip():
    pics = [np.zeros((384, 384, 3), np.uint8)] * 6
    strip = panels_picture(pics, list("abcdef"))
    grid = panels_picture(pics, list("abcdef"), columns=3)
    assert strip.shape[1] > 2300  # the strips
    assert grid.shape[1] == 3 * 384 + 2 * 12 and grid.shape[0] < grid.shape[1]
    # the fourth picture starts the second row, under the first, its title between
    cap = (grid.shape[0] - 2 * 384 - 12) // 2
    y = grid.shape[0] - 384
    assert (grid[y:, :384] == 0).all() and (grid[cap : cap + 384, :384] == 0).all()
    assert (grid[y - cap - 12 : y - cap, :] == 255).all()  # the gap between the rows
    assert (grid[y - cap : y, :384] < 128).any()  # the title "d"


# --------------------------------------------------------------------------- cloud legend


def test_render_points_with_a_legend_of_the_segment_colours():
    pts = np.array([[0.0, 0.0, 2.0], [0.3, 0.1, 2.0]])
    cols = np.array([[38, 101, 255], [165, 255, 38]], np.uint8)
    plain = render_points(pts, cols, size=(320, 240), point_size=6)
    named = [("plane 1", tuple(cols[0])), ("cluster 1", tuple(cols[1]))]
    pic = render_points(pts, cols, size=(320, 240), point_size=6, legend=named)
    assert pic.shape[0] == 240 and pic.shape[1] > 320 + 80
    np.testing.assert_array_equal(pic[:, :320], plain)  # the render is not covered
    panel = pic[:, 320:]
    for c in cols:
        assert _near(panel, c).sum() >= 100  # a swatch per entry
    assert (panel < 128).all(axis=2).sum() > 100  # the names, in black


# --------------------------------------------------------------------------- blobs


def test_blob_overlay_keeps_the_image_outside_the_blob_outlines():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (120, 160), dtype=np.uint8)
    lab = np.zeros((120, 160), np.int32)
    lab[20:60, 30:80] = 1
    lab[70:110, 100:150] = 2
    out = blob_overlay(image, lab, alpha=0.35, outline=1, boxes=False)
    colors = label_colors(np.array([0, 1, 2]))
    # background: the image itself
    np.testing.assert_array_equal(out[lab == 0], np.repeat(image[lab == 0, None], 3, axis=1))
    # the blob's border: its colour; its inside: a 35 % blend, the image showing through
    assert (out[20, 30:80] == colors[1]).all() and (out[59, 30:80] == colors[1]).all()
    inner = np.zeros_like(lab, bool)
    inner[21:59, 31:79] = True
    blend = np.round(0.65 * image[inner][:, None] + 0.35 * colors[1].astype(float))
    np.testing.assert_array_equal(out[inner], blend.astype(np.uint8))
    # outlines only: the inside is the image
    bare = blob_overlay(image, lab, alpha=0.0, outline=1, boxes=False)
    np.testing.assert_array_equal(bare[inner][:, 0], image[inner])
    # with boxes and ids: the image stays outside the boxes and captions
    boxed = blob_overlay(image, lab)
    assert (boxed[lab == 0] == np.repeat(image[lab == 0, None], 3, axis=1)).all(axis=1).mean() > 0.8


def test_blob_overlay_refusals_and_no_blobs():
    img = np.zeros((8, 8), np.uint8)
    assert (blob_overlay(img, np.zeros((8, 8), int)) == 0).all()
    with pytest.raises(InputError, match="labels must be >= 0"):
        blob_overlay(img, -np.ones((8, 8), int))
    with pytest.raises(InputError, match="integer"):
        blob_overlay(img, np.zeros((8, 8)))
    with pytest.raises(InputError, match="alpha"):
        blob_overlay(img, np.zeros((8, 8), int), alpha=2.0)


# --------------------------------------------------------------------------- 3-D pose


def _drawn_tick_labels(fig) -> list[tuple[int, str, object]]:
    """(panel, text, window extent) of every tick label as it is drawn."""
    from matplotlib.text import Text

    owner = {
        id(tick.label1): k
        for k, ax in enumerate(fig.axes)
        for axis in (ax.xaxis, ax.yaxis, ax.zaxis)
        for tick in axis.get_major_ticks()
    }
    seen = []
    original = Text.draw

    def draw(self, renderer):
        original(self, renderer)
        if id(self) in owner and self.get_visible() and self.get_text():
            seen.append((owner[id(self)], self.get_text(), self.get_window_extent(renderer)))

    Text.draw = draw
    try:
        fig.canvas.draw()
    finally:
        Text.draw = original
    return seen


POSE = np.array(
    [
        [0, -0.75, 0],
        [0.18, -0.55, 0.02],
        [-0.18, -0.55, 0.02],
        [0.25, -0.28, 0.05],
        [-0.22, -0.27, -0.05],
        [0.1, 0.0, 0],
        [-0.1, 0.0, 0],
        [0.12, 0.85, 0.0],
        [-0.1, 0.84, 0.02],
    ]
)
LINKS = [(0, 1), (0, 2), (1, 3), (2, 4), (1, 5), (2, 6), (5, 7), (6, 8)]


@pytest.mark.parametrize("scale", [1.0, 0.01])
def test_3d_pose_tick_labels_do_not_overlap(scale):
    # before: 12 and 45 overlapping pairs of tick labels in the two default panels (the
    # second view's y labels piled on one spot)
    fig = skeleton_3d_figure(POSE * scale, LINKS, reference=POSE * scale + 0.02 * scale)
    ticks = _drawn_tick_labels(fig)
    for panel in (0, 1):
        boxes = [t[2] for t in ticks if t[0] == panel]
        assert 4 <= len(boxes) <= 18
        pairs = [(a, b) for a, b in itertools.combinations(boxes, 2) if a.overlaps(b)]
        assert not pairs
    # the front view looks along y: its y axis shows no ticks, and the title says why
    assert len(fig.axes[1].yaxis.get_ticklocs()) == 0
    assert "y along the line of sight" in fig.axes[1].get_title()
    assert fig.axes[0].get_title().count("line of sight") == 0
