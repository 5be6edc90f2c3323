"""A point-cloud processing pipeline: filters, then plane extraction, then clusters.

The steps run in a fixed order, each one optional: drop non-finite points, pass-through
boxes, voxel grid, statistical outlier removal, RANSAC planes (largest first), Euclidean
clusters of the points left off the planes. Every point ends with a segment label:
0 unassigned, ``1..P`` the planes, ``P+1..`` the clusters (the PCL tutorial's
"planar segmentation, then cluster extraction" recipe).

A step that leaves no point at all (a pass-through box beside the cloud, a cloud with
no finite point) stops the pipeline with an
:class:`~robopercept.errors.EmptyResultError` naming the step and what the cloud held,
rather than returning an empty result that would be written as an empty file; clusters
and planes may find nothing (every point then keeps label 0).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from robopercept._checks import check_int, check_real, plain_repr
from robopercept.errors import EmptyResultError, InputError
from robopercept.pointcloud import (
    PointCloud,
    euclidean_clusters,
    pass_through,
    segment_planes,
    statistical_outlier_removal,
    voxel_downsample,
)
from robopercept.pointcloud.cloud import check_cloud

__all__ = ["CloudProcessing", "process_cloud"]


@dataclass(frozen=True)
class CloudProcessing:
    """Result of :func:`process_cloud`.

    Attributes
    ----------
    cloud : PointCloud
        The filtered cloud (the points the labels refer to).
    segment : (N,) int64
        0 unassigned, ``1..len(planes)`` the planes, then the clusters.
    steps : list of dict
        One record per step: ``step`` (its name), ``points_in``, ``points_out``, ``ms``
        and step-specific fields (``nonfinite_dropped``, ``planes``, ``cluster_sizes``).
    planes : list of dict
        ``equation`` (a, b, c, d of ax + by + cz + d = 0), ``inliers``, ``iterations``.
    cluster_sizes : list of int
        Points per cluster, in label order.
    """

    cloud: PointCloud
    segment: np.ndarray
    steps: list[dict[str, Any]]
    planes: list[dict[str, Any]]
    cluster_sizes: list[int]


def _seq(value: Any) -> list[Any]:
    """``boxes`` as a list after checking that it is a list or tuple."""
    if not isinstance(value, (list, tuple)):
        raise InputError(
            f"boxes must be a list of (axis, low, high) tuples; got {type(value).__name__}"
        )
    return list(value)


def _parts(value: Any, name: str, n: int, form: str) -> tuple[Any, ...]:
    """``value`` as a tuple after checking that it is a list or tuple of ``n`` items."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise InputError(f"{name} must be {form}, {n} values; got {plain_repr(value)}")
    return tuple(value)


def _emptied(name: str, box: bool, params: tuple, cloud: PointCloud) -> str:
    """The message of a filter step ``name`` that removed all points of ``cloud``."""
    n = len(cloud)
    if not box:
        return f"{name} removed all {n} points: nothing is left to process or write"
    axis, lo, hi = params
    values = cloud.points[:, "xyz".index(axis)]
    return (
        f"{name} (--pass-through {axis}:{lo:g}:{hi:g}) removed all {n} points: the cloud's "
        f"{axis} spans {values.min():.4g} to {values.max():.4g}; nothing is left to process "
        "or write: choose a range that overlaps it"
    )


