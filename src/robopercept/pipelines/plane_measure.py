r"""Plane measurement: one RGB-D frame to the plane of a coloured board and its covariance.

Per frame (:meth:`PlaneMeasurer.measure`):

1. **Coloured points.** Depth to points, each point's colour through the colour camera
   (with the z-buffer occlusion test, its tolerance growing as :math:`z^2` like the
   depth noise: ``occlusion_grows``) and the HSV box:
   :class:`~robopercept.depth.ColorRangeSelector`, the library path
   ``depth_to_points`` -> ``texture_coordinates`` -> ``sample_colors`` ->
   ``rgb_to_hsv`` -> ``hsv_range_mask`` fused into three compiled passes.
2. **RANSAC** on the coloured points (:func:`~robopercept.estimation.ransac` with
   :class:`~robopercept.estimation.PlaneModel`: 3 points, normal by cross product).
   Hypotheses are scored by MSAC, :math:`\sum_i \min(r_i^2, \tau^2)`, so that among
   planes with as many inliers the one nearer them wins (plain counting lets a plane
   tilt toward the background points that the colour image's parallax paints green at
   the board's edges). A predicted plane (from the tracker) is scored first, and the
   search stops early once a hypothesis has as large a share of inliers as the previous
   frame had. The inlier threshold grows with the squared distance like stereo depth
   noise, :math:`\tau(z) = \max(\tau_{min}, \tau_1 z^2)` at the points' median depth.
   Optionally (``hue_tolerance``) hue is an extra feature: a point is an inlier only if
   its hue is also near the hypothesis' sample hue (:class:`PlaneHueModel`). The
   hypotheses are scored on at most ``ransac_points`` (32768) of the points, every
   :math:`k`-th in pixel order: a board near the camera has :math:`10^5` of them, and
   scoring every one took most of a frame's time for no better choice among the
   hypotheses; the inliers of the plane chosen are then taken among every point.
3. **Refit in inverse depth.** The plane is refitted to its inliers by least squares in
   inverse depth (:func:`~robopercept.estimation.fit_plane_inverse_depth`): stereo
   depth noise is additive in disparity and lies along the viewing rays, so
   :math:`1/z = c^\top (x/z, y/z, 1)` with :math:`c = n / d` is the exact
   maximum-likelihood model, where total least squares tilts an oblique board by a
   fraction of a degree at 2 m. The inliers are re-selected against the refitted plane
   and the fit repeated (``refit_iterations`` times, or until the inliers no longer
   change: then the fit cannot either). Each selection and the sums of the next fit
   are one pass over the points
   (:func:`~robopercept.estimation.least_squares.fit_plane_inverse_depth_slab`),
   after a pass of the test alone
   (:func:`~robopercept.estimation.least_squares.slab_inliers`) has found that the
   inliers change.
4. **One plane, not a board and a neighbour** (with ``blob_residual_ratio`` set; off
   by default). Near the camera the inlier slab is thin, but at 2 m it is
   :math:`\pm 4` cm thick, and a green thing elsewhere in the image (a box top, a
   patch on a wall) that crosses the board's slab joins the inliers: a few hundred
   such points far from the board tilt the least-squares plane by degrees (2 deg and
   42 mm on a sweep sequence, with 4 % of the inliers). The inliers are grouped into
   blobs in the depth image (8-connected, on a grid of ``blob_cell`` pixels), the
   plane is fitted to the largest, and another blob of at least ``min_points / 4``
   points is dropped when its mean inverse-depth residual to that plane,
   :math:`|d - n^\top x| / (d z)` (uniform noise for stereo depth), is over
   ``blob_residual_ratio`` times the largest blob's, or when its own plane differs
   from the largest blob's (:func:`off_plane_blobs`), unless such blobs hold over a
   quarter of the inliers. The pieces of a board cut by an occluder lie on its plane
   and stay; a neighbour that touches the board in the image is one blob with it and
   is not separated. The refit and the inlier selection are then repeated without
   the dropped blobs.
5. **A board, not specks.** The inliers must form a board-like blob in the depth image:
   their solidity (inlier pixels over the pixels of their convex hull, scikit-image's
   ``regionprops(...).solidity``) must reach ``min_solidity``. Green specks scattered
   over a carpet, foliage or a poster lie on some plane too, but fill 0.7-3.7 % of
   their outline in the real RGB-D frames of the tests (TUM, NYU, PCL), where the
   synthetic board fills 35-99 % (the lower values with the occluder across it): such
   a frame has no plane ("no board found").
6. **Covariance with a floor.** The fit's covariance of the closest point
   :math:`\pi = d\, n` treats the :math:`N` inliers as independent; errors that are
   shared by neighbouring pixels (depth quantization, calibration, flying pixels along
   edges, colour parallax) do not average out that way. The reported covariance is the
   fit's scaled as if at most :math:`N_{eff}` points were independent,
   :math:`R = \Sigma_\pi \max(1, N / N_{eff})` (``effective_points``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit, prange
from scipy import ndimage

from robopercept._checks import check_int, check_numeric, check_real
from robopercept.depth import ColorRangeSelector
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import Plane, PlaneModel, fit_plane_inverse_depth, ransac
from robopercept.estimation.least_squares import fit_plane_inverse_depth_slab, slab_inliers
from robopercept.estimation.models import Model
from robopercept.sources.frames import RGBDFrame

__all__ = [
    "PlaneHueModel",
    "PlaneMeasurement",
    "PlaneMeasurer",
    "PlaneMeasurerConfig",
    "off_plane_blobs",
]

#: the default ``min_solidity``: real green specks reach 0.04, the board 0.35 and more
MIN_SOLIDITY = 0.15
#: squared Mahalanobis distance between two blobs' planes over which they are two
#: planes (:func:`off_plane_blobs`; chi-square with 3 dof passes 30 once in 10^6)
BLOB_MAHALANOBIS2 = 100.0
#: off-plane blobs holding more of the inliers than this are not dropped
#: (:func:`off_plane_blobs`)
MAX_OFF_PLANE_SHARE = 0.25


@dataclass(frozen=True)
class PlaneMeasurerConfig:
    """Settings of :class:`PlaneMeasurer` (defaults suit a D435 and a green board).

    Attributes
    ----------
    hsv_low, hsv_high : (3,) tuple
        HSV box on the OpenCV scale (H 0..180, S and V 0..255), bounds inclusive; the hue
        range wraps around when ``hsv_low[0] > hsv_high[0]``.
    occlusion_tolerance : float or None
        Z-buffer tolerance of the colour lookup, metres (None: no occlusion test); with
        ``occlusion_grows`` its value at 1 m, growing as :math:`z^2` beyond.
    occlusion_grows : bool
        Let the tolerance grow like stereo depth noise (see
        :class:`~robopercept.depth.ColorRangeSelector`): a fixed 2 cm hides the points
        whose noise puts them behind their neighbours, which tilted a board 2.4 m away
        by 0.6 deg.
    threshold_1m : float
        RANSAC inlier threshold at 1 m, metres; it grows with :math:`z^2`.
    threshold_min : float
        Lower bound of the threshold, metres.
    min_points : int
        Fewer coloured points (or inliers) than this: no plane.
    min_solidity : float
        Least solidity of the inliers in the depth image (their pixels over those of
        their convex hull, as scikit-image's ``regionprops(...).solidity``); below it
        they are scattered specks, not a board: no plane. 0 accepts any inliers.
    max_iterations : int
        RANSAC bound on hypotheses per frame.
    ransac_points : int or None
        RANSAC scores its hypotheses on at most this many of the coloured points, a
        regular subsample in pixel order (every k-th point); its plane's inliers and the
        refits then take every point. None: score on every point. A board near the
        camera has up to 2 x 10^5 coloured points, and scoring them all took 6-12 ms a
        frame; on every 10th frame of the default sequences at 640 x 480 and 848 x 480
        the plane measured with 32768 is within 0.008 deg and 0.07 mm of the one
        measured with every point, and never further from the truth (16384 moved
        three frames of a board half out of view by 0.2-0.3 deg).
    probability : float
        RANSAC confidence for the adaptive number of iterations.
    hue_tolerance : float or None
        Use hue as an extra RANSAC feature (OpenCV hue units); None: geometry only.
    refit_iterations : int
        Inverse-depth refits, each on the inliers of the previous plane.
    effective_points : int
        :math:`N_{eff}`: the covariance is never smaller than that of this many
        independent points.
    blob_cell : int
        Grid cell, in depth pixels, on which the inliers are grouped into blobs (two
        blobs are apart when at least one empty cell lies between them).
    blob_residual_ratio : float or None
        A blob whose mean inverse-depth residual to the largest blob's plane is over
        this many times the largest blob's own, or whose own plane differs from it, is
        not on the board's plane and is dropped (see the module docstring); None (the
        default) keeps every blob. 2.0 makes the raw fit better (p95 angle 0.64 ->
        0.19 deg on the jerky default sequence, seed 1); it is off until the track is
        tuned to the better fit, which it filters with a p95 offset 2 % above the fit's
        on hand-held tremor (seed 1).
    rng : int
        Seed of RANSAC's sampling (frame ``i`` uses ``(rng, i)``).
    """

    hsv_low: tuple[float, float, float] = (45.0, 35.0, 35.0)
    hsv_high: tuple[float, float, float] = (65.0, 255.0, 255.0)
    occlusion_tolerance: float | None = 0.02
    occlusion_grows: bool = True
    threshold_1m: float = 0.01
    threshold_min: float = 0.004
    min_points: int = 200
    min_solidity: float = MIN_SOLIDITY
    max_iterations: int = 200
    ransac_points: int | None = 32768
    probability: float = 0.999
    hue_tolerance: float | None = None
    refit_iterations: int = 3
    effective_points: int = 20000
    blob_cell: int = 4
    blob_residual_ratio: float | None = None
    rng: int = 0

    def __post_init__(self) -> None:
        # the HSV box is checked (and normalized to floats) by the selector's rules
        sel = ColorRangeSelector(
            self.hsv_low, self.hsv_high, self.occlusion_tolerance, self.occlusion_grows
        )
        object.__setattr__(self, "hsv_low", tuple(float(v) for v in sel.hsv_low))
        object.__setattr__(self, "hsv_high", tuple(float(v) for v in sel.hsv_high))
        object.__setattr__(self, "occlusion_tolerance", sel.occlusion_tolerance)
        for name in ("threshold_1m", "threshold_min"):
            v = check_real(getattr(self, name), f"{name} (metres)", 0.0, low_inclusive=False)
            object.__setattr__(self, name, v)
        if self.blob_residual_ratio is not None:
            v = check_real(
                self.blob_residual_ratio, "blob_residual_ratio (or None: keep every blob)", 1.0
            )
            object.__setattr__(self, "blob_residual_ratio", v)
        sol = check_real(self.min_solidity, "min_solidity", 0.0, 1.0)
        object.__setattr__(self, "min_solidity", sol)
        p = check_real(self.probability, "probability", 0.0, 1.0, low_inclusive=False,
                       high_inclusive=False)  # fmt: skip
        object.__setattr__(self, "probability", p)
        if self.hue_tolerance is not None:
            tol = check_real(self.hue_tolerance, "hue_tolerance (OpenCV hue units)", 0.0)
            object.__setattr__(self, "hue_tolerance", tol)
        if self.ransac_points is not None:
            v = check_int(self.ransac_points, "ransac_points (or None: every point)", 3)
            object.__setattr__(self, "ransac_points", v)
        for name, low in (
            ("min_points", 3),
            ("max_iterations", 1),
            ("refit_iterations", 0),
            ("effective_points", 1),
            ("blob_cell", 1),
            ("rng", 0),
        ):
            object.__setattr__(self, name, check_int(getattr(self, name), name, low))


@dataclass(frozen=True)
class PlaneMeasurement:
    """One frame's plane (see the module docstring).

    Attributes
    ----------
    found : bool
        A plane was fitted on at least ``min_points`` inliers forming a board-like blob
        (solidity at least ``min_solidity``).
    normal : (3,) ndarray
        Unit normal with ``normal @ x = d`` and ``d >= 0`` (NaN when not found).
    d : float
        Distance from the depth camera, metres (NaN when not found).
    covariance : (3, 3) ndarray
        Covariance of the closest point ``d * normal``, with the floor (NaN when not
        found).
    inliers : int
        Inliers of the plane (0 when not found).
    n_points, n_colored : int
        Depth pixels with a depth, and those with the board's colour.
    inlier_points : (K, 3) ndarray
        The inliers (depth frame), for drawing.
    ms : dict
        Milliseconds per stage: ``points``, ``color``, ``ransac`` (with the refit and
        the solidity test).
    solidity : float
        Solidity of the fitted plane's inliers in the depth image (NaN when no plane
        had enough inliers); below ``min_solidity`` the plane is not ``found``.
    """

    found: bool
    normal: np.ndarray
    d: float
    covariance: np.ndarray
    inliers: int
    n_points: int
    n_colored: int
    inlier_points: np.ndarray = field(repr=False)
    ms: dict[str, float] = field(default_factory=dict)
    solidity: float = math.nan

    @property
    def closest_point(self) -> np.ndarray:
        """:math:`\\pi = d\\, n`, the point of the plane nearest the camera."""
        return self.d * self.normal

    @property
    def dominant(self) -> bool:
        """At least half of the coloured points are the plane's inliers."""
        return self.found and self.inliers >= 0.5 * self.n_colored


