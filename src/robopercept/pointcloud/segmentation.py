"""Plane segmentation with the RANSAC engine: one plane, or several one after another.

Conventions kept by both functions, so that repeated calls and comparisons with Open3D
are simple:

* **Seed.** The default ``rng=0`` is a fixed seed: two calls with the default arguments
  give the same plane and inliers (Open3D's ``segment_plane`` draws from a global engine
  seeded at random unless ``open3d.utility.random.seed`` is called). ``rng=None`` asks
  for fresh entropy, an int or a Generator for another stream.
* **Sign.** The plane ``n . x + d = 0`` is reported with ``d >= 0``: the normal points
  to the side of the plane holding the origin (the sensor, for a cloud in its camera
  frame), whose signed distance from the plane, ``d``, is then non-negative. A plane
  through the origin (``d == 0``) has the first non-zero component of ``n`` positive.
  Open3D's sign is arbitrary; bring its ``(a, b, c, d)`` to this rule with
  ``eq * (1 if eq[3] >= 0 else -1)``.
* **Open3D's keywords.** ``distance_threshold``, ``ransac_n`` and ``num_iterations``
  are accepted as keyword-only aliases of ``threshold``, ``sample_size`` and
  ``max_iterations``; giving both spellings of one is an InputError.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robopercept._checks import (
    as_rng,
    check_int,
    check_magnitude,
    check_real,
    resolve_alias,
)
from robopercept.errors import DegenerateError, InputError
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


def _check(cloud: PointCloud, threshold: float | None, distance_threshold: float | None) -> float:
    """``threshold`` (or Open3D's ``distance_threshold``) as a float after checking it and
    the cloud: a PointCloud whose finite coordinates stay within 1e70 (the minimal plane
    fit multiplies squared edge lengths, a fourth power of the coordinates, which must
    stay below float64's 1.8e308)."""
    check_cloud(cloud)
    threshold = resolve_alias(threshold, "threshold", distance_threshold, "distance_threshold")
    if threshold is None:
        raise InputError(
            "threshold is required: the largest point-to-plane distance of an inlier, in "
            "the cloud's units (e.g. segment_plane(cloud, 0.01) for 1 cm); Open3D's "
            "distance_threshold= is accepted too"
        )
    check_magnitude(cloud.points, "cloud.points", 1e70)
    return check_real(threshold, "threshold", 0.0, low_inclusive=False)


def _iterations(max_iterations: int | None, num_iterations: int | None) -> int:
    """``max_iterations`` or Open3D's ``num_iterations`` (default 1000)."""
    value = resolve_alias(max_iterations, "max_iterations", num_iterations, "num_iterations")
    return 1000 if value is None else value


def _oriented(plane: Plane) -> Plane:
    """``plane`` itself or ``plane.flipped()``, whichever has :func:`segment_plane`'s sign:
    ``d >= 0`` (the normal points towards the origin's side), and for ``d == 0`` the first
    non-zero component of the normal positive."""
    d = float(plane.offset)
    if d > 0.0:
        return plane
    if d < 0.0:
        return plane.flipped()
    nonzero = np.flatnonzero(plane.normal)
    if nonzero.size and plane.normal[nonzero[0]] < 0:
        return plane.flipped()
    return plane


def segment_plane(
    cloud: PointCloud,
    threshold: float | None = None,
    *,
    probability: float = 0.99,
    max_iterations: int | None = None,
    sample_size: int | None = None,
    scoring: str = "ransac",
    local_optimization: bool = False,
    rng: int | np.random.Generator | None = 0,
    distance_threshold: float | None = None,
    ransac_n: int | None = None,
    num_iterations: int | None = None,
) -> tuple[Plane, np.ndarray]:
    """The dominant plane of ``cloud`` by RANSAC (:func:`~robopercept.estimation.ransac`
    with :class:`~robopercept.estimation.PlaneModel` and a least-squares refit).

    The counterpart of Open3D's ``segment_plane(distance_threshold, ransac_n,
    num_iterations, probability)``, whose keyword names are accepted too (see the
    module docstring); both return ``((a, b, c, d), inliers)``. Two differences: the
    default seed is fixed (``rng=0``: the same plane on every call; Open3D seeds its
    engine at random), and the sign is fixed (``d >= 0``, the normal pointing towards
    the origin's side; Open3D's is arbitrary). The stopping rule is the adaptive RANSAC
    bound at ``probability`` (Open3D's default 0.99999999 runs nearly all
    ``num_iterations``). Non-finite points are ignored (they are never inliers).

    Parameters
    ----------
    cloud : PointCloud
    threshold : float
        Largest point-to-plane distance of an inlier (> 0). Open3D's spelling:
        ``distance_threshold=``.
    probability : float
        Confidence of the adaptive stopping rule.
    max_iterations : int, default 1000
        Open3D's spelling: ``num_iterations=``.
    sample_size : int, default 3
        Points per RANSAC sample (more than 3 are fitted by least squares). Open3D's
        spelling: ``ransac_n=``.
    scoring : {'ransac', 'msac'}
    local_optimization : bool
    rng : int, Generator or None, default 0
        A fixed seed by default, so repeated calls agree; None for fresh entropy.
    distance_threshold, ransac_n, num_iterations
        Keyword-only aliases (Open3D's names) of ``threshold``, ``sample_size`` and
        ``max_iterations``.

    Returns
    -------
    plane : Plane
        ``plane.equation`` is Open3D's ``(a, b, c, d)``, with ``d >= 0``.
    inliers : (M,) int64 ndarray
        Positions in ``cloud``, increasing.

    Raises
    ------
    DegenerateError
        Fewer than 3 (or ``sample_size``) finite points, or all of them collinear.
    InputError
        Not a PointCloud, a missing threshold or one that is not a positive number,
        both spellings of one keyword, or coordinates beyond 1e70 in magnitude
        (rescale the cloud).

    Examples
    --------
    A floor 2 m below a camera (y down): the normal points up, towards the camera.

    >>> from robopercept.pointcloud import PointCloud
    >>> xz = np.random.default_rng(1).uniform(-1, 1, (200, 2))
    >>> floor = PointCloud(np.column_stack([xz[:, 0], np.full(200, 2.0), xz[:, 1] + 3]))
    >>> plane, inliers = segment_plane(floor, distance_threshold=0.01)
    >>> (np.round(plane.equation, 6) + 0.0).tolist(), inliers.size
    ([0.0, -1.0, 0.0, 2.0], 200)
    """
    threshold = _check(cloud, threshold, distance_threshold)
    iterations = _iterations(max_iterations, num_iterations)
    sample_size = resolve_alias(sample_size, "sample_size", ransac_n, "ransac_n")
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
        sample_size=sample_size,
        probability=probability,
        max_iterations=iterations,
        scoring=scoring,  # type: ignore[arg-type]
        local_optimization=local_optimization,
        rng=rng,
    )
    inliers = np.flatnonzero(res.inliers)
    return _oriented(res.model), (inliers if fin is None else fin[inliers])


def segment_planes(
    cloud: PointCloud,
    threshold: float | None = None,
    max_planes: int = 3,
    min_inliers: int = 100,
    *,
    probability: float = 0.99,
    max_iterations: int | None = None,
    rng: int | np.random.Generator | None = 0,
    distance_threshold: float | None = None,
    num_iterations: int | None = None,
) -> list[PlaneSegment]:
    """Extract up to ``max_planes`` planes, largest first.

    Repeats :func:`segment_plane` on the points not yet assigned, stopping when
    ``max_planes`` are found, when the best plane has fewer than ``min_inliers`` points,
    or when fewer than 3 points (or only collinear ones) remain. Each plane follows
    :func:`segment_plane`'s sign convention (``d >= 0``).

    Parameters
    ----------
    cloud : PointCloud
    threshold : float
        Open3D's spelling: ``distance_threshold=``.
    max_planes : int
    min_inliers : int
    probability, max_iterations, rng
        As in :func:`segment_plane` (a fixed seed by default); one generator serves all
        the planes. ``num_iterations=`` is Open3D's spelling of ``max_iterations``.
    distance_threshold, num_iterations
        Keyword-only aliases (Open3D's names) of ``threshold`` and ``max_iterations``.

    Returns
    -------
    list of PlaneSegment
        Disjoint inlier sets (positions in ``cloud``).
    """
    threshold = _check(cloud, threshold, distance_threshold)
    iterations = _iterations(max_iterations, num_iterations)
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
                max_iterations=iterations,
                rng=gen,
            )
        except DegenerateError:
            break
        if res.n_inliers < min_inliers:
            break
        found.append(PlaneSegment(_oriented(res.model), remaining[res.inliers], res.n_iterations))
        remaining = remaining[~res.inliers]
    return found
