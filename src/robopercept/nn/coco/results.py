r"""COCO detection results: the :class:`CocoResults` record and the results file.

NumPy only (no torch). A COCO results file is a list of
``{"image_id", "category_id", "bbox", "score"}`` (or ``"segmentation"`` RLE masks, or
``"keypoints"`` ``[x, y, s] * K``): :func:`read_coco_results`, :func:`results_from_list`,
:func:`write_coco_results`, :func:`results_to_list`. As pycocotools' ``loadRes``, a
mask result without a ``bbox`` gets its mask's box, and a keypoint result without one
the tight box of its keypoints. :func:`results_from_ground_truth` is the perfect
detector of a :class:`~robopercept.nn.coco.dataset.CocoDataset`, and
:func:`as_coco_results` checks results against their ground truth for the evaluations
(:mod:`robopercept.nn.coco.evaluate`, :func:`robopercept.nn.coco.voc.evaluate_voc`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import check_bool, check_real, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco._fields import (
    as_int,
    boxes_array,
    json_field,
    keypoint_array,
    keypoints_rows,
    load_json,
    readonly,
    record_rows,
    write_json,
)
from robopercept.nn.coco.dataset import CocoDataset
from robopercept.nn.coco.rle import rle_to_bbox

__all__ = [
    "CocoResults",
    "as_coco_results",
    "read_coco_results",
    "results_from_ground_truth",
    "results_from_list",
    "results_to_list",
    "write_coco_results",
]


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
        n = record_rows(self.scores, "CocoResults.scores")
        object.__setattr__(
            self, "keypoints", keypoint_array(self.keypoints, n, "CocoResults.keypoints")
        )

    def __len__(self) -> int:
        return int(self.scores.size)


_FROM_KEYPOINTS = object()  # a keypoint result's box: the tight box of its keypoints


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
        img[k] = as_int(json_field(r, "image_id", where, fix, err), f"{where}.image_id", err)
        cat[k] = as_int(json_field(r, "category_id", where, fix, err), f"{where}.category_id", err)
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
            rows.append(_FROM_KEYPOINTS)  # the tight box of the keypoints, below
        else:
            rows.append(json_field(r, "bbox", where, fix, err))
        segs.append(seg)
        s = json_field(r, "score", where, fix, err)
        if isinstance(s, bool) or not isinstance(s, (int, float, np.floating, np.integer)):
            raise err(f"{where}.score must be a number; got {plain_repr(s)}")
        if isinstance(s, int) and abs(s) > 2**1023:  # math.isfinite would overflow
            raise err(f"{where}.score {plain_repr(s)} is beyond float64: give a score in [0, 1]")
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
    keypoints = keypoints_rows(kps, [f"results[{k}]" for k in range(n)], err)
    empty = [j for j, kp in enumerate(kps) if isinstance(kp, list) and not kp]
    if any(has_kp) and empty:
        k = empty[0]
        raise err(f"results[{k}].keypoints is empty: give [x, y, s] for each of the K keypoints")
    for k in [j for j, row in enumerate(rows) if row is _FROM_KEYPOINTS]:
        # as pycocotools' loadRes: the tight box of all the keypoints, area (x1-x0)(y1-y0)
        x, y = keypoints[k, :, 0], keypoints[k, :, 1]
        x0, x1, y0, y1 = x.min(), x.max(), y.min(), y.max()
        rows[k] = [x0, y0, x1 - x0, y1 - y0]
    boxes = boxes_array(rows, [f"[{k}]" for k in range(n)], "results", err)
    kept = tuple(segs) if any(sg is not None for sg in segs) else ()
    return CocoResults(
        readonly(img), readonly(cat), readonly(boxes), readonly(scores), kept, keypoints
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
    data = load_json(path, "a COCO results JSON file")
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
    return write_json(results_to_list(results), path)


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
    >>> from robopercept.nn.coco.dataset import coco_from_dict
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
        readonly(dataset.image_ids[keep].copy()),
        readonly(dataset.category_ids[keep].copy()),
        readonly(dataset.boxes[keep].copy()),
        readonly(np.full(n, s)),
        (),
        dataset.keypoints[keep],
    )


def as_coco_results(results: Any, gt: CocoDataset) -> CocoResults:
    """The detections of an evaluation as :class:`CocoResults` (a COCO results list
    through :func:`results_from_list`), checked against the ground truth: every
    ``image_id`` and ``category_id`` must be one that ``gt`` lists.

    Parameters
    ----------
    results : CocoResults or list of dict
    gt : CocoDataset

    Returns
    -------
    CocoResults

    Raises
    ------
    InputError
        ``results`` neither CocoResults nor a list (or what :func:`results_from_list`
        refuses), ``gt`` not a CocoDataset, or a detection naming an image or category
        the ground truth lacks.

    Examples
    --------
    >>> from robopercept.nn.coco.dataset import coco_from_dict
    >>> gt = coco_from_dict({"images": [{"id": 1, "file_name": "a", "width": 9,
    ...     "height": 9}], "categories": [{"id": 1, "name": "x"}], "annotations": []})
    >>> as_coco_results([{"image_id": 2, "category_id": 1, "bbox": [0, 0, 1, 1],
    ...                   "score": 0.5}], gt)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: results[0] has image_id 2, which the ground truth ...
    """
    if not isinstance(gt, CocoDataset):
        raise InputError(
            f"gt must be a CocoDataset; got {type(gt).__name__}: use as_coco_dataset(gt)"
        )
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
