"""RGB-D frames from an Intel RealSense camera (pyrealsense2) or a recording of one
(rosbags: no librealsense).

A live camera needs pyrealsense2, an optional dependency: ``pip install
'robopercept[realsense]'``. Recordings (``.bag``: ROS 1, ``.db3``: ROS 2, as
librealsense's recorder writes them) are read in this process with rosbags
(:class:`~robopercept.sources.realsense_recording.RealSenseRecording`), without
pyrealsense2: every recorded depth frame comes back, in order, with the colour frame
nearest in time, and the intrinsics, depth-to-colour extrinsics and depth scale as
librealsense's playback reports them. :func:`write_realsense_recording` writes
recordings through librealsense's own recorder (pyrealsense2, in a child process).
"""

from __future__ import annotations

import contextlib
import itertools
import os
import pickle
import signal
import struct
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_real, plain_repr
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.fileio import atomic_path
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import se3
from robopercept.sources.frames import RGBDFrame
from robopercept.sources.realsense_recording import RealSenseRecording, rgb_from

__all__ = [
    "RealSenseSource",
    "SoftwareCamera",
    "SourceError",
    "import_pyrealsense2",
    "write_realsense_recording",
]

_MODELS = {
    "none": "none",
    "brown_conrady": "brown_conrady",
    "modified_brown_conrady": "modified_brown_conrady",
    "inverse_brown_conrady": "inverse_brown_conrady",
}
_RECORDING_SUFFIXES = (".bag", ".db3")


class SourceError(RoboperceptError, RuntimeError):
    """A frame source failed while running (e.g. the camera was unplugged)."""


