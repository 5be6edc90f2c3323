r"""The COCO evaluation (``pycocotools.cocoeval.COCOeval``) of boxes, masks and keypoints.

NumPy only (no torch): the matching kernel (compiled by numba, with its plain-Python
reference), the accumulation, the summary numbers (:class:`CocoEvaluation`), the object
keypoint similarity (:func:`keypoint_oks`) and the per-class precision-recall picture
(:func:`pr_curves_picture`, drawn by :mod:`robopercept.viz`). The records it reads are
:class:`~robopercept.nn.coco.dataset.CocoDataset` and
:class:`~robopercept.nn.coco.results.CocoResults`; the Pascal-VOC AP is
:mod:`robopercept.nn.coco.voc`.

Evaluation
----------
:func:`evaluate_detections` is the COCO evaluation of ``pycocotools.cocoeval.COCOeval``
(``iouType="bbox"`` and ``"segm"``) reimplemented with NumPy arrays and one compiled
matching kernel (for masks, the IoU below is that of the masks,
:func:`~robopercept.nn.coco.rle.rle_iou`, with the same crowd rule).
For every image and category, detections sorted by score (stable) and cut to the last
``max_dets`` are matched greedily to ground truth, for each of the 10 IoU thresholds
:math:`t \in \{.50, .55, \ldots, .95\}` and each area range (all, small < 32², medium,
large > 96²):

* the IoU of boxes :math:`d, g` (xywh) is
  :math:`\mathrm{IoU} = |d \cap g| / (|d| + |g| - |d \cap g|)`, except for a crowd
  ground truth, where the denominator is the detection's own area :math:`|d|`;
* ground truth is *ignored* when it is a crowd region or its ``area`` lies outside the
  area range; ignored ground truth is tried last, and a detection already matched to
  a real one stops there;
* each detection takes the ground truth of largest IoU :math:`\ge \min(t, 1-10^{-10})`
  not yet taken (a crowd region may be taken again); a detection matched to ignored
  ground truth is ignored, and so is an unmatched detection whose area (``w h``) lies
  outside the area range.

Per category, area range and ``max_dets`` :math:`M`, the first :math:`M` detections of
each image are pooled and sorted by score (stable: image order, then rank), and with
:math:`TP_n, FP_n` the cumulative counts of matched and unmatched non-ignored detections
and :math:`P` the number of non-ignored ground truth,

.. math::

    r_n = TP_n / P, \qquad p_n = TP_n / (TP_n + FP_n + \epsilon),\qquad
    \hat p_n = \max_{m \ge n} p_m,

and precision is :math:`\hat p` sampled at the 101 recall points
:math:`\rho \in \{0, .01, \ldots, 1\}` (at the first :math:`n` with :math:`r_n \ge \rho`;
0 where recall never reaches :math:`\rho`); recall is :math:`r` at the last detection.
A category with no non-ignored ground truth gets -1 throughout. The 12 summary numbers
are means over the entries that are not -1: AP, AP50, AP75, APs, APm, APl (precision),
AR1, AR10, AR100, ARs, ARm, ARl (recall), -1 when there are none.

The result equals pycocotools to rounding (the tests check 1e-9 on the arrays and the
summary) with one deliberate difference: pycocotools records a match by the matched
annotation's ``id``, so ground truth with ``id`` 0 counts as unmatched there; here a
match is a match whatever the id.

Edge cases, each tested: a box of zero width or height has IoU 0 with everything (the
object stays in the recall, the detection is a false positive), as in pycocotools; an
empty results list gives AP 0 for every category with ground truth (pycocotools'
``loadRes`` cannot take one); a data set without ground truth gives -1 everywhere.

Keypoints
---------
``evaluate_detections(gt, results, "keypoints")`` is ``COCOeval(..., iouType="keypoints")``:
the same matching and accumulation with the object keypoint similarity (OKS) in place
of the IoU (:func:`keypoint_oks`). For a detection :math:`d` and ground truth
:math:`g` of area :math:`s` (its ``area`` field) with keypoints
:math:`(x_i, y_i, v_i)`, per-keypoint constants :math:`\sigma_i` and
:math:`\kappa_i^2 = (2\sigma_i)^2`,

.. math::

    e_i = \frac{\Delta x_i^2 + \Delta y_i^2}{2\, \kappa_i^2\, (s + \epsilon)},\qquad
    \mathrm{OKS} = \frac{1}{|L|}\sum_{i \in L} e^{-e_i},

with :math:`L = \{i : v_i > 0\}` and :math:`\Delta = d_i - g_i`; when the ground truth
has no labelled keypoint, :math:`L` is every keypoint and :math:`\Delta` is the
distance from :math:`d_i` to the box :math:`[x - w, x + 2w] \times [y - h, y + 2h]`
(its ``bbox`` tripled about its centre). :math:`\epsilon` is ``np.spacing(1)``. Ground
truth with ``num_keypoints == 0`` is ignored (as crowd regions are); a detection's
area, for the area ranges, is that of its box, which for keypoint results without a
``bbox`` is the tight box of all its keypoints (as ``loadRes`` makes it). The area
ranges are all, medium and large, ``max_dets`` is (20,), and the 10 summary numbers
are AP, AP50, AP75, APm, APl, AR, AR50, AR75, ARm, ARl
(:data:`KEYPOINT_SUMMARY_NAMES`). The sigmas default to COCO's 17
(:data:`robopercept.nn.skeleton.COCO_17`); any other layout passes its own
(pycocotools' ``params.kpt_oks_sigmas``).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.imaging import write_image
from robopercept.nn.coco._fields import readonly
from robopercept.nn.coco.dataset import CocoDataset, as_coco_dataset
from robopercept.nn.coco.results import CocoResults, as_coco_results
from robopercept.nn.coco.rle import annotation_to_rle, rle_area, rle_iou
from robopercept.nn.skeleton import COCO_17
from robopercept.viz.learning import precision_recall_picture

__all__ = [
    "AREA_RANGES",
    "IOU_THRESHOLDS",
    "KEYPOINT_SUMMARY_NAMES",
    "RECALL_THRESHOLDS",
    "SUMMARY_NAMES",
    "CocoEvaluation",
    "evaluate_detections",
    "keypoint_oks",
    "pr_curves_picture",
    "write_pr_curves",
]

#: the 10 IoU thresholds .50:.05:.95 of COCO (as ``np.linspace`` makes them, like pycocotools)
IOU_THRESHOLDS = np.linspace(0.5, 0.95, 10)
#: the 101 recall points 0:.01:1
RECALL_THRESHOLDS = np.linspace(0.0, 1.0, 101)
#: area ranges (all, small, medium, large) in pixels², bounds included
AREA_RANGES = np.array(
    [[0.0, 1e5**2], [0.0, 32.0**2], [32.0**2, 96.0**2], [96.0**2, 1e5**2]], dtype=np.float64
)
AREA_NAMES = ("all", "small", "medium", "large")
#: the names of the 12 summary numbers, in COCOeval.stats' order
SUMMARY_NAMES = (
    "AP",
    "AP50",
    "AP75",
    "APs",
    "APm",
    "APl",
    "AR1",
    "AR10",
    "AR100",
    "ARs",
    "ARm",
    "ARl",
)

#: the names of the 10 keypoint summary numbers, in COCOeval.stats' order (iouType
#: "keypoints"; OKS thresholds in place of IoU, maxDets 20)
KEYPOINT_SUMMARY_NAMES = (
    "AP",
    "AP50",
    "AP75",
    "APm",
    "APl",
    "AR",
    "AR50",
    "AR75",
    "ARm",
    "ARl",
)
#: the keypoint evaluation's area ranges: all, medium, large (pycocotools' setKpParams)
_KP_AREAS = AREA_RANGES[[0, 2, 3]]
_KP_AREA_NAMES = ("all", "medium", "large")

_EMPTY_I = np.zeros(0, dtype=np.int64)


def _match_groups(
    groups: np.ndarray,
    gt_boxes: np.ndarray,
    gt_area: np.ndarray,
    gt_flags: np.ndarray,
    dt_boxes: np.ndarray,
    dt_area: np.ndarray,
    given: tuple[np.ndarray, np.ndarray],
    params: tuple[np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COCO's greedy matching for every (image, category) group.

    ``groups`` (G, 4) int64 holds ``gt_start, gt_stop, dt_start, dt_stop``; the
    detections of a group are sorted by score (stable) and cut to max_dets[-1].
    ``gt_flags`` (2, n_gt) bool: row 0 crowd (IoU over the detection's area, may be
    matched again), row 1 ignored in every area range (crowd regions; for keypoints
    also ground truth without labelled keypoints).
    ``dt_area`` (n_dt,) is each detection's area (for the area ranges). ``given`` =
    (IoUs, offsets): when ``offsets`` (G,) is not empty, group ``g``'s (nd, ng) IoU
    matrix is ``IoUs[offsets[g]:offsets[g] + nd ng]`` row-major (masks, computed
    outside), otherwise the IoU of the boxes (xywh) is computed here.
    ``params`` = (iou thresholds (T,), area ranges (A, 2)). Returns ``dt_matched``,
    ``dt_ignored`` (A, T, n_dt) and ``gt_ignored`` (A, n_gt) bool arrays.

    This plain-Python function is the reference; :func:`_match_groups_jit` is it
    compiled by numba (the tests compare them).
    """
    thrs, areas = params
    n_t = thrs.shape[0]
    n_a = areas.shape[0]
    n_dt = dt_boxes.shape[0]
    n_gt = gt_boxes.shape[0]
    dt_m = np.zeros((n_a, n_t, n_dt), dtype=np.bool_)
    dt_ig = np.zeros((n_a, n_t, n_dt), dtype=np.bool_)
    gt_ig = np.zeros((n_a, n_gt), dtype=np.bool_)
    given_ious, offsets = given
    gt_crowd = gt_flags[0]
    gt_base = gt_flags[1]
    for g in range(groups.shape[0]):
        g0, g1, d0, d1 = groups[g, 0], groups[g, 1], groups[g, 2], groups[g, 3]
        ng = g1 - g0
        nd = d1 - d0
        if nd == 0:
            for a in range(n_a):
                for j in range(g0, g1):
                    gt_ig[a, j] = gt_base[j] or gt_area[j] < areas[a, 0] or gt_area[j] > areas[a, 1]
            continue
        # IoU (nd, ng) as pycocotools' bbIou computes it (same operations, same order)
        ious = np.zeros((nd, ng))
        if offsets.size:
            o = offsets[g]
            for i in range(nd):
                for j in range(ng):
                    ious[i, j] = given_ious[o + i * ng + j]
        else:
            for j in range(ng):
                gx, gy, gw, gh = (
                    gt_boxes[g0 + j, 0],
                    gt_boxes[g0 + j, 1],
                    gt_boxes[g0 + j, 2],
                    gt_boxes[g0 + j, 3],
                )
                ga = gw * gh
                for i in range(nd):
                    dx, dy, dw, dh = (
                        dt_boxes[d0 + i, 0],
                        dt_boxes[d0 + i, 1],
                        dt_boxes[d0 + i, 2],
                        dt_boxes[d0 + i, 3],
                    )
                    w = min(dw + dx, gw + gx) - max(dx, gx)
                    if w <= 0:
                        continue
                    h = min(dh + dy, gh + gy) - max(dy, gy)
                    if h <= 0:
                        continue
                    inter = w * h
                    da = dw * dh
                    u = da if gt_crowd[g0 + j] else da + ga - inter
                    ious[i, j] = inter / u
        order = np.empty(ng, dtype=np.int64)
        ign = np.zeros(ng, dtype=np.bool_)
        taken = np.zeros(ng, dtype=np.bool_)
        for a in range(n_a):
            lo, hi = areas[a, 0], areas[a, 1]
            # ground truth: not ignored first, then ignored (each in file order)
            k = 0
            for flag in (False, True):
                for j in range(ng):
                    ig = gt_base[g0 + j] or gt_area[g0 + j] < lo or gt_area[g0 + j] > hi
                    if ig == flag:
                        order[k] = j
                        ign[k] = ig
                        k += 1
            for j in range(ng):
                gt_ig[a, g0 + order[j]] = ign[j]
            for t in range(n_t):
                taken[:] = False
                for i in range(nd):
                    best = min(thrs[t], 1 - 1e-10)
                    m = -1
                    for jj in range(ng):
                        j = order[jj]
                        if taken[jj] and not gt_crowd[g0 + j]:
                            continue
                        if m > -1 and not ign[m] and ign[jj]:
                            break
                        if ious[i, j] < best:
                            continue
                        best = ious[i, j]
                        m = jj
                    if m > -1:
                        dt_ig[a, t, d0 + i] = ign[m]
                        dt_m[a, t, d0 + i] = True
                        taken[m] = True
                    elif dt_area[d0 + i] < lo or dt_area[d0 + i] > hi:
                        dt_ig[a, t, d0 + i] = True
    return dt_m, dt_ig, gt_ig


