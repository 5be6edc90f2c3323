r"""Dynamic Graph CNN (Wang, Sun, Liu, Sarma, Bronstein and Solomon 2019), in plain torch.

Inputs are channels-last point clouds ``(B, N, C)`` with an optional ``(B, N)`` bool mask
of real points, as :mod:`robopercept.nn.cloud.pointnet` describes; the models return the same
:class:`~robopercept.nn.cloud.pointnet.CloudOutput`.

k nearest neighbours
--------------------
:func:`knn_graph` gives every point its ``k`` nearest points in feature space by squared
Euclidean distance, itself first (distance 0, as the reference ``knn`` of
``WangYueFt/dgcnn``), sorted by distance. Rows are processed in chunks so that each
distance block stays under 64 MB (a 100,000-point cloud never builds its 40 GB
``N x N`` matrix). Each block ranks the candidates by the fast expansion
:math:`\lVert x_j \rVert^2 - 2 x_i \cdot x_j` (the constant :math:`\lVert x_i \rVert^2`
dropped; clouds centred on their mean first), which loses precision to cancellation
(error about :math:`\epsilon \lVert x \rVert^2`, enough to swap near neighbours of a
large float32 cloud); the best :math:`k + 16` candidates are then **refined** with the
exact :math:`\sum_c (x_{ic} - x_{jc})^2` and re-ranked (ties by index). The result
matches :meth:`scipy.spatial.cKDTree.query` unless more than 16 points lie within that
rounding error beyond the k-th distance (computed in ``x``'s dtype: pass float64 for
float64 accuracy). Padded points are never neighbours
(distance :math:`+\infty`); a padded point's own row lists itself ``k`` times.

EdgeConv
--------
:class:`EdgeConv` computes, for each point :math:`x_i` and its neighbours
:math:`j \in \mathcal{N}(i)`,

.. math::

    x'_i = \max_{j \in \mathcal{N}(i)} \sigma\big(\mathrm{BN}(\Theta\,
    [x_i,\; x_j - x_i])\big),

with :math:`\Theta` a 1x1 convolution without bias (a ``Linear`` on the channels-last
edge features), batch norm and LeakyReLU(0.2). It never builds the ``2C``-channel edge
tensor: :math:`\Theta [x_i, x_j - x_i] = (\Theta_a - \Theta_b) x_i + \Theta_b x_j`
(:math:`\Theta = [\Theta_a \mid \Theta_b]`) is computed per point, then gathered.
The concatenation order ``(x_i, x_j - x_i)`` is the paper's and PyG's
:class:`torch_geometric.nn.EdgeConv`'s; the reference ``get_graph_feature`` stacks
``(x_j - x_i, x_i)``, a permutation of :math:`\Theta`'s columns (the same function
class).

DGCNN
-----
EdgeConv layers (widths 64, 64, 128, 256), each on the graph recomputed in the feature
space of its input (the *dynamic* graph; the first on xyz), or on the xyz graph at every
layer (``static_graph=True``, the paper's ablation). Their outputs are concatenated
(512 channels), mapped point-wise to ``embedding`` channels, and pooled by a masked max
and a masked average (over real points) concatenated: the global feature
:math:`2 \times` ``embedding``. Classification: FC 512, 256 (batch norm, LeakyReLU 0.2,
dropout) to ``K``. Segmentation (a simplification of the reference's part-segmentation
network, which has two convolutions per EdgeConv and a learned label embedding): each
point's concatenated layer outputs, the global feature and the category one-hot,
shared MLP 256, 256, 128 (dropout after the first two) to ``K`` per point.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_bool, check_choice, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import MAX_PARAMETERS, check_allocation, check_count
from robopercept.nn.cloud.pointnet import (
    TASKS,
    CloudOutput,
    MaskedBatchNorm,
    SharedMLP,
    check_cloud_batch,
)

__all__ = ["DGCNN", "CloudOutput", "EdgeConv", "edge_features", "knn_graph"]

#: bytes of one distance block of :func:`knn_graph` when ``chunk_size`` is None
BLOCK_BYTES = 64 * 2**20
_MAX_CHANNELS = 2**16


# --------------------------------------------------------------------------- k-NN graph


def knn_graph(
    x: torch.Tensor,
    k: int,
    mask: torch.Tensor | None = None,
    *,
    chunk_size: int | None = None,
) -> torch.Tensor:
    r"""The ``k`` nearest neighbours of every point, by squared Euclidean distance.

    :math:`\mathcal{N}_k(i) = \operatorname{argsort}_j \lVert x_i - x_j \rVert^2
    [:k]`, the point itself first, then by increasing distance (ties by index). See the
    module docstring for the chunked, refined computation and its accuracy.

    Parameters
    ----------
    x : torch.Tensor, shape (B, N, C) or (N, C)
        Points or per-point features, floating point, finite (real points).
    k : int
        Neighbours per point, the point itself included; at most the number of real
        points of each cloud.
    mask : torch.Tensor of bool, shape (B, N) or (N,), optional
        ``True`` for real points; padded points are never neighbours.
    chunk_size : int, optional
        Rows per distance block; ``None`` picks it so that a block stays under 64 MB.

    Returns
    -------
    torch.Tensor of int64, shape (B, N, k) or (N, k)

    Raises
    ------
    InputError
        ``x`` not a float tensor of 2 or 3 dims, NaN or inf among real points, a bad
        mask, ``k`` < 1 or more than the real points of a cloud (sample more points or
        lower ``k``), ``chunk_size`` < 1.

    Examples
    --------
    >>> x = torch.tensor([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0], [3.5, 0.0]])
    >>> knn_graph(x, 2).tolist()
    [[0, 1], [1, 0], [2, 3], [3, 2]]
    """
    single = isinstance(x, torch.Tensor) and x.ndim == 2
    if single:
        x = x[None]
        if isinstance(mask, torch.Tensor) and mask.ndim == 1:
            mask = mask[None]
    if not isinstance(x, torch.Tensor) or x.ndim != 3:
        raise InputError(
            f"x must be a torch.Tensor (B, N, C) or (N, C); got {type(x).__name__} "
            f"{tuple(getattr(x, 'shape', ()))}"
        )
    x, mask, _ = check_cloud_batch(x, x.shape[-1], mask)
    k = check_int(k, "k", 1)
    _check_enough(mask, x.shape[1], k, "knn_graph")
    rows = None if chunk_size is None else check_int(chunk_size, "chunk_size", 1)
    b, n = x.shape[:2]
    check_allocation(b * n * k, 8, f"the neighbour indices ({b}, {n}, {k})", "lower k")
    idx = _knn(x, k, mask, rows)
    return idx[0] if single else idx


def _check_enough(mask: torch.Tensor | None, n: int, k: int, who: str) -> None:
    """Refuse a cloud with fewer real points than ``k``."""
    fewest = n if mask is None else int(mask.sum(1).min())
    if fewest < k:
        b = 0 if mask is None else int(mask.sum(1).argmin())
        raise InputError(
            f"{who} needs at least k={k} real points per cloud (each point's k nearest, "
            f"itself included); cloud {b} has {fewest}: sample more points per cloud "
            f"(>= {k}) or use a smaller k"
        )


def _knn(
    x: torch.Tensor, k: int, mask: torch.Tensor | None, chunk_size: int | None
) -> torch.Tensor:
    """Unchecked :func:`knn_graph` on ``(B, N, C)``."""
    with torch.no_grad():
        x = x.detach()
        b, n, c = x.shape
        if mask is not None:
            x = x.masked_fill(~mask[..., None], 0.0)
            w = mask[..., None].to(x.dtype)
            centre = (x * w).sum(1, keepdim=True) / w.sum(1, keepdim=True).clamp_min(1.0)
        else:
            centre = x.mean(1, keepdim=True)
        x = x - centre
        sq = (x * x).sum(-1)
        if mask is not None:
            sq = sq.masked_fill(~mask, float("inf"))
        kc = min(n, k + 16)
        isz = x.element_size()
        if chunk_size is None:
            bs = min(b, max(1, BLOCK_BYTES // (n * isz)))
            rows = max(1, BLOCK_BYTES // (bs * max(n, kc * c) * isz))
        else:
            bs, rows = b, chunk_size
        rows = min(rows, n)
        out = torch.empty(b, n, k, dtype=torch.long, device=x.device)
        xt = x.transpose(1, 2)
        buf: torch.Tensor | None = None
        for b0 in range(0, b, bs):
            b1 = min(b, b0 + bs)
            bidx = torch.arange(b0, b1, device=x.device)[:, None, None]
            for r0 in range(0, n, rows):
                r1 = min(n, r0 + rows)
                xr = x[b0:b1, r0:r1]
                here = torch.arange(r0, r1, device=x.device)
                # rank by |x_j|^2 - 2 x_i.x_j (|x_i|^2 is constant along a row)
                full = (b1 - b0, r1 - r0) == (bs, rows)
                if full and buf is None:
                    buf = x.new_empty(bs, rows, n)  # reused: fresh 64 MB blocks cost page faults
                d = torch.baddbmm(
                    sq[b0:b1, None, :], xr, xt[b0:b1], alpha=-2.0, out=buf if full else None
                )
                d[:, torch.arange(r1 - r0, device=x.device), here] = float("-inf")
                cand = d.topk(kc, dim=-1, largest=False, sorted=False).indices
                cand = cand.sort(dim=-1).values  # ties below go to the lower index
                # exact distances of the candidates (index_select + in-place: one copy)
                flat = (cand + (bidx * n)).reshape(-1)
                diff = x.reshape(-1, c).index_select(0, flat).view(*cand.shape, c)
                dist = diff.sub_(xr[:, :, None, :]).square_().sum(-1)
                dist = dist.masked_fill(cand == here[None, :, None], -1.0)
                if mask is not None:
                    dist = dist.masked_fill(~mask[bidx, cand], float("inf"))
                order = dist.sort(dim=-1, stable=True).indices[..., :k]
                out[b0:b1, r0:r1] = cand.gather(-1, order)
        if mask is not None:
            own = torch.arange(n, device=x.device)[None, :, None].expand(b, n, k)
            out = torch.where(mask[..., None], out, own)
        return out


def edge_features(x: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    r"""The EdgeConv inputs :math:`(x_i,\; x_j - x_i)` for every point and neighbour.

    As the reference ``get_graph_feature`` (channels first, ``(B, 2C, N, k)``, ready for
    a 1x1 ``Conv2d``), with the paper's order: the first ``C`` channels are
    :math:`x_i`, the last ``C`` are :math:`x_j - x_i` (the reference stacks them the
    other way round).

    Parameters
    ----------
    x : torch.Tensor, shape (B, N, C)
        Channels last.
    idx : torch.Tensor of int64, shape (B, N, k)
        Neighbour indices in ``[0, N)`` (:func:`knn_graph`).

    Returns
    -------
    torch.Tensor, shape (B, 2C, N, k)

    Raises
    ------
    InputError
        Shapes that do not match, integer/float mix-ups, indices out of range.

    Examples
    --------
    >>> x = torch.tensor([[[0.0], [2.0]]])
    >>> edge_features(x, torch.tensor([[[0, 1], [1, 0]]]))[0].tolist()
    [[[0.0, 0.0], [2.0, 2.0]], [[0.0, 2.0], [0.0, -2.0]]]
    """
    x, idx = _check_graph_input(x, idx, None)
    b = x.shape[0]
    xj = x[torch.arange(b, device=x.device)[:, None, None], idx]
    xi = x[:, :, None, :].expand_as(xj)
    return torch.cat([xi, xj - xi], -1).permute(0, 3, 1, 2)


def _check_graph_input(x: Any, idx: Any, channels: int | None) -> tuple[torch.Tensor, torch.Tensor]:
    if not isinstance(x, torch.Tensor) or x.ndim != 3:
        raise InputError(
            f"x must be a (B, N, C) torch.Tensor (channels last); got {type(x).__name__} "
            f"{tuple(getattr(x, 'shape', ()))}"
        )
    if channels is not None and x.shape[2] != channels:
        hint = ": channels-first? use x.transpose(1, 2)" if x.shape[1] == channels else ""
        raise InputError(
            f"x must have {channels} channels (B, N, {channels}); got {tuple(x.shape)}{hint}"
        )
    if not x.is_floating_point():
        raise InputError(f"x must be floating point; got {x.dtype}: use x.float()")
    if (
        not isinstance(idx, torch.Tensor)
        or idx.ndim != 3
        or tuple(idx.shape[:2]) != tuple(x.shape[:2])
    ):
        raise InputError(
            f"idx must be a (B, N, k) int64 tensor matching x {tuple(x.shape)}; got "
            f"{type(idx).__name__} {tuple(getattr(idx, 'shape', ()))}: use knn_graph(x, k)"
        )
    if idx.dtype != torch.long:
        raise InputError(f"idx must be int64; got {idx.dtype}: use idx.long()")
    if idx.device != x.device:
        raise InputError(f"idx is on {idx.device} but x on {x.device}: use idx.to(x.device)")
    if idx.shape[2] == 0 or x.shape[1] == 0:
        raise InputError(f"idx must have k >= 1 neighbours per point; got {tuple(idx.shape)}")
    if bool(((idx < 0) | (idx >= x.shape[1])).any()):
        raise InputError(
            f"idx must hold point indices in [0, {x.shape[1]}); got values from "
            f"{int(idx.min())} to {int(idx.max())}"
        )
    return x, idx


class EdgeConv(nn.Module):
    r"""One EdgeConv layer: :math:`x'_i = \max_{j \in \mathcal{N}(i)}
    \mathrm{LeakyReLU}_{0.2}(\mathrm{BN}(\Theta [x_i, x_j - x_i]))`.

    Parameters
    ----------
    in_channels, out_channels : int
    k : int, default 20
        Neighbours used when ``forward`` is given no graph (:func:`knn_graph` on ``x``).
    negative_slope : float, default 0.2

    Attributes
    ----------
    linear : torch.nn.Linear
        :math:`\Theta`, ``(out, 2 in)``, no bias: the reference's 1x1 ``Conv2d`` weight
        ``linear.weight[:, :, None, None]`` applied to :func:`edge_features`.
    bn : MaskedBatchNorm

    Notes
    -----
    ``forward(x, idx=None, mask=None)``: ``x`` ``(B, N, in)`` channels last, ``idx``
    ``(B, N, k)`` neighbour indices, ``mask`` ``(B, N)`` (batch statistics over the
    edges of real points); returns ``(B, N, out)``.

    Examples
    --------
    >>> conv = EdgeConv(3, 8, k=4)
    >>> conv(torch.rand(2, 10, 3)).shape
    torch.Size([2, 10, 8])
    """

    def __init__(
        self, in_channels: int, out_channels: int, *, k: int = 20, negative_slope: float = 0.2
    ) -> None:
        super().__init__()
        self.in_channels = check_count(in_channels, "in_channels", 1, _MAX_CHANNELS)
        self.out_channels = check_count(out_channels, "out_channels", 1, _MAX_CHANNELS)
        self.k = check_count(k, "k", 1, 4096)
        self.negative_slope = check_real(negative_slope, "negative_slope", 0.0, 1.0)
        if 2 * self.in_channels * self.out_channels > MAX_PARAMETERS:
            raise InputError(
                f"EdgeConv({self.in_channels}, {self.out_channels}) would have "
                f"{2 * self.in_channels * self.out_channels} weights; the limit is "
                f"{MAX_PARAMETERS}: use fewer channels"
            )
        self.linear = nn.Linear(2 * self.in_channels, self.out_channels, bias=False)
        self.bn = MaskedBatchNorm(self.out_channels)

    def forward(
        self, x: torch.Tensor, idx: torch.Tensor | None = None, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        if idx is None:
            x, mask, _ = check_cloud_batch(x, self.in_channels, mask)
            _check_enough(mask, x.shape[1], self.k, "EdgeConv")
            idx = _knn(x, self.k, mask, None)
        else:
            x, mask, _ = check_cloud_batch(x, self.in_channels, mask)
            x, idx = _check_graph_input(x, idx, self.in_channels)
        p = self.linear.weight
        if x.dtype != p.dtype or x.device != p.device:
            raise InputError(
                f"x is {x.dtype} on {x.device} but the layer's weights are {p.dtype} on "
                f"{p.device}: use x.to(weights' dtype and device)"
            )
        return self._conv(x, idx, mask)

    def _conv(self, x: torch.Tensor, idx: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        c = self.in_channels
        w = self.linear.weight
        wa, wb = w[:, :c], w[:, c:]
        u = x @ (wa - wb).T  # the x_i part, per point
        v = x @ wb.T  # the x_j part, per point, gathered per edge
        vj = v[torch.arange(x.shape[0], device=x.device)[:, None, None], idx]
        if not self.training:
            # eval: BN is an affine map per channel and LeakyReLU is non-decreasing, both
            # monotone in floating point too, so the max over j commutes with them: the
            # max of u_i + v_j is u_i + max_j v_j (min_j where the BN scale is negative)
            lo, hi = torch.aminmax(vj, dim=2)
            scale = self.bn.weight * torch.rsqrt(self.bn.running_var + self.bn.eps)  # type: ignore[operator,arg-type]
            best = torch.where(scale >= 0, hi, lo)
            return F.leaky_relu(self.bn._normalize(u + best, None), self.negative_slope)
        e = u[:, :, None, :] + vj
        e = F.leaky_relu(self.bn._normalize(e, mask), self.negative_slope)
        return e.amax(dim=2)


# --------------------------------------------------------------------------- DGCNN


class DGCNN(nn.Module):
    r"""Dynamic Graph CNN for classification or part segmentation (Wang et al. 2019).

    See the module docstring for the layers.

    Parameters
    ----------
    num_outputs : int
        ``K``: classes (classify) or parts (segment).
    task : {"classify", "segment"}, default "classify"
    in_channels : int, default 3
        Channels per point, xyz first; the first graph is built on the first
        ``min(3, in_channels)`` channels.
    k : int, default 20
        Neighbours per point (itself included); every cloud needs ``k`` real points.
    widths : sequence of int, default (64, 64, 128, 256)
        Output channels of the EdgeConv layers.
    embedding : int, default 1024
        Channels of the point-wise layer before pooling (global feature: twice this).
    dropout : float, default 0.5
    num_categories : int, default 0
        Segmentation only: the one-hot of ``category`` ``(B,)`` joins the global feature.
    static_graph : bool, default False
        Use the xyz graph at every layer instead of recomputing it in feature space.

    Attributes
    ----------
    task, num_outputs, in_channels, k : as given
    config : dict
        The constructor's arguments (JSON-ready): ``type(m)(**m.config)`` rebuilds it.

    Notes
    -----
    ``forward(x, mask=None, category=None)`` returns logits ``(B, K)`` or ``(B, N, K)``;
    ``forward_aux`` the :class:`~robopercept.nn.cloud.pointnet.CloudOutput` with the graphs
    and ``pooled_index`` (``-1`` for the average-pooled half of the global feature).

    Examples
    --------
    >>> m = DGCNN(5, k=4, widths=(8, 8), embedding=16).eval()
    >>> m(torch.rand(2, 32, 3)).shape
    torch.Size([2, 5])
    """

    def __init__(
        self,
        num_outputs: int,
        *,
        task: str = "classify",
        in_channels: int = 3,
        k: int = 20,
        widths: Sequence[int] = (64, 64, 128, 256),
        embedding: int = 1024,
        dropout: float = 0.5,
        num_categories: int = 0,
        static_graph: bool = False,
    ) -> None:
        super().__init__()
        self.num_outputs = check_count(num_outputs, "num_outputs", 1, _MAX_CHANNELS)
        self.task = check_choice(task, "task", TASKS)
        self.in_channels = check_count(in_channels, "in_channels", 1, 4096)
        self.k = check_count(k, "k", 1, 4096)
        if isinstance(widths, (str, bytes)) or not isinstance(widths, Sequence):
            raise InputError(f"widths must be a sequence of ints; got {plain_repr(widths)}")
        ws = [check_count(w, "widths", 1, 8192) for w in widths]
        if not 1 <= len(ws) <= 64:
            raise InputError(f"widths must list 1 to 64 EdgeConv layers; got {len(ws)}")
        emb = check_count(embedding, "embedding", 1, 8192)
        p = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        ncat = check_int(num_categories, "num_categories", 0)
        if ncat > _MAX_CHANNELS:
            raise InputError(f"num_categories must be at most {_MAX_CHANNELS}; got {ncat}")
        if ncat and self.task != "segment":
            raise InputError(
                f"num_categories={ncat} is for part segmentation: build the model with "
                "task='segment', or num_categories=0 for classification"
            )
        self.num_categories = ncat
        self.static_graph = check_bool(static_graph, "static_graph")
        ins = [self.in_channels, *ws[:-1]]
        total = sum(ws)
        params = sum(2 * a * b for a, b in zip(ins, ws, strict=True)) + total * emb
        params += (
            2 * emb * 512 + 512 * 256 + 256 * self.num_outputs
            if self.task == "classify"
            else (total + 2 * emb + ncat) * 256 + 256 * 256 + 256 * 128 + 128 * self.num_outputs
        )
        if params > MAX_PARAMETERS:
            raise InputError(
                f"this DGCNN would have {params} parameters; the limit is {MAX_PARAMETERS}: "
                "lower widths or embedding"
            )
        self.config: dict[str, Any] = {
            "num_outputs": self.num_outputs,
            "task": self.task,
            "in_channels": self.in_channels,
            "k": self.k,
            "widths": ws,
            "embedding": emb,
            "dropout": p,
            "num_categories": ncat,
            "static_graph": self.static_graph,
        }
        self.xyz_channels = min(3, self.in_channels)
        self.convs = nn.ModuleList(EdgeConv(a, b, k=self.k) for a, b in zip(ins, ws, strict=True))
        self.embed = SharedMLP([total, emb], negative_slope=0.2)
        self.feature_channels = 2 * emb
        self.head: nn.Module
        if self.task == "classify":
            self.head = SharedMLP([2 * emb, 512, 256], negative_slope=0.2, dropout=p)
            self.out = nn.Linear(256, self.num_outputs)
        else:
            self.head = nn.ModuleList(
                [
                    SharedMLP([total + 2 * emb + ncat, 256, 256], negative_slope=0.2, dropout=p),
                    SharedMLP([256, 128], negative_slope=0.2),
                ]
            )
            self.out = nn.Linear(128, self.num_outputs)

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
        """Logits with the global feature, pooled indices and graphs (see ``CloudOutput``)."""
        x, mask, category = check_cloud_batch(
            x, self.in_channels, mask, category, self.num_categories
        )
        p = self.out.weight
        if x.dtype != p.dtype or x.device != p.device:
            raise InputError(
                f"x is {x.dtype} on {x.device} but the model's weights are {p.dtype} on "
                f"{p.device}: use x.to({p.dtype}) and x.to('{p.device}')"
            )
        _check_enough(mask, x.shape[1], self.k, "DGCNN")
        n = x.shape[1]
        graphs: list[torch.Tensor] = []
        feats: list[torch.Tensor] = []
        h = x
        xyz_graph = _knn(x[..., : self.xyz_channels], self.k, mask, None)
        for i, conv in enumerate(self.convs):
            if i == 0 or self.static_graph:
                idx = xyz_graph
            else:
                idx = _knn(h, self.k, mask, None)
            graphs.append(idx)
            h = conv._conv(h, idx, mask)  # type: ignore[operator]
            feats.append(h)
        point = torch.cat(feats, -1)
        emb = self.embed._run(point, mask)
        mx, index = _max_pool(emb, mask)
        pooled = torch.cat([mx, _avg(emb, mask)], -1)
        index = torch.cat([index, torch.full_like(index, -1)], -1)
        if self.task == "classify":
            logits = self.out(self.head._run(pooled, None))  # type: ignore[operator]
        else:
            glob = pooled
            if category is not None:
                onehot = F.one_hot(category, self.num_categories).to(pooled.dtype)
                glob = torch.cat([pooled, onehot], 1)
            z = torch.cat([point, glob[:, None, :].expand(-1, n, -1)], -1)
            for mlp in cast("list[SharedMLP]", self.head):
                z = mlp._run(z, mask)
            logits = self.out(z)
        return CloudOutput(logits, pooled, index, [], graphs)


def _max_pool(f: torch.Tensor, mask: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    if mask is not None:
        f = f.masked_fill(~mask[..., None], float("-inf"))
    return f.max(dim=1)


def _avg(f: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    if mask is None:
        return f.mean(1)
    w = mask[..., None].to(f.dtype)
    return (f * w).sum(1) / w.sum(1)
