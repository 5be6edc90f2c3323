"""``robopercept nn cloud``: train, evaluate and run point-cloud networks (extra ``deep``).

Three forms, chosen by the first word after ``cloud``::

    robopercept nn cloud train --model pointnet|dgcnn --data shapes|FOLDER -o run/
    robopercept nn cloud eval RUN_OR_MODEL --data shapes|FOLDER [-o DIR]
    robopercept nn cloud CLOUD... [--model PATH|pointnet|dgcnn] [--segment] [-o OUT] [--json]

``train`` keeps the weights of the epoch with the best validation score (accuracy, or
instance mIoU with ``--task segment``) and writes ``run/model.pt``, ``history.json``,
``metrics.json`` (on the test split) and ``confusion.png``. ``--data`` is ``shapes``
(the procedural shapes), ``shapes-partial`` or ``shapes-noisy`` (harder variants), or a
folder ``root/<class>/*.off|*.ply|*.pcd`` (ModelNet's ``root/<class>/{train,test}/``
too). ``eval`` scores a model on the test split of the same data (same ``--shapes``,
``--points`` and ``--seed``). ``CLOUD...`` classifies each PLY/PCD cloud or OFF/PLY mesh
(sampled to the model's point count, normalized to the unit sphere) and prints the
class with its probabilities; ``--segment`` also labels every point with a part of that
class and writes ``OUT/NAME_parts.ply`` coloured by part, and ``-o`` writes
``OUT/NAME.png`` (the cloud as the network saw it).

Without ``--model`` the shipped PointNet (trained on the procedural shapes) is used;
``--model dgcnn`` the shipped DGCNN; ``--segment`` the shipped PointNet part
segmenter. They are rebuilt from a checkout by ``python -m benchmarks.cloud_figures
--only pointnet dgcnn pointnet-parts --seeds 0 --save src/robopercept/data``.

The work is done by :mod:`robopercept.nn.cloud.run`, :mod:`robopercept.nn.cloud.data` and
:mod:`robopercept.viz.cloud_dl`; this module parses and prints. Exit 2 for bad
arguments (the message names the flag), 1 when the work fails.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, positive_int, register_forms, run_or_model_path

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
    p.add_argument("--device", help="cpu, cuda, ... (default: cuda when present)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def _parsers(cls: type[argparse.ArgumentParser]) -> dict[str, argparse.ArgumentParser]:
    t = cls(
        prog="robopercept nn cloud train",
        description="Train a point-cloud network; writes OUT/model.pt, history.json, "
        "metrics.json (test split) and confusion.png.",
    )
    _data_args(t)
    t.add_argument("--model", choices=CLOUD_CLI_MODELS, default="pointnet")
    t.add_argument("--task", choices=("classify", "segment"), default="classify")
    t.add_argument("--epochs", type=positive_int, default=20, help="default 20")
    t.add_argument("--batch-size", type=positive_int, default=32, help="default 32")
    t.add_argument("--lr", type=float, default=1e-3, help="AdamW learning rate (default 1e-3)")
    t.add_argument(
        "--width", type=float, default=0.5, help="pointnet: channel multiplier (default 0.5)"
    )
    t.add_argument("--k", type=positive_int, default=16, help="dgcnn: neighbours (default 16)")
    t.add_argument("-o", "--out", default="run", help="run folder (default run/)")
    e = cls(
        prog="robopercept nn cloud eval",
        description="Accuracy (or part mIoU) of a trained network (RUN folder or model.pt) "
        "on the test split of the data.",
    )
    e.add_argument("model", metavar="RUN_OR_MODEL")
    _data_args(e)
    e.add_argument("-o", "--out", help="folder for metrics.json and confusion.png")
    r = cls(
        prog="robopercept nn cloud",
        description="Classify each CLOUD (.ply/.pcd cloud or .off/.ply mesh).",
    )
    r.add_argument("clouds", nargs="+", metavar="CLOUD")
    r.add_argument(
        "--model",
        help="a model.pt or run folder, or a shipped model: pointnet (default) or dgcnn",
    )
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
    r.add_argument("--device", help="cpu, cuda, ...")
    r.add_argument("--json", action="store_true", help="print the predictions as JSON")
    r.add_argument("--quiet", action="store_true")
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


def _sets(args: argparse.Namespace) -> Any:
    from robopercept.errors import InputError
    from robopercept.nn.cloud.run import cloud_sets

    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0; got {args.seed}")
    try:
        return cloud_sets(
            args.data,
            shapes=args.shapes,
            n_points=args.points,
            seed=args.seed,
            progress=not (args.quiet or args.json),
        )
    except InputError as exc:
        raise UsageError(f"--data: {exc}") from None


def _write_metrics(out: Path, metrics: dict[str, Any], ev: Any, names: list[str]) -> list[Path]:
    from robopercept.imaging import write_image
    from robopercept.viz.learning import confusion_picture

    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1))
    k = len(names)
    pic = confusion_picture(ev.confusion[:k, :k], names, title=metrics.get("title", ""))
    return [out / "metrics.json", write_image(out / "confusion.png", pic)]


def _train(args: argparse.Namespace) -> int:
    from robopercept.nn.cloud.run import (
        build_cloud_model,
        evaluate_cloud_model,
        save_cloud_model,
        train_cloud_model,
    )
    from robopercept.nn.train.config import TrainConfig

    if not args.lr > 0:
        raise UsageError(f"--lr: must be > 0; got {args.lr}")
    if not 0 < args.width <= 8:
        raise UsageError(f"--width: a channel multiplier in (0, 8]; got {args.width}")
    if args.model == "dgcnn" and args.k > args.points:
        raise UsageError(f"--k: at most --points ({args.points}); got {args.k}")
    sets = _sets(args)
    train, val, test = sets.train, sets.val, sets.test
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    quiet = args.quiet or args.json
    segment = args.task == "segment"
    if not quiet:
        print(
            f"nn cloud train: {args.model} ({args.task}) on {args.data}: {len(train)} training, "
            f"{len(val)} validation, {len(test)} test clouds of {args.points} points",
            file=sys.stderr,
        )
    settings: dict[str, Any] = {"task": args.task}
    if args.model == "pointnet":
        settings["width"] = args.width
    else:
        settings["k"] = args.k
    if segment:
        settings["num_categories"] = train.num_classes
    outputs = train.num_parts if segment else train.num_classes
    model = build_cloud_model(args.model, outputs, seed=args.seed, **settings)
    cfg = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        device=args.device,
    )
    hist = train_cloud_model(model, train, cfg, val=val, progress=not quiet)
    save_cloud_model(
        out / "model.pt",
        model,
        list(train.class_names),
        part_names=list(train.part_names) if segment else (),
        part_classes=train.part_classes if segment else None,
        n_points=args.points,
        data=args.data,
        shapes=args.shapes,
        seed=args.seed,
    )
    (out / "history.json").write_text(json.dumps(hist.to_dict(), indent=1))
    ev = evaluate_cloud_model(model, test)
    names = list(train.part_names if segment else train.class_names)
    metrics = {
        "model": args.model,
        "task": args.task,
        "data": args.data,
        "split": "test",
        "clouds": len(test),
        "best_epoch": hist.best_epoch,
        "metrics": ev.summary(),
        "title": f"{args.model} on {args.data}: test",
    }
    written = [out / "model.pt", out / "history.json", *_write_metrics(out, metrics, ev, names)]
    files = {p.name: str(p) for p in written}
    if args.json:
        print(json.dumps({**metrics, "files": files}))
        return 0
    score = f"instance mIoU {ev.instance_miou:.4f}" if segment else f"accuracy {ev.accuracy:.4f}"
    print(
        f"nn cloud train: {args.model} on {args.data}, kept epoch {hist.best_epoch}; test {score}"
    )
    for name, path in files.items():
        print(f"  {name:<13} {path}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from robopercept.nn.cloud.run import evaluate_cloud_model, load_cloud_model

    path = run_or_model_path(args.model)
    if not path.is_file():
        raise UsageError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    model, info = load_cloud_model(path)
    if args.device:
        from robopercept.nn.train.config import resolve_device

        model.to(resolve_device(args.device))
    sets = _sets(args)
    if list(sets.test.class_names) != list(info["class_names"]):
        raise UsageError(
            f"--data: its classes {list(sets.test.class_names)} are not the model's "
            f"{info['class_names']}"
        )
    ev = evaluate_cloud_model(model, sets.test)
    segment = model.task == "segment"
    names = list(info["part_names"] if segment else info["class_names"])
    metrics = {
        "model": str(args.model),
        "task": model.task,
        "data": args.data,
        "split": "test",
        "clouds": len(sets.test),
        "metrics": ev.summary(),
        "title": f"{Path(args.model).name} on {args.data}: test",
    }
    if args.out:
        _write_metrics(Path(args.out), metrics, ev, names)
    if args.json:
        print(json.dumps(metrics))
        return 0
    print(f"nn cloud eval: {args.model} on {args.data} ({len(sets.test)} clouds)")
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
    from robopercept.nn.cloud.run import classify_cloud_file, load_cloud_model
    from robopercept.nn.train.config import resolve_device
    from robopercept.pointcloud import PointCloud, write_point_cloud
    from robopercept.viz.cloud_dl import cloud_picture
    from robopercept.viz.colormap import label_colors

    for name in args.clouds:
        if not Path(name).is_file():
            raise UsageError(f"CLOUD: {name} does not exist")
    if args.segment and not args.out:
        raise UsageError("--segment: give -o/--out, the folder for NAME_parts.ply")
    model, info = load_cloud_model(_model(args.model, "pointnet"))
    dev = resolve_device(args.device)
    model.to(dev)
    segmenter = None
    if args.segment:
        seg, sinfo = load_cloud_model(_model(args.segment, "pointnet-parts"))
        segmenter = (seg.to(dev), sinfo)
    out = Path(args.out) if args.out else None
    results = []
    for name in args.clouds:
        res = classify_cloud_file(
            name, model, info, segmenter=segmenter, n_points=args.points, rng=args.seed
        )
        row = res.to_dict()
        if out is not None:
            out.mkdir(parents=True, exist_ok=True)
            stem = Path(name).stem
            top = ", ".join(f"{k} {v:.2f}" for k, v in list(res.probabilities.items())[:3])
            written = []
            if res.parts is not None:
                colors = label_colors(res.parts + 1) / 255.0
                ply = out / f"{stem}_parts.ply"
                if ply.resolve() == Path(name).resolve():
                    raise UsageError(f"-o/--out: {ply} would overwrite the input {name}")
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
        print(json.dumps(results))
    return 0
