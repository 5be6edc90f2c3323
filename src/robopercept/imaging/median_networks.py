r"""Median filters of 3x3 and 5x5 windows as branch-free min/max networks.

The window median of :func:`robopercept.imaging.median_filter` for ``ksize`` 3 and 5,
at OpenCV's speed (``cv2.medianBlur`` sorts 3x3 and 5x5 windows by SIMD min/max
networks too). Exact: a median is a selection, so every output equals the one of the
insertion sort it replaces, for every dtype.

Both select the median from the window's columns sorted top to bottom
(:math:`S_0 \le S_1 \le \dots \le S_{k-1}` in each column); LLVM turns each ``min`` /
``max`` into one SIMD instruction (64 uint8 lanes on AVX-512).

**3x3.** With the three sorted columns of a window,

.. math:: \operatorname{med}_9 = \operatorname{med}_3\bigl(\max_j S_0[j],\;
          \operatorname{med}_3(S_1[j]),\; \min_j S_2[j]\bigr)

(the sorted-columns form of the 3x3 median, Paeth's and Smith's): 6 min/max to sort
each of the three columns and 12 to combine them, all in registers from nine loads, as
``cv2.medianBlur`` does with its 19-exchange network. The rows between the first and
the last are one loop over the flat image (output ``i`` reads source ``i + d`` for the
nine offsets ``d`` of its window), so no row pays a loop's setup; each row's first and
last column, where that loop runs across a row's end, and the first and last rows are
then rewritten through the border map.

**5x5.** Per output row, in two vectorized passes over contiguous arrays:

1. **Columns.** The five source rows of the window are sorted column by column into
   ``S[0] <= ... <= S[4]`` (the 9-exchange sorting network), over the padded width:
   each column is sorted once and serves the five windows that contain it.
2. **Windows.** Each rank row ``S_i[x..x+4]`` of the window is sorted across its
   columns; the matrix then has sorted rows and columns, so entry ``(i, j)`` has at
   least ``(i+1)(j+1) - 1`` values at or below it and ``(5-i)(5-j) - 1`` at or above.
   Only the 13 entries with ``(i+1)(j+1) <= 13`` and ``(5-i)(5-j) <= 13`` can be the
   median; 6 lie surely below it and 6 surely above, so the median of 25 is the median
   of those 13. The row sorts and a Batcher odd-even merge sort of the 13 (padded to 16
   with :math:`+\infty`) are pruned to the operations the median depends on:
   :func:`median_network` builds them (140 min/max per pixel), and the kernel's body is
   that list written out.

Correctness of the networks follows from the 0-1 principle (a min/max network that
selects correctly on every 0/1 input does so on every input); the tests check every
0/1 window up to the column sort (all ``(k+1)^k`` column counts), and parity with
``cv2.medianBlur``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
from numba import njit

__all__ = ["median_network", "median_rows"]

#: the optimal 5-input sorting network (9 compare-exchanges; Knuth, TAOCP 5.3.4)
SORT5 = ((0, 1), (3, 4), (2, 4), (2, 3), (1, 4), (0, 3), (0, 2), (1, 3), (1, 2))


def _oddeven_merge(lo: int, hi: int, r: int) -> Iterator[tuple[int, int]]:
    """Batcher's odd-even merge of wires ``lo..hi`` (inclusive) at distance ``r``."""
    step = r * 2
    if step < hi - lo:
        yield from _oddeven_merge(lo, hi, step)
        yield from _oddeven_merge(lo + r, hi, step)
        yield from ((i, i + r) for i in range(lo + r, hi - r, step))
    else:
        yield (lo, lo + r)


def _oddeven_sort(lo: int, hi: int) -> Iterator[tuple[int, int]]:
    """Batcher's odd-even merge sort of wires ``lo..hi`` (a power of two of them)."""
    if hi > lo:
        mid = lo + (hi - lo) // 2
        yield from _oddeven_sort(lo, mid)
        yield from _oddeven_sort(mid + 1, hi)
        yield from _oddeven_merge(lo, hi, 1)


