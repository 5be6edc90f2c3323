r"""Chessboard detection: the inner corners of a calibration board, ordered, to subpixel
accuracy.

:func:`find_chessboard_corners` works in four steps.

1. **Saddle response.** On the image blurred with :math:`\sigma = 1.5` px, the Hessian
   determinant is negative at an X-junction (intensity curves up along one diagonal and
   down along the other), zero on a straight edge of any direction and positive on a
   blob, so :math:`S = I_{xy}^2 - I_{xx} I_{yy}` peaks at chessboard corners. Local
   maxima of S (5 x 5) above 2 % of its largest value are the candidates.
2. **Ring test.** Around each candidate, 32 samples on a circle of radius 5 px must split,
   about their mid-level, into exactly four arcs (dark, bright, dark, bright) of
   reasonable length and contrast; the four transitions give the two edge directions
   through the corner. This rejects text, T-junctions and the board's outer corners.
3. **Grid growing** (compiled, shared with the circle-grid detector). Seeds are tried
   strongest saddle first (a printed board's corners are usually the sharpest
   X-junctions in view). From a seed, the neighbours along the two edge directions start
   a lattice; every further node is predicted by the parallelogram rule
   :math:`p_{i,j} \approx p_{i-1,j} + p_{i,j-1} - p_{i-1,j-1}` (or by linear
   extrapolation along a row), and the nearest candidate within 0.3 of the local
   spacing fills it. Perspective and lens distortion change the spacing slowly, so
   the predictions follow them. The board is found when a lattice has exactly the
   pattern's size with every node filled; otherwise the next seed is tried (a second,
   smaller board in the background does not confuse it).
4. **Subpixel refinement** (:func:`robopercept.features.refine_corners`, the method of
   ``cv2.cornerSubPix``):
   at the true corner q every image gradient :math:`g_p` in the window is orthogonal to
   :math:`p - q` (it lies on an edge through q or in a flat region), so q solves
   :math:`\left(\sum_p w_p g_p g_p^T\right) q = \sum_p w_p g_p g_p^T p`, iterated with
   Gaussian weights :math:`w_p` until the step is below 0.01 px.

**Order**, as OpenCV: row by row, ``pattern_size[0]`` corners per row; the column step
turns clockwise (on screen, y down) into the row step; and when the board is not
symmetric under a half turn (``w + h`` odd), the first corner touches black squares
diagonally. For symmetric boards the first corner is the one higher in the image.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numba import njit

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.calibration._lattice import along, grow_lattice
from robopercept.errors import InputError
from robopercept.features.harris import refine_corners
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.filters import gaussian_blur

__all__ = [
    "ChessboardDetection",
    "check_pattern_size",
    "chessboard_points",
    "find_chessboard_corners",
]

#: most points a calibration pattern may have (w * h): 24 MB of board coordinates
MAX_PATTERN_POINTS = 1_000_000
#: largest square side or circle spacing: board coordinates up to it times the pattern
#: size stay within the 1e150 the calibration accepts
MAX_LENGTH = 1e140

_RING = 32
_RADIUS = 5.0
_SIGMA = 1.5
_CONTRAST = 20.0  # grey levels (0-255 scale)


@dataclass(frozen=True)
class ChessboardDetection:
    """Result of :func:`find_chessboard_corners`.

    It unpacks as the tuple of ``ok, corners = cv2.findChessboardCorners(gray, (9, 6))``:
    ``ok, corners = find_chessboard_corners(gray, (9, 6))`` gives ``ok`` (bool) and,
    when found, ``corners`` as OpenCV's ``(w * h, 1, 2)`` float32 array (ready for
    ``cv2.cornerSubPix``, ``cv2.calibrateCamera`` and ``cv2.drawChessboardCorners``, and
    taken by :func:`~robopercept.calibration.calibrate_camera`,
    :func:`~robopercept.calibration.board_pose` and
    :func:`~robopercept.estimation.find_homography`), or ``None`` when not found, as
    OpenCV gives.
    The attributes stay the primary interface: :attr:`corners` there is (w * h, 2)
    float64, at full precision, and holds the partial lattice when not found.

    Attributes
    ----------
    found : bool
        Whether the whole board was found.
    corners : (w * h, 2) ndarray
        Ordered subpixel corners ``(x, y)`` when found, else whatever partial lattice
        was largest (unordered, for drawing), possibly empty.
    pattern_size : (int, int)
    reason : str
        Why the board was not found ("" when found).
    """

    found: bool
    corners: np.ndarray
    pattern_size: tuple[int, int]
    reason: str = ""

    def __iter__(self) -> Iterator[bool | np.ndarray | None]:
        """``ok, corners``, the order of ``cv2.findChessboardCorners``'s result."""
        corners = self.corners.astype(np.float32).reshape(-1, 1, 2) if self.found else None
        return iter((bool(self.found), corners))


