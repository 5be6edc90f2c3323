"""Pictures of detections: ``xyxy`` boxes (and instance masks) coloured and captioned
by class on an image (:func:`draw_detections`), and a grid of such images
(:func:`detections_grid`), from NumPy arrays and plain values.

Boxes are continuous ``xyxy`` in pixels, pixel ``(col, row)`` covering
``[col, col + 1) x [row, row + 1)`` (the torchvision and COCO convention), so a box is
outlined on the pixels it covers at its edges. Labels are 1-based (label ``k`` is
``classes[k - 1]``); class ``k`` takes colour ``k`` of
:func:`~robopercept.viz.colormap.label_colors`. The detection sets of
:mod:`robopercept.nn.detection.data` and the detectors' outputs are drawn with these.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_int, check_numeric, plain_repr
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import check_picture_size, draw_boxes, draw_mask, to_rgb8

__all__ = ["detections_grid", "draw_detections"]


def _classes(classes: Any) -> tuple[str, ...]:
    if not isinstance(classes, (list, tuple)) or not classes:
        raise InputError(
            f"classes must be a non-empty list of class names; got {plain_repr(classes)}"
        )
    if not all(isinstance(c, str) and c for c in classes):
        raise InputError(f"classes must be non-empty strings; got {plain_repr(classes)}")
    if len(set(classes)) != len(classes):
        raise InputError(f"classes must be distinct; got {plain_repr(classes)}")
    return tuple(classes)


def _labels(labels: Any, k: int, name: str = "labels") -> np.ndarray:
    y = check_numeric(labels, name).reshape(-1)
    if y.size != k:
        raise InputError(f"{name} must have one label per box ({k}); got {y.size}")
    if np.any(y != np.floor(y)) or np.any((y < 1) | (y > 1 << 30)):
        raise InputError(
            f"{name} must be integers in [1, {1 << 30}] (1-based; 0 is background); "
            f"got {plain_repr(labels)}"
        )
    return y.astype(np.int64)


def _masks(masks: Any, k: int, shape: tuple[int, ...], name: str = "masks") -> np.ndarray:
    m = check_numeric(masks, name)
    if m.size == 0:
        m = m.reshape(0, *shape)
    if m.shape != (k, *shape):
        raise InputError(f"{name} must be (K, H, W) = {(k, *shape)}; got {m.shape}")
    return m != 0


def draw_detections(
    image: np.ndarray,
    boxes: npt.ArrayLike,
    labels: npt.ArrayLike | None = None,
    classes: Sequence[str] | None = None,
    *,
    scores: npt.ArrayLike | None = None,
    masks: npt.ArrayLike | None = None,
    width: int = 1,
) -> np.ndarray:
    """Draw ``xyxy`` boxes (and masks), coloured and captioned by class.

    Box ``(x_1, y_1, x_2, y_2)`` is outlined on its edge pixels, columns ``x_1`` to
    ``x_2 - 1`` (:func:`~robopercept.viz.draw.draw_boxes` of ``(x_1, y_1, x_2 - x_1,
    y_2 - y_1)``); the caption is ``classes[label - 1]`` (or the label), followed by the
    score when given. Masks are blended at 40 % in the class colour
    (:func:`~robopercept.viz.colormap.label_colors`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1].
    boxes : (K, 4) array_like
    labels : (K,) int array_like, optional
        1-based (default: all 1).
    classes : sequence of str, optional
    scores : (K,) array_like, optional
    masks : (K, H, W) array_like, optional
    width : int
        Outline width.

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Examples
    --------
    >>> out = draw_detections(np.zeros((32, 32)), [[4, 16, 12, 28]], [1], ["x"])
    >>> out.shape, bool(out[16, 4].any()), bool(out[27, 11].any()), bool(out[22, 8].any())
    ((32, 32, 3), True, True, False)
    """
    out = to_rgb8(image) if isinstance(image, np.ndarray) else None
    if out is None:
        raise InputError(f"image must be a numpy array; got {type(image).__name__}")
    b = check_numeric(boxes, "boxes")
    if b.size == 0:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError(f"boxes must be (K, 4) xyxy; got shape {b.shape}")
    k = len(b)
    if labels is None:
        lab = np.ones(k, dtype=np.int64)
    else:
        lab = _labels(labels, k)
    names = None if classes is None else _classes(classes)
    sc = None
    if scores is not None:
        sc = check_numeric(scores, "scores").reshape(-1)
        if sc.size != k:
            raise InputError(f"scores must have one value per box ({k}); got {sc.size}")
    if masks is not None:
        m = _masks(masks, k, out.shape[:2])
    colors = label_colors(lab)
    for j in range(k):
        if masks is not None:
            out = draw_mask(out, m[j], color=tuple(int(c) for c in colors[j]), alpha=0.4)
    for j in range(k):
        name = str(lab[j])
        if names is not None and lab[j] <= len(names):
            name = names[lab[j] - 1]
        caption = name if sc is None else f"{name} {sc[j]:.2f}"
        x1, y1, x2, y2 = b[j]
        out = draw_boxes(
            out,
            np.array([[x1, y1, x2 - x1, y2 - y1]]),
            color=tuple(int(c) for c in colors[j]),
            width=width,
            labels=[caption],
        )
    return out


def detections_grid(
    images: Sequence[np.ndarray],
    boxes: Sequence[npt.ArrayLike],
    labels: Sequence[npt.ArrayLike] | None = None,
    classes: Sequence[str] | None = None,
    *,
    masks: Sequence[npt.ArrayLike] | None = None,
    columns: int = 4,
) -> np.ndarray:
    """A grid of images, each with its boxes, labels (and masks) drawn by
    :func:`draw_detections`.

    Parameters
    ----------
    images : list of (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1]; sizes may differ.
    boxes : list of (K_i, 4) array_like
        ``xyxy`` boxes of each image.
    labels : list of (K_i,) int array_like, optional
        1-based labels of each image's boxes (default: all 1).
    classes : sequence of str, optional
    masks : list of (K_i, H, W) array_like, optional
        Instance masks of each image.
    columns : int
        Images per row (>= 1).

    Returns
    -------
    (rows * H_max + gaps, columns * W_max + gaps, 3) uint8 ndarray
        Images top-left aligned in cells of the largest size, 2-pixel white gaps.

    Raises
    ------
    InputError
        No images, lists of different lengths, or a bad image, box, label or mask.

    Examples
    --------
    >>> pic = detections_grid([np.zeros((32, 32))] * 3, [[[4, 4, 12, 12]]] * 3)
    >>> pic.shape
    (32, 100, 3)
    """
    if not isinstance(images, (list, tuple)) or not images:
        raise InputError(
            f"images must be a non-empty list of (H, W[, 3]) arrays; got {plain_repr(images)}"
        )
    n = len(images)
    for name, value in (("boxes", boxes), ("labels", labels), ("masks", masks)):
        if (value is not None or name == "boxes") and (
            not isinstance(value, (list, tuple)) or len(value) != n
        ):
            raise InputError(f"{name} must be a list with one entry per image ({n})")
    for i, im in enumerate(images):
        if not isinstance(im, np.ndarray) or im.ndim not in (2, 3):
            raise InputError(f"images[{i}] must be an (H, W[, 3]) numpy array")
    columns = check_int(columns, "columns", 1)
    hmax = max(im.shape[0] for im in images)
    wmax = max(im.shape[1] for im in images)
    cols = min(columns, n)
    rows = -(-n // cols)
    gap = 2
    pw, ph = check_picture_size(cols * (wmax + gap) - gap, rows * (hmax + gap) - gap)
    out = np.full((ph, pw, 3), 255, dtype=np.uint8)
    for i, im in enumerate(images):
        pic = draw_detections(
            im,
            boxes[i],
            None if labels is None else labels[i],
            classes,
            masks=None if masks is None else masks[i],
        )
        r, c = divmod(i, cols)
        y, x = r * (hmax + gap), c * (wmax + gap)
        out[y : y + im.shape[0], x : x + im.shape[1]] = pic
    return out