def import_pyrealsense2() -> Any:
    """Import pyrealsense2, or raise an :class:`InputError` that names the extra."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise InputError(
            "RealSense cameras need pyrealsense2: pip install 'robopercept[realsense]' "
            "(recordings, .bag and .db3, play without it)"
        ) from None
    return rs


def intrinsics_from_rs(intr: Any) -> CameraIntrinsics:
    """:class:`CameraIntrinsics` from a ``pyrealsense2.intrinsics``."""
    model = str(intr.model).split(".")[-1]
    if model not in _MODELS:
        raise InputError(f"unsupported RealSense distortion model {model!r}")
    return CameraIntrinsics(
        int(intr.width),
        int(intr.height),
        float(intr.fx),
        float(intr.fy),
        float(intr.ppx),
        float(intr.ppy),
        _MODELS[model],  # type: ignore[arg-type]
        tuple(float(c) for c in intr.coeffs),  # type: ignore[arg-type]
    )


def transform_from_rs(extr: Any) -> np.ndarray:
    """4x4 transform from ``pyrealsense2.extrinsics`` (rotation stored column-major)."""
    r = np.asarray(extr.rotation, dtype=np.float64).reshape(3, 3).T
    return se3(r, np.asarray(extr.translation, dtype=np.float64))


class RealSenseSource:
    """Frames from a live RealSense camera or a recording.

    Parameters
    ----------
    device : str, path or None
        None: the first connected camera; a path ending in ``.bag`` or ``.db3``: that
        recording; any other string: the serial number of a connected camera.
    depth_size, color_size : (width, height)
        Live camera only: the stream resolutions (default 848x480 and 1280x720).
    fps : int
        Live camera only.
    timeout : float
        Live camera only: seconds to wait for a frame before deciding the camera is
        gone (a recording is read from the file, with no waiting).
    max_frames : int, optional
        Stop after this many frames (a live camera never ends on its own).
    watchdog : float
        Kept for compatibility and checked (> 0); unused since recordings are read with
        rosbags in this process (it bounded the wait on librealsense's player process).

    Raises
    ------
    InputError
        Live camera: pyrealsense2 missing. A non-positive ``watchdog``; a recording
        without a depth or colour stream, or with colour in a format other than
        ``rgb8``/``bgr8``/``rgba8``/``bgra8``.
    FileFormatError
        A recording that is missing, truncated or corrupt (what rosbags or SQLite
        cannot read, calibration no camera has), at once when opened; damage further in
        stops iteration there, the frames before are yielded.
    SourceError
        Live camera: none connected, or none with the serial number given.

    Notes
    -----
    A recording plays as librealsense's playback device does with ``set_real_time(False)``
    (no frame dropped), read by
    :class:`~robopercept.sources.realsense_recording.RealSenseRecording`: one frame per
    recorded depth frame, in recording order, with the colour frame nearest in time
    (:func:`~robopercept.sources.realsense_recording.pair_nearest_color`); an image that
    cannot be decoded is skipped, warned about and recorded in ``skipped``.

    Iteration stops at the end of a recording; if a live camera stops delivering frames
    (unplugged), iteration raises :class:`SourceError`, which
    :func:`~robopercept.pipelines.run_plane_tracking` turns into a clean stop.
    """

    def __init__(
        self,
        device: str | os.PathLike[str] | None = None,
        *,
        depth_size: tuple[int, int] = (848, 480),
        color_size: tuple[int, int] = (1280, 720),
        fps: int = 30,
        timeout: float = 5.0,
        max_frames: int | None = None,
        watchdog: float = 10.0,
    ) -> None:
        self.device = device
        self.path: Path | None = None
        self.recording: RealSenseRecording | None = None
        self.depth_size = tuple(depth_size)
        self.color_size = tuple(color_size)
        self.fps = int(fps)
        self.timeout = float(timeout)
        self.max_frames = max_frames
        self.watchdog = float(watchdog)
        if not self.watchdog > 0:
            raise InputError(f"watchdog must be a positive number of seconds; got {watchdog!r}")
        self.skipped: list[tuple[int, str]] = []
        self.rs: Any = None  # pyrealsense2, for a live camera
        if device is not None and not isinstance(device, (str, os.PathLike)):
            raise InputError(
                "device must be None (the first camera), a recording's path (.bag, .db3) "
                f"or a camera's serial number (str); got {plain_repr(device)}"
            )
        if device is not None and Path(device).suffix.lower() in _RECORDING_SUFFIXES:
            self.recording = RealSenseRecording(device)
            self.path = self.recording.path
            return
        self.rs = import_pyrealsense2()
        self._check_connected()

    def _check_connected(self) -> None:
        """Raise :class:`SourceError` now, not at the first frame, when no camera (or
        not the one with the serial number asked for) is connected."""
        rs = self.rs
        try:
            serials = [
                d.get_info(rs.camera_info.serial_number) for d in rs.context().query_devices()
            ]
        except RuntimeError as exc:
            raise SourceError(f"cannot list the RealSense cameras: {exc}") from None
        if not serials:
            raise SourceError(
                "no RealSense camera found: connect one (USB 3), or replay a recording with "
                "--source FILE.bag (or FILE.db3)"
            )
        if self.device is not None and str(self.device) not in serials:
            raise SourceError(
                f"no RealSense camera with serial number {self.device}; connected: "
                f"{', '.join(serials)}"
            )

    def __iter__(self) -> Iterator[RGBDFrame]:
        if self.recording is not None:
            return self.recording.frames(self.max_frames, self.skipped)
        return self._live_frames()

    def _start(self) -> tuple[Any, float, Any, Any]:
        """Start the live camera's pipeline: ``(pipeline, depth_scale, depth_profile,
        colour_profile)``."""
        rs = self.rs
        pipe, cfg = rs.pipeline(), rs.config()
        if self.device is not None:
            cfg.enable_device(str(self.device))
        w, h = self.depth_size
        cfg.enable_stream(rs.stream.depth, w, h, rs.format.z16, self.fps)
        w, h = self.color_size
        cfg.enable_stream(rs.stream.color, w, h, rs.format.rgb8, self.fps)
        try:
            profile = pipe.start(cfg)
        except RuntimeError as exc:
            raise FileFormatError(f"the RealSense camera: cannot start streaming: {exc}") from None
        scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
        dprof = profile.get_stream(rs.stream.depth).as_video_stream_profile()
        cprof = profile.get_stream(rs.stream.color).as_video_stream_profile()
        return pipe, scale, dprof, cprof

    def _live_frames(self) -> Iterator[RGBDFrame]:
        """The live camera's frames, read by librealsense in this process."""
        pipe, scale, dprof, cprof = self._start()
        try:
            kd = intrinsics_from_rs(dprof.get_intrinsics())
            kc = intrinsics_from_rs(cprof.get_intrinsics())
            T = transform_from_rs(dprof.get_extrinsics_to(cprof))
            index = 0
            t0: float | None = None
            while self.max_frames is None or index < self.max_frames:
                try:
                    ok, frames = pipe.try_wait_for_frames(int(self.timeout * 1000))
                except RuntimeError as exc:
                    raise SourceError(f"the RealSense stream failed: {exc}") from None
                if not ok:
                    raise SourceError(
                        f"no frame from the RealSense camera for {self.timeout:g} s (unplugged?)"
                    )
                depth, color = frames.get_depth_frame(), frames.get_color_frame()
                if not depth or not color:
                    reason = "frameset without both depth and colour"
                    warnings.warn(f"skipping frame {index}: {reason}", stacklevel=2)
                    self.skipped.append((index, reason))
                    index += 1
                    continue
                ts = depth.get_timestamp() / 1000.0
                t0 = ts if t0 is None else t0
                fmt = str(color.profile.format()).split(".")[-1]
                rgb = rgb_from(np.asanyarray(color.get_data()), fmt)
                yield RGBDFrame(
                    index,
                    ts - t0,
                    np.asanyarray(depth.get_data()).copy(),
                    np.ascontiguousarray(rgb).copy(),
                    kd,
                    kc,
                    T,
                    scale,
                )
                index += 1
        finally:
            try:
                pipe.stop()
            except RuntimeError:  # pragma: no cover - already stopped
                pass


