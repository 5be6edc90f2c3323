r"""A user's own annotated images in the forms annotation tools write, read as one
:class:`~robopercept.nn.coco.dataset.CocoDataset` (NumPy only, no torch).

:func:`read_annotations` takes any of the four and says which it found
(:class:`AnnotatedImages`):

- ``"coco"``: a COCO instances JSON file
  (:func:`~robopercept.nn.coco.dataset.read_coco_json`), its images beside it;
- ``"labelme"``: a folder of labelme JSON files, one per image
  (:func:`read_labelme_json`, :func:`labelme_to_coco`);
- ``"voc-xml"``: a folder of Pascal-VOC annotation XML files (boxes), flat or in the
  devkit's ``Annotations/`` + ``JPEGImages/`` layout
  (:func:`~robopercept.nn.coco.voc.read_voc_xml`,
  :func:`~robopercept.nn.coco.voc.voc_to_coco`);
- ``"voc-masks"``: a Pascal-VOC segmentation folder, ``SegmentationObject/`` (instance
  ids) + ``SegmentationClass/`` (class indices) + ``JPEGImages/``
  (:func:`read_voc_segmentation`).

labelme (wkentaro/labelme, ``examples/instance_segmentation/labelme2coco.py``): each
shape is a polygon (``rectangle`` and ``circle`` shapes become polygons); shapes that
share a label and a ``group_id`` are one instance, whose segmentation is the list of
their polygons and whose box and area are those of the union of their masks
(:func:`~robopercept.nn.coco.rle.annotation_to_rle`,
:func:`~robopercept.nn.coco.rle.rle_to_bbox`); a shape without ``group_id`` is an
instance alone. Labels that start with ``_`` (labelme's ``__ignore__`` and
``_background_``) are not classes: their shapes are dropped, as labelme2coco drops them.

Pascal-VOC segmentation (VOC devkit, ``VOCdevkit/VOC2012``): in ``SegmentationObject``
each value ``k`` in 1..254 is instance ``k``, 0 the background and 255 the "void" border
that no instance owns; the instance's class is the most frequent ``SegmentationClass``
value over its pixels (0 and 255 excluded), named by ``class_names.txt`` (one name per
line, line ``c`` naming class ``c``; labelme's VOC export writes it) or, without that
file, by the 21 VOC names (:data:`VOC_CLASSES`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_bool, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import read_text
from robopercept.imaging.io import IMAGE_EXTENSIONS, contained_path, read_image
from robopercept.nn.coco._fields import category_list, load_json, readonly
from robopercept.nn.coco.dataset import CocoCategory, CocoDataset, CocoImage, read_coco_json
from robopercept.nn.coco.rle import annotation_to_rle, rle_area, rle_encode, rle_to_bbox
from robopercept.nn.coco.voc import read_voc_xml, voc_to_coco

__all__ = [
    "ANNOTATION_FORMS",
    "VOC_CLASSES",
    "AnnotatedImages",
    "LabelmeAnnotation",
    "LabelmeShape",
    "labelme_to_coco",
    "read_annotations",
    "read_labelme_json",
    "read_voc_segmentation",
]

#: what :func:`read_annotations` recognises
ANNOTATION_FORMS = ("coco", "labelme", "voc-xml", "voc-masks")
#: the Pascal VOC class names, index = class value in ``SegmentationClass``
VOC_CLASSES = (
    "background",
    "aeroplane",
    "bicycle",
    "bird",
    "boat",
    "bottle",
    "bus",
    "car",
    "cat",
    "chair",
    "cow",
    "diningtable",
    "dog",
    "horse",
    "motorbike",
    "person",
    "pottedplant",
    "sheep",
    "sofa",
    "train",
    "tvmonitor",
)
#: the shape types of a labelme file that are objects (points and lines are not)
_AREA_SHAPES = ("polygon", "rectangle", "circle")
#: vertices of the polygon a labelme circle becomes
_CIRCLE_VERTICES = 32


@dataclass(frozen=True, eq=False)
class LabelmeShape:
    """One shape of a labelme file: ``label``, ``points`` (P, 2) float ``x, y`` pixels,
    ``group_id`` (None or an int joining the parts of one instance) and
    ``shape_type``."""

    label: str
    points: np.ndarray
    group_id: int | None
    shape_type: str


@dataclass(frozen=True)
class LabelmeAnnotation:
    """One labelme JSON file: ``image_path`` (relative to the file's folder, as labelme
    writes ``imagePath``), ``width``, ``height`` and its ``shapes``."""

    image_path: str
    width: int
    height: int
    shapes: tuple[LabelmeShape, ...]


@dataclass(frozen=True)
class AnnotatedImages:
    """What :func:`read_annotations` found: the annotations as ``coco`` (image file
    names relative to ``root``), the images' folder ``root`` and the ``form`` (one of
    :data:`ANNOTATION_FORMS`)."""

    coco: CocoDataset
    root: Path
    form: str


def read_labelme_json(path: str | os.PathLike[str]) -> LabelmeAnnotation:
    """Read one labelme annotation file.

    Parameters
    ----------
    path : path
        A ``.json`` file written by labelme (``shapes``, ``imagePath``, ``imageHeight``,
        ``imageWidth``).

    Returns
    -------
    LabelmeAnnotation

    Raises
    ------
    FileFormatError
        Not JSON, not a labelme file (a missing field names it), a shape without a
        label or with points that are not ``[[x, y], ...]`` numbers.

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.json"
    >>> _ = p.write_text(json.dumps({"imagePath": "a.jpg", "imageHeight": 8,
    ...     "imageWidth": 10, "shapes": [{"label": "cat", "group_id": None,
    ...     "shape_type": "rectangle", "points": [[1, 2], [5, 6]]}]}))
    >>> a = read_labelme_json(p)
    >>> a.image_path, a.shapes[0].label, a.shapes[0].points.tolist()
    ('a.jpg', 'cat', [[1.0, 2.0], [5.0, 6.0]])
    """
    return _labelme(load_json(path, "a labelme JSON file"), str(path))


def _labelme(data: Any, where: str) -> LabelmeAnnotation:
    """:func:`read_labelme_json` of the JSON value ``data`` read from ``where``."""
    if not isinstance(data, dict) or "shapes" not in data:
        raise FileFormatError(f"{where}: not a labelme file (no 'shapes')")
    for key in ("imagePath", "imageHeight", "imageWidth"):
        if key not in data:
            raise FileFormatError(f"{where}: a labelme file needs '{key}'")
    image_path = data["imagePath"]
    h, w = data["imageHeight"], data["imageWidth"]
    if not isinstance(image_path, str) or not image_path:
        raise FileFormatError(f"{where}: 'imagePath' must name the image file")
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (h, w)):
        raise FileFormatError(
            f"{where}: 'imageHeight' and 'imageWidth' must be positive integers; got "
            f"{plain_repr(h)}, {plain_repr(w)}"
        )
    if not isinstance(data["shapes"], list):
        raise FileFormatError(f"{where}: 'shapes' must be a list")
    shapes = []
    for k, s in enumerate(data["shapes"]):
        sw = f"{where} shape {k}"
        if not isinstance(s, dict) or not isinstance(s.get("label"), str):
            raise FileFormatError(f"{sw}: needs a 'label' string")
        try:
            pts = np.asarray(s.get("points"), dtype=np.float64)
        except (TypeError, ValueError):
            pts = np.zeros((0, 3))
        if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
            raise FileFormatError(
                f"{sw} ({s['label']}): 'points' must be [[x, y], ...] numbers; got "
                f"{plain_repr(s.get('points'))}"
            )
        gid = s.get("group_id")
        if gid is not None and (isinstance(gid, bool) or not isinstance(gid, int)):
            raise FileFormatError(f"{sw} ({s['label']}): 'group_id' must be null or an integer")
        kind = s.get("shape_type") or "polygon"
        if not isinstance(kind, str):
            raise FileFormatError(f"{sw} ({s['label']}): 'shape_type' must be a string")
        shapes.append(LabelmeShape(s["label"], readonly(pts), gid, kind))
    return LabelmeAnnotation(image_path, w, h, tuple(shapes))


def _shape_polygon(shape: LabelmeShape, where: str) -> list[float]:
    """A labelme shape as one flat COCO polygon ``[x0, y0, x1, y1, ...]``."""
    p = shape.points
    if shape.shape_type == "rectangle":
        if len(p) != 2:
            raise FileFormatError(f"{where}: a rectangle has 2 points; got {len(p)}")
        (x0, y0), (x1, y1) = p.min(0), p.max(0)
        p = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    elif shape.shape_type == "circle":
        if len(p) != 2:
            raise FileFormatError(f"{where}: a circle has 2 points (centre, rim); got {len(p)}")
        r = float(np.hypot(*(p[1] - p[0])))
        t = np.linspace(0, 2 * math.pi, _CIRCLE_VERTICES, endpoint=False)
        p = p[0] + r * np.stack((np.cos(t), np.sin(t)), 1)
    elif len(p) < 3:
        raise FileFormatError(f"{where}: a polygon needs 3 points or more; got {len(p)}")
    return [float(v) for v in p.reshape(-1)]


def labelme_to_coco(
    annotations: Sequence[LabelmeAnnotation],
    categories: Sequence[str] | None = None,
    *,
    where: Sequence[str] | None = None,
) -> CocoDataset:
    """labelme annotations as one :class:`CocoDataset` of polygon instances (module
    docstring: grouping, dropped ``_`` labels).

    Images get ids 1, 2, ... in the order given and ``file_name`` = their
    ``image_path``; categories ids 1, 2, ... in the order of ``categories`` (default:
    the sorted labels found); instances ids 1, 2, ... in the order of their first shape.

    Parameters
    ----------
    annotations : sequence of LabelmeAnnotation
    categories : sequence of str, optional
    where : sequence of str, optional
        A name per annotation for the messages (its file).

    Returns
    -------
    CocoDataset
        With ``segmentations`` (a list of polygons per instance).

    Raises
    ------
    InputError
        Not LabelmeAnnotation items, or a label not in ``categories``.
    FileFormatError
        A shape that is not an area (points, lines) or has too few points.

    Examples
    --------
    >>> sq = np.array([[0.0, 0], [4, 0], [4, 4], [0, 4]])
    >>> a = LabelmeAnnotation("a.jpg", 10, 10, (
    ...     LabelmeShape("cat", sq, 1, "polygon"), LabelmeShape("cat", sq + 5, 1, "polygon"),
    ...     LabelmeShape("dog", sq, None, "polygon"),
    ...     LabelmeShape("__ignore__", sq, None, "polygon")))
    >>> ds = labelme_to_coco([a])
    >>> ds.category_names(), ds.category_ids.tolist(), ds.boxes.tolist()
    ({1: 'cat', 2: 'dog'}, [1, 2], [[0.0, 0.0, 9.0, 9.0], [0.0, 0.0, 4.0, 4.0]])
    """
    if not isinstance(annotations, (list, tuple)) or not all(
        isinstance(a, LabelmeAnnotation) for a in annotations
    ):
        raise InputError(
            "annotations must be a list of LabelmeAnnotation (from read_labelme_json); got "
            f"{plain_repr(annotations)}"
        )
    names = where if where is not None else [f"annotation {i}" for i in range(len(annotations))]
    labels = sorted({s.label for a in annotations for s in a.shapes if not s.label.startswith("_")})
    if isinstance(categories, (list, tuple)):
        categories = [c for c in categories if not (isinstance(c, str) and c.startswith("_"))]
    cats = category_list(labels, categories, "label")
    cat_id = {c: k + 1 for k, c in enumerate(cats)}
    rows: list[tuple[int, int, list[list[float]]]] = []
    for i, a in enumerate(annotations):
        groups: dict[Any, list[list[float]]] = {}
        for k, s in enumerate(a.shapes):
            if s.label.startswith("_"):
                continue
            sw = f"{names[i]} shape {k} ({s.label})"
            if s.shape_type not in _AREA_SHAPES:
                raise FileFormatError(
                    f"{sw}: a {s.shape_type!r} shape is not an object's area; an instance is "
                    f"a {', '.join(_AREA_SHAPES)}: remove it or redraw it"
                )
            key = (s.label, s.group_id) if s.group_id is not None else ("", k)
            if key not in groups:
                groups[key] = []
                rows.append((i + 1, cat_id[s.label], groups[key]))
            groups[key].append(_shape_polygon(s, sw))
    masks = [
        annotation_to_rle(polys, annotations[img - 1].height, annotations[img - 1].width)
        for img, _, polys in rows
    ]
    images = [CocoImage(i + 1, a.image_path, a.width, a.height) for i, a in enumerate(annotations)]
    return _instances(images, [CocoCategory(k + 1, c) for k, c in enumerate(cats)], rows, masks)


def _instances(
    images: list[CocoImage],
    categories: list[CocoCategory],
    rows: list[tuple[int, int, Any]],
    masks: list[dict[str, Any]],
) -> CocoDataset:
    """The record of instances ``rows`` = (image id, category id, segmentation), ids 1,
    2, ..., each box and area those of its mask's RLE in ``masks``."""
    n = len(rows)
    boxes = np.array([rle_to_bbox(m) for m in masks], dtype=np.float64).reshape(n, 4)
    return CocoDataset(
        tuple(images),
        tuple(categories),
        readonly(np.arange(1, n + 1, dtype=np.int64)),
        readonly(np.array([r[0] for r in rows], dtype=np.int64)),
        readonly(np.array([r[1] for r in rows], dtype=np.int64)),
        readonly(boxes),
        readonly(np.array([float(rle_area(m)) for m in masks], dtype=np.float64)),
        readonly(np.zeros(n, dtype=bool)),
        segmentations=tuple(r[2] for r in rows),
    )


