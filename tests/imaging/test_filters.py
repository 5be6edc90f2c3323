"""Filters: hand-computed impulses, parity with OpenCV/SciPy, properties, bad input."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest
from scipy import ndimage

import robopercept.imaging as _im
from robopercept.errors import InputError
from robopercept.imaging import (
    box_filter,
    convolve,
    convolve_separable,
    correlate,
    correlate_separable,
    derivative_kernel,
    gaussian_blur,
    gaussian_kernel,
    gaussian_ksize,
    gradient,
    laplacian,
    laplacian_of_gaussian,
    median_filter,
    sobel,
)
from robopercept.imaging.filters import (
    MAX_KERNEL_SIZE,
    border_indices,
    gaussian_kernel_fixed,
    separable_filter_unchecked,
)

CV_BORDER = {
    "reflect101": cv2.BORDER_REFLECT_101,
    "reflect": cv2.BORDER_REFLECT,
    "replicate": cv2.BORDER_REPLICATE,
    "constant": cv2.BORDER_CONSTANT,
}


def impulse(h: int = 9, w: int = 9, dtype=np.float64) -> np.ndarray:
    img = np.zeros((h, w), dtype=dtype)
    img[h // 2, w // 2] = 1
    return img


# ----------------------------------------------------------------- hand-computed
def test_border_indices_hand():
    # abcd with 3 padded each side
    assert border_indices(4, 3, 3, "reflect101").tolist() == [3, 2, 1, 0, 1, 2, 3, 2, 1, 0]
    assert border_indices(4, 3, 3, "reflect").tolist() == [2, 1, 0, 0, 1, 2, 3, 3, 2, 1]
    assert border_indices(4, 2, 2, "replicate").tolist() == [0, 0, 0, 1, 2, 3, 3, 3]
    assert border_indices(4, 1, 1, "constant").tolist() == [-1, 0, 1, 2, 3, -1]
    # padding wider than the image still maps into range
    assert border_indices(2, 5, 5, "reflect101").min() >= 0


def test_correlate_impulse_gives_flipped_kernel_convolve_gives_kernel():
    k = np.arange(9, dtype=np.float64).reshape(3, 3)
    out_c = correlate(impulse(), k)
    out_v = convolve(impulse(), k)
    np.testing.assert_allclose(out_v[3:6, 3:6], k)
    np.testing.assert_allclose(out_c[3:6, 3:6], k[::-1, ::-1])
    assert out_c.sum() == pytest.approx(k.sum())


def test_gaussian_kernel_hand():
    k = gaussian_kernel(1.0, 3)
    e = np.exp(-0.5)
    np.testing.assert_allclose(k, [e / (1 + 2 * e), 1 / (1 + 2 * e), e / (1 + 2 * e)])
    # the default size is OpenCV's float rule round(8 sigma + 1) | 1 (+-4 sigma); it was
    # 2 ceil(3 sigma) + 1 = 13 before issue 22 aligned it with cv2.GaussianBlur on floats
    assert gaussian_kernel(2.0).size == 17
    np.testing.assert_allclose(gaussian_kernel(1.5, 9), cv2.getGaussianKernel(9, 1.5).ravel())


def test_gaussian_ksize_is_opencvs_rule_by_hand():
    # round(2 t sigma + 1) | 1, t = 3 for uint8 and 4 otherwise, worked by hand:
    # sigma 2: 8-bit round(13) | 1 = 13, float round(17) | 1 = 17
    assert gaussian_ksize(2.0, np.uint8) == 13 and gaussian_ksize(2.0, np.float32) == 17
    # sigma 1.5: round(10) | 1 = 11 (uint8), round(13) | 1 = 13 (float64, uint16)
    assert gaussian_ksize(1.5, np.uint8) == 11 and gaussian_ksize(1.5, np.float64) == 13
    assert gaussian_ksize(1.5, np.uint16) == 13
    # sigma 0.3: round(2.8) | 1 = 3 and round(3.4) | 1 = 3; sigma 0.5625 (float): 5.5 -> 7
    assert gaussian_ksize(0.3, np.uint8) == 3 and gaussian_ksize(0.3, np.float32) == 3
    assert gaussian_ksize(0.5625, np.float32) == 7


def test_gaussian_kernel_sigma_zero_hand_and_opencv():
    # sigma = 0: OpenCV's fixed binomial-like kernels up to 9 taps, then the sampled
    # Gaussian of sigma = 0.3 ((n - 1) / 2 - 1) + 0.8 (n = 11: sigma = 2.0)
    np.testing.assert_array_equal(gaussian_kernel(0, 3), [0.25, 0.5, 0.25])
    np.testing.assert_array_equal(gaussian_kernel(0, 5) * 16, [1, 4, 6, 4, 1])
    np.testing.assert_allclose(gaussian_kernel(0, 11), gaussian_kernel(2.0, 11), rtol=1e-15)
    for n in (1, 3, 5, 7, 9, 11, 15, 21):
        # equal to float64 rounding (OpenCV computes the same exp in double)
        np.testing.assert_allclose(
            gaussian_kernel(0, n), cv2.getGaussianKernel(n, 0).ravel(), rtol=0, atol=1e-15
        )


def test_gaussian_impulse_is_outer_product():
    k = gaussian_kernel(1.0, 5)
    out = gaussian_blur(impulse(), 1.0, ksize=5)
    np.testing.assert_allclose(out[2:7, 2:7], np.outer(k, k), atol=1e-15)


def test_sobel_impulse_and_ramp():
    out = sobel(impulse(), 1, 0)
    np.testing.assert_array_equal(out[3:6, 3:6], [[1, 0, -1], [2, 0, -2], [1, 0, -1]])
    ramp = np.tile(np.arange(10, dtype=np.float32) * 3, (6, 1))
    gx = sobel(ramp, 1, 0)
    np.testing.assert_allclose(gx[:, 1:-1], 8 * 3)  # 4 (smoothing) * 2 (central diff) * slope
    np.testing.assert_allclose(sobel(ramp, 0, 1), 0)


def test_derivative_kernels_match_opencv():
    for ksize in (1, 3, 5, 7):
        for order in range(0, 3):
            if ksize > 1 and order >= ksize:
                continue
            # OpenCV needs dx + dy > 0: read order 0 from the y kernel of (1, 0)
            ref = (
                cv2.getDerivKernels(order, 1, ksize)[0]
                if order
                else cv2.getDerivKernels(1, 0, ksize)[1]
            )
            np.testing.assert_array_equal(derivative_kernel(order, ksize), ref.ravel())


def test_laplacian_impulse():
    out = laplacian(impulse(), 1)
    np.testing.assert_array_equal(out[3:6, 3:6], [[0, 1, 0], [1, -4, 1], [0, 1, 0]])
    # a quadratic x^2 + y^2 has Laplacian 4 everywhere inside
    y, x = np.mgrid[0:12, 0:12].astype(np.float64)
    np.testing.assert_allclose(laplacian(x**2 + y**2)[1:-1, 1:-1], 4.0)


def test_box_and_median_hand():
    img = np.array([[1, 2, 3], [4, 5, 6], [7, 8, 9]], dtype=np.float64)
    assert box_filter(img, 3, border="constant")[1, 1] == pytest.approx(5.0)
    assert box_filter(img, 3, normalize=False, border="constant")[0, 0] == pytest.approx(12.0)
    speck = np.zeros((7, 7), np.uint8)
    speck[3, 3] = 255
    assert median_filter(speck, 3).max() == 0  # salt removed


def test_log_impulse_matches_formula():
    sigma = 1.5
    out = laplacian_of_gaussian(impulse(21, 21), sigma)
    r = int(4 * sigma + 0.5)
    x = np.arange(-r, r + 1)
    g = np.exp(-0.5 * x**2 / sigma**2)
    g /= g.sum()
    g2 = g * (x**2 / sigma**4 - 1 / sigma**2)
    expect = np.outer(g, g2) + np.outer(g2, g)
    np.testing.assert_allclose(out[10 - r : 11 + r, 10 - r : 11 + r], expect, atol=1e-15)


# ----------------------------------------------------------------- parity with OpenCV
@pytest.mark.parametrize("border", list(CV_BORDER))
def test_correlate_matches_filter2d(camera, astronaut, rng, border):
    kernel = rng.normal(size=(5, 7))
    for img in (camera, astronaut):
        f = img.astype(np.float32) / 255.0
        ours = correlate(f, kernel, border=border)
        ref = cv2.filter2D(f, -1, kernel, borderType=CV_BORDER[border])
        assert ours.dtype == np.float32
        # tolerance: float32 accumulation of 35 products of |values| <= ~3 (eps 6e-8)
        assert np.abs(ours - ref).max() <= 1e-5


def test_convolve_matches_filter2d_flipped(camera, rng):
    kernel = rng.normal(size=(3, 5))
    f = camera.astype(np.float32) / 255.0
    ref = cv2.filter2D(f, -1, cv2.flip(kernel, -1))
    assert np.abs(convolve(f, kernel) - ref).max() <= 1e-5
    np.testing.assert_allclose(
        convolve(f.astype(np.float64), kernel),
        ndimage.convolve(f.astype(np.float64), kernel, mode="mirror"),
        atol=1e-12,
    )


def test_separable_matches_sepfilter2d(astronaut, rng):
    kx, ky = rng.normal(size=7), rng.normal(size=5)
    f = astronaut.astype(np.float32) / 255.0
    ref = cv2.sepFilter2D(f, -1, kx, ky)
    assert np.abs(correlate_separable(f, kx, ky) - ref).max() <= 1e-5
    # separable == full 2-D kernel; convolve_separable == convolve with outer product
    np.testing.assert_allclose(
        correlate_separable(f, kx, ky), correlate(f, np.outer(ky, kx)), atol=1e-5
    )
    np.testing.assert_allclose(
        convolve_separable(f, kx, ky), convolve(f, np.outer(ky, kx)), atol=1e-5
    )


def test_gaussian_blur_matches_opencv(camera, astronaut, graf):
    for img in (camera, astronaut, graf):
        f = img.astype(np.float32) / 255.0
        ref = cv2.GaussianBlur(f, (9, 9), 1.7)
        assert np.abs(gaussian_blur(f, 1.7, ksize=9) - ref).max() <= 1e-6
        # uint8: OpenCV's 8-bit fixed-point kernel and integer sums, to the bit
        out8 = gaussian_blur(img, 1.7, ksize=9)
        assert out8.dtype == np.uint8
        np.testing.assert_array_equal(out8, cv2.GaussianBlur(img, (9, 9), 1.7))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("sigma", [2.0, 0.8, 1.3])
def test_gaussian_blur_default_size_matches_opencv_float(camera, astronaut, dtype, sigma):
    """gaussian_blur(f, sigma) == cv2.GaussianBlur(f, (0, 0), sigma): the same 4-sigma
    kernel size for float images. Tolerance: float rounding of the sums (both add
    mirrored taps first, in their own order), 1e-6 on [0, 1] float32 data (the largest
    seen: 2.4e-7); float64: 1e-12. The former 3-sigma kernel differed by ~1e-3 at sigma
    2, which these tolerances reject."""
    for img in (camera, astronaut):
        f = img.astype(dtype) / 255.0
        ours = gaussian_blur(f, sigma)
        ref = cv2.GaussianBlur(f, (0, 0), sigma)
        assert ours.dtype == dtype
        assert np.abs(ours - ref).max() <= (1e-6 if dtype == np.float32 else 1e-12)
    # anisotropic sigmas size each axis by its own sigma, as OpenCV
    f = camera.astype(dtype) / 255.0
    ref = cv2.GaussianBlur(f, (0, 0), sigma, sigmaY=2.5 * sigma)
    assert np.abs(gaussian_blur(f, sigma, sigma_y=2.5 * sigma) - ref).max() <= 1e-6


def test_gaussian_blur_default_size_matches_opencv_uint8(camera, astronaut):
    """uint8 keeps OpenCV's 3-sigma size (13 taps at sigma 2) and equals
    cv2.GaussianBlur to the bit (the same fixed-point kernel, integer sums)."""
    for img in (camera, astronaut):
        ours = gaussian_blur(img, 2.0)
        assert ours.dtype == np.uint8
        np.testing.assert_array_equal(ours, cv2.GaussianBlur(img, (0, 0), 2.0))
        np.testing.assert_array_equal(ours, gaussian_blur(img, 2.0, ksize=13))
    # (at 8 bits the 4-sigma kernel's extra taps round to 0: the size shows in the rule)
    assert gaussian_ksize(2.0, np.uint8) == 13 and gaussian_ksize(2.0, np.float32) == 17


@pytest.mark.parametrize("ksize", [3, 5, 7, 9, 11, (5, 9), (11, 3)])
def test_gaussian_blur_sigma_zero_takes_sigma_from_ksize(camera, ksize):
    """sigma=0 with a ksize: sigma = 0.3 ((ksize - 1) / 2 - 1) + 0.8 per axis (OpenCV's
    fixed kernels up to 9 taps), as cv2.GaussianBlur(f, ksize, 0). Same tolerances as
    above (float32 accumulation); 8-bit to the bit."""
    k = (ksize, ksize) if isinstance(ksize, int) else ksize
    f = camera.astype(np.float32) / 255.0
    assert np.abs(gaussian_blur(f, 0, ksize=ksize) - cv2.GaussianBlur(f, k, 0)).max() <= 1e-6
    f64 = f.astype(np.float64)
    ref = cv2.GaussianBlur(f64, k, 0)
    assert np.abs(gaussian_blur(f64, 0, ksize=ksize) - ref).max() <= 1e-12
    np.testing.assert_array_equal(
        gaussian_blur(camera, 0, ksize=ksize), cv2.GaussianBlur(camera, k, 0)
    )


@pytest.mark.parametrize("ksize", [1, 3, 5, 7])
@pytest.mark.parametrize(("dx", "dy"), [(1, 0), (0, 1), (1, 1), (2, 0)])
def test_sobel_matches_opencv(camera, graf, ksize, dx, dy):
    for img in (camera, graf):
        ours = sobel(img, dx, dy, ksize)
        ref = cv2.Sobel(img, cv2.CV_32F, dx, dy, ksize=ksize)
        # exact integer sums in float32 (uint8 input): identical
        np.testing.assert_array_equal(ours, ref)


@pytest.mark.parametrize("ksize", [1, 3, 5])
def test_laplacian_matches_opencv(camera, astronaut, ksize):
    for img in (camera, astronaut):
        ref = cv2.Laplacian(img, cv2.CV_32F, ksize=ksize)
        np.testing.assert_array_equal(laplacian(img, ksize), ref)


def test_box_and_median_match_opencv(astronaut, camera):
    np.testing.assert_allclose(
        box_filter(astronaut.astype(np.float32), (5, 3)),
        cv2.blur(astronaut.astype(np.float32), (5, 3)),
        atol=1e-4,
    )
    assert np.abs(box_filter(camera, 5).astype(int) - cv2.blur(camera, (5, 5))).max() <= 1
    for k in (3, 5):
        np.testing.assert_array_equal(median_filter(camera, k), cv2.medianBlur(camera, k))
        np.testing.assert_array_equal(median_filter(astronaut, k), cv2.medianBlur(astronaut, k))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_separable_sums_run_tap_by_tap_in_the_working_type(dtype) -> None:
    """The kernel adds the taps one at a time in the working type, in kernel order
    (four per pass over a row, the sum kept in a register: the same additions), so
    its interior equals NumPy's tap-by-tap sums bit for bit."""
    rng = np.random.default_rng(11)
    for kw, kh in ((1, 1), (3, 5), (4, 13), (9, 2), (13, 13)):
        image = rng.normal(size=(23, 37)).astype(dtype)
        kx, ky = rng.normal(size=kw).astype(dtype), rng.normal(size=kh).astype(dtype)
        ax, ay = kw // 2, kh // 2
        rows = image[border_indices(23, ay, kh - 1 - ay, "reflect101")]
        acc = ky[0] * rows[:23]
        for k in range(1, kh):
            acc = acc + ky[k] * rows[k : k + 23]
        cols = acc[:, border_indices(37, ax, kw - 1 - ax, "reflect101")]
        want = kx[0] * cols[:, :37]
        for k in range(1, kw):
            want = want + kx[k] * cols[:, k : k + 37]
        got = separable_filter_unchecked(image, kx, ky)
        inner = slice(ax, 37 - (kw - 1 - ax))  # the border pixels sum in float64
        np.testing.assert_array_equal(got[:, inner], want[:, inner])
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("border", ["reflect101", "reflect", "replicate", "constant"])
def test_uint8_box_in_integers_equals_the_float_path(border) -> None:
    """The integer window sums of uint8 means (odd windows up to BOX_INT_MAX) give the
    float32 separable path's output exactly: every odd (kw, kh), tiny and wide images,
    saturated and random pixels."""
    rng = np.random.default_rng(3)
    sizes = range(1, _im.filters.BOX_INT_MAX + 1, 2)
    for kw, kh in itertools.product(sizes, sizes):
        kx, ky = np.full(kw, 1.0 / kw), np.full(kh, 1.0 / kh)
        for shape in ((1, 1), (3, 2), (20, 17), (9, 31, 3)):
            for image in (
                rng.integers(0, 256, shape),
                np.full(shape, 255),
                rng.integers(250, 256, shape),
            ):
                image = image.astype(np.uint8)
                want = separable_filter_unchecked(image, kx, ky, border, 0.0, np.uint8)
                got = box_filter(image, (kw, kh), border=border)
                np.testing.assert_array_equal(got, want, err_msg=f"{kw}x{kh} {shape}")


