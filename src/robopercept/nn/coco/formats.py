r"""Detection data and its evaluation: COCO JSON, Pascal-VOC XML, COCO and VOC metrics.

NumPy only (no torch): the formats and the metrics of object detection.

Formats
-------
* :class:`CocoDataset` is a frozen record of a COCO ground-truth file: images
  (id, file_name, width, height), categories (id, name and, for keypoint categories,
  the ``keypoints`` names and 1-based ``skeleton`` links) and annotations as arrays (id,
  image_id, category_id, ``bbox`` = ``[x, y, w, h]``, area, iscrowd, and the keypoints
  ``[x, y, v] * K`` as a ``(N, K, 3)`` array with ``num_keypoints``). Read it with
  :func:`read_coco_json` or :func:`coco_from_dict`, write it with
  :func:`write_coco_json` / :func:`coco_to_dict`. Each annotation's ``segmentation``
  is kept as the file gives it (for the ``segm`` evaluation). One data set holds one
  keypoint layout: every annotation with keypoints has the same ``K``, and an
  annotation without them gets ``K`` unlabelled points (``v = 0``).
* :class:`CocoResults` is a COCO results file, a list of
  ``{"image_id", "category_id", "bbox", "score"}`` (or ``"segmentation"`` masks, or
  ``"keypoints"`` ``[x, y, s] * K``): :func:`read_coco_results`,
  :func:`results_from_list`, :func:`write_coco_results`, :func:`results_to_list`.
* :func:`read_voc_xml` reads one Pascal-VOC annotation file (:class:`VocAnnotation`);
  :func:`voc_to_coco` turns a set of them into a :class:`CocoDataset`.

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

:func:`voc_average_precision` is the all-point interpolated AP of the Pascal VOC devkit
(2010 onwards), and :func:`evaluate_voc` the VOC matching at one IoU threshold per class.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_file,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco.rle import annotation_to_rle, rle_area, rle_iou, rle_to_bbox
from robopercept.nn.skeleton import COCO_17

__all__ = [
    "AREA_RANGES",
    "IOU_THRESHOLDS",
    "KEYPOINT_SUMMARY_NAMES",
    "RECALL_THRESHOLDS",
    "SUMMARY_NAMES",
    "CocoCategory",
    "CocoDataset",
    "CocoEvaluation",
    "CocoImage",
    "CocoResults",
    "VocAnnotation",
    "VocEvaluation",
    "VocObject",
    "coco_from_dict",
    "coco_to_dict",
    "evaluate_detections",
    "evaluate_voc",
    "keypoint_oks",
    "pr_curves_picture",
    "read_coco_json",
    "read_coco_results",
    "read_voc_xml",
    "results_from_ground_truth",
    "results_from_list",
    "results_to_list",
    "voc_average_precision",
    "voc_to_coco",
    "write_coco_json",
    "write_coco_results",
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


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


# ----------------------------------------------------------------------------- records


def _record_rows(value: Any, name: str) -> int:
    """The number of rows ``N`` of a record's column (its first dimension)."""
    try:
        shape = np.shape(value)
    except (TypeError, ValueError):
        shape = ()
    if len(shape) < 1:
        raise InputError(f"{name} must be a 1-D array, one entry per row; got {plain_repr(value)}")
    return int(shape[0])


def _keypoint_array(value: Any, n: int, name: str) -> np.ndarray:
    """``value`` as a read-only finite (n, K, 3) float64 array; an empty (0, 0, 3) one
    (the records' default) gives (n, 0, 3)."""
    kp = check_numeric(value, name)
    if kp.shape == (0, 0, 3):
        return _readonly(np.zeros((n, 0, 3)))
    if kp.ndim != 3 or kp.shape[0] != n or kp.shape[2] != 3:
        raise InputError(
            f"{name} must be ({n}, K, 3) (x, y, v per keypoint, one row per entry); got "
            f"shape {kp.shape}"
        )
    if not np.isfinite(kp).all():
        raise InputError(f"{name} holds NaN or inf; keypoints must be finite (v = 0 if unlabelled)")
    if isinstance(value, np.ndarray) and value.dtype == np.float64 and not value.flags.writeable:
        return value  # read-only already (the readers' arrays): no copy
    return _readonly(kp.copy())


@dataclass(frozen=True)
class CocoImage:
    """One image of a COCO file: ``id``, ``file_name``, ``width``, ``height`` (pixels)."""

    id: int
    file_name: str
    width: int
    height: int


