r"""Dense stereo on a rectified pair: block matching and semi-global matching, and
disparity to depth.

For a rectified pair a left pixel :math:`(x, y)` matches the right pixel
:math:`(x - d, y)`; :math:`d` is the disparity, and the depth is

.. math::

    z = \frac{f B}{d}, \qquad \Delta z = \frac{z^2}{f B} \Delta d,

so one disparity step covers more depth the farther the point: the resolution falls
with the square of the distance.

**Block matching** compares windows: SAD :math:`\sum |L - R|`, SSD
:math:`\sum (L - R)^2` or zero-mean NCC (1 - correlation) over a
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
Columns left of the search range take only the disparities that stay inside the
right image (OpenCV marks the first ``numDisparities`` columns invalid instead).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from robopercept._checks import check_image
from robopercept.errors import InputError

__all__ = [
    "bad_pixel_rate",
    "block_matching",
    "census_transform",
    "depth_resolution",
    "disparity_to_depth",
    "disparity_to_points",
    "semi_global_matching",
]

_BIG = 1 << 14  # path-cost sentinel beyond any reachable value (costs stay < 2^13)


def _gray(image: np.ndarray, name: str) -> np.ndarray:
    img = check_image(image, name)
    g = img.astype(np.float32)
    if img.dtype.kind == "f":
        g = g * 255.0
    elif img.dtype != np.uint8:
        raise InputError(f"{name} must be uint8 or float in [0, 1]; got {img.dtype}")
    if g.ndim == 3:
        g = g @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    return np.ascontiguousarray(g)


def _pair(left: np.ndarray, right: np.ndarray, max_disparity: int, min_disparity: int):
    L, R = _gray(left, "left"), _gray(right, "right")
    if L.shape != R.shape:
        raise InputError(
            f"left and right must have the same size; got {L.shape} and {R.shape}: "
            "rectify the pair first"
        )
    if int(max_disparity) != max_disparity or int(min_disparity) != min_disparity:
        raise InputError("min_disparity and max_disparity must be integers")
    if not 0 <= min_disparity < max_disparity:
        raise InputError(
            f"need 0 <= min_disparity < max_disparity; got {min_disparity} and {max_disparity}"
        )
    if max_disparity >= L.shape[1]:
        raise InputError(
            f"max_disparity {max_disparity} must be below the image width {L.shape[1]}"
        )
    return L, R


# ---------------------------------------------------------------- census


@njit(cache=True, parallel=True)
def _census_kernel(img, r, out):  # pragma: no cover - compiled
    h, w = img.shape
    for y in prange(h):
        for x in range(w):
            c = img[y, x]
            bits = np.uint64(0)
            for dy in range(-r, r + 1):
                yy = min(max(y + dy, 0), h - 1)
                for dx in range(-r, r + 1):
                    if dy == 0 and dx == 0:
                        continue
                    xx = min(max(x + dx, 0), w - 1)
                    bits = (bits << np.uint64(1)) | np.uint64(img[yy, xx] < c)
            out[y, x] = bits


def census_transform(image: np.ndarray, window: int = 7) -> np.ndarray:
    """Census transform: per pixel, one bit per neighbour in the ``window`` (odd, at
    most 7 so the bits fit in 64), set where the neighbour is darker than the centre
    (borders replicated). Returns (H, W) uint64."""
    if int(window) != window or window < 3 or window % 2 == 0 or window > 7:
        raise InputError(f"census window must be 3, 5 or 7; got {window}")
    g = _gray(image, "image")
    out = np.empty(g.shape, dtype=np.uint64)
    _census_kernel(g, int(window) // 2, out)
    return out


@njit(cache=True, inline="always")
def _popcount(v):  # pragma: no cover - compiled
    v = v - ((v >> np.uint64(1)) & np.uint64(0x5555555555555555))
    v = (v & np.uint64(0x3333333333333333)) + ((v >> np.uint64(2)) & np.uint64(0x3333333333333333))
    v = (v + (v >> np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    return (v * np.uint64(0x0101010101010101)) >> np.uint64(56)


@njit(cache=True, parallel=True)
def _census_cost(cl, cr, dmin, nd, invalid, cost):  # pragma: no cover - compiled
    # cost[y, x, k] = Hamming(cl[y, x], cr[y, x - dmin - k]); ``invalid`` where outside
    h, w = cl.shape
    for y in prange(h):
        for x in range(w):
            a = cl[y, x]
            for k in range(nd):
                xr = x - dmin - k
                if xr >= 0:
                    cost[y, x, k] = np.uint16(_popcount(a ^ cr[y, xr]))
                else:
                    cost[y, x, k] = invalid


@njit(cache=True, parallel=True)
def _box_sum_cost(cost, r, out):  # pragma: no cover - compiled
    # out[y, x, k] = sum of cost over the (2r+1)^2 block around (y, x), borders clamped
    h, w, nd = cost.shape
    for y in prange(h):
        col = np.zeros((w, nd), dtype=np.int32)
        for dy in range(-r, r + 1):
            yy = min(max(y + dy, 0), h - 1)
            for x in range(w):
                for k in range(nd):
                    col[x, k] += cost[yy, x, k]
        acc = np.zeros(nd, dtype=np.int32)
        for dx in range(-r, r + 1):
            xx = min(max(dx, 0), w - 1)
            for k in range(nd):
                acc[k] += col[xx, k]
        for x in range(w):
            for k in range(nd):
                out[y, x, k] = np.uint16(acc[k])
            xo = min(max(x - r, 0), w - 1)
            xi = min(max(x + r + 1, 0), w - 1)
            for k in range(nd):
                acc[k] += col[xi, k] - col[xo, k]


# ---------------------------------------------------------------- SGM aggregation


@njit(cache=True, inline="always")
def _step(cost_row, prev, prev_min, p1, p2, out, nd):  # pragma: no cover - compiled
    # out[k] = C[k] + min(prev[k], prev[k-1] + P1, prev[k+1] + P1, prev_min + P2) - prev_min
    # prev is padded: prev[0] and prev[nd + 1] hold the sentinel
    m = prev_min + p2
    best = _BIG * 4
    for k in range(nd):
        v = prev[k + 1]
        a = prev[k] + p1
        b = prev[k + 2] + p1
        if a < v:
            v = a
        if b < v:
            v = b
        if m < v:
            v = m
        v = v - prev_min + cost_row[k]
        out[k + 1] = v
        if v < best:
            best = v
    return best


@njit(cache=True, inline="always")
def _start(cost_row, out, nd):  # pragma: no cover - compiled
    # a path's first pixel: L = C (padded like _step's output); returns its minimum
    best = _BIG * 4
    for k in range(nd):
        out[k + 1] = cost_row[k]
        if cost_row[k] < best:
            best = cost_row[k]
    return best


@njit(cache=True, parallel=True)
def _sgm_passes(cost, p1, p2, paths, s_out):  # pragma: no cover - compiled
    # two independent passes (top-down and bottom-up), one per thread; each writes its
    # own sum s_out[pass]
    h, w, nd = cost.shape
    for job in prange(2):
        s = s_out[job]
        down = job == 0
        # previous-row path costs for the three vertical/diagonal directions, padded
        pv = np.full((w, nd + 2), _BIG, dtype=np.int32)
        pa = np.full((w, nd + 2), _BIG, dtype=np.int32)
        pb = np.full((w, nd + 2), _BIG, dtype=np.int32)
        mv = np.zeros(w, dtype=np.int32)
        ma = np.zeros(w, dtype=np.int32)
        mb = np.zeros(w, dtype=np.int32)
        cv = np.full((w, nd + 2), _BIG, dtype=np.int32)
        ca = np.full((w, nd + 2), _BIG, dtype=np.int32)
        cb = np.full((w, nd + 2), _BIG, dtype=np.int32)
        nv = np.zeros(w, dtype=np.int32)
        na = np.zeros(w, dtype=np.int32)
        nb = np.zeros(w, dtype=np.int32)
        hz = np.full(nd + 2, _BIG, dtype=np.int32)
        hz2 = np.full(nd + 2, _BIG, dtype=np.int32)
        crow = np.zeros(nd, dtype=np.int32)
        for i in range(h):
            y = i if down else h - 1 - i
            first = i == 0
            # horizontal: left to right on the way down, right to left on the way up
            hmin = 0
            for j in range(w):
                x = j if down else w - 1 - j
                for k in range(nd):
                    crow[k] = cost[y, x, k]
                if j == 0:
                    hmin = _start(crow, hz, nd)
                else:
                    hmin = _step(crow, hz, hmin, p1, p2, hz2, nd)
                    hz, hz2 = hz2, hz
                for k in range(nd):
                    s[y, x, k] = hz[k + 1]
            # vertical (0, +-1) and, with 8 paths, the diagonals (+-1, +-1)
            for x in range(w):
                for k in range(nd):
                    crow[k] = cost[y, x, k]
                if first:
                    nv[x] = _start(crow, cv[x], nd)
                else:
                    nv[x] = _step(crow, pv[x], mv[x], p1, p2, cv[x], nd)
                for k in range(nd):
                    s[y, x, k] += cv[x, k + 1]
                if paths == 8:
                    xa = x - 1  # from the upper left (down) / lower left (up)
                    if first or xa < 0:
                        na[x] = _start(crow, ca[x], nd)
                    else:
                        na[x] = _step(crow, pa[xa], ma[xa], p1, p2, ca[x], nd)
                    xb = x + 1  # from the upper right (down) / lower right (up)
                    if first or xb >= w:
                        nb[x] = _start(crow, cb[x], nd)
                    else:
                        nb[x] = _step(crow, pb[xb], mb[xb], p1, p2, cb[x], nd)
                    for k in range(nd):
                        s[y, x, k] += ca[x, k + 1] + cb[x, k + 1]
            pv, cv = cv, pv
            pa, ca = ca, pa
            pb, cb = cb, pb
            mv, nv = nv, mv
            ma, na = na, ma
            mb, nb = nb, mb


# ---------------------------------------------------------------- winner takes all


@njit(cache=True, inline="always")
def _wta_row(rc, y, dmin, uniqueness, subpixel, disp, right):  # pragma: no cover - compiled
    # rc[k, x]: cost of disparity dmin + k at left column x. Left winners use only the
    # disparities that keep x - d inside the right image; right winners (for the
    # consistency check) those that keep xr + d inside the left image. Loops run over
    # x innermost, along rc's rows.
    nd, w = rc.shape
    best = rc[0].copy()
    kb = np.zeros(w, dtype=np.int32)
    for k in range(1, nd):
        kk = np.int32(k)
        for x in range(k + dmin, w):  # branch-free, so that it vectorizes
            v = rc[k, x]
            b = best[x]
            m = v < b
            best[x] = v if m else b
            kb[x] = kk if m else kb[x]
    ok = np.ones(w, dtype=np.bool_)
    if uniqueness > 0.0:
        for k in range(nd):
            for x in range(k + dmin, w):
                if (k < kb[x] - 1 or k > kb[x] + 1) and rc[k, x] * (1.0 - uniqueness) <= best[x]:
                    ok[x] = False
    for x in range(w):
        kmax = min(nd - 1, x - dmin)
        if kmax < 0 or not ok[x]:
            disp[y, x] = np.nan
            continue
        k = kb[x]
        d = float(k)
        if subpixel and 0 < k < kmax:
            a = float(rc[k - 1, x])
            b = float(rc[k + 1, x])
            den = a - 2.0 * float(best[x]) + b
            if den > 0:
                d += (a - b) / (2.0 * den)
        disp[y, x] = d + dmin
    rbest = np.empty(w, dtype=rc.dtype)
    rk = np.full(w, -1, dtype=np.int32)
    for xr in range(max(w - dmin, 0)):
        rbest[xr] = rc[0, xr + dmin]
        rk[xr] = 0
    for k in range(1, nd):
        kk = np.int32(k)
        for xr in range(max(w - dmin - k, 0)):
            v = rc[k, xr + dmin + k]
            b = rbest[xr]
            m = v < b
            rbest[xr] = v if m else b
            rk[xr] = kk if m else rk[xr]
    for xr in range(w):
        right[y, xr] = rk[xr] + dmin if rk[xr] >= 0 else -1


@njit(cache=True, parallel=True)
def _sgm_wta(s, dmin, uniqueness, subpixel, disp, right):  # pragma: no cover - compiled
    _, h, w, nd = s.shape
    for y in prange(h):
        rc = np.empty((nd, w), dtype=np.int32)
        for x in range(w):
            for k in range(nd):
                rc[k, x] = np.int32(s[0, y, x, k]) + np.int32(s[1, y, x, k])
        _wta_row(rc, y, dmin, uniqueness, subpixel, disp, right)


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


@njit(cache=True, parallel=True)
def _median3(disp, out):  # pragma: no cover - compiled
    # 3x3 median of the valid (non-NaN) neighbours, borders replicated; NaN stays NaN
    h, w = disp.shape
    for y in prange(h):
        buf = np.empty(9, dtype=np.float32)
        for x in range(w):
            if np.isnan(disp[y, x]):
                out[y, x] = np.nan
                continue
            n = 0
            for dy in range(-1, 2):
                yy = min(max(y + dy, 0), h - 1)
                for dx in range(-1, 2):
                    xx = min(max(x + dx, 0), w - 1)
                    v = disp[yy, xx]
                    if not np.isnan(v):
                        j = n  # insertion sort
                        while j > 0 and buf[j - 1] > v:
                            buf[j] = buf[j - 1]
                            j -= 1
                        buf[j] = v
                        n += 1
            out[y, x] = buf[n // 2] if n % 2 == 1 else 0.5 * (buf[n // 2 - 1] + buf[n // 2])


def _post(disp: np.ndarray, right: np.ndarray, lr_check: float | None, median: bool):
    if lr_check is not None:
        _lr_check(disp, right, float(lr_check))
    if median:
        out = np.empty_like(disp)
        _median3(disp, out)
        disp = out
    return disp


def _check_options(uniqueness: float, lr_check: float | None) -> None:
    if not 0.0 <= uniqueness < 1.0:
        raise InputError(f"uniqueness must be in [0, 1); got {uniqueness}")
    if lr_check is not None and not lr_check >= 0:
        raise InputError(f"lr_check must be None or a number of pixels >= 0; got {lr_check}")


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
        median of the valid disparities.

    Returns
    -------
    (H, W) float32 ndarray
        Disparities in pixels, NaN where rejected or outside the search range.
    """
    L, R = _pair(left, right, max_disparity, min_disparity)
    if paths not in (4, 8):
        raise InputError(f"paths must be 4 or 8; got {paths}")
    if int(block) != block or block < 1 or block % 2 == 0:
        raise InputError(f"block must be an odd integer >= 1; got {block}")
    _check_options(uniqueness, lr_check)
    area = int(block) ** 2
    p1 = round(3 * area if P1 is None else P1)
    p2 = round(16 * area if P2 is None else P2)
    if not 0 < p1 <= p2:
        raise InputError(f"need 0 < P1 <= P2; got P1={p1}, P2={p2}")
    nbits = int(census) ** 2 - 1
    if area * nbits + p2 >= (1 << 13):
        raise InputError(
            f"block {block} with census {census} and P2 {p2} overflow the 16-bit costs: "
            "use a smaller block or P2"
        )
    nd = int(max_disparity) - int(min_disparity) + 1
    cl, cr = census_transform(L, census), census_transform(R, census)
    h, w = L.shape
    cost = np.empty((h, w, nd), dtype=np.uint16)
    _census_cost(cl, cr, int(min_disparity), nd, np.uint16(nbits), cost)
    if block > 1:
        summed = np.empty_like(cost)
        _box_sum_cost(cost, int(block) // 2, summed)
        cost = summed
    s = np.empty((2, h, w, nd), dtype=np.uint16)
    _sgm_passes(cost, p1, p2, int(paths), s)
    disp = np.empty((h, w), dtype=np.float32)
    right_winners = np.empty((h, w), dtype=np.int32)
    _sgm_wta(s, int(min_disparity), float(uniqueness), bool(subpixel), disp, right_winners)
    return _post(disp, right_winners, lr_check, median)


def disparity_to_depth(disparity: np.ndarray, focal: float, baseline: float) -> np.ndarray:
    r"""Depth :math:`z = f B / d` (units of ``baseline``); NaN where :math:`d \le 0` or
    NaN. ``focal`` in pixels."""
    d = np.asarray(disparity, dtype=np.float64)
    if not focal > 0 or not baseline > 0:
        raise InputError(f"focal and baseline must be positive; got {focal} and {baseline}")
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, focal * baseline / d, np.nan)