_match_groups_jit = njit(cache=True)(_match_groups)


@dataclass(frozen=True, eq=False)
class CocoEvaluation:
    """The COCO evaluation's arrays and summary (what ``COCOeval.eval`` and ``.stats`` hold).

    Attributes
    ----------
    precision : (T, R, K, A, M) float64 ndarray
        Interpolated precision at the 101 recall points (-1 where undefined).
    recall : (T, K, A, M) float64 ndarray
    scores : (T, R, K, A, M) float64 ndarray
        The score at which each precision sample is reached (0 beyond the last).
    stats : (S,) float64 ndarray
        The summary numbers named by ``summary_names`` (-1 undefined): for boxes and
        masks the 12 AP, AP50, AP75, APs, APm, APl, AR1, AR10, AR100, ARs, ARm, ARl;
        for keypoints the 10 AP, AP50, AP75, APm, APl, AR, AR50, AR75, ARm, ARl.
    category_ids : (K,) int64 ndarray
    iou_thresholds : (T,) ndarray
        IoU thresholds (OKS thresholds for keypoints).
    recall_thresholds : (R,) ndarray
    max_dets : tuple of int
        (M,) values.
    summary_names : tuple of str
        The names of ``stats``: :data:`SUMMARY_NAMES` or :data:`KEYPOINT_SUMMARY_NAMES`.
    area_names : tuple of str
        The (A,) area ranges: all, small, medium, large (all, medium, large for
        keypoints).
    iou_type : str
        "bbox", "segm" or "keypoints".
    """

    precision: np.ndarray
    recall: np.ndarray
    scores: np.ndarray
    stats: np.ndarray
    category_ids: np.ndarray
    iou_thresholds: np.ndarray
    recall_thresholds: np.ndarray
    max_dets: tuple[int, ...]
    summary_names: tuple[str, ...] = SUMMARY_NAMES
    area_names: tuple[str, ...] = AREA_NAMES
    iou_type: str = "bbox"

    def summary(self) -> dict[str, float]:
        """The summary numbers by name (``summary_names``: the 12 of
        :data:`SUMMARY_NAMES`, or the 10 of :data:`KEYPOINT_SUMMARY_NAMES`)."""
        return dict(zip(self.summary_names, self.stats.tolist(), strict=True))

    def per_category_ap(self, iou: str = "0.50:0.95") -> dict[int, float]:
        """AP per category id (area all, the largest max_dets): ``iou`` is
        ``"0.50:0.95"``, ``"0.50"`` or ``"0.75"``; -1 for a category without ground truth.
        """
        t = {"0.50:0.95": slice(None), "0.50": slice(0, 1), "0.75": slice(5, 6)}
        check_choice(iou, "iou", t)
        p = self.precision[t[iou], :, :, 0, -1]
        out = {}
        for k, c in enumerate(self.category_ids.tolist()):
            v = p[:, :, k]
            out[c] = float(v[v > -1].mean()) if (v > -1).any() else -1.0
        return out


