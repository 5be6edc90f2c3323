"""``robopercept track``: multi-object tracking through a video or a folder of images
(:func:`~robopercept.pipelines.track_objects`: a Kalman filter per track, Hungarian
association), drawn, and written as a MOTChallenge results file."""

from __future__ import annotations

import argparse
import time

import numpy as np

from robopercept.cli._args import file_output, flag_errors, positive_int
from robopercept.cli._video import (
    add_video_arguments,
    finish,
    open_source,
    progress,
    text_size,
)

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``track`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "track",
        help="multi-object tracking (Kalman filter per track, Hungarian association)",
        description="Detections come from a MOTChallenge det.txt (--detections) or, "
        "without one, from background subtraction (Gaussian model, blobs of at least "
        "--min-area pixels). Draws each track with its ID and writes the MOTChallenge "
        "results file.",
    )
    p.add_argument("video", help="video file or folder of images (e.g. MOT17 img1/)")
    p.add_argument("--detections", default=None, help="MOTChallenge det.txt (frames from 1)")
    p.add_argument("--min-score", type=float, default=None, help="drop weaker detections")
    p.add_argument(
        "--results", type=file_output, default="tracks.txt", help="MOTChallenge results file"
    )
    p.add_argument("--cost", choices=("iou", "mahalanobis", "euclidean"), default="iou")
    p.add_argument("--gate", type=float, default=None, help="see MultiObjectTracker")
    p.add_argument("--min-hits", type=int, default=3)
    p.add_argument("--max-age", type=int, default=5)
    p.add_argument("--min-area", type=positive_int, default=100, help="no det.txt: blob size")
    p.add_argument("--no-detections", action="store_true", help="do not draw the detections")
    add_video_arguments(p, "tracks.mp4")
    p.set_defaults(func=run_track)


@flag_errors(
    cost="--cost",
    gate="--gate",
    min_hits="--min-hits",
    max_age="--max-age",
    min_score="--min-score",
    min_area="--min-area",
)
def run_track(args: argparse.Namespace) -> int:
    """Run ``robopercept track`` with the parsed ``args``; returns the exit status."""
    from robopercept.imaging import SnapshotVideoWriter
    from robopercept.pipelines import track_objects
    from robopercept.tracking import MultiObjectTracker, read_mot, write_mot
    from robopercept.viz import draw_boxes, draw_text, label_colors

    det_file = read_mot(args.detections) if args.detections else None
    source = open_source(args.video, args)
    tracker = MultiObjectTracker(
        cost=args.cost, gate=args.gate, min_hits=args.min_hits, max_age=args.max_age
    )
    results: list[tuple[int, int, np.ndarray, float]] = []
    ids: set[int] = set()
    n_det = frames = 0
    t0 = time.perf_counter()
    with (
        SnapshotVideoWriter(args.output, source.fps, args.snapshot) as out,
        progress(source, "track", args.quiet) as bar,
    ):
        steps = track_objects(
            source, det_file, tracker=tracker, min_score=args.min_score, min_area=args.min_area
        )
        try:
            for step in steps:
                frame = step.image
                n_det += len(step.boxes)
                picture = frame
                if not args.no_detections and len(step.boxes):
                    picture = draw_boxes(picture, step.boxes, color=(160, 160, 160), width=1)
                for t in step.tracks:
                    ids.add(t.id)
                    color = tuple(int(c) for c in label_colors(np.array([t.id]))[0])
                    picture = draw_boxes(
                        picture, t.box[None], color=color, width=2, labels=[str(t.id)]
                    )
                results.extend(step.rows)
                picture = draw_text(
                    picture,
                    f"frame {step.number}: {len(step.tracks)} track(s)",
                    size=text_size(frame),
                )
                out.add(step.index, picture)
                frames += 1
                bar.update(1)
        finally:  # results so far are kept, also on an error or Ctrl-C
            if frames:  # no results file for a run that read no frame
                write_mot(args.results, results)
                out.written.append(args.results)
    seconds = time.perf_counter() - t0
    print(f"detections        {n_det} ({n_det / max(frames, 1):.1f} per frame)")
    print(f"tracks            {len(ids)} identities, {len(results)} result rows")
    return finish(source, out.written, frames, seconds)
