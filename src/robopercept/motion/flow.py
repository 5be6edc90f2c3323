r"""Optical flow: pyramidal Lucas-Kanade (Bouguet's formulation, as OpenCV).

Brightness constancy :math:`I(x, y) = J(x + u, y + v)`, linearized, gives one equation
per pixel, :math:`I_x u + I_y v = I - J` (the image gradient :math:`\nabla I` dotted with
the displacement). Over a window of pixels that is an overdetermined system
:math:`S\,d = T` with :math:`S = [I_x\ I_y]` stacked per pixel and :math:`T = I - J`,
solved by least squares,

.. math::

    d = (S^T S)^{-1} S^T T,\qquad
    S^T S = \sum_w \begin{pmatrix} I_x^2 & I_x I_y \\ I_x I_y & I_y^2 \end{pmatrix}.

The linearization holds for small motions only, so the solution is iterated (J is
resampled at the current estimate with bilinear interpolation until the update is
below ``eps`` pixels) and run coarse to fine over a Gaussian pyramid: a displacement of
:math:`d` pixels is :math:`d / 2^L` at level :math:`L`, and each level starts from twice
the estimate of the level above.

:math:`S^T S` is the structure tensor of the window. When its smallest eigenvalue is
small, the window has an edge (or nothing) and the motion along the edge is unknown:
the aperture problem. Such points are flagged, as are points whose window leaves the
image and, unlike OpenCV, points whose iterations did not converge at the finest
level, or whose final window differs from the first by more than ``max_residual`` of
its contrast (a large motion tracked without a pyramid ends one of these two ways
rather than silently wrong).

Conventions are OpenCV's ``calcOpticalFlowPyrLK``: Scharr derivatives, ``levels`` is its
``maxLevel`` (0: no pyramid), the same stopping rules (30 iterations or an update below
0.01 px, and halving an update that undoes the previous one), and the minimum
eigenvalue normalized as OpenCV does (intensities on the 0-255 scale, divided by the
window area, threshold ``1e-4``).
"""

from __future__ import annotations

import enum
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit, prange

