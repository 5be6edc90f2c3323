"""A saved classifier run: the record that rebuilds its model and the checked loading
of a run's checkpoint.

:class:`Architecture` is what ``robopercept nn train`` records in both checkpoints of a
run (builder name and arguments, channels, classes, input size, class names) as JSON;
:func:`load_run` rebuilds the model from the checkpoint alone. Every field of the record
is checked before anything is built (:meth:`Architecture.from_json`: types, ranges,
the input size against the model's poolings on torch's ``meta`` device), and the weights
against the model (:func:`~robopercept.nn.train.checkpoint.load_checkpoint`: names,
shapes, finite values), so a damaged or hostile checkpoint is a
:class:`~robopercept.errors.FileFormatError` naming the file and the field, never a
torch error or a runaway allocation (issue 47).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from robopercept._checks import as_path, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import parse_json
from robopercept.nn._guards import check_device
from robopercept.nn.classification.models import MODELS, build_model
from robopercept.nn.data.augment import Normalize
from robopercept.nn.shipped import SHIPPED_CLASSIFIERS, shipped_model_path
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.runs import BEST_CHECKPOINT

__all__ = [
    "MAX_CLASSES",
    "MAX_INPUT_SIDE",
    "Architecture",
    "load_run",
]

#: the largest side (pixels) of a run's input size that a checkpoint may record
MAX_INPUT_SIDE = 1024
#: the most classes a run's checkpoint may record
MAX_CLASSES = 65536


@dataclass(frozen=True)
class Architecture:
    """Everything needed to rebuild a run's model: ``Sequential(Normalize, builder(...))``.

    Attributes
    ----------
    model : str
        A name of :data:`robopercept.nn.classification.models.MODELS`.
    kwargs : dict
        The builder's other keyword arguments (JSON values).
    in_channels, num_classes : int
    input_size : (height, width)
        The size the model was trained on (predict resizes to it).
    classes : tuple of str
        Class names, ``classes[k]`` for output ``k``.
    mode : {'gray', 'rgb'}
        How images are read (``'gray'`` for C = 1).
    """

    model: str
    kwargs: dict[str, Any]
    in_channels: int
    num_classes: int
    input_size: tuple[int, int]
    classes: tuple[str, ...]
    mode: str

    def to_json(self) -> str:
        """The JSON text stored in the checkpoints' ``"architecture"`` entry."""
        return json.dumps({"robopercept_run": 1, **asdict(self)}, sort_keys=True)

    @classmethod
    def from_json(cls, text: Any, where: str = "checkpoint") -> Architecture:
        """The inverse of :meth:`to_json`, every field checked.

        The record must be a JSON object (read by :func:`robopercept.fileio.parse_json`:
        nesting bounded) with the run marker ``"robopercept_run": 1`` and exactly the
        fields of the class: ``model`` a name of :data:`MODELS`; ``kwargs`` an object
        of the builder's other arguments (not ``in_channels`` or ``num_classes``;
        the builder checks their values when the model is built); ``in_channels`` 1
        with ``mode`` ``"gray"`` or 3 with ``"rgb"``; ``num_classes`` an integer in
        1..:data:`MAX_CLASSES` with as many ``classes`` (names); ``input_size`` two
        integers in 1..:data:`MAX_INPUT_SIDE` (height, width).

        Raises
        ------
        FileFormatError
            ``text`` is not the JSON of a run (a checkpoint not written by
            :func:`train_run`, e.g. one of :func:`~robopercept.nn.train.fit.fit` alone),
            or a field of the wrong type or out of range (the message names it).
        """
        foreign = FileFormatError(
            f"{where}: records no model architecture (not written by `robopercept nn "
            "train`): give the checkpoint.pt or checkpoint.best.pt of a run folder"
        )
        if not isinstance(text, (str, bytes)):
            raise foreign
        try:
            d = parse_json(text, where)
        except FileFormatError:
            raise foreign from None
        marker = d.get("robopercept_run") if isinstance(d, dict) else None
        if type(marker) is not int or marker != 1:
            raise foreign
        fields = {"robopercept_run", *cls.__dataclass_fields__}
        if set(d) != fields:
            odd = sorted(set(d) ^ fields)
            raise FileFormatError(
                f"{where}: its architecture record has missing or unknown fields "
                f"({', '.join(odd)}): the file is damaged or not a run's checkpoint"
            )

        def bad(name: str, expected: str) -> FileFormatError:
            return FileFormatError(
                f"{where}: its architecture's {name} must be {expected}; got "
                f"{plain_repr(d[name])}: the file is damaged or not a run's checkpoint"
            )

        def whole(value: Any, low: int, high: int) -> bool:
            return type(value) is int and low <= value <= high

        if not isinstance(d["model"], str) or d["model"] not in MODELS:
            raise bad("model", f"one of {', '.join(sorted(MODELS))}")
        kwargs = d["kwargs"]
        if (
            not isinstance(kwargs, dict)
            or not all(isinstance(k, str) for k in kwargs)
            or {"in_channels", "num_classes"} & set(kwargs)
        ):
            raise bad("kwargs", "an object of the builder's other arguments")
        if d["mode"] not in ("gray", "rgb"):
            raise bad("mode", "'gray' or 'rgb'")
        channels = 1 if d["mode"] == "gray" else 3
        if not whole(d["in_channels"], channels, channels):
            raise bad("in_channels", f"{channels} (its mode is {d['mode']!r})")
        if not whole(d["num_classes"], 1, MAX_CLASSES):
            raise bad("num_classes", f"an integer in 1..{MAX_CLASSES}")
        size = d["input_size"]
        if not (
            isinstance(size, list)
            and len(size) == 2
            and all(whole(v, 1, MAX_INPUT_SIDE) for v in size)
        ):
            raise bad("input_size", f"[height, width], integers in 1..{MAX_INPUT_SIDE}")
        classes = d["classes"]
        if (
            not isinstance(classes, list)
            or len(classes) != d["num_classes"]
            or not all(isinstance(c, str) for c in classes)
        ):
            raise bad("classes", f"a list of {d['num_classes']} class names (num_classes)")
        return cls(
            model=d["model"],
            kwargs=kwargs,
            in_channels=d["in_channels"],
            num_classes=d["num_classes"],
            input_size=(size[0], size[1]),
            classes=tuple(classes),
            mode=d["mode"],
        )

    def input_size_refusal(self) -> str | None:
        """Why the classifier of ``arch`` cannot take ``self.input_size`` images (torch's
        message: too small for its poolings), or None. Run on torch's ``meta`` device:
        shapes only, no memory, no arithmetic."""
        try:
            with torch.device("meta"):
                net = build_model(
                    self.model, in_channels=self.in_channels, num_classes=self.num_classes,
                    **self.kwargs,
                )  # fmt: skip
                net.eval()(torch.zeros(1, self.in_channels, *self.input_size))
        except RuntimeError as exc:
            lines = str(exc).strip().splitlines()
            return lines[0] if lines else type(exc).__name__
        return None

    def build(self) -> nn.Sequential:
        """The untrained model: ``Sequential(Normalize(0, 1), builder(**kwargs))`` (the
        normalization statistics are loaded with the weights)."""
        c = self.in_channels
        net = build_model(self.model, in_channels=c, num_classes=self.num_classes, **self.kwargs)
        return nn.Sequential(Normalize(np.zeros(c), np.ones(c)), net)


