r"""The detection record: :class:`DetectionDataset` (images with boxes, labels and
optional masks and keypoints), its checks, and the batching of its items.

Every detection set of robopercept is a :class:`DetectionDataset`, which a torch
training loop indexes like torchvision's detection data sets: item ``i`` is
``(image, target)`` with ``image`` a float32 tensor ``(3, H, W)`` in [0, 1] and
``target`` a dict

- ``"boxes"``: ``(K, 4)`` float32, ``xyxy`` in pixels;
- ``"labels"``: ``(K,)`` int64, 1-based (0 is the background of the R-CNN family);
- ``"masks"``: ``(K, H, W)`` uint8, where the set knows them (procedural and digits);
- ``"image_id"`` (int), ``"area"`` ((K,) float32: the mask's pixel count where masks
  are known, else ``w h``) and ``"iscrowd"`` ((K,) int64, all 0), as torchvision's COCO
  wrapper gives.

:func:`collate_detection` batches items as lists (images of different sizes stay
apart), :meth:`DetectionDataset.to_coco` gives the :class:`~robopercept.nn.coco.dataset.CocoDataset`
that :func:`~robopercept.nn.coco.evaluate.evaluate_detections` scores,
:meth:`DetectionDataset.from_coco` the set of a COCO file and its images, and
:meth:`DetectionDataset.split` a seeded train/validation/test split.
:func:`samples_picture` draws a grid of a set's images with their ground truth
(:mod:`robopercept.viz.detection` draws).

Box convention
--------------
Boxes are continuous ``xyxy`` with pixel ``(col, row)`` covering
``[col, col + 1) x [row, row + 1)`` (the torchvision and COCO convention, the one of
:mod:`robopercept.nn.ops.boxes`), so the tight box of a mask is

.. math::

    (x_1, y_1, x_2, y_2) = (\min c,\ \min r,\ \max c + 1,\ \max r + 1)

over its pixels ``(c, r)``: its width is the number of columns it spans and it equals
``pycocotools.mask.toBbox`` of the mask (converted to ``xyxy``); :func:`mask_to_box`
computes it.

The sets themselves live beside this module: the procedural shapes and the digits in
:mod:`robopercept.nn.detection.synthetic`, the DeepForest tree crowns in
:mod:`robopercept.nn.detection.deepforest`; the augmentations in
:mod:`robopercept.nn.detection.augment`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from robopercept._checks import as_path, check_bool, check_int, check_numeric, plain_repr
from robopercept.errors import InputError
from robopercept.imaging import read_image
from robopercept.imaging.io import contained_path
from robopercept.nn.coco.dataset import CocoDataset, coco_from_dict, read_coco_json
from robopercept.nn.coco.folders import read_annotations
from robopercept.nn.coco.rle import annotation_to_rle, rle_decode, rle_encode
from robopercept.nn.data.datasets import stratified_split, to_unit_float
from robopercept.viz.detection import detections_grid

__all__ = [
    "DetectionDataset",
    "check_classes",
    "collate_detection",
    "mask_to_box",
    "samples_picture",
]


# --------------------------------------------------------------------------- the record


def mask_to_box(mask: npt.ArrayLike) -> np.ndarray:
    """The tight ``xyxy`` box of a mask: ``(min c, min r, max c + 1, max r + 1)``.

    Pixel ``(c, r)`` covers ``[c, c + 1) x [r, r + 1)``, so the box's width is the number
    of columns the mask spans (as ``pycocotools.mask.toBbox``, in ``xyxy``).

    Parameters
    ----------
    mask : (H, W) bool array_like
        Non-empty.

    Returns
    -------
    (4,) float64 ndarray

    Raises
    ------
    InputError
        Not 2-D, not bool/numeric, or empty (no pixel set).

    Examples
    --------
    >>> m = np.zeros((5, 6), bool); m[1:3, 2:5] = True
    >>> mask_to_box(m).tolist()
    [2.0, 1.0, 5.0, 3.0]
    """
    m = check_numeric(mask, "mask")
    if m.ndim != 2:
        raise InputError(f"mask must be (H, W); got shape {m.shape}")
    m = m != 0
    if not m.any():
        raise InputError("mask is empty (no pixel set): an empty mask has no box; drop it")
    return _tight_box(m)


def _tight_box(m: np.ndarray) -> np.ndarray:
    cols = np.flatnonzero(m.any(0))
    rows = np.flatnonzero(m.any(1))
    return np.array([cols[0], rows[0], cols[-1] + 1, rows[-1] + 1], dtype=np.float64)


def check_classes(classes: Any) -> tuple[str, ...]:
    """Check a list of class names: non-empty, distinct, non-empty strings.

    Label ``k`` of a detection set is ``classes[k - 1]``; the synthetic sets check their
    ``classes`` argument with this before building a :class:`DetectionDataset`.

    Parameters
    ----------
    classes : list or tuple of str

    Returns
    -------
    tuple of str

    Raises
    ------
    InputError
        Not a non-empty list or tuple, an empty or non-string name, or a repeated name.

    Examples
    --------
    >>> check_classes(["cat", "dog"])
    ('cat', 'dog')
    """
    if not isinstance(classes, (list, tuple)) or not classes:
        raise InputError(
            f"classes must be a non-empty list of class names; got {plain_repr(classes)}"
        )
    if not all(isinstance(c, str) and c for c in classes):
        raise InputError(f"classes must be non-empty strings; got {plain_repr(classes)}")
    if len(set(classes)) != len(classes):
        raise InputError(f"classes must be distinct; got {plain_repr(classes)}")
    return tuple(classes)


def _check_list(value: Any, name: str, n: int | None) -> list[Any]:
    if not isinstance(value, (list, tuple)):
        raise InputError(
            f"{name} must be a list with one entry per image; got {type(value).__name__}"
        )
    if n is not None and len(value) != n:
        raise InputError(f"{name} must have one entry per image ({n}); got {len(value)}")
    return list(value)


class DetectionDataset:
    """Images with boxes, labels and (optionally) masks, indexed like torchvision's
    detection data sets.

    Parameters
    ----------
    images : list of (H, W, 3) float ndarray
        RGB in [0, 1] (sizes may differ between images); stored as float32.
    boxes : list of (K_i, 4) array_like
        ``xyxy`` in pixels (see the module's box convention), inside the image,
        ``x1 <= x2`` and ``y1 <= y2``.
    labels : list of (K_i,) int array_like
        1-based: label ``k`` is ``classes[k - 1]``.
    classes : sequence of str
        The class names.
    masks : list of (K_i, H, W) bool array_like, optional
        Instance masks (the visible pixels of each object).
    image_ids : sequence of int, optional
        Distinct ids (default ``1, 2, ...``).
    file_names : sequence of str, optional
        Names for :meth:`to_coco` (default ``"{id:06d}.png"``).
    meta : sequence of dict, optional
        Free per-image information (the generators record their sources there).
    keypoints : list of (K_i, J, 3) array_like, optional
        Per object, ``J`` keypoints ``(x, y, v)`` in pixels with COCO's visibility
        (0 unlabelled, 1 hidden, 2 seen): the targets of a keypoint detector
        (:class:`~robopercept.nn.detection.keypoint_rcnn.KeypointRCNN`), ``target["keypoints"]``.

    Examples
    --------
    >>> ds = DetectionDataset([np.zeros((4, 6, 3), np.float32)], [[[1, 1, 3, 4]]], [[1]],
    ...                       ["thing"])
    >>> image, target = ds[0]
    >>> tuple(image.shape), target["boxes"].tolist(), target["labels"].tolist()
    ((3, 4, 6), [[1.0, 1.0, 3.0, 4.0]], [1])
    """

    def __init__(
        self,
        images: Sequence[np.ndarray],
        boxes: Sequence[npt.ArrayLike],
        labels: Sequence[npt.ArrayLike],
        classes: Sequence[str],
        *,
        masks: Sequence[npt.ArrayLike] | None = None,
        image_ids: Sequence[int] | None = None,
        file_names: Sequence[str] | None = None,
        meta: Sequence[Mapping[str, Any]] | None = None,
        keypoints: Sequence[npt.ArrayLike] | None = None,
    ) -> None:
        self.classes = check_classes(classes)
        imgs = _check_list(images, "images", None)
        n = len(imgs)
        box_list = _check_list(boxes, "boxes", n)
        lab_list = _check_list(labels, "labels", n)
        self.images: tuple[np.ndarray, ...] = tuple(
            _check_image(im, f"images[{i}]") for i, im in enumerate(imgs)
        )
        self.boxes: tuple[np.ndarray, ...] = tuple(
            _check_boxes(b, f"boxes[{i}]", self.images[i].shape[:2]) for i, b in enumerate(box_list)
        )
        self.labels: tuple[np.ndarray, ...] = tuple(
            _check_labels(y, f"labels[{i}]", len(self.boxes[i]), len(self.classes))
            for i, y in enumerate(lab_list)
        )
        self.masks: tuple[np.ndarray, ...] | None = None
        if masks is not None:
            self.masks = tuple(
                _check_masks(m, f"masks[{i}]", len(self.boxes[i]), self.images[i].shape[:2])
                for i, m in enumerate(_check_list(masks, "masks", n))
            )
        self.keypoints: tuple[np.ndarray, ...] | None = None
        if keypoints is not None:
            self.keypoints = tuple(
                _check_keypoints(k, f"keypoints[{i}]", len(self.boxes[i]))
                for i, k in enumerate(_check_list(keypoints, "keypoints", n))
            )
            if len({k.shape[1] for k in self.keypoints if len(k)}) > 1:
                raise InputError("keypoints must have the same number of joints in every image")
        if image_ids is None:
            ids = list(range(1, n + 1))
        else:
            ids = [check_int(v, "image_ids", 0) for v in _check_list(image_ids, "image_ids", n)]
            if len(set(ids)) != n:
                raise InputError("image_ids must be distinct: give each image its own id")
        self.image_ids: tuple[int, ...] = tuple(ids)
        if file_names is None:
            self.file_names: tuple[str, ...] = tuple(f"{i:06d}.png" for i in ids)
        else:
            names = _check_list(file_names, "file_names", n)
            if not all(isinstance(s, str) for s in names):
                raise InputError("file_names must be strings, one per image")
            self.file_names = tuple(names)
        if meta is None:
            self.meta: tuple[dict[str, Any], ...] = tuple({} for _ in range(n))
        else:
            metas = _check_list(meta, "meta", n)
            if not all(isinstance(m, Mapping) for m in metas):
                raise InputError("meta must be dicts, one per image")
            self.meta = tuple(dict(m) for m in metas)

    @classmethod
    def from_instance_labels(
        cls,
        images: Sequence[np.ndarray],
        instances: Sequence[npt.ArrayLike],
        class_name: str = "object",
    ) -> DetectionDataset:
        """A one-class set from instance label images (0 background, each positive id one
        object, as StarDist's and the Data Science Bowl's ground truth): each object's
        mask is its id's pixels and its box the mask's tight box (:func:`mask_to_box`).

        Parameters
        ----------
        images : list of (H, W, 3) or (H, W) or (H, W, 1) float ndarray
            In [0, 1]; a grey image is repeated into three channels.
        instances : list of (H, W) int array_like
            One label image per image, of its size.
        class_name : str

        Raises
        ------
        InputError
            A label image of another size, negative ids, or a bad image.

        Examples
        --------
        >>> lab = np.array([[0, 4, 4], [0, 0, 9]])
        >>> ds = DetectionDataset.from_instance_labels([np.zeros((2, 3))], [lab], "cell")
        >>> ds.boxes[0].tolist(), ds.masks[0].sum((1, 2)).tolist(), ds.classes
        ([[1.0, 0.0, 3.0, 1.0], [2.0, 1.0, 3.0, 2.0]], [2, 1], ('cell',))
        """
        imgs = _check_list(images, "images", None)
        labs = _check_list(instances, "instances", len(imgs))
        rgb, boxes, labels, masks = [], [], [], []
        for i, (im, lab) in enumerate(zip(imgs, labs, strict=True)):
            a = np.asarray(im) if isinstance(im, np.ndarray) else im
            if isinstance(a, np.ndarray) and (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 1)):
                a = np.repeat(a.reshape(a.shape[0], a.shape[1], 1), 3, axis=2)
            a = _check_image(a, f"images[{i}]")
            y = np.asarray(lab)
            if y.shape != a.shape[:2] or y.dtype.kind not in "iu":
                raise InputError(
                    f"instances[{i}] must be an integer (H, W) label image of the image's size "
                    f"{a.shape[:2]}; got {plain_repr(lab)}"
                )
            if y.size and y.min() < 0:
                raise InputError(f"instances[{i}] has negative ids: 0 is the background")
            ids = np.unique(y)
            ids = ids[ids > 0]
            m = y[None] == ids[:, None, None]
            rgb.append(a)
            masks.append(m)
            boxes.append(np.array([mask_to_box(k) for k in m]) if len(ids) else np.zeros((0, 4)))
            labels.append(np.ones(len(ids), np.int64))
        return cls(rgb, boxes, labels, [class_name], masks=masks)

    @classmethod
    def from_coco(
        cls,
        path: str | os.PathLike[str],
        images_dir: str | os.PathLike[str] | None = None,
        masks: bool = False,
        *,
        allow_outside: bool = False,
    ) -> DetectionDataset:
        """A COCO ground-truth JSON file and its images as a detection set (what
        ``robopercept nn detect train|eval --data FILE.json`` reads).

        Each image ``images_dir / file_name`` is read as RGB in [0, 1]
        (:func:`robopercept.imaging.read_image`,
        :func:`~robopercept.nn.data.datasets.to_unit_float`); each non-crowd annotation
        gives a box, COCO's ``[x, y, w, h]`` turned into ``xyxy``
        ``(x, y, x + w, y + h)``, and a label, the 1-based position of its category in
        the file's ``categories`` (whose names become :attr:`classes`). Crowd regions
        (``iscrowd`` 1) are dropped, as torchvision's COCO detection references drop
        them for training. Image ids and file names are kept, so :meth:`to_coco` gives
        the file's images back.

        Parameters
        ----------
        path : path
            The COCO JSON file (:func:`~robopercept.nn.coco.dataset.read_coco_json`).
        images_dir : path, optional
            The folder of the images (default: the JSON file's folder).
        masks : bool
            Also each annotation's mask: its ``segmentation`` (polygons or RLE)
            rasterized at the image's size
            (:func:`~robopercept.nn.coco.rle.annotation_to_rle`, pycocotools' rule);
            what ``robopercept nn segment train --data FILE.json`` reads.
        allow_outside : bool, default False
            Read images whose ``file_name`` leads outside the images' folder
            (``../../x.png``, an absolute path), which is refused by default
            (:func:`~robopercept.imaging.io.contained_path`; the command line's
            ``--allow-outside-paths``): a file from elsewhere cannot make the command
            read files outside the data set.

        Returns
        -------
        DetectionDataset

        Raises
        ------
        InputError
            ``path`` is not a file, ``images_dir`` is not a folder, a listed image is
            missing from it, the file lists no images, or ``masks`` and an annotation
            without a ``segmentation`` (the messages name the command line's ``--data``
            and ``--images-dir``).
        FileFormatError
            The file is not COCO JSON, an image is unreadable, or a ``file_name`` leads
            outside the images' folder (without ``allow_outside``).

        Examples
        --------
        >>> import json, tempfile, pathlib
        >>> from robopercept.imaging import write_image
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = write_image(d / "a.png", np.zeros((8, 10, 3), np.uint8))
        >>> _ = (d / "gt.json").write_text(json.dumps({
        ...     "images": [{"id": 7, "file_name": "a.png", "width": 10, "height": 8}],
        ...     "categories": [{"id": 3, "name": "cat"}],
        ...     "annotations": [{"id": 1, "image_id": 7, "category_id": 3,
        ...                      "bbox": [1, 2, 4, 5], "area": 20, "iscrowd": 0}]}))
        >>> ds = DetectionDataset.from_coco(d / "gt.json")
        >>> ds.boxes[0].tolist(), ds.labels[0].tolist(), ds.classes, ds.image_ids
        ([[1.0, 2.0, 5.0, 7.0]], [1], ('cat',), (7,))
        """
        p = as_path(path, "path (--data)")
        if not p.is_file():
            raise InputError(f"--data: COCO file {p} does not exist")
        return cls._from_coco_dataset(
            read_coco_json(p), p, p.parent, images_dir, masks, allow_outside
        )

    @classmethod
    def from_annotations(
        cls,
        path: str | os.PathLike[str],
        images_dir: str | os.PathLike[str] | None = None,
        masks: bool = False,
        *,
        allow_outside: bool = False,
    ) -> DetectionDataset:
        """A user's annotated images in any form an annotation tool writes (what
        ``robopercept nn detect|segment train|eval --data PATH`` reads): a COCO JSON
        file, a folder of labelme JSON files, of Pascal-VOC XML files, or a VOC
        segmentation folder (:func:`~robopercept.nn.coco.folders.read_annotations`
        recognises which), read as :meth:`from_coco` reads a COCO file.

        Parameters
        ----------
        path : path
            The file or folder.
        images_dir : path, optional
            The images' folder, when not where the form puts them.
        masks : bool
            Also the instance masks (labelme polygons, VOC ``SegmentationObject``, COCO
            segmentations); a VOC XML folder has none.
        allow_outside : bool, default False
            Read images that the annotations place outside their folder (COCO
            ``file_name``, labelme ``imagePath``, VOC ``<filename>``), as
            :meth:`from_coco`; ``--allow-outside-paths``.

        Returns
        -------
        DetectionDataset

        Raises
        ------
        InputError
            Nothing there in any form, a missing image, ``masks`` with boxes only.
        FileFormatError
            A file of the form that cannot be read, or an image path outside the folder
            (without ``allow_outside``).

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from robopercept.imaging import write_image
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> _ = write_image(d / "a.png", np.zeros((8, 10, 3), np.uint8))
        >>> _ = (d / "a.xml").write_text(
        ...     "<annotation><filename>a.png</filename><size><width>10</width>"
        ...     "<height>8</height></size><object><name>tree</name><bndbox><xmin>1</xmin>"
        ...     "<ymin>2</ymin><xmax>5</xmax><ymax>6</ymax></bndbox></object></annotation>")
        >>> ds = DetectionDataset.from_annotations(d)
        >>> ds.boxes[0].tolist(), ds.classes
        ([[1.0, 2.0, 5.0, 6.0]], ('tree',))
        """
        found = read_annotations(path, allow_outside=allow_outside)
        if masks and found.form == "voc-xml":
            raise InputError(
                f"--data {found.root}: Pascal-VOC XML files hold boxes, not masks; a "
                "segmenter needs COCO segmentations, labelme polygons or a VOC "
                "SegmentationObject folder"
            )
        where = found.root if found.form != "coco" else as_path(path)
        return cls._from_coco_dataset(
            found.coco, where, found.root, images_dir, masks, allow_outside
        )

    @classmethod
    def _from_coco_dataset(
        cls,
        coco: CocoDataset,
        p: Any,
        default_root: Any,
        images_dir: str | os.PathLike[str] | None,
        masks: bool,
        allow_outside: bool = False,
    ) -> DetectionDataset:
        """The set of ``coco`` (read from ``p``) with its images under ``images_dir``
        or ``default_root`` (:meth:`from_coco`), each ``file_name`` inside that folder
        unless ``allow_outside``."""
        if images_dir is None or (isinstance(images_dir, str) and not images_dir):
            root = default_root
        else:
            root = as_path(images_dir, "images_dir (--images-dir)")
        if not root.is_dir():
            raise InputError(f"--images-dir: {root} is not a folder")
        masks = check_bool(masks, "masks")
        allow_outside = check_bool(allow_outside, "allow_outside (--allow-outside-paths)")
        if not coco.images:
            raise InputError(f"--data {p}: lists no images")
        label = {c.id: k + 1 for k, c in enumerate(coco.categories)}
        images, boxes, labels, all_masks = [], [], [], []
        segs = coco.segmentations or (None,) * len(coco.image_ids)
        for im in coco.images:
            f = contained_path(root, im.file_name, f"{p}: image {im.id} file_name", allow_outside)
            if not f.is_file():
                raise InputError(f"--images-dir: {f} (image {im.id} of {p}) does not exist")
            images.append(to_unit_float(read_image(f, mode="rgb")))
            sel = (coco.image_ids == im.id) & ~coco.iscrowd
            b = coco.boxes[sel]
            boxes.append(np.hstack((b[:, :2], b[:, :2] + b[:, 2:])))
            labels.append([label[int(c)] for c in coco.category_ids[sel]])
            if masks:
                h, w = images[-1].shape[:2]
                picked = np.flatnonzero(sel)
                # filled in place: no list of masks, no stacked copy (peak = the result)
                one = np.empty((len(picked), h, w), dtype=bool)
                for t, j in enumerate(picked):
                    if segs[j] is None:
                        raise InputError(
                            f"--data {p}: annotation {j + 1} of image {im.id} has no "
                            "segmentation: a segmenter needs masks"
                        )
                    one[t] = rle_decode(annotation_to_rle(segs[j], h, w))
                all_masks.append(one)
        return cls(
            images,
            boxes,
            labels,
            [c.name for c in coco.categories],
            masks=all_masks if masks else None,
            image_ids=[im.id for im in coco.images],
            file_names=[im.file_name for im in coco.images],
        )

    def class_maps(self) -> np.ndarray:
        """Per-pixel class labels ``(N, H, W)`` int64 from the instance masks: 0 the
        background, ``k`` where an object of ``classes[k - 1]`` is visible (masks are
        the visible parts, so they do not overlap; where they would, the later object
        wins). The semantic-segmentation ground truth of the procedural and digit sets.

        Raises
        ------
        InputError
            The set has no masks, or its images differ in size.

        Examples
        --------
        >>> m = np.zeros((1, 2, 3), bool); m[0, 0, 1:] = True
        >>> ds = DetectionDataset([np.zeros((2, 3, 3))], [[[1, 0, 3, 1]]], [[2]], ["a", "b"],
        ...                       masks=[m])
        >>> ds.class_maps().tolist()
        [[[0, 2, 2], [0, 0, 0]]]
        """
        self._check_masks()
        shapes = {im.shape[:2] for im in self.images}
        if len(shapes) != 1:
            raise InputError(f"class maps stack images of one size; these have {sorted(shapes)}")
        return np.stack([self.class_map(i) for i in range(len(self))])

    def class_map(self, index: int) -> np.ndarray:
        """The per-pixel class labels ``(H, W)`` int64 of image ``index``, at its own
        size (:meth:`class_maps`' rule: 0 the background, the later object wins).

        Raises
        ------
        InputError
            The set has no masks, or ``index`` is out of range.

        Examples
        --------
        >>> m = np.zeros((1, 2, 3), bool); m[0, 1, :2] = True
        >>> ds = DetectionDataset([np.zeros((2, 3, 3))], [[[0, 1, 2, 2]]], [[1]], ["a"],
        ...                       masks=[m])
        >>> ds.class_map(0).tolist()
        [[0, 0, 0], [1, 1, 0]]
        """
        self._check_masks()
        assert self.masks is not None
        i = self._index(index)
        out = np.zeros(self.images[i].shape[:2], np.int64)
        for mk, k in zip(self.masks[i], self.labels[i], strict=True):
            out[mk] = k
        return out

    def _check_masks(self) -> None:
        if self.masks is None:
            raise InputError(
                "this set has no masks, so no class maps: build it with masks "
                "(procedural_detection_set and digits_detection_set have them)"
            )

    def __len__(self) -> int:
        return len(self.images)

    def __repr__(self) -> str:
        return (
            f"DetectionDataset({len(self)} images, {self.n_boxes} boxes, "
            f"classes={self.classes}, masks={self.masks is not None})"
        )

    @property
    def n_boxes(self) -> int:
        """The number of boxes over all images."""
        return int(sum(len(b) for b in self.boxes))

    def _index(self, index: Any) -> int:
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
            raise InputError(f"index must be an integer; got {plain_repr(index)}")
        n = len(self)
        i = int(index)
        if not -n <= i < n:
            raise InputError(f"index {i} is out of range for {n} images")
        return i % n

    def areas(self, index: int) -> np.ndarray:
        """``(K,)`` areas of image ``index``'s objects: mask pixel counts where masks are
        known, else ``w h`` of the boxes."""
        i = self._index(index)
        if self.masks is not None:
            return self.masks[i].reshape(len(self.boxes[i]), -1).sum(1).astype(np.float64)
        b = self.boxes[i]
        return (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])

    def __getitem__(self, index: int) -> tuple[torch.Tensor, dict[str, Any]]:
        i = self._index(index)
        image = torch.from_numpy(np.ascontiguousarray(self.images[i].transpose(2, 0, 1)))
        k = len(self.boxes[i])
        target: dict[str, Any] = {
            "boxes": torch.from_numpy(self.boxes[i].astype(np.float32)),
            "labels": torch.from_numpy(self.labels[i].copy()),
            "image_id": self.image_ids[i],
            "area": torch.from_numpy(self.areas(i).astype(np.float32)),
            "iscrowd": torch.zeros(k, dtype=torch.int64),
        }
        if self.masks is not None:
            target["masks"] = torch.from_numpy(self.masks[i].astype(np.uint8))
        if self.keypoints is not None:
            target["keypoints"] = torch.from_numpy(self.keypoints[i].astype(np.float32))
        return image, target

    def subset(self, indices: npt.ArrayLike) -> DetectionDataset:
        """The images at ``indices`` (ids, names and meta kept), in that order."""
        sel = [int(v) for v in _indices(indices, len(self))]
        return DetectionDataset(
            [self.images[i] for i in sel],
            [self.boxes[i] for i in sel],
            [self.labels[i] for i in sel],
            self.classes,
            masks=None if self.masks is None else [self.masks[i] for i in sel],
            image_ids=[self.image_ids[i] for i in sel],
            file_names=[self.file_names[i] for i in sel],
            meta=[self.meta[i] for i in sel],
            keypoints=None if self.keypoints is None else [self.keypoints[i] for i in sel],
        )

    def with_classes(self, classes: Sequence[str], what: str = "--data") -> DetectionDataset:
        """The same images with labels renumbered for the class list ``classes``, by
        name (a model's classes, to score it on annotations that list theirs in another
        order or list fewer).

        Raises
        ------
        InputError
            An object's class is not in ``classes`` (the message names the classes
            missing and ``what``, the flag that gave the data).

        Examples
        --------
        >>> ds = DetectionDataset([np.zeros((4, 4, 3))], [[[0, 0, 2, 2]]], [[2]], ["a", "b"])
        >>> ds.with_classes(["x", "b", "a"]).labels[0].tolist()
        [2]
        """
        if not isinstance(classes, (list, tuple)) or not all(isinstance(c, str) for c in classes):
            raise InputError(f"classes must be a list of class names; got {plain_repr(classes)}")
        if list(classes) == list(self.classes):
            return self
        where = {c: k + 1 for k, c in enumerate(classes)}
        used = sorted({self.classes[int(v) - 1] for lab in self.labels for v in lab})
        missing = [c for c in used if c not in where]
        if missing:
            raise InputError(
                f"{what}: its objects of class {missing} are not among the model's classes "
                f"{list(classes)}: evaluate on data of the classes the model was trained for"
            )
        relabel = np.array([0] + [where.get(c, 0) for c in self.classes], dtype=np.int64)
        return DetectionDataset(
            self.images,
            self.boxes,
            [relabel[np.asarray(lab, dtype=np.int64)] for lab in self.labels],
            list(classes),
            masks=self.masks,
            image_ids=self.image_ids,
            file_names=self.file_names,
            meta=self.meta,
            keypoints=self.keypoints,
        )

    def split(
        self,
        fractions: Sequence[float] = (0.7, 0.15, 0.15),
        rng: int | np.random.Generator | None = 0,
    ) -> tuple[DetectionDataset, ...]:
        """A seeded random split by image (train, validation, test by default).

        Part ``j`` gets ``f_j N`` images rounded by the largest remainders
        (:func:`~robopercept.nn.data.datasets.stratified_split` with one stratum); the parts are
        disjoint and cover every image; the same seed gives the same split.

        Examples
        --------
        >>> ds = DetectionDataset([np.zeros((4, 4, 3), np.float32)] * 10,
        ...                       [np.zeros((0, 4))] * 10, [[]] * 10, ["x"])
        >>> [len(p) for p in ds.split((0.6, 0.2, 0.2), rng=1)]
        [6, 2, 2]
        """
        if len(self) == 0:
            raise InputError("cannot split an empty data set")
        parts = stratified_split(np.zeros(len(self), dtype=np.int64), fractions, rng)
        return tuple(self.subset(p) for p in parts)

    def to_coco(self, masks: bool = True) -> CocoDataset:
        """The ground truth as a :class:`~robopercept.nn.coco.dataset.CocoDataset` (boxes as COCO
        ``[x, y, w, h]``, ``area`` as :meth:`areas`, category ``k`` = ``classes[k - 1]``;
        where the set has masks and ``masks`` is true, each object's ``segmentation``
        is its mask's RLE, :func:`~robopercept.nn.coco.rle.rle_encode`; box
        evaluation passes ``masks=False`` and skips the encoding; where it has
        keypoints, each object's ``keypoints`` (``[x, y, v] * J``, unlabelled ones as
        ``0, 0, 0`` as in COCO files) and ``num_keypoints``).

        Examples
        --------
        >>> ds = DetectionDataset([np.zeros((4, 6, 3), np.float32)], [[[1, 1, 3, 4]]],
        ...                       [[1]], ["thing"])
        >>> ds.to_coco().boxes.tolist()
        [[1.0, 1.0, 2.0, 3.0]]
        """
        anns: list[dict[str, Any]] = []
        for i in range(len(self)):
            b = self.boxes[i]
            for j, (box, lab, area) in enumerate(
                zip(b, self.labels[i], self.areas(i), strict=True)
            ):
                ann: dict[str, Any] = {
                    "id": len(anns) + 1,
                    "image_id": self.image_ids[i],
                    "category_id": int(lab),
                    "bbox": [box[0], box[1], box[2] - box[0], box[3] - box[1]],
                    "area": float(area),
                    "iscrowd": 0,
                }
                if masks and self.masks is not None:
                    ann["segmentation"] = rle_encode(self.masks[i][j])
                if self.keypoints is not None:
                    kp = self.keypoints[i][j]
                    ann["keypoints"] = np.where(kp[:, 2:] > 0, kp, 0.0).ravel().tolist()
                    ann["num_keypoints"] = int((kp[:, 2] > 0).sum())
                anns.append(ann)
        return coco_from_dict(
            {
                "images": [
                    {"id": iid, "file_name": fn, "width": im.shape[1], "height": im.shape[0]}
                    for iid, fn, im in zip(
                        self.image_ids, self.file_names, self.images, strict=True
                    )
                ],
                "categories": [{"id": k + 1, "name": c} for k, c in enumerate(self.classes)],
                "annotations": anns,
            }
        )


def _check_image(image: Any, name: str) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise InputError(f"{name} must be an (H, W, 3) numpy array; got {type(image).__name__}")
    if image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
        hint = ""
        if image.ndim == 3 and image.shape[0] == 3:
            hint = ": channels-first? use image.transpose(1, 2, 0)"
        elif image.ndim == 2:
            hint = ": gray? use np.repeat(image[..., None], 3, axis=2)"
        raise InputError(f"{name} must be (H, W, 3) RGB; got shape {image.shape}{hint}")
    if image.dtype.kind != "f":
        raise InputError(
            f"{name} must be floating point in [0, 1]; got {image.dtype}: use "
            "robopercept.nn.data.datasets.to_unit_float(image)"
        )
    if not np.isfinite(image).all() or image.min() < 0 or image.max() > 1:
        raise InputError(f"{name} must hold finite values in [0, 1]: clip or rescale it")
    return image.astype(np.float32, copy=False)


def _check_boxes(boxes: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
    b = check_numeric(boxes, name)
    if b.size == 0:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError(f"{name} must be (K, 4) xyxy; got shape {b.shape}")
    if not np.isfinite(b).all():
        raise InputError(f"{name} must be finite; got NaN/inf: drop those boxes")
    h, w = shape
    if np.any(b[:, 2] < b[:, 0]) or np.any(b[:, 3] < b[:, 1]):
        raise InputError(f"{name} must have x1 <= x2 and y1 <= y2 (xyxy); swap the corners")
    if b.size and (b[:, :2].min() < 0 or b[:, 2].max() > w or b[:, 3].max() > h):
        raise InputError(
            f"{name} must lie inside the {w} x {h} image ([0, {w}] x [0, {h}]); clip them "
            f"with np.clip(boxes, 0, [{w}, {h}, {w}, {h}])"
        )
    return b.astype(np.float64)


def _check_labels(labels: Any, name: str, k: int, n_classes: int) -> np.ndarray:
    y = check_numeric(labels, name).reshape(-1)
    if y.size != k:
        raise InputError(f"{name} must have one label per box ({k}); got {y.size}")
    if np.any(y != np.floor(y)) or np.any((y < 1) | (y > n_classes)):
        raise InputError(
            f"{name} must be integers in [1, {n_classes}] (1-based; 0 is background); "
            f"got {plain_repr(labels)}"
        )
    return y.astype(np.int64)


def _check_masks(masks: Any, name: str, k: int, shape: tuple[int, ...]) -> np.ndarray:
    """``masks`` as a ``(k, *shape)`` bool array; a bool array of that shape is kept as
    it is (no copy: masks are the largest arrays of a set), any other numeric one is
    compared with 0 without a float64 copy."""
    if isinstance(masks, np.ndarray) and masks.dtype.kind in "biuf":
        m = masks
    else:
        m = check_numeric(masks, name)
    if m.size == 0:
        m = m.reshape(0, *shape)
    if m.shape != (k, *shape):
        raise InputError(f"{name} must be (K, H, W) = {(k, *shape)}; got {m.shape}")
    return m if m.dtype == bool else m != 0


def _check_keypoints(value: Any, name: str, k: int) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64) if not isinstance(value, np.ndarray) else value
    if a.ndim == 3 and a.shape[0] == 0:
        a = a.reshape(0, a.shape[1], 3) if a.shape[-1] == 3 else np.zeros((0, 0, 3))
    if a.ndim != 3 or a.shape[0] != k or a.shape[2] != 3:
        raise InputError(
            f"{name} must be ({k}, J, 3): rows (x, y, v) of J keypoints for each of the "
            f"{k} boxes; got {plain_repr(value)}"
        )
    a = a.astype(np.float64)
    v = a[..., 2]
    if not np.isin(v, (0.0, 1.0, 2.0)).all():
        raise InputError(f"{name}: visibility v must be 0, 1 or 2 (COCO); got {np.unique(v)}")
    if not np.isfinite(a[..., :2][v > 0]).all():
        raise InputError(f"{name}: labelled keypoints (v > 0) must have finite x, y")
    return a


def collate_detection(
    batch: Sequence[tuple[torch.Tensor, dict[str, Any]]],
) -> tuple[list[torch.Tensor], list[dict[str, Any]]]:
    """Batch detection items as two lists (images, targets): torchvision's detection
    ``collate_fn`` (``tuple(zip(*batch))``), for ``DataLoader(..., collate_fn=...)``.

    Images of different sizes cannot be stacked, so they stay a list, as torchvision's
    detection models take them.

    Parameters
    ----------
    batch : sequence of (image, target)

    Returns
    -------
    images : list of (3, H, W) torch.Tensor
    targets : list of dict

    Examples
    --------
    >>> ds = DetectionDataset([np.zeros((4, 6, 3), np.float32)] * 2,
    ...                       [[[1, 1, 3, 4]], np.zeros((0, 4))], [[1], []], ["thing"])
    >>> images, targets = collate_detection([ds[0], ds[1]])
    >>> len(images), [len(t["boxes"]) for t in targets]
    (2, [1, 0])
    """
    if not isinstance(batch, (list, tuple)) or not batch:
        raise InputError(
            f"batch must be a non-empty list of (image, target) pairs; got {plain_repr(batch)}"
        )
    images, targets = [], []
    for j, item in enumerate(batch):
        if (
            not isinstance(item, (list, tuple))
            or len(item) != 2
            or not isinstance(item[0], torch.Tensor)
            or not isinstance(item[1], Mapping)
        ):
            raise InputError(
                f"batch[{j}] must be an (image tensor, target dict) pair as a "
                f"DetectionDataset gives; got {type(item).__name__}"
            )
        images.append(item[0])
        targets.append(dict(item[1]))
    return images, targets


# --------------------------------------------------------------------------- pictures


def samples_picture(
    dataset: DetectionDataset,
    indices: npt.ArrayLike | None = None,
    *,
    columns: int = 4,
    show_masks: bool = True,
) -> np.ndarray:
    """A grid of images of ``dataset`` with their boxes, labels (and masks) drawn
    (:func:`~robopercept.viz.detection.detections_grid` of the images chosen).

    Parameters
    ----------
    dataset : DetectionDataset
    indices : (N,) int array_like, optional
        Images to show (default the first 8).
    columns : int
        Images per row (>= 1).
    show_masks : bool

    Returns
    -------
    (rows * H_max + gaps, columns * W_max + gaps, 3) uint8 ndarray
        Images top-left aligned in cells of the largest size, 2-pixel white gaps.

    Examples
    --------
    >>> ds = DetectionDataset([np.zeros((32, 32, 3), np.float32)] * 3, [[[4, 4, 12, 12]]] * 3,
    ...                       [[1]] * 3, ["x"])
    >>> samples_picture(ds).shape
    (32, 100, 3)
    """
    if not isinstance(dataset, DetectionDataset):
        raise InputError(f"dataset must be a DetectionDataset; got {type(dataset).__name__}")
    if len(dataset) == 0:
        raise InputError("dataset is empty: nothing to draw")
    if indices is None:
        sel = list(range(min(8, len(dataset))))
    else:
        sel = [int(v) for v in _indices(indices, len(dataset))]
        if not sel:
            raise InputError("indices is empty: give at least one image index")
    columns = check_int(columns, "columns", 1)
    show = check_bool(show_masks, "show_masks")
    return detections_grid(
        [dataset.images[i] for i in sel],
        [dataset.boxes[i] for i in sel],
        [dataset.labels[i] for i in sel],
        dataset.classes,
        masks=[dataset.masks[i] for i in sel] if show and dataset.masks is not None else None,
        columns=columns,
    )


def _indices(indices: npt.ArrayLike, n: int) -> np.ndarray:
    """``indices`` as int64 in [0, n) (negative ones count from the end)."""
    idx = check_numeric(indices, "indices").reshape(-1)
    if np.any(idx != np.floor(idx)) or np.any((idx < -n) | (idx >= n)):
        raise InputError(f"indices must be integers in [-{n}, {n}); got {plain_repr(indices)}")
    return idx.astype(np.int64) % n
