r"""Models for the RANSAC engine: 2-D line, plane, 2-D affine map, homography.

Every model satisfies the :class:`Model` protocol (its docstring is the contract): it
works on a data matrix with one row per observation and implements

``fit_minimal(samples)``
    ``(B, n, D)`` minimal samples -> ``(B, P)`` parameters and a ``(B,)`` validity mask;
    degenerate samples (coincident or collinear points) are marked invalid, never fitted.
``fit(data)``
    least-squares parameters from all rows (raises :class:`DegenerateError`; the models
    here also refuse data that is not a finite ``(N, dim)`` array within 1e150 with
    :class:`InputError`).
``residuals(params, data)``
    ``(B, P)`` hypotheses and ``(N, D)`` data -> ``(B, N)`` non-negative errors, all
    hypotheses at once.
``check(data)``
    raises :class:`DegenerateError` when no sample of ``data`` can be non-degenerate.
``result(params)``
    the typed result (:class:`Line`, :class:`Plane`, a 3x3 matrix).

Correspondence models (affine, homography) take rows ``(x, y, x', y')`` and their residual
is the transfer error :math:`\|H(x, y) - (x', y')\|`.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np
from numba import njit, prange

from robopercept._checks import check_magnitude, check_points
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.least_squares import (
    MAX_COORDINATE,
    Line,
    Plane,
    fit_line,
    fit_plane,
    fit_plane_from_scatter,
    scatter_matrix,
)

__all__ = [
    "AffineModel",
    "HomographyModel",
    "LineModel",
    "Model",
    "PlaneModel",
    "hartley_normalization",
    "homography_dlt",
]

_EPS = 1e-12
_CHUNK = 1 << 17  # rows per scoring chunk: B x 131072 float64 residuals at a time


_BLOCK = 2048  # points per scoring block: 48 KiB of x, y, z, read once for all hypotheses


@njit(cache=True, nogil=True, parallel=True)
def _plane_score_kernel(params, x, y, z, threshold, msac, counts, loss):  # pragma: no cover
    """Inlier counts and MSAC losses of plane hypotheses over coordinate arrays.

    The points go in blocks small enough to stay in cache while every hypothesis is
    scored on them (memory is read once per batch, not once per hypothesis); blocks run
    in parallel, and their partial sums are added in block order, so the result does not
    depend on the number of threads.
    """
    n = x.shape[0]
    nh = params.shape[0]
    nb = (n + _BLOCK - 1) // _BLOCK
    part_c = np.zeros((nb, nh), dtype=np.int64)
    part_l = np.zeros((nb, nh))
    t2 = threshold * threshold
    for blk in prange(nb):
        lo = blk * _BLOCK
        m = min(n - lo, _BLOCK)
        xs = x[lo : lo + m]
        ys = y[lo : lo + m]
        zs = z[lo : lo + m]
        for h in range(nh):
            a = params[h, 0]
            b = params[h, 1]
            c = params[h, 2]
            d = params[h, 3]
            cnt = 0
            acc = 0.0
            if msac:
                for i in range(m):
                    r = abs(a * xs[i] + b * ys[i] + c * zs[i] + d)
                    inside = r < threshold
                    cnt += inside
                    acc += r * r if inside else t2
            else:
                for i in range(m):
                    cnt += abs(a * xs[i] + b * ys[i] + c * zs[i] + d) < threshold
            part_c[blk, h] = cnt
            part_l[blk, h] = acc
    for h in range(nh):
        cnt = 0
        acc = 0.0
        for blk in range(nb):
            cnt += part_c[blk, h]
            acc += part_l[blk, h]
        counts[h] = cnt
        loss[h] = acc


@njit(cache=True, nogil=True, parallel=True)
def _plane_mask_kernel(params, x, y, z, threshold, mask):  # pragma: no cover - compiled
    a, b, c, d = params[0], params[1], params[2], params[3]
    for i in prange(x.shape[0]):
        mask[i] = abs(a * x[i] + b * y[i] + c * z[i] + d) < threshold


ResultT_co = TypeVar("ResultT_co", covariant=True)
"""The type of a model's typed result (:class:`Line`, :class:`Plane`, a 3x3 ndarray)."""


