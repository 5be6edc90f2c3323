r"""2-D pose estimation networks: heatmaps (a SimpleBaseline-style network and an
HRNet-style high-resolution network) and direct regression (DeepPose with cascaded
refinement), their targets, decoding, flip test, augmentation and training.

Coordinates
-----------
Keypoints are ``(x, y)`` pixels with the pixel-centre convention of
:mod:`robopercept.nn.ops.boxes`: pixel ``(c, r)`` covers ``[c, c + 1) x [r, r + 1)``. A
heatmap of stride :math:`s` has cell ``(i, j)`` centred on image point
:math:`((j + \tfrac12) s, (i + \tfrac12) s)`, so an image point ``x`` sits at the
continuous heatmap coordinate :math:`u = x / s - \tfrac12`. This makes a horizontal
flip of an image of width :math:`W = w s` the flip of its heatmap: :math:`x \mapsto W -
x` is :math:`u \mapsto (w - 1) - u`.

Targets and decoding
--------------------
:func:`gaussian_heatmaps` writes, for joint :math:`k` at :math:`(u_k, v_k)`, the
unnormalized Gaussian :math:`H_k(i, j) = \exp(-((j - u_k)^2 + (i - v_k)^2) / 2\sigma^2)`
centred at the exact sub-cell position (as mmpose's ``UDPHeatmap`` /
DARK, not rounded to a cell as the original ``MSRAHeatmap``), with weight 0 for joints
that are unlabelled (``v = 0``) or outside the image. :func:`decode_heatmaps` reads a
heatmap back three ways:

* ``"quarter"``: the argmax cell moved a quarter cell towards the higher neighbour,
  :math:`u = j + \tfrac14 \operatorname{sign}(H(i, j+1) - H(i, j-1))` (Newell et al.
  2016; SimpleBaseline), error up to a quarter cell;
* ``"quadratic"`` (default): the vertex of the parabola through the logarithms of the
  argmax and its two neighbours on each axis, :math:`u = j + \tfrac12 (L_{j-1} -
  L_{j+1}) / (L_{j-1} - 2 L_j + L_{j+1})`, exact for a Gaussian (its logarithm is a
  parabola): the one-dimensional form of DARK's Taylor step (Zhang et al. 2020);
* ``"soft-argmax"``: the expectation of the position under
  :math:`\operatorname{softmax}(\beta H)` (integral regression, Sun et al. 2018).

The flip test (:func:`predict_keypoints` with ``flip_test=True``) averages the heatmaps
of the image and of its mirror image, the latter flipped back and its left/right
channels swapped (:meth:`~robopercept.nn.skeleton.Skeleton.flip_permutation`).

Networks
--------
* :class:`SimpleBaseline` (Xiao et al. 2018): a residual encoder to stride 16, two
  transposed convolutions back to stride 4, a 1x1 convolution to one heatmap per joint.
* :class:`HRNet` (Sun et al. 2019): a stride-4 stem, then stages that keep the
  stride-4 branch throughout and add a branch at half the resolution at each stage
  (4, 8, 16), every stage ending in a *fusion* where each branch receives the sum of
  all branches brought to its resolution (strided 3x3 convolutions down, 1x1
  convolutions and nearest upsampling up); heatmaps from the stride-4 branch.
* :class:`DeepPose` (Toshev & Szegedy 2014): a convolutional encoder and two fully
  connected layers regress the normalized joint coordinates :math:`(x / W - \tfrac12,
  y / H - \tfrac12)`; :class:`DeepPoseRefiner` is a cascade stage: around each joint's
  current estimate it crops a window of side ``crop`` (pixels of the full image),
  resamples it to ``patch x patch`` (bilinear, :func:`torch.nn.functional.grid_sample`)
  and regresses that joint's displacement in units of the window.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_bool, check_choice, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn.core.blocks import ConvBNAct, ResidualBlock
from robopercept.nn.skeleton import Skeleton
from robopercept.nn.train.loop import EpochHistory, epoch_loop

__all__ = [
    "DECODERS",
    "HEATMAP_LOSSES",
    "POSE_MODELS",
    "DeepPose",
    "DeepPoseRefiner",
    "HRNet",
    "PoseEvaluation",
    "PoseHistory",
    "PoseResult",
    "SimpleBaseline",
    "augment_pose_batch",
    "build_pose_model",
    "crop_patches",
    "decode_heatmaps",
    "evaluate_pose",
    "gaussian_heatmaps",
    "heatmap_loss",
    "load_pose_model",
    "pose_arrays",
    "predict_heatmaps",
    "predict_keypoints",
    "refine_keypoints",
    "samples_picture",
    "save_pose_model",
    "train_cascade",
    "train_pose",
    "train_refiner",
]

#: the network names of :func:`build_pose_model`
POSE_MODELS = ("deeppose", "heatmap", "hrnet")
#: the heatmap decoders of :func:`decode_heatmaps`
DECODERS = ("quadratic", "quarter", "soft-argmax")
#: the heatmap losses of :func:`heatmap_loss` (and the ``heatmap`` kinds of the networks)
HEATMAP_LOSSES = ("softmax", "mse")


# ----------------------------------------------------------------------------- targets
def _keypoint_tensor(keypoints: Any, name: str = "keypoints") -> torch.Tensor:
    k = torch.as_tensor(np.asarray(keypoints, dtype=np.float32))
    if k.ndim != 3 or k.shape[-1] not in (2, 3) or k.shape[1] < 1:
        raise InputError(
            f"{name} must be (N, J, 3) rows (x, y, v) or (N, J, 2); got shape {tuple(k.shape)}"
        )
    if k.shape[-1] == 2:
        k = torch.cat([k, torch.full_like(k[..., :1], 2.0)], -1)
    return k


def gaussian_heatmaps(
    keypoints: npt.ArrayLike,
    image_size: tuple[int, int],
    stride: int = 4,
    sigma: float = 2.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Target heatmaps: an exact sub-cell Gaussian per labelled joint.

    :math:`H_k(i, j) = \exp(-((j - u_k)^2 + (i - v_k)^2) / 2\sigma^2)` with
    :math:`u_k = x_k / s - \tfrac12`, :math:`v_k = y_k / s - \tfrac12` (the module's
    convention), on a ``(H / s, W / s)`` grid.

    Parameters
    ----------
    keypoints : (N, J, 3) array_like
        ``(x, y, v)`` pixels; ``v = 0`` (or NaN coordinates) marks a joint without a label.
    image_size : (int, int)
        ``(width, height)``, multiples of ``stride``.
    stride : int
    sigma : float
        In heatmap cells.

    Returns
    -------
    heatmaps : (N, J, H / s, W / s) float32 tensor
    weights : (N, J) float32 tensor
        1 for a labelled joint inside the image, else 0 (its heatmap is all 0).

    Examples
    --------
    >>> hm, w = gaussian_heatmaps([[[6.0, 2.0, 2]]], (8, 8), stride=4)
    >>> hm.shape, float(hm[0, 0, 0, 1]), w.tolist()
    (torch.Size([1, 1, 2, 2]), 1.0, [[1.0]])
    """
    k = _keypoint_tensor(keypoints)
    w, h = _size(image_size, stride)
    stride = check_int(stride, "stride", 1)
    sigma = check_real(sigma, "sigma", 0.0, 1e3, low_inclusive=False)
    hw, hh = w // stride, h // stride
    x, y, v = k[..., 0], k[..., 1], k[..., 2]
    ok = (v > 0) & torch.isfinite(x) & torch.isfinite(y) & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    u = torch.where(ok, x / stride - 0.5, torch.zeros_like(x))
    vv = torch.where(ok, y / stride - 0.5, torch.zeros_like(y))
    jj = torch.arange(hw, dtype=torch.float32)
    ii = torch.arange(hh, dtype=torch.float32)
    gx = torch.exp(-((jj[None, None, :] - u[..., None]) ** 2) / (2 * sigma**2))
    gy = torch.exp(-((ii[None, None, :] - vv[..., None]) ** 2) / (2 * sigma**2))
    hm = gy[..., :, None] * gx[..., None, :] * ok[..., None, None]
    return hm.float(), ok.float()


