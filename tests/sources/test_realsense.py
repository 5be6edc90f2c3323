"""RealSenseSource: recordings read with rosbags (no librealsense in this process),
checked frame for frame against librealsense's own playback (pyrealsense2, in the
librealsense worker process) on the real recording and on recordings written at test
time: ``.db3`` by a pyrealsense2 software device and its recorder, ``.bag`` by rosbags in
librealsense's ROS 1 layout (which librealsense plays back too)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.pipelines import PlaneTracker
from robopercept.sources.realsense import RealSenseSource, import_pyrealsense2
from robopercept.sources.realsense_recording import RealSenseRecording, pair_nearest_color

try:
    import pyrealsense2 as rs
except ImportError:  # the recordings' tests that need no reference still run
    rs = None

needs_rs = pytest.mark.skipif(rs is None, reason="pyrealsense2 (the reference) not installed")

BAG = Path(__file__).parents[2] / ".." / "shared" / "data" / "rgbd" / "realsense_bag"
BAG = BAG / "single_depth_color_640x480.bag"


def _real_bag() -> Path:
    if not BAG.exists():
        pytest.skip(f"{BAG} absent")
    return BAG


def _intr(w, h, model=None):
    i = rs.intrinsics()
    i.width, i.height, i.fx, i.fy, i.ppx, i.ppy = w, h, 50.0, 51.0, w / 2 - 0.3, h / 2 + 0.2
    i.model, i.coeffs = model or rs.distortion.none, [0.0] * 5
    return i


def record(path, n=5, with_color=True, w=64, h=48):
    """Write a .db3 recording of n depth (+ colour) frames through a software device:
    depth frame i is 1000 + i everywhere, colour frame i is (i, 200, i)."""
    dev = rs.software_device()
    ds = dev.add_sensor("Depth")
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid, vs.width, vs.height = rs.stream.depth, 0, 0, w, h
    vs.fps, vs.bpp, vs.fmt, vs.intrinsics = 30, 2, rs.format.z16, _intr(w, h)
    dprof = ds.add_video_stream(vs)
    ds.add_read_only_option(rs.option.depth_units, 0.001)
    sensors = [(ds, dprof, 2)]
    if with_color:
        cs = dev.add_sensor("Color")
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid, vs.width, vs.height = rs.stream.color, 0, 1, w, h
        vs.fps, vs.bpp, vs.fmt = 30, 3, rs.format.rgb8
        vs.intrinsics = _intr(w, h, rs.distortion.inverse_brown_conrady)
        cprof = cs.add_video_stream(vs)
        ex = rs.extrinsics()
        ex.rotation = [1, 0, 0, 0, 1, 0, 0, 0, 1]
        ex.translation = [0.015, 0.001, 0.0]
        dprof.register_extrinsics_to(cprof, ex)
        sensors.append((cs, cprof, 3))
    rec = rs.recorder(str(path), dev)
    queue = rs.frame_queue(100)
    for s, p, _ in sensors:
        s.open(p)
        s.start(queue)
    for i in range(n):
        for s, p, bpp in sensors:
            f = rs.software_video_frame()
            pix = (
                np.full((h, w), 1000 + i, np.uint16)
                if bpp == 2
                else np.full((h, w, 3), i, np.uint8)
            )
            if bpp == 3:
                pix[..., 1] = 200  # R, G, B distinguishable
            f.pixels, f.bpp, f.stride = pix, bpp, bpp * w
            f.timestamp, f.domain, f.frame_number = (
                i * 1000 / 30,
                rs.timestamp_domain.hardware_clock,
                i,
            )
            f.profile = p.as_video_stream_profile()
            s.on_video_frame(f)
        time.sleep(0.05)
    time.sleep(1.0)  # let the recorder write the last frames before the sensors stop
    for s, _, _ in sensors:
        s.stop()
        s.close()
    del rec


def _record(pool, path, *args, **kwargs) -> None:
    """:func:`record` in the librealsense worker process."""
    pool.submit(record, str(path), *args, **kwargs).result(timeout=120)


_RS_MODEL_NAMES = {
    "none": "None",
    "brown_conrady": "Brown Conrady",
    "modified_brown_conrady": "Modified Brown Conrady",
    "inverse_brown_conrady": "Inverse Brown Conrady",
}


def write_ros1_bag(path, frames, *, compression=None, color_encoding="rgb8", depth_size=None):
    """Write ``frames`` as librealsense's ROS 1 recorder lays a ``.bag`` out (file
    version 3), with rosbags' writer: stream info, CameraInfo, the Depth Units option,
    the streams' transforms to their group's reference (depth: identity), then per frame
    a mono16 depth and a colour Image (header stamp = the frame's time + 1 ms) with their
    metadata. librealsense 2.59 plays these back (``test_recordings_equal_...``).
    ``depth_size`` overrides the width and height of every depth image (a bad one)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from scipy.spatial.transform import Rotation

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(
        get_types_from_msg(
            "uint32 fps\nstring encoding\nbool is_recommended\n", "realsense_msgs/msg/StreamInfo"
        )
    )
    M = store.types
    Header, Time, KV = M["std_msgs/msg/Header"], M["builtin_interfaces/msg/Time"], None
    KV = M["diagnostic_msgs/msg/KeyValue"]
    f0 = frames[0]

    def caminfo(k):
        K = np.array([k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1], np.float64)
        roi = M["sensor_msgs/msg/RegionOfInterest"](0, 0, 0, 0, False)
        return M["sensor_msgs/msg/CameraInfo"](
            Header(0, Time(0, 0), ""), k.height, k.width, _RS_MODEL_NAMES[k.model],
            np.array(k.coeffs, np.float64), K, np.zeros(9), np.zeros(12), 0, 0, roi,
        )  # fmt: skip

    def transform(T):
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        return M["geometry_msgs/msg/Transform"](
            M["geometry_msgs/msg/Vector3"](*T[:3, 3]), M["geometry_msgs/msg/Quaternion"](x, y, z, w)
        )

    writer = Writer(Path(path))
    if compression is not None:
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with writer as w:

        def put(conn, t, msg):
            w.write(conn, t, store.serialize_ros1(msg, conn.msgtype))

        def conn(topic, typ):
            return w.add_connection(topic, typ, typestore=store)

        d, c = "/device_0/sensor_0/Depth_0", "/device_0/sensor_1/Color_0"
        put(conn("/file_version", "std_msgs/msg/UInt32"), 1, M["std_msgs/msg/UInt32"](3))
        info = M["realsense_msgs/msg/StreamInfo"]
        put(conn(d + "/info", info.__msgtype__), 1, info(30, "mono16", True))
        put(
            conn(d + "/info/camera_info", "sensor_msgs/msg/CameraInfo"),
            1,
            caminfo(f0.depth_intrinsics),
        )
        put(conn(c + "/info", info.__msgtype__), 1, info(30, color_encoding, True))
        put(
            conn(c + "/info/camera_info", "sensor_msgs/msg/CameraInfo"),
            1,
            caminfo(f0.color_intrinsics),
        )
        dev = conn("/device_0/info", "diagnostic_msgs/msg/KeyValue")
        put(dev, 1, KV("Name", "Intel RealSense D435"))
        put(dev, 1, KV("Serial Number", "000000000000"))
        put(
            conn("/device_0/sensor_0/info", "diagnostic_msgs/msg/KeyValue"),
            1,
            KV("Name", "Stereo Module"),
        )
        put(
            conn("/device_0/sensor_1/info", "diagnostic_msgs/msg/KeyValue"),
            1,
            KV("Name", "RGB Camera"),
        )
        units = M["std_msgs/msg/Float32"](f0.depth_scale)
        put(conn("/device_0/sensor_0/option/Depth Units/value", "std_msgs/msg/Float32"), 1, units)
        put(conn(d + "/tf/0", "geometry_msgs/msg/Transform"), 1, transform(np.eye(4)))
        put(conn(c + "/tf/0", "geometry_msgs/msg/Transform"), 1, transform(f0.T_color_depth))
        images = {k: conn(k + "/image/data", "sensor_msgs/msg/Image") for k in (d, c)}
        meta = {k: conn(k + "/image/metadata", "diagnostic_msgs/msg/KeyValue") for k in (d, c)}
        for i, f in enumerate(frames):
            ns = 1_000_000 + round(f.timestamp * 1e9)
            stamp = Time(ns // 10**9, ns % 10**9)
            h, wd = f.depth.shape if depth_size is None else depth_size[::-1]
            pix = np.frombuffer(f.depth.astype("<u2").tobytes(), np.uint8)
            img = M["sensor_msgs/msg/Image"](Header(i, stamp, "0"), h, wd, "mono16", 0, 2 * wd, pix)
            put(images[d], ns, img)
            h, wd, _ = f.color.shape
            pix = np.ascontiguousarray(f.color).reshape(-1)
            img = M["sensor_msgs/msg/Image"](Header(i, stamp, "0"), h, wd, "rgb8", 0, 3 * wd, pix)
            put(images[c], ns + 1000, img)
            for k, t in ((d, ns), (c, ns + 1000)):
                put(meta[k], t, KV("timestamp_domain", "Hardware Clock"))
                put(meta[k], t, KV("Frame Counter", str(i)))


def _scene(n=6, depth=(64, 48), color=(80, 60)):
    from robopercept.sources import SyntheticRGBDScene

    return list(SyntheticRGBDScene(n_frames=n, depth_size=depth, color_size=color))


def _bag_calibration(path: str):
    """Depth intrinsics and depth-to-colour transform of a recording, as librealsense's
    playback device reports them (in the librealsense worker process). The profiles are
    read without streaming: a pipeline started on the real bag here once aborted the
    worker inside librealsense (``malloc_consolidate(): invalid chunk size``), and no
    stream threads means nothing of that kind can run (same values as the pipeline's)."""
    from robopercept.sources.realsense import intrinsics_from_rs, transform_from_rs

    dev = rs.context().load_device(path)
    dev.as_playback().set_real_time(False)
    profiles = {}
    for sensor in dev.query_sensors():
        for p in sensor.get_stream_profiles():
            profiles.setdefault(p.stream_type(), p.as_video_stream_profile())
    d, c = profiles[rs.stream.depth], profiles[rs.stream.color]
    return intrinsics_from_rs(d.get_intrinsics()), transform_from_rs(d.get_extrinsics_to(c))


def _librealsense_playback(path: str) -> dict:
    """Every frame of each stream as librealsense's playback device gives it (not in
    real time, and paused while the sensors start, so that no frame is lost), with the
    calibration its profiles and depth sensor report (in the librealsense worker)."""
    from robopercept.sources.realsense import intrinsics_from_rs, transform_from_rs
    from robopercept.sources.realsense_recording import rgb_from

    dev = rs.context().load_device(path)
    playback = dev.as_playback()
    playback.set_real_time(False)
    playback.pause()
    sensors = list(dev.query_sensors())
    profiles = {}
    for sensor in sensors:
        for p in sensor.get_stream_profiles():
            profiles.setdefault(p.stream_type(), p.as_video_stream_profile())
    d, c = profiles[rs.stream.depth], profiles[rs.stream.color]
    out = {
        "kd": intrinsics_from_rs(d.get_intrinsics()),
        "kc": intrinsics_from_rs(c.get_intrinsics()),
        "T": transform_from_rs(d.get_extrinsics_to(c)),
        "scale": float(dev.first_depth_sensor().get_depth_scale()),
        "depth": [],
        "color": [],
    }
    queue = rs.frame_queue(10_000, keep_frames=True)
    for s in sensors:
        s.open(s.get_stream_profiles())
    for s in sensors:
        s.start(queue)
    playback.resume()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        ok, f = queue.try_wait_for_frame(300)
        if not ok:
            if playback.current_status() != rs.playback_status.playing:
                break
            continue
        data = np.asanyarray(f.get_data()).copy()
        if f.profile.stream_type() == rs.stream.depth:
            out["depth"].append((f.get_frame_number(), f.get_timestamp(), data))
        else:
            fmt = str(f.profile.format()).split(".")[-1]
            out["color"].append((f.get_timestamp(), np.ascontiguousarray(rgb_from(data, fmt))))
    for s in sensors:
        s.stop()
        s.close()
    return out


def _nearest(t: float, stamps: list[float]) -> int:
    """The index of the stamp nearest to ``t``, the earlier on a tie."""
    return int(np.argmin(np.abs(np.asarray(stamps) - t)))


@pytest.mark.parametrize("kind", ["real .bag", "software .db3", "synthetic .db3", "synthetic .bag"])
@needs_rs
def test_recordings_equal_librealsense_playback(kind, tmp_path, librealsense):
    # every depth frame librealsense plays, in its order, with the same pixels and
    # timestamps (get_timestamp, in ms: the header stamp of a ROS 1 bag, the metadata's
    # timestamp in a ROS 2 .db3), paired with the colour frame librealsense plays
    # nearest in time; intrinsics, extrinsics and depth scale to the last bit (float32)
    truth = None
    if kind == "real .bag":
        path = _real_bag()
    elif kind == "software .db3":
        path = tmp_path / "rec.db3"
        _record(librealsense, path, n=8)
        truth = list(range(8))  # depth k with colour k
    elif kind == "synthetic .db3":
        from robopercept.sources.realsense import write_realsense_recording

        path = tmp_path / "s.db3"
        write_realsense_recording(path, _scene(), pace=0.02)
    else:
        path = tmp_path / "s.bag"
        write_ros1_bag(path, _scene())
        truth = list(range(6))
    ref = librealsense.submit(_librealsense_playback, str(path)).result(timeout=120)
    frames = list(RealSenseSource(path))
    assert len(frames) == len(ref["depth"]) > 0
    stamps = [t for t, _ in ref["color"]]
    t0 = ref["depth"][0][1] / 1000.0
    paired = []
    for f, (_, ms, depth) in zip(frames, ref["depth"], strict=True):
        assert np.array_equal(f.depth, depth)
        # exact: both are get_timestamp() / 1000 minus the first's
        assert f.timestamp == ms / 1000.0 - t0
        j = _nearest(ms, stamps)
        assert np.array_equal(f.color, ref["color"][j][1])
        paired.append(j)
        assert (f.depth_intrinsics, f.color_intrinsics) == (ref["kd"], ref["kc"])
        np.testing.assert_array_equal(f.T_color_depth, ref["T"])
        assert f.depth_scale == ref["scale"]
    if truth is not None:
        assert paired == truth
    if kind == "synthetic .db3":  # librealsense's recorder may lose the first frameset
        assert len(frames) >= 4


@pytest.mark.realdata
@needs_rs
def test_real_recording(librealsense):
    path = _real_bag()
    # the recording holds two depth frames (librealsense numbers 169 and 170, 166.7 ms
    # apart) and one colour frame 102 ms before the first: each depth frame comes back
    # with it (a pipeline dropped the first depth frame, which came before any colour)
    frames = list(RealSenseSource(path))
    assert len(frames) == 2
    assert np.array_equal(frames[0].color, frames[1].color)
    assert not np.array_equal(frames[0].depth, frames[1].depth)
    assert [f.index for f in frames] == [0, 1]
    assert frames[1].timestamp == pytest.approx(0.166676, abs=1e-9)
    f = frames[0]
    assert f.depth.shape == (480, 640) and f.depth.dtype == np.uint16
    assert f.color.shape == (480, 640, 3) and f.color.dtype == np.uint8
    assert f.depth.flags.writeable and f.color.flags.c_contiguous
    assert f.depth_scale == pytest.approx(0.001)
    assert (f.depth > 0).mean() > 0.5
    # the intrinsics and extrinsics are librealsense's own, read back through pyrealsense2
    k, T = librealsense.submit(_bag_calibration, str(path)).result(timeout=120)
    assert k == f.depth_intrinsics
    np.testing.assert_array_equal(T, f.T_color_depth)
    # the tracker runs on it (no green board in this scene: a row, no crash)
    r = PlaneTracker().process(f)
    assert r.n_points == int((f.depth > 0).sum())
    with pytest.raises(InputError, match="watchdog must be a positive"):
        RealSenseSource(path, watchdog=0)


@needs_rs
def test_software_device_recording_plays_back_in_order_and_in_sync(tmp_path, librealsense):
    # every recorded frame comes back, in order, each depth with its own colour (the
    # recorder writes depth k before colour k, at the same frame timestamp)
    path = tmp_path / "rec.db3"
    _record(librealsense, path, n=8)
    src = RealSenseSource(path, timeout=1.0)
    frames = list(src)
    assert len(frames) == 8
    for j, f in enumerate(frames):
        assert f.index == j
        assert (f.depth == 1000 + j).all()
        assert (f.color[..., 0] == j).all() and (f.color[..., 1] == 200).all()
        assert f.timestamp == pytest.approx(j / 30, abs=1e-6)
    f = frames[0]
    assert f.color_intrinsics.model == "inverse_brown_conrady"
    assert (f.depth_intrinsics.fx, f.depth_intrinsics.fy) == (50.0, 51.0)
    np.testing.assert_allclose(f.T_color_depth[:3, 3], [0.015, 0.001, 0.0], atol=1e-7)
    assert src.skipped == []
    assert len(list(RealSenseSource(path, max_frames=3))) == 3
    assert [f.index for f in src] == list(range(8))  # a second pass plays it again


@needs_rs
def test_recording_without_colour_is_refused(tmp_path, librealsense):
    path = tmp_path / "depth_only.db3"
    _record(librealsense, path, n=2, with_color=False)
    with pytest.raises(InputError, match="no colour stream"):
        RealSenseSource(path)


def test_recordings_play_without_pyrealsense2(tmp_path, monkeypatch):
    # issue 48: pyrealsense2 is needed for a live camera only
    monkeypatch.setitem(sys.modules, "pyrealsense2", None)
    with pytest.raises(InputError, match=r"robopercept\[realsense\]"):
        import_pyrealsense2()
    with pytest.raises(InputError, match=r"robopercept\[realsense\]"):
        RealSenseSource(None)  # a live camera
    with pytest.raises(FileFormatError, match=r"nope\.bag: recording not found"):
        RealSenseSource(tmp_path / "nope.bag")
    write_ros1_bag(tmp_path / "s.bag", _scene(3))
    frames = list(RealSenseSource(tmp_path / "s.bag"))
    assert [f.index for f in frames] == [0, 1, 2]
    if BAG.exists():
        assert len(list(RealSenseSource(BAG))) == 2


def _plane_track_without_pyrealsense2(source: Path, out: Path) -> subprocess.CompletedProcess:
    """``python -m robopercept.cli.main plane-track --source SOURCE ... --json`` in a
    fresh interpreter where ``import pyrealsense2`` fails."""
    code = (
        "import sys, runpy\n"
        "sys.modules['pyrealsense2'] = None\n"
        "try:\n"
        "    import pyrealsense2\n"
        "    raise SystemExit('pyrealsense2 is importable')\n"
        "except ImportError:\n"
        "    pass\n"
        "sys.argv = ['robopercept'] + sys.argv[1:]\n"
        "runpy.run_module('robopercept.cli.main', run_name='__main__')\n"
    )
    args = ["plane-track", "--source", str(source), "--out", str(out), "--no-video"]
    return subprocess.run(
        [sys.executable, "-c", code, *args, "--quiet", "--json"],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_plane_track_on_a_bag_without_pyrealsense2(tmp_path):
    # issue 48 acceptance: the synthetic board scene (small) as a librealsense-layout
    # ROS 1 .bag, tracked by the CLI in an interpreter that cannot import pyrealsense2
    frames = _scene(8, depth=(212, 120), color=(320, 180))
    write_ros1_bag(tmp_path / "board.bag", frames, compression="lz4")
    r = _plane_track_without_pyrealsense2(tmp_path / "board.bag", tmp_path / "out")
    assert r.returncode == 0, r.stderr[-2000:]
    summary = json.loads(r.stdout)["summary"]
    assert summary["frames"] == 8 and summary["skipped_frames"] == 0
    assert summary["measured_frames"] >= 6  # the board is found in (nearly) every frame
    assert (tmp_path / "out" / "plane.csv").is_file()


@needs_rs
def test_write_realsense_recording_round_trips_calibration(tmp_path):
    # the synthetic scene's frames through the software device and recorder: the same
    # depth, colour, intrinsics (float32 in librealsense), extrinsics and depth scale
    from robopercept.sources.realsense import write_realsense_recording

    frames = _scene(12)
    assert write_realsense_recording(tmp_path / "s.db3", frames) == 12
    back = list(RealSenseSource(tmp_path / "s.db3", timeout=1.0))
    # librealsense's recorder may lose frames at the ends of a short recording under
    # load (seen in CI: 3 of 6); what comes back is consecutive and exact
    assert len(back) >= 6
    k0 = next(k for k, f in enumerate(frames) if np.array_equal(f.depth, back[0].depth))
    for j, f in enumerate(back):
        assert np.array_equal(f.depth, frames[k0 + j].depth)
        assert np.array_equal(f.color, frames[k0 + j].color)
    kd, kd2 = frames[0].depth_intrinsics, back[0].depth_intrinsics
    assert (kd2.width, kd2.height) == (kd.width, kd.height)
    np.testing.assert_allclose([kd2.fx, kd2.cx, kd2.cy], [kd.fx, kd.cx, kd.cy], rtol=1e-6)
    # librealsense keeps extrinsics in float32 and its recorder rounds them again:
    # within 1e-6 (a micrometre, a microradian)
    np.testing.assert_allclose(back[0].T_color_depth, frames[0].T_color_depth, atol=1e-6)
    assert back[0].depth_scale == pytest.approx(frames[0].depth_scale)
    with pytest.raises(InputError, match="no frames"):
        write_realsense_recording(tmp_path / "e.db3", [])


@pytest.mark.parametrize("compression", [None, "bz2", "lz4"])
def test_ros1_chunk_compressions_read_alike(tmp_path, compression):
    frames = _scene(4)
    write_ros1_bag(tmp_path / "c.bag", frames, compression=compression)
    back = list(RealSenseSource(tmp_path / "c.bag"))
    assert len(back) == 4
    for a, b in zip(back, frames, strict=True):
        assert np.array_equal(a.depth, b.depth) and np.array_equal(a.color, b.color)
        assert a.timestamp == pytest.approx(b.timestamp, abs=1e-9)
    # through float32, as librealsense holds calibration
    np.testing.assert_allclose(back[0].T_color_depth, frames[0].T_color_depth, atol=1e-7)
    assert back[0].depth_intrinsics.fx == pytest.approx(frames[0].depth_intrinsics.fx, rel=1e-7)


def test_unreadable_frames_are_skipped_and_counted(tmp_path):
    # a depth image whose size is not its stream's: each frame is skipped, warned
    # about and recorded, as every source does
    write_ros1_bag(tmp_path / "size.bag", _scene(3), depth_size=(32, 48))
    src = RealSenseSource(tmp_path / "size.bag")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        assert list(src) == []
    assert [i for i, _ in src.skipped] == [0, 1, 2]
    assert str(said[0].message) == "skipping frame 0: depth image is 32x48, not 64x48"
    # colour in a format the frames cannot be converted from: refused when opened
    write_ros1_bag(tmp_path / "yuyv.bag", _scene(2), color_encoding="yuyv")
    with pytest.raises(InputError, match="colour stream format 'yuyv' is not supported"):
        RealSenseSource(tmp_path / "yuyv.bag")


@needs_rs
def test_a_broken_png_frame_in_a_db3_is_skipped(tmp_path, librealsense):
    import sqlite3

    path = tmp_path / "png.db3"
    _record(librealsense, path, n=4)
    con = sqlite3.connect(path)
    mid, data = con.execute(
        "SELECT m.id, m.data FROM messages m JOIN topics t ON m.topic_id = t.id "
        "WHERE t.name LIKE '%Depth_0/image/data%' ORDER BY m.timestamp LIMIT 1 OFFSET 2"
    ).fetchone()
    bad = bytearray(data)
    at = bad.index(b"IDAT") + 8
    bad[at : at + 16] = bytes(16)  # the zlib stream of the PNG
    con.execute("UPDATE messages SET data = ? WHERE id = ?", (bytes(bad), mid))
    con.commit()
    con.close()
    src = RealSenseSource(path)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        frames = list(src)
    assert [f.index for f in frames] == [0, 1, 3]
    assert [i for i, _ in src.skipped] == [2]
    assert any("skipping frame 2" in str(w.message) for w in said)
    assert (frames[2].depth == 1003).all() and (frames[2].color[..., 0] == 3).all()


def test_pairing_takes_the_colour_frame_nearest_in_time():
    # the pairing on scripted events: depth k with colour k whichever comes first
    ev = [("depth", 33.3 * k, f"d{k}") for k in range(4)]
    col = [("color", 33.3 * k, f"c{k}") for k in range(4)]
    order = [ev[0], col[0], ev[1], col[1], ev[2], col[2], col[3], ev[3]]
    assert list(pair_nearest_color(order)) == [(f"d{k}", f"c{k}") for k in range(4)]
    # the real bag's layout: depth, one colour frame 102 ms before it, depth 167 ms
    # later: both depth frames get that colour frame (the second at the end)
    bag = [("depth", 360815.089, "a"), ("color", 360713.523, "c"), ("depth", 360981.765, "b")]
    assert list(pair_nearest_color(bag)) == [("a", "c"), ("b", "c")]
    # between two colour frames, the nearer one (the earlier on a tie)
    mid = [("color", 0.0, "c0"), ("depth", 20.0, "d"), ("color", 33.0, "c1")]
    assert list(pair_nearest_color(mid)) == [("d", "c1")]
    tie = [("color", 0.0, "c0"), ("depth", 10.0, "d"), ("color", 20.0, "c1")]
    assert list(pair_nearest_color(tie)) == [("d", "c0")]
    # no colour at all: paired with None (the reader skips and counts them), the oldest
    # first once more than max_waiting wait
    lone = [("depth", 10.0 * k, f"d{k}") for k in range(4)]
    assert list(pair_nearest_color(lone, max_waiting=2)) == [(f"d{k}", None) for k in range(4)]


# issue 25 / 48: damaged recordings are FileFormatErrors naming the file, now raised by
# rosbags (or SQLite), which reads in this process and cannot crash or hang it as
# librealsense did


def _bag_length_words(data):
    """Offsets of every top-level record's header_len and data_len words, walked here
    independently of the code under test (ROS bag 2.0: magic, then records
    <header_len:u32><header><data_len:u32><data>)."""
    import struct

    assert data[:13] == b"#ROSBAG V2.0\n"
    off, words = 13, []
    while off < len(data):
        (hlen,) = struct.unpack_from("<I", data, off)
        (dlen,) = struct.unpack_from("<I", data, off + 4 + hlen)
        words += [off, off + 4 + hlen]
        off += 8 + hlen + dlen
    assert off == len(data)
    return words


def _same_frames(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x.depth, y.depth)
        and np.array_equal(x.color, y.color)
        and x.timestamp == y.timestamp
        and x.depth_intrinsics == y.depth_intrinsics
        and np.array_equal(x.T_color_depth, y.T_color_depth)
        for x, y in zip(a, b, strict=True)
    )


@pytest.mark.realdata
def test_bag_with_broken_length_words_is_refused_or_read_intact(tmp_path):
    data = _real_bag().read_bytes()
    good = list(RealSenseSource(BAG))
    words = _bag_length_words(data)
    # header_len and data_len of the bag header, the chunk and the first index record,
    # then a sample of the rest: refused naming the file, or (a length rosbags never
    # needs: the index records of topics not read) the very frames of the intact file
    refused = 0
    for off in words[:6] + words[6::11] + words[-2:]:
        bad = bytearray(data)
        bad[off : off + 4] = b"\xff\xff\xff\xff"
        path = tmp_path / f"ff_{off}.bag"
        path.write_bytes(bytes(bad))
        try:
            frames = list(RealSenseSource(path))
        except FileFormatError as exc:
            assert f"ff_{off}.bag: " in str(exc)
            refused += 1
        else:
            assert _same_frames(frames, good), off
        path.unlink()
    assert refused >= 20  # of 34 (220 of all 294 words)
    for n in (0, 12, 13, 100, 4117, 500_000, len(data) - 1):
        path = tmp_path / f"cut_{n}.bag"
        path.write_bytes(data[:n])
        with pytest.raises(FileFormatError, match=rf"cut_{n}\.bag: .*truncated or corrupt"):
            RealSenseSource(path)
    # the chunk record's header_len set to 0xFFFFFFFF made librealsense 2.59 spin forever
    chunk = words[2]
    bad = bytearray(data)
    bad[chunk : chunk + 4] = b"\xff\xff\xff\xff"
    (tmp_path / "hang.bag").write_bytes(bytes(bad))
    t = time.monotonic()
    with pytest.raises(FileFormatError, match=r"hang\.bag"):
        list(RealSenseSource(tmp_path / "hang.bag"))
    assert time.monotonic() - t < 5


@pytest.mark.realdata
def test_bag_chunk_and_index_fields_are_checked(tmp_path):
    import struct

    data = _real_bag().read_bytes()
    # the real bag: one lz4 chunk of 747,730 bytes holding 1,578,062 (2.1:1)
    chunk = _bag_length_words(data)[2]
    at = data.index(b"size=", chunk) + 5
    assert struct.unpack_from("<I", data, at)[0] == 1_578_062

    def patched(name, offset, new):
        bad = bytearray(data)
        bad[offset : offset + len(new)] = new
        (tmp_path / name).write_bytes(bytes(bad))
        return tmp_path / name

    # uncompressed size beyond lz4's 255:1 (and the 1 GiB cap), or below half the data:
    # refused before anything is decompressed
    for v in (0xFFFFFFFF, 0x7FFFFFFF, 255 * 747_730 + 65, 0, 373_800):
        p = patched(f"size_{v}.bag", at, struct.pack("<I", v))
        with pytest.raises(
            FileFormatError,
            match=rf"size_{v}\.bag: byte offset {chunk}: lz4 chunk of 747730 bytes claims an "
            rf"uncompressed size of {v} ",
        ):
            RealSenseSource(p)
    # within lz4's bounds but not what the chunk holds: refused when it is read
    for v, held in ((373_801, "more than 373801"), (1_578_063, "1578062, not 1578063")):
        p = patched(f"ok_{v}.bag", at, struct.pack("<I", v))
        with pytest.raises(FileFormatError, match=rf"ok_{v}\.bag: .*chunk holds {held} bytes"):
            list(RealSenseSource(p))
    # compression neither rosbags nor librealsense decodes
    c = data.index(b"compression=lz4", chunk) + len(b"compression=")
    with pytest.raises(FileFormatError, match=r"lz5\.bag: .*Compression 'lz5' is not supported"):
        RealSenseSource(patched("lz5.bag", c, b"lz5"))
    # an index record whose count disagrees with its data, or that is not an index
    # record; one that names no connection leaves its topic (/file_version, not read)
    # without messages: the frames are intact
    idx = _bag_length_words(data)[4]  # the first index data record (conn 0, count 1)
    cnt = data.index(b"count=", idx) + 6
    op = data.index(b"op=\x04", idx) + 3
    for name, offset, new in (("count.bag", cnt, struct.pack("<I", 2)), ("op.bag", op, b"\x02")):
        with pytest.raises(FileFormatError, match=rf"{name}: not a readable RealSense .*check"):
            list(RealSenseSource(patched(name, offset, new)))
    conn = data.index(b"conn=", idx) + 5
    bad = RealSenseSource(patched("conn.bag", conn, struct.pack("<I", 0x1234)))
    assert _same_frames(list(bad), list(RealSenseSource(BAG)))


@needs_rs
def test_corrupt_db3_recording_gives_file_format_error(tmp_path, librealsense):
    import sqlite3

    path = tmp_path / "rec.db3"
    _record(librealsense, path, n=2)
    assert len(list(RealSenseSource(path))) == 2  # a sound recording plays
    data = path.read_bytes()
    for name, bad in (
        ("cut.db3", data[: len(data) // 2]),
        ("page.db3", data[:4096] + bytes(4096) + data[8192:]),
        ("text.db3", b"not a database\n" * 10),
        ("empty.db3", b""),
    ):
        (tmp_path / name).write_bytes(bad)
        with pytest.raises(FileFormatError, match=name) as info:
            RealSenseSource(tmp_path / name)  # at once, before any frame
        assert not isinstance(info.value, sqlite3.Error)
    con = sqlite3.connect(tmp_path / "other.db3")  # sound SQLite, not a ROS2 bag
    con.execute("CREATE TABLE t (x)")
    con.commit()
    con.close()
    with pytest.raises(FileFormatError, match=r"other\.db3: .*missing tables"):
        RealSenseSource(tmp_path / "other.db3")


def _edit_db3(path, sql, *params):
    import sqlite3

    con = sqlite3.connect(path)
    con.execute(sql, params)
    con.commit()
    con.close()


@needs_rs
def test_db3_messages_that_crashed_or_hung_librealsense_give_file_format_error(
    tmp_path, librealsense
):
    # fuzz findings of issue 25, read in this process now: one byte of the
    # depth-to-colour transform text set to 0xAC made librealsense segfault
    import sqlite3

    path = tmp_path / "tf.db3"
    _record(librealsense, path, n=3)
    con = sqlite3.connect(path)
    rows = con.execute(
        "SELECT m.id, m.data FROM messages m JOIN topics t ON m.topic_id = t.id "
        "WHERE t.name LIKE '%/tf/ref_%'"
    ).fetchall()
    con.close()
    assert rows and all(b"rotation=1.000000," in bytes(d) for _, d in rows)
    for mid, data in rows:
        bad = bytearray(data)
        bad[bad.index(b"rotation=1.000000,") + 17] = 0xAC  # the first ','
        _edit_db3(path, "UPDATE messages SET data = ? WHERE id = ?", bytes(bad), mid)
    with pytest.raises(FileFormatError, match=r"tf\.db3: .*/tf/ref_1.*0xac"):
        RealSenseSource(path)
    # ... and a topic name with the bytes 00 00 00 80 in it made it spin forever
    path = tmp_path / "name.db3"
    _record(librealsense, path, n=3)
    _edit_db3(
        path,
        "UPDATE topics SET name = CAST(? AS TEXT) WHERE name LIKE '%Frames_Queue_Size/value'"
        " AND id = (SELECT MIN(id) FROM topics WHERE name LIKE '%Frames_Queue_Size/value')",
        b"/device_0/sensor_0/opt\x00\x00\x00\x80Frames_Queue_Size/value",
    )
    t = time.monotonic()
    with pytest.raises(FileFormatError, match=r"name\.db3: .*UnicodeDecodeError"):
        RealSenseSource(path)
    assert time.monotonic() - t < 5


def test_write_realsense_recording_keeps_librealsense_out_of_this_process(tmp_path, monkeypatch):
    # librealsense's recorder threads and the software device's teardown can abort the
    # process that held them, later and at random (CI died so): the recording is made in
    # a child process, so no SoftwareCamera is ever built here
    pytest.importorskip("pyrealsense2")
    from robopercept.sources import realsense

    def refuse(*args, **kwargs):
        raise AssertionError("a SoftwareCamera was built in the calling process")

    monkeypatch.setattr(realsense.SoftwareCamera, "__init__", refuse)
    frames = _scene(4, color=(80, 60))
    assert realsense.write_realsense_recording(tmp_path / "c.db3", frames, pace=0.0) == 4
    assert (tmp_path / "c.db3").stat().st_size > 0


def test_write_realsense_recording_names_what_failed_in_the_child(tmp_path, monkeypatch):
    pytest.importorskip("pyrealsense2")
    from robopercept.sources import realsense
    from robopercept.sources.realsense import SourceError, write_realsense_recording

    frames = _scene(2)
    # a missing folder no longer makes librealsense fail (issue 47 R59: the recording is
    # written to a temporary name through fileio.atomic_path, which creates the folder);
    # a recorder that writes part of its file and answers with librealsense's error
    with monkeypatch.context() as m:
        m.setattr(
            realsense,
            "_RECORDER",
            "import sys, os; from robopercept.sources.realsense import _send; "
            "open(sys.argv[1], 'wb').write(b'partial'); "
            "_send(os.fdopen(1, 'wb'), b'E', ('', 'RuntimeError: Failed to setup storage'))",
        )
        with pytest.raises(SourceError, match=r"librealsense failed writing .*x\.db3: .*storage"):
            write_realsense_recording(tmp_path / "no_dir" / "x.db3", frames, pace=0.0)
    assert list((tmp_path / "no_dir").iterdir()) == []  # no partial recording left
    with pytest.raises(InputError, match="pace"):
        write_realsense_recording(tmp_path / "y.db3", frames, pace=-1.0)


def test_recording_attributes_and_bad_paths(tmp_path):
    write_ros1_bag(tmp_path / "s.bag", _scene(3))
    rec = RealSenseRecording(tmp_path / "s.bag")
    assert (rec.ros1, rec.depth_frames, rec.color_frames) == (True, 3, 3)
    assert rec.depth_scale == pytest.approx(_scene(1)[0].depth_scale, rel=1e-7)
    (tmp_path / "dir.bag").mkdir()
    with pytest.raises(FileFormatError, match=r"dir\.bag: recording not found"):
        RealSenseSource(tmp_path / "dir.bag")
    with pytest.raises(InputError, match="NUL byte"):
        RealSenseRecording("a\x00.bag")
    with pytest.raises(InputError, match=r"device must be None .* got 3"):
        RealSenseSource(3)  # type: ignore[arg-type]


@pytest.mark.realdata
@pytest.mark.parametrize("record", [0, 1, 2])
def test_a_lying_record_length_is_refused_before_rosbags_allocates_it(tmp_path, record):
    """A top-level record whose header length says 0x7fffffff (rosbags would allocate
    2 GiB to read it; found by the fuzz campaign) is a FileFormatError naming the record,
    with at most a few MiB allocated."""
    import tracemalloc

    if not BAG.exists():
        pytest.skip(f"{BAG} is not there")
    data = bytearray(BAG.read_bytes())
    pos = 13
    for _ in range(record):  # skip whole records: header length, header, data length, data
        n = int.from_bytes(data[pos : pos + 4], "little")
        pos += 4 + n
        n = int.from_bytes(data[pos : pos + 4], "little")
        pos += 4 + n
    data[pos : pos + 4] = (0x7FFFFFFF).to_bytes(4, "little")
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    tracemalloc.start()
    try:
        with pytest.raises(FileFormatError, match=f"top-level record {record} says"):
            RealSenseSource(str(bad))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20


@pytest.mark.realdata
@pytest.mark.parametrize("new_id", [0, 4, 6, 255])
def test_a_changed_connection_id_gives_frames_or_a_file_format_error(tmp_path, new_id):
    """A top-level record whose ``conn`` field names another connection (found by the
    fuzz campaign: ``KeyError: 5`` escaped) reads as frames or a FileFormatError."""
    if not BAG.exists():
        pytest.skip(f"{BAG} is not there")
    data = bytearray(BAG.read_bytes())
    pos, changed = 13, 0
    while pos < len(data):
        start, n = pos + 4, int.from_bytes(data[pos : pos + 4], "little")
        header = bytes(data[start : start + n])
        at = header.find(b"conn=")
        if at >= 0 and b"op=\x04" in header:  # an index record: change its connection
            data[start + at + 5 : start + at + 9] = new_id.to_bytes(4, "little")
            changed += 1
        pos = start + n
        pos += 4 + int.from_bytes(data[pos : pos + 4], "little")
    assert changed
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    try:
        frames = list(RealSenseSource(str(bad), timeout=0.5, max_frames=20))
    except FileFormatError:
        return
    assert all(f.depth.shape == (480, 640) for f in frames)
