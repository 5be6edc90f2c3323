"""Pictures of learning results: scatter plots of labelled points, confusion matrices,
ROC and precision-recall curves (rasterized with Pillow, no plotting library)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.plot import Panel, Series, plot_series

__all__ = ["confusion_picture", "curves_picture", "scatter_picture", "tiles_picture"]


def _colors(n: int) -> list[tuple[int, int, int]]:
    # distinct hues; label_colors maps 0 to background, so start at 1
    return [tuple(int(v) for v in c) for c in label_colors(np.arange(1, n + 1))]


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
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"points must be (N, 2); got {pts.shape}")
    lab = np.zeros(len(pts), dtype=int) if labels is None else np.asarray(labels)
    if lab.shape != (len(pts),):
        raise InputError(f"labels must have one value per point; got {lab.shape}")
    values = np.unique(lab)
    if names is not None and len(names) != values.size:
        raise InputError(f"{values.size} labels but {len(names)} names")
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
    """Curves ``(x, y, label)`` in one panel (ROC: FPR vs TPR; PR: recall vs precision)."""
    if not curves:
        raise InputError("curves_picture needs at least one curve")
    colors = _colors(len(curves))
    series = [
        Series(np.asarray(x, float), np.asarray(y, float), label, colors[k])
        for k, (x, y, label) in enumerate(curves)
    ]
    return plot_series(
        [Panel(title, series, ylabel)], width=width, panel_height=height - 30, xlabel=xlabel
    )


def confusion_picture(
    matrix: np.ndarray, names: Sequence[str], *, title: str = "confusion matrix", cell: int = 0
) -> np.ndarray:
    """The confusion matrix as a grid: rows true classes, columns predictions, each cell
    shaded by its share of the row (white 0, dark blue 1) and labelled with its count."""
    from PIL import Image, ImageDraw, ImageFont

    cm = np.asarray(matrix)
    k = cm.shape[0]
    if cm.ndim != 2 or cm.shape[1] != k or len(names) != k:
        raise InputError(f"matrix must be (k, k) with k names; got {cm.shape}, {len(names)}")
    cell = cell or int(np.clip(480 // max(k, 1), 28, 90))
    try:
        font = ImageFont.load_default(size=13)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    label_w = max(60, 8 * max(len(str(n)) for n in names) + 16)
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

    t = np.asarray(tiles, dtype=np.float64)
    if t.ndim == 4 and t.shape[1] == 3:
        t = np.moveaxis(t, 1, -1)
    elif t.ndim != 3:
        raise InputError(f"tiles must be (K, H, W) or (K, 3, H, W); got {t.shape}")
    k = t.shape[0]
    if k == 0:
        raise InputError("no tiles to draw")
    cols = columns or int(np.ceil(np.sqrt(k)))
    rows = int(np.ceil(k / cols))
    cap = 18 if names is not None else 0
    h, w = t.shape[1], t.shape[2]
    scale = max(1, tile_px // max(h, w))
    th, tw = h * scale, w * scale
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
