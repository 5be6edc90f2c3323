"""Pictures of learning results: scatter plots of labelled points, confusion matrices,
ROC and precision-recall curves (rasterized with Pillow, no plotting library)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from robopercept._checks import (
    check_bool,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_points,
    check_text,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import check_picture_size
from robopercept.viz.plot import MIN_PANEL_HEIGHT, MIN_WIDTH, Panel, Series, plot_series

__all__ = ["confusion_picture", "curves_picture", "scatter_picture", "tiles_picture"]


def _colors(n: int) -> list[tuple[int, int, int]]:
    # distinct hues; label_colors maps 0 to background, so start at 1
    return [tuple(int(v) for v in c) for c in label_colors(np.arange(1, n + 1))]


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


def scatter_picture(
    points: np.ndarray,
    labels: np.ndarray | None = None,
    *,
    title: str = "",
    xlabel: str = "",
    names: Sequence[str] | np.ndarray | None = None,
    width: int = 800,
    height: int = 600,
) -> np.ndarray:
    """2-D points as dots, one colour per label (noise, label -1, in grey).

    Parameters
    ----------
    points : (N, 2) ndarray
    labels : (N,) ndarray, optional
        Any values; each distinct value gets a colour and a legend entry.
    names : sequence of str, optional
        Legend names for the sorted distinct labels (default: the labels themselves).
    """
    pts = check_magnitude(check_points(points, "points", 2), "points", 1e300)
    title, xlabel = check_text(title, "title"), check_text(xlabel, "xlabel")
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
    series = []
    for k, v in enumerate(values):
        sel = lab == v
        noise = np.issubdtype(values.dtype, np.integer) and v == -1
        name = "noise" if noise else (str(names[k]) if names is not None else str(v))
        color = (150, 150, 150) if noise else colors[k]
        label = f"{name} ({int(sel.sum())})" if labels is not None else f"{int(sel.sum())} points"
        series.append(Series(pts[sel, 0], pts[sel, 1], label, color, "dots"))
    return plot_series([Panel(title, series)], width=width, panel_height=height - 30, xlabel=xlabel)


def curves_picture(
    curves: Sequence[tuple[np.ndarray, np.ndarray, str]],
    *,
    title: str,
    xlabel: str,
    ylabel: str,
    width: int = 700,
    height: int = 560,
) -> np.ndarray:
    """Curves ``(x, y, label)`` in one panel (ROC: FPR vs TPR; PR: recall vs precision).

    Parameters
    ----------
    curves : sequence of (x, y, label)
        ``x`` and ``y`` 1-D real arrays of one length, ``label`` a string.
    title, xlabel, ylabel : str
    width, height : int
        Picture size, at least 100 x 90 pixels.

    Returns
    -------
    (height, width, 3) uint8 ndarray
    """
    if not isinstance(curves, (list, tuple)) or not curves:
        raise InputError("curves_picture needs at least one curve: a list of (x, y, label)")
    title, xlabel = check_text(title, "title"), check_text(xlabel, "xlabel")
    ylabel = check_text(ylabel, "ylabel")
    width, height = _plot_size(width, height)
    colors = _colors(len(curves))
    series = []
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
            arrays.append(v.astype(np.float64))
        if arrays[0].shape != arrays[1].shape:
            raise InputError(
                f"curves[{k}]: x and y must have one length; got {arrays[0].size} and "
                f"{arrays[1].size}"
            )
        series.append(Series(arrays[0], arrays[1], check_text(label, "label"), colors[k]))
    return plot_series(
        [Panel(title, series, ylabel)], width=width, panel_height=height - 30, xlabel=xlabel
    )


def confusion_picture(
    matrix: np.ndarray, names: Sequence[str], *, title: str = "confusion matrix", cell: int = 0
) -> np.ndarray:
    """The confusion matrix as a grid: rows true classes, columns predictions, each cell
    shaded by its share of the row (white 0, dark blue 1) and labelled with its count.

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
    """
    from PIL import Image, ImageDraw, ImageFont

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
    k = cm.shape[0]
    names = _names(names, k, "class")
    title = check_text(title, "title")
    cell = check_int(cell, "cell", 0)
    cell = cell or int(np.clip(480 // max(k, 1), 28, 90))
    label_w = max(60, 8 * max(len(n) for n in names) + 16)
    check_picture_size(label_w + 40 + k * cell, 100 + k * cell, "confusion picture")
    cm = check_magnitude(cm, "matrix", 1e300)
    try:
        font = ImageFont.load_default(size=13)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    left, top = label_w + 20, 60
    img = Image.new("RGB", (left + k * cell + 20, top + k * cell + 40), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    draw.text((10, 8), title, fill=(0, 0, 0), font=font)
    draw.text((left, 28), "predicted ->", fill=(80, 80, 80), font=font)
    draw.text((4, top - 18), "true", fill=(80, 80, 80), font=font)
    rows = cm.sum(axis=1, keepdims=True)
    share = np.divide(cm, rows, out=np.zeros(cm.shape), where=rows > 0)
    for i in range(k):
        draw.text((4, top + i * cell + cell // 2 - 7), str(names[i]), fill=(0, 0, 0), font=font)
        column = str(names[i])[: cell // 8]  # what fits under the column
        draw.text((left + i * cell + 4, top + k * cell + 6), column, fill=(0, 0, 0), font=font)
        for j in range(k):
            s = float(share[i, j])
            fill = tuple(round(255 - s * (255 - c)) for c in (8, 48, 107))
            x0, y0 = left + j * cell, top + i * cell
            draw.rectangle([x0, y0, x0 + cell, y0 + cell], fill=fill, outline=(200, 200, 200))
            text = str(int(cm[i, j]))
            box = draw.textbbox((0, 0), text, font=font)
            draw.text(
                (x0 + (cell - box[2]) / 2, y0 + (cell - box[3]) / 2),
                text,
                fill=(255, 255, 255) if s > 0.5 else (0, 0, 0),
                font=font,
            )
    return np.asarray(img)


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
