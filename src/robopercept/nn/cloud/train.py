r"""Building, training, scoring and saving the point-cloud networks (PointNet, DGCNN).

The models live in :mod:`robopercept.nn.cloud.pointnet` and :mod:`robopercept.nn.cloud.dgcnn`,
the data in :mod:`robopercept.nn.cloud.data`; this module is the task around them, the
recipe of the reference code (charlesq34/pointnet, WangYueFt/dgcnn). The run of
``robopercept nn cloud train|eval`` (data sets, the run folder, metrics and pictures) is
:mod:`robopercept.nn.cloud.run`'s.

- **Networks** (:func:`build_cloud_model`): a network by name (:data:`CLOUD_MODELS`);
  :func:`cloud_model_spec` reads off what the task code needs of one.
- **Training** (:func:`train_cloud_model`): mini-batches of a seeded shuffle,
  augmented on the fly (:func:`~robopercept.nn.cloud.data.augment_clouds`: a random
  rotation about the up axis, anisotropic scaling, jitter, shift), the cross-entropy of
  the class (or of every point's part, with the object's category one-hot given to the
  network, as in the reference part segmentation), plus for PointNet the feature
  transform's regularizer :math:`w \lVert I - A A^\top \rVert_F^2` (``w = 0.001``, the
  paper's). AdamW with a per-step cosine schedule
  (:class:`~robopercept.nn.train.config.TrainConfig`), the epoch with the best validation
  score kept (:func:`~robopercept.nn.train.loop.epoch_loop`), checkpoints after every
  epoch and resumption when asked.
- **Scores** (:func:`evaluate_cloud_model`, :func:`predict_clouds`): overall accuracy
  and the mean of the per-class accuracies (ModelNet's "class avg"), the confusion
  matrix; for parts the instance mIoU of ShapeNet-part's protocol (:func:`part_ious`):
  per shape, the IoU of each part of its category (argmax restricted to those parts), a
  part absent from both truth and prediction counting 1, averaged over the category's
  parts, then over shapes (``instance_miou``) and per category, then over categories
  (``class_miou``).
- **Files**: :func:`save_cloud_model` / :func:`load_cloud_model` (weights and what
  rebuilds the network, read back without pickled code).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import (
    check_bool,
    check_choice,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.nn._guards import check_count
from robopercept.nn.cloud.data import CloudDataset, augment_clouds
from robopercept.nn.cloud.dgcnn import DGCNN
from robopercept.nn.cloud.pointnet import PointNet, transform_regularizer
from robopercept.nn.train.checkpoint import load_built_model, save_built_model
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.loop import EpochHistory, epoch_loop

__all__ = [
    "CLOUD_MODELS",
    "CloudEvaluation",
    "CloudHistory",
    "CloudModelSpec",
    "build_cloud_model",
    "cloud_model_spec",
    "evaluate_cloud_model",
    "load_cloud_model",
    "part_ious",
    "predict_clouds",
    "save_cloud_model",
    "train_cloud_model",
]

#: the networks by name: ``"pointnet"`` (:class:`~robopercept.nn.cloud.pointnet.PointNet`) and
#: ``"dgcnn"`` (:class:`~robopercept.nn.cloud.dgcnn.DGCNN`)
CLOUD_MODELS = ("pointnet", "dgcnn")


def build_cloud_model(
    name: str, num_outputs: int, *, seed: int | None = None, **settings: Any
) -> nn.Module:
    """A point-cloud network by name.

    Parameters
    ----------
    name : {"pointnet", "dgcnn"}
    num_outputs : int
        Classes (``task="classify"``) or parts (``task="segment"``).
    seed : int, optional
        Seeds torch's generator before the weights are drawn.
    **settings
        The constructor's keyword arguments (``task``, ``width``, ``k``, ...).

    Returns
    -------
    torch.nn.Module

    Examples
    --------
    >>> net = build_cloud_model("pointnet", 4, width=0.125, seed=0)
    >>> net(torch.rand(2, 32, 3)).shape
    torch.Size([2, 4])
    """
    check_choice(name, "name", CLOUD_MODELS)
    num_outputs = check_count(num_outputs, "num_outputs", 1, 100_000)
    if seed is not None:
        torch.manual_seed(check_count(seed, "seed", 0, 2**63 - 1))
    if name == "pointnet":
        return PointNet(num_outputs, **settings)
    return DGCNN(num_outputs, **settings)


class CloudModelSpec(NamedTuple):
    """What the task code reads off a point-cloud network (:func:`cloud_model_spec`).

    Attributes
    ----------
    kind : {"pointnet", "dgcnn"}
        The network's name in :data:`CLOUD_MODELS`.
    task : {"classify", "segment"}
    num_outputs : int
        Classes (classifier) or parts (segmenter).
    in_channels : int
        The point features it reads (3: x, y, z).
    config : dict
        Its constructor settings (what :func:`save_cloud_model` records).
    """

    kind: str
    task: str
    num_outputs: int
    in_channels: int
    config: dict[str, Any]


def cloud_model_spec(model: nn.Module) -> CloudModelSpec:
    """The kind, task, outputs, input channels and settings of a point-cloud network,
    checked: what every function of this module reads off its ``model``.

    Parameters
    ----------
    model : PointNet or DGCNN
        As :func:`build_cloud_model` or :func:`load_cloud_model` return.

    Returns
    -------
    CloudModelSpec

    Raises
    ------
    InputError
        ``model`` is not a PointNet or DGCNN.

    Examples
    --------
    >>> spec = cloud_model_spec(build_cloud_model("pointnet", 4, width=0.125, seed=0))
    >>> spec.kind, spec.task, spec.num_outputs, spec.in_channels
    ('pointnet', 'classify', 4, 3)
    """
    name = type(model).__name__.lower()
    task = getattr(model, "task", None)
    if name not in CLOUD_MODELS or task not in ("classify", "segment"):
        raise InputError(
            f"model must be a PointNet or DGCNN (build_cloud_model); got {plain_repr(model)}"
        )
    config = getattr(model, "config", {})
    return CloudModelSpec(
        name,
        str(task),
        int(getattr(model, "num_outputs", 0)),
        int(getattr(model, "in_channels", 3)),
        dict(config) if isinstance(config, dict) else {},
    )


def _check_data(data: Any, what: str, task: str) -> Any:
    if not isinstance(data, CloudDataset):
        raise InputError(
            f"{what} must be a CloudDataset (procedural_shapes or read_cloud_folder); got "
            f"{plain_repr(data)}"
        )
    if len(data) == 0:
        raise InputError(f"{what} is empty")
    if task == "segment" and data.parts is None:
        raise InputError(
            f"{what} has no part labels: a segmentation network trains on data with parts "
            "(procedural_shapes gives them)"
        )
    return data


class CloudHistory(EpochHistory):
    """What :func:`train_cloud_model` measured per epoch: the training loss, seconds and
    the validation score (accuracy for classifiers, instance mIoU for segmenters)."""

    val_name = "val_score"


def train_cloud_model(
    model: nn.Module,
    train: Any,
    config: TrainConfig | None = None,
    *,
    val: Any = None,
    augment: bool = True,
    rotate: str | None = "up",
    up_axis: int = 2,
    regularizer: float = 0.001,
    progress: bool = True,
    checkpoint: str | os.PathLike[str] | None = None,
    resume: bool = False,
) -> CloudHistory:
    r"""Train a PointNet or DGCNN on a :class:`~robopercept.nn.cloud.data.CloudDataset`.

    Each step takes ``config.batch_size`` clouds of a seeded shuffle, augmented
    (``augment``: :func:`~robopercept.nn.cloud.data.augment_clouds` with ``rotate``
    about ``up_axis``, scaling in [0.8, 1.25] per axis, jitter 0.01 clipped at 0.05 and
    a shift of at most 0.1), and minimizes the cross-entropy of the classes
    (``task="classify"``) or of every point's part (``"segment"``, the object's class
    given as the category when the network takes one), plus
    ``regularizer`` :math:`\cdot \lVert I - A A^\top \rVert_F^2` of PointNet's feature
    transforms (batch mean, :func:`~robopercept.nn.cloud.pointnet.transform_regularizer`).
    With ``val`` the score (accuracy, or instance mIoU) is measured after every epoch
    and the best epoch's weights are kept.

    Parameters
    ----------
    model : PointNet or DGCNN
    train : CloudDataset
    config : TrainConfig, optional
        Epochs, batch size, AdamW learning rate, schedule, seed, device.
    val : CloudDataset, optional
    augment : bool
    rotate : {"up", "so3", None}
    up_axis : {0, 1, 2}
    regularizer : float
        The weight of the feature-transform regularizer (PointNet; 0 to disable).
    progress : bool
    checkpoint : path, optional
        Written after every epoch (:func:`~robopercept.nn.train.loop.epoch_loop`'s
        checkpoint); the best weights go to ``<stem>.best.pt``.
    resume : bool
        Continue the run of ``checkpoint`` (same model, data and settings): it ends with
        the weights of an uninterrupted run.

    Returns
    -------
    CloudHistory

    Raises
    ------
    InputError
        Not a point-cloud network, data without parts for a segmenter, labels out of the
        network's range, or a loss that became NaN (lower the learning rate).
    """
    spec = cloud_model_spec(model)
    task = spec.task
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    train = _check_data(train, "train", task)
    if val is not None:
        val = _check_data(val, "val", task)
    augment = check_bool(augment, "augment")
    if rotate is not None:
        check_choice(rotate, "rotate", ("up", "so3"))
    up_axis = check_count(up_axis, "up_axis", 0, 2)
    regularizer = check_real(regularizer, "regularizer", 0.0, 1e6)
    target_all = train.labels if task == "classify" else train.parts
    if int(target_all.max()) >= spec.num_outputs:
        raise InputError(
            f"the data has labels up to {int(target_all.max())}; the network predicts "
            f"{spec.num_outputs} outputs: build it with num_outputs >= "
            f"{int(target_all.max()) + 1}"
        )
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    points = torch.from_numpy(np.ascontiguousarray(train.points, dtype=np.float32))
    labels = torch.from_numpy(train.labels.astype(np.int64))
    parts = None if train.parts is None else torch.from_numpy(train.parts.astype(np.int64))
    in_c = spec.in_channels

    forward_aux = cast(Any, model).forward_aux

    def batch(idx: torch.Tensor) -> torch.Tensor:
        x = points[idx]
        if augment:
            x = augment_clouds(x, gen, rotate=rotate, up_axis=up_axis)
        y = labels[idx].to(dev)
        cat = y if spec.config.get("num_categories", 0) else None
        out = forward_aux(x[..., :in_c].to(dev), category=cat)
        if task == "classify":
            loss = F.cross_entropy(out.logits, y)
        else:
            assert parts is not None
            loss = F.cross_entropy(out.logits.flatten(0, 1), parts[idx].to(dev).flatten())
        for t in out.transforms:
            if regularizer and t.shape[-1] != in_c:  # the feature transforms only
                loss = loss + regularizer * transform_regularizer(t)
        return loss

    def validate() -> float:
        ev = evaluate_cloud_model(model, val, batch_size=cfg.batch_size)
        return ev.instance_miou if task == "segment" else ev.accuracy

    hist = CloudHistory()
    hist.val_name = "val_miou" if task == "segment" else "val_accuracy"
    epoch_loop(
        model,
        len(train),
        cfg,
        gen,
        batch,
        validate if val is not None else None,
        desc=f"training {type(model).__name__} ({task})",
        progress=progress,
        history=hist,
        checkpoint=checkpoint,
        resume=check_bool(resume, "resume"),
        checkpoint_extra={"architecture": type(model).__name__},
    )
    return hist


def _as_batch(points: Any) -> tuple[torch.Tensor, bool]:
    if isinstance(points, torch.Tensor):
        x = points.detach().float().cpu()
    else:
        try:
            x = torch.from_numpy(np.asarray(points, dtype=np.float32))
        except (TypeError, ValueError):
            raise InputError(
                f"points must be a (B, N, 3) or (N, 3) array; got {plain_repr(points)}"
            ) from None
    single = x.ndim == 2
    if single:
        x = x[None]
    if x.ndim != 3 or x.shape[1] == 0:
        raise InputError(
            f"points must be a (B, N, C) batch or one (N, C) cloud; got shape {tuple(x.shape)}"
        )
    return x, single


@torch.inference_mode()
def predict_clouds(
    model: nn.Module,
    points: Any,
    *,
    category: npt.ArrayLike | None = None,
    mask: Any = None,
    batch_size: int = 32,
) -> np.ndarray:
    """Class (or per-point part) probabilities of clouds, in eval mode.

    Parameters
    ----------
    model : PointNet or DGCNN
    points : (B, N, C) or (N, C) array_like or tensor
        Normalized as the training data were (unit sphere).
    category : (B,) int array_like, optional
        The objects' classes, for a segmenter that takes its category.
    mask : (B, N) bool, optional
        Real points (padded batches).
    batch_size : int

    Returns
    -------
    (B, K) or (B, N, K) float32 ndarray
        Softmax probabilities (without the batch axis for one cloud).

    Examples
    --------
    >>> net = build_cloud_model("pointnet", 3, width=0.125, seed=0)
    >>> p = predict_clouds(net, np.random.default_rng(0).random((16, 3)))
    >>> p.shape, bool(np.isclose(p.sum(), 1.0))
    ((3,), True)
    """
    spec = cloud_model_spec(model)
    x, single = _as_batch(points)
    batch_size = check_int(batch_size, "batch_size", 1)
    if spec.config.get("num_categories", 0) and category is None:
        raise InputError(
            "this segmenter takes the objects' category: pass category=(B,) class indices "
            "(e.g. a classifier's prediction)"
        )
    cat = None
    if category is not None:
        try:
            arr = np.asarray(category)
        except (TypeError, ValueError):  # ragged nesting
            arr = np.zeros(0, object)
        if arr.dtype.kind not in "iu" or arr.size == 0:
            raise InputError(
                f"category must be (B,) integer class indices; got {plain_repr(category)[:60]}"
            )
        cat = torch.as_tensor(arr.astype(np.int64).reshape(-1))
        if cat.shape[0] != x.shape[0]:
            raise InputError(f"category must give one class per cloud ({x.shape[0]})")
    m = None
    if mask is not None:
        m = torch.as_tensor(np.asarray(mask, dtype=bool))
        if m.ndim == 1:
            m = m[None]
        if tuple(m.shape) != tuple(x.shape[:2]):
            raise InputError(f"mask must be (B, N) = {tuple(x.shape[:2])}; got {tuple(m.shape)}")
    model.eval()
    dev = next(model.parameters()).device
    out = []
    for s in range(0, x.shape[0], batch_size):
        xb = x[s : s + batch_size].to(dev)
        mb = None if m is None else m[s : s + batch_size].to(dev)
        cb = None if cat is None else cat[s : s + batch_size].to(dev)
        out.append(F.softmax(model(xb, mask=mb, category=cb), dim=-1).cpu())
    prob = torch.cat(out).numpy()
    return prob[0] if single else prob


@dataclass(frozen=True)
class CloudEvaluation:
    """Scores of :func:`evaluate_cloud_model`.

    Attributes
    ----------
    accuracy : float
        Overall accuracy (classifiers) or per-point part accuracy (segmenters).
    mean_class_accuracy : float
        The mean over classes of each class's accuracy (ModelNet's "class avg").
    confusion : (K, K) int64 ndarray
        Rows true class, columns predicted (classifiers; parts for segmenters).
    predictions : (M,) or (M, N) int64 ndarray
    instance_miou, class_miou : float
        Segmenters: ShapeNet-part mIoU averaged over shapes, and over categories (NaN
        for classifiers).
    per_class_miou : (C,) float64 ndarray
        Segmenters: the mean shape IoU of each category (NaN where absent).
    """

    accuracy: float
    mean_class_accuracy: float
    confusion: np.ndarray
    predictions: np.ndarray
    instance_miou: float = float("nan")
    class_miou: float = float("nan")
    per_class_miou: np.ndarray | None = None

    def summary(self) -> dict[str, float]:
        """The scalar scores as a JSON-ready dict."""
        out = {"accuracy": self.accuracy, "mean_class_accuracy": self.mean_class_accuracy}
        if np.isfinite(self.instance_miou):
            out.update(instance_miou=self.instance_miou, class_miou=self.class_miou)
        return out


def _confusion(true: np.ndarray, pred: np.ndarray, k: int) -> np.ndarray:
    return np.bincount(true * k + pred, minlength=k * k).reshape(k, k).astype(np.int64)


def part_ious(
    pred: np.ndarray, parts: np.ndarray, labels: np.ndarray, part_classes: np.ndarray
) -> np.ndarray:
    r"""Per shape the ShapeNet-part mIoU: the mean over the parts of the shape's class of
    :math:`|P \cap T| / |P \cup T|` (1 when a part is in neither prediction nor truth).

    Parameters
    ----------
    pred, parts : (M, N) int
        Predicted and true global part ids.
    labels : (M,) int
        Each shape's class.
    part_classes : (P,) int
        The class of each part id.

    Returns
    -------
    (M,) float64 ndarray

    Examples
    --------
    >>> part_ious(np.array([[0, 0, 1, 1]]), np.array([[0, 0, 0, 1]]), np.array([0]),
    ...           np.array([0, 0, 1]))
    array([0.58333333])
    """
    pred = check_numeric(pred, "pred")
    parts = check_numeric(parts, "parts")
    labels = check_numeric(labels, "labels")
    part_classes = check_numeric(part_classes, "part_classes").reshape(-1)
    if pred.shape != parts.shape or pred.ndim != 2 or labels.shape != (pred.shape[0],):
        raise InputError(
            f"pred and parts must be (M, N) and labels (M,); got {pred.shape}, {parts.shape}, "
            f"{labels.shape}"
        )
    out = np.empty(pred.shape[0])
    for i in range(pred.shape[0]):
        ids = np.flatnonzero(part_classes == labels[i])
        ious = []
        for p in ids:
            a, b = pred[i] == p, parts[i] == p
            union = np.count_nonzero(a | b)
            ious.append(1.0 if union == 0 else np.count_nonzero(a & b) / union)
        out[i] = float(np.mean(ious)) if ious else float("nan")
    return out


@torch.inference_mode()
def evaluate_cloud_model(model: nn.Module, data: Any, *, batch_size: int = 32) -> CloudEvaluation:
    """Score a classifier or part segmenter on a
    :class:`~robopercept.nn.cloud.data.CloudDataset` (eval mode, no augmentation).

    Segmenters are given the true category (when they take one) and their argmax is
    restricted to the parts of that category, as in the ShapeNet-part evaluation of the
    PointNet and DGCNN reference code.

    Returns
    -------
    CloudEvaluation
    """
    spec = cloud_model_spec(model)
    data = _check_data(data, "data", spec.task)
    k = spec.num_outputs
    cat = data.labels if spec.config.get("num_categories", 0) else None
    prob = predict_clouds(
        model, data.points[..., : spec.in_channels], category=cat, batch_size=batch_size
    )
    if spec.task == "classify":
        pred = prob.argmax(-1).astype(np.int64)
        true = data.labels.astype(np.int64)
        conf = _confusion(true, pred, max(k, data.num_classes))
        with np.errstate(invalid="ignore", divide="ignore"):
            per = np.diag(conf) / conf.sum(1)
        return CloudEvaluation(float((pred == true).mean()), float(np.nanmean(per)), conf, pred)
    assert data.parts is not None and data.part_classes is not None
    pc = np.asarray(data.part_classes)
    allowed = pc[None, :] == data.labels[:, None]  # (M, P) the parts of each shape's class
    prob = np.where(allowed[:, None, : prob.shape[-1]], prob, -1.0)
    pred = prob.argmax(-1).astype(np.int64)
    true = data.parts.astype(np.int64)
    ious = part_ious(pred, true, data.labels, pc)
    per_class = np.full(data.num_classes, np.nan)
    for c in range(data.num_classes):
        sel = data.labels == c
        if sel.any():
            per_class[c] = float(ious[sel].mean())
    conf = _confusion(true.ravel(), pred.ravel(), max(k, data.num_parts))
    with np.errstate(invalid="ignore", divide="ignore"):
        per = np.diag(conf) / conf.sum(1)
    return CloudEvaluation(
        float((pred == true).mean()),
        float(np.nanmean(per)),
        conf,
        pred,
        float(ious.mean()),
        float(np.nanmean(per_class)),
        per_class,
    )


# ----------------------------------------------------------------------------- files
def _name_list(value: Any, name: str) -> list[str]:
    """``value`` (a list, tuple or array of names) as a list of str."""
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise InputError(f"{name} must be a list of names; got {plain_repr(value)[:60]}")
    return [str(v) for v in value]


def save_cloud_model(
    path: str | os.PathLike[str],
    model: nn.Module,
    class_names: Sequence[str],
    *,
    part_names: Sequence[str] = (),
    part_classes: npt.ArrayLike | None = None,
    n_points: int = 1024,
    **extra: Any,
) -> Path:
    """Write a point-cloud network with what rebuilds it (its name and constructor
    settings), the class names (and part names and each part's class for a
    segmenter), the point count it was trained on, and ``extra`` plain values.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> net = build_cloud_model("pointnet", 2, width=0.125, seed=0)
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "net.pt"
    >>> _ = save_cloud_model(p, net, ["cube", "ball"], n_points=64)
    >>> net2, info = load_cloud_model(p)
    >>> info["class_names"], info["n_points"]
    (['cube', 'ball'], 64)
    """
    spec = cloud_model_spec(model)
    names = _name_list(class_names, "class_names")
    parts = _name_list(part_names, "part_names")
    outputs = names if spec.task == "classify" else parts
    if len(outputs) != spec.num_outputs:
        raise InputError(
            f"the network has {spec.num_outputs} outputs; got {len(outputs)} "
            f"{'class' if spec.task == 'classify' else 'part'} names"
        )
    pcs: list[int] = []
    if part_classes is not None:
        arr = check_numeric(part_classes, "part_classes").reshape(-1)
        whole = np.isfinite(arr).all() and bool((arr == np.round(arr)).all())
        if not whole or ((arr < 0) | (arr >= len(names))).any():
            raise InputError(
                f"part_classes must be class indices 0 .. {len(names) - 1}, one per part; "
                f"got {plain_repr(part_classes)}"
            )
        if parts and arr.size != len(parts):
            raise InputError(f"part_classes must give {len(parts)} classes, one per part name")
        pcs = [int(v) for v in arr]
    settings = {k: v for k, v in spec.config.items() if k != "num_outputs"}
    return save_built_model(
        path,
        model,
        spec.kind,
        settings,
        outputs,
        class_names=names,
        part_names=parts,
        part_classes=pcs,
        n_points=check_int(n_points, "n_points", 1),
        **extra,
    )


def _build(kind: str, n: int, **settings: Any) -> nn.Module:
    return build_cloud_model(kind, n, **settings)


def load_cloud_model(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a network written by :func:`save_cloud_model` (eval mode, CPU).

    Returns
    -------
    model : nn.Module
    info : dict
        ``class_names``, ``part_names``, ``part_classes``, ``n_points``, the settings
        and what else was saved.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a checkpoint that is not a point-cloud network's,
        settings the network's class does not take or refuses, weights that do not fit
        it (checked before loading:
        :func:`~robopercept.nn.train.checkpoint.load_built_model`), or names, part
        classes or a point count that do not fit it.
    """
    model, info = load_built_model(
        path,
        CLOUD_MODELS,
        _build,
        "point-cloud network",
        "save_cloud_model or `robopercept nn cloud train`",
        constructors={"pointnet": PointNet, "dgcnn": DGCNN},
    )
    _check_cloud_info(info, cloud_model_spec(model), os.fspath(path))
    return model, info