def test_uint8_box_matches_opencv_exactly(astronaut, camera) -> None:
    for image in (camera, astronaut):
        for k in ((3, 3), (5, 5), (7, 3), (15, 15)):
            np.testing.assert_array_equal(box_filter(image, k), cv2.blur(image, k))


def test_log_matches_scipy(camera):
    f = camera.astype(np.float64)
    for sigma in (1.0, 2.5):
        np.testing.assert_allclose(
            laplacian_of_gaussian(f, sigma), ndimage.gaussian_laplace(f, sigma), atol=1e-9
        )


def test_gradient_direction_and_magnitude():
    y, x = np.mgrid[0:20, 0:20].astype(np.float64)
    mag, ang = gradient(x + y)  # gradient along (1, 1): 45 degrees, image-down positive
    np.testing.assert_allclose(ang[2:-2, 2:-2], np.pi / 4, atol=1e-12)
    np.testing.assert_allclose(mag[2:-2, 2:-2], 8 * np.sqrt(2), atol=1e-12)


# ----------------------------------------------------------------- properties
def test_linear_filters_are_linear_and_shift_equivariant(rng):
    a, b = rng.random((30, 40)), rng.random((30, 40))
    k = rng.normal(size=(3, 3))
    np.testing.assert_allclose(
        correlate(2 * a + 3 * b, k), 2 * correlate(a, k) + 3 * correlate(b, k), atol=1e-12
    )
    shifted = np.roll(a, (2, 3), axis=(0, 1))
    np.testing.assert_allclose(
        correlate(shifted, k)[5:-5, 5:-5],
        np.roll(correlate(a, k), (2, 3), axis=(0, 1))[5:-5, 5:-5],
        atol=1e-12,
    )


