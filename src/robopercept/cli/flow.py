"""``robopercept flow``: Lucas-Kanade optical flow between two images (arrows or a
colour-coded grid, and the motion named), or KLT point tracks through a video or a
folder of images (:class:`~robopercept.motion.KLTTracker`).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from robopercept.cli._args import UsageError, check_output, flag_errors, positive_int
from robopercept.cli._video import (
    add_video_arguments,
    finish,
    open_source,
    progress,
    text_size,
)

#: the library's parameters and the flags that set them
FLAGS = {
    "window": "--window",
    "levels": "--levels",
    "max_corners": "--max-corners",
    "quality": "--quality",
    "min_distance": "--min-distance",
    "step": "--step",
    "trail": "--trail",
    "scale": "--scale",
}

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``flow`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "flow",
        help="Lucas-Kanade optical flow between two images, or point tracks through a video",
        description="Two images A B: Shi-Tomasi corners of A tracked into B, drawn as arrows "
        "(or, with --dense, the flow on a grid coloured by the HSV wheel), and the motion "
        "classified as translation, rotation or zoom; --truth FILE.flo measures the "
        "endpoint error. One video: corners tracked frame to frame and drawn with their "
        "trails; lost corners are replaced.",
    )
    p.add_argument("inputs", nargs="+", help="A B (two images) or VIDEO (file or folder)")
    p.add_argument("--window", type=int, default=21, help="odd window side (default 21)")
    p.add_argument("--levels", type=int, default=3, help="pyramid levels above the image")
    p.add_argument(
        "--max-corners", type=positive_int, default=500, help="most Shi-Tomasi corners tracked"
    )
    p.add_argument("--quality", type=float, default=0.01, help="Shi-Tomasi quality level")
    p.add_argument("--min-distance", type=float, default=7.0, help="corner spacing (px)")
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        help="two images: arrow lengthening (default: automatic, the median arrow at "
        "least 2%% of the image diagonal; the factor is printed)",
    )
    p.add_argument("--dense", action="store_true", help="two images: colour-coded grid flow")
    p.add_argument("--step", type=positive_int, default=4, help="--dense: grid step (px)")
    p.add_argument("--trail", type=positive_int, default=15, help="video: trail length")
    p.add_argument(
        "--truth",
        default=None,
        help="two images: ground-truth flow of A -> B (Middlebury .flo): prints the endpoint "
        "error (mean, median, share over 1 and 3 px) of the tracked points or grid",
    )
    p.add_argument("--json", action="store_true", help="print the result as one JSON object")
    add_video_arguments(
        p,
        None,
        "output: an image for two images (default flow.png), a video (.mp4, .avi, ...) for "
        "one video (default flow.mp4)",
        video=False,
    )
    p.set_defaults(func=run_flow)


def _flow_pair(args: argparse.Namespace) -> int:
    import numpy as np

    from robopercept.errors import DegenerateError, InputError
    from robopercept.imaging import read_image, write_image
    from robopercept.motion import (
        FlowStatus,
        classify_motion,
        dense_flow,
        endpoint_error,
        good_features_to_track,
        lucas_kanade,
        read_flo,
    )
    from robopercept.viz import dense_flow_picture, draw_flow, draw_text
    from robopercept.viz.flow import ARROW_FRACTION, arrow_scale

    a, b = (read_image(p, mode="rgb") for p in args.inputs)
    if a.shape != b.shape:
        raise InputError(
            f"the two images must have the same size; got {a.shape[1]}x{a.shape[0]} and "
            f"{b.shape[1]}x{b.shape[0]}"
        )
    truth = None
    if args.truth:
        truth = read_flo(args.truth)
        if truth.shape[:2] != a.shape[:2]:
            raise InputError(
                f"--truth is {truth.shape[1]}x{truth.shape[0]}, the images "
                f"{a.shape[1]}x{a.shape[0]}: give the ground truth of this pair"
            )
    output = Path(args.output or "flow.png")
    lk = {"window": args.window, "levels": args.levels}
    t0 = time.perf_counter()
    scale = None
    if args.dense:
        grid, field, res = dense_flow(a, b, step=args.step, **lk)
        points, vectors = grid.reshape(-1, 2), field.reshape(-1, 2)
        picture = dense_flow_picture(field, args.step, a.shape)
    else:
        corners = good_features_to_track(a, args.max_corners, args.quality, args.min_distance)
        res = lucas_kanade(a, b, corners, **lk)
        points, vectors = res.start, np.where(res.status[:, None], res.flow, np.nan)
        scale = args.scale
        if scale is None:
            scale = arrow_scale(vectors, (a.shape[1], a.shape[0]))
        picture = draw_flow(a, res.start, res.end, status=res.status, scale=scale)
    ms = 1000 * (time.perf_counter() - t0)
    try:
        motion = classify_motion(points, vectors)
        kind = motion.kind
        desc = (
            f"{kind}: translation ({motion.translation[0]:+.2f}, {motion.translation[1]:+.2f}) "
            f"px, rotation {np.degrees(motion.rotation):+.2f} deg, scale {motion.scale:.4f}, "
            f"residual {motion.residual:.2f} px"
        )
    except DegenerateError:
        motion, kind, desc = None, "unknown", "unknown: fewer than 2 tracked points"
    label = desc.split(":")[0] + ("" if scale is None else f", arrows x{scale:g}")
    picture = draw_text(picture, label, (5, 5), size=text_size(a))
    write_image(output, picture)
    error = None
    if truth is not None:
        with flag_errors(truth="--truth"):
            error = endpoint_error(vectors, truth, points)
    reasons = np.bincount(res.reason.astype(np.int64), minlength=len(FlowStatus))
    median_flow = float(np.nanmedian(np.hypot(*vectors.T))) if res.status.any() else None
    summary = {
        "mode": "dense" if args.dense else "sparse",
        "points": len(res),
        "tracked": int(res.status.sum()),
        "aperture": int(reasons[FlowStatus.APERTURE]),
        "left_image": int(reasons[FlowStatus.LEFT_IMAGE]),
        "not_converged": int(reasons[FlowStatus.NOT_CONVERGED]),
        "high_residual": int(reasons[FlowStatus.HIGH_RESIDUAL]),
        "median_flow_px": median_flow,
        "arrow_scale": scale,
        "arrow_scale_auto": scale is not None and args.scale is None,
        "median_arrow_px": None if scale is None or median_flow is None else scale * median_flow,
        "motion": kind,
        "translation": None if motion is None else motion.translation.tolist(),
        "rotation_deg": None if motion is None else float(np.degrees(motion.rotation)),
        "scale": None if motion is None else motion.scale,
        "truth": None,
        "ms": ms,
        "output": str(output),
    }
    if error is not None:
        summary["truth"] = {
            "file": str(args.truth),
            "epe_mean_px": error.mean,
            "epe_median_px": error.median,
            "over_1px_percent": 100.0 * error.over_1,
            "over_3px_percent": 100.0 * error.over_3,
            "evaluated": error.evaluated,
            "unknown_truth": error.unknown_truth,
            "no_estimate": error.no_estimate,
        }
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"points            {summary['points']} ({summary['tracked']} tracked)")
    print(
        f"flagged           aperture {summary['aperture']}, left image "
        f"{summary['left_image']}, not converged {summary['not_converged']}, high residual "
        f"{summary['high_residual']}"
    )
    print(f"motion            {desc}")
    if scale is not None:
        how = (
            f"automatic: median arrow {summary['median_arrow_px']:.1f} px, at least "
            f"{100 * ARROW_FRACTION:g}% of the diagonal; --scale overrides"
            if summary["arrow_scale_auto"] and median_flow is not None
            else ("automatic: nothing tracked" if summary["arrow_scale_auto"] else "--scale")
        )
        print(f"arrows            x{scale:g} ({how})")
    if error is not None:
        print(
            f"vs truth          EPE mean {error.mean:.3f} px, median {error.median:.3f} px, "
            f"> 1 px {100 * error.over_1:.1f}%, > 3 px {100 * error.over_3:.1f}% "
            f"({error.evaluated} vectors; {error.unknown_truth} unknown truth, "
            f"{error.no_estimate} untracked)"
        )
    print(f"time              {ms:.1f} ms")
    print(f"wrote             {output}")
    return 0


def _flow_video(args: argparse.Namespace) -> int:
    import numpy as np

    from robopercept.errors import FileFormatError
    from robopercept.imaging import SnapshotVideoWriter
    from robopercept.motion import KLTTracker
    from robopercept.viz import draw_text, draw_trails, label_colors

    source = open_source(args.inputs[0], args, min_frames=2)  # tracks need two frames
    output = args.output or "flow.mp4"
    tracker = KLTTracker(
        args.max_corners,
        args.quality,
        args.min_distance,
        window=args.window,
        levels=args.levels,
        trail=args.trail,
    )
    kinds: dict[str, int] = {}
    tracked_counts: list[int] = []
    frames = 0
    t0 = time.perf_counter()
    with (
        SnapshotVideoWriter(output, source.fps, args.snapshot) as out,
        progress(source, "flow", args.quiet) as bar,
    ):
        for i, frame in source:
            step = tracker.update(frame)
            if step.motion is not None:
                kinds[step.motion] = kinds.get(step.motion, 0) + 1
            tracked_counts.append(len(step))
            picture = draw_trails(frame, step.trails, colors=label_colors(step.ids))
            picture = draw_text(
                picture, f"{len(step)} points, {step.motion or '-'}", (5, 5), size=text_size(frame)
            )
            out.add(i, picture)
            frames += 1
            bar.update(1)
    seconds = time.perf_counter() - t0
    if args.json:
        if frames == 0:
            raise FileFormatError(
                f"no frame of {source.path} could be read ({len(source.skipped)} skipped as "
                "unreadable): nothing was processed"
            )
        summary = {
            "mode": "video",
            "frames": frames,
            "skipped": len(source.skipped),
            "fps": frames / seconds if seconds > 0 else None,
            "mean_tracked": float(np.mean(tracked_counts)),
            "redetections": tracker.redetections,
            "motion": dict(sorted(kinds.items())),
            "outputs": list(out.written),
        }
        print(json.dumps(summary, indent=2))
        return 0
    if tracked_counts:
        print(f"points            {np.mean(tracked_counts):.0f} tracked per frame on average")
    print(
        f"detections        {tracker.redetections} (corners re-detected below "
        f"{args.max_corners // 2})"
    )
    if kinds:
        print("motion            " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    return finish(source, out.written, frames, seconds)


@flag_errors(**FLAGS)
def run_flow(args: argparse.Namespace) -> int:
    """Run ``robopercept flow`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    if len(args.inputs) == 2:
        if args.output:
            check_output(args.output, "image")
        if args.scale is not None and not (args.scale > 0 and np.isfinite(args.scale)):
            raise UsageError(f"--scale must be a positive number; got {args.scale:g}")
        return _flow_pair(args)
    if len(args.inputs) == 1:
        if args.truth:
            raise UsageError("--truth compares the flow of two images A B; got one video")
        if args.output:
            check_output(args.output, "video")
        return _flow_video(args)
    raise UsageError(f"flow takes two images (A B) or one video; got {len(args.inputs)} inputs")
