"""OpenCV FileStorage files without OpenCV: read_opencv_storage against a hand-written
file and against cv2.FileStorage (files it writes, and the real OpenCV files in
../shared/data), and load_calibration on the camera files OpenCV users have (YAML, XML,
the name variants, ROS camera_info), with bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.calibration import load_calibration, read_opencv_storage
from robopercept.errors import FileFormatError, InputError
from tests.conftest import data_path

K = np.array([[812.5, 0.0, 330.25], [0.0, 815.0, 241.75], [0.0, 0.0, 1.0]])
DIST = np.array([-0.21, 0.093, 0.0012, -0.0007, -0.015])


def _cv2_value(node):
    """What cv2.FileStorage reads for a node, as plain Python (the reference)."""
    if node.isMap() and {"dt", "data"} <= set(node.keys()):
        m = node.mat()  # the Python binding gives None for an empty matrix
        return np.zeros((0, 0)) if m is None else m
    if node.isMap():
        return {k: _cv2_value(node.getNode(k)) for k in node.keys()}
    if node.isSeq():
        return [_cv2_value(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return node.real()
    if node.isString():
        return node.string()
    return None


def _cv2_read(cv2, path):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        return {k: _cv2_value(fs.getNode(k)) for k in fs.root().keys()}
    finally:
        fs.release()


def _assert_same(ours, ref, where=""):
    """Equal structure, types, dtypes and values (NaN equal to NaN)."""
    if isinstance(ref, np.ndarray):
        assert isinstance(ours, np.ndarray), where
        assert ours.dtype == ref.dtype and ours.shape == ref.shape, (where, ours, ref)
        assert np.array_equal(ours, ref, equal_nan=True), where
    elif isinstance(ref, dict):
        assert isinstance(ours, dict) and list(ours) == list(ref), (where, ours, ref)
        for k in ref:
            _assert_same(ours[k], ref[k], f"{where}/{k}")
    elif isinstance(ref, list):
        assert isinstance(ours, list) and len(ours) == len(ref), (where, ours, ref)
        for i, (a, b) in enumerate(zip(ours, ref, strict=True)):
            _assert_same(a, b, f"{where}[{i}]")
    elif isinstance(ref, float) and np.isnan(ref):
        assert isinstance(ours, float) and np.isnan(ours), where
    else:
        assert type(ours) is type(ref) and ours == ref, (where, ours, ref)


def test_hand_written_yaml():
    """Every construct of the dialect, values written out by hand."""
    text = """%YAML:1.0
---
# a comment line
camera_matrix: !!opencv-matrix   # OpenCV's tag
   rows: 2
   cols: 3
   dt: f
   data: [ 1., 2.5, -3,
       4e1, .5, 6. ]
pts: !!opencv-matrix
   rows: 1
   cols: 2
   dt: "2i"
   data: [ 1, 2, 3, 4 ]
name: "a \\"quoted\\" #1"
plain: two words
single: 'it''s'
empty: ""
n: -7
x: 1.
inf: -.Inf
seq:
   - 1
   - two
   - [ 3, { a: 4 } ]
items:
- a: 1
  b: [1, 2]
- - 5
  - 6
nested:
   deep:
      v: 0x