def _class_names(folder: Path) -> tuple[str, ...]:
    """``class_names.txt`` of a VOC segmentation folder, else :data:`VOC_CLASSES`."""
    f = folder / "class_names.txt"
    if not f.is_file():
        return VOC_CLASSES
    text = read_text(f, "save it as UTF-8, one class name per line")
    names = tuple(line.strip() for line in text.splitlines())
    return tuple(n for n in names if n) or VOC_CLASSES


def _image_beside(folder: Path, stem: str, hint: str = "") -> Path | None:
    """The image file named ``hint`` in ``folder``, else the one with ``stem`` and an
    image extension (a VOC XML may name a ``.tif`` beside a ``.png``). ``hint`` has
    passed :func:`~robopercept.imaging.io.contained_path` (or outside paths are
    allowed)."""
    if hint and (folder / hint).is_file():
        return folder / hint
    for ext in IMAGE_EXTENSIONS:
        for e in (ext, ext.upper()):
            if (folder / f"{stem}{e}").is_file():
                return folder / f"{stem}{e}"
    return None


def _label_png(path: Path) -> np.ndarray:
    """A label PNG's values (H, W): a palette PNG's indices (VOC's), or a grey PNG's
    values."""
    try:
        return read_image(path, mode="index")
    except FileFormatError:  # not a palette PNG: its grey values are the labels
        a = read_image(path)
    if a.ndim != 2 or a.dtype.kind not in "ui":
        raise FileFormatError(
            f"{path}: a label PNG is a palette or grey image of integer labels; got shape "
            f"{a.shape}, {a.dtype}"
        )
    return a


