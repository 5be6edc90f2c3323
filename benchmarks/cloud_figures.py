"""Issue 29's figures for PointNet and DGCNN, trained here on the CPU (run
``python -m benchmarks.cloud_figures --only PART --seeds 0 1 2``; each run is merged into
``benchmarks/results/cloud_figures.json`` and the table printed).

Every run draws its weights from ``torch.manual_seed(seed)``, trains on procedural
shapes drawn with ``rng=seed`` (:func:`~robopercept.nn.cloud.synthetic.procedural_shapes`,
12 classes, rotated about the up axis), picks its epoch on validation shapes
(``rng=1000 + seed``) and is scored on test shapes (``rng=99``), never seen in training
or selection.

Parts:

- ``pointnet``, ``dgcnn``: classification of clean shapes (overall accuracy and mean
  class accuracy).
- ``pointnet-partial``, ``dgcnn-partial``, ``pointnet-noisy``, ``dgcnn-noisy``: the
  harder variants, partial views (only the points on the side of a random viewing
  direction) and strong noise (sigma 0.04 and 10 % outliers), trained and tested on
  that variant, both networks on the same data (:data:`HARDER`): the course's claim
  that neighbourhood features (DGCNN) help where the global shape is incomplete or
  corrupted.
- ``pointnet-parts``, ``dgcnn-parts``: part segmentation (the category given, argmax
  restricted to its parts, ShapeNet-part's instance and class mIoU).
- ``speed``: forward latency per cloud and training throughput of both models against
  the point count (512 to 4096), the share of DGCNN's forward spent on its k-NN graphs,
  and :func:`~robopercept.nn.cloud.dgcnn.knn_graph` against ``scipy.spatial.cKDTree`` from
  1,000 to 100,000 points.

``--save DIR`` writes the seed's ``pointnet``, ``dgcnn`` and ``pointnet-parts`` models as
the shipped ``cloud_*.pt`` files.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks._harness import figures_main, seeds_table, timing_row
from robopercept.nn.cloud import train as C
from robopercept.nn.cloud.synthetic import procedural_shapes
from robopercept.nn.train.config import TrainConfig

NAME = "cloud_figures"
#: per model: constructor settings, points per cloud, training shapes per class,
#: epochs, batch size, AdamW learning rate. PointNet at width 0.25 trains at ~0.36 s
#: and DGCNN (k = 16, widths 32-32-64-128, embedding 256) at 512 points at ~1.8 s per
#: batch of 32 on the 2 cores.
MODELS: dict[str, dict[str, Any]] = {
    "pointnet": {
        "settings": {"width": 0.25},
        "points": 1024,
        "shapes": 100,
        "epochs": 20,
        "batch_size": 32,
        "lr": 2e-3,
    },
    "dgcnn": {
        "settings": {"k": 16, "widths": [32, 32, 64, 128], "embedding": 256},
        "points": 512,
        "shapes": 60,
        "epochs": 12,
        "batch_size": 32,
        "lr": 2e-3,
    },
}
#: the harder variants (partial views, strong noise) train both networks on the same
#: data, DGCNN's budget: 60 shapes per class of 512 points, so that the comparison is
#: between the networks alone
HARDER = {"points": 512, "shapes": 60}
#: validation and test shapes per class
N_VAL, N_TEST = 10, 25
SHIPPED = {
    "pointnet": "cloud_pointnet_shapes.pt",
    "dgcnn": "cloud_dgcnn_shapes.pt",
    "pointnet-parts": "cloud_pointnet_parts.pt",
}


def _split(part: str) -> tuple[str, str, str]:
    """``dgcnn-partial`` -> ("dgcnn", "partial", "classify")."""
    model, _, rest = part.partition("-")
    if rest == "parts":
        return model, "clean", "segment"
    return model, rest or "clean", "classify"


def _spec(model: str, variant: str) -> dict[str, Any]:
    """The model's budget, with :data:`HARDER`'s data for the harder variants."""
    return {**MODELS[model], **(HARDER if variant != "clean" else {})}


def _sets(model: str, variant: str, seed: int, shapes: int | None = None) -> tuple[Any, Any, Any]:
    spec = _spec(model, variant)
    n = spec["points"]
    train = procedural_shapes(shapes or spec["shapes"], n, variant=variant, rng=seed)
    val = procedural_shapes(N_VAL, n, variant=variant, rng=1000 + seed)
    test = procedural_shapes(N_TEST, n, variant=variant, rng=99)
    return train, val, test


def _build(model: str, task: str, train: Any, seed: int) -> torch.nn.Module:
    settings = dict(MODELS[model]["settings"], task=task)
    if task == "segment":
        settings["num_categories"] = train.num_classes
    outputs = train.num_parts if task == "segment" else train.num_classes
    return C.build_cloud_model(model, outputs, seed=seed, **settings)


def _cfg(model: str, seed: int, epochs: int | None = None) -> TrainConfig:
    spec = MODELS[model]
    return TrainConfig(
        epochs=epochs or spec["epochs"],
        batch_size=spec["batch_size"],
        lr=spec["lr"],
        device="cpu",
        seed=seed,
    )


def network(part: str, seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """Train one model of ``part`` and score it on the test shapes."""
    model_name, variant, task = _split(part)
    train, val, test = _sets(model_name, variant, seed)
    model = _build(model_name, task, train, seed)
    t0 = time.perf_counter()
    hist = C.train_cloud_model(model, train, _cfg(model_name, seed), val=val, progress=progress)
    wall = time.perf_counter() - t0
    ev = C.evaluate_cloud_model(model, test)
    if save is not None and part in SHIPPED:
        C.save_cloud_model(
            save / SHIPPED[part],
            model,
            list(train.class_names),
            part_names=list(train.part_names) if task == "segment" else (),
            part_classes=train.part_classes if task == "segment" else None,
            n_points=MODELS[model_name]["points"],
            data="shapes",
            seed=seed,
            built_by=f"python -m benchmarks.cloud_figures --only {part} --seeds {seed} --save DIR",
        )
    scores = {k: round(v, 4) for k, v in ev.summary().items()}
    return {
        "part": part,
        "seed": seed,
        "model": model_name,
        "variant": variant,
        "task": task,
        "settings": _spec(model_name, variant),
        "clouds": {"train": len(train), "val": len(val), "test": len(test)},
        "parameters": sum(p.numel() for p in model.parameters()),
        "train_seconds": round(wall, 1),
        "val": hist.val,
        "best_epoch": hist.best_epoch,
        "test": scores,
    }


def _median_s(fn: Any, repeats: int = 5) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def speed(seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """Latency, training throughput and k-NN cost against the point count."""
    from scipy.spatial import cKDTree

    from robopercept.nn.cloud.dgcnn import knn_graph

    del progress, save
    rng = np.random.default_rng(seed)
    rows: list[dict[str, Any]] = []
    for name in ("pointnet", "dgcnn"):
        net = C.build_cloud_model(name, 12, seed=seed, **MODELS[name]["settings"])
        opt = torch.optim.AdamW(net.parameters())
        for n in (512, 1024, 2048, 4096):
            x1 = torch.from_numpy(rng.random((1, n, 3), dtype=np.float32))
            xb = torch.from_numpy(rng.random((8, n, 3), dtype=np.float32))
            y = torch.zeros(8, dtype=torch.long)
            net.eval()
            with torch.no_grad():
                latency = _median_s(lambda net=net, x1=x1: net(x1))

            def step(net: Any = net, opt: Any = opt, xb: Any = xb, y: Any = y) -> None:
                net.train()
                loss = torch.nn.functional.cross_entropy(net(xb), y)
                opt.zero_grad()
                loss.backward()
                opt.step()

            per_step = _median_s(step, repeats=3)
            row = {
                "model": name,
                "points": n,
                "latency_ms": round(1000 * latency, 2),
                "train_clouds_per_s": round(8 / per_step, 2),
            }
            if name == "dgcnn":
                k = MODELS[name]["settings"]["k"]
                widths = [3, *MODELS[name]["settings"]["widths"][:-1]]
                feats = [torch.from_numpy(rng.random((1, n, c), dtype=np.float32)) for c in widths]
                t_knn = sum(_median_s(lambda f=f, k=k: knn_graph(f, k)) for f in feats)
                row["knn_ms"] = round(1000 * t_knn, 2)
                row["knn_share"] = round(t_knn / latency, 3)
            rows.append(row)
    knn_rows = []
    for n in (1_000, 10_000, 30_000, 100_000):
        pts = rng.random((n, 3))
        x = torch.from_numpy(pts.astype(np.float32))
        t_ours = _median_s(lambda x=x: knn_graph(x, 16), repeats=1 if n > 30_000 else 3)
        t_ref = _median_s(lambda pts=pts: cKDTree(pts).query(pts, 16), repeats=3)
        knn_rows.append(
            {
                "points": n,
                "ours_ms": round(1000 * t_ours, 1),
                "ckdtree_ms": round(1000 * t_ref, 1),
                "ratio": round(t_ours / t_ref, 1),
            }
        )
    return {
        "part": "speed",
        "seed": seed,
        "threads": torch.get_num_threads(),
        "models": rows,
        "knn_k16": knn_rows,
        "test": {},
    }


def run(part: str, seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    if part == "speed":
        return speed(seed, progress, save)
    return network(part, seed, progress, save)


def time_part(part: str, epochs: int, threads: int) -> dict[str, Any]:
    """A part's training time from ``epochs`` timed epochs plus one validation."""
    model_name, variant, task = _split(part)
    train, val, _ = _sets(model_name, variant, 0)
    model = _build(model_name, task, train, 0)
    t0 = time.perf_counter()
    C.train_cloud_model(model, train, _cfg(model_name, 0, epochs), progress=False)
    per_epoch = (time.perf_counter() - t0) / epochs
    t0 = time.perf_counter()
    C.evaluate_cloud_model(model, val)
    per_val = time.perf_counter() - t0
    spec = MODELS[model_name]
    return timing_row(part, threads, epochs, per_epoch, per_val, spec["epochs"], 1)


PARTS = [
    "pointnet",
    "dgcnn",
    "pointnet-partial",
    "dgcnn-partial",
    "pointnet-noisy",
    "dgcnn-noisy",
    "pointnet-parts",
    "dgcnn-parts",
    "speed",
]


def main(argv: list[str] | None = None) -> int:
    return figures_main(
        argv,
        name=NAME,
        description=__doc__.splitlines()[0],
        parts=PARTS,
        run=run,
        time_part=time_part,
        table=seeds_table,
        save_help="folder for the shipped models (src/robopercept/data)",
    )


if __name__ == "__main__":
    raise SystemExit(main())
