"""Checkpoints: ``torch.save`` dictionaries of tensors and plain Python values, read back
with ``weights_only=True`` (no pickled code), written atomically (a temporary file renamed
over the target), so Ctrl-C leaves the last complete one readable.

:func:`save_checkpoint` / :func:`load_checkpoint` are the format of
:func:`~robopercept.nn.train.fit.fit` (model, optimizer, schedule, shuffling generator,
torch's random state, history, configuration, architecture); :func:`save_built_model` /
:func:`load_built_model` add what rebuilds the model through a builder (kind, settings,
class names): the format of the detectors, segmenters, pose and point-cloud networks.

Loading checks before it builds (:func:`check_state_dict`, the one validation of every
loader of weights): the weights must be a dict of the model's tensor names and shapes
with finite values; a built model's ``kind``, ``classes`` and ``settings`` are checked
field by field against the constructor's signature and ranges, and the model is first
built on torch's ``meta`` device, so a damaged or hostile file is a
:class:`~robopercept.errors.FileFormatError` naming the file (and the first mismatched
tensor), never a torch error or an allocation its settings alone ask for. Writing goes
through :func:`~robopercept.fileio.atomic_path`: a full disk is a
:class:`~robopercept.fileio.WriteError` (``no space left on the device``) and the
previous checkpoint stays intact.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import nn

from robopercept._checks import as_path, plain_repr
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.fileio import WriteError, atomic_path, describe_write_error, write_error
from robopercept.nn._guards import MAX_PARAMETERS, check_module

__all__ = [
    "MAX_CLASSES",
    "check_state_dict",
    "load_built_model",
    "load_checkpoint",
    "save_built_model",
    "save_checkpoint",
    "update_checkpoint",
]

#: the most class names a built model's checkpoint may list
MAX_CLASSES = 1 << 16
#: the longest class name, and the longest string setting, in characters
_MAX_NAME = 1024
#: the most items of a list setting
_MAX_ITEMS = 1024


def save_checkpoint(path: str | os.PathLike[str], state: dict[str, Any]) -> Path:
    """Write ``state`` (tensors and plain values) to ``path`` atomically (a temporary
    file renamed over it), so an interruption never leaves half a checkpoint.

    Raises
    ------
    InputError
        ``state`` is not a dict.
    WriteError
        The file could not be written (``"<path>: no space left on the device"`` for a
        full disk); the previous checkpoint at ``path`` is left as it was.
    """
    p = as_path(path, "the checkpoint path")
    if not isinstance(state, dict):
        raise InputError(f"state must be a dict of tensors and plain values; got {state!r}"[:200])
    with atomic_path(p) as tmp:  # the one atomic writer (robopercept.fileio)
        with open(tmp, "wb") as f:
            try:
                # through a Python file: a failed write leaves its OSError (errno) in the
                # context of torch's RuntimeError ("unexpected pos ...")
                torch.save(state, f)
            except RuntimeError as exc:
                # Ctrl-C or SIGTERM in the middle of the write reaches torch's writer
                # as an exception of its Python file, which torch reports as "unexpected
                # pos": the interruption goes on as itself (the faults campaign saw
                # Ctrl-C end as an error, exit 1)
                stop = _behind(exc, lambda e: not isinstance(e, Exception))
                if stop is not None:
                    raise stop from None
                raise _write_failure(p, exc) from exc
    return p


def _behind(exc: BaseException, wanted: Callable[[BaseException], bool]) -> BaseException | None:
    """The first exception of ``exc``'s chain of causes and contexts (itself included,
    16 links at most) for which ``wanted`` is true, or None."""
    cause: BaseException | None = exc
    for _ in range(16):
        if cause is None or wanted(cause):
            return cause
        cause = cause.__cause__ or cause.__context__
    return None


def _write_failure(path: Path, exc: RuntimeError) -> WriteError:
    """The :class:`WriteError` of a ``torch.save`` that failed: the first
    :class:`OSError` behind torch's RuntimeError (a full disk: ``ENOSPC``, ``EFBIG``)."""
    cause = _behind(exc, lambda e: isinstance(e, OSError))
    if isinstance(cause, OSError):
        return write_error(path, cause)
    return WriteError(describe_write_error(path, exc), None, os.fspath(path))


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
    *,
    constructors: Mapping[str, Callable[..., Any]] | None = None,
) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a model written by :func:`save_built_model`: ``build(kind, n_classes,
    **settings)``, its weights loaded, eval mode, on the CPU.

    Every field is checked before anything is built at full size: ``kind`` one of
    ``kinds``; ``classes`` a list of 1 to :data:`MAX_CLASSES` names (str); ``settings``
    a dict of plain values (numbers, strings, short lists of them) whose keys are
    keyword parameters of the kind's constructor (``constructors[kind]``, following
    ``**settings`` into its base class), none repeating the positional class count.
    The model is then built on torch's ``meta`` device (no memory): what the
    constructor refuses, more than :data:`~robopercept.nn._guards.MAX_PARAMETERS`
    parameters, or weights that do not fit it (:func:`check_state_dict`: names,
    shapes, finite values) are a :class:`FileFormatError`; only a checkpoint that fits
    is built on the CPU and loaded, so its settings alone never make the loader
    allocate more than the file's own weights.

    Parameters
    ----------
    path : path-like
    kinds : sequence of str
        The kinds this loader accepts (a detector's checkpoint is not a segmenter's).
    build : callable
        ``build(kind, n_classes, **settings)``.
    what, writer : str
        What the model is ("detector") and what writes such checkpoints, for the
        message.
    constructors : mapping of str to callable, optional
        The class each kind's settings are the keyword arguments of (default: the
        names are not checked against a signature; the builder still refuses unknown
        ones).

    Returns
    -------
    model : torch.nn.Module
    info : dict
        The checkpoint without the weights.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a checkpoint of another kind (or without
        ``kind``/``classes``), damaged ``classes`` or ``settings``, settings the
        constructor refuses, or weights that do not fit the model (the message names
        the file and the first mismatched tensor).
    """
    if (
        not isinstance(kinds, (list, tuple))
        or not kinds
        or not all(isinstance(k, str) for k in kinds)
    ):
        raise InputError(f"kinds must be a non-empty list of names; got {plain_repr(kinds)}")
    if not callable(build):
        raise InputError(f"build must be a callable (kind, n_classes, **settings); got {build!r}")
    if constructors is not None and not isinstance(constructors, Mapping):
        raise InputError(
            f"constructors must map each kind to its class; got {plain_repr(constructors)}"
        )
    p = as_path(path, "the checkpoint path")
    state = load_checkpoint(p)
    info = {k: v for k, v in state.items() if k != "model"}
    kind = info.get("kind")
    if not isinstance(kind, str) or kind not in kinds:
        raise FileFormatError(
            f"{p}: not a {what} checkpoint (kind {_short(kind)}, not one of "
            f"{', '.join(sorted(kinds))}): write it with {writer}"
        )
    classes = _check_classes(info.get("classes"), p, what, writer)
    ctor = None if constructors is None else constructors.get(kind)
    settings = _check_settings(info.get("settings"), p, kind, ctor)

    def make() -> nn.Module:
        try:
            model = build(kind, len(classes), **settings)
        except RoboperceptError as exc:
            raise FileFormatError(
                f"{p}: its settings cannot build a {kind} {what} ({exc}): the file is damaged "
                f"or not one {writer} wrote"
            ) from None
        except (TypeError, ValueError, OverflowError, RuntimeError, NotImplementedError) as exc:
            raise FileFormatError(
                f"{p}: its settings cannot build a {kind} {what} ({type(exc).__name__}: "
                f"{str(exc)[:120]}): the file is damaged or not one {writer} wrote"
            ) from None
        if not isinstance(model, nn.Module):
            raise InputError(f"build must return a torch.nn.Module; got {type(model).__name__}")
        return model

    with torch.device("meta"):  # the shapes alone: nothing allocated yet
        probe = make()
    size = sum(t.numel() for t in probe.parameters()) + sum(t.numel() for t in probe.buffers())
    if size > MAX_PARAMETERS:
        raise FileFormatError(
            f"{p}: its settings make a {kind} {what} of {size} values, over the limit of "
            f"{MAX_PARAMETERS}: the file is damaged or not one {writer} wrote"
        )
    arch = info.get("architecture")
    check_state_dict(probe, state["model"], str(p), arch if isinstance(arch, str) else None)
    model = make()
    _load_weights(model, state["model"], p)
    return model.eval(), info


def _short(value: Any) -> str:
    """``plain_repr(value)`` cut to 80 characters, for messages about hostile files."""
    text = plain_repr(value) if isinstance(value, (str, int, float, bool, type(None))) else ""
    if not text:
        text = f"a {type(value).__name__}"
    return text if len(text) <= 80 else text[:77] + "..."


def _check_classes(classes: Any, where: Path, what: str, writer: str) -> list[str]:
    """The checkpoint's ``classes``: 1 to :data:`MAX_CLASSES` names, each a str."""
    if not isinstance(classes, (list, tuple)) or not classes:
        raise FileFormatError(
            f"{where}: not a {what} checkpoint (its 'classes' is {_short(classes)}, not a "
            f"list of class names): write it with {writer}"
        )
    if len(classes) > MAX_CLASSES:
        raise FileFormatError(
            f"{where}: lists {len(classes)} classes, over the limit of {MAX_CLASSES}: the "
            "file is damaged"
        )
    for i, c in enumerate(classes):
        if not isinstance(c, str) or len(c) > _MAX_NAME:
            raise FileFormatError(
                f"{where}: classes[{i}] is {_short(c)}, not a class name (a str of at most "
                f"{_MAX_NAME} characters): the file is damaged"
            )
    return list(classes)


