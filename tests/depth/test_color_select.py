"""Colour selection of RGB-D points: parity with the composed library path on the
synthetic sequence and on a real D4xx frame, a hand-built case, the z-buffer left
clean, lens distortion, and bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from robopercept.depth import (
    ColoredPoints,
    ColorRangeSelector,
    depth_to_points,
    points_in_color_range,
    sample_colors,
    texture_coordinates,
)
from robopercept.depth import color_select as cs
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics, se3
from robopercept.imaging import hsv_range_mask, rgb_to_hsv
from robopercept.sources import SyntheticRGBDScene
from tests.conftest import data_path

SMALL = {"depth_size": (424, 240), "color_size": (640, 360)}
GREEN = ((45, 35, 35), (65, 255, 255))
BOXES = [
    (*GREEN, 0.02),  # the default green box, z-buffer on
    (*GREEN, None),  # no occlusion test
    ((170, 50, 50), (10, 255, 255), 0.02),  # red: the hue range wraps around
]


@pytest.fixture(scope="module")
def frames():
    """Frames 0, 95 and 190 of the default sequence: near, half out of view, far."""
    scene = SyntheticRGBDScene(n_frames=300, **SMALL)
    return [scene.frame(i) for i in (0, 95, 190)]


def library_path(depth, color, k_depth, k_color, T, scale, low, high, tol):
    """The composed public functions: the selected points (row-major), their hues, their
    flat depth-pixel indices and the number of pixels with depth."""
    pts = depth_to_points(depth, k_depth, scale).reshape(-1, 3)
    has = np.isfinite(pts[:, 2])
    ids = np.flatnonzero(has)
    pts = pts[has]
    uv, valid = texture_coordinates(pts, T, k_color, occlusion_tolerance=tol)
    hsv = rgb_to_hsv(sample_colors(color, uv, valid)[:, None, :])
    mask = hsv_range_mask(hsv, low, high)[:, 0] & valid
    return pts[mask], hsv[mask, 0, 0].astype(np.float64), ids[mask], int(has.sum())


def assert_equals_library(sel: ColoredPoints, ref, min_points: int = 100) -> None:
    pts, hue, ids, n_valid = ref
    assert pts.shape[0] >= min_points  # a selection worth comparing
    # exact: the same float64 formulas (rays * z, the same compiled projection, the
    # same bit-exact uint8 HSV conversion), so no tolerance is needed
    np.testing.assert_array_equal(sel.points, pts)
    np.testing.assert_array_equal(sel.hue, hue)
    np.testing.assert_array_equal(sel.pixels, ids)
    assert sel.n_valid == n_valid
    assert sel.points.dtype == np.float64 and sel.hue.dtype == np.float64
    assert sel.pixels.dtype == np.int64


def _args(f):
    return f.depth, f.color, f.depth_intrinsics, f.color_intrinsics, f.T_color_depth, f.depth_scale


# -- parity with the library path -----------------------------------------------------


@pytest.mark.parametrize(("low", "high", "tol"), BOXES)
def test_equals_the_library_path(frames, low, high, tol):
    select = ColorRangeSelector(low, high, tol)
    for f in frames:
        sel = select(*_args(f))
        assert_equals_library(sel, library_path(*_args(f), low, high, tol))
        assert np.isinf(select._zbuf).all()  # the z-buffer is clean for the next call
        # pixels are the flat indices of the points: depth_to_points there gives them
        flat = depth_to_points(f.depth, f.depth_intrinsics, f.depth_scale).reshape(-1, 3)
        np.testing.assert_array_equal(flat[sel.pixels], sel.points)
        assert np.all(np.diff(sel.pixels) > 0)  # row-major order
        assert set(sel.ms) == {"points", "color"} and min(sel.ms.values()) >= 0


def test_occlusion_test_removes_points(frames):
    # the z-buffer does something on this sequence (else the None case would test nothing)
    f = frames[0]
    with_test = ColorRangeSelector(*GREEN, 0.02)(*_args(f))
    without = ColorRangeSelector(*GREEN, None)(*_args(f))
    assert set(with_test.pixels) < set(without.pixels)


@pytest.mark.parametrize("model", ["brown_conrady", "inverse_brown_conrady"])
def test_distorted_color_camera_equals_the_library_path(frames, model):
    f = frames[0]
    k = f.color_intrinsics
    k_dist = dataclasses.replace(k, model=model, coeffs=(0.12, -0.25, 2e-3, -1e-3, 0.08))
    args = (f.depth, f.color, f.depth_intrinsics, k_dist, f.T_color_depth, f.depth_scale)
    sel = ColorRangeSelector(*GREEN)(*args)
    ref = library_path(*args, *GREEN, 0.02)
    assert_equals_library(sel, ref)
    # and the distortion matters: the undistorted camera selects other pixels
    plain = ColorRangeSelector(*GREEN)(*_args(f))
    assert not np.array_equal(plain.pixels, sel.pixels)


def test_float_depth_with_nan_equals_the_library_path(frames):
    # metres as float32 with NaN holes: NaN is no depth, like 0
    f = frames[1]
    depth = (f.depth * f.depth_scale).astype(np.float32)
    depth[::7, ::5] = np.nan
    args = (depth, f.color, f.depth_intrinsics, f.color_intrinsics, f.T_color_depth, 1.0)
    sel = ColorRangeSelector(*GREEN)(*args)
    assert_equals_library(sel, library_path(*args, *GREEN, 0.02))
    assert sel.n_valid < np.count_nonzero(f.depth)


# -- state between calls, the one-shot form -------------------------------------------


def test_reused_selector_equals_fresh_ones(frames):
    # the cached rays and the z-buffer carry nothing from one call to the next
    select = ColorRangeSelector(*GREEN)
    for f in (frames[0], frames[2], frames[0], frames[1]):
        a = select(*_args(f))
        b = ColorRangeSelector(*GREEN)(*_args(f))
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.hue, b.hue)
        np.testing.assert_array_equal(a.pixels, b.pixels)
        assert np.isinf(select._zbuf).all()


def test_without_hues_the_same_points(frames):
    # hues=False (the plane measurement without a hue feature) skips only the hues
    select = ColorRangeSelector(*GREEN)
    for f in frames[:2]:
        a = select(*_args(f))
        b = select(*_args(f), hues=False)
        assert b.hue is None and a.hue is not None and a.hue.size == a.points.shape[0]
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.pixels, b.pixels)
        assert a.n_valid == b.n_valid
    with pytest.raises(InputError, match="hues"):
        select(*_args(frames[0]), hues="no")


def test_new_camera_sizes_are_followed(frames):
    # a second stream with other resolutions through the same selector
    select = ColorRangeSelector(*GREEN)
    small = SyntheticRGBDScene(n_frames=2, depth_size=(212, 120), color_size=(320, 180)).frame(0)
    big = frames[0]
    for f in (big, small, big):
        sel = select(*_args(f))
        assert_equals_library(sel, library_path(*_args(f), *GREEN, 0.02))


def test_zbuffer_is_reset_after_an_error(frames, monkeypatch):
    select = ColorRangeSelector(*GREEN)

    def boom(*args):
        raise RuntimeError("selection failed")

    monkeypatch.setattr(cs, "_select_kernel", boom)
    with pytest.raises(RuntimeError, match="selection failed"):
        select(*_args(frames[0]))
    assert select._zbuf.size and np.isinf(select._zbuf).all()
    monkeypatch.undo()
    sel = select(*_args(frames[0]))
    assert_equals_library(sel, library_path(*_args(frames[0]), *GREEN, 0.02))


@pytest.mark.parametrize(("low", "high", "tol"), BOXES)
def test_one_shot_equals_the_selector(frames, low, high, tol):
    f = frames[0]
    a = points_in_color_range(*_args(f), low, high, occlusion_tolerance=tol)
    b = ColorRangeSelector(low, high, tol)(*_args(f))
    for name in ("points", "hue", "pixels", "n_valid"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


# -- a hand-built case ------------------------------------------------------------------

# A 4x3 depth image (fx = fy = 4, principal point (1.5, 1)) 1 m away, one pixel (row 1,
# col 0) at 0.5 m, one (row 2, col 2) without depth. The colour camera has the same
# intrinsics and sits 0.25 m to the left (p_c = p + (0.25, 0, 0)), so a point at depth z
# lands 4 * 0.25 / z columns to the right: 1 column at 1 m, 2 at 0.5 m. Hence
#   depth (r, c) at 1 m  -> colour (r, c + 1); column 3 falls outside the colour image;
#   depth (1, 0) at 0.5 m -> colour (1, 2), where it hides depth (1, 1) (1 m > 0.5 m + 2 cm).
K_HAND = CameraIntrinsics(4, 3, 4.0, 4.0, 1.5, 1.0)
T_HAND = se3(np.eye(3), [0.25, 0.0, 0.0])
DEPTH_HAND = np.full((3, 4), 1000, dtype=np.uint16)
DEPTH_HAND[1, 0] = 500
DEPTH_HAND[2, 2] = 0
G, G63, DARK, GREY, RED = (0, 255, 0), (0, 200, 20), (0, 20, 0), (90, 90, 90), (255, 0, 10)
COLOR_HAND = np.array(
    [
        [GREY, G, G63, GREY],  # colour row 0: depth (0, 0) -> G, (0, 1) -> G63, (0, 2) -> grey
        [RED, GREY, G, G],  # row 1: (1, 0) and (1, 1) -> col 2 G; (1, 2) -> col 3 G
        [GREY, G, DARK, RED],  # row 2: (2, 0) -> G, (2, 1) -> DARK (V 20 < 35), (2, 3) out
    ],
    dtype=np.uint8,
)


def _hand_point(r: int, c: int, z: float) -> list[float]:
    return [z * (c - 1.5) / 4.0, z * (r - 1.0) / 4.0, z]


def test_hand_built_case():
    args = (DEPTH_HAND, COLOR_HAND, K_HAND, K_HAND, T_HAND, 0.001)
    sel = ColorRangeSelector(*GREEN)(*args)
    # (0, 0) green H 60, (0, 1) H = 60 + 30 * 20 / 200 = 63, (1, 0) green at 0.5 m,
    # (1, 1) hidden by it, (1, 2) green, (2, 0) green
    assert sel.pixels.tolist() == [0, 1, 4, 6, 8]
    assert sel.hue.tolist() == [60.0, 63.0, 60.0, 60.0, 60.0]
    expected = [_hand_point(0, 0, 1), _hand_point(0, 1, 1), _hand_point(1, 0, 0.5),
                _hand_point(1, 2, 1), _hand_point(2, 0, 1)]  # fmt: skip
    np.testing.assert_allclose(sel.points, expected, rtol=0, atol=1e-15)
    assert sel.n_valid == 11
    # without the occlusion test (1, 1) takes the colour of (1, 2) in the colour image
    sel = ColorRangeSelector(*GREEN, occlusion_tolerance=None)(*args)
    assert sel.pixels.tolist() == [0, 1, 4, 5, 6, 8]
    # a tolerance larger than the 0.5 m gap keeps it too
    assert ColorRangeSelector(*GREEN, 0.6)(*args).pixels.tolist() == [0, 1, 4, 5, 6, 8]
    # red wraps around: (255, 0, 10) has H = 180 - round(30 * 10 / 255) = 179; the red
    # colour pixels (1, 0) and (2, 3) are seen by no depth pixel ((1, -1), (2, 2) none)
    sel = ColorRangeSelector((170, 50, 50), (10, 255, 255))(*args)
    assert sel.pixels.size == 0 and sel.points.shape == (0, 3)
    # the whole box: every point that sees the colour image and is not hidden
    sel = ColorRangeSelector((0, 0, 0), (180, 255, 255))(*args)
    assert sel.pixels.tolist() == [0, 1, 2, 4, 6, 8, 9]
    assert sel.hue.tolist() == [60.0, 63.0, 0.0, 60.0, 60.0, 60.0, 60.0]
    assert_equals_library(sel, library_path(*args, (0, 0, 0), (180, 255, 255), 0.02), min_points=7)


def test_a_growing_tolerance_keeps_far_points_behind_noisy_neighbours():
    # four depth pixels land on one colour pixel; one of them is 5 cm nearer
    k_depth = CameraIntrinsics(2, 2, 2.0, 2.0, 0.5, 0.5)
    k_color = CameraIntrinsics(1, 1, 1.0, 1.0, 0.0, 0.0)
    color = np.array([[[0, 255, 0]]], np.uint8)

    def selected(near_mm: int, far_mm: int, grows: bool) -> list[int]:
        depth = np.full((2, 2), far_mm, dtype=np.uint16)
        depth[0, 0] = near_mm
        sel = ColorRangeSelector(*GREEN, 0.02, occlusion_grows=grows)
        return sel(depth, color, k_depth, k_color, np.eye(4), 0.001).pixels.tolist()

    # at 3 m the tolerance is 0.02 * 3^2 = 18 cm: 5 cm of depth noise hides nothing
    assert selected(2950, 3000, False) == [0]
    assert selected(2950, 3000, True) == [0, 1, 2, 3]
    # up to 1 m it is 2 cm either way; a real occluder 0.5 m nearer still hides at 3 m
    assert selected(950, 1000, True) == [0]
    assert selected(2500, 3000, True) == [0]


def test_red_wraps_around():
    # a red colour pixel seen by a depth pixel: the colour image shifted one column left
    # (red moves to colour (1, 3) and (2, 2), seen by depth (1, 2) and (2, 1))
    color = np.roll(COLOR_HAND, -1, axis=1)
    args = (DEPTH_HAND, color, K_HAND, K_HAND, T_HAND, 0.001)
    sel = ColorRangeSelector((170, 50, 50), (10, 255, 255))(*args)
    assert sel.pixels.tolist() == [6, 9]
    assert sel.hue.tolist() == [179.0, 179.0]
    # hue 179 is outside 0..10 when the range does not wrap
    assert ColorRangeSelector((0, 50, 50), (10, 255, 255))(*args).pixels.size == 0


# -- a real D4xx frame ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def bag_frame():
    """librealsense's unit-test recording: one depth + colour frame, with its cameras, as
    RealSenseSource reads it (pyrealsense2's own intrinsics and extrinsics)."""
    pytest.importorskip("pyrealsense2")
    from robopercept.sources.realsense import RealSenseSource

    path = data_path("rgbd", "realsense_bag", "single_depth_color_640x480.bag")
    f = next(iter(RealSenseSource(path, timeout=1.0)))
    return (
        f.depth,
        f.color,
        f.depth_intrinsics,
        f.color_intrinsics,
        f.T_color_depth,
        f.depth_scale,
    )


@pytest.mark.realdata
def test_real_frame_equals_the_library_path(bag_frame):
    # every point whose colour is saturated enough (S >= 60), any hue, and a hue band
    for low, high in [((0, 60, 40), (180, 255, 255)), ((90, 30, 30), (130, 255, 255))]:
        sel = ColorRangeSelector(low, high)(*bag_frame)
        assert_equals_library(sel, library_path(*bag_frame, low, high, 0.02), min_points=50)


# -- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("low", "high", "match"),
    [
        ((45, 35), (65, 255, 255), "3 values each"),
        ((45, 35, 35), (65, 255, 255, 0), "3 values each"),
        ((90, 35, 35), (130, 255, 300), "OpenCV scale"),
        ((200, 35, 35), (260, 255, 255), "hue in degrees\\? halve it"),
        ((-1, 35, 35), (65, 255, 255), "H in 0..180"),
        ((45, 200, 35), (65, 100, 255), "swap them"),
        ((45, 35, np.nan), (65, 255, 255), "finite"),
        (("a", 35, 35), (65, 255, 255), "three numbers"),
    ],
)
def test_bad_hsv_bounds(low, high, match):
    with pytest.raises(InputError, match=match):
        ColorRangeSelector(low, high)


