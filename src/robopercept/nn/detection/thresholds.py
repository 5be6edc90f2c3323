r"""The score threshold a detector ships with, chosen on validation images
(:func:`choose_score_threshold`), and the rule that says an image lies outside the
model's domain (:func:`domain_warning`).

Choosing the threshold. Every validation detection is matched greedily to the
ground truth, as COCO's evaluation does at one IoU: per image and class, detections in
decreasing score take the unmatched true box of highest IoU, if that IoU is at least
``iou`` (0.5). Sorted by decreasing score over all images, the first :math:`k`
detections hold :math:`TP_k` matches, so keeping the scores :math:`\ge s_k` gives

.. math::

    P_k = TP_k / k, \qquad R_k = TP_k / G, \qquad F1_k = 2 P_k R_k / (P_k + R_k),

with :math:`G` the true boxes. The threshold is the score :math:`s_k` of the
:math:`k` with the largest :math:`F1_k` (the highest such score on ties): the operating
point a detector's user would pick from the validation precision-recall curve when
misses and false alarms cost the same.

The domain rules. A model's detections on images of its own kind reach the scores of
its validation matches; on an image of another kind (a street photo for a tree-crown
model) the best score stays far below. :func:`domain_warning` says so when the image's
highest score is below half the median score of the validation matches, or when no
detection reaches the threshold at all. Scores alone miss a confident mistake, so
:func:`input_warning` also compares the input with what the model was trained on: a
colour image for a model of grey micrographs (``input_colour == "grey"``: more than 5%
of the pixels with channels differing by over 0.1 of the full scale), or an image far
larger than the training canvases (``canvas`` ``(h, w)``: the shorter side over twice
the canvas's, as a photo for a model of 128 px procedural shapes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from robopercept._checks import check_int, check_numeric, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.geometry.boxes import box_iou_matrix

__all__ = [
    "ScoreThreshold",
    "choose_score_threshold",
    "domain_warning",
    "f1_threshold",
    "input_warning",
]


@dataclass(frozen=True)
class ScoreThreshold:
    """A threshold chosen on validation (:func:`choose_score_threshold`).

    Attributes
    ----------
    score_thresh : float
        Keep detections with ``score >= score_thresh``.
    f1, precision, recall : float
        On the validation images at that threshold.
    match_median : float
        The median score of the validation detections that matched a true box (the
        scores a model reaches on its own kind of images; :func:`domain_warning`).
    iou : float
        The IoU a match needs.
    images, truths : int
        Validation images and true boxes.
    """

    score_thresh: float
    f1: float
    precision: float
    recall: float
    match_median: float
    iou: float
    images: int
    truths: int

    def to_dict(self) -> dict[str, Any]:
        """Plain values (stored in a checkpoint's ``"calibration"``)."""
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(self).items()}


def _matches(
    boxes: np.ndarray,
    labels: np.ndarray,
    scores: np.ndarray,
    tb: np.ndarray,
    tl: np.ndarray,
    iou: float,
) -> np.ndarray:
    """True where a detection (in decreasing score) matches a free true box of its class."""
    order = np.argsort(-scores, kind="stable")
    hit = np.zeros(len(scores), bool)
    used = np.zeros(len(tb), bool)
    if not len(tb) or not len(boxes):
        return hit
    ious = box_iou_matrix(boxes, tb, fmt="xyxy")
    for i in order:
        cand = np.where((tl == labels[i]) & ~used & (ious[i] >= iou))[0]
        if len(cand):
            j = cand[np.argmax(ious[i, cand])]
            used[j] = True
            hit[i] = True
    return hit


