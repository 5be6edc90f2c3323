"""Deep learning in pure PyTorch: the layer arithmetic, the blocks of VGG, Inception and
ResNet, training and fine-tuning, detection, segmentation, pose and point-cloud networks
(extra ``deep``: ``pip install 'robopercept[deep]'``).

The package is laid out as task wings over shared floors, as torchvision is:

- ground, torch-free: :mod:`.functional` (convolution and pooling by the mathematics, in
  NumPy), :mod:`.skeleton`, :mod:`.shipped` (the shipped-model table), ``_guards``;
- shared floors: :mod:`.core` (blocks, summary, transfer, export), :mod:`.ops` (boxes,
  NMS, RoI ops), :mod:`.coco` (COCO/VOC formats and evaluation), :mod:`.data`
  (datasets, augmentations, fonts), :mod:`.train` (config, the loop, checkpoints, DDP);
- task wings: :mod:`.classification`, :mod:`.detection`, :mod:`.segmentation`,
  :mod:`.pose`, :mod:`.cloud`;
- on top: :mod:`.predict` (one prediction path for the CLI, the batch jobs and Python:
  ``robopercept.nn.load_predictor("trees")("aerial.png").boxes``; classifiers and
  point-cloud networks through :mod:`.predict_class`,
  ``load_predictor("digits")("digit.png").class_name``).

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
    "core.backbones",
    "core.summary",
    "core.transfer",
    "core.export",
    "ops.boxes",
    "ops.anchors",
    "ops.nms",
    "ops.roi",
    "ops.losses",
    "ops.heatmaps",
    "coco.rle",
    "coco.dataset",
    "coco.results",
    "coco.evaluate",
    "coco.voc",
    "data.augment",
    "data.datasets",
    "data.fonts",
    "data.textures",
    "train.config",
    "train.checkpoint",
    "train.loop",
    "train.fit",
    "train.runs",
    "train.distributed",
    "classification.models",
    "classification.run",
    "detection.data",
    "detection.augment",
    "detection.synthetic",
    "detection.deepforest",
    "detection.targets",
    "detection.base",
    "detection.rpn",
    "detection.roi_heads",
    "detection.train",
    "detection.localizer",
    "detection.rcnn",
    "detection.fast_rcnn",
    "detection.faster_rcnn",
    "detection.mask_rcnn",
    "detection.keypoint_rcnn",
    "detection.fcos",
    "detection.tta",
    "detection.zoo",
    "detection.thresholds",
    "detection.tiling",
    "detection.run",
    "segmentation.metrics",
    "segmentation.networks",
    "segmentation.data",
    "segmentation.run",
    "pose.metrics",
    "pose.io",
    "pose.pictorial",
    "pose.pictorial_learn",
    "pose.data",
    "pose.networks",
    "pose.inference",
    "pose.train",
    "pose.evaluate",
    "pose.views",
    "pose.library",
    "pose.lifting",
    "pose.run",
    "cloud.pointnet",
    "cloud.dgcnn",
    "cloud.data",
    "cloud.synthetic",
    "cloud.train",
    "cloud.run",
    "predict",
    "predict_class",
)

#: functions reachable from ``robopercept.nn`` itself, by module
_FUNCTIONS = {"load_predictor": "predict"}

__all__ = [*_SUBMODULES, *_FUNCTIONS, "MODULES"]


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _FUNCTIONS:
        return getattr(importlib.import_module(f"{__name__}.{_FUNCTIONS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
