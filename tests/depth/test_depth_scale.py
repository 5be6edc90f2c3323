"""Issue 48: ``depth_to_points(depth, K, 5000)`` (TUM's and Open3D's units per metre where
metres per unit are meant) gave a median depth of 37,550 km without a word. The Python
API now warns as ``rgbd-import`` does (the same rule: a median depth of the measured
pixels outside 0.1 to 20 m), naming the depth scale that fixes it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from robopercept.depth import depth_to_points
from robopercept.depth.rgbd import (
    PLAUSIBLE_DEPTH_M,
    DepthScaleWarning,
    depth_scale_warning,
    plausible_depth,
)
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.imaging import read_image
from tests.conftest import data_path

try:  # the reference; only the parity test needs it (its import takes seconds)
    import open3d  # noqa: F401
except ImportError:  # pragma: no cover - depends on the environment
    pass

# TUM fr1, as the slambook2 code that ships these frames uses it
TUM_K = CameraIntrinsics(640, 480, 520.9, 521.0, 325.1, 249.7)


@pytest.fixture(scope="module")
def tum_depth():
    depth = read_image(data_path("rgbd", "tum_pair_slambook2", "1_depth.png"))
    assert depth.dtype == np.uint16 and depth.shape == (480, 640)
    return depth


def _quiet(call):
    """``call()`` with DepthScaleWarning turned into an error (it must not fire)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", DepthScaleWarning)
        return call()


@pytest.mark.realdata
def test_tum_units_per_metre_warn_and_name_the_fix(tum_depth):
    with pytest.warns(DepthScaleWarning, match=r"use depth_scale=0\.0002 \(1/5000\)") as rec:
        pts = depth_to_points(tum_depth, TUM_K, 5000)
    assert len(rec) == 1 and "units per metre given?" in str(rec[0].message)
    assert rec[0].filename == __file__  # points at the caller's line
    assert np.nanmedian(pts[..., 2]) > 1e7  # the absurd depth of the issue (km)
    # the right scale: no warning, and a plausible scene
    good = _quiet(lambda: depth_to_points(tum_depth, TUM_K, 1 / 5000, organized=False))
    assert plausible_depth(float(np.median(good[:, 2])))


@pytest.mark.realdata
def test_tum_points_match_open3d_with_its_units_per_metre(tum_depth):
    """Open3D's create_from_depth_image takes units per metre (5000); ours metres per
    unit (1/5000): the same points, to float32 rounding (Open3D's image is float32)."""
    o3d = pytest.importorskip("open3d")  # imported at collection when present
    k = o3d.camera.PinholeCameraIntrinsic(640, 480, 520.9, 521.0, 325.1, 249.7)
    ref = o3d.geometry.PointCloud.create_from_depth_image(
        o3d.geometry.Image(tum_depth), k, depth_scale=5000.0, depth_trunc=1e6
    )
    ours = _quiet(lambda: depth_to_points(tum_depth, TUM_K, 1 / 5000, organized=False))
    np.testing.assert_allclose(ours, np.asarray(ref.points), rtol=1e-6, atol=1e-6)


def test_the_rule_is_rgbd_imports():
    lo, hi = PLAUSIBLE_DEPTH_M
    assert (lo, hi) == (0.1, 20.0)
    assert plausible_depth(0.1) and plausible_depth(20.0) and plausible_depth(1.0)
    assert not plausible_depth(0.0999) and not plausible_depth(20.01)
    assert not plausible_depth(float("nan"))


@pytest.mark.parametrize(
    "depth, scale, fix",
    [
        (np.full((48, 64), 9500, np.uint16), 5000, r"depth_scale=0\.0002 \(1/5000\)"),
        (np.full((48, 64), 1500, np.uint16), 1000, r"depth_scale=0\.001 \(1/1000\)"),
        (np.full((48, 64), 1.5, np.float32), 0.001, r"depth_scale=1 \(depth already in metres"),
        (np.full((48, 64), 1500.0), 1.0, r"depth_scale=0\.001 \(millimetres\)"),
        (np.full((48, 64), 1e9), 1.0, "check the depth image and its scale"),
    ],
)
def test_wrong_scales_warn_with_the_fix(depth, scale, fix):
    with pytest.warns(DepthScaleWarning, match=fix):
        depth_to_points(depth, CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0), scale)


@pytest.mark.parametrize(
    "depth, scale",
    [
        (np.full((48, 64), 1500, np.uint16), 0.001),  # a D435 frame at 1.5 m
        (np.full((48, 64), 9500, np.uint16), 1 / 5000),  # TUM
        (np.full((48, 64), 2.5, np.float32), 1.0),  # metres
        (np.zeros((48, 64), np.uint16), 5000),  # nothing measured: nothing to judge
        (np.full((48, 64), np.nan), 1.0),
    ],
)
def test_right_scales_and_empty_frames_do_not_warn(depth, scale):
    _quiet(lambda: depth_to_points(depth, CameraIntrinsics(64, 48, 50.0, 50.0, 32.0, 24.0), scale))
    assert depth_scale_warning(depth, scale) is None


def test_the_median_is_of_the_measured_pixels_only():
    # 90% holes (0) and NaN; the measured 10% at 2 m: plausible, no warning
    depth = np.zeros((480, 640), np.uint16)
    depth[::4, ::8] = 2000
    assert depth_scale_warning(depth, 0.001) is None
    depth[::4, ::8] = 60000  # 60 m at the millimetre scale
    assert "median depth 60 m" in depth_scale_warning(depth, 0.001)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: plausible_depth("2"), "median_m must be a real number"),
        (lambda: plausible_depth(None), "median_m must be a real number"),
        (lambda: plausible_depth(True), "median_m must be a real number"),
        (lambda: depth_scale_warning([[1, 2], ["a", 3]], 0.001), "depth must"),
        (lambda: depth_scale_warning(np.ones(5), 0.001), "2-D"),
        (lambda: depth_scale_warning(np.ones((2, 2)), 0), "depth_scale"),
        (lambda: depth_scale_warning(np.ones((2, 2)), "1"), "depth_scale"),
    ],
)
def test_bad_arguments_give_input_errors(call, words):
    with pytest.raises(InputError, match=words):
        call()


def test_huge_integers_are_judged_not_converted():
    assert not plausible_depth(10**400) and plausible_depth(np.int64(3))
