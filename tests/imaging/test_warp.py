"""warp_perspective / transform_points: exact integer shifts, parity with
cv2.warpPerspective, round trips, bad input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.imaging import transform_points, warp_perspective

H = np.array([[0.9, 0.1, 20.0], [-0.05, 1.1, 10.0], [1e-4, 2e-4, 1.0]])


def test_integer_shift_is_exact(camera):
    t = np.array([[1.0, 0, 7], [0, 1.0, -3], [0, 0, 1]])
    size = camera.shape[::-1]  # dsize is (width, height); square here
    out = warp_perspective(camera, t, size)
    np.testing.assert_array_equal(out[:-3, 7:], camera[3:, :-7])  # (x, y) -> (x + 7, y - 3)
    assert (out[:, :7] == 0).all() and (out[-3:, :] == 0).all()
    np.testing.assert_array_equal(warp_perspective(camera, np.eye(3), size), camera)


def test_dsize_is_width_height_hand_case():
    """dsize = (width, height), as OpenCV: a 3-wide, 2-high input shifted one column
    right into a 5-wide, 2-high output; the hand-written result."""
    img = np.array([[1, 2, 3], [4, 5, 6]], np.uint8)
    t = np.array([[1.0, 0, 1], [0, 1.0, 0], [0, 0, 1]])
    out = warp_perspective(img, t, (5, 2))
    assert out.shape == (2, 5)
    np.testing.assert_array_equal(out, [[0, 1, 2, 3, 0], [0, 4, 5, 6, 0]])
    # keeping the input's size: image.shape[1::-1] is (width, height) for gray and RGB
    rgb = np.dstack([img] * 3)
    assert warp_perspective(rgb, np.eye(3), rgb.shape[1::-1]).shape == (2, 3, 3)


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_non_square_dsize_equals_opencv(astronaut, dtype):
    """A wide (w=333 > h=211) and a tall (w=150 < h=420) output: the same shape as
    cv2.warpPerspective with the same dsize, and the same pixels up to OpenCV's 1/32-px
    sample quantization (mean difference < 0.1 grey level; float32 on the 0-255 scale).
    A transposed size would differ in shape and in content."""
    img = astronaut.astype(dtype)
    for dsize in ((333, 211), (150, 420)):
        ours = warp_perspective(img, H, dsize)
        ref = cv2.warpPerspective(img, H, dsize)
        assert ours.shape == ref.shape == (dsize[1], dsize[0], 3)
        d = np.abs(ours.astype(np.float64) - ref.astype(np.float64))
        assert d.mean() < 0.1 and d.max() <= 5


def test_parity_with_opencv(astronaut):
    # OpenCV quantizes the sample position to 1/32 px (fixed-point tables), which moves
    # a bilinear value by up to a few grey levels at strong edges: mean difference
    # < 0.1 grey level, at most 5, and > 2 on under 0.1% of the values
    ours = warp_perspective(astronaut, H, (500, 400))
    ref = cv2.warpPerspective(astronaut, H, (500, 400))
    d = np.abs(ours.astype(int) - ref.astype(int))
    assert ours.shape == ref.shape and ours.dtype == np.uint8
    assert d.mean() < 0.1 and d.max() <= 5 and np.mean(d > 2) < 1e-3
    near = warp_perspective(astronaut, H, (500, 400), interpolation="nearest")
    ref = cv2.warpPerspective(astronaut, H, (500, 400), flags=cv2.INTER_NEAREST)
    assert np.mean(near != ref) < 1e-4  # only exact half-pixel ties differ
    f = warp_perspective(astronaut.astype(np.float32) / 255, H, (500, 400))
    assert f.dtype == np.float32
    assert np.abs(f * 255 - ours).max() <= 0.5 + 1e-3


def test_transform_points_round_trip(rng):
    xy = rng.uniform(0, 500, (50, 2))
    back = transform_points(np.linalg.inv(H), transform_points(H, xy))
    np.testing.assert_allclose(back, xy, atol=1e-9)
    np.testing.assert_allclose(
        transform_points(H, xy), cv2.perspectiveTransform(xy[None], H)[0], atol=1e-9
    )


def test_bad_input(camera):
    with pytest.raises(DegenerateError, match="singular"):
        warp_perspective(camera, np.zeros((3, 3)), (10, 10))
    with pytest.raises(InputError, match=r"dsize must be the output \(width, height\)"):
        warp_perspective(camera, np.eye(3), 10)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"dsize\[1\] \(height\) must be >= 1"):
        warp_perspective(camera, np.eye(3), (10, 0))
    with pytest.raises(InputError):
        warp_perspective(camera, np.eye(2), (10, 10))


def test_remap_equals_opencv_and_handles_outside():
    """remap samples like cv2.remap (bilinear, constant border): integer maps copy
    pixels exactly; fractional maps agree within OpenCV's 1/32-px quantization."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.imaging import remap

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (40, 50, 3), dtype=np.uint8)
    yy, xx = np.mgrid[0:30, 0:35].astype(np.float32)
    mx, my = xx * 1.3 + 2, yy * 1.2 + 1
    ours = remap(img, np.round(mx), np.round(my))
    ref = cv2.remap(img, np.round(mx), np.round(my), cv2.INTER_LINEAR)
    np.testing.assert_array_equal(ours, ref)
    ours = remap(img, mx + 0.25, my + 0.5).astype(int)
    ref = cv2.remap(img, mx + 0.25, my + 0.5, cv2.INTER_LINEAR).astype(int)
    # a 1/32-px position error on noise with 255-level steps: at most 255/32 levels
    assert np.abs(ours - ref).max() <= 8 and np.abs(ours - ref).mean() < 1.5
    out = remap(img[..., 0], np.full((2, 2), -5.0), np.full((2, 2), np.nan), border_value=7)
    np.testing.assert_array_equal(out, 7)
    with pytest.raises(InputError):
        remap(img, mx, my[:5])


