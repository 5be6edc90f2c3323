"""Colour conversions: RGB <-> HSV, RGB -> gray, and HSV range masks.

Colour order is RGB everywhere in robopercept (OpenCV's readers give BGR: convert at the
I/O boundary).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numba import njit
from numpy.typing import DTypeLike

from robopercept._checks import check_choice, check_image, check_reals
from robopercept.errors import InputError

__all__ = [
    "gray_255",
    "hsv_range_mask",
    "hsv_to_rgb",
    "rgb_to_gray",
    "rgb_to_hsv",
    "rgb_to_hsv_pixel",
]

Scale = Literal["opencv", "unit"]


@njit(cache=True, nogil=True)
def _rgb_to_hsv_kernel(rgb, vmax, out, hscale, sscale, vscale):  # pragma: no cover
    n = rgb.shape[0]
    for i in range(n):
        r = rgb[i, 0] / vmax
        g = rgb[i, 1] / vmax
        b = rgb[i, 2] / vmax
        v = max(r, g, b)
        mn = min(r, g, b)
        diff = v - mn
        s = diff / v if v > 0 else 0.0
        if diff <= 0:
            h = 0.0
        elif v == r:
            h = 60.0 * (g - b) / diff
        elif v == g:
            h = 120.0 + 60.0 * (b - r) / diff
        else:
            h = 240.0 + 60.0 * (r - g) / diff
        if h < 0:
            h += 360.0
        h *= hscale
        s *= sscale
        v *= vscale
        out[i, 0] = h
        out[i, 1] = s
        out[i, 2] = v


_HSV_SHIFT = 12
# OpenCV's reciprocals round(2^12 * 255 / V) and round(2^12 * 180 / (6 Delta)), and the
# other constants of the uint8 conversion, all float32 so that the kernels stay float32
_SNUM = np.float32(255 << _HSV_SHIFT)
_HNUM = np.float32((180 << _HSV_SHIFT) // 6)
_UNSHIFT = np.float32(2.0**-_HSV_SHIFT)
_F0, _HALF, _F1, _F2, _F4 = (np.float32(x) for x in (0.0, 0.5, 1.0, 2.0, 4.0))
_F180 = np.float32(180.0)


@njit(cache=True, nogil=True, inline="always")
def rgb_to_hsv_pixel(r, g, b):  # pragma: no cover - compiled
    r"""HSV on OpenCV's uint8 scale of one uint8 RGB pixel, compiled (callable from numba
    kernels): the per-pixel core of :func:`rgb_to_hsv` for uint8 input.

    OpenCV's 12-bit fixed-point method, bit for bit: :math:`V = \max(R, G, B)`,
    :math:`\Delta = V - \min(R, G, B)`,

    .. math::
        S = (\Delta \, d_S(V) + 2^{11}) \gg 12, \quad d_S(V) =
        \operatorname{round}(2^{12} \cdot 255 / V), \qquad
        H = (h' \, d_H(\Delta) + 2^{11}) \gg 12, \quad d_H(\Delta) =
        \operatorname{round}(2^{12} \cdot 30 / \Delta)

    with :math:`h' = G - B`, :math:`B - R + 2\Delta` or :math:`R - G + 4\Delta` as V is
    R, G or B, and H wrapped into [0, 180). OpenCV tabulates :math:`d_S, d_H` and
    multiplies in int32; here every step is float32, and exact: the reciprocals come out
    as the same integers for every V and :math:`\Delta` in 1..255 (round of a correctly
    rounded float32 quotient), and the products are integers below :math:`2^{24}`
    (:math:`\Delta d_S(V) \le \Delta (2^{12} \cdot 255 / V + 1/2) \le 2^{12} \cdot 255
    + \Delta / 2` and :math:`|h' d_H| \le 5 \Delta (2^{12} \cdot 30 / \Delta + 1/2) \le
    2^{12} \cdot 150 + 5 \Delta / 2`), which float32 holds exactly, so the shift is a
    floor after the exact scaling by :math:`2^{-12}`. Identical to OpenCV on all
    :math:`2^{24}` colours (a test). float32 keeps 16 lanes in an AVX-512 register,
    where numba's integer arithmetic would widen to int64 (8 lanes).

    Parameters
    ----------
    r, g, b : int or float
        One pixel's channels, whole numbers in 0..255 (unchecked).

    Returns
    -------
    h, s, v : numpy.int32
        H in [0, 180), S and V in [0, 255], as ``cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)``.

    Examples
    --------
    >>> [int(x) for x in rgb_to_hsv_pixel(np.int32(0), np.int32(255), np.int32(0))]
    [60, 255, 255]
    """
    r, g, b = np.float32(r), np.float32(g), np.float32(b)
    v = max(r, max(g, b))
    diff = v - min(r, min(g, b))
    h = r - g + _F4 * diff  # V = B
    h = b - r + _F2 * diff if v == g else h
    h = g - b if v == r else h
    sdiv = np.rint(_SNUM / max(v, _F1)) * _UNSHIFT
    hdiv = np.rint(_HNUM / max(diff, _F1)) * _UNSHIFT
    hdiv = hdiv if diff > _F0 else _F0
    s = np.floor(diff * sdiv + _HALF)
    h = np.floor(h * hdiv + _HALF)
    h = h + _F180 if h < _F0 else h  # negative hue wraps around
    return np.int32(h), np.int32(s), np.int32(v)


@njit(cache=True, nogil=True)
def _rgb_to_hsv_u8_kernel(rgb, out):  # pragma: no cover - compiled
    """uint8 fast path on flat ``(3 N,)`` arrays: :func:`rgb_to_hsv_pixel` on every pixel
    (OpenCV's method bit for bit, in float32 so that the loop vectorizes 16 wide)."""
    for i in range(rgb.shape[0] // 3):
        h, s, v = rgb_to_hsv_pixel(rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2])
        out[3 * i] = h
        out[3 * i + 1] = s
        out[3 * i + 2] = v


def _scales(scale: str) -> tuple[float, float, float]:
    # the kernel computes H in degrees, S and V in [0, 1]
    if scale == "opencv":
        return 0.5, 255.0, 255.0
    return 1.0 / 360.0, 1.0, 1.0


def rgb_to_hsv(image: np.ndarray, scale: Scale = "opencv") -> np.ndarray:
    r"""Convert RGB to HSV.

    With :math:`V = \max(R, G, B)`, :math:`m = \min(R, G, B)`, :math:`\Delta = V - m`:

    .. math::
        S = \Delta / V \; (0 \text{ if } V = 0), \qquad
        H = 60^\circ \times \begin{cases}
            (G - B)/\Delta & V = R \\ 2 + (B - R)/\Delta & V = G \\ 4 + (R - G)/\Delta & V = B
        \end{cases} \pmod{360^\circ}

    ``scale="opencv"`` gives H in [0, 180) (degrees / 2), S and V in [0, 255]; for uint8
    input the result is uint8 and bit-identical to ``cv2.cvtColor(rgb,
    cv2.COLOR_RGB2HSV)`` (the divisions use the same 12-bit fixed-point reciprocals), for
    other input float32 (exact division). ``scale="unit"`` gives H, S, V in [0, 1] as float32
    (float64 stays float64), like ``skimage.color.rgb2hsv``.

    Parameters
    ----------
    image : (H, W, 3) ndarray
        RGB; uint8 (0..255), uint16 (0..65535) or float in [0, 1].
    scale : {'opencv', 'unit'}

    Returns
    -------
    (H, W, 3) ndarray
    """
    image = check_image(image)
    check_choice(scale, "scale", ("opencv", "unit"))
    if image.ndim != 3:
        raise InputError(f"image must be RGB (H, W, 3); got {image.shape}: a gray image has no hue")
    if image.dtype.kind in "ui":
        vmax = float(np.iinfo(image.dtype).max)
    else:
        vmax = 1.0
    round_out = scale == "opencv" and image.dtype == np.uint8
    if round_out:
        out_dtype = np.dtype(np.uint8)
    elif image.dtype == np.float64:
        out_dtype = np.dtype(np.float64)
    else:
        out_dtype = np.dtype(np.float32)
    rgb = np.ascontiguousarray(image).reshape(-1, 3)
    out = np.empty(rgb.shape, dtype=out_dtype)
    if round_out:
        _rgb_to_hsv_u8_kernel(rgb.reshape(-1), out.reshape(-1))
    else:
        _rgb_to_hsv_kernel(rgb, vmax, out, *_scales(scale))
    return out.reshape(image.shape)


def hsv_to_rgb(hsv: np.ndarray, scale: Scale = "opencv") -> np.ndarray:
    r"""Convert HSV back to RGB (the inverse of :func:`rgb_to_hsv`).

    With :math:`C = V S`, :math:`H' = H / 60^\circ`, :math:`X = C (1 - |H' \bmod 2 - 1|)`,
    :math:`(R, G, B) = (R_1, G_1, B_1) + (V - C)` where :math:`(R_1, G_1, B_1)` is
    :math:`(C, X, 0)`, :math:`(X, C, 0)`, ... by the sextant of :math:`H'`.

    Parameters
    ----------
    hsv : (H, W, 3) ndarray
        In the ranges of ``scale``.
    scale : {'opencv', 'unit'}

    Returns
    -------
    (H, W, 3) ndarray
        uint8 for uint8 OpenCV-scaled input; otherwise float in [0, 1].
    """
    hsv = check_image(hsv, "hsv")
    check_choice(scale, "scale", ("opencv", "unit"))
    if hsv.ndim != 3:
        raise InputError(f"hsv must be (H, W, 3); got {hsv.shape}")
    work = hsv.astype(np.float64)
    if scale == "opencv":
        h, s, v = work[..., 0] * 2.0, work[..., 1] / 255.0, work[..., 2] / 255.0
    else:
        h, s, v = work[..., 0] * 360.0, work[..., 1], work[..., 2]
    c = v * s
    hp = np.mod(h, 360.0) / 60.0
    x = c * (1.0 - np.abs(np.mod(hp, 2.0) - 1.0))
    zero = np.zeros_like(c)
    sextant = np.floor(hp).astype(np.int64) % 6
    r1 = np.choose(sextant, [c, x, zero, zero, x, c])
    g1 = np.choose(sextant, [x, c, c, x, zero, zero])
    b1 = np.choose(sextant, [zero, zero, x, c, c, x])
    m = v - c
    rgb = np.stack([r1 + m, g1 + m, b1 + m], axis=-1)
    if hsv.dtype == np.uint8 and scale == "opencv":
        return np.clip(np.floor(rgb * 255.0 + 0.5), 0, 255).astype(np.uint8)
    return rgb.astype(np.float64 if hsv.dtype == np.float64 else np.float32)


_BT601 = (0.299, 0.587, 0.114)  # ITU-R BT.601 luma weights of R, G, B


def rgb_to_gray(image: np.ndarray, dtype: DTypeLike | None = None) -> np.ndarray:
    r"""Luma :math:`Y = 0.299 R + 0.587 G + 0.114 B` (ITU-R BT.601), as ``cv2.COLOR_RGB2GRAY``.

    The one gray conversion of robopercept: every module that needs a gray image calls
    this. Values are never rescaled: :math:`Y` keeps the scale of the input (uint8
    0..255, uint16 0..65535, float in [0, 1]); a caller that works on another scale
    (e.g. thresholds in 0..255 grey levels) converts explicitly, after this call.

    ==============================  ==============================  ======================
    input                           ``dtype=None`` (default)        ``dtype=np.float32``
                                                                    or ``np.float64``
    ==============================  ==============================  ======================
    (H, W, 3) uint8, uint16, int16  same dtype: :math:`Y` rounded   :math:`Y` in
                                    half up and saturated           ``dtype``, not rounded
    (H, W, 3) int32                 int32, likewise
    (H, W, 3) float32, float64      same dtype
    (H, W) gray, any dtype          returned unchanged (no copy)    cast to ``dtype``
    ==============================  ==============================  ======================

    The sum is evaluated in one working type, with the weights rounded to it, in the
    order :math:`(0.299 R + 0.587 G) + 0.114 B` elementwise (no BLAS, so the result is
    the same on every machine): ``dtype`` when given (the input is cast to it first),
    otherwise ``numpy.result_type(image.dtype, numpy.float32)``, i.e. float32 for
    uint8, uint16, int16 and float32 input and float64 for int32 and float64 input.

    Matches ``cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)``: OpenCV sums integers with 14-bit
    fixed-point weights (off by up to :math:`2.5 \cdot 10^{-5}`), so uint8 results
    differ by at most one grey level (on 0.13% of all :math:`2^{24}` colours) and uint16
    ones by at most 2 of 65535; float32 agrees to the last bit or two.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray
        RGB (or already gray) image of a supported dtype, finite.
    dtype : {None, numpy.float32, numpy.float64}
        Output type; None keeps the input dtype (integers rounded back to it).

    Returns
    -------
    (H, W) ndarray
        The input dtype, or ``dtype`` when given (see the table).

    Raises
    ------
    InputError
        If ``image`` is not a valid image (shape, dtype, NaN/inf), or ``dtype`` is not
        None, float32 or float64.

    Examples
    --------
    >>> import numpy as np
    >>> rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [100, 100, 100]]], np.uint8)
    >>> rgb_to_gray(rgb)
    array([[ 76, 150,  29, 100]], dtype=uint8)
    >>> rgb_to_gray(rgb, dtype=np.float64).round(3)
    array([[ 76.245, 149.685,  29.07 , 100.   ]])
    """
    image = check_image(image)
    out = None
    if dtype is not None:
        try:
            out = np.dtype(dtype)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"dtype must be None, np.float32 or np.float64; got {dtype!r}"
            ) from exc
        if out not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise InputError(
                f"dtype must be None, np.float32 or np.float64; got {dtype!r}: "
                "for an integer image leave dtype=None (rounded to the input dtype)"
            )
    if image.ndim == 2:
        return image if out is None else image.astype(out, copy=False)
    work = np.result_type(image.dtype, np.float32) if out is None else out
    src = image if np.result_type(image.dtype, work) == work else image.astype(work)
    w_r, w_g, w_b = (work.type(w) for w in _BT601)
    y = src[..., 0] * w_r + src[..., 1] * w_g
    y += src[..., 2] * w_b
    if out is None and image.dtype.kind in "ui":
        info = np.iinfo(image.dtype)
        return np.clip(np.floor(y + 0.5), info.min, info.max).astype(image.dtype)
    return y.astype(image.dtype if out is None else out, copy=False)


