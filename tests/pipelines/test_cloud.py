"""The point-cloud pipeline: filters, then planes, then clusters off the planes."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.pipelines import process_cloud
from robopercept.pointcloud import PointCloud


def _scene(rng):
    # a 1 m x 1 m floor (z = 0) with two 5 cm cubes of points above it, one far outlier,
    # and a NaN point
    floor = np.c_[rng.uniform(0, 1, (2000, 2)), np.zeros(2000)]
    cube_a = rng.uniform(0, 0.05, (300, 3)) + np.array([0.2, 0.2, 0.1])
    cube_b = rng.uniform(0, 0.05, (300, 3)) + np.array([0.7, 0.7, 0.1])
    return np.r_[floor, cube_a, cube_b, [[5.0, 5.0, 5.0]], [[np.nan, 0, 0]]]


def test_planes_then_clusters_label_every_point():
    pts = _scene(np.random.default_rng(0))
    res = process_cloud(
        PointCloud(pts),
        boxes=[("x", -1.0, 2.0)],  # drops the far outlier
        planes=(1, 0.005),
        clusters=(0.02, 50, 10_000),
        rng=0,
    )
    names = [s["step"] for s in res.steps]
    assert names[0] == "read" and res.steps[0]["nonfinite_dropped"] == 1
    assert names[1] == "pass-through x [-1, 2]" and res.steps[1]["points_out"] == 2600
    assert len(res.planes) == 1 and res.planes[0]["inliers"] == 2000
    np.testing.assert_allclose(np.abs(res.planes[0]["equation"][:3]), [0, 0, 1], atol=1e-6)
    assert sorted(res.cluster_sizes) == [300, 300]
    # labels: 1 the floor, 2 and 3 the cubes, nothing left unassigned
    assert res.segment.shape == (2600,)
    np.testing.assert_array_equal(np.bincount(res.segment), [0, 2000, 300, 300])
    floor_z = res.cloud.points[res.segment == 1, 2]
    assert np.all(floor_z == 0)


def test_no_steps_keeps_the_finite_points():
    pts = _scene(np.random.default_rng(1))
    res = process_cloud(PointCloud(pts))
    assert len(res.cloud) == len(pts) - 1 and not res.segment.any()
    assert [s["step"] for s in res.steps] == ["read"] and res.planes == [] == res.cluster_sizes


# issue 25: every step's parameters are checked before any step runs
@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"sor": ("3", "3")}, "k must be an integer; got '3'"),
        ({"sor": (1,)}, r"sor must be \(k, std_ratio\), 2 values; got \(1,\)"),
        ({"clusters": ("3", "3")}, r"clusters must be \(tolerance, min_size, max_size\), 3"),
        ({"clusters": ()}, "clusters must be"),
        ({"clusters": (0.02, 10.5, 100)}, "min_size must be an integer"),
        ({"boxes": [[]]}, r"each pass-through box must be \(axis, low, high\)"),
        ({"boxes": "z"}, "boxes must be a list of"),
        ({"boxes": [("z", "0", 1)]}, "min_value must be a real number"),
        ({"planes": (1,)}, r"planes must be \(max_planes, threshold\)"),
        ({"planes": (1, -0.01)}, r"threshold must be in \(0, inf\]"),
        ({"voxel": np.nan}, "voxel_size must be finite"),
        ({"min_plane": None}, "min_inliers must be an integer"),
    ],
)
def test_bad_step_parameters(kwargs, words):
    cloud = PointCloud(_scene(np.random.default_rng(0)))
    with pytest.raises(InputError, match=words):
        process_cloud(cloud, **kwargs)


def test_a_bare_array_is_refused():
    with pytest.raises(InputError, match=r"cloud must be a PointCloud; got ndarray: wrap"):
        process_cloud(np.zeros((0, 3)))
