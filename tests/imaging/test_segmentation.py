"""Felzenszwalb-Huttenlocher segmentation: hand cases, parity with scikit-image, errors."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.imaging import felzenszwalb, grid_edges

skseg = pytest.importorskip("skimage.segmentation")
skdata = pytest.importorskip("skimage.data")


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Contingency check: equal up to relabelling iff every (a, b) label pair that occurs
    is a bijection (as many distinct pairs as labels in a and in b)."""
    pairs = np.unique(np.stack([a.ravel(), b.ravel()], 1), axis=0)
    return len(pairs) == len(np.unique(a)) == len(np.unique(b))


class TestGridEdges:
    def test_hand_case(self):
        # 2x2: right (1-0, 3-2), down (2-0, 3-1), down-right (3-0), up-right (1-2)
        assert grid_edges((2, 2)).tolist() == [[1, 0], [3, 2], [2, 0], [3, 1], [3, 0], [1, 2]]

    def test_count(self):
        h, w = 5, 7
        assert len(grid_edges((h, w))) == h * (w - 1) + (h - 1) * w + 2 * (h - 1) * (w - 1)

    def test_bad_shape(self):
        with pytest.raises(InputError, match=r"shape must be a tuple \(H, W\)"):
            grid_edges([2, 2])  # type: ignore[arg-type]
        with pytest.raises(InputError, match="H must be >= 1"):
            grid_edges((0, 3))
        # issue 25 campaign: (4, 24256621) allocated 740 MiB before failing
        with pytest.raises(InputError, match=r"more than the 16777216 \(2\*\*24\)"):
            grid_edges((4, 24256621))


class TestFelzenszwalbHand:
    def test_two_halves(self):
        img = np.zeros((6, 8), np.uint8)
        img[:, 4:] = 200
        lab = felzenszwalb(img, scale=10, sigma=0, min_size=2)
        expected = np.zeros((6, 8), np.int64)
        expected[:, 4:] = 1
        np.testing.assert_array_equal(lab, expected)

    def test_flat_image_is_one_segment(self):
        assert (felzenszwalb(np.full((5, 5, 3), 7, np.uint8)) == 0).all()

    def test_zero_scale_zero_min_size_splits_every_edge(self):
        # tau = 0 and w = 0 on a flat image: no edge is strictly lighter than 0
        lab = felzenszwalb(np.zeros((3, 4)), scale=0, sigma=0, min_size=0)
        np.testing.assert_array_equal(lab.ravel(), np.arange(12))

    def test_min_size_merges_small_segments(self):
        img = np.zeros((10, 10), np.uint8)
        img[4:6, 4:6] = 255  # a 4-pixel bright square
        assert felzenszwalb(img, scale=1, sigma=0, min_size=1).max() == 1
        assert felzenszwalb(img, scale=1, sigma=0, min_size=5).max() == 0

    def test_labels_raster_order_and_dtype(self, astronaut):
        lab = felzenszwalb(astronaut[::4, ::4], scale=100)
        assert lab.dtype == np.int64 and lab.shape == (128, 128)
        _, first = np.unique(lab.ravel(), return_index=True)
        assert (np.diff(first) > 0).all()  # label l's first pixel comes before l+1's

    def test_larger_scale_fewer_segments(self, astronaut):
        img = astronaut[::4, ::4]
        counts = [felzenszwalb(img, scale=s).max() + 1 for s in (10, 100, 1000)]
        assert counts[0] > counts[1] > counts[2]


class TestFelzenszwalbParity:
    """Exact: same partition AND same labels as scikit-image 0.26 (no tolerance: the
    smoothing follows SciPy's kernel and pass order, each pass rounded to the image's
    dtype, and the edges are sorted by the same argsort, so ties go the same way)."""

    @pytest.mark.parametrize(
        ("name", "args"),
        [
            ("astronaut", (100.0, 0.8, 50)),  # full size, 512x512
            ("coffee", (300.0, 0.8, 100)),  # full size, 400x600
            ("astronaut", (1.0, 0.8, 20)),
            ("coffee", (50.0, 0.5, 10)),
        ],
    )
    def test_full_size_uint8(self, name, args):
        img = getattr(skdata, name)()
        if args[0] < 10:
            img = img[::2, ::2]  # thousands of segments: half size is enough
        ours = felzenszwalb(img, *args)
        ref = skseg.felzenszwalb(img, *args)
        assert same_partition(ours, ref)
        np.testing.assert_array_equal(ours, ref)

    def test_float32_and_gray(self):
        img = skdata.coffee()[::3, ::3]
        f32 = (img / 255.0).astype(np.float32)
        np.testing.assert_array_equal(felzenszwalb(f32, 50), skseg.felzenszwalb(f32, 50))
        gray = img.mean(axis=2) / 255.0
        ref = skseg.felzenszwalb(gray, 30, 1.0, 5, channel_axis=None)
        np.testing.assert_array_equal(felzenszwalb(gray, 30, 1.0, 5), ref)

    def test_uint16_scaled_like_img_as_float(self):
        img = skdata.astronaut()[::4, ::4].astype(np.uint16) * 257  # 0..65535, same picture
        np.testing.assert_array_equal(
            felzenszwalb(img, 80), felzenszwalb(skdata.astronaut()[::4, ::4], 80)
        )


class TestFelzenszwalbErrors:
    def test_tiny_sigma_is_no_smoothing(self):
        """Issue 25 campaign: sigma=1e-162 squared to 0 and divided by it; a sigma below
        1/8 has SciPy's one-tap kernel, the same result as sigma=0."""
        img = np.random.default_rng(1).random((12, 16, 3))
        ref = felzenszwalb(img, scale=5, sigma=0)
        for sigma in (1e-162, 1e-300, 0.1):
            np.testing.assert_array_equal(felzenszwalb(img, scale=5, sigma=sigma), ref)

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"scale": -1.0}, "scale"),
            ({"scale": float("nan")}, "scale"),
            ({"sigma": -0.5}, "sigma"),
            ({"sigma": 1e6}, "at most sigma=10000"),
            ({"min_size": 2.5}, "min_size must be an integer"),
            ({"min_size": -1}, "min_size must be >= 0"),
        ],
    )
    def test_bad_parameters(self, kwargs, match):
        with pytest.raises(InputError, match=match):
            felzenszwalb(np.zeros((4, 4)), **kwargs)

    def test_bad_image(self):
        with pytest.raises(InputError, match="channels-first"):
            felzenszwalb(np.zeros((3, 20, 20)))
        with pytest.raises(InputError, match="must not be empty"):
            felzenszwalb(np.zeros((0, 4)))
