"""Scatter, curve and confusion-matrix pictures: sizes, colours, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import (
    confusion_picture,
    curves_picture,
    precision_recall_picture,
    scatter_picture,
    tiles_picture,
)


def test_confusion_picture_shades_by_row_share():
    cm = np.array([[9, 1], [0, 5]])
    pic = confusion_picture(cm, ["a", "b"], cell=50)
    assert pic.dtype == np.uint8 and pic.ndim == 3
    # sample each cell away from its number: darker means a larger share of the row
    left, top = 80, 60  # label column of 60 px + 20, as laid out by confusion_picture
    shade = [[int(pic[top + i * 50 + 5, left + j * 50 + 5].sum()) for j in (0, 1)] for i in (0, 1)]
    assert shade[0][0] < shade[0][1]  # 0.9 darker than 0.1
    assert shade[1][1] < shade[1][0]  # 1.0 darker than 0.0
    assert shade[1][0] == 3 * 255  # an empty cell stays white
    with pytest.raises(InputError):
        confusion_picture(np.zeros((2, 3)), ["a", "b"])


def test_scatter_and_curves():
    pts = np.array([[0, 0], [1, 1], [2, 0.5], [3, 2.0]])
    pic = scatter_picture(pts, np.array([0, 0, 1, -1]), title="t", width=400, height=300)
    assert pic.shape == (300, 400, 3)
    assert (np.abs(pic.astype(int) - 150).sum(axis=2) == 0).any()  # grey noise dots
    with pytest.raises(InputError, match=r"\(N, 2\)"):
        scatter_picture(np.zeros((3, 3)))
    with pytest.raises(InputError, match="one value per point"):
        scatter_picture(pts, np.zeros(2))
    x = np.linspace(0, 1, 5)
    assert curves_picture([(x, x, "diag")], title="ROC", xlabel="x", ylabel="y").ndim == 3
    with pytest.raises(InputError):
        curves_picture([], title="", xlabel="", ylabel="")


def test_precision_recall_picture_is_the_curves_of_the_defined_classes():
    r = np.linspace(0, 1, 101)
    p = np.stack([np.ones(101), -np.ones(101), 1 - r])  # class "b" has no ground truth
    pic = precision_recall_picture(r, p, ["a", "b", 3], iou_threshold=0.75, width=400, height=300)
    # the same picture as the two defined curves, labelled with their mean (the AP)
    ref = curves_picture(
        [(r, p[0], "a (AP 1.000)"), (r, p[2], "3 (AP 0.500)")],
        title="precision-recall per class, IoU 0.75",
        xlabel="recall",
        ylabel="precision",
        width=400,
        height=300,
    )
    np.testing.assert_array_equal(pic, ref)
    assert precision_recall_picture(r, p[:1], ["a"], iou_threshold=0.5).shape == (1000, 1600, 3)
    with pytest.raises(InputError, match="no category has ground truth"):
        precision_recall_picture(r, p[1:2], ["b"], iou_threshold=0.5)
    with pytest.raises(InputError, match=r"precision \(K, R\)"):
        precision_recall_picture(r, p[:, :50], ["a", "b", "c"], iou_threshold=0.5)
    with pytest.raises(InputError, match="labels must be 3 class names"):
        precision_recall_picture(r, p, ["a", "b"], iou_threshold=0.5)
    with pytest.raises(InputError, match="finite"):
        precision_recall_picture(r, np.full((1, 101), np.nan), ["a"], iou_threshold=0.5)


def test_tiles_picture_layout_and_colours() -> None:
    from robopercept.viz import tiles_picture

    w = np.zeros((5, 3, 3))
    w[0, 1, 1] = 1.0  # one positive weight
    w[1, 0, 0] = -1.0  # one negative weight
    img = tiles_picture(w, signed=True, columns=3, tile_px=30, gap=6)
    assert img.shape == (2 * 36 + 6, 3 * 36 + 6, 3) and img.dtype == np.uint8
    centre0 = img[6 + 15, 6 + 15]  # tile 0's middle cell: red
    corner1 = img[6 + 5, 6 + 36 + 5]  # tile 1's top-left cell: blue
    assert int(centre0[0]) > int(centre0[2]) + 80  # red
    assert int(corner1[2]) > int(corner1[0]) + 80  # blue
    assert (img[6 + 36 + 15, 6 + 2 * 36 + 15] == 255).all()  # the empty 6th slot stays white


def test_tiles_picture_activations_and_bad_input() -> None:
    from robopercept.viz import tiles_picture

    maps = np.stack([np.arange(16.0).reshape(4, 4), np.full((4, 4), 3.0)])
    img = tiles_picture(maps, tile_px=40, gap=0, columns=2)
    assert img[0, 0].tolist() == [0, 0, 0] and img[39, 39].tolist() == [255, 255, 255]
    assert (img[:, 40:] == 0).all()  # a constant map is drawn black, not divided by zero
    with pytest.raises(InputError):
        tiles_picture(np.zeros((2, 2)))
    with pytest.raises(InputError):
        tiles_picture(np.zeros((0, 3, 3)))


# issue 25: texts, sizes, counts and columns are checked ---------------------------------
_XY = np.random.default_rng(0).normal(size=(20, 2))
_CURVE = [(np.linspace(0, 1, 5), np.linspace(0, 1, 5), "a")]


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: confusion_picture(np.eye(2), ["a", "b"], title=["x"]), "title must be a string"),
        (lambda: confusion_picture(np.eye(2), ["a", "b"], cell=-90070), "cell must be >= 0"),
        (lambda: confusion_picture(np.eye(2), ["a", "b"], cell=2**40), "at most 67108864"),
        (lambda: confusion_picture(np.full((2, 2), np.nan), ["a", "b"]), "finite, non-negative"),
        (lambda: confusion_picture(np.eye(2), "ab"), "names must be a sequence"),
        (lambda: curves_picture(_CURVE, title=3, xlabel="x", ylabel="y"), "title must be"),
        (lambda: curves_picture(_CURVE, title="t", xlabel=["x"], ylabel="y"), "xlabel must"),
        (lambda: curves_picture(_CURVE, title="t", xlabel="x", ylabel=3), "ylabel must be"),
        (lambda: curves_picture(_CURVE, title="", xlabel="", ylabel="", width=0), "width must"),
        (lambda: curves_picture(_CURVE, title="", xlabel="", ylabel="", width=3.4e16), "width"),
        (lambda: curves_picture([(1, 2)], title="", xlabel="", ylabel=""), r"\(x, y, label\)"),
        (lambda: curves_picture([([1, 2], [1], "a")], title="", xlabel="", ylabel=""), "length"),
        (lambda: scatter_picture(_XY, width=-np.inf), "width must be an integer"),
        (lambda: scatter_picture(_XY, height=1e-162), "height must be an integer"),
        (lambda: scatter_picture(_XY, width=2**40), "at most 67108864"),
        (lambda: scatter_picture(_XY, xlabel=[""]), "xlabel must be a string"),
        (lambda: scatter_picture(_XY * 1e305), "overflow"),
        (lambda: tiles_picture(np.ones((3, 4, 4)), tile_px="3"), "tile_px must be an integer"),
        (lambda: tiles_picture(np.ones((3, 4, 4)), columns=5865057000623), "at most 67108864"),
        (lambda: tiles_picture(np.ones((3, 4, 4)), columns=0), "columns must be >= 1"),
        (lambda: tiles_picture(np.full((3, 4, 4), np.nan)), "tiles must be finite"),
        (lambda: tiles_picture(np.ones((3, 4, 4)), names=["a"]), "3 tiles but 1 names"),
    ],
)
def test_issue25_bad_arguments_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_extreme_but_valid_values_still_draw():
    """A single value near 1e300 (its range widened relatively, a fixed +-0.5 vanished
    there and divided by zero) and values up to 1e300 plot; the smallest sizes work."""
    pic = scatter_picture(np.full((3, 2), 1e300), width=100, height=90)
    assert pic.shape == (90, 100, 3) and (pic != 255).any()
    pic = curves_picture(
        [(np.array([-1e300, 1e300]), np.array([0.0, 1e-300]), "c")], title="", xlabel="", ylabel=""
    )
    assert pic.shape == (560, 700, 3)
    tiles = tiles_picture(np.array([[[1e308, -1e308]]]), tile_px=4, gap=0)
    assert tiles.shape == (2, 4, 3) and tiles[0, 0, 0] == 255 and tiles[0, 3, 0] == 0