def _mask_ious(
    gt: CocoDataset,
    res: CocoResults,
    g_ord: np.ndarray,
    d_ord: np.ndarray,
    groups: np.ndarray,
) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """The ``segm`` evaluation's IoUs: per group (rows of ``groups``, over the ground
    truth in ``g_ord`` and the detections in ``d_ord`` order) the (nd, ng) mask IoU,
    flattened into one array with each group's offset, and each detection's mask
    area."""
    sizes = {i.id: (i.height, i.width) for i in gt.images}
    # (no annotation or no result: nothing to check; the IoUs are empty)
    if len(gt.ann_ids) and (not gt.segmentations or any(sg is None for sg in gt.segmentations)):
        k = 0 if not gt.segmentations else [sg is None for sg in gt.segmentations].index(True)
        raise InputError(
            f"annotation id {int(gt.ann_ids[k])} has no segmentation: iou_type='segm' "
            "needs polygons or an RLE on every ground-truth annotation"
        )
    if len(res.image_ids) and (
        not res.segmentations or any(sg is None for sg in res.segmentations)
    ):
        k = 0 if not res.segmentations else [sg is None for sg in res.segmentations].index(True)
        raise InputError(
            f"results[{k}] has no segmentation: iou_type='segm' needs an RLE mask "
            "('segmentation': {'size': [h, w], 'counts': ...}) on every result"
        )

    def rle(seg: Any, image_id: int, what: str) -> dict[str, Any]:
        try:
            return annotation_to_rle(seg, *sizes[int(image_id)])
        except InputError as exc:
            raise InputError(f"{what}: {exc}") from None

    g_rle = [
        rle(gt.segmentations[k], gt.image_ids[k], f"annotation id {int(gt.ann_ids[k])}")
        for k in g_ord
    ]
    d_rle = [rle(res.segmentations[k], res.image_ids[k], f"results[{k}]") for k in d_ord]
    d_area = np.asarray(rle_area(d_rle), dtype=np.float64) if d_rle else np.zeros(0)
    crowd = gt.iscrowd[g_ord]
    parts, offsets, at = [], np.zeros(groups.shape[0], np.int64), 0
    for g, (g0, g1, d0, d1) in enumerate(groups):
        offsets[g] = at
        if g1 > g0 and d1 > d0:
            iou = rle_iou(d_rle[d0:d1], g_rle[g0:g1], crowd[g0:g1])
            parts.append(iou.ravel())
            at += iou.size
    flat = np.concatenate(parts) if parts else np.zeros(0)
    return (flat, offsets), d_area


