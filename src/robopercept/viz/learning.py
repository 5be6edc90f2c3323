"""Pictures of learning results: scatter plots of labelled points, confusion matrices,
ROC and precision-recall curves (matplotlib, Agg: :mod:`robopercept.viz.plot`'s rules),
and grids of small images (filters, feature maps).

Each plot has a ``*_figure`` function returning the :class:`matplotlib.figure.Figure` (to
inspect or save as a vector file) and a ``*_picture`` function returning its ``(H, W, 3)``
uint8 pixels. Class ``k`` (the k-th of the sorted distinct labels) takes the colour
``label_colors(k + 1)`` (:func:`~robopercept.viz.colormap.label_colors`,
golden-ratio hues), as in :mod:`robopercept.viz.cloud_dl`; noise (label -1) is grey;
curve ``k`` takes matplotlib's ``tab10`` colour ``k mod 10``.
Legends list the classes in their order, outside the data, all entries inside the
picture (:func:`~robopercept.viz.plot.outside_legend`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from robopercept._checks import (
    check_bool,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_numeric,
    check_points,
    check_real,
    check_text,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import check_picture_size
from robopercept.viz.figure import agg_figure, figure_to_rgb, readable_dpi
from robopercept.viz.plot import (
    FONT_PT,
    MIN_PANEL_HEIGHT,
    MIN_WIDTH,
    add_note,
    outside_legend,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "confusion_figure",
    "confusion_picture",
    "curves_figure",
    "curves_picture",
    "precision_recall_picture",
    "scatter_figure",
    "scatter_picture",
    "tiles_picture",
]

_NOISE = (150, 150, 150)
# the colour of a full cell of the confusion matrix (an empty one is white)
_FULL = (8, 48, 107)
_LINESTYLES = ("-", "--", "-.", ":")


def _colors(n: int) -> list[tuple[float, float, float]]:
    # distinct hues; label_colors maps 0 to background, so start at 1
    return [tuple(float(v) / 255.0 for v in c) for c in label_colors(np.arange(1, n + 1))]  # type: ignore[misc]


def _line_colors(n: int) -> list[tuple[float, float, float]]:
    """Colours of ``n`` curves: matplotlib's ``tab10`` cycled (ten colours that stay apart
    as thin lines on white; darkened golden-ratio hues made classes 1 and 9 the same olive
    in a 10-class ROC); from the 11th curve on the line style tells them apart."""
    from matplotlib import colormaps

    tab = colormaps["tab10"].colors  # type: ignore[attr-defined]  # a ListedColormap
    return [tuple(float(v) for v in tab[k % len(tab)][:3]) for k in range(n)]  # type: ignore[misc]


def _plot_size(width: Any, height: Any) -> tuple[int, int]:
    """``(width, height)`` of a one-panel plot: integers of at least 100 x 90 pixels."""
    w = check_int(width, "width", MIN_WIDTH)
    h = check_int(height, "height", MIN_PANEL_HEIGHT + 30)
    return check_picture_size(w, h, "plot")


def _names(names: Any, count: int, what: str) -> list[str]:
    """``names`` as ``count`` strings (``str()`` of each item: numbers are fine)."""
    if isinstance(names, (str, bytes)) or not isinstance(names, (Sequence, np.ndarray)):
        raise InputError(f"names must be a sequence of {what} names; got {plain_repr(names)}")
    if len(names) != count:
        raise InputError(f"{count} {what}s but {len(names)} names")
    return [str(n) for n in names]


def _labelled_axes(fig: Any, title: str, xlabel: str, ylabel: str) -> Any:
    ax = fig.add_subplot()
    ax.tick_params(labelsize=FONT_PT["tick"])
    ax.xaxis.get_offset_text().set_fontsize(FONT_PT["tick"])
    ax.yaxis.get_offset_text().set_fontsize(FONT_PT["tick"])
    ax.grid(True, color="#e0e0e0", linewidth=0.8)
    ax.set_axisbelow(True)
    if title:
        ax.set_title(title, fontsize=FONT_PT["title"])
    if xlabel:
        ax.set_xlabel(xlabel, fontsize=FONT_PT["label"])
    if ylabel:
        ax.set_ylabel(ylabel, fontsize=FONT_PT["label"])
    return ax


# ----------------------------------------------------------------------------- scatter


def scatter_figure(
    points: np.ndarray,
    labels: np.ndarray | None = None,
    *,
    title: str = "",
    xlabel: str = "PC1",
    ylabel: str = "PC2",
    names: Sequence[str] | np.ndarray | None = None,
    width: int = 800,
    height: int = 600,
) -> Figure:
    """The matplotlib figure of :func:`scatter_picture` (same parameters).

    Examples
    --------
    >>> fig = scatter_figure(np.eye(2), np.array([0, 1]), names=["a", "b"])
    >>> ax = fig.axes[0]
    >>> ax.get_xlabel(), [t.get_text() for t in ax.get_legend().get_texts()]
    ('PC1', ['a (1)', 'b (1)'])
    """
    pts = check_magnitude(check_points(points, "points", 2), "points", 1e300)
    title, xlabel = check_text(title, "title"), check_text(xlabel, "xlabel")
    ylabel = check_text(ylabel, "ylabel")
    width, height = _plot_size(width, height)
    lab = np.zeros(len(pts), dtype=int) if labels is None else np.asarray(labels)
    if lab.shape != (len(pts),):
        raise InputError(f"labels must have one value per point; got {lab.shape}")
    if lab.dtype == object:
        raise InputError("labels must be numbers or strings, one per point; got objects")
    values = np.unique(lab)
    if names is not None:
        names = _names(names, values.size, "label")
    colors = _colors(values.size)
    dpi = readable_dpi(width, height, comfortable=(640, 480))
    fig = agg_figure(width, height, layout="constrained", what="scatter_picture", dpi=dpi)
    ax = _labelled_axes(fig, title, xlabel, ylabel)
    area = float(np.clip(3000.0 / max(len(pts), 1), 6.0, 40.0))  # marker area, points^2
    entries: list[tuple[Any, str]] = []
    noise_entry: list[tuple[Any, str]] = []
    for k, v in enumerate(values):
        sel = lab == v
        noise = np.issubdtype(values.dtype, np.integer) and v == -1
        name = "noise" if noise else (str(names[k]) if names is not None else str(v))
        color = tuple(c / 255.0 for c in _NOISE) if noise else colors[k]
        handle = ax.scatter(
            pts[sel, 0], pts[sel, 1], s=area, color=color, linewidths=0, clip_on=False
        )
        (noise_entry if noise else entries).append((handle, f"{name} ({int(sel.sum())})"))
    entries += noise_entry  # noise is not a class: it ends the legend
    ax.margins(0.05)
    if not len(pts):
        add_note(ax, "no points")
    if labels is not None and entries:
        outside_legend(ax, [h for h, _ in entries], [t for _, t in entries])
    return fig


def scatter_picture(
    points: np.ndarray,
    labels: np.ndarray | None = None,
    *,
    title: str = "",
    xlabel: str = "PC1",
    ylabel: str = "PC2",
    names: Sequence[str] | np.ndarray | None = None,
    width: int = 800,
    height: int = 600,
) -> np.ndarray:
    """2-D points as dots, one colour per label (noise, label -1, in grey), with a
    legend of the labels (and their counts) right of the plot.

    The axes reach 5% beyond the points on each side, so no dot is cut by the frame.
    The marker area is ``clip(3000 / N, 6, 40)`` points^2.

    Parameters
    ----------
    points : (N, 2) ndarray
        Values up to 1e300 in magnitude; N = 0 gives the note "no points".
    labels : (N,) ndarray, optional
        Any values; each distinct value gets a colour and a legend entry, in sorted
        order (noise last). Without labels there is no legend.
    title : str
    xlabel, ylabel : str
        Axis names: the default names the first two principal components (what
        ``robopercept reduce`` draws); pass ``"LD1"``/``"LD2"`` or the feature names
        (with units) for other axes, ``""`` for none.
    names : sequence of str, optional
        Legend names for the sorted distinct labels (default: the labels themselves).
    width, height : int
        Picture size, at least 100 x 90 pixels (default 800 x 600, at 100 dpi: 12 pt
        text is 16.7 pixels high).

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        Points not (N, 2) or too large, labels not one per point, names of the wrong
        count, non-string texts or a bad size.

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(30, 2))
    >>> scatter_picture(pts, np.arange(30) % 3, width=400, height=300).shape
    (300, 400, 3)
    """
    fig = scatter_figure(
        points,
        labels,
        title=title,
        xlabel=xlabel,
        ylabel=ylabel,
        names=names,
        width=width,
        height=height,
    )
    return figure_to_rgb(fig, quiet_layout=True)


# ----------------------------------------------------------------------------- curves


def _check_curves(curves: Any) -> list[tuple[np.ndarray, np.ndarray, str]]:
    if not isinstance(curves, (list, tuple)) or not curves:
        raise InputError("curves_picture needs at least one curve: a list of (x, y, label)")
    out = []
    for k, curve in enumerate(curves):
        if not isinstance(curve, (tuple, list)) or len(curve) != 3:
            raise InputError(f"curves[{k}] must be (x, y, label); got {plain_repr(curve)}")
        x, y, label = curve
        arrays = []
        for axis, values in (("x", x), ("y", y)):
            v = np.asarray(values) if isinstance(values, np.ndarray) else None
            if v is None:
                try:
                    v = np.asarray(values, dtype=np.float64)
                except (TypeError, ValueError):
                    raise InputError(
                        f"curves[{k}]: {axis} must be a 1-D array of numbers; got "
                        f"{plain_repr(values)}"
                    ) from None
            if v.ndim != 1 or v.dtype.kind not in "biuf":
                raise InputError(
                    f"curves[{k}]: {axis} must be a 1-D array of numbers; got shape {v.shape} "
                    f"dtype {v.dtype}"
                )
            check_magnitude(v, f"curves[{k}]: {axis}", 1e300)
            arrays.append(v.astype(np.float64))
        if arrays[0].shape != arrays[1].shape:
            raise InputError(
                f"curves[{k}]: x and y must have one length; got {arrays[0].size} and "
                f"{arrays[1].size}"
            )
        out.append((arrays[0], arrays[1], check_text(label, "label")))
    return out


def curves_figure(
    curves: Sequence[tuple[np.ndarray, np.ndarray, str]],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    width: int = 700,
    height: int = 560,
) -> Figure:
    """The matplotlib figure of :func:`curves_picture` (same parameters).

    Examples
    --------
    >>> x = np.linspace(0, 1, 5)
    >>> fig = curves_figure([(x, x, "chance")], title="ROC", xlabel="FPR", ylabel="TPR")
    >>> [float(v) for v in fig.axes[0].get_xlim()]
    [-0.02, 1.02]
    """
    checked = _check_curves(curves)
    title, xlabel = check_text(title, "title"), check_text(xlabel, "xlabel")
    ylabel = check_text(ylabel, "ylabel")
    width, height = _plot_size(width, height)
    colors = _line_colors(len(checked))
    dpi = readable_dpi(width, height, comfortable=(640, 480))
    fig = agg_figure(width, height, layout="constrained", what="curves_picture", dpi=dpi)
    ax = _labelled_axes(fig, title, xlabel, ylabel)
    handles = []
    finite: list[np.ndarray] = []
    for k, (x, y, label) in enumerate(checked):
        style = _LINESTYLES[(k // 10) % len(_LINESTYLES)]  # 10 hues, then dashes
        (h,) = ax.plot(x, y, style, color=colors[k], linewidth=2, label=label)
        handles.append(h)
        ok = np.isfinite(x) & np.isfinite(y)
        finite += [x[ok], y[ok]]
    values = np.concatenate(finite)
    if not values.size:
        add_note(ax, "no data")
    elif values.min() >= 0.0 and values.max() <= 1.0:  # rates: the whole unit square
        ax.set_xlim(-0.02, 1.02)
        ax.set_ylim(-0.02, 1.02)
    outside_legend(ax, handles, [label for _, _, label in checked])
    return fig


def curves_picture(
    curves: Sequence[tuple[np.ndarray, np.ndarray, str]],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    width: int = 700,
    height: int = 560,
) -> np.ndarray:
    """Curves ``(x, y, label)`` in one panel (ROC: FPR vs TPR; PR: recall vs precision),
    with a legend right of the plot in the order of ``curves``.

    Curve ``k`` has matplotlib's ``tab10`` colour ``k mod 10`` and, from the 11th curve on, a
    dashed (then dash-dotted, dotted) line. When every value lies in [0, 1] (rates) the
    axes show the whole unit square. With many curves the legend takes several columns
    and smaller type so every entry stays inside the picture
    (:func:`~robopercept.viz.plot.outside_legend`).

    Parameters
    ----------
    curves : sequence of (x, y, label)
        ``x`` and ``y`` 1-D real arrays of one length (up to 1e300 in magnitude; NaN
        breaks a line), ``label`` a string. Curves without a finite point give the note
        "no data".
    title, xlabel, ylabel : str
        Name the axes with their units (``"false positive rate"``, ``"recall"``).
    width, height : int
        Picture size, at least 100 x 90 pixels (default 700 x 560, at 100 dpi: 12 pt
        text is 16.7 pixels high).

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        No curve, a curve that is not ``(x, y, label)`` or whose arrays differ in
        length, non-string texts or a bad size.

    Examples
    --------
    >>> x = np.linspace(0, 1, 5)
    >>> curves_picture([(x, x**2, "a")], title="ROC", xlabel="FPR", ylabel="TPR",
    ...                width=400, height=300).shape
    (300, 400, 3)
    """
    fig = curves_figure(
        curves, title=title, xlabel=xlabel, ylabel=ylabel, width=width, height=height
    )
    return figure_to_rgb(fig, quiet_layout=True)


def precision_recall_picture(
    recall: Any,
    precision: Any,
    labels: Sequence[str],
    *,
    iou_threshold: float,
    width: int = 1600,
    height: int = 1000,
) -> np.ndarray:
    r"""Per-class precision-recall curves at one IoU threshold, as an RGB picture
    (:func:`curves_picture`; 1600 x 1000 reads well on a 1080p screen).

    Class ``k``'s curve is ``precision[k]`` against ``recall``, labelled
    ``"labels[k] (AP a)"`` with :math:`a` the mean of ``precision[k]`` (COCO's AP when
    ``recall`` is its 101 recall points). A row whose every value is negative (COCO's -1:
    a class without ground truth) is left out. The title names the IoU threshold.

    Parameters
    ----------
    recall : (R,) array_like
        The recall points (x).
    precision : (K, R) array_like
        Each class's precision at the recall points; negative where undefined.
    labels : sequence of K str
        The classes' names (``str()`` of each item).
    iou_threshold : float
        The IoU threshold of the curves (for the title).
    width, height : int
        Picture size (see :func:`curves_picture`).

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        ``recall`` not 1-D, ``precision`` not ``(K, R)``, labels not ``K`` names, a
        non-finite value, or no class with a precision >= 0 (nothing to draw).

    Examples
    --------
    >>> r = np.linspace(0, 1, 101)
    >>> p = np.stack([1 - r**2, -np.ones(101)])  # the second class has no ground truth
    >>> precision_recall_picture(r, p, ["cat", "dog"], iou_threshold=0.5,
    ...                          width=400, height=300).shape
    (300, 400, 3)
    """
    rec = check_numeric(recall, "recall")
    prec = check_numeric(precision, "precision")
    if rec.ndim != 1 or prec.ndim != 2 or prec.shape[1] != rec.size:
        raise InputError(
            f"recall must be (R,) and precision (K, R), one row per class; got shapes "
            f"{rec.shape} and {prec.shape}"
        )
    for name, values in (("recall", rec), ("precision", prec)):
        check_finite(values, name)
        check_magnitude(values, name, 1e300)
    k = prec.shape[0]
    if (
        isinstance(labels, (str, bytes))
        or not isinstance(labels, (Sequence, np.ndarray))
        or len(labels) != k
    ):
        raise InputError(
            f"labels must be {k} class names, one per row of precision; got {plain_repr(labels)}"
        )
    names = [str(n) for n in labels]
    thr = check_real(iou_threshold, "iou_threshold")
    curves = []
    for p, label in zip(prec, names, strict=True):
        if (p < 0).all():
            continue
        curves.append((rec, p, f"{label} (AP {float(p.mean()):.3f})"))
    if not curves:
        raise InputError("no category has ground truth: there is no PR curve to draw")
    return curves_picture(
        curves,
        title=f"precision-recall per class, IoU {thr:.2f}",
        xlabel="recall",
        ylabel="precision",
        width=width,
        height=height,
    )


# ----------------------------------------------------------------------------- confusion


def _check_confusion(matrix: Any) -> np.ndarray:
    cm = np.asarray(matrix) if isinstance(matrix, np.ndarray) else None
    if cm is None:
        try:
            cm = np.asarray(matrix, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(
                f"matrix must be a (k, k) array of counts; got {plain_repr(matrix)}"
            ) from None
    if cm.ndim != 2 or cm.shape[0] != cm.shape[1] or cm.shape[0] == 0:
        raise InputError(f"matrix must be (k, k) with k >= 1; got shape {cm.shape}")
    if cm.dtype.kind not in "biuf" or not np.isfinite(cm).all() or (cm < 0).any():
        raise InputError("matrix must hold finite, non-negative counts")
    return cm


def _text_width(fig: Any, renderer: Any, texts: Sequence[str], size: float) -> float:
    """The widest of ``texts`` at ``size`` points, in pixels."""
    widest = 0.0
    for t in texts:
        art = fig.text(0, 0, t, fontsize=size)
        widest = max(widest, art.get_window_extent(renderer).width)
        art.remove()
    return widest


def confusion_figure(
    matrix: np.ndarray,
    names: Sequence[str],
    *,
    title: str = "confusion matrix",
    cell: int = 0,
) -> Figure:
    """The matplotlib figure of :func:`confusion_picture` (same parameters).

    Returns
    -------
    matplotlib.figure.Figure
        ``fig.axes[0]`` the matrix, ``fig.axes[1]`` the colour bar.

    Examples
    --------
    >>> fig = confusion_figure(np.array([[3, 1], [0, 4]]), ["cat", "dog"])
    >>> fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()
    ('predicted class', 'true class')
    """
    from matplotlib.colors import LinearSegmentedColormap

    cm = _check_confusion(matrix)
    k = cm.shape[0]
    names = _names(names, k, "class")
    title = check_text(title, "title")
    cell = check_int(cell, "cell", 0)
    cell = cell or int(np.clip(480 // max(k, 1), 28, 90))
    check_picture_size(k * cell + 200, k * cell + 120, "confusion picture")
    cm = check_magnitude(cm, "matrix", 1e300).astype(np.float64)
    tick = FONT_PT["tick"]
    count_pt = float(min(tick, 0.3 * cell))  # counts fit their cell
    # measure the labels first (at 100 dpi, 1 pt = 100 / 72 px), then place the
    # matrix in whole pixels: a margin for the names and axis labels, the colour bar right
    probe = agg_figure(100, 100, what="confusion_picture")
    renderer = probe.canvas.get_renderer()  # type: ignore[attr-defined]  # Agg canvas
    name_w = _text_width(probe, renderer, names, tick)
    title_w = _text_width(probe, renderer, [title], FONT_PT["title"]) if title else 0.0
    line = 1.4 * FONT_PT["label"] * 100 / 72  # the height of an axis label, px
    rotate = name_w > cell - 4
    left = int(max(80, np.ceil(name_w + 10 + line + 12)))
    top = 60
    bottom = int(np.ceil((name_w if rotate else tick * 1.4 * 100 / 72) + 10 + line + 14))
    right = 130
    side = k * cell
    width = int(max(left + side + right, np.ceil(title_w) + 20))
    height = top + side + bottom
    width, height = check_picture_size(width, height, "confusion picture")
    fig = agg_figure(width, height, what="confusion_picture")
    ax = fig.add_axes((left / width, bottom / height, side / width, side / height))
    rows = cm.sum(axis=1, keepdims=True)
    share = np.divide(cm, rows, out=np.zeros(cm.shape), where=rows > 0)
    blues = LinearSegmentedColormap.from_list(
        "share", [(1.0, 1.0, 1.0), tuple(c / 255.0 for c in _FULL)]
    )
    image = ax.imshow(share, cmap=blues, vmin=0.0, vmax=1.0, interpolation="nearest", aspect="auto")
    ax.set_xticks(range(k), names, rotation=90 if rotate else 0, fontsize=tick)
    ax.set_yticks(range(k), names, fontsize=tick)
    ax.set_xticks(np.arange(k + 1) - 0.5, minor=True)
    ax.set_yticks(np.arange(k + 1) - 0.5, minor=True)
    ax.grid(which="minor", color=(200 / 255,) * 3, linewidth=1)
    ax.tick_params(which="minor", length=0)
    ax.set_xlabel("predicted class", fontsize=FONT_PT["label"])
    ax.set_ylabel("true class", fontsize=FONT_PT["label"])
    if title:
        fig.text(10 / width, 1 - 8 / height, title, fontsize=FONT_PT["title"], va="top")
    for i in range(k):
        for j in range(k):
            ax.text(
                j,
                i,
                str(int(cm[i, j])),
                ha="center",
                va="center",
                fontsize=count_pt,
                color="white" if share[i, j] > 0.5 else "black",
            )
    cax = fig.add_axes(((left + side + 16) / width, bottom / height, 18 / width, side / height))
    bar = fig.colorbar(image, cax=cax)
    bar.ax.tick_params(labelsize=tick)
    # the label runs along the bar: a short one beside a small matrix
    bar.set_label("share of the true class" if side >= 200 else "share", fontsize=FONT_PT["label"])
    if rows.sum() == 0:
        add_note(ax, "no samples")
    return fig


def confusion_picture(
    matrix: np.ndarray, names: Sequence[str], *, title: str = "confusion matrix", cell: int = 0
) -> np.ndarray:
    """The confusion matrix as a grid: rows true classes, columns predictions, each cell
    shaded by its share of the row (white 0, dark blue 1, with a colour bar) and
    labelled with its count.

    The matrix is placed in whole pixels: its top-left corner at ``(left, 60)`` with
    ``left = max(80, the widest name + the axis label)``, each cell ``cell`` pixels
    square, the colour bar right of it; column names are turned upright when wider than
    a cell. Text is 12 pt at 100 dpi (16.7 pixels; counts smaller in cells under 40 px).
    An all-zero matrix gets the note "no samples".

    Parameters
    ----------
    matrix : (k, k) array_like
        Non-negative counts.
    names : sequence of str
        The k class names.
    title : str
    cell : int
        Cell side in pixels; 0 picks one from k (28 to 90).

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Raises
    ------
    InputError
        A matrix that is not square, empty, negative or not finite; names of the wrong
        count; a picture over 2**26 pixels.

    Examples
    --------
    >>> pic = confusion_picture(np.array([[9, 1], [0, 5]]), ["a", "b"], cell=50)
    >>> pic.shape[2], pic[60 + 55, 80 + 5].tolist()  # the empty cell (1, 0) is white
    (3, [255, 255, 255])
    """
    fig = confusion_figure(matrix, names, title=title, cell=cell)
    return figure_to_rgb(fig, quiet_layout=True)


def tiles_picture(
    tiles: np.ndarray,
    *,
    signed: bool = False,
    columns: int | None = None,
    tile_px: int = 96,
    gap: int = 6,
    names: Sequence[str] | None = None,
) -> np.ndarray:
    """A grid of small images, each enlarged (nearest neighbour) to ``tile_px`` pixels:
    a network's first-layer filters or its feature maps, readable at 1080p.

    Parameters
    ----------
    tiles : (K, H, W) or (K, 3, H, W) ndarray
        K single-channel tiles, or K colour filters (RGB).
    signed : bool
        Diverging colours (negative blue, zero white, positive red; one scale for all
        tiles, :func:`~robopercept.viz.colormap.colorize_signed`), for weights;
        otherwise each tile is stretched to its own min..max in gray, for activations.
    columns : int, optional
        Tiles per row (default about sqrt(K)).
    tile_px : int
        Side of an enlarged tile.
    gap : int
        White pixels between tiles.
    names : sequence of str, optional
        A caption under each tile.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    from robopercept.viz.colormap import colorize_signed
    from robopercept.viz.draw import draw_text

    t = check_ndim(tiles, "tiles", (3, 4))
    if t.dtype.kind not in "biuf":
        raise InputError(f"tiles must be real numbers; got dtype {t.dtype}")
    t = check_finite(t.astype(np.float64), "tiles")
    if t.ndim == 4 and t.shape[1] == 3:
        t = np.moveaxis(t, 1, -1)
    elif t.ndim != 3:
        raise InputError(f"tiles must be (K, H, W) or (K, 3, H, W); got {t.shape}")
    k = t.shape[0]
    if t.size == 0:
        raise InputError(f"no tiles to draw: tiles has shape {t.shape}")
    signed = check_bool(signed, "signed")
    cols = int(np.ceil(np.sqrt(k))) if columns is None else check_int(columns, "columns", 1)
    tile_px = check_int(tile_px, "tile_px", 1)
    gap = check_int(gap, "gap", 0)
    if names is not None:
        names = _names(names, k, "tile")
    # values near 1e308 would overflow the percentile and min..max stretches below
    t = t / max(float(np.abs(t).max()), 1e-300) if np.abs(t).max() > 1e300 else t
    rows = int(np.ceil(k / cols))
    cap = 18 if names is not None else 0
    h, w = t.shape[1], t.shape[2]
    scale = max(1, tile_px // max(h, w))
    th, tw = h * scale, w * scale
    check_picture_size(cols * (tw + gap) + gap, rows * (th + gap + cap) + gap, "tiles picture")
    out = np.full((rows * (th + gap + cap) + gap, cols * (tw + gap) + gap, 3), 255, np.uint8)
    limit = float(np.percentile(np.abs(t), 99)) or 1.0
    for i in range(k):
        tile = t[i]
        if tile.ndim == 3:  # colour filter: one scale, centred at grey
            rgb = np.clip(127.5 + 127.5 * tile / limit, 0, 255).astype(np.uint8)
        elif signed:
            rgb = colorize_signed(tile, limit)
        else:
            lo, hi = float(tile.min()), float(tile.max())
            g = np.zeros_like(tile) if hi <= lo else (tile - lo) / (hi - lo)
            rgb = np.repeat((255 * g).astype(np.uint8)[..., None], 3, axis=2)
        big = np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1)
        r, c = divmod(i, cols)
        y, x = gap + r * (th + gap + cap), gap + c * (tw + gap)
        out[y : y + th, x : x + tw] = big
    for i, name in enumerate(names or []):  # captions last: draw_text returns a new image
        r, c = divmod(i, cols)
        y, x = gap + r * (th + gap + cap), gap + c * (tw + gap)
        out = draw_text(out, str(name), (x, y + th + 2), color=(0, 0, 0), size=13, background=None)
    return np.ascontiguousarray(out)
