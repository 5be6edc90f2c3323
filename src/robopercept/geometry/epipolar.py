r"""Two-view (epipolar) geometry: essential and fundamental matrices, the normalized
eight-point algorithm, epipolar lines, epipoles, and the relative pose from E.

A point :math:`X` seen by two cameras with :math:`x_2 \sim K_2 (R X + t)` and
:math:`x_1 \sim K_1 X` satisfies the epipolar constraint

.. math::

    \hat x_2^T E \hat x_1 = 0, \quad E = [t]_\times R \qquad
    x_2^T F x_1 = 0, \quad F = K_2^{-T} E K_1^{-1},

with :math:`\hat x = K^{-1} x` normalized image coordinates. :math:`E` has two equal
singular values and a zero one; :math:`F` has rank 2. The epipolar line of
:math:`x_1` in the second image is :math:`l_2 = F x_1`, that of :math:`x_2` in the
first :math:`l_1 = F^T x_2`; the epipoles are the null vectors :math:`F e_1 = 0`,
:math:`F^T e_2 = 0`.

Conventions are OpenCV's (``cv2.findFundamentalMat`` takes ``points1, points2`` and
returns F with ``x2^T F x1 = 0``; ``cv2.recoverPose`` returns the R, t mapping camera-1
coordinates into camera 2: :math:`X_2 = R X_1 + t`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_magnitude,
    check_numeric,
    check_real,
    squeeze_point_axis,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.models import Model, hartley_normalization
from robopercept.geometry.transforms import check_matrix3

__all__ = [
    "EssentialModel",
    "FundamentalFit",
    "FundamentalModel",
    "RelativePose",
    "decompose_essential",
    "eight_point",
    "epipolar_lines",
    "epipoles",
    "essential_from_pose",
    "find_essential",
    "find_fundamental",
    "fundamental_from_essential",
    "sampson_distance",
    "skew",
]


def _vector3(v: npt.ArrayLike, name: str) -> np.ndarray:
    """``v`` as a finite float64 (3,) vector (a (3, 1) column too)."""
    a = check_numeric(v, name)
    if a.shape not in ((3,), (3, 1), (1, 3)):
        raise InputError(f"{name} must be 3 finite numbers, shape (3,); got shape {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"{name} must be 3 finite numbers; got {a.reshape(3).tolist()}")
    return a.reshape(3)


def skew(v: npt.ArrayLike) -> np.ndarray:
    r"""The cross-product matrix :math:`[v]_\times` with :math:`[v]_\times u = v \times u`.

    Parameters
    ----------
    v : (3,) array_like
        Finite (a ``(3, 1)`` column too).

    Returns
    -------
    (3, 3) float64 ndarray

    Raises
    ------
    InputError
        Not 3 finite real numbers.

    Examples
    --------
    >>> skew([1.0, 2.0, 3.0]).tolist()
    [[0.0, -3.0, 2.0], [3.0, 0.0, -1.0], [-2.0, 1.0, 0.0]]
    """
    x, y, z = _vector3(v, "v")
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _rotation(R: npt.ArrayLike, name: str = "R") -> np.ndarray:
    r = check_matrix3(R, name)
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-6) or np.linalg.det(r) < 0:
        raise InputError(f"{name} is not a rotation (R^T R != I or det < 0)")
    return r


def essential_from_pose(R: npt.ArrayLike, t: npt.ArrayLike) -> np.ndarray:
    r"""Essential matrix :math:`E = [t]_\times R` of the motion :math:`X_2 = R X_1 + t`.

    Raises :class:`InputError` if ``R`` is not a rotation or ``t`` not 3 finite numbers."""
    return skew(_vector3(t, "t")) @ _rotation(R)


def fundamental_from_essential(
    E: npt.ArrayLike, K1: npt.ArrayLike, K2: npt.ArrayLike
) -> np.ndarray:
    r""":math:`F = K_2^{-T} E K_1^{-1}`, scaled to unit Frobenius norm.

    Each matrix is divided by its largest absolute entry first (F is defined up to
    scale), so entries near 1e300 or 1e-300 neither overflow nor underflow.

    Raises
    ------
    InputError
        A matrix that is not finite, real and 3x3, a singular ``K1`` or ``K2``, or an
        all-zero ``E``.
    """
    e = check_matrix3(E, "E")
    k1, k2 = check_matrix3(K1, "K1", invertible=True), check_matrix3(K2, "K2", invertible=True)
    if not np.abs(e).max() > 0:
        raise InputError("E is the zero matrix: give the essential matrix [t]x R of the motion")
    e, k1, k2 = (m / np.abs(m).max() for m in (e, k1, k2))
    F = np.linalg.inv(k2).T @ e @ np.linalg.inv(k1)
    F /= np.abs(F).max()
    return F / np.linalg.norm(F)


def _points(x: npt.ArrayLike, name: str) -> np.ndarray:
    """(N, 2) or OpenCV's (N, 1, 2) points as a finite float64 (N, 2) array."""
    p = squeeze_point_axis(check_numeric(x, name), 2)
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(
            f"{name} must be (N, 2) pixel coordinates (or OpenCV's (N, 1, 2)); got shape {p.shape}"
        )
    if not np.isfinite(p).all():
        raise InputError(f"{name} contains NaN or inf; drop those correspondences first")
    return check_magnitude(p, name, 1e150)