def read_voc_segmentation(folder: str | os.PathLike[str]) -> CocoDataset:
    """A Pascal-VOC segmentation folder's instances (module docstring) as a
    :class:`CocoDataset` with one RLE mask per instance.

    Parameters
    ----------
    folder : path
        Holds ``SegmentationObject/*.png`` (palette PNGs of instance ids),
        ``SegmentationClass/*.png`` (class indices) of the same stems (palette PNGs as
        VOC writes them, or grey PNGs of the values), and
        ``JPEGImages/`` with an image of each stem.

    Returns
    -------
    CocoDataset
        ``file_name`` = ``JPEGImages/<image>`` relative to ``folder``; categories the
        class names but the background (ids = class values); each instance's box and area
        from its mask.

    Raises
    ------
    InputError
        A missing sub-folder, a class PNG or image missing for an instance PNG, a class
        value without a name.
    FileFormatError
        An unreadable PNG, or the two PNGs of a stem of different sizes.
    """
    root = as_path(folder, "folder (--data)")
    obj_dir, cls_dir, img_dir = (
        root / d for d in ("SegmentationObject", "SegmentationClass", "JPEGImages")
    )
    for d in (obj_dir, cls_dir, img_dir):
        if not d.is_dir():
            raise InputError(f"--data {root}: a VOC segmentation folder needs {d.name}/")
    names = _class_names(root)
    pngs = sorted(obj_dir.glob("*.png"))
    if not pngs:
        raise InputError(f"--data {root}: no .png in {obj_dir}")
    images, rows = [], []
    for i, f in enumerate(pngs):
        cf = cls_dir / f.name
        img = _image_beside(img_dir, f.stem)
        if not cf.is_file() or img is None:
            missing = cf if not cf.is_file() else img_dir / f"{f.stem}.jpg"
            raise InputError(f"--data {root}: {missing} is missing (it goes with {f})")
        obj, cls = _label_png(f), _label_png(cf)
        if obj.shape != cls.shape:
            raise FileFormatError(f"{f} and {cf} differ in size: {obj.shape} vs {cls.shape}")
        h, w = obj.shape
        images.append(CocoImage(i + 1, f"JPEGImages/{img.name}", w, h))
        for k in np.unique(obj):
            if k == 0 or k == 255:
                continue
            m = obj == k
            c = cls[m]
            c = c[(c != 0) & (c != 255)]
            if not c.size:
                continue  # an instance id without a class: nothing to learn
            value = int(np.bincount(c).argmax())
            if value >= len(names):
                raise InputError(
                    f"{cf}: class value {value} has no name ({len(names)} in "
                    f"{root / 'class_names.txt'} or VOC's list): add it"
                )
            rle = rle_encode(m)
            assert isinstance(rle, dict)  # one (H, W) mask gives one RLE
            rows.append((i + 1, value, rle))
    cats = [CocoCategory(c, names[c]) for c in range(1, len(names))]
    return _instances(images, cats, rows, [r[2] for r in rows])