@pytest.mark.parametrize("tol", [-0.01, np.nan])
def test_bad_tolerance(tol):
    with pytest.raises(InputError, match=r"occlusion_tolerance \(metres >= 0, or None"):
        ColorRangeSelector(*GREEN, tol)


def test_bad_frames():
    select = ColorRangeSelector(*GREEN)
    d, c, k, T = DEPTH_HAND, COLOR_HAND, K_HAND, T_HAND

    def check(match, *args):
        with pytest.raises(InputError, match=match):
            select(*args)
        assert np.isinf(select._zbuf).all()

    check("depth must be a 2-D .* drop the channel axis", d[..., None], c, k, k, T, 0.001)
    check("depth is 3x4 but depth_intrinsics describe 4x3", d.T, c, k, k, T, 0.001)
    check("CameraIntrinsics.scaled", d[:2], c, k, k, T, 0.001)
    check("depth must be numeric", d > 0, c, k, k, T, 0.001)
    check("color must be uint8 .* \\(color \\* 255\\)", d, c / 255.0, k, k, T, 0.001)
    check("color must be uint8 .* >> 8", d, c.astype(np.uint16) * 257, k, k, T, 0.001)
    check("RGBA\\? drop alpha", d, np.dstack([c, c[..., :1]]), k, k, T, 0.001)
    chw = np.zeros((3, 5, 6), dtype=np.uint8)
    check("channels-first\\? use color.transpose", d, chw, k, k, T, 0.001)
    check("gray image has no hue", d, c[..., 0], k, k, T, 0.001)
    check("color is 3x4 but color_intrinsics describe 4x3", d, c.transpose(1, 0, 2), k, k, T, 0.001)
    check("depth_intrinsics must be a CameraIntrinsics", d, c, np.eye(3), k, T, 0.001)
    check("color_intrinsics must be a CameraIntrinsics", d, c, k, None, T, 0.001)
    check("T_color_depth must be a finite 4x4", d, c, k, k, np.eye(3), 0.001)
    check("T_color_depth's last row", d, c, k, k, np.ones((4, 4)), 0.001)
    check("depth_scale", d, c, k, k, T, 0.0)
    check("depth_scale", d, c, k, k, T, -0.001)
    # one-shot: the same checks
    with pytest.raises(InputError, match="swap them"):
        points_in_color_range(d, c, k, k, T, 0.001, (0, 200, 0), (10, 100, 255))


