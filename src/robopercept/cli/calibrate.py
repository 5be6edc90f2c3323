"""``robopercept calibrate`` (camera intrinsics from chessboard photos),
``robopercept stereo-calibrate`` (a stereo rig from chessboard pairs) and
``robopercept handeye`` (camera-robot transform from robot and target poses)."""

from __future__ import annotations

import argparse
import glob
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept.cli._args import UsageError, board_size, file_output, flag_errors

if TYPE_CHECKING:
    import numpy as np

__all__ = ["register"]

_FORMAT_HELP = (
    "output format: json (robopercept), opencv (cv2.FileStorage YAML: camera_matrix, "
    "distortion_coefficients, ...) or ros (camera_info YAML); default by the extension of "
    "-o: .json json, .yml/.yaml opencv"
)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate``, ``stereo-calibrate`` and ``handeye`` commands to the
    subcommand parsers ``sub``."""
    p = sub.add_parser(
        "calibrate",
        help="camera intrinsics and distortion from chessboard photos (Zhang)",
        description="Find the chessboard in every image (images without the whole board are "
        "reported and skipped), calibrate with Zhang's method and Levenberg-Marquardt, "
        "print the per-view reprojection errors and write the camera as JSON, OpenCV "
        "FileStorage YAML or ROS camera_info YAML (--format, or the extension of -o).",
    )
    p.add_argument("images", nargs="+", help="chessboard photos: files or glob patterns")
    p.add_argument("--board", type=board_size, required=True, help="inner corners, e.g. 9x6")
    p.add_argument("--square", type=float, default=1.0, help="square side (sets the unit)")
    p.add_argument(
        "-o", "--output", type=file_output, default="camera.json", help="the camera file"
    )
    p.add_argument("--format", choices=("json", "opencv", "ros"), default=None, help=_FORMAT_HELP)
    p.add_argument("--camera-name", default="camera", help="camera_name of a ROS file")
    p.add_argument("--overlays", default=None, help="folder for detection overlays")
    p.add_argument("--undistorted", default=None, help="folder for undistorted previews")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run_calibrate)

    r = sub.add_parser(
        "stereo-calibrate",
        help="stereo rig (both cameras, R, T) from chessboard image pairs",
        description="Find the chessboard in each left/right pair (pairs without the whole "
        "board in both images are reported and skipped), calibrate each camera (Zhang), "
        "then the pose of the right camera relative to the left (X_right = R X_left + T) by "
        "Levenberg-Marquardt over both cameras' reprojection errors (cv2.stereoCalibrate). "
        "Writes the file that `robopercept stereo --calib` reads.",
    )
    r.add_argument(
        "--left", nargs="+", required=True, help="left images: files, a folder or a glob"
    )
    r.add_argument(
        "--right", nargs="+", required=True, help="right images, paired with --left in order"
    )
    r.add_argument("--board", type=board_size, required=True, help="inner corners, e.g. 9x6")
    r.add_argument("--square", type=float, default=1.0, help="square side (sets T's unit)")
    r.add_argument(
        "-o", "--output", type=file_output, default="stereo.json", help="the stereo rig file"
    )
    r.add_argument(
        "--format",
        choices=("json", "opencv", "ros"),
        default=None,
        help=_FORMAT_HELP + " (ros writes NAME_left.yaml and NAME_right.yaml)",
    )
    r.add_argument("--camera-name", default="stereo", help="ROS camera_name prefix")
    r.add_argument(
        "--free-intrinsics",
        action="store_true",
        help="refine both cameras' intrinsics in the joint step too (default: fixed, "
        "cv2.CALIB_FIX_INTRINSIC)",
    )
    r.add_argument("--json", action="store_true", help="print the result as JSON")
    r.add_argument("--quiet", action="store_true", help="no per-pair messages on stderr")
    r.set_defaults(func=run_stereo_calibrate)

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
    q.add_argument(
        "--method",
        choices=("tsai", "park", "daniilidis"),
        default="tsai",
        help="the closed-form start (Tsai-Lenz, Park-Martin or Daniilidis' dual "
        "quaternions, as cv2.calibrateHandEye's), refined by Levenberg-Marquardt",
    )
    q.add_argument(
        "-o", "--output", type=file_output, default="handeye.json", help="the result file"
    )
    q.add_argument(
        "--format",
        choices=("json", "ros"),
        default=None,
        help="json (X as 4x4, xyz + quaternion, residuals) or ros (a TransformStamped "
        "YAML); default by the extension of -o: .json json, .yml/.yaml ros",
    )
    q.add_argument(
        "--parent-frame",
        default=None,
        help="ROS parent frame of X (default tool0 eye-in-hand, base_link eye-to-hand)",
    )
    q.add_argument(
        "--child-frame", default=None, help="ROS child frame of X (default camera_optical_frame)"
    )
    q.add_argument(
        "--metres-per-unit",
        type=float,
        default=1.0,
        help="scale of the robot units to metres for the ROS transform (0.001 for mm)",
    )
    q.add_argument("--json", action="store_true", help="print the result as JSON")
    q.set_defaults(func=run_handeye)


# --------------------------------------------------------------------------- calibrate


def run_calibrate(args: argparse.Namespace) -> int:
    """Run ``robopercept calibrate`` with the parsed ``args``; returns the exit status."""
    import numpy as np

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
    fmt = _calibration_format(args.output, args.format)
    folders = [p for p in args.images if Path(p).is_dir()]
    if folders:  # not an unreadable photo to skip: the images were meant
        raise FileFormatError(
            f"{folders[0]} is a folder; give the image files in it (e.g. {Path(folders[0])}/*.png)"
        )
    # a quoted pattern ('left*.jpg') is expanded as stereo-calibrate expands it
    args.images = [
        f
        for spec in args.images
        for f in (_image_list([spec], "IMAGES") if glob.has_magic(spec) else [spec])
    ]
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
    extra = {
        "images": names,
        "board": list(args.board),
        "square": args.square,
        "skipped": [{"image": p, "reason": w} for p, w in skipped],
    }
    with flag_errors(camera_name="--camera-name"):
        written = save_calibration(args.output, res, fmt, extra=extra, camera_name=args.camera_name)
    data: dict[str, Any] = res.to_dict()
    data.update(extra, format=fmt, outputs=[str(w) for w in written])
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
    print(f"wrote {', '.join(data['outputs'])} ({fmt})")
    return 0


def _calibration_format(output: str, format: str | None) -> str:
    """``--format`` or the one told by ``-o``'s extension; a misfit is a usage error."""
    from robopercept.calibration import calibration_format
    from robopercept.errors import InputError

    try:
        return calibration_format(output, format)
    except InputError as exc:
        raise UsageError(f"-o/--output, --format: {exc}") from None


