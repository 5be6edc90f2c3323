"""``robopercept calibrate`` (camera intrinsics from chessboard photos) and
``robopercept handeye`` (camera-robot transform from robot and target poses)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from robopercept.cli._args import UsageError, board_size, file_output

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` and ``handeye`` commands to the subcommand parsers ``sub``."""
    p = sub.add_parser(
        "calibrate",
        help="camera intrinsics and distortion from chessboard photos (Zhang)",
        description="Find the chessboard in every image (images without the whole board are "
        "reported and skipped), calibrate with Zhang's method and Levenberg-Marquardt, "
        "print the per-view reprojection errors and write the camera as JSON.",
    )
    p.add_argument("images", nargs="+")
    p.add_argument("--board", type=board_size, required=True, help="inner corners, e.g. 9x6")
    p.add_argument("--square", type=float, default=1.0, help="square side (sets the unit)")
    p.add_argument("-o", "--output", type=file_output, default="camera.json")
    p.add_argument("--overlays", default=None, help="folder for detection overlays")
    p.add_argument("--undistorted", default=None, help="folder for undistorted previews")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_calibrate)

    q = sub.add_parser(
        "handeye",
        help="hand-eye calibration AX = XB from robot poses and target poses",
        description="Robot poses (gripper in base) and target poses (target in camera), one "
        "per station, give X = T_gripper_camera (eye in hand) or T_base_camera (eye to "
        "hand). Target poses come from files (4x4 matrices) or from images of a "
        "chessboard or circle grid with a calibrated camera (--images, --camera, --board, "
        "--square, --target).",
    )
    q.add_argument("--robot-poses", nargs="+", required=True, help="one file per station")
    q.add_argument(
        "--pose-format",
        choices=("rpy_xyz", "xyz_rpy", "matrix"),
        default="rpy_xyz",
        help="robot files: Rx Ry Rz X Y Z (degrees), X Y Z Rx Ry Rz, or 16 numbers",
    )
    src = q.add_mutually_exclusive_group(required=True)
    src.add_argument("--target-poses", nargs="+", help="4x4 target-in-camera per station")
    src.add_argument("--images", nargs="+", help="target image per station")
    q.add_argument(
        "--camera",
        default=None,
        help="camera file for --images: the JSON of calibrate, or OpenCV YAML/XML "
        "(camera_matrix / K, distortion_coefficients / D, as cv2.FileStorage writes them)",
    )
    q.add_argument(
        "--target",
        choices=("chessboard", "circles", "acircles"),
        default="chessboard",
        help="what --images show: a chessboard, a symmetric or an asymmetric circle grid",
    )
    q.add_argument(
        "--board",
        type=board_size,
        default=None,
        help="inner corners (chessboard) or circles per row x rows (grids) for --images",
    )
    q.add_argument(
        "--square",
        type=float,
        default=None,
        help="square side, or distance between neighbouring centres of a row, robot units",
    )
    q.add_argument(
        "--circles",
        choices=("dark", "light"),
        default="dark",
        help="circle-grid targets: circles darker or lighter than the board",
    )
    q.add_argument(
        "--setup",
        choices=("eye-in-hand", "eye-to-hand"),
        default=None,
        help="required: eye-in-hand (camera on the gripper, target fixed; X = "
        "T_gripper_camera) or eye-to-hand (camera fixed, target on the gripper; X = "
        "T_base_camera)",
    )
    q.add_argument("--method", choices=("tsai", "park", "daniilidis"), default="tsai")
    q.add_argument("-o", "--output", type=file_output, default="handeye.json")
    q.add_argument("--json", action="store_true", help="print the result as JSON")
    q.set_defaults(func=run_handeye)


# --------------------------------------------------------------------------- calibrate


