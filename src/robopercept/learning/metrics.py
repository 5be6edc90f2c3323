r"""Classification metrics: confusion matrix, precision, recall, F1, ROC and PR curves.

With TP, FP, FN, TN the counts of the confusion matrix for one class,

.. math::

    \text{precision} = \frac{TP}{TP + FP},\quad
    \text{recall} = \frac{TP}{TP + FN},\quad
    F_1 = \frac{2\,\text{precision}\cdot\text{recall}}{\text{precision} + \text{recall}}.

A score threshold :math:`t` turns scores into decisions (positive when
:math:`s \ge t`); sweeping :math:`t` over every distinct score gives the ROC curve
(FPR = FP / N against TPR = TP / P), whose trapezoid area is the AUC, and the
precision-recall curve, whose step integral
:math:`AP = \sum_k (R_k - R_{k-1}) P_k` is the average precision. Ties share one
threshold, so tied scores move the curve diagonally.

The definitions, the conventions at the ends (the ROC curve starts at a threshold of
:math:`+\infty`; the PR curve ends at precision 1, recall 0; an undefined ratio is 0)
and the order of the floating-point operations are scikit-learn's, so the numbers are
equal to ``sklearn.metrics`` to the last bits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_bool, check_numeric, plain_repr
from robopercept.errors import InputError

__all__ = [
    "ClassificationReport",
    "accuracy_score",
    "adjusted_rand_score",
    "auc",
    "average_precision_score",
    "check_labels",
    "classification_report",
    "confusion_matrix",
    "f1_score",
    "precision_recall_curve",
    "precision_score",
    "recall_score",
    "roc_auc_score",
    "roc_curve",
]

Average = Literal["binary", "macro", "micro", "weighted"] | None


def check_labels(y: npt.ArrayLike, name: str = "y", *, finite: bool = True) -> np.ndarray:
    """Return ``y`` as a 1-D array of class labels: numbers or strings.

    Parameters
    ----------
    y : (N,) array_like
    name : str
        The argument named in the message.
    finite : bool
        Refuse NaN and inf labels (NaN is not equal to itself, so it would make a
        class of its own per sample).

    Returns
    -------
    (N,) ndarray
        An object array of strings becomes a string array.

    Raises
    ------
    InputError
        Not 1-D, a ragged list, complex numbers or other objects, NaN/inf labels.

    Examples
    --------
    >>> check_labels(["a", "b"]).tolist()
    ['a', 'b']
    """
    try:
        arr = np.asarray(y)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise InputError(f"{name} must be a 1-D array of labels; {exc}") from None
    if arr.ndim != 1:
        raise InputError(
            f"{name} must be a 1-D array of labels; got shape {arr.shape}: one label per "
            f"sample ({name}.ravel() for a column)"
        )
    if arr.dtype.kind == "O" and all(isinstance(v, str) for v in arr.tolist()):
        arr = arr.astype(str)
    if arr.dtype.kind not in "biufUS":
        raise InputError(f"{name} must hold labels (numbers or strings); got dtype {arr.dtype}")
    if finite and arr.dtype.kind == "f" and not np.isfinite(arr).all():
        raise InputError(f"{name} has NaN or inf labels: drop or relabel those samples")
    return arr


def _same_kind(a: np.ndarray, b: np.ndarray, names: str) -> None:
    """Refuse string labels mixed with numbers (NumPy would turn the numbers into text)."""
    if (a.dtype.kind in "US") != (b.dtype.kind in "US") and a.size and b.size:
        raise InputError(
            f"{names} mix labels of different types (strings and numbers); pass one type"
        )


def _pair(
    y_true: npt.ArrayLike, y_pred: npt.ArrayLike, second: str = "y_pred"
) -> tuple[np.ndarray, np.ndarray]:
    a = check_labels(y_true, "y_true")
    b = check_labels(y_pred, second, finite=second != "y_score")
    if a.shape != b.shape:
        raise InputError(
            f"y_true and {second} must have the same length; got {a.size} and {b.size}"
        )
    if a.size == 0:
        raise InputError("y_true is empty; metrics need at least one sample")
    # y_score holds scores; labels_pred (a clustering) is compared as a partition, so
    # its label names need not be of y_true's type (class names vs cluster numbers)
    if second not in ("y_score", "labels_pred"):
        _same_kind(a, b, f"y_true and {second}")
    return a, b


def _check_pos_label(pos_label: object, optional: bool = False) -> None:
    """``pos_label`` must be one label: a number or a string (or None where optional)."""
    if pos_label is None and optional:
        return
    scalar = isinstance(pos_label, (int, float, str, np.integer, np.floating, np.str_))
    if not scalar or isinstance(pos_label, (bool, np.bool_)):
        raise InputError(
            f"pos_label must be one label (a number or a string); got {plain_repr(pos_label)}"
        )


def confusion_matrix(
    y_true: npt.ArrayLike, y_pred: npt.ArrayLike, labels: npt.ArrayLike | None = None
) -> np.ndarray:
    """Counts ``C[i, j]`` of samples of true class ``labels[i]`` predicted as ``labels[j]``.

    Parameters
    ----------
    y_true, y_pred : (N,) array_like
    labels : (K,) array_like, optional
        Row and column order; default the sorted union of both label sets.

    Returns
    -------
    (K, K) int64 array, rows true, columns predicted (``sklearn.metrics.confusion_matrix``).

    Examples
    --------
    >>> confusion_matrix([0, 0, 1, 1, 2], [0, 1, 1, 1, 2])
    array([[1, 1, 0],
           [0, 2, 0],
           [0, 0, 1]])
    """
    y_true, y_pred = _pair(y_true, y_pred)
    if labels is None:
        labels = np.union1d(y_true, y_pred)
    else:
        labels = check_labels(labels, "labels")
        if labels.size == 0:
            raise InputError("labels must name at least one class; got none")
        _same_kind(labels, y_true, "labels and y_true")
    k = labels.size
    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]

    def code(y: np.ndarray) -> np.ndarray:
        pos = np.clip(np.searchsorted(sorted_labels, y), 0, k - 1)
        found = sorted_labels[pos] == y
        return np.where(found, order[pos], -1)

    t, p = code(y_true), code(y_pred)
    keep = (t >= 0) & (p >= 0)
    return np.bincount(t[keep] * k + p[keep], minlength=k * k).reshape(k, k).astype(np.int64)


def accuracy_score(y_true: npt.ArrayLike, y_pred: npt.ArrayLike) -> float:
    """Fraction of samples whose prediction equals the truth."""
    y_true, y_pred = _pair(y_true, y_pred)
    return float(np.mean(y_true == y_pred))


def _prf(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    average: Average,
    pos_label: int | float | str | np.generic,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-class true positives, predicted counts and true counts (support)."""
    _check_pos_label(pos_label)
    y_true, y_pred = _pair(y_true, y_pred)
    labels = np.union1d(y_true, y_pred)
    cm = confusion_matrix(y_true, y_pred, labels=labels)
    tp = np.diag(cm).astype(np.float64)
    pred = cm.sum(axis=0).astype(np.float64)
    true = cm.sum(axis=1).astype(np.float64)
    if average == "binary":
        if labels.size > 2:
            raise InputError(
                f"average='binary' needs two classes; got {labels.size}: choose average="
                "'macro', 'micro', 'weighted' or None"
            )
        hit = np.flatnonzero(labels == pos_label)
        if hit.size == 0:
            if labels.size == 2:
                raise InputError(
                    f"pos_label={pos_label!r} is not one of the labels {labels.tolist()}"
                )
            return np.zeros(1), np.zeros(1), np.zeros(1)
        tp, pred, true = tp[hit], pred[hit], true[hit]
    elif average == "micro":
        tp, pred, true = tp.sum(keepdims=True), pred.sum(keepdims=True), true.sum(keepdims=True)
    return tp, pred, true


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    out = np.zeros_like(num)
    np.divide(num, den, out=out, where=den != 0)
    return out


