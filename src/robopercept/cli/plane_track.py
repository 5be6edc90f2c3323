"""``robopercept demo``, ``plane-track`` and ``synth-rgbd``: the RGB-D plane tracker."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import UsageError, hsv, positive_int
from robopercept.cli._constants import SCENE_DISTRACTORS, SCENE_MOTIONS
from robopercept.errors import InputError

if TYPE_CHECKING:
    from robopercept.pipelines import PlaneTrackSummary

__all__ = ["register", "summary_table"]

DEMO_FRAMES = 300
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``demo``, ``plane-track`` and ``synth-rgbd`` commands to the subcommand
    parsers ``sub``."""
    p = sub.add_parser(
        "demo",
        help="the main job: track a green board's plane in the built-in synthetic RGB-D scene",
        description="Render the default synthetic D435-like sequence (seeded), track the "
        "green board's plane in it, write robopercept-out/ (tracking.mp4, plane.csv, "
        "summary.json, plane.png) and print the figures against the ground truth.",
    )
    p.add_argument("--out", default="robopercept-out", help="output folder")
    p.add_argument(
        "--max-frames",
        "--frames",
        dest="frames",
        type=positive_int,
        default=DEMO_FRAMES,
        help=f"frames of the scene to render and track (default {DEMO_FRAMES})",
    )
    p.add_argument("--seed", type=int, default=0, help="scene seed")
    _scene_flags(p)
    _smooth_flag(p)
    p.add_argument("--no-video", action="store_true", help="skip tracking.mp4")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_demo)

    p = sub.add_parser(
        "plane-track",
        help="track a coloured board's plane in RGB-D frames",
        description="Sources: 'synthetic' (the built-in scene), a folder in the TUM "
        "layout with camera.json, a RealSense recording (.bag, .db3), or 'realsense' (a "
        "live camera). Writes plane.csv, tracking.mp4, summary.json and plane.png.",
    )
    p.add_argument(
        "--source", required=True, help="synthetic | DIR | FILE.bag | FILE.db3 | realsense"
    )
    p.add_argument("--out", default="robopercept-out", help="output folder")
    p.add_argument("--max-frames", type=positive_int, default=None, help="stop after N frames")
    p.add_argument("--frames", type=positive_int, default=DEMO_FRAMES, help="synthetic: frames")
    p.add_argument("--seed", type=int, default=0, help="synthetic: scene seed")
    _scene_flags(p, prefix="synthetic: ")
    p.add_argument(
        "--hsv-low",
        type=hsv,
        default=(45, 35, 35),
        metavar="H,S,V",
        help="lower corner of the board's colour box on OpenCV's HSV scale (H 0..180, "
        "degrees / 2; S and V 0..255); a hue above --hsv-high's wraps around red",
    )
    p.add_argument(
        "--hsv-high",
        type=hsv,
        default=(65, 255, 255),
        metavar="H,S,V",
        help="upper corner of the board's colour box, as --hsv-low",
    )
    p.add_argument(
        "--hue-tolerance",
        type=float,
        default=None,
        help="also use hue as a RANSAC feature: an inlier's hue is within this many "
        "OpenCV hue units of the sample's (default: geometry only)",
    )
    _smooth_flag(p)
    p.add_argument("--no-video", action="store_true", help="skip tracking.mp4")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=_plane_track)

    p = sub.add_parser(
        "synth-rgbd",
        help="write the synthetic RGB-D sequence as a TUM folder",
        description="Write the synthetic scene as rgb/, depth/ (16-bit PNG), rgb.txt, "
        "depth.txt, camera.json and planes.csv (ground truth), readable by "
        "`robopercept plane-track --source OUT_DIR`.",
    )
    p.add_argument("out_dir", help="output folder")
    p.add_argument("--frames", type=positive_int, default=DEMO_FRAMES, help="frames to write")
    p.add_argument("--seed", type=int, default=0, help="scene seed")
    _scene_flags(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=_synth)


def _scene_flags(p: argparse.ArgumentParser, prefix: str = "") -> None:
    p.add_argument(
        "--motion",
        choices=SCENE_MOTIONS,
        default="smooth",
        help=f"{prefix}the board's motion profile (default smooth)",
    )
    p.add_argument(
        "--no-occluder",
        dest="occluder",
        action="store_false",
        help=f"{prefix}no grey panel passing in front of the board",
    )
    p.add_argument(
        "--distractor",
        choices=SCENE_DISTRACTORS,
        default="box",
        help=f"{prefix}other green things: a small box, a patch on the wall, both or none",
    )