#: the most points per cloud a checkpoint may ask the predictors to sample
_MAX_POINTS = 1 << 20


def _check_cloud_info(info: dict[str, Any], spec: CloudModelSpec, where: str) -> None:
    """The names, part classes and point count :func:`save_cloud_model` stores beside
    the weights, checked against the network (a damaged file: FileFormatError)."""

    def names(key: str, n: int | None) -> list[str]:
        value = info.get(key, [])
        if (
            not isinstance(value, list)
            or not all(isinstance(v, str) for v in value)
            or (n is not None and len(value) != n)
        ):
            want = f"{n} names" if n is not None else "a list of names"
            raise FileFormatError(
                f"{where}: its {key!r} must be {want} (str) for this {spec.task} network; "
                f"got a {type(value).__name__}"
                + (f" of {len(value)}" if isinstance(value, list) else "")
                + ": the file is damaged"
            )
        return value

    classes = names("class_names", spec.num_outputs if spec.task == "classify" else None)
    parts = names("part_names", spec.num_outputs if spec.task == "segment" else None)
    pcs = info.get("part_classes", [])
    if (
        not isinstance(pcs, list)
        or len(pcs) not in (0, len(parts))
        or not all(
            isinstance(c, int) and not isinstance(c, bool) and 0 <= c < max(1, len(classes))
            for c in pcs
        )
    ):
        raise FileFormatError(
            f"{where}: its 'part_classes' must give each of the {len(parts)} parts the index "
            f"of its class (0 to {len(classes) - 1}): the file is damaged"
        )
    n = info.get("n_points", 1024)
    if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= _MAX_POINTS:
        raise FileFormatError(
            f"{where}: its 'n_points' must be a point count from 1 to {_MAX_POINTS}; got "
            f"{plain_repr(n)[:40]}: the file is damaged"
        )
