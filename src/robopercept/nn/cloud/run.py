r"""The run of ``robopercept nn cloud train|eval|CLOUD...``, owned by the library: the
data sets, the run folder, the metrics and pictures, and the prediction of one file.

The networks are built, trained, scored and saved by :mod:`robopercept.nn.cloud.train`;
this module is what a command does with them.

- **Data** (:func:`cloud_sets`): the procedural shapes (``"shapes"``,
  ``"shapes-partial"``, ``"shapes-noisy"``) or a folder of meshes and clouds, split into
  training, validation and test sets (seeded).
- **Training run** (:func:`train_run`): the run folder is checked first
  (:func:`~robopercept.nn.train.runs.prepare_run_folder`: a folder holding a run is
  refused unless resumed or overwritten), then the data are loaded, the network built
  (seeded), trained with a checkpoint after every epoch
  (:func:`~robopercept.nn.cloud.train.train_cloud_model`, the best validation epoch
  kept), saved, and scored on the test split. The run folder:

  ========================  ===========================================================
  ``checkpoint.pt``         the last complete epoch (weights, optimizer, schedule, random
                            states, history): Ctrl-C or SIGTERM keeps it, and
                            ``resume=True`` (``--resume``) continues from it to the
                            weights of an uninterrupted run
  ``checkpoint.best.pt``    the best validation epoch's weights
  ``model.pt``              the kept network and what rebuilds it
                            (:func:`~robopercept.nn.cloud.train.save_cloud_model`): what
                            ``eval`` and the cloud form load
  ``history.json``          per epoch the training loss, the seconds and the validation
                            score (:class:`~robopercept.nn.cloud.train.CloudHistory`);
                            written so far when the run is interrupted
  ``metrics.json``          the test split's scores (accuracy and class-mean accuracy;
                            instance and class mIoU for parts), the kept epoch
  ``confusion.png``         the test confusion matrix of classes (or parts)
                            (:func:`robopercept.viz.confusion_picture`)
  ========================  ===========================================================

- **Evaluation** (:func:`evaluate_run`): a saved network on the test split of the same
  data (same ``shapes``, ``n_points`` and ``seed``), optionally writing ``metrics.json``
  and ``confusion.png``.
- **One file** (:func:`classify_cloud_file`): a PLY/PCD cloud or OFF/PLY mesh classified
  (and segmented); :func:`shipped_cloud_model` gives the shipped networks.
"""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from torch import nn

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import ArgumentError, InputError
from robopercept.fileio import WriteError, atomic_write, describe_write_error, strict_json
from robopercept.imaging import write_image
from robopercept.nn._guards import check_count
from robopercept.nn.cloud.data import read_cloud_file, read_cloud_folder
from robopercept.nn.cloud.synthetic import procedural_shapes
from robopercept.nn.cloud.train import (
    CLOUD_MODELS,
    CloudEvaluation,
    CloudHistory,
    build_cloud_model,
    cloud_model_spec,
    evaluate_cloud_model,
    load_cloud_model,
    predict_clouds,
    save_cloud_model,
    train_cloud_model,
)
from robopercept.nn.shipped import BUILD_SHIPPED, SHIPPED_CLOUD_MODELS, shipped_model_path
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.runs import check_output_folder, prepare_run_folder
from robopercept.viz import confusion_picture

__all__ = [
    "CloudPrediction",
    "CloudRunEvaluation",
    "CloudTrainResult",
    "classify_cloud_file",
    "cloud_sets",
    "evaluate_run",
    "shipped_cloud_model",
    "train_run",
]

#: the command that rebuilds the shipped models from a checkout (the models,
#: :data:`~robopercept.nn.shipped.SHIPPED_CLOUD_MODELS`, are re-exported here)
BUILD_SHIPPED_CLOUD = BUILD_SHIPPED["cloud"]


# ----------------------------------------------------------------------------- data
#: clouds a training split keeps at least (batch norm learns from two clouds or more)
_MIN_TRAIN = 2


@dataclass(frozen=True)
class CloudSets:
    """The training, validation and test splits of :func:`cloud_sets` (``val`` None
    when the folder is too small to hold clouds out for it; ``train`` and ``val`` None
    for procedural data asked ``test_only``)."""

    train: Any
    val: Any
    test: Any
    source: str


