r"""Pictures for deep learning on point clouds: a cloud coloured by labels or values, a
grid of clouds (one shape per class, or test predictions), PointNet's critical point set
and DGCNN's neighbourhoods in feature space (matplotlib 3-D scatters, Agg).

This module takes NumPy arrays (points, integer labels, neighbour indices), never torch
tensors: ``viz`` sits below ``nn``. A network's outputs go through ``.numpy()`` first.

Every panel shows the cloud in a cube: the limits are
:math:`c_a \pm h` on each axis :math:`a`, with :math:`c` the centre of the bounding box
of the finite points and :math:`h = 1.05 \max_a (\max p_a - \min p_a) / 2`, and the
three axes have the same length on screen (``set_box_aspect((1, 1, 1))``), so a sphere
looks round. The viewpoint is matplotlib's ``view_init(elev, azim)``, given here in
radians (the API's unit): elevation above the x-y plane, azimuth about z; the default
(20 deg, -60 deg) is matplotlib's own isometric-ish view, the same as
:data:`robopercept.viz.pose.DEFAULT_VIEWS`.

Points with a NaN or inf coordinate are left out of the drawing (and counted in the
titles as "n not finite"); a cloud with no finite point gives a picture with an
"empty cloud" note in each panel rather than an error. Clouds of more than
:data:`MAX_DRAWN` points are thinned for drawing (every ``ceil(N / MAX_DRAWN)``-th
point of the background cloud; highlighted points are all drawn).

Label colours are :func:`~robopercept.viz.colormap.label_colors` of ``label + 1``
(golden-ratio hues, distinct for any number of classes; label ``c`` has the colour of
class ``c`` in :func:`~robopercept.viz.learning.scatter_picture`), negative labels
(unlabelled) grey. Sizes follow the picture: each function has a reference size (its
default ``size``) at which a figure is 100 dpi and text is 12 to 16 pt; another size
scales everything with it (:func:`~robopercept.viz.figure.agg_figure`).

The confusion matrix of a classifier is :func:`robopercept.viz.learning.confusion_picture`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from robopercept._checks import (
    check_int,
    check_magnitude,
    check_ndim,
    check_points,
    check_real,
    check_reals,
    check_size,
    check_text,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import check_picture_size
from robopercept.viz.figure import agg_figure, check_views, figure_to_rgb

__all__ = [
    "DEFAULT_AZIM",
    "DEFAULT_ELEV",
    "MAX_DRAWN",
    "cloud_picture",
    "clouds_grid",
    "critical_points_picture",
    "feature_neighbours_picture",
]

#: matplotlib's default elevation, 20 degrees, in radians
DEFAULT_ELEV = math.radians(20.0)
#: matplotlib's default azimuth, -60 degrees, in radians
DEFAULT_AZIM = math.radians(-60.0)
#: the most points of a background cloud drawn in one panel (more are thinned)
MAX_DRAWN = 20_000
#: the most panels of :func:`clouds_grid` (matplotlib draws 3-D axes one by one)
MAX_PANELS = 100
#: the most query points of :func:`feature_neighbours_picture`
MAX_QUERIES = 20
#: the most legend entries of :func:`cloud_picture`
MAX_LEGEND = 60

_TITLE_PT = 14.0
_TEXT_PT = 12.0
_SUPTITLE_PT = 16.0
_GREY = (0.55, 0.55, 0.55)
_LIGHT = (0.78, 0.78, 0.78)
_FAINT = (0.86, 0.86, 0.86)
_UNLABELLED = (160, 160, 160)
_NOTE_COLOR = "#b22222"


# ----------------------------------------------------------------------------- checks


def _cloud(points: Any, name: str = "points") -> np.ndarray:
    """``points`` as float64 (N, 3), NaN/inf rows kept (left out of the drawing)."""
    p = check_points(points, name, 3)
    check_magnitude(np.where(np.isfinite(p), p, 0.0), name, 1e9)
    return p


def _size(size: Any) -> tuple[int, int]:
    w, h = check_size(size, "size", 150, 4000, 12_000_000)
    return check_picture_size(w, h, "picture")


def _angles(elev: Any, azim: Any, name: str = "") -> tuple[float, float]:
    """(elevation, azimuth) in radians to degrees for matplotlib."""
    e = check_real(elev, f"{name}elev", -math.pi, math.pi)
    a = check_real(azim, f"{name}azim", -2 * math.pi, 2 * math.pi)
    return math.degrees(e), math.degrees(a)


def _int_array(value: Any, name: str, count: int | None, what: str) -> np.ndarray:
    """A 1-D integer array (``count`` long when given) as int64."""
    if isinstance(value, (list, tuple)) and len(value) == 0:
        arr = np.zeros(0, np.int64)
    else:
        arr = check_ndim(value, name, (1,))
    if arr.dtype.kind == "b":
        raise InputError(
            f"{name} must be integer {what}; got booleans: use np.flatnonzero({name}) "
            "for the indices of a mask"
        )
    if arr.size and arr.dtype.kind not in "iu":
        raise InputError(f"{name} must be integer {what}; got dtype {arr.dtype}")
    if count is not None and arr.shape[0] != count:
        raise InputError(f"{name} must have one entry per point ({count}); got {arr.shape[0]}")
    if arr.size and (arr.max() > 2**31 or arr.min() < -(2**31)):
        raise InputError(f"{name} must stay within +-2**31; got {plain_repr(arr.max())}")
    return arr.astype(np.int64)


def _indices(value: Any, name: str, n: int, what: str = "point indices") -> np.ndarray:
    """Indices into a cloud of ``n`` points: integers in 0..n-1."""
    idx = _int_array(value, name, None, what)
    _in_range(idx, name, n)
    return idx


def _in_range(idx: np.ndarray, name: str, n: int) -> None:
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        bad = idx[(idx < 0) | (idx >= n)][0]
        raise InputError(
            f"{name} must be point indices in 0..{n - 1} (the cloud has {n} points); got {int(bad)}"
        )


def _texts(value: Any, count: int, name: str, what: str) -> list[str]:
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise InputError(f"{name} must be a sequence of {what}; got {plain_repr(value)}")
    if len(value) != count:
        raise InputError(f"{name} must hold {count} {what}; got {len(value)}")
    return [check_text(t, f"{name}[{i}]") for i, t in enumerate(value)]


def _color(value: Any, name: str) -> Any:
    """A matplotlib colour from a name (``"red"``, ``"#d62728"``) or RGB in 0..255."""
    from matplotlib.colors import is_color_like

    if value is None:
        return "black"
    if isinstance(value, str):
        if not is_color_like(value):
            raise InputError(f"{name} must be a colour name like 'red' or '#d62728'; got {value!r}")
        return value
    try:
        rgb = check_reals(value, name, 3, 0.0, 255.0)
    except InputError:
        raise InputError(
            f"{name} must be a colour name like 'red', an RGB triple in 0..255 or None; "
            f"got {plain_repr(value)}"
        ) from None
    return tuple(float(c) / 255.0 for c in rgb)


# ----------------------------------------------------------------------------- drawing


def _label_rgb(labels: np.ndarray) -> np.ndarray:
    """(N,) labels to (N, 3) floats in [0, 1]: label_colors(label + 1), negatives grey."""
    return label_colors(np.maximum(labels, -1) + 1, background=_UNLABELLED) / 255.0


def _box(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half side of the cube around the finite points."""
    ok = points[np.isfinite(points).all(axis=1)]
    if len(ok) == 0:
        return np.zeros(3), 1.0
    lo, hi = ok.min(axis=0), ok.max(axis=0)
    mid = (lo + hi) / 2
    half = float((hi - lo).max()) / 2 * 1.05
    return mid, max(half, 1e-6 * max(1.0, float(np.abs(mid).max())), 1e-9)