@dataclass(frozen=True)
class CocoCategory:
    """One category of a COCO file: ``id``, ``name``, (optional) ``supercategory`` and,
    for a keypoint category, its ``keypoints`` names and ``skeleton`` links (pairs of
    1-based keypoint numbers, as COCO writes them).

    Examples
    --------
    >>> from robopercept.nn.skeleton import skeleton_from_coco_category
    >>> c = CocoCategory(1, "arm", "", ("shoulder", "elbow", "wrist"), ((1, 2), (2, 3)))
    >>> skeleton_from_coco_category(c.to_dict()).links
    ((0, 1), (1, 2))
    """

    id: int
    name: str
    supercategory: str = ""
    keypoints: tuple[str, ...] = ()
    skeleton: tuple[tuple[int, int], ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The COCO ``categories`` entry (``keypoints`` and ``skeleton`` as lists, when
        the category has them): what
        :func:`~robopercept.nn.skeleton.skeleton_from_coco_category` reads."""
        out: dict[str, Any] = {
            "id": self.id,
            "name": self.name,
            "supercategory": self.supercategory,
        }
        if self.keypoints:
            out["keypoints"] = list(self.keypoints)
        if self.keypoints or self.skeleton:
            out["skeleton"] = [list(p) for p in self.skeleton]
        return out


@dataclass(frozen=True, eq=False)
class CocoDataset:
    """COCO ground truth: images, categories and box annotations (arrays, read-only).

    Attributes
    ----------
    images : tuple of CocoImage
    categories : tuple of CocoCategory
    ann_ids, image_ids, category_ids : (N,) int64 ndarray
    boxes : (N, 4) float64 ndarray
        ``[x, y, w, h]`` in pixels (COCO's ``bbox``).
    areas : (N,) float64 ndarray
        COCO's ``area`` (the segmentation's area in COCO files; ``w h`` when absent).
    iscrowd : (N,) bool ndarray
    segmentations : tuple
        Each annotation's ``segmentation`` as the file gives it (polygons, an RLE) or
        None where it has none; empty when no annotation has one. Read as masks by
        :func:`~robopercept.nn.coco.rle.annotation_to_rle` for the ``segm``
        evaluation.
    keypoints : (N, K, 3) float64 ndarray
        Each annotation's keypoints ``x, y, v`` (COCO's ``keypoints`` list reshaped;
        ``v`` 0 unlabelled, 1 labelled but hidden, 2 visible); ``(N, 0, 3)`` when no
        annotation has keypoints, zeros on an annotation without them. The
        constructor's default, an empty ``(0, 0, 3)`` array, becomes ``(N, 0, 3)``.
    num_keypoints : (N,) int64 ndarray
        COCO's ``num_keypoints`` (the keypoint evaluation ignores ground truth where it
        is 0); where a file leaves it out, the count of ``v > 0``, and so for the
        constructor's default, an empty array.

    Raises
    ------
    InputError
        ``keypoints`` not a finite ``(N, K, 3)`` array or ``num_keypoints`` not ``N``
        integers >= 0 (N = ``len(ann_ids)``).

    Examples
    --------
    >>> ds = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a.jpg", "width": 64, "height": 48}],
    ...     "categories": [{"id": 3, "name": "cat"}],
    ...     "annotations": [{"id": 7, "image_id": 1, "category_id": 3,
    ...                      "bbox": [2, 4, 10, 20]}]})
    >>> len(ds), ds.areas.tolist(), ds.category_names(), ds.keypoints.shape
    (1, [200.0], {3: 'cat'}, (1, 0, 3))
    """

    images: tuple[CocoImage, ...]
    categories: tuple[CocoCategory, ...]
    ann_ids: np.ndarray
    image_ids: np.ndarray
    category_ids: np.ndarray
    boxes: np.ndarray
    areas: np.ndarray
    iscrowd: np.ndarray
    segmentations: tuple[Any, ...] = ()
    keypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))
    num_keypoints: np.ndarray = field(default_factory=lambda: _EMPTY_I)

    def __post_init__(self) -> None:
        n = _record_rows(self.ann_ids, "CocoDataset.ann_ids")
        kp = _keypoint_array(self.keypoints, n, "CocoDataset.keypoints")
        raw = check_numeric(self.num_keypoints, "CocoDataset.num_keypoints")
        if raw.size == 0:  # the default: the count of labelled keypoints
            nk = np.count_nonzero(kp[:, :, 2] > 0, axis=1).astype(np.int64)
        else:
            if (
                raw.shape != (n,)
                or not np.isfinite(raw).all()
                or (raw < 0).any()
                or (raw != np.round(raw)).any()
            ):
                raise InputError(
                    f"CocoDataset.num_keypoints must be {n} integers >= 0, one per "
                    f"annotation; got {plain_repr(self.num_keypoints)}"
                )
            nk = raw.astype(np.int64)
        object.__setattr__(self, "keypoints", kp)
        object.__setattr__(self, "num_keypoints", _readonly(nk))

    def __len__(self) -> int:
        return int(self.ann_ids.size)

    def category_names(self) -> dict[int, str]:
        """``{category id: name}``."""
        return {c.id: c.name for c in self.categories}


@dataclass(frozen=True, eq=False)
class CocoResults:
    """COCO detection results: one row per detection (arrays, read-only).

    Attributes
    ----------
    image_ids, category_ids : (N,) int64 ndarray
    boxes : (N, 4) float64 ndarray
        ``[x, y, w, h]``.
    scores : (N,) float64 ndarray
    segmentations : tuple
        Each detection's mask as a COCO RLE dict (the ``segm`` results), or empty for
        box results.
    keypoints : (N, K, 3) float64 ndarray
        Each detection's keypoints ``x, y, s`` (the keypoint results; ``s`` is a
        per-keypoint score the evaluation does not read); ``(N, 0, 3)`` for box and
        mask results (the constructor's default, an empty ``(0, 0, 3)`` array, becomes
        that).

    Raises
    ------
    InputError
        ``keypoints`` not a finite ``(N, K, 3)`` array (N = ``len(scores)``).

    Examples
    --------
    >>> r = results_from_list([{"image_id": 1, "category_id": 3,
    ...                         "bbox": [0, 0, 4, 4], "score": 0.9}])
    >>> len(r), r.scores.tolist()
    (1, [0.9])
    >>> k = results_from_list([{"image_id": 1, "category_id": 1, "score": 0.8,
    ...                         "keypoints": [2, 3, 1, 6, 11, 1]}])
    >>> k.keypoints.shape, k.boxes.tolist()  # the tight box of the keypoints
    ((1, 2, 3), [[2.0, 3.0, 4.0, 8.0]])
    """

    image_ids: np.ndarray
    category_ids: np.ndarray
    boxes: np.ndarray
    scores: np.ndarray
    segmentations: tuple[Any, ...] = ()
    keypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))

    def __post_init__(self) -> None:
        n = _record_rows(self.scores, "CocoResults.scores")
        object.__setattr__(
            self, "keypoints", _keypoint_array(self.keypoints, n, "CocoResults.keypoints")
        )

    def __len__(self) -> int:
        return int(self.scores.size)


# ----------------------------------------------------------------------------- parsing


def _field(item: Any, key: str, where: str, fix: str, err: type[Exception]) -> Any:
    if not isinstance(item, Mapping):
        raise err(f"{where} must be a JSON object; got {type(item).__name__} {plain_repr(item)}")
    if key not in item:
        raise err(f"{where} has no '{key}' field: {fix}")
    return item[key]


def _as_int(value: Any, what: str, err: type[Exception]) -> int:
    """``value`` as an int that fits int64 (integral floats such as ``3.0`` accepted)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        if not (isinstance(value, float) and value.is_integer()):
            raise err(f"{what} must be an integer; got {plain_repr(value)}")
    out = int(value)
    if not -(2**63) <= out < 2**63:
        raise err(f"{what} must fit in 64 bits; got {out}")
    return out


def _boxes_array(
    rows: list[Any], ids: Sequence[Any], what: str, err: type[Exception]
) -> np.ndarray:
    """``rows`` (each a 4-list) as a (N, 4) float64 array of finite boxes with w, h >= 0."""
    try:
        boxes = np.array(rows, dtype=np.float64).reshape(len(rows), 4)
    except (TypeError, ValueError):
        for k, b in enumerate(rows):
            ok = (
                isinstance(b, (list, tuple))
                and len(b) == 4
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in b)
            )
            if not ok:
                raise err(
                    f"{what} {ids[k]}: bbox must be 4 numbers [x, y, width, height]; got "
                    f"{plain_repr(b)}"
                ) from None
        raise err(f"{what}: bbox must be 4 numbers [x, y, width, height]") from None
    bad = ~np.isfinite(boxes).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise err(
            f"{what} {ids[k]}: bbox {plain_repr(rows[k])} is not finite (NaN or inf); "
            "drop or fix that box"
        )
    big = (np.abs(boxes) > 1e15).any(axis=1)
    if big.any():
        k = int(np.flatnonzero(big)[0])
        raise err(
            f"{what} {ids[k]}: bbox {plain_repr(rows[k])} has coordinates beyond 1e15 pixels, "
            "where areas and IoU lose their precision: rescale the boxes"
        )
    neg = (boxes[:, 2] < 0) | (boxes[:, 3] < 0)
    if neg.any():
        k = int(np.flatnonzero(neg)[0])
        raise err(
            f"{what} {ids[k]}: bbox {plain_repr(rows[k])} has a negative width or height; "
            "COCO boxes are [x, y, width, height], not [x1, y1, x2, y2]"
        )
    return boxes