def _plain(value: Any, depth: int = 0) -> bool:
    """Whether ``value`` is a plain setting: None, a bool, int, float or str (at most
    :data:`_MAX_NAME` characters), or a list/tuple of at most :data:`_MAX_ITEMS` of
    them, nested at most twice."""
    if value is None or isinstance(value, (bool, int, float)):
        return True
    if isinstance(value, str):
        return len(value) <= _MAX_NAME
    if isinstance(value, (list, tuple)):
        return depth < 2 and len(value) <= _MAX_ITEMS and all(_plain(v, depth + 1) for v in value)
    return False


def _keywords(ctor: Callable[..., Any]) -> tuple[set[str], set[str]]:
    """The keyword parameters of ``ctor`` (a class or function) and its positional
    count (the first parameter), following ``**kwargs`` into the base class's
    ``__init__`` (a Mask R-CNN's settings are a Faster R-CNN's)."""
    keywords: set[str] = set()
    positional: set[str] = set()
    chain: list[Callable[..., Any]] = [ctor]
    if isinstance(ctor, type):
        chain += [c for c in ctor.__mro__[1:] if "__init__" in vars(c) and c is not object]
    for target in chain:
        try:
            params = list(inspect.signature(target).parameters.values())
        except (TypeError, ValueError):  # a builtin without a signature
            break
        more = False
        for i, prm in enumerate(params):
            if prm.kind is prm.VAR_KEYWORD:
                more = True
            elif prm.kind is prm.VAR_POSITIONAL:
                continue
            elif i == 0 and prm.kind is not prm.KEYWORD_ONLY:
                positional.add(prm.name)
            else:
                keywords.add(prm.name)
        if not more:
            break
    return keywords - positional, positional


