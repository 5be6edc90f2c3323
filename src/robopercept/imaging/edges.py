r"""Canny edge detection, and the zero crossings of the Laplacian of Gaussian
(:func:`log_zero_crossings`: Marr-Hildreth edges with a hysteresis threshold).

The five steps (Canny 1986):

1. smooth with a Gaussian of ``sigma`` (1.0 by default; skipped when ``sigma == 0``,
   as ``cv2.Canny``, which never smooths);
2. Sobel gradient ``(g_x, g_y)`` (3x3, replicated border, as ``cv2.Canny``) and its
   magnitude :math:`\\sqrt{g_x^2 + g_y^2}` (or :math:`|g_x| + |g_y|`);
3. non-maximum suppression across the edge: a pixel stays only if its magnitude is a
   local maximum along the gradient direction, quantized to 0, 45, 90 or 135 degrees;
4. double threshold: magnitude > ``high`` is strong, > ``low`` is weak;
5. hysteresis: weak pixels are kept only when 8-connected, through other weak pixels, to a
   strong one.

Thresholds are gradient magnitudes in the grey levels of the image as given: 0..255 for
uint8, 0..65535 for uint16, [0, 1] for floats; nothing is rescaled. ``cv2.Canny`` takes
uint8 only (it refuses uint16); ``skimage.feature.canny`` works on floats in [0, 1].
:func:`grey_level_scale` converts thresholds written in 8-bit grey levels to another
dtype's scale (times 257 for uint16), and :func:`canny` warns when the thresholds cannot
be on the image's scale (8-bit-sized thresholds on a 16-bit image, and the reverse).
"""

from __future__ import annotations

import warnings

import numpy as np
from numba import njit
from numpy.typing import DTypeLike

from robopercept._checks import (
    check_bool,
    check_image,
    check_int,
    check_real,
    resolve_alias,
)
from robopercept.errors import InputError
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.filters import gaussian_blur

__all__ = ["LOG_HIGH", "LOG_LOW", "canny", "grey_level_scale", "log_zero_crossings"]

_TAN_22_5 = float(np.tan(np.deg2rad(22.5)))
_TAN_67_5 = float(np.tan(np.deg2rad(67.5)))
#: the largest Sobel gradient magnitude of an 8-bit image, |g_x| + |g_y| <= 2 * 4 * 255
#: (L2 is smaller); a float image in [0, 1] has at most 8
_MAX_8BIT_GRADIENT = 8.0 * 255.0


def grey_level_scale(dtype: DTypeLike) -> float:
    r"""The factor that takes a grey level (or a threshold) written on the 8-bit scale
    0..255 to the scale of images of ``dtype``.

    A grey level :math:`v_8` of an 8-bit image is :math:`v = s\,v_8` on the full range of
    ``dtype``, with :math:`s = 1` for uint8, :math:`s = 65535 / 255 = 257` for uint16
    (``v8 * 257`` maps 0..255 onto 0..65535 exactly, as ``cv2.convertScaleAbs`` inverts)
    and :math:`s = 1 / 255` for floating point images in [0, 1] (skimage's scale). Every
    threshold of :func:`canny` is linear in the grey levels, so it scales by the same
    :math:`s`.

    Parameters
    ----------
    dtype : numpy dtype
        uint8, uint16 or a floating point type.

    Returns
    -------
    float

    Raises
    ------
    InputError
        Another dtype (int32, int16, ...), which has no agreed full range.

    Examples
    --------
    >>> import numpy as np
    >>> grey_level_scale(np.uint16) * 150
    38550.0
    >>> grey_level_scale(np.float32) * 255
    1.0
    """
    dt = np.dtype(dtype)
    if dt == np.uint8:
        return 1.0
    if dt == np.uint16:
        return 257.0
    if dt.kind == "f":
        return 1.0 / 255.0
    raise InputError(
        f"no grey-level scale for {dt} images: convert to uint8, uint16 or float in [0, 1] "
        "(e.g. image.astype(np.uint16) when the values fit in 0..65535)"
    )