def _category_keypoints(
    c: Mapping[str, Any], where: str, err: type[Exception]
) -> tuple[tuple[str, ...], tuple[tuple[int, int], ...]]:
    """A category's ``keypoints`` names and 1-based ``skeleton`` links (both optional)."""
    names = c.get("keypoints") or []
    if not isinstance(names, list) or not all(isinstance(x, str) for x in names):
        raise err(f"{where}: keypoints must be a list of keypoint names; got {plain_repr(names)}")
    raw = c.get("skeleton") or []
    links = []
    ok = isinstance(raw, list)
    for pair in raw if ok else []:
        if not (
            isinstance(pair, (list, tuple))
            and len(pair) == 2
            and all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in pair)
        ):
            ok = False
            break
        a, b = int(pair[0]), int(pair[1])
        if names and not (1 <= a <= len(names) and 1 <= b <= len(names)):
            raise err(
                f"{where}: skeleton link {plain_repr(pair)} must join keypoints 1..{len(names)} "
                "(COCO numbers keypoints from 1)"
            )
        links.append((a, b))
    if not ok:
        raise err(
            f"{where}: skeleton must be a list of [i, j] pairs of 1-based keypoint numbers; "
            f"got {plain_repr(raw)}"
        )
    return tuple(names), tuple(links)


def _keypoints_rows(rows: list[Any], where: list[str], err: type[Exception]) -> np.ndarray:
    """Each entry's ``keypoints`` list ``[x, y, v] * K`` (or None / [] for none) as a
    read-only finite (N, K, 3) float64 array, zeros where an entry has none; one K."""
    n = len(rows)
    k_of = -1
    first = -1
    parsed: list[np.ndarray | None] = []
    for j, r in enumerate(rows):
        if r is None or (isinstance(r, list) and not r):
            parsed.append(None)
            continue
        arr = None
        if isinstance(r, (list, tuple, np.ndarray)):
            try:
                raw = np.asarray(r)
            except (TypeError, ValueError):
                raw = np.zeros(0, dtype=object)
            if raw.dtype.kind in "iuf":
                arr = raw.astype(np.float64)
        if arr is None or arr.ndim != 1 or arr.size == 0 or arr.size % 3:
            raise err(
                f"{where[j]}: keypoints must be a flat list of numbers [x1, y1, v1, x2, y2, "
                f"v2, ...] (3 per keypoint); got {plain_repr(r)}"
            )
        if not np.isfinite(arr).all():
            raise err(
                f"{where[j]}: keypoints {plain_repr(r)} hold NaN or inf; write 0, 0, 0 for a "
                "keypoint that is not labelled"
            )
        if k_of < 0:
            k_of, first = arr.size // 3, j
        elif arr.size // 3 != k_of:
            raise err(
                f"{where[j]} has {arr.size // 3} keypoints but {where[first]} has {k_of}: "
                "one data set holds one keypoint layout"
            )
        parsed.append(arr)
    out = np.zeros((n, max(k_of, 0), 3))
    for j, arr in enumerate(parsed):
        if arr is not None:
            out[j] = arr.reshape(-1, 3)
    return _readonly(out)


def _parse_coco(data: Any, err: type[Exception]) -> CocoDataset:
    if not isinstance(data, Mapping):
        raise err(
            f"a COCO dataset must be a JSON object with 'images', 'categories' and "
            f"'annotations'; got {type(data).__name__}"
        )
    lists = {}
    for key in ("images", "categories", "annotations"):
        if key not in data:
            raise err(f"the COCO dataset has no '{key}' list: add \"{key}\": [...]")
        if not isinstance(data[key], list):
            raise err(f"the COCO dataset's '{key}' must be a list; got {type(data[key]).__name__}")
        lists[key] = data[key]
    images = []
    for k, im in enumerate(lists["images"]):
        where = f"images[{k}]"
        fix = "each image needs id, file_name, width and height"
        iid = _as_int(_field(im, "id", where, fix, err), f"{where}.id", err)
        name = _field(im, "file_name", where, fix, err)
        if not isinstance(name, str):
            raise err(f"{where}.file_name must be a string; got {plain_repr(name)}")
        w = _as_int(_field(im, "width", where, fix, err), f"{where}.width", err)
        h = _as_int(_field(im, "height", where, fix, err), f"{where}.height", err)
        if w < 0 or h < 0:
            raise err(f"{where} (id {iid}) has a negative size {w} x {h}")
        images.append(CocoImage(iid, name, w, h))
    cats = []
    for k, c in enumerate(lists["categories"]):
        where = f"categories[{k}]"
        fix = "each category needs id and name"
        cid = _as_int(_field(c, "id", where, fix, err), f"{where}.id", err)
        name = _field(c, "name", where, fix, err)
        sup = c.get("supercategory") or ""
        if not isinstance(name, str) or not isinstance(sup, str):
            raise err(f"{where}: name and supercategory must be strings; got {plain_repr(name)}")
        names, links = _category_keypoints(c, f"{where} (id {cid})", err)
        cats.append(CocoCategory(cid, name, sup, names, links))
    for what, ids in (("image", [i.id for i in images]), ("category", [c.id for c in cats])):
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise err(f"{what} id {dup} appears more than once; ids must be unique")
    anns = lists["annotations"]
    n = len(anns)
    ann_ids = np.empty(n, dtype=np.int64)
    img_ids = np.empty(n, dtype=np.int64)
    cat_ids = np.empty(n, dtype=np.int64)
    areas = np.empty(n, dtype=np.float64)
    crowd = np.zeros(n, dtype=bool)
    has_area = np.zeros(n, dtype=bool)
    rows = []
    segs: list[Any] = []
    kp_rows: list[Any] = []
    num_kp = np.full(n, -1, dtype=np.int64)  # -1: not given, counted below
    fix = "each annotation needs id, image_id, category_id and bbox [x, y, w, h]"
    for k, a in enumerate(anns):
        where = f"annotations[{k}]"
        aid = _as_int(_field(a, "id", where, fix, err), f"{where}.id", err)
        where = f"annotation id {aid}"
        ann_ids[k] = aid
        img_ids[k] = _as_int(_field(a, "image_id", where, fix, err), f"{where}: image_id", err)
        cat_ids[k] = _as_int(
            _field(a, "category_id", where, fix, err), f"{where}: category_id", err
        )
        rows.append(_field(a, "bbox", where, fix, err))
        segs.append(a.get("segmentation"))
        kp_rows.append(a.get("keypoints"))
        if "num_keypoints" in a:
            nk = _as_int(a["num_keypoints"], f"{where}: num_keypoints", err)
            if nk < 0:
                raise err(f"{where}: num_keypoints must be >= 0; got {nk}")
            num_kp[k] = nk
        if "area" in a:
            ar = a["area"]
            if isinstance(ar, bool) or not isinstance(ar, (int, float)) or not math.isfinite(ar):
                raise err(f"{where}: area must be a finite number; got {plain_repr(ar)}")
            areas[k] = ar
            has_area[k] = True
        if "iscrowd" in a:
            ic = a["iscrowd"]
            if not isinstance(ic, (int, np.integer)) or ic not in (0, 1):
                raise err(f"{where}: iscrowd must be 0 or 1; got {plain_repr(ic)}")
            crowd[k] = bool(ic)
    boxes = _boxes_array(rows, ann_ids.tolist(), "annotation id", err)
    areas[~has_area] = boxes[~has_area, 2] * boxes[~has_area, 3]
    keypoints = _keypoints_rows(kp_rows, [f"annotation id {a}" for a in ann_ids.tolist()], err)
    counted = np.count_nonzero(keypoints[:, :, 2] > 0, axis=1)
    num_kp[num_kp < 0] = counted[num_kp < 0]
    n_kp = keypoints.shape[1]
    if n_kp:
        for c in cats:
            if c.keypoints and len(c.keypoints) != n_kp:
                raise err(
                    f"category id {c.id} names {len(c.keypoints)} keypoints but the "
                    f"annotations hold {n_kp} per object: one data set holds one layout"
                )
    if np.unique(ann_ids).size != n:
        u, c = np.unique(ann_ids, return_counts=True)
        raise err(f"annotation id {int(u[c > 1][0])} appears more than once; ids must be unique")
    for what, col, known in (
        ("image_id", img_ids, [i.id for i in images]),
        ("category_id", cat_ids, [c.id for c in cats]),
    ):
        unknown = ~np.isin(col, np.array(known, dtype=np.int64))
        if unknown.any():
            k = int(np.flatnonzero(unknown)[0])
            listed = "images" if what == "image_id" else "categories"
            raise err(
                f"annotation id {int(ann_ids[k])} has {what} {int(col[k])}, which is not in "
                f"the '{listed}' list: add it there or drop the annotation"
            )
    return CocoDataset(
        tuple(images),
        tuple(cats),
        _readonly(ann_ids),
        _readonly(img_ids),
        _readonly(cat_ids),
        _readonly(boxes),
        _readonly(areas),
        _readonly(crowd),
        tuple(segs) if any(sg is not None for sg in segs) else (),
        keypoints,
        _readonly(num_kp),
    )


