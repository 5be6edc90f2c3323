"""Harris / Shi-Tomasi: a hand-made square, parity with OpenCV (responses, corner
selection, subpixel refinement), invariances, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.features import (
    harris_corners,
    harris_response,
    min_eigenvalue,
    refine_corners,
    structure_tensor,
)
from robopercept.features.harris import good_features_to_track
from robopercept.imaging import rgb_to_gray


def _square(size: int = 40, lo: int = 10, hi: int = 29) -> np.ndarray:
    img = np.zeros((size, size), dtype=np.uint8)
    img[lo : hi + 1, lo : hi + 1] = 200
    return img


def test_square_corners_edges_and_flat():
    # a 20x20 bright square: the response is positive at its 4 corners, negative along
    # its edges, zero far away; the 4 strongest corners are the square's corners
    img = _square()
    r = harris_response(img, 3, 3, 0.04)
    assert r[10, 10] > 0 and r[29, 29] > 0
    assert r[20, 10] < 0 and r[10, 20] < 0  # edge middles
    assert r[2, 2] == 0 and r[20, 20] == 0  # flat outside and inside
    kp = harris_corners(img, block_size=3, threshold=0.1, min_distance=5)
    assert len(kp) == 4
    found = sorted(map(tuple, kp.xy.round().astype(int)))
    # the response peaks on the pixel pair straddling each corner
    for (x, y), (ex, ey) in zip(found, [(10, 10), (10, 29), (29, 10), (29, 29)], strict=True):
        assert abs(x - ex) <= 1 and abs(y - ey) <= 1
    assert np.all(np.isnan(kp.orientation)) and np.all(kp.scale == 3)
    assert np.all(np.diff(kp.response) <= 0)  # strongest first


def test_structure_tensor_hand_computed():
    # a horizontal ramp of slope 3 grey levels per pixel: the 3x3 Sobel x-derivative is
    # (1 + 2 + 1) * (3 * 2) = 24, scaled by OpenCV's 1 / (2^(3-1) * block 1 * 255);
    # with a 1-pixel window A = I_x^2 and B = C = 0 away from the border (float32: rtol)
    img = np.tile(np.arange(20, dtype=np.uint8) * 3, (10, 1))
    a, b, c = structure_tensor(img, block_size=1, ksize=3)
    gx = 24 / (4 * 255)
    np.testing.assert_allclose(a[3:-3, 3:-3], gx * gx, rtol=1e-5)
    assert np.all(b[3:-3, 3:-3] == 0) and np.all(c[3:-3, 3:-3] == 0)
    # on an edge the minimum eigenvalue is 0: an edge is not a corner
    assert np.all(min_eigenvalue(img, 3)[3:-3, 3:-3] == 0)


@pytest.mark.realdata
@pytest.mark.parametrize(("block", "ksize", "k"), [(2, 3, 0.04), (3, 5, 0.06), (5, 7, 0.05)])
def test_harris_matches_opencv(graf, block, ksize, k):
    # tolerance: both sides compute in float32 with the same operations in a different
    # order; max |diff| relative to the largest response measured at ~1e-6, bound 1e-4
    gray = rgb_to_gray(graf)
    ref = cv2.cornerHarris(gray, block, ksize, k)
    ours = harris_response(gray, block, ksize, k)
    assert ours.dtype == np.float32
    assert np.abs(ours - ref).max() <= 1e-4 * np.abs(ref).max()
    ref = cv2.cornerMinEigenVal(gray, block, ksize=ksize)
    ours = min_eigenvalue(gray, block, ksize)
    assert np.abs(ours - ref).max() <= 1e-4 * np.abs(ref).max()
    # float input in [0, 1] gives the same responses as uint8 (OpenCV's 1/255 scaling)
    f = gray.astype(np.float32) / 255
    np.testing.assert_allclose(
        harris_response(f, block, ksize, k),
        cv2.cornerHarris(f, block, ksize, k),
        atol=1e-4 * np.abs(ref).max(),
    )


@pytest.mark.realdata
@pytest.mark.parametrize("method", ["harris", "shi-tomasi"])
@pytest.mark.parametrize("min_distance", [0.0, 3.5, 10.0])
def test_corners_match_good_features_to_track(graf, method, min_distance):
    gray = rgb_to_gray(graf)
    kp = harris_corners(
        gray,
        method=method,
        block_size=3,
        threshold=0.01,
        min_distance=min_distance,
        max_corners=500,
    )
    ref = cv2.goodFeaturesToTrack(
        gray,
        500,
        0.01,
        min_distance,
        mask=None,
        blockSize=3,
        gradientSize=3,
        useHarrisDetector=method == "harris",
        k=0.04,
    )[:, 0]
    np.testing.assert_array_equal(kp.xy, ref)  # same corners, same order


@pytest.mark.realdata
def test_subpixel_matches_corner_subpix(graf):
    gray = rgb_to_gray(graf)
    start = cv2.goodFeaturesToTrack(gray, 300, 0.01, 10, mask=None, blockSize=3, gradientSize=3)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 0.001)
    ref = cv2.cornerSubPix(gray, start.copy(), (5, 5), (-1, -1), criteria)[:, 0]
    ours = refine_corners(gray, start[:, 0].astype(np.float64), 5, max_iter=40, eps=0.001)
    # OpenCV samples the window in float32, we in float64: measured max 2e-4 px
    assert np.abs(ours - ref).max() < 2e-3


def test_subpixel_finds_a_known_corner():
    # the saddle of a 2x2 checkerboard at (12.3, 14.6), rendered by 8x8 supersampling then
    # blurred: from a start 0.7 px off, the refinement lands within 0.02 px of it (a
    # saddle is symmetric, so the gradient-orthogonality estimate has no bias there)
    s = 8
    yy, xx = np.mgrid[0 : 32 * s, 0 : 32 * s]
    right = (xx + 0.5) / s - 0.5 >= 12.3
    below = (yy + 0.5) / s - 0.5 >= 14.6
    img = (right ^ below).reshape(32, s, 32, s).mean(axis=(1, 3))
    img = cv2.GaussianBlur(img, (5, 5), 1.0)
    out = refine_corners(img, [[13.0, 15.0]], 4)
    np.testing.assert_allclose(out[0], [12.3, 14.6], atol=0.02)


def test_rotation_invariance_and_intensity_scaling(camera):
    img = camera.astype(np.float64) / 255
    r = harris_response(img, 3, 3, 0.04)
    # a 90-degree rotation rotates the response (odd window: symmetric about its centre)
    np.testing.assert_allclose(
        np.rot90(harris_response(np.rot90(img), 3, 3, 0.04), -1), r, atol=1e-12
    )
    a = harris_corners(img, block_size=3, min_distance=5, max_corners=200)
    b = harris_corners(np.rot90(img).copy(), block_size=3, min_distance=5, max_corners=200)
    h = img.shape[0]
    # (x, y) in the rotated image is (y, h - 1 - x) ... rot90 maps (row, col) -> (W-1-col, row)
    back = np.column_stack([h - 1 - b.xy[:, 1], b.xy[:, 0]])
    assert {tuple(p) for p in back} == {tuple(p) for p in a.xy}
    # intensity: I -> 2 I multiplies R by 2^4 (not invariant), the relative threshold
    # keeps the same corners
    np.testing.assert_allclose(harris_response(2 * img, 3, 3, 0.04), 16 * r, rtol=1e-9, atol=1e-15)
    c = harris_corners(2 * img, block_size=3, min_distance=5, max_corners=200)
    np.testing.assert_array_equal(c.xy, a.xy)


def test_scale_is_not_invariant():
    # the same (slightly blurred) corner seen 4x larger: a 3x3 window on the big one sees
    # a nearly straight, soft edge, and the corner response collapses; hence SIFT's
    # search over scale
    small = cv2.GaussianBlur(_square().astype(np.float64) / 255, (5, 5), 1.0)
    big = cv2.resize(small, None, fx=4, fy=4, interpolation=cv2.INTER_CUBIC)
    r_small = harris_response(small, 3, 3, 0.04).max()
    r_big = harris_response(big, 3, 3, 0.04).max()
    assert r_big < 0.01 * r_small


def test_gaussian_window():
    img = _square().astype(np.float32) / 255
    a, _, _ = structure_tensor(img, 5, window="gaussian")
    box, _, _ = structure_tensor(img, 5)
    # same total weight as the box: equal on a constant gradient, peaked differently
    ramp = np.tile(np.linspace(0, 1, 30, dtype=np.float32), (30, 1))
    ga, _, _ = structure_tensor(ramp, 5, window="gaussian")
    ba, _, _ = structure_tensor(ramp, 5)
    np.testing.assert_allclose(ga[5:-5, 5:-5], ba[5:-5, 5:-5], rtol=1e-5)
    assert not np.allclose(a, box)
    kp = harris_corners(img, window="gaussian", block_size=5, threshold=0.1, min_distance=5)
    assert len(kp) == 4


def test_flat_image_and_bad_input():
    assert len(harris_corners(np.full((20, 20), 7, dtype=np.uint8))) == 0
    assert refine_corners(_square(), np.zeros((0, 2))).shape == (0, 2)
    img = _square()
    with pytest.raises(InputError, match="ksize"):
        harris_response(img, 3, 4)
    with pytest.raises(InputError, match="block_size"):
        harris_response(img, 0)
    with pytest.raises(InputError, match="threshold"):
        harris_corners(img, threshold=0)
    with pytest.raises(InputError, match="odd block_size"):
        harris_response(img, 4, window="gaussian")
    with pytest.raises(InputError, match="channels-first"):
        harris_response(np.zeros((3, 20, 20)))
    with pytest.raises(InputError, match="at least"):
        refine_corners(np.zeros((8, 8)), [[4.0, 4.0]], 5)
    # issue 25 (long fuzz campaign): an OverflowError from the int64 kernel argument
    with pytest.raises(InputError, match=r"max_iter must be at most 2\*\*31 - 1"):
        refine_corners(img, [[13.0, 15.0]], 4, max_iter=2**63)
    with pytest.raises(InputError, match=r"\(N, 2\)"):
        refine_corners(img, [1.0, 2.0, 3.0])


@pytest.mark.realdata
def test_good_features_to_track(graf):
    """Shi-Tomasi corners of the unrounded float32 luma, as cv2.goodFeaturesToTrack on
    the same gray image; motion re-exports the same function."""
    import robopercept.motion

    assert robopercept.motion.good_features_to_track is good_features_to_track
    square = np.zeros((20, 20), np.uint8)
    square[5:15, 5:15] = 255
    assert good_features_to_track(square, 4, 0.1, 3).tolist() == [
        [14.0, 14.0], [5.0, 14.0], [14.0, 5.0], [5.0, 5.0]
    ]  # fmt: skip
    xy = good_features_to_track(graf, 300, 0.01, 8)
    gray = rgb_to_gray(graf, dtype=np.float32)
    kp = harris_corners(gray, method="shi-tomasi", threshold=0.01, min_distance=8, max_corners=300)
    np.testing.assert_array_equal(xy, kp.xy)
    ref = cv2.goodFeaturesToTrack(gray, 300, 0.01, 8, blockSize=3).reshape(-1, 2)
    np.testing.assert_array_equal(xy, ref)  # integer pixel positions, same order
    # any dtype, scale-free: float input in [0, 1] gives the same corners as uint8 gray
    g8 = rgb_to_gray(graf)
    np.testing.assert_array_equal(
        good_features_to_track(g8, 300, 0.01, 8),
        good_features_to_track(g8.astype(np.float32) / 255, 300, 0.01, 8),
    )


# issue 25: images near 1e300 overflowed the 4th-order response and surfaced as a
# misleading "image must be finite" (float64) or NaN (float32 above ~1e10); refused
# with a typed error. Within the limits the response scales as the 4th power
@pytest.mark.parametrize(("dtype", "scale"), [(np.float64, 1e300), (np.float32, 1e10)])
def test_harris_refuses_values_whose_4th_power_overflows(dtype, scale):
    img = np.random.default_rng(0).random((32, 32))
    with pytest.raises(InputError, match="rescale your data"):
        harris_response((img * scale).astype(dtype))
    small = harris_response(img.astype(dtype))
    big = harris_response((img * 2.0**20).astype(dtype))  # exact scaling, 2^80 response
    np.testing.assert_allclose(big, small * 2.0**80, rtol=1e-4, atol=1e-30)
    assert (harris_response(img * 1e-300) == 0).all()  # (1e-300)^4 underflows to 0


# issue 25: block_size 2**40 allocated terabytes (2**63: OverflowError), and NaN or
# infinite zero_zone/corners raised ValueError/OverflowError; each is now an InputError
_IMG = np.zeros((32, 40), np.uint8)
_IMG[8:24, 10:30] = 255


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: min_eigenvalue(_IMG, 2**40), "block_size must be at most the image's larger"),
        (lambda: harris_corners(_IMG, block_size=2**63), "block_size must be at most"),
        (
            lambda: harris_response(_IMG, 41),
            "block_size must be at most the image's larger side, 40",
        ),
        (lambda: harris_response(_IMG, 3, np.array(3)), "ksize must be 1, 3, 5 or 7"),
        (lambda: harris_response(_IMG, 3, True), "ksize must be 1, 3, 5 or 7"),
        (lambda: refine_corners(_IMG, [[10.0, 8.0]], zero_zone=np.nan), "zero_zone must be an int"),
        (
            lambda: refine_corners(_IMG, [[10.0, 8.0]], zero_zone=-np.inf),
            "zero_zone must be an int",
        ),
        (lambda: refine_corners(_IMG, [[10.0, 8.0]], 3, zero_zone=3), "zero_zone must be smaller"),
        (lambda: refine_corners(_IMG, [[10.0, 8.0]], (3, 2, 1)), "window must be an int or a pair"),
        (lambda: refine_corners(_IMG, [[np.nan, 8.0]]), "corners must be finite"),
        (lambda: refine_corners(_IMG, "ab"), "corners must hold real numbers"),
    ],
)
def test_issue25_hostile_arguments_are_input_errors(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_largest_valid_block_and_zero_zone_still_work():
    r = min_eigenvalue(_IMG, 40)  # a block of the image's larger side is allowed
    assert r.shape == _IMG.shape and np.isfinite(r).all()
    out = refine_corners(_IMG.astype(np.float32), [[10.2, 8.3]], (4, 4), zero_zone=(1, 1))
    np.testing.assert_allclose(out, [[9.5, 7.5]], atol=0.05)  # the square's corner


def test_issue25_max_corners_beyond_the_pixels_keeps_all():
    # max_corners = 2**64 - 1 overflowed the compiled kernel's int64 (OverflowError)
    every = harris_corners(_IMG, min_distance=1.0)
    many = harris_corners(_IMG, min_distance=1.0, max_corners=2**64 - 1)
    np.testing.assert_array_equal(many.xy, every.xy)
    assert len(harris_corners(_IMG, min_distance=1.0, max_corners=1)) == 1
