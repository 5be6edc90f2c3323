"""Image and video files.

Images go through imageio (Pillow for PNG/JPEG/BMP/PNM, tifffile for TIFF). Pillow has
no 16-bit colour mode (it reads a 16-bit RGB PNG or PPM as 8 bits and cannot write one),
so 16-bit colour PNGs and 16-bit PGM/PPM files go through the small codecs at the end of
this module (the PNG and netpbm specifications, zlib for the compression): every image
that PNG, TIFF or PGM/PPM can hold, gray or colour, 8 or 16 bits, reads back exactly as
written, and a 16-bit file reads as uint16, as ``cv2.imread(path, cv2.IMREAD_UNCHANGED)``
gives it (in RGB order). JPEG and BMP hold 8 bits per channel, and writing uint16 to them
is refused with the alternative. Video goes through imageio-ffmpeg, which ships its own
ffmpeg. Arrays are RGB(A) or gray as stored; nothing is rescaled.
"""

from __future__ import annotations

import os
import re
import struct
import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import check_extension, check_file, check_image, check_positive
from robopercept.errors import FileFormatError, InputError

__all__ = [
    "SnapshotVideoWriter",
    "VideoReader",
    "VideoWriter",
    "check_image_path",
    "check_video_path",
    "read_image",
    "sample_image_path",
    "write_image",
]

_IMAGE_EXTS = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".pnm"}
#: containers that take the H.264 stream :class:`VideoWriter` encodes
_VIDEO_EXTS = {".mp4", ".m4v", ".mov", ".mkv", ".avi"}


