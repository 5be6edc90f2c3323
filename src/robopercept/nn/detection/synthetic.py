r"""Synthetic detection sets with exact ground truth: procedural shapes on real photos
(:func:`procedural_detection_set`) and real handwritten digits on canvases
(:func:`digits_detection_set`, :func:`single_digit_set`).

Each is a :class:`~robopercept.nn.detection.data.DetectionDataset` with masks, made
from a seed: the same ``rng`` gives the same images, boxes, labels and masks.

* :func:`procedural_detection_set`: the four shapes of
  :func:`~robopercept.nn.data.datasets.shape_masks` (circle, square, triangle, cross),
  textured, scaled, rotated, over real-photo tiles of scikit-image's bundled images
  (:func:`~robopercept.nn.data.textures.photo_background`), with clutter under them and
  occluding bars over them; boxes and masks are those of the *visible* part.
* :func:`digits_detection_set` and :func:`single_digit_set`: real handwritten digits of
  scikit-learn's ``load_digits`` (8 x 8, bundled), scaled and placed on black canvases.

Every box of these sets is exactly the tight box of its mask,
:func:`~robopercept.nn.detection.data.mask_to_box` (the box convention of
:mod:`robopercept.nn.detection.data`; tested).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

from robopercept._checks import as_rng, check_int, check_real, check_size, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.data.datasets import SHAPES, shape_masks
from robopercept.nn.data.textures import photo_background, random_texture
from robopercept.nn.detection.data import DetectionDataset, check_classes, mask_to_box

__all__ = [
    "DIGIT_CLASSES",
    "digits_detection_set",
    "procedural_detection_set",
    "single_digit_set",
]

#: the class names of the digit sets: label ``d + 1`` is digit ``d``
DIGIT_CLASSES = tuple(str(d) for d in range(10))
#: the largest data set (pixels over all images) a generator makes: 2**28 (3 GiB float32)
MAX_PIXELS = 2**28


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
       of one of scikit-image's bundled photos
       (:data:`~robopercept.nn.data.textures.BACKGROUNDS`), resized (bilinear,
       antialiased) to ``size``, contrast reduced to ``0.2 + 0.6 I``;
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
    later), and its box is the tight box of that mask
    (:func:`~robopercept.nn.detection.data.mask_to_box`), so an occluded object's box
    shrinks to what is seen. Pixels of an object's visible mask hold exactly its texture.

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
    cls = check_classes(classes)
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
        boxes.append(np.array([mask_to_box(v) for v in vis]).reshape(-1, 4))
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
    its box the tight box of that mask
    (:func:`~robopercept.nn.detection.data.mask_to_box`). A placement whose box has IoU
    above ``max_iou`` with an earlier digit's box is redrawn (50 tries, then the
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
                box = mask_to_box(glyph > 0) + np.array([x, y, x, y], dtype=np.float64)
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
