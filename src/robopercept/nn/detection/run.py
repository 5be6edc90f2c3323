"""A detection run from data to files: what ``robopercept nn detect train|eval`` does.

:func:`load_detection_data` turns the command line's ``--data`` into a training and a
validation :class:`~robopercept.nn.detection.data.DetectionDataset`: the procedural
shapes or the digit canvases of :mod:`robopercept.nn.detection.synthetic` (split 80/20,
seeded), the DeepForest NEON tiles of :mod:`robopercept.nn.detection.deepforest`
(training tiles, held-out strip), or a COCO file
(:meth:`~robopercept.nn.detection.data.DetectionDataset.from_coco`; split 80/20 for
training, wholly the validation set for evaluation).

:func:`train_run` builds the detector (:func:`~robopercept.nn.detection.zoo.build_detector`,
weights seeded by ``config.seed``), trains it with
:func:`~robopercept.nn.detection.train.train_detector` (THE loop,
:func:`~robopercept.nn.train.loop.train_loop`: validation every ``val_every`` epochs,
the weights of the epoch with the best validation mAP@[.5:.95] kept, optional weight
averaging), evaluates the kept weights on the validation split
(:func:`~robopercept.nn.detection.train.evaluate_detector`, the 12 COCO numbers) and
writes the run folder:

========================  =============================================================
``checkpoint.pt``         the last complete epoch (model, optimizer, schedule, random
                          states, history), written after every epoch: Ctrl-C or
                          SIGTERM keeps it, and ``resume=True`` (``--resume``)
                          continues from it to the weights of an uninterrupted run
``checkpoint.best.pt``    the best epoch's weights
``model.pt``              the kept weights with the constructor settings, the class
                          names and the run's data settings
                          (:func:`~robopercept.nn.detection.zoo.save_detector`)
``history.json``          per epoch the mean losses and seconds, the validation
                          mAP@[.5:.95] of the evaluated epochs, the kept epoch (written
                          from ``checkpoint.pt`` too when the run is interrupted)
``metrics.json``          the 12 COCO numbers on the validation split
``pr_curves.png``         precision-recall curves at IoU 0.5, per class
                          (:func:`~robopercept.nn.coco.evaluate.write_pr_curves`)
``samples.png``           the first four validation images in a 2 x 2 grid, enlarged to
                          read at 1080p, with the detections (score >= 0.3) and the
                          ground truth in two colours and a legend, "nothing
                          detected" where there is none
                          (:func:`robopercept.viz.detection.detection_samples_picture`)
========================  =============================================================

A folder that already holds a run (its ``checkpoint.pt``) is refused unless the run is
resumed or replaced (:func:`~robopercept.nn.train.runs.prepare_run_folder`); the check
comes before any data is made or read.

:func:`evaluate_run` evaluates a run (its folder or ``model.pt``) on the validation split
of the same built-in set (same ``images``, ``size`` and ``seed``) or on a whole COCO
file, optionally with test-time augmentation
(:class:`~robopercept.nn.detection.tta.TestTimeAugmentation`), and can write
``metrics.json`` and ``pr_curves.png``.

Errors in what the command line takes as ``--data``, ``--images``, ``--images-dir`` or
``RUN_OR_MODEL`` are :class:`~robopercept.errors.ArgumentError` (an
:class:`~robopercept.errors.InputError` that the command line reports as a usage
error, exit 2).
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from torch import nn

from robopercept._checks import as_path, check_bool, check_choice, check_int, check_real
from robopercept.errors import ArgumentError, FileFormatError, InputError
from robopercept.imaging import write_image
from robopercept.nn._guards import check_device
from robopercept.nn.coco.evaluate import CocoEvaluation, write_pr_curves
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.deepforest import DEEPFOREST_FOLDER, deepforest_tiles
from robopercept.nn.detection.synthetic import (
    digits_detection_set,
    procedural_detection_set,
    single_digit_set,
)
from robopercept.nn.detection.train import DetectionHistory, evaluate_detector, train_detector
from robopercept.nn.detection.tta import TTA_VIEWS, TestTimeAugmentation
from robopercept.nn.detection.zoo import build_detector, detect_arrays, load_detector, save_detector
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import TrainConfig
from robopercept.nn.train.runs import check_output_folder, prepare_run_folder
from robopercept.viz.detection import detection_samples_picture

__all__ = [
    "BUILTIN_DATA",
    "RUN_DETECTORS",
    "RUN_FILES",
    "VAL_FRACTION",
    "DetectionEvaluation",
    "DetectionTrainResult",
    "evaluate_run",
    "load_detection_data",
    "train_run",
]

#: the built-in data sets of ``data`` (``--data``); anything else must be a COCO JSON file
BUILTIN_DATA = ("shapes", "digits", "trees")
#: the detectors :func:`train_run` trains (names of :data:`~robopercept.nn.detection.zoo.DETECTORS`)
RUN_DETECTORS = ("fcos", "faster", "fast", "rcnn", "localizer")
#: the share of a built-in synthetic set or a COCO file held out for validation
VAL_FRACTION = 0.2
#: the files :func:`train_run` writes beside the checkpoints, in the order it lists them
RUN_FILES = ("model.pt", "history.json", "metrics.json", "pr_curves.png", "samples.png")
#: detections drawn in ``samples.png``: score at least this
_SAMPLE_SCORE = 0.3


@dataclass(frozen=True)
class DetectionEvaluation:
    """What :func:`evaluate_run` measured.

    Attributes
    ----------
    model : str
        The run folder or model file, as given.
    data : str
        The data, as given.
    tta : str or None
        The test-time augmentation (a name of :data:`~robopercept.nn.detection.tta.TTA_VIEWS`).
    images : int
        Images evaluated.
    evaluation : CocoEvaluation
        The 12 COCO numbers (``stats``) and the precision-recall tables.
    metrics : dict
        ``model``, ``data``, ``tta``, ``images``, ``metrics`` (the named COCO numbers)
        and ``stats``: the content of ``metrics.json``.
    files : dict of str to Path
        ``metrics.json`` and ``pr_curves.png`` when written (``out_dir``), else empty.
    """

    model: str
    data: str
    tta: str | None
    images: int
    evaluation: CocoEvaluation = field(repr=False)
    metrics: dict[str, Any] = field(repr=False)
    files: dict[str, Path] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: :attr:`metrics` (what ``nn detect eval --json`` prints)."""
        return dict(self.metrics)