def coco_from_dict(data: Mapping[str, Any]) -> CocoDataset:
    """A COCO ground-truth dict (as ``json.load`` gives it) as a :class:`CocoDataset`.

    Parameters
    ----------
    data : dict
        ``{"images": [{id, file_name, width, height}, ...], "categories": [{id, name,
        keypoints?, skeleton?}, ...], "annotations": [{id, image_id, category_id, bbox:
        [x, y, w, h], area?, iscrowd?, segmentation?, keypoints?, num_keypoints?},
        ...]}``. Other fields (info, licenses) are not kept; a missing ``area`` is
        ``w * h``, a missing ``iscrowd`` 0, a missing ``num_keypoints`` the count of
        keypoints with ``v > 0``.

    Returns
    -------
    CocoDataset

    Raises
    ------
    InputError
        A missing list or field, a duplicate id, an ``image_id`` or ``category_id`` not
        listed, a bbox that is not 4 finite numbers with ``w, h >= 0``, keypoints that
        are not ``3 K`` finite numbers, annotations with different ``K`` (or a ``K``
        other than their category's ``keypoints`` names), a ``skeleton`` link outside
        ``1..K``: the message names the annotation id and the fix.

    Examples
    --------
    >>> coco_from_dict({"images": [], "categories": [], "annotations": [
    ...     {"id": 5, "image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1]}]})
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: annotation id 5 has image_id 1, which is not in the ...
    """
    return _parse_coco(data, InputError)


def _load_json(path: str | os.PathLike[str], what: str) -> Any:
    p = check_file(path, what)
    try:
        with open(p, encoding="utf-8") as f:
            return json.load(f)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{p}: not a JSON file ({exc})") from None


def read_coco_json(path: str | os.PathLike[str]) -> CocoDataset:
    """Read a COCO ground-truth JSON file (instances or keypoints: boxes, segmentations and
    keypoints are kept).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    CocoDataset

    Raises
    ------
    FileFormatError
        Not a file, not JSON, or any problem :func:`coco_from_dict` names (with the
        same message, prefixed by the path).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = {"images": [{"id": 1, "file_name": "a.png", "width": 8, "height": 8}],
    ...      "categories": [{"id": 1, "name": "x"}], "annotations": []}
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "gt.json"
    >>> _ = write_coco_json(coco_from_dict(d), p)
    >>> len(read_coco_json(p).images)
    1
    """
    data = _load_json(path, "a COCO JSON file")
    try:
        return _parse_coco(data, FileFormatError)
    except FileFormatError as exc:
        raise FileFormatError(f"{path}: {exc}") from None


def coco_to_dict(dataset: CocoDataset) -> dict[str, Any]:
    """:class:`CocoDataset` as a COCO dict (``images``, ``categories``, ``annotations``).

    Keypoints (``keypoints`` ``[x, y, v] * K`` and ``num_keypoints``) are written on every
    annotation when the data set has them (``K > 0``), and a keypoint category's names
    and 1-based ``skeleton``; :func:`coco_from_dict` reads the dict back unchanged.

    Examples
    --------
    >>> d = {"images": [{"id": 1, "file_name": "a.png", "width": 8, "height": 8}],
    ...      "categories": [{"id": 1, "name": "x"}],
    ...      "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                       "bbox": [1.0, 2.0, 3.0, 4.0], "area": 12.0, "iscrowd": 0}]}
    >>> coco_to_dict(coco_from_dict(d))["annotations"] == d["annotations"]
    True
    """
    if not isinstance(dataset, CocoDataset):
        raise InputError(f"dataset must be a CocoDataset; got {type(dataset).__name__}")
    return {
        "images": [
            {"id": i.id, "file_name": i.file_name, "width": i.width, "height": i.height}
            for i in dataset.images
        ],
        "categories": [c.to_dict() for c in dataset.categories],
        "annotations": [
            {
                "id": int(a),
                "image_id": int(i),
                "category_id": int(c),
                "bbox": b.tolist(),
                "area": float(ar),
                "iscrowd": int(cr),
                **({"segmentation": sg} if sg is not None else {}),
                **({"keypoints": kp.ravel().tolist(), "num_keypoints": int(nk)} if kp.size else {}),
            }
            for a, i, c, b, ar, cr, sg, kp, nk in zip(
                dataset.ann_ids,
                dataset.image_ids,
                dataset.category_ids,
                dataset.boxes,
                dataset.areas,
                dataset.iscrowd,
                dataset.segmentations or (None,) * len(dataset),
                dataset.keypoints,
                dataset.num_keypoints,
                strict=True,
            )
        ],
    }


