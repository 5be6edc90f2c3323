"""Point-cloud files: PLY (through ``plyfile``) and PCD (a careful reader and writer here).

PCD (PCL's format, v0.7): a text header (``FIELDS``, ``SIZE``, ``TYPE``, ``COUNT``,
``WIDTH``, ``HEIGHT``, ``POINTS``, ``DATA``) and the data as ``ascii`` rows, ``binary``
records (one packed record per point), or ``binary_compressed``: two uint32 sizes and an
LZF stream that expands to the fields one after another (all x, then all y, ...).
Colours are PCL's packed ``rgb``/``rgba`` (``0x00RRGGBB`` in a float or uint32).

Per-point labels (:attr:`PointCloud.labels`: segment, cluster or class ids) are the
``label`` field: in PCD an unsigned 32-bit ``label`` after the colour, as PCL's
``PointXYZRGBL`` / ``PointXYZL`` store it (so ``pcl::io::loadPCDFile`` fills
``label``); in PLY a signed 32-bit ``property int label`` of the vertex element (Open3D's
tensor ``read_point_cloud``, plyfile and CloudCompare read it as a per-point scalar; -1
for noise, as Open3D's DBSCAN labels, fits). Both readers read ``label`` of any integer
type, or of a float type holding whole numbers.

Every size a header claims is checked against the bytes actually in the file before
anything is allocated, so a corrupt or hostile header (say ``POINTS 1000000000000``) is
refused with :class:`FileFormatError` instead of exhausting memory.
"""

from __future__ import annotations

import io as _io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from robopercept._checks import check_bool, check_extension, check_file
from robopercept.errors import FileFormatError, InputError
from robopercept.pointcloud.cloud import PointCloud, check_cloud

__all__ = [
    "PcdData",
    "check_cloud_path",
    "ply_element_counts",
    "read_pcd",
    "read_point_cloud",
    "write_point_cloud",
]

_MAX_HEADER = 1 << 16
_PCD_TYPES = {
    ("F", 4): "f4",
    ("F", 8): "f8",
    ("U", 1): "u1",
    ("U", 2): "u2",
    ("U", 4): "u4",
    ("U", 8): "u8",
    ("I", 1): "i1",
    ("I", 2): "i2",
    ("I", 4): "i4",
    ("I", 8): "i8",
}
_LZF_MAX_RATIO = 100  # an LZF stream cannot expand more than ~88x (264 bytes per 3)


def _fail(path: Path, what: str) -> FileFormatError:
    return FileFormatError(f"{path}: {what}")


# --------------------------------------------------------------------------- LZF
@njit(cache=True, nogil=True)
def _lzf_decompress(src, dst):  # pragma: no cover - compiled
    """Expand the LZF stream ``src`` into ``dst``; returns bytes written, -1 if corrupt.

    Each control byte ``c`` is a literal run (``c < 32``: copy the next ``c + 1`` bytes) or
    a back reference (length ``c >> 5`` plus 2, extended by one byte when 7; offset from
    the low 5 bits and the next byte, plus 1) into the output written so far.
    """
    ip = 0
    op = 0
    n_in = src.shape[0]
    n_out = dst.shape[0]
    while ip < n_in:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:
            run = ctrl + 1
            if ip + run > n_in or op + run > n_out:
                return -1
            for k in range(run):
                dst[op + k] = src[ip + k]
            ip += run
            op += run
        else:
            length = ctrl >> 5
            ref = op - ((ctrl & 0x1F) << 8) - 1
            if length == 7:
                if ip >= n_in:
                    return -1
                length += np.int64(src[ip])
                ip += 1
            if ip >= n_in:
                return -1
            ref -= np.int64(src[ip])
            ip += 1
            length += 2
            if ref < 0 or op + length > n_out:
                return -1
            for k in range(length):  # byte by byte: the reference may overlap the output
                dst[op + k] = dst[ref + k]
            op += length
    return op


