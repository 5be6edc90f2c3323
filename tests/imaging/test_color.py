"""Colour conversions and HSV masks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import color as skcolor

from robopercept.errors import InputError
from robopercept.imaging import hsv_range_mask, hsv_to_rgb, rgb_to_gray, rgb_to_hsv


def test_primaries_hand():
    rgb = np.array(
        [[[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255], [0, 0, 0], [128, 128, 0]]],
        dtype=np.uint8,
    )
    hsv = rgb_to_hsv(rgb)
    assert hsv.dtype == np.uint8
    np.testing.assert_array_equal(hsv[0, :, 0], [0, 60, 120, 0, 0, 30])
    np.testing.assert_array_equal(hsv[0, :, 1], [255, 255, 255, 0, 0, 255])
    np.testing.assert_array_equal(hsv[0, :, 2], [255, 255, 255, 255, 0, 128])


def test_matches_opencv_on_real_images(astronaut, graf):
    for img in (astronaut, graf):
        # uint8 uses the same 12-bit fixed-point reciprocals as OpenCV: bit-exact
        np.testing.assert_array_equal(rgb_to_hsv(img), cv2.cvtColor(img, cv2.COLOR_RGB2HSV))
    # every (r, g) pair for a spread of b values
    r, g = np.meshgrid(np.arange(256), np.arange(256))
    for b in range(0, 256, 17):
        img = np.dstack([r, g, np.full_like(r, b)]).astype(np.uint8)
        np.testing.assert_array_equal(rgb_to_hsv(img), cv2.cvtColor(img, cv2.COLOR_RGB2HSV))
    # float input (exact division) stays within one level of the fixed-point result
    d = np.abs(
        rgb_to_hsv(astronaut.astype(np.float32) / 255) - cv2.cvtColor(astronaut, cv2.COLOR_RGB2HSV)
    )
    d[..., 0] = np.minimum(d[..., 0], 180 - d[..., 0])  # hue is circular (179.8 ~ 0)
    assert d.max() <= 1.0 + 1e-4


def test_every_uint8_colour_is_bit_exact():
    # all 2^24 RGB triples: this covers every V and Delta in 0..255, so the float32
    # reciprocals of the kernel are checked against OpenCV's tables for every input
    c = np.arange(1 << 24, dtype=np.uint32)
    img = np.stack([c >> 16, (c >> 8) & 255, c & 255], axis=1).astype(np.uint8)
    img = img.reshape(4096, 4096, 3)
    np.testing.assert_array_equal(rgb_to_hsv(img), cv2.cvtColor(img, cv2.COLOR_RGB2HSV))


def test_unit_scale_matches_skimage(astronaut):
    f = astronaut.astype(np.float64) / 255
    np.testing.assert_allclose(rgb_to_hsv(f, "unit"), skcolor.rgb2hsv(f), atol=1e-12)
    f32 = astronaut.astype(np.float32) / 255
    assert rgb_to_hsv(f32, "unit").dtype == np.float32
    assert rgb_to_hsv(f32).dtype == np.float32  # opencv scale on float input stays float


def test_round_trip(rng):
    f = rng.random((40, 50, 3))
    for scale in ("unit", "opencv"):
        np.testing.assert_allclose(hsv_to_rgb(rgb_to_hsv(f, scale), scale), f, atol=1e-10)
    u8 = (rng.random((40, 50, 3)) * 255).astype(np.uint8)
    back = hsv_to_rgb(cv2.cvtColor(u8, cv2.COLOR_RGB2HSV))
    assert np.abs(back.astype(int) - u8).max() <= 5  # H quantized to 2 degrees


def test_gray_matches_opencv(astronaut):
    ref = cv2.cvtColor(astronaut, cv2.COLOR_RGB2GRAY)
    assert np.abs(rgb_to_gray(astronaut).astype(int) - ref).max() <= 1


def test_hsv_range_mask_with_wraparound():
    hsv = np.array([[[175, 200, 200], [5, 200, 200], [90, 200, 200], [5, 10, 200]]], np.uint8)
    red = hsv_range_mask(hsv, (170, 50, 50), (10, 255, 255))
    np.testing.assert_array_equal(red[0], [True, True, False, False])
    green = hsv_range_mask(hsv, (80, 50, 50), (100, 255, 255))
    np.testing.assert_array_equal(green[0], [False, False, True, False])


def test_hsv_range_matches_inrange(astronaut):
    hsv = cv2.cvtColor(astronaut, cv2.COLOR_RGB2HSV)
    low, high = (35, 40, 40), (85, 255, 255)
    ref = cv2.inRange(hsv, np.array(low), np.array(high)) > 0
    np.testing.assert_array_equal(hsv_range_mask(hsv, low, high), ref)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: rgb_to_hsv(np.zeros((4, 4))), "no hue"),
        (lambda: rgb_to_hsv(np.zeros((4, 4, 3)), scale="deg"), "scale must be"),
        (lambda: rgb_to_hsv(np.zeros((4, 4, 4))), "RGBA"),
        (lambda: hsv_range_mask(np.zeros((4, 4, 3)), (0, 9, 0), (10, 5, 5)), "swap"),
        (lambda: hsv_range_mask(np.zeros((4, 4, 3)), (0, 0), (10, 5, 5)), "3 finite real"),
        (lambda: hsv_range_mask(np.zeros((4, 4)), (0, 0, 0), (1, 1, 1)), "rgb_to_hsv"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


class TestRgbToGray:
    """The one gray conversion: hand values, every dtype, OpenCV parity, bad input."""

    def test_hand_pixels(self):
        rgb = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255], [100, 100, 100]]], np.uint8)
        # 0.299 * 255 = 76.245, 0.587 * 255 = 149.685, 0.114 * 255 = 29.07: rounded
        np.testing.assert_array_equal(rgb_to_gray(rgb), [[76, 150, 29, 100]])
        np.testing.assert_allclose(
            rgb_to_gray(rgb, dtype=np.float64), [[76.245, 149.685, 29.07, 100.0]], rtol=1e-15
        )
        f = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]])
        np.testing.assert_allclose(rgb_to_gray(f), [[0.299, 0.587, 0.114, 1.0]], rtol=1e-15)
        # half up: Y = 0.299 * 5 + 0.587 * 0 + 0.114 * 0 = 1.495 -> 1; R=G=B=v -> v
        np.testing.assert_array_equal(rgb_to_gray(np.array([[[5, 0, 0]]], np.uint8)), [[1]])

    @pytest.mark.parametrize(
        "dtype, top, work",
        [
            (np.uint8, 255, np.float32),
            (np.uint16, 65535, np.float32),
            (np.int16, 32767, np.float32),
            (np.int32, 2**31 - 1, np.float64),
            (np.float32, 1.0, np.float32),
            (np.float64, 1.0, np.float64),
        ],
    )
    def test_each_dtype(self, rng, dtype, top, work):
        img = (rng.random((30, 40, 3)) * top).astype(dtype)
        gray = rgb_to_gray(img)
        assert gray.dtype == dtype and gray.shape == (30, 40)
        # the documented evaluation: (wr R + wg G) + wb B in the working type
        src = img.astype(work)
        w = [work(0.299), work(0.587), work(0.114)]
        y = src[..., 0] * w[0] + src[..., 1] * w[1] + src[..., 2] * w[2]
        if np.dtype(dtype).kind in "iu":
            # integers: rounded half up and saturated (white stays at the top)
            np.testing.assert_array_equal(gray, np.clip(np.floor(y + 0.5), 0, top))
            white = np.full((1, 1, 3), top, dtype)
            assert rgb_to_gray(white)[0, 0] == top
        else:
            np.testing.assert_array_equal(gray, y)
        # explicit float output: unrounded, same scale (nothing rescaled)
        for out in (np.float32, np.float64):
            g = rgb_to_gray(img, dtype=out)
            assert g.dtype == out
            exact = img.astype(np.float64) @ [0.299, 0.587, 0.114]
            tol = 1e-6 if out == np.float32 else 1e-14
            np.testing.assert_allclose(g, exact, rtol=tol, atol=tol * top)

    def test_gray_passes_through(self, camera):
        assert rgb_to_gray(camera) is camera  # no copy, no rescale
        f = rgb_to_gray(camera, dtype=np.float32)
        assert f.dtype == np.float32 and f.max() == camera.max()  # cast, not rescaled
        f64 = camera / 255.0
        assert rgb_to_gray(f64, dtype=np.float64) is f64

    def test_integer_rounds_the_float_result(self, astronaut):
        np.testing.assert_array_equal(
            rgb_to_gray(astronaut), np.floor(rgb_to_gray(astronaut, dtype=np.float32) + 0.5)
        )

    def test_matches_opencv_every_uint8_colour(self):
        # OpenCV sums with 14-bit fixed-point weights (4899, 9617, 1868) / 2^14, which
        # differ from 0.299, 0.587, 0.114 by up to 2.5e-5: over all 2^24 colours the
        # results differ by at most one grey level, on about 0.13% of them
        c = np.arange(1 << 24, dtype=np.uint32)
        img = np.stack([c >> 16, (c >> 8) & 255, c & 255], axis=1).astype(np.uint8)
        img = img.reshape(4096, 4096, 3)
        d = rgb_to_gray(img).astype(np.int16) - cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        assert np.abs(d).max() <= 1
        assert np.count_nonzero(d) < 0.002 * d.size

    def test_matches_opencv_uint16_and_float32(self, rng):
        u16 = rng.integers(0, 65536, (200, 300, 3)).astype(np.uint16)
        ref = cv2.cvtColor(u16, cv2.COLOR_RGB2GRAY).astype(int)
        # the same 14-bit weights times 65535: at most 1.6 levels off, so 2 after rounding
        assert np.abs(rgb_to_gray(u16).astype(int) - ref).max() <= 2
        f32 = rng.random((200, 300, 3), dtype=np.float32)
        # float32 weights in both; OpenCV's SIMD order of the sum differs in the last bit
        eps = np.spacing(np.float32(1.0))
        np.testing.assert_allclose(
            rgb_to_gray(f32), cv2.cvtColor(f32, cv2.COLOR_RGB2GRAY), atol=2 * eps
        )

    @pytest.mark.parametrize(
        "call, match",
        [
            (lambda: rgb_to_gray(np.zeros((4, 4, 3), np.uint8), dtype=np.uint8), "dtype must be"),
            (lambda: rgb_to_gray(np.zeros((4, 4, 3)), dtype="no such type"), "dtype must be"),
            (lambda: rgb_to_gray(np.zeros((4, 4, 4), np.uint8)), "RGBA"),
            (lambda: rgb_to_gray(np.zeros((3, 8, 9), np.uint8)), "channels-first"),
            (lambda: rgb_to_gray(np.full((4, 4, 3), np.nan)), "finite"),
            (lambda: rgb_to_gray(np.zeros((4, 4, 3), np.int64)), "dtype"),
        ],
    )
    def test_bad_input(self, call, match):
        with pytest.raises(InputError, match=match):
            call()


class TestRgbToHsvPixel:
    def test_hand_cases_and_opencv_parity(self):
        # the compiled per-pixel core of rgb_to_hsv: bit for bit cv2.cvtColor on uint8
        from robopercept.imaging.color import rgb_to_hsv_pixel

        def hsv(r, g, b):
            return [int(x) for x in rgb_to_hsv_pixel(np.int32(r), np.int32(g), np.int32(b))]

        assert hsv(0, 255, 0) == [60, 255, 255]  # green: 120 degrees, halved
        assert hsv(0, 0, 0) == [0, 0, 0]
        assert hsv(255, 0, 128) == [165, 255, 255]  # hue wraps: 330 degrees
        rng = np.random.default_rng(0)
        rgb = rng.integers(0, 256, (1, 300, 3), dtype=np.uint8)
        ref = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)[0]
        ours = [rgb_to_hsv_pixel(*(np.int32(c) for c in p)) for p in rgb[0]]
        np.testing.assert_array_equal(np.array(ours), ref)


def test_gray_255_scales_floats_only_and_refuses_other_dtypes():
    from robopercept.imaging import gray_255, rgb_to_gray

    rgb8 = np.array([[[255, 0, 0], [10, 20, 30]]], np.uint8)
    np.testing.assert_array_equal(gray_255(rgb8), rgb_to_gray(rgb8, dtype=np.float32))
    assert gray_255(rgb8).dtype == np.float32 and gray_255(rgb8).flags.c_contiguous
    f = rgb8.astype(np.float32) / 255
    np.testing.assert_allclose(gray_255(f), rgb_to_gray(rgb8, dtype=np.float32), rtol=1e-6)
    np.testing.assert_array_equal(gray_255(np.array([[0.0, 1.0]])), [[0.0, 255.0]])
    with pytest.raises(InputError, match="left must be uint8 or float"):
        gray_255(np.zeros((2, 2), np.uint16), "left")


# issue 25: bounds are three finite real numbers ------------------------------------------
@pytest.mark.parametrize(
    ("low", "match"),
    [
        ((10.0, [1, 2], 20.0), "low must be 3 finite real numbers"),  # was ValueError
        ((0, np.nan, 0), "low must be 3 finite real numbers"),
        (("0", "0", "0"), "low must be 3 finite real numbers"),
        (None, "low must be 3 finite real numbers"),
        ((True, 0, 0), "low must be 3 finite real numbers"),
    ],
)
def test_issue25_hsv_bounds_are_checked(low, match):
    with pytest.raises(InputError, match=match):
        hsv_range_mask(np.zeros((4, 4, 3)), low, (90, 255, 255))


def test_issue25_hsv_bounds_accept_arrays_and_numpy_numbers():
    hsv = np.zeros((2, 2, 3), np.uint8)
    hsv[0, 0] = (10, 100, 100)
    m = hsv_range_mask(hsv, np.array([5, 50, 50]), (np.int64(15), 255.0, np.float32(255)))
    np.testing.assert_array_equal(m, [[True, False], [False, False]])


@pytest.mark.parametrize("dtype", ["3", [1, 2], np.int16])
def test_issue25_rgb_to_gray_dtype_is_checked(dtype):
    with pytest.raises(InputError, match=r"dtype must be None, np\.float32 or np\.float64"):
        rgb_to_gray(np.zeros((2, 2, 3), np.uint8), dtype=dtype)
