"""Argument types and the usage error shared by the command modules.

Each type is an ``argparse`` ``type=`` callable: it returns the parsed value or raises
``argparse.ArgumentTypeError``, which argparse reports as a usage error (exit code 2).
A command that finds a bad flag value or combination after parsing raises
:class:`UsageError` (exit code 2 as well).

Output files are checked when the flags are parsed (:func:`output_path`, with the
library writer's own extension check), so a name that does not fit the content is
refused before any work. Library errors that name a Python parameter are rewritten with
the flag the user typed (:func:`flag_errors`), in this one place.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from robopercept.errors import InputError

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "DefaultsHelpFormatter",
    "UsageError",
    "board_size",
    "box_xywh",
    "check_output",
    "cloud_output",
    "default_text",
    "file_output",
    "flag_errors",
    "hsv",
    "image_output",
    "image_size",
    "in_flags",
    "load_gray",
    "noise_filter",
    "non_negative_int",
    "numbers",
    "pass_through",
    "positive_float",
    "positive_int",
    "unit_interval",
    "video_output",
]


class UsageError(Exception):
    """A command-line argument, or a combination of them, is wrong (exit code 2)."""


# -- help ------------------------------------------------------------------------------
def default_text(value: object) -> str | None:
    """A flag's default as the user would type it, for its help; None when there is
    nothing to show (None, False, an empty list, :data:`argparse.SUPPRESS`).

    A tuple or list is written comma-separated (``--hsv-low 45,35,35``), a float
    without a trailing ``.0`` only when it is whole (``1.0`` -> ``1``), anything else
    as ``str``.

    Examples
    --------
    >>> default_text((45, 35, 35)), default_text(1.0), default_text(0.02), default_text("iou")
    ('45,35,35', '1', '0.02', 'iou')
    >>> default_text(None), default_text(False), default_text([]), default_text(0)
    (None, None, None, '0')
    """
    if value is None or value is False or value is argparse.SUPPRESS:
        return None
    if isinstance(value, (tuple, list)):
        return ",".join(t for t in (default_text(v) for v in value) if t) or None
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return str(value)


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """The help formatter of every ``robopercept`` parser: an option's help ends with
    ``(default: X)`` (:func:`default_text`) where it has a default worth showing and
    its help does not already say it (the word "default" in it), as argparse's
    :class:`argparse.ArgumentDefaultsHelpFormatter` does without the ``None``,
    ``False`` and doubled defaults. Switches (``store_true``, ``store_false``, counts)
    show none: their help says what giving them does."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "default" in text.lower() or action.nargs == 0:
            return text
        if not action.option_strings and action.nargs not in ("?", "*"):
            return text  # a required positional has no default
        shown = default_text(action.default)
        if shown is None:
            return text
        shown = shown.replace("%", "%%")  # argparse expands %(name)s in help
        return f"{text} (default: {shown})" if text else f"default: {shown}"


def positive_int(text: str) -> int:
    """An integer >= 1 (argparse type)."""
    return _int_at_least(text, 1)


def non_negative_int(text: str) -> int:
    """An integer >= 0 (argparse type)."""
    return _int_at_least(text, 0)


def _int_at_least(text: str, low: int) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects an integer; got {text!r}") from None
    if v < low:
        raise argparse.ArgumentTypeError(f"must be >= {low}; got {v}")
    return v


def positive_float(text: str) -> float:
    """A number > 0 (argparse type)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a number; got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0; got {text!r}")
    return v


def image_size(text: str) -> tuple[int, int]:
    """``WxH`` -> (width, height), both >= 16 (argparse type)."""
    parts = text.lower().split("x")
    try:
        w, h = (int(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects WxH, e.g. 128x128; got {text!r}") from None
    if min(w, h) < 16:
        raise argparse.ArgumentTypeError(f"expects both sides >= 16; got {text!r}")
    return w, h


def unit_interval(text: str) -> float:
    """A number in [0, 1] (argparse type): a score or IoU threshold."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects a number in [0, 1]; got {text!r}") from None
    if not 0 <= v <= 1:
        raise argparse.ArgumentTypeError(f"expects a number in [0, 1]; got {text!r}")
    return v


