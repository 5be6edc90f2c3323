r"""Dense stereo on a rectified pair: block matching and semi-global matching, and
disparity to depth.

For a rectified pair a left pixel :math:`(x, y)` matches the right pixel
:math:`(x - d, y)`; :math:`d` is the disparity, and the depth is

.. math::

    z = \frac{f B}{d}, \qquad \Delta z = \frac{z^2}{f B} \Delta d,

so one disparity step covers more depth the farther the point: the resolution falls
with the square of the distance.

**Block matching** compares windows: SAD :math:`\sum |L - R|`, SSD
:math:`\sum (L - R)^2` or zero-mean NCC (1 - correlation, the correlation clipped to
:math:`[-1, 1]` where a nearly flat window pushes it out) over a
``window x window`` square, and keeps the disparity of the lowest cost (winner takes
all). A large window is smooth but blurs depth edges and thin structure; a small one
keeps detail but is noisy where texture is weak.

**Semi-global matching** (Hirschmüller 2008) adds smoothness along ``paths``
directions :math:`r`: each path cost is

.. math::

    L_r(p, d) = C(p, d) + \min\bigl(L_r(p - r, d),\ L_r(p - r, d \pm 1) + P_1,\
        \min_k L_r(p - r, k) + P_2\bigr) - \min_k L_r(p - r, k),

small jumps cost :math:`P_1`, large ones :math:`P_2`, and the disparity minimizes
:math:`S(p, d) = \sum_r L_r(p, d)`. The pixel cost here is the Hamming distance of
census transforms (each pixel's window as bits "darker than the centre"), robust to
gain and bias between the cameras, summed over a small ``block``.

Both refine the winner by a parabola through its neighbours,
:math:`d^* = d + \frac{C_{d-1} - C_{d+1}}{2 (C_{d-1} - 2 C_d + C_{d+1})}`, can reject
ambiguous pixels (``uniqueness``: the best must beat every disparity more than one
step away by that fraction) and inconsistent ones (``lr_check``: the right image's
own winner must agree within that many pixels), and return NaN for rejected pixels.
The right image's winners come from the same cost volume (along its diagonals, as
Hirschmüller's :math:`D_m` and OpenCV's SGBM); near the left border, where the left
pixels see only part of the range, they lean to small disparities, so the check also
rejects winners at the lowest disparity searched: their cost minimum is not
bracketed, and the match may lie below the range (a pixel whose match left the right
image, or a background beyond the range). Columns left of the search range take only
the disparities that stay inside the right image (OpenCV marks the first
``numDisparities`` columns invalid instead).

**Swapped images.** A pair given right first has its true disparities negative, outside
every search range, and the matchers return noise: with the left-right check only part
of the pixels survive (48.5 % on Middlebury cones by SGM, against 88 %). When fewer
than :data:`SWAP_CHECK_BELOW` of the pixels are valid (or without the check, always),
both matchers run a quick test, as an OpenCV user would by trying the other order:
winner-takes-all SAD matching of the pair reduced to about 128 pixels wide, with a
left-right check, in both orders (10-60 ms). When the
exchanged order keeps at least 60 % of the pixels and 30 points more than the given one
(on the eight Middlebury pairs of the tests the right order keeps 87-99 %, the wrong
one 5-38 %), they warn with a :class:`~robopercept.errors.RoboperceptWarning` naming
both shares; the disparities are returned as computed.
"""

from __future__ import annotations

import warnings

import numba
import numpy as np
import numpy.typing as npt
from numba import njit, prange

from robopercept._checks import (
    check_bool,
    check_choice,
    check_finite,
    check_int,
    check_numeric,
    check_real,
    check_size,
)
from robopercept.errors import DegenerateError, InputError, RoboperceptWarning
from robopercept.imaging.color import gray_255

__all__ = [
    "bad_pixel_rate",
    "block_matching",
    "census_transform",
    "depth_resolution",
    "disparity_to_depth",
    "disparity_to_points",
    "reprojection_matrix",
    "semi_global_matching",
]

_BIG = 1 << 14  # path-cost sentinel beyond any reachable value (costs stay < 2^13)


def _pair(left: np.ndarray, right: np.ndarray, max_disparity: int, min_disparity: int):
    """The pair as gray 0-255 images and the disparity range as ints, checked."""
    L, R = gray_255(left, "left"), gray_255(right, "right")
    if L.shape != R.shape:
        raise InputError(
            f"left and right must have the same size; got {L.shape} and {R.shape}: "
            "rectify the pair first"
        )
    dmax = check_int(max_disparity, "max_disparity", 1)
    dmin = check_int(min_disparity, "min_disparity", 0)
    if not dmin < dmax:
        raise InputError(f"need 0 <= min_disparity < max_disparity; got {dmin} and {dmax}")
    if dmax >= L.shape[1]:
        raise InputError(f"max_disparity {dmax} must be below the image width {L.shape[1]}")
    return L, R, dmax, dmin


# ---------------------------------------------------------------- census
#
# The kernels below vectorize along one contiguous axis: x for the census, the
# disparity k for everything on the cost volume, whose layout is (y, x, k). The right
# image is read through row-reversed copies, so that R[x - dmin - k] is
# Rr[w - 1 - x + dmin + k], increasing with k. Path costs, window sums and winners
# are float32 (float64 where a sum can pass 2^24): every value is an integer below
# 2^24, so float arithmetic is exact in any order, and numba keeps float32 lanes
# where it would widen small integers to int64.


@njit(cache=True, parallel=True)
def _census_kernel(pad, r, out):  # pragma: no cover - compiled
    # pad: the image with r replicated pixels on every side
    h, w = out.shape
    for y in prange(h):
        bits = np.zeros(w, dtype=np.uint64)
        c = pad[y + r, r : r + w]
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                if dy == 0 and dx == 0:
                    continue
                nb = pad[y + r + dy, r + dx : r + dx + w]
                for x in range(w):
                    bits[x] = (bits[x] << np.uint64(1)) | np.uint64(nb[x] < c[x])
        out[y] = bits


def _census_window(window: int, name: str) -> int:
    """``window`` as an int after checking that it is 3, 5 or 7 (InputError naming ``name``)."""
    w = check_int(window, name)
    if w not in (3, 5, 7):
        raise InputError(
            f"{name} (the census window) must be 3, 5 or 7 (its bits must fit in 64); got {w}"
        )
    return w


