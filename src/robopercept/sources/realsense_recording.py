"""RealSense recordings (``.bag``: ROS 1, ``.db3``: ROS 2) read with rosbags.

librealsense's recorder writes a ROS bag in its own topic layout, one device with its
sensors and streams::

    /device_0/sensor_S/<Stream>_<i>/info              encoding and rate
    /device_0/sensor_S/<Stream>_<i>/info/camera_info  intrinsics (ROS 1: CameraInfo)
    /device_0/sensor_S/<Stream>_<i>/camera_info       intrinsics (ROS 2: "k=v;..." text)
    /device_0/sensor_S/<Stream>_<i>/tf/<g>            extrinsics (ROS 2: tf/ref_<g>, text)
    /device_0/sensor_S/<Stream>_<i>/image/data        the frames (ROS 2: .../compressed,
                                                      .../compressedDepth: PNG)
    /device_0/sensor_S/<Stream>_<i>/image/metadata    per-frame metadata
    /device_0/sensor_S/option/Depth Units/value       metres per depth unit (ROS 2:
                                                      Depth_Units)

:class:`RealSenseRecording` reads that layout with `rosbags
<https://ternaris.gitlab.io/rosbags/>`_ (``rosbags.rosbag1.Reader`` for ``.bag``, its
SQLite storage reader for ``.db3``) and its type store (``sensor_msgs/Image``,
``CompressedImage``, ``CameraInfo``, ``realsense_msgs/StreamInfo``): no librealsense and
no pyrealsense2. It reproduces what librealsense 2.59's playback device gives
(``rs2::playback`` with ``set_real_time(False)``), checked frame for frame against
pyrealsense2 in ``tests/sources/test_realsense.py``:

- **frames**: the depth frames in recording order, each with the colour frame nearest
  in time (:func:`pair_nearest_color`); pixels as librealsense returns them (``Z16``
  depth as uint16, colour converted to RGB from ``rgb8``, ``bgr8``, ``rgba8``,
  ``bgra8``; ROS 2's PNG-compressed images decoded with Pillow);
- **timestamps**: librealsense's ``frame.get_timestamp()`` (milliseconds, in the
  frame's own domain, the camera's hardware clock for a D4xx): in a ROS 1 bag the image
  header's stamp, ``(sec + 1e-9 nsec) * 1000`` (``ros::Time::toSec``), in a ROS 2
  recording the ``timestamp`` of the frame's metadata (its header stamps are the
  recorder's clock); ``RGBDFrame.timestamp`` is ``t / 1000 - t0 / 1000`` seconds from
  the first frame yielded;
- **depth units**: raw ``Z16`` values, ``depth_scale`` the depth sensor's ``Depth
  Units`` option (metres per unit, float32 as librealsense reads it);
- **intrinsics and extrinsics** in float32, as librealsense holds them. Each stream's
  ``tf`` is its transform from its group's reference stream (ROS 1: a quaternion,
  turned into a rotation in float64 and rounded, as librealsense does); librealsense
  registers ``inv(tf)`` as the stream-to-reference extrinsics and chains depth ->
  reference -> colour, so ``T_color_depth = inv(inv(tf_color)) @ inv(tf_depth)`` in
  float32, summed in C's order: equal to ``get_extrinsics_to`` to the last bit.

Damage raises :class:`~robopercept.errors.FileFormatError` naming the file: whatever
rosbags (or SQLite, lz4, bz2) raises on a file it cannot read, a ROS 1 chunk whose
content is not the size its header states, a SQLite file that fails ``PRAGMA
quick_check``, and calibration a camera cannot have. A frame whose image cannot be
decoded (a broken PNG, a size other than its stream's) is skipped, warned about and
recorded in ``skipped``, as every source does.
"""

from __future__ import annotations

import bz2
import contextlib
import functools
import io
import os
import re
import sqlite3
import warnings
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from robopercept._checks import as_path
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.camera import Model
from robopercept.geometry.transforms import se3
from robopercept.sources.frames import RGBDFrame

__all__ = [
    "MAX_BAG_CHUNK",
    "RealSenseRecording",
    "check_bag_records",
    "pair_nearest_color",
    "rgb_from",
]

