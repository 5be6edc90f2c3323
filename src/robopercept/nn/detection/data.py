r"""Detection data with exact ground truth: procedural shapes on real photos, real
handwritten digits on canvases, real aerial tree crowns cut into tiles.

Every set is a :class:`DetectionDataset`, which a torch training loop indexes like
torchvision's detection data sets: item ``i`` is ``(image, target)`` with ``image`` a
float32 tensor ``(3, H, W)`` in [0, 1] and ``target`` a dict

- ``"boxes"``: ``(K, 4)`` float32, ``xyxy`` in pixels;
- ``"labels"``: ``(K,)`` int64, 1-based (0 is the background of the R-CNN family);
- ``"masks"``: ``(K, H, W)`` uint8, where the set knows them (procedural and digits);
- ``"image_id"`` (int), ``"area"`` ((K,) float32: the mask's pixel count where masks
  are known, else ``w h``) and ``"iscrowd"`` ((K,) int64, all 0), as torchvision's COCO
  wrapper gives.

:func:`collate_detection` batches items as lists (images of different sizes stay
apart), :meth:`DetectionDataset.to_coco` gives the :class:`~robopercept.nn.coco.formats.CocoDataset`
that :func:`~robopercept.nn.coco.formats.evaluate_detections` scores, and
:meth:`DetectionDataset.split` a seeded train/validation/test split.

Box convention
--------------
Boxes are continuous ``xyxy`` with pixel ``(col, row)`` covering
``[col, col + 1) x [row, row + 1)`` (the torchvision and COCO convention, the one of
:mod:`robopercept.nn.ops.boxes`), so the tight box of a mask is

.. math::

    (x_1, y_1, x_2, y_2) = (\min c,\ \min r,\ \max c + 1,\ \max r + 1)

over its pixels ``(c, r)``: its width is the number of columns it spans and it equals
``pycocotools.mask.toBbox`` of the mask (converted to ``xyxy``). Every box of the
procedural and digit sets is exactly this box of its mask (tested).

The sets
--------
* :func:`procedural_detection_set`: the four shapes of
  :func:`~robopercept.nn.data.datasets.shape_masks` (circle, square, triangle, cross),
  textured, scaled, rotated, over real-photo tiles of scikit-image's bundled images, with
  clutter under them and occluding bars over them;
  boxes and masks are those of the *visible* part.
* :func:`digits_detection_set` and :func:`single_digit_set`: real handwritten digits of
  scikit-learn's ``load_digits`` (8 x 8, bundled), scaled and placed on black canvases.
* :func:`deepforest_tiles`: the real tree crowns of the DeepForest NEON images (VOC XML):
  tiles of the large YELL crop2 image, a held-out bottom strip as the test set, and the
  other three images as cross-image test sets.

:func:`draw_detections` and :func:`samples_picture` draw boxes, masks and labels.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from robopercept._checks import (
    as_path,
    as_rng,
    check_bool,
    check_int,
    check_numeric,
    check_real,
    check_size,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.imaging.io import read_image
from robopercept.nn._guards import check_allocation
from robopercept.nn.coco.formats import CocoDataset, coco_from_dict, read_voc_xml
from robopercept.nn.data.datasets import SHAPES, shape_masks, stratified_split
from robopercept.nn.ops.boxes import dihedral_boxes
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import check_picture_size, draw_boxes, draw_mask, to_rgb8

__all__ = [
    "BACKGROUNDS",
    "DEEPFOREST_IMAGES",
    "DIGIT_CLASSES",
    "DeepForestTiles",
    "DetectionDataset",
    "FlipRotate",
    "ScaleJitter",
    "collate_detection",
    "deepforest_tiles",
    "digits_detection_set",
    "draw_detections",
    "mask_to_box",
    "photo_background",
    "procedural_detection_set",
    "random_texture",
    "samples_picture",
    "single_digit_set",
]

#: scikit-image images (``skimage.data.<name>()``) whose files ship in the wheel, used as
#: backgrounds of :func:`procedural_detection_set` (none is fetched by pooch)
BACKGROUNDS = (
    "astronaut",
    "brick",
    "camera",
    "chelsea",
    "coffee",
    "coins",
    "grass",
    "gravel",
    "hubble_deep_field",
    "immunohistochemistry",
    "moon",
    "rocket",
)
#: the class names of the digit sets: label ``d + 1`` is digit ``d``
DIGIT_CLASSES = tuple(str(d) for d in range(10))
#: the four DeepForest NEON images (file stems); the first is the one cut into tiles
DEEPFOREST_IMAGES = (
    "2019_YELL_2_528000_4978000_image_crop2",
    "2019_YELL_2_541000_4977000_image_crop",
    "OSBS_029",
    "SOAP_061",
)
#: the largest data set (pixels over all images) a generator makes: 2**28 (3 GiB float32)
MAX_PIXELS = 2**28


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


def _check_classes(classes: Any) -> tuple[str, ...]:
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
        (:class:`~robopercept.nn.detection.models.KeypointRCNN`), ``target["keypoints"]``.

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
        self.classes = _check_classes(classes)
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
        if self.masks is None:
            raise InputError(
                "this set has no masks, so no class maps: build it with masks "
                "(procedural_detection_set and digits_detection_set have them)"
            )
        shapes = {im.shape[:2] for im in self.images}
        if len(shapes) != 1:
            raise InputError(f"class maps stack images of one size; these have {sorted(shapes)}")
        h, w = shapes.pop()
        out = np.zeros((len(self), h, w), np.int64)
        for i, (m, lab) in enumerate(zip(self.masks, self.labels, strict=True)):
            for mk, k in zip(m, lab, strict=True):
                out[i][mk] = k
        return out

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
        """The ground truth as a :class:`~robopercept.nn.coco.formats.CocoDataset` (boxes as COCO
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
        from robopercept.nn.coco.rle import rle_encode

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
    m = check_numeric(masks, name)
    if m.size == 0:
        m = m.reshape(0, *shape)
    if m.shape != (k, *shape):
        raise InputError(f"{name} must be (K, H, W) = {(k, *shape)}; got {m.shape}")
    return m != 0


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


def _augment_generator(generator: int | torch.Generator | None) -> torch.Generator:
    """The augmentations' source of draws: the generator given, one seeded with the int,
    or (None) one seeded from the system's entropy."""
    if isinstance(generator, torch.Generator):
        return generator
    if generator is None:
        g = torch.Generator()
        g.seed()
        return g
    return torch.Generator().manual_seed(check_int(generator, "generator", 0))


class FlipRotate:
    r"""Random mirror images and quarter turns of a detection sample, boxes (and masks)
    moved with the pixels: the dihedral augmentation of aerial and top-down images.

    For an image of width :math:`W` and height :math:`H` and an ``xyxy`` box
    :math:`(x_1, y_1, x_2, y_2)` in continuous pixel coordinates:

    - horizontal flip (probability ``horizontal``): :math:`(W - x_2, y_1, W - x_1, y_2)`;
    - vertical flip (probability ``vertical``): :math:`(x_1, H - y_2, x_2, H - y_1)`;
    - with ``rotate90``, :math:`k \sim U\{0..3\}` counter-clockwise quarter turns
      (``torch.rot90(image, k, (1, 2))``), each mapping a point :math:`(x, y)` to
      :math:`(y, W - x)` and the size to :math:`H \times W`, so a box becomes
      :math:`(y_1, W - x_2, y_2, W - x_1)`.

    Applied in that order (:func:`~robopercept.nn.ops.boxes.dihedral_boxes`). Same generator
    seed, same sequence of draws.

    Parameters
    ----------
    horizontal, vertical : float
        Probabilities in [0, 1].
    rotate90 : bool
        Random quarter turns (use only where orientation carries no meaning).
    generator : int or torch.Generator, optional
        Seed or source of the draws.

    Examples
    --------
    >>> t = FlipRotate(horizontal=1.0, generator=0)
    >>> image, target = t(torch.zeros(3, 10, 20), {"boxes": torch.tensor([[2.0, 1, 5, 4]])})
    >>> target["boxes"].tolist()
    [[15.0, 1.0, 18.0, 4.0]]
    """

    def __init__(
        self,
        horizontal: float = 0.5,
        vertical: float = 0.0,
        rotate90: bool = False,
        generator: int | torch.Generator | None = None,
    ) -> None:
        self.horizontal = check_real(horizontal, "horizontal (a probability)", 0.0, 1.0)
        self.vertical = check_real(vertical, "vertical (a probability)", 0.0, 1.0)
        self.rotate90 = check_bool(rotate90, "rotate90")
        self.generator = _augment_generator(generator)

    def __repr__(self) -> str:
        return (
            f"FlipRotate(horizontal={self.horizontal}, vertical={self.vertical}, "
            f"rotate90={self.rotate90})"
        )

    def __call__(
        self, image: torch.Tensor, target: Mapping[str, Any]
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Transform one ``(C, H, W)`` image and its target (``"boxes"`` ``(K, 4)``
        ``xyxy``, optional ``"masks"`` ``(K, H, W)``; other keys are kept)."""
        if not isinstance(image, torch.Tensor) or image.ndim != 3:
            raise InputError(f"image must be a (C, H, W) torch.Tensor; got {plain_repr(image)}")
        if not isinstance(target, Mapping) or "boxes" not in target:
            raise InputError("target must be a dict with 'boxes' ((K, 4) xyxy)")
        out = dict(target)
        b = torch.as_tensor(target["boxes"]).clone()
        masks = target.get("masks")
        u = torch.rand(3, generator=self.generator)
        hflip, vflip = bool(u[0] < self.horizontal), bool(u[1] < self.vertical)
        k = int(torch.randint(4, (1,), generator=self.generator)) if self.rotate90 else 0
        size = (int(image.shape[1]), int(image.shape[2]))
        b = dihedral_boxes(b.reshape(-1, 4), size, hflip=hflip, vflip=vflip, quarter_turns=k)
        dims = [d for d, on in ((2, hflip), (1, vflip)) if on]
        if dims:
            image = torch.flip(image, dims)
            masks = torch.flip(masks, dims) if masks is not None else None
        if k:
            image = torch.rot90(image, k, (1, 2))
            masks = torch.rot90(masks, k, (1, 2)) if masks is not None else None
        out["boxes"] = b.reshape(-1, 4)
        if masks is not None:
            out["masks"] = masks
        return image.contiguous(), out


class ScaleJitter:
    r"""Random zoom of a detection sample at a fixed image size, boxes moved with the
    pixels: torchvision's ``ScaleJitter`` followed by a random crop or pad back to the
    input size (large-scale jitter, as in Ghiasi et al. 2021, on one image).

    For an image of width :math:`W` and height :math:`H`, a scale
    :math:`s = \exp u`, :math:`u \sim U[\log s_{lo}, \log s_{hi}]` (log-uniform, so
    zooming in and out are equally likely), the image is resized bilinearly to
    :math:`(\lfloor sH \rceil, \lfloor sW \rceil)`, then an :math:`H \times W` window
    at a uniform offset :math:`(o_x, o_y)` is cut from it (:math:`s > 1`) or it is put
    at a uniform offset on a canvas of ``fill`` (:math:`s < 1`). An ``xyxy`` box
    becomes

    .. math:: (s x_1 - o_x, \; s y_1 - o_y, \; s x_2 - o_x, \; s y_2 - o_y)

    (:math:`o \le 0` when padding), clipped to the image. A box that keeps less than
    ``min_visible`` of its scaled area is dropped, with its entries in every other
    per-box field of the target (``labels``, ``masks``, ...: the tensors whose first
    dimension is the number of boxes). Masks are resized by nearest neighbour.

    Parameters
    ----------
    scale : (float, float)
        :math:`(s_{lo}, s_{hi})`, ``0 < s_lo <= s_hi``.
    min_visible : float
        In [0, 1]: the share of a box's area that must stay in the image.
    fill : float
        Value of padded pixels (the images are in [0, 1]).
    generator : int or torch.Generator, optional
        Seed or source of the draws.

    Examples
    --------
    >>> t = ScaleJitter(scale=(2.0, 2.0), generator=0)
    >>> image, target = t(torch.zeros(3, 10, 10), {"boxes": torch.tensor([[4.0, 4, 6, 6]]),
    ...                                            "labels": torch.tensor([1])})
    >>> image.shape, target["boxes"].shape  # same size; the box doubled and moved
    (torch.Size([3, 10, 10]), torch.Size([1, 4]))
    >>> float(target["boxes"][0, 2] - target["boxes"][0, 0])
    4.0
    """

    def __init__(
        self,
        scale: tuple[float, float] = (0.75, 1.33),
        min_visible: float = 0.5,
        fill: float = 0.0,
        generator: int | torch.Generator | None = None,
    ) -> None:
        if not isinstance(scale, (tuple, list)) or len(scale) != 2:
            raise InputError(f"scale must be a pair (low, high), e.g. (0.75, 1.33); got {scale!r}")
        lo = check_real(scale[0], "scale low", 0.0, 16.0, low_inclusive=False)
        hi = check_real(scale[1], "scale high", lo, 16.0)
        self.scale = (lo, hi)
        self.min_visible = check_real(min_visible, "min_visible (a share of the area)", 0.0, 1.0)
        self.fill = check_real(fill, "fill")
        self.generator = _augment_generator(generator)

    def __repr__(self) -> str:
        return f"ScaleJitter(scale={self.scale}, min_visible={self.min_visible}, fill={self.fill})"

    def __call__(
        self, image: torch.Tensor, target: Mapping[str, Any]
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Transform one ``(C, H, W)`` image and its target (``"boxes"`` ``(K, 4)``
        ``xyxy``; other per-box fields follow the boxes kept; other keys are kept)."""
        if not isinstance(image, torch.Tensor) or image.ndim != 3 or not image.is_floating_point():
            raise InputError(
                f"image must be a floating (C, H, W) torch.Tensor; got {plain_repr(image)}"
            )
        if not isinstance(target, Mapping) or "boxes" not in target:
            raise InputError("target must be a dict with 'boxes' ((K, 4) xyxy)")
        h, w = int(image.shape[1]), int(image.shape[2])
        if h < 1 or w < 1 or image.shape[0] < 1:
            raise InputError(f"image must have at least one pixel; got shape {tuple(image.shape)}")
        try:
            b = torch.as_tensor(target["boxes"], dtype=torch.float32)
        except (TypeError, ValueError, RuntimeError):
            b = torch.zeros(0)
        if b.ndim != 2 or b.shape[1] != 4 or not bool(torch.isfinite(b).all()):
            raise InputError(
                "target['boxes'] must be finite (K, 4) xyxy boxes; got "
                f"{plain_repr(target['boxes'])}"
            )
        masks = target.get("masks")
        n_masks = masks.shape[0] if isinstance(masks, torch.Tensor) and masks.ndim == 3 else 0
        u = torch.rand(3, generator=self.generator, dtype=torch.float64)
        lo, hi = math.log(self.scale[0]), math.log(self.scale[1])
        s = math.exp(lo + float(u[0]) * (hi - lo))
        sh, sw = max(1, round(s * h)), max(1, round(s * w))
        check_allocation(
            (image.shape[0] + n_masks) * sh * sw, 4,
            f"the zoomed image and masks ({image.shape[0]} + {n_masks}, {sh}, {sw})",
            "lower the scale's high end",
        )  # fmt: skip
        big = torch.nn.functional.interpolate(
            image[None], size=(sh, sw), mode="bilinear", align_corners=False
        )[0]
        # the offset of the output window in the resized image (negative: padding)
        oy = int(float(u[1]) * (sh - h + 1)) if sh >= h else -int(float(u[1]) * (h - sh + 1))
        ox = int(float(u[2]) * (sw - w + 1)) if sw >= w else -int(float(u[2]) * (w - sw + 1))
        out_img = image.new_full(image.shape, self.fill)
        # rows/cols of the output covered by the resized image, and where they come from
        y0, y1 = max(0, -oy), min(h, sh - oy)
        x0, x1 = max(0, -ox), min(w, sw - ox)
        out_img[:, y0:y1, x0:x1] = big[:, y0 + oy : y1 + oy, x0 + ox : x1 + ox]
        sx, sy = sw / w, sh / h  # the exact factors of the rounded size
        moved = b * torch.tensor([sx, sy, sx, sy]) - torch.tensor([ox, oy, ox, oy])
        clipped = torch.stack(
            [moved[:, 0].clamp(0, w), moved[:, 1].clamp(0, h), moved[:, 2].clamp(0, w),
             moved[:, 3].clamp(0, h)], 1,
        )  # fmt: skip
        area = (moved[:, 2] - moved[:, 0]) * (moved[:, 3] - moved[:, 1])
        kept_area = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
        keep = (kept_area > 0) & (kept_area >= self.min_visible * area)
        k = b.shape[0]
        out = dict(target)
        for key, value in target.items():
            if key == "boxes" or not isinstance(value, torch.Tensor) or value.ndim == 0:
                continue
            if value.shape[0] != k:
                continue
            if key == "masks" and value.ndim == 3:
                m = torch.nn.functional.interpolate(
                    value[None].float(), size=(sh, sw), mode="nearest"
                )[0].to(value.dtype)
                mo = value.new_zeros((k, h, w))
                mo[:, y0:y1, x0:x1] = m[:, y0 + oy : y1 + oy, x0 + ox : x1 + ox]
                value = mo
            out[key] = value[keep]
        out["boxes"] = clipped[keep].to(torch.as_tensor(target["boxes"]).dtype).reshape(-1, 4)
        return out_img.contiguous(), out


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


# --------------------------------------------------------------------------- helpers


def _check_range(value: Any, name: str, low: float, high: float, integer: bool) -> tuple:
    want = f"{name} must be a (low, high) pair with {low} <= low <= high <= {high}"
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise InputError(f"{want}; got {plain_repr(value)}")
    a: float
    b: float
    if integer:
        a, b = check_int(value[0], f"{name}[0]"), check_int(value[1], f"{name}[1]")
    else:
        a, b = check_real(value[0], f"{name}[0]"), check_real(value[1], f"{name}[1]")
    if not low <= a <= b <= high:
        raise InputError(f"{want}; got {plain_repr(value)}")
    return a, b


def _check_count(n: Any, size: tuple[int, int]) -> int:
    n = check_int(n, "n_images", 1)
    check_allocation(
        n * size[0] * size[1],
        60,
        f"{n} images of {size[0]} x {size[1]} (with their masks)",
        "lower n_images or size, or make the set in chunks with different seeds",
    )
    if n * size[0] * size[1] > MAX_PIXELS:
        raise InputError(
            f"{n} images of {size[0]} x {size[1]} exceed {MAX_PIXELS} pixels: lower n_images"
        )
    return n


def _resize(image: np.ndarray, shape: tuple[int, int], antialias: bool) -> np.ndarray:
    from skimage.transform import resize

    return np.asarray(
        resize(image, shape, order=1, mode="edge", anti_aliasing=antialias, preserve_range=True)
    )


@functools.cache
def _photo(name: str) -> np.ndarray:
    """scikit-image's bundled image ``name`` as float32 RGB in [0, 1] (read-only)."""
    import skimage.data

    im = np.asarray(getattr(skimage.data, name)())
    if im.ndim == 2:
        im = np.repeat(im[..., None], 3, axis=2)
    im = im[..., :3].astype(np.float32) / np.float32(np.iinfo(im.dtype).max)
    im.setflags(write=False)
    return im


def _check_gen_size(gen: Any, w: Any, h: Any) -> tuple[np.random.Generator, int, int]:
    if not isinstance(gen, np.random.Generator):
        raise InputError(
            f"gen must be a numpy.random.Generator (np.random.default_rng(seed)); got "
            f"{plain_repr(gen)}"
        )
    size = check_size((w, h), "(w, h)", 1, 8192, max_pixels=1 << 26)
    return gen, size[0], size[1]


def photo_background(gen: np.random.Generator, w: int, h: int) -> tuple[np.ndarray, dict[str, Any]]:
    """A random crop of a random bundled photo (:data:`BACKGROUNDS`): aspect ``w / h``,
    30-100 % of the largest such crop, resized (bilinear, antialiased) to ``(h, w)``, its
    contrast reduced to ``0.2 + 0.6 I``.

    Parameters
    ----------
    gen : numpy.random.Generator
        The generator the caller draws everything else from (not re-seeded here).
    w, h : int
        Width and height in pixels.

    Returns
    -------
    (h, w, 3) float64 ndarray
        RGB in [0.2, 0.8].
    dict
        ``"photo"``: the image's name, ``"crop"``: ``(x, y, w, h)`` in the photo.

    Examples
    --------
    >>> tile, info = photo_background(np.random.default_rng(0), 32, 24)
    >>> tile.shape, bool(tile.min() >= 0.2 and tile.max() <= 0.8), info["photo"] in BACKGROUNDS
    ((24, 32, 3), True, True)
    """
    gen, w, h = _check_gen_size(gen, w, h)
    name = BACKGROUNDS[int(gen.integers(len(BACKGROUNDS)))]
    photo = _photo(name)
    ph, pw = photo.shape[:2]
    ch_max = min(ph, pw * h / w)
    ch = gen.uniform(0.3, 1.0) * ch_max
    cw = ch * w / h
    ch_i, cw_i = max(1, round(ch)), max(1, round(cw))
    cw_i, ch_i = min(cw_i, pw), min(ch_i, ph)
    y0 = int(gen.integers(0, ph - ch_i + 1))
    x0 = int(gen.integers(0, pw - cw_i + 1))
    crop = photo[y0 : y0 + ch_i, x0 : x0 + cw_i]
    tile = _resize(crop, (h, w), antialias=True)
    return 0.2 + 0.6 * np.clip(tile, 0, 1), {"photo": name, "crop": (x0, y0, cw_i, ch_i)}


def random_texture(gen: np.random.Generator, w: int, h: int) -> np.ndarray:
    """An ``(h, w, 3)`` fill: a random saturated colour ``c`` modulated by one of flat,
    stripes, checker or noise, ``c (0.65 + 0.35 t)`` with the pattern ``t`` in [0, 1].

    Examples
    --------
    >>> t = random_texture(np.random.default_rng(0), 8, 6)
    >>> t.shape, bool(t.min() >= 0 and t.max() <= 1)
    ((6, 8, 3), True)
    """
    gen, w, h = _check_gen_size(gen, w, h)
    colour = gen.uniform(0.25, 1.0, 3)
    colour[int(gen.integers(3))] = gen.uniform(0.0, 0.3)  # a saturated hue
    kind = int(gen.integers(4))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    theta = gen.uniform(0, np.pi)
    period = gen.uniform(3.0, 8.0)
    if kind == 0:
        t = np.ones((h, w))
    elif kind == 1:
        t = 0.5 + 0.5 * np.sin(2 * np.pi * (xx * np.cos(theta) + yy * np.sin(theta)) / period)
    elif kind == 2:
        t = ((np.floor(xx / period) + np.floor(yy / period)) % 2).astype(np.float64)
    else:
        t = gen.uniform(0.0, 1.0, (h, w))
    return colour[None, None, :] * (0.65 + 0.35 * t[..., None])


def _bar_mask(cx: float, cy: float, length: float, thick: float, phi: float, w: int, h: int):
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    dx, dy = xx - cx, yy - cy
    qx = np.cos(phi) * dx + np.sin(phi) * dy
    qy = -np.sin(phi) * dx + np.cos(phi) * dy
    return (np.abs(qx) <= length / 2) & (np.abs(qy) <= thick / 2)


def _ellipse_mask(cx: float, cy: float, a: float, b: float, phi: float, w: int, h: int):
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    dx, dy = xx - cx, yy - cy
    qx = np.cos(phi) * dx + np.sin(phi) * dy
    qy = -np.sin(phi) * dx + np.cos(phi) * dy
    return (qx / a) ** 2 + (qy / b) ** 2 <= 1.0


def _clutter_mask(gen: np.random.Generator, w: int, h: int, s: float) -> np.ndarray:
    """A distractor: a thin bar (a line) or an elongated ellipse (aspect >= 2.5)."""
    cx, cy, phi = gen.uniform(0, w), gen.uniform(0, h), gen.uniform(0, np.pi)
    if gen.random() < 0.5:
        return _bar_mask(cx, cy, gen.uniform(0.3, 1.0) * s, gen.uniform(1.0, 3.0), phi, w, h)
    a = gen.uniform(0.08, 0.2) * s
    return _ellipse_mask(cx, cy, a, a / gen.uniform(2.5, 4.0), phi, w, h)


def _visible_ok(vis: list[np.ndarray], full_area: list[int], cover: np.ndarray, f: float) -> bool:
    return all(
        int((v & ~cover).sum()) >= max(1.0, f * a) for v, a in zip(vis, full_area, strict=True)
    )


# --------------------------------------------------------------------------- procedural


def procedural_detection_set(
    n_images: int,
    size: tuple[int, int] = (128, 128),
    classes: Sequence[str] = SHAPES,
    rng: int | np.random.Generator | None = None,
    *,
    objects_per_image: tuple[int, int] = (1, 4),
    scale: tuple[float, float] = (0.06, 0.2),
    clutter: int = 4,
    occlusion: float = 0.5,
    min_visible: float = 0.4,
) -> DetectionDataset:
    """Textured, scaled, rotated shapes on real-photo backgrounds, with clutter and
    occlusion, and exact boxes and masks of their visible parts.

    Each image is built in layers, later layers hiding earlier ones:

    1. a background: a random crop (aspect ``W/H``, 30-100 % of the largest such crop)
       of one of scikit-image's bundled photos (:data:`BACKGROUNDS`), resized
       (bilinear, antialiased) to ``size``, contrast reduced to ``0.2 + 0.6 I``;
    2. clutter: ``U{0..clutter}`` distractors (thin lines and elongated ellipses, in no
       class), textured;
    3. ``U{objects_per_image}`` objects: a class drawn uniformly from ``classes``, radius
       ``r = s min(W, H)`` with ``s ~ U(scale)``, centre uniform with the shape inside
       the image, rotation ``U(0, 2 pi)``, mask by
       :func:`~robopercept.nn.data.datasets.shape_masks`, filled with a texture (a random
       saturated colour ``c`` times ``0.65 + 0.35 t``, with ``t`` flat, stripes,
       checker or noise). A placement that would leave an earlier object with less than
       ``min_visible`` of its area visible is redrawn (20 tries, then the object is
       left out);
    4. with probability ``occlusion``, an occluding bar across a random object, under
       the same ``min_visible`` rule.

    The mask of an object is its visible pixels (its shape minus everything drawn
    later), and its box is the tight box of that mask (:func:`mask_to_box`), so an
    occluded object's box shrinks to what is seen. Pixels of an object's visible mask
    hold exactly its texture.

    Parameters
    ----------
    n_images : int
        Number of images (>= 1).
    size : (int, int)
        ``(width, height)`` (each >= 16).
    classes : sequence of str
        Distinct names from :data:`~robopercept.nn.data.datasets.SHAPES`; label ``k`` is
        ``classes[k - 1]``.
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same set.
    objects_per_image : (int, int)
        Inclusive range of the number of objects per image (0 <= low <= high <= 20).
    scale : (float, float)
        Range of the radius as a fraction of ``min(W, H)`` (within [0.03, 0.5]).
    clutter : int
        Largest number of distractors per image (0 to 50).
    occlusion : float
        Probability in [0, 1] of an occluding bar per image.
    min_visible : float
        Smallest visible fraction of an object's area, in (0, 1].

    Returns
    -------
    DetectionDataset
        With masks; ``meta[i]`` records the background ``"photo"`` and its ``"crop"``
        ``(x, y, w, h)``, whether an ``"occluder"`` bar was drawn, and ``"shapes"``,
        ``(K, 4)`` rows ``(cx, cy, r, phi)`` of each object's whole shape (before
        occlusion), in the order of the boxes.

    Examples
    --------
    >>> ds = procedural_detection_set(2, (64, 48), rng=0)
    >>> image, target = ds[0]
    >>> tuple(image.shape), ds.classes
    ((3, 48, 64), ('circle', 'square', 'triangle', 'cross'))
    """
    w, h = check_size(size, "size", 16, 4096)
    n = _check_count(n_images, (w, h))
    cls = _check_classes(classes)
    unknown = [c for c in cls if c not in SHAPES]
    if unknown:
        raise InputError(f"classes must be names from {SHAPES}; got {unknown[0]!r}")
    kinds = np.array([SHAPES.index(c) for c in cls], dtype=np.int64)
    lo, hi = _check_range(objects_per_image, "objects_per_image", 0, 20, True)
    s_lo, s_hi = _check_range(scale, "scale", 0.03, 0.5, False)
    clutter = check_int(clutter, "clutter", 0)
    if clutter > 50:
        raise InputError(f"clutter must be in [0, 50]; got {clutter}")
    occlusion = check_real(occlusion, "occlusion", 0.0, 1.0)
    min_visible = check_real(min_visible, "min_visible", 0.0, 1.0, low_inclusive=False)
    gen = as_rng(rng)
    side = min(w, h)
    images, boxes, labels, masks, meta = [], [], [], [], []
    for _ in range(n):
        canvas, info = photo_background(gen, w, h)
        for _ in range(int(gen.integers(0, clutter + 1))):
            m = _clutter_mask(gen, w, h, side)
            canvas[m] = random_texture(gen, w, h)[m]
        vis: list[np.ndarray] = []
        full: list[int] = []
        geo: list[tuple[float, float, float, float]] = []
        labs: list[int] = []
        for _ in range(int(gen.integers(lo, hi + 1))):
            for _try in range(20):
                j = int(gen.integers(len(cls)))
                r = gen.uniform(s_lo, s_hi) * side
                cx, cy = gen.uniform(r, w - r), gen.uniform(r, h - r)
                phi = gen.uniform(0, 2 * np.pi)
                m = shape_masks([kinds[j]], [cx], [cy], [r], [phi], (w, h))[0]
                if m.sum() >= 4 and _visible_ok(vis, full, m, min_visible):
                    break
            else:
                continue
            vis = [v & ~m for v in vis]
            vis.append(m)
            full.append(int(m.sum()))
            geo.append((cx, cy, r, phi))
            labs.append(j + 1)
            canvas[m] = random_texture(gen, w, h)[m]
        occluded = False
        if vis and gen.random() < occlusion:
            for _try in range(20):
                cx, cy, r, _phi = geo[int(gen.integers(len(geo)))]
                m = _bar_mask(
                    cx + gen.uniform(-r, r),
                    cy + gen.uniform(-r, r),
                    gen.uniform(1.5, 4.0) * r,
                    gen.uniform(0.25, 0.6) * r,
                    gen.uniform(0, np.pi),
                    w,
                    h,
                )
                if _visible_ok(vis, full, m, min_visible):
                    vis = [v & ~m for v in vis]
                    canvas[m] = random_texture(gen, w, h)[m]
                    occluded = True
                    break
        images.append(np.clip(canvas, 0.0, 1.0).astype(np.float32))
        boxes.append(np.array([_tight_box(v) for v in vis]).reshape(-1, 4))
        labels.append(np.array(labs, dtype=np.int64))
        masks.append(np.array(vis, dtype=bool).reshape(len(vis), h, w))
        meta.append(
            {**info, "occluder": occluded, "shapes": np.array(geo, dtype=np.float64).reshape(-1, 4)}
        )
    return DetectionDataset(images, boxes, labels, cls, masks=masks, meta=meta)


# --------------------------------------------------------------------------- digits


@functools.lru_cache(maxsize=1)
def _digits() -> tuple[np.ndarray, np.ndarray]:
    from sklearn.datasets import load_digits

    d = load_digits()
    images = (d.images / 16.0).astype(np.float64)
    images.setflags(write=False)
    return images, d.target.astype(np.int64)


def _iou(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    if not len(others):
        return np.zeros(0)
    iw = np.clip(np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]), 0, None)
    ih = np.clip(np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]), 0, None)
    inter = iw * ih
    a = (box[2] - box[0]) * (box[3] - box[1])
    b = (others[:, 2] - others[:, 0]) * (others[:, 3] - others[:, 1])
    return inter / (a + b - inter)