def depth_resolution(
    depth: Any, focal: float, baseline: float, disparity_step: float = 1.0
) -> np.ndarray:
    r"""Depth change of one disparity step at depth :math:`z`:
    :math:`\Delta z = z^2 \Delta d / (f B)` (the first-order error of :math:`z = fB/d`)."""
    z = np.asarray(depth, dtype=np.float64)
    if not focal > 0 or not baseline > 0 or not disparity_step > 0:
        raise InputError("focal, baseline and disparity_step must be positive")
    return z * z * disparity_step / (focal * baseline)


def disparity_to_points(disparity: np.ndarray, Q: Any) -> np.ndarray:
    r"""3-D points ``(H, W, 3)`` from a disparity map and the rectification's
    :math:`Q` (``cv2.reprojectImageTo3D``): :math:`(X, Y, Z, W)^T = Q (x, y, d, 1)^T`,
    point :math:`(X, Y, Z) / W`; NaN where the disparity is NaN or not positive."""
    d = np.asarray(disparity, dtype=np.float64)
    if d.ndim != 2:
        raise InputError(f"disparity must be (H, W); got shape {d.shape}")
    q = np.asarray(Q, dtype=np.float64)
    if q.shape != (4, 4):
        raise InputError(f"Q must be 4x4; got shape {q.shape}")
    h, w = d.shape
    ys, xs = np.mgrid[:h, :w].astype(np.float64)
    hom = np.stack([xs, ys, d, np.ones_like(d)], axis=-1) @ q.T
    with np.errstate(divide="ignore", invalid="ignore"):
        pts = hom[..., :3] / hom[..., 3:]
    pts[~(d > 0)] = np.nan
    return pts


