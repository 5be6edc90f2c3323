"""Axis-aligned boxes in pixels: ``(x, y, w, h)`` for the IoU matrix, and conversions
between the formats ``"xyxy"``, ``"xywh"`` and ``"cxcywh"`` (NumPy; the torch versions
used by the detectors are in :mod:`robopercept.nn.boxes`)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_choice, check_finite, check_magnitude, check_numeric
from robopercept.errors import InputError

__all__ = ["BOX_FORMATS", "box_convert", "box_iou_matrix"]

#: the box formats of :func:`box_convert`
BOX_FORMATS = ("xyxy", "xywh", "cxcywh")


def _boxes(boxes: npt.ArrayLike, name: str, fmt: str = "(x, y, w, h)") -> np.ndarray:
    """``boxes`` as a finite float64 ``(N, 4)`` array (one ``(4,)`` box too)."""
    arr = check_numeric(boxes, name)
    if arr.shape == (4,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(f"{name} must be (N, 4) boxes {fmt} or one (4,) box; got {arr.shape}")
    check_finite(arr, name)
    return check_magnitude(arr, name, 1e150)  # w * h of larger boxes overflows


def box_iou_matrix(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    r"""Intersection over union of every box of ``a`` ``(M, 4)`` with every box of ``b``
    ``(N, 4)``: :math:`|A \cap B| / |A \cup B|`, 0 where the union is empty.

    Parameters
    ----------
    a, b : (M, 4), (N, 4) array_like
        Boxes ``(x, y, w, h)`` in pixels (a single ``(4,)`` box counts as ``(1, 4)``),
        finite and at most 1e150 in magnitude.

    Returns
    -------
    (M, N) ndarray

    Raises
    ------
    InputError
        Another shape, non-numeric values, NaN/inf, or values beyond 1e150.

    Examples
    --------
    >>> box_iou_matrix([0, 0, 2, 2], [[1, 0, 2, 2], [5, 5, 1, 1]]).round(4).tolist()
    [[0.3333, 0.0]]
    """
    a = _boxes(a, "a")
    b = _boxes(b, "b")
    x0 = np.maximum(a[:, None, 0], b[None, :, 0])
    y0 = np.maximum(a[:, None, 1], b[None, :, 1])
    x1 = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2])
    y1 = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def box_convert(boxes: npt.ArrayLike, in_fmt: str, out_fmt: str) -> np.ndarray:
    r"""Convert boxes between ``"xyxy"`` (corners), ``"xywh"`` (COCO's corner and size)
    and ``"cxcywh"`` (centre and size), as torchvision's ``ops.box_convert``.

    .. math::
        x_2 = x_1 + w,\quad c_x = x_1 + w / 2 \quad(\text{same in } y)

    Parameters
    ----------
    boxes : (N, 4) or (4,) array_like
        Finite, at most 1e150 in magnitude.
    in_fmt, out_fmt : {"xyxy", "xywh", "cxcywh"}

    Returns
    -------
    (N, 4) ndarray of float64
        A new array (a single box comes back as ``(1, 4)``).

    Raises
    ------
    InputError
        Another shape, non-numeric values, NaN/inf, huge values, an unknown format.

    Examples
    --------
    >>> box_convert([10, 20, 4, 6], "xywh", "xyxy").tolist()
    [[10.0, 20.0, 14.0, 26.0]]
    """
    check_choice(in_fmt, "in_fmt", BOX_FORMATS)
    check_choice(out_fmt, "out_fmt", BOX_FORMATS)
    b = _boxes(boxes, "boxes", f"in the format {in_fmt!r}").copy()
    if in_fmt == "xywh":
        b[:, 2:] += b[:, :2]
    elif in_fmt == "cxcywh":
        b = np.concatenate([b[:, :2] - b[:, 2:] / 2, b[:, :2] + b[:, 2:] / 2], axis=1)
    if out_fmt == "xywh":
        b[:, 2:] -= b[:, :2]
    elif out_fmt == "cxcywh":
        b = np.concatenate([(b[:, :2] + b[:, 2:]) / 2, b[:, 2:] - b[:, :2]], axis=1)
    return b