def _pairs(x1: npt.ArrayLike, x2: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Checked correspondences: both (N, 2), finite, of one length."""
    p1, p2 = _points(x1, "x1"), _points(x2, "x2")
    if p1.shape != p2.shape:
        raise InputError(f"x1 and x2 must have the same shape; got {p1.shape} and {p2.shape}")
    return p1, p2


def _eight_point_batch(x1: np.ndarray, x2: np.ndarray, essential: bool) -> np.ndarray:
    """(B, n, 2) x (B, n, 2) -> (B, 3, 3), unit Frobenius norm, rank 2 (or (1, 1, 0))."""
    t1, t2 = hartley_normalization(x1), hartley_normalization(x2)
    a1 = x1 @ t1[:, :2, :2].transpose(0, 2, 1) + t1[:, None, :2, 2]
    a2 = x2 @ t2[:, :2, :2].transpose(0, 2, 1) + t2[:, None, :2, 2]
    u1, v1 = a1[..., 0], a1[..., 1]
    u2, v2 = a2[..., 0], a2[..., 1]
    one = np.ones_like(u1)
    A = np.stack([u2 * u1, u2 * v1, u2, v2 * u1, v2 * v1, v2, u1, v1, one], axis=-1)
    if A.shape[1] < 9:  # pad to square: the null vector of the 8x9 system
        A = np.concatenate([A, np.zeros((A.shape[0], 9 - A.shape[1], 9))], axis=1)
    # thin SVD: V is all that is needed (the full U of an N x N system costs O(N^2))
    _, _, vt = np.linalg.svd(A, full_matrices=False)
    F = vt[:, -1].reshape(-1, 3, 3)
    if essential:  # project after undoing the normalization, which would change E's shape
        F = t2.transpose(0, 2, 1) @ F @ t1
        u, s, wt = np.linalg.svd(F)
        s = np.stack([np.ones(len(s)), np.ones(len(s)), np.zeros(len(s))], axis=1)
        F = (u * s[:, None, :]) @ wt
    else:
        u, s, wt = np.linalg.svd(F)
        s = s.copy()
        s[:, 2] = 0.0
        F = t2.transpose(0, 2, 1) @ ((u * s[:, None, :]) @ wt) @ t1
    return F / np.linalg.norm(F, axis=(1, 2), keepdims=True)


def eight_point(x1: npt.ArrayLike, x2: npt.ArrayLike, *, essential: bool = False) -> np.ndarray:
    r"""The normalized eight-point algorithm (Hartley 1997).

    Both point sets are moved to their centroid and scaled to a mean distance of
    :math:`\sqrt 2` (:math:`\tilde x = T x`); every correspondence gives one row of
    :math:`A f = 0`,

    .. math::

        [\tilde x_2 \tilde x_1,\ \tilde x_2 \tilde y_1,\ \tilde x_2,\
         \tilde y_2 \tilde x_1,\ \tilde y_2 \tilde y_1,\ \tilde y_2,\
         \tilde x_1,\ \tilde y_1,\ 1]\, f = 0,

    :math:`f` is the right singular vector of the smallest singular value, the rank-2
    constraint is imposed by zeroing :math:`F`'s smallest singular value, and
    :math:`F = T_2^T \tilde F T_1`. For an essential matrix the singular values of
    :math:`T_2^T \tilde F T_1` are set to :math:`(1, 1, 0)` instead (after undoing the
    normalization, which does not keep two singular values equal).

    Parameters
    ----------
    x1, x2 : (N, 2) or (N, 1, 2) array_like
        Corresponding points, N >= 8 (pixels for F; normalized coordinates
        :math:`K^{-1} x` for E).
    essential : bool
        Project onto the essential manifold instead of rank 2.

    Returns
    -------
    (3, 3) ndarray
        Unit Frobenius norm, with :math:`x_2^T F x_1 \approx 0`.

    Raises
    ------
    DegenerateError
        Fewer than 8 correspondences, or all of them on a line.
    """
    p1, p2 = _pairs(x1, x2)
    if len(p1) < 8:
        raise DegenerateError(f"the eight-point algorithm needs 8 correspondences; got {len(p1)}")
    _check_spread(p1, p2)
    return _eight_point_batch(p1[None], p2[None], essential)[0]


def _check_spread(p1: np.ndarray, p2: np.ndarray) -> None:
    for name, p in (("x1", p1), ("x2", p2)):
        c = p - p.mean(axis=0)
        ev = np.linalg.eigvalsh(c.T @ c)
        if ev[0] <= 1e-12 * max(ev[1], 1e-300):
            raise DegenerateError(
                f"the {name} points are collinear (or coincide): F is not determined"
            )


def sampson_distance(F: npt.ArrayLike, x1: npt.ArrayLike, x2: npt.ArrayLike) -> np.ndarray:
    r"""First-order geometric error of each correspondence, in pixels:

    .. math::

        d = \frac{|x_2^T F x_1|}{\sqrt{(F x_1)_1^2 + (F x_1)_2^2 + (F^T x_2)_1^2
            + (F^T x_2)_2^2}}.
    """
    Fm = check_matrix3(F, "F")
    p1, p2 = _pairs(x1, x2)
    if np.abs(Fm).max() > 0:  # F is defined up to scale: keep its products finite
        Fm = Fm / np.abs(Fm).max()
    return _sampson(Fm[None], p1, p2)[0]


def _sampson(F: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """(B, 3, 3) hypotheses, (N, 2) points -> (B, N) Sampson distances."""
    h1 = np.c_[p1, np.ones(len(p1))]
    h2 = np.c_[p2, np.ones(len(p2))]
    Fx1 = np.einsum("bij,nj->bni", F, h1)
    Ftx2 = np.einsum("bji,nj->bni", F, h2)
    num = np.abs(np.einsum("ni,bni->bn", h2, Fx1))
    den = np.sqrt(Fx1[..., 0] ** 2 + Fx1[..., 1] ** 2 + Ftx2[..., 0] ** 2 + Ftx2[..., 1] ** 2)
    return num / np.maximum(den, 1e-300)


class FundamentalModel(Model[np.ndarray]):
    r"""F from correspondences ``(x1, y1, x2, y2)`` for :func:`robopercept.estimation.ransac`.

    Minimal sample: 8 correspondences, fitted by the normalized eight-point algorithm
    (samples with collinear points are invalid). Residual: the Sampson distance.
    """

    sample_size = 8
    dim = 4
    name = "fundamental"
    essential = False

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x1, x2 = samples[:, :, :2], samples[:, :, 2:]
        valid = np.ones(samples.shape[0], dtype=bool)
        for p in (x1, x2):
            c = p - p.mean(axis=1, keepdims=True)
            cov = np.einsum("bni,bnj->bij", c, c)
            ev = np.linalg.eigvalsh(cov)
            valid &= ev[:, 0] > 1e-12 * np.maximum(ev[:, 1], 1e-300)
        F = np.tile(np.eye(3), (samples.shape[0], 1, 1))
        if valid.any():
            F[valid] = _eight_point_batch(x1[valid], x2[valid], self.essential)
        valid &= np.isfinite(F).all(axis=(1, 2))
        return F.reshape(-1, 9), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        if data.shape[0] < 8:
            raise DegenerateError(f"F needs 8 correspondences; got {data.shape[0]}")
        self.check(data)
        return _eight_point_batch(data[None, :, :2], data[None, :, 2:], self.essential)[0].reshape(
            9
        )

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        return _sampson(params.reshape(-1, 3, 3), data[:, :2], data[:, 2:])

    def check(self, data: np.ndarray) -> None:
        _check_spread(data[:, :2], data[:, 2:])

    def result(self, params: np.ndarray) -> np.ndarray:
        return np.asarray(params, dtype=np.float64).reshape(3, 3)


class EssentialModel(FundamentalModel):
    """E from correspondences in normalized coordinates ``(x1, y1, x2, y2)`` (each point
    multiplied by :math:`K^{-1}`); the eight-point fit projected to singular values
    (1, 1, 0). Residual: the Sampson distance in normalized units."""

    name = "essential"
    essential = True


@dataclass(frozen=True)
class FundamentalFit:
    """Result of :func:`find_fundamental` / :func:`find_essential`.

    It unpacks as the tuple of ``F, mask = cv2.findFundamentalMat(x1, x2, cv2.FM_RANSAC)``
    and ``E, mask = cv2.findEssentialMat(x1, x2, K)``: ``F, mask = find_fundamental(x1,
    x2)`` gives ``F`` (3, 3) float64 and ``mask`` (N, 1) uint8, 1 for the inliers and 0
    for the rest (OpenCV's shape and values). ``F`` is this object's matrix as it is, with
    unit Frobenius norm (``cv2.findFundamentalMat`` scales F to ``F[2, 2] = 1``; both
    are the same F up to scale; ``cv2.findEssentialMat``'s E has unit norm too). The
    attributes stay the primary interface.

    Attributes
    ----------
    F : (3, 3) ndarray
        The matrix (F, or E for :func:`find_essential`), unit Frobenius norm.
    inliers : (N,) bool ndarray
    n_iterations : int
    residuals : (N,) ndarray
        Sampson distances (pixels; normalized units for E).
    """

    F: np.ndarray
    inliers: np.ndarray
    n_iterations: int
    residuals: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """:attr:`inliers` as OpenCV's inlier mask: (N, 1) uint8, 1 for an inlier."""
        return self.inliers.astype(np.uint8).reshape(-1, 1)

    def __iter__(self) -> Iterator[np.ndarray]:
        """``F, mask``, the order of ``cv2.findFundamentalMat``'s result."""
        return iter((self.F, self.mask))


def _fit(
    model: FundamentalModel, d: np.ndarray, method: str, threshold: float, kw: dict
) -> FundamentalFit:
    from robopercept.estimation.ransac import ransac

    if method == "8point":
        F = model.result(model.fit(d))
        r = model.residuals(F.reshape(1, 9), d)[0]
        return FundamentalFit(F, np.ones(len(d), dtype=bool), 1, r)
    if method != "ransac":
        raise InputError(f"method must be 'ransac' or '8point'; got {method!r}")
    if len(d) < 8:
        raise DegenerateError(f"F needs 8 correspondences; got {len(d)}")
    res = ransac(d, model, threshold, **kw)
    F = np.asarray(res.model, dtype=np.float64).reshape(3, 3)
    r = model.residuals(F.reshape(1, 9), d)[0]
    return FundamentalFit(F, np.asarray(res.inliers), int(res.n_iterations), r)


def find_fundamental(
    x1: npt.ArrayLike,
    x2: npt.ArrayLike,
    *,
    method: str = "ransac",
    threshold: float = 1.0,
    probability: float = 0.99,
    max_iterations: int = 2000,
    rng: int | np.random.Generator | None = None,
) -> FundamentalFit:
    """Fundamental matrix from pixel correspondences (``cv2.findFundamentalMat``).

    ``method="8point"`` fits all correspondences by the normalized eight-point
    algorithm; ``"ransac"`` runs :func:`robopercept.estimation.ransac` with
    :class:`FundamentalModel` (Sampson distance below ``threshold`` pixels is an
    inlier), then refits on the inliers.

    Parameters
    ----------
    x1, x2 : (N, 2) or (N, 1, 2) array_like
        Corresponding pixels (OpenCV's ``(N, 1, 2)`` point vectors too).
    method : {"ransac", "8point"}
        ``cv2.FM_RANSAC`` or ``cv2.FM_8POINT``.
    threshold : float
        Inlier threshold on the Sampson distance, pixels.
    probability : float
        Confidence of RANSAC's adaptive stopping rule.
    max_iterations : int
        Upper bound on RANSAC samples.
    rng : int, Generator or None
        RANSAC's seed.

    Returns
    -------
    FundamentalFit
        Unpacks as ``F, mask`` in the order of ``cv2.findFundamentalMat``.

    Raises
    ------
    DegenerateError
        Fewer than 8 correspondences, or collinear points.
    InputError
        Points that are not finite (N, 2) arrays of one shape, or a bad parameter.

    Examples
    --------
    >>> g = np.random.default_rng(0)
    >>> X = g.uniform(-1, 1, (20, 3)) + [0, 0, 5]
    >>> x1 = X[:, :2] / X[:, 2:]
    >>> x2 = (X[:, :2] + [0.5, 0.0]) / X[:, 2:]
    >>> F, mask = find_fundamental(x1, x2, method="8point")
    >>> F.shape, mask.shape, mask.dtype.name
    ((3, 3), (20, 1), 'uint8')
    """
    p1, p2 = _pairs(x1, x2)
    kw = {"probability": probability, "max_iterations": max_iterations, "rng": rng}
    return _fit(FundamentalModel(), np.c_[p1, p2], method, threshold, kw)


def find_essential(
    x1: npt.ArrayLike,
    x2: npt.ArrayLike,
    K: npt.ArrayLike,
    *,
    method: str = "ransac",
    threshold: float = 1.0,
    probability: float = 0.99,
    max_iterations: int = 2000,
    rng: int | np.random.Generator | None = None,
) -> FundamentalFit:
    """Essential matrix from pixel correspondences of one calibrated camera ``K``
    (eight-point on :math:`K^{-1} x`; ``threshold`` in pixels, divided by the focal
    length for the normalized residual, as ``cv2.findEssentialMat`` does).

    Parameters
    ----------
    x1, x2 : (N, 2) or (N, 1, 2) array_like
        Corresponding pixels (OpenCV's ``(N, 1, 2)`` point vectors too).
    K : (3, 3) array_like
        Camera matrix with positive focal lengths.
    method, threshold, probability, max_iterations, rng
        As :func:`find_fundamental`.

    Returns
    -------
    FundamentalFit
        ``F`` holds E (unit Frobenius norm, singular values (1, 1, 0) up to scale);
        unpacks as ``E, mask`` in the order of ``cv2.findEssentialMat``.

    Raises
    ------
    DegenerateError
        Fewer than 8 correspondences, or collinear points.
    InputError
        Points that are not finite (N, 2) arrays of one shape, a bad ``K``, or a bad
        parameter.
    """
    k = check_matrix3(K, "K", invertible=True)
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        raise InputError(
            f"K must have positive focal lengths K[0, 0], K[1, 1]; got {k.tolist()}: a "
            "camera matrix is [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
        )
    threshold = check_real(threshold, "threshold", 0.0, low_inclusive=False)
    p1, p2 = _pairs(x1, x2)
    kinv = np.linalg.inv(k)
    n1 = p1 @ kinv[:2, :2].T + kinv[:2, 2]
    n2 = p2 @ kinv[:2, :2].T + kinv[:2, 2]
    f = (k[0, 0] + k[1, 1]) / 2.0
    kw = {"probability": probability, "max_iterations": max_iterations, "rng": rng}
    return _fit(EssentialModel(), np.c_[n1, n2], method, threshold / f, kw)


def epipolar_lines(F: npt.ArrayLike, points: npt.ArrayLike, which: int = 1) -> np.ndarray:
    r"""Epipolar lines ``(N, 3)`` :math:`(a, b, c)` with :math:`a^2 + b^2 = 1`
    (``cv2.computeCorrespondEpilines``).

    ``which=1``: ``points`` are in the first image and the lines :math:`F x_1` in the
    second; ``which=2``: points in the second image, lines :math:`F^T x_2` in the first.
    A point :math:`(x, y)` lies on the line when :math:`a x + b y + c = 0`, and
    :math:`|a x + b y + c|` is its distance to the line in pixels.
    """
    Fm = check_matrix3(F, "F")
    p = _points(points, "points")
    if which not in (1, 2):
        raise InputError(f"which must be 1 (points in image 1) or 2; got {which!r}")
    h = np.c_[p, np.ones(len(p))]
    lines = h @ (Fm.T if which == 1 else Fm)
    n = np.hypot(lines[:, 0], lines[:, 1])
    return lines / np.where(n > 0, n, 1.0)[:, None]


def epipoles(F: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    r"""The epipoles :math:`e_1` (:math:`F e_1 = 0`, in image 1) and :math:`e_2`
    (:math:`F^T e_2 = 0`, in image 2) as homogeneous unit 3-vectors; divide by the last
    entry for pixels (it is 0 for an epipole at infinity, e.g. a sideways motion)."""
    Fm = check_matrix3(F, "F")
    u, _, vt = np.linalg.svd(Fm)
    e1, e2 = vt[-1], u[:, -1]
    for e in (e1, e2):
        if e[2] < 0:
            e *= -1.0
    return e1, e2


@dataclass(frozen=True)
class RelativePose:
    """Result of :func:`decompose_essential`.

    It unpacks as the tuple of ``retval, R, t, mask = cv2.recoverPose(E, x1, x2, K)``:
    ``n, R, t, mask = decompose_essential(E, x1, x2, K)`` gives ``n`` (int) the number
    of correspondences in front of both cameras, ``R`` (3, 3), ``t`` (3, 1) (OpenCV's
    column) and ``mask`` (N, 1) uint8, 255 for a correspondence in front of both
    cameras and 0 for the rest (the values ``cv2.recoverPose`` gives when no input mask
    is passed). The attributes stay the primary interface (``t`` there is (3,)).

    Attributes
    ----------
    R : (3, 3) ndarray
    t : (3,) ndarray
        Unit vector: :math:`X_2 = R X_1 + t` up to the scale of t.
    in_front : (N,) bool ndarray
        Correspondences triangulated in front of both cameras with this (R, t).
    candidates : int
        How many of the four (R, t) had the most points in front (1 unless ambiguous).
    """

    R: np.ndarray
    t: np.ndarray
    in_front: np.ndarray
    candidates: int

    def __iter__(self) -> Iterator[int | np.ndarray]:
        """``retval, R, t, mask``, the order of ``cv2.recoverPose``'s result."""
        mask = np.where(self.in_front, 255, 0).astype(np.uint8).reshape(-1, 1)
        n = int(np.count_nonzero(self.in_front))
        return iter((n, self.R, np.asarray(self.t).reshape(3, 1), mask))


def decompose_essential(
    E: npt.ArrayLike, x1: npt.ArrayLike, x2: npt.ArrayLike, K: npt.ArrayLike | None = None
) -> RelativePose:
    r"""Relative pose from an essential matrix by the cheirality test.

    With :math:`E = U \operatorname{diag}(1, 1, 0) V^T` (signs fixed so that U and V are
    rotations) and :math:`W = \begin{pmatrix} 0&-1&0\\1&0&0\\0&0&1 \end{pmatrix}`, the
    four candidates are :math:`R \in \{U W V^T, U W^T V^T\}`, :math:`t = \pm u_3`.
    Each is used to triangulate the correspondences; the one that puts most points in
    front of both cameras (positive depth) is the motion (``cv2.recoverPose``).

    Parameters
    ----------
    E : (3, 3) array_like
    x1, x2 : (N, 2) or (N, 1, 2) array_like
        Correspondences in pixels (with ``K``) or normalized coordinates (without);
        OpenCV's ``(N, 1, 2)`` point vectors too.
    K : (3, 3) array_like, optional

    Returns
    -------
    RelativePose
        Unpacks as ``retval, R, t, mask`` in the order of ``cv2.recoverPose``.

    Raises
    ------
    DegenerateError
        No correspondence lies in front of both cameras for any candidate.
    """
    from robopercept.geometry.triangulation import triangulate

    e = check_matrix3(E, "E")
    p1, p2 = _pairs(x1, x2)
    if K is not None:
        kinv = np.linalg.inv(check_matrix3(K, "K", invertible=True))
        p1 = p1 @ kinv[:2, :2].T + kinv[:2, 2]
        p2 = p2 @ kinv[:2, :2].T + kinv[:2, 2]
    U, sv, Vt = np.linalg.svd(e)
    if not sv[0] > 0 or sv[1] <= 1e-9 * sv[0]:
        raise DegenerateError(
            f"E must have two non-zero singular values (rank 2); got {sv.tolist()}"
        )
    if np.linalg.det(U) < 0:
        U = -U
    if np.linalg.det(Vt) < 0:
        Vt = -Vt
    W = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    P1 = np.c_[np.eye(3), np.zeros(3)]
    best: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
    for R in (U @ W @ Vt, U @ W.T @ Vt):
        for t in (U[:, 2], -U[:, 2]):
            X = triangulate(P1, np.c_[R, t], p1, p2)
            z1 = X[:, 2]
            z2 = X @ R[2] + t[2]
            front = (z1 > 0) & (z2 > 0) & np.isfinite(X).all(axis=1)
            best.append((int(front.sum()), R, t, front))
    counts = np.array([b[0] for b in best])
    if counts.max() == 0:
        raise DegenerateError(
            "no correspondence lies in front of both cameras for any of the four poses: "
            "check that x1 and x2 are not swapped and that E belongs to them"
        )
    k = int(np.argmax(counts))
    n, R, t, front = best[k]
    return RelativePose(R, t / np.linalg.norm(t), front, int((counts == n).sum()))
