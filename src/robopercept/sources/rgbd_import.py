"""Import RGB-D folders of other layouts into the folder layout the tracker reads.

:class:`~robopercept.sources.TUMFolderSource` (and ``robopercept plane-track --source
DIR``) reads ``rgb.txt``, ``depth.txt``, ``rgb/``, ``depth/`` (16-bit images) and a
``camera.json`` calibration. :func:`import_rgbd_folder` writes that layout from:

* a TUM RGB-D folder: ``rgb.txt`` and ``depth.txt`` (paired by nearest timestamp, within
  ``max_difference`` seconds), or an association list (``associations.txt``,
  ``associate.txt``, ``association.txt`` or ``assoc.txt``: ``t_rgb rgb/x.png t_depth
  depth/y.png`` per line, as the benchmark's ``associate.py`` writes it);
* ``color/`` (or ``rgb/``, ``colour/``) and ``depth/`` subfolders, paired by file name
  without extension (``color/1.png`` with ``depth/1.pgm``);
* image pairs in one folder: ``X_depth.EXT`` with ``X_color``, ``X_rgb``, ``X_colour``
  (``_``, ``-`` or no separator) or plain ``X`` (``1.png`` with ``1_depth.png``,
  ``NYU_color.ppm`` with ``NYU_depth.pgm``, ``frame_rgb.tiff`` with ``frame_depth.tiff``).

Depth images may be 16-bit PNG, 16-bit PGM, 16-bit or floating-point TIFF. A raw value
``v`` is decoded to metres by the depth encoding:

* ``linear`` (TUM, Kinect/PCL, RealSense, most datasets): ``z = v / u`` with ``u`` the
  depth units per metre (``depth_scale``; TUM 5000, millimetres 1000); ``v <= 0`` or
  non-finite means no measurement;
* ``sun`` (SUN RGB-D): the 16-bit value rotated right by 3 bits is millimetres,
  ``z = ((v >> 3) | (v << 13) mod 2^16) / 1000`` (the SUN RGB-D toolbox's
  ``read3dPoints``; Open3D's ``create_from_sun_format`` without its 7 m cut-off);
* ``nyu`` (NYU Depth v2 raw PGM): ``d`` = ``v`` with its two bytes swapped (the raw
  files store the Kinect disparity little-endian), ``z = 351.3 / (1092.5 - d)`` clipped
  to [0, 10] m (the NYU toolbox's ``depth_rel2depth_abs``; Open3D's
  ``create_from_nyu_format``).

The output depth is uint16 with ``camera.json``'s ``depth_scale`` (metres per unit, the
inverse of ``u``): integer ``linear`` input keeps its values and scale exactly
(``depth_scale = 1 / u``); floating-point and ``nyu`` input is stored in TUM's units
(1/5000 m), ``sun`` in millimetres. Values beyond the 16-bit range become 0 (no
measurement) and are counted.

The depth images are taken to be registered to the colour images (the same pixel grid,
as TUM's and the Kinect grabbers' are): one camera model serves both, and
``T_color_depth`` is the identity.
"""

from __future__ import annotations

import fnmatch
import itertools
import os
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import (
    as_path,
    check_bool,
    check_numeric,
    check_real,
    check_reals,
    plain_repr,
)
from robopercept.depth.rgbd import DepthScaleWarning, plausible_depth
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import read_text
from robopercept.geometry import CameraIntrinsics
from robopercept.imaging.io import IMAGE_EXTENSIONS, contained_path, read_image
from robopercept.sources.frames import RGBDFrame
from robopercept.sources.tum import (
    associate_timestamps,
    camera_dict,
    read_timestamp_list,
    write_tum_folder,
)

__all__ = [
    "ASSOCIATION_FILES",
    "CAMERA_PRESETS",
    "DEPTH_ENCODINGS",
    "RGBDImportResult",
    "RGBDPair",
    "camera_preset",
    "decode_depth",
    "depth_to_units",
    "find_rgbd_pairs",
    "import_rgbd_folder",
]

