"""``robopercept meanshift``: follow a colour region through a video or a folder of
images by mean shift (or CamShift), writing the boxes as CSV; with ``--truth`` (a VOT
``groundtruth.txt``) the mean IoU, success rate and success curve
(:func:`~robopercept.tracking.metrics.evaluate_single_object`), ``--plot`` draws the
curve; ``--json`` prints one JSON object (schema in docs/tracking.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import (
    UsageError,
    box_xywh,
    file_output,
    flag_errors,
    image_output,
    positive_int,
)
from robopercept.cli._video import (
    add_video_arguments,
    finish,
    open_source,
    progress,
    text_size,
)

if TYPE_CHECKING:
    import numpy as np

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
    p.add_argument(
        "--box",
        type=box_xywh,
        default=None,
        metavar="X,Y,W,H",
        help="target in frame 0 (default with --truth: its first box)",
    )
    p.add_argument(
        "--feature",
        choices=("hue", "rgb"),
        default="hue",
        help="the target's histogram: of hue (as OpenCV's CamShift sample; pixels too grey "
        "or dark left out), or of RGB colour",
    )
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
    p.add_argument(
        "--truth",
        default=None,
        metavar="GROUNDTRUTH.txt",
        help="VOT ground truth (x,y,w,h or x1,y1,...,x4,y4 per frame): mean IoU, success "
        "rate at IoU 0.5, success curve and its AUC",
    )
    p.add_argument(
        "--plot", type=image_output, default=None, help="with --truth: the success curve, PNG"
    )
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    add_video_arguments(p, "meanshift.mp4")
    p.set_defaults(func=run_meanshift)


@flag_errors(
    box="--box",
    feature="--feature",
    bins="--bins",
    min_saturation="--min-saturation",
    min_value="--min-value",
    truth="--truth",
)
def run_meanshift(args: argparse.Namespace) -> int:
    """Run ``robopercept meanshift`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.tracking.metrics import read_vot_groundtruth

    if args.plot and not args.truth:
        raise UsageError("--plot: the success curve needs --truth GROUNDTRUTH.txt")
    truth = read_vot_groundtruth(args.truth) if args.truth else None
    if args.box is None:
        if truth is None:
            raise UsageError("--box: give the target in frame 0 as X,Y,W,H (or --truth)")
        if np.isnan(truth[0]).any():
            raise UsageError(f"--box: {args.truth} has no target in frame 0; give --box")
        args.box = tuple(float(v) for v in truth[0])
    # --json: stdout holds the JSON object only; the human summary goes to stderr
    with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
        summary = _track(args)
    if truth is not None:
        summary["evaluation"] = _evaluate(args, summary.pop("_boxes"), truth)
    summary.pop("_boxes", None)
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0


def _track(args: argparse.Namespace) -> dict[str, Any]:
    """Track through the video, write the outputs, print the human summary (stdout);
    returns the JSON summary, with the frame indices and boxes under ``_boxes``."""
    import numpy as np

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
    sims = np.array([s for _, _, s in rows[1:]])
    if sims.size:
        print(f"similarity        mean {sims.mean():.3f}, min {sims.min():.3f}")
    finish(source, out.written, frames, seconds)
    return {
        "command": "meanshift",
        "frames": frames,
        "skipped": len(source.skipped),
        "fps": frames / seconds if seconds > 0 else None,
        "box": [float(v) for v in args.box],
        "similarity_mean": float(sims.mean()) if sims.size else None,
        "similarity_min": float(sims.min()) if sims.size else None,
        "outputs": list(out.written),
        "evaluation": None,
        "_boxes": ([i for i, _, _ in rows], np.array([b for _, b, _ in rows]).reshape(-1, 4)),
    }


def _evaluate(
    args: argparse.Namespace, boxes: tuple[list[int], np.ndarray], truth: np.ndarray
) -> dict[str, Any]:
    """``--truth``: the scores of the boxes of frames ``boxes[0]`` (printed unless
    ``--json``), and ``--plot``."""
    from robopercept.imaging import write_image
    from robopercept.tracking.metrics import evaluate_single_object, success_plot

    frames, predicted = boxes
    with flag_errors(truth="--truth"):
        scores = evaluate_single_object(predicted, truth, frames=frames)
    result: dict[str, Any] = {"truth": str(args.truth), **scores.to_dict()}
    if args.plot:
        name = "CamShift" if args.camshift else "mean shift"
        write_image(args.plot, success_plot(scores, f"{name} ({args.feature})", size=(1280, 720)))
        result["plot"] = str(args.plot)
    if not args.json:
        print(
            f"vs truth          mean IoU {scores.mean_iou:.3f}, success (IoU > 0.5) "
            f"{scores.success_50:.3f}, AUC {scores.auc:.3f} over {scores.frames} frames"
            + (f" ({scores.absent} without target)" if scores.absent else "")
        )
        if args.plot:
            print(f"wrote             {args.plot}")
    return result


def _write_boxes_csv(path: Path, rows: list[tuple[int, np.ndarray, float]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["frame,x,y,w,h,similarity"]
    lines += [f"{i},{b[0]:.2f},{b[1]:.2f},{b[2]:.2f},{b[3]:.2f},{s:.4f}" for i, b, s in rows]
    path.write_text("\n".join(lines) + "\n")
