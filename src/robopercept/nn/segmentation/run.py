r"""A segmentation run from data to files: what ``robopercept nn segment train|eval`` does.

:func:`load_segmentation_data` gives the built-in data by name
(:data:`~robopercept.nn.segmentation.data.BUILTIN_SEGMENTATION_DATA`: the procedural
shapes, the real-digit canvases, the real fluorescence nuclei) split into training and
validation sets. :func:`train_run` builds a network, a semantic one of
:data:`~robopercept.nn.segmentation.networks.SEGMENTERS` or Mask R-CNN
(:func:`resolve_segment_model`), trains it keeping the epoch with the best validation
score (:func:`~robopercept.nn.segmentation.networks.train_segmenter`, the mIoU after
every epoch; :func:`~robopercept.nn.detection.train.train_detector` with
``val_iou_type="segm"``, the mask AP@[.5:.95] every ``max(1, epochs // 10)`` epochs and
after the last), scores the kept weights on the validation split
(:func:`score_segmentation`) and writes the run folder:

========================  =============================================================
``checkpoint.pt``         the last complete epoch (model, optimizer, schedule, random
                          states, history; :func:`~robopercept.nn.train.loop.train_loop`):
                          written after every epoch, so Ctrl-C keeps it, and
                          ``resume=True`` (``--resume``) continues from it
``checkpoint.best.pt``    the best epoch's weights
``model.pt``              the kept weights with what rebuilds the network
                          (:func:`~robopercept.nn.segmentation.networks.save_segmenter`,
                          :func:`~robopercept.nn.detection.zoo.save_detector`) and the
                          data they were trained on (``data``, ``images``, ``size``,
                          ``seed``)
``history.json``          the mean training losses per epoch, the validation score by
                          epoch (``val_mIoU`` or ``val_mask_AP``) and ``best_epoch``
                          (written on Ctrl-C too, up to the last complete epoch)
``metrics.json``          the validation scores of the kept weights
``samples.png``           prediction above ground truth for the first three
                          validation images (:func:`robopercept.viz.panels_picture`)
========================  =============================================================

:func:`evaluate_run` scores a saved model on the validation split of the same data.

The scores (:class:`SegmentScores`): for a semantic network, from the confusion matrix
:math:`C` over the :math:`K + 1` labels (0 the background) of every validation pixel
(rows truth, columns prediction): pixel accuracy :math:`\sum_k C_{kk} / \sum C`, mean
accuracy :math:`\operatorname{mean}_k C_{kk} / \sum_j C_{kj}`, :math:`IoU_k = C_{kk} /
(\sum_j C_{kj} + \sum_i C_{ik} - C_{kk})`, their mean mIoU over the labels seen in truth
or prediction, and fwIoU weighted by the true frequency of each label
(:func:`~robopercept.nn.segmentation.metrics.segmentation_scores`, the figures of Long et
al., "Fully Convolutional Networks for Semantic Segmentation", 2015, and of torchvision's
segmentation references); for Mask R-CNN, the 12 COCO ``segm`` numbers
(:func:`~robopercept.nn.detection.train.evaluate_detector`, equal to pycocotools).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from robopercept._checks import as_path, check_bool, check_choice, check_int, plain_repr
from robopercept.errors import InputError
from robopercept.imaging import write_image
from robopercept.nn._guards import check_allocation, check_module
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.mask_rcnn import MaskRCNN
from robopercept.nn.detection.train import (
    check_detection_dataset,
    evaluate_detector,
    train_detector,
)
from robopercept.nn.detection.zoo import build_detector, detect_arrays, load_detector, save_detector
from robopercept.nn.segmentation.data import (
    BUILTIN_SEGMENTATION_DATA,
    NUCLEI_FOLDER,
    SegmentationSets,
    segmentation_sets,
)
from robopercept.nn.segmentation.metrics import segmentation_confusion, segmentation_scores
from robopercept.nn.segmentation.networks import (
    build_segmenter,
    load_segmenter,
    save_segmenter,
    segment_arrays,
    train_segmenter,
)
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.runs import check_output_folder, prepare_run_folder
from robopercept.viz.segmentation import class_overlay, instance_overlay, panels_picture

__all__ = [
    "RUN_FILES",
    "SEGMENT_MODELS",
    "TASKS",
    "VOID",
    "SegmentEvaluation",
    "SegmentScores",
    "SegmentTrainResult",
    "evaluate_run",
    "load_segmentation_data",
    "padded_class_maps",
    "resolve_segment_model",
    "score_segmentation",
    "train_run",
]

#: the networks :func:`train_run` builds: the semantic ones, then the instance one
SEGMENT_MODELS = ("unet", "fcn8s", "fcn16s", "fcn32s", "naive", "maskrcnn")
#: what a run segments: classes per pixel, or object instances
TASKS = ("semantic", "instance")
#: the files of a run folder besides the checkpoints, as the command line lists them
RUN_FILES = ("model.pt", "history.json", "metrics.json", "samples.png")
#: the U-Net's depth in a run (the other settings are the builders' defaults)
_UNET_DEPTH = 4


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class SegmentScores:
    """A segmentation model's scores on a labelled set (:func:`score_segmentation`).

    Attributes
    ----------
    instance : bool
        Mask R-CNN (COCO ``segm`` numbers) rather than a semantic network.
    metrics : dict of str to float
        Semantic: ``pixel_accuracy``, ``mean_accuracy``, ``mIoU``, ``fwIoU``; instance:
        the 12 COCO numbers by name (``AP``, ``AP50``, ... ``ARl``; -1 where undefined).
    iou : dict of str to float or None
        Semantic: the IoU of each label by name (``"background"`` first), None where
        the label is in neither truth nor prediction; empty for instances.
    stats : tuple of float
        Instance: the 12 COCO numbers in pycocotools' order; empty for semantic.
    """

    instance: bool
    metrics: dict[str, float]
    iou: dict[str, float | None] = field(default_factory=dict)
    stats: tuple[float, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"metrics", "iou"}`` (semantic) or ``{"metrics", "stats"}``."""
        if self.instance:
            return {"metrics": dict(self.metrics), "stats": list(self.stats)}
        return {"metrics": dict(self.metrics), "iou": dict(self.iou)}