def chessboard_points(pattern_size: tuple[int, int], square: float = 1.0) -> np.ndarray:
    """Board coordinates of the inner corners, in the detection order.

    Corner ``k`` (row ``k // w``, column ``k % w``) sits at ``(column * square,
    row * square, 0)``, as the usual ``np.mgrid`` construction for
    ``cv2.calibrateCamera``.

    Parameters
    ----------
    pattern_size : (int, int)
        Inner corners per row and per column, ``(w, h)``.
    square : float
        Side of a square (the unit of the calibration's translations).

    Returns
    -------
    (w * h, 3) float64 ndarray

    Raises
    ------
    InputError
        A ``pattern_size`` that :func:`check_pattern_size` refuses, or ``square`` not a
        real number in (0, 1e150].

    Examples
    --------
    >>> chessboard_points((3, 2), 0.5)[:, :2].tolist()
    [[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [0.0, 0.5], [0.5, 0.5], [1.0, 0.5]]
    """
    w, h = check_pattern_size(pattern_size)
    square = check_real(square, "square", 0.0, MAX_LENGTH, low_inclusive=False)
    out = np.zeros((w * h, 3))
    out[:, 0] = np.tile(np.arange(w), h) * square
    out[:, 1] = np.repeat(np.arange(h), w) * square
    return out


def check_pattern_size(pattern_size: tuple[int, int], noun: str = "corners") -> tuple[int, int]:
    """Validate the size of a calibration pattern, as OpenCV's ``patternSize``.

    ``(w, h)``: the number of points (a chessboard's inner corners, a grid's circles)
    per row and per column, each a whole number at least 2, and at most
    :data:`MAX_PATTERN_POINTS` points in all (a bound on the arrays built from it). Used
    by every detector and board model of this package.

    Parameters
    ----------
    pattern_size : (int, int)
        ``(points per row, points per column)``.
    noun : str
        What the points are, for the error message (``"corners"``, ``"circles"``).

    Returns
    -------
    (int, int)
        ``(w, h)`` as Python ints.

    Raises
    ------
    InputError
        If ``pattern_size`` is not a pair of whole numbers (``9.0`` is taken; ``9.5``,
        NaN/inf, bools and strings are not), either is below 2, or ``w * h`` exceeds
        :data:`MAX_PATTERN_POINTS`.

    Examples
    --------
    >>> check_pattern_size((9, 6))
    (9, 6)
    """
    want = (
        f"pattern_size must be ({noun} per row, {noun} per column), two whole numbers; "
        f"got {plain_repr(pattern_size)}"
    )
    items = pattern_size.tolist() if isinstance(pattern_size, np.ndarray) else pattern_size
    if not isinstance(items, (tuple, list)) or len(items) != 2:
        raise InputError(want)
    wh = []
    for v in items:
        if isinstance(v, (float, np.floating)) and np.isfinite(v) and float(v).is_integer():
            v = int(v)
        try:
            wh.append(check_int(v, "pattern_size"))
        except InputError:
            raise InputError(want) from None
    w, h = wh
    if w < 2 or h < 2:
        inner = "inner " if noun == "corners" else ""
        raise InputError(f"pattern_size needs at least 2 x 2 {inner}{noun}; got {(w, h)}")
    if w * h > MAX_PATTERN_POINTS:
        raise InputError(
            f"pattern_size {(w, h)} has {w * h} {noun}, more than {MAX_PATTERN_POINTS}: "
            f"give the {noun} per row and per column of the printed pattern, e.g. (9, 6)"
        )
    return w, h


