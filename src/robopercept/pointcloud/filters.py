r"""Point-cloud filters: pass-through, voxel grid, statistical and radius outlier removal.

Each filter returns ``(filtered_cloud, indices)``; ``indices`` are positions in the input
cloud (for :func:`voxel_downsample`, the voxel of each input point). Non-finite points
are never kept: they are dropped first and do not appear in ``indices``. Neighbour
queries go through k-d trees from libraries: nanoflann (``pynanoflann``, the engine
Open3D's ``KDTreeFlann`` wraps) for the k-nearest queries of
:func:`statistical_outlier_removal`, ``scipy.spatial.cKDTree`` for radius counts.

Open3D's keyword names are accepted as keyword-only aliases: ``nb_neighbors`` for
``k`` (``remove_statistical_outlier(nb_neighbors, std_ratio)``) and ``nb_points`` for
``min_neighbors`` (``remove_radius_outlier(nb_points, radius)``); ``std_ratio``,
``radius`` and ``voxel_size`` are spelled as in Open3D already. Giving both spellings
of one is an InputError.
"""

from __future__ import annotations

import math
import os
from typing import Literal

import numpy as np
import pynanoflann
from numba import njit, prange
from scipy.spatial import cKDTree

from robopercept._checks import check_int, check_real, resolve_alias
from robopercept.errors import InputError
from robopercept.pointcloud.cloud import PointCloud, check_cloud

__all__ = [
    "pass_through",
    "radius_outlier_removal",
    "statistical_outlier_removal",
    "voxel_downsample",
]

_AXES = {"x": 0, "y": 1, "z": 2}


def _finite_index(cloud: PointCloud) -> np.ndarray:
    return np.flatnonzero(cloud.finite_mask())


def pass_through(
    cloud: PointCloud,
    axis: Literal["x", "y", "z"] | int,
    min_value: float,
    max_value: float,
    *,
    invert: bool = False,
) -> tuple[PointCloud, np.ndarray]:
    """Keep the points whose coordinate on ``axis`` lies in ``[min_value, max_value]``.

    PCL's ``PassThrough`` filter (``setFilterLimitsNegative`` is ``invert``).

    Parameters
    ----------
    cloud : PointCloud
    axis : {'x', 'y', 'z'} or {0, 1, 2}
    min_value, max_value : float
        Inclusive limits, ``min_value <= max_value``.
    invert : bool
        Keep the finite points *outside* the limits instead.

    Returns
    -------
    cloud : PointCloud
    indices : (M,) int64 ndarray
        Kept input positions, in input order.
    """
    cloud = check_cloud(cloud)
    ax = _AXES.get(axis, axis) if isinstance(axis, str) else axis
    if isinstance(ax, bool) or ax not in (0, 1, 2):
        raise InputError(f"axis must be 'x', 'y', 'z' or 0, 1, 2; got {axis!r}")
    lo = check_real(min_value, "min_value")
    hi = check_real(max_value, "max_value")
    if lo > hi:
        raise InputError(f"min_value must be <= max_value; got {lo:g} > {hi:g}: swap them")
    v = cloud.points[:, ax]
    inside = (v >= lo) & (v <= hi)
    keep = (~inside if invert else inside) & cloud.finite_mask()
    idx = np.flatnonzero(keep)
    return cloud.select(idx), idx


@njit(cache=True, nogil=True)
def _bounds(pts):  # pragma: no cover - compiled
    """(3,) minimum and maximum of ``(N, 3)`` points in one pass."""
    lo = pts[0].copy()
    hi = pts[0].copy()
    for i in range(1, pts.shape[0]):
        for j in range(3):
            v = pts[i, j]
            if v < lo[j]:
                lo[j] = v
            elif v > hi[j]:
                hi[j] = v
    return lo, hi


@njit(cache=True, nogil=True)
def _group_sums(values, ids, m):  # pragma: no cover - compiled
    """(m, D) sums of the rows of ``values`` per group id."""
    out = np.zeros((m, values.shape[1]))
    for i in range(values.shape[0]):
        g = ids[i]
        for j in range(values.shape[1]):
            out[g, j] += values[i, j]
    return out


