"""HOG: hand-computed votes, parity with cv2.HOGDescriptor and skimage.feature.hog,
dense windows, properties, the picture, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage.feature import hog as sk_hog

from robopercept.errors import InputError
from robopercept.features import cell_histograms, hog, hog_windows
from robopercept.viz import hog_picture
from tests.conftest import data_path

# Tolerance against OpenCV: 1e-5, well inside the issue's 1e-3. Both sides use float32
# and the same polynomial atan2; what remains is the order of float32 sums (largest
# difference seen 7e-7). With the exact atan2 instead the difference would be ~7e-4.
CV_TOL = 1e-5
# Against skimage: float64 on both sides, the same arithmetic; 1e-6.
SK_TOL = 1e-6


def _cv_hog(win, block=(16, 16), stride=(8, 8), cell=(8, 8), nbins=9, **kw):
    # cv2 sizes are (width, height)
    return cv2.HOGDescriptor(win, block, stride, cell, nbins, **kw)


def _bgr(rgb: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb[..., ::-1])


def test_vertical_edge_votes_by_hand():
    # a vertical step: every gradient is horizontal (orientation 0), halfway between
    # the centres of bin 0 (10 deg) and bin 8 (170 deg), so OpenCV's linear split puts
    # half the magnitude in each; the step of 100 has magnitude 100 on the two columns
    # beside it ([-1 0 1] spans two pixels), 8 rows each -> mean 2 * 100 * 8 / 64 = 25
    img = np.zeros((8, 16), np.uint8)
    img[:, 8:] = 100
    h = cell_histograms(img, 8, 9)
    assert h.shape == (1, 2, 9)
    # column 7 is in cell 0 and column 8 in cell 1: one column of magnitude 100 each
    np.testing.assert_allclose(h[0, 0, [0, 8]], [100 * 8 / 64 / 2] * 2)
    np.testing.assert_allclose(h[0, 1, [0, 8]], [100 * 8 / 64 / 2] * 2)
    assert h[..., 1:8].sum() == 0
    # skimage's convention gives bin 0 the whole vote: the descriptor of a 1x2-cell
    # block with L1 norm is [1/2, 0...0, 1/2, 0...0] (two equal cells)
    d = hog(img, block_size=(1, 2), block_norm="L1", convention="skimage")
    expect = np.zeros(18)
    expect[[0, 9]] = 0.5
    np.testing.assert_allclose(d, expect, atol=1e-6)


def test_opencv_block_weights_by_hand():
    # one 16x16 block of 2x2 cells, a single vertical step at column 8 spanning all rows:
    # left/right symmetric, so the two cell columns get equal histograms, and the
    # top/bottom cells too; after L2-Hys every non-zero entry is equal
    img = np.zeros((16, 16), np.uint8)
    img[:, 8:] = 255
    d = hog(img, block_size=2)
    assert d.shape == (36,)
    nz = d[d > 0]
    assert nz.size == 8  # 4 cells x bins {0, 8}
    np.testing.assert_allclose(nz, nz[0], rtol=1e-6)


@pytest.mark.parametrize(
    ("win", "block", "stride", "cell", "nbins"),
    [
        ((64, 128), (16, 16), (8, 8), (8, 8), 9),  # the people-detector layout
        ((48, 96), (24, 24), (8, 8), (8, 8), 12),  # 3x3-cell blocks, 12 bins
        ((64, 64), (16, 16), (16, 16), (8, 8), 9),  # non-overlapping blocks
        ((60, 90), (20, 30), (10, 15), (10, 15), 6),  # rectangular cells
    ],
)
def test_parity_opencv_gray(camera, win, block, stride, cell, nbins):
    w, h = win
    img = np.ascontiguousarray(camera[150 : 150 + h, 200 : 200 + w])
    ref = _cv_hog(win, block, stride, cell, nbins).compute(img).ravel()
    ours = hog(
        img,
        orientations=nbins,
        cell_size=(cell[1], cell[0]),
        block_size=(block[1] // cell[1], block[0] // cell[0]),
        block_stride=(stride[1] // cell[1], stride[0] // cell[0]),
    )
    assert ours.dtype == np.float32 and ours.shape == ref.shape
    np.testing.assert_allclose(ours, ref, atol=CV_TOL)


def test_parity_opencv_colour_gamma_and_signed(astronaut):
    img = np.ascontiguousarray(astronaut[100:228, 200:264])
    ref = _cv_hog((64, 128)).compute(_bgr(img)).ravel()
    np.testing.assert_allclose(hog(img), ref, atol=CV_TOL)
    ref = cv2.HOGDescriptor(
        (64, 128), (16, 16), (8, 8), (8, 8), 9, 1, -1, 0, 0.2, True, 64, True
    ).compute(_bgr(img))
    np.testing.assert_allclose(hog(img, gamma=True, signed=True), ref.ravel(), atol=CV_TOL)
    # float input in [0, 1] gives the uint8 descriptor
    np.testing.assert_allclose(hog(img.astype(np.float32) / 255), hog(img), atol=1e-5)


@pytest.mark.realdata
def test_parity_opencv_dense_on_a_real_photo():
    from robopercept.imaging import read_image

    img = read_image(data_path("features", "opencv_box", "box_in_scene.png"), mode="gray")
    ref = _cv_hog((64, 128)).compute(img, winStride=(16, 8))
    ours = hog_windows(img, window=(64, 128), stride=(16, 8))
    ny, nx = (img.shape[0] - 128) // 8 + 1, (img.shape[1] - 64) // 16 + 1
    assert ours.shape == (ny, nx, 3780)
    np.testing.assert_allclose(ours.reshape(-1), ref.ravel(), atol=CV_TOL)


@pytest.mark.parametrize("norm", ["L2-Hys", "L2", "L1", "L1-sqrt"])
def test_parity_skimage_norms(camera, norm):
    ref = sk_hog(
        camera, orientations=9, pixels_per_cell=(8, 8), cells_per_block=(3, 3), block_norm=norm
    )
    ours = hog(camera, cell_size=8, block_size=3, block_norm=norm, convention="skimage")
    assert ours.shape == ref.shape
    np.testing.assert_allclose(ours, ref, atol=SK_TOL)


def test_parity_skimage_colour_sqrt_and_odd_sizes(astronaut, camera):
    ref = sk_hog(astronaut, channel_axis=-1)
    np.testing.assert_allclose(hog(astronaut, block_size=3, convention="skimage"), ref, atol=SK_TOL)
    crop = camera[:70, :93]  # not a whole number of cells: the remainder is ignored
    ref = sk_hog(
        crop, orientations=7, pixels_per_cell=(6, 9), cells_per_block=(2, 3), transform_sqrt=True
    )
    ours = hog(
        crop, orientations=7, cell_size=(6, 9), block_size=(2, 3), gamma=True, convention="skimage"
    )
    np.testing.assert_allclose(ours, ref, atol=SK_TOL)


def test_brightness_offset_and_contrast(camera):
    # gradients ignore an added constant exactly; the block normalization removes a
    # contrast gain up to its epsilon
    img = camera.astype(np.float64) / 255 * 0.5
    base = hog(img, convention="skimage", block_norm="L2")
    np.testing.assert_allclose(
        hog(img + 0.25, convention="skimage", block_norm="L2"), base, atol=1e-9
    )
    np.testing.assert_allclose(
        hog(img * 1.8, convention="skimage", block_norm="L2"), base, atol=1e-4
    )


def test_dense_windows_equal_single_windows(camera):
    # a window sees the whole image's gradient: the top-left window equals hog() of a
    # crop one pixel larger (so the window's right/bottom gradients see the same
    # neighbours; the extra row/column fills no block)
    dense = hog_windows(camera, window=(48, 64), stride=16)
    single = hog(np.ascontiguousarray(camera[:65, :49]))  # one extra row/col: same blocks
    np.testing.assert_allclose(dense[0, 0], single, atol=1e-6)


def test_people_detector_weights_fit_the_layout():
    # OpenCV's trained people detector is a linear SVM over this exact layout
    w = cv2.HOGDescriptor_getDefaultPeopleDetector().ravel()
    assert w.shape[0] == hog(np.zeros((128, 64), np.uint8)).shape[0] + 1


def test_hog_picture(camera):
    h = cell_histograms(camera, 8)
    pic = hog_picture(h, 8, scale=2)
    assert pic.shape == (1024, 1024, 3) and pic.dtype == np.uint8
    assert pic.max() == 255 and (pic > 0).mean() > 0.05
    # a single horizontal gradient draws a vertical line through the cell centre
    one = np.zeros((1, 1, 9))
    one[0, 0, 0] = 1.0
    pic = hog_picture(one, 16, scale=1)[..., 0]
    cols = np.nonzero(pic.sum(axis=0))[0]
    rows = np.nonzero(pic.sum(axis=1))[0]
    assert cols.max() - cols.min() <= 4 and rows.max() - rows.min() >= 12
    assert hog_picture(np.zeros((2, 3, 9)), 4).max() == 0


def test_bad_input():
    with pytest.raises(InputError, match="at least 16x16"):
        hog(np.zeros((12, 40), np.uint8))
    with pytest.raises(InputError, match="smaller than one 8x8 cell"):
        cell_histograms(np.zeros((5, 5), np.uint8))
    with pytest.raises(InputError, match="smaller than the 128x64 window"):
        hog_windows(np.zeros((100, 100), np.uint8))
    with pytest.raises(InputError, match="multiple of the block stride"):
        hog_windows(np.zeros((200, 200), np.uint8), stride=12)
    with pytest.raises(InputError, match="block size 16 plus a multiple"):
        hog_windows(np.zeros((200, 200), np.uint8), window=(64, 100))
    with pytest.raises(InputError, match="block_norm"):
        hog(np.zeros((32, 32), np.uint8), block_norm="L3")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="convention='opencv' only"):
        hog(np.zeros((32, 32), np.uint8), convention="skimage", signed=True)
    with pytest.raises(InputError, match="channels-first"):
        hog(np.zeros((3, 64, 64), np.uint8))


# issue 25: images near 1e300 (and from 1e17 on, in the float32 block norms) gave NaN
# descriptors silently; refused with a typed error. Within the limit HOG is scale
# invariant (up to the epsilon of the block norm)
def test_hog_refuses_values_that_overflow_the_block_norms():
    img = np.random.default_rng(0).random((128, 64))
    for call in (hog, hog_windows, cell_histograms):
        with pytest.raises(InputError, match="rescale your data"):
            call(img * 1e300)
    # (at 1e6 and 1e12 the block norm's epsilon is negligible; float32 rounding: 1e-5)
    np.testing.assert_allclose(hog(img * 1e12), hog(img * 1e6), atol=1e-5)
    assert np.isfinite(hog(img * 1e-300)).all()


# issue 25: orientations=2**31 + 1 allocated 768 GiB; the number of bins is now bounded
@pytest.mark.parametrize("call", [cell_histograms, hog])
def test_issue25_orientations_are_bounded(call):
    img = np.zeros((32, 32), np.uint8)
    with pytest.raises(InputError, match="orientations must be at most 360 bins"):
        call(img, orientations=2**31 + 1)
    with pytest.raises(InputError, match="orientations must be an integer"):
        call(img, orientations=9.5)
    assert cell_histograms(img, 8, orientations=360).shape == (4, 4, 360)


def test_issue25_block_sigma_and_flags_are_checked():
    # block_sigma=[1, 2] raised TypeError from float(); a block_sigma whose square
    # underflows (1e-162) gave 0 / 0 = NaN weights at the block centre
    img = np.zeros((64, 32), np.uint8)
    img[:, 16:] = 200
    for bad, match in (([1, 2], "block_sigma must be a real number"), (-1.0, "block_sigma")):
        with pytest.raises(InputError, match=match):
            hog_windows(img, block_sigma=bad)
    with pytest.raises(InputError, match="signed must be True or False"):
        hog(img, signed="yes")
    tiny = hog(img, block_sigma=1e-162)
    assert np.isfinite(tiny).all() and tiny.any()
    # a large block_sigma is the flat window, as block_sigma=0 (no weighting)
    np.testing.assert_allclose(hog(img, block_sigma=1e12), hog(img, block_sigma=0.0), atol=1e-6)


def test_issue25_sizes_are_bounded():
    # block_stride=2**63 overflowed the int64 grid arithmetic (OverflowError)
    img = np.zeros((64, 32), np.uint8)
    with pytest.raises(InputError, match="block_stride must be at most 65536"):
        hog(img, block_stride=2**63)
    with pytest.raises(InputError, match=r"cell_size\[1\] must be at most 65536"):
        hog(img, cell_size=(8, 2**40))
