"""Fixtures of the 3-D pose tests (views, library, lifting): library poses, held-out
views and the error of the trivial mean-pose lifter. The pose modules are imported in
the fixtures, so that collecting this folder without torch only skips the tests."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="module")
def library_poses() -> np.ndarray:
    from robopercept.nn.pose.data import random_poses_3d

    return random_poses_3d(600, rng=0)


@pytest.fixture(scope="module")
def held_out():
    """300 new poses, one random view each: (pixel joints of a ~100 px figure, rooted
    camera-frame truth)."""
    from robopercept.nn.pose.data import random_poses_3d
    from robopercept.nn.pose.views import random_views

    v = random_views(random_poses_3d(300, rng=100), 1, rng=101)
    px = v.keypoints2d * (100.0 / np.ptp(v.keypoints2d[..., 1], axis=1))[:, None, None]
    return px + np.array([320.0, 240.0]), v.rooted()


@pytest.fixture(scope="module")
def mean_pose_error(library_poses, held_out) -> float:
    """PA-MPJPE of the trivial lifter: the library's mean pose, whatever the input."""
    from robopercept.nn.pose.lifting import pa_mpjpe
    from robopercept.nn.pose.views import PELVIS

    _, truth = held_out
    mean = (library_poses - library_poses[:, PELVIS : PELVIS + 1]).mean(0)
    return pa_mpjpe(np.broadcast_to(mean, truth.shape), truth)
