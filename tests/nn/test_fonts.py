"""Tests of robopercept.nn.fonts: digits rendered from the system's TrueType fonts."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PIL")

from robopercept.errors import InputError
from robopercept.nn.fonts import find_fonts, render_digits

FONTS = find_fonts()
needs_fonts = pytest.mark.skipif(not FONTS, reason="no TrueType fonts on this system")


@pytest.fixture(scope="module")
def rendered() -> tuple[np.ndarray, np.ndarray]:
    """300 rendered digits, seed 0."""
    return render_digits(300, seed=0)


def test_shapes_dtypes_and_range(rendered):
    images, labels = rendered
    assert images.shape == (300, 1, 8, 8) and images.dtype == np.float32
    assert labels.shape == (300,) and labels.dtype == np.int64
    assert images.min() >= 0.0 and images.max() <= 1.0
    # block counts of a 32x32 bitmap in 4x4 blocks: multiples of 1/16, like sklearn's digits
    np.testing.assert_array_equal(images * 16, np.round(images * 16))


def test_labels_balanced_and_shuffled(rendered):
    _, labels = rendered
    np.testing.assert_array_equal(np.bincount(labels, minlength=10), np.full(10, 30))
    assert not np.array_equal(labels, np.tile(np.arange(10), 30))  # shuffled
    counts = np.bincount(render_digits(23, seed=1)[1], minlength=10)
    assert counts.max() - counts.min() <= 1  # n not a multiple of 10: off by one at most


def test_seeded_determinism():
    a = render_digits(40, seed=3)
    b = render_digits(40, seed=3)
    c = render_digits(40, seed=4)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0])


@needs_fonts
def test_no_blank_images_with_system_fonts(rendered):
    images, _ = rendered
    ink = images.reshape(len(images), -1).sum(axis=1)
    assert (ink > 0.5).all(), f"{int((ink <= 0.5).sum())} nearly blank images"


@needs_fonts
def test_find_fonts_skips_symbol_fonts():
    assert all(p.suffix.lower() in (".ttf", ".otf") for p in FONTS)
    assert not any("symbol" in p.name.lower() or "math" in p.name.lower() for p in FONTS)


def test_rendered_digits_look_like_the_real_ones():
    """A classifier trained only on rendered digits recognises real (UCI) digits far
    above chance (10%): the property the sim-to-real pretraining needs."""
    pytest.importorskip("sklearn")
    from sklearn.datasets import load_digits
    from sklearn.svm import SVC

    images, labels = render_digits(2000, seed=0)
    real = load_digits()
    clf = SVC(gamma="scale").fit(images.reshape(len(images), -1), labels)
    accuracy = (clf.predict(real.data / 16.0) == real.target).mean()
    assert accuracy >= 0.45, accuracy


def test_bad_n():
    with pytest.raises(InputError, match="n must be >= 1"):
        render_digits(0)
