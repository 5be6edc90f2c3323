r"""Axis-aligned boxes in pixels, in NumPy: conversions between the formats ``"xyxy"``,
``"xywh"`` and ``"cxcywh"``, the IoU matrix, greedy non-maximum suppression (the one
box toolkit: the HOG detector of :mod:`robopercept.learning.hog_detector` and the torch
``nms`` of :mod:`robopercept.nn.ops.nms` both call it), and the smallest rotated
rectangle around 2-D points (:func:`min_area_rectangle`). The torch IoU and GIoU, which
need autograd, are in :mod:`robopercept.nn.ops.boxes`.

IoU arithmetic (float64, the same in every function here): with the corners
:math:`(x_1, y_1, x_2, y_2)` and the area :math:`a` of each box (``w h`` for
``"xywh"`` and ``"cxcywh"``, :math:`(x_2 - x_1)(y_2 - y_1)` for ``"xyxy"``),

.. math::
    I = \max(0, \min(x_2, x_2') - \max(x_1, x_1'))\,
        \max(0, \min(y_2, y_2') - \max(y_1, y_1')),\quad
    \mathrm{IoU} = \frac{I}{a + a' - I}

and 0 where the union :math:`a + a' - I` is not positive.

Greedy NMS: the boxes are ranked by decreasing score (ties by index: a stable sort of
``-scores``); the best box is kept and every later box of its class whose IoU with it
exceeds the threshold (strictly: ``not IoU <= threshold``, so an IoU equal to the
threshold does not suppress) is dropped; a dropped box suppresses nothing; repeat with
the next box still alive. This is torchvision's ``ops.nms`` and onnxruntime's
``NonMaxSuppression`` (tested in ``tests/nn/ops/test_nms.py``); the loop is sequential,
so the result does not depend on the number of threads. :func:`greedy_suppression` is
the compiled loop, :func:`greedy_suppression_reference` its NumPy reference.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_choice,
    check_finite,
    check_magnitude,
    check_numeric,
    check_real,
    squeeze_point_axis,
)
from robopercept.errors import InputError

__all__ = [
    "BOX_FORMATS",
    "box_convert",
    "box_iou_matrix",
    "corners_and_areas",
    "greedy_nms",
    "greedy_suppression",
    "greedy_suppression_reference",
    "min_area_rectangle",
]

#: the box formats of :func:`box_convert`
BOX_FORMATS = ("xyxy", "xywh", "cxcywh")

_FORMAT_TEXT = {"xywh": "(x, y, w, h)", "xyxy": "(x1, y1, x2, y2)", "cxcywh": "(cx, cy, w, h)"}


def _boxes(boxes: npt.ArrayLike, name: str, fmt: str = "(x, y, w, h)") -> np.ndarray:
    """``boxes`` as a finite float64 ``(N, 4)`` array (one ``(4,)`` box too)."""
    arr = check_numeric(boxes, name)
    if arr.shape == (4,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(f"{name} must be (N, 4) boxes {fmt} or one (4,) box; got {arr.shape}")
    check_finite(arr, name)
    return check_magnitude(arr, name, 1e150)  # w * h of larger boxes overflows


def _checked(boxes: npt.ArrayLike, name: str, fmt: str) -> np.ndarray:
    """:func:`_boxes` in format ``fmt``; ``"xyxy"`` boxes must have ordered corners."""
    b = _boxes(boxes, name, _FORMAT_TEXT[fmt])
    if fmt == "xyxy":
        bad = (b[:, 2] < b[:, 0]) | (b[:, 3] < b[:, 1])
        if bad.any():
            i = int(np.nonzero(bad)[0][0])
            raise InputError(
                f"{name} must be (x1, y1, x2, y2) with x1 <= x2 and y1 <= y2; row {i} is "
                f"{b[i].tolist()}: (x, y, w, h) boxes? pass fmt='xywh'"
            )
    return b


def corners_and_areas(boxes: np.ndarray, fmt: str = "xywh") -> tuple[np.ndarray, np.ndarray]:
    r"""The corners :math:`(x_1, y_1, x_2, y_2)` and areas of checked float64 boxes: the
    two arrays every IoU and NMS here works on.

    ``"xywh"``: :math:`x_2 = x + w`, area :math:`w h`; ``"cxcywh"``:
    :math:`x_1 = c_x - w/2`, :math:`x_2 = c_x + w/2`, area :math:`w h`; ``"xyxy"``: the
    boxes themselves, area :math:`(x_2 - x_1)(y_2 - y_1)`. Not checked (the callers
    check): pass finite float64 ``(N, 4)`` arrays.

    Parameters
    ----------
    boxes : (N, 4) ndarray of float64
    fmt : {"xywh", "xyxy", "cxcywh"}

    Returns
    -------
    corners : (N, 4) ndarray of float64
        C-contiguous.
    areas : (N,) ndarray of float64

    Examples
    --------
    >>> c, a = corners_and_areas(np.array([[1.0, 2.0, 3.0, 4.0]]), "xywh")
    >>> c.tolist(), a.tolist()
    ([[1.0, 2.0, 4.0, 6.0]], [12.0])
    """
    if fmt == "xyxy":
        corners = boxes
        areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    elif fmt == "xywh":
        corners = np.concatenate([boxes[:, :2], boxes[:, :2] + boxes[:, 2:]], axis=1)
        areas = boxes[:, 2] * boxes[:, 3]
    else:
        half = boxes[:, 2:] / 2
        corners = np.concatenate([boxes[:, :2] - half, boxes[:, :2] + half], axis=1)
        areas = boxes[:, 2] * boxes[:, 3]
    return np.ascontiguousarray(corners, dtype=np.float64), np.ascontiguousarray(areas)


def _iou(ca: np.ndarray, aa: np.ndarray, cb: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """The ``(M, N)`` IoU of corners ``ca`` (areas ``aa``) with ``cb`` (areas ``ab``)."""
    x0 = np.maximum(ca[:, None, 0], cb[None, :, 0])
    y0 = np.maximum(ca[:, None, 1], cb[None, :, 1])
    x1 = np.minimum(ca[:, None, 2], cb[None, :, 2])
    y1 = np.minimum(ca[:, None, 3], cb[None, :, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = aa[:, None] + ab[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def box_iou_matrix(a: npt.ArrayLike, b: npt.ArrayLike, fmt: str = "xywh") -> np.ndarray:
    r"""Intersection over union of every box of ``a`` ``(M, 4)`` with every box of ``b``
    ``(N, 4)``: :math:`|A \cap B| / |A \cup B|`, 0 where the union is empty (the
    arithmetic is in the module docstring).

    Parameters
    ----------
    a, b : (M, 4), (N, 4) array_like
        Boxes in pixels (a single ``(4,)`` box counts as ``(1, 4)``), finite and at most
        1e150 in magnitude.
    fmt : {"xywh", "xyxy", "cxcywh"}
        The format of both: ``(x, y, w, h)`` by default; ``"xyxy"`` boxes need
        ``x1 <= x2`` and ``y1 <= y2``.

    Returns
    -------
    (M, N) ndarray

    Raises
    ------
    InputError
        Another shape, non-numeric values, NaN/inf, values beyond 1e150, an unknown
        format, or unordered ``"xyxy"`` corners.

    Examples
    --------
    >>> box_iou_matrix([0, 0, 2, 2], [[1, 0, 2, 2], [5, 5, 1, 1]]).round(4).tolist()
    [[0.3333, 0.0]]
    >>> box_iou_matrix([0, 0, 2, 2], [[1, 0, 3, 2]], fmt="xyxy").round(4).tolist()
    [[0.3333]]
    """
    check_choice(fmt, "fmt", BOX_FORMATS)
    ca, aa = corners_and_areas(_checked(a, "a", fmt), fmt)
    cb, ab = corners_and_areas(_checked(b, "b", fmt), fmt)
    return _iou(ca, aa, cb, ab)


def greedy_nms(
    boxes: npt.ArrayLike,
    scores: npt.ArrayLike,
    iou_threshold: float,
    *,
    fmt: str = "xywh",
    classes: npt.ArrayLike | None = None,
) -> np.ndarray:
    """Greedy non-maximum suppression (the rule is in the module docstring): the indices
    of the kept boxes, best score first.

    Parameters
    ----------
    boxes : (N, 4) array_like
        Finite, at most 1e150 in magnitude, in format ``fmt``.
    scores : (N,) array_like
        Real numbers, no NaN (a NaN has no rank); ``-inf`` is allowed.
    iou_threshold : float
        A box whose IoU with a kept box is above it is dropped; usually in ``[0, 1]``
        (1 or more keeps every box, below 0 keeps one box per class).
    fmt : {"xywh", "xyxy", "cxcywh"}
    classes : (N,) array_like of int, optional
        A box suppresses only boxes of its class; None: one class.

    Returns
    -------
    (K,) ndarray of int64

    Raises
    ------
    InputError
        Bad boxes (see :func:`box_iou_matrix`), scores or classes of another length,
        NaN scores, non-integer classes, a threshold that is not a finite number.

    Examples
    --------
    >>> b = [[0, 0, 10, 10], [1, 0, 10, 10], [20, 20, 5, 5]]
    >>> greedy_nms(b, [0.9, 0.95, 0.5], 0.5).tolist()
    [1, 2]
    """
    check_choice(fmt, "fmt", BOX_FORMATS)
    b = _checked(boxes, "boxes", fmt)
    n = b.shape[0]
    s = check_numeric(scores, "scores").ravel()
    if s.size != n:
        raise InputError(f"scores must hold one score per box ({n}); got {s.size}")
    if np.isnan(s).any():
        raise InputError(
            f"scores must not hold NaN (a NaN score has no rank); got {int(np.isnan(s).sum())}: "
            "drop them or use np.nan_to_num(scores, nan=-np.inf)"
        )
    thr = check_real(iou_threshold, "iou_threshold")
    if classes is None:
        cls = np.zeros(n, dtype=np.int64)
    else:
        cls = np.asarray(classes)
        if cls.shape != (n,) or cls.dtype.kind not in "iu":
            raise InputError(
                f"classes must be ({n},) integer class ids, one per box; got "
                f"{cls.dtype} {cls.shape}: use np.asarray(classes, dtype=np.int64)"
            )
    order = np.argsort(-s, kind="stable")
    corners, areas = corners_and_areas(b[order], fmt)
    alive = greedy_suppression(corners, areas, np.ascontiguousarray(cls[order], np.int64), thr)
    return order[alive].astype(np.int64)


def greedy_suppression_reference(
    corners: np.ndarray, areas: np.ndarray, classes: np.ndarray, iou_threshold: float
) -> np.ndarray:
    """The greedy loop of :func:`greedy_nms` in NumPy (one box against the rest at a
    time): the reference of its compiled kernel :func:`greedy_suppression`.

    Parameters
    ----------
    corners : (N, 4) ndarray of float64
        ``(x1, y1, x2, y2)``, already sorted best first (not checked; see
        :func:`corners_and_areas`).
    areas : (N,) ndarray of float64
    classes : (N,) ndarray of int64
        A box suppresses only boxes of its class (all 0 for plain NMS).
    iou_threshold : float

    Returns
    -------
    (N,) ndarray of bool
        Which sorted boxes are kept.

    Examples
    --------
    >>> c = np.array([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30]])
    >>> greedy_suppression_reference(c, np.full(3, 100.0), np.zeros(3, np.int64), 0.5).tolist()
    [True, False, True]
    """
    n = corners.shape[0]
    alive = np.ones(n, dtype=bool)
    for i in range(n):
        if not alive[i]:
            continue
        rest = np.nonzero(alive[i + 1 :])[0] + i + 1
        rest = rest[classes[rest] == classes[i]]
        if rest.size == 0:
            continue
        iou = _iou(corners[i : i + 1], areas[i : i + 1], corners[rest], areas[rest])[0]
        alive[rest[~(iou <= iou_threshold)]] = False
    return alive


@njit(cache=True)
def greedy_suppression(
    corners: np.ndarray, areas: np.ndarray, classes: np.ndarray, iou_threshold: float
) -> np.ndarray:
    """:func:`greedy_suppression_reference`, compiled: the same float64 arithmetic, in
    the same order, so the two agree exactly.

    Parameters
    ----------
    corners : (N, 4) ndarray of float64
        ``(x1, y1, x2, y2)``, C-contiguous, already sorted best first (not checked).
    areas : (N,) ndarray of float64
    classes : (N,) ndarray of int64
    iou_threshold : float

    Returns
    -------
    (N,) ndarray of bool
        Which sorted boxes are kept.

    Examples
    --------
    >>> c = np.array([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30]])
    >>> greedy_suppression(c, np.full(3, 100.0), np.zeros(3, np.int64), 0.5).tolist()
    [True, False, True]
    """
    n = corners.shape[0]
    alive = np.ones(n, dtype=np.bool_)
    for i in range(n):
        if not alive[i]:
            continue
        x1, y1, x2, y2 = corners[i, 0], corners[i, 1], corners[i, 2], corners[i, 3]
        for j in range(i + 1, n):
            if not alive[j] or classes[j] != classes[i]:
                continue
            w = min(x2, corners[j, 2]) - max(x1, corners[j, 0])
            h = min(y2, corners[j, 3]) - max(y1, corners[j, 1])
            iou = 0.0
            if w > 0.0 and h > 0.0:
                inter = w * h
                union = areas[i] + areas[j] - inter
                if union > 0.0:
                    iou = inter / union
            if not iou <= iou_threshold:
                alive[j] = False
    return alive


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
    pts = squeeze_point_axis(check_numeric(points, "points"), 2)  # OpenCV's (N, 1, 2) too
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
