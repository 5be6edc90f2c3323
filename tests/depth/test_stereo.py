"""Stereo matching (block matching, semi-global matching) and disparity to depth:
hand cases, synthetic pairs with known disparity, the Middlebury pairs against
OpenCV's StereoBM / StereoSGBM, and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.depth.stereo import (
    bad_pixel_rate,
    block_matching,
    census_transform,
    depth_resolution,
    disparity_to_depth,
    disparity_to_points,
    reprojection_matrix,
    semi_global_matching,
)
from robopercept.errors import InputError
from tests.conftest import data_path


def _texture(shape, seed=0):
    from robopercept.imaging.filters import gaussian_blur

    t = gaussian_blur(np.random.default_rng(seed).uniform(0, 1, shape), 1.0)
    return np.round(255 * (t - t.min()) / np.ptp(t)).astype(np.uint8)


def _shifted_pair(shape=(60, 120), disparity=7, seed=0):
    """left(x) = right(x - d): every left pixel has disparity d."""
    h, w = shape
    wide = _texture((h, w + disparity), seed)
    return wide[:, :w], wide[:, disparity:]


@pytest.mark.parametrize("method", ["bm-sad", "bm-ssd", "bm-ncc", "sgm"])
def test_constant_disparity_is_recovered(method):
    left, right = _shifted_pair()
    for subpixel in (False, True):
        if method == "sgm":
            d = semi_global_matching(left, right, 16, subpixel=subpixel)
        else:
            d = block_matching(left, right, 16, 7, method[3:], subpixel=subpixel)
        inner = d[5:-5, 20:-5]  # away from borders and the left band where d > x
        if subpixel:  # the parabola moves single pixels a little, not the whole
            assert abs(np.median(inner) - 7) < 0.02 and np.abs(inner - 7).max() < 0.5
        else:
            assert (inner == 7).all()


def test_left_band_uses_the_disparities_that_fit():
    """Column x can only have d <= x: columns 0..6 hold NaN or a disparity <= x."""
    left, right = _shifted_pair(disparity=3)
    d = semi_global_matching(left, right, 10, median=False)
    xs = np.arange(d.shape[1])
    ok = np.isnan(d) | (d <= xs[None, :] + 1e-6)
    assert ok.all()
    assert (np.nan_to_num(d[:, 0], nan=0.0) == 0).all()


def test_subpixel_shift():
    """A smooth texture moved by 5.3 px: the parabola finds the fraction, up to the
    parabola's known pull toward whole pixels (measured 5.11 for block matching)."""
    from scipy.ndimage import shift

    base = _texture((60, 140), seed=1).astype(float)
    left = base[:, 10:130]
    right = shift(base, (0, -5.3), order=3, mode="nearest")[:, 10:130]
    for d in (block_matching(left, right, 12, 9), semi_global_matching(left, right, 12)):
        inner = d[6:-6, 20:-6]
        assert abs(np.median(inner) - 5.3) < 0.25


def test_occlusion_is_rejected_by_the_consistency_check():
    """A square at disparity 12 over a background at 4: the background strip the
    square hides from the right camera fails the left-right check."""
    h, w = 80, 160
    bg = _texture((h, w + 20), seed=2)
    fg = _texture((30, 50), seed=3)
    left = bg[:, :w].copy()
    right = bg[:, 4 : 4 + w].copy()
    left[25:55, 70:120] = fg
    right[25:55, 58:108] = fg  # moved 12 px
    d = semi_global_matching(left, right, 20, lr_check=1.0)
    assert np.nanmedian(d[30:50, 80:110]) == pytest.approx(12, abs=0.2)
    assert np.nanmedian(d[5:20, 20:150]) == pytest.approx(4, abs=0.2)
    # the background just left of the square (x 62..69 in the left image) lands behind
    # the square in the right image: seen by the left camera only, so rejected
    assert np.isnan(d[30:50, 63:69]).mean() > 0.6
    assert np.isnan(d[5:20, 20:150]).mean() < 0.05


