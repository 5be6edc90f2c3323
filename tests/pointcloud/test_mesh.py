"""Triangle meshes: OFF/PLY reading (Open3D parity, ModelNet's quirk, bad files), area-
weighted surface sampling against Open3D's, farthest point sampling, normalization."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.pointcloud import (
    TriangleMesh,
    chamfer_distance,
    farthest_point_sampling,
    normalize_unit_sphere,
    read_mesh,
    sample_surface,
)
from tests.conftest import DATA, data_path

o3d = pytest.importorskip("open3d")

CUBE_OFF = """OFF
# a unit cube, quads
8 6 12

0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 0 1
1 1 1
0 1 1
4 0 3 2 1
4 4 5 6 7
4 0 1 5 4
4 2 3 7 6   # a trailing comment
4 1 2 6 5
4 0 4 7 3
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------- reading
class TestReadMesh:
    def test_quads_are_fan_triangulated(self, tmp_path):
        m = read_mesh(write(tmp_path, "cube.off", CUBE_OFF))
        assert m.vertices.shape == (8, 3) and m.faces.shape == (12, 3)
        assert m.faces[:2].tolist() == [[0, 3, 2], [0, 2, 1]]  # (p0, p1, p2), (p0, p2, p3)
        np.testing.assert_allclose(m.areas().sum(), 6.0)  # six unit squares
        assert m.face_labels is None

    def test_pentagon_fan_and_mixed_polygons(self, tmp_path):
        text = "OFF\n6 2 0\n0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n5 5 5\n5 0 1 2 3 4\n3 0 1 5\n"
        m = read_mesh(write(tmp_path, "p.off", text))
        assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 1, 5]]

    @pytest.mark.parametrize("head", ["OFF8 6 12\n", "OFF 8 6 12\n", "COFF\n8 6 12\n"])
    def test_modelnet_quirk_counts_glued_to_the_magic(self, tmp_path, head):
        # many ModelNet files start "OFF490 518 0": the counts on the magic's line
        text = head + CUBE_OFF.split("8 6 12\n", 1)[1]
        m = read_mesh(write(tmp_path, "q.off", text))
        assert m.faces.shape == (12, 3)
        np.testing.assert_allclose(m.areas().sum(), 6.0)

    def test_extra_vertex_and_face_columns_are_ignored(self, tmp_path):
        text = "OFF\n3 1 0\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n3 0 1 2 10 20 30\n"
        m = read_mesh(write(tmp_path, "c.off", text))
        assert m.faces.tolist() == [[0, 1, 2]] and m.vertices[1].tolist() == [1, 0, 0]

    @pytest.mark.parametrize("text", [True, False])
    def test_ply_round_trip(self, tmp_path, text):
        from plyfile import PlyData, PlyElement

        v = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 2)], "f4,f4,f4")
        v.dtype.names = ("x", "y", "z")
        f = np.empty(2, dtype=[("vertex_indices", "O")])
        f["vertex_indices"] = [np.array([0, 1, 2, 3], "i4"), np.array([0, 1, 4], "i4")]
        path = tmp_path / "m.ply"
        PlyData(
            [PlyElement.describe(v, "vertex"), PlyElement.describe(f, "face")], text=text
        ).write(str(path))
        m = read_mesh(path)
        assert m.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 2]]
        assert m.faces.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 4]]
        ref = o3d.io.read_triangle_mesh(str(path))  # Open3D triangulates the quad alike
        assert np.asarray(ref.triangles).tolist() == m.faces.tolist()

    def test_triangle_mesh_validates(self):
        with pytest.raises(InputError, match="must be finite"):
            TriangleMesh([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
        with pytest.raises(InputError, match="must lie in"):
            TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
        with pytest.raises(InputError, match="must hold integers"):
            TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 1.0, 2.0]])
        with pytest.raises(InputError, match="not be empty"):
            TriangleMesh([[0, 0, 0]], np.zeros((0, 3), int))
        with pytest.raises(InputError, match="one label per face"):
            TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], [0, 1])


