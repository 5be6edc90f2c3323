"""Issue 26's accuracy figures for :mod:`robopercept.nn.detection`, trained here on the
CPU (run ``python -m benchmarks.detection_figures --only PART --seeds 0 1 2``; each run
is merged into ``benchmarks/results/detection_figures.json`` and the table printed).

Every run: the weights drawn from ``torch.manual_seed(seed)``, trained with
:func:`~robopercept.nn.detection.train.train_detector` (AdamW, cosine schedule), the epoch
kept chosen on a validation split (``val=``), then evaluated once on a test split that
no choice saw. Synthetic sets are generated with disjoint seeds (train ``seed``,
validation ``1000 + seed``, test always ``99``, so every seed is tested on the same
images).

Parts:

- ``trees-fcos``, ``trees-faster``: the single-stage FCOS (target AP50 >= 0.45) and
  Faster R-CNN (reported beside it) on the real DeepForest NEON crowns
  (:func:`~robopercept.nn.detection.deepforest.deepforest_tiles`, 400 px tiles): the tiles
  above the held-out strip split 85/15 (seeded) into train and validation, AP50 on the
  held-out strip of YELL crop2, AP50 on the three other images reported. FCOS's final
  NMS threshold is chosen on the validation tiles (:func:`choose_nms`).
  ``trees-fcos-zoom`` is FCOS with :class:`~robopercept.nn.detection.augment.ScaleJitter`
  (zoom 0.67-1.5) after the flips.
- ``shapes-fcos``, ``shapes-faster``: the procedural set at 128 x 128 (target
  mAP@0.5 >= 0.90 and mAP@[.5:.95] >= 0.60).
- ``digits``: Faster R-CNN on the real-digits canvases (target mAP@0.5 >= 0.90). FCOS
  reached only 0.35-0.38 here (600 or 2000 canvases, seed 0), with a very low AP75.
- ``localizer``: :class:`~robopercept.nn.detection.localizer.SingleObjectLocalizer` on one real
  digit per 64 x 64 canvas (target mean IoU >= 0.80).
- ``family``: R-CNN, Fast R-CNN and Faster R-CNN on the same real-digits canvases:
  test mAP and the per-image latency (1 thread, batch 1, median of the test images;
  the R-CNN and Fast R-CNN latency includes their selective search, as at run time).
  During training the selective-search proposals of each training image are computed
  once and cached (they do not change between epochs).
"""

from __future__ import annotations

import functools
import hashlib
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks._harness import figures_main, load_runs, timing_row
from robopercept.nn.detection.augment import FlipRotate, ScaleJitter
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.deepforest import deepforest_tiles
from robopercept.nn.detection.localizer import evaluate_localizer
from robopercept.nn.detection.rcnn import selective_search_proposals
from robopercept.nn.detection.synthetic import (
    digits_detection_set,
    procedural_detection_set,
    single_digit_set,
)
from robopercept.nn.detection.train import evaluate_detector, train_detector
from robopercept.nn.detection.tta import TestTimeAugmentation
from robopercept.nn.detection.zoo import build_detector, calibrate_detector, save_detector
from robopercept.nn.train.config import TrainConfig

NAME = "detection_figures"
TREES = os.environ.get("ROBOPERCEPT_DEEPFOREST", "../shared/data/detection/deepforest_neon")


def _synthetic(make: Callable[..., Any], n: tuple[int, int, int], seed: int) -> tuple:
    return make(n[0], rng=seed), make(n[1], rng=1000 + seed), make(n[2], rng=99), {}


def chunked(
    make: Callable[..., Any], k: int, rng: int, chunk: int = 500, masks: bool = False
) -> Any:
    """``make(k, rng)`` built ``chunk`` images at a time (seeds ``rng * 100 + j``): one
    generator call's masks would pass the 1 GiB guard beyond ~1000 images. The chunks'
    masks are dropped unless ``masks`` (the detectors do not use them; a set of up to
    ``chunk`` images keeps them either way)."""
    if k <= chunk:
        return make(k, rng=rng)
    parts = [make(min(chunk, k - s), rng=rng * 100 + j) for j, s in enumerate(range(0, k, chunk))]
    return DetectionDataset(
        [im for p in parts for im in p.images],
        [b for p in parts for b in p.boxes],
        [lab for p in parts for lab in p.labels],
        parts[0].classes,
        masks=[m for p in parts for m in p.masks or ()] if masks else None,
    )


