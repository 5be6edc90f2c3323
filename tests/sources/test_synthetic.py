"""The synthetic D435-like scene: geometry against its own ground truth, the documented
sensor effects, colour alignment, seeded determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.depth import depth_to_points, texture_coordinates
from robopercept.errors import InputError
from robopercept.imaging import hsv_range_mask, rgb_to_hsv
from robopercept.sources import SyntheticRGBDScene
from robopercept.sources.synthetic import board_pose

SMALL = {"depth_size": (424, 240), "color_size": (640, 360)}


@pytest.fixture(scope="module")
def scene():
    return SyntheticRGBDScene(n_frames=300)


@pytest.fixture(scope="module")
def frame30(scene):
    return scene.frame(30)


def test_calibration_is_d435_like(scene):
    kd, kc = scene.depth_intrinsics, scene.color_intrinsics
    assert (kd.width, kd.height, kc.width, kc.height) == (848, 480, 1280, 720)
    # horizontal fields of view of 87 and 69 degrees
    assert np.degrees(2 * np.arctan(kd.width / 2 / kd.fx)) == pytest.approx(87.0)
    assert np.degrees(2 * np.arctan(kc.width / 2 / kc.fx)) == pytest.approx(69.0)
    # the colour camera is a separate pinhole 15 mm to the side
    assert np.linalg.norm(scene.T_color_depth[:3, 3]) == pytest.approx(0.015, abs=1e-3)


def test_board_points_lie_on_the_true_plane(frame30):
    # every valid board pixel, back-projected, is on the ground-truth plane n.x = d up to
    # the depth noise: sigma_z = z^2 sigma_d / (f B) in depth, times n_z along the normal
    f = frame30
    n, d = f.ground_truth["plane"]
    assert np.linalg.norm(n) == pytest.approx(1.0) and d > 0
    pts = depth_to_points(f.depth, f.depth_intrinsics, f.depth_scale)
    mask = f.ground_truth["board_mask"] & (f.depth > 0)
    assert mask.sum() == f.ground_truth["valid_board_pixels"] > 10000
    p = pts[mask]
    r = p @ n - d
    z = p[:, 2]
    sigma = z**2 * 0.08 / (f.depth_intrinsics.fx * 0.050) * abs(n[2])
    # robust spread (flying pixels at the edges are not noise): MAD-based sigma
    mad = 1.4826 * np.median(np.abs(r - np.median(r)))
    assert abs(np.median(r)) < 0.5e-3
    assert mad == pytest.approx(np.median(sigma), rel=0.35)


def test_depth_noise_on_the_back_wall_follows_the_disparity_model():
    # the back wall is a fronto-parallel plane at z = 6 m; on the image rows around the
    # principal point nothing else is in front of it at mid columns (except the board):
    # its RMS depth error is sigma_d z^2 / (f B)
    s = SyntheticRGBDScene(n_frames=151, flying_pixel_rate=0.0, dropout_rate=0.0)
    f = s.frame(150)  # the board is to the left and far
    band = np.zeros(f.depth.shape, bool)
    band[230:250, 274:574] = True
    sel = band & ~f.ground_truth["board_mask"] & (f.depth > 5000)
    assert sel.sum() > 1000
    err = f.depth[sel] * f.depth_scale - 6.0
    expected = 6.0**2 * 0.08 / (s.depth_intrinsics.fx * 0.05)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(expected, rel=0.1)
    assert abs(np.mean(err)) < 0.1 * expected


def test_depth_is_quantized_to_millimetres_and_subpixel_disparity(frame30):
    f = frame30
    assert f.depth.dtype == np.uint16 and f.depth_scale == 0.001
    z = f.depth[f.depth > 0].astype(np.float64) * f.depth_scale
    disp = f.depth_intrinsics.fx * 0.05 / z
    # the depth units round disparities off the 1/32 grid only by the 1 mm rounding
    step = np.abs(disp * 32 - np.rint(disp * 32)) / 32
    ddisp = disp * (0.0005 / z)  # disparity change of half a millimetre
    assert np.mean(step <= ddisp + 1e-9) > 0.99


def test_invalid_band_on_the_left_and_shadows_beside_the_board(frame30):
    f = frame30
    valid = f.depth > 0
    # the right imager cannot see the leftmost f B / z columns
    assert valid[:, :3].mean() < 0.02
    assert valid.mean() > 0.9
    # shadows: directly left of the board (nearer than the wall), a band without depth
    board = f.ground_truth["board_mask"]
    rows = np.flatnonzero(board.any(axis=1))
    left_edges = [(r, np.flatnonzero(board[r])[0]) for r in rows[::10]]
    shadowed = [not valid[r, c - 3] for r, c in left_edges if c > 10]
    assert np.mean(shadowed) > 0.8


def test_flying_pixels_and_dropouts():
    base = SyntheticRGBDScene(n_frames=31, flying_pixel_rate=0.0, dropout_rate=0.0).frame(30)
    fly = SyntheticRGBDScene(n_frames=31, dropout_rate=0.0).frame(30)
    drop = SyntheticRGBDScene(n_frames=31, flying_pixel_rate=0.0, dropout_rate=0.05).frame(30)
    lost = (base.depth > 0) & (drop.depth == 0)
    assert lost.sum() / (base.depth > 0).sum() == pytest.approx(0.05, abs=0.01)
    # flying pixels: some pixels change by far more than the noise, all at depth edges
    diff = np.abs(fly.depth.astype(int) - base.depth.astype(int))
    assert (diff > 100).sum() > 50


def test_colour_alignment_puts_the_board_on_green(frame30):
    # texture coordinates of the board's depth points land on board-coloured pixels
    f = frame30
    pts = depth_to_points(f.depth, f.depth_intrinsics, f.depth_scale)
    board = f.ground_truth["board_mask"] & (f.depth > 0)
    # stay off the board's rim (flying pixels, one-pixel rounding at the outline)
    inner = board & np.roll(board, 3, 0) & np.roll(board, -3, 0)
    inner &= np.roll(board, 3, 1) & np.roll(board, -3, 1)
    uv, ok = texture_coordinates(pts[inner], f.T_color_depth, f.color_intrinsics)
    kc = f.color_intrinsics
    col = np.rint(uv[ok, 0] * kc.width).astype(int)
    row = np.rint(uv[ok, 1] * kc.height).astype(int)
    green = hsv_range_mask(rgb_to_hsv(f.color), (45, 35, 35), (65, 255, 255))
    assert ok.sum() > 20000  # part of the board is outside the narrower colour view
    assert green[row, col].mean() > 0.99


def test_trajectory_is_smooth_and_in_range():
    ts = np.linspace(0, 1, 301)
    centers = np.array([board_pose(t)[0] for t in ts])
    assert centers[:, 2].min() >= 0.55 and centers[:, 2].max() <= 2.45
    step = np.linalg.norm(np.diff(centers, axis=0), axis=1)
    assert step.max() < 0.08  # under 8 cm per frame at 30 fps (2.4 m/s at the fastest)
    for t in ts[::7]:
        r = board_pose(t)[1]
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


def test_scene_is_seeded_and_frames_are_independent_of_order():
    a = SyntheticRGBDScene(n_frames=5, seed=3, **SMALL)
    b = SyntheticRGBDScene(n_frames=5, seed=3, **SMALL)
    c = SyntheticRGBDScene(n_frames=5, seed=4, **SMALL)
    f4 = a.frame(4)
    frames = list(b)
    assert np.array_equal(frames[4].depth, f4.depth)
    assert np.array_equal(frames[4].color, f4.color)
    assert not np.array_equal(c.frame(4).depth, f4.depth)
    assert [f.index for f in frames] == list(range(5))
    np.testing.assert_allclose([f.timestamp for f in frames], np.arange(5) / 30)


def test_the_board_is_occluded_briefly(scene):
    # the grey panel passes in front: no board pixel for a few frames around t = 0.66
    counts = [scene.frame(i).ground_truth["valid_board_pixels"] for i in range(190, 206, 3)]
    assert min(counts) == 0 and max(counts) > 500


def test_bad_input():
    with pytest.raises(InputError, match="n_frames"):
        SyntheticRGBDScene(n_frames=0)
    with pytest.raises(InputError, match="depth_size"):
        SyntheticRGBDScene(depth_size=(4, 4))
    with pytest.raises(InputError, match="dropout_rate"):
        SyntheticRGBDScene(dropout_rate=1.5)
    with pytest.raises(InputError, match="index"):
        SyntheticRGBDScene(n_frames=2, **SMALL).frame(2)
