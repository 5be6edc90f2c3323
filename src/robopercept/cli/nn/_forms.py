"""What the task commands of ``robopercept nn`` share: the three forms of ``nn detect``,
``nn segment``, ``nn pose`` and ``nn cloud`` (``train``, ``eval`` and ``IMAGE...``,
chosen by the first word; :func:`register_forms`), their data flags
(:func:`built_in_data_args`, :func:`data_path_options`), and the checks of the images
form (:func:`images_form_inputs`, :func:`run_or_model_path`) with its output names
(:data:`OUTPUT_NAMES_HELP`, :func:`robopercept.imaging.io.output_stems`)."""

from __future__ import annotations

import argparse
import importlib.util
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from robopercept.cli._args import UsageError, image_size, positive_int, unit_interval
from robopercept.errors import InputError

__all__ = [
    "OUTPUT_NAMES_HELP",
    "built_in_data_args",
    "check_run_folder_args",
    "data_path_options",
    "device_arg",
    "images_form_inputs",
    "note_warning",
    "prediction_args",
    "prediction_json",
    "print_model_line",
    "register_forms",
    "run_folder_args",
    "run_or_model_path",
    "shipped_help",
]


#: how the images forms name their outputs (robopercept.imaging.io.output_stems), for
#: the commands' help
OUTPUT_NAMES_HELP = (
    "NAME is the input's file name without its extension; inputs that share a name get "
    "their folders' names in front (a/x.png, b/x.png -> a_x, b_x), and inputs still "
    "alike (the same file twice) -2, -3, ... after it, so no input's output is written "
    "over another's"
)


def register_forms(
    ns: argparse._SubParsersAction,
    name: str,
    help: str,
    parsers: Callable[[], dict[str, argparse.ArgumentParser]],
    handlers: Mapping[str, Callable[[argparse.Namespace], int]],
) -> None:
    """Add ``robopercept nn NAME train|eval|IMAGE...`` to ``ns``: a command of three
    forms chosen by its first word (``train``, ``eval``, else the images form), each
    with its own parser from ``parsers()`` (built only when the command runs) and its
    handler in ``handlers`` (keys ``"train"``, ``"eval"``, ``"images"``). The handlers
    need torch: without it the command says which extra to install."""

    def run(args: argparse.Namespace) -> int:
        words = list(args.words)
        forms = parsers()
        if not words or words[0] in ("-h", "--help"):
            for p in forms.values():
                p.print_help()
                print()
            return 0 if words else 2
        form = words[0] if words[0] in ("train", "eval") else "images"
        sub = forms[form].parse_args(words[1:] if form != "images" else words)
        if importlib.util.find_spec("torch") is None:
            raise InputError(
                f"robopercept nn {name} needs the deep extra: pip install 'robopercept[deep]'"
            )
        return handlers[form](sub)

    d = ns.add_parser(
        name,
        help=help,
        description=f"robopercept nn {name} train|eval|IMAGE... (see --help of each form)",
        prefix_chars="\x00",
        add_help=False,
    )
    d.add_argument(
        "words",
        nargs="*",
        help=f"train ..., eval ..., or the images form; robopercept nn {name} --help shows "
        "all three",
    )
    d.set_defaults(func=run)


