"""THE training loop, :func:`train_loop`, and the trainers built on it: :func:`fit`
for classifiers on any ``torch.nn.Module``, :func:`epoch_loop` for the task trainers
that draw batches of sample indices, :func:`evaluate`.

:func:`train_loop` is the one loop of :mod:`robopercept.nn` (the detectors',
segmenters', pose, point-cloud and lifting trainers run their epochs through it): a
trainer gives its batches and its loss; the loop owns the optimizer step (non-finite
losses refused, gradient clipping, per-batch or per-epoch schedules), weight averaging,
validation every k epochs with the best epoch kept, early stopping, progress,
checkpoints after every epoch and resuming from them, and determinism.

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
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

from robopercept._checks import as_path, check_bool, plain_repr
from robopercept.errors import FileFormatError, InputError
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
    "LoopResult",
    "epoch_loop",
    "evaluate",
    "fit",
    "optimizer_step",
    "step_optimizer",
    "train_loop",
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
    (:func:`fit`, :func:`epoch_loop`,
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
        ``resume`` from a file that is not such a checkpoint, or of another model.
    """
    model = check_module(model)
    epochs = check_count(epochs, "epochs", 1, 1 << 30)
    val_every = check_count(val_every, "val_every", 1, 1 << 30)
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
        state = load_checkpoint(ckpt)
        if "epochs_done" not in state or "optimizer" not in state:
            raise FileFormatError(
                f"{ckpt}: not a checkpoint of a training run that can be resumed (no "
                "optimizer state): start a new run"
            )
        if averaged is not None:
            if "averaged" not in state:
                raise FileFormatError(
                    f"{ckpt}: the run kept no weight average; resume it without one"
                )
            model.load_state_dict(state["trained_model"])
            averaged.load_state_dict(state["averaged"])
        else:
            load_checkpoint(ckpt, model)
        optimizer.load_state_dict(state["optimizer"])
        if schedule is not None and state.get("scheduler") is not None:
            schedule.load_state_dict(state["scheduler"])
        for name, g in gens.items():
            g.set_state(state["generators"][name])
        torch.set_rng_state(state["torch_rng_state"])
        start = int(state["epochs_done"])
        result = LoopResult(
            start,
            int(state["best_epoch"]),
            float(state["best_score"]),
            str(state.get("stopped", "")),
        )
        if validate is not None and best_path is not None and best_path.exists():
            best_state = load_checkpoint(best_path)["model"]
        if restore is not None:
            restore(state)
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
    ``generator`` in batches of ``cfg.batch_size``, ``batch(indices)`` giving each
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

    def batches(epoch: int) -> Iterator[torch.Tensor]:
        order = torch.randperm(n, generator=generator)
        for b in range(steps):
            yield order[b * cfg.batch_size : (b + 1) * cfg.batch_size]

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

    def restore(state: dict[str, Any]) -> None:
        saved = state["history"]
        hist.losses[:] = list(saved["losses"])
        hist.seconds[:] = list(saved["seconds"])
        hist.val.clear()
        hist.val.update({int(k): float(v) for k, v in saved[hist.val_name].items()})
        hist.best_epoch = int(saved["best_epoch"])

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
        restore=restore,
        desc=desc,
        progress=progress,
    )
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
    sign = -1.0 if cfg.monitor == "val_accuracy" else 1.0
    figures = [0.0, 0.0, 0.0]  # loss sum, correct, count of the epoch

    def unfreeze(epoch: int) -> None:
        for prefix in (cfg.unfreeze_at or {}).get(epoch + 1, []):
            for name, param in model.named_parameters():
                if name.startswith(prefix):
                    param.requires_grad_(True)
        if sampler is not None:
            sampler.set_epoch(epoch)
        hist.lr.append(float(opt.param_groups[0]["lr"]))

    def step(xy: Any, epoch: int, b: int) -> torch.Tensor:
        x, y = xy[0].to(dev, torch.float32), xy[1].to(dev, torch.long)
        _check_batch(x, y, n_classes)
        with _autocast(dev, cfg.amp):
            logits = net(x)
            loss = nn.functional.cross_entropy(logits.float(), y)
        if bool(torch.isfinite(loss)):
            figures[0] += loss.item() * len(y)
            figures[1] += int((logits.argmax(1) == y).sum())
            figures[2] += len(y)
        return loss

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
        for f in fields(History):
            setattr(hist, f.name, getattr(saved, f.name))
        done = int(state["epochs_done"])
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
    return hist
