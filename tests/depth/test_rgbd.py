"""RGB-D geometry: librealsense pointcloud parity on the real recording, hand cases,
occlusion, alignment, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.depth import (
    align_color_to_depth,
    align_depth_to_color,
    depth_to_points,
    pixel_rays,
    sample_colors,
    texture_coordinates,
)
from robopercept.depth.rgbd import DepthScaleWarning, project_to_color
from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics, apply, project, se3
from robopercept.geometry.camera import compiled_params
from tests.conftest import data_path

rs = pytest.importorskip("pyrealsense2")


def _intrinsics(i) -> CameraIntrinsics:
    model = {"brown_conrady": "brown_conrady", "none": "none"}.get(i.model.name, "none")
    return CameraIntrinsics(i.width, i.height, i.fx, i.fy, i.ppx, i.ppy, model, tuple(i.coeffs))


def _extrinsics(e) -> np.ndarray:
    # librealsense stores the rotation column-major
    return se3(np.array(e.rotation).reshape(3, 3).T, e.translation)


@pytest.fixture(scope="module")
def bag_frame(librealsense):
    """The one depth + colour frame of librealsense's unit-test recording, read with
    pyrealsense2, and its rs2::pointcloud vertices and texture coordinates."""
    path = data_path("rgbd", "realsense_bag", "single_depth_color_640x480.bag")
    return librealsense.submit(_read_bag, str(path)).result(timeout=120)


def _read_bag(path: str) -> dict:
    """:func:`bag_frame`'s work, in the librealsense worker."""
    pipe = rs.pipeline()
    cfg = rs.config()
    cfg.enable_device_from_file(path, repeat_playback=False)
    profile = pipe.start(cfg)
    profile.get_device().as_playback().set_real_time(False)
    try:
        frames = pipe.wait_for_frames(5000)
        depth, color = frames.get_depth_frame(), frames.get_color_frame()
        pc = rs.pointcloud()
        pc.map_to(color)
        cloud = pc.calculate(depth)
        out = {
            "depth": np.asanyarray(depth.get_data()).copy(),
            "color": np.asanyarray(color.get_data()).copy(),
            "K_depth": _intrinsics(depth.profile.as_video_stream_profile().intrinsics),
            "K_color": _intrinsics(color.profile.as_video_stream_profile().intrinsics),
            "T": _extrinsics(depth.profile.get_extrinsics_to(color.profile)),
            "scale": profile.get_device().first_depth_sensor().get_depth_scale(),
            "vertices": np.asanyarray(cloud.get_vertices()).view(np.float32).reshape(-1, 3).copy(),
            "uv": np.asanyarray(cloud.get_texture_coordinates())
            .view(np.float32)
            .reshape(-1, 2)
            .copy(),
        }
    finally:
        pipe.stop()
    return out


@pytest.mark.realdata
def test_points_and_uv_match_librealsense_pointcloud(bag_frame):
    f = bag_frame
    pts = depth_to_points(f["depth"], f["K_depth"], f["scale"])
    flat = pts.reshape(-1, 3)
    has = f["depth"].reshape(-1) > 0
    # rs2::pointcloud leaves a vertex at 0 where its occlusion filter removes it; it
    # keeps the others, including those that map outside the colour image
    kept = f["vertices"][:, 2] > 0
    assert kept.sum() > 100_000 and not (kept & ~has).any()
    np.testing.assert_allclose(flat[kept], f["vertices"][kept], atol=1e-6)
    assert np.isnan(flat[~has]).all()
    uv, valid = texture_coordinates(pts, f["T"], f["K_color"])
    uv_flat = uv.reshape(-1, 2)
    np.testing.assert_allclose(uv_flat[kept], f["uv"][kept], atol=1e-3)
    # our validity (inside the colour image, not occluded) against librealsense's kept
    # points that land inside the colour image
    rs_inside = kept & (f["uv"] >= 0).all(axis=1) & (f["uv"] < 1).all(axis=1)
    assert np.mean(valid.reshape(-1)[has] == rs_inside[has]) > 0.99
    # flat output: the same points, valid pixels only
    np.testing.assert_allclose(
        depth_to_points(f["depth"], f["K_depth"], f["scale"], organized=False), flat[has]
    )
    colors = sample_colors(f["color"], uv, valid)
    assert colors.shape == (480, 640, 3) and colors.dtype == np.uint8
    assert valid.mean() > 0.3 and colors[valid].mean() > 10 and (colors[~valid] == 0).all()


