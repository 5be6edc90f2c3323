r"""Semantic segmentation scores: the confusion matrix of label maps and what the field
reads from it (pixel accuracy, per-class IoU, mIoU, frequency-weighted IoU), the
boundary F-score, and the one-to-one matching of instances at an IoU threshold
(precision, recall, F1: :func:`match_instances`).

NumPy only (no torch). With :math:`C` the confusion matrix over :math:`K` classes
(:math:`C_{ij}` pixels of true class :math:`i` predicted :math:`j`), :math:`t_i =
\sum_j C_{ij}` (true pixels of class :math:`i`), :math:`p_j = \sum_i C_{ij}` and
:math:`N = \sum_{ij} C_{ij}`, as in Long et al. (2015), "Fully convolutional networks
for semantic segmentation", section 5:

* pixel accuracy :math:`\sum_i C_{ii} / N`;
* mean accuracy :math:`\frac{1}{K'} \sum_i C_{ii} / t_i` over the :math:`K'` classes
  with :math:`t_i > 0`;
* :math:`\mathrm{IoU}_i = C_{ii} / (t_i + p_i - C_{ii})`, NaN for a class that is
  neither in the truth nor in the prediction; mIoU is the mean over the other
  classes (``nanmean``, as torchmetrics and mmsegmentation);
* frequency-weighted IoU :math:`\sum_i (t_i / N)\, \mathrm{IoU}_i` over the classes
  with :math:`t_i > 0`.

Pixels whose true label is ``ignore_index`` count nowhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from robopercept._checks import check_int, check_real, plain_repr
from robopercept.errors import InputError

__all__ = [
    "InstanceMatching",
    "SegmentationScores",
    "boundary_f_score",
    "match_instances",
    "segmentation_confusion",
    "segmentation_scores",
]


def _labels(value: npt.ArrayLike, name: str) -> np.ndarray:
    a = np.asarray(value)
    if a.ndim < 1 or a.size == 0 or a.dtype.kind not in "biu":
        raise InputError(
            f"{name} must be a non-empty integer label map (e.g. (H, W) or (N, H, W)); got "
            f"{plain_repr(value)}"
        )
    return a.astype(np.int64, copy=False)


#: most classes scored (the confusion matrix has K^2 counts: 128 MiB at 4096)
MAX_CLASSES = 4096


def _classes(num_classes: Any, ignore_index: Any) -> tuple[int, int | None]:
    k = check_int(num_classes, "num_classes", 1)
    if k > MAX_CLASSES:
        raise InputError(f"num_classes is {k}; at most {MAX_CLASSES} classes are scored")
    ig = None if ignore_index is None else check_int(ignore_index, "ignore_index")
    return k, ig


def segmentation_confusion(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    num_classes: int,
    ignore_index: int | None = None,
) -> np.ndarray:
    """The ``(K, K)`` confusion matrix of label maps: rows true class, columns
    predicted class; equals ``sklearn.metrics.confusion_matrix(t, p, labels=range(K))``
    on the pixels whose true label is not ``ignore_index``.

    Parameters
    ----------
    y_true, y_pred : array-like of int, same shape
        Label maps (any shape: one image or a batch).
    num_classes : int
        :math:`K`; labels must lie in ``[0, K)`` (the ignored pixels excepted).
    ignore_index : int, optional
        True label of pixels left out (255 in Pascal VOC's PNGs).

    Returns
    -------
    ndarray of int64, shape (K, K)

    Raises
    ------
    InputError
        Shapes that differ, non-integer maps, or a label outside ``[0, K)`` (its value
        named).

    Examples
    --------
    >>> segmentation_confusion([[0, 1], [1, 255]], [[0, 0], [1, 1]], 2, ignore_index=255)
    array([[1, 0],
           [1, 1]])
    """
    t = _labels(y_true, "y_true")
    p = _labels(y_pred, "y_pred")
    if t.shape != p.shape:
        raise InputError(f"y_true has shape {t.shape} and y_pred {p.shape}; they must match")
    k, ig = _classes(num_classes, ignore_index)
    keep = np.ones(t.shape, bool) if ig is None else t != ig
    t, p = t[keep], p[keep]
    for name, a in (("y_true", t), ("y_pred", p)):
        bad = (a < 0) | (a >= k)
        if bad.any():
            v = int(a[bad][0])
            hint = " (pass ignore_index for a void label)" if name == "y_true" else ""
            raise InputError(f"{name} holds label {v}, outside the {k} classes [0, {k}){hint}")
    return np.bincount(t * k + p, minlength=k * k).reshape(k, k).astype(np.int64)


@dataclass(frozen=True)
class SegmentationScores:
    """The scores of one confusion matrix (see the module docstring for the formulas).

    Attributes
    ----------
    pixel_accuracy, mean_accuracy, miou, fwiou : float
    iou : ndarray of float64, shape (K,)
        NaN for a class in neither the truth nor the prediction.
    accuracy : ndarray of float64, shape (K,)
        Per-class recall :math:`C_{ii} / t_i`, NaN where :math:`t_i = 0`.
    confusion : ndarray of int64, shape (K, K)
    """

    pixel_accuracy: float
    mean_accuracy: float
    miou: float
    fwiou: float
    iou: np.ndarray
    accuracy: np.ndarray
    confusion: np.ndarray

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the four figures and the per-class lists (NaN as None)."""

        def clean(a: np.ndarray) -> list[float | None]:
            return [None if np.isnan(v) else float(v) for v in a]

        return {
            "pixel_accuracy": self.pixel_accuracy,
            "mean_accuracy": self.mean_accuracy,
            "miou": self.miou,
            "fwiou": self.fwiou,
            "iou": clean(self.iou),
            "accuracy": clean(self.accuracy),
        }


def segmentation_scores(confusion: npt.ArrayLike) -> SegmentationScores:
    """Pixel accuracy, mean accuracy, per-class IoU, mIoU and frequency-weighted IoU of
    a confusion matrix (:func:`segmentation_confusion`).

    Raises
    ------
    InputError
        Not a square matrix of counts >= 0, or no pixel counted at all.

    Examples
    --------
    >>> s = segmentation_scores([[3, 1], [0, 4]])
    >>> s.pixel_accuracy, s.iou.round(3).tolist(), round(s.miou, 4)
    (0.875, [0.75, 0.8], 0.775)
    """
    try:
        c = np.asarray(confusion)
    except (TypeError, ValueError):
        c = np.zeros(0)
    if c.ndim != 2 or c.shape[0] != c.shape[1] or c.dtype.kind not in "iuf":
        raise InputError(
            f"confusion must be a (K, K) matrix of counts; got {plain_repr(confusion)}"
        )
    c = c.astype(np.float64)
    if not np.isfinite(c).all() or (c < 0).any():
        raise InputError("confusion must hold finite counts >= 0")
    n = c.sum()
    if n == 0:
        raise InputError("the confusion matrix counts no pixel: nothing to score")
    diag = np.diag(c)
    t, p = c.sum(1), c.sum(0)
    union = t + p - diag
    with np.errstate(invalid="ignore", divide="ignore"):
        iou = np.where(union > 0, diag / union, np.nan)
        acc = np.where(t > 0, diag / t, np.nan)
    present = t > 0
    return SegmentationScores(
        pixel_accuracy=float(diag.sum() / n),
        mean_accuracy=float(np.nanmean(acc)),
        miou=float(np.nanmean(iou)),
        fwiou=float(np.sum(t[present] / n * iou[present])),
        iou=iou,
        accuracy=acc,
        confusion=c.astype(np.int64),
    )


def _boundary(mask: np.ndarray) -> np.ndarray:
    """The pixels of ``mask`` with a 4-neighbour outside it or outside the image (the
    erosion counts pixels beyond the border as unset, ``border_value=0``)."""
    cross = ndimage.generate_binary_structure(2, 1)
    return mask & ~ndimage.binary_erosion(mask, structure=cross, border_value=0)


def boundary_f_score(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    num_classes: int,
    tolerance: float = 2.0,
    ignore_index: int | None = None,
) -> np.ndarray:
    r"""Per-class boundary F-score of one label map (Csurka et al. 2013, "What is a good
    evaluation measure for semantic segmentation?").

    For class :math:`k`, :math:`B_t` and :math:`B_p` are the boundary pixels of its
    true and predicted masks (pixels of the mask with a 4-neighbour outside it or on
    the image border). With :math:`d(x, B)` the Euclidean distance from pixel
    :math:`x` to the nearest pixel of :math:`B`,

    .. math::
        P = \frac{|\{x \in B_p : d(x, B_t) \le \theta\}|}{|B_p|}, \quad
        R = \frac{|\{x \in B_t : d(x, B_p) \le \theta\}|}{|B_t|}, \quad
        F = \frac{2 P R}{P + R},

    :math:`\theta` = ``tolerance`` pixels; F is 1 when neither mask has the class, 0
    when only one has it. Ignored pixels belong to no class.

    Parameters
    ----------
    y_true, y_pred : array-like of int, shape (H, W)
    num_classes : int
    tolerance : float
        :math:`\theta` in pixels (>= 0).
    ignore_index : int, optional

    Returns
    -------
    ndarray of float64, shape (K,)

    Examples
    --------
    >>> t = np.zeros((8, 8), int); t[2:6, 2:6] = 1
    >>> p = np.roll(t, 1, axis=1)   # shifted by one pixel
    >>> boundary_f_score(t, p, 2, tolerance=1.0).tolist(), boundary_f_score(t, p, 2, 0.0)[1]
    ([1.0, 1.0], np.float64(0.5))
    """
    t = _labels(y_true, "y_true")
    p = _labels(y_pred, "y_pred")
    if t.ndim != 2 or t.shape != p.shape:
        raise InputError(
            f"y_true and y_pred must be label maps of one (H, W) shape; got {t.shape} and {p.shape}"
        )
    k, ig = _classes(num_classes, ignore_index)
    theta = check_real(tolerance, "tolerance", 0.0)
    if ig is not None:
        void = t == ig
        t = np.where(void, -1, t)
        p = np.where(void, -1, p)
    out = np.empty(k)
    for c in range(k):
        bt, bp = _boundary(t == c), _boundary(p == c)
        nt, npred = int(bt.sum()), int(bp.sum())
        if nt == 0 and npred == 0:
            out[c] = 1.0
            continue
        if nt == 0 or npred == 0:
            out[c] = 0.0
            continue
        dt = ndimage.distance_transform_edt(~bt)
        dp = ndimage.distance_transform_edt(~bp)
        prec = float((dt[bp] <= theta).mean())
        rec = float((dp[bt] <= theta).mean())
        out[c] = 0.0 if prec + rec == 0 else 2 * prec * rec / (prec + rec)
    return out


# ------------------------------------------------------------------------ instances
@dataclass(frozen=True)
class InstanceMatching:
    """How predicted instances match true ones at an IoU threshold
    (:func:`match_instances`).

    Attributes
    ----------
    tp, fp, fn : int
        Matched pairs, unmatched predictions, unmatched true instances.
    precision, recall, f1 : float
        :math:`tp/(tp+fp)`, :math:`tp/(tp+fn)`, :math:`2tp/(2tp+fp+fn)` (1.0 where
        both sides are empty, 0.0 where only one is).
    mean_matched_iou : float
        Mean IoU of the matched pairs (NaN without one).
    pairs : (tp, 2) int64 ndarray
        ``(true label, predicted label)`` of each match.
    iou_threshold : float
    """

    tp: int
    fp: int
    fn: int
    precision: float
    recall: float
    f1: float
    mean_matched_iou: float
    pairs: np.ndarray
    iou_threshold: float


#: most (true id, predicted id) pairs matched at once (an IoU table of 200 MB)
MAX_INSTANCE_PAIRS = 25_000_000


def _instance_labels(value: npt.ArrayLike, name: str) -> np.ndarray:
    a = _labels(value, name)
    if a.size and a.min() < 0:
        raise InputError(f"{name} must hold instance ids >= 0 (0 the background); got {a.min()}")
    return a


def match_instances(
    true_labels: npt.ArrayLike, pred_labels: npt.ArrayLike, iou_threshold: float = 0.5
) -> InstanceMatching:
    r"""Match predicted instances to true ones one-to-one and count the hits, as
    StarDist's ``matching`` (the nuclei-segmentation convention).

    Both label images hold 0 for the background and one positive id per instance (ids
    need not be consecutive). The IoU of every pair comes from their pixel contingency
    table; the pairs are chosen by a maximum-cardinality assignment among those with
    :math:`\mathrm{IoU} \ge` ``iou_threshold``, ties broken towards the higher summed
    IoU of the matched pairs (cost :math:`-[\mathrm{IoU} \ge t](1 + \mathrm{IoU}/(2n))`
    with :math:`n` the larger count, :func:`scipy.optimize.linear_sum_assignment`).
    StarDist's cost, :math:`-[\mathrm{IoU} \ge t] - \mathrm{IoU}/(2n)`, also weighs the
    IoU of pairs below the threshold, so for :math:`t < 0.5` its tie-breaking may pick
    other pairs (never another count). For :math:`t > 0.5` a true instance overlaps at
    most one prediction that much, and the matching is unique.

    Parameters
    ----------
    true_labels, pred_labels : (H, W) int array_like
    iou_threshold : float
        In [0, 1]; a pair needs IoU >= it (0.5 by default; StarDist's and the
        Data Science Bowl's thresholds run from 0.5 to 0.95).

    Returns
    -------
    InstanceMatching

    Raises
    ------
    InputError
        Not two integer label images of one shape, negative ids, a threshold outside
        [0, 1].

    Examples
    --------
    >>> t = np.array([[1, 1, 0, 2, 2]])
    >>> p = np.array([[5, 5, 5, 0, 7]])
    >>> r = match_instances(t, p)   # IoU(1, 5) = 2/3, IoU(2, 7) = 1/2
    >>> r.tp, r.fp, r.fn, r.f1, r.pairs.tolist()
    (2, 0, 0, 1.0, [[1, 5], [2, 7]])
    >>> match_instances(t, p, 0.6).tp
    1
    """
    from scipy.optimize import linear_sum_assignment

    t = _instance_labels(true_labels, "true_labels")
    p = _instance_labels(pred_labels, "pred_labels")
    if t.shape != p.shape or t.ndim != 2:
        raise InputError(
            f"true_labels and pred_labels must be (H, W) label images of one shape; got "
            f"{t.shape} and {p.shape}"
        )
    thr = check_real(iou_threshold, "iou_threshold", 0.0, 1.0)
    t_ids, t_inv = np.unique(t.ravel(), return_inverse=True)
    p_ids, p_inv = np.unique(p.ravel(), return_inverse=True)
    if len(t_ids) * len(p_ids) > MAX_INSTANCE_PAIRS:
        raise InputError(
            f"{len(t_ids)} true and {len(p_ids)} predicted ids make too many pairs to "
            f"match (at most {MAX_INSTANCE_PAIRS}): score tiles of the images separately"
        )
    # contingency of (true id, predicted id) pixel counts, background included
    table = np.bincount(
        t_inv.astype(np.int64) * len(p_ids) + p_inv, minlength=len(t_ids) * len(p_ids)
    ).reshape(len(t_ids), len(p_ids))
    t_fg = t_ids > 0
    p_fg = p_ids > 0
    inter = table[np.ix_(t_fg, p_fg)].astype(np.float64)
    union = table.sum(1)[t_fg, None] + table.sum(0)[None, p_fg] - inter
    iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)
    nt, npred = int(t_fg.sum()), int(p_fg.sum())
    pairs = np.zeros((0, 2), np.int64)
    scores = np.zeros(0)
    if nt and npred:
        hit = iou >= thr
        # each hit is worth 1 plus less than 1/(2n): the most hits, then the most IoU
        cost = -np.where(hit, 1.0 + iou / (2 * max(nt, npred)), 0.0)
        rows, cols = linear_sum_assignment(cost)
        ok = hit[rows, cols]
        rows, cols = rows[ok], cols[ok]
        pairs = np.stack([t_ids[t_fg][rows], p_ids[p_fg][cols]], axis=1).astype(np.int64)
        scores = iou[rows, cols]
    tp = len(pairs)
    fp, fn = npred - tp, nt - tp

    def ratio(a: int, b: int) -> float:
        return a / b if b else (1.0 if nt == npred == 0 else 0.0)

    return InstanceMatching(
        tp=tp,
        fp=fp,
        fn=fn,
        precision=ratio(tp, tp + fp),
        recall=ratio(tp, tp + fn),
        f1=ratio(2 * tp, 2 * tp + fp + fn),
        mean_matched_iou=float(scores.mean()) if tp else float("nan"),
        pairs=pairs,
        iou_threshold=thr,
    )
