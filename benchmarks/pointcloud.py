"""Point-cloud processing against Open3D (issue 3), same inputs, one process.

Open3D runs with its default OpenMP threads and ours with cKDTree ``workers=-1``,
nanoflann ``n_jobs=4 * os.cpu_count()`` and numba's default threads (plane scoring):
both use the machine's 2 cores. Inputs: a synthetic
1M-point plane scene with known ground truth, and PCL's table scene (209,280 finite
points) from ../shared/data.

Statistical outlier removal's memory (issue 25) is measured in fresh processes
(:func:`sor_memory`): the peak resident memory (``ru_maxrss``) minus the resident memory
just before the call, on a shuffled 2M-point plane scene for both libraries, and on 20M
points when ``BENCH_SOR_20M=1`` is set (minutes on 2 cores; otherwise the last 20M
record in ``results/pointcloud.json`` is carried over with its date).
"""

from __future__ import annotations

import time
import tracemalloc
from pathlib import Path

import numpy as np
import open3d as o3d

from benchmarks._harness import Record, median_ms, paired_ms
from robopercept.estimation import Plane
from robopercept.pointcloud import (
    PointCloud,
    euclidean_clusters,
    read_point_cloud,
    segment_plane,
    statistical_outlier_removal,
    voxel_downsample,
)

TABLE = (
    Path(__file__).resolve().parents[2]
    / "shared/data/pointcloud/pcl/table_scene_mug_stereo_textured.pcd"
)
TRUE_PLANE = Plane.from_equation([0.2, -0.4, 1.0, -1.5])


