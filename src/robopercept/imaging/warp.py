r"""Perspective warping and remapping of images.

:func:`warp_perspective` maps every output pixel :math:`x'` back through
:math:`H^{-1}` (the backward map, so the output has no holes),
:math:`\tilde x = H^{-1} (x', y', 1)^\top`, :math:`x = \tilde x_1 / \tilde x_3,
y = \tilde x_2 / \tilde x_3`, and samples the input there bilinearly (or at the nearest
pixel); samples outside the input get ``border_value``. Pixel centres are at integer
coordinates, and the output size is ``dsize = (width, height)``, as in OpenCV;
``warp_perspective(image, H, (w, h))`` is ``cv2.warpPerspective(image, H, (w, h))``
(OpenCV quantizes the sample position to 1/32 pixel, hence differences of a grey level
or two).

:func:`remap` is the general form: each output pixel names its source position in two
maps (``cv2.remap``), as undistortion and stereo rectification need.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numba import njit, prange

from robopercept._checks import (
    check_choice,
    check_finite,
    check_image,
    check_int,
    check_points,
    check_real,
    check_shape,
)
from robopercept.errors import DegenerateError, InputError

__all__ = ["MAX_OUTPUT_PIXELS", "remap", "transform_points", "warp_perspective"]

#: the largest output of :func:`warp_perspective`, width x height: 2**27 pixels (an
#: 8K frame is 2**25; the float64 work buffer of a colour output is then 3 GiB)
MAX_OUTPUT_PIXELS = 2**27


def _check_homography(h: Any) -> np.ndarray:
    """``h`` as a finite float64 (3, 3) matrix scaled to largest entry 1 (a homography
    is defined up to scale; the scaling keeps entries near 1e300 from overflowing in
    the products), or InputError / DegenerateError (all zeros)."""
    m = check_shape(h, "H", (3, 3))
    if m.dtype.kind not in "biuf":
        raise InputError(f"H must be a real (3, 3) matrix; got dtype {m.dtype}")
    m = check_finite(m.astype(np.float64), "H")
    top = float(np.abs(m).max())
    if top == 0.0:
        raise DegenerateError("H is singular (all zeros): it maps no point; pass a homography")
    return m / top


def transform_points(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    r"""Apply a homography to points: :math:`(x', y') = \pi(H (x, y, 1)^\top)`.

    Parameters
    ----------
    h : (3, 3) array_like
        Finite; any scale (it is divided by its largest entry first).
    xy : (N, 2) array_like
        Points, or one point as ``(2,)``.

    Returns
    -------
    (N, 2) float64 ndarray
        Points mapped to infinity (third coordinate 0) come back as inf/NaN.

    Raises
    ------
    InputError
        ``h`` not a finite (3, 3) matrix, ``xy`` not (N, 2).
    DegenerateError
        ``h`` all zeros.

    Examples
    --------
    >>> transform_points(np.array([[2.0, 0, 1], [0, 2, 0], [0, 0, 1]]), [[1.0, 1.0]])
    array([[3., 2.]])
    """
    m = _check_homography(h)
    one = isinstance(xy, (list, tuple)) and len(xy) == 2
    one = one and all(isinstance(v, (int, float, np.integer, np.floating)) for v in xy)
    if one or (isinstance(xy, np.ndarray) and xy.shape == (2,)):
        xy = np.asarray(xy)[None, :]  # one point
    p = check_points(xy, "xy", 2)
    q = p @ m[:2, :2].T + m[:2, 2]
    w = p @ m[2, :2] + m[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return q / w[:, None]


@njit(cache=True, nogil=True, inline="always")
def _sample(src, sx, sy, linear, border, out, y, x):  # pragma: no cover - compiled
    """Write the sample of ``src`` at ``(sx, sy)`` into ``out[y, x]`` (bilinear or
    nearest; ``border`` outside, bilinear samples near the edge blend towards it)."""
    h, w, c = src.shape
    if not linear:
        ix = int(np.floor(sx + 0.5)) if abs(sx) < 1e9 else -1
        iy = int(np.floor(sy + 0.5)) if abs(sy) < 1e9 else -1
        if 0 <= ix < w and 0 <= iy < h:
            for k in range(c):
                out[y, x, k] = src[iy, ix, k]
        else:
            for k in range(c):
                out[y, x, k] = border
        return
    if not (-1.0 < sx < w and -1.0 < sy < h):
        for k in range(c):
            out[y, x, k] = border
        return
    x0 = int(np.floor(sx))
    y0 = int(np.floor(sy))
    fx = sx - x0
    fy = sy - y0
    for k in range(c):
        acc = 0.0
        for dy in range(2):
            yy = y0 + dy
            wy = fy if dy else 1.0 - fy
            for dx in range(2):
                xx = x0 + dx
                wx = fx if dx else 1.0 - fx
                v = src[yy, xx, k] if (0 <= yy < h and 0 <= xx < w) else border
                acc += wy * wx * v
        out[y, x, k] = acc


@njit(cache=True, nogil=True, parallel=True)
def _warp_kernel(src, minv, linear, border, out):  # pragma: no cover - compiled
    oh, ow = out.shape[0], out.shape[1]
    for y in prange(oh):
        for x in range(ow):
            zx = minv[0, 0] * x + minv[0, 1] * y + minv[0, 2]
            zy = minv[1, 0] * x + minv[1, 1] * y + minv[1, 2]
            zw = minv[2, 0] * x + minv[2, 1] * y + minv[2, 2]
            if zw == 0.0:
                _sample(src, -2.0, -2.0, linear, border, out, y, x)
            else:
                _sample(src, zx / zw, zy / zw, linear, border, out, y, x)


@njit(cache=True, nogil=True, parallel=True)
def _remap_kernel(src, map_x, map_y, linear, border, out):  # pragma: no cover - compiled
    oh, ow = out.shape[0], out.shape[1]
    for y in prange(oh):
        for x in range(ow):
            sx = map_x[y, x]
            sy = map_y[y, x]
            if not (np.isfinite(sx) and np.isfinite(sy)):
                sx = sy = -2.0
            _sample(src, sx, sy, linear, border, out, y, x)


def _finish(image: np.ndarray, out: np.ndarray) -> np.ndarray:
    if image.dtype.kind in "ui":
        info = np.iinfo(image.dtype)
        out = np.clip(np.rint(out), info.min, info.max)
    res = out.astype(image.dtype)
    return res if image.ndim == 3 else res[:, :, 0]


def remap(
    image: np.ndarray,
    map_x: np.ndarray,
    map_y: np.ndarray,
    *,
    interpolation: Literal["linear", "nearest"] = "linear",
    border_value: float = 0.0,
) -> np.ndarray:
    """Resample an image at arbitrary positions: ``out[y, x] = image(map_y[y, x],
    map_x[y, x])`` (``cv2.remap`` with a constant border).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
    map_x, map_y : (H', W') array_like
        Source column and row of every output pixel (NaN counts as outside).
    interpolation : {"linear", "nearest"}
    border_value : float

    Returns
    -------
    ndarray
        ``(H', W'[, C])``, the input's dtype (integers rounded).
    """
    image = check_image(image)
    maps = []
    for name, value in (("map_x", map_x), ("map_y", map_y)):
        arr = check_shape(value, name, (None, None))
        if arr.dtype.kind not in "biuf":
            raise InputError(f"{name} must be a real 2-D array; got dtype {arr.dtype}")
        maps.append(np.ascontiguousarray(arr, dtype=np.float64))
    mx, my = maps
    if mx.shape != my.shape:
        raise InputError(
            f"map_x and map_y must be 2-D arrays of one shape; got {mx.shape} and {my.shape}"
        )
    check_choice(interpolation, "interpolation", ("linear", "nearest"))
    border_value = check_real(border_value, "border_value")
    src = image if image.ndim == 3 else image[:, :, None]
    out = np.empty((*mx.shape, src.shape[2]), np.float64)
    _remap_kernel(np.ascontiguousarray(src), mx, my, interpolation == "linear", border_value, out)
    return _finish(image, out)


def warp_perspective(
    image: np.ndarray,
    h: np.ndarray,
    dsize: tuple[int, int],
    *,
    interpolation: Literal["linear", "nearest"] = "linear",
    border_value: float = 0.0,
) -> np.ndarray:
    """Warp ``image`` by the homography ``h`` (input -> output coordinates).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    h : (3, 3) array_like
        Maps input pixel coordinates to output pixel coordinates.
    dsize : (int, int)
        Output size ``(width, height)``, as ``cv2.warpPerspective``'s ``dsize`` (the
        result's shape is ``(height, width)``). To keep the input's size, pass
        ``image.shape[1::-1]``.
    interpolation : {"linear", "nearest"}
    border_value : float
        Value of output pixels whose source lies outside the input (bilinear samples
        near the edge blend towards it, as OpenCV's constant border).

    Returns
    -------
    ndarray
        ``(height, width)`` (plus the channel axis), the input's dtype (integers
        rounded).

    Raises
    ------
    DegenerateError
        If ``h`` is singular (or all zeros).
    InputError
        If ``h`` is not a finite (3, 3) matrix, ``dsize`` is not a pair of positive
        integers or asks for more than :data:`MAX_OUTPUT_PIXELS` pixels.

    Examples
    --------
    A shift by 2 columns into a 4 wide, 2 high output (``dsize`` is width first):

    >>> import numpy as np
    >>> img = np.arange(6, dtype=np.uint8).reshape(2, 3)
    >>> shift = np.array([[1.0, 0, 2], [0, 1, 0], [0, 0, 1]])
    >>> warp_perspective(img, shift, (4, 2)).tolist()
    [[0, 0, 0, 1], [0, 0, 3, 4]]
    """
    image = check_image(image)
    m = _check_homography(h)  # (largest entry 1)
    check_choice(interpolation, "interpolation", ("linear", "nearest"))
    if not isinstance(dsize, (tuple, list)) or len(dsize) != 2:
        raise InputError(f"dsize must be the output (width, height), as OpenCV's; got {dsize!r}")
    ow, oh = check_int(dsize[0], "dsize[0] (width)", 1), check_int(dsize[1], "dsize[1] (height)", 1)
    if ow * oh > MAX_OUTPUT_PIXELS:
        raise InputError(
            f"dsize {ow}x{oh} is {ow * oh} pixels; at most {MAX_OUTPUT_PIXELS} are made: "
            "pass the output (width, height) you need (image.shape[1::-1] keeps the size)"
        )
    border_value = check_real(border_value, "border_value")
    if abs(np.linalg.det(m)) <= 1e-12:
        raise DegenerateError("H is singular: it does not map the image onto a plane")
    minv = np.linalg.inv(m)
    src = image if image.ndim == 3 else image[:, :, None]
    out = np.empty((oh, ow, src.shape[2]), np.float64)
    _warp_kernel(np.ascontiguousarray(src), minv, interpolation == "linear", border_value, out)
    return _finish(image, out)
