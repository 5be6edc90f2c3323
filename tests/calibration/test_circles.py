"""Circle-grid detection: synthetic renders with known centres, the real Open3DV
eye-in-hand captures against cv2.findCirclesGrid (and the hand-eye result they give),
negatives and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.calibration import (
    board_pose,
    calibrate_hand_eye,
    circles_grid_points,
    find_circles_grid,
    read_xyz_rpy,
)
from robopercept.errors import InputError
from robopercept.geometry.transforms import rotation_from_rotvec
from tests.calibration._render import render_circles
from tests.conftest import data_path

K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
NO_DIST = np.zeros(5)


def _project(obj, rvec, tvec):
    X = obj @ rotation_from_rotvec(np.asarray(rvec, float)).T + np.asarray(tvec, float)
    x = X[:, :2] / X[:, 2:]
    return x @ K[:2, :2].T + K[:2, 2]


def test_grid_points_by_hand():
    """Asymmetric (2, 3), spacing 2: rows at y = 0, 1, 2, odd rows shifted by 1."""
    want = [[0, 0, 0], [2, 0, 0], [1, 1, 0], [3, 1, 0], [0, 2, 0], [2, 2, 0]]
    assert np.array_equal(circles_grid_points((2, 3), 2.0), want)
    sym = circles_grid_points((3, 2), 0.5, asymmetric=False)
    assert np.array_equal(sym[:, :2], [[0, 0], [0.5, 0], [1, 0], [0, 0.5], [0.5, 0.5], [1, 0.5]])


@pytest.mark.parametrize(
    ("rvec", "tvec"),
    [([0.15, -0.2, 0.1], [-0.05, -0.07, 0.45]), ([-0.25, 0.1, -0.4], [-0.06, -0.06, 0.5])],
)
def test_asymmetric_render_centres_and_order(rvec, tvec):
    """Dark circles under perspective: every centre within 0.1 px of the projected one
    (a disc's centroid moves off the projected centre by only r^2-order terms of the
    tilt, hundredths of a pixel here) and in the order of circles_grid_points."""
    img = render_circles(K, NO_DIST, rvec, tvec)
    det = find_circles_grid(img, (4, 11))
    assert det.found, det.reason
    truth = _project(circles_grid_points((4, 11), 0.03), rvec, tvec)
    err = np.linalg.norm(det.centers - truth, axis=1)
    assert err.max() < 0.1


def test_asymmetric_half_turn_keeps_the_board_order():
    """An asymmetric grid with an odd number of rows has no symmetry: turned upside down
    in the image, centre 0 is still the board's origin (now near the bottom)."""
    rvec, tvec = [0.1, 0.05, np.pi], [0.05, 0.08, 0.45]
    det = find_circles_grid(render_circles(K, NO_DIST, rvec, tvec), (4, 11))
    assert det.found, det.reason
    truth = _project(circles_grid_points((4, 11), 0.03), rvec, tvec)
    assert np.linalg.norm(det.centers - truth, axis=1).max() < 0.1
    assert det.centers[0, 1] > det.centers[-1, 1]


def test_symmetric_light_circles():
    """Light circles on a dark board, symmetric 5 x 4 grid: found with blob_color
    "light" (first centre the higher one), not with the default "dark"."""
    rvec, tvec = [0.1, 0.2, 0.05], [-0.06, -0.05, 0.5]
    img = render_circles(
        K, NO_DIST, rvec, tvec, (5, 4), 0.03, asymmetric=False, radius=0.008, dark=False
    )
    det = find_circles_grid(img, (5, 4), asymmetric=False, blob_color="light")
    assert det.found, det.reason
    truth = _project(circles_grid_points((5, 4), 0.03, asymmetric=False), rvec, tvec)
    assert np.linalg.norm(det.centers - truth, axis=1).max() < 0.1
    miss = find_circles_grid(img, (5, 4), asymmetric=False)
    assert not miss.found and "circle" in miss.reason


def _stamp_discs(img, centres, radius=10.0, value=25):
    """Dark discs (stray blobs: screws, holes) painted at image points."""
    out = img.copy()
    yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
    for x, y in centres:
        out[np.hypot(xx - x, yy - y) < radius] = value
    return out