# --------------------------------------------------------------------------- kernels


@njit(cache=True, nogil=True)
def _saddle_candidates(b, thr, max_out):  # pragma: no cover - compiled
    h, w = b.shape
    s = np.zeros((h, w), np.float32)
    two = np.float32(2.0)  # float32 throughout (a float64 constant would widen the loop)
    quarter = np.float32(0.25)
    zero = np.float32(0.0)
    for y in range(1, h - 1):
        up, row, down, out_row = b[y - 1], b[y], b[y + 1], s[y]  # row slices vectorize
        for x in range(1, w - 1):
            ixx = row[x + 1] - two * row[x] + row[x - 1]
            iyy = down[x] - two * row[x] + up[x]
            ixy = quarter * (down[x + 1] - down[x - 1] - up[x + 1] + up[x - 1])
            v = ixy * ixy - ixx * iyy
            out_row[x] = v if v > zero else zero
    out = np.empty((max_out, 3), np.float64)
    n = 0
    m = 8  # keep away from the border: the ring needs room
    for y in range(m, h - m):
        for x in range(m, w - m):
            v = s[y, x]
            if v <= thr:
                continue
            # a strict 5 x 5 maximum; ties go to the first in row-major order
            is_max = True
            for dy in range(-2, 3):
                for dx in range(-2, 3):
                    u = s[y + dy, x + dx]
                    if u > v or (u == v and (dy < 0 or (dy == 0 and dx < 0))):
                        is_max = False
                        break
                if not is_max:
                    break
            if is_max and n < max_out:
                out[n, 0] = x
                out[n, 1] = y
                out[n, 2] = v
                n += 1
    return out[:n]


@njit(cache=True, nogil=True)
def _bilinear(img, x, y):  # pragma: no cover - compiled
    h, w = img.shape
    x = min(max(x, 0.0), w - 1.001)
    y = min(max(y, 0.0), h - 1.001)
    x0 = int(x)
    y0 = int(y)
    fx = x - x0
    fy = y - y0
    return (1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x0 + 1]) + fy * (
        (1 - fx) * img[y0 + 1, x0] + fx * img[y0 + 1, x0 + 1]
    )


