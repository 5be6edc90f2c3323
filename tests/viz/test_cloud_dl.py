"""Pictures for deep learning on point clouds (issue 29): sizes at and away from the
reference size, label and query colours present, the pictures following their inputs
(critical sets, neighbour graphs, title colours), NaN points left out, empty clouds
noted, refusals; the figure helpers of viz.figure."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import (
    cloud_picture,
    clouds_grid,
    critical_points_picture,
    feature_neighbours_picture,
    label_colors,
)
from robopercept.viz.figure import agg_figure, figure_to_rgb

RNG = np.random.default_rng(29)
PTS = RNG.normal(size=(60, 3))
# the 4 nearest points (itself first) and 4 far points of each point: two "layers"
_D = ((PTS[:, None] - PTS[None]) ** 2).sum(-1)
NEAR = np.argsort(_D, axis=1)[:, :4]
FAR = np.argsort(-_D, axis=1)[:, :4]
SMALL = (400, 240)
NOTE = (178, 34, 34)  # the "empty cloud" note's colour, #b22222


def _has(pic: np.ndarray, rgb) -> bool:
    """Whether some pixel has exactly this colour."""
    return bool((pic == np.asarray(rgb, np.uint8)).all(axis=-1).any())


def _colours(pic: np.ndarray) -> int:
    return len(np.unique(pic.reshape(-1, 3), axis=0))


def _check(pic: np.ndarray, size: tuple[int, int]) -> None:
    assert pic.shape == (size[1], size[0], 3) and pic.dtype == np.uint8
    assert pic.flags.c_contiguous
    assert _colours(pic) > 20  # not blank: panes, grid lines, points, text


# ----------------------------------------------------------------------------- sizes


@pytest.mark.parametrize(
    ("make", "size"),
    [
        (lambda s: cloud_picture(PTS, labels=np.arange(60) % 3, size=s), (1600, 900)),
        (lambda s: clouds_grid([PTS, PTS[:30]], ["a", "b"], size=s), (1800, 1000)),
        (lambda s: critical_points_picture(PTS, [0, 1], size=s), (1600, 800)),
        (lambda s: feature_neighbours_picture(PTS, [NEAR, FAR], [0], size=s), (1800, 700)),
    ],
    ids=["cloud", "grid", "critical", "neighbours"],
)
def test_default_and_odd_sizes_are_exact(make, size):
    _check(make(size), size)
    _check(make((333, 211)), (333, 211))  # a scaled dpi: no pixel lost to rounding


def test_default_sizes_are_the_documented_ones():
    assert cloud_picture(PTS[:5]).shape == (900, 1600, 3)
    assert critical_points_picture(PTS[:5], [0]).shape == (800, 1600, 3)


# ----------------------------------------------------------------------------- colours


def test_label_colours_appear_with_their_legend():
    labels = np.arange(60) % 3
    pic = cloud_picture(PTS, labels=labels, names=["wing", "body", "tail"], size=(800, 450))
    for rgb in label_colors(np.array([1, 2, 3])):  # label c: label_colors(c + 1)
        assert _has(pic, rgb)
    # a label absent from the cloud is absent from the picture (and from the legend)
    two = cloud_picture(PTS, labels=labels % 2, names=["wing", "body", "tail"], size=(800, 450))
    assert not _has(two, label_colors(np.array([3]))[0])


def test_negative_labels_are_grey_and_values_take_viridis():
    labels = np.where(np.arange(60) < 30, -1, 0)
    pic = cloud_picture(PTS, labels=labels, size=(800, 450))
    assert _has(pic, (160, 160, 160)) and _has(pic, label_colors(np.array([1]))[0])
    vals = cloud_picture(PTS, values=PTS[:, 0], size=(800, 450))
    # the colour bar runs from viridis(0) to viridis(1)
    assert _has(vals, (68, 1, 84)) and _has(vals, (253, 231, 37))


def test_several_views_are_several_panels():
    one = cloud_picture(PTS, size=(800, 300))
    two = cloud_picture(PTS, views=((0.3, -1.0), (0.3, 0.5)), size=(800, 300))
    assert not np.array_equal(one, two)


def test_wrong_predictions_are_titled_in_red():
    clouds = [PTS, PTS * 2.0]
    plain = clouds_grid(clouds, ["chair / chair", "lamp / table"], size=(600, 300))
    red = clouds_grid(
        clouds, ["chair / chair", "lamp / table"], title_colors=[None, "red"], size=(600, 300)
    )
    assert _has(red, (255, 0, 0)) and not _has(plain, (255, 0, 0))
    same = clouds_grid(
        clouds, ["chair / chair", "lamp / table"], title_colors=[None, (255, 0, 0)], size=(600, 300)
    )
    np.testing.assert_array_equal(red, same)


def test_grid_labels_colour_each_cloud():
    pic = clouds_grid(
        [PTS, PTS], ["parts", "plain"], [np.arange(60) % 2, None], columns=1, size=(900, 1000)
    )
    for rgb in label_colors(np.array([1, 2])):
        assert _has(pic, rgb)


# ---------------------------------------------------------------- inputs shape the picture


def test_the_critical_set_shapes_the_right_panel():
    a = critical_points_picture(PTS, [0, 5, 9], size=SMALL)
    b = critical_points_picture(PTS, [1, 6, 9], size=SMALL)
    assert not np.array_equal(a, b)
    # repeated winners count once: the same set, the same picture
    np.testing.assert_array_equal(a, critical_points_picture(PTS, [9, 0, 5, 5, 0], size=SMALL))
    # the left panel (the whole cloud) does not depend on the set
    half = SMALL[0] // 2 - 20
    np.testing.assert_array_equal(a[40:, :half], b[40:, :half])


def test_neighbour_graphs_shape_their_panels():
    near = feature_neighbours_picture(PTS, [NEAR], [3], size=SMALL)
    far = feature_neighbours_picture(PTS, [FAR], [3], size=SMALL)
    assert not np.array_equal(near, far)
    other = feature_neighbours_picture(PTS, [NEAR], [7], size=SMALL)
    assert not np.array_equal(near, other)
    big = feature_neighbours_picture(PTS, [NEAR, FAR], [3, 7], size=(900, 350))
    for rgb in label_colors(np.array([1, 2])):  # query q: label_colors(q + 1)
        assert _has(big, rgb)


def test_nan_points_are_left_out_of_the_drawing():
    holes = np.vstack([PTS, np.full((5, 3), np.nan), [[np.inf, 0.0, 0.0]]])
    np.testing.assert_array_equal(
        clouds_grid([holes], ["x"], size=SMALL), clouds_grid([PTS], ["x"], size=SMALL)
    )
    # a NaN critical point is left out too (the count in the title still names it)
    pic = critical_points_picture(holes, [0, 62], size=SMALL)
    assert pic.shape == (SMALL[1], SMALL[0], 3)


@pytest.mark.parametrize(
    "make",
    [
        lambda p: cloud_picture(p, size=SMALL),
        lambda p: cloud_picture(p, labels=np.zeros(len(p), int), names=["a"], size=SMALL),
        lambda p: clouds_grid([p, PTS], ["empty", "full"], size=SMALL),
        lambda p: critical_points_picture(p, [], size=SMALL),
        lambda p: feature_neighbours_picture(p, [np.zeros((len(p), 2), int)], [], size=SMALL),
    ],
    ids=["cloud", "labels", "grid", "critical", "neighbours"],
)
@pytest.mark.parametrize("cloud", [np.zeros((0, 3)), np.full((4, 3), np.nan)], ids=["0", "nan"])
def test_an_empty_cloud_gives_a_note_not_a_crash(make, cloud):
    pic = make(cloud)
    assert pic.shape == (SMALL[1], SMALL[0], 3)
    assert _has(pic, NOTE)  # the red "empty cloud" note


# ----------------------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: cloud_picture(np.zeros((3, 2))), r"points must have shape \(N, 3\)"),
        (lambda: cloud_picture(np.zeros((3, 5))), r"points as columns\? use points\.T"),
        (lambda: cloud_picture(PTS, labels=[0, 1]), r"labels must have one entry per point \(60\)"),
        (lambda: cloud_picture(PTS, labels=np.zeros(60)), "labels must be integer"),
        (lambda: cloud_picture(PTS, labels=np.zeros(60, int), values=np.zeros(60)), "not both"),
        (lambda: cloud_picture(PTS, names=["a"]), "pass labels"),
        (
            lambda: cloud_picture(PTS, labels=np.arange(60) % 3, names=["a", "b"]),
            "labels go up to 2 but 2 names",
        ),
        (lambda: cloud_picture(PTS, values=np.full(60, np.inf)), "values must be finite"),
        (lambda: cloud_picture(PTS, views=((20, -60),)), r"views\[0\] elev"),
        (lambda: cloud_picture(PTS, views=[]), "1 to 6"),
        (lambda: cloud_picture(PTS, size=(100, 100)), r"each side in \[150, 4000\]"),
        (lambda: cloud_picture(PTS, title=3), "title must be a string"),
        (lambda: cloud_picture(PTS * 1e10), "points"),
        (lambda: clouds_grid([], []), "1 to 100 clouds"),
        (lambda: clouds_grid([PTS], ["a", "b"]), "titles must hold 1"),
        (lambda: clouds_grid([PTS], ["a"], [np.zeros(3, int)]), r"labels\[0\] must have one"),
        (lambda: clouds_grid([PTS], ["a"], title_colors=["nope"]), "colour name"),
        (lambda: clouds_grid([PTS], ["a"], title_colors=[(300, 0, 0)]), "RGB triple"),
        (lambda: clouds_grid([PTS], ["a"], columns=0), "columns"),
        (lambda: critical_points_picture(PTS, [60]), r"in 0\.\.59 \(the cloud has 60"),
        (lambda: critical_points_picture(PTS, [-1]), "got -1"),
        (lambda: critical_points_picture(PTS, [0.5]), "critical must be integer"),
        (lambda: critical_points_picture(PTS, np.ones(60, bool)), "np.flatnonzero"),
        (lambda: feature_neighbours_picture(PTS, [NEAR[:5]], [0]), r"\(N, k\) = \(60, k\)"),
        (lambda: feature_neighbours_picture(PTS, [NEAR + 60], [0]), r"graphs\[0\] must be point"),
        (lambda: feature_neighbours_picture(PTS, [NEAR * 0.5], [0]), "integer point indices"),
        (lambda: feature_neighbours_picture(PTS, [], [0]), "1 to 8 layers"),
        (lambda: feature_neighbours_picture(PTS, [NEAR], [99]), r"queries must be point"),
        (lambda: feature_neighbours_picture(PTS, [NEAR], np.arange(21)), "at most 20"),
        (lambda: feature_neighbours_picture(PTS, [NEAR], [0], layer_names=["a", "b"]), "hold 1"),
    ],
)
def test_refusals(call, match):
    with pytest.raises(InputError, match=match):
        call()


# ----------------------------------------------------------------------------- viz.figure


def test_figure_helpers():
    fig = agg_figure(300, 200, reference_width=600)
    assert fig.dpi == 50.0
    fig.add_subplot(facecolor="red")
    pic = figure_to_rgb(fig)
    assert pic.shape == (200, 300, 3) and _has(pic, (255, 0, 0))
    with pytest.raises(InputError, match="matplotlib Figure"):
        figure_to_rgb(np.zeros((2, 2)))
    with pytest.raises(InputError, match="layout must be one of"):
        agg_figure(300, 200, layout="grid")
