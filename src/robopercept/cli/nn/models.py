"""``robopercept nn models [--kind KIND] [--json]``: the shipped models and what each
knows (their cards, :data:`robopercept.nn.shipped.MODEL_CARDS`): task, classes, the data
it learnt from (real or procedural), the inputs it is meant for, its figure on a split
no choice saw, and the command that rebuilds it. Torch-free."""

from __future__ import annotations

import argparse
import json

__all__ = ["register"]

_KINDS = ("detect", "segment", "pose", "cloud", "classify")


def register(ns: argparse._SubParsersAction) -> None:
    """Add ``models`` to the ``nn`` task parsers ``ns``."""
    p = ns.add_parser(
        "models",
        help="the shipped models: task, classes, training data, inputs, figure",
        description="List the models shipped with robopercept and what each was trained "
        "on. Give one by name to --model of nn detect|segment|pose|cloud|predict.",
    )
    p.add_argument("--kind", choices=_KINDS, help="only the models of this task")
    p.add_argument("--json", action="store_true", help="print the cards as JSON")
    p.set_defaults(func=run_models)


def run_models(args: argparse.Namespace) -> int:
    """Print the model cards; returns the exit status."""
    from robopercept.errors import InputError
    from robopercept.nn.shipped import DEFAULT_SHIPPED, MODEL_CARDS, shipped_model_path

    cards = [c for c in MODEL_CARDS.values() if args.kind in (None, c.kind)]
    installed = {}
    for c in cards:
        try:
            installed[c.name] = shipped_model_path(c.kind, c.name).is_file()
        except InputError:  # not installed: reported, not raised
            installed[c.name] = False
    if args.json:
        rows = [
            {
                **c.to_dict(),
                "default": DEFAULT_SHIPPED[c.kind] == c.name,
                "installed": installed[c.name],
            }
            for c in cards
        ]
        print(json.dumps(rows))
        return 0
    for c in cards:
        flags = [
            f
            for f, on in (
                ("default", DEFAULT_SHIPPED[c.kind] == c.name),
                ("not installed", not installed[c.name]),
            )
            if on
        ]
        print(f"{c.name}  [{', '.join([c.kind, *flags])}]  {c.network}")
        print(f"  classes:  {', '.join(c.classes)}")
        print(f"  trained:  {'real' if c.real else 'procedural'} data: {c.data}")
        print(f"  inputs:   {c.domain}")
        print(f"  figure:   {c.figure}")
        print(f"  rebuild:  {c.build}")
    return 0