def _axes(
    fig: Any,
    grid: Any,
    box: tuple[np.ndarray, float],
    view: tuple[float, float],
    *,
    ticks: bool,
    letters: bool = True,
) -> Any:
    """A 3-D axes: the cube ``box``, equal aspect, the view, labelled axes."""
    if isinstance(grid, tuple):  # (rows, columns, index)
        ax = fig.add_subplot(*grid, projection="3d")
    else:  # a SubplotSpec
        ax = fig.add_subplot(grid, projection="3d")
    mid, half = box
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.0 if ticks else 1.15)
    ax.view_init(elev=view[0], azim=view[1])
    if letters:
        for setter, letter in ((ax.set_xlabel, "x"), (ax.set_ylabel, "y"), (ax.set_zlabel, "z")):
            setter(letter, fontsize=_TEXT_PT, labelpad=-8 if not ticks else 4)
    if ticks:
        ax.tick_params(labelsize=_TEXT_PT)
    else:
        ax.set_xticklabels([])
        ax.set_yticklabels([])
        ax.set_zticklabels([])
    return ax


def _thin(idx: np.ndarray) -> np.ndarray:
    step = -(-len(idx) // MAX_DRAWN)
    return idx[::step] if step > 1 else idx


def _scatter(ax: Any, points: np.ndarray, color: Any, size: float, **kw: Any) -> None:
    """Scatter the finite rows of ``points`` (``color`` one colour or (N, 3) rows)."""
    ok = np.isfinite(points).all(axis=1)
    if not ok.any():
        return
    if isinstance(color, np.ndarray) and color.ndim == 2:
        color = color[ok]
    kw.setdefault("linewidths", 0)
    ax.scatter(*points[ok].T, color=color, s=size, depthshade=False, **kw)


def _note(ax: Any, text: str) -> None:
    ax.text2D(
        0.5,
        0.5,
        text,
        transform=ax.transAxes,
        ha="center",
        va="center",
        fontsize=_SUPTITLE_PT,
        color=_NOTE_COLOR,
    )


def _marker_size(n: int) -> float:
    """Marker area in points^2 for a cloud of n points: about 8 for 1024 points."""
    return float(np.clip(8000.0 / max(n, 1), 3.0, 40.0))


def _count(p: np.ndarray) -> str:
    finite = int(np.isfinite(p).all(axis=1).sum())
    text = f"{len(p)} points"
    return text if finite == len(p) else f"{text} ({len(p) - finite} not finite)"


def _render(fig: Any, title: str) -> np.ndarray:
    if title:
        fig.suptitle(title, fontsize=_SUPTITLE_PT)
    with warnings.catch_warnings():
        # a very flat or very narrow size leaves the layout no room: drawn as it falls
        warnings.filterwarnings("ignore", message=".*[Ll]ayout not applied.*")
        warnings.filterwarnings("ignore", message=".*axes sizes collapsed.*")
        return figure_to_rgb(fig)


def _figure(size: tuple[int, int], reference: int, what: str) -> Any:
    fig = agg_figure(size[0], size[1], reference_width=reference, layout="constrained", what=what)
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers "3d")

    return fig