@runtime_checkable
class Model(Protocol[ResultT_co]):
    r"""The interface the RANSAC engine uses: a ``typing.Protocol``, generic over the
    type of :meth:`result`.

    Any object with these attributes and methods is a model (``isinstance(obj, Model)``
    checks that they are present, not their signatures); subclassing ``Model``
    explicitly (``class LineModel(Model[Line])``) also inherits the default
    :meth:`fit_inliers`, :meth:`prepare`, :meth:`score` and :meth:`inlier_mask`, which go
    through :meth:`residuals`. Arrays are float64. ``P`` is the number of parameters of
    one hypothesis (3 for a line, 4 for a plane, 6 affine, 9 homography and F), ``D`` the
    number of columns of the data (:attr:`dim`).

    Attributes
    ----------
    sample_size : int
        Rows in a minimal sample ``n`` (2 for a line, 3 for a plane or an affine map, 4
        for a homography, 8 for F); also the ``n`` of the stopping rule
        :math:`\log(1 - p) / \log(1 - w^n)`.
    dim : int
        Columns ``D`` of a data row (2 for 2-D points, 3 for 3-D points, 4 for a
        correspondence ``(x, y, x', y')``).
    name : str
        What the model is called in error messages (``"plane"``).
    """

    sample_size: ClassVar[int]
    dim: ClassVar[int]
    name: ClassVar[str]

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One hypothesis per minimal sample, all samples at once.

        Parameters
        ----------
        samples : (B, sample_size, D) float ndarray
            ``B`` minimal samples of rows of the data.

        Returns
        -------
        params : (B, P) float ndarray
            The hypothesis of each sample; rows where ``valid`` is False hold any finite
            placeholder.
        valid : (B,) bool ndarray
            False for a degenerate sample (repeated, coincident or collinear points, a
            singular system); never raises for degeneracy. The engine also drops rows
            of ``params`` that are not finite.
        """
        raise NotImplementedError

    def fit(self, data: np.ndarray) -> np.ndarray:
        """Least-squares parameters from all rows (``n >= sample_size``).

        Parameters
        ----------
        data : (n, D) float ndarray

        Returns
        -------
        (P,) float ndarray
            The same parameter form as :meth:`fit_minimal`'s rows.

        Raises
        ------
        DegenerateError
            When the rows cannot determine the model (too few, coincident, collinear);
            the engine then keeps its previous hypothesis.
        """
        raise NotImplementedError

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        """Errors of every row under every hypothesis.

        Parameters
        ----------
        params : (B, P) float ndarray
        data : (N, D) float ndarray

        Returns
        -------
        (B, N) float ndarray
            Non-negative, in the units of the data (orthogonal distance for a line or a
            plane, transfer error in pixels for affine maps and homographies, Sampson
            distance for F), comparable to the engine's ``threshold``; ``inf`` marks a
            row that can never be an inlier. A row is an inlier when its residual is
            strictly below ``threshold``.
        """
        raise NotImplementedError

    def check(self, data: np.ndarray) -> None:
        """Raise :class:`DegenerateError` if ``data`` (N, D) cannot determine the model
        (every sample would be degenerate, e.g. all points collinear for a plane); the
        engine calls it once, before sampling. The default accepts any data."""
        return None

    def result(self, params: np.ndarray) -> ResultT_co:
        """The typed result of ``params`` (P,): :class:`Line`, :class:`Plane`, a (3, 3)
        ndarray; it becomes :attr:`RansacResult.model`. The default returns ``params``
        itself (right for a ``Model[np.ndarray]`` only: override it)."""
        return params  # type: ignore[return-value]

    def fit_inliers(self, data: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """Least-squares parameters (P,) from the rows of ``data`` (N, D) where ``mask``
        (N,) is True; raises :class:`DegenerateError` as :meth:`fit` does. The default:
        ``fit(data[mask])``."""
        return self.fit(data[mask])

    # scoring hooks: the engine calls prepare() once, then score()/inlier_mask(); the
    # defaults go through residuals() in chunks of rows, a model may override them
    def prepare(self, data: np.ndarray) -> Any:
        """Data (N, D) in the layout :meth:`score` and :meth:`inlier_mask` read, computed
        once per :func:`ransac` call; opaque to the engine (the default: ``data``
        itself; :class:`PlaneModel`: contiguous x, y, z columns)."""
        return data

    def score(
        self, params: np.ndarray, prepared: Any, threshold: float, msac: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Score ``B`` hypotheses ``params`` (B, P) on the ``prepared`` data.

        Returns
        -------
        scores : (B,) float ndarray
            HIGHER IS BETTER; the engine keeps the maximum. Without ``msac``, the inlier
            count :math:`|\{i : r_i < t\}|` as a float; with ``msac``, MINUS the
            truncated squared loss, :math:`-\sum_i \min(r_i^2, t^2)` (<= 0, 0 is a
            perfect fit), ``t`` being ``threshold``.
        counts : (B,) int64 ndarray
            Inlier counts :math:`|\{i : r_i < t\}|` (the engine breaks ties of
            ``scores`` with them and feeds the best one to the stopping rule).
        """
        data = prepared
        b = params.shape[0]
        counts = np.zeros(b, dtype=np.int64)
        loss = np.zeros(b)
        t2 = threshold * threshold
        for start in range(0, data.shape[0], _CHUNK):
            r = self.residuals(params, data[start : start + _CHUNK])
            counts += np.count_nonzero(r < threshold, axis=1)
            if msac:
                np.square(r, out=r)
                np.minimum(r, t2, out=r)
                loss += r.sum(axis=1)
        return (-loss if msac else counts.astype(np.float64)), counts

    def inlier_mask(self, params: np.ndarray, prepared: Any, threshold: float) -> np.ndarray:
        """(N,) bool: residual of the single hypothesis ``params`` (P,) strictly below
        ``threshold``, on the ``prepared`` data."""
        data = prepared
        mask = np.empty(data.shape[0], dtype=bool)
        for start in range(0, data.shape[0], _CHUNK):
            stop = start + _CHUNK
            mask[start:stop] = self.residuals(params[None], data[start:stop])[0] < threshold
        return mask


