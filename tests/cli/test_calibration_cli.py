"""``robopercept calibrate``, ``handeye`` and ``stereo --calib`` against the library
calls, OpenCV and synthetic truth, with bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from tests.conftest import data_path

VIEWS = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14]


@pytest.mark.realdata
def test_calibrate_opencv_set_with_a_negative(tmp_path, capsys):
    """13 boards and one negative: the negative is reported and skipped, K equals the
    library call (and cv2 within 0.5 %), overlays and undistorted previews are written."""
    folder = data_path("calibration", "opencv_chessboard_stereo")
    neg = data_path("calibration", "opencv_extra_corners_gt", "negative", "negative_1.png")
    images = [str(folder / f"left{i:02d}.jpg") for i in VIEWS] + [str(neg)]
    out = tmp_path / "cam.json"
    code = main(["calibrate", *images, "--board", "9x6", "--square", "0.025", "-o", str(out),
                 "--overlays", str(tmp_path / "ov"), "--undistorted", str(tmp_path / "un"),
                 "--quiet"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr()
    assert "skipped" in text.err and "negative_1.png" in text.err
    assert "RMS reprojection error" in text.out and "left13.jpg" in text.out
    data = json.loads(out.read_text())
    assert len(data["images"]) == 13 and data["skipped"][0]["image"].endswith("negative_1.png")
    K = np.array(data["K"])
    assert abs(K[0, 0] / 536.07 - 1) < 0.005 and abs(K[1, 2] / 235.53 - 1) < 0.005
    assert data["rms"] < 1.02 * 0.4080
    assert len(list((tmp_path / "ov").glob("*.png"))) == 14
    assert len(list((tmp_path / "un").glob("*.png"))) == 13


def test_calibrate_too_few_boards_exits_2(tmp_path, capsys):
    from robopercept.imaging import write_image

    blank = tmp_path / "blank.png"
    write_image(blank, np.full((60, 80), 128, np.uint8))
    code = main(["calibrate", str(blank), str(blank), "--board", "9x6", "--quiet"])
    assert code == 1  # the data: no board found
    assert "found in 0 of 2 images" in capsys.readouterr().err
    assert main(["calibrate", str(blank), "--board", "9"]) == 2
    assert "expects inner corners as WxH" in capsys.readouterr().err


def _write_matrix(path, T):
    path.write_text("\n".join(" ".join(f"{v:.17g}" for v in row) for row in T) + "\n")


def test_handeye_from_pose_files(tmp_path, capsys):
    """Robot poses as Rx Ry Rz X Y Z files (Open3DV's format) and target poses as
    matrices: the command returns the X the stations were made with."""
    from robopercept.calibration import calibrate_hand_eye, pose_from_xyz_rpy
    from robopercept.geometry import invert, rotation_from_rotvec, se3

    rng = np.random.default_rng(4)
    X = se3(rotation_from_rotvec([0.1, -0.2, 1.5]), [30.0, -10.0, 80.0])
    Y = se3(rotation_from_rotvec([3.0, 0.1, 0.0]), [600.0, 50.0, 0.0])
    robots, targets, G = [], [], []
    for i in range(6):
        xyz = rng.normal(0, 100, 3) + np.array([500.0, 0, 400])
        rpy = rng.normal(0, 20, 3) + np.array([180.0, 0, 0])
        (tmp_path / f"pos{i}.txt").write_text("\n".join(f"{v:.10f}" for v in [*rpy, *xyz]))
        g = pose_from_xyz_rpy(xyz, rpy)
        G.append(g)
        _write_matrix(tmp_path / f"target{i}.txt", invert(g @ X) @ Y)
        robots.append(str(tmp_path / f"pos{i}.txt"))
        targets.append(str(tmp_path / f"target{i}.txt"))
    out = tmp_path / "he.json"
    code = main(["handeye", "--robot-poses", *robots, "--target-poses", *targets,
                 "--setup", "eye-in-hand", "-o", str(out), "--json"])  # fmt: skip
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(np.array(data["X"]), X, atol=1e-6)
    direct = calibrate_hand_eye(G, [invert(g @ X) @ Y for g in G])
    np.testing.assert_allclose(np.array(data["X"]), direct.X, atol=1e-6)
    assert json.loads(out.read_text())["rotation_rms_deg"] < 1e-6
    code = main(["handeye", "--robot-poses", *robots, "--target-poses", *targets[:5],
                 "--setup", "eye-in-hand"])  # fmt: skip
    assert code == 2 and "6 robot poses but 5 target poses" in capsys.readouterr().err


@pytest.mark.realdata
def test_stereo_calib_rectifies_the_chessboard_pair(tmp_path, capsys):
    """Calibrate the OpenCV pair, then ``stereo --calib``'s rectification puts each
    corner of left01/right01 on the same row (median |dy| < 0.5 px; 10 px before)."""
    from robopercept.calibration import (
        chessboard_points,
        find_chessboard_corners,
        load_calibration,
        rectify_pair,
        save_calibration,
        stereo_calibrate,
    )
    from robopercept.imaging import read_image

    folder = data_path("calibration", "opencv_chessboard_stereo")
    L, R = [], []
    for i in VIEWS:
        for side, out in (("left", L), ("right", R)):
            det = find_chessboard_corners(
                read_image(folder / f"{side}{i:02d}.jpg", mode="gray"), (9, 6)
            )
            out.append(det.corners)
    cal = stereo_calibrate(chessboard_points((9, 6), 0.025), L, R, (640, 480))
    save_calibration(tmp_path / "stereo.json", cal)
    left = read_image(folder / "left01.jpg", mode="rgb")
    right = read_image(folder / "right01.jpg", mode="rgb")
    rl, rr, Q = rectify_pair(left, right, load_calibration(tmp_path / "stereo.json"))
    a = find_chessboard_corners(rl, (9, 6))
    b = find_chessboard_corners(rr, (9, 6))
    assert a.found and b.found
    assert np.median(np.abs(a.corners[:, 1] - b.corners[:, 1])) < 0.5
    assert np.median(np.abs(L[0][:, 1] - R[0][:, 1])) > 5
    assert Q.shape == (4, 4)
    code = main(["stereo", str(folder / "left01.jpg"), str(folder / "right01.jpg"),
                 "--calib", str(tmp_path / "stereo.json"), "--max-disparity", "32",
                 "--method", "bm", "-o", str(tmp_path / "d.png"), "--ply",
                 str(tmp_path / "p.ply")])  # fmt: skip
    assert code == 0 and (tmp_path / "p.ply").exists()


@pytest.mark.realdata
def test_handeye_from_circle_grid_images(tmp_path, capsys):
    """The Open3DV eye-in-hand captures through --images --target acircles: the result
    equals the library's on the same detections; a station without the grid is
    reported and skipped."""
    from robopercept.calibration import (
        board_pose,
        calibrate_hand_eye,
        circles_grid_points,
        find_circles_grid,
        read_xyz_rpy,
    )
    from robopercept.imaging import read_image

    folder = data_path("calibration", "handeye_open3dv", "eye_in_hand")
    p = np.loadtxt(folder / "param.txt")
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"K": p[:9].reshape(3, 3).tolist(), "dist": p[9:14].tolist()}))
    neg = data_path("calibration", "opencv_chessboard_stereo", "left01.jpg")
    images = [str(folder / f"pos{k}.png") for k in range(6)] + [str(neg)]
    poses = [str(folder / f"pos{k}.txt") for k in range(7)]
    out = tmp_path / "he.json"
    code = main(["handeye", "--robot-poses", *poses, "--images", *images, "--camera", str(cam),
                 "--target", "acircles", "--circles", "light", "--board", "7x11",
                 "--square", "20", "--setup", "eye-in-hand", "-o", str(out)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr()
    assert "skipped station 6" in text.err and "AX = XB residuals over 15 pairs" in text.out
    obj = circles_grid_points((7, 11), 20.0)
    targets = []
    for k in range(6):
        det = find_circles_grid(read_image(images[k], mode="gray"), (7, 11), blob_color="light")
        targets.append(board_pose(obj, det.centers, p[:9].reshape(3, 3), p[9:14]))
    robot = [read_xyz_rpy(f, "rpy_xyz") for f in poses[:6]]
    ref = calibrate_hand_eye(robot, targets, "eye_in_hand", "tsai")
    assert np.allclose(json.loads(out.read_text())["X"], ref.X, atol=1e-9)


def test_handeye_setup_is_required(tmp_path, capsys):
    """Without --setup the command stops with a usage error (exit 2) that names both
    setups: eye in hand and eye to hand give different X from the same files, and a
    silent default gives a wrong X without a sign."""
    from robopercept.geometry import se3

    files = []
    for i in range(3):
        _write_matrix(tmp_path / f"m{i}.txt", se3(np.eye(3), [i, 0.0, 0.0]))
        files.append(str(tmp_path / f"m{i}.txt"))
    code = main(["handeye", "--robot-poses", *files, "--pose-format", "matrix",
                 "--target-poses", *files])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2
    assert "--setup is required" in err and "eye-in-hand" in err and "eye-to-hand" in err
    assert not (tmp_path / "handeye.json").exists()
    assert main(["handeye", "--robot-poses", *files, "--target-poses", *files,
                 "--setup", "eye-on-base"]) == 2  # fmt: skip
    assert "invalid choice" in capsys.readouterr().err


@pytest.mark.realdata
@pytest.mark.parametrize("fmt", ["yml", "xml"])
def test_handeye_eye_to_hand_images_with_an_opencv_camera_file(tmp_path, capsys, fmt):
    """The Open3DV eye-to-hand captures (fixed camera, 7 x 11 light circles, 40 mm, on
    the gripper) through --images with the camera in an OpenCV YAML / XML file written by
    cv2.FileStorage: all 5 stations are used and X = T_base_camera equals the library's
    on the same detections (1e-9: the same code)."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.calibration import (
        board_pose,
        calibrate_hand_eye,
        circles_grid_points,
        find_circles_grid,
        read_xyz_rpy,
    )
    from robopercept.imaging import read_image

    folder = data_path("calibration", "handeye_open3dv", "eye_to_hand")
    p = np.loadtxt(folder / "param.txt")
    K, dist = p[:9].reshape(3, 3), p[9:14]
    cam = tmp_path / f"camera.{fmt}"
    fs = cv2.FileStorage(str(cam), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1022)
    fs.write("image_height", 768)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", dist.reshape(1, 5))
    fs.release()
    images = [str(folder / f"pos{k}.png") for k in range(5)]
    poses = [str(folder / f"pos{k}.txt") for k in range(5)]
    out = tmp_path / "he.json"
    code = main(["handeye", "--robot-poses", *poses, "--images", *images, "--camera", str(cam),
                 "--target", "acircles", "--circles", "light", "--board", "7x11",
                 "--square", "40", "--setup", "eye-to-hand", "-o", str(out)])  # fmt: skip
    assert code == 0
    text = capsys.readouterr()
    assert "skipped" not in text.err
    assert "X = T_base_camera" in text.out and "AX = XB residuals over 10 pairs" in text.out
    obj = circles_grid_points((7, 11), 40.0)
    targets = []
    for path in images:
        det = find_circles_grid(read_image(path, mode="gray"), (7, 11), blob_color="light")
        targets.append(board_pose(obj, det.centers, K, dist))
    robot = [read_xyz_rpy(f, "rpy_xyz") for f in poses]
    ref = calibrate_hand_eye(robot, targets, "eye_to_hand", "tsai")
    data = json.loads(out.read_text())
    assert data["setup"] == "eye_to_hand" and data["stations"] == 5
    np.testing.assert_allclose(data["X"], ref.X, atol=1e-9)


