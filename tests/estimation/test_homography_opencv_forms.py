"""find_homography in OpenCV's call shapes (issue 48): ``H, mask = find_homography(...)``
in ``cv2.findHomography``'s order and types, OpenCV's ``(N, 1, 2)`` point arrays
(``cv2.goodFeaturesToTrack``, ``cv2.findChessboardCorners`` output) taken wherever
``(N, 2)`` is, with the attributes kept."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from robopercept._checks import check_points, squeeze_point_axis
from robopercept.calibration import chessboard_points
from robopercept.errors import InputError
from robopercept.estimation import HomographyFit, LineModel, find_homography, fit_line, ransac
from robopercept.imaging import transform_points
from tests.conftest import data_path

H_TRUE = np.array([[1.05, 0.04, 12.0], [-0.03, 0.97, -7.0], [1e-4, -5e-5, 1.0]])


def _corner_error(h1, h2, w=640, h=480):
    c = np.array([[0, 0], [w, 0], [w, h], [0, h]], float)
    return np.linalg.norm(transform_points(h1, c) - transform_points(h2, c), axis=1).max()


def _textured(seed=0, shape=(480, 640)):
    """A blurred random texture: plenty of Shi-Tomasi corners."""
    g = np.random.default_rng(seed).uniform(0, 255, (shape[0] // 8, shape[1] // 8))
    g = cv2.resize(g.astype(np.float32), shape[::-1], interpolation=cv2.INTER_CUBIC)
    return np.clip(cv2.GaussianBlur(g, (0, 0), 1.5), 0, 255).astype(np.uint8)


def test_unpacks_like_cv2_find_homography_and_keeps_attributes():
    """``H, mask`` as cv2.findHomography(src, dst, cv2.RANSAC, 3.0) gives them: H
    (3, 3) float64 equal to ``.H``; mask (N, 1) uint8 of 0/1 equal to ``.inliers``; the
    gross outliers are 0 in both masks and the two H agree within 0.2 px at the image
    corners (0.3 px noise; both refine on the inliers by Levenberg-Marquardt, from
    different samples: 0.07 px apart here)."""
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 640, (200, 2))
    dst = transform_points(H_TRUE, src) + rng.normal(0, 0.3, (200, 2))
    dst[:40] += rng.uniform(30, 80, (40, 2))  # gross outliers
    fit = find_homography(src, dst, 3.0)
    H, mask = fit
    assert isinstance(fit, HomographyFit) and fit.n_inliers == int(mask.sum())
    assert H is fit.H and H.shape == (3, 3) and H.dtype == np.float64
    assert mask.shape == (200, 1) and mask.dtype == np.uint8
    assert set(np.unique(mask)) <= {0, 1}
    np.testing.assert_array_equal(mask[:, 0].astype(bool), fit.inliers)
    assert np.isfinite(fit.rms) and fit.n_iterations > 0  # attribute access kept
    Hc, mc = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)
    assert mc.shape == mask.shape and mc.dtype == mask.dtype
    assert not mask[:40].any() and not mc[:40].any()
    assert _corner_error(H, Hc) < 0.2
    assert _corner_error(H, H_TRUE) < 0.5


def test_good_features_to_track_output_is_taken():
    """cv2.goodFeaturesToTrack gives (N, 1, 2) float32; mapped by cv2.perspectiveTransform
    (also (N, 1, 2)) they give exactly the H of the same points as (N, 2), and the true
    H within 1e-6 of the corners' positions (no noise)."""
    p0 = cv2.goodFeaturesToTrack(_textured(), 200, 0.01, 8)
    assert p0.ndim == 3 and p0.shape[1:] == (1, 2) and p0.dtype == np.float32
    p1 = cv2.perspectiveTransform(p0.astype(np.float64), H_TRUE)
    H, mask = find_homography(p0, p1, 1.0)
    flat = find_homography(p0[:, 0], p1[:, 0], 1.0)
    np.testing.assert_array_equal(H, flat.H)
    assert mask.shape == (len(p0), 1) and mask.all()
    assert _corner_error(H, H_TRUE) < 1e-3


@pytest.mark.realdata
def test_find_chessboard_corners_output_is_taken():
    """cv2.findChessboardCorners + cv2.cornerSubPix's (54, 1, 2) float32 corners of
    OpenCV's left01.jpg against the board's plane coordinates: the same H as from the
    (54, 2) corners, every corner an inlier, and a sub-pixel RMS (lens distortion
    included)."""
    g = cv2.imread(
        str(data_path("calibration", "opencv_chessboard_stereo", "left01.jpg")),
        cv2.IMREAD_GRAYSCALE,
    )
    ok, corners = cv2.findChessboardCorners(g, (9, 6))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    corners = cv2.cornerSubPix(g, corners, (11, 11), (-1, -1), crit)
    assert ok and corners.shape == (54, 1, 2) and corners.dtype == np.float32
    board = chessboard_points((9, 6), 25.0)[:, :2]
    fit = find_homography(board, corners, 3.0)
    H, mask = fit
    np.testing.assert_array_equal(H, find_homography(board, corners[:, 0], 3.0).H)
    assert mask.all() and fit.rms < 1.0


