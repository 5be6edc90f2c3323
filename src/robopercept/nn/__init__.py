"""Deep learning in pure PyTorch: the layer arithmetic, the blocks of VGG, Inception and
ResNet, training and fine-tuning, detection, segmentation, pose and point-cloud networks
(extra ``deep``: ``pip install 'robopercept[deep]'``).

The package is laid out as task wings over shared floors, as torchvision is:

- ground, torch-free: :mod:`.functional` (convolution and pooling by the mathematics, in
  NumPy), :mod:`.skeleton`, :mod:`.shipped` (the shipped-model table), ``_guards``;
- shared floors: :mod:`.core` (blocks, summary, transfer, export), :mod:`.ops` (boxes,
  NMS, RoI ops), :mod:`.coco` (COCO/VOC formats and evaluation), :mod:`.data`
  (datasets, augmentations, fonts), :mod:`.train` (the loop, DDP);
- task wings: :mod:`.classification`, :mod:`.detection`, :mod:`.segmentation`,
  :mod:`.pose`, :mod:`.cloud`;
- on top: :mod:`.predict` (one image-prediction path for the CLI and batch jobs).

This is the only package that imports torch, and only its torch modules do. Submodules
load on first use (``robopercept.nn.detection``, ...), so ``import robopercept.nn``
stays cheap. :data:`MODULES` lists every public module (the API fuzzer walks it).
"""

from __future__ import annotations

import importlib
from typing import Any

#: subpackages and modules reachable as attributes of ``robopercept.nn``
_SUBMODULES = (
    "functional",
    "skeleton",
    "shipped",
    "core",
    "ops",
    "coco",
    "data",
    "train",
    "classification",
    "detection",
    "segmentation",
    "pose",
    "cloud",
    "predict",
)

#: every public module of ``robopercept.nn``, dotted below it, floor by floor
MODULES = (
    "functional",
    "skeleton",
    "shipped",
    "core.blocks",
    "core.summary",
    "core.transfer",
    "core.export",
    "ops.boxes",
    "coco.rle",
    "coco.formats",
    "data.datasets",
    "data.fonts",
    "train.loop",
    "train.distributed",
    "classification.models",
    "classification.run",
    "detection.data",
    "detection.models",
    "segmentation.metrics",
    "segmentation.networks",
    "segmentation.data",
    "pose.metrics",
    "pose.io",
    "pose.pictorial",
    "pose.data",
    "pose.networks",
    "pose.lifting",
    "cloud.pointnet",
    "cloud.dgcnn",
    "cloud.data",
    "cloud.run",
    "predict",
)

__all__ = [*_SUBMODULES, "MODULES"]


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