# --------------------------------------------------------------- writing recordings
# librealsense's recorder runs in a child process fed through a pipe: messages
# <kind:c><meta_len:u64><n:u8><len_i:u64 x n><meta><buffers> (pickle protocol 5, the
# pixels as raw out-of-band buffers)

_HEAD = struct.Struct("<cQB")  # kind, length of the pickled part, number of raw buffers
_TYPED = {"InputError": InputError, "FileFormatError": FileFormatError, "SourceError": SourceError}


def _child_env() -> dict[str, str]:
    """The environment of a librealsense child process: this one's, with the folder
    holding ``robopercept/`` first on ``PYTHONPATH``."""
    root = str(Path(__file__).resolve().parents[2])
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return env


def _how_it_died(code: int, err: Any) -> tuple[str, str]:
    """For an error message: ``signal SIGSEGV`` or ``exit status N``, and ``; it said:
    ...`` with the last words the child wrote to the file ``err`` (its stderr; empty if
    none)."""
    why = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit status {code}"
    err.seek(0)
    tail = " | ".join(err.read()[-300:].decode("utf-8", "replace").split())
    return why, (f"; it said: {tail}" if tail else "")


def _send(out: Any, kind: bytes, obj: Any) -> None:
    """Write one message ``<kind:c><meta_len:u64><n:u8><len_i:u64 x n><meta><buffers>``;
    NumPy arrays travel as raw out-of-band buffers (pickle protocol 5), not copied
    into the pickle."""
    bufs: list[pickle.PickleBuffer] = []
    meta = pickle.dumps(obj, protocol=5, buffer_callback=bufs.append)
    views = [b.raw() for b in bufs]
    out.write(_HEAD.pack(kind, len(meta), len(views)))
    out.write(struct.pack(f"<{len(views)}Q", *(v.nbytes for v in views)))
    out.write(meta)
    for v in views:
        out.write(v)
    out.flush()


def _rs_intrinsics(rs: Any, k: CameraIntrinsics) -> Any:
    intr = rs.intrinsics()
    intr.width, intr.height, intr.fx, intr.fy = k.width, k.height, k.fx, k.fy
    intr.ppx, intr.ppy = k.cx, k.cy
    intr.model = getattr(rs.distortion, k.model)
    intr.coeffs = [float(c) for c in k.coeffs] if k.coeffs else [0.0] * 5
    return intr


