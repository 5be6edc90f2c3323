r"""Box operations of the R-CNN family, in torch: formats, IoU and GIoU, Faster R-CNN
box coding, anchors, greedy non-maximum suppression, RoI pooling, RoI Align and its
inverse, pasting per-box masks back into the image.

Box formats (all in pixels, floating point, one box per row):

- ``"xyxy"``: ``(x1, y1, x2, y2)``, the corners; width ``x2 - x1`` (the modern
  torchvision convention, not the ``+ 1`` of the original Caffe code).
- ``"xywh"``: ``(x1, y1, w, h)``, COCO's ``bbox``.
- ``"cxcywh"``: ``(cx, cy, w, h)``, the centre and the size.

Every function that takes boxes takes ``"xyxy"`` unless it says otherwise; a box with
``x2 < x1`` or ``y2 < y1`` is refused (convert it, or fix its corners), a box of zero
width or height is allowed and has area 0 (its IoU with anything is 0, as its union is
empty or its intersection is).

References matched (tests pin each): ``pycocotools.mask.iou`` for the IoU matrix,
onnxruntime's ``NonMaxSuppression`` for NMS and its ``RoiAlign`` (opset 16) for RoI
Align; torchvision's conventions for box coding, anchors and RoI pooling (looked up,
not imported: torchvision is not a dependency).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from numba import njit

from robopercept._checks import check_bool, check_choice, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation, check_float_dtype

__all__ = [
    "FORMATS",
    "AnchorGenerator",
    "BoxCoder",
    "RoIAlign",
    "RoIPool",
    "batched_nms",
    "box_area",
    "box_convert",
    "box_iou",
    "dihedral_boxes",
    "generalized_box_iou",
    "nms",
    "non_max_suppression",
    "paste_masks",
    "roi_align",
    "roi_pool",
]

#: the box formats of :func:`box_convert`
FORMATS = ("xyxy", "xywh", "cxcywh")


# --------------------------------------------------------------------------- guards
def _limit(dtype: torch.dtype) -> float:
    """Largest coordinate whose products (areas) stay finite in ``dtype``."""
    return math.sqrt(torch.finfo(dtype).max) / 4.0


def _check_boxes(boxes: Any, name: str, cols: int = 4, *, ordered: bool = True) -> torch.Tensor:
    """``boxes`` after checking it is a finite floating ``(N, cols)`` tensor (and, with
    ``ordered``, ``x1 <= x2``, ``y1 <= y2``)."""
    if not isinstance(boxes, torch.Tensor):
        raise InputError(
            f"{name} must be a torch.Tensor of shape (N, {cols}); got {type(boxes).__name__}: "
            f"convert it with torch.as_tensor({name}, dtype=torch.float32)"
        )
    if boxes.ndim != 2 or boxes.shape[1] != cols:
        hint = f": one box? use {name}[None]" if tuple(boxes.shape) == (cols,) else ""
        raise InputError(f"{name} must have shape (N, {cols}); got {tuple(boxes.shape)}{hint}")
    if not boxes.is_floating_point():
        raise InputError(f"{name} must be floating point; got {boxes.dtype}: use {name}.float()")
    if boxes.numel():
        if not bool(torch.isfinite(boxes).all()):
            raise InputError(
                f"{name} must be finite; got NaN/inf coordinates: drop those rows first, "
                f"e.g. {name}[torch.isfinite({name}).all(1)]"
            )
        big = float(boxes.detach().abs().max())
        if big > _limit(boxes.dtype):
            raise InputError(
                f"{name} has coordinates up to {big:.3g}; beyond {_limit(boxes.dtype):.3g} "
                f"their areas overflow {boxes.dtype}: use float64 or rescale the boxes"
            )
        if ordered and cols == 4:
            bad = (boxes[:, 2] < boxes[:, 0]) | (boxes[:, 3] < boxes[:, 1])
            if bool(bad.any()):
                i = int(torch.nonzero(bad)[0, 0])
                raise InputError(
                    f"{name} must be (x1, y1, x2, y2) with x1 <= x2 and y1 <= y2; row {i} is "
                    f"{plain_repr(boxes[i].tolist())}: (x, y, w, h) boxes? convert with "
                    f"box_convert({name}, 'xywh', 'xyxy')"
                )
    return boxes


def _check_scores(scores: Any, n: int, name: str = "scores") -> torch.Tensor:
    if not isinstance(scores, torch.Tensor):
        raise InputError(
            f"{name} must be a torch.Tensor of shape ({n},); got {type(scores).__name__}: "
            f"convert it with torch.as_tensor({name})"
        )
    if tuple(scores.shape) != (n,):
        raise InputError(f"{name} must have shape ({n},), one per box; got {tuple(scores.shape)}")
    if not scores.is_floating_point():
        raise InputError(f"{name} must be floating point; got {scores.dtype}: use {name}.float()")
    if n and bool(torch.isnan(scores).any()):
        raise InputError(
            f"{name} must not hold NaN (a NaN score has no rank); got "
            f"{int(torch.isnan(scores).sum())}: drop them or use torch.nan_to_num({name}, nan=-inf)"
        )
    return scores


def _check_threshold(value: Any, name: str) -> float:
    return check_real(value, name, 0.0, 1.0)


# --------------------------------------------------------------------------- formats
def box_convert(boxes: torch.Tensor, in_fmt: str, out_fmt: str) -> torch.Tensor:
    r"""Convert boxes between ``"xyxy"``, ``"xywh"`` and ``"cxcywh"`` (as torchvision's
    ``ops.box_convert``).

    .. math::
        x_2 = x_1 + w,\quad c_x = x_1 + w/2,\quad x_1 = c_x - w/2 \quad(\text{same in } y)

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
        Floating point, finite (the order of corners is not checked here).
    in_fmt, out_fmt : {"xyxy", "xywh", "cxcywh"}

    Returns
    -------
    (N, 4) torch.Tensor
        A new tensor (``boxes`` itself when the formats are the same).

    Raises
    ------
    InputError
        Not a floating ``(N, 4)`` tensor, NaN/inf, or an unknown format.

    Examples
    --------
    >>> import torch
    >>> box_convert(torch.tensor([[10.0, 20.0, 4.0, 6.0]]), "xywh", "cxcywh").tolist()
    [[12.0, 23.0, 4.0, 6.0]]
    """
    boxes = _check_boxes(boxes, "boxes", ordered=False)
    check_choice(in_fmt, "in_fmt", FORMATS)
    check_choice(out_fmt, "out_fmt", FORMATS)
    if in_fmt == out_fmt:
        return boxes
    a, b, c, d = boxes.unbind(-1)
    if in_fmt == "xywh":
        a, b, c, d = a, b, a + c, b + d
    elif in_fmt == "cxcywh":
        a, b, c, d = a - c / 2, b - d / 2, a + c / 2, b + d / 2
    # (a, b, c, d) are now x1, y1, x2, y2
    if out_fmt == "xywh":
        return torch.stack((a, b, c - a, d - b), -1)
    if out_fmt == "cxcywh":
        return torch.stack(((a + c) / 2, (b + d) / 2, c - a, d - b), -1)
    return torch.stack((a, b, c, d), -1)


def box_area(boxes: torch.Tensor) -> torch.Tensor:
    r"""Areas :math:`(x_2 - x_1)(y_2 - y_1)` of ``"xyxy"`` boxes.

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
        ``(x1, y1, x2, y2)`` with ``x1 <= x2``, ``y1 <= y2``.

    Returns
    -------
    (N,) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> box_area(torch.tensor([[0.0, 0.0, 2.0, 3.0], [1.0, 1.0, 1.0, 5.0]])).tolist()
    [6.0, 0.0]
    """
    boxes = _check_boxes(boxes, "boxes")
    return _area(boxes)


def _area(b: torch.Tensor) -> torch.Tensor:
    return (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])


def _inter_union(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    lt = torch.maximum(a[:, None, :2], b[None, :, :2])
    rb = torch.minimum(a[:, None, 2:], b[None, :, 2:])
    wh = (rb - lt).clamp(min=0)
    inter = wh[..., 0] * wh[..., 1]
    union = _area(a)[:, None] + _area(b)[None, :] - inter
    return inter, union


def _safe_div(num: torch.Tensor, den: torch.Tensor) -> torch.Tensor:
    pos = den > 0
    return torch.where(pos, num / torch.where(pos, den, torch.ones_like(den)), 0.0)


def box_iou(boxes1: torch.Tensor, boxes2: torch.Tensor) -> torch.Tensor:
    r"""Intersection over union of every box of ``boxes1`` with every box of ``boxes2``:
    :math:`|A \cap B| / |A \cup B|`, 0 where the union is empty.

    Equals ``pycocotools.mask.iou`` in bbox mode with ``iscrowd`` 0 (tested to 1e-9 in
    float64; pycocotools takes ``(x, y, w, h)``).

    Parameters
    ----------
    boxes1, boxes2 : (M, 4), (N, 4) torch.Tensor
        ``"xyxy"`` boxes of the same floating dtype.

    Returns
    -------
    (M, N) torch.Tensor

    Raises
    ------
    InputError
        Not floating ``(N, 4)`` tensors, NaN/inf, ``x2 < x1`` or ``y2 < y1``.

    Examples
    --------
    >>> import torch
    >>> a = torch.tensor([[0.0, 0.0, 2.0, 2.0]])
    >>> box_iou(a, torch.tensor([[1.0, 0.0, 3.0, 2.0], [5.0, 5.0, 6.0, 6.0]])).tolist()
    [[0.3333333432674408, 0.0]]
    """
    a = _check_boxes(boxes1, "boxes1")
    b = _check_boxes(boxes2, "boxes2")
    inter, union = _inter_union(a, b)
    return _safe_div(inter, union)


def generalized_box_iou(boxes1: torch.Tensor, boxes2: torch.Tensor) -> torch.Tensor:
    r"""Generalized IoU (Rezatofighi et al., CVPR 2019) of every pair:

    .. math::
        \mathrm{GIoU}(A, B) = \mathrm{IoU}(A, B) - \frac{|C| - |A \cup B|}{|C|}

    with :math:`C` the smallest box enclosing both; in ``[-1, 1]``. Where :math:`|C| = 0`
    (both boxes degenerate on one line or point) the penalty is 0 and GIoU = IoU = 0.
    Matches torchvision's ``ops.generalized_box_iou`` where that is defined.

    Parameters
    ----------
    boxes1, boxes2 : (M, 4), (N, 4) torch.Tensor
        ``"xyxy"`` boxes.

    Returns
    -------
    (M, N) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> a = torch.tensor([[0.0, 0.0, 1.0, 1.0]])
    >>> generalized_box_iou(a, torch.tensor([[2.0, 0.0, 3.0, 1.0]])).tolist()  # C = 3
    [[-0.3333333432674408]]
    """
    a = _check_boxes(boxes1, "boxes1")
    b = _check_boxes(boxes2, "boxes2")
    inter, union = _inter_union(a, b)
    iou = _safe_div(inter, union)
    lt = torch.minimum(a[:, None, :2], b[None, :, :2])
    rb = torch.maximum(a[:, None, 2:], b[None, :, 2:])
    wh = rb - lt
    hull = wh[..., 0] * wh[..., 1]
    return iou - _safe_div(hull - union, hull)


def dihedral_boxes(
    boxes: torch.Tensor,
    size: tuple[int, int],
    *,
    hflip: bool = False,
    vflip: bool = False,
    quarter_turns: int = 0,
    inverse: bool = False,
) -> torch.Tensor:
    r"""Move ``"xyxy"`` boxes with their image under mirror images and quarter turns
    (the dihedral group of the rectangle), or back.

    For an image of height :math:`H` and width :math:`W` (continuous pixel
    coordinates), in this order:

    - ``hflip`` (``torch.flip(image, [-1])``): :math:`(W - x_2, y_1, W - x_1, y_2)`;
    - ``vflip`` (``torch.flip(image, [-2])``): :math:`(x_1, H - y_2, x_2, H - y_1)`;
    - ``quarter_turns`` :math:`k` counter-clockwise turns
      (``torch.rot90(image, k, (-2, -1))``), each mapping a point :math:`(x, y)` to
      :math:`(y, W - x)` and the size to :math:`W \times H`: a box becomes
      :math:`(y_1, W - x_2, y_2, W - x_1)`.

    With ``inverse``, the boxes are in the transformed image and are moved back into
    the original one (the inverse steps in reverse order), so
    ``dihedral_boxes(dihedral_boxes(b, s, **t), s, **t, inverse=True)`` is ``b``.

    Parameters
    ----------
    boxes : (K, 4) torch.Tensor
    size : (int, int)
        ``(H, W)`` of the original (untransformed) image, in both directions.
    hflip, vflip : bool
    quarter_turns : int
        Taken modulo 4.
    inverse : bool

    Returns
    -------
    (K, 4) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[2.0, 1.0, 5.0, 4.0]])
    >>> dihedral_boxes(b, (10, 20), quarter_turns=1).tolist()  # (y1, W - x2, y2, W - x1)
    [[1.0, 15.0, 4.0, 18.0]]
    >>> dihedral_boxes(torch.tensor([[1.0, 15, 4, 18]]), (10, 20), quarter_turns=1,
    ...                inverse=True).tolist()
    [[2.0, 1.0, 5.0, 4.0]]
    """
    b = _check_boxes(boxes, "boxes")
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise InputError(f"size must be the image's (height, width); got {plain_repr(size)}")
    h, w = (check_int(v, "size (the image's height and width)", 1) for v in size)
    hflip = check_bool(hflip, "hflip")
    vflip = check_bool(vflip, "vflip")
    k = check_int(quarter_turns, "quarter_turns") % 4

    def turn(b: torch.Tensor, width: float) -> torch.Tensor:
        return torch.stack([b[:, 1], width - b[:, 2], b[:, 3], width - b[:, 0]], 1)

    def mirror(b: torch.Tensor) -> torch.Tensor:
        if hflip:
            b = torch.stack([w - b[:, 2], b[:, 1], w - b[:, 0], b[:, 3]], 1)
        if vflip:
            b = torch.stack([b[:, 0], h - b[:, 3], b[:, 2], h - b[:, 1]], 1)
        return b

    if not inverse:
        b = mirror(b)
        for i in range(k):  # the width before each turn: W, H, W, ...
            b = turn(b, (w, h)[i % 2])
        return b
    # k turns back are 4 - k more turns on, from the turned image (W x H when k is odd)
    widths = (h, w) if k % 2 else (w, h)
    for i in range((4 - k) % 4):
        b = turn(b, widths[i % 2])
    return mirror(b)


# --------------------------------------------------------------------------- coding
class BoxCoder:
    r"""Faster R-CNN box coding: the deltas that move a proposal (or anchor) onto a
    target, and back (Girshick et al. 2014, appendix C; torchvision's
    ``models.detection._utils.BoxCoder``, widths ``x2 - x1``).

    With the proposal centre and size :math:`(p_x, p_y, p_w, p_h)`, the target's
    :math:`(g_x, g_y, g_w, g_h)` and the weights :math:`(w_x, w_y, w_w, w_h)`:

    .. math::
        d_x = w_x \frac{g_x - p_x}{p_w},\ d_y = w_y \frac{g_y - p_y}{p_h},\
        d_w = w_w \log\frac{g_w}{p_w},\ d_h = w_h \log\frac{g_h}{p_h}

    and :meth:`decode` inverts it, clamping :math:`d_w / w_w` and :math:`d_h / w_h` at
    ``bbox_xform_clip`` (:math:`\log(1000/16)`) before the exponential so that a wild
    regression output cannot make an infinite box.

    Parameters
    ----------
    weights : 4 positive floats
        ``(wx, wy, ww, wh)``: ``(1, 1, 1, 1)`` for the RPN, ``(10, 10, 5, 5)`` for the
        Fast R-CNN head in torchvision.
    bbox_xform_clip : float
        Upper clamp of the log-scale deltas in :meth:`decode`, > 0.

    Examples
    --------
    >>> import torch
    >>> coder = BoxCoder((1.0, 1.0, 1.0, 1.0))
    >>> p = torch.tensor([[0.0, 0.0, 10.0, 10.0]])
    >>> d = coder.encode(torch.tensor([[5.0, 0.0, 15.0, 20.0]]), p)
    >>> [round(v, 4) for v in d[0].tolist()]
    [0.5, 0.5, 0.0, 0.6931]
    >>> coder.decode(d, p).tolist()
    [[5.0, 0.0, 15.0, 20.0]]
    """

    def __init__(
        self,
        weights: Sequence[float] = (1.0, 1.0, 1.0, 1.0),
        bbox_xform_clip: float = math.log(1000.0 / 16),
    ) -> None:
        if not isinstance(weights, (tuple, list)) or len(weights) != 4:
            raise InputError(
                f"weights must be 4 positive numbers (wx, wy, ww, wh); got {plain_repr(weights)}"
            )
        self.weights = tuple(check_real(w, "weights", 0.0, low_inclusive=False) for w in weights)
        self.bbox_xform_clip = check_real(
            bbox_xform_clip, "bbox_xform_clip", 0.0, 700.0, low_inclusive=False
        )

    def __repr__(self) -> str:
        return f"BoxCoder(weights={self.weights}, bbox_xform_clip={self.bbox_xform_clip:.6g})"

    def encode(self, reference_boxes: torch.Tensor, proposals: torch.Tensor) -> torch.Tensor:
        """Deltas ``(dx, dy, dw, dh)`` that move each proposal onto its reference box.

        Parameters
        ----------
        reference_boxes : (N, 4) torch.Tensor
            The targets (ground truth), ``"xyxy"``, positive width and height.
        proposals : (N, 4) torch.Tensor
            The proposals or anchors, ``"xyxy"``, positive width and height.

        Returns
        -------
        (N, 4) torch.Tensor

        Raises
        ------
        InputError
            Shapes differ, a box of zero width or height (its log-size is -inf), or the
            checks of :func:`box_iou`.
        """
        g = _check_boxes(reference_boxes, "reference_boxes")
        p = _check_boxes(proposals, "proposals")
        if g.shape != p.shape:
            raise InputError(
                "reference_boxes and proposals must pair up row by row; got shapes "
                f"{tuple(g.shape)} and {tuple(p.shape)}"
            )
        for t, name in ((g, "reference_boxes"), (p, "proposals")):
            if t.numel() and bool(((t[:, 2] <= t[:, 0]) | (t[:, 3] <= t[:, 1])).any()):
                raise InputError(
                    f"{name} must have positive widths and heights to be encoded (log of the "
                    "size); got a zero-size box: drop them first, e.g. "
                    f"{name}[box_area({name}) > 0]"
                )
        wx, wy, ww, wh = self.weights
        pw, ph = p[:, 2] - p[:, 0], p[:, 3] - p[:, 1]
        px, py = p[:, 0] + 0.5 * pw, p[:, 1] + 0.5 * ph
        gw, gh = g[:, 2] - g[:, 0], g[:, 3] - g[:, 1]
        gx, gy = g[:, 0] + 0.5 * gw, g[:, 1] + 0.5 * gh
        return torch.stack(
            (
                wx * (gx - px) / pw,
                wy * (gy - py) / ph,
                ww * torch.log(gw / pw),
                wh * torch.log(gh / ph),
            ),
            dim=1,
        )

    def decode(self, deltas: torch.Tensor, boxes: torch.Tensor) -> torch.Tensor:
        r"""Apply ``deltas`` to ``boxes``: the inverse of :meth:`encode`.

        .. math::
            \hat g_x = \frac{d_x}{w_x} p_w + p_x,\quad
            \hat g_w = p_w \exp\!\big(\min(d_w / w_w, \text{clip})\big)

        Parameters
        ----------
        deltas : (N, 4 k) torch.Tensor
            ``k`` sets of deltas per box (one per class in a per-class head).
        boxes : (N, 4) torch.Tensor
            ``"xyxy"`` boxes the deltas apply to.

        Returns
        -------
        (N, 4 k) torch.Tensor
            ``"xyxy"`` boxes.
        """
        b = _check_boxes(boxes, "boxes")
        if not isinstance(deltas, torch.Tensor) or deltas.ndim != 2 or deltas.shape[1] % 4:
            raise InputError(
                "deltas must be a (N, 4 k) torch.Tensor of (dx, dy, dw, dh); got "
                + (
                    str(tuple(deltas.shape))
                    if isinstance(deltas, torch.Tensor)
                    else type(deltas).__name__
                )
            )
        d = _check_boxes(deltas, "deltas", deltas.shape[1], ordered=False)
        if d.shape[0] != b.shape[0]:
            raise InputError(
                f"deltas and boxes must have the same number of rows; got {d.shape[0]} and "
                f"{b.shape[0]}"
            )
        d = d.reshape(d.shape[0], -1, 4).to(b.dtype)
        wx, wy, ww, wh = self.weights
        pw = (b[:, 2] - b[:, 0])[:, None]
        ph = (b[:, 3] - b[:, 1])[:, None]
        px = b[:, 0, None] + 0.5 * pw
        py = b[:, 1, None] + 0.5 * ph
        dw = (d[..., 2] / ww).clamp(max=self.bbox_xform_clip)
        dh = (d[..., 3] / wh).clamp(max=self.bbox_xform_clip)
        cx = d[..., 0] / wx * pw + px
        cy = d[..., 1] / wy * ph + py
        w = torch.exp(dw) * pw
        h = torch.exp(dh) * ph
        out = torch.stack((cx - 0.5 * w, cy - 0.5 * h, cx + 0.5 * w, cy + 0.5 * h), dim=2)
        return out.reshape(b.shape[0], -1)


# --------------------------------------------------------------------------- anchors
def _positive_tuple(value: Any, name: str) -> tuple[float, ...]:
    if not isinstance(value, (tuple, list)) or not value:
        raise InputError(
            f"{name} must be a non-empty tuple of positive numbers; got {plain_repr(value)}"
        )
    return tuple(check_real(v, name, 0.0, 1e6, low_inclusive=False) for v in value)


class AnchorGenerator:
    r"""Anchors of ``sizes`` x ``aspect_ratios`` at every cell of one or more feature maps
    (Faster R-CNN's RPN; torchvision's ``models.detection.anchor_utils.AnchorGenerator``).

    For feature map :math:`l` of shape :math:`(H_l, W_l)` on an image of shape
    :math:`(H, W)`, the stride is :math:`s = (\lfloor H / H_l \rfloor, \lfloor W / W_l
    \rfloor)` and the anchor of size :math:`a` and ratio :math:`r = h / w` at cell
    :math:`(i, j)` is centred at :math:`((j + o) s_x, (i + o) s_y)` with
    :math:`w = a / \sqrt r`, :math:`h = a \sqrt r` (area :math:`a^2`), :math:`o` the
    ``offset``.

    Ordering (as torchvision): feature maps in the given order; within one, cells in
    row-major order (y outer, x inner); within a cell, aspect ratios outer and sizes
    inner. The base anchors are **not** rounded by default (torchvision rounds them to
    integers; ``round_base=True`` reproduces that); ``offset=0`` (torchvision) centres
    anchors on the cell's top-left corner ``(j s_x, i s_y)``, ``offset=0.5`` on its centre.

    Parameters
    ----------
    sizes : tuple of float, or tuple of tuples (one per feature map)
        Anchor sizes :math:`a` (square roots of the areas), pixels.
    aspect_ratios : tuple of float, or tuple of tuples (one per feature map)
        Ratios :math:`h / w`, > 0.
    offset : float
        Cell offset :math:`o` in ``[0, 1)``.
    round_base : bool
        Round the base anchors' corners to integers (half to even) as torchvision does.

    Examples
    --------
    >>> gen = AnchorGenerator((32.0,), (0.5, 1.0, 2.0))
    >>> gen.num_anchors_per_location()
    [3]
    >>> a = gen((64, 64), [(2, 2)])
    >>> a.shape
    torch.Size([12, 4])
    >>> a[1].tolist()  # cell (0, 0), ratio 1: a 32 x 32 box centred at (0, 0)
    [-16.0, -16.0, 16.0, 16.0]
    """

    def __init__(
        self,
        sizes: Sequence[float] | Sequence[Sequence[float]] = ((32.0, 64.0, 128.0),),
        aspect_ratios: Sequence[float] | Sequence[Sequence[float]] = ((0.5, 1.0, 2.0),),
        offset: float = 0.0,
        round_base: bool = False,
    ) -> None:
        nested_s = isinstance(sizes, (tuple, list)) and all(
            isinstance(s, (tuple, list)) for s in sizes
        )
        nested_r = isinstance(aspect_ratios, (tuple, list)) and all(
            isinstance(r, (tuple, list)) for r in aspect_ratios
        )
        s_list = (
            [_positive_tuple(s, "sizes") for s in sizes]
            if nested_s
            else [_positive_tuple(sizes, "sizes")]
        )
        if nested_r:
            r_list = [_positive_tuple(r, "aspect_ratios") for r in aspect_ratios]
        else:
            r_list = [_positive_tuple(aspect_ratios, "aspect_ratios")]
        if len(r_list) == 1 and len(s_list) > 1:
            r_list = r_list * len(s_list)
        if len(r_list) != len(s_list):
            raise InputError(
                f"aspect_ratios must give one tuple per feature map ({len(s_list)} in sizes) or "
                f"one tuple for all; got {len(r_list)}"
            )
        self.sizes = s_list
        self.aspect_ratios = r_list
        self.offset = check_real(offset, "offset", 0.0, 1.0, high_inclusive=False)
        self.round_base = check_bool(round_base, "round_base")

    def __repr__(self) -> str:
        return (
            f"AnchorGenerator(sizes={self.sizes}, aspect_ratios={self.aspect_ratios}, "
            f"offset={self.offset}, round_base={self.round_base})"
        )

    def num_anchors_per_location(self) -> list[int]:
        """Anchors per cell of each feature map: ``len(sizes) * len(aspect_ratios)``."""
        return [len(s) * len(r) for s, r in zip(self.sizes, self.aspect_ratios, strict=True)]

    def base_anchors(self, level: int = 0, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        """The ``(A, 4)`` ``"xyxy"`` anchors of feature map ``level`` centred at (0, 0)."""
        level = check_int(level, "level", 0)
        dtype = check_float_dtype(dtype)
        if level >= len(self.sizes):
            raise InputError(f"level must be < {len(self.sizes)}; got {level}")
        scales = torch.tensor(self.sizes[level], dtype=torch.float64)
        ratios = torch.tensor(self.aspect_ratios[level], dtype=torch.float64)
        h_ratios = torch.sqrt(ratios)
        ws = (scales[None, :] / h_ratios[:, None]).reshape(-1)
        hs = (scales[None, :] * h_ratios[:, None]).reshape(-1)
        base = torch.stack((-ws, -hs, ws, hs), dim=1) / 2
        if self.round_base:
            base = base.round()
        return base.to(dtype)

    def __call__(
        self,
        image_shape: tuple[int, int],
        feature_shapes: Sequence[tuple[int, int]],
        dtype: torch.dtype = torch.float32,
    ) -> torch.Tensor:
        """All anchors of an image: ``(sum_l H_l W_l A_l, 4)``, ``"xyxy"``.

        Parameters
        ----------
        image_shape : (H, W)
            The (padded) input image's shape.
        feature_shapes : sequence of (H_l, W_l)
            One per feature map, as many as ``sizes`` has tuples.
        dtype : torch.dtype

        Returns
        -------
        (sum_l H_l W_l A_l, 4) torch.Tensor
        """
        if not isinstance(image_shape, (tuple, list)) or len(image_shape) != 2:
            raise InputError(f"image_shape must be (H, W); got {plain_repr(image_shape)}")
        H, W = (check_int(v, "image_shape", 1) for v in image_shape)
        if not isinstance(feature_shapes, (tuple, list)) or len(feature_shapes) != len(self.sizes):
            raise InputError(
                f"feature_shapes must be {len(self.sizes)} (H, W) shape(s), one per tuple of "
                f"sizes; got {plain_repr(feature_shapes)}"
            )
        dtype = check_float_dtype(dtype)
        out = []
        total = 0
        for level, fs in enumerate(feature_shapes):
            if not isinstance(fs, (tuple, list)) or len(fs) != 2:
                raise InputError(f"feature_shapes[{level}] must be (H, W); got {plain_repr(fs)}")
            fh, fw = (check_int(v, f"feature_shapes[{level}]", 1) for v in fs)
            if fh > H or fw > W:
                raise InputError(
                    f"feature_shapes[{level}] {(fh, fw)} is larger than image_shape {(H, W)}: "
                    "give (H, W) of the image, then of each feature map"
                )
            total += fh * fw * self.num_anchors_per_location()[level]
            check_allocation(total * 4, 8, "the anchors", "use smaller or fewer feature maps")
            sy, sx = H // fh, W // fw
            base = self.base_anchors(level, torch.float64)
            ys = (torch.arange(fh, dtype=torch.float64) + self.offset) * sy
            xs = (torch.arange(fw, dtype=torch.float64) + self.offset) * sx
            yy, xx = torch.meshgrid(ys, xs, indexing="ij")
            shifts = torch.stack((xx, yy, xx, yy), dim=-1).reshape(-1, 1, 4)
            out.append((shifts + base[None]).reshape(-1, 4))
        return torch.cat(out).to(dtype)


# --------------------------------------------------------------------------- NMS
def _greedy_reference(boxes: np.ndarray, classes: np.ndarray, iou_threshold: float) -> np.ndarray:
    """The greedy loop of :func:`nms` in NumPy, the reference of its compiled kernel.

    Parameters
    ----------
    boxes : (N, 4) ndarray of float64
        ``"xyxy"`` boxes, already sorted by decreasing score (not checked).
    classes : (N,) ndarray of int64
        A box suppresses only boxes of its class (all 0 for plain NMS).
    iou_threshold : float

    Returns
    -------
    (N,) ndarray of bool
        Which sorted boxes are kept.

    """
    n = boxes.shape[0]
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    alive = np.ones(n, dtype=bool)
    for i in range(n):
        if not alive[i]:
            continue
        rest = np.nonzero(alive[i + 1 :])[0] + i + 1
        rest = rest[classes[rest] == classes[i]]
        if rest.size == 0:
            continue
        r = boxes[rest]
        w = np.clip(np.minimum(boxes[i, 2], r[:, 2]) - np.maximum(boxes[i, 0], r[:, 0]), 0, None)
        h = np.clip(np.minimum(boxes[i, 3], r[:, 3]) - np.maximum(boxes[i, 1], r[:, 1]), 0, None)
        inter = w * h
        union = area[i] + area[rest] - inter
        pos = union > 0
        iou = np.where(pos, inter / np.where(pos, union, 1.0), 0.0)
        alive[rest[iou > iou_threshold]] = False
    return alive


@njit(cache=True)
def _greedy_kernel(boxes: np.ndarray, classes: np.ndarray, iou_threshold: float) -> np.ndarray:
    """:func:`_greedy_reference`, compiled (the same float64 arithmetic)."""
    n = boxes.shape[0]
    alive = np.ones(n, dtype=np.bool_)
    for i in range(n):
        if not alive[i]:
            continue
        x1, y1, x2, y2 = boxes[i, 0], boxes[i, 1], boxes[i, 2], boxes[i, 3]
        ai = (x2 - x1) * (y2 - y1)
        for j in range(i + 1, n):
            if not alive[j] or classes[j] != classes[i]:
                continue
            w = min(x2, boxes[j, 2]) - max(x1, boxes[j, 0])
            h = min(y2, boxes[j, 3]) - max(y1, boxes[j, 1])
            if w <= 0.0 or h <= 0.0:
                continue
            inter = w * h
            union = ai + (boxes[j, 2] - boxes[j, 0]) * (boxes[j, 3] - boxes[j, 1]) - inter
            if union > 0.0 and inter / union > iou_threshold:
                alive[j] = False
    return alive


def _greedy(
    boxes: torch.Tensor, order: torch.Tensor, thr: float, idxs: torch.Tensor | None
) -> torch.Tensor:
    """Greedy suppression over ``boxes[order]`` (already sorted); the kept entries of
    ``order``."""
    b = np.ascontiguousarray(boxes[order].detach().cpu().numpy(), dtype=np.float64)
    if idxs is None:
        cls = np.zeros(b.shape[0], dtype=np.int64)
    else:
        cls = np.ascontiguousarray(idxs[order].cpu().numpy(), dtype=np.int64)
    alive = _greedy_kernel(b, cls, thr)
    return order[torch.from_numpy(alive)]


def _sorted(scores: torch.Tensor) -> torch.Tensor:
    return torch.argsort(-scores.detach(), stable=True)


def nms(boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float) -> torch.Tensor:
    r"""Greedy non-maximum suppression: take the highest-scoring box, drop every box
    whose IoU with it exceeds ``iou_threshold`` (strictly), repeat with the rest.

    Ties in score are broken by index (the lower index first: a stable sort on
    ``-scores``); an IoU exactly equal to the threshold does not suppress. The result is
    the same as onnxruntime's ``NonMaxSuppression`` (tested) and torchvision's
    ``ops.nms``, and independent of the number of threads (the loop is sequential, the
    IoU arithmetic in float64).

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
        ``"xyxy"`` boxes; degenerate (zero-size) boxes overlap nothing.
    scores : (N,) torch.Tensor
        Floating point, no NaN (refused: a NaN has no rank); ``-inf`` is allowed.
    iou_threshold : float
        In ``[0, 1]``.

    Returns
    -------
    (K,) torch.Tensor of int64
        Indices of the kept boxes, by decreasing score.

    Raises
    ------
    InputError
        Bad boxes (see :func:`box_iou`), scores of another length or with NaN, a
        threshold outside ``[0, 1]``.

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30]])
    >>> nms(b, torch.tensor([0.9, 0.95, 0.5]), 0.5).tolist()
    [1, 2]
    """
    boxes = _check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    return _greedy(boxes, _sorted(scores), thr, None).to(boxes.device)


def _check_idxs(idxs: Any, n: int) -> torch.Tensor:
    if not isinstance(idxs, torch.Tensor) or tuple(idxs.shape) != (n,):
        got = tuple(idxs.shape) if isinstance(idxs, torch.Tensor) else type(idxs).__name__
        raise InputError(f"idxs must be a ({n},) integer torch.Tensor of class ids; got {got}")
    if idxs.is_floating_point() or idxs.is_complex() or idxs.dtype == torch.bool:
        raise InputError(f"idxs must hold integer class ids; got {idxs.dtype}: use idxs.long()")
    return idxs


def batched_nms(
    boxes: torch.Tensor, scores: torch.Tensor, idxs: torch.Tensor, iou_threshold: float
) -> torch.Tensor:
    """:func:`nms` within each class: a box suppresses only boxes of the same ``idxs``.

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
    scores : (N,) torch.Tensor
    idxs : (N,) torch.Tensor of int
        The class (or image) of each box.
    iou_threshold : float

    Returns
    -------
    (K,) torch.Tensor of int64
        Kept indices by decreasing score (all classes together, as torchvision's).

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10]])
    >>> batched_nms(b, torch.tensor([0.9, 0.8]), torch.tensor([0, 1]), 0.5).tolist()
    [0, 1]
    """
    boxes = _check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    idxs = _check_idxs(idxs, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    return _greedy(boxes, _sorted(scores), thr, idxs).to(boxes.device)


def non_max_suppression(
    boxes: torch.Tensor,
    scores: torch.Tensor,
    iou_threshold: float = 0.5,
    score_threshold: float | None = None,
    top_k: int | None = None,
    idxs: torch.Tensor | None = None,
) -> torch.Tensor:
    """Detections after a score threshold, NMS (per class when ``idxs`` is given) and a
    cap on their number: onnxruntime's ``NonMaxSuppression`` with
    ``score_threshold`` and ``max_output_boxes_per_class`` (per class when ``idxs`` is
    given, as the operator's class axis).

    A box is a candidate when ``score > score_threshold`` (strictly, as onnxruntime).

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
    scores : (N,) torch.Tensor
    iou_threshold : float
        In ``[0, 1]``.
    score_threshold : float, optional
        Candidates score strictly above it; None keeps every box.
    top_k : int, optional
        At most this many kept boxes (per class with ``idxs``), >= 0; None: no cap.
    idxs : (N,) torch.Tensor of int, optional
        Class ids for per-class suppression.

    Returns
    -------
    (K,) torch.Tensor of int64
        Kept indices by decreasing score.

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30], [40, 0, 50, 9]])
    >>> s = torch.tensor([0.9, 0.95, 0.5, 0.1])
    >>> non_max_suppression(b, s, 0.5, score_threshold=0.2, top_k=1).tolist()
    [1]
    """
    boxes = _check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    if idxs is not None:
        idxs = _check_idxs(idxs, boxes.shape[0])
    order = _sorted(scores)
    if score_threshold is not None:
        st = check_real(score_threshold, "score_threshold")
        order = order[scores[order] > st]
    keep = _greedy(boxes, order, thr, idxs)
    if top_k is not None:
        k = check_int(top_k, "top_k", 0)
        if idxs is None:
            keep = keep[:k]
        else:
            cls = idxs[keep]
            rank = torch.zeros_like(keep)
            for c in torch.unique(cls):
                m = cls == c
                rank[m] = torch.arange(int(m.sum()))
            keep = keep[rank < k]
    return keep.to(boxes.device)


# --------------------------------------------------------------------------- RoI ops
def _check_feature(input: Any) -> torch.Tensor:
    if not isinstance(input, torch.Tensor):
        raise InputError(
            f"input must be a (N, C, H, W) torch.Tensor of features; got {type(input).__name__}: "
            "use torch.from_numpy(x).float()"
        )
    if input.ndim != 4:
        hint = ": one image? use input.unsqueeze(0)" if input.ndim == 3 else ""
        raise InputError(f"input must be 4-D (N, C, H, W); got shape {tuple(input.shape)}{hint}")
    if not input.is_floating_point():
        raise InputError(f"input must be floating point; got {input.dtype}: use input.float()")
    if min(input.shape[2:]) < 1:
        raise InputError(f"input must have H, W >= 1; got shape {tuple(input.shape)}")
    return input


def _check_rois(boxes: Any, n_images: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(batch_index (K,), boxes (K, 4))`` from a (K, 5) tensor or a list of (Ki, 4)."""
    if isinstance(boxes, (list, tuple)):
        if len(boxes) != n_images:
            raise InputError(
                f"boxes as a list must hold one (Ki, 4) tensor per image ({n_images}); got "
                f"{len(boxes)}"
            )
        parts = [_check_boxes(b, f"boxes[{i}]", ordered=False) for i, b in enumerate(boxes)]
        dtype = parts[0].dtype if parts else torch.float32
        rois = torch.cat([p.to(dtype) for p in parts]) if parts else torch.zeros(0, 4, dtype=dtype)
        bidx = (
            torch.cat([torch.full((p.shape[0],), i, dtype=torch.long) for i, p in enumerate(parts)])
            if parts
            else torch.zeros(0, dtype=torch.long)
        )
        return bidx, rois
    if isinstance(boxes, torch.Tensor) and boxes.ndim == 2 and boxes.shape[1] == 4:
        raise InputError(
            "boxes must be a (K, 5) tensor [batch_index, x1, y1, x2, y2] or a list of (Ki, 4) "
            "tensors; got a (K, 4) tensor: pass [boxes] for a single image"
        )
    b = _check_boxes(boxes, "boxes", 5, ordered=False)
    bi = b[:, 0]
    if b.numel() and bool(((bi != bi.round()) | (bi < 0) | (bi >= n_images)).any()):
        raise InputError(
            f"boxes[:, 0] must be whole batch indices in [0, {n_images - 1}]; got "
            f"{plain_repr(sorted(set(bi.tolist()))[:5])}"
        )
    return bi.long(), b[:, 1:]


