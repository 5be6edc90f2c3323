"""Losses of the detection family: the sigmoid focal loss of RetinaNet (Lin et al.
2017), which the FCOS classification branch trains with
(:class:`~robopercept.nn.detection.fcos.FCOS`).
"""

from __future__ import annotations

import torch
from torch.nn import functional as F

from robopercept._checks import check_real, plain_repr
from robopercept.errors import InputError

__all__ = [
    "sigmoid_focal_loss",
]


def sigmoid_focal_loss(
    inputs: torch.Tensor,
    targets: torch.Tensor,
    alpha: float = 0.25,
    gamma: float = 2.0,
    reduction: str = "none",
) -> torch.Tensor:
    r"""Focal loss (Lin et al. 2017, RetinaNet) on logits, per element:

    .. math::
        p_t = p y + (1 - p)(1 - y),\quad
        \mathrm{FL} = -\alpha_t (1 - p_t)^\gamma \log p_t,\quad
        \alpha_t = \alpha y + (1 - \alpha)(1 - y)

    with :math:`p = \sigma(x)` (no :math:`\alpha_t` when ``alpha < 0``), the BCE term
    computed stably from the logits. Matches torchvision's ``ops.sigmoid_focal_loss``.

    Parameters
    ----------
    inputs : torch.Tensor
        Logits, any shape.
    targets : torch.Tensor
        Same shape, in [0, 1].
    alpha : float
        In [0, 1], or negative for no weighting.
    gamma : float
        >= 0; 0 gives (alpha-weighted) binary cross-entropy.
    reduction : {"none", "mean", "sum"}

    Returns
    -------
    torch.Tensor

    Examples
    --------
    >>> import torch
    >>> round(float(sigmoid_focal_loss(torch.tensor([0.0]), torch.tensor([1.0]))), 6)
    0.043322
    """
    if not isinstance(inputs, torch.Tensor) or not inputs.is_floating_point():
        raise InputError(
            f"inputs must be a floating torch.Tensor of logits; got {plain_repr(inputs)}"
        )
    if not isinstance(targets, torch.Tensor) or targets.shape != inputs.shape:
        raise InputError(
            f"targets must be a torch.Tensor of the shape of inputs {tuple(inputs.shape)}; got "
            + plain_repr(targets)
        )
    a = check_real(alpha, "alpha", None, 1.0)
    g = check_real(gamma, "gamma", 0.0, 1e3)
    if reduction not in ("none", "mean", "sum"):
        raise InputError(f"reduction must be 'none', 'mean' or 'sum'; got {plain_repr(reduction)}")
    t = targets.to(inputs.dtype)
    p = torch.sigmoid(inputs)
    ce = F.binary_cross_entropy_with_logits(inputs, t, reduction="none")
    p_t = p * t + (1 - p) * (1 - t)
    loss = ce * (1 - p_t) ** g
    if a >= 0:
        loss = (a * t + (1 - a) * (1 - t)) * loss
    if reduction == "mean":
        return loss.mean()
    if reduction == "sum":
        return loss.sum()
    return loss
