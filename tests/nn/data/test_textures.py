"""Tests of robopercept.nn.data.textures: photo backgrounds and textured fills, seeded."""

from __future__ import annotations

import numpy as np
import pytest
import skimage.data
from skimage.transform import resize

from robopercept.errors import InputError
from robopercept.nn.data.textures import BACKGROUNDS, photo_background, random_texture


def test_photo_background_is_the_contrast_reduced_crop():
    # the tile is the recorded crop of the named photo, resized as scikit-image's
    # bilinear antialiased resize (edge mode) does, mapped to 0.2 + 0.6 I (float32 reading of the
    # photo: 1e-6)
    for seed in range(4):
        tile, info = photo_background(np.random.default_rng(seed), 40, 30)
        assert tile.shape == (30, 40, 3) and info["photo"] in BACKGROUNDS
        photo = np.asarray(getattr(skimage.data, info["photo"])())
        if photo.ndim == 2:
            photo = np.repeat(photo[..., None], 3, axis=2)
        photo = photo[..., :3].astype(np.float32) / np.float32(255)
        x, y, w, h = info["crop"]
        assert abs(w / h - 40 / 30) < 0.05 and w <= photo.shape[1] and h <= photo.shape[0]
        crop = photo[y : y + h, x : x + w]
        ref = resize(crop, (30, 40), order=1, mode="edge", anti_aliasing=True)
        np.testing.assert_allclose(tile, 0.2 + 0.6 * np.clip(ref, 0, 1), atol=1e-6)


def test_seeded_and_drawing_from_the_callers_generator():
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    ta, ia = photo_background(a, 16, 12)
    tb, ib = photo_background(b, 16, 12)
    np.testing.assert_array_equal(ta, tb)
    assert ia == ib
    np.testing.assert_array_equal(random_texture(a, 9, 7), random_texture(b, 9, 7))
    assert a.random() == b.random()  # the same number of draws


def test_random_texture_is_a_modulated_colour():
    # c (0.65 + 0.35 t) with t in [0, 1]: every pixel is a multiple of one colour, in
    # [0.65 c, c], one channel of c at most 0.3 (saturated)
    for seed in range(12):
        t = random_texture(np.random.default_rng(seed), 8, 6)
        assert t.shape == (6, 8, 3)
        c = t.max((0, 1)) / t.max((0, 1)).max()
        ratio = t / np.maximum(t[..., :1], 1e-12)
        np.testing.assert_allclose(ratio, np.broadcast_to(c / c[0], t.shape), rtol=1e-9)
        assert t.min() >= 0 and t.max() <= 1 and t.max((0, 1)).min() <= 0.3


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: photo_background(0, 8, 8), r"gen must be a numpy.random.Generator"),
        (lambda: random_texture(np.random.default_rng(0), 0, 8), r"\(w, h\)"),
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()