def noise_filter(text: str) -> str | None:
    """``median``, ``open-close`` or ``none`` (-> None) (argparse type)."""
    if text not in ("median", "open-close", "none"):
        raise argparse.ArgumentTypeError(f"expects median, open-close or none; got {text!r}")
    return None if text == "none" else text


def board_size(text: str) -> tuple[int, int]:
    """``9x6`` -> (9, 6) inner corners, at least 2x2 (argparse type)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expects inner corners as WxH, e.g. 9x6; got {text!r}"
        ) from None
    if w < 2 or h < 2:
        raise argparse.ArgumentTypeError(f"needs at least 2x2 inner corners; got {text!r}")
    return w, h


def pass_through(text: str) -> tuple[str, float, float]:
    """``AXIS:MIN:MAX`` with AXIS in x, y, z (argparse type)."""
    parts = text.split(":")
    if len(parts) != 3 or parts[0] not in ("x", "y", "z"):
        raise argparse.ArgumentTypeError("expects AXIS:MIN:MAX with AXIS in x, y, z")
    try:
        return parts[0], float(parts[1]), float(parts[2])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def numbers(
    kinds: tuple[Callable[[str], object], ...], usage: str, sep: str = ":"
) -> Callable[[str], tuple]:
    """An argparse type for ``A:B:...`` (fields split at ``sep``) with one converter per
    field (``kinds``: types, or argparse types such as :func:`positive_int`); ``usage``
    names the fields in the error (``"K:STD_RATIO"``)."""

    def parse(text: str) -> tuple:
        parts = text.replace(" ", "").split(sep)
        if len(parts) != len(kinds):
            raise argparse.ArgumentTypeError(f"expects {usage}; got {text!r}")
        try:
            return tuple(k(p) for k, p in zip(kinds, parts, strict=True))
        except ValueError:
            raise argparse.ArgumentTypeError(f"expects {usage}; got {text!r}") from None

    return parse


box_xywh = numbers((float,) * 4, "x,y,w,h (four numbers)", ",")
box_xywh.__doc__ = "``x,y,w,h`` -> four floats (argparse type)."
hsv = numbers((float,) * 3, "H,S,V (three numbers)", ",")
hsv.__doc__ = "``H,S,V`` -> three floats (argparse type)."


def load_gray(path: str | None) -> tuple[Path, np.ndarray]:
    """The image at ``path`` as gray (the bundled sample image when None), with its
    path (:func:`~robopercept.imaging.read_image` with ``mode="gray"``)."""
    from robopercept.imaging import read_image, sample_image_path

    p = Path(path) if path else sample_image_path()
    return p, read_image(p, mode="gray")


# -- outputs ---------------------------------------------------------------------------
def _output_check(kind: str) -> Callable[[str], Path]:
    """The library's check of a file name for output ``kind`` (its writer's own); every
    kind refuses an existing folder (``"file"``: only that)."""
    if kind == "file":
        return Path
    if kind == "image":
        from robopercept.imaging import check_image_path

        return check_image_path
    if kind == "video":
        from robopercept.imaging import check_video_path

        return check_video_path
    if kind == "cloud":
        from robopercept.pointcloud import check_cloud_path

        return check_cloud_path
    if kind == "npy":
        from robopercept._checks import check_extension

        return lambda path: check_extension(path, (".npy",), "a NumPy array (np.save)")
    raise ValueError(f"unknown output kind {kind!r}")  # a programming error


def output_path(kind: str) -> Callable[[str], str]:
    """An argparse type for an output file of ``kind``: ``"image"``
    (:func:`~robopercept.imaging.check_image_path`), ``"video"``
    (:func:`~robopercept.imaging.check_video_path`), ``"cloud"``
    (:func:`~robopercept.pointcloud.check_cloud_path`), ``"npy"`` or ``"file"`` (any
    name); an existing folder is refused for every kind.

    The name is checked while the flags are parsed, so ``bgsub -o x.png`` is a usage
    error (exit code 2) naming the flag and the allowed extensions, before any frame is
    read, instead of an H.264 stream written under an image's name.
    """

    def parse(text: str) -> str:  # the library is imported when a flag is parsed
        if Path(text).is_dir():
            raise argparse.ArgumentTypeError(f"{text} is a folder; give a file name")
        try:
            _output_check(kind)(text)
        except InputError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text

    parse.__name__ = f"{kind}_output"
    return parse


image_output = output_path("image")
image_output.__doc__ = "An output image file: PNG, JPEG, TIFF, BMP, PNM (argparse type)."
video_output = output_path("video")
video_output.__doc__ = "An output video file: .mp4, .m4v, .mov, .mkv, .avi (argparse type)."
cloud_output = output_path("cloud")
cloud_output.__doc__ = "An output point cloud: .ply or .pcd (argparse type)."
file_output = output_path("file")
file_output.__doc__ = "An output file of any name, not an existing folder (argparse type)."


def check_output(path: str, kind: str, flag: str = "-o/--output") -> str:
    """``path`` after the check of :func:`output_path` for an output whose kind is known
    only after parsing (``flow -o``: an image for two images, a video for one video);
    a misfit is a :class:`UsageError` naming ``flag``."""
    if Path(path).is_dir():
        raise UsageError(f"{flag}: {path} is a folder; give a file name")
    try:
        _output_check(kind)(path)
    except InputError as exc:
        raise UsageError(f"{flag}: {exc}") from None
    return path


# -- library errors in the user's terms --------------------------------------------------
def in_flags(message: str, flags: Mapping[str, str]) -> str:
    """``message`` with each Python parameter of ``flags`` written as its flag.

    ``feature='rgb'`` becomes ``--feature rgb`` and a bare ``sigma`` becomes
    ``--sigma``; a name is replaced only as a whole word (``block_sigma`` keeps its
    ``sigma``, ``--sigma`` is not replaced again).

    Parameters
    ----------
    message : str
    flags : mapping of str to str
        Parameter name -> flag (``{"cell_size": "--cell"}``).

    Returns
    -------
    str

    Examples
    --------
    >>> in_flags("box holds no colour: use feature='rgb'", {"feature": "--feature"})
    'box holds no colour: use --feature rgb'
    >>> in_flags("cell_size must be >= 1; got 0", {"cell_size": "--cell"})
    '--cell must be >= 1; got 0'
    """
    for param, flag in flags.items():
        name = rf"(?<![\w-]){re.escape(param)}"
        literal = flag.replace("\\", "\\\\")  # re.sub's template: the flag as written
        message = re.sub(name + r"""=(['"]?)([^'"\s,;:)]*)\1""", literal + r" \2", message)
        message = re.sub(name + r"(?![\w-])", literal, message)
    return message


@contextmanager
def flag_errors(**flags: str) -> Iterator[None]:
    """Inside, an :class:`~robopercept.errors.InputError` from the library has the Python
    parameters of ``flags`` (``cell_size="--cell"``) written as the flags the user typed
    (:func:`in_flags`); it keeps its class (an ``InputError`` exits 1, an
    ``ArgumentError`` 2). Usable as a ``with``
    block around a library call or as a decorator of a command's ``run`` function.

    Examples
    --------
    >>> with flag_errors(sigma="--sigma"):  # doctest: +SKIP
    ...     canny(gray, 50, 150, sigma=args.sigma)
    """
    try:
        yield
    except InputError as exc:
        text = in_flags(str(exc), flags)
        if text == str(exc):
            raise
        try:
            renamed = type(exc)(text)
        except Exception:  # a subclass whose constructor takes more than the message
            renamed = InputError(text)
        raise renamed from exc
