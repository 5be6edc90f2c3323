r"""Anchors and box coding of the R-CNN family, in torch: :class:`BoxCoder` (the
Faster R-CNN deltas that move a proposal onto a target, and back) and
:class:`AnchorGenerator` (``sizes`` x ``aspect_ratios`` boxes at every cell of the
feature maps of an RPN), with torchvision's conventions (looked up, not imported).
Boxes are ``"xyxy"`` pixels (:mod:`robopercept.nn.ops.boxes`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation, check_float_dtype
from robopercept.nn.ops.boxes import check_boxes

__all__ = ["AnchorGenerator", "BoxCoder"]


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
            checks of :func:`~robopercept.nn.ops.boxes.check_boxes`.
        """
        g = check_boxes(reference_boxes, "reference_boxes")
        p = check_boxes(proposals, "proposals")
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
        b = check_boxes(boxes, "boxes")
        if not isinstance(deltas, torch.Tensor) or deltas.ndim != 2 or deltas.shape[1] % 4:
            raise InputError(
                "deltas must be a (N, 4 k) torch.Tensor of (dx, dy, dw, dh); got "
                + (
                    str(tuple(deltas.shape))
                    if isinstance(deltas, torch.Tensor)
                    else type(deltas).__name__
                )
            )
        d = check_boxes(deltas, "deltas", deltas.shape[1], ordered=False)
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