CAMERA_PRESETS: dict[str, CameraIntrinsics] = {
    "fr1": CameraIntrinsics(
        640,
        480,
        517.3,
        516.5,
        318.6,
        255.3,
        "brown_conrady",
        (0.2624, -0.9531, -0.0054, 0.0026, 1.1633),
    ),
    "fr2": CameraIntrinsics(
        640,
        480,
        520.9,
        521.0,
        325.1,
        249.7,
        "brown_conrady",
        (0.2312, -0.7849, -0.0033, -0.0001, 0.9172),
    ),
    "fr3": CameraIntrinsics(640, 480, 535.4, 539.2, 320.1, 247.6),
    "ros-default": CameraIntrinsics(640, 480, 525.0, 525.0, 319.5, 239.5),
}
"""The TUM RGB-D benchmark's published colour-camera calibrations (640x480; fr1 and fr2
with OpenCV's ``k1, k2, p1, p2, k3`` as a Brown-Conrady model), and the ROS default
that TUM recommends for its pre-registered depth images."""

DEPTH_ENCODINGS = ("linear", "sun", "nyu")
"""How raw depth values encode distance (see the module docstring)."""

ASSOCIATION_FILES = ("associations.txt", "associate.txt", "association.txt", "assoc.txt")
"""Names under which a TUM association list is recognised."""

_COLOR_DIRS = ("color", "rgb", "colour")
_COLOR_WORDS = ("color", "rgb", "colour")
_DEPTH_STEM = re.compile(r"^(?P<key>.*?)[_\-.]?depth$", re.IGNORECASE)
_FLOAT_UNITS = 5000.0  # output units per metre for floating-point or nyu depth (TUM's)


def camera_preset(name: str) -> CameraIntrinsics:
    """The camera model of a named preset.

    Parameters
    ----------
    name : {'fr1', 'fr2', 'fr3', 'ros-default'}
        TUM RGB-D Freiburg 1, 2, 3 colour cameras (calibration published by TUM) or the
        ROS default ``fx = fy = 525, cx = 319.5, cy = 239.5``.

    Returns
    -------
    CameraIntrinsics
        For 640x480 images.

    Raises
    ------
    InputError
        An unknown name, listing the presets.

    Examples
    --------
    >>> k = camera_preset("fr3")
    >>> (k.fx, k.fy, k.cx, k.cy, k.model)
    (535.4, 539.2, 320.1, 247.6, 'none')
    """
    if not isinstance(name, str) or name not in CAMERA_PRESETS:
        raise InputError(
            f"unknown camera preset {plain_repr(name)} (--preset); choose from "
            f"{', '.join(CAMERA_PRESETS)}, or give --intrinsics fx,fy,cx,cy"
        )
    return CAMERA_PRESETS[name]


def _check_encoding(encoding: str) -> None:
    """InputError unless ``encoding`` is one of :data:`DEPTH_ENCODINGS`."""
    if not isinstance(encoding, str) or encoding not in DEPTH_ENCODINGS:
        raise InputError(
            f"depth encoding must be one of {', '.join(DEPTH_ENCODINGS)} (--depth-encoding); "
            f"got {plain_repr(encoding)}"
        )


def _units(units_per_metre: float) -> float:
    """``units_per_metre`` as a float after checking that it is a real number > 0."""
    return check_real(
        units_per_metre, "depth units per metre (--depth-scale)", 0.0, low_inclusive=False
    )


