"""A small configurable classifier family built from :mod:`robopercept.nn.core.blocks`.

Each model is ``features -> global average pooling -> dropout -> linear``
(:class:`Classifier`): the convolutional body of VGG (Simonyan & Zisserman 2015),
GoogLeNet (Szegedy et al. 2015) or ResNet (He et al. 2016), scaled down so that it
trains in seconds on 8x8 digits and stays under 100k parameters at the defaults with
one input channel. Global average pooling (Lin et al. 2014, used by GoogLeNet and
ResNet) makes the head independent of the input size, so the same model runs on 8x8
and 32x32 images; dropout sits before the classifier head, as in the notes.

:data:`MODELS` maps names to builders; :func:`build_model` builds one by name.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from robopercept._checks import check_bool, check_real
from robopercept.errors import InputError
from robopercept.nn._guards import (
    MAX_LAYERS,
    MAX_PARAMETERS,
    check_allocation,
    check_count,
    check_module,
)
from robopercept.nn.core.blocks import (
    Bottleneck,
    ConvBNAct,
    InceptionBlock,
    ResidualBlock,
    VGGStage,
    check_input,
)

__all__ = [
    "MODELS",
    "Classifier",
    "build_model",
    "inception_small",
    "resnet_small",
    "vgg_small",
]


def _check_dropout(dropout: float) -> float:
    try:
        return check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
    except InputError as exc:
        raise InputError(f"{exc} (--dropout)") from None


def _check_widths(
    widths: object, name: str = "widths", maximum: int = MAX_PARAMETERS
) -> tuple[int, ...]:
    bad = InputError(
        f"{name} must be a non-empty sequence of positive integers (at most {maximum}, "
        f"at most {MAX_LAYERS} of them); got {widths!r}"
    )
    if not isinstance(widths, (tuple, list)) or not 1 <= len(widths) <= MAX_LAYERS:
        raise bad
    if any(
        isinstance(w, bool) or not isinstance(w, (int, np.integer)) or not 1 <= w <= maximum
        for w in widths
    ):
        raise bad
    return tuple(int(w) for w in widths)


def _within_budget(build: Callable[[], Classifier], name: str) -> Classifier:
    """Build the model once on torch's ``meta`` device (shapes only, no memory) to count
    its parameters, refuse it beyond :data:`~robopercept.nn._guards.MAX_PARAMETERS`,
    then build it for real."""
    with torch.device("meta"):
        count = sum(p.numel() for p in build().parameters())
    if count > MAX_PARAMETERS:
        raise InputError(
            f"{name} with these arguments would have {count:,} parameters; the limit is "
            f"{MAX_PARAMETERS:,} (1 GiB of float32 weights): lower widths, depth or "
            "num_classes"
        )
    return build()


class Classifier(nn.Module):
    """``head(dropout(flatten(avgpool(features(x)))))``: a convolutional classifier.

    Parameters
    ----------
    features : nn.Module
        The convolutional body, ``(N, in_channels, H, W) -> (N, num_features, h, w)``.
    num_features : int
        Channels of the body's output.
    num_classes : int
    in_channels : int
        Channels the input must have (checked in :meth:`forward` by
        :func:`~robopercept.nn.core.blocks.check_input`).
    dropout : float, default 0.0
        Drop probability before the linear head.

    Notes
    -----
    Children: ``features``, ``pool`` (:class:`torch.nn.AdaptiveAvgPool2d` to 1x1),
    ``flatten``, ``dropout``, ``head`` (:class:`torch.nn.Linear`). Replace ``head`` to
    fine-tune on another number of classes.
    """

    def __init__(
        self,
        features: nn.Module,
        num_features: int,
        num_classes: int,
        in_channels: int,
        dropout: float = 0.0,
    ) -> None:
        super().__init__()
        features = check_module(features, "features")
        num_classes = check_count(num_classes, "num_classes", 1, MAX_PARAMETERS)
        num_features = check_count(num_features, "num_features", 1, MAX_PARAMETERS)
        in_channels = check_count(in_channels, "in_channels", 1, MAX_PARAMETERS)
        check_allocation(
            num_features * num_classes,
            torch.get_default_dtype().itemsize,
            f"the linear head ({num_classes} classes x {num_features} features)",
            "lower num_classes or the last width",
        )
        self.in_channels = in_channels
        self.num_classes = num_classes
        self.num_features = num_features
        self.features = features
        self.pool = nn.AdaptiveAvgPool2d(1)
        self.flatten = nn.Flatten(1)
        self.dropout = nn.Dropout(_check_dropout(dropout))
        self.head = nn.Linear(num_features, num_classes)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return the class logits.

        Parameters
        ----------
        x : torch.Tensor, shape (N, in_channels, H, W), floating point

        Returns
        -------
        torch.Tensor, shape (N, num_classes)
            Unnormalized scores (apply ``softmax(dim=1)`` for probabilities).

        Raises
        ------
        InputError
            Wrong channel count, channels-last or 3-D input, non-float tensors.
        """
        x = check_input(x, self.in_channels)
        return self.head(self.dropout(self.flatten(self.pool(self.features(x)))))


