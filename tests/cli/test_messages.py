"""Messages in the user's terms and honest exit codes (issue 22, "a new user's first
hour").

One test per class of message: a folder where a file is expected, flag names instead of
Python parameters, no NumPy reprs, the right units, no advice to load pickles unsafely,
output names that do not fit their content (refused before any work, exit code 2), a
run that processed nothing (exit code 1) and output lists that name only files written.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept._checks import check_extension, check_file, plain_repr
from robopercept.cli._args import flag_errors, in_flags
from robopercept.cli.main import build_parser, main
from robopercept.errors import ArgumentError, FileFormatError, InputError
from robopercept.imaging import SnapshotVideoWriter, VideoWriter, write_image
from tests.conftest import data_path


def _folder(path, frames):
    path.mkdir()
    for i, f in enumerate(frames):
        write_image(path / f"{i:06d}.png", f)
    return path


def _noise_frames(n, shape=(48, 64, 3), seed=0):
    rng = np.random.default_rng(seed)
    return [rng.integers(0, 256, shape, dtype=np.uint8) for _ in range(n)]


def _error(capsys) -> str:
    """The one stderr line of a failed command (and no traceback)."""
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err
    return lines[-1]


# ------------------------------------------------------- a folder where a file is expected
def test_check_file_tells_a_folder_from_a_missing_file(tmp_path):
    with pytest.raises(FileFormatError, match=r"is a folder; give an image file$"):
        check_file(tmp_path, "an image file")
    with pytest.raises(FileFormatError, match=r"nothing\.png: no such file$"):
        check_file(tmp_path / "nothing.png", "an image file")
    f = tmp_path / "a.txt"
    f.write_text("x")
    assert check_file(f, "a text file") == f


@pytest.mark.parametrize(
    ("command", "folder_says"),
    [
        (["edges"], "is a folder; give an image file"),
        (["calibrate", "--board", "9x6", "--quiet"], "is a folder; give the image files in it"),
        (["cloud"], "is a folder; give a point cloud file (.ply or .pcd)"),
    ],
)
def test_folder_and_missing_file_are_told_apart(tmp_path, capsys, command, folder_says):
    name, *flags = command
    folder = tmp_path / "photos"
    folder.mkdir()
    assert main([name, str(folder), *flags]) == 1
    err = _error(capsys)
    assert folder_says in err and str(folder) in err
    assert "no such file" not in err and "extension" not in err
    missing = tmp_path / ("absent.ply" if name == "cloud" else "absent.png")
    assert main([name, str(missing), *flags]) == 1
    err = capsys.readouterr().err
    assert f"{missing}: no such file" in err and "is a folder" not in err


def test_other_readers_tell_a_folder_too(tmp_path, capsys):
    """The CSV of `learn`, the model of `detect-hog` and the det.txt of `track`."""
    image = write_image(tmp_path / "a.png", _noise_frames(1)[0])
    assert main(["learn", "cluster", str(tmp_path)]) == 1
    assert "is a folder; give a CSV file" in _error(capsys)
    assert main(["detect-hog", str(image), "--model", str(tmp_path)]) == 1
    assert "is a folder; give a model file (.npz" in _error(capsys)
    seq = _folder(tmp_path / "seq", _noise_frames(2))
    out = tmp_path / "t.mp4"
    assert main(["track", str(seq), "--detections", str(tmp_path), "-o", str(out), "--quiet"]) == 1
    assert "is a folder; give a MOTChallenge text file" in _error(capsys)


@pytest.mark.realdata
def test_calibrate_on_the_real_photo_folder_asks_for_its_images(capsys):
    """The first-hour mistake: the folder of the OpenCV chessboard photos, not its files."""
    folder = data_path("calibration", "opencv_chessboard_stereo")
    assert main(["calibrate", str(folder), "--board", "9x6", "--quiet"]) == 1
    assert f"{folder} is a folder; give the image files in it (e.g. {folder}/*.png)" in _error(
        capsys
    )


@pytest.mark.realdata
def test_cloud_on_the_real_bunny_folder(capsys):
    folder = data_path("pointcloud", "stanford_bunny")
    assert main(["cloud", str(folder)]) == 1
    err = _error(capsys)
    assert "is a folder; give a point cloud file" in err and "unknown" not in err


# --------------------------------------------------------- flag names, not Python names
def test_in_flags_hand_cases():
    flags = {"sigma": "--sigma", "feature": "--feature", "cell_size": "--cell"}
    assert in_flags("sigma must be in [0, inf]; got -1.0", flags) == (
        "--sigma must be in [0, inf]; got -1.0"
    )
    assert in_flags("use feature='rgb' or lower", flags) == "use --feature rgb or lower"
    assert in_flags("cell_size must be >= 1; got 0", flags) == "--cell must be >= 1; got 0"
    # whole words only: another parameter that ends in a mapped name keeps it, and a
    # flag already written is not rewritten again
    assert in_flags("block_sigma and --sigma", flags) == "block_sigma and --sigma"
    assert in_flags("got low=200, high=100", {"low": "--low", "high": "--high"}) == (
        "got --low 200, --high 100"
    )
    assert in_flags("nothing to do", flags) == "nothing to do"


def test_flag_errors_keeps_the_error_class():
    # an ArgumentError (exit 2) renamed into flags stays an ArgumentError, not exit 1
    with pytest.raises(ArgumentError, match=r"^--scheduler must be") as info:
        with flag_errors(scheduler="--scheduler"):
            raise ArgumentError("scheduler must be tcp://HOST:PORT")
    assert type(info.value) is ArgumentError
    with pytest.raises(InputError, match=r"^--sigma") as info2:
        with flag_errors(sigma="--sigma"):
            raise InputError("sigma must be > 0")
    assert type(info2.value) is InputError


def test_meanshift_feature_advice_names_the_flags(tmp_path, capsys):
    """A grey box has no hue: the advice names --feature rgb and --min-saturation, the
    flags the user can type, and following it works."""
    grey = [np.full((48, 64, 3), v, np.uint8) for v in (120, 125, 130)]
    seq = _folder(tmp_path / "seq", grey)
    out = tmp_path / "m.mp4"
    args = ["meanshift", str(seq), "--box", "10,10,20,20", "-o", str(out), "--quiet"]
    assert main(args) == 1
    err = _error(capsys)
    assert "--feature rgb" in err and "--min-saturation" in err and "--box" in err
    assert "feature=" not in err and "min_saturation" not in err
    assert not out.exists()
    assert main([*args, "--feature", "rgb"]) == 0
    assert main([*args, "--min-saturation", "0"]) == 0


@pytest.mark.parametrize(
    ("args", "flag", "param"),
    [
        (["edges", "--sigma", "-1"], "--sigma must be in [0, inf]", "sigma must"),
        (["hog", "--cell", "0"], "--cell must be >= 1; got 0", "cell_size"),
        (["features", "--quality", "3"], "--quality must be in (0, 1]", "threshold"),
    ],
)
def test_library_refusals_name_the_flag(tmp_path, capsys, args, flag, param):
    assert main([*args, "-o", str(tmp_path / "out.png")]) == 1
    err = _error(capsys)
    assert flag in err
    assert f" {param}" not in err and not err.endswith(param)
    assert not (tmp_path / "out.png").exists()


def test_bgsub_k_is_in_standard_deviations(tmp_path, capsys):
    seq = _folder(tmp_path / "seq", _noise_frames(2))
    args = ["bgsub", str(seq), "--k", "-1", "-o", str(tmp_path / "b.mp4"), "--quiet"]
    assert main(args) == 1
    assert "--k must be a positive number (standard deviations); got -1.0" in _error(capsys)


# ------------------------------------------------------------------------ no NumPy reprs
def test_plain_repr_hand_cases():
    assert plain_repr((np.float64(1000.0), np.int64(3))) == "(1000.0, 3)"
    assert plain_repr(np.array([[1, 2]])) == "[[1, 2]]"
    assert plain_repr([np.float32(0.5), "a"]) == "[0.5, 'a']"
    assert plain_repr("rgb") == "'rgb'"


def test_box_outside_the_image_has_no_numpy_repr(tmp_path, capsys):
    seq = _folder(tmp_path / "seq", _noise_frames(2))
    args = ["meanshift", str(seq), "--box", "1000,1000,10,10", "-o", str(tmp_path / "m.mp4")]
    assert main(args) == 1
    err = _error(capsys)
    assert "--box x, y, w, h = 1000, 1000, 10, 10 is not inside the 64x48 image" in err
    assert "np." not in err and "float64" not in err


# ------------------------------------------------------------ no advice to unpickle
@pytest.mark.parametrize("name", ["model.csv", "model.npy"])
def test_detect_hog_model_that_is_not_a_model(tmp_path, capsys, name):
    model = tmp_path / name
    if name.endswith(".csv"):
        model.write_text("a,b\n1,2\n")
    else:
        np.save(model, np.zeros(3))
    image = write_image(tmp_path / "a.png", _noise_frames(1)[0])
    out = tmp_path / "d.png"
    assert main(["detect-hog", str(image), "--model", str(model), "-o", str(out)]) == 1
    err = _error(capsys)
    assert f"{model} is not a robopercept HOG model file (.npz written by `robopercept " in err
    assert "pickle" not in err and "unsafe" not in err
    assert not out.exists()


# ---------------------------------------------------------------- usage: parser and flags
def test_mistyped_command_gets_did_you_mean(capsys):
    assert main(["edgs"]) == 2
    err = _error(capsys)
    assert "did you mean 'edges'?" in err


def test_demo_takes_max_frames():
    args = build_parser().parse_args(["demo", "--max-frames", "2"])
    assert args.frames == 2
    assert build_parser().parse_args(["demo", "--frames", "3"]).frames == 3  # the alias


def test_demo_max_frames_must_be_positive(capsys):
    assert main(["demo", "--max-frames", "0"]) == 2
    assert "--max-frames" in _error(capsys)


# ------------------------------------------- outputs that do not fit: refused before work
def test_video_writer_refuses_a_non_video_name_before_writing(tmp_path):
    for name in ("x.png", "x"):
        with pytest.raises(InputError, match=r"a video needs one of the extensions \.avi"):
            VideoWriter(tmp_path / name)
        with pytest.raises(InputError, match=r"\.mp4"):
            SnapshotVideoWriter(tmp_path / name, 10.0)
    assert list(tmp_path.iterdir()) == []
    assert VideoWriter(tmp_path / "x.MKV").path.name == "x.MKV"  # any case


def test_check_extension_hand_cases(tmp_path):
    assert check_extension("a.PLY", {".ply", ".pcd"}, "a point cloud").name == "a.PLY"
    with pytest.raises(InputError, match=r"a\.npy: x needs the extension \.npz; got '\.npy'"):
        check_extension("a.npy", {".npz"}, "x")
    with pytest.raises(InputError, match="got no extension"):
        check_extension("a", {".npz"}, "x")


def test_bgsub_png_output_is_a_usage_error_before_any_work(tmp_path, capsys):
    """-o x.png would get an H.264 stream under an image's name: refused while parsing,
    so even a missing input is not reached (exit code 2, the flag and the extensions)."""
    out = tmp_path / "x.png"
    assert main(["bgsub", str(tmp_path / "absent.avi"), "-o", str(out)]) == 2
    err = _error(capsys)
    assert "argument -o/--output" in err and ".mp4" in err and "got '.png'" in err
    assert "absent.avi" not in err
    assert not out.exists()


@pytest.mark.realdata
def test_bgsub_png_output_refused_on_a_real_video(tmp_path, capsys):
    video = data_path("video", "vot_bag")
    out = tmp_path / "x.png"
    assert main(["bgsub", str(video), "-o", str(out)]) == 2
    assert "a video needs one of the extensions" in _error(capsys)
    assert not out.exists() and not (tmp_path / "x_000000.png").exists()


def test_flow_output_kind_follows_its_inputs(tmp_path, capsys):
    a = write_image(tmp_path / "a.png", _noise_frames(1)[0])
    seq = _folder(tmp_path / "seq", _noise_frames(2))
    assert main(["flow", str(a), str(a), "-o", str(tmp_path / "f.mp4")]) == 2
    assert "-o/--output" in (err := _error(capsys)) and "an image needs" in err
    assert main(["flow", str(seq), "-o", str(tmp_path / "f.png"), "--quiet"]) == 2
    assert "-o/--output" in (err := _error(capsys)) and "a video needs" in err
    assert not (tmp_path / "f.mp4").exists() and not (tmp_path / "f.png").exists()


@pytest.mark.parametrize(
    "args",
    [
        ["stereo", "L.png", "R.png", "--max-disparity", "8", "--npy", "disp"],
        ["stereo", "L.png", "R.png", "--max-disparity", "8", "--ply", "pts.txt"],
        ["hog", "-o", "hog.mp4"],
        ["cloud", "in.ply", "--image", "cloud.mp4"],
    ],
)
def test_other_outputs_are_checked_while_parsing(args, capsys):
    # the inputs do not exist: the output name is refused first
    assert main(args) == 2
    err = _error(capsys)
    assert "needs" in err and "extension" in err


def test_a_folder_as_a_results_file_is_refused_before_work(tmp_path, capsys):
    seq = _folder(tmp_path / "seq", _noise_frames(2))
    args = ["meanshift", str(seq), "--box", "1,1,5,5", "--results", str(tmp_path)]
    assert main([*args, "-o", str(tmp_path / "m.mp4")]) == 2
    assert "is a folder; give a file name" in _error(capsys)
    assert not (tmp_path / "m.mp4").exists()


# --------------------------------------------------- nothing processed: not a success
@pytest.mark.parametrize(
    "command",
    [
        ["bgsub"],
        ["flow"],
        ["meanshift", "--box", "1,1,5,5", "--results", "{tmp}/boxes.csv"],
        ["track", "--results", "{tmp}/tracks.txt"],
    ],
)
def test_all_frames_corrupt_exits_1_and_lists_nothing(tmp_path, capsys, command):
    seq = tmp_path / "seq"
    seq.mkdir()
    for i in range(3):
        (seq / f"{i:06d}.png").write_bytes(b"not a png at all")
    out = tmp_path / "o.mp4"
    name, *flags = (c.replace("{tmp}", str(tmp_path)) for c in command)
    assert main([name, str(seq), *flags, "-o", str(out), "--snapshot", "0", "--quiet"]) == 1
    captured = capsys.readouterr()
    assert "wrote             nothing" in captured.out
    assert "skipped 3" in captured.out
    last = captured.err.strip().splitlines()[-1]
    assert last == (
        f"robopercept: error: no frame of {seq} could be read (3 skipped as unreadable): "
        "nothing was processed"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]  # nothing written


def test_only_files_written_are_listed(tmp_path, capsys):
    """A snapshot past the last frame is not written, so not listed; the masks are
    listed with their count; one corrupt frame is skipped, counted, and the run
    succeeds."""
    frames = _noise_frames(4)
    seq = _folder(tmp_path / "seq", frames)
    (seq / "000002.png").write_bytes(b"corrupt")
    out = tmp_path / "b.mp4"
    masks = tmp_path / "masks"
    args = ["bgsub", str(seq), "--method", "diff", "-o", str(out), "--masks", str(masks)]
    assert main([*args, "--snapshot", "1", "--snapshot", "99", "--quiet"]) == 0
    stdout = capsys.readouterr().out
    wrote = next(ln for ln in stdout.splitlines() if ln.startswith("wrote"))
    listed = wrote.split(maxsplit=1)[1].split(", ")
    assert listed == [str(out), str(tmp_path / "b_000001.png"), f"{masks}/ (3 masks)"]
    assert out.exists() and (tmp_path / "b_000001.png").exists()
    assert not (tmp_path / "b_000099.png").exists()
    assert sorted(p.name for p in masks.iterdir()) == ["000000.png", "000001.png", "000003.png"]
    assert "skipped 1" in stdout


def test_blobs_json_names_the_overlay_it_wrote(tmp_path, capsys):
    img = np.zeros((40, 40), np.uint8)
    img[10:20, 10:20] = 255
    src = write_image(tmp_path / "m.png", img)
    overlay = tmp_path / "o.png"
    assert main(["blobs", str(src), "--json", "-o", str(overlay)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["overlay"] == str(overlay) and overlay.exists()
    assert main(["blobs", str(src), "--json"]) == 0
    assert "overlay" not in json.loads(capsys.readouterr().out)
