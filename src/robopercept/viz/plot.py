"""Plots as RGB images, drawn with matplotlib on its Agg canvas (no display needed).

Two kinds of plot live here, each as a ``*_figure`` function that returns the
:class:`matplotlib.figure.Figure` (to inspect its artists, or save as a vector file) and a
``*_picture`` / :func:`plot_series` function that rasterizes it to an ``(H, W, 3)``
uint8 array (:func:`~robopercept.viz.figure.figure_to_rgb`):

* :func:`series_figure` / :func:`plot_series`: curves against a shared x axis, one
  panel per quantity (a grid of ``columns`` panels). Values that are NaN break a line,
  which is how gaps (frames without a detection) show; an isolated finite value between
  gaps is drawn as a dot so it does not vanish.
* :func:`scalar_map_figure` / :func:`scalar_map_picture`: a 2-D array of scalars (a
  disparity or depth map, a cost volume slice) as an image with a colour bar, NaN and
  infinite values in a colour of their own.

Every plot follows the same rules, so pictures read well on a 1920 x 1080 screen:
axis labels on every axes (units in brackets, ``d [m]``); fonts of 12 pt (ticks, legend)
to 15 pt (titles) at the resolution :func:`~robopercept.viz.figure.readable_dpi` picks
(100 dpi for pictures up to 1920 x 1080: 12 pt is 16.7 pixels); legends outside the data
(:func:`outside_legend`: to the right of the axes, or above all panels when they share
their entries), in the order the series were given, all entries inside the picture (in
several columns and smaller type when there are many); integer ticks on an x axis of
integers (frames, epochs: ``MaxNLocator(integer=True)``); a grey note ("no data") in
any axes that has nothing to show. The layout is matplotlib's constrained layout, which
keeps titles, labels, legends and colour bars inside the picture.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from robopercept._checks import (
    check_choice,
    check_int,
    check_magnitude,
    check_ndim,
    check_real,
    check_text,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.viz.draw import check_color, check_picture_size
from robopercept.viz.figure import agg_figure, figure_to_rgb, readable_dpi

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.legend import Legend

__all__ = [
    "FONT_PT",
    "MAX_LEGEND_ENTRIES",
    "MIN_PANEL_HEIGHT",
    "MIN_WIDTH",
    "Panel",
    "Series",
    "add_note",
    "disparity_picture",
    "outside_legend",
    "plot_series",
    "scalar_map_figure",
    "scalar_map_picture",
    "series_figure",
]

#: the smallest plot width and panel height in pixels
MIN_WIDTH, MIN_PANEL_HEIGHT = 100, 60
#: font sizes in points: ticks and legends, axis labels, axes titles, figure titles, notes
FONT_PT = {"tick": 12.0, "label": 13.0, "title": 14.0, "suptitle": 15.0, "note": 16.0}
#: a legend lists at most this many entries; more end with a "... and k more" line
MAX_LEGEND_ENTRIES = 40
#: the largest magnitude of a plotted value: differences of values beyond it overflow
_MAX_VALUE = 1e300
_NOTE_COLOR = "#555555"


@dataclass
class Series:
    """One curve: ``y`` against ``x``, drawn as a line or as dots; ``color`` is RGB
    0..255."""

    x: np.ndarray
    y: np.ndarray
    label: str
    color: tuple[int, int, int] = (31, 119, 180)
    style: str = "line"  # "line" or "dots"


@dataclass
class Panel:
    """One plot area with a title, a y-axis label (with its unit) and its series."""

    title: str
    series: list[Series] = field(default_factory=list)
    ylabel: str = ""


# ----------------------------------------------------------------------------- helpers


def _rgb(color: Sequence[int]) -> tuple[float, float, float]:
    return (color[0] / 255.0, color[1] / 255.0, color[2] / 255.0)


def add_note(ax: Axes, text: str) -> None:
    """Write ``text`` (e.g. "no data", "nothing detected") in grey in the middle of
    ``ax``, on a white box, so an empty plot says why it is empty.

    Examples
    --------
    >>> from robopercept.viz.figure import agg_figure
    >>> ax = agg_figure(300, 200).add_subplot()
    >>> add_note(ax, "no data")
    >>> ax.texts[0].get_text()
    'no data'
    """
    from matplotlib.axes import Axes

    if not isinstance(ax, Axes):
        raise InputError(f"ax must be a matplotlib Axes; got {plain_repr(ax)}")
    ax.text(
        0.5,
        0.5,
        check_text(text, "text"),
        transform=ax.transAxes,
        ha="center",
        va="center",
        fontsize=FONT_PT["note"],
        color=_NOTE_COLOR,
        bbox={"boxstyle": "round,pad=0.4", "facecolor": "white", "edgecolor": "#bbbbbb"},
    )


def outside_legend(
    host: Any,
    handles: Sequence[Any],
    labels: Sequence[str],
    *,
    where: Literal["right", "top", "bottom"] = "right",
    max_height: float = 0.9,
    max_width: float = 0.45,
) -> Legend | None:
    """A legend outside the data: beside ``host`` (an Axes) or outside all axes (a
    Figure, with constrained layout), its entries in the order given, sized to fit.

    An Axes gets its legend to the right of the data (``where="right"``, upper left
    corner at ``(1.02, 1)`` in axes coordinates) or below it (``"bottom"``); a Figure
    gets it above the panels (``"top"``, one row), below them (``"bottom"``) or to the
    right (``"right"``). The legend starts in one column at 12 pt; while it is taller
    than ``max_height`` times the picture's height it takes one more column, and while
    it is wider than ``max_width`` times the picture's width (for ``"right"``) or than
    the picture (otherwise), its type shrinks by 1 pt (down to 6 pt). More than
    :data:`MAX_LEGEND_ENTRIES` entries are cut to the first ``MAX_LEGEND_ENTRIES - 1``
    and a line "... and k more".

    Parameters
    ----------
    host : matplotlib Axes or Figure
    handles : sequence of artists
    labels : sequence of str
        One per handle.
    where : {"right", "top", "bottom"}
    max_height, max_width : float
        Fractions of the picture's height and width, in (0, 1].

    Returns
    -------
    matplotlib.legend.Legend or None
        None when there are no entries.

    Examples
    --------
    >>> from robopercept.viz.figure import agg_figure
    >>> fig = agg_figure(600, 400, layout="constrained")
    >>> ax = fig.add_subplot()
    >>> lines = [ax.plot([0, 1], [k, k])[0] for k in range(3)]
    >>> leg = outside_legend(ax, lines, ["a", "b", "c"])
    >>> [t.get_text() for t in leg.get_texts()]
    ['a', 'b', 'c']
    """
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure, SubFigure
    from matplotlib.patches import Patch

    if not isinstance(host, (Axes, Figure, SubFigure)):
        raise InputError(f"host must be a matplotlib Axes or Figure; got {plain_repr(host)}")
    where = check_choice(where, "where", ("right", "top", "bottom"))
    max_height = check_real(max_height, "max_height", 0.0, 1.0, low_inclusive=False)
    max_width = check_real(max_width, "max_width", 0.0, 1.0, low_inclusive=False)
    handles, labels = list(handles), [check_text(t, "a legend label") for t in labels]
    if len(handles) != len(labels):
        raise InputError(f"{len(handles)} legend handles but {len(labels)} labels")
    if not handles:
        return None
    if len(handles) > MAX_LEGEND_ENTRIES:
        more = len(handles) - (MAX_LEGEND_ENTRIES - 1)
        handles = [*handles[: MAX_LEGEND_ENTRIES - 1], Patch(visible=False)]
        labels = [*labels[: MAX_LEGEND_ENTRIES - 1], f"... and {more} more"]
    fig = host
    while not isinstance(fig, Figure):  # an Axes or SubFigure: up to the root figure
        fig = fig.figure
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]  # Agg canvas
    fig_w, fig_h = fig.bbox.width, fig.bbox.height
    if isinstance(host, Axes):
        kw: dict[str, Any] = (
            {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0), "borderaxespad": 0.0}
            if where == "right"
            else {"loc": "upper center", "bbox_to_anchor": (0.5, -0.12), "borderaxespad": 0.0}
        )
    else:
        kw = {
            "loc": {"right": "outside right upper", "top": "outside upper center"}.get(
                where, "outside lower center"
            )
        }
    n = len(handles)
    width_limit = (max_width if where == "right" else 0.98) * fig_w
    size, ncol = FONT_PT["tick"], 1 if where == "right" else n
    legend = None
    for _ in range(80):
        if legend is not None:
            legend.remove()
        legend = host.legend(handles, labels, fontsize=size, ncols=ncol, **kw)
        box = legend.get_window_extent(renderer)
        if box.height > max_height * fig_h and ncol < n:
            ncol += 1
        elif box.width > width_limit and size > 6.0:
            size -= 1.0
            if where != "right":
                ncol = n
        elif box.width > width_limit and ncol > 1 and where != "right":
            ncol = max(1, ncol // 2)  # 6 pt and still too wide: more rows
        else:
            break
    return legend


def _finite_values(arrays: Sequence[np.ndarray]) -> np.ndarray:
    vals = [a[np.isfinite(a)] for a in arrays]
    return np.concatenate(vals) if vals else np.zeros(0)


def _integral(x: np.ndarray) -> bool:
    return bool(x.size) and bool(np.all(x == np.round(x)))


def _style_axes(ax: Axes) -> None:
    ax.tick_params(labelsize=FONT_PT["tick"])
    ax.xaxis.get_offset_text().set_fontsize(FONT_PT["tick"])
    ax.yaxis.get_offset_text().set_fontsize(FONT_PT["tick"])
    ax.grid(True, color="#e0e0e0", linewidth=0.8)
    ax.set_axisbelow(True)


def _check_panels(panels: Any) -> list[Panel]:
    if not isinstance(panels, (list, tuple)) or not panels:
        raise InputError("plot_series needs at least one panel (a list of Panel)")
    for panel in panels:
        if not isinstance(panel, Panel):
            raise InputError(f"panels must be Panel objects; got {type(panel).__name__}")
        check_text(panel.title, "title")
        check_text(panel.ylabel, "ylabel")
        if not isinstance(panel.series, (list, tuple)):
            raise InputError(f"a panel's series must be a list of Series; got {panel.series!r}")
        for s in panel.series:
            if not isinstance(s, Series):
                raise InputError(f"a panel's series must be Series; got {type(s).__name__}")
            check_text(s.label, "a curve's label")
            check_color(s.color, "a curve's color")
            check_choice(s.style, "a curve's style", ("line", "dots"))
            shapes = []
            for axis, values in (("x", s.x), ("y", s.y)):
                v = np.asarray(values)
                if v.dtype.kind not in "biuf":
                    raise InputError(
                        f"series {s.label!r}: {axis} must be real numbers; got dtype {v.dtype}"
                    )
                check_magnitude(v, f"series {s.label!r}: {axis}", _MAX_VALUE)
                shapes.append(v.shape)
            if shapes[0] != shapes[1] or len(shapes[0]) > 1:
                raise InputError(
                    f"series {s.label!r}: x and y must be 1-D of one length; got shapes "
                    f"{shapes[0]} and {shapes[1]}"
                )
    return list(panels)


# ----------------------------------------------------------------------------- series


def series_figure(
    panels: Sequence[Panel],
    *,
    width: int = 1000,
    panel_height: int = 220,
    xlabel: str = "",
    title: str = "",
    columns: int = 1,
    integer_x: bool | None = None,
    legend: Literal["auto", "panel", "figure", "none"] = "auto",
    empty_note: str = "no data",
) -> Figure:
    """The matplotlib figure of :func:`plot_series` (same parameters), for inspection.

    Returns
    -------
    matplotlib.figure.Figure
        ``width`` x ``panel_height * rows + 30`` pixels, its axes in ``fig.axes`` in
        panel order (row by row).

    Examples
    --------
    >>> x = np.arange(5.0)
    >>> fig = series_figure([Panel("y", [Series(x, x**2, "x^2")], "y [m]")], xlabel="frame")
    >>> ax = fig.axes[0]
    >>> ax.get_xlabel(), ax.get_ylabel(), [t.get_text() for t in ax.get_legend().get_texts()]
    ('frame', 'y [m]', ['x^2'])
    """
    from matplotlib.ticker import MaxNLocator

    panels = _check_panels(panels)
    xlabel, title = check_text(xlabel, "xlabel"), check_text(title, "title")
    empty_note = check_text(empty_note, "empty_note")
    width = check_int(width, "width", MIN_WIDTH)
    panel_height = check_int(panel_height, "height of a panel", MIN_PANEL_HEIGHT)
    columns = check_int(columns, "columns", 1)
    if integer_x is not None and not isinstance(integer_x, (bool, np.bool_)):
        raise InputError(f"integer_x must be True, False or None; got {plain_repr(integer_x)}")
    legend = check_choice(legend, "legend", ("auto", "panel", "figure", "none"))
    columns = min(columns, len(panels))
    rows = math.ceil(len(panels) / columns)
    height = panel_height * rows + 30
    check_picture_size(width, height, "plot")
    dpi = readable_dpi(width, height, comfortable=(500 * columns, 150 * rows + 30))
    fig = agg_figure(width, height, layout="constrained", what="plot_series", dpi=dpi)
    grid = fig.subplots(rows, columns, sharex=True, squeeze=False)
    axes = list(grid.ravel())
    for ax in axes[len(panels) :]:
        ax.remove()
    all_x = _finite_values([np.asarray(s.x, np.float64).ravel() for p in panels for s in p.series])
    if integer_x is None:
        integer_x = _integral(all_x)
    if all_x.size:  # the x axis spans every x given, with or without a finite y
        lo, hi = float(all_x.min()), float(all_x.max())
        if hi <= lo:
            d = max(0.5, abs(lo) * 1e-9)
            lo, hi = lo - d, hi + d
        pad = 0.02 * (hi - lo)
        axes[0].set_xlim(lo - pad, hi + pad)
    label_lists = [[s.label for s in p.series] for p in panels]
    if legend == "auto":
        shared = len(panels) > 1 and all(labels == label_lists[0] for labels in label_lists)
        legend = "figure" if shared else "panel"
    fig_handles: list[Any] = []
    for k, (panel, ax) in enumerate(zip(panels, axes, strict=False)):
        _style_axes(ax)
        handles = []
        finite = 0
        for s in panel.series:
            x = np.asarray(s.x, np.float64).ravel()
            y = np.asarray(s.y, np.float64).ravel()
            ok = np.isfinite(x) & np.isfinite(y)
            finite += int(ok.sum())
            color = _rgb(s.color)
            if s.style == "dots":
                (h,) = ax.plot(x[ok], y[ok], "o", color=color, markersize=4, label=s.label)
            else:
                (h,) = ax.plot(x, y, "-", color=color, linewidth=2, label=s.label)
                prev = np.r_[False, ok[:-1]]
                nxt = np.r_[ok[1:], False]
                alone = ok & ~prev & ~nxt
                if alone.any():
                    ax.plot(x[alone], y[alone], "o", color=color, markersize=4)
            handles.append(h)
        if panel.title:
            ax.set_title(panel.title, fontsize=FONT_PT["title"])
        if panel.ylabel:
            ax.set_ylabel(panel.ylabel, fontsize=FONT_PT["label"])
        if k + columns >= len(panels) and xlabel:
            ax.set_xlabel(xlabel, fontsize=FONT_PT["label"])
            ax.tick_params(labelbottom=True)
        if finite == 0:
            add_note(ax, empty_note)
            ax.set_yticks([])
        if integer_x:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        if legend == "panel" and handles:
            outside_legend(ax, handles, [s.label for s in panel.series], max_height=0.9 / rows)
        if k == 0:
            fig_handles = handles
    if legend == "figure" and fig_handles:
        outside_legend(fig, fig_handles, label_lists[0], where="top")
    if title:
        fig.suptitle(title, fontsize=FONT_PT["suptitle"])
    return fig


def plot_series(
    panels: Sequence[Panel],
    *,
    width: int = 1000,
    panel_height: int = 220,
    xlabel: str = "",
    title: str = "",
    columns: int = 1,
    integer_x: bool | None = None,
    legend: Literal["auto", "panel", "figure", "none"] = "auto",
    empty_note: str = "no data",
) -> np.ndarray:
    """Render ``panels`` in a grid (``columns`` wide, filled row by row) sharing one x
    axis, and return the ``(H, W, 3)`` uint8 image.

    Parameters
    ----------
    panels : sequence of Panel
        At least one; titles, y labels and series labels are strings; values beyond
        1e300 in magnitude are refused (their differences overflow).
    width : int
        At least :data:`MIN_WIDTH` (100) pixels.
    panel_height : int
        Height of a row of panels, at least :data:`MIN_PANEL_HEIGHT` (60) pixels.
    xlabel : str
        Under the bottom panel of each column, with its unit (``"frame"``,
        ``"time [s]"``).
    title : str
        Above all panels.
    columns : int
        Panels per row.
    integer_x : bool, optional
        Integer ticks on the x axis (``MaxNLocator(integer=True)``: frames, epochs);
        default when every finite x value is an integer.
    legend : {"auto", "panel", "figure", "none"}
        One legend per panel, right of its axes; or one for the figure, above the
        panels (the first panel's entries); ``"auto"`` picks ``"figure"`` when there
        are several panels whose series have the same labels in the same order.
    empty_note : str
        Written in any panel with no finite point.

    Returns
    -------
    (panel_height * rows + 30, width, 3) uint8 ndarray
        ``rows = ceil(len(panels) / columns)``; drawn at
        :func:`~robopercept.viz.figure.readable_dpi`.

    Raises
    ------
    InputError
        No panel, a bad size, a series whose x and y differ in shape, non-numeric or
        too large values, or non-string texts.

    Examples
    --------
    >>> x = np.arange(10.0)
    >>> p = Panel("distance", [Series(x, np.sqrt(x), "sqrt")], "d [m]")
    >>> plot_series([p], width=400, panel_height=200, xlabel="frame").shape
    (230, 400, 3)
    """
    fig = series_figure(
        panels,
        width=width,
        panel_height=panel_height,
        xlabel=xlabel,
        title=title,
        columns=columns,
        integer_x=integer_x,
        legend=legend,
        empty_note=empty_note,
    )
    return figure_to_rgb(fig, quiet_layout=True)


# ----------------------------------------------------------------------------- scalar maps

# candidate colours for values that are not finite: the one farthest from every colour
# of the colour map is used (white, black, grey, magenta, red, green, cyan)
_NAN_CANDIDATES = np.array(
    [
        [255, 255, 255],
        [0, 0, 0],
        [128, 128, 128],
        [255, 0, 255],
        [255, 0, 0],
        [0, 200, 0],
        [0, 255, 255],
    ],
    dtype=np.float64,
)


def _nan_color(cmap: Any) -> tuple[int, int, int]:
    table = cmap(np.linspace(0.0, 1.0, 256))[:, :3] * 255.0
    dist = np.linalg.norm(_NAN_CANDIDATES[:, None, :] - table[None, :, :], axis=2).min(axis=1)
    return tuple(int(v) for v in _NAN_CANDIDATES[int(np.argmax(dist))])  # type: ignore[return-value]


def scalar_map_figure(
    values: np.ndarray,
    *,
    cmap: str = "viridis",
    label: str = "value",
    title: str = "",
    nan_color: tuple[int, int, int] | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
    xlabel: str = "x [px]",
    ylabel: str = "y [px]",
    width: int | None = None,
    height: int | None = None,
) -> Figure:
    """The matplotlib figure of :func:`scalar_map_picture` (same parameters).

    Returns
    -------
    matplotlib.figure.Figure
        ``fig.axes[0]`` holds the image, ``fig.axes[1]`` the colour bar.

    Examples
    --------
    >>> fig = scalar_map_figure(np.arange(12.0).reshape(3, 4), label="disparity [px]")
    >>> fig.axes[1].get_ylabel()
    'disparity [px]'
    """
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    v = check_ndim(values, "values", (2,))
    if v.dtype.kind not in "biuf":
        raise InputError(f"values must be real numbers; got dtype {v.dtype}")
    if v.size == 0:
        raise InputError(f"values must be a non-empty (H, W) array; got shape {v.shape}")
    v = v.astype(np.float64)
    cmap_name = check_text(cmap, "cmap")
    if cmap_name not in colormaps:
        raise InputError(
            f"cmap must be a matplotlib colour map name (viridis, magma, gray, turbo, ...); "
            f"got {cmap_name!r}"
        )
    label, title = check_text(label, "label"), check_text(title, "title")
    xlabel, ylabel = check_text(xlabel, "xlabel"), check_text(ylabel, "ylabel")
    if height is None:
        height = 900
    height = check_int(height, "height", MIN_PANEL_HEIGHT + 30)
    if width is None:  # the map's aspect at the height, and room for labels and colour bar
        width = int(np.clip(round((height - 100) * v.shape[1] / v.shape[0]) + 300, 640, 1920))
    width, height = check_picture_size(check_int(width, "width", MIN_WIDTH), height)
    base = colormaps[cmap_name]
    nan_rgb = _nan_color(base) if nan_color is None else check_color(nan_color, "nan_color")
    cm = base.with_extremes(bad=_rgb(nan_rgb))
    finite = np.isfinite(v)
    good = v[finite]
    check_magnitude(good, "values", _MAX_VALUE)
    lo = float(good.min()) if good.size else 0.0
    hi = float(good.max()) if good.size else 1.0
    lo = lo if vmin is None else check_real(vmin, "vmin", -_MAX_VALUE, _MAX_VALUE)
    hi = hi if vmax is None else check_real(vmax, "vmax", -_MAX_VALUE, _MAX_VALUE)
    if hi < lo:
        raise InputError(f"vmin must be <= vmax; got vmin={lo}, vmax={hi}")
    if hi == lo:  # a constant map: a range of positive width around it
        d = max(0.5, abs(lo) * 1e-9)
        lo, hi = lo - d, hi + d
    below, above = bool((good < lo).any()), bool((good > hi).any())
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max"}.get(
        (below, above), "both"
    )
    dpi = readable_dpi(width, height, comfortable=(640, 400))
    fig = agg_figure(width, height, layout="constrained", what="scalar_map_picture", dpi=dpi)
    ax = fig.add_subplot()
    image = ax.imshow(
        np.ma.masked_invalid(v), cmap=cm, norm=Normalize(lo, hi), interpolation="antialiased"
    )
    ax.tick_params(labelsize=FONT_PT["tick"])
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(MaxNLocator(integer=True))
    if xlabel:
        ax.set_xlabel(xlabel, fontsize=FONT_PT["label"])
    if ylabel:
        ax.set_ylabel(ylabel, fontsize=FONT_PT["label"])
    if title:
        ax.set_title(title, fontsize=FONT_PT["title"])
    bar = fig.colorbar(image, ax=ax, extend=extend, fraction=0.05, pad=0.02)
    bar.ax.tick_params(labelsize=FONT_PT["tick"])
    bar.ax.yaxis.get_offset_text().set_fontsize(FONT_PT["tick"])
    if label:
        bar.set_label(label, fontsize=FONT_PT["label"])
    bad = int(v.size - good.size)
    if bad:
        share = 100.0 * bad / v.size
        patch = Patch(facecolor=_rgb(nan_rgb), edgecolor="#444444")
        outside_legend(
            fig, [patch], [f"no value (NaN/inf): {share:.1f}% of pixels"], where="bottom"
        )
    if not good.size:
        add_note(ax, "no finite value")
    return fig


def scalar_map_picture(
    values: np.ndarray,
    *,
    cmap: str = "viridis",
    label: str = "value",
    title: str = "",
    nan_color: tuple[int, int, int] | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
    xlabel: str = "x [px]",
    ylabel: str = "y [px]",
    width: int | None = None,
    height: int | None = None,
) -> np.ndarray:
    """A 2-D array of scalars (a disparity, depth or cost map) drawn as an image with a
    colour bar, as an ``(height, width, 3)`` uint8 picture.

    Value ``v`` takes the colour ``cmap((clip(v, vmin, vmax) - vmin) / (vmax - vmin))``
    (matplotlib's ``Normalize``); the colour bar shows that scale, with arrows at an end
    where values were clipped (``extend``). Pixel ``(x, y)`` (column, row; origin the
    centre of the top-left pixel, y down, as images) is drawn at ``(x, y)`` with the
    axes in pixels and integer ticks; the map keeps its aspect ratio (square pixels).
    Values that are NaN or infinite (a disparity rejected by the left-right check,
    depth with no return) are drawn in ``nan_color``, and a legend under the map says
    which share of the pixels they are. A map with no finite value is drawn all in
    ``nan_color`` with the note "no finite value".

    Parameters
    ----------
    values : (H, W) array_like
        Real numbers; NaN and +-inf mark pixels without a value.
    cmap : str
        A matplotlib colour map name (``"viridis"``, ``"magma"``, ``"turbo"``,
        ``"gray"``, ...).
    label : str
        The colour bar's label, with the unit: ``"disparity [px]"``, ``"depth [m]"``.
    title : str
    nan_color : (3,) ints, optional
        RGB 0..255 of pixels without a value; default the colour among white, black,
        grey, magenta, red, green and cyan farthest from every colour of ``cmap``
        (magenta for viridis, gray and turbo).
    vmin, vmax : float, optional
        The ends of the colour scale; default the finite minimum and maximum (a constant
        map gets ``v -+ 0.5``).
    xlabel, ylabel : str
        Axis labels (default pixel columns and rows).
    width, height : int, optional
        Picture size in pixels; default height 900 and the width that fits the map's
        aspect ratio beside its labels and colour bar, ``clip((height - 100) W / H +
        300, 640, 1920)`` (1367 for a 4:3 map). Up to 1920 x 1080 the picture is drawn at
        100 dpi (12 pt text is 16.7 pixels high).

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        ``values`` not 2-D real numbers or empty, an unknown colour map, ``vmin >
        vmax``, a bad colour or size, or values beyond 1e300 in magnitude.

    Examples
    --------
    >>> disparity = np.tile(np.arange(8.0), (6, 1))
    >>> disparity[0, 0] = np.nan  # rejected by the left-right check
    >>> pic = scalar_map_picture(disparity, label="disparity [px]", width=400, height=300)
    >>> pic.shape, pic.dtype
    ((300, 400, 3), dtype('uint8'))
    """
    fig = scalar_map_figure(
        values,
        cmap=cmap,
        label=label,
        title=title,
        nan_color=nan_color,
        vmin=vmin,
        vmax=vmax,
        xlabel=xlabel,
        ylabel=ylabel,
        width=width,
        height=height,
    )
    return figure_to_rgb(fig, quiet_layout=True)


def disparity_picture(
    disparity: np.ndarray,
    *,
    method: str = "sgm",
    min_disparity: float = 0.0,
    max_disparity: float | None = None,
    lr_check: float | None = 1.0,
) -> np.ndarray:
    """A disparity map coloured with Turbo (near: red, far: blue) with its colour bar,
    as ``robopercept stereo`` and ``robopercept batch stereo`` write it.

    :func:`scalar_map_picture` of the map on the scale ``[min_disparity,
    max_disparity]`` (the search range), 1280 pixels wide and ``clip(0.82 * 1280 H / W
    + 90, 360, 1080)`` high; pixels rejected by the left-right check (NaN) are drawn
    apart, their share under the map. The title names the method and the check.

    Parameters
    ----------
    disparity : (H, W) float ndarray
        Disparities in pixels; NaN where rejected.
    method : str
        The matcher's name for the title (``"sgm"``, ``"bm"``).
    min_disparity, max_disparity : float
        The search range (the colour scale); ``max_disparity`` defaults to the largest
        finite disparity.
    lr_check : float or None
        The left-right check's tolerance in pixels, for the title (None: off).

    Returns
    -------
    (height, 1280, 3) uint8 ndarray

    Raises
    ------
    InputError
        From :func:`scalar_map_picture`: not a 2-D real map, ``min_disparity >
        max_disparity``.

    Examples
    --------
    >>> d = np.tile(np.linspace(0.0, 16.0, 40), (30, 1))
    >>> d[:, :3] = np.nan  # no match: left-right check
    >>> disparity_picture(d, max_disparity=16).shape
    (877, 1280, 3)
    """
    arr = np.asarray(disparity)
    if arr.ndim != 2:
        raise InputError(f"disparity must be an (H, W) map; got shape {arr.shape}")
    h, w = arr.shape
    width = 1280
    height = int(np.clip(0.82 * width * h / max(w, 1) + 90, 360, 1080))
    lo = check_real(min_disparity, "min_disparity")
    hi = None if max_disparity is None else check_real(max_disparity, "max_disparity")
    lr = None if lr_check is None else check_real(lr_check, "lr_check")
    check = "off" if lr is None else f"{lr:g} px"
    return scalar_map_picture(
        arr,
        cmap="turbo",
        label="disparity [px] (near: high)",
        title=f"{method} disparity, left-right check {check}",
        vmin=lo,
        vmax=hi,
        width=width,
        height=height,
    )
