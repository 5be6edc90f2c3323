r"""Training and COCO evaluation of the detectors: :func:`train_detector` (the one
loop, :func:`~robopercept.nn.train.loop.train_loop`, over a
:class:`~robopercept.nn.detection.data.DetectionDataset`, with validation that keeps the
best epoch and optional weight averaging), :func:`evaluate_detector` (boxes, masks or
keypoints, equal to pycocotools) and :class:`DetectionHistory`.

Determinism: sampling draws from torch's global generator, so a run seeded by
:func:`train_detector` (``TrainConfig.seed``) gives identical losses and weights on the
CPU for the same thread count. Models run on CUDA when moved there (``config.device``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import torch
from torch import nn
from torch.optim.swa_utils import AveragedModel

from robopercept._checks import as_path, check_bool, check_choice, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.coco.evaluate import evaluate_detections
from robopercept.nn.coco.rle import rle_encode
from robopercept.nn.detection.data import DetectionDataset, collate_detection
from robopercept.nn.train.config import TrainConfig, resolve_device
from robopercept.nn.train.loop import LoopResult, step_optimizer, train_loop

__all__ = [
    "VAL_METRICS",
    "DetectionHistory",
    "check_detection_dataset",
    "detections_per_image",
    "evaluate_detector",
    "train_detector",
]


@dataclass
class DetectionHistory:
    """What :func:`train_detector` measured: per epoch, the mean of each loss over the
    batches (and of their sum, ``"loss"``), and the seconds it took; with a validation
    set, the validation figure at each evaluated epoch and the epoch that was kept.

    Attributes
    ----------
    losses : list of dict of str to float
    seconds : list of float
        Training seconds per epoch (validation not included).
    val : dict of int to float
        Epoch (1-based) -> validation ``val_metric`` (empty without ``val``).
    best_epoch : int
        The epoch whose weights the model holds at the end (the last epoch without
        ``val``).
    val_seconds : float
        Seconds spent evaluating the validation set.
    """

    losses: list[dict[str, float]] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    val: dict[int, float] = field(default_factory=dict)
    best_epoch: int = 0
    val_seconds: float = 0.0


#: validation figures :func:`train_detector` can select on: index into the COCO stats
VAL_METRICS = {"AP": 0, "AP50": 1, "AP75": 2}


def check_detection_dataset(dataset: Any) -> Any:
    """Check that ``dataset`` is a non-empty
    :class:`~robopercept.nn.detection.data.DetectionDataset` and return it.

    Parameters
    ----------
    dataset : DetectionDataset

    Returns
    -------
    DetectionDataset

    Raises
    ------
    InputError
        Another type, or an empty set.
    """

    if not isinstance(dataset, DetectionDataset):
        raise InputError(
            "dataset must be a DetectionDataset (procedural_detection_set, digits_detection_set, "
            f"deepforest_tiles, ...); got {type(dataset).__name__}"
        )
    if len(dataset) == 0:
        raise InputError("dataset is empty: give at least one image")
    return dataset


def train_detector(
    model: nn.Module,
    dataset: Any,
    config: Any = None,
    *,
    checkpoint: str | os.PathLike[str] | None = None,
    progress: bool = True,
    val: Any = None,
    val_every: int = 1,
    val_metric: str = "AP",
    augment: Callable[[torch.Tensor, dict[str, Any]], tuple[torch.Tensor, dict[str, Any]]]
    | None = None,
    ema: float | None = None,
    val_iou_type: str = "bbox",
    val_sigmas: Any = None,
    resume: bool = False,
) -> DetectionHistory:
    r"""Train a detector of this module (or any model keeping the torchvision detection
    contract) on a :class:`~robopercept.nn.detection.data.DetectionDataset`.

    Each step: a shuffled mini-batch of ``config.batch_size`` images (a generator seeded
    by ``config.seed``), the model's loss dict in train mode, their sum back-propagated,
    an optimizer step (``config.optimizer``, ``lr``, ``weight_decay``; gradient clipping
    with ``clip_grad_norm``) and, per epoch, the schedule of ``config.schedule``. Torch's
    global generator is seeded with ``config.seed`` first (weights are not re-initialized:
    build the model after your own ``torch.manual_seed`` for a fully seeded run) and
    deterministic algorithms are on, so the same seed gives identical losses on the CPU.

    With ``val``, the model is evaluated on it (:func:`evaluate_detector`, COCO) every
    ``val_every`` epochs and after the last, and at the end holds the weights of the
    evaluated epoch with the highest ``val_metric`` (the earliest on ties), as
    :func:`~robopercept.nn.train.fit.fit` keeps its best epoch; the schedule still runs
    its full ``config.epochs`` (no early stopping).

    Parameters
    ----------
    model : torch.nn.Module
    dataset : DetectionDataset
    config : TrainConfig, optional
        :class:`~robopercept.nn.train.config.TrainConfig` (``patience``, ``monitor`` and
        the learning-rate multipliers are not used here).
    checkpoint : path, optional
        Written after every epoch (:func:`~robopercept.nn.train.loop.train_loop`'s
        checkpoint with ``"epoch"``, ``"losses"``, ``"history"`` and ``"architecture"``,
        the class name; ``"model"`` holds the kept weights, the average with ``ema``);
        the best weights go to ``<stem>.best.pt``. Read the weights back with
        :func:`~robopercept.nn.train.checkpoint.load_checkpoint` ``(path, model)``.
    progress : bool
        A bar per epoch on stderr.
    val : DetectionDataset, optional
        Validation set that selects the epoch kept.
    val_every : int
        Evaluate every this many epochs (>= 1).
    val_metric : {"AP", "AP50", "AP75"}
        mAP@[.5:.95], mAP@0.5 or mAP@0.75 (:data:`VAL_METRICS`).
    augment : callable, optional
        ``(image, target) -> (image, target)`` applied to each training sample as it
        is drawn, e.g. :class:`~robopercept.nn.detection.augment.FlipRotate` (seed it for a
        repeatable run).
    ema : float, optional
        Keep an exponential moving average of the weights and buffers (Polyak
        averaging, as ultralytics' ``ModelEMA``), updated after every optimizer step
        ``n = 1, 2, ...`` as :math:`\bar\theta \leftarrow d_n \bar\theta + (1 - d_n)
        \theta` with :math:`d_n = \min(\texttt{ema}, \frac{1 + n}{10 + n})` (the
        warm-up of ``tf.train.ExponentialMovingAverage``'s ``num_updates``, so the
        random initial weights are forgotten early), through
        :class:`torch.optim.swa_utils.AveragedModel`. The averaged weights are the ones
        validated, kept and returned in ``model``. In (0, 1); None: no averaging.
    val_iou_type : {"bbox", "segm", "keypoints"}
        What validation scores (:func:`evaluate_detector`'s ``iou_type``): the masks
        of a :class:`MaskRCNN` with ``"segm"``, the keypoints of a
        :class:`KeypointRCNN` with ``"keypoints"`` (OKS with ``val_sigmas``).
    val_sigmas : (J,) array_like, optional
        The OKS constants for ``"keypoints"``.
    resume : bool
        Continue the run of ``checkpoint`` (same model, data and settings): it ends with
        the weights of an uninterrupted run (``augment`` drawing from its own generator
        is not part of the checkpoint: resume exactly without it, or with a stateless one).

    Returns
    -------
    DetectionHistory

    Raises
    ------
    InputError
        Not a detection dataset or model, an unknown ``val_metric``, or a loss that
        became NaN or infinite.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.detection.fcos import FCOS
    >>> from robopercept.nn.detection.synthetic import digits_detection_set
    >>> from robopercept.nn.train.config import TrainConfig
    >>> _ = torch.manual_seed(0)
    >>> ds = digits_detection_set(2, (32, 32), (1, 1), rng=0, scale=(12, 16))
    >>> h = train_detector(FCOS(10, width=8, head_channels=16), ds,
    ...                    TrainConfig(epochs=1, batch_size=2, device="cpu"), progress=False)
    >>> sorted(h.losses[0])
    ['bbox_ctrness', 'bbox_regression', 'classification', 'loss']
    """
    model = check_module(model)
    ds = check_detection_dataset(dataset)
    if config is not None and not isinstance(config, TrainConfig):
        raise InputError(f"config must be a TrainConfig or None; got {plain_repr(config)}")
    cfg = config or TrainConfig()
    progress = check_bool(progress, "progress")
    ckpt = as_path(checkpoint, "checkpoint") if checkpoint is not None else None
    resume = check_bool(resume, "resume")
    val_ds = check_detection_dataset(val) if val is not None else None
    if augment is not None and not callable(augment):
        raise InputError(
            f"augment must be a callable (image, target) -> (image, target), e.g. "
            f"FlipRotate(); got {plain_repr(augment)}"
        )
    val_every = check_count(val_every, "val_every", 1, 1 << 30)
    check_choice(val_metric, "val_metric", VAL_METRICS)
    check_choice(val_iou_type, "val_iou_type", ("bbox", "segm", "keypoints"))
    if ema is not None:
        ema = check_real(ema, "ema (--ema)", 0.0, 1.0, low_inclusive=False, high_inclusive=False)
    dev = resolve_device(cfg.device)
    torch.manual_seed(cfg.seed)
    model.to(dev)
    gen = torch.Generator().manual_seed(cfg.seed)
    params = [p for p in model.parameters() if p.requires_grad]
    n = len(ds)
    steps = -(-n // cfg.batch_size)
    opt, sched = step_optimizer(params, cfg, steps)
    hist = DetectionHistory()
    averaged = _weight_average(model, ema) if ema is not None else None
    # the model validated and kept: the average when there is one
    kept = averaged.module if averaged is not None else model
    sums: dict[str, float] = {}

    def batches(epoch: int) -> Iterator[list[tuple[torch.Tensor, dict[str, Any]]]]:
        order = torch.randperm(n, generator=gen).tolist()
        for b in range(steps):
            items = [ds[j] for j in order[b * cfg.batch_size : (b + 1) * cfg.batch_size]]
            yield [augment(im, t) for im, t in items] if augment is not None else items

    def step(items: list[tuple[torch.Tensor, dict[str, Any]]], epoch: int, b: int) -> torch.Tensor:
        images, targets = collate_detection(items)
        losses = model(
            [im.to(dev) for im in images],
            [
                {k: t[k].to(dev) for k in ("boxes", "labels", "masks", "keypoints") if k in t}
                for t in targets
            ],
        )
        if not isinstance(losses, dict) or not losses:
            raise InputError(
                "the model must return a dict of losses in train mode (the torchvision "
                f"detection contract); got {type(losses).__name__}"
            )
        loss = sum(losses.values())
        assert isinstance(loss, torch.Tensor)
        for k, v in losses.items():
            sums[k] = sums.get(k, 0.0) + float(v.detach())
        sums["loss"] = sums.get("loss", 0.0) + float(loss.detach())
        return loss

    def end_epoch(epoch: int, seconds: float) -> None:
        hist.losses.append({k: v / steps for k, v in sums.items()})
        hist.seconds.append(seconds)
        sums.clear()

    def validate(epoch: int) -> float:
        t1 = time.perf_counter()
        ev = evaluate_detector(kept, val_ds, iou_type=val_iou_type, sigmas=val_sigmas)
        hist.val_seconds += time.perf_counter() - t1
        hist.val[epoch + 1] = float(ev.stats[VAL_METRICS[val_metric]])
        return hist.val[epoch + 1]

    def after_epoch(epoch: int, res: LoopResult, seconds: float) -> dict[str, str]:
        hist.best_epoch = res.best_epoch
        post = {"loss": f"{hist.losses[-1]['loss']:.3f}"}
        if hist.val:
            post[f"val {val_metric}"] = f"{hist.val[max(hist.val)]:.3f}"
        return post

    def restore(state: dict[str, Any]) -> None:
        saved = state["history"]
        hist.losses[:] = [dict(d) for d in saved["losses"]]
        hist.seconds[:] = list(saved["seconds"])
        hist.val.update({int(k): float(v) for k, v in saved["val"].items()})
        hist.best_epoch = int(saved["best_epoch"])
        hist.val_seconds = float(saved["val_seconds"])

    def extra(epoch: int) -> dict[str, Any]:
        return {
            "epoch": epoch + 1,
            "losses": hist.losses,
            "architecture": type(model).__name__,
            "history": {**asdict(hist), "val": {str(k): v for k, v in hist.val.items()}},
        }

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
        validate=validate if val_ds is not None else None,
        val_every=val_every,
        after_epoch=after_epoch,
        averaged=averaged,
        generators={"shuffle": gen},
        checkpoint=ckpt,
        checkpoint_extra=extra,
        best_extra={"architecture": type(model).__name__},
        resume=resume,
        restore=restore,
        desc="training detector",
        progress=progress,
    )
    return hist


def _weight_average(model: nn.Module, decay: float) -> Any:
    """``AveragedModel`` of ``model`` (weights and buffers) with the warmed-up EMA of
    :func:`train_detector`'s ``ema``."""

    def ema_step(avg: torch.Tensor, new: torch.Tensor, n: torch.Tensor | int) -> torch.Tensor:
        d = min(decay, (1.0 + float(n)) / (10.0 + float(n)))
        return d * avg + (1.0 - d) * new

    return AveragedModel(model, avg_fn=ema_step, use_buffers=True)


@torch.no_grad()
def evaluate_detector(
    model: nn.Module,
    dataset: Any,
    *,
    batch_size: int = 8,
    device: str | None = None,
    iou_type: str = "bbox",
    sigmas: Any = None,
) -> Any:
    """COCO evaluation (:func:`~robopercept.nn.coco.evaluate.evaluate_detections`, equal to
    pycocotools) of ``model``'s eval-mode detections on ``dataset``: of the boxes, or
    with ``iou_type="segm"`` of the instance masks (a :class:`MaskRCNN`'s
    probabilities thresholded at 0.5, run-length encoded by
    :func:`~robopercept.nn.coco.rle.rle_encode`, against the dataset's masks), or
    with ``iou_type="keypoints"`` of a :class:`KeypointRCNN`'s keypoints by OKS with
    the per-joint ``sigmas`` (required unless the set has COCO's 17 keypoints).

    Parameters
    ----------
    model : torch.nn.Module
        Eval mode returns ``[{"boxes", "labels", "scores"}]`` per image (and
        ``"masks"`` ``(D, 1, H, W)`` for ``"segm"``).
    dataset : DetectionDataset
        With masks for ``"segm"``.
    batch_size : int
    device : str, optional
        None: the device of the model's parameters.
    iou_type : {"bbox", "segm", "keypoints"}
    sigmas : (J,) array_like, optional
        The OKS constants of ``"keypoints"`` (e.g. ``MPII_16.sigmas``).

    Returns
    -------
    CocoEvaluation
        ``.stats[0]`` is mAP@[.5:.95], ``.stats[1]`` mAP@0.5.

    Examples
    --------
    >>> import torch
    >>> from robopercept.nn.detection.fcos import FCOS
    >>> from robopercept.nn.detection.synthetic import digits_detection_set
    >>> _ = torch.manual_seed(0)
    >>> ds = digits_detection_set(2, (32, 32), (1, 1), rng=0, scale=(12, 16))
    >>> ev = evaluate_detector(FCOS(10, width=8, head_channels=16), ds)
    >>> ev.stats.shape
    (12,)
    """
    model = check_module(model)
    ds = check_detection_dataset(dataset)
    bs = check_count(batch_size, "batch_size", 1, 1 << 16)
    kind = check_choice(iou_type, "iou_type", ("bbox", "segm", "keypoints"))
    segm = kind == "segm"
    keypoints = kind == "keypoints"
    if keypoints and ds.keypoints is None:
        raise InputError(
            "iou_type='keypoints' scores keypoints, and this dataset has none: use a set "
            "with keypoints (procedural_pose_scenes)"
        )
    if segm and ds.masks is None:
        raise InputError(
            "iou_type='segm' scores masks, and this dataset has none: use a set with "
            "instance masks (procedural_detection_set, digits_detection_set)"
        )
    if device is None:
        p = next(model.parameters(), None)
        dev = p.device if p is not None else torch.device("cpu")
    else:
        dev = resolve_device(device)
        model.to(dev)
    results: list[Mapping[str, Any]] = []
    for t, d in detections_per_image(model, ds, bs, dev):
        b = d["boxes"].detach().cpu().double().numpy()
        if segm and "masks" not in d:
            raise InputError(
                f"iou_type='segm' needs masks, and {type(model).__name__} gives none: use "
                "a MaskRCNN, or iou_type='bbox'"
            )
        if keypoints and "keypoints" not in d:
            raise InputError(
                f"iou_type='keypoints' needs keypoints, and {type(model).__name__} gives none: "
                "use a KeypointRCNN, or iou_type='bbox'"
            )
        masks = (d["masks"][:, 0] > 0.5).cpu().numpy() if segm else None
        kps = d["keypoints"].detach().cpu().double().numpy() if keypoints else None
        for j, (box, lab, sc) in enumerate(
            zip(b, d["labels"].cpu().numpy(), d["scores"].cpu().double().numpy(), strict=True)
        ):
            res: dict[str, Any] = {
                "image_id": int(t["image_id"]),
                "category_id": int(lab),
                "bbox": [
                    float(box[0]),
                    float(box[1]),
                    float(box[2] - box[0]),
                    float(box[3] - box[1]),
                ],
                "score": float(sc),
            }
            if masks is not None:
                res["segmentation"] = rle_encode(masks[j])
            if kps is not None:
                res["keypoints"] = kps[j].ravel().tolist()
            results.append(res)
    return evaluate_detections(ds.to_coco(masks=segm), results, iou_type=kind, sigmas=sigmas)


def detections_per_image(
    model: nn.Module, ds: Any, batch_size: int, dev: torch.device
) -> list[tuple[dict[str, Any], dict[str, torch.Tensor]]]:
    """(target, eval-mode detections) of every image of ``ds``, in batches; the model's
    train/eval mode is restored after.

    Parameters
    ----------
    model : torch.nn.Module
        A detector (eval mode gives ``[{"boxes", "labels", "scores", ...}]``).
    ds : DetectionDataset
        Checked (:func:`check_detection_dataset`).
    batch_size : int
    dev : torch.device
        Where the images go.

    Returns
    -------
    list of (dict, dict)
        The dataset's target and the model's detections, per image, in order.
    """
    was = model.training
    model.eval()
    out: list[tuple[dict[str, Any], dict[str, torch.Tensor]]] = []
    try:
        for start in range(0, len(ds), batch_size):
            images, targets = collate_detection(
                [ds[j] for j in range(start, min(len(ds), start + batch_size))]
            )
            out.extend(zip(targets, model([im.to(dev) for im in images]), strict=True))
    finally:
        model.train(was)
    return out