def _image_arrays(item: Any, where: str, scored: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(boxes (D, 4), labels (D,), scores (D,))`` of one image's dict, checked: a dict
    with those keys, numeric, finite boxes and scores of one length (no scores: zeros)."""
    keys = ("boxes", "labels", "scores") if scored else ("boxes", "labels")
    if not isinstance(item, Mapping) or any(k not in item for k in keys):
        raise InputError(
            f"{where} must be a dict with {', '.join(map(repr, keys))}; got {plain_repr(item)[:80]}"
        )
    boxes = check_numeric(item["boxes"], f"{where}['boxes']")
    labels = check_numeric(item["labels"], f"{where}['labels']").reshape(-1)
    scores = check_numeric(item["scores"], f"{where}['scores']").reshape(-1) if scored else None
    if boxes.size % 4 or (boxes.ndim != 2 and boxes.size):
        raise InputError(f"{where}['boxes'] must be (D, 4) xyxy; got shape {boxes.shape}")
    boxes = boxes.reshape(-1, 4)
    n = len(boxes)
    if scores is None:
        scores = np.zeros(n)
    if len(labels) != n or len(scores) != n:
        raise InputError(
            f"{where} must hold one label{' and one score' if scored else ''} per box; got "
            f"{n} boxes, {len(labels)} labels" + (f", {len(scores)} scores" if scored else "")
        )
    if not (np.isfinite(boxes).all() and np.isfinite(scores).all()):
        raise InputError(f"{where} holds NaN or inf boxes or scores: drop those entries")
    return boxes, labels, scores


def choose_score_threshold(
    detections: Sequence[Mapping[str, Any]],
    truths: Sequence[Mapping[str, Any]],
    iou: float = 0.5,
) -> ScoreThreshold:
    """The F1-best score threshold on validation images (module docstring).

    Parameters
    ----------
    detections : sequence of dict
        Per image: ``boxes`` (D, 4) xyxy, ``labels`` (D,), ``scores`` (D,) (what
        :func:`~robopercept.nn.detection.zoo.detect_arrays` gives).
    truths : sequence of dict
        Per image, in the same order: ``boxes`` (G, 4) xyxy and ``labels`` (G,).
    iou : float in (0, 1]
        The IoU a match needs.

    Returns
    -------
    ScoreThreshold

    Raises
    ------
    InputError
        Lists of different lengths, or no true box at all (nothing to choose on).

    Examples
    --------
    >>> import numpy as np
    >>> truth = [{"boxes": np.array([[0, 0, 10, 10], [20, 20, 30, 30]]),
    ...           "labels": np.array([1, 1])}]
    >>> det = [{"boxes": np.array([[0, 0, 10, 10], [50, 50, 60, 60], [20, 20, 30, 31]]),
    ...         "labels": np.array([1, 1, 1]), "scores": np.array([0.9, 0.8, 0.6])}]
    >>> t = choose_score_threshold(det, truth)
    >>> (t.score_thresh, round(t.f1, 3), t.precision, t.recall)
    (0.6, 0.8, 0.6666666666666666, 1.0)
    """
    iou = check_real(iou, "iou", 1e-9, 1.0)
    for name, value in (("detections", detections), ("truths", truths)):
        if not isinstance(value, (list, tuple)):
            raise InputError(
                f"{name} must be a list of per-image dicts (boxes, labels[, scores]); got "
                f"{plain_repr(value)[:60]}"
            )
    if len(detections) != len(truths):
        raise InputError(
            f"detections ({len(detections)} images) and truths ({len(truths)}) must pair up"
        )
    hits, scores = [], []
    n_true = 0
    for i, (d, t) in enumerate(zip(detections, truths, strict=True)):
        b, lab, s = _image_arrays(d, f"detections[{i}]", scored=True)
        tb, tl, _ = _image_arrays(t, f"truths[{i}]", scored=False)
        n_true += len(tb)
        hits.append(_matches(b, lab, s, tb, tl, iou))
        scores.append(s)
    if n_true == 0:
        raise InputError("the validation images hold no true box: nothing to choose a threshold on")
    hit = np.concatenate(hits) if hits else np.zeros(0, bool)
    sc = np.concatenate(scores) if scores else np.zeros(0)
    return f1_threshold(sc, hit, n_true, iou=iou, images=len(truths))


def f1_threshold(
    scores: np.ndarray, hits: np.ndarray, positives: int, *, iou: float = 0.5, images: int = 0
) -> ScoreThreshold:
    """The F1-best threshold of scored outputs of which ``hits`` are right, out of
    ``positives`` that should be found (module docstring; a detection matched to a
    true box, or a joint within its PCK distance).

    Parameters
    ----------
    scores : (N,) ndarray
    hits : (N,) bool ndarray
    positives : int
        The number of true items (``G``), >= 1.
    iou : float
        Recorded in the result (the match rule).
    images : int
        Recorded in the result.

    Returns
    -------
    ScoreThreshold
        ``score_thresh`` 1.0 and F1 0 when there is no output.

    Examples
    --------
    >>> import numpy as np
    >>> t = f1_threshold(np.array([0.9, 0.8, 0.3, 0.2]), np.array([1, 1, 0, 1], bool), 3)
    >>> t.score_thresh, round(t.f1, 3)  # all four: P 3/4, R 1; the top two: P 1, R 2/3
    (0.2, 0.857)
    """
    sc = check_numeric(scores, "scores").reshape(-1)
    hit = check_numeric(hits, "hits").reshape(-1).astype(bool)
    if sc.shape != hit.shape:
        raise InputError(f"scores {sc.shape} and hits {hit.shape} must have the same length")
    if not np.isfinite(sc).all():
        raise InputError("scores hold NaN or inf: drop those entries")
    positives = check_int(positives, "positives")
    if positives < 1:
        raise InputError("positives must be >= 1: nothing to choose a threshold on")
    iou = check_real(iou, "iou", 0.0, 1.0)
    images = check_int(images, "images", 0)
    if not len(sc):
        return ScoreThreshold(1.0, 0.0, 0.0, 0.0, 0.0, iou, images, positives)
    order = np.argsort(-sc, kind="stable")
    sc, hit = sc[order], hit[order]
    # cut only between distinct scores: keeping "score >= s" keeps every tie of s
    last = np.r_[sc[1:] != sc[:-1], True]
    tp = np.cumsum(hit)[last]
    k = np.arange(1, len(sc) + 1)[last]
    f1 = np.where(tp > 0, 2 * tp / (k + positives), 0.0)
    best = int(np.flatnonzero(f1 == f1.max())[0])
    matched = sc[hit]
    return ScoreThreshold(
        score_thresh=float(sc[last][best]),
        f1=float(f1[best]),
        precision=float(tp[best] / k[best]),
        recall=float(tp[best] / positives),
        match_median=float(np.median(matched)) if len(matched) else 0.0,
        iou=iou,
        images=images,
        truths=positives,
    )


def domain_warning(
    best: float, calibration: Mapping[str, Any] | None, model_name: str, trained_on: str
) -> str | None:
    """The one-line warning when an image looks outside a model's domain, else None.

    The rule (module docstring): ``best`` (a detector's highest score on the image, a
    pose network's median joint score) is below ``calibration["score_thresh"]``, or
    below half of ``calibration["match_median"]``.

    Parameters
    ----------
    best : float
        The image's score to judge (0 when there is no output).
    calibration : dict or None
        :meth:`ScoreThreshold.to_dict` as stored with the model; None (an uncalibrated
        model) gives no warning.
    model_name, trained_on : str
        For the message.

    Returns
    -------
    str or None

    Examples
    --------
    >>> cal = {"score_thresh": 0.4, "match_median": 0.7}
    >>> domain_warning(0.9, cal, "trees", "aerial tree crowns") is None
    True
    >>> print(domain_warning(0.2, cal, "trees", "aerial tree crowns"))
    warning: trees scores at most 0.20 here (threshold 0.40, true detections on validation
    0.70): this input may lie outside what it was trained on (aerial tree crowns)
    """
    if calibration is None:
        return None
    if not isinstance(calibration, Mapping):
        raise InputError(
            "calibration must be a dict with 'score_thresh' (ScoreThreshold.to_dict()) or "
            f"None; got {plain_repr(calibration)[:60]}"
        )
    if not calibration:
        return None
    top = check_real(best, "best")
    if "score_thresh" not in calibration:
        raise InputError(
            f"calibration must hold 'score_thresh'; got keys {sorted(map(str, calibration))}"
        )
    thr = check_real(calibration["score_thresh"], "calibration['score_thresh']")
    med = check_real(calibration.get("match_median", 0.0), "calibration['match_median']")
    model_name, trained_on = str(model_name), str(trained_on)
    if top >= thr and top >= 0.5 * med:
        return None
    return (
        f"warning: {model_name} scores at most {top:.2f} here (threshold {thr:.2f}, true "
        f"detections on validation {med:.2f}): this input may lie outside what it was "
        f"trained on ({trained_on})"
    )


def input_warning(
    image: np.ndarray, info: Mapping[str, Any], model_name: str, trained_on: str
) -> str | None:
    """The one-line warning when an input differs from a model's training images in
    colour or scale (module docstring), else None.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        As given (uint8, uint16 or float in [0, 1]).
    info : dict
        The checkpoint's entries: ``input_colour`` ("grey") and ``canvas`` ``(h, w)``
        where stored.
    model_name, trained_on : str
        For the message.

    Returns
    -------
    str or None

    Examples
    --------
    >>> im = np.zeros((600, 800, 3), np.uint8)
    >>> print(input_warning(im, {"canvas": [128, 128]}, "fcos", "generated shapes"))
    warning: fcos was trained on 128 x 128 images and this one is 800 x 600: it may lie
    outside what it was trained on (generated shapes)
    >>> im[..., 0] = 255  # a red image for a model of grey micrographs
    >>> input_warning(im, {"input_colour": "grey"}, "nuclei", "micrographs")[:40]
    'warning: nuclei was trained on grey imag'
    """
    if not isinstance(info, Mapping):
        raise InputError(f"info must be a dict of entries; got {type(info).__name__}")
    if not isinstance(image, np.ndarray) or image.ndim not in (2, 3):
        raise InputError("image must be an (H, W) or (H, W, 3) array")
    h, w = image.shape[:2]
    what = None
    if info.get("input_colour") == "grey" and image.ndim == 3 and image.shape[2] == 3:
        scale = 255.0 if image.dtype == np.uint8 else 65535.0 if image.dtype == np.uint16 else 1.0
        x = image.astype(np.float32) / np.float32(scale)
        spread = x.max(axis=2) - x.min(axis=2)
        if float((spread > 0.1).mean()) > 0.05:
            what = "grey images and this one is in colour"
    canvas = info.get("canvas")
    if what is None and canvas is not None and min(h, w) > 2 * min(canvas):
        what = f"{canvas[1]} x {canvas[0]} images and this one is {w} x {h}"
    if what is None:
        return None
    return (
        f"warning: {model_name} was trained on {what}: it may lie outside what it was "
        f"trained on ({trained_on})"
    )
