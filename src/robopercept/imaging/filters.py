"""Linear and rank filters: correlation, convolution, Gaussian, box, median, derivatives.

All filters work per channel on ``(H, W)`` and ``(H, W, 3)`` images and share one border
convention, named as in OpenCV:

=============  ==========================  ======================
``border``     padding of ``abcdefgh``     OpenCV / SciPy name
=============  ==========================  ======================
``reflect101`` ``gfedcb|abcdefgh|gfedcba`` BORDER_REFLECT_101 / ``mirror``
``reflect``    ``fedcba|abcdefgh|hgfedcb`` BORDER_REFLECT / ``reflect``
``replicate``  ``aaaaaa|abcdefgh|hhhhhhh`` BORDER_REPLICATE / ``nearest``
``constant``   ``cccccc|abcdefgh|ccccccc`` BORDER_CONSTANT / ``constant``
=============  ==========================  ======================

``reflect101`` is the default, as in OpenCV.

Output dtypes: linear filters that can produce negative or fractional values
(:func:`correlate`, :func:`convolve`, derivatives) return float32 for integer input and
keep float32/float64 as they are; smoothing filters (:func:`gaussian_blur`,
:func:`box_filter`, :func:`median_filter`) keep the input dtype, rounding and saturating
integers as OpenCV does. Values are never rescaled.

The two numba kernels below loop over the kernel taps outside and over a contiguous image
row inside, so the inner loop vectorizes; an ``(H, W, C)`` image is seen as an
``(H, W*C)`` array whose horizontal tap stride is ``C``.

Two uint8 paths run in 16-bit integer lanes (sixteen per AVX2 instruction, as OpenCV's
uint8 kernels do) and give the float path's results to the bit:

* integer taps to float32 (:func:`sobel`, second derivatives, unnormalized sums): both
  passes in int16 and one conversion per pixel (:data:`INT_TAPS_MAX`);
* :func:`box_filter`'s means: uint16 column sums and a rounded division by
  multiply-high (:mod:`robopercept.imaging.fixed_point`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from fractions import Fraction
from typing import Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_bool,
    check_choice,
    check_image,
    check_int,
    check_kernel,
    check_odd_size,
    check_real,
    plain_repr,
    resolve_alias,
)
from robopercept.errors import InputError
from robopercept.imaging.fixed_point import mulhi_u16, rounding_divisor
from robopercept.imaging.median_networks import median_rows

__all__ = [
    "BORDERS",
    "BOX_INT_MAX",
    "MAX_KERNEL_SIZE",
    "box_filter",
    "convolve",
    "convolve_separable",
    "correlate",
    "correlate_separable",
    "derivative_kernel",
    "gaussian_blur",
    "gaussian_kernel",
    "gaussian_ksize",
    "gradient",
    "laplacian",
    "laplacian_of_gaussian",
    "median_filter",
    "separable_filter_unchecked",
    "sobel",
]

Border = Literal["reflect101", "reflect", "replicate", "constant"]
BORDERS: tuple[str, ...] = ("reflect101", "reflect", "replicate", "constant")
#: the longest 1-D kernel a filter builds from a scalar parameter (a Gaussian's sigma, a
#: box or kernel size, a LoG's truncation): 2**16 - 1 taps, a Gaussian of sigma up to
#: 8191 on float images. Larger requests (``sigma=2**40`` would ask for terabytes) are
#: refused with this limit named; blur a downsampled image instead.
MAX_KERNEL_SIZE = 2**16 - 1
#: the widest median window: the sorting network costs about ``ksize**4 / 4``
#: comparisons per pixel and channel (ksize 31: 2.3e5)
MAX_MEDIAN_KSIZE = 31


# --------------------------------------------------------------------------- borders
def border_indices(n: int, before: int, after: int, border: str) -> np.ndarray:
    """Source index for each position of a padded axis.

    Parameters
    ----------
    n : int
        Length of the axis.
    before, after : int
        Padding added before and after.
    border : str
        One of :data:`BORDERS`.

    Returns
    -------
    (before + n + after,) int64 ndarray
        Index into ``0 .. n-1``, or ``-1`` where the constant value is used.
    """
    return _border_map(n, before, after, border).copy()


@functools.lru_cache(maxsize=256)
def _border_map(n: int, before: int, after: int, border: str) -> np.ndarray:
    """:func:`border_indices`, computed once per axis (an image's axes repeat from call
    to call; the maps are a third of the Python-side time of a 3x3 filter)."""
    i = np.arange(-before, n + after, dtype=np.int64)
    if border == "constant":
        return np.where((i >= 0) & (i < n), i, -1)
    if border == "replicate" or n == 1:
        return np.clip(i, 0, n - 1)
    if border == "reflect101":
        period = 2 * n - 2
        m = np.mod(i, period)
        return np.where(m >= n, period - m, m)
    # reflect: period 2n, the edge sample repeated
    m = np.mod(i, 2 * n)
    return np.where(m >= n, 2 * n - 1 - m, m)


# --------------------------------------------------------------------------- kernels
@njit(cache=True, nogil=True)
def _store_row(dst, acc, is_int, lo, hi):  # pragma: no cover - compiled
    """dst = acc, rounded half up and saturated to [lo, hi] when ``is_int``."""
    if is_int and hi <= 65535.0 and lo >= -65536.0:
        # 8/16-bit output: round and clamp in the float type, then convert through
        # int32 (a conversion AVX2 vectorizes; the int64 one below it cannot)
        flo = acc.dtype.type(lo)
        fhi = acc.dtype.type(hi)
        half = acc.dtype.type(0.5)
        for x in range(acc.shape[0]):
            v = np.floor(acc[x] + half)
            dst[x] = np.int32(min(max(v, flo), fhi))
    elif is_int:
        for x in range(acc.shape[0]):
            v = math.floor(acc[x] + 0.5)
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
            dst[x] = v
    else:
        for x in range(acc.shape[0]):
            dst[x] = acc[x]


@njit(cache=True, nogil=True)
def _pad_row(srow, cidx, channels, cval, buf):  # pragma: no cover - compiled
    for j in range(cidx.shape[0]):
        s = cidx[j]
        if s < 0:
            for c in range(channels):
                buf[j * channels + c] = cval
        else:
            for c in range(channels):
                buf[j * channels + c] = srow[s * channels + c]


def _make_taps(stride: int) -> Callable[..., None]:
    """Compile the horizontal tap loop for one tap stride (the channel count).

    ``stride`` is frozen into the compiled function as a constant (numba treats closure
    variables as compile-time constants), so for 1 and 3 LLVM sees a literal stride and
    vectorizes the inner loops; ``stride=0`` compiles the generic loop, which reads the
    stride from its ``channels`` argument (slower: not vectorized). One definition, three
    specializations: :data:`_taps1`, :data:`_taps3`, :data:`_taps_any`.
    """

    @njit(cache=True, nogil=True)
    def taps(acc, kx, ax, cidx, channels, const, res):  # pragma: no cover - compiled
        """res[x] = sum_k kx[k] acc[x + (k - ax) s], s the tap stride, the border pixels
        through ``cidx``."""
        s = channels if stride == 0 else stride
        n = kx.shape[0]
        width = cidx.shape[0] - n + 1
        lo = ax * s
        hi = (width - (n - 1 - ax)) * s
        if hi > lo:
            dst = res[lo:hi]
            k = 0
            while k < n:  # up to four taps per pass, as the vertical taps of the caller
                g = min(4, n - k)
                if g >= 2:
                    sa, sb = acc[k * s :], acc[(k + 1) * s :]
                    sc, sd = acc[(k + g - 2) * s :], acc[(k + g - 1) * s :]
                    wa, wb, wc, wd = kx[k], kx[k + 1], kx[k + g - 2], kx[k + g - 1]
                    if g == 4 and k == 0:
                        for x in range(hi - lo):
                            dst[x] = wa * sa[x] + wb * sb[x] + wc * sc[x] + wd * sd[x]
                    elif g == 4:
                        for x in range(hi - lo):
                            dst[x] = dst[x] + wa * sa[x] + wb * sb[x] + wc * sc[x] + wd * sd[x]
                    elif g == 3 and k == 0:  # (sc is sb)
                        for x in range(hi - lo):
                            dst[x] = wa * sa[x] + wb * sb[x] + wd * sd[x]
                    elif g == 3:
                        for x in range(hi - lo):
                            dst[x] = dst[x] + wa * sa[x] + wb * sb[x] + wd * sd[x]
                    elif k == 0:
                        for x in range(hi - lo):
                            dst[x] = wa * sa[x] + wb * sb[x]
                    else:
                        for x in range(hi - lo):
                            dst[x] = dst[x] + wa * sa[x] + wb * sb[x]
                    k += g
                    continue
                wk = kx[k]
                seg = acc[k * s :]
                if k == 0:
                    for x in range(hi - lo):
                        dst[x] = wk * seg[x]
                else:
                    for x in range(hi - lo):
                        dst[x] += wk * seg[x]
                k += 1
        else:
            lo = hi = 0
        nb = lo // s  # the border pixels only: left of lo, right of hi
        for q in range(nb + width - hi // s):
            p = q if q < nb else hi // s + q - nb
            for c in range(s):
                v = 0.0
                for k in range(n):
                    j = cidx[p + k]
                    v += kx[k] * (const if j < 0 else acc[j * s + c])
                res[p * s + c] = v

    return taps


_taps1 = _make_taps(1)  # gray
_taps3 = _make_taps(3)  # RGB
_taps_any = _make_taps(0)  # any other channel count


@njit(cache=True, nogil=True)
def _taps(acc, kx, ax, cidx, channels, const, res):  # pragma: no cover - compiled
    """Dispatch on the tap stride so that LLVM sees it as a literal."""
    if channels == 1:
        _taps1(acc, kx, ax, cidx, 1, const, res)
    elif channels == 3:
        _taps3(acc, kx, ax, cidx, 3, const, res)
    else:
        _taps_any(acc, kx, ax, cidx, channels, const, res)


@njit(cache=True, nogil=True)
def _separable_kernel(
    src, kx, ky, ax, cidx, ridx, channels, cval, out, is_int, lo, hi
):  # pragma: no cover
    """out = kx (horizontal) o ky (vertical) correlation of src; src, out: (H, W*C).

    One fused pass per output row: the vertical taps accumulate source rows into ``acc``,
    then the horizontal taps write the output row (float output) or ``res``, which
    :func:`_store_row` rounds and saturates (integer output); the branches on
    ``channels`` give LLVM a literal tap stride, which it needs to vectorize.
    """
    height, length = out.shape
    ny = ky.shape[0]
    acc = np.empty(length, dtype=kx.dtype)
    res = np.empty(length, dtype=kx.dtype)
    const_row = cval * ky.sum()
    direct = not is_int and out.dtype == acc.dtype
    cast = acc.dtype.type
    for y in range(height):
        k = 0
        while k < ny:
            # four taps per pass over the row when their rows are inside the image: the
            # sum stays in a register between them (the same additions in the same
            # order as one pass per tap, so the same result, with a quarter of the
            # loads and stores of acc)
            g = min(4, ny - k)
            if g >= 2 and min(ridx[y + k : y + k + g]) >= 0:
                ra, rb = src[ridx[y + k]], src[ridx[y + k + 1]]
                rc, rd = src[ridx[y + k + g - 2]], src[ridx[y + k + g - 1]]
                wa, wb, wc, wd = ky[k], ky[k + 1], ky[k + g - 2], ky[k + g - 1]
                first = k == 0
                if g == 4 and first:
                    for x in range(length):
                        v = cast(wa * ra[x])  # rounded to acc's type at each step,
                        v = cast(v + wb * rb[x])  # as the store of a pass per tap is
                        v = cast(v + wc * rc[x])
                        acc[x] = v + wd * rd[x]
                elif g == 4:
                    for x in range(length):
                        v = cast(acc[x] + wa * ra[x])
                        v = cast(v + wb * rb[x])
                        v = cast(v + wc * rc[x])
                        acc[x] = v + wd * rd[x]
                elif g == 3 and first:  # (rc is rb: the last two taps are c and d)
                    for x in range(length):
                        v = cast(wa * ra[x])
                        v = cast(v + wb * rb[x])
                        acc[x] = v + wd * rd[x]
                elif g == 3:
                    for x in range(length):
                        v = cast(acc[x] + wa * ra[x])
                        v = cast(v + wb * rb[x])
                        acc[x] = v + wd * rd[x]
                elif first:
                    for x in range(length):
                        v = cast(wa * ra[x])
                        acc[x] = v + wb * rb[x]
                else:
                    for x in range(length):
                        v = cast(acc[x] + wa * ra[x])
                        acc[x] = v + wb * rb[x]
                k += g
                continue
            r = ridx[y + k]
            wk = ky[k]
            if r < 0:
                c = wk * cval
                if k == 0:
                    for x in range(length):
                        acc[x] = c
                else:
                    for x in range(length):
                        acc[x] += c
            else:
                srow = src[r]
                if k == 0:
                    for x in range(length):
                        acc[x] = wk * srow[x]
                else:
                    for x in range(length):
                        acc[x] += wk * srow[x]
            k += 1
        if direct:  # float output: the taps write the output row itself
            _taps(acc, kx, ax, cidx, channels, const_row, out[y])
        else:
            _taps(acc, kx, ax, cidx, channels, const_row, res)
            _store_row(out[y], res, is_int, lo, hi)


#: the largest sum of absolute integer taps (horizontal times vertical) that
#: :func:`separable_filter_unchecked` runs in int16 for uint8 images: 255 times it
#: fits int16 (Sobel 3x3: 8, 5x5: 96, the 2nd derivative 5x5: 64)
INT_TAPS_MAX = 32767 // 255


def _make_int_taps(stride: int) -> Callable[..., None]:
    """Compile the all-integer separable filter for one tap stride (1 or 3)."""

    @njit(cache=True, nogil=True)
    def run(src, kyi, kxi, ax, cidx, ridx, cval, out):  # pragma: no cover - compiled
        """out = float32 of the integer correlation of uint8 src with integer taps
        (vertical kyi, horizontal kxi), every partial sum within int16; src: (H, W*C)
        uint8, out: (H, W*C) float32; ``cval`` the integer outside a constant border.

        The vertical taps sum source rows into an int16 row (sixteen lanes, one pass
        for three taps), the horizontal taps sum that row's shifted slices in int16
        and convert once to float32; the outputs whose window reaches past the row go
        through the border map."""
        s = stride
        height, n = out.shape
        ny, nx = kyi.shape[0], kxi.shape[0]
        w = n // s
        col = np.empty(n, np.int16)
        row = np.empty(n, np.int16)
        lo = ax * s
        hi = max(lo, n - (nx - 1 - ax) * s)
        m = hi - lo
        for y in range(height):
            inside = True
            for k in range(ny):
                inside = inside and ridx[y + k] >= 0
            if ny == 3 and inside:
                ra, rb, rc = src[ridx[y]], src[ridx[y + 1]], src[ridx[y + 2]]
                wa, wb, wc = kyi[0], kyi[1], kyi[2]
                for x in range(n):
                    col[x] = wa * ra[x] + wb * rb[x] + wc * rc[x]
            else:
                for x in range(n):
                    col[x] = 0
                for k in range(ny):
                    r, wk = ridx[y + k], kyi[k]
                    if r < 0:
                        c = wk * cval
                        for x in range(n):
                            col[x] += c
                    else:
                        srow = src[r]
                        for x in range(n):
                            col[x] += wk * srow[x]
            o = out[y]
            inner = o[lo:hi]
            if nx == 3:
                c0, c1, c2 = col[:m], col[s : s + m], col[2 * s : 2 * s + m]
                wa, wb, wc = kxi[0], kxi[1], kxi[2]
                for x in range(m):
                    inner[x] = np.int16(wa * c0[x] + wb * c1[x] + wc * c2[x])
            else:
                part = row[:m]
                for x in range(m):
                    part[x] = 0
                for t in range(nx):
                    seg, wt = col[t * s : t * s + m], kxi[t]
                    for x in range(m):
                        part[x] += wt * seg[x]
                for x in range(m):
                    inner[x] = part[x]
            edges = nx - 1 if m > 0 else w
            for b in range(edges):
                px = b if b < ax or m == 0 else w - (nx - 1) + b
                for c in range(s):
                    total = 0
                    for t in range(nx):
                        j = cidx[px + t]
                        v = cval * kyi.sum() if j < 0 else col[j * s + c]
                        total += kxi[t] * v
                    o[px * s + c] = total

    return run


_int_taps1 = _make_int_taps(1)
_int_taps3 = _make_int_taps(3)


def _integer_taps(
    image: np.ndarray, kx: np.ndarray, ky: np.ndarray, cval: float, out_dtype: np.dtype
) -> tuple[np.ndarray, np.ndarray] | None:
    """``kx, ky`` as int16 when the integer kernel gives the float path's result: a
    uint8 image with 1 or 3 channels to float32, integer taps and ``cval``, and sums
    within int16 (:data:`INT_TAPS_MAX`). Every partial sum of the float path is then
    an integer below 2^24, exact in float32, so the two agree to the bit."""
    if image.dtype != np.uint8 or out_dtype != np.float32 or image.size == 0:
        return None
    if (image.shape[2] if image.ndim == 3 else 1) not in (1, 3) or cval != round(cval):
        return None
    if not (np.array_equal(kx, np.round(kx)) and np.array_equal(ky, np.round(ky))):
        return None
    if np.abs(kx).sum() * np.abs(ky).sum() > INT_TAPS_MAX or not 0 <= cval <= 255:
        return None
    return kx.astype(np.int16), ky.astype(np.int16)


@njit(cache=True, nogil=True)
def _correlate_kernel(
    src, kernel, cidx, ridx, channels, cval, out, is_int, lo, hi
):  # pragma: no cover
    """Full 2-D correlation; src, out: (H, W*C); kernel: (kh, kw)."""
    height, length = out.shape
    src_h = src.shape[0]
    kh, kw = kernel.shape
    plen = cidx.shape[0] * channels
    padded = np.empty((src_h + 1, plen), dtype=kernel.dtype)
    for y in range(src_h):
        _pad_row(src[y], cidx, channels, cval, padded[y])
    for x in range(plen):
        padded[src_h, x] = cval
    acc = np.empty(length, dtype=kernel.dtype)
    for y in range(height):
        for x in range(length):
            acc[x] = 0
        for i in range(kh):
            r = ridx[y + i]
            prow = padded[src_h] if r < 0 else padded[r]
            for j in range(kw):
                wk = kernel[i, j]
                if wk == 0:
                    continue
                seg = prow[j * channels :]
                for x in range(length):
                    acc[x] += wk * seg[x]
        _store_row(out[y], acc, is_int, lo, hi)


# --------------------------------------------------------------------------- drivers
def _out_dtype(image: np.ndarray, keep_dtype: bool) -> np.dtype:
    if keep_dtype or image.dtype.kind == "f":
        return image.dtype
    return np.dtype(np.float32)


def _work_dtype(image: np.ndarray) -> np.dtype:
    return np.dtype(np.float64) if image.dtype == np.float64 else np.dtype(np.float32)


def _int_limits(dtype: np.dtype) -> tuple[bool, float, float]:
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        return True, float(info.min), float(info.max)
    return False, 0.0, 0.0


def _as_rows(image: np.ndarray) -> tuple[np.ndarray, int]:
    """View an (H, W) or (H, W, C) image as a contiguous (H, W*C) array."""
    channels = 1 if image.ndim == 2 else image.shape[2]
    src = np.ascontiguousarray(image).reshape(image.shape[0], image.shape[1] * channels)
    return src, channels


def _check_border(border: str, cval: float) -> float:
    check_choice(border, "border", BORDERS)
    return check_real(cval, "cval")


def _check_taps(size: int, name: str, hint: str) -> int:
    """``size`` after checking that it is at most :data:`MAX_KERNEL_SIZE` taps."""
    if size > MAX_KERNEL_SIZE:
        raise InputError(
            f"{name} asks for a kernel of {size} taps; at most {MAX_KERNEL_SIZE} are built: {hint}"
        )
    return size


def _check_anchor(anchor: object, kernel_shape: tuple[int, int]) -> tuple[int, int] | None:
    """The public ``anchor=(a_x, a_y)`` of :func:`correlate`: None or two integers inside
    the kernel."""
    if anchor is None:
        return None
    if not isinstance(anchor, (tuple, list)) or len(anchor) != 2:
        raise InputError(f"anchor must be (a_x, a_y), two integers; got {plain_repr(anchor)}")
    kh, kw = kernel_shape
    out = []
    for v, size, axis in ((anchor[0], kw, "a_x"), (anchor[1], kh, "a_y")):
        a = check_int(v, f"anchor {axis}")
        if not 0 <= a < size:
            raise InputError(
                f"anchor {axis} must be in [0, {size - 1}] for a kernel of {size}; got {a}"
            )
        out.append(a)
    return out[0], out[1]


def _anchor(size: int, anchor: int | None, name: str) -> int:
    if anchor is None:
        return size // 2
    if not 0 <= int(anchor) < size:
        raise InputError(f"{name} must be in [0, {size - 1}] for a kernel of {size}; got {anchor}")
    return int(anchor)


def _plan(
    image: np.ndarray,
    kw: int,
    kh: int,
    ax: int | None,
    ay: int | None,
    border: str,
    out_dtype: np.dtype,
) -> tuple:
    """Shared setup of the kernels: row view, anchors, border maps, output and limits."""
    ax = _anchor(kw, ax, "anchor x")
    ay = _anchor(kh, ay, "anchor y")
    src, channels = _as_rows(image)
    h, w = image.shape[:2]
    cidx = border_indices(w, ax, kw - 1 - ax, border)
    ridx = border_indices(h, ay, kh - 1 - ay, border)
    out = np.empty(src.shape, dtype=out_dtype)
    return src, channels, ax, cidx, ridx, out, *_int_limits(out_dtype)


def separable_filter_unchecked(
    image: np.ndarray,
    kx: np.ndarray,
    ky: np.ndarray,
    border: str = "reflect101",
    cval: float = 0.0,
    out_dtype: np.dtype | type | None = None,
    ax: int | None = None,
    ay: int | None = None,
) -> np.ndarray:
    r"""Separable correlation ``g = k_y \star_y (k_x \star_x f)`` WITHOUT input checks: the
    compiled engine behind :func:`correlate_separable`, :func:`gaussian_blur`,
    :func:`box_filter`, :func:`sobel`, :func:`laplacian` and
    :func:`laplacian_of_gaussian`, for callers that have validated their input already
    (and that call it in a loop, e.g. pyramids and scale spaces).

    .. math:: g(x, y) = \sum_{i, j} k_y[i]\, k_x[j]\, f(x + j - a_x,\; y + i - a_y)

    It does not validate anything: ``image`` must already be a finite ``(H, W)`` or
    ``(H, W, C)`` array of a supported dtype (e.g. from ``check_image``), the kernels
    finite 1-D arrays, ``border`` one of :data:`BORDERS`, the anchors inside the
    kernels. Bad input gives wrong output or a crash, not an :class:`InputError`; use
    :func:`correlate_separable` at a public boundary.

    The sums run in float32 (float64 for float64 images); integer outputs are rounded
    half up and saturated, as OpenCV does. The result equals
    ``correlate_separable(image, kx, ky, border=border, cval=cval)`` when ``out_dtype`` is
    float32 for integer input, and ``gaussian_blur(image, sigma, ksize=n)`` for
    ``kx = ky = gaussian_kernel(sigma, n)``, ``out_dtype=None`` and a float image (a
    uint8 image's blur uses OpenCV's fixed-point kernels instead).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Validated image.
    kx, ky : (kw,), (kh,) ndarray
        Horizontal and vertical kernels (any float dtype; cast to the working type).
    border : {'reflect101', 'reflect', 'replicate', 'constant'}
    cval : float
        The value outside the image for ``border="constant"``.
    out_dtype : dtype, optional
        Output dtype; default the input dtype (a smoothing filter).
    ax, ay : int, optional
        Anchors in ``kx`` and ``ky``; default their centres ``kw // 2``, ``kh // 2``.

    Returns
    -------
    ndarray
        Same shape as ``image``, dtype ``out_dtype``.

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((5, 5), np.float32); img[2, 2] = 1
    >>> k = np.array([1.0, 2.0, 1.0]) / 4
    >>> separable_filter_unchecked(img, k, k)[1:4, 1:4] * 16
    array([[1., 2., 1.],
           [2., 4., 2.],
           [1., 2., 1.]], dtype=float32)
    """
    out_dtype = image.dtype if out_dtype is None else np.dtype(out_dtype)
    work = _work_dtype(image)
    src, channels, ax, cidx, ridx, out, is_int, lo, hi = _plan(
        image, kx.size, ky.size, ax, ay, border, out_dtype
    )
    taps = _integer_taps(image, kx, ky, cval, out_dtype)
    if taps is not None:  # uint8 with integer taps (derivatives): int16, the same bits
        kernel = _int_taps1 if channels == 1 else _int_taps3
        kernel(src, taps[1], taps[0], ax, cidx, ridx, np.int16(cval), out)
        return out.reshape(image.shape)
    kx, ky, cv = kx.astype(work), ky.astype(work), work.type(cval)
    _separable_kernel(src, kx, ky, ax, cidx, ridx, channels, cv, out, is_int, lo, hi)
    return out.reshape(image.shape)


def _run_correlate(
    image: np.ndarray,
    kernel: np.ndarray,
    border: str,
    cval: float,
    out_dtype: np.dtype,
    anchor: tuple[int, int] | None = None,
) -> np.ndarray:
    work = _work_dtype(image)
    kh, kw = kernel.shape
    ax, ay = (None, None) if anchor is None else anchor
    src, channels, _, cidx, ridx, out, is_int, lo, hi = _plan(
        image, kw, kh, ax, ay, border, out_dtype
    )
    k, cv = np.ascontiguousarray(kernel, dtype=work), work.type(cval)
    _correlate_kernel(src, k, cidx, ridx, channels, cv, out, is_int, lo, hi)
    return out.reshape(image.shape)


# --------------------------------------------------------------------------- public API
def correlate(
    image: np.ndarray,
    kernel: np.ndarray,
    *,
    border: Border = "reflect101",
    cval: float = 0.0,
    anchor: tuple[int, int] | None = None,
) -> np.ndarray:
    r"""2-D correlation of each channel with ``kernel``.

    .. math:: g(x, y) = \sum_{i, j} K(i, j)\, f(x + j - a_x,\; y + i - a_y)

    with the anchor ``(a_x, a_y)`` at the kernel centre ``(kw // 2, kh // 2)`` by default.
    This is ``cv2.filter2D(image, -1, kernel, borderType=...)`` (which correlates, despite
    its name) with float output for integer input.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8/uint16/int16/int32 or float32/float64.
    kernel : (kh, kw) array_like
        Correlation kernel.
    border : {'reflect101', 'reflect', 'replicate', 'constant'}
        How the image is extended past its edges.
    cval : float
        Value outside the image with ``border='constant'``.
    anchor : (int, int), optional
        ``(a_x, a_y)`` kernel element placed over the output pixel.

    Returns
    -------
    ndarray
        Same shape; float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    kernel = check_kernel(kernel)
    cval = _check_border(border, cval)
    anchor = _check_anchor(anchor, kernel.shape)
    return _run_correlate(image, kernel, border, cval, _out_dtype(image, False), anchor)


def convolve(
    image: np.ndarray, kernel: np.ndarray, *, border: Border = "reflect101", cval: float = 0.0
) -> np.ndarray:
    r"""2-D convolution of each channel with ``kernel``.

    .. math:: g(x, y) = \sum_{i, j} K(i, j)\, f(x - j + a_x,\; y - i + a_y)

    i.e. :func:`correlate` with the kernel flipped in both axes (the anchor, the kernel
    centre, flips with it). Matches ``cv2.filter2D(image, -1, cv2.flip(kernel, -1))``
    for odd kernels, and ``scipy.ndimage.convolve``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    kernel : (kh, kw) array_like
    border : {'reflect101', 'reflect', 'replicate', 'constant'}
    cval : float

    Returns
    -------
    ndarray
        Same shape; float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    kernel = check_kernel(kernel)
    cval = _check_border(border, cval)
    kh, kw = kernel.shape
    anchor = (kw - 1 - kw // 2, kh - 1 - kh // 2)
    return _run_correlate(image, kernel[::-1, ::-1], border, cval, _out_dtype(image, False), anchor)


def correlate_separable(
    image: np.ndarray,
    kernel_x: np.ndarray,
    kernel_y: np.ndarray,
    *,
    border: Border = "reflect101",
    cval: float = 0.0,
) -> np.ndarray:
    r"""Correlation with the separable kernel ``K = k_y k_x^T``: rows first, then columns.

    .. math:: g = k_y \star_y (k_x \star_x f)

    costs ``kw + kh`` instead of ``kw kh`` operations per pixel. Matches
    ``cv2.sepFilter2D(image, -1, kernel_x, kernel_y)`` with float output for integer input.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    kernel_x, kernel_y : 1-D array_like
        Horizontal and vertical kernels (anchors at their centres).
    border : {'reflect101', 'reflect', 'replicate', 'constant'}
    cval : float

    Returns
    -------
    ndarray
        Same shape; float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    kx = check_kernel(kernel_x, "kernel_x", 1)
    ky = check_kernel(kernel_y, "kernel_y", 1)
    cval = _check_border(border, cval)
    return separable_filter_unchecked(image, kx, ky, border, cval, _out_dtype(image, False))


def convolve_separable(
    image: np.ndarray,
    kernel_x: np.ndarray,
    kernel_y: np.ndarray,
    *,
    border: Border = "reflect101",
    cval: float = 0.0,
) -> np.ndarray:
    """Convolution with the separable kernel ``k_y k_x^T`` (both kernels flipped).

    See :func:`correlate_separable`; this flips each 1-D kernel and its anchor.
    """
    image = check_image(image)
    kx = check_kernel(kernel_x, "kernel_x", 1)
    ky = check_kernel(kernel_y, "kernel_y", 1)
    cval = _check_border(border, cval)
    return separable_filter_unchecked(
        image,
        kx[::-1],
        ky[::-1],
        border,
        cval,
        _out_dtype(image, False),
        kx.size - 1 - kx.size // 2,
        ky.size - 1 - ky.size // 2,
    )


# cv2.getGaussianKernel(n, 0) for odd n <= 9: OpenCV 4.x's fixed small kernels (used
# instead of the sampled Gaussian of sigma = 0.3 ((n - 1) / 2 - 1) + 0.8 when sigma <= 0)
_SMALL_GAUSSIAN = {
    1: (1.0,),
    3: (0.25, 0.5, 0.25),
    5: (0.0625, 0.25, 0.375, 0.25, 0.0625),
    7: (0.03125, 0.109375, 0.21875, 0.28125, 0.21875, 0.109375, 0.03125),
    9: (1 / 64, 13 / 256, 15 / 128, 51 / 256, 15 / 64, 51 / 256, 15 / 128, 13 / 256, 1 / 64),
}


def gaussian_ksize(sigma: float, dtype: npt.DTypeLike = np.float64) -> int:
    r"""OpenCV's automatic Gaussian kernel size for ``sigma`` and an image dtype.

    .. math:: n = \operatorname{round}(2 t \sigma + 1) \;|\; 1, \qquad
              t = 3 \text{ for uint8}, \quad t = 4 \text{ otherwise}

    (``| 1`` makes it odd), the rule of OpenCV's ``createGaussianKernels`` behind
    ``cv2.GaussianBlur(image, (0, 0), sigma)``: the kernel covers +-3 sigma for 8-bit
    images, whose result is rounded to a grey level anyway, and +-4 sigma for every
    other depth (scikit-image's ``gaussian`` also truncates at 4 sigma).

    Parameters
    ----------
    sigma : float
        Standard deviation in pixels, > 0.
    dtype : dtype-like
        The image's dtype (``np.uint8`` selects the 3-sigma rule).

    Returns
    -------
    int
        Odd kernel length.

    Raises
    ------
    InputError
        ``sigma`` not a positive real number, or so large that the kernel would have
        more than :data:`MAX_KERNEL_SIZE` taps (sigma above 8191 for float images).

    Examples
    --------
    >>> gaussian_ksize(2.0, np.float32), gaussian_ksize(2.0, np.uint8)
    (17, 13)
    """
    sigma = check_real(sigma, "sigma", 0.0, low_inclusive=False)
    try:
        t = 3.0 if np.dtype(dtype) == np.uint8 else 4.0
    except TypeError:
        raise InputError(f"dtype must be a NumPy dtype; got {plain_repr(dtype)}") from None
    # the limit before the product: sigma near 1e308 would overflow it to inf
    if sigma > (MAX_KERNEL_SIZE - 1) / (2.0 * t):
        raise InputError(
            f"sigma={sigma:g} asks for a Gaussian kernel of about {2 * t * sigma:.3g} taps; at "
            f"most {MAX_KERNEL_SIZE} are built (sigma <= {(MAX_KERNEL_SIZE - 1) / (2 * t):g} "
            "here): blur a downsampled image (robopercept.imaging.pyr_down) with a smaller sigma"
        )
    # Python's round is round-half-even, as OpenCV's cvRound; "| 1" hides the tie rule
    return round(sigma * t * 2.0 + 1.0) | 1


def gaussian_kernel(sigma: float, size: int | None = None) -> np.ndarray:
    r"""Normalized 1-D Gaussian kernel, ``cv2.getGaussianKernel(size, sigma)``.

    .. math:: w_i = \frac{\exp(-x_i^2 / 2\sigma^2)}{\sum_j \exp(-x_j^2 / 2\sigma^2)},
              \quad x_i = i - \frac{n - 1}{2}

    With ``sigma = 0`` the standard deviation comes from the size, as in OpenCV:
    :math:`\sigma = 0.3 ((n - 1) / 2 - 1) + 0.8`; for ``n <= 9`` OpenCV (4.x) then uses
    fixed small kernels instead (``[1/4, 1/2, 1/4]`` for ``n = 3``, ``[1, 4, 6, 4, 1] / 16``
    for ``n = 5``, ...), and so does this function, so the result equals
    ``cv2.getGaussianKernel(size, 0)`` for every odd size.

    Parameters
    ----------
    sigma : float
        Standard deviation in pixels, > 0; or 0 to derive it from ``size``.
    size : int, optional
        Odd kernel length; by default :func:`gaussian_ksize` for float images,
        ``round(8 sigma + 1) | 1`` (covers +-4 sigma). Required when ``sigma = 0``.

    Returns
    -------
    (size,) float64 ndarray

    Examples
    --------
    >>> gaussian_kernel(0, 5) * 16
    array([1., 4., 6., 4., 1.])
    >>> gaussian_kernel(1.0).size
    9
    """
    sigma = check_real(sigma, "sigma", 0.0)
    if size is not None:
        size = check_odd_size(size, "size")
        _check_taps(size, "size", "pass a smaller odd size")
    if sigma == 0.0:
        if size is None:
            raise InputError(
                "sigma=0 derives sigma from the kernel size, as OpenCV: give the size "
                "(e.g. gaussian_kernel(0, 5)) or a sigma > 0"
            )
        if size in _SMALL_GAUSSIAN:
            return np.array(_SMALL_GAUSSIAN[size], dtype=np.float64)
        sigma = 0.3 * ((size - 1) * 0.5 - 1.0) + 0.8
    elif size is None:
        size = gaussian_ksize(sigma, np.float64)
    x = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    # (x / sigma)^2 rather than x^2 / sigma^2: sigma^2 underflows to 0 below 1e-162 and
    # would give 0/0 = NaN at the centre; this way a tiny sigma gives the impulse [.., 0,
    # 1, 0, ..] (the identity filter), its limit
    with np.errstate(over="ignore"):
        w = np.exp(-0.5 * np.square(x / sigma))
    return w / w.sum()


def gaussian_kernel_fixed(sigma: float, size: int, bits: int = 8) -> np.ndarray:
    r"""OpenCV's fixed-point Gaussian kernel: integer taps summing to :math:`2^{bits}`,
    those of ``cv2.GaussianBlur`` on uint8 images (``bits = 8``).

    OpenCV samples the Gaussian in float64 in its own order of operations
    (``getGaussianKernelBitExact``): with :math:`s = -	frac18 / \sigma^2` and
    :math:`t_i = \exp(s\, u_i^2)` at the doubled offsets :math:`u_i = 2 i + 1 - n`,
    :math:`w_i = t_i / (2 \sum_{i < n/2} t_i + 1)` (the centre's :math:`t = 1`); for
    :math:`\sigma \le 0` it takes :math:`\sigma = 0.15 n + 0.35` (one rounding, a fused
    multiply-add) or, for :math:`n \le 9`, the fixed small kernels of
    :func:`gaussian_kernel`. The taps are then rounded by error diffusion from the
    outside in (``getGaussianKernelFixedPoint_ED``): :math:`a_i = 2^{bits} w_i + e`,
    :math:`k_i = \operatorname{rint}(a_i)`, :math:`e = a_i - k_i`, mirrored, and the
    centre takes what is left of :math:`2^{bits}`.

    Parameters
    ----------
    sigma : float
        Standard deviation, or 0 (from ``size``, as :func:`gaussian_kernel`).
    size : int
        Odd kernel length.
    bits : int
        Fraction bits, 1 to 32.

    Returns
    -------
    (size,) int64 ndarray
        Symmetric, summing to ``2**bits``.

    Examples
    --------
    >>> gaussian_kernel_fixed(0, 5).tolist()
    [16, 64, 96, 64, 16]
    >>> int(gaussian_kernel_fixed(2.0, 13).sum())
    256
    """
    sigma = check_real(sigma, "sigma", 0.0)
    size = check_odd_size(size, "size")
    _check_taps(size, "size", "pass a smaller odd size")
    bits = check_int(bits, "bits", 1)
    if bits > 32:
        raise InputError(f"bits must be at most 32 (OpenCV's fixed-point kernels); got {bits}")
    if sigma == 0.0 and size in _SMALL_GAUSSIAN:
        w = np.array(_SMALL_GAUSSIAN[size], dtype=np.float64)
    else:
        if sigma == 0.0:  # 0.15 n + 0.35 rounded once, as OpenCV's mulAdd
            sigma = float(Fraction(size) * Fraction(0.15) + Fraction(0.35))
        with np.errstate(over="ignore", under="ignore", divide="ignore"):
            scale = np.float64(-0.125) / np.float64(sigma * sigma)  # -inf on underflow: an impulse
        half = size // 2
        u = np.arange(1 - size, 0, 2, dtype=np.float64)  # the doubled offsets left of centre
        with np.errstate(over="ignore", under="ignore"):
            t = np.exp(u * u * scale)
        total = 0.0
        for v in t.tolist():  # summed in order, as OpenCV
            total += v
        inv = 1.0 / (total * 2.0 + 1.0)
        w = np.empty(size, dtype=np.float64)
        w[:half] = t * inv
        w[half + 1 :] = w[:half][::-1]
        w[half] = inv
    one = 1 << bits
    taps = np.empty(size, dtype=np.int64)
    err, total_taps = 0.0, 0
    for i in range(size // 2):
        adjusted = float(w[i]) * one + err
        k = int(np.rint(adjusted))  # cvRound: to nearest, ties to even
        err = adjusted - k
        taps[i] = taps[size - 1 - i] = k
        total_taps += k
    taps[size // 2] = one - 2 * total_taps
    return taps


def _make_gaussian(stride: int, integer: bool) -> Callable[..., None]:
    """Compile the Gaussian for one tap stride (1 or 3), for uint8 (``integer``:
    OpenCV's fixed-point taps) or float32/float64 images; both are compile-time
    constants, so LLVM sees a literal stride and numba drops the other type's
    branches."""

    @njit(cache=True, nogil=True)
    def blur(src, kx, ky, cidx, ridx, out):  # pragma: no cover - compiled
        """out = kx (horizontal) o ky (vertical) correlation of src with symmetric
        kernels; a border index -1 reads 0. src, out: (H, W*C).

        Mirrored rows (and columns) are added before their one multiply, two pairs
        per pass, as OpenCV's symmetric column and row filters do: a third fewer
        operations than a multiply and an add per tap. uint8: integer taps of sum 256
        each (gaussian_kernel_fixed), vertical sums in uint16 (at most 255 * 256),
        horizontal in uint32, out = (sum + 2^15) >> 16, exact, so equal to OpenCV's
        horizontal-first order; sixteen and eight lanes. Float: the image's type."""
        s = stride
        height, n = out.shape
        nx, ny = kx.shape[0], ky.shape[0]
        ax, ay = nx // 2, ny // 2
        # one row's vertical sums, padded by the border columns
        col = np.zeros(cidx.shape[0] * s, np.uint16 if integer else src.dtype)
        acc = np.empty(n if integer else 0, np.uint32)
        zero = np.zeros(n, src.dtype)
        wz = np.zeros(1, ky.dtype)[0]  # a weight 0 of the taps' type
        inner = col[ax * s : ax * s + n]
        for y in range(height):
            # the centre row joins the first pass of mirrored pairs (taken out of the
            # loop by LLVM: the test on `first` does not change within a row)
            r = ridx[y + ay]
            row, wc = (src[r] if r >= 0 else zero), ky[ay]
            if ay == 0:
                for x in range(n):
                    inner[x] = wc * row[x]
            t, first = 0, True
            while t < ay:
                # up to three mirrored pairs per pass; a pass of fewer repeats its
                # first pair with weight 0
                g = min(3, ay - t)
                k2, k3 = (t + 1 if g == 3 else t), (t + g - 1)
                ra, rb, w = ridx[y + t], ridx[y + ny - 1 - t], ky[t]
                rc, rd, v = ridx[y + k2], ridx[y + ny - 1 - k2], (ky[k2] if g == 3 else wz)
                re, rf, u = ridx[y + k3], ridx[y + ny - 1 - k3], (ky[k3] if g >= 2 else wz)
                a, b = (src[ra] if ra >= 0 else zero), (src[rb] if rb >= 0 else zero)
                c, d = (src[rc] if rc >= 0 else zero), (src[rd] if rd >= 0 else zero)
                e, f = (src[re] if re >= 0 else zero), (src[rf] if rf >= 0 else zero)
                if integer:
                    for x in range(n):
                        base = wc * np.uint16(row[x]) if first else inner[x]
                        inner[x] = (
                            base
                            + w * (np.uint16(a[x]) + b[x])
                            + v * (np.uint16(c[x]) + d[x])
                            + u * (np.uint16(e[x]) + f[x])
                        )
                else:
                    for x in range(n):
                        base = wc * row[x] if first else inner[x]
                        inner[x] = base + w * (a[x] + b[x]) + v * (c[x] + d[x]) + u * (e[x] + f[x])
                t, first = t + g, False
            for b in range(nx - 1):  # the padded columns: ax before, as many after
                p = b if b < ax else cidx.shape[0] - (nx - 1) + b
                j = cidx[p]
                for c in range(s):
                    col[p * s + c] = 0 if j < 0 else col[(j + ax) * s + c]
            o = out[y]
            res = acc if integer else o  # the horizontal sums, passes as above
            wc = kx[ax]
            if ax == 0:
                for x in range(n):
                    res[x] = wc * inner[x] if not integer else np.uint32(wc) * inner[x]
            t, first = 0, True
            while t < ax:
                g = min(3, ax - t)
                k2, k3 = (t + 1 if g == 3 else t), (t + g - 1)
                w, lo, hi = kx[t], col[t * s :], col[(nx - 1 - t) * s :]
                v, lo2, hi2 = (kx[k2] if g == 3 else wz), col[k2 * s :], col[(nx - 1 - k2) * s :]
                u, lo3, hi3 = (kx[k3] if g >= 2 else wz), col[k3 * s :], col[(nx - 1 - k3) * s :]
                if integer:
                    for x in range(n):
                        base = np.uint32(wc) * inner[x] if first else res[x]
                        res[x] = (
                            base
                            + w * (np.uint32(lo[x]) + hi[x])
                            + v * (np.uint32(lo2[x]) + hi2[x])
                            + u * (np.uint32(lo3[x]) + hi3[x])
                        )
                else:
                    for x in range(n):
                        base = wc * inner[x] if first else res[x]
                        res[x] = (
                            base
                            + w * (lo[x] + hi[x])
                            + v * (lo2[x] + hi2[x])
                            + u * (lo3[x] + hi3[x])
                        )
                t, first = t + g, False
            if integer:
                for x in range(n):
                    o[x] = (acc[x] + 32768) >> 16

    return blur


_gaussian_u8_gray = _make_gaussian(1, True)
_gaussian_u8_rgb = _make_gaussian(3, True)
_gaussian_float_gray = _make_gaussian(1, False)
_gaussian_float_rgb = _make_gaussian(3, False)


def _gaussian_size(sigma: float, size: int, dtype: np.dtype, flag: str) -> int:
    # the kernel size of one axis of gaussian_blur: size 0 is automatic (OpenCV's rule)
    if size == 0:
        if sigma == 0.0:
            raise InputError(
                f"sigma=0 needs the {flag} to derive sigma from, as OpenCV: pass an odd "
                "ksize (e.g. ksize=5) or sigma > 0 (the size then follows OpenCV's rule)"
            )
        size = gaussian_ksize(sigma, dtype)
    return size


@functools.lru_cache(maxsize=64)
def _gaussian_taps(sigma: float, size: int, dtype: str) -> np.ndarray:
    """The taps of one axis for :func:`gaussian_blur`'s compiled passes, computed once
    per (sigma, size, image dtype): OpenCV's 8-bit fixed-point kernel as uint16 for
    uint8 images, the float kernel in the image's type for float32 and float64 (the
    kernels cost more than filtering a small image). Internal: never handed out."""
    if dtype == "uint8":
        return gaussian_kernel_fixed(sigma, size).astype(np.uint16)
    return gaussian_kernel(sigma, size).astype(dtype)


def _pair(value: object, name: str) -> tuple[int, int]:
    """An ``int`` or a ``(width, height)`` pair of ints as ``(width, height)``, refusing
    other types (floats, strings, NaN, other lengths) with an InputError naming ``name``."""
    if type(value) is int:  # the common case, a microsecond sooner
        return value, value
    pair = (value, value) if not isinstance(value, (tuple, list)) else tuple(value)
    ok = len(pair) == 2 and all(
        isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in pair
    )
    if not ok:
        raise InputError(
            f"{name} must be an int or (width, height) of ints; got {plain_repr(value)}"
        )
    return int(pair[0]), int(pair[1])


def _is_size_pair(value: object) -> bool:
    # OpenCV's ksize: a (width, height) tuple or list (or a 1-D array of two)
    if isinstance(value, np.ndarray):
        return value.ndim == 1
    return isinstance(value, (tuple, list))


def gaussian_blur(
    image: np.ndarray,
    sigma: float | tuple[int, int] | None = None,
    sigmaX: float | None = None,
    *,
    ksize: int | tuple[int, int] | None = None,
    sigma_y: float | None = None,
    border: Border = "reflect101",
    sigmaY: float | None = None,
) -> np.ndarray:
    r"""Gaussian smoothing, separable: :func:`gaussian_kernel` along x, then along y.

    .. math:: g = G_{\sigma_y} \star_y (G_{\sigma_x} \star_x f)

    Two call shapes, the same filter:

    - ours, ``gaussian_blur(image, sigma, ksize=None, sigma_y=None)``: the size follows
      from ``sigma`` unless given;
    - OpenCV's positional order, ``gaussian_blur(image, (kw, kh), sigmaX)`` as
      ``cv2.GaussianBlur(image, (kw, kh), sigmaX)``, told apart by the second argument
      being a ``(width, height)`` pair; ``sigmaX`` may be left out (0: from the size),
      and ``sigmaY=`` / ``sigma_y=`` follow by keyword (OpenCV's fourth positional is its
      output array, so there is no positional ``sigmaY``). The keyword form
      ``gaussian_blur(image, ksize=(5, 5), sigmaX=0)`` works too.

    The same filter as ``cv2.GaussianBlur(image, ksize, sigma, sigmaY=sigma_y)``, with the
    same defaults: without ``ksize`` each axis' kernel size is :func:`gaussian_ksize`,
    ``round(2 t sigma + 1) | 1`` with ``t = 3`` for uint8 and ``t = 4`` for every other
    dtype (so ``gaussian_blur(f, 2.0)`` uses 13 taps on uint8 and 17 on float images);
    ``sigma = 0`` with a ``ksize`` derives sigma from the size as
    :func:`gaussian_kernel` (``0.3 ((ksize - 1) / 2 - 1) + 0.8``, OpenCV's fixed kernels
    up to 9 taps). The result equals OpenCV's to float rounding for float input, and
    bit for bit for uint8: there OpenCV rounds each kernel to 8-bit fixed point
    (:func:`gaussian_kernel_fixed`) and filters in integers, and so does this function
    (vertical sums in uint16 and horizontal in uint32, mirrored taps added before their
    one multiply).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    sigma : float or (width, height)
        Standard deviation along x (and y unless ``sigma_y``), >= 0; 0 takes it from
        ``ksize``. A ``(width, height)`` pair here is OpenCV's ``ksize`` in OpenCV's
        positional order (see above).
    sigmaX : float, optional
        OpenCV's name of ``sigma``: the third positional argument after an OpenCV
        ``ksize`` pair, or a keyword alias of ``sigma``.
    ksize : int or (width, height), optional
        Odd kernel size for both axes, or per axis as OpenCV's ``(kw, kh)``; 0 (or None)
        for the automatic size above.
    sigma_y : float, optional
        Standard deviation along y; None or 0 means ``sigma``, as OpenCV's ``sigmaY=0``.
    border : {'reflect101', 'reflect', 'replicate', 'constant'}
    sigmaY : float, optional
        Keyword-only alias (OpenCV's name) of ``sigma_y``.

    Returns
    -------
    ndarray
        Same shape and dtype as ``image``.

    Raises
    ------
    InputError
        If ``sigma`` (or ``sigma_y``) is negative, a ``ksize`` is even, an axis has
        neither a sigma nor a kernel size, no sigma is given at all, or one value is
        given under both of its spellings (``sigma`` and ``sigmaX``, ``sigma_y`` and
        ``sigmaY``, a positional ``(kw, kh)`` and ``ksize=``).

    Examples
    --------
    An impulse spreads into the (normalized) Gaussian kernel itself:

    >>> img = np.zeros((5, 5)); img[2, 2] = 1.0
    >>> out = gaussian_blur(img, 1.0, ksize=3)
    >>> np.round(out[1:4, 1:4], 4)
    array([[0.0751, 0.1238, 0.0751],
           [0.1238, 0.2042, 0.1238],
           [0.0751, 0.1238, 0.0751]])
    >>> round(float(out.sum()), 12)
    1.0

    OpenCV's order gives the same result:

    >>> bool((gaussian_blur(img, (3, 3), 1.0) == out).all())
    True
    """
    image = check_image(image)
    check_choice(border, "border", BORDERS)
    if _is_size_pair(sigma):  # OpenCV's order: (image, ksize, sigmaX)
        if ksize is not None:
            raise InputError(
                f"ksize given twice: {plain_repr(sigma)} as the second positional argument "
                f"(OpenCV's order: image, ksize, sigmaX) and ksize={plain_repr(ksize)}: "
                "drop one"
            )
        ksize = _pair(
            tuple(sigma) if isinstance(sigma, np.ndarray) else sigma,
            "ksize (a pair as the second argument: OpenCV's order image, ksize, sigmaX)",
        )
        sigma = 0.0 if sigmaX is None else sigmaX
    else:
        if sigma is not None and sigmaX is not None:
            raise InputError(
                f"give sigma or its OpenCV spelling sigmaX, not both (got sigma="
                f"{plain_repr(sigma)} and sigmaX={plain_repr(sigmaX)}): a third positional "
                "argument is OpenCV's sigmaX after a (width, height) ksize, as in "
                "gaussian_blur(image, (5, 5), 0)"
            )
        sigma = sigmaX if sigma is None else sigma
        if sigma is None:
            raise InputError(
                "gaussian_blur needs sigma (gaussian_blur(image, 1.5)) or OpenCV's ksize "
                "and sigmaX (gaussian_blur(image, (5, 5), 0)); got neither"
            )
    sy_given = resolve_alias(sigma_y, "sigma_y", sigmaY, "sigmaY", "OpenCV")
    sx = check_real(sigma, "sigma", 0.0)
    sy = sx if sy_given is None else check_real(sy_given, "sigma_y", 0.0)
    if sy == 0.0:  # OpenCV: sigmaY <= 0 takes sigmaX
        sy = sx
    kw, kh = _pair(0 if ksize is None else ksize, "ksize")
    for k in (kw, kh):
        if k != 0:  # 0 is automatic, as OpenCV's (0, 0)
            _check_taps(check_odd_size(k, "ksize"), "ksize", "pass a smaller odd ksize")
    nx = _gaussian_size(sx, kw, image.dtype, "kernel width")
    ny = nx if (sy, kh) == (sx, kw) else _gaussian_size(sy, kh, image.dtype, "kernel height")
    if image.dtype in (np.uint8, np.float32, np.float64):
        # mirrored taps added first, as OpenCV's symmetric filters; uint8 with OpenCV's
        # fixed-point kernels in integers (its result to the bit), float in the
        # image's type (within 3e-7 of OpenCV on [0, 1] float32 data)
        u8 = image.dtype == np.uint8
        tx = _gaussian_taps(sx, nx, image.dtype.name)
        ty = _gaussian_taps(sy, ny, image.dtype.name)
        src, channels = _as_rows(image)
        h, w = image.shape[:2]
        cidx = _border_map(w, tx.size // 2, tx.size // 2, border)
        ridx = _border_map(h, ty.size // 2, ty.size // 2, border)
        out = np.empty_like(src)
        gray, rgb = (
            (_gaussian_u8_gray, _gaussian_u8_rgb)
            if u8
            else (_gaussian_float_gray, _gaussian_float_rgb)
        )
        (gray if channels == 1 else rgb)(src, tx, ty, cidx, ridx, out)
        return out.reshape(image.shape)
    kx = gaussian_kernel(sx, nx)
    ky = kx if (sy, ny) == (sx, nx) else gaussian_kernel(sy, ny)
    return separable_filter_unchecked(image, kx, ky, border, 0.0, image.dtype)


def box_filter(
    image: np.ndarray,
    ksize: int | tuple[int, int],
    *,
    normalize: bool = True,
    border: Border = "reflect101",
) -> np.ndarray:
    r"""Box (mean) filter: the sum over a ``kw x kh`` window, divided by ``kw kh``.

    .. math:: g(x, y) = \frac{1}{k_w k_h} \sum_{|i| \le k_h/2,\,|j| \le k_w/2} f(x + j, y + i)

    Matches ``cv2.blur`` (``normalize=True``) and ``cv2.boxFilter``. With
    ``normalize=False`` the window sum is returned as float32 (float64 for float64 input).

    A uint8 mean over an odd window from 3x3 up to :data:`BOX_INT_MAX` (15) keeps the
    window's column sums in uint16, updated by one row in and one out per output row, so
    a pixel costs the same for every window height, and divides by multiply-high
    (:func:`~robopercept.imaging.fixed_point.rounding_divisor`, sixteen lanes at once);
    the means are those of the float32 separable path the other cases take, the exact
    :math:`\operatorname{round}(S / (k_w k_h))` (tested on every sum of every such
    window).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    ksize : int or (kw, kh)
        Window size (any positive size; even sizes anchor at ``k // 2``).
    normalize : bool
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    ndarray
        Same dtype as ``image`` when normalized.
    """
    image = check_image(image)
    check_choice(border, "border", BORDERS)
    normalize = check_bool(normalize, "normalize")
    kw, kh = _pair(ksize, "ksize")
    for name, k in (("ksize (width)", kw), ("ksize (height)", kh)):
        if k < 1:
            raise InputError(f"{name} must be a positive integer; got {k!r}")
        _check_taps(k, name, "pass a smaller window")
    divisor = (
        rounding_divisor(kw * kh, 255 * kw * kh)
        if normalize and image.dtype == np.uint8 and max(kw, kh) <= BOX_INT_MAX
        else None
    )
    if divisor is not None:
        # the window sums in integers, the means rounded by multiply-high
        src, channels = _as_rows(image)
        h, w = image.shape[:2]
        cidx = _border_map(w, kw // 2, kw // 2, border)
        ridx = _border_map(h, kh // 2, kh // 2, border)
        out = np.empty_like(src)
        kernel = _box_u8_gray if channels == 1 else _box_u8_rgb
        kernel(src, cidx, ridx, kw, kh, kw // 2, *divisor, out)
        return out.reshape(image.shape)
    scale_x = 1.0 / kw if normalize else 1.0
    scale_y = 1.0 / kh if normalize else 1.0
    kx = np.full(int(kw), scale_x)
    ky = np.full(int(kh), scale_y)
    out_dtype = image.dtype if normalize else _out_dtype(image, False)
    return separable_filter_unchecked(image, kx, ky, border, 0.0, out_dtype)


#: the widest odd box window :func:`box_filter` sums in integers for uint8 images: the
#: sum of up to 225 pixels fits uint16 (255 * 225 = 57,375, plus the rounding bias
#: 112), and the float32 path it replaces rounds every window mean the same way (its
#: error, under (kw + kh) * 255 * 2**-24, stays below half the 1 / (kw kh) gap that
#: keeps a mean off a rounding tie)
BOX_INT_MAX = 15


# fmt: off
def _make_box_u8(stride: int) -> Callable[..., None]:
    """Compile the uint8 box mean in integers for one channel count (1 or 3, a
    compile-time constant so that LLVM vectorizes the passes)."""

    @njit(cache=True, nogil=True)
    def box(src, cidx, ridx, kw, kh, ax, bias, mult, shift, out):  # pragma: no cover
        """out = round(S / (kw kh)) = mulhi_u16(S + bias, mult, shift) (constants from
        rounding_divisor), S the window sum; src, out: (H, W*C) uint8.

        The window's column sums are kept in uint16 and updated by one row in and one
        row out per output row. Outputs whose window lies inside the row add ``kw``
        shifted slices of the column sums; the ``kw - 1`` outputs at the row's ends
        read the column sums through the border map."""
        s = stride
        height, n = out.shape
        w = n // s
        col = np.zeros(n, np.uint16)
        lo = ax * s  # the outputs [lo, hi) have their whole window inside the row
        hi = max(lo, n - (kw - 1 - ax) * s)
        m = hi - lo
        acc = np.empty(m, np.uint16)
        for i in range(kh):
            r = ridx[i]
            if r >= 0:
                row = src[r]
                for x in range(n):
                    col[x] += row[x]
        for y in range(height):
            r_in = ridx[y + kh - 1] if y > 0 else -1
            r_out = ridx[y - 1] if y > 0 else -1
            if r_in >= 0 and r_out >= 0:  # one row in, one out, fused
                new, old = src[r_in], src[r_out]
                for x in range(n):
                    col[x] = col[x] + new[x] - old[x]
            else:
                if r_in >= 0:
                    new = src[r_in]
                    for x in range(n):
                        col[x] += new[x]
                if r_out >= 0:
                    old = src[r_out]
                    for x in range(n):
                        col[x] -= old[x]
            o = out[y]
            inner = o[lo:hi]
            if kw == 3:  # the taps and the rounding in one pass
                c0, c1, c2 = col[:m], col[s : s + m], col[2 * s : 2 * s + m]
                for x in range(m):
                    v = np.uint16(c0[x] + c1[x] + c2[x] + bias)
                    inner[x] = np.uint8(mulhi_u16(v, mult, shift))
            elif kw == 5:
                c0, c1, c2 = col[:m], col[s : s + m], col[2 * s : 2 * s + m]
                c3, c4 = col[3 * s : 3 * s + m], col[4 * s : 4 * s + m]
                for x in range(m):
                    v = np.uint16(c0[x] + c1[x] + c2[x] + c3[x] + c4[x] + bias)
                    inner[x] = np.uint8(mulhi_u16(v, mult, shift))
            else:
                for x in range(m):
                    acc[x] = col[x] + bias
                for t in range(1, kw):
                    seg = col[t * s : t * s + m]
                    for x in range(m):
                        acc[x] += seg[x]
                for x in range(m):
                    inner[x] = np.uint8(mulhi_u16(acc[x], mult, shift))
            # the outputs whose window reaches past the row (every output of a row
            # narrower than the window), through the border map
            edges = kw - 1 if m > 0 else w
            for b in range(edges):
                px = b if b < ax or m == 0 else w - (kw - 1) + b
                for c in range(s):
                    total = np.uint16(bias)
                    for t in range(kw):
                        j = cidx[px + t]
                        if j >= 0:
                            total += col[j * s + c]
                    o[px * s + c] = np.uint8(mulhi_u16(total, mult, shift))

    return box
# fmt: on


_box_u8_gray = _make_box_u8(1)
_box_u8_rgb = _make_box_u8(3)


@njit(cache=True, nogil=True)
def _median_kernel(src, cidx, ridx, channels, k, out):  # pragma: no cover - compiled
    height = out.shape[0]
    width = cidx.shape[0] - k + 1
    win = np.empty(k * k, dtype=src.dtype)
    half = (k * k) // 2
    for y in range(height):
        for x in range(width):
            for c in range(channels):
                n = 0
                for i in range(k):
                    srow = src[ridx[y + i]]
                    for j in range(k):
                        v = srow[cidx[x + j] * channels + c]
                        # insertion sort keeps win[:n] ordered
                        m = n
                        while m > 0 and win[m - 1] > v:
                            win[m] = win[m - 1]
                            m -= 1
                        win[m] = v
                        n += 1
                out[y, x * channels + c] = win[half]


def median_filter(
    image: np.ndarray,
    ksize: int = 3,
    *,
    border: Literal["replicate", "reflect101", "reflect"] = "replicate",
) -> np.ndarray:
    """Median of each ``ksize x ksize`` window, per channel.

    Matches ``cv2.medianBlur(image, ksize)`` (which replicates the border) exactly.
    ``ksize`` 3 and 5 run as vectorized min/max networks on the window's sorted
    columns (:mod:`robopercept.imaging.median_networks`, at or below
    ``cv2.medianBlur``'s single-thread time); wider windows sort each window by
    insertion.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    ksize : int
        Odd window size, 3 to :data:`MAX_MEDIAN_KSIZE` (31): from 7 up the window is
        sorted by insertion, about ``ksize**4 / 4`` comparisons per pixel and channel.
    border : {'replicate', 'reflect101', 'reflect'}

    Returns
    -------
    ndarray
        Same shape and dtype as ``image``.
    """
    image = check_image(image)
    ksize = check_odd_size(ksize, "ksize", 3)
    if ksize > MAX_MEDIAN_KSIZE:
        raise InputError(
            f"ksize must be an odd integer in [3, {MAX_MEDIAN_KSIZE}]; got {ksize}: the "
            f"insertion sort costs about ksize**4 / 4 comparisons per pixel; for a wider "
            "window take the median of a downsampled image (robopercept.imaging.pyr_down)"
        )
    check_choice(border, "border", ("replicate", "reflect101", "reflect"))
    src, channels = _as_rows(image)
    h, w = image.shape[:2]
    r = ksize // 2
    cidx = _border_map(w, r, r, border)  # cached, read only
    ridx = _border_map(h, r, r, border)
    out = np.empty_like(src)
    # 3x3 and 5x5: min/max networks, vectorized (exact: the same selection)
    if ksize <= 5 and channels in (1, 3):
        median_rows(src, cidx, ridx, channels, ksize, out)
    else:
        _median_kernel(src, cidx, ridx, channels, ksize, out)
    return out.reshape(image.shape)


# --------------------------------------------------------------------------- derivatives
def derivative_kernel(order: int, ksize: int) -> np.ndarray:
    r"""1-D Sobel kernel: binomial smoothing of length ``ksize - order`` convolved
    ``order`` times with the difference ``[-1, 1]``.

    ``ksize=3`` gives ``[1, 2, 1]``, ``[-1, 0, 1]`` and ``[1, -2, 1]`` for orders 0, 1, 2:
    the kernels of ``cv2.getDerivKernels``. ``ksize=1`` means no smoothing: ``[1]`` for
    order 0, a 3-tap difference otherwise.

    Parameters
    ----------
    order : int
        Derivative order, 0 <= order < ksize (or <= 2 with ksize 1).
    ksize : int
        1, 3, 5 or 7.

    Returns
    -------
    (n,) float64 ndarray

    Raises
    ------
    InputError
        ``order`` not an integer in range, or ``ksize`` not 1, 3, 5 or 7.

    Examples
    --------
    >>> derivative_kernel(1, 5)
    array([-1., -2.,  0.,  2.,  1.])
    """
    order = check_int(order, "order", 0)
    ksize = _check_ksize(ksize)
    if ksize == 1:
        if order == 0:
            return np.ones(1)
        ksize = 3
    if order < 0 or order >= ksize:
        raise InputError(
            f"derivative order must be in [0, {ksize - 1}] for ksize {ksize}; got {order}"
        )
    return _derivative_taps(order, ksize).copy()


@functools.lru_cache(maxsize=64)
def _derivative_taps(order: int, ksize: int) -> np.ndarray:
    """The taps of :func:`derivative_kernel` (checked arguments), computed once."""
    k = np.ones(1)
    for _ in range(ksize - order - 1):
        k = np.convolve(k, [1.0, 1.0])
    for _ in range(order):
        k = np.convolve(k, [-1.0, 1.0])
    return k


def _check_ksize(ksize: int) -> int:
    integer = isinstance(ksize, (int, np.integer)) and not isinstance(ksize, (bool, np.bool_))
    if not integer or ksize not in (1, 3, 5, 7):
        raise InputError(f"ksize must be 1, 3, 5 or 7; got {ksize!r}")
    return int(ksize)


def sobel(
    image: np.ndarray,
    dx: int,
    dy: int,
    ksize: int = 3,
    *,
    scale: float = 1.0,
    border: Border = "reflect101",
) -> np.ndarray:
    r"""Sobel derivative :math:`\partial^{dx+dy} f / \partial x^{dx} \partial y^{dy}`.

    The separable kernel is ``derivative_kernel(dx, ksize)`` along x times
    ``derivative_kernel(dy, ksize)`` along y (for ``ksize=3, dx=1``:
    ``[[-1, 0, 1], [-2, 0, 2], [-1, 0, 1]]``), applied as a correlation, so a brightness
    that grows to the right gives a positive ``dx``. Matches
    ``cv2.Sobel(image, cv2.CV_32F, dx, dy, ksize=ksize, scale=scale)``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    dx, dy : int
        Derivative orders, ``dx + dy >= 1``.
    ksize : {1, 3, 5, 7}
    scale : float
        Factor applied to the result.
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    ndarray
        float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    check_choice(border, "border", BORDERS)
    ksize = _check_ksize(ksize)
    for name, v in (("dx", dx), ("dy", dy)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise InputError(f"{name} must be a non-negative integer; got {v!r}")
    if dx + dy < 1:
        raise InputError(f"dx + dy must be >= 1; got dx={dx}, dy={dy}")
    scale = check_real(scale, "scale")
    kx = derivative_kernel(int(dx), ksize) * scale
    ky = derivative_kernel(int(dy), ksize)
    return separable_filter_unchecked(image, kx, ky, border, 0.0, _out_dtype(image, False))


def gradient(
    image: np.ndarray, ksize: int = 3, *, border: Border = "reflect101"
) -> tuple[np.ndarray, np.ndarray]:
    r"""Gradient magnitude and direction from Sobel derivatives.

    .. math:: |\nabla f| = \sqrt{f_x^2 + f_y^2}, \qquad \theta = \operatorname{atan2}(f_y, f_x)

    ``theta`` is in radians in ``(-pi, pi]``, measured from +x towards +y (image down).
    A colour image is reduced per pixel to the channel of largest magnitude.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    ksize : {1, 3, 5, 7}
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    magnitude, direction : (H, W) ndarray
        float32 for integer input, else the input dtype.
    """
    gx = sobel(image, 1, 0, ksize, border=border)
    gy = sobel(image, 0, 1, ksize, border=border)
    mag = np.hypot(gx, gy)
    if mag.ndim == 3:
        best = np.argmax(mag, axis=2)[..., None]
        gx = np.take_along_axis(gx, best, 2)[..., 0]
        gy = np.take_along_axis(gy, best, 2)[..., 0]
        mag = np.take_along_axis(mag, best, 2)[..., 0]
    return mag, np.arctan2(gy, gx)


_LAPLACE_1 = np.array([[0.0, 1.0, 0.0], [1.0, -4.0, 1.0], [0.0, 1.0, 0.0]])
_LAPLACE_3 = np.array([[2.0, 0.0, 2.0], [0.0, -8.0, 0.0], [2.0, 0.0, 2.0]])


def laplacian(
    image: np.ndarray, ksize: int = 1, *, scale: float = 1.0, border: Border = "reflect101"
) -> np.ndarray:
    r"""Laplacian :math:`\nabla^2 f = f_{xx} + f_{yy}`.

    ``ksize=1`` uses the 5-point stencil ``[[0, 1, 0], [1, -4, 1], [0, 1, 0]]``,
    ``ksize=3`` the kernel ``[[2, 0, 2], [0, -8, 0], [2, 0, 2]]``, larger sizes the sum of
    the second Sobel derivatives: the kernels of ``cv2.Laplacian(image, cv2.CV_32F,
    ksize=ksize)``, which this matches.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    ksize : {1, 3, 5, 7}
    scale : float
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    ndarray
        float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    check_choice(border, "border", BORDERS)
    ksize = _check_ksize(ksize)
    scale = check_real(scale, "scale")
    out_dtype = _out_dtype(image, False)
    if ksize in (1, 3):
        kernel = (_LAPLACE_1 if ksize == 1 else _LAPLACE_3) * scale
        return _run_correlate(image, kernel, border, 0.0, out_dtype)
    d2 = derivative_kernel(2, ksize) * scale
    d0 = derivative_kernel(0, ksize)
    fxx = separable_filter_unchecked(image, d2, d0, border, 0.0, out_dtype)
    return fxx + separable_filter_unchecked(image, d0, d2, border, 0.0, out_dtype)


#: the smallest sigma of the unnormalized LoG: its centre weight -1/sigma^2 is 1e30 there,
#: which keeps the output of any image within float32
_LOG_MIN_SIGMA = 1e-15


def laplacian_of_gaussian(
    image: np.ndarray,
    sigma: float,
    *,
    normalized: bool = False,
    truncate: float = 4.0,
    border: Border = "reflect",
) -> np.ndarray:
    r"""Laplacian of Gaussian, by two separable passes.

    .. math::
        \nabla^2 (G_\sigma * f) = G''_\sigma(x) G_\sigma(y) * f + G_\sigma(x) G''_\sigma(y) * f,
        \qquad G''_\sigma(x) = G_\sigma(x) \left(\frac{x^2}{\sigma^4} - \frac{1}{\sigma^2}\right)

    with :math:`G_\sigma` sampled on ``|x| <= truncate * sigma`` and normalized to sum 1,
    exactly as ``scipy.ndimage.gaussian_laplace`` (whose default border ``reflect`` is the
    default here too). ``normalized=True`` multiplies by :math:`\sigma^2`, the
    scale-normalized LoG used for blob detection (its extrema at :math:`\sigma = r/\sqrt 2`).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    sigma : float
        > 0.
    normalized : bool
    truncate : float
        Kernel half-width in units of sigma.
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    ndarray
        float32 for integer input, else the input dtype.
    """
    image = check_image(image)
    sigma = check_real(sigma, "sigma", 0.0, low_inclusive=False)
    truncate = check_real(truncate, "truncate", 0.0, low_inclusive=False)
    normalized = check_bool(normalized, "normalized")
    check_choice(border, "border", BORDERS)
    if not normalized and sigma < _LOG_MIN_SIGMA:
        raise InputError(
            f"sigma={sigma:g} is too small for the unnormalized LoG: its centre weight "
            f"-1/sigma^2 overflows (sigma >= {_LOG_MIN_SIGMA:g}); pass normalized=True "
            "(the sigma^2-scaled LoG, finite for any sigma) or a larger sigma"
        )
    half = truncate * sigma + 0.5  # (the product before int(): 1e300 * 1e300 is inf)
    if half >= (MAX_KERNEL_SIZE + 1) / 2:
        raise InputError(
            f"truncate * sigma = {truncate * sigma:.3g} asks for a kernel of about "
            f"{2 * half:.3g} taps; at most {MAX_KERNEL_SIZE} are built: use a smaller "
            "sigma or truncate, or filter a downsampled image"
        )
    radius = int(half)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    u2 = np.square(x / sigma)  # as in gaussian_kernel: no sigma^2 that underflows
    g = np.exp(-0.5 * u2)
    g /= g.sum()
    # G'' sigma^2 = G (x^2 / sigma^2 - 1); taps whose weight underflowed to 0 stay 0
    g2n = np.where(g > 0, g * (u2 - 1.0), 0.0)
    g2 = g2n if normalized else g2n / (sigma * sigma)
    out_dtype = _out_dtype(image, False)
    # both kernels are symmetric, so correlation equals convolution here
    fxx = separable_filter_unchecked(image, g2, g, border, 0.0, out_dtype)
    return fxx + separable_filter_unchecked(image, g, g2, border, 0.0, out_dtype)
