"""A mutation fuzzer for every file reader, seeded from the real files in ../shared/data.

Each reader gets seed files: real files from ``../shared/data`` (see its ``SOURCES.md``;
the files are read in place, never copied into the project) and, where no real file of
a format exists, files written by the project's own writer from real data (a binary
PCD, PLY files, a 16-bit RGB PNG, a TUM folder, a calibration JSON, a ``.db3``
recording). Mutant ``i`` of a reader is a pure function of ``(seed, reader, i)``:

- the seed file is ``seeds[(i + i // M) % S]`` and the mutation ``mutations[i % M]``
  (``M`` mutations, ``S`` seeds), so a short run covers every mutation on several seeds;
- the mutation's choices (offsets, values) come from
  ``numpy.random.default_rng([seed, crc32(reader), i])``; past the first ``4 M``
  mutants a campaign stacks a second and third mutation on some inputs.

The mutations: bit flips, random bytes, truncation at a random offset, a duplicated or
removed byte range, a 32-bit word set to 0 / 0x7FFFFFFF / 0x80000000 / 0xFFFFFFFF
(little or big endian, biased to the header), non-UTF-8 bytes; in text (headers of PCD,
PLY and PNM, and whole JSON, YAML, MOT and TUM list files) a numeric token replaced by
``0``, ``-1``, ``2147483647``, ``4294967295``, ``99999999999``, ``1e308``, ``nan``,
``Infinity``, ``-0`` ..., a line removed or duplicated; format-aware: a PNG's IHDR
width, height, depth or colour type with its CRC fixed, a PNG chunk length, a
``.npz`` model rewritten with a hostile ``meta`` JSON or ``coef`` array, a ROS bag's
record, field and data length words and field values (the recording is patched in place
on one copy and restored after each call, not copied per mutant); for a TUM folder one
of its files (``camera.json``, the lists, ``planes.csv``, an image) is mutated, removed,
or a listed name made 300 characters long.

The readers of issue 47 (:mod:`tests.fuzz.loaders` holds their targets, seeds and
format-aware mutations) add: COCO, labelme, Pascal-VOC, MPII and imgaug annotations,
COCO results, OpenCV ``FileStorage`` XML/YAML/JSON, ROS transforms, a TUM
``camera.json``, the RGB-D importer's input folders, ModelNet folders, the shipped
network checkpoints, a classification run folder and a batch ``OUT`` folder; mutations
of a parsed JSON node, of XML (deep nesting, entity bombs) and YAML (alias bombs,
``!!python`` tags), file names sent outside the dataset, and checkpoints rewritten
field by field. A ``"folder"`` reader mutates one member file of a copy of its seed
folder per mutant (or removes it); ``beside`` readers write the mutant next to the
files it names; ``make`` prepares a seed in a fresh interpreter (a training run, a Dask
batch).

Each call runs in a :class:`~tests.fuzz.sandbox.Sandbox`. A call is bad when it ends
``untyped``, ``crash``, ``hang`` or ``memory`` (``MemoryError`` under the worker's
``RLIMIT_AS``), or when its traced peak allocation exceeds the bound of issue 25::

    bound = 4 x (size of the mutated file) + (bytes the reader returns for the seed)
            + 8 MiB

with 48 x (:data:`JSON_FACTOR`) in place of 4 for the bytes of JSON text (a JSON file,
the ``.json`` files of a folder): the Python objects of a parsed JSON value take 20 to
45 times its text, which no reader can change.

The last term is a floor for what any call allocates whatever its input (parser
objects, Python frames, a codec's tables; a reader whose call also evaluates, trains or
draws says a larger one); the middle term is "the decoded image's real size", taken
from the unmutated seed with the same keyword arguments, so that a header that invents
rows is caught. Such a call is counted as ``memory`` when it is confirmed: the same
input is run again at once in a fresh worker (:meth:`~tests.fuzz.sandbox.Sandbox.restart`)
and again goes over the bound. A reader's allocation depends on its input alone, so a
peak that does not come back is not the reader's: in the full campaign the worker has
run the API and flags campaigns first, and twice a typed error of a SQLite reader was
traced at 14.7 MiB there that no rerun of the same input, alone or after the readers
or the flags campaign, came near (0.3 MiB). Such a peak is counted in the tally's
``unconfirmed`` with the first attempt's message, and the rerun's outcome is the
mutant's.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tests.fuzz import loaders as lf
from tests.fuzz.report import Tally
from tests.fuzz.sandbox import Outcome, Sandbox

__all__ = [
    "DATA",
    "FLOOR_BYTES",
    "READERS",
    "Mutant",
    "Reader",
    "ReaderRun",
    "SilentWrongAnswer",
    "fuzz_reader",
    "judge",
    "run_readers_campaign",
]

#: the real data folder, ../shared/data from the repository root (as tests/conftest.py)
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
#: the repository root
ROOT = Path(__file__).resolve().parents[2]
#: the project's bundled files (the HOG face model)
PACKAGE_DATA = Path(__file__).resolve().parents[2] / "src" / "robopercept" / "data"
#: allocation every call may make whatever its input (see the module docstring)
FLOOR_BYTES = 8 * 1024 * 1024
#: bytes of Python objects one byte of JSON text may become (:func:`judge`), in place
#: of 4 for other formats: the smallest JSON values are two or three bytes of text
#: (``[],`` ``{},`` ``[0],``) and each becomes a list or dict of 56 to 64 bytes plus an
#: 8-byte slot in its parent's array, which over-allocates and is copied as it grows.
#: Measured with ``tracemalloc`` on ``json.loads`` (``fileio.parse_json``): 40 to 45 x
#: the text for 200,000 repeated ``[]``, ``{}`` or ``[0]``, 24 x for numbers, 18 x for
#: short strings; 2.5 to 3 x for the real COCO files (``read_coco_json`` on mmpose's
#: ``test_coco.json``, 61 kB: 20 x with its arrays). A reader cannot shrink Python's
#: objects, so the bound states them rather than calling every JSON reader a defect.
JSON_FACTOR = 48

SPECIAL_WORDS = (0, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 1, 0x10000)
SPECIAL_TOKENS = (
    "0",
    "-1",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "99999999999",
    "18446744073709551616",
    "1e308",
    "-1e308",
    "1e309",
    "nan",
    "NaN",
    "inf",
    "Infinity",
    "-Infinity",
    "-0",
    "1e-320",
    "0x10",
    "1.5",
    "",
)
NON_UTF8 = (b"\xff\xfe", b"\xc3\x28", b"\x80", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80")
_NUMBER = re.compile(rb"(?<![A-Za-z_])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


class SilentWrongAnswer(AssertionError):
    """A reader returned a value that breaks its documented contract (counted untyped)."""


# ----------------------------------------------------------------------------- targets
# run inside the sandbox's worker: module-level, so they are pickled by reference


def read_tum(path: str) -> list[Any]:
    """Open a TUM folder and read every frame (:class:`TUMFolderSource`)."""
    from robopercept.sources import TUMFolderSource

    return list(TUMFolderSource(path))


def read_realsense(path: str) -> list[Any]:
    """Play a ``.bag`` / ``.db3`` recording to its end (:class:`RealSenseSource`)."""
    from robopercept.sources.realsense import RealSenseSource

    return list(RealSenseSource(path, timeout=0.5, max_frames=20))


def read_mot_checked(path: str) -> Any:
    """:func:`read_mot`, then its contract: frame and id numbers are integers that the
    file stated (a ``nan``, ``inf`` or ``1e30`` must not become -2**63)."""
    from robopercept.tracking.mot_io import read_mot

    rows = read_mot(path)
    for name in ("frame", "id"):
        values = np.asarray(getattr(rows, name))
        if values.size and np.abs(values.astype(np.float64)).max() >= 2.0**53:
            bad = values[np.abs(values.astype(np.float64)) >= 2.0**53][0]
            raise SilentWrongAnswer(f"read_mot returned {name} number {bad}")
    return rows


def write_db3(path: str, color: np.ndarray, depth: np.ndarray) -> int:
    """Write a 3-frame ``.db3`` recording of ``color``/``depth`` (run in the sandbox, so
    librealsense's threads never start in the fuzzing process)."""
    from robopercept.geometry import CameraIntrinsics
    from robopercept.sources import RGBDFrame
    from robopercept.sources.realsense import write_realsense_recording

    h, w = depth.shape
    k = CameraIntrinsics(w, h, 520.9 * w / 640, 521.0 * w / 640, w / 2, h / 2)
    frames = [RGBDFrame(i, i / 30, depth, color, k, k, np.eye(4), 0.0002) for i in range(3)]
    return write_realsense_recording(path, frames)


# ----------------------------------------------------------------------- file regions


def text_region(data: bytes, fmt: str) -> int:
    """End of the part of ``data`` that is text: a PCD header through its ``DATA``
    line, a PLY header through ``end_header``, a PNM header (magic, width, height,
    maxval); the whole file for text formats; 0 for binary formats."""
    if fmt in ("text", "json", "yaml", "mot", "xml", "list"):
        return len(data)
    if fmt == "pcd":
        m = re.search(rb"^DATA[^\n]*\n", data[:65536], re.M)
        return m.end() if m else min(len(data), 1024)
    if fmt == "ply":
        i = data.find(b"end_header\n", 0, 65536)
        return i + 11 if i >= 0 else min(len(data), 1024)
    if fmt == "pnm":
        m = re.match(rb"P\d(?:\s+(?:#[^\n]*\n\s*)*\d+){2,3}\s", data)
        return m.end() if m else 0
    return 0


def _offset(data: bytes, rng: np.random.Generator, head: int) -> int:
    """A random offset, half the time inside the first ``head`` bytes (the header)."""
    n = max(len(data), 1)
    if head > 0 and rng.random() < 0.5:
        return int(rng.integers(0, min(head, n)))
    return int(rng.integers(0, n))


# --------------------------------------------------------------------------- mutations
# each: (data, rng, fmt) -> (mutated data, a short description of what was done)

Mutation = Callable[[bytes, np.random.Generator, str], tuple[bytes, str]]


def _head(data: bytes, fmt: str) -> int:
    return text_region(data, fmt) or min(len(data), 1024)


def flip_bits(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Flip 1 to 8 random bits."""
    b = bytearray(data)
    where = []
    for _ in range(int(rng.integers(1, 9))):
        i = _offset(data, rng, _head(data, fmt))
        if b:
            b[i] ^= 1 << int(rng.integers(0, 8))
            where.append(i)
    return bytes(b), f"bits flipped at {where[:4]}"


def random_bytes(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Overwrite a run of 1 to 32 bytes with random bytes."""
    i = _offset(data, rng, _head(data, fmt))
    n = int(rng.integers(1, 33))
    chunk = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    return data[:i] + chunk + data[i + n :], f"{n} random bytes at {i}"


def truncate(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Cut the file at a random offset."""
    i = _offset(data, rng, _head(data, fmt))
    return data[:i], f"truncated at {i} of {len(data)}"


def duplicate_range(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Repeat a random range of up to 4 KiB right after itself."""
    i = _offset(data, rng, _head(data, fmt))
    n = int(rng.integers(1, 4097))
    return data[: i + n] + data[i : i + n] + data[i + n :], f"bytes {i}..{i + n} duplicated"


def remove_range(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Delete a random range of up to 4 KiB."""
    i = _offset(data, rng, _head(data, fmt))
    n = int(rng.integers(1, 4097))
    return data[:i] + data[i + n :], f"bytes {i}..{i + n} removed"


def int_word(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Set a 32-bit word (aligned, little or big endian, header-biased) to a special
    value."""
    if len(data) < 4:
        return data + b"\xff\xff\xff\xff", "word appended"
    i = min(_offset(data, rng, _head(data, fmt)) & ~3, len(data) - 4)
    value = SPECIAL_WORDS[int(rng.integers(len(SPECIAL_WORDS)))]
    order = "<" if rng.random() < 0.5 else ">"
    return data[:i] + struct.pack(order + "I", value) + data[i + 4 :], (
        f"word at {i} = {value:#x} ({'LE' if order == '<' else 'BE'})"
    )


def non_utf8(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Insert bytes that are not UTF-8 (inside the text part when there is one)."""
    head = text_region(data, fmt)
    i = int(rng.integers(0, max(head, 1))) if head else _offset(data, rng, 0)
    junk = NON_UTF8[int(rng.integers(len(NON_UTF8)))]
    return data[:i] + junk + data[i:], f"non-UTF-8 {junk!r} at {i}"


def numeric_token(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Replace one number of the text part with a special token (``1e308``, ``nan``,
    ``4294967295``, ...)."""
    head = text_region(data, fmt)
    numbers = list(_NUMBER.finditer(data, 0, head)) if head else []
    if not numbers:
        return flip_bits(data, rng, fmt)
    m = numbers[int(rng.integers(len(numbers)))]
    token = SPECIAL_TOKENS[int(rng.integers(len(SPECIAL_TOKENS)))]
    line = data.count(b"\n", 0, m.start()) + 1
    return data[: m.start()] + token.encode() + data[m.end() :], (
        f"line {line}: {m.group().decode(errors='replace')} -> {token!r}"
    )


def _lines(data: bytes, fmt: str) -> tuple[list[bytes], int]:
    head = text_region(data, fmt)
    lines = data[:head].splitlines(keepends=True)
    return lines, head


def line_remove(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Remove one line of the text part (a header line for PCD/PLY)."""
    lines, head = _lines(data, fmt)
    if not lines:
        return remove_range(data, rng, fmt)
    k = int(rng.integers(len(lines)))
    what = lines[k][:40].decode(errors="replace").strip()
    return b"".join(lines[:k] + lines[k + 1 :]) + data[head:], f"line {k + 1} removed ({what})"


def line_duplicate(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Repeat one line of the text part."""
    lines, head = _lines(data, fmt)
    if not lines:
        return duplicate_range(data, rng, fmt)
    k = int(rng.integers(len(lines)))
    what = lines[k][:40].decode(errors="replace").strip()
    return b"".join(lines[: k + 1] + lines[k:]) + data[head:], f"line {k + 1} doubled ({what})"


def _png_chunks(data: bytes) -> list[tuple[int, int, bytes]]:
    """(offset, length, type) of a PNG's chunks, as far as they parse."""
    out, i = [], 8
    while i + 8 <= len(data) and len(out) < 64:
        n = struct.unpack(">I", data[i : i + 4])[0]
        out.append((i, n, data[i + 4 : i + 8]))
        if n > len(data):
            break
        i += 12 + n
    return out


def png_ihdr(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Set the IHDR width, height, bit depth or colour type, and fix the chunk's CRC so
    that the decoder believes it."""
    if len(data) < 33 or data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        return int_word(data, rng, fmt)
    ihdr = bytearray(data[16:29])
    w, h = struct.unpack(">II", ihdr[:8])
    choice = int(rng.integers(4))
    sizes = (0, 1, 100_000, 50_000_000, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, w * 1000)
    if choice == 0:
        ihdr[0:4] = struct.pack(">I", sizes[int(rng.integers(len(sizes)))] & 0xFFFFFFFF)
    elif choice == 1:
        ihdr[4:8] = struct.pack(">I", sizes[int(rng.integers(len(sizes)))] & 0xFFFFFFFF)
    elif choice == 2:
        ihdr[8] = int(rng.choice([0, 1, 2, 3, 4, 7, 8, 16, 32, 255]))
    else:
        ihdr[9] = int(rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 255]))
    crc = struct.pack(">I", zlib.crc32(b"IHDR" + bytes(ihdr)) & 0xFFFFFFFF)
    nw, nh = struct.unpack(">II", ihdr[:8])
    desc = f"IHDR {w}x{h} -> {nw}x{nh}, depth {ihdr[8]}, colour type {ihdr[9]} (CRC fixed)"
    return data[:16] + bytes(ihdr) + crc + data[33:], desc


def png_chunk_len(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Set one chunk's length word (not covered by the CRC) to a special value."""
    chunks = _png_chunks(data) if data[:8] == b"\x89PNG\r\n\x1a\n" else []
    if not chunks:
        return int_word(data, rng, fmt)
    off, n, kind = chunks[int(rng.integers(len(chunks)))]
    value = int(rng.choice([0, n + 1, max(n - 1, 0), 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF]))
    value &= 0xFFFFFFFF
    desc = f"{kind.decode(errors='replace')} chunk at {off}: length {n} -> {value:#x}"
    return data[:off] + struct.pack(">I", value) + data[off + 4 :], desc


def npz_content(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Rewrite a HOG model ``.npz`` with a hostile ``meta`` (a number made special, a
    key removed or of the wrong type, not JSON) or ``coef`` (wrong shape or dtype)."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        meta = json.loads(str(arrays["meta"]))
    except Exception:  # the seed is a model; a stacked mutation may have broken it
        return flip_bits(data, rng, fmt)
    choice = int(rng.integers(6))
    if not isinstance(meta, dict) or not meta:  # an earlier mutation replaced it
        choice = 3 + choice % 3
    if choice == 0:  # a number of the JSON made special
        text = json.dumps(meta).encode()
        text, desc = numeric_token(text, rng, "json")
        arrays["meta"] = np.array(text.decode(errors="replace"))
    elif choice == 1:
        key = sorted(meta)[int(rng.integers(len(meta)))]
        del meta[key]
        arrays["meta"], desc = np.array(json.dumps(meta)), f"meta without {key!r}"
    elif choice == 2:
        key = sorted(meta)[int(rng.integers(len(meta)))]
        bad = [None, "x", [], {}, [1, 2, 3], -1, 1e308, True][int(rng.integers(8))]
        meta[key] = bad
        arrays["meta"], desc = np.array(json.dumps(meta)), f"meta[{key!r}] = {bad!r}"
    elif choice == 3:
        junk = ["{", "[]", "1", "null", '"kind"', "\udcff"][int(rng.integers(6))]
        arrays["meta"], desc = np.array(junk), f"meta = {junk!r}"
    elif choice == 4:
        shapes = [(0,), (1,), (2, 3), (10**6,), ()]
        shape = shapes[int(rng.integers(len(shapes)))]
        arrays["coef"], desc = np.ones(shape), f"coef of shape {shape}"
    else:
        dtype = ["U3", "complex128", "bool", "int8", "V8", "S2"][int(rng.integers(6))]
        arrays["coef"], desc = np.zeros(arrays["coef"].shape, dtype), f"coef as {dtype}"
    buf = io.BytesIO()
    try:
        np.savez(buf, **arrays)
    except Exception:  # a value NumPy cannot save without pickle: mutate bytes instead
        return flip_bits(data, rng, fmt)
    return buf.getvalue(), desc


def model_content(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """Rewrite a classifier model ``.npz`` (:func:`robopercept.learning.save_model`) with
    a hostile header (a value of the wrong type, a number made special) or one hostile
    array: another shape or
    dtype, a NaN, an index made -5, 0, 2**31 or 2**62 (a tree child pointing back, a
    split feature out of range), or the array removed."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        names = sorted(k for k in arrays if k != "meta")
    except Exception:  # a stacked mutation broke the archive: mutate bytes instead
        return flip_bits(data, rng, fmt)
    if not names or rng.random() < 0.3:  # the JSON header
        try:
            meta = json.loads(str(arrays["meta"]))
        except Exception:
            meta = None
        if isinstance(meta, dict) and meta and rng.random() < 0.7:
            key = sorted(meta)[int(rng.integers(len(meta)))]
            bad = [None, "x", [], {}, [1, 2, 3], -1, 0, 2**62, 1e308, True, "SVC"]
            meta[key] = bad[int(rng.integers(len(bad)))]
            text, desc = json.dumps(meta), f"meta[{key!r}] = {meta[key]!r}"
        else:
            raw = str(arrays.get("meta", "{}")).encode()
            out, desc = numeric_token(raw, rng, "json")
            text = out.decode(errors="replace")
        arrays["meta"] = np.array(text)
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return buf.getvalue(), desc
    name = names[int(rng.integers(len(names)))]
    a = arrays[name]
    choice = int(rng.integers(5))
    if choice == 0 or a.size == 0:
        shape = [(0,), (1,), (2, 3), (10**5,), (), (*a.shape, 2)][int(rng.integers(6))]
        arrays[name], desc = np.ones(shape, a.dtype), f"{name} of shape {shape}"
    elif choice == 1:
        dtype = ["U3", "complex128", "bool", "int8", "float32", "S2", "uint64"]
        dt = dtype[int(rng.integers(len(dtype)))]
        arrays[name], desc = np.zeros(a.shape, dt), f"{name} as {dt}"
    elif choice == 2:
        special = [-5, 0, 2**31, 2**62, -(2**62)] if a.dtype.kind in "iu" else [np.nan, np.inf]
        value = special[int(rng.integers(len(special)))]
        b = a.copy()
        try:
            b.flat[int(rng.integers(b.size))] = value
        except (OverflowError, ValueError):
            return flip_bits(data, rng, fmt)
        arrays[name], desc = b, f"{name}[one] = {value}"
    elif choice == 3:
        b = a.copy()
        rng.shuffle(b.reshape(-1))
        arrays[name], desc = b, f"{name} shuffled"
    else:
        del arrays[name]
        desc = f"{name} removed"
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue(), desc


BINARY: tuple[Mutation, ...] = (
    flip_bits,
    random_bytes,
    truncate,
    duplicate_range,
    remove_range,
    int_word,
)
TEXT: tuple[Mutation, ...] = (numeric_token, line_remove, line_duplicate, non_utf8, *BINARY)
PNG: tuple[Mutation, ...] = (png_ihdr, png_chunk_len, *BINARY)
NPZ: tuple[Mutation, ...] = (npz_content, npz_content, *BINARY)
MODEL: tuple[Mutation, ...] = (model_content, model_content, model_content, *BINARY)

# ------------------------------------------------------------------------- ROS bag


def bag_words(data: bytes, max_records: int = 8) -> list[tuple[int, int, str]]:
    """The length words of a ROS bag v2.0's first records (and of the records inside
    its first uncompressed chunk): ``(offset, size in bytes, description)``, plus the
    ``op`` byte and the integer field values of each record header.

    A record is ``header_len (u32 LE), header, data_len (u32 LE), data``; a header is a
    run of ``field_len (u32 LE), name=value`` (rosbag format 2.0).
    """
    out: list[tuple[int, int, str]] = []

    def walk(start: int, stop: int, limit: int, where: str) -> None:
        i, n = start, 0
        while i + 4 <= stop and n < limit:
            hlen = struct.unpack_from("<I", data, i)[0]
            out.append((i, 4, f"{where} record {n} header_len"))
            j, hend = i + 4, i + 4 + hlen
            fields = {}
            while j + 4 <= min(hend, stop):
                flen = struct.unpack_from("<I", data, j)[0]
                out.append((j, 4, f"{where} record {n} field_len"))
                body = data[j + 4 : j + 4 + flen]
                name, _, value = body.partition(b"=")
                vstart = j + 4 + len(name) + 1
                if name == b"op":
                    out.append((vstart, 1, f"{where} record {n} op"))
                elif len(value) in (4, 8):
                    label = name.decode(errors="replace")
                    out.append((vstart, len(value), f"{where} record {n} {label}"))
                fields[name] = value
                j += 4 + flen
            if hend + 4 > stop:
                return
            dlen = struct.unpack_from("<I", data, hend)[0]
            out.append((hend, 4, f"{where} record {n} data_len"))
            op = fields.get(b"op", b"")
            if op == b"\x05" and fields.get(b"compression") == b"none" and where == "top":
                walk(hend + 4, min(hend + 4 + dlen, stop), 16, f"chunk@{hend + 4}")
            i = hend + 4 + dlen
            n += 1

    if data.startswith(b"#ROSBAG V2.0\n"):
        walk(13, len(data), max_records, "top")
    return out


def bag_edit(
    data: bytes, rng: np.random.Generator
) -> tuple[list[tuple[int, bytes]], int | None, str, str]:
    """One mutation of a ROS bag as in-place edits: ``(patches, truncate_at, name,
    description)``.

    A length word or an integer field set to 0 / 0xFFFFFFFF / 0x7FFFFFFF / off by one,
    the op byte changed, a few bits of the first 64 KiB flipped, random bytes there,
    or the file truncated.
    """
    words = bag_words(data)
    choice = int(rng.integers(5)) if words else 3
    if choice in (0, 1):  # a length word or a field value (the defect)
        off, size, what = words[int(rng.integers(len(words)))]
        old = int.from_bytes(data[off : off + size], "little")
        if size == 1:
            new = int(rng.choice([0, 1, 2, 3, 4, 5, 6, 7, 255]))
        else:
            top = (1 << (8 * size)) - 1
            new = int(rng.choice([0, top, top >> 1, old + 1, max(old - 1, 0), old * 2])) & top
        name = "bag_length_word" if what.endswith("_len") else "bag_field_value"
        return [(off, new.to_bytes(size, "little"))], None, name, f"{what} {old:#x} -> {new:#x}"
    if choice == 2:
        head = min(len(data), 65536)
        patches, where = [], []
        for _ in range(int(rng.integers(1, 9))):
            i = int(rng.integers(0, head))
            patches.append((i, bytes([data[i] ^ (1 << int(rng.integers(8)))])))
            where.append(i)
        return patches, None, "flip_bits", f"bits flipped at {where[:4]}"
    if choice == 3:
        cut = (
            int(rng.integers(0, len(data)))
            if rng.random() < 0.5
            else int(rng.integers(0, min(len(data), 65536)))
        )
        return [], cut, "truncate", f"truncated at {cut} of {len(data)}"
    i = int(rng.integers(0, min(len(data), 65536) - 32))
    n = int(rng.integers(1, 33))
    chunk = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    return [(i, chunk)], None, "random_bytes", f"{n} random bytes at {i}"


@contextlib.contextmanager
def patched(
    path: Path, original: bytes, patches: Sequence[tuple[int, bytes]], cut: int | None
) -> Iterator[Path]:
    """Apply byte patches (or a truncation) to ``path`` in place, and restore it to
    ``original`` afterwards (only the touched bytes are written back)."""
    with path.open("r+b") as fh:
        for off, new in patches:
            fh.seek(off)
            fh.write(new)
        if cut is not None:
            fh.truncate(cut)
    try:
        yield path
    finally:
        with path.open("r+b") as fh:
            for off, new in patches:
                fh.seek(off)
                fh.write(original[off : off + len(new)])
            if cut is not None:
                fh.seek(cut)
                fh.write(original[cut:])


# ----------------------------------------------------------------------------- readers


@dataclass(frozen=True)
class Reader:
    """A reader under test.

    Attributes
    ----------
    name : str
        Row name of the table (``"pcd"``, ``"image"``).
    target : str or callable
        What the sandbox calls with the mutant's path (``"module:function"``).
    fmt : str
        Format family for the text/header regions (``"pcd"``, ``"ply"``, ``"png"``,
        ``"text"``, ``"json"``, ``"xml"``, ``"pt"`` ...; ``"auto"``: told by each seed's
        suffix; ``"tum"`` and ``"folder"`` for folders, ``"bag"`` for in-place
        patching).
    seeds : callable
        ``seeds(workdir) -> list[Path]``: the seed files (or folders); may write derived
        seeds into ``workdir``; an empty list skips the reader (no data).
    mutations : tuple of callable
        The byte mutations (unused for ``"tum"``, ``"folder"``, ``"auto"`` and
        ``"bag"``).
    kwargs : tuple of dict
        Keyword arguments cycled over the mutants (``read_image``'s ``mode``).
    timeout : float
        Seconds per call before it counts as a hang.
    members : tuple of str
        ``"folder"``: patterns (``fnmatch``, relative POSIX paths) of the files that are
        mutated or removed, one per mutant in turn; the others are copied as they are.
    beside : bool
        Write each file mutant into its seed's folder (a copy in ``workdir``), where the
        files it names lie (a COCO file's images, a results file's ground truth).
    make : callable, optional
        ``make(workdir)``, a module-level function run once in a fresh interpreter
        before ``seeds`` (a training run, a Dask batch: kept out of the fuzzing
        process).
    floor : int
        The bound's floor in bytes (:func:`judge`): what any call of the target
        allocates whatever its input.
    """

    name: str
    target: str | Callable[..., Any]
    fmt: str
    seeds: Callable[[Path], list[Path]]
    mutations: tuple[Mutation, ...] = BINARY
    kwargs: tuple[dict[str, Any], ...] = ({},)
    timeout: float = 10.0
    members: tuple[str, ...] = ()
    beside: bool = False
    make: Callable[[str], Any] | None = None
    floor: int = FLOOR_BYTES


def _real(*parts: str) -> list[Path]:
    """The real seed files that exist (none when ../shared/data is absent)."""
    return [p for p in (DATA / q for q in parts) if p.is_file()]


def _pcd_seeds(work: Path) -> list[Path]:
    from robopercept.pointcloud import read_point_cloud, write_point_cloud

    seeds = _real(
        "pointcloud/pcl/bunny.pcd",
        "pointcloud/pcl/bun0.pcd",
        "pointcloud/pcl/car6.pcd",
        "pointcloud/pcl/table_scene_mug_stereo_textured.pcd",
    )
    car = DATA / "pointcloud/pcl/car6.pcd"
    if car.is_file():  # no real uncompressed binary PCD: the project's writer makes one
        out = work / "car6_binary.pcd"
        write_point_cloud(out, read_point_cloud(car).finite(), binary=True)
        seeds.append(out)
    return seeds


def _ply_seeds(work: Path) -> list[Path]:
    from robopercept.pointcloud import read_point_cloud, write_point_cloud

    seeds = _real("pointcloud_cls/ModelNet_samples_zeaggler/bathtub/bathtub_0154_open3d.ply")
    bun0 = DATA / "pointcloud/pcl/bun0.pcd"
    table = DATA / "pointcloud/pcl/table_scene_mug_stereo_textured.pcd"
    if bun0.is_file():  # normals
        cloud = read_point_cloud(bun0).finite()
        write_point_cloud(work / "bun0_ascii.ply", cloud, binary=False)
        seeds.append(work / "bun0_ascii.ply")
    if table.is_file():  # colours, 3000 points
        cloud = read_point_cloud(table).finite()
        keep = np.zeros(len(cloud.points), bool)
        keep[:3000] = True
        cloud = cloud.select(keep)
        write_point_cloud(work / "table_binary.ply", cloud, binary=True)
        write_point_cloud(work / "table_ascii.ply", cloud, binary=False)
        seeds += [work / "table_binary.ply", work / "table_ascii.ply"]
    return seeds


def _mesh_seeds(work: Path) -> list[Path]:
    """Real ModelNet meshes: OFF (with its "OFF490 518 0" first line) and a PLY mesh."""
    del work
    return _real(
        "pointcloud_cls/ModelNet10/sofa/test/sofa_0681.off",
        "pointcloud_cls/ModelNet_samples_zeaggler/bed/bed_0001.off",
        "pointcloud_cls/ModelNet_samples_zeaggler/bathtub/bathtub_0154_open3d.ply",
    )


def _image_seeds(work: Path) -> list[Path]:
    from robopercept.imaging import read_image, write_image

    seeds = _real(
        "rgbd/single_frames_open3d/TUM_depth.png",  # 16-bit gray PNG
        "calibration/opencv_chessboard_stereo/left01.jpg",  # JPEG
        "rgbd/rgbd5_poses_slambook2/depth/1.pgm",  # 16-bit PGM
        "rgbd/pcl_kinect_grabber_sequence/frame_20121214T142255.814212_depth.tiff",
        "features/opencv_box/box.png",  # 8-bit gray PNG
    )
    color = DATA / "rgbd/single_frames_open3d/TUM_color.png"
    if color.is_file():  # no real 16-bit RGB PNG or 8-bit PPM: written from a real photo
        crop = read_image(color, mode="rgb")[200:296, 240:368]
        write_image(work / "tum_rgb16.png", crop.astype(np.uint16) * 257)
        write_image(work / "tum_rgb8.ppm", crop)
        write_image(work / "tum_rgb8.png", crop)
        seeds += [work / "tum_rgb16.png", work / "tum_rgb8.ppm", work / "tum_rgb8.png"]
    return seeds


def _mot_seeds(work: Path) -> list[Path]:
    seeds = _real(
        "video/mot17_mini/MOT17-02-FRCNN/gt/gt.txt", "video/mot17_mini/MOT17-04-FRCNN/gt/gt.txt"
    )
    det = DATA / "video/mot17_mini/MOT17-02-FRCNN/det/det.txt"
    if det.is_file():  # the first 300 rows: the whole file takes 0.3 s a read
        lines = det.read_bytes().splitlines(keepends=True)[:300]
        (work / "det_head.txt").write_bytes(b"".join(lines))
        seeds.append(work / "det_head.txt")
    return seeds


def _tum_seeds(work: Path) -> list[Path]:
    """A 2-frame TUM folder written by :func:`write_tum_folder` from 96x72 crops of two
    real TUM RGB-D frames (slambook2's pair; depth scale 1/5000, fr1 intrinsics)."""
    from robopercept.geometry import CameraIntrinsics
    from robopercept.imaging import read_image
    from robopercept.sources import RGBDFrame, write_tum_folder

    root = DATA / "rgbd/tum_pair_slambook2"
    if not (root / "1.png").is_file():
        return []
    x0, y0, w, h = 280, 200, 96, 72
    k = CameraIntrinsics(w, h, 520.9, 521.0, 325.1 - x0, 249.7 - y0)
    frames = []
    for i in (1, 2):
        color = read_image(root / f"{i}.png", mode="rgb")[y0 : y0 + h, x0 : x0 + w]
        depth = read_image(root / f"{i}_depth.png")[y0 : y0 + h, x0 : x0 + w]
        truth = {"plane": (np.array([0.0, 0.6, -0.8]), 1.25)} if i == 1 else {}
        frames.append(
            RGBDFrame(
                i - 1,
                1305031102.0 + i / 30,
                np.ascontiguousarray(depth),
                np.ascontiguousarray(color),
                k,
                k,
                np.eye(4),
                1 / 5000,
                truth,
            )
        )
    return [write_tum_folder(work / "tum_seq", frames)]


def _calibration_json_seeds(work: Path) -> list[Path]:
    """The OpenCV sample's reference result (left_intrinsics.yml) saved with
    :func:`save_calibration` (no real calibration JSON exists)."""
    from robopercept.calibration.intrinsics import (
        CalibrationResult,
        load_calibration,
        save_calibration,
    )

    yml = DATA / "calibration/opencv_chessboard_stereo/left_intrinsics.yml"
    if not yml.is_file():
        return []
    cam = load_calibration(yml)
    ext = np.asarray(cam.get("extrinsic_parameters", np.zeros((13, 6))), float).reshape(-1, 6)
    errors = np.asarray(cam.get("per_view_reprojection_errors", np.zeros(len(ext))), float)
    result = CalibrationResult(
        cam["K"],
        cam["dist"],
        ext[:, :3],
        ext[:, 3:],
        float(cam.get("avg_reprojection_error", 0.0)),
        errors.ravel(),
        tuple(cam["image_size"]),
    )
    save_calibration(work / "left_intrinsics.json", result)
    return [work / "left_intrinsics.json"]


def _calibration_yaml_seeds(work: Path) -> list[Path]:
    """OpenCV's sample result (an ``!!opencv-matrix`` FileStorage YAML) and the same
    values as a ROS ``camera_info`` YAML (``{rows, cols, data}`` mappings)."""
    from robopercept.calibration.intrinsics import load_calibration

    seeds = _real("calibration/opencv_chessboard_stereo/left_intrinsics.yml")
    if seeds:
        cam = load_calibration(seeds[0])
        w, h = cam["image_size"]
        k = ", ".join(f"{v:.17g}" for v in np.ravel(cam["K"]))
        d = ", ".join(f"{v:.17g}" for v in np.ravel(cam["dist"]))
        ros = (
            f"image_width: {w}\nimage_height: {h}\ncamera_name: left\n"
            f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{k}]\n"
            f"distortion_model: plumb_bob\n"
            f"distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [{d}]\n"
        )
        (work / "left_ros.yaml").write_text(ros)
        seeds.append(work / "left_ros.yaml")
    return seeds


def _bag_seeds(work: Path) -> list[Path]:
    return _real("rgbd/realsense_bag/single_depth_color_640x480.bag")


def _hog_seeds(work: Path) -> list[Path]:
    p = PACKAGE_DATA / "face_hog_svm.npz"
    return [p] if p.is_file() else []


def load_model_and_predict(path: str) -> Any:
    """:func:`robopercept.learning.load_model`, then predict three rows of zeros: a
    loaded model must predict without crashing (tree indices, SVC machines checked)."""
    from robopercept.learning import load_model

    saved = load_model(path)
    X = np.zeros((3, saved.n_features))
    out = [saved.predict(X)]
    for method in ("predict_proba", "decision_function"):
        if hasattr(saved.model, method):
            out.append(getattr(saved.model, method)(saved.transform(X)))
    return out


def _model_seeds(work: Path) -> list[Path]:
    """Classifier model files written by :func:`save_model` from models trained on real
    data (the iris measurements shipped with scikit-learn): a tree, a 5-tree forest,
    an RBF SVC with feature and class names and standardization, an LDA."""
    from sklearn.datasets import load_iris

    from robopercept.learning import (
        LDA,
        SVC,
        DecisionTreeClassifier,
        RandomForestClassifier,
        SavedModel,
        save_model,
        standard_scaling,
    )

    X, y = load_iris(return_X_y=True)
    mean, scale = standard_scaling(X)
    svc = SVC().fit((X - mean) / scale, y)
    names = ["sepal length", "sepal width", "petal length", "petal width"]
    models = {
        "tree.npz": DecisionTreeClassifier(max_depth=4, random_state=0).fit(X, y),
        "forest.npz": RandomForestClassifier(5, random_state=0).fit(X, y),
        "svc.npz": SavedModel(
            svc, names, ["setosa", "versicolor", "virginica"], "species", mean, scale
        ),
        "lda.npz": LDA().fit(X, y),
    }
    return [save_model(m, work / name) for name, m in models.items()]


def _vot_seeds(work: Path) -> list[Path]:
    """VOT "bag"'s polygon ground truth, and the same boxes written as ``x,y,w,h``
    rectangles (with a NaN frame) by the project's own conversion."""
    seeds = _real("video/vot_bag/groundtruth.txt")
    if seeds:
        from robopercept.tracking.metrics import read_vot_groundtruth

        boxes = read_vot_groundtruth(seeds[0])[:60]
        boxes[10] = np.nan
        lines = [",".join(f"{v:.2f}" for v in b) for b in boxes]
        (work / "vot_rect.txt").write_text("\n".join(lines) + "\n")
        seeds.append(work / "vot_rect.txt")
    return seeds


def _flo_seeds(work: Path) -> list[Path]:
    """Middlebury's RubberWhale ground truth (584 x 388, with unknown pixels) and a
    40 x 30 crop of it written by :func:`write_flo` (small: mutants reach the data)."""
    from robopercept.motion import read_flo, write_flo

    seeds = _real("flow/middlebury_rubberwhale/RubberWhale.flo")
    if seeds:
        crop = read_flo(seeds[0])[180:210, 260:300]
        seeds.append(write_flo(work / "rubberwhale_crop.flo", crop))
    return seeds


READERS: tuple[Reader, ...] = (
    Reader("pcd", "robopercept.pointcloud.io:read_point_cloud", "pcd", _pcd_seeds, TEXT),
    Reader("ply", "robopercept.pointcloud.io:read_point_cloud", "ply", _ply_seeds, TEXT),
    Reader("mesh", "robopercept.pointcloud.mesh:read_mesh", "text", _mesh_seeds, TEXT),
    Reader(
        "image",
        "robopercept.imaging.io:read_image",
        "image",
        _image_seeds,
        PNG,
        ({}, {"mode": "rgb"}, {"mode": "gray"}),
    ),
    Reader("mot", read_mot_checked, "mot", _mot_seeds, TEXT),
    Reader("vot", "robopercept.tracking.metrics:read_vot_groundtruth", "text", _vot_seeds, TEXT),
    Reader("tum", read_tum, "tum", _tum_seeds),
    Reader(
        "calibration-json",
        "robopercept.calibration.intrinsics:load_calibration",
        "json",
        _calibration_json_seeds,
        TEXT,
    ),
    Reader(
        "calibration-yaml",
        "robopercept.calibration.intrinsics:load_calibration",
        "yaml",
        _calibration_yaml_seeds,
        TEXT,
    ),
    Reader(
        "hog-model", "robopercept.learning.hog_detector:HogDetector.load", "npz", _hog_seeds, NPZ
    ),
    Reader("learn-model", load_model_and_predict, "npz", _model_seeds, MODEL),
    Reader("realsense-bag", read_realsense, "bag", _bag_seeds, timeout=15.0),
    Reader("realsense-db3", read_realsense, "db3", lambda work: [], BINARY, timeout=15.0),
    Reader("flo", "robopercept.motion.flow_truth:read_flo", "flo", _flo_seeds, BINARY),
    # ---- issue 47: annotations, calibration and camera files, folders, checkpoints, run
    # folders and batch manifests (tests.fuzz.loaders.READER_SPECS)
    *(
        Reader(**{**spec, "mutations": lf.mutations(spec.get("mutations", "binary"))})
        for spec in lf.READER_SPECS
    ),
)


def _fmt_of(path: Path, reader: Reader) -> str:
    """Format family of one file (a TUM or folder member, an image by its extension, a
    file of an ``"auto"`` reader by its suffix)."""
    suffix = path.suffix.lower()
    if reader.fmt in ("folder", "auto"):
        return lf.member_format(path.name)
    if reader.fmt not in ("image", "tum"):
        return reader.fmt
    return {
        ".png": "png",
        ".pgm": "pnm",
        ".ppm": "pnm",
        ".json": "json",
        ".txt": "text",
        ".csv": "text",
    }.get(suffix, "binary")


def _mutations_for(fmt: str, reader: Reader) -> tuple[Mutation, ...]:
    if reader.fmt in ("folder", "auto"):
        return lf.mutations(fmt)
    if reader.fmt == "tum":
        return PNG if fmt == "png" else TEXT
    if fmt == "pnm":
        return (numeric_token, line_remove, *BINARY)
    if fmt in ("png",):
        return PNG
    return reader.mutations


# ---------------------------------------------------------------------------- running


@dataclass(frozen=True)
class Mutant:
    """One fuzz input and how the reader took it.

    Attributes
    ----------
    reader, seed : str
        Reader name and the seed file it was made from.
    index : int
        Its number ``i`` (with the campaign's seed, it remakes the input).
    mutation : str
        Mutation name(s) (``"png_ihdr"``, ``"camera.json:numeric_token"``).
    detail : str
        What exactly was changed.
    outcome : Outcome
        As the sandbox reported it, with an over-bound allocation turned into
        ``kind="memory"``.
    bound_mb : float
        The allocation bound of this input, MiB.
    unconfirmed : str
        The first attempt's over-bound message when the rerun in a fresh worker stayed
        within the bound (see the module docstring); empty otherwise.
    """

    reader: str
    seed: str
    index: int
    mutation: str
    detail: str
    outcome: Outcome
    bound_mb: float
    unconfirmed: str = ""


@dataclass
class ReaderRun:
    """The mutants of one reader and their tally."""

    reader: str
    mutants: list[Mutant] = field(default_factory=list)
    seed_failures: list[tuple[str, Outcome]] = field(default_factory=list)
    tally: Tally | None = None

    def bad(self, kinds: Sequence[str]) -> list[Mutant]:
        """The mutants whose outcome kind is in ``kinds``."""
        return [m for m in self.mutants if m.outcome.kind in kinds]


def _tree_size(path: Path, suffix: str | None = None) -> int:
    """Bytes of the file ``path`` or of all files under the folder ``path`` (only those
    ending in ``suffix`` when given)."""
    if path.is_dir():
        return sum(
            p.stat().st_size
            for p in path.rglob("*")
            if p.is_file() and (suffix is None or p.name.lower().endswith(suffix))
        )
    if suffix is not None and not path.name.lower().endswith(suffix):
        return 0
    return path.stat().st_size if path.exists() else 0


def judge(
    outcome: Outcome, size: int, decoded: int, floor: int = FLOOR_BYTES, json_size: int = 0
) -> tuple[Outcome, float]:
    """Apply the allocation bound of issue 25 to one reader call.

    ``bound = 4 * (size - json_size) + JSON_FACTOR * json_size + decoded + floor``; an
    ``ok`` or ``typed`` outcome whose traced peak exceeds it becomes ``kind="memory"``,
    ``error="over bound"``. JSON text is given :data:`JSON_FACTOR` instead of 4: its
    parsed value is Python objects, whose size the reader cannot choose (see there).

    Parameters
    ----------
    outcome : Outcome
        As the sandbox reported the call.
    size : int
        Bytes of the mutated file (of all files of a mutated folder).
    decoded : int
        Bytes the reader returns for the unmutated seed.
    floor : int
        What any call allocates whatever its input (:data:`FLOOR_BYTES` unless the
        reader says more).
    json_size : int
        Bytes of ``size`` that are JSON text the reader parses (the mutated file when
        it is JSON, the ``.json`` files of a mutated folder).

    Returns
    -------
    Outcome
        ``outcome`` itself when within the bound.
    float
        The bound, MiB.
    """
    json_size = min(max(json_size, 0), size)
    bound = 4 * (size - json_size) + JSON_FACTOR * json_size + decoded + floor
    if outcome.kind in ("ok", "typed") and outcome.peak_mb * 2**20 > bound:
        text = f"4 x {size} B file" if not json_size else (
            f"4 x {size - json_size} B + {JSON_FACTOR} x {json_size} B of JSON"
        )  # fmt: skip
        msg = (
            f"peak {outcome.peak_mb:.1f} MiB > bound {bound / 2**20:.1f} MiB ({text} + "
            f"{decoded} B decoded + {floor / 2**20:g} MiB); was {outcome.kind} "
            f"{outcome.error} {outcome.message}"
        )
        outcome = dataclasses.replace(outcome, kind="memory", error="over bound", message=msg[:300])
    return outcome, bound / 2**20


def _mutate(
    data: bytes,
    rng: np.random.Generator,
    muts: Sequence[Mutation],
    first: int,
    fmt: str,
    stack: int,
) -> tuple[bytes, str, str]:
    names, details = [], []
    for k in range(stack):
        m = muts[first % len(muts)] if k == 0 else muts[int(rng.integers(len(muts)))]
        try:
            data, d = m(data, rng, fmt)
        except Exception as exc:  # a fuzzer defect must not end a long campaign: say it
            data, d = flip_bits(data, rng, fmt)
            d = f"{m.__name__} failed ({type(exc).__name__}: {exc}), so {d}"
        names.append(m.__name__)
        details.append(d)
    return data, "+".join(names), "; ".join(details)


def _stack(i: int, n_mut: int, rng: np.random.Generator, campaign: bool) -> int:
    if not campaign or i < 4 * n_mut:
        return 1
    return 1 + int(rng.integers(0, 3))


class _Prepared:
    """A reader's seeds, their decoded sizes, and the sandbox warmed on them."""

    def __init__(self, reader: Reader, sandbox: Sandbox, work: Path) -> None:
        self.reader = reader
        self.work = work
        self.seeds: list[tuple[Path, list[int]]] = []
        self.failures: list[tuple[str, Outcome]] = []
        if reader.make is not None:
            self._make(reader.make, work)
        paths = reader.seeds(work)
        if reader.fmt == "db3":
            paths = self._db3(sandbox, work)
        # every new worker reads the seeds once with each keyword set (untraced: torch's
        # import took a minute under tracemalloc) before its first measured call, so
        # that imports and numba's kernel loading are not counted as a mutant's time or
        # allocation; the first time with a long limit (a kernel whose cache is stale
        # compiles: 10 s and more)
        for kwargs in reader.kwargs if paths else ():
            first = (reader.target, (str(paths[0]),), kwargs)
            sandbox.run(lf.untraced, first, timeout=300.0)
        sandbox.warm(
            [
                (lf.untraced, (reader.target, (str(p),), kwargs), {})
                for p in paths
                for kwargs in reader.kwargs
            ]
        )
        for p in paths:
            decoded = []  # the bytes returned for the seed, per keyword set
            for k, kwargs in enumerate(reader.kwargs):
                out = sandbox.run(reader.target, (str(p),), kwargs, timeout=60.0)
                if out.kind != "ok" and k == 0:
                    self.failures.append((str(p), out))
                    break
                decoded.append(out.result_bytes if out.kind == "ok" else decoded[0])
            else:
                self.seeds.append((p, decoded))

    def _make(self, make: Callable[[str], Any], work: Path) -> None:
        """Run ``make(work)`` in a fresh interpreter: a training run or a Dask cluster
        (whose nanny processes a daemonic sandbox worker may not start) kept out of the
        fuzzing process."""
        code = f"import sys; from {make.__module__} import {make.__name__} as f; f(sys.argv[1])"
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        }
        t0 = time.perf_counter()
        try:
            done = subprocess.run(
                [sys.executable, "-c", code, str(work)],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
            )
        except subprocess.TimeoutExpired:
            out = Outcome("hang", "timeout", "no end within 600 s", time.perf_counter() - t0, 0.0)
            self.failures.append((f"{make.__name__}({work})", out))
            return
        if done.returncode:
            tail = (done.stderr.strip().splitlines() or [""])[-1]
            out = Outcome(
                "crash", f"exit {done.returncode}", tail[:300], time.perf_counter() - t0, 0.0
            )
            self.failures.append((f"{make.__name__}({work})", out))

    def _db3(self, sandbox: Sandbox, work: Path) -> list[Path]:
        from robopercept.imaging import read_image

        root = DATA / "rgbd/tum_pair_slambook2"
        if not (root / "1.png").is_file():
            return []
        color = np.ascontiguousarray(read_image(root / "1.png", mode="rgb")[200:248, 280:344])
        depth = np.ascontiguousarray(read_image(root / "1_depth.png")[200:248, 280:344])
        path = work / "tum_crop.db3"
        out = sandbox.run(write_db3, (str(path), color, depth), timeout=60.0)
        return [path] if out.kind == "ok" and path.is_file() else []


def _folder_mutant(
    prep: _Prepared, path: Path, rng: np.random.Generator, i: int, campaign: bool
) -> tuple[Path, str, str]:
    """A copy of the seed folder ``path`` with one member (of ``reader.members``, in
    turn) mutated by the mutations of its format, or removed: ``(folder, mutation,
    detail)``."""
    reader = prep.reader
    mutant = prep.work / "mutants" / f"{path.name}_{i}"
    shutil.rmtree(mutant, ignore_errors=True)
    shutil.copytree(path, mutant, copy_function=shutil.copyfile)
    members = sorted(
        p.relative_to(mutant).as_posix()
        for p in mutant.rglob("*")
        if p.is_file() and lf.matches(p.relative_to(mutant).as_posix(), reader.members)
    )
    if not members:
        return mutant, "none", "no member to mutate"
    member = members[i % len(members)]
    fmt = _fmt_of(Path(member), reader)
    muts = _mutations_for(fmt, reader)
    choice = (i // len(members)) % (len(muts) + 1)
    file = mutant / member
    if choice == len(muts):
        file.unlink()
        return mutant, f"{member}:removed", "file removed"
    data, names, detail = _mutate(
        file.read_bytes(), rng, muts, choice, fmt, _stack(i, len(muts), rng, campaign)
    )
    file.write_bytes(data)
    return mutant, f"{member}:{names}", detail


def _one(prep: _Prepared, sandbox: Sandbox, i: int, seed: int, campaign: bool) -> Mutant:
    """Make mutant ``i``, run it, restore whatever was patched."""
    reader = prep.reader
    rng = np.random.default_rng([seed, zlib.crc32(reader.name.encode()), i])
    n_mut = 12 if reader.fmt in ("bag", "tum", "folder") else len(reader.mutations)
    path, decoded_per_kwargs = prep.seeds[(i + i // n_mut) % len(prep.seeds)]
    kwargs = reader.kwargs[i % len(reader.kwargs)]
    decoded = decoded_per_kwargs[i % len(reader.kwargs)]
    target_dir = prep.work / "mutants"
    target_dir.mkdir(exist_ok=True)
    if reader.fmt == "bag":
        work_copy = prep.work / ("bag_copy" + path.suffix)
        if not work_copy.exists():
            shutil.copyfile(path, work_copy)
        original = path.read_bytes()
        patches, cut, mutation, detail = bag_edit(original, rng)
        size = cut if cut is not None else len(original)
        json_size = 0
        with patched(work_copy, original, patches, cut):
            out, bound, unconfirmed = _run_judged(
                prep, sandbox, str(work_copy), kwargs, size, decoded, json_size
            )
    elif reader.fmt == "tum":
        mutant = target_dir / f"tum_{i}"
        shutil.rmtree(mutant, ignore_errors=True)
        shutil.copytree(path, mutant)
        members = sorted(p.relative_to(mutant) for p in mutant.rglob("*") if p.is_file())
        member = members[i % len(members)]
        fmt = _fmt_of(member, reader)
        muts = _mutations_for(fmt, reader)
        choice = (i // len(members)) % (len(muts) + 2)
        file = mutant / member
        if choice == len(muts):
            file.unlink()
            mutation, detail = f"{member.name}:removed", "file removed"
        elif choice == len(muts) + 1 and member.suffix == ".txt":
            text = file.read_bytes()
            names = re.findall(rb"(?:rgb|depth)/[^\s]+", text)
            long = b"rgb/" + b"x" * 300 + b".png" if rng.random() < 0.5 else b"rgb/a\x00b.png"
            if names:
                text = text.replace(names[int(rng.integers(len(names)))], long, 1)
            file.write_bytes(text)
            mutation, detail = f"{member.name}:bad_name", f"a listed name -> {long[:24]!r}..."
        else:
            data, names, detail = _mutate(
                file.read_bytes(), rng, muts, choice, fmt, _stack(i, len(muts), rng, campaign)
            )
            file.write_bytes(data)
            mutation = f"{member.name}:{names}"
        size = _tree_size(mutant)
        json_size = _tree_size(mutant, ".json")
        out, bound, unconfirmed = _run_judged(
            prep, sandbox, str(mutant), kwargs, size, decoded, json_size
        )
        shutil.rmtree(mutant, ignore_errors=True)
    elif reader.fmt == "folder":
        mutant, mutation, detail = _folder_mutant(prep, path, rng, i, campaign)
        size = _tree_size(mutant)
        json_size = _tree_size(mutant, ".json")
        out, bound, unconfirmed = _run_judged(
            prep, sandbox, str(mutant), kwargs, size, decoded, json_size
        )
        shutil.rmtree(mutant, ignore_errors=True)
    else:
        fmt = _fmt_of(path, reader)
        muts = _mutations_for(fmt, reader)
        data, mutation, detail = _mutate(
            path.read_bytes(), rng, muts, i, fmt, _stack(i, len(muts), rng, campaign)
        )
        folder = path.parent if reader.beside else target_dir
        mutant = folder / f"fuzz_m{i % 4}{path.suffix}"
        mutant.write_bytes(data)
        size = len(data)
        json_size = size if fmt == "json" else 0
        out, bound, unconfirmed = _run_judged(
            prep, sandbox, str(mutant), kwargs, size, decoded, json_size
        )
        if reader.beside:
            mutant.unlink(missing_ok=True)
    if kwargs:
        detail += f"; {kwargs}"
    return Mutant(reader.name, path.name, i, mutation, detail, out, bound, unconfirmed)


def _run_judged(
    prep: _Prepared,
    sandbox: Sandbox,
    arg: str,
    kwargs: dict,
    size: int,
    decoded: int,
    json_size: int,
) -> tuple[Outcome, float, str]:
    """Run the reader on ``arg`` and :func:`judge` it; an over-bound peak is run again
    in a fresh worker and kept only if it comes back (see the module docstring).

    Returns
    -------
    Outcome
        The judged outcome (the rerun's when the first peak did not come back).
    float
        The bound, MiB.
    str
        The first attempt's message when it did not come back, else empty.
    """
    reader = prep.reader
    first = sandbox.run(reader.target, (arg,), kwargs, timeout=reader.timeout)
    out, bound = judge(first, size, decoded, reader.floor, json_size)
    if out.kind != "memory" or first.kind == "memory":  # MemoryError: refused, not traced
        return out, bound, ""
    sandbox.restart()
    again = sandbox.run(reader.target, (arg,), kwargs, timeout=reader.timeout)
    rerun, _ = judge(again, size, decoded, reader.floor, json_size)
    if rerun.kind == "memory":
        return out, bound, ""
    return rerun, bound, f"{out.message} (rerun in a fresh worker: {again.peak_mb:.1f} MiB)"


def fuzz_reader(
    reader: Reader,
    sandbox: Sandbox,
    *,
    n: int | None = None,
    seed: int = 0,
    budget_s: float | None = None,
    workdir: str | Path | None = None,
    campaign: bool = False,
    at_least: int = 0,
) -> ReaderRun:
    """Run mutants ``0 .. n-1`` of ``reader`` (or as many as ``budget_s`` allows).

    Parameters
    ----------
    reader : Reader
    sandbox : Sandbox
    n : int, optional
        Number of mutants (unbounded when None: then ``budget_s`` must be given).
    seed : int
        The campaign seed; with the reader's name and the mutant's index it fixes
        every choice.
    budget_s : float, optional
        Stop starting mutants after this many seconds.
    workdir : path, optional
        Where seeds and mutants are written (a temporary folder when None).
    campaign : bool
        Stack 2-3 mutations on some inputs past the first ``4 M`` (long runs).
    at_least : int
        Run this many mutants even when ``budget_s`` is spent (by a slow preparation:
        a training run, a cluster), so that every reader of a campaign is tried.

    Returns
    -------
    ReaderRun
        Every mutant with its outcome, the seeds the reader refused (a finding too),
        and the :class:`~tests.fuzz.report.Tally` (group ``"readers"``).
    """
    if n is None and budget_s is None:
        raise ValueError("give n or budget_s")
    run = ReaderRun(reader.name)
    tally = Tally(f"read {reader.name}", "readers")
    with contextlib.ExitStack() as stack:
        if workdir is None:
            work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="fuzz-")))
        else:
            work = Path(workdir) / reader.name
            work.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        prep = _Prepared(reader, sandbox, work)
        run.seed_failures = prep.failures
        for name, out in prep.failures:
            tally.add(out, "seed", name)
        i = 0
        try:
            while prep.seeds and (n is None or i < n):
                spent = budget_s is not None and time.perf_counter() - t0 > budget_s
                if spent and i >= at_least:
                    break
                m = _one(prep, sandbox, i, seed, campaign)
                run.mutants.append(m)
                tally.add(m.outcome, m.mutation, f"{m.seed} #{m.index}: {m.detail}")
                if m.unconfirmed:
                    tally.add_unconfirmed(
                        m.mutation, f"{m.seed} #{m.index}: {m.detail}", m.unconfirmed
                    )
                i += 1
        finally:
            sandbox.warm([])
    run.tally = tally
    return run


#: mutants every reader gets in a campaign, even past its share of the budget
CAMPAIGN_AT_LEAST = 8


def run_readers_campaign(
    budget_s: float, seed: int, sandbox: Sandbox, readers: Sequence[Reader] = READERS
) -> list[Tally]:
    """The readers' part of ``python -m tests.fuzz``: each reader gets an equal share of
    ``budget_s`` (what a reader without data leaves goes to the next ones), and at least
    :data:`CAMPAIGN_AT_LEAST` mutants whatever its seeds took to prepare (a short budget
    then runs over: every reader is tried).

    Parameters
    ----------
    budget_s : float
        Seconds for all readers together (seed preparation included).
    seed : int
        Campaign seed (see :func:`fuzz_reader`).
    sandbox : Sandbox
        Where every call runs.
    readers : sequence of Reader

    Returns
    -------
    list of Tally
        One per reader, group ``"readers"``; an over-bound allocation is counted in
        ``memory``.
    """
    tallies = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz-readers-") as work:
        for k, reader in enumerate(readers):
            left = budget_s - (time.perf_counter() - t0)
            share = max(left / (len(readers) - k), 0.0)
            run = fuzz_reader(
                reader,
                sandbox,
                seed=seed,
                budget_s=share,
                workdir=work,
                campaign=True,
                at_least=CAMPAIGN_AT_LEAST,
            )
            shutil.rmtree(Path(work) / reader.name, ignore_errors=True)
            if run.tally is not None and (run.tally.inputs or run.seed_failures):
                tallies.append(run.tally)
    return tallies


def describe(mutants: Sequence[Mutant]) -> str:
    """One line per mutant: reader, seed, index, mutation, detail, outcome."""
    return "\n".join(
        f"{m.reader} {m.seed} #{m.index} {m.mutation} [{m.detail}] -> {m.outcome.kind} "
        f"{m.outcome.error}: {m.outcome.message[:160]} ({m.outcome.where})"
        for m in mutants
    )