def plane_scene(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n points, half on TRUE_PLANE (1 cm Gaussian noise), half uniform in a 10 m cube."""
    rng = np.random.default_rng(seed)
    m = n // 2
    inl = TRUE_PLANE.project(rng.uniform(-5, 5, (m, 3)))
    inl += rng.normal(0, 0.01, (m, 1)) * TRUE_PLANE.normal
    pts = np.vstack([inl, rng.uniform(-5, 5, (n - m, 3))])
    truth = np.zeros(n, dtype=bool)
    truth[:m] = True
    return pts, truth


def _sor_input(n: int, seed: int = 2) -> np.ndarray:
    """n points as in :func:`plane_scene`, made 1M at a time so that making them does
    not raise the process's peak memory much above the (n, 3) float64 cloud itself."""
    rng = np.random.default_rng(seed)
    pts = np.empty((n, 3))
    m = n // 2
    for start in range(0, n, 1_000_000):
        stop = min(n, start + 1_000_000)
        block = rng.uniform(-5, 5, (stop - start, 3))
        if start < m:
            k = min(stop, m) - start
            block[:k] = TRUE_PLANE.project(block[:k])
            block[:k] += rng.normal(0, 0.01, (k, 1)) * TRUE_PLANE.normal
        pts[start:stop] = block
    return pts


def _rss_mb() -> tuple[float, float]:
    """(current, peak) resident memory of this process in MiB (VmRSS, ru_maxrss)."""
    import resource

    with open("/proc/self/status") as fh:
        cur = next(int(ln.split()[1]) for ln in fh if ln.startswith("VmRSS:"))
    return cur / 1024, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def sor_child(which: str, n: int) -> None:
    """Run one statistical outlier removal (k = 50, std 1.0) on :func:`_sor_input` ``(n)``
    in this fresh process and print a JSON line: seconds, kept points, input MiB, the
    resident memory just before the call and the peak after it (``ru_maxrss``); extra =
    peak - before. ``which`` is ``'ours'`` or ``'open3d'``."""
    import json

    warm = PointCloud(_sor_input(5000, seed=3))
    pts = _sor_input(n)
    if which == "ours":
        statistical_outlier_removal(warm, 50, 1.0)  # JIT and thread pools, off the clock
        cloud = PointCloud(pts)
        call = lambda: len(statistical_outlier_removal(cloud, 50, 1.0)[1])  # noqa: E731
    else:
        warm.to_open3d().remove_statistical_outlier(50, 1.0)
        pc = PointCloud(pts).to_open3d()  # Open3D keeps its own copy of the points
        del pts
        call = lambda: len(pc.remove_statistical_outlier(50, 1.0)[1])  # noqa: E731
    before, _ = _rss_mb()
    t0 = time.perf_counter()
    kept = call()
    seconds = time.perf_counter() - t0
    _, peak = _rss_mb()
    out = {"seconds": seconds, "kept": kept, "input_mb": n * 24 / 2**20}
    print(json.dumps({**out, "rss_before_mb": before, "peak_mb": peak}))


def sor_memory(n: int, timeout: float = 3600, which: tuple[str, ...] = ("ours", "open3d")) -> dict:
    """:func:`sor_child` for ours and Open3D, each in a fresh process, one after the other."""
    import json
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    res = {}
    for lib in which:
        code = f"from benchmarks.pointcloud import sor_child; sor_child({lib!r}, {n})"
        done = subprocess.run(
            [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=timeout
        )
        if done.returncode != 0:
            res[lib] = {"error": f"exit {done.returncode}: {done.stderr[-300:]}"}
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        r["extra_mb"] = r["peak_mb"] - r["rss_before_mb"]
        res[lib] = r
    return res


def _sor_record(n: int, res: dict) -> Record:
    ours, ref = res["ours"], res.get("open3d", {})
    return Record(
        "statistical_outlier memory",
        f"{n / 1e6:g}M pts shuffled plane scene, k=50: extra peak RSS / input",
        ours["seconds"] * 1e3,
        ref["seconds"] * 1e3 if "seconds" in ref else float("nan"),
        "open3d remove_statistical_outlier (fresh process each); "
        "target at 20M: extra peak < 2x the input (peak < 3x)",
        "extra peak RSS / input (ours)",
        ours["extra_mb"] / ours["input_mb"],
        None,
        {
            "ours": ours,
            "open3d": ref or "not run (too slow on 2 cores)",
            # issue 25's target is for 20M points (at 2M the 128 MiB query block dominates)
            "meets_memory_target": ours["extra_mb"] < 2 * ours["input_mb"] if n >= 10**7 else None,
            "ref_extra_over_input": ref["extra_mb"] / ref["input_mb"]
            if "extra_mb" in ref
            else None,
            "same_kept_count": ref.get("kept") == ours["kept"] if ref else None,
            "measured": time.strftime("%Y-%m-%d"),
        },
    )


def _sor_memory_records() -> list[Record]:
    """2M points for both libraries; 20M with ``BENCH_SOR_20M=1`` (ours, and Open3D too
    with ``BENCH_SOR_20M=both``), else the last 20M record carried over."""
    import json
    import os

    recs = [_sor_record(2_000_000, sor_memory(2_000_000))]
    big = os.environ.get("BENCH_SOR_20M", "")
    if big:
        res = sor_memory(20_000_000, which=("ours", "open3d") if big == "both" else ("ours",))
        recs.append(_sor_record(20_000_000, res))
        return recs
    old = Path(__file__).resolve().parent / "results" / "pointcloud.json"
    if old.exists():
        for r in json.loads(old.read_text())["records"]:
            if r["name"] == "statistical_outlier memory" and r["case"].startswith("20M"):
                r.pop("ratio", None)
                r.pop("meets_target", None)
                recs.append(Record(**r))
    return recs


def _f1(found: np.ndarray, truth: np.ndarray) -> float:
    mask = np.zeros(truth.shape[0], dtype=bool)
    mask[found] = True
    return 2 * np.count_nonzero(mask & truth) / (np.count_nonzero(mask) + np.count_nonzero(truth))


def run(repeats: int = 30) -> tuple[list[Record], dict]:
    recs: list[Record] = []
    few = max(3, repeats // 6)

    # --- segment_plane, 1M points, 50% inliers, threshold 3 cm
    pts, truth = plane_scene(1_000_000)
    cloud = PointCloud(pts)
    pc = cloud.to_open3d()
    eq, ref_idx = pc.segment_plane(0.03, 3, 1000)
    ref_angle = np.degrees(Plane.from_equation(eq).angle_to(TRUE_PLANE))
    ref_f1 = _f1(np.asarray(ref_idx), truth)
    ref_ms = median_ms(lambda: pc.segment_plane(0.03, 3, 1000), few, warmup=1)
    for p in (0.99999999, 0.99):
        plane, idx = segment_plane(cloud, 0.03, probability=p, rng=0)
        recs.append(
            Record(
                "segment_plane",
                f"1M pts, 50% inliers, p={p:g}",
                median_ms(lambda p=p: segment_plane(cloud, 0.03, probability=p, rng=0), few),
                ref_ms,
                "open3d segment_plane(0.03, 3, 1000) [p=0.99999999]",
                "normal error deg (ours)",
                float(np.degrees(plane.angle_to(TRUE_PLANE))),
                0.2 if p == 0.99999999 else None,
                {
                    "ours_inlier_f1": _f1(idx, truth),
                    "ref_inlier_f1": ref_f1,
                    "ref_normal_error_deg": float(ref_angle),
                },
            )
        )

    # --- extra peak memory of segment_plane on 10M points
    big, _ = plane_scene(10_000_000, seed=1)
    big_cloud = PointCloud(big)
    segment_plane(big_cloud, 0.03, rng=0)  # compile / warm
    tracemalloc.start()
    t0 = time.perf_counter()
    plane, _ = segment_plane(big_cloud, 0.03, rng=0)
    seconds = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    recs.append(
        Record(
            "segment_plane memory",
            "10M pts: extra peak / cloud bytes",
            seconds * 1e3,
            float("nan"),
            "target: extra peak < 2x the cloud (tracemalloc)",
            "extra peak / cloud",
            peak / big.nbytes,
            None,
            {"cloud_mb": big.nbytes / 2**20, "extra_peak_mb": peak / 2**20},
        )
    )
    del big, big_cloud

    # --- table scene: SOR, voxel grid, Euclidean clusters
    table = read_point_cloud(TABLE).finite()
    tpc = table.to_open3d()
    _, ours_idx = statistical_outlier_removal(table, 50, 1.0)
    _, ref_idx = tpc.remove_statistical_outlier(50, 1.0)
    agree = 1 - np.setxor1d(ours_idx, np.asarray(ref_idx)).size / len(table)
    recs.append(
        Record(
            "statistical_outlier",
            "table scene 209k pts, k=50, std 1.0",
            *paired_ms(
                lambda: statistical_outlier_removal(table, 50, 1.0),
                lambda: tpc.remove_statistical_outlier(50, 1.0),
                2 * few + 1,
                warmup=1,
            ),
            "open3d remove_statistical_outlier",
            "kept-index agreement",
            float(agree),
            1.0,
        )
    )
    recs.extend(_sor_memory_records())
    for size in (0.005, 0.01):
        ours, _ = voxel_downsample(table, size)
        ref = tpc.voxel_down_sample(size)
        a = ours.points[np.lexsort(ours.points.T)]
        b = np.asarray(ref.points)
        b = b[np.lexsort(b.T)]
        err = float(np.abs(a - b).max()) if a.shape == b.shape else float("inf")
        recs.append(
            Record(
                "voxel_downsample",
                f"table scene, voxel {size * 1000:g} mm -> {len(ours)} pts",
                *paired_ms(
                    lambda size=size: voxel_downsample(table, size),
                    lambda size=size: tpc.voxel_down_sample(size),
                    repeats,
                ),
                "open3d voxel_down_sample",
                "max centroid diff m",
                err,
                2.0,
            )
        )
    _, inl = segment_plane(table, 0.01, rng=0)
    rest = table.select(inl, invert=True)
    rpc = rest.to_open3d()
    ours_lab = euclidean_clusters(rest, 0.02)
    ref_lab = np.asarray(rpc.cluster_dbscan(0.02, 1))
    same = np.unique(np.stack([ours_lab, ref_lab]), axis=1).shape[1] == ours_lab.max() + 1
    recs.append(
        Record(
            "euclidean_clusters",
            f"table scene minus table ({len(rest)} pts), tol 2 cm",
            *paired_ms(
                lambda: euclidean_clusters(rest, 0.02),
                lambda: rpc.cluster_dbscan(0.02, 1),
                few,
                warmup=1,
            ),
            "open3d cluster_dbscan(0.02, min_points=1)",
            "identical partition (1 = yes)",
            float(same),
            1.0,
        )
    )
    return recs, {
        "threads": "2 cores for both (Open3D OpenMP; ours cKDTree workers=-1, "
        "nanoflann n_jobs=8, numba default threads)",
        "repeats": few,
        "timing": "ours and Open3D alternate call by call (paired_ms) for the filters and "
        "clusters; statistical outlier removal over 2 * repeats + 1 pairs",
        "open3d": o3d.__version__,
    }