def _shapes(n: tuple[int, int, int], seed: int) -> tuple:
    make = functools.partial(procedural_detection_set, size=(128, 128))
    return _synthetic(functools.partial(chunked, make), n, seed)


def _digits(n: tuple[int, int, int], seed: int) -> tuple:
    make = functools.partial(digits_detection_set, size=(128, 128))
    return _synthetic(functools.partial(chunked, make), n, seed)


def _family_digits(n: tuple[int, int, int], seed: int) -> tuple:
    return _synthetic(lambda k, rng: digits_detection_set(k, (96, 96), (1, 3), rng=rng), n, seed)


def _single(n: tuple[int, int, int], seed: int) -> tuple:
    return _synthetic(lambda k, rng: single_digit_set(k, (64, 64), rng=rng), n, seed)


def _trees(n: tuple[int, int, int], seed: int, extra: tuple[str, ...] = ()) -> tuple:
    tiles = deepforest_tiles(TREES, train_extra=extra)
    train, val = tiles.train.split((0.85, 0.15), rng=seed)
    return train, val, tiles.test, dict(tiles.cross)


#: the other YELL image (same site as the strip, 13 km away), trained on by trees-all
YELL_CROP = "2019_YELL_2_541000_4977000_image_crop"


def _part(
    data: Callable[..., Any],
    n: tuple[int, int, int],
    kind: str,
    settings: dict[str, Any],
    metric: str,
    epochs: int,
    batch_size: int = 8,
    lr: float = 2e-3,
    augment: dict[str, Any] | None = None,
    nms_grid: tuple[float, ...] | None = None,
    ema: float | None = None,
    tta: str | None = None,
) -> dict[str, Any]:
    train = {"epochs": epochs, "batch_size": batch_size, "lr": lr, "weight_decay": 1e-4}
    return {
        "data": data,
        "n": n,
        "kind": kind,
        "settings": settings,
        "train": train,
        "metric": metric,
        "augment": augment,
        "nms_grid": nms_grid,
        "ema": ema,
        "tta": tta,
    }


