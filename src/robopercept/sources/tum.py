"""RGB-D sequences in the TUM RGB-D folder layout, with a ``camera.json`` calibration.

Layout (the TUM benchmark's, plus two files of ours)::

    rgb.txt        "timestamp rgb/<name>.png" per line ('#' comments)
    depth.txt      "timestamp depth/<name>.png" per line (16-bit PNG, PGM or TIFF)
    rgb/, depth/   the images
    camera.json    {"depth": {"width", "height", "fx", "fy", "cx", "cy", "model", "coeffs"},
                    "color": {same}, "T_color_depth": 4x4 list, "depth_scale": m per unit}
    planes.csv     optional ground truth: "frame,nx,ny,nz,d" (n . x = d on the plane;
                   frame: the position in the lists, from 0)

``robopercept rgbd-import`` (:mod:`robopercept.sources.rgbd_import`) writes this layout
from other RGB-D folders; docs/tracking.md describes ``camera.json`` field by field.

Colour and depth images are associated by nearest timestamp (each depth image to the
closest colour image within ``max_difference`` seconds), like the benchmark's
``associate.py``.
"""

from __future__ import annotations

import csv
import io
import json
import os
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_bool, check_real
from robopercept.depth.rgbd import check_intrinsics
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import parse_json
from robopercept.geometry import CameraIntrinsics
from robopercept.imaging.io import (
    check_png_compression,
    contained_path,
    read_image,
    write_image,
)
from robopercept.sources.frames import RGBDFrame

__all__ = [
    "CAMERA_JSON_HELP",
    "TUMFolderSource",
    "associate_timestamps",
    "camera_dict",
    "read_camera_json",
    "read_timestamp_list",
    "write_tum_folder",
]

CAMERA_JSON_HELP = (
    "camera.json needs depth, color, T_color_depth and depth_scale: 'depth' and 'color' "
    "cameras (each width, height, fx, fy, cx, cy in pixels; optional model and coeffs), "
    "'T_color_depth' (4x4, depth frame to colour frame, metres) and 'depth_scale' "
    "(metres per depth unit: 0.0002 for TUM's 5000 units per metre, 0.001 for "
    "millimetres); write it with `robopercept rgbd-import SRC_DIR OUT_DIR --preset "
    "fr1|fr2|fr3|ros-default` (or --intrinsics fx,fy,cx,cy), see docs/tracking.md"
)
"""The schema of ``camera.json`` in one line, with the command that writes it: the
remedy every camera.json error ends with."""


_NAME_MAX = 255  # bytes per path component (Linux, macOS, Windows)
_PATH_MAX = 4095  # bytes per path (Linux)


def _intrinsics(d: dict[str, Any], what: str, path: Path) -> CameraIntrinsics:
    try:
        return CameraIntrinsics(
            int(d["width"]),
            int(d["height"]),
            float(d["fx"]),
            float(d["fy"]),
            float(d["cx"]),
            float(d["cy"]),
            d.get("model", "none"),
            tuple(d.get("coeffs", (0.0,) * 5)),
        )
    except (KeyError, TypeError, ValueError, OverflowError, InputError) as exc:
        # OverflowError: int(Infinity), which json.loads accepts
        raise FileFormatError(f"{path}: bad '{what}' camera ({exc}); {CAMERA_JSON_HELP}") from None


