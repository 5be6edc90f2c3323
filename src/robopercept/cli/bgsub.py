"""``robopercept bgsub``: background subtraction or frame differencing on a video (any
file ffmpeg reads) or a folder of images (sorted by name).

Writes the foreground as a red overlay with blob boxes (or overlay | background | mask
side by side), optionally every mask as a PNG, and prints the foreground share and the
blobs per frame (``--json``: one JSON object with the same figures and every frame's
blob boxes; see ``_json_report``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import deque
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import flag_errors, noise_filter, positive_int
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

BGSUB_METHODS = ("static", "average", "gaussian", "diff", "diff3")


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``bgsub`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "bgsub",
        help="background subtraction or frame differencing on a video",
        description="Find moving objects with a background model (static: the first frame "
        "or --reference; average: mean of the first frames; gaussian: per-pixel running "
        "Gaussian) or by differencing (diff: frame n back; diff3: three-frame AND, no "
        "ghosts; --gap frames apart, then a closing and hole filling). Writes the foreground as a "
        "red overlay with blob boxes.",
    )
    p.add_argument("video", help="video file or folder of images")
    p.add_argument(
        "--method",
        choices=BGSUB_METHODS,
        default="gaussian",
        help="the background model or differencing scheme (the description above)",
    )
    p.add_argument("--reference", default=None, help="static: image of the empty scene")
    p.add_argument(
        "--threshold",
        type=float,
        default=None,
        help="0-255 (static/average 30, diff 25, diff3 15)",
    )
    p.add_argument("--k", type=float, default=2.5, help="gaussian: threshold in std devs")
    p.add_argument("--learning-rate", type=float, default=0.02, help="gaussian: alpha")
    p.add_argument("--init-frames", type=positive_int, default=20, help="average/gaussian")
    p.add_argument("--n", type=positive_int, default=1, help="diff: frames between the two")
    p.add_argument(
        "--gap",
        type=positive_int,
        default=3,
        help="diff3: frames between the three (default 3; the mask is GAP frames late)",
    )
    p.add_argument(
        "--noise", type=noise_filter, default="median", help="median | open-close | none"
    )
    p.add_argument(
        "--noise-size",
        type=positive_int,
        default=3,
        help="side of the --noise filter's window (pixels)",
    )
    p.add_argument("--min-area", type=positive_int, default=100, help="smallest blob (pixels)")
    p.add_argument("--gray", action="store_true", help="work on gray frames (faster)")
    p.add_argument(
        "--layout",
        choices=("overlay", "panels"),
        default="overlay",
        help="overlay only, or overlay | background | mask side by side",
    )
    p.add_argument("--masks", default=None, help="also write each mask as DIR/NNNNNN.png")
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (figures and every frame's blob boxes) instead of text",
    )
    add_video_arguments(p, "bgsub.mp4")
    p.set_defaults(func=run_bgsub)


@flag_errors(
    k="--k",
    learning_rate="--learning-rate",
    init_frames="--init-frames",
    n_frames="--init-frames",
    threshold="--threshold",
    n="--n",
    gap="--gap",
    noise="--noise",
    noise_size="--noise-size",
    **{"noise size": "--noise-size"},
)
def _bg_model(args: argparse.Namespace, first: np.ndarray) -> Any:
    from robopercept.imaging import read_image
    from robopercept.motion import (
        AveragedBackground,
        FrameDifference,
        GaussianBackground,
        StaticBackground,
        ThreeFrameDifference,
    )

    clean = {"noise": args.noise, "noise_size": args.noise_size}
    m = args.method
    if m == "static":
        ref = first if args.reference is None else read_image(args.reference, mode="rgb")
        return StaticBackground(_prepare(ref, args.gray), args.threshold or 30.0, **clean)
    if m == "average":
        return AveragedBackground(args.init_frames, args.threshold or 30.0, **clean)
    if m == "gaussian":
        return GaussianBackground(args.k, args.learning_rate, init_frames=args.init_frames, **clean)
    if m == "diff":
        return FrameDifference(args.n, args.threshold or 25.0, **clean)
    return ThreeFrameDifference(args.threshold or 15.0, args.gap, **clean)


def _prepare(frame: np.ndarray, gray: bool) -> np.ndarray:
    from robopercept.imaging import rgb_to_gray

    return rgb_to_gray(frame) if gray else frame


def _bg_picture(
    frame: np.ndarray,
    mask: np.ndarray,
    boxes: np.ndarray,
    background: np.ndarray | None,
    layout: str,
    label: str = "background",
) -> np.ndarray:
    import numpy as np

    from robopercept.viz import draw_boxes, draw_mask, draw_text
    from robopercept.viz.draw import to_rgb8

    over = draw_boxes(draw_mask(frame, mask, color=(255, 0, 0), alpha=0.45), boxes, width=2)
    over = draw_text(over, f"{len(boxes)} blob(s)", (5, 5), size=text_size(frame))
    if layout == "overlay":
        return over
    if background is None:
        bg = np.zeros_like(over)
    else:
        bg = to_rgb8(np.clip(np.round(np.asarray(background)), 0, 255).astype(np.uint8))
    bg = draw_text(bg, label, (5, 5), size=text_size(frame))
    mk = draw_text(to_rgb8(mask), "mask", (5, 5), size=text_size(frame))
    return np.concatenate([over, bg, mk], axis=1)


def run_bgsub(args: argparse.Namespace) -> int:
    """Run ``robopercept bgsub`` with the parsed ``args``; returns the exit status."""
    import numpy as np

    from robopercept.imaging import SnapshotVideoWriter, write_image
    from robopercept.motion import detections_from_mask

    source = open_source(args.video, args)
    masks_dir = Path(args.masks) if args.masks else None
    n_masks = 0
    model: Any = None
    delay = args.gap if args.method == "diff3" else 0  # ThreeFrameDifference.delay
    label = {"diff": f"frame t-{args.n}", "diff3": "(no background model)"}.get(
        args.method, "background"
    )
    per_frame: list[dict[str, Any]] = []
    held: deque[tuple[int, np.ndarray]] = deque()
    fractions: list[float] = []
    blobs = frames = 0
    t0 = time.perf_counter()
    with (
        SnapshotVideoWriter(args.output, source.fps, args.snapshot) as out,
        progress(source, f"bgsub {args.method}", args.quiet) as bar,
    ):

        def emit(
            index: int, frame: np.ndarray, mask: np.ndarray, background: np.ndarray | None
        ) -> None:
            nonlocal blobs, n_masks
            det = detections_from_mask(mask, args.min_area)
            blobs += len(det)
            fractions.append(float(mask.mean()))
            if args.json:
                per_frame.append(
                    {
                        "frame": int(index),
                        "foreground": round(fractions[-1], 6),
                        "boxes": det.boxes.astype(int).tolist(),
                        "areas": det.areas.tolist(),
                    }
                )
            out.add(index, _bg_picture(frame, mask, det.boxes, background, args.layout, label))
            if masks_dir is not None:
                write_image(masks_dir / f"{index:06d}.png", mask.astype(np.uint8) * 255)
                n_masks += 1

        for i, frame in source:
            work = _prepare(frame, args.gray)
            if model is None:
                model = _bg_model(args, work)
            background = None if model.background is None else model.background.copy()
            mask = model.apply(work)
            frames += 1
            held.append((i, frame))
            if len(held) > delay:
                j, shown = held.popleft()
                emit(j, shown, mask, background if delay == 0 else None)
            bar.update(1)
        for j, shown in held:  # diff3: the last GAP frames have no later frame to compare
            emit(j, shown, np.zeros(shown.shape[:2], dtype=bool), None)
    seconds = time.perf_counter() - t0
    if n_masks:
        out.written.append(f"{masks_dir}/ ({n_masks} masks)")
    if args.json:
        return _print_json(args, source, out.written, per_frame, frames, seconds)
    print(f"method            {args.method}")
    if fractions:
        print(f"foreground        {100 * float(np.mean(fractions)):.2f}% of pixels on average")
        print(f"blobs             {blobs / len(fractions):.2f} per frame (>= {args.min_area} px)")
    return finish(source, out.written, frames, seconds)


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    """The method's settings as used (defaults filled in)."""
    m = args.method
    clean = {"noise": args.noise, "noise_size": args.noise_size, "gray": bool(args.gray)}
    if m in ("static", "average"):
        out: dict[str, Any] = {"threshold": args.threshold or 30.0}
        if m == "average":
            out["init_frames"] = args.init_frames
        elif args.reference is not None:
            out["reference"] = args.reference
    elif m == "gaussian":
        out = {"k": args.k, "learning_rate": args.learning_rate, "init_frames": args.init_frames}
    elif m == "diff":
        out = {"threshold": args.threshold or 25.0, "n": args.n}
    else:
        out = {"threshold": args.threshold or 15.0, "gap": args.gap, "delay": args.gap}
    return {**out, **clean}


