r"""Binary and grey-level morphology with a structuring element.

Erosion and dilation are the minimum and maximum over the structuring element
:math:`B` (anchored at its centre):

.. math:: (f \ominus B)(p) = \min_{b \in B} f(p + b), \qquad
          (f \oplus B)(p) = \max_{b \in B} f(p - b)

Pixels outside the image never win (they count as +inf for erosion and -inf for
dilation), which is OpenCV's default border. Opening is erosion then dilation, closing
the reverse. All four match ``cv2.erode``/``cv2.dilate``/``cv2.morphologyEx`` exactly.
"""

from __future__ import annotations

import hashlib

import numpy as np

from robopercept._checks import check_choice, check_image, check_int, check_ndim, plain_repr
from robopercept.errors import InputError

__all__ = ["MAX_ELEMENT_SIZE", "closing", "dilate", "erode", "opening", "structuring_element"]

#: the largest side of a :func:`structuring_element` (OpenCV builds any size; an element
#: of 2**40 pixels would ask for terabytes): 4095 pixels, 16 MiB for a square
MAX_ELEMENT_SIZE = 4095


def structuring_element(shape: str, size: int | tuple[int, int]) -> np.ndarray:
    """A ``rect``, ``cross`` or ``ellipse`` structuring element, as ``cv2.getStructuringElement``.

    Parameters
    ----------
    shape : {'rect', 'cross', 'ellipse'}
    size : int or (width, height)
        Integers in ``[1, MAX_ELEMENT_SIZE]`` (4095).

    Returns
    -------
    (height, width) bool ndarray

    Raises
    ------
    InputError
        An unknown shape, or a size that is not one or two integers in range.

    Examples
    --------
    >>> structuring_element("cross", 3).astype(int)
    array([[0, 1, 0],
           [1, 1, 1],
           [0, 1, 0]])
    """
    check_choice(shape, "shape", ("rect", "cross", "ellipse"))
    pair = tuple(size) if isinstance(size, (tuple, list)) else (size, size)
    if len(pair) != 2:
        raise InputError(f"size must be an int or (width, height); got {plain_repr(size)}")
    w, h = check_int(pair[0], "size (width)"), check_int(pair[1], "size (height)")
    if not (1 <= w <= MAX_ELEMENT_SIZE and 1 <= h <= MAX_ELEMENT_SIZE):
        raise InputError(
            f"size must be in [1, {MAX_ELEMENT_SIZE}] pixels per side; got {plain_repr(size)}: "
            "for a wider element, work on a downsampled image (robopercept.imaging.pyr_down)"
        )
    if shape == "rect":
        return np.ones((h, w), dtype=bool)
    if shape == "cross":
        se = np.zeros((h, w), dtype=bool)
        se[h // 2, :] = True
        se[:, w // 2] = True
        return se
    # ellipse, following OpenCV: per row, the half-width of the inscribed ellipse
    se = np.zeros((h, w), dtype=bool)
    r, c = h // 2, w // 2
    inv_r2 = 1.0 / (r * r) if r > 0 else 0.0
    for i in range(h):
        dy = i - r
        if abs(dy) <= r:
            dx = round(c * np.sqrt(max(0.0, (r * r - dy * dy) * inv_r2))) if r > 0 else c
            se[i, max(c - dx, 0) : min(c + dx + 1, w)] = True
    return se


def _check_se(se: np.ndarray | None) -> np.ndarray:
    if se is None:
        return np.ones((3, 3), dtype=bool)
    se = check_ndim(se, "structuring element", (2,))
    if se.size == 0 or not np.any(se):
        raise InputError("structuring element must have at least one nonzero element")
    return se.astype(bool)


def _rank(image: np.ndarray, se: np.ndarray, op: str, iterations: int) -> np.ndarray:
    image = check_image(image, allow_bool=True)
    se = _check_se(se)
    iterations = check_int(iterations, "iterations", 1)
    is_bool = image.dtype == np.bool_
    work = image.view(np.uint8) if is_bool else image
    kh, kw = se.shape
    ay, ax = kh // 2, kw // 2
    if work.dtype.kind == "f":
        fill = np.inf if op == "min" else -np.inf
    else:
        info = np.iinfo(work.dtype)
        fill = info.max if op == "min" else info.min
    reduce = np.minimum if op == "min" else np.maximum
    # dilation reflects the element: max over f(p - b)
    offsets = np.argwhere(se) - (ay, ax)
    if op == "max":
        offsets = -offsets
    top, left = max(0, -offsets[:, 0].min()), max(0, -offsets[:, 1].min())
    bottom, right = max(0, offsets[:, 0].max()), max(0, offsets[:, 1].max())
    h, w = work.shape[:2]
    pad = ((top, bottom), (left, right)) + (((0, 0),) if work.ndim == 3 else ())
    out = work
    # Each pass is a function of the previous result only, so once a result repeats
    # the sequence is periodic from there and the remaining passes can be skipped
    # exactly: a large ``iterations`` (2**63) costs the passes until the result stops
    # changing (about the image's size for an element that holds its anchor), not a hang.
    seen: dict[bytes, int] | None = {}
    k = 0
    while k < iterations:
        padded = np.pad(out, pad, constant_values=fill)
        acc = None
        for dy, dx in offsets:
            view = padded[top + dy : top + dy + h, left + dx : left + dx + w]
            acc = view.copy() if acc is None else reduce(acc, view, out=acc)
        out = acc
        k += 1
        if seen is not None and iterations - k > 1:
            key = hashlib.blake2b(out.tobytes(), digest_size=16).digest()
            if key in seen:  # pass k repeats pass seen[key]: periodic from here
                iterations = k + (iterations - k) % (k - seen[key])
                seen = None  # (the few passes left need no more bookkeeping)
            else:
                seen[key] = k
    return _as_result(out, is_bool)


def _as_result(out: np.ndarray, is_bool: bool) -> np.ndarray:
    return out.view(np.bool_) if is_bool else out


def erode(image: np.ndarray, se: np.ndarray | None = None, iterations: int = 1) -> np.ndarray:
    """Erosion: the minimum of ``image`` over the structuring element (3x3 square by default).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray, bool or numeric
    se : (kh, kw) array_like of bool, optional
        Structuring element, anchored at ``(kh // 2, kw // 2)``.
    iterations : int
        Passes, >= 1 (any size: once the result repeats, the remaining passes are
        skipped exactly).

    Returns
    -------
    ndarray
        Same shape and dtype.
    """
    return _rank(image, se, "min", iterations)


def dilate(image: np.ndarray, se: np.ndarray | None = None, iterations: int = 1) -> np.ndarray:
    """Dilation: the maximum of ``image`` over the reflected structuring element.

    See :func:`erode` for the parameters.

    Examples
    --------
    The default 3x3 square grows one pixel into a 3x3 block:

    >>> m = np.zeros((5, 5), np.uint8); m[2, 2] = 1
    >>> dilate(m)
    array([[0, 0, 0, 0, 0],
           [0, 1, 1, 1, 0],
           [0, 1, 1, 1, 0],
           [0, 1, 1, 1, 0],
           [0, 0, 0, 0, 0]], dtype=uint8)
    """
    return _rank(image, se, "max", iterations)


def opening(image: np.ndarray, se: np.ndarray | None = None) -> np.ndarray:
    r"""Opening :math:`(f \ominus B) \oplus B`: removes bright specks smaller than ``se``."""
    return dilate(erode(image, se), se)


def closing(image: np.ndarray, se: np.ndarray | None = None) -> np.ndarray:
    r"""Closing :math:`(f \oplus B) \ominus B`: fills dark gaps smaller than ``se``."""
    return erode(dilate(image, se), se)
