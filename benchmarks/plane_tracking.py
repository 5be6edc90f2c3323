"""The plane-tracking pipeline against a reference pipeline built from the libraries
practitioners use, on the same synthetic frames, one process (issue 4).

Reference per frame: librealsense's ``rs2::pointcloud`` (``map_to`` the colour frame,
``calculate`` on the depth frame pushed through a software device) for vertices and
texture coordinates; ``cv2.cvtColor(RGB2HSV)`` + ``cv2.inRange`` for the green mask,
sampled at the texture coordinates; Open3D ``segment_plane`` (3 points, the same inlier
threshold as ours, 200 iterations = our bound) on the green points. Ours:
:class:`robopercept.pipelines.PlaneTracker` (points, colour, RANSAC, Kalman). Both run
over the same frames in order; the time of pushing frames into the software device is
not counted. Accuracy: normal angle error against the ground truth.
"""

from __future__ import annotations

import time
from typing import Any

import cv2
import numpy as np
import open3d as o3d
import pyrealsense2 as rs

from benchmarks._harness import Record
from robopercept.pipelines import PlaneTracker, plane_errors
from robopercept.sources import SyntheticRGBDScene
from robopercept.sources.realsense import SoftwareCamera


def _push(cam: SoftwareCamera, frame):
    """Push one frame through the software device and take librealsense's depth and
    colour frames back (the time of this is not counted)."""
    cam.push(frame)
    got = [cam.queue.wait_for_frame(5000) for _ in range(2)]
    d = next(x for x in got if x.profile.stream_type() == rs.stream.depth)
    c = next(x for x in got if x.profile.stream_type() == rs.stream.color)
    return d.as_depth_frame(), c


def _reference(depth_frame, color_frame, color: np.ndarray, thr: float, seed: int):
    pc = rs.pointcloud()
    pc.map_to(color_frame)
    cloud = pc.calculate(depth_frame)
    v = np.asanyarray(cloud.get_vertices()).view(np.float32).reshape(-1, 3)
    uv = np.asanyarray(cloud.get_texture_coordinates()).view(np.float32).reshape(-1, 2)
    hsv = cv2.cvtColor(color, cv2.COLOR_RGB2HSV)
    mask = cv2.inRange(hsv, (45, 35, 35), (65, 255, 255))
    h, w = mask.shape
    col = np.rint(uv[:, 0] * w).astype(np.int64)
    row = np.rint(uv[:, 1] * h).astype(np.int64)
    ok = (v[:, 2] > 0) & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    idx = np.flatnonzero(ok)
    green = idx[mask[row[idx], col[idx]] > 0]
    pts = v[green].astype(np.float64)
    if pts.shape[0] < 200:
        return None
    o3d.utility.random.seed(seed)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    eq, _ = pcd.segment_plane(thr, 3, 200)
    n = np.asarray(eq[:3])
    d = -eq[3] / np.linalg.norm(n)
    n = n / np.linalg.norm(n)
    return (n, d) if d >= 0 else (-n, -d)


#: the cameras of the speed cases (issue 49) and the tracker's time targets, ms per
#: frame: a Kinect-style 640x480 pair (the sweep's, depth scale 0.001), the D435's
#: 848x480 depth with its 1280x720 colour, and its full modes (the course's
#: mini-project): 1280x720 depth with 1920x1080 colour
CAMERAS: dict[str, tuple[dict[str, Any], float]] = {
    "640x480": (
        {
            "depth_size": (640, 480),
            "color_size": (640, 480),
            "depth_hfov": 62.0,
            "color_hfov": 62.0,
            "depth_scale": 0.001,
        },
        6.0,
    ),
    "848x480": ({"depth_size": (848, 480), "color_size": (1280, 720)}, 6.0),
    "1280x720": ({"depth_size": (1280, 720), "color_size": (1920, 1080)}, 20.0),
}