def _threshold_scale_warning(gray: np.ndarray, low: float, high: float) -> str | None:
    """A warning when the thresholds cannot be on the scale of ``gray``, else None.

    Two cheap tests, on the largest value of the image ``peak``: a uint16 image that uses
    more than 8 bits (``peak > 255``) with ``high <= _MAX_8BIT_GRADIENT`` (thresholds sized
    for 8-bit data: on 16 bits they sit at about two 8-bit grey levels, i.e. noise); a
    uint8 image, or a float image in [0, 1], with ``low`` above the largest gradient such
    an image can have (no pixel can ever pass: 16-bit or 8-bit thresholds).

    Parameters
    ----------
    gray : (H, W) ndarray
    low, high : float

    Returns
    -------
    str or None
    """
    if gray.dtype == np.uint16 and high <= _MAX_8BIT_GRADIENT:
        peak = int(gray.max())
        if peak > 255:
            return (
                f"canny thresholds {low:g} and {high:g} look like 8-bit grey levels (at most "
                f"{_MAX_8BIT_GRADIENT:g}, the largest gradient of an 8-bit image) but the image "
                f"is 16-bit (values up to {peak}): for the edges of its 8-bit version use 257 "
                f"times them ({low * 257:g} and {high * 257:g}); if they are in the image's "
                "own units (a depth map in mm), ignore this warning"
            )
    elif gray.dtype == np.uint8 and low > _MAX_8BIT_GRADIENT:
        return (
            f"canny threshold {low:g} is above {_MAX_8BIT_GRADIENT:g}, the largest gradient "
            "of an 8-bit image, so there can be no edge: for thresholds written for 16-bit "
            f"images divide by 257 ({low / 257:.4g} and {high / 257:.4g})"
        )
    elif gray.dtype.kind == "f" and low > 8.0 and float(gray.max()) <= 1.0:
        return (
            f"canny threshold {low:g} is above 8, the largest gradient of an image in "
            "[0, 1], so there can be no edge: for thresholds in 8-bit grey levels divide "
            f"by 255 ({low / 255:.4g} and {high / 255:.4g})"
        )
    return None


@njit(cache=True, nogil=True)
def _gradient_row(r0, r1, r2, l2, s, d, gx, gy, mag):  # pragma: no cover - compiled
    """One row of the 3x3 Sobel ``gx``, ``gy`` (replicated border) and its magnitude.

    ``s = r0 + 2 r1 + r2`` and ``d = r2 - r0`` down the columns (``s``, ``d`` have one
    replicated sample each side), then ``gx = s[x+1] - s[x-1]`` and
    ``gy = d[x-1] + 2 d[x] + d[x+1]`` along the row; ``mag[1 + x]`` gets the magnitude.
    """
    w = gx.shape[0]
    one = gx.dtype.type(1)
    two = gx.dtype.type(2)
    sv = s[1:]
    dv = d[1:]
    for x in range(w):
        a = one * r0[x]
        b = one * r1[x]
        c = one * r2[x]
        sv[x] = a + two * b + c
        dv[x] = c - a
    s[0] = s[1]
    s[w + 1] = s[w]
    d[0] = d[1]
    d[w + 1] = d[w]
    mr = mag[1:]
    s2 = s[2:]
    d1 = d[1:]
    d2 = d[2:]
    if l2:
        for x in range(w):
            a = s2[x] - s[x]
            b = d[x] + two * d1[x] + d2[x]
            gx[x] = a
            gy[x] = b
            mr[x] = np.sqrt(a * a + b * b)
    else:
        for x in range(w):
            a = s2[x] - s[x]
            b = d[x] + two * d1[x] + d2[x]
            gx[x] = a
            gy[x] = b
            mr[x] = abs(a) + abs(b)