def process_cloud(
    cloud: PointCloud,
    *,
    boxes: Sequence[tuple[Literal["x", "y", "z"], float, float]] = (),
    voxel: float | None = None,
    sor: tuple[int, float] | None = None,
    planes: tuple[int, float] | None = None,
    min_plane: int = 100,
    clusters: tuple[float, int, int] | None = None,
    rng: int | np.random.Generator | None = 0,
) -> CloudProcessing:
    """Run the pipeline on ``cloud`` (each step optional, in the module's order).

    Parameters
    ----------
    cloud : PointCloud
    boxes : sequence of (axis, low, high)
        Pass-through filters (:func:`~robopercept.pointcloud.pass_through`), applied in turn.
    voxel : float, optional
        Voxel size for :func:`~robopercept.pointcloud.voxel_downsample`.
    sor : (k, std_ratio), optional
        :func:`~robopercept.pointcloud.statistical_outlier_removal`.
    planes : (max_planes, threshold), optional
        :func:`~robopercept.pointcloud.segment_planes`, planes of at least ``min_plane``
        inliers.
    clusters : (tolerance, min_size, max_size), optional
        :func:`~robopercept.pointcloud.euclidean_clusters` of the points off the planes.
    rng : int, Generator or None
        Seed of the plane RANSAC.

    Returns
    -------
    CloudProcessing

    Raises
    ------
    InputError
        ``cloud`` not a PointCloud, or a step's parameters of the wrong type, number or
        range (checked before any step runs; named as the steps name them, ``voxel_size``,
        ``k``, ``std_ratio``, ``max_planes``, ``threshold``, ``min_inliers``,
        ``tolerance``, ``min_size``, ``max_size``, ``min_value``, ``max_value``).
    EmptyResultError
        ``cloud`` has no finite point, or a filter step removed every point (the message
        names the step and, for a pass-through box, the cloud's extent along its axis):
        there is nothing to segment or write. PCL's ``PassThrough`` and Open3D's
        ``crop`` return the empty cloud instead; here an empty result is always a
        mistake in the parameters (metres vs millimetres, a swapped range).

    Examples
    --------
    >>> from robopercept.pointcloud import PointCloud
    >>> cloud = PointCloud(np.random.default_rng(0).uniform(0, 1, (100, 3)))
    >>> res = process_cloud(cloud, boxes=[("z", 0.0, 0.5)])
    >>> res.steps[1]["points_in"], res.steps[1]["points_out"] > 0
    (100, True)
    >>> process_cloud(cloud, boxes=[("z", 5.0, 6.0)])
    Traceback (most recent call last):
    ...
    robopercept.errors.EmptyResultError: pass-through z [5, 6] ... removed all 100 points...
    """
    check_cloud(cloud)
    boxes = [_parts(b, "each pass-through box", 3, "(axis, low, high)") for b in _seq(boxes)]
    boxes = [(a, check_real(lo, "min_value"), check_real(hi, "max_value")) for a, lo, hi in boxes]
    if voxel is not None:
        voxel = check_real(voxel, "voxel_size", 0.0, low_inclusive=False)
    if sor is not None:
        k, ratio = _parts(sor, "sor", 2, "(k, std_ratio)")
        sor = (check_int(k, "k", 2), check_real(ratio, "std_ratio", 0.0))
    min_plane = check_int(min_plane, "min_inliers", 3)
    if planes is not None:
        n, thr = _parts(planes, "planes", 2, "(max_planes, threshold)")
        planes = (
            check_int(n, "max_planes", 1),
            check_real(thr, "threshold", 0.0, low_inclusive=False),
        )
    if clusters is not None:
        tol, cmin, cmax = _parts(clusters, "clusters", 3, "(tolerance, min_size, max_size)")
        clusters = (
            check_real(tol, "tolerance", 0.0, low_inclusive=False),
            check_int(cmin, "min_size", 1),
            check_int(cmax, "max_size", 1),
        )
    steps: list[dict[str, Any]] = []

    def step(name: str, n_in: int, n_out: int, t0: float, **extra: Any) -> None:
        ms = round((time.perf_counter() - t0) * 1e3, 2)
        steps.append({"step": name, "points_in": n_in, "points_out": n_out, "ms": ms, **extra})

    t0 = time.perf_counter()
    n_read = len(cloud)
    cloud = cloud.finite()
    step("read", n_read, len(cloud), t0, nonfinite_dropped=n_read - len(cloud))
    if len(cloud) == 0:
        raise EmptyResultError(
            f"the cloud holds no finite point ({n_read} read, {n_read} not finite): nothing "
            "to process or write"
            if n_read
            else "the cloud holds no point: nothing to process or write"
        )
    filters: list[tuple[str, Any, tuple]] = [
        (f"pass-through {a} [{lo:g}, {hi:g}]", pass_through, (a, lo, hi)) for a, lo, hi in boxes
    ]
    if voxel is not None:
        filters.append((f"voxel {voxel:g}", voxel_downsample, (voxel,)))
    if sor is not None:
        filters.append((f"sor k={sor[0]} std={sor[1]:g}", statistical_outlier_removal, sor))
    for name, fn, params in filters:
        t0, n = time.perf_counter(), len(cloud)
        kept, _ = fn(cloud, *params)
        step(name, n, len(kept), t0)
        if len(kept) == 0:
            raise EmptyResultError(_emptied(name, fn is pass_through, params, cloud))
        cloud = kept

    segment = np.zeros(len(cloud), dtype=np.int64)
    planes_out: list[dict[str, Any]] = []
    if planes is not None:
        t0 = time.perf_counter()
        n_planes, thr = planes
        found = segment_planes(cloud, thr, max_planes=n_planes, min_inliers=min_plane, rng=rng)
        for i, seg in enumerate(found):
            segment[seg.inliers] = i + 1
            planes_out.append(
                {
                    "equation": [round(float(v), 6) for v in seg.plane.equation],
                    "inliers": int(seg.inliers.size),
                    "iterations": seg.n_iterations,
                }
            )
        left = int(np.count_nonzero(segment == 0))
        step(f"planes (threshold {thr:g})", len(cloud), left, t0, planes=planes_out)
    sizes: list[int] = []
    if clusters is not None:
        t0 = time.perf_counter()
        tol, cmin, cmax = clusters
        free = np.flatnonzero(segment == 0)
        labels = euclidean_clusters(cloud.select(free), tol, cmin, cmax)
        kept = labels >= 0
        segment[free[kept]] = labels[kept] + len(planes_out) + 1
        sizes = np.bincount(labels[kept]).tolist() if kept.any() else []
        name = f"clusters (tol {tol:g}, {cmin}..{cmax})"
        step(name, int(free.size), int(sum(sizes)), t0, cluster_sizes=sizes)
    return CloudProcessing(cloud, segment, steps, planes_out, sizes)