def _case(camera: str, n_frames: int) -> Record:
    settings, target_ms = CAMERAS[camera]
    scene = SyntheticRGBDScene(n_frames=300, **settings)
    # consecutive frames at 30 fps, as the tracker sees them: the first half of the loop
    # (near, far, half out of view)
    frames = [scene.frame(i) for i in range(n_frames)]
    truths = [f.ground_truth for f in frames]
    tracker = PlaneTracker()
    tracker.process(frames[0])  # JIT warm-up and a first track
    tracker.reset()
    ours_ms, ours_err, raw_err = [], [], []
    stages: list[dict[str, float]] = []
    for f, t in zip(frames, truths, strict=True):
        t0 = time.perf_counter()
        r = tracker.process(f)
        ours_ms.append((time.perf_counter() - t0) * 1e3)
        stages.append(r.ms)
        if t["valid_board_pixels"] >= 500:
            ours_err.append(plane_errors(r.track_normal, r.track_d, *t["plane"])[0])
            if r.detected:
                raw_err.append(plane_errors(r.normal, r.d, *t["plane"])[0])
    # the reference after ours, not frame by frame in turn: Open3D's OpenMP threads
    # spin for a while after each of its calls, and took the cores from ours between
    # (every stage of ours 20-50 % slower when the two alternated)
    cam = SoftwareCamera(frames[0])
    ref_ms, ref_err = [], []
    try:
        for i, (f, t) in enumerate(zip(frames, truths, strict=True)):
            d, c = _push(cam, f)
            pts_z = f.depth[f.depth > 0] * f.depth_scale
            g = max(0.004, 0.01 * float(np.median(pts_z)) ** 2) if pts_z.size else 0.01
            t0 = time.perf_counter()
            res = _reference(d, c, f.color, g, i)
            ref_ms.append((time.perf_counter() - t0) * 1e3)
            if t["valid_board_pixels"] >= 500:
                ref_err.append(plane_errors(*res, *t["plane"])[0] if res else np.nan)
    finally:
        cam.close()
    (w, h), (cw, ch) = settings["depth_size"], settings["color_size"]
    ours_err_a = np.array(ours_err)
    ref_err_a = np.array(ref_err)
    return Record(
        "plane_tracking",
        f"depth {w}x{h}, colour {cw}x{ch}, {len(frames)} frames",
        float(np.median(ours_ms)),
        float(np.median(ref_ms)),
        "rs2::pointcloud + cv2 cvtColor/inRange + open3d segment_plane",
        "tracked normal error median deg (ours)",
        float(np.nanmedian(ours_err_a)),
        1.0,
        {
            "ours_ms_p95": float(np.percentile(ours_ms, 95)),
            "ours_raw_error_median_deg": float(np.median(raw_err)),
            "ours_tracked_error_p95_deg": float(np.nanpercentile(ours_err_a, 95)),
            "ref_error_median_deg": float(np.nanmedian(ref_err_a)),
            "ref_error_p95_deg": float(np.nanpercentile(ref_err_a, 95)),
            "ref_failures": int(np.isnan(ref_err_a).sum()),
            "stage_ms_median": {k: float(np.median([m[k] for m in stages])) for k in stages[0]},
        },
        target_ms=target_ms,
    )


def _stage_medians(source, out) -> dict[str, float]:
    from robopercept.pipelines.plane_outputs import run_plane_tracking

    summary = run_plane_tracking(source, out, video=True, progress=False)
    stages = {k: float(v) for k, v in summary.ms_per_stage_median.items() if v is not None}
    stages["wall_ms_per_frame"] = 1e3 * float(summary.wall_seconds) / summary.frames
    return stages


def _demo_vs_folder(n_frames: int) -> Record:
    """Issue 24: the stage timings ``demo`` reports (the scene rendered frame by frame
    beside the tracker) against ``plane-track`` on the same frames read back from a
    ``synth-rgbd`` folder, side by side in this process, both writing the video (whose
    encoder runs at the lowest priority)."""
    import tempfile
    from pathlib import Path

    from robopercept.sources import TUMFolderSource, write_tum_folder

    scene = SyntheticRGBDScene(n_frames=n_frames)
    with tempfile.TemporaryDirectory() as tmp:
        folder = write_tum_folder(Path(tmp) / "seq", scene)
        _stage_medians(TUMFolderSource(folder), Path(tmp) / "warm")  # JIT, caches
        # ABBA order, median over five runs each: one run's median of a 1.5 to 3 ms
        # stage moves by 10 to 20% with what else the two cores do at the time (three
        # runs each left 16% on the 1.5 ms kalman stage once in four, with the sign of
        # the difference changing from run to run)
        runs: dict[str, list[dict[str, float]]] = {"demo": [], "folder": []}
        order = ("demo", "folder", "folder", "demo") * 2 + ("demo", "folder")
        for i, which in enumerate(order):
            source = scene if which == "demo" else TUMFolderSource(folder)
            runs[which].append(_stage_medians(source, Path(tmp) / f"{which}{i}"))
    demo, read = (
        {k: float(np.median([r[k] for r in runs[w]])) for k in runs[w][0]}
        for w in ("demo", "folder")
    )
    diff = {k: demo[k] / read[k] - 1.0 for k in ("points", "color", "ransac", "kalman", "total")}
    return Record(
        "plane_tracking_sources",
        f"demo vs plane-track from a folder, {n_frames} frames 848x480",
        demo["total"],
        read["total"],
        "the same frames read back from a synth-rgbd folder (TUMFolderSource)",
        "largest stage difference demo vs folder, % (target <= 15)",
        100.0 * max(abs(v) for k, v in diff.items() if k != "total"),
        1.15,
        {
            "demo_ms": demo,
            "folder_ms": read,
            "stage_difference": diff,
            "runs": runs,
        },
    )


def run(repeats: int = 30) -> tuple[list[Record], dict]:
    n = max(30, 5 * repeats)
    recs = [*(_case(camera, n) for camera in CAMERAS), _demo_vs_folder(max(60, n))]
    settings = {
        "frames": n,
        "threads": "numba and Open3D default (2 cores); librealsense pointcloud as built",
        "note": "the first n consecutive frames of the default synthetic sequence",
    }
    return recs, settings
