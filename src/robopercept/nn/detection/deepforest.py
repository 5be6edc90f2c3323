r"""Real aerial tree crowns as detection sets: the DeepForest NEON images (Pascal-VOC
boxes) cut into tiles, with a held-out spatial strip and the other images as
cross-image tests (:func:`deepforest_tiles`, :class:`DeepForestTiles`).

The YELL crop2 image (:data:`DEEPFOREST_IMAGES`, the first) is cut into tiles, a
held-out bottom strip of it is the test set, and the other three images are
cross-image test sets; every set is a
:class:`~robopercept.nn.detection.data.DetectionDataset` of one class, ``"Tree"``, with
boxes ``xyxy`` in the box convention of :mod:`robopercept.nn.detection.data`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_int, check_real
from robopercept.errors import InputError
from robopercept.imaging.io import read_image
from robopercept.nn.coco.voc import read_voc_xml
from robopercept.nn.detection.data import DetectionDataset

__all__ = ["DEEPFOREST_IMAGES", "DeepForestTiles", "deepforest_strip", "deepforest_tiles"]

#: the four DeepForest NEON images (file stems); the first is the one cut into tiles
DEEPFOREST_IMAGES = (
    "2019_YELL_2_528000_4978000_image_crop2",
    "2019_YELL_2_541000_4977000_image_crop",
    "OSBS_029",
    "SOAP_061",
)
#: what the DeepForest folder is and holds, for messages: the NEON sample that the
#: ``deepforest`` package ships (``deepforest/data/``)
DEEPFOREST_FOLDER = (
    "a folder holding the DeepForest NEON tree-crown sample: the .png image and its "
    f"Pascal-VOC .xml boxes for each of {', '.join(DEEPFOREST_IMAGES)}, as the deepforest "
    "package ships them in deepforest/data/"
)


@dataclass(frozen=True, eq=False)
class DeepForestTiles:
    """The DeepForest tree crowns as training and test sets (:func:`deepforest_tiles`).

    Attributes
    ----------
    train, test : DetectionDataset
        Tiles of the YELL crop2 image above the held-out strip (then those of the
        ``train_extra`` images), and tiles of the strip.
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


def _check_folder(folder: Any) -> Any:
    path = as_path(folder, "folder")
    if not path.is_dir():
        raise InputError(
            f"DeepForest folder {str(path)!r} does not exist or is not a folder: pass "
            f"{DEEPFOREST_FOLDER}"
        )
    return path


def _strip_top(height: int, test_fraction: Any) -> int:
    test_fraction = check_real(
        test_fraction, "test_fraction", 0.0, 1.0, low_inclusive=False, high_inclusive=False
    )
    return height - math.ceil(test_fraction * height)


def _clip_boxes(
    src: np.ndarray, x: int, y: int, tw: int, th: int, frac: float
) -> tuple[np.ndarray, int]:
    """The boxes of ``src`` kept in the window ``(x, y, tw, th)`` (at least ``frac`` of
    their area inside), clipped and shifted to window coordinates; and the pieces
    dropped."""
    area = (src[:, 2] - src[:, 0]) * (src[:, 3] - src[:, 1])
    ix = np.minimum(src[:, 2], x + tw) - np.maximum(src[:, 0], x)
    iy = np.minimum(src[:, 3], y + th) - np.maximum(src[:, 1], y)
    meets = (ix > 0) & (iy > 0)
    inter = np.where(meets, ix * iy, 0.0)
    keep = meets & (inter >= frac * area)
    b = src[keep].copy()
    b[:, [0, 2]] = np.clip(b[:, [0, 2]], x, x + tw) - x
    b[:, [1, 3]] = np.clip(b[:, [1, 3]], y, y + th) - y
    return b, int((meets & ~keep).sum())


def deepforest_strip(
    folder: str | os.PathLike[str],
    *,
    test_fraction: float = 0.2,
    min_area_fraction: float = 0.5,
) -> DetectionDataset:
    """The held-out strip of YELL crop2 as one image (2299 x 495 with the defaults):
    the region :func:`deepforest_tiles` tests on, not cut into tiles, with its VOC boxes
    kept and clipped by the same rule (at least ``min_area_fraction`` of a box inside
    the strip).

    Parameters
    ----------
    folder : path-like
        A folder holding the DeepForest NEON images and their Pascal-VOC boxes
        (:data:`DEEPFOREST_IMAGES`).
    test_fraction : float
        Height of the strip as a fraction of the image height, in (0, 1).
    min_area_fraction : float
        Smallest fraction of a box's area inside the strip, in (0, 1].

    Returns
    -------
    DetectionDataset
        One image (float32 RGB in [0, 1]), class ``"Tree"``, ``meta`` giving the
        strip's origin in the source image.

    Raises
    ------
    InputError
        No such folder or a parameter out of range.
    FileFormatError
        A missing or malformed file.
    """
    path = _check_folder(folder)
    frac = check_real(min_area_fraction, "min_area_fraction", 0.0, 1.0, low_inclusive=False)
    stem = DEEPFOREST_IMAGES[0]
    image, src = _read_deepforest(path, stem)
    h, w = image.shape[:2]
    top = _strip_top(h, test_fraction)
    b, _ = _clip_boxes(src, 0, top, w, h - top, frac)
    return DetectionDataset(
        [image[top:]],
        [b],
        [np.ones(len(b), dtype=np.int64)],
        ("Tree",),
        file_names=[f"{stem}_strip_y{top}.png"],
        meta=[{"source": stem, "origin": (0, top)}],
    )


