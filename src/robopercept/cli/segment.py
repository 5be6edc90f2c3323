"""``robopercept nn segment``: train, evaluate and run segmentation networks (extra
``deep``).

Three forms, chosen by the first word after ``segment``::

    robopercept nn segment train --task semantic|instance --model unet|fcn8s|...|maskrcnn
                                 --data shapes|digits|nuclei [--images-dir DIR] -o run/
    robopercept nn segment eval RUN_OR_MODEL --data ... [-o DIR]
    robopercept nn segment IMAGE... [--model PATH|unet|maskrcnn] -o out/ [--json]

``train`` keeps the weights of the epoch with the best validation score (mIoU for the
semantic networks, mask AP@[.5:.95] for Mask R-CNN) and writes ``run/model.pt``,
``history.json``, ``metrics.json`` (the validation split) and ``samples.png``
(prediction beside ground truth). ``eval`` scores a run on the validation split of the
same data (same ``--images``, ``--size`` and ``--seed``): pixel accuracy, mIoU,
frequency-weighted IoU and per-class IoU, or the 12 COCO ``segm`` numbers.
``IMAGE...`` writes ``out/NAME.png`` (class overlay with a legend, or instance
overlay with outlines and scores) and ``out/NAME_labels.png`` (class labels, or
instance ids, as a VOC-palette PNG); ``--json`` prints COCO results with RLE masks.

Without ``--model`` the ``IMAGE`` form uses the shipped U-Net; ``--model maskrcnn`` the
shipped Mask R-CNN. Both were trained on the procedural shapes and are rebuilt, from a
checkout, by ``python -m benchmarks.segmentation_figures --only shapes-unet
shapes-maskrcnn --seeds 0 --save src/robopercept/data``.

The work is done by :mod:`robopercept.nn.segmentation.networks`,
:mod:`robopercept.nn.segmentation.data`, :mod:`robopercept.nn.detection.train` and
:mod:`robopercept.viz.segmentation`; this module parses and prints. Exit 2 for bad
arguments (the message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
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

__all__ = ["SEGMENT_MODELS", "register"]

#: ``--model`` of ``train``: the semantic networks, then the instance one
SEGMENT_MODELS = ("unet", "fcn8s", "fcn16s", "fcn32s", "naive", "maskrcnn")


def _data_args(p: argparse.ArgumentParser) -> None:
    built_in_data_args(
        p,
        "procedural shapes, real-digit canvases, or the real nuclei (with --images-dir)",
        "nuclei: the stardist_nuclei folder",
        ("shapes", "digits", "nuclei"),
    )


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn segment train",
        description="Train a segmentation network; writes OUT/model.pt, history.json, "
        "metrics.json (validation split) and samples.png.",
    )
    _data_args(t)
    t.add_argument("--task", choices=("semantic", "instance"), default="semantic")
    t.add_argument("--model", choices=SEGMENT_MODELS, default=None, help="default unet / maskrcnn")
    t.add_argument("--epochs", type=positive_int, default=20, help="default 20")
    t.add_argument("--batch-size", type=positive_int, default=8, help="default 8")
    t.add_argument("--lr", type=float, default=2e-3, help="AdamW learning rate (default 2e-3)")
    t.add_argument("--width", type=positive_int, default=16, help="network width (default 16)")
    t.add_argument("-o", "--out", default="run", help="run folder (default run/)")
    e = cls(
        prog="robopercept nn segment eval",
        description="Scores of a trained segmenter (RUN folder or model.pt) on the validation "
        "split of a built-in set.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json")
    r = cls(
        prog="robopercept nn segment",
        description="Segment IMAGE... and write OUT/NAME.png (overlay) and OUT/NAME_labels.png.",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE")
    r.add_argument(
        "--model", help="a model.pt or run folder, or a shipped model: unet (default) or maskrcnn"
    )
    r.add_argument("-o", "--out", help="folder for the pictures and label PNGs")
    r.add_argument(
        "--score-thresh", type=unit_interval, default=0.5, help="instances kept (default 0.5)"
    )
    r.add_argument("--device", help="cpu, cuda, ...")
    r.add_argument("--json", action="store_true", help="print COCO results with RLE masks")
    r.add_argument("--quiet", action="store_true")
    return {"train": t, "eval": e, "images": r}


def register(ns: argparse._SubParsersAction, parser_class: type[argparse.ArgumentParser]) -> None:
    """Add ``segment`` to the ``nn`` task parsers ``ns``; ``parser_class`` parses the
    three forms (so their errors exit 2 like the others)."""
    register_forms(
        ns,
        "segment",
        "segmentation networks: train, eval, or segment images (needs torch)",
        lambda: _parsers(parser_class),
        {"train": _train, "eval": _eval, "images": _images},
    )


# --------------------------------------------------------------------------- helpers
def _sets(args: argparse.Namespace) -> Any:
    from robopercept.nn.segmentation.data import segmentation_sets

    if args.data == "nuclei" and (not args.images_dir or not Path(args.images_dir).is_dir()):
        raise UsageError(
            f"--images-dir: --data nuclei needs the stardist_nuclei folder; got "
            f"{args.images_dir!r} (e.g. ../shared/data/segmentation/stardist_nuclei)"
        )
    if args.images < 2:
        raise UsageError("--images: give at least 2 (a training and a validation image)")
    return segmentation_sets(args.data, args.images, args.size, args.seed, args.images_dir)


def _scores(model: Any, val: Any, instance: bool, device: str | None) -> dict[str, Any]:
    import numpy as np

    from robopercept.nn.detection.train import evaluate_detector
    from robopercept.nn.segmentation.metrics import segmentation_confusion, segmentation_scores
    from robopercept.nn.segmentation.networks import segment_arrays

    if instance:
        ev = evaluate_detector(model, val, device=device, iou_type="segm")
        return {"metrics": ev.summary(), "stats": ev.stats.tolist()}
    if device:
        from robopercept.nn.train.config import resolve_device

        model.to(resolve_device(device))
    pred = np.stack(segment_arrays(model, list(val.images)))
    k = len(val.classes) + 1
    s = segmentation_scores(segmentation_confusion(val.class_maps(), pred, k))
    names = ["background", *val.classes]
    return {
        "metrics": {
            "pixel_accuracy": s.pixel_accuracy,
            "mean_accuracy": s.mean_accuracy,
            "mIoU": s.miou,
            "fwIoU": s.fwiou,
        },
        "iou": {n: (None if np.isnan(v) else float(v)) for n, v in zip(names, s.iou, strict=True)},
    }


def _samples(model: Any, val: Any, instance: bool, path: Path, count: int = 3) -> Path:
    from robopercept.imaging import write_image
    from robopercept.nn.predict import ImagePrediction, ImagePredictor
    from robopercept.viz.segmentation import panels_picture

    classes = list(val.classes)
    predictor = ImagePredictor("segment", None, model, {"classes": classes}, instance=instance)
    pics, titles = [], []
    for i in range(min(count, len(val))):
        im = val.images[i]
        truth: dict[str, Any] = (
            {"masks": val.masks[i], "labels": val.labels[i]}
            if instance
            else {"labels": val.class_maps()[i]}
        )
        pics += [predictor.predict(im).pictures("p")["p.png"]]
        pics += [ImagePrediction("segment", im, classes, truth).pictures("t")["t.png"]]
        titles += [f"prediction {i + 1}", f"ground truth {i + 1}"]
    return write_image(path, panels_picture(pics, titles))


# --------------------------------------------------------------------------- forms
def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.detection.train import train_detector
    from robopercept.nn.detection.zoo import build_detector, save_detector
    from robopercept.nn.segmentation.networks import (
        build_segmenter,
        save_segmenter,
        train_segmenter,
    )
    from robopercept.nn.train.config import TrainConfig

    model_name = args.model or ("maskrcnn" if args.task == "instance" else "unet")
    if (model_name == "maskrcnn") != (args.task == "instance"):
        raise UsageError(
            f"--model: {model_name} does not do --task {args.task} (maskrcnn is the instance "
            "model; unet, fcn8s, fcn16s, fcn32s and naive are semantic)"
        )
    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    sets = _sets(args)
    train, val = sets.train, sets.val
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
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
            f"nn segment train: {model_name} ({args.task}) on {args.data} ({len(train)} "
            f"training, {len(val)} validation images)",
            file=sys.stderr,
        )
    settings: dict[str, Any] = {"width": args.width}
    extra = {"data": args.data, "images": args.images, "size": list(args.size), "seed": args.seed}
    instance = model_name == "maskrcnn"
    if instance:
        model = build_detector("maskrcnn", len(sets.classes), seed=args.seed, **settings)
        hist = train_detector(
            model,
            train,
            cfg,
            progress=not quiet,
            val=val,
            val_every=max(1, args.epochs // 10),
            val_iou_type="segm",
        )
        save_detector(out / "model.pt", model, "maskrcnn", settings, list(sets.classes), **extra)
        history = {"losses": hist.losses, "val_mask_AP": hist.val, "best_epoch": hist.best_epoch}
    else:
        import numpy as np

        if model_name == "unet":
            settings["depth"] = 4
        model = build_segmenter(model_name, len(sets.classes) + 1, **settings)
        seg = train_segmenter(
            model,
            np.stack(train.images),
            train.class_maps(),
            cfg,
            val=(np.stack(val.images), val.class_maps()),
            dihedral=False,
            progress=not quiet,
        )
        save_segmenter(out / "model.pt", model, model_name, settings, list(sets.classes), **extra)
        history = {"losses": seg.losses, "val_mIoU": seg.val, "best_epoch": seg.best_epoch}
    (out / "history.json").write_text(json.dumps(history, indent=1))
    metrics = {
        "model": model_name,
        "task": args.task,
        "data": args.data,
        "split": "validation",
        "best_epoch": history["best_epoch"],
        **_scores(model, val, instance, args.device),
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1))
    _samples(model, val, instance, out / "samples.png")
    files = {n: str(out / n) for n in ("model.pt", "history.json", "metrics.json", "samples.png")}
    if args.json:
        print(json.dumps({**metrics, "files": files}))
        return 0
    key = "AP" if instance else "mIoU"
    figure = metrics["metrics"][next(k for k in metrics["metrics"] if k.startswith(key))]
    print(
        f"nn segment train: {model_name} on {args.data}, kept epoch {history['best_epoch']}; "
        f"validation {'mask AP@[.5:.95]' if instance else 'mIoU'} {figure:.4f}"
    )
    for name, path in files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    path = run_or_model_path(args.model)
    if not path.is_file():
        raise UsageError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    from robopercept.nn.predict import load_segment_model

    model, info, instance = load_segment_model(path)
    sets = _sets(args)
    if list(sets.classes) != list(info["classes"]):
        raise InputError(
            f"--data: its classes {list(sets.classes)} differ from the model's "
            f"{info['classes']}: evaluate on the data the model was trained for"
        )
    metrics = {
        "model": str(args.model),
        "data": args.data,
        "images": len(sets.val),
        **_scores(model, sets.val, instance, args.device),
    }
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "metrics.json").write_text(json.dumps(metrics, indent=1))
    if args.json:
        print(json.dumps(metrics))
        return 0
    print(f"nn segment eval: {args.model} on {args.data} ({len(sets.val)} images)")
    for name, v in metrics["metrics"].items():
        print(f"  {name:<40} {v:7.4f}")
    return 0


def _images(args: argparse.Namespace) -> int:
    from robopercept.nn.predict import load_image_predictor

    model_path = images_form_inputs(
        args, "segment", lambda stem: [f"{stem}.png", f"{stem}_labels.png"]
    )
    predictor = load_image_predictor(
        "segment", model_path, device=args.device, score_thresh=args.score_thresh
    )
    instance = predictor.instance
    out = Path(args.out) if args.out else None
    results: list[dict[str, Any]] = []
    for k, name in enumerate(args.images, 1):
        pred = predictor.predict_file(name)
        results += pred.coco_results(k)
        if out is not None:
            pic, lab = pred.write(out, Path(name).stem)
            if not (args.quiet or args.json):
                v = pred.values
                n = len(v["masks"]) if instance else len({int(x) for x in v["labels"].flat})
                what = "instances" if instance else "labels"
                print(f"{name}: {n} {what} -> {pic}, {lab}")
    if args.json:
        print(json.dumps(results))
    return 0