def test_uniqueness_rejects_a_blank_region():
    left, right = _shifted_pair((60, 120), 5, seed=4)
    left, right = left.copy(), right.copy()
    left[20:40, 40:80] = 128
    right[20:40, 35:75] = 128
    d = block_matching(left, right, 16, 7, uniqueness=0.1)
    assert np.isnan(d[25:35, 50:70]).all()
    assert np.isfinite(d[45:55, 30:110]).mean() > 0.95


def test_census_hand_case():
    img = np.arange(1, 10, dtype=np.uint8).reshape(3, 3) * 10
    c = census_transform(img, 3)
    # neighbours of the centre (50) in row order: 10 20 30 40 | 60 70 80 90
    assert int(c[1, 1]) == 0b11110000
    assert c.dtype == np.uint64


def test_depth_from_disparity():
    d = np.array([[10.0, 20.0], [0.0, np.nan]])
    z = disparity_to_depth(d, focal=500.0, baseline=0.1)
    assert z[0, 0] == pytest.approx(5.0) and z[0, 1] == pytest.approx(2.5)
    assert np.isnan(z[1]).all()
    # one disparity step at 5 m: 25 * 1 / 50 = 0.5 m; it grows with z squared
    assert depth_resolution(5.0, 500.0, 0.1) == pytest.approx(0.5)
    assert depth_resolution(10.0, 500.0, 0.1) == pytest.approx(2.0)
    assert depth_resolution(5.0, 500.0, 0.1, 0.25) == pytest.approx(0.125)


def test_points_equal_opencv_reproject():
    cv2 = pytest.importorskip("cv2")
    Q = np.array([[1, 0, 0, -320.0], [0, 1, 0, -240], [0, 0, 0, 700], [0, 0, 1 / 0.12, 0]])
    d = np.random.default_rng(0).uniform(5, 60, (48, 64)).astype(np.float32)
    ours = disparity_to_points(d, Q)
    ref = cv2.reprojectImageTo3D(d, Q)
    assert np.allclose(ours, ref, rtol=1e-5)
    d[0, 0] = np.nan
    assert np.isnan(disparity_to_points(d, Q)[0, 0]).all()


def test_bad_pixel_rate_hand_case():
    truth = np.array([[1.0, 2.0, 0.0, 4.0]])
    disp = np.array([[1.5, 5.0, 9.0, np.nan]])
    # known: 3 pixels; bad: 2.0 (off by 3) and 4.0 (invalid) -> 2 / 3
    assert bad_pixel_rate(disp, truth, 2.0) == pytest.approx(2 / 3)


def test_bad_input():
    left, right = _shifted_pair()
    with pytest.raises(InputError, match="rectify"):
        block_matching(left, right[:, :100], 16)
    with pytest.raises(InputError, match="below the image width"):
        semi_global_matching(left, right, 500)
    with pytest.raises(InputError, match="min_disparity"):
        semi_global_matching(left, right, 5, min_disparity=5)
    with pytest.raises(InputError, match="paths"):
        semi_global_matching(left, right, 16, paths=6)
    with pytest.raises(InputError, match="P1 <= P2"):
        semi_global_matching(left, right, 16, P1=100, P2=50)
    with pytest.raises(InputError, match="window"):
        block_matching(left, right, 16, 8)
    with pytest.raises(InputError, match="cost"):
        block_matching(left, right, 16, 7, "census")
    with pytest.raises(InputError, match="uniqueness"):
        block_matching(left, right, 16, uniqueness=1.5)
    with pytest.raises(InputError, match="census window"):
        census_transform(left, 9)
    with pytest.raises(InputError, match=r"focal \(pixels\) must be in \(0, inf\]"):
        disparity_to_depth(np.ones((2, 2)), 0.0, 0.1)


# ------------------------------------------------------------------ Middlebury

PAIRS = {"tsukuba": (16, 16), "venus": (8, 32), "cones": (4, 64), "teddy": (4, 64)}


