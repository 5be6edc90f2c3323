"""A training run from data to files: what ``robopercept nn train|eval|predict`` does.

:func:`train_run` is the course's recipe end to end: load the data (scikit-learn's
``digits``, scikit-image's ``lfw_subset`` or an image folder ``root/class_name/*.png``),
split it into train / validation / test keeping the class proportions (seeded), compute
the normalization statistics on the training split only and put them first in the model
(:class:`~robopercept.nn.data.augment.Normalize`, so the checkpoint carries them), train
with :func:`~robopercept.nn.train.fit.fit`, evaluate the best epoch on the test split and
write the run folder (:func:`train_ddp` does the same on several processes,
DistributedDataParallel: ``nn train --nproc N``):

========================  =============================================================
``checkpoint.pt``         the last epoch (model, optimizer, schedule, random states):
                          ``resume=True`` continues from it
``checkpoint.best.pt``    the best epoch's weights (what ``eval`` and ``predict`` use)
``history.csv``           one row per epoch (:meth:`History.write_csv`)
``curves.png``            loss, accuracy and learning rate against the epoch
``metrics.json``          test accuracy, per-class precision / recall / F1, confusion
                          matrix, parameters, seconds, configuration, classes, the model
``confusion.png``         the test confusion matrix (:func:`robopercept.viz.confusion_picture`)
========================  =============================================================

Both checkpoints record the model's :class:`Architecture` (builder name and arguments,
channels, classes, input size, class names) as JSON, so :func:`load_run` rebuilds the
model from the checkpoint alone.
"""

from __future__ import annotations

import contextlib
import json
import os
import reprlib
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from torch.utils.data import Dataset