# --------------------------------------------------------------------------- PCD
@dataclass(frozen=True)
class PcdData:
    """Everything a PCD file holds.

    Attributes
    ----------
    fields : dict of str -> ndarray
        One array per field, ``(N,)`` or ``(N, count)``, in the file's dtype.
    width, height : int
        ``height > 1`` for organized clouds (``N = width * height``, row-major).
    viewpoint : (7,) float ndarray
        ``tx ty tz qw qx qy qz`` of the acquisition viewpoint.
    data : str
        ``'ascii'``, ``'binary'`` or ``'binary_compressed'``.
    """

    fields: dict[str, np.ndarray]
    width: int
    height: int
    viewpoint: np.ndarray
    data: str


def _read_header(raw: bytes, path: Path) -> tuple[dict[str, list[str]], int]:
    """Header entries and the offset of the data section."""
    header: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0 or end > _MAX_HEADER:
            raise _fail(path, "no DATA line within the first 64 KiB: not a PCD file?")
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        header[key.upper()] = vals
        if key.upper() == "DATA":
            return header, pos


def _int_entry(header: dict[str, list[str]], key: str, path: Path, default: int | None = None):
    vals = header.get(key)
    if not vals:
        if default is not None:
            return default
        raise _fail(path, f"header has no {key} line")
    try:
        v = int(vals[0])
    except ValueError:
        raise _fail(path, f"{key} must be an integer; got {vals[0]!r}") from None
    if v < 0:
        raise _fail(path, f"{key} must be >= 0; got {v}")
    return v


def read_pcd(path: str | os.PathLike[str]) -> PcdData:
    """Read every field of a PCD file (ascii, binary or binary_compressed).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    PcdData

    Raises
    ------
    FileFormatError
        Missing, truncated or corrupt file, or a header that does not match the data.
    """
    p = check_file(path, "a PCD file")
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot read ({exc.strerror or exc})") from exc
    header, offset = _read_header(raw, p)
    names = header.get("FIELDS") or header.get("COLUMNS")
    if not names:
        raise _fail(p, "header has no FIELDS line")
    n_fields = len(names)
    sizes = header.get("SIZE", ["4"] * n_fields)
    types = header.get("TYPE", ["F"] * n_fields)
    counts = header.get("COUNT", ["1"] * n_fields)
    if not len(sizes) == len(types) == len(counts) == n_fields:
        raise _fail(
            p,
            f"FIELDS ({n_fields}), SIZE ({len(sizes)}), TYPE ({len(types)}) and COUNT "
            f"({len(counts)}) must have one entry per field",
        )
    formats = []
    record = 0
    for name, size, typ, count in zip(names, sizes, types, counts, strict=True):
        try:
            code = _PCD_TYPES[(typ.upper(), int(size))]
        except (KeyError, ValueError):
            raise _fail(p, f"field {name!r} has unsupported TYPE {typ} SIZE {size}") from None
        try:
            cnt = int(count)
        except ValueError:
            raise _fail(p, f"field {name!r} has COUNT {count!r}; expected an integer") from None
        if cnt < 1:
            raise _fail(p, f"field {name!r} has COUNT {cnt}; expected >= 1")
        # issue 25: a record is bounded by the file (and numpy's C-int shapes) before
        # np.dtype sees it; COUNT 2**31 used to escape as a ValueError
        record += cnt * int(size)
        if record > len(raw) or cnt >= 2**31:
            raise _fail(
                p,
                f"field {name!r} has COUNT {cnt}: {record} bytes per point, more than the "
                f"whole file ({len(raw)} bytes): corrupt header",
            )
        formats.append((name, "<" + code, (cnt,)) if cnt > 1 else (name, "<" + code))
    # unique names: PCL pads with "_" fields; numpy needs distinct names
    seen: dict[str, int] = {}
    uniq = []
    for f in formats:
        k = seen.get(f[0], 0)
        seen[f[0]] = k + 1
        uniq.append((f[0] if k == 0 else f"{f[0]}_{k}", *f[1:]))
    dtype = np.dtype(uniq)
    width = _int_entry(header, "WIDTH", p)
    height = _int_entry(header, "HEIGHT", p, 1)
    n = _int_entry(header, "POINTS", p, width * height)
    if n != width * height:
        raise _fail(p, f"POINTS ({n}) must equal WIDTH x HEIGHT ({width} x {height})")
    vp = np.array([0, 0, 0, 1, 0, 0, 0], dtype=np.float64)
    if "VIEWPOINT" in header:
        try:
            vp = np.array([float(v) for v in header["VIEWPOINT"]], dtype=np.float64)
        except ValueError:
            vp = np.empty(0)
        if vp.shape != (7,) or not np.isfinite(vp).all():
            raise _fail(
                p, f"VIEWPOINT must be 7 finite numbers; got {' '.join(header['VIEWPOINT'])!r}"
            )
    kind = (header["DATA"] or ["?"])[0].lower()
    body = memoryview(raw)[offset:]
    if kind == "ascii":
        arr = _read_ascii(bytes(body), dtype, n, p)
    elif kind == "binary":
        need = n * dtype.itemsize
        if len(body) < need:
            raise _fail(
                p,
                f"truncated: {n} points of {dtype.itemsize} bytes need {need} bytes of "
                f"data, the file has {len(body)}",
            )
        arr = np.frombuffer(body, dtype=dtype, count=n)
    elif kind == "binary_compressed":
        arr = _read_compressed(body, dtype, n, p)
    else:
        raise _fail(p, f"DATA must be ascii, binary or binary_compressed; got {kind!r}")
    fields = {name: np.array(arr[name]) for name in dtype.names}  # type: ignore[union-attr]
    return PcdData(fields, width, height, vp, kind)


