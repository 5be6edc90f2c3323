"""Pictures of 2-D features: HOG glyphs and keypoint matches between two images.

Match pictures follow OpenCV's ``drawMatches`` and its feature-homography tutorial: the
two images side by side, the best matches (smallest descriptor distance) joined by
lines, inliers and outliers in distinct colours, and the first image's border mapped
through the fitted homography onto the second (the found object's outline).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robopercept._checks import check_bool, check_int, check_ndim, check_text, plain_repr
from robopercept.errors import InputError
from robopercept.viz.draw import (
    check_color,
    check_picture_size,
    check_stroke,
    check_xy,
    clip_segments,
    draw_label,
    to_rgb8,
)

__all__ = [
    "OUTLINE_COLOR",
    "MatchPicture",
    "draw_matches",
    "hog_picture",
    "matches_picture",
    "project_outline",
    "select_matches",
]


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


#: the colour of the projected outline of image A on image B in match pictures
OUTLINE_COLOR = (0, 200, 255)
#: the dark rim drawn under every line of a match picture, so that it shows on any image
_RIM = (0, 0, 0)


@dataclass(frozen=True)
class MatchPicture:
    """A picture of matches between two images, and what it shows.

    Attributes
    ----------
    image : (max(Ha, Hb), Wa + Wb, 3) uint8 ndarray
        A on the left, B on the right.
    drawn : (K,) int64 ndarray
        Rows of the matches drawn, best (smallest descriptor distance) first.
    outline : (4, 2) float64 ndarray or None
        The corners of A's border (pixel edges ``(-0.5, -0.5)``, ``(Wa - 0.5, -0.5)``,
        ``(Wa - 0.5, Ha - 0.5)``, ``(-0.5, Ha - 0.5)``) mapped by the homography into
        B's pixel coordinates; None when no homography was given or the border passes
        through the line at infinity (some corner maps to ``w <= 0``).
    """

    image: np.ndarray
    drawn: np.ndarray
    outline: np.ndarray | None


def _check_homography(h: object) -> np.ndarray:
    arr = None
    if isinstance(h, (np.ndarray, list, tuple)):
        try:
            arr = np.asarray(h, dtype=np.float64)
        except (TypeError, ValueError, OverflowError):  # (strings, ragged rows, objects)
            arr = None
    if arr is None or arr.shape != (3, 3) or not np.isfinite(arr).all():
        raise InputError(
            "homography must be a finite 3x3 matrix mapping A's pixels to B's (e.g. "
            f"match_images(a, b).fit.H); got {plain_repr(h)}"
        )
    return arr


def project_outline(homography: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    r"""The border of a ``size`` = (width, height) image mapped by ``homography``.

    Corner :math:`c = (x, y)` maps to :math:`(u / w, v / w)` with
    :math:`(u, v, w)^T = H (x, y, 1)^T`, as ``cv2.perspectiveTransform`` of the four
    corners (the drawing in OpenCV's feature-homography tutorial); the corners are the
    pixel edges ``(-0.5, -0.5)``, ``(W - 0.5, -0.5)``, ``(W - 0.5, H - 0.5)``,
    ``(-0.5, H - 0.5)`` of the pixel-centre convention.

    Parameters
    ----------
    homography : (3, 3) array_like
    size : (int, int)
        ``(width, height)`` of the source image.

    Returns
    -------
    (4, 2) float64 ndarray or None
        None when a corner maps to :math:`w \le 0` (the border crosses the line at
        infinity: its image is not a closed quadrilateral).

    Examples
    --------
    >>> project_outline(np.diag([2.0, 2.0, 1.0]), (3, 2)).tolist()
    [[-1.0, -1.0], [5.0, -1.0], [5.0, 3.0], [-1.0, 3.0]]
    """
    hm = _check_homography(homography)
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise InputError(f"size must be (width, height); got {plain_repr(size)}")
    w, h = check_int(size[0], "size[0]", 1), check_int(size[1], "size[1]", 1)
    corners = np.array([[-0.5, -0.5, 1.0], [w - 0.5, -0.5, 1.0], [w - 0.5, h - 0.5, 1.0]])
    corners = np.vstack([corners, [-0.5, h - 0.5, 1.0]])
    with np.errstate(all="ignore"):
        uvw = corners @ hm.T
        scale = np.max(np.abs(hm))
        if not scale > 0 or not (uvw[:, 2] > 1e-12 * scale).all():
            return None
        out = uvw[:, :2] / uvw[:, 2:]
    return out if np.isfinite(out).all() else None


def select_matches(
    n: int,
    *,
    distance: np.ndarray | None = None,
    inliers: np.ndarray | None = None,
    max_matches: int | None = 100,
    show_outliers: bool = True,
) -> np.ndarray:
    """Which of ``n`` matches a picture draws: at most ``max_matches``, the smallest
    descriptor ``distance`` first (ties in row order), among the inliers only when
    ``show_outliers`` is False; evenly spaced rows when no distance is given.

    With both inliers and outliers shown, the drawn set keeps the inlier fraction of all
    the matches: ``k_in = round(K n_in / n)`` best inliers and ``K - k_in`` best outliers
    (``K = min(max_matches, n)``). Ranking all together would misstate it: under a
    viewpoint change the correct matches' descriptors differ more than those of
    repeated texture, so on Oxford graf 1 -> 3 the 100 smallest distances hold 39 %
    inliers against 58 % of all 677 matches.

    Parameters
    ----------
    n : int
        Number of matches.
    distance : (n,) array_like, optional
        Descriptor distances (``Matches.distance``); NaN sorts last.
    inliers : (n,) bool array_like, optional
    max_matches : int or None
        None draws every candidate.
    show_outliers : bool

    Returns
    -------
    (K,) int64 ndarray
        Rows, best first.

    Examples
    --------
    >>> select_matches(4, distance=[0.4, 0.1, 0.3, 0.2], max_matches=2).tolist()
    [1, 3]
    >>> select_matches(4, distance=[0.4, 0.1, 0.3, 0.2], inliers=[1, 0, 1, 0],
    ...                max_matches=5, show_outliers=False).tolist()
    [2, 0]
    >>> select_matches(4, distance=[0.4, 0.1, 0.3, 0.2], inliers=[1, 0, 1, 0],
    ...                max_matches=2).tolist()  # one inlier, one outlier: half are inliers
    [1, 2]
    """
    n = check_int(n, "n", 0)
    keep = _check_inliers(inliers, n)
    if max_matches is not None:
        max_matches = check_int(max_matches, "max_matches", 1)
    show_outliers = check_bool(show_outliers, "show_outliers")
    rows = np.arange(n) if show_outliers else np.flatnonzero(keep)
    if distance is not None:
        d = check_ndim(distance, "distance", (1,))
        if d.dtype.kind not in "biuf":
            raise InputError(f"distance must be real numbers (one per match); got {d.dtype}")
        if d.shape[0] != n:
            raise InputError(f"distance has {d.shape[0]} entries for {n} matches")
        rows = rows[np.argsort(d[rows].astype(np.float64), kind="stable")]
        if max_matches is not None and rows.size > max_matches:
            if show_outliers and inliers is not None:
                k_in = round(max_matches * int(keep.sum()) / n)
                best_in, best_out = rows[keep[rows]][:k_in], rows[~keep[rows]]
                best_out = best_out[: max_matches - best_in.size]
                chosen = np.zeros(n, bool)
                chosen[best_in] = chosen[best_out] = True
                rows = rows[chosen[rows]]  # (best first, as ranked)
            else:
                rows = rows[:max_matches]
    elif max_matches is not None and rows.size > max_matches:
        rows = rows[np.linspace(0, rows.size - 1, max_matches).astype(int)]
    return rows.astype(np.int64)


def _check_inliers(inliers: np.ndarray | None, n: int) -> np.ndarray:
    if inliers is None:
        return np.ones(n, bool)
    keep = check_ndim(inliers, "inliers", (1,))
    if keep.dtype.kind not in "biuf":
        raise InputError(f"inliers must be bool (one per match); got dtype {keep.dtype}")
    if keep.shape[0] != n:
        raise InputError(f"inliers has {keep.shape[0]} entries for {n} matches")
    return keep.astype(bool)


def matches_picture(
    image_a: np.ndarray,
    xy_a: np.ndarray,
    image_b: np.ndarray,
    xy_b: np.ndarray,
    *,
    inliers: np.ndarray | None = None,
    distance: np.ndarray | None = None,
    homography: np.ndarray | None = None,
    max_matches: int | None = 100,
    show_outliers: bool = True,
    color: Sequence[int] = (0, 255, 0),
    outlier_color: Sequence[int] = (255, 0, 255),
    outline_color: Sequence[int] = OUTLINE_COLOR,
    width: int | None = None,
    caption: str | None = None,
) -> MatchPicture:
    """Two images side by side, the best matches joined by lines, and A's outline on B.

    The ``max_matches`` matches of smallest descriptor distance are drawn
    (:func:`select_matches`; every match still counts in whatever fit the caller made):
    inliers in ``color`` (green), outliers in ``outlier_color`` (magenta, which shows on
    red and green scenes alike), outliers first so that inliers stay on top; every line
    and end-point disc has a dark rim, so it stays visible on any background. With a
    ``homography`` (A -> B), the border of A is mapped into B
    (:func:`project_outline`) and drawn there in ``outline_color``, as OpenCV's
    feature-homography tutorial draws the found object.

    Parameters
    ----------
    image_a, image_b : (H, W) or (H, W, 3) ndarray
        The two images (the shorter one is padded with black at the bottom).
    xy_a, xy_b : (N, 2) array_like
        Matched ``(x, y)`` positions, row i of one matching row i of the other.
    inliers : (N,) bool array_like, optional
        All inliers when omitted.
    distance : (N,) array_like, optional
        Descriptor distances; without them the drawn matches are evenly spaced rows.
    homography : (3, 3) array_like, optional
        Maps A's pixels to B's.
    max_matches : int or None
        Draw at most this many (None: all).
    show_outliers : bool
        False draws inliers only.
    color, outlier_color, outline_color : (3,) ints
    width : int, optional
        Line width in pixels (default ``max(1, round(H / 400))``: 2 px at 640 rows,
        3 px at 1080p).
    caption : str, optional
        A :func:`~robopercept.viz.draw.draw_label` in the top-left corner.

    Returns
    -------
    MatchPicture

    Examples
    --------
    >>> img = np.zeros((40, 40), np.uint8)
    >>> xy = np.array([[10.0, 10.0], [20.0, 30.0], [30.0, 5.0]])
    >>> pic = matches_picture(img, xy, img, xy, distance=[3.0, 1.0, 2.0], max_matches=2,
    ...                       homography=np.eye(3))
    >>> pic.image.shape, pic.drawn.tolist(), pic.outline[2].tolist()
    ((40, 80, 3), [1, 2], [39.5, 39.5])
    """
    from PIL import Image, ImageDraw

    a, b = to_rgb8(image_a), to_rgb8(image_b)
    pa = check_xy(xy_a, "xy_a")
    pb = check_xy(xy_b, "xy_b")
    if pa.shape != pb.shape:
        raise InputError(f"xy_a and xy_b must have the same shape; got {pa.shape} and {pb.shape}")
    n = pa.shape[0]
    keep = _check_inliers(inliers, n)
    drawn = select_matches(
        n,
        distance=distance,
        inliers=keep,
        max_matches=max_matches,
        show_outliers=show_outliers,
    )
    hm = None if homography is None else _check_homography(homography)
    good, bad = check_color(color), check_color(outlier_color, "outlier_color")
    ring = check_color(outline_color, "outline_color")
    if caption is not None:
        caption = check_text(caption, "caption")
    h = max(a.shape[0], b.shape[0])
    check_picture_size(a.shape[1] + b.shape[1], h, "side-by-side picture")
    lw = max(1, round(h / 400)) if width is None else int(check_stroke(width, "width"))
    outline = None if hm is None else project_outline(hm, (a.shape[1], a.shape[0]))
    if outline is not None:  # drawn on B alone, so that it never spills onto A
        pil_b = Image.fromarray(b)
        draw_b = ImageDraw.Draw(pil_b)
        quad = np.hstack([outline, np.roll(outline, -1, axis=0)])
        quad = clip_segments(quad, b.shape[1], b.shape[0], 2.0 * lw + 2)
        for pen, col in ((2 * lw + 2, _RIM), (2 * lw, ring)):
            for x0, y0, x1, y1 in quad:
                draw_b.line([(x0, y0), (x1, y1)], fill=col, width=pen)
        b = np.asarray(pil_b)
    canvas = np.zeros((h, a.shape[1] + b.shape[1], 3), np.uint8)
    canvas[: a.shape[0], : a.shape[1]] = a
    canvas[: b.shape[0], a.shape[1] :] = b
    pil = Image.fromarray(canvas)
    draw = ImageDraw.Draw(pil)
    off = a.shape[1]
    W, H = pil.width, pil.height
    r = 2 * lw + 1
    # outliers first so that inliers stay visible on top
    for i in sorted(drawn.tolist(), key=lambda k: bool(keep[k])):
        col = good if keep[i] else bad
        (x0, y0), (x1, y1) = pa[i], pb[i]
        if not np.isfinite([x0, y0, x1, y1]).all():
            continue
        x1 = x1 + off
        seg = clip_segments(np.array([x0, y0, x1, y1]), W, H, r + 2.0)
        for pen, fill in ((lw + 2, _RIM), (lw, col)):
            for sx0, sy0, sx1, sy1 in seg:
                draw.line([(sx0, sy0), (sx1, sy1)], fill=fill, width=pen)
        for x, y in ((x0, y0), (x1, y1)):
            if -r - 1 <= x <= W + r and -r - 1 <= y <= H + r:
                draw.ellipse((x - r, y - r, x + r, y + r), fill=col, outline=_RIM)
    out = np.asarray(pil)
    if caption:
        out = draw_label(out, caption, (0, 0), color=(0, 0, 0), anchor="lt")
    return MatchPicture(out, drawn, outline)


def draw_matches(
    image_a: np.ndarray,
    xy_a: np.ndarray,
    image_b: np.ndarray,
    xy_b: np.ndarray,
    *,
    inliers: np.ndarray | None = None,
    color: Sequence[int] = (0, 255, 0),
    outlier_color: Sequence[int] = (255, 0, 255),
    max_lines: int | None = 500,
    distance: np.ndarray | None = None,
    homography: np.ndarray | None = None,
) -> np.ndarray:
    """Put two images side by side and join matched points with lines: the picture of
    :func:`matches_picture` (which also says what it drew).

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
        Draw at most this many matches (the smallest ``distance`` first, else evenly
        spaced); None draws all.
    distance : (N,) array_like, optional
        Descriptor distances.
    homography : (3, 3) array_like, optional
        A -> B: A's outline is drawn on B.

    Returns
    -------
    (max(Ha, Hb), Wa + Wb, 3) uint8 ndarray

    Examples
    --------
    >>> xy = np.array([[5.0, 5.0]])
    >>> draw_matches(np.zeros((10, 10)), xy, np.zeros((12, 8)), xy).shape
    (12, 18, 3)
    """
    if max_lines is not None:
        max_lines = check_int(max_lines, "max_lines", 1)
    return matches_picture(
        image_a,
        xy_a,
        image_b,
        xy_b,
        inliers=inliers,
        distance=distance,
        homography=homography,
        max_matches=max_lines,
        color=color,
        outlier_color=outlier_color,
    ).image