def read_camera_json(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a ``camera.json`` calibration.

    The file holds ``{"depth": CAM, "color": CAM, "T_color_depth": 4x4 list,
    "depth_scale": float}`` with ``CAM = {"width", "height", "fx", "fy", "cx", "cy"}`` in
    pixels plus optional ``"model"`` (a :class:`CameraIntrinsics` lens model, default
    ``"none"``) and ``"coeffs"`` (``k1, k2, p1, p2, k3``). ``T_color_depth`` maps
    depth-frame points into the colour frame (metres); ``depth_scale`` is metres per
    raw depth unit, so ``z = depth_scale * D`` (RealSense's convention; the inverse of
    TUM's and Open3D's "units per metre").

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    dict
        ``{"depth": CameraIntrinsics, "color": CameraIntrinsics, "T_color_depth": (4, 4)
        ndarray, "depth_scale": float}``.

    Raises
    ------
    FileFormatError
        Missing, unreadable or incomplete file, not UTF-8 JSON, or nested deeper than
        :data:`~robopercept.fileio.MAX_NESTING` levels; the message ends with
        :data:`CAMERA_JSON_HELP` (the fields and ``robopercept rgbd-import``).
    InputError
        ``path`` cannot name a file (:func:`~robopercept._checks.as_path`).
    """
    p = as_path(path, "the path of camera.json")
    try:
        if not p.is_file():
            raise FileFormatError(f"{p}: missing; {CAMERA_JSON_HELP}")
        text = p.read_bytes()
    except FileFormatError:
        raise
    except OSError as exc:
        raise FileFormatError(
            f"{p}: cannot read ({exc.strerror or exc}); {CAMERA_JSON_HELP}"
        ) from None
    try:  # the one reading policy: not UTF-8, not JSON, nested too deep
        raw = parse_json(text, str(p))
    except FileFormatError as exc:
        raise FileFormatError(f"{exc}; {CAMERA_JSON_HELP}") from None
    try:
        T = np.asarray(raw["T_color_depth"], dtype=np.float64)
        scale = float(raw["depth_scale"])
        out = {
            "depth": _intrinsics(raw["depth"], "depth", p),
            "color": _intrinsics(raw["color"], "color", p),
            "T_color_depth": T,
            "depth_scale": scale,
        }
    except (KeyError, TypeError, ValueError) as exc:
        raise FileFormatError(f"{p}: field {exc} missing or wrong; {CAMERA_JSON_HELP}") from None
    if T.shape != (4, 4) or not np.isfinite(T).all() or not (0 < scale < np.inf):
        raise FileFormatError(
            f"{p}: T_color_depth must be a 4x4 list of finite numbers and depth_scale a "
            f"finite number > 0; {CAMERA_JSON_HELP}"
        )
    return out


def read_timestamp_list(
    path: str | os.PathLike[str], *, allow_outside: bool = False
) -> list[tuple[float, str]]:
    """Read a TUM list such as ``rgb.txt``: ``timestamp file`` per line.

    Blank lines and ``#`` comments are skipped; columns after the second are ignored.
    A file that leads outside the list's folder (``../../x.png``, an absolute path) is
    refused unless ``allow_outside`` (:func:`~robopercept.imaging.io.contained_path`):
    a folder from elsewhere cannot make a reader open files outside it.

    Parameters
    ----------
    path : str or path-like
    allow_outside : bool, default False
        Take files outside the list's folder (a list you trust).

    Returns
    -------
    list of (float, str)
        Timestamp (seconds) and the file path relative to the list's folder.

    Raises
    ------
    FileFormatError
        A missing file (naming ``robopercept rgbd-import`` for other layouts), a line
        that is not ``timestamp file``, or a file outside the folder (naming the line).
    InputError
        ``path`` cannot name a file (:func:`~robopercept._checks.as_path`), or
        ``allow_outside`` is not a bool.
    """
    path = as_path(path, "the path of the timestamp list")
    allow_outside = check_bool(allow_outside, "allow_outside")
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileFormatError(
            f"{path}: missing (a tracker folder needs rgb.txt, depth.txt and camera.json; "
            "convert other layouts with `robopercept rgbd-import SRC_DIR OUT_DIR`)"
        ) from None
    except UnicodeDecodeError as exc:
        raise FileFormatError(
            f"{path}: not UTF-8 text (byte {exc.start}): expected 'timestamp file' lines"
        ) from None
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        try:
            t = float(parts[0])
            name = parts[1]
        except (IndexError, ValueError):
            raise FileFormatError(f"{path}:{n}: expected 'timestamp file', got {line!r}") from None
        if not np.isfinite(t):
            raise FileFormatError(f"{path}:{n}: timestamp {parts[0]!r} is not a finite number")
        longest = max(len(c.encode("utf-8")) for c in Path(name).parts) if name else 0
        if longest > _NAME_MAX or len(name.encode("utf-8")) > _PATH_MAX:
            raise FileFormatError(
                f"{path}:{n}: file name too long ({len(name.encode('utf-8'))} bytes, a "
                f"name may have {_NAME_MAX} per folder level): expected 'timestamp file'"
            )
        contained_path(path.parent, name, f"{path}:{n}: file", allow_outside)
        rows.append((t, name))
    return rows


def associate_timestamps(
    depth: list[tuple[float, str]], rgb: list[tuple[float, str]], max_difference: float
) -> list[tuple[float, str, str]]:
    """Pair each depth image with the colour image nearest in time.

    For each depth entry ``(t, d)`` the colour entry ``(t_c, c)`` minimising
    ``|t - t_c|`` is taken if ``|t - t_c| <= max_difference``; otherwise the depth image
    is left out. Unlike the TUM benchmark's ``associate.py`` a colour image may serve
    two depth images (it does not remove matched entries).

    Parameters
    ----------
    depth, rgb : list of (float, str)
        ``(timestamp, file)`` as :func:`read_timestamp_list` returns them.
    max_difference : float
        Largest gap, seconds.

    Returns
    -------
    list of (float, str, str)
        ``(depth timestamp, depth file, colour file)`` in the order of ``depth``.

    Examples
    --------
    >>> associate_timestamps([(1.0, "d1"), (2.0, "d2")], [(1.01, "c1"), (5.0, "c5")], 0.02)
    [(1.0, 'd1', 'c1')]
    """
    max_difference = check_real(max_difference, "max_difference (seconds)", 0.0)
    if not rgb:
        return []
    t_rgb = np.array([t for t, _ in rgb])
    order = np.argsort(t_rgb)
    t_sorted = t_rgb[order]
    out = []
    for t, dname in depth:
        i = int(np.searchsorted(t_sorted, t))
        best = min(
            (j for j in (i - 1, i) if 0 <= j < len(t_sorted)), key=lambda j: abs(t_sorted[j] - t)
        )
        if abs(t_sorted[best] - t) <= max_difference:
            out.append((t, dname, rgb[order[best]][1]))
    return out


class TUMFolderSource:
    """Frames of a TUM-layout folder (see the module docstring).

    Iterating yields :class:`RGBDFrame` objects. A frame whose image is missing, cannot
    be decoded, or whose size disagrees with ``camera.json`` is skipped with a warning
    naming the file and recorded in :attr:`skipped` (so one bad frame does not end a
    run). A folder that vanishes while it is read raises :class:`FileFormatError`
    naming it: that cannot be skipped.

    Parameters
    ----------
    path : str or path-like
    max_difference : float
        Largest colour/depth timestamp gap, seconds.
    allow_outside : bool, default False
        Take images that ``rgb.txt`` / ``depth.txt`` place outside the folder
        (:func:`read_timestamp_list`); refused by default.

    Raises
    ------
    FileFormatError
        Not a folder, or a bad ``camera.json`` or list (an entry outside the folder
        included).

    Attributes
    ----------
    camera : dict
        The parsed ``camera.json``.
    planes : dict of int -> (n, d)
        Ground truth from ``planes.csv`` (empty if absent).
    skipped : list of (int, str)
        Frame index and reason of every skipped frame.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        max_difference: float = 0.02,
        *,
        allow_outside: bool = False,
    ) -> None:
        self.path = as_path(path, "the TUM folder")
        max_difference = check_real(max_difference, "max_difference (seconds)", 0.0)
        allow_outside = check_bool(allow_outside, "allow_outside")
        try:
            is_dir = self.path.is_dir()
        except OSError as exc:  # ENAMETOOLONG, ELOOP, EACCES
            raise FileFormatError(f"{self.path}: cannot open ({exc.strerror or exc})") from None
        if not is_dir:
            raise FileFormatError(f"{self.path}: not a folder")
        self.camera = read_camera_json(self.path / "camera.json")
        self.pairs = associate_timestamps(
            read_timestamp_list(self.path / "depth.txt", allow_outside=allow_outside),
            read_timestamp_list(self.path / "rgb.txt", allow_outside=allow_outside),
            max_difference,
        )
        self.planes = self._read_planes(self.path / "planes.csv")
        self.skipped: list[tuple[int, str]] = []

    @staticmethod
    def _read_planes(path: Path) -> dict[int, dict[str, Any]]:
        if not path.exists():
            return {}
        planes = {}
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise FileFormatError(
                f"{path}: not UTF-8 text (byte {exc.start}): expected frame,nx,ny,nz,d"
            ) from None
        with io.StringIO(text, newline="") as fh:
            for n, row in enumerate(csv.DictReader(fh), 2):
                try:
                    normal = np.array([float(row["nx"]), float(row["ny"]), float(row["nz"])])
                    truth: dict[str, Any] = {"plane": (normal, float(row["d"]))}
                    if row.get("board_pixels") not in (None, ""):
                        truth["valid_board_pixels"] = int(row["board_pixels"])
                    planes[int(row["frame"])] = truth
                except (KeyError, TypeError, ValueError):
                    raise FileFormatError(
                        f"{path}:{n}: expected frame,nx,ny,nz,d[,board_pixels]"
                    ) from None
        return planes

    def __len__(self) -> int:
        return len(self.pairs)

    def __iter__(self) -> Iterator[RGBDFrame]:
        cam = self.camera
        for index, (t, dname, cname) in enumerate(self.pairs):
            dpath, cpath = self.path / dname, self.path / cname
            missing = [p for p in (dpath, cpath) if not _exists(p)]
            if missing:
                if not _exists(self.path):  # not a frame's fault: cannot be skipped
                    raise FileFormatError(
                        f"{self.path}: the folder is gone (frame {index} of {len(self)})"
                    )
                self._skip(index, f"{missing[0]}: file is missing")
                continue
            try:
                depth = read_image(dpath)
                color = read_image(cpath, mode="rgb")
            except FileFormatError as exc:
                self._skip(index, str(exc))
                continue
            if depth.dtype != np.uint16 or depth.ndim != 2:
                self._skip(
                    index,
                    f"{dpath}: depth must be 16-bit single-channel (PNG, PGM or TIFF); got "
                    f"{depth.dtype} {depth.shape}: convert the folder with `robopercept "
                    "rgbd-import` (it reads float and 16-bit depth)",
                )
                continue
            truth = dict(self.planes.get(index, {}))
            try:
                frame = RGBDFrame(
                    index,
                    t,
                    depth,
                    np.ascontiguousarray(color[..., :3]),
                    cam["depth"],
                    cam["color"],
                    cam["T_color_depth"],
                    cam["depth_scale"],
                    truth,
                )
            except InputError as exc:  # an image of the wrong size
                self._skip(index, f"{dpath.name} / {cpath.name}: {exc}")
                continue
            yield frame

    def _skip(self, index: int, reason: str) -> None:
        """Warn ``skipping frame <index>: <reason>`` and record it in :attr:`skipped`."""
        warnings.warn(f"skipping frame {index}: {reason}", stacklevel=3)
        self.skipped.append((index, reason))