def _middlebury(name):
    from robopercept.imaging import read_image

    folder = data_path("stereo", "middlebury_opencv_extra", name)
    scale, nd = PAIRS[name]
    left = read_image(folder / "im2.png", mode="gray")
    right = read_image(folder / "im6.png", mode="gray")
    truth = read_image(folder / "disp2.png", mode="gray").astype(float) / scale
    return left, right, truth, nd


@pytest.mark.realdata
@pytest.mark.parametrize("name", list(PAIRS))
def test_sgm_beats_opencv_sgbm_on_middlebury(name):
    """bad-2.0 (invalid counted as bad) at most cv2.StereoSGBM's with comparable
    settings: the same disparity range, 5x5 blocks, P1 = 8 * 25 and P2 = 32 * 25 (the
    values of OpenCV's sample), default mode. Measured (ours / OpenCV, %): tsukuba
    5.3 / 5.7, venus 4.4 / 9.2, cones 13.1 / 21.4, teddy 14.6 / 24.0."""
    cv2 = pytest.importorskip("cv2")
    left, right, truth, nd = _middlebury(name)
    ours = bad_pixel_rate(semi_global_matching(left, right, nd - 1), truth)
    sgbm = cv2.StereoSGBM_create(0, nd, 5, P1=8 * 25, P2=32 * 25)
    ref = sgbm.compute(left, right).astype(float) / 16
    ref[ref < 0] = np.nan
    assert ours <= bad_pixel_rate(ref, truth), (name, ours)


@pytest.mark.realdata
@pytest.mark.parametrize("name", list(PAIRS))
def test_block_matching_beats_opencv_bm_on_middlebury(name):
    """bad-2.0 at most cv2.StereoBM's with the same 9x9 window and disparity range
    (its defaults otherwise). Measured (ours SAD / OpenCV, %): tsukuba 9.9 / 14.1,
    venus 9.2 / 22.1, cones 23.8 / 28.5, teddy 26.8 / 34.3."""
    cv2 = pytest.importorskip("cv2")
    left, right, truth, nd = _middlebury(name)
    ours = bad_pixel_rate(block_matching(left, right, nd - 1, 9), truth)
    ref = cv2.StereoBM_create(nd, 9).compute(left, right).astype(float) / 16
    ref[ref < 0] = np.nan
    assert ours <= bad_pixel_rate(ref, truth), (name, ours)


@pytest.mark.realdata
def test_left_right_check_on_cones_keeps_accurate_pixels_and_near_points():
    """Issue 30: with the left-right check (1 px, robopercept stereo's default; OpenCV's
    SGBM always applies one) the rejected pixels are NaN and the valid share is honest:
    cones keeps 88 % of the pixels (OpenCV SGBM: 84 %), and only 4.1 % of the kept
    pixels with known truth are off by more than 2 px (without the check 13.0 %;
    OpenCV SGBM 5.6 %). The left band, whose matches left the right image, is
    rejected, and with a nominal rig (f = 700 px, B = 0.16 m: the scene, truth 5.5-55
    px, lies at 2.0-20.4 m) the points of disparities above 1 px stay within the
    scene but for < 0.05 % (before: points up to 223 m, 2.8 % beyond the scene)."""
    cv2 = pytest.importorskip("cv2")
    left, right, truth, nd = _middlebury("cones")
    dense = semi_global_matching(left, right, nd - 1)
    d = semi_global_matching(left, right, nd - 1, lr_check=1.0)
    assert np.isfinite(dense).all()
    valid = np.isfinite(d)
    assert 0.80 < valid.mean() < 0.95
    assert np.isnan(d[:, :15]).mean() > 0.9  # the left band
    assert (d[valid] > 0).all()  # winners at the range's end (d = 0) are rejected
    ours = bad_pixel_rate(d, truth, 2.0, invalid="ignore")
    assert ours < 0.06 and bad_pixel_rate(dense, truth, 2.0, invalid="ignore") > 0.1
    sgbm = cv2.StereoSGBM_create(0, nd, 5, P1=8 * 25, P2=32 * 25)
    ref = sgbm.compute(left, right).astype(float) / 16
    ref[ref < 0] = np.nan
    assert ours <= bad_pixel_rate(ref, truth, 2.0, invalid="ignore")
    fb = 700.0 * 0.16
    Q = reprojection_matrix(700.0, 0.16, left.shape[::-1])
    pts = disparity_to_points(d, Q, min_disparity=1.0)
    z = pts[..., 2][np.isfinite(pts[..., 2])]
    assert z.size > 0.8 * d.size and z.max() < fb  # d > 1 px: z < f B
    scene = fb / truth[truth > 0].min()
    assert (z > scene).mean() < 5e-4


