"""``robopercept cloud`` writes the segments as a per-point ``label`` field (PLY and PCD)
that Open3D and our reader read, with the label meanings in --json (issue 30)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.pointcloud import PointCloud, read_point_cloud, write_point_cloud


def _scene(path):
    """A floor z = 0 and two boxes above it (the scene of tests/cli/test_cli.py)."""
    rng = np.random.default_rng(0)
    floor = np.column_stack([rng.uniform(-1, 1, (3000, 2)), rng.normal(0, 0.001, 3000)])
    box1 = rng.uniform([0.2, 0.2, 0.05], [0.4, 0.4, 0.25], (600, 3))
    box2 = rng.uniform([-0.6, -0.5, 0.05], [-0.4, -0.3, 0.2], (500, 3))
    write_point_cloud(path, PointCloud(np.vstack([floor, box1, box2])))
    return len(floor), len(box1), len(box2)


@pytest.mark.parametrize("ext", [".ply", ".pcd"])
def test_cloud_segments_are_written_as_a_label_field(tmp_path, capsys, ext):
    """Label 0 unassigned, 1 the floor plane, 2 and 3 the boxes (clusters by size): each
    label holds the points of its segment and one colour; Open3D's tensor reader sees
    the same labels."""
    o3d = pytest.importorskip("open3d")
    n_floor, n1, n2 = _scene(tmp_path / "scene.ply")
    out = tmp_path / f"seg{ext}"
    code = main(["cloud", str(tmp_path / "scene.ply"), "-o", str(out), "--planes", "1:0.01",
                 "--clusters", "0.05:50:100000", "--json"])  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["label_field"] is True
    assert summary["labels"] == {"0": "unassigned", "1": "plane 1", "2": "cluster 1",
                                 "3": "cluster 2"}  # fmt: skip
    seg = read_point_cloud(out)
    counts = np.bincount(seg.labels, minlength=4)
    assert abs(counts[1] - n_floor) <= 10 and sorted(counts[2:4]) == sorted([n1, n2])
    for k in range(1, 4):  # one colour per segment
        assert len(np.unique(seg.colors[seg.labels == k], axis=0)) == 1
    ref = o3d.t.io.read_point_cloud(str(out)).point["label"].numpy().ravel()
    np.testing.assert_array_equal(ref, seg.labels)


def test_cloud_without_segmentation_keeps_the_input_labels(tmp_path, capsys):
    """No --planes/--clusters: the input's labels (here PCL-style) pass through a
    pass-through filter to the output; an unlabelled input gives no label field."""
    pts = np.random.default_rng(1).uniform(-1, 1, (200, 3))
    labels = (pts[:, 0] > 0).astype(int) + 1
    write_point_cloud(tmp_path / "in.pcd", PointCloud(pts, labels=labels))
    code = main(["cloud", str(tmp_path / "in.pcd"), "-o", str(tmp_path / "out.ply"),
                 "--pass-through", "z:0:1", "--json"])  # fmt: skip
    assert code == 0 and json.loads(capsys.readouterr().out)["label_field"] is True
    out = read_point_cloud(tmp_path / "out.ply")
    keep = pts[:, 2] >= 0
    np.testing.assert_array_equal(out.labels, labels[keep])
    write_point_cloud(tmp_path / "plain.ply", PointCloud(pts))
    assert main(["cloud", str(tmp_path / "plain.ply"), "-o", str(tmp_path / "o2.ply")]) == 0
    assert read_point_cloud(tmp_path / "o2.ply").labels is None
    assert "label field" not in capsys.readouterr().out
