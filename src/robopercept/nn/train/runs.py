"""The run folder: where a training command writes its model, checkpoints, history,
metrics and pictures, and the rule that keeps one run from silently replacing another.

Every training run of :mod:`robopercept.nn` (``nn train``, ``nn detect train``,
``nn segment train``, ``nn pose train``, ``nn cloud train``, and their library
functions, the ``run`` modules of the task wings) writes one folder:

========================  =============================================================
``checkpoint.pt``         the last complete epoch (model, optimizer, schedule, random
                          states, history; :func:`~robopercept.nn.train.loop.train_loop`):
                          written after every epoch, so Ctrl-C or SIGTERM keeps it, and
                          ``resume=True`` (``--resume``) continues from it
``checkpoint.best.pt``    the best epoch's weights
========================  =============================================================

and the task's own files beside them (the model, ``history``, ``metrics.json``,
pictures). :func:`prepare_run_folder` refuses a folder that already holds a run unless
the caller resumes it or replaces it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from robopercept._checks import as_path, check_bool, plain_repr
from robopercept.errors import InputError, RunExistsError
from robopercept.fileio import MAX_NESTING, atomic_path, nesting_depth, strict_json

__all__ = [
    "BEST_CHECKPOINT",
    "CHECKPOINT",
    "check_output_folder",
    "prepare_run_folder",
    "write_json",
]

#: the last complete epoch of a run (what ``--resume`` continues)
CHECKPOINT = "checkpoint.pt"
#: the best epoch's weights
BEST_CHECKPOINT = "checkpoint.best.pt"


def check_output_folder(value: Any, flag: str = "-o/--out") -> Path | None:
    """An evaluation's output folder (None stays None): a path that is not an existing
    file (the folder is created when written).

    Raises
    ------
    InputError
        Not a path, or an existing file, naming ``flag``.

    Examples
    --------
    >>> check_output_folder(None) is None
    True
    """
    if value is None:
        return None
    out = as_path(value, f"out_dir ({flag})")
    if out.exists() and not out.is_dir():
        raise InputError(f"{flag} {out} is a file; give a folder")
    return out


def prepare_run_folder(
    out_dir: str | os.PathLike[str], *, resume: bool = False, overwrite: bool = False
) -> Path:
    """Check and create the run folder ``out_dir``; return its checkpoint path.

    A folder holding a run (its ``checkpoint.pt``) is refused unless ``resume``
    (continue it) or ``overwrite`` (start afresh: the new run's first epoch replaces the
    checkpoints; nothing is removed before, so a run that fails on its data loses
    nothing). ``resume`` needs the checkpoint.

    Parameters
    ----------
    out_dir : path
    resume, overwrite : bool
        Exclusive.

    Returns
    -------
    Path
        ``out_dir / "checkpoint.pt"``.

    Raises
    ------
    RunExistsError
        The folder holds a run and neither ``resume`` nor ``overwrite`` was given (the
        message names ``--resume`` and ``--overwrite``).
    InputError
        Both flags; ``resume`` without a checkpoint; ``out_dir`` is a file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp()) / "run"
    >>> prepare_run_folder(d).name
    'checkpoint.pt'
    >>> _ = (d / "checkpoint.pt").write_bytes(b"")
    >>> prepare_run_folder(d)
    Traceback (most recent call last):
    ...
    robopercept.errors.RunExistsError: ...
    """
    out = as_path(out_dir, "-o/--out")
    resume = check_bool(resume, "resume (--resume)")
    overwrite = check_bool(overwrite, "overwrite (--overwrite)")
    if resume and overwrite:
        raise InputError("--resume and --overwrite exclude each other: give one")
    if out.exists() and not out.is_dir():
        raise InputError(f"-o/--out {out} is a file; give a folder")
    ckpt = out / CHECKPOINT
    if resume and not ckpt.exists():
        raise InputError(
            f"nothing to resume: {ckpt} does not exist; drop --resume to start a new run"
        )
    if not resume and not overwrite and ckpt.exists():
        raise RunExistsError(
            f"{out} already holds a run ({CHECKPOINT}): pass --resume to continue it, "
            "--overwrite to start afresh, or choose another -o/--out folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    return ckpt


def write_json(path: str | os.PathLike[str], value: Any) -> Path:
    """Write ``value`` as indented, strict JSON (NaN and infinities as null,
    :func:`robopercept.fileio.strict_json`) atomically; return the path."""
    p = as_path(path, "path")
    if nesting_depth(value, MAX_NESTING) > MAX_NESTING:
        raise InputError(
            f"value nests more than {MAX_NESTING} levels deep (or holds itself): no run "
            "record is that deep; write flat dicts and lists"
        )
    try:
        text = json.dumps(strict_json(value), indent=1) + "\n"
    except (TypeError, ValueError) as exc:  # an array, a set, an object; a cycle
        raise InputError(
            f"value must be JSON data (dicts with str keys, lists, str, numbers, bool, None); "
            f"got {type(value).__name__} {plain_repr(value)[:60]} ({exc}): convert arrays with "
            ".tolist()"
        ) from None
    with atomic_path(p) as tmp:
        Path(tmp).write_text(text)
    return p