def _stable_rank_in_groups(keys: np.ndarray) -> np.ndarray:
    """Rank of each element within its run of equal ``keys`` (keys sorted)."""
    n = keys.size
    if n == 0:
        return _EMPTY_I
    start = np.r_[0, np.flatnonzero(np.diff(keys)) + 1]
    lengths = np.diff(np.r_[start, n])
    return np.arange(n) - np.repeat(start, lengths)


def _oks(
    dt_xy: np.ndarray,
    gt_kp: np.ndarray,
    gt_area: np.ndarray,
    gt_box: np.ndarray,
    variances: np.ndarray,
) -> np.ndarray:
    """OKS of broadcastable stacks (unchecked): ``dt_xy`` (..., K, 2), ``gt_kp``
    (..., K, 3), ``gt_area`` (...), ``gt_box`` (..., 4), ``variances`` (K,) =
    ``(2 sigma)^2``; returns (...). The operations of pycocotools' computeOks."""
    xd, yd = dt_xy[..., 0], dt_xy[..., 1]
    xg, yg = gt_kp[..., 0], gt_kp[..., 1]
    labelled = gt_kp[..., 2] > 0
    n_lab = np.count_nonzero(labelled, axis=-1)
    none = (n_lab == 0)[..., None]
    # ground truth without labelled keypoints: the distance to its box tripled about
    # the centre, [x - w, x + 2w] x [y - h, y + 2h], over every keypoint
    bx, by, bw, bh = (gt_box[..., c, None] for c in range(4))
    x0, x1, y0, y1 = bx - bw, bx + bw * 2, by - bh, by + bh * 2
    dx = np.where(none, np.maximum(0, x0 - xd) + np.maximum(0, xd - x1), xd - xg)
    dy = np.where(none, np.maximum(0, y0 - yd) + np.maximum(0, yd - y1), yd - yg)
    e = (dx**2 + dy**2) / variances / (gt_area[..., None] + np.spacing(1)) / 2
    counted = labelled | none
    total = np.sum(np.where(counted, np.exp(-e), 0.0), axis=-1)
    return total / np.count_nonzero(counted, axis=-1)