#: the largest uncompressed ROS 1 chunk accepted (ROS writes 768 KiB chunks; one
#: message larger than that, a 4K colour image, makes a chunk of some 25 MB)
MAX_BAG_CHUNK = 1 << 30
#: lz4's largest expansion (a run of one byte: 255 output bytes per input byte)
_LZ4_MAX_RATIO = 255
#: librealsense's names of its lens models (``rs2_distortion_to_string``)
_MODELS: dict[str, Model] = {
    "none": "none",
    "brown conrady": "brown_conrady",
    "modified brown conrady": "modified_brown_conrady",
    "inverse brown conrady": "inverse_brown_conrady",
}
#: librealsense models that CameraIntrinsics has no formula for
_UNSUPPORTED_MODELS = ("ftheta", "kannala brandt4")
#: colour encodings the frames can be converted from, and their channel counts
_COLOR_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4}
_DEPTH_ENCODINGS = ("z16", "mono16", "16uc1")
#: realsense_msgs/StreamInfo (ROS 1), which no type store ships
_STREAM_INFO = "uint32 fps\nstring encoding\nbool is_recommended\n"
_STREAM = re.compile(
    r"/device_0/sensor_(\d+)/(Depth|Color)_(\d+)/"
    r"(info|info/camera_info|camera_info|image/data(?:/compressed|/compressedDepth)?|"
    r"image/metadata|tf/(?:ref_)?\d+)"
)
_DEPTH_UNITS = re.compile(r"/device_0/sensor_(\d+)/option/Depth[ _]Units/value")
_IMAGES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
_TEXT = ("std_msgs/msg/String",)
#: the message types of the topics read, per role: ROS 1 (True) and ROS 2 (False)
_ROLE_TYPES: dict[bool, dict[str, tuple[str, ...]]] = {
    True: {
        "image": _IMAGES,
        "info": ("realsense_msgs/msg/StreamInfo",),
        "info/camera_info": ("sensor_msgs/msg/CameraInfo",),
        "tf": ("geometry_msgs/msg/Transform",),
        "units": ("std_msgs/msg/Float32",),
    },
    False: {
        "image": _IMAGES,
        "info": _TEXT,
        "camera_info": _TEXT,
        "tf": _TEXT,
        "image/metadata": _TEXT,
        "units": _TEXT,
    },
}
_CORRUPT = "copy it again, or record it again"

_T = TypeVar("_T")


def rgb_from(data: np.ndarray, fmt: str) -> np.ndarray:
    """RGB pixels from colour pixels in librealsense's format ``fmt``, as
    ``rs2_format`` names them (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``; any case).

    Parameters
    ----------
    data : (H, W, 3) or (H, W, 4) uint8 ndarray
    fmt : str

    Returns
    -------
    (H, W, 3) uint8 ndarray
        A view of ``data`` (reversed or sliced channels), not a copy.

    Raises
    ------
    InputError
        Another format (``yuyv``, ``mono8``, ...): record colour in one of those.

    Examples
    --------
    >>> rgb_from(np.array([[[1, 2, 3, 255]]], np.uint8), "BGRA8").tolist()
    [[[3, 2, 1]]]
    """
    fmt = fmt.lower()
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


def pair_nearest_color(
    events: Iterable[tuple[str, float, _T]], max_waiting: int = 8, max_colors: int = 4
) -> Iterator[tuple[_T, _T | None]]:
    """Pair each depth frame with the colour frame nearest to it in time, in playback
    order: librealsense's pairing of a recording's streams.

    ``events`` are ``("depth" | "color", timestamp, item)`` in the order a player
    delivers them. Each depth frame waits until a colour frame at or after its
    timestamp has come (or the events end), and is then paired with the colour frame
    nearest to it in time among the last ``max_colors`` seen, the earlier one on a tie:
    streams that share timestamps come back exactly paired (depth ``k`` with colour
    ``k``, whichever came first), a depth frame between two colour frames gets the
    nearer, and depth frames after the last colour frame get it. At most
    ``max_waiting`` depth frames wait; any beyond are paired with the nearest colour
    frame seen so far, or with None when there is none (the reader skips those).

    This is what :class:`~robopercept.sources.realsense.RealSenseSource` did over
    librealsense's ``syncer`` (which passes the first depth and colour frames of a
    recording on as two framesets, and under load a depth frame before the colour frame
    of the same instant); on a recording read in order it is deterministic.

    Parameters
    ----------
    events : iterable of (str, float, item)
    max_waiting, max_colors : int

    Yields
    ------
    (depth item, colour item or None)

    Examples
    --------
    >>> ev = [("depth", 0.0, "d0"), ("color", 0.0, "c0"), ("color", 33.0, "c1"),
    ...       ("depth", 33.0, "d1"), ("depth", 60.0, "d2")]
    >>> list(pair_nearest_color(ev))
    [('d0', 'c0'), ('d1', 'c1'), ('d2', 'c1')]
    """
    colors: deque[tuple[float, _T]] = deque(maxlen=max_colors)
    waiting: deque[tuple[float, _T]] = deque()

    def nearest(t: float) -> _T | None:
        if not colors:
            return None
        return min(colors, key=lambda c: abs(c[0] - t))[1]  # the first (earliest) on a tie

    def release(flush: bool) -> Iterator[tuple[_T, _T | None]]:
        latest = colors[-1][0] if colors else None
        while waiting:
            t, item = waiting[0]
            due = latest is not None and latest >= t
            if not (due or flush or len(waiting) > max_waiting):
                return
            waiting.popleft()
            yield item, nearest(t)

    for kind, t, item in events:
        if kind == "color":
            colors.append((t, item))
        else:
            waiting.append((t, item))
        yield from release(flush=False)
    yield from release(flush=True)


def _damaged(path: Path, exc: BaseException, what: str = "") -> FileFormatError:
    """The FileFormatError for whatever a reader raised on ``path``."""
    said = str(exc).strip() or "a consistency check of the reader failed"
    where = f" ({what})" if what else ""
    return FileFormatError(
        f"{path}: not a readable RealSense recording{where}: {type(exc).__name__}: {said}; "
        f"the recording is truncated or corrupt ({_CORRUPT})"
    )