def decode_depth(
    raw: np.ndarray, encoding: str = "linear", units_per_metre: float = 5000.0
) -> np.ndarray:
    """Raw depth values to metres.

    Parameters
    ----------
    raw : (H, W) ndarray
        Integer or floating-point depth as read from the file (``sun`` and ``nyu`` need
        16-bit values).
    encoding : {'linear', 'sun', 'nyu'}
        ``linear``: ``z = v / units_per_metre``; ``sun``: ``z = rotr16(v, 3) / 1000``;
        ``nyu``: ``z = clip(351.3 / (1092.5 - bswap16(v)), 0, 10)`` (module docstring).
    units_per_metre : float
        ``linear`` only: raw units per metre (TUM 5000, millimetres 1000).

    Returns
    -------
    (H, W) float64 ndarray
        Metres; 0 where there is no measurement (``v <= 0``, NaN or inf).

    Raises
    ------
    InputError
        Not a single-channel image, an unknown encoding, ``units_per_metre <= 0``, or
        ``sun``/``nyu`` data that is not 16-bit.

    Examples
    --------
    >>> decode_depth(np.array([[5000, 0]], np.uint16)).tolist()
    [[1.0, 0.0]]
    >>> decode_depth(np.array([[8000]], np.uint16), "sun").tolist()  # 8000 = 1000 << 3
    [[1.0]]
    """
    raw = np.asarray(raw)
    if raw.ndim != 2:
        raise InputError(f"depth must be a single-channel (H, W) image; got shape {raw.shape}")
    if raw.dtype.kind not in "buif":
        raise InputError(f"depth must be numeric; got dtype {raw.dtype}")
    _check_encoding(encoding)
    if encoding == "linear":
        units_per_metre = _units(units_per_metre)
        z = raw.astype(np.float64) / units_per_metre
        z[~np.isfinite(z) | (z < 0)] = 0.0
        return z
    if raw.dtype.kind not in "ui" or (raw.size and (raw.min() < 0 or raw.max() > 65535)):
        raise InputError(
            f"--depth-encoding {encoding} needs 16-bit integer depth; got {raw.dtype} "
            "(use --depth-encoding linear)"
        )
    v = raw.astype(np.uint16)
    if encoding == "sun":
        mm = (v >> np.uint16(3)) | (v << np.uint16(13))
        return mm.astype(np.float64) / 1000.0
    d = v.byteswap().astype(np.float64)
    return np.clip(351.3 / (1092.5 - d), 0.0, 10.0)


def depth_to_units(metres: np.ndarray, units_per_metre: float) -> tuple[np.ndarray, int]:
    """Metres to uint16 depth units, ``D = round(z * units_per_metre)``.

    Parameters
    ----------
    metres : (H, W) float ndarray
        0 = no measurement.
    units_per_metre : float

    Returns
    -------
    depth : (H, W) uint16 ndarray
        0 where ``z <= 0``, non-finite, or ``D > 65535``.
    out_of_range : int
        How many measured pixels were beyond 65535 units and set to 0.

    Examples
    --------
    >>> d, n = depth_to_units(np.array([[1.0, 20.0, 0.0]]), 5000)
    >>> d.tolist(), n
    ([[5000, 0, 0]], 1)
    """
    units = _units(units_per_metre)
    z = check_numeric(metres, "metres")
    with np.errstate(over="ignore", invalid="ignore"):
        scaled = np.rint(z * units)
        measured = np.isfinite(z) & (z > 0)
        # a finite depth whose units overflow to inf is out of range too
        over = measured & ~(scaled <= 65535)
        scaled[~measured | over | (scaled < 0)] = 0.0
    return scaled.astype(np.uint16), int(over.sum())


@dataclass(frozen=True)
class RGBDPair:
    """One colour image and the depth image taken with it.

    Attributes
    ----------
    name : str
        The pair's name (the depth file's name without extension and depth suffix);
        ``match`` patterns are tested against it.
    color, depth : Path
    timestamp : float or None
        Seconds, when the layout carries it (TUM lists, names such as
        ``1305031102.175304``); None for numbered frames.
    """

    name: str
    color: Path
    depth: Path
    timestamp: float | None = None


def _natural_key(text: str) -> list[Any]:
    return [(0, int(t), "") if t.isdigit() else (1, 0, t) for t in re.split(r"(\d+)", text)]


def _name_time(name: str) -> float | None:
    """A timestamp from a name like ``1305031102.175304``; None for ``1`` or ``NYU``."""
    if "." not in name:
        return None
    try:
        return float(name)
    except ValueError:
        return None


def _images(folder: Path) -> list[Path]:
    return sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS),
        key=lambda p: _natural_key(p.name),
    )


