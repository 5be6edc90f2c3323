r"""Descriptor matching: brute force (L2 or Hamming), k nearest, Lowe's ratio test,
cross-check, and a k-d tree path for large float sets.

For query descriptors :math:`q_i` and train descriptors :math:`t_j` the distance is
:math:`\|q_i - t_j\|_2` for float descriptors (SIFT, HOG) or the Hamming distance
:math:`\operatorname{popcount}(q_i \oplus t_j)` for binary ones packed in uint8 (ORB,
BRIEF). Brute force computes all of them, in blocks of query rows so that memory stays
bounded: :math:`\|q - t\|^2 = \|q\|^2 + \|t\|^2 - 2\, q \cdot t` through one matrix
product per block. Lowe's ratio test keeps a match when its distance is below ``ratio``
times the second-best distance (an ambiguous match has a close runner-up); the
cross-check keeps :math:`i \to j` only when :math:`j`'s best match is :math:`i`.
Matches ``cv2.BFMatcher(NORM_L2 / NORM_HAMMING, crossCheck)`` and its ``knnMatch``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numba import njit, prange
from scipy.spatial import cKDTree

from robopercept._checks import check_bool, check_choice, check_int, check_real
from robopercept.errors import InputError

__all__ = ["Matches", "knn_match", "match_descriptors"]

Metric = Literal["l2", "hamming"]
_BLOCK = 1024  # query rows per block of the brute-force distance matrix


@dataclass(frozen=True)
class Matches:
    """Matched pairs, one row per match.

    Attributes
    ----------
    query_idx, train_idx : (N,) int64 ndarray
    distance : (N,) float64 ndarray
    """

    query_idx: np.ndarray
    train_idx: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return int(self.query_idx.shape[0])


def _check(desc: np.ndarray, name: str, metric: str) -> np.ndarray:
    d = np.asarray(desc)
    if d.ndim != 2:
        raise InputError(f"{name} must be (N, D) descriptors; got shape {d.shape}")
    if metric == "hamming":
        if d.dtype != np.uint8:
            raise InputError(
                f"{name}: Hamming matching needs uint8 (bit-packed) descriptors; got {d.dtype}"
            )
        return np.ascontiguousarray(d)
    if d.dtype.kind not in "fiu":
        raise InputError(f"{name} must be numeric; got dtype {d.dtype}")
    d = np.ascontiguousarray(d, dtype=np.float32)
    if not np.isfinite(d).all():
        raise InputError(f"{name} contains NaN or inf")
    return d


_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.int32)


@njit(cache=True, nogil=True, parallel=True)
def _hamming_knn(q, t, k, pop, idx, dist):  # pragma: no cover - compiled
    # for each query row the k train rows of smallest Hamming distance (ties: lower
    # index first), by insertion into a sorted list of k
    nq, nb = q.shape
    nt = t.shape[0]
    for i in prange(nq):
        bd = np.full(k, 1 << 30, dtype=np.int64)
        bi = np.full(k, -1, dtype=np.int64)
        for j in range(nt):
            d = 0
            for b in range(nb):
                d += pop[q[i, b] ^ t[j, b]]
            if d < bd[k - 1]:
                p = k - 1
                while p > 0 and bd[p - 1] > d:
                    bd[p] = bd[p - 1]
                    bi[p] = bi[p - 1]
                    p -= 1
                bd[p] = d
                bi[p] = j
        for m in range(k):
            idx[i, m] = bi[m]
            dist[i, m] = bd[m]


def _l2_knn(q: np.ndarray, t: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    nq = q.shape[0]
    idx = np.empty((nq, k), dtype=np.int64)
    dist = np.empty((nq, k))
    tn = np.einsum("ij,ij->i", t, t)
    for a in range(0, nq, _BLOCK):
        qb = q[a : a + _BLOCK]
        d2 = qb @ t.T
        d2 *= -2
        d2 += tn
        d2 += np.einsum("ij,ij->i", qb, qb)[:, None]
        part = np.argpartition(d2, k - 1, axis=1)[:, :k]
        vals = np.take_along_axis(d2, part, 1)
        order = np.argsort(vals, axis=1, kind="stable")
        best = np.take_along_axis(part, order, 1)
        idx[a : a + _BLOCK] = best
        # exact distances of the chosen pairs (the expansion loses digits near 0)
        diff = qb[:, None, :].astype(np.float64) - t[best].astype(np.float64)
        dist[a : a + _BLOCK] = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    # the expansion's rounding can swap near-equal neighbours: order by exact distance
    order = np.argsort(dist, axis=1, kind="stable")
    return np.take_along_axis(idx, order, 1), np.take_along_axis(dist, order, 1)


def knn_match(
    query: np.ndarray,
    train: np.ndarray,
    k: int = 2,
    *,
    metric: Metric = "l2",
    method: Literal["auto", "brute", "kdtree"] = "auto",
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest train descriptors of every query descriptor.

    Parameters
    ----------
    query : (Nq, D) array_like
    train : (Nt, D) array_like
    k : int
        Neighbours per query, 1 <= k; capped at ``Nt``.
    metric : {'l2', 'hamming'}
        Hamming needs uint8 bit-packed descriptors.
    method : {'auto', 'brute', 'kdtree'}
        ``kdtree`` (L2 only) queries a ``scipy.spatial.cKDTree`` of the train set: faster
        for large sets of low-dimensional descriptors; ``auto`` picks it when ``D <= 16``
        and both sets have more than 2000 rows, brute force otherwise.

    Returns
    -------
    idx : (Nq, k) int64 ndarray
        Train indices, nearest first.
    dist : (Nq, k) float64 ndarray
    """
    check_choice(metric, "metric", ("l2", "hamming"))
    check_choice(method, "method", ("auto", "brute", "kdtree"))
    k = check_int(k, "k", 1)
    q = _check(query, "query", metric)
    t = _check(train, "train", metric)
    if q.shape[0] and t.shape[0] and q.shape[1] != t.shape[1]:
        raise InputError(
            f"query and train descriptors differ in length: {q.shape[1]} vs {t.shape[1]}"
        )
    k = min(k, t.shape[0])
    if q.shape[0] == 0 or k == 0:
        return np.zeros((q.shape[0], k), dtype=np.int64), np.zeros((q.shape[0], k))
    if metric == "hamming":
        if method == "kdtree":
            raise InputError("method='kdtree' is for L2 descriptors; use 'brute' for Hamming")
        idx = np.empty((q.shape[0], k), dtype=np.int64)
        dist = np.empty((q.shape[0], k), dtype=np.int64)
        _hamming_knn(q, t, k, _POPCOUNT, idx, dist)
        return idx, dist.astype(np.float64)
    use_tree = method == "kdtree" or (
        method == "auto" and q.shape[1] <= 16 and min(q.shape[0], t.shape[0]) > 2000
    )
    if use_tree:
        dist, idx = cKDTree(t.astype(np.float64)).query(q.astype(np.float64), k=k, workers=-1)
        return idx.reshape(q.shape[0], k).astype(np.int64), dist.reshape(q.shape[0], k)
    return _l2_knn(q, t, k)


