r"""Tracking against ground truth: single-object overlap (VOT / OTB success curve) and
multi-object CLEAR-MOT and identity (IDF1) metrics.

**Single object.** A VOT ``groundtruth.txt`` holds one region per frame: a rectangle
``x,y,w,h`` or a polygon ``x1,y1,...,xk,yk`` (VOT's rotated boxes are 4 corners),
converted to its axis-aligned bounding box :math:`[\min x, \max x] \times [\min y,
\max y]` as the VOT toolkit converts regions for axis-aligned trackers. Per frame the
overlap is the IoU :math:`o_t = |P_t \cap G_t| / |P_t \cup G_t|` of the predicted and
true boxes; frames without a target (NaN or empty truth) are left out, a frame without a
prediction scores 0. The success curve (Wu, Lim and Yang, OTB 2013) is

.. math::

    S(\tau) = \frac{1}{n} \#\{t : o_t > \tau\}, \qquad
    \mathrm{AUC} = \frac{1}{|T|} \sum_{\tau \in T} S(\tau)

over the thresholds :math:`T` (OTB's 21: 0, 0.05, ..., 1), as the OTB toolkit computes
it (strict :math:`>`, so a perfect tracker has AUC 20/21); the AUC tends to the mean IoU
as the thresholds get denser. The success rate at 0.5 is :math:`S(0.5)`.

**Multiple objects** (Bernardin and Stiefelhagen 2008, CLEAR MOT; the conventions of
py-motmetrics' ``MOTAccumulator``, which the tests match exactly on its TUD data). The
distance between a true box and a hypothesis is :math:`d = 1 - \mathrm{IoU}`, a pair
being allowed when :math:`d \le 1 - \theta` (:math:`\theta = 0.5`). In each frame:

1. a true object still paired with the hypothesis it was last matched to keeps it when
   the pair is allowed (a *match*);
2. the remaining objects and hypotheses are assigned by the Hungarian algorithm
   (``scipy.optimize.linear_sum_assignment``) with forbidden pairs priced at
   :math:`2 r c + 1` (:math:`r` the smaller side, :math:`c` one more than the largest
   distance), so the most pairs are made first, then the cheapest; a pair whose object
   was last matched to another hypothesis, in any earlier frame, is an *identity
   switch*, the others matches;
3. unassigned objects are misses (FN), unassigned hypotheses false positives (FP).

Then with :math:`g` the true boxes over all frames and :math:`c` the matches plus
switches,

.. math::

    \mathrm{MOTA} = 1 - \frac{FN + IDSW + FP}{g}, \qquad
    \mathrm{MOTP} = \frac{\sum_{\text{matches, switches}} d}{c}

(MOTP as motmetrics: the mean :math:`1 - \mathrm{IoU}`, lower is better; the
MOTChallenge devkit prints :math:`1 - \mathrm{MOTP}`). The identity metrics (Ristani et
al. 2016) match whole trajectories once: with :math:`n_{oh}` the frames where object
:math:`o` and hypothesis :math:`h` form an allowed pair, IDTP is the largest
:math:`\sum n_{oh}` over one-to-one pairings of objects with hypotheses (the same
optimum as motmetrics' min-cost IDFP + IDFN assignment, which equals
:math:`g + p - 2\,\mathrm{IDTP}`), and

.. math::

    \mathrm{IDF1} = \frac{2\,\mathrm{IDTP}}{g + p}, \quad
    \mathrm{IDP} = \frac{\mathrm{IDTP}}{p}, \quad \mathrm{IDR} = \frac{\mathrm{IDTP}}{g}

with :math:`p` the hypothesis boxes over all frames. A ratio whose denominator is 0 is
NaN.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_file,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
    check_size,
    check_text,
    plain_repr,
)
from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.geometry.boxes import box_iou_matrix
from robopercept.tracking.mot_io import MotRows

__all__ = [
    "OTB_THRESHOLDS",
    "MotAccumulator",
    "MotEvents",
    "MotMetrics",
    "SuccessScores",
    "evaluate_mot",
    "evaluate_single_object",
    "paired_iou",
    "polygons_to_boxes",
    "read_vot_groundtruth",
    "select_ground_truth",
    "success_plot",
]

#: OTB's overlap thresholds of the success curve: 0, 0.05, ..., 1
OTB_THRESHOLDS = np.linspace(0.0, 1.0, 21)
#: largest coordinate a ground-truth file may hold (areas of larger boxes overflow)
_LIMIT = 1e150


# ------------------------------------------------------------------ single object


def polygons_to_boxes(polygons: npt.ArrayLike) -> np.ndarray:
    r"""Axis-aligned bounding boxes ``(x, y, w, h)`` of polygons ``x1, y1, ..., xk, yk``,
    as the VOT toolkit converts a polygon region to a rectangle:
    :math:`x = \min_i x_i,\ w = \max_i x_i - \min_i x_i` (same in :math:`y`).

    Parameters
    ----------
    polygons : (N, 2k) or (2k,) array_like
        ``k >= 3`` vertices per row; a row with a NaN gives a NaN box.

    Returns
    -------
    (N, 4) ndarray of float64

    Raises
    ------
    InputError
        Not real numbers, an odd count or fewer than 3 vertices, inf.

    Examples
    --------
    >>> polygons_to_boxes([334.02, 128.36, 438.19, 188.78, 396.39, 260.83, 292.23, 200.41])
    array([[292.23, 128.36, 145.96, 132.47]])
    """
    p = check_numeric(polygons, "polygons")
    if p.ndim == 1:
        p = p[None]
    if p.ndim != 2 or p.shape[1] % 2 or p.shape[1] < 6:
        raise InputError(
            "polygons must be (N, 2k) vertices x1,y1,...,xk,yk with k >= 3 (a VOT rotated "
            f"box has 8 numbers); got shape {p.shape}"
        )
    if np.isinf(p).any():
        raise InputError("polygons must be finite (NaN marks a frame without target); got inf")
    check_magnitude(p, "polygons", _LIMIT)
    xs, ys = p[:, 0::2], p[:, 1::2]
    x0, y0 = xs.min(axis=1), ys.min(axis=1)
    return np.stack([x0, y0, xs.max(axis=1) - x0, ys.max(axis=1) - y0], axis=1)


def read_vot_groundtruth(path: str | Path) -> np.ndarray:
    """Read a VOT ``groundtruth.txt`` (one region per frame) as axis-aligned boxes.

    Each line is a rectangle ``x,y,w,h`` or a polygon of ``k >= 3`` vertices
    ``x1,y1,...,xk,yk`` (VOT's rotated boxes: ``k = 4``), converted to its bounding box
    (:func:`polygons_to_boxes`); commas, tabs or spaces separate the numbers (OTB files
    use either). A frame without the target is a line of NaN values, a single number (VOT's
    ``0``) or a box of zero width or height: its row is NaN. Trailing blank lines are
    ignored; line ``i`` is frame ``i - 1`` (0-based).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    (N, 4) ndarray of float64
        ``x, y, w, h`` per frame; NaN rows where the target is absent.

    Raises
    ------
    FileFormatError
        A missing file or a folder, not UTF-8 text, a blank line inside the file, a line
        that is not numbers or has 2, 3, 5 or an odd number (>= 5) of them, an inf, a
        negative width or height, values beyond 1e150, or no line at all; the message
        names the file and the line.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = pathlib.Path(d) / "groundtruth.txt"
    ...     _ = p.write_text("10,20,30,40\\n0,0,10,0,10,10,0,10\\nnan,nan,nan,nan\\n")
    ...     read_vot_groundtruth(p).tolist()
    [[10.0, 20.0, 30.0, 40.0], [0.0, 0.0, 10.0, 10.0], [nan, nan, nan, nan]]
    """
    path = check_file(path, "a VOT groundtruth.txt")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text file (a VOT groundtruth.txt)") from None
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise FileFormatError(f"{path}: no box; a VOT groundtruth.txt has one line per frame")
    boxes = np.full((len(lines), 4), np.nan)
    want = "x,y,w,h or a polygon x1,y1,...,xk,yk (k >= 3)"
    for i, line in enumerate(lines, start=1):
        fields = line.replace(",", " ").replace("\t", " ").split()
        if not fields:
            raise FileFormatError(
                f"{path}: line {i} is blank; a VOT groundtruth.txt has one region per frame "
                "(NaN,NaN,NaN,NaN for a frame without the target): fill or remove that line"
            )
        try:
            values = np.array([float(v) for v in fields])
        except ValueError:
            raise FileFormatError(
                f"{path}: line {i} ({line.strip()[:80]!r}) is not numbers; expected {want}"
            ) from None
        n = values.size
        if n == 1 or np.isnan(values).any():
            continue  # VOT's special codes and NaN rows: no target in this frame
        if n != 4 and (n < 6 or n % 2):
            raise FileFormatError(
                f"{path}: line {i} has {n} numbers; expected {want}: fix or drop that line"
            )
        if np.isinf(values).any() or np.abs(values).max() > _LIMIT:
            raise FileFormatError(
                f"{path}: line {i} ({line.strip()[:80]}): values must be finite and at most "
                f"{_LIMIT:g}; fix that line"
            )
        box = values if n == 4 else polygons_to_boxes(values)[0]
        if box[2] < 0 or box[3] < 0:
            raise FileFormatError(
                f"{path}: line {i} ({line.strip()[:80]}): negative width or height; a "
                "rectangle is x,y,w,h with w, h >= 0"
            )
        if box[2] > 0 and box[3] > 0:
            boxes[i - 1] = box
    return boxes


def _check_boxes(value: npt.ArrayLike, name: str, nan: bool = False) -> np.ndarray:
    """``value`` as float64 ``(N, 4)`` boxes ``x, y, w, h`` with ``w, h >= 0``; NaN rows
    allowed with ``nan`` (an absent box), never inf."""
    a = check_numeric(value, name)
    if a.ndim == 1 and a.size == 4:
        a = a[None]
    if a.size == 0:
        a = a.reshape(0, 4)
    if a.ndim != 2 or a.shape[1] != 4:
        raise InputError(f"{name} must be (N, 4) boxes x, y, w, h; got shape {a.shape}")
    if np.isinf(a).any() or (not nan and np.isnan(a).any()):
        absent = " (NaN marks a frame without a box)" if nan else ""
        raise InputError(f"{name} must hold finite numbers{absent}; got {plain_repr(a)[:80]}")
    check_magnitude(a, name, _LIMIT)
    with np.errstate(invalid="ignore"):
        if (a[:, 2:] < 0).any():
            raise InputError(f"{name} has a negative width or height: boxes are x, y, w, h")
    return a


def paired_iou(a: npt.ArrayLike, b: npt.ArrayLike) -> np.ndarray:
    r"""IoU of each box of ``a`` with the box of ``b`` in the same row:
    :math:`|A_i \cap B_i| / |A_i \cup B_i|` (0 where the union is empty; NaN where a
    row of either holds a NaN).

    The diagonal of :func:`~robopercept.geometry.box_iou_matrix` without its
    :math:`N^2` work.

    Parameters
    ----------
    a, b : (N, 4) array_like
        Boxes ``x, y, w, h``; NaN rows allowed.

    Returns
    -------
    (N,) ndarray of float64

    Raises
    ------
    InputError
        Other shapes, different lengths, inf, negative sizes.

    Examples
    --------
    >>> paired_iou([[0, 0, 2, 2], [0, 0, 1, 1]], [[1, 0, 2, 2], [5, 5, 1, 1]]).round(4)
    array([0.3333, 0.    ])
    """
    a = _check_boxes(a, "a", nan=True)
    b = _check_boxes(b, "b", nan=True)
    if len(a) != len(b):
        raise InputError(f"a and b must hold as many boxes; got {len(a)} and {len(b)}")
    w = np.minimum(a[:, 0] + a[:, 2], b[:, 0] + b[:, 2]) - np.maximum(a[:, 0], b[:, 0])
    h = np.minimum(a[:, 1] + a[:, 3], b[:, 1] + b[:, 3]) - np.maximum(a[:, 1], b[:, 1])
    inter = np.clip(w, 0, None) * np.clip(h, 0, None)
    union = a[:, 2] * a[:, 3] + b[:, 2] * b[:, 3] - inter
    with np.errstate(invalid="ignore"):
        iou = np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
    iou[np.isnan(union)] = np.nan
    return iou


@dataclass(frozen=True)
class SuccessScores:
    """Overlap of a single-object tracker with its ground truth
    (:func:`evaluate_single_object`).

    Attributes
    ----------
    ious : (N,) ndarray
        IoU per predicted frame; NaN where the truth has no target.
    thresholds : (T,) ndarray
        Overlap thresholds of the success curve.
    success : (T,) ndarray
        Fraction of the evaluated frames whose IoU exceeds each threshold.
    mean_iou : float
        Mean IoU over the evaluated frames.
    success_50 : float
        Fraction of the evaluated frames with IoU > 0.5.
    auc : float
        Mean of ``success`` (OTB's area under the curve).
    frames : int
        Frames evaluated (the target present in the truth).
    absent : int
        Predicted frames whose truth has no target (left out).
    """

    ious: np.ndarray
    thresholds: np.ndarray
    success: np.ndarray
    mean_iou: float
    success_50: float
    auc: float
    frames: int
    absent: int

    def to_dict(self, curve: bool = True) -> dict[str, Any]:
        """The scores as JSON-ready Python values (with the curve unless ``curve`` is
        False).

        Examples
        --------
        >>> s = evaluate_single_object([[0, 0, 10, 10]], [[0, 0, 10, 10]])
        >>> s.to_dict(curve=False)  # no IoU exceeds 1: a perfect run has AUC 20/21
        {'frames': 1, 'absent': 0, 'mean_iou': 1.0, 'success_50': 1.0, 'auc': 0.9523809523809523}
        """
        out: dict[str, Any] = {
            "frames": self.frames,
            "absent": self.absent,
            "mean_iou": self.mean_iou,
            "success_50": self.success_50,
            "auc": self.auc,
        }
        if curve:
            out["thresholds"] = [round(float(t), 6) for t in self.thresholds]
            out["success"] = [float(s) for s in self.success]
        return out


def evaluate_single_object(
    predicted: npt.ArrayLike,
    truth: npt.ArrayLike,
    *,
    frames: npt.ArrayLike | None = None,
    thresholds: npt.ArrayLike | None = None,
) -> SuccessScores:
    """Mean IoU, success rate at 0.5 and the success curve of a single-object tracker
    (the OTB protocol; see the module docstring for the formulas).

    Parameters
    ----------
    predicted : (N, 4) array_like
        Predicted boxes ``x, y, w, h``; a NaN row (no prediction) scores IoU 0.
    truth : (M, 4) array_like
        True boxes per frame (:func:`read_vot_groundtruth`); NaN rows: no target, left out.
    frames : (N,) array_like of int, optional
        The truth row of each prediction (0-based frame indices); default ``0 .. N-1``
        (then ``M >= N``). Truth rows not named are ignored.
    thresholds : (T,) array_like, optional
        Overlap thresholds in [0, 1], increasing; default :data:`OTB_THRESHOLDS`.

    Returns
    -------
    SuccessScores

    Raises
    ------
    InputError
        Bad shapes, inf or negative sizes, a frame index outside the truth, bad
        thresholds.
    DegenerateError
        No evaluated frame holds the target.

    Examples
    --------
    >>> s = evaluate_single_object([[0, 0, 10, 10], [5, 0, 10, 10]],
    ...                            [[0, 0, 10, 10], [0, 0, 10, 10]])
    >>> round(s.mean_iou, 4), s.success_50, round(s.auc, 4)
    (0.6667, 0.5, 0.6429)
    """
    pred = _check_boxes(predicted, "predicted", nan=True)
    gt = _check_boxes(truth, "truth", nan=True)
    if frames is None:
        idx = np.arange(len(pred))
    else:
        f = check_numeric(frames, "frames").reshape(-1)
        if f.size != len(pred) or (f.size and (f != np.round(f)).any()):
            raise InputError(
                f"frames must be one whole frame index per predicted box ({len(pred)}); "
                f"got {plain_repr(frames)[:80]}"
            )
        idx = f.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= len(gt)):
        raise InputError(
            f"truth has {len(gt)} boxes (frames 0-{len(gt) - 1}); the predictions reach frame "
            f"{int(idx.max())}: give the ground truth of the whole sequence"
        )
    t = OTB_THRESHOLDS if thresholds is None else check_numeric(thresholds, "thresholds")
    t = t.reshape(-1)
    if t.size == 0 or not np.isfinite(t).all() or (t < 0).any() or (t > 1).any() or (
        np.diff(t) <= 0).any():  # fmt: skip
        raise InputError(
            f"thresholds must be increasing numbers in [0, 1]; got {plain_repr(thresholds)[:80]}"
        )
    g = gt[idx]
    present = ~np.isnan(g).any(axis=1)
    if not present.any():
        raise DegenerateError(
            f"truth has no target in any of the {len(idx)} predicted frames: nothing to "
            "evaluate (NaN rows mark frames without the target)"
        )
    ious = np.full(len(idx), np.nan)
    ious[present] = np.nan_to_num(paired_iou(pred[present], g[present]), nan=0.0)
    o = ious[present]
    success = (o[None, :] > t[:, None]).mean(axis=1)
    return SuccessScores(
        ious=ious,
        thresholds=t.copy(),
        success=success,
        mean_iou=float(o.mean()),
        success_50=float((o > 0.5).mean()),
        auc=float(success.mean()),
        frames=int(present.sum()),
        absent=int((~present).sum()),
    )


def success_plot(
    scores: SuccessScores | Sequence[SuccessScores],
    labels: str | Sequence[str] | None = None,
    *,
    size: tuple[int, int] = (1280, 720),
    title: str = "Success plot",
) -> np.ndarray:
    """The success curve(s) as a picture (OTB's success plot), drawn with matplotlib
    (:func:`~robopercept.viz.figure.agg_figure`, fonts scaled to the picture).

    Parameters
    ----------
    scores : SuccessScores or sequence of them
        One curve each (at most 10).
    labels : str or sequence of str, optional
        Legend names; each gets its AUC, ``"meanshift [AUC 0.412]"`` as OTB writes it.
    size : (int, int)
        ``(width, height)`` in pixels, at least 320 x 240.
    title : str

    Returns
    -------
    (H, W, 3) ndarray of uint8

    Raises
    ------
    InputError
        Not SuccessScores, too many curves, labels that do not fit, a bad size, or
        matplotlib missing.

    Examples
    --------
    >>> s = evaluate_single_object([[0, 0, 10, 10]], [[1, 0, 10, 10]])
    >>> success_plot(s, "ours", size=(640, 360)).shape
    (360, 640, 3)
    """
    from robopercept.viz.figure import agg_figure, figure_to_rgb

    runs = [scores] if isinstance(scores, SuccessScores) else scores
    if (
        isinstance(runs, (str, bytes))
        or not isinstance(runs, Sequence)
        or not 1 <= len(runs) <= 10
        or not all(isinstance(s, SuccessScores) for s in runs)
    ):
        raise InputError(
            f"scores must be a SuccessScores or 1 to 10 of them; got {plain_repr(scores)[:80]}"
        )
    if labels is None:
        names = [f"run {k + 1}" for k in range(len(runs))] if len(runs) > 1 else ["tracker"]
    else:
        given = [labels] if isinstance(labels, str) else labels
        if (
            isinstance(given, (str, bytes))
            or not isinstance(given, Sequence)
            or len(given) != len(runs)
        ):
            raise InputError(
                f"labels must be one name per curve ({len(runs)}); got {plain_repr(labels)[:80]}"
            )
        names = [check_text(n, "labels") for n in given]
    w, h = check_size(size, "size", minimum=240, maximum=8192)
    if w < 320:
        raise InputError(f"size must be at least 320 x 240 pixels; got {w} x {h}")
    fig = agg_figure(w, h, reference_width=1280, layout="constrained", what="success_plot")
    ax = fig.add_subplot()
    for s, name in zip(runs, names, strict=True):
        ax.plot(s.thresholds, s.success, marker="o", markersize=5, linewidth=2.5,
                label=f"{name} [AUC {s.auc:.3f}]")  # fmt: skip
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel("overlap threshold (IoU)", fontsize=15)
    ax.set_ylabel("success rate (fraction of frames)", fontsize=15)
    ax.set_title(check_text(title, "title"), fontsize=17)
    ax.tick_params(labelsize=13)
    ax.grid(True, alpha=0.35)
    ax.legend(loc="best", fontsize=13)
    return figure_to_rgb(fig)


# ----------------------------------------------------------------- multiple objects


@dataclass(frozen=True)
class MotEvents:
    """The events of one frame of :class:`MotAccumulator` (ids as given).

    Attributes
    ----------
    matches, switches : tuple of (object id, hypothesis id)
    misses : tuple of object ids
    false_positives : tuple of hypothesis ids
    """

    matches: tuple[tuple[int, int], ...]
    switches: tuple[tuple[int, int], ...]
    misses: tuple[int, ...]
    false_positives: tuple[int, ...]


@dataclass(frozen=True)
class MotMetrics:
    """CLEAR-MOT and identity metrics (:class:`MotAccumulator`; formulas in the module
    docstring; names as motmetrics').

    Attributes
    ----------
    mota, motp, idf1, idp, idr, precision, recall : float
        NaN when undefined (no true box, no match). ``motp`` is the mean ``1 - IoU``
        of the matches (motmetrics); ``precision`` = (matches + switches) / hypotheses,
        ``recall`` = (matches + switches) / true boxes.
    num_switches, num_false_positives, num_misses, num_matches : int
        Event counts (``num_matches`` excludes switches, as motmetrics).
    num_objects, num_predictions, num_frames : int
        True boxes, hypothesis boxes and frames evaluated.
    num_unique_objects : int
        Distinct true ids.
    idtp, idfp, idfn : int
        Identity true positives, false positives, false negatives.
    """

    mota: float
    motp: float
    idf1: float
    idp: float
    idr: float
    precision: float
    recall: float
    num_switches: int
    num_false_positives: int
    num_misses: int
    num_matches: int
    num_objects: int
    num_predictions: int
    num_frames: int
    num_unique_objects: int
    idtp: int
    idfp: int
    idfn: int

    def to_dict(self) -> dict[str, float | int | None]:
        """Every metric as a JSON-ready value (NaN as None).

        Examples
        --------
        >>> acc = MotAccumulator()
        >>> _ = acc.update([1], [[0, 0, 10, 10]], [7], [[0, 0, 10, 10]])
        >>> d = acc.metrics().to_dict()
        >>> d["mota"], d["idf1"], d["num_matches"]
        (1.0, 1.0, 1)
        """
        out: dict[str, float | int | None] = {}
        for name in self.__dataclass_fields__:
            v = getattr(self, name)
            out[name] = None if isinstance(v, float) and not np.isfinite(v) else v
        return out


def _ratio(a: float, b: float) -> float:
    return float(a) / float(b) if b else float("nan")


def _check_ids(value: npt.ArrayLike, name: str, n: int) -> list[int]:
    """``n`` distinct whole-number ids as Python ints."""
    a = check_numeric(value, name).reshape(-1)
    if a.size != n:
        raise InputError(f"{name} must hold one id per box ({n}); got {a.size}")
    if a.size and (not np.isfinite(a).all() or (a != np.round(a)).any()
                   or np.abs(a).max() >= 2.0**53):  # fmt: skip
        raise InputError(f"{name} must be whole numbers below 2^53; got {plain_repr(a)[:80]}")
    ids = [int(v) for v in a]
    if len(set(ids)) != len(ids):
        dup = next(v for v in ids if ids.count(v) > 1)
        raise InputError(
            f"{name} holds id {dup} twice in one frame: the ids of a frame must be distinct"
        )
    return ids


def _assign(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hungarian assignment of ``cost`` (NaN: forbidden) as motmetrics'
    ``lsa_solve_scipy``: the most allowed pairs, then the least cost."""
    from scipy.optimize import linear_sum_assignment

    valid = np.isfinite(cost)
    if not valid.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    big = 2 * min(cost.shape) * (np.abs(cost[valid]).max() + 1) + 1
    rows, cols = linear_sum_assignment(np.where(valid, cost, big))
    keep = valid[rows, cols]
    return rows[keep], cols[keep]


@dataclass
class MotAccumulator:
    """CLEAR-MOT events frame by frame, with motmetrics' ``MOTAccumulator`` rules
    (module docstring): kept matches, Hungarian assignment of the rest, identity
    switches against the last match of each object, ever.

    Parameters
    ----------
    iou_threshold : float
        Least IoU of an allowed pair, in (0, 1] (motmetrics' ``max_iou = 1 - theta``;
        default 0.5, the MOTChallenge rule).

    Examples
    --------
    >>> acc = MotAccumulator()
    >>> acc.update([1, 2], [[0, 0, 10, 10], [20, 0, 10, 10]],
    ...            [5, 6], [[0, 0, 10, 10], [21, 0, 10, 10]])  # doctest: +ELLIPSIS
    MotEvents(matches=((1, 5), (2, 6)), switches=(), misses=(), false_positives=())
    >>> acc.update([1, 2], [[0, 0, 10, 10], [20, 0, 10, 10]],
    ...            [6], [[0, 0, 10, 10]]).switches
    ((1, 6),)
    >>> m = acc.metrics()
    >>> m.num_switches, m.num_misses, round(m.mota, 3)
    (1, 1, 0.5)
    """

    iou_threshold: float = 0.5
    _last: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    _counts: dict[str, int] = field(default_factory=dict, init=False, repr=False)
    _dist_sum: float = field(default=0.0, init=False, repr=False)
    _ocs: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    _hcs: dict[int, int] = field(default_factory=dict, init=False, repr=False)
    _tps: dict[tuple[int, int], int] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        self.iou_threshold = check_real(
            self.iou_threshold, "iou_threshold", 0.0, 1.0, low_inclusive=False
        )
        self._counts = dict.fromkeys(
            ("frames", "objects", "predictions", "matches", "switches", "misses", "fp"), 0
        )

    def update(
        self,
        gt_ids: npt.ArrayLike,
        gt_boxes: npt.ArrayLike,
        hyp_ids: npt.ArrayLike,
        hyp_boxes: npt.ArrayLike,
    ) -> MotEvents:
        """Add one frame: the true objects and the tracker's hypotheses.

        Parameters
        ----------
        gt_ids : (G,) array_like of int
            Distinct object ids.
        gt_boxes : (G, 4) array_like
            ``x, y, w, h``, finite, ``w, h >= 0``.
        hyp_ids : (H,) array_like of int
        hyp_boxes : (H, 4) array_like

        Returns
        -------
        MotEvents

        Raises
        ------
        InputError
            Bad shapes, non-finite boxes, negative sizes, ids that are not distinct
            whole numbers, or not one id per box.
        """
        gb = _check_boxes(gt_boxes, "gt_boxes")
        hb = _check_boxes(hyp_boxes, "hyp_boxes")
        oids = _check_ids(gt_ids, "gt_ids", len(gb))
        hids = _check_ids(hyp_ids, "hyp_ids", len(hb))
        c = self._counts
        c["frames"] += 1
        c["objects"] += len(oids)
        c["predictions"] += len(hids)
        for o in oids:
            self._ocs[o] = self._ocs.get(o, 0) + 1
        for h in hids:
            self._hcs[h] = self._hcs.get(h, 0) + 1
        matches: list[tuple[int, int]] = []
        switches: list[tuple[int, int]] = []
        o_done = np.zeros(len(oids), bool)
        h_done = np.zeros(len(hids), bool)
        if oids and hids:
            dist = 1.0 - box_iou_matrix(gb, hb)
            dist[dist > 1.0 - self.iou_threshold] = np.nan
            for i, j in zip(*np.nonzero(np.isfinite(dist)), strict=True):
                key = (oids[i], hids[j])
                self._tps[key] = self._tps.get(key, 0) + 1
            col = {h: j for j, h in enumerate(hids)}
            for i, o in enumerate(oids):  # 1. keep the pairs of the last frames
                previous = self._last.get(o)
                j = -1 if previous is None else col.get(previous, -1)
                if j >= 0 and not h_done[j] and np.isfinite(dist[i, j]):
                    o_done[i] = h_done[j] = True
                    matches.append((o, hids[j]))
                    self._dist_sum += float(dist[i, j])
            rest = dist.copy()
            rest[o_done, :] = np.nan
            rest[:, h_done] = np.nan
            for i, j in zip(*_assign(rest), strict=True):  # 2. assign the others
                o, h = oids[i], hids[j]
                (switches if o in self._last and self._last[o] != h else matches).append((o, h))
                self._last[o] = h
                o_done[i] = h_done[j] = True
                self._dist_sum += float(dist[i, j])
        misses = tuple(o for o, done in zip(oids, o_done, strict=True) if not done)
        fps = tuple(h for h, done in zip(hids, h_done, strict=True) if not done)
        c["matches"] += len(matches)
        c["switches"] += len(switches)
        c["misses"] += len(misses)
        c["fp"] += len(fps)
        return MotEvents(tuple(matches), tuple(switches), misses, fps)

    def metrics(self) -> MotMetrics:
        """The metrics of the frames so far.

        Returns
        -------
        MotMetrics
        """
        from scipy.optimize import linear_sum_assignment

        c = self._counts
        idtp = 0
        if self._tps:
            o_index = {o: k for k, o in enumerate(self._ocs)}
            h_index = {h: k for k, h in enumerate(self._hcs)}
            n = np.zeros((len(o_index), len(h_index)))
            for (o, h), count in self._tps.items():
                n[o_index[o], h_index[h]] = count
            rows, cols = linear_sum_assignment(n, maximize=True)
            idtp = int(n[rows, cols].sum())
        g, p = c["objects"], c["predictions"]
        found = c["matches"] + c["switches"]
        return MotMetrics(
            mota=1.0 - _ratio(c["misses"] + c["switches"] + c["fp"], g) if g else float("nan"),
            motp=_ratio(self._dist_sum, found),
            idf1=_ratio(2 * idtp, g + p),
            idp=_ratio(idtp, p),
            idr=_ratio(idtp, g),
            precision=_ratio(found, p),
            recall=_ratio(found, g),
            num_switches=c["switches"],
            num_false_positives=c["fp"],
            num_misses=c["misses"],
            num_matches=c["matches"],
            num_objects=g,
            num_predictions=p,
            num_frames=c["frames"],
            num_unique_objects=len(self._ocs),
            idtp=idtp,
            idfp=p - idtp,
            idfn=g - idtp,
        )


def select_ground_truth(rows: MotRows, classes: Iterable[int] | None = (1,)) -> MotRows:
    """The rows of a MOTChallenge ``gt.txt`` that count: flag (7th column) not 0, and in
    the 9-column files of MOT16/17/20 (``frame,id,x,y,w,h,flag,class,visibility``) a
    class of ``classes`` or -1 (1 = pedestrian, the class the devkit evaluates). Files of
    other widths (6 columns; MOT15 and TUD with world coordinates in columns 8-10) keep
    every row whose flag is not 0.

    Parameters
    ----------
    rows : MotRows
        :func:`~robopercept.tracking.read_mot` of the ``gt.txt``.
    classes : iterable of int or None
        Classes kept; None keeps every class.

    Returns
    -------
    MotRows

    Raises
    ------
    InputError
        ``rows`` not MotRows, or classes not whole numbers.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.tracking import read_mot
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = pathlib.Path(d) / "gt.txt"
    ...     _ = p.write_text("1,1,0,0,9,9,1,1,1\\n1,2,0,0,9,9,0,1,1\\n1,3,0,0,9,9,1,3,1\\n")
    ...     select_ground_truth(read_mot(p)).id.tolist()
    [1]
    """
    if not isinstance(rows, MotRows):
        raise InputError(f"rows must be MotRows (read_mot); got {plain_repr(rows)[:60]}")
    keep = rows.conf != 0
    if classes is not None and rows.extra.shape[1] == 2:  # the MOT16+ ground truth
        if isinstance(classes, (str, bytes)) or not isinstance(classes, Iterable):
            raise InputError(f"classes must be whole numbers or None; got {plain_repr(classes)}")
        wanted = [check_int(k, "classes") for k in classes]
        cls = rows.extra[:, 0]
        keep &= (cls == -1) | np.isin(cls, wanted)
    return MotRows(rows.frame[keep], rows.id[keep], rows.boxes[keep], rows.conf[keep],
                   rows.extra[keep])  # fmt: skip


def evaluate_mot(
    ground_truth: MotRows,
    hypotheses: MotRows,
    *,
    iou_threshold: float = 0.5,
    frames: npt.ArrayLike | None = None,
) -> MotMetrics:
    """CLEAR-MOT and IDF1 of a MOTChallenge results file against its ground truth, as
    motmetrics' ``compare_to_groundtruth(gt, dt, "iou", distth=1 - iou_threshold)``
    then ``compute`` (one :class:`MotAccumulator` over the frames).

    Parameters
    ----------
    ground_truth : MotRows
        The true boxes (pass them through :func:`select_ground_truth` first for a
        MOTChallenge ``gt.txt``).
    hypotheses : MotRows
        The tracker's rows (:func:`~robopercept.tracking.read_mot` of its results).
    iou_threshold : float
        Least IoU of a match (default 0.5).
    frames : array_like of int, optional
        Frame numbers to evaluate (the frames the tracker saw); default every frame of
        either file, as motmetrics (a frame missing from the results counts its true
        boxes as misses).

    Returns
    -------
    MotMetrics

    Raises
    ------
    InputError
        Not MotRows, a repeated id within a frame (says which), bad threshold or frames.

    Examples
    --------
    >>> from robopercept.tracking.mot_io import MotRows
    >>> def rows(f, i, b):
    ...     f, i, b = np.array(f), np.array(i), np.array(b, float)
    ...     return MotRows(f, i, b, np.ones(len(f)), np.zeros((len(f), 0)))
    >>> gt = rows([1, 2], [1, 1], [[0, 0, 10, 10], [2, 0, 10, 10]])
    >>> hyp = rows([1, 2, 2], [4, 4, 9], [[0, 0, 10, 10], [2, 0, 10, 10], [50, 50, 5, 5]])
    >>> m = evaluate_mot(gt, hyp)
    >>> m.num_matches, m.num_false_positives, round(m.mota, 2), round(m.idf1, 2)
    (2, 1, 0.5, 0.8)
    """
    for name, r in (("ground_truth", ground_truth), ("hypotheses", hypotheses)):
        if not isinstance(r, MotRows):
            raise InputError(f"{name} must be MotRows (read_mot); got {plain_repr(r)[:60]}")
    if frames is None:
        numbers = np.union1d(ground_truth.frame, hypotheses.frame)
    else:
        f = check_numeric(frames, "frames").reshape(-1)
        if f.size and (not np.isfinite(f).all() or (f != np.round(f)).any()):
            raise InputError(f"frames must be whole frame numbers; got {plain_repr(frames)[:80]}")
        numbers = np.unique(f.astype(np.int64))
    acc = MotAccumulator(iou_threshold)
    g_order = np.argsort(ground_truth.frame, kind="stable")
    h_order = np.argsort(hypotheses.frame, kind="stable")
    g_frames, h_frames = ground_truth.frame[g_order], hypotheses.frame[h_order]
    for number in numbers:
        gs = g_order[np.searchsorted(g_frames, number) : np.searchsorted(g_frames, number, "right")]
        hs = h_order[np.searchsorted(h_frames, number) : np.searchsorted(h_frames, number, "right")]
        try:
            acc.update(ground_truth.id[gs], ground_truth.boxes[gs], hypotheses.id[hs],
                       hypotheses.boxes[hs])  # fmt: skip
        except InputError as exc:
            raise InputError(f"frame {int(number)}: {exc}") from None
    return acc.metrics()