# issue 25: scalars and cameras of the wrong type or size are refused, typed
def test_bad_scalars_and_cameras():
    d, c, k, T = DEPTH_HAND, COLOR_HAND, K_HAND, T_HAND
    with pytest.raises(InputError, match=r"occlusion_tolerance .* must be a real number"):
        points_in_color_range(d, c, k, k, T, 0.001, *GREEN, occlusion_tolerance=[1, 2])
    with pytest.raises(InputError, match=r"depth\.astype\(np\.float32\)"):
        points_in_color_range(d.astype(np.float16), c, k, k, T, 0.001, *GREEN)
    huge = CameraIntrinsics(65536, 65536, 500.0, 500.0, 0.0, 0.0)
    with pytest.raises(InputError, match="color_intrinsics describe a 65536x65536 image"):
        points_in_color_range(d, c, k, huge, T, 0.001, *GREEN)
    with pytest.raises(InputError, match="depth_scale"):
        points_in_color_range(d, c, k, k, T, "3", *GREEN)
    # a numpy tolerance is a tolerance
    ref = points_in_color_range(d, c, k, k, T, 0.001, *GREEN, occlusion_tolerance=0.02)
    got = points_in_color_range(d, c, k, k, T, 0.001, *GREEN, occlusion_tolerance=np.float32(0.02))
    np.testing.assert_array_equal(got.pixels, ref.pixels)


