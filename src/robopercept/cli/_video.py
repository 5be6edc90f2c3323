"""What the video commands (``bgsub``, ``flow``, ``meanshift``, ``track``) share: their
common options, the progress bar, caption size and the closing summary lines.

Each of them reads a video file or an image folder
(:class:`~robopercept.sources.VideoSource`), writes an annotated MP4 and ``--snapshot``
PNGs (:class:`~robopercept.imaging.SnapshotVideoWriter`), shows a progress bar and
prints a summary. An image of a folder that cannot be read is skipped and counted; a
video that cannot be decoded is one error (exit code 1).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from robopercept.cli._args import positive_int

__all__ = ["add_video_arguments", "open_source", "print_summary", "progress", "text_size"]


def add_video_arguments(
    p: argparse.ArgumentParser, default_out: str | None, out_help: str | None = None
) -> None:
    """``-o/--output``, ``--max-frames``, ``--fps``, ``--snapshot`` and ``--quiet``."""
    p.add_argument(
        "-o",
        "--output",
        default=default_out,
        help=out_help or "output video (default: %(default)s)",
    )
    p.add_argument("--max-frames", type=positive_int, default=None, help="stop after N frames")
    p.add_argument("--fps", type=float, default=None, help="frame rate of an image folder")
    p.add_argument(
        "--snapshot",
        type=int,
        action="append",
        default=None,
        metavar="N",
        help="also save frame N (0-based) as OUTPUT_<N>.png; repeatable",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def open_source(path: str, args: argparse.Namespace) -> Any:
    """The :class:`~robopercept.sources.VideoSource` of ``path`` with ``--fps`` and
    ``--max-frames``."""
    from robopercept.sources import VideoSource

    return VideoSource(path, fps=args.fps, max_frames=args.max_frames)


def text_size(image: np.ndarray) -> int:
    """Caption height in pixels: readable on small frames, and on 1080p ones."""
    return max(12, round(image.shape[0] / 36))


def progress(source: Any, desc: str, quiet: bool) -> Any:
    """A tqdm progress bar on stderr over the frames of ``source``."""
    from tqdm import tqdm

    return tqdm(total=len(source), unit="frame", desc=desc, disable=quiet, file=sys.stderr)


def print_summary(source: Any, written: list[str], frames: int, seconds: float) -> None:
    """The skipped frames (stderr), the speed and the files written."""
    if source.skipped:
        print(
            f"skipped {len(source.skipped)} unreadable frame(s), first: {source.skipped[0][1]}",
            file=sys.stderr,
        )
    speed = frames / seconds if seconds > 0 else float("nan")
    print(f"frames            {frames} ({speed:.1f} fps), skipped {len(source.skipped)}")
    print(f"wrote             {', '.join(written) or 'nothing'}")