def _output_size(value: Any) -> tuple[int, int]:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value, value)
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"output_size must be an int or (height, width); got {plain_repr(value)}")
    ph, pw = (check_int(v, "output_size", 1) for v in value)
    if ph > 4096 or pw > 4096:
        raise InputError(f"output_size must be at most 4096 per side; got {plain_repr(value)}")
    return ph, pw


def _align_weights(
    start: torch.Tensor, size: torch.Tensor, bins: int, grid: torch.Tensor, length: int
) -> torch.Tensor:
    """``(K, bins, length)`` matrix whose row ``p`` averages the bilinear samples of bin
    ``p`` along one axis (torchvision's ``bilinear_interpolate``, one axis at a time)."""
    K = start.shape[0]
    gmax = max(int(grid.max()) if K else 1, 1)
    dt = start.dtype
    bin_size = size / bins
    p = torch.arange(bins, dtype=dt)
    s = torch.arange(gmax, dtype=dt)
    g = grid.to(dt).clamp(min=1)
    # sample positions (K, bins, gmax)
    y = (
        start[:, None, None]
        + p[None, :, None] * bin_size[:, None, None]
        + (s[None, None, :] + 0.5) * (bin_size / g)[:, None, None]
    )
    used = s[None, None, :] < grid[:, None, None]
    inside = (y >= -1.0) & (y <= length)
    y = y.clamp(min=0)
    low = y.floor().long()
    top = low >= length - 1
    low = torch.where(top, torch.full_like(low, length - 1), low)
    high = torch.where(top, low, low + 1)
    y = torch.where(top, low.to(dt), y)
    frac = y - low.to(dt)
    w = (used & inside).to(dt) / g[:, None, None]
    out = torch.zeros(K, bins, length, dtype=dt)
    out.scatter_add_(2, low, w * (1 - frac))
    out.scatter_add_(2, high, w * frac)
    return out


