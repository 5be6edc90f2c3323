"""Morphology and pyramids against OpenCV."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.imaging import (
    closing,
    dilate,
    erode,
    gaussian_pyramid,
    opening,
    pyr_down,
    structuring_element,
)


def test_hand_cases():
    img = np.zeros((7, 7), np.uint8)
    img[2:5, 2:5] = 1
    np.testing.assert_array_equal(np.argwhere(erode(img)), [[3, 3]])
    assert dilate(img).sum() == 25
    speck = img.copy()
    speck[0, 6] = 1
    np.testing.assert_array_equal(opening(speck), img)  # speck removed, square kept
    holed = np.ones((7, 7), np.uint8)
    holed[3, 3] = 0
    assert closing(holed)[3, 3] == 1


@pytest.mark.parametrize("shape", ["rect", "cross", "ellipse"])
@pytest.mark.parametrize("size", [3, 5, (7, 3)])
def test_match_opencv(camera, astronaut, shape, size):
    se = structuring_element(shape, size)
    cv_shape = {"rect": cv2.MORPH_RECT, "cross": cv2.MORPH_CROSS, "ellipse": cv2.MORPH_ELLIPSE}
    ref_se = cv2.getStructuringElement(
        cv_shape[shape], size if isinstance(size, tuple) else (size, size)
    )
    np.testing.assert_array_equal(se, ref_se.astype(bool))
    for img in (camera, astronaut):
        np.testing.assert_array_equal(erode(img, se), cv2.erode(img, ref_se))
        np.testing.assert_array_equal(dilate(img, se), cv2.dilate(img, ref_se))
        np.testing.assert_array_equal(
            opening(img, se), cv2.morphologyEx(img, cv2.MORPH_OPEN, ref_se)
        )
        np.testing.assert_array_equal(
            closing(img, se), cv2.morphologyEx(img, cv2.MORPH_CLOSE, ref_se)
        )


def test_bool_masks_and_iterations():
    m = np.zeros((9, 9), bool)
    m[4, 4] = True
    out = dilate(m, iterations=2)
    assert out.dtype == np.bool_ and out.sum() == 25


def test_pyramid_matches_pyrdown(camera, astronaut):
    for img in (camera, astronaut, astronaut[:101, :77]):
        np.testing.assert_array_equal(pyr_down(img), cv2.pyrDown(img))
        f = img.astype(np.float32) / 255
        np.testing.assert_allclose(pyr_down(f), cv2.pyrDown(f), atol=1e-6)
    levels = gaussian_pyramid(camera, 4)
    assert [lv.shape for lv in levels] == [(512, 512), (256, 256), (128, 128), (64, 64)]


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: structuring_element("disk", 3), "shape must be"),
        (lambda: erode(np.zeros((4, 4)), np.zeros((3, 3))), "nonzero"),
        (lambda: erode(np.zeros((4, 4)), iterations=0), "iterations"),
        (lambda: gaussian_pyramid(np.zeros((8, 8)), 5), "too many"),
        (lambda: gaussian_pyramid(np.zeros((8, 8)), 0), "levels"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_pyr_down_unchecked_is_pyr_down_without_the_checks():
    from robopercept.imaging.pyramids import pyr_down, pyr_down_unchecked

    img = np.random.default_rng(0).random((9, 12)).astype(np.float32)
    np.testing.assert_array_equal(pyr_down_unchecked(img), pyr_down(img))
    bad = img.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError):
        pyr_down(bad)
    assert np.isnan(pyr_down_unchecked(bad)[0, 0])  # no isfinite scan: NaN goes through
