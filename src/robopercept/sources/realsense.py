"""RGB-D frames from an Intel RealSense camera or a recording of one (pyrealsense2).

pyrealsense2 is an optional dependency: ``pip install 'robopercept[realsense]'``.
Recordings (``.bag``; ``.db3`` where the installed librealsense reads ROS 2 bags) are
played back not in real time, so no frame is dropped however slow the consumer is.
Intrinsics, the depth-to-colour extrinsics and the depth scale come from the stream
profiles and the depth sensor, as the camera reports them.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import os
import pickle
import select
import signal
import sqlite3
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

from robopercept._checks import as_path, check_real
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.fileio import atomic_path
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import se3
from robopercept.sources.frames import RGBDFrame

__all__ = [
    "RealSenseSource",
    "SoftwareCamera",
    "SourceError",
    "check_db3_recording",
    "check_ros1_bag",
    "import_pyrealsense2",
    "write_realsense_recording",
]

_MODELS = {
    "none": "none",
    "brown_conrady": "brown_conrady",
    "modified_brown_conrady": "modified_brown_conrady",
    "inverse_brown_conrady": "inverse_brown_conrady",
}


class SourceError(RoboperceptError, RuntimeError):
    """A frame source failed while running (e.g. the camera was unplugged)."""


def import_pyrealsense2() -> Any:
    """Import pyrealsense2, or raise an :class:`InputError` that names the extra."""
    try:
        import pyrealsense2 as rs
    except ImportError:
        raise InputError(
            "RealSense sources need pyrealsense2: pip install 'robopercept[realsense]'"
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


def _to_rgb(data: np.ndarray, fmt: str) -> np.ndarray:
    if fmt == "rgb8":
        return data
    if fmt == "bgr8":
        return data[..., ::-1]
    if fmt == "rgba8":
        return data[..., :3]
    if fmt == "bgra8":
        return data[..., 2::-1]
    raise InputError(
        f"colour stream format {fmt!r} is not supported; record colour as rgb8, bgr8, "
        "rgba8 or bgra8"
    )


ROS1_BAG_MAGIC = b"#ROSBAG V2.0\n"
_OP_CHUNK, _OP_BAG_HEADER, _OP_INDEX, _OP_CHUNK_INFO, _OP_CONNECTION = 5, 3, 4, 6, 7
_OP_MESSAGE = 2
#: chunk compressions librealsense's rosbag reader decodes
BAG_COMPRESSIONS = (b"none", b"lz4", b"bz2")
#: the largest uncompressed chunk accepted (ROS writes 768 KiB chunks; one message
#: larger than that, a 4K colour image, makes a chunk of some 25 MB)
MAX_BAG_CHUNK = 1 << 30
#: LZ4's largest expansion (a run of one byte: 255 output bytes per input byte)
_LZ4_MAX_RATIO = 255
_U32 = struct.Struct("<I")


def _bag_error(path: Path, offset: int, what: str) -> FileFormatError:
    return FileFormatError(
        f"{path}: byte offset {offset}: {what}; the recording is truncated or corrupt "
        "(copy it again, or record it again)"
    )


def _bag_fields(path: Path, header: bytes, offset: int) -> dict[bytes, bytes]:
    """The ``name=value`` fields of a ROS1 bag record header (each prefixed by its
    length, a little-endian u32), checked against the header's length."""
    fields: dict[bytes, bytes] = {}
    i = 0
    while i < len(header):
        if len(header) - i < 4:
            raise _bag_error(path, offset + i, "a header field length is cut short")
        (n,) = _U32.unpack_from(header, i)
        if n > len(header) - i - 4:
            raise _bag_error(path, offset + i, f"header field length {n} runs past its header")
        name, eq, value = header[i + 4 : i + 4 + n].partition(b"=")
        if not eq or not name:
            raise _bag_error(path, offset + i, "a header field is not name=value")
        fields[name] = value
        i += 4 + n
    return fields


