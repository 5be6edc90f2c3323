"""``python -m benchmarks [NAME ...] [--repeats N]``: run and record benchmarks."""

from __future__ import annotations

import argparse
import importlib
import sys

from benchmarks._harness import save

BENCHMARKS = {
    "imaging": "benchmarks.imaging",
    "pointcloud": "benchmarks.pointcloud",
    "plane_tracking": "benchmarks.plane_tracking",
    "features": "benchmarks.features",
    "learning": "benchmarks.learning",
    "motion": "benchmarks.motion",
    "depth": "benchmarks.depth",
    "calibration": "benchmarks.calibration",
    "nn_ops": "benchmarks.nn_ops",
    "coco_eval": "benchmarks.coco_eval",
    "proposals": "benchmarks.proposals",
}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__)
    p.add_argument("names", nargs="*", help=f"which to run (default all): {', '.join(BENCHMARKS)}")
    p.add_argument("--repeats", type=int, default=30)
    args = p.parse_args(argv)
    names = args.names or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print(f"unknown benchmark(s) {unknown}; choose from {list(BENCHMARKS)}", file=sys.stderr)
        return 2
    for name in names:
        records, settings = importlib.import_module(BENCHMARKS[name]).run(args.repeats)
        path = save(name, records, settings)
        print(f"\n{name}  ({settings})")
        print(
            f"{'kernel':<22} {'case':<44} {'ours ms':>8} {'ref ms':>8} {'ratio':>6} "
            f"{'target':>6}  accuracy"
        )
        for r in records:
            target = "" if r.target_ratio is None else f"<={r.target_ratio:g}"
            if r.target_ms is not None:
                target += f" & <={r.target_ms:g} ms"
            print(
                f"{r.name:<22} {r.case:<44} {r.ours_ms:>8.2f} {r.ref_ms:>8.2f} {r.ratio:>6.2f} "
                f"{target:>6}  {r.accuracy} = {r.accuracy_value:.4g} (vs {r.reference})"
            )
        print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