def _average(values: np.ndarray, support: np.ndarray, average: Average) -> float | np.ndarray:
    if average is None:
        return values
    if average == "weighted":
        return float(np.average(values, weights=support)) if support.sum() > 0 else 0.0
    return float(np.mean(values))


def _check_average(average: Average) -> None:
    if average not in ("binary", "macro", "micro", "weighted", None):
        raise InputError(
            f"average must be 'binary', 'macro', 'micro', 'weighted' or None; got {average!r}"
        )


def precision_score(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    *,
    average: Average = "binary",
    pos_label: int | float | str | np.generic = 1,
) -> float | np.ndarray:
    """TP / (TP + FP) per class, averaged as ``average`` says (0 where undefined)."""
    _check_average(average)
    tp, pred, true = _prf(y_true, y_pred, average, pos_label)
    return _average(_ratio(tp, pred), true, average)


def recall_score(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    *,
    average: Average = "binary",
    pos_label: int | float | str | np.generic = 1,
) -> float | np.ndarray:
    """TP / (TP + FN) per class, averaged as ``average`` says (0 where undefined)."""
    _check_average(average)
    tp, _, true = _prf(y_true, y_pred, average, pos_label)
    return _average(_ratio(tp, true), true, average)


def f1_score(
    y_true: npt.ArrayLike,
    y_pred: npt.ArrayLike,
    *,
    average: Average = "binary",
    pos_label: int | float | str | np.generic = 1,
) -> float | np.ndarray:
    """2 TP / (2 TP + FP + FN) per class (the harmonic mean of precision and recall)."""
    _check_average(average)
    tp, pred, true = _prf(y_true, y_pred, average, pos_label)
    return _average(_ratio(2 * tp, pred + true), true, average)