@njit(cache=True, nogil=True)
def _voxel_ids(pts, base, size, dims):  # pragma: no cover - compiled
    """Voxel id of each point, ids numbered by first occurrence; returns (ids, count).

    The voxel ``floor((p - base) / size)`` is packed into one int64 key and looked up in
    an open-addressing hash table (multiplicative hashing, linear probing): one pass,
    no sort.
    """
    n = pts.shape[0]
    bits = 1
    while (1 << bits) < 2 * n:
        bits += 1
    mask = (1 << bits) - 1
    keys = np.full(1 << bits, -1, dtype=np.int64)
    slot_id = np.empty(1 << bits, dtype=np.int64)
    ids = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        cx = np.int64(math.floor((pts[i, 0] - base[0]) / size))
        cy = np.int64(math.floor((pts[i, 1] - base[1]) / size))
        cz = np.int64(math.floor((pts[i, 2] - base[2]) / size))
        key = (cz * dims[1] + cy) * dims[0] + cx
        h = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(64 - bits))
        while keys[h] != -1 and keys[h] != key:
            h = (h + 1) & mask
        if keys[h] == -1:
            keys[h] = key
            slot_id[h] = m
            m += 1
        ids[i] = slot_id[h]
    return ids, m


def voxel_downsample(cloud: PointCloud, voxel_size: float) -> tuple[PointCloud, np.ndarray]:
    r"""Replace the points of each occupied voxel by their centroid.

        Voxels are cubes of side ``s`` anchored as in Open3D's ``voxel_down_sample``: point
        ``p`` goes to voxel :math:`\lfloor (p - b) / s \rfloor` with
        :math:`b = \min_i p_i - s/2`. Colours and normals are averaged per voxel (normals
        re-normalized). Output points are in the order of each voxel's first input point
    (Open3D's order is its hash map's; compare the two as sets).

        Parameters
        ----------
        cloud : PointCloud
        voxel_size : float
            > 0, in the cloud's units.

        Returns
        -------
        cloud : PointCloud
            One point per occupied voxel.
        voxel_of_point : (N,) int64 ndarray
            For each input point, the output point it went into (-1 for non-finite points).

        Raises
        ------
        InputError
            ``voxel_size`` not > 0, or so small against the cloud's extent that voxel
            numbers would not fit in int64 (more than 2**62 voxels along one axis).

    Examples
    --------
    The first two points share a 0.1 m voxel and are averaged:

    >>> from robopercept.pointcloud import PointCloud
    >>> cloud = PointCloud(np.array([[0.01, 0.01, 0.0], [0.03, 0.01, 0.0], [0.51, 0.0, 0.0]]))
    >>> down, index = voxel_downsample(cloud, 0.1)
    >>> np.round(down.points, 3).tolist(), index.tolist()
    ([[0.02, 0.01, 0.0], [0.51, 0.0, 0.0]], [0, 0, 1])
    """
    cloud = check_cloud(cloud)
    s = check_real(voxel_size, "voxel_size", 0.0, low_inclusive=False)
    fin = _finite_index(cloud)
    inverse = np.full(len(cloud), -1, dtype=np.int64)
    if fin.size == 0:
        return PointCloud(np.empty((0, 3))), inverse
    pts = cloud.points if fin.size == len(cloud) else cloud.points[fin]
    lo, hi = _bounds(pts)
    with np.errstate(over="ignore"):
        extent = float((hi - lo).max())
    if not extent / s < 2.0**62:  # int64 voxel numbers would wrap (issue 25: 1e308 clouds)
        if not math.isfinite(extent):
            raise InputError(
                "the cloud's extent overflows float64 (coordinates near 1e308): "
                "rescale the cloud before voxel_downsample"
            )
        raise InputError(
            f"voxel_size {s:g} is too small for the cloud's extent {extent:g}: more than "
            f"2**62 voxels along one axis; use voxel_size >= {extent / 2.0**62:g}"
        )
    base = lo - 0.5 * s
    dims = np.floor((hi - base) / s).astype(np.int64) + 1
    if float(np.prod(dims.astype(np.float64))) < 2.0**62:
        inv, m = _voxel_ids(pts, base, s, dims)
        inv = inv[: pts.shape[0]]
        counts = np.bincount(inv, minlength=m).astype(np.float64)
    else:  # a huge extent for the voxel size: unique rows instead of a packed key
        cell = np.floor((pts - base) / s).astype(np.int64)
        _, inv, counts = np.unique(cell, axis=0, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
    m = counts.shape[0]

    def mean(values: np.ndarray) -> np.ndarray:
        return _group_sums(np.ascontiguousarray(values, dtype=np.float64), inv, m) / counts[:, None]

    colors = None if cloud.colors is None else mean(cloud.colors[fin])
    normals = None
    if cloud.normals is not None:
        normals = mean(cloud.normals[fin])
        norm = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.divide(normals, norm, out=np.zeros_like(normals), where=norm > 0)
    inverse[fin] = inv
    return PointCloud(mean(pts), colors, normals), inverse


def _tree(points: np.ndarray) -> cKDTree:
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


@njit(cache=True, parallel=True)
def _mean_root(d2: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    """Row means of the square roots of ``d2``, summed left to right as Open3D does."""
    n, k = d2.shape
    out = np.empty(n)
    for i in prange(n):
        s = 0.0
        for j in range(k):
            s += math.sqrt(d2[i, j])
        out[i] = s / k
    return out


# bytes of nanoflann results (squared distances and indices, 16 bytes per neighbour) per
# block of queries: 128 MiB is about 168k points at k = 50
_KNN_BLOCK_BYTES = 128 << 20  # (clouds up to twice that go in one block)
# |coordinates| beyond 2**500 (or below 2**-500) would overflow (underflow) the squared
# distances, and a span of inf crashes nanoflann's tree build
_SAFE_EXPONENT = 500
# from this many points on, the queries go in Morton (Z-curve) order of a 1024^3 grid
_ORDER_MIN = 1 << 20


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Insert two zero bits after each of the 10 low bits of ``v`` (uint32): ``b9..b0``
    becomes ``b9 0 0 b8 0 0 ... b0``, the 30-bit Morton layout of one axis."""
    v = v & 0x3FF
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


def _morton_order(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    r"""(N,) int64 permutation that visits ``points`` along a Z-order (Morton) curve.

    Each point's cell in a :math:`1024^3` grid over the bounding box ``[lo, hi]``,
    :math:`c = \lfloor 1023.99 (p - lo) / \max(hi - lo) \rfloor`, is interleaved into the
    30-bit key :math:`\sum_b 2^{3b} (c_{x,b} + 2 c_{y,b} + 4 c_{z,b})`; points sorted by
    key come in spatially compact runs. Computed 1M points at a time (NumPy).
    """
    n = points.shape[0]
    inv = 1023.99 / float((hi - lo).max())
    key = np.empty(n, dtype=np.uint32)
    for start in range(0, n, 1 << 20):
        cell = ((points[start : start + (1 << 20)] - lo) * inv).astype(np.uint32)
        key[start : start + (1 << 20)] = (
            _spread_bits(cell[:, 0])
            | (_spread_bits(cell[:, 1]) << 1)
            | (_spread_bits(cell[:, 2]) << 2)
        )
    return np.argsort(key)


def _knn_mean_distance(
    points: np.ndarray, k: int, block: int | None = None
) -> tuple[np.ndarray, int]:
    r"""(N,) mean Euclidean distance from each point to its k nearest points (itself included).

    :math:`\bar d_i = \frac1k \sum_{j=1}^{k} \lVert p_i - p_{(j)} \rVert` over the ``k``
    nearest points :math:`p_{(j)}` of :math:`p_i`, the point itself first (Open3D's
    statistic in ``remove_statistical_outlier``).

    nanoflann with leaves of 20 points; about 1.4x faster than ``cKDTree.query`` on the
    PCL table scene (209k points, k = 50; ``python -m benchmarks pointcloud``). The
    queries go in blocks of ``block`` points (by default as many as fit
    ``_KNN_BLOCK_BYTES`` of nanoflann's (block, k) distance and index arrays), each
    block to 4 threads per core: pynanoflann gives each thread one contiguous run, and
    smaller runs balance dense and sparse parts of the cloud better. Each block's
    squared distances are reduced in place by :func:`_mean_root`, so the memory beyond
    the tree is the (N,) result plus one block, not N x k (issue 25: 20M points). From
    ``_ORDER_MIN`` points on, the blocks follow a Morton order (:func:`_morton_order`,
    one more (N,) int64 array): a cloud larger than the cache queried in scattered
    order spends most of its time on cache misses (3.7x the CPU time for 200k of 1M
    uniformly shuffled points). Each point's result is the same in either order.

    Degenerate clouds are handled before nanoflann sees them, because its tree build
    reads uninitialized memory (and segfaults) when the bounding box has zero extent
    (every point the same) or an infinite one (coordinates near +-1e308): a zero-extent
    cloud gets all-zero distances without a tree; coordinates beyond ``2**500`` (or all
    below ``2**-500``) are scaled by ``2**-exponent`` (exact in floating point), and the
    distances come back in units of ``2**exponent`` (the true ones may not be
    representable). Lines, planes and repeated points are fine for nanoflann and take
    the ordinary path.

    Parameters
    ----------
    points : (N, 3) float64 ndarray
        Finite, C-contiguous.
    k : int
        ``1 <= k <= N``.
    block : int, optional
        Points per block of queries (tests use small blocks).

    Returns
    -------
    mean_distance : (N,) float64 ndarray
        In units of ``2**exponent``.
    exponent : int
        0 unless the cloud was rescaled.
    """
    n = points.shape[0]
    lo, hi = _bounds(points)
    if (lo == hi).all():  # zero extent: every distance is 0 (nanoflann would crash)
        return np.zeros(n), 0
    exponent = math.frexp(float(max(np.abs(lo).max(), np.abs(hi).max())))[1]
    if abs(exponent) > _SAFE_EXPONENT:  # power-of-two rescale: exact; no copy otherwise
        points = np.ldexp(points, -exponent)
        lo, hi = np.ldexp(lo, -exponent), np.ldexp(hi, -exponent)
    else:
        exponent = 0
    # the order first: its sort keys are freed before the tree takes its memory
    order = _morton_order(points, lo, hi) if n >= _ORDER_MIN else None
    tree = pynanoflann.KDTree(n_neighbors=k, metric="l2", leaf_size=20)
    tree.fit(points)
    rows = block if block is not None else max(1024, _KNN_BLOCK_BYTES // (16 * k))
    if block is None and n <= 2 * rows:  # one block up to twice the budget: a second,
        rows = n  # smaller block costs about 6% on the table scene (209k points)
    threads = 4 * (os.cpu_count() or 1)
    out = np.empty(n)
    for start in range(0, n, rows):
        if order is None:
            d2, _ = tree.index.kneighbors_multithreaded(points[start : start + rows], k, threads)
            out[start : start + rows] = _mean_root(d2)
        else:
            sel = order[start : start + rows]
            d2, _ = tree.index.kneighbors_multithreaded(points[sel], k, threads)
            out[sel] = _mean_root(d2)
        del d2, _
    return out, exponent


def statistical_outlier_removal(
    cloud: PointCloud,
    k: int | None = None,
    std_ratio: float = 1.0,
    *,
    nb_neighbors: int | None = None,
) -> tuple[PointCloud, np.ndarray]:
    r"""Drop points whose mean distance to their neighbours is unusually large.

    For each point, :math:`\bar d_i` is the mean distance to its ``k`` nearest points
    counting the point itself (distance 0), exactly as Open3D's
    ``remove_statistical_outlier(k, std_ratio)``; PCL's ``StatisticalOutlierRemoval``
    uses the same statistic over ``k`` neighbours excluding the point. With :math:`\mu`
    and :math:`\sigma` the mean and sample standard deviation of the :math:`\bar d_i`,
    a point is kept when

    .. math:: 0 < \bar d_i < \mu + \text{std\_ratio}\; \sigma

    (Open3D's rule; the lower bound drops points that coincide with all their
    neighbours). A cloud whose points are all the same therefore gives an empty result,
    as Open3D's does (issue 25: it used to crash nanoflann); a cloud with coordinates
    near the float64 limit is rescaled exactly by a power of two, which leaves the rule
    unchanged, instead of overflowing the squared distances.

    The neighbour queries go in blocks (about 168k points at k = 50), in Morton order
    from 1M points on, so the memory beyond the input is the k-d tree, one (N,) float64
    array of mean distances (and one (N,) int64 order), one block of nanoflann's
    (block, k) results (128 MiB) and the output; an all-finite cloud is not copied.
    20M points (458 MiB) took 730 MiB beyond the input at its peak, output included
    (``BENCH_SOR_20M=1 python -m benchmarks pointcloud``, ``docs/benchmarks.md``).

    Parameters
    ----------
    cloud : PointCloud
    k : int, default 50
        Neighbours per point, >= 2. Open3D's spelling: ``nb_neighbors=``.
    std_ratio : float
        >= 0.
    nb_neighbors : int, optional
        Keyword-only alias (Open3D's name) of ``k``.

    Returns
    -------
    cloud : PointCloud
    indices : (M,) int64 ndarray
        Kept input positions, in input order.

    Raises
    ------
    InputError
        Not a PointCloud, ``k`` < 2, ``std_ratio`` < 0, or both ``k`` and
        ``nb_neighbors``.

    Examples
    --------
    The point far from the others is dropped (Open3D's keyword names work too):

    >>> from robopercept.pointcloud import PointCloud
    >>> pts = np.vstack([np.random.default_rng(0).normal(0, 0.01, (50, 3)), [[1, 1, 1]]])
    >>> _, kept = statistical_outlier_removal(PointCloud(pts), nb_neighbors=10, std_ratio=2.0)
    >>> 50 in kept
    False
    """
    cloud = check_cloud(cloud)
    k = resolve_alias(k, "k", nb_neighbors, "nb_neighbors")
    k = check_int(50 if k is None else k, "k", 2)
    ratio = check_real(std_ratio, "std_ratio", 0.0)
    finite = cloud.finite_mask()
    fin = None if finite.all() else np.flatnonzero(finite)  # None: no copy of the points
    del finite
    pts = np.ascontiguousarray(cloud.points if fin is None else cloud.points[fin])
    if pts.shape[0] == 0:
        return PointCloud(np.empty((0, 3))), np.empty(0, dtype=np.int64)
    # the rule is scale-free, so the distances' units (2**exponent) do not matter
    mean_d, _ = _knn_mean_distance(pts, min(k, pts.shape[0]))
    mu = mean_d.mean()
    sigma = mean_d.std(ddof=1) if mean_d.size > 1 else 0.0
    keep = (mean_d > 0) & (mean_d < mu + ratio * sigma)
    del mean_d
    idx = np.flatnonzero(keep) if fin is None else fin[keep]
    del keep
    return cloud.select(idx), idx


def radius_outlier_removal(
    cloud: PointCloud,
    radius: float,
    min_neighbors: int | None = None,
    *,
    nb_points: int | None = None,
) -> tuple[PointCloud, np.ndarray]:
    """Keep points with at least ``min_neighbors`` other points within ``radius``.

    The point itself is not counted. Matches Open3D's
    ``remove_radius_outlier(nb_points=min_neighbors, radius)`` index for index (checked
    on the PCL table scene and office scene) and PCL's ``RadiusOutlierRemoval``;
    Open3D's call ``radius_outlier_removal(cloud, nb_points=16, radius=0.05)`` works as
    written.

    Parameters
    ----------
    cloud : PointCloud
    radius : float
        > 0.
    min_neighbors : int
        >= 0; required (here or as ``nb_points``). Open3D's spelling: ``nb_points=``.
    nb_points : int, optional
        Keyword-only alias (Open3D's name) of ``min_neighbors``.

    Returns
    -------
    cloud : PointCloud
    indices : (M,) int64 ndarray

    Raises
    ------
    InputError
        Not a PointCloud, ``radius`` not > 0, ``min_neighbors`` missing or < 0, or
        both ``min_neighbors`` and ``nb_points``.
    """
    cloud = check_cloud(cloud)
    if isinstance(min_neighbors, float) and isinstance(radius, (int, np.integer)):
        raise InputError(
            f"radius_outlier_removal takes (cloud, radius, min_neighbors); got radius="
            f"{radius} and min_neighbors={min_neighbors}: Open3D's order (nb_points, "
            f"radius)? write radius_outlier_removal(cloud, {min_neighbors}, {radius}) or "
            f"use keywords (nb_points={radius}, radius={min_neighbors})"
        )
    r = check_real(radius, "radius", 0.0, low_inclusive=False)
    need = resolve_alias(min_neighbors, "min_neighbors", nb_points, "nb_points")
    if need is None:
        raise InputError(
            "min_neighbors is required: the fewest other points within radius that a "
            "kept point has (Open3D's nb_points= is accepted too), e.g. "
            "radius_outlier_removal(cloud, 0.05, 16)"
        )
    need = check_int(need, "min_neighbors", 0)
    fin = _finite_index(cloud)
    if fin.size == 0:
        return PointCloud(np.empty((0, 3))), fin
    pts = cloud.points[fin]
    counts = _tree(pts).query_ball_point(pts, r, return_length=True, workers=-1)
    idx = fin[np.asarray(counts) - 1 >= need]
    return cloud.select(idx), idx