def test_stray_blobs_on_the_lattice_extension():
    """Two blobs above the first row and one left of row 5, each where the grid's
    lattice would continue (the Open3DV eye-to-hand case: the grown lattice holds 47
    circles, and the detector gave up before it searched for the 4 x 11 window): the
    grid is found, its centres within 0.1 px of the projected ones and in order."""
    rvec, tvec = [0.15, -0.2, 0.1], [-0.05, -0.07, 0.45]
    strays = _project(np.array([[0.015, -0.015, 0], [0.075, -0.015, 0], [-0.015, 0.075, 0]]),
                      rvec, tvec)  # fmt: skip
    img = _stamp_discs(render_circles(K, NO_DIST, rvec, tvec), strays)
    det = find_circles_grid(img, (4, 11))
    assert det.found, det.reason
    truth = _project(circles_grid_points((4, 11), 0.03), rvec, tvec)
    assert np.linalg.norm(det.centers - truth, axis=1).max() < 0.1
    # the three strays are circle-like blobs to the detector (44 + 3), so the grid was
    # found among more candidates than it has circles
    assert "only 47 circle-like blobs" in find_circles_grid(img, (4, 12)).reason


def test_wrong_size_and_blank_are_reported():
    """A 4 x 10 (or 3 x 11) pattern fits inside the rendered 4 x 11 grid, but which
    window would be a guess: not found, and the reason says the grid is larger."""
    img = render_circles(K, NO_DIST, [0.1, -0.1, 0.0], [-0.05, -0.07, 0.45])
    det = find_circles_grid(img, (4, 10))
    assert not det.found and "4 x 10" in det.reason and len(det.centers) > 0
    assert "holds a 4 x 11 grid" in det.reason and "more circles than" in det.reason
    det = find_circles_grid(img, (3, 11))
    assert not det.found and "holds a 4 x 11 grid" in det.reason
    blank = find_circles_grid(np.full((120, 160), 200, np.uint8), (4, 11))
    assert not blank.found and "are the circles dark?" in blank.reason


def test_bad_input():
    img = np.zeros((50, 60), np.uint8)
    with pytest.raises(InputError, match="blob_color"):
        find_circles_grid(img, (4, 11), blob_color="grey")
    with pytest.raises(InputError):
        find_circles_grid(img, (1, 11))
    with pytest.raises(InputError, match="min_area"):
        find_circles_grid(img, (4, 11), min_area=100, max_area=10)
    with pytest.raises(InputError, match="spacing"):
        circles_grid_points((4, 11), 0.0)


def test_noise_is_not_a_circle_grid():
    rng = np.random.default_rng(0)
    noise = rng.integers(0, 256, (240, 320)).astype(np.uint8)
    assert not find_circles_grid(noise, (4, 11)).found


@pytest.mark.realdata
def test_chessboard_photo_is_not_a_circle_grid():
    from robopercept.imaging import read_image

    path = data_path("calibration", "opencv_chessboard_stereo", "left01.jpg")
    img = read_image(path, mode="gray")
    for color in ("dark", "light"):
        assert not find_circles_grid(img, (4, 11), blob_color=color).found


# --------------------------------------------------------------------------- real data

EYE_IN_HAND = ("calibration", "handeye_open3dv", "eye_in_hand")


@pytest.fixture(scope="module")
def open3dv():
    """The eight eye-in-hand captures (white circles, 7 x 11 asymmetric, 20 mm), the
    camera from param.txt and the robot poses (Rx Ry Rz deg, X Y Z mm)."""
    from robopercept.imaging import read_image

    folder = data_path(*EYE_IN_HAND)
    p = np.loadtxt(folder / "param.txt")
    images = [read_image(folder / f"pos{k}.png", mode="gray") for k in range(8)]
    robot = [read_xyz_rpy(folder / f"pos{k}.txt", "rpy_xyz") for k in range(8)]
    dets = [find_circles_grid(g, (7, 11), blob_color="light") for g in images]
    return images, dets, robot, p[:9].reshape(3, 3), p[9:14]


@pytest.mark.realdata
def test_open3dv_captures_match_opencv(open3dv):
    """All eight grids found, in cv2.findCirclesGrid's order (on the negative image: its
    default detector wants dark circles); centres within 0.05 px median and 0.3 px max
    of OpenCV's (both average blob centroids over the same thresholds; OpenCV's come
    from contour moments, ours from pixel moments)."""
    cv2 = pytest.importorskip("cv2")
    images, dets, *_ = open3dv
    meds = []
    for g, det in zip(images, dets, strict=True):
        assert det.found, det.reason
        ok, c = cv2.findCirclesGrid(255 - g, (7, 11), flags=cv2.CALIB_CB_ASYMMETRIC_GRID)
        assert ok
        err = np.linalg.norm(det.centers - c.reshape(-1, 2), axis=1)
        assert err.max() < 0.3
        meds.append(np.median(err))
    assert np.median(meds) < 0.05


