"""Backgrounds and textures of the procedural data sets: random crops of real photos
(:func:`photo_background`) and random textured fills (:func:`random_texture`).

They are shared by the synthetic sets of every wing (the detection shapes of
:func:`~robopercept.nn.detection.synthetic.procedural_detection_set`, the pose scenes of
:mod:`robopercept.nn.pose.data`). Both draw from a ``numpy.random.Generator`` that the
caller passes and keeps drawing from, so a generator's whole scene stays seeded.

The photos are scikit-image's bundled images (:data:`BACKGROUNDS`), whose files ship in
its wheel (none is fetched by pooch); each is read once and cached read-only.
NumPy and scikit-image only (no torch).
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from robopercept._checks import check_size, plain_repr
from robopercept.errors import InputError

__all__ = ["BACKGROUNDS", "photo_background", "random_texture"]

#: scikit-image images (``skimage.data.<name>()``) whose files ship in the wheel, used as
#: backgrounds of the procedural sets (none is fetched by pooch)
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
    from skimage.transform import resize

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
    tile = np.asarray(
        resize(crop, (h, w), order=1, mode="edge", anti_aliasing=True, preserve_range=True)
    )
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