#: ink below this (after resizing, of a maximum of 1) is set to 0, so a digit's mask and
#: box are exactly its visible ink
INK_THRESHOLD = 0.2


def digits_detection_set(
    n_images: int,
    size: tuple[int, int] = (128, 128),
    digits_per_image: tuple[int, int] = (1, 5),
    rng: int | np.random.Generator | None = None,
    *,
    scale: tuple[int, int] = (16, 48),
    max_iou: float = 0.1,
) -> DetectionDataset:
    """Real handwritten digits (scikit-learn's ``load_digits``) placed on black canvases.

    Each canvas gets ``U{digits_per_image}`` digits. A digit is a random one of the 1797
    8 x 8 images (values ``v / 16``), resized bilinearly to ``s x s`` with
    ``s ~ U{scale}``, with values below :data:`INK_THRESHOLD` set to 0; it is placed
    at a uniform position inside the canvas, and the canvas keeps the pixel-wise
    maximum of the digits (ink adds as on paper). Its mask is its non-zero pixels and
    its box the tight box of that mask (:func:`mask_to_box`). A placement whose box has
    IoU above ``max_iou`` with an earlier digit's box is redrawn (50 tries, then the
    digit is left out, so a crowded canvas can hold fewer). Label ``d + 1`` is digit
    ``d`` (:data:`DIGIT_CLASSES`). The objects are real, their layout generated.

    Parameters
    ----------
    n_images : int
        Number of canvases (>= 1).
    size : (int, int)
        ``(width, height)`` (each >= 8).
    digits_per_image : (int, int)
        Inclusive range of digits per canvas (0 <= low <= high <= 50).
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same set.
    scale : (int, int)
        Inclusive range of the digit side in pixels (8 <= low <= high <= min(W, H)).
    max_iou : float
        Largest IoU between two digits' boxes, in [0, 1].

    Returns
    -------
    DetectionDataset
        With masks; ``meta[i]["digit_index"]`` gives each object's index into
        ``load_digits()``, ``meta[i]["side"]`` its side ``s``, ``meta[i]["origin"]`` the
        top-left corner ``(x, y)`` of its ``s x s`` square.

    Examples
    --------
    >>> ds = digits_detection_set(3, (64, 64), (2, 2), rng=0)
    >>> [len(b) for b in ds.boxes], ds.classes[:3]
    ([2, 2, 2], ('0', '1', '2'))
    """
    w, h = check_size(size, "size", 8, 4096)
    n = _check_count(n_images, (w, h))
    lo, hi = _check_range(digits_per_image, "digits_per_image", 0, 50, True)
    s_lo, s_hi = _check_range(scale, "scale", 8, min(w, h), True)
    max_iou = check_real(max_iou, "max_iou", 0.0, 1.0)
    gen = as_rng(rng)
    digits, targets = _digits()
    glyph_cache: dict[tuple[int, int], np.ndarray] = {}
    images, boxes, labels, masks, meta = [], [], [], [], []
    for _ in range(n):
        canvas = np.zeros((h, w), dtype=np.float64)
        bxs: list[np.ndarray] = []
        ms: list[np.ndarray] = []
        labs, idxs, sides, origins = [], [], [], []
        for _ in range(int(gen.integers(lo, hi + 1))):
            for _try in range(50):
                idx = int(gen.integers(len(digits)))
                s = int(gen.integers(s_lo, s_hi + 1))
                x, y = int(gen.integers(0, w - s + 1)), int(gen.integers(0, h - s + 1))
                key = (idx, s)
                if key not in glyph_cache:
                    g = _resize(digits[idx], (s, s), antialias=False)
                    glyph_cache[key] = np.where(g >= INK_THRESHOLD, g, 0.0)
                glyph = glyph_cache[key]
                box = _tight_box(glyph > 0) + np.array([x, y, x, y], dtype=np.float64)
                if not bxs or _iou(box, np.array(bxs)).max() <= max_iou:
                    break
            else:
                continue
            m = np.zeros((h, w), dtype=bool)
            m[y : y + s, x : x + s] = glyph > 0
            region = canvas[y : y + s, x : x + s]
            np.maximum(region, glyph, out=region)
            bxs.append(box)
            ms.append(m)
            labs.append(int(targets[idx]) + 1)
            idxs.append(idx)
            sides.append(s)
            origins.append((x, y))
        images.append(np.repeat(canvas[..., None], 3, axis=2).astype(np.float32))
        boxes.append(np.array(bxs).reshape(-1, 4))
        labels.append(np.array(labs, dtype=np.int64))
        masks.append(np.array(ms, dtype=bool).reshape(len(ms), h, w))
        meta.append(
            {"digit_index": np.array(idxs, dtype=np.int64), "side": sides, "origin": origins}
        )
    return DetectionDataset(images, boxes, labels, DIGIT_CLASSES, masks=masks, meta=meta)


