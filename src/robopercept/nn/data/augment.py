"""Augmentations and normalization of image tensors for the networks of
:mod:`robopercept.nn` (torch).

Augmentations are written in torch and take their randomness from a ``torch.Generator``
given to them (an int seed makes one), never from torch's global state: the same seed
gives the same sequence of augmented images. Each works on one image ``(C, H, W)`` or a
batch ``(N, C, H, W)`` (one independent draw per image) and returns the same shape.
:class:`Compose` chains them.

:class:`Normalize` is ``(x - mean_c) / std_c`` per channel, with the statistics of the
training split only (:func:`~robopercept.nn.data.datasets.normalization_stats`): a
module put first in a model (its buffers travel in the checkpoint) or a dataset
transform.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import (
    check_bool,
    check_choice,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_real,
)
from robopercept.errors import InputError

__all__ = [
    "ColorJitter",
    "Compose",
    "GaussianNoise",
    "Normalize",
    "RandomAffine",
    "RandomCrop",
    "RandomFlip",
]

#: what a dataset's ``transform`` is: one image tensor to another
Transform = Callable[[torch.Tensor], torch.Tensor]


def _as_generator(generator: torch.Generator | int | None) -> torch.Generator:
    """A ``torch.Generator``: the one given, or a new one seeded with the int (0 if None)."""
    if isinstance(generator, torch.Generator):
        return generator
    if generator is None:
        generator = 0
    if isinstance(generator, bool) or not isinstance(generator, (int, np.integer)):
        raise InputError(f"generator must be a torch.Generator or an int seed; got {generator!r}")
    if not -(2**63) <= int(generator) < 2**64:
        raise InputError(f"the seed (generator) must be in [-2**63, 2**64); got {generator}")
    return torch.Generator().manual_seed(int(generator))


def _batched(x: torch.Tensor, name: str) -> tuple[torch.Tensor, bool]:
    """``x`` as ``(N, C, H, W)`` and whether it was one ``(C, H, W)`` image."""
    if not isinstance(x, torch.Tensor):
        raise InputError(
            f"{name} takes a torch tensor; got {type(x).__name__}: use torch.from_numpy"
        )
    if not x.is_floating_point():
        raise InputError(
            f"{name} takes floating-point images; got dtype {x.dtype}: use x.float() / 255 "
            "for 8-bit images"
        )
    if x.ndim == 3:
        return x[None], True
    if x.ndim == 4:
        return x, False
    raise InputError(f"{name} takes (C, H, W) or (N, C, H, W); got shape {tuple(x.shape)}")


def _real_pair(
    value: object, name: str, low: float | None, high: float | None
) -> tuple[float, float]:
    """``value`` as a pair of finite floats in ``[low, high]``."""
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise InputError(f"{name} must be a pair (a, b) of numbers; got {value!r}")
    return check_real(value[0], name, low, high), check_real(value[1], name, low, high)


def _uniform(n: int, lo: float, hi: float, gen: torch.Generator) -> torch.Tensor:
    """``n`` draws of ``U(lo, hi)`` (float32, CPU) from ``gen``."""
    return lo + (hi - lo) * torch.rand(n, generator=gen)


class _Augmentation:
    """Base of the augmentations: the generator and the batch handling."""

    def __init__(self, generator: torch.Generator | int | None) -> None:
        self.generator = _as_generator(generator)

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """Augment one image ``(C, H, W)`` or each image of a batch ``(N, C, H, W)``."""
        batch, single = _batched(x, type(self).__name__)
        out = self._apply(batch)
        return out[0] if single else out

    def _apply(self, x: torch.Tensor) -> torch.Tensor:  # pragma: no cover - abstract
        raise NotImplementedError


class RandomCrop(_Augmentation):
    """Pad by ``padding`` zeros on each side, then cut a random ``size`` window.

    The window's top-left corner ``(i, j)`` is uniform over
    ``0 .. H + 2 p - h`` by ``0 .. W + 2 p - w``; like torchvision's
    ``RandomCrop(size, padding)`` with constant zero fill.

    Parameters
    ----------
    size : int or (height, width)
        Output size.
    padding : int
        Zeros added on each side first (>= 0).
    generator : torch.Generator or int, optional
        Source of randomness (an int seeds a new generator; None seeds 0).
    """

    def __init__(
        self,
        size: int | tuple[int, int],
        padding: int = 0,
        generator: torch.Generator | int | None = None,
    ) -> None:
        super().__init__(generator)
        hw = (size, size) if isinstance(size, (int, np.integer)) else size
        if not isinstance(hw, (tuple, list)) or len(hw) != 2:
            raise InputError(f"size must be an int or (height, width); got {size!r}")
        self.size = (check_int(hw[0], "size", 1), check_int(hw[1], "size", 1))
        self.padding = check_int(padding, "padding", 0)

    def _apply(self, x: torch.Tensor) -> torch.Tensor:
        """Crop each image of the batch at its own random corner."""
        p = self.padding
        if p:
            x = F.pad(x, (p, p, p, p))
        n, _, hp, wp = x.shape
        h, w = self.size
        if h > hp or w > wp:
            raise InputError(
                f"RandomCrop size {self.size} is larger than the padded image ({hp}, {wp}): "
                "use a smaller size or more padding"
            )
        i = torch.randint(0, hp - h + 1, (n,), generator=self.generator)
        j = torch.randint(0, wp - w + 1, (n,), generator=self.generator)
        return torch.stack([x[k, :, i[k] : i[k] + h, j[k] : j[k] + w] for k in range(n)])


class RandomFlip(_Augmentation):
    """Mirror each image with probability ``p``.

    Parameters
    ----------
    p : float
        Probability of flipping, in [0, 1].
    axis : {'horizontal', 'vertical'}
        ``'horizontal'`` mirrors left-right (``torch.flip(x, [-1])``), ``'vertical'``
        top-bottom (``torch.flip(x, [-2])``).
    generator : torch.Generator or int, optional
        Source of randomness.
    """

    def __init__(
        self,
        p: float = 0.5,
        axis: str = "horizontal",
        generator: torch.Generator | int | None = None,
    ) -> None:
        super().__init__(generator)
        self.p = check_real(p, "p (a probability)", 0.0, 1.0)
        axis = check_choice(axis, "axis", ("horizontal", "vertical"))
        self.axis = axis

    def _apply(self, x: torch.Tensor) -> torch.Tensor:
        """Flip the images whose uniform draw is below ``p``."""
        dim = -1 if self.axis == "horizontal" else -2
        flip = torch.rand(x.shape[0], generator=self.generator) < self.p
        return torch.where(flip[:, None, None, None].to(x.device), torch.flip(x, [dim]), x)


class RandomAffine(_Augmentation):
    """Random rotation, translation and scaling about the image centre.

    In pixel coordinates centred on the image (x right, y down), the output pixel
    ``u`` takes the input at ``A^-1 (u - t)`` with ``A = s R(theta)``,
    ``R(theta) = [[cos, sin], [-sin, cos]]`` (positive ``theta`` turns the picture
    counter-clockwise as displayed, as torchvision's ``RandomAffine``),
    ``theta ~ U(degrees)``, ``t = (t_x W, t_y H)`` with ``t_x ~ U(-translate[0],
    translate[0])``, ``t_y`` likewise, ``s ~ U(scale)``. Sampled bilinearly with zeros
    outside (``torch.nn.functional.affine_grid`` / ``grid_sample``, ``align_corners=False``,
    whose normalized coordinates are ``n = D^-1 u`` with ``D = diag(W/2, H/2)``, so
    ``theta_grid = [D^-1 A^-1 D | -D^-1 A^-1 t]``).

    Parameters
    ----------
    degrees : float or (low, high)
        Rotation range in degrees (a float ``d`` means ``(-d, d)``).
    translate : (float, float)
        Largest shift as fractions of width and height, in [0, 1] (as torchvision).
    scale : (low, high)
        Range of the scale factor, within [0.001, 1000].
    generator : torch.Generator or int, optional
        Source of randomness.
    """

    def __init__(
        self,
        degrees: float | tuple[float, float] = 0.0,
        translate: tuple[float, float] = (0.0, 0.0),
        scale: tuple[float, float] = (1.0, 1.0),
        generator: torch.Generator | int | None = None,
    ) -> None:
        super().__init__(generator)
        if isinstance(degrees, (int, float, np.integer, np.floating)) and not isinstance(
            degrees, (bool, np.bool_)
        ):
            d = check_real(degrees, "degrees", 0.0)
            degrees = (-d, d)
        self.degrees = _real_pair(degrees, "degrees", None, None)
        # beyond a shift of the whole image or a scale of 1000 nothing of it is left
        self.translate = _real_pair(translate, "translate", 0.0, 1.0)
        self.scale = _real_pair(scale, "scale", 1e-3, 1e3)
        if self.degrees[0] > self.degrees[1] or self.scale[0] > self.scale[1]:
            raise InputError("degrees and scale ranges must be (low, high) with low <= high")

    def _apply(self, x: torch.Tensor) -> torch.Tensor:
        """Warp each image of the batch with its own random affine map."""
        n, _, h, w = x.shape
        g = self.generator
        theta = torch.deg2rad(_uniform(n, *self.degrees, g).double())
        tx = _uniform(n, -self.translate[0], self.translate[0], g).double() * w
        ty = _uniform(n, -self.translate[1], self.translate[1], g).double() * h
        s = _uniform(n, *self.scale, g).double()
        c, si = torch.cos(theta), torch.sin(theta)
        # A^-1 = R(-theta) / s
        inv = (
            torch.stack([torch.stack([c, -si], -1), torch.stack([si, c], -1)], -2)
            / s[:, None, None]
        )
        d = torch.tensor([w / 2.0, h / 2.0], dtype=torch.float64)
        lin = inv * d[None, None, :] / d[None, :, None]
        t = torch.stack([tx, ty], -1)
        off = -(inv @ t[:, :, None])[:, :, 0] / d[None, :]
        mat = torch.cat([lin, off[:, :, None]], -1).to(dtype=x.dtype, device=x.device)
        grid = F.affine_grid(mat, list(x.shape), align_corners=False)
        return F.grid_sample(x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


class ColorJitter(_Augmentation):
    """Random brightness and contrast: ``x' = clip(c (b x - m) + m, 0, 1)``.

    ``b ~ U(1 - brightness, 1 + brightness)``, ``c ~ U(1 - contrast, 1 + contrast)``,
    ``m`` the mean of ``b x`` over the image's pixels and channels (torchvision uses the
    gray mean, the same for gray images). Apply before normalization (the clip assumes
    [0, 1]; pass ``clip=False`` otherwise).

    Parameters
    ----------
    brightness, contrast : float
        Largest relative change, in [0, 1].
    clip : bool
        Clip the result to [0, 1].
    generator : torch.Generator or int, optional
        Source of randomness.
    """

    def __init__(
        self,
        brightness: float = 0.0,
        contrast: float = 0.0,
        clip: bool = True,
        generator: torch.Generator | int | None = None,
    ) -> None:
        super().__init__(generator)
        self.brightness = check_real(brightness, "brightness", 0.0, 1.0)
        self.contrast = check_real(contrast, "contrast", 0.0, 1.0)
        self.clip = check_bool(clip, "clip")

    def _apply(self, x: torch.Tensor) -> torch.Tensor:
        """Scale brightness, then stretch about the mean, per image."""
        n = x.shape[0]
        b = _uniform(n, 1 - self.brightness, 1 + self.brightness, self.generator)
        c = _uniform(n, 1 - self.contrast, 1 + self.contrast, self.generator)
        b = b.to(x)[:, None, None, None]
        c = c.to(x)[:, None, None, None]
        y = b * x
        m = y.mean(dim=(1, 2, 3), keepdim=True)
        y = c * (y - m) + m
        return y.clamp(0.0, 1.0) if self.clip else y


class GaussianNoise(_Augmentation):
    """Add ``N(0, std^2)`` noise to every pixel (no clipping).

    Parameters
    ----------
    std : float
        Standard deviation (>= 0).
    generator : torch.Generator or int, optional
        Source of randomness.
    """

    def __init__(self, std: float = 0.05, generator: torch.Generator | int | None = None) -> None:
        super().__init__(generator)
        self.std = check_real(std, "std", 0.0)

    def _apply(self, x: torch.Tensor) -> torch.Tensor:
        """``x + std * z`` with ``z`` standard normal from the generator."""
        z = torch.randn(x.shape, generator=self.generator, dtype=x.dtype)
        return x + self.std * z.to(x.device)


class Compose:
    """Apply transforms in order: ``Compose([a, b])(x) == b(a(x))``.

    Parameters
    ----------
    transforms : sequence of callables
    """

    def __init__(self, transforms: Sequence[Transform]) -> None:
        if not isinstance(transforms, (tuple, list)):
            raise InputError(
                "transforms must be a list of callables, e.g. [RandomFlip(), "
                f"GaussianNoise()]; got {transforms!r}"
            )
        self.transforms = list(transforms)
        for t in self.transforms:
            if not callable(t):
                raise InputError(f"Compose takes callables; got {t!r}")

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """Run every transform on ``x``."""
        for t in self.transforms:
            x = t(x)
        return x

    def __repr__(self) -> str:
        """``Compose([...])`` with the transforms' class names."""
        return f"Compose([{', '.join(type(t).__name__ for t in self.transforms)}])"