def census_transform(image: np.ndarray, window: int = 7) -> np.ndarray:
    """Census transform: per pixel, one bit per neighbour in the ``window`` (odd, at
    most 7 so the bits fit in 64), set where the neighbour is darker than the centre
    (borders replicated). Returns (H, W) uint64.

    Examples
    --------
    A bright centre pixel: all eight neighbours of a 3x3 window are darker.

    >>> img = np.zeros((3, 3), np.uint8); img[1, 1] = 9
    >>> int(census_transform(img, 3)[1, 1])
    255
    """
    window = _census_window(window, "window")
    g = gray_255(image, "image")
    r = window // 2
    out = np.empty(g.shape, dtype=np.uint64)
    _census_kernel(np.pad(g, r, mode="edge"), r, out)
    return out


@njit(cache=True, inline="always")
def _popcount(v):  # pragma: no cover - compiled
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (v * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True, fastmath=True, inline="always")
def _hamming_row(cl, crr, yy, dmin, invalid, out, slot):  # pragma: no cover - compiled
    # out[slot, x, k] = Hamming(cl[yy, x], cr[yy, x - dmin - k]), ``invalid`` where x - dmin
    # - k falls outside; crr holds cr's rows reversed (crr[y, w - 1 - x] = cr[y, x])
    # (1-D row slices: an index of unknown sign, as base + k, makes numba wrap it per
    # element and keeps the loop from vectorizing)
    _, w, nd = out.shape
    for x in range(w):
        a = cl[yy, x]
        base = w - 1 - x + dmin
        kmax = x - dmin
        rr = crr[yy, base : base + nd]
        o = out[slot, x]
        for k in range(nd):
            v = np.float32(np.int32(_popcount(a ^ rr[k])))
            o[k] = v if k <= kmax else invalid


@njit(cache=True, fastmath=True, inline="always")
def _window_start(col, r, acc):  # pragma: no cover - compiled
    # acc[k] = sum of col[clip(x, 0, w - 1), k] for x in -r..r: the window at column 0,
    # borders replicated
    w, nd = col.shape
    for k in range(nd):
        acc[k] = col[0, k] * (r + 1)
    for t in range(1, r + 1):
        xx = min(t, w - 1)
        for k in range(nd):
            acc[k] += col[xx, k]


@njit(cache=True, fastmath=True, inline="always")
def _window_move(col, x, r, acc):  # pragma: no cover - compiled
    # slide the window sums acc from column x to x + 1 (borders replicated)
    w, nd = col.shape
    xi = min(x + r + 1, w - 1)
    xo = max(x - r, 0)
    for k in range(nd):
        acc[k] += col[xi, k] - col[xo, k]


@njit(cache=True, parallel=True, fastmath=True)
def _census_block_cost(cl, crr, dmin, r, invalid, rings, cols, out):  # pragma: no cover
    # out[y, x, k] = sum of the Hamming costs over the (2r+1)^2 block around (y, x),
    # borders replicated. Per chunk of rows: the block's 2r+1 cost rows in a ring
    # (rings[c]), their column sums (cols[c]) moved one row at a time, then running
    # sums along x.
    h, w = cl.shape
    n_chunks, _, nd = cols.shape
    n = 2 * r + 1
    step = (h + n_chunks - 1) // n_chunks
    for c in prange(n_chunks):
        y0 = c * step
        y1 = min(h, y0 + step)
        ring = rings[c]
        col = cols[c]
        acc = np.zeros(nd, dtype=np.float32)
        for y in range(y0, y1):
            if y == y0:
                col[:] = 0
                for t in range(n):
                    _hamming_row(cl, crr, min(max(y - r + t, 0), h - 1), dmin, invalid, ring, t)
                    for x in range(w):
                        for k in range(nd):
                            col[x, k] += ring[t, x, k]
            else:
                # the slot of row y - r - 1 (entered 2r + 1 rows ago) takes row y + r
                slot = (y - y0 - 1) % n
                for x in range(w):
                    for k in range(nd):
                        col[x, k] -= ring[slot, x, k]
                _hamming_row(cl, crr, min(y + r, h - 1), dmin, invalid, ring, slot)
                for x in range(w):
                    for k in range(nd):
                        col[x, k] += ring[slot, x, k]
            _window_start(col, r, acc)
            for x in range(w):
                for k in range(nd):
                    out[y, x, k] = np.uint16(np.int32(acc[k]))
                _window_move(col, x, r, acc)


# ---------------------------------------------------------------- SGM aggregation


@njit(cache=True, inline="always")
def _row_min(Qi, o, box, boxi, nd):  # pragma: no cover - compiled
    # min of row o's costs 1..nd, found on the int32 view Qi (floats >= 0 order like
    # their bits, and int32 minima vectorize where float ones do not); box/boxi (a
    # float32 array of one and its int32 view) turn the bits back. The scan covers all
    # nd entries, the first twice: with nd a multiple of the vector width no element is
    # left to a scalar tail (the 63 after the first took 4x as long).
    best = Qi[o, 1]
    for k in range(1, nd + 1):
        q = Qi[o, k]
        best = q if q < best else best
    boxi[0] = best
    return box[0]


@njit(cache=True, fastmath=True, inline="always")
def _step(cost, y, x, P, pr, pmin, p1, p2, Q, o, Qi, box, boxi, nd):  # pragma: no cover
    # Q[o, k+1] = C[k] + min(P[pr, k+1], P[pr, k] + P1, P[pr, k+2] + P1, pmin + P2) - pmin
    # with C = cost[y, x]; rows of P and Q are padded with the sentinel at 0 and nd + 1.
    # Returns min_k Q[o, k+1] (_row_min). Whole arrays and indices, not row views, keep
    # numba from reference-counting a view per call.
    m = pmin + p2
    for k in range(nd):
        v = P[pr, k + 1]
        a = P[pr, k] + p1
        b = P[pr, k + 2] + p1
        v = a if a < v else v
        v = b if b < v else v
        v = m if m < v else v
        Q[o, k + 1] = v - pmin + np.float32(cost[y, x, k])
    return _row_min(Qi, o, box, boxi, nd)


@njit(cache=True, fastmath=True, inline="always")
def _start(cost, y, x, Q, o, Qi, box, boxi, nd):  # pragma: no cover - compiled
    # a path's first pixel: Q[o, k+1] = C[k]; returns its minimum (as _step)
    for k in range(nd):
        Q[o, k + 1] = np.float32(cost[y, x, k])
    return _row_min(Qi, o, box, boxi, nd)