class PlaneHueModel(Model[Plane]):
    """A plane whose inliers must also match the hypothesis' hue.

    Data rows are ``(x, y, z, h)`` with h the OpenCV hue (0..180). The minimal sample is
    3 points; the hypothesis is the plane through them plus the circular mean hue of the
    sample, :math:`(n, d, \\bar h)`. A row's residual is its distance to the plane when
    its hue is within ``hue_tolerance`` of :math:`\\bar h` (on the 180-periodic circle),
    and infinity otherwise.
    """

    sample_size = 3
    dim = 4
    name = "plane with hue"

    def __init__(self, hue_tolerance: float) -> None:
        self.tol = check_real(hue_tolerance, "hue_tolerance (OpenCV hue units)", 0.0)
        self._plane = PlaneModel()

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        params, valid = self._plane.fit_minimal(np.ascontiguousarray(samples[..., :3]))
        ang = samples[..., 3] * (2 * np.pi / 180.0)
        hue = np.arctan2(np.sin(ang).mean(1), np.cos(ang).mean(1)) * (180.0 / (2 * np.pi))
        return np.column_stack([params, np.mod(hue, 180.0)]), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        p = self._plane.fit(np.ascontiguousarray(data[:, :3]))
        ang = data[:, 3] * (2 * np.pi / 180.0)
        hue = math.atan2(np.sin(ang).mean(), np.cos(ang).mean()) * (180.0 / (2 * np.pi))
        return np.append(p, hue % 180.0)

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        r = self._plane.residuals(params[:, :4], np.ascontiguousarray(data[:, :3]))
        dh = np.abs(data[None, :, 3] - params[:, 4:5]) % 180.0
        dh = np.minimum(dh, 180.0 - dh)
        r[dh > self.tol] = np.inf
        return r

    def check(self, data: np.ndarray) -> None:
        self._plane.check(np.ascontiguousarray(data[:, :3]))

    def result(self, params: np.ndarray) -> Plane:
        return self._plane.result(params[:4])