def keypoint_oks(
    dt_keypoints: npt.ArrayLike,
    gt_keypoints: npt.ArrayLike,
    gt_area: npt.ArrayLike,
    gt_box: npt.ArrayLike,
    sigmas: npt.ArrayLike,
) -> np.ndarray:
    r"""Object keypoint similarity of every detection with every ground truth (COCO's
    OKS, ``pycocotools.cocoeval.COCOeval.computeOks``).

    With per-keypoint variances :math:`\kappa_i^2 = (2 \sigma_i)^2`, the ground truth's
    area :math:`s` and :math:`\epsilon` = ``np.spacing(1)``,

    .. math::

        e_i = \frac{\Delta x_i^2 + \Delta y_i^2}{2\, \kappa_i^2\, (s + \epsilon)},
        \qquad \mathrm{OKS}(d, g) = \frac{1}{|L|} \sum_{i \in L} e^{-e_i},

    where :math:`L` is the ground truth's labelled keypoints (:math:`v_i > 0`) and
    :math:`\Delta = d_i - g_i`. For ground truth with no labelled keypoint, :math:`L` is
    all :math:`K` keypoints and :math:`\Delta x_i = \max(0, x_0 - x^d_i) + \max(0, x^d_i
    - x_1)` (likewise :math:`y`), the distance to the box
    :math:`[x - w, x + 2w] \times [y - h, y + 2h]` of its ``bbox`` :math:`(x, y, w, h)`.

    Parameters
    ----------
    dt_keypoints : (D, K, 2) or (D, K, 3) array_like
        Detected keypoints ``x, y`` (a third column, the score, is not read).
    gt_keypoints : (G, K, 3) array_like
        Ground-truth keypoints ``x, y, v``.
    gt_area : (G,) array_like
        The ground truth's ``area`` (>= 0; the segmentation's area in COCO files).
    gt_box : (G, 4) array_like
        The ground truth's ``bbox`` ``[x, y, w, h]`` (read only where no keypoint is
        labelled).
    sigmas : (K,) array_like
        Per-keypoint constants, > 0 (:data:`robopercept.nn.skeleton.COCO_17` ``.sigmas``
        for COCO's persons).

    Returns
    -------
    (D, G) float64 ndarray
        OKS in [0, 1].

    Raises
    ------
    InputError
        Shapes that do not agree (the message names both), non-finite values, a
        negative area, sigmas <= 0.

    Examples
    --------
    >>> gt = [[[10.0, 10.0, 2.0], [20.0, 10.0, 2.0]]]
    >>> dt = [[[10.0, 10.0], [20.0, 12.0]]]  # the second keypoint 2 px off
    >>> oks = keypoint_oks(dt, gt, [100.0], [[10, 10, 10, 1]], [0.5, 0.5])
    >>> round(float(oks[0, 0]), 6)  # (1 + exp(-4 / (2 * 1.0 * 100))) / 2
    0.990099
    """
    dt = check_numeric(dt_keypoints, "dt_keypoints")
    gk = check_numeric(gt_keypoints, "gt_keypoints")
    area = check_numeric(gt_area, "gt_area")
    box = check_numeric(gt_box, "gt_box")
    sig = check_numeric(sigmas, "sigmas")
    if gk.ndim != 3 or gk.shape[2] != 3:
        raise InputError(
            f"gt_keypoints must be (G, K, 3) (x, y, v per keypoint); got shape {gk.shape}"
        )
    n_g, n_k = gk.shape[0], gk.shape[1]
    if dt.ndim != 3 or dt.shape[2] not in (2, 3) or dt.shape[1] != n_k:
        raise InputError(
            f"dt_keypoints must be (D, {n_k}, 2) or (D, {n_k}, 3), as many keypoints as "
            f"gt_keypoints ({n_k}); got shape {dt.shape}"
        )
    if area.shape != (n_g,) or box.shape != (n_g, 4):
        raise InputError(
            f"gt_area must be ({n_g},) and gt_box ({n_g}, 4), one per ground truth; got "
            f"shapes {area.shape} and {box.shape}"
        )
    if sig.shape != (n_k,) or not np.isfinite(sig).all() or (sig <= 0).any():
        raise InputError(
            f"sigmas must be {n_k} positive numbers, one per keypoint; got {plain_repr(sigmas)}"
        )
    for name, arr in (("dt_keypoints", dt), ("gt_keypoints", gk), ("gt_area", area)):
        if not np.isfinite(arr).all():
            raise InputError(f"{name} holds NaN or inf; OKS needs finite coordinates")
    if not np.isfinite(box).all():
        raise InputError("gt_box holds NaN or inf; give finite [x, y, w, h] boxes")
    if (area < 0).any():
        raise InputError(f"gt_area must be >= 0; got {plain_repr(area)}")
    if n_k == 0:
        raise InputError("keypoint arrays hold no keypoints (K = 0); OKS needs K >= 1")
    return _oks(dt[:, None, :, :2], gk[None], area[None], box[None], (sig * 2) ** 2)


