"""DDP training speed: training images per second of ``nn train`` on digits with 1 and 2
processes (one torch thread each, gloo on the CPU), written to
benchmarks/results/ddp_speed.json.

Run: ``PYTHONPATH=src python benchmarks/ddp_speed.py [--epochs 3]``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results" / "ddp_speed.json"


def measure(nproc: int, epochs: int, batch_size: int, model: str) -> dict[str, float]:
    """One run of ``train_ddp``: images/s over the training (fit) time, validation included."""
    from robopercept.nn.classification.run import train_ddp
    from robopercept.nn.train.config import TrainConfig

    cfg = TrainConfig(epochs=epochs, batch_size=batch_size, patience=None, device="cpu")
    with tempfile.TemporaryDirectory() as tmp:
        res = train_ddp(
            "digits", model, Path(tmp, "run"), nproc=nproc, config=cfg, threads=1, progress=False
        )
    images = res.metrics["split"]["train"] * res.metrics["epochs_run"]
    return {
        "nproc": nproc,
        "seconds": res.seconds,
        "images": images,
        "images_per_s": images / res.seconds,
        "test_accuracy": res.test.accuracy,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--model", default="vgg_small")
    a = ap.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    rows = [measure(n, a.epochs, a.batch_size, a.model) for n in (1, 2)]
    for r in rows:
        print(
            f"nproc {r['nproc']}: {r['images_per_s']:8.0f} images/s "
            f"({r['images']} images in {r['seconds']:.2f} s), test accuracy "
            f"{r['test_accuracy']:.4f}"
        )
    speedup = rows[1]["images_per_s"] / rows[0]["images_per_s"]
    print(f"speed-up with 2 processes: {speedup:.2f}x")
    out = {
        "benchmark": "ddp_speed",
        "data": "digits",
        "model": a.model,
        "epochs": a.epochs,
        "global_batch": a.batch_size,
        "threads_per_process": 1,
        "cpus": os.cpu_count(),
        "machine": platform.processor() or platform.machine(),
        "runs": rows,
        "speedup_2": speedup,
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(out, indent=2) + "\n")
    print(f"-> {RESULTS}")


if __name__ == "__main__":
    main()