def _check_settings(
    settings: Any, where: Path, kind: str, ctor: Callable[..., Any] | None
) -> dict[str, Any]:
    """The checkpoint's ``settings``: a dict of plain values whose keys are keyword
    parameters of ``ctor`` (none its positional count); missing or None is ``{}``."""
    if settings is None:
        return {}
    if not isinstance(settings, dict):
        raise FileFormatError(
            f"{where}: its 'settings' is {_short(settings)}, not a dict of the {kind} "
            "constructor's keyword arguments: the file is damaged"
        )
    allowed, positional = _keywords(ctor) if ctor is not None else (None, set())
    for key, value in settings.items():
        if not isinstance(key, str):
            raise FileFormatError(
                f"{where}: 'settings' has the key {_short(key)}; the keys are the {kind} "
                "constructor's keyword arguments (str): the file is damaged"
            )
        if key in positional:
            raise FileFormatError(
                f"{where}: setting {key!r} repeats an argument the loader gives (the count "
                "comes from the checkpoint's 'classes'): the file is damaged"
            )
        if allowed is not None and key not in allowed:
            raise FileFormatError(
                f"{where}: unknown setting {_short(key)} for a {kind} (it takes "
                f"{', '.join(sorted(allowed))}): the file is damaged or of another version"
            )
        if not _plain(value):
            raise FileFormatError(
                f"{where}: setting {key!r} is {_short(value)}, not a plain value (a number, "
                "a string or a short list of them): the file is damaged"
            )
    return dict(settings)