def test_hand_case_and_occlusion():
    k = CameraIntrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)
    depth = np.zeros((3, 4), np.uint16)
    depth[1, 1] = 2000  # 2 m at pixel (1, 1)
    pts = depth_to_points(depth, k)
    np.testing.assert_allclose(pts[1, 1], [2 * (1 - 1.5) / 2, 0.0, 2.0])
    assert np.isnan(pts[0, 0]).all()
    # identity extrinsics, same camera: uv is the pixel over the size
    uv, valid = texture_coordinates(pts, np.eye(4), k)
    np.testing.assert_allclose(uv[1, 1], [1 / 4, 1 / 3])
    assert valid.sum() == 1
    # a near point in front of a far one on the same ray: the far one is occluded
    two = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 3.0], [0.0, 0.0, np.nan]])
    _, v = texture_coordinates(two, np.eye(4), k)
    assert v.tolist() == [True, False, False]
    _, v = texture_coordinates(two, np.eye(4), k, occlusion_tolerance=None)
    assert v.tolist() == [True, True, False]


def test_alignment_round_trip_with_a_baseline():
    # a fronto-parallel wall at 1.5 m seen by a depth camera and a colour camera 15 mm
    # to its side: aligned depth is the wall depth wherever the colour camera sees it
    kd = CameraIntrinsics(64, 48, 40.0, 40.0, 31.5, 23.5)
    kc = CameraIntrinsics(80, 60, 50.0, 50.0, 39.5, 29.5)
    T = se3(None, [-0.015, 0.0, 0.0])
    depth = np.full((48, 64), 1500, np.uint16)
    aligned = align_depth_to_color(depth, kd, kc, T)
    assert aligned.shape == (60, 80) and aligned.dtype == np.uint16
    hit = aligned > 0
    assert hit.mean() > 0.5 and (aligned[hit] == 1500).all()
    color = np.zeros((60, 80, 3), np.uint8)
    color[:, 40:] = 255  # right half white in the colour image
    resampled, valid = align_color_to_depth(color, depth, kd, kc, T)
    assert resampled.shape == (48, 64, 3) and valid.all()
    # the colour edge lands near the depth image's middle, shifted by the baseline
    # parallax f_d * b / z = 40 * 0.015 / 1.5 = 0.4 px
    edge = np.argmax(resampled[24, :, 0] > 0)
    assert abs(edge - 32) <= 1


def test_bad_input():
    k = CameraIntrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)
    with pytest.raises(InputError, match="intrinsics describe"):
        depth_to_points(np.zeros((4, 4), np.uint16), k)
    with pytest.raises(InputError, match="2-D"):
        depth_to_points(np.zeros((3, 4, 1)), k)
    with pytest.raises(InputError, match="depth_scale"):
        depth_to_points(np.zeros((3, 4)), k, 0.0)
    with pytest.raises(InputError, match="4x4"):
        texture_coordinates(np.zeros((1, 3)), np.eye(3), k)
    with pytest.raises(InputError, match="color_image"):
        sample_colors(np.zeros((3, 4)), np.zeros((1, 2)))


