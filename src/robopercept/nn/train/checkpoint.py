"""Checkpoints: ``torch.save`` dictionaries of tensors and plain Python values, read back
with ``weights_only=True`` (no pickled code), written atomically (a temporary file renamed
over the target), so Ctrl-C leaves the last complete one readable.

:func:`save_checkpoint` / :func:`load_checkpoint` are the format of
:func:`~robopercept.nn.train.fit.fit` (model, optimizer, schedule, shuffling generator,
torch's random state, history, configuration, architecture); :func:`save_built_model` /
:func:`load_built_model` add what rebuilds the model through a builder (kind, settings,
class names): the format of the detectors, segmenters and point-cloud networks.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import nn

from robopercept._checks import as_path, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import atomic_path
from robopercept.nn._guards import check_module

__all__ = [
    "load_built_model",
    "load_checkpoint",
    "save_built_model",
    "save_checkpoint",
    "update_checkpoint",
]


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any]) -> Path:
    """Write ``state`` (tensors and plain values) to ``path`` atomically (a temporary
    file renamed over it), so an interruption never leaves half a checkpoint."""
    p = as_path(path, "the checkpoint path")
    if not isinstance(state, dict):
        raise InputError(f"state must be a dict of tensors and plain values; got {state!r}"[:200])
    p.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(p) as tmp:  # the one atomic writer (robopercept.fileio)
        torch.save(state, tmp)
    return p


def save_built_model(
    path: str | os.PathLike[str],
    model: nn.Module,
    kind: str,
    settings: Mapping[str, Any],
    classes: Sequence[str],
    **extra: Any,
) -> Path:
    """Write ``model``'s weights with what rebuilds it through a builder (``kind``, the
    constructor ``settings``, the ``classes``) and ``extra`` plain values beside them:
    the checkpoint format of the detectors and segmenters
    (:func:`~robopercept.nn.detection.zoo.save_detector`,
    :func:`~robopercept.nn.segmentation.networks.save_segmenter`). Returns the path.

    Raises
    ------
    InputError
        Settings not a dict of keyword arguments, or no class names.
    """
    model = check_module(model)
    if not isinstance(settings, Mapping) or not all(isinstance(k, str) for k in settings):
        raise InputError(
            "settings must be a dict of the class's keyword arguments (e.g. {'width': 8}); "
            f"got {plain_repr(settings)}"
        )
    if (
        not isinstance(classes, (list, tuple))
        or not classes
        or not all(isinstance(c, str) for c in classes)
    ):
        raise InputError(
            f"classes must be a non-empty list of class names (str); got {plain_repr(classes)}"
        )
    return save_checkpoint(
        path,
        {
            **extra,
            "model": model.state_dict(),
            "architecture": type(model).__name__,
            "kind": kind,
            "settings": dict(settings),
            "classes": list(classes),
        },
    )


def load_built_model(
    path: str | os.PathLike[str],
    kinds: Sequence[str],
    build: Callable[..., nn.Module],
    what: str,
    writer: str,
) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a model written by :func:`save_built_model`: ``build(kind, n_classes,
    **settings)``, its weights loaded, eval mode, on the CPU.

    Parameters
    ----------
    path : path-like
    kinds : sequence of str
        The kinds this loader accepts (a detector's checkpoint is not a segmenter's).
    build : callable
    what, writer : str
        What the model is ("detector") and what writes such checkpoints, for the
        message.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, or a checkpoint of another kind (or without
        ``kind``/``classes``).
    """
    if (
        not isinstance(kinds, (list, tuple))
        or not kinds
        or not all(isinstance(k, str) for k in kinds)
    ):
        raise InputError(f"kinds must be a non-empty list of names; got {plain_repr(kinds)}")
    if not callable(build):
        raise InputError(f"build must be a callable (kind, n_classes, **settings); got {build!r}")
    state = load_checkpoint(path)
    info = {k: v for k, v in state.items() if k != "model"}
    kind, classes = info.get("kind"), info.get("classes")
    if kind not in kinds or not isinstance(classes, list) or not classes:
        raise FileFormatError(
            f"{path}: not a {what} checkpoint (kind {plain_repr(kind)}, not one of "
            f"{', '.join(sorted(kinds))}): write it with {writer}"
        )
    model = build(str(kind), len(classes), **dict(info.get("settings") or {}))
    model.load_state_dict(state["model"])
    return model.eval(), info


def load_checkpoint(path: str | os.PathLike[str], model: nn.Module | None = None) -> dict[str, Any]:
    """Read a checkpoint written by :func:`~robopercept.nn.train.fit.fit`
    (``weights_only=True``: tensors and plain values only, no code) and, with ``model``,
    load its weights into it.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, not a robopercept checkpoint, or weights of another
        architecture (the message names the architecture recorded in the checkpoint).
    """
    p = as_path(path, "the checkpoint path")
    if model is not None:
        model = check_module(model)
    if p.is_dir():
        raise FileFormatError(f"{p} is a folder; give a checkpoint file (.pt)")
    if not p.exists():
        raise FileFormatError(f"{p}: no such file")
    try:
        state = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a foreign file
        raise FileFormatError(
            f"{p}: not a readable torch checkpoint ({type(exc).__name__})"
        ) from None
    if not isinstance(state, dict) or "model" not in state:
        raise FileFormatError(f"{p}: not a robopercept checkpoint (no 'model' weights)")
    if model is not None:
        own = model.state_dict()
        theirs = state["model"]
        if not isinstance(theirs, dict) or not all(
            isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in theirs.items()
        ):
            raise FileFormatError(f"{p}: its 'model' entry is not a dict of named tensors")
        # a model that renamed its layers (a detector's renamed_keys) loads the old names:
        # compare under the names its load_state_dict will give them
        renames = getattr(model, "renamed_keys", None) or {}
        named = {_renamed(k, renames, theirs): v for k, v in theirs.items()}
        bad = sorted(set(own) ^ set(named)) + sorted(
            k for k in set(own) & set(named) if tuple(own[k].shape) != tuple(named[k].shape)
        )
        if bad:
            arch = state.get("architecture", "an unrecorded architecture")
            raise FileFormatError(
                f"{p}: weights of {arch}, not of this model ({len(bad)} mismatched tensors, "
                f"first {bad[0]!r}): build the model the checkpoint was trained with"
            )
        model.load_state_dict(theirs)
    return state


def _renamed(key: str, renames: Mapping[str, str], keys: Mapping[str, Any]) -> str:
    """``key`` under the first old prefix of ``renames`` it starts with, unless the new
    name is already present (the rule of ``Detector._load_from_state_dict``)."""
    for old, new in renames.items():
        if key.startswith(old) and new + key[len(old) :] not in keys:
            return new + key[len(old) :]
    return key


def update_checkpoint(path: str | os.PathLike[str], **values: Any) -> Path:
    """Set plain ``values`` in the checkpoint at ``path`` (its weights unchanged),
    atomically: e.g. the ``calibration`` chosen on validation after training.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = save_checkpoint(pathlib.Path(tempfile.mkdtemp()) / "c.pt", {"model": {}})
    >>> _ = update_checkpoint(p, calibration={"score_thresh": 0.4})
    >>> load_checkpoint(p)["calibration"]
    {'score_thresh': 0.4}
    """
    state = load_checkpoint(path)
    if not isinstance(state, dict):
        raise FileFormatError(f"{path}: not a checkpoint dictionary")
    state.update(values)
    return save_checkpoint(path, state)
