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
        (lambda: hsv_range_mask(np.zeros((4, 4, 3)), (0, 0), (10, 5, 5)), "shape"),
        (lambda: hsv_range_mask(np.zeros((4, 4)), (0, 0, 0), (1, 1, 1)), "rgb_to_hsv"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
