r"""Feature extractors shared by the task wings: a small ResNet-style
:class:`DetectionBackbone` built from :mod:`robopercept.nn.core.blocks`, with an optional
feature pyramid (:class:`FPN`, Lin et al. 2017). The detectors of
:mod:`robopercept.nn.detection` and the FCN of :mod:`robopercept.nn.segmentation.networks`
stand on it.

:data:`IMAGE_MEAN` and :data:`IMAGE_STD` (ImageNet's) are the input normalization
:math:`(x - \mu) / \sigma` that every detector applies inside the model, and
:data:`MAX_CHANNELS` bounds the width of any FPN or head.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.blocks import ConvBNAct, ResidualBlock

__all__ = [
    "FPN",
    "IMAGE_MEAN",
    "IMAGE_STD",
    "MAX_CHANNELS",
    "DetectionBackbone",
]


#: the most channels a detector's FPN or head may have (a 3 x 3 convolution of 4096 to
#: 4096 channels holds 600 MB of weights)
MAX_CHANNELS = 4096

#: ImageNet mean and std: the normalization inside every detector
IMAGE_MEAN = (0.485, 0.456, 0.406)
IMAGE_STD = (0.229, 0.224, 0.225)

_STRIDES = (4, 8, 16, 32)


class FPN(nn.Module):
    r"""Feature pyramid network (Lin et al. 2017): lateral 1 x 1 convolutions to
    ``out_channels``, a top-down pathway adding the nearest-upsampled coarser level,
    and a 3 x 3 convolution on each sum: :math:`P_l = \mathrm{conv}_{3}(\mathrm{lat}(C_l)
    + \mathrm{up}(P'_{l+1}))`.

    Parameters
    ----------
    in_channels : sequence of int
        Channels of the input maps, finest first.
    out_channels : int

    Examples
    --------
    >>> import torch
    >>> fpn = FPN([8, 16], 12)
    >>> [tuple(p.shape) for p in fpn([torch.zeros(1, 8, 8, 8), torch.zeros(1, 16, 4, 4)])]
    [(1, 12, 8, 8), (1, 12, 4, 4)]
    """

    def __init__(self, in_channels: Sequence[int], out_channels: int) -> None:
        super().__init__()
        if not isinstance(in_channels, (list, tuple)) or not in_channels:
            raise InputError(
                f"in_channels must be a non-empty list of ints; got {plain_repr(in_channels)}"
            )
        chans = [check_count(c, "in_channels", 1, 1 << 16) for c in in_channels]
        out_channels = check_count(out_channels, "out_channels", 1, MAX_CHANNELS)
        self.lateral = nn.ModuleList(nn.Conv2d(c, out_channels, 1) for c in chans)
        self.output = nn.ModuleList(
            nn.Conv2d(out_channels, out_channels, 3, padding=1) for _ in chans
        )
        self.out_channels = out_channels

    def forward(self, features: list[torch.Tensor]) -> list[torch.Tensor]:
        if not isinstance(features, (list, tuple)) or len(features) != len(self.lateral):
            raise InputError(
                f"features must be a list of {len(self.lateral)} (N, C, H, W) maps, finest "
                f"first; got {plain_repr(features)}"
            )
        inner = self.lateral[-1](features[-1])
        out = [self.output[-1](inner)]
        for i in range(len(features) - 2, -1, -1):
            lat = self.lateral[i](features[i])
            inner = lat + F.interpolate(inner, size=lat.shape[-2:], mode="nearest")
            out.insert(0, self.output[i](inner))
        return out


class DetectionBackbone(nn.Module):
    """A small ResNet-style feature extractor from the foundation's blocks, with an
    optional :class:`FPN`.

    Layout: a stride-2 3 x 3 :class:`~robopercept.nn.core.blocks.ConvBNAct` stem of ``width``
    channels and a :class:`~robopercept.nn.core.blocks.ResidualBlock`, then one stride-2
    residual block per further stride (4, 8, 16, 32), doubling the channels up to
    ``8 width``. The maps at ``strides`` are returned, finest first (through the FPN
    when ``fpn_channels`` is given).

    Parameters
    ----------
    width : int
        Channels of the stem.
    strides : sequence of int
        Output strides, increasing, from {4, 8, 16, 32}.
    fpn_channels : int, optional
        Build an FPN with this many channels on the outputs.
    blocks : int
        Residual blocks per stride-2 stage (1 by default; ResNet-18 has 2): each extra
        block (stride 1, same channels) adds two 3 x 3 convolutions, so :math:`4 s`
        pixels of receptive field at the stage's stride :math:`s`.

    Attributes
    ----------
    out_channels : list of int
        Channels of each output map.

    Examples
    --------
    >>> import torch
    >>> bb = DetectionBackbone(8, strides=(8, 16), fpn_channels=16)
    >>> [tuple(f.shape) for f in bb(torch.zeros(1, 3, 64, 64))]
    [(1, 16, 8, 8), (1, 16, 4, 4)]
    """

    def __init__(
        self,
        width: int = 16,
        strides: Sequence[int] = (8,),
        fpn_channels: int | None = None,
        blocks: int = 1,
    ) -> None:
        super().__init__()
        width = check_count(width, "width", 1, 1024)
        self.blocks = check_count(blocks, "blocks", 1, 16)
        if (
            not isinstance(strides, (list, tuple))
            or not strides
            or any(s not in _STRIDES for s in strides)
            or list(strides) != sorted(set(strides))
        ):
            raise InputError(
                f"strides must be increasing values from {_STRIDES}, e.g. (8, 16); got "
                f"{plain_repr(strides)}"
            )
        self.strides = tuple(int(s) for s in strides)
        self.stem = nn.Sequential(ConvBNAct(3, width, 3, stride=2), ResidualBlock(width, width))
        stages = []
        chans = {2: width}
        c = width
        for s in _STRIDES:
            if s > max(self.strides):
                break
            c_out = min(2 * c, 8 * width)
            stage: nn.Module = ResidualBlock(c, c_out, stride=2)
            if self.blocks > 1:  # (one block alone keeps the shipped checkpoints' keys)
                more = [ResidualBlock(c_out, c_out) for _ in range(self.blocks - 1)]
                stage = nn.Sequential(stage, *more)
            stages.append(stage)
            c = c_out
            chans[s] = c
        self.stages = nn.ModuleList(stages)
        channels = [chans[s] for s in self.strides]
        if fpn_channels is not None:
            fpn_channels = check_count(fpn_channels, "fpn_channels", 1, MAX_CHANNELS)
        self.fpn = FPN(channels, fpn_channels) if fpn_channels is not None else None
        self.out_channels = [self.fpn.out_channels] * len(channels) if self.fpn else channels

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        x = self.stem(x)
        out = []
        s = 2
        for stage in self.stages:
            x = stage(x)
            s *= 2
            if s in self.strides:
                out.append(x)
        return self.fpn(out) if self.fpn is not None else out
