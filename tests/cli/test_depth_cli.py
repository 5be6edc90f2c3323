"""``robopercept stereo`` against the library call and a synthetic truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.depth import semi_global_matching
from robopercept.imaging import read_image, write_image


def _pair(tmp_path, d=6, shape=(60, 120)):
    from robopercept.imaging.filters import gaussian_blur

    h, w = shape
    t = gaussian_blur(np.random.default_rng(0).uniform(0, 1, (h, w + d)), 1.0)
    wide = np.round(255 * (t - t.min()) / np.ptp(t)).astype(np.uint8)
    write_image(tmp_path / "l.png", wide[:, :w])
    write_image(tmp_path / "r.png", wide[:, d:])
    write_image(tmp_path / "gt.png", np.full(shape, 4 * d, dtype=np.uint8))  # scale 4
    return tmp_path / "l.png", tmp_path / "r.png", tmp_path / "gt.png"


def test_stereo_json_truth_npy_and_ply(tmp_path, capsys):
    from robopercept.pointcloud import read_point_cloud

    left, right, gt = _pair(tmp_path)
    out = tmp_path / "disp.png"
    code = main(["stereo", str(left), str(right), "--max-disparity", "15", "-o", str(out),
                 "--truth", str(gt), "--truth-scale", "4", "--npy", str(tmp_path / "d.npy"),
                 "--ply", str(tmp_path / "p.ply"), "--focal", "500", "--baseline", "0.1",
                 "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    disp = np.load(tmp_path / "d.npy")
    # the left-right check (1 px) is on by default
    expected = semi_global_matching(read_image(left), read_image(right), 15, lr_check=1.0)
    assert np.array_equal(disp, expected, equal_nan=True)
    assert summary["lr_check_px"] == 1.0
    assert summary["valid_percent"] == pytest.approx(100 * np.isfinite(disp).mean())
    assert summary["bad_2_percent"] < 15  # the left band (x < 6) and borders only
    assert summary["bad_2_valid_percent"] < 2
    assert read_image(out).shape[2] == 3 and read_image(out).shape[1] == 1280  # colour bar
    cloud = read_point_cloud(tmp_path / "p.ply")
    assert len(cloud) == summary["points"] > 5000
    assert summary["max_depth"] == pytest.approx(cloud.points[:, 2].max(), rel=1e-6)
    inner = np.abs(cloud.points[:, 2] - 500 * 0.1 / 6) < 0.5
    assert inner.mean() > 0.8  # z = f B / d = 8.33 m


def test_stereo_block_matching_and_errors(tmp_path, capsys):
    left, right, _ = _pair(tmp_path)
    code = main(["stereo", str(left), str(right), "--method", "bm", "--max-disparity", "15",
                 "--window", "7", "-o", str(tmp_path / "bm.png")])  # fmt: skip
    assert code == 0 and "valid" in capsys.readouterr().out
    assert main(["stereo", str(left), str(right), "--max-disparity", "15", "--ply", "x.ply"]) == 2
    assert "--focal" in capsys.readouterr().err
    assert main(["stereo", str(left), str(right), "--max-disparity", "500"]) == 1
    assert "image width" in capsys.readouterr().err
