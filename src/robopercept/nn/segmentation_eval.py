r"""Semantic segmentation scores: the confusion matrix of label maps and what the field
reads from it (pixel accuracy, per-class IoU, mIoU, frequency-weighted IoU), and the
boundary F-score.

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
    "SegmentationScores",
    "boundary_f_score",
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
