"""Calibration files users' other tools read: OpenCV FileStorage YAML written here and
read by cv2.FileStorage (and the other way round), ROS camera_info YAML in
camera_calibration_parsers' layout, ROS transforms with quaternions (against scipy), and
the stereo image pairs that feed stereo_calibrate, with bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.calibration import (
    CalibrationResult,
    HandEyeResult,
    StereoCalibration,
    calibration_format,
    camera_info,
    chessboard_points,
    find_board_pairs,
    hand_eye_report,
    load_calibration,
    quaternion_from_rotation,
    read_opencv_storage,
    read_transform,
    rotation_from_quaternion,
    save_calibration,
    save_hand_eye,
    stereo_calibrate,
    transform_stamped,
    write_opencv_storage,
    write_ros_yaml,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.geometry import rotation_from_rotvec, se3
from robopercept.geometry.epipolar import essential_from_pose
from tests.calibration._render import render_board

K = np.array([[812.5, 0.0, 330.25], [0.0, 815.0, 241.75], [0.0, 0.0, 1.0]])
DIST = np.array([-0.21, 0.093, 0.0012, -0.0007, -0.015])
K2 = np.array([[805.0, 0.0, 322.5], [0.0, 806.5, 238.0], [0.0, 0.0, 1.0]])
R_REL = rotation_from_rotvec([0.01, -0.03, 0.005])
T_REL = np.array([-0.12, 0.002, 0.001])


def _mono():
    rng = np.random.default_rng(0)
    return CalibrationResult(
        K, DIST, rng.normal(0, 0.2, (4, 3)), rng.normal(0, 1, (4, 3)) + np.array([0, 0, 5.0]),
        0.31, np.array([0.2, 0.3, 0.25, 0.4]), (640, 480),
    )  # fmt: skip


def _stereo():
    E = essential_from_pose(R_REL, T_REL)
    F = np.linalg.inv(K2).T @ E @ np.linalg.inv(K)
    return StereoCalibration(
        K, DIST, K2, DIST * 0.5, R_REL, T_REL, E, F / F[2, 2], 0.4,
        np.array([[0.3, 0.5], [0.4, 0.45]]), (640, 480),
    )  # fmt: skip


# --------------------------------------------------------------------------- OpenCV


def test_opencv_yaml_is_read_by_cv2_bit_for_bit(tmp_path):
    """Every value type write_opencv_storage takes, read back by cv2.FileStorage with
    the same dtype and the same bits (floats written in their shortest exact form), and
    by our reader likewise."""
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(1)
    data = {
        "n": 640,
        "x": 0.1 + 1e-17,
        "s": 'a "quoted"\\ string\nwith a newline',
        "d": rng.normal(size=(3, 4)),
        "f": rng.normal(size=(2, 3)).astype(np.float32),
        "i": np.arange(-3, 3, dtype=np.int32).reshape(2, 3),
        "u": np.arange(6, dtype=np.uint8).reshape(3, 2),
        "v": rng.normal(size=5),  # a vector is a column, as cv::Mat stores std::vector
        "c": rng.normal(size=(2, 2, 3)),  # three channels: dt "3d"
        "seq": [1, 2.5, "x"],
        "nested": {"a": 1, "m": np.eye(2)},
        "rows": [{"image": "a.png", "reason": "no board"}],
    }
    path = write_opencv_storage(tmp_path / "x.yml", data)
    assert path.read_text().startswith("%YAML:1.0\n---\n")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    ours = read_opencv_storage(path)
    for key in ("d", "f", "i", "u", "v", "c"):
        ref = fs.getNode(key).mat()
        want = data[key][:, None] if data[key].ndim == 1 else data[key]
        assert ref.dtype == want.dtype and np.array_equal(ref, want), key
        assert ours[key].dtype == want.dtype and np.array_equal(ours[key], want), key
    assert fs.getNode("n").real() == 640 and fs.getNode("x").real() == data["x"]
    assert fs.getNode("s").string() == data["s"] == ours["s"]
    assert fs.getNode("seq").at(2).string() == "x" and ours["seq"] == [1, 2.5, "x"]
    assert np.array_equal(fs.getNode("nested").getNode("m").mat(), np.eye(2))
    assert fs.getNode("rows").at(0).getNode("reason").string() == "no board"
    assert ours["rows"] == [{"image": "a.png", "reason": "no board"}]
    fs.release()


def test_opencv_calibration_matches_the_sample_layout_and_cv2_reads_it(tmp_path):
    """save_calibration's OpenCV file has the names of OpenCV's calibration sample;
    cv2 reads K, distortion and the size; load_calibration reads it back exactly."""
    cv2 = pytest.importorskip("cv2")
    res = _mono()
    [path] = save_calibration(tmp_path / "cam.yaml", res, extra={"board": [9, 6]})
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert np.array_equal(fs.getNode("camera_matrix").mat(), K)
    assert np.array_equal(fs.getNode("distortion_coefficients").mat().ravel(), DIST)
    assert fs.getNode("image_width").real() == 640 and fs.getNode("image_height").real() == 480
    assert fs.getNode("avg_reprojection_error").real() == 0.31
    ext = fs.getNode("extrinsic_parameters").mat()
    assert np.array_equal(ext, np.c_[res.rvecs, res.tvecs])
    fs.release()
    cam = load_calibration(path)
    assert np.array_equal(cam["K"], K) and np.array_equal(cam["dist"], DIST)
    assert cam["image_size"] == (640, 480) and cam["board"] == [9, 6]


def test_calibration_written_by_cv2_is_read(tmp_path):
    """The other way round: a calibration that cv2.FileStorage writes."""
    cv2 = pytest.importorskip("cv2")
    path = tmp_path / "cv.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", DIST.reshape(1, 5))
    fs.release()
    cam = load_calibration(path)
    assert np.array_equal(cam["K"], K) and np.array_equal(cam["dist"], DIST)
    assert cam["image_size"] == (640, 480)


def test_opencv_stereo_file_has_the_stereo_calib_names_and_cv2_rectification(tmp_path):
    """M1 D1 M2 D2 R T (stereo_calib's names) plus R1 R2 P1 P2 Q equal to
    cv2.stereoRectify's (to 1e-6: both are Bouguet's; the repository's own parity test
    of rectify_stereo holds the tolerance); load_calibration gives K1..T back."""
    cv2 = pytest.importorskip("cv2")
    st = _stereo()
    [path] = save_calibration(tmp_path / "stereo.yml", st)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert np.array_equal(fs.getNode("M2").mat(), K2)
    assert np.array_equal(fs.getNode("T").mat().ravel(), T_REL)
    R1, R2, P1, P2, Q, *_ = cv2.stereoRectify(K, DIST, K2, DIST * 0.5, (640, 480), R_REL, T_REL)
    for name, ref in (("R1", R1), ("R2", R2), ("P1", P1), ("P2", P2), ("Q", Q)):
        np.testing.assert_allclose(fs.getNode(name).mat(), ref, atol=1e-6, err_msg=name)
    fs.release()
    cal = load_calibration(path)
    for key, want in (("K1", K), ("K2", K2), ("R", R_REL), ("T", T_REL), ("dist2", DIST * 0.5)):
        assert np.array_equal(cal[key], want), key


# --------------------------------------------------------------------------- ROS

# the layout camera_calibration_parsers' writeCalibrationYml gives (its test file and the
# `camera_calibration` node's ost.yaml): keys in this order, matrices as rows/cols/data
ROS_KEYS = [
    "image_width", "image_height", "camera_name", "camera_matrix", "distortion_model",
    "distortion_coefficients", "rectification_matrix", "projection_matrix",
]  # fmt: skip


def test_ros_camera_info_layout_and_round_trip(tmp_path):
    res = _mono()
    [path] = save_calibration(tmp_path / "ost.yaml", res, "ros", camera_name="narrow_stereo")
    text = path.read_text()
    top = [ln.split(":")[0] for ln in text.splitlines() if not ln.startswith(" ")]
    assert top == ROS_KEYS
    assert "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [812.5, 0.0, 330.25," in text
    assert "distortion_model: plumb_bob\n" in text and "camera_name: narrow_stereo\n" in text
    assert "projection_matrix:\n  rows: 3\n  cols: 4\n" in text
    assert not text.startswith("%YAML")  # plain YAML: yaml.safe_load and yaml-cpp read it
    cam = load_calibration(path)
    assert np.array_equal(cam["K"], K) and np.array_equal(cam["dist"], DIST)
    assert cam["image_size"] == (640, 480) and cam["camera_name"] == "narrow_stereo"
    P = np.array(cam["projection_matrix"]["data"]).reshape(3, 4)
    assert np.array_equal(P, np.c_[K, np.zeros(3)])  # mono: [K | 0], R = I
    assert cam["rectification_matrix"]["data"] == np.eye(3).ravel().tolist()
    yaml = pytest.importorskip("yaml", reason="PyYAML not installed: the layout checks above")
    assert list(yaml.safe_load(text)) == ROS_KEYS


def test_ros_stereo_pair_writes_left_and_right_with_the_baseline_in_P(tmp_path):
    """Two camera_info files; the right projection's P[0, 3] is -f' B (B the baseline),
    as cv2.stereoRectify's P2 and the ROS stereo pipeline expect."""
    paths = save_calibration(tmp_path / "rig.yaml", _stereo(), "ros")
    assert [p.name for p in paths] == ["rig_left.yaml", "rig_right.yaml"]
    left, right = (load_calibration(p) for p in paths)
    assert left["camera_name"] == "camera/left" and np.array_equal(right["K"], K2)
    P2 = np.array(right["projection_matrix"]["data"]).reshape(3, 4)
    assert P2[0, 3] == pytest.approx(-P2[0, 0] * np.linalg.norm(T_REL), rel=1e-9)
    R1 = np.array(left["rectification_matrix"]["data"]).reshape(3, 3)
    np.testing.assert_allclose(R1 @ R1.T, np.eye(3), atol=1e-12)