def single_digit_set(
    n_images: int,
    size: tuple[int, int] = (64, 64),
    rng: int | np.random.Generator | None = None,
    *,
    scale: tuple[int, int] = (16, 48),
) -> DetectionDataset:
    """Exactly one real digit per canvas: :func:`digits_detection_set` with
    ``digits_per_image=(1, 1)``, for single-object localisation (class + one box).

    Examples
    --------
    >>> ds = single_digit_set(4, rng=0)
    >>> [len(b) for b in ds.boxes]
    [1, 1, 1, 1]
    """
    return digits_detection_set(n_images, size, (1, 1), rng, scale=scale)


# --------------------------------------------------------------------------- DeepForest


@dataclass(frozen=True, eq=False)
class DeepForestTiles:
    """The DeepForest tree crowns as training and test sets (:func:`deepforest_tiles`).

    Attributes
    ----------
    train, test : DetectionDataset
        Tiles of the YELL crop2 image above the held-out strip, and tiles of the strip.
    cross : dict of str to DetectionDataset
        Each other image whole (one image per set), by file stem: cross-image tests.
    strip_top : int
        First row of the held-out strip.
    tile : int
    min_area_fraction : float
    n_source_boxes : int
        Boxes in the YELL crop2 file (574).
    n_dropped : int
        Box pieces dropped because less than ``min_area_fraction`` of the box fell in
        a tile.
    """

    train: DetectionDataset
    test: DetectionDataset
    cross: dict[str, DetectionDataset] = field(default_factory=dict)
    strip_top: int = 0
    tile: int = 400
    min_area_fraction: float = 0.5
    n_source_boxes: int = 0
    n_dropped: int = 0