class SoftwareCamera:
    """A pyrealsense2 *software device* with the depth and colour streams of an
    :class:`~robopercept.sources.frames.RGBDFrame`'s calibration: frames pushed into it
    come out of librealsense as a D4xx's would (into :attr:`queue`), and with
    ``record_to`` its recorder writes them to a RealSense recording (``.db3`` with
    librealsense 2.59), readable by :class:`RealSenseSource`.

    Parameters
    ----------
    frame : RGBDFrame
        Gives the resolutions, intrinsics, extrinsics (``T_color_depth``) and depth units.
    record_to : path, optional
        Record every pushed frame there.
    queue_size : int
        Frames librealsense keeps in :attr:`queue` (``rs.frame_queue``).
    fps : int
        The streams' nominal rate.

    Notes
    -----
    librealsense writes a recording from its own threads: :meth:`close` waits
    ``settle`` seconds for the last frames before it stops the sensors (frames still in
    flight then are lost).
    """

    def __init__(
        self,
        frame: RGBDFrame,
        record_to: str | os.PathLike[str] | None = None,
        queue_size: int = 4,
        fps: int = 30,
    ) -> None:
        rs = import_pyrealsense2()
        self.rs = rs
        self.device = rs.software_device()
        self.sensors: list[tuple[Any, Any, int]] = []
        for name, typ, uid, k, bpp, fmt in (
            ("Depth", rs.stream.depth, 0, frame.depth_intrinsics, 2, rs.format.z16),
            ("Color", rs.stream.color, 1, frame.color_intrinsics, 3, rs.format.rgb8),
        ):
            sensor = self.device.add_sensor(name)
            vs = rs.video_stream()
            vs.type, vs.index, vs.uid, vs.width, vs.height = typ, 0, uid, k.width, k.height
            vs.fps, vs.bpp, vs.fmt, vs.intrinsics = fps, bpp, fmt, _rs_intrinsics(rs, k)
            self.sensors.append((sensor, sensor.add_video_stream(vs), bpp))
        ex = rs.extrinsics()
        T = frame.T_color_depth
        ex.rotation = T[:3, :3].T.reshape(-1).tolist()  # column-major
        ex.translation = T[:3, 3].tolist()
        self.sensors[0][1].register_extrinsics_to(self.sensors[1][1], ex)
        self.sensors[0][0].add_read_only_option(rs.option.depth_units, float(frame.depth_scale))
        self.recorder = None if record_to is None else rs.recorder(str(record_to), self.device)
        self.queue = rs.frame_queue(int(queue_size), keep_frames=True)
        for sensor, profile, _ in self.sensors:
            sensor.open(profile)
            sensor.start(self.queue)
        self.count = 0

    def push(self, frame: RGBDFrame) -> None:
        """Hand one frame's depth and colour to librealsense (timestamps in ms from
        ``frame.timestamp``)."""
        rs = self.rs
        for (sensor, profile, bpp), pixels in zip(
            self.sensors, (frame.depth, frame.color), strict=True
        ):
            f = rs.software_video_frame()
            f.pixels, f.bpp, f.stride = pixels, bpp, bpp * pixels.shape[1]
            f.timestamp, f.domain = 1000.0 * frame.timestamp, rs.timestamp_domain.hardware_clock
            f.frame_number = self.count
            f.profile = profile.as_video_stream_profile()
            sensor.on_video_frame(f)
        self.count += 1

    def close(self, settle: float = 0.0) -> None:
        """Stop the sensors (after ``settle`` seconds) and finish the recording."""
        import time

        time.sleep(settle)
        for sensor, _, _ in self.sensors:
            sensor.stop()
            sensor.close()
        self.recorder = None


#: the recorder's child process (see :func:`write_realsense_recording`)
_RECORDER = (
    "import sys; from robopercept.sources.realsense import _recorder_main; "
    "_recorder_main(sys.argv[1], float(sys.argv[2]))"
)


def _receive(inp: Any) -> tuple[bytes, Any] | None:
    """Read one message written by :func:`_send` from the binary stream ``inp``
    (blocking); None at end of stream."""
    head = inp.read(_HEAD.size)
    if len(head) < _HEAD.size:
        return None
    kind, n_meta, n_buf = _HEAD.unpack(head)
    lens = struct.unpack(f"<{n_buf}Q", inp.read(8 * n_buf))
    meta = inp.read(n_meta)
    bufs = [inp.read(n) for n in lens]
    if len(meta) < n_meta or any(len(b) < n for b, n in zip(bufs, lens, strict=True)):
        return None
    return kind, pickle.loads(meta, buffers=bufs)


