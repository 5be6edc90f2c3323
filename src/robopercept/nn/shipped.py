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
from dataclasses import asdict, dataclass
from pathlib import Path

from robopercept._checks import as_path, check_choice, plain_repr
from robopercept.errors import InputError

__all__ = [
    "BUILD_SHIPPED",
    "DEFAULT_SHIPPED",
    "MODEL_CARDS",
    "SHIPPED",
    "SHIPPED_CLASSIFIERS",
    "SHIPPED_CLOUD_MODELS",
    "SHIPPED_DETECTORS",
    "SHIPPED_POSE_MODELS",
    "SHIPPED_SEGMENTERS",
    "ModelCard",
    "domain_line",
    "model_card",
    "resolve_model",
    "shipped_model_path",
]


@dataclass(frozen=True)
class ModelCard:
    """What a shipped model knows: its task, classes, the data it learnt from and how
    well it does on images it never saw (``robopercept nn models``).

    Attributes
    ----------
    name : str
        The name to give ``--model`` (unique over all kinds).
    kind : {"detect", "segment", "pose", "cloud", "classify"}
    file : str
        The weights, relative to the package.
    network : str
        The architecture in a few words.
    classes : tuple of str
        What it outputs (the joints for pose).
    real : bool
        Trained on real images (True) or on generated, procedural ones (False).
    data : str
        The training data, where it comes from and its terms.
    domain : str
        The inputs it is meant for, with their scale.
    tile : int or None
        The window side tiled inference uses on larger images (detect and segment).
    figure : str
        Its measured figure on a split no choice saw.
    build : str
        The command, run in a checkout, that rebuilds it.
    """

    name: str
    kind: str
    file: str
    network: str
    classes: tuple[str, ...]
    real: bool
    data: str
    domain: str
    tile: int | None
    figure: str
    build: str

    @property
    def trained_on(self) -> str:
        """``"real data: ..."`` or ``"procedural data: ..."``, the first clause of
        :attr:`data`."""
        return f"{'real' if self.real else 'procedural'} data: {self.data.split(';')[0]}"

    def to_dict(self) -> dict[str, object]:
        """Plain values (``nn models --json``)."""
        d = asdict(self)
        d["classes"] = list(self.classes)
        d["training_data"] = "real" if self.real else "procedural"
        del d["real"]
        return d


_SHAPES = ("circle", "square", "triangle", "cross")
_SHAPES_DATA = (
    "generated shapes (circle, square, triangle, cross) on 128 x 128 crops of "
    "scikit-image's bundled photos; made by robopercept, no outside images"
)
_FIGURES_DATA = (
    "generated articulated stick figures (16 MPII-style joints) on 128 x 128 crops of "
    "scikit-image's bundled photos; made by robopercept"
)
_CLOUD_DATA = "generated point clouds of simple solids (sampled meshes); made by robopercept"
_DEEPFOREST = (
    "DeepForest NEON aerial RGB orthophotos with hand-drawn tree-crown boxes, YELL crop2 "
    "above its held-out strip and the YELL crop image (Weinstein et al.; from the PyPI "
    "wheel deepforest 2.1.0); "
    "the images' terms are not stated upstream, only the weights are shipped"
)
_NUCLEI = (
    "fluorescence microscopy nuclei (2018 Data Science Bowl, BBBC038, Caicedo et al. "
    "2019; the 512 x 512 sample of the PyPI wheel stardist 0.9.2), three quadrants; the "
    "image's terms are not stated upstream, only the weights are shipped"
)
_SHAPES_DOMAIN = "RGB images of the generated shapes, objects 16-60 px"
_NUCLEI_DOMAIN = "grey fluorescence microscopy of cell nuclei, nuclei about 10-30 px across"


_SHIPPED_MODELS = (
    "python -m benchmarks.shipped_models --only {} --seeds 0 --threads {} "
    "--save src/robopercept/data"
)

