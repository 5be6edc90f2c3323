"""``robopercept demo``, ``plane-track`` and ``synth-rgbd`` from the command line."""

from __future__ import annotations

import csv
import json

import pytest

from robopercept.cli.main import main
from robopercept.pipelines.plane_outputs import CSV_COLUMNS


def test_demo_writes_its_outputs_and_prints_the_figures(tmp_path, capsys):
    out = tmp_path / "demo"
    # --max-frames, as every other frame command (--frames stays as an alias)
    code = main(["demo", "--out", str(out), "--max-frames", "6", "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    for needle in ("detection rate", "tracked", "ms/frame", "plane.csv"):
        assert needle in text
    for name in ("plane.csv", "tracking.mp4", "summary.json", "plane.png"):
        assert (out / name).stat().st_size > 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames"] == 6 and summary["detection_rate"] == 1.0


def test_synth_rgbd_then_plane_track_from_the_folder(tmp_path, capsys):
    seq = tmp_path / "seq"
    assert main(["synth-rgbd", str(seq), "--frames", "4", "--quiet"]) == 0
    for name in ("camera.json", "planes.csv", "rgb.txt", "depth.txt"):
        assert (seq / name).exists()
    out = tmp_path / "out"
    code = main(
        [
            "plane-track",
            "--source",
            str(seq),
            "--out",
            str(out),
            "--no-video",
            "--quiet",
            "--hsv-low",
            "45,35,35",
            "--hsv-high",
            "65,255,255",
            "--max-frames",
            "3",
        ]
    )
    assert code == 0
    with open(out / "plane.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and tuple(rows[0]) == CSV_COLUMNS
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tracked"]["angle_deg"]["median"] < 1.0  # ground truth read back


def test_a_run_that_tracked_no_frame_exits_1(tmp_path, capsys):
    seq = tmp_path / "seq"
    assert main(["synth-rgbd", str(seq), "--frames", "2", "--quiet"]) == 0
    for depth in (seq / "depth").iterdir():
        depth.write_bytes(b"not a png")  # every frame unreadable: skipped and counted
    out = tmp_path / "out"
    code = main(["plane-track", "--source", str(seq), "--out", str(out), "--no-video", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert err[-1] == (
        "robopercept: error: no frame was tracked (2 skipped as unreadable): check --source"
    )
    assert (out / "summary.json").exists()  # what was written is kept


def test_hsv_box_matching_nothing_detects_nothing(tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        [
            "plane-track",
            "--source",
            "synthetic",
            "--frames",
            "3",
            "--out",
            str(out),
            "--no-video",
            "--quiet",
            "--hsv-low",
            "140,35,35",
            "--hsv-high",
            "170,255,255",
        ]
    )
    assert code == 0
    with open(out / "plane.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["detected"] for r in rows] == ["0", "0", "0"]


@pytest.mark.parametrize(
    ("args", "match", "code"),
    [
        (["plane-track", "--source", "nowhere"], "not 'synthetic'", 2),
        (["plane-track", "--source", "synthetic", "--hsv-low", "1,2"], "H,S,V", 2),
        (["plane-track", "--source", "synthetic", "--hsv-low", "45,35,999"], "OpenCV scale", 2),
        (["plane-track", "--source", "missing.bag"], "not found", 1),
        (["demo", "--frames", "0"], ">= 1", 2),
    ],
)
def test_errors_are_one_line_with_their_exit_code(tmp_path, capsys, args, match, code):
    assert main([*args, "--out", str(tmp_path)] if args[0] != "demo" else args) == code
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1
