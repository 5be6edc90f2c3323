"""Issue 48: what a user of Open3D types first. ``segment_plane`` gives the same plane twice
with the default arguments and a stated sign (d >= 0); Open3D's keyword names are
accepted as aliases (both spellings at once is an InputError naming both); parity with
Open3D through those keywords on a real PCL scene (office1, not yet used elsewhere)."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import Plane
from robopercept.pointcloud import (
    PointCloud,
    radius_outlier_removal,
    read_point_cloud,
    segment_plane,
    segment_planes,
    statistical_outlier_removal,
    voxel_downsample,
)
from tests.conftest import data_path

o3d = pytest.importorskip("open3d")


def _noisy_plane(rng, equation, n=2000, outliers=500, noise=0.002):
    true = Plane.from_equation(equation)
    pts = true.project(rng.uniform(-1, 1, (n, 3))) + rng.normal(0, noise, (n, 1)) * true.normal
    return true, PointCloud(np.vstack([pts, rng.uniform(-1, 1, (outliers, 3))]))


@pytest.fixture(scope="module")
def office():
    """PCL's office1 scene (Kinect, 640x480 organized, XYZRGB), finite points only."""
    return read_point_cloud(data_path("pointcloud", "pcl", "office1.pcd")).finite()


# --------------------------------------------------------------- item 1: seed and sign
def test_default_calls_give_the_same_plane_twice(rng):
    _, cloud = _noisy_plane(rng, [0.3, -0.5, 0.8, 1.2])
    (p1, i1), (p2, i2) = segment_plane(cloud, 0.01), segment_plane(cloud, 0.01)
    np.testing.assert_array_equal(p1.equation, p2.equation)
    np.testing.assert_array_equal(i1, i2)
    # the default is the seed 0, stated in the docstring
    p0, i0 = segment_plane(cloud, 0.01, rng=0)
    np.testing.assert_array_equal(p0.equation, p1.equation)
    np.testing.assert_array_equal(i0, i1)
    a, b = segment_planes(cloud, 0.01, max_planes=2), segment_planes(cloud, 0.01, max_planes=2)
    assert [s.plane.equation.tolist() for s in a] == [s.plane.equation.tolist() for s in b]


@pytest.mark.parametrize(
    "equation",
    [[0, 0, 1, -2], [0, 0, 1, 2], [0.3, -0.5, 0.8, 1.2], [-0.3, 0.5, -0.8, 1.2], [0, -1, 0, -1.5]],
)
def test_sign_rule_normal_towards_the_origin(rng, equation):
    true, cloud = _noisy_plane(rng, equation)
    seen = set()
    for seed in (None, None, 1, 2):  # fresh entropy too: the sign never flips
        plane, _ = segment_plane(cloud, 0.01, rng=seed)
        assert plane.offset >= 0  # d >= 0 ...
        # ... i.e. the origin is on the normal's side: distance(0) = d >= 0, and the normal
        # points from the plane's closest point towards the origin
        assert float(plane.normal @ (np.zeros(3) - plane.point)) >= 0
        assert np.degrees(plane.angle_to(true)) < 1.0
        seen.add(tuple(np.sign(np.round(plane.normal, 2))))
    assert len(seen) == 1
    expect = true.equation if true.offset > 0 else -true.equation
    np.testing.assert_allclose(plane.equation, expect, atol=0.02)


def test_sign_rule_for_a_plane_through_the_origin(rng):
    # z = 0 through the origin: d == 0 up to noise; the normal is (0, 0, 1) either way
    pts = np.column_stack([rng.uniform(-1, 1, (500, 2)), np.zeros(500)])
    for seed in range(4):
        plane, inl = segment_plane(PointCloud(pts), 0.01, rng=seed)
        assert inl.size == 500 and plane.offset == 0
        np.testing.assert_allclose(plane.normal, [0, 0, 1], atol=1e-12)