def bad_pixel_rate(disparity: np.ndarray, truth: np.ndarray, threshold: float = 2.0) -> float:
    """Middlebury's bad-pixel rate: the share of pixels with known truth (``truth > 0``)
    whose disparity is off by more than ``threshold`` pixels; invalid (NaN) disparities
    count as bad."""
    d = np.asarray(disparity, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if d.shape != t.shape:
        raise InputError(f"disparity and truth must have the same shape; got {d.shape}, {t.shape}")
    known = t > 0
    if not known.any():
        raise InputError("truth has no known pixel (all <= 0)")
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(d - t) <= threshold)
    return float((bad & known).sum() / known.sum())


# ---------------------------------------------------------------- block matching


@njit(cache=True, inline="always")
def _add_row(col, Lrow, Rpad, off, nd, w, mode, sign):  # pragma: no cover - compiled
    # col[k, x] += sign * term(L[x], R[x - dmin - k]); Rpad holds R shifted by ``off``
    for k in range(nd):
        base = off - k
        if mode == 0:
            for x in range(w):
                col[k, x] += sign * abs(Lrow[x] - Rpad[x + base])
        elif mode == 1:
            for x in range(w):
                t = Lrow[x] - Rpad[x + base]
                col[k, x] += sign * t * t
        else:
            for x in range(w):
                col[k, x] += sign * Lrow[x] * Rpad[x + base]