def match_descriptors(
    query: np.ndarray,
    train: np.ndarray,
    *,
    metric: Metric = "l2",
    ratio: float | None = None,
    cross_check: bool = False,
    max_distance: float | None = None,
    method: Literal["auto", "brute", "kdtree"] = "auto",
) -> Matches:
    """Best train match of every query descriptor, filtered.

    Parameters
    ----------
    query, train, metric, method
        See :func:`knn_match`.
    ratio : float, optional
        Lowe's ratio test: keep a match when ``d1 < ratio * d2`` (0.7-0.8 usual); needs
        at least 2 train descriptors.
    cross_check : bool
        Keep ``i -> j`` only when ``i`` is also ``j``'s best query match
        (``cv2.BFMatcher(crossCheck=True)``).
    max_distance : float, optional
        Drop matches farther than this.

    Returns
    -------
    Matches
        In query order. Empty (never an exception) when either set is empty, with the
        cross-check or the ratio test too (int64 indices, float64 distances).

    Raises
    ------
    InputError
        Descriptors that are not ``(N, D)`` numeric (uint8 for Hamming) or of different
        lengths, NaN/inf, ``ratio`` outside (0, 1], a negative ``max_distance``, a
        ``cross_check`` that is not a bool, or the ratio test with a single train
        descriptor and a non-empty query.

    Examples
    --------
    >>> query = np.array([[0.0, 0.0], [1.0, 1.0]])
    >>> train = np.array([[1.0, 1.1], [5.0, 5.0], [0.1, 0.0]])
    >>> m = match_descriptors(query, train)
    >>> m.query_idx.tolist(), m.train_idx.tolist(), np.round(m.distance, 3).tolist()
    ([0, 1], [2, 0], [0.1, 0.1])
    """
    if ratio is not None:
        ratio = check_real(ratio, "ratio", 0.0, 1.0, low_inclusive=False)
    if max_distance is not None:
        max_distance = check_real(max_distance, "max_distance", 0.0)
    cross_check = check_bool(cross_check, "cross_check")
    k = 2 if ratio is not None else 1
    idx, dist = knn_match(query, train, k, metric=metric, method=method)
    nq = idx.shape[0]
    if nq == 0 or idx.shape[1] == 0:
        # an empty query or train set (a blank image's SIFT): no match, whatever the
        # filters, as cv2.BFMatcher(crossCheck=True).match gives ()
        z = np.zeros(0, dtype=np.int64)
        return Matches(z, z.copy(), np.zeros(0))
    keep = np.ones(nq, dtype=bool)
    if ratio is not None:
        if idx.shape[1] < 2:
            raise InputError("the ratio test needs at least 2 train descriptors")
        keep &= dist[:, 0] < ratio * dist[:, 1]
    if cross_check:
        back, _ = knn_match(train, query, 1, metric=metric, method=method)
        keep &= back[idx[:, 0], 0] == np.arange(nq)
    if max_distance is not None:
        keep &= dist[:, 0] <= max_distance
    q_idx = np.flatnonzero(keep).astype(np.int64)
    return Matches(q_idx, idx[q_idx, 0].copy(), dist[q_idx, 0].copy())
