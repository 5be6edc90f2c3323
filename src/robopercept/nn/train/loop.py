"""THE training loop: :func:`fit` for classifiers on any ``torch.nn.Module``,
:func:`epoch_loop` for the per-batch trainers of the task wings, :func:`evaluate`.

:func:`fit` runs the loop the notes teach: mini-batches of the training set (shuffled
by a seeded generator), cross-entropy loss, back-propagation, an optimizer step (SGD
with momentum, optionally Nesterov, and weight decay; or AdamW), a learning-rate
schedule (constant, step, cosine or one-cycle), gradient clipping, evaluation on the
validation set after every epoch, early stopping when the monitored figure has not
improved for ``patience`` epochs, and the best epoch's weights restored at the end.
Mixed precision is used only on CUDA (``amp="auto"``).

Optimizers and schedules are PyTorch's own (:mod:`torch.optim`,
:mod:`torch.optim.lr_scheduler`): they are not perception methods. A run is
deterministic on the CPU: the same seed and thread count give bit-identical weights
(:func:`~robopercept.nn.train.config.deterministic_algorithms` during the run), and a
run resumed from its checkpoint ends where an uninterrupted one does (the checkpoint,
:mod:`robopercept.nn.train.checkpoint`, holds the model, the optimizer, the schedule,
the shuffling generator and torch's random state), written after every epoch.
"""

from __future__ import annotations

import contextlib
import copy
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

from robopercept._checks import as_path, check_bool, plain_repr
from robopercept.errors import InputError
from robopercept.learning.metrics import confusion_matrix
from robopercept.nn._guards import check_count, check_dataset, check_module
from robopercept.nn.train.checkpoint import load_checkpoint, save_checkpoint
from robopercept.nn.train.config import (
    History,
    TrainConfig,
    deterministic_algorithms,
    resolve_device,
)
from robopercept.progress import progress_bar

__all__ = [
    "EpochHistory",
    "Evaluation",
    "epoch_loop",
    "evaluate",
    "fit",
    "optimizer_step",
    "step_optimizer",
]


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