@njit(cache=True, parallel=True)
def _bm_kernel(L, Rpad, pad, dmin, nd, r, mode, n_chunks, sl, sl2, sr, sr2,
               uniqueness, subpixel, disp, right):  # fmt: skip  # pragma: no cover
    # per chunk of rows: column sums of the pixel term over the window's rows, moved
    # one row at a time, then the window sums along x, then winner-takes-all per row.
    # Rpad[y, pad + x] = R[y, x] with replicated borders, so R at x - dmin - k is
    # Rpad[y, x + pad - dmin - k] without clamping.
    h, w = L.shape
    step = (h + n_chunks - 1) // n_chunks
    n = float((2 * r + 1) * (2 * r + 1))
    off = pad - dmin
    for c in prange(n_chunks):
        y0 = c * step
        y1 = min(h, y0 + step)
        col = np.zeros((nd, w), dtype=np.int32)
        rc = np.empty((nd, w), dtype=np.float64)
        pre = np.zeros(w + 2 * r + 2, dtype=np.int32)
        for y in range(y0, y1):
            if y == y0:
                for t in range(-r, r + 1):
                    ya = min(max(y + t, 0), h - 1)
                    _add_row(col, L[ya], Rpad[ya], off, nd, w, mode, 1)
            else:
                ya = min(y + r, h - 1)
                ys = max(y - r - 1, 0)
                _add_row(col, L[ya], Rpad[ya], off, nd, w, mode, 1)
                _add_row(col, L[ys], Rpad[ys], off, nd, w, mode, -1)
            for k in range(nd):
                # prefix sums of the column sums over x with replicated borders:
                # pre[i] = sum of col[k, clamp(j - r - 1)] for j < i
                pre[0] = 0
                for i in range(w + 2 * r + 1):
                    pre[i + 1] = pre[i] + col[k, min(max(i - r, 0), w - 1)]
                if mode == 2:  # 1 - zero-mean NCC
                    for x in range(w):
                        acc = pre[x + 2 * r + 1] - pre[x]
                        xr = min(max(x - dmin - k, 0), w - 1)
                        vl = sl2[y, x] - sl[y, x] * sl[y, x] / n
                        vr = sr2[y, xr] - sr[y, xr] * sr[y, xr] / n
                        num = acc - sl[y, x] * sr[y, xr] / n
                        rc[k, x] = 1.0 - num / np.sqrt(max(vl, 1e-9) * max(vr, 1e-9))
                else:
                    for x in range(w):
                        rc[k, x] = pre[x + 2 * r + 1] - pre[x]
            _wta_row(rc, y, dmin, uniqueness, subpixel, disp, right)