def _write_json(obj: Any, path: str | os.PathLike[str]) -> Path:
    p = as_path(path)
    if p.is_dir():
        raise InputError(f"{p} is a folder; give a .json file path")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(obj), encoding="utf-8")
    return p


def write_coco_json(dataset: CocoDataset, path: str | os.PathLike[str]) -> Path:
    """Write a :class:`CocoDataset` as COCO JSON; returns the path (see
    :func:`read_coco_json` for an example). Folders are created."""
    return _write_json(coco_to_dict(dataset), path)


def _parse_results(data: Any, err: type[Exception]) -> CocoResults:
    if not isinstance(data, list):
        raise err(
            "COCO results must be a list of {image_id, category_id, bbox, score}; got "
            f"{type(data).__name__}"
        )
    n = len(data)
    img = np.empty(n, dtype=np.int64)
    cat = np.empty(n, dtype=np.int64)
    scores = np.empty(n, dtype=np.float64)
    rows: list[Any] = []
    segs: list[Any] = []
    kps: list[Any] = []
    fix = (
        "each result needs image_id, category_id, score and bbox [x, y, w, h] (or a "
        "segmentation RLE, or keypoints [x, y, s] * K)"
    )
    for k, r in enumerate(data):
        where = f"results[{k}]"
        img[k] = _as_int(_field(r, "image_id", where, fix, err), f"{where}.image_id", err)
        cat[k] = _as_int(_field(r, "category_id", where, fix, err), f"{where}.category_id", err)
        seg = r.get("segmentation")
        kp = r.get("keypoints")
        kps.append(kp)
        if seg is not None:
            try:
                box = rle_to_bbox(seg).tolist() if isinstance(seg, Mapping) else None
            except InputError as exc:
                raise err(f"{where}.segmentation: {exc}") from None
            if box is None:
                raise err(
                    f"{where}.segmentation must be an RLE dict {{'size': [h, w], 'counts': "
                    "...}} (COCO results hold masks as RLE)"
                )
            # as pycocotools' loadRes: the mask's box where no bbox is given
            rows.append(r["bbox"] if "bbox" in r else box)
        elif kp is not None and "bbox" not in r:
            rows.append(None)  # the tight box of the keypoints, below
        else:
            rows.append(_field(r, "bbox", where, fix, err))
        segs.append(seg)
        s = _field(r, "score", where, fix, err)
        if isinstance(s, bool) or not isinstance(s, (int, float, np.floating, np.integer)):
            raise err(f"{where}.score must be a number; got {plain_repr(s)}")
        if not math.isfinite(s):
            raise err(f"{where}.score is {s}; scores must be finite: drop that detection")
        scores[k] = s
    has_kp = [kp is not None for kp in kps]
    if any(has_kp) and not all(has_kp):
        k = has_kp.index(not has_kp[0])
        which = "has no" if has_kp[0] else "has"
        raise err(
            f"results[{k}] {which} 'keypoints' unlike results[0]: keypoint results give "
            "keypoints [x, y, s] * K on every detection, box and mask results on none"
        )
    keypoints = _keypoints_rows(kps, [f"results[{k}]" for k in range(n)], err)
    empty = [j for j, kp in enumerate(kps) if isinstance(kp, list) and not kp]
    if any(has_kp) and empty:
        k = empty[0]
        raise err(f"results[{k}].keypoints is empty: give [x, y, s] for each of the K keypoints")
    for k in [j for j, row in enumerate(rows) if row is None]:
        # as pycocotools' loadRes: the tight box of all the keypoints, area (x1-x0)(y1-y0)
        x, y = keypoints[k, :, 0], keypoints[k, :, 1]
        x0, x1, y0, y1 = x.min(), x.max(), y.min(), y.max()
        rows[k] = [x0, y0, x1 - x0, y1 - y0]
    boxes = _boxes_array(rows, [f"[{k}]" for k in range(n)], "results", err)
    kept = tuple(segs) if any(sg is not None for sg in segs) else ()
    return CocoResults(
        _readonly(img), _readonly(cat), _readonly(boxes), _readonly(scores), kept, keypoints
    )


def results_from_list(results: Sequence[Mapping[str, Any]]) -> CocoResults:
    """A COCO results list (``[{"image_id", "category_id", "bbox", "score"}, ...]``) as
    :class:`CocoResults`.

    Raises
    ------
    InputError
        Not a list, a missing field, a bbox that is not 4 finite numbers with
        ``w, h >= 0``, a NaN/inf score.

    Examples
    --------
    >>> results_from_list([{"image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1],
    ...                     "score": float("nan")}])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: results[0].score is nan; scores must be finite: ...
    """
    return _parse_results(results, InputError)


def read_coco_results(path: str | os.PathLike[str]) -> CocoResults:
    """Read a COCO results JSON file (a list of detections); errors as
    :func:`results_from_list` but as :class:`FileFormatError` prefixed by the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "res.json"
    >>> r = results_from_list([{"image_id": 1, "category_id": 2, "bbox": [0, 0, 3, 3],
    ...                         "score": 0.5}])
    >>> read_coco_results(write_coco_results(r, p)).category_ids.tolist()
    [2]
    """
    data = _load_json(path, "a COCO results JSON file")
    try:
        return _parse_results(data, FileFormatError)
    except FileFormatError as exc:
        raise FileFormatError(f"{path}: {exc}") from None


def results_to_list(results: CocoResults) -> list[dict[str, Any]]:
    """:class:`CocoResults` as the COCO results list (with ``keypoints`` ``[x, y, s] * K``
    on each detection of keypoint results, and always the ``bbox``).

    Examples
    --------
    >>> r = results_from_list([{"image_id": 1, "category_id": 2, "bbox": [0, 0, 3, 3],
    ...                         "score": 0.5}])
    >>> results_to_list(r)
    [{'image_id': 1, 'category_id': 2, 'bbox': [0.0, 0.0, 3.0, 3.0], 'score': 0.5}]
    """
    if not isinstance(results, CocoResults):
        raise InputError(f"results must be CocoResults; got {type(results).__name__}")
    return [
        {
            "image_id": int(i),
            "category_id": int(c),
            "bbox": b.tolist(),
            "score": float(s),
            **({"segmentation": sg} if sg is not None else {}),
            **({"keypoints": kp.ravel().tolist()} if kp.size else {}),
        }
        for i, c, b, s, sg, kp in zip(
            results.image_ids,
            results.category_ids,
            results.boxes,
            results.scores,
            results.segmentations or (None,) * len(results),
            results.keypoints,
            strict=True,
        )
    ]