def roi_align(
    input: torch.Tensor,
    boxes: torch.Tensor | list[torch.Tensor],
    output_size: int | tuple[int, int],
    spatial_scale: float = 1.0,
    sampling_ratio: int = -1,
    aligned: bool = False,
) -> torch.Tensor:
    r"""RoI Align (He et al., Mask R-CNN 2017): average of bilinear samples on a regular
    grid in each of the ``output_size`` bins of each region, no quantization.

    A box :math:`(x_1, y_1, x_2, y_2)` in image pixels maps to the feature map as
    :math:`x s - o` with :math:`s` = ``spatial_scale`` and :math:`o = 0.5` when
    ``aligned`` (pixel centres at half-integers), else 0; without ``aligned`` a region
    is at least 1 x 1. Bin :math:`(p, q)` of a region of size :math:`h \times w`
    averages :math:`g_h g_w` samples at
    :math:`y = y_1 + p\,h/P + (i + \tfrac12)\,h/(P g_h)` (same in x), with
    :math:`g = ` ``sampling_ratio`` or, if it is <= 0, :math:`\lceil h / P \rceil`.
    A sample outside :math:`[-1, H] \times [-1, W]` counts as 0; one in the border
    band is clamped to the edge. This is torchvision's ``ops.roi_align`` and
    onnxruntime's ``RoiAlign`` (``coordinate_transformation_mode`` ``"half_pixel"`` =
    ``aligned=True``, ``"output_half_pixel"`` = ``aligned=False``, mode ``"avg"``;
    tested to 1e-5).

    The bilinear weights are separable, so each region is two small matrix products
    :math:`A_y F A_x^\top` (vectorized over regions, one loop over images);
    differentiable with respect to ``input``.

    Parameters
    ----------
    input : (N, C, H, W) torch.Tensor
    boxes : (K, 5) torch.Tensor or list of N (K_i, 4) torch.Tensor
        ``[batch_index, x1, y1, x2, y2]`` rows, or ``"xyxy"`` boxes per image.
    output_size : int or (P, Q)
    spatial_scale : float
        Feature-map pixels per image pixel (1/16 for a stride-16 backbone), > 0.
    sampling_ratio : int
        Samples per bin side; <= 0 for adaptive.
    aligned : bool

    Returns
    -------
    (K, C, P, Q) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> roi_align(x, torch.tensor([[0.0, 0.5, 0.5, 2.5, 2.5]]), 1, aligned=True).item()
    5.0
    """
    x = _check_feature(input)
    bidx, rois = _check_rois(boxes, x.shape[0])
    P, Q = _output_size(output_size)
    scale = check_real(spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False)
    ratio = check_int(sampling_ratio, "sampling_ratio")
    if ratio > 1024:
        raise InputError(
            f"sampling_ratio must be at most 1024 samples per bin side; got {ratio}: "
            "2 is the usual choice, <= 0 for adaptive"
        )
    ratio = max(ratio, 0)
    aligned = check_bool(aligned, "aligned")
    _, C, H, W = x.shape
    K = rois.shape[0]
    dt = x.dtype
    r = rois.detach().to(torch.float64) * scale - (0.5 if aligned else 0.0)
    rw = r[:, 2] - r[:, 0]
    rh = r[:, 3] - r[:, 1]
    if not aligned:
        rw, rh = rw.clamp(min=1.0), rh.clamp(min=1.0)
    if ratio > 0:
        gh = torch.full((K,), ratio, dtype=torch.long)
        gw = gh
    else:
        gh = torch.ceil(rh / P).long()
        gw = torch.ceil(rw / Q).long()
    gmax = max(int(gh.max()) if K else 1, int(gw.max()) if K else 1, 1)
    check_allocation(
        K * max(P * max(H, gmax), Q * max(W, gmax)) * 2 + K * C * P * W,
        8,
        f"the sampling of {K} regions",
        "use fewer or smaller boxes, a smaller spatial_scale, or a positive sampling_ratio",
    )
    Ay = _align_weights(r[:, 1], rh, P, gh, H).to(dt)
    Ax = _align_weights(r[:, 0], rw, Q, gw, W).to(dt)
    parts, where = [], []
    for n in torch.unique(bidx).tolist():
        m = torch.nonzero(bidx == n)[:, 0]
        k = m.shape[0]
        # along y: one GEMM (k P, H) @ (H, C W); along x: k products (P C, W) @ (W, Q)
        t = Ay[m].reshape(k * P, H) @ x[n].transpose(0, 1).reshape(H, C * W)
        t = torch.bmm(t.reshape(k, P * C, W), Ax[m].transpose(1, 2))
        parts.append(t.reshape(k, P, C, Q).permute(0, 2, 1, 3))
        where.append(m)
    if not parts:
        return x.new_zeros((0, C, P, Q))
    order = torch.cat(where) if len(where) > 1 else where[0]
    out = torch.cat(parts) if len(parts) > 1 else parts[0]
    if bool((order != torch.arange(K)).any()):
        out = out[torch.argsort(order)]
    return out.contiguous()


