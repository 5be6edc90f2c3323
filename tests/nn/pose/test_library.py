"""Tests of robopercept.nn.pose.library: lifting by matching against a library of
projected 3-D poses (fixtures in conftest.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import DegenerateError, InputError  # noqa: E402
from robopercept.nn.pose.library import PoseLibrary  # noqa: E402
from robopercept.nn.pose.lifting import pa_mpjpe  # noqa: E402
from robopercept.nn.pose.views import PELVIS, normalize_pose2d, random_views  # noqa: E402
from tests.conftest import data_path  # noqa: E402

HEAD = 9  # MPII_16's head top


@pytest.fixture(scope="module")
def library(library_poses: np.ndarray) -> PoseLibrary:
    return PoseLibrary(library_poses, views_per_pose=16, rng=1)


# ============================================================================= matching


class TestPoseLibrary:
    def test_own_views_give_their_exact_pose(self, library, library_poses):
        v = random_views(library_poses, 16, rng=1)  # the library's own views
        pick = np.arange(0, len(v), 397)
        query = 3.7 * v.keypoints2d[pick] * 100 + [512.0, -80.0]
        np.testing.assert_allclose(library.lift(query), v.rooted()[pick], atol=1e-12)
        np.testing.assert_array_equal(library.pose_index, v.pose_index)
        # one pose alone, and the same with its missing joints marked
        one = library.lift(query[0])
        assert one.shape == (16, 3)
        assert library.lift(np.zeros((0, 16, 2))).shape == (0, 16, 3)  # an empty batch
        vis = np.ones(16, bool)
        vis[[0, 15]] = False
        masked = np.where(vis[:, None], query[0], np.nan)
        np.testing.assert_allclose(library.lift(masked, vis), one, atol=1e-12)

    def test_invariant_to_2d_translation_and_scale(self, library, held_out):
        px, _ = held_out
        a = library.lift(px)
        b = library.lift(0.25 * px - [1000.0, 3.0])
        np.testing.assert_allclose(b, a, atol=1e-12)

    def test_nearest_neighbour_by_brute_force(self, library, held_out, rng):
        # the reference: normalize both sides by normalize_pose2d, then argmin / k smallest
        px, _ = held_out
        q = normalize_pose2d(px[:40]).reshape(40, -1)
        lib = library.keypoints2d.reshape(len(library), -1)
        d = ((q[:, None] - lib[None]) ** 2).sum(-1)
        np.testing.assert_allclose(library.lift(px[:40]), library.joints3d[d.argmin(1)])
        near = np.argsort(d, axis=1)[:, :3]
        np.testing.assert_allclose(library.lift(px[:40], k=3), library.joints3d[near].mean(1))
        # with missing joints: over the visible joints, both sides normalized over them
        vis = rng.random((40, 16)) > 0.25
        vis[:, PELVIS] = True
        vis[::2, PELVIS] = False
        q = normalize_pose2d(px[:40], vis)
        want = []
        for i in range(40):
            lv = normalize_pose2d(library.keypoints2d, np.broadcast_to(vis[i], (len(library), 16)))
            dist = np.nansum((lv - q[i]) ** 2, axis=(1, 2))
            want.append(library.joints3d[dist.argmin()])
        np.testing.assert_allclose(
            library.lift(np.where(vis[..., None], px[:40], np.nan), vis), want
        )

    def test_beats_the_mean_pose(self, library, held_out, mean_pose_error):
        # measured (600 poses x 16 views): mean pose 185 mm, k=1 157 mm (0.85), k=5
        # 129 mm (0.70); noise of 2 px on the 100 px figures: k=5 131 mm (0.71)
        px, truth = held_out
        noisy = px + np.random.default_rng(7).normal(0, 2.0, px.shape)
        assert pa_mpjpe(library.lift(px), truth) < 0.92 * mean_pose_error
        assert pa_mpjpe(library.lift(px, k=5), truth) < 0.78 * mean_pose_error
        assert pa_mpjpe(library.lift(noisy, k=5), truth) < 0.78 * mean_pose_error

    def test_seeded(self, library_poses):
        a = PoseLibrary(library_poses[:10], views_per_pose=3, rng=4)
        b = PoseLibrary(library_poses[:10], views_per_pose=3, rng=4)
        np.testing.assert_array_equal(a.keypoints2d, b.keypoints2d)
        np.testing.assert_array_equal(a.joints3d, b.joints3d)

    def test_bad_input(self, library, library_poses):
        with pytest.raises(InputError, match="library's 16 joints; got 17"):
            library.lift(np.zeros((2, 17, 2)))
        with pytest.raises(InputError, match="mark missing joints with visible"):
            library.lift(np.where(np.eye(16, 2, dtype=bool), np.nan, 1.0))
        with pytest.raises(InputError, match=r"visible must be one flag per joint, shape \(16,\)"):
            library.lift(np.eye(16, 2), np.ones(15))
        with pytest.raises(InputError, match="k must be at most the library size"):
            library.lift(np.eye(16, 2), k=len(library) + 1)
        with pytest.raises(DegenerateError, match="cannot be normalized"):
            library.lift(np.ones((16, 2)))
        with pytest.raises(InputError, match="empty"):
            PoseLibrary(np.zeros((0, 16, 3)))
        with pytest.raises(InputError, match="k must be at most the library size, 2"):
            PoseLibrary(library_poses[:1], views_per_pose=2, k=3)
        with pytest.raises(DegenerateError, match="library views"):
            PoseLibrary(np.zeros((1, 16, 3)))

    @pytest.mark.realdata
    def test_real_mpii_annotations(self, library):
        # five people of MPII Human Pose (mmpose's test subset; joints in MPII_16's
        # order, joints_vis marks the labelled ones). No 3-D truth: the lifted pose,
        # seen along the camera's axis, must look like the input -- its normalized
        # projection closer to the query than the library's average 2-D pose is
        records = json.loads(
            data_path("detection", "mpii_keypoints_mmpose", "test_mpii.json").read_text()
        )
        kp = np.array([r["joints"] for r in records], float)
        vis = np.array([r["joints_vis"] for r in records]) > 0
        lifted = library.lift(kp, vis, k=3)
        assert np.isfinite(lifted).all() and np.all(lifted[:, PELVIS] == 0)
        mean2d = library.keypoints2d.mean(0)
        for i in range(len(kp)):
            q = normalize_pose2d(kp[i], vis[i])[vis[i]]
            ours = normalize_pose2d(lifted[i, :, :2], vis[i])[vis[i]]
            base = normalize_pose2d(mean2d, vis[i])[vis[i]]
            assert np.sqrt(((ours - q) ** 2).sum(1).mean()) < np.sqrt(
                ((base - q) ** 2).sum(1).mean()
            )
