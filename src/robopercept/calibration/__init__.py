"""Camera calibration: chessboard and circle-grid detection, intrinsics (Zhang's method with
Levenberg-Marquardt refinement), stereo calibration, hand-eye calibration (AX = XB), and
calibration files (JSON, OpenCV FileStorage YAML/XML)."""

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
from robopercept.calibration.filestorage import read_opencv_storage
from robopercept.calibration.handeye import (
    HandEyeResult,
    calibrate_hand_eye,
    hand_eye_residuals,
    pose_from_xyz_rpy,
    read_xyz_rpy,
    xyz_rpy_from_pose,
)
from robopercept.calibration.intrinsics import (
    CalibrationResult,
    StereoCalibration,
    board_pose,
    calibrate_camera,
    load_calibration,
    rectify_pair,
    reprojection_errors,
    save_calibration,
    stereo_calibrate,
    undistort,
)

__all__ = [
    "CalibrationResult",
    "ChessboardDetection",
    "CircleGridDetection",
    "HandEyeResult",
    "StereoCalibration",
    "board_pose",
    "calibrate_camera",
    "calibrate_hand_eye",
    "chessboard_points",
    "circles_grid_points",
    "find_chessboard_corners",
    "find_circles_grid",
    "hand_eye_residuals",
    "load_calibration",
    "pose_from_xyz_rpy",
    "read_opencv_storage",
    "read_xyz_rpy",
    "rectify_pair",
    "reprojection_errors",
    "save_calibration",
    "stereo_calibrate",
    "undistort",
    "xyz_rpy_from_pose",
]