BAD_FILES = [
    ("trunc.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "truncated"),
    ("range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "face index out of range"),
    ("neg.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "face index out of range"),
    ("nan.off", "OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "non-finite"),
    ("huge.off", "OFF\n1000000000000 1 0\n0 0 0\n3 0 0 0\n", "claims 1000000000000 vertices"),
    ("empty.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "empty mesh"),
    ("two.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "needs at least 3"),
    ("text.off", "OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "not a number"),
    ("magic.off", "PLY\n3 1 0\n", "not an OFF file"),
    ("counts.off", "OFF\n3 one 0\n", "must be integers"),
    ("blank.off", "\n\n", "empty file"),
    ("short.off", "OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n", "fewer than 3 coordinates"),
    (
        "cloud.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n",
        "empty mesh",
    ),
    (
        "huge.ply",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty "
        "float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int "
        "vertex_indices\nend_header\n",
        "at least",
    ),
    ("mesh.obj", "v 0 0 0\n", "unknown mesh extension"),
]


@pytest.mark.parametrize(("name", "text", "message"), BAD_FILES)
def test_bad_files_are_refused(tmp_path, name, text, message):
    path = write(tmp_path, name, text)
    with pytest.raises(FileFormatError, match=message) as info:
        read_mesh(path)
    assert str(path) in str(info.value)  # the message names the file


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_mesh(tmp_path / "nope.off")
    with pytest.raises(FileFormatError, match="is a folder"):
        read_mesh(tmp_path)


# --------------------------------------------------------------------------- sampling
def disjoint_triangles() -> TriangleMesh:
    """Four right triangles of areas 1, 2, 4, 8 spread along x, and one of zero area."""
    verts, faces = [], []
    for k, area in enumerate((1.0, 2.0, 4.0, 8.0)):
        leg = np.sqrt(2 * area)
        x = 10.0 * k
        verts += [[x, 0, 0], [x + leg, 0, 0], [x, leg, 0]]
        faces.append([3 * k, 3 * k + 1, 3 * k + 2])
    verts += [[50, 0, 0], [51, 0, 0], [52, 0, 0]]  # collinear: zero area
    faces.append([12, 13, 14])
    return TriangleMesh(verts, faces)


class TestSampleSurface:
    def test_hit_counts_follow_the_areas_like_open3d(self):
        mesh = disjoint_triangles()
        n = 30000
        p = np.array([1, 2, 4, 8]) / 15.0
        _, faces = sample_surface(mesh, n, rng=0)
        ours = np.bincount(faces, minlength=5)
        assert ours[4] == 0  # the zero-area triangle is never picked
        # Open3D's hit triangle is the one whose x-range holds the point (10 apart)
        ref = o3d.geometry.TriangleMesh(
            o3d.utility.Vector3dVector(mesh.vertices), o3d.utility.Vector3iVector(mesh.faces)
        )
        o3d.utility.random.seed(0)
        pts = np.asarray(ref.sample_points_uniformly(n).points)
        theirs = np.bincount(np.floor(pts[:, 0] / 10).astype(int), minlength=5)
        assert theirs[4] == 0
        # both draw triangles i.i.d. by area: counts multinomial(n, p). Pearson's
        # chi-square (3 degrees of freedom) stays below its 99.9 % quantile, 16.3, but
        # for 1 seed in 1000 (the seeds are fixed: this is not flaky)
        for counts in (ours, theirs):
            chi2 = ((counts[:4] - n * p) ** 2 / (n * p)).sum()
            assert chi2 < stats.chi2.ppf(0.999, 3)

    def test_points_lie_on_the_surface_and_match_open3d(self):
        ref = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=12)
        mesh = TriangleMesh(np.asarray(ref.vertices), np.asarray(ref.triangles))
        ours, _ = sample_surface(mesh, 4000, rng=1)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(ref))
        dist = scene.compute_distance(o3d.core.Tensor(ours.astype(np.float32))).numpy()
        assert dist.max() < 1e-5  # on the triangles (float32 arithmetic in Open3D)
        o3d.utility.random.seed(1)
        theirs = np.asarray(ref.sample_points_uniformly(4000).points)
        o3d.utility.random.seed(2)
        dense = np.asarray(ref.sample_points_uniformly(200000).points)
        # two independent uniform samples of 4000 points on a 12.5 m^2 surface are about
        # 0.5 / sqrt(4000 / 12.5) = 0.03 apart: ours and Open3D's are as close as that,
        # and both are as close to a dense sample (density errors would show there)
        assert chamfer_distance(ours, theirs) < 0.04
        to_dense_ours, to_dense_theirs = (
            chamfer_distance(ours, dense),
            chamfer_distance(theirs, dense),
        )
        assert abs(to_dense_ours - to_dense_theirs) < 0.15 * to_dense_theirs

    def test_uniform_inside_a_triangle(self):
        # the 4 midpoint sub-triangles have equal areas: equal hit counts (chi-square,
        # 3 degrees of freedom, 99.9 % quantile); the mean is the centroid (5 sigma)
        mesh = TriangleMesh([[0, 0, 0], [3, 0, 0], [0, 3, 0]], [[0, 1, 2]])
        pts, _ = sample_surface(mesh, 20000, rng=3)
        x, y = pts[:, 0], pts[:, 1]
        corner = np.where(x > 1.5, 1, np.where(y > 1.5, 2, np.where(x + y < 1.5, 0, 3)))
        counts = np.bincount(corner, minlength=4)
        assert ((counts - 5000) ** 2 / 5000).sum() < stats.chi2.ppf(0.999, 3)
        sigma = np.sqrt(0.5) / np.sqrt(20000)  # per-coordinate sd of the triangle is 0.71
        np.testing.assert_allclose(pts.mean(0), [1, 1, 0], atol=5 * sigma)
        assert np.all(pts[:, 2] == 0) and np.all(x + y <= 3 + 1e-12)

    def test_seeded(self):
        mesh = disjoint_triangles()
        a, fa = sample_surface(mesh, 100, rng=5)
        b, fb = sample_surface(mesh, 100, rng=np.random.default_rng(5))
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(fa, fb)
        assert not np.array_equal(a, sample_surface(mesh, 100, rng=6)[0])

    def test_bad_input(self):
        flat = TriangleMesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]])
        with pytest.raises(DegenerateError, match="zero area"):
            sample_surface(flat, 10)
        with pytest.raises(InputError, match="TriangleMesh"):
            sample_surface(np.zeros((3, 3)), 10)
        with pytest.raises(InputError, match="n must be >= 1"):
            sample_surface(disjoint_triangles(), 0)
        with pytest.raises(InputError, match="at most"):
            sample_surface(disjoint_triangles(), 10**12)


# --------------------------------------------------------------------------- FPS
def fps_reference(points: np.ndarray, n: int, start: int = 0) -> list[int]:
    """The definition, literally: the next index maximizes the distance to the nearest
    index chosen so far (ties to the lowest index)."""
    chosen = [start]
    while len(chosen) < n:
        d = np.linalg.norm(points[:, None] - points[chosen][None], axis=2).min(1)
        d[chosen] = -1
        chosen.append(int(np.argmax(d)))
    return chosen


class TestFarthestPointSampling:
    def test_line_picks_the_ends_then_the_middle(self):
        pts = np.column_stack([np.arange(11.0), np.zeros(11), np.zeros(11)])
        assert farthest_point_sampling(pts, 4).tolist() == [0, 10, 5, 2]
        assert farthest_point_sampling(pts, 2, start=4).tolist() == [4, 10]

    def test_equals_the_plain_loop(self, rng):
        pts = rng.normal(size=(200, 3))
        for start in (0, 17):
            got = farthest_point_sampling(pts, 60, start=start)
            assert got.tolist() == fps_reference(pts, 60, start)
            assert got.dtype == np.int64

    def test_covering_radius_shrinks(self, rng):
        pts = rng.uniform(-1, 1, (2000, 3))
        idx = farthest_point_sampling(pts, 64)
        radii = []
        for k in range(1, 64):
            d = np.linalg.norm(pts[:, None] - pts[idx[:k]][None], axis=2).min(1)
            radii.append(d.max())
            # the next pick is the farthest point: its distance is the covering radius
            assert np.isclose(d[idx[k]], d.max())
        assert np.all(np.diff(radii) <= 1e-12)

    def test_duplicates_and_random_start(self, rng):
        pts = np.zeros((5, 3))
        assert sorted(farthest_point_sampling(pts, 5).tolist()) == [0, 1, 2, 3, 4]
        cloud = rng.normal(size=(100, 3))
        a = farthest_point_sampling(cloud, 10, start=None, rng=3)
        assert a.tolist() == farthest_point_sampling(cloud, 10, start=None, rng=3).tolist()
        assert a.tolist() == fps_reference(cloud, 10, int(a[0]))

    def test_bad_input(self):
        pts = np.zeros((5, 3))
        with pytest.raises(InputError, match="at most the number of points"):
            farthest_point_sampling(pts, 6)
        with pytest.raises(InputError, match="start must be an index"):
            farthest_point_sampling(pts, 2, start=5)
        with pytest.raises(InputError, match="finite"):
            farthest_point_sampling([[0, 0, np.nan]], 1)
        with pytest.raises(InputError, match="points as columns"):
            farthest_point_sampling(np.zeros((3, 5)), 1)


# --------------------------------------------------------------------------- normalize, chamfer
def test_normalize_unit_sphere(rng):
    pts = rng.normal(3.0, 2.0, (500, 3))
    out, centroid, scale = normalize_unit_sphere(pts)
    np.testing.assert_allclose(out.mean(0), 0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1).max(), 1.0)
    np.testing.assert_allclose(out * scale + centroid, pts)
    with pytest.raises(DegenerateError, match="all 4 points are equal"):
        normalize_unit_sphere(np.ones((4, 3)))


def test_chamfer_distance(rng):
    a = rng.normal(size=(50, 3))
    b = rng.normal(size=(70, 3))
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    assert np.isclose(chamfer_distance(a, b), 0.5 * (d.min(1).mean() + d.min(0).mean()))
    assert chamfer_distance(a, a[::-1]) == 0.0
    with pytest.raises(InputError, match="must not be empty"):
        chamfer_distance(np.zeros((0, 3)), a)


# --------------------------------------------------------------------------- real data
REAL = sorted(
    p for p in (DATA / "pointcloud_cls").rglob("*") if p.suffix.lower() in (".off", ".ply")
)


@pytest.mark.realdata
@pytest.mark.parametrize("path", REAL or [None], ids=lambda p: p.name if p else "absent")
def test_real_meshes_read_sample_and_match_open3d(path):
    if path is None:
        data_path("pointcloud_cls")  # skips with the reason
        pytest.skip("no .off or .ply file under pointcloud_cls")
    mesh = read_mesh(path)
    assert len(mesh.faces) > 0 and mesh.areas().sum() > 0
    pts, _ = sample_surface(mesh, 1024, rng=0)
    assert pts.shape == (1024, 3) and np.isfinite(pts).all()
    ref = o3d.io.read_triangle_mesh(str(path))
    # Open3D reads OFF coordinates as float32: equal to ours rounded to float32
    np.testing.assert_array_equal(
        np.asarray(ref.vertices), mesh.vertices.astype(np.float32).astype(np.float64)
    )
    np.testing.assert_array_equal(np.asarray(ref.triangles), mesh.faces)
