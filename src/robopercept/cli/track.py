"""``robopercept track``: multi-object tracking through a video or a folder of images
(:func:`~robopercept.pipelines.track_objects`: a Kalman filter per track, Hungarian
association), drawn, and written as a MOTChallenge results file; with ``--gt`` (a
MOTChallenge ``gt.txt``) the results are scored: MOTA, MOTP, IDF1, IDP, IDR, identity
switches, FP, FN (:func:`~robopercept.tracking.metrics.evaluate_mot`); ``--json`` prints
one JSON object (schema in docs/tracking.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from typing import Any

from robopercept.cli._args import (
    UsageError,
    file_output,
    flag_errors,
    positive_int,
    unit_interval,
)
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
    p.add_argument(
        "--cost",
        choices=("iou", "mahalanobis", "euclidean"),
        default="iou",
        help="association cost between a track's predicted box and a detection: 1 - IoU, "
        "the Kalman filter's Mahalanobis distance, or the centre distance in pixels",
    )
    p.add_argument(
        "--gate",
        type=float,
        default=None,
        help="the loosest match --cost allows: iou: least IoU (default 0.3); mahalanobis: "
        "largest squared distance (default 13.28, chi-square 99 %%, 4 dof); euclidean: "
        "largest centre distance in pixels (default 50)",
    )
    p.add_argument(
        "--min-hits",
        type=int,
        default=3,
        help="matches that confirm a track (only confirmed tracks are drawn and written)",
    )
    p.add_argument(
        "--max-age",
        type=int,
        default=5,
        help="frames a confirmed track coasts on its prediction without a match before it ends",
    )
    p.add_argument("--min-area", type=positive_int, default=100, help="no det.txt: blob size")
    p.add_argument("--no-detections", action="store_true", help="do not draw the detections")
    p.add_argument(
        "--gt",
        default=None,
        metavar="GT.txt",
        help="MOTChallenge ground truth: score the results (MOTA, MOTP, IDF1, switches) "
        "over the frames read; flag-0 rows are left out, and in 9-column files classes "
        "other than --gt-classes",
    )
    p.add_argument(
        "--gt-classes",
        default="1",
        metavar="C[,C...]",
        help="classes of a MOT16/17 gt.txt that count (default 1: pedestrians); 'all'",
    )
    p.add_argument(
        "--iou",
        type=unit_interval,
        default=0.5,
        help="--gt: least IoU of a match (default 0.5, MOTChallenge)",
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_video_arguments(p, "tracks.mp4")
    p.set_defaults(func=run_track)


@flag_errors(
    cost="--cost",
    gate="--gate",
    min_hits="--min-hits",
    max_age="--max-age",
    min_score="--min-score",
    min_area="--min-area",
    iou_threshold="--iou",
    classes="--gt-classes",
)
def run_track(args: argparse.Namespace) -> int:
    """Run ``robopercept track`` with the parsed ``args``; returns the exit status."""
    from robopercept.tracking import read_mot
    from robopercept.tracking.metrics import select_ground_truth

    classes = _classes(args.gt_classes)
    gt = select_ground_truth(read_mot(args.gt), classes) if args.gt else None
    # --json: stdout holds the JSON object only; the human summary goes to stderr
    with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
        summary = _track(args)
    numbers = summary.pop("_numbers")
    if gt is not None:
        summary["evaluation"] = _evaluate(args, gt, numbers)
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0


def _classes(text: str) -> list[int] | None:
    """``--gt-classes``: ``1,2`` -> [1, 2]; ``all`` -> None."""
    if text.strip().lower() == "all":
        return None
    try:
        return [int(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise UsageError(
            f"--gt-classes: expects class numbers such as 1 or 1,2,7 (or all); got {text!r}"
        ) from None


def _track(args: argparse.Namespace) -> dict[str, Any]:
    """Track through the video, write the outputs, print the human summary (stdout);
    returns the JSON summary, with the frame numbers read under ``_numbers``."""
    import numpy as np

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
    numbers: list[int] = []
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
                numbers.append(int(step.number))
                frames += 1
                bar.update(1)
        finally:  # results so far are kept, also on an error or Ctrl-C
            if frames:  # no results file for a run that read no frame
                write_mot(args.results, results)
                out.written.append(args.results)
    seconds = time.perf_counter() - t0
    print(f"detections        {n_det} ({n_det / max(frames, 1):.1f} per frame)")
    print(f"tracks            {len(ids)} identities, {len(results)} result rows")
    finish(source, out.written, frames, seconds)
    return {
        "command": "track",
        "frames": frames,
        "skipped": len(source.skipped),
        "fps": frames / seconds if seconds > 0 else None,
        "detections": n_det,
        "identities": len(ids),
        "result_rows": len(results),
        "results": str(args.results),
        "outputs": list(out.written),
        "evaluation": None,
        "_numbers": numbers,
    }


def _evaluate(args: argparse.Namespace, gt: Any, numbers: list[int]) -> dict[str, Any]:
    """``--gt``: score the results file over the frame ``numbers`` read (printed unless
    ``--json``)."""
    import numpy as np

    from robopercept.tracking import read_mot
    from robopercept.tracking.metrics import evaluate_mot

    with flag_errors(ground_truth="--gt", hypotheses="--results"):
        m = evaluate_mot(gt, read_mot(args.results), iou_threshold=args.iou, frames=numbers)
    result: dict[str, Any] = {"gt": str(args.gt), "iou_threshold": args.iou, **m.to_dict()}
    if not args.json:

        def f(v: float) -> str:
            return "n/a" if not np.isfinite(v) else f"{v:.3f}"

        print(
            f"vs ground truth   MOTA {f(m.mota)}, IDF1 {f(m.idf1)} (IDP {f(m.idp)}, "
            f"IDR {f(m.idr)}), MOTP {f(m.motp)} (mean 1 - IoU)"
        )
        print(
            f"                  {m.num_switches} ID switches, {m.num_false_positives} FP, "
            f"{m.num_misses} FN, {m.num_matches} matches; {m.num_objects} true boxes in "
            f"{m.num_frames} frames"
        )
    return result