# ----------------------------------------------------------------------------- pictures


def cloud_picture(
    points: np.ndarray,
    *,
    labels: np.ndarray | None = None,
    values: np.ndarray | None = None,
    names: Sequence[str] | None = None,
    title: str = "",
    views: Sequence[tuple[float, float]] = ((DEFAULT_ELEV, DEFAULT_AZIM),),
    size: tuple[int, int] = (1600, 900),
) -> np.ndarray:
    """One point cloud as a 3-D scatter, coloured by integer labels (with a legend) or
    by scalar values (with a colour bar), one panel per viewpoint.

    Labels take the categorical colours ``label_colors(label + 1)`` (negative labels,
    unlabelled, grey); the legend outside the panels lists the labels present, named
    ``names[label]`` (or the numbers, for at most :data:`MAX_LEGEND` labels, when no
    names are given). Values map linearly through viridis from their finite minimum
    to their maximum (points whose value is NaN are grey). Without either, points are
    coloured by their height ``z``. The marker area is ``clip(8000 / N, 3, 40)``
    points^2.

    Parameters
    ----------
    points : (N, 3) array_like
        The cloud; NaN/inf rows are left out.
    labels : (N,) int array_like, optional
        A class per point (part segmentation, or a cloud's class repeated).
    values : (N,) float array_like, optional
        A scalar per point (a score, a distance); not with ``labels``.
    names : sequence of str, optional
        The label names, ``names[c]`` for label ``c`` (needs ``labels``).
    title : str
        Above the panels.
    views : sequence of (elevation, azimuth)
        One panel per view, 1 to 6, in radians (matplotlib's ``view_init``).
    size : (int, int)
        ``(width, height)`` in pixels, each side 150 to 4000.

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        Points not (N, 3) or beyond 1e9, labels or values of another length, labels
        not integers, values inf, both labels and values, names without labels or too
        few for the labels, bad views, title or size, or matplotlib missing.

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(50, 3))
    >>> pic = cloud_picture(pts, labels=np.arange(50) % 2, names=["a", "b"], size=(400, 240))
    >>> pic.shape, pic.dtype
    ((240, 400, 3), dtype('uint8'))
    """
    p = _cloud(points)
    n = len(p)
    title = check_text(title, "title")
    if labels is not None and values is not None:
        raise InputError("give labels or values, not both (one colouring per picture)")
    lab = None if labels is None else _int_array(labels, "labels", n, "class labels")
    val = None
    if values is not None:
        val = check_ndim(values, "values", (1,))
        if val.dtype.kind not in "biuf":
            raise InputError(f"values must be real numbers; got dtype {val.dtype}")
        val = val.astype(np.float64)
        if val.shape[0] != n:
            raise InputError(f"values must have one entry per point ({n}); got {val.shape[0]}")
        if np.isinf(val).any():
            raise InputError("values must be finite (NaN: a point drawn grey); got inf")
        check_magnitude(np.nan_to_num(val), "values", 1e150)
    if names is not None and lab is None:
        raise InputError("names name the labels: pass labels=... with them")
    top = int(lab.max()) + 1 if lab is not None and lab.size and lab.max() >= 0 else 0
    label_names = None
    if names is not None:
        if isinstance(names, (str, bytes)) or not isinstance(names, (Sequence, np.ndarray)):
            raise InputError(f"names must be a sequence of label names; got {plain_repr(names)}")
        if len(names) < top:
            raise InputError(
                f"names must name every label: labels go up to {top - 1} but {len(names)} "
                "names came"
            )
        label_names = [check_text(t, f"names[{i}]") for i, t in enumerate(names)]
    angles = check_views(views)
    width, height = _size(size)

    fig = _figure((width, height), 1600, "cloud_picture")
    box = _box(p)
    finite = np.isfinite(p).all(axis=1)
    draw = _thin(np.flatnonzero(finite))
    marker = _marker_size(len(draw))
    color: Any
    mappable = None
    if lab is not None:
        color = _label_rgb(lab[draw])
    elif val is not None:
        from matplotlib import colormaps
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize

        good = val[finite & np.isfinite(val)]
        lo, hi = (float(good.min()), float(good.max())) if good.size else (0.0, 1.0)
        if hi <= lo:
            lo, hi = lo - 0.5, hi + 0.5
        mappable = ScalarMappable(Normalize(lo, hi), colormaps["viridis"])
        v = val[draw]
        color = np.tile(np.array(_GREY), (len(draw), 1))
        ok = np.isfinite(v)
        color[ok] = mappable.to_rgba(v[ok])[:, :3]
    else:
        from matplotlib import colormaps
        from matplotlib.colors import Normalize

        z = p[draw, 2]
        zf = z[np.isfinite(z)]
        lo, hi = (float(zf.min()), float(zf.max())) if zf.size else (0.0, 1.0)
        norm = Normalize(lo, hi if hi > lo else lo + 1.0)
        color = colormaps["viridis"](norm(np.nan_to_num(z)))[:, :3]
    cells = len(angles) + (mappable is not None)
    ratios = [1.0] * len(angles) + ([0.04] if mappable is not None else [])
    gs = fig.add_gridspec(1, cells, width_ratios=ratios)
    for k, (elev, azim) in enumerate(angles):
        ax = _axes(fig, gs[0, k], box, (elev, azim), ticks=True)
        if finite.any():
            _scatter(ax, p[draw], color, marker)
        else:
            _note(ax, "empty cloud" if n == 0 else f"empty cloud ({n} points, none finite)")
        ax.set_title(f"{_count(p)}, elevation {elev:.0f}°, azimuth {azim:.0f}°", fontsize=_TITLE_PT)
    if lab is not None and finite.any():
        present = np.unique(lab[finite])
        shown = present[present >= 0]
        if label_names is not None or len(shown) <= MAX_LEGEND:
            _legend(fig, shown[:MAX_LEGEND], label_names, bool((present < 0).any()))
    if mappable is not None:
        # the bar in its own narrow column, 70 % of the height
        cax = fig.add_subplot(gs[0, -1].subgridspec(3, 1, height_ratios=[0.15, 0.7, 0.15])[1])
        bar = fig.colorbar(mappable, cax=cax)
        bar.ax.tick_params(labelsize=_TEXT_PT)
    return _render(fig, title)