def run_calibrate(args: argparse.Namespace) -> int:
    """Run ``robopercept calibrate`` with the parsed ``args``; returns the exit status."""
    from robopercept.calibration import (
        calibrate_camera,
        chessboard_points,
        find_chessboard_corners,
        save_calibration,
        undistort,
    )
    from robopercept.errors import FileFormatError, InputError
    from robopercept.imaging import read_image, write_image
    from robopercept.progress import progress_bar
    from robopercept.viz import draw_chessboard

    if not (np.isfinite(args.square) and args.square > 0):
        raise UsageError(f"--square must be a positive length; got {args.square}")
    folders = [p for p in args.images if Path(p).is_dir()]
    if folders:  # not an unreadable photo to skip: the images were meant
        raise FileFormatError(
            f"{folders[0]} is a folder; give the image files in it (e.g. {Path(folders[0])}/*.png)"
        )
    size, names, corners, skipped = None, [], [], []
    for path in progress_bar(args.images, unit="image", desc="chessboard", disable=args.quiet):
        try:
            gray = read_image(path, mode="gray")
        except FileFormatError as exc:
            skipped.append((path, f"unreadable ({exc})"))
            continue
        if size is None:
            size = (gray.shape[1], gray.shape[0])
        elif (gray.shape[1], gray.shape[0]) != size:
            raise InputError(
                f"{path} is {gray.shape[1]}x{gray.shape[0]} but the first image is "
                f"{size[0]}x{size[1]}: calibrate one camera resolution at a time"
            )
        det = find_chessboard_corners(gray, args.board)
        if args.overlays:
            out = Path(args.overlays)
            out.mkdir(parents=True, exist_ok=True)
            write_image(
                out / f"{Path(path).stem}.png",
                draw_chessboard(gray, det.corners, args.board, det.found),
            )
        if det.found:
            names.append(path)
            corners.append(det.corners)
        else:
            skipped.append((path, det.reason))
    for path, why in skipped:
        print(f"skipped {path}: {why}", file=sys.stderr)
    if len(corners) < 3:
        raise InputError(
            f"the board was found in {len(corners)} of {len(args.images)} images; "
            "calibration needs at least 3 (check --board: inner corners, not squares)"
        )
    assert size is not None  # set by the first readable image
    res = calibrate_camera(chessboard_points(args.board, args.square), corners, size)
    save_calibration(args.output, res)
    data = json.loads(Path(args.output).read_text())
    data.update(images=names, board=list(args.board), square=args.square)
    data["skipped"] = [{"image": p, "reason": w} for p, w in skipped]
    Path(args.output).write_text(json.dumps(data, indent=2) + "\n")
    if args.undistorted:
        out = Path(args.undistorted)
        out.mkdir(parents=True, exist_ok=True)
        for path in names:
            img = read_image(path, mode="rgb")
            write_image(out / f"{Path(path).stem}.png", undistort(img, res.K, res.dist))
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    width = max(len(Path(n).name) for n in names)
    print(f"{'image':<{width}}  error (px)")
    for n, e in zip(names, res.per_view_errors, strict=True):
        print(f"{Path(n).name:<{width}}  {e:.3f}")
    print(
        f"RMS reprojection error  {res.rms:.3f} px over {len(names)} views ({len(skipped)} skipped)"
    )
    fx, fy, cx, cy = res.K[0, 0], res.K[1, 1], res.K[0, 2], res.K[1, 2]
    print(f"fx fy cx cy  {fx:.2f} {fy:.2f} {cx:.2f} {cy:.2f}")
    print("k1 k2 p1 p2 k3  " + " ".join(f"{v:.5f}" for v in res.dist))
    print(f"wrote {args.output}")
    return 0


# --------------------------------------------------------------------------- hand-eye


def _matrix_file(path: str) -> np.ndarray:
    from robopercept.errors import FileFormatError

    try:
        v = np.array(Path(path).read_text().split(), dtype=np.float64)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise FileFormatError(f"{path}: not a 4x4 matrix of numbers ({exc})") from exc
    if v.size not in (12, 16) or not np.isfinite(v).all():
        raise FileFormatError(f"{path}: a pose matrix needs 12 or 16 numbers; found {v.size}")
    T = np.eye(4)
    T[:3] = v[:12].reshape(3, 4)
    return T