def _read_deepforest(folder: Any, stem: str) -> tuple[np.ndarray, np.ndarray]:
    voc = read_voc_xml(folder / f"{stem}.xml")
    image = read_image(folder / f"{stem}.png", mode="rgb")
    if image.shape[:2] != (voc.height, voc.width):
        raise InputError(
            f"{folder / stem}.png is {image.shape[1]} x {image.shape[0]} but its XML says "
            f"{voc.width} x {voc.height}: the files do not belong together"
        )
    boxes = np.array([o.bbox for o in voc.objects], dtype=np.float64).reshape(-1, 4)
    scale = 65535.0 if image.dtype == np.uint16 else 255.0
    return (image.astype(np.float32) / np.float32(scale)), boxes


def deepforest_tiles(
    folder: str | os.PathLike[str],
    tile: int = 400,
    *,
    test_fraction: float = 0.2,
    min_area_fraction: float = 0.5,
) -> DeepForestTiles:
    """Real aerial tree crowns (DeepForest NEON, Pascal-VOC boxes) as tiles with a
    held-out spatial strip, plus the other images as cross-image tests.

    The YELL crop2 image (``W x H`` = 2299 x 2472, 574 boxes) is split at row
    ``strip_top = H - ceil(test_fraction H)``: the held-out strip (rows
    ``y >= strip_top``) is the test region, the rows above it the training region. Each
    region is cut into a grid of ``tile x tile`` tiles from its own top-left corner
    (tiles in the last column and row are smaller where the region ends; tiles do not
    overlap, and no tile spans both regions, so no training pixel lies in the strip).
    Each VOC box ``b = (x_1, y_1, x_2, y_2)`` (continuous, as
    :func:`~robopercept.nn.coco.formats.voc_to_coco`) is clipped to every tile ``T`` it meets,
    shifted into tile coordinates, and kept when

    .. math::

        |b \\cap T| \\ge \\texttt{min\\_area\\_fraction} \\cdot |b|,\\qquad |b \\cap T| > 0,

    so a crown split by a tile border survives in the tile holding at least that
    fraction of it (with the default 0.5, the larger piece of a box cut in two; a box
    cut into four near a tile corner may keep no piece). ``n_dropped`` counts the
    pieces left out.
    The other three images (YELL crop, OSBS_029, SOAP_061) are returned whole; every
    class (``Tree``; ``Alive`` and ``Dead`` in SOAP_061) is one class ``"Tree"``.

    Parameters
    ----------
    folder : path-like
        The ``deepforest_neon`` folder (``../shared/data/detection/deepforest_neon``).
    tile : int
        Tile side in pixels (64 to 2472).
    test_fraction : float
        Height of the held-out strip as a fraction of the image height, in (0, 1).
    min_area_fraction : float
        Smallest fraction of a box's area that must fall in a tile, in (0, 1].

    Returns
    -------
    DeepForestTiles

    Raises
    ------
    InputError
        The folder does not exist, or a parameter is out of range.
    FileFormatError
        A file is missing or malformed.
    """
    path = as_path(folder, "folder")
    if not path.is_dir():
        raise InputError(
            f"DeepForest folder {str(path)!r} does not exist or is not a folder: pass the "
            "deepforest_neon folder (e.g. ../shared/data/detection/deepforest_neon) that "
            f"holds {DEEPFOREST_IMAGES[0]}.png/.xml"
        )
    tile = check_int(tile, "tile", 64)
    if tile > 2472:
        raise InputError(f"tile must be in [64, 2472] pixels; got {tile}")
    test_fraction = check_real(
        test_fraction, "test_fraction", 0.0, 1.0, low_inclusive=False, high_inclusive=False
    )
    frac = check_real(min_area_fraction, "min_area_fraction", 0.0, 1.0, low_inclusive=False)
    stem = DEEPFOREST_IMAGES[0]
    image, src = _read_deepforest(path, stem)
    h, w = image.shape[:2]
    strip_top = h - math.ceil(test_fraction * h)
    area = (src[:, 2] - src[:, 0]) * (src[:, 3] - src[:, 1])
    parts: dict[bool, dict[str, list[Any]]] = {
        t: {"images": [], "boxes": [], "names": [], "meta": []} for t in (False, True)
    }
    dropped = 0
    for is_test, top, bottom in ((False, 0, strip_top), (True, strip_top, h)):
        for y in range(top, bottom, tile):
            for x in range(0, w, tile):
                tw, th = min(tile, w - x), min(tile, bottom - y)
                ix = np.minimum(src[:, 2], x + tw) - np.maximum(src[:, 0], x)
                iy = np.minimum(src[:, 3], y + th) - np.maximum(src[:, 1], y)
                meets = (ix > 0) & (iy > 0)
                inter = np.where(meets, ix * iy, 0.0)
                keep = meets & (inter >= frac * area)
                dropped += int((meets & ~keep).sum())
                b = src[keep].copy()
                b[:, [0, 2]] = np.clip(b[:, [0, 2]], x, x + tw) - x
                b[:, [1, 3]] = np.clip(b[:, [1, 3]], y, y + th) - y
                p = parts[is_test]
                p["images"].append(image[y : y + th, x : x + tw])
                p["boxes"].append(b)
                p["names"].append(f"{stem}_x{x}_y{y}.png")
                p["meta"].append({"source": stem, "origin": (x, y)})
    sets = {}
    next_id = 1
    for t in (False, True):
        p = parts[t]
        k = len(p["images"])
        sets[t] = DetectionDataset(
            p["images"],
            p["boxes"],
            [np.ones(len(b), dtype=np.int64) for b in p["boxes"]],
            ("Tree",),
            image_ids=list(range(next_id, next_id + k)),
            file_names=p["names"],
            meta=p["meta"],
        )
        next_id += k
    cross = {}
    for other in DEEPFOREST_IMAGES[1:]:
        im, b = _read_deepforest(path, other)
        cross[other] = DetectionDataset(
            [im],
            [b],
            [np.ones(len(b), dtype=np.int64)],
            ("Tree",),
            file_names=[f"{other}.png"],
            meta=[{"source": other, "origin": (0, 0)}],
        )
    return DeepForestTiles(sets[False], sets[True], cross, strip_top, tile, frac, len(src), dropped)