def _relative(img: Path, root: Path) -> str:
    """``img`` relative to ``root`` (``..`` included) when it starts with ``root``, else
    as it is (an absolute path, taken only with outside paths allowed)."""
    try:
        return img.relative_to(root).as_posix()
    except ValueError:
        return img.as_posix()


def _voc_xml_folder(root: Path, xmls: list[Path], allow_outside: bool) -> AnnotatedImages:
    """VOC XML files of ``root`` (or ``root/Annotations``) with their images."""
    anns = [read_voc_xml(x) for x in xmls]
    img_dir = root / "JPEGImages" if (root / "JPEGImages").is_dir() else xmls[0].parent
    found = []
    for x, a in zip(xmls, anns, strict=True):
        if a.filename:  # relative to the images' folder, which lies in root
            name = img_dir.relative_to(root) / a.filename
            contained_path(root, name, f"{x}: <filename>", allow_outside)
        img = _image_beside(img_dir, x.stem, a.filename)
        if img is None:
            raise InputError(
                f"--data {root}: no image for {x} ({a.filename!r} or {x.stem}.<image "
                f"extension> in {img_dir})"
            )
        found.append(_relative(img, root))
    coco = voc_to_coco(anns)
    images = tuple(replace(im, file_name=f) for im, f in zip(coco.images, found, strict=True))
    return AnnotatedImages(replace(coco, images=images), root, "voc-xml")