def test_calibration_format_and_bad_outputs(tmp_path):
    assert calibration_format("a.json") == "json"
    assert calibration_format("a.YML") == "opencv"
    assert calibration_format("a.yaml", "ros") == "ros"
    with pytest.raises(InputError, match=r"got 'a.xml'"):
        calibration_format("a.xml")
    with pytest.raises(InputError, match=r"format 'json' writes .json files; got 'a.yaml'"):
        calibration_format("a.yaml", "json")
    with pytest.raises(InputError, match="format must be one of"):
        calibration_format("a.yaml", "matlab")
    with pytest.raises(InputError, match="extra names entries of the calibration itself: K"):
        save_calibration(tmp_path / "a.json", _mono(), extra={"K": 1})
    with pytest.raises(InputError, match="FileStorage holds numbers"):
        save_calibration(tmp_path / "a.yml", _mono(), extra={"bad": None})
    with pytest.raises(InputError, match="FileStorage names start with a letter"):
        write_opencv_storage(tmp_path / "b.yml", {"1x": 1})
    with pytest.raises(InputError, match="camera_name must be a string"):
        save_calibration(tmp_path / "a.yaml", _mono(), "ros", camera_name=3)
    with pytest.raises(InputError, match="YAML values here are numbers"):
        write_ros_yaml(tmp_path / "c.yaml", {"a": np.eye(2)})
    with pytest.raises(InputError, match=r"image_size must be \(width, height\)"):
        camera_info(K, DIST, (640, 0))