# -- the fast paths (issue 49) ---------------------------------------------------------


def test_distorted_depth_camera_equals_the_library_path(frames):
    # a depth camera with lens distortion has rays that are not (rx[u], ry[v], 1): the
    # selector must read its full ray table
    f = frames[0]
    k = dataclasses.replace(
        f.depth_intrinsics, model="inverse_brown_conrady", coeffs=(0.1, -0.2, 1e-3, 2e-3, 0.05)
    )
    args = (f.depth, f.color, k, f.color_intrinsics, f.T_color_depth, f.depth_scale)
    select = ColorRangeSelector(*GREEN)
    sel = select(*args)
    assert not select._separable
    assert_equals_library(sel, library_path(*args, *GREEN, 0.02))
    select(*_args(f))
    assert select._separable  # the plain camera's rays are separable


@pytest.mark.parametrize(("low", "high"), [GREEN, ((170, 50, 50), (10, 255, 255))])
def test_box_table_equals_the_hsv_conversion(low, high):
    # every 7th of the 2^24 colours: the table's bit against rgb_to_hsv + hsv_range_mask
    keys = np.arange(0, 1 << 24, 7)
    rgb = np.stack([keys >> 16, (keys >> 8) & 255, keys & 255], axis=-1).astype(np.uint8)
    want = hsv_range_mask(rgb_to_hsv(rgb[:, None, :]), low, high)[:, 0]
    table = cs._box_table(tuple(map(float, low)), tuple(map(float, high)))
    got = (table[keys >> 3] >> (keys & 7)) & 1
    np.testing.assert_array_equal(got.astype(bool), want)
    assert 1000 < want.sum() < keys.size - 1000  # a box that selects some, not all


