"""``robopercept warmup``: compile every command's kernels ahead of time, in parallel.

robopercept's numba kernels compile on first use and are cached on disk; ``warmup``
runs each command once on tiny generated inputs (an image, a short video, a stereo
pair, a point cloud, a table, chessboard views, two synthetic RGB-D frames) in worker
processes, so that the first real run of every command starts at full speed.
:func:`workloads` is also what ``benchmarks/first_use.py`` times cold and warm.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["FIRST_USE_SECONDS", "first_use_seconds", "make_inputs", "register", "workloads"]

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
    "detect-hog": 8.0,
    "cloud": 6.0,
    "edges": 5.0,
    "learn": 5.0,
    "bgsub": 3.0,
    "hog": 3.0,
    "blobs": 3.0,
    "track": 2.0,
}


def first_use_seconds(command: str) -> float | None:
    """The expected first-use compile time of ``command`` (``None`` if unmeasured)."""
    return FIRST_USE_SECONDS.get(command)


def _chessboard_views(folder: Path, board: tuple[int, int]) -> list[Path]:
    """Three pinhole views of a chessboard with ``board`` inner corners (640x480)."""
    from robopercept.geometry.transforms import rotation_from_rotvec
    from robopercept.imaging import write_image

    cols, rows = board
    square = 0.03
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    rays = np.stack([(u - 320) / 600, (v - 240) / 600, np.ones_like(u)], axis=-1)
    paths = []
    for i, rvec in enumerate(([0.2, 0.1, 0.0], [-0.15, 0.25, 0.1], [0.1, -0.3, -0.05])):
        r = rotation_from_rotvec(np.array(rvec))
        centre = np.array([(cols + 1) * square / 2, (rows + 1) * square / 2, 0.0])
        t = np.array([0.0, 0.0, 0.5]) - r @ centre
        n = r[:, 2]
        s = (n @ t) / (rays @ n)
        b = (rays * s[..., None] - t) @ r  # board-plane coordinates
        ix = np.floor(b[..., 0] / square).astype(int)
        iy = np.floor(b[..., 1] / square).astype(int)
        inside = (ix >= 0) & (ix <= cols) & (iy >= 0) & (iy <= rows)
        img = np.where(inside & ((ix + iy) % 2 == 0), 20, 235).astype(np.uint8)
        path = folder / f"board_{i}.png"
        write_image(path, img)
        paths.append(path)
    return paths


def make_inputs(folder: str | Path) -> dict[str, Path]:
    """Write the tiny inputs the warmup commands read into ``folder``.

    Returns
    -------
    dict
        ``image`` (the sample image, coloured), ``image2`` (the first shifted 6 px right
        and 3 px down), ``left`` and ``right`` (a rectified pair with 4 px disparity),
        ``video`` (8 frames, MP4),
        ``cloud`` (PLY: a floor and two boxes), ``table`` (CSV, 3 classes) and
        ``board0..2`` (chessboard views with 6x4 inner corners).
    """
    from robopercept.imaging import VideoWriter, read_image, sample_image_path, write_image
    from robopercept.pointcloud import PointCloud
    from robopercept.pointcloud.io import write_point_cloud

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    gray = read_image(sample_image_path(), mode="gray")
    g = gray.astype(np.float64)  # a colour version: most users' images are RGB
    image = np.stack([g, 0.6 * g + 60, 255 - 0.8 * g], axis=-1).astype(np.uint8)
    paths = {"image": write_image(out / "image.png", image)}
    paths["image2"] = write_image(out / "image2.png", np.roll(image, (3, 6), axis=(0, 1)))
    paths["left"] = write_image(out / "left.png", gray)
    paths["right"] = write_image(out / "right.png", np.roll(gray, -4, axis=1))
    with VideoWriter(out / "video.mp4", fps=10.0) as video:
        for i in range(8):
            video.write(np.roll(image, (i, 2 * i), axis=(0, 1))[:208, :320])
    paths["video"] = out / "video.mp4"
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(0, 2, (3000, 2)), rng.normal(0, 0.002, 3000)]
    boxes = [rng.uniform(0, 0.2, (400, 3)) + np.array([x, 0.5, 0.05]) for x in (0.3, 1.2)]
    write_point_cloud(out / "cloud.ply", PointCloud(np.vstack([floor, *boxes])))
    paths["cloud"] = out / "cloud.ply"
    x = np.vstack([rng.normal(c, 0.5, (30, 3)) for c in (0.0, 3.0, 6.0)])
    lines = ["a,b,c,label"] + [
        f"{r[0]:.4f},{r[1]:.4f},{r[2]:.4f},{i // 30}" for i, r in enumerate(x)
    ]
    (out / "table.csv").write_text("\n".join(lines) + "\n")
    paths["table"] = out / "table.csv"
    for i, p in enumerate(_chessboard_views(out, (6, 4))):
        paths[f"board{i}"] = p
    return paths


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

    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="robopercept-warmup-") as tmp:
        names = list(_LINES)
        if args.list:
            print("\n".join(names))
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