def vgg_small(
    in_channels: int = 1,
    num_classes: int = 10,
    widths: Sequence[int] = (16, 32, 64),
    convs_per_stage: int = 2,
    dropout: float = 0.2,
) -> Classifier:
    """A small VGG: one :class:`~robopercept.nn.core.blocks.VGGStage` per width.

    Simonyan & Zisserman (2015): stages of 3x3 convolutions, each ending in a 2x2 max
    pool that halves the resolution while the width grows. Here with batch norm and
    a global-average-pool head in place of VGG's three fully connected layers.

    Parameters
    ----------
    in_channels : int, default 1
    num_classes : int, default 10
    widths : sequence of int, default (16, 32, 64)
        Output channels of each stage; ``len(widths)`` pools, so the input side must be
        at least ``2 ** len(widths)`` (8 for the default).
    convs_per_stage : int, default 2
    dropout : float, default 0.2

    Returns
    -------
    Classifier
        72,666 parameters at the defaults.

    Examples
    --------
    >>> import torch
    >>> vgg_small()(torch.zeros(2, 1, 8, 8)).shape
    torch.Size([2, 10])
    """
    widths = _check_widths(widths)
    convs_per_stage = check_count(convs_per_stage, "convs_per_stage", 1, MAX_LAYERS)
    dropout = _check_dropout(dropout)

    def build() -> Classifier:
        stages = []
        channels = in_channels
        for width in widths:
            stages.append(VGGStage(channels, width, n_convs=convs_per_stage))
            channels = width
        return Classifier(nn.Sequential(*stages), channels, num_classes, in_channels, dropout)

    return _within_budget(build, "vgg_small")


#: default Inception configuration: (ch1x1, ch3x3red, ch3x3, ch5x5red, ch5x5, pool_proj)
INCEPTION_SMALL_BLOCKS = ((16, 16, 24, 4, 8, 8), (32, 32, 48, 8, 16, 16))


def inception_small(
    in_channels: int = 1,
    num_classes: int = 10,
    stem_width: int = 32,
    blocks: Sequence[Sequence[int]] = INCEPTION_SMALL_BLOCKS,
    factorize_5x5: bool = False,
    dropout: float = 0.2,
) -> Classifier:
    """A small GoogLeNet: a 3x3 stem, then Inception blocks with a 2x2 max pool between.

    Szegedy et al. (2015): Inception blocks (:class:`~robopercept.nn.core.blocks.
    InceptionBlock`) stacked with max pools between groups, global average pooling,
    dropout and one linear layer (the paper's head, without the auxiliary classifiers).

    Parameters
    ----------
    in_channels : int, default 1
    num_classes : int, default 10
    stem_width : int, default 32
        Channels of the 3x3 stem convolution.
    blocks : sequence of 6-tuples of int
        ``(ch1x1, ch3x3red, ch3x3, ch5x5red, ch5x5, pool_proj)`` per block; a 2x2 max
        pool follows every block but the last.
    factorize_5x5 : bool, default False
        Two 3x3 convolutions in place of the 5x5 (Inception-v3).
    dropout : float, default 0.2

    Returns
    -------
    Classifier
        29,554 parameters at the defaults.

    Examples
    --------
    >>> import torch
    >>> inception_small()(torch.zeros(2, 1, 8, 8)).shape
    torch.Size([2, 10])
    """
    if (
        not isinstance(blocks, (tuple, list))
        or not 1 <= len(blocks) <= MAX_LAYERS
        or any(not isinstance(b, (tuple, list)) or len(b) != 6 for b in blocks)
    ):
        raise InputError(
            "blocks must be a non-empty sequence of 6-tuples (ch1x1, ch3x3red, ch3x3, "
            f"ch5x5red, ch5x5, pool_proj); got {blocks!r}"
        )
    configs = [_check_widths(b, "each Inception block") for b in blocks]
    factorize_5x5 = check_bool(factorize_5x5, "factorize_5x5")
    dropout = _check_dropout(dropout)

    def build() -> Classifier:
        layers: list[nn.Module] = [ConvBNAct(in_channels, stem_width, 3)]
        channels = stem_width
        for i, config in enumerate(configs):
            ch1x1, ch3x3red, ch3x3, ch5x5red, ch5x5, pool_proj = config
            block = InceptionBlock(
                channels, ch1x1, ch3x3red, ch3x3, ch5x5red, ch5x5, pool_proj, factorize_5x5
            )
            layers.append(block)
            channels = block.out_channels
            if i < len(configs) - 1:
                layers.append(nn.MaxPool2d(2, 2))
        return Classifier(nn.Sequential(*layers), channels, num_classes, in_channels, dropout)

    return _within_budget(build, "inception_small")


