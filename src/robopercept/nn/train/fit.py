"""Classifiers trained on any ``torch.nn.Module``: :func:`fit` and :func:`evaluate`.

:func:`fit` runs the loop the notes teach, through the one loop
(:func:`~robopercept.nn.train.loop.train_loop`): mini-batches of the training set
(shuffled by a seeded generator), cross-entropy loss, back-propagation, an optimizer
step (SGD with momentum, optionally Nesterov, and weight decay; or AdamW), a
learning-rate schedule (constant, step, cosine or one-cycle), gradient clipping,
evaluation on the validation set after every epoch, early stopping when the monitored
figure has not improved for ``patience`` epochs, and the best epoch's weights restored
at the end. Mixed precision is used only on CUDA (``amp="auto"``); with
``distributed=True`` one rank of a DistributedDataParallel run. Checkpoints after every
epoch, and ``resume`` ends where an uninterrupted run does.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import reprlib
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

from robopercept._checks import as_path, check_bool
from robopercept.errors import ArgumentError, FileFormatError, InputError
from robopercept.fileio import MAX_NESTING, nesting_depth
from robopercept.learning.metrics import confusion_matrix
from robopercept.nn._guards import check_count, check_dataset, check_module
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import (
    History,
    TrainConfig,
    resolve_device,
)
from robopercept.nn.train.distributed import sync_batchnorm as sync_bn_layers
from robopercept.nn.train.loop import LoopResult, train_loop

__all__ = ["Evaluation", "evaluate", "fit"]


@dataclass
class Evaluation:
    """A model's figures on a dataset.

    Attributes
    ----------
    loss, accuracy : float
    y_true, y_pred : (N,) int ndarray
    probabilities : (N, K) float ndarray
    """

    loss: float
    accuracy: float
    y_true: np.ndarray
    y_pred: np.ndarray
    probabilities: np.ndarray

    def confusion_matrix(self, n_classes: int | None = None) -> np.ndarray:
        """Counts ``[true, predicted]`` (:func:`robopercept.learning.metrics.confusion_matrix`)."""
        k = n_classes or self.probabilities.shape[1]
        return confusion_matrix(self.y_true, self.y_pred, labels=np.arange(k))


def _check_batch(x: torch.Tensor, y: torch.Tensor, n_classes: int) -> None:
    if x.ndim != 4:
        raise InputError(f"images must be (N, C, H, W) batches; got shape {tuple(x.shape)}")
    if y.numel() and (int(y.min()) < 0 or int(y.max()) >= n_classes):
        raise InputError(
            f"labels must be in 0..{n_classes - 1} (the model has {n_classes} outputs); "
            f"got {int(y.min())}..{int(y.max())}"
        )


def _autocast(device: torch.device, amp: bool | str) -> contextlib.AbstractContextManager[Any]:
    use = device.type == "cuda" if amp == "auto" else bool(amp)
    if use and device.type == "cuda":
        return torch.autocast("cuda", dtype=torch.bfloat16)
    return contextlib.nullcontext()


def _n_outputs(model: nn.Module, sample: torch.Tensor, device: torch.device) -> int:
    was = model.training
    model.eval()
    with torch.no_grad():
        out = model(sample[:1].to(device))
    model.train(was)
    if out.ndim != 2:
        raise InputError(f"the model must output (N, classes) logits; got {tuple(out.shape)}")
    return int(out.shape[1])


@torch.no_grad()
def evaluate(
    model: nn.Module,
    data: Dataset[Any],
    *,
    batch_size: int = 256,
    device: str | None = None,
) -> Evaluation:
    """Loss, accuracy and predictions of ``model`` on ``data`` (eval mode, no gradients).

    Parameters
    ----------
    model : torch.nn.Module
        Maps an (N, C, H, W) batch to (N, K) logits.
    data : Dataset
        Items ``(image (C, H, W), label)``.
    batch_size : int
    device : str, optional

    Returns
    -------
    Evaluation
    """
    model = check_module(model)
    data = check_dataset(data, "data")
    batch_size = check_count(batch_size, "batch_size", 1, 2**31)
    dev = resolve_device(device)
    model = model.to(dev)
    was = model.training
    model.eval()
    losses, trues, probs = [], [], []
    for x, y in DataLoader(data, batch_size=batch_size, shuffle=False):
        x, y = x.to(dev, torch.float32), y.to(dev, torch.long)
        logits = model(x).float()
        _check_batch(x, y, logits.shape[1])
        losses.append(nn.functional.cross_entropy(logits, y, reduction="sum").item())
        trues.append(y.cpu().numpy())
        probs.append(torch.softmax(logits, 1).cpu().numpy())
    model.train(was)
    p = np.concatenate(probs)
    t = np.concatenate(trues)
    pred = p.argmax(1)
    return Evaluation(float(sum(losses) / len(t)), float((pred == t).mean()), t, pred, p)


def _optimizer(model: nn.Module, cfg: TrainConfig) -> torch.optim.Optimizer:
    """One parameter group per learning-rate multiplier. Every parameter is given to the
    optimizer, frozen ones too: torch's optimizers skip a parameter without a gradient
    (no step, no weight decay), so unfreezing later needs no new group."""
    named = list(model.named_parameters())
    multipliers = cfg.lr_multipliers or {}
    if not any(p.requires_grad for _, p in named) and not cfg.unfreeze_at:
        raise InputError("the model has no trainable parameters (everything is frozen)")
    groups: dict[float, list[nn.Parameter]] = {}
    for name, param in named:
        keys = [k for k in multipliers if name.startswith(k)]
        mult = multipliers[max(keys, key=len)] if keys else 1.0
        groups.setdefault(float(mult), []).append(param)
    arg = [{"params": ps, "lr": cfg.lr * m} for m, ps in groups.items()]
    if cfg.optimizer == "sgd":
        return torch.optim.SGD(
            arg,
            lr=cfg.lr,
            momentum=cfg.momentum,
            nesterov=cfg.nesterov,
            weight_decay=cfg.weight_decay,
        )
    return torch.optim.AdamW(arg, lr=cfg.lr, weight_decay=cfg.weight_decay)


def _scheduler(opt: torch.optim.Optimizer, cfg: TrainConfig, steps_per_epoch: int) -> Any:
    if cfg.schedule == "step":
        return torch.optim.lr_scheduler.StepLR(opt, step_size=cfg.step_size, gamma=cfg.gamma)
    if cfg.schedule == "cosine":
        return torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=cfg.epochs)
    if cfg.schedule == "onecycle":
        return torch.optim.lr_scheduler.OneCycleLR(
            opt,
            max_lr=[g["lr"] for g in opt.param_groups],
            epochs=cfg.epochs,
            steps_per_epoch=steps_per_epoch,
        )
    return torch.optim.lr_scheduler.LambdaLR(opt, lambda _: 1.0)


def _ranks(cfg: TrainConfig) -> tuple[int, int]:
    """(rank, world size) of the initialized process group; the batch size checked."""
    import torch.distributed as dist

    if not (dist.is_available() and dist.is_initialized()):
        raise InputError(
            "distributed=True needs an initialized torch.distributed process group: run "
            "through robopercept.nn.train.distributed (nn train --nproc N, or torchrun)"
        )
    rank, world = dist.get_rank(), dist.get_world_size()
    if cfg.unfreeze_at:
        raise InputError(
            "unfreeze_at is not supported with distributed=True (DistributedDataParallel "
            "fixes the trainable parameters when it wraps the model): train on one process"
        )
    if cfg.batch_size % world:
        raise InputError(
            f"--batch-size {cfg.batch_size} is the global batch; it must be a multiple of the "
            f"{world} processes (--nproc): choose e.g. --batch-size "
            f"{max(world, cfg.batch_size - cfg.batch_size % world)}"
        )
    return rank, world


def _sum_over_ranks(values: list[float], dev: torch.device) -> list[float]:
    import torch.distributed as dist

    t = torch.tensor(values, dtype=torch.float64, device=dev)
    dist.all_reduce(t)
    return [float(v) for v in t.cpu()]


def _from_rank0(values: list[float], dev: torch.device) -> list[float]:
    import torch.distributed as dist

    t = torch.tensor(values, dtype=torch.float64, device=dev)
    dist.broadcast(t, 0)
    return [float(v) for v in t.cpu()]


#: the ``nn train`` flag of each :class:`TrainConfig` field that has one
_FLAGS = {
    "epochs": "--epochs",
    "batch_size": "--batch-size",
    "optimizer": "--optimizer",
    "lr": "--lr",
    "schedule": "--schedule",
    "patience": "--patience",
    "seed": "--seed",
    "device": "--device",
}


def _check_run_options(options: Any) -> dict[str, Any]:
    """``run_options`` as a plain dict of str to JSON values (``{}`` for None)."""
    if options is None:
        return {}
    bad = InputError(
        "run_options must be a dict of option names (str) to JSON values, e.g. "
        f"{{'--data': 'digits'}}; got {reprlib.repr(options)}"
    )
    if not isinstance(options, Mapping) or not all(isinstance(k, str) for k in options):
        raise bad
    if nesting_depth(options) > MAX_NESTING:
        raise bad
    try:
        plain = json.loads(json.dumps(dict(options), allow_nan=False))
    except (TypeError, ValueError):
        raise bad from None
    return dict(plain)


def _same(saved: Any, now: Any) -> bool:
    """``saved`` (read from a checkpoint: anything) equals the JSON value ``now``."""
    try:
        return bool(json.dumps(saved, sort_keys=True) == json.dumps(now, sort_keys=True))
    except (TypeError, ValueError, RecursionError):
        return False


def _check_resume(
    checkpoint: Path, cfg: TrainConfig, architecture: str, options: dict[str, Any]
) -> None:
    """Refuse to resume the run of ``checkpoint`` under other options (``fit``'s
    ``resume``): ArgumentError naming every difference and ``--overwrite``."""
    state = load_checkpoint(checkpoint)
    saved_cfg = state.get("config")
    if not isinstance(saved_cfg, dict) or not all(isinstance(k, str) for k in saved_cfg):
        raise FileFormatError(
            f"{checkpoint}: its 'config' entry is damaged (not a configuration): start "
            "afresh with --overwrite"
        )
    now = json.loads(json.dumps(asdict(cfg), default=str))
    diffs: list[str] = []
    for name, value in now.items():
        if name == "device":
            continue
        if name == "epochs" and cfg.schedule != "onecycle":
            continue
        if name not in saved_cfg or _same(saved_cfg[name], value):
            continue
        flag = _FLAGS.get(name, name)
        note = ""
        if name == "epochs":
            note = "; a one-cycle schedule spans the run's epochs: it cannot be extended"
        diffs.append(f"{flag} ({reprlib.repr(saved_cfg[name])} in the run, {value!r} now{note})")
    saved_options = state.get("run_options")
    if saved_options is not None:
        if not isinstance(saved_options, dict):
            raise FileFormatError(
                f"{checkpoint}: its 'run_options' entry is damaged (not a dict): start "
                "afresh with --overwrite"
            )
        for name, value in options.items():
            if name not in saved_options:
                diffs.append(f"{name} (not recorded in the run, {value!r} now)")
            elif not _same(saved_options[name], value):
                diffs.append(
                    f"{name} ({reprlib.repr(saved_options[name])} in the run, {value!r} now)"
                )
    saved_arch = state.get("architecture", "")
    if not diffs and architecture and not _same(saved_arch, architecture):
        diffs.append(
            "the model (its architecture: the data's classes or image size, or the "
            "model's settings, differ from the run's)"
        )
    if diffs:
        raise ArgumentError(
            f"--resume continues the run in {checkpoint.parent} with the options it was "
            f"started with; these differ: {'; '.join(diffs)}. Give the run's values to "
            "resume it, or start afresh with --overwrite"
        )


def fit(
    model: nn.Module,
    train: Dataset[Any],
    val: Dataset[Any] | None = None,
    config: TrainConfig | None = None,
    *,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
    architecture: str = "",
    run_options: Mapping[str, Any] | None = None,
    progress: bool = True,
    distributed: bool = False,
    sync_batchnorm: bool = True,
) -> History:
    """Train ``model`` on ``train`` (items ``(image (C, H, W), label)``), validating on
    ``val`` after each epoch; return the :class:`History`.

    Parameters
    ----------
    model : torch.nn.Module
        Logits ``(N, K)`` for an ``(N, C, H, W)`` batch. Trained in place; at the end it
        holds the best epoch's weights (by ``config.monitor``; the last epoch's without
        ``val``).
    train, val : Dataset
    config : TrainConfig, optional
    checkpoint : path, optional
        Written after every epoch (model, optimizer, schedule, random states, history,
        config, ``architecture``); the best weights go to ``<name>.best.pt`` beside it.
    resume : bool
        Continue from ``checkpoint`` (ends as the uninterrupted run would). The run must
        go on as it was started: the checkpoint's configuration must equal ``config`` in
        every field but ``device`` (where to train may change) and ``epochs`` (more
        epochs extend a run, except under the ``"onecycle"`` schedule, whose steps are
        fixed when it starts; a ``"cosine"`` schedule keeps the period of the epochs it
        was made for, so past them its learning rate rises again), and
        its ``architecture`` and ``run_options`` must equal these; otherwise
        :class:`~robopercept.errors.ArgumentError` names every difference (by the
        ``nn train`` flag where there is one) and ``--overwrite``.
    architecture : str
        Recorded in the checkpoint (named when loading into the wrong model).
    run_options : dict of str to JSON values, optional
        The caller's options that define the run (keys as the user knows them, e.g.
        ``"--data"``), recorded in the checkpoint and compared on ``resume``.
    progress : bool
        A bar per epoch on stderr (:func:`robopercept.progress.progress_bar`).
    distributed : bool
        This process is one rank of a data-parallel run (a ``torch.distributed`` process
        group is initialized; :mod:`robopercept.nn.train.distributed` sets it up): the model is
        wrapped in :class:`~torch.nn.parallel.DistributedDataParallel` (gradients
        averaged over the ranks); every rank draws the global batches of one process
        (the same seeded shuffle, so every image is seen once per epoch, none repeated)
        and runs its contiguous share of each (a last batch that does not divide evenly
        gives some ranks one image fewer, their loss weighed by their share), so the
        gradient, the global batch and the learning rate are those of one process; the
        training figures are summed over the ranks, rank 0 validates and sends its
        figures to the others (one early-stopping decision), and only rank 0 writes
        checkpoints and shows the progress bar. False (the default): the single-process
        loop, unchanged.
    sync_batchnorm : bool
        With ``distributed``: batch norm takes the statistics of the whole global batch
        (:class:`~robopercept.nn.train.distributed.SyncBatchNorm`, swapped in for the
        run and back after), so 2 processes train the model 1 process would; False keeps
        each process's own statistics (``nn train --per-process-bn``).

    Returns
    -------
    History

    Raises
    ------
    InputError
        Empty dataset, images not (C, H, W), labels out of range, or a loss that became
        NaN or infinite (lower the learning rate); ``distributed`` without a process
        group, or a batch size that the number of processes does not divide.
    ArgumentError
        ``resume`` with other options than the run's (see ``resume``).
    FileFormatError
        ``resume`` from a damaged checkpoint (the message names the entry).
    """
    model = check_module(model)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(
            f"config must be a TrainConfig (e.g. TrainConfig(epochs=10)) or None; got {config!r}"
        )
    cfg = config or TrainConfig()
    train = check_dataset(train, "the training set")
    if val is not None:
        val = check_dataset(val, "the validation set")
    if checkpoint is not None:
        checkpoint = as_path(checkpoint, "checkpoint")
    resume = check_bool(resume, "resume")
    if not isinstance(architecture, str):
        raise InputError(f"architecture must be a str; got {architecture!r}")
    options = _check_run_options(run_options)
    if resume and checkpoint is None:
        raise InputError("resume needs the checkpoint to resume from")
    distributed = check_bool(distributed, "distributed")
    sync_batchnorm = check_bool(sync_batchnorm, "sync_batchnorm")
    rank, world = _ranks(cfg) if distributed else (0, 1)
    if resume and checkpoint is not None:
        _check_resume(checkpoint, cfg, architecture, options)
    dev = resolve_device(cfg.device)
    # one process and rank 0 draw as before; the other ranks' dropout differs from rank 0's
    torch.manual_seed(cfg.seed if rank == 0 else (cfg.seed + rank) % 2**64)
    model.to(dev)
    x0, _ = train[0]
    if torch.as_tensor(x0).ndim != 3:
        raise InputError(
            f"training images must be (C, H, W) tensors (channels first); got shape "
            f"{tuple(torch.as_tensor(x0).shape)}"
        )
    n_classes = _n_outputs(model, torch.as_tensor(x0)[None].float(), dev)
    shuffle = torch.Generator().manual_seed(cfg.seed)
    net: nn.Module = model  # what runs forward and backward: the model or its DDP wrapper
    # every process draws the same global batches as one process would (the same
    # seeded shuffle) and runs its contiguous share of each: every image once per epoch
    loader = DataLoader(train, batch_size=cfg.batch_size, shuffle=True, generator=shuffle)
    undo_sync: Callable[[], None] | None = None
    if distributed:
        from torch.nn.parallel import DistributedDataParallel

        if sync_batchnorm:
            undo_sync = sync_bn_layers(model)
        net = DistributedDataParallel(
            model, device_ids=[dev.index] if dev.type == "cuda" and dev.index is not None else None
        )
        progress = progress and rank == 0
    opt = _optimizer(model, cfg)
    sched = _scheduler(opt, cfg, len(loader))
    hist = History()
    sign = -1.0 if cfg.monitor == "val_accuracy" else 1.0
    figures = [0.0, 0.0, 0.0]  # loss sum, correct, count of the epoch

    def unfreeze(epoch: int) -> None:
        for prefix in (cfg.unfreeze_at or {}).get(epoch + 1, []):
            for name, param in model.named_parameters():
                if name.startswith(prefix):
                    param.requires_grad_(True)
        hist.lr.append(float(opt.param_groups[0]["lr"]))

    def step(xy: Any, epoch: int, b: int) -> torch.Tensor:
        x, y = xy[0].to(dev, torch.float32), xy[1].to(dev, torch.long)
        _check_batch(x, y, n_classes)
        weight = 1.0
        if distributed:  # this rank's share; DDP averages, so weigh by the share's size
            n_global = len(y)
            share = torch.tensor_split(torch.arange(n_global), world)[rank]
            x, y = x[share], y[share]
            weight = len(y) * world / n_global
        with _autocast(dev, cfg.amp):
            logits = net(x)
            if len(y):
                loss = nn.functional.cross_entropy(logits.float(), y)
            else:  # a last batch smaller than the world: this rank only joins the sums
                loss = logits.float().sum() * 0.0
        if bool(torch.isfinite(loss)):
            figures[0] += loss.item() * len(y)
            figures[1] += int((logits.argmax(1) == y).sum())
            figures[2] += len(y)
        return loss * weight if distributed else loss

    def end_epoch(epoch: int, seconds: float) -> None:
        total, correct, count = figures
        if distributed:
            summed = _sum_over_ranks([total, correct, count], dev)
            total, correct, count = summed[0], round(summed[1]), round(summed[2])
        hist.epoch.append(epoch + 1)
        hist.train_loss.append(total / count)
        hist.train_accuracy.append(correct / count)
        figures[:] = [0.0, 0.0, 0.0]
        if val is None:
            hist.val_loss.append(math.nan)
            hist.val_accuracy.append(math.nan)

    def validate(epoch: int) -> float:  # higher is better: -sign * the monitored figure
        assert val is not None
        if distributed:
            both = [math.nan, math.nan]
            if rank == 0:
                ev = evaluate(model, val, batch_size=max(cfg.batch_size, 256), device=str(dev))
                both = [ev.loss, ev.accuracy]
            val_loss, val_acc = _from_rank0(both, dev)
        else:
            ev = evaluate(model, val, batch_size=max(cfg.batch_size, 256), device=str(dev))
            val_loss, val_acc = ev.loss, ev.accuracy
        hist.val_loss.append(val_loss)
        hist.val_accuracy.append(val_acc)
        return -sign * (val_acc if sign < 0 else val_loss)

    def after_epoch(epoch: int, res: LoopResult, seconds: float) -> dict[str, str]:
        hist.seconds.append(seconds)
        hist.best_epoch = res.best_epoch
        hist.stopped = res.stopped
        return {
            "loss": f"{hist.train_loss[-1]:.3f}",
            "acc": f"{hist.train_accuracy[-1]:.3f}",
            "val_acc": f"{hist.val_accuracy[-1]:.3f}",
        }

    def restore(state: dict[str, Any]) -> None:
        saved = History.from_dict(state["history"])
        done = int(state["epochs_done"])
        if len(saved.epoch) != done:
            raise ValueError(f"{len(saved.epoch)} epochs recorded, {done} done")
        for f in fields(History):
            setattr(hist, f.name, getattr(saved, f.name))
        for k, prefixes in (cfg.unfreeze_at or {}).items():  # what the run had unfrozen
            if k <= done:
                for name, param in model.named_parameters():
                    if any(name.startswith(pf) for pf in prefixes):
                        param.requires_grad_(True)

    try:
        train_loop(
            model,
            opt,
            lambda epoch: loader,
            step,
            epochs=cfg.epochs,
            schedule=sched,
            schedule_per_batch=cfg.schedule == "onecycle",
            clip_grad_norm=cfg.clip_grad_norm,
            lr=cfg.lr,
            before_epoch=unfreeze,
            end_epoch=end_epoch,
            validate=validate if val is not None else None,
            after_epoch=after_epoch,
            patience=cfg.patience,
            generators={"shuffle": shuffle},
            checkpoint=checkpoint,
            checkpoint_extra=lambda epoch: {
                "history": hist.to_dict(),
                "epoch": epoch,
                "config": asdict(cfg),
                "architecture": architecture,
                "run_options": options,
            },
            best_extra={"architecture": architecture},
            resume=resume,
            restore=restore,
            write=rank == 0,
            desc="training",
            progress=progress,
        )
    except KeyboardInterrupt:
        hist.stopped = "interrupted"
        raise
    finally:
        if undo_sync is not None:
            undo_sync()
    return hist
