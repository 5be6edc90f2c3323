"""``robopercept warmup``: compile every command's kernels ahead of time, in parallel.

robopercept's numba kernels compile on first use and are cached on disk; ``warmup``
runs each command once on tiny generated inputs (an image, a short video, a stereo
pair, a point cloud, a table, chessboard views, two synthetic RGB-D frames) in worker
processes, so that the first real run of every command starts at full speed.
:func:`workloads` (on :func:`robopercept.pipelines.samples.make_inputs`) is also what
``benchmarks/first_use.py`` times cold and warm.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["FIRST_USE_SECONDS", "first_use_seconds", "register", "workloads"]

#: First-use compile time in seconds of each command on this project's 2-core machine,
#: the largest over the command's workloads, measured by ``benchmarks/first_use.py``
#: (cold numba cache; ``benchmarks/results/first_use.json``): what the "compiling kernels
#: ... about N s" notice says. A command not listed compiles for under a second.
FIRST_USE_SECONDS: dict[str, float] = {
    "stereo": 25.0,
    "stitch": 15.0,
    "flow": 14.0,
    "demo": 13.0,
    "plane-track": 13.0,
    "match": 13.0,
    "features": 13.0,
    "calibrate": 8.0,
    "stereo-calibrate": 8.0,  # the kernels of calibrate (its workload compiles them)
    "detect-hog": 8.0,
    "cloud": 6.0,
    "edges": 5.0,
    "learn": 5.0,
    "bgsub": 3.0,
    "hog": 3.0,
    "blobs": 3.0,
    "proposals": 4.0,
    "track": 2.0,
}


def first_use_seconds(command: str) -> float | None:
    """The expected first-use compile time of ``command`` (``None`` if unmeasured)."""
    return FIRST_USE_SECONDS.get(command)


def workloads(inputs: dict[str, Path], out: str | Path) -> dict[str, list[str]]:
    """The command lines that compile every command's kernels, by name, writing into
    ``out``. Ordered slowest first (the order :func:`~robopercept.jit.run_in_workers`
    hands them out in)."""
    paths = {k: str(v) for k, v in inputs.items()} | {"o": str(Path(out))}
    # split first, then fill in: paths may hold spaces
    return {name: [tok.format(**paths) for tok in line.split()] for name, line in _LINES.items()}


_V = "-o {o}/v.mp4 --quiet"
_T = "{table} --label label"
_LINES = {
    "stereo sgm": "stereo {left} {right} --max-disparity 16 -o {o}/d.png",
    "demo": "demo --max-frames 3 --out {o}/demo --quiet",
    "edges canny": "edges {image} -o {o}/e.png",
    "features sift": "features {image} --detector sift -o {o}/f.png",
    "match": "match {image} {image2} -o {o}/m.png",
    "stereo bm": "stereo {left} {right} --method bm --max-disparity 16 -o {o}/d.png",
    "calibrate": "calibrate {board0} {board1} {board2} --board 6x4 --square 0.03 "
    "-o {o}/cam.json --quiet",
    "flow": "flow {image} {image2} -o {o}/flow.png",
    "flow dense": "flow {image} {image2} --dense -o {o}/flowd.png",
    "flow video": f"flow {{video}} {_V}",
    "bgsub": f"bgsub {{video}} {_V}",
    "bgsub diff": f"bgsub {{video}} --method diff {_V}",
    "meanshift": f"meanshift {{video}} --box 100,60,60,60 --results {{o}}/ms.csv {_V}",
    "meanshift camshift": "meanshift {video} --box 100,60,60,60 --camshift "
    f"--results {{o}}/ms.csv {_V}",
    "track": f"track {{video}} --results {{o}}/t.txt {_V}",
    "edges sobel": "edges {image} --method sobel -o {o}/e.png",
    "edges log": "edges {image} --method log -o {o}/e.png",
    "features harris": "features {image} -o {o}/f.png",
    "features shi-tomasi": "features {image} --detector shi-tomasi --subpixel -o {o}/f.png",
    "hog": "hog {image} -o {o}/h.png",
    "detect-hog": "detect-hog {image} -o {o}/dh.png",
    "blobs": "blobs {image} -o {o}/b.png",
    "stitch": "stitch {image} {image2} -o {o}/s.png",
    "proposals": "proposals {image} --max 20 -o {o}/p.png --quiet",
    "cloud": "cloud {cloud} --voxel 0.02 --sor 8:2 --planes 1:0.01 --clusters 0.05:10:100000 "
    "-o {o}/c.ply",
    "learn kmeans": f"learn cluster {_T} -o {{o}}/k.png",
    "learn meanshift": f"learn cluster {_T} --method meanshift -o {{o}}/k.png",
    "learn dbscan": f"learn cluster {_T} --method dbscan -o {{o}}/k.png",
    "learn forest": f"learn classify {_T} -o {{o}}/c.png",
    "learn tree": f"learn classify {_T} --model tree -o {{o}}/c.png",
    "learn svm": f"learn classify {_T} --model svm -o {{o}}/c.png",
    "learn reduce": f"learn reduce {_T} -o {{o}}/r.png",
}


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``warmup`` command to the subcommand parsers ``sub``."""
    p = sub.add_parser(
        "warmup",
        help="compile every command's kernels ahead of time (once per install)",
        description="Run every command once on tiny generated inputs, in parallel worker "
        "processes, so numba compiles and caches their kernels now instead of on first "
        "use. Takes a few minutes once; later runs find everything cached and finish in "
        "seconds.",
    )
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: CPUs)")
    p.add_argument("--only", nargs="+", default=None, metavar="NAME", help="these workloads")
    p.add_argument("--list", action="store_true", help="list the workloads and exit")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_warmup)


