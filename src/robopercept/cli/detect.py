"""``robopercept nn detect``: train, evaluate and run object detectors (extra ``deep``).

Three forms, chosen by the first word after ``detect``::

    robopercept nn detect train --data shapes|digits|trees|COCO_JSON --model fcos -o run/
    robopercept nn detect eval RUN_OR_MODEL --data ... [-o DIR]
    robopercept nn detect IMAGE... [--model PATH] -o out/

``train`` keeps the weights of the epoch with the best validation mAP@[.5:.95]
(evaluated every ``--val-every`` epochs) and writes ``run/model.pt`` (weights with the
constructor settings and class names, :func:`~robopercept.nn.detection.zoo.save_detector`),
``history.json``, ``metrics.json`` (the 12 COCO numbers of
:func:`~robopercept.nn.detection.train.evaluate_detector` on the validation split),
``pr_curves.png`` and ``samples.png``.
``eval`` evaluates a run (or its ``model.pt``) on the validation split of the same
built-in set (same ``--images``, ``--size`` and ``--seed``) or on a whole COCO file.
``IMAGE...`` draws the boxes, labels and scores to ``out/NAME.png`` (``--json``: COCO
results, ``image_id`` the 1-based position of the image on the command line).

Without ``--model`` the ``IMAGE`` form uses the shipped FCOS model
``robopercept/data/detector_fcos_shapes.pt``; ``--model faster`` the shipped Faster
R-CNN (``detector_faster_shapes.pt``). Both were trained on the procedural shapes set
(``circle``, ``square``, ``triangle``, ``cross``) and are rebuilt, from a checkout, by::

    python -m benchmarks.detection_figures --only shapes-fcos-ema shapes-faster --seeds 0 \\
        --save src/robopercept/data

The work is done by the modules of :mod:`robopercept.nn.detection` (``zoo``, ``train``,
``tta``, ``data``) and :mod:`robopercept.nn.coco`; this module parses and prints. torch is
imported only when a command runs. Progress goes to stderr; exit 2 for bad arguments (the
message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from robopercept.cli._args import (
    UsageError,
    built_in_data_args,
    images_form_inputs,
    positive_int,
    register_forms,
    run_or_model_path,
    unit_interval,
)
from robopercept.errors import InputError

__all__ = ["BUILTIN_DATA", "DETECTOR_NAMES", "register"]

#: the names of :data:`robopercept.nn.detection.zoo.DETECTORS` (the parser needs no torch)
DETECTOR_NAMES = ("fcos", "faster", "fast", "rcnn", "localizer")
#: the built-in data sets of ``--data`` (anything else must be a COCO JSON file)
BUILTIN_DATA = ("shapes", "digits", "trees")
_VAL_FRACTION = 0.2


def _decay(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not 0 < v < 1:
        raise argparse.ArgumentTypeError(f"expects a decay in (0, 1), e.g. 0.999; got {text!r}")
    return v


def _data_args(p: argparse.ArgumentParser) -> None:
    built_in_data_args(
        p,
        "shapes, digits, trees (with --images-dir: the DeepForest folder) or a COCO JSON",
        "COCO: folder of the images (default: the JSON's folder)",
    )


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn detect train",
        description="Train a detector; writes OUT/model.pt, history.json, metrics.json "
        "(validation split), pr_curves.png and samples.png.",
    )
    _data_args(t)
    t.add_argument("--model", choices=DETECTOR_NAMES, default="fcos")
    t.add_argument("--epochs", type=positive_int, default=30, help="default 30")
    t.add_argument("--batch-size", type=positive_int, default=8, help="default 8")
    t.add_argument("--lr", type=float, default=1e-3, help="AdamW learning rate (default 1e-3)")
    t.add_argument("--width", type=positive_int, default=16, help="backbone width (default 16)")
    t.add_argument(
        "--val-every",
        type=positive_int,
        default=None,
        help="evaluate the validation split every N epochs and keep the best epoch's "
        "weights (default: epochs / 10)",
    )
    t.add_argument(
        "--ema",
        type=_decay,
        default=None,
        metavar="DECAY",
        help="keep an exponential moving average of the weights with this decay, e.g. "
        "0.999, and validate and save it (default: none)",
    )
    t.add_argument("-o", "--out", default="run", help="run folder (default run/)")
    e = cls(
        prog="robopercept nn detect eval",
        description="COCO metrics of a trained detector (RUN folder or model.pt) on the "
        "validation split of a built-in set or on a whole COCO file.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json and pr_curves.png")
    r = cls(
        prog="robopercept nn detect",
        description="Detect objects in IMAGE... and draw boxes, labels and scores to OUT/NAME.png.",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE")
    r.add_argument(
        "--model",
        help="a model.pt or run folder, or a shipped model: fcos (the default) or faster",
    )
    r.add_argument("-o", "--out", help="folder for the pictures")
    r.add_argument(
        "--score-thresh", type=unit_interval, default=0.3, help="detections kept (default 0.3)"
    )
    r.add_argument("--device", help="cpu, cuda, ...")
    r.add_argument("--json", action="store_true", help="print COCO results")
    r.add_argument("--quiet", action="store_true")
    for p in (e, r):  # the views of nn.detection.tta.TTA_VIEWS (torch is not imported here)
        p.add_argument(
            "--tta",
            choices=("hflip", "flips", "dihedral"),
            help="test-time augmentation: detect in mirrored (flips) and turned (dihedral, "
            "8 views: for top-down images) copies and fuse the boxes (default: none)",
        )
    return {"train": t, "eval": e, "images": r}


def register(ns: argparse._SubParsersAction, parser_class: type[argparse.ArgumentParser]) -> None:
    """Add ``detect`` to the ``nn`` task parsers ``ns``; ``parser_class`` parses the
    three forms (so their errors exit 2 like the others)."""
    register_forms(
        ns,
        "detect",
        "object detectors: train, eval, or detect in images (needs torch)",
        lambda: _parsers(parser_class),
        {"train": _train, "eval": _eval, "images": _images},
    )


# --------------------------------------------------------------------------- data
def _coco_dataset(path: Path, images_dir: str | None) -> Any:
    """A COCO JSON and its images as a DetectionDataset (crowd boxes dropped; labels
    are the categories' positions, 1-based, in the file's order)."""
    import numpy as np

    from robopercept.imaging import read_image
    from robopercept.nn.coco.dataset import read_coco_json
    from robopercept.nn.data.datasets import to_unit_float
    from robopercept.nn.detection.data import DetectionDataset

    root = Path(images_dir) if images_dir else path.parent
    if not root.is_dir():
        raise UsageError(f"--images-dir: {root} is not a folder")
    coco = read_coco_json(path)
    if not coco.images:
        raise InputError(f"--data {path}: no images in the COCO file")
    label = {c.id: k + 1 for k, c in enumerate(coco.categories)}
    images, boxes, labels = [], [], []
    for im in coco.images:
        f = root / im.file_name
        if not f.is_file():
            raise UsageError(f"--images-dir: {f} (image {im.id} of {path}) does not exist")
        images.append(to_unit_float(read_image(f, mode="rgb")))
        sel = (coco.image_ids == im.id) & ~coco.iscrowd
        b = coco.boxes[sel]
        boxes.append(np.hstack((b[:, :2], b[:, :2] + b[:, 2:])))
        labels.append([label[int(c)] for c in coco.category_ids[sel]])
    return DetectionDataset(
        images,
        boxes,
        labels,
        [c.name for c in coco.categories],
        image_ids=[im.id for im in coco.images],
        file_names=[im.file_name for im in coco.images],
    )


def _load_data(args: argparse.Namespace, kind: str | None) -> tuple[Any, Any]:
    """(train, validation) DetectionDatasets of ``--data``; a COCO file is split 80/20
    (seeded) for ``train`` and is wholly the validation set for ``eval``."""
    from robopercept.nn.detection.deepforest import deepforest_tiles
    from robopercept.nn.detection.synthetic import (
        digits_detection_set,
        procedural_detection_set,
        single_digit_set,
    )

    data, n, size, seed = args.data, args.images, args.size, args.seed
    if data in ("shapes", "digits"):
        if data == "shapes":
            ds = procedural_detection_set(n, size, rng=seed)
        elif kind == "localizer":
            ds = single_digit_set(n, size, rng=seed)
        else:
            ds = digits_detection_set(n, size, rng=seed)
        if n < 2:
            raise UsageError("--images: give at least 2 (a training and a validation image)")
        train, val = ds.split((1 - _VAL_FRACTION, _VAL_FRACTION), rng=seed)
        return train, val
    if data == "trees":
        if not args.images_dir or not Path(args.images_dir).is_dir():
            raise UsageError(
                f"--images-dir: --data trees needs the DeepForest NEON folder; got "
                f"{args.images_dir!r} (e.g. ../shared/data/detection/deepforest_neon)"
            )
        tiles = deepforest_tiles(args.images_dir)
        return tiles.train, tiles.test
    path = Path(data)
    if path.suffix.lower() != ".json":
        raise UsageError(
            f"--data: expects one of {', '.join(BUILTIN_DATA)} or a COCO .json file; got {data!r}"
        )
    if not path.is_file():
        raise UsageError(f"--data: COCO file {path} does not exist")
    ds = _coco_dataset(path, args.images_dir)
    if kind is None:
        return ds, ds
    if len(ds) < 2:
        raise UsageError(f"--data: {path} has {len(ds)} image; training needs at least 2")
    return ds.split((1 - _VAL_FRACTION, _VAL_FRACTION), rng=seed)


# --------------------------------------------------------------------------- outputs
def _samples(model: Any, ds: Any, path: Path, count: int = 4) -> Path:
    """Detections drawn on the first ``count`` images of ``ds``, side by side."""
    import numpy as np

    from robopercept.imaging import write_image
    from robopercept.nn.detection.zoo import detect_arrays
    from robopercept.viz.detection import draw_detections

    n = min(count, len(ds))
    pics = []
    for im, d in zip(ds.images[:n], detect_arrays(model, list(ds.images[:n])), strict=True):
        keep = d["scores"] >= 0.3
        pics.append(
            draw_detections(
                im, d["boxes"][keep], d["labels"][keep], ds.classes, scores=d["scores"][keep]
            )
        )
    h = max(p.shape[0] for p in pics)
    row = [np.pad(p, ((0, h - p.shape[0]), (0, 4), (0, 0))) for p in pics]
    return write_image(path, np.concatenate(row, axis=1))


def _write_metrics(ev: Any, ds: Any, out: Path, extra: dict[str, Any]) -> dict[str, Any]:
    from robopercept.nn.coco.evaluate import write_pr_curves

    out.mkdir(parents=True, exist_ok=True)
    metrics = {**extra, "images": len(ds), "metrics": ev.summary(), "stats": ev.stats.tolist()}
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1))
    names = {k + 1: c for k, c in enumerate(ds.classes)}
    write_pr_curves(ev, out / "pr_curves.png", names=names)
    return metrics


def _print_metrics(metrics: dict[str, Any]) -> None:
    for name, v in metrics["metrics"].items():
        print(f"  {name:<40} {v:7.4f}")


# --------------------------------------------------------------------------- forms
def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.detection.train import evaluate_detector, train_detector
    from robopercept.nn.detection.zoo import build_detector, save_detector
    from robopercept.nn.train.config import TrainConfig

    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    train, val = _load_data(args, args.model)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    settings: dict[str, Any] = {"width": args.width}
    model = build_detector(args.model, len(train.classes), seed=args.seed, **settings)
    cfg = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        device=args.device,
    )
    quiet = args.quiet or args.json
    if not quiet:
        print(
            f"nn detect train: {args.model} on {args.data} ({len(train)} training, "
            f"{len(val)} validation images)",
            file=sys.stderr,
        )
    hist = train_detector(
        model,
        train,
        cfg,
        progress=not quiet,
        val=val,
        val_every=args.val_every or max(1, args.epochs // 10),
        ema=args.ema,
    )
    model_path = save_detector(
        out / "model.pt",
        model,
        args.model,
        settings,
        train.classes,
        data=str(args.data),
        images=args.images,
        size=list(args.size),
        seed=args.seed,
        epochs=args.epochs,
    )
    (out / "history.json").write_text(
        json.dumps(
            {
                "losses": hist.losses,
                "seconds": hist.seconds,
                "val_AP": hist.val,
                "best_epoch": hist.best_epoch,
            },
            indent=1,
        )
    )
    ev = evaluate_detector(model, val)
    metrics = _write_metrics(
        ev,
        val,
        out,
        {
            "model": args.model,
            "data": str(args.data),
            "split": "validation",
            "best_epoch": hist.best_epoch,
        },
    )
    _samples(model, val, out / "samples.png")
    files = {
        name: str(out / name)
        for name in ("model.pt", "history.json", "metrics.json", "pr_curves.png", "samples.png")
    }
    assert Path(files["model.pt"]) == model_path
    if args.json:
        print(json.dumps({**metrics, "epochs": len(hist.losses), "files": files}))
        return 0
    print(
        f"nn detect train: {args.model} on {args.data}, {len(hist.losses)} epochs in "
        f"{sum(hist.seconds):.1f} s, kept epoch {hist.best_epoch} (best validation "
        f"mAP@[.5:.95]); validation mAP@0.5 {ev.stats[1]:.4f}, mAP@[.5:.95] {ev.stats[0]:.4f}"
    )
    for name, path in files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from robopercept.nn.detection.train import evaluate_detector
    from robopercept.nn.detection.tta import TestTimeAugmentation
    from robopercept.nn.detection.zoo import load_detector

    _, val = _load_data(args, None)
    path = run_or_model_path(args.model)
    if not path.is_file():
        raise UsageError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    model, info = load_detector(path)
    if list(val.classes) != list(info["classes"]):
        raise InputError(
            f"--data: its classes {list(val.classes)} differ from the model's "
            f"{info['classes']}: evaluate on the data the model was trained for"
        )
    if args.tta:
        model = TestTimeAugmentation(model, args.tta)
    ev = evaluate_detector(model, val, device=args.device)
    extra = {"model": str(args.model), "data": str(args.data), "tta": args.tta}
    if args.out:
        metrics = _write_metrics(ev, val, Path(args.out), extra)
    else:
        metrics = {**extra, "images": len(val), "metrics": ev.summary(), "stats": ev.stats.tolist()}
    if args.json:
        print(json.dumps(metrics))
        return 0
    print(f"nn detect eval: {args.model} on {args.data} ({len(val)} images)")
    _print_metrics(metrics)
    if args.out:
        print(f"-> {Path(args.out) / 'metrics.json'}, {Path(args.out) / 'pr_curves.png'}")
    return 0


def _images(args: argparse.Namespace) -> int:
    from robopercept.nn.predict import load_image_predictor

    model_path = images_form_inputs(args, "detect", lambda stem: [f"{stem}.png"])
    predictor = load_image_predictor(
        "detect", model_path, device=args.device, score_thresh=args.score_thresh, tta=args.tta
    )
    results: list[dict[str, Any]] = []
    out = Path(args.out) if args.out else None
    for k, name in enumerate(args.images, 1):
        pred = predictor.predict_file(name)
        results += pred.coco_results(k)
        if out is not None:
            (written,) = pred.write(out, Path(name).stem)
            if not (args.quiet or args.json):
                print(f"{name}: {len(pred.values['boxes'])} detections -> {written}")
    if args.json:
        print(json.dumps(results))
    return 0