def _smooth_flag(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--smooth",
        type=int,
        default=2,
        metavar="N",
        help="fixed-lag smoothing: each frame's plane also uses the next N frames "
        "(N frames of latency; default 2); 0: the causal filter",
    )


def _scene(args: argparse.Namespace) -> Any:
    from robopercept.sources import SyntheticRGBDScene

    return SyntheticRGBDScene(
        n_frames=args.frames,
        seed=args.seed,
        motion=args.motion,
        occluder=args.occluder,
        distractor=args.distractor,
    )


def _source(args: argparse.Namespace) -> Any:
    from robopercept.sources import TUMFolderSource
    from robopercept.sources.realsense import RealSenseSource

    src = args.source
    if src == "synthetic":
        return _scene(args)
    if src == "realsense":
        return RealSenseSource(None, max_frames=args.max_frames)
    path = Path(src)
    if path.suffix.lower() in (".bag", ".db3"):
        return RealSenseSource(path)
    if path.is_dir():
        return TUMFolderSource(path)
    raise UsageError(
        f"--source {src}: not 'synthetic', 'realsense', a folder or a .bag/.db3 recording"
    )


def _fmt(v: float | None, unit: str = "", digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}{unit}"


def summary_table(summary: PlaneTrackSummary) -> str:
    """The figures of :func:`~robopercept.pipelines.run_plane_tracking` as text."""
    s = summary
    counts = ", ".join(f"{k} {v}" for k, v in s.status_counts.items() if v)
    lines = [
        f"frames            {s.frames} (skipped {s.skipped_frames})",
        f"plane measured    {s.measured_frames}, accepted {s.accepted_frames} ({counts})",
    ]
    if s.detection_rate is not None:
        lines.append(
            f"detection rate    {100 * s.detection_rate:.1f}% of "
            f"{s.evaluated_frames} frames with >= 500 valid board pixels"
        )
    if s.raw is not None and s.tracked is not None:
        lines.append("                  angle median   angle p95   offset median   offset p95")
        for key, e in (("raw fit", s.raw), ("tracked", s.tracked)):
            a, o = e.angle_deg, e.offset_mm
            lines.append(
                f"{key:<17} {_fmt(a.median, ' deg', 3):>12} {_fmt(a.p95, ' deg', 3):>11} "
                f"{_fmt(o.median, ' mm'):>15} {_fmt(o.p95, ' mm'):>12}"
            )
    if s.jitter_raw_deg is not None or s.jitter_tracked_deg is not None:
        lines.append(
            f"normal jitter     raw {_fmt(s.jitter_raw_deg, ' deg', 3)}, "
            f"tracked {_fmt(s.jitter_tracked_deg, ' deg', 3)}"
        )
    ms = s.ms_per_stage_median
    if ms.get("total") is not None:
        stages = ", ".join(f"{k} {v:.1f}" for k, v in ms.items() if k != "total")
        lines.append(
            f"tracker speed     {_fmt(s.fps, ' fps', 1)} ({ms['total']:.1f} ms/frame "
            f"median, the tracker's own work: {stages})"
        )
    if s.wall_seconds:
        lines.append(
            f"wall time         {s.wall_seconds:.1f} s ({_fmt(s.wall_fps, ' frames/s', 1)} "
            "with the source and the outputs)"
        )
    if s.stopped:
        lines.append(f"stopped early     {s.stopped}")
    return "\n".join(lines)


def _scene_dict(args: argparse.Namespace) -> dict[str, Any]:
    """The synthetic scene's flags (the settings of :class:`SyntheticRGBDScene`)."""
    return {
        "frames": args.frames,
        "seed": args.seed,
        "motion": args.motion,
        "occluder": args.occluder,
        "distractor": args.distractor,
    }


def _report(args: argparse.Namespace, config: Any, summary: PlaneTrackSummary) -> dict[str, Any]:
    """What ``demo --json`` and ``plane-track --json`` print: the inputs and settings,
    and ``summary``, the object written to ``summary.json`` (unchanged)."""
    source = getattr(args, "source", "synthetic")
    return {
        "source": source,
        "out_dir": str(args.out),
        "max_frames": getattr(args, "max_frames", None),
        "video": not args.no_video,
        "scene": _scene_dict(args) if source == "synthetic" else None,
        "config": dataclasses.asdict(config),
        "summary": summary.to_dict(),
    }


