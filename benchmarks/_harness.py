"""Timing helpers shared by the benchmark modules."""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"


@dataclass
class Record:
    name: str
    case: str
    ours_ms: float
    ref_ms: float
    reference: str
    accuracy: str
    accuracy_value: float
    target_ratio: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: an absolute target on ``ours_ms`` as well, where the issue sets one
    target_ms: float | None = None

    @property
    def ratio(self) -> float:
        return self.ours_ms / self.ref_ms if self.ref_ms > 0 else float("inf")

    def to_json(self) -> dict[str, Any]:
        d = asdict(self)
        d["ratio"] = round(self.ratio, 3)
        d["meets_target"] = None if self.target_ratio is None else self.ratio <= self.target_ratio
        if self.target_ms is not None:
            d["meets_target"] = (d["meets_target"] is not False) and self.ours_ms <= self.target_ms
        return d


def median_ms(fn: Callable[[], object], repeats: int = 30, warmup: int = 3) -> float:
    """Median wall time of ``fn()`` in milliseconds after ``warmup`` untimed calls
    (which also absorb JIT compilation)."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3)


def paired_ms(
    ours: Callable[[], object],
    ref: Callable[[], object],
    repeats: int = 30,
    warmup: int = 3,
) -> tuple[float, float]:
    """Median wall times of ``ours()`` and ``ref()`` in milliseconds, the calls
    alternating (ours, ref, ours, ref, ...) so that a slow spell of a shared machine
    falls on both sides rather than on whichever ran during it."""
    for _ in range(warmup):
        ours()
        ref()
    a, b = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        ours()
        a.append(time.perf_counter() - t)
        t = time.perf_counter()
        ref()
        b.append(time.perf_counter() - t)
    return float(np.median(a) * 1e3), float(np.median(b) * 1e3)


def machine() -> dict[str, Any]:
    import os

    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "numpy": np.__version__,
    }


def save(name: str, records: list[Record], settings: dict[str, Any]) -> Path:
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {
        "benchmark": name,
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine(),
        "settings": settings,
        "records": [r.to_json() for r in records],
    }
    path.write_text(json.dumps(payload, indent=2) + "\n")
    return path


def load_runs(name: str) -> dict[str, Any]:
    """The accumulated record ``benchmarks/results/NAME.json`` of a figures script
    (``{"benchmark", "machine", "runs": {key: row}}``, plus what the script adds), or a
    new empty one."""
    path = RESULTS / f"{name}.json"
    if path.exists():
        return json.loads(path.read_text())
    return {"benchmark": name, "runs": {}}


def store_run(name: str, key: str, row: dict[str, Any]) -> Path:
    """Merge one run's ``row`` under ``runs[key]`` of ``NAME.json`` (re-read first, so
    runs written meanwhile by other processes are kept) with this machine's details."""
    results = load_runs(name)
    results["machine"] = machine()
    results["runs"][key] = row
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(results, indent=1))
    return path


def store_timing(name: str, part: str, row: dict[str, Any]) -> Path:
    """Merge a timing ``row`` (a figures script's ``--time-epochs``) under
    ``timing[part]`` of ``NAME.json``, with this machine's details."""
    results = load_runs(name)
    results.setdefault("timing", {})[part] = {**row, "machine": machine()}
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(results, indent=1))
    return path


def timing_row(
    part: str, threads: int, timed: int, per_epoch: float, per_val: float, epochs: int, every: int
) -> dict[str, Any]:
    """A ``--time-epochs`` record: ``timed`` epochs took ``per_epoch`` s each and one
    validation ``per_val`` s; a run of ``epochs`` epochs validating every ``every``
    epochs and after the last is estimated from them."""
    n_val = len(range(every, epochs + 1, every)) + (epochs % every != 0)
    return {
        "part": part,
        "threads": threads,
        "epochs_timed": timed,
        "seconds_per_epoch": round(per_epoch, 2),
        "seconds_per_validation": round(per_val, 2),
        "estimated_train_seconds": round(per_epoch * epochs + per_val * n_val, 1),
        "epochs": epochs,
    }


def figures_main(
    argv: list[str] | None,
    *,
    name: str,
    description: str,
    parts: list[str],
    run: Callable[[str, int, bool, Path | None], dict[str, Any]],
    time_part: Callable[[str, int, int], dict[str, Any]],
    table: Callable[[dict[str, Any]], str],
    save_help: str,
) -> int:
    """The command line of a figures script (``detection_figures``,
    ``segmentation_figures``): ``--only PART...``, ``--seeds``, ``--threads``,
    ``--quiet``, ``--save DIR`` and ``--time-epochs K``. Each ``run(part, seed,
    progress, save)`` row is printed and merged into ``NAME.json`` as it finishes
    (:func:`store_run`), then the table of all runs is printed; with ``--time-epochs``
    each part's :func:`timing_row` is stored instead (:func:`store_timing`)."""
    import argparse

    import torch

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--only", nargs="+", choices=sorted(parts), default=sorted(parts))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--save", type=Path, default=None, help=save_help)
    ap.add_argument(
        "--time-epochs",
        type=int,
        default=None,
        metavar="K",
        help="instead of full runs, time K epochs of each part and extrapolate its "
        "training time (stored under 'timing'; run alone on the machine)",
    )
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    if args.time_epochs:
        for part in args.only:
            row = time_part(part, args.time_epochs, args.threads)
            print(json.dumps(row), flush=True)
            store_timing(name, part, row)
        return 0
    for part in args.only:
        for seed in args.seeds:
            row = run(part, seed, not args.quiet, args.save)
            print(json.dumps(row), flush=True)
            store_run(name, f"{part}/{seed}", row)
    print(table(load_runs(name)))
    return 0


def seeds_table(results: dict[str, Any]) -> str:
    """The table of a figures script (``segmentation_figures``, ``pose_figures``): per
    part and numeric ``test`` figure, the mean +- std over the seeds run, and the mean
    training seconds (0 where a part records none)."""
    import numpy as np

    by: dict[str, list[dict[str, Any]]] = {}
    for row in results["runs"].values():
        by.setdefault(row["part"], []).append(row)
    lines = ["| part | seeds | figure | mean ± std | train s |", "|---|---|---|---:|---:|"]
    for part, rows in sorted(by.items()):
        seeds = ",".join(str(r["seed"]) for r in sorted(rows, key=lambda r: r["seed"]))
        t = np.mean([r.get("train_seconds", 0.0) for r in rows])
        for key, v in rows[0]["test"].items():
            if not isinstance(v, float):
                continue
            vals = [r["test"][key] for r in rows]
            lines.append(
                f"| {part} | {seeds} | {key} | {np.mean(vals):.3f} ± {np.std(vals):.3f} | {t:.0f} |"
            )
    return "\n".join(lines)
