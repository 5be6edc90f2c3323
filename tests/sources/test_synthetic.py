"""The synthetic D435-like scene: geometry against its own ground truth, the documented
sensor effects, colour alignment, seeded determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.depth import depth_to_points, texture_coordinates
from robopercept.errors import InputError
from robopercept.imaging import hsv_range_mask, rgb_to_hsv
from robopercept.sources import MOTIONS, SyntheticRGBDScene
from robopercept.sources.synthetic import board_pose, stop_go_phase

SMALL = {"depth_size": (424, 240), "color_size": (640, 360)}
TINY = {"depth_size": (212, 120), "color_size": (320, 180)}
GREEN = ((45, 35, 35), (65, 255, 255))  # the tracker's default HSV box (OpenCV scale)


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


@pytest.mark.parametrize("distractor", ["none", "both"])
def test_still_scene_cast_once_renders_the_frames_of_one_full_pass(distractor):
    # each frame casts its rays against the board and the occluder only, continuing
    # from the hits on the still scene cast once per scene; with an empty still cache
    # (no groups cast in advance) every frame is one pass over the whole scene, as
    # before the cache. The two must agree to the bit, on frames with the occluder
    # across the board (t = 0.6..0.72 of the loop) and without it.
    kwargs = {"n_frames": 300, "seed": 2, "motion": "handheld", "distractor": distractor}
    cached = SyntheticRGBDScene(**kwargs, **TINY)
    full = SyntheticRGBDScene(**kwargs, **TINY)
    full.frame(0)  # sets the rays (and the cache, replaced below)
    n_d = full.depth_intrinsics.width * full.depth_intrinsics.height
    n_c = full.color_intrinsics.width * full.color_intrinsics.height
    empty = {
        "groups": 0,
        "rects": 0,
        "z": np.full(n_d, np.inf),
        "ids": np.full(n_d, -1, dtype=np.int64),
        "seen": np.zeros(n_d, bool),
        "tc": np.full(n_c, np.inf),
        "idc": np.full(n_c, -1, dtype=np.int64),
    }
    object.__setattr__(full, "_still", empty)
    for i in (0, 150, 190, 205):
        a, b = cached.frame(i), full.frame(i)
        assert np.array_equal(a.depth, b.depth)
        assert np.array_equal(a.color, b.color)
        assert np.array_equal(a.ground_truth["board_mask"], b.ground_truth["board_mask"])
    assert cached._still["groups"] > 0  # the cache was used


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
    msg = "motion must be one of smooth, fast, jerky, stop-go, handheld; got 'x'"
    with pytest.raises(InputError, match=msg):
        SyntheticRGBDScene(motion="x")
    with pytest.raises(InputError, match=msg):
        board_pose(0.1, "x")
    with pytest.raises(
        InputError, match="distractor must be one of none, box, wall, both; got 'y'"
    ):
        SyntheticRGBDScene(distractor="y")
    with pytest.raises(InputError, match="occluder must be True or False"):
        SyntheticRGBDScene(occluder="no")


# ---------------------------------------------------------------- motion profiles, options


def _poses(motion, seed=0, n=300, fps=30.0, period=10.0):
    """Centres (n, 3) and rotations (n, 3, 3) at frames 0..n-1 (as the scene samples)."""
    poses = [board_pose((i / fps / period) % 1.0, motion, seed, period) for i in range(n)]
    return np.array([p[0] for p in poses]), np.array([p[1] for p in poses])


def _clipped_area(poly, width, height):
    """Area in pixels of a convex polygon (K, 2) clipped to [0, width] x [0, height]
    (Sutherland-Hodgman against the four image edges, then the shoelace formula)."""
    pts = [tuple(p) for p in poly]
    for axis, bound, keep_below in (
        (0, 0.0, False),
        (0, width, True),
        (1, 0.0, False),
        (1, height, True),
    ):
        out = []
        for k, cur in enumerate(pts):
            prev = pts[k - 1]
            cin = cur[axis] <= bound if keep_below else cur[axis] >= bound
            pin = prev[axis] <= bound if keep_below else prev[axis] >= bound
            if cin != pin:
                a = (bound - prev[axis]) / (cur[axis] - prev[axis])
                out.append((prev[0] + a * (cur[0] - prev[0]), prev[1] + a * (cur[1] - prev[1])))
            if cin:
                out.append(cur)
        pts = out
        if not pts:
            return 0.0
    x, y = np.array(pts).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _board_corners(center, rot):
    hw, hh = 0.30, 0.225  # the board is 0.60 x 0.45 m
    return np.array(
        [
            center + sx * hw * rot[:, 0] + sy * hh * rot[:, 1]
            for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))
        ]
    )


def _projected_area(center, rot, k):
    """Pixels of the image covered by the board (geometry only: no occluder, shadow or
    invalid band)."""
    c = _board_corners(center, rot)
    uv = np.c_[k.fx * c[:, 0] / c[:, 2] + k.cx + 0.5, k.fy * c[:, 1] / c[:, 2] + k.cy + 0.5]
    return _clipped_area(uv, k.width, k.height)


def test_default_scene_is_the_smooth_one_and_the_smooth_pose_is_unchanged():
    a = SyntheticRGBDScene(n_frames=40, **TINY).frame(30)
    b = SyntheticRGBDScene(n_frames=40, motion="smooth", occluder=True, distractor="box", **TINY)
    fb = b.frame(30)
    assert np.array_equal(a.depth, fb.depth) and np.array_equal(a.color, fb.color)
    # by hand at t = 0.25 (w = pi / 2): z = 1.5 - 0.9 cos(pi/2) = 1.5,
    # x = 0.45 z sin(3 pi / 4) + 0.35 z exp(-1) = 0.477297 + 0.193137, y = 0.08 sin(pi) - 0.05
    c, r = board_pose(0.25)
    np.testing.assert_allclose(c, [0.670434, -0.05, 1.5], atol=1e-6)
    # normal R e_z = Ry(yaw) Rx(pitch) e_z = (cos p sin y, -sin p, cos p cos y) with
    # yaw = 40 deg sin(0.65 pi), pitch = 25 deg sin(0.45 pi + 1)
    yaw, pitch = np.radians(40 * np.sin(0.65 * np.pi)), np.radians(25 * np.sin(0.45 * np.pi + 1))
    n = [np.cos(pitch) * np.sin(yaw), -np.sin(pitch), np.cos(pitch) * np.cos(yaw)]
    np.testing.assert_allclose(r[:, 2], n, atol=1e-12)
    # the pose of the smooth profile does not depend on the seed, nor on the period
    assert np.array_equal(board_pose(0.4, "smooth", 7, 3.0)[1], board_pose(0.4)[1])


@pytest.mark.parametrize("motion", MOTIONS)
def test_each_profile_stays_in_range_in_view_and_facing_the_camera(motion):
    scene = SyntheticRGBDScene()  # full default resolution: 848x480 depth
    centers, rots = _poses(motion)
    assert 0.55 <= centers[:, 2].min() and centers[:, 2].max() <= 2.5
    # the normal within 50 deg of the optical axis: always seen from the front
    assert np.degrees(np.arccos(np.abs(rots[:, 2, 2]))).max() <= 50.0
    for r in rots[::13]:
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    area = np.array(
        [_projected_area(c, r, scene.depth_intrinsics) for c, r in zip(centers, rots, strict=True)]
    )
    # 1000 px of projected board leave >= 500 valid pixels after the invalid band, the
    # shadows and dropouts (within 5 %: checked on rendered frames in the next test)
    assert np.mean(area >= 1000) >= 0.9


def test_projected_area_predicts_valid_board_pixels():
    # the proxy used above, against rendered full-resolution frames off the occluder
    for motion in ("smooth", "jerky"):
        scene = SyntheticRGBDScene(motion=motion, occluder=False)
        for i in (10, 95, 140, 250):
            f = scene.frame(i)
            c, r = board_pose(i / 300, motion)
            area = _projected_area(c, r, scene.depth_intrinsics)
            assert f.ground_truth["valid_board_pixels"] == pytest.approx(area, rel=0.05)


@pytest.mark.parametrize("motion", MOTIONS)
def test_each_profile_renders_the_board_on_its_true_plane(motion):
    # the plane recipe of test_board_points_lie_on_the_true_plane, on the frame (of every
    # 10th) where the board covers the most of the image
    scene = SyntheticRGBDScene(motion=motion, seed=1, **SMALL)
    centers, rots = _poses(motion, seed=1)
    best = max(
        range(0, 300, 10),
        key=lambda i: _projected_area(centers[i], rots[i], scene.depth_intrinsics),
    )
    f = scene.frame(best)
    n, d = f.ground_truth["plane"]
    np.testing.assert_allclose(n, rots[best][:, 2] * np.sign(rots[best][:, 2] @ centers[best]))
    assert d == pytest.approx(abs(rots[best][:, 2] @ centers[best]))
    pts = depth_to_points(f.depth, f.depth_intrinsics, f.depth_scale)
    mask = f.ground_truth["board_mask"] & (f.depth > 0)
    assert mask.sum() == f.ground_truth["valid_board_pixels"] > 3000
    p = pts[mask]
    r = p @ n - d
    sigma = p[:, 2] ** 2 * 0.08 / (f.depth_intrinsics.fx * 0.050) * abs(n[2])
    mad = 1.4826 * np.median(np.abs(r - np.median(r)))
    assert abs(np.median(r)) < 0.2 * np.median(sigma)
    assert mad == pytest.approx(np.median(sigma), rel=0.35)


def _speeds(centers, rots, fps=30.0):
    """Centre speeds (m/s) and rotation rates (deg/s) between consecutive frames."""
    v = np.linalg.norm(np.diff(centers, axis=0), axis=1) * fps
    rel = np.einsum("nji,njk->nik", rots[:-1], rots[1:])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)
    return v, np.degrees(np.arccos(cos)) * fps


def test_fast_is_about_three_times_the_smooth_speed():
    v_s, w_s = _speeds(*_poses("smooth"))
    v_f, w_f = _speeds(*_poses("fast"))
    assert v_f.max() / v_s.max() >= 2.0
    assert 2.5 <= np.median(v_f) / np.median(v_s) <= 3.5
    assert 1.0 <= np.median(v_f) <= 2.0  # m/s
    assert 80 <= w_f.max() <= 150 and w_f.max() >= 2 * w_s.max()  # deg/s
    # position is continuous over the loop: the last frame is one step from the first
    c, _ = _poses("fast", n=301)
    assert np.linalg.norm(c[300] - c[299]) < 0.1


def test_jerky_has_constant_velocity_segments_kinks_and_reversals():
    centers, rots = _poses("jerky", seed=5)
    v = np.diff(centers, axis=0) * 30
    acc = np.linalg.norm(np.diff(v, axis=0), axis=1) * 30
    # piecewise linear: most frame triples lie on one segment (zero acceleration), and
    # at the knots the velocity jumps (acceleration spikes the smooth path never has)
    assert np.mean(acc < 1e-6) > 0.5
    assert (acc > 10).sum() >= 10
    smooth_v = np.diff(_poses("smooth")[0], axis=0) * 30
    assert (np.linalg.norm(np.diff(smooth_v, axis=0), axis=1) * 30).max() < 10
    # direction reversals: velocity two frames later points backwards
    vn = np.linalg.norm(v, axis=1)
    rev = np.einsum("ij,ij->i", v[:-2], v[2:]) < -0.5 * vn[:-2] * vn[2:]
    assert rev.sum() >= 5
    # rotations are piecewise constant-rate too
    _, w = _speeds(centers, rots)
    assert np.mean(np.abs(np.diff(w)) < 1e-6) > 0.3 and w.max() < 250
    # segment lengths 0.2 .. 0.6 s: no velocity run longer than 0.6 s (18 frames)
    still_rate = np.r_[False, acc < 1e-6, False]
    edges = np.flatnonzero(np.diff(still_rate.astype(int)))
    assert (edges[1::2] - edges[::2]).max() <= 18


def test_stop_go_dwells_then_catches_up():
    centers, rots = _poses("stop-go")
    same = np.array(
        [
            np.array_equal(centers[i], centers[i + 1]) and np.array_equal(rots[i], rots[i + 1])
            for i in range(299)
        ]
    )
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, same.astype(int), 0])))[::2] + 1
    assert (runs >= 15).sum() >= 3 and runs.max() <= 46  # frames of an identical pose
    v_sg, _ = _speeds(centers, rots)
    v_s, _ = _speeds(*_poses("smooth"))
    assert v_sg.max() > 1.2 * v_s.max()
    # the re-timing is continuous and on the smooth schedule at each cycle's end
    assert stop_go_phase(0.25) == 0.25 and stop_go_phase(0.01) == 0.0
    s = [stop_go_phase(t) for t in np.linspace(0, 0.999, 2000)]
    assert np.all(np.diff(s) >= 0) and np.max(np.diff(s)) < 0.002


def test_handheld_is_smooth_plus_millimetre_tremor():
    c_s, r_s = _poses("smooth")
    c_h, r_h = _poses("handheld")
    diff = c_h - c_s
    rms = np.sqrt(np.mean(np.sum(diff**2, axis=1)))
    assert 0.002 <= rms <= 0.01
    # energy above 3 Hz (30 fps, 300 frames: bins of 0.1 Hz): the tremor, a few mm RMS
    spec = np.fft.rfft(diff - diff.mean(0), axis=0)
    freq = np.fft.rfftfreq(300, 1 / 30)
    high = np.sqrt(2 * np.sum(np.abs(spec[freq > 3]) ** 2) / 300**2)
    assert 0.002 <= high <= 0.005
    ang = np.degrees(np.arccos(np.clip((np.einsum("nji,nji->n", r_s, r_h) - 1) / 2, -1, 1)))
    assert 0.3 <= np.sqrt(np.mean(ang**2)) <= 1.0


def test_profiles_are_seeded_functions_of_time():
    for motion in ("jerky", "handheld"):
        c0 = _poses(motion, seed=0, n=60)[0]
        c1 = _poses(motion, seed=1, n=60)[0]
        assert np.abs(c0 - c1).max() > 0.002
        # any order, any time: a late pose computed first equals the same pose later
        late = board_pose(0.73, motion, 2)
        _poses(motion, seed=2, n=30)
        assert np.array_equal(board_pose(0.73, motion, 2)[0], late[0])
    for motion in ("smooth", "fast", "stop-go"):
        assert np.array_equal(_poses(motion, seed=0, n=30)[0], _poses(motion, seed=9, n=30)[0])
    a = SyntheticRGBDScene(n_frames=8, seed=3, motion="jerky", **TINY)
    b = SyntheticRGBDScene(n_frames=8, seed=3, motion="jerky", **TINY)
    frames = list(a)
    f7 = b.frame(7)
    assert np.array_equal(frames[7].depth, f7.depth) and np.array_equal(frames[7].color, f7.color)
    c = SyntheticRGBDScene(n_frames=8, seed=4, motion="jerky", **TINY)
    assert not np.allclose(c.frame(7).ground_truth["plane"][0], f7.ground_truth["plane"][0])


def test_occluder_can_be_switched_off():
    on = SyntheticRGBDScene(**SMALL)
    off = SyntheticRGBDScene(occluder=False, **SMALL)
    idx = range(186, 211, 3)  # t = 0.62 .. 0.70
    assert min(on.frame(i).ground_truth["valid_board_pixels"] for i in idx) == 0
    assert min(off.frame(i).ground_truth["valid_board_pixels"] for i in idx) > 1000


def _green_off_board(scene, i):
    """Pixels of the colour image inside the default green HSV box and more than 3 px
    outside the board's outline projected into the colour camera."""
    f = scene.frame(i)
    green = hsv_range_mask(rgb_to_hsv(f.color), *GREEN)
    c, r = board_pose(i / 300)
    p = (f.T_color_depth @ np.c_[_board_corners(c, r), np.ones(4)].T)[:3].T
    kc = f.color_intrinsics
    uv = np.c_[kc.fx * p[:, 0] / p[:, 2] + kc.cx, kc.fy * p[:, 1] / p[:, 2] + kc.cy]
    yy, xx = np.mgrid[: kc.height, : kc.width]
    inside = np.ones(green.shape, bool)
    e0, e1 = uv[1] - uv[0], uv[2] - uv[1]
    sign = np.sign(e0[0] * e1[1] - e0[1] * e1[0])
    for k in range(4):
        a, b = uv[k], uv[(k + 1) % 4]
        e = b - a
        dist = sign * (e[0] * (yy - a[1]) - e[1] * (xx - a[0])) / np.linalg.norm(e)
        inside &= dist >= -3.0
    return green & ~inside


