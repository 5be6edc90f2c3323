"""Argument types and the usage error shared by the command modules.

Each type is an ``argparse`` ``type=`` callable: it returns the parsed value or raises
``argparse.ArgumentTypeError``, which argparse reports as a usage error (exit code 2).
A command that finds a bad flag value or combination after parsing raises
:class:`UsageError` (exit code 2 as well).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = [
    "UsageError",
    "board_size",
    "box_xywh",
    "hsv",
    "load_gray",
    "noise_filter",
    "numbers",
    "pass_through",
    "positive_int",
]


class UsageError(Exception):
    """A command-line argument, or a combination of them, is wrong (exit code 2)."""


def positive_int(text: str) -> int:
    """An integer >= 1 (argparse type)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects an integer; got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1; got {v}")
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


def numbers(kinds: tuple[type, ...], usage: str, sep: str = ":") -> Callable[[str], tuple]:
    """An argparse type for ``A:B:...`` (fields split at ``sep``) with one converter per
    field (``kinds``); ``usage`` names the fields in the error (``"K:STD_RATIO"``)."""

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