@njit(cache=True, nogil=True)
def _canny_kernel(src, l2, low, high, proto):  # pragma: no cover - compiled
    """Gradient, non-maximum suppression, double threshold and hysteresis.

    Rows stream through small ring buffers (three magnitude rows with a zero frame, two
    gradient rows), as in OpenCV, so the only full-size array is ``state`` (framed by one
    pixel): 0 none, 1 weak candidate, 2 edge. Strong pixels go on a stack as they are
    found; popping one promotes its weak 8-neighbours, which are pushed in turn. Each
    pixel is pushed at most once, so the stack never outgrows the candidates.
    """
    h, w = src.shape
    stride = w + 2
    work = proto.dtype
    s = np.empty(w + 2, dtype=work)
    d = np.empty(w + 2, dtype=work)
    mag = np.zeros((4, w + 2), dtype=work)  # ring of 3 + a zero row (outside the image)
    gx = np.empty((2, w), dtype=work)
    gy = np.empty((2, w), dtype=work)
    state = np.zeros((h + 2) * stride, dtype=np.uint8)
    stack = np.empty(h * w, dtype=np.int32)
    top = 0
    for y in range(h + 1):
        if y < h:
            _gradient_row(
                src[max(y - 1, 0)], src[y], src[min(y + 1, h - 1)], l2, s, d,
                gx[y % 2], gy[y % 2], mag[y % 3],
            )  # fmt: skip
        if y == 0:
            continue
        # suppression of row yy = y - 1 between magnitude rows yy - 1 and yy + 1
        yy = y - 1
        up = mag[3] if yy == 0 else mag[(yy - 1) % 3]
        mid = mag[yy % 3]
        dn = mag[3] if yy == h - 1 else mag[y % 3]
        gxr = gx[yy % 2]
        gyr = gy[yy % 2]
        base = (yy + 1) * stride + 1
        for x in range(w):
            m = mid[x + 1]
            if m <= low:
                continue
            ax = abs(gxr[x])
            ay = abs(gyr[x])
            if ay < ax * _TAN_22_5:  # gradient ~ horizontal: compare left/right
                keep = m > mid[x] and m >= mid[x + 2]
            elif ay > ax * _TAN_67_5:  # gradient ~ vertical: compare up/down
                keep = m > up[x + 1] and m >= dn[x + 1]
            else:  # diagonal: along (1, 1) if the signs agree, else (1, -1)
                sg = 1 if (gxr[x] >= 0) == (gyr[x] >= 0) else -1
                keep = m > up[x + 1 - sg] and m > dn[x + 1 + sg]
            if keep:
                i = base + x
                if m > high:
                    state[i] = 2
                    stack[top] = i
                    top += 1
                else:
                    state[i] = 1
    while top > 0:
        top -= 1
        i = stack[top]
        for j in (
            i - stride - 1, i - stride, i - stride + 1, i - 1, i + 1,
            i + stride - 1, i + stride, i + stride + 1,
        ):  # fmt: skip
            if state[j] == 1:
                state[j] = 2
                stack[top] = j
                top += 1
    return state.reshape(h + 2, stride)


