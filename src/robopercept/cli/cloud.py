"""``robopercept cloud``: a point-cloud processing pipeline from the command line."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, flag_errors, image_output, numbers, pass_through

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``cloud`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "cloud",
        help="filter, segment planes and cluster a point cloud (PLY/PCD)",
        description="Run the steps given, in this order: pass-through, voxel grid, "
        "statistical outlier removal, plane extraction, Euclidean clustering. Prints a "
        "summary and writes a PLY or PCD coloured by segment (planes, then clusters; grey: "
        "unassigned) with each point's segment in a 'label' field (0 unassigned, 1..P the "
        "planes, P+1.. the clusters; PCL's PointXYZRGBL layout in PCD).",
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
        "--image",
        type=image_output,
        default=None,
        metavar="PNG",
        help="also render the coloured cloud to an image (.png, .jpg, ...)",
    )
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")
    p.add_argument("--json", action="store_true", help="machine-readable summary on stdout")
    p.set_defaults(func=run_cloud)


@flag_errors(
    voxel_size="--voxel",
    k="--sor K",
    std_ratio="--sor STD_RATIO",
    max_planes="--planes N",
    threshold="--planes THRESHOLD",
    min_inliers="--min-plane",
    tolerance="--clusters TOL",
    min_size="--clusters MIN",
    max_size="--clusters MAX",
    min_value="--pass-through MIN",
    max_value="--pass-through MAX",
)
def run_cloud(args: argparse.Namespace) -> int:
    """Run ``robopercept cloud`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.pipelines.cloud import process_cloud
    from robopercept.pointcloud import read_point_cloud, write_point_cloud
    from robopercept.viz.colormap import label_colors

    out = Path(args.output)
    if out.suffix.lower() not in (".ply", ".pcd"):
        raise UsageError(f"output must end in .ply or .pcd; got {out.name}")
    t0 = time.perf_counter()
    cloud = read_point_cloud(args.input)
    read_ms = (time.perf_counter() - t0) * 1e3
    res = process_cloud(
        cloud,
        boxes=args.pass_through,
        voxel=args.voxel,
        sor=args.sor,
        planes=args.planes,
        min_plane=args.min_plane,
        clusters=args.clusters,
        rng=args.seed,
    )
    res.steps[0]["ms"] = round(res.steps[0]["ms"] + read_ms, 2)  # the read step reads too
    cloud = res.cloud
    colors = label_colors(res.segment, background=(128, 128, 128)).astype(np.float64) / 255.0
    segmented = args.planes is not None or args.clusters is not None
    if not segmented and cloud.colors is not None:
        colors = cloud.colors
    labels = res.segment if segmented else cloud.labels
    write_point_cloud(out, cloud.with_colors(colors).with_labels(labels))
    names: dict[int, str] = {}
    if segmented:
        n_planes = len(res.planes)
        names = {
            0: "unassigned",
            **{i + 1: f"plane {i + 1}" for i in range(n_planes)},
            **{n_planes + j + 1: f"cluster {j + 1}" for j in range(len(res.cluster_sizes))},
        }
    if args.image:
        from robopercept.imaging import write_image
        from robopercept.viz import render_points

        legend = None
        if segmented:  # each segment's colour named beside the render
            ids = np.array(sorted(names))
            legend = [
                (names[int(k)], tuple(int(v) for v in c))
                for k, c in zip(ids, label_colors(ids, background=(128, 128, 128)), strict=True)
            ]
        write_image(args.image, render_points(cloud.points, colors, legend=legend))
    summary: dict[str, Any] = {"input": str(args.input), "output": str(out), "steps": res.steps}
    summary["label_field"] = labels is not None
    if segmented:
        summary["labels"] = {str(k): v for k, v in names.items()}
    if args.image:
        summary["image"] = str(args.image)
    if args.json:
        json.dump(summary, sys.stdout, indent=2)
        print()
        return 0
    print(f"{'step':<34} {'in':>9} {'out':>9} {'ms':>9}")
    for s in res.steps:
        print(f"{s['step']:<34} {s['points_in']:>9} {s['points_out']:>9} {s['ms']:>9.1f}")
    for i, pl in enumerate(res.planes):
        a, b, c, d = pl["equation"]
        print(
            f"plane {i + 1}: {a:+.4f} x {b:+.4f} y {c:+.4f} z {d:+.4f} = 0, {pl['inliers']} points"
        )
    if res.cluster_sizes:
        print(f"clusters: {len(res.cluster_sizes)}, sizes {res.cluster_sizes}")
    if segmented:
        listed = ", ".join(f"{k} {v}" for k, v in summary["labels"].items())
        print(f"label field: {listed}")
    print(f"wrote {out}" + (f" and {args.image}" if args.image else ""))
    return 0