def test_distractor_options():
    # frame 150: the board is far left, clear of both distractors
    counts = {
        d: int(_green_off_board(SyntheticRGBDScene(distractor=d, **SMALL), 150).sum())
        for d in ("none", "box", "wall", "both")
    }
    assert counts["none"] <= 5
    assert counts["box"] > 300 and counts["wall"] > 300
    assert counts["both"] == pytest.approx(counts["box"] + counts["wall"], rel=0.05)
    # the wall patch is seen on most frames of the loop (the board hides it at times)
    scene = SyntheticRGBDScene(distractor="wall", **TINY)
    seen = [_green_off_board(scene, i).sum() > 50 for i in range(0, 300, 30)]
    assert np.mean(seen) >= 0.7


# issue 25: sizes and scalars of the wrong type or size are InputErrors
@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"color_size": (64, [1, 2])}, r"color_size must be \(width, height\)"),
        ({"depth_size": (100000, 100000)}, r"depth_size must be \(width, height\) with each"),
        ({"depth_size": (8192, 8192)}, "more than the 16777216 allowed"),
        ({"disparity_noise": 1 + 1j}, "disparity_noise must be a real number"),
        ({"fps": None}, "fps must be a real number"),
        ({"baseline": np.inf}, "baseline must be finite"),
        ({"flying_pixel_rate": "0.3"}, "flying_pixel_rate must be a real number"),
        ({"motion": ["smooth"]}, "motion must be one of"),
        ({"distractor": np.array(["box"])}, "distractor must be one of"),
    ],
)
def test_bad_parameters_give_input_errors(kwargs, words):
    with pytest.raises(InputError, match=words):
        SyntheticRGBDScene(**kwargs)


