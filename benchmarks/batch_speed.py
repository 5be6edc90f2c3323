"""Items per second of ``robopercept batch`` (issue 31): ``cloud`` and ``plane-track``
batches on a LocalCluster of 1 and 2 workers against a plain sequential loop of
:func:`robopercept.pipelines.batch.run_item` in one process, and the constants of the
cost model ``wall ~ T0 + ceil(n / w) * t + n * c``.

Run from the repository root (standalone, not a ``python -m benchmarks`` entry)::

    PYTHONPATH=src .venv/bin/python benchmarks/batch_speed.py [--clouds 8] [--recordings 4]

Inputs: the ``--clouds`` smallest PCD files of ../shared/data/pointcloud (``cloud`` with
``voxel=0.005, planes=(1, 0.01)``) and ``--recordings`` synthetic recordings of 20 frames
written by ``SyntheticRGBDScene`` (``plane-track``). Writes
benchmarks/results/batch_speed.json.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[0].parent / "shared" / "data" / "pointcloud"


def _startup(workers: int) -> float:
    """Seconds to start the LocalCluster of ``run_batch`` (``workers``) and connect (then
    close it)."""
    from distributed import Client

    from robopercept.pipelines.batch import local_cluster

    t0 = time.perf_counter()
    cluster = local_cluster(workers)
    client = Client(cluster)
    seconds = time.perf_counter() - t0
    client.close()
    cluster.close()
    return seconds


def main(argv: list[str] | None = None) -> int:
    from robopercept.pipelines.batch import run_batch, run_item
    from robopercept.sources import SyntheticRGBDScene, write_tum_folder

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--clouds", type=int, default=8, help="PCD files (smallest first)")
    parser.add_argument("--recordings", type=int, default=4, help="20-frame recordings")
    args = parser.parse_args(argv)
    clouds = sorted(DATA.glob("*/*.pcd"), key=lambda p: p.stat().st_size)[: args.clouds]
    tmp = Path(tempfile.mkdtemp(prefix="batch_speed_"))
    recs = [write_tum_folder(tmp / "rec" / f"seq{i}", SyntheticRGBDScene(n_frames=20, seed=i))
            for i in range(args.recordings)]  # fmt: skip
    jobs = {"cloud": (clouds, {"voxel": 0.005, "planes": (1, 0.01)}), "plane-track": (recs, {})}
    run_item("cloud", clouds[0], tmp / "warm", jobs["cloud"][1])  # compile numba kernels once
    rows = []
    for job, (inputs, opts) in jobs.items():
        t0 = time.perf_counter()
        for k, p in enumerate(inputs):
            run_item(job, p, tmp / f"seq-{job}" / str(k), opts)
        seq = time.perf_counter() - t0
        rows.append({"job": job, "mode": "sequential", "workers": 1, "items": len(inputs),
                     "seconds": seq, "items_per_second": len(inputs) / seq})  # fmt: skip
        for w in (1, 2):
            res = run_batch(job, inputs, tmp / f"{job}-w{w}", workers=w, options=opts,
                            progress=False)  # fmt: skip
            assert res.count("ok") == len(inputs), res.items
            worker_t = sum(r["seconds"] for r in res.items) / len(inputs)
            rows.append({"job": job, "mode": "batch", "workers": w, "items": len(inputs),
                         "seconds": res.seconds, "items_per_second": len(inputs) / res.seconds,
                         "worker_seconds_per_item": worker_t})  # fmt: skip
    startup = {w: _startup(w) for w in (1, 2)}
    model = []
    for job in jobs:
        seq = next(r for r in rows if r["job"] == job and r["mode"] == "sequential")
        t = seq["seconds"] / seq["items"]
        for r in rows:
            if r["job"] == job and r["mode"] == "batch":
                n, w = r["items"], r["workers"]
                c = (r["seconds"] - startup[w] - math.ceil(n / w) * t) / n
                r["overhead_per_item"] = c
                model.append({"job": job, "workers": w, "T0": startup[w], "t": t, "c": c})
    doc = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        "python": sys.version.split()[0],
        "startup_seconds": startup,
        "rows": rows,
        "cost_model": model,
    }
    out = HERE / "results" / "batch_speed.json"
    out.write_text(json.dumps(doc, indent=2) + "\n")
    for r in rows:
        print(f"{r['job']:<12} {r['mode']:<10} w={r['workers']} {r['items']} items "
              f"{r['seconds']:7.2f} s {r['items_per_second']:6.2f} items/s")  # fmt: skip
    print(f"startup T0: {startup}; written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
