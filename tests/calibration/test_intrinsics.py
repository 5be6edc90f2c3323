"""Zhang calibration, stereo calibration and undistortion: against cv2.calibrateCamera /
stereoCalibrate on the OpenCV sample set, against known cameras on synthetic views and
renders, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.calibration import (
    calibrate_camera,
    chessboard_points,
    find_chessboard_corners,
    load_calibration,
    reprojection_errors,
    save_calibration,
    stereo_calibrate,
    undistort,
)
from robopercept.calibration.intrinsics import _project
from robopercept.errors import DegenerateError, FileFormatError, InputError
from tests.calibration._render import render_board

K_TRUE = np.array([[612.0, 0, 318.5], [0, 608.0, 243.0], [0, 0, 1]])
D_TRUE = np.array([-0.21, 0.08, 0.0012, -0.0007, -0.01])


def _poses(n, rng):
    rv = rng.normal(0, 0.35, (n, 3))
    tv = np.c_[rng.uniform(-0.15, 0.0, n), rng.uniform(-0.1, 0.0, n), rng.uniform(0.5, 0.8, n)]
    return rv, tv


def _views(obj, rv, tv):
    """Exact projections of the board in each pose (the true camera)."""
    return [
        _project(obj, np.zeros(len(obj), int), rv[i : i + 1], tv[i : i + 1], K_TRUE, D_TRUE)
        for i in range(len(rv))
    ]


def test_exact_views_recover_the_camera(rng):
    """Noise-free projections of 10 board poses: K and the distortion to 1e-6."""
    obj = chessboard_points((9, 6), 0.03)
    rv, tv = _poses(10, rng)
    img = _views(obj, rv, tv)
    res = calibrate_camera(obj, img, (640, 480))
    np.testing.assert_allclose(res.K, K_TRUE, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(res.dist, D_TRUE, atol=1e-6)
    np.testing.assert_allclose(res.rvecs, rv, atol=1e-6)
    assert res.rms < 1e-6 and res.per_view_errors.shape == (10,)
    rms, per = reprojection_errors(obj, img, res.K, res.dist, res.rvecs, res.tvecs)
    assert rms == pytest.approx(res.rms, abs=1e-9) and per == pytest.approx(
        res.per_view_errors, abs=1e-9
    )


def test_synthetic_renders_full_pipeline(rng):
    """Acceptance: rendered photographs of a board (known K and distortion) through our
    detector and calibration: fx, fy, cx, cy within 0.5 %."""
    rv, tv = _poses(8, rng)
    obj = chessboard_points((9, 6), 0.03)
    corners = []
    for i in range(8):
        det = find_chessboard_corners(render_board(K_TRUE, D_TRUE, rv[i], tv[i]), (9, 6))
        assert det.found, det.reason
        corners.append(det.corners)
    res = calibrate_camera(obj, corners, (640, 480))
    got = res.K[[0, 1, 0, 1], [0, 1, 2, 2]]
    want = K_TRUE[[0, 1, 0, 1], [0, 1, 2, 2]]
    assert np.all(np.abs(got / want - 1) < 0.005), got
    assert res.rms < 0.1


@pytest.mark.realdata
def test_parity_with_opencv_calibrate_camera(opencv_corners):
    """Acceptance: left01..14 with our detector: RMS at most 1.02x cv2.calibrateCamera's
    (0.408 px on cv2's own corners), fx, fy, cx, cy within 0.5 %."""
    cv2 = pytest.importorskip("cv2")
    ref, images = opencv_corners
    obj = chessboard_points((9, 6), 0.025)
    names = sorted(n for n in images if n.startswith("left"))
    ours = [find_chessboard_corners(images[n], (9, 6)) for n in names]
    corners = [d.corners for d in ours if d.found]
    res = calibrate_camera(obj, corners, (640, 480))
    rms, K, dist, _, _ = cv2.calibrateCamera(
        [obj.astype(np.float32)] * 13,
        [ref[n].astype(np.float32) for n in names],
        (640, 480),
        None,
        None,
    )
    assert res.rms <= 1.02 * rms
    got = res.K[[0, 1, 0, 1], [0, 1, 2, 2]]
    want = K[[0, 1, 0, 1], [0, 1, 2, 2]]
    assert np.all(np.abs(got / want - 1) < 0.005), (got, want)
    # the solver alone, on OpenCV's corners: the same optimum
    same = calibrate_camera(obj, [ref[n] for n in names], (640, 480))
    assert same.rms == pytest.approx(rms, rel=1e-4)
    np.testing.assert_allclose(same.K, K, rtol=1e-5)
    np.testing.assert_allclose(same.dist, dist.ravel(), atol=1e-4)


@pytest.mark.realdata
def test_stereo_calibrate_matches_opencv(opencv_corners):
    cv2 = pytest.importorskip("cv2")
    ref, _ = opencv_corners
    obj = chessboard_points((9, 6), 0.025)
    L = [ref[f"left{i:02d}"] for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]
    R = [ref[f"right{i:02d}"] for i in (1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14)]
    o32 = [obj.astype(np.float32)] * 13
    f32 = lambda a: [x.astype(np.float32) for x in a]  # noqa: E731
    _, K1, d1, _, _ = cv2.calibrateCamera(o32, f32(L), (640, 480), None, None)
    _, K2, d2, _, _ = cv2.calibrateCamera(o32, f32(R), (640, 480), None, None)
    rms, *_, Rc, Tc, _, _ = cv2.stereoCalibrate(
        o32, f32(L), f32(R), K1, d1, K2, d2, (640, 480), flags=cv2.CALIB_FIX_INTRINSIC
    )
    st = stereo_calibrate(obj, L, R, (640, 480), K1=K1, dist1=d1, K2=K2, dist2=d2)
    assert st.rms == pytest.approx(rms, rel=1e-4)
    np.testing.assert_allclose(st.R, Rc, atol=1e-6)
    np.testing.assert_allclose(st.T, Tc.ravel(), atol=1e-6)
    x1, x2 = L[0], R[0]  # the fundamental matrix holds for the (distorted) corners roughly
    d = np.abs(np.einsum("ni,ij,nj->n", np.c_[x2, np.ones(54)], st.F, np.c_[x1, np.ones(54)]))
    assert st.F.shape == (3, 3) and np.isfinite(d).all()


def test_undistort_matches_opencv():
    cv2 = pytest.importorskip("cv2")
    K = np.array([[300.0, 0, 80], [0, 300, 60], [0, 0, 1]])
    d = np.array([-0.3, 0.1, 0.001, 0.002, 0.0])
    img = (np.indices((120, 160)).sum(axis=0) * 7 % 256).astype(np.uint8)
    ours = undistort(img, K, d)
    ref = cv2.undistort(img, K, d)
    inner = (slice(5, -5), slice(5, -5))
    # OpenCV samples at 1/32 px in fixed point: a few grey levels on this sharp pattern
    assert np.mean(np.abs(ours[inner].astype(int) - ref[inner])) < 2.0


def test_save_and_load_round_trip(tmp_path, rng):
    obj = chessboard_points((5, 4), 0.03)
    rv, tv = _poses(4, rng)
    img = _views(obj, rv, tv)
    res = calibrate_camera(obj, img, (640, 480))
    save_calibration(tmp_path / "cam.json", res)
    back = load_calibration(tmp_path / "cam.json")
    np.testing.assert_allclose(back["K"], res.K)
    np.testing.assert_allclose(back["dist"], res.dist)
    assert back["image_size"] == (640, 480)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(FileFormatError, match=r"bad\.json"):
        load_calibration(tmp_path / "bad.json")
    (tmp_path / "short.json").write_text('{"K": [[1, 0], [0, 1]], "dist": [0, 0, 0, 0]}')
    with pytest.raises(FileFormatError, match="'K'"):
        load_calibration(tmp_path / "short.json")


def test_bad_input(rng):
    obj = chessboard_points((9, 6), 0.03)
    rv, tv = _poses(3, rng)
    img = _views(obj, rv, tv)
    with pytest.raises(InputError, match="at least 3 views"):
        calibrate_camera(obj, img[:2], (640, 480))
    with pytest.raises(InputError, match="object_points has 2 views"):
        calibrate_camera([obj, obj], img, (640, 480))
    with pytest.raises(InputError, match="54 object points but 53"):
        calibrate_camera(obj, [img[0][:53], img[1], img[2]], (640, 480))
    bent = obj.copy()
    bent[:, 2] = 0.01
    with pytest.raises(InputError, match="z = 0"):
        calibrate_camera(bent, img, (640, 480))
    # the same view three times: K is not determined
    with pytest.raises(DegenerateError, match="tilt the board"):
        calibrate_camera(obj, [img[0]] * 3, (640, 480))
    # issue 25: an infinite or fractional image size raised OverflowError or was cut
    for size in ((float("inf"), 480), (640, float("nan")), (640.5, 480), (True, 480), "ab"):
        with pytest.raises(InputError, match="image_size must be"):
            calibrate_camera(obj, img, size)


def test_rectify_pair_without_distortion_is_the_bouguet_remap():
    """An identity calibration (same camera, pure x baseline) rectifies to itself up to
    the remap's interpolation; a mono file or different sizes are refused."""
    from robopercept.calibration import rectify_pair

    K = np.array([[300.0, 0, 31.5], [0, 300.0, 23.5], [0, 0, 1]])
    cal = {"K1": K, "K2": K, "R": np.eye(3), "T": np.array([-0.1, 0.0, 0.0])}
    rng = np.random.default_rng(0)
    left = rng.integers(0, 255, (48, 64), dtype=np.uint8)
    right = rng.integers(0, 255, (48, 64), dtype=np.uint8)
    rl, rr, Q = rectify_pair(left, right, cal)
    assert rl.shape == left.shape and rl.dtype == np.uint8 and Q.shape == (4, 4)
    np.testing.assert_array_equal(rl[2:-2, 2:-2], left[2:-2, 2:-2])
    np.testing.assert_array_equal(rr[2:-2, 2:-2], right[2:-2, 2:-2])
    assert Q[3, 2] == pytest.approx(10.0)  # 1 / baseline
    with pytest.raises(InputError, match="not a stereo calibration"):
        rectify_pair(left, right, {"K": K, "dist": np.zeros(5)})
    with pytest.raises(InputError, match="differ in size"):
        rectify_pair(left, right[:, :-1], cal)


# issue 25: hostile arguments (a string for the views, mis-shaped rvecs/tvecs/K, an
# oversized max_iterations, a singular or complex camera matrix, an int for the
# calibration or the result, paths that are empty, bytes or folders) raised ValueError,
# IndexError, OverflowError, LinAlgError, AttributeError or OSError; each is now an
# InputError (or FileFormatError for a file that cannot be written)
def _exact(rng, n=3):
    obj = chessboard_points((5, 4), 0.03)
    rv, tv = _poses(n, rng)
    return obj, rv, tv, _views(obj, rv, tv)


def test_issue25_hostile_views_and_camera_matrices(rng):
    from robopercept.calibration import board_pose

    obj, rv, tv, img = _exact(rng)
    cases = [
        (lambda: calibrate_camera("abc", img, (640, 480)), "object_points must be a list"),
        (lambda: calibrate_camera(obj, img, (640, 480), max_iterations=2**63), "max_iterations"),
        (lambda: calibrate_camera(obj, img, (640, 480), tangential=None), "tangential must be"),
        (lambda: calibrate_camera(obj, [p * 1e300 for p in img], (640, 480)), "values up to"),
        (lambda: calibrate_camera(obj, [[["a", "b"]]] * 3, (640, 480)), "must hold real"),
        (lambda: reprojection_errors(obj, img, K_TRUE, D_TRUE, rv[:2], tv), r"rvecs must be 3 "),
        (lambda: reprojection_errors(obj, img, K_TRUE, D_TRUE, rv, 1.0), r"tvecs must be 3 "),
        (lambda: reprojection_errors(obj, img, np.stack([K_TRUE] * 2), D_TRUE, rv, tv), "K must"),
        (lambda: board_pose(obj, img[0], np.ones((3, 3))), "K must be a camera matrix"),
        (lambda: board_pose(obj, img[0], np.full((3, 3), np.inf)), "K must be a finite 3x3"),
        (lambda: board_pose(obj, img[0] * 1e300, K_TRUE), "image_points.* values up to"),
        (lambda: stereo_calibrate(obj, img, img, (640, 480), K1=np.ones((2, 3))), "K1 must"),
        (lambda: stereo_calibrate("abc", img, img, (640, 480)), "object_points must be a list"),
        (lambda: undistort(np.zeros((8, 8)), np.eye(3, dtype=np.complex64), D_TRUE), "K must"),
        (
            lambda: undistort(np.zeros((8, 8)), K_TRUE, D_TRUE, np.full((3, 3), 1, object)),
            "new_K must",
        ),
    ]
    for call, match in cases:
        with pytest.raises(InputError, match=match):
            call()
    # the valid call still works
    rms, per = reprojection_errors(obj, img, K_TRUE, D_TRUE, rv[:, :, None], tv)
    assert rms < 1e-9 and per.shape == (3,)


def test_issue25_rectify_pair_and_save_calibration_check_their_arguments(tmp_path):
    from robopercept.calibration import rectify_pair

    img = np.zeros((8, 8), np.uint8)
    for bad in (3, None, [], np.eye(3)):
        with pytest.raises(InputError, match="calibration must be a dict"):
            rectify_pair(img, img, bad)
    with pytest.raises(InputError, match="left must"):
        rectify_pair([[1, 2]], img, {"K1": 0, "K2": 0, "R": 0, "T": 0})
    for bad in (3, None, {}, np.eye(3)):
        with pytest.raises(InputError, match="result must be a CalibrationResult"):
            save_calibration(tmp_path / "cam.json", bad)


def test_issue25_save_calibration_paths(rng, tmp_path):
    obj, _, _, img = _exact(rng)
    res = calibrate_camera(obj, img, (640, 480))
    for bad, match in (
        ("", "must not be empty"),
        (3, "path must be a file"),
        (tmp_path, "is a folder"),
    ):
        with pytest.raises(InputError, match=match):
            save_calibration(bad, res)
    with pytest.raises(InputError, match="file name too long"):
        save_calibration(str(tmp_path / ("n" * 300)), res)
    with pytest.raises(FileFormatError, match="cannot write the calibration"):
        save_calibration(tmp_path / "missing" / "cam.json", res)
    save_calibration(bytes(tmp_path / "cam.json"), res)  # bytes paths are paths
    np.testing.assert_allclose(load_calibration(tmp_path / "cam.json")["K"], res.K)


def test_issue25_levenberg_marquardt_budgets_are_bounded(rng, monkeypatch):
    # absurd distortion (coefficients in the hundreds) made stereo_calibrate spend
    # scipy's default budget, minutes of Jacobians; every LM run now has a bound of a
    # few hundred steps (valid views converge in under ten), and the call returns
    import scipy.optimize

    budgets = []
    real = scipy.optimize.least_squares

    def spy(*args, **kwargs):
        budgets.append(kwargs.get("max_nfev"))
        return real(*args, **kwargs)

    monkeypatch.setattr(scipy.optimize, "least_squares", spy)
    obj, _, _, img = _exact(rng, 4)
    d = np.array([209.7, -596.7, 1126.6, 362.5, -1500.2])
    res = stereo_calibrate(obj, img, img, (640, 480), K1=K_TRUE, dist1=d, K2=K_TRUE, dist2=D_TRUE)
    assert np.isfinite(res.rms) and budgets and all(b is not None and b <= 200 for b in budgets)
