"""A pose training run from data to files: what ``robopercept nn pose train|eval`` does.

:func:`train_run` is the recipe end to end: the data (:func:`load_pose_data`: the
built-in procedural figures over real photos, MPII's 16 joints, or your own COCO
keypoints file cut into top-down crops, :mod:`robopercept.nn.pose.crops`; split into
training and validation images), a network of
:func:`~robopercept.nn.pose.networks.build_pose_model` (``"hrnet"``, ``"heatmap"`` or
``"deeppose"``) trained by :func:`~robopercept.nn.pose.train.train_pose` (THE loop,
:func:`~robopercept.nn.train.loop.train_loop`, keeping the epoch of the best validation
PCK@0.1), for DeepPose its cascade stages
(:func:`~robopercept.nn.pose.train.train_cascade`), then the validation split scored
(:func:`~robopercept.nn.pose.evaluate.evaluate_pose`) and the run folder written:

========================  =============================================================
``checkpoint.pt``         the network's last complete epoch (model, optimizer, schedule,
                          random states, history): written after every epoch, so Ctrl-C
                          keeps it, and ``resume=True`` (``--resume``) continues from it
``checkpoint.best.pt``    the network's best epoch's weights
``model.pt``              the network, its settings, the skeleton and the cascade stages
                          (:func:`~robopercept.nn.pose.networks.save_pose_model`; what
                          ``eval`` and the image form load)
``history.json``          ``{"network": ..., "stages": [...]}``: per epoch the mean loss,
                          seconds and validation PCK, the epoch kept
``metrics.json``          PCK and COCO keypoint AP/AR on the validation split
``samples.png``           the first validation images with the predicted skeletons
                          (:func:`~robopercept.nn.pose.inference.samples_picture`)
========================  =============================================================

**Resuming.** The network resumes exactly: :func:`~robopercept.nn.train.loop.train_loop`
restores its weights, optimizer, schedule and random states and ends with the weights of
an uninterrupted run. The DeepPose cascade stages keep no checkpoint: a resumed run
trains them again, from scratch, after the network (which, when the interruption came
during the stages, runs no epoch more). A stage is deterministic given the network's
weights, its seed (``config.seed``) and torch's random state, which the checkpoint
restores, so a resumed run's ``model.pt`` equals an uninterrupted run's, stages
included. Ctrl-C (``KeyboardInterrupt``) propagates after ``history.json`` is written
with the network's epochs done so far.

:func:`evaluate_run` scores a trained model (``model.pt`` or its run folder) on the
validation split of the same data (same ``images``, ``size`` and ``seed``), or on every
person of a COCO file.
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

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_int,
    check_size,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.fileio import strict_json
from robopercept.imaging import write_image
from robopercept.nn.data.datasets import stratified_split
from robopercept.nn.pose.crops import pose_set_from_coco
from robopercept.nn.pose.data import POSE_DATA, PoseDataset, pose_sets
from robopercept.nn.pose.evaluate import PoseEvaluation, evaluate_pose
from robopercept.nn.pose.inference import samples_picture
from robopercept.nn.pose.networks import (
    POSE_MODELS,
    DeepPoseRefiner,
    build_pose_model,
    load_pose_model,
    save_pose_model,
)
from robopercept.nn.pose.train import PoseHistory, train_cascade, train_pose
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.runs import check_output_folder, prepare_run_folder

__all__ = [
    "RUN_FILES",
    "PoseRunEvaluation",
    "PoseTrainResult",
    "evaluate_run",
    "load_pose_data",
    "model_path",
    "train_run",
]

#: the task's files of a run folder, beside ``checkpoint.pt`` and ``checkpoint.best.pt``
RUN_FILES = ("model.pt", "history.json", "metrics.json", "samples.png")

#: cascade stages at most (:func:`~robopercept.nn.pose.train.train_cascade`'s limit)
_MAX_STAGES = 8


@dataclass(frozen=True)
class PoseTrainResult:
    """What :func:`train_run` made.

    Attributes
    ----------
    out_dir : Path
    files : dict of str to Path
        :data:`RUN_FILES` by name (``"model.pt"`` -> ``out_dir / "model.pt"``...).
    checkpoint : Path
        ``out_dir / "checkpoint.pt"`` (the best weights in ``checkpoint.best.pt``).
    metrics : dict
        The content of ``metrics.json``: model, data, split, best epoch, metrics.
    history : dict
        The content of ``history.json``: ``"network"`` and ``"stages"``.
    best_epoch : int
        The network's epoch kept (1-based).
    seconds : float
        Training time (the network and its stages).
    evaluation : PoseEvaluation
        The model (stages applied) on the validation split.
    """

    out_dir: Path
    files: dict[str, Path]
    checkpoint: Path
    metrics: dict[str, Any]
    history: dict[str, Any] = field(repr=False)
    best_epoch: int
    seconds: float
    evaluation: PoseEvaluation = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """``metrics.json``'s content with ``"files"`` (name -> path text): what
        ``robopercept nn pose train --json`` prints."""
        return {**self.metrics, "files": {n: str(p) for n, p in self.files.items()}}


@dataclass(frozen=True)
class PoseRunEvaluation:
    """What :func:`evaluate_run` measured.

    Attributes
    ----------
    model : str
        The model as given (a run folder or a ``model.pt``).
    data : str
    n : int
        Validation images scored.
    evaluation : PoseEvaluation
    metrics : dict
        Model, data, images, flip test, the metrics by name and the PCK@0.1 per joint
        (NaN for a joint no image labels): ``metrics.json``'s content before
        :func:`~robopercept.fileio.strict_json`.
    files : dict of str to Path
        ``{"metrics.json": path}`` when ``out_dir`` was given, else empty.
    """

    model: str
    data: str
    n: int
    evaluation: PoseEvaluation = field(repr=False)
    metrics: dict[str, Any]
    files: dict[str, Path]

    def to_dict(self) -> dict[str, Any]:
        """:attr:`metrics` as strict JSON (NaN as None): what ``robopercept nn pose eval
        --json`` prints."""
        return dict(strict_json(self.metrics))


# --------------------------------------------------------------------------- data


def _data_args(
    data: Any, images: Any, size: Any, seed: Any
) -> tuple[str, int, tuple[int, int], int]:
    """The data arguments, checked, with their flags in the messages."""
    if _is_coco(data):
        if not Path(data).is_file():
            raise InputError(f"--data: COCO file {data} does not exist")
        data = os.fspath(data)
    else:
        data = check_choice(data, "--data (figures or a COCO keypoints .json)", POSE_DATA)
    if isinstance(images, bool) or not isinstance(images, int):
        raise InputError(f"--images must be an integer; got {plain_repr(images)}")
    if images < 2:
        raise InputError("--images: give at least 2")
    if images > 1_000_000:
        raise InputError(f"--images: at most 1000000 figures; got {images}")
    w, h = check_size(size, "--size", 32, 1024)
    seed = check_int(seed, "--seed", 0)
    if seed >= 2**32:
        raise InputError(f"--seed must be below 2**32; got {seed}")
    return data, images, (w, h), seed


def _is_coco(data: Any) -> bool:
    return isinstance(data, (str, os.PathLike)) and os.fspath(data).lower().endswith(".json")


def load_pose_data(
    data: str = "figures",
    *,
    images: int = 2000,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    images_dir: str | os.PathLike[str] | None = None,
    evaluate: bool = False,
    allow_outside: bool = False,
) -> tuple[PoseDataset, PoseDataset]:
    """The training and validation sets of a pose data set, as ``robopercept nn pose
    train|eval`` make them.

    ``"figures"``: :func:`~robopercept.nn.pose.data.pose_sets` with a one-image test
    split (unused here): ``images`` procedural figures for training (seed ``seed``) and
    a tenth of them, at least 1, for validation (seed ``1000 + seed``). A COCO keypoints
    ``.json`` file (your own people): its persons as top-down crops of ``size``
    (:func:`~robopercept.nn.pose.crops.pose_set_from_coco`), split 80/20 with ``seed``
    (neither part empty, :func:`~robopercept.nn.data.datasets.stratified_split`), or
    with ``evaluate`` all of them for validation (and training).

    Parameters
    ----------
    data : str
        ``"figures"`` (:data:`~robopercept.nn.pose.data.POSE_DATA`) or a COCO keypoints
        JSON file.
    images : int
        Training images, at least 2 (figures).
    size : (width, height)
        Pixels, each side in [32, 1024].
    seed : int
        >= 0.
    images_dir : path, optional
        The COCO file's images (default: its folder).
    evaluate : bool
        The data is for evaluation: a COCO file is not split.
    allow_outside : bool, default False
        Your own annotations: read images they place outside their folder
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).

    Returns
    -------
    train, val : PoseDataset

    Raises
    ------
    InputError
        Unknown data, fewer than 2 images, a bad size or seed (the message names the
        flag: ``--data``, ``--images``, ``--size``, ``--seed``).

    Examples
    --------
    >>> train, val = load_pose_data("figures", images=10, size=(64, 64))
    >>> len(train), len(val), train.skeleton.name
    (10, 1, 'mpii16')
    """
    data, images, size, seed = _data_args(data, images, size, seed)
    if _is_coco(data):
        full = pose_set_from_coco(data, images_dir, size, allow_outside=allow_outside)
        if check_bool(evaluate, "evaluate"):
            return full, full
        if len(full) < 2:
            raise InputError(
                f"--data {data}: {len(full)} person with keypoints; training needs at least 2 "
                "(one to train on, one to validate)"
            )
        train, val = stratified_split(np.zeros(len(full), np.int64), (0.8, 0.2), seed)
        return full.subset(train), full.subset(val)
    sets = pose_sets(data, images, size, seed, test_images=1)
    return sets.train, sets.val


def model_path(model: str | os.PathLike[str]) -> Path:
    """A run folder's ``model.pt``, or ``model`` itself when it is a file.

    Raises
    ------
    InputError
        Neither exists (the message names ``RUN_OR_MODEL``).

    Examples
    --------
    >>> model_path("/nonexistent/run")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: RUN_OR_MODEL: /nonexistent/run does not exist ...
    """
    p = as_path(model, "RUN_OR_MODEL (a run folder or its model.pt)")
    p = p / "model.pt" if p.is_dir() else p
    if not p.is_file():
        raise InputError(f"RUN_OR_MODEL: {p} does not exist (a run folder or its model.pt)")
    return p


# --------------------------------------------------------------------------- train


def _write_json(path: Path, value: Any) -> None:
    path.write_text(json.dumps(value, indent=1))


def _interrupted_history(ckpt: Path, hist: PoseHistory | None) -> dict[str, Any] | None:
    """``history.json``'s content when training stops early: the network's history
    (from the checkpoint while it trains), no stage."""
    if hist is not None:
        return {"network": hist.to_dict(), "stages": []}
    if ckpt.exists():
        saved = load_checkpoint(ckpt).get("history")
        if isinstance(saved, dict):
            return {"network": saved, "stages": []}
    return None


def train_run(
    data: str,
    out_dir: str | os.PathLike[str],
    *,
    model: str = "hrnet",
    images: int = 2000,
    size: tuple[int, int] = (128, 128),
    config: TrainConfig | None = None,
    width: int = 16,
    stages: int = 1,
    images_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    allow_outside: bool = False,
) -> PoseTrainResult:
    """Train pose network ``model`` on ``data`` and write the run folder ``out_dir``
    (module docstring).

    Steps: :func:`~robopercept.nn.train.runs.prepare_run_folder` (before any work);
    :func:`load_pose_data` with ``config.seed``; the network built with
    ``config.seed`` (:func:`~robopercept.nn.pose.networks.build_pose_model`, ``width``;
    DeepPose for ``size``); :func:`~robopercept.nn.pose.train.train_pose` with the
    skeleton's flip pairs, checkpointing every epoch; for ``"deeppose"``, ``stages``
    cascade stages (:func:`~robopercept.nn.pose.train.train_cascade`); ``model.pt``,
    ``history.json``; the validation split scored
    (:func:`~robopercept.nn.pose.evaluate.evaluate_pose`, flip test) into
    ``metrics.json``; ``samples.png``.

    Parameters
    ----------
    data : str
        ``"figures"`` or a COCO keypoints JSON file (:func:`load_pose_data`).
    out_dir : path
        The run folder (created).
    model : {'hrnet', 'heatmap', 'deeppose'}
    images : int
        Training images (validation: a tenth, at least 1).
    size : (width, height)
        Image size; both sides multiples of 16.
    config : TrainConfig, optional
        Epochs, batch size, learning rate, seed (data, split and weights), device.
    width : int
        The network's width.
    stages : int
        DeepPose: cascade stages after the network, 0 to 8 (ignored for the others).
    images_dir : path, optional
        A COCO file's images (default: its folder).
    allow_outside : bool, default False
        Your own annotations: read images they place outside their folder
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).
    resume : bool
        Continue the run in ``out_dir`` from its ``checkpoint.pt`` (same data, model and
        configuration): ends as an uninterrupted run would.
    overwrite : bool
        Start afresh in a folder that already holds a run (refused otherwise).
    progress : bool
        A line naming the data and a progress bar on stderr.

    Returns
    -------
    PoseTrainResult

    Raises
    ------
    InputError
        Bad data arguments (:func:`load_pose_data`), an unknown model, a size not a
        multiple of 16, ``stages`` out of 0..8, ``resume`` and ``overwrite`` together,
        ``resume`` without a checkpoint; errors of training.
    RunExistsError
        ``out_dir`` holds a run and neither ``resume`` nor ``overwrite`` was given.
    FileFormatError
        Resuming from a checkpoint of another network.
    KeyboardInterrupt
        Propagated; ``checkpoint.pt`` holds the last complete epoch and
        ``history.json`` the epochs done.
    """
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    model = check_choice(model, "--model", POSE_MODELS)
    data, images, size, seed = _data_args(data, images, size, cfg.seed)
    if size[0] % 16 or size[1] % 16:
        raise InputError(f"--size: width and height must be multiples of 16; got {size}")
    width = check_int(width, "--width", 1)
    stages = check_int(stages, "--stages", 0)
    if stages > _MAX_STAGES:
        raise InputError(f"--stages: 0 to {_MAX_STAGES} cascade stages; got {stages}")
    progress = check_bool(progress, "progress")
    ckpt = prepare_run_folder(out_dir, resume=resume, overwrite=overwrite)
    out = ckpt.parent
    train, val = load_pose_data(
        data,
        images=images,
        size=size,
        seed=seed,
        images_dir=images_dir,
        allow_outside=allow_outside,
    )
    sk = train.skeleton
    if progress:
        print(
            f"nn pose train: {model} on {data} ({len(train)} training, "
            f"{len(val)} validation images)",
            file=sys.stderr,
        )
    settings: dict[str, Any] = {"width": width}
    if model == "deeppose":
        settings["image_size"] = list(size)
    net = build_pose_model(model, sk.num_joints, seed=seed, **settings)
    hist: PoseHistory | None = None
    t0 = time.perf_counter()
    try:
        hist = train_pose(
            net, train, cfg, val=val, skeleton=sk, progress=progress, checkpoint=ckpt, resume=resume
        )
        history: dict[str, Any] = {"network": hist.to_dict(), "stages": []}
        refiners: list[DeepPoseRefiner] = []
        if model == "deeppose" and stages:
            refiners, stage_hist = train_cascade(
                net, train, stages, cfg, val=val, width=width, progress=progress
            )
            history["stages"] = [h.to_dict() for h in stage_hist]
        # written before the model: a signal during the model's save must leave the
        # history as one during training does (the faults campaign's SIGTERM did not)
        _write_json(out / "history.json", history)
    except BaseException:  # Ctrl-C, SIGTERM, a failure: the last epoch is in checkpoint.pt
        partial = _interrupted_history(ckpt, hist)
        if partial is not None:
            _write_json(out / "history.json", partial)
        raise
    seconds = time.perf_counter() - t0
    files = {name: out / name for name in RUN_FILES}
    extra = {"data": data, "images": images, "size": list(size), "seed": seed}
    save_pose_model(files["model.pt"], net, model, settings, sk, refiners=refiners, **extra)
    ev = evaluate_pose(net, val, refiners=refiners)
    metrics = {
        "model": model,
        "data": data,
        "split": "validation",
        "best_epoch": hist.best_epoch,
        "metrics": ev.summary(),
    }
    _write_json(files["metrics.json"], metrics)
    write_image(files["samples.png"], samples_picture(net, val, refiners=refiners))
    return PoseTrainResult(out, files, ckpt, metrics, history, hist.best_epoch, seconds, ev)


# --------------------------------------------------------------------------- eval


def evaluate_run(
    model: str | os.PathLike[str],
    data: str = "figures",
    *,
    images: int = 2000,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    flip: bool = True,
    device: str | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    images_dir: str | os.PathLike[str] | None = None,
    allow_outside: bool = False,
) -> PoseRunEvaluation:
    """PCK and COCO keypoint AP of a trained pose network on the validation split of
    ``data`` (:func:`load_pose_data` with the same ``images``, ``size`` and ``seed`` as
    its training run; a COCO file whole), cascade stages applied
    (:func:`~robopercept.nn.pose.evaluate.evaluate_pose`).

    Parameters
    ----------
    model : path
        A run folder or a ``model.pt`` (:func:`model_path`).
    data : str
    images, size, seed
        As :func:`load_pose_data`.
    flip : bool
        The flip test.
    device : str, optional
        Where the network runs (default: the CPU).
    out_dir : path, optional
        A folder (created) for ``metrics.json`` (:attr:`PoseRunEvaluation.to_dict`).
    images_dir : path, optional
        A COCO file's images (default: its folder); the whole file is scored.
    allow_outside : bool, default False
        Your own annotations: read images they place outside their folder
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).

    Returns
    -------
    PoseRunEvaluation

    Raises
    ------
    InputError
        No such model (``RUN_OR_MODEL``), bad data arguments, a model of another
        skeleton than the data's.
    FileFormatError
        A file that is not a pose network's.
    """
    path = model_path(model)
    data, images, size, seed = _data_args(data, images, size, seed)
    flip = check_bool(flip, "flip (--no-flip)")
    out = check_output_folder(out_dir)
    net, info = load_pose_model(path)
    if device is not None:
        net.to(resolve_device(device))
    _, val = load_pose_data(
        data,
        images=images,
        size=size,
        seed=seed,
        images_dir=images_dir,
        evaluate=True,
        allow_outside=allow_outside,
    )
    joints = tuple(info["skeleton"].joints)
    if joints != tuple(val.skeleton.joints):
        raise InputError(
            f"RUN_OR_MODEL {path} finds the {len(joints)} joints of {info['skeleton'].name}; "
            f"--data {data} has the {val.skeleton.num_joints} of {val.skeleton.name}: "
            "evaluate on the kind of data it was trained on"
        )
    ev = evaluate_pose(net, val, refiners=info["refiners"], flip=flip)
    metrics = {
        "model": str(model),
        "data": data,
        "images": len(val),
        "flip_test": flip,
        "metrics": ev.summary(),
        "pck_per_joint": dict(
            zip(val.skeleton.joints, [float(v) for v in ev.per_joint], strict=True)
        ),
    }
    files: dict[str, Path] = {}
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        files["metrics.json"] = out / "metrics.json"
        _write_json(files["metrics.json"], strict_json(metrics))
    return PoseRunEvaluation(str(model), data, len(val), ev, metrics, files)
