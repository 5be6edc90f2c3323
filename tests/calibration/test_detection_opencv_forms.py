"""Board detection in OpenCV's call shapes (issue 48): ``ok, corners =
find_chessboard_corners(g, (9, 6))`` and ``ok, centers = find_circles_grid(...)`` in the
order and types of ``cv2.findChessboardCorners`` / ``cv2.findCirclesGrid`` ((N, 1, 2)
float32, or None when not found), with the attributes kept; the unpacked corners go
straight into our functions and OpenCV's."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.calibration import (
    ChessboardDetection,
    CircleGridDetection,
    board_pose,
    chessboard_points,
    circles_grid_points,
    find_chessboard_corners,
    find_circles_grid,
)
from robopercept.estimation import find_homography
from tests.conftest import data_path

CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)


def _gray(*parts):
    return cv2.imread(str(data_path(*parts)), cv2.IMREAD_GRAYSCALE)


def _board(w=9, h=6, square=24, margin=24):
    """A flat, fronto-parallel chessboard image: inner corner (i, j) at
    (margin + square (j + 1) - 0.5, margin + square (i + 1) - 0.5) in pixel centres."""
    img = np.full(((h + 1) * square + 2 * margin, (w + 1) * square + 2 * margin), 230, np.uint8)
    for i in range(h + 1):
        for j in range(w + 1):
            if (i + j) % 2 == 0:
                y, x = margin + i * square, margin + j * square
                img[y : y + square, x : x + square] = 25
    return img


def test_unpacking_on_a_drawn_board_and_not_found():
    """A drawn board: ``ok`` True and (54, 1, 2) float32 corners equal to ``.corners``
    within float32 rounding, within 0.05 px of the drawn corners and in cv2's order
    (cv2.findChessboardCorners + cornerSubPix on the same image: 0.05 px); a blank
    image: ``(False, None)`` as cv2 gives, with the attributes still telling why."""
    g = _board()
    det = find_chessboard_corners(g, (9, 6))
    ok, corners = det
    assert isinstance(det, ChessboardDetection) and ok is True and det.found
    assert corners.shape == (54, 1, 2) and corners.dtype == np.float32
    np.testing.assert_allclose(corners[:, 0], det.corners, atol=1e-4)
    assert det.corners.dtype == np.float64 and det.pattern_size == (9, 6)
    okc, ref = cv2.findChessboardCorners(g, (9, 6))
    ref = cv2.cornerSubPix(g, ref, (5, 5), (-1, -1), CRIT)
    assert okc and ref.shape == corners.shape and ref.dtype == corners.dtype
    assert np.abs(corners - ref).max() < 0.05
    blank = np.full((120, 160), 128, np.uint8)
    nothing = find_chessboard_corners(blank, (4, 3))
    assert tuple(nothing) == (False, None) == cv2.findChessboardCorners(blank, (4, 3))
    assert nothing.reason and nothing.corners.shape[1] == 2  # attributes kept


@pytest.mark.realdata
def test_chessboard_unpacks_like_cv2_on_opencv_left01():
    """OpenCV's left01.jpg: our unpacked corners within 0.1 px of cv2.findChessboardCorners
    + cv2.cornerSubPix (11 x 11) in the same (54, 1, 2) float32 layout; and they go
    unchanged into cv2.calibrateCamera's and cv2.solvePnP's image points, our board_pose
    and find_homography (the same pose as from ``.corners`` within 1e-4 m / 1e-4)."""
    g = _gray("calibration", "opencv_chessboard_stereo", "left01.jpg")
    det = find_chessboard_corners(g, (9, 6))
    ok, corners = det
    okc, ref = cv2.findChessboardCorners(g, (9, 6))
    ref = cv2.cornerSubPix(g, ref, (11, 11), (-1, -1), CRIT)
    assert ok and okc and corners.shape == ref.shape and corners.dtype == ref.dtype
    assert np.abs(corners - ref).max() < 0.1
    obj = chessboard_points((9, 6), 0.025)
    K = np.array([[535.0, 0, 342], [0, 535, 235], [0, 0, 1]])
    T = board_pose(obj, corners, K)
    np.testing.assert_allclose(T, board_pose(obj, det.corners, K), atol=1e-4)
    okp, _, tvec = cv2.solvePnP(obj.astype(np.float32), corners, K, None)
    assert okp and np.abs(tvec.ravel() - T[:3, 3]).max() < 2e-3
    _, mask = find_homography(obj[:, :2], corners)
    assert mask.all()


@pytest.mark.realdata
def test_circles_grid_unpacks_like_cv2_on_open3dv():
    """An Open3DV eye-in-hand capture (light circles, 7 x 11 asymmetric): ``ok, centers``
    (77, 1, 2) float32, within 0.3 px of cv2.findCirclesGrid's on the negative image
    (its default detector wants dark circles; the existing parity test explains the
    0.3 px), equal to ``.centers`` within float32 rounding; the unpacked centres give
    the board pose that ``.centers`` give. A blank image: ``(False, None)`` as cv2."""
    g = _gray("calibration", "handeye_open3dv", "eye_in_hand", "pos0.png")
    det = find_circles_grid(g, (7, 11), blob_color="light")
    ok, centers = det
    assert isinstance(det, CircleGridDetection) and ok is True and det.asymmetric
    okc, ref = cv2.findCirclesGrid(255 - g, (7, 11), flags=cv2.CALIB_CB_ASYMMETRIC_GRID)
    assert okc and centers.shape == ref.shape == (77, 1, 2) and centers.dtype == ref.dtype
    assert np.abs(centers - ref).max() < 0.3
    np.testing.assert_allclose(centers[:, 0], det.centers, atol=1e-4)
    obj = circles_grid_points((7, 11), 20.0)
    K = np.array([[2000.0, 0, 640], [0, 2000, 512], [0, 0, 1]])
    np.testing.assert_allclose(
        board_pose(obj, centers, K), board_pose(obj, det.centers, K), atol=1e-3
    )
    blank = np.full((120, 160), 128, np.uint8)
    assert tuple(find_circles_grid(blank, (4, 11))) == (False, None)
    assert cv2.findCirclesGrid(blank, (4, 11), flags=cv2.CALIB_CB_ASYMMETRIC_GRID) == (False, None)
