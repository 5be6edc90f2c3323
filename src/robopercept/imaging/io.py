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
import types
import warnings
import zlib
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    as_path,
    check_bool,
    check_extension,
    check_file,
    check_image,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError, RoboperceptError, RoboperceptWarning

_inflate_lib: types.ModuleType
_inflate_errors: tuple[type[BaseException], ...]
try:  # Intel ISA-L's inflate, about 3x the standard library's; the same zlib streams
    from isal import isal_zlib

    # (isal's stub declares its error class as an instance)
    _inflate_lib, _inflate_errors = isal_zlib, (zlib.error, cast(type, isal_zlib.error))
except ImportError:  # pragma: no cover - a platform without isal wheels
    _inflate_lib, _inflate_errors = zlib, (zlib.error,)

__all__ = [
    "IMAGE_EXTENSIONS",
    "SnapshotVideoWriter",
    "VideoReader",
    "VideoWriter",
    "check_image_path",
    "check_png_compression",
    "check_video_path",
    "contained_path",
    "output_stems",
    "read_image",
    "sample_image_path",
    "write_image",
]

#: the image file extensions :func:`read_image` and :func:`write_image` take (any case)
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm")
#: containers that take the H.264 stream :class:`VideoWriter` encodes
_VIDEO_EXTS = {".mp4", ".m4v", ".mov", ".mkv", ".avi"}


