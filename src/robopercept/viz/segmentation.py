"""Pictures of segmentations: class overlays with a legend, instance overlays with one
colour and an outline per instance, and side-by-side panels (prediction beside ground
truth), readable at 1080p.

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

from robopercept._checks import check_int, check_ndim, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors, voc_palette
from robopercept.viz.draw import check_picture_size, draw_text, enlarge_picture, to_rgb8

__all__ = ["class_overlay", "instance_overlay", "panels_picture"]

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
    size = _font(pic)
    rows = entries or [("nothing segmented", (255, 255, 255))]
    longest = max(len(n) for n, _ in rows)
    width = int(size * (2 + 0.62 * longest)) + 2 * size
    h = max(pic.shape[0], (len(rows) + 1) * int(size * 1.6))
    check_picture_size(pic.shape[1] + width, h, "overlay with its legend")
    out = np.full((h, pic.shape[1] + width, 3), 255, np.uint8)
    out[: pic.shape[0], : pic.shape[1]] = pic
    x0 = pic.shape[1] + size // 2
    tops = [size // 2 + int(i * size * 1.6) for i in range(len(rows))]
    for y, (_, color) in zip(tops, entries, strict=False):
        out[y : y + size, x0 : x0 + size] = 0  # a swatch with a black frame
        out[y + 1 : y + size - 1, x0 + 1 : x0 + size - 1] = color
    for y, (name, _) in zip(tops, rows, strict=True):
        out = draw_text(
            out,
            name,
            (x0 + (int(size * 1.4) if entries else 0), y - 1),
            color=(0, 0, 0),
            size=size,
            background=None,
        )
    return out


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
    pictures: Sequence[np.ndarray], titles: Sequence[str], *, gap: int = 12
) -> np.ndarray:
    """Pictures side by side on white, each under its title (prediction beside ground
    truth, or one architecture beside another); shorter ones are padded at the bottom.

    Examples
    --------
    >>> panels_picture([np.zeros((40, 30, 3), np.uint8)] * 2, ["a", "b"]).shape[1]
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
    size = _font(max(pics, key=lambda p: max(p.shape[:2])))
    cap = int(size * 1.6)
    h = max(p.shape[0] for p in pics) + cap
    w = sum(p.shape[1] for p in pics) + g * (len(pics) - 1)
    check_picture_size(w, h, "panels")
    out = np.full((h, w, 3), 255, np.uint8)
    xs = np.cumsum([0] + [p.shape[1] + g for p in pics[:-1]])
    for x, p in zip(xs, pics, strict=True):
        out[cap : cap + p.shape[0], x : x + p.shape[1]] = p
    for x, t in zip(xs, titles, strict=True):
        out = draw_text(out, str(t), (int(x) + 2, 2), color=(0, 0, 0), size=size, background=None)
    return out