def _exists(p: Path) -> bool:
    """``p.exists()``, False for a path the OS refuses (too long, a loop)."""
    try:
        return p.exists()
    except OSError:
        return False


def camera_dict(k: CameraIntrinsics) -> dict[str, Any]:
    """The camera as camera.json stores it: ``width``, ``height``, ``fx``, ``fy``,
    ``cx``, ``cy`` (pixels), ``model`` and ``coeffs`` (see ``docs/tracking.md``)."""
    check_intrinsics(k, "k")
    return {
        "width": k.width,
        "height": k.height,
        "fx": k.fx,
        "fy": k.fy,
        "cx": k.cx,
        "cy": k.cy,
        "model": k.model,
        "coeffs": list(k.coeffs),
    }


def write_tum_folder(
    path: str | os.PathLike[str], frames: Iterable[RGBDFrame], *, png_compression: int = 1
) -> Path:
    """Write frames as a TUM folder with ``camera.json`` (from the first frame) and, when
    the frames carry ``ground_truth["plane"] = (n, d)``, ``planes.csv``.

    Files are written frame by frame, and the lists are flushed as they grow, so an
    interrupted write leaves a readable folder with the frames written so far.

    Parameters
    ----------
    path : path-like
        The folder (created).
    frames : iterable of RGBDFrame
    png_compression : int
        zlib level 0..9 of the PNG files (:func:`~robopercept.imaging.write_image`): 1
        (default) is fast with files 2-3x smaller than raw; 0 stores them uncompressed,
        about 20x faster to write, for folders that are read once and deleted.

    Raises
    ------
    InputError
        ``path`` cannot name a folder (:func:`~robopercept._checks.as_path`), or
        ``frames`` is not an iterable of :class:`RGBDFrame`.
    """
    out = as_path(path, "the output folder")
    check_png_compression(png_compression)
    if isinstance(frames, (str, bytes, RGBDFrame)) or not isinstance(frames, Iterable):
        raise InputError(
            f"frames must be an iterable of RGBDFrame objects; got {type(frames).__name__}"
        )
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    header = "# written by robopercept\n"
    with (
        (out / "rgb.txt").open("w") as rgb_list,
        (out / "depth.txt").open("w") as depth_list,
        (out / "planes.csv").open("w", newline="") as planes,
    ):
        rgb_list.write(header)
        depth_list.write(header)
        writer = csv.writer(planes)
        writer.writerow(["frame", "nx", "ny", "nz", "d", "board_pixels"])
        wrote_camera = False
        has_planes = False
        for k, f in enumerate(frames):
            if not isinstance(f, RGBDFrame):
                raise InputError(f"frames must be RGBDFrame objects; got {type(f).__name__}")
            if not wrote_camera:
                cam = {
                    "depth": camera_dict(f.depth_intrinsics),
                    "color": camera_dict(f.color_intrinsics),
                    "T_color_depth": f.T_color_depth.tolist(),
                    "depth_scale": f.depth_scale,
                }
                (out / "camera.json").write_text(json.dumps(cam, indent=2))
                wrote_camera = True
            name = f"{f.timestamp:.6f}.png"
            write_image(out / "depth" / name, f.depth, png_compression=png_compression)
            write_image(out / "rgb" / name, f.color, png_compression=png_compression)
            depth_list.write(f"{f.timestamp:.6f} depth/{name}\n")
            rgb_list.write(f"{f.timestamp:.6f} rgb/{name}\n")
            depth_list.flush()
            rgb_list.flush()
            if "plane" in f.ground_truth:
                n, d = f.ground_truth["plane"]
                pixels = f.ground_truth.get("valid_board_pixels", "")
                # the row of the k-th frame written: TUMFolderSource numbers the frames
                # it reads from 0, whatever index they had (a sequence cut from a scene)
                writer.writerow([k, *(f"{v:.9g}" for v in n), f"{d:.9g}", pixels])
                planes.flush()
                has_planes = True
    if not has_planes:
        (out / "planes.csv").unlink()
    return out