@pytest.mark.realdata
def test_open3dv_hand_eye(open3dv):
    """Eye in hand from our centres: AX = XB residuals below 0.1 deg and 1.5 mm RMS over
    the 28 station pairs, and X within 0.1 deg and 3 mm of cv2.calibrateHandEye (Park)
    on OpenCV's own centres (the two differ by the centres' hundredths of a pixel)."""
    cv2 = pytest.importorskip("cv2")
    images, dets, robot, Kc, dist = open3dv
    obj = circles_grid_points((7, 11), 20.0)
    targets = [board_pose(obj, d.centers, Kc, dist) for d in dets]
    res = calibrate_hand_eye(robot, targets, "eye_in_hand", "park")
    assert len(res.rotation_residuals) == 28
    assert res.rotation_rms < 0.1 and res.translation_rms < 1.5
    ref_targets = []
    for g in images:
        _, c = cv2.findCirclesGrid(255 - g, (7, 11), flags=cv2.CALIB_CB_ASYMMETRIC_GRID)
        ref_targets.append(board_pose(obj, c.reshape(-1, 2), Kc, dist))
    R, t = cv2.calibrateHandEye(
        [T[:3, :3] for T in robot], [T[:3, 3] for T in robot],
        [T[:3, :3] for T in ref_targets], [T[:3, 3] for T in ref_targets],
        method=cv2.CALIB_HAND_EYE_PARK,
    )  # fmt: skip
    cos = np.clip((np.trace(R.T @ res.X[:3, :3]) - 1) / 2, -1, 1)
    assert np.degrees(np.arccos(cos)) < 0.1
    assert np.linalg.norm(t.ravel() - res.X[:3, 3]) < 3.0


EYE_TO_HAND = ("calibration", "handeye_open3dv", "eye_to_hand")


@pytest.mark.realdata
def test_open3dv_eye_to_hand_captures_match_opencv():
    """The five eye-to-hand captures (1022 x 768, 7 x 11 light circles, stray bright
    screws on the robot flange and a label on the lattice's extension in pos0-2): all
    five found, as cv2.findCirclesGrid finds them, in its order; centres 0.06-0.07 px
    apart on average (we measure) and at most 0.23 px, so the bounds are 0.1 px mean and
    0.3 px max (the same blob-centroid averaging; contour against pixel moments)."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.imaging import read_image

    folder = data_path(*EYE_TO_HAND)
    for k in range(5):
        g = read_image(folder / f"pos{k}.png", mode="gray")
        det = find_circles_grid(g, (7, 11), blob_color="light")
        assert det.found, (k, det.reason)
        ok, c = cv2.findCirclesGrid(255 - g, (7, 11), flags=cv2.CALIB_CB_ASYMMETRIC_GRID)
        assert ok
        err = np.linalg.norm(det.centers - c.reshape(-1, 2), axis=1)
        assert err.mean() < 0.1 and err.max() < 0.3, (k, err.mean(), err.max())


# issue 25: pattern_size (4, 2**40) allocated 32 TiB and (inf, inf) raised
# OverflowError; a complex min_area raised TypeError; each is now an InputError
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: circles_grid_points((4, 2**40)), "more than 1000000"),
        (lambda: circles_grid_points((4, -np.inf)), "two whole numbers"),
        (lambda: circles_grid_points((4, 3), None), "spacing must be a real number"),
        (lambda: circles_grid_points((4, 3), asymmetric="no"), "asymmetric must be True"),
        (
            lambda: find_circles_grid(np.zeros((16, 16), np.uint8), (np.inf, np.inf)),
            "two whole numbers",
        ),
        (
            lambda: find_circles_grid(np.zeros((16, 16), np.uint8), (4, 3), min_area=1 + 1j),
            "min_area must be a real number",
        ),
        (
            lambda: find_circles_grid(np.zeros((16, 16), np.uint8), (4, 3), blob_color=None),
            "blob_color must be one of",
        ),
        (
            lambda: find_circles_grid(np.zeros((16, 16), np.uint8), (4, 3), max_seeds=2**0.5),
            "max_seeds must be an integer",
        ),
    ],
)
def test_issue25_hostile_arguments_are_input_errors(call, match):
    with pytest.raises(InputError, match=match):
        call()
