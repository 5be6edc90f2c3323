"""``robopercept meanshift``: follow a colour region through a video or a folder of
images by mean shift (or CamShift), writing the boxes as CSV."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from robopercept.cli._args import box_xywh, file_output, flag_errors, positive_int
from robopercept.cli._video import (
    add_video_arguments,
    finish,
    open_source,
    progress,
    text_size,
)

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``meanshift`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "meanshift",
        help="track a colour region through a video by mean shift (or CamShift)",
        description="Learn the colour histogram of --box in the first frame, then move the "
        "window to the centre of mass of the back-projected likelihood in every frame.",
    )
    p.add_argument("video", help="video file or folder of images")
    p.add_argument("--box", type=box_xywh, required=True, metavar="X,Y,W,H", help="target, frame 0")
    p.add_argument("--feature", choices=("hue", "rgb"), default="hue")
    p.add_argument("--bins", type=positive_int, default=None, help="16 (hue) or 8 (rgb)")
    p.add_argument(
        "--min-saturation",
        type=int,
        default=60,
        help="hue: pixels below this saturation (0-255) are left out (default 60)",
    )
    p.add_argument(
        "--min-value",
        type=int,
        default=32,
        help="hue: pixels below this brightness (0-255) are left out (default 32)",
    )
    p.add_argument("--camshift", action="store_true", help="adapt the window size (CamShift)")
    p.add_argument(
        "--plain-histogram",
        action="store_true",
        help="no background weighting (OpenCV's histogram)",
    )
    p.add_argument(
        "--results", type=file_output, default=None, help="CSV of frame,x,y,w,h,similarity"
    )
    add_video_arguments(p, "meanshift.mp4")
    p.set_defaults(func=run_meanshift)


@flag_errors(
    box="--box",
    feature="--feature",
    bins="--bins",
    min_saturation="--min-saturation",
    min_value="--min-value",
)
def run_meanshift(args: argparse.Namespace) -> int:
    """Run ``robopercept meanshift`` with the parsed ``args``; returns the exit status."""
    from robopercept.imaging import SnapshotVideoWriter
    from robopercept.tracking import MeanShiftTracker
    from robopercept.viz import draw_boxes, draw_text

    source = open_source(args.video, args)
    tracker: MeanShiftTracker | None = None
    rows: list[tuple[int, np.ndarray, float]] = []
    frames = 0
    t0 = time.perf_counter()
    with (
        SnapshotVideoWriter(args.output, source.fps, args.snapshot) as out,
        progress(source, "camshift" if args.camshift else "meanshift", args.quiet) as bar,
    ):
        try:
            for i, frame in source:
                if tracker is None:
                    tracker = MeanShiftTracker(
                        frame,
                        args.box,
                        feature=args.feature,
                        bins=args.bins,
                        adaptive=args.camshift,
                        min_saturation=args.min_saturation,
                        min_value=args.min_value,
                        background_weighting=not args.plain_histogram,
                    )
                    box, similarity = tracker.box.astype(np.float64), 1.0
                else:
                    r = tracker.update(frame)
                    box, similarity = np.asarray(r.box, dtype=np.float64), float(r.similarity)
                rows.append((i, box, similarity))
                picture = draw_boxes(frame, box[None], color=(255, 255, 0), width=2)
                picture = draw_text(
                    picture, f"similarity {similarity:.2f}", (5, 5), size=text_size(frame)
                )
                out.add(i, picture)
                frames += 1
                bar.update(1)
        finally:  # the boxes so far are kept, also on an error or Ctrl-C
            if args.results and rows:
                _write_boxes_csv(Path(args.results), rows)
                out.written.append(args.results)
    seconds = time.perf_counter() - t0
    if len(rows) > 1:
        sims = np.array([s for _, _, s in rows[1:]])
        print(f"similarity        mean {sims.mean():.3f}, min {sims.min():.3f}")
    return finish(source, out.written, frames, seconds)


def _write_boxes_csv(path: Path, rows: list[tuple[int, np.ndarray, float]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["frame,x,y,w,h,similarity"]
    lines += [f"{i},{b[0]:.2f},{b[1]:.2f},{b[2]:.2f},{b[3]:.2f},{s:.4f}" for i, b, s in rows]
    path.write_text("\n".join(lines) + "\n")
