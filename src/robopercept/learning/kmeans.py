r"""k-means clustering (Lloyd's algorithm with k-means++ seeding).

k-means looks for :math:`k` centres :math:`\mu_j` minimizing the inertia

.. math::

    J = \sum_i \min_j \lVert x_i - \mu_j \rVert^2 .

Lloyd's algorithm alternates the two steps that each lower :math:`J`: assign every
sample to its nearest centre, then move every centre to the mean of its samples. It
stops when the assignment no longer changes, when the centres moved by less than
``tol`` (in total squared distance, relative to the mean feature variance), or after
``max_iter`` rounds; the result is a local minimum, so ``n_init`` seedings are tried
and the lowest inertia kept.

k-means++ (Arthur and Vassilvitskii, 2007) seeds the first centre at a random sample
and each next one at a sample drawn with probability proportional to its squared
distance :math:`D(x)^2` to the nearest centre chosen so far; the greedy variant tries
:math:`2 + \lfloor \ln k \rfloor` candidates per step and keeps the one that lowers
the potential :math:`\sum_x D(x)^2` most. A cluster left empty is moved to the sample
farthest from its centre.

The loop, the stopping rules and the greedy seeding are those of
``sklearn.cluster.KMeans(algorithm="lloyd")``: with the same initial centres both give
the same labels and inertia.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
)
from robopercept.errors import InputError
from robopercept.learning._base import (
    ClusterMixin,
    Estimator,
    RandomStateLike,
    TransformerMixin,
    check_matrix,
    check_option,
    renamed_rng,
    seed_from,
)

__all__ = ["MAX_LOCAL_TRIALS", "MAX_N_INIT", "KMeans", "kmeans_plusplus"]

#: most k-means++ candidates per centre (scikit-learn's default is 2 + ln k)
MAX_LOCAL_TRIALS = 1000
#: most seedings KMeans tries (each one a full run)
MAX_N_INIT = 1000

_CHUNK = 8192


def _sq_dist(X: np.ndarray, C: np.ndarray, x_sq: np.ndarray) -> np.ndarray:
    """Squared distances ``(len(X), len(C))`` by :math:`|x|^2 - 2 x\\cdot c + |c|^2`."""
    d = x_sq[:, None] - 2.0 * (X @ C.T) + np.einsum("ij,ij->i", C, C)[None, :]
    return np.maximum(d, 0.0, out=d)


def _assign(X: np.ndarray, C: np.ndarray, x_sq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest centre and its squared distance for every sample, in bounded chunks."""
    n = X.shape[0]
    labels = np.empty(n, dtype=np.int64)
    dist = np.empty(n)
    c_sq = np.einsum("ij,ij->i", C, C)
    for s in range(0, n, _CHUNK):
        e = min(s + _CHUNK, n)
        d = c_sq[None, :] - 2.0 * (X[s:e] @ C.T)
        lab = np.argmin(d, axis=1)
        labels[s:e] = lab
        dist[s:e] = np.maximum(d[np.arange(e - s), lab] + x_sq[s:e], 0.0)
    return labels, dist


@njit(cache=True, nogil=True)
def _nearest_sums(dots, c_sq, x_sq, X, labels, dist, sums, counts):  # pragma: no cover
    # one pass over a chunk: nearest centre (the first of equals, as argmin), its
    # squared distance |x|^2 - 2 x.c + |c|^2, and the per-cluster sums and counts
    n, k = dots.shape
    d = X.shape[1]
    for i in range(n):
        best = 0
        bd = c_sq[0] - 2.0 * dots[i, 0]
        for j in range(1, k):
            v = c_sq[j] - 2.0 * dots[i, j]
            if v < bd:
                bd = v
                best = j
        labels[i] = best
        dist[i] = max(bd + x_sq[i], 0.0)
        counts[best] += 1.0
        for t in range(d):
            sums[best, t] += X[i, t]