def test_gaussian_preserves_mean_and_dtype(astronaut):
    f = astronaut.astype(np.float32) / 255
    out = gaussian_blur(f, 2.0)
    assert out.dtype == np.float32 and out.shape == f.shape
    assert abs(out.mean() - f.mean()) < 2e-3
    assert gaussian_blur(f.astype(np.float64), 2.0).dtype == np.float64


def test_color_channels_filtered_independently(astronaut):
    f = astronaut.astype(np.float32)
    out = gaussian_blur(f, 1.2)
    for c in range(3):
        np.testing.assert_allclose(out[..., c], gaussian_blur(f[..., c].copy(), 1.2), atol=1e-4)


def test_tiny_images_all_borders():
    for shape in ((1, 1), (1, 5), (5, 1), (2, 2)):
        img = np.arange(np.prod(shape), dtype=np.float32).reshape(shape)
        for border in CV_BORDER:
            ours = correlate(img, np.ones((3, 3)), border=border)
            ref = cv2.filter2D(img, -1, np.ones((3, 3)), borderType=CV_BORDER[border])
            np.testing.assert_allclose(ours, ref, atol=1e-5)


# ----------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: correlate(np.zeros((3, 4, 5)), np.ones((3, 3))), r"\(H, W\) or \(H, W, 3\)"),
        (lambda: correlate(np.zeros((3, 64, 64)), np.ones((3, 3))), "channels-first"),
        (lambda: correlate(np.zeros((0, 4)), np.ones((3, 3))), "empty"),
        (lambda: correlate(np.full((4, 4), np.nan), np.ones((3, 3))), "finite"),
        (lambda: correlate(np.zeros((4, 4)), np.ones(3)), "2-D"),
        (lambda: correlate(np.zeros((4, 4)), np.ones((3, 3)), border="wrap"), "border must be"),
        (lambda: correlate(np.zeros((4, 4), np.complex64), np.ones((3, 3))), "dtype"),
        (lambda: gaussian_kernel(-1.0), r"sigma must be in \[0"),
        (lambda: gaussian_kernel(0.0), r"sigma=0 derives sigma from the kernel size"),
        (lambda: gaussian_kernel(1.0, 4), "odd"),
        (lambda: gaussian_blur(np.zeros((4, 4)), 0.0), r"sigma=0 needs the kernel width"),
        (
            lambda: gaussian_blur(np.zeros((4, 4)), 0.0, ksize=(3, 0)),
            "sigma=0 needs the kernel height",
        ),
        (lambda: gaussian_blur(np.zeros((4, 4)), 1.0, ksize=4), r"ksize must be an odd .* try 5"),
        (lambda: gaussian_blur(np.zeros((4, 4)), 1.0, ksize="5"), r"\(width, height\)"),
        (lambda: gaussian_blur(np.zeros((4, 4)), 1.0, sigma_y=-1.0), r"sigma_y must be in \[0"),
        (lambda: sobel(np.zeros((4, 4)), 0, 0), "dx \\+ dy"),
        (lambda: sobel(np.zeros((4, 4)), 1, 0, ksize=4), "ksize must be 1, 3, 5 or 7"),
        (lambda: median_filter(np.zeros((4, 4)), 2), "odd"),
        (lambda: box_filter(np.zeros((4, 4)), 0), "positive"),
        (lambda: laplacian_of_gaussian(np.zeros((4, 4)), 0), "sigma"),
        (lambda: correlate(np.zeros((4, 4)), np.ones((3, 3)), anchor=(5, 0)), "anchor"),
    ],
)
def test_bad_input_raises_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