def check_png_compression(level: int) -> int:
    """Return ``level`` after checking that it is a zlib level 0..9, as
    :func:`write_image`'s ``png_compression`` takes; callers that write many images
    check it before the first."""
    v = check_int(level, "png_compression", 0)
    if v > 9:
        raise InputError(f"png_compression must be in 0..9; got {v}")
    return v


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
    return check_extension(path, set(IMAGE_EXTENSIONS), "an image")


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
    mode : {None, 'rgb', 'gray', 'index'}
        None keeps what the file stores (gray (H, W), gray + alpha (H, W, 2), RGB
        (H, W, 3), RGBA (H, W, 4), uint8 or uint16); 'rgb' gives (H, W, 3) (gray
        replicated, alpha dropped); 'gray' gives (H, W) (BT.601 luma of colour files,
        :func:`~robopercept.imaging.rgb_to_gray`, in the file's dtype); 'index' gives
        a palette PNG's indices (H, W) uint8, not their colours (the label maps of
        Pascal VOC's SegmentationClass and SegmentationObject: 0 background, 255 void;
        ``cv2.imread`` has no such mode, PIL's ``Image.open(path)`` in mode "P" does).

    Returns
    -------
    ndarray
        uint8 for 8-bit files; uint16 for 16-bit PNG, TIFF and PGM/PPM files (gray or
        colour), with the samples as stored: nothing is rescaled (a PGM with maxval 4095
        gives 0..4095).

    Raises
    ------
    FileFormatError
        Missing, empty, truncated or undecodable file, naming the file; every exception
        a decoder raises on a corrupt file comes as this one. A header that declares
        more pixels than the file can hold (PNG: more data than deflate's 1032:1 can
        expand to; BMP, PGM/PPM, uncompressed TIFF: more samples than bytes; baseline
        JPEG: fewer than 2 bits per 8x8 block) or more than Pillow's decompression-bomb
        limit ``PIL.Image.MAX_IMAGE_PIXELS`` is refused before the image is allocated; a
        PNG whose image data ends before the rows its header declares is refused rather
        than padded with zero rows.
    """
    from robopercept.imaging.color import rgb_to_gray

    p = as_path(path, "path")
    if mode not in (None, "rgb", "gray", "index"):
        raise InputError(f"mode must be None, 'rgb', 'gray' or 'index'; got {mode!r}")
    check_file(p, "an image file")
    if p.stat().st_size == 0:
        raise FileFormatError(f"{p}: the file is empty")
    try:
        img = _decode_image(p, indexed=mode == "index")
    except (RoboperceptError, MemoryError):
        raise
    except Exception as exc:  # decoders raise many kinds (OSError, SyntaxError, ...)
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


def _decode_image(p: Path, indexed: bool = False) -> np.ndarray:
    """The array of an image file as its decoder gives it, after the header checks.

    PNG goes through :func:`_read_png` (every PNG, so its data is checked against its
    header); a 16-bit PGM/PPM through :func:`_decode_netpbm16`; the rest through imageio
    once :func:`_check_declared_size` has passed, with the plugin named by the file's
    first bytes (:func:`_imageio_plugin`: tifffile for TIFF, Pillow for the rest), so that
    a damaged file is never handed to imageio's probe of every plugin (which imports
    OpenCV and tifffile to try them: megabytes, for a file none of them reads).

    Parameters
    ----------
    p : Path
        An existing, non-empty file.
    indexed : bool
        A palette PNG's indices (H, W) instead of its colours; any other file is
        refused.

    Returns
    -------
    ndarray
        As decoded (gray, gray + alpha, RGB or RGBA; uint8, uint16, int32 or bool).

    Raises
    ------
    FileFormatError
        From the checks; decoders' own exceptions pass through (read_image types them).
    """
    import imageio.v3 as iio

    with open(p, "rb") as fh:
        head = fh.read(4096)  # a PNG's IHDR; a netpbm header, comments included
    if head.startswith(_PNG_SIGNATURE):
        return _read_png(p.read_bytes(), p, indexed)
    if indexed:
        raise FileFormatError(
            f"{p}: mode='index' reads palette PNGs (label maps such as Pascal VOC's "
            "SegmentationClass); this is not a PNG: read it with mode=None"
        )
    _check_declared_size(p)
    header = _netpbm_header(head)
    if header is not None and header[3] > 255:
        img = _decode_netpbm16(p.read_bytes(), p)
        if img is not None:
            return img
    return np.asarray(iio.imread(p, plugin=_imageio_plugin(head)))


#: the first bytes of a TIFF file (little- and big-endian; BigTIFF has 43 for 42)
_TIFF_SIGNATURES = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")


def _imageio_plugin(head: bytes) -> str:
    """The imageio plugin that decodes a non-PNG image file starting with ``head``:
    ``"tifffile"`` for a TIFF signature (``II*\\0``, ``MM\\0*``, BigTIFF's), else
    ``"pillow"``, which knows JPEG, BMP, PNM, GIF, WebP and more by their own
    signatures and raises on anything else.

    >>> _imageio_plugin(b"II*\\x00\\x08\\x00"), _imageio_plugin(b"\\xff\\xd8\\xff\\xe0")
    ('tifffile', 'pillow')
    """
    return "tifffile" if head[:4] in _TIFF_SIGNATURES else "pillow"


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


# --------------------------------------------------------------------------- file names


def contained_path(
    root: str | os.PathLike[str],
    name: str | os.PathLike[str],
    what: str,
    allow_outside: bool = False,
) -> Path:
    """The file ``root / name`` that an annotation or list file names, refused when the
    name leads outside ``root`` (the data set's folder).

    A data set's files name their images relative to a folder: COCO's ``file_name``,
    labelme's ``imagePath``, Pascal VOC's ``<filename>``, the lists of a TUM folder
    (``rgb.txt``, ``depth.txt``, ``associations.txt``). A file from elsewhere could name
    ``../../home/user/.ssh/id_rsa`` or ``/etc/passwd`` and have it read (and copied into
    an output folder). The rule, on the name as written (lexically, without touching the
    disk): an absolute name, or one whose ``..`` climb above ``root`` once normalised
    (``os.path.normpath``), is outside. ``a/../b.png`` stays inside. A symbolic link
    inside ``root`` is followed wherever it points: putting it there was the folder
    owner's choice. With ``allow_outside`` every name is taken, as before this rule.

    Parameters
    ----------
    root : str or path-like
        The data set's folder.
    name : str or path-like
        The path as the file writes it, relative to ``root``.
    what : str
        The entry, for the message: the file and where in it (``"gt.json:
        images[3].file_name"``, ``"rgb.txt:12"``).
    allow_outside : bool, default False
        Take names outside ``root`` (a file you trust; the command-line option
        ``--allow-outside-paths``).

    Returns
    -------
    Path
        ``Path(root) / name``, as written (not normalised).

    Raises
    ------
    FileFormatError
        ``name`` is not a usable path (not a string, empty, a NUL byte, too long), or
        leads outside ``root`` while ``allow_outside`` is False; the message names the
        entry and the remedies.
    InputError
        ``root`` is not a usable path, ``allow_outside`` not a bool.

    Examples
    --------
    >>> contained_path("data", "images/a.png", "gt.json: images[0].file_name")
    PosixPath('data/images/a.png')
    >>> contained_path("data", "../../etc/passwd", "gt.json: images[1].file_name")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: gt.json: images[1].file_name '../../etc/passwd' \
leads outside the data set's folder data (an absolute path, or '..' above it): move the \
file into data and name it relative to data, or allow paths outside the folder for a file \
you trust (allow_outside=True in Python, --allow-outside-paths on the command line)
    >>> contained_path("data", "/tmp/a.png", "rgb.txt:3", allow_outside=True)
    PosixPath('/tmp/a.png')
    """
    base = as_path(root, "root")
    allow_outside = check_bool(allow_outside, "allow_outside")
    try:
        rel = as_path(name, what)
    except InputError as exc:
        raise FileFormatError(f"{what}: not a usable file name ({exc})") from None
    joined = base / rel
    if allow_outside:
        return joined
    norm = os.path.normpath(os.fspath(rel))
    if (
        rel.is_absolute()
        or rel.drive
        or rel.root
        or norm == os.pardir
        or norm.startswith(os.pardir + os.sep)
    ):
        raise FileFormatError(
            f"{what} {os.fspath(name)!r} leads outside the data set's folder {base} (an "
            f"absolute path, or '..' above it): move the file into {base} and name it "
            f"relative to {base}, or allow paths outside the folder for a file you trust "
            "(allow_outside=True in Python, --allow-outside-paths on the command line)"
        )
    return joined


def output_stems(
    paths: Sequence[str | os.PathLike[str]], suffixes: Sequence[str] = ("",)
) -> list[str]:
    """One output name stem per input file, distinct even when inputs share a name.

    A command that writes ``OUT/<stem><suffix>`` for each input (``nn segment a/x.png
    b/x.png -o OUT``) would write the second input's files over the first's. The rule:

    1. each input's stem is its file name without the extension (``x`` for ``a/x.png``);
    2. inputs whose stems are equal (compared without case, as on macOS and Windows
       file systems) get the names of their folders prefixed, joined by ``_``, one
       level more at a time until they differ: ``a/x.png``, ``b/x.png`` give ``a_x``
       and ``b_x``; ``a/c/x.png``, ``b/c/x.png`` give ``a_c_x`` and ``b_c_x`` (the
       folders of the absolute path; the fewest levels that tell most of them apart);
    3. a name whose output files (``stem + suffix`` for each of ``suffixes``) would
       still meet those of an earlier input (the same file given twice, ``x.png`` and
       ``x.jpg`` in one folder, ``x.png`` beside ``x_labels.png`` when ``_labels.png``
       is a suffix) gets ``-2``, ``-3``, ... in input order: ``x``, ``x-2``.

    Inputs with distinct stems keep their stems, so a single input, or inputs with
    different names, are written as ``OUT/<stem>...`` as always.

    Parameters
    ----------
    paths : sequence of str or path-like
        The inputs, in order.
    suffixes : sequence of str, default ("",)
        What each input writes after its stem (``(".png", "_labels.png")``): rule 3
        keeps every written name distinct (without case).

    Returns
    -------
    list of str
        One stem per input, in order.

    Raises
    ------
    InputError
        ``paths`` not a sequence of paths (or one naming no file: ``/``, ``..``), or
        ``suffixes`` not a sequence of strings.

    Examples
    --------
    >>> output_stems(["a/x.png", "b/x.png", "b/y.png"])
    ['a_x', 'b_x', 'y']
    >>> output_stems(["x.png", "x.png", "x.jpg"])
    ['x', 'x-2', 'x-3']
    >>> output_stems(["x.png", "x_labels.png"], suffixes=(".png", "_labels.png"))
    ['x', 'x_labels-2']
    """
    if isinstance(paths, (str, bytes, os.PathLike)) or not isinstance(paths, Sequence):
        raise InputError(f"paths must be a list of file paths; got {plain_repr(paths)}")
    if isinstance(suffixes, (str, bytes)) or not (
        isinstance(suffixes, Sequence) and all(isinstance(s, str) for s in suffixes)
    ):
        raise InputError(
            f"suffixes must be a list of strings such as ['.png']; got {plain_repr(suffixes)}"
        )
    files = [as_path(p, f"paths[{k}]") for k, p in enumerate(paths)]
    for k, f in enumerate(files):
        if f.name in ("", ".", ".."):
            raise InputError(f"paths[{k}] must name a file; got {os.fspath(f)!r}")
    stems = [f.stem for f in files]
    groups: dict[str, list[int]] = {}
    for k, stem in enumerate(stems):
        groups.setdefault(stem.casefold(), []).append(k)
    for members in groups.values():
        if len(members) < 2:
            continue
        folders = {k: Path(os.path.abspath(files[k])).parent.parts[1:] for k in members}
        deepest = max(len(f) for f in folders.values())
        best, best_count = 0, 1
        for level in range(1, deepest + 1):
            names = {"_".join((*folders[k][-level:], stems[k])).casefold() for k in members}
            if len(names) > best_count:
                best, best_count = level, len(names)
            if best_count == len(members):
                break
        if best:
            for k in members:
                stems[k] = "_".join((*folders[k][-best:], stems[k]))
    ends = tuple(suffixes) or ("",)
    used: set[str] = set()
    out = []
    for stem in stems:
        name, n = stem, 1
        while any((name + e).casefold() in used for e in ends):
            n += 1
            name = f"{stem}-{n}"
        used.update((name + e).casefold() for e in ends)
        out.append(name)
    return out


def write_image(
    path: str | os.PathLike[str],
    image: np.ndarray,
    *,
    png_compression: int | None = None,
    palette: npt.ArrayLike | None = None,
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
        than the default for 20% larger files, what sequences of frames want; 0 stores
        the rows unfiltered and uncompressed, at memory speed, for scratch files).
    palette : (n, 3) array-like of uint8, optional
        Write a palette PNG: ``image`` is then an (H, W) uint8 map of indices below
        ``n <= 256`` and index ``i`` shows as colour ``palette[i]`` (the label maps of
        Pascal VOC with its palette; read the indices back with
        ``read_image(path, mode="index")``).

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

    p = as_path(path, "path")
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
    if png_compression is not None:
        level = check_png_compression(png_compression)
        if ext == ".png":
            extra["compress_level"] = level
    pal = None if palette is None else _check_palette(palette, arr, ext, p)
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        if pal is not None:
            from PIL import Image

            im = Image.fromarray(np.ascontiguousarray(arr))  # mode "L"
            im.putpalette(pal.ravel().tolist())  # "L" -> "P", the values kept as indices
            im.save(p, format="PNG", compress_level=extra.get("compress_level", 6))
        elif ext == ".png" and (
            (arr.dtype == np.uint16 and arr.ndim == 3) or extra.get("compress_level") == 0
        ):
            # 16-bit colour (which imageio's Pillow cannot write), and stored files (at
            # level 0 Pillow still filters every row: 20x slower than memory speed)
            p.write_bytes(_encode_png(arr, extra.get("compress_level", 6)))
        elif arr.dtype == np.uint16 and ext in _PNM_EXTS:
            p.write_bytes(_encode_netpbm16(arr))
        else:
            iio.imwrite(p, np.ascontiguousarray(arr), **extra)
    except Exception as exc:
        raise FileFormatError(f"{p}: cannot write ({type(exc).__name__}: {exc})") from exc
    return p


def _check_palette(palette: Any, arr: np.ndarray, ext: str, p: Path) -> np.ndarray:
    """``palette`` as an (n, 3) uint8 array fit to write ``arr`` (indices) to ``p``."""
    if ext != ".png":
        raise InputError(f"{p}: a palette is written to PNG only; use a .png path")
    pal = np.asarray(palette)
    if (
        pal.ndim != 2
        or pal.shape[1] != 3
        or not 1 <= pal.shape[0] <= 256
        or pal.dtype.kind not in "iu"
        or pal.min() < 0
        or pal.max() > 255
    ):
        raise InputError(
            f"palette must be (n, 3) integer colours in 0..255 with 1 <= n <= 256; got "
            f"{plain_repr(palette)}"
        )
    if arr.ndim != 2 or arr.dtype != np.uint8:
        raise InputError(
            f"with a palette, image must be an (H, W) uint8 map of indices; got "
            f"{arr.dtype} {arr.shape}"
        )
    if arr.size and int(arr.max()) >= pal.shape[0]:
        raise InputError(
            f"image holds index {int(arr.max())} but the palette has {pal.shape[0]} "
            "colours: extend the palette (e.g. robopercept.viz.voc_palette(256))"
        )
    return pal.astype(np.uint8)


# -- 16-bit PNG and netpbm ---------------------------------------------------------------
#
# Pillow has no 16-bit colour mode: it reads a 16-bit RGB(A) PNG or PPM as 8 bits and
# cannot write one. These files go through the small codecs below (the PNG and netpbm
# specifications, zlib for the compression); everything else goes through imageio.

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: PNG colour type -> channels, and the bit depths the specification allows for it
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
_PNG_DEPTHS = {0: (1, 2, 4, 8, 16), 2: (8, 16), 3: (1, 2, 4, 8), 4: (8, 16), 6: (8, 16)}
#: the Adam7 passes: first column, first row, column step, row step
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
          (0, 1, 1, 2))  # fmt: skip
#: deflate's largest expansion: a 258-byte match coded in 1 + 1 bits (zlib's header and
#: the block headers only lower it)
_DEFLATE_MAX_RATIO = 1032
#: PNG colour type -> channels, for the 16-bit colour types that Pillow reduces to 8 bits
_PNG16_CHANNELS = {2: 3, 4: 2, 6: 4}
_PNM_EXTS = {".ppm", ".pgm", ".pnm"}


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
    steps (a row-by-row loop would need one Python step per pixel for types 3 and 4),
    in memory linear in the image (two int16 copies of it).
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
    # r[(y + 1) * (w + 1) + x + 1] is pixel (y, x); row 0 and column 0 of the (h + 1) x
    # (w + 1) grid stand for the zeros outside the image, so the left, upper and
    # upper-left neighbours of flat index i are i - 1, i - (w + 1) and i - (w + 2)
    f = filtered.reshape(h * w, bpp).astype(np.int16)
    r = np.zeros(((h + 1) * (w + 1), bpp), np.int16)
    kind = types.astype(np.int16)
    for t in range(w + h - 1):
        ys = np.arange(max(0, t - w + 1), min(h, t + 1))
        i = (ys + 1) * (w + 1) + (t - ys) + 1
        a, b, c = r[i - 1], r[i - (w + 1)], r[i - (w + 2)]
        k = kind[ys][:, None]
        pred = np.where(k == 1, a, np.where(k == 2, b, 0))
        pred = np.where(k == 3, (a + b) >> 1, pred)
        if (k == 4).any():
            pred = np.where(k == 4, _paeth(a, b, c), pred)
        r[i] = (f[ys * w + (t - ys)] + pred) & 255
    return r.reshape(h + 1, w + 1, bpp)[1:, 1:].astype(np.uint8).reshape(h, n)


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
    crc = zlib.crc32(data, zlib.crc32(kind)) & 0xFFFFFFFF  # no copy of kind + data
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)


def _encode_png(image: np.ndarray, level: int) -> bytes:
    """A PNG file of 8- or 16-bit gray, RGB or RGBA samples (not interlaced).

    Parameters
    ----------
    image : (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) uint8 or uint16 ndarray
    level : int
        zlib compression level 0..9. Level 0 stores the rows unfiltered (filter type
        none), as libpng does when it does not compress: filtering only helps a
        compressor, and the file is then written at memory speed.

    Returns
    -------
    bytes
        The whole file. 16-bit samples are stored big-endian, as the PNG specification
        says.
    """
    h, w = image.shape[:2]
    ch = 1 if image.ndim == 2 else image.shape[2]
    depth = 8 * image.dtype.itemsize
    dtype = ">u2" if depth == 16 else np.uint8
    raw = np.ascontiguousarray(image, dtype=dtype).view(np.uint8).reshape(h, w * ch * depth // 8)
    if level == 0:
        rows = np.zeros((h, raw.shape[1] + 1), np.uint8)
        rows[:, 1:] = raw
    else:
        rows = _png_filter(raw, ch * depth // 8)
    idat = zlib.compress(rows.tobytes(), level)
    ihdr = struct.pack(">IIBBBBB", w, h, depth, {1: 0, 2: 4, 3: 2, 4: 6}[ch], 0, 0, 0)
    return (
        _PNG_SIGNATURE
        + _png_chunk(b"IHDR", ihdr)
        + _png_chunk(b"IDAT", idat)
        + _png_chunk(b"IEND", b"")
    )


def _png_chunks(data: bytes, p: Path) -> list[tuple[bytes, int, int]]:
    """The chunks of a PNG file up to its IEND, each as ``(type, start, end)`` (``end``
    past its CRC), checked as libpng checks them.

    A chunk that runs past the end of the file, or a file without IEND, is truncated; a
    critical chunk (type starting upper case: IHDR, PLTE, IDAT, IEND) whose CRC-32 does
    not match is corrupt; an ancillary chunk with a bad CRC is left out (libpng's
    default: warn and discard).

    Parameters
    ----------
    data : bytes
        The whole file, signature included.
    p : Path
        The file's name, for error messages.

    Returns
    -------
    list of (bytes, int, int)

    Raises
    ------
    FileFormatError
    """
    chunks, pos = [], len(_PNG_SIGNATURE)
    while True:
        if pos + 12 > len(data):
            raise FileFormatError(
                f"{p}: truncated PNG (the file ends at byte {len(data)}, before its IEND chunk)"
            )
        (length,) = struct.unpack_from(">I", data, pos)
        kind, end = data[pos + 4 : pos + 8], pos + 12 + length
        if end > len(data):
            raise FileFormatError(f"{p}: truncated PNG (the {kind!r} chunk is cut short)")
        (crc,) = struct.unpack_from(">I", data, end - 4)
        if zlib.crc32(data[pos + 4 : end - 4]) & 0xFFFFFFFF == crc:
            chunks.append((kind, pos, end))
        elif kind[:1].isupper():
            raise FileFormatError(f"{p}: corrupt PNG (CRC mismatch in the {kind!r} chunk)")
        if kind == b"IEND":
            return chunks
        pos = end


def _png_stream_size(w: int, h: int, bits: int, interlace: int) -> int:
    """Bytes of the decompressed IDAT stream of a ``w`` x ``h`` PNG (PNG specification,
    sections 7.2 and 8.2): each row is a filter-type byte and
    :math:`\\lceil w \\cdot bits / 8 \\rceil` bytes; an Adam7 file holds the rows of its 7
    passes (pass ``(x0, y0, dx, dy)`` has :math:`\\lceil (w - x0) / dx \\rceil` columns
    and :math:`\\lceil (h - y0) / dy \\rceil` rows; an empty pass has no bytes).

    Parameters
    ----------
    w, h : int
        Width and height, > 0.
    bits : int
        Bits per pixel (bit depth times channels).
    interlace : int
        0 none, 1 Adam7.

    Returns
    -------
    int
    """
    passes = _ADAM7 if interlace else ((0, 0, 1, 1),)
    total = 0
    for x0, y0, dx, dy in passes:
        cols, rows = -(-(w - x0) // dx), -(-(h - y0) // dy)
        if cols > 0 and rows > 0:
            total += rows * (1 + (cols * bits + 7) // 8)
    return total


def _check_pixels(p: Path, fmt: str, w: int, h: int, decoded_bytes: int) -> None:
    """Refuse a header's image size before anything is allocated for it: no pixels, or
    more than Pillow's decompression-bomb limit ``PIL.Image.MAX_IMAGE_PIXELS`` (read at
    each call, so raising it, or setting None, lets trusted large files through).

    Parameters
    ----------
    p : Path
        The file, for the message.
    fmt : str
        Its format's name, for the message.
    w, h : int
        The size its header declares.
    decoded_bytes : int
        What the decoded image would take, for the message.

    Raises
    ------
    FileFormatError
    """
    from PIL import Image

    if w <= 0 or h <= 0:
        raise FileFormatError(f"{p}: corrupt {fmt} (its header declares a {w}x{h} image)")
    cap = Image.MAX_IMAGE_PIXELS
    if cap is not None and w * h > cap:
        raise FileFormatError(
            f"{p}: the {fmt} header declares {w}x{h} = {w * h} pixels "
            f"({decoded_bytes / 2**20:.0f} MiB decoded), over the decompression-bomb limit "
            f"of {int(cap)} pixels; if the file is trusted, raise PIL.Image.MAX_IMAGE_PIXELS"
        )


def _read_png(data: bytes, p: Path, indexed: bool = False) -> np.ndarray:
    """Decode a PNG, its data checked against its header before and while decoding.

    1. The chunks are walked and checked (:func:`_png_chunks`); IHDR must come first
       with a bit depth and colour type the specification allows.
    2. Before anything is decompressed: the size must pass :func:`_check_pixels`, and
       the IDAT stream the header implies (:func:`_png_stream_size`) must fit in what
       deflate can make of the compressed bytes, at most 1032 bytes per byte (a
       258-byte match coded in 2 bits).
    3. The stream is decompressed to at most its declared size; a stream that ends
       before it is a truncated file (Pillow pads the missing rows with zeros).
    4. 16-bit colour (RGB, gray + alpha, RGBA) is reconstructed here
       (:func:`_decode_png16`: Pillow has no 16-bit colour mode); everything else goes
       to Pillow as the same file with the checked stream in one stored (uncompressed)
       IDAT, so it is decompressed once.

    Parameters
    ----------
    data : bytes
        The whole file.
    p : Path
        The file's name, for error messages.

    Returns
    -------
    ndarray
        As ``cv2.imread(path, cv2.IMREAD_UNCHANGED)`` gives it, in RGB(A) order.

    Raises
    ------
    FileFormatError
    """
    import imageio.v3 as iio

    chunks = _png_chunks(data, p)
    first, start, end = chunks[0]
    if first != b"IHDR" or end - start != 25:
        raise FileFormatError(f"{p}: corrupt PNG (no IHDR chunk first)")
    w, h, depth, ctype, method, filt, interlace = struct.unpack_from(">IIBBBBB", data, start + 8)
    if depth not in _PNG_DEPTHS.get(ctype, ()) or method or filt or interlace > 1:
        raise FileFormatError(
            f"{p}: corrupt PNG header (bit depth {depth}, colour type {ctype}, "
            f"methods {method}/{filt}/{interlace})"
        )
    if interlace and depth == 16 and ctype in _PNG16_CHANNELS:
        raise FileFormatError(
            f"{p}: interlaced (Adam7) 16-bit colour PNGs are not read; re-save it without "
            "interlacing, e.g. cv2.imwrite(out, cv2.imread(path, cv2.IMREAD_UNCHANGED))"
        )
    if indexed and ctype != 3:
        raise FileFormatError(
            f"{p}: mode='index' reads palette PNGs (colour type 3); this one has colour "
            f"type {ctype}: read it with mode=None (a gray PNG holds its labels as values)"
        )
    channels = 4 if ctype == 3 else _PNG_CHANNELS[ctype]  # palette: expanded to RGB(A)
    _check_pixels(p, "PNG", w, h, w * h * channels * max(depth // 8, 1))
    idat = b"".join(data[a + 8 : b - 4] for kind, a, b in chunks if kind == b"IDAT")
    size = _png_stream_size(w, h, depth * _PNG_CHANNELS[ctype], interlace)
    if size > _DEFLATE_MAX_RATIO * len(idat):
        raise FileFormatError(
            f"{p}: truncated or corrupt PNG (its header declares {w}x{h} pixels, "
            f"{size} bytes of image data, but it holds {len(idat)} compressed bytes, "
            f"which deflate cannot expand beyond {_DEFLATE_MAX_RATIO * len(idat)})"
        )
    try:
        stream = _inflate_lib.decompressobj().decompress(idat, size)
    except _inflate_errors as exc:
        raise FileFormatError(f"{p}: corrupt PNG image data ({exc})") from exc
    if len(stream) < size:
        raise FileFormatError(
            f"{p}: truncated PNG ({len(stream)} bytes of image data, {size} expected "
            f"for the {w}x{h} pixels its header declares)"
        )
    if depth == 16 and ctype in _PNG16_CHANNELS:
        return _decode_png16(stream, w, h, _PNG16_CHANNELS[ctype], p)
    kinds = {kind for kind, _, _ in chunks}
    if depth in (8, 16) and ctype in (0, 2, 6) and not interlace and b"tRNS" not in kinds:
        # rows stored unfiltered (filter type 0 on every row, as write_image writes
        # png_compression=0): the samples as they are, without a pass through Pillow
        ch = _PNG_CHANNELS[ctype]
        rows = np.frombuffer(stream, np.uint8, size).reshape(h, 1 + w * ch * depth // 8)
        if not rows[:, 0].any():
            samples = rows[:, 1:].view(">u2" if depth == 16 else np.uint8)
            img = samples.astype(np.uint16 if depth == 16 else np.uint8)
            return img.reshape((h, w) if ch == 1 else (h, w, ch))
    parts, stored = [data[:8]], _png_chunk(b"IDAT", zlib.compress(stream, 0))
    for kind, a, b in chunks:
        if kind != b"IDAT":
            parts.append(data[a:b])
        elif stored:
            parts.append(stored)
            stored = b""
    if indexed:  # the palette indices, not their colours (Pillow's mode "P")
        return np.asarray(iio.imread(b"".join(parts), plugin="pillow", extension=".png", mode="P"))
    return np.asarray(iio.imread(b"".join(parts), plugin="pillow", extension=".png"))


def _decode_png16(stream: bytes, w: int, h: int, ch: int, p: Path) -> np.ndarray:
    """Reconstruct a non-interlaced 16-bit colour PNG (colour types 2, 4, 6) from its
    decompressed IDAT stream, without loss.

    Ancillary chunks (gamma, ``sBIT``, text, and ``tRNS``: a transparent colour key is
    not turned into an alpha channel) are not applied, so the samples come as stored.

    Parameters
    ----------
    stream : bytes
        The decompressed IDAT stream, at least ``h * (1 + w * ch * 2)`` bytes (checked
        by :func:`_read_png`).
    w, h, ch : int
        Width, height, channels.
    p : Path
        The file's name, for error messages.

    Returns
    -------
    (H, W, C) uint16 ndarray
        C = 3 (RGB), 2 (gray, alpha) or 4 (RGBA), native byte order.

    Raises
    ------
    FileFormatError
        A row filter type above 4.
    """
    n = w * ch * 2
    rows = np.frombuffer(stream, np.uint8, h * (n + 1)).reshape(h, n + 1)
    if rows[:, 0].max() > 4:
        raise FileFormatError(f"{p}: corrupt PNG (row filter type {rows[:, 0].max()} > 4)")
    raw = _png_unfilter(rows[:, 1:], rows[:, 0], ch * 2)
    return raw.view(">u2").reshape(h, w, ch).astype(np.uint16)


def _check_declared_size(p: Path) -> None:
    """Refuse, before decoding, a non-PNG image whose header declares more pixels than
    the file can hold or than :func:`_check_pixels` allows.

    Where the format bounds its compression, the header's size is compared with the
    file's: BMP without compression (``offset + stride * |height|`` bytes, rows padded
    to 4 bytes), binary PGM/PPM/PBM (their samples' bytes), plain PGM/PPM (at least 2
    bytes a sample: a digit and a separator; 1 a pixel for plain PBM), TIFF (every
    strip or tile inside the file; uncompressed: all its samples' bytes), baseline and
    extended Huffman JPEG (at least 2 bits per 8x8 block of its largest component: a DC
    code and an end-of-block code). Progressive and arithmetic-coded JPEG, RLE BMP and
    compressed TIFF have no such bound: only the pixel limit applies to them.

    Parameters
    ----------
    p : Path
        An existing, non-empty file.

    Raises
    ------
    FileFormatError
    """
    size = p.stat().st_size
    with open(p, "rb") as fh:
        head = fh.read(4096)
        if head[:2] == b"\xff\xd8":
            dims = _jpeg_frame(fh)
            if dims is not None:
                w, h, ch, huffman = dims
                _check_pixels(p, "JPEG", w, h, w * h * ch)
                need = -(-w // 8) * -(-h // 8) // 4
                if huffman and need > size:
                    raise FileFormatError(
                        f"{p}: truncated or corrupt JPEG (its header declares {w}x{h} pixels, "
                        f"which take at least {need} bytes of Huffman-coded data; the file "
                        f"has {size})"
                    )
            return
    fmt, need = "", 0
    if head[:2] == b"BM" and len(head) >= 30:
        (offset,) = struct.unpack_from("<I", head, 10)
        if struct.unpack_from("<I", head, 14)[0] == 12:  # OS/2 BITMAPCOREHEADER
            w, h, _, bits = struct.unpack_from("<HHHH", head, 18)
            compression = 0
        elif len(head) >= 34:
            w, h, _, bits, compression = struct.unpack_from("<iiHHI", head, 18)
        else:
            return
        h = abs(h)  # negative: rows stored top-down
        _check_pixels(p, "BMP", w, h, w * h * 4)
        fmt = "BMP"
        if compression in (0, 3, 6):  # BI_RGB, BI_BITFIELDS, BI_ALPHABITFIELDS
            need = offset + (w * bits + 31) // 32 * 4 * h
    elif (header := _netpbm_header(head)) is not None:
        magic, w, h, maxval, offset = header
        ch = 3 if magic in ("P3", "P6") else 1
        fmt = magic
        _check_pixels(p, magic, w, h, w * h * ch * (2 if maxval > 255 else 1))
        samples = w * h * ch
        need = offset + {
            "P1": samples,
            "P4": -(-w // 8) * h,
            "P5": samples * (2 if maxval > 255 else 1),
            "P6": samples * (2 if maxval > 255 else 1),
        }.get(magic, 2 * samples - 1)
    elif head[:4] in (b"II*\x00", b"MM\x00*"):
        fmt = "TIFF"
        need = _tiff_need(p, size)
    if need > size:
        raise FileFormatError(
            f"{p}: truncated {fmt} (its header declares {need} bytes of image data and "
            f"header; the file has {size})"
        )


def _jpeg_frame(fh: Any) -> tuple[int, int, int, bool] | None:
    """The frame header (SOF) of a JPEG: width, height, components, and whether it is
    sequential Huffman-coded (SOF0, SOF1, SOF3); None if the markers before it cannot be
    walked (the decoder then says what is wrong).

    Parameters
    ----------
    fh : binary file
        Positioned anywhere; read from byte 2 (after SOI).

    Returns
    -------
    (int, int, int, bool) or None
    """
    fh.seek(2)
    while True:
        marker = fh.read(4)
        if len(marker) < 4 or marker[0] != 0xFF or marker[1] in (0xD9, 0xDA):
            return None
        if 0xC0 <= marker[1] <= 0xCF and marker[1] not in (0xC4, 0xC8, 0xCC):
            frame = fh.read(6)
            if len(frame) < 6:
                return None
            _, h, w, ch = struct.unpack(">BHHB", frame)
            return w, h, ch, marker[1] in (0xC0, 0xC1, 0xC3)
        (length,) = struct.unpack(">H", marker[2:])
        if length < 2:  # a corrupt length (it counts its own 2 bytes)
            return None
        fh.seek(length - 2, os.SEEK_CUR)


def _tiff_need(p: Path, size: int) -> int:
    """The bytes the first page of a TIFF needs, from its tags (tifffile parses them):
    every strip or tile must lie inside the file (a missing one, of 0 bytes, would be
    filled with zeros by the decoder) and, uncompressed, hold all the page's samples.

    Parameters
    ----------
    p : Path
        The file.
    size : int
        Its size in bytes.

    Returns
    -------
    int
        The size the file must have at least (``size + 1`` for a strip outside it).

    Raises
    ------
    FileFormatError
        Over the pixel limit (:func:`_check_pixels`).
    """
    import tifffile

    with tifffile.TiffFile(p) as tif:
        page = tif.pages.first
        h, w = int(page.imagelength), int(page.imagewidth)
        _check_pixels(p, "TIFF", w, h, int(page.size) * page.dtype.itemsize)
        counts = [int(c) for c in page.databytecounts]
        if not counts or min(counts) == 0:
            return size + 1
        end = max(int(o) + c for o, c in zip(page.dataoffsets, counts, strict=True))
        if int(page.compression) == 1:  # uncompressed
            return max(end, int(page.size) * page.dtype.itemsize)
        return end


def _netpbm_header(data: bytes) -> tuple[str, int, int, int, int] | None:
    """Parse a PBM/PGM/PPM header (binary P4/P5/P6 or plain P1/P2/P3).

    Parameters
    ----------
    data : bytes
        The file, or at least its header.

    Returns
    -------
    (magic, width, height, maxval, offset) or None
        ``maxval`` is 1 for PBM (P1/P4, which have none); ``offset`` is where the
        samples start (after the one whitespace byte that ends a binary header); None
        when ``data`` is no such header.
    """
    if len(data) < 2 or data[:2] not in (b"P1", b"P2", b"P3", b"P4", b"P5", b"P6"):
        return None
    fields: list[int] = []
    pos = 2
    while len(fields) < (2 if data[:2] in (b"P1", b"P4") else 3):
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
    maxval = fields[2] if len(fields) == 3 else 1
    return data[:2].decode(), fields[0], fields[1], maxval, pos + 1


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

        self.path = check_file(path, "a video file")
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


_FRAGMENTED = [
    "-movflags",
    "+frag_keyframe+empty_moov+default_base_moof",
    "-frag_duration",
    "1000000",
]


#: the frame rates :class:`VideoWriter` takes: ffmpeg refuses rates near 1e-6 and 1e300,
#: and the container of a rate above 1e4 reads back as 0 fps
MIN_FPS, MAX_FPS = 1e-3, 1e4


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
        Frames per second, in ``[MIN_FPS, MAX_FPS]`` (0.001 to 10000: rates outside
        are refused by ffmpeg or not read back).
    quality : float
        1..10 (imageio-ffmpeg's scale; higher is better).
    fragmented : bool
        MP4/MOV only: write a fragmented file (``-movflags frag_keyframe+empty_moov``,
        a fragment at least every second), playable up to the last fragment written
        even when the encoder never finishes (a full disk, a killed process); a plain
        MP4 is unreadable without its closing index.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        fps: float = 30.0,
        quality: float = 7.0,
        fragmented: bool = False,
    ) -> None:
        self.path = check_video_path(path)
        self.fps = check_real(fps, "fps", MIN_FPS, MAX_FPS)
        self.quality = check_real(quality, "quality", 1.0, 10.0)
        fragmented = check_bool(fragmented, "fragmented")
        self.fragmented = fragmented and self.path.suffix.lower() in (".mp4", ".m4v", ".mov")
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
                output_params=["-preset", "veryfast"] + (_FRAGMENTED if self.fragmented else []),
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
    A snapshot index that no frame reached (``--snapshot 100`` on a 68-frame video) is
    named in a :class:`~robopercept.errors.RoboperceptWarning` when the writer is
    closed normally (not when a ``with`` block is left by an error).

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
        self.path = check_video_path(path)
        if snapshots is None:
            snapshots = ()
        if isinstance(snapshots, (str, bytes)) or not isinstance(snapshots, Iterable):
            raise InputError(
                f"snapshots must be an iterable of frame indices (e.g. [0, 25]); got "
                f"{plain_repr(snapshots)}"
            )
        self.snapshots = {check_int(i, "snapshots (each index)", 0) for i in snapshots}
        self.writer = VideoWriter(self.path, fps=fps)
        self.written: list[str] = []
        self._saved: set[int] = set()
        self._last: int | None = None  # the largest index added
        self._checked = False

    def add(self, index: int, picture: np.ndarray) -> None:
        """Append ``picture`` (RGB uint8) to the video; save it too if ``index`` is a
        snapshot."""
        index = check_int(index, "index")
        self.writer.write(picture)
        self._last = index if self._last is None else max(self._last, index)
        if index in self.snapshots:
            png = self.path.with_name(f"{self.path.stem}_{index:06d}.png")
            write_image(png, picture)
            self.written.append(str(png))
            self._saved.add(index)

    def missed_snapshots(self) -> list[int]:
        """The snapshot indices no frame added so far had, in increasing order.

        Examples
        --------
        >>> with SnapshotVideoWriter("out.mp4", 25.0, [0, 100]) as out:  # doctest: +SKIP
        ...     out.add(0, np.zeros((48, 64, 3), np.uint8))
        >>> out.missed_snapshots()  # doctest: +SKIP
        [100]
        """
        return sorted(self.snapshots - self._saved)

    def close(self) -> None:
        """Complete the video (and list it first in :attr:`written` if it has frames),
        and warn (:class:`~robopercept.errors.RoboperceptWarning`, once) about the
        snapshots that no frame reached, such as ``--snapshot 100`` on a 68-frame
        video."""
        self._close()
        self._warn_missed()

    def _warn_missed(self) -> None:
        """The warning of :meth:`close` (at most once), attributed to the caller of
        :meth:`close` or to the ``with`` statement."""
        missed = self.missed_snapshots()
        if missed and not self._checked:
            self._checked = True
            n = self.writer.frames_written
            which = ", ".join(map(str, missed[:5])) + (", ..." if len(missed) > 5 else "")
            frames = (
                "no frame was written"
                if self._last is None
                else f"{n} {'frame was' if n == 1 else 'frames were'} written, indices up "
                f"to {self._last}"
            )
            warnings.warn(
                f"snapshot{'s' if len(missed) > 1 else ''} {which} (--snapshot) not saved: "
                f"{frames} (snapshots are 0-based frame indices)",
                RoboperceptWarning,
                stacklevel=3,
            )

    def _close(self) -> None:
        self.writer.close()
        if self.writer.frames_written and str(self.path) not in self.written:
            self.written.insert(0, str(self.path))

    def __enter__(self) -> SnapshotVideoWriter:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        # after an error or Ctrl-C the missing snapshots are not news: only complete
        self._close()
        if exc_type is None:
            self._warn_missed()