def _round_half_away(v: torch.Tensor) -> torch.Tensor:
    return torch.sign(v) * torch.floor(v.abs() + 0.5)


def paste_masks(masks: torch.Tensor, boxes: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    r"""Paste ``M x M`` per-box masks (Mask R-CNN's 28 x 28 outputs) back into an image of
    ``size`` ``(H, W)``: the inverse of :func:`roi_align` with ``aligned=True``.

    Mask cell :math:`j` of a box :math:`(x_1, y_1, x_2, y_2)` is centred at
    :math:`x_1 + (j + \tfrac12)(x_2 - x_1)/M` (same in y). Image pixel :math:`(c, r)`,
    centred at :math:`(c + \tfrac12, r + \tfrac12)` in the same continuous coordinates,
    takes the bilinear interpolation of the mask at
    :math:`u = (c + \tfrac12 - x_1) M / (x_2 - x_1) - \tfrac12` (clamped to the edge
    cells) when its centre lies inside the box, and 0 outside it. torchvision's
    ``paste_masks_in_image`` resizes a zero-padded mask to the integer box instead, which
    spreads a mask half a cell beyond its box; here a mask of ones pastes exactly the
    pixels whose centres the box covers (tested).

    Parameters
    ----------
    masks : (D, M, M) or (D, 1, M, M) float torch.Tensor
        Probabilities (or logits) per box.
    boxes : (D, 4) float torch.Tensor
        ``"xyxy"`` pixels.
    size : (H, W)
        Image shape.

    Returns
    -------
    (D, H, W) torch.Tensor
        Of ``masks``' dtype.

    Raises
    ------
    InputError
        Masks not ``(D, M, M)`` floating point, boxes not ``(D, 4)`` ordered and finite,
        or a size that is not two positive ints.

    Examples
    --------
    >>> import torch
    >>> out = paste_masks(torch.ones(1, 4, 4), torch.tensor([[1.0, 0.5, 3.0, 2.4]]), (3, 4))
    >>> out[0].int().tolist()
    [[0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]
    """
    if isinstance(masks, torch.Tensor) and masks.ndim == 4 and masks.shape[1] == 1:
        masks = masks[:, 0]
    if (
        not isinstance(masks, torch.Tensor)
        or masks.ndim != 3
        or masks.shape[1] < 1
        or masks.shape[2] < 1
        or not masks.is_floating_point()
    ):
        raise InputError(
            f"masks must be a (D, M, M) float torch.Tensor, one mask per box; got "
            f"{plain_repr(masks)}"
        )
    b = _check_boxes(boxes, "boxes")
    if b.shape[0] != masks.shape[0]:
        raise InputError(
            f"masks and boxes must pair up: {masks.shape[0]} masks, {b.shape[0]} boxes"
        )
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
    ):
        raise InputError(f"size must be (H, W), two positive ints; got {plain_repr(size)}")
    h, w = int(size[0]), int(size[1])
    d = masks.shape[0]
    check_allocation(
        d * h * w,
        masks.element_size(),
        f"({d}, {h}, {w}) pasted masks",
        "use fewer boxes or a smaller image",
    )
    out = masks.new_zeros((d, h, w))
    mh, mw = masks.shape[1], masks.shape[2]
    bd = b.detach().to(torch.float64).cpu()
    for i in range(d):
        x1, y1, x2, y2 = (float(v) for v in bd[i])
        # pixels whose centres c + 1/2 lie in [x1, x2]
        c0, c1 = max(math.ceil(x1 - 0.5), 0), min(math.floor(x2 - 0.5), w - 1)
        r0, r1 = max(math.ceil(y1 - 0.5), 0), min(math.floor(y2 - 0.5), h - 1)
        if c1 < c0 or r1 < r0 or x2 <= x1 or y2 <= y1:
            continue
        dev = masks.device
        cx = torch.arange(c0, c1 + 1, dtype=torch.float64, device=dev) + 0.5
        cy = torch.arange(r0, r1 + 1, dtype=torch.float64, device=dev) + 0.5
        u = ((cx - x1) * mw / (x2 - x1) - 0.5).clamp(0, mw - 1)
        v = ((cy - y1) * mh / (y2 - y1) - 0.5).clamp(0, mh - 1)
        out[i, r0 : r1 + 1, c0 : c1 + 1] = _bilinear_grid(masks[i], v, u)
    return out