def test_lr_check_rejects_winners_at_the_lowest_disparity():
    """A pair at disparity 0 with min_disparity 0: every winner is the range's lower
    end, unbracketed: NaN with the check, kept without it; at disparity 3 the check
    keeps the interior."""
    left, right = _shifted_pair((40, 80), 0, seed=5)
    assert np.isnan(semi_global_matching(left, right, 8, lr_check=1.0)).all()
    assert (semi_global_matching(left, right, 8) == 0).mean() > 0.95
    left, right = _shifted_pair((40, 80), 3, seed=5)
    d = semi_global_matching(left, right, 8, lr_check=1.0)
    assert np.nanmedian(d[:, 10:]) == pytest.approx(3.0, abs=0.1)
    assert np.isfinite(d[5:-5, 10:-5]).mean() > 0.95


def test_bad_pixel_rate_on_valid_pixels_and_point_floor():
    d = np.array([[10.0, 12.5, np.nan, 3.0]])
    t = np.array([[10.0, 10.0, 10.0, 0.0]])
    assert bad_pixel_rate(d, t) == pytest.approx(2 / 3)  # NaN counts as bad
    assert bad_pixel_rate(d, t, invalid="ignore") == pytest.approx(1 / 2)
    with pytest.raises(InputError, match="invalid"):
        bad_pixel_rate(d, t, invalid="skip")
    from robopercept.errors import DegenerateError

    with pytest.raises(DegenerateError, match="no pixel with known truth has a disparity"):
        bad_pixel_rate(np.full((1, 4), np.nan), t, invalid="ignore")
    Q = reprojection_matrix(500.0, 0.1, (4, 1))
    pts = disparity_to_points(np.array([[0.5, 1.0, 1.5, 50.0]]), Q, min_disparity=1.0)
    assert np.isnan(pts[0, :2]).all() and np.isfinite(pts[0, 2:]).all()
    assert pts[0, 3, 2] == pytest.approx(1.0)  # z = f B / d = 50 / 50
    with pytest.raises(InputError, match="min_disparity"):
        disparity_to_points(d, Q, min_disparity=-1.0)


def test_reprojection_matrix_hand_case_and_cv2():
    import cv2

    from robopercept.depth.stereo import disparity_to_points, reprojection_matrix

    Q = reprojection_matrix(400.0, 0.2, (9, 5))
    # centre pixel (4, 2) at disparity 40: Z = f B / d = 2, X = Y = 0; one pixel to the
    # right: X = (5 - 4) * 2 / 400
    pts = disparity_to_points(np.full((5, 9), 40.0), Q)
    np.testing.assert_allclose(pts[2, 4], [0.0, 0.0, 2.0])
    np.testing.assert_allclose(pts[2, 5], [2.0 / 400, 0.0, 2.0])
    # the same points as cv2.reprojectImageTo3D with this Q (float32 inside OpenCV)
    ref = cv2.reprojectImageTo3D(np.full((5, 9), 40.0, np.float32), Q)
    np.testing.assert_allclose(pts, ref, rtol=1e-6, atol=1e-7)
    with pytest.raises(InputError, match=r"focal \(pixels\) must be in \(0, inf\]"):
        reprojection_matrix(0.0, 0.2, (9, 5))


