r"""Augmentations of detection samples: each moves the boxes (and masks, and every
other per-box field) with the pixels.

:class:`FlipRotate` draws mirror images and quarter turns (the dihedral group of the
square, for aerial and top-down images); :class:`ScaleJitter` zooms in or out at a
fixed image size (large-scale jitter). Both are callables ``(image, target) ->
(image, target)`` on a ``(C, H, W)`` tensor and a target dict as
:class:`~robopercept.nn.detection.data.DetectionDataset` gives, so a training loop
applies them to each item it draws; boxes are ``xyxy`` in continuous pixel
coordinates (the box convention of :mod:`robopercept.nn.detection.data`).

Each takes ``generator``: a ``torch.Generator``, an int seed, or None (seeded from the
system's entropy); the same seed gives the same sequence of draws.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import torch

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.ops.boxes import dihedral_boxes

__all__ = ["FlipRotate", "ScaleJitter"]


def _augment_generator(generator: int | torch.Generator | None) -> torch.Generator:
    """The augmentations' source of draws: the generator given, one seeded with the int,
    or (None) one seeded from the system's entropy."""
    if isinstance(generator, torch.Generator):
        return generator
    if generator is None:
        g = torch.Generator()
        g.seed()
        return g
    return torch.Generator().manual_seed(check_int(generator, "generator", 0))