# --------------------------------------------------------------------------- issue 30


@pytest.mark.realdata
def test_stereo_calibrate_writes_what_stereo_calib_reads(tmp_path, capsys):
    """The OpenCV pairs (a folder and a glob): --json equals the library on the same
    pairs (1e-9: the same code), the OpenCV YAML it writes is read by cv2.FileStorage and
    by `stereo --calib`, and --format ros writes one camera_info per camera."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.calibration import chessboard_points, find_board_pairs, stereo_calibrate

    folder = data_path("calibration", "opencv_chessboard_stereo")
    out = tmp_path / "stereo.yml"
    code = main(["stereo-calibrate", "--left", str(folder / "left*.jpg"),
                 "--right", str(folder / "right*.jpg"), "--board", "9x6",
                 "--square", "0.025", "-o", str(out), "--json"])  # fmt: skip
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["format"] == "opencv" and data["outputs"] == [str(out)]
    assert len(data["left_images"]) == 13 and data["skipped"] == []
    left = sorted(str(p) for p in folder.glob("left*.jpg"))
    right = sorted(str(p) for p in folder.glob("right*.jpg"))
    pairs = find_board_pairs(left, right, (9, 6))
    ref = stereo_calibrate(chessboard_points((9, 6), 0.025), pairs.corners1, pairs.corners2,
                           pairs.image_size)  # fmt: skip
    np.testing.assert_allclose(data["T"], ref.T, atol=1e-9)
    assert data["baseline"] == pytest.approx(np.linalg.norm(ref.T))
    assert 0.07 < data["baseline"] < 0.1  # OpenCV's sample rig: about 8.3 cm (square 25 mm)
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(fs.getNode("M1").mat(), ref.K1)
    np.testing.assert_array_equal(fs.getNode("T").mat().ravel(), ref.T)
    fs.release()
    code = main(["stereo", str(folder / "left01.jpg"), str(folder / "right01.jpg"),
                 "--calib", str(out), "--max-disparity", "32", "--method", "bm",
                 "-o", str(tmp_path / "d.png"), "--json"])  # fmt: skip
    assert code == 0 and json.loads(capsys.readouterr().out)["size"] == [640, 480]
    code = main(["stereo-calibrate", "--left", str(folder / "left0*.jpg"),
                 "--right", str(folder / "right0*.jpg"), "--board", "9x6",
                 "-o", str(tmp_path / "rig.yaml"), "--format", "ros", "--quiet"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "rig_left.yaml" in text and "rig_right.yaml" in text
    assert "camera_name: stereo/right" in (tmp_path / "rig_right.yaml").read_text()


def test_stereo_calibrate_usage_errors(tmp_path, capsys):
    from robopercept.imaging import write_image

    for name in ("l1.png", "l2.png", "r1.png"):
        write_image(tmp_path / name, np.full((40, 60), 128, np.uint8))
    base = ["stereo-calibrate", "--board", "9x6"]
    code = main([*base, "--left", str(tmp_path / "l*.png"), "--right", str(tmp_path / "r*.png")])
    assert code == 2 and "--left gives 2 images but --right 1" in capsys.readouterr().err
    code = main([*base, "--left", str(tmp_path / "q*.png"), "--right", str(tmp_path / "r1.png")])
    assert code == 2 and "--left: no file matches" in capsys.readouterr().err
    code = main([*base, "--left", str(tmp_path / "l1.png"), "--right", str(tmp_path / "r1.png"),
                 "-o", str(tmp_path / "s.json"), "--format", "ros"])  # fmt: skip
    assert code == 2 and "format 'ros' writes .yaml or .yml files" in capsys.readouterr().err
    code = main([*base, "--left", str(tmp_path / "l1.png"), "--right", str(tmp_path / "r1.png"),
                 "-o", str(tmp_path / "s.json"), "--quiet"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 1 and "found in both images of 0 of 1 pairs" in err


@pytest.mark.realdata
def test_calibrate_writes_opencv_yaml_that_cv2_reads(tmp_path, capsys):
    """-o cam.yml: an OpenCV FileStorage file with the calibration sample's names, equal
    to the --json summary; a JSON name with --format opencv is a usage error."""
    cv2 = pytest.importorskip("cv2")
    folder = data_path("calibration", "opencv_chessboard_stereo")
    images = [str(folder / f"left{i:02d}.jpg") for i in (1, 3, 4, 6, 11, 14)]
    out = tmp_path / "cam.yml"
    code = main(["calibrate", *images, "--board", "9x6", "--square", "0.025", "-o", str(out),
                 "--quiet", "--json"])  # fmt: skip
    assert code == 0
    data = json.loads(capsys.readouterr().out)
    assert data["format"] == "opencv" and data["images"] == images
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    np.testing.assert_array_equal(fs.getNode("camera_matrix").mat(), np.array(data["K"]))
    np.testing.assert_array_equal(
        fs.getNode("distortion_coefficients").mat().ravel(), np.array(data["dist"])
    )
    assert fs.getNode("image_width").real() == 640
    assert fs.getNode("avg_reprojection_error").real() == data["rms"]
    assert fs.getNode("board").at(0).real() == 9
    fs.release()
    code = main(["calibrate", *images, "--board", "9x6", "-o", str(tmp_path / "c.json"),
                 "--format", "opencv"])  # fmt: skip
    assert code == 2 and "format 'opencv' writes .yaml or .yml" in capsys.readouterr().err


def test_handeye_quaternion_and_ros_transform(tmp_path, capsys):
    """--json holds X's quaternion (x, y, z, w) and the ROS transform in metres
    (--metres-per-unit 0.001 for millimetre poses); -o .yaml writes the transform that
    read_transform reads back with the frames given."""
    from robopercept.calibration import pose_from_xyz_rpy, quaternion_from_rotation, read_transform
    from robopercept.geometry import invert, rotation_from_rotvec, se3

    rng = np.random.default_rng(5)
    X = se3(rotation_from_rotvec([0.1, -0.2, 1.5]), [30.0, -10.0, 80.0])
    Y = se3(rotation_from_rotvec([3.0, 0.1, 0.0]), [600.0, 50.0, 0.0])
    robots, targets = [], []
    for i in range(5):
        xyz = rng.normal(0, 100, 3) + np.array([500.0, 0, 400])
        g = pose_from_xyz_rpy(xyz, rng.normal(0, 20, 3) + np.array([180.0, 0, 0]))
        _write_matrix(tmp_path / f"g{i}.txt", g)
        _write_matrix(tmp_path / f"c{i}.txt", invert(g @ X) @ Y)
        robots.append(str(tmp_path / f"g{i}.txt"))
        targets.append(str(tmp_path / f"c{i}.txt"))
    args = ["handeye", "--robot-poses", *robots, "--pose-format", "matrix",
            "--target-poses", *targets, "--setup", "eye-in-hand",
            "--metres-per-unit", "0.001"]  # fmt: skip
    assert main([*args, "-o", str(tmp_path / "he.json"), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(
        data["quaternion_xyzw"], quaternion_from_rotation(X[:3, :3]), atol=1e-7
    )
    tr = data["transform"]["transform"]["translation"]
    assert [tr["x"], tr["y"], tr["z"]] == pytest.approx([0.03, -0.01, 0.08], abs=1e-8)
    assert data["parent_frame"] == "tool0" and data["child_frame"] == "camera_optical_frame"
    out = tmp_path / "he.yaml"
    assert main([*args, "-o", str(out), "--parent-frame", "flange", "--child-frame", "cam"]) == 0
    assert "static_transform_publisher" in capsys.readouterr().out
    T, parent, child = read_transform(out)
    np.testing.assert_allclose(T[:3, :3], X[:3, :3], atol=1e-7)
    np.testing.assert_allclose(T[:3, 3], X[:3, 3] / 1000, atol=1e-9)
    assert (parent, child) == ("flange", "cam")
    assert main([*args, "-o", str(tmp_path / "he.txt")]) == 2
    assert "hand-eye files are .json" in capsys.readouterr().err
    assert main([*args[:-1], "0", "-o", str(tmp_path / "h.json")]) == 1
    assert "--metres-per-unit must be" in capsys.readouterr().err


@pytest.mark.realdata
def test_calibrate_expands_a_quoted_pattern_as_the_shell_would(tmp_path, capsys):
    # 'left0*.jpg' reached calibrate unexpanded (quoted, or from a script) and was read as
    # one missing file: "board found in 0 of 1 images"; it now means its matches
    folder = data_path("calibration", "opencv_chessboard_stereo")
    files = sorted(str(f) for f in folder.glob("left0*.jpg"))
    out_a, out_b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["calibrate", str(folder / "left0*.jpg"), "--board", "9x6", "-o", str(out_a),
                 "--quiet", "--json"]) == 0  # fmt: skip
    by_pattern = json.loads(capsys.readouterr().out)
    assert main(["calibrate", *files, "--board", "9x6", "-o", str(out_b), "--quiet", "--json"]) == 0
    by_files = json.loads(capsys.readouterr().out)
    assert len(files) >= 5 and by_pattern["images"] == by_files["images"]
    assert by_pattern["K"] == by_files["K"]
    assert main(["calibrate", str(folder / "nothing*.jpg"), "--board", "9x6", "-o",
                 str(out_a)]) == 2  # fmt: skip
    assert "no file matches" in capsys.readouterr().err