@dataclass(frozen=True)
class SegmentEvaluation:
    """A saved model scored on the validation split of a data set (:func:`evaluate_run`).

    Attributes
    ----------
    model : str
        The run folder or ``model.pt`` as given.
    data : str or None
        The data's name.
    images : int
        Validation images scored.
    scores : SegmentScores
    files : dict of str to Path
        ``{"metrics.json": path}`` when written, else empty.
    """

    model: str
    data: str | None
    images: int
    scores: SegmentScores
    files: dict[str, Path] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """What ``metrics.json`` holds and ``nn segment eval --json`` prints: ``model``,
        ``data``, ``images`` and the scores (:meth:`SegmentScores.to_dict`)."""
        return {
            "model": self.model,
            "data": self.data,
            "images": self.images,
            **self.scores.to_dict(),
        }


@dataclass(frozen=True)
class SegmentTrainResult:
    """What :func:`train_run` made.

    Attributes
    ----------
    out_dir : Path
    files : dict of str to Path
        ``model.pt``, ``history.json``, ``metrics.json``, ``samples.png``.
    checkpoint : Path
        The run's ``checkpoint.pt`` (``checkpoint.best.pt`` beside it).
    model : str
        The network's name (:data:`SEGMENT_MODELS`).
    task : {"semantic", "instance"}
    history : dict
        The content of ``history.json``: ``losses`` per epoch, ``val_mIoU`` or
        ``val_mask_AP`` by epoch, ``best_epoch``.
    scores : SegmentScores
        The kept weights on the validation split.
    metrics : dict
        The content of ``metrics.json``.
    best_epoch : int
        The epoch kept (1-based).
    seconds : float
        Training time.
    """

    out_dir: Path
    files: dict[str, Path]
    checkpoint: Path
    model: str
    task: str
    history: dict[str, Any] = field(repr=False)
    scores: SegmentScores
    metrics: dict[str, Any] = field(repr=False)
    best_epoch: int
    seconds: float

    def to_dict(self) -> dict[str, Any]:
        """What ``nn segment train --json`` prints: ``metrics.json`` and the files."""
        return {**self.metrics, "files": {n: str(p) for n, p in self.files.items()}}


