r"""Semantic segmentation networks and losses in torch: the notes' naive
full-resolution network, FCN-32s/16s/8s and U-Net.

Every network maps ``(N, C, H, W)`` images to ``(N, K, H, W)`` class logits for any
``H, W``: the downsampling ones pad the input on the right and bottom to a multiple of
their total stride and crop the logits back (the role of FCN's crop layers).

* :class:`NaiveFCN`: ``depth`` 3 x 3 convolutions at full resolution (padding only),
  then a 1 x 1 classifier: receptive field :math:`1 + 2\,\mathrm{depth}` pixels and
  :math:`O(\mathrm{depth}\, H W c^2)` operations, the cost the notes warn of.
* :class:`FCN` (Long et al. 2015): a strided backbone (the detection backbone's
  residual stages, strides 8, 16, 32), a 1 x 1 class scorer on the stride-32 map,
  upsampled by 2 and added to the scores of the stride-16 map (16s), again to those of
  the stride-8 map (8s), then upsampled to the input size. Upsampling is a learned
  transposed convolution initialised to bilinear interpolation (the paper's) or fixed
  bilinear interpolation (``upsample``).
* :class:`UNet` (Ronneberger et al. 2015): an encoder of double 3 x 3 convolutions and
  2 x 2 max pools, a decoder that upsamples by 2 (transposed convolution or bilinear
  interpolation followed by a 1 x 1 convolution), concatenates the encoder map of the
  same resolution (skip connection) and applies a double convolution.

Losses: :func:`segmentation_cross_entropy` (per-pixel softmax cross entropy with class
weights and an ignore index, ``torch.nn.functional.cross_entropy``) and
:func:`dice_loss` (soft Dice, Milletari et al. 2016).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import (
    check_bool,
    check_choice,
    check_int,
    check_real,
    check_reals,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.nn._guards import MAX_PARAMETERS, check_count
from robopercept.nn.coco.rle import rle_encode
from robopercept.nn.core.backbones import MAX_CHANNELS, DetectionBackbone
from robopercept.nn.core.blocks import ConvBNAct, check_input
from robopercept.nn.data.datasets import to_unit_float
from robopercept.nn.segmentation.metrics import segmentation_confusion, segmentation_scores
from robopercept.nn.train.checkpoint import load_built_model, save_built_model
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.loop import EpochHistory, LoopResult, step_optimizer, train_loop

__all__ = [
    "FCN",
    "SEGMENTERS",
    "NaiveFCN",
    "SegmentationHistory",
    "UNet",
    "bilinear_kernel",
    "build_segmenter",
    "coco_segmentation_results",
    "dice_loss",
    "load_segmenter",
    "predict_segmentation",
    "save_segmenter",
    "segment_arrays",
    "segmentation_cross_entropy",
    "train_segmenter",
]

UPSAMPLE = ("transposed", "bilinear")


def bilinear_kernel(channels: int, factor: int) -> torch.Tensor:
    r"""The ``(channels, channels, k, k)`` weight, :math:`k = 2 f - f \bmod 2`, that
    makes ``conv_transpose2d(x, w, stride=f, padding=(k - f) // 2 ... )`` bilinear
    upsampling by :math:`f` channel by channel (FCN's initialisation,
    ``upsample_filt``):

    .. math:: w_{cc}(i, j) = \left(1 - \frac{|i - c_0|}{s}\right)
                             \left(1 - \frac{|j - c_0|}{s}\right),\quad
              s = \lceil k / 2 \rceil,\;
              c_0 = s - 1 \text{ (k odd) or } s - \tfrac12 \text{ (k even)},

    and 0 between different channels.

    Examples
    --------
    >>> bilinear_kernel(1, 2)[0, 0]
    tensor([[0.0625, 0.1875, 0.1875, 0.0625],
            [0.1875, 0.5625, 0.5625, 0.1875],
            [0.1875, 0.5625, 0.5625, 0.1875],
            [0.0625, 0.1875, 0.1875, 0.0625]])
    """
    c = check_count(channels, "channels", 1, MAX_CHANNELS)
    f = check_count(factor, "factor", 1, 64)
    k = 2 * f - f % 2
    s = (k + 1) // 2
    center = s - 1 if k % 2 == 1 else s - 0.5
    r = torch.arange(k, dtype=torch.float32)
    filt = 1 - (r - center).abs() / s
    w = torch.zeros(c, c, k, k)
    w[range(c), range(c)] = filt[:, None] * filt[None, :]
    return w


class _Upsample(nn.Module):
    """Upsample by ``factor``: a transposed convolution initialised to bilinear
    interpolation (learned), or fixed bilinear interpolation."""

    def __init__(self, channels: int, factor: int, mode: str) -> None:
        super().__init__()
        self.factor, self.mode = factor, mode
        if mode == "transposed":
            k = 2 * factor - factor % 2
            self.conv: nn.ConvTranspose2d | None = nn.ConvTranspose2d(
                channels, channels, k, stride=factor, padding=(k - factor) // 2, bias=False
            )
            with torch.no_grad():
                self.conv.weight.copy_(bilinear_kernel(channels, factor))
        else:
            self.conv = None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.conv is None:
            return F.interpolate(x, scale_factor=self.factor, mode="bilinear", align_corners=False)
        return self.conv(x)


def _check_images(net: nn.Module, x: Any, in_channels: int) -> None:
    """:func:`~robopercept.nn.core.blocks.check_input`, then an image of at least one
    pixel per side in the network's own floating dtype (a float64 batch for float32
    weights: ``x.float()``)."""
    check_input(x, in_channels)
    if x.shape[2] == 0 or x.shape[3] == 0:
        raise InputError(f"x must hold images of at least 1 x 1 pixels; got shape {tuple(x.shape)}")
    weight = next(net.parameters(), None)
    if weight is not None and x.dtype != weight.dtype:
        raise InputError(
            f"x is {x.dtype} but the network's weights are {weight.dtype}: convert the "
            f"images (x.to({weight.dtype})) or the network (net.to({weight.dtype}))"
        )


def _pad_to(x: torch.Tensor, multiple: int, training: bool) -> tuple[torch.Tensor, int, int]:
    """``x`` padded right and bottom to a multiple of ``multiple``, with its size;
    refuses a training batch whose coarsest map would hold one value per channel
    (batch norm cannot normalise it)."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    if training and x.shape[0] * ((h + ph) // multiple) * ((w + pw) // multiple) == 1:
        raise InputError(
            f"a batch of one {h} x {w} image is too small to train on: the stride-"
            f"{multiple} map has a single value per channel, which batch norm cannot "
            f"normalise; use batches of 2 or more, or images larger than {multiple} px "
            "(model.eval() for inference)"
        )
    if ph or pw:
        x = F.pad(x, (0, pw, 0, ph))
    return x, h, w