@njit(cache=True, inline="always")
def _copy_row(src, i, dst, j, n):  # pragma: no cover - compiled
    for k in range(n):
        dst[j, k] = src[i, k]


@njit(cache=True, parallel=True, fastmath=True)
def _sgm_passes(cost, p1, p2, paths, s_out):  # pragma: no cover - compiled
    # Two independent passes, one per thread, each writing its own sum of path costs
    # s_out[pass]: top-down with x rising (paths from the left, above, upper left and
    # upper right) and bottom-up with x falling (the four opposite ones). Per pass,
    # one row of path costs per direction (float32, padded with a sentinel at both
    # ends of the disparity axis) is updated in place: the vertical and the "ahead"
    # diagonal (from x + dx, not visited yet in this row) write column x at once; the
    # "behind" diagonal (from x - dx) holds the new costs of x - dx until x has read
    # the old ones.
    h, w, nd = cost.shape
    big = np.float32(_BIG)
    for job in prange(2):
        s = s_out[job]
        down = job == 0
        dx = 1 if down else -1
        V = np.full((w, nd + 2), big, dtype=np.float32)
        A = np.full((w, nd + 2), big, dtype=np.float32)  # behind: from x - dx
        B = np.full((w, nd + 2), big, dtype=np.float32)  # ahead: from x + dx
        mV = np.zeros(w, dtype=np.float32)
        mA = np.zeros(w, dtype=np.float32)
        mB = np.zeros(w, dtype=np.float32)
        # this pixel's new costs: rows 0/1 horizontal (this and the previous pixel, in
        # turn), 2 vertical, 3/4 behind (this and the held one, in turn), 5 ahead
        T = np.full((6, nd + 2), big, dtype=np.float32)
        Ti = T.view(np.int32)
        box = np.zeros(1, dtype=np.float32)
        boxi = box.view(np.int32)
        for i in range(h):
            y = i if down else h - 1 - i
            hm = big
            am_held = big
            hc, hp, ta, th = 0, 1, 3, 4
            x = 0
            for j in range(w):
                x = j if down else w - 1 - j
                if j == 0:
                    hm = _start(cost, y, x, T, hc, Ti, box, boxi, nd)
                else:
                    hm = _step(cost, y, x, T, hp, hm, p1, p2, T, hc, Ti, box, boxi, nd)
                if i == 0:
                    vm = _start(cost, y, x, T, 2, Ti, box, boxi, nd)
                else:
                    vm = _step(cost, y, x, V, x, mV[x], p1, p2, T, 2, Ti, box, boxi, nd)
                if paths == 8:
                    xa = x - dx
                    xb = x + dx
                    if i == 0 or j == 0:
                        am = _start(cost, y, x, T, ta, Ti, box, boxi, nd)
                    else:
                        am = _step(cost, y, x, A, xa, mA[xa], p1, p2, T, ta, Ti, box, boxi, nd)
                    if i == 0 or j == w - 1:
                        bm = _start(cost, y, x, T, 5, Ti, box, boxi, nd)
                    else:
                        bm = _step(cost, y, x, B, xb, mB[xb], p1, p2, T, 5, Ti, box, boxi, nd)
                    if j > 0:  # x has read the old A[x - dx]: store the held new one
                        _copy_row(T, th, A, xa, nd + 2)
                        mA[xa] = am_held
                    ta, th = th, ta
                    am_held = am
                    _copy_row(T, 5, B, x, nd + 2)
                    mB[x] = bm
                    for k in range(nd):
                        t = T[hc, k + 1] + T[2, k + 1] + T[th, k + 1] + T[5, k + 1]
                        s[y, x, k] = np.uint16(t)
                else:
                    for k in range(nd):
                        s[y, x, k] = np.uint16(T[hc, k + 1] + T[2, k + 1])
                _copy_row(T, 2, V, x, nd + 2)
                mV[x] = vm
                hc, hp = hp, hc
            if paths == 8:
                _copy_row(T, th, A, x, nd + 2)
                mA[x] = am_held


# ---------------------------------------------------------------- winner takes all

_FAR = 3.0e38  # finite "no cost yet" (the kernels are compiled with fast-math)


@njit(cache=True, fastmath=True, inline="always")
def _wta_row(C, Ci, y, dmin, uniqueness, subpixel, want_right, ks, ksi, rb, rk,
             disp, right):  # fmt: skip  # pragma: no cover - compiled
    # C[x, k] >= 0: cost of disparity dmin + k at left column x, Ci its integer view
    # (same width). Left winners use only the disparities that keep x - d inside the
    # right image; right winners (for the consistency check, when ``want_right``)
    # those that keep xr + d inside the left image, gathered in rb/rk reversed (index
    # w - 1 - xr) so that both run along k. Ties go to the smallest disparity. ks, ksi:
    # 0..nd-1 as float32 and int32.
    w, nd = C.shape
    if want_right:
        for j in range(rb.shape[0]):
            rb[j] = _FAR
            rk[j] = -1.0
    for x in range(w):
        kmax = min(nd - 1, x - dmin)
        if kmax < 0:
            disp[y, x] = np.nan
            continue
        row = C[x]
        rowi = Ci[x]
        # the minimum and its first index, on the bits (costs are >= 0): integer
        # minima vectorize
        bi = rowi[0]  # all kmax + 1 entries, no scalar tail (see _row_min)
        for k in range(kmax + 1):
            v = rowi[k]
            bi = v if v < bi else bi
        kb = np.int32(nd)
        for k in range(kmax + 1):
            j = ksi[k] if rowi[k] == bi else np.int32(nd)  # int32 throughout, to vectorize
            kb = j if j < kb else kb
        best = row[kb]
        if want_right:
            base = w - 1 - x + dmin
            rbx = rb[base : base + kmax + 1]  # row slices: see _hamming_row
            rkx = rk[base : base + kmax + 1]
            for k in range(kmax + 1):
                v = row[k]
                o = rbx[k]
                m = v < o
                rbx[k] = v if m else o
                rkx[k] = ks[k] if m else rkx[k]
        if uniqueness > 0.0:
            lim = float(best)
            f = 1.0 - uniqueness
            bad = 0
            for k in range(kmax + 1):
                if (k < kb - 1 or k > kb + 1) and float(row[k]) * f <= lim:
                    bad += 1
            if bad > 0:
                disp[y, x] = np.nan
                continue
        d = float(kb)
        if subpixel and 0 < kb < kmax:
            a = float(row[kb - 1])
            b = float(row[kb + 1])
            den = a - 2.0 * float(best) + b
            if den > 0:
                d += (a - b) / (2.0 * den)
        disp[y, x] = d + dmin
    if want_right:
        for xr in range(w):
            k = rk[w - 1 - xr]
            right[y, xr] = np.int32(k) + dmin if k >= 0 else -1