# --------------------------------------------------------------------------- transforms


def test_quaternions_match_scipy_and_round_trip():
    """Random rotations and the hard cases (identity, 180 degrees about each axis, near
    180): equal to scipy's canonical quaternion (w >= 0) to 1e-12."""
    Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    rng = np.random.default_rng(3)
    vecs = [rng.normal(size=3) for _ in range(50)]
    vecs += [np.zeros(3), [np.pi, 0, 0], [0, np.pi, 0], [0, 0, np.pi], [3.14159, 0.001, 0]]
    for v in vecs:
        R = rotation_from_rotvec(np.asarray(v, float))
        q = quaternion_from_rotation(R)
        ref = Rotation.from_matrix(R).as_quat(canonical=True)
        if abs(ref[3]) < 1e-12:  # w = 0: q and -q both canonical up to the first nonzero
            ref = ref * np.sign(ref[np.flatnonzero(np.abs(ref) > 1e-9)[0]])
            q = q * np.sign(q[np.flatnonzero(np.abs(q) > 1e-9)[0]])
        np.testing.assert_allclose(q, ref, atol=1e-12)
        np.testing.assert_allclose(rotation_from_quaternion(q), R, atol=1e-12)
    with pytest.raises(InputError, match="q is zero"):
        rotation_from_quaternion([0, 0, 0, 0])
    with pytest.raises(InputError, match="q must be 4 finite numbers"):
        rotation_from_quaternion([0, 0, 1])


