r"""Tiled inference: detect (or segment) an image larger than the windows a model was
trained on, window by window, and merge the windows' outputs into one answer for the
whole image.

The windows (:func:`tile_windows`) are ``tile x tile`` squares whose origins step by
``tile - overlap`` along each axis; the last window of a row or column is moved back so
that it ends on the image's edge (every pixel is covered, no window leaves the image;
an image side shorter than ``tile`` gets one window of that side). Each window *owns*
the part of the image nearer its own centre than its neighbours': along an axis, the
boundary between two consecutive windows starting at :math:`s_i < s_{i+1}` is the middle
of their overlap, :math:`(s_{i+1} + s_i + \mathrm{tile}) / 2`. The owned regions cut
the image into disjoint rectangles.

Merging detections (:func:`detect_tiled`): a window's box, shifted to image
coordinates, is kept when its centre lies in the window's owned region, so an object
seen whole by one window and cut by the edge of another is taken from the first
whenever the overlap is at least the object's size (the cut view's centre lies in the
other window's margin). The kept boxes then go through a class-wise greedy NMS
(:func:`~robopercept.nn.ops.nms.batched_nms`) at the model's own ``nms_thresh``, which
removes the duplicates of an object larger than the overlap. This is the rule of
SAHI's and DeepForest's ``predict_tile`` (overlapping windows, then NMS) with the
ownership test added before the NMS.

Merging class maps (:func:`segment_tiled`): each pixel takes the label its owning
window gave it.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import torch

from robopercept._checks import check_int, check_real
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.ops.nms import batched_nms

__all__ = [
    "MAX_TILED_SIDE",
    "TILE_OVERLAP",
    "check_tiling",
    "detect_tiled",
    "segment_tiled",
    "tile_origins",
    "tile_windows",
]

#: the default overlap of two windows, as a fraction of the window side
TILE_OVERLAP = 0.25


#: the longest image side tiled (pixels): a 1 Mpx-wide mosaic; beyond it the window list
#: alone would not fit in memory
MAX_TILED_SIDE = 1 << 20


def tile_origins(length: int, tile: int, overlap: int) -> list[int]:
    """Window origins along one axis of ``length`` pixels.

    Parameters
    ----------
    length : int
        The image side, >= 1.
    tile : int
        The window side, >= 1.
    overlap : int
        Pixels shared by two consecutive windows, ``0 <= overlap < tile``.

    Returns
    -------
    list of int
        ``0, step, 2 step, ...`` with ``step = tile - overlap``, the last moved back to
        ``length - tile`` so the windows end on the edge; ``[0]`` when
        ``length <= tile``.

    Raises
    ------
    InputError
        A size below 1, a ``length`` beyond :data:`MAX_TILED_SIDE` or an overlap outside
        ``[0, tile)``.

    Examples
    --------
    >>> tile_origins(1000, 400, 100)
    [0, 300, 600]
    >>> tile_origins(1001, 400, 100)
    [0, 300, 600, 601]
    >>> tile_origins(250, 400, 100)
    [0]
    """
    length = check_count(length, "length (the image side)", 1, MAX_TILED_SIDE)
    tile = check_int(tile, "tile (--tile)", 1)
    overlap = check_int(overlap, "overlap (--overlap)", 0)
    if overlap >= tile:
        raise InputError(
            f"--overlap {overlap} must be smaller than --tile {tile} (windows must advance)"
        )
    if length <= tile:
        return [0]
    step = tile - overlap
    starts = list(range(0, length - tile + 1, step))
    if starts[-1] != length - tile:
        starts.append(length - tile)
    return starts


def _owned(starts: list[int], tile: int, length: int) -> list[tuple[float, float]]:
    """The owned interval ``[lo, hi)`` of each window along one axis."""
    side = min(tile, length)
    cuts = [(a + side + b) / 2 for a, b in itertools.pairwise(starts)]
    return list(zip([0.0, *cuts], [*cuts, float(length)], strict=True))


def tile_windows(
    height: int, width: int, tile: int, overlap: int
) -> list[tuple[int, int, int, int, tuple[float, float, float, float]]]:
    """The windows covering a ``height x width`` image, row by row.

    Parameters
    ----------
    height, width : int
        The image size, >= 1.
    tile : int
        The window side (a side shorter than ``tile`` gets windows of its own length).
    overlap : int
        Pixels shared by neighbouring windows, ``0 <= overlap < tile``.

    Returns
    -------
    list of (y0, x0, y1, x1, owned)
        The window ``image[y0:y1, x0:x1]`` and the region it owns,
        ``owned = (ox0, oy0, ox1, oy1)`` (half-open, image pixels); the owned regions
        tile the image without overlap.

    Examples
    --------
    >>> [w[:4] for w in tile_windows(500, 300, 400, 100)]
    [(0, 0, 400, 300), (100, 0, 500, 300)]
    >>> tile_windows(500, 300, 400, 100)[0][4]
    (0.0, 0.0, 300.0, 250.0)
    """
    ys = tile_origins(height, tile, overlap)
    xs = tile_origins(width, tile, overlap)
    oy = _owned(ys, tile, height)
    ox = _owned(xs, tile, width)
    th, tw = min(tile, height), min(tile, width)
    return [
        (y, x, y + th, x + tw, (ox[j][0], oy[i][0], ox[j][1], oy[i][1]))
        for i, y in enumerate(ys)
        for j, x in enumerate(xs)
    ]


def check_tiling(tile: Any, overlap: Any = None) -> tuple[int, int]:
    """``tile`` (>= 16 pixels) and ``overlap`` in pixels: ``overlap`` pixels, a float
    fraction of ``tile`` in [0, 0.9], or None for :data:`TILE_OVERLAP`.

    Raises
    ------
    InputError
        A window below 16 pixels or an overlap not smaller than it.

    Examples
    --------
    >>> check_tiling(400), check_tiling(400, 0.1), check_tiling(400, 32)
    ((400, 100), (400, 40), (400, 32))
    """
    tile = check_int(tile, "tile (--tile)", 16)
    if overlap is None:
        overlap = TILE_OVERLAP
    if isinstance(overlap, float):
        overlap = round(check_real(overlap, "overlap (--overlap)", 0.0, 0.9) * tile)
    overlap = check_int(overlap, "overlap (--overlap)", 0)
    if overlap >= tile:
        raise InputError(f"--overlap {overlap} must be smaller than --tile {tile}")
    return tile, overlap


def detect_tiled(
    detect: Callable[[np.ndarray], dict[str, np.ndarray]],
    image: np.ndarray,
    tile: int,
    overlap: int | float | None = None,
    nms_thresh: float = 0.5,
) -> dict[str, np.ndarray]:
    """Detections of a large image, window by window (module docstring).

    Parameters
    ----------
    detect : callable
        One window ``(h, w, 3)`` -> ``{"boxes": (D, 4) xyxy, "labels": (D,),
        "scores": (D,)}`` in window pixels (and optionally ``"masks"`` ``(D, h, w)``),
        e.g. ``lambda im: detect_arrays(model, [im])[0]``.
    image : (H, W, 3) ndarray
    tile : int
        The window side in pixels (>= 16): the size the model was trained on.
    overlap : int or float, optional
        Pixels shared by neighbouring windows, or a fraction of ``tile`` (default
        :data:`TILE_OVERLAP`).
    nms_thresh : float in [0, 1]
        The IoU above which the merge drops the lower-scoring of two boxes of a class.

    Returns
    -------
    dict
        ``boxes`` (D, 4) float64 image pixels, ``labels`` (D,) int64, ``scores`` (D,)
        float64, sorted by decreasing score; ``masks`` (D, H, W) bool when ``detect``
        gives masks.

    Raises
    ------
    InputError
        Not an ``(H, W, 3)`` image, a window side below 16, a bad overlap.

    Examples
    --------
    >>> import numpy as np
    >>> def one_box(im):  # a box at the centre of every window
    ...     h, w = im.shape[:2]
    ...     b = np.array([[w / 2 - 5, h / 2 - 5, w / 2 + 5, h / 2 + 5]])
    ...     return {"boxes": b, "labels": np.array([1]), "scores": np.array([0.9])}
    >>> d = detect_tiled(one_box, np.zeros((100, 180, 3)), tile=100, overlap=20)
    >>> d["boxes"].round(1).tolist()
    [[45.0, 45.0, 55.0, 55.0], [125.0, 45.0, 135.0, 55.0]]
    """
    if not callable(detect):
        raise InputError(f"detect must be a function of a window; got {type(detect).__name__}")
    if not isinstance(image, np.ndarray) or image.ndim != 3 or image.shape[2] != 3:
        raise InputError("image must be an (H, W, 3) RGB array")
    tile, overlap = check_tiling(tile, overlap)
    nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
    h, w = image.shape[:2]
    boxes, labels, scores, masks = [], [], [], []
    with_masks = False
    for y0, x0, y1, x1, (ox0, oy0, ox1, oy1) in tile_windows(h, w, tile, overlap):
        d = detect(np.ascontiguousarray(image[y0:y1, x0:x1]))
        b = np.asarray(d["boxes"], np.float64).reshape(-1, 4) + np.array([x0, y0, x0, y0])
        cx, cy = (b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2
        keep = (cx >= ox0) & (cx < ox1) & (cy >= oy0) & (cy < oy1)
        boxes.append(b[keep])
        labels.append(np.asarray(d["labels"], np.int64)[keep])
        scores.append(np.asarray(d["scores"], np.float64)[keep])
        if "masks" in d:
            with_masks = True
            m = np.asarray(d["masks"], bool)[keep]
            full = np.zeros((len(m), h, w), bool)
            full[:, y0:y1, x0:x1] = m
            masks.append(full)
    b = np.concatenate(boxes) if boxes else np.zeros((0, 4))
    lab = np.concatenate(labels) if labels else np.zeros(0, np.int64)
    sc = np.concatenate(scores) if scores else np.zeros(0)
    kept = batched_nms(
        torch.from_numpy(b), torch.from_numpy(sc), torch.from_numpy(lab), nms_thresh
    ).numpy()
    kept = kept[np.argsort(-sc[kept], kind="stable")]
    out = {"boxes": b[kept], "labels": lab[kept], "scores": sc[kept]}
    if with_masks:
        out["masks"] = np.concatenate(masks)[kept]
    return out


def segment_tiled(
    segment: Callable[[np.ndarray], np.ndarray],
    image: np.ndarray,
    tile: int,
    overlap: int | float | None = None,
) -> np.ndarray:
    """The class map of a large image, window by window: each pixel takes the label of
    the window that owns it (module docstring).

    Parameters
    ----------
    segment : callable
        One window ``(h, w[, C])`` -> its class map ``(h, w)``.
    image : (H, W) or (H, W, C) ndarray
    tile : int
        The window side (>= 16).
    overlap : int or float, optional
        Pixels, or a fraction of ``tile`` (default :data:`TILE_OVERLAP`).

    Returns
    -------
    (H, W) int64 ndarray

    Examples
    --------
    >>> import numpy as np
    >>> image = np.arange(50 * 70, dtype=float).reshape(50, 70)
    >>> labels = segment_tiled(lambda im: (im > 1000).astype(int), image, tile=32, overlap=8)
    >>> bool((labels == (image > 1000)).all())
    True
    """
    if not callable(segment):
        raise InputError(f"segment must be a function of a window; got {type(segment).__name__}")
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        raise InputError("image must be an (H, W) or (H, W, C) array")
    tile, overlap = check_tiling(tile, overlap)
    h, w = image.shape[:2]
    out = np.zeros((h, w), np.int64)
    for y0, x0, y1, x1, (ox0, oy0, ox1, oy1) in tile_windows(h, w, tile, overlap):
        lab = np.asarray(segment(np.ascontiguousarray(image[y0:y1, x0:x1])))
        if lab.shape != (y1 - y0, x1 - x0):
            raise InputError(
                f"segment gave a map of shape {lab.shape} for a window of {(y1 - y0, x1 - x0)}"
            )
        # owned bounds are integers or half-integers: the pixels whose centres lie inside
        a0, a1 = int(np.ceil(oy0 - 0.5)), int(np.ceil(oy1 - 0.5))
        b0, b1 = int(np.ceil(ox0 - 0.5)), int(np.ceil(ox1 - 0.5))
        out[a0:a1, b0:b1] = lab[a0 - y0 : a1 - y0, b0 - x0 : b1 - x0]
    return out