def _warmup(args: argparse.Namespace) -> int:
    from robopercept.cli._args import UsageError
    from robopercept.jit import call_by_name, run_in_workers
    from robopercept.pipelines.samples import make_inputs

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="robopercept-warmup-") as tmp:
        names = list(_LINES)
        if args.list:
            print(json.dumps({"workloads": names}, indent=2) if args.json else "\n".join(names))
            return 0
        chosen = list(names) if args.only is None else args.only
        unknown = [n for n in chosen if n not in names]
        if unknown:
            raise UsageError(f"--only: unknown workload(s) {', '.join(unknown)} (see --list)")
        todo = workloads(make_inputs(tmp), tmp)  # a few seconds
        results = run_in_workers(
            [(n, call_by_name, ("robopercept.cli.main", "main", todo[n])) for n in chosen],
            jobs=args.jobs,
            progress=not args.quiet,
        )
    failed = [r for r in results if r.error or r.result not in (0, None)]
    total = time.perf_counter() - start
    if args.json:
        print(
            json.dumps(
                {
                    "seconds": round(total, 2),
                    "jobs": args.jobs,
                    "compiled": sum(r.compiled for r in results),
                    "compile_seconds": round(sum(r.compile_seconds for r in results), 2),
                    "failed": [r.name for r in failed],
                    "workloads": [
                        {
                            "name": r.name,
                            "exit_code": r.result,
                            "error": r.error,
                            "compiled": r.compiled,
                            "compile_seconds": round(r.compile_seconds, 2),
                            "seconds": round(r.seconds, 2),
                        }
                        for r in results
                    ],
                },
                indent=2,
            )
        )
    else:
        n = sum(r.compiled for r in results)
        secs = sum(r.compile_seconds for r in results)
        print(
            f"warmup: {len(results)} workloads in {total:.1f} s; {n} kernel compilations "
            f"({secs:.1f} s of compiling{'' if n else ': everything was cached'})"
        )
    for r in failed:
        why = r.error or f"exit code {r.result}"
        last = r.output.splitlines()[-1] if r.output.strip() else ""
        print(
            f"robopercept: warning: warmup {r.name!s} failed: {why} {last}".rstrip(),
            file=sys.stderr,
        )
    return 1 if failed and len(failed) == len(results) else 0
