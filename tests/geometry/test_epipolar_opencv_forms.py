"""Two-view geometry in OpenCV's call shapes (issue 48): ``F, mask = find_fundamental``,
``E, mask = find_essential`` and ``retval, R, t, mask = decompose_essential`` in the
order and types of ``cv2.findFundamentalMat``, ``cv2.findEssentialMat`` and
``cv2.recoverPose``; OpenCV's ``(N, 1, 2)`` point arrays taken; attributes kept."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.geometry import (
    FundamentalFit,
    RelativePose,
    decompose_essential,
    eight_point,
    epipolar_lines,
    find_essential,
    find_fundamental,
    sampson_distance,
)
from robopercept.geometry.transforms import rotation_from_rotvec

K = np.array([[700.0, 0.0, 320.0], [0.0, 690.0, 240.0], [0.0, 0.0, 1.0]])
R_TRUE = rotation_from_rotvec(np.array([0.05, -0.2, 0.03]))
T_TRUE = np.array([-0.5, 0.05, 0.1])


def _scene(n=150, seed=0, outliers=0):
    """Pixels of points 3-8 m ahead in two cameras (X2 = R X1 + t), the first
    ``outliers`` of x2 moved 20-60 px, as OpenCV's (N, 1, 2) float32 arrays."""
    g = np.random.default_rng(seed)
    X = np.c_[g.uniform(-2, 2, n), g.uniform(-1.5, 1.5, n), g.uniform(3, 8, n)]
    x1 = X @ K.T
    x2 = (X @ R_TRUE.T + T_TRUE) @ K.T
    x1, x2 = x1[:, :2] / x1[:, 2:], x2[:, :2] / x2[:, 2:]
    x2[:outliers] += g.uniform(20, 60, (outliers, 2)) * g.choice([-1, 1], (outliers, 2))
    return x1.astype(np.float32)[:, None], x2.astype(np.float32)[:, None]


def _unit(m):
    m = m / np.linalg.norm(m)
    return m if m.flat[np.argmax(np.abs(m))] > 0 else -m


def test_find_fundamental_unpacks_like_cv2():
    """``F, mask`` as cv2.findFundamentalMat(x1, x2, cv2.FM_RANSAC, 1, 0.99) gives them:
    F (3, 3) float64 (ours unit Frobenius norm, cv2's F[2, 2] = 1: the same F up to
    scale, within 1e-3 once both are unit norm: float32 pixels); mask (N, 1) uint8 of
    0/1, the 30 outliers 0 in both."""
    x1, x2 = _scene(outliers=30)
    fit = find_fundamental(x1, x2, rng=0)
    F, mask = fit
    assert isinstance(fit, FundamentalFit) and F is fit.F
    assert F.shape == (3, 3) and F.dtype == np.float64
    assert mask.shape == (150, 1) and mask.dtype == np.uint8 and set(np.unique(mask)) == {0, 1}
    np.testing.assert_array_equal(mask[:, 0].astype(bool), fit.inliers)
    assert fit.n_iterations > 0 and fit.residuals.shape == (150,)  # attributes kept
    Fc, mc = cv2.findFundamentalMat(x1, x2, cv2.FM_RANSAC, 1.0, 0.99)
    assert mc.shape == mask.shape and mc.dtype == mask.dtype
    assert not mask[:30].any() and not mc[:30].any() and mask[30:].all()
    assert np.abs(_unit(F) - _unit(Fc)).max() < 1e-3


