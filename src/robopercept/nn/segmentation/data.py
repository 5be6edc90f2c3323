"""Segmentation data with ground truth: the real fluorescence nuclei image, split into
quadrants for training and a held-out test, and the built-in sets by name (the shapes
and digits are the detection sets of :mod:`robopercept.nn.detection.synthetic`, whose
masks give the class maps).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_int, check_real
from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import read_image
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.synthetic import digits_detection_set, procedural_detection_set

__all__ = [
    "BUILTIN_SEGMENTATION_DATA",
    "NucleiSplit",
    "SegmentationSets",
    "nuclei_quadrants",
    "percentile_normalize",
    "segmentation_sets",
]

#: the files of the nuclei folder (StarDist's sample)
NUCLEI_FILES = ("img2d.tif", "mask2d.tif")
#: what the nuclei folder is and holds, for messages: the sample that the ``stardist``
#: package ships (``stardist/data/images/``)
NUCLEI_FOLDER = (
    "a folder holding the StarDist nuclei sample: img2d.tif (a 512 x 512 fluorescence "
    "image of the 2018 Data Science Bowl, BBBC038) and mask2d.tif (its instance labels), "
    "as the stardist package ships them in stardist/data/images/"
)


def percentile_normalize(
    image: np.ndarray, low: float = 1.0, high: float = 99.8, reference: np.ndarray | None = None
) -> np.ndarray:
    r"""``(x - p_{low}) / (p_{high} - p_{low})`` as float32, the percentiles taken over
    ``reference`` (``image`` itself by default): the normalisation of fluorescence
    images in StarDist and CSBDeep (``csbdeep.utils.normalize``), not clipped.

    Raises
    ------
    InputError
        Percentiles outside ``0 <= low < high <= 100``, or a constant reference.

    Examples
    --------
    >>> percentile_normalize(np.arange(11.0), 0, 100).tolist()[:3]
    [0.0, 0.10000000149011612, 0.20000000298023224]
    """
    lo = check_real(low, "low", 0.0, 100.0)
    hi = check_real(high, "high", 0.0, 100.0)
    if not lo < hi:
        raise InputError(f"low must be below high; got {lo} and {hi}")
    x = np.asarray(image, dtype=np.float64)
    ref = x if reference is None else np.asarray(reference, dtype=np.float64)
    if ref.size == 0 or not np.isfinite(ref).all() or not np.isfinite(x).all():
        raise InputError("image and reference must be non-empty and finite")
    p_lo, p_hi = np.percentile(ref, [lo, hi])
    if p_hi <= p_lo:
        raise InputError(
            f"the {lo}th and {hi}th percentiles are equal ({p_lo:g}): the reference is "
            "(nearly) constant, nothing to normalise"
        )
    return ((x - p_lo) / (p_hi - p_lo)).astype(np.float32)


@dataclass(frozen=True)
class NucleiSplit:
    """Quadrant tiles of the nuclei image for training and the held-out one.

    Attributes
    ----------
    train_images : (3, h, w, 1) float32
        The three training quadrants, normalised by :func:`percentile_normalize` with
        the percentiles of the training quadrants only.
    train_instances : (3, h, w) int32
        Instance labels (0 background, 1.. the nuclei; a nucleus cut by a quadrant
        border appears in both tiles).
    test_image : (h, w, 1) float32
        The held-out quadrant, normalised with the training percentiles.
    test_instances : (h, w) int32
    quadrant : int
        Which quadrant is held out: 0 top left, 1 top right, 2 bottom left, 3 bottom
        right.
    """

    train_images: np.ndarray
    train_instances: np.ndarray
    test_image: np.ndarray
    test_instances: np.ndarray
    quadrant: int

    @property
    def train_masks(self) -> np.ndarray:
        """Foreground (1) and background (0) of the training tiles, int64."""
        return (self.train_instances > 0).astype(np.int64)

    @property
    def test_mask(self) -> np.ndarray:
        """Foreground (1) and background (0) of the held-out tile, int64."""
        return (self.test_instances > 0).astype(np.int64)


def nuclei_quadrants(folder: str | os.PathLike[str], test_quadrant: int = 3) -> NucleiSplit:
    """The real fluorescence nuclei of StarDist's sample (``img2d.tif``, a 512 x 512
    uint16 image of the 2018 Data Science Bowl, and ``mask2d.tif``, its instance labels,
    125 nuclei; the ``stardist`` package ships both in ``stardist/data/images/``) cut into
    four 256 x 256 quadrants: three to train on, one held out.

    Parameters
    ----------
    folder : path-like
        A folder holding ``img2d.tif`` and ``mask2d.tif`` (:data:`NUCLEI_FILES`).
    test_quadrant : int
        0 top left, 1 top right, 2 bottom left, 3 bottom right (the default).

    Returns
    -------
    NucleiSplit

    Raises
    ------
    InputError
        The folder does not exist, or ``test_quadrant`` is not 0..3.
    FileFormatError
        A file is missing or not a 2-D image, or the two differ in size.
    """
    path = as_path(folder, "folder")
    if not path.is_dir():
        raise InputError(f"nuclei folder {str(path)!r} does not exist: pass {NUCLEI_FOLDER}")
    q = check_int(test_quadrant, "test_quadrant", 0)
    if q > 3:
        raise InputError(f"test_quadrant must be 0..3; got {q}")
    image = read_image(path / NUCLEI_FILES[0])
    labels = read_image(path / NUCLEI_FILES[1])
    if image.ndim != 2 or labels.ndim != 2 or image.shape != labels.shape:
        raise FileFormatError(
            f"{path}: img2d.tif and mask2d.tif must be 2-D images of one size; got "
            f"{image.shape} and {labels.shape}"
        )
    h, w = image.shape
    hh, hw = h // 2, w // 2
    corners = [(0, 0), (0, hw), (hh, 0), (hh, hw)]
    tiles = [(image[y : y + hh, x : x + hw], labels[y : y + hh, x : x + hw]) for y, x in corners]
    train = [t for k, t in enumerate(tiles) if k != q]
    ref = np.stack([t[0] for t in train])
    norm = [percentile_normalize(t[0], reference=ref)[..., None] for t in tiles]
    return NucleiSplit(
        np.stack([norm[k] for k in range(4) if k != q]),
        np.stack([t[1] for t in train]).astype(np.int32),
        norm[q],
        tiles[q][1].astype(np.int32),
        q,
    )


#: the built-in data of ``robopercept nn segment train --data``
BUILTIN_SEGMENTATION_DATA = ("shapes", "digits", "nuclei")


@dataclass(frozen=True)
class SegmentationSets:
    """Training and validation images with instance masks (and so class maps), as
    :class:`~robopercept.nn.detection.data.DetectionDataset` objects.

    Attributes
    ----------
    train, val : DetectionDataset
        With ``masks``; :meth:`~robopercept.nn.detection.data.DetectionDataset.class_maps`
        gives their semantic labels.
    classes : tuple of str
        The names of labels 1..K (0 is the background).
    source : dict
        The arguments that made the sets (``data``, ``images``, ``size`` as
        ``[width, height]``, ``seed``; what a trained model records beside its
        weights); empty for sets built otherwise.
    """

    train: Any
    val: Any
    classes: tuple[str, ...]
    source: dict[str, Any] = field(default_factory=dict, compare=False)


def segmentation_sets(
    data: str,
    n_images: int = 200,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    folder: str | os.PathLike[str] | None = None,
    val_fraction: float = 0.2,
) -> SegmentationSets:
    """The built-in segmentation data by name (:data:`BUILTIN_SEGMENTATION_DATA`).

    * ``"shapes"``: :func:`~robopercept.nn.detection.synthetic.procedural_detection_set`
      (``n_images`` canvases of ``size`` = (width, height), seeded), split
      ``1 - val_fraction`` / ``val_fraction``;
    * ``"digits"``: the real-digit canvases of
      :func:`~robopercept.nn.detection.synthetic.digits_detection_set` with their stroke
      masks, split the same way;
    * ``"nuclei"``: the real fluorescence nuclei in ``folder``
      (:func:`nuclei_quadrants`): the three training quadrants and the held-out one as
      the validation set, grey repeated to RGB and clipped to [0, 1]
      (``n_images``, ``size`` and ``seed`` do not apply).

    Raises
    ------
    InputError
        Unknown name, fewer than 2 images to split, or ``"nuclei"`` without its folder.
    """
    if data not in BUILTIN_SEGMENTATION_DATA:
        raise InputError(
            f"data must be one of {', '.join(BUILTIN_SEGMENTATION_DATA)}; got {data!r}"
        )
    if data == "nuclei":
        if folder is None:
            raise InputError(f"the nuclei data needs its folder (folder=): {NUCLEI_FOLDER}")
        s = nuclei_quadrants(folder)
        train = DetectionDataset.from_instance_labels(
            list(np.clip(s.train_images, 0, 1)), list(s.train_instances), "nucleus"
        )
        val = DetectionDataset.from_instance_labels(
            [np.clip(s.test_image, 0, 1)], [s.test_instances], "nucleus"
        )
        given = list(size) if isinstance(size, (tuple, list)) else size
        source = {"data": data, "images": n_images, "size": given, "seed": seed}
        return SegmentationSets(train, val, tuple(train.classes), source)
    n = check_int(n_images, "n_images", 2)
    frac = check_real(
        val_fraction, "val_fraction", 0.0, 1.0, low_inclusive=False, high_inclusive=False
    )
    make = procedural_detection_set if data == "shapes" else digits_detection_set
    ds = make(n, size, rng=seed)
    train, val = ds.split((1 - frac, frac), rng=seed)
    source = {"data": data, "images": n, "size": list(size), "seed": seed}
    return SegmentationSets(train, val, tuple(ds.classes), source)