from robopercept._checks import (
    as_path,
    check_choice,
    check_image,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.fileio import strict_json
from robopercept.imaging import read_image, rgb_to_gray, write_image
from robopercept.learning.metrics import classification_report
from robopercept.nn.classification.models import MODELS, build_model
from robopercept.nn.classification.saved import MAX_INPUT_SIDE, Architecture, load_run
from robopercept.nn.core.summary import ModelSummary, summary
from robopercept.nn.data.augment import Compose, Normalize, RandomAffine, RandomCrop
from robopercept.nn.data.datasets import (
    ArrayDataset,
    ImageFolder,
    load_digits,
    load_lfw_subset,
    normalization_stats,
    stratified_split,
    to_unit_float,
)
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import History, TrainConfig
from robopercept.nn.train.distributed import (
    check_world_batch,
    rank_device,
    run_ranks,
    torchrun_env,
)
from robopercept.nn.train.fit import evaluate, fit
from robopercept.nn.train.runs import BEST_CHECKPOINT, CHECKPOINT, prepare_run_folder
from robopercept.viz import confusion_picture

__all__ = [
    "BUILTIN_DATA",
    "SHRINK_LIMIT",
    "SHRINK_WARNING",
    "Prediction",
    "RunEvaluation",
    "TrainResult",
    "class_probabilities",
    "evaluate_run",
    "load_data",
    "model_summary",
    "predict",
    "predict_loaded",
    "train_ddp",
    "train_run",
]

#: data sets named instead of a folder
BUILTIN_DATA = ("digits", "lfw")


@dataclass(frozen=True)
class RunEvaluation:
    """A run's model on a labelled data set.

    Attributes
    ----------
    accuracy, loss : float
    classes : tuple of str
    precision, recall, f1 : (K,) float ndarray
        Per class (0 where undefined), :func:`robopercept.learning.metrics.classification_report`.
    support : (K,) int ndarray
    confusion : (K, K) int ndarray
        Counts ``[true, predicted]``.
    n : int
        Images evaluated.
    """

    accuracy: float
    loss: float
    classes: tuple[str, ...]
    precision: np.ndarray
    recall: np.ndarray
    f1: np.ndarray
    support: np.ndarray
    confusion: np.ndarray
    n: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: accuracy, loss, per-class figures by name, the confusion matrix."""
        return {
            "accuracy": self.accuracy,
            "loss": self.loss,
            "n": self.n,
            "classes": list(self.classes),
            "per_class": {
                name: {
                    "precision": float(self.precision[k]),
                    "recall": float(self.recall[k]),
                    "f1": float(self.f1[k]),
                    "support": int(self.support[k]),
                }
                for k, name in enumerate(self.classes)
            },
            "confusion": self.confusion.tolist(),
        }

    def picture(self, title: str = "confusion matrix") -> np.ndarray:
        """The confusion matrix drawn (:func:`robopercept.viz.confusion_picture`), (H, W, 3)
        uint8."""
        return confusion_picture(self.confusion, self.classes, title=title)


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_run` made.

    Attributes
    ----------
    out_dir : Path
    files : dict of str to Path
        ``checkpoint``, ``best``, ``history``, ``curves``, ``metrics``, ``confusion``.
    architecture : Architecture
    history : History
    test : RunEvaluation
        The best epoch's model on the test split.
    parameters : int
    seconds : float
        Training time (fit only).
    metrics : dict
        The content of ``metrics.json``.
    """

    out_dir: Path
    files: dict[str, Path]
    architecture: Architecture
    history: History
    test: RunEvaluation
    parameters: int
    seconds: float
    metrics: dict[str, Any] = field(repr=False)


@dataclass(frozen=True)
class Prediction:
    """The top classes of one image: ``top`` is ``((class, probability), ...)``,
    most probable first; ``warning`` says when the image lies outside what the model
    was trained on (:data:`SHRINK_WARNING`)."""

    path: Path
    top: tuple[tuple[str, float], ...]
    warning: str | None = None


#: the domain rule of the classifiers: an image shrunk by more than this factor to the
#: model's input size lies outside what it learnt (its details are gone)
SHRINK_LIMIT = 4.0
#: the warning of :func:`predict_loaded` when the rule holds
SHRINK_WARNING = (
    "warning: the model sees {h} x {w} images; this one is {H} x {W}, shrunk {f:.0f} "
    "times: it may lie outside what the model was trained on"
)


# --------------------------------------------------------------------------- data


def load_data(
    data: str | os.PathLike[str],
    *,
    mode: str = "rgb",
    size: tuple[int, int] | None = None,
) -> ArrayDataset:
    """The data set named ``data``: ``"digits"``
    (:func:`~robopercept.nn.data.datasets.load_digits`), ``"lfw"``
    (:func:`~robopercept.nn.data.datasets.load_lfw_subset`) or a folder
    ``root/class_name/*.png`` (:class:`~robopercept.nn.data.datasets.ImageFolder`).

    Parameters
    ----------
    data : str or path
    mode : {'rgb', 'gray'}
        Folders only: colour or grey images.
    size : (width, height), optional
        Folders only: resize every image to this.

    Returns
    -------
    ArrayDataset

    Raises
    ------
    InputError
        Neither a built-in name nor an existing folder; a folder without images.
    FileFormatError
        A non-image or unreadable file in the folder.
    """
    text = str(as_path(data, "--data (digits, lfw or an image folder)"))
    mode = check_choice(mode, "mode", ("rgb", "gray"))
    if text == "digits":
        return load_digits()
    if text == "lfw":
        return load_lfw_subset()
    if not Path(text).is_dir():
        raise InputError(
            f"--data {text!r}: no such folder; give 'digits', 'lfw' or a folder laid out "
            "as root/class_name/image.png"
        )
    return ImageFolder(text, mode=mode, size=size)


def _parameters(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))


def _run_evaluation(model: nn.Module, data: ArrayDataset, device: str | None) -> RunEvaluation:
    # ArrayDataset keeps torch's map-style contract without subclassing Dataset
    ev = evaluate(model, cast(Dataset[Any], data), device=device)
    k = len(data.classes)
    rep = classification_report(ev.y_true, ev.y_pred)
    full = {name: np.zeros(k) for name in ("precision", "recall", "f1")}
    for i, label in enumerate(rep.labels):
        for name in full:
            full[name][int(label)] = getattr(rep, name)[i]
    cm = ev.confusion_matrix(k)
    return RunEvaluation(
        accuracy=ev.accuracy,
        loss=ev.loss,
        classes=tuple(data.classes),
        support=cm.sum(axis=1),
        confusion=cm,
        n=len(data),
        **full,
    )


