"""Colour maps for depth, signed fields and labels (RGB uint8 out)."""

from __future__ import annotations

import numpy as np

from robopercept._checks import check_finite, check_int, check_ndim, check_real
from robopercept.errors import InputError
from robopercept.viz.draw import check_color

__all__ = ["colorize_depth", "colorize_signed", "label_colors", "turbo", "voc_palette"]

# Turbo (Mikhailov 2019) as the published polynomial fit: each channel a degree-5
# polynomial of t in [0, 1].
_TURBO = np.array(
    [
        [0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943],
        [0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604],
        [0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973],
    ]
)


def turbo(t: np.ndarray) -> np.ndarray:
    """Map ``t`` in [0, 1] to Turbo RGB uint8 (values outside are clipped).

    Parameters
    ----------
    t : array_like
        Real, finite values.

    Returns
    -------
    (..., 3) uint8 ndarray

    Examples
    --------
    >>> turbo([0.0, 1.0]).tolist()
    [[35, 23, 27], [144, 13, 0]]
    """
    arr = check_ndim(t, "t", range(33))
    if arr.dtype.kind not in "biuf":
        raise InputError(f"t must be real numbers; got dtype {arr.dtype}")
    t = np.clip(check_finite(arr.astype(np.float64), "t"), 0.0, 1.0)
    powers = np.stack([t**k for k in range(6)], axis=-1)
    rgb = np.clip(powers @ _TURBO.T, 0.0, 1.0)
    return np.round(rgb * 255.0).astype(np.uint8)


def colorize_depth(
    depth: np.ndarray,
    min_depth: float | None = None,
    max_depth: float | None = None,
    *,
    invalid: float = 0,
) -> np.ndarray:
    """Colour a depth map with Turbo: near blue, far red; invalid pixels black.

    Parameters
    ----------
    depth : (H, W) ndarray
        Any numeric dtype; pixels equal to ``invalid`` or non-finite are invalid.
    min_depth, max_depth : float, optional
        Range mapped to the colours; by default the 1st and 99th percentiles of valid
        depth. With ``max_depth <= min_depth`` the map is a step: depths above
        ``min_depth`` get the far colour.
    invalid : float
        The value that marks a pixel without depth (NaN: none besides NaN/inf).

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    d = check_ndim(depth, "depth", (2,))
    if d.dtype.kind not in "biuf":
        raise InputError(f"depth must be a numeric (H, W) array; got dtype {d.dtype}")
    d = d.astype(np.float64)
    if not (isinstance(invalid, (float, np.floating)) and np.isnan(invalid)):
        invalid = check_real(invalid, "invalid")  # (NaN: no sentinel, NaN is invalid anyway)
    lo = None if min_depth is None else check_real(min_depth, "min_depth")
    hi = None if max_depth is None else check_real(max_depth, "max_depth")
    valid = np.isfinite(d) & (d != invalid)
    out = np.zeros((*d.shape, 3), dtype=np.uint8)
    if not valid.any():
        return out
    # in halves, so that depths and ranges near 1e308 do not overflow the differences
    half = 0.5 * d[valid]
    lo_h = float(np.percentile(half, 1)) if lo is None else 0.5 * lo
    hi_h = float(np.percentile(half, 99)) if hi is None else 0.5 * hi
    if hi_h > lo_h:
        t = (half - lo_h) / (hi_h - lo_h)
    else:
        t = (half > lo_h).astype(np.float64)
    out[valid] = turbo(t)
    return out


def colorize_signed(field: np.ndarray, limit: float | None = None) -> np.ndarray:
    """Diverging map for signed values: negative blue, zero white, positive red.

    Parameters
    ----------
    field : (H, W) ndarray
    limit : float, optional
        Magnitude mapped to full colour; default the 99th percentile of ``|field|``.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    f = check_ndim(field, "field", (2,))
    if f.dtype.kind not in "biuf":
        raise InputError(f"field must be a numeric (H, W) array; got dtype {f.dtype}")
    f = f.astype(np.float64)
    f = np.where(np.isfinite(f), f, 0.0)
    if limit is None:
        limit = float(np.percentile(np.abs(f), 99)) if f.size else 1.0
    else:
        limit = check_real(limit, "limit")
    if limit <= 0:
        limit = 1.0
    with np.errstate(over="ignore"):  # (|f| / a tiny limit is inf: clipped to 1)
        t = np.clip(f / limit, -1.0, 1.0)[..., None]
    white = np.array([255.0, 255.0, 255.0])
    red = np.array([178.0, 24.0, 43.0])
    blue = np.array([33.0, 102.0, 172.0])
    rgb = np.where(t >= 0, white + t * (red - white), white + (-t) * (blue - white))
    return np.round(rgb).astype(np.uint8)


def label_colors(labels: np.ndarray, *, background: tuple[int, int, int] = (0, 0, 0)) -> np.ndarray:
    """Distinct colours per integer label (golden-ratio hues); label 0 (and < 0) is background.

    Parameters
    ----------
    labels : (H, W) or (N,) int ndarray
    background : (3,) ints
        The colour of labels <= 0.

    Returns
    -------
    (..., 3) uint8 ndarray
    """
    lab = check_ndim(labels, "labels", range(33))
    if lab.dtype.kind not in "iu":
        raise InputError(f"labels must be integers; got {lab.dtype}")
    background = check_color(background, "background")
    hue = np.mod(lab.astype(np.float64) * 0.618033988749895, 1.0)
    h6 = hue * 6.0
    x = 1.0 - np.abs(np.mod(h6, 2.0) - 1.0)
    sextant = np.floor(h6).astype(np.int64) % 6
    one, zero = np.ones_like(x), np.zeros_like(x)
    r = np.choose(sextant, [one, x, zero, zero, x, one])
    g = np.choose(sextant, [x, one, one, x, zero, zero])
    b = np.choose(sextant, [zero, zero, x, one, one, x])
    rgb = np.stack([r, g, b], axis=-1) * 0.85 + 0.15
    out = np.round(rgb * 255.0).astype(np.uint8)
    out[lab <= 0] = background
    return out


def voc_palette(n: int = 256) -> np.ndarray:
    """The Pascal VOC colour map: ``(n, 3)`` uint8, colour ``i`` from the bits of ``i``
    spread over the high bits of R, G and B (bit ``3k`` of ``i`` to bit ``7 - k`` of R,
    ``3k + 1`` to G, ``3k + 2`` to B), as the VOC devkit's ``labelcolormap.m`` and every
    VOC-style label PNG (0 black background, 255 the cream void border).

    Examples
    --------
    >>> voc_palette(4).tolist()
    [[0, 0, 0], [128, 0, 0], [0, 128, 0], [128, 128, 0]]
    >>> voc_palette()[255].tolist()
    [224, 224, 192]
    """
    n = check_int(n, "n", 1)
    if n > 256:
        raise InputError(f"n must be at most 256 (the colours of a palette PNG); got {n}")
    idx = np.arange(n)
    out = np.zeros((n, 3), np.uint8)
    for k in range(8):
        for ch in range(3):
            bit = (idx >> (3 * k + ch)) & 1
            out[:, ch] |= (bit << (7 - k)).astype(np.uint8)
    return out
