r"""Lattice growing, shared by the chessboard and circle-grid detectors.

From three detected points that start a lattice, node :math:`(0, 0)` and its neighbours
:math:`(1, 0)` and :math:`(0, 1)`, every empty node next to the lattice is predicted by
the parallelogram rule

.. math:: p_{i,j} \approx p_{i-1,j} + p_{i,j-1} - p_{i-1,j-1}

(any of the four diagonal orientations), else by linear extrapolation along a line,
:math:`p_{i,j} \approx 2 p_{i-1,j} - p_{i-2,j}`; the nearest free point within 0.3 of
the local spacing fills it. Rounds over the lattice's rim (in row-major order of the
empty nodes) repeat while they add nodes and the lattice spans fewer than ``limit``
nodes along both axes. A node is retried only when more of its neighbours have become
known since its last try. Perspective and lens distortion change the spacing slowly, so
the predictions follow them.

The loop is compiled; the point sets are small (hundreds to a few thousand candidates),
so the nearest free point is found by a scan rather than an index.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["grow_lattice"]

_COS20 = float(np.cos(np.deg2rad(20.0)))
_STEPS = ((1, 0), (-1, 0), (0, 1), (0, -1))
_DIAGONALS = ((1, 1), (1, -1), (-1, 1), (-1, -1))


@njit(cache=True, nogil=True)
def along(dirs, k, sx, sy):  # pragma: no cover - compiled
    """Whether one of point k's two edge directions is within 20 degrees of (sx, sy)."""
    n = max((sx * sx + sy * sy) ** 0.5, 1e-9)
    a = abs(dirs[k, 0, 0] * sx + dirs[k, 0, 1] * sy)
    b = abs(dirs[k, 1, 0] * sx + dirs[k, 1, 1] * sy)
    return max(a, b) > _COS20 * n


@njit(cache=True, nogil=True)
def _predict(G, pts, i, j):  # pragma: no cover - compiled
    # (found, x, y, local spacing) of node (i, j) from the nodes G holds
    for di, dj in _DIAGONALS:
        a = G[i - di, j]
        b = G[i, j - dj]
        c = G[i - di, j - dj]
        if a >= 0 and b >= 0 and c >= 0:
            ax, ay = pts[a, 0] - pts[c, 0], pts[a, 1] - pts[c, 1]
            bx, by = pts[b, 0] - pts[c, 0], pts[b, 1] - pts[c, 1]
            step = min((ax * ax + ay * ay) ** 0.5, (bx * bx + by * by) ** 0.5)
            return True, pts[c, 0] + ax + bx, pts[c, 1] + ay + by, step
    for di, dj in _STEPS:
        a = G[i - di, j - dj]
        b = G[i - 2 * di, j - 2 * dj]
        if a >= 0 and b >= 0:
            dx, dy = pts[a, 0] - pts[b, 0], pts[a, 1] - pts[b, 1]
            return True, pts[a, 0] + dx, pts[a, 1] + dy, (dx * dx + dy * dy) ** 0.5
    return False, 0.0, 0.0, 0.0


@njit(cache=True, nogil=True)
def _nearest(pts, free, x, y, tol):  # pragma: no cover - compiled
    # the nearest free point strictly within tol of (x, y), -1 if none
    best = -1
    bd = tol * tol
    for k in range(pts.shape[0]):
        if free[k]:
            dx = pts[k, 0] - x
            dy = pts[k, 1] - y
            d = dx * dx + dy * dy
            if d < bd:
                bd = d
                best = k
    return best


@njit(cache=True, nogil=True)
def _grow(pts, dirs, check_dirs, seed, limit):  # pragma: no cover - compiled
    off = limit + 3  # node (i, j) lives at G[i + off, j + off]; the lattice spans <= limit + 1
    size = 2 * off + 1
    G = np.full((size, size), -1, np.int64)
    tried = np.full((size, size), -1, np.int64)
    free = np.ones(pts.shape[0], np.bool_)
    G[off, off], G[off + 1, off], G[off, off + 1] = seed[0], seed[1], seed[2]
    for k in seed:
        free[k] = False
    lo_i, hi_i, lo_j, hi_j = off, off + 1, off, off + 1
    fi = np.empty(size * size, np.int64)
    fj = np.empty(size * size, np.int64)
    changed = True
    while changed:
        changed = False
        nf = 0  # this round's empty nodes next to the lattice, row-major (2 from the
        # edge of G, so that predictions two steps back stay inside)
        for i in range(max(lo_i - 1, 2), min(hi_i + 2, size - 2)):
            for j in range(max(lo_j - 1, 2), min(hi_j + 2, size - 2)):
                if G[i, j] < 0 and (
                    G[i - 1, j] >= 0 or G[i + 1, j] >= 0 or G[i, j - 1] >= 0 or G[i, j + 1] >= 0
                ):
                    fi[nf] = i
                    fj[nf] = j
                    nf += 1
        for f in range(nf):
            i, j = fi[f], fj[f]
            known = 0
            for di, dj in _STEPS:
                known += G[i + di, j + dj] >= 0
            if tried[i, j] >= known:
                continue
            ok, x, y, step = _predict(G, pts, i, j)
            if not ok:
                continue
            tried[i, j] = known
            k = _nearest(pts, free, x, y, 0.3 * step)
            if k >= 0 and check_dirs:  # the edges through k must point at its neighbours
                for di, dj in _STEPS:
                    m = G[i + di, j + dj]
                    if m >= 0 and not along(dirs, k, pts[k, 0] - pts[m, 0], pts[k, 1] - pts[m, 1]):
                        k = -1
                        break
            if k >= 0:
                G[i, j] = k
                free[k] = False
                changed = True
                lo_i, hi_i = min(lo_i, i), max(hi_i, i)
                lo_j, hi_j = min(lo_j, j), max(hi_j, j)
        if hi_i - lo_i >= limit or hi_j - lo_j >= limit:
            break
    out = np.empty((np.count_nonzero(G >= 0), 3), np.int64)
    n = 0
    for i in range(size):
        for j in range(size):
            if G[i, j] >= 0:
                out[n, 0], out[n, 1], out[n, 2] = i - off, j - off, G[i, j]
                n += 1
    return out


def grow_lattice(
    pts: np.ndarray,
    seed: int,
    first: int,
    second: int,
    limit: int,
    dirs: np.ndarray | None = None,
) -> dict[tuple[int, int], int]:
    """Lattice ``{(i, j): point index}`` grown from node (0, 0) = ``seed``, (1, 0) =
    ``first`` and (0, 1) = ``second`` (see the module docstring).

    Parameters
    ----------
    pts : (N, 2) float ndarray
        Candidate points.
    seed, first, second : int
        The three points that start the lattice.
    limit : int
        Growing stops once the lattice spans ``limit`` nodes or more along an axis.
    dirs : (N, 2, 2) float ndarray, optional
        Two edge directions per point (chessboard corners): a point joins the lattice
        only if, for each of its known neighbours, one of its directions is within 20
        degrees of the step to that neighbour.
    """
    p = np.ascontiguousarray(pts, dtype=np.float64)
    d = np.zeros((1, 2, 2)) if dirs is None else np.ascontiguousarray(dirs, dtype=np.float64)
    nodes = _grow(p, d, dirs is not None, np.array([seed, first, second], np.int64), int(limit))
    return {(int(i), int(j)): int(k) for i, j, k in nodes}
