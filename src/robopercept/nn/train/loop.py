"""Training a classifier: the course's steps spelled out, on any ``torch.nn.Module``.

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
(``torch.use_deterministic_algorithms`` during the run), and a run resumed from its
checkpoint ends where an uninterrupted one does (the checkpoint holds the model, the
optimizer, the schedule, the shuffling generator and torch's random state).

Checkpoints are ``torch.save`` dictionaries of tensors and plain Python values, read back
with ``weights_only=True`` (no pickled code), written atomically after every epoch, so
Ctrl-C leaves the last complete one readable.
"""

from __future__ import annotations

import contextlib
import copy
import csv
import math
import os
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset

from robopercept._checks import (
    as_path,
    check_bool,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_real,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import atomic_path
from robopercept.nn._guards import (
    check_count,
    check_dataset,
    check_device,
    check_module,
)

__all__ = [
    "EpochHistory",
    "Evaluation",
    "History",
    "Normalize",
    "TrainConfig",
    "deterministic_algorithms",
    "epoch_loop",
    "evaluate",
    "fit",
    "load_built_model",
    "load_checkpoint",
    "optimizer_step",
    "resolve_device",
    "save_built_model",
    "save_checkpoint",
    "step_optimizer",
]

#: the most epochs (and the largest step size or patience) a run may ask for
MAX_EPOCHS = 100_000

Optimizer = Literal["sgd", "adamw"]
Schedule = Literal["constant", "step", "cosine", "onecycle"]


@dataclass
class TrainConfig:
    """How :func:`fit` trains.

    Attributes
    ----------
    epochs : int
        Most epochs (early stopping may end sooner).
    batch_size : int
    optimizer : {"sgd", "adamw"}
        SGD with ``momentum`` (``nesterov``) and L2 ``weight_decay``, or AdamW
        (decoupled weight decay).
    lr : float
        Learning rate (the peak for ``"onecycle"``).
    momentum, nesterov, weight_decay
        As in :class:`torch.optim.SGD` / :class:`torch.optim.AdamW`.
    schedule : {"constant", "step", "cosine", "onecycle"}
        ``"step"``: lr x ``gamma`` every ``step_size`` epochs
        (:class:`~torch.optim.lr_scheduler.StepLR`); ``"cosine"``: cosine annealing to 0
        over ``epochs`` (:class:`~torch.optim.lr_scheduler.CosineAnnealingLR`);
        ``"onecycle"``: warm-up then annealing, stepped per batch
        (:class:`~torch.optim.lr_scheduler.OneCycleLR`).
    step_size, gamma
        The step schedule.
    patience : int or None
        Stop after this many epochs without improvement of ``monitor`` (None: never).
    monitor : {"val_loss", "val_accuracy"}
        The figure that picks the best epoch (lower loss, higher accuracy).
    clip_grad_norm : float or None
        Clip the gradients' global L2 norm to this.
    amp : {"auto", True, False}
        Mixed precision (bfloat16 autocast); "auto" uses it on CUDA only.
    seed : int
        Seeds the initial weights' random state, the shuffling and dropout.
    device : str or None
        ``"cpu"``, ``"cuda"``, ...; None: CUDA when available, else the CPU.
    lr_multipliers : dict of str to float, optional
        Discriminative learning rates: parameters whose qualified name starts with a
        key train at ``lr`` times its value (the longest matching key wins), e.g.
        ``{"features": 0.1}`` for a pretrained trunk under a new head.
    unfreeze_at : dict of int to list of str, optional
        At the start of epoch ``k`` (1-based), make the parameters under these name
        prefixes trainable (``[""]``: all): gradual unfreezing.
    """

    epochs: int = 30
    batch_size: int = 64
    optimizer: Optimizer = "adamw"
    lr: float = 1e-3
    momentum: float = 0.9
    nesterov: bool = False
    weight_decay: float = 1e-4
    schedule: Schedule = "cosine"
    step_size: int = 10
    gamma: float = 0.1
    patience: int | None = 10
    monitor: Literal["val_loss", "val_accuracy"] = "val_accuracy"
    clip_grad_norm: float | None = None
    amp: bool | Literal["auto"] = "auto"
    seed: int = 0
    device: str | None = None
    lr_multipliers: dict[str, float] | None = None
    unfreeze_at: dict[int, list[str]] | None = None

    def __post_init__(self) -> None:
        self.epochs = check_count(self.epochs, "epochs (--epochs)", 1, MAX_EPOCHS)
        self.batch_size = check_count(self.batch_size, "batch_size (--batch-size)", 1, 2**31)
        self.step_size = check_count(self.step_size, "step_size", 1, MAX_EPOCHS)
        self.lr = check_real(self.lr, "lr (the learning rate, --lr)", 0.0, low_inclusive=False)
        self.momentum = check_real(self.momentum, "momentum", 0.0, 1.0)
        self.nesterov = check_bool(self.nesterov, "nesterov")
        self.weight_decay = check_real(self.weight_decay, "weight_decay", 0.0)
        self.gamma = check_real(self.gamma, "gamma", 0.0, low_inclusive=False)
        if self.clip_grad_norm is not None:
            self.clip_grad_norm = check_real(
                self.clip_grad_norm, "clip_grad_norm", 0.0, low_inclusive=False
            )
        if not (self.amp == "auto" and isinstance(self.amp, str)):
            self.amp = check_bool(self.amp, "amp ('auto', True or False)")
        self.seed = check_int(self.seed, "seed (--seed)", -(2**63))
        if self.seed >= 2**64:
            raise InputError(f"seed (--seed) must be below 2**64; got {self.seed}")
        dev = check_device(self.device, "device (--device)")
        self.device = None if dev is None else str(dev)
        if self.lr_multipliers is None:
            self.lr_multipliers = {}
        if self.unfreeze_at is None:
            self.unfreeze_at = {}
        if not isinstance(self.lr_multipliers, dict) or not all(
            isinstance(k, str) for k in self.lr_multipliers
        ):
            raise InputError(
                "lr_multipliers must be a dict of parameter-name prefix to factor, e.g. "
                f"{{'features': 0.1}}; got {self.lr_multipliers!r}"
            )
        self.lr_multipliers = {
            k: check_real(v, f"lr_multipliers[{k!r}]", 0.0) for k, v in self.lr_multipliers.items()
        }
        if not isinstance(self.unfreeze_at, dict) or not all(
            isinstance(v, (list, tuple)) and all(isinstance(pf, str) for pf in v)
            for v in self.unfreeze_at.values()
        ):
            raise InputError(
                "unfreeze_at must be a dict of epoch to a list of parameter-name prefixes, "
                f"e.g. {{5: ['features.2']}}; got {self.unfreeze_at!r}"
            )
        self.unfreeze_at = {
            check_int(k, "unfreeze_at epoch", 1): list(v) for k, v in self.unfreeze_at.items()
        }
        if self.optimizer not in ("sgd", "adamw"):
            raise InputError(f"optimizer must be 'sgd' or 'adamw'; got {self.optimizer!r}")
        if self.schedule not in ("constant", "step", "cosine", "onecycle"):
            raise InputError(
                "schedule must be 'constant', 'step', 'cosine' or 'onecycle'; "
                f"got {self.schedule!r}"
            )
        if self.monitor not in ("val_loss", "val_accuracy"):
            raise InputError(f"monitor must be 'val_loss' or 'val_accuracy'; got {self.monitor!r}")
        if self.patience is not None:
            self.patience = check_count(self.patience, "patience (or None)", 1, MAX_EPOCHS)


@dataclass
class History:
    """Per-epoch figures of a run (``val_*`` are NaN without a validation set)."""

    epoch: list[int] = field(default_factory=list)
    train_loss: list[float] = field(default_factory=list)
    train_accuracy: list[float] = field(default_factory=list)
    val_loss: list[float] = field(default_factory=list)
    val_accuracy: list[float] = field(default_factory=list)
    lr: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    best_epoch: int = -1
    stopped: str = ""

    _COLUMNS = (
        "epoch",
        "train_loss",
        "train_accuracy",
        "val_loss",
        "val_accuracy",
        "lr",
        "seconds",
    )

    def to_dict(self) -> dict[str, Any]:
        """Plain lists and values (JSON- and checkpoint-ready)."""
        return {k: v for k, v in asdict(self).items() if not k.startswith("_")}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> History:
        """The inverse of :meth:`to_dict`."""
        return cls(
            **{k: d[k] for k in cls.__dataclass_fields__ if not k.startswith("_") and k in d}
        )

    def write_csv(self, path: str | os.PathLike[str]) -> Path:
        """One row per epoch: the columns of the class."""
        p = Path(path)
        with p.open("w", newline="") as f:
            w = csv.writer(f)
            w.writerow(self._COLUMNS)
            for row in zip(*(getattr(self, c) for c in self._COLUMNS), strict=True):
                w.writerow([f"{v:.6g}" if isinstance(v, float) else v for v in row])
        return p

    def picture(self) -> np.ndarray:
        """Loss, accuracy and learning rate against the epoch, as an (H, W, 3) uint8
        image (:func:`robopercept.viz.plot.plot_series`), readable at 1080p."""
        from robopercept.viz.plot import Panel, Series, plot_series

        x = np.asarray(self.epoch, float)
        blue, orange, green = (31, 119, 180), (255, 127, 14), (44, 160, 44)

        def curves(name: str) -> list[Series]:
            out = [Series(x, np.asarray(getattr(self, f"train_{name}"), float), "train", blue)]
            val = np.asarray(getattr(self, f"val_{name}"), float)
            if np.isfinite(val).any():
                out.append(Series(x, val, "validation", orange))
            return out

        panels = [
            Panel("loss (cross-entropy)", curves("loss"), "loss"),
            Panel("accuracy", curves("accuracy"), "accuracy [0-1]"),
            Panel(
                "learning rate",
                [Series(x, np.asarray(self.lr, float), "lr", green)],
                "learning rate",
            ),
        ]
        return plot_series(panels, width=1200, panel_height=260, xlabel="epoch")


def _statistics(value: Any, name: str) -> np.ndarray:
    """``value`` (a number or a (C,) sequence) as finite float32 ``(C,)`` statistics."""
    arr = check_ndim(value, name, (0, 1))
    if arr.dtype.kind not in "iuf" or arr.size == 0:
        raise InputError(
            f"{name} must be real numbers, one per channel (e.g. [0.5]); got {value!r}"
        )
    arr = check_finite(arr.astype(np.float64), name)
    # float32 buffers: beyond 1e30 the statistics (and 1/std) leave float32's range
    arr = check_magnitude(arr, name, 1e30, smallest=None)
    if name == "std" and np.any((arr > 0) & (arr < 1e-30)):
        raise InputError(f"std must be >= 1e-30 in every channel (float32); got {value!r}")
    return np.atleast_1d(arr.astype(np.float32))


class Normalize(nn.Module):
    """``(x - mean_c) / std_c`` per channel, with the statistics as buffers (saved in the
    checkpoint, moved with the model, exported to ONNX): put it first in a model, with
    statistics of the training split only
    (:func:`~robopercept.nn.data.datasets.normalization_stats`). Also usable as a dataset
    transform: takes ``(C, H, W)`` images as well as ``(N, C, H, W)`` batches.

    Parameters
    ----------
    mean, std : (C,) array
        Per-channel statistics; ``std`` > 0.
    """

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, mean: Any, std: Any) -> None:
        super().__init__()
        m, s = (_statistics(v, n) for v, n in ((mean, "mean"), (std, "std")))
        if m.shape != s.shape or m.ndim != 1:
            raise InputError(
                f"mean and std must be (C,) of one length; got {m.shape} and {s.shape}"
            )
        if np.any(s <= 0):
            raise InputError(
                "std must be > 0 in every channel: a constant channel cannot be normalized"
            )
        self.register_buffer("mean", torch.from_numpy(m).view(1, -1, 1, 1))
        self.register_buffer("std", torch.from_numpy(s).view(1, -1, 1, 1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Normalize ``(C, H, W)`` or ``(N, C, H, W)``."""
        if not isinstance(x, torch.Tensor) or not x.is_floating_point():
            raise InputError(
                "Normalize takes a floating-point torch tensor (C, H, W) or (N, C, H, W); "
                f"got {type(x).__name__}"
                + (f" of dtype {x.dtype}" if isinstance(x, torch.Tensor) else "")
                + ": use torch.from_numpy(images).float()"
            )
        single = x.ndim == 3
        batch = x[None] if single else x
        if batch.ndim != 4 or batch.shape[1] != self.mean.shape[1]:
            raise InputError(
                f"Normalize has {self.mean.shape[1]} channels; got an input of shape "
                f"{tuple(x.shape)} (images are (C, H, W), batches (N, C, H, W))"
            )
        out = (batch - self.mean.to(batch)) / self.std.to(batch)
        return out[0] if single else out


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
        from robopercept.learning.metrics import confusion_matrix

        k = n_classes or self.probabilities.shape[1]
        return confusion_matrix(self.y_true, self.y_pred, labels=np.arange(k))


def resolve_device(name: str | torch.device | None) -> torch.device:
    """The torch device a run uses: ``name`` checked, or, for None, CUDA when
    available, else the CPU (what :func:`fit` and the detectors' trainer do).

    Raises
    ------
    InputError
        A name torch does not know (``"cpu"``, ``"cuda"``, ``"cuda:1"``, ...).

    Examples
    --------
    >>> resolve_device("cpu")
    device(type='cpu')
    """
    dev = check_device(name, "device (--device)")
    if dev is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return dev


def _check_batch(x: torch.Tensor, y: torch.Tensor, n_classes: int) -> None:
    if x.ndim != 4:
        raise InputError(f"images must be (N, C, H, W) batches; got shape {tuple(x.shape)}")
    if y.numel() and (int(y.min()) < 0 or int(y.max()) >= n_classes):
        raise InputError(
            f"labels must be in 0..{n_classes - 1} (the model has {n_classes} outputs); "
            f"got {int(y.min())}..{int(y.max())}"
        )


@contextlib.contextmanager
def deterministic_algorithms() -> Iterator[None]:
    """Within the block, torch uses deterministic algorithms only
    (``torch.use_deterministic_algorithms(True, warn_only=True)``), restored after:
    the same seed and thread count give bit-identical training runs on the CPU.

    Examples
    --------
    >>> with deterministic_algorithms():
    ...     torch.are_deterministic_algorithms_enabled()
    True
    """
    before = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before)


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
    from robopercept.progress import progress_bar

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
    (:func:`~robopercept.nn.detection.models.save_detector`,
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
    """Read a checkpoint written by :func:`fit` (``weights_only=True``: tensors and plain
    values only, no code) and, with ``model``, load its weights into it.

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
        bad = sorted(set(own) ^ set(theirs)) + sorted(
            k for k in set(own) & set(theirs) if tuple(own[k].shape) != tuple(theirs[k].shape)
        )
        if bad:
            arch = state.get("architecture", "an unrecorded architecture")
            raise FileFormatError(
                f"{p}: weights of {arch}, not of this model ({len(bad)} mismatched tensors, "
                f"first {bad[0]!r}): build the model the checkpoint was trained with"
            )
        model.load_state_dict(theirs)
    return state


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
    from robopercept.progress import progress_bar

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
