r"""PointNet (Qi, Su, Mo and Guibas 2017), written in plain torch, and the pieces that
:mod:`robopercept.nn.cloud.dgcnn` shares with it.

Inputs
------
Every model here takes a batch of point clouds **channels-last**, ``x`` of shape
``(B, N, C)`` (``C = in_channels``, xyz first, then any extra per-point features such as
normals), float, and an optional ``mask`` ``(B, N)`` bool: ``True`` for a real point,
``False`` for padding, so that clouds of different sizes share a batch. Padded points
never influence a real point's output nor the pooled global feature: the padded rows of
``x`` are set to zero, pooling fills them with :math:`-\infty` (max) or leaves them out
(average), and batch normalization takes its training statistics over the real points
only (:class:`MaskedBatchNorm`). A cloud in a padded batch gives the same output (eval
mode) as alone.

The network
-----------
A shared MLP is the same small network :math:`h` applied to every point (the 1x1
``Conv1d`` of the reference code, written here as a :class:`torch.nn.Linear` on the
channels-last rows): ``Linear`` (no bias: batch norm's shift plays its role), batch
norm, ReLU. PointNet's global feature is a symmetric function of the point set,

.. math::

    g(\{x_1, \dots, x_N\}) = \max_{i} h(T_2\, \phi(T_1 x_i)) \in \mathbb{R}^{1024}

(max per channel), so the output is invariant to the order of the points. :math:`T_1`
(3x3, on xyz) and :math:`T_2` (64x64, on the per-point features) are predicted by
T-Nets (:class:`TNet`: a mini PointNet whose last layer starts at the identity), applied
to points as row vectors, ``x @ T`` (as the reference code's ``bmm``), and kept near
orthogonal by :func:`transform_regularizer` :math:`L_{reg} = \lVert I - A A^T
\rVert_F^2`. Classification maps :math:`g` through FC 512, 256 (batch norm, ReLU,
dropout) to ``K`` logits; segmentation concatenates each point's 64-d feature (after
:math:`T_2`) with :math:`g` (and a one-hot object category, for part segmentation) and
maps it through a shared MLP 512, 256, 128 to ``K`` logits per point (the paper's Fig. 2).

Critical points
---------------
Each global-feature channel takes its max at one point; the set of these points is the
paper's critical point set :math:`C_S` (:func:`critical_points`). Since :math:`\max` over
a superset of the argmaxes is unchanged, the model gives the same global feature on
:math:`C_S` alone as on the whole cloud (with T-Nets, the points that set the T-Nets'
own max pools are added, since the transforms depend on them).

Reference code: ``charlesq34/pointnet`` (TensorFlow) and ``fxia22/pointnet.pytorch``;
the layer sizes are the paper's (``pointnet.pytorch`` drops one 64-wide layer).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_bool, check_choice, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import MAX_PARAMETERS, check_count, check_module

__all__ = [
    "TASKS",
    "CloudOutput",
    "MaskedBatchNorm",
    "PointNet",
    "SharedMLP",
    "TNet",
    "check_cloud_batch",
    "critical_points",
    "masked_max_pool",
    "transform_regularizer",
]

#: what a point-cloud model predicts: one label per cloud or one per point
TASKS = ("classify", "segment")
#: the most output classes, object categories and channels a layer may ask for
_MAX_CHANNELS = 2**16
#: the widest channel multiplier of :class:`PointNet` (the 256x256 feature T-Net then
#: has 67 M parameters)
_MAX_WIDTH = 4.0


@dataclass(frozen=True)
class CloudOutput:
    """What a point-cloud model computes, besides its logits (``forward_aux``).

    Parameters
    ----------
    logits : torch.Tensor, shape (B, K) or (B, N, K)
        Per cloud (``task="classify"``) or per point (``task="segment"``).
    global_feature : torch.Tensor, shape (B, F)
        The pooled feature of each cloud (before any category one-hot is appended).
    pooled_index : torch.Tensor, shape (B, F), int64
        For each global-feature channel set by a max pool, the point that set it
        (the argmax of the masked max pool; the first such point on ties); ``-1`` for
        channels that are not a max (DGCNN's average-pooled half).
    transforms : list of torch.Tensor
        PointNet: the input transform ``(B, 3, 3)`` and the feature transform
        ``(B, 64, 64)``, those enabled; ``[]`` otherwise.
    graphs : list of torch.Tensor
        DGCNN: the ``(B, N, k)`` neighbour indices each EdgeConv layer used; ``[]``
        otherwise.

    Examples
    --------
    >>> out = PointNet(2, width=0.125).eval().forward_aux(torch.rand(1, 16, 3))
    >>> out.logits.shape, out.global_feature.shape, [t.shape[1] for t in out.transforms]
    (torch.Size([1, 2]), torch.Size([1, 128]), [3, 8])
    """

    logits: torch.Tensor
    global_feature: torch.Tensor
    pooled_index: torch.Tensor
    transforms: list[torch.Tensor] = field(default_factory=list)
    graphs: list[torch.Tensor] = field(default_factory=list)


# --------------------------------------------------------------------------- input checks


def check_cloud_batch(
    x: Any,
    in_channels: int,
    mask: Any = None,
    category: Any = None,
    num_categories: int = 0,
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor | None]:
    """Check a batch of point clouds (and its mask and categories) at a model's boundary.

    Parameters
    ----------
    x : torch.Tensor, shape (B, N, in_channels)
        Channels-last, floating point; the real points finite.
    in_channels : int
        The channel count the model was built for.
    mask : torch.Tensor of bool, shape (B, N), optional
        ``True`` for real points; each cloud needs at least one.
    category : torch.Tensor of int, shape (B,), optional
        Object categories in ``[0, num_categories)``; required when
        ``num_categories > 0``, refused otherwise.
    num_categories : int, default 0

    Returns
    -------
    x : torch.Tensor, shape (B, N, in_channels)
        ``x`` with its padded rows set to zero (``x`` itself when nothing is padded).
    mask : torch.Tensor of bool or None
        ``None`` when no point is padded (an all-true mask included).
    category : torch.Tensor of int64, shape (B,), or None

    Raises
    ------
    InputError
        ``x`` not a tensor (``torch.from_numpy(points).float()``), not floating point
        (``x.float()``), one cloud ``(N, C)`` (``x.unsqueeze(0)``), channels-first
        ``(B, C, N)`` (``x.transpose(1, 2)``), the wrong channel count, empty; NaN or
        inf in a real point (drop those points: ``x[torch.isfinite(x).all(-1)]``); a
        mask of the wrong shape, type or device, or a cloud without a real point; a
        missing, unexpected or out-of-range category.

    Examples
    --------
    >>> x, m, c = check_cloud_batch(torch.ones(2, 4, 3), 3, torch.tensor([[1, 1, 0, 0]] * 2) > 0)
    >>> x[0, :, 0].tolist(), m.shape, c
    ([1.0, 1.0, 0.0, 0.0], torch.Size([2, 4]), None)
    >>> check_cloud_batch(torch.ones(2, 3, 100), 3)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: x must be channels-last (B, N, C) with C=3; got (2, 3, 100), ...
    """
    c = check_int(in_channels, "in_channels", 1)
    if not isinstance(x, torch.Tensor):
        raise InputError(
            f"x must be a torch.Tensor (B, N, {c}); got {type(x).__name__} "
            f"{plain_repr(x)[:60]}: convert it with torch.from_numpy(points).float()"
        )
    shape = tuple(x.shape)
    if x.ndim == 2 and shape[-1] == c:
        raise InputError(
            f"x must be a batch of clouds (B, N, {c}); got one cloud {shape}: add the batch "
            "dimension with x.unsqueeze(0)"
        )
    if x.ndim != 3:
        raise InputError(f"x must be 3-D (B, N, C) with C={c}; got {x.ndim}-D with shape {shape}")
    if shape[2] != c:
        if shape[1] == c:
            raise InputError(
                f"x must be channels-last (B, N, C) with C={c}; got {shape}, which looks "
                "channels-first (B, C, N): use x.transpose(1, 2)"
            )
        raise InputError(
            f"the model expects {c} channel(s) per point; got {shape[2]} in x of shape "
            f"{shape}: build the model with in_channels={shape[2]}, or keep the first {c} "
            f"channels (x[..., :{c}])"
        )
    if not x.is_floating_point():
        raise InputError(f"x must be floating point; got {x.dtype}: use x.float()")
    if shape[0] == 0 or shape[1] == 0:
        raise InputError(f"x is empty: shape {shape}; give at least one cloud of one point")
    if mask is not None:
        if not isinstance(mask, torch.Tensor) or mask.dtype != torch.bool:
            raise InputError(
                f"mask must be a bool torch.Tensor (B, N) (True = real point); got "
                f"{type(mask).__name__} {getattr(mask, 'dtype', '')}: use mask.bool()"
            )
        if tuple(mask.shape) != shape[:2]:
            raise InputError(
                f"mask must have shape (B, N) = {shape[:2]} to match x {shape}; got "
                f"{tuple(mask.shape)}"
            )
        if mask.device != x.device:
            raise InputError(f"mask is on {mask.device} but x on {x.device}: use mask.to(x.device)")
        counts = mask.sum(1)
        if bool((counts == 0).any()):
            b = int(torch.nonzero(counts == 0)[0, 0])
            raise InputError(
                f"cloud {b} of the batch has no real point (its mask row is all False): "
                "drop empty clouds from the batch"
            )
    bad = ~torch.isfinite(x).all(-1)
    if mask is not None:
        bad &= mask
    if bool(bad.any()):
        b, i = (int(v) for v in torch.nonzero(bad)[0])
        raise InputError(
            f"x has NaN or inf at point {i} of cloud {b} ({int(bad.sum())} point(s) in all): "
            "drop those points first, e.g. x[torch.isfinite(x).all(-1)] for one cloud"
        )
    if mask is not None:
        if bool(mask.all()):
            mask = None
        else:
            x = x.masked_fill(~mask[..., None], 0.0)
    ncat = check_int(num_categories, "num_categories", 0)
    return x, mask, _check_category(category, ncat, shape[0], x.device)


def _check_category(
    category: Any, num_categories: int, batch: int, device: torch.device
) -> torch.Tensor | None:
    if num_categories == 0:
        if category is not None:
            raise InputError(
                "category given, but the model was built with num_categories=0: build it "
                "with num_categories=<number of object categories> (task='segment'), or "
                "pass category=None"
            )
        return None
    if category is None:
        raise InputError(
            f"the model was built with num_categories={num_categories}: pass category, a "
            f"(B,) int64 tensor of object categories in [0, {num_categories})"
        )
    if not isinstance(category, torch.Tensor):
        raise InputError(
            f"category must be a torch.Tensor (B,) of int64; got {type(category).__name__} "
            f"{plain_repr(category)[:60]}: use torch.as_tensor(category)"
        )
    if category.dtype.is_floating_point or category.dtype == torch.bool or category.is_complex():
        raise InputError(f"category must be integer; got {category.dtype}: use category.long()")
    if tuple(category.shape) != (batch,):
        raise InputError(f"category must have shape (B,) = ({batch},); got {tuple(category.shape)}")
    if bool(((category < 0) | (category >= num_categories)).any()):
        raise InputError(
            f"category must be in [0, {num_categories}); got values from "
            f"{int(category.min())} to {int(category.max())}"
        )
    return category.to(device=device, dtype=torch.long)


def _match_model(module: nn.Module, x: torch.Tensor) -> None:
    """Refuse an input whose dtype or device differs from the module's weights."""
    p = next(module.parameters())
    if x.dtype != p.dtype:
        raise InputError(
            f"x is {x.dtype} but the model's weights are {p.dtype}: use x.to({p.dtype}) "
            f"(or model.to({x.dtype}))"
        )
    if x.device != p.device:
        raise InputError(f"x is on {x.device} but the model on {p.device}: use x.to('{p.device}')")


def _check_mask_shape(mask: Any, x: torch.Tensor) -> None:
    """Refuse a mask that is not bool of shape ``x.shape[:mask.ndim]`` (fewer dims than x)."""
    if mask is not None and (
        not isinstance(mask, torch.Tensor)
        or mask.dtype != torch.bool
        or mask.ndim >= x.ndim
        or tuple(mask.shape) != tuple(x.shape[: mask.ndim])
        or mask.device != x.device
    ):
        raise InputError(
            f"mask must be a bool tensor of shape x.shape[:mask.ndim] on x's device; got "
            f"{type(mask).__name__} {tuple(getattr(mask, 'shape', ()))} "
            f"{getattr(mask, 'dtype', '')} for x {tuple(x.shape)}"
        )


def _scaled(channels: int, width: float) -> int:
    return max(1, round(channels * width))


# --------------------------------------------------------------------------- layers


def masked_max_pool(
    features: torch.Tensor, mask: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Max over the real points of each cloud, per channel, and which point set it.

    :math:`g_{bc} = \max_{i:\, m_{bi}} f_{bic}` (padded points filled with
    :math:`-\infty` first), and :math:`\arg\max` (the first index on ties).

    Parameters
    ----------
    features : torch.Tensor, shape (B, N, F)
    mask : torch.Tensor of bool, shape (B, N), optional
        ``True`` for real points (each cloud needs one); ``None``: all real.

    Returns
    -------
    values : torch.Tensor, shape (B, F)
    index : torch.Tensor of int64, shape (B, F)

    Raises
    ------
    InputError
        ``features`` not a 3-D float tensor, or a mask of another shape than ``(B, N)``.

    Examples
    --------
    >>> f = torch.tensor([[[1.0, 5.0], [3.0, 0.0], [9.0, 9.0]]])
    >>> v, i = masked_max_pool(f, torch.tensor([[True, True, False]]))
    >>> v.tolist(), i.tolist()
    ([[3.0, 5.0]], [[1, 0]])
    """
    if not isinstance(features, torch.Tensor) or features.ndim != 3:
        raise InputError(
            f"features must be a (B, N, F) torch.Tensor; got {type(features).__name__} "
            f"{tuple(getattr(features, 'shape', ()))}"
        )
    if not features.is_floating_point():
        raise InputError(f"features must be floating point; got {features.dtype}")
    if mask is not None and (
        not isinstance(mask, torch.Tensor)
        or mask.dtype != torch.bool
        or tuple(mask.shape) != tuple(features.shape[:2])
    ):
        raise InputError(
            f"mask must be a bool tensor of shape (B, N) = {tuple(features.shape[:2])}; got "
            f"{type(mask).__name__} {tuple(getattr(mask, 'shape', ()))}"
        )
    if features.shape[1] == 0:
        raise InputError("features has no points (N = 0): nothing to pool")
    return _max_pool(features, mask)


def _max_pool(
    features: torch.Tensor, mask: torch.Tensor | None
) -> tuple[torch.Tensor, torch.Tensor]:
    if mask is not None:
        features = features.masked_fill(~mask[..., None], float("-inf"))
    values, index = features.max(dim=1)
    return values, index


class MaskedBatchNorm(nn.BatchNorm1d):
    r"""Batch normalization of channels-last features whose statistics skip padded points.

    :math:`y = \gamma (x - \mu) / \sqrt{\sigma^2 + \epsilon} + \beta` per channel (the
    last dimension). In training, :math:`\mu, \sigma^2` are the mean and (biased)
    variance over the **real** entries only (``x[mask]``), and the running statistics
    are updated as :class:`torch.nn.BatchNorm1d` updates them (unbiased variance,
    ``momentum``); in eval mode the running statistics are used and the mask does not
    matter. With no mask this is :class:`torch.nn.BatchNorm1d` on
    ``x.reshape(-1, C)`` (same parameters and buffers, so state dicts are alike).

    Parameters
    ----------
    num_features : int
        Channels ``C``.
    eps : float, default 1e-5
    momentum : float, default 0.1

    Notes
    -----
    ``forward(x, mask=None)``: ``x`` of shape ``(..., C)`` and ``mask`` of shape
    ``x.shape[:mask.ndim]`` (``(B, N)`` for ``(B, N, C)`` point features or ``(B, N, k,
    C)`` edge features). Training needs at least two real entries per channel.

    Examples
    --------
    >>> bn = MaskedBatchNorm(2)
    >>> x = torch.tensor([[[0.0, 1.0], [2.0, 3.0], [100.0, 100.0]]])
    >>> y = bn(x, torch.tensor([[True, True, False]]))
    >>> y[0, :2].round(decimals=3).tolist(), bn.running_mean.tolist()
    ([[-1.0, -1.0], [1.0, 1.0]], [0.10000000149011612, 0.20000000298023224])
    """

    def __init__(self, num_features: int, eps: float = 1e-5, momentum: float = 0.1) -> None:
        n = check_count(num_features, "num_features", 1, _MAX_CHANNELS)
        eps = check_real(eps, "eps", 0.0, 1.0, low_inclusive=False)
        momentum = check_real(momentum, "momentum", 0.0, 1.0)
        super().__init__(n, eps=eps, momentum=momentum)

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:  # type: ignore[override]
        if not isinstance(x, torch.Tensor) or x.ndim < 1 or x.shape[-1] != self.num_features:
            raise InputError(
                f"x must be a tensor (..., {self.num_features}) (channels last); got "
                f"{type(x).__name__} {tuple(getattr(x, 'shape', ()))}"
            )
        if not x.is_floating_point():
            raise InputError(f"x must be floating point; got {x.dtype}: use x.float()")
        _check_mask_shape(mask, x)
        _match_model(self, x)
        return self._normalize(x, mask)

    def _normalize(self, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        if mask is None and (not self.training or x.numel() >= 2 * self.num_features):
            # torch's own kernel: the same statistics, several times faster on the CPU
            m = self.momentum
            if self.training:
                with torch.no_grad():
                    self.num_batches_tracked += 1  # type: ignore[operator,assignment]
                if m is None:  # cumulative average, as torch's BatchNorm
                    m = 1.0 / float(self.num_batches_tracked)  # type: ignore[arg-type]
            rows = F.batch_norm(
                x.reshape(-1, self.num_features),
                self.running_mean,
                self.running_var,
                self.weight,
                self.bias,
                self.training,
                0.0 if m is None else m,
                self.eps,
            )
            return rows.reshape(x.shape)
        if self.training:
            rows = (x if mask is None else x[mask]).reshape(-1, self.num_features)
            n = rows.shape[0]
            if n < 2:
                raise InputError(
                    f"batch norm in training mode needs more than one value per channel; "
                    f"got {n} (a batch of one cloud?): use a batch of 2 or more, or "
                    "model.eval()"
                )
            var, mean = torch.var_mean(rows, dim=0, correction=0)
            with torch.no_grad():
                self.num_batches_tracked += 1  # type: ignore[operator,assignment]
                m = self.momentum
                if m is None:  # cumulative average, as torch's BatchNorm
                    m = 1.0 / float(self.num_batches_tracked)  # type: ignore[arg-type]
                self.running_mean.lerp_(mean.detach(), m)  # type: ignore[union-attr]
                self.running_var.lerp_(var.detach() * (n / (n - 1)), m)  # type: ignore[union-attr]
        else:
            mean, var = self.running_mean, self.running_var  # type: ignore[assignment]
        scale = torch.rsqrt(var + self.eps) * self.weight
        return torch.addcmul(self.bias - mean * scale, x, scale)  # one pass over x


class SharedMLP(nn.Module):
    r"""The same MLP on every point: ``Linear`` (no bias), :class:`MaskedBatchNorm`,
    ReLU (or LeakyReLU) and optional dropout, per layer.

    :math:`h^{(l+1)}_i = \mathrm{drop}(\sigma(\mathrm{BN}(W_l h^{(l)}_i)))` for every
    point :math:`i` -- the 1x1 convolutions of the PointNet/DGCNN reference code. On
    ``(B, F)`` inputs (no point axis) it is the FC stack of a classification head.

    Parameters
    ----------
    channels : sequence of int
        ``(in, out_1, ..., out_L)``, at least two.
    negative_slope : float, default 0.0
        0: ReLU; DGCNN uses LeakyReLU with 0.2.
    dropout : float, default 0.0
        Dropout probability after each layer's activation.

    Notes
    -----
    ``forward(x, mask=None)``: ``x`` of shape ``(..., in)``, the mask as
    :class:`MaskedBatchNorm`'s; returns ``(..., out_L)``.

    Examples
    --------
    >>> SharedMLP([3, 8, 16])(torch.rand(2, 5, 3)).shape
    torch.Size([2, 5, 16])
    """

    def __init__(
        self, channels: Sequence[int], *, negative_slope: float = 0.0, dropout: float = 0.0
    ) -> None:
        super().__init__()
        if isinstance(channels, (str, bytes)) or not isinstance(channels, Sequence):
            raise InputError(f"channels must be a sequence of ints; got {plain_repr(channels)}")
        ch = [check_count(c, "channels", 1, _MAX_CHANNELS) for c in channels]
        if len(ch) < 2:
            raise InputError(f"channels must be (in, out, ...), at least two; got {ch}")
        params = sum(a * b for a, b in itertools.pairwise(ch))
        if params > MAX_PARAMETERS:
            raise InputError(
                f"a shared MLP with channels {ch} would have {params} weights; the limit is "
                f"{MAX_PARAMETERS}: use fewer channels"
            )
        self.negative_slope = check_real(negative_slope, "negative_slope", 0.0, 1.0)
        p = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        self.linears = nn.ModuleList(nn.Linear(a, b, bias=False) for a, b in itertools.pairwise(ch))
        self.norms = nn.ModuleList(MaskedBatchNorm(b) for b in ch[1:])
        self.dropout = nn.Dropout(p) if p > 0 else None
        self.in_channels, self.out_channels = ch[0], ch[-1]

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        if not isinstance(x, torch.Tensor) or x.ndim < 2 or x.shape[-1] != self.in_channels:
            raise InputError(
                f"x must be a tensor (..., {self.in_channels}) (channels last); got "
                f"{type(x).__name__} {tuple(getattr(x, 'shape', ()))}"
            )
        if not x.is_floating_point():
            raise InputError(f"x must be floating point; got {x.dtype}: use x.float()")
        _check_mask_shape(mask, x)
        _match_model(self, x)
        return self._run(x, mask)

    def _run(self, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        for linear, norm in zip(self.linears, self.norms, strict=True):
            x = norm._normalize(linear(x), mask)  # type: ignore[operator]
            # not in place: the normalized tensor may be a view (a reshape of torch's
            # batch norm), and an in-place op on a view costs a copy in the backward pass
            if self.negative_slope:
                x = F.leaky_relu(x, self.negative_slope)
            else:
                x = F.relu(x)
            if self.dropout is not None:
                x = self.dropout(x)
        return x


# --------------------------------------------------------------------------- T-Net


class TNet(nn.Module):
    r"""A mini PointNet that predicts a ``k x k`` transform of each cloud.

    Shared MLP 64, 128, 1024 (batch norm, ReLU), masked max pool, FC 512, 256 (batch
    norm, ReLU), then a linear layer to the ``k * k`` entries. That last layer starts
    with zero weights and the identity as its bias, so at initialization the output is
    :math:`I_k` for every cloud (as the reference code, which adds the identity).

    Parameters
    ----------
    k : int
        Size of the transform (3 on xyz, 64 on the features), at most 256.
    width : float, default 1.0
        Multiplies the hidden channel counts (64, 128, 1024, 512, 256), not ``k``.
    in_channels : int, optional
        Channels of the input points (default ``k``; PointNet's input T-Net sees all
        the input channels, normals included, and transforms the xyz ones).

    Notes
    -----
    ``forward(x, mask=None)``: ``x`` of shape ``(B, N, in_channels)`` (channels last),
    mask ``(B, N)`` bool; returns ``(B, k, k)``.

    Examples
    --------
    >>> t = TNet(3, width=0.125).eval()
    >>> torch.equal(t(torch.rand(2, 10, 3)), torch.eye(3).expand(2, 3, 3))
    True
    """

    def __init__(self, k: int, width: float = 1.0, in_channels: int | None = None) -> None:
        super().__init__()
        self.k = check_count(k, "k", 1, 256)
        w = check_real(width, "width", 0.0, _MAX_WIDTH, low_inclusive=False)
        c = self.k if in_channels is None else check_count(in_channels, "in_channels", 1, 4096)
        self.in_channels = c
        self.mlp = SharedMLP([c, _scaled(64, w), _scaled(128, w), _scaled(1024, w)])
        self.fc = SharedMLP([_scaled(1024, w), _scaled(512, w), _scaled(256, w)])
        self.out = nn.Linear(_scaled(256, w), self.k * self.k)
        nn.init.zeros_(self.out.weight)
        with torch.no_grad():
            self.out.bias.copy_(torch.eye(self.k).flatten())

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        x, mask, _ = check_cloud_batch(x, self.in_channels, mask)
        _match_model(self, x)
        return self._transform(x, mask)[0]

    def _transform(
        self, x: torch.Tensor, mask: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The transforms (B, k, k) and the points that set the pooled feature (B, F)."""
        pooled, index = _max_pool(self.mlp._run(x, mask), mask)
        t = self.out(self.fc._run(pooled, None))
        return t.view(-1, self.k, self.k), index


def transform_regularizer(transform: torch.Tensor) -> torch.Tensor:
    r"""PointNet's orthogonality loss :math:`L_{reg} = \frac{1}{B} \sum_b \lVert I -
    A_b A_b^T \rVert_F^2`.

    Zero exactly when every :math:`A_b` is orthogonal. This is the paper's Eq. (2),
    averaged over the batch; ``pointnet.pytorch`` uses the Frobenius norm unsquared and
    the TensorFlow reference ``tf.nn.l2_loss`` (half the squared norm, summed over the
    batch): the scale differs, the minimizers do not.

    Parameters
    ----------
    transform : torch.Tensor, shape (B, k, k)

    Returns
    -------
    torch.Tensor
        A scalar (differentiable).

    Raises
    ------
    InputError
        Not a float ``(B, k, k)`` tensor.

    Examples
    --------
    >>> float(transform_regularizer(torch.eye(3)[None]))
    0.0
    >>> float(transform_regularizer(2 * torch.eye(2)[None]))  # (1 - 4)^2 * 2
    18.0
    """
    if (
        not isinstance(transform, torch.Tensor)
        or transform.ndim != 3
        or transform.shape[1] != transform.shape[2]
        or transform.shape[0] == 0
    ):
        raise InputError(
            f"transform must be a (B, k, k) torch.Tensor; got {type(transform).__name__} "
            f"{tuple(getattr(transform, 'shape', ()))}: for one matrix use A[None]"
        )
    if not transform.is_floating_point():
        raise InputError(f"transform must be floating point; got {transform.dtype}")
    k = transform.shape[1]
    eye = torch.eye(k, dtype=transform.dtype, device=transform.device)
    diff = eye - transform @ transform.transpose(1, 2)
    return (diff * diff).sum((1, 2)).mean()


# --------------------------------------------------------------------------- PointNet


class PointNet(nn.Module):
    r"""PointNet for classification or part segmentation (Qi et al. 2017).

    Input T-Net (3x3 on xyz), shared MLP 64, 64, feature T-Net (64x64), shared MLP 64,
    128, 1024, masked max pool to the global feature; then the classification head
    (FC 512, 256 with batch norm, ReLU and dropout, to ``K``) or the segmentation head
    (each point's 64-d feature, the global feature and the category one-hot, shared MLP
    512, 256, 128, to ``K`` per point). See the module docstring.

    Parameters
    ----------
    num_outputs : int
        ``K``: classes (classify) or parts (segment).
    task : {"classify", "segment"}, default "classify"
    in_channels : int, default 3
        Channels per point, xyz first (6 with normals). The input T-Net transforms the
        first ``min(3, in_channels)``; extra channels pass through untransformed.
    input_transform, feature_transform : bool, default True
        The two T-Nets (the feature one is regularized by
        :func:`transform_regularizer`, which the training loss adds).
    width : float, default 1.0
        Multiplies every hidden channel count (0.125 gives a small, fast network).
    dropout : float, default 0.3
        Dropout probability in the classification head (the reference keeps 0.7).
    num_categories : int, default 0
        Segmentation only: when > 0, ``forward`` takes ``category`` ``(B,)`` and its
        one-hot joins the global feature (as the part-segmentation reference code).

    Attributes
    ----------
    task, num_outputs, in_channels : as given
    config : dict
        The constructor's arguments (JSON-ready): ``type(m)(**m.config)`` rebuilds it.

    Notes
    -----
    ``forward(x, mask=None, category=None)``: ``x`` ``(B, N, in_channels)``, ``mask``
    ``(B, N)`` bool; returns logits ``(B, K)`` or ``(B, N, K)``.
    ``forward_aux`` returns the :class:`CloudOutput` (transforms, global feature,
    pooled indices). In eval mode the output is invariant to the order of the points.

    Examples
    --------
    >>> m = PointNet(5, width=0.125).eval()
    >>> m(torch.rand(2, 32, 3)).shape
    torch.Size([2, 5])
    >>> PointNet(4, task="segment", width=0.125).eval()(torch.rand(2, 32, 3)).shape
    torch.Size([2, 32, 4])
    """

    def __init__(
        self,
        num_outputs: int,
        *,
        task: str = "classify",
        in_channels: int = 3,
        input_transform: bool = True,
        feature_transform: bool = True,
        width: float = 1.0,
        dropout: float = 0.3,
        num_categories: int = 0,
    ) -> None:
        super().__init__()
        self.num_outputs = check_count(num_outputs, "num_outputs", 1, _MAX_CHANNELS)
        self.task = check_choice(task, "task", TASKS)
        self.in_channels = check_count(in_channels, "in_channels", 1, 4096)
        use_t1 = check_bool(input_transform, "input_transform")
        use_t2 = check_bool(feature_transform, "feature_transform")
        w = check_real(width, "width", 0.0, _MAX_WIDTH, low_inclusive=False)
        p = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        self.num_categories = _check_categories(num_categories, self.task)
        self.config: dict[str, Any] = {
            "num_outputs": self.num_outputs,
            "task": self.task,
            "in_channels": self.in_channels,
            "input_transform": use_t1,
            "feature_transform": use_t2,
            "width": w,
            "dropout": p,
            "num_categories": self.num_categories,
        }
        c64, c128, c1024 = _scaled(64, w), _scaled(128, w), _scaled(1024, w)
        self.xyz_channels = min(3, self.in_channels)
        self.input_tnet = (
            TNet(self.xyz_channels, w, in_channels=self.in_channels) if use_t1 else None
        )
        self.mlp1 = SharedMLP([self.in_channels, c64, c64])
        self.feature_tnet = TNet(c64, w) if use_t2 else None
        self.mlp2 = SharedMLP([c64, c64, c128, c1024])
        self.feature_channels = c1024
        if self.task == "classify":
            self.head = SharedMLP([c1024, _scaled(512, w), _scaled(256, w)], dropout=p)
            self.out = nn.Linear(_scaled(256, w), self.num_outputs)
        else:
            self.head = SharedMLP(
                [
                    c64 + c1024 + self.num_categories,
                    _scaled(512, w),
                    _scaled(256, w),
                    _scaled(128, w),
                ]
            )
            self.out = nn.Linear(_scaled(128, w), self.num_outputs)

    def forward(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None = None,
        category: torch.Tensor | None = None,
    ) -> torch.Tensor:
        return self.forward_aux(x, mask, category).logits

    def forward_aux(
        self,
        x: torch.Tensor,
        mask: torch.Tensor | None = None,
        category: torch.Tensor | None = None,
    ) -> CloudOutput:
        """Logits with the global feature, pooled indices and transforms (:class:`CloudOutput`)."""
        x, mask, category = check_cloud_batch(
            x, self.in_channels, mask, category, self.num_categories
        )
        _match_model(self, x)
        point, pooled, index, transforms, _ = self._encode(x, mask)
        if self.task == "classify":
            logits = self.out(self.head._run(pooled, None))
        else:
            glob = pooled
            if category is not None:
                onehot = F.one_hot(category, self.num_categories).to(pooled.dtype)
                glob = torch.cat([pooled, onehot], 1)
            h = torch.cat([point, glob[:, None, :].expand(-1, point.shape[1], -1)], -1)
            logits = self.out(self.head._run(h, mask))
        return CloudOutput(logits, pooled, index, transforms, [])

    def _encode(
        self, x: torch.Tensor, mask: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, list[torch.Tensor], list[torch.Tensor]]:
        """Per-point 64-d features, global feature, its argmax, transforms, T-Net argmaxes."""
        transforms: list[torch.Tensor] = []
        tnet_index: list[torch.Tensor] = []
        if self.input_tnet is not None:
            t1, i1 = self.input_tnet._transform(x, mask)
            transforms.append(t1)
            tnet_index.append(i1)
            xyz = x[..., : self.xyz_channels] @ t1
            x = torch.cat([xyz, x[..., self.xyz_channels :]], -1) if x.shape[-1] > 3 else xyz
        h = self.mlp1._run(x, mask)
        if self.feature_tnet is not None:
            t2, i2 = self.feature_tnet._transform(h, mask)
            transforms.append(t2)
            tnet_index.append(i2)
            h = h @ t2
        pooled, index = _max_pool(self.mlp2._run(h, mask), mask)
        return h, pooled, index, transforms, tnet_index


def _check_categories(num_categories: Any, task: str) -> int:
    n = check_int(num_categories, "num_categories", 0)
    if n > _MAX_CHANNELS:
        raise InputError(f"num_categories must be at most {_MAX_CHANNELS}; got {n}")
    if n and task != "segment":
        raise InputError(
            f"num_categories={n} is for part segmentation: build the model with "
            "task='segment', or num_categories=0 for classification"
        )
    return n


def critical_points(
    model: nn.Module,
    points: Any,
    mask: Any = None,
    *,
    include_transforms: bool = True,
) -> np.ndarray:
    r"""The critical point set :math:`C_S` of one cloud: the points that set the max of
    at least one global-feature channel (Qi et al. 2017, Sec. 4.3 and Fig. 7).

    :math:`C_S = \{\arg\max_i h_c(x_i) : c = 1 \dots F\}`. The paper's theorem: any set
    :math:`T` with :math:`C_S \subseteq T \subseteq S` gives the same global feature. With
    T-Nets the per-point function depends on the cloud through the transforms, so the
    points that set the T-Nets' own max pools are included too (``include_transforms``);
    then evaluating the model on ``points[critical_points(model, points)]`` gives exactly
    the same global feature (eval mode). The model is run in eval mode, without
    gradients, and put back in its mode.

    Parameters
    ----------
    model : PointNet
    points : array or torch.Tensor, shape (N, in_channels)
        One cloud.
    mask : array or torch.Tensor of bool, shape (N,), optional
        ``True`` for real points (indices refer to ``points``).
    include_transforms : bool, default True
        Add the points that set the T-Nets' pooled features (the paper's strict
        :math:`C_S` with ``False``; then the property holds for a model without T-Nets).

    Returns
    -------
    numpy.ndarray of int64, shape (M,)
        Sorted unique indices into ``points``.

    Raises
    ------
    InputError
        Not a :class:`PointNet`; points not ``(N, in_channels)``, or with NaN or inf
        among the real points.

    Examples
    --------
    >>> m = PointNet(2, width=0.125, input_transform=False, feature_transform=False)
    >>> pts = torch.rand(200, 3)
    >>> idx = critical_points(m, pts)
    >>> bool(len(idx) <= 128)  # at most one per global-feature channel
    True
    """
    check_module(model)
    if not isinstance(model, PointNet):
        raise InputError(
            f"model must be a PointNet (critical points are defined for its max-pooled "
            f"global feature); got {type(model).__name__}"
        )
    inc = check_bool(include_transforms, "include_transforms")
    p = next(model.parameters())
    if isinstance(points, torch.Tensor):
        pts = points.detach()
    else:
        arr = np.asarray(points)
        if arr.dtype.kind not in "biuf":
            raise InputError(f"points must be numeric; got dtype {arr.dtype}")
        pts = torch.from_numpy(np.ascontiguousarray(arr))
    c = model.in_channels
    if pts.ndim != 2 or pts.shape[1] != c:
        hint = ": points as columns? use points.T" if pts.ndim == 2 and pts.shape[0] == c else ""
        raise InputError(f"points must have shape (N, {c}); got {tuple(pts.shape)}{hint}")
    pts = pts.to(device=p.device, dtype=p.dtype)[None]
    m = None
    if mask is not None:
        if isinstance(mask, torch.Tensor):
            m = mask
        else:
            arr = np.asarray(mask)
            if arr.dtype != np.bool_:
                raise InputError(
                    f"mask must be a bool array (N,) (True = real point); got dtype {arr.dtype}"
                )
            m = torch.from_numpy(np.array(arr))
        if m.dtype != torch.bool or tuple(m.shape) != (pts.shape[1],):
            raise InputError(
                f"mask must be bool of shape (N,) = ({pts.shape[1]},); got {m.dtype} "
                f"{tuple(m.shape)}"
            )
        m = m.to(p.device)[None]
    x, m, _ = check_cloud_batch(pts, c, m)
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            _, _, index, _, tnet_index = model._encode(x, m)
    finally:
        model.train(was_training)
    sets = [index] + (tnet_index if inc else [])
    return np.unique(torch.cat([s.flatten() for s in sets]).cpu().numpy()).astype(np.int64)
