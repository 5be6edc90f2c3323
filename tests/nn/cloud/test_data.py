"""Point-cloud data: the data set and its stratified splits, the augmentations, sampling,
and folders of meshes and clouds (ModelNet's layout)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.cloud.data import (  # noqa: E402
    CloudDataset,
    augment_clouds,
    check_n_points,
    pick_points,
    read_cloud_file,
    read_cloud_folder,
)
from robopercept.nn.cloud.synthetic import procedural_shapes, shape_mesh  # noqa: E402
from robopercept.pointcloud import PointCloud, write_point_cloud  # noqa: E402
from tests.conftest import data_path  # noqa: E402


@pytest.fixture(scope="module")
def small() -> CloudDataset:
    return procedural_shapes(3, 128, rng=0)


# --------------------------------------------------------------------------- the data set
class TestCloudDataset:
    def test_split_is_stratified_and_disjoint(self):
        ds = procedural_shapes(10, 16, classes=("cone", "box", "torus"), rng=0)
        parts = ds.split((0.8, 0.1, 0.1), rng=1)
        for part, per_class in zip(parts, (8, 1, 1), strict=True):
            assert np.bincount(part.labels, minlength=3).tolist() == [per_class] * 3
        seen = [tuple(p.ravel()) for part in parts for p in part.points]
        assert sorted(seen) == sorted(tuple(p.ravel()) for p in ds.points)
        again = ds.split((0.8, 0.1, 0.1), rng=1)
        np.testing.assert_array_equal(again[0].points, parts[0].points)

    def test_subset_and_validation(self, small):
        sub = small.subset([4, 0])
        assert sub.labels.tolist() == [1, 0] and sub.parts.shape == (2, 128)
        np.testing.assert_array_equal(sub.points[1], small.points[0])
        with pytest.raises(InputError, match="indices must lie in"):
            small.subset([len(small)])
        with pytest.raises(InputError, match=r"points must be \(M, N, 3\)"):
            CloudDataset(np.zeros((4, 3)), [0], ("a",))
        with pytest.raises(InputError, match=r"labels must lie in \[0, 1\)"):
            CloudDataset(np.zeros((1, 4, 3)), [1], ("a",))
        with pytest.raises(InputError, match="parts need part_names"):
            CloudDataset(np.zeros((1, 4, 3)), [0], ("a",), parts=np.zeros((1, 4), int))
        with pytest.raises(InputError, match="finite"):
            CloudDataset(np.full((1, 4, 3), np.nan), [0], ("a",))


# --------------------------------------------------------------------------- sampling
def test_check_n_points_and_pick_points():
    assert check_n_points(2) == 2 and check_n_points(1 << 20) == 1 << 20
    with pytest.raises(InputError, match="n_points must be at most"):
        check_n_points((1 << 20) + 1)
    with pytest.raises(InputError, match="n_points must be >= 2"):
        check_n_points(1)
    # FPS from any start keeps the two far points of three (two nearly coincide)
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0.01, 0, 0]])
    for seed in range(5):
        assert sorted(pick_points(pts, 2, rng=seed).tolist()) in ([0, 1], [1, 2])
    idx = pick_points(np.random.default_rng(0).normal(size=(50, 3)), 20, fps=False, rng=0)
    assert len(set(idx.tolist())) == 20
    np.testing.assert_array_equal(idx, np.random.default_rng(0).choice(50, 20, replace=False))
    with pytest.raises(InputError, match="n must be at most the 3 points"):
        pick_points(pts, 4)
    with pytest.raises(InputError, match=r"points must be \(M, 3\)"):
        pick_points(np.zeros((4, 2)), 2)


# --------------------------------------------------------------------------- augmentation
class TestAugment:
    @pytest.mark.parametrize("up", [0, 1, 2])
    def test_up_rotation_keeps_the_up_coordinate_and_planar_norms(self, up):
        x = torch.randn(4, 100, 3, generator=torch.Generator().manual_seed(0))
        y = augment_clouds(x, 1, rotate="up", up_axis=up, scale=None, jitter=0.0, shift=0.0)
        assert torch.equal(y[..., up], x[..., up])  # exactly
        plane = [a for a in range(3) if a != up]
        torch.testing.assert_close(
            y[..., plane].norm(dim=-1), x[..., plane].norm(dim=-1), atol=1e-6, rtol=0
        )
        assert not torch.allclose(y, x)

    def test_so3_preserves_distances_and_is_uniform(self):
        x = torch.randn(3, 50, 3, generator=torch.Generator().manual_seed(0))
        y = augment_clouds(x, 2, rotate="so3", scale=None, jitter=0.0, shift=0.0)
        exact = "donot_use_mm_for_euclid_dist"  # (the matmul form loses 1e-3 near 0)
        torch.testing.assert_close(
            torch.cdist(y, y, compute_mode=exact),
            torch.cdist(x, x, compute_mode=exact),
            atol=1e-5,
            rtol=0,
        )
        # the image of a fixed unit vector under uniform rotations is uniform on the
        # sphere: its mean over 4000 draws is 0 within 4 / sqrt(3 * 4000) = 0.04
        e = torch.tensor([1.0, 0.0, 0.0]).expand(4000, 1, 3)
        r = augment_clouds(e, 3, rotate="so3", scale=None, jitter=0.0, shift=0.0)
        assert r.mean(dim=(0, 1)).abs().max() < 0.04

    def test_scale_shift_jitter_dropout(self):
        x = torch.rand(8, 64, 3, generator=torch.Generator().manual_seed(0)) + 0.5
        y = augment_clouds(x, 4, rotate=None, jitter=0.0, shift=0.0)
        ratio = y / x  # one factor per cloud and axis, in [0.8, 1.25]
        assert torch.allclose(ratio, ratio[:, :1].expand_as(ratio))
        assert ratio.min() >= 0.8 - 1e-6 and ratio.max() <= 1.25 + 1e-6
        y = augment_clouds(x, 4, rotate=None, scale=None, jitter=0.0, shift=0.1)
        d = y - x
        assert torch.allclose(d, d[:, :1].expand_as(d)) and d.abs().max() <= 0.1
        y = augment_clouds(x, 4, rotate=None, scale=None, jitter=1.0, clip=0.05, shift=0.0)
        assert (y - x).abs().max() <= 0.05 + 1e-6  # clipped as PointNet's jitter
        y = augment_clouds(x, 5, rotate=None, scale=None, jitter=0.0, shift=0.0, dropout=0.9)
        assert y.shape == x.shape
        dropped = (y != x).any(-1)
        assert dropped.any()
        assert torch.equal(y[dropped], x[:, :1].expand_as(x)[dropped])  # the first point

    def test_seeded_and_not_in_place(self):
        x = torch.randn(2, 32, 3)
        before = x.clone()
        a = augment_clouds(x, 7, rotate="so3", dropout=0.5)
        b = augment_clouds(x, torch.Generator().manual_seed(7), rotate="so3", dropout=0.5)
        assert torch.equal(a, b) and torch.equal(x, before)
        assert not torch.equal(a, augment_clouds(x, 8, rotate="so3", dropout=0.5))
        assert augment_clouds(x[0], 7).shape == (32, 3)  # one cloud

    def test_bad_input(self):
        x = torch.zeros(1, 4, 3)
        with pytest.raises(InputError, match="rotate must be one of"):
            augment_clouds(x, rotate="z")
        with pytest.raises(InputError, match=r"\(B, N, 3\)"):
            augment_clouds(torch.zeros(1, 4, 2))
        with pytest.raises(InputError, match="torch tensor"):
            augment_clouds(np.zeros((1, 4, 3)))
        with pytest.raises(InputError, match="dropout must be in"):
            augment_clouds(x, dropout=1.0)
        with pytest.raises(InputError, match="scale must be"):
            augment_clouds(x, scale=1.0)


# --------------------------------------------------------------------------- folders
def write_off(path: Path, name: str, rng: int) -> None:
    mesh = shape_mesh(name, rng=rng)
    lines = [f"OFF{len(mesh.vertices)} {len(mesh.faces)} 0"]  # ModelNet's glued header
    lines += [" ".join(f"{c:.6f}" for c in v) for v in mesh.vertices]
    lines += [f"3 {a} {b} {c}" for a, b, c in mesh.faces]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


class TestFolders:
    def test_flat_layout_meshes_and_clouds(self, tmp_path):
        write_off(tmp_path / "cone" / "a.off", "cone", 0)
        write_off(tmp_path / "cone" / "b.OFF", "cone", 1)
        pts = np.random.default_rng(0).normal(size=(500, 3))
        pts[3] = np.nan  # dropped
        write_point_cloud(tmp_path / "blob" / "big.pcd", PointCloud(pts))
        write_point_cloud(tmp_path / "blob" / "few.ply", PointCloud(pts[:20]))
        (tmp_path / "blob" / "notes.txt").write_text("ignored")
        (tmp_path / "blob" / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n")
        with pytest.warns(UserWarning, match=r"skipped 1 unreadable file.*broken\.off"):
            ds = read_cloud_folder(tmp_path, 64, progress=False)
        assert ds.class_names == ("blob", "cone")  # sorted folder names
        assert ds.labels.tolist() == [0, 0, 1, 1] and ds.points.shape == (4, 64, 3)
        assert [Path(n).name for n in ds.names] == ["big.pcd", "few.ply", "a.off", "b.OFF"]
        assert [Path(s).name for s in ds.skipped] == ["broken.off"]
        np.testing.assert_allclose(np.linalg.norm(ds.points, axis=2).max(1), 1.0, atol=1e-6)
        # the cloud of 20 points, one NaN: the 19 finite ones each kept, 45 repeats
        assert len(np.unique(ds.points[1], axis=0)) == 19
        with pytest.warns(UserWarning, match="skipped 1"):
            again = read_cloud_folder(tmp_path, 64, progress=False, rng=0)
        np.testing.assert_array_equal(again.points, ds.points)

    def test_modelnet_layout_and_split(self, tmp_path):
        write_off(tmp_path / "cone" / "train" / "cone_0001.off", "cone", 0)
        write_off(tmp_path / "cone" / "test" / "cone_0002.off", "cone", 1)
        write_off(tmp_path / "torus" / "train" / "torus_0001.off", "torus", 0)
        test = read_cloud_folder(tmp_path, 32, split="test", progress=False)
        assert test.class_names == ("cone", "torus") and test.labels.tolist() == [0]
        train = read_cloud_folder(tmp_path, 32, split="train", progress=False)
        assert train.labels.tolist() == [0, 1]
        assert len(read_cloud_folder(tmp_path, 32, progress=False)) == 3

    def test_read_cloud_file(self, tmp_path):
        write_off(tmp_path / "m.off", "box", 0)
        a = read_cloud_file(tmp_path / "m.off", 100, rng=1)
        assert a.shape == (100, 3) and a.dtype == np.float32
        np.testing.assert_array_equal(a, read_cloud_file(tmp_path / "m.off", 100, rng=1))
        b = read_cloud_file(tmp_path / "m.off", 100, rng=1, fps=False)
        assert b.shape == (100, 3)

    def test_bad_input(self, tmp_path):
        with pytest.raises(InputError, match="does not exist or is not a folder"):
            read_cloud_folder(tmp_path / "nope")
        with pytest.raises(InputError, match="no class subfolders"):
            read_cloud_folder(tmp_path)
        (tmp_path / "empty_class").mkdir()
        with pytest.raises(InputError, match=r"no readable mesh or cloud file: expected root"):
            read_cloud_folder(tmp_path, progress=False)
        with pytest.raises(InputError, match="split must be one of"):
            read_cloud_folder(tmp_path, split="val")
        with pytest.raises(InputError, match="n_points must be >= 2"):
            read_cloud_folder(tmp_path, 0)
        (tmp_path / "x.obj").write_text("v 0 0 0\n")
        with pytest.raises(FileFormatError, match="unknown extension"):
            read_cloud_file(tmp_path / "x.obj")


@pytest.mark.realdata
def test_real_modelnet10_test_split():
    root = data_path("pointcloud_cls", "ModelNet10")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every real file reads
        ds = read_cloud_folder(root, 256, split="test", progress=False)
    assert ds.class_names == ("sofa", "table")
    assert ds.labels.tolist() == [0, 1]
    assert [Path(n).name for n in ds.names] == ["sofa_0681.off", "table_0393.off"]
    assert np.isfinite(ds.points).all() and ds.points.shape == (2, 256, 3)
    np.testing.assert_allclose(np.linalg.norm(ds.points, axis=2).max(1), 1.0, atol=1e-6)