def canny(
    image: np.ndarray,
    low: float,
    high: float,
    aperture_size: int | None = None,
    *,
    sigma: float = 1.0,
    l2_gradient: bool | None = None,
    apertureSize: int | None = None,
    L2gradient: bool | None = None,
) -> np.ndarray:
    """Canny edges.

    Two defaults differ from ``cv2.Canny(image, low, high)``: the image is first smoothed
    by a Gaussian of ``sigma = 1.0``, and the gradient magnitude is the L2 norm
    (OpenCV's default is no smoothing and the L1 norm). ``canny(image, low, high,
    sigma=0, l2_gradient=False)`` gives ``cv2.Canny(image, low, high)``'s edges (on
    ``box_in_scene.png`` with 50, 150: the same 23,539 pixels, where the defaults keep
    14,828), and ``sigma=0`` alone gives ``cv2.Canny(image, low, high,
    L2gradient=True)``. OpenCV's call shapes are accepted: ``canny(g, 50, 150, 3)`` (the
    aperture, which must be 3) and the keywords ``apertureSize=`` and ``L2gradient=``.

    Thresholds are in the units of the gradient magnitude of ``image`` as given, that is
    in its grey levels per pixel times the Sobel gain of 4 per axis: 0..255 grey levels
    for uint8, 0..65535 for uint16, [0, 1] for floats; nothing is rescaled. ``cv2.Canny``
    refuses uint16, and the uint16 image ``257 * img8`` with thresholds ``257 * low``,
    ``257 * high`` gives the edges of ``img8`` (see :func:`grey_level_scale`). Colour
    images are converted to gray first (OpenCV instead takes the channel of largest
    gradient).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8, uint16 or float.
    low, high : float
        Hysteresis thresholds, ``0 <= low <= high``, on the image's scale (above). A
        :class:`UserWarning` says when they cannot be: a uint16 image using more than 8
        bits with ``high <= 2040`` (the largest gradient of an 8-bit image, so 8-bit
        thresholds: multiply by 257), or a uint8 / [0, 1] float image with ``low`` above
        its largest possible gradient (no edge can pass).
    aperture_size : int, optional
        Sobel aperture, OpenCV's ``apertureSize``: 3 (the default, and the only one
        implemented; OpenCV's 5 and 7 are refused with an :class:`InputError`).
    sigma : float
        Gaussian smoothing before differentiation (default 1.0); 0 skips it, as
        ``cv2.Canny``.
    l2_gradient : bool, optional
        Magnitude :math:`\\sqrt{g_x^2 + g_y^2}` (True, the default) or
        :math:`|g_x| + |g_y|` (False, OpenCV's default).
    apertureSize, L2gradient : optional
        Keyword-only aliases (OpenCV's names) of ``aperture_size`` and ``l2_gradient``.

    Returns
    -------
    (H, W) bool ndarray
        True on edge pixels.

    Raises
    ------
    InputError
        ``low > high``, a negative threshold or ``sigma``, an aperture other than 3, or
        one setting given under both of its spellings.

    Examples
    --------
    A bright square's outline, with OpenCV's settings (no smoothing, L1 norm):

    >>> img = np.zeros((12, 12), np.uint8); img[3:9, 3:9] = 200
    >>> e = canny(img, 50, 150, 3, sigma=0, l2_gradient=False)
    >>> int(e.sum()), bool(e[5, 2] or e[5, 3]), bool(e[5, 5])
    (20, True, False)
    """
    image = check_image(image)
    low = check_real(low, "low", 0.0)
    high = check_real(high, "high", 0.0)
    sigma = check_real(sigma, "sigma", 0.0)
    aperture = resolve_alias(aperture_size, "aperture_size", apertureSize, "apertureSize", "OpenCV")
    if aperture is not None:
        aperture = check_int(aperture, "aperture_size", 1)
        if aperture != 3:
            raise InputError(
                f"aperture_size must be 3 (the 3x3 Sobel, cv2.Canny's default); got "
                f"{aperture}: OpenCV's 5 and 7 are not implemented here; for coarser edges "
                "raise sigma instead"
            )
    l2 = resolve_alias(l2_gradient, "l2_gradient", L2gradient, "L2gradient", "OpenCV")
    l2 = True if l2 is None else check_bool(l2, "l2_gradient")
    if low > high:
        raise InputError(f"low must be <= high; got low={low:g}, high={high:g}: swap them")
    gray = rgb_to_gray(image) if image.ndim == 3 else image
    message = _threshold_scale_warning(gray, low, high)
    if message:
        warnings.warn(message, stacklevel=2)
    work = gray
    if sigma > 0:
        work = gaussian_blur(gray if gray.dtype.kind == "f" else gray.astype(np.float32), sigma)
    proto = np.empty(0, dtype=np.float64 if work.dtype == np.float64 else np.float32)
    state = _canny_kernel(np.ascontiguousarray(work), l2, low, high, proto)
    return state[1:-1, 1:-1] == 2


#: :func:`log_zero_crossings`'s default hysteresis thresholds on the slope of a
#: crossing, in multiples of the mean absolute LoG response
LOG_LOW, LOG_HIGH = 1.5, 4.0