class TestSeparableFilterUnchecked:
    """The unchecked separable engine that validated callers (SIFT, pyramids) use."""

    def test_impulse_hand(self):
        img = np.zeros((5, 5), np.float32)
        img[2, 2] = 1
        k = np.array([1.0, 2.0, 1.0]) / 4
        out = separable_filter_unchecked(img, k, k)
        np.testing.assert_array_equal(out[1:4, 1:4] * 16, [[1, 2, 1], [2, 4, 2], [1, 2, 1]])
        assert out.dtype == np.float32 and out.sum() == 1

    @pytest.mark.parametrize("shape", [(37, 41), (37, 41, 3), (20, 23, 4)])
    @pytest.mark.parametrize("dtype", [np.uint8, np.float32, np.float64])
    def test_equals_the_checked_filters(self, rng, shape, dtype):
        # bit-identical to the public filters it serves (they call it after checking);
        # 4 channels run the generic tap loop, 1 and 3 the stride-specialized ones
        img = (rng.random(shape) * (255 if dtype == np.uint8 else 1)).astype(dtype)
        g = gaussian_kernel(1.3, gaussian_ksize(1.3, dtype))  # gaussian_blur's size rule
        for border in ("reflect101", "reflect", "replicate", "constant"):
            blur = separable_filter_unchecked(img, g, g, border)
            if (len(shape) == 2 or shape[2] == 3) and dtype != np.uint8:
                # gaussian_blur adds mirrored taps before multiplying: float rounding
                tol = 1e-6 if dtype == np.float32 else 1e-13
                np.testing.assert_allclose(blur, gaussian_blur(img, 1.3, border=border), atol=tol)
            kx, ky = np.array([1.0, -2.0, 0.5, 3.0]), np.array([0.25, 1.0, -1.0])
            out = np.float32 if dtype == np.uint8 else dtype
            res = separable_filter_unchecked(img, kx, ky, border, 7.0, out, 1, 2)
            assert res.dtype == out
            if len(shape) == 2 or shape[2] == 3:
                ref = correlate(img, np.outer(ky, kx), border=border, cval=7.0, anchor=(1, 2))
                np.testing.assert_allclose(res, ref, rtol=1e-5, atol=1e-3)
            else:  # channel by channel equals the gray result
                for c in range(shape[2]):
                    one = np.ascontiguousarray(img[..., c])
                    np.testing.assert_array_equal(
                        res[..., c], separable_filter_unchecked(one, kx, ky, border, 7.0, out, 1, 2)
                    )

    def test_does_not_validate(self):
        # documented: no input checks (NaN goes through), unlike the public filters
        img = np.full((6, 6), np.nan)
        assert np.isnan(separable_filter_unchecked(img, np.ones(3), np.ones(3))).all()
        with pytest.raises(InputError, match="finite"):
            gaussian_blur(img, 1.0)