def check_state_dict(
    model: nn.Module, weights: Any, where: str, architecture: str | None = None
) -> None:
    """Check that ``weights`` (a checkpoint's ``"model"`` entry) fit ``model`` before
    they are loaded: the one validation of every loader of weights.

    ``weights`` must be a dict of named dense tensors with exactly the model's names
    (under the model's ``renamed_keys``, as its ``load_state_dict`` maps them) and
    shapes, floating where the model's are, every floating value finite and every
    batch-norm running variance non-negative. ``model`` may live on the ``meta``
    device (only its names and shapes are read).

    Parameters
    ----------
    model : torch.nn.Module
    weights : object
        What the file holds.
    where : str
        The file, for the message.
    architecture : str, optional
        What the file says it holds, for the message.

    Raises
    ------
    InputError
        ``model`` is not a module.
    FileFormatError
        The first mismatch, named: ``"<file>: weights of <architecture>, not of this
        model (... first 'head.weight' ...)"``, or a tensor with NaN or infinite values.

    Examples
    --------
    >>> net = nn.Linear(2, 1)
    >>> check_state_dict(net, {"weight": torch.zeros(1, 2), "bias": torch.zeros(1)}, "m.pt")
    >>> check_state_dict(net, {"weight": torch.zeros(1, 3), "bias": torch.zeros(1)}, "m.pt")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: m.pt: weights of another model, not of this model (1 \
mismatched tensors, first 'weight': shape (1, 3) where the model has (1, 2)): build the \
model the checkpoint was trained with
    """
    model = check_module(model)
    if not isinstance(where, str):
        raise InputError(f"where must be the file's name (str); got {plain_repr(where)}")
    if not isinstance(weights, dict):
        raise FileFormatError(
            f"{where}: its 'model' entry is {_short(weights)}, not a dict of named tensors"
        )
    for k, v in weights.items():
        if not isinstance(k, str) or not isinstance(v, torch.Tensor):
            raise FileFormatError(
                f"{where}: its 'model' entry is not a dict of named tensors (entry "
                f"{_short(k)} is a {type(v).__name__})"
            )
    own = model.state_dict()
    # a model that renamed its layers (a detector's renamed_keys) loads the old names:
    # compare under the names its load_state_dict will give them
    renames = getattr(model, "renamed_keys", None) or {}
    named = {_renamed(k, renames, weights): (k, v) for k, v in weights.items()}
    bad: list[str] = []
    for k in sorted(set(own) - set(named)):
        bad.append(f"{k!r}: missing from the file")
    for k in sorted(set(named) - set(own)):
        bad.append(f"{named[k][0]!r}: not a tensor of the model")
    for k in sorted(set(own) & set(named)):
        mine, theirs = own[k], named[k][1]
        if tuple(mine.shape) != tuple(theirs.shape):
            bad.append(
                f"{named[k][0]!r}: shape {tuple(theirs.shape)} where the model has "
                f"{tuple(mine.shape)}"
            )
        elif theirs.device.type != "cpu":  # map_location="cpu" leaves only "meta" here
            bad.append(f"{named[k][0]!r}: a {theirs.device.type} tensor without values")
        elif (
            theirs.layout != torch.strided
            or theirs.is_quantized
            or theirs.is_complex()
            or theirs.is_floating_point() != mine.is_floating_point()
        ):
            bad.append(
                f"{named[k][0]!r}: a {theirs.dtype} {theirs.layout} tensor where the model "
                f"has {mine.dtype}"
            )
    if bad:
        arch = architecture if isinstance(architecture, str) else "another model"
        arch = arch if len(arch) <= 80 else arch[:77] + "..."
        raise FileFormatError(
            f"{where}: weights of {arch}, not of this model ({len(bad)} mismatched tensors, "
            f"first {bad[0]}): build the model the checkpoint was trained with"
        )
    for k, (name, v) in named.items():
        if v.is_floating_point() and not bool(torch.isfinite(v).all()):
            raise FileFormatError(
                f"{where}: tensor {name!r} holds NaN or infinite values: the weights are "
                "damaged (a diverged training run?); use an earlier checkpoint"
            )
        if k.endswith("running_var") and v.is_floating_point() and bool((v < 0).any()):
            raise FileFormatError(
                f"{where}: tensor {name!r} holds negative variances: the weights are damaged"
            )


def _load_weights(model: nn.Module, weights: dict[str, torch.Tensor], where: Path) -> None:
    """``model.load_state_dict(weights)`` after :func:`check_state_dict`; what torch
    still refuses is a :class:`FileFormatError` naming ``where``."""
    try:
        model.load_state_dict(weights)
    except (RuntimeError, TypeError, ValueError) as exc:
        raise FileFormatError(
            f"{where}: weights that do not load into the model ({str(exc).splitlines()[0][:160]})"
        ) from None


def load_checkpoint(path: str | os.PathLike[str], model: nn.Module | None = None) -> dict[str, Any]:
    """Read a checkpoint written by :func:`~robopercept.nn.train.fit.fit`
    (``weights_only=True``: tensors and plain values only, no code) and, with ``model``,
    load its weights into it after :func:`check_state_dict`.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, not a robopercept checkpoint, or weights that do not
        fit ``model`` (the message names the first mismatched tensor) or are not finite.
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
        arch = state.get("architecture")
        check_state_dict(model, state["model"], str(p), arch if isinstance(arch, str) else None)
        _load_weights(model, state["model"], p)
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