@njit(cache=True, parallel=True, fastmath=True)
def _sgm_wta(s, dmin, uniqueness, subpixel, want_right, disp, right):  # pragma: no cover - compiled
    _, h, w, nd = s.shape
    ks = np.arange(nd).astype(np.float32)
    ksi = np.arange(nd).astype(np.int32)
    for y in prange(h):
        C = np.empty((w, nd), dtype=np.float32)
        Ci = C.view(np.int32)
        rb = np.empty(w + nd + dmin, dtype=np.float32)
        rk = np.empty(w + nd + dmin, dtype=np.float32)
        s0 = s[0, y]
        s1 = s[1, y]
        for x in range(w):
            for k in range(nd):
                C[x, k] = np.float32(s0[x, k]) + np.float32(s1[x, k])
        _wta_row(C, Ci, y, dmin, uniqueness, subpixel, want_right, ks, ksi, rb, rk, disp, right)


@njit(cache=True, parallel=True)
def _lr_check(disp, right, max_diff):  # pragma: no cover - compiled
    h, w = disp.shape
    for y in prange(h):
        for x in range(w):
            d = disp[y, x]
            if np.isnan(d):
                continue
            xr = int(np.floor(x - d + 0.5))
            if xr < 0 or xr >= w or right[y, xr] < 0 or abs(right[y, xr] - d) > max_diff:
                disp[y, x] = np.nan


@njit(cache=True, inline="always")
def _sort2(a, b):  # pragma: no cover - compiled
    return (a, b) if a < b else (b, a)


@njit(cache=True, inline="always")
def _median9(p0, p1, p2, p3, p4, p5, p6, p7, p8):  # pragma: no cover - compiled
    # the median of nine by 19 exchanges (Paeth's network, as in Devillard's opt_med9)
    p1, p2 = _sort2(p1, p2)
    p4, p5 = _sort2(p4, p5)
    p7, p8 = _sort2(p7, p8)
    p0, p1 = _sort2(p0, p1)
    p3, p4 = _sort2(p3, p4)
    p6, p7 = _sort2(p6, p7)
    p1, p2 = _sort2(p1, p2)
    p4, p5 = _sort2(p4, p5)
    p7, p8 = _sort2(p7, p8)
    p0, p3 = _sort2(p0, p3)
    p5, p8 = _sort2(p5, p8)
    p4, p7 = _sort2(p4, p7)
    p3, p6 = _sort2(p3, p6)
    p1, p4 = _sort2(p1, p4)
    p2, p5 = _sort2(p2, p5)
    p4, p7 = _sort2(p4, p7)
    p4, p2 = _sort2(p4, p2)
    p6, p4 = _sort2(p6, p4)
    p4, p2 = _sort2(p4, p2)
    return p4