def load_run(
    checkpoint: str | os.PathLike[str], *, device: str | None = None
) -> tuple[nn.Sequential, Architecture]:
    """The model of a run, rebuilt from its checkpoint alone, in eval mode.

    Parameters
    ----------
    checkpoint : path
        ``checkpoint.pt`` or ``checkpoint.best.pt`` of a run folder, the folder itself
        (its ``checkpoint.best.pt``), or a shipped classifier's name
        (:data:`~robopercept.nn.shipped.SHIPPED_CLASSIFIERS`: ``"digits"``).
    device : str, optional
        Where to put the model (default: the CPU).

    Returns
    -------
    model : nn.Sequential
        ``Sequential(Normalize, classifier)``.
    architecture : Architecture

    Raises
    ------
    FileFormatError
        Missing or unreadable file, no recorded architecture or one with a field of the
        wrong type or out of range (:meth:`Architecture.from_json`: e.g. an input size
        over :data:`MAX_INPUT_SIDE`), weights that do not fit the recorded architecture
        or are not finite, or normalization statistics that are not finite or a
        standard deviation <= 0.
    """
    if isinstance(checkpoint, str) and checkpoint in SHIPPED_CLASSIFIERS:
        checkpoint = shipped_model_path("classify", checkpoint)
    p = as_path(checkpoint, "the checkpoint (a run's checkpoint.pt or its folder)")
    dev = check_device(device, "device (--device)")
    if p.is_dir():
        p = p / BEST_CHECKPOINT
    if not p.exists():
        raise FileFormatError(f"{p}: no such checkpoint")
    state = load_checkpoint(p)
    arch = Architecture.from_json(state.get("architecture"), str(p))
    try:
        model = arch.build()
    except InputError as exc:  # kwargs the builder refuses
        raise FileFormatError(
            f"{p}: its architecture cannot be built ({exc}): the file is damaged or not a "
            "run's checkpoint"
        ) from None
    why = arch.input_size_refusal()
    if why is not None:
        raise FileFormatError(
            f"{p}: its model cannot take its recorded input size {arch.input_size[0]} x "
            f"{arch.input_size[1]} ({why}): the file is damaged or not a run's checkpoint"
        )
    load_checkpoint(p, model)  # the weights fit the model and are finite
    _check_normalization(model[0], p)
    model.eval()
    if dev is not None:
        model.to(dev)
    return model, arch


def _check_normalization(norm: nn.Module, where: Path) -> None:
    """A loaded run's :class:`Normalize` divides by positive, finite deviations and
    subtracts finite means (a zero or NaN ``std`` makes every probability NaN)."""
    std, mean = getattr(norm, "std", None), getattr(norm, "mean", None)
    if not (isinstance(std, torch.Tensor) and isinstance(mean, torch.Tensor)):
        raise FileFormatError(f"{where}: the model has no normalization statistics")
    if not (bool(torch.isfinite(mean).all()) and bool(torch.isfinite(std).all())) or bool(
        (std <= 0).any()
    ):
        raise FileFormatError(
            f"{where}: its normalization statistics are unusable (mean "
            f"{mean.flatten().tolist()}, std {std.flatten().tolist()}; std must be finite "
            "and > 0): the file is damaged; train the run again (nn train --overwrite)"
        )
