"""Stereo rectification: Bouguet (against cv2.stereoRectify and the row property) and
Hartley's uncalibrated version; the rotation-vector logarithm against cv2.Rodrigues."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.geometry.epipolar import essential_from_pose, fundamental_from_essential
from robopercept.geometry.rectification import (
    rectify_stereo,
    rectify_uncalibrated,
    undistort_rectify_map,
)
from robopercept.geometry.transforms import rotation_from_rotvec, rotvec_from_rotation

K1 = np.array([[700.0, 0, 318.0], [0, 705.0, 242.0], [0, 0, 1]])
K2 = np.array([[690.0, 0, 325.0], [0, 695.0, 236.0], [0, 0, 1]])
D1 = np.array([-0.2, 0.05, 0.001, -0.0005, 0.0])
D2 = np.array([-0.15, 0.02, 0.0, 0.001, 0.01])


@pytest.mark.parametrize(
    "rotvec",
    [
        [0.0, 0.0, 0.0],
        [0.3, -0.2, 0.1],
        [1e-9, 0, 0],
        [np.pi, 0, 0],
        [0, np.pi - 1e-9, 0],
        [2.0, 1.0, -0.5],
    ],
)
def test_rotvec_round_trip_and_opencv(rotvec):
    cv2 = pytest.importorskip("cv2")
    R = rotation_from_rotvec(np.array(rotvec, dtype=float))
    r = rotvec_from_rotation(R)
    assert np.allclose(rotation_from_rotvec(r), R, atol=1e-9)
    ref = cv2.Rodrigues(R)[0].ravel()
    assert np.allclose(rotation_from_rotvec(ref), rotation_from_rotvec(r), atol=1e-9)


@pytest.mark.parametrize(
    ("rotvec", "T", "dist"),
    [
        ([0.01, -0.03, 0.005], [-0.12, 0.004, 0.002], False),
        ([0.01, -0.03, 0.005], [-0.12, 0.004, 0.002], True),
        ([0.02, 0.01, -0.01], [0.003, -0.1, 0.01], True),  # a vertical rig
    ],
)
def test_equals_opencv(rotvec, T, dist):
    """R1, R2 to 1e-12; P1, P2, Q to 1e-4 (OpenCV centres the corners in float32)."""
    cv2 = pytest.importorskip("cv2")
    R = rotation_from_rotvec(np.array(rotvec))
    d1, d2 = (D1, D2) if dist else (np.zeros(5), np.zeros(5))
    ours = rectify_stereo(K1, d1, K2, d2, R, T, (640, 480))
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(K1, d1, K2, d2, (640, 480), R, np.array(T))
    assert np.allclose(ours.R1, R1, atol=1e-12) and np.allclose(ours.R2, R2, atol=1e-12)
    for a, b in ((ours.P1, P1), (ours.P2, P2), (ours.Q, Q)):
        assert np.allclose(a, b, atol=1e-4)
    assert ours.vertical == (abs(T[1]) > abs(T[0]))


def test_rectified_rows_agree_and_q_gives_depth():
    R = rotation_from_rotvec(np.array([0.01, -0.03, 0.005]))
    T = np.array([-0.12, 0.004, 0.002])
    rect = rectify_stereo(K1, None, K2, None, R, T, (640, 480))
    gen = np.random.default_rng(0)
    X1 = np.c_[gen.uniform(-1, 1, 50), gen.uniform(-1, 1, 50), gen.uniform(2, 6, 50)]
    X2 = X1 @ R.T + T
    # the same point in each rectified frame, projected by P1, P2
    Y1, Y2 = X1 @ rect.R1.T, X2 @ rect.R2.T
    p1 = np.c_[Y1, np.ones(50)] @ rect.P1.T
    p2 = np.c_[Y1, np.ones(50)] @ rect.P2.T
    u1, u2 = p1[:, :2] / p1[:, 2:], p2[:, :2] / p2[:, 2:]
    assert np.abs(u1[:, 1] - u2[:, 1]).max() < 1e-9  # same row
    q2 = Y2 @ rect.P2[:, :3].T
    assert np.allclose(q2[:, :2] / q2[:, 2:], u2, atol=1e-9)  # P2 is camera 2's view
    d = u1[:, 0] - u2[:, 0]
    h = np.c_[u1, d, np.ones(50)] @ rect.Q.T
    assert np.allclose(h[:, :3] / h[:, 3:], Y1, rtol=1e-9)


def test_uncalibrated_rectification_aligns_rows():
    R = rotation_from_rotvec(np.array([0.02, -0.1, 0.03]))
    T = np.array([-0.5, 0.05, 0.05])
    gen = np.random.default_rng(1)
    X = np.c_[gen.uniform(-2, 2, 80), gen.uniform(-1.5, 1.5, 80), gen.uniform(4, 9, 80)]
    x1 = X @ K1.T
    x1 = x1[:, :2] / x1[:, 2:]
    x2 = (X @ R.T + T) @ K2.T
    x2 = x2[:, :2] / x2[:, 2:]
    F = fundamental_from_essential(essential_from_pose(R, T), K1, K2)
    H1, H2 = rectify_uncalibrated(F, x1, x2, (640, 480))
    a = np.c_[x1, np.ones(80)] @ H1.T
    b = np.c_[x2, np.ones(80)] @ H2.T
    assert np.abs(a[:, 1] / a[:, 2] - b[:, 1] / b[:, 2]).max() < 1e-6
    # the second epipole goes to infinity along x
    u, _, _ = np.linalg.svd(F)
    e = H2 @ u[:, -1]
    assert abs(e[2]) < 1e-9 * np.hypot(e[0], e[1]) and abs(e[1]) < 1e-9 * abs(e[0])


def test_bad_input():
    R = np.eye(3)
    with pytest.raises(InputError, match="non-zero"):
        rectify_stereo(K1, None, K2, None, R, [0, 0, 0], (640, 480))
    with pytest.raises(InputError, match="coefficients"):
        rectify_stereo(K1, [1, 2, 3], K2, None, R, [0.1, 0, 0], (640, 480))
    # forward motion: the epipole lies in the image
    F = fundamental_from_essential(essential_from_pose(R, [0.01, 0.0, 1.0]), K1, K1)
    pts = np.array([[100.0, 100], [500, 120], [300, 400]])
    with pytest.raises(DegenerateError, match="inside the image"):
        rectify_uncalibrated(F, pts, pts + 1, (640, 480))


def test_undistort_rectify_map_equals_opencv():
    """The maps equal cv2.initUndistortRectifyMap (float32) to 1e-3 px, for plain
    undistortion and for a rectifying rotation with a new camera."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.geometry.rectification import undistort_rectify_map

    K = np.array([[520.0, 0, 315], [0, 515, 242], [0, 0, 1]])
    d = np.array([-0.25, 0.08, 0.001, -0.002, 0.01])
    R = rotation_from_rotvec([0.01, -0.02, 0.005])
    P = np.array([[500.0, 0, 300, 0], [0, 500, 240, 0], [0, 0, 1, 0]])
    for r, p in ((None, K), (R, P)):
        mx, my = undistort_rectify_map(K, d, r, p, (640, 480))
        rx, ry = cv2.initUndistortRectifyMap(
            K, d, np.eye(3) if r is None else r, p, (640, 480), cv2.CV_32FC1
        )
        assert mx.shape == (480, 640) and mx.dtype == np.float32
        assert np.abs(mx - rx).max() < 1e-3 and np.abs(my - ry).max() < 1e-3
    with pytest.raises(InputError):
        undistort_rectify_map(K, d, None, np.eye(2), (640, 480))