def write_coco_results(results: CocoResults, path: str | os.PathLike[str]) -> Path:
    """Write :class:`CocoResults` as a COCO results JSON file; returns the path."""
    return _write_json(results_to_list(results), path)


def results_from_ground_truth(
    dataset: CocoDataset, score: float = 1.0, *, require_keypoints: bool = False
) -> CocoResults:
    """The non-crowd ground-truth boxes (and keypoints, when the data set has them) as
    detections of one ``score``: a perfect detector, whose every AP is 1.

    Parameters
    ----------
    dataset : CocoDataset
    score : float
    require_keypoints : bool
        Keep only the annotations with labelled keypoints (``num_keypoints > 0``): the
        perfect keypoint detector. The keypoint evaluation ignores the others, so as
        detections they would be false positives there (their OKS with themselves uses
        the box-extended distance of unlabelled ground truth).

    Returns
    -------
    CocoResults
        Boxes, scores and ``keypoints`` ``(N, K, 3)`` (the ground truth's ``v`` stands in
        the score column).

    Examples
    --------
    >>> ds = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 9, "height": 9}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 2, 2]},
    ...                     {"id": 2, "image_id": 1, "category_id": 1, "bbox": [0, 0, 9, 9],
    ...                      "iscrowd": 1}]})
    >>> len(results_from_ground_truth(ds))
    1
    """
    if not isinstance(dataset, CocoDataset):
        raise InputError(f"dataset must be a CocoDataset; got {type(dataset).__name__}")
    s = check_real(score, "score")
    keep = ~dataset.iscrowd
    if check_bool(require_keypoints, "require_keypoints"):
        keep &= dataset.num_keypoints > 0
    n = int(keep.sum())
    return CocoResults(
        _readonly(dataset.image_ids[keep].copy()),
        _readonly(dataset.category_ids[keep].copy()),
        _readonly(dataset.boxes[keep].copy()),
        _readonly(np.full(n, s)),
        (),
        dataset.keypoints[keep],
    )


# ----------------------------------------------------------------------------- VOC XML


@dataclass(frozen=True)
class VocObject:
    """One ``<object>`` of a VOC file: class ``name``, ``bbox`` = (xmin, ymin, xmax,
    ymax) in pixels as written, and the ``difficult`` and ``truncated`` flags."""

    name: str
    bbox: tuple[float, float, float, float]
    difficult: bool = False
    truncated: bool = False


@dataclass(frozen=True)
class VocAnnotation:
    """One Pascal-VOC annotation file: ``filename``, ``width``, ``height``, ``depth`` and
    its ``objects``."""

    filename: str
    width: int
    height: int
    depth: int
    objects: tuple[VocObject, ...] = field(default_factory=tuple)


def _voc_text(node: ET.Element, tag: str, where: str, required: bool = True) -> str | None:
    child = node.find(tag)
    if child is None or child.text is None or not child.text.strip():
        if required:
            raise FileFormatError(f"{where} has no <{tag}>: a Pascal-VOC file needs it")
        return None
    return child.text.strip()


def _voc_number(node: ET.Element, tag: str, where: str, required: bool = True) -> float | None:
    text = _voc_text(node, tag, where, required)
    if text is None:
        return None
    try:
        v = float(text)
    except ValueError:
        raise FileFormatError(f"{where}: <{tag}> must be a number; got {text!r}") from None
    if not math.isfinite(v):
        raise FileFormatError(f"{where}: <{tag}> is {text!r}; it must be finite")
    return v


def read_voc_xml(path: str | os.PathLike[str]) -> VocAnnotation:
    """Read one Pascal-VOC annotation XML file.

    Reads ``<filename>``, ``<size>`` (width, height, depth) and every ``<object>``
    (``<name>``, ``<difficult>``, ``<truncated>``, ``<bndbox>`` xmin/ymin/xmax/ymax).
    Files with a DOCTYPE or entity declarations are refused (no entity expansion).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    VocAnnotation

    Raises
    ------
    FileFormatError
        Not a file, not XML, a root other than ``<annotation>``, a DTD, a missing tag,
        a coordinate that is not a finite number, ``xmax < xmin`` or ``ymax < ymin``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.xml"
    >>> _ = p.write_text("<annotation><filename>a.jpg</filename><size><width>10</width>"
    ...     "<height>8</height><depth>3</depth></size><object><name>tree</name>"
    ...     "<bndbox><xmin>1</xmin><ymin>2</ymin><xmax>5</xmax><ymax>6</ymax></bndbox>"
    ...     "</object></annotation>")
    >>> read_voc_xml(p).objects[0]
    VocObject(name='tree', bbox=(1.0, 2.0, 5.0, 6.0), difficult=False, truncated=False)
    """
    p = check_file(path, "a Pascal-VOC XML file")
    raw = p.read_bytes()
    if b"<!DOCTYPE" in raw or b"<!ENTITY" in raw:
        raise FileFormatError(
            f"{p}: has a DOCTYPE/ENTITY declaration; VOC files have none and they are "
            "refused (entity expansion)"
        )
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as exc:
        raise FileFormatError(f"{p}: not an XML file ({exc})") from None
    if root.tag != "annotation":
        raise FileFormatError(f"{p}: the root element is <{root.tag}>, not <annotation>")
    where = str(p)
    filename = _voc_text(root, "filename", where) or ""
    size = root.find("size")
    if size is None:
        raise FileFormatError(f"{p} has no <size>: a Pascal-VOC file needs it")
    w = int(_voc_number(size, "width", f"{p} <size>") or 0)
    h = int(_voc_number(size, "height", f"{p} <size>") or 0)
    d = int(_voc_number(size, "depth", f"{p} <size>", required=False) or 0)
    objects = []
    for k, obj in enumerate(root.findall("object")):
        ow = f"{p} <object> {k}"
        name = _voc_text(obj, "name", ow) or ""
        box = obj.find("bndbox")
        if box is None:
            raise FileFormatError(f"{ow} ({name}) has no <bndbox>")
        x0, y0, x1, y1 = (
            float(_voc_number(box, t, f"{ow} ({name}) <bndbox>") or 0.0)
            for t in ("xmin", "ymin", "xmax", "ymax")
        )
        if x1 < x0 or y1 < y0:
            raise FileFormatError(
                f"{ow} ({name}): bndbox ({x0:g}, {y0:g}, {x1:g}, {y1:g}) has xmax < xmin or "
                "ymax < ymin; swap them"
            )
        diff = _voc_number(obj, "difficult", ow, required=False) or 0.0
        trunc = _voc_number(obj, "truncated", ow, required=False) or 0.0
        objects.append(VocObject(name, (x0, y0, x1, y1), bool(diff), bool(trunc)))
    return VocAnnotation(filename, w, h, d, tuple(objects))


