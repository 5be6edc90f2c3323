"""How a training run is configured and what it records: :class:`TrainConfig` (epochs,
batch, optimizer, schedule, early stopping, seed, device, discriminative learning rates,
gradual unfreezing), :class:`History` (the per-epoch figures of
:func:`~robopercept.nn.train.fit.fit`), the device a run uses (:func:`resolve_device`)
and the determinism switch every trainer runs under (:func:`deterministic_algorithms`).

A run is deterministic on the CPU: the same seed and thread count give bit-identical
weights (``torch.use_deterministic_algorithms`` during the run).
"""

from __future__ import annotations

import contextlib
import csv
import os
import reprlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from robopercept._checks import check_bool, check_int, check_real
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_device
from robopercept.viz.plot import Panel, Series, plot_series

__all__ = [
    "History",
    "TrainConfig",
    "deterministic_algorithms",
    "resolve_device",
]

#: the most epochs (and the largest step size or patience) a run may ask for
MAX_EPOCHS = 100_000

Optimizer = Literal["sgd", "adamw"]
Schedule = Literal["constant", "step", "cosine", "onecycle"]


@dataclass
class TrainConfig:
    """How :func:`~robopercept.nn.train.fit.fit` trains.

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
        """The inverse of :meth:`to_dict`, checked: the columns are lists of one length
        (``epoch`` of integers, the others of real numbers, NaN allowed),
        ``best_epoch`` an integer, ``stopped`` a str; missing entries take their
        defaults.

        Raises
        ------
        InputError
            ``d`` is not such a record (the message names the entry).
        """
        if not isinstance(d, dict):
            raise InputError(f"a history must be a dict of its columns; got {type(d).__name__}")
        values = {k: d[k] for k in cls.__dataclass_fields__ if not k.startswith("_") and k in d}
        for name in cls._COLUMNS:
            column = values.get(name, [])
            kinds = (int,) if name == "epoch" else (int, float)
            if not isinstance(column, list) or not all(
                isinstance(v, kinds) and not isinstance(v, bool) for v in column
            ):
                raise InputError(
                    f"the history's {name!r} must be a list of numbers; got {reprlib.repr(column)}"
                )
            values[name] = list(column)
        lengths = {len(values[name]) for name in cls._COLUMNS}
        if len(lengths) > 1:
            raise InputError(f"the history's columns differ in length ({sorted(lengths)})")
        if type(values.get("best_epoch", -1)) is not int:
            raise InputError(
                f"the history's 'best_epoch' must be an integer; got "
                f"{reprlib.repr(values['best_epoch'])}"
            )
        if not isinstance(values.get("stopped", ""), str):
            raise InputError(
                f"the history's 'stopped' must be a str; got {reprlib.repr(values['stopped'])}"
            )
        return cls(**values)

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


def resolve_device(name: str | torch.device | None) -> torch.device:
    """The torch device a run uses: ``name`` checked, or, for None, CUDA when
    available, else the CPU (what :func:`~robopercept.nn.train.fit.fit` and the
    detectors' trainer do).

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


@contextlib.contextmanager
def deterministic_algorithms() -> Iterator[None]:
    """Within the block, torch uses deterministic algorithms only
    (``torch.use_deterministic_algorithms(True, warn_only=True)``), restored after:
    the same seed and thread count give bit-identical training runs on the CPU.

    torch's companion setting ``torch.utils.deterministic.fill_uninitialized_memory``
    (on by default with deterministic algorithms: every ``torch.empty`` is filled with
    NaN, so that an operation that reads memory it never wrote gives the same result
    every time) is turned off in the block. The fill cost 2-3 % of a training epoch of
    the digits CNN (``python -m benchmarks nn_ops``), and only a faulty operation
    reads memory it did not write; the trainers' seeded-determinism tests
    (bit-identical runs) hold without it.

    Examples
    --------
    >>> with deterministic_algorithms():
    ...     torch.are_deterministic_algorithms_enabled()
    True
    """
    # a property of torch's module object, which its type stubs do not declare
    import torch.utils.deterministic as torch_deterministic

    before = torch.are_deterministic_algorithms_enabled()
    warn_only = torch.is_deterministic_algorithms_warn_only_enabled()
    fill = torch_deterministic.fill_uninitialized_memory  # type: ignore[attr-defined]
    torch.use_deterministic_algorithms(True, warn_only=True)
    torch_deterministic.fill_uninitialized_memory = False  # type: ignore[attr-defined]
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before, warn_only=warn_only)
        torch_deterministic.fill_uninitialized_memory = fill  # type: ignore[attr-defined]
