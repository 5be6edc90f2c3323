"""``robopercept nn cloud``: train, evaluate and run point-cloud networks (extra ``deep``).

Three forms, chosen by the first word after ``cloud``::

    robopercept nn cloud train --model pointnet|dgcnn --data shapes|FOLDER -o run/
                               [--resume | --overwrite]
    robopercept nn cloud eval RUN_OR_MODEL --data shapes|FOLDER [-o DIR]
    robopercept nn cloud CLOUD... [--model PATH|pointnet|dgcnn] [--segment] [-o OUT] [--json]

``train`` keeps the weights of the epoch with the best validation score (accuracy, or
instance mIoU with ``--task segment``) and writes ``run/model.pt``, ``history.json``,
``metrics.json`` (on the test split) and ``confusion.png``, beside ``checkpoint.pt``
(the last complete epoch, written after every epoch) and ``checkpoint.best.pt``. A
folder that already holds a run is refused (exit 2) unless ``--resume`` continues it
(to the weights of an uninterrupted run; after Ctrl-C, exit 130, or SIGTERM, exit 143)
or ``--overwrite`` starts afresh. ``--data`` is ``shapes``
(the procedural shapes), ``shapes-partial`` or ``shapes-noisy`` (harder variants), or a
folder ``root/<class>/*.off|*.ply|*.pcd`` (ModelNet's ``root/<class>/{train,test}/``
too). ``eval`` scores a model on the test split of the same data (same ``--shapes``,
``--points`` and ``--seed``). ``CLOUD...`` classifies each PLY/PCD cloud or OFF/PLY mesh
(sampled to the model's point count, normalized to the unit sphere) and prints the
class with its probabilities; ``--segment`` also labels every point with a part of that
class and writes ``OUT/NAME_parts.ply`` coloured by part, and ``-o`` writes
``OUT/NAME.png`` (the cloud as the network saw it).
``NAME`` is the input's file name without its extension; inputs that share one get
their folders' names in front (``a/x.png``, ``b/x.png``: ``a_x``, ``b_x``), and inputs
still alike ``-2``, ``-3`` (:func:`robopercept.imaging.io.output_stems`).

Without ``--model`` the shipped PointNet (trained on the procedural shapes) is used;
``--model dgcnn`` the shipped DGCNN; ``--segment`` the shipped PointNet part
segmenter. They are rebuilt from a checkout by ``python -m benchmarks.cloud_figures
--only pointnet dgcnn pointnet-parts --seeds 0 --save src/robopercept/data``.

The work is done by :mod:`robopercept.nn.cloud.run` (:func:`~robopercept.nn.cloud.run.train_run`,
:func:`~robopercept.nn.cloud.run.evaluate_run`,
:func:`~robopercept.nn.cloud.run.classify_cloud_file`), the pictures by
:mod:`robopercept.viz.cloud_dl`; this module parses and prints. Exit 2 for bad
arguments (the message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from robopercept.cli._args import UsageError, positive_int
from robopercept.cli.nn._forms import (
    OUTPUT_NAMES_HELP,
    check_run_folder_args,
    device_arg,
    prediction_json,
    print_model_line,
    register_forms,
    run_folder_args,
    run_or_model_path,
    shipped_help,
)

__all__ = ["CLOUD_CLI_MODELS", "register"]

#: ``--model`` of ``train``
CLOUD_CLI_MODELS = ("pointnet", "dgcnn")


def _data_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data",
        required=True,
        help="shapes, shapes-partial, shapes-noisy (procedural) or a folder "
        "root/<class>/*.off|*.ply|*.pcd",
    )
    p.add_argument(
        "--shapes",
        type=positive_int,
        default=100,
        help="procedural data: training shapes per class (default 100)",
    )
    p.add_argument("--points", type=positive_int, default=1024, help="per cloud (default 1024)")
    p.add_argument("--seed", type=int, default=0, help="data, split and weights (default 0)")
    device_arg(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn cloud train",
        description="Train a point-cloud network; writes OUT/model.pt, history.json, "
        "metrics.json (test split), confusion.png and the checkpoints.",
    )
    _data_args(t)
    t.add_argument(
        "--model",
        choices=CLOUD_CLI_MODELS,
        default="pointnet",
        help="PointNet (shared per-point MLPs, max pooling) or DGCNN (edge convolutions "
        "over the --k nearest neighbours)",
    )
    t.add_argument(
        "--task",
        choices=("classify", "segment"),
        default="classify",
        help="one class per cloud, or a part label per point",
    )
    t.add_argument("--epochs", type=positive_int, default=20, help="most epochs (default 20)")
    t.add_argument(
        "--batch-size", type=positive_int, default=32, help="clouds per step (default 32)"
    )
    t.add_argument("--lr", type=float, default=1e-3, help="AdamW learning rate (default 1e-3)")
    t.add_argument(
        "--width", type=float, default=0.5, help="pointnet: channel multiplier (default 0.5)"
    )
    t.add_argument("--k", type=positive_int, default=16, help="dgcnn: neighbours (default 16)")
    run_folder_args(t)
    e = cls(
        prog="robopercept nn cloud eval",
        description="Accuracy (or part mIoU) of a trained network (RUN folder or model.pt) "
        "on the test split of the data.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL", help="a run folder or its model.pt")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json and confusion.png")
    r = cls(
        prog="robopercept nn cloud",
        description="Classify each CLOUD (.ply/.pcd cloud or .off/.ply mesh); with -o, "
        f"write OUT/NAME.png (and OUT/NAME_parts.ply). {OUTPUT_NAMES_HELP}.",
    )
    r.add_argument(
        "clouds",
        nargs="+",
        metavar="CLOUD",
        help="point clouds (.ply, .pcd) or meshes (.off, .ply)",
    )
    r.add_argument("--model", help=shipped_help("cloud"))
    r.add_argument(
        "--segment",
        nargs="?",
        const="pointnet-parts",
        metavar="MODEL",
        help="also label every point with a part (default: the shipped PointNet part "
        "segmenter); writes OUT/NAME_parts.ply",
    )
    r.add_argument("--points", type=positive_int, help="sample this many (default: the model's)")
    r.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    r.add_argument("-o", "--out", help="folder for NAME.png (and NAME_parts.ply)")
    device_arg(r)
    r.add_argument(
        "--json",
        action="store_true",
        help='print {"model": LINE, "warnings": [], "results": [predictions]}',
    )
    r.add_argument("--quiet", action="store_true", help="no progress on stderr")
    return {"train": t, "eval": e, "images": r}


def register(ns: argparse._SubParsersAction, parser_class: type[argparse.ArgumentParser]) -> None:
    """Add ``cloud`` to the ``nn`` task parsers ``ns``."""
    register_forms(
        ns,
        "cloud",
        "point-cloud networks (PointNet, DGCNN): train, eval, or classify clouds (needs torch)",
        lambda: _parsers(parser_class),
        {"train": _train, "eval": _eval, "images": _clouds},
    )


def _check_seed(args: argparse.Namespace) -> None:
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0; got {args.seed}")


def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.cloud.run import TrainConfig, train_run

    check_run_folder_args(args)
    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    if not 0 < args.width <= 8:
        raise UsageError(f"--width: a channel multiplier in (0, 8]; got {args.width}")
    if args.model == "dgcnn" and args.k > args.points:
        raise UsageError(f"--k: at most --points ({args.points}); got {args.k}")
    _check_seed(args)
    quiet = args.quiet or args.json
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
        task=args.task,
        config=cfg,
        shapes=args.shapes,
        n_points=args.points,
        width=args.width,
        k=args.k,
        resume=args.resume,
        overwrite=args.overwrite,
        progress=not quiet,
    )
    if args.json:
        print(json.dumps(res.to_dict()))
        return 0
    ev = res.test
    segment = args.task == "segment"
    score = f"instance mIoU {ev.instance_miou:.4f}" if segment else f"accuracy {ev.accuracy:.4f}"
    print(f"nn cloud train: {args.model} on {args.data}, kept epoch {res.best_epoch}; test {score}")
    for name, path in res.files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from robopercept.nn.cloud.run import evaluate_run

    path = run_or_model_path(args.model)
    if not path.is_file():
        raise UsageError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    _check_seed(args)
    res = evaluate_run(
        args.model,
        args.data,
        shapes=args.shapes,
        n_points=args.points,
        seed=args.seed,
        device=args.device,
        out_dir=args.out,
        progress=not (args.quiet or args.json),
    )
    metrics = res.metrics
    if args.json:
        print(json.dumps(res.to_dict()))
        return 0
    print(f"nn cloud eval: {args.model} on {args.data} ({metrics['clouds']} clouds)")
    for name, v in metrics["metrics"].items():
        print(f"  {name:<22} {v:7.4f}")
    return 0


def _model(name: str | None, default: str) -> Path:
    from robopercept.nn.shipped import SHIPPED_CLOUD_MODELS, shipped_model_path

    if name is None or name in SHIPPED_CLOUD_MODELS:
        return shipped_model_path("cloud", name or default)
    path = run_or_model_path(name)
    if not path.is_file():
        raise UsageError(f"--model: {path} does not exist (a run folder or model.pt)")
    return path


def _clouds(args: argparse.Namespace) -> int:
    from robopercept.imaging import write_image
    from robopercept.imaging.io import output_stems
    from robopercept.nn.cloud.run import classify_cloud_file, load_cloud_model, resolve_device
    from robopercept.pointcloud import PointCloud, write_point_cloud
    from robopercept.viz.cloud_dl import cloud_picture
    from robopercept.viz.colormap import label_colors

    for name in args.clouds:
        if not Path(name).is_file():
            raise UsageError(f"CLOUD: {name} does not exist")
    if args.segment and not args.out:
        raise UsageError("--segment: give -o/--out, the folder for NAME_parts.ply")
    stems = output_stems(args.clouds, [".png", "_parts.ply"] if args.segment else [".png"])
    inputs = {Path(name).resolve(): name for name in args.clouds}
    for stem in stems if args.segment else ():
        ply = Path(args.out) / f"{stem}_parts.ply"
        if ply.resolve() in inputs:
            raise UsageError(
                f"-o/--out: {ply} would overwrite the input {inputs[ply.resolve()]}: write "
                "to another folder"
            )
    line = print_model_line(args, "cloud")
    model, info = load_cloud_model(_model(args.model, "pointnet"))
    dev = resolve_device(args.device)
    model.to(dev)
    segmenter = None
    if args.segment:
        seg, sinfo = load_cloud_model(_model(args.segment, "pointnet-parts"))
        segmenter = (seg.to(dev), sinfo)
    out = Path(args.out) if args.out else None
    results = []
    for name, stem in zip(args.clouds, stems, strict=True):
        res = classify_cloud_file(
            name, model, info, segmenter=segmenter, n_points=args.points, rng=args.seed
        )
        row = res.to_dict()
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            top = ", ".join(f"{k} {v:.2f}" for k, v in list(res.probabilities.items())[:3])
            written = []
            if res.parts is not None:
                colors = label_colors(res.parts + 1) / 255.0
                ply = out / f"{stem}_parts.ply"
                cloud = PointCloud(res.points.astype(float), colors=colors)
                written.append(write_point_cloud(ply, cloud))
                pic = cloud_picture(
                    res.points,
                    labels=res.parts,
                    names=list(res.part_names),
                    title=f"{stem}: {top}",
                )
            else:
                pic = cloud_picture(res.points, title=f"{stem}: {top}")
            written.append(write_image(out / f"{stem}.png", pic))
            row["files"] = [str(p) for p in written]
        results.append(row)
        if not (args.quiet or args.json):
            top = ", ".join(f"{k} {v:.3f}" for k, v in list(res.probabilities.items())[:3])
            print(f"{name}: {res.label} ({top})")
            for f in row.get("files", []):
                print(f"  wrote {f}")
    if args.json:
        print(prediction_json(line, [], results))
    return 0
