"""``robopercept batch``: one job over many inputs on a Dask cluster (local or remote)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, flag_errors, numbers, positive_int

__all__ = ["register"]

_JOBS = ("cloud", "edges", "features", "plane-track", "nn-cloud")
_CLOUD_CLASSIFIERS = ("pointnet", "dgcnn")  # the shipped classifiers nn-cloud may name


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
        "keypoints.json), plane-track (recording folder -> its outputs), nn-cloud (PLY/PCD/OFF "
        "-> prediction.json: the class and probabilities of `robopercept nn cloud`).",
    )
    p.add_argument("job", choices=_JOBS, help="the job run on each input")
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="files, folders or globs")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument(
        "--scheduler",
        default="local",
        help="'local' (default: a LocalCluster of --workers processes) or the address of a "
        "running scheduler, tcp://HOST:PORT (its workers must see the same files)",
    )
    p.add_argument(
        "--workers", type=positive_int, default=2, help="local workers (default: %(default)s)"
    )
    p.add_argument(
        "--retries",
        type=int,
        default=1,
        help="reruns of an item that failed (default: %(default)s)",
    )
    p.add_argument(
        "--connect-timeout",
        type=float,
        default=10.0,
        metavar="SECONDS",
        help="wait this long for --scheduler ADDRESS (default: %(default)s)",
    )
    again = p.add_mutually_exclusive_group()
    again.add_argument(
        "--resume", action="store_true", help="skip the items OUT/batch.json has as done"
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
    p.add_argument("--method", choices=("canny", "sobel"), default="canny", help="edges")
    p.add_argument(
        "--detector", choices=("harris", "shi-tomasi"), default="harris", help="features"
    )
    p.add_argument(
        "--max-frames", type=positive_int, default=None, help="plane-track: frames per item"
    )
    p.add_argument(
        "--model",
        default=None,
        metavar="MODEL",
        help="nn-cloud: pointnet (default), dgcnn or a model.pt file",
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


_JOB_FLAGS = {
    "cloud": {"voxel": "--voxel", "planes": "--planes"},
    "edges": {"method": "--method"},
    "features": {"detector": "--detector"},
    "plane-track": {"max_frames": "--max-frames"},
    "nn-cloud": {"model": "--model", "points": "--points"},
}
_DEFAULTS = {"voxel": None, "planes": None, "method": "canny", "detector": "harris",
             "max_frames": None, "model": None, "points": None}  # fmt: skip


@flag_errors(
    workers="--workers",
    retries="--retries",
    connect_timeout="--connect-timeout",
    voxel_size="--voxel",
    max_planes="--planes N",
    threshold="--planes THRESHOLD",
)
def run_batch_command(args: argparse.Namespace) -> int:
    """Run ``robopercept batch`` with the parsed ``args``; returns the exit status."""
    from robopercept.pipelines.batch import run_batch

    if args.retries < 0:
        raise UsageError(f"--retries must be >= 0; got {args.retries}")
    if args.connect_timeout <= 0:
        raise UsageError(f"--connect-timeout must be > 0; got {args.connect_timeout:g}")
    if args.scheduler != "local" and "://" not in args.scheduler:
        raise UsageError(f"--scheduler must be 'local' or tcp://HOST:PORT; got {args.scheduler}")
    out = Path(args.output)
    if out.is_dir() and any(out.iterdir()) and not (args.resume or args.overwrite):
        raise UsageError(
            f"-o {out}: exists and is not empty: pass --resume to finish its batch or "
            "--overwrite to run every item again"
        )
    if args.model is not None and not (
        args.model in _CLOUD_CLASSIFIERS or Path(args.model).is_file()
    ):
        raise UsageError(
            f"--model must be {' or '.join(_CLOUD_CLASSIFIERS)} or a model.pt file; got "
            f"{args.model} (no such file)"
        )
    options: dict[str, Any] = {}
    for name, flag in (f for job, fl in _JOB_FLAGS.items() for f in fl.items()):
        given = getattr(args, name)
        if given != _DEFAULTS[name]:
            if name not in _JOB_FLAGS[args.job]:
                raise UsageError(f"{flag} does not apply to the {args.job} job")
            options[name] = given
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
    summary = result.to_dict()
    ran = [r for r in result.items if r["status"] in ("ok", "failed")]
    all_failed = bool(ran) and all(r["status"] == "failed" for r in ran)
    if args.json:
        print(json.dumps(summary, indent=2, default=str))
    else:
        print(
            f"batch {args.job}: {summary['ok']} ok, {summary['failed']} failed, "
            f"{summary['skipped']} skipped of {summary['items']} items on "
            f"{summary['workers']} workers in {summary['seconds']:.1f} s "
            f"({summary['items_per_second']:.2f} items/s) -> {summary['manifest']}"
        )
        for r in result.items:
            if r["status"] == "failed":
                print(f"  {r['item']} ({r['input']}): {r['error']}")
    if all_failed:
        first = ran[0]
        print(
            f"robopercept: error: every item failed (first: {first['item']}: {first['error']})",
            file=sys.stderr,
        )
        return 1
    return 0
