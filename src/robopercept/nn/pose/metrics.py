r"""2-D pose metrics: the percentage of correct keypoints (PCK, PCKh) and its normalizers.

NumPy only (no torch). For samples :math:`n = 1..N` and joints :math:`j = 1..J`, with
a prediction :math:`\hat p_{nj}`, the truth :math:`p_{nj}`, a visibility flag
:math:`u_{nj}` and a per-sample length :math:`L_n` (the *normalizer*),

.. math::

    c_{nj} = \big[\, \lVert \hat p_{nj} - p_{nj} \rVert_2 / L_n < \alpha \,\big],
    \qquad \mathrm{PCK}_j = \frac{\sum_n u_{nj}\, c_{nj}}{\sum_n u_{nj}},

over the samples with :math:`L_n > 0` only (a zero normalizer drops its sample, as
mmpose does). The mean PCK is the plain mean of :math:`\mathrm{PCK}_j` over the joints
that count anywhere (mmpose's ``avg_acc``); the *pooled* PCK is
:math:`\sum_{nj} u_{nj} c_{nj} / \sum_{nj} u_{nj}`, every counted joint alike (MPII's
count-weighted mean, :meth:`PckScores.weighted`).

Conventions, each tested:

* the test is strict, :math:`d / L < \alpha`, as mmpose's ``keypoint_pck_accuracy``
  (the original MPII Matlab evaluation writes :math:`\le`; the two differ only for an
  error exactly on the threshold);
* joints with visibility 0 do not count (neither hit nor miss); by default the
  visibility is the truth's third column :math:`v > 0` (COCO's flag), or every joint
  when the truth has two columns;
* a NaN or infinite prediction of a counted joint is a *miss* (a network that gives no
  position for a joint has not found it); non-finite truth of a counted joint is
  refused;
* PCK (bounding-box normalizer) as in the literature uses :math:`L` = the box
  diagonal, :func:`bbox_diagonal`; mmpose's ``PCKAccuracy(norm_item="bbox")`` uses the
  longer box side :math:`\max(w, h)` instead: pass that to :func:`pck` to match it;
* PCKh (MPII) uses :math:`L` = the head size, :math:`0.6` times the diagonal of the
  annotated head rectangle (``SC_BIAS = 0.6`` of the MPII evaluation code, mmpose and
  HRNet), :func:`mpii_head_sizes`, with :math:`\alpha = 0.5`.

Examples
--------
>>> import numpy as np
>>> truth = np.array([[[0.0, 0.0], [10.0, 0.0]]])
>>> pred = np.array([[[1.0, 0.0], [14.0, 0.0]]])  # errors 1 and 4 px
>>> s = pck(pred, truth, None, 0.2, [10.0])  # threshold 2 px
>>> s.per_joint.tolist(), s.mean
([1.0, 0.0], 0.5)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_choice, check_numeric, check_real, plain_repr
from robopercept.errors import InputError

__all__ = [
    "MPII_HEAD_SCALE",
    "PckScores",
    "bbox_diagonal",
    "mpii_head_sizes",
    "pck",
    "pckh",
]

#: MPII's head-size factor (``SC_BIAS`` of the MPII evaluation code): the head size is
#: 0.6 times the diagonal of the annotated head rectangle
MPII_HEAD_SCALE = 0.6


@dataclass(frozen=True, eq=False)
class PckScores:
    """The PCK of a set of poses.

    Attributes
    ----------
    per_joint : (J,) float64 ndarray
        The fraction of counted samples where the joint is found; NaN for a joint that
        no sample counts (mmpose writes -1 there).
    mean : float
        The mean of ``per_joint`` over the joints that count (mmpose's ``avg_acc``);
        NaN when none does.
    pooled : float
        Found over counted, all joints together (each joint weighted by its count);
        NaN when nothing counts.
    correct, counts : (J,) int64 ndarray
        Per joint, the samples where it is found and the samples that count it
        (visible, with a positive normalizer).
    threshold : float
        :math:`\\alpha`, the fraction of the normalizer within which a joint is found.

    Examples
    --------
    >>> s = PckScores.from_counts([3, 0], [4, 0], 0.5)
    >>> s.per_joint.tolist()[0], s.mean, s.weighted([0])
    (0.75, 0.75, 0.75)
    """

    per_joint: np.ndarray
    mean: float
    pooled: float
    correct: np.ndarray
    counts: np.ndarray
    threshold: float

    @classmethod
    def from_counts(
        cls, correct: npt.ArrayLike, counts: npt.ArrayLike, threshold: float
    ) -> PckScores:
        """The scores from per-joint ``correct`` and ``counts`` (``correct <= counts``)."""
        cf = check_numeric(correct, "correct")
        nf = check_numeric(counts, "counts")
        whole = all(np.isfinite(a).all() and (a == np.round(a)).all() for a in (cf, nf))
        c, n = (a.astype(np.int64) if whole else np.full(a.shape, -1) for a in (cf, nf))
        if c.ndim != 1 or c.shape != n.shape or (c < 0).any() or (c > n).any():
            raise InputError(
                "correct and counts must be 1-D arrays of one length of integers with "
                f"0 <= correct <= counts; got {plain_repr(correct)} and {plain_repr(counts)}"
            )
        with np.errstate(invalid="ignore", divide="ignore"):
            per = np.where(n > 0, c / np.maximum(n, 1), np.nan)
        counted = n > 0
        mean = float(per[counted].mean()) if counted.any() else float("nan")
        pooled = float(c.sum() / n.sum()) if n.sum() else float("nan")
        for a in (per, c, n):
            a.setflags(write=False)
        alpha = check_real(threshold, "threshold", 0.0, low_inclusive=False)
        return cls(per, mean, pooled, c, n, alpha)

    def weighted(self, joints: Sequence[int] | None = None) -> float:
        """Found over counted on the ``joints`` given (default all): the count-weighted
        mean PCK of those joints. MPII's reported mean PCKh leaves out the pelvis and
        the thorax: ``weighted([j for j in range(16) if j not in (6, 7)])`` in
        :data:`~robopercept.nn.skeleton.MPII_16`'s order."""
        n_j = self.counts.size
        if joints is None:
            sel = np.arange(n_j)
        else:
            try:
                sel = np.asarray(joints, dtype=np.int64).reshape(-1)
            except (TypeError, ValueError):
                sel = np.array([-1])
            if sel.size == 0 or (sel < 0).any() or (sel >= n_j).any():
                raise InputError(f"joints must be indices 0..{n_j - 1}; got {plain_repr(joints)}")
        total = int(self.counts[sel].sum())
        return float(self.correct[sel].sum() / total) if total else float("nan")


def _coords(value: npt.ArrayLike, name: str, columns: tuple[int, ...]) -> np.ndarray:
    arr = check_numeric(value, name)
    if arr.ndim != 3 or arr.shape[2] not in columns:
        cols = " or ".join(str(c) for c in columns)
        hint = ""
        if arr.ndim == 2 and arr.shape[-1] in columns:
            hint = f": one pose? pass {name}[None] (a batch of one)"
        elif arr.ndim == 3 and name == "pred" and arr.shape[2] == 3:
            hint = ": drop the score column, pred[..., :2]"
        raise InputError(f"{name} must be (N, J, {cols}); got shape {arr.shape}{hint}")
    return arr


def pck(
    pred: npt.ArrayLike,
    truth: npt.ArrayLike,
    visible: npt.ArrayLike | None,
    threshold: float,
    normalizer: npt.ArrayLike,
) -> PckScores:
    r"""Percentage of correct keypoints: joint :math:`j` of sample :math:`n` is found
    when :math:`\lVert \hat p_{nj} - p_{nj} \rVert / L_n < \alpha` (strict, as mmpose's
    ``keypoint_pck_accuracy``); see the module docstring for the formulas and the
    conventions.

    Parameters
    ----------
    pred : (N, J, 2) array_like
        Predicted ``x, y``; NaN (or inf) marks a joint the model did not place, a miss.
    truth : (N, J, 2) or (N, J, 3) array_like
        True ``x, y`` (and visibility ``v``).
    visible : (N, J) array_like of bool, or None
        Which joints count. None: ``truth[..., 2] > 0`` for 3 columns, else all.
    threshold : float
        :math:`\alpha > 0`, the fraction of the normalizer (0.2 for PCK@0.2).
    normalizer : (N,) array_like
        :math:`L_n \ge 0` per sample: the box diagonal (:func:`bbox_diagonal`), the head
        size (:func:`mpii_head_sizes`), a torso length; a sample with :math:`L_n = 0`
        does not count (as in mmpose).

    Returns
    -------
    PckScores

    Raises
    ------
    InputError
        Shapes that do not agree (fewer joints in ``pred`` than in ``truth``, another
        number of samples), a ``visible`` that is not (N, J), a non-finite truth on a
        counted joint, a normalizer that is negative or not finite, a threshold <= 0.

    Examples
    --------
    >>> import numpy as np
    >>> truth = np.array([[[0, 0, 2], [10, 0, 2], [5, 5, 0]]], dtype=float)
    >>> pred = np.array([[[0.5, 0.0], [np.nan, np.nan], [50.0, 50.0]]])
    >>> s = pck(pred, truth, None, 0.1, [10.0])  # joint 2 is not labelled
    >>> s.per_joint.tolist(), s.counts.tolist(), s.pooled
    ([1.0, 0.0, nan], [1, 1, 0], 0.5)
    """
    p = _coords(pred, "pred", (2,))
    t = _coords(truth, "truth", (2, 3))
    if p.shape[:2] != t.shape[:2]:
        raise InputError(
            f"pred and truth must hold the same samples and joints; got pred {p.shape[:2]} "
            f"(N, J) and truth {t.shape[:2]}"
            + (": pred has fewer joints than truth" if p.shape[1] < t.shape[1] else "")
            + (": pred has more joints than truth" if p.shape[1] > t.shape[1] else "")
        )
    n, j = t.shape[:2]
    if visible is None:
        vis = t[:, :, 2] > 0 if t.shape[2] == 3 else np.ones((n, j), dtype=bool)
    else:
        v = check_numeric(visible, "visible")
        if v.shape != (n, j):
            raise InputError(
                f"visible must be (N, J) = ({n}, {j}), one flag per joint; got shape {v.shape}"
            )
        if not np.isfinite(v).all():
            raise InputError("visible holds NaN or inf; give 0/1 or booleans")
        vis = v > 0
    alpha = check_real(threshold, "threshold", 0.0, low_inclusive=False)
    norm = check_numeric(normalizer, "normalizer")
    if norm.ndim == 0 and n == 1:
        norm = norm.reshape(1)
    if norm.shape != (n,):
        raise InputError(
            f"normalizer must be (N,) = ({n},), one length per sample; got shape {norm.shape}"
        )
    if not np.isfinite(norm).all() or (norm < 0).any():
        raise InputError(
            f"normalizer must be finite lengths >= 0; got {plain_repr(norm)} (a sample of "
            "length 0 is left out)"
        )
    counted = vis & (norm > 0)[:, None]
    bad = counted & ~np.isfinite(t[:, :, :2]).all(axis=2)
    if bad.any():
        s_, j_ = (int(i) for i in np.argwhere(bad)[0])
        raise InputError(
            f"truth of sample {s_}, joint {j_} is not finite but the joint counts: mark it "
            "invisible (visible 0 or v = 0)"
        )
    with np.errstate(invalid="ignore", over="ignore"):
        dist = np.hypot(p[:, :, 0] - t[:, :, 0], p[:, :, 1] - t[:, :, 1])
        found = dist / np.where(norm > 0, norm, 1.0)[:, None] < alpha  # NaN: False
    correct = np.count_nonzero(found & counted, axis=0)
    return PckScores.from_counts(correct, np.count_nonzero(counted, axis=0), alpha)


def pckh(
    pred: npt.ArrayLike,
    truth: npt.ArrayLike,
    visible: npt.ArrayLike | None,
    head_sizes: npt.ArrayLike,
    alpha: float = 0.5,
) -> PckScores:
    r"""PCKh (MPII): :func:`pck` with the head size as the normalizer, PCKh@0.5 by default.

    The head size is MPII's convention, :math:`0.6` times the diagonal of the annotated
    head rectangle (:func:`mpii_head_sizes`, ``SC_BIAS`` of the MPII evaluation code
    and of mmpose), so a joint is found within half of it: :math:`d < 0.3\, \lVert
    (x_2 - x_1, y_2 - y_1) \rVert`. mmpose's ``MpiiPCKAccuracy`` also shifts the
    predictions by +1 px (Matlab's 1-based pixels) before comparing: do that to the
    predictions when the truth is in MPII's 1-based coordinates.

    Parameters
    ----------
    pred, truth, visible
        As :func:`pck`.
    head_sizes : (N,) array_like
        The head size of each sample (already scaled by 0.6).
    alpha : float
        The fraction of the head size (0.5).

    Returns
    -------
    PckScores

    Examples
    --------
    >>> import numpy as np
    >>> heads = mpii_head_sizes([[0.0, 0.0, 30.0, 40.0]])  # 0.6 x 50 = 30 px
    >>> truth = np.zeros((1, 2, 2))
    >>> pred = np.array([[[14.0, 0.0], [16.0, 0.0]]])
    >>> pckh(pred, truth, None, heads).per_joint.tolist()  # within 15 px
    [1.0, 0.0]
    """
    return pck(pred, truth, visible, alpha, head_sizes)


def bbox_diagonal(boxes: npt.ArrayLike, box_format: str = "xywh") -> np.ndarray:
    r"""Per-sample box diagonals :math:`\sqrt{w^2 + h^2}`, the normalizer of PCK.

    Parameters
    ----------
    boxes : (N, 4) or (N, J, 2|3) array_like
        Boxes (``box_format``), or keypoints, whose tight box is taken over the labelled
        ones (``v > 0`` when there is a third column; finite ``x, y``): a sample with
        fewer than one labelled keypoint gets 0 (left out by :func:`pck`).
    box_format : {"xywh", "xyxy"}
        ``[x, y, w, h]`` (COCO) or corners ``[x1, y1, x2, y2]`` (VOC, MPII's head
        rectangles).

    Returns
    -------
    (N,) float64 ndarray

    Raises
    ------
    InputError
        Another shape, non-finite boxes, negative widths or heights.

    Examples
    --------
    >>> bbox_diagonal([[5, 5, 3, 4]]).tolist()
    [5.0]
    >>> bbox_diagonal([[[0, 0, 2], [6, 8, 2], [100, 100, 0]]]).tolist()  # v=0 left out
    [10.0]
    """
    fmt = check_choice(box_format, "box_format", ("xywh", "xyxy"))
    arr = check_numeric(boxes, "boxes")
    if arr.ndim == 2 and arr.shape[1] == 4:
        if not np.isfinite(arr).all():
            raise InputError("boxes hold NaN or inf; give finite boxes")
        wh = arr[:, 2:] if fmt == "xywh" else arr[:, 2:] - arr[:, :2]
        if (wh < 0).any():
            fix = "x2 < x1 or y2 < y1: swap them" if fmt == "xyxy" else "negative w or h"
            raise InputError(f"boxes ({fmt}) have {fix}; got {plain_repr(arr)}")
        return np.hypot(wh[:, 0], wh[:, 1])
    if arr.ndim == 3 and arr.shape[2] in (2, 3):
        ok = np.isfinite(arr[:, :, :2]).all(axis=2)
        if arr.shape[2] == 3:
            ok &= arr[:, :, 2] > 0
        x = np.where(ok, arr[:, :, 0], np.nan)
        y = np.where(ok, arr[:, :, 1], np.nan)
        out = np.zeros(arr.shape[0])
        has = ok.any(axis=1)
        if has.any():
            w = np.nanmax(x[has], axis=1) - np.nanmin(x[has], axis=1)
            h = np.nanmax(y[has], axis=1) - np.nanmin(y[has], axis=1)
            out[has] = np.hypot(w, h)
        return out
    raise InputError(f"boxes must be (N, 4) boxes or (N, J, 2|3) keypoints; got shape {arr.shape}")


def mpii_head_sizes(head_boxes: npt.ArrayLike) -> np.ndarray:
    r"""MPII head sizes: :math:`0.6 \sqrt{(x_2 - x_1)^2 + (y_2 - y_1)^2}` of each head
    rectangle (:data:`MPII_HEAD_SCALE`; the normalizer of :func:`pckh`).

    Parameters
    ----------
    head_boxes : (N, 4) array_like
        Head rectangles as corners ``[x1, y1, x2, y2]`` (MPII's ``x1, y1, x2, y2`` of
        each ``annorect``; ``headboxes_src`` of its ``gt_valid.mat`` transposed).

    Returns
    -------
    (N,) float64 ndarray

    Examples
    --------
    >>> mpii_head_sizes([[10, 10, 40, 50]]).tolist()
    [30.0]
    """
    arr = check_numeric(head_boxes, "head_boxes")
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(
            f"head_boxes must be (N, 4) corners [x1, y1, x2, y2]; got shape {arr.shape}"
        )
    if not np.isfinite(arr).all():
        raise InputError("head_boxes hold NaN or inf; give finite corners")
    # the length of the corner difference, whichever corner comes first (as MPII's code)
    return MPII_HEAD_SCALE * np.hypot(arr[:, 2] - arr[:, 0], arr[:, 3] - arr[:, 1])