def _pixel_solidity(pixels: np.ndarray, width: int) -> float:
    """Solidity of a set of pixels: their number over that of the pixels of their
    convex hull.

    The hull is that of the leftmost and rightmost pixel of each row (the same hull as
    of all of them), its pixel count :math:`A + P / 2 + 1` by Pick's theorem from its
    area :math:`A` and perimeter :math:`P` between pixel centres. This equals
    scikit-image's ``regionprops(mask)[0].solidity`` to three decimals (tested); a
    filled convex blob is near 1, scattered pixels near 0.

    Parameters
    ----------
    pixels : (N,) int ndarray
        Flat indices ``row * width + col`` in increasing order, N >= 1.
    width : int
        Image width.

    Returns
    -------
    float
        In (0, 1]; collinear pixels have a hull of zero area and count as a line.

    Examples
    --------
    A filled 10 x 10 square and its corners alone:

    >>> square = np.arange(100).reshape(10, 10).ravel()
    >>> round(_pixel_solidity(square, 10), 2)
    1.0
    >>> round(_pixel_solidity(np.array([0, 9, 90, 99]), 10), 2)
    0.04
    """
    return pixel_solidity_masked(np.asarray(pixels, dtype=np.int64), None, width)


def pixel_solidity_masked(pixels: np.ndarray, mask: np.ndarray | None, width: int) -> float:
    """:func:`_pixel_solidity` of ``pixels[mask]`` (all of them with None), without
    gathering them first."""
    sel = np.zeros(1, dtype=np.bool_) if mask is None else np.asarray(mask, dtype=np.bool_)
    return float(_solidity_kernel(pixels, sel, mask is not None, int(width)))