def check_image_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` after checking that :func:`write_image` can write an image there
    (its extension is one of PNG, JPEG, TIFF, BMP, PGM/PPM/PNM, any case).

    Callers that write an image after long work call it first, so a wrong name is
    refused before the work starts.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Another extension, naming the allowed ones.

    Examples
    --------
    >>> check_image_path("edges.PNG").name
    'edges.PNG'
    """
    return check_extension(path, _IMAGE_EXTS, "an image")


def check_video_path(path: str | os.PathLike[str]) -> Path:
    """Return ``path`` after checking that :class:`VideoWriter` can write a video there
    (``.mp4``, ``.m4v``, ``.mov``, ``.mkv`` or ``.avi``: containers of its H.264 stream).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Another extension (``out.png`` would get an H.264 stream under an image's name),
        naming the allowed ones.

    Examples
    --------
    >>> check_video_path("out.png")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: out.png: a video needs one of the extensions ...; got '.png'
    """
    return check_extension(path, _VIDEO_EXTS, "a video")


def read_image(path: str | os.PathLike[str], *, mode: str | None = None) -> np.ndarray:
    """Read an image file.

    Parameters
    ----------
    path : path-like
        PNG, JPEG, TIFF, BMP or PNM.
    mode : {None, 'rgb', 'gray'}
        None keeps what the file stores (gray (H, W), gray + alpha (H, W, 2), RGB
        (H, W, 3), RGBA (H, W, 4), uint8 or uint16); 'rgb' gives (H, W, 3) (gray
        replicated, alpha dropped); 'gray' gives (H, W) (BT.601 luma of colour files,
        :func:`~robopercept.imaging.rgb_to_gray`, in the file's dtype).

    Returns
    -------
    ndarray
        uint8 for 8-bit files; uint16 for 16-bit PNG, TIFF and PGM/PPM files (gray or
        colour), with the samples as stored: nothing is rescaled (a PGM with maxval 4095
        gives 0..4095).

    Raises
    ------
    FileFormatError
        Missing, empty, truncated or undecodable file, naming the file.
    """
    import imageio.v3 as iio

    from robopercept.imaging.color import rgb_to_gray

    p = Path(path)
    if mode not in (None, "rgb", "gray"):
        raise InputError(f"mode must be None, 'rgb' or 'gray'; got {mode!r}")
    check_file(p, "an image file")
    if p.stat().st_size == 0:
        raise FileFormatError(f"{p}: the file is empty")
    img = _read_16bit_special(p)
    if img is None:
        try:
            img = np.asarray(iio.imread(p))
        except Exception as exc:  # decoders raise many kinds
            raise FileFormatError(
                f"{p}: cannot decode as an image ({type(exc).__name__}: {exc})"
            ) from exc
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3) or img.size == 0:
        raise FileFormatError(f"{p}: decoded to an array of shape {img.shape}, not an image")
    if img.dtype == np.bool_:
        img = img.astype(np.uint8) * 255
    if img.dtype == np.int32 and p.suffix.lower() in (".pgm", ".pnm") and img.size:
        # Pillow decodes a 16-bit PGM (maxval <= 65535) to int32 (its mode "I"): the
        # values are 16-bit by the format, so keep the file's uint16 (depth maps)
        if 0 <= int(img.min()) and int(img.max()) <= 65535:
            img = img.astype(np.uint16)
    if mode is not None and img.ndim == 3 and img.shape[2] == 2:  # gray + alpha
        img = np.ascontiguousarray(img[..., 0])
    if mode == "rgb":
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        img = np.ascontiguousarray(img[..., :3])
    elif mode == "gray" and img.ndim == 3:
        img = rgb_to_gray(np.ascontiguousarray(img[..., :3]))
    return img


def _read_16bit_special(p: Path) -> np.ndarray | None:
    """The image of a 16-bit colour PNG or a 16-bit PGM/PPM, read without loss; None
    for every other file (which imageio reads without loss).

    Parameters
    ----------
    p : Path
        An existing, non-empty file.

    Returns
    -------
    ndarray or None
        uint16 (see :func:`_decode_png16` and :func:`_decode_netpbm16`).
    """
    with open(p, "rb") as fh:
        head = fh.read(4096)  # a PNG's IHDR; a netpbm header, comments included
    if _png16_colour_type(head) is not None:
        return _decode_png16(p.read_bytes(), p)
    header = _netpbm_header(head)
    if header is not None and header[3] > 255:
        return _decode_netpbm16(p.read_bytes(), p)
    return None


def sample_image_path() -> Path:
    """Path of the sample image shipped with the package.

    It is OpenCV's ``box.png`` (324x223, 8-bit gray; see ``robopercept/data/SOURCES.md``),
    the picture the command-line tools use when no image is given.

    Returns
    -------
    Path

    Examples
    --------
    >>> read_image(sample_image_path()).shape
    (223, 324)
    """
    from importlib import resources

    return Path(str(resources.files("robopercept") / "data" / "box.png"))


def write_image(
    path: str | os.PathLike[str], image: np.ndarray, *, png_compression: int | None = None
) -> Path:
    """Write an image; the format follows the extension.

    uint16, gray or colour, is kept exactly by PNG, TIFF and PGM/PPM (depth maps, 16-bit
    photos; PGM/PPM take gray or RGB, no alpha, and ``.pgm``/``.ppm``/``.pnm`` all get P5
    for gray and P6 for RGB, as OpenCV writes them); JPEG and BMP hold 8 bits per channel
    and refuse uint16, naming the alternative. Float images are refused rather than
    silently rescaled: convert with ``(np.clip(img, 0, 1) * 255).round().astype(np.uint8)``.

    Parameters
    ----------
    path : path-like
    image : (H, W), (H, W, 3) or (H, W, 4) ndarray, uint8 or uint16 (or bool: 0/255)
    png_compression : int, optional
        zlib level 0..9 for PNG (the writer's default when None; 1 is about 5x faster
        than the default for 20% larger files, what sequences of frames want).

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    InputError
        An unknown extension, a dtype other than uint8/uint16 (or bool), uint16 to a
        format that holds 8 bits, or RGBA to PGM/PPM; each message names the fix.
    FileFormatError
        The file cannot be written.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> photo = np.array([[[0, 257, 65535]]], dtype=np.uint16)  # one 16-bit RGB pixel
    >>> path = write_image(os.path.join(tempfile.mkdtemp(), "p.png"), photo)
    >>> read_image(path)
    array([[[    0,   257, 65535]]], dtype=uint16)
    """
    import imageio.v3 as iio

    p = Path(path)
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 4:
        check_image(arr[..., :3], "image")
    else:
        check_image(arr, "image", allow_bool=True)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8) * 255
    ext = check_image_path(p).suffix.lower()
    if arr.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"image must be uint8 or uint16 to write; got {arr.dtype}: convert with "
            "(np.clip(image, 0, 1) * 255).round().astype(np.uint8)"
        )
    if arr.dtype == np.uint16 and ext in (".jpg", ".jpeg", ".bmp"):
        fmt = "BMP" if ext == ".bmp" else "JPEG"
        raise InputError(
            f"{p}: {fmt} holds 8 bits per channel; got uint16: write .png or .tiff for "
            "uint16 data, or convert to 8 bits with (image / 257).round().astype(np.uint8)"
        )
    if ext in _PNM_EXTS and arr.ndim == 3 and arr.shape[2] == 4:
        raise InputError(
            f"{p}: PGM/PPM hold gray or RGB, not RGBA: write .png or .tiff to keep the alpha "
            "channel, or drop it with image[..., :3]"
        )
    extra = {}
    if png_compression is not None and ext == ".png":
        if not 0 <= int(png_compression) <= 9:
            raise InputError(f"png_compression must be in 0..9; got {png_compression}")
        extra["compress_level"] = int(png_compression)
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        if arr.dtype == np.uint16 and ext == ".png" and arr.ndim == 3:
            p.write_bytes(_encode_png16(arr, extra.get("compress_level", 6)))
        elif arr.dtype == np.uint16 and ext in _PNM_EXTS:
            p.write_bytes(_encode_netpbm16(arr))
        else:
            iio.imwrite(p, np.ascontiguousarray(arr), **extra)
    except Exception as exc:
        raise FileFormatError(f"{p}: cannot write ({type(exc).__name__}: {exc})") from exc
    return p


# -- 16-bit PNG and netpbm ---------------------------------------------------------------
#
# Pillow has no 16-bit colour mode: it reads a 16-bit RGB(A) PNG or PPM as 8 bits and
# cannot write one. These files go through the small codecs below (the PNG and netpbm
# specifications, zlib for the compression); everything else goes through imageio.

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type -> channels, for the 16-bit colour types that Pillow reduces to 8 bits
_PNG16_CHANNELS = {2: 3, 4: 2, 6: 4}
_PNM_EXTS = {".ppm", ".pgm", ".pnm"}


def _png16_colour_type(head: bytes) -> int | None:
    """The colour type of a 16-bit colour PNG from its first 29 bytes, else None.

    Parameters
    ----------
    head : bytes
        The start of the file: the 8-byte signature, then the IHDR chunk (length, type,
        width, height, bit depth at byte 24, colour type at byte 25).

    Returns
    -------
    int or None
        2 (RGB), 4 (gray + alpha) or 6 (RGBA) for a 16-bit file of those types; None
        for any other file (Pillow reads those without loss).
    """
    if len(head) < 29 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        return None
    if head[24] != 16 or head[25] not in _PNG16_CHANNELS:
        return None
    return int(head[25])


def _paeth(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The PNG Paeth predictor of each byte from its left ``a``, upper ``b`` and
    upper-left ``c`` neighbours (PNG specification, section 9.4).

    With :math:`p = a + b - c`, the predictor is whichever of ``a``, ``b``, ``c`` is
    nearest to :math:`p` (ties in that order): :math:`|p - a| = |b - c|`,
    :math:`|p - b| = |a - c|`, :math:`|p - c| = |a + b - 2c|`.

    Parameters
    ----------
    a, b, c : ndarray of int16
        Byte values 0..255, one shape.

    Returns
    -------
    ndarray of int16
    """
    pa = np.abs(b - c)
    pb = np.abs(a - c)
    pc = np.abs(a + b - 2 * c)
    return np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))


def _png_unfilter(filtered: np.ndarray, types: np.ndarray, bpp: int) -> np.ndarray:
    """Undo the PNG row filters (PNG specification, section 9).

    Each byte is reconstructed as :math:`R(x) = F(x) + P(a, b, c) \\bmod 256` with ``a``
    the reconstructed byte one pixel (``bpp`` bytes) to the left, ``b`` the one above and
    ``c`` the one above-left (0 outside the image), and the predictor ``P`` of the row's
    filter type: 0 none, 1 ``a``, 2 ``b``, 3 :math:`\\lfloor (a + b) / 2 \\rfloor`, 4 Paeth.
    Pixel ``(y, x)`` needs only pixels of smaller ``x + y``, so the pixels of one
    anti-diagonal ``t = x + y`` are reconstructed together, in NumPy, in ``W + H - 1``
    steps (a row-by-row loop would need one Python step per pixel for types 3 and 4).
    Files whose rows use only types 0, 1 and 2 (those this module writes, and OpenCV's)
    are reconstructed row by row instead: a running sum for 1, a sum of rows for 2.

    Parameters
    ----------
    filtered : (H, W * bpp) uint8 ndarray
        The filtered bytes of each row, without the filter-type byte.
    types : (H,) uint8 ndarray
        The filter type of each row, 0..4.
    bpp : int
        Bytes per pixel.

    Returns
    -------
    (H, W * bpp) uint8 ndarray
        The reconstructed bytes.
    """
    h, n = filtered.shape
    w = n // bpp
    if types.max(initial=0) <= 2:  # none, sub, up only: row by row, each row at once
        out = filtered.copy()
        for y in range(h):
            row = out[y].reshape(w, bpp)
            if types[y] == 1:  # a running sum of the pixels, modulo 256
                np.cumsum(row, axis=0, dtype=np.uint8, out=row)
            elif types[y] == 2 and y > 0:
                out[y] += out[y - 1]
        return out
    ys = np.arange(h)[:, None]
    diag = ys + np.arange(w)[None, :]  # (H, W): the step t = x + y of each pixel
    steps = w + h - 1
    f = np.zeros((steps, h, bpp), np.int16)
    f[diag, ys] = filtered.reshape(h, w, bpp)
    # r[t + 2, y + 1] is pixel (y, x = t - y); r[:, 0] (above the image) and every
    # entry of a pixel outside the image stay 0
    r = np.zeros((steps + 2, h + 1, bpp), np.int16)
    kind = types.astype(np.int16)[:, None]
    for t in range(steps):
        y0, y1 = max(0, t - w + 1), min(h, t + 1)
        a = r[t + 1, y0 + 1 : y1 + 1]
        b = r[t + 1, y0:y1]
        c = r[t, y0:y1]
        k = kind[y0:y1]
        pred = np.where(k == 1, a, np.where(k == 2, b, 0))
        pred = np.where(k == 3, (a + b) >> 1, pred)
        if (k == 4).any():
            pred = np.where(k == 4, _paeth(a, b, c), pred)
        r[t + 2, y0 + 1 : y1 + 1] = (f[t, y0:y1] + pred) & 255
    return r[diag + 2, ys + 1].astype(np.uint8).reshape(h, n)


def _png_filter(raw: np.ndarray, bpp: int) -> np.ndarray:
    """Filter PNG rows, each with the type that libpng's heuristic picks among its "fast
    filters" (``PNG_FAST_FILTERS``: none, sub, up; see :func:`_png_unfilter`).

    Each row keeps the filter with the smallest sum of its filtered bytes read as
    signed, :math:`\\sum_x |F(x) - 256 [F(x) > 127]|`. Average and Paeth are left out:
    they compress photos a few per cent better but decode only pixel by pixel.

    Parameters
    ----------
    raw : (H, W * bpp) uint8 ndarray
    bpp : int
        Bytes per pixel.

    Returns
    -------
    (H, 1 + W * bpp) uint8 ndarray
        Each row's filter type followed by its filtered bytes, as the IDAT stream holds
        them.
    """
    signed_abs = np.abs(np.arange(256) - 256 * (np.arange(256) > 127)).astype(np.uint8)
    sub = raw.copy()
    sub[:, bpp:] -= raw[:, :-bpp]  # uint8 arithmetic is modulo 256, as PNG's
    up = raw.copy()
    up[1:] -= raw[:-1]
    out = np.empty((raw.shape[0], raw.shape[1] + 1), np.uint8)
    out[:, 0] = np.argmin(
        [signed_abs[f].sum(axis=1, dtype=np.int64) for f in (raw, sub, up)], axis=0
    )
    for kind, f in enumerate((raw, sub, up)):
        rows = out[:, 0] == kind
        out[rows, 1:] = f[rows]
    return out


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data and the CRC-32 of type and data (big-endian)."""
    crc = zlib.crc32(kind + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def _encode_png16(image: np.ndarray, level: int) -> bytes:
    """A 16-bit RGB or RGBA PNG file (colour type 2 or 6, not interlaced).

    Parameters
    ----------
    image : (H, W, 3) or (H, W, 4) uint16 ndarray
    level : int
        zlib compression level 0..9.

    Returns
    -------
    bytes
        The whole file. Samples are stored big-endian, as the PNG specification says.
    """
    h, w, ch = image.shape
    raw = np.ascontiguousarray(image, dtype=">u2").view(np.uint8).reshape(h, w * ch * 2)
    idat = zlib.compress(_png_filter(raw, ch * 2).tobytes(), level)
    ihdr = struct.pack(">IIBBBBB", w, h, 16, 6 if ch == 4 else 2, 0, 0, 0)
    return (
        _PNG_SIGNATURE
        + _png_chunk(b"IHDR", ihdr)
        + _png_chunk(b"IDAT", idat)
        + _png_chunk(b"IEND", b"")
    )


def _decode_png16(data: bytes, p: Path) -> np.ndarray:
    """Decode a 16-bit colour PNG (colour types 2, 4, 6) without loss.

    Chunks are checked against their CRC-32; ancillary chunks (gamma, ``sBIT``, text,
    and ``tRNS``: a transparent colour key is not turned into an alpha channel) are
    skipped, so the samples come as stored.

    Parameters
    ----------
    data : bytes
        The whole file.
    p : Path
        The file's name, for error messages.

    Returns
    -------
    (H, W, C) uint16 ndarray
        C = 3 (RGB), 2 (gray, alpha) or 4 (RGBA), native byte order.

    Raises
    ------
    FileFormatError
        A bad CRC, a truncated or corrupt stream, or an interlaced file.
    """
    pos, header = 8, b""
    idat: list[bytes] = []
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        body = data[pos + 8 : pos + 8 + length]
        crc = data[pos + 8 + length : pos + 12 + length]
        if len(body) < length or len(crc) < 4:
            raise FileFormatError(f"{p}: truncated PNG (the {kind!r} chunk is cut short)")
        if zlib.crc32(kind + body) & 0xFFFFFFFF != struct.unpack(">I", crc)[0]:
            raise FileFormatError(f"{p}: corrupt PNG (CRC mismatch in the {kind!r} chunk)")
        if kind == b"IHDR":
            header = body
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if len(header) != 13 or not idat:
        raise FileFormatError(f"{p}: truncated PNG (no {'IDAT' if header else 'IHDR'} chunk)")
    w, h, _, ctype, _, _, interlace = struct.unpack(">IIBBBBB", header)
    if interlace:
        raise FileFormatError(
            f"{p}: interlaced (Adam7) 16-bit colour PNGs are not read; re-save it without "
            "interlacing, e.g. cv2.imwrite(out, cv2.imread(path, cv2.IMREAD_UNCHANGED))"
        )
    ch = _PNG16_CHANNELS[ctype]
    n = w * ch * 2
    try:
        stream = zlib.decompress(b"".join(idat))
    except zlib.error as exc:
        raise FileFormatError(f"{p}: corrupt PNG image data ({exc})") from exc
    if w == 0 or h == 0 or len(stream) < h * (n + 1):
        raise FileFormatError(
            f"{p}: truncated PNG ({len(stream)} bytes of image data, {h * (n + 1)} expected)"
        )
    rows = np.frombuffer(stream, np.uint8, h * (n + 1)).reshape(h, n + 1)
    if rows[:, 0].max() > 4:
        raise FileFormatError(f"{p}: corrupt PNG (row filter type {rows[:, 0].max()} > 4)")
    raw = _png_unfilter(rows[:, 1:], rows[:, 0], ch * 2)
    return raw.view(">u2").reshape(h, w, ch).astype(np.uint16)


def _netpbm_header(data: bytes) -> tuple[str, int, int, int, int] | None:
    """Parse a PGM/PPM header (binary P5/P6 or plain P2/P3).

    Parameters
    ----------
    data : bytes
        The file, or at least its header.

    Returns
    -------
    (magic, width, height, maxval, offset) or None
        ``offset`` is where the samples start (after the one whitespace byte that ends a
        binary header); None when ``data`` is no such header.
    """
    if len(data) < 2 or data[:2] not in (b"P2", b"P3", b"P5", b"P6"):
        return None
    fields: list[int] = []
    pos = 2
    while len(fields) < 3:
        while pos < len(data) and (data[pos : pos + 1].isspace() or data[pos] == ord("#")):
            if data[pos] == ord("#"):
                end = data.find(b"\n", pos)
                pos = len(data) if end < 0 else end
            pos += 1
        start = pos
        while pos < len(data) and data[pos : pos + 1].isdigit():
            pos += 1
        if pos == start:
            return None
        fields.append(int(data[start:pos]))
    return data[:2].decode(), fields[0], fields[1], fields[2], pos + 1


def _decode_netpbm16(data: bytes, p: Path) -> np.ndarray | None:
    """Decode a 16-bit PGM/PPM (maxval > 255) without loss; None for any other file.

    Samples are kept as stored (a maxval of 4095 gives values 0..4095; nothing is
    rescaled), as ``cv2.imread(path, cv2.IMREAD_UNCHANGED)`` gives them. Binary samples
    are big-endian (the netpbm specification).

    Parameters
    ----------
    data : bytes
        The whole file.
    p : Path
        The file's name, for error messages.

    Returns
    -------
    (H, W) or (H, W, 3) uint16 ndarray, or None
        None when the file is not a 16-bit PGM/PPM (Pillow reads the others).
    """
    head = _netpbm_header(data)
    if head is None or not 255 < head[3] <= 65535:
        return None
    magic, w, h, _, offset = head
    ch = 3 if magic in ("P3", "P6") else 1
    count = w * h * ch
    if magic in ("P5", "P6"):
        if len(data) < offset + 2 * count:
            raise FileFormatError(
                f"{p}: truncated {magic} file ({len(data) - offset} bytes of samples, "
                f"{2 * count} expected)"
            )
        values = np.frombuffer(data, ">u2", count, offset).astype(np.uint16)
    else:
        text = re.sub(rb"#[^\n]*", b" ", data[offset - 1 :])
        values = np.array(text.split()[:count], dtype=np.int64)
        if values.size < count or values.max(initial=0) > 65535:
            raise FileFormatError(f"{p}: truncated or corrupt {magic} file")
        values = values.astype(np.uint16)
    return values.reshape((h, w, 3) if ch == 3 else (h, w))


def _encode_netpbm16(image: np.ndarray) -> bytes:
    """A binary 16-bit PGM (P5, gray) or PPM (P6, RGB) file with maxval 65535.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) uint16 ndarray

    Returns
    -------
    bytes
        The header, then the samples big-endian, as the netpbm specification says.
    """
    h, w = image.shape[:2]
    magic = b"P6" if image.ndim == 3 else b"P5"
    return b"%s\n%d %d\n65535\n" % (magic, w, h) + np.ascontiguousarray(image, ">u2").tobytes()


def _passthrough() -> list[str]:
    """ffmpeg options that hand over the decoded frames as they are.

    Without them ffmpeg resamples to the container's constant frame rate, repeating
    frames of a variable-rate file (``tree.avi``: 449 frames, of which 68 are distinct).
    ``-fps_mode`` is ffmpeg >= 5.1's name for the older ``-vsync``.
    """
    import imageio_ffmpeg

    try:
        major, minor = (
            int(v) for v in imageio_ffmpeg.get_ffmpeg_version().lstrip("n").split(".")[:2]
        )
    except ValueError:  # a build without a plain version number: assume a recent one
        major, minor = 99, 0
    if (major, minor) >= (5, 1):
        return ["-fps_mode", "passthrough"]
    return ["-vsync", "passthrough"]


class VideoReader:
    """Iterate over the frames of a video file as RGB uint8 arrays.

    Parameters
    ----------
    path : path-like
        Any container/codec that ffmpeg reads (MP4, AVI, MKV, ...).

    Attributes
    ----------
    fps : float
        Frames per second from the container.
    size : (int, int)
        ``(width, height)``.
    frame_count : int
        Number of frames; counted by decoding the file once on first access (exact, not
        the container's estimate).

    Frames come as decoded, one per coded picture, as ``cv2.VideoCapture`` gives
    them: a variable-frame-rate file is not padded with repeated frames.

    Examples
    --------
    >>> with VideoReader("clip.mp4") as video:  # doctest: +SKIP
    ...     for frame in video:
    ...         ...
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        import imageio_ffmpeg

        self.path = Path(path)
        check_file(self.path, "a video file")
        try:
            gen = imageio_ffmpeg.read_frames(str(self.path))
            meta: dict[str, Any] = gen.__next__()
            gen.close()
        except Exception as exc:
            raise FileFormatError(f"{self.path}: cannot open as video ({exc})") from exc
        self.fps = float(meta.get("fps") or 0.0)
        w, h = meta.get("size", (0, 0))
        self.size = (int(w), int(h))
        self.duration = float(meta.get("duration") or 0.0)
        self._frame_count: int | None = None
        self._gen: Any = None

    @property
    def frame_count(self) -> int:
        """Number of frames in the file, counted by decoding it once (then cached)."""
        if self._frame_count is None:
            import imageio_ffmpeg

            self._frame_count = int(imageio_ffmpeg.count_frames_and_secs(str(self.path))[0])
        return self._frame_count

    def __len__(self) -> int:
        return self.frame_count

    def __iter__(self) -> Iterator[np.ndarray]:
        import imageio_ffmpeg

        w, h = self.size
        self._gen = imageio_ffmpeg.read_frames(
            str(self.path), pix_fmt="rgb24", output_params=_passthrough()
        )
        self._gen.__next__()  # metadata
        try:
            for raw in self._gen:
                yield np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)
        finally:
            self.close()

    def close(self) -> None:
        """Stop decoding and release the ffmpeg process (iterating again reopens it)."""
        if self._gen is not None:
            self._gen.close()
            self._gen = None

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _lowest_priority(gen: Any) -> None:
    """Run the ffmpeg process behind an ``imageio_ffmpeg.write_frames`` generator at the
    lowest CPU priority, so that it encodes on the cores the pipeline leaves idle instead
    of taking them from it: Linux's ``SCHED_IDLE`` policy where the OS has it (the
    encoder runs only when a core has nothing else to run; nice 19 alone still takes a
    share of a busy core, in proportion to the frame rate), else nice 19. Applied to
    every thread the process has (threads it starts later inherit it)."""
    proc = getattr(getattr(gen, "gi_frame", None), "f_locals", {}).get("p")
    pid = getattr(proc, "pid", None)
    if pid is None or not hasattr(os, "setpriority"):
        return
    try:
        tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except (OSError, ValueError):
        tids = [pid]
    for tid in tids:
        try:
            os.setpriority(os.PRIO_PROCESS, tid, 19)
            if hasattr(os, "SCHED_IDLE"):
                os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
        except OSError:  # not permitted here, or the thread ended: it keeps its priority
            pass


class VideoWriter:
    """Write RGB uint8 frames to an H.264 MP4 (yuv420p, playable everywhere).

    The encoder (an ffmpeg process) runs at the lowest CPU priority where the OS allows
    it, so it takes only the cores the pipeline leaves idle. Every frame must have the
    size of the first. The file is complete once
    :meth:`close` runs (also on leaving a ``with`` block after an error), so frames
    written before an interruption are kept.

    Parameters
    ----------
    path : path-like
        ``.mp4``, ``.m4v``, ``.mov``, ``.mkv`` or ``.avi`` (:func:`check_video_path`);
        another extension is refused here, before any frame is made.
    fps : float
    quality : float
        0..10 (imageio-ffmpeg's scale; higher is better).
    """

    def __init__(
        self, path: str | os.PathLike[str], fps: float = 30.0, quality: float = 7.0
    ) -> None:
        self.path = check_video_path(path)
        self.fps = check_positive(fps, "fps")
        self.quality = float(quality)
        self._gen: Any = None
        self._size: tuple[int, int] | None = None
        self.frames_written = 0

    def write(self, frame: np.ndarray) -> None:
        """Append one (H, W, 3) uint8 RGB frame (a gray (H, W) frame is replicated)."""
        import imageio_ffmpeg

        frame = check_image(frame, "frame")
        if frame.dtype != np.uint8:
            raise InputError(f"frame must be uint8; got {frame.dtype}")
        if frame.ndim == 2:
            frame = np.repeat(frame[..., None], 3, axis=2)
        h, w = frame.shape[:2]
        if self._gen is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._size = (w, h)
            self._gen = imageio_ffmpeg.write_frames(
                str(self.path),
                (w, h),
                fps=self.fps,
                quality=self.quality,
                macro_block_size=1,
                pix_fmt_out="yuv420p" if w % 2 == 0 and h % 2 == 0 else "yuv444p",
                # x264's "veryfast" preset: about a third of "medium"'s CPU time for a
                # somewhat larger file at the same quality (the encoder runs beside
                # the pipeline, on the same cores)
                output_params=["-preset", "veryfast"],
            )
            self._gen.send(None)
            _lowest_priority(self._gen)
        elif (w, h) != self._size:
            raise InputError(
                f"frame size {w}x{h} differs from the first frame's {self._size[0]}x{self._size[1]}"
            )
        self._gen.send(np.ascontiguousarray(frame))
        self.frames_written += 1

    def close(self) -> None:
        """Flush the encoder and finish the file (a later ``write`` starts it anew)."""
        if self._gen is not None:
            self._gen.close()
            self._gen = None

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SnapshotVideoWriter:
    """A :class:`VideoWriter` that also saves chosen frames as PNG images.

    Frame ``index`` of :meth:`add` goes into the video; when ``index`` is one of
    ``snapshots`` it is also written to ``<stem>_<index:06d>.png`` beside the video
    (``out.mp4`` -> ``out_000025.png``). Closing (also on leaving a ``with`` block after
    an error) completes the video, so what was written before an interruption is kept.

    Parameters
    ----------
    path : path-like
        The MP4 to write.
    fps : float
    snapshots : iterable of int, optional
        Indices of the frames to save as PNG as well.

    Attributes
    ----------
    written : list of str
        Files written so far: the snapshots as they are written, and the video (first)
        once closed with at least one frame in it. Callers may append their own files.

    Examples
    --------
    >>> with SnapshotVideoWriter("out.mp4", 25.0, [0]) as out:  # doctest: +SKIP
    ...     out.add(0, np.zeros((48, 64, 3), np.uint8))
    >>> out.written  # doctest: +SKIP
    ['out.mp4', 'out_000000.png']
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        fps: float,
        snapshots: Iterable[int] | None = None,
    ) -> None:
        self.path = Path(path)
        self.writer = VideoWriter(self.path, fps=fps)
        self.snapshots = {int(i) for i in (snapshots or [])}
        self.written: list[str] = []

    def add(self, index: int, picture: np.ndarray) -> None:
        """Append ``picture`` (RGB uint8) to the video; save it too if ``index`` is a
        snapshot."""
        self.writer.write(picture)
        if index in self.snapshots:
            png = self.path.with_name(f"{self.path.stem}_{index:06d}.png")
            write_image(png, picture)
            self.written.append(str(png))

    def close(self) -> None:
        """Complete the video (and list it first in :attr:`written` if it has frames)."""
        self.writer.close()
        if self.writer.frames_written and str(self.path) not in self.written:
            self.written.insert(0, str(self.path))

    def __enter__(self) -> SnapshotVideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