def test_transform_yaml_round_trip_and_bad_files(tmp_path):
    T = se3(rotation_from_rotvec([0.3, -1.2, 2.0]), [0.1, -0.25, 0.5])
    msg = transform_stamped(T, "tool0", "camera_optical_frame")
    assert msg["header"] == {"frame_id": "tool0"}
    path = write_ros_yaml(tmp_path / "tf.yaml", msg)
    assert path.read_text().splitlines()[:4] == [
        "header:", "  frame_id: tool0", "child_frame_id: camera_optical_frame", "transform:",
    ]  # fmt: skip
    back, parent, child = read_transform(path)
    np.testing.assert_allclose(back, T, atol=1e-15)
    assert (parent, child) == ("tool0", "camera_optical_frame")
    (tmp_path / "bad.yaml").write_text("header:\n  frame_id: a\nchild_frame_id: b\n")
    with pytest.raises(FileFormatError, match="not a transform"):
        read_transform(tmp_path / "bad.yaml")
    with pytest.raises(InputError, match="parent_frame must be a frame name"):
        transform_stamped(T, "", "b")


def test_hand_eye_report_and_files(tmp_path):
    """The report's quaternion is scipy's of X; the ROS transform is in metres with
    metres_per_unit, the JSON keeps the input units; both files read back."""
    Rotation = pytest.importorskip("scipy.spatial.transform").Rotation
    X = se3(rotation_from_rotvec([0.1, -0.2, 1.5]), [30.0, -10.0, 80.0])  # millimetres
    res = HandEyeResult(X, np.eye(4), "eye_in_hand", "tsai", np.zeros(2), np.zeros(2))
    rep = hand_eye_report(res, metres_per_unit=0.001)
    np.testing.assert_allclose(
        rep["quaternion_xyzw"], Rotation.from_matrix(X[:3, :3]).as_quat(canonical=True), atol=1e-12
    )
    assert rep["xyz"] == pytest.approx([30.0, -10.0, 80.0])
    assert rep["transform"]["transform"]["translation"] == pytest.approx(
        {"x": 0.03, "y": -0.01, "z": 0.08}
    )
    assert (rep["parent_frame"], rep["child_frame"]) == ("tool0", "camera_optical_frame")
    command = rep["static_transform_publisher"]
    assert "--frame-id tool0 --child-frame-id camera_optical_frame" in command
    save_hand_eye(tmp_path / "he.yaml", res, parent_frame="flange", metres_per_unit=0.001)
    T, parent, _ = read_transform(tmp_path / "he.yaml")
    np.testing.assert_allclose(T[:3, 3], X[:3, 3] / 1000, atol=1e-15)
    assert parent == "flange"
    save_hand_eye(tmp_path / "he.json", res, extra={"stations": 7})
    data = json.loads((tmp_path / "he.json").read_text())
    assert data["stations"] == 7 and np.allclose(data["X"], X)
    with pytest.raises(InputError, match=r"hand-eye files are .json"):
        save_hand_eye(tmp_path / "he.txt", res)
    with pytest.raises(InputError, match="metres_per_unit must be"):
        hand_eye_report(res, metres_per_unit=0)


# --------------------------------------------------------------------------- stereo pairs


