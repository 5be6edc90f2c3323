"""``robopercept nn segment``: train, evaluate and run segmentation networks (extra
``deep``).

Three forms, chosen by the first word after ``segment``::

    robopercept nn segment train --task semantic|instance --model unet|fcn8s|...|maskrcnn
                                 --data shapes|digits|nuclei [--images-dir DIR] -o run/
                                 [--resume | --overwrite]
    robopercept nn segment eval RUN_OR_MODEL --data ... [-o DIR]
    robopercept nn segment IMAGE... [--model PATH|unet|maskrcnn] -o out/ [--json]

``train`` keeps the weights of the epoch with the best validation score (mIoU for the
semantic networks, mask AP@[.5:.95] for Mask R-CNN) and writes ``run/model.pt``,
``history.json``, ``metrics.json`` (the validation split) and ``samples.png``
(prediction beside ground truth), with ``checkpoint.pt`` (the last complete epoch,
written after every epoch) and ``checkpoint.best.pt``. A folder holding a run is
refused (exit 2) unless ``--resume`` continues it (after Ctrl-C, exit 130, or SIGTERM,
exit 143: it ends with the weights of an uninterrupted run) or ``--overwrite`` replaces
it. ``eval`` scores a run on the validation split of a built-in set (same ``--images``,
``--size`` and ``--seed``) or on the whole of your own annotations: pixel accuracy, mIoU,
frequency-weighted IoU and per-class IoU, or the 12 COCO ``segm`` numbers.
``IMAGE...`` writes ``out/NAME.png`` (class overlay with a legend, or instance
overlay with outlines and scores) and ``out/NAME_labels.png`` (class labels, or
instance ids, as a VOC-palette PNG); ``--json`` prints COCO results with RLE masks.
``NAME`` is the input's file name without its extension; inputs that share one get
their folders' names in front (``a/x.png``, ``b/x.png``: ``a_x``, ``b_x``), and inputs
still alike ``-2``, ``-3`` (:func:`robopercept.imaging.io.output_stems`).
``--allow-outside-paths`` lets ``train`` and ``eval`` read images that your annotations
place outside their folder (refused by default).

Without ``--model`` the ``IMAGE`` form uses the shipped U-Net; ``--model maskrcnn`` the
shipped Mask R-CNN. Both were trained on the procedural shapes and are rebuilt, from a
checkout, by ``python -m benchmarks.segmentation_figures --only shapes-unet
shapes-maskrcnn --seeds 0 --save src/robopercept/data``.

The work is done by :mod:`robopercept.nn.segmentation.run` (``train`` and ``eval``: data,
training, run folder, scores, pictures) and :mod:`robopercept.nn.predict` (``IMAGE...``);
this module parses and prints. Exit 2 for bad arguments (the message names the flag), 1
when the work fails.
"""

from __future__ import annotations

import argparse
import json
import sys
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
    run_or_model_path,
)
from robopercept.errors import InputError

__all__ = ["SEGMENT_MODELS", "register"]

#: ``--model`` of ``train``: the semantic networks, then the instance one
SEGMENT_MODELS = ("unet", "fcn8s", "fcn16s", "fcn32s", "naive", "maskrcnn")