@contextlib.contextmanager
def _reading(path: Path, what: str = "") -> Iterator[None]:
    """Turn anything but a robopercept error raised inside into a FileFormatError
    naming ``path``: rosbags, SQLite (apsw), lz4, bz2 and the message deserializers raise
    many kinds on a damaged file (ReaderError, struct.error, KeyError, AssertionError,
    UnicodeDecodeError, ...)."""
    try:
        yield
    except RoboperceptError:
        raise
    except Exception as exc:
        raise _damaged(path, exc, what) from None


def _guarded(path: Path, it: Iterator[_T]) -> Iterator[_T]:
    """``it``'s items, each ``next`` inside :func:`_reading`."""
    while True:
        with _reading(path, "reading its messages"):
            try:
                item = next(it)
            except StopIteration:
                return
        yield item


@functools.lru_cache(maxsize=2)
def _typestore(ros1: bool) -> Any:
    """rosbags' type store of ROS 1 Noetic (with realsense_msgs/StreamInfo) or ROS 2
    Humble."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:
        store.register(get_types_from_msg(_STREAM_INFO, "realsense_msgs/msg/StreamInfo"))
    return store


def _bounded_decompressor(
    path: Path, pos: int, compression: str, size: int, datasize: int
) -> Callable[[bytes], bytes]:
    """A chunk decompressor that yields at most ``size`` bytes (the uncompressed size the
    chunk header states) and refuses a chunk whose content is not that size."""
    lo, hi = {
        "none": (datasize, datasize),
        "lz4": (datasize // 2 - 64, _LZ4_MAX_RATIO * datasize + 64),
        "bz2": (1, MAX_BAG_CHUNK),
    }.get(compression, (0, -1))
    if hi < 0:
        raise FileFormatError(
            f"{path}: byte offset {pos}: chunk compression {compression!r} is not one of "
            f"none, lz4 or bz2 ({_CORRUPT})"
        )
    hi = min(hi, MAX_BAG_CHUNK)
    if not lo <= size <= hi:
        raise FileFormatError(
            f"{path}: byte offset {pos}: {compression} chunk of {datasize} bytes claims an "
            f"uncompressed size of {size} (expected {max(lo, 0)} to {hi}); the recording is "
            f"truncated or corrupt ({_CORRUPT})"
        )

    def decompress(data: bytes) -> bytes:
        if compression == "none":
            out = data
        elif compression == "bz2":
            out = bz2.BZ2Decompressor().decompress(data, max_length=size + 1)
        else:
            import lz4.frame  # rosbags' own dependency

            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
        if len(out) != size:
            held = f"more than {size}" if len(out) > size else f"{len(out)}, not {size}"
            raise FileFormatError(
                f"{path}: byte offset {pos}: {compression} chunk holds {held} bytes, the size "
                f"its header states; the recording is truncated or corrupt ({_CORRUPT})"
            )
        return out

    return decompress


def _bound_ros1_chunks(path: Path, reader: Any) -> None:
    """Replace rosbags' chunk decompressors by :func:`_bounded_decompressor`: rosbags
    does not read a chunk header's ``size``, and decompresses whatever the chunk holds."""
    from rosbags.rosbag1.reader import Chunk, Header, RecordType

    for pos, chunk in list(reader.chunks.items()):
        reader.bio.seek(pos)
        header = Header.read(reader.bio, RecordType.CHUNK)
        compression, size = header.get_string("compression"), header.get_uint32("size")
        reader.chunks[pos] = Chunk(
            chunk.datasize,
            chunk.datapos,
            _bounded_decompressor(path, pos, compression, size, chunk.datasize),
        )


def _quick_check(path: Path) -> None:
    """SQLite's own ``PRAGMA quick_check`` (every page and record well formed, O(N)) on
    a read-only connection: a damaged ``.db3`` fails here, before any frame."""
    try:
        with path.open("rb") as f:
            magic = f.read(16)
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read the recording: {exc}") from None
    if magic != b"SQLite format 3\x00":
        raise FileFormatError(
            f"{path}: not an SQLite database (a ROS 2 .db3 recording): it starts with "
            f"{magic!r}; RealSense recordings are .bag (ROS 1) or .db3 (ROS 2)"
        )
    try:
        con = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
        # its report quotes damaged records, which need not be UTF-8
        con.text_factory = lambda b: b.decode("utf-8", "replace")
        try:
            check = con.execute("PRAGMA quick_check").fetchall()
        finally:
            con.close()
    except (sqlite3.Error, UnicodeDecodeError) as exc:  # a damaged schema need not be UTF-8
        raise FileFormatError(f"{path}: corrupt SQLite recording: {exc} ({_CORRUPT})") from None
    if check != [("ok",)]:
        raise FileFormatError(f"{path}: corrupt SQLite recording: {check[0][0]} ({_CORRUPT})")