# issue 25: hostile sizes and matrices (an int for a size, NaN/inf sides, a singular or
# complex P) raised TypeError, IndexError, OverflowError or LinAlgError, and a huge size
# allocated without bound; each is now an InputError naming the argument
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: rectify_stereo(K1, D1, K2, D2, np.eye(3), [0.1, 0, 0], 7), "size must be"),
        (lambda: rectify_stereo(K1, D1, K2, D2, np.eye(3), [0.1, 0, 0], (1,)), "size must be"),
        (
            lambda: rectify_stereo(K1, D1, K2, D2, np.eye(3), [0.1, 0, 0], (np.nan, 48)),
            "size must be",
        ),
        (
            lambda: rectify_stereo(K1, D1, K2, D2, np.eye(3), [0.1, 0, 0], (64, None)),
            "size must be",
        ),
        (
            lambda: rectify_stereo(np.ones((3, 3)), D1, K2, D2, np.eye(3), [0.1, 0, 0], (64, 48)),
            "K1 is singular",
        ),
        (
            lambda: rectify_stereo(K1, D1, K2, D2, np.eye(3), ["a", 0, 0], (64, 48)),
            "T must hold real numbers",
        ),
        (lambda: rectify_uncalibrated(np.eye(3), np.ones((5, 2)), np.ones((5, 2)), ()), "size"),
        (
            lambda: rectify_uncalibrated(np.eye(3), np.ones((5, 2)), np.ones((5, 2)), (64, np.inf)),
            "size must be",
        ),
        (
            lambda: rectify_uncalibrated(
                np.zeros((3, 3)), np.ones((5, 2)), np.ones((5, 2)), (64, 48)
            ),
            "F must be a fundamental matrix \\(rank 2\\)",
        ),
        (
            lambda: undistort_rectify_map(K1, D1, None, np.eye(3, dtype=np.complex64), (64, 48)),
            "P must hold real numbers",
        ),
        (
            lambda: undistort_rectify_map(K1, D1, None, np.ones((3, 3)), (64, 48)),
            "singular",
        ),
        (
            lambda: undistort_rectify_map(K1, D1, None, K1, (65536, 65536)),
            "more than the 268435456 allowed",
        ),
        (lambda: undistort_rectify_map(K1, D1, None, K1, (2**40, 4)), r"in \[1, 65536\]"),
    ],
)
def test_issue25_hostile_arguments_are_input_errors(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_maps_in_blocks_of_rows_equal_the_whole(monkeypatch):
    """The maps are computed in blocks of rows (bounded intermediates): blocks of 7 rows
    of a 50 x 33 map give exactly the one-block result."""
    import robopercept.geometry.rectification as rect

    R = rotation_from_rotvec([0.01, -0.02, 0.005])
    P = np.array([[500.0, 0, 20, 0], [0, 500, 15, 0], [0, 0, 1, 0]])
    whole = rect.undistort_rectify_map(K1, D1, R, P, (50, 33.0))  # integral float sides
    monkeypatch.setattr(rect, "_BLOCK_PIXELS", 7 * 50)
    blocks = rect.undistort_rectify_map(K1, D1, R, P, (50, 33))
    for a, b in zip(whole, blocks, strict=True):
        assert a.shape == (33, 50)
        np.testing.assert_array_equal(a, b)
