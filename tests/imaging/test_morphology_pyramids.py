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


# issue 25: iterations and element sizes are checked; huge iteration counts end ----------
_MASK = (np.random.default_rng(25).uniform(0, 1, (12, 17)) > 0.6).astype(np.uint8) * 200


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: dilate(_MASK, iterations=[1, 2]), "iterations must be an integer"),
        (lambda: dilate(_MASK, iterations=-np.inf), "iterations must be an integer"),
        (lambda: erode(_MASK, iterations=np.nan), "iterations must be an integer"),
        (lambda: erode(_MASK, iterations=2.0), "iterations must be an integer"),
        (lambda: erode(_MASK, iterations=0), "iterations must be >= 1"),
        # 2**40 raised NumPy's "array is too big"; 109280 asked for 11 GiB
        (lambda: structuring_element("rect", 2**40), r"\[1, 4095\].*downsampled"),
        (lambda: structuring_element("ellipse", 109280), r"\[1, 4095\]"),
        (lambda: structuring_element("cross", (3, 0)), r"\[1, 4095\]"),
        (lambda: structuring_element("cross", (3,)), r"int or \(width, height\)"),
        (lambda: structuring_element("cross", (1.5, 3)), "size .width. must be an integer"),
        (lambda: structuring_element("cross", None), "size .width. must be an integer"),
        (lambda: gaussian_pyramid(_MASK, [1, 2]), "levels must be an integer"),
    ],
)
def test_issue25_bad_scalars_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def _passes(img, se, op, n):
    out = img
    for _ in range(n):
        out = op(out, se)
    return out


@pytest.mark.parametrize(
    "se",
    [
        None,  # holds its anchor: the result settles (a fixed point)
        np.array([[1, 0, 1]], bool),  # offsets -1, +1: the result alternates, period 2
        np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]], bool),  # period 3 on the lattice
    ],
)
@pytest.mark.parametrize("op", [erode, dilate])
def test_issue25_any_iteration_count_ends_and_equals_repeated_passes(se, op):
    """iterations=2**63 hung (one pass after another); each pass depends only on the
    previous result, so once a result repeats the rest is skipped exactly. Checked
    against the passes done one by one, around and beyond the period."""
    for n in (1, 2, 3, 17, 40, 41, 42, 43):
        np.testing.assert_array_equal(op(_MASK, se, iterations=n), _passes(_MASK, se, op, n))
    big = 2**63 + 5
    period_end = _passes(_MASK, se, op, 60 + (big - 60) % 6)  # 6: a multiple of 1, 2, 3
    np.testing.assert_array_equal(op(_MASK, se, iterations=big), period_end)


def test_issue25_element_limit_is_accepted():
    se = structuring_element("rect", (4095, 1))
    assert se.shape == (1, 4095) and se.all()
    np.testing.assert_array_equal(
        structuring_element("ellipse", (np.int64(5), 5)), structuring_element("ellipse", 5)
    )