def _software_frames(depth, color, kd, kc, translation):
    """Push one depth and one colour frame through a pyrealsense2 software device and
    return rs2::pointcloud's vertices and texture coordinates for them (in the
    librealsense worker)."""
    di, ci = _rs_intr(kd), _rs_intr(kc)
    h, w = depth.shape
    hc, wc = color.shape[:2]
    dev = rs.software_device()
    ds, cs = dev.add_sensor("Depth"), dev.add_sensor("Color")
    streams = []
    for sensor, typ, uid, (sw, sh), bpp, fmt, intr in (
        (ds, rs.stream.depth, 0, (w, h), 2, rs.format.z16, di),
        (cs, rs.stream.color, 1, (wc, hc), 3, rs.format.rgb8, ci),
    ):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = typ, 0, uid, sw, sh
        vs.fps, vs.bpp, vs.fmt, vs.intrinsics = 30, bpp, fmt, intr
        streams.append(sensor.add_video_stream(vs))
    ex = rs.extrinsics()
    ex.rotation = [1, 0, 0, 0, 1, 0, 0, 0, 1]
    ex.translation = list(translation)
    streams[0].register_extrinsics_to(streams[1], ex)
    ds.add_read_only_option(rs.option.depth_units, 0.001)
    queue = rs.frame_queue(10)
    for sensor, prof in ((ds, streams[0]), (cs, streams[1])):
        sensor.open(prof)
        sensor.start(queue)
    for sensor, prof, pixels, bpp in ((ds, streams[0], depth, 2), (cs, streams[1], color, 3)):
        f = rs.software_video_frame()
        f.pixels, f.bpp, f.stride = pixels, bpp, bpp * pixels.shape[1]
        f.timestamp, f.domain, f.frame_number = 0.0, rs.timestamp_domain.hardware_clock, 0
        f.profile = prof.as_video_stream_profile()
        sensor.on_video_frame(f)
    frames = [queue.wait_for_frame(2000) for _ in range(2)]
    d = next(x for x in frames if x.profile.stream_type() == rs.stream.depth).as_depth_frame()
    c = next(x for x in frames if x.profile.stream_type() == rs.stream.color)
    pc = rs.pointcloud()
    pc.map_to(c)
    cloud = pc.calculate(d)
    vertices = np.asanyarray(cloud.get_vertices()).view(np.float32).reshape(-1, 3).copy()
    uv = np.asanyarray(cloud.get_texture_coordinates()).view(np.float32).reshape(-1, 2).copy()
    for sensor in (ds, cs):
        sensor.stop()
        sensor.close()
    return vertices, uv


def _rs_intr(k: CameraIntrinsics):
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = k.width, k.height, k.fx, k.fy, k.cx, k.cy
    i.model = getattr(rs.distortion, k.model)
    i.coeffs = list(k.coeffs)
    return i


@pytest.mark.parametrize(
    ("depth_model", "color_model"),
    [
        ("none", "none"),
        ("none", "inverse_brown_conrady"),
        ("none", "brown_conrady"),
        ("brown_conrady", "inverse_brown_conrady"),
    ],
)
def test_uv_match_librealsense_on_software_device_frames(depth_model, color_model, librealsense):
    # the colour side takes every lens model; the depth side has zero coefficients, as on
    # real D4xx depth streams: with non-zero ones, librealsense 2.59 itself disagrees
    # between rs2::pointcloud (one-step polynomial) and rs2_deproject_pixel_to_point
    # (iterative inversion, which deproject() matches)
    rng = np.random.default_rng(4)
    kd = CameraIntrinsics(64, 48, 50.0, 51.0, 31.7, 23.2, depth_model, (0.0,) * 5)
    kc = CameraIntrinsics(80, 60, 60.0, 60.5, 39.6, 29.8, color_model, (0.02, 0.01, 0.0, 0.0, 0.0))
    depth = rng.integers(400, 3000, (48, 64)).astype(np.uint16)
    depth[rng.random((48, 64)) < 0.1] = 0
    color = rng.integers(0, 255, (60, 80, 3), dtype=np.uint8)
    t = (-0.015, 0.001, 0.0002)
    work = librealsense.submit(_software_frames, depth, color, kd, kc, t)
    vertices, uv_ref = work.result(timeout=120)
    pts = depth_to_points(depth, kd, 0.001).reshape(-1, 3)
    uv, _ = texture_coordinates(pts, se3(None, t), kc)
    kept = vertices[:, 2] > 0
    assert kept.sum() > 1500
    np.testing.assert_allclose(pts[kept], vertices[kept], atol=1e-5)
    np.testing.assert_allclose(uv.reshape(-1, 2)[kept], uv_ref[kept], atol=1e-3)


@pytest.mark.parametrize("model", ["none", "brown_conrady", "inverse_brown_conrady"])
def test_project_to_color_matches_apply_then_project(model):
    # the compiled per-point form equals the NumPy path (apply, then project) to rounding
    rng = np.random.default_rng(9)
    kc = CameraIntrinsics(80, 60, 60.0, 60.5, 39.6, 29.8, model, (0.02, 0.01, 1e-3, -2e-3, 0.0))
    T = se3(np.array([0.01, -0.02, 0.005]), (-0.015, 0.001, 0.0002))
    pts = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(0.3, 3, 50)])
    ref = project(apply(T, pts), kc)
    k, code, c = compiled_params(kc)
    R, t = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])
    ours = np.array([project_to_color(*p, R, t, k, code, c) for p in pts])
    np.testing.assert_allclose(ours[:, :2], ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours[:, 2], apply(T, pts)[:, 2], atol=1e-15)
    u, v, z = project_to_color(0.0, 0.0, -1.0, np.eye(3), np.zeros(3), k, code, c)
    assert np.isnan(u) and np.isnan(v) and z == -1.0  # behind the colour camera


