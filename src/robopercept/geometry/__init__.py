"""Camera models, rigid transforms, boxes, two-view geometry and triangulation."""

from robopercept.geometry.boxes import box_iou_matrix
from robopercept.geometry.camera import MODELS, CameraIntrinsics, deproject, project
from robopercept.geometry.epipolar import (
    EssentialModel,
    FundamentalFit,
    FundamentalModel,
    RelativePose,
    decompose_essential,
    eight_point,
    epipolar_lines,
    epipoles,
    essential_from_pose,
    find_essential,
    find_fundamental,
    fundamental_from_essential,
    sampson_distance,
    skew,
)
from robopercept.geometry.transforms import apply, compose, invert, rotation_from_rotvec, se3
from robopercept.geometry.triangulation import triangulate

__all__ = [
    "MODELS",
    "CameraIntrinsics",
    "EssentialModel",
    "FundamentalFit",
    "FundamentalModel",
    "RelativePose",
    "apply",
    "box_iou_matrix",
    "compose",
    "decompose_essential",
    "deproject",
    "eight_point",
    "epipolar_lines",
    "epipoles",
    "essential_from_pose",
    "find_essential",
    "find_fundamental",
    "fundamental_from_essential",
    "invert",
    "project",
    "rotation_from_rotvec",
    "sampson_distance",
    "se3",
    "skew",
    "triangulate",
]