def _bilinear_grid(m: torch.Tensor, v: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """``m`` (h, w) sampled bilinearly at rows ``v`` x columns ``u`` (both in range):
    the separable weights as two small matrix products ``A_v m A_u^T``."""

    def weights(t: torch.Tensor, n: int) -> torch.Tensor:
        lo = t.floor().long().clamp(max=n - 1)
        hi = (lo + 1).clamp(max=n - 1)
        f = t - lo.to(t.dtype)
        a = torch.zeros((t.shape[0], n), dtype=t.dtype, device=t.device)
        rows = torch.arange(t.shape[0], device=t.device)
        a.index_put_((rows, lo), 1.0 - f, accumulate=True)
        a.index_put_((rows, hi), f, accumulate=True)
        return a.to(m.dtype)

    return weights(v, m.shape[0]) @ m @ weights(u, m.shape[1]).T


def roi_pool(
    input: torch.Tensor,
    boxes: torch.Tensor | list[torch.Tensor],
    output_size: int | tuple[int, int],
    spatial_scale: float = 1.0,
) -> torch.Tensor:
    r"""RoI max pooling (Girshick, Fast R-CNN 2015) with torchvision's quantization.

    The box corners are scaled and rounded (half away from zero, C's ``round``):
    :math:`x_1' = \mathrm{round}(x_1 s)`, :math:`x_2' = \mathrm{round}(x_2 s)`, the
    region is :math:`w = \max(x_2' - x_1' + 1, 1)` cells wide; bin :math:`q` covers
    columns :math:`[\lfloor q w / Q \rfloor, \lceil (q + 1) w / Q \rceil)` offset by
    :math:`x_1'` and clipped to the map (same in y), and holds the maximum there, or 0
    for an empty bin. Differentiable with respect to ``input`` (the gradient of a max
    goes to the arg-max; ties share it, where torchvision gives it to the first).

    Parameters
    ----------
    input : (N, C, H, W) torch.Tensor
    boxes : (K, 5) torch.Tensor or list of N (K_i, 4) torch.Tensor
        As in :func:`roi_align`.
    output_size : int or (P, Q)
    spatial_scale : float
        > 0.

    Returns
    -------
    (K, C, P, Q) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> roi_pool(x, [torch.tensor([[0.0, 0.0, 3.0, 3.0]])], 2)[0, 0].tolist()
    [[5.0, 7.0], [13.0, 15.0]]
    """
    x = _check_feature(input)
    bidx, rois = _check_rois(boxes, x.shape[0])
    P, Q = _output_size(output_size)
    scale = check_real(spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False)
    _, C, H, W = x.shape
    K = rois.shape[0]
    r = _round_half_away(rois.detach().to(torch.float64) * scale)

    def bands(
        lo: torch.Tensor, hi: torch.Tensor, bins: int, length: int
    ) -> tuple[torch.Tensor, torch.Tensor]:
        size = (hi - lo + 1).clamp(min=1)
        b = size / bins
        p = torch.arange(bins, dtype=torch.float64)
        start = torch.floor(p[None] * b[:, None]) + lo[:, None]
        end = torch.ceil((p[None] + 1) * b[:, None]) + lo[:, None]
        return start.clamp(0, length).long(), end.clamp(0, length).long()

    hs, he = bands(r[:, 1], r[:, 3], P, H)
    ws, we = bands(r[:, 0], r[:, 2], Q, W)
    hb = max(int((he - hs).max()) if K else 1, 1)
    wb = max(int((we - ws).max()) if K else 1, 1)
    check_allocation(
        K * C * P * hb * Q * wb,
        x.element_size(),
        f"the bins of {K} regions",
        "use fewer or smaller boxes or a smaller spatial_scale",
    )
    iy = hs[..., None] + torch.arange(hb)  # (K, P, hb)
    ix = ws[..., None] + torch.arange(wb)
    my = iy < he[..., None]
    mx = ix < we[..., None]
    iy = iy.clamp(max=H - 1)
    ix = ix.clamp(max=W - 1)
    out = x.new_zeros((K, C, P, Q))
    for n in torch.unique(bidx).tolist():
        m = torch.nonzero(bidx == n)[:, 0]
        # (C, k, P, hb, Q, wb)
        vals = x[n][:, iy[m][:, :, :, None, None], ix[m][:, None, None, :, :]]
        mask = my[m][:, :, :, None, None] & mx[m][:, None, None, :, :]
        vals = vals.masked_fill(~mask, float("-inf"))
        mx_ = vals.amax(dim=(3, 5))  # (C, k, P, Q)
        empty = ~mask.any(dim=4).any(dim=2)  # (k, P, Q)
        mx_ = mx_.masked_fill(empty[None], 0.0)
        out = out.index_copy(0, m, mx_.permute(1, 0, 2, 3))
    return out


class RoIAlign(torch.nn.Module):
    """:func:`roi_align` as a module (its parameters fixed at construction, checked then).

    Parameters
    ----------
    output_size : int or (P, Q)
    spatial_scale : float
    sampling_ratio : int
    aligned : bool

    Examples
    --------
    >>> import torch
    >>> layer = RoIAlign(2, spatial_scale=0.5, sampling_ratio=2, aligned=True)
    >>> layer(torch.zeros(1, 3, 8, 8), [torch.tensor([[0.0, 0.0, 8.0, 8.0]])]).shape
    torch.Size([1, 3, 2, 2])
    """

    def __init__(
        self,
        output_size: int | tuple[int, int],
        spatial_scale: float = 1.0,
        sampling_ratio: int = -1,
        aligned: bool = False,
    ) -> None:
        super().__init__()
        self.output_size = _output_size(output_size)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )
        self.sampling_ratio = check_int(sampling_ratio, "sampling_ratio")
        self.aligned = check_bool(aligned, "aligned")

    def forward(
        self, input: torch.Tensor, boxes: torch.Tensor | list[torch.Tensor]
    ) -> torch.Tensor:
        """:func:`roi_align` of ``input`` ``(N, C, H, W)`` over ``boxes``: ``(K, C, P, Q)``."""
        return roi_align(
            input, boxes, self.output_size, self.spatial_scale, self.sampling_ratio, self.aligned
        )

    def extra_repr(self) -> str:
        return (
            f"output_size={self.output_size}, spatial_scale={self.spatial_scale}, "
            f"sampling_ratio={self.sampling_ratio}, aligned={self.aligned}"
        )


class RoIPool(torch.nn.Module):
    """:func:`roi_pool` as a module.

    Parameters
    ----------
    output_size : int or (P, Q)
    spatial_scale : float

    Examples
    --------
    >>> import torch
    >>> RoIPool((2, 3))(torch.ones(1, 1, 6, 6), torch.tensor([[0.0, 0, 0, 5, 5]])).shape
    torch.Size([1, 1, 2, 3])
    """

    def __init__(self, output_size: int | tuple[int, int], spatial_scale: float = 1.0) -> None:
        super().__init__()
        self.output_size = _output_size(output_size)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )

    def forward(
        self, input: torch.Tensor, boxes: torch.Tensor | list[torch.Tensor]
    ) -> torch.Tensor:
        """:func:`roi_pool` of ``input`` ``(N, C, H, W)`` over ``boxes``: ``(K, C, P, Q)``."""
        return roi_pool(input, boxes, self.output_size, self.spatial_scale)

    def extra_repr(self) -> str:
        return f"output_size={self.output_size}, spatial_scale={self.spatial_scale}"
