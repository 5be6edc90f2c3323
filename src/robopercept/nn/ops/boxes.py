r"""Box operations of the R-CNN family, in torch: formats, areas, IoU and GIoU (kept
in torch for autograd), moving boxes with their image under flips and quarter turns,
and :func:`check_boxes`, the boundary check of every box-taking function of
:mod:`robopercept.nn.ops` (:mod:`.anchors`, :mod:`.nms`, :mod:`.roi`). The NumPy IoU
matrix and greedy NMS are in :mod:`robopercept.geometry.boxes`.

Box formats (all in pixels, floating point, one box per row):

- ``"xyxy"``: ``(x1, y1, x2, y2)``, the corners; width ``x2 - x1`` (the modern
  torchvision convention, not the ``+ 1`` of the original Caffe code).
- ``"xywh"``: ``(x1, y1, w, h)``, COCO's ``bbox``.
- ``"cxcywh"``: ``(cx, cy, w, h)``, the centre and the size.

Every function that takes boxes takes ``"xyxy"`` unless it says otherwise; a box with
``x2 < x1`` or ``y2 < y1`` is refused (convert it, or fix its corners), a box of zero
width or height is allowed and has area 0 (its IoU with anything is 0, as its union is
empty or its intersection is).

References matched (tests pin each): ``pycocotools.mask.iou`` for the IoU matrix;
torchvision's ``ops.box_convert`` and ``ops.generalized_box_iou`` (looked up, not
imported: torchvision is not a dependency).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from robopercept._checks import check_bool, check_choice, check_int, plain_repr
from robopercept.errors import InputError

__all__ = [
    "FORMATS",
    "box_area",
    "box_convert",
    "box_iou",
    "check_boxes",
    "dihedral_boxes",
    "generalized_box_iou",
]

#: the box formats of :func:`box_convert`
FORMATS = ("xyxy", "xywh", "cxcywh")


# --------------------------------------------------------------------------- guards
def _limit(dtype: torch.dtype) -> float:
    """Largest coordinate whose products (areas) stay finite in ``dtype``."""
    return math.sqrt(torch.finfo(dtype).max) / 4.0


def numpy_view(t: torch.Tensor) -> np.ndarray | None:
    """A NumPy view of ``t`` (detached) when it is a CPU float32 or float64 tensor, else
    None: the input checks of the ops run in NumPy where they can, a fifth of torch's
    per-call cost on a detector's 10^3 boxes."""
    t = t.detach()
    if t.device.type == "cpu" and t.dtype in (torch.float32, torch.float64):
        return t.numpy()
    return None


def check_boxes(boxes: Any, name: str, cols: int = 4, *, ordered: bool = True) -> torch.Tensor:
    r"""``boxes`` after checking it is a finite floating ``(N, cols)`` tensor (and, with
    ``ordered``, ``x1 <= x2``, ``y1 <= y2``): the boundary check of every function of
    :mod:`robopercept.nn.ops` that takes boxes.

    Coordinates are also refused beyond :math:`\sqrt{\max} / 4` of their dtype, where
    the products (areas) would overflow.

    Parameters
    ----------
    boxes : (N, cols) torch.Tensor
        Floating point, finite.
    name : str
        The argument named in the messages.
    cols : int
        Columns per row (4 for boxes, 5 for ``[batch_index, x1, y1, x2, y2]`` rows).
    ordered : bool
        With 4 columns, refuse ``x2 < x1`` or ``y2 < y1`` (``"xyxy"`` corners).

    Returns
    -------
    (N, cols) torch.Tensor
        ``boxes`` itself.

    Raises
    ------
    InputError
        Not a tensor, another shape, not floating point, NaN/inf, coordinates whose
        areas overflow, or unordered corners.

    Examples
    --------
    >>> import torch
    >>> check_boxes(torch.tensor([[0.0, 0.0, 2.0, 3.0]]), "boxes").shape
    torch.Size([1, 4])
    """
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
        view = numpy_view(boxes)
        host = view is not None
        x: Any = view if host else boxes.detach()
        if not bool(np.isfinite(x).all() if host else torch.isfinite(x).all()):
            raise InputError(
                f"{name} must be finite; got NaN/inf coordinates: drop those rows first, "
                f"e.g. {name}[torch.isfinite({name}).all(1)]"
            )
        big = float(np.abs(x).max() if host else x.abs().max())
        if big > _limit(boxes.dtype):
            raise InputError(
                f"{name} has coordinates up to {big:.3g}; beyond {_limit(boxes.dtype):.3g} "
                f"their areas overflow {boxes.dtype}: use float64 or rescale the boxes"
            )
        if ordered and cols == 4:
            bad = (x[:, 2] < x[:, 0]) | (x[:, 3] < x[:, 1])
            if bool(bad.any()):
                i = int(np.flatnonzero(bad)[0] if host else torch.nonzero(bad)[0, 0])
                raise InputError(
                    f"{name} must be (x1, y1, x2, y2) with x1 <= x2 and y1 <= y2; row {i} is "
                    f"{plain_repr(boxes[i].tolist())}: (x, y, w, h) boxes? convert with "
                    f"box_convert({name}, 'xywh', 'xyxy')"
                )
    return boxes


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
    boxes = check_boxes(boxes, "boxes", ordered=False)
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
    boxes = check_boxes(boxes, "boxes")
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
    a = check_boxes(boxes1, "boxes1")
    b = check_boxes(boxes2, "boxes2")
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
    a = check_boxes(boxes1, "boxes1")
    b = check_boxes(boxes2, "boxes2")
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
    b = check_boxes(boxes, "boxes")
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