def built_in_data_args(
    p: argparse.ArgumentParser,
    data_help: str,
    dir_help: str,
    choices: tuple[str, ...] | None = None,
    *,
    images: int = 200,
    generated: str = "shapes/digits",
) -> None:
    """The data flags of the ``nn detect``, ``nn segment`` and ``nn pose`` forms:
    ``--data`` (with ``choices`` where only built-in sets are taken), ``--images-dir``
    (unless ``dir_help`` is empty) and ``--allow-outside-paths`` (with it;
    :func:`data_path_options`), ``--images`` (default ``images``), ``--size``,
    ``--seed``, ``--device``, ``--json`` and ``--quiet``; ``generated`` names the
    generated sets in the help."""
    p.add_argument("--data", required=True, choices=choices, help=data_help)
    if dir_help:
        p.add_argument("--images-dir", help=dir_help)
        p.add_argument(
            "--allow-outside-paths",
            action="store_true",
            help="your own data: read images that the annotations place outside their "
            "folder (a file_name, imagePath or <filename> with '..' above it, or an "
            "absolute path); refused by default, so that annotations from elsewhere cannot "
            "make the command read other files. Give it only for annotations you trust",
        )
    p.add_argument(
        "--images",
        type=positive_int,
        default=images,
        help=f"{generated}: images (default {images})",
    )
    p.add_argument(
        "--size",
        type=image_size,
        default=(128, 128),
        help=f"{generated}: WxH (default 128x128)",
    )
    p.add_argument("--seed", type=int, default=0, help="data, split and weights (default 0)")
    device_arg(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")


def data_path_options(args: argparse.Namespace) -> dict[str, bool]:
    """The keyword arguments of ``--allow-outside-paths`` for the library's data
    loaders: ``{"allow_outside": True}`` when it is given, else none (the loaders'
    default: image paths stay inside the data set's folder,
    :func:`robopercept.imaging.io.contained_path`)."""
    return {"allow_outside": True} if getattr(args, "allow_outside_paths", False) else {}


def run_folder_args(p: argparse.ArgumentParser) -> None:
    """The run-folder flags of every ``nn ... train`` form: ``-o/--out`` (default
    ``run``), ``--resume`` and ``--overwrite`` (:func:`check_run_folder_args`; the
    library's :func:`~robopercept.nn.train.runs.prepare_run_folder` applies them)."""
    p.add_argument("-o", "--out", default="run", help="run folder (default run/)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out")
    p.add_argument("--overwrite", action="store_true", help="replace a run already in --out")


def check_run_folder_args(args: argparse.Namespace) -> None:
    """Refuse ``--resume`` with ``--overwrite`` (exit 2)."""
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")


def run_or_model_path(text: str) -> Path:
    """A run folder's ``model.pt``, or the file itself."""
    p = Path(text)
    return p / "model.pt" if p.is_dir() else p


def images_form_inputs(
    args: argparse.Namespace,
    kind: str,
    outputs: Sequence[str],
) -> tuple[str | Path | None, list[str]]:
    """Check the images form of ``nn detect`` / ``nn segment`` / ``nn pose`` and return
    the model argument of the predictor (None or a shipped name as given, else the
    checkpoint's path) and each IMAGE's output stem: ``--model`` a run folder, a
    ``model.pt`` or a shipped name of ``kind``
    (:func:`robopercept.nn.shipped.resolve_model`; without ``--model`` the kind's
    default), ``-o/--out`` or ``--json`` given, every IMAGE present, and no output
    (``OUT/<stem><ending>`` for each of the ``outputs`` endings, such as ``".png"``)
    over an input. The stems are :func:`robopercept.imaging.io.output_stems` of the
    IMAGEs (:data:`OUTPUT_NAMES_HELP`): two inputs never write to the same file."""
    from robopercept.imaging.io import output_stems
    from robopercept.nn.shipped import SHIPPED, resolve_model

    model: str | Path | None = args.model
    if args.model is None or args.model in SHIPPED[kind]:
        resolve_model(kind, args.model)  # says how to build one that is not installed
    else:
        model_path = run_or_model_path(args.model)
        if not model_path.is_file():
            raise UsageError(f"--model: {model_path} does not exist (a run folder or model.pt)")
        model = model_path
    if not args.out and not args.json:
        raise UsageError("-o/--out: give a folder for the pictures (or --json for results)")
    for name in args.images:
        if not Path(name).is_file():
            raise UsageError(f"IMAGE: {name} does not exist")
    stems = output_stems(args.images, outputs)
    inputs = {Path(name).resolve(): name for name in args.images}
    for stem in stems if args.out else ():
        for end in outputs:
            written = Path(args.out) / f"{stem}{end}"
            if written.resolve() in inputs:
                raise UsageError(
                    f"-o/--out: {written} would overwrite the input "
                    f"{inputs[written.resolve()]}: write to another folder"
                )
    return model, stems


def shipped_help(kind: str) -> str:
    """The ``--model`` help of a prediction command: every shipped model of ``kind``
    with what it learnt from (the model cards; torch-free)."""
    from robopercept.nn.shipped import DEFAULT_SHIPPED, MODEL_CARDS

    names = [
        f"{c.name} ({'real' if c.real else 'procedural'} data: {c.domain.split(',')[0]})"
        for c in MODEL_CARDS.values()
        if c.kind == kind
    ]
    return (
        f"a model.pt or run folder, or a shipped model: {'; '.join(names)}; default "
        f"{DEFAULT_SHIPPED[kind]} (robopercept nn models describes them)"
    )


def prediction_args(
    r: argparse.ArgumentParser, kind: str, *, scores: str | None, tiling: bool
) -> None:
    """The model flags of a prediction form: ``--model`` (listing the shipped models of
    ``kind``), and with ``scores`` (what a score keeps, e.g. "detections")
    ``--score-thresh`` (default the model's stored threshold) and ``--all-scores``;
    with ``tiling`` ``--tile`` and ``--overlap``."""
    r.add_argument("--model", help=shipped_help(kind))
    if scores:
        r.add_argument(
            "--score-thresh",
            type=unit_interval,
            default=None,
            help=f"{scores} kept (default: the threshold stored with the model, chosen on "
            "its validation images; 0.3 for detect and 0.5 for segment where none is stored)",
        )
        r.add_argument("--all-scores", action="store_true", help=f"keep every one of the {scores}")
    if tiling:
        r.add_argument(
            "--tile",
            type=int,
            default=None,
            metavar="PX",
            help="predict images larger than PX in overlapping PX x PX windows and merge "
            "them (default: the window the model was trained on, where it stores one; "
            "0 never tiles)",
        )
        r.add_argument(
            "--overlap",
            type=int,
            default=None,
            metavar="PX",
            help="pixels shared by neighbouring windows (default a quarter of --tile)",
        )


def print_model_line(args: argparse.Namespace, kind: str) -> str:
    """Print (unless ``--json``) and return the line naming the model of a prediction
    run and what it was trained on."""
    from robopercept.nn.shipped import domain_line

    line = domain_line(kind, args.model)
    if not args.json:
        print(line)
    return line


def prediction_json(line: str, warnings: list[str], results: list[Any]) -> str:
    """The ``--json`` document of a prediction run: the model line, the domain
    warnings and the per-image results."""
    import json

    return json.dumps({"model": line, "warnings": warnings, "results": results})


def note_warning(args: argparse.Namespace, name: str, warning: str | None, into: list[str]) -> None:
    """Keep an image's domain warning for ``--json`` (in ``into``) and print it on
    stderr otherwise."""
    import sys

    if warning:
        into.append(f"{name}: {warning}")
        if not args.json:
            print(into[-1], file=sys.stderr)


def device_arg(p: argparse.ArgumentParser) -> None:
    """``--device auto|cpu|cuda|cuda:N`` (``auto``, like leaving it out: CUDA when torch
    sees a GPU, else the CPU; :func:`robopercept.nn._guards.check_device`)."""
    p.add_argument(
        "--device",
        metavar="DEVICE",
        help="auto, cpu, cuda or cuda:N (default: cuda when torch sees a GPU, else cpu)",
    )