# issue 25: homographies at any scale, output sizes bounded, points checked ---------------
@pytest.mark.parametrize(
    ("call", "error", "match"),
    [
        # a (3, 3) array of points raised NumPy's "cannot reshape array of size 9"
        (lambda: transform_points(H, np.ones((3, 3))), InputError, r"xy must have shape \(N, 2\)"),
        (lambda: transform_points(H, [[1, 2], [3]]), InputError, "xy must be"),
        (lambda: transform_points(np.full((3, 3), np.nan), [[1, 2]]), InputError, "finite"),
        (lambda: transform_points(np.zeros((3, 3)), [[1, 2]]), DegenerateError, "all zeros"),
        (lambda: transform_points(np.eye(3).astype(object), [[1, 2]]), InputError, "H must"),
        (
            lambda: warp_perspective(np.zeros((4, 4)), np.eye(3), (2**40, 2**40)),
            InputError,
            r"at most 134217728",
        ),
        (lambda: warp_perspective(np.zeros((4, 4)), np.eye(3), 7), InputError, "dsize must"),
        (
            lambda: warp_perspective(np.zeros((4, 4)), np.eye(3), (4, 4), border_value=None),
            InputError,
            "border_value must be a real",
        ),
    ],
)
def test_issue25_bad_arguments(call, error, match):
    with pytest.raises(error, match=match):
        call()


def test_issue25_homography_scale_does_not_matter():
    """H and 1e300 H (or 1e-300 H) are the same homography: the result is the same,
    where the products of 1e300 entries overflowed to inf/NaN and the singularity test
    (det <= 1e-12 max|H|^3, inf <= inf) called a valid 1e300 H singular."""
    pts = np.array([[0.0, 0.0], [10.0, 5.0], [63.0, 47.0]])
    ref = transform_points(H, pts)
    for s in (1e300, 1e-300):
        np.testing.assert_allclose(transform_points(H * s, pts), ref, rtol=1e-12)
    img = np.random.default_rng(0).integers(0, 256, (48, 64), dtype=np.uint8)
    np.testing.assert_array_equal(
        warp_perspective(img, H * 1e300, (64, 48)), warp_perspective(img, H, (64, 48))
    )
    # one point as (2,) still works
    np.testing.assert_allclose(transform_points(H, pts[1]), ref[1:2])
