r"""2-D pose estimation networks: heatmap networks (a SimpleBaseline-style network and
an HRNet-style high-resolution network) and direct regression (DeepPose and its
cascade stage), built by name, saved and loaded with what rebuilds them.

Coordinates are ``(x, y)`` pixels with the pixel-centre convention of
:mod:`robopercept.nn.ops.heatmaps`, whose codec (targets, decoding, loss) the heatmap
networks are trained and read with; running them on images is
:mod:`robopercept.nn.pose.inference`, training them :mod:`robopercept.nn.pose.train`.

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
  resamples it to ``patch x patch`` (bilinear, :func:`torch.nn.functional.grid_sample`,
  :func:`crop_patches`) and regresses that joint's displacement in units of the window.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_choice, check_int, check_real, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.nn._guards import MAX_LAYERS, check_allocation, check_count
from robopercept.nn.core.backbones import MAX_CHANNELS
from robopercept.nn.core.blocks import ConvBNAct, ResidualBlock
from robopercept.nn.ops.heatmaps import HEATMAP_LOSSES, check_float_tensor, check_image_size
from robopercept.nn.skeleton import Skeleton
from robopercept.nn.train.checkpoint import check_state_dict, load_built_model, save_built_model

__all__ = [
    "POSE_MODELS",
    "DeepPose",
    "DeepPoseRefiner",
    "HRNet",
    "SimpleBaseline",
    "build_pose_model",
    "crop_patches",
    "load_pose_model",
    "save_pose_model",
]

#: the network names of :func:`build_pose_model`
POSE_MODELS = ("deeppose", "heatmap", "hrnet")
#: the most joints a pose network predicts
_MAX_JOINTS = 1024


# ----------------------------------------------------------------------------- networks
def _head(channels: int, joints: int) -> nn.Conv2d:
    """The 1x1 heatmap layer, weights N(0, 0.001^2) and bias 0 (SimpleBaseline's init):
    the maps start flat instead of at a random scale."""
    head = nn.Conv2d(channels, joints, 1)
    nn.init.normal_(head.weight, std=0.001)
    nn.init.zeros_(head.bias)  # type: ignore[arg-type]
    return head


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
        What the maps are trained as
        (:func:`~robopercept.nn.ops.heatmaps.heatmap_loss`): the logits of a
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
        self.num_joints = check_count(num_joints, "num_joints", 1, _MAX_JOINTS)
        self.heatmap = check_choice(heatmap, "heatmap", HEATMAP_LOSSES)
        w = check_count(width, "width", 1, MAX_CHANNELS // 8)
        in_channels = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
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
        self.num_joints = check_count(num_joints, "num_joints", 1, _MAX_JOINTS)
        self.heatmap = check_choice(heatmap, "heatmap", HEATMAP_LOSSES)
        w = check_count(width, "width", 1, MAX_CHANNELS // 4)
        in_channels = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        nb = check_count(blocks, "blocks", 1, 64)
        if isinstance(modules, (str, bytes)) or not isinstance(modules, Sequence):
            raise InputError(
                f"modules must be two counts (stages 2 and 3), e.g. (1, 2); got "
                f"{plain_repr(modules)[:60]}"
            )
        if len(modules) != 2:
            raise InputError(
                f"modules must be two counts (stages 2 and 3); got {len(modules)} values"
            )
        mods = [check_count(m, "modules", 1, 64) for m in modules]
        total = nb * (1 + 2 * mods[0] + 3 * mods[1])  # residual blocks in all branches
        if total > MAX_LAYERS:
            raise InputError(
                f"blocks={nb} with modules={mods} makes {total} residual blocks; the limit "
                f"is {MAX_LAYERS}: lower blocks or modules"
            )
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
        self.num_joints = check_count(num_joints, "num_joints", 1, _MAX_JOINTS)
        self.image_size = check_image_size(image_size, 16)
        w = check_count(width, "width", 1, MAX_CHANNELS // 8)
        hidden = check_count(hidden, "hidden", 1, 1 << 16)
        in_channels = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        p = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
        cells = (self.image_size[0] // 16) * (self.image_size[1] // 16)
        check_allocation(
            2 * w * cells * hidden,
            4,
            f"the regressor's weights ({2 * w * cells} x {hidden})",
            "lower image_size, width or hidden",
        )
        self.encoder = nn.Sequential(
            ConvBNAct(in_channels, w, stride=2),
            ResidualBlock(w, w),
            ResidualBlock(w, 2 * w, stride=2),
            ResidualBlock(2 * w, 4 * w, stride=2),
            ResidualBlock(4 * w, 8 * w, stride=2),
            ConvBNAct(8 * w, 2 * w, 1),
        )
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
        self.num_joints = check_count(num_joints, "num_joints", 1, _MAX_JOINTS)
        self.crop = check_real(crop, "crop", 1.0, 1e5)
        self.patch = check_count(patch, "patch", 8, 1024)
        self.width = w = check_count(width, "width", 1, MAX_CHANNELS // 4)
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
        torch.manual_seed(check_count(seed, "seed", 0, 2**63 - 1))
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
    check_float_tensor(images, "images", 4, "(N, C, H, W)")
    check_float_tensor(centres, "centres", 3, "(N, K, 2) of (x, y)")
    n, _c, h, w = images.shape
    if h == 0 or w == 0:
        raise InputError(f"images must be at least 1 x 1 pixels; got shape {tuple(images.shape)}")
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
    values; the checkpoint format of :func:`~robopercept.nn.train.checkpoint.save_built_model`.
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
    check_choice(name, "name", POSE_MODELS)
    if not isinstance(skeleton, Skeleton):
        raise InputError(f"skeleton must be a Skeleton; got {plain_repr(skeleton)}")
    if isinstance(refiners, nn.Module) or not isinstance(refiners, (list, tuple)):
        raise InputError(
            f"refiners must be a list of DeepPoseRefiner stages; got {plain_repr(refiners)}"
        )
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
        Missing or unreadable file, a checkpoint that is not a pose network's, settings
        the network's class does not take or refuses, a damaged skeleton or cascade
        stage, or weights that do not fit (checked before loading:
        :func:`~robopercept.nn.train.checkpoint.load_built_model`).
    """
    model, info = load_built_model(
        path,
        POSE_MODELS,
        _build_from_joints,
        "pose network",
        "save_pose_model or `robopercept nn pose train`",
        constructors={"heatmap": SimpleBaseline, "hrnet": HRNet, "deeppose": DeepPose},
    )
    try:
        info["skeleton"] = Skeleton.from_dict(info.get("skeleton", {}))
    except (KeyError, IndexError, TypeError, ValueError, OverflowError, InputError) as exc:
        raise FileFormatError(
            f"{path}: a pose checkpoint without a valid skeleton ({str(exc)[:160]})"
        ) from None
    if info["skeleton"].num_joints != len(info["classes"]):
        raise FileFormatError(
            f"{path}: its skeleton has {info['skeleton'].num_joints} joints but the network "
            f"predicts {len(info['classes'])}: the file is damaged"
        )
    info["refiners"] = _load_refiners(info.get("refiners"), len(info["classes"]), str(path))
    return model, info


#: the most cascade stages a DeepPose checkpoint may hold
_MAX_STAGES = 16


def _load_refiners(stages: Any, n_joints: int, where: str) -> list[DeepPoseRefiner]:
    """The DeepPose cascade stages of a checkpoint (``[{"settings": ..., "state":
    ...}]``), each checked as the network is: settings ``crop``, ``patch``, ``width``
    only, built on the meta device first, the weights checked
    (:func:`~robopercept.nn.train.checkpoint.check_state_dict`) before loading."""
    if stages is None:
        return []
    if not isinstance(stages, list) or len(stages) > _MAX_STAGES:
        raise FileFormatError(
            f"{where}: its 'refiners' must be a list of at most {_MAX_STAGES} cascade stages; "
            f"got a {type(stages).__name__}"
            + (f" of {len(stages)}" if isinstance(stages, list) else "")
        )
    out = []
    for i, stage in enumerate(stages):
        settings = stage.get("settings") if isinstance(stage, dict) else None
        if (
            not isinstance(settings, dict)
            or not set(settings) <= {"crop", "patch", "width"}
            or "state" not in stage
        ):
            raise FileFormatError(
                f"{where}: refiners[{i}] must be {{'settings': {{'crop', 'patch', 'width'}}, "
                "'state': weights}: the file is damaged"
            )
        try:
            with torch.device("meta"):  # the shapes alone: nothing allocated yet
                probe = DeepPoseRefiner(n_joints, **settings)
        except InputError as exc:
            raise FileFormatError(f"{where}: refiners[{i}] has bad settings ({exc})") from None
        check_state_dict(probe, stage["state"], f"{where} (refiners[{i}])")
        r = DeepPoseRefiner(n_joints, **settings)
        try:
            r.load_state_dict(stage["state"])
        except RuntimeError as exc:  # checked above; what torch still refuses
            raise FileFormatError(f"{where}: refiners[{i}]: {str(exc)[:160]}") from None
        out.append(r.eval())
    return out