# --------------------------------------------------------------------------- stereo


def _image_list(specs: list[str], flag: str) -> list[str]:
    """Files of ``specs``: a folder gives its images (sorted), a pattern with ``*``,
    ``?`` or ``[`` that names no file its matches (sorted), a file itself."""
    from robopercept.sources import IMAGE_EXTENSIONS

    out: list[str] = []
    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            found = sorted(str(f) for f in p.iterdir() if f.suffix.lower() in IMAGE_EXTENSIONS)
            if not found:
                raise UsageError(f"{flag}: the folder {spec} holds no images")
            out += found
        elif not p.exists() and glob.has_magic(spec):
            found = sorted(glob.glob(spec))
            if not found:
                raise UsageError(f"{flag}: no file matches {spec}")
            out += found
        else:
            out.append(spec)
    return out


def run_stereo_calibrate(args: argparse.Namespace) -> int:
    """Run ``robopercept stereo-calibrate`` with the parsed ``args``; returns the exit
    status."""
    import numpy as np

    from robopercept.calibration import (
        chessboard_points,
        find_board_pairs,
        save_calibration,
        stereo_calibrate,
    )
    from robopercept.errors import InputError

    if not (np.isfinite(args.square) and args.square > 0):
        raise UsageError(f"--square must be a positive length; got {args.square}")
    fmt = _calibration_format(args.output, args.format)
    left = _image_list(args.left, "--left")
    right = _image_list(args.right, "--right")
    if len(left) != len(right):
        raise UsageError(
            f"--left gives {len(left)} images but --right {len(right)}: one right image per "
            "left image, in the same (sorted) order"
        )
    with flag_errors(left="--left", right="--right", pattern_size="--board"):
        pairs = find_board_pairs(left, right, args.board)
    if not args.quiet:
        for i, why in pairs.skipped:
            print(f"skipped pair {left[i]} / {right[i]}: {why}", file=sys.stderr)
    if len(pairs.used) < 3:
        raise InputError(
            f"the board was found in both images of {len(pairs.used)} of {len(left)} pairs; "
            "stereo calibration needs at least 3 (check --board: inner corners, not squares)"
        )
    assert pairs.image_size is not None  # set by the first readable image
    cal = stereo_calibrate(
        chessboard_points(args.board, args.square),
        pairs.corners1,
        pairs.corners2,
        pairs.image_size,
        fix_intrinsics=not args.free_intrinsics,
    )
    extra = {
        "left_images": [left[i] for i in pairs.used],
        "right_images": [right[i] for i in pairs.used],
        "board": list(args.board),
        "square": args.square,
        "skipped": [{"left": left[i], "right": right[i], "reason": w} for i, w in pairs.skipped],
    }
    with flag_errors(camera_name="--camera-name"):
        written = save_calibration(args.output, cal, fmt, extra=extra, camera_name=args.camera_name)
    data: dict[str, Any] = cal.to_dict()
    data.update(
        extra,
        baseline=float(np.linalg.norm(cal.T)),
        flipped=[left[i] for i in pairs.flipped],
        format=fmt,
        outputs=[str(w) for w in written],
    )
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    width = max(len(Path(n).name) for n in data["left_images"])
    print(f"{'left':<{width}}  {'right':<{width}}  error left / right (px)")
    for a, b, (e1, e2) in zip(
        data["left_images"], data["right_images"], cal.per_view_errors, strict=True
    ):
        print(f"{Path(a).name:<{width}}  {Path(b).name:<{width}}  {e1:.3f} / {e2:.3f}")
    print(
        f"RMS reprojection error  {cal.rms:.3f} px over {len(pairs.used)} pairs "
        f"({len(pairs.skipped)} skipped)"
    )
    for name, K, d in (("left ", cal.K1, cal.dist1), ("right", cal.K2, cal.dist2)):
        print(
            f"{name} fx fy cx cy  {K[0, 0]:.2f} {K[1, 1]:.2f} {K[0, 2]:.2f} {K[1, 2]:.2f}"
            "   k1 k2 p1 p2 k3  " + " ".join(f"{v:.5f}" for v in d)
        )
    print("T (right from left)  " + " ".join(f"{v:.5f}" for v in cal.T)
          + f"   baseline {data['baseline']:.5f}")  # fmt: skip
    note = "" if fmt == "ros" else "; `robopercept stereo --calib` reads it"
    print(f"wrote {', '.join(data['outputs'])} ({fmt}{note})")
    return 0


