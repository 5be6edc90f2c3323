r"""Canny edge detection.

The five steps (Canny 1986):

1. smooth with a Gaussian of ``sigma`` (skipped when ``sigma == 0``, as in OpenCV);
2. Sobel gradient ``(g_x, g_y)`` (3x3, replicated border, as ``cv2.Canny``) and its
   magnitude :math:`\\sqrt{g_x^2 + g_y^2}` (or :math:`|g_x| + |g_y|`);
3. non-maximum suppression across the edge: a pixel stays only if its magnitude is a
   local maximum along the gradient direction, quantized to 0, 45, 90 or 135 degrees;
4. double threshold: magnitude > ``high`` is strong, > ``low`` is weak;
5. hysteresis: weak pixels are kept only when 8-connected, through other weak pixels, to a
   strong one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from robopercept._checks import check_image, check_range
from robopercept.errors import InputError
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.filters import gaussian_blur, sobel

__all__ = ["canny"]

_TAN_22_5 = float(np.tan(np.deg2rad(22.5)))
_TAN_67_5 = float(np.tan(np.deg2rad(67.5)))


@njit(cache=True, nogil=True)
def _nms_threshold(gx, gy, l2, low, high, state):  # pragma: no cover - compiled
    """state: 0 none, 1 weak candidate, 2 strong; returns the strong pixels' count."""
    h, w = gx.shape
    mag = np.zeros((h + 2, w + 2), dtype=np.float32)
    for y in range(h):
        for x in range(w):
            if l2:
                mag[y + 1, x + 1] = np.sqrt(gx[y, x] * gx[y, x] + gy[y, x] * gy[y, x])
            else:
                mag[y + 1, x + 1] = abs(gx[y, x]) + abs(gy[y, x])
    n_strong = 0
    for y in range(h):
        for x in range(w):
            state[y, x] = 0
            m = mag[y + 1, x + 1]
            if m <= low:
                continue
            ax = abs(gx[y, x])
            ay = abs(gy[y, x])
            if ay < ax * _TAN_22_5:  # gradient ~ horizontal: compare left/right
                keep = m > mag[y + 1, x] and m >= mag[y + 1, x + 2]
            elif ay > ax * _TAN_67_5:  # gradient ~ vertical: compare up/down
                keep = m > mag[y, x + 1] and m >= mag[y + 2, x + 1]
            else:  # diagonal: along (1, 1) if the signs agree, else (1, -1)
                s = 1 if (gx[y, x] >= 0) == (gy[y, x] >= 0) else -1
                keep = m > mag[y, x + 1 - s] and m > mag[y + 2, x + 1 + s]
            if keep:
                if m > high:
                    state[y, x] = 2
                    n_strong += 1
                else:
                    state[y, x] = 1
    return n_strong


@njit(cache=True, nogil=True)
def _push(stack, top, y, x):  # pragma: no cover - compiled
    """Store (y, x) at stack[top], doubling the stack when full; returns the stack."""
    if top >= stack.shape[0]:
        grown = np.empty((stack.shape[0] * 2, 2), dtype=np.int64)
        grown[:top] = stack[:top]
        stack = grown
    stack[top, 0] = y
    stack[top, 1] = x
    return stack


@njit(cache=True, nogil=True)
def _hysteresis(state, n_strong):  # pragma: no cover - compiled
    h, w = state.shape
    stack = np.empty((max(n_strong, 1) + 16, 2), dtype=np.int64)
    top = 0
    for y in range(h):
        for x in range(w):
            if state[y, x] == 2:
                stack = _push(stack, top, y, x)
                top += 1
    while top > 0:
        top -= 1
        y = stack[top, 0]
        x = stack[top, 1]
        for dy in range(-1, 2):
            yy = y + dy
            if yy < 0 or yy >= h:
                continue
            for dx in range(-1, 2):
                xx = x + dx
                if xx < 0 or xx >= w or state[yy, xx] != 1:
                    continue
                state[yy, xx] = 2
                stack = _push(stack, top, yy, xx)
                top += 1
    out = np.empty((h, w), dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            out[y, x] = state[y, x] == 2
    return out


def canny(
    image: np.ndarray, low: float, high: float, *, sigma: float = 1.0, l2_gradient: bool = True
) -> np.ndarray:
    """Canny edges.

    Thresholds are in the units of the gradient magnitude of ``image`` as given (a uint8
    image's gradients are in grey levels per pixel, times the Sobel gain of 4 per axis);
    nothing is rescaled. With ``sigma=0`` this is ``cv2.Canny(image, low, high,
    L2gradient=l2_gradient)``; colour images are converted to gray first (OpenCV instead
    takes the channel of largest gradient).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    low, high : float
        Hysteresis thresholds, ``0 <= low <= high``.
    sigma : float
        Gaussian smoothing before differentiation; 0 skips it.
    l2_gradient : bool
        Magnitude :math:`\\sqrt{g_x^2 + g_y^2}` (True) or :math:`|g_x| + |g_y|`.

    Returns
    -------
    (H, W) bool ndarray
        True on edge pixels.
    """
    image = check_image(image)
    low = check_range(low, "low", 0.0)
    high = check_range(high, "high", 0.0)
    sigma = check_range(sigma, "sigma", 0.0)
    if low > high:
        raise InputError(f"low must be <= high; got low={low:g}, high={high:g}: swap them")
    gray = rgb_to_gray(image) if image.ndim == 3 else image
    work = gray.astype(np.float32) if gray.dtype != np.float64 else gray
    if sigma > 0:
        work = gaussian_blur(work, sigma)
    gx = sobel(work, 1, 0, 3, border="replicate")
    gy = sobel(work, 0, 1, 3, border="replicate")
    state = np.empty(work.shape, dtype=np.uint8)
    n_strong = _nms_threshold(
        np.ascontiguousarray(gx),
        np.ascontiguousarray(gy),
        bool(l2_gradient),
        float(low),
        float(high),
        state,
    )
    return _hysteresis(state, n_strong)