# issue 25: scalar parameters are checked for type, finiteness and size at the boundary
def _bad_stereo_calls():
    left, right = _shifted_pair((30, 50), 3)
    d = np.full((2, 3), 4.0)
    return [
        (lambda: block_matching(left, right, 8, float("inf")), "window must be an"),
        (lambda: block_matching(left, right, -np.inf), "max_disparity must be an integer"),
        (lambda: block_matching(left, right, 8.0), "max_disparity must be an integer; got 8.0"),
        (lambda: block_matching(left, right, 8, uniqueness=None), "uniqueness must be a real"),
        (lambda: block_matching(left, right, 8, uniqueness=1 + 1j), "uniqueness .* real number"),
        (
            lambda: block_matching(left, right, 8, lr_check="3"),
            r"lr_check \(pixels; None: no",
        ),
        (lambda: block_matching(left, right, 8, cost=["sad"]), "cost must be"),
        (lambda: block_matching(left, right, 8, subpixel="yes"), "subpixel must be True or"),
        (lambda: semi_global_matching(left, right, 8, min_disparity=np.inf), "min_disparity"),
        (lambda: semi_global_matching(left, right, 8, paths=4.0), "paths must be an integer"),
        (lambda: semi_global_matching(left, right, 8, P2=2.0**40), r"P2 must be in \[0, 8192\]"),
        (lambda: semi_global_matching(left, right, 8, census=1 + 1j), "census must be an int"),
        (lambda: semi_global_matching(left, right, 8, block=2**40 + 1), "overflow the 16-bit"),
        (lambda: semi_global_matching(left, right, 8, median=None), "median must be True"),
        (lambda: census_transform(left, 1 + 1j), "window must be an integer"),
        (lambda: census_transform(left, [1, 2]), "window must be an integer"),
        (lambda: depth_resolution(1.0, None, 0.1), r"focal \(pixels\) must be a real"),
        (lambda: depth_resolution(1.0, 500.0, 0.1, 1 + 1j), "disparity_step must be a real"),
        (lambda: disparity_to_depth(d, 500.0, [1, 2]), "baseline must be a real"),
        (lambda: disparity_to_depth(d, 1e200, 1e200), "focal \\* baseline overflows"),
        (lambda: disparity_to_depth([["a"]], 500.0, 0.1), "disparity must hold real numbers"),
        (lambda: reprojection_matrix(500.0, 0.1, ()), r"size must be \(width, height\)"),
        (lambda: reprojection_matrix(500.0, None, (9, 5)), "baseline"),
        (lambda: bad_pixel_rate(d, d, None), r"threshold \(pixels\) must be a real"),
        (lambda: bad_pixel_rate(d, d, invalid=None), "invalid must be 'bad' or 'ignore'"),
        (lambda: disparity_to_points(d, np.full((4, 4), np.nan)), "Q must be finite"),
    ]


@pytest.mark.parametrize("i", range(len(_bad_stereo_calls())))
def test_bad_scalars_give_input_errors(i):
    call, words = _bad_stereo_calls()[i]
    with pytest.raises(InputError, match=words):
        call()


def test_cost_volume_is_bounded():
    """A 4000x3000 pair with 2001 disparities would need 134 GiB: refused, limit named."""
    big = np.broadcast_to(np.zeros(1, np.uint8), (3000, 4000))
    with pytest.raises(
        InputError,
        match=r"134\.9 GiB cost volume, over the limit of 4 GiB: search fewer",
    ):
        semi_global_matching(big, big, 2000)


def test_valid_edge_scalars_still_work():
    left, right = _shifted_pair((30, 50), 3)
    ref = block_matching(left, right, 8, 5)
    got = block_matching(left, right, np.int64(8), np.int32(5), min_disparity=np.int16(0))
    np.testing.assert_array_equal(got, ref)
    # fractional penalties round to the integer costs
    np.testing.assert_array_equal(
        semi_global_matching(left, right, 8, P1=10.4, P2=40.6),
        semi_global_matching(left, right, 8, P1=10, P2=41),
    )
    # a tiny but positive baseline gives z = f B / d exactly, not 0 or NaN
    assert disparity_to_depth(np.array([2.0]), 500.0, 1e-10)[0] == pytest.approx(2.5e-8)
    Q = reprojection_matrix(500.0, 0.1, (9.0, 5.0))  # integral floats are sizes too
    assert Q[0, 3] == -4.0 and Q[1, 3] == -2.0