def _augmentation(shape: tuple[int, int, int], seed: int) -> Compose:
    """Shifts of up to an eighth of the size (padded crop) and a small affine jitter;
    no flips (a mirrored digit is another symbol)."""
    _, h, w = shape
    gen = torch.Generator().manual_seed(seed)
    pad = max(1, min(h, w) // 8)
    return Compose(
        [
            RandomCrop((h, w), padding=pad, generator=gen),
            RandomAffine(degrees=10.0, scale=(0.9, 1.1), generator=gen),
        ]
    )


# --------------------------------------------------------------------------- train


def train_run(
    data: str | os.PathLike[str],
    model: str,
    out_dir: str | os.PathLike[str],
    *,
    config: TrainConfig | None = None,
    model_kwargs: dict[str, Any] | None = None,
    mode: str = "rgb",
    size: tuple[int, int] | None = None,
    fractions: Sequence[float] = (0.7, 0.15, 0.15),
    augment: bool = False,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    distributed: bool = False,
    sync_batchnorm: bool = True,
) -> TrainResult:
    """Train ``model`` on ``data`` and write the run folder ``out_dir`` (module docstring).

    Steps: :func:`load_data`; :func:`~robopercept.nn.data.datasets.stratified_split` into train,
    validation and test by ``fractions`` with ``config.seed``; per-channel mean and
    standard deviation of the train split only
    (:func:`~robopercept.nn.data.datasets.normalization_stats`) in a
    :class:`~robopercept.nn.data.augment.Normalize` before the network; :func:`fit`
    (checkpoint every epoch, early stopping and best-epoch restore on validation);
    evaluation of the best weights on the test split.

    Parameters
    ----------
    data : str or path
        ``"digits"``, ``"lfw"`` or an image folder.
    model : str
        A name of :data:`robopercept.nn.classification.models.MODELS`.
    out_dir : path
        The run folder (created).
    config : TrainConfig, optional
        Epochs, optimizer, learning rate, schedule, seed, device...
    model_kwargs : dict, optional
        More arguments of the builder (``widths``, ``depth``, ``dropout``...; JSON values).
    mode : {'rgb', 'gray'}
        Image folders: read colour (C = 3) or grey (C = 1) images.
    size : (width, height), optional
        Image folders: resize every image to this.
    fractions : (train, validation, test)
        Shares of every class, summing to 1.
    augment : bool
        Random shifts, rotations and scales of the training images (seeded).
    resume : bool
        Continue the run in ``out_dir`` from its ``checkpoint.pt``: ends as an
        uninterrupted run would. Everything that defines the run must be as it was
        started: ``data``, ``model``, ``model_kwargs``, ``mode``, ``size``,
        ``fractions``, ``augment``, ``sync_batchnorm`` (with ``distributed``) and every
        field of ``config`` (seed, optimizer, schedule, learning rate, batch size,
        patience, ...), else :class:`~robopercept.errors.ArgumentError` (exit 2) names
        the differing flags and ``--overwrite``. What may change: ``config.device``,
        ``config.epochs`` (more epochs extend the run, not under the one-cycle schedule,
        whose steps are fixed when it starts; see :func:`fit`), ``progress``,
        the number of processes (``nn train --nproc``) and what the command prints
        (``--json``, ``--quiet``).
    overwrite : bool
        Start afresh in a folder that already holds a run (refused otherwise).
    progress : bool
        A progress bar on stderr.
    distributed : bool
        This process is one rank of a DistributedDataParallel run (an initialized
        ``torch.distributed`` process group; :func:`train_ddp` sets it up): :func:`fit`
        trains with ``distributed=True``; rank 0 alone evaluates
        the test split and writes the run folder, then sends the result to the other
        ranks, which wait for it (every rank returns the same :class:`TrainResult`).
    sync_batchnorm : bool
        With ``distributed``: batch norm over the whole global batch (the default: the
        model one process would train); False keeps each process's statistics.
        ``metrics.json`` records it and the process count (``nproc``).

    Returns
    -------
    TrainResult

    Raises
    ------
    InputError
        Unknown data or model, a bad split, images larger than :data:`MAX_INPUT_SIDE`
        pixels a side, ``resume`` without a checkpoint; errors of :func:`fit`.
    ArgumentError
        A folder holding a run without ``resume`` or ``overwrite``
        (:class:`~robopercept.errors.RunExistsError`); ``resume`` under other options
        than the run's.
    FileFormatError
        A non-image file in the image folder; when resuming, a checkpoint of another
        architecture or with a damaged training state (the message names the entry).
    """
    cfg = config or TrainConfig()
    if model not in MODELS:
        raise InputError(f"unknown model {model!r} (--model): choose one of {', '.join(MODELS)}")
    try:
        fr = tuple(float(f) for f in fractions)
    except (TypeError, ValueError, OverflowError):
        fr = ()
    if len(fr) != 3:
        raise InputError(
            f"fractions must be (train, validation, test); got {reprlib.repr(fractions)}"
        )
    try:
        if not isinstance(model_kwargs, (dict, type(None))):
            raise TypeError
        kwargs = json.loads(json.dumps(model_kwargs or {}, allow_nan=False))
    except (TypeError, ValueError, RecursionError):
        raise InputError(
            "model_kwargs must be a dict of the builder's arguments as JSON values, e.g. "
            f"{{'dropout': 0.2}}; got {reprlib.repr(model_kwargs)}"
        ) from None
    out = Path(out_dir)
    ckpt = prepare_run_folder(out, resume=resume, overwrite=overwrite)
    ds = load_data(data, mode=mode, size=size)
    c, h, w = ds.image_shape
    if max(h, w) > MAX_INPUT_SIDE:
        raise InputError(
            f"--data {os.fspath(data)!r} has {w} x {h} images; a run takes at most "
            f"{MAX_INPUT_SIDE} pixels a side: resize them with --size WxH"
        )
    train_idx, val_idx, test_idx = stratified_split(ds.labels, fr, rng=cfg.seed)
    transform = _augmentation(ds.image_shape, cfg.seed) if augment else None
    train = ds.subset(train_idx, transform=transform)
    val, test = ds.subset(val_idx), ds.subset(test_idx)
    mean, std = normalization_stats(ds.subset(train_idx))
    std = np.where(std > 0, std, 1.0)  # a constant channel is only centred
    arch = Architecture(
        model=model,
        kwargs=kwargs,
        in_channels=c,
        num_classes=len(ds.classes),
        input_size=(h, w),
        classes=tuple(ds.classes),
        mode="gray" if c == 1 else "rgb",
    )
    text = str(as_path(data, "--data (digits, lfw or an image folder)"))
    options = {  # what defines the run besides the configuration (compared on resume)
        "--data": text if text in BUILTIN_DATA else str(Path(text).resolve()),
        "--model": model,
        "--dropout (model_kwargs)": arch.kwargs,
        "--gray": mode == "gray",
        "--size": None if size is None else list(size),
        "--split": list(fr),
        "--augment": bool(augment),
        "--per-process-bn": bool(distributed and not sync_batchnorm),
    }
    why = arch.input_size_refusal()
    if why is not None:
        raise InputError(
            f"--model {model} cannot take the {w} x {h} images of --data "
            f"{os.fspath(data)!r} ({why}): enlarge them with --size WxH or choose "
            "--model resnet_small"
        )
    torch.manual_seed(cfg.seed)  # the initial weights
    net = arch.build()
    net[0] = Normalize(mean, std)
    t0 = time.perf_counter()
    try:
        hist = fit(
            net,
            cast(Dataset[Any], train),
            cast(Dataset[Any], val),
            cfg,
            checkpoint=ckpt,
            resume=resume,
            architecture=arch.to_json(),
            run_options=options,
            progress=progress,
            distributed=distributed,
            sync_batchnorm=sync_batchnorm,
        )
        if _rank(distributed) == 0:  # before the model: a signal while it is saved
            hist.write_csv(out / "history.csv")  # leaves the history, as during training
    except BaseException:  # Ctrl-C, SIGTERM, a failure: keep the last epoch's history.csv too
        if ckpt.exists() and _rank(distributed) == 0:
            # never hide the interruption or the error behind a damaged checkpoint
            with contextlib.suppress(Exception):
                History.from_dict(load_checkpoint(ckpt)["history"]).write_csv(out / "history.csv")
        raise
    seconds = time.perf_counter() - t0
    if distributed:  # rank 0 evaluates and writes; the others receive its result
        import torch.distributed as dist

        box: list[Any] = [None]
        if dist.get_rank() == 0:
            box[0] = _finish_run(
                net,
                hist,
                test,
                seconds,
                out,
                arch,
                data,
                cfg,
                mean,
                std,
                augment,
                (len(train), len(val)),
                nproc=dist.get_world_size(),
                sync_batchnorm=sync_batchnorm,
            )
        dist.broadcast_object_list(box, src=0)
        return cast(TrainResult, box[0])
    return _finish_run(
        net, hist, test, seconds, out, arch, data, cfg, mean, std, augment, (len(train), len(val))
    )


def _rank(distributed: bool) -> int:
    if not distributed:
        return 0
    import torch.distributed as dist

    return dist.get_rank()


def _finish_run(
    net: nn.Module,
    hist: History,
    test: ArrayDataset,
    seconds: float,
    out: Path,
    arch: Architecture,
    data: str | os.PathLike[str],
    cfg: TrainConfig,
    mean: np.ndarray,
    std: np.ndarray,
    augment: bool,
    sizes: tuple[int, int],
    nproc: int = 1,
    sync_batchnorm: bool = True,
) -> TrainResult:
    """Evaluate the best weights on the test split and write the run folder."""
    test_ev = _run_evaluation(net, test, cfg.device)
    files = _write_run(out, hist, test_ev)
    metrics = {
        "data": os.fspath(data),
        "test_accuracy": test_ev.accuracy,
        "test": test_ev.to_dict(),
        "parameters": _parameters(net),
        "seconds": seconds,
        "best_epoch": hist.best_epoch,
        "epochs_run": len(hist.epoch),
        "stopped": hist.stopped,
        "split": {"train": sizes[0], "validation": sizes[1], "test": len(test)},
        "normalization": {"mean": np.asarray(mean).tolist(), "std": np.asarray(std).tolist()},
        "augment": augment,
        "nproc": nproc,
        "batch_norm": "global batch" if sync_batchnorm or nproc == 1 else "per process",
        "config": {**asdict(cfg), "nproc": nproc},
        "classes": list(arch.classes),
        "architecture": asdict(arch),
    }
    files["metrics"].write_text(json.dumps(strict_json(metrics), indent=2) + "\n")
    return TrainResult(out, files, arch, hist, test_ev, _parameters(net), seconds, metrics)


def _write_run(out: Path, hist: History, test_ev: RunEvaluation) -> dict[str, Path]:
    files = {
        "checkpoint": out / CHECKPOINT,
        "best": out / BEST_CHECKPOINT,
        "history": out / "history.csv",
        "curves": out / "curves.png",
        "metrics": out / "metrics.json",
        "confusion": out / "confusion.png",
    }
    hist.write_csv(files["history"])
    write_image(files["curves"], hist.picture())
    write_image(files["confusion"], test_ev.picture("confusion matrix (test split)"))
    return files


def _train_rank(
    data: str, model: str, out_dir: str, cfg: TrainConfig, kwargs: dict[str, Any]
) -> TrainResult:
    """One rank of :func:`train_ddp`."""
    cfg, _ = rank_device(cfg)
    return train_run(data, model, out_dir, config=cfg, distributed=True, **kwargs)


def train_ddp(
    data: str | os.PathLike[str],
    model: str,
    out_dir: str | os.PathLike[str],
    *,
    nproc: int = 1,
    config: TrainConfig | None = None,
    threads: int | None = None,
    timeout: float = 1800.0,
    **kwargs: Any,
) -> TrainResult:
    """:func:`train_run` on ``nproc`` processes with DistributedDataParallel
    (:mod:`robopercept.nn.train.distributed`), or as one rank of a ``torchrun`` run.

    The gradient of a step is the mean over the global batch of ``B = batch_size``
    images, :math:`g = \\frac{1}{N}\\sum_{r=1}^{N} \\frac{1}{B/N}\\sum_{i \\in b_r}
    \\nabla \\ell_i = \\frac{1}{B}\\sum_{i \\in b} \\nabla \\ell_i`, with rank ``r``'s
    share :math:`b_r` of :math:`B/N` images (DDP's all-reduce averages over ranks): the
    step of one process on the same ``B`` images, so the learning rate is unchanged.

    Parameters
    ----------
    data, model, out_dir
        As :func:`train_run`.
    nproc : int
        Processes on this machine (1: :func:`train_run` itself, unless under torchrun,
        whose processes are then the ranks; torchrun needs ``nproc`` 1).
    config : TrainConfig, optional
        ``batch_size`` is the global batch (a multiple of the number of processes).
    threads : int, optional
        torch threads per process (default: torch's thread count divided by the
        processes on this machine, at least 1).
    timeout : float
        Seconds a collective waits for the other ranks before failing.
    **kwargs
        More arguments of :func:`train_run` (``model_kwargs``, ``mode``, ``size``,
        ``fractions``, ``augment``, ``resume``, ``overwrite``, ``progress``).

    Returns
    -------
    TrainResult
        Rank 0's (under torchrun every rank returns it).

    Raises
    ------
    InputError
        ``nproc`` < 1, larger than the batch or not dividing it, ``nproc`` > 1 under
        torchrun; the errors of :func:`train_run`, raised again from the first rank that
        failed.

    Examples
    --------
    >>> train_ddp("digits", "vgg_small", "run", nproc=0)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: nproc (--nproc) must be >= 1; got 0
    """
    nproc = check_int(nproc, "nproc (--nproc)", 1)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    timeout = check_real(timeout, "timeout (seconds)", 0.0, low_inclusive=False)
    if threads is not None:
        threads = check_int(threads, "threads", 1)
    if "distributed" in kwargs:
        raise InputError("train_ddp sets train_run's distributed itself; do not pass it")
    env = torchrun_env()
    world = env[1] if env is not None else nproc
    check_world_batch(world, cfg.batch_size)
    if env is None and nproc == 1:
        return train_run(data, model, out_dir, config=cfg, **kwargs)
    _, backend = rank_device(cfg)
    return cast(
        TrainResult,
        run_ranks(
            _train_rank,
            nproc,
            (os.fspath(data), model, os.fspath(out_dir), cfg, kwargs),
            backend=backend,
            threads=threads,
            timeout=timeout,
        ),
    )


# --------------------------------------------------------------------------- load, eval, predict


def evaluate_run(
    checkpoint: str | os.PathLike[str],
    data: str | os.PathLike[str],
    *,
    device: str | None = None,
) -> RunEvaluation:
    """A run's model on a whole labelled data set (``"digits"``, ``"lfw"`` or a folder).

    Folder images are read as the model was trained (grey or colour) and resized to its
    input size. Note that the built-in sets hold the run's training images too: for an
    unbiased figure use ``metrics.json``'s test accuracy, or a folder of new images.

    Parameters
    ----------
    checkpoint : path
        See :func:`load_run`.
    data : str or path
    device : str, optional

    Returns
    -------
    RunEvaluation

    Raises
    ------
    InputError
        Data whose image shape or classes differ from the model's.
    FileFormatError
        See :func:`load_run`.
    """
    model, arch = load_run(checkpoint, device=device)
    h, w = arch.input_size
    ds = load_data(data, mode=arch.mode, size=(w, h))
    expected = (arch.in_channels, h, w)
    if ds.image_shape != expected:
        raise InputError(
            f"--data {os.fspath(data)!r} has images of shape (C, H, W) {ds.image_shape}; the "
            f"model takes {expected}: evaluate on the kind of data it was trained on"
        )
    if tuple(ds.classes) != arch.classes:
        raise InputError(
            f"--data {os.fspath(data)!r} has classes {list(ds.classes)}; the model "
            f"predicts {list(arch.classes)}: give data with the same classes"
        )
    return _run_evaluation(model, ds, device)


@torch.no_grad()
def model_summary(model: str, input_shape: Sequence[int], num_classes: int) -> ModelSummary:
    """The layer table of a model of :data:`~robopercept.nn.classification.models.MODELS`
    built for ``input_shape`` ``(C, H, W)`` and ``num_classes`` outputs
    (:func:`~robopercept.nn.core.summary.summary`, equal to torchinfo's): what
    ``robopercept nn summary`` prints.

    Raises
    ------
    InputError
        An unknown model (``--model``), a shape that is not three positive integers, or
        an image smaller than the model's pooling layers can take (the message gives the
        smallest ``--input`` side).

    Examples
    --------
    >>> model_summary("vgg_small", (1, 8, 8), 10).output_shape
    (1, 10)
    """
    if not isinstance(model, str) or model not in MODELS:
        raise InputError(
            f"unknown model {plain_repr(model)} (--model): choose one of {', '.join(MODELS)}"
        )
    if (
        not isinstance(input_shape, (list, tuple))
        or len(input_shape) != 3
        or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in input_shape)
        or min(input_shape) < 1
    ):
        raise InputError(
            "input_shape must be (C, H, W), three positive integers (--input C,H,W, e.g. "
            f"1,8,8); got {plain_repr(input_shape)}"
        )
    net = build_model(model, in_channels=int(input_shape[0]), num_classes=num_classes)
    h, w = int(input_shape[1]), int(input_shape[2])
    if min(_output_side(net, h), _output_side(net, w)) < 1:
        least = next(s for s in range(1, 1 << 16) if _output_side(net, s) >= 1)
        raise InputError(
            f"{model} cannot take an image of height {h} and width {w} (--input "
            f"{input_shape[0]},{h},{w}): its "
            f"pooling layers need at least {least} px per side; give --input "
            f"{input_shape[0]},{max(h, least)},{max(w, least)} or larger"
        )
    return summary(net, input_shape)