"""
    from pathlib import Path
    from tempfile import TemporaryDirectory

    with TemporaryDirectory() as d:
        p = Path(d) / "f.yml"
        p.write_text(text)
        fs = read_opencv_storage(p)
    m = fs["camera_matrix"]
    assert m.dtype == np.float32 and m.shape == (2, 3)
    assert np.array_equal(m, [[1, 2.5, -3], [40, 0.5, 6]])
    assert fs["pts"].dtype == np.int32 and fs["pts"].shape == (1, 2, 2)
    assert fs["pts"][0, 1].tolist() == [3, 4]
    assert fs["name"] == 'a "quoted" #1' and fs["plain"] == "two words"
    assert fs["single"] == "it's" and fs["empty"] == ""
    assert fs["n"] == -7 and isinstance(fs["n"], int)
    assert fs["x"] == 1.0 and isinstance(fs["x"], float) and fs["inf"] == -np.inf
    assert fs["seq"] == [1, "two", [3, {"a": 4}]]
    assert fs["items"] == [{"a": 1, "b": [1, 2]}, [5, 6]]
    assert fs["nested"] == {"deep": {"v": "0x"}}


@pytest.fixture
def cv2():
    return pytest.importorskip("cv2")


@pytest.mark.parametrize("ext", ["yml", "xml"])
def test_files_written_by_opencv(cv2, tmp_path, ext):
    """Parity with cv2.FileStorage's reader on what its writer makes: every dt, channels,
    nested maps and sequences, strings with quotes, backslashes and '#', .Inf and .Nan,
    an empty matrix."""
    path = tmp_path / f"all.{ext}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", DIST.reshape(1, 5))
    fs.write("image_width", 640)
    fs.write("rms", 0.3125)
    for dt in (np.uint8, np.int8, np.uint16, np.int16, np.int32, np.float32, np.float16):
        fs.write(f"m_{np.dtype(dt).name}", np.arange(-3, 9).reshape(3, 4).astype(dt) % 7)
    fs.write("corners", np.arange(12, dtype=np.float32).reshape(3, 2, 2))
    fs.write("empty", np.zeros((0, 0)))
    for key, s in [("q", 'say "hi" & <go>'), ("win", "C:\\new\\dir"), ("hash", "it's #1"),
                   ("words", "two words"), ("digits", "42"), ("blank", "")]:  # fmt: skip
        fs.write(key, s)
    fs.write("inf", float("-inf"))
    fs.write("nan", float("nan"))
    fs.startWriteStruct("nested", cv2.FileNode_MAP)
    fs.write("a", 1)
    fs.startWriteStruct("seq", cv2.FileNode_SEQ)
    for v in (1, 2.5, "three"):
        fs.write("", v)
    fs.endWriteStruct()
    fs.endWriteStruct()
    fs.startWriteStruct("views", cv2.FileNode_SEQ)
    for k in range(2):
        fs.startWriteStruct("", cv2.FileNode_MAP)
        fs.write("id", k)
        fs.write("T", np.eye(2) * k)
        fs.endWriteStruct()
    fs.endWriteStruct()
    fs.release()
    ours = read_opencv_storage(path)
    _assert_same(ours, _cv2_read(cv2, path))
    assert ours["q"] == 'say "hi" & <go>' and ours["win"] == "C:\\new\\dir"
    assert ours["corners"].shape == (3, 2, 2) and ours["digits"] == "42"


@pytest.mark.realdata
def test_real_opencv_files(cv2):
    """OpenCV's own files in the data folder, equal to cv2.FileStorage's reading:
    calibration results (YAML), ground-truth corners (YAML, dt "2f"), homographies (XML)."""
    cal = data_path("calibration", "opencv_chessboard_stereo")
    gt = data_path("calibration", "opencv_extra_corners_gt")
    files = [cal / "left_intrinsics.yml", cal / "intrinsics.yml", cal / "stereo_calib.xml",
             gt / "acircles" / "acircles_corners1.dat", gt / "circles" / "circles_list.dat",
             gt / "negative" / "negative_1.dat",
             data_path("features", "oxford_affine", "graf", "H1to3p.xml")]  # fmt: skip
    for path in files:
        _assert_same(read_opencv_storage(path), _cv2_read(cv2, path), str(path))
    corners = read_opencv_storage(gt / "acircles" / "acircles_corners1.dat")["corners"]
    assert corners.shape == (13, 7, 2) and corners.dtype == np.float32


@pytest.mark.parametrize("ext", ["yml", "xml", "json"])
@pytest.mark.parametrize(
    ("k_name", "d_name"),
    [("camera_matrix", "distortion_coefficients"), ("K", "D"), ("cameraMatrix", "distCoeffs")],
)
def test_load_calibration_opencv_names(cv2, tmp_path, ext, k_name, d_name):
    """A camera file written by cv2.FileStorage under each common naming gives K, dist
    and image_size exactly (the numbers are written with 17 digits)."""
    path = tmp_path / f"cam.{ext}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write(k_name, K)
    fs.write(d_name, DIST.reshape(5, 1))
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("avg_reprojection_error", 0.25)
    fs.release()
    cam = load_calibration(path)
    assert np.array_equal(cam["K"], K) and np.array_equal(cam["dist"], DIST)
    assert cam["image_size"] == (640, 480) and cam["avg_reprojection_error"] == 0.25


def test_load_calibration_stereo_and_short_distortion(cv2, tmp_path):
    """OpenCV's stereo names (M1, D1, M2, D2, R, T with T a 3 x 1 column) and 4 or
    zero-padded 8 coefficients."""
    R = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    K2 = K.copy()
    K2[:2] *= 1.01  # a camera matrix keeps its bottom row (0, 0, 1)
    path = tmp_path / "stereo.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("M1", K)
    fs.write("D1", DIST[:4].reshape(1, 4))
    fs.write("M2", K2)
    fs.write("D2", np.r_[DIST, 0, 0, 0].reshape(1, 8))
    fs.write("R", R)
    fs.write("T", np.array([[-0.1], [0.0], [0.002]]))
    fs.release()
    cam = load_calibration(path)
    assert np.array_equal(cam["K1"], K) and np.array_equal(cam["K2"], K2)
    assert np.array_equal(cam["dist1"], [*DIST[:4], 0.0])
    assert np.array_equal(cam["dist2"], DIST)
    assert cam["T"].shape == (3,) and np.array_equal(cam["R"], R)


def test_load_calibration_ros_camera_info(tmp_path):
    """ROS camera_calibration's YAML: plain YAML, matrices as {rows, cols, data}."""
    path = tmp_path / "ost.yaml"
    path.write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: narrow_stereo\n"
        "camera_matrix:\n  rows: 3\n  cols: 3\n  data: ["
        + ", ".join(str(v) for v in K.ravel())
        + "]\ndistortion_model: plumb_bob\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
        "  data: [" + ", ".join(str(v) for v in DIST) + "]\n"
    )
    cam = load_calibration(path)
    assert np.array_equal(cam["K"], K) and np.array_equal(cam["dist"], DIST)
    assert cam["image_size"] == (640, 480)