@dataclass(frozen=True)
class DetectionTrainResult:
    """What :func:`train_run` made.

    Attributes
    ----------
    out_dir : Path
        The run folder.
    files : dict of str to Path
        ``model.pt``, ``history.json``, ``metrics.json``, ``pr_curves.png``,
        ``samples.png`` (:data:`RUN_FILES`), by name.
    checkpoint : Path
        ``checkpoint.pt`` (the last epoch; ``checkpoint.best.pt`` beside it).
    model : str
        The detector's name (:data:`RUN_DETECTORS`).
    data : str
        The data, as given.
    history : DetectionHistory
        Losses and seconds per epoch, validation figures, the kept epoch.
    best_epoch : int
        The epoch whose weights ``model.pt`` holds (1-based).
    seconds : float
        Training seconds over all epochs (validation not included).
    evaluation : CocoEvaluation
        The kept weights on the validation split.
    metrics : dict
        The content of ``metrics.json``.
    """

    out_dir: Path
    files: dict[str, Path]
    checkpoint: Path
    model: str
    data: str
    history: DetectionHistory = field(repr=False)
    best_epoch: int
    seconds: float
    evaluation: CocoEvaluation = field(repr=False)
    metrics: dict[str, Any] = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: :attr:`metrics` with the number of epochs and the files (what
        ``nn detect train --json`` prints)."""
        return {
            **self.metrics,
            "epochs": len(self.history.losses),
            "files": {name: str(p) for name, p in self.files.items()},
        }


# --------------------------------------------------------------------------- data


def _text(value: Any, name: str) -> str:
    """A path-like argument as the text the user gave (a ``str`` unchanged)."""
    p = as_path(value, name)
    return value if isinstance(value, str) else str(p)


def _check_source(data: Any, images: Any, images_dir: Any, evaluate: bool) -> tuple[str, int]:
    """Check what names the data without making or reading it: ``(data text, images)``."""
    text = _text(data, "data (--data)")
    n = check_int(images, "images (--images)", 1)
    if text in ("shapes", "digits"):
        if n < 2:
            raise ArgumentError("--images: give at least 2 (a training and a validation image)")
    elif text == "trees":
        folder = None
        if images_dir is not None and not (isinstance(images_dir, str) and not images_dir):
            folder = as_path(images_dir, "images_dir (--images-dir)")
        if folder is None or not folder.is_dir():
            raise ArgumentError(
                f"--images-dir: --data trees needs the DeepForest NEON folder, "
                f"{DEEPFOREST_FOLDER}; got {images_dir!r}"
            )
    else:
        path = Path(text)
        if path.suffix.lower() == ".json" and not path.is_file():
            raise ArgumentError(f"--data: COCO file {path} does not exist")
        if not path.is_dir() and path.suffix.lower() != ".json":
            raise ArgumentError(
                f"--data: expects one of {', '.join(BUILTIN_DATA)}, a COCO .json file or a "
                f"folder of annotated images (labelme .json, Pascal-VOC .xml or "
                f"SegmentationObject/); got {text!r}"
            )
    return text, n


def load_detection_data(
    data: str | os.PathLike[str],
    *,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    images_dir: str | os.PathLike[str] | None = None,
    model: str | None = None,
    evaluate: bool = False,
    allow_outside: bool = False,
) -> tuple[DetectionDataset, DetectionDataset]:
    """The training and validation sets of ``data`` (``--data``).

    - ``"shapes"``: :func:`~robopercept.nn.detection.synthetic.procedural_detection_set`
      of ``images`` canvases of ``size``; ``"digits"``:
      :func:`~robopercept.nn.detection.synthetic.digits_detection_set` (for the
      single-object ``"localizer"``,
      :func:`~robopercept.nn.detection.synthetic.single_digit_set`); both drawn with
      ``seed`` and split by :meth:`~robopercept.nn.detection.data.DetectionDataset.split`
      into ``1 - VAL_FRACTION`` and ``VAL_FRACTION`` (seeded by ``seed``);
    - ``"trees"``: the DeepForest NEON tiles of ``images_dir``
      (:func:`~robopercept.nn.detection.deepforest.deepforest_tiles`): its training tiles
      and its held-out strip;
    - your own annotated images: a COCO ``.json`` file with its images in
      ``images_dir`` (default: the file's folder), or a folder of labelme JSON files,
      of Pascal-VOC XML files or a VOC segmentation folder
      (:meth:`~robopercept.nn.detection.data.DetectionDataset.from_annotations`): split
      as the synthetic sets, or with ``evaluate`` wholly the validation set (and the
      training set too).

    Parameters
    ----------
    data : str or path
        A name of :data:`BUILTIN_DATA`, a COCO JSON file or an annotation folder.
    images : int
        Canvases of the synthetic sets (at least 2).
    size : (width, height)
        Canvas size of the synthetic sets.
    seed : int
        Draws and split of the synthetic sets; split of a COCO file.
    images_dir : path, optional
        The DeepForest folder (``"trees"``) or the COCO images' folder.
    model : str, optional
        The detector the data is for: ``"localizer"`` gets one digit per canvas.
    evaluate : bool
        The data is for evaluation: a COCO file is not split.
    allow_outside : bool, default False
        Your own annotations: read images they place outside their folder
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).

    Returns
    -------
    train, val : DetectionDataset

    Raises
    ------
    ArgumentError
        An unknown name, a file that is not ``.json`` or does not exist, ``"trees"``
        without its folder, fewer than 2 synthetic images, a COCO file whose folder or
        images are missing, that lists no image, or that has fewer than 2 images to
        split for training.
    InputError
        ``size``, ``seed`` or ``model`` of the wrong type or value.
    FileFormatError
        A COCO file that is not COCO JSON, an unreadable image.

    Examples
    --------
    >>> train, val = load_detection_data("shapes", images=5, size=(32, 32), seed=0)
    >>> len(train), len(val), train.classes
    (4, 1, ('circle', 'square', 'triangle', 'cross'))
    >>> load_detection_data("foo")
    Traceback (most recent call last):
    ...
    robopercept.errors.ArgumentError: --data: expects one of shapes, ...
    """
    evaluate = check_bool(evaluate, "evaluate")
    if model is not None:
        check_choice(model, "model (--model)", RUN_DETECTORS)
    seed = check_int(seed, "seed (--seed)")
    text, n = _check_source(data, images, images_dir, evaluate)
    if text in ("shapes", "digits"):
        if text == "shapes":
            ds = procedural_detection_set(n, size, rng=seed)
        elif model == "localizer":
            ds = single_digit_set(n, size, rng=seed)
        else:
            ds = digits_detection_set(n, size, rng=seed)
        train, val = ds.split((1 - VAL_FRACTION, VAL_FRACTION), rng=seed)
        return train, val
    if text == "trees":
        assert images_dir is not None  # _check_source
        tiles = deepforest_tiles(images_dir)
        return tiles.train, tiles.test
    path = Path(text)
    try:
        ds = DetectionDataset.from_annotations(path, images_dir, allow_outside=allow_outside)
    except ArgumentError:
        raise
    except InputError as exc:  # the file's or the folder's fault: a usage error
        raise ArgumentError(str(exc)) from None
    if evaluate:
        return ds, ds
    if len(ds) < 2:
        raise ArgumentError(f"--data: {path} has {len(ds)} image; training needs at least 2")
    train, val = ds.split((1 - VAL_FRACTION, VAL_FRACTION), rng=seed)
    return train, val


# --------------------------------------------------------------------------- outputs


def _write_samples(model: nn.Module, ds: DetectionDataset, path: Path, count: int = 4) -> Path:
    """The first ``count`` images of ``ds`` in a grid with their detections (score >=
    0.3) and their ground truth, told apart by colour and named in a legend
    (:func:`robopercept.viz.detection.detection_samples_picture`)."""
    n = min(count, len(ds))
    images = list(ds.images[:n])
    preds = detect_arrays(model, images)
    truth = [{"boxes": ds.boxes[i], "labels": ds.labels[i]} for i in range(n)]
    pic = detection_samples_picture(images, preds, truth, list(ds.classes), threshold=_SAMPLE_SCORE)
    return write_image(path, pic)


def _metrics(ev: CocoEvaluation, ds: DetectionDataset, extra: dict[str, Any]) -> dict[str, Any]:
    return {**extra, "images": len(ds), "metrics": ev.summary(), "stats": ev.stats.tolist()}


def _write_metrics(
    ev: CocoEvaluation, ds: DetectionDataset, out: Path, extra: dict[str, Any]
) -> dict[str, Any]:
    """Write ``metrics.json`` and ``pr_curves.png`` into ``out``; return the metrics."""
    out.mkdir(parents=True, exist_ok=True)
    metrics = _metrics(ev, ds, extra)
    (out / "metrics.json").write_text(json.dumps(metrics, indent=1))
    names = {k + 1: c for k, c in enumerate(ds.classes)}
    write_pr_curves(ev, out / "pr_curves.png", names=names)
    return metrics


def _history_json(history: dict[str, Any]) -> str:
    """The text of ``history.json`` from :class:`DetectionHistory`'s fields."""
    return json.dumps(
        {
            "losses": history["losses"],
            "seconds": history["seconds"],
            "val_AP": history["val"],
            "best_epoch": history["best_epoch"],
        },
        indent=1,
    )