def test_segment_planes_follow_the_sign_rule(rng):
    pts = []
    for axis, n in ((0, 3000), (1, 2000), (2, 1000)):
        p = rng.uniform(0.02, 1, (n, 3))
        p[:, axis] = 0.5 + rng.normal(0, 0.002, n)  # the planes x, y, z = 0.5
        pts.append(p)
    found = segment_planes(PointCloud(np.vstack(pts)), 0.008, min_inliers=400)
    assert len(found) == 3
    for seg, axis in zip(found, (0, 1, 2), strict=True):
        assert seg.plane.offset >= 0  # d = 0.5, normal -e_axis: towards the origin
        np.testing.assert_allclose(seg.plane.equation, [*(-np.eye(3)[axis]), 0.5], atol=0.01)


@pytest.mark.realdata
def test_default_segment_plane_on_the_office_matches_open3d_with_the_sign_rule(office):
    cloud, _ = voxel_downsample(office, 0.05)  # 16,814 points
    plane, inl = segment_plane(cloud, 0.02)
    again, inl2 = segment_plane(cloud, 0.02)
    np.testing.assert_array_equal(plane.equation, again.equation)
    np.testing.assert_array_equal(inl, inl2)
    o3d.utility.random.seed(0)  # Open3D's engine is seeded at random otherwise
    eq, ref = cloud.to_open3d().segment_plane(
        distance_threshold=0.02, ransac_n=3, num_iterations=1000
    )
    eq = np.asarray(eq) * (1 if eq[3] >= 0 else -1)  # Open3D's sign brought to d >= 0
    # the same dominant plane: normals within 1 degree, offsets within 1 cm, and 95% of
    # the inliers shared (RANSAC's samples differ; both refit to the inliers)
    assert plane.offset >= 0
    assert np.degrees(plane.angle_to(Plane.from_equation(eq))) < 1.0
    assert abs(plane.offset - eq[3]) < 0.01
    ref = np.asarray(ref)
    assert np.intersect1d(inl, ref).size / np.union1d(inl, ref).size >= 0.95


# --------------------------------------------------------------- item 2: Open3D keywords
def test_segment_plane_aliases_give_the_native_result(rng):
    _, cloud = _noisy_plane(rng, [0.3, -0.5, 0.8, 1.2])
    native = segment_plane(cloud, 0.01, sample_size=3, max_iterations=300, rng=4)
    alias = segment_plane(cloud, distance_threshold=0.01, ransac_n=3, num_iterations=300, rng=4)
    np.testing.assert_array_equal(native[0].equation, alias[0].equation)
    np.testing.assert_array_equal(native[1], alias[1])
    # ransac_n > 3: least-squares samples, as Open3D does with more points
    five, _ = segment_plane(cloud, distance_threshold=0.01, ransac_n=5, rng=4)
    native5, _ = segment_plane(cloud, 0.01, sample_size=5, rng=4)
    np.testing.assert_array_equal(five.equation, native5.equation)
    a = segment_planes(cloud, 0.01, max_iterations=200, rng=1)
    b = segment_planes(cloud, distance_threshold=0.01, num_iterations=200, rng=1)
    assert [s.inliers.tolist() for s in a] == [s.inliers.tolist() for s in b]


def test_filter_aliases_give_the_native_result(rng):
    pts = np.vstack([rng.normal(0, 0.02, (400, 3)), rng.uniform(-1, 1, (40, 3))])
    cloud = PointCloud(pts)
    _, native = statistical_outlier_removal(cloud, 12, 1.5)
    _, alias = statistical_outlier_removal(cloud, nb_neighbors=12, std_ratio=1.5)
    np.testing.assert_array_equal(native, alias)
    assert native.size < len(cloud)
    _, native = radius_outlier_removal(cloud, 0.05, 4)
    _, alias = radius_outlier_removal(cloud, nb_points=4, radius=0.05)
    np.testing.assert_array_equal(native, alias)
    assert 0 < native.size < len(cloud)
    # defaults unchanged: k = 50 and max_iterations = 1000 when neither spelling is given
    np.testing.assert_array_equal(
        statistical_outlier_removal(cloud)[1], statistical_outlier_removal(cloud, 50, 1.0)[1]
    )
    np.testing.assert_array_equal(
        segment_plane(cloud, 0.01)[1], segment_plane(cloud, 0.01, max_iterations=1000)[1]
    )