def _read_ascii(body: bytes, dtype: np.dtype, n: int, path: Path) -> np.ndarray:
    cols = sum(int(np.prod(dtype[i].shape or (1,))) for i in range(len(dtype)))
    if n * 2 * cols > len(body) + 1:  # every value needs a digit and a separator
        raise _fail(
            path, f"header claims {n} points; {len(body)} bytes of ascii data cannot hold them"
        )
    if n == 0:
        return np.zeros(0, dtype=dtype)
    try:
        table = np.loadtxt(_io.BytesIO(body), dtype=np.float64, ndmin=2, max_rows=n)
    except ValueError as exc:
        raise _fail(path, f"corrupt ascii data: {exc}") from None
    if table.shape != (n, cols):
        raise _fail(
            path,
            f"ascii data has {table.shape[0]} rows of {table.shape[1]} values; "
            f"the header says {n} rows of {cols}",
        )
    # float fields keep the decimal text's float64 value (as Open3D and PCL's strtod do)
    wide = np.dtype(
        [
            (name, "<f8" if dtype[name].base.kind == "f" else dtype[name].base, dtype[name].shape)
            for name in dtype.names  # type: ignore[union-attr]
        ]
    )
    out = np.zeros(n, dtype=wide)
    c = 0
    for name in dtype.names:  # type: ignore[union-attr]
        width = int(np.prod(out[name].shape[1:] or (1,)))
        block = table[:, c : c + width]
        out[name] = block if width > 1 else block[:, 0]
        c += width
    return out


def _read_compressed(body: memoryview, dtype: np.dtype, n: int, path: Path) -> np.ndarray:
    if len(body) < 8:
        raise _fail(path, "truncated: binary_compressed data has no size header")
    comp, uncomp = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
    need = n * dtype.itemsize
    if uncomp != need:
        raise _fail(
            path,
            f"compressed block expands to {uncomp} bytes, the header's {n} points need {need}",
        )
    if comp > len(body) - 8:
        raise _fail(path, f"truncated: compressed block of {comp} bytes, {len(body) - 8} present")
    if need > _LZF_MAX_RATIO * comp + 1024:
        raise _fail(path, f"{comp} compressed bytes cannot expand to {need}: corrupt header")
    out = np.empty(need, dtype=np.uint8)
    if need:
        src = np.frombuffer(body[8 : 8 + comp], dtype=np.uint8)
        if _lzf_decompress(src, out) != need:
            raise _fail(path, "corrupt LZF stream in binary_compressed data")
    # the expanded bytes hold each field for all points, one field after another
    arr = np.empty(n, dtype=dtype)
    pos = 0
    for name in dtype.names:  # type: ignore[union-attr]
        sub = dtype.fields[name][0]  # type: ignore[index]
        nbytes = n * sub.itemsize
        arr[name] = np.frombuffer(out[pos : pos + nbytes].tobytes(), dtype=sub.base).reshape(
            (n, *sub.shape)
        )
        pos += nbytes
    return arr


