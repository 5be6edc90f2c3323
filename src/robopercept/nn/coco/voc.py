r"""Pascal VOC: the annotation XML files and the VOC average precision.

NumPy only (no torch). :func:`read_voc_xml` reads one Pascal-VOC annotation file
(:class:`VocAnnotation` of :class:`VocObject`); :func:`voc_to_coco` turns a set of them
into a :class:`~robopercept.nn.coco.dataset.CocoDataset`.

:func:`voc_average_precision` is the all-point interpolated AP of the Pascal VOC devkit
(2010 onwards), and :func:`evaluate_voc` the VOC matching at one IoU threshold per class
(:class:`VocEvaluation`). The COCO evaluation is :mod:`robopercept.nn.coco.evaluate`.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept._checks import check_bool, check_file, check_numeric, check_real
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import parse_xml
from robopercept.nn.coco._fields import category_list, readonly
from robopercept.nn.coco.dataset import CocoCategory, CocoDataset, CocoImage, as_coco_dataset
from robopercept.nn.coco.results import CocoResults, as_coco_results

__all__ = [
    "VocAnnotation",
    "VocEvaluation",
    "VocObject",
    "evaluate_voc",
    "read_voc_xml",
    "voc_average_precision",
    "voc_to_coco",
]


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
        Not a file, not XML, a root other than ``<annotation>``, a DTD, nested deeper
        than :data:`robopercept.fileio.MAX_NESTING` (:func:`~robopercept.fileio.parse_xml`),
        a missing tag,
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
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    root = parse_xml(raw, str(p))  # no DTD (entity expansion), nesting bounded
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
    cats = category_list(names, categories, "class")
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
        readonly(np.arange(1, n + 1, dtype=np.int64)),
        readonly(np.array([r[0] for r in rows], dtype=np.int64)),
        readonly(np.array([r[1] for r in rows], dtype=np.int64)),
        readonly(boxes),
        readonly(boxes[:, 2] * boxes[:, 3]),
        readonly(np.zeros(n, dtype=bool)),
    )


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
    >>> from robopercept.nn.coco.dataset import coco_from_dict
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
    gtd = as_coco_dataset(gt)
    res = as_coco_results(results, gtd)
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