# --------------------------------------------------------------------------- data, model
def _is_own(data: Any) -> bool:
    """``data`` names a user's annotations: a ``.json`` file or a folder."""
    if not isinstance(data, (str, os.PathLike)) or str(data) in BUILTIN_SEGMENTATION_DATA:
        return False
    return str(data).lower().endswith(".json") or Path(data).is_dir()


def _check_data_args(data: Any, images: Any, images_dir: Any) -> tuple[str, int]:
    """The cheap checks of :func:`load_segmentation_data` (no data is made)."""
    if _is_own(data):
        if str(data).lower().endswith(".json") and not Path(data).is_file():
            raise InputError(f"--data: COCO file {data} does not exist")
        return "own", check_int(images, "--images")
    name = check_choice(data, "--data", BUILTIN_SEGMENTATION_DATA)
    if name == "nuclei":
        folder = None if images_dir is None else as_path(images_dir, "--images-dir")
        if folder is None or not folder.is_dir():
            raise InputError(
                f"--images-dir: --data nuclei needs {NUCLEI_FOLDER}; got {images_dir!r}"
            )
    n = check_int(images, "--images")
    if n < 2:
        raise InputError("--images: give at least 2 (a training and a validation image)")
    return name, n


def load_segmentation_data(
    data: str,
    *,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    images_dir: str | os.PathLike[str] | None = None,
    evaluate: bool = False,
    allow_outside: bool = False,
) -> SegmentationSets:
    """The segmentation data ``data`` split into training and validation sets: a
    built-in set (:func:`~robopercept.nn.segmentation.data.segmentation_sets`: 80 % /
    20 % of ``images`` seeded canvases, or the nuclei's three training quadrants and the
    held-out one), or your own annotated images, a COCO instances JSON file, a folder of
    labelme files or a VOC segmentation folder
    (:meth:`~robopercept.nn.detection.data.DetectionDataset.from_annotations` with the masks,
    split 80 % / 20 % by image with ``seed``, neither part empty), with the checks of
    ``nn segment``'s flags.

    Parameters
    ----------
    data : {"shapes", "digits", "nuclei"} or path
        A built-in name, a ``.json`` COCO file (polygons or RLE masks), or a folder of
        labelme ``.json`` files or a VOC ``SegmentationObject`` folder.
    images : int
        shapes / digits: canvases (at least 2: one to train on, one to validate).
    size : (width, height)
        shapes / digits: canvas size.
    seed : int
        shapes / digits: the canvases and the split.
    images_dir : path, optional
        nuclei: a folder holding StarDist's nuclei sample, ``img2d.tif`` and
        ``mask2d.tif`` (:data:`~robopercept.nn.segmentation.data.NUCLEI_FOLDER`); a COCO
        file: its images' folder (default: the file's folder).
    evaluate : bool
        The data is for evaluation: your own annotations are not split (all of them
        are the validation set, and the training set too), as ``nn segment eval``
        scores a whole file.
    allow_outside : bool, default False
        Your own annotations: read images they place outside their folder
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).

    Returns
    -------
    SegmentationSets
        ``train``, ``val`` (with masks, and so class maps), ``classes`` and ``source``
        (the arguments, recorded in a trained model).

    Raises
    ------
    InputError
        An unknown name (``--data``), nuclei without an existing folder
        (``--images-dir``), fewer than 2 images (``--images``), a bad size or seed.
    FileFormatError
        The nuclei folder's files missing or unreadable.

    Examples
    --------
    >>> s = load_segmentation_data("shapes", images=5, size=(32, 32))
    >>> len(s.train), len(s.val), s.classes[:2]
    (4, 1, ('circle', 'square'))
    >>> load_segmentation_data("shapes", images=1)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: --images: give at least 2 (a training and a validation image)
    """
    name, n = _check_data_args(data, images, images_dir)
    if name == "own":
        full = DetectionDataset.from_annotations(
            data, images_dir, masks=True, allow_outside=allow_outside
        )
        train, val = (
            (full, full) if check_bool(evaluate, "evaluate") else full.split((0.8, 0.2), rng=seed)
        )
        source = {"data": str(data), "images_dir": None if images_dir is None else str(images_dir)}
        return SegmentationSets(train, val, full.classes, {**source, "seed": seed})
    return segmentation_sets(name, n, size, seed, images_dir)