#: every shipped model's card, by name
MODEL_CARDS: dict[str, ModelCard] = {
    c.name: c
    for c in (
        ModelCard(
            "trees",
            "detect",
            "data/detector_fcos_trees.pt",
            "FCOS, ResNet-style backbone with FPN, 0.93 M parameters",
            ("Tree",),
            True,
            _DEEPFOREST,
            "RGB aerial orthophotos at about 10 cm per pixel, crowns 15-70 px; trained on "
            "400 px tiles, larger images are tiled",
            400,
            "AP50 0.62 on the 12 held-out tiles of YELL crop2, 0.51 on the strip as one "
            "image (COCO's default cap of 100; 0.63 with 300), with the test-time "
            "augmentation it ships with (flips at 3 scales, chosen on validation; "
            "--tta none: 0.51 and 0.39); other sites in docs/detection.md",
            _SHIPPED_MODELS.format("trees", 2),
        ),
        ModelCard(
            "fcos",
            "detect",
            "data/detector_fcos_shapes.pt",
            "FCOS, ResNet-style backbone with FPN",
            _SHAPES,
            False,
            _SHAPES_DATA,
            _SHAPES_DOMAIN,
            None,
            "mAP@0.5 0.91 on 200 test canvases",
            "python -m benchmarks.detection_figures --only shapes-fcos-ema --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "faster",
            "detect",
            "data/detector_faster_shapes.pt",
            "Faster R-CNN, ResNet-style backbone with FPN",
            _SHAPES,
            False,
            _SHAPES_DATA,
            _SHAPES_DOMAIN,
            None,
            "mAP@0.5 0.93 on 200 test canvases",
            "python -m benchmarks.detection_figures --only shapes-faster --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "nuclei",
            "segment",
            "data/segmenter_unet_nuclei.pt",
            "U-Net, width 8, depth 3, 121 k parameters (grey input)",
            ("nucleus",),
            True,
            _NUCLEI,
            _NUCLEI_DOMAIN,
            256,
            "foreground IoU 0.90, instance F1@0.5 0.88 on the held-out quadrant",
            _SHIPPED_MODELS.format("nuclei", 1),
        ),
        ModelCard(
            "nuclei-maskrcnn",
            "segment",
            "data/segmenter_maskrcnn_nuclei.pt",
            "Mask R-CNN, anchors 8-32 px",
            ("nucleus",),
            True,
            _NUCLEI,
            _NUCLEI_DOMAIN,
            256,
            "mask AP50 0.86 on the held-out quadrant",
            _SHIPPED_MODELS.format("nuclei-maskrcnn", 1),
        ),
        ModelCard(
            "unet",
            "segment",
            "data/segmenter_unet_shapes.pt",
            "U-Net, width 8, depth 4",
            _SHAPES,
            False,
            _SHAPES_DATA,
            _SHAPES_DOMAIN,
            None,
            "mIoU 0.88 on 200 test canvases",
            "python -m benchmarks.segmentation_figures --only shapes-unet --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "maskrcnn",
            "segment",
            "data/segmenter_maskrcnn_shapes.pt",
            "Mask R-CNN, ResNet-style backbone with FPN",
            _SHAPES,
            False,
            _SHAPES_DATA,
            _SHAPES_DOMAIN,
            None,
            "mask AP50 0.87 on 200 test canvases",
            "python -m benchmarks.segmentation_figures --only shapes-maskrcnn --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "hrnet",
            "pose",
            "data/pose_hrnet_figures.pt",
            "small HRNet, heatmaps",
            ("16 joints",),
            False,
            _FIGURES_DATA,
            "one figure per image, about the size of the image (top-down), 128 px",
            None,
            "PCKh@0.5 in docs/pose.md",
            "python -m benchmarks.pose_figures --only hrnet --seeds 0 --save src/robopercept/data",
        ),
        ModelCard(
            "deeppose",
            "pose",
            "data/pose_deeppose_figures.pt",
            "DeepPose regression with a cascade stage",
            ("16 joints",),
            False,
            _FIGURES_DATA,
            "one figure per image, about the size of the image (top-down), 128 px",
            None,
            "PCKh@0.5 in docs/pose.md",
            "python -m benchmarks.pose_figures --only deeppose --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "pointnet",
            "cloud",
            "data/cloud_pointnet_shapes.pt",
            "PointNet classifier",
            ("shape classes",),
            False,
            _CLOUD_DATA,
            "one object's point cloud, centred and scaled to the unit sphere",
            None,
            "accuracy in docs/pointnet.md",
            "python -m benchmarks.cloud_figures --only pointnet --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "dgcnn",
            "cloud",
            "data/cloud_dgcnn_shapes.pt",
            "DGCNN classifier",
            ("shape classes",),
            False,
            _CLOUD_DATA,
            "one object's point cloud, centred and scaled to the unit sphere",
            None,
            "accuracy in docs/pointnet.md",
            "python -m benchmarks.cloud_figures --only dgcnn --seeds 0 --save src/robopercept/data",
        ),
        ModelCard(
            "pointnet-parts",
            "cloud",
            "data/cloud_pointnet_parts.pt",
            "PointNet part segmentation",
            ("part labels",),
            False,
            _CLOUD_DATA,
            "one object's point cloud, centred and scaled to the unit sphere",
            None,
            "part mIoU in docs/pointnet.md",
            "python -m benchmarks.cloud_figures --only pointnet-parts --seeds 0 "
            "--save src/robopercept/data",
        ),
        ModelCard(
            "digits",
            "classify",
            "data/classifier_digits.pt",
            "resnet_small, 78 k parameters (8 x 8 grey input)",
            tuple("0123456789"),
            True,
            "scikit-learn's handwritten digits (UCI optical recognition of handwritten "
            "digits, 1,797 8 x 8 images), stratified 70/15/15; CC BY 4.0 (UCI)",
            "8 x 8 grey images of one light handwritten digit on black; larger images are "
            "shrunk to 8 x 8",
            None,
            "test accuracy 0.99 on 270 digits",
            _SHIPPED_MODELS.format("digits", 1),
        ),
    )
}