def cloud_sets(
    data: str,
    *,
    shapes: int = 100,
    n_points: int = 1024,
    seed: int = 0,
    progress: bool = False,
    test_only: bool = False,
) -> CloudSets:
    """The splits a command trains and scores on.

    ``data`` is ``"shapes"`` (the procedural shapes,
    :func:`~robopercept.nn.cloud.synthetic.procedural_shapes`, ``shapes`` per class for
    training, a tenth as many for validation and for test, each drawn with its own
    seed), ``"shapes-partial"`` or ``"shapes-noisy"`` (the harder variants), or a folder
    ``root/<class>/*.off|*.ply|*.pcd`` (80/10/10 stratified split, seeded) or in
    ModelNet's layout ``root/<class>/{train,test}/*.off`` (its test split kept; a tenth
    of its training split held out for validation). No split is left empty
    (:func:`~robopercept.nn.data.datasets.stratified_split`). A folder too small to
    hold a validation cloud of each class out and keep 2 to train on has no validation
    split (``val`` None: training keeps its last epoch), as Keras trains without
    ``validation_split``.

    ``test_only`` makes only the test split of procedural data (each split has its own
    seed, so it is the same test split; evaluation does not pay for the training
    split, ten times larger). A folder is read and split as for training either way.

    Returns
    -------
    CloudSets

    Raises
    ------
    InputError
        Not a data name or folder; fewer clouds than splits (the message gives the
        count).
    """
    shapes = check_count(shapes, "shapes", 1, 1_000_000)
    test_only = check_bool(test_only, "test_only")
    n_points = check_count(n_points, "n_points", 1, 1 << 20)
    seed = check_count(seed, "seed", 0, 2**31 - 1)
    if not isinstance(data, (str, os.PathLike)):
        raise InputError(
            "data must be shapes, shapes-partial, shapes-noisy or a folder path "
            f"root/<class>/*.off (--data); got {plain_repr(data)[:60]}"
        )
    if data in ("shapes", "shapes-partial", "shapes-noisy"):
        variant = "clean" if data == "shapes" else data.split("-")[1]
        small = max(1, shapes // 10)
        sets = [
            procedural_shapes(n, n_points, variant=variant, rng=seed * 3 + i, progress=progress)
            if i == 2 or not test_only
            else None
            for i, n in enumerate((shapes, small, small))
        ]
        return CloudSets(sets[0], sets[1], sets[2], data)
    root = as_path(data, "data (--data)")
    if not root.is_dir():
        raise InputError(
            f"data must be shapes, shapes-partial, shapes-noisy or a folder root/<class>/*.off; "
            f"{data} is not a folder"
        )
    has_split = any((c / "train").is_dir() for c in root.iterdir() if c.is_dir())
    if has_split:
        full = read_cloud_folder(root, n_points, split="train", rng=seed, progress=progress)
        test = read_cloud_folder(root, n_points, split="test", rng=seed, progress=progress)
        if len(full) >= _MIN_TRAIN + full.num_classes:  # a held-out cloud of each class
            train, val = full.split((0.9, 0.1), rng=seed)
            return CloudSets(train, val, test, str(root))
        return CloudSets(full, None, test, str(root))
    full = read_cloud_folder(root, n_points, rng=seed, progress=progress)
    if len(full) >= _MIN_TRAIN + 2 * full.num_classes:
        train, val, test = full.split((0.8, 0.1, 0.1), rng=seed)
        return CloudSets(train, val, test, str(root))
    train, test = full.split((0.9, 0.1), rng=seed)
    return CloudSets(train, None, test, str(root))


# ----------------------------------------------------------------------------- runs
@dataclass(frozen=True)
class CloudTrainResult:
    """What :func:`train_run` made.

    Attributes
    ----------
    out_dir : Path
        The run folder.
    files : dict of str to Path
        ``model.pt``, ``history.json``, ``metrics.json`` and ``confusion.png`` by name
        (the checkpoints, ``checkpoint.pt`` and ``checkpoint.best.pt``, lie beside them).
    metrics : dict
        The content of ``metrics.json``.
    history : CloudHistory
    test : CloudEvaluation
        The kept network on the test split.
    best_epoch : int
        The kept (1-based) epoch.
    seconds : float
        Training time (the epochs only).
    """

    out_dir: Path
    files: dict[str, Path]
    metrics: dict[str, Any] = field(repr=False)
    history: CloudHistory = field(repr=False)
    test: CloudEvaluation = field(repr=False)
    best_epoch: int = 0
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``metrics.json``'s content and ``files`` (name -> path as str),
        what ``robopercept nn cloud train --json`` prints."""
        return {**self.metrics, "files": {name: str(p) for name, p in self.files.items()}}


@dataclass(frozen=True)
class CloudRunEvaluation:
    """What :func:`evaluate_run` measured.

    Attributes
    ----------
    evaluation : CloudEvaluation
        The scores on the test split.
    metrics : dict
        The JSON-ready report (``model``, ``task``, ``data``, ``split``, ``clouds``,
        ``metrics``: :meth:`CloudEvaluation.summary`, ``title``), as in ``metrics.json``.
    files : dict of str to Path
        ``metrics.json`` and ``confusion.png`` when an output folder was given, else empty.
    """

    evaluation: CloudEvaluation = field(repr=False)
    metrics: dict[str, Any]
    files: dict[str, Path] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the report, what ``robopercept nn cloud eval --json`` prints."""
        return dict(self.metrics)


def _data_name(data: Any) -> str:
    """``data`` (a name or a folder) as text, checked to be one."""
    if not isinstance(data, str | os.PathLike):
        raise ArgumentError(
            "--data must be shapes, shapes-partial, shapes-noisy or a folder "
            f"root/<class>/*.off; got {plain_repr(data)}"
        )
    return os.fspath(data)


def _load_sets(
    data: str, shapes: int, n_points: int, seed: int, progress: bool, test_only: bool = False
) -> CloudSets:
    """:func:`cloud_sets`, its errors an :class:`~robopercept.errors.ArgumentError`
    starting with ``--data`` (exit 2 on the command line)."""
    try:
        return cloud_sets(
            data,
            shapes=shapes,
            n_points=n_points,
            seed=seed,
            progress=progress,
            test_only=test_only,
        )
    except InputError as exc:
        raise ArgumentError(f"--data: {exc}") from None


def _write_metrics(
    out: Path, metrics: dict[str, Any], ev: CloudEvaluation, names: list[str]
) -> list[Path]:
    """Write ``metrics.json`` and ``confusion.png`` (classes, or parts) into ``out``."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file in the way, a read-only parent
        raise WriteError(describe_write_error(out, exc), exc.errno, str(out)) from None
    atomic_write(out / "metrics.json", json.dumps(strict_json(metrics), indent=1))
    k = len(names)
    pic = confusion_picture(ev.confusion[:k, :k], names, title=metrics.get("title", ""))
    return [out / "metrics.json", write_image(out / "confusion.png", pic)]


def _history_so_far(ckpt: Path, stamp: int | None, path: Path) -> None:
    """After an interruption: the history of the last complete epoch (the checkpoint's),
    written to ``path`` when this run wrote (or resumed) that checkpoint."""
    try:
        if ckpt.exists() and ckpt.stat().st_mtime_ns != stamp:
            path.write_text(json.dumps(load_checkpoint(ckpt)["history"], indent=1))
    except Exception:  # never hide the interruption behind this
        pass


def train_run(
    data: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    model: str = "pointnet",
    task: str = "classify",
    config: TrainConfig | None = None,
    shapes: int = 100,
    n_points: int = 1024,
    width: float = 0.5,
    k: int = 16,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> CloudTrainResult:
    """Train a point-cloud network on ``data`` and write the run folder ``out_dir``
    (module docstring): what ``robopercept nn cloud train`` does.

    Steps: the run folder is checked
    (:func:`~robopercept.nn.train.runs.prepare_run_folder`); :func:`cloud_sets` with
    ``config.seed``; the network built with ``config.seed``
    (:func:`~robopercept.nn.cloud.train.build_cloud_model`: PointNet with ``width``,
    DGCNN with ``k``; a part segmenter (``task="segment"``) takes the object's category);
    :func:`~robopercept.nn.cloud.train.train_cloud_model` on the training split with the
    validation split choosing the kept epoch (accuracy, or instance mIoU), a checkpoint
    after every epoch; the network saved (``model.pt``, with the data, shapes, points and
    seed it was trained on) and scored on the test split.

    Parameters
    ----------
    data : str or path
        ``"shapes"``, ``"shapes-partial"``, ``"shapes-noisy"`` or a folder
        (:func:`cloud_sets`).
    out_dir : path
        The run folder (created).
    model : {"pointnet", "dgcnn"}
    task : {"classify", "segment"}
    config : TrainConfig, optional
        Epochs, batch size, AdamW learning rate, seed (data, split, weights), device.
    shapes : int
        Procedural data: training shapes per class.
    n_points : int
        Points per cloud.
    width : float
        PointNet: the channel multiplier, in (0, 8].
    k : int
        DGCNN: the neighbours of each point, at most ``n_points``.
    resume : bool
        Continue the run in ``out_dir`` from its ``checkpoint.pt`` (same data, model and
        configuration): it ends with the weights of an uninterrupted run.
    overwrite : bool
        Start afresh in a folder that already holds a run (refused otherwise).
    progress : bool
        A line about the data and progress bars on stderr.

    Returns
    -------
    CloudTrainResult

    Raises
    ------
    RunExistsError
        ``out_dir`` holds a run and neither ``resume`` nor ``overwrite`` was given.
    InputError
        A bad setting (the message names its flag), data that cannot be loaded (the
        message starts with ``--data``), ``resume`` without a checkpoint; the errors of
        :func:`~robopercept.nn.cloud.train.train_cloud_model`.

    Examples
    --------
    >>> train_run("shapes", "run", model="pointnet++")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: model (--model) must be one of ...
    """
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    name = _data_name(data)
    check_choice(model, "model (--model)", CLOUD_MODELS)
    check_choice(task, "task (--task)", ("classify", "segment"))
    shapes = check_count(shapes, "shapes (--shapes)", 1, 1_000_000)
    n_points = check_count(n_points, "n_points (--points)", 1, 1 << 20)
    seed = check_count(cfg.seed, "config.seed (--seed)", 0, 2**31 - 1)
    width = check_real(width, "width (--width)", 0.0, 8.0, low_inclusive=False)
    k = check_int(k, "k (--k)", 1)
    if model == "dgcnn" and k > n_points:
        raise InputError(f"--k: at most --points ({n_points}); got {k}")
    progress = check_bool(progress, "progress")
    ckpt = prepare_run_folder(out_dir, resume=resume, overwrite=overwrite)
    out = ckpt.parent
    sets = _load_sets(name, shapes, n_points, seed, progress)
    train, val, test = sets.train, sets.val, sets.test
    if len(train) < 2:  # batch norm learns from two clouds or more
        raise InputError(
            f"--data {name}: {len(train)} cloud left to train on after the held-out "
            "splits; training needs at least 2 (batch norm learns from two clouds or "
            "more): add clouds"
        )
    segment = task == "segment"
    if progress:
        print(
            f"nn cloud train: {model} ({task}) on {name}: {len(train)} training, "
            f"{'no' if val is None else len(val)} validation, {len(test)} test clouds of "
            f"{n_points} points"
            + (
                " (too few clouds to hold any out for validation: the last epoch is kept)"
                if val is None
                else ""
            ),
            file=sys.stderr,
        )
    settings: dict[str, Any] = {"task": task}
    if model == "pointnet":
        settings["width"] = width
    else:
        settings["k"] = k
    if segment:
        settings["num_categories"] = train.num_classes
    outputs = train.num_parts if segment else train.num_classes
    net = build_cloud_model(model, outputs, seed=seed, **settings)
    stamp = ckpt.stat().st_mtime_ns if ckpt.exists() and not resume else None
    t0 = time.perf_counter()
    try:
        hist = train_cloud_model(
            net, train, cfg, val=val, progress=progress, checkpoint=ckpt, resume=resume
        )
        # written before the model: a signal during the model's save must leave the
        # history as one during training does
        (out / "history.json").write_text(json.dumps(hist.to_dict(), indent=1))
    except BaseException:  # Ctrl-C, SIGTERM, a failure: keep the history of the last epoch
        _history_so_far(ckpt, stamp, out / "history.json")
        raise
    seconds = time.perf_counter() - t0
    save_cloud_model(
        out / "model.pt",
        net,
        list(train.class_names),
        part_names=list(train.part_names) if segment else (),
        part_classes=train.part_classes if segment else None,
        n_points=n_points,
        data=name,
        shapes=shapes,
        seed=seed,
    )
    ev = evaluate_cloud_model(net, test)
    names = list(train.part_names if segment else train.class_names)
    metrics = {
        "model": model,
        "task": task,
        "data": name,
        "split": "test",
        "clouds": len(test),
        "validation_clouds": 0 if val is None else len(val),
        "best_epoch": hist.best_epoch,
        "metrics": ev.summary(),
        "title": f"{model} on {name}: test",
    }
    written = [out / "model.pt", out / "history.json", *_write_metrics(out, metrics, ev, names)]
    return CloudTrainResult(
        out, {p.name: p for p in written}, metrics, hist, ev, hist.best_epoch, seconds
    )


def evaluate_run(
    model: str | os.PathLike[str],
    data: str | os.PathLike[str],
    *,
    shapes: int = 100,
    n_points: int = 1024,
    seed: int = 0,
    device: str | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    progress: bool = True,
) -> CloudRunEvaluation:
    """Score a saved network on the test split of ``data``: what
    ``robopercept nn cloud eval`` does.

    The network (a run folder, i.e. its ``model.pt``, or the file itself) is loaded
    (:func:`~robopercept.nn.cloud.train.load_cloud_model`), the data split as for
    training (:func:`cloud_sets` with the same ``shapes``, ``n_points`` and ``seed``), and
    the test split scored (:func:`~robopercept.nn.cloud.train.evaluate_cloud_model`).

    Parameters
    ----------
    model : path
        A run folder or a ``model.pt``.
    data : str or path
        As in :func:`train_run`; its classes must be the network's.
    shapes, n_points, seed : int
        The data's settings (those of the training run).
    device : str, optional
        Where to run the network (default: the CPU).
    out_dir : path, optional
        Write ``metrics.json`` and ``confusion.png`` there.
    progress : bool
        Progress bars on stderr while the data are made or read.

    Returns
    -------
    CloudRunEvaluation

    Raises
    ------
    FileFormatError
        A missing or unreadable network.
    InputError
        Data that cannot be loaded or whose classes are not the network's (the messages
        start with ``--data``); a bad device.
    """
    given = as_path(model, "model (RUN_OR_MODEL)")
    path = given / "model.pt" if given.is_dir() else given
    name = _data_name(data)
    shapes = check_count(shapes, "shapes (--shapes)", 1, 1_000_000)
    n_points = check_count(n_points, "n_points (--points)", 1, 1 << 20)
    seed = check_count(seed, "seed (--seed)", 0, 2**31 - 1)
    progress = check_bool(progress, "progress")
    out = check_output_folder(out_dir)
    net, info = load_cloud_model(path)
    if device:
        net.to(resolve_device(device))
    sets = _load_sets(name, shapes, n_points, seed, progress, test_only=True)
    if list(sets.test.class_names) != list(info["class_names"]):
        raise ArgumentError(
            f"--data: its classes {list(sets.test.class_names)} are not the model's "
            f"{info['class_names']}"
        )
    ev = evaluate_cloud_model(net, sets.test)
    task = cloud_model_spec(net).task
    segment = task == "segment"
    names = list(info["part_names"] if segment else info["class_names"])
    metrics = {
        "model": os.fspath(model),
        "task": task,
        "data": name,
        "split": "test",
        "clouds": len(sets.test),
        "metrics": ev.summary(),
        "title": f"{given.name} on {name}: test",
    }
    files: dict[str, Path] = {}
    if out is not None:
        files = {p.name: p for p in _write_metrics(out, metrics, ev, names)}
    return CloudRunEvaluation(ev, metrics, files)


# ----------------------------------------------------------------------------- files
def shipped_cloud_model(name: str = "pointnet") -> Path:
    """The path of a shipped model: ``"pointnet"`` (the default classifier), ``"dgcnn"``
    or ``"pointnet-parts"`` (part segmentation), trained on the procedural shapes.

    Raises
    ------
    InputError
        Unknown name, or the file is not installed (the message gives the command that
        builds it).
    """
    check_choice(name, "name", tuple(SHIPPED_CLOUD_MODELS))
    return shipped_model_path("cloud", name)


@dataclass(frozen=True)
class CloudPrediction:
    """What :func:`classify_cloud_file` found in one file.

    Attributes
    ----------
    path : str
    label : str
        The most probable class.
    probabilities : dict of str to float
        Every class's probability, most probable first.
    points : (n, 3) float32 ndarray
        The sampled, unit-sphere-normalized points the network saw.
    parts : (n,) int64 ndarray or None
        Per-point part ids (with a segmenter).
    part_names : tuple of str
    """

    path: str
    label: str
    probabilities: dict[str, float]
    points: np.ndarray
    parts: np.ndarray | None = None
    part_names: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the class, the probabilities, and the part counts."""
        out: dict[str, Any] = {
            "file": self.path,
            "class": self.label,
            "probabilities": {k: round(v, 6) for k, v in self.probabilities.items()},
            "points": int(self.points.shape[0]),
        }
        if self.parts is not None:
            ids, counts = np.unique(self.parts, return_counts=True)
            out["part_points"] = {
                self.part_names[i]: int(c) for i, c in zip(ids, counts, strict=True)
            }
        return out


def classify_cloud_file(
    path: str | os.PathLike[str],
    model: nn.Module,
    info: dict[str, Any],
    *,
    segmenter: tuple[nn.Module, dict[str, Any]] | None = None,
    n_points: int | None = None,
    rng: int = 0,
) -> CloudPrediction:
    """Classify (and with ``segmenter``, segment) the cloud or mesh in one file.

    The file (PLY or PCD cloud, OFF or PLY mesh) is read and sampled to ``n_points``
    (default: the count the model was trained on) and normalized to the unit sphere by
    :func:`~robopercept.nn.cloud.data.read_cloud_file`; the classifier gives the class
    probabilities; the segmenter, given the predicted class as the category, labels each
    point with the most probable part of that class.

    Returns
    -------
    CloudPrediction
    """
    cloud_model_spec(model)
    if not isinstance(info, dict) or not isinstance(info.get("class_names"), (list, tuple)):
        raise InputError(
            f"info must be load_cloud_model's dict (with class_names); got {plain_repr(info)}"
        )
    if segmenter is not None and not (
        isinstance(segmenter, tuple)
        and len(segmenter) == 2
        and isinstance(segmenter[1], dict)
        and cloud_model_spec(segmenter[0]).task == "segment"
    ):
        raise InputError(
            "segmenter must be a (model, info) pair of a segmentation network, as "
            f"load_cloud_model returns; got {plain_repr(segmenter)}"
        )
    n = int(info.get("n_points", 1024)) if n_points is None else check_int(n_points, "n_points", 1)
    pts = read_cloud_file(path, n, rng=rng)
    prob = predict_clouds(model, pts)
    names = list(info["class_names"])
    order = np.argsort(-prob)
    label = int(order[0])
    parts = None
    part_names: tuple[str, ...] = ()
    if segmenter is not None:
        seg, sinfo = segmenter
        if list(sinfo["class_names"]) != names:
            raise InputError(
                "the segmenter was trained on other classes than the classifier: "
                f"{sinfo['class_names']} vs {names}"
            )
        pp = predict_clouds(seg, pts, category=[label])
        pcs = np.asarray(sinfo["part_classes"])
        pp = np.where(pcs[None, : pp.shape[-1]] == label, pp, -1.0)
        parts = pp.argmax(-1).astype(np.int64)
        part_names = tuple(sinfo["part_names"])
    return CloudPrediction(
        str(path),
        names[label],
        {names[i]: float(prob[i]) for i in order},
        pts,
        parts,
        part_names,
    )
