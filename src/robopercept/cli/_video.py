"""What the video commands (``bgsub``, ``flow``, ``meanshift``, ``track``) share: their
common options, the progress bar, caption size and the closing summary lines.

Each of them reads a video file or an image folder
(:class:`~robopercept.sources.VideoSource`), writes an annotated MP4 and ``--snapshot``
PNGs (:class:`~robopercept.imaging.SnapshotVideoWriter`), shows a progress bar and
prints a summary. An image of a folder that cannot be read is skipped and counted; a
video that cannot be decoded is one error (exit code 1), and so is a run in which no
frame could be read (:func:`finish`). The output video's name is checked when the flags
are parsed, so a wrong extension is refused before any frame is read.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import positive_int, video_output

if TYPE_CHECKING:
    import numpy as np

__all__ = ["add_video_arguments", "finish", "open_source", "progress", "text_size"]


def add_video_arguments(
    p: argparse.ArgumentParser,
    default_out: str | None,
    out_help: str | None = None,
    *,
    video: bool = True,
) -> None:
    """``-o/--output``, ``--max-frames``, ``--fps``, ``--snapshot`` and ``--quiet``.

    With ``video`` (the default) ``-o`` must name a video file (.mp4, .avi, ...),
    checked while parsing; a command whose output kind depends on its inputs
    (``flow``) passes False and checks it with
    :func:`~robopercept.cli._args.check_output`."""
    p.add_argument(
        "-o",
        "--output",
        type=video_output if video else str,
        default=default_out,
        help=out_help or "output video: .mp4, .m4v, .mov, .mkv or .avi (default: %(default)s)",
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


def open_source(path: str, args: argparse.Namespace, min_frames: int = 1) -> Any:
    """The :class:`~robopercept.sources.VideoSource` of ``path`` with ``--fps`` and
    ``--max-frames``, refused before anything is written when it holds fewer than
    ``min_frames`` frames."""
    from robopercept.sources import VideoSource

    return VideoSource(path, fps=args.fps, max_frames=args.max_frames, min_frames=min_frames)


def text_size(image: np.ndarray) -> int:
    """Caption height in pixels: readable on small frames, and on 1080p ones (the one
    rule for text on pictures, :func:`robopercept.viz.draw.label_size_for`)."""
    from robopercept.viz.draw import label_size_for

    return label_size_for(image.shape[0])


def progress(source: Any, desc: str, quiet: bool) -> Any:
    """Progress over the frames of ``source`` on stderr
    (:func:`~robopercept.progress.progress_bar`: a bar on a terminal, a few lines in a
    log)."""
    from robopercept.progress import progress_bar

    return progress_bar(total=len(source), unit="frame", desc=desc, disable=quiet)


def finish(source: Any, written: list[str], frames: int, seconds: float) -> int:
    """Print the skipped frames (stderr), the speed and the files written; return the
    exit status 0.

    Only files that exist are listed (``written``, as the writers record them).

    Raises
    ------
    FileFormatError
        No frame was processed (every frame skipped as unreadable): exit code 1, after
        the summary, so a run that did nothing never looks like a success.
    """
    from robopercept.errors import FileFormatError

    if source.skipped:
        print(
            f"skipped {len(source.skipped)} unreadable frame(s), first: {source.skipped[0][1]}",
            file=sys.stderr,
        )
    speed = frames / seconds if seconds > 0 else float("nan")
    print(f"frames            {frames} ({speed:.1f} fps), skipped {len(source.skipped)}")
    print(f"wrote             {', '.join(written) or 'nothing'}")
    if frames == 0:
        raise FileFormatError(
            f"no frame of {source.path} could be read ({len(source.skipped)} skipped as "
            "unreadable): nothing was processed"
        )
    return 0