def _history_from_checkpoint(ckpt: Path, path: Path) -> None:
    """Write ``history.json`` from the history in ``ckpt`` (an interrupted run's last
    complete epoch); a checkpoint that cannot be read leaves it unwritten, so that the
    interruption, not this, is what the caller sees."""
    try:
        state = load_checkpoint(ckpt)
        path.write_text(_history_json(state["history"]))
    except (FileFormatError, KeyError, TypeError, OSError):
        pass


def _stamp(path: Path) -> int | None:
    return path.stat().st_mtime_ns if path.exists() else None


# --------------------------------------------------------------------------- train


def train_run(
    data: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    model: str = "fcos",
    config: TrainConfig | None = None,
    width: int = 16,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    images_dir: str | os.PathLike[str] | None = None,
    val_every: int | None = None,
    ema: float | None = None,
    allow_outside: bool = False,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> DetectionTrainResult:
    """Train the detector ``model`` on ``data`` and write the run folder ``out_dir``
    (module docstring).

    Steps: :func:`~robopercept.nn.train.runs.prepare_run_folder` (refuses a folder
    holding a run unless ``resume`` or ``overwrite``); :func:`load_detection_data` with
    ``config.seed``; :func:`~robopercept.nn.detection.zoo.build_detector` ``(model,
    classes, seed=config.seed, width=width)``;
    :func:`~robopercept.nn.detection.train.train_detector` with validation every
    ``val_every`` epochs (the best mAP@[.5:.95] kept), ``checkpoint.pt`` after every
    epoch; ``model.pt``, ``history.json``; the kept weights on the validation split
    (:func:`~robopercept.nn.detection.train.evaluate_detector`): ``metrics.json``,
    ``pr_curves.png``; ``samples.png``.

    On Ctrl-C or SIGTERM during training the exception propagates after
    ``history.json`` is written from the last complete epoch's ``checkpoint.pt``;
    ``resume=True`` with the same arguments then ends with the weights an uninterrupted
    run has.

    Parameters
    ----------
    data : str or path
        A name of :data:`BUILTIN_DATA` or a COCO JSON file (:func:`load_detection_data`).
    out_dir : path
        The run folder (created).
    model : str
        A name of :data:`RUN_DETECTORS`.
    config : TrainConfig, optional
        Epochs, batch size, learning rate, seed (data, split and weights), device...
    width : int
        The backbone width (the detector's ``width`` setting).
    images, size, images_dir, allow_outside
        As :func:`load_detection_data`.
    val_every : int, optional
        Evaluate the validation split every this many epochs (default:
        ``max(1, epochs // 10)``).
    ema : float, optional
        Decay of the weight average validated and kept, in (0, 1)
        (:func:`~robopercept.nn.detection.train.train_detector`).
    resume : bool
        Continue the run in ``out_dir`` from its ``checkpoint.pt`` (same arguments).
    overwrite : bool
        Start afresh in a folder that already holds a run.
    progress : bool
        The data sizes and a bar per epoch on stderr.

    Returns
    -------
    DetectionTrainResult

    Raises
    ------
    RunExistsError
        ``out_dir`` holds a run and neither ``resume`` nor ``overwrite`` was given.
    ArgumentError
        See :func:`load_detection_data`.
    InputError
        An unknown model, bad settings, ``resume`` and ``overwrite`` together,
        ``resume`` without a checkpoint; the errors of
        :func:`~robopercept.nn.detection.train.train_detector`.
    FileFormatError
        A checkpoint of another model when resuming.

    Examples
    --------
    >>> cfg = TrainConfig(epochs=2, batch_size=4, seed=0, device="cpu")
    >>> res = train_run("digits", "run", images=8, size=(64, 64), width=8,
    ...                 config=cfg, progress=False)  # doctest: +SKIP
    >>> sorted(res.files), res.best_epoch  # doctest: +SKIP
    (['history.json', 'metrics.json', 'model.pt', 'pr_curves.png', 'samples.png'], 2)
    """
    model = check_choice(model, "model (--model)", RUN_DETECTORS)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {type(config).__name__}")
    cfg = config or TrainConfig()
    width = check_int(width, "width (--width)", 1)
    if val_every is not None:
        val_every = check_int(val_every, "val_every (--val-every)", 1)
    if ema is not None:
        ema = check_real(ema, "ema (--ema)", 0.0, 1.0, low_inclusive=False, high_inclusive=False)
    progress = check_bool(progress, "progress")
    out = Path(_text(out_dir, "out_dir (-o/--out)"))
    text, _ = _check_source(data, images, images_dir, False)  # before the folder is made
    ckpt = prepare_run_folder(out, resume=resume, overwrite=overwrite)
    train, val = load_detection_data(
        data,
        images=images,
        size=size,
        seed=cfg.seed,
        images_dir=images_dir,
        model=model,
        allow_outside=allow_outside,
    )
    if progress:
        print(
            f"nn detect train: {model} on {text} ({len(train)} training, "
            f"{len(val)} validation images)",
            file=sys.stderr,
        )
    settings: dict[str, Any] = {"width": width}
    net = build_detector(model, len(train.classes), seed=cfg.seed, **settings)
    before = _stamp(ckpt)
    try:
        hist = train_detector(
            net,
            train,
            cfg,
            checkpoint=ckpt,
            resume=resume,
            progress=progress,
            val=val,
            val_every=val_every or max(1, cfg.epochs // 10),
            ema=ema,
        )
        # written before the model: a signal during the model's save must leave the
        # history as one during training does
        (out / "history.json").write_text(
            _history_json(
                {
                    "losses": hist.losses,
                    "seconds": hist.seconds,
                    "val": hist.val,
                    "best_epoch": hist.best_epoch,
                }
            )
        )
    except BaseException as exc:
        # Ctrl-C, SIGTERM: keep the history of the complete epochs beside their checkpoint
        if not isinstance(exc, Exception) and (resume or _stamp(ckpt) != before):
            _history_from_checkpoint(ckpt, out / "history.json")
        raise
    files = {name: out / name for name in RUN_FILES}
    save_detector(
        files["model.pt"],
        net,
        model,
        settings,
        train.classes,
        data=text,
        images=images,
        size=list(size),
        seed=cfg.seed,
        epochs=cfg.epochs,
    )
    ev = evaluate_detector(net, val)
    extra = {"model": model, "data": text, "split": "validation", "best_epoch": hist.best_epoch}
    metrics = _write_metrics(ev, val, out, extra)
    _write_samples(net, val, files["samples.png"])
    return DetectionTrainResult(
        out_dir=out,
        files=files,
        checkpoint=ckpt,
        model=model,
        data=text,
        history=hist,
        best_epoch=hist.best_epoch,
        seconds=float(sum(hist.seconds)),
        evaluation=ev,
        metrics=metrics,
    )


# --------------------------------------------------------------------------- evaluate


def evaluate_run(
    model: str | os.PathLike[str],
    data: str | os.PathLike[str],
    *,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    images_dir: str | os.PathLike[str] | None = None,
    tta: str | None = None,
    device: str | None = None,
    out_dir: str | os.PathLike[str] | None = None,
    allow_outside: bool = False,
) -> DetectionEvaluation:
    """COCO metrics of a trained detector on the validation split of a built-in set or on
    a whole COCO file (:func:`load_detection_data` with ``evaluate=True``).

    Give the ``images``, ``size`` and ``seed`` the run was trained with, so that a
    built-in set's validation split is the run's. With ``out_dir``, ``metrics.json`` and
    ``pr_curves.png`` are written there.

    Parameters
    ----------
    model : path
        A run folder (its ``model.pt``) or a model file of
        :func:`~robopercept.nn.detection.zoo.save_detector`.
    data : str or path
        A name of :data:`BUILTIN_DATA`, a COCO JSON file or an annotation folder.
    images, size, seed, images_dir, allow_outside
        As :func:`load_detection_data`.
    tta : {"hflip", "flips", "dihedral"}, optional
        Test-time augmentation (:class:`~robopercept.nn.detection.tta.TestTimeAugmentation`).
    device : str, optional
        Where the model runs.
    out_dir : path, optional
        Folder for ``metrics.json`` and ``pr_curves.png``.

    Returns
    -------
    DetectionEvaluation

    Raises
    ------
    ArgumentError
        See :func:`load_detection_data`; no model file at ``model``.
    InputError
        Data whose classes differ from the model's; a bad ``tta`` or ``device``.
    FileFormatError
        Not a detector checkpoint.
    """
    if tta is not None:
        check_choice(tta, "tta (--tta)", TTA_VIEWS)
    check_device(device, "device (--device)")
    label = _text(model, "model (RUN_OR_MODEL)")
    text = _text(data, "data (--data)")
    out = check_output_folder(out_dir)
    _, val = load_detection_data(
        data,
        images=images,
        size=size,
        seed=seed,
        images_dir=images_dir,
        evaluate=True,
        allow_outside=allow_outside,
    )
    path = Path(label)
    if path.is_dir():
        path = path / "model.pt"
    if not path.is_file():
        raise ArgumentError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    net, info = load_detector(path)
    val = val.with_classes(list(info["classes"]))
    if tta:
        net = TestTimeAugmentation(net, tta)
    ev = evaluate_detector(net, val, device=device)
    extra = {"model": label, "data": text, "tta": tta}
    files: dict[str, Path] = {}
    if out is not None:
        metrics = _write_metrics(ev, val, out, extra)
        files = {"metrics.json": out / "metrics.json", "pr_curves.png": out / "pr_curves.png"}
    else:
        metrics = _metrics(ev, val, extra)
    return DetectionEvaluation(label, text, tta, len(val), ev, metrics, files)