# --------------------------------------------------------------------------- hand-eye


def _matrix_file(path: str) -> np.ndarray:
    import numpy as np

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
    from robopercept.calibration.handeye import hand_eye_format, save_hand_eye
    from robopercept.errors import InputError

    try:
        fmt = hand_eye_format(args.output, args.format)
    except InputError as exc:
        raise UsageError(f"-o/--output, --format: {exc}") from None
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
    with flag_errors(
        parent_frame="--parent-frame",
        child_frame="--child-frame",
        metres_per_unit="--metres-per-unit",
    ):
        data = save_hand_eye(
            args.output,
            res,
            args.format,
            parent_frame=args.parent_frame,
            child_frame=args.child_frame,
            metres_per_unit=args.metres_per_unit,
            extra={"stations": len(stations)},
        )
    data.update(format=fmt, output=str(args.output))
    xyz, rpy, q = data["xyz"], data["rpy_deg"], data["quaternion_xyzw"]
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    what = "T_gripper_camera" if setup == "eye_in_hand" else "T_base_camera"
    print(f"X = {what} ({args.method}, refined, {len(stations)} stations)")
    for row in res.X:
        print("  " + " ".join(f"{v:12.6f}" for v in row))
    print("xyz      " + " ".join(f"{v:.3f}" for v in xyz))
    print("rpy deg  " + " ".join(f"{v:.3f}" for v in rpy))
    print("quaternion x y z w  " + " ".join(f"{v:.6f}" for v in q))
    print(f"ROS: {data['static_transform_publisher']}")
    print(
        f"AX = XB residuals over {len(res.rotation_residuals)} pairs: rotation RMS "
        f"{res.rotation_rms:.4f} deg, translation RMS {res.translation_rms:.4f}"
    )
    print(f"wrote {args.output}")
    return 0
