r"""Keypoint R-CNN (He et al. 2017, section 5):
:class:`~robopercept.nn.detection.faster_rcnn.FasterRCNN` with a keypoint branch
(:class:`KeypointHead`) plugged into its RoI heads beside the box head, each keypoint a
one-hot mask over the region's :math:`M \times M` grid (``loss_keypoint``, the cross
entropy of the softmax over the cells), decoded at inference by
:func:`~robopercept.nn.ops.heatmaps.decode_heatmaps`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import MAX_CHANNELS
from robopercept.nn.detection.faster_rcnn import FasterRCNN
from robopercept.nn.ops.heatmaps import decode_heatmaps
from robopercept.nn.ops.roi import roi_align

__all__ = [
    "KeypointHead",
    "KeypointRCNN",
]


def _check_keypoints_target(t: Mapping[str, Any], i: int, j: int) -> torch.Tensor:
    kp = t.get("keypoints")
    k = int(t["boxes"].shape[0])
    if kp is None:
        raise InputError(
            f"targets[{i}] has no 'keypoints': Keypoint R-CNN trains on a (K, J, 3) float "
            "tensor of (x, y, v) per box (e.g. procedural_pose_scenes')"
        )
    if not isinstance(kp, torch.Tensor) or tuple(kp.shape) != (k, j, 3):
        raise InputError(
            f"targets[{i}]['keypoints'] must be ({k}, {j}, 3): {j} keypoints (x, y, v) per "
            f"box; got {plain_repr(kp)}"
        )
    return kp


class KeypointHead(nn.Module):
    r"""The keypoint branch of Keypoint R-CNN, a part of
    :class:`~robopercept.nn.detection.roi_heads.RoIHeads` (its ``keypoint_head``).

    Each region is pooled with RoI Align (``aligned=True``) to ``keypoint_pool_size``
    cells of the features, then ``keypoint_convs`` 3 x 3 convolutions of
    ``keypoint_channels`` with ReLU and a 4 x 4 stride-2 transposed convolution give
    :math:`J` logit maps of side :math:`M = 2\,` ``keypoint_pool_size``
    (torchvision's ``KeypointRCNNHeads`` + ``KeypointRCNNPredictor``, with fewer
    channels and without the final 2x bilinear upsampling). Convolutions are
    initialized He-normal (``fan_out``) with zero bias.

    Each keypoint is a *one-hot mask* (:meth:`keypoint_targets`): its target is the
    single cell of the :math:`M \times M` grid over the region that contains it,
    :math:`(\lfloor (x - x_1) M / w \rfloor, \lfloor (y - y_1) M / h \rfloor)` (as
    torchvision's ``keypoints_to_heatmap``), and ``loss_keypoint`` (:meth:`losses`) is
    the cross entropy of the softmax over the :math:`M^2` cells, averaged over the
    labelled keypoints (``v > 0``) that fall inside their sampled foreground region (0
    when there are none).

    At inference (:meth:`outputs`) each final box's maps go through a softmax over the
    cells and are decoded by :func:`~robopercept.nn.ops.heatmaps.decode_heatmaps` (the
    argmax cell refined by the parabola through the log-probabilities), mapped back
    into the box: :math:`x = x_1 + \hat u\, w / M` with :math:`\hat u` the decoded
    position in cell units (cell centres at :math:`j + \tfrac12`).

    Parameters
    ----------
    in_channels : int
        Channels of the features.
    num_keypoints : int
        :math:`J`.
    keypoint_pool_size : int
        RoI Align side (14: 28 x 28 maps).
    keypoint_channels, keypoint_convs : int
        Width and depth (torchvision: 512 and 8).
    spatial_scale : float
        Features per image pixel (1/8 on a stride-8 map).

    Examples
    --------
    >>> import torch
    >>> head = KeypointHead(8, num_keypoints=3, keypoint_pool_size=4, keypoint_convs=1)
    >>> head.keypoint_logits(torch.rand(1, 8, 8, 8), [torch.tensor([[0.0, 0, 32, 32]])]).shape
    torch.Size([1, 3, 8, 8])
    """

    def __init__(
        self,
        in_channels: int,
        *,
        num_keypoints: int = 16,
        keypoint_pool_size: int = 14,
        keypoint_channels: int = 64,
        keypoint_convs: int = 4,
        spatial_scale: float = 0.125,
    ) -> None:
        super().__init__()
        c = check_count(in_channels, "in_channels", 1, MAX_CHANNELS)
        self.num_keypoints = check_count(num_keypoints, "num_keypoints", 1, 1024)
        self.keypoint_pool_size = check_count(keypoint_pool_size, "keypoint_pool_size", 1, 64)
        self.keypoint_resolution = 2 * self.keypoint_pool_size
        channels = check_count(keypoint_channels, "keypoint_channels", 1, MAX_CHANNELS)
        convs = check_count(keypoint_convs, "keypoint_convs", 0, 16)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )
        layers: list[nn.Module] = []
        for _ in range(convs):
            layers += [nn.Conv2d(c, channels, 3, padding=1), nn.ReLU()]
            c = channels
        self.convs = nn.Sequential(*layers)
        self.logits = nn.ConvTranspose2d(c, self.num_keypoints, 4, stride=2, padding=1)
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d)):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
                nn.init.zeros_(m.bias)  # type: ignore[arg-type]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(R, J, M, M)`` keypoint logits of pooled regions ``(R, in_channels, P, P)``."""
        return self.logits(self.convs(x))

    def keypoint_logits(self, features: torch.Tensor, rois: list[torch.Tensor]) -> torch.Tensor:
        """``(R, J, M, M)`` keypoint logits of the regions ``rois`` (one list entry per
        image, ``xyxy`` pixels) on ``features``."""
        pooled = roi_align(
            features,
            rois,
            self.keypoint_pool_size,
            self.spatial_scale,
            sampling_ratio=2,
            aligned=True,
        )
        return self(pooled)

    def keypoint_targets(
        self, rois: torch.Tensor, keypoints: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The one-hot targets of keypoints ``(R, J, 3)`` in regions ``rois`` ``(R, 4)``:
        the flat cell index ``(R, J)`` (row ``M + column``) and whether it counts
        (labelled and inside the region)."""
        m = self.keypoint_resolution
        x1, y1 = rois[:, 0:1], rois[:, 1:2]
        w = (rois[:, 2:3] - x1).clamp_min(1e-6)
        h = (rois[:, 3:4] - y1).clamp_min(1e-6)
        cx = torch.floor((keypoints[..., 0] - x1) * m / w)
        cy = torch.floor((keypoints[..., 1] - y1) * m / h)
        valid = (keypoints[..., 2] > 0) & (cx >= 0) & (cx < m) & (cy >= 0) & (cy < m)
        index = (cy.clamp(0, m - 1) * m + cx.clamp(0, m - 1)).long()
        return index, valid

    def losses(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        targets: Sequence[Mapping[str, torch.Tensor]],
        rois: list[torch.Tensor],
        labels: list[torch.Tensor],
        matched: list[torch.Tensor],
    ) -> dict[str, torch.Tensor]:
        """``{"loss_keypoint": ...}`` on the sampled foreground regions (the class
        docstring); ``targets`` carry ``"keypoints"`` ``(K, J, 3)`` per image.

        Raises
        ------
        InputError
            A target without ``"keypoints"`` or with keypoints not ``(K, J, 3)``.
        """
        gt = [_check_keypoints_target(t, i, self.num_keypoints) for i, t in enumerate(targets)]
        fg = [lab > 0 for lab in labels]
        idx, val = [], []
        for r, f, g, mt in zip(rois, fg, gt, matched, strict=True):
            i, v = self.keypoint_targets(r[f], g.to(r.dtype)[mt[f]])
            idx.append(i)
            val.append(v)
        index, valid = torch.cat(idx), torch.cat(val)
        if not bool(valid.any()):
            zero = torch.stack([p.sum() for p in self.parameters()]).sum() * 0.0
            return {"loss_keypoint": zero}
        z = self.keypoint_logits(features, [r[f] for r, f in zip(rois, fg, strict=True)])
        z = z.flatten(2)  # (R, J, M^2)
        return {"loss_keypoint": F.cross_entropy(z[valid], index[valid])}

    def outputs(
        self,
        features: torch.Tensor,
        sizes: list[tuple[int, int]],
        detections: list[dict[str, torch.Tensor]],
    ) -> list[dict[str, torch.Tensor]]:
        """``detections`` with ``"keypoints"`` ``(D, J, 3)`` rows ``(x, y, 1)`` and
        ``"keypoints_scores"`` ``(D, J)``, the peak softmax probability."""
        j, m = self.num_keypoints, self.keypoint_resolution
        boxes = [d["boxes"] for d in detections]
        if not sum(b.shape[0] for b in boxes):
            for d in detections:
                d["keypoints"] = features.new_zeros((0, j, 3))
                d["keypoints_scores"] = features.new_zeros((0, j))
            return detections
        z = self.keypoint_logits(features, boxes)
        probs = torch.softmax(z.flatten(2), -1).reshape(z.shape)
        cells, score = decode_heatmaps(probs.detach(), 1, "quadratic")
        cells_t = torch.as_tensor(cells, dtype=features.dtype, device=features.device)
        score_t = torch.as_tensor(score, dtype=features.dtype, device=features.device)
        start = 0
        for d in detections:
            b = d["boxes"].detach()
            k = b.shape[0]
            c = cells_t[start : start + k]
            w = (b[:, 2] - b[:, 0])[:, None]
            h = (b[:, 3] - b[:, 1])[:, None]
            x = b[:, 0:1] + c[..., 0] * w / m
            y = b[:, 1:2] + c[..., 1] * h / m
            d["keypoints"] = torch.stack([x, y, torch.ones_like(x)], -1)
            d["keypoints_scores"] = score_t[start : start + k]
            start += k
        return detections


class KeypointRCNN(FasterRCNN):
    r"""Keypoint R-CNN (He et al. 2017, section 5): :class:`FasterRCNN` whose RoI heads
    carry a keypoint branch (:class:`KeypointHead`) beside the box head, for several
    people per image.

    The branch pools each region with RoI Align (``aligned=True``) to
    ``keypoint_pool_size`` cells of the stride-8 features, runs ``keypoint_convs``
    3 x 3 convolutions of ``keypoint_channels`` and a 4 x 4 stride-2 transposed
    convolution to :math:`J` logit maps of side :math:`M = 2\,` ``keypoint_pool_size``.
    Each keypoint is a *one-hot mask*: its target is the single cell of the
    :math:`M \times M` grid over the region that contains it,
    :math:`(\lfloor (x - x_1) M / w \rfloor, \lfloor (y - y_1) M / h \rfloor)` (as
    torchvision's ``keypoints_to_heatmap``), and ``loss_keypoint`` is the cross
    entropy of the softmax over the :math:`M^2` cells, averaged over the labelled
    keypoints (``v > 0``) that fall inside their sampled foreground region (0 when
    there are none).

    At inference each final box's maps go through a softmax over the cells and are
    decoded by :func:`~robopercept.nn.ops.heatmaps.decode_heatmaps` (the argmax cell refined by
    the parabola through the log-probabilities), mapped back into the box:
    :math:`x = x_1 + \hat u\, w / M` with :math:`\hat u` the decoded position in cell
    units (cell centres at :math:`j + \tfrac12`).

    Parameters
    ----------
    num_classes : int
    num_keypoints : int
    keypoint_pool_size : int
        RoI Align side (14: 28 x 28 maps).
    keypoint_channels, keypoint_convs : int
        Width and depth of the branch (torchvision: 512 and 8).
    **settings
        Those of :class:`FasterRCNN`.

    Returns (eval mode)
    -------------------
    Per image ``{"boxes", "labels", "scores", "keypoints", "keypoints_scores"}``:
    ``"keypoints"`` ``(D, J, 3)`` rows ``(x, y, 1)`` (torchvision's layout),
    ``"keypoints_scores"`` ``(D, J)`` the peak softmax probability.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = KeypointRCNN(1, num_keypoints=2, width=8, hidden=32, keypoint_channels=8,
    ...                  keypoint_convs=1)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1]),
    ...       "keypoints": torch.tensor([[[8.0, 9, 2], [15, 20, 2]]])}]
    >>> "loss_keypoint" in m([torch.rand(3, 32, 32)], t)
    True
    """

    def __init__(
        self,
        num_classes: int,
        *,
        num_keypoints: int = 16,
        keypoint_pool_size: int = 14,
        keypoint_channels: int = 64,
        keypoint_convs: int = 4,
        **settings: Any,
    ) -> None:
        if "mask_head" in settings or "keypoint_head" in settings:
            raise InputError(
                "KeypointRCNN builds its own keypoint_head; give its keypoint_* settings"
            )

        def keypoint_head(in_channels: int, spatial_scale: float) -> KeypointHead:
            return KeypointHead(
                in_channels,
                num_keypoints=num_keypoints,
                keypoint_pool_size=keypoint_pool_size,
                keypoint_channels=keypoint_channels,
                keypoint_convs=keypoint_convs,
                spatial_scale=spatial_scale,
            )

        super().__init__(num_classes, keypoint_head=keypoint_head, **settings)