def _fit_data(data: np.ndarray, model: Model[Any]) -> np.ndarray:
    """``data`` of a public :meth:`Model.fit` call as a finite float64 ``(n, dim)`` array
    with at least ``sample_size`` rows and values within 1e150 (their squares, which the
    normal equations and Hartley's normalization form, stay finite)."""
    x = check_points(data, "data", model.dim)
    if not np.isfinite(x).all():
        raise InputError(
            "data must be finite; drop NaN/inf rows first: data[np.isfinite(data).all(1)]"
        )
    check_magnitude(x, "data", MAX_COORDINATE)
    if x.shape[0] < model.sample_size:
        raise DegenerateError(
            f"a {model.name} needs {model.sample_size} rows (points or correspondences); "
            f"got {x.shape[0]}"
        )
    return x


def _scale(points: np.ndarray) -> float:
    return max(float(np.abs(points).max()) if points.size else 0.0, 1.0)


class LineModel(Model[Line]):
    r"""2-D line :math:`a x + b y + c = 0`, :math:`a^2 + b^2 = 1`; data ``(N, 2)``.

    Minimal sample: 2 distinct points, normal :math:`\perp (p_1 - p_0)`. Residual: the
    orthogonal distance. Least squares: total least squares (:func:`fit_line`).
    """

    sample_size = 2
    dim = 2
    name = "line"

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = samples[:, 1] - samples[:, 0]
        length = np.hypot(d[:, 0], d[:, 1])
        valid = length > _EPS * _scale(samples)
        n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.where(valid, length, 1.0)[:, None]
        c = -(n * samples[:, 0]).sum(axis=1)
        return np.column_stack([n, c]), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        return fit_line(_fit_data(data, self)).line.coefficients

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        return np.abs(params[:, :2] @ data.T + params[:, 2:3])

    def check(self, data: np.ndarray) -> None:
        if np.ptp(data, axis=0).max() == 0.0:
            raise DegenerateError("all points are the same point: no line is determined")

    def result(self, params: np.ndarray) -> Line:
        return Line(np.asarray(params, dtype=np.float64))


