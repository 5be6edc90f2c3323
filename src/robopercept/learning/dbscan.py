r"""DBSCAN: density-based clustering with noise (Ester et al., 1996).

A sample is a *core* point when at least ``min_samples`` samples (itself included) lie
within distance :math:`\varepsilon` of it. Core points closer than
:math:`\varepsilon` to each other are density-connected, and each connected set of core
points is a cluster. A non-core sample within :math:`\varepsilon` of a core point is a
*border* point and joins that core point's cluster; every other sample is noise,
labelled -1.

The computation never holds an :math:`N \times N` matrix nor every neighbourhood at
once: neighbour queries go to a k-d tree (``scipy.spatial.cKDTree``; above 12
dimensions, where a k-d tree degenerates, to blocks of brute-force distances) in chunks
of samples; (1) the neighbour counts mark the core points, (2) the core-core pairs of each
chunk are merged into a union-find forest, (3) every non-core sample looks for core
points within :math:`\varepsilon`. Memory is the data, the tree and one chunk's
neighbour lists.

Clusters are numbered in the order of their lowest-index core point, and a border
point reachable from several clusters joins the lowest-numbered one, which is exactly
what ``sklearn.cluster.DBSCAN``'s breadth-first expansion produces, so the labels are
identical to scikit-learn's (not only up to renaming).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import chain

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import check_bool, check_int, check_magnitude, check_real
from robopercept.imaging.blobs import uf_roots, uf_union_pairs
from robopercept.learning._base import ClusterMixin, Estimator
from robopercept.progress import progress_bar

__all__ = ["DBSCAN"]

_CHUNK = 32768
_BRUTE_DIM = 12
_BLOCK_BYTES = 64 << 20
_CACHE_BYTES = 512 << 20


@njit(cache=True)
def _brute_pairs(
    gram: np.ndarray, q_sq: np.ndarray, p_sq: np.ndarray, eps2: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs with :math:`|q|^2 - 2 q \\cdot p + |p|^2 \\le \\varepsilon^2` from the Gram block."""
    m, n = gram.shape
    total = 0
    for i in range(m):
        for j in range(n):
            if q_sq[i] - 2.0 * gram[i, j] + p_sq[j] <= eps2:
                total += 1
    rows = np.empty(total, dtype=np.int64)
    cols = np.empty(total, dtype=np.int64)
    t = 0
    for i in range(m):
        for j in range(n):
            if q_sq[i] - 2.0 * gram[i, j] + p_sq[j] <= eps2:
                rows[t] = i
                cols[t] = j
                t += 1
    return rows, cols


