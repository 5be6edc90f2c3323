"""The building blocks of VGG, Inception and ResNet, written in plain torch.

Every block takes and returns a ``(N, C, H, W)`` float tensor (channels first, as in
torch). Each is a readable implementation of its paper's idea:

* :class:`ConvBNAct` -- convolution, batch normalization, activation. The convolution
  has no bias when batch norm follows, since ``BN(Wx + b) = BN(Wx)`` (the mean
  subtraction removes ``b``; Ioffe & Szegedy 2015).
* :class:`VGGStage` -- ``n`` 3x3 convolutions then a 2x2 max pool (Simonyan &
  Zisserman 2015): two stacked 3x3 convolutions see 5x5 with ``2 * 9 = 18`` weights per
  channel pair instead of 25, with one more non-linearity.
* :class:`InceptionBlock` -- parallel 1x1, 1x1->3x3, 1x1->5x5 and 3x3 pool->1x1
  branches concatenated along channels (Szegedy et al. 2015, "Going deeper with
  convolutions"); the 1x1 reductions keep the cost of the wide kernels low.
* :class:`ResidualBlock` and :class:`Bottleneck` -- ``y = relu(F(x) + S(x))`` with an
  identity skip ``S(x) = x``, or a 1x1 projection when the stride or channel count
  changes (He et al. 2016, "Deep residual learning for image recognition", option B).

:func:`check_input` is the boundary guard the models call in ``forward``.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import cast

import torch
from torch import nn

from robopercept._checks import check_bool, check_int
from robopercept.errors import InputError
from robopercept.nn._guards import (
    MAX_LAYERS,
    MAX_PARAMETERS,
    check_allocation,
    check_count,
)

__all__ = [
    "Bottleneck",
    "ConvBNAct",
    "InceptionBlock",
    "ResidualBlock",
    "VGGStage",
    "check_input",
    "make_activation",
]

#: activations accepted by name in :func:`make_activation`
ACTIVATIONS = ("relu", "gelu", "silu", "leaky_relu", "tanh", "none")


def check_input(x: object, in_channels: int) -> torch.Tensor:
    """Check that ``x`` is a ``(N, C, H, W)`` floating-point tensor with ``C == in_channels``.

    Parameters
    ----------
    x : torch.Tensor, shape (N, in_channels, H, W)
        A batch of images, channels first, floating point.
    in_channels : int
        The number of channels the model was built for.

    Returns
    -------
    torch.Tensor
        ``x`` itself (nothing is copied or converted).

    Raises
    ------
    InputError
        If ``x`` is not a tensor (NumPy arrays: ``torch.from_numpy``), not 4-D (a single
        image: ``x.unsqueeze(0)``), channels-last ``(N, H, W, C)`` (``x.permute(0, 3, 1,
        2)``), has the wrong channel count (build the model with ``in_channels=C``, or
        convert the images to grey/RGB), or is not floating point (``x.float()``).

    Examples
    --------
    >>> import torch
    >>> check_input(torch.zeros(2, 1, 8, 8), 1).shape
    torch.Size([2, 1, 8, 8])
    """
    if not isinstance(x, torch.Tensor):
        raise InputError(
            f"input must be a torch.Tensor (N, C, H, W); got {type(x).__name__}: "
            "convert it with torch.from_numpy(images).float()"
        )
    if torch.jit.is_tracing():  # shapes are symbolic while tracing (ONNX export)
        return x
    shape = tuple(x.shape)
    if x.ndim == 3 and in_channels in (shape[0], shape[-1]):
        raise InputError(
            f"input must be a batch (N, C, H, W); got one image of shape {shape}: "
            "add the batch dimension with x.unsqueeze(0)"
        )
    if x.ndim != 4:
        raise InputError(
            f"input must be 4-D (N, C, H, W) with C={in_channels}; got {x.ndim}-D with "
            f"shape {shape}"
        )
    if shape[1] != in_channels:
        if shape[3] == in_channels:
            raise InputError(
                f"input must be channels-first (N, C, H, W) with C={in_channels}; got "
                f"{shape}, which looks channels-last (N, H, W, C): use "
                "x.permute(0, 3, 1, 2)"
            )
        raise InputError(
            f"the model expects {in_channels} input channel(s); got {shape[1]} in input "
            f"of shape {shape}: build the model with in_channels={shape[1]} (--in-channels "
            "on the command line) or convert the images (grey: 1, RGB: 3)"
        )
    if not x.is_floating_point():
        raise InputError(
            f"input must be floating point; got {x.dtype}: use x.float() (and scale uint8 "
            "images to [0, 1] with x.float() / 255)"
        )
    return x


def make_activation(act: str | nn.Module | None) -> nn.Module | None:
    """Return the activation module named ``act`` (a fresh one each call).

    Parameters
    ----------
    act : {'relu', 'gelu', 'silu', 'leaky_relu', 'tanh', 'none'}, nn.Module or None
        A name, a module (returned as is) or ``None``/``'none'`` for no activation.

    Returns
    -------
    nn.Module or None

    Raises
    ------
    InputError
        For an unknown name; the message lists the choices.

    Examples
    --------
    >>> make_activation("relu")
    ReLU(inplace=True)
    """
    if act is None or isinstance(act, nn.Module):
        return act
    if not isinstance(act, str):
        raise InputError(
            f"activation must be one of {', '.join(ACTIVATIONS)}, an nn.Module or None; "
            f"got {type(act).__name__} {act!r}"
        )
    table: dict[str, Callable[[], nn.Module | None]] = {
        "relu": lambda: nn.ReLU(inplace=True),
        "gelu": nn.GELU,
        "silu": lambda: nn.SiLU(inplace=True),
        "leaky_relu": lambda: nn.LeakyReLU(0.1, inplace=True),
        "tanh": nn.Tanh,
        "none": lambda: None,
    }
    if act not in table:
        raise InputError(f"activation must be one of {', '.join(ACTIVATIONS)}; got {act!r}")
    return table[act]()


#: the largest kernel size, stride, padding or dilation a block takes (pixels)
MAX_GEOMETRY = 2**16


class ConvBNAct(nn.Sequential):
    """Convolution, batch normalization and activation: ``act(BN(conv(x)))``.

    The convolution has no bias when batch norm follows (the BN shift ``beta`` plays
    its role; Ioffe & Szegedy 2015). The default padding ``dilation * (k - 1) // 2``
    keeps the spatial size at stride 1 for odd ``k`` ("same" padding, as in VGG);
    output size ``floor((H + 2p - d (k - 1) - 1) / s) + 1``.

    Parameters
    ----------
    in_channels, out_channels : int
        Channels of the input and of the output.
    kernel_size : int, default 3
    stride : int, default 1
    padding : int or None, default None
        ``None`` for "same" padding ``dilation * (kernel_size - 1) // 2``.
    dilation, groups : int, default 1
    bn : bool, default True
        Batch norm after the convolution (and then no convolution bias).
    act : str, nn.Module or None, default 'relu'
        See :func:`make_activation`; ``None`` leaves the output linear (the last BN of a
        residual branch).

    Notes
    -----
    Children, in order: ``conv`` (:class:`torch.nn.Conv2d`), ``bn``
    (:class:`torch.nn.BatchNorm2d`, if ``bn``), ``act`` (if any). Input
    ``(N, in_channels, H, W)``, output ``(N, out_channels, H', W')``.

    Examples
    --------
    >>> import torch
    >>> ConvBNAct(1, 8)(torch.zeros(2, 1, 8, 8)).shape
    torch.Size([2, 8, 8, 8])
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int = 3,
        stride: int = 1,
        padding: int | None = None,
        dilation: int = 1,
        groups: int = 1,
        bn: bool = True,
        act: str | nn.Module | None = "relu",
    ) -> None:
        in_channels = check_count(in_channels, "in_channels", 1, MAX_PARAMETERS)
        out_channels = check_count(out_channels, "out_channels", 1, MAX_PARAMETERS)
        kernel_size = check_count(kernel_size, "kernel_size", 1, MAX_GEOMETRY)
        stride = check_count(stride, "stride", 1, MAX_GEOMETRY)
        dilation = check_count(dilation, "dilation", 1, MAX_GEOMETRY)
        groups = check_count(groups, "groups", 1, MAX_PARAMETERS)
        if in_channels % groups or out_channels % groups:
            raise InputError(
                f"groups={groups} must divide in_channels ({in_channels}) and out_channels "
                f"({out_channels}): choose a common divisor"
            )
        if padding is None:
            padding = dilation * (kernel_size - 1) // 2
        else:
            padding = check_count(padding, "padding", 0, MAX_GEOMETRY)
        bn = check_bool(bn, "bn")
        check_allocation(
            out_channels * (in_channels // groups) * kernel_size**2,
            torch.get_default_dtype().itemsize,
            f"the weights of a {kernel_size}x{kernel_size} convolution from {in_channels} "
            f"to {out_channels} channels",
            "lower the channel counts (widths) or kernel_size",
        )
        layers: OrderedDict[str, nn.Module] = OrderedDict()
        layers["conv"] = nn.Conv2d(
            in_channels,
            out_channels,
            kernel_size,
            stride=stride,
            padding=padding,
            dilation=dilation,
            groups=groups,
            bias=not bn,
        )
        if bn:
            layers["bn"] = nn.BatchNorm2d(out_channels)
        activation = make_activation(act)
        if activation is not None:
            layers["act"] = activation
        super().__init__(layers)
        self.in_channels = in_channels
        self.out_channels = out_channels


class VGGStage(nn.Sequential):
    """``n_convs`` 3x3 :class:`ConvBNAct` layers then a 2x2 max pool (stride 2).

    Simonyan & Zisserman (2015), "Very deep convolutional networks for large-scale
    image recognition": a stack of ``n`` 3x3 convolutions (stride 1, padding 1) has a
    receptive field of ``2n + 1`` with ``9 n C^2`` weights, against ``(2n + 1)^2 C^2``
    for one convolution of that size, and ``n`` non-linearities instead of one. The
    pool halves ``H`` and ``W`` (floor). Batch norm is a later addition (the paper's
    VGG has none; torchvision's ``vgg*_bn`` has it).

    Parameters
    ----------
    in_channels, out_channels : int
    n_convs : int, default 2
    pool : bool, default True
        End with ``MaxPool2d(2)``; ``False`` keeps the spatial size.
    act : str, nn.Module or None, default 'relu'

    Examples
    --------
    >>> import torch
    >>> VGGStage(1, 16)(torch.zeros(2, 1, 8, 8)).shape
    torch.Size([2, 16, 4, 4])
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        n_convs: int = 2,
        pool: bool = True,
        act: str | nn.Module | None = "relu",
    ) -> None:
        n_convs = check_count(n_convs, "n_convs", 1, MAX_LAYERS)
        pool = check_bool(pool, "pool")
        layers: OrderedDict[str, nn.Module] = OrderedDict()
        for i in range(n_convs):
            layers[f"conv{i + 1}"] = ConvBNAct(
                in_channels if i == 0 else out_channels, out_channels, 3, act=act
            )
        if pool:
            layers["pool"] = nn.MaxPool2d(2, 2)
        super().__init__(layers)
        self.in_channels = in_channels
        self.out_channels = out_channels


class InceptionBlock(nn.Module):
    """Inception module: four parallel branches concatenated along channels.

    Szegedy et al. (2015), "Going deeper with convolutions" (GoogLeNet), figure 2(b):

    * ``branch1``: 1x1 convolution to ``ch1x1``;
    * ``branch3``: 1x1 reduction to ``ch3x3red``, then 3x3 to ``ch3x3``;
    * ``branch5``: 1x1 reduction to ``ch5x5red``, then 5x5 to ``ch5x5`` (or two 3x3,
      same receptive field, ``18`` instead of ``25`` weights per channel pair, as in
      Inception-v2/v3, with ``factorize_5x5=True``);
    * ``branch_pool``: 3x3 max pool (stride 1, padding 1), then 1x1 to ``pool_proj``.

    Every branch keeps ``H`` and ``W``, so the output is
    ``(N, ch1x1 + ch3x3 + ch5x5 + pool_proj, H, W)`` (:attr:`out_channels`). Each
    convolution is a :class:`ConvBNAct` (batch norm as in Inception-v2).

    Parameters
    ----------
    in_channels : int
    ch1x1, ch3x3red, ch3x3, ch5x5red, ch5x5, pool_proj : int
        Output channels of each branch and of its 1x1 reduction, named as in the paper's
        table 1.
    factorize_5x5 : bool, default False
    act : str, nn.Module or None, default 'relu'

    Examples
    --------
    >>> import torch
    >>> block = InceptionBlock(8, 4, 4, 8, 2, 4, 4)
    >>> block.out_channels, block(torch.zeros(1, 8, 6, 6)).shape
    (20, torch.Size([1, 20, 6, 6]))
    """

    def __init__(
        self,
        in_channels: int,
        ch1x1: int,
        ch3x3red: int,
        ch3x3: int,
        ch5x5red: int,
        ch5x5: int,
        pool_proj: int,
        factorize_5x5: bool = False,
        act: str | nn.Module | None = "relu",
    ) -> None:
        super().__init__()
        factorize_5x5 = check_bool(factorize_5x5, "factorize_5x5")
        self.branch1 = ConvBNAct(in_channels, ch1x1, 1, act=act)
        self.branch3 = nn.Sequential(
            ConvBNAct(in_channels, ch3x3red, 1, act=act), ConvBNAct(ch3x3red, ch3x3, 3, act=act)
        )
        if factorize_5x5:
            self.branch5 = nn.Sequential(
                ConvBNAct(in_channels, ch5x5red, 1, act=act),
                ConvBNAct(ch5x5red, ch5x5, 3, act=act),
                ConvBNAct(ch5x5, ch5x5, 3, act=act),
            )
        else:
            self.branch5 = nn.Sequential(
                ConvBNAct(in_channels, ch5x5red, 1, act=act),
                ConvBNAct(ch5x5red, ch5x5, 5, act=act),
            )
        self.branch_pool = nn.Sequential(
            nn.MaxPool2d(3, stride=1, padding=1), ConvBNAct(in_channels, pool_proj, 1, act=act)
        )
        self.in_channels = in_channels
        #: channels of the concatenated output
        self.out_channels = int(ch1x1 + ch3x3 + ch5x5 + pool_proj)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Concatenate the four branches along channels.

        Parameters
        ----------
        x : torch.Tensor, shape (N, in_channels, H, W)

        Returns
        -------
        torch.Tensor, shape (N, out_channels, H, W)
        """
        return torch.cat(
            [self.branch1(x), self.branch3(x), self.branch5(x), self.branch_pool(x)], dim=1
        )


def _shortcut(in_channels: int, out_channels: int, stride: int) -> nn.Module:
    """Identity when shapes agree, else a 1x1 projection with BN (He et al. option B)."""
    if stride == 1 and in_channels == out_channels:
        return nn.Identity()
    return ConvBNAct(in_channels, out_channels, 1, stride=stride, padding=0, act=None)


class ResidualBlock(nn.Module):
    """Basic residual block: ``relu(BN(conv3x3(relu(BN(conv3x3(x))))) + S(x))``.

    He et al. (2016), "Deep residual learning for image recognition", figure 2 / the
    "basic" block of ResNet-18/34. The skip ``S`` is the identity when ``stride == 1``
    and ``in_channels == out_channels``, else a 1x1 convolution with stride and batch
    norm (the paper's option B). The first 3x3 convolution carries the stride.

    With the last batch norm's ``gamma`` set to zero (``zero_init_residual=True``, Goyal
    et al. 2017), the residual branch outputs 0 and an identity block computes
    ``relu(x)``: the network starts as a shallower one.

    Parameters
    ----------
    in_channels, out_channels : int
    stride : int, default 1
    zero_init_residual : bool, default False
    act : str, nn.Module or None, default 'relu'

    Examples
    --------
    >>> import torch
    >>> ResidualBlock(8, 16, stride=2)(torch.zeros(1, 8, 8, 8)).shape
    torch.Size([1, 16, 4, 4])
    """

    #: output channels per ``out_channels`` (1 for the basic block)
    expansion = 1

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        stride: int = 1,
        zero_init_residual: bool = False,
        act: str | nn.Module | None = "relu",
    ) -> None:
        super().__init__()
        zero_init_residual = check_bool(zero_init_residual, "zero_init_residual")
        self.conv1 = ConvBNAct(in_channels, out_channels, 3, stride=stride, act=act)
        self.conv2 = ConvBNAct(out_channels, out_channels, 3, act=None)
        self.shortcut = _shortcut(in_channels, out_channels, stride)
        self.act = make_activation(act) or nn.Identity()
        self.in_channels = in_channels
        self.out_channels = out_channels
        if zero_init_residual:
            nn.init.zeros_(cast(nn.BatchNorm2d, self.conv2.bn).weight)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return ``act(F(x) + S(x))``.

        Parameters
        ----------
        x : torch.Tensor, shape (N, in_channels, H, W)

        Returns
        -------
        torch.Tensor, shape (N, out_channels, H', W'), ``H' = floor((H - 1) / stride) + 1``
        """
        return self.act(self.conv2(self.conv1(x)) + self.shortcut(x))


class Bottleneck(nn.Module):
    """Bottleneck residual block: 1x1 reduce, 3x3, 1x1 expand (x4), plus the skip.

    He et al. (2016), figure 5 (right), the block of ResNet-50/101/152:
    ``relu(BN(W3 relu(BN(W2 relu(BN(W1 x))))) + S(x))`` with ``W1`` 1x1 to ``width``,
    ``W2`` 3x3 at ``width`` (carrying the stride, as torchvision's "ResNet v1.5"), ``W3``
    1x1 to ``width * expansion`` channels, ``expansion = 4``. The skip is the identity
    when shapes agree, else a 1x1 projection with batch norm.

    Parameters
    ----------
    in_channels : int
    width : int
        Channels inside the bottleneck; the output has ``width * expansion``.
    stride : int, default 1
    expansion : int, default 4
    zero_init_residual : bool, default False
        Start the last batch norm's ``gamma`` at zero.
    act : str, nn.Module or None, default 'relu'

    Examples
    --------
    >>> import torch
    >>> Bottleneck(16, 8, stride=2)(torch.zeros(1, 16, 8, 8)).shape
    torch.Size([1, 32, 4, 4])
    """

    #: output channels per bottleneck ``width`` (4 in He et al. 2016)
    expansion = 4

    def __init__(
        self,
        in_channels: int,
        width: int,
        stride: int = 1,
        expansion: int = 4,
        zero_init_residual: bool = False,
        act: str | nn.Module | None = "relu",
    ) -> None:
        super().__init__()
        expansion = check_count(expansion, "expansion", 1, MAX_LAYERS)
        zero_init_residual = check_bool(zero_init_residual, "zero_init_residual")
        self.expansion = expansion
        out_channels = check_int(width, "width", 1) * expansion
        self.conv1 = ConvBNAct(in_channels, width, 1, act=act)
        self.conv2 = ConvBNAct(width, width, 3, stride=stride, act=act)
        self.conv3 = ConvBNAct(width, out_channels, 1, act=None)
        self.shortcut = _shortcut(in_channels, out_channels, stride)
        self.act = make_activation(act) or nn.Identity()
        self.in_channels = in_channels
        self.out_channels = out_channels
        if zero_init_residual:
            nn.init.zeros_(cast(nn.BatchNorm2d, self.conv3.bn).weight)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Return ``act(F(x) + S(x))``.

        Parameters
        ----------
        x : torch.Tensor, shape (N, in_channels, H, W)

        Returns
        -------
        torch.Tensor, shape (N, width * expansion, H', W')
        """
        return self.act(self.conv3(self.conv2(self.conv1(x))) + self.shortcut(x))