def median_network(k: int) -> tuple[list[tuple[str, str, str, str]], str]:
    """The min/max operations that give the median of a ``k x k`` window whose columns
    are sorted (``k`` = 5; see the module docstring).

    Parameters
    ----------
    k : int
        5 (the 3x3 kernel's five operations are written by hand).

    Returns
    -------
    ops : list of (name, 'min' or 'max', a, b)
        ``name = kind(a, b)`` in order; inputs are ``c{j}{i}``, the ``i``-th smallest of
        the window's column ``j``; temporaries are ``t0, t1, ...``.
    out : str
        The name holding the median.
    """
    if k != 5:
        raise ValueError("median_network builds the 5x5 network only")
    ops: list[tuple[str, str, str, str]] = []
    count = 0

    def exchange(wires: list[str], i: int, j: int) -> None:
        nonlocal count
        a, b = wires[i], wires[j]
        if b == "inf":  # min(a, inf) = a: nothing to do
            return
        if a == "inf":  # the value moves down, the infinity up
            wires[i], wires[j] = b, a
            return
        lo, hi = f"u{count}", f"u{count + 1}"
        count += 2
        ops.append((lo, "min", a, b))
        ops.append((hi, "max", a, b))
        wires[i], wires[j] = lo, hi

    rows = [[f"c{j}{i}" for j in range(k)] for i in range(k)]
    for row in rows:
        for i, j in SORT5:
            exchange(row, i, j)
    half = k * k // 2 + 1  # 13
    cand = [rows[i][j] for i in range(k) for j in range(k)
            if (i + 1) * (j + 1) <= half and (k - i) * (k - j) <= half]  # fmt: skip
    wires = cand + ["inf"] * (16 - len(cand))
    for i, j in _oddeven_sort(0, 15):
        exchange(wires, i, j)
    out = wires[len(cand) // 2]
    need, kept = {out}, []
    for op in reversed(ops):  # keep what the median depends on
        if op[0] in need:
            kept.append(op)
            need |= {op[2], op[3]}
    kept.reverse()
    names = {op[0]: f"t{n}" for n, op in enumerate(kept)}
    renamed = [(names[n], kind, names.get(a, a), names.get(b, b)) for n, kind, a, b in kept]
    return renamed, names[out]


# fmt: off
def _make_median5(stride: int) -> Callable[..., None]:
    """Compile the 5x5 median for one tap stride (the channel count).

    ``stride`` is frozen as a compile-time constant, so that LLVM vectorizes the passes
    (as :func:`robopercept.imaging.filters` does for its taps)."""

    @njit(cache=True, nogil=True)
    def median(src, cidx, ridx, channels, out):  # pragma: no cover - compiled
        """out: the median of each 5 x 5 window of src, (H, W*C); cidx, ridx: the
        padded column and row indices (border_indices)."""
        s = stride
        height, n = out.shape
        r = 2
        m = cidx.shape[0] * s  # the padded row length
        s0, s1, s2 = np.empty(m, src.dtype), np.empty(m, src.dtype), np.empty(m, src.dtype)
        s3, s4 = np.empty(m, src.dtype), np.empty(m, src.dtype)
        for y in range(height):
            # 1. the window's rows, each column sorted (the interior, then the border)
            b0, b1, b2 = s0[r * s : r * s + n], s1[r * s : r * s + n], s2[r * s : r * s + n]
            b3, b4 = s3[r * s : r * s + n], s4[r * s : r * s + n]
            r0, r1, r2 = src[ridx[y]], src[ridx[y + 1]], src[ridx[y + 2]]
            r3, r4 = src[ridx[y + 3]], src[ridx[y + 4]]
            for x in range(n):
                v0, v1, v2, v3, v4 = r0[x], r1[x], r2[x], r3[x], r4[x]
                v0, v1 = min(v0, v1), max(v0, v1)  # SORT5
                v3, v4 = min(v3, v4), max(v3, v4)
                v2, v4 = min(v2, v4), max(v2, v4)
                v2, v3 = min(v2, v3), max(v2, v3)
                v1, v4 = min(v1, v4), max(v1, v4)
                v0, v3 = min(v0, v3), max(v0, v3)
                v0, v2 = min(v0, v2), max(v0, v2)
                v1, v3 = min(v1, v3), max(v1, v3)
                v1, v2 = min(v1, v2), max(v1, v2)
                b0[x], b1[x], b2[x], b3[x], b4[x] = v0, v1, v2, v3, v4
            for b in range(2 * r):  # the r padded columns on each side
                p = b if b < r else cidx.shape[0] - 2 * r + b
                q = (cidx[p] + r) * s
                for c in range(s):
                    s0[p * s + c], s1[p * s + c], s2[p * s + c] = s0[q + c], s1[q + c], s2[q + c]
                    s3[p * s + c], s4[p * s + c] = s3[q + c], s4[q + c]
            # 2. the windows
            o = out[y]
            C00, C01, C02, C03, C04 = s0[:n], s1[:n], s2[:n], s3[:n], s4[:n]
            C10, C11, C12 = s0[s : s + n], s1[s : s + n], s2[s : s + n]
            C13, C14 = s3[s : s + n], s4[s : s + n]
            C20, C21, C22 = s0[2 * s : 2 * s + n], s1[2 * s : 2 * s + n], s2[2 * s : 2 * s + n]
            C23, C24 = s3[2 * s : 2 * s + n], s4[2 * s : 2 * s + n]
            C30, C31, C32 = s0[3 * s : 3 * s + n], s1[3 * s : 3 * s + n], s2[3 * s : 3 * s + n]
            C33, C34 = s3[3 * s : 3 * s + n], s4[3 * s : 3 * s + n]
            C40, C41, C42 = s0[4 * s : 4 * s + n], s1[4 * s : 4 * s + n], s2[4 * s : 4 * s + n]
            C43, C44 = s3[4 * s : 4 * s + n], s4[4 * s : 4 * s + n]
            for x in range(n):
                c00, c01, c02, c03, c04 = C00[x], C01[x], C02[x], C03[x], C04[x]
                c10, c11, c12, c13, c14 = C10[x], C11[x], C12[x], C13[x], C14[x]
                c20, c21, c22, c23, c24 = C20[x], C21[x], C22[x], C23[x], C24[x]
                c30, c31, c32, c33, c34 = C30[x], C31[x], C32[x], C33[x], C34[x]
                c40, c41, c42, c43, c44 = C40[x], C41[x], C42[x], C43[x], C44[x]
                # median_network(5), written out
                t0 = min(c00, c10)
                t1 = max(c00, c10)
                t2 = min(c30, c40)
                t3 = max(c30, c40)
                t4 = min(c20, t3)
                t5 = max(c20, t3)
                t6 = max(t4, t2)
                t7 = min(t1, t5)
                t8 = max(t1, t5)
                t9 = max(t0, t6)
                t10 = max(t7, t9)
                t11 = min(c01, c11)
                t12 = max(c01, c11)
                t13 = min(c31, c41)
                t14 = max(c31, c41)
                t15 = min(c21, t14)
                t16 = max(c21, t14)
                t17 = min(t15, t13)
                t18 = max(t15, t13)
                t19 = min(t12, t16)
                t20 = max(t12, t16)
                t21 = min(t11, t18)
                t22 = max(t11, t18)
                t23 = max(t21, t17)
                t24 = min(t19, t22)
                t25 = max(t19, t22)
                t26 = max(t24, t23)
                t27 = min(c02, c12)
                t28 = max(c02, c12)
                t29 = min(c32, c42)
                t30 = max(c32, c42)
                t31 = min(c22, t30)
                t32 = max(c22, t30)
                t33 = min(t31, t29)
                t34 = max(t31, t29)
                t35 = min(t28, t32)
                t36 = min(t27, t34)
                t37 = max(t27, t34)
                t38 = max(t36, t33)
                t39 = min(t35, t37)
                t40 = max(t35, t37)
                t41 = min(t39, t38)
                t42 = max(t39, t38)
                t43 = min(c03, c13)
                t44 = max(c03, c13)
                t45 = min(c33, c43)
                t46 = max(c33, c43)
                t47 = min(c23, t46)
                t48 = max(c23, t46)
                t49 = min(t47, t45)
                t50 = max(t47, t45)
                t51 = min(t44, t48)
                t52 = min(t43, t50)
                t53 = max(t43, t50)
                t54 = min(t52, t49)
                t55 = max(t52, t49)
                t56 = min(t51, t53)
                t57 = min(t56, t55)
                t58 = max(t56, t55)
                t59 = min(c04, c14)
                t60 = max(c04, c14)
                t61 = min(c34, c44)
                t62 = max(c34, c44)
                t63 = min(c24, t62)
                t64 = max(c24, t62)
                t65 = min(t63, t61)
                t66 = max(t63, t61)
                t67 = min(t60, t64)
                t68 = min(t59, t66)
                t69 = max(t59, t66)
                t70 = min(t68, t65)
                t71 = max(t68, t65)
                t72 = min(t67, t69)
                t73 = min(t72, t71)
                t74 = min(t10, t8)
                t75 = max(t10, t8)
                t76 = min(t26, t25)
                t77 = max(t26, t25)
                t78 = min(t74, t76)
                t79 = max(t74, t76)
                t80 = min(t75, t77)
                t81 = max(t75, t77)
                t82 = min(t80, t79)
                t83 = max(t80, t79)
                t84 = min(t20, t41)
                t85 = max(t20, t41)
                t86 = min(t42, t40)
                t87 = max(t42, t40)
                t88 = min(t84, t86)
                t89 = max(t84, t86)
                t90 = min(t85, t87)
                t91 = max(t85, t87)
                t92 = min(t90, t89)
                t93 = max(t90, t89)
                t94 = min(t78, t88)
                t95 = max(t78, t88)
                t96 = min(t83, t93)
                t97 = max(t83, t93)
                t98 = min(t96, t95)
                t99 = max(t96, t95)
                t100 = min(t82, t92)
                t101 = max(t82, t92)
                t102 = min(t81, t91)
                t103 = min(t102, t101)
                t104 = max(t102, t101)
                t105 = min(t100, t98)
                t106 = max(t100, t98)
                t107 = min(t103, t99)
                t108 = max(t103, t99)
                t109 = min(t104, t97)
                t110 = max(t104, t97)
                t111 = min(t54, t57)
                t112 = max(t54, t57)
                t113 = min(t58, t70)
                t114 = max(t58, t70)
                t115 = min(t111, t113)
                t116 = max(t111, t113)
                t117 = min(t112, t114)
                t118 = max(t112, t114)
                t119 = min(t117, t116)
                t120 = max(t117, t116)
                t121 = min(t115, t73)
                t122 = max(t115, t73)
                t123 = min(t120, t122)
                t124 = max(t120, t122)
                t125 = min(t119, t123)
                t126 = max(t119, t123)
                t127 = min(t118, t124)
                t128 = max(t118, t124)
                t129 = max(t94, t121)
                t130 = min(t108, t128)
                t131 = max(t130, t129)
                t132 = max(t106, t126)
                t133 = min(t110, t132)
                t134 = min(t133, t131)
                t135 = max(t105, t125)
                t136 = min(t109, t135)
                t137 = min(t107, t127)
                t138 = max(t137, t136)
                t139 = max(t138, t134)
                o[x] = t139

    return median
# fmt: on


@njit(cache=True, nogil=True, inline="always")
def _sort3(a, b, c):  # pragma: no cover - compiled
    # a column of three, sorted: six min/max
    lo, hi = min(a, b), max(a, b)
    return min(lo, c), max(lo, min(hi, c)), max(hi, c)


@njit(cache=True, nogil=True, inline="always")
def _med9(l0, l1, l2, m0, m1, m2, h0, h1, h2):  # pragma: no cover - compiled
    # the 3x3 median from its three sorted columns (lows l, middles m, highs h)
    lo = max(max(l0, l1), l2)
    hi = min(min(h0, h1), h2)
    me = max(min(m0, m1), min(max(m0, m1), m2))
    return max(min(lo, me), min(max(lo, me), hi))


@njit(cache=True, nogil=True, inline="always")
def _median3_span(t0, t1, t2, m0, m1, m2, b0, b1, b2, out, count):  # pragma: no cover
    # out[x] = the median of the window whose top, middle and bottom rows are t, m, b
    # (columns 0, 1, 2 of each), for x in 0..count-1: one vectorized loop
    for x in range(count):
        l0, c0, h0 = _sort3(t0[x], m0[x], b0[x])
        l1, c1, h1 = _sort3(t1[x], m1[x], b1[x])
        l2, c2, h2 = _sort3(t2[x], m2[x], b2[x])
        out[x] = _med9(l0, l1, l2, c0, c1, c2, h0, h1, h2)


@njit(cache=True, nogil=True, inline="always")
def _median3_columns(r0, r1, r2, o, cidx, s, first, last):  # pragma: no cover - compiled
    # output columns first and last of one row (every channel), through the border map
    for xc in (first, last):
        for c in range(s):
            j0, j1, j2 = cidx[xc] * s + c, cidx[xc + 1] * s + c, cidx[xc + 2] * s + c
            l0, c0, h0 = _sort3(r0[j0], r1[j0], r2[j0])
            l1, c1, h1 = _sort3(r0[j1], r1[j1], r2[j1])
            l2, c2, h2 = _sort3(r0[j2], r1[j2], r2[j2])
            o[xc * s + c] = _med9(l0, l1, l2, c0, c1, c2, h0, h1, h2)


@njit(cache=True, nogil=True, inline="always")
def _median3_row(r0, r1, r2, o, cidx, s):  # pragma: no cover - compiled
    # one output row from its three source rows: the interior, then the edge columns
    n = o.shape[0]
    w = n // s
    if w >= 3:
        m = n - 2 * s
        _median3_span(
            r0[:m], r0[s : s + m], r0[2 * s :], r1[:m], r1[s : s + m], r1[2 * s :],
            r2[:m], r2[s : s + m], r2[2 * s :], o[s : s + m], m,
        )  # fmt: skip
        _median3_columns(r0, r1, r2, o, cidx, s, 0, w - 1)
    else:
        for xc in range(w):
            _median3_columns(r0, r1, r2, o, cidx, s, xc, xc)


def _make_median3(stride: int) -> Callable[..., None]:
    """Compile the 3x3 median for one tap stride (the channel count).

    The interior of the image, every row but the first and last, is one loop over the
    flat array: output ``i`` reads source ``i + d`` for the nine offsets ``d`` of its
    window (rows ``-n, 0, n`` apart, columns ``-s, 0, s``), so one vectorized loop runs
    over all the rows with no per-row setup. The positions where that loop wraps from
    one row's end to the next row's start (each row's first and last column) are then
    rewritten through the border map, and so are the first and last rows."""

    @njit(cache=True, nogil=True)
    def median(src, cidx, ridx, channels, out):  # pragma: no cover - compiled
        """out: the median of each 3 x 3 window of src, (H, W*C); cidx, ridx: the
        padded column and row indices (border_indices)."""
        s = stride
        height, n = out.shape
        interior = height >= 3 and n >= 3 * s
        if interior:
            fs, fo = src.reshape(-1), out.reshape(-1)
            a = n + s  # row 1, column 1: the first interior output
            e = (height - 1) * n - s  # past row height - 2, column w - 2
            _median3_span(
                fs[a - n - s : e - n - s], fs[a - n : e - n], fs[a - n + s : e - n + s],
                fs[a - s : e - s], fs[a:e], fs[a + s : e + s],
                fs[a + n - s : e + n - s], fs[a + n : e + n], fs[a + n + s : e + n + s],
                fo[a:e], e - a,
            )  # fmt: skip
            for y in range(1, height - 1):  # the columns where the flat loop wrapped
                r0, r1, r2 = src[ridx[y]], src[ridx[y + 1]], src[ridx[y + 2]]
                _median3_columns(r0, r1, r2, out[y], cidx, s, 0, n // s - 1)
        for y in range(height):
            if not interior or y == 0 or y == height - 1:
                _median3_row(src[ridx[y]], src[ridx[y + 1]], src[ridx[y + 2]], out[y], cidx, s)

    return median


_median3_gray = _make_median3(1)
_median3_rgb = _make_median3(3)
_median5_gray = _make_median5(1)
_median5_rgb = _make_median5(3)


def median_rows(
    src: np.ndarray, cidx: np.ndarray, ridx: np.ndarray, channels: int, k: int, out: np.ndarray
) -> None:
    """Write into ``out`` the median of each ``k x k`` window of ``src`` (``k`` 3 or 5).

    Parameters
    ----------
    src, out : (H, W*C) ndarray
        The image as rows (channels interleaved), and the output of the same shape and
        dtype, both C-contiguous.
    cidx, ridx : (W + k - 1,), (H + k - 1,) ndarray of int
        The source column and row of each padded position
        (:func:`robopercept.imaging.filters.border_indices`, a border without
        constants).
    channels : int
        1 or 3.
    k : int
        3 or 5.
    """
    if not (src.flags.c_contiguous and out.flags.c_contiguous):
        raise ValueError("median_rows takes C-contiguous src and out (np.ascontiguousarray)")
    if (k, channels) == (3, 1):
        _median3_gray(src, cidx, ridx, 1, out)
    elif (k, channels) == (3, 3):
        _median3_rgb(src, cidx, ridx, 3, out)
    elif (k, channels) == (5, 1):
        _median5_gray(src, cidx, ridx, 1, out)
    elif (k, channels) == (5, 3):
        _median5_rgb(src, cidx, ridx, 3, out)
    else:
        raise ValueError(f"median_rows takes k 3 or 5 and 1 or 3 channels; got {k}, {channels}")
