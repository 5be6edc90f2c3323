"""Outputs of a plane-tracking run: files, their columns, and clean stops (Ctrl-C, a
failing source, corrupt frames)."""

from __future__ import annotations

import csv
import json

import imageio.v2 as imageio
import numpy as np
import pytest

from robopercept.imaging import read_image
from robopercept.pipelines.plane_outputs import CSV_COLUMNS, annotate_frame, run_plane_tracking
from robopercept.pipelines.plane_tracking import PlaneTracker
from robopercept.sources import SyntheticRGBDScene, TUMFolderSource, write_tum_folder
from robopercept.sources.realsense import SourceError

SMALL = {"depth_size": (424, 240), "color_size": (640, 360)}


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _check_outputs(out, n_rows, video=True):
    rows = _rows(out / "plane.csv")
    assert len(rows) == n_rows
    assert tuple(rows[0]) == CSV_COLUMNS if rows else True
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == n_rows
    plot = read_image(out / "plane.png")
    assert plot.ndim == 3 and plot.shape[2] == 3
    if video:
        with imageio.get_reader(out / "tracking.mp4") as r:
            assert sum(1 for _ in r) == n_rows
    return rows, summary


def test_run_writes_every_output(tmp_path):
    scene = SyntheticRGBDScene(n_frames=8, **SMALL)
    summary = run_plane_tracking(scene, tmp_path / "out", progress=False)
    rows, saved = _check_outputs(tmp_path / "out", 8)
    assert saved == json.loads(json.dumps(summary.to_dict(), default=float))
    assert summary.detection_rate == 1.0
    assert summary.status_counts["new"] == 1 and summary.status_counts["tracking"] == 7
    for row in rows:
        n = np.array([float(row["nx"]), float(row["ny"]), float(row["nz"])])
        assert (row["measured"], row["accepted"]) == ("1", "1")
        assert row["status"] in ("new", "tracking")
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-5)
        # n.x = d with d the distance: d > 0
        assert float(row["d"]) > 0 and float(row["track_d"]) > 0
        assert float(row["ms"]) > 0 and int(row["inliers"]) > 500
    # the CSV's plane agrees with the ground truth
    truth_n, truth_d = scene.frame(7).ground_truth["plane"]
    last = rows[-1]
    assert float(last["d"]) == pytest.approx(truth_d, abs=0.01)
    n_last = np.array([float(last[k]) for k in ("nx", "ny", "nz")])
    assert n_last @ truth_n > np.cos(np.radians(1.0))


def test_max_frames_and_no_video(tmp_path):
    scene = SyntheticRGBDScene(n_frames=8, **SMALL)
    summary = run_plane_tracking(scene, tmp_path, max_frames=3, video=False, progress=False)
    _check_outputs(tmp_path, 3, video=False)
    assert not (tmp_path / "tracking.mp4").exists()
    assert "tracking.mp4" not in summary.outputs


def _interrupted(scene, after, exc):
    for i, f in enumerate(scene):
        if i == after:
            raise exc
        yield f


def test_ctrl_c_stops_cleanly_with_complete_outputs(tmp_path):
    scene = SyntheticRGBDScene(n_frames=8, **SMALL)
    summary = run_plane_tracking(
        _interrupted(scene, 3, KeyboardInterrupt()), tmp_path, progress=False
    )
    assert summary.stopped == "interrupted"
    _check_outputs(tmp_path, 3)


def test_a_failing_source_stops_cleanly(tmp_path):
    scene = SyntheticRGBDScene(n_frames=8, **SMALL)
    with pytest.warns(UserWarning, match="unplugged"):
        summary = run_plane_tracking(
            _interrupted(scene, 4, SourceError("no frame for 5 s (unplugged?)")),
            tmp_path,
            progress=False,
        )
    assert "unplugged" in summary.stopped
    _check_outputs(tmp_path, 4)


def test_corrupt_frame_is_skipped_and_counted(tmp_path):
    scene = SyntheticRGBDScene(n_frames=4, **SMALL)
    folder = write_tum_folder(tmp_path / "seq", scene)
    victim = sorted((folder / "rgb").iterdir())[1]
    victim.write_bytes(b"\x89PNG\r\n\x1a\n this is not a PNG")
    with pytest.warns(UserWarning, match="skipping frame 1"):
        summary = run_plane_tracking(
            TUMFolderSource(folder), tmp_path / "out", progress=False, video=False
        )
    assert summary.skipped_frames == 1
    rows, _ = _check_outputs(tmp_path / "out", 3, video=False)
    assert [r["frame"] for r in rows] == ["0", "2", "3"]


def test_annotated_frame_marks_the_inliers():
    scene = SyntheticRGBDScene(n_frames=1, **SMALL)
    f = scene.frame(0)
    r = PlaneTracker().process(f)
    img = annotate_frame(f, r, np.array([0.0, 0.0, 0.2, 0.15]))
    assert img.shape == f.color.shape and img.dtype == np.uint8
    magenta = (img[..., 0] > 150) & (img[..., 1] < 120) & (img[..., 2] > 150)
    assert magenta.sum() > 1000
    assert not np.array_equal(img, f.color)
