"""Axis-aligned boxes in pixels: ``(x, y, w, h)`` for the IoU matrix, and conversions
between the formats ``"xyxy"``, ``"xywh"`` and ``"cxcywh"`` (NumPy; the torch versions
used by the detectors are in :mod:`robopercept.nn.ops.boxes`); the smallest rotated
rectangle around 2-D points (:func:`min_area_rectangle`)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_choice, check_finite, check_magnitude, check_numeric
from robopercept.errors import InputError

__all__ = ["BOX_FORMATS", "box_convert", "box_iou_matrix", "min_area_rectangle"]

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


def min_area_rectangle(points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
    r"""The smallest-area rectangle enclosing 2-D points, at any rotation.

    One side of the optimal rectangle lies along an edge of the points' convex hull
    (Freeman and Shapira 1975), so each hull edge direction :math:`\theta` is tried:
    the points are rotated by :math:`-\theta`, their axis-aligned bounds taken, and the
    smallest area kept (rotating calipers, :math:`O(h^2)` for :math:`h` hull vertices).
    The area equals that of ``cv2.minAreaRect``; the sides may be named the other way
    round (OpenCV's angle convention differs).

    Parameters
    ----------
    points : (N, 2) array_like
        Finite points, ``N >= 1``. Collinear points give a rectangle of width 0, one
        point (or repeats of it) a rectangle of size 0.

    Returns
    -------
    center : (2,) ndarray
    half_sizes : (2,) ndarray
        Half the side lengths, along ``(cos t, sin t)`` then ``(-sin t, cos t)``.
    angle : float
        ``t`` in radians, in ``[0, pi/2)``.

    Raises
    ------
    InputError
        Not finite ``(N, 2)`` points with ``N >= 1``.

    Examples
    --------
    >>> square = [[0, 1], [1, 0], [2, 1], [1, 2]]  # a square turned by 45 degrees
    >>> c, h, t = min_area_rectangle(square)
    >>> c.round(6).tolist(), h.round(6).tolist(), round(float(np.degrees(t)), 6)
    ([1.0, 1.0], [0.707107, 0.707107], 45.0)
    """
    pts = check_numeric(points, "points")
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1:
        raise InputError(f"points must be (N, 2) with N >= 1; got shape {pts.shape}")
    pts = check_magnitude(check_finite(pts.astype(np.float64), "points"), "points", 1e150)
    hull = pts
    if len(np.unique(pts, axis=0)) >= 3:
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = pts[ConvexHull(pts).vertices]
        except QhullError:  # collinear: every point is a vertex of the flat "hull"
            hull = pts
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2)
    angles = np.unique(np.concatenate([[0.0], angles]))
    cos, sin = np.cos(angles), np.sin(angles)
    u = hull @ np.stack([cos, sin])  # (h, k): coordinates along each candidate side
    v = hull @ np.stack([-sin, cos])
    area = np.ptp(u, axis=0) * np.ptp(v, axis=0)
    k = int(np.argmin(area))
    lo_u, hi_u, lo_v, hi_v = u[:, k].min(), u[:, k].max(), v[:, k].min(), v[:, k].max()
    cu, cv = (lo_u + hi_u) / 2, (lo_v + hi_v) / 2
    center = cu * np.array([cos[k], sin[k]]) + cv * np.array([-sin[k], cos[k]])
    half = np.array([(hi_u - lo_u) / 2, (hi_v - lo_v) / 2])
    return center, half, float(angles[k])
