r"""COCO ground truth: the :class:`CocoDataset` record and the COCO JSON file.

NumPy only (no torch). :class:`CocoDataset` is a frozen record of a COCO ground-truth
file: images (id, file_name, width, height), categories (id, name and, for keypoint
categories, the ``keypoints`` names and 1-based ``skeleton`` links) and annotations as
arrays (id, image_id, category_id, ``bbox`` = ``[x, y, w, h]``, area, iscrowd, and the
keypoints ``[x, y, v] * K`` as a ``(N, K, 3)`` array with ``num_keypoints``). Read it with
:func:`read_coco_json` or :func:`coco_from_dict`, write it with :func:`write_coco_json` /
:func:`coco_to_dict`; :func:`as_coco_dataset` takes either form for the evaluations. Each
annotation's ``segmentation`` is kept as the file gives it (for the ``segm`` evaluation,
:mod:`robopercept.nn.coco.evaluate`). One data set holds one keypoint layout: every
annotation with keypoints has the same ``K``, and an annotation without them gets ``K``
unlabelled points (``v = 0``).

Results files are :mod:`robopercept.nn.coco.results`, Pascal-VOC files
:mod:`robopercept.nn.coco.voc`.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import check_numeric, plain_repr
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

__all__ = [
    "CocoCategory",
    "CocoDataset",
    "CocoImage",
    "as_coco_dataset",
    "coco_from_dict",
    "coco_to_dict",
    "read_coco_json",
    "write_coco_json",
]

_EMPTY_I = np.zeros(0, dtype=np.int64)


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
        n = record_rows(self.ann_ids, "CocoDataset.ann_ids")
        kp = keypoint_array(self.keypoints, n, "CocoDataset.keypoints")
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
        object.__setattr__(self, "num_keypoints", readonly(nk))

    def __len__(self) -> int:
        return int(self.ann_ids.size)

    def category_names(self) -> dict[int, str]:
        """``{category id: name}``."""
        return {c.id: c.name for c in self.categories}


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
        iid = as_int(json_field(im, "id", where, fix, err), f"{where}.id", err)
        name = json_field(im, "file_name", where, fix, err)
        if not isinstance(name, str):
            raise err(f"{where}.file_name must be a string; got {plain_repr(name)}")
        w = as_int(json_field(im, "width", where, fix, err), f"{where}.width", err)
        h = as_int(json_field(im, "height", where, fix, err), f"{where}.height", err)
        if w < 0 or h < 0:
            raise err(f"{where} (id {iid}) has a negative size {w} x {h}")
        images.append(CocoImage(iid, name, w, h))
    cats = []
    for k, c in enumerate(lists["categories"]):
        where = f"categories[{k}]"
        fix = "each category needs id and name"
        cid = as_int(json_field(c, "id", where, fix, err), f"{where}.id", err)
        name = json_field(c, "name", where, fix, err)
        sup = c.get("supercategory") or ""
        if not isinstance(name, str) or not isinstance(sup, str):
            raise err(f"{where}: name and supercategory must be strings; got {plain_repr(name)}")
        names, links = _category_keypoints(c, f"{where} (id {cid})", err)
        cats.append(CocoCategory(cid, name, sup, names, links))
    for what, ids in (("image", [i.id for i in images]), ("category", [c.id for c in cats])):
        if len(set(ids)) != len(ids):
            dup = next(i for i, count in Counter(ids).items() if count > 1)
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
        aid = as_int(json_field(a, "id", where, fix, err), f"{where}.id", err)
        where = f"annotation id {aid}"
        ann_ids[k] = aid
        img_ids[k] = as_int(json_field(a, "image_id", where, fix, err), f"{where}: image_id", err)
        cat_ids[k] = as_int(
            json_field(a, "category_id", where, fix, err), f"{where}: category_id", err
        )
        rows.append(json_field(a, "bbox", where, fix, err))
        segs.append(a.get("segmentation"))
        kp_rows.append(a.get("keypoints"))
        if "num_keypoints" in a:
            nk = as_int(a["num_keypoints"], f"{where}: num_keypoints", err)
            if nk < 0:
                raise err(f"{where}: num_keypoints must be >= 0; got {nk}")
            num_kp[k] = nk
        if "area" in a:
            ar = a["area"]
            if (
                isinstance(ar, bool)
                or not isinstance(ar, (int, float))
                or (isinstance(ar, int) and abs(ar) > 2**1023)  # math.isfinite overflows
                or not math.isfinite(ar)
            ):
                raise err(f"{where}: area must be a finite number; got {plain_repr(ar)}")
            areas[k] = ar
            has_area[k] = True
        if "iscrowd" in a:
            ic = a["iscrowd"]
            if not isinstance(ic, (int, np.integer)) or ic not in (0, 1):
                raise err(f"{where}: iscrowd must be 0 or 1; got {plain_repr(ic)}")
            crowd[k] = bool(ic)
    boxes = boxes_array(rows, ann_ids.tolist(), "annotation id", err)
    areas[~has_area] = boxes[~has_area, 2] * boxes[~has_area, 3]
    keypoints = keypoints_rows(kp_rows, [f"annotation id {a}" for a in ann_ids.tolist()], err)
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
        readonly(ann_ids),
        readonly(img_ids),
        readonly(cat_ids),
        readonly(boxes),
        readonly(areas),
        readonly(crowd),
        tuple(segs) if any(sg is not None for sg in segs) else (),
        keypoints,
        readonly(num_kp),
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
    data = load_json(path, "a COCO JSON file")
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


def write_coco_json(dataset: CocoDataset, path: str | os.PathLike[str]) -> Path:
    """Write a :class:`CocoDataset` as COCO JSON; returns the path (see
    :func:`read_coco_json` for an example). Folders are created."""
    return write_json(coco_to_dict(dataset), path)


def as_coco_dataset(gt: Any) -> CocoDataset:
    """The ground truth of an evaluation as a :class:`CocoDataset`: one as is, a COCO
    dict through :func:`coco_from_dict`.

    Parameters
    ----------
    gt : CocoDataset or dict

    Returns
    -------
    CocoDataset

    Raises
    ------
    InputError
        Neither a CocoDataset nor a mapping, or what :func:`coco_from_dict` refuses.

    Examples
    --------
    >>> ds = as_coco_dataset({"images": [], "categories": [{"id": 1, "name": "x"}],
    ...                       "annotations": []})
    >>> as_coco_dataset(ds) is ds, ds.category_names()
    (True, {1: 'x'})
    """
    if isinstance(gt, CocoDataset):
        return gt
    if isinstance(gt, Mapping):
        return coco_from_dict(gt)
    raise InputError(
        f"gt must be a CocoDataset or a COCO dict; got {type(gt).__name__}: use "
        "read_coco_json(path) or coco_from_dict(d)"
    )
