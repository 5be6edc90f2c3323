"""Pictures of 2-D features: HOG glyphs and keypoint matches between two images."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robopercept._checks import check_int, check_ndim
from robopercept.errors import InputError
from robopercept.viz.draw import check_color, check_picture_size, check_xy, clip_segments, to_rgb8

__all__ = ["draw_matches", "hog_picture"]


def hog_picture(histograms: np.ndarray, cell_size: int = 8, *, scale: int = 2) -> np.ndarray:
    """The HOG picture: per cell, a star of lines, one per orientation bin.

    Each bin draws a line through the cell centre along the *edge* direction of that
    bin (perpendicular to its gradient orientation, the bin centre
    :math:`(b + \\tfrac12)\\pi / n`), as bright as the bin's value relative to the
    99th percentile of the image's non-zero bins (brighter bins saturate); within a
    cell the strongest bins are drawn last.

    Parameters
    ----------
    histograms : (NY, NX, B) array_like
        Cell histograms, e.g. :func:`robopercept.features.cell_histograms`.
    cell_size : int
        Cell size in pixels of the source image.
    scale : int
        Magnification of the picture (cells of ``cell_size * scale`` pixels).

    Returns
    -------
    (NY * cell_size * scale, NX * cell_size * scale, 3) uint8 ndarray
        White glyphs on black.
    """
    from PIL import Image, ImageDraw

    hist = check_ndim(histograms, "histograms", (3,))
    if hist.dtype.kind not in "biuf":
        raise InputError(f"histograms must be real numbers; got dtype {hist.dtype}")
    hist = hist.astype(np.float64)
    if not np.isfinite(hist).all() or (hist < 0).any():
        raise InputError("histograms must be finite and non-negative")
    c = check_int(cell_size, "cell_size", 1) * check_int(scale, "scale", 1)
    ny, nx, nb = hist.shape
    if hist.size == 0:
        raise InputError(f"histograms must not be empty; got shape {hist.shape}")
    check_picture_size(nx * c, ny * c, "HOG picture (cells x cell_size x scale)")
    # values near 1e308 would overflow the 99th-percentile interpolation: scale first
    hist = hist / max(float(hist.max()), 1e-300)
    positive = hist[hist > 0]
    top = np.percentile(positive, 99.0) if positive.size else 0.0
    level = np.zeros_like(hist) if top <= 0 else np.minimum(hist / top, 1.0)
    pil = Image.new("L", (nx * c, ny * c), 0)
    draw = ImageDraw.Draw(pil)
    theta = (np.arange(nb) + 0.5) * np.pi / nb + np.pi / 2  # edge direction per bin
    r = c / 2.0 - 0.5
    dx, dy = r * np.cos(theta), r * np.sin(theta)
    for i in range(ny):
        for j in range(nx):
            cx, cy = j * c + (c - 1) / 2.0, i * c + (c - 1) / 2.0
            for b in np.argsort(level[i, j], kind="stable"):
                v = round(255 * level[i, j, b])
                if v:
                    draw.line([(cx - dx[b], cy - dy[b]), (cx + dx[b], cy + dy[b])], fill=v)
    return to_rgb8(np.asarray(pil))


def draw_matches(
    image_a: np.ndarray,
    xy_a: np.ndarray,
    image_b: np.ndarray,
    xy_b: np.ndarray,
    *,
    inliers: np.ndarray | None = None,
    color: Sequence[int] = (0, 255, 0),
    outlier_color: Sequence[int] = (255, 0, 0),
    max_lines: int | None = 500,
) -> np.ndarray:
    """Put two images side by side and join matched points with lines.

    Parameters
    ----------
    image_a, image_b : (H, W) or (H, W, 3) ndarray
        The two images (the shorter one is padded with black at the bottom).
    xy_a, xy_b : (N, 2) array_like
        Matched ``(x, y)`` positions, row i of one matching row i of the other.
    inliers : (N,) bool array_like, optional
        Inlier matches are drawn in ``color``, the others in ``outlier_color``
        (all in ``color`` when omitted).
    color, outlier_color : (3,) ints
    max_lines : int, optional
        Draw at most this many matches (evenly spaced); None draws all.

    Returns
    -------
    (max(Ha, Hb), Wa + Wb, 3) uint8 ndarray
    """
    from PIL import Image, ImageDraw

    a, b = to_rgb8(image_a), to_rgb8(image_b)
    pa = check_xy(xy_a, "xy_a")
    pb = check_xy(xy_b, "xy_b")
    if pa.shape != pb.shape:
        raise InputError(f"xy_a and xy_b must have the same shape; got {pa.shape} and {pb.shape}")
    n = pa.shape[0]
    if inliers is None:
        keep = np.ones(n, bool)
    else:
        keep = check_ndim(inliers, "inliers", (1,))
        if keep.dtype.kind not in "biuf":
            raise InputError(f"inliers must be bool (one per match); got dtype {keep.dtype}")
        keep = keep.astype(bool)
    if keep.shape[0] != n:
        raise InputError(f"inliers has {keep.shape[0]} entries for {n} matches")
    if max_lines is not None:
        max_lines = check_int(max_lines, "max_lines", 1)
    good, bad = check_color(color), check_color(outlier_color, "outlier_color")
    h = max(a.shape[0], b.shape[0])
    check_picture_size(a.shape[1] + b.shape[1], h, "side-by-side picture")
    canvas = np.zeros((h, a.shape[1] + b.shape[1], 3), np.uint8)
    canvas[: a.shape[0], : a.shape[1]] = a
    canvas[: b.shape[0], a.shape[1] :] = b
    pil = Image.fromarray(canvas)
    draw = ImageDraw.Draw(pil)
    order = np.arange(n)
    if max_lines is not None and n > max_lines:
        order = np.linspace(0, n - 1, max_lines).astype(int)
    off = a.shape[1]
    W, H = pil.width, pil.height
    # outliers first so that inliers stay visible on top
    for i in sorted(order, key=lambda k: bool(keep[k])):
        col = good if keep[i] else bad
        (x0, y0), (x1, y1) = pa[i], pb[i]
        if not np.isfinite([x0, y0, x1, y1]).all():
            continue
        x1 = x1 + off
        for sx0, sy0, sx1, sy1 in clip_segments(np.array([x0, y0, x1, y1]), W, H, 3.0):
            draw.line([(sx0, sy0), (sx1, sy1)], fill=col, width=1)
        for x, y in ((x0, y0), (x1, y1)):
            if -3 <= x <= W + 3 and -3 <= y <= H + 3:
                draw.ellipse((x - 2, y - 2, x + 2, y + 2), outline=col)
    return np.asarray(pil)