@pytest.mark.realdata
def test_graf_tutorial_form_against_ground_truth():
    """OpenCV's feature-homography tutorial, line for line, with ours in place of
    cv2.findHomography: ``src_pts = np.float32([...]).reshape(-1, 1, 2)``, then
    ``M, mask = find_homography(src_pts, dst_pts, 5.0)``. graf 1 -> 2: the image corners
    within 3 px of the dataset's H (cv2.findHomography on the same matches: ~1-2 px)."""
    root = ("features", "oxford_affine", "graf")
    a = cv2.imread(str(data_path(*root, "img1.png")), cv2.IMREAD_GRAYSCALE)
    b = cv2.imread(str(data_path(*root, "img2.png")), cv2.IMREAD_GRAYSCALE)
    fs = cv2.FileStorage(str(data_path(*root, "H1to2p.xml")), cv2.FILE_STORAGE_READ)
    truth = fs.getNode(fs.root().keys()[0]).mat()
    sift = cv2.SIFT_create(600)
    kp1, des1 = sift.detectAndCompute(a, None)
    kp2, des2 = sift.detectAndCompute(b, None)
    good = [
        m for m, n in cv2.BFMatcher().knnMatch(des1, des2, k=2) if m.distance < 0.7 * n.distance
    ]
    src_pts = np.float32([kp1[m.queryIdx].pt for m in good]).reshape(-1, 1, 2)
    dst_pts = np.float32([kp2[m.trainIdx].pt for m in good]).reshape(-1, 1, 2)
    M, mask = find_homography(src_pts, dst_pts, 5.0)
    assert mask.shape == (len(good), 1) and mask.sum() > 50
    h, w = a.shape
    assert _corner_error(M, truth, w, h) < 3.0


def test_shared_point_check_squeezes_only_opencv_point_vectors():
    """check_points takes (N, 1, dim) as (N, dim) (a view: no copy needed for float64),
    and refuses (N, 2, 1), (N, 1, 3) for dim 2, and 4-D arrays, naming OpenCV's form."""
    p = np.arange(10.0).reshape(5, 1, 2)
    assert np.shares_memory(squeeze_point_axis(p, 2), p)
    np.testing.assert_array_equal(check_points(p, "p", 2), p[:, 0])
    assert squeeze_point_axis(p, None).shape == (5, 2)
    assert check_points(np.zeros((3, 1, 3)), "p", 3).shape == (3, 3)
    assert check_points(np.zeros((0, 1, 2)), "p", 2).shape == (0, 2)
    for bad in (np.zeros((5, 2, 1)), np.zeros((5, 1, 3)), np.zeros((5, 1, 1, 2))):
        with pytest.raises(
            InputError, match=r"p must have shape \(N, 2\) \(or OpenCV's \(N, 1, 2\)\)"
        ):
            check_points(bad, "p", 2)


def test_other_estimation_functions_take_opencv_point_vectors():
    """fit_line and ransac (through the shared check) give the same result for
    (N, 1, 2) as for (N, 2)."""
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 10, 50)
    pts = np.c_[x, 2 * x + 1 + rng.normal(0, 0.01, 50)]
    a, b = fit_line(pts[:, None, :]), fit_line(pts)
    np.testing.assert_array_equal(a.line.coefficients, b.line.coefficients)
    r1 = ransac(pts[:, None, :], LineModel(), 0.1, rng=0)
    r2 = ransac(pts, LineModel(), 0.1, rng=0)
    np.testing.assert_array_equal(r1.inliers, r2.inliers)
    with pytest.raises(InputError, match="src and dst must have the same shape"):
        find_homography(np.zeros((5, 1, 2)), np.zeros((4, 1, 2)))


def test_opencv_keyword_names_and_the_method_constant_trap():
    """OpenCV's keyword names give the native result; both spellings are refused; an
    int 8 (cv2.RANSAC) in OpenCV's third place is read as pixels, with a warning."""
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 400, (60, 2))
    h = np.array([[1.1, 0.05, 4.0], [0.02, 0.95, -3.0], [1e-4, 2e-5, 1.0]])
    d = np.c_[src, np.ones(60)] @ h.T
    dst = d[:, :2] / d[:, 2:]
    dst[:10] += rng.uniform(-40, 40, (10, 2))
    native = find_homography(src, dst, 2.0, max_iterations=500, probability=0.99)
    cv_named = find_homography(src, dst, ransacReprojThreshold=2.0, maxIters=500, confidence=0.99)
    np.testing.assert_array_equal(native.H, cv_named.H)
    with pytest.raises(InputError, match="ransacReprojThreshold"):
        find_homography(src, dst, 2.0, ransacReprojThreshold=3.0)
    with pytest.warns(UserWarning, match="cv2.RANSAC"):
        trap = find_homography(src, dst, cv2.RANSAC)
    np.testing.assert_array_equal(trap.H, find_homography(src, dst, 8.0).H)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        find_homography(src, dst, 5)  # other ints are plain pixels, no warning