@njit(cache=True, parallel=True)
def _median3(pad, out):  # pragma: no cover - compiled
    # 3x3 median of the valid (non-NaN) neighbours, borders replicated (pad: the map
    # with one replicated pixel per side); NaN stays NaN. Windows without NaN (most)
    # go through a sorting network, branch-free along the row; the rest are sorted.
    h, w = out.shape
    for y in prange(h):
        a, b, c = pad[y], pad[y + 1], pad[y + 2]
        total = np.empty(w, dtype=np.float32)
        for x in range(w):
            out[y, x] = _median9(a[x], a[x + 1], a[x + 2], b[x], b[x + 1], b[x + 2],
                                 c[x], c[x + 1], c[x + 2])  # fmt: skip
            total[x] = (
                (a[x] + a[x + 1] + a[x + 2])
                + (b[x] + b[x + 1] + b[x + 2])
                + (c[x] + c[x + 1] + c[x + 2])
            )
        buf = np.empty(9, dtype=np.float32)
        for x in range(w):
            if not np.isnan(total[x]):
                continue
            if np.isnan(b[x + 1]):
                out[y, x] = np.nan
                continue
            n = 0
            for row in (a, b, c):
                for dx in range(3):
                    v = row[x + dx]
                    if not np.isnan(v):
                        j = n  # insertion sort
                        while j > 0 and buf[j - 1] > v:
                            buf[j] = buf[j - 1]
                            j -= 1
                        buf[j] = v
                        n += 1
            out[y, x] = buf[n // 2] if n % 2 == 1 else 0.5 * (buf[n // 2 - 1] + buf[n // 2])


#: below this share of valid pixels (left-right check on), the matchers test the order
SWAP_CHECK_BELOW = 0.7

#: width (pixels) the swap test reduces the pair to
_SWAP_WIDTH = 128


def _order_score(A: np.ndarray, B: np.ndarray, D: int, win: int) -> float:
    """Share of the pixels of ``A`` (columns ``D..``) whose winner-takes-all SAD match
    in ``B`` over disparities ``0..D`` lies strictly inside the range and passes a 1-px
    left-right check."""
    from scipy.ndimage import uniform_filter

    w = A.shape[1]
    x = np.arange(w)
    d = np.arange(D + 1)[:, None]
    Bp = np.pad(B, ((0, 0), (D, 0)), mode="edge")
    diff = np.abs(A[None] - Bp[:, x + D - d].transpose(1, 0, 2))  # |A(x) - B(x - d)|
    cost = uniform_filter(diff, (1, win, win), mode="nearest")
    cost = np.where((x >= d)[:, None, :], cost, np.inf)
    dl = cost.argmin(0)
    j = x + d  # the right pixel x' at disparity d is the left pixel x' + d
    rc = np.take_along_axis(cost, np.broadcast_to(np.minimum(j, w - 1)[:, None, :], cost.shape), 2)
    dr = np.where((j < w)[:, None, :], rc, np.inf).argmin(0)
    back = np.take_along_axis(dr, np.clip(x[None, :] - dl, 0, w - 1), 1)
    ok = (np.abs(back - dl) <= 1) & (dl > 0) & (dl < D)
    return float(ok[:, D:].mean())


def _order_scores(L: np.ndarray, R: np.ndarray, dmax: int) -> tuple[float, float] | None:
    """How well the gray pair ``L``, ``R`` (0-255, checked) matches as given and with the
    images exchanged: :func:`_order_score` of both orders on the pair reduced (block
    means) to about :data:`_SWAP_WIDTH` pixels wide, disparities ``0..dmax`` scaled; None
    when the reduced pair is too small to tell (fewer than 3 disparity steps, or a width
    below 3 times the range). The right order keeps 87-99 % of the pixels on the
    Middlebury pairs of the tests, the wrong one 5-38 %: true disparities of the wrong
    order are negative, outside the range (what an OpenCV user checks by running
    ``StereoSGBM`` on both orders)."""
    h, w = L.shape
    s = max(1, min(-(-w // _SWAP_WIDTH), dmax // 8))
    D = -(-dmax // s)
    h, w = h // s, w // s
    if D < 3 or w < 3 * D or h < 5:
        return None
    A = L[: h * s, : w * s].reshape(h, s, w, s).mean(axis=(1, 3), dtype=np.float32)
    B = R[: h * s, : w * s].reshape(h, s, w, s).mean(axis=(1, 3), dtype=np.float32)
    return _order_score(A, B, D, 5), _order_score(B, A, D, 5)


def _warn_if_swapped(
    L: np.ndarray, R: np.ndarray, dmax: int, disp: np.ndarray, lr_check: float | None
) -> None:
    """Warn when the pair looks swapped (module docstring, "Swapped images")."""
    valid = float(np.isfinite(disp).mean()) if lr_check is not None else None
    if valid is not None and valid >= SWAP_CHECK_BELOW:
        return
    scores = _order_scores(L, R, dmax)
    if scores is None:
        return
    given, exchanged = scores
    if exchanged >= 0.6 and exchanged - given >= 0.3:
        shown = "" if valid is None else f"{100 * valid:.1f}% of the pixels valid; "
        warnings.warn(
            f"left and right look swapped ({shown}a quick check matches {100 * given:.0f}% "
            f"of the pixels as given, {100 * exchanged:.0f}% with the two images "
            "exchanged): pass the left camera's image first (robopercept stereo LEFT RIGHT)",
            RoboperceptWarning,
            stacklevel=3,
        )


def _post(disp: np.ndarray, right: np.ndarray, lr_check: float | None, median: bool, dmin: int):
    if lr_check is not None:
        _lr_check(disp, right, float(lr_check))
        disp[disp <= dmin] = np.nan  # a winner at the range's end: not bracketed
    if median:
        out = np.empty_like(disp)
        _median3(np.pad(disp, 1, mode="edge"), out)
        disp = out
    return disp


#: largest cost volume (bytes) semi_global_matching allocates
MAX_VOLUME_BYTES = 4 * 2**30


def _check_volume(w: int, h: int, nd: int, need: int) -> None:
    """InputError when the cost volume of a ``w x h`` pair with ``nd`` disparities,
    ``need`` bytes, would pass :data:`MAX_VOLUME_BYTES`."""
    if need > MAX_VOLUME_BYTES:
        raise InputError(
            f"a {w}x{h} pair with {nd} disparities needs a {need / 2**30:.1f} GiB cost volume, "
            f"over the limit of {MAX_VOLUME_BYTES / 2**30:.0f} GiB: search fewer disparities "
            "(max_disparity, min_disparity) or downscale the pair"
        )


def _check_options(
    uniqueness: float, lr_check: float | None, subpixel: bool, median: bool
) -> tuple[float, float | None, bool, bool]:
    """The options shared by both matchers, checked and converted."""
    u = check_real(uniqueness, "uniqueness", 0.0, 1.0, high_inclusive=False)
    if lr_check is not None:
        lr_check = check_real(lr_check, "lr_check (pixels; None: no check)", 0.0)
    return u, lr_check, check_bool(subpixel, "subpixel"), check_bool(median, "median")


def semi_global_matching(
    left: np.ndarray,
    right: np.ndarray,
    max_disparity: int,
    P1: float | None = None,
    P2: float | None = None,
    paths: int = 8,
    *,
    min_disparity: int = 0,
    census: int = 5,
    block: int = 5,
    uniqueness: float = 0.0,
    lr_check: float | None = None,
    subpixel: bool = True,
    median: bool = True,
) -> np.ndarray:
    """Semi-global matching with census costs (see the module docstring).

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3) ndarray
        Rectified pair (uint8 or float in [0, 1]).
    max_disparity : int
        Largest disparity searched (inclusive; OpenCV's ``numDisparities`` is
        ``max_disparity - min_disparity + 1``).
    P1, P2 : float, optional
        Penalties for disparity changes of one and of more than one step, in census
        bits summed over the block (defaults 3 and 16 per block pixel, 75 and 400 for
        the 5x5 block: chosen on the four Middlebury pairs of the tests).
    paths : {4, 8}
        Aggregation directions: horizontal and vertical, plus the diagonals.
    min_disparity : int
    census : int
        Census window (3, 5 or 7).
    block : int
        Odd side of the block over which pixel costs are summed (1: none).
    uniqueness, lr_check, subpixel, median
        Rejection and refinement (see the module docstring); ``median`` is a 3x3
        median of the valid disparities. ``lr_check`` (pixels; None: off, the dense
        map) rejects occluded and mismatched pixels as NaN: 1 is OpenCV SGBM's
        tolerance, which its matcher always applies, and ``robopercept stereo``'s
        default (on Middlebury cones it keeps 88 % of the pixels, 4.1 % of them off
        by more than 2 px, against 13.0 % of all of them without the check).

    Returns
    -------
    (H, W) float32 ndarray
        Disparities in pixels, NaN where rejected or outside the search range.
    """
    L, R, max_disparity, min_disparity = _pair(left, right, max_disparity, min_disparity)
    paths = check_int(paths, "paths")
    if paths not in (4, 8):
        raise InputError(f"paths must be 4 or 8; got {paths}")
    block = check_int(block, "block", 1)
    if block % 2 == 0:
        raise InputError(f"block must be an odd integer >= 1; got {block}: try {block + 1}")
    census = _census_window(census, "census")
    uniqueness, lr_check, subpixel, median = _check_options(uniqueness, lr_check, subpixel, median)
    area = block**2
    # penalties beyond the 16-bit costs are refused below; bound them first so that
    # round() never sees an overflowing value
    p1 = round(3 * area if P1 is None else check_real(P1, "P1", 0.0, 1 << 13))
    p2 = round(16 * area if P2 is None else check_real(P2, "P2", 0.0, 1 << 13))
    if not 0 < p1 <= p2:
        raise InputError(f"need 0 < P1 <= P2; got P1={p1}, P2={p2}")
    nbits = census**2 - 1
    if area * nbits + p2 >= (1 << 13):
        raise InputError(
            f"block {block} with census {census} and P2 {p2} overflow the 16-bit costs: "
            "use a smaller block or P2"
        )
    nd = int(max_disparity) - int(min_disparity) + 1
    h, w = L.shape
    n_chunks = max(1, min(h, 2 * numba.get_num_threads()))
    # the uint16 cost and two path sums per cell, and the float32 block-sum rings
    _check_volume(w, h, nd, h * w * nd * 6 + n_chunks * (block + 1) * w * nd * 4)
    cl, cr = census_transform(L, census), census_transform(R, census)
    cost = np.empty((h, w, nd), dtype=np.uint16)
    crr = _reversed_rows(cr, int(max_disparity))
    r = int(block) // 2
    rings = np.empty((n_chunks, 2 * r + 1, w, nd), dtype=np.float32)
    cols = np.empty((n_chunks, w, nd), dtype=np.float32)
    _census_block_cost(cl, crr, int(min_disparity), r, np.float32(nbits), rings, cols, cost)
    s = np.empty((2, h, w, nd), dtype=np.uint16)
    _sgm_passes(cost, np.float32(p1), np.float32(p2), int(paths), s)
    disp = np.empty((h, w), dtype=np.float32)
    right_winners = np.empty((h, w), dtype=np.int32)
    _sgm_wta(s, int(min_disparity), float(uniqueness), bool(subpixel), lr_check is not None,
             disp, right_winners)  # fmt: skip
    disp = _post(disp, right_winners, lr_check, median, int(min_disparity))
    _warn_if_swapped(L, R, int(max_disparity), disp, lr_check)
    return disp


def disparity_to_depth(disparity: np.ndarray, focal: float, baseline: float) -> np.ndarray:
    r"""Depth :math:`z = f B / d` (units of ``baseline``); NaN where :math:`d \le 0` or
    NaN. ``focal`` in pixels.

    Examples
    --------
    :math:`Z = f B / d`; a zero disparity (no match) gives NaN:

    >>> disparity_to_depth(np.array([[64.0, 32.0, 0.0]]), focal=640.0, baseline=0.05)
    array([[0.5, 1. , nan]])
    """
    d = check_numeric(disparity, "disparity")
    fb = _focal_baseline(focal, baseline)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.where(d > 0, fb / d, np.nan)


def _focal_baseline(focal: float, baseline: float) -> float:
    """:math:`f B` after checking that both are positive and their product is finite."""
    f = check_real(focal, "focal (pixels)", 0.0, low_inclusive=False)
    b = check_real(baseline, "baseline", 0.0, low_inclusive=False)
    fb = f * b
    if not (0.0 < fb < np.inf and 1.0 / b < np.inf):
        raise InputError(
            f"focal * baseline overflows or underflows float64; got {f:g} * {b:g} = {fb:g}: "
            "give the focal length in pixels and the baseline in metres"
        )
    return fb


def depth_resolution(
    depth: npt.ArrayLike, focal: float, baseline: float, disparity_step: float = 1.0
) -> np.ndarray:
    r"""Depth change of one disparity step at depth :math:`z`:
    :math:`\Delta z = z^2 \Delta d / (f B)` (the first-order error of :math:`z = fB/d`)."""
    z = check_numeric(depth, "depth")
    fb = _focal_baseline(focal, baseline)
    step = check_real(disparity_step, "disparity_step", 0.0, low_inclusive=False)
    with np.errstate(over="ignore"):
        return z * z * (step / fb)


def disparity_to_points(
    disparity: np.ndarray, Q: npt.ArrayLike, *, min_disparity: float = 0.0
) -> np.ndarray:
    r"""3-D points ``(H, W, 3)`` from a disparity map and the rectification's
    :math:`Q` (``cv2.reprojectImageTo3D``): :math:`(X, Y, Z, W)^T = Q (x, y, d, 1)^T`,
    point :math:`(X, Y, Z) / W`; NaN where the disparity is NaN or not above
    ``min_disparity``.

    A disparity :math:`d` has the relative depth error :math:`\Delta z / z = \Delta d / d`
    (:func:`depth_resolution`): at :math:`d \le 1` px one disparity step is an error of
    100 % or more, and a wrong match there lands far beyond the scene (a 0.1 px
    disparity of a 700 px, 0.16 m rig is 1.1 km away). ``min_disparity=1`` keeps only
    points whose depth is known to better than a factor of two (``robopercept stereo``
    uses it, and the matcher's own lower bound when that is larger).

    Parameters
    ----------
    disparity : (H, W) array_like
        Pixels; NaN where rejected.
    Q : (4, 4) array_like
        The reprojection matrix (:func:`reprojection_matrix`, ``cv2.stereoRectify``).
    min_disparity : float
        Disparities at or below it give NaN points (default 0: only non-positive ones).

    Returns
    -------
    (H, W, 3) float64 ndarray

    Examples
    --------
    >>> Q = reprojection_matrix(500.0, 0.1, (3, 1))
    >>> pts = disparity_to_points(np.array([[25.0, 0.5, np.nan]]), Q, min_disparity=1.0)
    >>> pts[0, 0].tolist(), bool(np.isnan(pts[0, 1:]).all())
    ([-0.004, 0.0, 2.0], True)
    """
    d = check_numeric(disparity, "disparity")
    if d.ndim != 2:
        raise InputError(f"disparity must be (H, W); got shape {d.shape}")
    q = check_numeric(Q, "Q")
    if q.shape != (4, 4):
        raise InputError(f"Q must be 4x4; got shape {q.shape}")
    check_finite(q, "Q")
    floor = check_real(min_disparity, "min_disparity (pixels)", 0.0)
    h, w = d.shape
    ys, xs = np.mgrid[:h, :w].astype(np.float64)
    hom = np.stack([xs, ys, d, np.ones_like(d)], axis=-1) @ q.T
    with np.errstate(divide="ignore", invalid="ignore"):
        pts = hom[..., :3] / hom[..., 3:]
    pts[~(d > floor)] = np.nan
    return pts


def reprojection_matrix(focal: float, baseline: float, size: tuple[int, int]) -> np.ndarray:
    r"""The :math:`Q` of an ideal rectified pair, for :func:`disparity_to_points`.

    With the principal point at the image centre :math:`c = ((w-1)/2, (h-1)/2)`:

    .. math::

        Q = \begin{pmatrix} 1 & 0 & 0 & -c_x \\ 0 & 1 & 0 & -c_y \\
            0 & 0 & 0 & f \\ 0 & 0 & 1/B & 0 \end{pmatrix},

    so a pixel :math:`(x, y)` of disparity :math:`d` goes to
    :math:`Z = fB/d`, :math:`X = (x - c_x) Z / f`, :math:`Y = (y - c_y) Z / f`
    (``cv2.stereoRectify``'s :math:`Q` with equal principal points, up to the sign
    convention of :math:`T_x = -B`).

    Parameters
    ----------
    focal : float
        Focal length in pixels.
    baseline : float
        Distance between the optical centres (its unit is the points' unit).
    size : (width, height)
        Image size, as OpenCV.

    Examples
    --------
    >>> import numpy as np
    >>> Q = reprojection_matrix(500.0, 0.1, (5, 3))
    >>> disparity_to_points(np.full((3, 5), 25.0), Q)[1, 2].tolist()
    [0.0, 0.0, 2.0]
    """
    _focal_baseline(focal, baseline)
    f, b = float(focal), float(baseline)
    w, h = check_size(size, "size")
    return np.array(
        [
            [1.0, 0.0, 0.0, -(w - 1) / 2],
            [0.0, 1.0, 0.0, -(h - 1) / 2],
            [0.0, 0.0, 0.0, f],
            [0.0, 0.0, 1.0 / b, 0.0],
        ]
    )


def bad_pixel_rate(
    disparity: np.ndarray,
    truth: np.ndarray,
    threshold: float = 2.0,
    *,
    invalid: str = "bad",
) -> float:
    """Middlebury's bad-pixel rate: the share of pixels with known truth (``truth > 0``)
    whose disparity is off by more than ``threshold`` pixels.

    Parameters
    ----------
    disparity, truth : (H, W) array_like
        Estimate (NaN where rejected) and ground truth (0 where unknown), in pixels.
    threshold : float
        Pixels of error allowed (Middlebury's bad-1.0, bad-2.0 ...).
    invalid : {"bad", "ignore"}
        ``"bad"``: rejected (NaN) disparities count as bad, out of every pixel with
        known truth (Middlebury's figure for a map with holes, and OpenCV's tests');
        ``"ignore"``: the rate among the pixels that have both a disparity and a known
        truth (the accuracy of what was kept; report it with the density).

    Returns
    -------
    float
        A fraction in [0, 1].

    Raises
    ------
    InputError
        Shapes differ, no known truth, or a bad ``threshold`` / ``invalid``.
    DegenerateError
        ``invalid="ignore"`` and no pixel with known truth has a disparity.

    Examples
    --------
    >>> d = np.array([[10.0, 12.5, np.nan, 3.0]])
    >>> t = np.array([[10.0, 10.0, 10.0, 0.0]])  # the last pixel's truth unknown
    >>> bad_pixel_rate(d, t, 2.0), bad_pixel_rate(d, t, 2.0, invalid="ignore")
    (0.6666666666666666, 0.5)
    """
    d, t = check_numeric(disparity, "disparity"), check_numeric(truth, "truth")
    threshold = check_real(threshold, "threshold (pixels)", 0.0)
    if not isinstance(invalid, str):
        raise InputError(f"invalid must be 'bad' or 'ignore'; got {invalid!r}")
    check_choice(invalid, "invalid", ("bad", "ignore"))
    if d.shape != t.shape:
        raise InputError(f"disparity and truth must have the same shape; got {d.shape}, {t.shape}")
    known = t > 0
    if not known.any():
        raise InputError("truth has no known pixel (all <= 0)")
    if invalid == "ignore":
        known &= np.isfinite(d)
        if not known.any():
            raise DegenerateError(
                "no pixel with known truth has a disparity (all rejected): nothing to score"
            )
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(d - t) <= threshold)
    return float((bad & known).sum() / known.sum())


# ---------------------------------------------------------------- block matching


@njit(cache=True, fastmath=True, inline="always")
def _move_rows(col, La, Ra, Ls, Rs, dmin, mode, remove):  # pragma: no cover - compiled
    # col[x, k] += term(La[x], R_a[x - dmin - k]) - term(Ls[x], R_s[x - dmin - k]) (the
    # second only when ``remove``); Ra, Rs are reversed right rows, mode 0 |.|, 1 (.)^2,
    # 2 product
    w, nd = col.shape
    for x in range(w):
        base = w - 1 - x + dmin
        la = La[x]
        ls = Ls[x]
        c = col[x]
        ra = Ra[base : base + nd]  # row slices: see _hamming_row
        rs = Rs[base : base + nd]
        if mode == 0:
            if remove:
                for k in range(nd):
                    c[k] += abs(la - ra[k]) - abs(ls - rs[k])
            else:
                for k in range(nd):
                    c[k] += abs(la - ra[k])
        elif mode == 1:
            if remove:
                for k in range(nd):
                    ta = la - ra[k]
                    ts = ls - rs[k]
                    c[k] += ta * ta - ts * ts
            else:
                for k in range(nd):
                    ta = la - ra[k]
                    c[k] += ta * ta
        elif remove:
            for k in range(nd):
                c[k] += la * ra[k] - ls * rs[k]
        else:
            for k in range(nd):
                c[k] += la * ra[k]


@njit(cache=True, parallel=True, fastmath=True)
def _bm_kernel(L, Rr, dmin, r, mode, cols, costs, cints, sl, srr, vl, vrr,
               uniqueness, subpixel, want_right, disp, right):  # fmt: skip  # pragma: no cover
    # per chunk of rows: column sums of the pixel term over the window's rows (cols[c],
    # (w, nd)), moved one row at a time; window sums along x by a running sum
    # (costs[c]); then winner-takes-all per row. Rr[y, w - 1 - x + j] = R[y, x - j]
    # with the left border replicated.
    h, w = L.shape
    n_chunks, _, nd = cols.shape
    step = (h + n_chunks - 1) // n_chunks
    n = float((2 * r + 1) * (2 * r + 1))
    ks = np.arange(nd).astype(np.float32)
    ksi = np.arange(nd).astype(np.int32)
    for c in prange(n_chunks):
        y0 = c * step
        y1 = min(h, y0 + step)
        col = cols[c]
        C = costs[c]
        Ci = cints[c]
        acc = np.zeros_like(col[0])
        rb = np.empty_like(Rr[0])  # the cost dtype
        rk = np.empty_like(Rr[0])
        col[:] = 0
        for y in range(y0, y1):
            if y == y0:
                for t in range(-r, r + 1):
                    ya = min(max(y + t, 0), h - 1)
                    _move_rows(col, L[ya], Rr[ya], L[ya], Rr[ya], dmin, mode, False)
            else:
                ya = min(y + r, h - 1)
                ys = max(y - r - 1, 0)
                _move_rows(col, L[ya], Rr[ya], L[ys], Rr[ys], dmin, mode, True)
            # running window sums along x, borders replicated
            _window_start(col, r, acc)
            for x in range(w):
                if mode == 2:  # 1 - zero-mean NCC
                    base = w - 1 - x + dmin
                    a = sl[y, x]
                    b = vl[y, x]
                    sr = srr[y, base : base + nd]
                    vr = vrr[y, base : base + nd]
                    for k in range(nd):
                        q = (acc[k] - a * sr[k] / n) / np.sqrt(b * vr[k])
                        q = q if q < 1.0 else 1.0  # the correlation's own range, so that
                        q = q if q > -1.0 else -1.0  # the cost is >= 0 (see _wta_row)
                        C[x, k] = 1.0 - q
                else:
                    for k in range(nd):
                        C[x, k] = acc[k]
                _window_move(col, x, r, acc)
            _wta_row(C, Ci, y, dmin, uniqueness, subpixel, want_right, ks, ksi, rb, rk, disp, right)


def _box(img: np.ndarray, r: int) -> np.ndarray:
    """Window sums with replicated borders (the same windows as :func:`_bm_kernel`)."""
    from scipy.ndimage import uniform_filter

    n = (2 * r + 1) ** 2
    return uniform_filter(img.astype(np.float64), 2 * r + 1, mode="nearest") * n


def _reversed_rows(a: np.ndarray, dmax: int) -> np.ndarray:
    """``out[y, w - 1 - x + j] = a[y, clip(x - j, 0, w - 1)]`` for ``0 <= j <= dmax``:
    rows reversed and padded by ``dmax`` copies of the first column."""
    return np.ascontiguousarray(np.pad(a, ((0, 0), (dmax, 0)), mode="edge")[:, ::-1])


def block_matching(
    left: np.ndarray,
    right: np.ndarray,
    max_disparity: int,
    window: int = 9,
    cost: str = "sad",
    *,
    min_disparity: int = 0,
    uniqueness: float = 0.0,
    lr_check: float | None = None,
    subpixel: bool = True,
    median: bool = False,
) -> np.ndarray:
    """Block matching with winner-takes-all (see the module docstring).

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3) ndarray
        Rectified pair (uint8 or float in [0, 1]); matched on gray levels 0-255.
    max_disparity : int
        Largest disparity searched (inclusive).
    window : int
        Odd window side.
    cost : {"sad", "ssd", "ncc"}
        Sum of absolute or squared differences, or 1 - zero-mean normalized
        cross-correlation (insensitive to gain and offset between the cameras).
    min_disparity, uniqueness, lr_check, subpixel, median
        As in :func:`semi_global_matching`.

    Returns
    -------
    (H, W) float32 ndarray
        Disparities, NaN where rejected or outside the search range.
    """
    L, R, max_disparity, min_disparity = _pair(left, right, max_disparity, min_disparity)
    window = check_int(window, "window")
    if window < 1 or window % 2 == 0 or window > 45:
        raise InputError(f"window must be an odd integer in 1..45; got {window}")
    if not isinstance(cost, str):
        raise InputError(f"cost must be 'sad', 'ssd' or 'ncc'; got {cost!r}")
    check_choice(cost, "cost", ("sad", "ssd", "ncc"))
    uniqueness, lr_check, subpixel, median = _check_options(uniqueness, lr_check, subpixel, median)
    nd = int(max_disparity) - int(min_disparity) + 1
    r = int(window) // 2
    h, w = L.shape
    mode = {"sad": 0, "ssd": 1, "ncc": 2}[cost]
    # float32 while every window sum (and a sum plus one column) stays below 2^24,
    # where float32 holds integers exactly; float64 otherwise
    side = 2 * r + 1
    exact32 = mode == 0 or (mode == 1 and (side * side + side) * 255**2 < 2**24)
    dtype = np.float32 if exact32 else np.float64
    Li = np.round(L).astype(dtype)
    Ri = np.round(R).astype(dtype)
    Rr = _reversed_rows(Ri, int(max_disparity))
    if mode == 2:
        n = side * side
        sl, sl2, sr, sr2 = _box(Li, r), _box(Li * Li, r), _box(Ri, r), _box(Ri * Ri, r)
        vl = np.maximum(sl2 - sl * sl / n, 1e-9)
        vr = np.maximum(sr2 - sr * sr / n, 1e-9)
        srr, vrr = _reversed_rows(sr, int(max_disparity)), _reversed_rows(vr, int(max_disparity))
    else:
        sl = vl = srr = vrr = np.zeros((1, 1))
    n_chunks = max(1, min(h, 2 * numba.get_num_threads()))
    cols = np.zeros((n_chunks, w, nd), dtype=dtype)
    costs = np.empty((n_chunks, w, nd), dtype=dtype)
    disp = np.empty((h, w), dtype=np.float32)
    right_winners = np.empty((h, w), dtype=np.int32)
    cints = costs.view(np.int32 if dtype == np.float32 else np.int64)
    _bm_kernel(Li, Rr, int(min_disparity), r, mode, cols, costs, cints, sl, srr, vl, vrr,
               float(uniqueness), bool(subpixel), lr_check is not None, disp,
               right_winners)  # fmt: skip
    disp = _post(disp, right_winners, lr_check, median, int(min_disparity))
    _warn_if_swapped(L, R, int(max_disparity), disp, lr_check)
    return disp
