"""Deep learning in pure PyTorch: the layer arithmetic, the blocks of VGG, Inception and
ResNet, training and fine-tuning (extra ``deep``: ``pip install 'robopercept[deep]'``).

This is the only package that imports torch, and only its torch modules do:
:mod:`robopercept.nn.functional` (convolution and pooling by the mathematics, in NumPy)
works without torch. Submodules load on first use (``robopercept.nn.blocks``,
``robopercept.nn.models``, ...), so ``import robopercept.nn`` stays cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

#: submodules reachable as attributes of ``robopercept.nn``
_SUBMODULES = (
    "functional",
    "blocks",
    "models",
    "summary",
    "data",
    "training",
    "transfer",
    "export",
    "run",
    "boxes",
    "coco",
    "coco_mask",
    "segmentation_eval",
    "segmentation",
    "segmentation_data",
    "detection_data",
    "detection",
    "skeleton",
    "pose_eval",
    "pose_io",
    "pictorial",
    "pose3d",
    "pose_data",
    "pose",
    "pointnet",
    "dgcnn",
    "cloud_data",
    "cloud",
    "distributed",
    "shipped",
    "image_predict",
)

__all__ = list(_SUBMODULES)


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
