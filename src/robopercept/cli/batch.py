"""``robopercept batch``: one job over many inputs on a Dask cluster (local or remote)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from robopercept.cli._args import (
    UsageError,
    flag_errors,
    in_flags,
    non_negative_int,
    numbers,
    positive_float,
    positive_int,
)
from robopercept.cli._constants import BATCH_JOBS as JOBS
from robopercept.cli._constants import BATCH_MAX_WORKERS as MAX_WORKERS
from robopercept.errors import ArgumentError

__all__ = ["register"]


def _workers(text: str) -> int:
    """A worker count in ``[1, MAX_WORKERS]`` (argparse type)."""
    v = positive_int(text)
    if v > MAX_WORKERS:
        raise argparse.ArgumentTypeError(
            f"must be at most {MAX_WORKERS} (each local worker is a process); got {v}: "
            "give about the number of cores"
        )
    return v


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``batch`` command to the ``robopercept`` subcommand parsers ``sub``."""
    p = sub.add_parser(
        "batch",
        help="run one job over many inputs on a Dask cluster (local or tcp://)",
        description="Run JOB on every input (files, folders of matching files, glob "
        "patterns; recording folders for plane-track), each as a Dask task, writing "
        "OUT/<item>/ and the manifest OUT/batch.json (rewritten as items finish). A failed "
        "item is recorded and the batch goes on; exit 1 when every item failed. Jobs: "
        "cloud (PCD/PLY -> segments.ply), edges (image -> edges.png), features (image -> "
        "keypoints.json), stereo (pair folder: left/right, im0/im1, im2/im6 or view1/view5 -> "
        "disparity.npy and disparity.png), plane-track (recording folder or .bag/.db3 -> its "
        "outputs), "
        "nn-predict, nn-detect, nn-segment, nn-pose (image -> prediction.json and the pictures "
        "of `robopercept nn predict|detect|segment|pose`), nn-cloud (PLY/PCD/OFF -> "
        "prediction.json: the class and probabilities of `robopercept nn cloud`). Dask's "
        "logs (worker tracebacks among them) go to OUT/batch.log, never the terminal; a "
        "failed item is one line on stderr.",
    )
    p.add_argument("job", choices=JOBS, help="the job run on each input")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="files, folders or globs")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument(
        "--scheduler",
        default="local",
        help="'local' (default: a LocalCluster of --workers processes) or the address of a "
        "running scheduler, tcp://HOST:PORT (HOST a name, an IPv4 address or [IPv6]; its "
        "workers must see the same files); tls://, ucx:// and others are refused",
    )
    p.add_argument(
        "--workers",
        type=_workers,
        default=2,
        help=f"local workers, 1 to {MAX_WORKERS} (default: %(default)s)",
    )
    p.add_argument(
        "--retries",
        type=non_negative_int,
        default=1,
        help="reruns of an item that failed (default: %(default)s)",
    )
    p.add_argument(
        "--connect-timeout",
        type=positive_float,
        default=10.0,
        metavar="SECONDS",
        help="wait this long for --scheduler ADDRESS (default: %(default)s)",
    )
    again = p.add_mutually_exclusive_group()
    again.add_argument(
        "--resume",
        action="store_true",
        help="skip the items OUT/batch.json has as done and run the others; the job and its "
        "options must be those the manifest records (else exit 2: use --overwrite)",
    )
    again.add_argument("--overwrite", action="store_true", help="run every item again")
    p.add_argument("--voxel", type=float, default=None, metavar="SIZE", help="cloud: voxel (m)")
    p.add_argument(
        "--planes",
        type=numbers((int, float), "N:THRESHOLD"),
        default=None,
        metavar="N:THRESHOLD",
        help="cloud: extract up to N planes (RANSAC threshold in metres)",
    )
    p.add_argument(
        "--method",
        choices=("canny", "sobel", "sgm", "bm"),
        default=None,
        help="edges: canny (default) or sobel; stereo: sgm (default) or bm",
    )
    p.add_argument(
        "--detector",
        choices=("harris", "shi-tomasi"),
        default=None,
        help="features: harris (default) or shi-tomasi",
    )
    p.add_argument(
        "--max-disparity", type=positive_int, default=None, help="stereo (required): largest d"
    )
    p.add_argument("--min-disparity", type=int, default=None, help="stereo: smallest d (0)")
    lr = p.add_mutually_exclusive_group()
    lr.add_argument(
        "--lr-check",
        type=float,
        default=None,
        metavar="PX",
        help="stereo: left-right consistency tolerance in pixels (default 1)",
    )
    lr.add_argument(
        "--no-lr-check", action="store_true", help="stereo: keep every pixel's best match"
    )
    p.add_argument(
        "--max-frames", type=positive_int, default=None, help="plane-track: frames per item"
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL",
        help="nn-*: a run folder or model file (nn-predict: required), or a shipped model: "
        "nn-detect fcos (default) or faster, nn-segment unet (default) or maskrcnn, nn-pose "
        "hrnet (default) or deeppose, nn-cloud pointnet (default) or dgcnn",
    )
    p.add_argument(
        "--top-k", type=positive_int, default=None, help="nn-predict: classes per image (3)"
    )
    p.add_argument(
        "--score-thresh",
        type=float,
        default=None,
        help="nn-detect, nn-segment: smallest score kept (default: the command's)",
    )
    p.add_argument(
        "--points",
        type=positive_int,
        default=None,
        help="nn-cloud: points sampled per cloud (default: the model's)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=run_batch_command)


#: each option's flag (an option is given when its flag was)
_FLAGS = {
    "voxel": "--voxel",
    "planes": "--planes",
    "method": "--method",
    "detector": "--detector",
    "max_disparity": "--max-disparity",
    "min_disparity": "--min-disparity",
    "lr_check": "--lr-check",
    "max_frames": "--max-frames",
    "model": "--model",
    "top_k": "--top-k",
    "score_thresh": "--score-thresh",
    "points": "--points",
}


@flag_errors(
    workers="--workers",
    retries="--retries",
    connect_timeout="--connect-timeout",
    resume="--resume",
    overwrite="--overwrite",
    voxel_size="--voxel",
    max_planes="--planes N",
    threshold="--planes THRESHOLD",
    **_FLAGS,
)
def run_batch_command(args: argparse.Namespace) -> int:
    """Run ``robopercept batch`` with the parsed ``args``; returns the exit status."""
    from robopercept.pipelines.batch import JOB_OPTIONS, run_batch
    from robopercept.progress import format_rate

    options: dict[str, Any] = {}
    if args.no_lr_check:
        args.lr_check = "off"
    for name, flag in _FLAGS.items():
        given = getattr(args, name)
        if given is None:
            continue
        if name not in JOB_OPTIONS[args.job]:
            raise UsageError(f"{flag} does not apply to the {args.job} job")
        options[name] = None if given == "off" else given
    out = Path(args.output)
    try:
        result = run_batch(
            args.job,
            args.inputs,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            retries=args.retries,
            resume=args.resume,
            overwrite=args.overwrite,
            connect_timeout=args.connect_timeout,
            options=options,
            progress=not args.quiet,
        )
    except ArgumentError as exc:  # in the flags' terms, still a usage error (exit 2)
        text = in_flags(str(exc), {**_FLAGS, "scheduler": "--scheduler"})
        if text == str(exc):
            raise
        raise ArgumentError(text) from exc
    summary = result.to_dict()
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
    else:
        ran = int(summary["ok"]) + int(summary["failed"])  # skipped items took no time
        rate = format_rate(ran, float(summary["seconds"]), "item")
        print(
            f"batch {args.job}: {summary['ok']} ok, {summary['failed']} failed, "
            f"{summary['skipped']} skipped of {summary['items']} items on "
            f"{summary['workers']} workers in {summary['seconds']:.1f} s"
            f"{f' ({rate})' if rate else ''} -> {summary['manifest']}"
        )
        for r in result.items:
            if r["status"] == "failed":
                print(f"  {r['item']} ({r['input']}): {r['error']}")
    first = result.first_failure()
    if first is not None:
        print(
            f"robopercept: error: every item failed (first: {first['item']}: {first['error']})",
            file=sys.stderr,
        )
        return 1
    return 0
