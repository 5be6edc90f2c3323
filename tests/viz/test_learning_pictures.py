"""Scatter, curve and confusion-matrix pictures: sizes, colours, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import confusion_picture, curves_picture, scatter_picture


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
