"""Datasets, splits and normalization statistics for the networks of :mod:`robopercept.nn`
(torch).

A dataset here is a set of images ``(N, C, H, W)`` float32 in [0, 1] with integer labels
``(N,)`` in ``0 .. K-1`` and class names ``(K,)``. :class:`ArrayDataset` holds them in
memory and serves ``(image, label)`` pairs, ``image`` a ``(C, H, W)`` float32 tensor and
``label`` an int, as ``torch.utils.data.DataLoader`` expects (the contract of
``torch.utils.data.Dataset``: ``__len__`` and ``__getitem__``).

Sources of real data that work offline:

- :func:`load_digits`: scikit-learn's 1,797 handwritten digits, 8 x 8, values 0..16
  divided by 16.
- :func:`load_lfw_subset`: scikit-image's ``lfw_subset``, 200 images of 25 x 25 pixels,
  the first 100 faces and the next 100 non-faces (scikit-image's docstring); label 1 is
  ``face``.
- :class:`ImageFolder`: the torchvision layout ``root/class_name/*.png``, classes sorted
  by name, pixels divided by the file's maximum (255 for 8-bit, 65535 for 16-bit).
- :func:`shapes_dataset`: procedural circles, squares, triangles and crosses (for
  pretraining and tests).

The course's data steps: :func:`stratified_split` (train / validation / test with the
class proportions kept) and :func:`normalization_stats` (per-channel mean and standard
deviation from the training split only, then
:class:`~robopercept.nn.data.augment.Normalize`). The augmentations a dataset's
``transform`` may apply are in :mod:`robopercept.nn.data.augment`.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F

from robopercept._checks import (
    as_path,
    as_rng,
    check_bool,
    check_choice,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_numeric,
    check_real,
    check_size,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.imaging.io import IMAGE_EXTENSIONS as _IMAGE_EXTENSIONS
from robopercept.imaging.io import read_image
from robopercept.nn._guards import MAX_BYTES, check_allocation
from robopercept.nn.data.augment import Transform

__all__ = [
    "IMAGE_EXTENSIONS",
    "SHAPES",
    "ArrayDataset",
    "ImageFolder",
    "load_digits",
    "load_lfw_subset",
    "normalization_stats",
    "shape_masks",
    "shapes_dataset",
    "stratified_split",
    "to_unit_float",
]

#: file extensions :class:`ImageFolder` reads (lower case)
IMAGE_EXTENSIONS = _IMAGE_EXTENSIONS

# --------------------------------------------------------------------------- datasets


def _check_transform(transform: object) -> Transform | None:
    """``transform`` if it is None or callable."""
    if transform is not None and not callable(transform):
        raise InputError(
            "transform must be a callable Tensor -> Tensor (e.g. RandomFlip()) or None; "
            f"got {type(transform).__name__} {transform!r}"[:200]
        )
    return transform


def _check_images(images: npt.ArrayLike) -> np.ndarray:
    """``images`` as float32 ``(N, C, H, W)``: gray ``(N, H, W)`` gets ``C = 1``."""
    if isinstance(images, torch.Tensor):
        images = images.detach().cpu().numpy()
    arr = check_ndim(images, "images", (2, 3, 4))
    if arr.ndim == 3:
        arr = arr[:, None]
    if arr.ndim != 4:
        raise InputError(
            f"images must be (N, C, H, W) or gray (N, H, W); got shape {arr.shape}"
            + (": a single image? use images[None]" if arr.ndim == 2 else "")
        )
    if arr.shape[0] == 0:
        raise InputError("images is empty (N = 0): the dataset needs at least one image")
    if arr.shape[-1] in (1, 3, 4) and arr.shape[1] not in (1, 3, 4):
        raise InputError(
            f"images must be channels-first (N, C, H, W); got {arr.shape}: channels-last? "
            "use images.transpose(0, 3, 1, 2)"
        )
    if arr.dtype.kind in "iub":
        raise InputError(
            f"images must be floating point in [0, 1]; got dtype {arr.dtype}: "
            "divide by the maximum first (images / 255.0 for 8-bit)"
        )
    if arr.dtype.kind != "f":
        raise InputError(f"images must be floating point; got dtype {arr.dtype}")
    if not np.isfinite(arr).all():
        raise InputError("images contain NaN or inf: drop or repair those images first")
    # float32 storage: beyond 1e18 squares (variances, losses) overflow float32
    check_magnitude(arr, "images", 1e18)
    return np.ascontiguousarray(arr, dtype=np.float32)


def _check_labels(labels: npt.ArrayLike, n: int, n_classes: int) -> np.ndarray:
    """``labels`` as int64 ``(n,)`` with values in ``0 .. n_classes - 1``."""
    arr = check_ndim(labels, "labels", (0, 1, 2, 3))
    if arr.ndim != 1 or arr.shape[0] != n:
        raise InputError(f"labels must have shape ({n},), one per image; got {arr.shape}")
    if arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(np.int64)
        else:
            raise InputError(
                f"labels must be integers 0 .. {n_classes - 1}; got dtype {arr.dtype}: "
                "map class names to indices first (np.unique(names, return_inverse=True))"
            )
    bad = (arr < 0) | (arr >= n_classes)
    if bad.any():
        raise InputError(
            f"labels must be in 0 .. {n_classes - 1} ({n_classes} classes); got "
            f"{int(arr[bad][0])} at index {int(np.flatnonzero(bad)[0])}: pass all class "
            "names in classes"
        )
    return arr.astype(np.int64)


class ArrayDataset:
    """Images and labels held in memory, served one ``(image, label)`` pair at a time.

    Follows the ``torch.utils.data.Dataset`` map-style contract, so it can be given to
    ``torch.utils.data.DataLoader`` directly.

    Parameters
    ----------
    images : (N, C, H, W) or (N, H, W) float array
        Pixels in [0, 1] (gray images get ``C = 1``). Integer images are refused rather
        than rescaled: divide by 255 (8-bit) first.
    labels : (N,) int array
        Class indices in ``0 .. len(classes) - 1``.
    classes : sequence of str, length K
        Class names; ``classes[labels[i]]`` names image ``i``.
    transform : callable, optional
        Applied to each ``(C, H, W)`` tensor in ``__getitem__`` (an augmentation of this
        module or any ``Tensor -> Tensor`` function).

    Attributes
    ----------
    images : (N, C, H, W) float32 ndarray
    labels : (N,) int64 ndarray
    classes : tuple of str
    transform : callable or None

    Raises
    ------
    InputError
        Empty dataset, channels-last or integer images, NaN pixels, labels of the wrong
        length or out of range.

    Examples
    --------
    >>> import numpy as np
    >>> ds = ArrayDataset(np.zeros((4, 8, 8), np.float32), [0, 1, 0, 1], ["a", "b"])
    >>> len(ds), ds[1][0].shape, ds[1][1]
    (4, torch.Size([1, 8, 8]), 1)
    """

    def __init__(
        self,
        images: npt.ArrayLike,
        labels: npt.ArrayLike,
        classes: Sequence[str],
        transform: Transform | None = None,
    ) -> None:
        if isinstance(classes, bytes) or not isinstance(classes, Iterable):
            raise InputError(
                f"classes must be a sequence of class names, e.g. ['cat', 'dog']; got {classes!r}"
            )
        classes = tuple(str(c) for c in classes)
        if len(classes) == 0:
            raise InputError("classes is empty: pass one name per class, e.g. ['cat', 'dog']")
        self.images = _check_images(images)
        self.labels = _check_labels(labels, self.images.shape[0], len(classes))
        self.classes = classes
        self.transform = _check_transform(transform)

    def __len__(self) -> int:
        """Number of images ``N``."""
        return int(self.images.shape[0])

    def __getitem__(self, index: int) -> tuple[torch.Tensor, int]:
        """Image ``index`` as a ``(C, H, W)`` float32 tensor (transformed) and its label."""
        image = torch.from_numpy(self.images[index])
        if self.transform is not None:
            image = self.transform(image)
        return image, int(self.labels[index])

    @property
    def image_shape(self) -> tuple[int, int, int]:
        """``(C, H, W)`` of every image."""
        c, h, w = self.images.shape[1:]
        return int(c), int(h), int(w)

    def subset(self, indices: npt.ArrayLike, transform: Transform | None = None) -> ArrayDataset:
        """A new dataset with the images at ``indices`` (e.g. one split of
        :func:`stratified_split`), the same classes and ``transform`` (or this one's).

        Parameters
        ----------
        indices : (M,) int array
            Positions in this dataset.
        transform : callable, optional
            Transform of the subset; None keeps this dataset's.

        Returns
        -------
        ArrayDataset
        """
        idx = np.asarray(indices, dtype=np.int64)
        return ArrayDataset(
            self.images[idx],
            self.labels[idx],
            self.classes,
            transform if transform is not None else self.transform,
        )


def load_digits(transform: Transform | None = None) -> ArrayDataset:
    """scikit-learn's handwritten digits: 1,797 images of 8 x 8, ten classes.

    The pixels (counts 0..16 of the original 32 x 32 bitmaps) are divided by 16, so they
    lie in [0, 1]. Same images and order as ``sklearn.datasets.load_digits()``.

    Parameters
    ----------
    transform : callable, optional
        See :class:`ArrayDataset`.

    Returns
    -------
    ArrayDataset
        ``images`` (1797, 1, 8, 8), ``labels`` 0..9, ``classes`` ``('0', ..., '9')``.

    Raises
    ------
    InputError
        scikit-learn is not installed (``pip install scikit-learn``).
    """
    try:
        from sklearn.datasets import load_digits as _sk_load_digits
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise InputError("load_digits needs scikit-learn: pip install scikit-learn") from exc
    bunch = _sk_load_digits()
    images = (np.asarray(bunch.images, dtype=np.float32) / 16.0)[:, None]
    return ArrayDataset(images, bunch.target, [str(d) for d in range(10)], transform)


def load_lfw_subset(transform: Transform | None = None) -> ArrayDataset:
    """scikit-image's ``lfw_subset``: 100 faces and 100 non-faces of 25 x 25 pixels.

    scikit-image documents the order: the first 100 images are faces, the next 100
    non-faces (background crops of the same LFW photos). Pixels are uint8 divided by 255.

    Parameters
    ----------
    transform : callable, optional
        See :class:`ArrayDataset`.

    Returns
    -------
    ArrayDataset
        ``images`` (200, 1, 25, 25), ``classes`` ``('non-face', 'face')``: label 1 for
        the first 100 images, 0 for the next 100.

    Raises
    ------
    InputError
        scikit-image is not installed (``pip install scikit-image``).
    """
    try:
        from skimage.data import lfw_subset
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise InputError("load_lfw_subset needs scikit-image: pip install scikit-image") from exc
    raw = np.asarray(lfw_subset())
    images = (raw.astype(np.float32) / 255.0)[:, None]
    labels = np.r_[np.ones(100, np.int64), np.zeros(raw.shape[0] - 100, np.int64)]
    return ArrayDataset(images, labels, ("non-face", "face"), transform)


def to_unit_float(image: np.ndarray) -> np.ndarray:
    """An image read from a file as float32 with the file's full scale mapped to 1:
    uint8 / 255, uint16 / 65535, floats kept."""
    if image.dtype == np.uint8:
        return image.astype(np.float32) / 255.0
    if image.dtype == np.uint16:
        return image.astype(np.float32) / 65535.0
    return image.astype(np.float32)


class ImageFolder(ArrayDataset):
    """Images in the layout ``root/class_name/*.png`` (torchvision's ``ImageFolder``).

    Every subfolder of ``root`` is a class; classes are sorted by name and numbered from
    0. Every file in them is read eagerly with :func:`robopercept.imaging.read_image`
    (so a broken file is found now, not mid-training), converted to ``mode`` and to
    float32 in [0, 1] (8-bit / 255, 16-bit / 65535), optionally resized.

    Files are handled so: names starting with ``.`` (``.DS_Store``) are ignored; a file
    without an image extension (:data:`IMAGE_EXTENSIONS`) or one that cannot be decoded
    raises :class:`~robopercept.errors.FileFormatError` naming it, unless
    ``skip_invalid=True``, in which case it is skipped and one warning counts the skipped
    files (their paths are in ``skipped``).

    Parameters
    ----------
    root : path-like
        The folder holding one subfolder per class.
    mode : {'rgb', 'gray'}
        ``'rgb'`` gives C = 3, ``'gray'`` C = 1 (BT.601 luma).
    size : (width, height), optional
        Resize every image to this size (bilinear with antialiasing,
        ``torch.nn.functional.interpolate``). Without it all images must share one size.
    transform : callable, optional
        See :class:`ArrayDataset`.
    skip_invalid : bool
        Skip non-image and unreadable files with a warning instead of raising.

    Attributes
    ----------
    paths : tuple of Path
        The file of each image, in dataset order (class by class, names sorted).
    skipped : tuple of Path
        Files skipped (only with ``skip_invalid=True``).

    Raises
    ------
    InputError
        ``root`` is not a folder, has no class subfolder, or has no image; images of
        different sizes without ``size``.
    FileFormatError
        A non-image or unreadable file (without ``skip_invalid``), naming the file.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        mode: str = "rgb",
        size: tuple[int, int] | None = None,
        transform: Transform | None = None,
        skip_invalid: bool = False,
    ) -> None:
        root = as_path(root, "root (the image folder)")
        mode = check_choice(mode, "mode", ("rgb", "gray"))
        skip_invalid = check_bool(skip_invalid, "skip_invalid")
        transform = _check_transform(transform)
        if size is not None:
            size = _check_size(size)
            check_allocation(3 * size[0] * size[1], 4, f"one image resized to {size}", "lower size")
        loaded = 0
        if not root.is_dir():
            raise InputError(f"image folder {str(root)!r} does not exist or is not a folder")
        class_dirs = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
        if not class_dirs:
            raise InputError(
                f"image folder {str(root)!r} has no class subfolders: lay it out as "
                "root/class_name/image.png"
            )
        images: list[np.ndarray] = []
        labels: list[int] = []
        paths: list[Path] = []
        skipped: list[Path] = []
        for label, cdir in enumerate(class_dirs):
            for f in sorted(cdir.iterdir()):
                if f.name.startswith(".") or f.is_dir():
                    continue
                if f.suffix.lower() not in IMAGE_EXTENSIONS:
                    if skip_invalid:
                        skipped.append(f)
                        continue
                    raise FileFormatError(
                        f"{str(f)!r} is not an image file (extensions read: "
                        f"{', '.join(IMAGE_EXTENSIONS)}): move it out of the image folder "
                        "or pass skip_invalid=True"
                    )
                try:
                    img = read_image(f, mode=mode)
                except FileFormatError as exc:
                    if skip_invalid:
                        skipped.append(f)
                        continue
                    raise FileFormatError(
                        f"cannot read image {str(f)!r} ({exc}): remove or repair it, or pass "
                        "skip_invalid=True"
                    ) from exc
                arr = to_unit_float(img)
                arr = arr[None] if arr.ndim == 2 else arr.transpose(2, 0, 1)
                if size is not None:
                    arr = _resize(arr, size)
                loaded += arr.nbytes
                if loaded > MAX_BYTES:
                    raise InputError(
                        f"the images of {str(root)!r} take more than 1 GiB as float32 (at "
                        f"{f}): pass a smaller size=(width, height), or split the folder"
                    )
                images.append(np.ascontiguousarray(arr))
                labels.append(label)
                paths.append(f)
        if skipped:
            warnings.warn(
                f"ImageFolder skipped {len(skipped)} non-image or unreadable file(s) in "
                f"{str(root)!r} (see .skipped)",
                stacklevel=2,
            )
        if not images:
            raise InputError(
                f"image folder {str(root)!r} has no images in its class subfolders "
                f"({', '.join(p.name for p in class_dirs)}): add files with extensions "
                f"{', '.join(IMAGE_EXTENSIONS)}"
            )
        shapes = sorted({im.shape[1:] for im in images})
        if len(shapes) > 1:
            raise InputError(
                f"images in {str(root)!r} have {len(shapes)} different sizes (H, W) "
                f"{shapes[:3]}...: pass size=(width, height) to resize them"
            )
        super().__init__(np.stack(images), labels, [p.name for p in class_dirs], transform)
        self.paths = tuple(paths)
        self.skipped = tuple(skipped)


def _check_size(size: object) -> tuple[int, int]:
    """``size`` as a ``(width, height)`` pair of positive ints."""
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise InputError(f"size must be (width, height), e.g. (32, 32); got {size!r}")
    return check_int(size[0], "size (width)", 1), check_int(size[1], "size (height)", 1)


def _resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(C, H, W)`` resized to ``size = (width, height)`` by antialiased bilinear."""
    w, h = _check_size(size)
    t = torch.from_numpy(image)[None]
    out = F.interpolate(t, size=(h, w), mode="bilinear", align_corners=False, antialias=True)
    return out[0].numpy()


#: the shape classes of :func:`shapes_dataset` and :func:`shape_masks`, in label order
SHAPES = ("circle", "square", "triangle", "cross")


def shape_masks(
    kinds: npt.ArrayLike,
    cx: npt.ArrayLike,
    cy: npt.ArrayLike,
    r: npt.ArrayLike,
    phi: npt.ArrayLike,
    size: tuple[int, int],
) -> np.ndarray:
    """Rasterize rotated shapes of :data:`SHAPES`, one per row: the masks of
    :func:`shapes_dataset`.

    Pixel ``p`` (its centre, ``(col + 0.5, row + 0.5)`` with edges on integers) is in
    shape ``i`` when, with ``q = R(-phi_i) (p - c_i)`` and ``r = r_i``:

    - circle (kind 0): ``|q| <= r``;
    - square (1): ``max(|q_x|, |q_y|) <= r / sqrt(2)``;
    - triangle (2): equilateral, vertices ``r (cos a_k, sin a_k)``,
      ``a_k = 2 pi k / 3 - pi/2``, ``q`` on the inner side of its three edges;
    - cross (3): ``min(|q_x|, |q_y|) <= r / 4`` and ``max(|q_x|, |q_y|) <= r``.

    Parameters
    ----------
    kinds : (N,) int array_like
        Index into :data:`SHAPES` of each shape.
    cx, cy, r, phi : (N,) float array_like
        Centres, radii (> 0) and rotations (radians).
    size : (int, int)
        ``(width, height)`` of the masks.

    Returns
    -------
    (N, H, W) bool ndarray

    Examples
    --------
    >>> m = shape_masks([1], [4.0], [4.0], [2 * 2**0.5], [0.0], (8, 8))
    >>> int(m.sum()), m[0, 2:6, 2:6].all()
    (16, np.True_)
    """
    kf = check_finite(check_numeric(kinds, "kinds"), "kinds").reshape(-1)
    if np.any((kf < 0) | (kf > len(SHAPES) - 1) | (kf != np.floor(kf))):
        raise InputError(
            f"kinds must be integers in [0, {len(SHAPES) - 1}] (indices into {SHAPES}); "
            f"got {plain_repr(kinds)}"
        )
    k = kf.astype(np.int64)
    rows = []
    for name, v in (("cx", cx), ("cy", cy), ("r", r), ("phi", phi)):
        arr = check_finite(check_numeric(v, name), name).astype(np.float64).reshape(-1)
        if arr.shape != k.shape:
            raise InputError(f"{name} must have one value per shape ({k.size}); got {arr.size}")
        rows.append(check_magnitude(arr, name, 1e100))
    cx_, cy_, r_, phi_ = rows
    if np.any(r_ <= 0):
        raise InputError(f"r must be > 0; got {plain_repr(r)}")
    w, h = check_size(size, "size", max_pixels=1 << 26)
    check_allocation(k.size * w * h, 100, f"{k.size} masks of {w} x {h}", "lower N or size")
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    dx = xx[None] - cx_[:, None, None]
    dy = yy[None] - cy_[:, None, None]
    cos, sin = np.cos(phi_)[:, None, None], np.sin(phi_)[:, None, None]
    qx = cos * dx + sin * dy
    qy = -sin * dx + cos * dy
    rr = r_[:, None, None]
    ax, ay = np.abs(qx), np.abs(qy)
    out = np.zeros((k.size, h, w), dtype=bool)
    sel = k == 0
    out[sel] = (qx**2 + qy**2 <= rr**2)[sel]
    sel = k == 1
    out[sel] = (np.maximum(ax, ay) <= rr / np.sqrt(2))[sel]
    sel = k == 2
    if sel.any():
        inside = np.ones((int(sel.sum()), h, w), dtype=bool)
        qxs, qys, rrs = qx[sel], qy[sel], rr[sel]
        for j in range(3):
            a = 2 * np.pi * j / 3 - np.pi / 2
            b = 2 * np.pi * (j + 1) / 3 - np.pi / 2
            # edge from vertex a to vertex b; the centre (origin) is on its inner side
            ex, ey = np.cos(b) - np.cos(a), np.sin(b) - np.sin(a)
            cross_p = ex * (qys / rrs - np.sin(a)) - ey * (qxs / rrs - np.cos(a))
            cross_0 = ex * (0 - np.sin(a)) - ey * (0 - np.cos(a))
            inside &= cross_p * np.sign(cross_0) >= 0
        out[sel] = inside
    sel = k == 3
    out[sel] = ((np.minimum(ax, ay) <= rr / 4) & (np.maximum(ax, ay) <= rr))[sel]
    return out


def shapes_dataset(
    n: int,
    size: int = 32,
    rng: int | np.random.Generator | None = None,
    *,
    noise: float = 0.05,
    transform: Transform | None = None,
) -> ArrayDataset:
    """Procedural gray images of four shapes: circle, square, triangle, cross.

    Each image has a uniform background of intensity ``b ~ U(0, 0.4)`` and one shape of
    intensity ``f ~ U(0.6, 1)`` (so the shape is always at least 0.2 brighter), centre
    ``c`` uniform with the shape inside the image, radius ``r ~ U(size/6, size/3)`` and
    a random rotation (squares, triangles and crosses), then Gaussian noise of standard
    deviation ``noise``, clipped to [0, 1]. Membership of pixel ``p`` (centre of the
    pixel), with ``q = R(-phi) (p - c)``:

    - circle: ``|q| <= r``;
    - square: ``max(|q_x|, |q_y|) <= r / sqrt(2)`` (corners on the circle of radius r);
    - triangle: equilateral, vertices ``r (cos a_k, sin a_k)`` with ``a_k = 2 pi k / 3 - pi/2``,
      ``q`` on the inner side of its three edges;
    - cross: ``min(|q_x|, |q_y|) <= r / 4`` and ``max(|q_x|, |q_y|) <= r``.

    Labels are balanced (``i mod 4`` shuffled).

    Parameters
    ----------
    n : int
        Number of images (>= 1).
    size : int
        Side of the square images (>= 8).
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same images.
    noise : float
        Standard deviation of the additive noise (>= 0).
    transform : callable, optional
        See :class:`ArrayDataset`.

    Returns
    -------
    ArrayDataset
        ``images`` (n, 1, size, size) in [0, 1]; ``classes``
        ``('circle', 'square', 'triangle', 'cross')``.
    """
    n = check_int(n, "n", 1)
    size = check_int(size, "size", 8)
    noise = check_real(noise, "noise (a standard deviation)", 0.0)
    transform = _check_transform(transform)
    # about 100 bytes of intermediate arrays per pixel (masks, float64 coordinates)
    check_allocation(
        n * size * size,
        100,
        f"{n} images of {size} x {size} (with their intermediate arrays)",
        "lower n or size, or make the data set in chunks with different seeds",
    )
    gen = as_rng(rng)
    labels = gen.permutation(np.arange(n) % 4)
    r = gen.uniform(size / 6, size / 3, n)
    cx = gen.uniform(r, size - r)
    cy = gen.uniform(r, size - r)
    phi = gen.uniform(0, 2 * np.pi, n)
    bg = gen.uniform(0.0, 0.4, n)
    fg = gen.uniform(0.6, 1.0, n)
    mask = shape_masks(labels, cx, cy, r, phi, (size, size))
    images = np.where(mask, fg[:, None, None], bg[:, None, None])
    images = images + noise * gen.standard_normal(images.shape)
    images = np.clip(images, 0.0, 1.0).astype(np.float32)[:, None]
    return ArrayDataset(images, labels, SHAPES, transform)


# --------------------------------------------------------------------------- splits and stats


def stratified_split(
    labels: npt.ArrayLike,
    fractions: Sequence[float] = (0.7, 0.15, 0.15),
    rng: int | np.random.Generator | None = 0,
) -> tuple[np.ndarray, ...]:
    """Split indices into parts with the class proportions of ``labels`` kept in each.

    For each class ``k`` with ``n_k`` members (shuffled), part ``j`` gets
    ``floor(f_j n_k)`` of them and the remaining ones go to the parts with the largest
    remainders ``f_j n_k - floor(f_j n_k)`` (Hamilton's method), so the parts are
    disjoint, cover every index, and each holds ``f_j n_k`` members of class ``k``
    rounded to a neighbouring integer. Same idea as scikit-learn's
    ``train_test_split(..., stratify=labels)`` for any number of parts. A part that
    rounding leaves empty (a small set: a few items per class) takes the last item of
    the largest part, so every part holds at least one item.

    Parameters
    ----------
    labels : (N,) int array
    fractions : sequence of float
        One positive fraction per part, summing to 1 (e.g. train, validation, test).
    rng : int, numpy.random.Generator or None
        Seed of the shuffle.

    Returns
    -------
    tuple of (N_j,) int64 ndarray
        Sorted indices of each part, in the order of ``fractions``; none empty.

    Raises
    ------
    InputError
        Fewer items than parts (the message names the smallest count), bad fractions.

    Examples
    --------
    >>> train, test = stratified_split([0, 0, 0, 0, 1, 1, 1, 1], (0.5, 0.5), rng=0)
    >>> len(train), len(test)
    (4, 4)
    >>> [len(p) for p in stratified_split([0, 1], (0.9, 0.1))]  # one item per class
    [1, 1]
    """
    y = check_ndim(labels, "labels", (0, 1, 2, 3))
    if y.ndim != 1 or y.size == 0:
        raise InputError(f"labels must be a non-empty (N,) array; got shape {y.shape}")
    y = check_finite(y, "labels")
    f = check_ndim(fractions, "fractions", (0, 1, 2))
    if f.dtype.kind not in "iuf":
        raise InputError(
            f"fractions must be positive numbers, e.g. (0.7, 0.15, 0.15); got {fractions!r}"
        )
    f = f.astype(np.float64)
    if f.ndim != 1 or f.size < 1 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError(
            f"fractions must be positive numbers, e.g. (0.7, 0.15, 0.15); got {fractions!r}"
        )
    if abs(f.sum() - 1.0) > 1e-6:
        raise InputError(f"fractions must sum to 1; got {fractions!r} (sum {f.sum():.6g})")
    gen = as_rng(rng)
    parts: list[list[np.ndarray]] = [[] for _ in f]
    for k in np.unique(y):
        members = gen.permutation(np.flatnonzero(y == k))
        exact = f * members.size
        counts = np.floor(exact).astype(np.int64)
        left = members.size - int(counts.sum())
        order = np.argsort(-(exact - counts), kind="stable")
        counts[order[:left]] += 1
        bounds = np.r_[0, np.cumsum(counts)]
        for j in range(f.size):
            parts[j].append(members[bounds[j] : bounds[j + 1]])
    out = [np.concatenate(p).astype(np.int64) for p in parts]
    if y.size < f.size:
        raise InputError(
            f"{y.size} items cannot fill {f.size} parts (e.g. training, validation and "
            f"test): give at least {f.size}, one per part"
        )
    for j in range(f.size):  # a small set: no part is left empty
        if not out[j].size:
            big = int(np.argmax([p.size for p in out]))
            out[j], out[big] = out[big][-1:], out[big][:-1]
    return tuple(np.sort(p) for p in out)


def normalization_stats(data: ArrayDataset | npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and standard deviation, to normalize ``(x - mean) / std``.

    ``mean_c = mean over n, h, w of x[n, c, h, w]``, ``std_c`` the population standard
    deviation (``ddof = 0``, as ``numpy.std``). Compute them on the training split only
    (``normalization_stats(ds.subset(train))``) and apply the same numbers to validation
    and test, so nothing of the held-out data leaks into training.

    Parameters
    ----------
    data : ArrayDataset or (N, C, H, W) / (N, H, W) float array

    Returns
    -------
    mean, std : (C,) float64 ndarray

    Raises
    ------
    InputError
        Empty, channels-last, integer or non-finite images.
    """
    images = data.images if isinstance(data, ArrayDataset) else _check_images(data)
    x = images.astype(np.float64)
    return x.mean(axis=(0, 2, 3)), x.std(axis=(0, 2, 3))