# --------------------------------------------------------------------------- pictures


def draw_detections(
    image: np.ndarray,
    boxes: npt.ArrayLike,
    labels: npt.ArrayLike | None = None,
    classes: Sequence[str] | None = None,
    *,
    scores: npt.ArrayLike | None = None,
    masks: npt.ArrayLike | None = None,
    width: int = 1,
) -> np.ndarray:
    """Draw ``xyxy`` boxes (and masks), coloured and captioned by class.

    Box ``(x_1, y_1, x_2, y_2)`` is outlined on its edge pixels, columns ``x_1`` to
    ``x_2 - 1`` (:func:`~robopercept.viz.draw.draw_boxes` of ``(x_1, y_1, x_2 - x_1,
    y_2 - y_1)``); the caption is ``classes[label - 1]`` (or the label), followed by the
    score when given. Masks are blended at 40 % in the class colour
    (:func:`~robopercept.viz.colormap.label_colors`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1].
    boxes : (K, 4) array_like
    labels : (K,) int array_like, optional
        1-based (default: all 1).
    classes : sequence of str, optional
    scores : (K,) array_like, optional
    masks : (K, H, W) array_like, optional
    width : int
        Outline width.

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Examples
    --------
    >>> out = draw_detections(np.zeros((32, 32)), [[4, 16, 12, 28]], [1], ["x"])
    >>> out.shape, bool(out[16, 4].any()), bool(out[27, 11].any()), bool(out[22, 8].any())
    ((32, 32, 3), True, True, False)
    """
    out = to_rgb8(image) if isinstance(image, np.ndarray) else None
    if out is None:
        raise InputError(f"image must be a numpy array; got {type(image).__name__}")
    b = check_numeric(boxes, "boxes")
    if b.size == 0:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError(f"boxes must be (K, 4) xyxy; got shape {b.shape}")
    k = len(b)
    if labels is None:
        lab = np.ones(k, dtype=np.int64)
    else:
        lab = _check_labels(labels, "labels", k, 1 << 30)
    names = None if classes is None else _check_classes(classes)
    sc = None
    if scores is not None:
        sc = check_numeric(scores, "scores").reshape(-1)
        if sc.size != k:
            raise InputError(f"scores must have one value per box ({k}); got {sc.size}")
    if masks is not None:
        m = _check_masks(masks, "masks", k, out.shape[:2])
    colors = label_colors(lab)
    for j in range(k):
        if masks is not None:
            out = draw_mask(out, m[j], color=tuple(int(c) for c in colors[j]), alpha=0.4)
    for j in range(k):
        name = str(lab[j])
        if names is not None and lab[j] <= len(names):
            name = names[lab[j] - 1]
        caption = name if sc is None else f"{name} {sc[j]:.2f}"
        x1, y1, x2, y2 = b[j]
        out = draw_boxes(
            out,
            np.array([[x1, y1, x2 - x1, y2 - y1]]),
            color=tuple(int(c) for c in colors[j]),
            width=width,
            labels=[caption],
        )
    return out