def test_stereo_from_rendered_pairs_recovers_the_rig():
    """A rig of two known 320x240 cameras (baseline 12 cm) photographs a board from 5
    poses; with the cameras known the pairs give back T to 1 mm and R to 0.1 degree
    (the rendering blurs corners by ~0.1 px), and cv2.stereoCalibrate
    on the same corners and intrinsics agrees with stereo_calibrate (to 1e-5: one
    least-squares problem, two Levenberg-Marquardt solvers)."""
    cv2 = pytest.importorskip("cv2")
    k1 = np.array([[400.0, 0, 162.5], [0, 401.0, 118.5], [0, 0, 1]])
    k2 = np.array([[396.0, 0, 158.0], [0, 397.5, 121.0], [0, 0, 1]])
    poses = [([0.1, -0.2, 0.05], [-0.03, -0.08, 0.6]), ([-0.25, 0.1, 0.0], [-0.06, -0.05, 0.55]),
             ([0.3, 0.25, -0.1], [-0.05, -0.06, 0.65]), ([0.0, -0.35, 0.2], [-0.02, -0.1, 0.6]),
             ([-0.2, -0.1, -0.15], [-0.05, -0.04, 0.5])]  # fmt: skip
    left, right = [], []
    for rv, tv in poses:
        R1, t1 = rotation_from_rotvec(np.array(rv)), np.array(tv)
        left.append(render_board(k1, DIST, rv, tv, (7, 5), 0.03, (320, 240), 2))
        r2 = cv2.Rodrigues(R_REL @ R1)[0].ravel()
        right.append(
            render_board(k2, DIST * 0.5, r2, R_REL @ t1 + T_REL, (7, 5), 0.03, (320, 240), 2)
        )
    pairs = find_board_pairs(left, right, (7, 5))
    assert pairs.used == [0, 1, 2, 3, 4] and pairs.image_size == (320, 240)
    obj = chessboard_points((7, 5), 0.03)
    # the true intrinsics: five 320x240 views pin each camera's centre only to a few
    # pixels (cx 5 px off, T 8 mm off when they are calibrated too); the pose is the test
    st = stereo_calibrate(obj, pairs.corners1, pairs.corners2, (320, 240),
                          K1=k1, dist1=DIST, K2=k2, dist2=DIST * 0.5)  # fmt: skip
    assert np.linalg.norm(st.T - T_REL) < 1e-3
    angle = np.degrees(np.arccos(np.clip((np.trace(st.R @ R_REL.T) - 1) / 2, -1, 1)))
    assert angle < 0.1
    f32 = lambda a: [x.astype(np.float32) for x in a]  # noqa: E731
    out = cv2.stereoCalibrate(
        [obj.astype(np.float32)] * 5, f32(pairs.corners1), f32(pairs.corners2),
        st.K1, st.dist1, st.K2, st.dist2, (320, 240), flags=cv2.CALIB_FIX_INTRINSIC,
    )  # fmt: skip
    np.testing.assert_allclose(st.R, out[5], atol=1e-5)
    np.testing.assert_allclose(st.T, out[6].ravel(), atol=1e-5)


def test_board_pairs_reverses_a_board_numbered_from_the_other_end(monkeypatch):
    """When one image's corners run the other way the right-hand ones are reversed, so
    corner k is the same board point in both; a pair without the board is skipped."""
    import robopercept.calibration.stereo_images as si
    from robopercept.calibration import ChessboardDetection

    grid = chessboard_points((4, 3), 10.0)[:, :2] + 50.0
    shift = np.array([5.0, 0.0])
    calls = iter([grid, grid[::-1] + shift, grid, None])

    def fake(image, pattern_size):
        c = next(calls)
        if c is None:
            return ChessboardDetection(False, np.empty((0, 2)), (4, 3), "no corners")
        return ChessboardDetection(True, c, (4, 3))

    monkeypatch.setattr(si, "find_chessboard_corners", fake)
    img = np.zeros((120, 160), np.uint8)
    pairs = find_board_pairs([img, img], [img, img], (4, 3))
    assert pairs.used == [0] and pairs.flipped == [0]
    np.testing.assert_array_equal(pairs.corners2[0], grid + shift)
    assert pairs.skipped == [(1, "right image: no corners")]
    with pytest.raises(InputError, match="2 left images but 1 right images"):
        find_board_pairs([img, img], [img], (4, 3))
    calls = iter([grid])
    with pytest.raises(InputError, match="is 80x60 but the first image is 160x120"):
        find_board_pairs([img], [np.zeros((60, 80), np.uint8)], (4, 3))
