r"""Greedy non-maximum suppression of torch boxes: :func:`nms`, per class
:func:`batched_nms`, and :func:`non_max_suppression` with onnxruntime's score threshold
and cap.

The rule (ranking by decreasing score, ties by index; a box whose IoU with a kept box
exceeds the threshold, strictly, is dropped) and the loop itself are
:mod:`robopercept.geometry.boxes`' (:func:`~robopercept.geometry.boxes.greedy_suppression`,
compiled, with its NumPy reference): the checked ``"xyxy"`` tensors are ranked in torch,
go to NumPy in float64, and the kept indices come back as a tensor on the boxes'
device. Results equal onnxruntime's ``NonMaxSuppression`` (tested) and torchvision's
``ops.nms``, on any number of threads.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from robopercept._checks import check_int, check_real
from robopercept.errors import InputError
from robopercept.geometry.boxes import corners_and_areas, greedy_suppression
from robopercept.nn.ops.boxes import check_boxes, numpy_view

__all__ = ["batched_nms", "nms", "non_max_suppression"]


# --------------------------------------------------------------------------- guards
def _check_scores(scores: Any, n: int, name: str = "scores") -> torch.Tensor:
    if not isinstance(scores, torch.Tensor):
        raise InputError(
            f"{name} must be a torch.Tensor of shape ({n},); got {type(scores).__name__}: "
            f"convert it with torch.as_tensor({name})"
        )
    if tuple(scores.shape) != (n,):
        raise InputError(f"{name} must have shape ({n},), one per box; got {tuple(scores.shape)}")
    if not scores.is_floating_point():
        raise InputError(f"{name} must be floating point; got {scores.dtype}: use {name}.float()")
    view = numpy_view(scores)
    if n and bool(np.isnan(view).any() if view is not None else torch.isnan(scores).any()):
        raise InputError(
            f"{name} must not hold NaN (a NaN score has no rank); got "
            f"{int(torch.isnan(scores).sum())}: drop them or use torch.nan_to_num({name}, nan=-inf)"
        )
    return scores


def _check_threshold(value: Any, name: str) -> float:
    return check_real(value, name, 0.0, 1.0)


def _greedy(
    boxes: torch.Tensor, order: torch.Tensor, thr: float, idxs: torch.Tensor | None
) -> torch.Tensor:
    """Greedy suppression over ``boxes[order]`` (already sorted); the kept entries of
    ``order``."""
    o = order.cpu().numpy()
    b = boxes.detach()
    if b.dtype not in (torch.float32, torch.float64):  # NumPy has no bfloat16
        b = b.to(torch.float64)
    # gathered and widened in NumPy (the same float64 values, a third of torch's time)
    b = b.cpu().numpy()[o].astype(np.float64)
    if idxs is None:
        cls = np.zeros(b.shape[0], dtype=np.int64)
    else:
        cls = np.ascontiguousarray(idxs.cpu().numpy()[o], dtype=np.int64)
    corners, areas = corners_and_areas(b, "xyxy")
    alive = greedy_suppression(corners, areas, cls, thr)
    return torch.from_numpy(o[alive]).to(order.device)


def _sorted(scores: torch.Tensor) -> torch.Tensor:
    # the stable order of -scores (ties by index), by NumPy on the CPU
    s = scores.detach()
    if s.dtype not in (torch.float32, torch.float64):
        s = s.to(torch.float32)  # float16 and bfloat16 are exact in float32
    return torch.from_numpy(np.argsort(-s.cpu().numpy(), kind="stable")).to(scores.device)


def nms(boxes: torch.Tensor, scores: torch.Tensor, iou_threshold: float) -> torch.Tensor:
    r"""Greedy non-maximum suppression: take the highest-scoring box, drop every box
    whose IoU with it exceeds ``iou_threshold`` (strictly), repeat with the rest.

    Ties in score are broken by index (the lower index first: a stable sort on
    ``-scores``); an IoU exactly equal to the threshold does not suppress. The result is
    the same as onnxruntime's ``NonMaxSuppression`` (tested) and torchvision's
    ``ops.nms``, and independent of the number of threads (the loop is sequential, the
    IoU arithmetic in float64).

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
        ``"xyxy"`` boxes; degenerate (zero-size) boxes overlap nothing.
    scores : (N,) torch.Tensor
        Floating point, no NaN (refused: a NaN has no rank); ``-inf`` is allowed.
    iou_threshold : float
        In ``[0, 1]``.

    Returns
    -------
    (K,) torch.Tensor of int64
        Indices of the kept boxes, by decreasing score.

    Raises
    ------
    InputError
        Bad boxes (see :func:`~robopercept.nn.ops.boxes.check_boxes`), scores of another
        length or with NaN, a threshold outside ``[0, 1]``.

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30]])
    >>> nms(b, torch.tensor([0.9, 0.95, 0.5]), 0.5).tolist()
    [1, 2]
    """
    boxes = check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    return _greedy(boxes, _sorted(scores), thr, None).to(boxes.device)


def _check_idxs(idxs: Any, n: int) -> torch.Tensor:
    if not isinstance(idxs, torch.Tensor) or tuple(idxs.shape) != (n,):
        got = tuple(idxs.shape) if isinstance(idxs, torch.Tensor) else type(idxs).__name__
        raise InputError(f"idxs must be a ({n},) integer torch.Tensor of class ids; got {got}")
    if idxs.is_floating_point() or idxs.is_complex() or idxs.dtype == torch.bool:
        raise InputError(f"idxs must hold integer class ids; got {idxs.dtype}: use idxs.long()")
    return idxs


def batched_nms(
    boxes: torch.Tensor, scores: torch.Tensor, idxs: torch.Tensor, iou_threshold: float
) -> torch.Tensor:
    """:func:`nms` within each class: a box suppresses only boxes of the same ``idxs``.

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
    scores : (N,) torch.Tensor
    idxs : (N,) torch.Tensor of int
        The class (or image) of each box.
    iou_threshold : float

    Returns
    -------
    (K,) torch.Tensor of int64
        Kept indices by decreasing score (all classes together, as torchvision's).

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10]])
    >>> batched_nms(b, torch.tensor([0.9, 0.8]), torch.tensor([0, 1]), 0.5).tolist()
    [0, 1]
    """
    boxes = check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    idxs = _check_idxs(idxs, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    return _greedy(boxes, _sorted(scores), thr, idxs).to(boxes.device)


def non_max_suppression(
    boxes: torch.Tensor,
    scores: torch.Tensor,
    iou_threshold: float = 0.5,
    score_threshold: float | None = None,
    top_k: int | None = None,
    idxs: torch.Tensor | None = None,
) -> torch.Tensor:
    """Detections after a score threshold, NMS (per class when ``idxs`` is given) and a
    cap on their number: onnxruntime's ``NonMaxSuppression`` with
    ``score_threshold`` and ``max_output_boxes_per_class`` (per class when ``idxs`` is
    given, as the operator's class axis).

    A box is a candidate when ``score > score_threshold`` (strictly, as onnxruntime).

    Parameters
    ----------
    boxes : (N, 4) torch.Tensor
    scores : (N,) torch.Tensor
    iou_threshold : float
        In ``[0, 1]``.
    score_threshold : float, optional
        Candidates score strictly above it; None keeps every box.
    top_k : int, optional
        At most this many kept boxes (per class with ``idxs``), >= 0; None: no cap.
    idxs : (N,) torch.Tensor of int, optional
        Class ids for per-class suppression.

    Returns
    -------
    (K,) torch.Tensor of int64
        Kept indices by decreasing score.

    Examples
    --------
    >>> import torch
    >>> b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30], [40, 0, 50, 9]])
    >>> s = torch.tensor([0.9, 0.95, 0.5, 0.1])
    >>> non_max_suppression(b, s, 0.5, score_threshold=0.2, top_k=1).tolist()
    [1]
    """
    boxes = check_boxes(boxes, "boxes")
    scores = _check_scores(scores, boxes.shape[0])
    thr = _check_threshold(iou_threshold, "iou_threshold")
    if idxs is not None:
        idxs = _check_idxs(idxs, boxes.shape[0])
    order = _sorted(scores)
    if score_threshold is not None:
        st = check_real(score_threshold, "score_threshold")
        order = order[scores[order] > st]
    keep = _greedy(boxes, order, thr, idxs)
    if top_k is not None:
        k = check_int(top_k, "top_k", 0)
        if idxs is None:
            keep = keep[:k]
        else:
            cls = idxs[keep]
            rank = torch.zeros_like(keep)
            for c in torch.unique(cls):
                m = cls == c
                rank[m] = torch.arange(int(m.sum()))
            keep = keep[rank < k]
    return keep.to(boxes.device)