def _unpack_rgb(values: np.ndarray) -> np.ndarray:
    """PCL packed colour (float or uint32 holding 0x(AA)RRGGBB) -> (N, 3) float in [0, 1]."""
    v = np.ascontiguousarray(values).view(np.uint32).reshape(-1)
    rgb = np.stack([(v >> 16) & 255, (v >> 8) & 255, v & 255], axis=1)
    return rgb.astype(np.float64) / 255.0


def _file_labels(values: np.ndarray, path: Path) -> np.ndarray:
    """A file's ``label`` column as int64; whole numbers only."""
    v = np.asarray(values)
    if v.dtype.kind in "iu":
        return v.astype(np.int64)
    if v.dtype.kind == "f":
        ok = np.isfinite(v) & (v == np.round(v)) & (np.abs(v) <= 2**53)
        if ok.all():
            return v.astype(np.int64)
        raise _fail(path, f"field 'label' holds {float(v[~ok][0])!r}; labels are whole numbers")
    raise _fail(path, f"field 'label' has type {v.dtype}; labels are integers")


def _cloud_from_pcd(pcd: PcdData, path: Path) -> PointCloud:
    f = pcd.fields
    if not {"x", "y", "z"} <= f.keys():
        raise _fail(path, f"no x, y, z fields (fields: {', '.join(f)})")
    for key in ("x", "y", "z", "normal_x", "normal_y", "normal_z", "label"):
        if key in f and f[key].ndim != 1:
            raise _fail(path, f"field {key!r} has COUNT {f[key].shape[1]}; it must be 1")
    pts = np.column_stack([f["x"], f["y"], f["z"]]).astype(np.float64)
    colors = None
    for key in ("rgb", "rgba"):
        if key in f and f[key].ndim == 1 and f[key].dtype.itemsize == 4:
            colors = _unpack_rgb(f[key])
            break
    normals = None
    if {"normal_x", "normal_y", "normal_z"} <= f.keys():
        normals = np.column_stack([f["normal_x"], f["normal_y"], f["normal_z"]]).astype(np.float64)
    shape = (pcd.height, pcd.width) if pcd.height > 1 else None
    labels = _file_labels(f["label"], path) if "label" in f else None
    return PointCloud(pts, colors, normals, shape, labels)