def _output_side(net: nn.Module, side: int) -> int:
    """The side of ``net``'s feature map for an input side of ``side``, along the chain of
    its convolutions and pools (a parallel branch is followed as if in series: every
    layer here keeps or shrinks the side, so a side that stays >= 1 does so in any
    order); below 1 the network cannot take the input."""
    for m in net.modules():
        if isinstance(m, (nn.Conv2d, nn.MaxPool2d, nn.AvgPool2d)):
            k, s, p = (
                int(v[0]) if isinstance(v, tuple) else int(v)  # type: ignore[arg-type]
                for v in (m.kernel_size, m.stride, m.padding)
            )
            d = m.dilation if isinstance(m, (nn.Conv2d, nn.MaxPool2d)) else 1
            d = int(d[0]) if isinstance(d, tuple) else int(d)
            side = (side + 2 * p - d * (k - 1) - 1) // s + 1
            if side < 1:
                return side
    return side


def predict(
    checkpoint: str | os.PathLike[str],
    image_paths: Sequence[str | os.PathLike[str]],
    *,
    top_k: int = 3,
    device: str | None = None,
) -> list[Prediction]:
    """The ``top_k`` most probable classes of each image, by a run's model.

    Each image is read grey or colour as the model was trained
    (:func:`robopercept.imaging.read_image`), scaled to [0, 1] (8-bit / 255, 16-bit /
    65535) and resized to the model's input size (bilinear with antialiasing,
    ``torch.nn.functional.interpolate``); probabilities are the softmax of the logits.

    A ``digits`` model sees 8 x 8 images of light strokes on a black background: it is
    only meaningful for digit-like images of that kind (a photo shrunk to 8 x 8 still
    gets ten probabilities, which then mean nothing).

    Parameters
    ----------
    checkpoint : path
        See :func:`load_run`.
    image_paths : sequence of path
    top_k : int
        Classes per image (at most the number of classes).
    device : str, optional

    Returns
    -------
    list of Prediction
        One per image, in order.

    Raises
    ------
    InputError
        No images, ``top_k`` < 1.
    FileFormatError
        A missing or unreadable image or checkpoint.
    """
    image_paths, top_k = _predict_inputs(image_paths, top_k)
    model, arch = load_run(checkpoint, device=device)
    return predict_loaded(model, arch, image_paths, top_k=top_k)


