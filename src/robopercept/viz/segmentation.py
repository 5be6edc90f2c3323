"""Pictures of segmentations: class overlays with a legend, instance overlays with one
colour and an outline per instance, blob overlays that keep the image visible, and
panels side by side or in a grid (prediction above ground truth), readable at 1080p.

A small image (the 128 x 128 canvases, a 256 x 256 tile) is enlarged first, by an
integer factor with nearest-neighbour sampling (pixels stay sharp and labels exact),
so that its longer side reaches ``min_side`` pixels; text is sized from the result.
Colours: class ``k`` takes colour ``k`` of the Pascal VOC map
(:func:`~robopercept.viz.colormap.voc_palette`), so an overlay and a VOC-style label
PNG of the same labels agree; instance ``i`` takes the golden-ratio hue of
:func:`~robopercept.viz.colormap.label_colors`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from robopercept._checks import check_bool, check_int, check_ndim, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors, voc_palette
from robopercept.viz.draw import (
    MAX_STROKE,
    check_picture_size,
    draw_boxes,
    draw_text,
    enlarge_picture,
    legend_panel,
    to_rgb8,
)

__all__ = ["blob_overlay", "class_overlay", "instance_overlay", "panels_picture"]

#: the longer side a small picture is enlarged to (integer factors, nearest neighbour)
MIN_SIDE = 512


def _font(img: np.ndarray) -> int:
    """Text height: about 1/40 of the longer side, at least 14 px (22 px at 1080p)."""
    return int(max(14, round(max(img.shape[:2]) / 40)))


def _labels_of(labels: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    lab = check_ndim(labels, name, (2,))
    if lab.dtype.kind not in "iub":
        raise InputError(f"{name} must be an integer (H, W) label image; got dtype {lab.dtype}")
    if lab.shape != shape:
        raise InputError(f"{name} must have the image's shape {shape}; got {lab.shape}")
    return lab.astype(np.int64)


def _outline(mask: np.ndarray, width: int) -> np.ndarray:
    """The pixels of ``mask`` within ``width`` of its border (the image edge counts as
    outside)."""
    inner = ndimage.binary_erosion(mask, iterations=width, border_value=0)
    return mask & ~inner


def class_overlay(
    image: Any,
    labels: Any,
    classes: Sequence[str],
    *,
    alpha: float = 0.5,
    ignore_index: int | None = 255,
    min_side: int = MIN_SIDE,
) -> np.ndarray:
    """Blend each pixel's class colour over ``image`` and add a legend of the classes
    present, in a panel to the right (never over the data).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    labels : (H, W) int array_like
        0 the background (left untinted), ``k`` for ``classes[k - 1]``;
        ``ignore_index`` pixels are drawn in the VOC void colour.
    classes : sequence of str
        The names of labels 1..K.
    alpha : float
        Opacity of the class colours, in [0, 1].
    ignore_index : int or None
    min_side : int
        Small images are enlarged to about this longer side.

    Returns
    -------
    (H', W', 3) uint8 ndarray

    Raises
    ------
    InputError
        Labels of another shape or not integers, a label outside 0..K (and not the
        ignore index), no class names.

    Examples
    --------
    >>> lab = np.zeros((8, 8), int); lab[2:6, 2:6] = 1
    >>> pic = class_overlay(np.zeros((8, 8, 3), np.uint8), lab, ["box"], min_side=64)
    >>> pic.shape[0], pic.shape[1] > 64, pic[24, 24].tolist()
    (64, True, [64, 0, 0])
    """
    img = to_rgb8(image)
    lab = _labels_of(labels, img.shape[:2], "labels")
    names = [str(c) for c in classes] if isinstance(classes, (list, tuple)) else None
    if not names:
        raise InputError(f"classes must be a non-empty list of names; got {plain_repr(classes)}")
    a = check_real(alpha, "alpha", 0.0, 1.0)
    side = check_int(min_side, "min_side", 1)
    if ignore_index is not None:
        ignore_index = check_int(ignore_index, "ignore_index")
    void = lab == ignore_index if ignore_index is not None else np.zeros(lab.shape, bool)
    bad = (~void) & ((lab < 0) | (lab > len(names)))
    if bad.any():
        void_note = "" if ignore_index is None else f" or the ignore index {ignore_index}"
        raise InputError(
            f"labels must be in 0..{len(names)} (one per class name){void_note}; got "
            f"{int(lab[bad][0])}: pass every class name"
        )
    pal = voc_palette(256)
    out = img.astype(np.float64)
    fg = (lab > 0) & ~void
    col = pal[np.clip(lab, 0, 255)].astype(np.float64)
    out[fg] = (1 - a) * out[fg] + a * col[fg]
    out[void] = pal[255]
    pic, _ = enlarge_picture(np.round(out).astype(np.uint8), side)
    present = [k for k in range(1, len(names) + 1) if (lab == k).any()]
    return _with_legend(pic, [(names[k - 1], tuple(pal[k])) for k in present])


def _with_legend(pic: np.ndarray, entries: list[tuple[str, tuple[int, ...]]]) -> np.ndarray:
    """``pic`` with a white panel on its right listing ``entries`` (name, colour): a
    swatch and the name per row; "nothing segmented" when there is none."""
    return legend_panel(pic, entries, size=_font(pic), empty="nothing segmented")


def _per_instance(values: Any, n: int, name: str, kinds: str) -> np.ndarray:
    try:
        v = np.asarray(values)
    except (TypeError, ValueError):
        v = np.zeros((0, 0))
    if v.shape != (n,) or v.dtype.kind not in kinds or not np.isfinite(v).all():
        what = "integers" if kinds == "iu" else "finite numbers"
        raise InputError(
            f"{name} must have one entry per instance ({n}), {what}; got {plain_repr(values)}"
        )
    return v


def instance_overlay(
    image: Any,
    masks: Any,
    *,
    labels: Sequence[int] | None = None,
    classes: Sequence[str] | None = None,
    scores: Sequence[float] | None = None,
    alpha: float = 0.45,
    min_side: int = MIN_SIDE,
) -> np.ndarray:
    """Tint each instance in its own colour, outline it, and write its class (and
    score) at its top-left corner on a dark box; "nothing segmented" on an empty set.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    masks : (N, H, W) bool array_like, or an (H, W) instance label image
        (0 background, each positive id one instance).
    labels : sequence of N int, optional
        Class of each instance (1-based into ``classes``).
    classes : sequence of str, optional
    scores : sequence of N float, optional
    alpha : float
    min_side : int

    Returns
    -------
    (H', W', 3) uint8 ndarray

    Raises
    ------
    InputError
        Masks of another size, or labels / scores not one per instance.

    Examples
    --------
    >>> m = np.zeros((2, 16, 16), bool); m[0, 2:8, 2:8] = True; m[1, 9:15, 4:12] = True
    >>> pic = instance_overlay(np.zeros((16, 16)), m, min_side=64)
    >>> pic.shape, pic[8, 8].tolist() != [0, 0, 0]
    ((64, 64, 3), True)
    """
    img = to_rgb8(image)
    m = np.asarray(masks)
    if m.ndim == 2:
        lab = _labels_of(m, img.shape[:2], "masks")
        ids = np.unique(lab[lab > 0])
        m = lab[None] == ids[:, None, None]
    elif m.ndim != 3 or m.shape[1:] != img.shape[:2] or m.dtype.kind not in "biuf":
        raise InputError(
            f"masks must be (N, H, W) with the image's (H, W) = {img.shape[:2]}, or an "
            f"(H, W) label image; got {plain_repr(masks)}"
        )
    m = m.astype(bool)
    n = m.shape[0]
    lab_ids = None if labels is None else _per_instance(labels, n, "labels", "iu")
    score_v = None if scores is None else _per_instance(scores, n, "scores", "iuf")
    if classes is not None and (
        not isinstance(classes, (list, tuple)) or not all(isinstance(c, str) for c in classes)
    ):
        raise InputError(f"classes must be a list of names (str); got {plain_repr(classes)}")
    a = check_real(alpha, "alpha", 0.0, 1.0)
    side = check_int(min_side, "min_side", 1)
    big, f = enlarge_picture(img, side)
    out = big.astype(np.float64)
    colors = label_colors(np.arange(1, n + 1)).astype(np.float64)
    size = _font(big)
    line = max(1, size // 8)
    boxes = []
    for i in range(n):
        mi = np.repeat(np.repeat(m[i], f, axis=0), f, axis=1)
        out[mi] = (1 - a) * out[mi] + a * colors[i]
        out[_outline(mi, line)] = colors[i]
        rows, cols = np.nonzero(m[i])
        boxes.append((cols.min() * f, rows.min() * f) if rows.size else None)
    pic = np.round(out).astype(np.uint8)
    for i, corner in enumerate(boxes):
        if corner is None or (lab_ids is None and score_v is None):
            continue
        parts = []
        if lab_ids is not None:
            k = int(lab_ids[i])
            parts.append(classes[k - 1] if classes and 1 <= k <= len(classes) else str(k))
        if score_v is not None:
            parts.append(f"{float(score_v[i]):.2f}")
        y = max(0, corner[1] - size - 4)
        pic = draw_text(pic, " ".join(parts), (corner[0] + 2, y), size=size)
    if n == 0:
        pic = draw_text(pic, "nothing segmented", (size // 2, size // 2), size=size)
    return pic


def panels_picture(
    pictures: Sequence[np.ndarray],
    titles: Sequence[str],
    *,
    gap: int = 12,
    columns: int | None = None,
) -> np.ndarray:
    """Pictures on white, each under its title (prediction beside ground truth, or one
    architecture beside another): side by side, or in a grid of ``columns`` per row
    filled row by row (``columns=math.ceil(math.sqrt(n))`` gives a roughly square
    sheet, as matplotlib's ``subplots`` grids are laid out). Each grid column is as
    wide as its widest picture and each row as tall as its tallest; smaller pictures
    sit at the top-left of their cell.

    Parameters
    ----------
    pictures : sequence of (H, W) or (H, W, 3) ndarray
    titles : sequence of str
        One per picture.
    gap : int
        White pixels between columns and between rows (>= 0).
    columns : int, optional
        Pictures per row (>= 1); default all in one row.

    Returns
    -------
    (H', W', 3) uint8 ndarray

    Examples
    --------
    >>> panels_picture([np.zeros((40, 30, 3), np.uint8)] * 2, ["a", "b"]).shape[1]
    72
    >>> panels_picture([np.zeros((40, 30, 3), np.uint8)] * 4, list("abcd"), columns=2).shape[1]
    72
    """
    if isinstance(pictures, np.ndarray) or not isinstance(pictures, Sequence):
        raise InputError(
            f"pictures must be a list of images, one per panel; got {plain_repr(pictures)}"
        )
    pics = [to_rgb8(p) for p in pictures]
    if isinstance(titles, str) or not isinstance(titles, Sequence):
        raise InputError(
            f"titles must be a list of strings, one per picture; got {plain_repr(titles)}"
        )
    titles = [str(t) for t in titles]
    if not pics or len(titles) != len(pics):
        raise InputError(
            f"give one title per picture; got {len(pics)} pictures and {len(titles)} titles"
        )
    g = check_int(gap, "gap", 0)
    n = len(pics)
    cols = n if columns is None else min(check_int(columns, "columns", 1), n)
    rows = -(-n // cols)
    size = _font(max(pics, key=lambda p: max(p.shape[:2])))
    cap = int(size * 1.6)
    col_w = [max(pics[i].shape[1] for i in range(c, n, cols)) for c in range(cols)]
    row_h = [max(p.shape[0] for p in pics[r * cols : (r + 1) * cols]) for r in range(rows)]
    w = sum(col_w) + g * (cols - 1)
    h = sum(row_h) + (cap + g) * rows - g
    check_picture_size(w, h, "panels")
    out = np.full((h, w, 3), 255, np.uint8)
    xs = np.cumsum([0] + [cw + g for cw in col_w[:-1]])
    ys = np.cumsum([0] + [rh + cap + g for rh in row_h[:-1]])
    for i, p in enumerate(pics):
        x, y = int(xs[i % cols]), int(ys[i // cols])
        out[y + cap : y + cap + p.shape[0], x : x + p.shape[1]] = p
    for i, t in enumerate(titles):
        x, y = int(xs[i % cols]), int(ys[i // cols])
        out = draw_text(out, t, (x + 2, y + 2), color=(0, 0, 0), size=size, background=None)
    return out


def blob_overlay(
    image: Any,
    labels: Any,
    *,
    alpha: float = 0.35,
    outline: int | None = None,
    boxes: bool = True,
) -> np.ndarray:
    """Connected components over their image, the image kept visible: each blob tinted
    in its colour at ``alpha`` (``(1 - a) I + a c``), its border outlined in that
    colour, and its bounding box drawn and captioned with its id; every other pixel is
    the image's own. ``robopercept blobs -o`` draws this.

    The blob colours are :func:`~robopercept.viz.colormap.label_colors` of the ids
    (OpenCV's ``connectedComponentsWithStats`` examples paint each label a colour;
    here the colour is blended so that the image shows through, as
    ``skimage.color.label2rgb(labels, image, alpha=...)`` blends). Captions are
    placed by :func:`~robopercept.viz.draw.caption_boxes`, so no two overlap.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    labels : (H, W) int array_like
        0 background, each positive id one blob (as
        :func:`~robopercept.imaging.label_components` gives).
    alpha : float
        Opacity of the tint, in [0, 1] (0: outlines only).
    outline : int, optional
        Outline width in pixels (>= 0; default ``max(1, round(H / 540))``: 2 px at
        1080p).
    boxes : bool
        Draw each blob's bounding box with its id.

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Raises
    ------
    InputError
        Labels of another shape, not integers, or negative; a bad alpha or width.

    Examples
    --------
    >>> lab = np.zeros((40, 40), np.int32); lab[10:30, 10:30] = 1
    >>> out = blob_overlay(np.full((40, 40), 100, np.uint8), lab, boxes=False)
    >>> out[0, 0].tolist(), out[10, 20].tolist() == label_colors(np.array([1]))[0].tolist()
    ([100, 100, 100], True)
    """
    img = to_rgb8(image)
    lab = _labels_of(labels, img.shape[:2], "labels")
    if (lab < 0).any():
        raise InputError(
            f"labels must be >= 0 (0 background, each positive id a blob); got {int(lab.min())}"
        )
    a = check_real(alpha, "alpha", 0.0, 1.0)
    width = (
        max(1, round(img.shape[0] / 540)) if outline is None else check_int(outline, "outline", 0)
    )
    if width > MAX_STROKE:
        raise InputError(f"outline must be at most {MAX_STROKE} pixels; got {width}")
    show_boxes = check_bool(boxes, "boxes")
    ids = np.unique(lab[lab > 0])
    if ids.size == 0:
        return img
    compact = np.zeros(lab.shape, np.int64)
    fg = lab > 0
    compact[fg] = np.searchsorted(ids, lab[fg]) + 1
    colors = np.vstack([np.zeros((1, 3), np.uint8), label_colors(ids)])
    out = img.astype(np.float64)
    out[fg] = (1 - a) * out[fg] + a * colors[compact[fg]]
    pic = np.round(out).astype(np.uint8)
    if width > 0:
        size = 2 * min(width, max(lab.shape)) + 1
        hi = ndimage.grey_dilation(compact, size=(size, size), mode="constant", cval=0)
        lo = ndimage.grey_erosion(compact, size=(size, size), mode="constant", cval=0)
        border = fg & ((hi != compact) | (lo != compact))
        pic[border] = colors[compact[border]]
    if show_boxes:
        slices = ndimage.find_objects(compact)
        rects = np.array(
            [
                [s[1].start, s[0].start, s[1].stop - s[1].start, s[0].stop - s[0].start]
                for s in slices
            ],
            dtype=np.float64,
        )
        pic = draw_boxes(
            pic,
            rects,
            color=colors[1:],
            width=max(1, width // 2) if width else 1,
            labels=[str(int(k)) for k in ids],
        )
    return pic
