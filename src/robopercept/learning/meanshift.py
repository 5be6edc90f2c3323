r"""Mean-shift clustering (Fukunaga and Hostetler, 1975; Comaniciu and Meer, 2002).

Mean shift climbs the kernel density estimate :math:`\hat f(x) \propto \sum_i
k(\lVert x - x_i \rVert^2 / h^2)` to its modes. From each seed :math:`y_0` it repeats

.. math::

    y_{t+1} = \frac{\sum_i w_i(y_t)\, x_i}{\sum_i w_i(y_t)}, \qquad
    w_i(y) = \begin{cases}
      [\lVert y - x_i \rVert \le h] & \text{flat kernel} \\
      \exp(-\lVert y - x_i \rVert^2 / 2h^2) & \text{Gaussian kernel}
    \end{cases}

(the flat kernel's shift is the mean of the samples in the window of radius
:math:`h`, the bandwidth) until the step is at most :math:`10^{-3} h` or ``max_iter``
steps were taken. Converged seeds are modes; they are ranked by how many samples lie
within :math:`h` of them, and a mode within :math:`h` of a better-ranked one is merged
into it. Each sample is labelled with its nearest mode.

Seeds are every sample (``seeds="all"``, scikit-learn's default) or the occupied cells
of a grid of spacing :math:`h` (``seeds="grid"``, scikit-learn's ``bin_seeding``),
which is far cheaper on large data. All seeds move together: each step computes the
seed-to-sample distances of a block of seeds with one matrix product,
:math:`\lVert y - x \rVert^2 = \lVert y \rVert^2 - 2 y \cdot x + \lVert x \rVert^2`,
and the new positions with another, in blocks of bounded memory; seeds that have
converged leave the block.

The rules (stopping, ranking, merging, labelling) are those of
``sklearn.cluster.MeanShift``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_bool,
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
    check_matrix,
    check_option,
    renamed_rng,
    seed_from,
)
from robopercept.progress import progress_bar

__all__ = ["MeanShift", "estimate_bandwidth"]

_BLOCK_BYTES = 64 << 20


def estimate_bandwidth(
    X: npt.ArrayLike,
    *,
    quantile: float = 0.3,
    n_samples: int | None = None,
    random_state: RandomStateLike = None,
    rng: int | np.random.Generator | None = None,
) -> float:
    """A bandwidth from the data: the mean distance from each sample to its
    ``quantile * N``-th nearest neighbour (scikit-learn's heuristic), over at most
    ``n_samples`` random samples.

    Parameters
    ----------
    X : (N, d) array_like
    quantile : float in (0, 1]
    n_samples : int, optional
        Subsample size (all samples by default).
    random_state : int, Generator, RandomState or None
        Seed of the subsample (scikit-learn's name).
    rng
        Deprecated alias of ``random_state`` (one release).

    Returns
    -------
    float
    """
    random_state = renamed_rng("estimate_bandwidth", random_state, rng)
    X = check_magnitude(check_matrix(X, "X"), "X", 1e150)  # squared distances
    quantile = check_real(quantile, "quantile", 0.0, 1.0, low_inclusive=False)
    if n_samples is not None:
        n_samples = check_int(n_samples, "n_samples", 1)
    if n_samples is not None and n_samples < X.shape[0]:
        X = X[seed_from(random_state).choice(X.shape[0], size=n_samples, replace=False)]
    return _bandwidth(X, quantile)


def _bandwidth(X: np.ndarray, quantile: float) -> float:
    # estimate_bandwidth of checked data
    from scipy.spatial import cKDTree

    k = max(1, int(X.shape[0] * quantile))
    dist, _ = cKDTree(X).query(X, k=k)
    return float(np.mean(dist if k == 1 else dist[:, -1]))


def grid_seeds(X: np.ndarray, bin_size: float, min_bin_freq: int = 1) -> np.ndarray:
    """Centres of the grid cells (spacing ``bin_size``) holding >= ``min_bin_freq`` samples."""
    cells, counts = np.unique(np.round(X / bin_size), axis=0, return_counts=True)
    return cells[counts >= min_bin_freq] * bin_size


class MeanShift(ClusterMixin, Estimator):
    """Mean-shift clustering.

    Parameters
    ----------
    bandwidth : float or None
        Window radius :math:`h` (flat) or standard deviation (Gaussian); ``None``
        estimates it with :func:`estimate_bandwidth`.
    kernel : {"flat", "gaussian"}
    seeds : {"all", "grid"} or (S, d) array
        Starting points: every sample, the occupied grid cells, or given points.
    min_bin_freq : int
        With ``seeds="grid"``, cells with fewer samples are not seeds.
    cluster_all : bool
        ``False`` labels samples farther than ``bandwidth`` from every mode -1.
    max_iter : int
    progress : bool
        Show a progress bar over the shift iterations.

    Attributes
    ----------
    cluster_centers_ : (k, d) ndarray
        Modes, by decreasing number of samples within the bandwidth.
    labels_ : (N,) ndarray
    n_iter_ : int
        The most steps any seed took.
    """

    def __init__(
        self,
        bandwidth: float | None = None,
        *,
        kernel: str = "flat",
        seeds: str | np.ndarray = "all",
        min_bin_freq: int = 1,
        cluster_all: bool = True,
        max_iter: int = 300,
        progress: bool = False,
    ) -> None:
        self.bandwidth = bandwidth
        self.kernel = kernel
        self.seeds = seeds
        self.min_bin_freq = min_bin_freq
        self.cluster_all = cluster_all
        self.max_iter = max_iter
        self.progress = progress

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> MeanShift:
        """Find the modes of ``X`` (N, d) and label every sample."""
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150)  # squared distances
        check_option(self.kernel, "kernel", ("flat", "gaussian"))
        cluster_all = check_bool(self.cluster_all, "cluster_all")
        check_bool(self.progress, "progress")
        max_iter = check_int(self.max_iter, "max_iter", 1)
        if self.bandwidth is None:
            h = _bandwidth(X, 0.3)
            if not h > 0:
                raise InputError(
                    f"the estimated bandwidth is 0 ({X.shape[0]} sample(s), all at one "
                    "point?): pass bandwidth= explicitly"
                )
        else:
            h = check_real(self.bandwidth, "bandwidth", 0.0, low_inclusive=False)
        if isinstance(self.seeds, str):
            check_option(self.seeds, "seeds", ("all", "grid"))
            if self.seeds == "all":
                seeds = X.copy()
            else:
                seeds = grid_seeds(X, h, check_int(self.min_bin_freq, "min_bin_freq", 1))
        else:
            seeds = check_numeric(self.seeds, "seeds")
            if seeds.ndim != 2 or seeds.shape[1] != X.shape[1] or seeds.shape[0] == 0:
                raise InputError(f"seeds must be (S, {X.shape[1]}); got shape {seeds.shape}")
            if not np.isfinite(seeds).all():
                raise InputError("seeds must be finite")
            check_magnitude(seeds, "seeds", 1e150)
        if seeds.shape[0] == 0:
            raise InputError(
                "no grid cell holds min_bin_freq samples; lower min_bin_freq or bandwidth"
            )
        modes, counts, n_iter = self._shift(X, seeds, h, max_iter)
        keep = counts > 0
        if not np.any(keep):
            raise InputError(
                f"no seed has a sample within bandwidth={h}; the bandwidth is too small"
            )
        modes, counts = modes[keep], counts[keep]
        # identical modes collapse; rank by count then by coordinates, descending
        modes, first = np.unique(modes, axis=0, return_index=True)
        counts = counts[first]
        order = np.lexsort((*(modes[:, j] for j in range(modes.shape[1] - 1, -1, -1)), counts))
        modes, counts = modes[order[::-1]], counts[order[::-1]]
        centers = self._merge(modes, h)
        labels, dist = _nearest(X, centers)
        if not cluster_all:
            labels = np.where(dist <= h * h, labels, -1)
        self.bandwidth_ = h
        self.cluster_centers_ = centers
        self.labels_ = labels
        self.n_iter_ = n_iter
        return self

    def _shift(
        self, X: np.ndarray, seeds: np.ndarray, h: float, max_iter: int
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """Move all seeds to their modes; returns modes, window counts, steps."""
        x_sq = np.einsum("ij,ij->i", X, X)
        h2 = h * h
        stop = 1e-3 * h
        pos = seeds.copy()
        counts = np.zeros(pos.shape[0], dtype=np.int64)
        active = np.arange(pos.shape[0])
        block = int(max(1, _BLOCK_BYTES // (8 * X.shape[0])))
        n_iter = 0
        bar = progress_bar(
            total=max_iter + 1, desc="mean shift", unit="iteration", disable=not self.progress
        )
        for it in range(max_iter + 1):
            if active.size == 0:
                break
            n_iter = it
            still = []
            for s in range(0, active.size, block):
                idx = active[s : s + block]
                y = pos[idx]
                d2 = np.einsum("ij,ij->i", y, y)[:, None] - 2.0 * (y @ X.T) + x_sq[None, :]
                inside = d2 <= h2
                cnt = np.count_nonzero(inside, axis=1)
                counts[idx] = cnt
                if self.kernel == "flat":
                    w = inside.astype(np.float64)
                    wsum = cnt.astype(np.float64)
                else:
                    w = np.exp(-np.maximum(d2, 0.0) / (2.0 * h2))
                    wsum = w.sum(axis=1)
                ok = wsum > 0
                new = y.copy()
                new[ok] = (w[ok] @ X) / wsum[ok, None]
                moved = np.sqrt(np.sum((new - y) ** 2, axis=1))
                pos[idx] = new
                going = ok & (moved > stop)
                still.append(idx[going])
            active = np.concatenate(still) if it < max_iter else active[:0]
            bar.update()
        bar.close()
        return pos, counts, n_iter

    @staticmethod
    def _merge(modes: np.ndarray, h: float) -> np.ndarray:
        """Drop every mode within ``h`` of a better-ranked kept one (modes sorted)."""
        from scipy.spatial import cKDTree

        tree = cKDTree(modes)
        unique = np.ones(modes.shape[0], dtype=bool)
        for i in range(modes.shape[0]):
            if unique[i]:
                unique[tree.query_ball_point(modes[i], h)] = False
                unique[i] = True
        return modes[unique]

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Index of the nearest mode for every sample."""
        self._check_fitted("cluster_centers_")
        X = self._check_X(X)
        return _nearest(X, self.cluster_centers_)[0]


def _nearest(X: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial import cKDTree

    d, i = cKDTree(C).query(X)
    return i.astype(np.int64), d * d
