"""Tests of robopercept.nn.pose.views: random views of 3-D poses and the 2-D
normalization (fixtures in conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import DegenerateError, InputError  # noqa: E402
from robopercept.nn.pose.data import project_points  # noqa: E402
from robopercept.nn.pose.views import PELVIS, normalize_pose2d, random_views  # noqa: E402

# ============================================================================ views


class TestRandomViews:
    def test_projection_and_rigidity(self, library_poses):
        k = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
        v = random_views(library_poses[:20], 3, rng=5, camera_matrix=k)
        assert len(v) == 60
        np.testing.assert_allclose(project_points(v.joints3d, k), v.keypoints2d, atol=1e-9)
        src = library_poses[v.pose_index]
        d_src = np.linalg.norm(src[:, :, None] - src[:, None], axis=-1)
        d_cam = np.linalg.norm(v.joints3d[:, :, None] - v.joints3d[:, None], axis=-1)
        np.testing.assert_allclose(d_cam, d_src, atol=1e-12)
        np.testing.assert_allclose(v.joints3d[:, PELVIS], np.c_[np.zeros((60, 2)), v.distance])
        assert np.all((v.distance >= 3) & (v.distance <= 6))
        assert np.all(np.abs(v.yaw) <= np.pi)

    def test_hand_cases_of_the_camera(self):
        # a head 1 m above the pelvis and a nose 0.5 m in front of it (J = 3, root 0)
        pose = np.array([[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.5]]])
        v = random_views(pose, 50, rng=2, elevation=(0.0, 0.0), root=0)
        head, nose = v.joints3d[:, 1], v.joints3d[:, 2]
        np.testing.assert_allclose(head, np.c_[np.zeros(50), -np.ones(50), v.distance], atol=1e-12)
        want = np.c_[0.5 * np.sin(v.yaw), np.zeros(50), v.distance - 0.5 * np.cos(v.yaw)]
        np.testing.assert_allclose(nose, want, atol=1e-12)
        # a raised camera (elevation e > 0) sees the head nearer: (0, -cos e, d - sin e)
        v = random_views(pose, 50, rng=3, elevation=(0.2, 0.6), root=0)
        e = v.elevation
        want = np.c_[np.zeros(50), -np.cos(e), v.distance - np.sin(e)]
        np.testing.assert_allclose(v.joints3d[:, 1], want, atol=1e-12)

    def test_left_is_image_right_when_facing(self):
        # the figure's left (+x) is on the image's right when it faces the camera
        pose = np.array([[[0.0, 0.0, 0.0], [0.3, 0.0, 0.0]]])
        v = random_views(pose, 200, rng=4, root=0)
        facing = np.cos(v.yaw) > 0.5
        assert np.all(v.keypoints2d[facing, 1, 0] > 0)
        assert np.all(v.keypoints2d[~facing & (np.cos(v.yaw) < -0.5), 1, 0] < 0)

    def test_seeded(self, library_poses):
        a = random_views(library_poses[:5], 4, rng=9)
        b = random_views(library_poses[:5], 4, rng=np.random.default_rng(9))
        np.testing.assert_array_equal(a.keypoints2d, b.keypoints2d)
        assert not np.allclose(a.keypoints2d, random_views(library_poses[:5], 4, rng=8).keypoints2d)

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"poses3d": np.zeros((0, 16, 3))}, "empty"),
            ({"poses3d": np.zeros((16, 3))}, "one pose"),
            ({"poses3d": np.full((1, 16, 3), np.nan)}, "finite"),
            ({"views_per_pose": 0}, "views_per_pose must be >= 1"),
            ({"elevation": (0.5, 0.1)}, "elevation"),
            ({"distance": (0.1, 0.2)}, "behind it"),
            ({"camera_matrix": np.eye(2)}, "camera_matrix"),
            ({"views_per_pose": 2**40}, "lower views_per_pose"),
        ],
    )
    def test_bad_input(self, library_poses, kwargs, match):
        # seeded: with fresh entropy the "behind it" case passed or failed by the draw
        # of the camera's yaw (issue 44: a test's outcome must depend on the code only)
        args = {"poses3d": library_poses[:2], "rng": 0, **kwargs}
        with pytest.raises(InputError, match=match):
            random_views(**args)

    def test_millimetres_are_caught(self, library_poses):
        with pytest.raises(InputError, match="metres"):
            random_views(library_poses[:2] * 1000, rng=0)


# ========================================================================= normalization


class TestNormalize:
    def test_hand_case(self):
        p = np.array([[10.0, 10.0], [12.0, 10.0], [10.0, 14.0]])
        s = np.sqrt((0 + 4 + 16) / 3)  # RMS distance to joint 0
        np.testing.assert_allclose(normalize_pose2d(p, root=0), (p - p[0]) / s)
        c = p.mean(0)
        s = np.sqrt(((p - c) ** 2).sum(1).mean())
        np.testing.assert_allclose(normalize_pose2d(p, center="mean", root=0), (p - c) / s)

    def test_invariance(self, rng):
        p = rng.normal(size=(4, 16, 2))
        q = 37.0 * p + [100.0, -50.0]
        np.testing.assert_allclose(normalize_pose2d(q), normalize_pose2d(p), atol=1e-12)
        n = normalize_pose2d(p)
        np.testing.assert_allclose((n**2).sum(-1).mean(-1), 1.0)
        np.testing.assert_array_equal(n[:, PELVIS], 0.0)

    def test_missing_joints(self, rng):
        p = rng.normal(size=(16, 2))
        vis = np.ones(16, bool)
        vis[[0, PELVIS]] = False  # the root is missing: the centre is the visible mean
        p[0] = np.nan
        n = normalize_pose2d(p, vis)
        assert np.isnan(n[[0, PELVIS]]).all()
        seen = p[vis]
        c = seen.mean(0)
        np.testing.assert_allclose(n[vis], (seen - c) / np.sqrt(((seen - c) ** 2).sum(1).mean()))

    def test_errors(self):
        with pytest.raises(DegenerateError, match="fewer than 2 visible joints"):
            normalize_pose2d(np.ones((16, 2)))
        with pytest.raises(DegenerateError, match="fewer than 2"):
            normalize_pose2d(np.arange(32.0).reshape(16, 2), np.eye(16)[3])
        with pytest.raises(InputError, match="NaN/inf at 2 visible joint"):
            normalize_pose2d(np.where(np.eye(16, 2, dtype=bool), np.nan, 1.0))
        with pytest.raises(InputError, match=r"\(x, y, v\) keypoints\?"):
            normalize_pose2d(np.zeros((2, 16, 3)))
        with pytest.raises(InputError, match="center must be one of"):
            normalize_pose2d(np.eye(16, 2), center="median")