def _json_report(
    video: str,
    method: str,
    settings: dict[str, Any],
    min_area: int,
    per_frame: list[dict[str, Any]],
    frames: int,
    skipped: list[tuple[int, str]],
    seconds: float,
    written: list[str],
) -> dict[str, Any]:
    """The ``robopercept bgsub --json`` object.

    Keys: ``command`` ("bgsub"), ``video``, ``method``, ``settings`` (the method's
    settings as used), ``min_area`` (px), ``frames`` (processed), ``skipped`` (count),
    ``skipped_frames`` (``[index, message]`` pairs), ``seconds``, ``fps``,
    ``foreground_mean`` (mean share of foreground pixels, 0-1), ``blobs_per_frame``,
    ``per_frame`` (one ``{"frame", "foreground", "boxes", "areas"}`` per frame, boxes
    ``[x, y, w, h]`` of the blobs >= ``min_area`` px, largest first) and ``written``.

    Examples
    --------
    >>> rows = [{"frame": 0, "foreground": 0.5, "boxes": [[0, 0, 2, 2]], "areas": [4]}]
    >>> r = _json_report("v.mp4", "diff", {}, 1, rows, 1, [], 0.5, ["o.mp4"])
    >>> r["blobs_per_frame"], r["fps"], r["foreground_mean"]
    (1.0, 2.0, 0.5)
    """
    import numpy as np

    n = len(per_frame)
    return {
        "command": "bgsub",
        "video": str(video),
        "method": method,
        "settings": settings,
        "min_area": int(min_area),
        "frames": int(frames),
        "skipped": len(skipped),
        "skipped_frames": [[int(i), str(msg)] for i, msg in skipped],
        "seconds": round(seconds, 3),
        "fps": round(frames / seconds, 2) if seconds > 0 else None,
        "foreground_mean": round(float(np.mean([r["foreground"] for r in per_frame])), 6)
        if n
        else 0.0,
        "blobs_per_frame": round(sum(len(r["boxes"]) for r in per_frame) / n, 4) if n else 0.0,
        "per_frame": per_frame,
        "written": list(written),
    }


def _print_json(
    args: argparse.Namespace,
    source: Any,
    written: list[str],
    per_frame: list[dict[str, Any]],
    frames: int,
    seconds: float,
) -> int:
    """Print the ``--json`` object (skipped frames also named on stderr); exit 1 when no
    frame could be read, as :func:`~robopercept.cli._video.finish`."""
    from robopercept.errors import FileFormatError

    if source.skipped:
        print(
            f"skipped {len(source.skipped)} unreadable frame(s), first: {source.skipped[0][1]}",
            file=sys.stderr,
        )
    if frames == 0:
        raise FileFormatError(
            f"no frame of {source.path} could be read ({len(source.skipped)} skipped as "
            "unreadable): nothing was processed"
        )
    report = _json_report(
        args.video, args.method, _settings(args), args.min_area, per_frame, frames,
        list(source.skipped), seconds, written,
    )  # fmt: skip
    print(json.dumps(report))
    return 0
