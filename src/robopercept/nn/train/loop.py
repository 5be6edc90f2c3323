"""THE training loop of :mod:`robopercept.nn`: :func:`train_loop`, with the optimizer
and per-batch schedule of the task trainers (:func:`step_optimizer`,
:func:`optimizer_step`) and :func:`epoch_loop`, the loop of the trainers that draw
batches of sample indices (pose networks, point-cloud networks).

:func:`train_loop` is the one loop (the only epoch loop in the package, as a grep
for the loop's header shows): :func:`~robopercept.nn.train.fit.fit`, the detectors',
segmenters', pose, point-cloud and lifting trainers give it their batches and their
loss; the loop owns the
optimizer step (non-finite losses refused, gradient clipping, per-batch or per-epoch
schedules), weight averaging, validation every k epochs with the best epoch kept, early
stopping, progress, checkpoints after every epoch and resuming from them, and
determinism.

Optimizers and schedules are PyTorch's own (:mod:`torch.optim`,
:mod:`torch.optim.lr_scheduler`): they are not perception methods. A run is
deterministic on the CPU: the same seed and thread count give bit-identical weights
(:func:`~robopercept.nn.train.config.deterministic_algorithms` during the run), and a
run resumed from its checkpoint ends where an uninterrupted one does (the checkpoint,
written atomically after every epoch by
:func:`~robopercept.nn.train.checkpoint.save_checkpoint`, holds the model, the
optimizer, the schedule, the generators' and torch's random states and the trainer's
history).
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import reprlib
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeGuard

import torch
from torch import nn
from torch.optim.swa_utils import AveragedModel

from robopercept._checks import as_path, check_bool, check_real, plain_repr
from robopercept.errors import ArgumentError, FileFormatError, InputError
from robopercept.nn._guards import check_allocation, check_count, check_module
from robopercept.nn.train.checkpoint import load_checkpoint, save_checkpoint
from robopercept.nn.train.config import (
    TrainConfig,
    deterministic_algorithms,
)
from robopercept.progress import progress_bar

__all__ = [
    "EpochHistory",
    "LoopResult",
    "epoch_loop",
    "optimizer_step",
    "step_optimizer",
    "train_loop",
]


def step_optimizer(
    params: list[nn.Parameter], cfg: TrainConfig, steps_per_epoch: int
) -> tuple[torch.optim.Optimizer, Any]:
    """The optimizer and a learning-rate schedule stepped after every batch (not every
    epoch, as :func:`~robopercept.nn.train.fit.fit`'s), for loops that step per batch:
    the detectors' and the segmenters'.

    ``cfg.optimizer``: SGD (``momentum``, ``nesterov``, ``weight_decay``) or AdamW
    (``lr``, ``weight_decay``); ``cfg.schedule``: ``"cosine"`` anneals to 0 over
    ``epochs * steps_per_epoch`` steps, ``"step"`` multiplies by ``gamma`` every
    ``step_size`` epochs, ``"onecycle"`` is OneCycleLR over all the steps,
    ``"constant"`` keeps ``lr``.

    Parameters
    ----------
    params : list of Parameter
        The trainable parameters (at least one).
    cfg : TrainConfig
    steps_per_epoch : int

    Returns
    -------
    (torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler)

    Raises
    ------
    InputError
        No parameter to train.
    """
    if not isinstance(cfg, TrainConfig):
        raise InputError(f"cfg must be a TrainConfig; got {plain_repr(cfg)}")
    if not isinstance(params, (list, tuple)) or not all(
        isinstance(p, torch.Tensor) for p in params
    ):
        raise InputError(
            f"params must be a list of tensors, e.g. list(model.parameters()); got "
            f"{plain_repr(params)}"
        )
    if not params:
        raise InputError("the model has no trainable parameters (everything is frozen)")
    steps = check_count(steps_per_epoch, "steps_per_epoch", 1, 1 << 40)
    if cfg.optimizer == "sgd":
        opt: torch.optim.Optimizer = torch.optim.SGD(
            params,
            lr=cfg.lr,
            momentum=cfg.momentum,
            nesterov=cfg.nesterov,
            weight_decay=cfg.weight_decay,
        )
    else:
        opt = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    if cfg.schedule == "cosine":
        sched: Any = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=cfg.epochs * steps)
    elif cfg.schedule == "step":
        sched = torch.optim.lr_scheduler.StepLR(opt, cfg.step_size * steps, cfg.gamma)
    elif cfg.schedule == "onecycle":
        sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=cfg.epochs * steps)
    else:
        sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda _: 1.0)
    return opt, sched


def optimizer_step(
    loss: torch.Tensor,
    opt: torch.optim.Optimizer,
    sched: Any,
    params: list[nn.Parameter],
    cfg: TrainConfig,
    where: str,
) -> None:
    """One step of a per-batch loop (:func:`step_optimizer`'s pair): refuse a loss that
    is not finite (naming ``where``, e.g. "epoch 3, batch 2", and the learning rate to
    lower), then zero the gradients, back-propagate, clip their norm at
    ``cfg.clip_grad_norm`` (when set), step the optimizer and the schedule.

    Raises
    ------
    InputError
        The loss is NaN or infinite.
    """
    if (
        not isinstance(loss, torch.Tensor)
        or loss.numel() != 1
        or not isinstance(opt, torch.optim.Optimizer)
        or not callable(getattr(sched, "step", None))
        or not isinstance(cfg, TrainConfig)
        or not isinstance(params, (list, tuple))
    ):
        raise InputError(
            "optimizer_step takes a scalar loss tensor, the optimizer and schedule of "
            "step_optimizer, their parameters (a list) and the TrainConfig"
        )
    if not bool(torch.isfinite(loss)):
        raise InputError(
            f"the loss became {float(loss)} at {where}: lower the learning rate (lr {cfg.lr:g})"
        )
    opt.zero_grad(set_to_none=True)
    loss.backward()
    if cfg.clip_grad_norm is not None:
        nn.utils.clip_grad_norm_(params, cfg.clip_grad_norm)
    opt.step()
    sched.step()


@dataclass
class LoopResult:
    """What :func:`train_loop` ends with.

    Attributes
    ----------
    epochs_done : int
        Completed epochs (counting those of a resumed checkpoint).
    best_epoch : int
        The (1-based) epoch whose weights the model holds (the last epoch without
        validation; 0 when no epoch ran).
    best_score : float
        Its validation score (``-inf`` without validation).
    stopped : str
        ``""``, or why the loop ended early (``"early stopping: ..."``).
    """

    epochs_done: int = 0
    best_epoch: int = 0
    best_score: float = -math.inf
    stopped: str = ""


def train_loop(
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    batches: Callable[[int], Iterable[Any]],
    step: Callable[[Any, int, int], torch.Tensor],
    *,
    epochs: int,
    schedule: Any = None,
    schedule_per_batch: bool = True,
    clip_grad_norm: float | None = None,
    clip_params: Sequence[torch.Tensor] | None = None,
    lr: float | None = None,
    before_epoch: Callable[[int], None] | None = None,
    end_epoch: Callable[[int, float], None] | None = None,
    validate: Callable[[int], float] | None = None,
    val_every: int = 1,
    after_epoch: Callable[[int, LoopResult, float], dict[str, str]] | None = None,
    averaged: Any = None,
    patience: int | None = None,
    generators: Mapping[str, torch.Generator] | None = None,
    checkpoint: str | os.PathLike[str] | None = None,
    checkpoint_extra: Callable[[int], dict[str, Any]] | None = None,
    best_extra: Mapping[str, Any] | None = None,
    resume: bool = False,
    restore: Callable[[dict[str, Any]], None] | None = None,
    write: bool = True,
    desc: str = "training",
    progress: bool = True,
) -> LoopResult:
    r"""THE training loop: every trainer of :mod:`robopercept.nn` runs its epochs here
    (:func:`~robopercept.nn.train.fit.fit`, :func:`epoch_loop`,
    :func:`~robopercept.nn.detection.train.train_detector`,
    :func:`~robopercept.nn.segmentation.networks.train_segmenter`,
    :func:`~robopercept.nn.pose.lifting.train_lifter`), each giving its batches and its
    loss.

    Per epoch ``e`` (0-based): ``before_epoch(e)``; the model in train mode; for each
    batch ``b`` of ``batches(e)``, ``loss = step(batch, e, b)``, refused when not finite
    (the message names the epoch, the batch and the learning rate ``lr`` to lower),
    then ``zero_grad``, back-propagation, gradient-norm clipping at ``clip_grad_norm``
    (of ``clip_params``, by default every parameter),
    the optimizer step, the schedule's step when ``schedule_per_batch``, and the update
    of the weight average ``averaged`` (a :class:`torch.optim.swa_utils.AveragedModel`);
    the schedule's step after the batches otherwise; ``end_epoch(e, seconds)``. Every
    ``val_every`` epochs and after the last, ``validate(e)`` scores the kept model (the
    average when there is one; higher is better) and the best score's weights are
    copied (the earliest on ties); without ``validate`` every epoch is the best, so the
    last weights are kept. ``after_epoch(e, result, seconds)`` sees the running
    :class:`LoopResult` and returns the progress bar's figures. With ``patience``, the
    loop stops when the best epoch lies ``patience`` epochs back. At the end (and when
    interrupted) the model holds the best weights.

    The run is deterministic on the CPU for a thread count: the loop runs under
    :func:`~robopercept.nn.train.config.deterministic_algorithms`, the caller seeds
    torch and the ``generators`` it draws batches from.

    **Checkpoints.** With ``checkpoint``, after every epoch (when ``write``: rank 0 of a
    distributed run) the file holds the kept weights (``"model"``), the optimizer and
    schedule, the ``generators``' and torch's random states, the weight average and the
    trained weights under it, ``"epochs_done"``, ``"best_epoch"``, ``"best_score"`` and
    ``checkpoint_extra(e)`` (the trainer's history and settings); the best weights go to
    ``<stem>.best.pt`` beside it with ``best_extra``. Written atomically
    (:func:`~robopercept.nn.train.checkpoint.save_checkpoint`), so Ctrl-C or SIGTERM
    leaves the last complete epoch. ``resume`` reads them back (then ``restore(state)``
    gives the trainer its history) and continues with epoch ``epochs_done``: the run
    ends with the weights an uninterrupted one has.

    Parameters
    ----------
    model : torch.nn.Module
    optimizer : torch.optim.Optimizer
    batches : callable
        ``batches(epoch) -> iterable`` of the epoch's batches (drawn lazily, so that
        the random draws interleave with the steps as they always did).
    step : callable
        ``step(batch, epoch, b) -> loss``, a scalar tensor attached to the graph; the
        trainer accumulates its own figures here.
    epochs : int
    schedule : torch.optim.lr_scheduler.LRScheduler, optional
    schedule_per_batch : bool
    clip_grad_norm : float, optional
    clip_params : sequence of Parameter, optional
    lr : float, optional
        The learning rate the user set, named when a loss is not finite (default: the
        optimizer's first group's).
    before_epoch, end_epoch, after_epoch : callable, optional
    validate : callable, optional
    val_every : int
    averaged : AveragedModel, optional
    patience : int, optional
    generators : dict of str to torch.Generator, optional
    checkpoint : path, optional
    checkpoint_extra : callable, optional
    best_extra : dict, optional
    resume : bool
    restore : callable, optional
    write : bool
    desc : str
        The progress bar's label.
    progress : bool

    Returns
    -------
    LoopResult

    Raises
    ------
    InputError
        A loss that became NaN or infinite; ``resume`` without a checkpoint.
    FileFormatError
        ``resume`` from a file that is not such a checkpoint, of another model, or with a
        damaged or unfitting training state (epochs, best epoch and score, optimizer,
        schedule, random states, history: the message names the entry and
        ``--overwrite``).
    ArgumentError
        ``resume`` with ``epochs`` fewer than the checkpoint's completed epochs.
    """
    model = check_module(model)
    if not isinstance(optimizer, torch.optim.Optimizer):
        raise InputError(f"optimizer must be a torch.optim.Optimizer; got {plain_repr(optimizer)}")
    if not callable(batches) or not callable(step):
        raise InputError(
            "batches must be a callable (epoch -> batches) and step a callable (batch, epoch, "
            f"b -> loss); got {plain_repr(batches)} and {plain_repr(step)}"
        )
    hooks = {
        "before_epoch": before_epoch,
        "end_epoch": end_epoch,
        "validate": validate,
        "after_epoch": after_epoch,
        "checkpoint_extra": checkpoint_extra,
        "restore": restore,
    }
    for name, hook in hooks.items():
        if hook is not None and not callable(hook):
            raise InputError(f"{name} must be a callable or None; got {plain_repr(hook)}")
    epochs = check_count(epochs, "epochs", 1, 1 << 30)
    val_every = check_count(val_every, "val_every", 1, 1 << 30)
    if schedule is not None and not (
        callable(getattr(schedule, "step", None))
        and callable(getattr(schedule, "state_dict", None))
    ):
        raise InputError(
            f"schedule must be a torch LRScheduler or None; got {plain_repr(schedule)}"
        )
    if clip_grad_norm is not None:
        clip_grad_norm = check_real(clip_grad_norm, "clip_grad_norm", 0.0, low_inclusive=False)
    if clip_params is not None and (
        not isinstance(clip_params, (list, tuple))
        or not all(isinstance(p, torch.Tensor) for p in clip_params)
    ):
        raise InputError(f"clip_params must be a list of tensors; got {plain_repr(clip_params)}")
    if lr is not None:
        lr = check_real(lr, "lr", 0.0)
    if averaged is not None and not isinstance(averaged, AveragedModel):
        raise InputError(
            f"averaged must be a torch.optim.swa_utils.AveragedModel; got {plain_repr(averaged)}"
        )
    if patience is not None:
        patience = check_count(patience, "patience", 1, 1 << 30)
    if generators is not None and (
        not isinstance(generators, Mapping)
        or not all(
            isinstance(k, str) and isinstance(g, torch.Generator) for k, g in generators.items()
        )
    ):
        raise InputError(
            f"generators must be a dict of names to torch.Generator; got {plain_repr(generators)}"
        )
    if best_extra is not None and not isinstance(best_extra, Mapping):
        raise InputError(f"best_extra must be a dict or None; got {plain_repr(best_extra)}")
    schedule_per_batch = check_bool(schedule_per_batch, "schedule_per_batch")
    resume = check_bool(resume, "resume")
    write = check_bool(write, "write")
    progress = check_bool(progress, "progress")
    if not isinstance(desc, str):
        raise InputError(f"desc must be a str; got {plain_repr(desc)}")
    gens = dict(generators or {})
    ckpt = as_path(checkpoint, "checkpoint") if checkpoint is not None else None
    if resume and ckpt is None:
        raise InputError("resume needs the checkpoint to resume from")
    best_path = ckpt.with_name(ckpt.stem + ".best.pt") if ckpt is not None else None
    kept = averaged.module if averaged is not None else model
    rate = float(optimizer.param_groups[0]["lr"]) if lr is None else float(lr)
    clip = list(clip_params) if clip_params is not None else None
    result = LoopResult()
    best_state: dict[str, torch.Tensor] | None = None
    start = 0
    if resume and ckpt is not None:
        result, best_state = _resume(
            ckpt, model, kept, optimizer, schedule, averaged, gens, epochs, restore,
            best_path if validate is not None else None,
        )  # fmt: skip
        start = result.epochs_done
    bar = progress_bar(total=epochs - start, desc=desc, unit="epoch", disable=not progress)
    try:
        with deterministic_algorithms():
            for epoch in range(start, epochs):
                t0 = time.perf_counter()
                if before_epoch is not None:
                    before_epoch(epoch)
                model.train()
                for b, batch in enumerate(batches(epoch)):
                    loss = step(batch, epoch, b)
                    if not bool(torch.isfinite(loss)):
                        value = loss.item()
                        raise InputError(
                            f"the loss became {value} at epoch {epoch + 1}, batch {b + 1}: "
                            f"lower the learning rate (lr {rate:g})"
                        )
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    if clip_grad_norm is not None:
                        nn.utils.clip_grad_norm_(
                            clip if clip is not None else model.parameters(), clip_grad_norm
                        )
                    optimizer.step()
                    if schedule is not None and schedule_per_batch:
                        schedule.step()
                    if averaged is not None:
                        averaged.update_parameters(model)
                if schedule is not None and not schedule_per_batch:
                    schedule.step()
                if end_epoch is not None:
                    end_epoch(epoch, time.perf_counter() - t0)
                improved = validate is None
                if validate is not None and ((epoch + 1) % val_every == 0 or epoch + 1 == epochs):
                    score = float(validate(epoch))
                    if best_state is None or score > result.best_score:
                        result.best_score, improved = score, True
                        best_state = copy.deepcopy(kept.state_dict())
                if improved:
                    result.best_epoch = epoch + 1
                result.epochs_done = epoch + 1
                if (
                    patience is not None
                    and validate is not None
                    and epoch + 1 - result.best_epoch >= patience
                ):
                    result.stopped = f"early stopping: no improvement for {patience} epochs"
                post = after_epoch(epoch, result, time.perf_counter() - t0) if after_epoch else {}
                if ckpt is not None and best_path is not None and write:
                    if improved:
                        save_checkpoint(
                            best_path, {**dict(best_extra or {}), "model": kept.state_dict()}
                        )
                    save_checkpoint(
                        ckpt,
                        _loop_state(
                            result,
                            model,
                            kept,
                            optimizer,
                            schedule,
                            averaged,
                            gens,
                            checkpoint_extra,
                            epoch,
                        ),
                    )
                bar.update(1)
                if post:
                    bar.set_postfix(**post)
                if result.stopped:
                    break
    finally:
        bar.close()
        if best_state is not None:
            model.load_state_dict(best_state)
        elif averaged is not None:
            model.load_state_dict(kept.state_dict())
    return result


#: what a damaged training state raises while it is restored
_DAMAGE = (
    TypeError,
    ValueError,
    KeyError,
    IndexError,
    AttributeError,
    RuntimeError,
    OverflowError,
    RecursionError,
)


def _damaged(ckpt: Path, entry: str, detail: str) -> FileFormatError:
    return FileFormatError(
        f"{ckpt}: its {entry!r} entry is damaged or does not fit this run ({detail}): "
        "resume with the options the run was started with, or start afresh with --overwrite"
    )


@contextlib.contextmanager
def _entry(ckpt: Path, entry: str) -> Iterator[None]:
    """Errors of restoring ``entry`` become :class:`FileFormatError` naming it."""
    try:
        yield
    except FileFormatError:
        raise
    except _DAMAGE as exc:
        lines = str(exc).strip().splitlines()
        detail = f"{type(exc).__name__}: {lines[0][:200]}" if lines else type(exc).__name__
        raise _damaged(ckpt, entry, detail) from None


def _same_kind(fresh: Any, saved: Any, *, exact_keys: bool, depth: int = 0) -> bool:
    """``saved`` has the structure of ``fresh``: the same keys (``exact_keys``) or a
    value of the same kind for every key of both, lists and tuples of the same length,
    finite numbers for numbers (``bool`` apart), equal strings, ``None`` for ``None``."""
    if depth > 16:
        return False
    if isinstance(fresh, bool) or fresh is None or isinstance(fresh, str):
        return type(saved) is type(fresh) and (not isinstance(fresh, str) or saved == fresh)
    if isinstance(fresh, (int, float)):
        return (
            isinstance(saved, (int, float)) and not isinstance(saved, bool) and math.isfinite(saved)
        )
    if isinstance(fresh, torch.Tensor):
        return isinstance(saved, torch.Tensor) and saved.shape == fresh.shape
    if isinstance(fresh, dict):
        if not isinstance(saved, dict) or (exact_keys and set(saved) != set(fresh)):
            return False
        return all(
            _same_kind(fresh[k], saved[k], exact_keys=exact_keys, depth=depth + 1)
            for k in set(fresh) & set(saved)
        )
    if isinstance(fresh, (list, tuple)):
        return (
            isinstance(saved, (list, tuple))
            and len(saved) == len(fresh)
            and all(
                _same_kind(f, v, exact_keys=exact_keys, depth=depth + 1)
                for f, v in zip(fresh, saved, strict=True)
            )
        )
    return True  # a value torch keeps opaque (a function's place, ...)


def _finite_tensors(values: Any) -> bool:
    return all(
        not (isinstance(v, torch.Tensor) and v.is_floating_point()) or bool(torch.isfinite(v).all())
        for v in values
    )


def _check_optimizer(optimizer: torch.optim.Optimizer, fresh_groups: list[dict[str, Any]]) -> None:
    """After ``load_state_dict``: the hyper-parameters of every group of the kind the
    optimizer made, and a finite per-parameter state of each parameter's shape with
    the entries its step reads (``exp_avg``... for Adam and AdamW)."""
    for fresh, group in zip(fresh_groups, optimizer.param_groups, strict=True):
        hyper = {k: v for k, v in fresh.items() if k != "params"}
        loaded = {k: v for k, v in group.items() if k != "params"}
        if not _same_kind(hyper, loaded, exact_keys=False):
            raise ValueError(f"hyper-parameters {reprlib.repr(loaded)} are not of this optimizer")
    needed: set[str] = set()
    if isinstance(optimizer, (torch.optim.Adam, torch.optim.AdamW)):
        needed = {"step", "exp_avg", "exp_avg_sq"}
    for group in optimizer.param_groups:
        for param in group["params"]:
            st = optimizer.state.get(param)
            if not st:
                continue
            if not isinstance(st, dict) or not needed <= set(st):
                raise ValueError(f"a parameter's state lacks {sorted(needed)}")
            for key, v in st.items():
                if v is None:
                    continue
                if not isinstance(v, torch.Tensor) or not _finite_tensors([v]):
                    raise ValueError(f"a parameter's {key!r} is not a finite tensor")
                if v.ndim and v.shape != param.shape:
                    raise ValueError(
                        f"a parameter's {key!r} has shape {tuple(v.shape)}, the parameter "
                        f"{tuple(param.shape)}"
                    )


def _count(ckpt: Path, state: dict[str, Any], entry: str, low: int, high: int) -> int:
    v = state.get(entry)
    if type(v) is not int or not low <= v <= high:
        raise _damaged(ckpt, entry, f"an integer in {low}..{high} expected; got {reprlib.repr(v)}")
    return v


def _resume(
    ckpt: Path,
    model: nn.Module,
    kept: nn.Module,
    optimizer: torch.optim.Optimizer,
    schedule: Any,
    averaged: Any,
    gens: dict[str, torch.Generator],
    epochs: int,
    restore: Callable[[dict[str, Any]], None] | None,
    best_path: Path | None,
) -> tuple[LoopResult, dict[str, torch.Tensor] | None]:
    """Restore a :func:`train_loop` checkpoint, every entry checked (the weights by
    :func:`load_checkpoint`); return the running result and the best weights."""
    state = load_checkpoint(ckpt)
    for entry in ("epochs_done", "optimizer"):
        if entry not in state:
            raise FileFormatError(
                f"{ckpt}: not a checkpoint of a training run that can be resumed (no "
                f"{entry!r} entry): start afresh with --overwrite"
            )
    done = _count(ckpt, state, "epochs_done", 0, 1 << 30)
    best_epoch = _count(ckpt, state, "best_epoch", 0, done)
    score = state.get("best_score")
    if (
        not isinstance(score, (int, float))
        or isinstance(score, bool)
        or math.isnan(score)
        or score == math.inf
    ):
        raise _damaged(ckpt, "best_score", f"a number expected; got {reprlib.repr(score)}")
    stopped = state.get("stopped", "")
    if not isinstance(stopped, str):
        raise _damaged(ckpt, "stopped", f"a str expected; got {reprlib.repr(stopped)}")
    if done > epochs:
        raise ArgumentError(
            f"--epochs {epochs} is fewer than the {done} epochs the run in {ckpt.parent} has "
            f"done: give --epochs {done} or more, or start afresh with --overwrite"
        )
    if averaged is not None:
        if "averaged" not in state:
            raise FileFormatError(f"{ckpt}: the run kept no weight average; resume it without one")
        load_checkpoint(ckpt, kept)  # the average's weights: they fit and are finite
        with _entry(ckpt, "trained_model"):
            trained = state.get("trained_model")
            if not isinstance(trained, dict) or not _finite_tensors(trained.values()):
                raise ValueError("not a dict of finite tensors")
            model.load_state_dict(trained)
        with _entry(ckpt, "averaged"):
            avg = state["averaged"]
            if not isinstance(avg, dict) or not _finite_tensors(avg.values()):
                raise ValueError("not a dict of finite tensors")
            averaged.load_state_dict(avg)
    else:
        load_checkpoint(ckpt, model)
    with _entry(ckpt, "optimizer"):
        fresh = [dict(g) for g in optimizer.param_groups]
        saved = state["optimizer"]
        if not isinstance(saved, dict) or set(saved) != {"state", "param_groups"}:
            raise ValueError("not an optimizer's state_dict")
        optimizer.load_state_dict(saved)
        _check_optimizer(optimizer, fresh)
    if schedule is not None and state.get("scheduler") is not None:
        with _entry(ckpt, "scheduler"):
            saved = state["scheduler"]
            if not _same_kind(schedule.state_dict(), saved, exact_keys=True):
                raise ValueError(f"not the state of a {type(schedule).__name__}")
            schedule.load_state_dict(saved)
    with _entry(ckpt, "generators"):
        saved_gens = state.get("generators")
        if not isinstance(saved_gens, dict):
            raise TypeError(f"a dict of generator states expected; got {reprlib.repr(saved_gens)}")
        for name, g in gens.items():
            g.set_state(saved_gens[name])
    with _entry(ckpt, "torch_rng_state"):
        torch.set_rng_state(state["torch_rng_state"])
    best_state: dict[str, torch.Tensor] | None = None
    if best_path is not None and best_path.exists():
        probe = copy.deepcopy(kept)
        load_checkpoint(best_path, probe)  # the best weights fit and are finite
        best_state = probe.state_dict()
    if restore is not None:
        with _entry(ckpt, "history"):
            restore(state)
    return LoopResult(done, best_epoch, float(score), stopped), best_state


def _loop_state(
    result: LoopResult,
    model: nn.Module,
    kept: nn.Module,
    optimizer: torch.optim.Optimizer,
    schedule: Any,
    averaged: Any,
    gens: dict[str, torch.Generator],
    extra: Callable[[int], dict[str, Any]] | None,
    epoch: int,
) -> dict[str, Any]:
    state: dict[str, Any] = dict(extra(epoch)) if extra is not None else {}
    state.update(
        model=kept.state_dict(),
        optimizer=optimizer.state_dict(),
        scheduler=schedule.state_dict() if schedule is not None else None,
        generators={k: g.get_state() for k, g in gens.items()},
        torch_rng_state=torch.get_rng_state(),
        epochs_done=result.epochs_done,
        best_epoch=result.best_epoch,
        best_score=result.best_score,
        stopped=result.stopped,
    )
    if averaged is not None:
        state.update(trained_model=model.state_dict(), averaged=averaged.state_dict())
    return state


@dataclass
class EpochHistory:
    """What :func:`epoch_loop` measured: the mean training loss and the seconds of each
    epoch, the validation score by (1-based) epoch, and the epoch whose weights were kept."""

    losses: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    val: dict[int, float] = field(default_factory=dict)
    best_epoch: int = 0

    #: the name of the validation score in :meth:`to_dict` and on the progress bar
    val_name = "val"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (the validation scores under :attr:`val_name`)."""
        return {
            "losses": self.losses,
            "seconds": self.seconds,
            self.val_name: {str(k): v for k, v in self.val.items()},
            "best_epoch": self.best_epoch,
        }

    def load_dict(self, saved: Mapping[str, Any]) -> None:
        """Take back what :meth:`to_dict` gave (a resumed run's history), checked:
        ``losses`` and ``seconds`` lists of numbers of one length, the validation scores
        a dict of epoch (a decimal str) to number, ``best_epoch`` an integer.

        Raises
        ------
        InputError
            ``saved`` is not such a record (the message names the entry); nothing is
            changed then.
        """

        def numbers(value: Any) -> TypeGuard[list[float]]:
            return isinstance(value, list) and all(
                isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
            )

        if not isinstance(saved, Mapping):
            raise InputError(f"a history must be a dict; got {type(saved).__name__}")
        losses, seconds = saved.get("losses"), saved.get("seconds")
        val, best = saved.get(self.val_name), saved.get("best_epoch")
        if not numbers(losses) or not numbers(seconds) or len(losses) != len(seconds):
            raise InputError("the history's 'losses' and 'seconds' must be lists of numbers")
        if not isinstance(val, dict) or not all(
            isinstance(k, str) and k.isdecimal() and len(k) < 12 and numbers([v])
            for k, v in val.items()
        ):
            raise InputError(f"the history's {self.val_name!r} must map epochs to numbers")
        if type(best) is not int:
            raise InputError(f"the history's 'best_epoch' must be an integer; got {best!r:.80}")
        self.losses[:] = list(losses)
        self.seconds[:] = list(seconds)
        self.val.clear()
        self.val.update({int(k): float(v) for k, v in val.items()})
        self.best_epoch = best


def epoch_loop(
    model: nn.Module,
    n: int,
    cfg: TrainConfig,
    generator: torch.Generator,
    batch: Callable[[torch.Tensor], torch.Tensor],
    validate: Callable[[], float] | None,
    *,
    desc: str,
    progress: bool = True,
    history: EpochHistory | None = None,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
    checkpoint_extra: Mapping[str, Any] | None = None,
) -> EpochHistory:
    """:func:`train_loop` for the task trainers that draw batches of sample indices
    (pose networks, point-cloud networks): per epoch a shuffle of the ``n`` samples by
    ``generator`` in batches of ``cfg.batch_size`` (a last batch of one sample joins the
    one before it: batch norm cannot learn from one), ``batch(indices)`` giving each
    batch's loss, one optimizer step per batch (:func:`step_optimizer`'s optimizer and
    per-step schedule, the loss refused when not finite), then ``validate()`` (higher is
    better) and the best epoch's weights kept (the last epoch's without ``validate``).
    Runs under :func:`deterministic_algorithms`; the model is left in eval mode.

    Parameters
    ----------
    model : torch.nn.Module
        Its trainable parameters are optimized in place.
    n : int
        The number of training samples (indices ``0 .. n-1`` go to ``batch``).
    cfg : TrainConfig
        ``epochs``, ``batch_size``, the optimizer and schedule.
    generator : torch.Generator
        Draws the shuffles (seeded by the caller).
    batch : callable
        ``batch(indices: LongTensor) -> loss`` (a scalar tensor attached to the graph).
    validate : callable or None
        ``validate() -> float`` after each epoch, higher better.
    desc : str
        The progress bar's label.
    progress : bool
        Show a bar per run (one step per epoch) on stderr.
    history : EpochHistory, optional
        Filled in and returned (a subclass names its score, e.g. the pose PCK).
    checkpoint : path, optional
        Written after every epoch (:func:`train_loop`'s checkpoint, with the history
        and ``checkpoint_extra``); the best weights in ``<stem>.best.pt``.
    resume : bool
        Continue from ``checkpoint``: ends with the weights of an uninterrupted run.
    checkpoint_extra : dict, optional
        Plain values stored in both checkpoint files (e.g. the model's settings).

    Returns
    -------
    EpochHistory

    Raises
    ------
    InputError
        A loss became NaN or infinite (lower the learning rate); ``n`` beyond what one
        shuffle of the indices may take (1 GiB: 2**27 samples).
    """
    model = check_module(model)
    n = check_count(n, "n (training samples)", 1, 1 << 40)
    # every epoch shuffles the n indices (torch.randperm: int64)
    check_allocation(n, 8, f"the shuffle of n={n} samples", "train on fewer samples")
    if not isinstance(cfg, TrainConfig):
        raise InputError(f"cfg must be a TrainConfig; got {plain_repr(cfg)}")
    if not isinstance(generator, torch.Generator):
        raise InputError(
            f"generator must be a torch.Generator (torch.Generator().manual_seed(0)); got "
            f"{plain_repr(generator)}"
        )
    if not callable(batch) or (validate is not None and not callable(validate)):
        raise InputError(
            "batch must be a callable (indices -> loss) and validate a callable (-> score) "
            f"or None; got {plain_repr(batch)} and {plain_repr(validate)}"
        )
    if not isinstance(desc, str) or not isinstance(history, (EpochHistory, type(None))):
        raise InputError("desc must be a str and history an EpochHistory or None")
    steps = -(-n // cfg.batch_size)
    if n > 1 and n % cfg.batch_size == 1:  # a last batch of one joins the one before:
        steps -= 1  # batch norm cannot learn from one sample
    params = [p for p in model.parameters() if p.requires_grad]
    opt, sched = step_optimizer(params, cfg, steps)
    hist = EpochHistory() if history is None else history

    def batches(epoch: int) -> Iterator[torch.Tensor]:
        order = torch.randperm(n, generator=generator)
        for b in range(steps):
            end = n if b == steps - 1 else (b + 1) * cfg.batch_size
            yield order[b * cfg.batch_size : end]

    total = [0.0]

    def step(idx: torch.Tensor, epoch: int, b: int) -> torch.Tensor:
        value = batch(idx)
        if not isinstance(value, torch.Tensor) or value.numel() != 1:
            raise InputError(f"batch must return a scalar loss tensor; got {plain_repr(value)}")
        total[0] += float(value.detach())
        return value

    def end_epoch(epoch: int, seconds: float) -> None:
        hist.losses.append(total[0] / steps)
        hist.seconds.append(seconds)
        total[0] = 0.0

    def scored(epoch: int) -> float:
        assert validate is not None
        score = float(validate())
        hist.val[epoch + 1] = score
        return score

    def after_epoch(epoch: int, res: LoopResult, seconds: float) -> dict[str, str]:
        hist.best_epoch = res.best_epoch
        post = {"loss": f"{hist.losses[-1]:.4g}"}
        if hist.val:
            post[hist.val_name] = f"{hist.val[epoch + 1]:.3f}"
        return post

    train_loop(
        model,
        opt,
        batches,
        step,
        epochs=cfg.epochs,
        schedule=sched,
        clip_grad_norm=cfg.clip_grad_norm,
        clip_params=params,
        lr=cfg.lr,
        end_epoch=end_epoch,
        validate=scored if validate is not None else None,
        after_epoch=after_epoch,
        generators={"shuffle": generator},
        checkpoint=checkpoint,
        checkpoint_extra=lambda e: {"history": hist.to_dict(), **dict(checkpoint_extra or {})},
        best_extra=checkpoint_extra,
        resume=resume,
        restore=lambda state: hist.load_dict(state["history"]),
        desc=desc,
        progress=progress,
    )
    model.eval()
    return hist