def resolve_segment_model(task: str = "semantic", model: str | None = None) -> str:
    """The network of a run: ``model`` checked against ``task``, or the task's default
    (``"unet"`` for ``"semantic"``, ``"maskrcnn"`` for ``"instance"``).

    Parameters
    ----------
    task : {"semantic", "instance"}
    model : str, optional
        A name of :data:`SEGMENT_MODELS`.

    Returns
    -------
    str

    Raises
    ------
    InputError
        An unknown task or model, or a model that does not do the task (the message
        names ``--task`` and ``--model``).

    Examples
    --------
    >>> resolve_segment_model("instance")
    'maskrcnn'
    >>> resolve_segment_model("instance", "unet")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: --model: unet does not do --task instance (maskrcnn is \
the instance model; unet, fcn8s, fcn16s, fcn32s and naive are semantic)
    """
    check_choice(task, "--task", TASKS)
    if model is not None:
        check_choice(model, "--model", SEGMENT_MODELS)
    name = model or ("maskrcnn" if task == "instance" else "unet")
    if (name == "maskrcnn") != (task == "instance"):
        raise InputError(
            f"--model: {name} does not do --task {task} (maskrcnn is the instance "
            "model; unet, fcn8s, fcn16s, fcn32s and naive are semantic)"
        )
    return str(name)


def _load_model(path: Path) -> tuple[nn.Module, dict[str, Any]]:
    """A segmentation ``model.pt`` and its record: Mask R-CNN (its ``kind``) or a
    semantic network."""
    if load_checkpoint(path).get("kind") == "maskrcnn":
        return load_detector(path)
    return load_segmenter(path)


#: the label of padding in :func:`padded_class_maps` (Pascal VOC's "void"): no loss, no score
VOID = 255


def _canvas(images: list[np.ndarray]) -> tuple[int, int]:
    """``(H, W)``: the largest height and width of ``images``."""
    return max(im.shape[0] for im in images), max(im.shape[1] for im in images)