def _recorder_main(path: str, pace: float) -> None:
    """The child process of :func:`write_realsense_recording`: read frames from stdin
    (:func:`_send` messages, ``D`` at the end), push them through a
    :class:`SoftwareCamera` recording to ``path``, and answer on stdout with the count
    (``D``) or the error (``E``). Ends with ``os._exit`` once the recorder has been
    released (the recording is complete then): librealsense's teardown of the software
    device is not waited for."""
    inp, out = sys.stdin.buffer, os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever librealsense prints goes to stderr, not into the answer
    cam: SoftwareCamera | None = None
    try:
        while (msg := _receive(inp)) is not None and msg[0] == b"F":
            frame = msg[1]
            if cam is None:
                cam = SoftwareCamera(frame, record_to=path, queue_size=64)
                time.sleep(0.5)  # the recorder starts on its own thread: early frames can be lost
            cam.push(frame)
            while cam.queue.poll_for_frame():  # nobody reads them here
                pass
            time.sleep(pace)
        count = 0 if cam is None else cam.count
        if cam is not None:
            cam.close(settle=1.0)
        _send(out, b"D", count)
    except RoboperceptError as exc:
        _send(out, b"E", (type(exc).__name__, str(exc)))
    except Exception as exc:  # librealsense's own errors, named
        _send(out, b"E", ("", f"{type(exc).__name__}: {exc}"))
    out.close()
    os._exit(0)


def write_realsense_recording(path: str | os.PathLike[str], frames: Any, pace: float = 0.03) -> int:
    """Write ``frames`` (RGBDFrames of one calibration) to a RealSense recording through
    a :class:`SoftwareCamera` and librealsense's recorder.

    librealsense records from threads of its own, and tearing its software device down
    in a process that goes on (a test run, a notebook) is not safe: it can abort the
    whole process later. So the recording is made in a child process
    (a fresh interpreter) that the frames are streamed to; this process holds no
    librealsense object.

    The recording is written under a temporary name beside ``path``
    (``.<name>.<pid>.tmp.db3``, :func:`robopercept.fileio.atomic_path`) and renamed to
    ``path`` only once the recorder has finished: a recording interrupted in any way
    (an error or Ctrl-C in ``frames``, the recorder failing or dying) leaves no file at
    ``path`` (or the previous one there, intact), and its partial temporary file is
    removed. Only a process killed outright can leave a temporary file behind, under
    that name, never a short recording under ``path``. ``path``'s folder is created
    if needed.

    Parameters
    ----------
    path : path
        The recording (``.db3`` with librealsense 2.59).
    frames : iterable of RGBDFrame
    pace : float
        Seconds between frames, so that librealsense's recorder keeps up.

    Returns
    -------
    int
        Frames pushed.

    Raises
    ------
    InputError
        No frames, a ``path`` that cannot name a file, or pyrealsense2 is not installed.
    SourceError
        The recorder process failed or died (its last words are quoted).
    WriteError
        The finished recording could not be moved to ``path``.
    """
    dest = as_path(path, "the recording's path")
    import_pyrealsense2()  # the missing extra is named here, not in the child
    it = iter(frames)
    try:
        first = next(it)
    except StopIteration:
        raise InputError("no frames to record") from None
    pace = check_real(pace, "pace (seconds)", 0.0)
    with atomic_path(dest) as tmp:
        try:
            return _record_in_child(tmp, dest, itertools.chain((first,), it), pace)
        except BaseException:
            # sqlite's side files of a recorder killed mid-write (atomic_path removes
            # the temporary recording itself)
            for side in ("-journal", "-wal", "-shm"):
                with contextlib.suppress(OSError):
                    tmp.with_name(tmp.name + side).unlink(missing_ok=True)
            raise


def _record_in_child(tmp: Path, dest: Path, frames: Iterator[RGBDFrame], pace: float) -> int:
    """Stream ``frames`` to a recorder child process writing ``tmp``; the count of frames
    pushed, or the child's error as a typed one (messages name ``dest``)."""
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(
            [sys.executable, "-c", _RECORDER, str(tmp), repr(pace)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=err,
            env=_child_env(),
        )
        assert proc.stdin is not None and proc.stdout is not None
        try:
            try:
                for frame in frames:  # streamed, never all held
                    _send(proc.stdin, b"F", frame)
                _send(proc.stdin, b"D", None)
                proc.stdin.close()
            except BrokenPipeError:  # the child died: said below
                pass
            answer = _receive(proc.stdout)
            code = proc.wait()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if answer is not None and answer[0] == b"D":
            return int(answer[1])
        if answer is not None and answer[0] == b"E":
            name, message = answer[1]
            if name in _TYPED:
                raise _TYPED[name](message)
            raise SourceError(f"librealsense failed writing {dest}: {message}")
        why, said = _how_it_died(code, err)
        raise SourceError(f"the RealSense recorder process died writing {dest} ({why}){said}")
