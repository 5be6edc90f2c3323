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
from robopercept.geometry.rectification import (
    StereoRectification,
    rectify_stereo,
    rectify_uncalibrated,
    undistort_rectify_map,
)
from robopercept.geometry.transforms import (
    apply,
    compose,
    invert,
    nearest_rotation,
    rotation_from_rotvec,
    rotvec_from_rotation,
    se3,
)
from robopercept.geometry.triangulation import triangulate

__all__ = [
    "MODELS",
    "CameraIntrinsics",
    "EssentialModel",
    "FundamentalFit",
    "FundamentalModel",
    "RelativePose",
    "StereoRectification",
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
    "nearest_rotation",
    "project",
    "rectify_stereo",
    "rectify_uncalibrated",
    "rotation_from_rotvec",
    "rotvec_from_rotation",
    "sampson_distance",
    "se3",
    "skew",
    "triangulate",
    "undistort_rectify_map",
]