def padded_class_maps(
    ds: DetectionDataset, canvas: tuple[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A segmentation set's images and class maps as two stacked arrays, each image
    padded at its bottom and right to ``canvas`` ``(H, W)`` (default: the largest
    height and width of the set) with black and its class map with :data:`VOID`, which
    the loss and the scores ignore: how a semantic network trains on your own images of
    several sizes (as torchvision's segmentation references pad a batch with 255).

    Returns
    -------
    images : (N, H, W, 3) float32 ndarray
    maps : (N, H, W) int64 ndarray
        0 background, ``k`` the class ``classes[k - 1]``, :data:`VOID` the padding.

    Raises
    ------
    InputError
        A set without masks, an image larger than ``canvas``, a canvas whose arrays would
        take more than 1 GiB (:data:`~robopercept.nn._guards.MAX_BYTES`).

    Examples
    --------
    >>> m = [np.ones((1, 2, 2), bool), np.ones((1, 1, 3), bool)]
    >>> ds = DetectionDataset([np.zeros((2, 2, 3)), np.zeros((1, 3, 3))],
    ...                       [[[0, 0, 2, 2]], [[0, 0, 3, 1]]], [[1], [1]], ["a"], masks=m)
    >>> padded_class_maps(ds)[1].tolist()
    [[[1, 1, 255], [1, 1, 255]], [[1, 1, 1], [255, 255, 255]]]
    """
    ds = check_detection_dataset(ds)
    if canvas is None:
        h, w = _canvas(list(ds.images))
    elif isinstance(canvas, (tuple, list)) and len(canvas) == 2:
        h, w = (check_int(v, "canvas (H, W)", 1) for v in canvas)
    else:
        raise InputError(f"canvas must be (H, W) pixels; got {plain_repr(canvas)}")
    # per pixel: 3 float32 colours and one int64 class
    check_allocation(
        len(ds) * h * w,
        3 * 4 + 8,
        f"{len(ds)} padded images and class maps of {h} x {w}",
        "give a smaller canvas (H, W), or crop or tile the largest images",
    )
    images = np.zeros((len(ds), h, w, 3), np.float32)
    maps = np.full((len(ds), h, w), VOID, np.int64)
    for i, im in enumerate(ds.images):
        ih, iw = im.shape[:2]
        if ih > h or iw > w:
            raise InputError(f"image {i} is {iw} x {ih}, larger than the canvas {w} x {h}")
        images[i, :ih, :iw] = im
        maps[i, :ih, :iw] = ds.class_map(i)
    return images, maps


# --------------------------------------------------------------------------- scores
def score_segmentation(model: nn.Module, val: Any, *, device: str | None = None) -> SegmentScores:
    """The scores of a segmentation model on a labelled set (module docstring).

    A :class:`~robopercept.nn.detection.mask_rcnn.MaskRCNN` is scored by COCO ``segm``
    (:func:`~robopercept.nn.detection.train.evaluate_detector`, masks thresholded at
    0.5), any other model as a semantic network: the class maps of
    :func:`~robopercept.nn.segmentation.networks.segment_arrays` against the set's
    (:meth:`~robopercept.nn.detection.data.DetectionDataset.class_maps`), over the
    background and the set's classes.

    Parameters
    ----------
    model : torch.nn.Module
        A semantic segmenter of :mod:`robopercept.nn.segmentation.networks` or a Mask
        R-CNN.
    val : DetectionDataset
        With masks (:func:`load_segmentation_data`'s ``val``).
    device : str, optional
        Where to run (default: the model's device).

    Returns
    -------
    SegmentScores

    Raises
    ------
    InputError
        Not a model, a set without masks, or images the model cannot take.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.segmentation.networks import build_segmenter
    >>> s = load_segmentation_data("shapes", images=5, size=(32, 32))
    >>> _ = torch.manual_seed(0)
    >>> scores = score_segmentation(build_segmenter("naive", 5, width=4), s.val)
    >>> sorted(scores.metrics), list(scores.iou)[0]
    (['fwIoU', 'mIoU', 'mean_accuracy', 'pixel_accuracy'], 'background')
    """
    model = check_module(model)
    val = check_detection_dataset(val)
    if isinstance(model, MaskRCNN):
        ev = evaluate_detector(model, val, device=device, iou_type="segm")
        return SegmentScores(True, ev.summary(), stats=tuple(ev.stats.tolist()))
    if device:
        model.to(resolve_device(device))
    pred = segment_arrays(model, list(val.images))
    names = ["background", *val.classes]
    conf = sum(  # image by image: the images may differ in size
        segmentation_confusion(val.class_map(i), p, len(names)) for i, p in enumerate(pred)
    )
    s = segmentation_scores(conf)
    metrics = {
        "pixel_accuracy": s.pixel_accuracy,
        "mean_accuracy": s.mean_accuracy,
        "mIoU": s.miou,
        "fwIoU": s.fwiou,
    }
    iou = {n: (None if np.isnan(v) else float(v)) for n, v in zip(names, s.iou, strict=True)}
    return SegmentScores(False, metrics, iou=iou)


def _samples_picture(model: nn.Module, val: Any, count: int = 3) -> np.ndarray:
    """The first ``count`` images of ``val`` in a grid: the predictions in the top row,
    the ground truth under each (the overlays of ``nn segment IMAGE``, instances with
    score >= 0.5), each enlarged to 384 pixels (a 1176 x 830 sheet for three 128 x 128
    canvases, readable at 1080p)."""
    classes = list(val.classes)
    instance = isinstance(model, MaskRCNN)
    n = min(count, len(val))
    preds, truths = [], []
    for i in range(n):
        im = val.images[i]
        if instance:
            d = detect_arrays(model, [im])[0]
            keep = d["scores"] >= 0.5
            preds.append(
                instance_overlay(
                    im,
                    d["masks"][keep],
                    labels=d["labels"][keep],
                    classes=classes,
                    scores=d["scores"][keep],
                    min_side=_SAMPLE_SIDE,
                )
            )
            truths.append(
                instance_overlay(
                    im, val.masks[i], labels=val.labels[i], classes=classes, min_side=_SAMPLE_SIDE
                )
            )
        else:
            pred = segment_arrays(model, [im])[0]
            preds.append(class_overlay(im, pred, classes, min_side=_SAMPLE_SIDE))
            truths.append(class_overlay(im, val.class_maps()[i], classes, min_side=_SAMPLE_SIDE))
    titles = [f"prediction {i + 1}" for i in range(n)] + [f"ground truth {i + 1}" for i in range(n)]
    return panels_picture(preds + truths, titles, columns=n)


#: the longer side the sample images of ``samples.png`` are enlarged to
_SAMPLE_SIDE = 384


# --------------------------------------------------------------------------- train
def _history_record(hist: Any, instance: bool) -> dict[str, Any]:
    """``history.json`` of a training history (or of a checkpoint's ``"history"``)."""
    get = hist.get if isinstance(hist, dict) else lambda k: getattr(hist, k)
    key = "val_mask_AP" if instance else "val_mIoU"
    return {"losses": get("losses"), key: get("val"), "best_epoch": get("best_epoch")}


def train_run(
    data: str | SegmentationSets,
    out_dir: str | os.PathLike[str],
    *,
    task: str = "semantic",
    model: str | None = None,
    config: TrainConfig | None = None,
    width: int = 16,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    images_dir: str | os.PathLike[str] | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> SegmentTrainResult:
    """Train a segmentation network on ``data`` and write the run folder ``out_dir``
    (module docstring).

    Steps: :func:`resolve_segment_model`; :func:`load_segmentation_data` (with
    ``config.seed``) unless the sets are given; the network, seeded by
    ``config.seed`` (width ``width``, a U-Net of depth 4); the training, which writes
    ``checkpoint.pt`` after every epoch and keeps the best validation epoch's weights;
    ``model.pt``, ``history.json``, the validation scores of the kept weights
    (:func:`score_segmentation`) in ``metrics.json``, and ``samples.png``.

    Parameters
    ----------
    data : str or SegmentationSets
        A name of :data:`~robopercept.nn.segmentation.data.BUILTIN_SEGMENTATION_DATA`,
        or the sets of :func:`load_segmentation_data` (then ``images``, ``size`` and
        ``images_dir`` are not used; ``model.pt`` records their ``source``).
    out_dir : path
        The run folder (created; one holding a run is refused unless ``resume`` or
        ``overwrite``: :func:`~robopercept.nn.train.runs.prepare_run_folder`).
    task : {"semantic", "instance"}
    model : str, optional
        A name of :data:`SEGMENT_MODELS` (default: the task's, ``unet`` / ``maskrcnn``).
    config : TrainConfig, optional
        Epochs, batch size, learning rate, seed (data, split and weights), device.
    width : int
        The network's width (channels of its first stage).
    images, size, images_dir
        As :func:`load_segmentation_data`.
    resume : bool
        Continue the run in ``out_dir`` from its ``checkpoint.pt`` (same data, model and
        configuration): it ends with the weights of an uninterrupted run.
    overwrite : bool
        Start afresh in a folder that already holds a run.
    progress : bool
        A progress bar on stderr.

    Returns
    -------
    SegmentTrainResult

    Raises
    ------
    InputError
        Unknown task or model or a model not doing the task, bad data arguments, bad
        ``config`` or ``width``; ``resume`` without a checkpoint or with ``overwrite``.
    RunExistsError
        ``out_dir`` holds a run and neither ``resume`` nor ``overwrite`` was given.
    KeyboardInterrupt
        Ctrl-C during training: ``checkpoint.pt`` and ``history.json`` hold the last
        complete epoch (``resume=True`` continues from it).

    Examples
    --------
    >>> import tempfile
    >>> from robopercept.nn.train.config import TrainConfig
    >>> cfg = TrainConfig(epochs=1, batch_size=4, device="cpu")
    >>> r = train_run("shapes", tempfile.mkdtemp(), model="naive", config=cfg, width=4,
    ...               images=5, size=(32, 32), progress=False)
    >>> sorted(r.files), r.best_epoch
    (['history.json', 'metrics.json', 'model.pt', 'samples.png'], 1)
    """
    name = resolve_segment_model(task, model)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    width = check_int(width, "width (--width)", 1)
    if not isinstance(data, SegmentationSets):
        _check_data_args(data, images, images_dir)  # before the run folder is touched
    ckpt = prepare_run_folder(out_dir, resume=resume, overwrite=overwrite)
    out = ckpt.parent
    sets = (
        data
        if isinstance(data, SegmentationSets)
        else load_segmentation_data(
            data, images=images, size=size, seed=cfg.seed, images_dir=images_dir
        )
    )
    train, val = sets.train, sets.val
    settings: dict[str, Any] = {"width": width}
    extra = dict(sets.source)
    instance = name == "maskrcnn"
    before = ckpt.stat().st_mtime_ns if ckpt.exists() else None  # another run's, or resumed
    t0 = time.perf_counter()
    try:
        if instance:
            net = build_detector("maskrcnn", len(sets.classes), seed=cfg.seed, **settings)
            hist: Any = train_detector(
                net,
                train,
                cfg,
                checkpoint=ckpt,
                resume=resume,
                progress=progress,
                val=val,
                val_every=max(1, cfg.epochs // 10),
                val_iou_type="segm",
            )
        else:
            if name == "unet":
                settings["depth"] = _UNET_DEPTH
            torch.manual_seed(cfg.seed)  # the initial weights
            net = build_segmenter(name, len(sets.classes) + 1, **settings)
            canvas = _canvas([*train.images, *val.images])
            hist = train_segmenter(
                net,
                *padded_class_maps(train, canvas),
                cfg,
                val=padded_class_maps(val, canvas),
                ignore_index=VOID,
                dihedral=False,
                progress=progress,
                checkpoint=ckpt,
                resume=resume,
            )
        # written before the model: a signal during the model's save must leave the
        # history as one during training does
        history = _history_record(hist, instance)
        (out / "history.json").write_text(json.dumps(history, indent=1))
    except BaseException:  # Ctrl-C, SIGTERM, a failure: keep the last epoch's history.json
        if ckpt.exists() and ckpt.stat().st_mtime_ns != before:  # an epoch of this run
            saved = load_checkpoint(ckpt)["history"]
            history = _history_record(saved, instance)
            (out / "history.json").write_text(json.dumps(history, indent=1))
        raise
    seconds = time.perf_counter() - t0
    files = {n: out / n for n in RUN_FILES}
    if instance:
        save_detector(files["model.pt"], net, "maskrcnn", settings, list(sets.classes), **extra)
    else:
        save_segmenter(files["model.pt"], net, name, settings, list(sets.classes), **extra)
    scores = score_segmentation(net, val, device=cfg.device)
    metrics = {
        "model": name,
        "task": "instance" if instance else "semantic",
        "data": extra.get("data"),
        "split": "validation",
        "best_epoch": history["best_epoch"],
        **scores.to_dict(),
    }
    files["metrics.json"].write_text(json.dumps(metrics, indent=1))
    write_image(files["samples.png"], _samples_picture(net, val))
    return SegmentTrainResult(
        out_dir=out,
        files=files,
        checkpoint=ckpt,
        model=name,
        task=metrics["task"],
        history=history,
        scores=scores,
        metrics=metrics,
        best_epoch=int(history["best_epoch"]),
        seconds=seconds,
    )


# --------------------------------------------------------------------------- eval
def evaluate_run(
    model: str | os.PathLike[str],
    data: str | SegmentationSets,
    *,
    images: int = 200,
    size: tuple[int, int] = (128, 128),
    seed: int = 0,
    images_dir: str | os.PathLike[str] | None = None,
    device: str | None = None,
    out_dir: str | os.PathLike[str] | None = None,
) -> SegmentEvaluation:
    """Score a saved segmentation model on the validation split of ``data``
    (:func:`score_segmentation`); give the data arguments of its training run (its
    ``model.pt`` records them) to score it on the images it did not train on.

    Parameters
    ----------
    model : path
        A run folder (its ``model.pt``) or a ``model.pt`` of :func:`train_run`.
    data : str or SegmentationSets
        A name (with ``images``, ``size``, ``seed``, ``images_dir`` as
        :func:`load_segmentation_data`) or the sets themselves.
    images, size, seed, images_dir
        As :func:`load_segmentation_data`.
    device : str, optional
        Where to run (default: the CPU).
    out_dir : path, optional
        A folder (created) for ``metrics.json`` (:meth:`SegmentEvaluation.to_dict`).

    Returns
    -------
    SegmentEvaluation

    Raises
    ------
    InputError
        No such model file (``RUN_OR_MODEL``), bad data arguments, or data whose
        classes differ from the model's (``--data``).
    FileFormatError
        A file that is not a segmentation model.

    Examples
    --------
    >>> evaluate_run("/nonexistent/run", "shapes")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: RUN_OR_MODEL: /nonexistent/run does not exist (a run \
folder or its model.pt)
    """
    path = as_path(model, "RUN_OR_MODEL")
    if path.is_dir():
        path = path / "model.pt"
    if not path.is_file():
        raise InputError(f"RUN_OR_MODEL: {path} does not exist (a run folder or its model.pt)")
    if not isinstance(data, SegmentationSets):
        _check_data_args(data, images, images_dir)
    net, info = _load_model(path)
    sets = (
        data
        if isinstance(data, SegmentationSets)
        else load_segmentation_data(
            data, images=images, size=size, seed=seed, images_dir=images_dir, evaluate=True
        )
    )
    if list(sets.classes) != list(info["classes"]):  # by name, as the model numbers them
        val = sets.val.with_classes(list(info["classes"]))
        sets = SegmentationSets(sets.train, val, val.classes, sets.source)
    folder = check_output_folder(out_dir)
    scores = score_segmentation(net, sets.val, device=device)
    name = sets.source.get("data", data if isinstance(data, str) else None)
    files = {} if folder is None else {"metrics.json": folder / "metrics.json"}
    ev = SegmentEvaluation(os.fsdecode(model), name, len(sets.val), scores, files)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
        files["metrics.json"].write_text(json.dumps(ev.to_dict(), indent=1))
    return ev
