r"""FCOS (Tian et al. 2019), the single-stage detector. **Why FCOS** rather than an
anchor-based RetinaNet: it has no anchor sizes or ratios to tune (each feature-map
location inside a ground-truth box's centre region regresses its distances to the four
sides), which suits small objects of varying shape such as the tree crowns of
:func:`~robopercept.nn.detection.deepforest.deepforest_tiles`, and it is the single-stage
detector of the notes. Per location: classification with the sigmoid focal loss
(:func:`~robopercept.nn.ops.losses.sigmoid_focal_loss`), ``ltrb`` regression (divided by
the level's stride) with the GIoU loss, and centerness with binary cross-entropy;
losses ``classification``, ``bbox_regression``, ``bbox_ctrness`` (torchvision's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from robopercept._checks import check_bool, check_choice, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count
from robopercept.nn.core.backbones import MAX_CHANNELS, DetectionBackbone
from robopercept.nn.detection.base import Detector, clip_boxes, init_conv
from robopercept.nn.ops.boxes import box_iou, generalized_box_iou
from robopercept.nn.ops.losses import sigmoid_focal_loss
from robopercept.nn.ops.nms import batched_nms

__all__ = [
    "FCOS",
]


class FCOS(Detector):
    r"""FCOS (Tian et al. 2019): anchor-free single-stage detection on an FPN (strides 8
    and 16 by default).

    A location :math:`(x, y) = ((j + \tfrac12) s, (i + \tfrac12) s)` of a level of
    stride :math:`s` is assigned to a ground-truth box when it lies inside the box and
    within ``center_radius`` :math:`\cdot s` of its centre (centre sampling), and when
    :math:`m = \max(l, t, r, b)` of its distances to the sides is in the level's range
    :math:`[4 s, 8 s]` (0 below the first level, no upper bound on the last); among
    several boxes, the one of smallest area (torchvision's FCOS rules). Per location
    the head predicts class logits (sigmoid focal loss, summed over all locations and
    divided by the number of foreground ones), :math:`(l, t, r, b) / s` through a ReLU
    (torchvision's) or the paper's :math:`\exp(s_l x)` with a learnable scale
    :math:`s_l` per level (``box_activation``; GIoU loss of the decoded box, foreground
    only) and a centerness logit with target
    :math:`\sqrt{\frac{\min(l, r)}{\max(l, r)} \frac{\min(t, b)}{\max(t, b)}}`
    (binary cross-entropy, foreground only). Eval: score
    :math:`\sqrt{\sigma(c) \sigma(o)}`, threshold, top ``topk_candidates`` per level,
    clip, per-class NMS, the ``detections_per_img`` best.

    Parameters
    ----------
    num_classes : int
    width : int
        Backbone width.
    strides : sequence of int
        FPN levels.
    head_channels : int
        FPN and head width.
    blocks : int
        Residual blocks per backbone stage (:class:`DetectionBackbone`).
    num_convs : int
        3 x 3 convolution + GroupNorm + ReLU layers in each of the two towers (class
        and box) before their outputs: 2 here by default, 4 in torchvision's
        ``FCOSHead`` and the paper.
    center_radius : float
    box_activation : {"relu", "exp"}
        ``"relu"`` (the default, torchvision's) can die: once every pre-activation of
        the box branch is negative, every box has zero size and no gradient flows back
        (seen with flips and quarter turns on the shapes set). ``"exp"`` cannot (its
        gradient is never zero) and starts every side at one stride.
    centerness_weighted : bool
        Weight each foreground location's GIoU loss by its centerness target and
        divide by their sum (FCOS v2, Tian et al. 2020), instead of the plain mean:
        the box is learnt best where the score (which includes the centerness) makes
        it survive NMS.
    quality : {"centerness", "iou"}
        The target of the third branch: the centerness above (the paper's), or the IoU
        of the location's decoded box with its ground-truth box, detached (the IoU
        prediction of IoU-aware detectors, Wu et al. 2020, and of YOLOX's objectness):
        the score then ranks boxes by how well they are placed, not by where the
        location sits in the box. Eval is the same for both.
    score_thresh, nms_thresh, topk_candidates, detections_per_img
        Post-processing.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> m = FCOS(2, width=8, head_channels=16)
    >>> t = [{"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1])}]
    >>> sorted(m([torch.rand(3, 32, 32)], t))
    ['bbox_ctrness', 'bbox_regression', 'classification']
    """

    def __init__(
        self,
        num_classes: int,
        *,
        width: int = 16,
        strides: Sequence[int] = (8, 16),
        head_channels: int = 64,
        blocks: int = 1,
        num_convs: int = 2,
        center_radius: float = 1.5,
        box_activation: str = "relu",
        centerness_weighted: bool = False,
        quality: str = "centerness",
        score_thresh: float = 0.2,
        nms_thresh: float = 0.6,
        topk_candidates: int = 1000,
        detections_per_img: int = 100,
    ) -> None:
        super().__init__()
        head_channels = check_count(head_channels, "head_channels", 2, MAX_CHANNELS)
        self.backbone = DetectionBackbone(width, strides, fpn_channels=head_channels, blocks=blocks)
        self._init_common(num_classes, max(self.backbone.strides))
        c = head_channels
        # GroupNorm with 8 groups (fewer where the channels do not divide), each of at
        # least 2 channels: a group of one channel on a 1 x 1 map (a tiny image at the
        # coarsest stride) has one value and no variance, and torch refuses it
        groups = math.gcd(c, 8)
        while groups > 1 and c // groups < 2:
            groups //= 2

        self.num_convs = check_count(num_convs, "num_convs", 1, 16)

        def tower() -> nn.Sequential:
            layers: list[nn.Module] = []
            for _ in range(self.num_convs):
                layers += [nn.Conv2d(c, c, 3, padding=1), nn.GroupNorm(groups, c), nn.ReLU()]
            return nn.Sequential(*layers)

        self.cls_tower = tower()
        self.reg_tower = tower()
        self.cls_logits = nn.Conv2d(c, self.num_classes, 3, padding=1)
        self.bbox_reg = nn.Conv2d(c, 4, 3, padding=1)
        self.bbox_ctrness = nn.Conv2d(c, 1, 3, padding=1)
        for layer in (self.bbox_reg, self.bbox_ctrness):
            init_conv(layer, 0.0)
        # the prior: every location starts at foreground probability 0.01 (RetinaNet)
        init_conv(self.cls_logits, -math.log((1 - 0.01) / 0.01))
        self.center_radius = check_real(center_radius, "center_radius", 0.0, low_inclusive=False)
        if box_activation not in ("relu", "exp"):
            raise InputError(
                f"box_activation must be 'relu' or 'exp'; got {plain_repr(box_activation)}"
            )
        self.box_activation = box_activation
        self.centerness_weighted = check_bool(centerness_weighted, "centerness_weighted")
        check_choice(quality, "quality", ("centerness", "iou"))
        self.quality = quality
        if box_activation == "exp":
            # the paper's exp(s_l x): one learnable scale per level, starting at 1
            self.scales = nn.Parameter(torch.ones(len(self.backbone.strides)))
        self.score_thresh = check_real(score_thresh, "score_thresh", 0.0, 1.0)
        self.nms_thresh = check_real(nms_thresh, "nms_thresh", 0.0, 1.0)
        self.topk_candidates = check_count(topk_candidates, "topk_candidates", 1, 1 << 20)
        self.detections_per_img = check_count(detections_per_img, "detections_per_img", 1, 1 << 20)

    def head(
        self, feats: list[torch.Tensor]
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, list[int]]:
        """Per location of all levels (concatenated): class logits ``(N, L, C)``, ltrb /
        stride ``(N, L, 4)``, centerness logits ``(N, L)``, the locations ``(L, 2)``,
        their strides ``(L,)`` and the number of locations per level."""
        cls, reg, ctr, locs, strides, counts = [], [], [], [], [], []
        for level, (f, s) in enumerate(zip(feats, self.backbone.strides, strict=True)):
            n, _, fh, fw = f.shape
            ct, rt = self.cls_tower(f), self.reg_tower(f)
            cls.append(self.cls_logits(ct).permute(0, 2, 3, 1).reshape(n, -1, self.num_classes))
            r = self.bbox_reg(rt)
            if self.box_activation == "exp":
                # clamped so that exp cannot overflow: ltrb <= e^8 strides
                r = torch.exp((self.scales[level] * r).clamp(max=8.0))
            else:
                r = F.relu(r)
            reg.append(r.permute(0, 2, 3, 1).reshape(n, -1, 4))
            ctr.append(self.bbox_ctrness(rt).reshape(n, -1))
            ys = (torch.arange(fh, device=f.device, dtype=f.dtype) + 0.5) * s
            xs = (torch.arange(fw, device=f.device, dtype=f.dtype) + 0.5) * s
            yy, xx = torch.meshgrid(ys, xs, indexing="ij")
            locs.append(torch.stack((xx, yy), dim=-1).reshape(-1, 2))
            strides.append(torch.full((fh * fw,), float(s), device=f.device, dtype=f.dtype))
            counts.append(fh * fw)
        return (
            torch.cat(cls, 1),
            torch.cat(reg, 1),
            torch.cat(ctr, 1),
            torch.cat(locs),
            torch.cat(strides),
            counts,
        )

    def assign(
        self, locs: torch.Tensor, strides: torch.Tensor, counts: list[int], gt: torch.Tensor
    ) -> torch.Tensor:
        """Index of the ground-truth box of each location, -1 for background."""
        n = locs.shape[0]
        if gt.shape[0] == 0:
            return torch.full((n,), -1, dtype=torch.int64, device=locs.device)
        x, y = locs[:, 0, None], locs[:, 1, None]
        ltrb = torch.stack((x - gt[:, 0], y - gt[:, 1], gt[:, 2] - x, gt[:, 3] - y), dim=-1)
        inside = ltrb.min(dim=-1).values > 0
        cx, cy = (gt[:, 0] + gt[:, 2]) / 2, (gt[:, 1] + gt[:, 3]) / 2
        r = self.center_radius * strides[:, None]
        center = ((x - cx).abs() < r) & ((y - cy).abs() < r)
        m = ltrb.max(dim=-1).values
        lower = strides * 4
        upper = strides * 8
        lower[: counts[0]] = 0
        upper[n - counts[-1] :] = math.inf
        ok = inside & center & (m >= lower[:, None]) & (m <= upper[:, None])
        area = ((gt[:, 2] - gt[:, 0]) * (gt[:, 3] - gt[:, 1]))[None].expand(n, -1)
        area = torch.where(ok, area, torch.full_like(area, math.inf))
        best, idx = area.min(dim=1)
        idx[torch.isinf(best)] = -1
        return idx

    def forward(
        self, images: Any, targets: Any = None
    ) -> dict[str, torch.Tensor] | list[dict[str, torch.Tensor]]:
        """Losses (train mode) or detections (eval mode) of ``images``.

        Parameters
        ----------
        images : list of (3, H, W) float torch.Tensor, or (N, 3, H, W)
            RGB in [0, 1]; sizes may differ.
        targets : list of dict, optional
            ``"boxes"`` (K, 4) float ``"xyxy"`` and ``"labels"`` (K,) int64 in
            1..num_classes; required in train mode.

        Returns
        -------
        dict of str to scalar torch.Tensor (train) or list of dict (eval)
            The losses, or ``{"boxes": (D, 4), "labels": (D,), "scores": (D,)}`` per image.

        Raises
        ------
        InputError
            Images not (3, H, W) floating point and finite; missing targets in train
            mode; boxes not (K, 4) float, with NaN or of zero width or height; labels not
            int64 or out of range.
        """
        batch, sizes, tgts = self._prepare(images, targets)
        feats = self.backbone(batch)
        cls, reg, ctr, locs, strides, counts = self.head(feats)
        if self.training:
            assert tgts is not None
            return self._losses(cls, reg, ctr, locs, strides, counts, tgts)
        return self._postprocess(cls, reg, ctr, locs, strides, counts, sizes)

    def _decode(self, reg: torch.Tensor, locs: torch.Tensor, strides: torch.Tensor) -> torch.Tensor:
        d = reg * strides[:, None]
        return torch.stack(
            (
                locs[:, 0] - d[:, 0],
                locs[:, 1] - d[:, 1],
                locs[:, 0] + d[:, 2],
                locs[:, 1] + d[:, 3],
            ),
            dim=1,
        )

    def _losses(
        self,
        cls: torch.Tensor,
        reg: torch.Tensor,
        ctr: torch.Tensor,
        locs: torch.Tensor,
        strides: torch.Tensor,
        counts: list[int],
        tgts: list[dict[str, torch.Tensor]],
    ) -> dict[str, torch.Tensor]:
        cls_t = torch.zeros_like(cls)
        fg_pred, fg_gt, fg_ctr, fg_ctr_t = [], [], [], []
        for i, t in enumerate(tgts):
            gt = t["boxes"].to(locs.dtype)
            idx = self.assign(locs, strides, counts, gt)
            fg = idx >= 0
            if not bool(fg.any()):
                continue
            g = gt[idx[fg]]
            cls_t[i, fg, t["labels"][idx[fg]] - 1] = 1.0
            fg_pred.append(self._decode(reg[i][fg], locs[fg], strides[fg]))
            fg_gt.append(g)
            lo = locs[fg]
            l_, t_ = lo[:, 0] - g[:, 0], lo[:, 1] - g[:, 1]
            r_, b_ = g[:, 2] - lo[:, 0], g[:, 3] - lo[:, 1]
            ctr_t = torch.sqrt(
                (torch.minimum(l_, r_) / torch.maximum(l_, r_))
                * (torch.minimum(t_, b_) / torch.maximum(t_, b_))
            )
            fg_ctr.append(ctr[i][fg])
            fg_ctr_t.append(ctr_t)
        n_fg = max(1, sum(p.shape[0] for p in fg_pred))
        loss_cls = sigmoid_focal_loss(cls, cls_t, reduction="sum") / n_fg
        if fg_pred:
            pred, gtb = torch.cat(fg_pred), torch.cat(fg_gt)
            giou = torch.diagonal(generalized_box_iou(pred, gtb)) if pred.shape[0] else pred.sum(1)
            centerness = torch.cat(fg_ctr_t)
            if self.centerness_weighted:
                w = centerness
                loss_reg = ((1 - giou) * w).sum() / w.sum().clamp(min=1e-6)
            else:
                loss_reg = (1 - giou).sum() / n_fg
            if self.quality == "iou":
                target = torch.diagonal(box_iou(pred.detach(), gtb))
            else:
                target = centerness
            loss_ctr = (
                F.binary_cross_entropy_with_logits(torch.cat(fg_ctr), target, reduction="sum")
                / n_fg
            )
        else:
            loss_reg = reg.sum() * 0.0
            loss_ctr = ctr.sum() * 0.0
        return {"classification": loss_cls, "bbox_regression": loss_reg, "bbox_ctrness": loss_ctr}

    def _postprocess(
        self,
        cls: torch.Tensor,
        reg: torch.Tensor,
        ctr: torch.Tensor,
        locs: torch.Tensor,
        strides: torch.Tensor,
        counts: list[int],
        sizes: list[tuple[int, int]],
    ) -> list[dict[str, torch.Tensor]]:
        out = []
        c = self.num_classes
        for i, size in enumerate(sizes):
            scores_all = torch.sqrt(torch.sigmoid(cls[i]) * torch.sigmoid(ctr[i])[:, None])
            boxes_l, scores_l, labels_l = [], [], []
            start = 0
            for n in counts:
                sc = scores_all[start : start + n].reshape(-1)
                keep = torch.nonzero(sc > self.score_thresh).flatten()
                sc = sc[keep]
                if sc.numel() > self.topk_candidates:
                    sc, top = sc.topk(self.topk_candidates)
                    keep = keep[top]
                loc_idx = keep // c + start
                boxes_l.append(self._decode(reg[i][loc_idx], locs[loc_idx], strides[loc_idx]))
                scores_l.append(sc)
                labels_l.append(keep % c + 1)
                start += n
            boxes = clip_boxes(torch.cat(boxes_l), size)
            scores, labels = torch.cat(scores_l), torch.cat(labels_l)
            ok = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
            boxes, scores, labels = boxes[ok], scores[ok], labels[ok]
            kept = batched_nms(boxes.detach(), scores.detach(), labels, self.nms_thresh)
            kept = kept[: self.detections_per_img]
            out.append({"boxes": boxes[kept], "labels": labels[kept], "scores": scores[kept]})
        return out