def hsv_range_mask(
    hsv: np.ndarray,
    low: tuple[float, float, float] | np.ndarray,
    high: tuple[float, float, float] | np.ndarray,
) -> np.ndarray:
    r"""Pixels whose HSV lies in the box ``low <= (H, S, V) <= high`` (bounds inclusive).

    Hue is circular: when ``low[0] > high[0]`` the hue range wraps around, so
    ``low=(170, 50, 50), high=(10, 255, 255)`` on the OpenCV scale selects red, i.e.
    :math:`H \ge 170 \lor H \le 10`. Without wrap-around this is
    ``cv2.inRange(hsv, low, high) > 0``.

    Parameters
    ----------
    hsv : (H, W, 3) ndarray
        An image from :func:`rgb_to_hsv` (any scale; the bounds use the same scale).
    low, high : (3,) array_like
        Lower and upper bounds of H, S, V.

    Returns
    -------
    (H, W) bool ndarray
    """
    hsv = check_image(hsv, "hsv")
    if hsv.ndim != 3:
        raise InputError(f"hsv must be (H, W, 3); got {hsv.shape}: convert with rgb_to_hsv")
    low = check_reals(low, "low", 3)
    high = check_reals(high, "high", 3)
    if low[1] > high[1] or low[2] > high[2]:
        raise InputError(
            f"low must be <= high for S and V; got low={low.tolist()}, high={high.tolist()}: "
            "swap them (only hue may wrap around)"
        )
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    sv = (s >= low[1]) & (s <= high[1]) & (v >= low[2]) & (v <= high[2])
    if low[0] <= high[0]:
        hue = (h >= low[0]) & (h <= high[0])
    else:
        hue = (h >= low[0]) | (h <= high[0])
    return hue & sv