def _table(kind: str) -> dict[str, str]:
    return {n: c.file for n, c in MODEL_CARDS.items() if c.kind == kind}


#: the shipped detectors, relative to the package
SHIPPED_DETECTORS: dict[str, str] = _table("detect")
#: the shipped segmenters (semantic U-Nets, Mask R-CNN instances)
SHIPPED_SEGMENTERS: dict[str, str] = _table("segment")
#: the shipped pose networks (procedural figures; DeepPose with its cascade stage)
SHIPPED_POSE_MODELS: dict[str, str] = _table("pose")
#: the shipped point-cloud networks (procedural shapes; part segmentation for parts)
SHIPPED_CLOUD_MODELS: dict[str, str] = _table("cloud")
#: the shipped image classifiers (``robopercept nn predict --model``)
SHIPPED_CLASSIFIERS: dict[str, str] = _table("classify")
#: every shipped table by kind (the same dict objects as above)
SHIPPED: dict[str, dict[str, str]] = {
    "detect": SHIPPED_DETECTORS,
    "segment": SHIPPED_SEGMENTERS,
    "pose": SHIPPED_POSE_MODELS,
    "cloud": SHIPPED_CLOUD_MODELS,
    "classify": SHIPPED_CLASSIFIERS,
}
#: the model of each kind when none is named
DEFAULT_SHIPPED: dict[str, str] = {
    "detect": "fcos",
    "segment": "unet",
    "pose": "hrnet",
    "cloud": "pointnet",
    "classify": "digits",
}
#: the command, run in a checkout, that rebuilds the shipped models of each kind
BUILD_SHIPPED: dict[str, str] = {
    "detect": "python -m benchmarks.detection_figures --only shapes-fcos-ema shapes-faster "
    "--seeds 0 --save src/robopercept/data; " + _SHIPPED_MODELS.format("trees", 2),
    "segment": "python -m benchmarks.segmentation_figures --only shapes-unet shapes-maskrcnn "
    "--seeds 0 --save src/robopercept/data; " + _SHIPPED_MODELS.format("nuclei nuclei-maskrcnn", 1),
    "pose": "python -m benchmarks.pose_figures --only hrnet deeppose --seeds 0 "
    "--save src/robopercept/data",
    "cloud": "python -m benchmarks.cloud_figures --only pointnet dgcnn pointnet-parts --seeds 0 "
    "--save src/robopercept/data",
    "classify": _SHIPPED_MODELS.format("digits", 1),
}


def model_card(name: str) -> ModelCard:
    """The card of the shipped model ``name``.

    Raises
    ------
    InputError
        No shipped model of that name (the message lists them).

    Examples
    --------
    >>> c = model_card("trees")
    >>> (c.kind, c.real, c.tile)
    ('detect', True, 400)
    """
    if not isinstance(name, str) or name not in MODEL_CARDS:
        raise InputError(
            f"--model: no shipped model {plain_repr(name)}; the shipped ones are "
            f"{', '.join(MODEL_CARDS)} (robopercept nn models lists them)"
        )
    return MODEL_CARDS[name]


def domain_line(kind: str, model: str | os.PathLike[str] | None) -> str:
    """The one line every prediction prints about the model it used: the shipped
    model's name, its network and what it was trained on; for a run folder or
    checkpoint, its path.

    Examples
    --------
    >>> print(domain_line("detect", "trees"))  # doctest: +ELLIPSIS
    model: trees (FCOS, ...), trained on real data: DeepForest NEON aerial RGB ...
    >>> domain_line("detect", "runs/mine")
    'model: runs/mine (your own run; its training data is what you gave it)'
    """
    check_choice(kind, "kind", tuple(SHIPPED))
    name = DEFAULT_SHIPPED[kind] if model is None else model
    if isinstance(name, str) and name in SHIPPED[kind]:
        c = MODEL_CARDS[name]
        return f"model: {c.name} ({c.network}), trained on {c.trained_on}"
    if not isinstance(name, str | os.PathLike):
        raise InputError(
            f"model must be a shipped name, a run folder or a model.pt path; got "
            f"{plain_repr(name)[:60]}"
        )
    return f"model: {os.fspath(name)} (your own run; its training data is what you gave it)"


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
            f"instead, or build it from a checkout with: {MODEL_CARDS[key].build}"
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
    path = as_path(model, "MODEL (a run folder or a model.pt)")
    try:
        if path.is_dir():
            path = path / "model.pt"
        found = path.is_file()
    except OSError as exc:  # a folder that cannot be searched: EACCES, EIO
        raise InputError(
            f"MODEL: cannot read {path} ({exc.strerror or type(exc).__name__}): give a run "
            f"folder, a model.pt or a shipped model ({', '.join(SHIPPED[kind])})"
        ) from None
    if not found:
        raise InputError(
            f"MODEL: no such file: {path}: give a run folder, a model.pt or a shipped model "
            f"({', '.join(SHIPPED[kind])})"
        )
    return path