def _flatten(lists: Sequence[Sequence[int]] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour lists -> (row index, neighbour index) arrays."""
    lengths = np.fromiter((len(x) for x in lists), dtype=np.int64, count=len(lists))
    flat = np.fromiter(chain.from_iterable(lists), dtype=np.int64, count=int(lengths.sum()))
    rows = np.repeat(np.arange(len(lists)), lengths)
    return rows, flat


class DBSCAN(ClusterMixin, Estimator):
    """Density-based spatial clustering of applications with noise.

    Parameters
    ----------
    eps : float
        Neighbourhood radius :math:`\\varepsilon` (Euclidean; inclusive).
    min_samples : int
        Samples within ``eps`` (the sample itself counted) that make a core point.
    progress : bool
        Show a progress bar over the chunks (useful above a million samples).

    Attributes
    ----------
    labels_ : (N,) int64 ndarray
        Cluster of every sample, -1 for noise.
    core_sample_indices_ : (M,) ndarray
    n_clusters_ : int
    """

    def __init__(self, eps: float = 0.5, min_samples: int = 5, progress: bool = False) -> None:
        self.eps = eps
        self.min_samples = min_samples
        self.progress = progress

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> DBSCAN:
        """Cluster ``X`` (N, d)."""
        # squared distances (the k-d tree's too) overflow beyond 1e150
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150)
        eps = check_real(self.eps, "eps", 0.0, low_inclusive=False)
        check_bool(self.progress, "progress")
        min_samples = check_int(self.min_samples, "min_samples", 1)
        n = X.shape[0]
        search = _Neighbours(X, eps)
        step = search.chunk
        chunks = range(0, n, step)
        bar = progress_bar(
            total=3 * len(chunks), desc="dbscan", unit="block", disable=not self.progress
        )
        # pass 1: neighbour counts; the pairs are kept while they fit in the budget so
        # that passes 2 and 3 need no second query
        counts = np.empty(n, dtype=np.int64)
        cache: list[tuple[np.ndarray, np.ndarray]] | None = []
        cached = 0
        for s in chunks:
            q = X[s : s + step]
            if cache is not None:
                rows, nb = search.pairs(q)
                counts[s : s + step] = np.bincount(rows, minlength=q.shape[0])
                cached += 16 * rows.size
                cache.append((rows + s, nb))
                if cached > _CACHE_BYTES:
                    cache = None
            else:
                counts[s : s + step] = search.count(q)
            bar.update()
        is_core = counts >= min_samples
        core_idx = np.flatnonzero(is_core)
        labels = np.full(n, -1, dtype=np.int64)
        self.n_clusters_ = 0
        if core_idx.size:
            core_pos = np.cumsum(is_core) - 1  # index among the core points
            core_search = None if cache is not None else _Neighbours(X[core_idx], eps)
            # pass 2: union-find over core-core pairs
            parent = np.arange(core_idx.size, dtype=np.int64)
            if cache is not None:
                for rows, nb in cache:
                    keep = is_core[rows] & is_core[nb]
                    uf_union_pairs(parent, core_pos[rows[keep]], core_pos[nb[keep]])
                    bar.update()
            else:
                for s in range(0, core_idx.size, step):
                    rows, nb = core_search.pairs(X[core_idx[s : s + step]])
                    uf_union_pairs(parent, rows + s, nb)
                    bar.update()
            roots = uf_roots(parent)
            # roots are the lowest core index of each cluster: number them in that order
            uniq, core_label = np.unique(roots, return_inverse=True)
            labels[core_idx] = core_label
            # pass 3: a border point joins the lowest-numbered cluster among its core
            # neighbours
            other = np.flatnonzero(~is_core)
            big = np.iinfo(np.int64).max
            best = np.full(n, big)
            if cache is not None:
                for rows, nb in cache:
                    keep = ~is_core[rows] & is_core[nb]
                    np.minimum.at(best, rows[keep], core_label[core_pos[nb[keep]]])
                    bar.update()
            else:
                for s in range(0, other.size, step):
                    part = other[s : s + step]
                    rows, nb = core_search.pairs(X[part])
                    np.minimum.at(best, part[rows], core_label[nb])
                    bar.update()
            hit = other[best[other] != big]
            labels[hit] = best[hit]
            self.n_clusters_ = int(uniq.size)
        bar.close()
        self.labels_ = labels
        self.core_sample_indices_ = core_idx
        return self


class _Neighbours:
    r"""Fixed-radius neighbours of query chunks among ``points``, in bounded memory.

    Up to :data:`_BRUTE_DIM` dimensions a k-d tree answers; above that a k-d tree
    visits nearly every leaf and loses to brute force, so each chunk of queries is
    compared with every point through one matrix product,
    :math:`\lVert q - p \rVert^2 = \lVert q \rVert^2 - 2 q \cdot p + \lVert p \rVert^2`,
    holding only a chunk-by-N block (at most :data:`_BLOCK_BYTES`).
    """

    def __init__(self, points: np.ndarray, eps: float) -> None:
        self.points = points
        self.eps = eps
        n, d = points.shape
        self.brute = d > _BRUTE_DIM
        if self.brute:
            self.sq = np.einsum("ij,ij->i", points, points)
            self.chunk = int(max(1, min(_CHUNK, _BLOCK_BYTES // (8 * max(n, 1)))))
        else:
            from scipy.spatial import cKDTree

            self.tree = cKDTree(points)
            self.chunk = _CHUNK

    def count(self, q: np.ndarray) -> np.ndarray:
        """Number of points within ``eps`` of each query (a point counts itself)."""
        if self.brute:
            rows, _ = self.pairs(q)
            return np.bincount(rows, minlength=q.shape[0])
        return self.tree.query_ball_point(q, self.eps, return_length=True, workers=-1)

    def pairs(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(query row, point index) of every pair within ``eps``, by query row."""
        if self.brute:
            gram = q @ self.points.T
            return _brute_pairs(gram, np.einsum("ij,ij->i", q, q), self.sq, self.eps**2)
        return _flatten(self.tree.query_ball_point(q, self.eps, workers=-1))
