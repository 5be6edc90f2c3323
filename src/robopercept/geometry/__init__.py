"""Camera models, rigid transforms and boxes."""

from robopercept.geometry.boxes import box_iou_matrix
from robopercept.geometry.camera import MODELS, CameraIntrinsics, deproject, project
from robopercept.geometry.transforms import apply, compose, invert, rotation_from_rotvec, se3

__all__ = [
    "MODELS",
    "CameraIntrinsics",
    "apply",
    "box_iou_matrix",
    "compose",
    "deproject",
    "invert",
    "project",
    "rotation_from_rotvec",
    "se3",
]