def gray_255(image: np.ndarray, name: str = "image") -> np.ndarray:
    """The float32 gray image on the 0-255 scale, for methods whose thresholds and costs
    are written in 8-bit grey levels (stereo costs, Lucas-Kanade's eigenvalue and
    residual thresholds, as OpenCV's).

    :math:`Y` is :func:`rgb_to_gray` ``(image, dtype=np.float32)``; uint8 input keeps its
    scale, float input in [0, 1] is multiplied by 255 (the one place this scaling is
    written). Other dtypes (uint16 among them) are refused rather than guessed.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint8 or float ndarray
    name : str
        The argument's name in error messages (``"left"``, ``"prev"``).

    Returns
    -------
    (H, W) float32 ndarray, C-contiguous

    Examples
    --------
    >>> import numpy as np
    >>> gray_255(np.array([[0.0, 0.5, 1.0]]))
    array([[  0. , 127.5, 255. ]], dtype=float32)
    """
    img = check_image(image, name)
    if img.dtype.kind != "f" and img.dtype != np.uint8:
        raise InputError(f"{name} must be uint8 or float in [0, 1]; got {img.dtype}")
    g = rgb_to_gray(img, dtype=np.float32)
    if img.dtype.kind == "f":
        g = g * np.float32(255.0)  # floats are [0, 1]
    return np.ascontiguousarray(g)
