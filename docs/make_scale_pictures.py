"""Make ``docs/img/scale_cost_model.png``: the cost model of ``robopercept batch``
(``docs/scale.md``) beside the measured wall times (issue 31).

The model, for *n* items of *t* seconds each on *w* workers, is

    wall ≈ T0 + ceil(n / w) · t + n · c

against the sequential loop's n · t; ``T0`` (cluster start-up), ``t`` (one item in a
warm process) and ``c`` (per-item overhead) are read from the benchmark's results
(``cost_model``; a missing ``c`` is fitted from the measured batch as ``docs/scale.md``
says: c = (wall − T0 − ceil(n/w) · t) / n). Nothing is rerun: run the benchmark first
for new numbers. From the repository root (a second)::

    PYTHONPATH=src python benchmarks/batch_speed.py      # the measurements (minutes)
    PYTHONPATH=src python docs/make_scale_pictures.py
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from robopercept.imaging import write_image
from robopercept.viz.figure import agg_figure, figure_to_rgb, readable_dpi

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "batch_speed.json"
OUT = Path(__file__).parent / "img" / "scale_cost_model.png"
JOBS = ("cloud", "plane-track")
WORKERS = (1, 2)
COLORS = {1: "tab:blue", 2: "tab:orange", "sequential": "tab:green"}


def model_wall(n: np.ndarray, w: int, t0: float, t: float, c: float) -> np.ndarray:
    """``T0 + ceil(n / w) · t + n · c`` for each item count in ``n`` (seconds)."""
    n = np.asarray(n, dtype=np.float64)
    return t0 + np.ceil(n / w) * t + n * c


def constants(data: dict[str, Any], job: str, w: int) -> tuple[float, float, float]:
    """``(T0, t, c)`` of ``job`` on ``w`` workers: from ``cost_model``, with what is
    missing taken from the measured rows (``t`` from the sequential loop, ``c`` fitted
    from the batch run)."""
    rec = next((r for r in data.get("cost_model", []) if r["job"] == job and r["workers"] == w), {})
    rows = {(r["mode"], r["workers"]): r for r in data["rows"] if r["job"] == job}
    t0 = rec.get("T0", data["startup_seconds"][str(w)])
    seq = rows[("sequential", 1)]
    t = rec.get("t", seq["seconds"] / seq["items"])
    if "c" in rec:
        return float(t0), float(t), float(rec["c"])
    run = rows[("batch", w)]
    n = run["items"]
    return float(t0), float(t), (run["seconds"] - t0 - math.ceil(n / w) * t) / n


def cost_model_picture(data: dict[str, Any], width: int = 1600, height: int = 700) -> np.ndarray:
    """Two panels (``cloud``, ``plane-track``): the model's wall time against the number
    of items, 1 to 64, for 1 and 2 workers and the sequential loop (lines), and the
    measured wall times (points); as an RGB picture."""
    fig = agg_figure(width, height, layout="constrained", dpi=readable_dpi(width, height))
    n = np.arange(1, 65)
    axes = fig.subplots(1, len(JOBS))
    for ax, job in zip(axes, JOBS, strict=True):
        rows = [r for r in data["rows"] if r["job"] == job]
        t = 0.0
        for w in WORKERS:
            t0, t, c = constants(data, job, w)
            ax.plot(n, model_wall(n, w, t0, t, c), color=COLORS[w], lw=2,
                    label=f"model, batch on {w} worker{'s' * (w > 1)}")  # fmt: skip
            for r in rows:
                if r["mode"] == "batch" and r["workers"] == w:
                    ax.plot(r["items"], r["seconds"], "o", ms=9, color=COLORS[w],
                            markeredgecolor="black",
                            label=f"measured, batch on {w} worker{'s' * (w > 1)}")  # fmt: skip
        ax.plot(n, n * t, color=COLORS["sequential"], lw=2, ls="--",
                label="model, sequential loop (n · t)")  # fmt: skip
        for r in rows:
            if r["mode"] == "sequential":
                ax.plot(r["items"], r["seconds"], "s", ms=9, color=COLORS["sequential"],
                        markeredgecolor="black", label="measured, sequential loop")  # fmt: skip
        ax.set_yscale("log")
        ax.set(xlabel="number of items n", ylabel="wall time (s, log scale)", xlim=(0, 65),
               title=f"{job}: t = {t:.3g} s per item")  # fmt: skip
        ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3)
    fig.suptitle("robopercept batch: wall ≈ T0 + ⌈n / w⌉ · t + n · c (lines) and measured (points)")
    return figure_to_rgb(fig)


def main() -> None:
    data = json.loads(RESULTS.read_text())
    write_image(OUT, cost_model_picture(data))
    print(f"-> {OUT}")


if __name__ == "__main__":
    main()
