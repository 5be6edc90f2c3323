"""How well a pose network finds the joints of a labelled data set: PCK at several
thresholds of the box diagonal (:func:`~robopercept.nn.pose.metrics.pck`) and the COCO
keypoint AP/AR with the skeleton's OKS sigmas
(:func:`~robopercept.nn.coco.evaluate.evaluate_detections`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from torch import nn

from robopercept._checks import check_bool, check_real, check_reals, plain_repr
from robopercept.errors import InputError
from robopercept.nn.coco.evaluate import evaluate_detections
from robopercept.nn.detection.thresholds import ScoreThreshold, f1_threshold
from robopercept.nn.pose.inference import pose_data_arrays, predict_keypoints, refine_keypoints
from robopercept.nn.pose.metrics import bbox_diagonal, pck
from robopercept.nn.pose.networks import DeepPoseRefiner
from robopercept.nn.skeleton import Skeleton

__all__ = ["PoseEvaluation", "evaluate_pose", "joint_threshold"]


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
    COCO keypoint AP (:func:`~robopercept.nn.coco.evaluate.evaluate_detections` with
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
        PCK thresholds, each > 0 (fractions of the box diagonal).
    skeleton : Skeleton, optional
        Default: the data set's (its flip pairs and sigmas).
    """
    x, kp, boxes = pose_data_arrays(data, "data")
    alpha_values = check_reals(alphas, "alphas (PCK thresholds)", low=0.0)
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
    for a in alpha_values:
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


def joint_threshold(
    model: nn.Module,
    data: Any,
    *,
    refiners: Sequence[DeepPoseRefiner] = (),
    flip: bool = True,
    alpha: float = 0.1,
    skeleton: Skeleton | None = None,
) -> ScoreThreshold:
    """The joint score threshold a pose network ships with, chosen on validation
    figures: each predicted joint is an output with its score, right when it lies within
    ``alpha`` times the figure's box diagonal of the truth (PCK's rule), and the
    threshold is the F1-best one
    (:func:`~robopercept.nn.detection.thresholds.f1_threshold`; every joint of every
    figure is a positive). Joints scoring under it are not drawn.

    Parameters
    ----------
    model : nn.Module
    data : PoseDataset
        Validation figures.
    refiners : sequence of DeepPoseRefiner
    flip : bool
        The flip test, as at run time.
    alpha : float
        The PCK distance, a fraction of the box diagonal.
    skeleton : Skeleton, optional
        Default: the data set's.

    Returns
    -------
    ScoreThreshold
        ``iou`` holds ``alpha``; ``match_median`` the median score of the right joints.
    """
    x, kp, boxes = pose_data_arrays(data, "data")
    sk = skeleton if skeleton is not None else getattr(data, "skeleton", None)
    if not isinstance(sk, Skeleton):
        raise InputError(f"skeleton must be a Skeleton; got {plain_repr(sk)}")
    alpha = check_real(alpha, "alpha", 0.0, low_inclusive=False)
    if not isinstance(refiners, (list, tuple)) or not all(
        isinstance(r, DeepPoseRefiner) for r in refiners
    ):
        raise InputError(
            "refiners must be a list of DeepPoseRefiner stages (one stage: [stage]); got "
            f"{plain_repr(refiners)[:60]}"
        )
    perm = sk.flip_permutation() if check_bool(flip, "flip") else None
    pred, scores = predict_keypoints(model, x, flip_permutation=perm)
    if refiners:
        pred = refine_keypoints(x, pred, refiners)
    truth = kp.numpy().astype(np.float64)[..., :2]
    diag = bbox_diagonal(boxes, "xyxy")
    right = np.linalg.norm(pred - truth, axis=-1) <= alpha * diag[:, None]
    s = np.asarray(scores, np.float64)
    return f1_threshold(s.ravel(), right.ravel(), right.size, iou=alpha, images=len(s))