def _association_pairs(path: Path, allow_outside: bool) -> list[RGBDPair]:
    """The pairs of a TUM association list, each file checked by
    :func:`~robopercept.imaging.io.contained_path` (issue 47 R43)."""
    expected = "expected 'timestamp rgb_file timestamp depth_file' lines"
    text = read_text(path, expected)  # issue 47 R48
    pairs = []
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        try:
            t1, f1, t2, f2 = float(parts[0]), parts[1], float(parts[2]), parts[3]
        except (IndexError, ValueError):
            raise FileFormatError(
                f"{path}:{n}: expected 'timestamp rgb_file timestamp depth_file'; got {line!r}"
            ) from None
        if not (np.isfinite(t1) and np.isfinite(t2)):
            raise FileFormatError(f"{path}:{n}: timestamps must be finite numbers; got {line!r}")
        for name, col in ((f1, 2), (f2, 4)):
            contained_path(path.parent, name, f"{path}:{n}: file (column {col})", allow_outside)
        first_is_depth = "depth" in f1.lower()
        if first_is_depth == ("depth" in f2.lower()):
            raise FileFormatError(
                f"{path}:{n}: cannot tell the depth file from the colour file (exactly one "
                f"path should contain 'depth'); got {f1!r} and {f2!r}"
            )
        (td, fd), fc = ((t1, f1), f2) if first_is_depth else ((t2, f2), f1)
        pairs.append(RGBDPair(Path(fd).stem, path.parent / fc, path.parent / fd, td))
    return pairs


def _subfolder_pairs(color_dir: Path, depth_dir: Path) -> list[RGBDPair]:
    colors = {p.stem: p for p in _images(color_dir)}
    pairs = []
    for d in _images(depth_dir):
        if d.stem in colors:
            pairs.append(RGBDPair(d.stem, colors[d.stem], d, _name_time(d.stem)))
    return pairs


def _flat_pairs(folder: Path) -> list[RGBDPair]:
    images = _images(folder)
    by_stem: dict[str, Path] = {}
    for p in images:
        by_stem.setdefault(p.stem.lower(), p)
    pairs = []
    for d in images:
        m = _DEPTH_STEM.match(d.stem)
        if not m:
            continue
        key = m.group("key")
        candidates = [f"{key}{sep}{w}" for w in _COLOR_WORDS for sep in ("_", "-", "")]
        if key:
            candidates.append(key)
        color = next((by_stem[c.lower()] for c in candidates if c.lower() in by_stem), None)
        if color is not None and color != d:
            pairs.append(RGBDPair(key or d.stem, color, d, _name_time(key)))
    return pairs


def find_rgbd_pairs(
    src: str | os.PathLike[str],
    *,
    match: str | None = None,
    max_difference: float = 0.02,
    allow_outside: bool = False,
) -> tuple[str, list[RGBDPair]]:
    """Find the colour/depth pairs of a folder (the layouts of the module docstring).

    The layouts are tried in this order: an association list, ``rgb.txt`` +
    ``depth.txt``, colour and depth subfolders, image pairs in the folder itself.

    Parameters
    ----------
    src : str or path-like
        The folder.
    match : str, optional
        Keep only the pairs whose name matches this shell pattern (``fnmatch``, e.g.
        ``"TUM*"``).
    max_difference : float
        ``rgb.txt``/``depth.txt``: largest colour/depth timestamp gap, seconds.
    allow_outside : bool, default False
        Take files that an association list, ``rgb.txt`` or ``depth.txt`` places outside
        ``src`` (``../../x.png``, an absolute path): refused by default, as a folder from
        elsewhere could name any file on the machine
        (:func:`~robopercept.imaging.io.contained_path`).

    Returns
    -------
    layout : str
        ``"tum-associations"``, ``"tum-lists"``, ``"subfolders"`` or ``"pairs"``.
    pairs : list of RGBDPair
        In time order (lists) or natural name order (``2`` before ``10``).

    Raises
    ------
    FileFormatError
        ``src`` is not a folder, no pair is found (the message lists the layouts), a
        list that is not UTF-8 text or has a bad line, or a listed file outside ``src``
        while ``allow_outside`` is False (the message names the line).
    """
    folder = as_path(src, "SRC_DIR")
    allow_outside = check_bool(allow_outside, "allow_outside (--allow-outside-paths)")
    if match is not None and not isinstance(match, str):
        raise InputError(
            f"match (--match) must be a shell pattern string such as 'TUM*'; got "
            f"{plain_repr(match)}"
        )
    max_difference = check_real(max_difference, "max_difference (seconds)", 0.0)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder (SRC_DIR must be an RGB-D folder)")
    layout, pairs = "pairs", []
    assoc = next((folder / n for n in ASSOCIATION_FILES if (folder / n).is_file()), None)
    if assoc is not None:
        layout, pairs = "tum-associations", _association_pairs(assoc, allow_outside)
    elif (folder / "rgb.txt").is_file() and (folder / "depth.txt").is_file():
        triples = associate_timestamps(
            read_timestamp_list(folder / "depth.txt", allow_outside=allow_outside),
            read_timestamp_list(folder / "rgb.txt", allow_outside=allow_outside),
            max_difference,
        )
        layout = "tum-lists"
        pairs = [RGBDPair(Path(d).stem, folder / c, folder / d, t) for t, d, c in triples]
    else:
        color_dir = next((folder / n for n in _COLOR_DIRS if (folder / n).is_dir()), None)
        if color_dir is not None and (folder / "depth").is_dir():
            layout, pairs = "subfolders", _subfolder_pairs(color_dir, folder / "depth")
        if not pairs:
            layout, pairs = "pairs", _flat_pairs(folder)
    if match is not None:
        pairs = [p for p in pairs if fnmatch.fnmatch(p.name, match)]
    if not pairs:
        what = f" matching {match!r} (--match)" if match is not None else ""
        raise FileFormatError(
            f"{folder}: no colour/depth image pairs{what} found; rgbd-import reads rgb.txt + "
            "depth.txt (TUM), an associations.txt list, color/ (or rgb/) and depth/ "
            "subfolders with the same file names, or pairs NAME_color.EXT / NAME_depth.EXT "
            "(also NAME_rgb, NAME.EXT) in the folder"
        )
    return layout, pairs