@dataclass(frozen=True)
class ClassificationReport:
    """Per-class precision, recall, F1 and support, plus accuracy and the matrix."""

    labels: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    f1: np.ndarray
    support: np.ndarray
    accuracy: float
    confusion: np.ndarray

    def table(self) -> str:
        """The report as a text table (one row per class, then macro and weighted means)."""
        names = [str(x) for x in self.labels]
        w = max(12, *(len(n) for n in names))
        lines = [f"{'class':>{w}} {'precision':>9} {'recall':>9} {'f1':>9} {'support':>8}"]
        for n, p, r, f, s in zip(
            names, self.precision, self.recall, self.f1, self.support, strict=True
        ):
            lines.append(f"{n:>{w}} {p:>9.4f} {r:>9.4f} {f:>9.4f} {s:>8d}")
        total = int(self.support.sum())
        wts = self.support / max(total, 1)
        for name, agg in (("macro avg", np.mean), ("weighted avg", None)):
            vals = [
                agg(v) if agg else float(np.sum(v * wts))
                for v in (self.precision, self.recall, self.f1)
            ]
            lines.append(f"{name:>{w}} {vals[0]:>9.4f} {vals[1]:>9.4f} {vals[2]:>9.4f} {total:>8d}")
        lines.append(f"{'accuracy':>{w}} {'':>9} {'':>9} {self.accuracy:>9.4f} {total:>8d}")
        return "\n".join(lines)


def classification_report(y_true: npt.ArrayLike, y_pred: npt.ArrayLike) -> ClassificationReport:
    """Precision, recall, F1 and support of every class (``average=None``)."""
    y_true, y_pred = _pair(y_true, y_pred)
    labels = np.union1d(y_true, y_pred)
    cm = confusion_matrix(y_true, y_pred, labels=labels)
    tp = np.diag(cm).astype(np.float64)
    pred, true = cm.sum(axis=0).astype(np.float64), cm.sum(axis=1).astype(np.float64)
    return ClassificationReport(
        labels=labels,
        precision=_ratio(tp, pred),
        recall=_ratio(tp, true),
        f1=_ratio(2 * tp, pred + true),
        support=cm.sum(axis=1),
        accuracy=accuracy_score(y_true, y_pred),
        confusion=cm,
    )


# --------------------------------------------------------------------------- ranking