def _labelme_folder(
    root: Path, files: list[Path], docs: list[Any], allow_outside: bool
) -> AnnotatedImages:
    """The labelme files ``files`` of ``root`` (their JSON values ``docs``)."""
    anns = [_labelme(d, str(f)) for f, d in zip(files, docs, strict=True)]
    found = []
    for f, a in zip(files, anns, strict=True):
        name = f.parent.relative_to(root) / a.image_path  # imagePath: beside the file
        contained_path(root, name, f"{f}: imagePath", allow_outside)
        img = _image_beside(f.parent, f.stem, a.image_path)
        if img is None:
            raise InputError(f"--data {root}: no image for {f} ({a.image_path!r} beside it)")
        found.append(_relative(img, root))
    anns = [replace(a, image_path=p) for a, p in zip(anns, found, strict=True)]
    return AnnotatedImages(labelme_to_coco(anns, where=[str(f) for f in files]), root, "labelme")


def read_annotations(
    path: str | os.PathLike[str], *, allow_outside: bool = False
) -> AnnotatedImages:
    """A user's annotated images in any of :data:`ANNOTATION_FORMS` (module docstring),
    recognised by what ``path`` holds, in this order:

    1. a ``.json`` file: COCO (images beside it, ``file_name`` relative to its folder);
    2. a folder with ``SegmentationObject/``: VOC segmentation masks;
    3. a folder with ``.json`` files that have ``shapes``: labelme;
    4. a folder with ``.xml`` files, or ``Annotations/*.xml``: VOC XML boxes.

    A labelme ``imagePath`` or a VOC ``<filename>`` that leads outside the folder
    (``../../x.png``, an absolute path) is refused unless ``allow_outside``
    (:func:`~robopercept.imaging.io.contained_path`); a COCO file's ``file_name`` is
    checked where the images are read
    (:meth:`~robopercept.nn.detection.data.DetectionDataset.from_coco`).

    Parameters
    ----------
    path : path
        What ``--data`` names.
    allow_outside : bool, default False
        Take image paths outside the folder (``--allow-outside-paths``).

    Returns
    -------
    AnnotatedImages

    Raises
    ------
    InputError
        ``path`` does not exist, or is a folder in none of the forms (the message lists
        them), or an image is missing.
    FileFormatError
        A file of the form that cannot be read, or an image path outside the folder.

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> from robopercept.imaging import write_image
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_image(d / "a.png", np.zeros((8, 10, 3), np.uint8))
    >>> _ = (d / "a.json").write_text(json.dumps({"imagePath": "a.png", "imageHeight": 8,
    ...     "imageWidth": 10, "shapes": [{"label": "cat", "group_id": None,
    ...     "shape_type": "rectangle", "points": [[1, 2], [5, 6]]}]}))
    >>> found = read_annotations(d)
    >>> found.form, found.coco.boxes.tolist(), found.coco.images[0].file_name
    ('labelme', [[1.0, 2.0, 4.0, 4.0]], 'a.png')
    """
    p = as_path(path, "path (--data)")
    allow_outside = check_bool(allow_outside, "allow_outside (--allow-outside-paths)")
    if p.is_file():
        if p.suffix.lower() != ".json":
            raise InputError(f"--data: {p} is a file but not a COCO .json file")
        return AnnotatedImages(read_coco_json(p), p.parent, "coco")
    if not p.is_dir():
        raise InputError(f"--data: {p} does not exist")
    if (p / "SegmentationObject").is_dir():
        return AnnotatedImages(read_voc_segmentation(p), p, "voc-masks")
    jsons = sorted(f for f in p.glob("*.json") if f.is_file())
    labelme, docs, bad = [], [], []
    for f in jsons:
        try:
            doc = load_json(f, "a labelme JSON file")
        except FileFormatError as exc:
            bad.append(exc)
            continue
        if isinstance(doc, dict) and "shapes" in doc:
            labelme.append(f)
            docs.append(doc)
    if labelme and bad:  # a broken file among labelme files is not skipped unsaid
        raise bad[0]
    if labelme:
        return _labelme_folder(p, labelme, docs, allow_outside)
    xmls = sorted(f for f in p.glob("*.xml") if f.is_file())
    if not xmls and (p / "Annotations").is_dir():
        xmls = sorted(f for f in (p / "Annotations").glob("*.xml") if f.is_file())
    if xmls:
        return _voc_xml_folder(p, xmls, allow_outside)
    raise InputError(
        f"--data: {p} holds no annotations: give a COCO .json file, or a folder of labelme "
        ".json files, of Pascal-VOC .xml files (or Annotations/*.xml), or a VOC "
        "segmentation folder (SegmentationObject/, SegmentationClass/, JPEGImages/)"
    )