_FCOS = {"width": 16, "score_thresh": 0.05}
#: every flip and quarter turn (FlipRotate): for the top-down trees. Not for digits
#: (orientation is their class); not for the shapes either: with it, FCOS's validation
#: AP stayed 0.0 from epoch 3 to 30 (seed 0, 2000 canvases), where without it the same
#: run reached 0.65. Its box branch had died: every (l, t, r, b) output was <= 0 before
#: FCOS's ReLU, so every box had zero size and the ReLU passed no gradient back (the
#: reason for FCOS's box_activation="exp", which the trees part uses)
_DIHEDRAL = {"horizontal": 0.5, "vertical": 0.5, "rotate90": True}
_TREES_FCOS = _part(
    _trees,
    (0, 0, 0),
    "fcos",
    {**_FCOS, "box_activation": "exp", "center_radius": 2.5},
    "AP50",
    200,
    batch_size=4,
    augment=_DIHEDRAL,
    nms_grid=(0.3, 0.4, 0.5, 0.6),
)
#: trees-fcos with two residual blocks per backbone stage, scale jitter, an EMA of the
#: weights and dihedral TTA (trees-fcos-blocks2, the recipe the shipped model follows)
_TREES_BLOCKS2 = {
    **_TREES_FCOS,
    "settings": {**_TREES_FCOS["settings"], "blocks": 2},
    "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)},
    "ema": 0.995,
    "tta": "dihedral",
}
#: part -> data builder ((train, val, test) image counts, seed) -> (train, val, test,
#: cross-image tests), the counts, detector kind, settings, TrainConfig keywords, the
#: validation metric that picks the epoch and the NMS thresholds it chooses from
PARTS: dict[str, dict[str, Any]] = {
    # The single-stage detector carries the trees target. FCOS with the paper's exp box
    # output (torchvision's ReLU died under flips and turns), centre sampling radius 2.5
    # (1.5 gave 0.372 on seed 0, centerness-weighted GIoU 0.339), 200 epochs, and the
    # final NMS threshold chosen on the validation tiles
    "trees-fcos": _TREES_FCOS,
    # the same with scale jitter (ScaleJitter, zoom 0.67-1.5 at the tile size) after the
    # flips: the validation curve of trees-fcos peaks at epoch 100 of 200 and falls
    # (26 tiles are learnt by heart); an experiment
    "trees-fcos-zoom": {**_TREES_FCOS, "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)}},
    # and with an exponential moving average of the weights (train_detector's ema)
    "trees-fcos-ema": {
        **_TREES_FCOS,
        "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)},
        "ema": 0.995,
        "tta": "dihedral",
    },
    # and with the IoU of the decoded box as the third branch's target (IoU-aware)
    "trees-fcos-iou": {
        **_TREES_FCOS,
        "settings": {**_TREES_FCOS["settings"], "quality": "iou"},
        "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)},
        "ema": 0.995,
        "tta": "dihedral",
    },
    # and with AdamW's usual weight decay (0.05) instead of 1e-4, against memorisation
    "trees-fcos-wd": {
        **_TREES_FCOS,
        "train": {**_TREES_FCOS["train"], "weight_decay": 0.05},
        "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)},
        "ema": 0.995,
        "tta": "dihedral",
    },
    # and with torchvision's 4-layer head towers instead of 2
    "trees-fcos-deep": {
        **_TREES_FCOS,
        "settings": {**_TREES_FCOS["settings"], "num_convs": 4},
        "augment": {**_DIHEDRAL, "scale": (0.67, 1.5)},
        "ema": 0.995,
        "tta": "dihedral",
    },
    # and with two residual blocks per backbone stage instead of one (0.93M parameters)
    "trees-fcos-blocks2": _TREES_BLOCKS2,
    # and trained on every DeepForest tile but the strip's (the issue's "all but the
    # held-out strip": YELL crop joins the training tiles, 42 tiles in all), for 240
    # epochs: blocks2's validation AP still rose at its last epoch (0.588 at 180, 0.594
    # at 200). OSBS_029 and SOAP_061 stay the other sites' tests
    "trees-all": {
        **_TREES_BLOCKS2,
        "data": functools.partial(_trees, extra=(YELL_CROP,)),
        "train": {**_TREES_FCOS["train"], "epochs": 240},
    },
    # Faster R-CNN beside it, reported: anchors 16/32/64 px for crowns of 15-69 px
    "trees-faster": _part(
        _trees,
        (0, 0, 0),
        "faster",
        {"width": 16},
        "AP50",
        200,
        batch_size=4,
        augment=_DIHEDRAL,
    ),
    "shapes-fcos": _part(_shapes, (2000, 100, 200), "fcos", _FCOS, "AP", 30),
    # the same with an EMA of the weights (horizon 1000 steps, 4 of the 30 epochs)
    "shapes-fcos-ema": _part(_shapes, (2000, 100, 200), "fcos", _FCOS, "AP", 30, ema=0.999),
    # 20 epochs: at 30 (best epochs 27, 27, 24) it took 1,089 s alone on 2 threads,
    # over the 15 minutes (the 30-epoch runs are kept as experiments)
    "shapes-faster": _part(_shapes, (2000, 100, 200), "faster", {"width": 16}, "AP", 20),
    "digits": _part(_digits, (1000, 100, 200), "faster", {"width": 16}, "AP50", 30),
    "localizer": _part(
        _single, (1000, 200, 500), "localizer", {"width": 16}, "AP", 30, batch_size=32
    ),
    "family-rcnn": _part(_family_digits, (300, 60, 100), "rcnn", {}, "AP50", 15),
    "family-fast": _part(_family_digits, (300, 60, 100), "fast", {"width": 16}, "AP50", 15),
    "family-faster": _part(_family_digits, (300, 60, 100), "faster", {"width": 16}, "AP50", 15),
}


class CachedProposals:
    """Selective-search proposals memoized by image content (training revisits each
    image every epoch; its proposals never change)."""

    def __init__(self) -> None:
        self.cache: dict[str, torch.Tensor] = {}
        self.seconds = 0.0

    def __call__(self, image: torch.Tensor) -> torch.Tensor:
        key = hashlib.blake2b(image.detach().cpu().numpy().tobytes(), digest_size=16).hexdigest()
        if key not in self.cache:
            t0 = time.perf_counter()
            self.cache[key] = selective_search_proposals(image)
            self.seconds += time.perf_counter() - t0
        return self.cache[key]


def choose_nms(
    model: torch.nn.Module, val: Any, grid: tuple[float, ...], metric: str
) -> tuple[float, dict[str, float]]:
    """The final NMS IoU threshold of ``grid`` with the best validation ``metric`` (the
    first on ties), and the metric of each: a post-processing choice made on the
    validation split like the epoch, never on the test split."""
    scores = {}
    for t in grid:
        model.nms_thresh = t
        scores[str(t)] = float(evaluate_detector(model, val).summary()[metric])
    best = max(grid, key=lambda t: scores[str(t)])
    return best, scores


def _latency_ms(model: torch.nn.Module, images: list[np.ndarray], k: int = 20) -> float:
    model.eval()
    times = []
    with torch.no_grad():
        for im in images[:k]:
            x = torch.from_numpy(np.ascontiguousarray(im.transpose(2, 0, 1))).float()
            t0 = time.perf_counter()
            model([x])
            times.append(time.perf_counter() - t0)
    return 1000 * statistics.median(times)


def _augmenter(spec: dict[str, Any] | None, seed: int) -> Any:
    """FlipRotate from ``spec``'s flip keys, then ScaleJitter where ``spec["scale"]``
    gives its ``(low, high)``; None for no augmentation."""
    if not spec:
        return None
    flips = {k: v for k, v in spec.items() if k != "scale"}
    flip = FlipRotate(**flips, generator=seed)
    if "scale" not in spec:
        return flip
    zoom = ScaleJitter(tuple(spec["scale"]), generator=10_000 + seed)

    def both(image: torch.Tensor, target: dict[str, Any]) -> tuple[torch.Tensor, dict]:
        return zoom(*flip(image, target))

    return both


def _setup(
    spec: dict[str, Any], train: Any, seed: int, epochs: int | None = None
) -> tuple[torch.nn.Module, TrainConfig, CachedProposals | None]:
    """The model (weights from ``seed``), the TrainConfig (``epochs`` overriding the
    part's) and the proposal cache (R-CNN and Fast R-CNN) of a run of ``spec``."""
    settings = dict(spec["settings"])
    cached = None
    if spec["kind"] in ("fast", "rcnn"):
        cached = CachedProposals()
        settings["proposal_fn"] = cached
    model = build_detector(spec["kind"], len(train.classes), seed=seed, **settings)
    train_kw = {**spec["train"], **({"epochs": epochs} if epochs else {})}
    cfg = TrainConfig(seed=seed, device="cpu", schedule="cosine", clip_grad_norm=10.0, **train_kw)
    return model, cfg, cached


def run_one(
    part: str, seed: int, progress: bool = True, save: Path | None = None
) -> dict[str, Any]:
    spec = PARTS[part]
    train, val, test, cross = spec["data"](spec["n"], seed)
    model, cfg, cached = _setup(spec, train, seed)
    t0 = time.perf_counter()
    augment = _augmenter(spec["augment"], seed)
    hist = train_detector(
        model,
        train,
        cfg,
        progress=progress,
        val=val,
        val_every=max(1, cfg.epochs // 10),
        val_metric=spec["metric"],
        augment=augment,
        ema=spec.get("ema"),
    )
    wall = time.perf_counter() - t0
    nms_val = None
    if spec.get("nms_grid"):
        model.nms_thresh, nms_val = choose_nms(model, val, spec["nms_grid"], spec["metric"])
    ev = evaluate_detector(model, test)
    tta = None
    deployed: torch.nn.Module = model
    if spec.get("tta"):
        # test-time augmentation is kept only where it beats the plain model on the
        # validation tiles (the same rule as the epoch and the NMS threshold)
        wrapped = TestTimeAugmentation(model, spec["tta"])
        val_plain = float(evaluate_detector(model, val).summary()[spec["metric"]])
        val_tta = float(evaluate_detector(wrapped, val).summary()[spec["metric"]])
        ev_tta = evaluate_detector(wrapped, test)
        tta = {
            "views": spec["tta"],
            "val": val_tta,
            "val_plain": val_plain,
            "used": val_tta > val_plain,
            "test": {k: round(v, 4) for k, v in ev_tta.summary().items()},
            "test_plain": {k: round(v, 4) for k, v in ev.summary().items()},
        }
        if tta["used"]:
            ev, deployed = ev_tta, wrapped
    row: dict[str, Any] = {
        "part": part,
        "seed": seed,
        "kind": spec["kind"],
        "settings": {k: v for k, v in spec["settings"].items()},
        "train": spec["train"],
        "augment": spec["augment"],
        "ema": spec.get("ema"),
        "parameters": sum(p.numel() for p in model.parameters()),
        "images": {"train": len(train), "val": len(val), "test": len(test)},
        "train_seconds": round(wall, 1),
        "proposal_seconds": round(cached.seconds, 1) if cached else None,
        "val": hist.val,
        "best_epoch": hist.best_epoch,
        "nms_thresh": model.nms_thresh,
        "nms_val": nms_val,
        "tta": tta,
        "test": {k: round(v, 4) for k, v in ev.summary().items()},
    }
    if spec["kind"] == "localizer":
        loc = evaluate_localizer(model, test)
        row["test"]["mean_iou"] = round(loc.mean_iou, 4)
        row["test"]["accuracy"] = round(loc.accuracy, 4)
    if cross:
        row["cross_AP50"] = {
            name: round(float(evaluate_detector(deployed, ds).stats[1]), 4)
            for name, ds in cross.items()
        }
    if save is not None:
        path = save / f"detector_{spec['kind']}_{part.split('-')[0]}.pt"
        save_detector(
            path,
            model,
            spec["kind"],
            {**spec["settings"], "nms_thresh": model.nms_thresh},
            train.classes,
            calibration=calibrate_detector(model, val).to_dict(),
            # the procedural canvases: a much larger input is outside the domain
            **({"canvas": [128, 128]} if part.startswith("shapes") else {}),
            data=part,
            seed=seed,
            built_by=f"python -m benchmarks.detection_figures --only {part} --seeds {seed} "
            "--save DIR",
            test=row["test"],
        )
        row["saved"] = str(path)
    if part.startswith("family"):
        if cached is not None:  # at run time proposals are not cached
            model.proposal_fn = selective_search_proposals  # type: ignore[assignment]
        torch.set_num_threads(1)
        row["latency_ms"] = round(_latency_ms(model, list(test.images)), 1)
        torch.set_num_threads(2)
    return row


def _load() -> dict[str, Any]:
    return load_runs(NAME)


def table(results: dict[str, Any]) -> str:
    """Mean +- std over the seeds run, per part."""
    keys = ("AP", "AP50", "mean_iou")
    lines = [
        "| part | seeds | " + " | ".join(keys) + " | train s | latency ms |",
        "|---|---|" + "---:|" * (len(keys) + 2),
    ]
    by: dict[str, list[dict[str, Any]]] = {}
    for row in results["runs"].values():
        by.setdefault(row["part"], []).append(row)
    for part, rows in sorted(by.items()):
        cells = []
        for k in keys:
            v = [r["test"][k] for r in rows if k in r["test"]]
            cells.append(f"{np.mean(v):.3f} ± {np.std(v):.3f}" if v else "")
        t = [r["train_seconds"] for r in rows]
        lat = [r["latency_ms"] for r in rows if "latency_ms" in r]
        seeds = ",".join(str(r["seed"]) for r in sorted(rows, key=lambda r: r["seed"]))
        lines.append(
            f"| {part} | {seeds} | "
            + " | ".join(cells)
            + f" | {np.mean(t):.0f} | {f'{np.mean(lat):.0f}' if lat else ''} |"
        )
    return "\n".join(lines)


def time_part(part: str, epochs: int, threads: int) -> dict[str, Any]:
    """The training time of ``part`` measured on a few epochs: ``epochs`` epochs of its
    seed-0 run (same data, model, batch size and augmentation; no validation), plus one
    evaluation of its validation split, extrapolated to the part's epochs and its
    validations (every epochs / 10 epochs and after the last, as :func:`run_one`). Run
    it with nothing else on the machine: the figure is the time a full run takes alone."""
    spec = PARTS[part]
    train, val, _, _ = spec["data"](spec["n"], 0)
    model, cfg, _ = _setup(spec, train, 0, epochs)
    t0 = time.perf_counter()
    train_detector(
        model,
        train,
        cfg,
        progress=False,
        augment=_augmenter(spec["augment"], 0),
        ema=spec.get("ema"),
    )
    per_epoch = (time.perf_counter() - t0) / epochs
    t0 = time.perf_counter()
    evaluate_detector(model, val)
    per_val = time.perf_counter() - t0
    full = spec["train"]["epochs"]
    return timing_row(part, threads, epochs, per_epoch, per_val, full, max(1, full // 10))


def main(argv: list[str] | None = None) -> int:
    return figures_main(
        argv,
        name=NAME,
        description=__doc__.splitlines()[0],
        parts=list(PARTS),
        run=lambda part, seed, progress, save: run_one(part, seed, progress, save),
        time_part=time_part,
        table=table,
        save_help="write each trained model to DIR/detector_KIND_DATA.pt (the shipped "
        "models: --only shapes-fcos-ema shapes-faster --seeds 0 --save src/robopercept/data)",
    )


if __name__ == "__main__":
    raise SystemExit(main())
