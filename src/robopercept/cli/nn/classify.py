"""``robopercept nn train|eval|predict|summary``: convolutional classifiers (extra ``deep``).

The work is done by :mod:`robopercept.nn.classification.run` (training, evaluation,
prediction and the layer table); this module parses and prints. torch is imported only
when a command runs, so the parser (and every other command) stays torch-free; without torch
a command fails with the install line of the ``deep`` extra.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from typing import Any

from robopercept.cli._args import UsageError, image_output, numbers, positive_float, positive_int
from robopercept.cli.nn._forms import check_run_folder_args, device_arg, run_folder_args
from robopercept.errors import InputError

__all__ = ["MODEL_NAMES", "register"]

#: the names of :data:`robopercept.nn.classification.models.MODELS` (kept here so the parser
#: needs no torch)
MODEL_NAMES = ("vgg_small", "inception_small", "resnet_small")

_NO_TORCH = "robopercept nn needs the deep extra: pip install 'robopercept[deep]'"


def _need_torch() -> None:
    """Raise a one-line error (exit 1) when torch is not installed."""
    if importlib.util.find_spec("torch") is None:
        raise InputError(_NO_TORCH)


def _size(text: str) -> tuple[int, int]:
    """``WxH`` (or ``WXH``) -> (width, height), both >= 1 (argparse type)."""
    w, h = numbers((positive_int,) * 2, "WxH, two positive integers, e.g. 32x32", "x")(text.lower())
    return w, h


_chw = numbers((positive_int,) * 3, "C,H,W, three positive integers, e.g. 1,8,8", ",")
_chw.__doc__ = "``C,H,W`` -> three integers >= 1 (argparse type)."


def register(ns: argparse._SubParsersAction) -> None:
    """Add the classifier commands ``train``, ``eval``, ``predict`` and ``summary`` to the
    ``nn`` task parsers ``ns``."""
    t = ns.add_parser(
        "train",
        help="train a classifier and write a run folder",
        description="Split the data (stratified train/validation/test, seeded), normalize "
        "with train statistics, train, and write OUT/checkpoint.pt (last epoch), "
        "checkpoint.best.pt, history.csv, curves.png, metrics.json and confusion.png.",
    )
    t.add_argument(
        "--data", required=True, help="digits, lfw, or a folder laid out as root/class/img.png"
    )
    t.add_argument(
        "--model",
        choices=MODEL_NAMES,
        default="resnet_small",
        help="the network (robopercept nn summary MODEL prints its layers)",
    )
    t.add_argument("--epochs", type=positive_int, default=30, help="most epochs (default 30)")
    t.add_argument("--lr", type=positive_float, default=1e-3, help="learning rate (default 1e-3)")
    t.add_argument(
        "--batch-size", type=positive_int, default=64, help="images per step (default 64)"
    )
    t.add_argument(
        "--optimizer",
        choices=("adamw", "sgd"),
        default="adamw",
        help="AdamW, or SGD with momentum 0.9",
    )
    t.add_argument(
        "--schedule",
        choices=("cosine", "step", "onecycle", "constant"),
        default="cosine",
        help="learning rate over the epochs: cosine annealing to 0, steps down, one cycle "
        "(warm-up then annealing, per batch) or constant",
    )
    t.add_argument(
        "--patience", type=positive_int, default=10, help="early stopping (default 10 epochs)"
    )
    t.add_argument("--seed", type=int, default=0, help="split, weights and shuffling (default 0)")
    t.add_argument("--augment", action="store_true", help="random shifts, rotations, scales")
    t.add_argument("--gray", action="store_true", help="image folders: read grey images")
    t.add_argument("--size", type=_size, help="image folders: resize to WxH")
    t.add_argument(
        "--split",
        type=_split,
        default=(0.7, 0.15, 0.15),
        help="train,validation,test shares (default 0.7,0.15,0.15)",
    )
    device_arg(t)
    t.add_argument(
        "--nproc",
        type=positive_int,
        default=1,
        help="processes (DistributedDataParallel; --batch-size is the global batch, "
        "a multiple of N; default 1): the model one process trains, batch norm over the "
        "global batch",
    )
    t.add_argument(
        "--dropout",
        type=float,
        default=None,
        metavar="P",
        help="dropout before the classifier, in [0, 1) (default: the model's, 0.2)",
    )
    t.add_argument(
        "--per-process-bn",
        action="store_true",
        help="with --nproc N: batch-norm statistics of each process's share only",
    )
    run_folder_args(t)
    t.add_argument("--json", action="store_true", help="print metrics.json")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=run_train)

    e = ns.add_parser(
        "eval",
        help="accuracy, per-class figures and confusion matrix of a trained classifier",
        description="Evaluate CHECKPOINT (a run's .pt file or its folder) on a whole data "
        "set; writes the confusion matrix picture. The built-in sets include the run's "
        "training images: metrics.json holds the held-out test figures.",
    )
    e.add_argument("checkpoint", help="a run folder or its checkpoint (.pt)")
    e.add_argument("--data", required=True, help="digits, lfw, or an image folder")
    e.add_argument(
        "-o", "--output", type=image_output, default="confusion.png", help="the confusion matrix"
    )
    device_arg(e)
    e.add_argument("--json", action="store_true", help="print the figures as JSON")
    e.set_defaults(func=run_eval)

    r = ns.add_parser(
        "predict",
        help="the most probable classes of images",
        description="Classify each IMAGE with CHECKPOINT (read grey or colour and resized "
        "as the model was trained). A digits model expects 8x8 light-on-dark digits.",
    )
    r.add_argument(
        "checkpoint",
        metavar="CHECKPOINT",
        help="a run folder or its checkpoint, or a shipped classifier: digits (robopercept "
        "nn models describes it)",
    )
    r.add_argument("images", nargs="+", metavar="IMAGE", help="images to classify")
    r.add_argument("--top-k", type=positive_int, default=3, help="classes per image (default 3)")
    device_arg(r)
    r.add_argument("--json", action="store_true", help="print the predictions as JSON")
    r.set_defaults(func=run_predict)

    s = ns.add_parser(
        "summary",
        help="per-layer output shapes, parameters and receptive fields of a model",
        description="Build MODEL (untrained) and print its layers for an input of C,H,W.",
    )
    s.add_argument("model", choices=MODEL_NAMES, help="the network")
    s.add_argument("--input", type=_chw, default=(1, 8, 8), help="C,H,W (default 1,8,8)")
    s.add_argument("--classes", type=positive_int, default=10, help="outputs (default 10)")
    s.add_argument("--json", action="store_true", help="print the table as JSON")
    s.set_defaults(func=run_summary)


def _split(text: str) -> tuple[float, float, float]:
    """``0.7,0.15,0.15`` -> three positive shares summing to 1 (argparse type)."""
    try:
        parts = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expects TRAIN,VAL,TEST shares; got {text!r}") from None
    if len(parts) != 3 or min(parts) <= 0 or abs(sum(parts) - 1) > 1e-6:
        raise argparse.ArgumentTypeError(
            f"expects three positive shares summing to 1, e.g. 0.7,0.15,0.15; got {text!r}"
        )
    return parts[0], parts[1], parts[2]


def run_train(args: argparse.Namespace) -> int:
    """Run ``robopercept nn train`` with the parsed ``args``; returns the exit status."""
    _need_torch()
    from robopercept.nn.classification.run import TrainConfig, torchrun_env, train_ddp, train_run

    check_run_folder_args(args)
    if args.batch_size % args.nproc:
        raise UsageError(
            f"--batch-size {args.batch_size} (the global batch) must be a multiple of "
            f"--nproc {args.nproc}"
        )
    cfg = TrainConfig(
        epochs=args.epochs,
        batch_size=args.batch_size,
        optimizer=args.optimizer,
        lr=args.lr,
        schedule=args.schedule,
        patience=args.patience,
        seed=args.seed,
        device=args.device,
    )
    kwargs: dict[str, Any] = {
        "config": cfg,
        "mode": "gray" if args.gray else "rgb",
        "size": args.size,
        "fractions": args.split,
        "augment": args.augment,
        "resume": args.resume,
        "overwrite": args.overwrite,
        "progress": not (args.quiet or args.json),
    }
    if args.per_process_bn:
        kwargs["sync_batchnorm"] = False
    if args.dropout is not None:
        kwargs["model_kwargs"] = {"dropout": args.dropout}
    env = torchrun_env()
    rank = 0 if env is None else env[0]
    if args.nproc > 1 or env is not None:  # DDP (nn.train.distributed)
        res = train_ddp(args.data, args.model, args.out, nproc=args.nproc, **kwargs)
    else:
        res = train_run(args.data, args.model, args.out, **kwargs)
    if rank != 0:  # under torchrun: rank 0 prints
        return 0
    if args.json:
        print(json.dumps(json.loads(res.files["metrics"].read_text())))
        return 0
    h = res.history
    print(
        f"nn train: {args.model} ({res.parameters:,} parameters) on {args.data}, "
        f"{len(h.epoch)} epochs in {res.seconds:.1f} s; best epoch {h.best_epoch} "
        f"(validation accuracy {h.val_accuracy[h.best_epoch - 1]:.4f})"
        + (f"; {h.stopped}" if h.stopped else "")
    )
    print(f"test accuracy {res.test.accuracy:.4f} on {res.test.n} images")
    for name, path in res.files.items():
        print(f"  {name:<10} {path}")
    return 0


def run_eval(args: argparse.Namespace) -> int:
    """Run ``robopercept nn eval`` with the parsed ``args``; returns the exit status."""
    _need_torch()
    from robopercept.imaging import write_image
    from robopercept.nn.classification.run import evaluate_run

    ev = evaluate_run(args.checkpoint, args.data, device=args.device)
    written = write_image(args.output, ev.picture(f"confusion matrix ({args.data})"))
    if args.json:
        print(json.dumps({**ev.to_dict(), "output": str(written)}))
        return 0
    print(f"nn eval: accuracy {ev.accuracy:.4f}, loss {ev.loss:.4f} on {ev.n} images")
    width = max(5, *(len(c) for c in ev.classes))
    print(f"  {'class':<{width}}  precision  recall      f1  support")
    for k, name in enumerate(ev.classes):
        print(
            f"  {name:<{width}}  {ev.precision[k]:9.3f}  {ev.recall[k]:6.3f}  "
            f"{ev.f1[k]:6.3f}  {int(ev.support[k]):7d}"
        )
    print(f"-> {written}")
    return 0


def run_predict(args: argparse.Namespace) -> int:
    """Run ``robopercept nn predict`` with the parsed ``args``; returns the exit status."""
    _need_torch()
    from robopercept.nn.classification.run import predict
    from robopercept.nn.shipped import domain_line

    line = domain_line("classify", args.checkpoint)
    preds = predict(args.checkpoint, args.images, top_k=args.top_k, device=args.device)
    warnings = [f"{p.path}: {p.warning}" for p in preds if p.warning]
    if args.json:
        rows: list[dict[str, Any]] = [
            {
                "image": str(p.path),
                "top": [{"class": c, "probability": prob} for c, prob in p.top],
            }
            for p in preds
        ]
        print(json.dumps({"model": line, "warnings": warnings, "results": rows}))
        return 0
    print(line)
    for w in warnings:
        print(w, file=sys.stderr)
    width = max(5, *(len(str(p.path)) for p in preds))
    print(f"{'image':<{width}}  rank  class                 probability")
    for p in preds:
        for rank, (c, prob) in enumerate(p.top, 1):
            print(f"{str(p.path) if rank == 1 else '':<{width}}  {rank:4d}  {c:<20}  {prob:11.4f}")
    return 0


def run_summary(args: argparse.Namespace) -> int:
    """Run ``robopercept nn summary`` with the parsed ``args``; returns the exit status."""
    _need_torch()
    from robopercept.nn.classification.run import model_summary

    s = model_summary(args.model, args.input, args.classes)
    if not args.json:
        print(s)
        return 0
    print(
        json.dumps(
            {
                "model": args.model,
                "input_shape": list(s.input_shape),
                "output_shape": list(s.output_shape),
                "total_params": s.total_params,
                "trainable_params": s.trainable_params,
                "layers": [
                    {
                        "name": row.name,
                        "type": row.type,
                        "output_shape": list(row.output_shape),
                        "params": row.params,
                        "receptive_field": (
                            None if row.receptive_field is None else list(row.receptive_field)
                        ),
                    }
                    for row in s.rows
                ],
            }
        )
    )
    return 0