# issue 25: intrinsics of the wrong type, masks of the wrong shape, cameras too large
_K = CameraIntrinsics(4, 3, 2.0, 2.0, 1.5, 1.0)
_DEPTH = np.full((3, 4), 1000, np.uint16)
_COLOR = np.zeros((3, 4, 3), np.uint8)
_HUGE = CameraIntrinsics(65536, 65536, 500.0, 500.0, 32767.5, 32767.5)


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: pixel_rays(None), "intrinsics must be a CameraIntrinsics; got NoneType"),
        (lambda: pixel_rays(np.eye(3)), r"CameraIntrinsics\.from_matrix"),
        (lambda: pixel_rays(_HUGE), "65536x65536 image, more than 67108864 pixels"),
        (lambda: depth_to_points(_DEPTH, []), "intrinsics must be a CameraIntrinsics; got list"),
        (lambda: depth_to_points(_DEPTH, _K, organized="yes"), "organized must be True or"),
        (lambda: depth_to_points(_DEPTH.astype(np.float16), _K), r"depth\.astype\(np\.float32"),
        (lambda: texture_coordinates(np.zeros((1, 3)), np.eye(4), {}), "color_intrinsics must"),
        (lambda: texture_coordinates(np.zeros((1, 3)), np.eye(4), _HUGE), "more than 67108864"),
        (
            lambda: texture_coordinates(np.zeros((1, 3)), np.eye(4), _K, occlusion_tolerance=[1]),
            r"occlusion_tolerance \(metres, or None\) must be a real number",
        ),
        (lambda: texture_coordinates([["a", "b", "c"]], np.eye(4), _K), "points must hold real"),
        (lambda: sample_colors(_COLOR, np.zeros((5, 2)), np.ones((4, 3))), r"valid must be a bo"),
        (lambda: sample_colors(_COLOR, np.zeros((5, 2)), np.ones(5)), "valid must be a boolean"),
        (lambda: sample_colors(_COLOR, np.full((1, 1), np.inf)), r"uv must have shape \(\.\.\., 2"),
        (
            lambda: align_color_to_depth(_COLOR, _DEPTH, _K, np.eye(3), np.eye(4)),
            "color_intrinsics must be a CameraIntrinsics; got ndarray",
        ),
        (
            lambda: align_depth_to_color(_DEPTH, 3, _K, np.eye(4)),
            "depth_intrinsics must be a CameraIntrinsics; got int",
        ),
        (
            lambda: align_depth_to_color(_DEPTH, _K, "object", np.eye(4)),
            "color_intrinsics must be a CameraIntrinsics; got str",
        ),
        (lambda: align_depth_to_color(_DEPTH, _K, _K, np.eye(4), "3"), "depth_scale"),
    ],
)
def test_bad_arguments_give_input_errors(call, words):
    with pytest.raises(InputError, match=words):
        call()


def test_valid_edge_arguments_still_work():
    uv, valid = texture_coordinates(depth_to_points(_DEPTH, _K), np.eye(4), _K)
    # a mask given as a nested list of bools is a mask too
    got = sample_colors(_COLOR + 7, uv, valid.tolist())
    np.testing.assert_array_equal(got, sample_colors(_COLOR + 7, uv, valid))
    assert (got == 7).all()
    # a depth scale of numpy type, and a tiny positive one: z = s * D, not 0 or NaN
    pts = depth_to_points(_DEPTH, _K, np.float32(0.001), organized=np.True_)
    assert pts[1, 1, 2] == pytest.approx(1.0)
    with pytest.warns(DepthScaleWarning, match="implausible"):  # 1e-297 m: issue 48
        assert depth_to_points(_DEPTH, _K, 1e-300)[1, 1, 2] == pytest.approx(1e-297)