def _assign_sums(
    X: np.ndarray, C: np.ndarray, x_sq: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One Lloyd pass: labels, squared distances, per-cluster sums and counts (the
    distances' cross terms by BLAS in chunks, the rest fused in one compiled loop)."""
    n, k = X.shape[0], C.shape[0]
    labels = np.empty(n, dtype=np.int64)
    dist = np.empty(n)
    sums = np.zeros((k, X.shape[1]))
    counts = np.zeros(k)
    c_sq = np.einsum("ij,ij->i", C, C)
    for s in range(0, n, _CHUNK):
        e = min(s + _CHUNK, n)
        _nearest_sums(X[s:e] @ C.T, c_sq, x_sq[s:e], X[s:e], labels[s:e], dist[s:e], sums,
                      counts)  # fmt: skip
    return labels, dist, sums, counts


def kmeans_plusplus(
    X: npt.ArrayLike,
    n_clusters: int,
    *,
    random_state: RandomStateLike = None,
    n_local_trials: int | None = None,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Greedy k-means++ seeding: ``(n_clusters, d)`` initial centres drawn from ``X``.

    Parameters
    ----------
    X : (N, d) array_like
    n_clusters : int
    random_state : int, Generator, RandomState or None
        Seed (scikit-learn's name); a Generator is not consumed.
    n_local_trials : int, optional
        Candidates tried per centre (default ``2 + ln k``, scikit-learn's).
    rng
        Deprecated alias of ``random_state`` (one release).

    Returns
    -------
    (n_clusters, d) ndarray
    """
    random_state = renamed_rng("kmeans_plusplus", random_state, rng)
    X = check_magnitude(check_matrix(X, "X"), "X", 1e150)  # squared distances
    k = check_int(n_clusters, "n_clusters", 1)
    if k > X.shape[0]:
        raise InputError(f"n_clusters={k} is more than the {X.shape[0]} samples: lower n_clusters")
    if n_local_trials is not None:
        n_local_trials = check_int(n_local_trials, "n_local_trials", 1)
        if n_local_trials > MAX_LOCAL_TRIALS:
            raise InputError(
                f"n_local_trials must be in 1..{MAX_LOCAL_TRIALS} (each trial is a row of "
                f"N distances); got {n_local_trials}"
            )
    return _plusplus(X, k, seed_from(random_state), n_local_trials)


def _plusplus(
    X: np.ndarray, n_clusters: int, gen: np.random.Generator, n_local_trials: int | None
) -> np.ndarray:
    # kmeans_plusplus drawing from (and advancing) gen, so that KMeans' n_init runs
    # each get their own seeding
    n = X.shape[0]
    trials = n_local_trials if n_local_trials is not None else 2 + int(np.log(n_clusters))
    x_sq = np.einsum("ij,ij->i", X, X)
    centers = np.empty((n_clusters, X.shape[1]))
    first = gen.choice(n)
    centers[0] = X[first]
    closest = np.maximum(x_sq - 2 * X @ X[first] + x_sq[first], 0.0)
    potential = closest.sum()
    for c in range(1, n_clusters):
        draws = gen.uniform(size=trials) * potential
        cand = np.minimum(np.searchsorted(np.cumsum(closest), draws), n - 1)
        d = np.maximum(x_sq[cand][:, None] - 2.0 * X[cand] @ X.T + x_sq[None, :], 0.0)
        np.minimum(closest, d, out=d)
        pots = d.sum(axis=1)
        best = int(np.argmin(pots))
        potential, closest = pots[best], d[best]
        centers[c] = X[cand[best]]
    return centers


class KMeans(ClusterMixin, TransformerMixin, Estimator):
    """k-means clustering.

    Parameters
    ----------
    n_clusters : int
    init : {"k-means++", "random"} or (n_clusters, d) array
        Seeding: greedy k-means++, ``n_clusters`` distinct random samples, or given
        centres (then a single run).
    n_init : int or "auto"
        Seedings tried; ``"auto"``: 1 for k-means++ and given centres, 10 for random.
    max_iter : int
    tol : float
        Convergence when the centres' total squared shift is at most
        ``tol * mean(var(X, axis=0))``.
    random_state : int, Generator, RandomState or None
        Seed of the seedings (scikit-learn's name); the same seed gives the same
        clustering.
    rng : int, Generator or None
        Deprecated alias of ``random_state`` (one release): ``fit`` warns and uses it.

    Attributes
    ----------
    cluster_centers_ : (k, d) ndarray
    labels_ : (N,) ndarray
    inertia_ : float
        Sum of squared distances of the samples to their centres.
    n_iter_ : int

    Examples
    --------
    Two well separated blobs:

    >>> X = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1], [5.0, 5.0], [5.1, 5.0], [5.0, 5.1]])
    >>> km = KMeans(2, random_state=0).fit(X)
    >>> (km.labels_ == km.labels_[0]).tolist()
    [True, True, True, False, False, False]
    >>> np.round(np.sort(km.cluster_centers_[:, 0]), 3).tolist()
    [0.033, 5.033]
    """

    def __init__(
        self,
        n_clusters: int = 8,
        *,
        init: str | np.ndarray = "k-means++",
        n_init: int | str = "auto",
        max_iter: int = 300,
        tol: float = 1e-4,
        random_state: RandomStateLike = None,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        self.n_clusters = n_clusters
        self.init = init
        self.n_init = n_init
        self.max_iter = max_iter
        self.tol = tol
        self.random_state = random_state
        self.rng = rng

    def _seeds(self, X: np.ndarray) -> tuple[list[np.ndarray] | None, int]:
        k = check_int(self.n_clusters, "n_clusters", 1)
        if k > X.shape[0]:
            raise InputError(
                f"n_clusters={k} is more than the {X.shape[0]} samples; lower n_clusters"
            )
        if isinstance(self.init, str):
            check_option(self.init, "init", ("k-means++", "random"))
            if isinstance(self.n_init, str) and self.n_init == "auto":
                runs = 1 if self.init == "k-means++" else 10
            else:
                runs = check_int(self.n_init, "n_init (or 'auto')", 1)
                if runs > MAX_N_INIT:
                    raise InputError(f"n_init must be in 1..{MAX_N_INIT} or 'auto'; got {runs}")
            return None, runs
        C = check_numeric(self.init, "init")
        if C.shape != (k, X.shape[1]):
            raise InputError(f"init centres must have shape ({k}, {X.shape[1]}); got {C.shape}")
        if not np.isfinite(C).all():
            raise InputError("init centres must be finite")
        check_magnitude(C, "init", 1e150)
        return [C.copy()], 1

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> KMeans:
        """Cluster ``X`` (N, d); keeps the best of ``n_init`` runs."""
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150, smallest=1e-150)
        check_int(self.max_iter, "max_iter", 1)
        check_real(self.tol, "tol", 0.0)
        given, runs = self._seeds(X)
        gen = seed_from(self._random_state())
        # centred data give more accurate |x|^2 - 2 x.c + |c|^2 distances (as sklearn)
        offset: npt.NDArray[np.float64] = X.mean(axis=0)
        X = X - offset
        x_sq = np.einsum("ij,ij->i", X, X)
        tol = float(np.mean(np.var(X, axis=0))) * float(self.tol)
        best: tuple | None = None
        k = int(self.n_clusters)
        for _ in range(runs):
            if given is not None:
                C = given[0] - offset
            elif self.init == "k-means++":
                C = _plusplus(X, k, gen, None)
            else:
                C = X[gen.choice(X.shape[0], size=k, replace=False)].copy()
            labels, centers, inertia, n_iter = self._lloyd(X, C, x_sq, tol)
            if best is None or inertia < best[2]:
                best = (labels, centers, inertia, n_iter)
        assert best is not None
        self.labels_, centers, self.inertia_, self.n_iter_ = best
        self.cluster_centers_ = centers + offset
        self.inertia_ = float(self.inertia_)
        return self

    def _lloyd(
        self, X: np.ndarray, centers: np.ndarray, x_sq: np.ndarray, tol: float
    ) -> tuple[np.ndarray, np.ndarray, float, int]:
        labels_old = np.full(X.shape[0], -1)
        n_iter = 0
        for n_iter in range(1, int(self.max_iter) + 1):  # noqa: B007 (read after the loop)
            labels, dist, sums, counts = _assign_sums(X, centers, x_sq)
            new = self._means(X, labels, dist, sums, counts)
            shift = float(np.sum((new - centers) ** 2))
            centers = new
            if np.array_equal(labels, labels_old):
                break
            if shift <= tol:
                break
            labels_old = labels
        # the final assignment to the final centres (unchanged if the labels converged)
        labels, dist = _assign(X, centers, x_sq)
        return labels, centers, float(dist.sum()), n_iter

    @staticmethod
    def _means(
        X: np.ndarray, labels: np.ndarray, dist: np.ndarray, sums: np.ndarray, counts: np.ndarray
    ) -> np.ndarray:
        empty = np.flatnonzero(counts == 0)
        if empty.size:  # move each empty cluster to one of the farthest samples
            far = np.argsort(dist, kind="stable")[::-1][: empty.size]
            for j, i in zip(empty, far, strict=False):
                old = labels[i]
                sums[old] -= X[i]
                counts[old] -= 1
                sums[j] = X[i]
                counts[j] = 1
        return sums / counts[:, None]

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Index of the nearest centre for every sample."""
        self._check_fitted("cluster_centers_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        return _assign(X, self.cluster_centers_, np.einsum("ij,ij->i", X, X))[0]

    def transform(self, X: npt.ArrayLike) -> np.ndarray:
        """Euclidean distance of every sample to every centre, ``(N, k)``."""
        self._check_fitted("cluster_centers_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        return np.sqrt(_sq_dist(X, self.cluster_centers_, np.einsum("ij,ij->i", X, X)))

    def score(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> float:
        """Minus the inertia of ``X`` with the fitted centres (higher is better)."""
        self._check_fitted("cluster_centers_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        return -float(_assign(X, self.cluster_centers_, np.einsum("ij,ij->i", X, X))[1].sum())
