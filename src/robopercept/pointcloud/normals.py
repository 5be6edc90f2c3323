r"""Surface normals by PCA of each point's neighbourhood.

For the neighbours :math:`q_j` of a point, the covariance
:math:`C = \frac{1}{k} \sum_j (q_j - \bar q)(q_j - \bar q)^\top` has its smallest
eigenvalue along the surface normal; the normal is that eigenvector, flipped to face the
viewpoint :math:`v`: :math:`n^\top (v - p) \ge 0`. The curvature estimate
:math:`\lambda_0 / (\lambda_0 + \lambda_1 + \lambda_2)` is PCL's.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from robopercept._checks import check_int, check_real, check_reals
from robopercept.errors import InputError
from robopercept.pointcloud.cloud import PointCloud, check_cloud

__all__ = ["estimate_normals"]

_CHUNK = 65536
_PAIR_CHUNK = 1 << 21


def estimate_normals(
    cloud: PointCloud,
    k: int | None = 30,
    radius: float | None = None,
    viewpoint: tuple[float, float, float] | np.ndarray = (0.0, 0.0, 0.0),
) -> tuple[PointCloud, np.ndarray]:
    """Estimate unit normals oriented toward ``viewpoint``.

    Parameters
    ----------
    cloud : PointCloud
    k : int, optional
        Neighbours per point (the point included), >= 3. With ``radius`` as well, the
        ``k`` nearest within ``radius`` (Open3D's hybrid search).
    radius : float, optional
        Neighbourhood radius; alone, every point within it.
    viewpoint : (3,) array_like
        The sensor position; normals point toward it (camera frame: the origin).

    Returns
    -------
    cloud : PointCloud
        The input with ``normals`` set (NaN for non-finite points and for points with
        fewer than 3 neighbours).
    curvature : (N,) float ndarray
        Surface variation :math:`\\lambda_0 / \\sum \\lambda`.
    """
    check_cloud(cloud)
    if k is None and radius is None:
        raise InputError("give k, radius or both")
    if k is not None:
        k = check_int(k, "k", 3)
    if radius is not None:
        radius = check_real(radius, "radius", 0.0, low_inclusive=False)
    vp = check_reals(viewpoint, "viewpoint", 3)
    n = len(cloud)
    normals = np.full((n, 3), np.nan)
    curvature = np.full(n, np.nan)
    fin = np.flatnonzero(cloud.finite_mask())
    if fin.size < 3:
        return cloud.with_normals(normals), curvature
    pts = cloud.points[fin]
    tree = cKDTree(pts)
    out_n = np.full((pts.shape[0], 3), np.nan)
    out_c = np.full(pts.shape[0], np.nan)
    if k is not None:
        kk = min(k, pts.shape[0])
        for s in range(0, pts.shape[0], _CHUNK):
            q = pts[s : s + _CHUNK]
            ub = np.inf if radius is None else radius
            d, idx = tree.query(q, k=kk, distance_upper_bound=ub, workers=-1)
            valid = np.isfinite(d.reshape(q.shape[0], kk))
            idx = np.where(valid, idx.reshape(q.shape[0], kk), 0)
            nb = pts[idx]  # (m, k, 3)
            w = valid[..., None].astype(np.float64)
            cnt = w.sum(axis=1)  # (m, 1)
            mean = (nb * w).sum(axis=1) / np.maximum(cnt, 1)
            dev = (nb - mean[:, None]) * w
            cov = np.einsum("mki,mkj->mij", dev, dev) / np.maximum(cnt, 1)[:, :, None]
            _fill(cov, cnt[:, 0], out_n, out_c, s)
    else:
        # every pair closer than the radius, once (i < j); each point also counts itself
        pairs = tree.query_pairs(radius, output_type="ndarray")
        m = pts.shape[0]
        cnt = (
            np.ones(m)
            + np.bincount(pairs[:, 0], minlength=m)
            + np.bincount(pairs[:, 1], minlength=m)
        )
        m1 = np.zeros((m, 3))
        m2 = np.zeros((m, 6))
        upper = [(i, j) for i in range(3) for j in range(i, 3)]
        for s in range(0, pairs.shape[0], _PAIR_CHUNK):
            pi, pj = pairs[s : s + _PAIR_CHUNK, 0], pairs[s : s + _PAIR_CHUNK, 1]
            # offsets from each point to its neighbour: d for i, -d for j (moments about
            # the query point keep the sums well conditioned)
            d = pts[pj] - pts[pi]
            for c in range(3):
                m1[:, c] += np.bincount(pi, d[:, c], m) - np.bincount(pj, d[:, c], m)
            for c, (i, j) in enumerate(upper):
                w = d[:, i] * d[:, j]
                m2[:, c] += np.bincount(pi, w, m) + np.bincount(pj, w, m)
        m1 /= cnt[:, None]
        cov = np.empty((m, 3, 3))
        for c, (i, j) in enumerate(upper):
            cov[:, i, j] = cov[:, j, i] = m2[:, c] / cnt - m1[:, i] * m1[:, j]
        _fill(cov, cnt, out_n, out_c, 0)
    # orient toward the viewpoint
    flip = ((vp - pts) * out_n).sum(axis=1) < 0
    out_n[flip] *= -1
    normals[fin] = out_n
    curvature[fin] = out_c
    return cloud.with_normals(normals), curvature


def _fill(
    cov: np.ndarray, cnt: np.ndarray, out_n: np.ndarray, out_c: np.ndarray, start: int
) -> None:
    evals, evecs = np.linalg.eigh(cov)  # ascending
    ok = cnt >= 3
    stop = start + cov.shape[0]
    nrm = evecs[:, :, 0]
    total = evals.sum(axis=1)
    curv = np.divide(evals[:, 0], total, out=np.zeros_like(total), where=total > 0)
    out_n[start:stop] = np.where(ok[:, None], nrm, np.nan)
    out_c[start:stop] = np.where(ok, curv, np.nan)