def step_optimizer(
    params: list[nn.Parameter], cfg: TrainConfig, steps_per_epoch: int
) -> tuple[torch.optim.Optimizer, Any]:
    """The optimizer and a learning-rate schedule stepped after every batch (not every
    epoch, as :func:`fit`'s), for loops that step per batch: the detectors' and the
    segmenters'.

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
) -> EpochHistory:
    """The per-batch training loop of the task trainers (pose networks, point-cloud
    networks): per epoch a shuffle of the ``n`` samples by ``generator`` in batches of
    ``cfg.batch_size``, ``batch(indices)`` giving each batch's loss, one optimizer step
    per batch (:func:`step_optimizer`'s optimizer and per-step schedule,
    :func:`optimizer_step`'s checks), then ``validate()`` (higher is better) and the
    best epoch's weights kept (the last epoch's without ``validate``). Runs under
    :func:`deterministic_algorithms`; the model is left in eval mode.

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

    Returns
    -------
    EpochHistory

    Raises
    ------
    InputError
        A loss became NaN or infinite (lower the learning rate).
    """
    model = check_module(model)
    n = check_count(n, "n (training samples)", 1, 1 << 40)
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
    params = [p for p in model.parameters() if p.requires_grad]
    opt, sched = step_optimizer(params, cfg, steps)
    hist = EpochHistory() if history is None else history
    best: dict[str, torch.Tensor] | None = None
    best_value = -math.inf
    bar = progress_bar(total=cfg.epochs, desc=desc, unit="epoch", disable=not progress)
    try:
        with deterministic_algorithms():
            for epoch in range(cfg.epochs):
                t0 = time.perf_counter()
                model.train()
                order = torch.randperm(n, generator=generator)
                total = 0.0
                for b in range(steps):
                    value = batch(order[b * cfg.batch_size : (b + 1) * cfg.batch_size])
                    optimizer_step(value, opt, sched, params, cfg, f"epoch {epoch + 1}")
                    total += float(value.detach())
                hist.losses.append(total / steps)
                hist.seconds.append(time.perf_counter() - t0)
                if validate is not None:
                    score = float(validate())
                    hist.val[epoch + 1] = score
                    if best is None or score > best_value:
                        best_value, hist.best_epoch = score, epoch + 1
                        best = copy.deepcopy(model.state_dict())
                else:
                    hist.best_epoch = epoch + 1
                bar.update(1)
                post = {"loss": f"{hist.losses[-1]:.4g}"}
                if hist.val:
                    post[hist.val_name] = f"{hist.val[epoch + 1]:.3f}"
                bar.set_postfix(**post)
    finally:
        bar.close()
    if best is not None:
        model.load_state_dict(best)
    model.eval()
    return hist


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


def fit(
    model: nn.Module,
    train: Dataset[Any],
    val: Dataset[Any] | None = None,
    config: TrainConfig | None = None,
    *,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
    architecture: str = "",
    progress: bool = True,
    distributed: bool = False,
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
        Continue from ``checkpoint`` (ends as the uninterrupted run would).
    architecture : str
        Recorded in the checkpoint (named when loading into the wrong model).
    progress : bool
        A bar per epoch on stderr (:func:`robopercept.progress.progress_bar`).
    distributed : bool
        This process is one rank of a data-parallel run (a ``torch.distributed`` process
        group is initialized; :mod:`robopercept.nn.train.distributed` sets it up): the model is
        wrapped in :class:`~torch.nn.parallel.DistributedDataParallel` (gradients
        averaged over the ranks), each rank draws its shard of the training set through
        a :class:`~torch.utils.data.DistributedSampler` (shuffled with ``config.seed``,
        ``set_epoch`` every epoch) in batches of ``batch_size / world_size``, so the
        global batch and the learning rate are those of one process; the training
        figures are summed over the ranks, rank 0 validates and sends its figures to the
        others (one early-stopping decision), and only rank 0 writes checkpoints and
        shows the progress bar. False (the default): the single-process loop, unchanged.

    Returns
    -------
    History

    Raises
    ------
    InputError
        Empty dataset, images not (C, H, W), labels out of range, or a loss that became
        NaN or infinite (lower the learning rate); ``distributed`` without a process
        group, or a batch size that the number of processes does not divide.
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
    if resume and checkpoint is None:
        raise InputError("resume needs the checkpoint to resume from")
    distributed = check_bool(distributed, "distributed")
    rank, world = _ranks(cfg) if distributed else (0, 1)
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
    sampler: Any = None
    net: nn.Module = model  # what runs forward and backward: the model or its DDP wrapper
    if distributed:
        from torch.nn.parallel import DistributedDataParallel
        from torch.utils.data import DistributedSampler

        sampler = DistributedSampler(
            train, num_replicas=world, rank=rank, shuffle=True, seed=cfg.seed
        )
        loader = DataLoader(train, batch_size=cfg.batch_size // world, sampler=sampler)
        net = DistributedDataParallel(
            model, device_ids=[dev.index] if dev.type == "cuda" and dev.index is not None else None
        )
        progress = progress and rank == 0
    else:
        loader = DataLoader(train, batch_size=cfg.batch_size, shuffle=True, generator=shuffle)
    opt = _optimizer(model, cfg)
    sched = _scheduler(opt, cfg, len(loader))
    hist = History()
    start_epoch = 0
    best_state: dict[str, torch.Tensor] | None = None
    best_value = math.inf
    ckpt = Path(checkpoint) if checkpoint is not None else None
    best_path = ckpt.with_name(ckpt.stem + ".best.pt") if ckpt is not None else None
    if resume and ckpt is not None:
        state = load_checkpoint(ckpt, model)
        opt.load_state_dict(state["optimizer"])
        sched.load_state_dict(state["scheduler"])
        shuffle.set_state(state["shuffle_state"])
        torch.set_rng_state(state["torch_rng_state"])
        hist = History.from_dict(state["history"])
        start_epoch = int(state["epoch"]) + 1
        for k, prefixes in (cfg.unfreeze_at or {}).items():  # what the run had unfrozen
            if k <= start_epoch:
                for name, param in model.named_parameters():
                    if any(name.startswith(pf) for pf in prefixes):
                        param.requires_grad_(True)
        best_value = float(state["best_value"])
        if best_path is not None and best_path.exists():
            best_state = load_checkpoint(best_path)["model"]
    sign = -1.0 if cfg.monitor == "val_accuracy" else 1.0
    bar = progress_bar(
        total=cfg.epochs - start_epoch, desc="training", unit="epoch", disable=not progress
    )
    try:
        with deterministic_algorithms():
            for epoch in range(start_epoch, cfg.epochs):
                t0 = time.perf_counter()
                for prefix in (cfg.unfreeze_at or {}).get(epoch + 1, []):
                    for name, param in model.named_parameters():
                        if name.startswith(prefix):
                            param.requires_grad_(True)
                model.train()
                if sampler is not None:
                    sampler.set_epoch(epoch)
                lr = float(opt.param_groups[0]["lr"])
                total, correct, count = 0.0, 0, 0
                for b, (x, y) in enumerate(loader):
                    x, y = x.to(dev, torch.float32), y.to(dev, torch.long)
                    _check_batch(x, y, n_classes)
                    with _autocast(dev, cfg.amp):
                        logits = net(x)
                        loss = nn.functional.cross_entropy(logits.float(), y)
                    if not torch.isfinite(loss):
                        raise InputError(
                            f"the loss became {loss.item()} at epoch {epoch + 1}, batch {b + 1}: "
                            f"lower the learning rate (lr {cfg.lr:g})"
                        )
                    opt.zero_grad(set_to_none=True)
                    loss.backward()
                    if cfg.clip_grad_norm is not None:
                        nn.utils.clip_grad_norm_(model.parameters(), cfg.clip_grad_norm)
                    opt.step()
                    if cfg.schedule == "onecycle":
                        sched.step()
                    total += loss.item() * len(y)
                    correct += int((logits.argmax(1) == y).sum())
                    count += len(y)
                if cfg.schedule != "onecycle":
                    sched.step()
                if distributed:
                    summed = _sum_over_ranks([total, correct, count], dev)
                    total, correct, count = summed[0], round(summed[1]), round(summed[2])
                hist.epoch.append(epoch + 1)
                hist.train_loss.append(total / count)
                hist.train_accuracy.append(correct / count)
                if val is not None and distributed:
                    figures = [math.nan, math.nan]
                    if rank == 0:
                        ev = evaluate(
                            model, val, batch_size=max(cfg.batch_size, 256), device=str(dev)
                        )
                        figures = [ev.loss, ev.accuracy]
                    val_loss, val_acc = _from_rank0(figures, dev)
                    hist.val_loss.append(val_loss)
                    hist.val_accuracy.append(val_acc)
                    value = sign * (val_acc if sign < 0 else val_loss)
                elif val is not None:
                    ev = evaluate(model, val, batch_size=max(cfg.batch_size, 256), device=str(dev))
                    hist.val_loss.append(ev.loss)
                    hist.val_accuracy.append(ev.accuracy)
                    value = sign * (ev.accuracy if sign < 0 else ev.loss)
                else:
                    hist.val_loss.append(math.nan)
                    hist.val_accuracy.append(math.nan)
                    value = -float(epoch)  # the last epoch is the best
                hist.lr.append(lr)
                hist.seconds.append(time.perf_counter() - t0)
                if value < best_value:
                    best_value = value
                    hist.best_epoch = epoch + 1
                    best_state = copy.deepcopy(model.state_dict())
                    if best_path is not None and rank == 0:
                        save_checkpoint(
                            best_path, {"model": best_state, "architecture": architecture}
                        )
                if ckpt is not None and rank == 0:
                    save_checkpoint(
                        ckpt,
                        {
                            "model": model.state_dict(),
                            "optimizer": opt.state_dict(),
                            "scheduler": sched.state_dict(),
                            "shuffle_state": shuffle.get_state(),
                            "torch_rng_state": torch.get_rng_state(),
                            "history": hist.to_dict(),
                            "epoch": epoch,
                            "best_value": best_value,
                            "config": asdict(cfg),
                            "architecture": architecture,
                        },
                    )
                bar.update(1)
                bar.set_postfix(
                    loss=f"{hist.train_loss[-1]:.3f}",
                    acc=f"{hist.train_accuracy[-1]:.3f}",
                    val_acc=f"{hist.val_accuracy[-1]:.3f}",
                )
                if (
                    cfg.patience is not None
                    and val is not None
                    and epoch + 1 - hist.best_epoch >= cfg.patience
                ):
                    hist.stopped = f"early stopping: no improvement for {cfg.patience} epochs"
                    break
    except KeyboardInterrupt:
        hist.stopped = "interrupted"
        raise
    finally:
        bar.close()
        if best_state is not None:
            model.load_state_dict(best_state)
    return hist