# --------------------------------------------------------------------------- PLY
_PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2}
_PLY_SIZES.update({"int16": 2, "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4})
_PLY_SIZES.update({"float": 4, "float32": 4, "double": 8, "float64": 8})


def ply_element_counts(raw_head: bytes, size: int, path: Path) -> dict[str, int]:
    """The element counts of a PLY header (``{"vertex": 8, "face": 12}``), after checking
    that a file of ``size`` bytes can hold them (each element's rows at their smallest:
    2 bytes per ascii property, the type's size per binary one), so a hostile header is
    refused before plyfile allocates anything.

    Parameters
    ----------
    raw_head : bytes
        The first bytes of the file (the header, at most 64 KiB).
    size : int
        The file's size in bytes.
    path : Path
        Named in the error.

    Returns
    -------
    dict of str to int

    Raises
    ------
    FileFormatError
        No ``ply`` magic or ``end_header``, a bad or negative element count, or counts
        the file cannot hold.

    Examples
    --------
    >>> head = b"ply\\nformat ascii 1.0\\nelement vertex 2\\nproperty float x\\nend_header\\n"
    >>> ply_element_counts(head, 60, Path("a.ply"))
    {'vertex': 2}
    """
    text = raw_head.decode("ascii", errors="replace")
    end = text.find("end_header")
    if not text.startswith("ply") or end < 0:
        raise _fail(path, "not a PLY file (no 'ply' magic or no end_header in 64 KiB)")
    lines = text[:end].splitlines()
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format ") and ln.split()[1:]), "")
    counts: dict[str, int] = {}
    min_bytes = 0
    count = row = 0
    for ln in [*lines, "element end 0"]:
        parts = ln.split()
        if not parts:
            continue
        if parts[0] == "element":
            min_bytes += count * max(row, 1)
            try:
                count = int(parts[2])
            except (IndexError, ValueError):
                raise _fail(path, f"bad element line {ln!r}") from None
            if count < 0:
                raise _fail(path, f"negative element count in {ln!r}")
            counts[parts[1]] = count
            row = 0
        elif parts[0] == "property":
            if fmt == "ascii":
                row += 2  # a digit and a separator at least
            elif parts[1:2] == ["list"] and len(parts) > 2:
                row += _PLY_SIZES.get(parts[2], 1)
            elif len(parts) > 1:
                row += _PLY_SIZES.get(parts[1], 1)
    counts.pop("end", None)
    if min_bytes > size:
        raise _fail(
            path, f"header claims elements needing at least {min_bytes} bytes; the file has {size}"
        )
    return counts


def _ply_colors(c: np.ndarray, path: Path) -> np.ndarray:
    """``(N, 3)`` PLY colour columns as RGB in [0, 1]: integer properties (uchar, as
    every writer stores them) are 0..255 and divided by 255; float ones in [0, 1] are
    kept, and float ones in [0, 255] are divided by 255 as Open3D does with any type."""
    if c.size == 0:
        return c.astype(np.float64)
    lo, hi = float(c.min()), float(c.max())
    if c.dtype.kind in "iu" or (c.dtype.kind == "f" and hi > 1.0):
        if 0.0 <= lo and hi <= 255.0:
            return c.astype(np.float64) / 255.0
    elif 0.0 <= lo and hi <= 1.0:
        return c.astype(np.float64)
    raise _fail(
        path,
        f"colour values run from {lo:g} to {hi:g}; PLY colours must be 0..255 "
        "(or floats in [0, 1])",
    )


def _read_ply(path: Path) -> PointCloud:
    try:
        from plyfile import PlyData
    except ImportError as exc:  # pragma: no cover - plyfile is a core dependency
        raise ImportError("reading PLY needs plyfile: pip install plyfile") from exc
    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            ply_element_counts(fh.read(_MAX_HEADER), size, path)
        ply = PlyData.read(str(path))
    except FileFormatError:
        raise
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except Exception as exc:  # plyfile raises several parse errors
        raise _fail(path, f"corrupt PLY ({type(exc).__name__}: {exc})") from None
    if "vertex" not in ply:
        raise _fail(path, "no 'vertex' element")
    v = ply["vertex"].data
    names = v.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise _fail(path, f"vertex element has no x, y, z (properties: {', '.join(names)})")
    # issue 25: a list property (dtype object) used to escape np.column_stack as ValueError
    used = {"x", "y", "z", "red", "green", "blue", "r", "g", "b", "nx", "ny", "nz", "label"}
    lists = [k for k in names if k in used and v.dtype[k].kind not in "biuf"]
    if lists:
        raise _fail(
            path,
            f"vertex propert{'ies' if len(lists) > 1 else 'y'} {', '.join(lists)} "
            "declared as a list; x, y, z (and colours, normals) must be scalar properties",
        )
    pts = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    colors = None
    for r, g, b in (("red", "green", "blue"), ("r", "g", "b")):
        if {r, g, b} <= set(names):
            colors = _ply_colors(np.column_stack([v[r], v[g], v[b]]), path)
            break
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = np.column_stack([v["nx"], v["ny"], v["nz"]]).astype(np.float64)
    labels = _file_labels(v["label"], path) if "label" in names else None
    return PointCloud(pts, colors, normals, labels=labels)


def _records(
    cloud: PointCloud, normal_names: tuple[str, ...], color_cols: list, label_type: str
) -> np.ndarray:
    """float32 x, y, z (and normals under ``normal_names``) plus empty colour columns,
    then the labels as ``label`` of ``label_type``."""
    cols = [(k, "<f4") for k in ("x", "y", "z")]
    if cloud.normals is not None:
        cols += [(k, "<f4") for k in normal_names]
    if cloud.colors is not None:
        cols += color_cols
    if cloud.labels is not None:
        info = np.iinfo(label_type)
        lab = cloud.labels
        if lab.size and (lab.min() < info.min or lab.max() > info.max):
            bad = int(lab.min() if lab.min() < info.min else lab.max())
            fix = (
                "PCL's label is unsigned: shift noise (-1) to 0 with labels + 1, or write .ply"
                if info.min == 0
                else "renumber the labels (np.unique(labels, return_inverse=True)[1])"
            )
            raise InputError(
                f"labels must fit the file's label field ({np.dtype(label_type).name}, "
                f"{info.min}..{info.max}); got {bad}: {fix}"
            )
        cols.append(("label", label_type))
    rec = np.empty(len(cloud), dtype=cols)
    if cloud.labels is not None:
        rec["label"] = cloud.labels
    for i, k in enumerate("xyz"):
        rec[k] = cloud.points[:, i]
    if cloud.normals is not None:
        for i, k in enumerate(normal_names):
            rec[k] = cloud.normals[:, i]
    return rec


def _colors8(cloud: PointCloud) -> np.ndarray:
    """(N, 3) uint32 8-bit colours ``rint(255 c)`` of the cloud's [0, 1] colours (the
    inverse of the readers' ``v / 255``: uint8 colours given to :class:`PointCloud`
    come back exactly)."""
    return np.clip(np.rint(cloud.colors * 255.0), 0, 255).astype(np.uint32)  # type: ignore[operator]


def _write_ply(path: Path, cloud: PointCloud, binary: bool) -> None:
    from plyfile import PlyData, PlyElement

    rgb = ("red", "green", "blue")
    rec = _records(cloud, ("nx", "ny", "nz"), [(k, "u1") for k in rgb], "<i4")
    if cloud.colors is not None:
        c8 = _colors8(cloud)
        for i, k in enumerate(rgb):
            rec[k] = c8[:, i]
    PlyData([PlyElement.describe(rec, "vertex")], text=not binary).write(str(path))


def _write_pcd(path: Path, cloud: PointCloud, binary: bool) -> None:
    normal_names = ("normal_x", "normal_y", "normal_z")
    rec = _records(cloud, normal_names, [("rgb", "<u4")], "<u4")
    names = list(rec.dtype.names)  # type: ignore[arg-type]
    if cloud.colors is not None:
        c8 = _colors8(cloud)
        rec["rgb"] = (c8[:, 0] << 16) | (c8[:, 1] << 8) | c8[:, 2]
    h, w = cloud.shape if cloud.shape is not None else (1, len(cloud))
    types = ["U" if k in ("rgb", "label") else "F" for k in names]
    head = (
        "# .PCD v0.7 - Point Cloud Data file format (robopercept)\nVERSION 0.7\n"
        f"FIELDS {' '.join(names)}\nSIZE {' '.join('4' for _ in names)}\n"
        f"TYPE {' '.join(types)}\nCOUNT {' '.join('1' for _ in names)}\n"
        f"WIDTH {w}\nHEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(cloud)}\n"
        f"DATA {'binary' if binary else 'ascii'}\n"
    )
    with path.open("wb") as fh:
        fh.write(head.encode("ascii"))
        if binary:
            fh.write(rec.tobytes())
        else:
            fmt = ["%d" if k in ("rgb", "label") else "%.9g" for k in names]
            rows = np.column_stack([rec[k].astype(np.float64) for k in names])
            np.savetxt(fh, rows, fmt=fmt)


# --------------------------------------------------------------------------- public API
def read_point_cloud(path: str | os.PathLike[str]) -> PointCloud:
    """Read a ``.ply`` or ``.pcd`` file.

    Points are returned as stored, NaN included (Open3D's ``read_point_cloud`` default);
    an organized PCD (``HEIGHT > 1``) keeps its ``(H, W)`` shape. Use
    :meth:`PointCloud.finite` to drop the invalid points.

    Parameters
    ----------
    path : str or path-like
        A PLY (ascii, binary little or big endian) or PCD (ascii, binary,
        binary_compressed) file.

    Returns
    -------
    PointCloud
        Colours in [0, 1] when the file has them (PLY ``red green blue``: integer
        values 0..255 divided by 255, float values kept when in [0, 1] and divided by
        255 when in [0, 255] as Open3D does; PCD ``rgb``/``rgba``), normals when it has
        ``nx ny nz`` / ``normal_x ...``, labels (int64) when it has a ``label`` field.

    Raises
    ------
    FileFormatError
        Missing file or a folder, truncated or corrupt file, unknown extension.
    """
    p = check_file(path, "a point cloud file (.ply or .pcd)")
    suffix = p.suffix.lower()
    if suffix == ".pcd":
        return _cloud_from_pcd(read_pcd(p), p)
    if suffix == ".ply":
        return _read_ply(p)
    raise FileFormatError(f"{p}: unknown point-cloud extension {suffix!r}: use .ply or .pcd")


def check_cloud_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` after checking that :func:`write_point_cloud` can write there
    (extension ``.ply`` or ``.pcd``, any case), so a caller can refuse a wrong name
    before the work that makes the cloud.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Another extension, naming the two allowed.

    Examples
    --------
    >>> check_cloud_path("scan.PLY").name
    'scan.PLY'
    """
    return check_extension(path, (".ply", ".pcd"), "a point cloud")


def write_point_cloud(path: str | os.PathLike[str], cloud: PointCloud, binary: bool = True) -> Path:
    """Write ``cloud`` as ``.ply`` or ``.pcd`` (float32 coordinates, 8-bit colours,
    labels as a ``label`` field).

    Fields in order: ``x y z``, the normals (PLY ``nx ny nz``, PCD ``normal_x normal_y
    normal_z``), the colours (PLY ``red green blue`` uchar, PCD packed ``rgb`` uint32),
    and :attr:`PointCloud.labels` as ``label`` (PLY ``int``, PCD ``U 4``, PCL's
    ``PointXYZRGBL`` layout). The 8-bit colours are ``rint(255 c)`` of the [0, 1]
    colours, so a cloud made with uint8 colours is written with exactly those values
    (and Open3D's ``read_point_cloud`` reads them as ``v / 255``, as ours does).

    Parameters
    ----------
    path : str or path-like
        The extension picks the format.
    cloud : PointCloud
    binary : bool
        Binary (little endian) or ascii.

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    InputError
        ``cloud`` not a PointCloud, another extension, or labels outside the file's
        field: int32 for PLY, 0 .. 2^32 - 1 for PCD (PCL's unsigned label).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> cloud = PointCloud(np.eye(3), labels=[0, 2, 2])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     path = write_point_cloud(pathlib.Path(d) / "seg.pcd", cloud, binary=False)
    ...     print(path.read_text().splitlines()[2])
    ...     read_point_cloud(path).labels
    FIELDS x y z label
    array([0, 2, 2])
    """
    check_cloud(cloud)
    p = check_cloud_path(path)
    binary = check_bool(binary, "binary")
    suffix = p.suffix.lower()
    if p.parent and not p.parent.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".ply":
        _write_ply(p, cloud, binary)
    else:
        _write_pcd(p, cloud, binary)
    return p
