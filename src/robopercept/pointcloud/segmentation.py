"""Plane segmentation with the RANSAC engine: one plane, or several one after another."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robopercept._checks import as_rng, check_int, check_magnitude, check_real
from robopercept.errors import DegenerateError
from robopercept.estimation import Plane, PlaneModel, ransac
from robopercept.pointcloud.cloud import PointCloud, check_cloud

__all__ = ["PlaneSegment", "segment_plane", "segment_planes"]


@dataclass(frozen=True)
class PlaneSegment:
    """One plane found by :func:`segment_planes`.

    Attributes
    ----------
    plane : Plane
    inliers : (M,) int64 ndarray
        Positions in the input cloud.
    n_iterations : int
        RANSAC samples drawn.
    """

    plane: Plane
    inliers: np.ndarray
    n_iterations: int


def _check(cloud: PointCloud, threshold: float) -> float:
    """``threshold`` as a float after checking it and the cloud: a PointCloud whose finite
    coordinates stay within 1e70 (the minimal plane fit multiplies squared edge lengths,
    a fourth power of the coordinates, which must stay below float64's 1.8e308)."""
    check_cloud(cloud)
    check_magnitude(cloud.points, "cloud.points", 1e70)
    return check_real(threshold, "threshold", 0.0, low_inclusive=False)


def segment_plane(
    cloud: PointCloud,
    threshold: float,
    *,
    probability: float = 0.99,
    max_iterations: int = 1000,
    scoring: str = "ransac",
    local_optimization: bool = False,
    rng: int | np.random.Generator | None = None,
) -> tuple[Plane, np.ndarray]:
    """The dominant plane of ``cloud`` by RANSAC (:func:`~robopercept.estimation.ransac`
    with :class:`~robopercept.estimation.PlaneModel` and a least-squares refit).

    The counterpart of Open3D's ``segment_plane(distance_threshold, 3, num_iterations,
    probability)``. Non-finite points are ignored (they are never inliers).

    Parameters
    ----------
    cloud : PointCloud
    threshold : float
        Largest point-to-plane distance of an inlier (> 0).
    probability : float
        Confidence of the adaptive stopping rule.
    max_iterations : int
    scoring : {'ransac', 'msac'}
    local_optimization : bool
    rng : int, Generator or None

    Returns
    -------
    plane : Plane
        ``plane.equation`` is Open3D's ``(a, b, c, d)``.
    inliers : (M,) int64 ndarray
        Positions in ``cloud``, increasing.

    Raises
    ------
    DegenerateError
        Fewer than 3 finite points, or all of them collinear.
    InputError
        Not a PointCloud, a threshold that is not a positive number, or coordinates
        beyond 1e70 in magnitude (rescale the cloud).
    """
    threshold = _check(cloud, threshold)
    finite = cloud.finite_mask()
    n_fin = int(np.count_nonzero(finite))
    if n_fin < 3:
        raise DegenerateError(
            f"a plane needs 3 finite points; the cloud has {n_fin} "
            f"({len(cloud) - n_fin} non-finite dropped)"
        )
    # all finite (the usual case): no index array, no copy of the points
    fin = None if n_fin == len(cloud) else np.flatnonzero(finite)
    pts = cloud.points if fin is None else cloud.points[fin]
    res = ransac(
        pts,
        PlaneModel(),
        threshold,
        probability=probability,
        max_iterations=max_iterations,
        scoring=scoring,  # type: ignore[arg-type]
        local_optimization=local_optimization,
        rng=rng,
    )
    inliers = np.flatnonzero(res.inliers)
    return res.model, (inliers if fin is None else fin[inliers])


def segment_planes(
    cloud: PointCloud,
    threshold: float,
    max_planes: int = 3,
    min_inliers: int = 100,
    *,
    probability: float = 0.99,
    max_iterations: int = 1000,
    rng: int | np.random.Generator | None = None,
) -> list[PlaneSegment]:
    """Extract up to ``max_planes`` planes, largest first.

    Repeats :func:`segment_plane` on the points not yet assigned, stopping when
    ``max_planes`` are found, when the best plane has fewer than ``min_inliers`` points,
    or when fewer than 3 points (or only collinear ones) remain.

    Parameters
    ----------
    cloud : PointCloud
    threshold : float
    max_planes : int
    min_inliers : int
    probability, max_iterations, rng
        As in :func:`segment_plane`; one generator serves all the planes.

    Returns
    -------
    list of PlaneSegment
        Disjoint inlier sets (positions in ``cloud``).
    """
    threshold = _check(cloud, threshold)
    max_planes = check_int(max_planes, "max_planes", 1)
    min_inliers = check_int(min_inliers, "min_inliers", 3)
    gen = as_rng(rng)
    remaining = np.flatnonzero(cloud.finite_mask())
    found: list[PlaneSegment] = []
    while len(found) < max_planes and remaining.size >= max(3, min_inliers):
        try:
            res = ransac(
                cloud.points[remaining],
                PlaneModel(),
                threshold,
                probability=probability,
                max_iterations=max_iterations,
                rng=gen,
            )
        except DegenerateError:
            break
        if res.n_inliers < min_inliers:
            break
        found.append(PlaneSegment(res.model, remaining[res.inliers], res.n_iterations))
        remaining = remaining[~res.inliers]
    return found