def test_integral_float_sizes_and_numpy_scalars_still_work():
    scene = SyntheticRGBDScene(
        n_frames=1, depth_size=(212.0, 120), color_size=(np.int64(320), 180), fps=np.float32(30)
    )
    f = scene.frame(0)
    assert f.depth.shape == (120, 212) and f.color.shape == (180, 320, 3)
    assert scene.depth_size == (212, 120) and type(scene.fps) is float


def test_fields_of_view_set_the_focal_lengths():
    """A Kinect-style 640x480 camera (62 deg for both streams), f = (w / 2) / tan(hfov / 2)."""
    import math

    from robopercept.errors import InputError

    s = SyntheticRGBDScene(
        n_frames=1, depth_size=(640, 480), color_size=(640, 480), depth_hfov=62.0, color_hfov=62.0
    )
    f = 320 / math.tan(math.radians(31.0))
    assert s.depth_intrinsics.fx == pytest.approx(f) and s.color_intrinsics.fy == pytest.approx(f)
    d435 = SyntheticRGBDScene(n_frames=1)
    assert d435.depth_intrinsics.fx == pytest.approx(424 / math.tan(math.radians(43.5)))
    frame = s.frame(0)
    assert frame.depth.shape == (480, 640) and frame.ground_truth["valid_board_pixels"] > 500
    for bad in (0.5, 180.0, float("nan"), "62"):
        with pytest.raises(InputError, match="depth_hfov"):
            SyntheticRGBDScene(n_frames=1, depth_hfov=bad)