# issue 25: scalar parameters are checked for type, finiteness and size -----------------
_IMG = np.random.default_rng(25).uniform(0, 1, (24, 32)).astype(np.float32)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        # sigma = 2**40 asked for a 48 TiB kernel; near 1e308 the size overflowed to inf
        (lambda: _im.gaussian_blur(_IMG, 2**40), r"at most 65535.*downsampled"),
        (lambda: _im.gaussian_ksize(1e308), r"sigma=1e\+308.*at most 65535"),
        (lambda: _im.gaussian_kernel(1.5, 2**63 + 1), r"size asks for a kernel of"),
        (lambda: _im.gaussian_blur(_IMG, np.nan), r"sigma must be finite"),
        # issue 48: a pair as the second argument is OpenCV's ksize (was: a bad sigma)
        (lambda: _im.gaussian_blur(_IMG, [1, 2]), r"ksize must be an odd integer"),
        (lambda: _im.gaussian_blur(_IMG, [1.5, 2]), r"OpenCV's order image, ksize, sigmaX"),
        (lambda: _im.gaussian_blur(_IMG, "1"), r"sigma must be a real number"),
        (lambda: _im.gaussian_blur(_IMG, 1.0, sigma_y="3"), r"sigma_y must be a real number"),
        (lambda: _im.gaussian_blur(_IMG, 1.0, ksize=(3, 1.5)), r"\(width, height\) of ints"),
        (lambda: _im.gaussian_blur(_IMG, 1.0, ksize=(np.inf, 3)), r"\(width, height\) of ints"),
        (lambda: _im.gaussian_blur(_IMG, 1.0, ksize=2**40 + 1), r"at most 65535"),
        (lambda: _im.box_filter(_IMG, 2**40), r"ksize \(width\) asks for a kernel"),
        (lambda: _im.box_filter(_IMG, 3, normalize="yes"), r"normalize must be True or False"),
        (lambda: _im.median_filter(_IMG, 2**40 + 1), r"\[3, 31\].*downsampled"),
        # order=[1, 2] raised TypeError; ksize=2**63 hung in repeated np.convolve
        (lambda: _im.derivative_kernel([1, 2], 3), r"order must be an integer"),
        (lambda: _im.derivative_kernel(1, 2**63), r"ksize must be 1, 3, 5 or 7"),
        (lambda: _im.derivative_kernel(1, 3.0), r"ksize must be 1, 3, 5 or 7"),
        (lambda: _im.sobel(_IMG, 1, 0, scale="3"), r"scale must be a real number"),
        (lambda: _im.laplacian(_IMG, scale=np.nan), r"scale must be finite"),
        (lambda: _im.correlate(_IMG, np.ones((3, 3)), cval=None), r"cval must be a real"),
        (lambda: _im.correlate(_IMG, np.ones((3, 3)), anchor=(np.nan, 1)), r"anchor a_x"),
        (lambda: _im.correlate(_IMG, np.ones((3, 3)), anchor=7), r"anchor must be \(a_x, a_y\)"),
        (lambda: _im.correlate(_IMG, np.ones((3, 3)), anchor=(0, 3)), r"anchor a_y must be in"),
        # 1e-162: sigma^4 underflowed to 0 and the LoG was all NaN
        (lambda: _im.laplacian_of_gaussian(_IMG, 1e-162), r"normalized=True"),
        (lambda: _im.laplacian_of_gaussian(_IMG, 1e150, truncate=1e300), r"at most 65535"),
        (lambda: _im.laplacian_of_gaussian(_IMG, 1.0, normalized=2), r"normalized must be"),
    ],
)
def test_issue25_filter_scalars_are_refused_with_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_tiny_sigma_is_the_identity_not_nan():
    """sigma <= 1e-162 returned an all-NaN image (sigma**2 underflowed to 0, 0/0 at the
    centre); the limit of a shrinking Gaussian is the impulse, i.e. the identity."""
    for sigma in (1e-162, 1e-300, 5e-324):
        k = _im.gaussian_kernel(sigma, 5)
        np.testing.assert_array_equal(k, [0.0, 0.0, 1.0, 0.0, 0.0])
        out = _im.gaussian_blur(_IMG, sigma)
        np.testing.assert_array_equal(out, _IMG)
        np.testing.assert_array_equal(_im.gaussian_blur(_IMG, sigma, ksize=7), _IMG)
    # the normalized LoG of a tiny sigma is -2 f (kernel radius 0: sigma^2 G'' = -G)
    log = _im.laplacian_of_gaussian(_IMG, 1e-162, normalized=True)
    np.testing.assert_allclose(log, -2.0 * _IMG, rtol=1e-6)
    # just above the unnormalized floor: -2 f / sigma^2, finite
    small = _im.laplacian_of_gaussian(_IMG.astype(np.float64), 1e-15)
    assert np.isfinite(small).all()
    np.testing.assert_allclose(small, -2e30 * _IMG, rtol=1e-6)


