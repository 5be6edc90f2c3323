"""``robopercept nn detect``: train, evaluate and run object detectors (extra ``deep``).

Three forms, chosen by the first word after ``detect``::

    robopercept nn detect train --data shapes|digits|trees|COCO_JSON|FOLDER --model fcos -o run/ \
        [--resume | --overwrite]
    robopercept nn detect eval RUN_OR_MODEL --data ... [-o DIR]
    robopercept nn detect IMAGE... [--model PATH] -o out/

``train`` keeps the weights of the epoch with the best validation mAP@[.5:.95]
(evaluated every ``--val-every`` epochs) and writes ``run/model.pt`` (weights with the
constructor settings and class names, :func:`~robopercept.nn.detection.zoo.save_detector`),
``history.json``, ``metrics.json`` (the 12 COCO numbers of
:func:`~robopercept.nn.detection.train.evaluate_detector` on the validation split),
``pr_curves.png`` and ``samples.png``, beside ``checkpoint.pt`` (the last complete
epoch, written after every epoch) and ``checkpoint.best.pt``. A folder that holds a run
is refused (exit 2) unless ``--resume`` continues it (to the weights of an uninterrupted
run) or ``--overwrite`` replaces it; Ctrl-C (exit 130) and SIGTERM (exit 143) keep the
last complete epoch.
``eval`` evaluates a run (or its ``model.pt``) on the validation split of the same
built-in set (same ``--images``, ``--size`` and ``--seed``) or on a whole COCO file.
``IMAGE...`` draws the boxes, labels and scores to ``out/NAME.png`` (``--json``: COCO
results, ``image_id`` the 1-based position of the image on the command line).
``NAME`` is the input's file name without its extension; inputs that share one get
their folders' names in front (``a/x.png``, ``b/x.png``: ``a_x``, ``b_x``), and inputs
still alike ``-2``, ``-3`` (:func:`robopercept.imaging.io.output_stems`).
``--allow-outside-paths`` lets ``train`` and ``eval`` read images that your annotations
place outside their folder (refused by default).

Without ``--model`` the ``IMAGE`` form uses the shipped FCOS model
``robopercept/data/detector_fcos_shapes.pt``; ``--model faster`` the shipped Faster
R-CNN (``detector_faster_shapes.pt``). Both were trained on the procedural shapes set
(``circle``, ``square``, ``triangle``, ``cross``) and are rebuilt, from a checkout, by::

    python -m benchmarks.detection_figures --only shapes-fcos-ema shapes-faster --seeds 0 \\
        --save src/robopercept/data

The work is done by :mod:`robopercept.nn.detection.run` (``train`` and ``eval``:
:func:`~robopercept.nn.detection.run.train_run`,
:func:`~robopercept.nn.detection.run.evaluate_run`) and :mod:`robopercept.nn.predict`
(``IMAGE...``); this module parses and prints. torch is imported only when a command
runs. Progress goes to stderr; exit 2 for bad arguments (the
message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, positive_int
from robopercept.cli.nn._forms import (
    OUTPUT_NAMES_HELP,
    built_in_data_args,
    check_run_folder_args,
    data_path_options,
    device_arg,
    images_form_inputs,
    note_warning,
    prediction_args,
    prediction_json,
    print_model_line,
    register_forms,
    run_folder_args,
)

__all__ = ["BUILTIN_DATA", "DETECTOR_NAMES", "register"]

#: the names of :data:`robopercept.nn.detection.zoo.DETECTORS` (the parser needs no torch)
DETECTOR_NAMES = ("fcos", "faster", "fast", "rcnn", "localizer")
#: the built-in data sets of ``--data`` (anything else must be a COCO JSON file)
BUILTIN_DATA = ("shapes", "digits", "trees")


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
        "shapes, digits, trees (with --images-dir: the DeepForest folder), or your own "
        "annotated images: a COCO JSON, or a folder of labelme .json or Pascal-VOC .xml files "
        "or a VOC SegmentationObject/ folder",
        "your own data: folder of the images (default: where the annotations put them)",
    )


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn detect train",
        description="Train a detector; writes OUT/model.pt, history.json, metrics.json "
        "(validation split), pr_curves.png and samples.png.",
    )
    _data_args(t)
    t.add_argument(
        "--model",
        choices=DETECTOR_NAMES,
        default="fcos",
        help="FCOS (one stage, anchor-free), Faster R-CNN (region proposal network and RoI "
        "heads), Fast R-CNN and R-CNN (selective-search proposals), or a one-object "
        "localizer",
    )
    t.add_argument("--epochs", type=positive_int, default=30, help="most epochs (default 30)")
    t.add_argument("--batch-size", type=positive_int, default=8, help="images per step (default 8)")
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
    run_folder_args(t)
    e = cls(
        prog="robopercept nn detect eval",
        description="COCO metrics of a trained detector (RUN folder or model.pt) on the "
        "validation split of a built-in set or on a whole COCO file.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL", help="a run folder or its model.pt")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json and pr_curves.png")
    r = cls(
        prog="robopercept nn detect",
        description="Detect objects in IMAGE... and draw boxes, labels and scores to "
        f"OUT/NAME.png. {OUTPUT_NAMES_HELP}.",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE", help="images to detect objects in")
    prediction_args(r, "detect", scores="detections", tiling=True)
    r.add_argument("-o", "--out", help="folder for the pictures")
    device_arg(r)
    r.add_argument(
        "--json",
        action="store_true",
        help='print {"model": LINE, "warnings": [...], "results": [COCO results]}',
    )
    r.add_argument("--quiet", action="store_true", help="no progress on stderr")
    # the views of nn.detection.tta.TTA_VIEWS and TTA_CHOICES (torch is not imported here)
    e.add_argument(
        "--tta",
        choices=("hflip", "flips", "dihedral"),
        help="test-time augmentation: detect in mirrored (flips) and turned (dihedral, "
        "8 views: for top-down images) copies and fuse the boxes (default: none)",
    )
    r.add_argument(
        "--tta",
        choices=("none", "identity", "hflip", "flips", "dihedral"),
        help="test-time augmentation: detect in mirrored (flips) and turned (dihedral, "
        "8 views: for top-down images) copies and fuse the boxes; default the model's own "
        "(the trees model: flips at 3 scales, chosen on its validation tiles), else none; "
        "none turns it off",
    )
    r.add_argument(
        "--tta-scales",
        type=float,
        nargs="+",
        metavar="S",
        help="image scales of test-time augmentation, e.g. 0.9 1 1.1 (with --tta identity: "
        "rescaled copies only); default the model's, else 1",
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


def _print_metrics(metrics: dict[str, Any]) -> None:
    for name, v in metrics["metrics"].items():
        print(f"  {name:<40} {v:7.4f}")


# --------------------------------------------------------------------------- forms
def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.detection.run import TrainConfig, train_run

    check_run_folder_args(args)
    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    cfg = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        device=args.device,
    )
    res = train_run(
        args.data,
        args.out,
        model=args.model,
        config=cfg,
        width=args.width,
        images=args.images,
        size=args.size,
        images_dir=args.images_dir,
        val_every=args.val_every,
        **data_path_options(args),
        ema=args.ema,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=not (args.quiet or args.json),
    )
    if args.json:
        print(json.dumps(res.to_dict()))
        return 0
    ev = res.evaluation
    print(
        f"nn detect train: {args.model} on {args.data}, {len(res.history.losses)} epochs in "
        f"{res.seconds:.1f} s, kept epoch {res.best_epoch} (best validation "
        f"mAP@[.5:.95]); validation mAP@0.5 {ev.stats[1]:.4f}, mAP@[.5:.95] {ev.stats[0]:.4f}"
    )
    for name, path in res.files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from robopercept.nn.detection.run import evaluate_run

    res = evaluate_run(
        args.model,
        args.data,
        images=args.images,
        size=args.size,
        seed=args.seed,
        images_dir=args.images_dir,
        tta=args.tta,
        **data_path_options(args),
        device=args.device,
        out_dir=args.out or None,
    )
    metrics = res.to_dict()
    if args.json:
        print(json.dumps(metrics))
        return 0
    print(f"nn detect eval: {args.model} on {args.data} ({res.images} images)")
    _print_metrics(metrics)
    if args.out:
        print(f"-> {Path(args.out) / 'metrics.json'}, {Path(args.out) / 'pr_curves.png'}")
    return 0


def _images(args: argparse.Namespace) -> int:
    from robopercept.nn.predict import load_image_predictor

    if args.tta == "none" and args.tta_scales is not None:
        raise UsageError("--tta-scales needs test-time augmentation: drop --tta none")
    model_path, stems = images_form_inputs(args, "detect", [".png"])
    line = print_model_line(args, "detect")
    predictor = load_image_predictor(
        "detect",
        model_path,
        device=args.device,
        score_thresh=args.score_thresh,
        all_scores=args.all_scores,
        tta=args.tta,
        tta_scales=args.tta_scales,
        tile=args.tile,
        overlap=args.overlap,
    )
    results: list[dict[str, Any]] = []
    warnings: list[str] = []
    out = Path(args.out) if args.out else None
    for k, (name, stem) in enumerate(zip(args.images, stems, strict=True), 1):
        pred = predictor.predict_file(name)
        results += pred.coco_results(k)
        note_warning(args, name, pred.warning, warnings)
        if out is not None:
            (written,) = pred.write(out, stem)
            if not (args.quiet or args.json):
                print(f"{name}: {len(pred.boxes)} detections -> {written}")
    if args.json:
        print(prediction_json(line, warnings, results))
    return 0