def _run(args: argparse.Namespace, source: Any, config: Any) -> int:
    from robopercept.fileio import WriteError
    from robopercept.pipelines.plane_outputs import run_plane_tracking
    from robopercept.sources.realsense import SourceError

    summary = run_plane_tracking(
        source,
        args.out,
        config=config,
        max_frames=getattr(args, "max_frames", None),
        video=not args.no_video,
        fps=30.0,
        progress=not args.quiet,
    )
    if args.json:
        print(json.dumps(_report(args, config, summary), indent=2, default=float))
    else:
        print(summary_table(summary))
    stopped = summary.stopped or ""
    if stopped.startswith("output failed"):  # a full disk: what was written is kept
        if not args.json and summary.outputs:
            print(f"outputs in {args.out}/: {', '.join(summary.outputs)}")
        lost = [n for n in ("plane.png", "summary.json") if n not in summary.outputs]
        raise WriteError(
            f"{stopped} (after {summary.frames} frames"
            + (f"; {' and '.join(lost)} not written" if lost else "")
            + "): free some space or choose another --out"
        )
    if summary.frames == 0:  # nothing tracked: not a success, and no video or plot
        skipped = getattr(source, "skipped", None) or []
        reason = str(skipped[0][1]).splitlines()[0] if isinstance(skipped, list) and skipped else ""
        first = f"; first: {reason}" if reason else ""
        why = stopped or f"{summary.skipped_frames} skipped as unreadable{first}"
        raise InputError(f"no frame was tracked ({why}): check --source")
    if not args.json:
        print(f"outputs in {args.out}/: {', '.join(summary.outputs)}")
    if summary.skipped_frames:
        print(
            f"robopercept: warning: {summary.skipped_frames} frames skipped (missing, "
            "unreadable or of the wrong size; listed in the warnings above)",
            file=sys.stderr,
        )
    if stopped.startswith("source failed"):  # outputs cover the frames before the failure
        raise SourceError(f"{stopped} after {summary.frames} frames")
    if stopped == "interrupted":
        print(
            f"robopercept: interrupted (Ctrl-C) after {summary.frames} frames; the outputs "
            "cover them",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if stopped.startswith("stopped by SIGTERM"):
        print(
            f"robopercept: stopped by SIGTERM after {summary.frames} frames; the outputs "
            "cover them",
            file=sys.stderr,
        )
        return EXIT_TERMINATED
    return 0


def _demo(args: argparse.Namespace) -> int:
    from robopercept.pipelines import PlaneTrackerConfig

    try:
        config = PlaneTrackerConfig(smoothing_lag=args.smooth)
    except InputError as exc:
        raise UsageError(str(exc).replace("smoothing_lag", "--smooth")) from exc
    return _run(args, _scene(args), config)


def _plane_track(args: argparse.Namespace) -> int:
    from robopercept.pipelines import PlaneTrackerConfig

    try:  # made from the flags alone: what it refuses is a bad flag value
        config = PlaneTrackerConfig(
            hsv_low=args.hsv_low,
            hsv_high=args.hsv_high,
            hue_tolerance=args.hue_tolerance,
            smoothing_lag=args.smooth,
        )
    except InputError as exc:
        raise UsageError(str(exc).replace("smoothing_lag", "--smooth")) from exc
    return _run(args, _source(args), config)


def _synth(args: argparse.Namespace) -> int:
    from robopercept.progress import progress_bar
    from robopercept.sources import write_tum_folder

    scene = _scene(args)
    frames = progress_bar(scene, unit="frame", desc="rendering", disable=args.quiet)
    out = write_tum_folder(args.out_dir, frames)
    if args.json:
        names = ("rgb", "depth", "rgb.txt", "depth.txt", "camera.json", "planes.csv")
        report = {
            "out_dir": str(out),
            **_scene_dict(args),
            "files": [n for n in names if (out / n).exists()],
        }
        print(json.dumps(report, indent=2))
    else:
        print(f"wrote {len(scene)} frames to {out}/ (camera.json, planes.csv)")
    return 0
