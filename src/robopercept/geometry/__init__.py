"""Camera models and rigid transforms."""

from robopercept.geometry.camera import MODELS, CameraIntrinsics, deproject, project
from robopercept.geometry.transforms import apply, compose, invert, rotation_from_rotvec, se3

__all__ = [
    "MODELS",
    "CameraIntrinsics",
    "apply",
    "compose",
    "deproject",
    "invert",
    "project",
    "rotation_from_rotvec",
    "se3",
]