def log_zero_crossings(
    log: np.ndarray,
    low: float = LOG_LOW,
    high: float = LOG_HIGH,
    *,
    contrast: float = 0.0,
) -> np.ndarray:
    r"""Edges as the zero crossings of a Laplacian-of-Gaussian response (Marr-Hildreth),
    kept by a hysteresis threshold on their slope.

    A zero crossing lies between two 4-neighbours whose responses have opposite signs
    (positive against non-positive); it is marked on the one of the two nearer to zero
    (the crossing is closer to it), and its **slope** is the jump across it,

    .. math::

        s = |L(p) - L(q)|,\qquad \operatorname{sgn} L(p) \ne \operatorname{sgn} L(q).

    A real edge crosses with a steep slope, the noise of a flat area with a shallow one
    (in flat areas the LoG of noise has as many crossings as an edge, so without a
    threshold the map is "noise everywhere"). As MATLAB's ``edge(I, 'log')``, whose
    default threshold is :math:`0.75\,\overline{|L|}`, the thresholds are relative to
    the mean absolute response :math:`\overline{|L|}`; as Canny, they are two: a pixel
    whose slope exceeds :math:`t_\text{low} = \text{low}\cdot\overline{|L|}` is kept when
    it is 8-connected, through such pixels, to one whose slope exceeds
    :math:`t_\text{high} = \text{high}\cdot\overline{|L|}`. That keeps whole contours
    (a contour's slope dips in places) and drops isolated crossings. The defaults (1.5
    and 4) give clean contours at :math:`\sigma = 1` on the Middlebury and Oxford
    photographs (5-9 % of the pixels, against 8-15 % with a threshold of 5 % of the
    largest response, which left the flat areas speckled). ``low = high = 0`` keeps
    every crossing.

    Parameters
    ----------
    log : (H, W) float ndarray
        The response, e.g. :func:`~robopercept.imaging.laplacian_of_gaussian` (the
        thresholds are relative, so its scale does not matter).
    low, high : float
        Hysteresis thresholds on the slope, in multiples of the mean absolute response,
        ``0 <= low <= high``.
    contrast : float in [0, 1)
        Also require :math:`|L| > c \max |L|` at the marked pixel (0: no such test).

    Returns
    -------
    (H, W) bool ndarray

    Raises
    ------
    InputError
        Not a 2-D real array, ``low > high``, or a threshold out of range.

    Examples
    --------
    The LoG of a vertical step (lobes +8 and -8) between flat areas with a little
    noise: ``low = high = 0`` keeps every crossing, the default only the step's.

    >>> import numpy as np
    >>> log = np.array([[-0.1, 2.0, 8.0, -8.0, -2.0, 0.1, -0.1]] * 2)
    >>> log_zero_crossings(log, 0, 0).astype(int)
    array([[1, 0, 1, 0, 0, 1, 0],
           [1, 0, 1, 0, 0, 1, 0]])
    >>> log_zero_crossings(log).astype(int)
    array([[0, 0, 1, 0, 0, 0, 0],
           [0, 0, 1, 0, 0, 0, 0]])
    """
    from scipy import ndimage

    log = check_image(log, "log")
    if log.ndim != 2:
        raise InputError(f"log must be a 2-D response; got shape {log.shape}")
    lo = check_real(low, "low", 0.0)
    hi = check_real(high, "high", 0.0)
    if lo > hi:
        raise InputError(f"low must be <= high; got low={lo:g}, high={hi:g}: swap them")
    c = check_real(contrast, "contrast", 0.0, 1.0, high_inclusive=False)
    v = log.astype(np.float64)
    v = np.where(np.isfinite(v), v, 0.0)  # (NaN/inf: no crossing there)
    a = np.abs(v)
    pos = v > 0
    slope = np.zeros(v.shape)
    for axis in (0, 1):  # down and right neighbours
        head = (slice(None, -1), slice(None)) if axis == 0 else (slice(None), slice(None, -1))
        tail = (slice(1, None), slice(None)) if axis == 0 else (slice(None), slice(1, None))
        with np.errstate(over="ignore"):
            jump = np.where(pos[head] != pos[tail], np.abs(v[head] - v[tail]), 0.0)
        first = a[head] <= a[tail]  # mark the pixel nearer to zero
        slope[head] = np.maximum(slope[head], np.where(first, jump, 0.0))
        slope[tail] = np.maximum(slope[tail], np.where(first, 0.0, jump))
    crossing = slope > 0
    if c > 0:
        crossing &= a > c * float(a.max())
    peak = float(a.max())
    mean = float(np.mean(a / peak)) * peak if peak > 0 else 0.0  # (no overflow near 1e308)
    t_low, t_high = lo * mean, hi * mean
    weak = crossing & (slope > t_low) if lo > 0 else crossing
    strong = weak & (slope > t_high) if hi > 0 else weak
    if not strong.any():
        return strong
    labels, n = ndimage.label(weak, structure=np.ones((3, 3), dtype=bool))
    keep = np.zeros(n + 1, dtype=bool)
    keep[np.unique(labels[strong])] = True
    keep[0] = False
    return keep[labels]