@pytest.mark.realdata
def test_load_calibration_opencv_sample_result():
    """OpenCV's calibration sample output (left_intrinsics.yml) reads as the camera it
    holds; the stereo sample's intrinsics.yml has no R, T and is refused by name."""
    folder = data_path("calibration", "opencv_chessboard_stereo")
    cam = load_calibration(folder / "left_intrinsics.yml")
    assert cam["K"][0, 0] == 5.3591573396163199e02 and cam["K"][1, 2] == 2.3557082909788173e02
    assert cam["dist"][4] == 2.3839153080878486e-01 and cam["image_size"] == (640, 480)
    with pytest.raises(FileFormatError, match="found D1, D2, M1, M2"):
        load_calibration(folder / "intrinsics.yml")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        # PyYAML's messages (issue 48), with the file and the line
        ("%YAML:1.0\na: 1\n   b: 2\n", "line 3: mapping values are not allowed here"),
        ("%YAML:1.0\na: [1, 2\n", r"expected ',' or '\]'.*flow sequence at line 2"),
        ("%YAML:1.0\nm: !!opencv-matrix\n   rows: 2\n   cols: 2\n   dt: d\n   data: [1, 2]\n",
         "needs 4 numbers"),
        ("%YAML:1.0\nm: !!opencv-matrix\n   rows: 1\n   cols: 1\n   dt: q\n   data: [1]\n",
         "dt='q'"),
        ("%YAML:1.0\na: &anchor 1\n", "anchors"),
        ("%YAML:1.0\n\ta: 1\n", "tab"),
        ("<?xml version='1.0'?>\n<root><a>1</a></root>\n", "<opencv_storage>"),
        ("<?xml version='1.0'?>\n<opencv_storage><a>1</opencv_storage>\n", "not well-formed"),
    ],
)  # fmt: skip
def test_bad_storage_files(tmp_path, text, match):
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=match):
        read_opencv_storage(path)


