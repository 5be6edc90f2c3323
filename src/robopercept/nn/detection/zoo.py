r"""The detectors by name: :data:`DETECTORS`, and :func:`build_detector`,
:func:`save_detector` and :func:`load_detector` that rebuild any of them by name from a
checkpoint (the ``robopercept nn detect`` CLI); :func:`detect_arrays` runs one on NumPy
images.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from robopercept._checks import plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_count, check_module
from robopercept.nn.data.datasets import to_unit_float
from robopercept.nn.detection.fast_rcnn import FastRCNN
from robopercept.nn.detection.faster_rcnn import FasterRCNN
from robopercept.nn.detection.fcos import FCOS
from robopercept.nn.detection.keypoint_rcnn import KeypointRCNN
from robopercept.nn.detection.localizer import SingleObjectLocalizer
from robopercept.nn.detection.mask_rcnn import MaskRCNN
from robopercept.nn.detection.rcnn import RCNN, selective_search_proposals
from robopercept.nn.detection.thresholds import ScoreThreshold, choose_score_threshold
from robopercept.nn.train.checkpoint import load_built_model, save_built_model

__all__ = [
    "DETECTORS",
    "build_detector",
    "calibrate_detector",
    "detect_arrays",
    "load_detector",
    "save_detector",
]


#: the detectors by the names the CLI uses
DETECTORS: dict[str, type[nn.Module]] = {
    "fcos": FCOS,
    "faster": FasterRCNN,
    "maskrcnn": MaskRCNN,
    "keypointrcnn": KeypointRCNN,
    "fast": FastRCNN,
    "rcnn": RCNN,
    "localizer": SingleObjectLocalizer,
}


def build_detector(
    kind: str, num_classes: int, *, seed: int | None = None, **settings: Any
) -> nn.Module:
    """A detector of :data:`DETECTORS` by name, with its constructor ``settings``.

    ``"fast"`` gets :func:`selective_search_proposals` as ``proposal_fn`` (``"rcnn"``
    uses it by default), so every kind rebuilt from a checkpoint runs on bare images.

    Parameters
    ----------
    kind : {"fcos", "faster", "fast", "rcnn", "localizer"}
    num_classes : int
    seed : int, optional
        Seeds torch's global generator (:func:`torch.manual_seed`) before the weights
        are drawn.
    **settings
        Keyword arguments of the class (e.g. ``width=8``): plain ints, floats, strings
        and tuples, so :func:`save_detector` can store them.

    Returns
    -------
    torch.nn.Module

    Raises
    ------
    InputError
        Unknown ``kind`` or a setting the class does not take (or out of range).

    Examples
    --------
    >>> type(build_detector("fcos", 3, width=8)).__name__
    'FCOS'
    """
    if not isinstance(kind, str) or kind not in DETECTORS:
        raise InputError(f"kind must be one of {sorted(DETECTORS)}; got {plain_repr(kind)}")
    cls = DETECTORS[kind]
    if kind == "fast":
        settings = {"proposal_fn": selective_search_proposals, **settings}
    if seed is not None:
        torch.manual_seed(check_count(seed, "seed", 0, 2**63 - 1))
    try:
        return cls(num_classes, **settings)
    except TypeError as exc:
        raise InputError(f"{cls.__name__}: {exc}; give keyword settings of the class") from None


def save_detector(
    path: str | os.PathLike[str],
    model: nn.Module,
    kind: str,
    settings: Mapping[str, Any],
    classes: Sequence[str],
    **extra: Any,
) -> Any:
    """Write ``model``'s weights with what rebuilds it (``kind``, ``settings``,
    ``classes``) to ``path`` (:func:`~robopercept.nn.train.checkpoint.save_checkpoint`);
    ``extra`` plain values (the data, the epochs ...) are stored beside them. Returns
    the path.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> m = build_detector("fcos", 2, width=8)
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "m.pt"
    >>> _ = save_detector(p, m, "fcos", {"width": 8}, ["a", "b"])
    >>> m2, info = load_detector(p)
    >>> info["classes"], type(m2).__name__
    (['a', 'b'], 'FCOS')
    """
    if not isinstance(kind, str) or kind not in DETECTORS:
        raise InputError(f"kind must be one of {sorted(DETECTORS)}; got {plain_repr(kind)}")
    return save_built_model(path, model, kind, settings, classes, **extra)


def load_detector(path: str | os.PathLike[str]) -> tuple[nn.Module, dict[str, Any]]:
    """Rebuild a detector written by :func:`save_detector` (eval mode, on the CPU).

    Returns
    -------
    model : torch.nn.Module
    info : dict
        The checkpoint without the weights (``kind``, ``settings``, ``classes``, ...).

    Raises
    ------
    FileFormatError
        Missing or unreadable file, a checkpoint without ``kind``/``classes`` (e.g. a
        classifier's), settings the detector's class does not take or refuses, or
        weights that do not fit it (checked before loading:
        :func:`~robopercept.nn.train.checkpoint.load_built_model`).
    """
    return load_built_model(
        path,
        tuple(DETECTORS),
        build_detector,
        "detector",
        "save_detector or `robopercept nn detect train`",
        constructors=DETECTORS,
    )


def detect_arrays(model: nn.Module, images: Sequence[Any]) -> list[dict[str, Any]]:
    """Eval-mode detections of NumPy images, as NumPy arrays.

    Each image, ``(H, W, 3)`` ``uint8``, ``uint16`` or float in [0, 1], is scaled to
    [0, 1] (:func:`~robopercept.nn.data.datasets.to_unit_float`), made a ``(3, H, W)`` tensor
    on the model's device and run through ``model.predict`` one at a time.

    Parameters
    ----------
    model : torch.nn.Module
        A detector of this module (it has ``predict``).
    images : sequence of (H, W, 3) ndarray

    Returns
    -------
    list of dict
        ``{"boxes": (D, 4) float64 xyxy, "labels": (D,) int64, "scores": (D,) float64}``,
        and for a :class:`MaskRCNN` ``"masks"`` ``(D, H, W)`` bool (probability > 0.5),
        for a :class:`KeypointRCNN` ``"keypoints"`` ``(D, J, 3)`` float64 rows
        ``(x, y, score)``.

    Raises
    ------
    InputError
        Not a detector, or an image that is not ``(H, W, 3)``.

    Examples
    --------
    >>> import numpy as np
    >>> m = build_detector("fcos", 2, width=4)
    >>> d = detect_arrays(m, [np.zeros((32, 32, 3), np.uint8)])
    >>> sorted(d[0]), d[0]["boxes"].shape[1]
    (['boxes', 'labels', 'scores'], 4)
    """
    model = check_module(model)
    if not callable(getattr(model, "predict", None)):
        raise InputError(f"model must be a detector with predict(); got {type(model).__name__}")
    if isinstance(images, np.ndarray) or not isinstance(images, Sequence):
        raise InputError(
            f"images must be a list of (H, W, 3) arrays; got {plain_repr(images)}: wrap one "
            "image in a list"
        )
    p = next(model.parameters(), None)
    dev = p.device if p is not None else torch.device("cpu")
    out = []
    for i, im in enumerate(images):
        if not isinstance(im, np.ndarray) or im.ndim != 3 or im.shape[2] != 3:
            raise InputError(
                f"images[{i}] must be an (H, W, 3) RGB ndarray; got {plain_repr(im)}: read it "
                "with read_image(path, mode='rgb')"
            )
        x = np.ascontiguousarray(to_unit_float(im).astype(np.float32).transpose(2, 0, 1))
        d = model.predict([torch.from_numpy(x).to(dev)])[0]  # type: ignore[operator]
        res = {
            "boxes": d["boxes"].detach().cpu().double().numpy(),
            "labels": d["labels"].cpu().numpy(),
            "scores": d["scores"].detach().cpu().double().numpy(),
        }
        if "masks" in d:
            res["masks"] = (d["masks"][:, 0] > 0.5).cpu().numpy()
        if "keypoints" in d:
            kp = d["keypoints"].detach().cpu().double().numpy().copy()
            kp[..., 2] = d["keypoints_scores"].detach().cpu().double().numpy()
            res["keypoints"] = kp
        out.append(res)
    return out


def calibrate_detector(model: nn.Module, dataset: Any, iou: float = 0.5) -> ScoreThreshold:
    """The score threshold ``model`` should ship with, chosen on the validation images
    of ``dataset``: its eval-mode detections (:func:`detect_arrays`) matched to the
    true boxes and the F1-best threshold taken
    (:func:`~robopercept.nn.detection.thresholds.choose_score_threshold`). Store
    ``.to_dict()`` as the checkpoint's ``calibration``: the predictor keeps detections
    at or above it and warns on images whose best score falls short.

    Parameters
    ----------
    model : torch.nn.Module
        A detector of this module.
    dataset : DetectionDataset
        Validation images with their boxes and labels.
    iou : float
        The IoU a detection needs to count as right.

    Returns
    -------
    ScoreThreshold
    """
    model = check_module(model)
    if not all(hasattr(dataset, a) for a in ("images", "boxes", "labels")):
        raise InputError(
            f"dataset must be a DetectionDataset (images with boxes and labels); got "
            f"{plain_repr(dataset)}"
        )
    images = [np.asarray(im) for im in dataset.images]
    truths = [
        {"boxes": np.asarray(b), "labels": np.asarray(lab)}
        for b, lab in zip(dataset.boxes, dataset.labels, strict=True)
    ]
    was = model.training
    model.eval()
    try:
        return choose_score_threshold(detect_arrays(model, images), truths, iou)
    finally:
        model.train(was)