@dataclass(frozen=True)
class RGBDImportResult:
    """What :func:`import_rgbd_folder` wrote.

    Attributes
    ----------
    out_dir : Path
    layout : str
        The layout found in the source folder (:func:`find_rgbd_pairs`).
    frames : int
        Pairs written.
    skipped : tuple of (str, str)
        Name and reason of every pair that could not be read.
    camera : CameraIntrinsics
        The model written for both cameras.
    depth_scale : float
        Metres per output depth unit, as written to ``camera.json``.
    depth_range_m : (float, float, float)
        Minimum, median and maximum measured depth of the first frame, metres (a check
        on the depth scale).
    out_of_range : int
        Depth pixels beyond the 16-bit range, written as 0.
    files : tuple of str
        The files and folders written, relative to ``out_dir``.
    """

    out_dir: Path
    layout: str
    frames: int
    skipped: tuple[tuple[str, str], ...]
    camera: CameraIntrinsics
    depth_scale: float
    depth_range_m: tuple[float, float, float]
    out_of_range: int
    files: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready types (``--json``)."""
        k = self.camera
        return {
            "out_dir": str(self.out_dir),
            "layout": self.layout,
            "frames": self.frames,
            "skipped": [{"pair": n, "reason": r} for n, r in self.skipped],
            "camera": camera_dict(k),
            "depth_scale": self.depth_scale,
            "depth_range_m": list(self.depth_range_m),
            "out_of_range_pixels": self.out_of_range,
            "files": list(self.files),
        }


def _camera(
    preset: str | None, intrinsics: tuple[float, ...] | None, width: int, height: int
) -> CameraIntrinsics:
    if (preset is None) == (intrinsics is None):
        raise InputError(
            "give the camera: --preset fr1|fr2|fr3|ros-default or --intrinsics fx,fy,cx,cy "
            "(exactly one)"
        )
    if preset is not None:
        k = camera_preset(preset)
        if (k.width, k.height) != (width, height):
            raise InputError(
                f"the {preset} preset is for {k.width}x{k.height} images; these are "
                f"{width}x{height}: give --intrinsics fx,fy,cx,cy for them"
            )
        return k
    assert intrinsics is not None
    fx, fy, cx, cy = _check_intrinsics(intrinsics)
    return CameraIntrinsics(width, height, fx, fy, cx, cy)


def _check_intrinsics(intrinsics: Any) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` as floats after checking four finite numbers, focals > 0."""
    fx, fy, cx, cy = (float(v) for v in check_reals(intrinsics, "--intrinsics fx,fy,cx,cy", 4))
    if not (fx > 0 and fy > 0):
        raise InputError(f"--intrinsics fx,fy (pixels) must be > 0; got {fx:g}, {fy:g}")
    return fx, fy, cx, cy