def _size(image_size: Any, stride: int) -> tuple[int, int]:
    from robopercept._checks import check_size

    w, h = check_size(image_size, "image_size", 1, 1 << 15)
    if w % stride or h % stride:
        raise InputError(
            f"image_size {(w, h)} must be a multiple of the stride {stride} in both sides"
        )
    return w, h


def decode_heatmaps(
    heatmaps: torch.Tensor | npt.ArrayLike,
    stride: int = 4,
    method: str = "quadratic",
    beta: float = 50.0,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Keypoints from heatmaps (see the module docstring for the three methods).

    Parameters
    ----------
    heatmaps : (N, J, h, w) tensor or array
    stride : int
        Image pixels per heatmap cell.
    method : {"quadratic", "quarter", "soft-argmax"}
    beta : float
        The soft-argmax temperature (``softmax(beta H)``).

    Returns
    -------
    keypoints : (N, J, 2) float64 ndarray
        ``(x, y)`` pixels, :math:`x = s (u + \tfrac12)`.
    scores : (N, J) float64 ndarray
        The heatmap maximum.

    Examples
    --------
    >>> hm, _ = gaussian_heatmaps([[[13.3, 6.9, 2]]], (32, 16), stride=4)
    >>> kp, score = decode_heatmaps(hm, stride=4)
    >>> np.round(kp, 6).tolist()
    [[[13.3, 6.9]]]
    """
    hm = torch.as_tensor(np.asarray(heatmaps) if not torch.is_tensor(heatmaps) else heatmaps)
    if hm.ndim != 4 or hm.shape[-1] < 1 or hm.shape[-2] < 1:
        raise InputError(f"heatmaps must be (N, J, h, w); got shape {tuple(hm.shape)}")
    hm = hm.detach().to(torch.float64).cpu()
    if not torch.isfinite(hm).all():
        raise InputError("heatmaps must be finite; got NaN or inf (a diverged network?)")
    stride = check_int(stride, "stride", 1)
    check_choice(method, "method", DECODERS)
    n, j, h, w = hm.shape
    flat = hm.reshape(n, j, -1)
    score, idx = flat.max(-1)
    row = (idx // w).to(torch.float64)
    col = (idx % w).to(torch.float64)
    if method == "soft-argmax":
        beta = check_real(beta, "beta", 0.0, 1e6, low_inclusive=False)
        p = torch.softmax(beta * flat, -1).reshape(n, j, h, w)
        col = (p.sum(-2) * torch.arange(w, dtype=torch.float64)).sum(-1)
        row = (p.sum(-1) * torch.arange(h, dtype=torch.float64)).sum(-1)
    else:
        r, c = row.long(), col.long()
        ni, ji = torch.meshgrid(torch.arange(n), torch.arange(j), indexing="ij")

        def at(rr: torch.Tensor, cc: torch.Tensor) -> torch.Tensor:
            return hm[ni, ji, rr.clamp(0, h - 1), cc.clamp(0, w - 1)]

        centre = at(r, c)
        offsets = []
        for dr, dc, size, pos in ((0, 1, w, c), (1, 0, h, r)):
            lo = at(r - dr, c - dc)
            hi = at(r + dr, c + dc)
            inner = (pos > 0) & (pos < size - 1)
            if method == "quarter":
                off = 0.25 * torch.sign(hi - lo)
            else:
                tiny = 1e-10
                l0, l1, l2 = (torch.log(t.clamp_min(tiny)) for t in (lo, centre, hi))
                den = l0 - 2 * l1 + l2
                off = torch.where(den < -1e-12, 0.5 * (l0 - l2) / den.clamp(max=-1e-12), 0 * den)
                off = off.clamp(-0.5, 0.5)
            offsets.append(torch.where(inner, off, torch.zeros_like(off)))
        col = col + offsets[0]
        row = row + offsets[1]
    kp = torch.stack([(col + 0.5) * stride, (row + 0.5) * stride], -1)
    return kp.numpy(), score.numpy()


# ----------------------------------------------------------------------------- networks
def _head(channels: int, joints: int) -> nn.Conv2d:
    """The 1x1 heatmap layer, weights N(0, 0.001^2) and bias 0 (SimpleBaseline's init):
    the maps start flat instead of at a random scale."""
    head = nn.Conv2d(channels, joints, 1)
    nn.init.normal_(head.weight, std=0.001)
    nn.init.zeros_(head.bias)  # type: ignore[arg-type]
    return head


def heatmap_loss(
    output: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, kind: str = "softmax"
) -> torch.Tensor:
    r"""The loss of a heatmap network against :func:`gaussian_heatmaps` targets.

    * ``"mse"`` (SimpleBaseline, HRNet's papers): the network regresses the Gaussian map,
      :math:`\frac{1}{N J} \sum_{n,k} w_{nk} \frac{1}{h w} \lVert \hat H_{nk} - H_{nk}
      \rVert^2`.
    * ``"softmax"``: the map is the logits of a distribution over the cells, and the
      loss is the cross entropy to the target normalized into one,
      :math:`-\frac{1}{\sum w} \sum_{n,k} w_{nk} \sum_{ij} q_{nkij} \log
      \operatorname{softmax}(\hat H_{nk})_{ij}`, :math:`q = H / \sum H` (the
      one-hot cross entropy of Mask R-CNN's keypoint head, with Gaussian soft targets).
      On these small sets it trains in a fraction of the epochs MSE needs, as the
      background cells no longer dominate the loss.

    Parameters
    ----------
    output, target : (N, J, h, w) tensor
    weight : (N, J) tensor
        1 for joints that count, 0 for the others.
    kind : {"softmax", "mse"}

    Examples
    --------
    >>> t, w = gaussian_heatmaps([[[6.0, 6.0, 2]]], (16, 16), 4, 1.0)
    >>> float(heatmap_loss(t, t, w, "mse"))
    0.0
    """
    check_choice(kind, "kind", HEATMAP_LOSSES)
    _tensor(output, "output", 4, "(N, J, h, w)")
    _tensor(target, "target", 4, "(N, J, h, w)")
    _tensor(weight, "weight", 2, "(N, J)")
    if output.shape != target.shape or weight.shape != output.shape[:2]:
        raise InputError(
            f"output {tuple(output.shape)}, target {tuple(target.shape)} and weight "
            f"{tuple(weight.shape)} must be (N, J, h, w), (N, J, h, w) and (N, J)"
        )
    if kind == "mse":
        return (((output - target) ** 2).mean((-1, -2)) * weight).mean()
    q = target.flatten(2)
    q = q / q.sum(-1, keepdim=True).clamp_min(1e-12)
    ce = -(q * torch.log_softmax(output.flatten(2), -1)).sum(-1)
    return (ce * weight).sum() / weight.sum().clamp_min(1.0)


class SimpleBaseline(nn.Module):
    """Heatmaps from a residual encoder and transposed convolutions (Xiao et al. 2018).

    Stem ``ConvBNAct(3, w, stride 2)``, residual stages of widths ``w, 2w, 4w, 8w`` with
    strides ``1, 2, 2, 2`` (stride 16 in all), two 4x4 transposed convolutions (stride
    2, width ``4w``, BN, ReLU) back to stride 4, and a 1x1 convolution to ``J``
    heatmaps.

    Parameters
    ----------
    num_joints : int
    width : int, default 16
    in_channels : int, default 3
    heatmap : {"softmax", "mse"}, default "softmax"
        What the maps are trained as (:func:`heatmap_loss`): the logits of a
        distribution over the cells, or a regression of the Gaussian maps.

    Examples
    --------
    >>> SimpleBaseline(16, width=8)(torch.zeros(1, 3, 64, 64)).shape
    torch.Size([1, 16, 16, 16])
    """

    output = "heatmaps"
    stride = 4

    def __init__(
        self, num_joints: int, width: int = 16, in_channels: int = 3, heatmap: str = "softmax"
    ) -> None:
        super().__init__()
        self.num_joints = check_int(num_joints, "num_joints", 1)
        self.heatmap = check_choice(heatmap, "heatmap", HEATMAP_LOSSES)
        w = check_int(width, "width", 1)
        self.encoder = nn.Sequential(
            ConvBNAct(in_channels, w, stride=2),
            ResidualBlock(w, w),
            ResidualBlock(w, 2 * w, stride=2),
            ResidualBlock(2 * w, 4 * w, stride=2),
            ResidualBlock(4 * w, 8 * w, stride=2),
        )
        layers: list[nn.Module] = []
        c = 8 * w
        for _ in range(2):
            layers += [
                nn.ConvTranspose2d(c, 4 * w, 4, stride=2, padding=1, bias=False),
                nn.BatchNorm2d(4 * w),
                nn.ReLU(inplace=True),
            ]
            c = 4 * w
        self.decoder = nn.Sequential(*layers)
        self.head = _head(4 * w, self.num_joints)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.decoder(self.encoder(x)))


class _Fuse(nn.Module):
    """HRNet's exchange unit: output branch ``i`` is ``relu(sum_j f_ij(x_j))``."""

    def __init__(self, widths: Sequence[int]) -> None:
        super().__init__()
        self.paths = nn.ModuleList()
        for i, wi in enumerate(widths):
            row = nn.ModuleList()
            for j, wj in enumerate(widths):
                if j == i:
                    row.append(nn.Identity())
                elif j > i:  # lower resolution: 1x1 conv then nearest upsampling
                    row.append(
                        nn.Sequential(
                            ConvBNAct(wj, wi, 1, act=None),
                            nn.Upsample(scale_factor=2 ** (j - i), mode="nearest"),
                        )
                    )
                else:  # higher resolution: (i - j) strided 3x3 convolutions
                    steps: list[nn.Module] = []
                    for s in range(i - j):
                        last = s == i - j - 1
                        steps.append(
                            ConvBNAct(
                                wj, wi if last else wj, 3, stride=2, act=None if last else "relu"
                            )
                        )
                    row.append(nn.Sequential(*steps))
            self.paths.append(row)

    def forward(self, xs: list[torch.Tensor]) -> list[torch.Tensor]:
        out = []
        for i, row in enumerate(self.paths):
            total = xs[i]
            for j, f in enumerate(cast(nn.ModuleList, row)):
                if j != i:
                    total = total + f(xs[j])
            out.append(F.relu(total))
        return out


class HRNet(nn.Module):
    """A small HRNet: parallel branches at strides 4, 8, 16 with repeated fusion.

    Stem: two stride-2 ``ConvBNAct`` (stride 4, width ``w``) and ``blocks`` residual
    blocks. Stage 2 adds a stride-8 branch (width ``2w``) and stage 3 a stride-16
    branch (``4w``) by a strided convolution from the lowest branch; each stage has
    ``modules`` modules of ``blocks`` residual blocks per branch followed by a fusion
    (:class:`_Fuse`). Heatmaps come from the stride-4 branch by a 1x1 convolution, so
    the high-resolution representation is kept from the stem to the output.

    Parameters
    ----------
    num_joints : int
    width : int, default 16
    blocks : int, default 2
    modules : (int, int), default (1, 2)
        Modules in stages 2 and 3.
    in_channels : int, default 3
    heatmap : {"softmax", "mse"}, default "softmax"
        As :class:`SimpleBaseline`'s.

    Examples
    --------
    >>> HRNet(16, width=8, blocks=1)(torch.zeros(1, 3, 64, 64)).shape
    torch.Size([1, 16, 16, 16])
    """

    output = "heatmaps"
    stride = 4

    def __init__(
        self,
        num_joints: int,
        width: int = 16,
        blocks: int = 2,
        modules: Sequence[int] = (1, 2),
        in_channels: int = 3,
        heatmap: str = "softmax",
    ) -> None:
        super().__init__()
        self.num_joints = check_int(num_joints, "num_joints", 1)
        self.heatmap = check_choice(heatmap, "heatmap", HEATMAP_LOSSES)
        w = check_int(width, "width", 1)
        nb = check_int(blocks, "blocks", 1)
        mods = [check_int(m, "modules", 1) for m in modules]
        if len(mods) != 2:
            raise InputError(f"modules must be two counts (stages 2 and 3); got {list(modules)}")
        self.stem = nn.Sequential(
            ConvBNAct(in_channels, w, stride=2),
            ConvBNAct(w, w, stride=2),
            *[ResidualBlock(w, w) for _ in range(nb)],
        )
        self.transitions = nn.ModuleList()
        self.stages = nn.ModuleList()
        widths = [w]
        for stage, n_mod in enumerate(mods):
            new = widths[-1] * 2
            self.transitions.append(ConvBNAct(widths[-1], new, stride=2))
            widths = [*widths, new]
            mod_list = nn.ModuleList()
            for _ in range(n_mod):
                branches = nn.ModuleList(
                    nn.Sequential(*[ResidualBlock(c, c) for _ in range(nb)]) for c in widths
                )
                mod_list.append(nn.ModuleList([branches, _Fuse(widths)]))
            self.stages.append(mod_list)
            del stage
        self.head = _head(w, self.num_joints)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        xs = [self.stem(x)]
        for trans, modules in zip(self.transitions, self.stages, strict=True):
            xs = [*xs, trans(xs[-1])]
            for module in modules:  # type: ignore[attr-defined]
                branches, fuse = module[0], module[1]
                xs = fuse([b(t) for b, t in zip(branches, xs, strict=True)])
        return self.head(xs[0])


class DeepPose(nn.Module):
    """Direct regression of normalized joint coordinates (Toshev & Szegedy 2014).

    A residual encoder to stride 16 (widths ``w .. 8w``), flattened, then
    ``Linear(., hidden)``, ReLU, dropout and ``Linear(hidden, 2 J)``: the output is
    ``(N, J, 2)`` normalized coordinates :math:`(x / W - \tfrac12, y / H - \tfrac12)`.

    Parameters
    ----------
    num_joints : int
    image_size : (int, int), default (128, 128)
        ``(width, height)`` the network is built for (multiples of 16).
    width : int, default 16
    hidden : int, default 512
    dropout : float, default 0.2

    Examples
    --------
    >>> DeepPose(16, image_size=(64, 64), width=4)(torch.zeros(2, 3, 64, 64)).shape
    torch.Size([2, 16, 2])
    """

    output = "coordinates"
    stride = 16

    def __init__(
        self,
        num_joints: int,
        image_size: tuple[int, int] = (128, 128),
        width: int = 16,
        hidden: int = 512,
        dropout: float = 0.2,
        in_channels: int = 3,
    ) -> None:
        super().__init__()
        self.num_joints = check_int(num_joints, "num_joints", 1)
        self.image_size = _size(image_size, 16)
        w = check_int(width, "width", 1)
        hidden = check_int(hidden, "hidden", 1)
        p = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        self.encoder = nn.Sequential(
            ConvBNAct(in_channels, w, stride=2),
            ResidualBlock(w, w),
            ResidualBlock(w, 2 * w, stride=2),
            ResidualBlock(2 * w, 4 * w, stride=2),
            ResidualBlock(4 * w, 8 * w, stride=2),
            ConvBNAct(8 * w, 2 * w, 1),
        )
        cells = (self.image_size[0] // 16) * (self.image_size[1] // 16)
        self.regressor = nn.Sequential(
            nn.Flatten(),
            nn.Linear(2 * w * cells, hidden),
            nn.ReLU(inplace=True),
            nn.Dropout(p),
            nn.Linear(hidden, 2 * self.num_joints),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.regressor(self.encoder(x)).reshape(-1, self.num_joints, 2)


class DeepPoseRefiner(nn.Module):
    """A DeepPose cascade stage: per-joint displacements from windows around the
    current estimates.

    For joint :math:`k` at the estimate :math:`\\hat p_k`, the window of side ``crop``
    pixels centred there is resampled to ``patch x patch`` (:func:`crop_patches`); a
    small convolutional network maps it to ``2 J`` numbers of which the pair of joint
    :math:`k` is its displacement in units of the window: :math:`p_k = \\hat p_k +
    \\text{crop}\\, \\delta_k`.

    Parameters
    ----------
    num_joints : int
    crop : float, default 32
        Window side in image pixels.
    patch : int, default 32
    width : int, default 16

    Examples
    --------
    >>> r = DeepPoseRefiner(16, crop=16, patch=16, width=4)
    >>> r(torch.zeros(2, 3, 16, 16), torch.tensor([0, 3])).shape
    torch.Size([2, 2])
    """

    output = "refinement"

    def __init__(
        self, num_joints: int, crop: float = 32.0, patch: int = 32, width: int = 16
    ) -> None:
        super().__init__()
        self.num_joints = check_int(num_joints, "num_joints", 1)
        self.crop = check_real(crop, "crop", 1.0, 1e5)
        self.patch = check_int(patch, "patch", 8)
        self.width = w = check_int(width, "width", 1)
        self.net = nn.Sequential(
            ConvBNAct(3, w),
            ResidualBlock(w, 2 * w, stride=2),
            ResidualBlock(2 * w, 4 * w, stride=2),
            ResidualBlock(4 * w, 4 * w, stride=2),
            nn.AdaptiveAvgPool2d(2),
            nn.Flatten(),
            nn.Linear(16 * w, 2 * self.num_joints),
        )

    def forward(self, patches: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
        """Displacements ``(P, 2)`` (window units) for patches ``(P, 3, p, p)`` of joints
        ``(P,)``."""
        out = self.net(patches).reshape(-1, self.num_joints, 2)
        return out[torch.arange(len(joints)), joints]


def build_pose_model(
    name: str,
    num_joints: int,
    image_size: tuple[int, int] = (128, 128),
    *,
    seed: int | None = None,
    **kwargs: Any,
) -> nn.Module:
    """A pose network by name (:data:`POSE_MODELS`): ``"heatmap"``
    (:class:`SimpleBaseline`), ``"hrnet"`` (:class:`HRNet`) or ``"deeppose"``
    (:class:`DeepPose`, built for ``image_size``); other keywords go to the class.
    ``seed`` seeds torch's global generator before the weights are drawn.

    Examples
    --------
    >>> type(build_pose_model("hrnet", 16, width=8)).__name__
    'HRNet'
    """
    check_choice(name, "name", POSE_MODELS)
    if seed is not None:
        torch.manual_seed(check_int(seed, "seed", 0))
    if name == "heatmap":
        return SimpleBaseline(num_joints, **kwargs)
    if name == "hrnet":
        return HRNet(num_joints, **kwargs)
    return DeepPose(num_joints, image_size=image_size, **kwargs)


# ----------------------------------------------------------------------------- geometry
def crop_patches(
    images: torch.Tensor, centres: torch.Tensor, crop: float, patch: int
) -> torch.Tensor:
    r"""Square windows of side ``crop`` pixels centred at ``centres``, resampled to
    ``patch x patch`` by bilinear interpolation (zeros outside the image).

    Window pixel ``(a, b)`` samples the image at :math:`c + \text{crop} ((b + \tfrac12) /
    p - \tfrac12, (a + \tfrac12) / p - \tfrac12)` in the module's pixel-centre
    coordinates (RoI Align with one sample per bin and ``aligned=True``).

    Parameters
    ----------
    images : (N, C, H, W) tensor
    centres : (N, K, 2) tensor
        ``(x, y)`` pixels.
    crop : float
    patch : int

    Returns
    -------
    (N K, C, patch, patch) tensor
        Window ``n K + k`` is joint ``k`` of image ``n``.

    Examples
    --------
    >>> im = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> crop_patches(im, torch.tensor([[[2.0, 2.0]]]), 2.0, 2)[0, 0].tolist()
    [[5.0, 6.0], [9.0, 10.0]]
    """
    _tensor(images, "images", 4, "(N, C, H, W)")
    _tensor(centres, "centres", 3, "(N, K, 2) of (x, y)")
    n, _c, h, w = images.shape
    if centres.shape[0] != n or centres.shape[2] != 2:
        raise InputError(
            f"centres must be ({n}, K, 2), (x, y) per window of each image; got "
            f"{tuple(centres.shape)}"
        )
    crop = check_real(crop, "crop", 0.0, 1e6, low_inclusive=False)
    patch = check_int(patch, "patch", 1)
    if patch > 1024:
        raise InputError(f"patch must be at most 1024 pixels; got {patch}")
    k = centres.shape[1]
    t = (torch.arange(patch, dtype=images.dtype) + 0.5) / patch - 0.5
    ox = centres[..., 0:1] + crop * t  # (N, K, p)
    oy = centres[..., 1:2] + crop * t
    gx = 2 * ox / w - 1
    gy = 2 * oy / h - 1
    grid = torch.stack(
        [
            gx[:, :, None, :].expand(n, k, patch, patch),
            gy[:, :, :, None].expand(n, k, patch, patch),
        ],
        -1,
    ).reshape(n * k, patch, patch, 2)
    src = images.repeat_interleave(k, 0)
    return F.grid_sample(src, grid.to(images.dtype), mode="bilinear", align_corners=False)


def augment_pose_batch(
    images: torch.Tensor,
    keypoints: torch.Tensor,
    flip_permutation: npt.ArrayLike | None,
    generator: torch.Generator,
    *,
    rotation: float = 30.0,
    scale: tuple[float, float] = (0.75, 1.25),
    shift: float = 0.1,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Random flips, rotations, scalings and shifts of images and their keypoints.

    Each image gets the map (pixels, about the image centre :math:`c`)
    :math:`p' = c + s R_\theta (F(p) - c) + t`, with :math:`F` a horizontal flip
    :math:`x \mapsto W - x` (probability 1/2, when ``flip_permutation`` is given; the
    joints then swap sides by the permutation), :math:`\theta \sim U(\pm` ``rotation``
    :math:`)` degrees, :math:`s \sim U(` ``scale`` :math:`)`, :math:`t \sim U(\pm`
    ``shift`` :math:`\cdot (W, H))`. The image is resampled bilinearly (zeros outside);
    keypoints mapped outside the image get ``v = 0``.

    Returns
    -------
    images : (N, C, H, W) tensor
    keypoints : (N, J, 3) tensor
    """
    _tensor(images, "images", 4, "(N, C, H, W)")
    _tensor(keypoints, "keypoints", 3, "(N, J, 3) of (x, y, v)")
    if keypoints.shape[0] != images.shape[0] or keypoints.shape[2] != 3:
        raise InputError(
            f"keypoints must be ({images.shape[0]}, J, 3) for the images; got "
            f"{tuple(keypoints.shape)}"
        )
    if not isinstance(generator, torch.Generator):
        raise InputError(f"generator must be a torch.Generator; got {plain_repr(generator)}")
    rotation = check_real(rotation, "rotation", 0.0, 180.0)
    shift = check_real(shift, "shift", 0.0, 1.0)
    try:
        s_lo, s_hi = (check_real(v, "scale", 0.01, 100.0) for v in scale)
    except (TypeError, ValueError):
        raise InputError(f"scale must be (low, high); got {plain_repr(scale)}") from None
    if s_lo > s_hi:
        raise InputError(f"scale must be (low, high) with low <= high; got {(s_lo, s_hi)}")
    scale = (s_lo, s_hi)
    n, _c, h, w = images.shape
    dt = images.dtype
    u = torch.rand((n, 5), generator=generator, dtype=torch.float64)
    theta = torch.deg2rad((2 * u[:, 0] - 1) * rotation)
    s = scale[0] + (scale[1] - scale[0]) * u[:, 1]
    tx = (2 * u[:, 2] - 1) * shift * w
    ty = (2 * u[:, 3] - 1) * shift * h
    flip = (u[:, 4] < 0.5) if flip_permutation is not None else torch.zeros(n, dtype=torch.bool)
    cx, cy = w / 2.0, h / 2.0
    cos, sin = torch.cos(theta), torch.sin(theta)
    # forward map p' = A p + a
    fx = torch.where(flip, -1.0, 1.0).to(torch.float64)
    a11, a12 = s * cos * fx, -s * sin
    a21, a22 = s * sin * fx, s * cos
    x0 = torch.where(flip, w - cx, -cx).to(torch.float64)  # F(p) - c, x part offset
    a1 = s * (cos * x0 - sin * (-cy)) + cx + tx
    a2 = s * (sin * x0 + cos * (-cy)) + cy + ty
    kp = keypoints.clone().to(torch.float64)
    if flip_permutation is not None:
        perm = torch.as_tensor(_permutation(flip_permutation, int(kp.shape[1])))
        kp[flip] = kp[flip][:, perm]
    x, y = kp[..., 0], kp[..., 1]
    nx = a11[:, None] * x + a12[:, None] * y + a1[:, None]
    ny = a21[:, None] * x + a22[:, None] * y + a2[:, None]
    inside = (nx >= 0) & (nx < w) & (ny >= 0) & (ny < h)
    kp[..., 0], kp[..., 1] = nx, ny
    kp[..., 2] = torch.where(inside, kp[..., 2], torch.zeros_like(kp[..., 2]))
    # inverse map for sampling, in normalized coordinates n = D p - 1, D = diag(2/W, 2/H)
    det = a11 * a22 - a12 * a21
    b11, b12, b21, b22 = a22 / det, -a12 / det, -a21 / det, a11 / det
    b1 = -(b11 * a1 + b12 * a2)
    b2 = -(b21 * a1 + b22 * a2)
    dx, dy = 2.0 / w, 2.0 / h
    m = torch.zeros((n, 2, 3), dtype=torch.float64)
    m[:, 0, 0], m[:, 0, 1] = b11, b12 * dx / dy
    m[:, 1, 0], m[:, 1, 1] = b21 * dy / dx, b22
    m[:, 0, 2] = dx * (b11 / dx + b12 / dy + b1) - 1
    m[:, 1, 2] = dy * (b21 / dx + b22 / dy + b2) - 1
    grid = F.affine_grid(m.to(dt), list(images.shape), align_corners=False)
    out = F.grid_sample(images, grid, mode="bilinear", align_corners=False)
    return out, kp.to(keypoints.dtype)


# ----------------------------------------------------------------------------- inference
def _tensor(value: Any, name: str, ndim: int, what: str) -> torch.Tensor:
    """A float tensor of ``ndim`` dimensions (``what`` says their meaning), or InputError."""
    if not torch.is_tensor(value) or not value.is_floating_point() or value.ndim != ndim:
        raise InputError(f"{name} must be a float torch.Tensor {what}; got {plain_repr(value)}")
    return value


def _images(images: Any, what: str = "images") -> torch.Tensor:
    if torch.is_tensor(images):
        x = images.to(torch.float32)
    else:
        from robopercept._checks import check_numeric

        a = check_numeric(images, what)
        if a.ndim != 4 or a.shape[-1] not in (1, 3):
            raise InputError(
                f"{what} must be (N, H, W, 3) float in [0, 1]; got {plain_repr(images)}"
            )
        x = torch.from_numpy(np.ascontiguousarray(a.transpose(0, 3, 1, 2), dtype=np.float32))
    if x.ndim != 4:
        raise InputError(f"{what} must be a batch (N, C, H, W); got shape {tuple(x.shape)}")
    return x


def _permutation(value: Any, j: int) -> np.ndarray:
    """A permutation of ``0..j-1`` (a skeleton's flip permutation), or InputError."""
    try:
        perm = np.asarray(value, dtype=np.int64).reshape(-1)
    except (TypeError, ValueError):
        perm = np.zeros(0, np.int64)
    if perm.shape != (j,) or sorted(perm.tolist()) != list(range(j)):
        raise InputError(
            f"flip_permutation must be a permutation of the {j} joints (e.g. "
            f"skeleton.flip_permutation()); got {plain_repr(value)}"
        )
    return perm


def _check_input_size(model: nn.Module, x: torch.Tensor) -> None:
    h, w = x.shape[-2:]
    size = getattr(model, "image_size", None)
    if size is not None and (w, h) != tuple(size):
        raise InputError(
            f"the network was built for {size[0]} x {size[1]} images; got {w} x {h}: resize "
            "or crop the person to that size"
        )
    need = 16  # every network here downsamples by 16 at its deepest
    if w % need or h % need or w < need or h < need:
        raise InputError(
            f"images must be at least {need} px and a multiple of {need} in each side; got "
            f"{w} x {h}"
        )


@torch.no_grad()
def predict_keypoints(
    model: nn.Module,
    images: Any,
    *,
    flip_permutation: npt.ArrayLike | None = None,
    method: str = "quadratic",
    batch_size: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints of images through a pose network (eval mode).

    Heatmap networks are decoded by :func:`decode_heatmaps` (``method``), with the flip
    test when ``flip_permutation`` is given; a :class:`DeepPose` network's normalized
    output is scaled back to pixels (score 1; with the flip test the two estimates are
    averaged).

    Parameters
    ----------
    model : nn.Module
    images : (N, H, W, 3) array or (N, 3, H, W) tensor
    flip_permutation : (J,) array_like, optional
    method : str
    batch_size : int

    Returns
    -------
    keypoints : (N, J, 2) ndarray
    scores : (N, J) ndarray
    """
    kp, sc, _ = predict_heatmaps(
        model, images, flip_permutation=flip_permutation, method=method, batch_size=batch_size
    )
    return kp, sc


def _as_maps(model: nn.Module, out: torch.Tensor) -> torch.Tensor:
    """A ``"softmax"`` network's logits as the distribution over the cells (per joint);
    an ``"mse"`` network's maps as they are."""
    if getattr(model, "heatmap", "mse") != "softmax":
        return out
    n, j, h, w = out.shape
    return torch.softmax(out.reshape(n, j, -1), -1).reshape(n, j, h, w)


@torch.no_grad()
def predict_heatmaps(
    model: nn.Module,
    images: Any,
    *,
    flip_permutation: npt.ArrayLike | None = None,
    method: str = "quadratic",
    batch_size: int = 64,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`predict_keypoints` and the (flip-averaged) heatmaps ``(N, J, h, w)``
    float32 they were decoded from (None for DeepPose)."""
    from robopercept.nn._guards import check_module

    model = check_module(model)
    x = _images(images)
    _check_input_size(model, x)
    check_choice(method, "method", DECODERS)
    batch_size = check_int(batch_size, "batch_size", 1)
    model.eval()
    dev = next(model.parameters()).device
    kps, scores, hms = [], [], []
    j = int(getattr(model, "num_joints", 0))
    perm = None
    if flip_permutation is not None:
        size = j or int(np.asarray(flip_permutation).size)
        perm = torch.as_tensor(_permutation(flip_permutation, size))
    regression = getattr(model, "output", "heatmaps") == "coordinates"
    for i in range(0, len(x), batch_size):
        xb = x[i : i + batch_size].to(dev)
        out = model(xb)
        if regression:
            h, w = xb.shape[-2:]
            scale = torch.tensor([w, h], dtype=out.dtype, device=out.device)
            kp = ((out + 0.5) * scale).cpu().double().numpy()
            if perm is not None:
                out_f = model(xb.flip(-1))[:, perm]
                kp_f = ((out_f + 0.5) * scale).cpu().double().numpy()
                kp_f[..., 0] = w - kp_f[..., 0]
                kp = 0.5 * (kp + kp_f)
            kps.append(kp)
            scores.append(np.ones(kp.shape[:2]))
            continue
        if perm is not None:
            out_f = model(xb.flip(-1)).flip(-1)[:, perm]
            out = 0.5 * (_as_maps(model, out) + _as_maps(model, out_f))
        else:
            out = _as_maps(model, out)
        kp, sc = decode_heatmaps(out, int(getattr(model, "stride", 4)), method)
        kps.append(kp)
        scores.append(sc)
        hms.append(out.cpu().float().numpy())
    return (
        np.concatenate(kps),
        np.concatenate(scores),
        None if regression else np.concatenate(hms),
    )


@torch.no_grad()
def refine_keypoints(
    images: Any, keypoints: npt.ArrayLike, refiners: Sequence[DeepPoseRefiner]
) -> np.ndarray:
    """Run DeepPose cascade stages: each moves every joint by its predicted
    displacement, from windows around the previous stage's estimates.

    Parameters
    ----------
    images : (N, H, W, 3) array or (N, 3, H, W) tensor
    keypoints : (N, J, 2) array_like
        The first stage's estimates (pixels).
    refiners : sequence of DeepPoseRefiner

    Returns
    -------
    (N, J, 2) ndarray
    """
    x = _images(images)
    kp = torch.as_tensor(np.asarray(keypoints, dtype=np.float32))
    if kp.ndim != 3 or kp.shape[0] != len(x) or kp.shape[-1] != 2:
        raise InputError(f"keypoints must be (N, J, 2) for the N images; got {tuple(kp.shape)}")
    for stage in refiners:
        if not isinstance(stage, DeepPoseRefiner):
            raise InputError(f"refiners must be DeepPoseRefiner stages; got {plain_repr(stage)}")
        stage.eval()
        if stage.num_joints != kp.shape[1]:
            raise InputError(
                f"a refiner for {stage.num_joints} joints cannot refine {kp.shape[1]} joints"
            )
        out = []
        for i in range(0, len(x), 32):
            xb, kb = x[i : i + 32], kp[i : i + 32]
            n, j = kb.shape[:2]
            patches = crop_patches(xb, kb, stage.crop, stage.patch)
            joints = torch.arange(j).repeat(n)
            delta = stage(patches, joints).reshape(n, j, 2)
            out.append(kb + stage.crop * delta)
        kp = torch.cat(out)
    return kp.double().numpy()


# ----------------------------------------------------------------------------- training
class PoseHistory(EpochHistory):
    """What :func:`train_pose` and :func:`train_refiner` measured: mean training loss
    and seconds per epoch, the validation PCK by epoch, the epoch kept."""

    val_name = "val_pck"


def _pck(pred: np.ndarray, keypoints: np.ndarray, boxes: np.ndarray, alpha: float) -> float:
    from robopercept.nn.pose.metrics import bbox_diagonal, pck

    return float(pck(pred, keypoints, None, alpha, bbox_diagonal(boxes, "xyxy")).mean)


def _data_arrays(data: Any, what: str) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    images = getattr(data, "images", None)
    keypoints = getattr(data, "keypoints", None)
    boxes = getattr(data, "boxes", None)
    if images is None or keypoints is None or boxes is None:
        raise InputError(
            f"{what} must be a PoseDataset (procedural_pose_set, ...); got {plain_repr(data)}"
        )
    return _images(images, what), _keypoint_tensor(keypoints), np.asarray(boxes)


def train_pose(
    model: nn.Module,
    train: Any,
    config: Any = None,
    *,
    val: Any = None,
    skeleton: Skeleton | None = None,
    sigma: float = 2.0,
    augment: bool = True,
    pck_alpha: float = 0.1,
    progress: bool = True,
) -> PoseHistory:
    r"""Train a heatmap network or DeepPose on a :class:`~robopercept.nn.pose.data.PoseDataset`.

    Each step takes ``config.batch_size`` images of a seeded shuffle, augmented
    (:func:`augment_pose_batch`, flips only when ``skeleton`` gives the flip pairs).
    Heatmap networks minimize :func:`heatmap_loss` of their kind (``model.heatmap``,
    ``"softmax"`` or ``"mse"``) against :func:`gaussian_heatmaps` targets (``sigma``
    cells) over labelled joints;
    DeepPose minimizes the squared error of the normalized coordinates over labelled
    joints, :math:`\sum w_{nk} \lVert \hat y_{nk} - y_{nk} \rVert^2 / \sum w_{nk}`.
    Optimizer and per-step schedule from
    :func:`~robopercept.nn.train.loop.step_optimizer`. With ``val``, the PCK@``pck_alpha``
    (of the box diagonal) is measured after every epoch and the best epoch's weights
    are kept.

    Returns
    -------
    PoseHistory
    """
    from robopercept.nn.train.loop import (
        TrainConfig,
        resolve_device,
    )

    if not isinstance(model, nn.Module) or getattr(model, "output", None) not in (
        "heatmaps",
        "coordinates",
    ):
        raise InputError(
            f"model must be a pose network (build_pose_model); got {plain_repr(model)}"
        )
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    x, kp, _boxes = _data_arrays(train, "train")
    if kp.shape[1] != model.num_joints:
        raise InputError(
            f"the network predicts {model.num_joints} joints; the data has {kp.shape[1]}"
        )
    _check_input_size(model, x)
    if val is not None:
        vx, vkp, vboxes = _data_arrays(val, "val")
    sigma = check_real(sigma, "sigma", 0.0, 1e3, low_inclusive=False)
    check_bool(augment, "augment")
    perm = None if skeleton is None else skeleton.flip_permutation()
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    n, _, h, w = x.shape
    stride = int(getattr(model, "stride", 4))

    def batch(idx: torch.Tensor) -> torch.Tensor:
        xb, kb = x[idx], kp[idx]
        if augment:
            xb, kb = augment_pose_batch(xb, kb, perm, gen)
        out = model(xb.to(dev))
        if model.output == "heatmaps":
            target, weight = gaussian_heatmaps(kb, (w, h), stride, sigma)
            kind = getattr(model, "heatmap", "mse")
            return heatmap_loss(out, target.to(dev), weight.to(dev), kind)
        size = torch.tensor([w, h], dtype=torch.float32)
        y = kb[..., :2] / size - 0.5
        lab = (kb[..., 2] > 0).float().to(dev)
        err = ((out - y.to(dev)) ** 2).sum(-1)
        return (err * lab).sum() / lab.sum().clamp_min(1.0)

    def validate() -> float:
        pred, _ = predict_keypoints(model, vx)
        return _pck(pred, vkp.numpy(), vboxes, pck_alpha)

    hist = PoseHistory()
    epoch_loop(
        model,
        n,
        cfg,
        gen,
        batch,
        validate if val is not None else None,
        desc="training pose network",
        progress=progress,
        history=hist,
    )
    return hist


def train_refiner(
    refiner: DeepPoseRefiner,
    train: Any,
    estimates: npt.ArrayLike,
    config: Any = None,
    *,
    val: Any = None,
    val_estimates: npt.ArrayLike | None = None,
    progress: bool = True,
    pck_alpha: float = 0.1,
) -> PoseHistory:
    r"""Train one DeepPose cascade stage on the previous stage's estimates.

    As in Toshev & Szegedy (2014), section 3.2, the windows are centred on the
    previous stage's estimate of each joint on the training images and, as
    augmentation, on the truth displaced by a draw from a normal distribution fitted
    to that stage's displacements (their mean and covariance per joint); the target is
    the displacement to the truth in window units,
    :math:`\delta_k = (p_k - \hat p_k) / \text{crop}`, its squared error averaged over
    the labelled joints.

    Parameters
    ----------
    refiner : DeepPoseRefiner
    train : PoseDataset
    estimates : (N, J, 2) array_like
        The previous stage's estimates on ``train`` (pixels).
    config : TrainConfig, optional
    val, val_estimates : optional
        Validation data and its previous-stage estimates: the PCK after refinement is
        measured every epoch and the best epoch kept.

    Returns
    -------
    PoseHistory
    """
    from robopercept.nn.train.loop import (
        TrainConfig,
        resolve_device,
    )

    if not isinstance(refiner, DeepPoseRefiner):
        raise InputError(f"refiner must be a DeepPoseRefiner; got {plain_repr(refiner)}")
    cfg = config or TrainConfig()
    x, kp, _ = _data_arrays(train, "train")
    est = torch.as_tensor(np.asarray(estimates, dtype=np.float32))
    if est.shape != kp[..., :2].shape:
        raise InputError(
            f"estimates must be (N, J, 2) = {tuple(kp[..., :2].shape)}; got {tuple(est.shape)}"
        )
    if val is not None:
        vx, vkp, vboxes = _data_arrays(val, "val")
        if val_estimates is None:
            raise InputError("val needs val_estimates (the previous stage's output on it)")
        vest = np.asarray(val_estimates, dtype=np.float64)
    lab = kp[..., 2] > 0
    resid = (kp[..., :2] - est).double()
    mu = torch.stack([resid[:, k][lab[:, k]].mean(0) for k in range(kp.shape[1])])
    cov = torch.stack(
        [
            torch.cov(resid[:, k][lab[:, k]].T) + 1e-3 * torch.eye(2, dtype=torch.float64)
            for k in range(kp.shape[1])
        ]
    )
    chol = torch.linalg.cholesky(cov)
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    refiner.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    n, j = kp.shape[:2]

    def batch(idx: torch.Tensor) -> torch.Tensor:
        m = len(idx)
        truth = kp[idx, :, :2].double()
        z = torch.randn((m, j, 2), generator=gen, dtype=torch.float64)
        sim = truth - mu - torch.einsum("jab,mjb->mja", chol, z)
        use_est = torch.rand((m, 1, 1), generator=gen) < 0.5
        centres = torch.where(use_est, est[idx].double(), sim).float()
        patches = crop_patches(x[idx], centres, refiner.crop, refiner.patch)
        joints = torch.arange(j).repeat(m)
        target = ((truth.float() - centres) / refiner.crop).reshape(-1, 2)
        weight = lab[idx].reshape(-1).float().to(dev)
        out = refiner(patches.to(dev), joints.to(dev))
        err = ((out - target.to(dev)) ** 2).sum(-1)
        return (err * weight).sum() / weight.sum().clamp_min(1.0)

    def validate() -> float:
        pred = refine_keypoints(vx, vest, [refiner])
        return _pck(pred, vkp.numpy(), vboxes, pck_alpha)

    hist = PoseHistory()
    epoch_loop(
        refiner,
        n,
        cfg,
        gen,
        batch,
        validate if val is not None else None,
        desc="training DeepPose stage",
        progress=progress,
        history=hist,
    )
    return hist


# ----------------------------------------------------------------------------- checkpoints
def _build_from_joints(name: str, n_joints: int, **settings: Any) -> nn.Module:
    return build_pose_model(name, n_joints, **settings)


def save_pose_model(
    path: Any,
    model: nn.Module,
    name: str,
    settings: dict[str, Any],
    skeleton: Skeleton,
    *,
    refiners: Sequence[DeepPoseRefiner] = (),
    **extra: Any,
) -> Any:
    """Write a pose network's weights with what rebuilds it: ``name`` of
    :data:`POSE_MODELS`, its keyword ``settings`` (``image_size`` included for
    DeepPose), the ``skeleton`` (as :meth:`~robopercept.nn.skeleton.Skeleton.to_dict`),
    DeepPose cascade ``refiners`` (their settings and weights) and ``extra`` plain
    values; the checkpoint format of :func:`~robopercept.nn.train.loop.save_built_model`.
    Returns the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.nn.skeleton import MPII_16
    >>> net = build_pose_model("hrnet", 16, width=4, blocks=1)
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "pose.pt"
    >>> _ = save_pose_model(p, net, "hrnet", {"width": 4, "blocks": 1}, MPII_16)
    >>> net2, info = load_pose_model(p)
    >>> type(net2).__name__, info["skeleton"].name
    ('HRNet', 'mpii16')
    """
    from robopercept.nn.train.loop import save_built_model

    check_choice(name, "name", POSE_MODELS)
    if not isinstance(skeleton, Skeleton):
        raise InputError(f"skeleton must be a Skeleton; got {plain_repr(skeleton)}")
    stages = []
    for r in refiners:
        if not isinstance(r, DeepPoseRefiner):
            raise InputError(f"refiners must be DeepPoseRefiner stages; got {plain_repr(r)}")
        stages.append(
            {
                "settings": {"crop": r.crop, "patch": r.patch, "width": r.width},
                "state": r.state_dict(),
            }
        )
    return save_built_model(
        path,
        model,
        name,
        settings,
        list(skeleton.joints),
        skeleton=skeleton.to_dict(),
        refiners=stages,
        **extra,
    )


def load_pose_model(path: Any) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a pose network written by :func:`save_pose_model` (eval mode, CPU).

    Returns
    -------
    model : nn.Module
    info : dict
        The checkpoint's plain values, with ``"skeleton"`` a
        :class:`~robopercept.nn.skeleton.Skeleton` and ``"refiners"`` a list of
        :class:`DeepPoseRefiner` (empty for heatmap networks).

    Raises
    ------
    FileFormatError
        Missing or unreadable file, or a checkpoint that is not a pose network's.
    """
    from robopercept.errors import FileFormatError
    from robopercept.nn.train.loop import load_built_model

    model, info = load_built_model(
        path,
        POSE_MODELS,
        _build_from_joints,
        "pose network",
        "save_pose_model or `robopercept nn pose train`",
    )
    try:
        info["skeleton"] = Skeleton.from_dict(info["skeleton"])
        stages = []
        for s in info.get("refiners") or []:
            r = DeepPoseRefiner(len(info["classes"]), **s["settings"])
            r.load_state_dict(s["state"])
            stages.append(r.eval())
        info["refiners"] = stages
    except (KeyError, TypeError, InputError, RuntimeError) as exc:
        raise FileFormatError(
            f"{path}: a pose checkpoint without a valid skeleton or stages ({exc})"
        ) from None
    return model, info


# ----------------------------------------------------------------------------- any image
@dataclass(frozen=True)
class PoseResult:
    """Keypoints found on one image.

    Attributes
    ----------
    keypoints : (J, 2) float64 ndarray
        ``(x, y)`` pixels of the input image.
    scores : (J,) float64 ndarray
        Per-joint confidence (the heatmap peak; 1 for DeepPose).
    heatmaps : (J, h, w) float32 ndarray or None
        The network's heatmaps over the image's part of the letterboxed input (cells of
        ``stride`` input pixels; None for DeepPose).
    box : (4,) float64 ndarray
        The image region given to the network (``xyxy``).
    """

    keypoints: np.ndarray
    scores: np.ndarray
    heatmaps: np.ndarray | None
    box: np.ndarray


def pose_arrays(
    model: nn.Module,
    images: Sequence[Any],
    *,
    input_size: tuple[int, int] = (128, 128),
    flip_permutation: npt.ArrayLike | None = None,
    refiners: Sequence[DeepPoseRefiner] = (),
) -> list[PoseResult]:
    """Single-person (top-down) pose of whole NumPy images through a pose network.

    Each image, ``(H, W)`` or ``(H, W, 3)``, ``uint8``, ``uint16`` or float in [0, 1]
    (:func:`~robopercept.nn.data.datasets.to_unit_float`), is letterboxed into the network's
    ``input_size``: scaled by :math:`s = \\min(W_0 / W, H_0 / H)` (bilinear,
    antialiased), centred, padded with zeros; the keypoints are mapped back by the
    inverse of that map, so they are in the input image's pixels.

    Raises
    ------
    InputError
        Images that are not 2-D/3-channel arrays, or smaller than 8 x 8 pixels.
    """
    from robopercept.nn.data.datasets import to_unit_float

    w0, h0 = _size(getattr(model, "image_size", input_size), 16)
    batch, boxes, scales, offsets = [], [], [], []
    for i, im in enumerate(images):
        a = np.asarray(im)
        if a.ndim == 3 and a.shape[-1] == 1:
            a = a[..., 0]
        if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[-1] != 3):
            raise InputError(f"images[{i}] must be (H, W) or (H, W, 3); got {plain_repr(im)}")
        if min(a.shape[:2]) < 8:
            raise InputError(
                f"images[{i}] is {a.shape[1]} x {a.shape[0]} px; a person needs at least 8 x 8"
            )
        f = to_unit_float(a).astype(np.float32)
        if f.ndim == 2:
            f = np.repeat(f[..., None], 3, axis=2)
        h, w = f.shape[:2]
        s = min(w0 / w, h0 / h)
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        t = torch.from_numpy(np.ascontiguousarray(f.transpose(2, 0, 1)))[None]
        t = F.interpolate(t, size=(nh, nw), mode="bilinear", antialias=True, align_corners=False)
        ox, oy = (w0 - nw) // 2, (h0 - nh) // 2
        canvas = torch.zeros((3, h0, w0))
        canvas[:, oy : oy + nh, ox : ox + nw] = t[0].clamp(0, 1)
        batch.append(canvas)
        sx, sy = nw / w, nh / h
        scales.append((sx, sy))
        offsets.append((ox, oy))
        boxes.append(np.array([0.0, 0.0, w, h]))
    if not batch:
        return []
    x = torch.stack(batch)
    kp, sc, hm = predict_heatmaps(model, x, flip_permutation=flip_permutation)
    if refiners:
        kp = refine_keypoints(x, kp, refiners)
    results = []
    for i in range(len(batch)):
        (sx, sy), (ox, oy) = scales[i], offsets[i]
        k = np.stack([(kp[i, :, 0] - ox) / sx, (kp[i, :, 1] - oy) / sy], -1)
        heat = None
        if hm is not None:
            st = int(getattr(model, "stride", 4))
            nw, nh = round(sx * boxes[i][2]), round(sy * boxes[i][3])
            heat = hm[i][:, oy // st : -(-(oy + nh) // st), ox // st : -(-(ox + nw) // st)].copy()
        results.append(PoseResult(k, sc[i], heat, boxes[i]))
    return results


# ----------------------------------------------------------------------------- evaluation
@dataclass(frozen=True, eq=False)
class PoseEvaluation:
    """How well a pose network finds the joints of a :class:`~robopercept.nn.pose.data.PoseDataset`.

    Attributes
    ----------
    pck : dict of float to float
        PCK at each ``alpha`` of the box diagonal (mmpose's mean over joints).
    per_joint : (J,) float64 ndarray
        PCK@0.1 per joint.
    oks : CocoEvaluation
        COCO keypoint AP/AR (OKS with the skeleton's sigmas), one result per image
        scored by its mean joint score.
    keypoints : (N, J, 2) float64 ndarray
        The predictions.
    """

    pck: dict[float, float]
    per_joint: np.ndarray
    oks: Any
    keypoints: np.ndarray

    def summary(self) -> dict[str, float]:
        """PCK@alpha and the 10 keypoint AP/AR numbers, by name."""
        out = {f"PCK@{a:g}": v for a, v in self.pck.items()}
        out.update({f"OKS {k}": v for k, v in self.oks.summary().items()})
        return out


def evaluate_pose(
    model: nn.Module,
    data: Any,
    *,
    refiners: Sequence[DeepPoseRefiner] = (),
    flip: bool = True,
    alphas: Sequence[float] = (0.05, 0.1, 0.2),
    skeleton: Skeleton | None = None,
) -> PoseEvaluation:
    """PCK (:func:`~robopercept.nn.pose.metrics.pck`, the box diagonal as normalizer) and
    COCO keypoint AP (:func:`~robopercept.nn.coco.formats.evaluate_detections` with
    ``iou_type="keypoints"``) of a pose network on a data set.

    Parameters
    ----------
    model : nn.Module
    data : PoseDataset
    refiners : sequence of DeepPoseRefiner
        DeepPose cascade stages applied after the network.
    flip : bool
        The flip test (heatmap networks; averaged coordinates for DeepPose).
    alphas : sequence of float
    skeleton : Skeleton, optional
        Default: the data set's (its flip pairs and sigmas).
    """
    from robopercept.nn.coco.formats import evaluate_detections
    from robopercept.nn.pose.metrics import bbox_diagonal, pck

    x, kp, boxes = _data_arrays(data, "data")
    sk = skeleton if skeleton is not None else getattr(data, "skeleton", None)
    if not isinstance(sk, Skeleton):
        raise InputError(f"skeleton must be a Skeleton; got {plain_repr(sk)}")
    check_bool(flip, "flip")
    perm = sk.flip_permutation() if flip else None
    pred, scores = predict_keypoints(model, x, flip_permutation=perm)
    if refiners:
        pred = refine_keypoints(x, pred, refiners)
    truth = kp.numpy().astype(np.float64)
    diag = bbox_diagonal(boxes, "xyxy")
    values = {}
    for a in alphas:
        values[float(a)] = float(pck(pred, truth, None, float(a), diag).mean)
    per_joint = pck(pred, truth, None, 0.1, diag).per_joint
    results: list[Mapping[str, Any]] = [
        {
            "image_id": i + 1,
            "category_id": 1,
            "keypoints": np.concatenate([pred[i], np.ones((len(pred[i]), 1))], 1).ravel().tolist(),
            "score": float(np.mean(scores[i])),
        }
        for i in range(len(pred))
    ]
    oks = evaluate_detections(data.to_coco(), results, "keypoints", sigmas=sk.sigmas)
    return PoseEvaluation(values, np.asarray(per_joint), oks, pred)


def train_cascade(
    model: nn.Module,
    train: Any,
    stages: int,
    config: Any = None,
    *,
    val: Any = None,
    crop: float | None = None,
    width: int = 16,
    progress: bool = True,
) -> tuple[list[DeepPoseRefiner], list[PoseHistory]]:
    """DeepPose's cascade: ``stages`` :class:`DeepPoseRefiner` stages, each trained by
    :func:`train_refiner` on the estimates of the network and the stages before it
    (on ``train``, and on ``val`` for picking each stage's epoch).

    Parameters
    ----------
    model : nn.Module
        The trained first stage (a :class:`DeepPose`, or any pose network).
    train, val : PoseDataset
    stages : int
        0 to 8.
    config : TrainConfig, optional
    crop : float, optional
        The window side in pixels (default a quarter of the shorter image side).
    width : int

    Returns
    -------
    refiners : list of DeepPoseRefiner
    histories : list of PoseHistory
    """
    stages = check_int(stages, "stages", 0)
    if stages > 8:
        raise InputError(f"stages must be 0 to 8 cascade stages; got {stages}")
    x, kp, _ = _data_arrays(train, "train")
    vx = _data_arrays(val, "val")[0] if val is not None else None
    side = crop if crop is not None else 0.25 * min(x.shape[-2:])
    est, _ = predict_keypoints(model, x)
    vest = predict_keypoints(model, vx)[0] if vx is not None else None
    refiners: list[DeepPoseRefiner] = []
    histories: list[PoseHistory] = []
    for _ in range(stages):
        stage = DeepPoseRefiner(int(kp.shape[1]), crop=side, width=width)
        h = train_refiner(stage, train, est, config, val=val, val_estimates=vest, progress=progress)
        refiners.append(stage)
        histories.append(h)
        est = refine_keypoints(x, est, [stage])
        if vx is not None and vest is not None:
            vest = refine_keypoints(vx, vest, [stage])
    return refiners, histories


def samples_picture(
    model: nn.Module,
    data: Any,
    *,
    refiners: Sequence[DeepPoseRefiner] = (),
    count: int = 6,
) -> np.ndarray:
    """The first ``count`` images of a pose data set with the network's skeletons
    (flip test, ``refiners`` applied), side by side and enlarged to read at 1080p: the
    ``samples.png`` of ``robopercept nn pose train``.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    from robopercept.viz.pose import draw_skeleton
    from robopercept.viz.segmentation import panels_picture

    sk = getattr(data, "skeleton", None)
    if not isinstance(sk, Skeleton):
        raise InputError(f"data must be a PoseDataset; got {plain_repr(data)}")
    n = min(check_int(count, "count", 1), len(data))
    images = list(data.images[:n])
    res = pose_arrays(model, images, flip_permutation=sk.flip_permutation(), refiners=refiners)
    pics = [
        draw_skeleton(im, r.keypoints, sk.links, flip_pairs=sk.flip_pairs, min_side=384)
        for im, r in zip(images, res, strict=True)
    ]
    return panels_picture(pics, [f"image {i + 1}" for i in range(n)])
