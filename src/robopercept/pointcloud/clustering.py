r"""Euclidean cluster extraction (Rusu 2009; PCL's ``EuclideanClusterExtraction``).

Two points belong to the same cluster when a chain of points joins them with every step
shorter than ``tolerance``: the clusters are the connected components of the graph with
an edge between every pair of points closer than ``tolerance``. PCL grows each cluster by
a breadth-first search of radius queries; here the edges come from one
``cKDTree.query_pairs`` call and the components from a compiled union-find over those
pairs, which gives the same partition.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial import cKDTree

from robopercept._checks import check_int, check_magnitude, check_real
from robopercept.errors import InputError
from robopercept.pointcloud.cloud import PointCloud, check_cloud

__all__ = ["euclidean_clusters"]


@njit(cache=True, nogil=True)
def _components(n, pairs):  # pragma: no cover - compiled
    """Connected components of the graph on ``n`` nodes with edges ``pairs`` (E, 2).

    Union-find with path halving, the smaller root kept; returns component ids numbered
    in order of each component's first node.
    """
    parent = np.arange(n)
    for e in range(pairs.shape[0]):
        a = pairs[e, 0]
        b = pairs[e, 1]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    comp = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        r = i
        while parent[r] != r:
            r = parent[r]
        if r == i:
            comp[i] = count
            count += 1
        else:
            comp[i] = comp[r]
    return comp


def euclidean_clusters(
    cloud: PointCloud,
    tolerance: float,
    min_size: int = 1,
    max_size: int | None = None,
) -> np.ndarray:
    """Label the Euclidean clusters of ``cloud``.

    Parameters
    ----------
    cloud : PointCloud
    tolerance : float
        Largest gap inside a cluster (> 0), PCL's ``setClusterTolerance``.
    min_size, max_size : int
        Clusters with fewer than ``min_size`` or more than ``max_size`` points are
        rejected (label -1), as in PCL.

    Returns
    -------
    (N,) int64 ndarray
        Cluster label per point: ``0 .. n-1`` ordered by decreasing size (ties by first
        point), ``-1`` for rejected clusters and non-finite points.
    """
    check_cloud(cloud)
    # the k-d tree squares coordinate differences: 1e150 keeps them below float64's max
    check_magnitude(cloud.points, "cloud.points", 1e150)
    tol = check_real(tolerance, "tolerance", 0.0, 1e150, low_inclusive=False)
    min_size = check_int(min_size, "min_size", 1)
    max_size = max(len(cloud), 1) if max_size is None else check_int(max_size, "max_size", 1)
    if max_size < min_size:
        raise InputError(f"max_size ({max_size}) must be >= min_size ({min_size})")
    labels = np.full(len(cloud), -1, dtype=np.int64)
    fin = np.flatnonzero(cloud.finite_mask())
    if fin.size == 0:
        return labels
    pts = cloud.points[fin]
    pairs = cKDTree(pts).query_pairs(tol, output_type="ndarray")
    comp = _components(pts.shape[0], pairs)
    sizes = np.bincount(comp)
    # order: decreasing size, then by first point (component ids follow first points)
    order = np.lexsort((np.arange(sizes.size), -sizes))
    ok = (sizes[order] >= min_size) & (sizes[order] <= max_size)
    new = np.full(sizes.size, -1, dtype=np.int64)
    new[order[ok]] = np.arange(int(ok.sum()))
    labels[fin] = new[comp]
    return labels