def _legend(fig: Any, shown: np.ndarray, names: list[str] | None, unlabelled: bool) -> None:
    from matplotlib.lines import Line2D

    rgb = _label_rgb(shown)
    handles = [
        Line2D(
            [],
            [],
            marker="o",
            linestyle="",
            markersize=11,
            color=tuple(rgb[i]),
            label=names[c] if names is not None else str(c),
        )
        for i, c in enumerate(shown.tolist())
    ]
    if unlabelled:
        handles.append(
            Line2D(
                [],
                [],
                marker="o",
                linestyle="",
                markersize=11,
                color=tuple(np.array(_UNLABELLED) / 255.0),
                label="unlabelled",
            )
        )
    if handles:
        fig.legend(
            handles=handles,
            loc="outside right upper",
            fontsize=_TEXT_PT,
            ncols=1 + (len(handles) - 1) // 20,
            frameon=False,
        )


def clouds_grid(
    clouds: Sequence[np.ndarray],
    titles: Sequence[str],
    labels: Sequence[np.ndarray | None] | None = None,
    *,
    title_colors: Sequence[Any] | None = None,
    columns: int = 5,
    title: str = "",
    elev: float = DEFAULT_ELEV,
    azim: float = DEFAULT_AZIM,
    size: tuple[int, int] = (1800, 1000),
) -> np.ndarray:
    """A grid of small 3-D scatters, one cloud per panel, each with its title: one shape
    per class, or test clouds titled "true / predicted" (the wrong ones in red).

    Each panel has its own cube (its cloud fills it) and the same viewpoint; tick
    numbers are left out (they would crowd small panels). A cloud with labels takes
    the label colours of :func:`cloud_picture`; one without is coloured by its height
    ``z`` (viridis). An empty cloud's panel says "empty cloud".

    Parameters
    ----------
    clouds : sequence of (N_i, 3) array_like
        1 to :data:`MAX_PANELS` clouds (their sizes may differ).
    titles : sequence of str
        One per cloud.
    labels : sequence of (N_i,) int array_like or None, optional
        Labels per point of each cloud (an entry None: that cloud by height).
    title_colors : sequence, optional
        One per cloud: a matplotlib colour name (``"red"``, ``"#d62728"``), an RGB
        triple in 0..255, or None (black).
    columns : int
        Panels per row (at least 1; fewer when there are fewer clouds).
    title : str
        Above the grid.
    elev, azim : float
        The viewpoint in radians.
    size : (int, int)
        ``(width, height)`` in pixels, each side 150 to 4000.

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        No clouds or more than :data:`MAX_PANELS`, a cloud not (N, 3) or beyond 1e9,
        titles, labels or title colours of another count, labels of another length
        than their cloud, bad colours, columns, view or size, or matplotlib missing.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> pic = clouds_grid([rng.normal(size=(30, 3)) for _ in range(3)], ["a", "b", "c"],
    ...                   title_colors=[None, "red", (0, 128, 0)], size=(450, 200))
    >>> pic.shape
    (200, 450, 3)
    """
    if isinstance(clouds, np.ndarray) and clouds.ndim == 3:
        clouds = list(clouds)
    if isinstance(clouds, (str, bytes)) or not isinstance(clouds, Sequence):
        raise InputError(f"clouds must be a list of (N, 3) arrays; got {plain_repr(clouds)}")
    count = len(clouds)
    if not 1 <= count <= MAX_PANELS:
        raise InputError(f"clouds must hold 1 to {MAX_PANELS} clouds; got {count}")
    pts = [_cloud(c, f"clouds[{i}]") for i, c in enumerate(clouds)]
    heads = _texts(titles, count, "titles", "titles (one per cloud)")
    labs: list[np.ndarray | None] = [None] * count
    if labels is not None:
        if isinstance(labels, np.ndarray) and labels.ndim == 2:
            labels = list(labels)
        if isinstance(labels, (str, bytes)) or not isinstance(labels, Sequence):
            raise InputError(f"labels must be a list of (N,) arrays; got {plain_repr(labels)}")
        if len(labels) != count:
            raise InputError(f"labels must hold one array per cloud ({count}); got {len(labels)}")
        labs = [
            None if lb is None else _int_array(lb, f"labels[{i}]", len(pts[i]), "class labels")
            for i, lb in enumerate(labels)
        ]
    colors: list[Any] = ["black"] * count
    if title_colors is not None:
        if isinstance(title_colors, (str, bytes)) or not isinstance(title_colors, Sequence):
            raise InputError(
                f"title_colors must be a list, one colour per cloud; got {plain_repr(title_colors)}"
            )
        if len(title_colors) != count:
            raise InputError(
                f"title_colors must hold one colour per cloud ({count}); got {len(title_colors)}"
            )
        colors = [_color(c, f"title_colors[{i}]") for i, c in enumerate(title_colors)]
    cols = check_int(columns, "columns", 1)
    cols = min(cols, count)
    rows = -(-count // cols)
    title = check_text(title, "title")
    view = _angles(elev, azim)
    width, height = _size(size)

    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    fig = _figure((width, height), 1800, "clouds_grid")
    for i, (p, head) in enumerate(zip(pts, heads, strict=True)):
        ax = _axes(fig, (rows, cols, i + 1), _box(p), view, ticks=False, letters=False)
        finite = np.isfinite(p).all(axis=1)
        draw = _thin(np.flatnonzero(finite))
        lab = labs[i]
        if not finite.any():
            _note(ax, "empty cloud")
        elif lab is not None:
            _scatter(ax, p[draw], _label_rgb(lab[draw]), _marker_size(len(draw)) / 2)
        else:
            z = p[draw, 2]
            zf = z[np.isfinite(z)]
            norm = Normalize(float(zf.min()), float(max(zf.max(), zf.min() + 1e-12)))
            rgb = colormaps["viridis"](norm(np.nan_to_num(z)))[:, :3]
            _scatter(ax, p[draw], rgb, _marker_size(len(draw)) / 2)
        ax.set_title(head, fontsize=_TEXT_PT, color=colors[i])
    return _render(fig, title)


def critical_points_picture(
    points: np.ndarray,
    critical: np.ndarray,
    *,
    title: str = "",
    elev: float = DEFAULT_ELEV,
    azim: float = DEFAULT_AZIM,
    size: tuple[int, int] = (1600, 800),
) -> np.ndarray:
    r"""PointNet's critical point set beside its cloud (Qi et al., CVPR 2017, Fig. 7).

    PointNet's global feature is :math:`g = \max_{i} h(p_i)`, a max over points for
    each of its channels; the critical set :math:`C_S` is the set of points that win at
    least one channel (``argmax`` over points, per channel). Any cloud between
    :math:`C_S` and the full cloud gives the same :math:`g`. The left panel draws the
    cloud in light grey, titled "N points"; the right one the critical points in colour
    (by height, viridis; larger markers) over the faint cloud, titled "critical set: M
    points" (``M`` distinct indices: repeated winners count once).

    Parameters
    ----------
    points : (N, 3) array_like
        The cloud; NaN/inf rows are left out.
    critical : (M,) int array_like
        Indices of the critical points in 0..N-1 (repeats allowed).
    title : str
        Above the panels.
    elev, azim : float
        The viewpoint in radians (both panels).
    size : (int, int)
        ``(width, height)`` in pixels, each side 150 to 4000.

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        Points not (N, 3) or beyond 1e9, indices not integers or out of range, bad
        view, title or size, or matplotlib missing.

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(40, 3))
    >>> critical_points_picture(pts, [0, 3, 3, 7], size=(400, 200)).shape
    (200, 400, 3)
    """
    p = _cloud(points)
    n = len(p)
    idx = np.unique(_indices(critical, "critical", n))
    title = check_text(title, "title")
    view = _angles(elev, azim)
    width, height = _size(size)

    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    fig = _figure((width, height), 1600, "critical_points_picture")
    box = _box(p)
    finite = np.isfinite(p).all(axis=1)
    draw = _thin(np.flatnonzero(finite))
    marker = _marker_size(len(draw))
    left = _axes(fig, (1, 2, 1), box, view, ticks=False)
    right = _axes(fig, (1, 2, 2), box, view, ticks=False)
    left.set_title(_count(p), fontsize=_TITLE_PT)
    right.set_title(f"critical set: {len(idx)} points", fontsize=_TITLE_PT)
    if not finite.any():
        _note(left, "empty cloud")
        _note(right, "empty cloud")
        return _render(fig, title)
    _scatter(left, p[draw], _LIGHT, marker * 1.5)
    _scatter(right, p[draw], _FAINT, marker, alpha=0.5)
    crit = p[idx]
    z = crit[:, 2]
    zf = p[finite, 2]
    norm = Normalize(float(zf.min()), float(max(zf.max(), zf.min() + 1e-12)))
    rgb = colormaps["viridis"](norm(np.nan_to_num(z)))[:, :3]
    _scatter(right, crit, rgb, max(4.0 * marker, 30.0), edgecolors="black", linewidths=0.4)
    return _render(fig, title)


def feature_neighbours_picture(
    points: np.ndarray,
    graphs: Sequence[np.ndarray],
    queries: np.ndarray,
    *,
    layer_names: Sequence[str] | None = None,
    title: str = "",
    elev: float = DEFAULT_ELEV,
    azim: float = DEFAULT_AZIM,
    size: tuple[int, int] = (1800, 700),
) -> np.ndarray:
    r"""The k nearest neighbours of a few points in each layer's graph, drawn in space
    (the DGCNN paper's Fig. 4: Wang et al., ACM TOG 2019).

    DGCNN's EdgeConv layer :math:`\ell` links point :math:`i` to the k points nearest
    to it in that layer's input features :math:`x^{(\ell)}` (the coordinates for the
    first layer, learned features after). One panel per layer draws the cloud in light
    grey, each query point as a large star in its own colour
    (``label_colors(q + 1)`` for the ``q``-th query) and its k neighbours in that
    layer's graph as dots of the same colour: in the first layer the neighbours sit
    around the query, in deeper ones they spread to points of the same part far away.

    Parameters
    ----------
    points : (N, 3) array_like
        The cloud; NaN/inf rows are left out.
    graphs : sequence of (N, k) int array_like
        1 to 8 layers' neighbour indices (``graphs[l][i]`` the neighbours of point
        ``i`` in layer ``l``; k may differ between layers), each in 0..N-1.
    queries : (Q,) int array_like
        0 to :data:`MAX_QUERIES` point indices to show.
    layer_names : sequence of str, optional
        Panel titles; default "layer 1 (xyz)", "layer 2 (features)", ...
    title : str
        Above the panels.
    elev, azim : float
        The viewpoint in radians (every panel).
    size : (int, int)
        ``(width, height)`` in pixels, each side 150 to 4000.

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        Points not (N, 3) or beyond 1e9, a graph not (N, k) integers in 0..N-1, no
        graph or more than 8, queries not integers in 0..N-1 or more than
        :data:`MAX_QUERIES`, layer names of another count, bad view, title or size, or
        matplotlib missing.

    Examples
    --------
    >>> pts = np.random.default_rng(0).normal(size=(30, 3))
    >>> near = np.argsort(((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, :4]
    >>> far = np.argsort(-((pts[:, None] - pts[None]) ** 2).sum(-1), axis=1)[:, :4]
    >>> feature_neighbours_picture(pts, [near, far], [0, 5], size=(600, 240)).shape
    (240, 600, 3)
    """
    p = _cloud(points)
    n = len(p)
    if isinstance(graphs, np.ndarray) and graphs.ndim == 3:
        graphs = list(graphs)
    if isinstance(graphs, (str, bytes)) or not isinstance(graphs, Sequence):
        raise InputError(
            f"graphs must be a list of (N, k) neighbour-index arrays; got {plain_repr(graphs)}"
        )
    if not 1 <= len(graphs) <= 8:
        raise InputError(f"graphs must hold 1 to 8 layers' (N, k) indices; got {len(graphs)}")
    nets = []
    for i, g in enumerate(graphs):
        arr = check_ndim(g, f"graphs[{i}]", (2,))
        if arr.shape[0] != n:
            raise InputError(
                f"graphs[{i}] must be (N, k) = ({n}, k), one row of neighbours per point; "
                f"got {arr.shape}"
            )
        if arr.size and arr.dtype.kind not in "iu":
            raise InputError(f"graphs[{i}] must be integer point indices; got dtype {arr.dtype}")
        arr = arr.astype(np.int64)
        _in_range(arr.ravel(), f"graphs[{i}]", n)
        nets.append(arr)
    qs = _indices(queries, "queries", n)
    if len(qs) > MAX_QUERIES:
        raise InputError(f"queries must hold at most {MAX_QUERIES} points; got {len(qs)}")
    if layer_names is None:
        heads = [f"layer {i + 1} ({'xyz' if i == 0 else 'features'})" for i in range(len(nets))]
    else:
        heads = _texts(layer_names, len(nets), "layer_names", "names (one per graph)")
    title = check_text(title, "title")
    view = _angles(elev, azim)
    width, height = _size(size)

    fig = _figure((width, height), 1800, "feature_neighbours_picture")
    box = _box(p)
    finite = np.isfinite(p).all(axis=1)
    draw = _thin(np.flatnonzero(finite))
    marker = _marker_size(len(draw))
    rgb = label_colors(np.arange(1, len(qs) + 1)) / 255.0
    for k, (net, head) in enumerate(zip(nets, heads, strict=True)):
        ax = _axes(fig, (1, len(nets), k + 1), box, view, ticks=False)
        ax.set_title(f"{head}, k = {net.shape[1]}", fontsize=_TITLE_PT)
        if not finite.any():
            _note(ax, "empty cloud")
            continue
        _scatter(ax, p[draw], _LIGHT, marker)
        for q, color in zip(qs.tolist(), rgb, strict=True):
            c = tuple(color)
            _scatter(ax, p[net[q]], c, max(3.0 * marker, 25.0), edgecolors="black", linewidths=0.3)
            _scatter(ax, p[[q]], c, 320.0, marker="*", edgecolors="black", linewidths=0.8)
    if len(qs) and finite.any():
        from matplotlib.lines import Line2D

        handles = [
            Line2D(
                [],
                [],
                marker="*",
                linestyle="",
                markersize=16,
                color="0.4",
                markeredgecolor="black",
                label="query point",
            ),
            Line2D(
                [],
                [],
                marker="o",
                linestyle="",
                markersize=8,
                color="0.4",
                markeredgecolor="black",
                label="its k neighbours in the layer's graph",
            ),
        ]
        fig.legend(
            handles=handles, loc="outside lower center", ncols=2, fontsize=_TEXT_PT, frameon=False
        )
    return _render(fig, title)