_ROW_BLOCKS = 64  # blocks of the parallel row gathers


@njit(cache=True, nogil=True, parallel=True)
def _rows_kernel(src, mask, step, out):  # pragma: no cover - compiled
    # out = src[mask] (step == 0) or src[::step] (mask unused),
    # rows in order: each block counts its rows, then copies them from its offset
    # (parallel; np.compress and the strided copy are serial, 0.3-0.5 ms for 10^5
    # rows). Returns m.
    n = src.shape[0]
    counts = np.zeros(_ROW_BLOCKS + 1, dtype=np.int64)
    for b in prange(_ROW_BLOCKS):
        lo, hi = b * n // _ROW_BLOCKS, (b + 1) * n // _ROW_BLOCKS
        if step > 0:
            counts[b + 1] = (hi - 1) // step - (lo - 1) // step if hi > lo else 0
        else:
            c = 0
            for i in range(lo, hi):
                c += np.int64(mask[i])
            counts[b + 1] = c
    for b in range(_ROW_BLOCKS):
        counts[b + 1] += counts[b]
    for b in prange(_ROW_BLOCKS):
        lo, hi = b * n // _ROW_BLOCKS, (b + 1) * n // _ROW_BLOCKS
        g = counts[b]
        if step > 0:
            first = -(-lo // step) * step
            for i in range(first, hi, step):
                for k in range(src.shape[1]):
                    out[g, k] = src[i, k]
                g += 1
        elif counts[b + 1] > g:
            # branch-free: every row is written, the next one over it unless kept, up to
            # the block's last kept row (a row after it would land on the next block's)
            last = hi - 1
            while not mask[last]:
                last -= 1
            d = src.shape[1]
            if d == 3:  # points: the copy unrolled (twice as fast)
                for i in range(lo, last):
                    out[g, 0] = src[i, 0]
                    out[g, 1] = src[i, 1]
                    out[g, 2] = src[i, 2]
                    g += np.int64(mask[i])
            else:
                for i in range(lo, last):
                    for k in range(d):
                        out[g, k] = src[i, k]
                    g += np.int64(mask[i])
            for k in range(d):
                out[g, k] = src[last, k]
    return counts[_ROW_BLOCKS]


def _take_rows(src: np.ndarray, mask: np.ndarray | None = None, step: int = 0) -> np.ndarray:
    """``src[mask]`` or ``src[::step]`` of a C-contiguous (N, D) float64 array, in
    parallel (the same rows, the same order)."""
    n = src.shape[0]
    sel = np.zeros(1, dtype=np.bool_) if mask is None else mask
    size = -(-n // step) if step > 0 else int(np.count_nonzero(sel))
    out = np.empty((size, src.shape[1]))
    got = _rows_kernel(src, sel, step, out)
    assert got == size
    return out


@njit(cache=True, nogil=True)
def _cross(ox, oy, ax, ay, bx, by):  # pragma: no cover - compiled
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@njit(cache=True, nogil=True)
def _solidity_kernel(pixels, mask, use_mask, width):  # pragma: no cover - compiled
    # The row ends in (row, col) order, which is lexicographic: Andrew's monotone chain
    # builds the two halves of their hull in one pass each (O(rows), where scipy's
    # ConvexHull of the same points through qhull cost a millisecond a frame).
    xs = np.empty(2 * pixels.shape[0])
    ys = np.empty(2 * pixels.shape[0])
    n = 0  # pixels counted
    m = 0  # row ends stored
    row = -1
    first = last = 0
    row_start = row_end = 0  # the current row's first pixel index and the next row's
    for i in range(pixels.shape[0]):
        if use_mask and not mask[i]:
            continue
        n += 1
        p = pixels[i]
        if p >= row_end:  # a new row (increasing pixels: one division per row)
            r = p // width
            row_start, row_end = r * width, (r + 1) * width
        else:
            r = row
        col = p - row_start
        if r != row:
            if row >= 0:  # the previous row's ends
                xs[m], ys[m] = first, row
                m += 1
                if last != first:
                    xs[m], ys[m] = last, row
                    m += 1
            row, first = r, col
        last = col
    if row >= 0:
        xs[m], ys[m] = first, row
        m += 1
        if last != first:
            xs[m], ys[m] = last, row
            m += 1
    # lower then upper chain over the points sorted by (y, x)
    hx = np.empty(2 * m + 1)
    hy = np.empty(2 * m + 1)
    k = 0
    for t in range(m):
        while k >= 2 and _cross(hx[k - 2], hy[k - 2], hx[k - 1], hy[k - 1], xs[t], ys[t]) <= 0:
            k -= 1
        hx[k], hy[k] = xs[t], ys[t]
        k += 1
    low = k + 1
    for t in range(m - 2, -1, -1):
        while k >= low and _cross(hx[k - 2], hy[k - 2], hx[k - 1], hy[k - 1], xs[t], ys[t]) <= 0:
            k -= 1
        hx[k], hy[k] = xs[t], ys[t]
        k += 1
    # k - 1 hull vertices (the first repeated at the end); shoelace area, perimeter
    area = 0.0
    perimeter = 0.0
    for t in range(k - 1):
        area += hx[t] * hy[t + 1] - hx[t + 1] * hy[t]
        perimeter += math.hypot(hx[t + 1] - hx[t], hy[t + 1] - hy[t])
    area = abs(area) / 2.0
    if m == 1:
        perimeter = 0.0
    return min(1.0, n / (area + perimeter / 2.0 + 1.0))


def off_plane_blobs(
    points: np.ndarray,
    pixels: np.ndarray,
    shape: tuple[int, ...],
    inliers: np.ndarray,
    cell: int = 4,
    ratio: float = 2.0,
    min_size: int = 50,
    max_mahalanobis2: float = BLOB_MAHALANOBIS2,
) -> np.ndarray | None:
    r"""The inliers that form blobs in the depth image lying off the largest blob's
    plane (see :mod:`.plane_measure`, step 4).

    The inlier pixels are binned into ``cell`` x ``cell`` cells and the occupied cells
    labelled 8-connected (:func:`scipy.ndimage.label`). The plane
    :math:`n^\top x = d` of the largest blob is fitted in inverse depth
    (:func:`~robopercept.estimation.fit_plane_inverse_depth`) and each point's residual
    taken in inverse depth, :math:`e = |d - n^\top x| / (d z)`, where stereo noise is
    uniform. A blob of at least ``min_size`` points is off the plane when its mean
    :math:`e` exceeds ``ratio`` times the largest blob's (a neighbour beside the
    board's plane), or when its own plane's closest point :math:`\pi_b` differs from
    the largest blob's :math:`\pi_0` by a squared Mahalanobis distance
    :math:`(\pi_b - \pi_0)^\top (\Sigma_b + \Sigma_0)^{-1} (\pi_b - \pi_0)` over
    ``max_mahalanobis2`` (a neighbour across it, whose residuals look like the
    board's), unless such blobs hold more
    than :data:`MAX_OFF_PLANE_SHARE` of the inliers: then the largest blob is itself
    a piece of the board joined to a neighbour in the image, and nothing is dropped.

    Parameters
    ----------
    points : (N, 3) ndarray
        Points in the depth camera frame, z > 0.
    pixels : (N,) int ndarray
        Their flat depth-image indices ``row * width + col``.
    shape : tuple
        The depth image's ``(height, width)``.
    inliers : (N,) bool ndarray
        The plane's inliers.
    cell : int
        Grid cell in pixels.
    ratio : float
        Mean-residual ratio over which a blob is off the plane.
    min_size : int
        Smaller blobs are kept whatever their residual.
    max_mahalanobis2 : float
        Squared Mahalanobis distance between a blob's plane and the largest blob's over
        which it is off the plane (the fits' covariances take the points as
        independent, so the default :data:`BLOB_MAHALANOBIS2` is far out in the
        3-dof chi-square tail).

    Returns
    -------
    (N,) bool ndarray or None
        The points of the off-plane blobs; None when there are none (a single blob, or
        every blob on the plane).

    Examples
    --------
    Two patches of the plane z = 2 and one of z = 2.05 further down the image:

    >>> yy, xx = np.mgrid[0:60, 0:40]
    >>> pix = (yy * 40 + xx).ravel()
    >>> z = np.where(yy.ravel() < 40, 2.0, 2.05) + 1e-3 * np.sin(pix)
    >>> pts = np.column_stack([(xx.ravel() - 20) * z / 500, (yy.ravel() - 30) * z / 500, z])
    >>> keep = (yy.ravel() < 15) | ((yy.ravel() > 20) & (yy.ravel() < 40)) | (yy.ravel() > 50)
    >>> off = off_plane_blobs(pts, pix, (60, 40), keep, cell=2, min_size=10)
    >>> int(off.sum()), bool(off[yy.ravel() > 50].all())
    (360, True)
    """
    idx = np.flatnonzero(inliers)
    if idx.size < 2 * min_size:
        return None
    h, w = int(shape[0]), int(shape[1])
    hc, wc = -(-h // cell), -(-w // cell)
    r, col = np.divmod(pixels[idx], w)
    cells = (r // cell) * wc + col // cell
    grid = np.zeros(hc * wc, dtype=bool)
    grid[cells] = True
    labels, k = ndimage.label(grid.reshape(hc, wc), structure=np.ones((3, 3), dtype=bool))
    if k < 2:
        return None
    lab = labels.ravel()[cells]
    sizes = np.bincount(lab, minlength=k + 1)
    big = int(np.argmax(sizes[1:])) + 1
    ref = lab == big
    if int(sizes[big]) < 3:
        return None
    p = points[idx]
    fit = fit_plane_inverse_depth(p, ref)
    e = np.abs(fit.d - p @ fit.normal) / (fit.d * p[:, 2])
    mean = np.bincount(lab, weights=e, minlength=k + 1) / np.maximum(sizes, 1)
    off_label = (sizes >= min_size) & (mean > ratio * mean[big])
    off_label[big] = False
    # a blob across the slab (a box top crossing the board's plane) has residuals like
    # the board's, but a plane of its own: its closest point against the reference's
    for b in np.flatnonzero((sizes >= min_size) & ~off_label):
        if b == big:
            continue
        own = fit_plane_inverse_depth(p, lab == b)
        diff = own.closest_point - fit.closest_point
        cov = own.covariance + fit.covariance
        try:
            m2 = float(diff @ np.linalg.solve(cov, diff))
        except np.linalg.LinAlgError:
            continue
        off_label[b] = m2 > max_mahalanobis2
    # the board dominates its inliers: blobs this large are the board (the largest blob
    # then holds a neighbour too, which blobs cannot separate), not what to drop
    if not off_label.any() or sizes[off_label].sum() > MAX_OFF_PLANE_SHARE * idx.size:
        return None
    out = np.zeros(points.shape[0], dtype=bool)
    out[idx[off_label[lab]]] = True
    return out


def closest_point_form(normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    """From ``n.x + offset = 0`` to ``(n', d)`` with ``n'.x = d`` and ``d >= 0``."""
    n = np.asarray(normal, dtype=np.float64)
    d = -float(offset)
    if d < 0:
        n, d = -n, -d
    return n, d


class PlaneMeasurer:
    """Measure a coloured board's plane in RGB-D frames (see the module docstring).

    Parameters
    ----------
    config : PlaneMeasurerConfig, optional

    Examples
    --------
    >>> from robopercept.sources import SyntheticRGBDScene
    >>> scene = SyntheticRGBDScene(n_frames=1, depth_size=(212, 120), color_size=(320, 180))
    >>> m = PlaneMeasurer().measure(scene.frame(0))
    >>> m.found, bool(m.inliers > 1000)
    (True, True)
    """

    def __init__(self, config: PlaneMeasurerConfig | None = None) -> None:
        self.config = PlaneMeasurerConfig() if config is None else config
        if not isinstance(self.config, PlaneMeasurerConfig):
            raise InputError(
                f"config must be a PlaneMeasurerConfig or None; got {type(self.config).__name__}"
            )
        c = self.config
        self.selector = ColorRangeSelector(
            c.hsv_low, c.hsv_high, c.occlusion_tolerance, c.occlusion_grows
        )
        self._prev_ratio: float | None = None

    def reset(self) -> None:
        """Forget the previous frame's inlier share (the early-stop target)."""
        self._prev_ratio = None

    def threshold(self, points: np.ndarray) -> float:
        """RANSAC inlier threshold :math:`\\max(\\tau_{min}, \\tau_1 z^2)` at the median
        depth of (a subsample of) ``points``, metres."""
        c = self.config
        z = float(np.median(points[:: max(1, points.shape[0] // 4096), 2]))
        return max(c.threshold_min, c.threshold_1m * z * z)

    def measure(self, frame: RGBDFrame, predicted: np.ndarray | None = None) -> PlaneMeasurement:
        """The board's plane in ``frame``.

        Parameters
        ----------
        frame : RGBDFrame
        predicted : (3,) ndarray, optional
            A predicted closest point :math:`\\pi = d\\, n` (from a tracker), scored
            first by RANSAC.

        Returns
        -------
        PlaneMeasurement
        """
        if not isinstance(frame, RGBDFrame):
            raise InputError(f"frame must be an RGBDFrame; got {type(frame).__name__}")
        if predicted is not None:
            predicted = check_numeric(predicted, "predicted")
            if predicted.shape != (3,):
                raise InputError(
                    "predicted must be a closest point d * n, 3 numbers, or None; got shape "
                    f"{predicted.shape}"
                )
        cp = self.selector(
            frame.depth,
            frame.color,
            frame.depth_intrinsics,
            frame.color_intrinsics,
            frame.T_color_depth,
            frame.depth_scale,
            copy=False,  # used up in this call: what is kept (the inliers) is copied
            hues=self.config.hue_tolerance is not None,
        )
        ms = dict(cp.ms)
        t0 = time.perf_counter()
        pts = cp.points
        try:
            plane = self._fit(pts, cp.hue, frame.index, predicted, cp.pixels, frame.depth.shape)
        except DegenerateError:
            plane = None
        solidity = math.nan
        if plane is not None:
            solidity = pixel_solidity_masked(cp.pixels, plane[3], frame.depth.shape[1])
            if solidity < self.config.min_solidity:
                plane = None  # scattered specks on some plane: no board
        self._prev_ratio = None if plane is None else plane[4]
        ms["ransac"] = (time.perf_counter() - t0) * 1e3
        if plane is None:
            nan3 = np.full(3, np.nan)
            return PlaneMeasurement(
                False, nan3, math.nan, np.full((3, 3), np.nan), 0, cp.n_valid,
                pts.shape[0], np.zeros((0, 3)), ms, solidity,
            )  # fmt: skip
        normal, d, cov, inl, _ = plane
        n_in = int(inl.sum())
        return PlaneMeasurement(
            True,
            normal,
            d,
            cov,
            n_in,
            cp.n_valid,
            pts.shape[0],
            _take_rows(pts, mask=inl),
            ms,
            solidity,
        )

    def _fit(
        self,
        pts: np.ndarray,
        hue: np.ndarray | None,
        index: int,
        predicted: np.ndarray | None,
        pixels: np.ndarray,
        shape: tuple[int, ...],
    ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, float] | None:
        # RANSAC, then the inverse-depth refits: (normal, d, floored covariance, inlier
        # mask, RANSAC's inlier share), or None with fewer than min_points
        c = self.config
        if pts.shape[0] < c.min_points:
            return None
        thr = self.threshold(pts)
        initial = None
        if predicted is not None and np.all(np.isfinite(predicted)):
            dp = math.hypot(*predicted)  # no overflow for large finite coordinates
            if 0 < dp < math.inf:
                initial = np.append(predicted / dp, -dp)[None]
        model: Model[Plane]
        if c.hue_tolerance is None or hue is None:
            data, model = pts, PlaneModel()
        else:
            data, model = np.column_stack([pts, hue]), PlaneHueModel(c.hue_tolerance)
            if initial is not None:
                initial = np.append(initial[0], float(np.median(hue)))[None]
        sub = data  # the points RANSAC scores on: a regular subsample of many
        if c.ransac_points is not None and data.shape[0] > c.ransac_points:
            sub = _take_rows(data, step=-(-data.shape[0] // c.ransac_points))
        min_inl = None
        if self._prev_ratio is not None:
            min_inl = max(c.min_points, int(self._prev_ratio * sub.shape[0]))
        res = ransac(
            sub,
            model,
            thr,
            max_iterations=c.max_iterations,
            probability=c.probability,
            scoring="msac",
            min_inliers=min_inl,
            initial=initial,
            rng=np.random.default_rng([c.rng, index]),
        )
        # the early-stop target of the next frame is RANSAC's own share of inliers: the
        # refitted plane's (larger) share is out of reach of the hypotheses, and asking
        # for it would run every frame to max_iterations
        share = int(res.inliers.sum()) / sub.shape[0]
        hue_ok = None  # with hue: the hypothesis' hue test, which every refit keeps
        if c.hue_tolerance is not None:
            hue_ok = res.inliers
            if sub is not data:
                hue_ok = model.inlier_mask(res.params, model.prepare(data), thr)
        # RANSAC's inliers among every point and their inverse-depth fit, then each
        # refit's inliers and theirs: one pass over the points each
        normal, d = closest_point_form(res.model.normal, res.model.offset)
        fit, inl = fit_plane_inverse_depth_slab(pts, normal, d, thr, hue_ok)
        for _ in range(c.refit_iterations):
            if fit.count < c.min_points:
                return None
            normal, d = fit.normal, fit.d
            # the same inliers give the same fit: converged, exactly (asked first with
            # the test alone, a sixth of the fit's pass)
            if np.array_equal(slab_inliers(pts, normal, d, thr, hue_ok), inl):
                break
            fit, inl = fit_plane_inverse_depth_slab(pts, normal, d, thr, hue_ok)
        if c.blob_residual_ratio is not None:
            dropped = np.zeros(pts.shape[0], dtype=bool)
            for _ in range(2):  # a second pass: the corrected plane may take in new blobs
                off = off_plane_blobs(
                    pts, pixels, shape, inl, c.blob_cell, c.blob_residual_ratio,
                    max(3, c.min_points // 4),
                )  # fmt: skip
                if off is None:
                    break
                dropped |= off
                keep = inl & ~dropped
                if int(keep.sum()) < c.min_points:
                    return None
                fit = fit_plane_inverse_depth(pts, keep)
                normal, d = fit.normal, fit.d
                allowed = ~dropped if hue_ok is None else ~dropped & hue_ok
                fit, inl = fit_plane_inverse_depth_slab(pts, normal, d, thr, allowed)
        n_in = int(inl.sum())
        if n_in < c.min_points:
            return None
        if c.refit_iterations > 0:  # else RANSAC's plane, with the fit's covariance
            normal, d = fit.normal, fit.d
        return normal, d, fit.covariance * max(1.0, n_in / c.effective_points), inl, share
