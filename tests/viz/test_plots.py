"""Plots drawn with matplotlib (issue 30): each plot rendered and checked through
matplotlib's layout engine: size, non-empty, every legend inside the picture and clear
of the titles and axis labels, integer frame ticks, axis labels, notes on empty data,
colour bars on scalar maps."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz.figure import agg_figure, figure_to_rgb, readable_dpi
from robopercept.viz.learning import (
    confusion_figure,
    confusion_picture,
    curves_figure,
    curves_picture,
    scatter_figure,
    scatter_picture,
)
from robopercept.viz.plot import (
    MAX_LEGEND_ENTRIES,
    Panel,
    Series,
    outside_legend,
    plot_series,
    scalar_map_figure,
    scalar_map_picture,
    series_figure,
)

_X = np.linspace(0.0, 1.0, 30)


def _roc(n: int) -> list[tuple[np.ndarray, np.ndarray, str]]:
    return [(_X, _X ** (1.0 / (k + 1.5)), f"class {k} AUC 0.{900 + k}") for k in range(n)]


def _draw(fig):
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*[Ll]ayout not applied.*")
        fig.canvas.draw()
    return fig.canvas.get_renderer()


def _overlap(a, b) -> float:
    """Area in px^2 shared by two display boxes."""
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return max(w, 0.0) * max(h, 0.0)


def _legends(fig):
    found = list(fig.legends)
    found += [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    return found


def _check_layout(fig, *, legends: int | None = None) -> None:
    """Every legend lies inside the figure (1 px of anti-aliasing allowed) and covers no
    title, axis label or axes; every title and axis label lies inside the figure."""
    renderer = _draw(fig)
    box = fig.bbox
    texts = [t for ax in fig.axes for t in (ax.title, ax.xaxis.label, ax.yaxis.label)]
    suptitle = getattr(fig, "_suptitle", None)  # matplotlib keeps it there
    texts += [suptitle] if suptitle is not None else []
    texts = [t for t in texts if t.get_text()]
    for t in texts:
        e = t.get_window_extent(renderer)
        assert e.x0 >= box.x0 - 1 and e.x1 <= box.x1 + 1, t.get_text()
        assert e.y0 >= box.y0 - 1 and e.y1 <= box.y1 + 1, t.get_text()
    found = _legends(fig)
    if legends is not None:
        assert len(found) == legends
    for leg in found:
        e = leg.get_window_extent(renderer)
        assert e.x0 >= box.x0 - 1 and e.x1 <= box.x1 + 1, (e, box)
        assert e.y0 >= box.y0 - 1 and e.y1 <= box.y1 + 1, (e, box)
        for t in texts:
            assert _overlap(e, t.get_window_extent(renderer)) < 1.0, t.get_text()
        for ax in fig.axes:
            assert _overlap(e, ax.get_window_extent(renderer)) < 1.0, "legend over the data"


def _entries(legend) -> list[str]:
    return [t.get_text() for t in legend.get_texts()]


def _check_picture(pic: np.ndarray, shape: tuple[int, int]) -> None:
    assert pic.shape == (*shape, 3) and pic.dtype == np.uint8
    assert len(np.unique(pic.reshape(-1, 3), axis=0)) > 10  # not one colour: something drawn


# ----------------------------------------------------------------------------- curves


@pytest.mark.parametrize("size", [(700, 560), (400, 300)])
def test_ten_class_roc_legend_is_whole_and_clear(size):
    fig = curves_figure(
        _roc(10), title="svm: ROC (one vs rest)", xlabel="false positive rate",
        ylabel="true positive rate", width=size[0], height=size[1],
    )  # fmt: skip
    _check_layout(fig, legends=1)
    ax = fig.axes[0]
    assert _entries(ax.get_legend()) == [f"class {k} AUC 0.{900 + k}" for k in range(10)]
    assert ax.get_xlabel() == "false positive rate" and ax.get_ylabel() == "true positive rate"
    _check_picture(figure_to_rgb(fig), size[::-1])


def test_many_curves_fill_columns_and_stay_inside():
    fig = curves_figure(_roc(25), title="PR", xlabel="recall", ylabel="precision")
    _check_layout(fig, legends=1)
    legend = fig.axes[0].get_legend()
    assert len(_entries(legend)) == 25
    # 60 curves: the legend is cut to MAX_LEGEND_ENTRIES lines, the last one says so
    fig = curves_figure(_roc(60), title="PR", xlabel="recall", ylabel="precision", width=1600,
                        height=1000)  # fmt: skip
    _check_layout(fig, legends=1)
    entries = _entries(fig.axes[0].get_legend())
    assert len(entries) == MAX_LEGEND_ENTRIES
    assert entries[-1] == f"... and {60 - MAX_LEGEND_ENTRIES + 1} more"


def test_curves_default_size_fonts_and_empty_note():
    fig = curves_figure(_roc(2), title="t", xlabel="recall", ylabel="precision")
    assert fig.dpi == 100.0  # 700 x 560 fits a 1080p screen: 12 pt is 16.7 px
    _draw(fig)
    ax = fig.axes[0]
    assert min(t.get_fontsize() for t in ax.get_xticklabels()) >= 12
    assert min(t.get_fontsize() for t in _legends(fig)[0].get_texts()) >= 12
    # rates: the whole unit square is shown
    assert ax.get_xlim() == pytest.approx((-0.02, 1.02))
    fig = curves_figure([(np.zeros(0), np.zeros(0), "none")], title="", xlabel="x", ylabel="y")
    assert [t.get_text() for t in fig.axes[0].texts] == ["no data"]
    _check_picture(figure_to_rgb(fig), (560, 700))


# ----------------------------------------------------------------------------- scatter


def test_scatter_labels_axes_keeps_class_order_and_does_not_clip():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(200, 2)) * [5.0, 1.0]
    labels = np.r_[np.arange(11), rng.integers(-1, 11, 189)]
    fig = scatter_figure(pts, labels, title="PCA", names=None)
    _check_layout(fig, legends=1)
    ax = fig.axes[0]
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("PC1", "PC2")  # the default names
    counts = {v: int((labels == v).sum()) for v in range(-1, 11)}
    # class order, noise (-1) last: not reversed
    expected = [f"{v} ({counts[v]})" for v in range(11)] + [f"noise ({counts[-1]})"]
    assert _entries(ax.get_legend()) == expected
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    # every point strictly inside the axes, with a margin
    assert x0 < pts[:, 0].min() and pts[:, 0].max() < x1
    assert y0 < pts[:, 1].min() and pts[:, 1].max() < y1
    fig = scatter_figure(pts, None, xlabel="LD1", ylabel="LD2")
    assert (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()) == ("LD1", "LD2")
    assert fig.axes[0].get_legend() is None  # no labels: one group, no legend
    pic = scatter_picture(pts, labels, names=[f"c{k}" for k in range(12)])
    _check_picture(pic, (600, 800))


def test_scatter_without_points_says_so():
    fig = scatter_figure(np.zeros((0, 2)))
    assert [t.get_text() for t in fig.axes[0].texts] == ["no points"]


# ----------------------------------------------------------------------------- series


def _plane_panels(t: np.ndarray, y: np.ndarray) -> list[Panel]:
    return [
        Panel(
            name, [Series(t, y, "measured", (214, 39, 40), "dots"), Series(t, y, "tracked")], unit
        )
        for name, unit in (("n_x", "n_x"), ("n_y", "n_y"), ("n_z", "n_z"), ("d", "d [m]"))
    ]


def test_series_grid_shares_one_legend_and_integer_frame_ticks():
    t = np.arange(7.0)  # few frames: matplotlib's default ticks would be 0, 0.5, 1, ...
    y = np.sin(t)
    y[2:4] = np.nan
    fig = series_figure(_plane_panels(t, y), width=1600, panel_height=435, columns=2,
                        xlabel="frame")  # fmt: skip
    _check_layout(fig, legends=1)
    assert len(fig.legends) == 1 and _entries(fig.legends[0]) == ["measured", "tracked"]
    for ax in fig.axes:
        lo, hi = ax.get_xlim()
        ticks = [v for v in ax.get_xticks() if lo <= v <= hi]
        assert ticks and all(float(v).is_integer() for v in ticks), ticks
        assert ax.get_ylabel()
    assert [ax.get_xlabel() for ax in fig.axes] == ["", "", "frame", "frame"]
    pic = plot_series(_plane_panels(t, y), width=1600, panel_height=435, columns=2)
    _check_picture(pic, (900, 1600))


def test_series_panel_legends_right_of_their_axes():
    x = np.arange(1.0, 31.0)
    panels = [
        Panel("loss", [Series(x, 1 / x, "train"), Series(x, 1.2 / x, "validation")], "loss"),
        Panel("learning rate", [Series(x, 0.1 * 0.9**x, "lr", (44, 160, 44))], "lr"),
    ]
    fig = series_figure(panels, width=1200, panel_height=260, xlabel="epoch")
    _check_layout(fig, legends=2)
    assert [_entries(ax.get_legend()) for ax in fig.axes] == [["train", "validation"], ["lr"]]
    for ax in fig.axes:  # right of the data
        assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
    # real-valued x: no integer locator
    fig = series_figure([Panel("p", [Series(np.linspace(0, 1, 5), np.ones(5), "a")])])
    _draw(fig)
    assert any(not float(v).is_integer() for v in fig.axes[0].get_xticks())


def test_series_with_nothing_to_show_gets_a_note():
    t = np.arange(5.0)
    nan = np.full(5, np.nan)
    fig = series_figure(_plane_panels(t, nan), width=1600, panel_height=435, columns=2,
                        empty_note="no board detected in 5 frames")  # fmt: skip
    _check_layout(fig)
    for ax in fig.axes:
        assert [x.get_text() for x in ax.texts] == ["no board detected in 5 frames"]
        lo, hi = ax.get_xlim()  # the frames still span the x axis, in whole frames
        assert lo < 0 and hi > 4
        assert all(float(v).is_integer() for v in ax.get_xticks() if lo <= v <= hi)
    pic = plot_series([Panel("empty", [])], width=400, panel_height=200)
    _check_picture(pic, (230, 400))


def test_plane_figure_without_a_board_has_notes_and_whole_frames():
    """plane.png of a run where the board is never seen: four panels with the note, not
    four blank axes; with a board: truth, measured and tracked in one legend above."""
    from robopercept.pipelines.plane_outputs import plane_parameters_figure

    nan = np.full((3, 4), np.nan)
    fig = plane_parameters_figure(np.arange(3), nan, nan)
    _check_layout(fig, legends=1)
    assert _entries(fig.legends[0]) == ["measured (0 of 3 frames)", "tracked"]
    for ax in fig.axes:
        assert [x.get_text() for x in ax.texts] == ["no board detected in 3 frames"]
        lo, hi = ax.get_xlim()
        assert all(float(v).is_integer() for v in ax.get_xticks() if lo <= v <= hi)
    _check_picture(figure_to_rgb(fig), (900, 1600))
    rows = np.tile([0.0, 0.6, 0.8, 1.5], (9, 1)) + np.linspace(0, 0.01, 9)[:, None]
    measured = rows.copy()
    measured[4] = np.nan
    fig = plane_parameters_figure(np.arange(9), measured, rows, rows)
    _check_layout(fig, legends=1)
    assert _entries(fig.legends[0]) == ["truth", "measured (8 of 9 frames)", "tracked"]
    assert [ax.get_ylabel() for ax in fig.axes][-1] == "d [m]"
    assert all(not ax.texts for ax in fig.axes)
    with pytest.raises(InputError, match=r"measured must be \(9, 4\)"):
        plane_parameters_figure(np.arange(9), rows[:, :3], rows)


# ----------------------------------------------------------------------------- maps


def test_scalar_map_has_colour_bar_and_nan_colour():
    d = np.tile(np.arange(64.0), (48, 1))
    d[10:20, 10:30] = np.nan
    fig = scalar_map_figure(d, label="disparity [px]", title="SGM", nan_color=(255, 0, 0))
    _check_layout(fig, legends=1)
    image_ax, bar_ax = fig.axes
    assert bar_ax.get_ylabel() == "disparity [px]"
    assert (image_ax.get_xlabel(), image_ax.get_ylabel()) == ("x [px]", "y [px]")
    assert _entries(fig.legends[0]) == ["no value (NaN/inf): 6.5% of pixels"]  # 200 / 3072
    pic = figure_to_rgb(fig)
    _check_picture(pic, (900, int(np.clip(round(800 * 64 / 48) + 300, 640, 1920))))
    red = (pic == [255, 0, 0]).all(axis=2)
    assert red.sum() > 1000  # the NaN block, enlarged
    # the default NaN colour is far from every viridis colour: magenta
    pic = scalar_map_picture(d, width=640, height=480)
    _check_picture(pic, (480, 640))
    assert ((pic == [255, 0, 255]).all(axis=2)).sum() > 100


def test_scalar_map_clipping_constant_and_empty_maps():
    d = np.tile(np.arange(10.0), (10, 1))
    fig = scalar_map_figure(d, vmin=2.0, vmax=7.0)
    assert fig.axes[1].get_ylabel() == "value"
    im = fig.axes[0].images[0]
    assert im.norm.vmin == 2.0 and im.norm.vmax == 7.0
    assert im.colorbar.extend == "both"  # clipped at both ends: arrows on the bar
    fig = scalar_map_figure(np.full((4, 4), 3.0))  # constant: a range around it
    assert fig.axes[0].images[0].norm.vmin < 3.0 < fig.axes[0].images[0].norm.vmax
    fig = scalar_map_figure(np.full((4, 4), np.nan))
    assert [t.get_text() for t in fig.axes[0].texts] == ["no finite value"]
    _check_picture(figure_to_rgb(fig), (900, 1100))  # square: 800 + 300 px wide


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: scalar_map_picture(np.zeros(5)), "values must have 2 dimensions|ndim|2-D|got"),
        (lambda: scalar_map_picture(np.zeros((0, 3))), "non-empty"),
        (lambda: scalar_map_picture(np.zeros((3, 3)), cmap="nope"), "colour map name"),
        (lambda: scalar_map_picture(np.zeros((3, 3)), vmin=2.0, vmax=1.0), "vmin must be <="),
        (lambda: scalar_map_picture(np.zeros((3, 3)), label=3), "label must be a string"),
        (lambda: scalar_map_picture(np.zeros((3, 3)), nan_color=(1, 2)), "nan_color"),
        (lambda: scalar_map_picture(np.array([["a"]])), "real numbers"),
        (lambda: plot_series([Panel("p", [Series(np.arange(3), np.arange(4), "a")])]), "1-D"),
        (lambda: plot_series([Panel("p", [])], columns=0), "columns must be >= 1"),
        (lambda: plot_series([Panel("p", [])], legend="left"), "legend must be one of"),
        (lambda: plot_series([Panel("p", [])], integer_x=1), "integer_x must be"),
        (lambda: plot_series([Panel("p", [Series([1], [1], "a", style="bar")])]), "style"),
        (lambda: outside_legend("ax", [], []), "host must be a matplotlib Axes"),
        (lambda: agg_figure(10, 10, dpi=50.0, reference_width=5), "not both"),
        (lambda: agg_figure(10, 10, dpi=0.0), "dpi"),
        (lambda: readable_dpi(100, 100, comfortable=(0, 1)), "comfortable width"),
    ],
)
def test_bad_arguments_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_outside_legend_mismatch_and_empty():
    fig = agg_figure(300, 200, layout="constrained")
    ax = fig.add_subplot()
    (line,) = ax.plot([0, 1], [0, 1])
    with pytest.raises(InputError, match="1 legend handles but 2 labels"):
        outside_legend(ax, [line], ["a", "b"])
    assert outside_legend(ax, [], []) is None


# ----------------------------------------------------------------------------- confusion


def test_confusion_colour_bar_and_long_names_inside():
    rng = np.random.default_rng(2)
    names = [f"long class name {k}" for k in range(12)]
    fig = confusion_figure(rng.integers(0, 50, (12, 12)), names)
    renderer = _draw(fig)
    ax, bar = fig.axes
    assert bar.get_ylabel() == "share of the true class"
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("predicted class", "true class")
    labels = [*ax.get_xticklabels(), *ax.get_yticklabels(), ax.xaxis.label, ax.yaxis.label]
    for t in labels + list(fig.texts):
        e = t.get_window_extent(renderer)
        assert e.x0 >= -1 and e.y0 >= -1, t.get_text()
        assert e.x1 <= fig.bbox.x1 + 1 and e.y1 <= fig.bbox.y1 + 1, t.get_text()
    assert [t.get_text() for t in ax.get_xticklabels()] == names
    fig = confusion_figure(np.zeros((2, 2)), ["a", "b"])
    assert "no samples" in [t.get_text() for t in fig.axes[0].texts]
    _check_picture(confusion_picture(np.eye(3), ["a", "b", "c"]), confusion_figure(
        np.eye(3), ["a", "b", "c"]).canvas.get_width_height()[::-1])  # fmt: skip


def test_readable_dpi_hand_computed():
    assert readable_dpi(1920, 1080) == 100.0  # fits the screen
    assert readable_dpi(3840, 1080) == 200.0  # shown at half size: text twice as large
    assert readable_dpi(320, 1000) == 50.0  # half the comfortable width
    assert readable_dpi(10, 10) == pytest.approx(30.0)  # the floor
    assert curves_picture(_roc(1), title="", xlabel="", ylabel="", width=100, height=90).shape == (
        90, 100, 3,
    )  # fmt: skip