def test_issue25_limits_still_work_at_their_edge():
    """The largest sigma that gaussian_ksize takes gives the longest kernel, and the
    size limits themselves are accepted."""
    assert _im.gaussian_ksize(8191.75) == MAX_KERNEL_SIZE
    assert _im.gaussian_kernel(0.5, MAX_KERNEL_SIZE).size == MAX_KERNEL_SIZE
    out = _im.median_filter(_IMG[:8, :8], 31)
    assert out.shape == (8, 8)
    np.testing.assert_allclose(_im.derivative_kernel(np.int64(2), 5), [1, 0, -2, 0, 1])
    # an anchor given as NumPy ints still works, and the default anchor equals the centre
    a = _im.correlate(_IMG, np.ones((3, 3)), anchor=(np.int64(1), np.int64(1)))
    np.testing.assert_array_equal(a, _im.correlate(_IMG, np.ones((3, 3))))


# issue 48: OpenCV's call shape gaussian_blur(img, (kw, kh), sigmaX)
@pytest.mark.parametrize(
    ("ksize", "sigma_x"), [((5, 5), 0), ((9, 9), 1.7), ((5, 9), 0), ((7, 3), 1.2)]
)
def test_gaussian_blur_opencv_positional_order_matches_opencv(camera, ksize, sigma_x):
    """gaussian_blur(img, ksize, sigmaX) == cv2.GaussianBlur(img, ksize, sigmaX), the
    tolerances of the tests above (float32 accumulation, 1e-6 on [0, 1] data; one grey
    level and < 10% off-by-one for uint8), and the same array as our keyword form."""
    f = camera.astype(np.float32) / 255.0
    ours = gaussian_blur(f, ksize, sigma_x)
    assert np.abs(ours - cv2.GaussianBlur(f, ksize, sigma_x)).max() <= 1e-6
    np.testing.assert_array_equal(ours, gaussian_blur(f, sigma_x, ksize=ksize))
    np.testing.assert_array_equal(ours, gaussian_blur(f, ksize=ksize, sigmaX=sigma_x))
    out8 = gaussian_blur(camera, ksize, sigma_x)
    diff = np.abs(out8.astype(int) - cv2.GaussianBlur(camera, ksize, sigma_x))
    assert out8.dtype == np.uint8 and diff.max() <= 1 and diff.mean() < 0.1


