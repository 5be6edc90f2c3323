"""The networks shipped with robopercept, and where a model argument points.

The package ships small models trained on the procedural data sets (the detectors and
segmenters on the shapes, the pose networks on the articulated figures, the
point-cloud networks on the shape clouds). Their files live in the package's ``data``
folder; they are rebuilt from a checkout by the commands of :data:`BUILD_SHIPPED`.

A *model* argument, wherever robopercept takes one (``robopercept nn detect IMAGE
--model``, the batch jobs, :func:`~robopercept.nn.predict.load_image_predictor`),
is one of three things, resolved by :func:`resolve_model`:

- ``None``: the default shipped model of the kind (:data:`DEFAULT_SHIPPED`);
- a shipped name (a key of ``SHIPPED[kind]``, e.g. ``"faster"``);
- a run folder (the folder's ``model.pt``) or a checkpoint file.

This module imports no torch (the command line reads the names for its ``--help``).
"""

from __future__ import annotations

import os
from pathlib import Path

from robopercept._checks import check_choice, plain_repr
from robopercept.errors import InputError

__all__ = [
    "BUILD_SHIPPED",
    "DEFAULT_SHIPPED",
    "SHIPPED",
    "SHIPPED_CLOUD_MODELS",
    "SHIPPED_DETECTORS",
    "SHIPPED_POSE_MODELS",
    "SHIPPED_SEGMENTERS",
    "resolve_model",
    "shipped_model_path",
]

#: the shipped detectors (trained on the procedural shapes), relative to the package
SHIPPED_DETECTORS: dict[str, str] = {
    "fcos": "data/detector_fcos_shapes.pt",
    "faster": "data/detector_faster_shapes.pt",
}
#: the shipped segmenters (U-Net semantic, Mask R-CNN instance; procedural shapes)
SHIPPED_SEGMENTERS: dict[str, str] = {
    "unet": "data/segmenter_unet_shapes.pt",
    "maskrcnn": "data/segmenter_maskrcnn_shapes.pt",
}
#: the shipped pose networks (procedural figures; DeepPose with its cascade stage)
SHIPPED_POSE_MODELS: dict[str, str] = {
    "hrnet": "data/pose_hrnet_figures.pt",
    "deeppose": "data/pose_deeppose_figures.pt",
}
#: the shipped point-cloud networks (procedural shapes; part segmentation for parts)
SHIPPED_CLOUD_MODELS: dict[str, str] = {
    "pointnet": "data/cloud_pointnet_shapes.pt",
    "dgcnn": "data/cloud_dgcnn_shapes.pt",
    "pointnet-parts": "data/cloud_pointnet_parts.pt",
}
#: every shipped table by kind (the same dict objects as above)
SHIPPED: dict[str, dict[str, str]] = {
    "detect": SHIPPED_DETECTORS,
    "segment": SHIPPED_SEGMENTERS,
    "pose": SHIPPED_POSE_MODELS,
    "cloud": SHIPPED_CLOUD_MODELS,
}
#: the model of each kind when none is named
DEFAULT_SHIPPED: dict[str, str] = {
    "detect": "fcos",
    "segment": "unet",
    "pose": "hrnet",
    "cloud": "pointnet",
}
#: the command, run in a checkout, that rebuilds the shipped models of each kind
BUILD_SHIPPED: dict[str, str] = {
    "detect": "python -m benchmarks.detection_figures --only shapes-fcos-ema shapes-faster "
    "--seeds 0 --save src/robopercept/data",
    "segment": "python -m benchmarks.segmentation_figures --only shapes-unet shapes-maskrcnn "
    "--seeds 0 --save src/robopercept/data",
    "pose": "python -m benchmarks.pose_figures --only hrnet deeppose --seeds 0 "
    "--save src/robopercept/data",
    "cloud": "python -m benchmarks.cloud_figures --only pointnet dgcnn pointnet-parts --seeds 0 "
    "--save src/robopercept/data",
}


def _package_root() -> Path:
    from importlib.resources import files

    return Path(str(files("robopercept")))


def shipped_model_path(kind: str, name: str | None = None) -> Path:
    """The installed file of a shipped model.

    The path is ``<robopercept package>/SHIPPED[kind][name]``; ``name=None`` means
    ``DEFAULT_SHIPPED[kind]``.

    Parameters
    ----------
    kind : {"detect", "segment", "pose", "cloud"}
    name : str, optional
        A key of ``SHIPPED[kind]`` (default: the kind's default model).

    Returns
    -------
    pathlib.Path
        The checkpoint file.

    Raises
    ------
    InputError
        Unknown kind or name (the message lists the names), or the file is not installed
        (the message gives the command of :data:`BUILD_SHIPPED` that builds it).

    Examples
    --------
    >>> shipped_model_path("detect").name
    'detector_fcos_shapes.pt'
    >>> shipped_model_path("pose", "deeppose").name
    'pose_deeppose_figures.pt'
    """
    check_choice(kind, "kind", tuple(SHIPPED))
    table = SHIPPED[kind]
    key = DEFAULT_SHIPPED[kind] if name is None else name
    if not isinstance(key, str) or key not in table:
        raise InputError(
            f"name: no shipped {kind} model {plain_repr(name)}; the shipped ones are "
            f"{', '.join(table)} (or give a run folder or model.pt)"
        )
    path = _package_root() / table[key]
    if not path.is_file():
        raise InputError(
            f"the shipped model {table[key]} is not installed: give a run folder or model.pt "
            f"instead, or build it from a checkout with: {BUILD_SHIPPED[kind]}"
        )
    return path


def resolve_model(kind: str, model: str | os.PathLike[str] | None = None) -> Path:
    """The checkpoint file that a model argument names.

    ``None`` or a shipped name (a key of ``SHIPPED[kind]``) gives
    :func:`shipped_model_path`; anything else is a path: a folder means its
    ``model.pt`` (a training run's folder), a file is itself.

    Parameters
    ----------
    kind : {"detect", "segment", "pose", "cloud"}
    model : str or path-like, optional
        ``None`` (the kind's default shipped model), a shipped name, a run folder or a
        checkpoint file.

    Returns
    -------
    pathlib.Path
        An existing file (whether it is a checkpoint of the right kind is for the loader
        to say).

    Raises
    ------
    InputError
        Unknown kind, a shipped model that is not installed, or no such file.

    Examples
    --------
    >>> resolve_model("segment", "maskrcnn").name
    'segmenter_maskrcnn_shapes.pt'
    >>> resolve_model("cloud") == shipped_model_path("cloud", "pointnet")
    True
    """
    check_choice(kind, "kind", tuple(SHIPPED))
    if model is None or (isinstance(model, str) and model in SHIPPED[kind]):
        return shipped_model_path(kind, model)
    if not isinstance(model, str | os.PathLike):
        raise InputError(
            f"model must be a shipped name, a run folder or a model.pt path; got "
            f"{plain_repr(model)}"
        )
    path = Path(model)
    if path.is_dir():
        path = path / "model.pt"
    if not path.is_file():
        raise InputError(
            f"MODEL: no such file: {path}: give a run folder, a model.pt or a shipped model "
            f"({', '.join(SHIPPED[kind])})"
        )
    return path