class PlaneModel(Model[Plane]):
    r"""Plane :math:`n^\top x + d = 0`, :math:`\|n\| = 1`; data ``(N, 3)``.

    Minimal sample: 3 non-collinear points, :math:`n \propto (p_1 - p_0) \times
    (p_2 - p_0)`. Residual: the orthogonal distance :math:`|n^\top x + d|`. Least squares:
    total least squares (:func:`fit_plane`).
    """

    sample_size = 3
    dim = 3
    name = "plane"

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p0 = samples[:, 0]
        e1 = samples[:, 1] - p0
        e2 = samples[:, 2] - p0
        n = np.cross(e1, e2)
        norm = np.sqrt((n * n).sum(axis=1))
        # collinear (or repeated) points: the cross product is tiny relative to the edges
        edges = np.sqrt((e1 * e1).sum(axis=1) * (e2 * e2).sum(axis=1))
        valid = norm > 1e-9 * np.maximum(edges, _EPS)
        valid &= edges > 0
        n = n / np.where(valid, norm, 1.0)[:, None]
        d = -(n * p0).sum(axis=1)
        return np.column_stack([n, d]), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        return fit_plane(_fit_data(data, self)).plane.equation

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        r = params[:, :3] @ data.T
        r += params[:, 3:4]
        return np.abs(r, out=r)

    def fit_inliers(self, data: np.ndarray, mask: np.ndarray) -> np.ndarray:
        # the moments of the selected rows chunk by chunk: no copy of the inliers
        c, s = scatter_matrix(data, mask)
        return fit_plane_from_scatter(c, s)

    def check(self, data: np.ndarray) -> None:
        # every sample is degenerate exactly when all points lie on one line
        evals = np.linalg.eigvalsh(scatter_matrix(data)[1])
        if evals[-1] <= 0.0:
            raise DegenerateError("all points are the same point: no plane is determined")
        if evals[-2] <= 1e-12 * evals[-1]:
            raise DegenerateError("all points are collinear: no plane is determined")

    def result(self, params: np.ndarray) -> Plane:
        return Plane(np.asarray(params[:3], dtype=np.float64), float(params[3]))

    # scoring on x, y, z coordinate arrays with a compiled loop and no residual matrix:
    # cache-sized blocks of points, every hypothesis of the batch scored on a block while
    # it is in cache, blocks in parallel
    def prepare(self, data: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # the rows of one (3, N) copy: one allocation, not three (each of a few hundred
        # kB came from fresh pages, 0.45 ms for 32768 points where one copy takes 0.06)
        xyz = np.ascontiguousarray(data.T)
        return xyz[0], xyz[1], xyz[2]

    def score(
        self, params: np.ndarray, prepared: Any, threshold: float, msac: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        counts = np.zeros(params.shape[0], dtype=np.int64)
        loss = np.zeros(params.shape[0])
        p = np.ascontiguousarray(params, dtype=np.float64)
        _plane_score_kernel(p, *prepared, float(threshold), bool(msac), counts, loss)
        return (-loss if msac else counts.astype(np.float64)), counts

    def inlier_mask(self, params: np.ndarray, prepared: Any, threshold: float) -> np.ndarray:
        mask = np.empty(prepared[0].shape[0], dtype=bool)
        p = np.ascontiguousarray(params, dtype=np.float64)
        _plane_mask_kernel(p, *prepared, float(threshold), mask)
        return mask


def _triangle_area2(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Twice the signed area of triangles ``(B, 2)`` a, b, c."""
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def _apply(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map ``(N, 2)`` points by ``(B, 3, 3)`` matrices -> ``(B, N, 2)``."""
    x = h[:, :, 0:1] * xy[:, 0] + h[:, :, 1:2] * xy[:, 1] + h[:, :, 2:3]  # (B, 3, N)
    w = x[:, 2]
    w = np.where(np.abs(w) < _EPS, _EPS, w)
    return np.stack([x[:, 0] / w, x[:, 1] / w], axis=2)


class AffineModel(Model[np.ndarray]):
    r"""2-D affine map :math:`x' = A x + t` from correspondences ``(x, y, x', y')``.

    Parameters are the 6 entries of the top two rows of the 3x3 matrix. Minimal sample: 3
    correspondences whose source points are not collinear (one 6x6 linear system).
    Least squares: ``numpy.linalg.lstsq`` on all rows, as ``cv2.estimateAffine2D``'s
    refinement. Residual: transfer error.
    """

    sample_size = 3
    dim = 4
    name = "affine"

    def _design(self, src: np.ndarray) -> np.ndarray:
        return np.concatenate([src, np.ones((*src.shape[:-1], 1))], axis=-1)

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        src, dst = samples[:, :, :2], samples[:, :, 2:]
        area = np.abs(_triangle_area2(src[:, 0], src[:, 1], src[:, 2]))
        valid = area > 1e-9 * _scale(src) ** 2
        a = self._design(src)  # (B, 3, 3)
        a = np.where(valid[:, None, None], a, np.eye(3))
        m = np.linalg.solve(a, dst)  # (B, 3, 2): columns are the two output rows
        return m.transpose(0, 2, 1).reshape(-1, 6), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        data = _fit_data(data, self)
        self.check(data)
        a = self._design(data[:, :2])
        m = np.linalg.lstsq(a, data[:, 2:], rcond=None)[0]
        return m.T.reshape(6)

    def _matrices(self, params: np.ndarray) -> np.ndarray:
        h = np.zeros((params.shape[0], 3, 3))
        h[:, :2, :] = params.reshape(-1, 2, 3)
        h[:, 2, 2] = 1.0
        return h

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        m = params.reshape(-1, 2, 3)
        x = m[:, :, 0:1] * data[:, 0] + m[:, :, 1:2] * data[:, 1] + m[:, :, 2:3]
        return np.hypot(x[:, 0] - data[:, 2], x[:, 1] - data[:, 3])

    def check(self, data: np.ndarray) -> None:
        c = data[:, :2] - data[:, :2].mean(axis=0)
        evals = np.linalg.eigvalsh(c.T @ c)
        if evals[0] <= 1e-12 * max(evals[1], 1e-300):
            raise DegenerateError(
                "the source points are collinear: an affine map is not determined"
            )

    def result(self, params: np.ndarray) -> np.ndarray:
        return self._matrices(params[None])[0]


def hartley_normalization(xy: np.ndarray) -> np.ndarray:
    r"""Hartley's normalizing similarities of ``B`` point sets at once.

    For each set, :math:`T = \begin{bmatrix} s & 0 & -s c_x \\ 0 & s & -s c_y \\ 0 & 0 & 1
    \end{bmatrix}` moves the centroid :math:`c` to the origin and scales the mean
    distance to it to :math:`\sqrt 2`: :math:`s = \sqrt 2 / \bar d` (Hartley & Zisserman,
    section 4.4.4). It conditions the DLT and the eight-point algorithm. Unchecked
    (an internal building block: the caller validates its points).

    Parameters
    ----------
    xy : (B, n, 2) float64 ndarray
        ``B`` sets of ``n`` points.

    Returns
    -------
    (B, 3, 3) float64 ndarray
        One :math:`T` per set (points that coincide: :math:`\bar d` is clamped to
        :math:`10^{-12}`).

    Examples
    --------
    >>> T = hartley_normalization(np.array([[[0.0, 2.0], [2.0, 2.0]]]))  # c = (1, 2), d = 1
    >>> np.round(T[0], 4).tolist()
    [[1.4142, 0.0, -1.4142], [0.0, 1.4142, -2.8284], [0.0, 0.0, 1.0]]
    """
    c = xy.mean(axis=1)
    d = np.sqrt(((xy - c[:, None]) ** 2).sum(axis=2)).mean(axis=1)
    s = np.sqrt(2.0) / np.maximum(d, _EPS)
    t = np.zeros((xy.shape[0], 3, 3))
    t[:, 0, 0] = s
    t[:, 1, 1] = s
    t[:, 0, 2] = -s * c[:, 0]
    t[:, 1, 2] = -s * c[:, 1]
    t[:, 2, 2] = 1.0
    return t


def homography_dlt(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    r"""Normalized DLT for ``(B, n, 2)`` correspondences -> ``(B, 3, 3)`` with
    :math:`h_{33} = 1` where possible (Hartley & Zisserman, Alg. 4.2; what
    ``cv2.findHomography(src, dst, 0)`` starts from). Unchecked: ``n >= 4`` float64
    points, validated by the caller; degenerate sets give a meaningless or non-finite H.

    Each correspondence gives two rows of :math:`A h = 0`,
    :math:`[-x, -y, -1, 0, 0, 0, x' x, x' y, x'] h = 0` and
    :math:`[0, 0, 0, -x, -y, -1, y' x, y' y, y'] h = 0`; :math:`h` is the right singular
    vector of the smallest singular value, computed on Hartley-normalized points and
    mapped back: :math:`H = T'^{-1} \hat H T`.
    """
    ts, td = hartley_normalization(src), hartley_normalization(dst)
    s = src @ ts[:, :2, :2].transpose(0, 2, 1) + ts[:, None, :2, 2]
    d = dst @ td[:, :2, :2].transpose(0, 2, 1) + td[:, None, :2, 2]
    b, n = s.shape[:2]
    a = np.zeros((b, 2 * n, 9))
    x, y = s[..., 0], s[..., 1]
    u, v = d[..., 0], d[..., 1]
    a[:, 0::2, 0] = -x
    a[:, 0::2, 1] = -y
    a[:, 0::2, 2] = -1
    a[:, 0::2, 6] = u * x
    a[:, 0::2, 7] = u * y
    a[:, 0::2, 8] = u
    a[:, 1::2, 3] = -x
    a[:, 1::2, 4] = -y
    a[:, 1::2, 5] = -1
    a[:, 1::2, 6] = v * x
    a[:, 1::2, 7] = v * y
    a[:, 1::2, 8] = v
    if n == 4:  # square system padded: the null vector of the 8x9 matrix
        a = np.concatenate([a, np.zeros((b, 1, 9))], axis=1)
    _, _, vt = np.linalg.svd(a, full_matrices=False)  # 9 columns: vt is (b, 9, 9) either way
    h = vt[:, -1].reshape(b, 3, 3)
    h = np.linalg.inv(td) @ h @ ts
    scale = h[:, 2:3, 2:3]
    h = h / np.where(np.abs(scale) > _EPS, scale, 1.0)
    return h


class HomographyModel(Model[np.ndarray]):
    r"""Homography :math:`x' \sim H x` from correspondences ``(x, y, x', y')``.

    Minimal sample: 4 correspondences with no 3 source (or destination) points collinear.
    Fit: the normalized DLT (Hartley & Zisserman, Alg. 4.2), for the minimal sample and
    the least-squares refit alike; parameters are the 9 entries of H with
    :math:`h_{33} = 1`. Residual: transfer error :math:`\|\pi(H x) - x'\|`.
    """

    sample_size = 4
    dim = 4
    name = "homography"

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        src, dst = samples[:, :, :2], samples[:, :, 2:]
        valid = np.ones(samples.shape[0], dtype=bool)
        for pts in (src, dst):
            tol = 1e-9 * _scale(pts) ** 2
            for i, j, k in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)):
                valid &= np.abs(_triangle_area2(pts[:, i], pts[:, j], pts[:, k])) > tol
        h = np.tile(np.eye(3), (samples.shape[0], 1, 1))
        if valid.any():
            h[valid] = homography_dlt(src[valid], dst[valid])
        valid &= np.isfinite(h).all(axis=(1, 2))
        return h.reshape(-1, 9), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        data = _fit_data(data, self)
        self.check(data)
        return homography_dlt(data[None, :, :2], data[None, :, 2:])[0].reshape(9)

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        p = _apply(params.reshape(-1, 3, 3), data[:, :2])
        return np.hypot(p[..., 0] - data[:, 2], p[..., 1] - data[:, 3])

    def check(self, data: np.ndarray) -> None:
        for name, xy in (("source", data[:, :2]), ("destination", data[:, 2:])):
            c = xy - xy.mean(axis=0)
            evals = np.linalg.eigvalsh(c.T @ c)
            if evals[0] <= 1e-12 * max(evals[1], 1e-300):
                raise DegenerateError(
                    f"the {name} points are collinear: a homography is not determined"
                )

    def result(self, params: np.ndarray) -> np.ndarray:
        return np.asarray(params, dtype=np.float64).reshape(3, 3)