def deepforest_tiles(
    folder: str | os.PathLike[str],
    tile: int = 400,
    *,
    test_fraction: float = 0.2,
    min_area_fraction: float = 0.5,
    train_extra: tuple[str, ...] = (),
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
    :func:`~robopercept.nn.coco.voc.voc_to_coco`) is clipped to every tile ``T`` it meets,
    shifted into tile coordinates, and kept when

    .. math::

        |b \\cap T| \\ge \\texttt{min\\_area\\_fraction} \\cdot |b|,\\qquad |b \\cap T| > 0,

    so a crown split by a tile border survives in the tile holding at least that
    fraction of it (with the default 0.5, the larger piece of a box cut in two; a box
    cut into four near a tile corner may keep no piece). ``n_dropped`` counts the
    pieces left out.
    The other three images (YELL crop, OSBS_029, SOAP_061) are returned whole; every
    class (``Tree``; ``Alive`` and ``Dead`` in SOAP_061) is one class ``"Tree"``. An
    image named in ``train_extra`` is instead cut into tiles the same way (whole, from
    its top-left corner) and added to the training set after the YELL crop2 tiles.

    Parameters
    ----------
    folder : path-like
        A folder holding the DeepForest NEON images and their Pascal-VOC boxes
        (``<stem>.png`` and ``<stem>.xml`` for each stem of :data:`DEEPFOREST_IMAGES`,
        as the ``deepforest`` package ships them in ``deepforest/data/``).
    tile : int
        Tile side in pixels (64 to 2472).
    test_fraction : float
        Height of the held-out strip as a fraction of the image height, in (0, 1).
    min_area_fraction : float
        Smallest fraction of a box's area that must fall in a tile, in (0, 1].
    train_extra : tuple of str
        Stems of the other images (of ``DEEPFOREST_IMAGES[1:]``) to train on too, for
        example ``("2019_YELL_2_541000_4977000_image_crop",)``: the same site as the
        strip, 13 km away.

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
    path = _check_folder(folder)
    tile = check_int(tile, "tile", 64)
    if tile > 2472:
        raise InputError(f"tile must be in [64, 2472] pixels; got {tile}")
    frac = check_real(min_area_fraction, "min_area_fraction", 0.0, 1.0, low_inclusive=False)
    if not isinstance(train_extra, (tuple, list)):
        raise InputError(
            f"train_extra must be a tuple of DeepForest image stems (of "
            f"{DEEPFOREST_IMAGES[1:]}); got {type(train_extra).__name__}"
        )
    extra = tuple(train_extra)
    if any(e not in DEEPFOREST_IMAGES[1:] for e in extra) or len(set(extra)) < len(extra):
        raise InputError(
            f"train_extra must name other DeepForest images, each once, of "
            f"{DEEPFOREST_IMAGES[1:]}; got {extra!r}"
        )
    stem = DEEPFOREST_IMAGES[0]
    image, src = _read_deepforest(path, stem)
    h = image.shape[0]
    strip_top = _strip_top(h, test_fraction)
    parts: dict[bool, dict[str, list[Any]]] = {
        t: {"images": [], "boxes": [], "names": [], "meta": []} for t in (False, True)
    }
    dropped = 0
    regions = [(stem, image, src, False, 0, strip_top), (stem, image, src, True, strip_top, h)]
    for other in extra:
        im, b = _read_deepforest(path, other)
        regions.append((other, im, b, False, 0, im.shape[0]))
    for name, im, boxes, is_test, top, bottom in regions:
        width = im.shape[1]
        for y in range(top, bottom, tile):
            for x in range(0, width, tile):
                tw, th = min(tile, width - x), min(tile, bottom - y)
                b, n = _clip_boxes(boxes, x, y, tw, th, frac)
                dropped += n
                p = parts[is_test]
                p["images"].append(im[y : y + th, x : x + tw])
                p["boxes"].append(b)
                p["names"].append(f"{name}_x{x}_y{y}.png")
                p["meta"].append({"source": name, "origin": (x, y)})
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
        if other in extra:
            continue
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