@njit(cache=True, nogil=True)
def _ring_test(b, pts, radius, n, min_contrast, max_asym):  # pragma: no cover - compiled
    """Per candidate: ok flag and the two edge directions (unit vectors)."""
    m = pts.shape[0]
    ok = np.zeros(m, np.bool_)
    dirs = np.zeros((m, 2, 2), np.float64)
    v = np.empty(n, np.float64)
    ox = np.empty(n, np.float64)  # the ring's offsets, computed once
    oy = np.empty(n, np.float64)
    for k in range(n):
        ox[k] = radius * np.cos(2.0 * np.pi * k / n)
        oy[k] = radius * np.sin(2.0 * np.pi * k / n)
    for c in range(m):
        lo = 1e30
        hi = -1e30
        for k in range(n):
            v[k] = _bilinear(b, pts[c, 0] + ox[k], pts[c, 1] + oy[k])
            lo = min(lo, v[k])
            hi = max(hi, v[k])
        if hi - lo < min_contrast:
            continue
        asym = 0.0  # an X-junction is point-symmetric: v(a) = v(a + pi)
        for k in range(n // 2):
            asym += abs(v[k] - v[k + n // 2])
        if asym / (n // 2) > max_asym * (hi - lo):
            continue
        mid = 0.5 * (lo + hi)
        trans = np.empty(8, np.float64)
        nt = 0
        for k in range(n):
            a0 = v[k] - mid
            a1 = v[(k + 1) % n] - mid
            if (a0 > 0) != (a1 > 0):
                if nt < 8:
                    f = a0 / (a0 - a1)
                    trans[nt] = 2.0 * np.pi * (k + f) / n
                nt += 1
        if nt != 4:
            continue
        good = True
        for t in range(4):  # each arc at least 2 samples wide
            d = trans[(t + 1) % 4] - trans[t]
            if d < 0:
                d += 2 * np.pi
            if d < 2.0 * 2.0 * np.pi / n:
                good = False
        if not good:
            continue
        for t in range(2):  # the two edges cross the corner: t and t+2 nearly opposite
            d = abs(trans[t + 2] - trans[t] - np.pi)
            if d > 0.6:
                good = False
            ux = np.cos(trans[t]) - np.cos(trans[t + 2])
            uy = np.sin(trans[t]) - np.sin(trans[t + 2])
            nu = np.hypot(ux, uy)
            dirs[c, t, 0] = ux / nu
            dirs[c, t, 1] = uy / nu
        ok[c] = good
    return ok, dirs


# --------------------------------------------------------------------------- lattice


def _seed_neighbours(pts: np.ndarray, dirs: np.ndarray, s: int) -> dict:
    """Nearest candidates along the seed's +-u, +-v directions (within 15 degrees)."""
    d = pts - pts[s]
    dist = np.hypot(d[:, 0], d[:, 1])
    dist[s] = np.inf
    out = {}
    for axis in range(2):
        u = dirs[s, axis]
        for sign in (1, -1):
            cos = sign * (d @ u) / np.maximum(dist, 1e-9)
            ok = (cos > np.cos(np.deg2rad(15))) & (dist > 3)
            if ok.any():
                k = int(np.argmin(np.where(ok, dist, np.inf)))
                key = (sign, 0) if axis == 0 else (0, sign)
                out[key] = k
    return out


def _step(grid: dict, pts: np.ndarray, i: int, j: int, di: int, dj: int) -> np.ndarray | None:
    """Lattice step along (di, dj) at node (i, j), from it or from a node beside it."""
    for a, b in ((0, 0), (dj, di), (-dj, -di)):
        p, q, r = (i + a, j + b), (i + a + di, j + b + dj), (i + a - di, j + b - dj)
        if p in grid and q in grid:
            return pts[grid[q]] - pts[grid[p]]
        if p in grid and r in grid:
            return pts[grid[p]] - pts[grid[r]]
    return None


def _cells_ok(gray: np.ndarray, grid: dict, pts: np.ndarray, i: int, j: int) -> bool:
    """The four cells around node (i, j) must alternate: both diagonal cells of one
    pair darker, by the minimum contrast, than both of the other (an inner corner of a
    chessboard; not a corner on the board's rim next to the background)."""
    si, sj = _step(grid, pts, i, j, 1, 0), _step(grid, pts, i, j, 0, 1)
    if si is None or sj is None:
        return True  # not decidable yet
    p = pts[grid[(i, j)]]
    v = [
        _bilinear(gray, *(p + 0.5 * (a * si + b * sj)))
        for a, b in ((1, 1), (-1, -1), (1, -1), (-1, 1))
    ]
    gap = max(min(v[0], v[1]) - max(v[2], v[3]), min(v[2], v[3]) - max(v[0], v[1]))
    return gap > _CONTRAST


def _trim(grid: dict, pts: np.ndarray, n: int, gray: np.ndarray) -> dict:
    """While the lattice has more than ``n`` nodes, drop the outer line that looks least
    like part of the board: the fraction of its nodes failing :func:`_cells_ok` (rim
    corners beside the background) plus the fraction of its places left empty (a real
    board fills every line); lines scoring under 0.5 stay."""
    grid = dict(grid)
    while len(grid) > n:
        ii = [a for a, _ in grid]
        jj = [b for _, b in grid]
        extent = (max(jj) - min(jj) + 1, max(ii) - min(ii) + 1)
        worst, score = None, 0.5
        for axis, value in ((0, min(ii)), (0, max(ii)), (1, min(jj)), (1, max(jj))):
            line = [key for key in grid if key[axis] == value]
            bad = sum(not _cells_ok(gray, grid, pts, *key) for key in line) / len(line)
            empty = 1.0 - len(line) / extent[axis]
            if bad + empty > score:
                worst, score = line, bad + empty
        if worst is None:
            break
        for key in worst:
            del grid[key]
    return grid


def _grow(pts: np.ndarray, dirs: np.ndarray, s: int, limit: int) -> dict:
    """Lattice ``{(i, j): candidate}`` grown from seed ``s``: its nearest neighbours
    along its two edge directions start it, :func:`grow_lattice` does the rest."""
    nb = _seed_neighbours(pts, dirs, s)
    if (1, 0) not in nb or (0, 1) not in nb:
        return {(0, 0): s}
    # the first steps must be mutually consistent in length
    l1 = np.linalg.norm(pts[nb[(1, 0)]] - pts[s])
    l2 = np.linalg.norm(pts[nb[(0, 1)]] - pts[s])
    if max(l1, l2) > 2.5 * min(l1, l2):
        return {(0, 0): s}
    for key in ((1, 0), (0, 1)):
        k = nb[key]
        dx, dy = pts[k] - pts[s]
        if not along(dirs, k, float(dx), float(dy)):
            return {(0, 0): s}
    return grow_lattice(pts, s, nb[(1, 0)], nb[(0, 1)], limit, dirs)


def _order(grid: dict, pts: np.ndarray, w: int, h: int, gray: np.ndarray) -> np.ndarray | None:
    ii = np.array([a for a, _ in grid])
    jj = np.array([b for _, b in grid])
    ni, nj = ii.max() - ii.min() + 1, jj.max() - jj.min() + 1
    if len(grid) != w * h or {ni, nj} != {w, h}:
        return None
    lattice = np.empty((nj, ni, 2))
    for (i, j), k in grid.items():
        lattice[j - jj.min(), i - ii.min()] = pts[k]
    if (nj, ni) != (h, w):
        lattice = lattice.transpose(1, 0, 2)
    # the column step turns clockwise into the row step (y down); else mirror the rows
    a, b = lattice[0, 1] - lattice[0, 0], lattice[1, 0] - lattice[0, 0]
    if a[0] * b[1] - a[1] * b[0] < 0:
        lattice = lattice[:, ::-1]
    flat = lattice.reshape(-1, 2)
    if (w + h) % 2:  # not symmetric under a half turn: first corner on black squares
        q = lattice
        inner = _bilinear(gray, *(0.25 * (q[0, 0] + q[0, 1] + q[1, 0] + q[1, 1])))
        side = _bilinear(gray, *(0.25 * (q[0, 1] + q[0, 2] + q[1, 1] + q[1, 2])))
        if inner > side:
            flat = flat[::-1]
    elif flat[0, 1] > flat[-1, 1]:
        flat = flat[::-1]
    return flat.copy()


def find_chessboard_corners(
    image: np.ndarray,
    pattern_size: tuple[int, int],
    *,
    refine: bool = True,
    half_window: int | None = None,
    max_seeds: int = 30,
) -> ChessboardDetection:
    """Find the inner corners of a chessboard (``cv2.findChessboardCorners`` followed by
    ``cv2.cornerSubPix``).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 or float image (RGB for colour).
    pattern_size : (int, int)
        Inner corners per row and per column, e.g. ``(9, 6)`` for a board of 10 x 7
        squares.
    refine : bool
        Subpixel refinement with :func:`robopercept.features.refine_corners`.
    half_window : int, optional
        Its window half-size; default half the smallest corner spacing, at most 11
        (the value OpenCV's calibration sample passes to ``cornerSubPix``).
    max_seeds : int
        Lattices (of 4 corners or more) grown before giving up.

    Returns
    -------
    ChessboardDetection
        ``found`` is False (with the reason) unless every inner corner was found.
        Unpacks as ``ok, corners`` in the order of ``cv2.findChessboardCorners``
        (corners ``(w * h, 1, 2)`` float32, or None when not found).

    Raises
    ------
    InputError
        An image that :func:`~robopercept.imaging.rgb_to_gray` refuses, a
        ``pattern_size`` that :func:`check_pattern_size` refuses, or a parameter of the
        wrong type or range.
    """
    w, h = check_pattern_size(pattern_size)
    refine = check_bool(refine, "refine")
    if half_window is not None:
        half_window = check_int(half_window, "half_window", 1)
    max_seeds = check_int(max_seeds, "max_seeds", 1)
    gray = np.ascontiguousarray(rgb_to_gray(image), dtype=np.float64)  # validates; same scale
    if gray.dtype.kind == "f" and gray.max() <= 1.0 + 1e-9 and image.dtype.kind == "f":
        gray = gray * 255.0
    blurred = gaussian_blur(gray.astype(np.float32), _SIGMA)
    # an ideal X-junction of contrast c blurred by sigma has I_xy = c / (pi sigma^2) at its
    # centre; keep a quarter of that response for the weakest contrast accepted
    thr = 0.25 * (_CONTRAST / (np.pi * _SIGMA**2)) ** 2
    cand = _saddle_candidates(blurred, thr, 50000)
    if len(cand) < w * h:
        return ChessboardDetection(False, np.zeros((0, 2)), (w, h), "too few corner candidates")
    ok, dirs = _ring_test(blurred, cand[:, :2].copy(), _RADIUS, _RING, _CONTRAST, 0.25)
    pts, dirs, strength = cand[ok, :2], dirs[ok], cand[ok, 2]
    if len(pts) < w * h:
        return ChessboardDetection(
            False, pts, (w, h), f"only {len(pts)} chessboard-like corners; need {w * h}"
        )
    # seeds: the strongest saddles first. A printed board's black-white corners are the
    # sharpest, highest-contrast X-junctions in most scenes, so its lattice is usually
    # the first one grown, and clutter is never visited.
    order = np.argsort(-strength, kind="stable")
    used = np.zeros(len(pts), dtype=bool)
    largest: dict = {}
    tries = 0
    for s in order:
        if used[s]:
            continue
        grid = _grow(pts, dirs, int(s), max(w, h) + 3)
        used[list(grid.values())] = True
        grid = _trim(grid, pts, w * h, blurred)
        if len(grid) < 4:  # clutter: a seed that starts no lattice costs little
            continue
        tries += 1
        if len(grid) > len(largest):
            largest = grid
        flat = _order(grid, pts, w, h, blurred)
        if flat is None:
            if tries >= max_seeds:
                break
            continue
        if refine:
            hw = half_window
            if hw is None:  # as cv2's usual 11, but inside the smallest square
                lat = flat.reshape(h, w, 2)
                step = min(
                    np.linalg.norm(np.diff(lat, axis=0), axis=2).min(),
                    np.linalg.norm(np.diff(lat, axis=1), axis=2).min(),
                )
                hw = int(np.clip(np.floor(0.5 * step), 2, 11))
            flat = refine_corners(gray, flat, int(hw), max_iter=30, eps=0.01)
        return ChessboardDetection(True, flat, (w, h))
    partial = pts[list(largest.values())] if largest else np.zeros((0, 2))
    reason = (
        f"no complete {w} x {h} lattice of corners (largest found: {len(largest)} corners); "
        "the whole board must be visible, with its white border"
    )
    return ChessboardDetection(False, partial, (w, h), reason)