def voc_to_coco(
    annotations: Sequence[VocAnnotation],
    categories: Sequence[str] | None = None,
    *,
    include_difficult: bool = True,
) -> CocoDataset:
    """A set of VOC annotations as one :class:`CocoDataset`.

    Images get ids 1, 2, ... in the order given; categories ids 1, 2, ... in the order
    of ``categories`` (default: the sorted class names found); annotations ids 1, 2, ...
    A VOC box ``(xmin, ymin, xmax, ymax)`` becomes ``[xmin, ymin, xmax - xmin,
    ymax - ymin]`` (continuous coordinates, no "+1"), with ``area = w h``.

    Parameters
    ----------
    annotations : sequence of VocAnnotation
    categories : sequence of str, optional
    include_difficult : bool
        ``False`` drops objects marked difficult.

    Returns
    -------
    CocoDataset

    Raises
    ------
    InputError
        Not VocAnnotation items, or a class name not in ``categories``.

    Examples
    --------
    >>> a = VocAnnotation("a.jpg", 10, 8, 3, (VocObject("tree", (1, 2, 5, 6)),))
    >>> ds = voc_to_coco([a])
    >>> ds.boxes.tolist(), ds.category_names()
    ([[1.0, 2.0, 4.0, 4.0]], {1: 'tree'})
    """
    if not isinstance(annotations, (list, tuple)) or not all(
        isinstance(a, VocAnnotation) for a in annotations
    ):
        raise InputError(
            "annotations must be a list of VocAnnotation (from read_voc_xml); got "
            f"{type(annotations).__name__}"
        )
    keep_difficult = check_bool(include_difficult, "include_difficult")
    names = sorted({o.name for a in annotations for o in a.objects})
    if categories is None:
        cats = names
    else:
        if not isinstance(categories, (list, tuple)) or not all(
            isinstance(c, str) for c in categories
        ):
            raise InputError(
                f"categories must be a list of class names; got {plain_repr(categories)}"
            )
        cats = list(categories)
        missing = sorted(set(names) - set(cats))
        if missing:
            raise InputError(
                f"class {missing[0]!r} is not in categories {plain_repr(cats)}: add it"
            )
    cat_id = {c: k + 1 for k, c in enumerate(cats)}
    rows: list[tuple[int, int, tuple[float, float, float, float]]] = []
    for i, a in enumerate(annotations):
        for o in a.objects:
            if o.difficult and not keep_difficult:
                continue
            rows.append((i + 1, cat_id[o.name], o.bbox))
    n = len(rows)
    boxes = np.array([b for _, _, b in rows], dtype=np.float64).reshape(n, 4)
    boxes[:, 2:] -= boxes[:, :2]
    return CocoDataset(
        tuple(CocoImage(i + 1, a.filename, a.width, a.height) for i, a in enumerate(annotations)),
        tuple(CocoCategory(k + 1, c) for k, c in enumerate(cats)),
        _readonly(np.arange(1, n + 1, dtype=np.int64)),
        _readonly(np.array([r[0] for r in rows], dtype=np.int64)),
        _readonly(np.array([r[1] for r in rows], dtype=np.int64)),
        _readonly(boxes),
        _readonly(boxes[:, 2] * boxes[:, 3]),
        _readonly(np.zeros(n, dtype=bool)),
    )


# ----------------------------------------------------------------------------- matching


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


# ----------------------------------------------------------------------------- evaluation


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


def _check_dataset(gt: Any) -> CocoDataset:
    if isinstance(gt, CocoDataset):
        return gt
    if isinstance(gt, Mapping):
        return coco_from_dict(gt)
    raise InputError(
        f"gt must be a CocoDataset or a COCO dict; got {type(gt).__name__}: use "
        "read_coco_json(path) or coco_from_dict(d)"
    )


def _check_results(results: Any, gt: CocoDataset) -> CocoResults:
    if isinstance(results, CocoResults):
        res = results
    elif isinstance(results, list):
        res = results_from_list(results)
    else:
        raise InputError(
            f"results must be CocoResults or a COCO results list; got {type(results).__name__}"
        )
    img_known = np.array([i.id for i in gt.images], dtype=np.int64)
    cat_known = np.array([c.id for c in gt.categories], dtype=np.int64)
    for what, ids, known in (
        ("image_id", res.image_ids, img_known),
        ("category_id", res.category_ids, cat_known),
    ):
        bad = ~np.isin(ids, known)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"results[{k}] has {what} {int(ids[k])}, which the ground truth does not "
                "list: detections must refer to the ground truth's images and categories"
            )
    return res


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
    if not gt.segmentations or any(sg is None for sg in gt.segmentations):
        k = 0 if not gt.segmentations else [sg is None for sg in gt.segmentations].index(True)
        raise InputError(
            f"annotation id {int(gt.ann_ids[k])} has no segmentation: iou_type='segm' "
            "needs polygons or an RLE on every ground-truth annotation"
        )
    if not res.segmentations or any(sg is None for sg in res.segmentations):
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
    gtd = _check_dataset(gt)
    res = _check_results(results, gtd)
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
        _readonly(precision),
        _readonly(recall),
        _readonly(scores),
        _readonly(_summary_stats(precision, recall, kp_eval)),
        _readonly(cat_ids),
        IOU_THRESHOLDS.copy(),
        RECALL_THRESHOLDS.copy(),
        md,
        KEYPOINT_SUMMARY_NAMES if kp_eval else SUMMARY_NAMES,
        _KP_AREA_NAMES if kp_eval else AREA_NAMES,
        iou_type,
    )


# ----------------------------------------------------------------------------- VOC AP