def test_below_the_table_size_the_direct_test_gives_the_same(frames):
    # the same frame cropped under _TABLE_PIXELS depth pixels takes the per-pixel HSV
    # test; both equal the library path (the full frame takes the table)
    f = frames[0]
    h, w = 200, 300
    assert h * w < cs._TABLE_PIXELS <= f.depth.size
    k = dataclasses.replace(f.depth_intrinsics, width=w, height=h)
    args = (f.depth[:h, :w].copy(), f.color, k, f.color_intrinsics, f.T_color_depth, f.depth_scale)
    assert_equals_library(ColorRangeSelector(*GREEN)(*args), library_path(*args, *GREEN, 0.02))


def test_copy_false_gives_views_of_the_buffers_until_the_next_call(frames):
    select = ColorRangeSelector(*GREEN)
    kept = select(*_args(frames[0]))
    view = select(*_args(frames[0]), copy=False)
    for name in ("points", "hue", "pixels"):
        np.testing.assert_array_equal(getattr(view, name), getattr(kept, name))
    assert not np.shares_memory(kept.points, view.points)
    later = select(*_args(frames[2]))  # the next call overwrites the views' buffers
    assert np.shares_memory(view.points, select._work["out"])
    assert not np.array_equal(view.pixels[: later.pixels.size], kept.pixels[: later.pixels.size])
    with pytest.raises(InputError, match="copy"):
        select(*_args(frames[0]), copy="no")