def _predict_inputs(
    image_paths: Sequence[str | os.PathLike[str]], top_k: int
) -> tuple[list[Path], int]:
    """``image_paths`` as a list of paths and ``top_k``, checked."""
    if isinstance(image_paths, (str, bytes, os.PathLike)):
        image_paths = [image_paths]
    if not isinstance(image_paths, (list, tuple)):
        raise InputError(
            f"image_paths must be a list of image files; got {type(image_paths).__name__}"
        )
    if not image_paths:
        raise InputError("no images to predict: give one or more image files")
    paths = [as_path(p, "each image path") for p in image_paths]
    return paths, check_int(top_k, "top_k (--top-k)", 1)


@torch.inference_mode()
def predict_loaded(
    model: nn.Module,
    arch: Architecture,
    image_paths: Sequence[str | os.PathLike[str]],
    *,
    top_k: int = 3,
) -> list[Prediction]:
    """:func:`predict` with a model already loaded by :func:`load_run` (to classify many
    batches of images without reading the checkpoint again).

    Parameters
    ----------
    model : torch.nn.Module
        The run's model, in eval mode, on its device.
    arch : Architecture
        Its architecture (:func:`load_run`'s second value).
    image_paths : sequence of path
    top_k : int
        Classes per image (at most the number of classes).

    Returns
    -------
    list of Prediction
        One per image, in order.

    Raises
    ------
    InputError
        No images, ``top_k`` < 1, ``model`` or ``arch`` of the wrong type.
    FileFormatError
        A missing or unreadable image.

    Examples
    --------
    >>> model, arch = load_run("run/checkpoint.pt")  # doctest: +SKIP
    >>> predict_loaded(model, arch, ["digit.png"], top_k=1)  # doctest: +SKIP
    [Prediction(path=PosixPath('digit.png'), top=(('3', 0.98),))]
    """
    if not isinstance(model, nn.Module):
        raise InputError(f"model must be a torch.nn.Module (load_run); got {plain_repr(model)}")
    if not isinstance(arch, Architecture):
        raise InputError(f"arch must be an Architecture (load_run); got {plain_repr(arch)}")
    image_paths, top_k = _predict_inputs(image_paths, top_k)
    k = min(int(top_k), arch.num_classes)
    out: list[Prediction] = []
    for path in image_paths:
        prob, warning = class_probabilities(model, arch, read_image(path, mode=arch.mode))
        order = np.argsort(-prob, kind="stable")[:k]
        top = tuple((arch.classes[int(i)], float(prob[i])) for i in order)
        out.append(Prediction(Path(path), top, warning))
    return out