def _keypoint_ious(
    gt: CocoDataset,
    res: CocoResults,
    g_ord: np.ndarray,
    d_ord: np.ndarray,
    groups: np.ndarray,
    sigmas: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``keypoints`` evaluation's OKS: per group (rows of ``groups``) the (nd, ng)
    OKS matrix row-major, all groups in one flat array, with each group's offset; every
    pair of every group is computed in one vectorized call."""
    ng = groups[:, 1] - groups[:, 0]
    nd = groups[:, 3] - groups[:, 2]
    sizes = ng * nd
    offsets = (np.cumsum(sizes) - sizes).astype(np.int64)
    total = int(sizes.sum())
    if total == 0:
        return np.zeros(0), offsets
    grp = np.repeat(np.arange(groups.shape[0]), sizes)
    local = np.arange(total) - offsets[grp]
    gi = g_ord[groups[grp, 0] + local % np.maximum(ng[grp], 1)]
    di = d_ord[groups[grp, 2] + local // np.maximum(ng[grp], 1)]
    oks = _oks(
        res.keypoints[di, :, :2],
        gt.keypoints[gi],
        gt.areas[gi],
        gt.boxes[gi],
        (sigmas * 2) ** 2,
    )
    return np.ascontiguousarray(oks, dtype=np.float64), offsets


def _check_sigmas(sigmas: Any, n_k: int) -> np.ndarray:
    if sigmas is None:
        if n_k == COCO_17.num_joints:
            return np.array(COCO_17.sigmas)
        raise InputError(
            f"sigmas is needed: the keypoints have K = {n_k}, not COCO's 17, so there are "
            f"no default OKS constants; pass sigmas=[...] ({n_k} positive numbers, e.g. "
            "a Skeleton's .sigmas)"
        )
    sig = check_numeric(sigmas, "sigmas")
    if sig.shape != (n_k,) or not np.isfinite(sig).all() or (sig <= 0).any():
        raise InputError(
            f"sigmas must be {n_k} positive numbers, one per keypoint; got {plain_repr(sigmas)}"
        )
    return sig


def _summary_stats(precision: np.ndarray, recall: np.ndarray, keypoints: bool) -> np.ndarray:
    """COCOeval.summarize's numbers from the (T, R, K, A, M) precision and (T, K, A, M)
    recall: the 12 of boxes and masks or the 10 of keypoints (areas all, medium,
    large); the last max_dets throughout but for AR1/AR10."""

    def mean(s: np.ndarray) -> float:
        v = s[s > -1]
        return float(np.mean(v)) if v.size else -1.0

    if keypoints:
        return np.array(
            [
                mean(precision[:, :, :, 0, -1]),
                mean(precision[0, :, :, 0, -1]),
                mean(precision[5, :, :, 0, -1]),
                mean(precision[:, :, :, 1, -1]),
                mean(precision[:, :, :, 2, -1]),
                mean(recall[:, :, 0, -1]),
                mean(recall[0, :, 0, -1]),
                mean(recall[5, :, 0, -1]),
                mean(recall[:, :, 1, -1]),
                mean(recall[:, :, 2, -1]),
            ]
        )
    return np.array(
        [
            mean(precision[:, :, :, 0, -1]),
            mean(precision[0, :, :, 0, -1]),
            mean(precision[5, :, :, 0, -1]),
            mean(precision[:, :, :, 1, -1]),
            mean(precision[:, :, :, 2, -1]),
            mean(precision[:, :, :, 3, -1]),
            mean(recall[:, :, 0, 0]),
            mean(recall[:, :, 0, 1]),
            mean(recall[:, :, 0, 2]),
            mean(recall[:, :, 1, -1]),
            mean(recall[:, :, 2, -1]),
            mean(recall[:, :, 3, -1]),
        ]
    )


def _check_max_dets(max_dets: Any, keypoints: bool) -> tuple[int, ...]:
    if max_dets is None:
        return (20,) if keypoints else (1, 10, 100)
    if keypoints:
        if not isinstance(max_dets, (list, tuple)) or len(max_dets) < 1:
            raise InputError(
                "max_dets for iou_type='keypoints' must be increasing ints like (20,); got "
                f"{plain_repr(max_dets)}"
            )
    elif not isinstance(max_dets, (list, tuple)) or len(max_dets) != 3:
        raise InputError(
            f"max_dets must be three increasing ints like (1, 10, 100); got {plain_repr(max_dets)}"
        )
    md = tuple(check_int(m, "max_dets", minimum=1) for m in max_dets)
    if any(a >= b for a, b in itertools.pairwise(md)):
        raise InputError(f"max_dets must be increasing; got {plain_repr(max_dets)}")
    return md


def evaluate_detections(
    gt: CocoDataset | Mapping[str, Any],
    results: CocoResults | list[Mapping[str, Any]],
    iou_type: str = "bbox",
    *,
    max_dets: Sequence[int] | None = None,
    use_jit: bool = True,
    sigmas: npt.ArrayLike | None = None,
) -> CocoEvaluation:
    r"""COCO box, mask or keypoint evaluation of ``results`` against ``gt``; equals
    ``pycocotools``' ``COCOeval(gt, dt, iou_type)`` ``evaluate(); accumulate();
    summarize()`` for ``"bbox"``, ``"segm"`` and ``"keypoints"``.

    The algorithm is in the module docstring: greedy matching by score per image and
    category at IoU (or OKS) .50:.05:.95, crowd and out-of-range ground truth ignored,
    the monotone precision envelope sampled at 101 recall points.

    Parameters
    ----------
    gt : CocoDataset or dict
        Ground truth; its images and categories are those evaluated.
    results : CocoResults or list of dict
        Detections; every ``image_id`` and ``category_id`` must be in ``gt``.
    iou_type : {"bbox", "segm", "keypoints"}
        ``"segm"``: the IoU of the masks (:func:`~robopercept.nn.coco.rle.rle_iou`,
        the crowd rule as for boxes) replaces that of the boxes: every ground-truth
        annotation needs a ``segmentation`` (polygons or RLE, rasterized at its
        image's size) and every result an RLE ``segmentation``; a detection's area
        for the area ranges is its mask's, a ground truth's is its ``area`` field.
        ``"keypoints"``: the OKS (:func:`keypoint_oks`) replaces the IoU; the ground
        truth needs keypoints and the results ``keypoints`` of the same ``K``; ground
        truth with ``num_keypoints == 0`` is ignored; area ranges all, medium, large;
        the 10 keypoint summary numbers (:data:`KEYPOINT_SUMMARY_NAMES`).
    max_dets : increasing positive ints, optional
        Detections kept per image: for boxes and masks three (default COCO's 1, 10,
        100), the summary's AR1/AR10/AR100 use them in order and the APs the last;
        for keypoints one or more (default COCO's (20,)), the summary uses the last.
        (pycocotools' ``summarize`` asks for ``maxDets=100`` (20 for keypoints) by
        value, giving -1 where that value is not among them; here it is the value at
        ``max_dets[-1]``.)
    use_jit : bool
        ``False`` runs the plain-Python matching (the reference of the compiled one).
    sigmas : (K,) array_like, optional
        The per-keypoint OKS constants (``iou_type="keypoints"`` only; pycocotools'
        ``params.kpt_oks_sigmas``). Default: COCO's 17
        (:data:`robopercept.nn.skeleton.COCO_17`) when ``K == 17``; required otherwise.

    Returns
    -------
    CocoEvaluation
        Its ``summary_names`` say which summary numbers ``stats`` holds.

    Raises
    ------
    InputError
        ``iou_type`` other than "bbox", "segm" or "keypoints"; a missing or bad
        segmentation for "segm"; for "keypoints", ground truth without keypoints,
        results without keypoints or with another ``K``, missing ``sigmas`` when
        ``K != 17`` or sigmas that are not ``K`` positive numbers; ``sigmas`` for
        another ``iou_type``; bad ``max_dets``; results naming an image or category
        the ground truth lacks, or anything :func:`coco_from_dict` /
        :func:`results_from_list` refuse.

    Examples
    --------
    >>> from robopercept.nn.coco.dataset import coco_from_dict
    >>> gt = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 100, "height": 100}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                      "bbox": [10, 10, 50, 50]}]})
    >>> ev = evaluate_detections(gt, [
    ...     {"image_id": 1, "category_id": 1, "bbox": [10, 10, 50, 40], "score": 0.9}])
    >>> round(ev.summary()["AP50"], 9), round(ev.summary()["AP"], 9)  # IoU 0.8
    (1.0, 0.7)

    Keypoints (two of them, sigmas given as K is not 17): the detection's OKS is
    :math:`(e^{-4/160} + e^{-25/160}) / 2 \approx 0.915`, a match at the thresholds
    .50 to .90:

    >>> gt = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 100, "height": 100}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "area": 2000,
    ...                      "bbox": [10, 10, 50, 50], "keypoints": [20, 20, 2, 40, 50, 2]}]})
    >>> ev = evaluate_detections(gt, [{"image_id": 1, "category_id": 1, "score": 0.9,
    ...     "keypoints": [22, 20, 1, 40, 55, 1]}], "keypoints", sigmas=[0.1, 0.1])
    >>> ev.summary_names[:3], round(ev.summary()["AP"], 9)
    (('AP', 'AP50', 'AP75'), 0.9)
    """
    check_choice(iou_type, "iou_type", ("bbox", "segm", "keypoints"))
    kp_eval = iou_type == "keypoints"
    if sigmas is not None and not kp_eval:
        raise InputError(
            f"sigmas are the OKS constants of iou_type='keypoints'; got iou_type={iou_type!r}: "
            "drop sigmas or evaluate keypoints"
        )
    md = _check_max_dets(max_dets, kp_eval)
    jit = check_bool(use_jit, "use_jit")
    gtd = as_coco_dataset(gt)
    res = as_coco_results(results, gtd)
    if kp_eval:
        n_kp = gtd.keypoints.shape[1]
        if n_kp == 0:
            raise InputError(
                "the ground truth has no keypoints: iou_type='keypoints' needs annotations "
                "with 'keypoints' [x, y, v] * K (a COCO person_keypoints file)"
            )
        if len(res) and res.keypoints.shape[1] != n_kp:
            got = res.keypoints.shape[1]
            raise InputError(
                f"iou_type='keypoints' needs results with 'keypoints' [x, y, s] * {n_kp} (the "
                f"ground truth's K); got "
                + ("none (box or mask results)" if got == 0 else f"K = {got}")
            )
        sig = _check_sigmas(sigmas, n_kp)
    area_ranges = _KP_AREAS if kp_eval else AREA_RANGES

    img_ids = np.unique(np.array([i.id for i in gtd.images], dtype=np.int64))
    cat_ids = np.unique(np.array([c.id for c in gtd.categories], dtype=np.int64))
    n_i, n_k = img_ids.size, cat_ids.size
    T, R, A, M = IOU_THRESHOLDS.size, RECALL_THRESHOLDS.size, area_ranges.shape[0], len(md)

    # group keys: category-major, then image (pycocotools' evalImgs order)
    g_key = np.searchsorted(cat_ids, gtd.category_ids) * n_i + np.searchsorted(
        img_ids, gtd.image_ids
    )
    g_ord = np.argsort(g_key, kind="stable")
    g_key = g_key[g_ord]
    d_key = np.searchsorted(cat_ids, res.category_ids) * n_i + np.searchsorted(
        img_ids, res.image_ids
    )
    d_ord = np.lexsort((-res.scores, d_key))  # by key, then score descending, stable
    d_key = d_key[d_ord]
    d_rank = _stable_rank_in_groups(d_key)
    keep = d_rank < md[-1]
    d_ord, d_key, d_rank = d_ord[keep], d_key[keep], d_rank[keep]
    keys = np.union1d(np.unique(g_key), np.unique(d_key))
    groups = np.stack(
        [
            np.searchsorted(g_key, keys, "left"),
            np.searchsorted(g_key, keys, "right"),
            np.searchsorted(d_key, keys, "left"),
            np.searchsorted(d_key, keys, "right"),
        ],
        axis=1,
    ).astype(np.int64)
    gt_boxes = np.ascontiguousarray(gtd.boxes[g_ord])
    gt_area = np.ascontiguousarray(gtd.areas[g_ord])
    gt_crowd = gtd.iscrowd[g_ord]
    # ignored in every area range: crowd regions, and for keypoints unlabelled persons
    gt_base = gt_crowd | (gtd.num_keypoints[g_ord] == 0) if kp_eval else gt_crowd
    gt_flags = np.ascontiguousarray(np.stack([gt_crowd, gt_base]))
    dt_boxes = np.ascontiguousarray(res.boxes[d_ord])
    dt_scores = res.scores[d_ord]
    dt_area = np.ascontiguousarray(dt_boxes[:, 2] * dt_boxes[:, 3])
    if iou_type == "segm":
        given, dt_area = _mask_ious(gtd, res, g_ord, d_ord, groups)
    elif kp_eval:
        given = _keypoint_ious(gtd, res, g_ord, d_ord, groups, sig)
    else:
        given = (np.zeros(0), np.zeros(0, np.int64))
    match = _match_groups_jit if jit else _match_groups
    dt_m, dt_ig, gt_ig = match(
        groups,
        gt_boxes,
        gt_area,
        gt_flags,
        dt_boxes,
        dt_area,
        given,
        (IOU_THRESHOLDS, np.ascontiguousarray(area_ranges)),
    )

    precision = -np.ones((T, R, K := n_k, A, M))
    recall = -np.ones((T, K, A, M))
    scores = -np.ones((T, R, K, A, M))
    g_cat = g_key // max(n_i, 1)
    d_cat = d_key // max(n_i, 1)
    g_bounds = np.searchsorted(g_cat, np.arange(K + 1))
    d_bounds = np.searchsorted(d_cat, np.arange(K + 1))
    eps = np.spacing(1)
    for k in range(K):
        gs, ge, ds, de = g_bounds[k], g_bounds[k + 1], d_bounds[k], d_bounds[k + 1]
        if ge == gs and de == ds:
            continue
        for a in range(A):
            npig = int(np.count_nonzero(~gt_ig[a, gs:ge]))
            if npig == 0:
                continue
            for m, maxdet in enumerate(md):
                sel = np.flatnonzero(d_rank[ds:de] < maxdet) + ds
                sc = dt_scores[sel]
                o = np.argsort(-sc, kind="mergesort")
                sel, sc = sel[o], sc[o]
                mt = dt_m[a][:, sel]
                ig = dt_ig[a][:, sel]
                tp = np.cumsum(mt & ~ig, axis=1, dtype=np.float64)
                fp = np.cumsum(~mt & ~ig, axis=1, dtype=np.float64)
                nd = sel.size
                if nd == 0:
                    recall[:, k, a, m] = 0
                    precision[:, :, k, a, m] = 0
                    scores[:, :, k, a, m] = 0
                    continue
                rc = tp / npig
                pr = tp / (fp + tp + eps)
                recall[:, k, a, m] = rc[:, -1]
                pr = np.maximum.accumulate(pr[:, ::-1], axis=1)[:, ::-1]
                for t in range(T):
                    idx = np.searchsorted(rc[t], RECALL_THRESHOLDS, side="left")
                    ok = idx < nd
                    q = np.zeros(R)
                    ss = np.zeros(R)
                    q[ok] = pr[t, idx[ok]]
                    ss[ok] = sc[idx[ok]]
                    precision[t, :, k, a, m] = q
                    scores[t, :, k, a, m] = ss

    return CocoEvaluation(
        readonly(precision),
        readonly(recall),
        readonly(scores),
        readonly(_summary_stats(precision, recall, kp_eval)),
        readonly(cat_ids),
        IOU_THRESHOLDS.copy(),
        RECALL_THRESHOLDS.copy(),
        md,
        KEYPOINT_SUMMARY_NAMES if kp_eval else SUMMARY_NAMES,
        _KP_AREA_NAMES if kp_eval else AREA_NAMES,
        iou_type,
    )


def pr_curves_picture(
    evaluation: CocoEvaluation,
    *,
    iou_threshold: float = 0.5,
    names: Mapping[int, str] | None = None,
    width: int = 1600,
    height: int = 1000,
) -> np.ndarray:
    """Per-class precision-recall curves (COCO's 101-point interpolated precision, area
    "all", the largest max_dets) at one of the 10 IoU thresholds, as an RGB picture
    (drawn by :func:`robopercept.viz.precision_recall_picture`; 1600 x 1000 reads well
    on a 1080p screen).

    Parameters
    ----------
    evaluation : CocoEvaluation
    iou_threshold : float
        One of .50, .55, ..., .95.
    names : dict, optional
        ``{category id: name}`` for the legend (:meth:`CocoDataset.category_names`).
    width, height : int

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Examples
    --------
    >>> from robopercept.nn.coco.dataset import coco_from_dict
    >>> gt = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 99, "height": 99}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                      "bbox": [1, 1, 40, 40]}]})
    >>> ev = evaluate_detections(gt, [{"image_id": 1, "category_id": 1,
    ...                                "bbox": [1, 1, 40, 40], "score": 1.0}])
    >>> pr_curves_picture(ev, width=400, height=300).shape
    (300, 400, 3)
    """
    if not isinstance(evaluation, CocoEvaluation):
        raise InputError(f"evaluation must be a CocoEvaluation; got {type(evaluation).__name__}")
    thr = check_real(iou_threshold, "iou_threshold")
    t = np.flatnonzero(np.isclose(evaluation.iou_thresholds, thr, atol=1e-9))
    if t.size == 0:
        raise InputError(
            f"iou_threshold must be one of {plain_repr(np.round(evaluation.iou_thresholds, 2))}; "
            f"got {thr}"
        )
    if names is not None and not isinstance(names, Mapping):
        raise InputError(f"names must be a dict {{category id: name}}; got {plain_repr(names)}")
    ids = evaluation.category_ids.tolist()
    labels = [str(names.get(c, c)) if names is not None else str(c) for c in ids]
    return precision_recall_picture(
        evaluation.recall_thresholds,
        evaluation.precision[t[0], :, :, 0, -1].T,
        labels,
        iou_threshold=thr,
        width=width,
        height=height,
    )


def write_pr_curves(
    evaluation: CocoEvaluation,
    path: str | os.PathLike[str],
    *,
    iou_threshold: float = 0.5,
    names: Mapping[int, str] | None = None,
) -> Path:
    """Write :func:`pr_curves_picture` (1600 x 1000) as a PNG; returns the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.nn.coco.dataset import coco_from_dict
    >>> gt = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 99, "height": 99}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                      "bbox": [1, 1, 40, 40]}]})
    >>> ev = evaluate_detections(gt, [{"image_id": 1, "category_id": 1,
    ...                                "bbox": [1, 1, 40, 40], "score": 1.0}])
    >>> write_pr_curves(ev, pathlib.Path(tempfile.mkdtemp()) / "pr.png").suffix
    '.png'
    """
    p = as_path(path)
    if p.suffix.lower() != ".png":
        raise InputError(f"{p}: PR curves are written as PNG; give a path ending in .png")
    img = pr_curves_picture(evaluation, iou_threshold=iou_threshold, names=names)
    p.parent.mkdir(parents=True, exist_ok=True)
    return write_image(p, img)