def check_bag_records(path: Path) -> None:
    """Walk the top-level records of a ROS 1 bag (``#ROSBAG V2.0``, then records of a
    4-byte header length, the header, a 4-byte data length and the data), checking each
    length against the bytes left in the file, before rosbags reads them: rosbags
    allocates what a header length says (2 GiB for a lying 0x7fffffff). Reads 8 bytes
    a record; a bag has a few dozen top-level records (chunks, connections, indices).

    The bag header record (the first) says where the index starts (``index_pos``), and
    rosbags jumps there to read the connection records: that offset must be one of the
    top-level records' starts, or a damaged ``index_pos`` sends rosbags into the middle
    of a chunk, whose bytes it reads as lengths (1.8 GiB for one flipped bit).

    Raises
    ------
    FileFormatError
        A length that runs past the end of the file, naming the record and its offset;
        an ``index_pos`` that is not the start of a record.
    """
    size = path.stat().st_size
    starts: set[int] = set()
    index_pos: int | None = None
    with open(path, "rb") as fh:
        pos = len(fh.read(13))  # the version line; rosbags checks its text
        record = 0
        while pos < size:
            starts.add(pos)
            for part in ("header", "data"):
                word = fh.read(4)
                if len(word) < 4:
                    raise FileFormatError(
                        f"{path}: top-level record {record} at byte {pos} is cut short "
                        f"(its {part} length); the recording is truncated or corrupt "
                        f"({_CORRUPT})"
                    )
                n = int.from_bytes(word, "little")
                pos += 4
                if n > size - pos:
                    raise FileFormatError(
                        f"{path}: top-level record {record} says its {part} holds {n} "
                        f"bytes at byte {pos}, but only {size - pos} are left; the "
                        f"recording is truncated or corrupt ({_CORRUPT})"
                    )
                if record == 0 and part == "header":
                    index_pos = _bag_index_pos(fh.read(min(n, 4096)))
                pos += n
                fh.seek(pos)
            record += 1
    if index_pos is not None and index_pos not in starts:
        raise FileFormatError(
            f"{path}: the bag header says the index starts at byte {index_pos}, where no "
            f"record starts; the recording is truncated or corrupt ({_CORRUPT})"
        )


def _bag_index_pos(header: bytes) -> int | None:
    """``index_pos`` of a ROS 1 bag header record's header (fields of a 4-byte length
    and ``name=value``; the value a little-endian uint64), None when it has none.

    >>> field = b"index_pos=" + (4117).to_bytes(8, "little")
    >>> _bag_index_pos(len(field).to_bytes(4, "little") + field)
    4117
    """
    at = 0
    while at + 4 <= len(header):
        n = int.from_bytes(header[at : at + 4], "little")
        body = header[at + 4 : at + 4 + n]
        at += 4 + n
        name, eq, value = body.partition(b"=")
        if eq and name == b"index_pos" and len(value) == 8:
            return int.from_bytes(value, "little")
    return None


def _open(path: Path, ros1: bool) -> Any:
    """An open rosbags reader of ``path``."""
    reader: Any
    if ros1:
        check_bag_records(path)
    with _reading(path, "opening it"):
        if ros1:
            from rosbags.rosbag1 import Reader

            reader = Reader(path)
            reader.open()
            try:
                _bound_ros1_chunks(path, reader)
            except BaseException:
                reader.close()
                raise
        else:
            from rosbags.rosbag2.storage_sqlite3 import Sqlite3Reader

            reader = Sqlite3Reader(path)
            reader.open()
    return reader


def _fields(text: str) -> dict[str, str]:
    """The ``key=value;key=value`` text librealsense writes in ROS 2 recordings."""
    out = {}
    for part in text.split(";"):
        key, eq, value = part.partition("=")
        if eq:
            out[key.strip()] = value.strip()
    return out


def _f32(values: Any) -> np.ndarray:
    """``values`` as float32 (librealsense's precision) widened to float64 (beyond
    float32's range: inf, which the checks after refuse)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(values, dtype=np.float64).astype(np.float32).astype(np.float64)


def _numbers(path: Path, text: str, what: str, n: int) -> np.ndarray:
    """``n`` comma-separated numbers of a ROS 2 recording's text, as float32."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not np.isfinite(values).all():
        raise FileFormatError(
            f"{path}: {what} is not {n} finite numbers: {text[:80]!r} ({_CORRUPT})"
        )
    out = _f32(values)
    if not np.isfinite(out).all():
        raise FileFormatError(f"{path}: {what} overflows float32: {text[:80]!r} ({_CORRUPT})")
    return out


def _rotation_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation matrix of the unit quaternion ``(x, y, z, w)`` (Eigen's
    ``toRotationMatrix``), computed in float64 from the message's float64 fields and
    rounded to float32, as librealsense stores a ROS 1 recording's
    ``geometry_msgs/Transform`` (equal to pyrealsense2's to the last bit on the real
    recording)."""
    tx, ty, tz = 2 * x, 2 * y, 2 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    r = [
        [1 - (tyy + tzz), txy - twz, txz + twy],
        [txy + twz, 1 - (txx + tzz), tyz - twx],
        [txz - twy, tyz + twx, 1 - (txx + tyy)],
    ]
    return _f32(r)


def _mul32(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a @ b`` (3x3 by 3x3 or 3) in float32, summed left to right as C code does (not
    in BLAS's order, which depends on the memory layout)."""
    a, b = a.astype(np.float32), b.astype(np.float32)
    if b.ndim == 1:
        return a[:, 0] * b[0] + a[:, 1] * b[1] + a[:, 2] * b[2]
    return a[:, 0:1] * b[0] + a[:, 1:2] * b[1] + a[:, 2:3] * b[2]