from robopercept._checks import (
    check_image,
    check_int,
    check_magnitude,
    check_numeric,
    check_odd_size,
    check_real,
    squeeze_point_axis,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.features.harris import good_features_to_track  # re-exported
from robopercept.imaging.color import gray_255
from robopercept.imaging.pyramids import pyr_down_unchecked

__all__ = [
    "FlowStatus",
    "MotionClass",
    "SparseFlow",
    "classify_motion",
    "dense_flow",
    "good_features_to_track",
    "lucas_kanade",
]

#: most Lucas-Kanade iterations per point and level (OpenCV's default: 30)
MAX_ITERATIONS = 1000


class FlowStatus(enum.IntEnum):
    """Codes of :attr:`SparseFlow.reason` (integers: ``reason == FlowStatus.TRACKED``
    compares an int8 array with them, and the compiled tracker writes them)."""

    TRACKED = 0
    APERTURE = 1  # smallest eigenvalue of the structure tensor below the threshold
    LEFT_IMAGE = 2  # the window left the image
    NOT_CONVERGED = 3  # no update below eps within the iterations at the finest level
    HIGH_RESIDUAL = 4  # the window at the end does not look like the one at the start


@dataclass(frozen=True)
class SparseFlow:
    """Tracked points of :func:`lucas_kanade`.

    It unpacks as the tuple of ``p1, st, err = cv2.calcOpticalFlowPyrLK(prev, next, p0,
    None)``: ``p1, st, err = lucas_kanade(prev, next, p0)`` gives ``p1`` float32 in the
    layout ``p0`` came in (``(N, 1, 2)`` for OpenCV's point vectors, as
    ``cv2.goodFeaturesToTrack`` returns them, else ``(N, 2)``), ``st`` ``(N, 1)`` uint8 (1
    where tracked) and ``err`` ``(N, 1)`` float32, OpenCV's shapes and dtypes, so that
    ``p1[st == 1]`` picks the tracked end points as in OpenCV's tutorial. ``st`` is 0 also
    for the failures OpenCV does not flag (:attr:`FlowStatus.NOT_CONVERGED`,
    :attr:`FlowStatus.HIGH_RESIDUAL`). The attributes below stay the primary interface
    ((N, 2) float64 positions, an (N,) bool status).

    Attributes
    ----------
    start, end : (N, 2) ndarray
        Positions ``(x, y)`` in the first and second image.
    status : (N,) bool ndarray
        True where the point was tracked.
    reason : (N,) int8 ndarray
        :class:`FlowStatus` code.
    error : (N,) ndarray
        Mean absolute intensity difference over the window (0-255 scale), as OpenCV.
    min_eigenvalue : (N,) ndarray
        Normalized smallest eigenvalue of :math:`S^T S` at the finest level.
    residual : (N,) ndarray
        ``error`` relative to the window's own contrast (its mean absolute deviation).
    opencv_layout : bool
        True when the points came as OpenCV's ``(N, 1, 2)`` array: the unpacked ``p1``
        keeps that shape.

    Examples
    --------
    >>> y, x = np.mgrid[0:64, 0:64]
    >>> a = np.sin(x / 3.0) * np.cos(y / 4.0) * 0.4 + 0.5
    >>> b = np.sin((x - 1) / 3.0) * np.cos(y / 4.0) * 0.4 + 0.5  # moved 1 px right
    >>> p0 = np.array([[[30.0, 30.0]], [[20.0, 34.0]]], np.float32)  # (N, 1, 2)
    >>> p1, st, err = lucas_kanade(a, b, p0)
    >>> p1.shape, p1.dtype, st.ravel().tolist(), err.shape
    ((2, 1, 2), dtype('float32'), [1, 1], (2, 1))
    >>> (np.round(p1[st == 1] - p0[st == 1], 2) + 0.0).tolist()
    [[1.0, 0.0], [1.0, 0.0]]
    """

    start: np.ndarray
    end: np.ndarray
    status: np.ndarray
    reason: np.ndarray
    error: np.ndarray
    min_eigenvalue: np.ndarray
    residual: np.ndarray
    opencv_layout: bool = False

    @property
    def flow(self) -> np.ndarray:
        """Displacements ``end - start``, ``(N, 2)``."""
        return self.end - self.start

    def __len__(self) -> int:
        return int(self.status.size)

    def __iter__(self) -> Iterator[np.ndarray]:
        """``p1, st, err`` with the shapes and dtypes of ``cv2.calcOpticalFlowPyrLK``."""
        n = len(self)
        p1 = self.end.astype(np.float32).reshape((n, 1, 2) if self.opencv_layout else (n, 2))
        st = self.status.astype(np.uint8).reshape(n, 1)
        err = self.error.astype(np.float32).reshape(n, 1)
        return iter((p1, st, err))


_WORK = threading.local()


def _buffers(shape: tuple[int, int]) -> list[np.ndarray]:
    """Four float32 work images of ``shape``, kept per thread between calls: writing
    fresh memory (page faults) cost more than the filtering itself."""
    cached = getattr(_WORK, "buffers", None)
    if cached is None or cached[0].shape != shape:
        cached = [np.empty(shape, dtype=np.float32) for _ in range(4)]
        _WORK.buffers = cached
    return cached


def _padded(img: np.ndarray, pad: int, out: np.ndarray) -> np.ndarray:
    """``img`` with a border of ``pad`` pixels, reflect101 (OpenCV's default), in ``out``."""
    h, w = img.shape
    rows = _reflect101(np.arange(-pad, h + pad), h)
    cols = _reflect101(np.arange(-pad, w + pad), w)
    _gather(img, rows, cols, out)
    return out


def _reflect101(i: np.ndarray, n: int) -> np.ndarray:
    period = max(2 * n - 2, 1)
    i = np.mod(i, period)
    return np.where(i < n, i, period - i)


@njit(cache=True, nogil=True)
def _gather(img, rows, cols, out):  # pragma: no cover - compiled
    w = img.shape[1]
    pad = (cols.size - w) // 2
    for y in range(rows.size):
        src = img[rows[y]]
        dst = out[y]
        for x in range(pad):
            dst[x] = src[cols[x]]
            dst[pad + w + x] = src[cols[pad + w + x]]
        dst[pad : pad + w] = src


@njit(cache=True, nogil=True, fastmath=True)
def _scharr_padded(src, pad, ix, iy):  # pragma: no cover - compiled
    # Scharr derivatives / 32 of the image inside src's border (whose reflect101
    # pixels give OpenCV's border), zero outside it, as OpenCV pads the derivatives
    hp, wp = src.shape
    ix[:] = 0.0
    iy[:] = 0.0
    for r in range(pad, hp - pad):
        up = src[r - 1]
        mid = src[r]
        down = src[r + 1]
        ox = ix[r]
        oy = iy[r]
        three, ten, scale = np.float32(3.0), np.float32(10.0), np.float32(1.0 / 32.0)
        for c in range(pad, wp - pad):
            dx = three * (up[c + 1] - up[c - 1] + down[c + 1] - down[c - 1])
            ox[c] = (dx + ten * (mid[c + 1] - mid[c - 1])) * scale
            dy = three * (down[c - 1] - up[c - 1] + down[c + 1] - up[c + 1])
            oy[c] = (dy + ten * (down[c] - up[c])) * scale


def _pyramid(img: np.ndarray, levels: int, window: int) -> list[np.ndarray]:
    # as OpenCV's buildOpticalFlowPyramid: stop before a level smaller than the window
    pyr = [img]
    for _ in range(levels):
        nxt = pyr_down_unchecked(pyr[-1])
        if nxt.shape[0] <= window or nxt.shape[1] <= window:
            break
        pyr.append(nxt)
    return pyr


@njit(cache=True, nogil=True, fastmath=True)
def _interp_row(src, r, c0, n, w00, w01, w10, w11, out):  # pragma: no cover - compiled
    # bilinear samples src(r + b, c0 + x + a), x = 0..n-1, with the four weights
    top = src[r]
    bottom = src[r + 1]
    for x in range(n):
        c = c0 + x
        out[x] = w00 * top[c] + w01 * top[c + 1] + w10 * bottom[c] + w11 * bottom[c + 1]


@njit(cache=True, nogil=True, fastmath=True)
def _weights(fx, fy):  # pragma: no cover - compiled
    a = np.float32(fx)
    b = np.float32(fy)
    one = np.float32(1.0)
    return (one - a) * (one - b), a * (one - b), (one - a) * b, a * b


@njit(cache=True, nogil=True, fastmath=True)
def _window_at(x, y, win, w, h, pad):  # pragma: no cover - compiled
    # the window whose top-left corner is (x, y): whether it is still on the (padded)
    # level, as OpenCV's bounds, its integer corner in the padded arrays and the
    # bilinear weights of the fractional part
    ix = np.floor(x)
    iy = np.floor(y)
    inside = not (ix < -win or ix >= w or iy < -win or iy >= h)
    w00, w01, w10, w11 = _weights(x - ix, y - iy)
    return inside, int(iy) + pad, int(ix) + pad, w00, w01, w10, w11


@njit(cache=True, nogil=True, fastmath=True)
def _track(p, ii, gxi, gyi, jj, pad, h, w, prev, nxt, scale, win, iters, eps2, min_eig,
           finest, reason, err, eig, rel, iwin, gx, gy, row):  # fmt: skip  # pragma: no cover
    # one point at one level (Bouguet's algorithm, the comments of lucas_kanade)
    half = (win - 1) * 0.5
    area = win * win
    inside, r0, c0, w00, w01, w10, w11 = _window_at(
        prev[p, 0] * scale - half, prev[p, 1] * scale - half, win, w, h, pad
    )
    if not inside:
        if finest:
            reason[p] = FlowStatus.LEFT_IMAGE
        return
    a11 = 0.0
    a12 = 0.0
    a22 = 0.0
    for y in range(win):
        _interp_row(ii, r0 + y, c0, win, w00, w01, w10, w11, iwin[y])
        _interp_row(gxi, r0 + y, c0, win, w00, w01, w10, w11, gx[y])
        _interp_row(gyi, r0 + y, c0, win, w00, w01, w10, w11, gy[y])
        s11 = np.float32(0.0)
        s12 = np.float32(0.0)
        s22 = np.float32(0.0)
        gxy = gx[y]
        gyy = gy[y]
        for x in range(win):
            s11 += gxy[x] * gxy[x]
            s12 += gxy[x] * gyy[x]
            s22 += gyy[x] * gyy[x]
        a11 += s11
        a12 += s12
        a22 += s22
    # OpenCV's scale: derivatives x32 squared, / 2^20; the eigenvalue also / area
    a11 /= 1024.0
    a12 /= 1024.0
    a22 /= 1024.0
    det = a11 * a22 - a12 * a12
    me = (a22 + a11 - np.sqrt((a11 - a22) ** 2 + 4.0 * a12 * a12)) / (2.0 * area)
    if finest:
        eig[p] = me
    if me < min_eig or det < 1.1920929e-07:
        if finest:
            reason[p] = FlowStatus.APERTURE
        return
    nx = nxt[p, 0] - half
    ny = nxt[p, 1] - half
    pdx = 0.0
    pdy = 0.0
    converged = False
    for j in range(iters):
        inside, r0, c0, v00, v01, v10, v11 = _window_at(nx, ny, win, w, h, pad)
        if not inside:
            if finest:
                reason[p] = FlowStatus.LEFT_IMAGE
            break
        b1 = 0.0
        b2 = 0.0
        for y in range(win):
            _interp_row(jj, r0 + y, c0, win, v00, v01, v10, v11, row)
            irow = iwin[y]
            gxy = gx[y]
            gyy = gy[y]
            t1 = np.float32(0.0)
            t2 = np.float32(0.0)
            for x in range(win):
                diff = row[x] - irow[x]
                t1 += diff * gxy[x]
                t2 += diff * gyy[x]
            b1 += t1
            b2 += t2
        b1 /= 1024.0
        b2 /= 1024.0
        dx = (a12 * b2 - a22 * b1) / det
        dy = (a12 * b1 - a11 * b2) / det
        nx += dx
        ny += dy
        if dx * dx + dy * dy <= eps2:
            converged = True
            break
        if j > 0 and abs(dx + pdx) < 0.01 and abs(dy + pdy) < 0.01:
            nx -= dx * 0.5  # oscillating between two positions: take the middle
            ny -= dy * 0.5
            converged = True
            break
        pdx = dx
        pdy = dy
    nxt[p, 0] = nx + half
    nxt[p, 1] = ny + half
    if not finest or reason[p] != FlowStatus.TRACKED:
        return
    if not converged:
        reason[p] = FlowStatus.NOT_CONVERGED
    inside, r0, c0, v00, v01, v10, v11 = _window_at(nx, ny, win, w, h, pad)
    if not inside:
        reason[p] = FlowStatus.LEFT_IMAGE
        return
    # the error (mean |J - I|, as OpenCV) and the residual relative to the contrast
    mean = 0.0
    for y in range(win):
        for x in range(win):
            mean += iwin[y, x]
    mean /= area
    e = 0.0
    spread = 0.0
    for y in range(win):
        _interp_row(jj, r0 + y, c0, win, v00, v01, v10, v11, row)
        for x in range(win):
            e += abs(row[x] - iwin[y, x])
            spread += abs(iwin[y, x] - mean)
    err[p] = e / area
    rel[p] = e / max(spread, 1e-6)


@njit(cache=True, nogil=True, parallel=True)
def _lk_level(ii, gxi, gyi, jj, pad, h, w, prev, nxt, scale, win, iters, eps2, min_eig, finest,
              reason, err, eig, rel):  # fmt: skip  # pragma: no cover - compiled
    # points in chunks, each with its own window buffers; points are independent, so
    # the result does not depend on the number of threads
    n = prev.shape[0]
    chunks = min(n, 64)
    for k in prange(chunks):
        iwin = np.empty((win, win), dtype=np.float32)
        gx = np.empty((win, win), dtype=np.float32)
        gy = np.empty((win, win), dtype=np.float32)
        row = np.empty(win, dtype=np.float32)
        for p in range(k * n // chunks, (k + 1) * n // chunks):
            if reason[p] == FlowStatus.TRACKED:
                _track(p, ii, gxi, gyi, jj, pad, h, w, prev, nxt, scale, win, iters, eps2,
                       min_eig, finest, reason, err, eig, rel, iwin, gx, gy, row)  # fmt: skip


def lucas_kanade(
    prev: np.ndarray,
    next: np.ndarray,
    points: npt.ArrayLike,
    *,
    window: int = 21,
    levels: int = 3,
    iterations: int = 30,
    eps: float = 0.01,
    min_eigenvalue: float = 1e-4,
    max_residual: float | None = 0.75,
    initial: npt.ArrayLike | None = None,
) -> SparseFlow:
    r"""Track ``points`` from ``prev`` to ``next`` by pyramidal Lucas-Kanade.

    Parameters
    ----------
    prev, next : (H, W) or (H, W, 3) ndarray
        The two frames (uint8, or float in [0, 1]); colour is converted to gray.
    points : (N, 2) or (N, 1, 2) array_like
        Positions ``(x, y)`` in ``prev``; OpenCV's ``(N, 1, 2)`` point vectors
        (``cv2.goodFeaturesToTrack``'s output) too.
    window : int
        Odd window side in pixels (OpenCV's ``winSize``).
    levels : int
        Pyramid levels above the image (OpenCV's ``maxLevel``; 0: single level).
    iterations, eps : int, float
        Stop after ``iterations`` updates or when an update is at most ``eps`` pixels.
    min_eigenvalue : float
        Aperture threshold on the normalized smallest eigenvalue of :math:`S^T S`.
    max_residual : float or None
        Flag a track whose final mean absolute difference exceeds this fraction of the
        window's contrast (mean absolute deviation from its mean). Two unrelated
        patches give about :math:`\sqrt 2`; a matched one, well under 1 (RubberWhale:
        median 0.11, largest 0.72). None keeps every converged track, as OpenCV.
    initial : (N, 2) or (N, 1, 2) array_like, optional
        Starting guesses in ``next`` (default: the points themselves).

    Returns
    -------
    SparseFlow
        End positions, status, the reason of every failure, error and eigenvalue.
        Unpacks as ``p1, st, err``, the result of ``cv2.calcOpticalFlowPyrLK(prev, next,
        points, None, winSize=(window, window), maxLevel=levels)``, in OpenCV's shapes.

    Raises
    ------
    InputError
        Frames of different sizes, a bad window, or points not ``(N, 2)`` finite.
    """
    I0 = gray_255(prev, "prev")
    J0 = gray_255(next, "next")
    if I0.shape != J0.shape:
        raise InputError(f"prev and next must have the same size; got {I0.shape} and {J0.shape}")
    window = check_odd_size(window, "window", 3)
    largest = max(I0.shape)
    if window > largest:
        raise InputError(
            f"window must be an odd integer in 3..{largest} (the image's larger side); got {window}"
        )
    levels = check_int(levels, "levels", 0)
    iterations = check_int(iterations, "iterations", 1)
    if iterations > MAX_ITERATIONS:
        raise InputError(f"iterations must be in 1..{MAX_ITERATIONS}; got {iterations}")
    eps = check_real(eps, "eps", 0.0)
    min_eigenvalue = check_real(min_eigenvalue, "min_eigenvalue", 0.0)
    if max_residual is not None:
        max_residual = check_real(max_residual, "max_residual (or None)", 0.0, low_inclusive=False)
    pts = check_numeric(points, "points")
    opencv_layout = pts.ndim == 3 and pts.shape[1:] == (1, 2)
    if pts.size == 0:
        pts = pts.reshape(0, 2)
    pts = squeeze_point_axis(pts, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(
            f"points must be (N, 2) (x, y) or OpenCV's (N, 1, 2); got shape {pts.shape}"
        )
    if not np.isfinite(pts).all():
        raise InputError("points contain NaN or inf; drop them before tracking")
    n = pts.shape[0]
    guess = (
        pts.copy()
        if initial is None
        else squeeze_point_axis(check_numeric(initial, "initial"), 2).copy()
    )
    if guess.shape != pts.shape:
        raise InputError(f"initial must have the shape of points {pts.shape}; got {guess.shape}")
    if not np.isfinite(guess).all():
        raise InputError("initial contains NaN or inf: give finite guesses (or initial=None)")
    # far outside the image a point just leaves it; clipping keeps the compiled
    # tracker's integer window corners in range
    big = 4.0 * largest + 4.0 * window
    start = np.clip(pts, -big, big)
    guess = np.clip(guess, -big, big)
    pyr_i = _pyramid(I0, levels, window)
    pyr_j = _pyramid(J0, len(pyr_i) - 1, window)
    top = len(pyr_i) - 1
    nxt = guess / 2.0**top
    reason = np.full(n, FlowStatus.TRACKED, dtype=np.int8)
    err = np.zeros(n)
    eig = np.zeros(n)
    rel = np.zeros(n)
    pad = window + 2
    for level in range(top, -1, -1):
        img_i, img_j = pyr_i[level], pyr_j[level]
        shape = (img_i.shape[0] + 2 * pad, img_i.shape[1] + 2 * pad)
        if level == 0:  # the large level reuses this thread's buffers
            Ip, Jp, ixp, iyp = _buffers(shape)
        else:
            Ip, Jp, ixp, iyp = (np.empty(shape, dtype=np.float32) for _ in range(4))
        _padded(img_i, pad, Ip)
        _padded(img_j, pad, Jp)
        _scharr_padded(Ip, pad, ixp, iyp)
        _lk_level(Ip, ixp, iyp, Jp, pad, img_i.shape[0], img_i.shape[1], start, nxt,
                  1.0 / 2.0**level, window, iterations, eps**2, min_eigenvalue, level == 0,
                  reason, err, eig, rel)  # fmt: skip
        if level > 0:
            nxt = nxt * 2.0
    if max_residual is not None:
        reason[(reason == FlowStatus.TRACKED) & (rel > max_residual)] = FlowStatus.HIGH_RESIDUAL
    return SparseFlow(pts, nxt, reason == FlowStatus.TRACKED, reason, err, eig, rel, opencv_layout)


def dense_flow(
    prev: np.ndarray,
    next: np.ndarray,
    *,
    step: int = 8,
    **kwargs: Any,
) -> tuple[np.ndarray, np.ndarray, SparseFlow]:
    """Lucas-Kanade on a regular grid every ``step`` pixels.

    Returns
    -------
    grid : (GH, GW, 2) ndarray
        The grid positions ``(x, y)``.
    flow : (GH, GW, 2) ndarray
        Their displacements, NaN where not tracked.
    result : SparseFlow
        The raw per-point result.
    """
    step = check_int(step, "step", 1)
    img = check_image(prev, "prev")
    h, w = img.shape[:2]
    if step > max(h, w):
        raise InputError(
            f"step must be in 1..{max(h, w)} (the image's larger side) pixels; got {step}"
        )
    ys, xs = np.mgrid[step // 2 : h : step, step // 2 : w : step]
    grid = np.stack([xs, ys], axis=-1).astype(np.float64)
    res = lucas_kanade(prev, next, grid.reshape(-1, 2), **kwargs)
    flow = np.where(res.status[:, None], res.flow, np.nan).reshape(grid.shape)
    return grid, flow, res


@dataclass(frozen=True)
class MotionClass:
    """What :func:`classify_motion` found.

    Attributes
    ----------
    kind : str
        ``"translation"``, ``"rotation"`` or ``"zoom"``: the component that moves the
        points most; ``"static"`` when nothing moves ``min_motion`` pixels;
        ``"complex"`` when the vectors are no similarity transform (the residual is
        as large as the largest component: independent motions, a non-rigid scene).
    translation : (2,) ndarray
        Motion of the points' centroid ``(dx, dy)`` in pixels.
    rotation : float
        Angle in radians, positive from +x toward +y (clockwise on screen, y down).
    scale : float
        Zoom factor (> 1: zoom in, objects grow).
    displacement : dict
        Pixels each component moves a point at the RMS radius of the points:
        ``|t|``, :math:`2 r \\sin(|\\theta|/2)` and :math:`|s - 1| r`.
    residual : float
        RMS distance of the flow end points from the fitted similarity (inliers).
    inliers : (N,) bool ndarray
        Vectors kept by the fit (finite ones, after trimming outliers).
    """

    kind: str
    translation: np.ndarray
    rotation: float
    scale: float
    displacement: dict[str, float]
    residual: float
    inliers: np.ndarray = field(repr=False)


def _similarity(p: np.ndarray, q: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray]:
    pm, qm = p.mean(axis=0), q.mean(axis=0)
    pc, qc = p - pm, q - qm
    norm = float((pc**2).sum())
    if norm <= 1e-12:
        raise DegenerateError(
            "classify_motion needs points at different positions; all of them coincide"
        )
    a = float((pc * qc).sum()) / norm
    b = float((pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0]).sum()) / norm
    pred = qm + pc @ np.array([[a, b], [-b, a]])
    return a, b, qm - pm, np.hypot(*(q - pred).T)


def classify_motion(
    points: npt.ArrayLike, flow: npt.ArrayLike, *, min_motion: float = 0.5, trim: float = 3.0
) -> MotionClass:
    r"""Tell translation, rotation and zoom apart by fitting a similarity transform.

    The end points :math:`q_i = p_i + f_i` are fitted, in the least-squares sense, by
    :math:`q = s R(\theta) (p - \bar p) + \bar p + t`. With centred coordinates
    :math:`p'_i, q'_i` the solution is closed form:

    .. math::

        a = s\cos\theta = \frac{\sum p'_i \cdot q'_i}{\sum |p'_i|^2},\quad
        b = s\sin\theta = \frac{\sum p'_i \times q'_i}{\sum |p'_i|^2},\quad
        t = \bar q - \bar p.

    Each component is then measured in pixels at the RMS radius :math:`r` of the
    points about their centroid (translation :math:`|t|`, rotation
    :math:`2 r \sin(|\theta|/2)`, zoom :math:`|s - 1| r`), and the largest names the
    motion; below ``min_motion`` pixels it is ``"static"``, and when the RMS residual
    of the fit is at least as large (and at least ``min_motion``) it is ``"complex"``:
    no single camera-like motion explains the vectors. The fit is repeated without the
    vectors whose residual exceeds ``trim`` times the median residual (and 1 px) until
    no more are dropped (at most 10 rounds), so a few independently moving objects do
    not decide the answer.

    Parameters
    ----------
    points : (N, 2) array_like
        Positions ``(x, y)``.
    flow : (N, 2) array_like
        Their displacements; rows with NaN (failed tracks) are ignored.
    min_motion : float
        Pixels below which nothing is said to move.
    trim : float
        Outlier cut, in median residuals.

    Returns
    -------
    MotionClass

    Raises
    ------
    DegenerateError
        Fewer than two usable vectors, or all at one position.
    """
    p = check_numeric(points, "points")
    f = check_numeric(flow, "flow")
    if p.ndim != 2 or p.shape[1] != 2 or f.shape != p.shape:
        raise InputError(f"points and flow must both be (N, 2); got shapes {p.shape} and {f.shape}")
    # squared below: beyond 1e150 the sums overflow
    check_magnitude(p, "points", 1e150)
    check_magnitude(f, "flow", 1e150)
    min_motion = check_real(min_motion, "min_motion", 0.0)
    trim = check_real(trim, "trim", 0.0, low_inclusive=False)
    usable = np.isfinite(p).all(axis=1) & np.isfinite(f).all(axis=1)
    if usable.sum() < 2:
        raise DegenerateError(
            f"classify_motion needs at least 2 finite flow vectors; got {int(usable.sum())}"
        )
    q = p + f
    idx = np.flatnonzero(usable)
    a, b, t, res = _similarity(p[idx], q[idx])
    for _ in range(10):  # refit without the outliers until the kept set is stable
        keep = res <= max(float(trim) * float(np.median(res)), 1.0)
        if keep.all() or keep.sum() < 2:
            break
        idx = idx[keep]
        a, b, t, res = _similarity(p[idx], q[idx])
    inliers = np.zeros(len(p), dtype=bool)
    inliers[idx] = True
    pc = p[idx] - p[idx].mean(axis=0)
    r = float(np.sqrt((pc**2).sum(axis=1).mean()))
    s, theta = float(np.hypot(a, b)), float(np.arctan2(b, a))
    disp = {
        "translation": float(np.hypot(*t)),
        "rotation": 2.0 * r * abs(float(np.sin(theta / 2.0))),
        "zoom": abs(s - 1.0) * r,
    }
    rms = float(np.sqrt(np.mean(res**2)))
    kind = max(disp, key=disp.__getitem__)
    if rms >= max(disp[kind], min_motion):
        kind = "complex"
    elif disp[kind] < min_motion:
        kind = "static"
    return MotionClass(kind, t, theta, s, disp, rms, inliers)