class NaiveFCN(nn.Module):
    """The notes' naive fully convolutional network: ``depth`` 3 x 3
    :class:`~robopercept.nn.core.blocks.ConvBNAct` layers of ``width`` channels at full
    resolution, then a 1 x 1 classifier.

    Parameters
    ----------
    num_classes : int
    in_channels : int
    width : int
    depth : int

    Examples
    --------
    >>> NaiveFCN(3, depth=2)(torch.zeros(1, 3, 10, 7)).shape
    torch.Size([1, 3, 10, 7])
    """

    def __init__(self, num_classes: int, in_channels: int = 3, width: int = 16, depth: int = 6):
        super().__init__()
        self.num_classes = check_count(num_classes, "num_classes", 1, MAX_CHANNELS)
        self.in_channels = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        width = check_count(width, "width", 1, MAX_CHANNELS)
        depth = check_count(depth, "depth", 1, 256)
        params = 9 * width * (self.in_channels + (depth - 1) * width)
        if params > MAX_PARAMETERS:
            raise InputError(
                f"a NaiveFCN of depth {depth} and width {width} would have {params} weights; "
                f"the limit is {MAX_PARAMETERS}: lower the width or the depth"
            )
        layers: list[nn.Module] = []
        c = self.in_channels
        for _ in range(depth):
            layers.append(ConvBNAct(c, width))
            c = width
        self.features = nn.Sequential(*layers)
        self.classifier = nn.Conv2d(width, self.num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _check_images(self, x, self.in_channels)
        if self.training and x.shape[0] * x.shape[2] * x.shape[3] == 1:
            raise InputError(
                "a batch of one 1 x 1 image is too small to train on: batch norm needs more "
                "than one value per channel; use batches of 2 or more, or larger images "
                "(model.eval() for inference)"
            )
        return self.classifier(self.features(x))


class FCN(nn.Module):
    """FCN-32s, 16s or 8s on the detection backbone (strides 8, 16, 32).

    Parameters
    ----------
    num_classes : int
    variant : {"32s", "16s", "8s"}
    width : int
        Backbone width (its stride-8, 16, 32 maps have 4, 8, 8 times ``width``
        channels).
    upsample : {"transposed", "bilinear"}
        Learned transposed convolutions initialised to bilinear interpolation (the
        paper's), or fixed bilinear interpolation.
    in_channels : int
        3 only (the backbone's stem takes RGB).

    Examples
    --------
    >>> FCN(4, "8s", width=4)(torch.zeros(2, 3, 50, 37)).shape
    torch.Size([2, 4, 50, 37])
    """

    def __init__(
        self,
        num_classes: int,
        variant: str = "8s",
        width: int = 16,
        upsample: str = "transposed",
        in_channels: int = 3,
    ) -> None:
        super().__init__()
        self.num_classes = check_count(num_classes, "num_classes", 1, MAX_CHANNELS)
        self.variant = check_choice(variant, "variant", ("32s", "16s", "8s"))
        self.upsample = check_choice(upsample, "upsample", UPSAMPLE)
        if in_channels != 3:
            raise InputError(f"FCN takes RGB images (in_channels=3); got {plain_repr(in_channels)}")
        self.in_channels = 3
        self.backbone = DetectionBackbone(width, strides=(8, 16, 32))
        k = self.num_classes
        c8, c16, c32 = self.backbone.out_channels
        self.score32 = nn.Conv2d(c32, k, 1)
        self.score16 = nn.Conv2d(c16, k, 1) if variant in ("16s", "8s") else None
        self.score8 = nn.Conv2d(c8, k, 1) if variant == "8s" else None
        self.up2a = _Upsample(k, 2, self.upsample) if self.score16 is not None else None
        self.up2b = _Upsample(k, 2, self.upsample) if self.score8 is not None else None
        final = {"32s": 32, "16s": 16, "8s": 8}[variant]
        self.up_final = _Upsample(k, final, self.upsample)
        for s in (self.score16, self.score8):
            if s is not None and s.bias is not None:  # the skips start silent (the paper
                nn.init.zeros_(s.weight)  # zero-initialises them)
                nn.init.zeros_(s.bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _check_images(self, x, 3)
        x, h, w = _pad_to(x, 32, self.training)
        f8, f16, f32 = self.backbone(x)
        s = self.score32(f32)
        if self.score16 is not None and self.up2a is not None:
            s = self.up2a(s) + self.score16(f16)
        if self.score8 is not None and self.up2b is not None:
            s = self.up2b(s) + self.score8(f8)
        return self.up_final(s)[..., :h, :w]


class _Double(nn.Sequential):
    def __init__(self, c_in: int, c_out: int) -> None:
        super().__init__(ConvBNAct(c_in, c_out), ConvBNAct(c_out, c_out))


class UNet(nn.Module):
    """U-Net: ``depth`` levels of double 3 x 3 convolutions (``width`` channels at the
    top, doubling each level down) with 2 x 2 max pooling, a bottom double
    convolution, and a decoder of 2 x upsampling, skip concatenation and double
    convolution; a 1 x 1 classifier.

    Parameters
    ----------
    num_classes : int
    in_channels : int
    width : int
    depth : int
        Downsampling steps (total stride :math:`2^{\\mathrm{depth}}`).
    upsample : {"transposed", "bilinear"}
        A 2 x 2 stride-2 transposed convolution halving the channels, or bilinear
        interpolation then a 1 x 1 convolution halving them.

    Examples
    --------
    >>> net = UNet(2, in_channels=1, width=8, depth=3)
    >>> net(torch.zeros(1, 1, 30, 21)).shape
    torch.Size([1, 2, 30, 21])
    """

    def __init__(
        self,
        num_classes: int,
        in_channels: int = 3,
        width: int = 16,
        depth: int = 4,
        upsample: str = "transposed",
    ) -> None:
        super().__init__()
        self.num_classes = check_count(num_classes, "num_classes", 1, MAX_CHANNELS)
        self.in_channels = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        width = check_count(width, "width", 1, MAX_CHANNELS)
        self.depth = check_count(depth, "depth", 1, 8)
        self.upsample = check_choice(upsample, "upsample", UPSAMPLE)
        if width << self.depth > MAX_CHANNELS:
            raise InputError(
                f"width {width} doubled {self.depth} times passes {MAX_CHANNELS} channels: "
                "lower the width or the depth"
            )
        chans = [width << i for i in range(self.depth + 1)]
        # double 3 x 3 convolutions down, at the bottom and up (skip + upsampled input)
        params = sum(
            9 * (c_in * c + c * c)
            for c_in, c in zip([self.in_channels, *chans[:-1]], chans, strict=True)
        )
        params += sum(9 * 3 * c * c + 4 * 2 * c * c for c in chans[:-1])
        if params > MAX_PARAMETERS:
            raise InputError(
                f"a UNet of width {width} and depth {self.depth} would have about {params} "
                f"weights; the limit is {MAX_PARAMETERS}: lower the width or the depth"
            )
        self.down = nn.ModuleList()
        c = self.in_channels
        for ch in chans[:-1]:
            self.down.append(_Double(c, ch))
            c = ch
        self.bottom = _Double(chans[-2], chans[-1])
        self.ups = nn.ModuleList()
        self.decode = nn.ModuleList()
        for i in range(self.depth - 1, -1, -1):
            hi, lo = chans[i + 1], chans[i]
            if self.upsample == "transposed":
                self.ups.append(nn.ConvTranspose2d(hi, lo, 2, stride=2))
            else:
                self.ups.append(
                    nn.Sequential(
                        nn.Upsample(scale_factor=2, mode="bilinear", align_corners=False),
                        nn.Conv2d(hi, lo, 1),
                    )
                )
            self.decode.append(_Double(2 * lo, lo))
        self.classifier = nn.Conv2d(chans[0], self.num_classes, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        _check_images(self, x, self.in_channels)
        x, h, w = _pad_to(x, 1 << self.depth, self.training)
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
            x = F.max_pool2d(x, 2)
        x = self.bottom(x)
        for up, dec, skip in zip(self.ups, self.decode, reversed(skips), strict=True):
            x = dec(torch.cat([skip, up(x)], dim=1))
        return self.classifier(x)[..., :h, :w]


def _check_logits_target(logits: Any, target: Any) -> tuple[torch.Tensor, torch.Tensor]:
    if not isinstance(logits, torch.Tensor) or logits.ndim != 4:
        raise InputError(f"logits must be a (N, K, H, W) tensor; got {plain_repr(logits)}")
    if not logits.is_floating_point():
        raise InputError(
            f"logits must be floating point (the network's scores); got {logits.dtype}: "
            "use logits.float()"
        )
    if not isinstance(target, torch.Tensor) or target.dtype not in (
        torch.int64,
        torch.int32,
        torch.uint8,
    ):
        raise InputError(
            f"target must be an integer (N, H, W) label tensor; got {plain_repr(target)}: "
            "use torch.as_tensor(labels).long()"
        )
    n, _, h, w = logits.shape
    if tuple(target.shape) != (n, h, w):
        raise InputError(
            f"target has shape {tuple(target.shape)}; the logits {tuple(logits.shape)} need "
            f"({n}, {h}, {w})"
        )
    return logits, target.long()


def _check_labels(target: torch.Tensor, k: int, ignore_index: int) -> None:
    bad = (target != ignore_index) & ((target < 0) | (target >= k))
    if bool(bad.any()):
        v = int(target[bad][0])
        raise InputError(
            f"target holds label {v}, outside the {k} classes [0, {k}) and not the "
            f"ignore_index {ignore_index}"
        )


def segmentation_cross_entropy(
    logits: torch.Tensor,
    target: torch.Tensor,
    weight: torch.Tensor | None = None,
    ignore_index: int = -100,
) -> torch.Tensor:
    r"""Per-pixel softmax cross entropy, averaged over the pixels that are not ignored,
    each weighted by its true class's weight :math:`w_{y}`:

    .. math:: L = \frac{\sum_p w_{y_p} (-\log \mathrm{softmax}(z_p)_{y_p})}{\sum_p w_{y_p}},

    ``torch.nn.functional.cross_entropy(logits, target, weight, ignore_index=...)``,
    after checking the shapes and labels (a label outside the classes is an error
    naming it, not a CUDA assert).

    Parameters
    ----------
    logits : tensor (N, K, H, W)
    target : integer tensor (N, H, W)
    weight : tensor (K,), optional
    ignore_index : int
    """
    logits, target = _check_logits_target(logits, target)
    k = logits.shape[1]
    ig = check_int(ignore_index, "ignore_index")
    _check_labels(target, k, ig)
    if weight is not None:
        try:
            weight = torch.as_tensor(weight, dtype=logits.dtype, device=logits.device)
        except (TypeError, ValueError, RuntimeError):
            weight = torch.full((0,), math.nan)
        if (
            weight.shape != (k,)
            or not bool(torch.isfinite(weight).all())
            or bool((weight < 0).any())
        ):
            raise InputError(f"weight must be {k} finite class weights >= 0")
    if not bool((target != ig).any()):
        return logits.sum() * 0.0  # every pixel ignored: no loss, a zero gradient
    return F.cross_entropy(logits, target, weight=weight, ignore_index=ig)


def dice_loss(
    logits: torch.Tensor,
    target: torch.Tensor,
    ignore_index: int = -100,
    eps: float = 1.0,
) -> torch.Tensor:
    r"""Soft Dice loss over the classes (Milletari et al. 2016, V-Net; averaged over
    classes as in segmentation_models_pytorch's ``DiceLoss``):

    .. math:: L = 1 - \frac{1}{K} \sum_k \frac{2 \sum_p P_{pk} T_{pk} + \epsilon}
                                         {\sum_p P_{pk} + \sum_p T_{pk} + \epsilon},

    :math:`P = \mathrm{softmax}(z)`, :math:`T` the one-hot target, over the pixels not
    ignored.

    Parameters
    ----------
    logits : tensor (N, K, H, W)
    target : integer tensor (N, H, W)
    ignore_index : int
    eps : float
        Smoothing :math:`\epsilon > 0` (an absent class then scores 1, not 0 / 0).
    """
    logits, target = _check_logits_target(logits, target)
    k = logits.shape[1]
    ig = check_int(ignore_index, "ignore_index")
    _check_labels(target, k, ig)
    e = check_real(eps, "eps", 0.0, low_inclusive=False)
    keep = (target != ig).unsqueeze(1).to(logits.dtype)
    prob = logits.softmax(dim=1) * keep
    onehot = F.one_hot(torch.where(target == ig, 0, target), k).permute(0, 3, 1, 2)
    onehot = onehot.to(logits.dtype) * keep
    dims = (0, 2, 3)
    inter = (prob * onehot).sum(dims)
    denom = prob.sum(dims) + onehot.sum(dims)
    return 1 - ((2 * inter + e) / (denom + e)).mean()


#: the names :func:`build_segmenter` takes
SEGMENTERS = ("naive", "fcn32s", "fcn16s", "fcn8s", "unet")
#: the class of each name (an FCN's variant is in its name)
_SEGMENTER_CLASSES: dict[str, type[nn.Module]] = {
    "naive": NaiveFCN,
    "fcn32s": FCN,
    "fcn16s": FCN,
    "fcn8s": FCN,
    "unet": UNet,
}


def build_segmenter(name: str, num_classes: int, **kwargs: Any) -> nn.Module:
    """A segmentation network by name: ``"naive"``, ``"fcn32s"``, ``"fcn16s"``,
    ``"fcn8s"`` or ``"unet"``, the other keywords passed on.

    Examples
    --------
    >>> type(build_segmenter("fcn16s", 3, width=4)).__name__, build_segmenter(
    ...     "fcn16s", 3, width=4).variant
    ('FCN', '16s')
    """
    check_choice(name, "name", SEGMENTERS)
    if name == "naive":
        return NaiveFCN(num_classes, **kwargs)
    if name == "unet":
        return UNet(num_classes, **kwargs)
    if "variant" in kwargs:
        raise InputError(
            f"the name {name!r} sets the FCN variant; got variant={plain_repr(kwargs['variant'])} "
            "too: give the variant in the name only"
        )
    return FCN(num_classes, variant=name[3:], **kwargs)


def save_segmenter(
    path: str | os.PathLike[str],
    model: nn.Module,
    name: str,
    settings: Mapping[str, Any],
    classes: Sequence[str],
    **extra: Any,
) -> Any:
    """Write a segmenter's weights with what rebuilds it (``name`` of
    :data:`SEGMENTERS`, its keyword ``settings``, the ``classes`` of labels 1..K-1,
    label 0 being the background) and ``extra`` plain values; the format of
    :func:`~robopercept.nn.detection.zoo.save_detector`. Returns the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> net = build_segmenter("unet", 3, width=4, depth=2)
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "seg.pt"
    >>> _ = save_segmenter(p, net, "unet", {"width": 4, "depth": 2}, ["a", "b"])
    >>> net2, info = load_segmenter(p)
    >>> info["classes"], type(net2).__name__, net2.num_classes
    (['a', 'b'], 'UNet', 3)
    """

    check_choice(name, "name", SEGMENTERS)
    return save_built_model(path, model, name, settings, classes, **extra)


def _build_from_classes(name: str, n_classes: int, **settings: Any) -> nn.Module:
    # the checkpoint names the foreground classes; the network also scores the background
    return build_segmenter(name, n_classes + 1, **settings)


def load_segmenter(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a segmenter written by :func:`save_segmenter` (eval mode, on the CPU).

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a checkpoint that is not a segmenter's, settings
        the network's class does not take or refuses, or weights that do not fit it
        (checked before loading: :func:`~robopercept.nn.train.checkpoint.load_built_model`).
    """

    return load_built_model(
        path,
        SEGMENTERS,
        _build_from_classes,
        "segmenter",
        "save_segmenter or `robopercept nn segment train`",
        constructors={name: _SEGMENTER_CLASSES[name] for name in SEGMENTERS},
    )


# ----------------------------------------------------------------------------- training
@dataclass
class SegmentationHistory(EpochHistory):
    """What :func:`train_segmenter` did: the mean training loss per epoch, the
    validation mIoU by epoch (``val``), the epoch kept and the seconds per epoch."""


def _images_tensor(images: Any, what: str) -> torch.Tensor:
    """``(N, H, W, C)`` float images as an ``(N, C, H, W)`` float32 tensor."""
    import numpy as np

    try:
        x = np.asarray(images)
    except (TypeError, ValueError):
        x = np.zeros(0)
    if x.ndim != 4 or x.dtype.kind not in "fiu" or x.shape[0] == 0:
        raise InputError(
            f"{what} images must be a non-empty (N, H, W, C) array (channels last, "
            f"floats); got {plain_repr(images)}"
        )
    if not np.isfinite(x).all():
        raise InputError(f"{what} images hold NaN or infinite values")
    return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 3, 1, 2), dtype=np.float32))


def _segmentation_arrays(images: Any, masks: Any, what: str) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_images_tensor` and ``(N, H, W)`` integer masks as an int64 tensor."""
    import numpy as np

    x = _images_tensor(images, what)
    try:
        y = np.asarray(masks)
    except (TypeError, ValueError):
        y = np.zeros(0)
    n, _, h, w = x.shape
    if y.shape != (n, h, w) or y.dtype.kind not in "iu":
        raise InputError(
            f"{what} masks must be (N, H, W) integer labels matching the images "
            f"{(n, h, w)}; got {plain_repr(masks)}"
        )
    return x, torch.from_numpy(y.astype(np.int64))


@torch.no_grad()
def predict_segmentation(model: nn.Module, images: Any) -> torch.Tensor:
    """Class labels ``(N, H, W)`` (argmax of the logits) of ``(N, H, W, C)`` images,
    one image at a time, in eval mode."""
    if not isinstance(model, nn.Module):
        raise InputError(f"model must be a torch.nn.Module; got {plain_repr(model)}")
    return _predict(model, _images_tensor(images, "predict"))


@torch.no_grad()
def _predict(model: nn.Module, x: torch.Tensor) -> torch.Tensor:
    model.eval()
    dev = next((p.device for p in model.parameters()), torch.device("cpu"))
    return torch.cat([model(x[i : i + 1].to(dev)).argmax(1).cpu() for i in range(len(x))])


def train_segmenter(
    model: nn.Module,
    images: Any,
    masks: Any,
    config: Any = None,
    *,
    val: tuple[Any, Any] | None = None,
    loss: str = "ce+dice",
    class_weights: Any = None,
    ignore_index: int = -100,
    crop: int | None = None,
    dihedral: bool = True,
    samples_per_epoch: int | None = None,
    progress: bool = True,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
) -> SegmentationHistory:
    r"""Train a segmentation network on labelled images.

    Each step takes ``config.batch_size`` samples: an image drawn from a seeded
    shuffle, a random ``crop x crop`` window of it (the whole image without ``crop``),
    and with ``dihedral`` a random flip and quarter turn of image and mask together
    (the 8 symmetries of the square; turns only for square samples). The loss is
    :func:`segmentation_cross_entropy` (``"ce"``), :func:`dice_loss` (``"dice"``) or
    their sum (``"ce+dice"``); the optimizer and per-step schedule come from
    :func:`~robopercept.nn.train.loop.step_optimizer` (``config``), gradients clipped
    at ``config.clip_grad_norm``. With ``val``, the mIoU of the whole validation
    images (:func:`~robopercept.nn.segmentation.metrics.segmentation_scores`) is
    measured after every epoch and the best epoch's weights are kept.

    Parameters
    ----------
    model : nn.Module
        Logits ``(N, K, H, W)`` for images ``(N, C, H, W)``.
    images : array (N, H, W, C) float
    masks : array (N, H, W) int
        Labels in ``[0, K)`` or ``ignore_index``.
    config : TrainConfig, optional
    val : (images, masks), optional
    loss : {"ce", "dice", "ce+dice"}
    class_weights : sequence of K floats, optional
        For the cross entropy: one weight >= 0 per class of the network.
    ignore_index : int
    crop : int, optional
        Side of the random training window (at most the image's sides).
    dihedral : bool
    samples_per_epoch : int, optional
        Samples per epoch (the number of images by default; more when ``crop`` cuts
        several windows from few images).
    progress : bool
    checkpoint : path, optional
        Written after every epoch (:func:`~robopercept.nn.train.loop.train_loop`'s
        checkpoint with ``"history"`` and ``"architecture"``); the best weights go to
        ``<stem>.best.pt``.
    resume : bool
        Continue the run of ``checkpoint`` (same model, data and settings): it ends with
        the weights of an uninterrupted run.

    Returns
    -------
    SegmentationHistory

    Examples
    --------
    >>> import numpy as np
    >>> from robopercept.nn.train.config import TrainConfig
    >>> x = np.zeros((4, 16, 16, 1), np.float32); x[:, 4:12, 4:12] = 1
    >>> y = (x[..., 0] > 0).astype(np.int64)
    >>> net = UNet(2, in_channels=1, width=4, depth=2)
    >>> h = train_segmenter(net, x, y, TrainConfig(epochs=2, batch_size=2, device="cpu"),
    ...                     val=(x, y), progress=False)
    >>> len(h.losses), sorted(h.val)
    (2, [1, 2])
    """

    if not isinstance(model, nn.Module):
        raise InputError(f"model must be a torch.nn.Module; got {plain_repr(model)}")
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    x, y = _segmentation_arrays(images, masks, "training")
    if val is not None and (not isinstance(val, (tuple, list)) or len(val) != 2):
        raise InputError(f"val must be (images, masks); got {plain_repr(val)}")
    vx, vy = _segmentation_arrays(*val, "validation") if val is not None else (None, None)
    check_choice(loss, "loss", ("ce", "dice", "ce+dice"))
    ig = check_int(ignore_index, "ignore_index")
    n, _, h, w = x.shape
    if crop is not None:
        crop = check_count(crop, "crop", 1, 1 << 16)
        if crop > min(h, w):
            raise InputError(f"crop {crop} is larger than the {h} x {w} images")
    per_epoch = (
        n
        if samples_per_epoch is None
        else check_count(samples_per_epoch, "samples_per_epoch", 1, 1 << 30)
    )
    resume = check_bool(resume, "resume")
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    k = getattr(model, "num_classes", None)
    weight = None
    if class_weights is not None:
        cw = check_reals(class_weights, "class_weights", k if isinstance(k, int) else None, 0.0)
        weight = torch.as_tensor(cw, dtype=torch.float32)
    steps = -(-per_epoch // cfg.batch_size)
    params = [p for p in model.parameters() if p.requires_grad]
    opt, sched = step_optimizer(params, cfg, steps)

    def sample() -> tuple[torch.Tensor, torch.Tensor]:
        i = int(torch.randint(n, (1,), generator=gen))
        xi, yi = x[i], y[i]
        if crop is not None:
            y0 = int(torch.randint(h - crop + 1, (1,), generator=gen))
            x0 = int(torch.randint(w - crop + 1, (1,), generator=gen))
            xi, yi = xi[:, y0 : y0 + crop, x0 : x0 + crop], yi[y0 : y0 + crop, x0 : x0 + crop]
        if dihedral:
            if int(torch.randint(2, (1,), generator=gen)):
                xi, yi = xi.flip(-1), yi.flip(-1)
            if xi.shape[-1] == xi.shape[-2]:
                t = int(torch.randint(4, (1,), generator=gen))
                xi, yi = torch.rot90(xi, t, (1, 2)), torch.rot90(yi, t, (0, 1))
        return xi, yi

    def objective(out: torch.Tensor, yb: torch.Tensor) -> torch.Tensor:
        total = out.new_zeros(())
        if loss in ("ce", "ce+dice"):
            total = total + segmentation_cross_entropy(out, yb, weight, ig)
        if loss in ("dice", "ce+dice"):
            total = total + dice_loss(out, yb, ig)
        return total

    hist = SegmentationHistory()
    total = [0.0]

    def batches(epoch: int) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        for b in range(steps):
            m = min(cfg.batch_size, per_epoch - b * cfg.batch_size)
            pairs = [sample() for _ in range(m)]
            yield torch.stack([p[0] for p in pairs]), torch.stack([p[1] for p in pairs])

    def step(xy: tuple[torch.Tensor, torch.Tensor], epoch: int, b: int) -> torch.Tensor:
        value = objective(model(xy[0].to(dev)), xy[1].to(dev))
        total[0] += float(value.detach())
        return value

    def end_epoch(epoch: int, seconds: float) -> None:
        hist.losses.append(total[0] / steps)
        hist.seconds.append(seconds)
        total[0] = 0.0

    def validate(epoch: int) -> float:
        assert vx is not None and vy is not None
        pred = _predict(model, vx)
        classes = k if isinstance(k, int) else int(max(pred.max(), vy.max())) + 1
        conf = segmentation_confusion(vy.numpy(), pred.numpy(), classes, None if ig < 0 else ig)
        hist.val[epoch + 1] = segmentation_scores(conf).miou
        return hist.val[epoch + 1]

    def after_epoch(epoch: int, res: LoopResult, seconds: float) -> dict[str, str]:
        hist.best_epoch = res.best_epoch
        post = {"loss": f"{hist.losses[-1]:.3f}"}
        if hist.val:
            post["val mIoU"] = f"{hist.val[epoch + 1]:.3f}"
        return post

    train_loop(
        model,
        opt,
        batches,
        step,
        epochs=cfg.epochs,
        schedule=sched,
        clip_grad_norm=cfg.clip_grad_norm,
        clip_params=params,
        lr=cfg.lr,
        end_epoch=end_epoch,
        validate=validate if vx is not None else None,
        after_epoch=after_epoch,
        generators={"sampling": gen},
        checkpoint=checkpoint,
        checkpoint_extra=lambda epoch: {
            "architecture": type(model).__name__,
            "history": hist.to_dict(),
        },
        best_extra={"architecture": type(model).__name__},
        resume=resume,
        restore=lambda state: hist.load_dict(state["history"]),
        desc="training segmenter",
        progress=progress,
    )
    return hist


# ----------------------------------------------------------------------------- inference
def segment_arrays(model: nn.Module, images: Sequence[Any]) -> list[Any]:
    """Class labels ``(H, W)`` int64 of NumPy images through a semantic segmenter.

    Each image, ``(H, W)`` or ``(H, W, 3)``, ``uint8``, ``uint16`` or float in [0, 1],
    is scaled to [0, 1] (:func:`~robopercept.nn.data.datasets.to_unit_float`), made grey (the
    channel mean) for a one-channel network or RGB for a three-channel one, and
    predicted one at a time in eval mode (:func:`predict_segmentation`).

    Raises
    ------
    InputError
        Not a segmenter of this module, or an image that is not 2-D grey or RGB.

    Examples
    --------
    >>> import numpy as np
    >>> net = build_segmenter("unet", 3, width=4, depth=2)
    >>> [lab.shape for lab in segment_arrays(net, [np.zeros((20, 30, 3), np.uint8)])]
    [(20, 30)]
    """
    import numpy as np

    c = getattr(model, "in_channels", None)
    if not isinstance(model, nn.Module) or c not in (1, 3):
        raise InputError(
            f"model must be a segmenter of this module taking 1 or 3 channels; got "
            f"{plain_repr(model)}"
        )
    if isinstance(images, np.ndarray) or not isinstance(images, Sequence):
        raise InputError(f"images must be a list of images; got {plain_repr(images)}")
    out = []
    for i, im in enumerate(images):
        a = np.asarray(im) if isinstance(im, np.ndarray) else None
        if a is None or not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
            raise InputError(
                f"images[{i}] must be an (H, W) or (H, W, 3) array; got {plain_repr(im)}"
            )
        x = to_unit_float(a).astype(np.float32)
        if x.ndim == 2:
            x = x[..., None]
        x = x.mean(axis=2, keepdims=True) if c == 1 else np.broadcast_to(x, (*x.shape[:2], 3))
        out.append(predict_segmentation(model, x[None])[0].numpy())
    return out


def coco_segmentation_results(
    image_id: int,
    *,
    labels: Any = None,
    detections: Mapping[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """COCO result entries with run-length encoded masks
    (:func:`~robopercept.nn.coco.rle.rle_encode`) for one image: from a semantic label
    map, one entry per class present (``category_id`` = label, score 1, the class's
    pixels as its mask: COCO's stuff-segmentation format); from instance detections
    (:func:`~robopercept.nn.detection.zoo.detect_arrays` of a Mask R-CNN), one entry per
    instance with its box and score (COCO's ``segm`` results).

    Examples
    --------
    >>> import numpy as np
    >>> r = coco_segmentation_results(3, labels=np.array([[0, 2], [2, 2]]))  # runs 1, 3
    >>> [(e["image_id"], e["category_id"], e["segmentation"]["counts"]) for e in r]
    [(3, 2, '13')]
    """
    import numpy as np

    image_id = check_int(image_id, "image_id")
    if (labels is None) == (detections is None):
        raise InputError("give either labels (semantic) or detections (instances)")
    out: list[dict[str, Any]] = []
    if labels is not None:
        lab = np.asarray(labels)
        if lab.ndim != 2 or lab.dtype.kind not in "iu":
            raise InputError(f"labels must be an (H, W) integer map; got {plain_repr(labels)}")
        for k in np.unique(lab):
            if k <= 0:
                continue
            out.append(
                {
                    "image_id": int(image_id),
                    "category_id": int(k),
                    "segmentation": rle_encode(lab == k),
                    "score": 1.0,
                }
            )
        return out
    assert detections is not None
    if "masks" not in detections:
        raise InputError("detections have no 'masks': run an instance segmenter (Mask R-CNN)")
    for b, k, s, m in zip(
        detections["boxes"],
        detections["labels"],
        detections["scores"],
        detections["masks"],
        strict=True,
    ):
        out.append(
            {
                "image_id": int(image_id),
                "category_id": int(k),
                "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])],
                "score": float(s),
                "segmentation": rle_encode(np.asarray(m)),
            }
        )
    return out
