r"""Least-squares fits of 2-D lines and 3-D planes, and the :class:`Line` / :class:`Plane`
results shared by the RANSAC models and the point-cloud code.

Two kinds of fit:

- **ordinary** least squares treats one coordinate as a function of the others and
  minimizes vertical residuals: :math:`\min_w \|y - X w\|^2`, solved by
  ``numpy.linalg.lstsq`` (an SVD, no normal equations);
- **total** least squares minimizes the orthogonal distances. For a plane
  :math:`n^\top x + d = 0` with :math:`\|n\| = 1`,

  .. math:: \min_{n, d} \sum_i (n^\top x_i + d)^2
            \;\Rightarrow\; d = -n^\top \bar x,\quad
            n = \text{right singular vector of } [x_i - \bar x]
            \text{ with the smallest singular value,}

  and likewise for a 2-D line (the normal is the smallest singular direction).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numba import njit, prange

from robopercept._checks import check_choice, check_magnitude, check_points
from robopercept.errors import DegenerateError, InputError

__all__ = [
    "MAX_COORDINATE",
    "DepthPlaneFit",
    "Line",
    "LineFit",
    "Plane",
    "PlaneFit",
    "fit_line",
    "fit_plane",
    "fit_plane_from_scatter",
    "fit_plane_inverse_depth",
    "fit_plane_inverse_depth_slab",
    "scatter_matrix",
    "slab_inliers",
]

Method = Literal["total", "ordinary"]


@dataclass(frozen=True)
class Line:
    r"""A 2-D line :math:`a x + b y + c = 0` with :math:`a^2 + b^2 = 1`.

    Attributes
    ----------
    coefficients : (3,) float ndarray
        ``(a, b, c)``; ``(a, b)`` is the unit normal, ``|c|`` the distance to the origin.
    """

    coefficients: np.ndarray

    @property
    def normal(self) -> np.ndarray:
        """(2,) unit normal ``(a, b)``."""
        return self.coefficients[:2]

    @property
    def direction(self) -> np.ndarray:
        """(2,) unit direction ``(-b, a)``."""
        a, b = self.coefficients[:2]
        return np.array([-b, a])

    @property
    def point(self) -> np.ndarray:
        """(2,) the point of the line closest to the origin, ``-c (a, b)``."""
        return -self.coefficients[2] * self.coefficients[:2]

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distances of ``(N, 2)`` points (positive on the normal's side)."""
        p = check_points(points, "points", 2)
        return p @ self.coefficients[:2] + self.coefficients[2]