def _u32_field(path: Path, fields: dict[bytes, bytes], name: bytes, off: int) -> int:
    """The little-endian u32 header field ``name`` of the record at ``off``."""
    raw = fields.get(name, b"")
    if len(raw) != 4:
        raise _bag_error(path, off, f"the {name.decode()} field is not 4 bytes")
    return int(_U32.unpack(raw)[0])


def _check_bag_record(
    path: Path, f: Any, off: int, op: int, fields: dict[bytes, bytes], dlen: int, data_at: int
) -> list[tuple[int, int]]:
    """Check the header fields librealsense's rosbag reader trusts in one record (op
    ``op`` at ``off``, ``dlen`` data bytes at ``data_at``); return the connection ids it
    refers to, each with the offset to name if it was never declared.

    - chunk (5): ``compression`` is none, lz4 or bz2; ``size`` (uncompressed) is at
      most :data:`MAX_BAG_CHUNK`, equals ``data_len`` when uncompressed, and for lz4
      lies within ``[data_len / 2 - 64, 255 data_len + 64]`` (lz4 stores incompressible
      blocks raw, with 4-byte block headers; it expands at most 255:1);
    - message data (2), connection (7), index data (4): a 4-byte ``conn``;
    - index data (4): ``ver`` 1 and ``data_len == 12 count`` (time u64, offset u32);
    - chunk info (6): ``ver`` 1, ``data_len == 8 count`` ((conn u32, count u32) pairs).
    """
    refs: list[tuple[int, int]] = []
    if op == _OP_CHUNK:
        comp = fields.get(b"compression", b"")
        if comp not in BAG_COMPRESSIONS:
            raise _bag_error(
                path, off, f"chunk compression {comp!r} is not one of none, lz4 or bz2"
            )
        size = _u32_field(path, fields, b"size", off)
        lo, hi = {
            b"none": (dlen, dlen),
            b"lz4": (dlen // 2 - 64, _LZ4_MAX_RATIO * dlen + 64),
            b"bz2": (1, MAX_BAG_CHUNK),
        }[comp]
        if not lo <= size <= min(hi, MAX_BAG_CHUNK):
            raise _bag_error(
                path,
                off,
                f"{comp.decode()} chunk of {dlen} bytes claims an uncompressed size of {size}"
                f" (expected {max(lo, 0)} to {min(hi, MAX_BAG_CHUNK)})",
            )
    elif op in (_OP_MESSAGE, _OP_INDEX):
        refs.append((off, _u32_field(path, fields, b"conn", off)))
    if op in (_OP_INDEX, _OP_CHUNK_INFO):
        if _u32_field(path, fields, b"ver", off) != 1:
            raise _bag_error(path, off, "index version is not 1")
        count = _u32_field(path, fields, b"count", off)
        width = 12 if op == _OP_INDEX else 8
        if dlen != width * count:
            raise _bag_error(
                path, off, f"{count} index entries need {width * count} bytes, not {dlen}"
            )
        if op == _OP_CHUNK_INFO:
            f.seek(data_at)
            pairs = np.frombuffer(f.read(dlen), "<u4").reshape(-1, 2)
            refs += [(off, int(c)) for c in pairs[:, 0]]
    return refs


def _walk_bag_records(
    path: Path,
    f: Any,
    start: int,
    end: int,
    in_chunk: bool,
    found: dict[int, int],
    conns: set[int],
    refs: list[tuple[int, int]],
) -> None:
    """Walk the records ``<header_len:u32><header><data_len:u32><data>`` that tile
    ``[start, end)`` of the open file ``f``, checking every length against ``end`` and
    each record's fields (:func:`_check_bag_record`); the records inside an
    uncompressed chunk are walked too. ``found`` collects the offset and op code of
    every top-level record, ``conns`` the connection ids declared, ``refs`` the
    (offset, connection id) references to check against them."""
    off = start
    while off < end:
        f.seek(off)
        head = f.read(4)
        if len(head) < 4 or end - off < 4:
            raise _bag_error(path, off, "a record header length is cut short")
        (hlen,) = _U32.unpack(head)
        if hlen > end - off - 8:
            raise _bag_error(
                path, off, f"record header length {hlen} runs past the end ({end} bytes)"
            )
        header = f.read(hlen + 4)
        if len(header) < hlen + 4:
            raise _bag_error(path, off, "a record header is cut short")
        fields = _bag_fields(path, header[:hlen], off + 4)
        (dlen,) = _U32.unpack_from(header, hlen)
        data_at = off + 8 + hlen
        if dlen > end - data_at:
            raise _bag_error(
                path, off + 4 + hlen, f"record data length {dlen} runs past the end ({end} bytes)"
            )
        op = fields.get(b"op", b"")
        if len(op) != 1:
            raise _bag_error(path, off, "a record has no one-byte op field")
        if in_chunk and op[0] not in (_OP_MESSAGE, _OP_CONNECTION):
            raise _bag_error(path, off, f"record op {op[0]} cannot sit inside a chunk")
        top = (_OP_BAG_HEADER, _OP_CHUNK, _OP_INDEX, _OP_CHUNK_INFO, _OP_CONNECTION)
        if not in_chunk and op[0] not in top:
            raise _bag_error(path, off, f"record op {op[0]} cannot sit outside a chunk")
        refs += _check_bag_record(path, f, off, op[0], fields, dlen, data_at)
        if op[0] == _OP_CONNECTION:
            conns.add(_u32_field(path, fields, b"conn", off))
        if not in_chunk:
            found[off] = op[0]
            if op[0] == _OP_CHUNK and fields.get(b"compression") == b"none":
                _walk_bag_records(path, f, data_at, data_at + dlen, True, found, conns, refs)
        off = data_at + dlen


def check_ros1_bag(path: str | os.PathLike[str]) -> int:
    """Check the record structure of a ROS1 bag (format 2.0, librealsense's ``.bag``)
    before librealsense reads it, and return its number of top-level records.

    The file is the magic ``#ROSBAG V2.0\\n`` followed by records
    ``<header_len:u32><header><data_len:u32><data>`` (little-endian), each header a
    sequence of ``<field_len:u32>name=value`` fields with a one-byte ``op``. Every length
    is checked against what remains of the file (of the chunk, for the records inside an
    uncompressed chunk), every header field must parse, the bag header's ``index_pos``
    must point at a record, and every chunk-info ``chunk_pos`` at a chunk. Data is
    skipped by seeking, so the check reads only the headers (about 1 ms for the 1 MB
    sample recording). This is the file format of http://wiki.ros.org/Bags/Format/2.0;
    librealsense's reader (ROS ``rosbag_storage``) trusts these lengths, and spins
    forever on a length word of ``0xFFFFFFFF``.

    Parameters
    ----------
    path : path
        The ``.bag`` file.

    Returns
    -------
    int
        The number of top-level records.

    Raises
    ------
    FileFormatError
        Not a ROS1 bag v2.0, or a length, field or pointer that does not fit the file;
        the message names the file and the byte offset.
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        with path.open("rb") as f:
            magic = f.read(len(ROS1_BAG_MAGIC))
            if magic != ROS1_BAG_MAGIC:
                raise FileFormatError(
                    f"{path}: not a ROS1 bag (format 2.0): it starts with {magic!r}, not "
                    f"{ROS1_BAG_MAGIC!r}; RealSense recordings are .bag (ROS1) or .db3 (ROS2)"
                )
            found: dict[int, int] = {}
            conns: set[int] = set()
            refs: list[tuple[int, int]] = []
            _walk_bag_records(path, f, len(ROS1_BAG_MAGIC), size, False, found, conns, refs)
            for off, conn in refs:
                if conn not in conns:
                    raise _bag_error(path, off, f"connection {conn} is never declared")
            first = len(ROS1_BAG_MAGIC)
            if found.get(first) != _OP_BAG_HEADER:
                raise _bag_error(path, first, "the first record is not the bag header")
            for off, op in found.items():
                if op not in (_OP_BAG_HEADER, _OP_CHUNK_INFO):
                    continue
                f.seek(off)
                (hlen,) = _U32.unpack(f.read(4))
                fields = _bag_fields(path, f.read(hlen), off + 4)
                name, want = (
                    (b"index_pos", None) if op == _OP_BAG_HEADER else (b"chunk_pos", _OP_CHUNK)
                )
                raw = fields.get(name, b"")
                if len(raw) != 8:
                    raise _bag_error(path, off, f"the {name.decode()} field is not 8 bytes")
                pos = int.from_bytes(raw, "little")
                if want is None and pos == 0:
                    continue  # a bag still being recorded (no index yet)
                if pos not in found or (want is not None and found[pos] != want):
                    raise _bag_error(path, off, f"{name.decode()} {pos} does not point at a record")
    except OSError as exc:
        if isinstance(exc, FileFormatError):
            raise
        raise FileFormatError(f"{path}: cannot read the recording: {exc}") from None
    return len(found)


SQLITE_MAGIC = b"SQLite format 3\x00"


def check_db3_recording(path: str | os.PathLike[str]) -> None:
    """Check that a ``.db3`` recording (a ROS2 bag, librealsense's SQLite storage) is a
    sound SQLite database with the ROS2 tables, before librealsense reads it.

    Runs SQLite's ``PRAGMA quick_check`` (every page and record well formed, O(N)) on
    a read-only connection, looks for the ``topics`` and ``messages`` tables of
    rosbag2's sqlite3 storage plugin, and checks that every topic's name and type are
    printable ASCII (as ROS names are; librealsense hangs on some that are not). The
    messages themselves are not parsed here: :class:`RealSenseSource` plays recordings
    in a watched child process, which turns what librealsense does with a corrupt
    message (a crash, a hang) into a :class:`FileFormatError`.

    Parameters
    ----------
    path : path
        The ``.db3`` file.

    Raises
    ------
    FileFormatError
        Not SQLite, a corrupt database, or no rosbag2 tables; the message names the file.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            magic = f.read(len(SQLITE_MAGIC))
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read the recording: {exc}") from None
    if magic != SQLITE_MAGIC:
        raise FileFormatError(
            f"{path}: not an SQLite database (a ROS2 .db3 recording): it starts with "
            f"{magic!r}; RealSense recordings are .bag (ROS1) or .db3 (ROS2)"
        )
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True)
        try:
            check = con.execute("PRAGMA quick_check").fetchall()
            tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master")}
            con.text_factory = bytes
            topics = (
                con.execute("SELECT id, name, type FROM topics").fetchall()
                if {"topics", "messages"} <= tables
                else []
            )
        finally:
            con.close()
    except sqlite3.Error as exc:
        raise FileFormatError(f"{path}: corrupt SQLite recording: {exc}") from None
    if check != [("ok",)]:
        raise FileFormatError(f"{path}: corrupt SQLite recording: {check[0][0]}")
    missing = {"topics", "messages"} - tables
    if missing:
        raise FileFormatError(
            f"{path}: not a ROS2 recording: no {', '.join(sorted(missing))} table"
        )
    for tid, name, typ in topics:  # librealsense hangs on some non-ASCII topic names
        for what, text in (("name", name), ("type", typ)):
            if not isinstance(text, bytes) or not all(32 <= c < 127 for c in text):
                raise FileFormatError(
                    f"{path}: corrupt SQLite recording: topic {tid} has a {what} that is "
                    f"not printable ASCII ({text!r}); copy or record it again"
                )


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
        Seconds to wait for a frame before deciding the camera is gone (live), or
        before asking the player whether the recording has ended (it has when the
        player has stopped; while it still plays, the wait goes on, up to ``timeout +
        watchdog`` seconds without a frame).
    max_frames : int, optional
        Stop after this many frames (a live camera never ends on its own).
    watchdog : float
        Recordings: seconds beyond ``timeout`` to wait for the player process's next
        message before deciding librealsense hangs (default 10; raise it for a
        recording that is sound but slow to open).

    Raises
    ------
    InputError
        pyrealsense2 missing, a non-positive ``watchdog``, or a recording without a
        depth or colour stream.
    FileFormatError
        A recording that cannot be opened, or whose structure is corrupt: checked by
        :func:`check_ros1_bag` / :func:`check_db3_recording` before librealsense sees
        it; while playing, librealsense crashing (``librealsense crashed reading FILE
        at frame N``) or hanging (``stopped responding``) on a corrupt message.
    SourceError
        Live camera: none connected, or none with the serial number given.

    Notes
    -----
    On POSIX, recordings are played by librealsense in a child process
    (:func:`_play_in_child`): a crash or an endless loop in librealsense on a corrupt
    recording (which no check before playback can rule out: it trusts every message)
    becomes a :class:`FileFormatError` after the frames read so far have been yielded.
    The cost: about 0.45 s to start the player (an interpreter importing
    pyrealsense2) and 1 to 2 ms per 640x480 frame (7.6 ms in process, 8.6 to 9.8 ms
    through the pipe, on this project's 2-core machine).

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
        self.rs = import_pyrealsense2()
        self.device = device
        self.path: Path | None = None
        if device is not None and Path(device).suffix.lower() in (".bag", ".db3"):
            self.path = Path(device)
            if not self.path.is_file():
                raise FileFormatError(f"{self.path}: recording not found")
            if self.path.suffix.lower() == ".bag":
                check_ros1_bag(self.path)  # librealsense hangs on some corrupt bags
            else:
                check_db3_recording(self.path)
        self.depth_size = tuple(depth_size)
        self.color_size = tuple(color_size)
        self.fps = int(fps)
        self.timeout = float(timeout)
        self.max_frames = max_frames
        self.watchdog = float(watchdog)
        if not self.watchdog > 0:
            raise InputError(f"watchdog must be a positive number of seconds; got {watchdog!r}")
        self.skipped: list[tuple[int, str]] = []
        if self.path is None:
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

    def _start(self) -> tuple[Any, Any, Any, Any, Any]:
        """Start streaming: ``(waiter, depth_scale, depth_profile, colour_profile,
        playback)``; ``waiter.try_wait_for_frames(ms)`` gives ``(ok, frameset)`` and
        ``waiter.stop()`` ends it; ``playback`` is None for a live camera.

        A live camera streams through a ``pipeline``. A recording is loaded as a
        playback device whose player is switched to non-real-time (it waits for the
        reader) *before* its sensors start into a ``syncer``: through a pipeline the
        player starts in real time at ``start`` and the switch comes after it, and the
        first framesets of a short recording were often lost in between."""
        rs = self.rs
        if self.path is None:
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
                raise FileFormatError(
                    f"the RealSense camera: cannot start streaming: {exc}"
                ) from None
            scale = float(profile.get_device().first_depth_sensor().get_depth_scale())
            dprof = profile.get_stream(rs.stream.depth).as_video_stream_profile()
            cprof = profile.get_stream(rs.stream.color).as_video_stream_profile()
            return pipe, scale, dprof, cprof, None
        try:
            dev = rs.context().load_device(str(self.path))
            playback = dev.as_playback()
            playback.set_real_time(False)
            sensors = list(dev.query_sensors())
            profiles = {p.stream_type(): p for s in sensors for p in s.get_stream_profiles()}
        except RuntimeError as exc:
            raise FileFormatError(f"{self.path}: cannot open the recording: {exc}") from None
        for kind, name in ((rs.stream.depth, "depth"), (rs.stream.color, "colour")):
            if kind not in profiles:
                raise InputError(
                    f"{self.path} has no {name} stream; the plane tracker needs depth and "
                    "colour (record both)"
                )
        player = _RecordingPlayer(rs, sensors, playback)
        try:
            scale = float(dev.first_depth_sensor().get_depth_scale())
        except RuntimeError as exc:
            player.stop()
            raise FileFormatError(f"{self.path}: no depth scale in the recording: {exc}") from None
        dprof = profiles[rs.stream.depth].as_video_stream_profile()
        cprof = profiles[rs.stream.color].as_video_stream_profile()
        return player, scale, dprof, cprof, playback

    def __iter__(self) -> Iterator[RGBDFrame]:
        if self.path is not None and os.name == "posix":
            return _play_in_child(self)
        return self._frames_here()

    def _frames_here(self) -> Iterator[RGBDFrame]:
        """The frames, read by librealsense in this process (a live camera; recordings
        where no child process can be watched)."""
        rs = self.rs
        waiter, scale, dprof, cprof, playback = self._start()
        try:
            kd = intrinsics_from_rs(dprof.get_intrinsics())
            kc = intrinsics_from_rs(cprof.get_intrinsics())
            T = transform_from_rs(dprof.get_extrinsics_to(cprof))
            index = 0
            t0: float | None = None
            last_number: int | None = None
            silent = 0.0  # seconds waited since the last frameset
            while self.max_frames is None or index < self.max_frames:
                try:
                    ok, frames = waiter.try_wait_for_frames(int(self.timeout * 1000))
                except RuntimeError as exc:
                    raise SourceError(f"the RealSense stream failed: {exc}") from None
                if not ok:
                    if playback is None:
                        raise SourceError(
                            f"no frame from the RealSense camera for {self.timeout:g} s "
                            "(unplugged?)"
                        )
                    if playback.current_status() != rs.playback_status.playing:
                        return  # the player has reached the end of the recording
                    # still playing: the machine is slow, not the recording over (a
                    # timeout alone cut recordings short under load)
                    silent += self.timeout
                    if silent >= self.timeout + self.watchdog:
                        raise FileFormatError(
                            f"{self.path}: librealsense stopped responding for {silent:g} s "
                            f"reading frame {index} (a corrupt recording; if it is sound but "
                            "slow to open, raise the watchdog)"
                        )
                    continue
                silent = 0.0
                if isinstance(frames, tuple):  # a recording: already split
                    depth, color = frames
                else:
                    depth, color = frames.get_depth_frame(), frames.get_color_frame()
                if not depth or not color:
                    reason = "frameset without both depth and colour"
                    warnings.warn(f"skipping frame {index}: {reason}", stacklevel=2)
                    self.skipped.append((index, reason))
                    index += 1
                    continue
                number = depth.get_frame_number()
                if self.path is not None and last_number is not None and number <= last_number:
                    return  # playback wrapped around
                last_number = number
                ts = depth.get_timestamp() / 1000.0
                t0 = ts if t0 is None else t0
                fmt = str(color.profile.format()).split(".")[-1]
                rgb = _to_rgb(np.asanyarray(color.get_data()), fmt)
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
                waiter.stop()
            except RuntimeError:  # pragma: no cover - already stopped
                pass


class _RecordingPlayer:
    """The sensors of a playback device started into a ``syncer``, read as
    ``(ok, (depth, colour))`` like a pipeline: one pair per recorded depth frame, in
    order.

    A syncer passes a frame on alone until it has seen every stream (on each recording
    here the first depth and the first colour frame come as two framesets), and under
    load it may pass a depth frame on before the colour frame of the same instant. So
    each depth frame waits until a colour frame at or after its timestamp has come
    (or the player has stopped), and is then paired with the colour frame nearest to
    it in time among those seen (the earlier one on a tie): recordings whose streams
    share timestamps come back exactly paired, and a depth frame between two colour
    frames gets the nearer, as a pipeline's syncer pairs them. Depth frames that come
    after the last colour frame are paired with it when the player stops. At most
    ``max_waiting`` depth frames wait: any beyond are paired with the nearest colour
    frame seen so far, or passed on without colour (and skipped, counted, by the
    reader) when there is none."""

    max_waiting = 8
    #: colour frames kept to pair the waiting depth frames with
    max_colors = 4

    def __init__(self, rs: Any, sensors: list[Any], playback: Any = None) -> None:
        self.rs, self.sensors, self.playback = rs, sensors, playback
        self.sync = rs.syncer()
        self.colors: collections.deque[Any] = collections.deque(maxlen=self.max_colors)
        self.waiting: collections.deque[Any] = collections.deque()  # depth, in order
        self.ready: collections.deque[tuple[Any, Any]] = collections.deque()
        opened: list[Any] = []
        try:
            for s in sensors:
                s.open(s.get_stream_profiles())
                opened.append(s)
            for s in sensors:
                s.start(self.sync)
        except RuntimeError:
            for s in opened:
                with contextlib.suppress(RuntimeError):
                    s.close()
            raise

    def _nearest(self, depth: Any) -> Any:
        """The colour frame seen nearest in time to ``depth`` (None if none)."""
        if not self.colors:
            return None
        t = depth.get_timestamp()
        return min(self.colors, key=lambda c: abs(c.get_timestamp() - t))

    def _release(self, flush: bool) -> None:
        """Pair the waiting depth frames, front first, whose colour has come (all of
        them with ``flush``; the oldest beyond ``max_waiting`` in any case)."""
        latest = self.colors[-1].get_timestamp() if self.colors else None
        while self.waiting:
            front = self.waiting[0]
            due = latest is not None and latest >= front.get_timestamp()
            if not (due or flush or len(self.waiting) > self.max_waiting):
                break
            self.ready.append((self.waiting.popleft(), self._nearest(front)))

    def _stopped(self) -> bool:
        if self.playback is None:
            return True
        try:
            return bool(self.playback.current_status() != self.rs.playback_status.playing)
        except RuntimeError:  # pragma: no cover - a device already gone
            return True

    def try_wait_for_frames(self, ms: int) -> tuple[bool, tuple[Any, Any] | None]:
        while True:
            if self.ready:
                return True, self.ready.popleft()
            ok, frames = self.sync.try_wait_for_frames(ms)
            if not ok:
                if self.waiting and self._stopped():
                    self._release(flush=True)  # no later colour frame will come
                    continue
                return False, None
            depth, color = frames.get_depth_frame(), frames.get_color_frame()
            if color:
                self.colors.append(color)
            if depth:
                self.waiting.append(depth)
            self._release(flush=False)

    def stop(self) -> None:
        for s in self.sensors:
            with contextlib.suppress(RuntimeError):
                s.stop()
        for s in self.sensors:
            with contextlib.suppress(RuntimeError):
                s.close()


#: the child process's entry point (a fresh interpreter: no fork of a process that holds
#: locks or librealsense threads, and no re-import of the user's ``__main__``)
_PLAYER = (
    "import sys; from robopercept.sources.realsense import _player_main; "
    "_player_main(int(sys.argv[1]), sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), "
    "float(sys.argv[5]))"
)
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


def _player_main(
    fd: int, path: str, timeout: float, max_frames: int, watchdog: float = 10.0
) -> None:
    """The child process of :func:`_play_in_child`: play the recording ``path`` with
    librealsense and send every frame, skip and error up the pipe ``fd``; ``max_frames``
    < 0 means all. Ends with ``os._exit`` (librealsense's teardown is not waited for)."""
    out = os.fdopen(fd, "wb")
    index = 0
    try:
        src = RealSenseSource.__new__(RealSenseSource)
        src.rs, src.device, src.path = import_pyrealsense2(), path, Path(path)
        src.timeout, src.max_frames = timeout, (None if max_frames < 0 else max_frames)
        src.watchdog = watchdog
        src.skipped = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the parent warns about skips
            for frame in src._frames_here():
                for skip in src.skipped[index:]:
                    _send(out, b"K", skip)
                index = len(src.skipped)
                _send(out, b"F", frame)
        for skip in src.skipped[index:]:
            _send(out, b"K", skip)
        _send(out, b"D", None)
    except RoboperceptError as exc:
        _send(out, b"E", (type(exc).__name__, str(exc)))
    except Exception as exc:  # librealsense's own errors: named, typed by the parent
        _send(out, b"E", ("", f"{type(exc).__name__}: {exc}"))
    out.close()
    os._exit(0)


def _read_exact(fd: int, n: int, deadline: float) -> bytearray | None:
    """``n`` bytes from the pipe ``fd``, waiting at most until ``deadline``
    (``time.monotonic``); None at end of file; raises TimeoutError past the deadline."""
    buf = bytearray(n)
    view, got = memoryview(buf), 0
    while got < n:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise TimeoutError
        k = os.readv(fd, [view[got:]])
        if k == 0:
            return None
        got += k
    return buf


def _play_in_child(src: RealSenseSource) -> Iterator[RGBDFrame]:
    """Play ``src``'s recording in a child process, watched.

    librealsense trusts what a recording says: some corrupt ``.bag`` / ``.db3`` files
    make it crash (SIGSEGV) or spin forever holding the GIL, out of reach of Python's
    exceptions, ``timeout`` and Ctrl-C. A fresh interpreter (``subprocess``, not
    ``multiprocessing``: no re-import of the caller's ``__main__``, and it works from a
    daemonic process) reads the recording with :meth:`RealSenseSource._frames_here` and
    sends each frame up a pipe (pickle protocol 5, the pixels as raw buffers: one copy
    each way). This process waits at most ``timeout + watchdog`` seconds for each
    message, then kills the child (SIGKILL works while native code holds the GIL).

    Yields
    ------
    RGBDFrame
        The frames as :meth:`RealSenseSource._frames_here` makes them; skipped frames are
        warned about and added to ``src.skipped``.

    Raises
    ------
    FileFormatError
        The child crashed (``librealsense crashed reading FILE at frame N``), hung, or
        librealsense raised; the frames yielded before are the consumer's to keep.
    InputError, SourceError
        As raised by librealsense playback in the child (e.g. no colour stream).
    """
    import fcntl  # POSIX only, as is select() on a pipe

    path = src.path
    assert path is not None
    r, w = os.pipe()
    with contextlib.suppress(OSError, AttributeError):  # fewer wake-ups per frame (Linux)
        fcntl.fcntl(w, fcntl.F_SETPIPE_SZ, 1 << 20)  # type: ignore[attr-defined]
    args = [
        str(path),
        repr(src.timeout),
        str(-1 if src.max_frames is None else src.max_frames),
        repr(src.watchdog),
    ]
    err = tempfile.TemporaryFile()
    try:
        proc = subprocess.Popen(
            [sys.executable, "-c", _PLAYER, str(w), *args],
            pass_fds=(w,),
            stdin=subprocess.DEVNULL,
            stdout=err,
            stderr=err,
            env=_child_env(),
        )
    except OSError as exc:
        os.close(r)
        os.close(w)
        err.close()
        raise SourceError(f"cannot start the RealSense player process: {exc}") from None
    os.close(w)
    limit = src.timeout + src.watchdog
    index, done = 0, False
    try:
        while True:
            deadline = time.monotonic() + limit
            try:
                head = _read_exact(r, _HEAD.size, deadline)
                if head is None:
                    break
                kind, n_meta, n_buf = _HEAD.unpack(head)
                sizes = _read_exact(r, 8 * n_buf, deadline)
                meta = _read_exact(r, n_meta, deadline)
                lens = struct.unpack(f"<{n_buf}Q", sizes or b"")
                bufs = [_read_exact(r, n, deadline) for n in lens]
            except TimeoutError:
                proc.kill()
                raise FileFormatError(
                    f"{path}: librealsense stopped responding for {limit:g} s reading frame "
                    f"{index} (a corrupt recording; if it is sound but slow to open, raise "
                    "the watchdog)"
                ) from None
            if meta is None or any(b is None for b in bufs):
                break
            obj = pickle.loads(meta, buffers=bufs)
            if kind == b"F":
                index = obj.index + 1
                yield obj
            elif kind == b"K":
                warnings.warn(f"skipping frame {obj[0]}: {obj[1]}", stacklevel=2)
                src.skipped.append(obj)
                index = obj[0] + 1
            elif kind == b"E":
                name, message = obj
                if name in _TYPED:
                    raise _TYPED[name](message)
                raise FileFormatError(f"{path}: librealsense failed at frame {index}: {message}")
            else:  # b"D": the end of the recording
                done = True
                return
        # the pipe closed before the end: the child died
        try:
            code = proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        why, said = _how_it_died(code, err)
        raise FileFormatError(
            f"librealsense crashed reading {path} at frame {index} ({why}); the recording "
            f"is corrupt (copy it again, or record it again){said}"
        )
    finally:
        os.close(r)
        if proc.poll() is None:
            if not done:  # the consumer stopped early, or an error: no need to wait
                proc.kill()
            try:
                proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        err.close()


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
    whole process later. So, as playback does, the recording is made in a child process
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