def test_bad_camera_files(tmp_path):
    """Each refusal names what to change."""

    def write(name, data):
        (tmp_path / name).write_text(json.dumps(data))
        return tmp_path / name

    rational = write("r.json", {"K": K.tolist(), "dist": [*DIST, 0.01, 0, 0]})
    with pytest.raises(FileFormatError, match="recalibrate without CALIB_RATIONAL_MODEL"):
        load_calibration(rational)
    fisheye = write("f.json", {"K": K.tolist(), "D": [0.1, 0.01, 0, 0],
                               "distortion_model": "equidistant"})  # fmt: skip
    with pytest.raises(FileFormatError, match="'equidistant' is not OpenCV's"):
        load_calibration(fisheye)
    nothing = write("n.json", {"fx": 500.0})
    with pytest.raises(FileFormatError, match=r"camera_matrix.*found fx"):
        load_calibration(nothing)
    ros = tmp_path / "ros.yaml"
    ros.write_text("camera_matrix:\n  rows: 3\n  cols: 3\n  data: [1, 2, 3]\n")
    with pytest.raises(FileFormatError, match="rows x cols"):
        load_calibration(ros)
    size = write("s.json", {"K": K.tolist(), "image_size": [640]})
    with pytest.raises(FileFormatError, match="image_size"):
        load_calibration(size)
    with pytest.raises(FileFormatError, match=r"missing\.yml: no such file"):
        load_calibration(tmp_path / "missing.yml")
    with pytest.raises(FileFormatError, match=r"is a folder; give a camera file \(\.json"):
        load_calibration(tmp_path)


# issue 25: load_calibration with "image_size": [Infinity, 480] raised OverflowError;
# every numeric field is now checked for type, finiteness and range


@pytest.mark.parametrize(
    "size",
    [
        "[Infinity, 480]",
        "[640, -Infinity]",
        "[NaN, 480]",
        "[1e30, 480]",
        "[640.5, 480]",
        "[0, 480]",
        "[-640, 480]",
        "[true, 480]",
        '["640", 480]',
        "[640, 480, 3]",
        "640",
        "[[640, 480]]",
        "[640, 2147483648]",
    ],
)
def test_json_image_size_must_be_two_whole_positive_numbers(tmp_path, size):
    path = tmp_path / "cam.json"
    path.write_text(f'{{"K": {json.dumps(K.tolist())}, "image_size": {size}}}')
    with pytest.raises(FileFormatError, match=r"cam\.json: field 'image_size'.*width, height"):
        load_calibration(path)


def test_json_image_size_as_whole_floats_reads_as_ints(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text(f'{{"K": {json.dumps(K.tolist())}, "image_size": [640.0, 480.0]}}')
    size = load_calibration(path)["image_size"]
    assert size == (640, 480) and all(type(v) is int for v in size)


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("K", '[["500", 0, 320], [0, 500, 240], [0, 0, 1]]', "'K' must hold numbers"),
        ("K", "[[1" + "0" * 400 + ", 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' must hold numb"),
        ("K", "[[true, 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' must hold numbers"),
        ("K", "[[null, 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' must hold numbers"),
        ("K", "[[NaN, 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' is not finite"),
        ("K", "[[1e999, 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' is not finite"),
        ("K", "[[-500, 0, 320], [0, 500, 240], [0, 0, 1]]", "'K' must be a camera matrix"),
        ("K", "[[500, 0, 320], [0, 0, 240], [0, 0, 1]]", r"'K' .* with fx, fy > 0"),
        ("K", "[[500, 0, 320], [0, 500, 240], [0, 0, 2]]", r"'K' .*\[0, 0, 1\]\] with"),
        ("dist", "[0.1, Infinity, 0, 0, 0]", "'dist' is not finite"),
        ("dist", '[0.1, 0, 0, 0, "x"]', "'dist' must hold numbers"),
    ],
)
def test_json_matrices_must_be_finite_numbers_of_the_right_form(tmp_path, field, value, match):
    data = {"K": json.dumps(K.tolist()), "dist": json.dumps(DIST.tolist())}
    data[field] = value
    path = tmp_path / "cam.json"
    path.write_text("{" + ", ".join(f'"{k}": {v}' for k, v in data.items()) + "}")
    with pytest.raises(FileFormatError, match=rf"cam\.json: field {match}"):
        load_calibration(path)


