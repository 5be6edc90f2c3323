"""``robopercept demo``, ``plane-track`` and ``synth-rgbd``: the RGB-D plane tracker."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, hsv, positive_int
from robopercept.errors import InputError

__all__ = ["register", "summary_table"]

DEMO_FRAMES = 300


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
    p.add_argument("--no-video", action="store_true", help="skip tracking.mp4")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
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
    p.add_argument("--hsv-low", type=hsv, default=(45, 35, 35), metavar="H,S,V")
    p.add_argument("--hsv-high", type=hsv, default=(65, 255, 255), metavar="H,S,V")
    p.add_argument("--hue-tolerance", type=float, default=None, help="hue as RANSAC feature")
    p.add_argument("--no-video", action="store_true", help="skip tracking.mp4")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_plane_track)

    p = sub.add_parser(
        "synth-rgbd",
        help="write the synthetic RGB-D sequence as a TUM folder",
        description="Write the synthetic scene as rgb/, depth/ (16-bit PNG), rgb.txt, "
        "depth.txt, camera.json and planes.csv (ground truth), readable by "
        "`robopercept plane-track --source OUT_DIR`.",
    )
    p.add_argument("out_dir", help="output folder")
    p.add_argument("--frames", type=positive_int, default=DEMO_FRAMES)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_synth)


def _source(args: argparse.Namespace) -> Any:
    from robopercept.sources import SyntheticRGBDScene, TUMFolderSource
    from robopercept.sources.realsense import RealSenseSource

    src = args.source
    if src == "synthetic":
        return SyntheticRGBDScene(n_frames=args.frames, seed=args.seed)
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


def summary_table(summary: dict[str, Any]) -> str:
    """The figures of :func:`~robopercept.pipelines.run_plane_tracking` as text."""
    lines = [
        f"frames            {summary['frames']} (skipped {summary['skipped_frames']})",
        f"detected          {summary['detected_frames']}",
    ]
    if summary.get("detection_rate") is not None:
        lines.append(
            f"detection rate    {100 * summary['detection_rate']:.1f}% of "
            f"{summary['evaluated_frames']} frames with >= 500 valid board pixels"
        )
    if "raw" in summary:
        lines.append("                  angle median   angle p95   offset median   offset p95")
        for key in ("raw", "tracked"):
            a, o = summary[key]["angle_deg"], summary[key]["offset_mm"]
            lines.append(
                f"{key:<17} {_fmt(a['median'], ' deg'):>12} {_fmt(a['p95'], ' deg'):>11} "
                f"{_fmt(o['median'], ' mm'):>15} {_fmt(o['p95'], ' mm'):>12}"
            )
    jit = summary.get("jitter_deg") or {}
    if jit:
        lines.append(
            f"normal jitter     raw {_fmt(jit.get('raw'), ' deg', 3)}, "
            f"tracked {_fmt(jit.get('tracked'), ' deg', 3)}"
        )
    ms = summary.get("ms_per_stage_median") or {}
    if ms.get("total") is not None:
        stages = ", ".join(f"{k} {v:.1f}" for k, v in ms.items() if k != "total")
        lines.append(
            f"speed             {_fmt(summary.get('fps'), ' fps', 1)} "
            f"({ms['total']:.1f} ms/frame: {stages})"
        )
    wall = summary.get("wall_seconds")
    if wall:
        rate = summary.get("wall_fps_including_source")
        lines.append(
            f"wall time         {wall:.1f} s ({_fmt(rate, ' frames/s', 1)} with the source "
            "and the outputs; the speed above is the tracker alone)"
        )
    if summary.get("stopped"):
        lines.append(f"stopped early     {summary['stopped']}")
    return "\n".join(lines)


def _run(args: argparse.Namespace, source: Any, config: Any) -> int:
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
    print(summary_table(summary))
    stopped = summary.get("stopped") or ""
    if summary["frames"] == 0:  # nothing tracked: not a success, and no video or plot
        why = stopped or f"{summary['skipped_frames']} skipped as unreadable"
        raise InputError(f"no frame was tracked ({why}): check --source")
    print(f"outputs in {args.out}/: {', '.join(summary['outputs'])}")
    if stopped.startswith("source failed"):  # outputs cover the frames before the failure
        raise SourceError(f"{stopped} after {summary['frames']} frames")
    return 130 if stopped == "interrupted" else 0


def _demo(args: argparse.Namespace) -> int:
    from robopercept.pipelines import PlaneTrackerConfig
    from robopercept.sources import SyntheticRGBDScene

    return _run(
        args, SyntheticRGBDScene(n_frames=args.frames, seed=args.seed), PlaneTrackerConfig()
    )


def _plane_track(args: argparse.Namespace) -> int:
    from robopercept.pipelines import PlaneTrackerConfig

    try:  # made from the flags alone: what it refuses is a bad flag value
        config = PlaneTrackerConfig(
            hsv_low=args.hsv_low, hsv_high=args.hsv_high, hue_tolerance=args.hue_tolerance
        )
    except InputError as exc:
        raise UsageError(str(exc)) from exc
    return _run(args, _source(args), config)


def _synth(args: argparse.Namespace) -> int:
    from robopercept.progress import progress_bar
    from robopercept.sources import SyntheticRGBDScene, write_tum_folder

    scene = SyntheticRGBDScene(n_frames=args.frames, seed=args.seed)
    frames = progress_bar(scene, unit="frame", desc="rendering", disable=args.quiet)
    out = write_tum_folder(args.out_dir, frames)
    print(f"wrote {len(scene)} frames to {out}/ (camera.json, planes.csv)", file=sys.stdout)
    return 0
