"""Segmentation pictures (issue 27): class colours equal the VOC palette blended at
alpha, the legend lists exactly the classes present and sits outside the image, small
images are enlarged by whole factors with labels kept exact, instance outlines and
captions, the empty-result note, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import voc_palette
from robopercept.viz.segmentation import class_overlay, instance_overlay, panels_picture


def _scene():
    img = np.full((32, 40, 3), 100, np.uint8)
    lab = np.zeros((32, 40), np.int64)
    lab[4:12, 4:20] = 1
    lab[20:30, 25:38] = 3
    return img, lab


def test_class_overlay_blends_the_voc_colour_and_keeps_the_background():
    img, lab = _scene()
    pic = class_overlay(img, lab, ["a", "b", "c"], alpha=0.5, min_side=80)
    f = 2  # 40 px enlarged by the whole factor 80 // 40
    assert pic.shape[0] >= 32 * f and pic.shape[1] > 40 * f  # the legend may be taller
    core = pic[: 32 * f, : 40 * f]
    for k in (1, 3):
        expect = np.round(0.5 * 100 + 0.5 * voc_palette()[k].astype(float))
        ys, xs = np.nonzero(np.repeat(np.repeat(lab == k, f, 0), f, 1))
        np.testing.assert_array_equal(core[ys, xs], np.broadcast_to(expect, (len(ys), 3)))
    assert (core[np.repeat(np.repeat(lab == 0, f, 0), f, 1)] == 100).all()


def test_class_overlay_legend_lists_the_present_classes_beside_the_image():
    img, lab = _scene()
    pic = class_overlay(img, lab, ["a", "b", "c"], min_side=320)
    panel = pic[:, 320:]
    pal = voc_palette()
    has = lambda k: bool((panel == pal[k]).all(-1).any())  # noqa: E731
    assert has(1) and has(3) and not has(2)  # class 2 is absent: not listed
    empty = class_overlay(img, np.zeros_like(lab), ["a"], min_side=320)
    assert (empty[:, 320:] < 128).any()  # the "nothing segmented" note is written


def test_class_overlay_void_pixels_and_refusals():
    img, lab = _scene()
    lab[0, 0] = 255
    pic = class_overlay(img, lab, ["a", "b", "c"], min_side=1)
    assert pic[0, 0].tolist() == voc_palette()[255].tolist()
    with pytest.raises(InputError, match=r"0\.\.2"):
        class_overlay(img, lab, ["a", "b"])
    with pytest.raises(InputError, match="image's shape"):
        class_overlay(img, lab[:-1], ["a", "b", "c"])
    with pytest.raises(InputError, match="integer"):
        class_overlay(img, lab.astype(float), ["a", "b", "c"])
    with pytest.raises(InputError, match="non-empty list"):
        class_overlay(img, lab, [])


def test_instance_overlay_outlines_each_instance_in_its_colour():
    img, lab = _scene()
    masks = np.stack([lab == 1, lab == 3])
    pic = instance_overlay(img, masks, min_side=1, alpha=0.0)
    # alpha 0: only the outlines change the image, on the border pixels of each mask
    changed = (pic != img).any(-1)
    for m in masks:
        inner = m.copy()
        inner[1:-1, 1:-1] &= m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]
        assert changed[m & ~inner].all() and not changed[inner].any()
    assert not changed[lab == 0].any()
    # a label image gives the same picture as its masks
    np.testing.assert_array_equal(instance_overlay(img, lab, min_side=1, alpha=0.0), pic)


def test_instance_overlay_captions_and_the_empty_note():
    img, lab = _scene()
    masks = np.stack([lab == 1, lab == 3])
    plain = instance_overlay(img, masks)
    named = instance_overlay(img, masks, labels=[1, 2], classes=["x", "y"], scores=[0.9, 0.4])
    # enlarged by the whole factor 512 // 40 = 12
    assert plain.shape == named.shape == (32 * 12, 40 * 12, 3)
    assert not np.array_equal(named, plain)  # the captions
    empty = instance_overlay(img, np.zeros((0, 32, 40), bool))
    assert (empty != np.repeat(np.repeat(img, 12, 0), 12, 1)).any()  # the note
    with pytest.raises(InputError, match="one entry per instance"):
        instance_overlay(img, masks, labels=[1])
    with pytest.raises(InputError, match="image's"):
        instance_overlay(img, np.zeros((1, 31, 40), bool))


def test_panels_picture_places_each_picture_under_its_title():
    a = np.full((40, 30, 3), 10, np.uint8)
    b = np.full((20, 50, 3), 200, np.uint8)
    pic = panels_picture([a, b], ["left", "right"], gap=5)
    assert pic.shape[1] == 30 + 5 + 50
    cap = pic.shape[0] - 40
    assert (pic[cap:, :30] == 10).all() and (pic[cap : cap + 20, 35:] == 200).all()
    assert (pic[cap + 20 :, 35:] == 255).all()  # the shorter one padded with white
    with pytest.raises(InputError, match="one title per picture"):
        panels_picture([a, b], ["only one"])