def test_stereo_rotation_must_be_a_rotation(tmp_path):
    cam = {"K1": K.tolist(), "K2": K.tolist(), "T": [-0.1, 0, 0]}
    for name, R in (("scaled", 2 * np.eye(3)), ("mirror", np.diag([1.0, 1, -1]))):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({**cam, "R": R.tolist()}))
        with pytest.raises(FileFormatError, match=r"field 'R' must be a rotation"):
            load_calibration(path)
    path = tmp_path / "ok.json"
    path.write_text(json.dumps({**cam, "R": np.eye(3).tolist()}))
    assert np.array_equal(load_calibration(path)["R"], np.eye(3))


@pytest.mark.parametrize(
    ("matrix", "match"),
    [
        ("rows: .inf\n   cols: 1\n   dt: d\n   data: [1]", r"rows must be an integer .* \.?inf"),
        ("rows: 1\n   cols: .nan\n   dt: d\n   data: [1]", "cols must be an integer"),
        ("rows: 2.5\n   cols: 2\n   dt: d\n   data: [1, 2, 3, 4, 5]", "rows must be an integer"),
        ("rows: -1\n   cols: -3\n   dt: d\n   data: [1, 2, 3]", "rows must be an integer"),
        ('rows: 1\n   cols: "3"\n   dt: d\n   data: [1, 2, 3]', "cols must be an integer"),
        ("rows: 65536\n   cols: 65536\n   dt: d\n   data: [1]", "needs 4294967296 numbers"),
        ("rows: 1\n   cols: 1\n   dt: 999999d\n   data: [1]", "1 to 512 channels"),
        ("rows: 1\n   cols: 2\n   dt: u\n   data: [1, 300]", r"300\.0 does not fit .*\(uint8\)"),
        ("rows: 1\n   cols: 2\n   dt: i\n   data: [1, 2.5]", r"2\.5 does not fit .*\(int32\)"),
        ("rows: 1\n   cols: 1\n   dt: f\n   data: [1e300]", r"1e\+300 does not fit .*\(float32\)"),
    ],
)
def test_yaml_matrix_sizes_and_values_are_checked(tmp_path, matrix, match):
    path = tmp_path / "m.yml"
    path.write_text(f"%YAML:1.0\nm: !!opencv-matrix\n   {matrix}\n")
    with pytest.raises(FileFormatError, match=match):
        read_opencv_storage(path)


def test_yaml_image_size_fields_are_checked(tmp_path):
    head = "%YAML:1.0\ncamera_matrix:\n  rows: 3\n  cols: 3\n  data: ["
    head += ", ".join(str(v) for v in K.ravel()) + "]\n"
    for w, h in ((".inf", "480"), ("640", ".nan"), ("640.5", "480"), ("-1", "480")):
        path = tmp_path / "cam.yml"
        path.write_text(head + f"image_width: {w}\nimage_height: {h}\n")
        with pytest.raises(FileFormatError, match=r"cam\.yml: field 'image_size'"):
            load_calibration(path)
    ros = tmp_path / "ros.yml"  # ROS {rows, cols, data} with a non-integer size
    ros.write_text("camera_matrix:\n  rows: .inf\n  cols: 3\n  data: [1, 2, 3]\n")
    with pytest.raises(FileFormatError, match="'K': rows x cols"):
        load_calibration(ros)


# issue 25: bytes, None or an int for the path raised TypeError, a NUL byte ValueError;
# paths now go through the shared path check (InputError), a missing file is a
# FileFormatError, and bytes paths are read
def test_issue25_read_opencv_storage_paths(tmp_path):
    f = tmp_path / "c.yml"
    f.write_text("%YAML:1.0\nimage_width: 640\n")
    assert read_opencv_storage(bytes(f)) == {"image_width": 640}
    cases = [
        (None, "must be a file or folder path"),
        (3, "must be a file or folder"),
        (str(f) + "\x00.yml", "NUL byte"),
        ("n" * 300, "file name too long"),
    ]
    for bad, match in cases:
        with pytest.raises(InputError, match=match):
            read_opencv_storage(bad)
    with pytest.raises(FileFormatError, match="is a folder"):
        read_opencv_storage(tmp_path)
    with pytest.raises(FileFormatError, match="no such file"):
        read_opencv_storage(tmp_path / "missing.yml")