def voc_average_precision(recall: Any, precision: Any) -> float:
    r"""All-point interpolated average precision (Pascal VOC devkit, 2010 onwards).

    With the points framed as :math:`r = (0, r_1, \ldots, r_n, 1)`,
    :math:`p = (0, p_1, \ldots, p_n, 0)` and the envelope
    :math:`\hat p_i = \max_{j \ge i} p_j`,

    .. math:: AP = \sum_{i : r_{i+1} \ne r_i} (r_{i+1} - r_i)\, \hat p_{i+1},

    the area under the monotone envelope of the PR curve (``voc_ap(rec, prec,
    use_07_metric=False)`` of the devkit's Python port).

    Parameters
    ----------
    recall, precision : (N,) array_like
        Recall (non-decreasing) and precision after each detection in score order.

    Returns
    -------
    float

    Raises
    ------
    InputError
        Not 1-D arrays of one length, values outside [0, 1], recall decreasing.

    Examples
    --------
    >>> voc_average_precision([0.5, 0.5, 1.0], [1.0, 0.5, 2 / 3])
    0.8333333333333333
    """
    rec = check_numeric(recall, "recall")
    prec = check_numeric(precision, "precision")
    if rec.ndim != 1 or prec.shape != rec.shape:
        raise InputError(
            f"recall and precision must be 1-D arrays of one length; got shapes {rec.shape} "
            f"and {prec.shape}"
        )
    for name, v in (("recall", rec), ("precision", prec)):
        if not (np.isfinite(v).all() and (v >= 0).all() and (v <= 1).all()):
            raise InputError(f"{name} must hold finite values in [0, 1]")
    if (np.diff(rec) < 0).any():
        raise InputError("recall must be non-decreasing (detections in score order)")
    mrec = np.concatenate(([0.0], rec, [1.0]))
    mpre = np.concatenate(([0.0], prec, [0.0]))
    mpre = np.maximum.accumulate(mpre[::-1])[::-1]
    i = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[i + 1] - mrec[i]) * mpre[i + 1]))


@dataclass(frozen=True)
class VocEvaluation:
    """VOC evaluation at one IoU threshold: ``ap`` per category id (NaN for a category
    without ground truth), ``mean_ap`` over the categories with ground truth."""

    ap: dict[int, float]
    mean_ap: float
    iou_threshold: float


def evaluate_voc(
    gt: CocoDataset | Mapping[str, Any],
    results: CocoResults | list[Mapping[str, Any]],
    iou_threshold: float = 0.5,
) -> VocEvaluation:
    r"""Pascal-VOC mAP: per class, detections of all images in score order (stable)
    each take the unmatched ground truth of highest IoU in their image if that IoU
    exceeds ``iou_threshold`` (strictly, as the devkit); crowd ground truth plays VOC's
    "difficult" (a detection on it is neither TP nor FP, and it is not counted in the
    recall). AP is :func:`voc_average_precision`. IoU is continuous
    (:math:`|d \cap g| / |d \cup g|`, no "+1" pixel).

    Parameters
    ----------
    gt : CocoDataset or dict
    results : CocoResults or list of dict
    iou_threshold : float in [0, 1)

    Returns
    -------
    VocEvaluation

    Examples
    --------
    >>> gt = coco_from_dict({
    ...     "images": [{"id": 1, "file_name": "a", "width": 100, "height": 100}],
    ...     "categories": [{"id": 1, "name": "x"}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                      "bbox": [0, 0, 10, 10]},
    ...                     {"id": 2, "image_id": 1, "category_id": 1,
    ...                      "bbox": [50, 50, 10, 10]}]})
    >>> evaluate_voc(gt, [
    ...     {"image_id": 1, "category_id": 1, "bbox": [0, 0, 10, 10], "score": 0.9},
    ...     {"image_id": 1, "category_id": 1, "bbox": [20, 20, 10, 10], "score": 0.8},
    ...     {"image_id": 1, "category_id": 1, "bbox": [50, 50, 10, 10], "score": 0.7}]).mean_ap
    0.8333333333333333
    """
    thr = check_real(iou_threshold, "iou_threshold", 0.0, 1.0, high_inclusive=False)
    gtd = _check_dataset(gt)
    res = _check_results(results, gtd)
    ap: dict[int, float] = {}
    for c in sorted(x.id for x in gtd.categories):
        gsel = np.flatnonzero(gtd.category_ids == c)
        npos = int(np.count_nonzero(~gtd.iscrowd[gsel]))
        if npos == 0:
            ap[c] = float("nan")
            continue
        dsel = np.flatnonzero(res.category_ids == c)
        dsel = dsel[np.argsort(-res.scores[dsel], kind="stable")]
        taken = np.zeros(gsel.size, dtype=bool)
        tp = np.zeros(dsel.size)
        fp = np.zeros(dsel.size)
        g_img = gtd.image_ids[gsel]
        gb = gtd.boxes[gsel]
        for n, d in enumerate(dsel):
            cand = np.flatnonzero(g_img == res.image_ids[d])
            if cand.size == 0:
                fp[n] = 1
                continue
            b = res.boxes[d]
            g = gb[cand]
            w = np.minimum(b[0] + b[2], g[:, 0] + g[:, 2]) - np.maximum(b[0], g[:, 0])
            h = np.minimum(b[1] + b[3], g[:, 1] + g[:, 3]) - np.maximum(b[1], g[:, 1])
            inter = np.clip(w, 0, None) * np.clip(h, 0, None)
            union = b[2] * b[3] + g[:, 2] * g[:, 3] - inter
            iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)
            j = int(np.argmax(iou))
            if iou[j] > thr:
                if gtd.iscrowd[gsel[cand[j]]]:
                    continue
                if not taken[cand[j]]:
                    taken[cand[j]] = True
                    tp[n] = 1
                else:
                    fp[n] = 1
            else:
                fp[n] = 1
        keep = (tp + fp) > 0
        ctp, cfp = np.cumsum(tp[keep]), np.cumsum(fp[keep])
        rec = ctp / npos
        prec = ctp / np.maximum(ctp + cfp, np.finfo(np.float64).eps)
        ap[c] = voc_average_precision(rec, prec) if rec.size else 0.0
    vals = [v for v in ap.values() if not math.isnan(v)]
    return VocEvaluation(ap, float(np.mean(vals)) if vals else float("nan"), thr)


# ----------------------------------------------------------------------------- pictures


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
    (:func:`robopercept.viz.curves_picture`; 1600 x 1000 reads well on a 1080p screen).

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
    from robopercept.viz import curves_picture

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
    curves = []
    for k, c in enumerate(evaluation.category_ids.tolist()):
        p = evaluation.precision[t[0], :, k, 0, -1]
        if (p < 0).all():
            continue
        ap = float(p.mean())
        label = str(names.get(c, c)) if names is not None else str(c)
        curves.append((evaluation.recall_thresholds, p, f"{label} (AP {ap:.3f})"))
    if not curves:
        raise InputError("no category has ground truth: there is no PR curve to draw")
    return curves_picture(
        curves,
        title=f"precision-recall per class, IoU {thr:.2f}",
        xlabel="recall",
        ylabel="precision",
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
    from robopercept.imaging import write_image

    p = as_path(path)
    if p.suffix.lower() != ".png":
        raise InputError(f"{p}: PR curves are written as PNG; give a path ending in .png")
    img = pr_curves_picture(evaluation, iou_threshold=iou_threshold, names=names)
    p.parent.mkdir(parents=True, exist_ok=True)
    return write_image(p, img)