def test_find_essential_and_recover_pose_unpack_like_cv2():
    """``E, mask = find_essential(x1, x2, K)`` then ``n, R, t, mask =
    decompose_essential(E, x1, x2, K)`` on (N, 1, 2) float32 pixels, against
    cv2.findEssentialMat and cv2.recoverPose on the same arrays: E equal up to sign
    within 1e-3, R within 1e-3, t (3, 1) within 1e-3 of cv2's and of the true direction,
    the same count, and the same (N, 1) uint8 mask of 255 (cv2.recoverPose without an
    input mask)."""
    x1, x2 = _scene()
    E, emask = find_essential(x1, x2, K, rng=0)
    Ec, emc = cv2.findEssentialMat(x1, x2, K, cv2.RANSAC, 0.999, 1.0)
    assert emask.shape == emc.shape == (150, 1) and emask.dtype == np.uint8
    assert np.abs(_unit(E) - _unit(Ec)).max() < 1e-3
    pose = decompose_essential(E, x1, x2, K)
    n, R, t, mask = pose
    nc, Rc, tc, mc = cv2.recoverPose(Ec, x1, x2, K)
    assert isinstance(pose, RelativePose) and pose.t.shape == (3,)  # attributes kept
    assert isinstance(n, int) and n == nc == 150
    assert t.shape == tc.shape == (3, 1) and R.shape == (3, 3)
    np.testing.assert_allclose(R, Rc, atol=1e-3)
    np.testing.assert_allclose(t, tc, atol=1e-3)
    np.testing.assert_allclose(t[:, 0], T_TRUE / np.linalg.norm(T_TRUE), atol=1e-3)
    assert mask.dtype == mc.dtype == np.uint8 and mask.shape == mc.shape
    np.testing.assert_array_equal(mask, mc)


def test_point_functions_take_opencv_point_vectors():
    """eight_point, sampson_distance and epipolar_lines give for (N, 1, 2) exactly what
    they give for (N, 2); other 3-D shapes are refused with OpenCV's form named."""
    x1, x2 = _scene(40)
    f1, f2 = x1[:, 0].astype(float), x2[:, 0].astype(float)
    F = eight_point(x1, x2)
    np.testing.assert_array_equal(F, eight_point(f1, f2))
    np.testing.assert_array_equal(sampson_distance(F, x1, x2), sampson_distance(F, f1, f2))
    np.testing.assert_array_equal(epipolar_lines(F, x1), epipolar_lines(F, f1))
    with pytest.raises(InputError, match=r"x1 must be \(N, 2\) pixel coordinates \(or OpenCV's"):
        eight_point(np.zeros((40, 2, 1)), f2)


def test_eight_point_on_many_matches_is_fast():
    """The eight-point system of N matches is N x 9: its thin SVD is enough (the full
    one built an N x N matrix: 1 s and 32 MB at N = 2000). 5000 matches, exact."""
    g = np.random.default_rng(2)
    X = np.c_[g.uniform(-2, 2, 5000), g.uniform(-1.5, 1.5, 5000), g.uniform(3, 8, 5000)]
    x1 = X @ K.T
    x2 = (X @ R_TRUE.T + T_TRUE) @ K.T
    x1, x2 = x1[:, :2] / x1[:, 2:], x2[:, :2] / x2[:, 2:]
    F = eight_point(x1, x2)  # a full SVD here would need a 10000 x 10000 U (800 MB)
    assert sampson_distance(F, x1, x2).max() < 1e-6


def test_triangulation_rectification_undistortion_take_opencv_point_vectors():
    """triangulate, rectify_uncalibrated, undistort_points and min_area_rectangle give
    for OpenCV's (N, 1, 2) exactly what they give for (N, 2); triangulate agrees with
    cv2.triangulatePoints (1e-6 m: both solve the same DLT in float64)."""
    from robopercept.geometry import (
        min_area_rectangle,
        rectify_uncalibrated,
        triangulate,
        undistort_points,
    )

    x1, x2 = _scene(40)
    f1, f2 = x1[:, 0].astype(float), x2[:, 0].astype(float)
    P1 = K @ np.c_[np.eye(3), np.zeros(3)]
    P2 = K @ np.c_[R_TRUE, T_TRUE]
    X = triangulate(P1, P2, x1, x2)
    np.testing.assert_array_equal(X, triangulate(P1, P2, f1, f2))
    h = cv2.triangulatePoints(P1, P2, f1.T, f2.T)
    np.testing.assert_allclose(X, (h[:3] / h[3]).T, atol=1e-6)
    F = eight_point(f1, f2)
    a, b = rectify_uncalibrated(F, x1, x2, (640, 480)), rectify_uncalibrated(F, f1, f2, (640, 480))
    for u, v in zip(a, b, strict=True):
        np.testing.assert_array_equal(u, v)
    dist = np.array([0.1, -0.05, 0.001, 0.002, 0.0])
    np.testing.assert_array_equal(undistort_points(x1, K, dist), undistort_points(f1, K, dist))
    for u, v in zip(min_area_rectangle(x1), min_area_rectangle(f1), strict=True):
        np.testing.assert_array_equal(u, v)