def _read_pair(pair: RGBDPair) -> tuple[np.ndarray, np.ndarray]:
    """(depth, colour) of a pair; FileFormatError with the reason if unusable."""
    depth = read_image(pair.depth)
    color = read_image(pair.color, mode="rgb")
    if depth.ndim != 2:
        raise FileFormatError(f"{pair.depth}: depth must be single-channel; got {depth.shape}")
    if depth.dtype == np.uint8:
        raise FileFormatError(f"{pair.depth}: 8-bit depth (a picture, not a depth map?)")
    if color.dtype != np.uint8:
        raise FileFormatError(f"{pair.color}: colour must be 8-bit; got {color.dtype}")
    if depth.shape != color.shape[:2]:
        raise FileFormatError(
            f"{pair.name}: depth is {depth.shape[1]}x{depth.shape[0]} but colour is "
            f"{color.shape[1]}x{color.shape[0]}; rgbd-import needs depth registered to the "
            "colour image (same size)"
        )
    return depth, color


def import_rgbd_folder(
    src: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    preset: str | None = None,
    intrinsics: tuple[float, ...] | None = None,
    depth_scale: float | None = None,
    depth_encoding: str = "linear",
    match: str | None = None,
    fps: float = 30.0,
    max_difference: float = 0.02,
    progress: bool = False,
    allow_outside: bool = False,
) -> RGBDImportResult:
    """Write an RGB-D folder of another layout as a folder the plane tracker reads.

    Finds the pairs (:func:`find_rgbd_pairs`), decodes each depth image to metres
    (:func:`decode_depth`), stores it as uint16 (:func:`depth_to_units`) and writes
    ``rgb/``, ``depth/`` (PNG), ``rgb.txt``, ``depth.txt`` and ``camera.json`` through
    :func:`~robopercept.sources.write_tum_folder`. ``camera.json`` gets the same camera
    for depth and colour, ``T_color_depth = I`` and ``depth_scale`` in metres per unit.

    Parameters
    ----------
    src, out : str or path-like
        Source and output folders (they must differ).
    preset : {'fr1', 'fr2', 'fr3', 'ros-default'}, optional
        The camera (:data:`CAMERA_PRESETS`); exactly one of ``preset`` and
        ``intrinsics``.
    intrinsics : (fx, fy, cx, cy), optional
        Pixels, no lens distortion.
    depth_scale : float, optional
        ``linear`` encoding: raw depth units per metre (default 5000, TUM's; 1000 for
        millimetres). Not used by ``sun`` and ``nyu``, which fix their units.
    depth_encoding : {'linear', 'sun', 'nyu'}
    match : str, optional
        Import only the pairs whose name matches this shell pattern.
    fps : float
        Timestamps ``i / fps`` for layouts without timestamps.
    max_difference : float
        TUM lists: largest colour/depth timestamp gap, seconds.
    progress : bool
        Show progress on stderr (:func:`robopercept.progress.progress_bar`).
    allow_outside : bool, default False
        Import images that the source's lists (``associations.txt``, ``rgb.txt``,
        ``depth.txt``) place outside ``src``; refused by default (``rgbd-import
        --allow-outside-paths``), so that a folder from elsewhere cannot have any file
        of the machine copied into ``out``.

    Returns
    -------
    RGBDImportResult

    Raises
    ------
    FileFormatError
        ``src`` missing or without pairs, no pair readable, a list that is not UTF-8
        text, or a listed file outside ``src`` (without ``allow_outside``).
    InputError
        Bad camera, depth scale or encoding; ``out`` equal to ``src``.

    Notes
    -----
    A pair that cannot be decoded, or whose size differs from the first pair's, is
    skipped with a warning and listed in ``skipped``. Nothing is written before the
    first pair has been read, so a failed import leaves no output.
    """
    from robopercept.progress import progress_bar

    src_p, out_p = as_path(src, "SRC_DIR"), as_path(out, "OUT_DIR")
    _check_encoding(depth_encoding)
    if depth_scale is not None and depth_encoding != "linear":
        raise InputError(
            f"--depth-scale applies to --depth-encoding linear only; {depth_encoding} fixes "
            "its own units"
        )
    units = 5000.0 if depth_scale is None else _units(depth_scale)
    fps = check_real(fps, "--fps", 0.0, low_inclusive=False)
    progress = check_bool(progress, "progress")
    if preset is not None:
        camera_preset(preset)
    if intrinsics is not None:
        _check_intrinsics(intrinsics)
    layout, pairs = find_rgbd_pairs(
        src_p, match=match, max_difference=max_difference, allow_outside=allow_outside
    )
    if out_p.resolve() == src_p.resolve():
        raise InputError(f"OUT_DIR must differ from SRC_DIR ({src_p}): give a new folder")
    stamps = [p.timestamp for p in pairs]
    times = [t for t in stamps if t is not None]
    if len(times) < len(pairs) or len({f"{t:.6f}" for t in times}) < len(times):
        times = [i / fps for i in range(len(pairs))]  # no (distinct) timestamps

    skipped: list[tuple[str, str]] = []
    out_of_range = 0
    state: dict[str, Any] = {}

    def skip(pair: RGBDPair, reason: str) -> None:
        warnings.warn(f"skipping {pair.name}: {reason}", stacklevel=3)
        skipped.append((pair.name, reason))

    def frames() -> Iterator[RGBDFrame]:
        nonlocal out_of_range
        bar = progress_bar(pairs, unit="pair", desc="importing", disable=not progress)
        for index, (pair, t) in enumerate(zip(bar, times, strict=True)):
            try:
                raw, color = _read_pair(pair)
                metres = decode_depth(raw, depth_encoding, units)
            except (FileFormatError, InputError) as exc:
                skip(pair, str(exc))
                continue
            if "camera" not in state:
                h, w = raw.shape
                state["camera"] = _camera(preset, intrinsics, w, h)
                if depth_encoding == "sun":
                    state["units"] = 1000.0  # millimetres, kept exactly
                elif depth_encoding == "nyu" or raw.dtype.kind == "f":
                    state["units"] = _FLOAT_UNITS
                else:
                    state["units"] = units  # integer depth kept exactly
                valid = metres[metres > 0]
                state["range"] = (
                    tuple(float(v) for v in np.percentile(valid, [0, 50, 100]))
                    if valid.size
                    else (0.0, 0.0, 0.0)
                )
                if not plausible_depth(state["range"][1]):
                    warnings.warn(
                        f"{pair.name}: median depth {state['range'][1]:.3g} m is implausible "
                        f"for an RGB-D camera: check --depth-scale ({units:g} units per "
                        "metre) and --depth-encoding",
                        DepthScaleWarning,
                        stacklevel=3,
                    )
            k: CameraIntrinsics = state["camera"]
            if raw.shape != (k.height, k.width):
                skip(pair, f"{raw.shape[1]}x{raw.shape[0]}, not {k.width}x{k.height} as the first")
                continue
            depth, n_over = depth_to_units(metres, state["units"])
            out_of_range += n_over
            yield RGBDFrame(index, float(t), depth, color, k, k, np.eye(4), 1.0 / state["units"])
        bar.close()

    it = frames()
    first = next(it, None)
    if first is None:
        raise FileFormatError(
            f"{src_p}: none of the {len(pairs)} pairs could be read (first: {skipped[0][1]})"
        )

    written = 0

    def counted() -> Iterator[RGBDFrame]:
        nonlocal written
        for f in itertools.chain([first], it):
            written += 1
            yield f

    write_tum_folder(out_p, counted())
    return RGBDImportResult(
        out_dir=out_p,
        layout=layout,
        frames=written,
        skipped=tuple(skipped),
        camera=state["camera"],
        depth_scale=1.0 / state["units"],
        depth_range_m=state["range"],
        out_of_range=out_of_range,
        files=("camera.json", "rgb.txt", "depth.txt", "rgb/", "depth/"),
    )
