r"""Keypoint annotation files: mmpose's MPII JSON (and its MPII-TRB variant) and imgaug's
keypoint JSON (the quokka file). COCO keypoint files are read by
:func:`robopercept.nn.coco.dataset.read_coco_json`.

NumPy only (no torch). Every reader returns frozen records with read-only arrays, the
keypoints as ``(J, 3)`` rows ``x, y, v`` in robopercept's pixel convention (``(x, y)`` =
(column, row), origin at the centre of the top-left pixel, as OpenCV) and COCO's
visibility codes (``v = 0`` not labelled, ``1`` labelled but not visible, ``2`` labelled
and visible); an unlabelled joint is ``(0, 0, 0)``, as in COCO files.

MPII (mmpose's ``mpii`` annotation list)
----------------------------------------
A JSON list of people, ``{"image", "joints": 16 x [x, y], "joints_vis": 16 x 0|1,
"center": [x, y], "scale": s}``, in the order of
:data:`~robopercept.nn.skeleton.MPII_16` (the files of HRNet's
``deep-high-resolution-net.pytorch``, which mmpose reuses). Their coordinates are
MPII's MATLAB ones, **1-based** (an unlabelled joint is ``(-1, -1)``): mmpose 0.x
(``TopDownMpiiDataset``) and HRNet subtract 1 from the joints and the centre; mmpose
1.x subtracts 1 from the centre only and adds 1 to predictions before its PCKh
(``MpiiPCKAccuracy``). Here, as in mmpose 0.x and HRNet, both are shifted:

.. math::  x = x_\mathrm{file} - 1, \qquad y = y_\mathrm{file} - 1 .

``joints_vis`` says whether a joint is labelled (MPII's JSON does not say whether it is
occluded), so a labelled joint gets ``v = 2`` (mmpose treats them all as visible).

The person box is the one mmpose derives (``MpiiDataset``: "mpii bbox scales are
normalized with factor 200"): a square of side :math:`200 s` pixels around the centre
moved down by :math:`15 s` pixels ("to avoid cropping limbs"; not when the file's centre
is ``-1``),

.. math::  c' = (c_x - 1,\; c_y - 1 + 15 s), \qquad
           \mathrm{box} = (c'_x - 100 s,\; c'_y - 100 s,\; 200 s,\; 200 s)

as ``(x, y, w, h)``. (mmpose then pads it by 1.25 in its ``GetBBoxCenterScale`` step;
that padding is the training pipeline's, not the file's, and is not applied here.)

MPII-TRB (mmpose's ``mpii_trb``)
--------------------------------
A COCO-style dict (``images``, ``annotations``, ``categories``) whose annotations hold
40 keypoints ``[x, y, v] * 40`` (14 skeleton joints and 26 contour points, named by the
category's ``keypoints``), ``center`` and ``scale``, and optionally ``headbox``. The
same people as the MPII files carry the same 1-based numbers (the labelled joints equal
the MPII file's), so they are shifted by -1 alike. Their ``scale`` is not MPII's: it
is the zoom from the person to the network's 256-pixel input, and mmpose 0.x
(``TopDownMpiiTrbDataset``) takes the box side as :math:`256 / s` pixels around the
(unmoved) centre, which is what is done here:

.. math::  \mathrm{box} = (c_x - 1 - 128 / s,\; c_y - 1 - 128 / s,\; 256 / s,\; 256 / s).

(mmpose 1.x's ``MpiiTrbDataset`` multiplies by 200 as for MPII, which on mmpose's own
test file gives 35 to 94 pixel boxes around people 300 to 630 pixels tall; on that file
:math:`256/s` is 1.545 times the MPII file's :math:`200 s` for every person.) The
skeleton is :data:`MPII_TRB_40` when the names are mmpose's 40, else one built from the
names (the category's COCO ``skeleton`` links if it has them).

imgaug (the quokka annotation)
------------------------------
imgaug's ``quokka_annotations.json``: ``bounding_boxes`` (``x1, y1, x2, y2, label``),
``keypoints`` (``x, y, label``) and ``polygons`` (``keypoints``: a list of ``{x, y}``).
imgaug draws a point at pixel ``(round(x), round(y))``, the convention here, so
coordinates are kept as written; boxes become ``(x1, y1, x2 - x1, y2 - y1)``.

Left/right pairs (the flips) come from the names: a name with the word ``left`` (split
at ``_``) pairs with the same name with ``right`` in its place (``ear_tip_left`` and
``ear_tip_right``, ``medial_left_bow`` and ``medial_right_bow``), the left one first, as
in :class:`~robopercept.nn.skeleton.Skeleton`'s presets.

Examples
--------
>>> import json, pathlib, tempfile
>>> p = pathlib.Path(tempfile.mkdtemp()) / "mpii.json"
>>> joints = [[float(10 + i), 21.0] for i in range(16)]
>>> _ = p.write_text(json.dumps([{"image": "a.jpg", "joints": joints,
...     "joints_vis": [1] * 15 + [0], "center": [31.0, 41.0], "scale": 0.5}]))
>>> ann = read_mpii_json(p)
>>> person = ann.people[0]
>>> person.keypoints[0].tolist(), person.keypoints[15].tolist(), person.box.tolist()
([9.0, 20.0, 2.0], [0.0, 0.0, 0.0], [-20.0, -2.5, 100.0, 100.0])
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from robopercept._checks import plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import read_json
from robopercept.nn.skeleton import MPII_16, Skeleton

__all__ = [
    "MPII_TRB_40",
    "ImgaugAnnotation",
    "MpiiAnnotations",
    "MpiiPerson",
    "read_imgaug_keypoints",
    "read_mpii_json",
]

#: mmpose's MPII person boxes are ``scale * PIXEL_STD`` pixels ("normalized with factor 200")
PIXEL_STD = 200.0
#: the input side (pixels) that the MPII-TRB ``scale`` zooms a person to (mmpose 0.x)
TRB_INPUT_SIDE = 256.0

_TRB_NAMES = (
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
    "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
    "right_ankle", "head", "neck", "right_neck", "left_neck", "medial_right_shoulder",
    "lateral_right_shoulder", "medial_right_bow", "lateral_right_bow", "medial_right_wrist",
    "lateral_right_wrist", "medial_left_shoulder", "lateral_left_shoulder", "medial_left_bow",
    "lateral_left_bow", "medial_left_wrist", "lateral_left_wrist", "medial_right_hip",
    "lateral_right_hip", "medial_right_knee", "lateral_right_knee", "medial_right_ankle",
    "lateral_right_ankle", "medial_left_hip", "lateral_left_hip", "medial_left_knee",
    "lateral_left_knee", "medial_left_ankle", "lateral_left_ankle",
)  # fmt: skip
# mmpose's configs/_base_/datasets/mpii_trb.py ``skeleton_info``, by name
_TRB_LINKS = (
    ("head", "neck"), ("neck", "left_shoulder"), ("neck", "right_shoulder"),
    ("left_shoulder", "left_elbow"), ("right_shoulder", "right_elbow"),
    ("left_elbow", "left_wrist"), ("right_elbow", "right_wrist"),
    ("left_shoulder", "left_hip"), ("right_shoulder", "right_hip"), ("left_hip", "right_hip"),
    ("left_hip", "left_knee"), ("right_hip", "right_knee"), ("left_knee", "left_ankle"),
    ("right_knee", "right_ankle"), ("right_neck", "left_neck"),
    ("medial_right_shoulder", "lateral_right_shoulder"),
    ("medial_right_bow", "lateral_right_bow"), ("medial_right_wrist", "lateral_right_wrist"),
    ("medial_left_shoulder", "lateral_left_shoulder"), ("medial_left_bow", "lateral_left_bow"),
    ("medial_left_wrist", "lateral_left_wrist"), ("medial_right_hip", "lateral_right_hip"),
    ("medial_right_knee", "lateral_right_knee"), ("medial_right_ankle", "lateral_right_ankle"),
    ("medial_left_hip", "lateral_left_hip"), ("medial_left_knee", "lateral_left_knee"),
    ("medial_left_ankle", "lateral_left_ankle"),
)  # fmt: skip


def _flip_pairs(names: Sequence[str]) -> list[tuple[int, int]]:
    """``(left, right)`` index pairs of names that differ by the word left/right."""
    index = {n: i for i, n in enumerate(names)}
    pairs = []
    for i, name in enumerate(names):
        words = name.split("_")
        if "left" in words and "right" not in words:
            twin = "_".join("right" if w == "left" else w for w in words)
            if twin in index:
                pairs.append((i, index[twin]))
    return pairs


#: MPII-TRB's 40 keypoints (14 joints, 26 contour points) in mmpose's order, the 27 links
#: of mmpose's ``mpii_trb`` config and its 19 left/right pairs (no OKS sigmas: 0.05 each)
MPII_TRB_40 = Skeleton(
    "mpii_trb40",
    _TRB_NAMES,
    [(_TRB_NAMES.index(a), _TRB_NAMES.index(b)) for a, b in _TRB_LINKS],
    _flip_pairs(_TRB_NAMES),
)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    a.setflags(write=False)
    return a


# ----------------------------------------------------------------------------- records


@dataclass(frozen=True, eq=False)
class MpiiPerson:
    """One annotated person of an MPII (or MPII-TRB) file.

    Attributes
    ----------
    image : str
        The image file name.
    keypoints : (J, 3) float64 ndarray, read-only
        ``x, y, v``: 0-based pixels (the file's 1-based numbers minus 1), ``v`` in
        {0, 1, 2}; an unlabelled joint is ``(0, 0, 0)``.
    center : (2,) float64 ndarray, read-only
        The file's ``center`` minus 1 (not moved; the box is).
    scale : float
        The file's ``scale`` as written (MPII: box side / 200; TRB: 256 / box side).
    box : (4,) float64 ndarray, read-only
        mmpose's person box ``(x, y, w, h)`` (see the module notes).
    id : int
        The annotation's ``id`` (TRB), or its index in the list (MPII).
    headbox : (4,) float64 ndarray or None
        ``x1, y1, x2, y2`` of the head (minus 1) where the file gives it (TRB ``headbox``).
    """

    image: str
    keypoints: np.ndarray
    center: np.ndarray
    scale: float
    box: np.ndarray
    id: int
    headbox: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class MpiiAnnotations:
    """The people of an MPII or MPII-TRB file and their skeleton.

    Attributes
    ----------
    people : tuple of MpiiPerson
    skeleton : Skeleton
        :data:`~robopercept.nn.skeleton.MPII_16` or :data:`MPII_TRB_40` (or one made
        from a TRB file's own names).
    layout : str
        ``"mpii"`` or ``"mpii_trb"``.
    """

    people: tuple[MpiiPerson, ...]
    skeleton: Skeleton
    layout: str

    def __len__(self) -> int:
        return len(self.people)

    @property
    def keypoints(self) -> np.ndarray:
        """``(P, J, 3)`` float64: every person's keypoints, stacked."""
        if not self.people:
            return np.zeros((0, self.skeleton.num_joints, 3))
        return np.stack([p.keypoints for p in self.people])

    @property
    def boxes(self) -> np.ndarray:
        """``(P, 4)`` float64: every person's box ``(x, y, w, h)``."""
        return np.array([p.box for p in self.people]).reshape(-1, 4)


@dataclass(frozen=True, eq=False)
class ImgaugAnnotation:
    """An imgaug keypoint annotation (boxes, named keypoints and polygons of one image).

    Attributes
    ----------
    boxes : (N, 4) float64 ndarray, read-only
        ``(x, y, w, h)`` = ``(x1, y1, x2 - x1, y2 - y1)``.
    box_labels : tuple of str
        One per box (``""`` where the file has none).
    names : tuple of str
        The keypoints' labels (``keypoint_<i>`` where the file has none).
    keypoints : (K, 3) float64 ndarray, read-only
        ``x, y, v`` with ``v = 2`` (imgaug has no visibility).
    polygons : tuple of (M, 2) float64 ndarray
        Each polygon's vertices ``(x, y)``, read-only.
    polygon_labels : tuple of str
    skeleton : Skeleton or None
        Named ``"imgaug"``: the keypoint names, no links, left/right pairs from the
        names; None when the file has no keypoints.
    """

    boxes: np.ndarray
    box_labels: tuple[str, ...]
    names: tuple[str, ...]
    keypoints: np.ndarray
    polygons: tuple[np.ndarray, ...]
    polygon_labels: tuple[str, ...]
    skeleton: Skeleton | None


# ----------------------------------------------------------------------------- parsing


def _load_json(path: str | os.PathLike[str], what: str) -> Any:
    """The JSON value of ``path`` under the one reading policy
    (:func:`robopercept.fileio.read_json`: bounded nesting, typed errors)."""
    return read_json(path, what)


def _field(item: Any, key: str, where: str) -> Any:
    if not isinstance(item, Mapping):
        raise FileFormatError(f"{where} must be a JSON object; got {plain_repr(item)[:80]}")
    if key not in item:
        raise FileFormatError(f"{where} has no {key!r} field; got the fields {sorted(item)}")
    return item[key]


def _numbers(value: Any, shape: tuple[int, ...], where: str, what: str) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (-1: any length)."""
    try:
        arr = np.array(value) if isinstance(value, list) else None
    except (ValueError, TypeError, OverflowError):  # ragged lists
        arr = None
    ok = arr is not None and arr.dtype.kind in "iuf" and arr.ndim == len(shape)
    if (
        arr is None
        or not ok
        or any(s not in (-1, n) for s, n in zip(shape, arr.shape, strict=True))
    ):
        raise FileFormatError(f"{where} must be {what}; got {plain_repr(value)[:120]}")
    arr = arr.astype(np.float64)
    if not np.isfinite(arr).all():
        raise FileFormatError(f"{where} must be {what}, all finite; got {plain_repr(value)[:120]}")
    return arr


def _number(value: Any, where: str, what: str = "a finite number") -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise FileFormatError(f"{where} must be {what}; got {plain_repr(value)[:80]}")
    try:
        v = float(value)
    except OverflowError:  # an integer beyond float64
        v = math.inf
    if not math.isfinite(v):
        raise FileFormatError(f"{where} must be {what}; got {plain_repr(value)[:80]}")
    return v


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise FileFormatError(f"{where} must be a non-empty string; got {plain_repr(value)[:80]}")
    return value


def _mpii_entry(entry: Any, k: int, joints_count: int) -> MpiiPerson:
    where = f"entry {k}"
    image = _text(_field(entry, "image", where), f"{where}: image")
    where = f"entry {k} ({image})"
    center = _numbers(_field(entry, "center", where), (2,), f"{where}: center", "[x, y]")
    scale = _number(_field(entry, "scale", where), f"{where}: scale", "a positive number")
    if scale <= 0:
        raise FileFormatError(f"{where}: scale must be a positive number; got {scale}")
    kp = np.zeros((joints_count, 3))
    if "joints" in entry or "joints_vis" in entry:  # (mmpose's test set has neither)
        what = f"{joints_count} [x, y] pairs (MPII's joints, in MPII_16's order)"
        joints = _numbers(_field(entry, "joints", where), (-1, 2), f"{where}: joints", what)
        vis = _numbers(
            _field(entry, "joints_vis", where), (-1,), f"{where}: joints_vis", "a list of 0 or 1"
        )
        if len(joints) != joints_count:
            raise FileFormatError(f"{where}: joints must be {what}; got {len(joints)} pairs")
        if len(vis) != joints_count or not np.isin(vis, (0, 1)).all():
            raise FileFormatError(
                f"{where}: joints_vis must be {joints_count} flags 0 or 1 (one per joint); "
                f"got {plain_repr(vis)}"
            )
        on = vis > 0
        kp[on, :2] = joints[on] - 1.0  # MATLAB's 1-based pixels to 0-based
        kp[on, 2] = 2.0
    c = center - 1.0
    box_c = c.copy()
    if center[0] != -1:  # mmpose: "Adjust center/scale slightly to avoid cropping limbs"
        box_c[1] += 15.0 * scale
    side = PIXEL_STD * scale
    box = _box(box_c, side, f"{where}: center and scale", "200 scale")
    return MpiiPerson(image, _readonly(kp), _readonly(c), scale, _readonly(box), k)


def _box(center: np.ndarray, side: float, where: str, formula: str) -> np.ndarray:
    """The square ``(x, y, w, h)`` of ``side`` around ``center``, which must be finite."""
    with np.errstate(over="ignore", invalid="ignore"):
        box = np.array([center[0] - side / 2, center[1] - side / 2, side, side])
    if not np.isfinite(box).all():
        raise FileFormatError(
            f"{where} give a person box beyond the float range (side {formula} = {side:.3g} pixels)"
        )
    return box


def _key(value: Any, where: str) -> int | str:
    """An image id (an integer or a string)."""
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise FileFormatError(f"{where} must be an integer or a string; got {plain_repr(value)}")
    return value


def _trb_skeleton(category: Any, where: str) -> Skeleton:
    names_raw = _field(category, "keypoints", where)
    if not isinstance(names_raw, list) or not all(isinstance(n, str) for n in names_raw):
        raise FileFormatError(f"{where}: keypoints must be a list of names; got {names_raw!r}")
    names = tuple(names_raw)
    if not names or len(set(names)) != len(names):
        raise FileFormatError(f"{where}: keypoints must be distinct names; got {list(names)}")
    if names == MPII_TRB_40.joints and "skeleton" not in category:
        return MPII_TRB_40
    links = []
    pairs = category.get("skeleton", [])
    if not isinstance(pairs, list):
        raise FileFormatError(f"{where}: skeleton must be a list of [i, j] pairs; got {pairs!r}")
    for i, pair in enumerate(pairs):
        ab = _numbers(pair, (2,), f"{where}: skeleton[{i}]", "a pair of 1-based keypoint indices")
        if not ((ab >= 1) & (ab <= len(names)) & (ab == np.round(ab))).all() or ab[0] == ab[1]:
            raise FileFormatError(
                f"{where}: skeleton[{i}] must join two of the keypoints 1..{len(names)}; got {pair}"
            )
        links.append((int(ab[0]) - 1, int(ab[1]) - 1))
    try:
        return Skeleton(str(category.get("name") or "mpii_trb"), names, links, _flip_pairs(names))
    except InputError as exc:
        raise FileFormatError(f"{where}: not a valid skeleton ({exc})") from None


def _trb(data: Mapping[str, Any]) -> MpiiAnnotations:
    cats = _field(data, "categories", "the file")
    if not isinstance(cats, list) or len(cats) != 1:
        raise FileFormatError(
            f"categories must list the one person category with its keypoint names; got "
            f"{plain_repr(cats)[:120]}"
        )
    skeleton = _trb_skeleton(cats[0], "categories[0]")
    n = skeleton.num_joints
    images = _field(data, "images", "the file")
    annotations = _field(data, "annotations", "the file")
    if not isinstance(images, list) or not isinstance(annotations, list):
        raise FileFormatError("images and annotations must be JSON lists")
    names: dict[int | str, str] = {}
    for i, im in enumerate(images):
        image_id = _key(_field(im, "id", f"images[{i}]"), f"images[{i}].id")
        names[image_id] = _text(_field(im, "file_name", f"images[{i}]"), f"images[{i}].file_name")
    people = []
    for k, ann in enumerate(annotations):
        where = f"annotations[{k}]"
        ann_id = _field(ann, "id", where)
        if isinstance(ann_id, bool) or not isinstance(ann_id, int):
            raise FileFormatError(f"{where}: id must be an integer; got {plain_repr(ann_id)}")
        where = f"annotations[{k}] (id {ann_id})"
        image_id = _key(_field(ann, "image_id", where), f"{where}: image_id")
        if image_id not in names:
            raise FileFormatError(f"{where}: image_id {image_id!r} is not in images")
        flat = _numbers(_field(ann, "keypoints", where), (-1,), f"{where}: keypoints", "numbers")
        if flat.size != 3 * n:
            raise FileFormatError(
                f"{where}: keypoints must be {n} x [x, y, v] = {3 * n} numbers (the category "
                f"names {n} keypoints); got {flat.size}"
            )
        kp = flat.reshape(n, 3)
        if not np.isin(kp[:, 2], (0, 1, 2)).all():
            raise FileFormatError(
                f"{where}: keypoint visibilities must be 0, 1 or 2; got {np.unique(kp[:, 2])}"
            )
        on = kp[:, 2] > 0
        kp[on, :2] -= 1.0  # the same 1-based numbers as the MPII file
        kp[~on] = 0.0
        center = _numbers(_field(ann, "center", where), (2,), f"{where}: center", "[x, y]")
        scale = _number(_field(ann, "scale", where), f"{where}: scale", "a positive number")
        if scale <= 0:
            raise FileFormatError(f"{where}: scale must be a positive number; got {scale}")
        c = center - 1.0
        box = _box(c, TRB_INPUT_SIDE / scale, f"{where}: center and scale", "256 / scale")
        head = None
        if "headbox" in ann:
            head = _readonly(
                _numbers(ann["headbox"], (4,), f"{where}: headbox", "[x1, y1, x2, y2]") - 1.0
            )
        people.append(
            MpiiPerson(
                names[image_id], _readonly(kp), _readonly(c), scale, _readonly(box), ann_id, head
            )
        )
    return MpiiAnnotations(tuple(people), skeleton, "mpii_trb")


def read_mpii_json(path: str | os.PathLike[str]) -> MpiiAnnotations:
    r"""Read mmpose's MPII annotation JSON, or its MPII-TRB variant.

    The MPII list (``image``, ``joints`` 16 x 2, ``joints_vis``, ``center``, ``scale``)
    and the MPII-TRB COCO-style dict (``images``, ``annotations`` with 40 ``[x, y, v]``
    keypoints, ``center`` and ``scale``, ``categories`` with the keypoint names) are
    told apart by their shape. Coordinates are shifted from MPII's 1-based pixels to
    0-based ones (:math:`x - 1`, as mmpose 0.x and HRNet); the box is mmpose's:
    :math:`200 s` pixels square around the centre moved down by :math:`15 s` (MPII),
    :math:`256 / s` pixels square around the centre (MPII-TRB); see the module notes.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    MpiiAnnotations
        ``people`` in file order (TRB: as written, each with its annotation ``id``),
        the ``skeleton`` and the ``layout`` (``"mpii"`` or ``"mpii_trb"``).

    Raises
    ------
    FileFormatError
        Not a file, not JSON, a COCO keypoint file without ``center``/``scale`` (read
        it with :func:`~robopercept.nn.coco.dataset.read_coco_json`), another layout, or an
        entry with a missing or malformed field (named with its entry).

    Examples
    --------
    >>> import json, pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "mpii.json"
    >>> _ = p.write_text(json.dumps([{"image": "a.jpg", "joints": [[1, 1]] * 16,
    ...     "joints_vis": [1] * 16, "center": [11, 11], "scale": 0.1}]))
    >>> ann = read_mpii_json(p)
    >>> ann.layout, ann.skeleton.name, ann.keypoints.shape, ann.boxes.tolist()
    ('mpii', 'mpii16', (1, 16, 3), [[0.0, 1.5, 20.0, 20.0]])
    """
    data = _load_json(path, "an MPII annotation JSON file")
    try:
        if isinstance(data, list):
            n = MPII_16.num_joints
            people = tuple(_mpii_entry(e, k, n) for k, e in enumerate(data))
            return MpiiAnnotations(people, MPII_16, "mpii")
        if isinstance(data, Mapping) and "annotations" in data:
            anns = data["annotations"]
            first = anns[0] if isinstance(anns, list) and anns else {}
            if isinstance(first, Mapping) and ("center" not in first or "scale" not in first):
                raise FileFormatError(
                    "the annotations have no 'center' and 'scale': a COCO keypoint file? "
                    "read it with robopercept.nn.coco.dataset.read_coco_json"
                )
            return _trb(data)
    except FileFormatError as exc:
        raise FileFormatError(f"{path}: {exc}") from None
    raise FileFormatError(
        f"{path}: not an MPII annotation file: expected mmpose's MPII list of "
        "{image, joints, joints_vis, center, scale} entries, or the MPII-TRB dict of "
        f"images, annotations (keypoints, center, scale) and categories; got "
        f"{type(data).__name__} {plain_repr(data)[:80]}"
    )


def _label(item: Mapping[str, Any], where: str, default: str) -> str:
    label = item.get("label")
    if label is None:
        return default
    if not isinstance(label, str):
        raise FileFormatError(f"{where}: label must be a string; got {plain_repr(label)[:80]}")
    return label


def _xy(item: Any, where: str) -> tuple[float, float]:
    return (
        _number(_field(item, "x", where), f"{where}: x"),
        _number(_field(item, "y", where), f"{where}: y"),
    )


def _imgaug(data: Any) -> ImgaugAnnotation:
    keys = ("bounding_boxes", "keypoints", "polygons")
    if not isinstance(data, Mapping) or not any(k in data for k in keys):
        raise FileFormatError(
            "not an imgaug annotation: expected a JSON object with bounding_boxes, keypoints "
            f"and/or polygons; got {type(data).__name__} {plain_repr(data)[:80]}"
        )
    for k in keys:
        if not isinstance(data.get(k, []), list):
            raise FileFormatError(f"{k} must be a JSON list; got {plain_repr(data[k])[:80]}")
    boxes, box_labels = [], []
    for i, b in enumerate(data.get("bounding_boxes", [])):
        where = f"bounding_boxes[{i}]"
        x1, y1, x2, y2 = (
            _number(_field(b, c, where), f"{where}: {c}") for c in ("x1", "y1", "x2", "y2")
        )
        if x2 < x1 or y2 < y1:
            raise FileFormatError(
                f"{where}: needs x1 <= x2 and y1 <= y2; got ({x1}, {y1}, {x2}, {y2})"
            )
        boxes.append((x1, y1, x2 - x1, y2 - y1))
        box_labels.append(_label(b, where, ""))
    names, points = [], []
    for i, kpt in enumerate(data.get("keypoints", [])):
        where = f"keypoints[{i}]"
        points.append((*_xy(kpt, where), 2.0))
        names.append(_label(kpt, where, f"keypoint_{i}"))
    seen: dict[str, int] = {}
    for i, n in enumerate(names):
        if n in seen:
            raise FileFormatError(
                f"keypoints[{i}]: label {n!r} repeats keypoints[{seen[n]}]'s: keypoint "
                "names must be distinct"
            )
        seen[n] = i
    polygons, polygon_labels = [], []
    for i, poly in enumerate(data.get("polygons", [])):
        where = f"polygons[{i}]"
        verts = _field(poly, "keypoints", where)
        if not isinstance(verts, list) or len(verts) < 3:
            raise FileFormatError(
                f"{where}: keypoints must list at least 3 vertices {{x, y}}; got "
                f"{plain_repr(verts)[:80]}"
            )
        xy = np.array([_xy(v, f"{where}.keypoints[{j}]") for j, v in enumerate(verts)])
        polygons.append(_readonly(xy))
        polygon_labels.append(_label(poly, where, ""))
    skeleton = Skeleton("imgaug", names, [], _flip_pairs(names)) if names else None
    return ImgaugAnnotation(
        _readonly(np.array(boxes, dtype=np.float64).reshape(-1, 4)),
        tuple(box_labels),
        tuple(names),
        _readonly(np.array(points, dtype=np.float64).reshape(-1, 3)),
        tuple(polygons),
        tuple(polygon_labels),
        skeleton,
    )


def read_imgaug_keypoints(path: str | os.PathLike[str]) -> ImgaugAnnotation:
    """Read an imgaug keypoint annotation JSON (imgaug's ``quokka_annotations.json``).

    ``bounding_boxes`` (``x1, y1, x2, y2``, optional ``label``) become ``(x, y, w, h)``
    rows, ``keypoints`` (``x, y``, optional ``label``) ``(K, 3)`` rows ``x, y, 2`` with
    their names, ``polygons`` (``keypoints``: at least 3 ``{x, y}``) ``(M, 2)`` arrays.
    Coordinates are kept as written (imgaug draws a point at pixel
    ``(round(x), round(y))``, robopercept's convention). Any of the three lists may be
    absent; other fields are ignored.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    ImgaugAnnotation
        With a :class:`~robopercept.nn.skeleton.Skeleton` named ``"imgaug"`` of the
        keypoint names (no links; left/right pairs from the names), or None without
        keypoints.

    Raises
    ------
    FileFormatError
        Not a file, not JSON, none of the three lists, a box with ``x2 < x1``, a
        coordinate that is missing or not a finite number, a repeated keypoint name, a
        polygon of fewer than 3 vertices (each named with its entry).

    Examples
    --------
    >>> import json, pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "kp.json"
    >>> _ = p.write_text(json.dumps({"bounding_boxes": [
    ...     {"x1": 1, "y1": 2, "x2": 11, "y2": 22, "label": "animal"}], "keypoints": [
    ...     {"x": 3, "y": 4, "label": "eye_left"}, {"x": 8, "y": 4, "label": "eye_right"}]}))
    >>> ann = read_imgaug_keypoints(p)
    >>> ann.boxes.tolist(), ann.keypoints[1].tolist(), ann.skeleton.flip_pairs
    ([[1.0, 2.0, 10.0, 20.0]], [8.0, 4.0, 2.0], ((0, 1),))
    """
    data = _load_json(path, "an imgaug annotation JSON file")
    try:
        return _imgaug(data)
    except FileFormatError as exc:
        raise FileFormatError(f"{path}: {exc}") from None