@dataclass(frozen=True)
class Plane:
    r"""A plane :math:`n^\top x + d = 0` with :math:`\|n\| = 1`.

    ``equation`` is ``(a, b, c, d)``, the form Open3D's ``segment_plane`` returns.

    Attributes
    ----------
    normal : (3,) float ndarray
        Unit normal.
    offset : float
        ``d``; the plane is ``|d|`` from the origin.
    """

    normal: np.ndarray
    offset: float

    @classmethod
    def from_equation(cls, equation: np.ndarray) -> Plane:
        """Plane from ``(a, b, c, d)`` (any scale; normalized here)."""
        e = np.asarray(equation, dtype=np.float64).reshape(-1)
        if e.shape != (4,) or not np.isfinite(e).all():
            raise InputError(f"equation must be 4 finite numbers (a, b, c, d); got {equation!r}")
        norm = float(np.linalg.norm(e[:3]))
        if norm == 0.0:
            raise DegenerateError("equation has a zero normal (a, b, c) = 0: not a plane")
        return cls(e[:3] / norm, float(e[3] / norm))

    @classmethod
    def from_point_normal(cls, point: np.ndarray, normal: np.ndarray) -> Plane:
        """Plane through ``point`` with normal ``normal`` (normalized here)."""
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        p = np.asarray(point, dtype=np.float64).reshape(3)
        return cls.from_equation(np.append(n, -float(n @ p)))

    @property
    def equation(self) -> np.ndarray:
        """(4,) ``(a, b, c, d)``."""
        return np.append(self.normal, self.offset)

    @property
    def point(self) -> np.ndarray:
        """(3,) the point of the plane closest to the origin, ``-d n``."""
        return -self.offset * self.normal

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(N,) signed distances of ``(N, 3)`` points (positive on the normal's side)."""
        p = check_points(points, "points", 3)
        return p @ self.normal + self.offset

    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) orthogonal projections of ``(N, 3)`` points onto the plane."""
        p = check_points(points, "points", 3)
        return p - np.outer(p @ self.normal + self.offset, self.normal)

    def angle_to(self, other: Plane) -> float:
        """Angle between the two planes in radians, in ``[0, pi/2]`` (normal sign ignored)."""
        c = abs(float(np.clip(self.normal @ other.normal, -1.0, 1.0)))
        return float(np.arccos(min(c, 1.0)))

    def flipped(self) -> Plane:
        """The same plane with the normal reversed."""
        return Plane(-self.normal, -self.offset)


@dataclass(frozen=True)
class LineFit:
    """Result of :func:`fit_line`: the line, the per-point residuals and their RMS."""

    line: Line
    residuals: np.ndarray
    rms: float
    method: str = field(default="total")


@dataclass(frozen=True)
class PlaneFit:
    """Result of :func:`fit_plane`: the plane, the per-point residuals and their RMS."""

    plane: Plane
    residuals: np.ndarray
    rms: float
    method: str = field(default="total")


#: largest coordinate the fits take (and :func:`~robopercept.estimation.ransac`): their
#: scatter matrices sum squares of coordinates, which overflow beyond about 1e154
MAX_COORDINATE = 1e150


def _checked(points: np.ndarray, dim: int, need: int, what: str) -> np.ndarray:
    p = check_points(points, "points", dim)
    if not np.isfinite(p).all():
        raise InputError(
            "points must be finite; drop NaN/inf rows first: points[np.isfinite(points).all(1)]"
        )
    if p.shape[0] < need:
        raise DegenerateError(f"a {what} needs at least {need} points; got {p.shape[0]}")
    # the scatter matrix sums squares of the coordinates: beyond 1e150 they overflow
    return check_magnitude(p, "points", MAX_COORDINATE)


@njit(cache=True, nogil=True)
def _scatter3_kernel(points, mask, use_mask):  # pragma: no cover - compiled
    # _scatter_kernel for d = 3 with the loops over coordinates unrolled: the same
    # additions in the same order (so the same bits), four times faster
    n = points.shape[0]
    c0 = c1 = c2 = 0.0
    count = 0
    for i in range(n):
        if use_mask and not mask[i]:
            continue
        count += 1
        c0 += points[i, 0]
        c1 += points[i, 1]
        c2 += points[i, 2]
    m = max(count, 1)
    c0 /= m
    c1 /= m
    c2 /= m
    s00 = s01 = s02 = s11 = s12 = s22 = 0.0
    for i in range(n):
        if use_mask and not mask[i]:
            continue
        e0 = points[i, 0] - c0
        e1 = points[i, 1] - c1
        e2 = points[i, 2] - c2
        s00 += e0 * e0
        s01 += e0 * e1
        s02 += e0 * e2
        s11 += e1 * e1
        s12 += e1 * e2
        s22 += e2 * e2
    c = np.array([c0, c1, c2])
    s = np.array([[s00, s01, s02], [s01, s11, s12], [s02, s12, s22]])
    return c, s


@njit(cache=True, nogil=True)
def _scatter_kernel(points, mask, use_mask):  # pragma: no cover - compiled
    n, d = points.shape
    if d == 3:
        return _scatter3_kernel(points, mask, use_mask)
    c = np.zeros(d)
    count = 0
    for i in range(n):
        if use_mask and not mask[i]:
            continue
        count += 1
        for j in range(d):
            c[j] += points[i, j]
    c /= max(count, 1)
    s = np.zeros((d, d))
    dev = np.empty(d)
    for i in range(n):  # a second pass: deviations from the exact centroid
        if use_mask and not mask[i]:
            continue
        for j in range(d):
            dev[j] = points[i, j] - c[j]
        for j in range(d):
            for k in range(j, d):
                s[j, k] += dev[j] * dev[k]
    for j in range(d):
        for k in range(j):
            s[j, k] = s[k, j]
    return c, s


def scatter_matrix(
    points: np.ndarray, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    r"""Centroid :math:`\bar x` and scatter :math:`S = \sum_i (x_i - \bar x)(x_i - \bar x)^\top`
    of the ``(N, D)`` points (those where ``mask`` is True).

    Two compiled passes over the rows (the centroid, then the deviations from it), with
    no ``N x D`` temporary and no copy of the selected rows.
    """
    pts = np.asarray(points, dtype=np.float64)
    if mask is None:
        return _scatter_kernel(pts, np.zeros(1, dtype=np.bool_), False)
    return _scatter_kernel(pts, np.asarray(mask, dtype=np.bool_), True)


def fit_plane_from_scatter(centroid: np.ndarray, scatter: np.ndarray) -> np.ndarray:
    """Plane equation ``(a, b, c, d)`` through ``centroid`` with the normal of least scatter."""
    n = _smallest_direction(scatter, "plane", 2)
    return np.append(n, -float(n @ centroid))


def _smallest_direction(scatter: np.ndarray, what: str, rank_needed: int) -> np.ndarray:
    """Unit direction of least spread, from the scatter matrix, after checking its rank.

    The right singular vectors of the centred points are the eigenvectors of their small
    scatter matrix :math:`S = X^T X` (eigenvalues: the squared singular values).
    """
    evals, evecs = np.linalg.eigh(scatter)  # ascending
    top = float(evals[-1])
    if top <= 0.0:
        raise DegenerateError(f"the points do not determine a {what}: they are all the same point")
    if evals[-rank_needed] <= 1e-12 * top:
        raise DegenerateError(f"the points do not determine a {what}: they are collinear")
    return evecs[:, 0]


@dataclass(frozen=True)
class DepthPlaneFit:
    r"""Result of :func:`fit_plane_inverse_depth`.

    Attributes
    ----------
    normal : (3,) ndarray
        Unit normal :math:`n` with :math:`n^\top x = d`, :math:`d \ge 0` (it points from
        the camera toward the plane).
    d : float
        Distance of the plane from the camera centre, metres.
    closest_point : (3,) ndarray
        :math:`\pi = d\, n`, the point of the plane nearest the camera.
    covariance : (3, 3) ndarray
        Covariance of :math:`\pi` under the fit's noise model (see the function).
    sigma : float
        RMS residual in inverse depth, 1/m (its noise level).
    count : int
        Points fitted.
    """

    normal: np.ndarray
    d: float
    closest_point: np.ndarray
    covariance: np.ndarray
    sigma: float
    count: int


@njit(cache=True, nogil=True)
def _inverse_depth_moments(points, mask, use_mask):  # pragma: no cover - compiled
    # M = sum a a^T (3x3), b = sum a w, ww = sum w^2, with a = (x/z, y/z, 1), w = 1/z
    m = np.zeros((3, 3))
    b = np.zeros(3)
    ww = 0.0
    count = 0
    for i in range(points.shape[0]):
        if use_mask and not mask[i]:
            continue
        z = points[i, 2]
        if not z > 0:
            continue
        w = 1.0 / z
        a0 = points[i, 0] * w
        a1 = points[i, 1] * w
        m[0, 0] += a0 * a0
        m[0, 1] += a0 * a1
        m[0, 2] += a0
        m[1, 1] += a1 * a1
        m[1, 2] += a1
        m[2, 2] += 1.0
        b[0] += a0 * w
        b[1] += a1 * w
        b[2] += w
        ww += w * w
        count += 1
    m[1, 0] = m[0, 1]
    m[2, 0] = m[0, 2]
    m[2, 1] = m[1, 2]
    return m, b, ww, count


def fit_plane_inverse_depth(points: np.ndarray, mask: np.ndarray | None = None) -> DepthPlaneFit:
    r"""Plane through depth-camera points by least squares in inverse depth: the
    maximum-likelihood fit for stereo depth, whose noise is additive in disparity.

    A point seen along the ray :math:`r = (x/z, y/z, 1)` lies on the plane
    :math:`n^\top x = d` at depth :math:`z = d / (n^\top r)`, so its inverse depth is
    linear in the normalized image coordinates:

    .. math:: \frac{1}{z} = c^\top r = c_0 \frac{x}{z} + c_1 \frac{y}{z} + c_2,
              \qquad c = n / d.

    A stereo camera measures disparity :math:`\delta = f B / z` with additive noise of
    constant variance, i.e. :math:`1/z` with constant noise :math:`\sigma`, and along
    the viewing ray; ordinary least squares of :math:`w = 1/z` on :math:`r` is then the
    exact maximum-likelihood (and unbiased) fit:
    :math:`\hat c = (A^\top A)^{-1} A^\top w`. Total least squares (:func:`fit_plane`)
    assumes isotropic noise instead; with depth noise growing as :math:`z^2` along the
    rays it tilts the normal of an oblique plane by a systematic fraction of a degree at
    2 m, and the tilt moves :math:`d` by millimetres.

    The result is :math:`n = c / \|c\|`, :math:`d = 1 / \|c\|` and the closest point
    :math:`\pi = d\, n = c / \|c\|^2`, whose covariance follows to first order from
    :math:`\operatorname{Cov}(\hat c) = \hat\sigma^2 (A^\top A)^{-1}`,
    :math:`\hat\sigma^2 = \|w - A \hat c\|^2 / (N - 3)`, through the Jacobian
    :math:`\partial \pi / \partial c = (\|c\|^2 I - 2 c c^\top) / \|c\|^4`.

    Parameters
    ----------
    points : (N, 3) array_like
        Points in the camera frame (metres, :math:`z > 0`; rows with :math:`z \le 0`
        are ignored).
    mask : (N,) bool array_like, optional
        Fit only these rows (no copy is made).

    Returns
    -------
    DepthPlaneFit

    Raises
    ------
    InputError
        Points that are not ``(N, 3)`` real numbers, or selected rows with NaN/inf
        ``x``/``y`` or values whose ratios overflow (rows whose ``z`` is NaN or not
        positive are ignored).
    DegenerateError
        Fewer than 3 points, or all of them on one ray line (collinear in the image).

    Notes
    -----
    Reference: ``numpy.linalg.lstsq`` on the same design matrix (the tests compare);
    the disparity-space plane is the model of slanted-plane stereo (e.g. Bleyer et al.,
    PatchMatch Stereo, 2011).
    """
    pts = check_points(points, "points", 3)
    if mask is None:
        m, b, ww, count = _inverse_depth_moments(pts, np.zeros(1, dtype=np.bool_), False)
    else:
        sel = np.asarray(mask, dtype=np.bool_)
        if sel.shape != (pts.shape[0],):
            raise InputError(f"mask must have shape ({pts.shape[0]},); got {sel.shape}")
        m, b, ww, count = _inverse_depth_moments(pts, sel, True)
    return _fit_from_moments(m, b, ww, count)


def _fit_from_moments(m: np.ndarray, b: np.ndarray, ww: float, count: int) -> DepthPlaneFit:
    """:func:`fit_plane_inverse_depth` from the sums of its design (``M = A^T A``,
    ``b = A^T w``, ``w^T w`` and the number of points)."""
    if not (np.isfinite(m).all() and np.isfinite(b).all() and math.isfinite(ww)):
        # (checked on the sums: no pass over the points; rows with z NaN are skipped)
        raise InputError(
            "points must be finite, with x / z, y / z and 1 / z within about 1e150: the "
            "fit's sums overflowed or hold NaN; drop those rows first, "
            "points[np.isfinite(points).all(1)]"
        )
    if count < 3:
        raise DegenerateError(f"a plane needs at least 3 points with z > 0; got {count}")
    evals = np.linalg.eigvalsh(m)
    if not evals[0] > 1e-12 * evals[-1]:
        raise DegenerateError("the points lie on one line in the image: no plane is determined")
    m_inv = np.linalg.inv(m)
    c = m_inv @ b
    rss = max(ww - float(c @ b), 0.0)  # w'w - 2 c'A'w + c'A'A c with A'A c = A'w
    sigma2 = rss / max(count - 3, 1)
    k2 = float(c @ c)
    if not k2 > 0:
        raise DegenerateError("the fitted plane passes through the camera centre")
    jac = (k2 * np.eye(3) - 2.0 * np.outer(c, c)) / (k2 * k2)
    cov = jac @ (sigma2 * m_inv) @ jac.T
    d = 1.0 / math.sqrt(k2)
    normal = c * d
    return DepthPlaneFit(normal, d, c / k2, 0.5 * (cov + cov.T), math.sqrt(sigma2), int(count))


_SLAB_BLOCKS = 64  # point blocks of the parallel slab pass (sums added in block order)


@njit(cache=True, nogil=True)
def _in_slab(x, y, z, nx, ny, nz, d, threshold):  # pragma: no cover - compiled
    # |n.x - d| < threshold: the slab fit's inlier test (scalars: inlined, no call cost)
    return abs(nx * x + ny * y + nz * z - d) < threshold


@njit(cache=True, nogil=True)
def _slab_block(
    points, blk, nx, ny, nz, d, threshold, within, use_within, out, pm, pc
):  # pragma: no cover - compiled
    # block blk of _slab_kernel: out[i] = |n.x_i - d| < threshold (and within[i]) and the
    # inverse-depth moments of those points into pm[blk], their count into pc[blk]
    n = points.shape[0]
    s00 = s01 = s02 = s11 = s12 = s22 = b0 = b1 = b2 = sww = 0.0
    count = 0
    for i in range(blk * n // _SLAB_BLOCKS, (blk + 1) * n // _SLAB_BLOCKS):
        x = points[i, 0]
        y = points[i, 1]
        z = points[i, 2]
        inside = _in_slab(x, y, z, nx, ny, nz, d, threshold)
        if use_within:
            inside = inside and within[i]
        out[i] = inside
        if not inside or not z > 0:
            continue
        w = 1.0 / z
        a0 = x * w
        a1 = y * w
        s00 += a0 * a0
        s01 += a0 * a1
        s02 += a0
        s11 += a1 * a1
        s12 += a1
        s22 += 1.0
        b0 += a0 * w
        b1 += a1 * w
        b2 += w
        sww += w * w
        count += 1
    pm[blk, 0] = s00
    pm[blk, 1] = s01
    pm[blk, 2] = s02
    pm[blk, 3] = s11
    pm[blk, 4] = s12
    pm[blk, 5] = s22
    pm[blk, 6] = b0
    pm[blk, 7] = b1
    pm[blk, 8] = b2
    pm[blk, 9] = sww
    pc[blk] = count


@njit(cache=True, nogil=True)
def _slab_total(pm, pc):  # pragma: no cover - compiled
    # the blocks' sums added in block order: the moments of _slab_kernel
    t = np.zeros(10)
    for blk in range(_SLAB_BLOCKS):
        t += pm[blk]
    m = np.array([[t[0], t[1], t[2]], [t[1], t[3], t[4]], [t[2], t[4], t[5]]])
    return m, np.array([t[6], t[7], t[8]]), t[9], pc.sum()


@njit(cache=True, nogil=True, parallel=True)
def _slab_kernel(points, nx, ny, nz, d, threshold, within, use_within, out):  # pragma: no cover
    # out[i] = |n.x_i - d| < threshold (and within[i]); the inverse-depth moments of
    # those points, summed per block of rows and the blocks added in order, so the
    # sums do not depend on the number of threads
    pm = np.zeros((_SLAB_BLOCKS, 10))
    pc = np.zeros(_SLAB_BLOCKS, dtype=np.int64)
    for blk in prange(_SLAB_BLOCKS):
        _slab_block(points, blk, nx, ny, nz, d, threshold, within, use_within, out, pm, pc)
    return _slab_total(pm, pc)


@njit(cache=True, nogil=True)
def _slab_kernel_serial(
    points, nx, ny, nz, d, threshold, within, use_within, out
):  # pragma: no cover - compiled
    # _slab_kernel on one thread: the same blocks, so the same bits
    pm = np.zeros((_SLAB_BLOCKS, 10))
    pc = np.zeros(_SLAB_BLOCKS, dtype=np.int64)
    for blk in range(_SLAB_BLOCKS):
        _slab_block(points, blk, nx, ny, nz, d, threshold, within, use_within, out, pm, pc)
    return _slab_total(pm, pc)


#: fewest points for which the slab pass runs on every thread: below it, waking the
#: threads cost more than they save (2 cores: 0.26 vs 0.19 ms on 30,000 points,
#: 0.48 vs 0.39 ms on 60,000, 0.81 vs 0.96 ms on 150,000)
SLAB_PARALLEL_MIN = 100_000


@njit(cache=True, nogil=True, parallel=True)
def _slab_mask_kernel(
    points, nx, ny, nz, d, threshold, within, use_within, out
):  # pragma: no cover - compiled
    # out[i]: _slab_kernel's inlier test alone (the same function, so the same bits)
    n = points.shape[0]
    for blk in prange(_SLAB_BLOCKS):
        for i in range(blk * n // _SLAB_BLOCKS, (blk + 1) * n // _SLAB_BLOCKS):
            p = points[i]
            inside = _in_slab(p[0], p[1], p[2], nx, ny, nz, d, threshold)
            out[i] = inside and (not use_within or within[i])


def slab_inliers(
    points: np.ndarray,
    normal: np.ndarray,
    d: float,
    threshold: float,
    within: np.ndarray | None = None,
) -> np.ndarray:
    r"""The points within ``threshold`` of the plane :math:`n^\top x = d`: the inlier
    mask of :func:`fit_plane_inverse_depth_slab`, bit for bit, without the fit.

    ``np.abs(points @ normal - d) < threshold`` (``& within``) in one compiled pass, the
    residual computed as the slab fit computes it. A refit loop asks it whether a new
    plane changes the inliers before it pays for the fit's sums (when it does not, the
    fit would be the same one).

    Parameters
    ----------
    points : (N, 3) float64 ndarray
        Camera-frame points (unchecked, as in a per-frame loop: the caller's).
    normal : (3,) array_like
    d : float
        The plane.
    threshold : float
        Inlier distance.
    within : (N,) bool ndarray, optional
        Only these points may be inliers.

    Returns
    -------
    (N,) bool ndarray

    Examples
    --------
    >>> pts = np.array([[0.0, 0.0, 2.0], [0.1, 0.0, 2.05], [0.0, 0.1, 2.3]])
    >>> slab_inliers(pts, np.array([0.0, 0.0, 1.0]), 2.0, 0.1).tolist()
    [True, True, False]
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    sel = np.zeros(1, dtype=np.bool_) if within is None else np.asarray(within, dtype=np.bool_)
    _slab_mask_kernel(
        pts, n[0], n[1], n[2], float(d), float(threshold), sel, within is not None, out
    )
    return out


def fit_plane_inverse_depth_slab(
    points: np.ndarray,
    normal: np.ndarray,
    d: float,
    threshold: float,
    within: np.ndarray | None = None,
) -> tuple[DepthPlaneFit, np.ndarray]:
    r"""The points within ``threshold`` of the plane :math:`n^\top x = d` and
    :func:`fit_plane_inverse_depth` of them, in one pass over the points.

    The inlier selection and refit of a RANSAC plane, as
    ``inl = np.abs(points @ normal - d) < threshold`` (``& within``) then
    ``fit_plane_inverse_depth(points, inl)``, without the temporaries: one compiled
    parallel pass tests each point and sums the fit's moments of the inliers (per
    block of points, the blocks added in order: the same sums on any number of
    threads; the order of the additions differs from
    :func:`fit_plane_inverse_depth`'s, so the two agree to rounding).

    Parameters
    ----------
    points : (N, 3) float64 ndarray
        Camera-frame points, finite (unchecked, as in a per-frame loop: the caller's).
    normal : (3,) array_like
    d : float
        The plane.
    threshold : float
        Inlier distance, > 0.
    within : (N,) bool ndarray, optional
        Only these points may be inliers.

    Returns
    -------
    fit : DepthPlaneFit
    inliers : (N,) bool ndarray

    Raises
    ------
    DegenerateError
        As :func:`fit_plane_inverse_depth` (fewer than 3 inliers, or all on one ray
        line).

    Examples
    --------
    >>> yy, xx = np.mgrid[0:20, 0:20]
    >>> z = 2.0 + 0.01 * xx.ravel()
    >>> pts = np.column_stack([(xx.ravel() - 10) * z / 100, (yy.ravel() - 10) * z / 100, z])
    >>> pts[::7, 2] += 0.5  # off the plane
    >>> fit, inl = fit_plane_inverse_depth_slab(pts, np.array([0, 0, 1.0]), 2.1, 0.2)
    >>> ref = fit_plane_inverse_depth(pts, inl)
    >>> int(inl.sum()), bool(np.allclose(fit.normal, ref.normal, atol=1e-12))
    (342, True)
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    sel = np.zeros(1, dtype=np.bool_) if within is None else np.asarray(within, dtype=np.bool_)
    kernel = _slab_kernel if pts.shape[0] >= SLAB_PARALLEL_MIN else _slab_kernel_serial
    m, b, ww, count = kernel(
        pts, n[0], n[1], n[2], float(d), float(threshold), sel, within is not None, out
    )
    return _fit_from_moments(m, b, ww, int(count)), out


def fit_line(points: np.ndarray, method: Method = "total") -> LineFit:
    r"""Least-squares 2-D line.

    ``method="total"``: orthogonal regression, the line through the centroid whose normal
    is the smallest singular direction of the centred points (residuals: signed
    orthogonal distances). ``method="ordinary"``: :math:`y = w_0 + w_1 x` by
    ``numpy.linalg.lstsq`` (residuals: :math:`y_i - \hat y_i`); a vertical line has no such
    form and raises :class:`DegenerateError`.

    Parameters
    ----------
    points : (N, 2) array_like
        N >= 2 finite points.
    method : {'total', 'ordinary'}

    Returns
    -------
    LineFit

    Examples
    --------
    Points on :math:`y = 2x + 1`:

    >>> fit = fit_line(np.array([[0.0, 1.0], [1.0, 3.0], [2.0, 5.0], [3.0, 7.0]]))
    >>> a, b, c = fit.line.coefficients  # a x + b y + c = 0
    >>> round(float(-a / b), 9), round(float(-c / b), 9), bool(fit.rms < 1e-12)
    (2.0, 1.0, True)
    """
    check_choice(method, "method", ("total", "ordinary"))
    p = _checked(points, 2, 2, "line")
    if method == "ordinary":
        x, y = p[:, 0], p[:, 1]
        if np.ptp(x) == 0.0:
            raise DegenerateError(
                "all x are equal: y = w0 + w1 x cannot describe a vertical line; use method='total'"
            )
        design = np.column_stack([np.ones_like(x), x])
        w = np.linalg.lstsq(design, y, rcond=None)[0]
        res = y - design @ w
        coef = np.array([-w[1], 1.0, -w[0]]) / np.hypot(w[1], 1.0)
        return LineFit(Line(coef), res, float(np.sqrt(np.mean(res**2))), method)
    c, scatter = scatter_matrix(p)
    n = _smallest_direction(scatter, "line", 1)
    coef = np.append(n, -float(n @ c))
    res = p @ n + coef[2]
    return LineFit(Line(coef), res, float(np.sqrt(np.mean(res**2))), method)


def fit_plane(
    points: np.ndarray, method: Method = "total", weights: np.ndarray | None = None
) -> PlaneFit:
    r"""Least-squares plane.

    ``method="total"``: the plane through the (weighted) centroid whose normal is the
    smallest singular direction of the centred points; residuals are signed orthogonal
    distances. ``method="ordinary"``: :math:`z = w_0 + w_1 x + w_2 y` by
    ``numpy.linalg.lstsq``; residuals are :math:`z_i - \hat z_i`.

    Parameters
    ----------
    points : (N, 3) array_like
        N >= 3 finite points, not all collinear.
    method : {'total', 'ordinary'}
    weights : (N,) array_like, optional
        Non-negative weights (total least squares only).

    Returns
    -------
    PlaneFit
    """
    check_choice(method, "method", ("total", "ordinary"))
    p = _checked(points, 3, 3, "plane")
    if method == "ordinary":
        design = np.column_stack([np.ones(len(p)), p[:, 0], p[:, 1]])
        w, _, rank, _ = np.linalg.lstsq(design, p[:, 2], rcond=None)
        if rank < 3:
            raise DegenerateError(
                "the (x, y) of the points are collinear: z = w0 + w1 x + w2 y is not "
                "determined; use method='total'"
            )
        res = p[:, 2] - design @ w
        plane = Plane.from_equation(np.array([w[1], w[2], -1.0, w[0]]))
        return PlaneFit(plane, res, float(np.sqrt(np.mean(res**2))), method)
    if weights is None:
        c, scatter = scatter_matrix(p)
    else:
        wts = np.asarray(weights, dtype=np.float64).reshape(-1)
        if wts.shape[0] != p.shape[0] or (wts < 0).any() or not np.isfinite(wts).all():
            raise InputError(
                f"weights must be {p.shape[0]} finite non-negative numbers; got {wts.shape}"
            )
        if wts.sum() <= 0:
            raise DegenerateError("all weights are zero")
        c = (wts[:, None] * p).sum(axis=0) / wts.sum()
        centered = (p - c) * np.sqrt(wts)[:, None]
        scatter = centered.T @ centered
    n = _smallest_direction(scatter, "plane", 2)
    plane = Plane(n, -float(n @ c))
    res = p @ n + plane.offset
    return PlaneFit(plane, res, float(np.sqrt(np.mean(res**2))), method)