def _data_args(p: argparse.ArgumentParser) -> None:
    built_in_data_args(
        p,
        "shapes (procedural), digits (real-digit canvases), nuclei (real, with "
        "--images-dir), or your own instances: a COCO JSON (polygon or RLE masks), a folder "
        "of labelme .json files or a VOC folder (SegmentationObject/, SegmentationClass/, "
        "JPEGImages/)",
        "nuclei: the stardist_nuclei folder; your own data: the images' folder (default: "
        "where the annotations put them)",
    )


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn segment train",
        description="Train a segmentation network; writes OUT/model.pt, history.json, "
        "metrics.json (validation split), samples.png and the checkpoints.",
    )
    _data_args(t)
    t.add_argument(
        "--task",
        choices=("semantic", "instance"),
        default="semantic",
        help="a class per pixel, or a mask per object",
    )
    t.add_argument(
        "--model",
        choices=SEGMENT_MODELS,
        default=None,
        help="the network (default unet for --task semantic, maskrcnn for instance)",
    )
    t.add_argument("--epochs", type=positive_int, default=20, help="most epochs (default 20)")
    t.add_argument("--batch-size", type=positive_int, default=8, help="images per step (default 8)")
    t.add_argument("--lr", type=float, default=2e-3, help="AdamW learning rate (default 2e-3)")
    t.add_argument("--width", type=positive_int, default=16, help="network width (default 16)")
    run_folder_args(t)
    e = cls(
        prog="robopercept nn segment eval",
        description="Scores of a trained segmenter (RUN folder or model.pt) on the validation "
        "split of a built-in set.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL", help="a run folder or its model.pt")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json")
    r = cls(
        prog="robopercept nn segment",
        description="Segment IMAGE... and write OUT/NAME.png (overlay) and "
        f"OUT/NAME_labels.png. {OUTPUT_NAMES_HELP}.",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE", help="images to segment")
    prediction_args(r, "segment", scores="instances", tiling=True)
    r.add_argument("-o", "--out", help="folder for the pictures and label PNGs")
    device_arg(r)
    r.add_argument(
        "--json",
        action="store_true",
        help='print {"model": LINE, "warnings": [...], "results": [COCO results, RLE masks]}',
    )
    r.add_argument("--quiet", action="store_true", help="no progress on stderr")
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


# --------------------------------------------------------------------------- forms
def _sets(args: argparse.Namespace, evaluate: bool = False) -> Any:
    """The data of ``--data`` and its flags (``evaluate``: your own annotations whole,
    not split); a bad flag is a usage error (exit 2)."""
    from robopercept.nn.segmentation.run import load_segmentation_data

    try:
        return load_segmentation_data(
            args.data,
            images=args.images,
            size=args.size,
            seed=args.seed,
            images_dir=args.images_dir,
            evaluate=evaluate,
            **data_path_options(args),
        )
    except InputError as exc:
        raise UsageError(str(exc)) from None


def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.segmentation.run import TrainConfig, resolve_segment_model, train_run

    check_run_folder_args(args)
    try:
        model_name = resolve_segment_model(args.task, args.model)
    except InputError as exc:
        raise UsageError(str(exc)) from None
    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    sets = _sets(args)
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
            f"nn segment train: {model_name} ({args.task}) on {args.data} ({len(sets.train)} "
            f"training, {len(sets.val)} validation images)",
            file=sys.stderr,
        )
    res = train_run(
        sets,
        args.out,
        task=args.task,
        model=model_name,
        config=cfg,
        width=args.width,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=not quiet,
    )
    if args.json:
        print(json.dumps(res.to_dict()))
        return 0
    instance = res.task == "instance"
    key = "AP" if instance else "mIoU"
    figure = res.metrics["metrics"][next(k for k in res.metrics["metrics"] if k.startswith(key))]
    print(
        f"nn segment train: {model_name} on {args.data}, kept epoch {res.best_epoch}; "
        f"validation {'mask AP@[.5:.95]' if instance else 'mIoU'} {figure:.4f}"
    )
    for name, path in res.files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    path = run_or_model_path(args.model)
    if not path.is_file():
        raise UsageError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    from robopercept.nn.segmentation.run import evaluate_run

    ev = evaluate_run(args.model, _sets(args, evaluate=True), device=args.device, out_dir=args.out)
    metrics = ev.to_dict()
    if args.json:
        print(json.dumps(metrics))
        return 0
    print(f"nn segment eval: {args.model} on {args.data} ({ev.images} images)")
    for name, v in metrics["metrics"].items():
        print(f"  {name:<40} {v:7.4f}")
    return 0


def _images(args: argparse.Namespace) -> int:
    from robopercept.nn.predict import load_image_predictor

    model, stems = images_form_inputs(args, "segment", [".png", "_labels.png"])
    line = print_model_line(args, "segment")
    predictor = load_image_predictor(
        "segment",
        model,
        device=args.device,
        score_thresh=args.score_thresh,
        all_scores=args.all_scores,
        tile=args.tile,
        overlap=args.overlap,
    )
    instance = predictor.instance
    out = Path(args.out) if args.out else None
    results: list[dict[str, Any]] = []
    warnings: list[str] = []
    for k, (name, stem) in enumerate(zip(args.images, stems, strict=True), 1):
        pred = predictor.predict_file(name)
        results += pred.coco_results(k)
        note_warning(args, name, pred.warning, warnings)
        if out is not None:
            pic, lab = pred.write(out, stem)
            if not (args.quiet or args.json):
                n = len(pred.masks) if instance else len({int(x) for x in pred.labels.flat})
                what = "instances" if instance else "labels"
                print(f"{name}: {n} {what} -> {pic}, {lab}")
    if args.json:
        print(prediction_json(line, warnings, results))
    return 0