def _box(img: np.ndarray, r: int) -> np.ndarray:
    """Window sums with replicated borders (the same windows as :func:`_bm_kernel`)."""
    from scipy.ndimage import uniform_filter

    n = (2 * r + 1) ** 2
    return uniform_filter(img.astype(np.float64), 2 * r + 1, mode="nearest") * n


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
    L, R = _pair(left, right, max_disparity, min_disparity)
    if int(window) != window or window < 1 or window % 2 == 0 or window > 45:
        raise InputError(f"window must be an odd integer in 1..45; got {window}")
    if cost not in ("sad", "ssd", "ncc"):
        raise InputError(f"cost must be 'sad', 'ssd' or 'ncc'; got {cost!r}")
    _check_options(uniqueness, lr_check)
    Li = np.round(L).astype(np.int32)  # window sums of 255^2 terms fit up to 45x45
    Ri = np.round(R).astype(np.int32)
    nd = int(max_disparity) - int(min_disparity) + 1
    r = int(window) // 2
    h, w = L.shape
    pad = int(max_disparity)
    Rpad = np.pad(Ri, ((0, 0), (pad, 0)), mode="edge")
    mode = {"sad": 0, "ssd": 1, "ncc": 2}[cost]
    if mode == 2:
        L64, R64 = Li.astype(np.float64), Ri.astype(np.float64)
        sl, sl2, sr, sr2 = _box(L64, r), _box(L64 * L64, r), _box(R64, r), _box(R64 * R64, r)
    else:
        sl = sl2 = sr = sr2 = np.zeros((1, 1))
    disp = np.empty((h, w), dtype=np.float32)
    right_winners = np.empty((h, w), dtype=np.int32)
    _bm_kernel(Li, Rpad, pad, int(min_disparity), nd, r, mode, 16, sl, sl2, sr, sr2,
               float(uniqueness), bool(subpixel), disp, right_winners)  # fmt: skip
    return _post(disp, right_winners, lr_check, median)