def test_gaussian_blur_opencv_forms_sigma_y_and_defaults(camera):
    f = camera.astype(np.float64) / 255.0
    ref = cv2.GaussianBlur(f, (7, 11), 1.1, sigmaY=2.3)
    for ours in (
        gaussian_blur(f, (7, 11), 1.1, sigmaY=2.3),
        gaussian_blur(f, (7, 11), 1.1, sigma_y=2.3),
        gaussian_blur(f, [7, 11], sigmaX=1.1, sigmaY=2.3),
        gaussian_blur(f, np.array([7, 11]), 1.1, sigmaY=2.3),
    ):
        assert np.abs(ours - ref).max() <= 1e-12
    # sigmaX left out: 0, taken from the size (OpenCV requires it; 0 is its usual value)
    np.testing.assert_array_equal(gaussian_blur(f, (5, 5)), gaussian_blur(f, (5, 5), 0))
    # our own forms are unchanged
    np.testing.assert_array_equal(gaussian_blur(f, 1.5), gaussian_blur(f, sigma=1.5))
    np.testing.assert_array_equal(gaussian_blur(f, 1.5), gaussian_blur(f, sigmaX=1.5))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda f: gaussian_blur(f, 1.5, 2.0), "give sigma or its OpenCV spelling sigmaX"),
        (lambda f: gaussian_blur(f, sigma=1.5, sigmaX=1.5), "not both"),
        (lambda f: gaussian_blur(f, 1.0, sigma_y=1.0, sigmaY=2.0), "sigma_y or its OpenCV"),
        (lambda f: gaussian_blur(f, (5, 5), 0, ksize=5), "ksize given twice"),
        (lambda f: gaussian_blur(f), "needs sigma"),
        (lambda f: gaussian_blur(f, (5, 5, 5), 0), "ksize"),
        (lambda f: gaussian_blur(f, (4, 4), 0), "ksize must be an odd integer"),
        (lambda f: gaussian_blur(f, (5, 5), -1.0), "sigma must be"),
    ],
)
def test_gaussian_blur_both_spellings_and_bad_opencv_forms_are_input_errors(call, match):
    with pytest.raises(InputError, match=match):
        call(np.zeros((16, 16), np.float32))


def _float_path(image, kx, ky, border, cval, ax=None, ay=None):
    # the float32 separable kernel on its own, as before the integer path
    work = np.dtype(np.float32)
    src, channels, ax, cidx, ridx, out, is_int, lo, hi = _im.filters._plan(
        image, kx.size, ky.size, ax, ay, border, work
    )
    _im.filters._separable_kernel(
        src, kx.astype(work), ky.astype(work), ax, cidx, ridx, channels, work.type(cval), out,
        is_int, lo, hi,
    )  # fmt: skip
    return out.reshape(image.shape)


