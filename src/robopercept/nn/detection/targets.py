"""Training targets of the detectors: which candidates (anchors or proposals) are
foreground, background or ignored, and which of them a step trains on.

:func:`match_boxes` labels candidates by IoU thresholds with an ignored band and
low-quality matches (torchvision's ``Matcher``); :func:`sample_balanced` draws a fixed
number of examples with a cap on the positive fraction (torchvision's
``BalancedPositiveNegativeSampler``). The region proposal network
(:class:`~robopercept.nn.detection.rpn.RegionProposalNetwork`) and the region heads
(:class:`~robopercept.nn.detection.roi_heads.RoIHeads`) use both, with the box coder
:class:`~robopercept.nn.ops.anchors.BoxCoder` for the regression targets.

Determinism: sampling draws from torch's global generator, so a run seeded by
:func:`~robopercept.nn.detection.train.train_detector` (``TrainConfig.seed``) gives the
same samples.
"""

from __future__ import annotations

import torch

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.errors import InputError

__all__ = [
    "match_boxes",
    "sample_balanced",
]


def match_boxes(
    iou: torch.Tensor,
    fg_threshold: float,
    bg_threshold: float,
    bg_low: float = 0.0,
    allow_low_quality: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Label each candidate (anchor or proposal) from its IoU with the ground truth.

    With :math:`q_j = \max_i \mathrm{IoU}(g_i, c_j)`: label 1 (foreground) when
    :math:`q_j \ge` ``fg_threshold``, 0 (background) when ``bg_low`` :math:`\le q_j <`
    ``bg_threshold``, -1 (ignored) otherwise. With ``allow_low_quality``, every
    candidate whose IoU with some :math:`g_i` equals that box's best IoU
    :math:`\max_j \mathrm{IoU}(g_i, c_j) > 0` is foreground too (the Faster R-CNN RPN
    rule: every ground-truth box gets at least one anchor), matched to that
    :math:`g_i` (as torchvision's ``Matcher``). Without ground truth every candidate
    with ``bg_low == 0`` is background.

    Parameters
    ----------
    iou : (G, N) torch.Tensor
        IoU of G ground-truth boxes (rows) with N candidates.
    fg_threshold, bg_threshold : float
        In [0, 1], ``bg_threshold <= fg_threshold``.
    bg_low : float
        Lowest IoU of a background candidate (0.1 in Fast R-CNN).
    allow_low_quality : bool

    Returns
    -------
    labels : (N,) int64 torch.Tensor
        1, 0 or -1.
    matched : (N,) int64 torch.Tensor
        Index of the matched ground-truth box (0 where there is none).

    Examples
    --------
    >>> import torch
    >>> iou = torch.tensor([[0.9, 0.5, 0.2, 0.05]])
    >>> match_boxes(iou, 0.7, 0.3)[0].tolist()
    [1, -1, 0, 0]
    >>> match_boxes(torch.tensor([[0.6, 0.2]]), 0.7, 0.3, allow_low_quality=True)[0].tolist()
    [1, 0]
    """
    if not isinstance(iou, torch.Tensor) or iou.ndim != 2 or not iou.is_floating_point():
        raise InputError(
            "iou must be a (G, N) floating torch.Tensor (box_iou(gt, candidates)); got "
            + plain_repr(iou)
        )
    if iou.numel() and not bool(torch.isfinite(iou).all()):
        raise InputError("iou must be finite; got NaN or inf: check the boxes for NaN")
    fg = check_real(fg_threshold, "fg_threshold", 0.0, 1.0)
    bg = check_real(bg_threshold, "bg_threshold", 0.0, fg)
    lo = check_real(bg_low, "bg_low", 0.0, bg)
    low_q = check_bool(allow_low_quality, "allow_low_quality")
    n = iou.shape[1]
    if iou.shape[0] == 0:
        labels = torch.full((n,), 0 if lo <= 0.0 else -1, dtype=torch.int64, device=iou.device)
        return labels, torch.zeros(n, dtype=torch.int64, device=iou.device)
    q, matched = iou.max(dim=0)
    labels = torch.full((n,), -1, dtype=torch.int64, device=iou.device)
    labels[(q >= lo) & (q < bg)] = 0
    labels[q >= fg] = 1
    if low_q and n:
        best = iou.max(dim=1).values
        g_idx, c_idx = torch.nonzero((iou == best[:, None]) & (best[:, None] > 0), as_tuple=True)
        labels[c_idx] = 1
        matched[c_idx] = g_idx
    return labels, matched


def sample_balanced(
    labels: torch.Tensor, batch_size: int, positive_fraction: float
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Sample at most ``batch_size`` candidates with at most a ``positive_fraction`` of
    positives: :math:`n_+ = \min(\#\{l = 1\}, \lfloor b f \rfloor)`,
    :math:`n_- = \min(\#\{l = 0\}, b - n_+)`, each drawn uniformly without replacement
    (torch's global generator: seed it with :func:`torch.manual_seed`); ignored (-1)
    candidates are never drawn. torchvision's ``BalancedPositiveNegativeSampler``.

    Parameters
    ----------
    labels : (N,) int torch.Tensor
        1 positive, 0 negative, -1 ignored.
    batch_size : int
        >= 1 (256 anchors in the RPN, 512 or 128 regions in the head).
    positive_fraction : float
        In [0, 1] (0.5 in the RPN, 0.25 in the head).

    Returns
    -------
    positive, negative : (N,) bool torch.Tensor
        The sampled candidates.

    Examples
    --------
    >>> import torch
    >>> _ = torch.manual_seed(0)
    >>> pos, neg = sample_balanced(torch.tensor([1, 1, 1, 0, 0, 0, 0, -1]), 4, 0.25)
    >>> int(pos.sum()), int(neg.sum()), bool(pos[7] or neg[7])
    (1, 3, False)
    """
    if (
        not isinstance(labels, torch.Tensor)
        or labels.ndim != 1
        or labels.is_floating_point()
        or labels.is_complex()
    ):
        raise InputError(
            "labels must be a (N,) integer torch.Tensor of 1 / 0 / -1; got " + plain_repr(labels)
        )
    b = check_int(batch_size, "batch_size", 1)
    f = check_real(positive_fraction, "positive_fraction", 0.0, 1.0)
    pos_idx = torch.nonzero(labels == 1).flatten()
    neg_idx = torch.nonzero(labels == 0).flatten()
    n_pos = min(pos_idx.numel(), int(b * f))
    n_neg = min(neg_idx.numel(), b - n_pos)
    pos_pick = pos_idx[torch.randperm(pos_idx.numel())[:n_pos].to(labels.device)]
    neg_pick = neg_idx[torch.randperm(neg_idx.numel())[:n_neg].to(labels.device)]
    pos = torch.zeros_like(labels, dtype=torch.bool)
    neg = torch.zeros_like(labels, dtype=torch.bool)
    pos[pos_pick] = True
    neg[neg_pick] = True
    return pos, neg
