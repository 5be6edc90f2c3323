"""Procedural point-cloud shapes: the classes and their parts, the variants, seeds."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.cloud.data import CloudDataset  # noqa: E402
from robopercept.nn.cloud.synthetic import (  # noqa: E402
    SHAPE_CLASSES,
    SHAPE_PARTS,
    procedural_shapes,
    shape_mesh,
)


@pytest.fixture(scope="module")
def small() -> CloudDataset:
    return procedural_shapes(3, 128, rng=0)


# --------------------------------------------------------------------------- procedural
class TestProceduralShapes:
    def test_shapes_dtypes_and_normalization(self, small):
        m = 3 * len(SHAPE_CLASSES)
        assert small.points.shape == (m, 128, 3) and small.points.dtype == np.float32
        assert small.labels.dtype == np.int64 and small.parts.dtype == np.int64
        assert small.labels.tolist() == np.repeat(np.arange(len(SHAPE_CLASSES)), 3).tolist()
        assert small.class_names == SHAPE_CLASSES and len(small) == m
        norms = np.linalg.norm(small.points, axis=2)
        np.testing.assert_allclose(norms.max(1), 1.0, atol=1e-6)
        np.testing.assert_allclose(small.points.mean(1), 0.0, atol=1e-6)
        assert small.num_parts == sum(len(p) for p in SHAPE_PARTS.values())

    def test_parts_belong_to_the_class(self, small):
        # ShapeNet-part's rule: every point's part is one of its shape's class
        assert (small.part_classes[small.parts] == small.labels[:, None]).all()
        assert small.part_names[:3] == ("sphere/upper", "sphere/lower", "box/top")
        for k in range(small.num_classes):  # every part of every class is sampled
            own = np.flatnonzero(small.part_classes == k)
            assert set(np.unique(small.parts[small.labels == k])) == set(own)

    @pytest.mark.parametrize("name", SHAPE_CLASSES)
    def test_each_class_builds_a_labelled_mesh(self, name):
        mesh = shape_mesh(name, rng=1)
        offset = sum(len(SHAPE_PARTS[c]) for c in SHAPE_CLASSES[: SHAPE_CLASSES.index(name)])
        want = set(range(offset, offset + len(SHAPE_PARTS[name])))
        assert set(mesh.face_labels.tolist()) == want
        areas = mesh.areas()
        for part in want:  # every part has surface to sample
            assert areas[mesh.face_labels == part].sum() > 0

    def test_hand_checked_parts(self):
        ds = procedural_shapes(2, 400, classes=("sphere", "torus"), rng=2)
        z = ds.points[..., 2]
        upper = ds.parts[0] == 0
        # sphere: upper hemisphere above the equator (jitter 0.005 blurs the boundary)
        assert (z[0][upper] > -0.03).all() and (z[0][~upper] < 0.03).all()
        # torus: outer half farther from the axis than the inner half
        r = np.linalg.norm(ds.points[2, :, :2], axis=1)
        assert r[ds.parts[2] == 2].min() > r[ds.parts[2] == 3].max() - 0.03

    def test_seeded(self):
        a = procedural_shapes(1, 32, classes=("cone", "mug"), variant="noisy", rng=4)
        b = procedural_shapes(1, 32, classes=("cone", "mug"), variant="noisy", rng=4)
        c = procedural_shapes(1, 32, classes=("cone", "mug"), variant="noisy", rng=5)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.parts, b.parts)
        assert not np.array_equal(a.points, c.points)

    def test_up_axis_is_a_rotation_of_the_axes(self):
        z_up = procedural_shapes(1, 64, classes=("cone",), rng=3)
        for up in (0, 1):
            other = procedural_shapes(1, 64, classes=("cone",), up_axis=up, rng=3)
            np.testing.assert_array_equal(other.points[..., up], z_up.points[..., 2])
            np.testing.assert_allclose(
                np.linalg.det(np.roll(np.eye(3), up - 2, axis=1)), 1.0
            )  # cyclic: no mirror

    def test_variants(self):
        kw = {"classes": ("sphere",), "rng": 6}
        clean = procedural_shapes(20, 256, **kw)
        partial = procedural_shapes(20, 256, variant="partial", **kw)
        noisy = procedural_shapes(20, 256, variant="noisy", **kw)

        def flatness(ds):  # smallest / largest covariance eigenvalue, per cloud
            ev = np.linalg.eigvalsh(np.einsum("mni,mnj->mij", ds.points, ds.points) / 256)
            return ev[:, 0] / ev[:, 2]

        # a whole sphere spreads alike in all directions (ratio near 1); a partial view
        # is a cap of at most 70 % of it: flat along the view direction
        assert flatness(clean).min() > 0.6
        assert flatness(partial).max() < 0.5
        # noisy: the norms of a sphere's points spread (sigma 0.04 against 0.005, and
        # 10 % outliers in the unit ball, a third of them within radius 0.7 of the centre)
        norms = [np.linalg.norm(d.points, axis=2) for d in (clean, noisy)]
        assert norms[1].std(1).mean() > 2 * norms[0].std(1).mean()
        assert (norms[0] < 0.7).mean() == 0 and (norms[1] < 0.7).mean() > 0.02
        assert (noisy.part_classes[noisy.parts] == noisy.labels[:, None]).all()

    def test_fps_variant(self):
        ds = procedural_shapes(1, 64, classes=("box",), fps=True, rng=0)
        assert ds.points.shape == (1, 64, 3)

    def test_bad_input(self):
        with pytest.raises(InputError, match="unknown shape class 'cube'"):
            procedural_shapes(1, 16, classes=("cube",))
        with pytest.raises(InputError, match="distinct"):
            procedural_shapes(1, 16, classes=("box", "box"))
        with pytest.raises(InputError, match="n_points must be >= 2"):
            procedural_shapes(1, 0)
        with pytest.raises(InputError, match="variant must be one of"):
            procedural_shapes(1, 16, variant="blurry")
        with pytest.raises(InputError, match="up_axis must be one of"):
            procedural_shapes(1, 16, up_axis=3)
        with pytest.raises(InputError, match="limit is 1 GiB"):
            procedural_shapes(10**6, 2**20)
        with pytest.raises(InputError, match="unknown shape class"):
            shape_mesh("blob")
