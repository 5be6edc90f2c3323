"""Procedural pose data (issue 28): the 3-D figure's kinematics, the camera, the
rendering's ground truth (projection, visibility, silhouette), determinism, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.pose.data import (
    BONE_LENGTHS,
    PoseDataset,
    procedural_pose_set,
    project_points,
    random_poses_3d,
)
from robopercept.nn.skeleton import MPII_16

J = {name: i for i, name in enumerate(MPII_16.joints)}


def _len(p: np.ndarray, a: str, b: str) -> np.ndarray:
    return np.linalg.norm(p[:, J[a]] - p[:, J[b]], axis=-1)


def _angle(p: np.ndarray, a: str, b: str, c: str) -> np.ndarray:
    """Angle at b between b->a and b->c, degrees."""
    u = p[:, J[a]] - p[:, J[b]]
    v = p[:, J[c]] - p[:, J[b]]
    cos = (u * v).sum(-1) / np.linalg.norm(u, axis=-1) / np.linalg.norm(v, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def test_random_poses_have_the_bone_lengths_and_joint_limits_of_the_table():
    p = random_poses_3d(2000, rng=0)
    assert p.shape == (2000, 16, 3)
    np.testing.assert_array_equal(p[:, J["pelvis"]], 0.0)
    # body scale U(0.85, 1.15) times a per-bone factor U(0.92, 1.08)
    lo, hi = 0.85 * 0.92, 1.15 * 1.08
    for (a, b), bone in (
        (("right_hip", "right_knee"), "thigh"),
        (("left_knee", "left_ankle"), "shin"),
        (("pelvis", "thorax"), "spine"),
        (("left_shoulder", "left_elbow"), "upper_arm"),
        (("right_elbow", "right_wrist"), "forearm"),
        (("upper_neck", "head_top"), "head"),
    ):
        ratio = _len(p, a, b) / BONE_LENGTHS[bone]
        assert lo - 1e-9 <= ratio.min() and ratio.max() <= hi + 1e-9, bone
    # the knee bends back by 0..130 degrees: the hip-knee-ankle angle is 50..180
    for side in ("left", "right"):
        knee = _angle(p, f"{side}_hip", f"{side}_knee", f"{side}_ankle")
        assert knee.min() >= 50 - 1e-6 and knee.max() <= 180 + 1e-6
        elbow = _angle(p, f"{side}_shoulder", f"{side}_elbow", f"{side}_wrist")
        assert elbow.min() >= 35 - 1e-6
    # the figure's left side is at +x (its own frame): hips never cross
    assert np.all(p[:, J["left_hip"], 0] > p[:, J["right_hip"], 0])
    # the knee bends backwards: the ankle is behind the thigh's line (z) when flexed
    np.testing.assert_array_equal(random_poses_3d(5, rng=3), random_poses_3d(5, rng=3))


def test_project_points_equals_opencv():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(0)
    pts = rng.uniform([-1, -1, 2], [1, 1, 6], (50, 3))
    k = np.array([[300.0, 0, 64.5], [0, 310.0, 60.2], [0, 0, 1]])
    ours = project_points(pts, k)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, None)
    # OpenCV's pixel (x, y) is ours under the same convention: 1e-9 up to float rounding
    np.testing.assert_allclose(ours, ref[:, 0], atol=1e-9)
    with pytest.raises(InputError, match="in front"):
        project_points([[0, 0, -1.0]], k)
    with pytest.raises(InputError, match=r"\(\.\.\., 3\)"):
        project_points([[0, 0]], k)


@pytest.fixture(scope="module")
def figures() -> PoseDataset:
    return procedural_pose_set(40, (128, 96), rng=7)


def test_keypoints_are_the_projections_of_the_3d_joints(figures):
    ds = figures
    assert ds.images.shape == (40, 96, 128, 3) and ds.images.dtype == np.float32
    assert 0.0 <= ds.images.min() and ds.images.max() <= 1.0
    proj = project_points(ds.joints3d, ds.cameras)
    np.testing.assert_allclose(ds.keypoints[..., :2], proj, atol=1e-9)
    assert set(np.unique(ds.keypoints[..., 2])) <= {0.0, 1.0, 2.0}
    # every figure is inside the image with most joints seen
    assert (ds.keypoints[..., 2] > 0).mean() > 0.97
    assert 0.6 < (ds.keypoints[..., 2] == 2).mean() < 0.98


def test_seen_joints_lie_on_the_silhouette_and_the_box_is_the_mask_box(figures):
    ds = figures
    seen = ds.keypoints[..., 2] == 2
    n, j = np.nonzero(seen)
    c = ds.keypoints[n, j, 0].astype(int)
    r = ds.keypoints[n, j, 1].astype(int)
    # a seen joint's pixel shows the figure (it is not hidden by the bar or the border)
    assert ds.masks[n, r, c].mean() > 0.99
    for i in range(len(ds)):
        ys, xs = np.nonzero(ds.masks[i])
        np.testing.assert_array_equal(ds.boxes[i], [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1])


def test_the_figure_faces_the_camera_so_left_is_on_the_image_right_mostly(figures):
    ds = figures
    # facing the camera (yaw within 75 degrees), the figure's left shoulder is on the
    # image's right unless the torso twists or leans far: check the large majority
    left = ds.keypoints[:, J["left_shoulder"], 0]
    right = ds.keypoints[:, J["right_shoulder"], 0]
    assert (left > right).mean() > 0.85


def test_determinism_split_and_refusals():
    a = procedural_pose_set(3, (64, 64), rng=11)
    b = procedural_pose_set(3, (64, 64), rng=11)
    np.testing.assert_array_equal(a.images, b.images)
    np.testing.assert_array_equal(a.keypoints, b.keypoints)
    parts = procedural_pose_set(10, (32, 32), rng=1).split((0.6, 0.2, 0.2), rng=0)
    assert [len(p) for p in parts] == [6, 2, 2]
    image, target = a[0]
    assert tuple(image.shape) == (3, 64, 64) and tuple(target["keypoints"].shape) == (16, 3)
    with pytest.raises(InputError, match="size"):
        procedural_pose_set(2, (16, 16))
    with pytest.raises(InputError, match="scale"):
        procedural_pose_set(2, (64, 64), scale=(0.9, 0.5))
    with pytest.raises(InputError, match="n_images"):
        procedural_pose_set(0)
    with pytest.raises(InputError, match="fewer or smaller"):
        procedural_pose_set(100000, (1024, 1024))
    with pytest.raises(InputError, match="sum to 1"):
        a.split((0.5, 0.2))