@pytest.mark.parametrize(
    "call, words",
    [
        (
            lambda c: segment_plane(c, 0.01, distance_threshold=0.01),
            "give threshold or its Open3D spelling distance_threshold, not both",
        ),
        (
            lambda c: segment_plane(c, 0.01, max_iterations=10, num_iterations=10),
            "max_iterations or its Open3D spelling num_iterations, not both",
        ),
        (
            lambda c: segment_plane(c, 0.01, sample_size=3, ransac_n=3),
            "sample_size or its Open3D spelling ransac_n, not both",
        ),
        (
            lambda c: segment_planes(c, 0.01, distance_threshold=0.02),
            "threshold or its Open3D spelling distance_threshold, not both",
        ),
        (
            lambda c: statistical_outlier_removal(c, 10, nb_neighbors=10),
            "k or its Open3D spelling nb_neighbors, not both",
        ),
        (
            lambda c: radius_outlier_removal(c, 0.1, 3, nb_points=3),
            "min_neighbors or its Open3D spelling nb_points, not both",
        ),
        (lambda c: segment_plane(c), r"threshold is required.*distance_threshold"),
        (lambda c: segment_planes(c), "threshold is required"),
        (lambda c: radius_outlier_removal(c, 0.1), r"min_neighbors is required.*nb_points"),
        (lambda c: radius_outlier_removal(c, 16, 0.05), r"Open3D's order \(nb_points, radius\)"),
        (lambda c: segment_plane(c, distance_threshold=-1), "threshold must be"),
        (lambda c: segment_plane(c, 0.01, ransac_n=2), "sample_size must be >= 3"),
        (lambda c: segment_plane(c, 0.01, ransac_n=2.5), "sample_size must be an integer"),
        (lambda c: segment_plane(c, 0.01, num_iterations=0), "max_iterations must be >= 1"),
        (lambda c: statistical_outlier_removal(c, nb_neighbors=1), "k must be >= 2"),
        (lambda c: radius_outlier_removal(c, 0.1, nb_points=-1), "min_neighbors must be >= 0"),
    ],
)
def test_alias_misuse_gives_input_errors(call, words):
    cloud = PointCloud(np.random.default_rng(0).uniform(-1, 1, (100, 3)) * [1, 1, 0.001])
    with pytest.raises(InputError, match=words):
        call(cloud)


def test_ransac_n_larger_than_the_cloud_is_degenerate():
    with pytest.raises(DegenerateError, match="samples of 5 rows"):
        segment_plane(PointCloud(np.eye(3) + 0.5), 0.1, ransac_n=5)


@pytest.mark.realdata
def test_filters_with_open3d_keywords_match_open3d_on_the_office(office):
    # voxel grid: the same voxels (as sets) and centroids within 1e-6 m (float32 input)
    down, _ = voxel_downsample(office, voxel_size=0.04)  # 23,914 points: quick filters
    ref = np.asarray(office.to_open3d().voxel_down_sample(voxel_size=0.04).points)
    assert down.points.shape == ref.shape
    np.testing.assert_allclose(
        down.points[np.lexsort(down.points.T)], ref[np.lexsort(ref.T)], atol=1e-6
    )
    ref_down = down.to_open3d()
    # statistical outliers: 99.9% of the points get the same verdict (ties in the
    # neighbour distances are broken differently by the two k-d trees)
    _, idx = statistical_outlier_removal(down, nb_neighbors=20, std_ratio=2.0)
    _, ref_idx = ref_down.remove_statistical_outlier(nb_neighbors=20, std_ratio=2.0)
    assert 1 - np.setxor1d(idx, np.asarray(ref_idx)).size / len(down) >= 0.999
    # radius outliers: index for index
    _, idx = radius_outlier_removal(down, nb_points=8, radius=0.1)
    _, ref_idx = ref_down.remove_radius_outlier(nb_points=8, radius=0.1)
    np.testing.assert_array_equal(idx, np.asarray(ref_idx))
    assert 0 < idx.size < len(down)
