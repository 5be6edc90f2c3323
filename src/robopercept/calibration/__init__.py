"""Camera calibration: chessboard and circle-grid detection, intrinsics (Zhang's method with
Levenberg-Marquardt refinement), stereo calibration, hand-eye calibration (AX = XB), and
calibration files (JSON, OpenCV FileStorage YAML/XML, ROS camera_info YAML and
transforms)."""

from robopercept.calibration.chessboard import (
    ChessboardDetection,
    chessboard_points,
    find_chessboard_corners,
)
from robopercept.calibration.circles import (
    CircleGridDetection,
    circles_grid_points,
    find_circles_grid,
)
from robopercept.calibration.filestorage import read_opencv_storage, write_opencv_storage
from robopercept.calibration.handeye import (
    HandEyeResult,
    calibrate_hand_eye,
    hand_eye_format,
    hand_eye_report,
    hand_eye_residuals,
    pose_from_xyz_rpy,
    read_xyz_rpy,
    save_hand_eye,
    xyz_rpy_from_pose,
)
from robopercept.calibration.intrinsics import (
    CALIBRATION_FORMATS,
    CalibrationResult,
    StereoCalibration,
    board_pose,
    calibrate_camera,
    calibration_format,
    load_calibration,
    rectify_pair,
    reprojection_errors,
    save_calibration,
    stereo_calibrate,
    undistort,
)
from robopercept.calibration.ros import (
    camera_info,
    quaternion_from_rotation,
    read_transform,
    rotation_from_quaternion,
    transform_stamped,
    write_ros_yaml,
)
from robopercept.calibration.stereo_images import BoardPairs, find_board_pairs

__all__ = [
    "CALIBRATION_FORMATS",
    "BoardPairs",
    "CalibrationResult",
    "ChessboardDetection",
    "CircleGridDetection",
    "HandEyeResult",
    "StereoCalibration",
    "board_pose",
    "calibrate_camera",
    "calibrate_hand_eye",
    "calibration_format",
    "camera_info",
    "chessboard_points",
    "circles_grid_points",
    "find_board_pairs",
    "find_chessboard_corners",
    "find_circles_grid",
    "hand_eye_format",
    "hand_eye_report",
    "hand_eye_residuals",
    "load_calibration",
    "pose_from_xyz_rpy",
    "quaternion_from_rotation",
    "read_opencv_storage",
    "read_transform",
    "read_xyz_rpy",
    "rectify_pair",
    "reprojection_errors",
    "rotation_from_quaternion",
    "save_calibration",
    "save_hand_eye",
    "stereo_calibrate",
    "transform_stamped",
    "undistort",
    "write_opencv_storage",
    "write_ros_yaml",
    "xyz_rpy_from_pose",
]