def _statistics(value: Any, name: str) -> np.ndarray:
    """``value`` (a number or a (C,) sequence) as finite float32 ``(C,)`` statistics."""
    arr = check_ndim(value, name, (0, 1))
    if arr.dtype.kind not in "iuf" or arr.size == 0:
        raise InputError(
            f"{name} must be real numbers, one per channel (e.g. [0.5]); got {value!r}"
        )
    arr = check_finite(arr.astype(np.float64), name)
    # float32 buffers: beyond 1e30 the statistics (and 1/std) leave float32's range
    arr = check_magnitude(arr, name, 1e30, smallest=None)
    if name == "std" and np.any((arr > 0) & (arr < 1e-30)):
        raise InputError(f"std must be >= 1e-30 in every channel (float32); got {value!r}")
    return np.atleast_1d(arr.astype(np.float32))


class Normalize(nn.Module):
    """``(x - mean_c) / std_c`` per channel, with the statistics as buffers (saved in the
    checkpoint, moved with the model, exported to ONNX): put it first in a model, with
    statistics of the training split only
    (:func:`~robopercept.nn.data.datasets.normalization_stats`). Also usable as a dataset
    transform: takes ``(C, H, W)`` images as well as ``(N, C, H, W)`` batches.

    Parameters
    ----------
    mean, std : (C,) array
        Per-channel statistics; ``std`` > 0.
    """

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, mean: Any, std: Any) -> None:
        super().__init__()
        m, s = (_statistics(v, n) for v, n in ((mean, "mean"), (std, "std")))
        if m.shape != s.shape or m.ndim != 1:
            raise InputError(
                f"mean and std must be (C,) of one length; got {m.shape} and {s.shape}"
            )
        if np.any(s <= 0):
            raise InputError(
                "std must be > 0 in every channel: a constant channel cannot be normalized"
            )
        self.register_buffer("mean", torch.from_numpy(m).view(1, -1, 1, 1))
        self.register_buffer("std", torch.from_numpy(s).view(1, -1, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Normalize ``(C, H, W)`` or ``(N, C, H, W)``."""
        if not isinstance(x, torch.Tensor) or not x.is_floating_point():
            raise InputError(
                "Normalize takes a floating-point torch tensor (C, H, W) or (N, C, H, W); "
                f"got {type(x).__name__}"
                + (f" of dtype {x.dtype}" if isinstance(x, torch.Tensor) else "")
                + ": use torch.from_numpy(images).float()"
            )
        single = x.ndim == 3
        batch = x[None] if single else x
        if batch.ndim != 4 or batch.shape[1] != self.mean.shape[1]:
            raise InputError(
                f"Normalize has {self.mean.shape[1]} channels; got an input of shape "
                f"{tuple(x.shape)} (images are (C, H, W), batches (N, C, H, W))"
            )
        out = (batch - self.mean.to(batch)) / self.std.to(batch)
        return out[0] if single else out