def _invert32(T: np.ndarray) -> np.ndarray:
    """``T``'s inverse ``[R^T, -R^T t]`` in float32, as librealsense inverts extrinsics."""
    rt = T[:3, :3].T
    return se3(rt, -_mul32(rt, T[:3, 3]).astype(np.float64))


def _compose32(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A @ B`` of two rigid transforms in float32 (librealsense's precision)."""
    r = _mul32(A[:3, :3], B[:3, :3])
    t = _mul32(A[:3, :3], B[:3, 3]) + A[:3, 3].astype(np.float32)
    return se3(r.astype(np.float64), t.astype(np.float64))


@dataclass
class _Stream:
    """One recorded stream: its topics and calibration."""

    kind: str  # "depth" or "color"
    sensor: int
    index: int
    topics: dict[str, Any] = field(default_factory=dict)  # role -> rosbags Connection
    encoding: str = ""
    intrinsics: CameraIntrinsics | None = None
    tf: tuple[int, np.ndarray] | None = None  # (group, T_stream_reference)


@dataclass
class _Image:
    """One image message, decoded on demand (and once: a colour frame may pair with
    several depth frames)."""

    msg: Any
    bag_time: int
    timestamp: float | None = None
    pixels: np.ndarray | str | None = None  # decoded, or why it could not be


class RealSenseRecording:
    """A librealsense recording (``.bag`` ROS 1 or ``.db3`` ROS 2), read with rosbags.

    Opening reads and checks the layout and the calibration; :meth:`frames` plays the
    depth frames in recording order, each with the colour frame nearest in time, as
    librealsense's playback gives them (see the module's notes for what is reproduced).

    Parameters
    ----------
    path : path
        The recording.

    Attributes
    ----------
    path : Path
    ros1 : bool
        A ROS 1 bag (``.bag``), else a ROS 2 SQLite recording (``.db3``).
    depth_intrinsics, color_intrinsics : CameraIntrinsics
    T_color_depth : (4, 4) ndarray
        Depth frame to colour frame (librealsense's ``get_extrinsics_to``).
    depth_scale : float
        Metres per depth unit (the depth sensor's ``Depth Units``).
    depth_frames, color_frames : int
        Image messages of each stream.

    Raises
    ------
    FileFormatError
        No such file, a file rosbags (or SQLite) cannot read, or calibration no camera
        has; the message names the file.
    InputError
        A recording without a depth or colour stream, a colour format other than
        ``rgb8``/``bgr8``/``rgba8``/``bgra8``, or a lens model CameraIntrinsics lacks.

    Examples
    --------
    >>> RealSenseRecording("missing.bag")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: missing.bag: recording not found
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = as_path(path, "the recording's path")
        if not self.path.is_file():
            raise FileFormatError(f"{self.path}: recording not found")
        self.ros1 = self.path.suffix.lower() != ".db3"
        if not self.ros1:
            _quick_check(self.path)
        reader = _open(self.path, self.ros1)
        try:
            with _reading(self.path, "reading its layout"):
                streams, units = self._layout(reader.connections)
            self._calibrate(reader, streams, units)
        finally:
            with contextlib.suppress(Exception):
                reader.close()

    # ------------------------------------------------------------------ opening

    def _layout(self, connections: list[Any]) -> tuple[dict[str, _Stream], list[tuple[int, Any]]]:
        """The depth and colour streams (the lowest-numbered of each kind with image
        data) and the ``(sensor, connection)`` of the ``Depth Units`` options."""
        found: dict[tuple[str, int, int], _Stream] = {}
        units = []
        types = _ROLE_TYPES[self.ros1]
        for c in connections:
            topic = str(c.topic)
            if m := _STREAM.fullmatch(topic):
                sensor, name, index, role = int(m[1]), m[2], int(m[3]), m[4]
                role = "image" if role.startswith("image/data") else role
                role = "tf" if role.startswith("tf/") else role
            elif m := _DEPTH_UNITS.fullmatch(topic):
                sensor, role = int(m[1]), "units"
            else:
                continue
            if role not in types:
                continue
            if c.msgtype not in types[role]:
                raise FileFormatError(
                    f"{self.path}: the topic {topic} holds {c.msgtype}, not "
                    f"{' or '.join(types[role])} ({_CORRUPT})"
                )
            if role == "units":
                units.append((sensor, c))
                continue
            kind = "depth" if name == "Depth" else "color"
            s = found.setdefault((kind, index, sensor), _Stream(kind, sensor, index))
            s.topics.setdefault(role, c)
        streams = {}
        for kind, name in (("depth", "depth"), ("color", "colour")):
            have = sorted(k for k, s in found.items() if k[0] == kind and "image" in s.topics)
            if not have:
                raise InputError(
                    f"{self.path} has no {name} stream; the plane tracker needs depth and "
                    "colour (record both)"
                )
            streams[kind] = found[have[0]]
        return streams, units

    def _calibrate(
        self, reader: Any, streams: dict[str, _Stream], units: list[tuple[int, Any]]
    ) -> None:
        """Read the streams' encodings, intrinsics and transforms and the depth units."""
        depth, color = streams["depth"], streams["color"]
        scale_conn = next((c for sensor, c in units if sensor == depth.sensor), None)
        wanted: dict[int, tuple[_Stream, str]] = {}
        for s in (depth, color):
            for role in ("info", "info/camera_info", "camera_info", "tf"):
                if role in s.topics:
                    wanted[s.topics[role].id] = (s, role)
        if scale_conn is not None:
            wanted[scale_conn.id] = (depth, "units")
        conns = [c for c in reader.connections if c.id in wanted]
        scale: float | None = None
        seen: set[int] = set()
        store = _typestore(self.ros1)
        messages = iter(reader.messages(conns)) if conns else iter(())
        for conn, _, raw in _guarded(self.path, messages):
            if conn.id in seen or conn.id not in wanted:  # a damaged index's other topic
                continue
            seen.add(conn.id)
            s, role = wanted[conn.id]
            with _reading(self.path, f"message on {conn.topic}"):
                msg = self._deserialize(store, raw, conn.msgtype)
                if role == "units":
                    scale = self._depth_units(msg)
                elif role == "info":
                    s.encoding = self._encoding(msg)
                elif role == "tf":
                    s.tf = self._transform(conn.topic, msg)
                else:
                    s.intrinsics = self._intrinsics(s, msg)
        for s, name in ((depth, "depth"), (color, "colour")):
            if s.intrinsics is None:
                raise FileFormatError(
                    f"{self.path}: the {name} stream has no camera_info (its intrinsics); "
                    f"the recording is truncated or corrupt ({_CORRUPT})"
                )
        if depth.encoding and depth.encoding not in _DEPTH_ENCODINGS:
            raise FileFormatError(
                f"{self.path}: the depth stream's format is {depth.encoding!r}, not Z16 "
                f"({_CORRUPT})"
            )
        if color.encoding:
            rgb_from(np.zeros((1, 1, 4), np.uint8), color.encoding)  # InputError if not
        if scale is None:
            raise FileFormatError(
                f"{self.path}: no depth scale in the recording (no Depth Units option on "
                f"sensor {depth.sensor}) ({_CORRUPT})"
            )
        if depth.tf is None or color.tf is None or depth.tf[0] != color.tf[0]:
            raise FileFormatError(
                f"{self.path}: no depth-to-colour extrinsics (the streams' tf topics are "
                f"missing or name different reference groups) ({_CORRUPT})"
            )
        # librealsense registers each stream's transform to its group's reference as
        # stream -> reference = inv(tf), and chains depth -> reference -> colour
        T = _compose32(_invert32(_invert32(color.tf[1])), _invert32(depth.tf[1]))
        assert depth.intrinsics is not None and color.intrinsics is not None
        self.depth_intrinsics = depth.intrinsics
        self.color_intrinsics = color.intrinsics
        self.T_color_depth = T
        self.depth_scale = scale
        self.depth_frames = int(depth.topics["image"].msgcount)
        self.color_frames = int(color.topics["image"].msgcount)
        self._streams = streams

    def _deserialize(self, store: Any, raw: bytes, msgtype: str) -> Any:
        if self.ros1:
            return store.deserialize_ros1(raw, msgtype)
        return store.deserialize_cdr(raw, msgtype)

    def _text(self, msg: Any, what: str) -> str:
        """The text of a ROS 2 ``std_msgs/String``."""
        text = getattr(msg, "data", None)
        if not isinstance(text, str):
            raise FileFormatError(
                f"{self.path}: {what} is a {type(msg).__name__}, not text ({_CORRUPT})"
            )
        return text

    def _depth_units(self, msg: Any) -> float:
        raw = msg.data if self.ros1 else self._text(msg, "the Depth Units option")
        value = _numbers(self.path, str(raw), "the Depth Units option", 1)[0]
        if not value > 0:
            raise FileFormatError(
                f"{self.path}: the depth units are {value} metres; a camera's are > 0 ({_CORRUPT})"
            )
        return float(value)

    def _encoding(self, msg: Any) -> str:
        if self.ros1:
            text = getattr(msg, "encoding", "")
        else:
            text = _fields(self._text(msg, "a stream's info")).get("encoding", "")
        return str(text).lower()

    def _intrinsics(self, s: _Stream, msg: Any) -> CameraIntrinsics:
        """CameraIntrinsics from a ROS 1 CameraInfo or a ROS 2 ``camera_info`` text."""
        name = "depth" if s.kind == "depth" else "colour"
        what = f"the {name} stream's camera_info"
        if self.ros1:
            size = (int(msg.width), int(msg.height))
            k, d = np.asarray(msg.K, np.float64), np.asarray(msg.D, np.float64)
            if k.shape != (9,):
                raise FileFormatError(f"{self.path}: {what} has no 3x3 K ({_CORRUPT})")
            vals = _f32([k[0], k[4], k[2], k[5]])
            coeffs = _f32(np.concatenate([d.ravel(), np.zeros(5)])[:5])
            model_name = str(msg.distortion_model)
        else:
            f = _fields(self._text(msg, what))
            try:
                size = (int(f["width"]), int(f["height"]))
                vals = _numbers(
                    self.path, ",".join(f[k] for k in ("fx", "fy", "ppx", "ppy")), what, 4
                )
                coeffs = _numbers(self.path, f.get("coeffs", "0,0,0,0,0"), what, 5)
                model_name = f.get("model", "None")
            except (KeyError, ValueError):
                raise FileFormatError(
                    f"{self.path}: {what} is not width, height, fx, fy, ppx, ppy: "
                    f"{str(msg.data)[:80]!r} ({_CORRUPT})"
                ) from None
        key = model_name.strip().lower().replace("_", " ")
        if key in _UNSUPPORTED_MODELS:
            raise InputError(f"unsupported RealSense distortion model {model_name!r}")
        if key not in _MODELS:
            raise FileFormatError(
                f"{self.path}: {what} names the lens model {model_name[:40]!r}, not one of "
                f"librealsense's ({_CORRUPT})"
            )
        if not np.isfinite(coeffs).all():
            raise FileFormatError(f"{self.path}: {what} has non-finite coefficients")
        fx, fy, cx, cy = (float(v) for v in vals)
        k1, k2, p1, p2, k3 = (float(c) for c in coeffs)
        try:
            return CameraIntrinsics(
                size[0], size[1], fx, fy, cx, cy, _MODELS[key], (k1, k2, p1, p2, k3)
            )
        except InputError as exc:
            raise FileFormatError(f"{self.path}: {what}: {exc} ({_CORRUPT})") from None

    def _transform(self, topic: str, msg: Any) -> tuple[int, np.ndarray]:
        """``(reference group, 4x4 transform)`` of a stream's ``tf/<group>`` message."""
        group = int(re.sub(r"\D", "", topic.rsplit("/", 1)[-1]))
        what = f"the transform on {topic}"
        if self.ros1:
            q, t = msg.rotation, msg.translation
            quat = np.array([q.x, q.y, q.z, q.w], np.float64)
            if not np.isfinite(quat).all() or abs(np.linalg.norm(quat) - 1) > 1e-3:
                raise FileFormatError(
                    f"{self.path}: {what} has the rotation quaternion {quat.tolist()}, not a "
                    f"unit quaternion ({_CORRUPT})"
                )
            r = _rotation_from_quaternion(*quat)
            tr = _numbers(self.path, f"{t.x},{t.y},{t.z}", what, 3)
        else:
            f = _fields(self._text(msg, what))
            r = _numbers(self.path, f.get("rotation", ""), what, 9).reshape(3, 3).T
            tr = _numbers(self.path, f.get("translation", ""), what, 3)
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-3):
            raise FileFormatError(
                f"{self.path}: {what} has a rotation matrix that is not orthonormal ({_CORRUPT})"
            )
        return group, se3(r, tr)

    # ------------------------------------------------------------------ playing

    def _events(self, reader: Any) -> Iterator[tuple[str, float, _Image]]:
        """``(kind, timestamp in ms, image)`` of the two streams' image messages in
        recording order, each once its metadata (ROS 2: the same stream's message at the
        same recorder time, before or after the image) has been read."""
        depth, color = self._streams["depth"], self._streams["color"]
        roles = {}
        for s in (depth, color):
            roles[s.topics["image"].id] = (s.kind, "image")
            if not self.ros1 and "image/metadata" in s.topics:
                roles[s.topics["image/metadata"].id] = (s.kind, "meta")
        conns = [c for c in reader.connections if c.id in roles]
        store = _typestore(self.ros1)
        pending: dict[str, _Image] = {}
        meta: dict[str, tuple[int, float | None]] = {}  # the last metadata's time, stamp

        def finish(kind: str) -> tuple[str, float, _Image]:
            img = pending.pop(kind)
            if img.timestamp is None or not np.isfinite(img.timestamp):
                img.pixels = "no timestamp in its metadata"
                img.timestamp = float("nan")
            return kind, img.timestamp, img

        for conn, bag_time, raw in _guarded(self.path, iter(reader.messages(conns))):
            if conn.id not in roles:  # a message on a topic not asked for (damaged index)
                continue
            for kind in [k for k, img in pending.items() if img.bag_time < bag_time]:
                yield finish(kind)
            kind, role = roles[conn.id]
            with _reading(self.path, f"message on {conn.topic} at {bag_time} ns"):
                msg = self._deserialize(store, raw, conn.msgtype)
            if role == "image":
                if kind in pending:
                    yield finish(kind)
                img = pending[kind] = _Image(msg, bag_time)
                if self.ros1:
                    stamp = msg.header.stamp
                    # ros::Time::toSec() * 1000, as librealsense computes it
                    img.timestamp = (float(stamp.sec) + 1e-9 * float(stamp.nanosec)) * 1e3
                elif kind in meta and meta[kind][0] == bag_time:
                    img.timestamp = meta[kind][1]
            else:
                value = _fields(self._text(msg, "a frame's metadata")).get("timestamp", "")
                try:
                    ts: float | None = float(value)
                except ValueError:
                    ts = None
                meta[kind] = (bag_time, ts)
                if kind in pending and pending[kind].bag_time == bag_time:
                    pending[kind].timestamp = ts
        for kind in list(pending):
            yield finish(kind)

    def _decode(self, img: _Image, s: _Stream) -> np.ndarray | str:
        """The pixels of ``img`` (uint16 depth, RGB colour), or why they cannot be read
        (whatever Pillow raises on a broken PNG, or a size that is not the stream's)."""
        if img.pixels is None:
            try:
                img.pixels = self._pixels(img.msg, s)
            except Exception as exc:  # untrusted bytes through Pillow: said, not raised
                img.pixels = f"{type(exc).__name__}: {exc}"
            img.msg = None  # the message's bytes are no longer needed
        return img.pixels

    def _pixels(self, msg: Any, s: _Stream) -> np.ndarray | str:
        k = s.intrinsics
        assert k is not None
        w, h = k.width, k.height
        name = "depth" if s.kind == "depth" else "colour"
        fmt = str(getattr(msg, "format", "")).lower()
        if fmt:  # sensor_msgs/CompressedImage: "<enc>; png compressed <enc>" or
            # "16UC1; compressedDepth png" (a 12-byte header, then the PNG)
            data = bytes(msg.data)
            if "compresseddepth" in fmt:
                if "png" not in fmt:
                    return f"{name} image compressed as {fmt!r}; only PNG is read"
                data = data[12:]
            from PIL import Image

            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                with Image.open(io.BytesIO(data)) as im:
                    if im.size != (w, h):
                        return f"{name} image is {im.size[0]}x{im.size[1]}, not {w}x{h}"
                    mode = im.mode
                    arr = np.asarray(im)
            if s.kind == "depth":
                if mode not in ("I;16", "I;16B", "I;16L", "I"):
                    return f"depth PNG is {mode}, not 16-bit grey"
                if arr.dtype != np.uint16 and (arr.min() < 0 or arr.max() > 65535):
                    return "depth PNG values outside 0..65535"
                return np.ascontiguousarray(arr, dtype=np.uint16)
            if mode not in ("RGB", "RGBA"):
                return f"colour PNG is {mode}, not RGB"
            return np.ascontiguousarray(arr[..., :3])
        # sensor_msgs/Image: rows of `step` bytes
        enc = str(msg.encoding).lower()
        if (int(msg.width), int(msg.height)) != (w, h):
            return f"{name} image is {msg.width}x{msg.height}, not {w}x{h}"
        if s.kind == "depth":
            if enc not in _DEPTH_ENCODINGS:
                return f"depth image encoding {enc!r}, not mono16"
            dtype: np.dtype[Any] = np.dtype(">u2" if msg.is_bigendian else "<u2")
            channels = 1
        else:
            if enc not in _COLOR_ENCODINGS:
                return f"colour image encoding {enc!r}, not rgb8, bgr8, rgba8 or bgra8"
            channels, dtype = _COLOR_ENCODINGS[enc], np.dtype(np.uint8)
        row = w * channels * dtype.itemsize
        step, raw = int(msg.step), np.asarray(msg.data, np.uint8).ravel()
        if step < row or raw.size < step * h:
            return f"{name} image of {raw.size} bytes, step {step}: too short for {w}x{h}"
        rows = np.ascontiguousarray(raw[: step * h].reshape(h, step)[:, :row])
        if s.kind == "depth":
            return rows.view(dtype).reshape(h, w).astype(np.uint16)
        return np.ascontiguousarray(rgb_from(rows.reshape(h, w, channels), enc))

    def frames(
        self, max_frames: int | None = None, skipped: list[tuple[int, str]] | None = None
    ) -> Iterator[RGBDFrame]:
        """Play the recording: one :class:`RGBDFrame` per depth frame, in recording order,
        with the colour frame nearest in time (:func:`pair_nearest_color`).

        Parameters
        ----------
        max_frames : int, optional
            Stop after this many frames (skipped ones count).
        skipped : list, optional
            Receives ``(index, reason)`` for each frame skipped (an image that cannot be
            decoded, no colour frame to pair with); each is also warned about.

        Yields
        ------
        RGBDFrame
            ``index`` counts from 0 (skipped frames too); ``timestamp`` in seconds from
            the first frame yielded.

        Raises
        ------
        FileFormatError
            The recording is damaged past the frames yielded (they are the caller's to
            keep).
        """
        skipped = [] if skipped is None else skipped
        depth, color = self._streams["depth"], self._streams["color"]
        reader = _open(self.path, self.ros1)
        try:
            index, t0 = 0, None
            for d, c in pair_nearest_color(self._events(reader)):
                if max_frames is not None and index >= max_frames:
                    return
                dpx = self._decode(d, depth)
                cpx = "no colour frame to pair with" if c is None else self._decode(c, color)
                if isinstance(dpx, str) or isinstance(cpx, str):
                    reason = dpx if isinstance(dpx, str) else cpx
                    warnings.warn(f"skipping frame {index}: {reason}", stacklevel=2)
                    skipped.append((index, str(reason)))
                    index += 1
                    continue
                assert d.timestamp is not None
                ts = d.timestamp / 1000.0
                t0 = ts if t0 is None else t0
                yield RGBDFrame(
                    index,
                    ts - t0,
                    dpx.copy(),
                    cpx.copy(),
                    self.depth_intrinsics,
                    self.color_intrinsics,
                    self.T_color_depth,
                    self.depth_scale,
                )
                index += 1
        finally:
            with contextlib.suppress(Exception):
                reader.close()
