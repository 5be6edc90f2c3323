"""``robopercept cloud``: a point-cloud processing pipeline from the command line."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from robopercept.cli._args import UsageError, numbers, pass_through

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``cloud`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "cloud",
        help="filter, segment planes and cluster a point cloud (PLY/PCD)",
        description="Run the steps given, in this order: pass-through, voxel grid, "
        "statistical outlier removal, plane extraction, Euclidean clustering. Prints a "
        "summary and writes a PLY coloured by segment (planes, then clusters; grey: "
        "unassigned).",
    )
    p.add_argument("input", help="input .ply or .pcd")
    p.add_argument("-o", "--output", default="segments.ply", help="output .ply or .pcd")
    p.add_argument(
        "--pass-through",
        type=pass_through,
        action="append",
        default=[],
        metavar="AXIS:MIN:MAX",
        help="keep points with MIN <= AXIS <= MAX (metres; repeatable)",
    )
    p.add_argument("--voxel", type=float, default=None, metavar="SIZE", help="voxel size (m)")
    p.add_argument(
        "--sor",
        type=numbers((int, float), "K:STD_RATIO"),
        default=None,
        metavar="K:STD_RATIO",
        help="statistical outlier removal (e.g. 50:1.0)",
    )
    p.add_argument(
        "--planes",
        type=numbers((int, float), "N:THRESHOLD"),
        default=None,
        metavar="N:THRESHOLD",
        help="extract up to N planes with a RANSAC threshold in metres (e.g. 1:0.01)",
    )
    p.add_argument(
        "--min-plane", type=int, default=100, help="smallest plane kept (points; default 100)"
    )
    p.add_argument(
        "--clusters",
        type=numbers((float, int, int), "TOL:MIN:MAX"),
        default=None,
        metavar="TOL:MIN:MAX",
        help="Euclidean clusters of the points off the planes (e.g. 0.02:100:25000)",
    )
    p.add_argument(
        "--image", default=None, metavar="PNG", help="also render the coloured cloud to a PNG"
    )
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    p.set_defaults(func=run_cloud)


def run_cloud(args: argparse.Namespace) -> int:
    """Run ``robopercept cloud`` with the parsed ``args``; returns the exit status."""
    from robopercept.pointcloud import (
        euclidean_clusters,
        pass_through,
        read_point_cloud,
        segment_planes,
        statistical_outlier_removal,
        voxel_downsample,
        write_point_cloud,
    )
    from robopercept.viz.colormap import label_colors

    out = Path(args.output)
    if out.suffix.lower() not in (".ply", ".pcd"):
        raise UsageError(f"output must end in .ply or .pcd; got {out.name}")
    steps: list[dict[str, Any]] = []

    def step(name: str, n_in: int, n_out: int, t0: float, **extra: Any) -> None:
        steps.append(
            {
                "step": name,
                "points_in": n_in,
                "points_out": n_out,
                "ms": round((time.perf_counter() - t0) * 1e3, 2),
                **extra,
            }
        )

    t0 = time.perf_counter()
    cloud = read_point_cloud(args.input)
    n_read = len(cloud)
    cloud = cloud.finite()
    step("read", n_read, len(cloud), t0, nonfinite_dropped=n_read - len(cloud))
    for axis, lo, hi in args.pass_through:
        t0 = time.perf_counter()
        n = len(cloud)
        cloud, _ = pass_through(cloud, axis, lo, hi)
        step(f"pass-through {axis} [{lo:g}, {hi:g}]", n, len(cloud), t0)
    if args.voxel is not None:
        t0 = time.perf_counter()
        n = len(cloud)
        cloud, _ = voxel_downsample(cloud, args.voxel)
        step(f"voxel {args.voxel:g}", n, len(cloud), t0)
    if args.sor is not None:
        t0 = time.perf_counter()
        n = len(cloud)
        cloud, _ = statistical_outlier_removal(cloud, *args.sor)
        step(f"sor k={args.sor[0]} std={args.sor[1]:g}", n, len(cloud), t0)

    segment = np.zeros(len(cloud), dtype=np.int64)  # 0 unassigned, 1.. planes then clusters
    planes_out: list[dict[str, Any]] = []
    if args.planes is not None:
        t0 = time.perf_counter()
        n_planes, thr = args.planes
        found = segment_planes(
            cloud, thr, max_planes=n_planes, min_inliers=args.min_plane, rng=args.seed
        )
        for i, seg in enumerate(found):
            segment[seg.inliers] = i + 1
            planes_out.append(
                {
                    "equation": [round(float(v), 6) for v in seg.plane.equation],
                    "inliers": int(seg.inliers.size),
                    "iterations": seg.n_iterations,
                }
            )
        step(
            f"planes (threshold {thr:g})",
            len(cloud),
            int(np.count_nonzero(segment == 0)),
            t0,
            planes=planes_out,
        )
    clusters_out: list[int] = []
    if args.clusters is not None:
        t0 = time.perf_counter()
        tol, cmin, cmax = args.clusters
        free = np.flatnonzero(segment == 0)
        labels = euclidean_clusters(cloud.select(free), tol, cmin, cmax)
        base = len(planes_out) + 1
        segment[free[labels >= 0]] = labels[labels >= 0] + base
        clusters_out = np.bincount(labels[labels >= 0]).tolist() if (labels >= 0).any() else []
        step(
            f"clusters (tol {tol:g}, {cmin}..{cmax})",
            int(free.size),
            int(sum(clusters_out)),
            t0,
            cluster_sizes=clusters_out,
        )

    colors = label_colors(segment, background=(128, 128, 128)).astype(np.float64) / 255.0
    if args.planes is None and args.clusters is None and cloud.colors is not None:
        colors = cloud.colors
    write_point_cloud(out, cloud.with_colors(colors))
    if args.image:
        from robopercept.imaging import write_image
        from robopercept.viz import render_points

        write_image(args.image, render_points(cloud.points, colors))
    summary = {"input": str(args.input), "output": str(out), "steps": steps}
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        print()
        return 0
    print(f"{'step':<34} {'in':>9} {'out':>9} {'ms':>9}")
    for s in steps:
        print(f"{s['step']:<34} {s['points_in']:>9} {s['points_out']:>9} {s['ms']:>9.1f}")
    for i, pl in enumerate(planes_out):
        a, b, c, d = pl["equation"]
        print(
            f"plane {i + 1}: {a:+.4f} x {b:+.4f} y {c:+.4f} z {d:+.4f} = 0, {pl['inliers']} points"
        )
    if clusters_out:
        print(f"clusters: {len(clusters_out)}, sizes {clusters_out}")
    print(f"wrote {out}" + (f" and {args.image}" if args.image else ""))
    return 0
