"""The predictors' loaders under hostile run folders and checkpoints (issue 47): the
entries a checkpoint stores for prediction (calibration, tiling, input normalisation,
canvas, kind), a folder where a file belongs and impossible names give a typed
robopercept error, never AttributeError, ValueError, TypeError or OSError."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError, RoboperceptError  # noqa: E402
from robopercept.nn.predict import load_image_predictor, load_predictor  # noqa: E402
from robopercept.nn.predict_class import load_class_predictor  # noqa: E402
from robopercept.nn.shipped import resolve_model, shipped_model_path  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def fcos():
    return torch.load(shipped_model_path("detect", "fcos"), weights_only=True)


def _run(tmp_path, state, name="model.pt"):
    d = tmp_path / "run"
    d.mkdir()
    torch.save(state, d / name)
    return d


@pytest.mark.parametrize(
    ("entries", "match"),
    [
        ({"calibration": [1]}, "'calibration' must be a dict"),
        ({"calibration": {"score_thresh": "x"}}, "score_thresh must be a number"),
        ({"calibration": {"score_thresh": float("nan")}}, "score_thresh must be a number"),
        ({"calibration": {"score_thresh": 0.5, "match_median": 7}}, "match_median"),
        ({"calibration": {"f1": 0.5}}, "score_thresh must be a number"),
        ({"tile": "x"}, "'tile' must be a window side"),
        ({"tile": 10**30}, "'tile' must be a window side"),
        ({"tile": 64, "tile_overlap": 64}, "'tile_overlap'"),
        ({"tile": 64, "tile_overlap": "x"}, "'tile_overlap'"),
        ({"input_normalize": {"percentile": 5}}, "'input_normalize'"),
        ({"input_normalize": {"percentile": [99, 1]}}, "'input_normalize'"),
        ({"input_normalize": {"percentile": [1, 99], "clip": "yes"}}, "'input_normalize'"),
        ({"input_colour": 3}, "'input_colour'"),
        ({"canvas": "ab"}, "'canvas'"),
        ({"canvas": [128]}, "'canvas'"),
        ({"tta": "flips"}, "'tta' must be a test-time augmentation"),
        ({"tta": {"views": "flips"}}, "'tta' must be a test-time augmentation"),
        ({"tta": {"views": "spin", "scales": [1], "iou_thresh": None}}, "'tta'.*one of identity"),
        ({"tta": {"views": "flips", "scales": [0], "iou_thresh": None}}, "'tta'.*in .0.25, 4"),
        ({"tta": {"views": "flips", "scales": [1, 1], "iou_thresh": None}}, "'tta'"),
        ({"tta": {"views": "flips", "scales": [1], "iou_thresh": 2}}, "'tta'.*None or in"),
    ],
)
def test_damaged_prediction_entries(tmp_path, fcos, entries, match):
    run = _run(tmp_path, {**fcos, **entries})
    for load in (lambda: load_image_predictor("detect", run), lambda: load_predictor(run)):
        with pytest.raises(FileFormatError, match=match) as err:
            load()
        assert "model.pt" in str(err.value)


def test_the_shipped_entries_pass(fcos, tmp_path):
    assert load_predictor(_run(tmp_path, fcos)).kind == "detect"


@pytest.mark.parametrize("kind", [["fcos"], {"a": 1}, 3])
def test_an_unhashable_kind_is_not_a_type_error(tmp_path, fcos, kind):
    with pytest.raises(RoboperceptError, match="not a model robopercept saved"):
        load_predictor(_run(tmp_path, {**fcos, "kind": kind}))


@pytest.mark.parametrize("name", ["model.pt", "checkpoint.best.pt"])
def test_a_folder_where_the_checkpoint_belongs(tmp_path, name):
    (tmp_path / "run" / name).mkdir(parents=True)
    for load in (
        lambda: load_predictor(tmp_path / "run"),
        lambda: load_image_predictor("detect", tmp_path / "run"),
        lambda: load_class_predictor("cloud", tmp_path / "run"),
        lambda: load_class_predictor("classify", tmp_path / "run"),
    ):
        with pytest.raises(RoboperceptError):
            load()


@pytest.mark.parametrize("content", [b"", b"garbage", b"PK\x03\x04broken"])
def test_a_checkpoint_that_is_not_one(tmp_path, content):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.pt").write_bytes(content)
    with pytest.raises(FileFormatError, match="not a readable torch checkpoint"):
        load_predictor(tmp_path / "run")
    with pytest.raises(FileFormatError, match="not a readable torch checkpoint"):
        load_class_predictor("cloud", tmp_path / "run")


def test_a_name_too_long_for_the_file_system():
    with pytest.raises(InputError, match="too long"):
        resolve_model("detect", "x" * 5000)
    with pytest.raises(InputError, match="too long"):
        load_predictor("x" * 5000)


@pytest.mark.parametrize("model", [3, float("nan"), ["trees"]])
def test_domain_line_of_something_that_is_not_a_model(model):
    from robopercept.nn.shipped import domain_line

    with pytest.raises(InputError, match="model must be a shipped name"):
        domain_line("detect", model)


@pytest.mark.parametrize(
    ("command", "kind", "change", "says"),
    [
        ("detect", "detect", lambda s: s["model"].popitem(), "not of this model"),
        ("segment", "segment", lambda s: s.update(settings=[1]), "not a dict"),
        ("pose", "pose", lambda s: s["settings"].update(blocks=2**31), "blocks must be at most"),
        ("detect", "detect", lambda s: s.update(calibration=[1]), "'calibration'"),
    ],
)
def test_the_commands_exit_1_on_a_hostile_checkpoint(tmp_path, capsys, command, kind, change, says):
    """R40, R41, R47 through the command line: exit 1 with the file named, never 70."""
    import numpy as np

    from robopercept.cli.main import main
    from robopercept.imaging import write_image

    state = torch.load(shipped_model_path(kind), weights_only=True)
    change(state)
    bad = tmp_path / "bad.pt"
    torch.save(state, bad)
    img = write_image(tmp_path / "a.png", np.zeros((32, 32, 3), np.uint8))
    assert main(["nn", command, str(img), "--model", str(bad), "-o", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err
    assert says in err and "bad.pt" in err


def test_a_keypoint_rcnn_with_a_skeleton_is_a_detector(tmp_path):
    from robopercept.nn.detection.zoo import build_detector, save_detector
    from robopercept.nn.skeleton import MPII_16

    net = build_detector("keypointrcnn", 2, width=4)
    p = save_detector(
        tmp_path / "k.pt", net, "keypointrcnn", {"width": 4}, ["a", "b"], skeleton=MPII_16.to_dict()
    )
    assert load_predictor(p, device="cpu").kind == "detect"
    assert load_predictor(shipped_model_path("pose", "hrnet"), device="cpu").kind == "pose"