@torch.inference_mode()
def class_probabilities(
    model: nn.Module, arch: Architecture, image: np.ndarray
) -> tuple[np.ndarray, str | None]:
    """The class probabilities of one image by a run's model, and the domain warning.

    The image is made grey or colour as the model was trained (a colour image given to a
    grey model by :func:`~robopercept.imaging.rgb_to_gray`, a grey one to a colour model
    repeated in three channels), scaled to [0, 1] (8-bit / 255, 16-bit / 65535,
    :func:`~robopercept.nn.data.datasets.to_unit_float`) and resized to the model's input
    size (bilinear with antialiasing, ``torch.nn.functional.interpolate``); the
    probabilities are the softmax of the logits. The warning
    (:data:`SHRINK_WARNING`) is set when the image is shrunk more than
    :data:`SHRINK_LIMIT` times.

    Parameters
    ----------
    model : torch.nn.Module
        The run's model (:func:`load_run`), in eval mode, on its device.
    arch : Architecture
    image : (H, W) or (H, W, 3) ndarray
        uint8, uint16 or float in [0, 1].

    Returns
    -------
    probabilities : (K,) float64 ndarray
        In ``arch.classes`` order, summing to 1.
    warning : str or None

    Raises
    ------
    InputError
        ``model`` or ``arch`` of the wrong type, not an image.
    """
    if not isinstance(model, nn.Module):
        raise InputError(f"model must be a torch.nn.Module (load_run); got {plain_repr(model)}")
    if not isinstance(arch, Architecture):
        raise InputError(f"arch must be an Architecture (load_run); got {plain_repr(arch)}")
    img = to_unit_float(check_image(image, "image"))
    if arch.mode == "gray" and img.ndim == 3:
        img = rgb_to_gray(img).astype(np.float32)
    elif arch.mode == "rgb" and img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    h, w = arch.input_size
    chw = img[None] if img.ndim == 2 else img.transpose(2, 0, 1)
    x = torch.from_numpy(np.ascontiguousarray(chw, dtype=np.float32))[None]
    if x.shape[2:] != (h, w):
        x = F.interpolate(x, size=(h, w), mode="bilinear", align_corners=False, antialias=True)
    dev = next(model.parameters()).device
    prob = torch.softmax(model(x.to(dev)).double(), 1)[0].cpu().numpy()
    shrink = max(chw.shape[1] / h, chw.shape[2] / w)
    warning = (
        SHRINK_WARNING.format(h=h, w=w, H=chw.shape[1], W=chw.shape[2], f=shrink)
        if shrink > SHRINK_LIMIT
        else None
    )
    return prob, warning