def _binary_truth(
    y_true: npt.ArrayLike, y_score: npt.ArrayLike, pos_label: int | float | str | np.generic | None
) -> tuple[np.ndarray, np.ndarray]:
    _check_pos_label(pos_label, optional=True)
    y_true, y_score = _pair(y_true, y_score, "y_score")
    score = check_numeric(y_score, "y_score")
    if not np.all(np.isfinite(score)):
        raise InputError("y_score contains NaN or inf; scores must be finite")
    classes = np.unique(y_true)
    if classes.size > 2:
        raise InputError(
            f"y_true must be binary for a curve; got {classes.size} classes: binarize it "
            "(y_true == positive_class) for a one-vs-rest curve"
        )
    if pos_label is None:
        if classes.size == 2 and not (
            np.array_equal(classes, [0, 1])
            or np.array_equal(classes, [-1, 1])
            or np.array_equal(classes, [0])
            or np.array_equal(classes, [1])
        ):
            raise InputError(
                f"y_true has labels {classes.tolist()}; say which is positive with pos_label"
            )
        pos_label = 1
    return (y_true == pos_label).astype(np.float64), score


def _counts_at_thresholds(
    truth: np.ndarray, score: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """False and true positive counts when thresholding at each distinct score."""
    order = np.argsort(score, kind="mergesort")[::-1]
    score, truth = score[order], truth[order]
    distinct = np.where(np.diff(score))[0]
    idx = np.r_[distinct, truth.size - 1]
    tps = np.cumsum(truth)[idx]
    fps = 1 + idx - tps
    return fps, tps, score[idx]


def roc_curve(
    y_true: npt.ArrayLike,
    y_score: npt.ArrayLike,
    *,
    pos_label: int | float | str | np.generic | None = None,
    drop_intermediate: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Receiver operating characteristic: ``(fpr, tpr, thresholds)``.

    Points strictly between collinear neighbours are dropped when ``drop_intermediate``
    (they do not change the curve or its area). The first threshold is ``inf`` so the
    curve starts at (0, 0). Equal to ``sklearn.metrics.roc_curve``.
    """
    drop_intermediate = check_bool(drop_intermediate, "drop_intermediate")
    truth, score = _binary_truth(y_true, y_score, pos_label)
    fps, tps, thr = _counts_at_thresholds(truth, score)
    if drop_intermediate and fps.size > 2:
        keep = np.where(np.r_[True, np.logical_or(np.diff(fps, 2), np.diff(tps, 2)), True])[0]
        fps, tps, thr = fps[keep], tps[keep], thr[keep]
    tps = np.r_[0.0, tps]
    fps = np.r_[0.0, fps]
    thr = np.r_[np.inf, thr]
    fpr = fps / fps[-1] if fps[-1] > 0 else np.full(fps.shape, np.nan)
    tpr = tps / tps[-1] if tps[-1] > 0 else np.full(tps.shape, np.nan)
    return fpr, tpr, thr


def auc(x: npt.ArrayLike, y: npt.ArrayLike) -> float:
    """Area under a curve by the trapezoid rule (``x`` monotonic)."""
    x, y = check_numeric(x, "x"), check_numeric(y, "y")
    if x.shape != y.shape or x.ndim != 1 or x.size < 2:
        raise InputError(
            f"auc needs two 1-D arrays of >= 2 equal lengths; got {x.shape}, {y.shape}"
        )
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise InputError("auc needs finite x and y; drop the NaN/inf points")
    dx = np.diff(x)
    direction = 1.0
    if np.any(dx < 0):
        if np.all(dx <= 0):
            direction = -1.0
        else:
            raise InputError("x must be monotonic (increasing or decreasing) for auc")
    from scipy.integrate import trapezoid

    return float(direction * trapezoid(y, x))


def roc_auc_score(
    y_true: npt.ArrayLike,
    y_score: npt.ArrayLike,
    *,
    pos_label: int | float | str | np.generic | None = None,
) -> float:
    """Area under the ROC curve: the probability that a random positive outranks a
    random negative (ties count one half). Needs both classes in ``y_true``."""
    truth, _ = _binary_truth(y_true, y_score, pos_label)
    if truth.min() == truth.max():
        raise InputError("roc_auc_score needs positive and negative samples in y_true")
    fpr, tpr, _ = roc_curve(y_true, y_score, pos_label=pos_label)
    return auc(fpr, tpr)


def precision_recall_curve(
    y_true: npt.ArrayLike,
    y_score: npt.ArrayLike,
    *,
    pos_label: int | float | str | np.generic | None = None,
    drop_intermediate: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision and recall at every distinct threshold: ``(precision, recall, thresholds)``.

    Recall decreases along the arrays; the last point is (recall 0, precision 1) and has
    no threshold. Equal to ``sklearn.metrics.precision_recall_curve``.
    """
    drop_intermediate = check_bool(drop_intermediate, "drop_intermediate")
    truth, score = _binary_truth(y_true, y_score, pos_label)
    fps, tps, thr = _counts_at_thresholds(truth, score)
    if drop_intermediate and fps.size > 2:
        keep = np.where(np.r_[True, np.logical_or(np.diff(tps[:-1]), np.diff(tps[1:])), True])[0]
        fps, tps, thr = fps[keep], tps[keep], thr[keep]
    ps = tps + fps
    precision = _ratio(tps, ps)
    recall = np.ones_like(tps) if tps[-1] == 0 else tps / tps[-1]
    return np.r_[precision[::-1], 1.0], np.r_[recall[::-1], 0.0], thr[::-1]


def average_precision_score(
    y_true: npt.ArrayLike,
    y_score: npt.ArrayLike,
    *,
    pos_label: int | float | str | np.generic | None = None,
) -> float:
    r"""Average precision :math:`\sum_k (R_k - R_{k-1}) P_k` (no interpolation)."""
    precision, recall, _ = precision_recall_curve(y_true, y_score, pos_label=pos_label)
    return float(max(0.0, -np.sum(np.diff(recall) * precision[:-1])))


def adjusted_rand_score(labels_true: npt.ArrayLike, labels_pred: npt.ArrayLike) -> float:
    r"""Agreement of two clusterings, corrected for chance (Hubert and Arabie's ARI).

    With the contingency table :math:`n_{ij}` (samples in class :math:`i` and cluster
    :math:`j`), its row sums :math:`a_i`, column sums :math:`b_j` and
    :math:`\binom{\cdot}{2}` pair counts,

    .. math::

        \text{ARI} = \frac{\sum_{ij} \binom{n_{ij}}{2} - E}
                          {\tfrac12 [\sum_i \binom{a_i}{2} + \sum_j \binom{b_j}{2}] - E},
        \qquad E = \frac{\sum_i \binom{a_i}{2} \sum_j \binom{b_j}{2}}{\binom{n}{2}}.

    1 for identical partitions (whatever the label names), about 0 for random ones.
    Noise labels (-1) count as one more cluster, as in scikit-learn.
    """
    a, b = _pair(labels_true, labels_pred, "labels_pred")
    _, ia = np.unique(a, return_inverse=True)
    _, ib = np.unique(b, return_inverse=True)
    ia, ib = ia.reshape(-1).astype(np.int64), ib.reshape(-1).astype(np.int64)
    na, nb = int(ia.max()) + 1, int(ib.max()) + 1
    # the non-zero cells of the contingency table only (n distinct labels on both
    # sides would make a dense n x n table)
    _, cells = np.unique(ia * nb + ib, return_counts=True)

    def pairs(v: np.ndarray) -> float:
        v = v.astype(np.float64)
        return float(np.sum(v * (v - 1) / 2))

    n = a.size
    index, rows, cols = pairs(cells), pairs(np.bincount(ia)), pairs(np.bincount(ib))
    if na == nb == 1 or (na == nb == n and n > 0):
        return 1.0  # one cluster each, or every sample alone in both: the same partition
    expected = rows * cols / (n * (n - 1) / 2)
    top = 0.5 * (rows + cols) - expected
    return float((index - expected) / top) if top != 0 else 1.0
