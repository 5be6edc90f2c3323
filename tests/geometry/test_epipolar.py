"""Two-view geometry: eight-point F and E, RANSAC, epipolar lines, epipoles, relative
pose by cheirality, triangulation; against OpenCV and synthetic ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.geometry.epipolar import (
    decompose_essential,
    eight_point,
    epipolar_lines,
    epipoles,
    essential_from_pose,
    find_essential,
    find_fundamental,
    fundamental_from_essential,
    sampson_distance,
    skew,
)
from robopercept.geometry.transforms import rotation_from_rotvec
from robopercept.geometry.triangulation import triangulate

K = np.array([[700.0, 0.0, 320.0], [0.0, 690.0, 240.0], [0.0, 0.0, 1.0]])


def _scene(n=200, seed=0, rotvec=(0.05, -0.2, 0.03), t=(-0.5, 0.05, 0.1)):
    """Points 3-8 m in front of camera 1; camera 2 at X2 = R X1 + t."""
    gen = np.random.default_rng(seed)
    X = np.c_[gen.uniform(-2, 2, n), gen.uniform(-1.5, 1.5, n), gen.uniform(3, 8, n)]
    R = rotation_from_rotvec(np.array(rotvec))
    t = np.asarray(t, dtype=float)
    x1 = X @ K.T
    x1 = x1[:, :2] / x1[:, 2:]
    X2 = X @ R.T + t
    x2 = X2 @ K.T
    x2 = x2[:, :2] / x2[:, 2:]
    return X, R, t, x1, x2


def _same_up_to_scale(a, b, tol):
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    return min(np.abs(a - b).max(), np.abs(a + b).max()) <= tol


def test_skew_is_the_cross_product():
    v, u = np.array([1.0, -2.0, 3.0]), np.array([0.5, 4.0, -1.0])
    assert np.allclose(skew(v) @ u, np.cross(v, u))


def test_eight_point_exact_without_noise():
    _, R, t, x1, x2 = _scene()
    F = eight_point(x1, x2)
    assert sampson_distance(F, x1, x2).max() < 1e-6
    assert np.linalg.matrix_rank(F, tol=1e-10) == 2
    truth = fundamental_from_essential(essential_from_pose(R, t), K, K)
    assert _same_up_to_scale(F, truth, 1e-8)


def test_eight_point_equals_opencv():
    cv2 = pytest.importorskip("cv2")
    _, _, _, x1, x2 = _scene(seed=1)
    x2 = x2 + np.random.default_rng(2).normal(0, 0.5, x2.shape)
    F = eight_point(x1, x2)
    ref, _ = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)
    # same algorithm (normalized 8-point with rank-2 projection); 1e-6 after scaling
    assert _same_up_to_scale(F, ref, 1e-6)


def test_essential_from_normalized_points():
    _, R, t, x1, x2 = _scene(seed=3)
    kinv = np.linalg.inv(K)
    n1 = x1 @ kinv[:2, :2].T + kinv[:2, 2]
    n2 = x2 @ kinv[:2, :2].T + kinv[:2, 2]
    E = eight_point(n1, n2, essential=True)
    assert _same_up_to_scale(E, essential_from_pose(R, t), 1e-8)
    s = np.linalg.svd(E, compute_uv=False)
    assert np.allclose(s / s[0], [1.0, 1.0, 0.0], atol=1e-12)


def test_ransac_with_noise_and_outliers():
    """0.5 px noise and 30 % outliers: the inliers found are the true ones and F keeps
    the noise-free correspondences within the noise level."""
    _, _, _, x1, x2 = _scene(300, seed=4)
    gen = np.random.default_rng(5)
    clean2 = x2.copy()
    noisy1 = x1 + gen.normal(0, 0.5, x1.shape)
    noisy2 = x2 + gen.normal(0, 0.5, x2.shape)
    bad = gen.choice(300, 90, replace=False)
    noisy2[bad] = gen.uniform([0, 0], [640, 480], (90, 2))
    fit = find_fundamental(noisy1, noisy2, threshold=1.5, rng=0)
    truth = np.ones(300, dtype=bool)
    truth[bad] = False
    far = truth | (sampson_distance(fit.F, noisy1, noisy2) < 1.5)  # a random match may fit
    assert fit.inliers[truth].mean() >= 0.97
    assert not fit.inliers[~far].any()
    d = sampson_distance(fit.F, x1, clean2)
    assert np.sqrt(np.mean(d[truth] ** 2)) < 0.5
    again = find_fundamental(noisy1, noisy2, threshold=1.5, rng=0)
    assert np.array_equal(again.F, fit.F) and np.array_equal(again.inliers, fit.inliers)


def test_find_essential_and_recover_pose_against_opencv():
    cv2 = pytest.importorskip("cv2")
    _, R, t, x1, x2 = _scene(250, seed=6)
    gen = np.random.default_rng(7)
    x1n, x2n = x1 + gen.normal(0, 0.3, x1.shape), x2 + gen.normal(0, 0.3, x2.shape)
    fit = find_essential(x1n, x2n, K, threshold=1.0, rng=1)
    pose = decompose_essential(fit.F, x1n[fit.inliers], x2n[fit.inliers], K)
    angle = np.degrees(np.arccos(np.clip((np.trace(pose.R.T @ R) - 1) / 2, -1, 1)))
    assert angle < 0.2
    assert np.degrees(np.arccos(pose.t @ (t / np.linalg.norm(t)))) < 1.0
    assert pose.candidates == 1 and pose.in_front.mean() > 0.99
    # the same decomposition as cv2.recoverPose for the same E
    _, R_cv, t_cv, _ = cv2.recoverPose(fit.F, x1n[fit.inliers], x2n[fit.inliers], K)
    assert np.allclose(pose.R, R_cv, atol=1e-9) and np.allclose(pose.t, t_cv.ravel(), atol=1e-9)


@pytest.mark.parametrize(
    ("rotvec", "t"),
    [
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        ((0.1, 0.3, -0.2), (0.2, -0.1, 1.0)),
        ((-0.3, 0.05, 0.1), (-0.4, 0.3, -0.2)),
    ],
)
def test_decompose_essential_recovers_synthetic_motions(rotvec, t):
    _, R, tt, x1, x2 = _scene(100, seed=8, rotvec=rotvec, t=t)
    pose = decompose_essential(essential_from_pose(R, tt), x1, x2, K)
    assert np.allclose(pose.R, R, atol=1e-9)
    assert np.allclose(pose.t, tt / np.linalg.norm(tt), atol=1e-9)
    assert pose.in_front.all()


def test_epipolar_lines_and_epipoles():
    cv2 = pytest.importorskip("cv2")
    _, R, t, x1, x2 = _scene(50, seed=9)
    F = fundamental_from_essential(essential_from_pose(R, t), K, K)
    l2 = epipolar_lines(F, x1, which=1)
    l1 = epipolar_lines(F, x2, which=2)
    assert np.abs((np.c_[x2, np.ones(50)] * l2).sum(axis=1)).max() < 1e-9  # x2 on F x1
    assert np.abs((np.c_[x1, np.ones(50)] * l1).sum(axis=1)).max() < 1e-9
    ref = cv2.computeCorrespondEpilines(x1.reshape(-1, 1, 2), 1, F).reshape(-1, 3)
    assert np.allclose(np.abs(l2), np.abs(ref), atol=1e-9)
    e1, e2 = epipoles(F)
    assert np.abs(F @ e1).max() < 1e-12 and np.abs(F.T @ e2).max() < 1e-12
    # e1 is the image of camera 2's centre in camera 1, e2 that of camera 1 in camera 2
    c2 = -R.T @ t
    p = K @ c2
    assert np.allclose(e1[:2] / e1[2], p[:2] / p[2], atol=1e-6)
    p = K @ t
    assert np.allclose(e2[:2] / e2[2], p[:2] / p[2], atol=1e-6)
    assert all(np.abs(line[:, 0] ** 2 + line[:, 1] ** 2 - 1).max() < 1e-12 for line in (l1, l2))


def test_triangulation_matches_opencv_and_the_truth():
    cv2 = pytest.importorskip("cv2")
    X, R, t, x1, x2 = _scene(100, seed=10)
    P1 = K @ np.c_[np.eye(3), np.zeros(3)]
    P2 = K @ np.c_[R, t]
    ours = triangulate(P1, P2, x1, x2)
    assert np.allclose(ours, X, rtol=1e-9)
    gen = np.random.default_rng(11)
    n1, n2 = x1 + gen.normal(0, 1, x1.shape), x2 + gen.normal(0, 1, x2.shape)
    ours = triangulate(P1, P2, n1, n2)
    ref = cv2.triangulatePoints(P1, P2, n1.T, n2.T)
    ref = (ref[:3] / ref[3]).T
    assert np.abs(ours - ref).max() <= 1e-6 * np.abs(ref).max()
    mid = triangulate(P1, P2, x1, x2, method="midpoint")
    assert np.allclose(mid, X, rtol=1e-9)


def test_bad_input():
    _, _, _, x1, x2 = _scene(20)
    with pytest.raises(DegenerateError, match="8 correspondences"):
        eight_point(x1[:7], x2[:7])
    line = np.c_[np.arange(10.0), 2 * np.arange(10.0) + 1]
    with pytest.raises(DegenerateError, match="collinear"):
        eight_point(line, line + 1)
    with pytest.raises(InputError, match="same shape"):
        eight_point(x1, x2[:10])
    with pytest.raises(InputError, match="NaN"):
        eight_point(np.where(np.arange(20)[:, None] == 3, np.nan, x1), x2)
    with pytest.raises(InputError, match="not a rotation"):
        essential_from_pose(np.ones((3, 3)), [1, 0, 0])
    with pytest.raises(InputError, match="which"):
        epipolar_lines(np.eye(3), x1, which=3)
    with pytest.raises(InputError, match="3x4"):
        triangulate(np.eye(3), np.eye(3), x1, x2)
    P = np.c_[np.eye(3), np.zeros(3)]
    with pytest.raises(DegenerateError, match="parallel"):
        triangulate(P, P, x1[:3], x1[:3], method="midpoint")
    with pytest.raises(DegenerateError, match="rank 2"):
        decompose_essential(np.zeros((3, 3)), x1, x2)
    with pytest.raises(InputError, match="method"):
        find_fundamental(x1, x2, method="lmeds")


# issue 25: hostile arguments (wrong shapes, complex/object arrays, singular camera
# matrices, negative seeds, coordinates near 1e300) raised NumPy's ValueError or
# LinAlgError; each is now an InputError naming the argument
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda x1, x2: skew([1.0, 2.0]), r"v must be 3 finite numbers, shape \(3,\)"),
        (lambda x1, x2: skew(np.nan), "v must be 3 finite numbers"),
        (lambda x1, x2: skew([1.0, np.nan, 0.0]), "v must be 3 finite numbers"),
        (lambda x1, x2: essential_from_pose(np.eye(3), np.ones((2, 3))), "t must be 3 finite"),
        (lambda x1, x2: essential_from_pose(np.eye(3), []), "t must be 3 finite"),
        (
            lambda x1, x2: fundamental_from_essential(np.eye(3), np.ones((3, 3)), K),
            "K1 is singular",
        ),
        (
            lambda x1, x2: fundamental_from_essential(np.zeros((3, 3)), K, K),
            "E is the zero matrix",
        ),
        (
            lambda x1, x2: decompose_essential(np.eye(3), x1, x2, np.full((3, 3), 1, object)),
            "K must hold real numbers",
        ),
        (lambda x1, x2: find_essential(x1, x2, np.zeros((3, 3))), "K is singular"),
        (lambda x1, x2: find_fundamental(x1, x2, rng=-1), "rng must be an int seed >= 0"),
        (lambda x1, x2: find_essential(x1, x2, K, rng=-5), "rng must be an int seed >= 0"),
        (lambda x1, x2: eight_point(x1 * 1e300, x2), "x1 has values up to"),
        (lambda x1, x2: sampson_distance(np.eye(3), x1, x2.astype(complex)), "x2 must hold"),
    ],
)
def test_issue25_hostile_arguments_are_input_errors(call, match):
    _, _, _, x1, x2 = _scene(20)
    with pytest.raises(InputError, match=match):
        call(x1, x2)


def test_issue25_scale_extremes_still_give_the_right_matrices():
    _, R, t, x1, x2 = _scene(20)
    E = essential_from_pose(R, t.reshape(3, 1))  # a (3, 1) column is still a vector
    F = fundamental_from_essential(E, K, K)
    # E and K near 1e300 (or 1e-300) are normalized first: the same unit F, not NaN
    np.testing.assert_allclose(fundamental_from_essential(1e300 * E, K, K), F, atol=1e-12)
    np.testing.assert_allclose(fundamental_from_essential(E, 1e-300 * K, K), F, atol=1e-12)
    d = sampson_distance(F, x1, x2)
    np.testing.assert_allclose(sampson_distance(1e300 * F, x1, x2), d, rtol=1e-9, atol=1e-12)
    assert d.max() < 1e-6


def test_issue25_find_essential_checks_threshold_and_focal_lengths():
    _, _, _, x1, x2 = _scene(20)
    with pytest.raises(InputError, match="threshold must be a real number"):
        find_essential(x1, x2, K, threshold=None)
    with pytest.raises(InputError, match="K must have positive focal lengths"):
        find_essential(x1, x2, np.diag([-700.0, 690.0, 1.0]))
