"""The field checks shared by the COCO ground-truth and results readers (private to
:mod:`robopercept.nn.coco`): JSON objects and their fields, integer ids, ``[x, y, w, h]``
boxes, flat keypoint lists ``[x, y, v] * K``, JSON files, and the read-only arrays of the
records (:class:`~robopercept.nn.coco.dataset.CocoDataset`,
:class:`~robopercept.nn.coco.results.CocoResults`).

Each parser takes the exception type to raise (``err``): :class:`InputError` for a dict
or list given in Python, :class:`FileFormatError` for a file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_numeric, plain_repr
from robopercept.errors import InputError
from robopercept.fileio import read_json

__all__ = [
    "as_int",
    "boxes_array",
    "category_list",
    "json_field",
    "keypoint_array",
    "keypoints_rows",
    "load_json",
    "readonly",
    "record_rows",
    "write_json",
]


def readonly(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only in place (the records' arrays are frozen); returns ``a``."""
    a.setflags(write=False)
    return a


def record_rows(value: Any, name: str) -> int:
    """The number of rows ``N`` of a record's column (its first dimension)."""
    try:
        shape = np.shape(value)
    except (TypeError, ValueError):
        shape = ()
    if len(shape) < 1:
        raise InputError(f"{name} must be a 1-D array, one entry per row; got {plain_repr(value)}")
    return int(shape[0])


def keypoint_array(value: Any, n: int, name: str) -> np.ndarray:
    """``value`` as a read-only finite (n, K, 3) float64 array; an empty (0, 0, 3) one
    (the records' default) gives (n, 0, 3)."""
    kp = check_numeric(value, name)
    if kp.shape == (0, 0, 3):
        return readonly(np.zeros((n, 0, 3)))
    if kp.ndim != 3 or kp.shape[0] != n or kp.shape[2] != 3:
        raise InputError(
            f"{name} must be ({n}, K, 3) (x, y, v per keypoint, one row per entry); got "
            f"shape {kp.shape}"
        )
    if not np.isfinite(kp).all():
        raise InputError(f"{name} holds NaN or inf; keypoints must be finite (v = 0 if unlabelled)")
    if isinstance(value, np.ndarray) and value.dtype == np.float64 and not value.flags.writeable:
        return value  # read-only already (the readers' arrays): no copy
    return readonly(kp.copy())


def json_field(item: Any, key: str, where: str, fix: str, err: type[Exception]) -> Any:
    """``item[key]`` of a JSON object; ``err`` (naming ``where`` and the ``fix``) when
    ``item`` is not a mapping or lacks ``key``."""
    if not isinstance(item, Mapping):
        raise err(f"{where} must be a JSON object; got {type(item).__name__} {plain_repr(item)}")
    if key not in item:
        raise err(f"{where} has no '{key}' field: {fix}")
    return item[key]


def as_int(value: Any, what: str, err: type[Exception]) -> int:
    """``value`` as an int that fits int64 (integral floats such as ``3.0`` accepted)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        if not (isinstance(value, float) and value.is_integer()):
            raise err(f"{what} must be an integer; got {plain_repr(value)}")
    out = int(value)
    if not -(2**63) <= out < 2**63:
        raise err(f"{what} must fit in 64 bits; got {out}")
    return out


def _is_number(v: Any) -> bool:
    """``v`` is an int or float (NumPy's too), not a bool."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(
        v, (bool, np.bool_)
    )


def _box_row(b: Any) -> bool:
    """``b`` is 4 numbers: a list or tuple of 4 ints or floats, or a numeric (4,) array."""
    if isinstance(b, np.ndarray):
        return b.shape == (4,) and b.dtype.kind in "iuf"
    return isinstance(b, (list, tuple)) and len(b) == 4 and all(_is_number(v) for v in b)


def boxes_array(rows: list[Any], ids: Sequence[Any], what: str, err: type[Exception]) -> np.ndarray:
    """``rows`` (each a 4-list) as a (N, 4) float64 array of finite boxes with w, h >= 0;
    ``err`` naming the entry (``what`` and its id in ``ids``) for a row that is not 4
    numbers (None, a string, nested lists, booleans), not finite, beyond 1e15 or of
    negative size."""
    for k, b in enumerate(rows):
        if not _box_row(b):
            raise err(
                f"{what} {ids[k]}: bbox must be 4 numbers [x, y, width, height]; got "
                f"{plain_repr(b)}"
            )
    try:
        boxes = np.array(rows, dtype=np.float64).reshape(len(rows), 4)
    except OverflowError:  # an integer beyond float64 (JSON allows any digits)
        k = next(j for j, b in enumerate(rows) if not _finite_float(b))
        raise err(
            f"{what} {ids[k]}: bbox {plain_repr(rows[k])} has coordinates beyond 1e15 "
            "pixels, where areas and IoU lose their precision: rescale the boxes"
        ) from None
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


def _finite_float(b: Any) -> bool:
    """Every value of ``b`` converts to float64 (no integer beyond 1.8e308)."""
    try:
        np.array(b, dtype=np.float64)
    except OverflowError:
        return False
    return True


def keypoints_rows(rows: list[Any], where: list[str], err: type[Exception]) -> np.ndarray:
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
    return readonly(out)


def load_json(path: str | os.PathLike[str], what: str) -> Any:
    """The JSON value of the file ``path`` (``what`` names the file kind expected) under
    the one reading policy of :func:`robopercept.fileio.read_json`:
    :class:`FileFormatError` when it is missing, not UTF-8 JSON, or nested deeper than
    :data:`~robopercept.fileio.MAX_NESTING` levels (never ``RecursionError``)."""
    return read_json(path, what)


def write_json(obj: Any, path: str | os.PathLike[str]) -> Path:
    """Write ``obj`` as JSON (UTF-8) to ``path``, creating folders; returns the path.
    :class:`InputError` when ``path`` is a folder."""
    p = as_path(path)
    if p.is_dir():
        raise InputError(f"{p} is a folder; give a .json file path")
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(obj), encoding="utf-8")
    return p


def category_list(found: list[str], categories: Any, what: str) -> list[str]:
    """The category names of a conversion to COCO: ``categories`` checked to be a list
    of names holding every one of ``found`` (the sorted names the annotations use,
    also the default when ``categories`` is None); ``what`` names an annotation's
    class (``"class"``, ``"label"``) in the message."""
    if categories is None:
        return list(found)
    if not isinstance(categories, (list, tuple)) or not all(isinstance(c, str) for c in categories):
        raise InputError(f"categories must be a list of class names; got {plain_repr(categories)}")
    missing = sorted(set(found) - set(categories))
    if missing:
        raise InputError(
            f"{what} {missing[0]!r} is not in categories {plain_repr(list(categories))}: add it"
        )
    return list(categories)
