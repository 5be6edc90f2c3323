"""``robopercept nn pose``: train, evaluate and run 2-D pose networks (extra ``deep``).

Three forms, chosen by the first word after ``pose``::

    robopercept nn pose train --model deeppose|heatmap|hrnet --data figures|COCO_JSON -o run/
                              [--resume | --overwrite]
    robopercept nn pose eval RUN_OR_MODEL --data figures|COCO_JSON [-o DIR]
    robopercept nn pose IMAGE... [--model PATH|hrnet|deeppose] -o out/ [--json]
                                 [--lift3d] [--heatmaps]

``train`` keeps the weights of the epoch with the best validation PCK@0.1 and writes
``run/model.pt``, ``history.json``, ``metrics.json`` (PCK and COCO keypoint AP on the
validation split) and ``samples.png`` (predicted skeletons), beside ``checkpoint.pt``
(the last complete epoch, written after every epoch) and ``checkpoint.best.pt``.
``--model deeppose`` also trains ``--stages`` cascade stages on the first stage's
estimates. A folder that already holds a run is refused (exit 2) unless ``--resume``
continues it (to the weights of an uninterrupted run) or ``--overwrite`` replaces it;
Ctrl-C keeps the last complete epoch (exit 130). ``eval`` scores a model on the
validation split of the same data (same ``--images``, ``--size`` and ``--seed``).
``IMAGE...`` treats each image as one person (top-down): it is letterboxed
into the network's input, and ``out/NAME.png`` shows the skeleton with per-joint
confidence; ``--heatmaps`` adds ``out/NAME_heatmaps.png``; ``--lift3d`` lifts the 2-D
pose to 3-D by matching against a library of projected 3-D poses (the course's
recipe, :class:`~robopercept.nn.pose.library.PoseLibrary`) and writes ``out/NAME_3d.png``
(two views). ``--json`` prints, per image, the keypoints (pixels), their scores and
(with ``--lift3d``) the root-relative 3-D joints in metres.
``NAME`` is the input's file name without its extension; inputs that share one get
their folders' names in front (``a/x.png``, ``b/x.png``: ``a_x``, ``b_x``), and inputs
still alike ``-2``, ``-3`` (:func:`robopercept.imaging.io.output_stems`).
``--allow-outside-paths`` lets ``train`` and ``eval`` read images that a COCO file
places outside its folder (refused by default).

Without ``--model`` the ``IMAGE`` form uses the shipped HRNet; ``--model deeppose`` the
shipped DeepPose with its cascade stage. Both were trained on the procedural figures
and are rebuilt, from a checkout, by ``python -m benchmarks.pose_figures --only hrnet
deeppose --seeds 0 --save src/robopercept/data``.

The work is done by :mod:`robopercept.nn.pose.run` (``train`` and ``eval``:
:func:`~robopercept.nn.pose.run.train_run`, :func:`~robopercept.nn.pose.run.evaluate_run`)
and :mod:`robopercept.nn.predict` (the image form); this module parses and prints.
Exit 2 for bad arguments (the message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

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
from robopercept.errors import InputError

__all__ = ["POSE_CLI_MODELS", "register"]

#: ``--model`` of ``train``
POSE_CLI_MODELS = ("hrnet", "heatmap", "deeppose")


def _data_args(p: argparse.ArgumentParser) -> None:
    built_in_data_args(
        p,
        "figures (procedural articulated figures over real photos, MPII's 16 joints) or "
        "your own COCO person-keypoints .json (each person cut out around its box)",
        "COCO: folder of the images (default: the JSON's folder)",
        images=2000,
        generated="figures",
    )


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn pose train",
        description="Train a pose network; writes OUT/model.pt, history.json, metrics.json "
        "(validation split) and samples.png.",
    )
    _data_args(t)
    t.add_argument(
        "--model",
        choices=POSE_CLI_MODELS,
        default="hrnet",
        help="HRNet (high-resolution heatmaps), SimpleBaseline (heatmap), or DeepPose "
        "(joint coordinates regressed, --stages refinements) (default hrnet)",
    )
    t.add_argument("--epochs", type=positive_int, default=20, help="most epochs (default 20)")
    t.add_argument(
        "--batch-size", type=positive_int, default=32, help="images per step (default 32)"
    )
    t.add_argument("--lr", type=float, default=3e-3, help="AdamW learning rate (default 3e-3)")
    t.add_argument("--width", type=positive_int, default=16, help="network width (default 16)")
    t.add_argument(
        "--stages",
        type=int,
        default=1,
        help="deeppose: cascade refinement stages after the first (default 1; 0 for none)",
    )
    run_folder_args(t)
    e = cls(
        prog="robopercept nn pose eval",
        description="PCK and COCO keypoint AP of a trained pose network (RUN folder or "
        "model.pt) on the validation split of the figures or on every person of a COCO file.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL", help="a run folder or its model.pt")
    _data_args(e)
    e.add_argument("--no-flip", action="store_true", help="without the flip test")
    e.add_argument("-o", "--out", help="folder for metrics.json")
    r = cls(
        prog="robopercept nn pose",
        description="Find one person's joints in each IMAGE and write OUT/NAME.png. "
        f"{OUTPUT_NAMES_HELP}.",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE", help="images of one person each")
    prediction_args(r, "pose", scores="joints drawn", tiling=False)
    r.add_argument("-o", "--out", help="folder for the pictures")
    r.add_argument("--lift3d", action="store_true", help="also the 3-D pose (by matching)")
    r.add_argument("--heatmaps", action="store_true", help="also OUT/NAME_heatmaps.png")
    r.add_argument("--no-flip", action="store_true", help="without the flip test")
    device_arg(r)
    r.add_argument(
        "--json",
        action="store_true",
        help='print {"model": LINE, "warnings": [...], "results": [keypoints (and 3-D)]}',
    )
    r.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return {"train": t, "eval": e, "images": r}


def register(ns: argparse._SubParsersAction, parser_class: type[argparse.ArgumentParser]) -> None:
    """Add ``pose`` to the ``nn`` task parsers ``ns``."""
    register_forms(
        ns,
        "pose",
        "pose networks: train, eval, or find a person's joints in images (needs torch)",
        lambda: _parsers(parser_class),
        {"train": _train, "eval": _eval, "images": _images},
    )


def _check_data(args: argparse.Namespace) -> None:
    """The data flags a usage error refuses (exit 2) before any work."""
    if args.images < 2:
        raise UsageError("--images: give at least 2")
    if args.data.lower().endswith(".json"):
        if not Path(args.data).is_file():
            raise UsageError(f"--data: COCO file {args.data} does not exist")
    elif args.data != "figures":
        raise UsageError(
            f"--data: figures or a COCO person-keypoints .json file; got {args.data!r}"
        )


def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.pose.run import TrainConfig, train_run

    check_run_folder_args(args)
    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    if args.stages < 0 or args.stages > 8:
        raise UsageError(f"--stages: 0 to 8 cascade stages; got {args.stages}")
    if args.size[0] % 16 or args.size[1] % 16:
        raise UsageError(f"--size: width and height must be multiples of 16; got {args.size}")
    _check_data(args)
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
        images=args.images,
        size=args.size,
        config=cfg,
        width=args.width,
        stages=args.stages,
        images_dir=args.images_dir,
        resume=args.resume,
        **data_path_options(args),
        overwrite=args.overwrite,
        progress=not (args.quiet or args.json),
    )
    if args.json:
        print(json.dumps(res.to_dict()))
        return 0
    ev = res.evaluation
    print(
        f"nn pose train: {args.model} on {args.data}, kept epoch {res.best_epoch}; "
        f"validation PCK@0.1 {ev.pck[0.1]:.4f}, OKS AP {ev.oks.stats[0]:.4f}"
    )
    for name, path in res.files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from robopercept.nn.pose.run import evaluate_run, model_path

    try:
        model_path(args.model)
    except InputError as exc:
        raise UsageError(str(exc)) from None
    _check_data(args)
    res = evaluate_run(
        args.model,
        args.data,
        images=args.images,
        size=args.size,
        seed=args.seed,
        flip=not args.no_flip,
        device=args.device,
        out_dir=args.out,
        images_dir=args.images_dir,
        **data_path_options(args),
    )
    if args.json:  # a joint no validation sample counts has PCK NaN: null
        print(json.dumps(res.to_dict()))
        return 0
    print(f"nn pose eval: {args.model} on {args.data} ({res.n} images)")
    for name, v in res.metrics["metrics"].items():
        print(f"  {name:<40} {v:7.4f}")
    return 0


def _images(args: argparse.Namespace) -> int:
    import numpy as np

    from robopercept.nn.predict import load_image_predictor

    outputs = [".png"] + ["_heatmaps.png"] * args.heatmaps + ["_3d.png"] * args.lift3d
    model, stems = images_form_inputs(args, "pose", outputs)
    line = print_model_line(args, "pose")
    predictor = load_image_predictor(
        "pose",
        model,
        device=args.device,
        score_thresh=args.score_thresh,
        all_scores=args.all_scores,
        flip=not args.no_flip,
        heatmaps=args.heatmaps,
        lift3d=args.lift3d,
    )
    out = Path(args.out) if args.out else None
    results = []
    warnings: list[str] = []
    for name, stem in zip(args.images, stems, strict=True):
        pred = predictor.predict_file(name)
        results.append({"image": name, **pred.record()})
        note_warning(args, name, pred.warning, warnings)
        if out is not None:
            written = pred.write(out, stem)
            if not (args.quiet or args.json):
                mean = float(np.mean(pred.values["scores"]))
                print(f"{name}: mean joint score {mean:.3f} -> {', '.join(map(str, written))}")
    if args.json:
        print(prediction_json(line, warnings, results))
    return 0