@pytest.mark.parametrize("border", ["reflect101", "reflect", "replicate", "constant"])
def test_uint8_integer_taps_equal_the_float_path(border) -> None:
    """uint8 images with integer taps (the derivatives) run in int16 and give the float32
    path's output to the bit: every partial sum is an integer exact in float32. Tiny,
    narrow and wide images, gray and RGB, saturated pixels, integer constants, anchors
    off centre, and taps whose sums reach INT_TAPS_MAX."""
    rng = np.random.default_rng(7)
    d = derivative_kernel
    pairs = [
        (d(1, 3), d(0, 3)),
        (d(0, 5), d(2, 5)),
        (np.array([1.0, -2.0, 1.0]), np.array([3.0, 0.0, 0.0, 1.0, -1.0])),
        (np.ones(7), np.ones(1)),
        (np.array([2.0]), np.array([-1.0, 1.0])),
        (np.full(2, 8.0), np.full(1, 8.0)),  # 128 = INT_TAPS_MAX: sums up to 32,640
    ]
    for (kx, ky), shape, cval in itertools.product(
        pairs, [(1, 1), (2, 3), (5, 4), (17, 23), (9, 31, 3), (3, 2, 3)], (0.0, 7.0, 255.0)
    ):
        assert np.abs(kx).sum() * np.abs(ky).sum() <= _im.filters.INT_TAPS_MAX
        for image in (rng.integers(0, 256, shape), np.full(shape, 255)):
            image = image.astype(np.uint8)
            for ax, ay in ((None, None), (0, ky.size - 1)):
                got = separable_filter_unchecked(image, kx, ky, border, cval, np.float32, ax, ay)
                want = _float_path(image, kx, ky, border, cval, ax, ay)
                np.testing.assert_array_equal(got, want, err_msg=f"{kx} {ky} {shape} {cval}")
    image = rng.integers(0, 256, (6, 5)).astype(np.uint8)
    # what the integer path does not take: fractional taps or constants, sums too large
    for kx, ky, cval in (
        (np.array([0.5, 1.0]), np.ones(3), 0.0),
        (np.ones(3), np.ones(3), 0.5),
        (np.full(3, 11.0), np.ones(4), 0.0),
    ):
        assert _im.filters._integer_taps(image, kx, ky, cval, np.dtype(np.float32)) is None


@pytest.mark.parametrize("border", ["reflect101", "reflect", "replicate", "constant"])
def test_uint8_gaussian_is_opencvs_to_the_bit(border) -> None:
    """uint8 blurs equal cv2.GaussianBlur exactly: sigmas from the fixed small kernels
    (sigma 0) to wide ones, automatic and given sizes, anisotropic sigmas, gray and RGB,
    images narrower and shorter than the kernel, a single row."""
    rng = np.random.default_rng(11)
    images = [
        rng.integers(0, 256, (37, 53)).astype(np.uint8),
        rng.integers(0, 256, (29, 41, 3)).astype(np.uint8),
        rng.integers(0, 256, (1, 17)).astype(np.uint8),
        rng.integers(0, 256, (6, 3, 3)).astype(np.uint8),
        np.full((9, 12), 255, np.uint8),
    ]
    cases = [(0.0, 3), (0.0, 9), (0.0, 11), (0.8, 0), (1.3, 0), (2.0, 13), (3.3, 21), (5.0, 0)]
    for (sigma, k), img in itertools.product(cases, images):
        ours = gaussian_blur(img, sigma, ksize=k or None, border=border)
        ref = cv2.GaussianBlur(img, (k, k), sigma, borderType=CV_BORDER[border])
        np.testing.assert_array_equal(ours, ref, err_msg=f"{sigma} {k} {img.shape}")
    img = images[1]
    ours = gaussian_blur(img, 1.0, sigma_y=2.5, border=border)
    ref = cv2.GaussianBlur(img, (0, 0), 1.0, sigmaY=2.5, borderType=CV_BORDER[border])
    np.testing.assert_array_equal(ours, ref)


def test_gaussian_kernel_fixed() -> None:
    # OpenCV's small kernels exactly; symmetric, summing to 2^bits, close to the float
    # kernel (error diffusion keeps each partial sum within half a unit)
    assert gaussian_kernel_fixed(0, 3).tolist() == [64, 128, 64]
    assert gaussian_kernel_fixed(0, 9).tolist() == [4, 13, 30, 51, 60, 51, 30, 13, 4]
    for sigma, n, bits in ((2.0, 13, 8), (0.7, 5, 8), (3.3, 21, 16), (0.0, 15, 8), (9.0, 7, 12)):
        k = gaussian_kernel_fixed(sigma, n, bits)
        assert k.sum() == 2**bits and (k == k[::-1]).all() and (k >= 0).all()
        w = gaussian_kernel(sigma, n) * 2**bits
        assert np.abs(np.cumsum(k - w)[: n // 2]).max() <= 0.5 + 1e-9
    assert gaussian_kernel_fixed(1e-300, 5).tolist() == [0, 0, 256, 0, 0]  # an impulse
    with pytest.raises(InputError, match="bits must be at most 32"):
        gaussian_kernel_fixed(1.0, 5, 40)
    with pytest.raises(InputError, match="odd"):
        gaussian_kernel_fixed(1.0, 4)