def samples_picture(
    dataset: DetectionDataset,
    indices: npt.ArrayLike | None = None,
    *,
    columns: int = 4,
    show_masks: bool = True,
) -> np.ndarray:
    """A grid of images of ``dataset`` with their boxes, labels (and masks) drawn.

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
    >>> samples_picture(single_digit_set(3, (32, 32), rng=0, scale=(8, 16))).shape
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
    hmax = max(dataset.images[i].shape[0] for i in sel)
    wmax = max(dataset.images[i].shape[1] for i in sel)
    cols = min(columns, len(sel))
    rows = -(-len(sel) // cols)
    gap = 2
    pw, ph = check_picture_size(cols * (wmax + gap) - gap, rows * (hmax + gap) - gap)
    out = np.full((ph, pw, 3), 255, dtype=np.uint8)
    for n, i in enumerate(sel):
        im = dataset.images[i]
        pic = draw_detections(
            im,
            dataset.boxes[i],
            dataset.labels[i],
            dataset.classes,
            masks=dataset.masks[i] if show and dataset.masks is not None else None,
        )
        r, c = divmod(n, cols)
        y, x = r * (hmax + gap), c * (wmax + gap)
        out[y : y + im.shape[0], x : x + im.shape[1]] = pic
    return out


def _indices(indices: npt.ArrayLike, n: int) -> np.ndarray:
    """``indices`` as int64 in [0, n) (negative ones count from the end)."""
    idx = check_numeric(indices, "indices").reshape(-1)
    if np.any(idx != np.floor(idx)) or np.any((idx < -n) | (idx >= n)):
        raise InputError(f"indices must be integers in [-{n}, {n}); got {plain_repr(indices)}")
    return idx.astype(np.int64) % n