class FlipRotate:
    r"""Random mirror images and quarter turns of a detection sample, boxes (and masks)
    moved with the pixels: the dihedral augmentation of aerial and top-down images.

    For an image of width :math:`W` and height :math:`H` and an ``xyxy`` box
    :math:`(x_1, y_1, x_2, y_2)` in continuous pixel coordinates:

    - horizontal flip (probability ``horizontal``): :math:`(W - x_2, y_1, W - x_1, y_2)`;
    - vertical flip (probability ``vertical``): :math:`(x_1, H - y_2, x_2, H - y_1)`;
    - with ``rotate90``, :math:`k \sim U\{0..3\}` counter-clockwise quarter turns
      (``torch.rot90(image, k, (1, 2))``), each mapping a point :math:`(x, y)` to
      :math:`(y, W - x)` and the size to :math:`H \times W`, so a box becomes
      :math:`(y_1, W - x_2, y_2, W - x_1)`.

    Applied in that order (:func:`~robopercept.nn.ops.boxes.dihedral_boxes`). Same generator
    seed, same sequence of draws.

    Parameters
    ----------
    horizontal, vertical : float
        Probabilities in [0, 1].
    rotate90 : bool
        Random quarter turns (use only where orientation carries no meaning).
    generator : int or torch.Generator, optional
        Seed or source of the draws.

    Examples
    --------
    >>> t = FlipRotate(horizontal=1.0, generator=0)
    >>> image, target = t(torch.zeros(3, 10, 20), {"boxes": torch.tensor([[2.0, 1, 5, 4]])})
    >>> target["boxes"].tolist()
    [[15.0, 1.0, 18.0, 4.0]]
    """

    def __init__(
        self,
        horizontal: float = 0.5,
        vertical: float = 0.0,
        rotate90: bool = False,
        generator: int | torch.Generator | None = None,
    ) -> None:
        self.horizontal = check_real(horizontal, "horizontal (a probability)", 0.0, 1.0)
        self.vertical = check_real(vertical, "vertical (a probability)", 0.0, 1.0)
        self.rotate90 = check_bool(rotate90, "rotate90")
        self.generator = _augment_generator(generator)

    def __repr__(self) -> str:
        return (
            f"FlipRotate(horizontal={self.horizontal}, vertical={self.vertical}, "
            f"rotate90={self.rotate90})"
        )

    def __call__(
        self, image: torch.Tensor, target: Mapping[str, Any]
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Transform one ``(C, H, W)`` image and its target (``"boxes"`` ``(K, 4)``
        ``xyxy``, optional ``"masks"`` ``(K, H, W)``; other keys are kept)."""
        if not isinstance(image, torch.Tensor) or image.ndim != 3:
            raise InputError(f"image must be a (C, H, W) torch.Tensor; got {plain_repr(image)}")
        if not isinstance(target, Mapping) or "boxes" not in target:
            raise InputError("target must be a dict with 'boxes' ((K, 4) xyxy)")
        out = dict(target)
        b = torch.as_tensor(target["boxes"]).clone()
        masks = target.get("masks")
        u = torch.rand(3, generator=self.generator)
        hflip, vflip = bool(u[0] < self.horizontal), bool(u[1] < self.vertical)
        k = int(torch.randint(4, (1,), generator=self.generator)) if self.rotate90 else 0
        size = (int(image.shape[1]), int(image.shape[2]))
        b = dihedral_boxes(b.reshape(-1, 4), size, hflip=hflip, vflip=vflip, quarter_turns=k)
        dims = [d for d, on in ((2, hflip), (1, vflip)) if on]
        if dims:
            image = torch.flip(image, dims)
            masks = torch.flip(masks, dims) if masks is not None else None
        if k:
            image = torch.rot90(image, k, (1, 2))
            masks = torch.rot90(masks, k, (1, 2)) if masks is not None else None
        out["boxes"] = b.reshape(-1, 4)
        if masks is not None:
            out["masks"] = masks
        return image.contiguous(), out


class ScaleJitter:
    r"""Random zoom of a detection sample at a fixed image size, boxes moved with the
    pixels: torchvision's ``ScaleJitter`` followed by a random crop or pad back to the
    input size (large-scale jitter, as in Ghiasi et al. 2021, on one image).

    For an image of width :math:`W` and height :math:`H`, a scale
    :math:`s = \exp u`, :math:`u \sim U[\log s_{lo}, \log s_{hi}]` (log-uniform, so
    zooming in and out are equally likely), the image is resized bilinearly to
    :math:`(\lfloor sH \rceil, \lfloor sW \rceil)`, then an :math:`H \times W` window
    at a uniform offset :math:`(o_x, o_y)` is cut from it (:math:`s > 1`) or it is put
    at a uniform offset on a canvas of ``fill`` (:math:`s < 1`). An ``xyxy`` box
    becomes

    .. math:: (s x_1 - o_x, \; s y_1 - o_y, \; s x_2 - o_x, \; s y_2 - o_y)

    (:math:`o \le 0` when padding), clipped to the image. A box that keeps less than
    ``min_visible`` of its scaled area is dropped, with its entries in every other
    per-box field of the target (``labels``, ``masks``, ...: the tensors whose first
    dimension is the number of boxes). Masks are resized by nearest neighbour.

    Parameters
    ----------
    scale : (float, float)
        :math:`(s_{lo}, s_{hi})`, ``0 < s_lo <= s_hi``.
    min_visible : float
        In [0, 1]: the share of a box's area that must stay in the image.
    fill : float
        Value of padded pixels (the images are in [0, 1]).
    generator : int or torch.Generator, optional
        Seed or source of the draws.

    Examples
    --------
    >>> t = ScaleJitter(scale=(2.0, 2.0), generator=0)
    >>> image, target = t(torch.zeros(3, 10, 10), {"boxes": torch.tensor([[4.0, 4, 6, 6]]),
    ...                                            "labels": torch.tensor([1])})
    >>> image.shape, target["boxes"].shape  # same size; the box doubled and moved
    (torch.Size([3, 10, 10]), torch.Size([1, 4]))
    >>> float(target["boxes"][0, 2] - target["boxes"][0, 0])
    4.0
    """

    def __init__(
        self,
        scale: tuple[float, float] = (0.75, 1.33),
        min_visible: float = 0.5,
        fill: float = 0.0,
        generator: int | torch.Generator | None = None,
    ) -> None:
        if not isinstance(scale, (tuple, list)) or len(scale) != 2:
            raise InputError(f"scale must be a pair (low, high), e.g. (0.75, 1.33); got {scale!r}")
        lo = check_real(scale[0], "scale low", 0.0, 16.0, low_inclusive=False)
        hi = check_real(scale[1], "scale high", lo, 16.0)
        self.scale = (lo, hi)
        self.min_visible = check_real(min_visible, "min_visible (a share of the area)", 0.0, 1.0)
        self.fill = check_real(fill, "fill")
        self.generator = _augment_generator(generator)

    def __repr__(self) -> str:
        return f"ScaleJitter(scale={self.scale}, min_visible={self.min_visible}, fill={self.fill})"

    def __call__(
        self, image: torch.Tensor, target: Mapping[str, Any]
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Transform one ``(C, H, W)`` image and its target (``"boxes"`` ``(K, 4)``
        ``xyxy``; other per-box fields follow the boxes kept; other keys are kept)."""
        if not isinstance(image, torch.Tensor) or image.ndim != 3 or not image.is_floating_point():
            raise InputError(
                f"image must be a floating (C, H, W) torch.Tensor; got {plain_repr(image)}"
            )
        if not isinstance(target, Mapping) or "boxes" not in target:
            raise InputError("target must be a dict with 'boxes' ((K, 4) xyxy)")
        h, w = int(image.shape[1]), int(image.shape[2])
        if h < 1 or w < 1 or image.shape[0] < 1:
            raise InputError(f"image must have at least one pixel; got shape {tuple(image.shape)}")
        try:
            b = torch.as_tensor(target["boxes"], dtype=torch.float32)
        except (TypeError, ValueError, RuntimeError):
            b = torch.zeros(0)
        if b.ndim != 2 or b.shape[1] != 4 or not bool(torch.isfinite(b).all()):
            raise InputError(
                "target['boxes'] must be finite (K, 4) xyxy boxes; got "
                f"{plain_repr(target['boxes'])}"
            )
        masks = target.get("masks")
        n_masks = masks.shape[0] if isinstance(masks, torch.Tensor) and masks.ndim == 3 else 0
        u = torch.rand(3, generator=self.generator, dtype=torch.float64)
        lo, hi = math.log(self.scale[0]), math.log(self.scale[1])
        s = math.exp(lo + float(u[0]) * (hi - lo))
        sh, sw = max(1, round(s * h)), max(1, round(s * w))
        check_allocation(
            (image.shape[0] + n_masks) * sh * sw, 4,
            f"the zoomed image and masks ({image.shape[0]} + {n_masks}, {sh}, {sw})",
            "lower the scale's high end",
        )  # fmt: skip
        big = torch.nn.functional.interpolate(
            image[None], size=(sh, sw), mode="bilinear", align_corners=False
        )[0]
        # the offset of the output window in the resized image (negative: padding)
        oy = int(float(u[1]) * (sh - h + 1)) if sh >= h else -int(float(u[1]) * (h - sh + 1))
        ox = int(float(u[2]) * (sw - w + 1)) if sw >= w else -int(float(u[2]) * (w - sw + 1))
        out_img = image.new_full(image.shape, self.fill)
        # rows/cols of the output covered by the resized image, and where they come from
        y0, y1 = max(0, -oy), min(h, sh - oy)
        x0, x1 = max(0, -ox), min(w, sw - ox)
        out_img[:, y0:y1, x0:x1] = big[:, y0 + oy : y1 + oy, x0 + ox : x1 + ox]
        sx, sy = sw / w, sh / h  # the exact factors of the rounded size
        moved = b * torch.tensor([sx, sy, sx, sy]) - torch.tensor([ox, oy, ox, oy])
        clipped = torch.stack(
            [moved[:, 0].clamp(0, w), moved[:, 1].clamp(0, h), moved[:, 2].clamp(0, w),
             moved[:, 3].clamp(0, h)], 1,
        )  # fmt: skip
        area = (moved[:, 2] - moved[:, 0]) * (moved[:, 3] - moved[:, 1])
        kept_area = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
        keep = (kept_area > 0) & (kept_area >= self.min_visible * area)
        k = b.shape[0]
        out = dict(target)
        for key, value in target.items():
            if key == "boxes" or not isinstance(value, torch.Tensor) or value.ndim == 0:
                continue
            if value.shape[0] != k:
                continue
            if key == "masks" and value.ndim == 3:
                m = torch.nn.functional.interpolate(
                    value[None].float(), size=(sh, sw), mode="nearest"
                )[0].to(value.dtype)
                mo = value.new_zeros((k, h, w))
                mo[:, y0:y1, x0:x1] = m[:, y0 + oy : y1 + oy, x0 + ox : x1 + ox]
                value = mo
            out[key] = value[keep]
        out["boxes"] = clipped[keep].to(torch.as_tensor(target["boxes"]).dtype).reshape(-1, 4)
        return out_img.contiguous(), out