def _target_poses(args: argparse.Namespace) -> tuple[list[np.ndarray], list[int]]:
    """Target poses and the stations they belong to (images without the board are
    reported and dropped)."""
    from robopercept.calibration import (
        board_pose,
        chessboard_points,
        circles_grid_points,
        find_chessboard_corners,
        find_circles_grid,
        load_calibration,
    )
    from robopercept.errors import InputError
    from robopercept.imaging import read_image

    if args.target_poses:
        return [_matrix_file(p) for p in args.target_poses], list(range(len(args.target_poses)))
    if not (args.camera and args.board and args.square):
        raise UsageError(
            "--images needs --camera (the JSON of calibrate, or an OpenCV YAML/XML "
            "camera file), --board and --square"
        )
    cam = load_calibration(args.camera)
    if "K" not in cam:
        raise InputError(
            f"{args.camera} is a stereo calibration; --camera needs one camera's "
            "(K or camera_matrix, and its distortion)"
        )
    asym = args.target == "acircles"
    if args.target == "chessboard":
        obj = chessboard_points(args.board, args.square)
    else:
        obj = circles_grid_points(args.board, args.square, asymmetric=asym)
    poses, stations = [], []
    for i, path in enumerate(args.images):
        gray = read_image(path, mode="gray")
        det: Any
        if args.target == "chessboard":
            det = find_chessboard_corners(gray, args.board)
        else:
            det = find_circles_grid(gray, args.board, asymmetric=asym, blob_color=args.circles)
        if not det.found:
            print(f"skipped station {i} ({path}): {det.reason}", file=sys.stderr)
            continue
        poses.append(board_pose(obj, det.corners, cam["K"], cam.get("dist")))
        stations.append(i)
    return poses, stations


def run_handeye(args: argparse.Namespace) -> int:
    """Run ``robopercept handeye`` with the parsed ``args``; returns the exit status."""
    from robopercept.calibration import calibrate_hand_eye, read_xyz_rpy
    from robopercept.calibration.handeye import xyz_rpy_from_pose

    if args.setup is None:  # no default: the wrong setup gives a wrong X without a sign
        raise UsageError(
            "--setup is required: eye-in-hand (camera on the gripper, target fixed) or "
            "eye-to-hand (camera fixed, target on the gripper)"
        )
    sources = args.target_poses or args.images
    if len(sources) != len(args.robot_poses):
        raise UsageError(
            f"{len(args.robot_poses)} robot poses but {len(sources)} "
            f"{'target poses' if args.target_poses else 'images'}: give one per station"
        )
    if args.pose_format == "matrix":
        robot = [_matrix_file(p) for p in args.robot_poses]
    else:
        robot = [read_xyz_rpy(p, args.pose_format) for p in args.robot_poses]
    targets, stations = _target_poses(args)
    setup = args.setup.replace("-", "_")
    res = calibrate_hand_eye([robot[i] for i in stations], targets, setup, args.method)
    xyz, rpy = xyz_rpy_from_pose(res.X)
    data: dict[str, Any] = res.to_dict()
    data.update(xyz=xyz.tolist(), rpy_deg=rpy.tolist(), stations=len(stations))
    Path(args.output).write_text(json.dumps(data, indent=2) + "\n")
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    what = "T_gripper_camera" if setup == "eye_in_hand" else "T_base_camera"
    print(f"X = {what} ({args.method}, refined, {len(stations)} stations)")
    for row in res.X:
        print("  " + " ".join(f"{v:12.6f}" for v in row))
    print("xyz      " + " ".join(f"{v:.3f}" for v in xyz))
    print("rpy deg  " + " ".join(f"{v:.3f}" for v in rpy))
    print(
        f"AX = XB residuals over {len(res.rotation_residuals)} pairs: rotation RMS "
        f"{res.rotation_rms:.4f} deg, translation RMS {res.translation_rms:.4f}"
    )
    print(f"wrote {args.output}")
    return 0