def resnet_small(
    in_channels: int = 1,
    num_classes: int = 10,
    widths: Sequence[int] | None = None,
    depth: Sequence[int] | int = 1,
    block: str = "basic",
    zero_init_residual: bool = False,
    dropout: float = 0.2,
) -> Classifier:
    """A small ResNet: a 3x3 stem, then stages of residual blocks, stride 2 between.

    He et al. (2016): the CIFAR layout of the paper's section 4.2 (3x3 stem, no
    initial pool, stages of widths ``w``, ``2w``, ``4w``; the first block of every stage
    after the first has stride 2 and a projection shortcut), with basic
    (:class:`~robopercept.nn.core.blocks.ResidualBlock`) or bottleneck
    (:class:`~robopercept.nn.core.blocks.Bottleneck`, output ``4 * width``) blocks.

    Parameters
    ----------
    in_channels : int, default 1
    num_classes : int, default 10
    widths : sequence of int or None
        Block width per stage (the stem has ``widths[0]`` channels); ``None``:
        ``(16, 32, 64)`` for basic blocks, ``(8, 16, 32)`` for bottlenecks.
    depth : int or sequence of int, default 1
        Blocks per stage (one int for every stage).
    block : {'basic', 'bottleneck'}, default 'basic'
    zero_init_residual : bool, default False
        Start each block's last batch-norm ``gamma`` at zero (Goyal et al. 2017).
    dropout : float, default 0.2

    Returns
    -------
    Classifier
        77,754 parameters (basic) and 33,090 (bottleneck) at the defaults.

    Examples
    --------
    >>> import torch
    >>> resnet_small(block="bottleneck")(torch.zeros(2, 1, 8, 8)).shape
    torch.Size([2, 10])
    """
    if not isinstance(block, str) or block not in ("basic", "bottleneck"):
        raise InputError(f"block must be 'basic' or 'bottleneck'; got {block!r} (--block)")
    if widths is None:
        widths = (16, 32, 64) if block == "basic" else (8, 16, 32)
    widths = _check_widths(widths)
    if isinstance(depth, (int, np.integer)) and not isinstance(depth, bool):
        depths = (check_count(depth, "depth", 1, MAX_LAYERS),) * len(widths)
    else:
        depths = _check_widths(depth, "depth", MAX_LAYERS)
    if len(depths) != len(widths):
        raise InputError(
            f"depth must give one number of blocks per stage ({len(widths)} stages); got {depths!r}"
        )
    zero_init_residual = check_bool(zero_init_residual, "zero_init_residual")
    dropout = _check_dropout(dropout)

    def build() -> Classifier:
        layers: list[nn.Module] = [ConvBNAct(in_channels, widths[0], 3)]
        channels = widths[0]
        for stage, (width, n) in enumerate(zip(widths, depths, strict=True)):
            blocks: list[nn.Module] = []
            for i in range(n):
                stride = 2 if stage > 0 and i == 0 else 1
                unit: ResidualBlock | Bottleneck
                if block == "basic":
                    unit = ResidualBlock(channels, width, stride, zero_init_residual)
                else:
                    unit = Bottleneck(
                        channels, width, stride, zero_init_residual=zero_init_residual
                    )
                blocks.append(unit)
                channels = unit.out_channels
            layers.append(nn.Sequential(*blocks))
        return Classifier(nn.Sequential(*layers), channels, num_classes, in_channels, dropout)

    return _within_budget(build, "resnet_small")


#: the model family by name, for :func:`build_model` and ``robopercept nn ... --model``
MODELS: dict[str, Callable[..., Classifier]] = {
    "vgg_small": vgg_small,
    "inception_small": inception_small,
    "resnet_small": resnet_small,
}


def build_model(name: str, **kwargs: Any) -> Classifier:
    """Build the model ``name`` of :data:`MODELS` with its keyword arguments.

    Parameters
    ----------
    name : {'vgg_small', 'inception_small', 'resnet_small'}
    **kwargs
        Passed to the builder (``in_channels``, ``num_classes``, ``widths``, ...).

    Returns
    -------
    Classifier

    Raises
    ------
    InputError
        Unknown name (the message lists the choices) or an argument the builder does
        not take.

    Examples
    --------
    >>> build_model("resnet_small", num_classes=2).num_classes
    2
    """
    if not isinstance(name, str) or name not in MODELS:
        raise InputError(
            f"unknown model {name!r} (--model): choose one of {', '.join(sorted(MODELS))}"
        )
    try:
        return MODELS[name](**kwargs)
    except TypeError as exc:
        raise InputError(f"bad argument for model {name!r}: {exc}") from exc
