"""Issue 48, item 3, from the command line: a command whose result is empty says so in
one line and exits 1 without writing it; one whose result is written but implausible
says so in one warning line and exits 0.

* ``cloud --pass-through z:5:6`` (nothing left): exit 1, no PLY;
* ``flow one.png -o f.mp4`` (one frame): exit 1, no video;
* ``plane-track`` without a board: a warning, exit 0 (the per-frame record is written);
* ``stereo RIGHT LEFT`` (swapped): a warning, exit 0;
* ``bgsub --snapshot N`` beyond the last frame: a warning, exit 0 (the video is written).

The library side of each case is in ``tests/pipelines/test_no_ops.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.imaging import write_image
from tests.pipelines.test_no_ops import _scene, _specks, _textured_pair


def _one_line(err: str, prefix: str) -> str:
    """The single stderr line that starts with ``prefix``."""
    lines = [line for line in err.splitlines() if line.startswith(prefix)]
    assert len(lines) == 1, err
    return lines[0]


def test_cloud_that_filters_out_every_point_exits_1_and_writes_nothing(tmp_path, capsys):
    from robopercept.pointcloud import PointCloud, write_point_cloud

    ply = tmp_path / "blob.ply"
    write_point_cloud(ply, PointCloud(np.random.default_rng(0).normal(0, 0.03, (397, 3))))
    out = tmp_path / "segments.ply"
    for extra in ([], ["--json"], ["--planes", "1:0.01"]):
        code = main(["cloud", str(ply), "--pass-through", "z:5:6", "-o", str(out), *extra])
        captured = capsys.readouterr()
        assert code == 1 and captured.out == ""
        assert captured.err.count("\n") == 1
        assert captured.err.startswith(
            "robopercept: error: pass-through z [5, 6] (--pass-through z:5:6) removed all 397 "
            "points: the cloud's z spans "
        )
        assert not out.exists()
    assert main(["cloud", str(ply), "--pass-through", "z:-1:1", "-o", str(out)]) == 0
    assert out.exists()


def test_flow_of_one_image_exits_1_before_writing(tmp_path, capsys):
    png = tmp_path / "one.png"
    write_image(png, np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8))
    out = tmp_path / "f.mp4"
    assert main(["flow", str(png), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"robopercept: error: {png} holds 1 frame (a still image?); at least 2" in err
    assert not out.exists()


def test_plane_track_without_a_board_warns_in_one_line(tmp_path, capsys):
    from robopercept.sources import write_tum_folder

    seq = tmp_path / "seq"
    write_tum_folder(seq, [_specks(f, seed=f.index) for f in _scene(3)])
    out = tmp_path / "out"
    code = main(["plane-track", "--source", str(seq), "--out", str(out), "--quiet", "--no-video"])
    captured = capsys.readouterr()
    assert code == 0  # the frame-by-frame record (every row unmeasured) is the result
    line = _one_line(captured.err, "robopercept: warning: no board found")
    assert line.startswith(
        "robopercept: warning: no board found in any of the 3 frames: the board-coloured "
        "pixels are scattered specks"
    )
    assert line.endswith("(hsv_low, hsv_high; --hsv-low, --hsv-high)")
    assert "plane measured    0, accepted 0" in captured.out
    assert (out / "plane.csv").exists()


@pytest.mark.realdata
def test_plane_track_on_the_tum_pair_finds_no_board(tmp_path, capsys):
    """The issue's case: the slambook2 TUM pair has 548 scattered green pixels on a
    plane; they were fitted and drawn as a board."""
    from tests.conftest import data_path

    seq, out = tmp_path / "seq", tmp_path / "out"
    src = data_path("rgbd", "tum_pair_slambook2")
    assert main(["rgbd-import", str(src), str(seq), "--preset", "fr2", "-q"]) == 0
    capsys.readouterr()
    code = main(["plane-track", "--source", str(seq), "--out", str(out), "--quiet", "--no-video"])
    captured = capsys.readouterr()
    assert code == 0
    line = _one_line(captured.err, "robopercept: warning: no board found")
    assert "no board found in any of the 2 frames" in line and "scattered specks" in line
    assert "plane measured    0, accepted 0 (lost 2)" in captured.out


def test_stereo_with_left_and_right_swapped_warns_in_one_line(tmp_path, capsys):
    left, right = _textured_pair()
    a, b = tmp_path / "left.png", tmp_path / "right.png"
    write_image(a, np.round(left * 255).astype(np.uint8))
    write_image(b, np.round(right * 255).astype(np.uint8))
    flags = ["--max-disparity", "16", "--method", "bm", "--window", "7"]
    out = tmp_path / "d.png"
    code = main(["stereo", str(b), str(a), *flags, "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0 and out.exists()  # the map is written: the user may mean it
    line = _one_line(captured.err, "robopercept: warning:")
    assert line.startswith("robopercept: warning: left and right look swapped (")
    assert line.endswith("pass the left camera's image first (robopercept stereo LEFT RIGHT)")
    assert main(["stereo", str(a), str(b), *flags, "-o", str(out)]) == 0
    assert "warning" not in capsys.readouterr().err


def test_bgsub_snapshot_beyond_the_video_warns_in_one_line(tmp_path, capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    rng = np.random.default_rng(0)
    for i in range(5):
        write_image(seq / f"{i:03d}.png", rng.integers(0, 255, (32, 48, 3), dtype=np.uint8))
    out = tmp_path / "b.mp4"
    command = ["bgsub", str(seq), "--method", "diff", "-o", str(out), "--quiet"]
    assert main([*command, "--snapshot", "100", "--snapshot", "2"]) == 0
    captured = capsys.readouterr()
    line = _one_line(captured.err, "robopercept: warning:")
    assert line == (
        "robopercept: warning: snapshot 100 (--snapshot) not saved: 5 frames were written, "
        "indices up to 4 (snapshots are 0-based frame indices)"
    )
    assert out.exists() and (tmp_path / "b_000002.png").exists()
    assert not (tmp_path / "b_000100.png").exists()
