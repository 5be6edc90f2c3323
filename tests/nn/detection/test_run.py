"""Tests of robopercept.nn.detection.run: the data of ``--data`` (errors naming the
flags), a tiny training run writing its folder (and refusing, resuming, keeping the
history on Ctrl-C), and the evaluation of a run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import ArgumentError, InputError, RunExistsError  # noqa: E402
from robopercept.imaging import read_image, write_image  # noqa: E402
from robopercept.nn.coco.dataset import write_coco_json  # noqa: E402
from robopercept.nn.detection.run import (  # noqa: E402
    RUN_FILES,
    DetectionTrainResult,
    TrainConfig,
    evaluate_run,
    load_detection_data,
    train_run,
)
from robopercept.nn.detection.synthetic import (  # noqa: E402
    digits_detection_set,
    procedural_detection_set,
    single_digit_set,
)
from robopercept.nn.detection.train import evaluate_detector  # noqa: E402
from robopercept.nn.detection.zoo import load_detector  # noqa: E402
from tests.cli.nn_runs import ctrl_c, ctrl_c_after_first_epoch, weights  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

#: a tiny run: 2 epochs of a width-4 FCOS on 3 training canvases of 64 x 64
DATA = {"images": 4, "size": (64, 64)}
CFG = TrainConfig(epochs=2, batch_size=2, lr=3e-3, seed=0, device="cpu")


def _tiny(out: Path, **kwargs) -> DetectionTrainResult:
    return train_run("digits", out, width=4, config=CFG, progress=False, **DATA, **kwargs)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> DetectionTrainResult:
    torch.set_num_threads(1)
    return _tiny(tmp_path_factory.mktemp("detrun") / "run")


# --------------------------------------------------------------------------- data


def test_builtin_sets_are_the_generators_split_80_20():
    train, val = load_detection_data("shapes", images=10, size=(48, 48), seed=3)
    whole = procedural_detection_set(10, (48, 48), rng=3)
    ref_train, ref_val = whole.split((0.8, 0.2), rng=3)
    assert (len(train), len(val)) == (8, 2)
    assert train.image_ids == ref_train.image_ids and val.image_ids == ref_val.image_ids
    np.testing.assert_array_equal(val.images[0], ref_val.images[0])
    _, val = load_detection_data("digits", images=5, size=(64, 64), seed=0)
    ref = digits_detection_set(5, (64, 64), rng=0).split((0.8, 0.2), rng=0)[1]
    np.testing.assert_array_equal(val.images[0], ref.images[0])
    # the localizer gets one digit per canvas, for training and evaluation alike
    _, val = load_detection_data("digits", images=5, size=(64, 64), seed=0, model="localizer")
    ref = single_digit_set(5, (64, 64), rng=0).split((0.8, 0.2), rng=0)[1]
    np.testing.assert_array_equal(val.images[0], ref.images[0])


def _coco(tmp_path: Path, n: int) -> Path:
    ds = digits_detection_set(n, (64, 64), rng=1)
    coco = ds.to_coco()
    for im, rec in zip(ds.images, coco.images, strict=True):
        write_image(tmp_path / rec.file_name, (np.asarray(im) * 255).round().astype(np.uint8))
    return write_coco_json(coco, tmp_path / "gt.json")


def test_coco_file_is_split_for_training_and_whole_for_evaluation(tmp_path):
    f = _coco(tmp_path, 5)
    train, val = load_detection_data(f, seed=0)
    assert (len(train), len(val)) == (4, 1)
    a, b = load_detection_data(str(f), evaluate=True)
    assert a is b and len(a) == 5 and a.classes == tuple(str(d) for d in range(10))


@pytest.mark.parametrize(
    ("data", "kwargs", "flag"),
    [
        ("foo", {}, "--data: expects one of shapes, digits, trees, a COCO .json file or a folder"),
        ("missing.json", {}, "--data: COCO file missing.json does not exist"),
        ("trees", {}, "--images-dir: --data trees needs the DeepForest NEON folder"),
        ("trees", {"images_dir": "no_such_folder"}, "--images-dir"),
        ("shapes", {"images": 1}, "--images: give at least 2"),
        ("digits", {"images": 1}, "--images: give at least 2"),
    ],
)
def test_data_errors_name_the_flag(data, kwargs, flag, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ArgumentError, match=flag):
        load_detection_data(data, **kwargs)


def test_coco_errors_are_argument_errors(tmp_path):
    one = tmp_path / "one"
    one.mkdir()
    f = _coco(one, 1)
    with pytest.raises(ArgumentError, match="has 1 image; training needs at least 2"):
        load_detection_data(f)
    assert len(load_detection_data(f, evaluate=True)[1]) == 1
    with pytest.raises(ArgumentError, match=r"--images-dir: .* is not a folder"):
        load_detection_data(f, images_dir=tmp_path / "no")
    (one / "000001.png").unlink()
    with pytest.raises(ArgumentError, match=r"--images-dir: .*000001.png"):
        load_detection_data(f, evaluate=True)
    empty = tmp_path / "empty.json"
    empty.write_text(json.dumps({"images": [], "categories": [], "annotations": []}))
    with pytest.raises(ArgumentError, match="lists no images"):
        load_detection_data(empty)


def test_bad_settings_are_input_errors():
    with pytest.raises(InputError, match="model"):
        load_detection_data("shapes", model="yolo")
    with pytest.raises(InputError, match="seed"):
        load_detection_data("shapes", seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="images"):
        load_detection_data("shapes", images=0)


# --------------------------------------------------------------------------- train


def test_train_run_writes_the_run_folder(run):
    out = run.out_dir
    assert set(RUN_FILES) | {"checkpoint.pt", "checkpoint.best.pt"} <= {
        p.name for p in out.iterdir()
    }
    assert run.files == {name: out / name for name in RUN_FILES}
    assert run.checkpoint == out / "checkpoint.pt"
    assert run.model == "fcos" and run.data == "digits"
    assert len(run.history.losses) == 2 and run.best_epoch == run.history.best_epoch >= 1
    assert run.seconds == pytest.approx(sum(run.history.seconds))
    assert json.loads((out / "metrics.json").read_text()) == run.metrics
    assert run.metrics["stats"] == run.evaluation.stats.tolist()
    assert run.metrics["split"] == "validation" and run.metrics["images"] == 1
    hist = json.loads((out / "history.json").read_text())
    assert set(hist) == {"losses", "seconds", "val_AP", "best_epoch"}
    assert hist["best_epoch"] == run.best_epoch and len(hist["losses"]) == 2
    printed = run.to_dict()
    assert printed["epochs"] == 2 and printed["files"]["model.pt"] == str(out / "model.pt")
    assert json.loads(json.dumps(printed)) == printed  # JSON-ready
    assert read_image(out / "pr_curves.png").shape[:2] == (1000, 1600)
    # one 64 x 64 validation image, enlarged 12 times to 768 (issue 48: read at 1080p),
    # under the legend and its title
    samples = read_image(out / "samples.png")
    assert samples.shape[1] == 768 and 768 < samples.shape[0] < 900
    # model.pt holds the kept weights: the metrics are its own on the validation split
    model, info = load_detector(out / "model.pt")
    assert info["kind"] == "fcos" and info["settings"] == {"width": 4}
    assert info["images"] == 4 and info["size"] == [64, 64] and info["seed"] == 0
    val = load_detection_data("digits", **DATA, seed=0)[1]
    assert evaluate_detector(model, val).stats.tolist() == run.metrics["stats"]


def test_train_run_refuses_an_existing_run(run):
    before = (run.out_dir / "checkpoint.pt").read_bytes()
    with pytest.raises(RunExistsError, match=r"--resume.*--overwrite"):
        _tiny(run.out_dir)
    with pytest.raises(InputError, match="exclude each other"):
        _tiny(run.out_dir, resume=True, overwrite=True)
    assert (run.out_dir / "checkpoint.pt").read_bytes() == before


def test_train_run_interrupted_keeps_history_and_resumes(run, tmp_path):
    out = tmp_path / "part"
    with ctrl_c_after_first_epoch() as written, pytest.raises(KeyboardInterrupt):
        _tiny(out)
    assert written == [1] and (out / "checkpoint.pt").exists()
    assert not (out / "model.pt").exists()
    hist = json.loads((out / "history.json").read_text())  # the complete epoch's
    assert len(hist["losses"]) == 1 and hist["losses"][0] == run.history.losses[0]
    res = _tiny(out, resume=True)
    assert res.history.losses == run.history.losses
    a, b = weights(run.out_dir / "model.pt"), weights(out / "model.pt")
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert res.metrics["stats"] == run.metrics["stats"]


def test_a_signal_while_the_model_is_saved_leaves_the_whole_history(run, tmp_path, monkeypatch):
    # the faults campaign's SIGTERM after the last epoch, while model.pt was written
    from robopercept.nn.detection import run as det_run

    monkeypatch.setattr(det_run, "save_detector", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        _tiny(tmp_path / "part")
    history = json.loads((tmp_path / "part" / "history.json").read_text())
    assert history["losses"] == run.history.losses


def test_train_run_bad_settings(tmp_path):
    with pytest.raises(InputError, match="model"):
        train_run("digits", tmp_path / "r", model="yolo")
    with pytest.raises(InputError, match="ema"):
        train_run("digits", tmp_path / "r", ema=1.5)
    with pytest.raises(InputError, match="config must be a TrainConfig"):
        train_run("digits", tmp_path / "r", config={"epochs": 1})  # type: ignore[arg-type]
    with pytest.raises(ArgumentError, match="--data"):
        train_run("foo", tmp_path / "r")
    with pytest.raises(ArgumentError, match="--images-dir"):
        train_run("trees", tmp_path / "r", images_dir="")
    assert not (tmp_path / "r").exists()  # refused before the folder is made


# --------------------------------------------------------------------------- evaluate


def test_evaluate_run_equals_the_run_metrics(run, tmp_path):
    res = evaluate_run(run.out_dir, "digits", **DATA, seed=0)
    assert res.evaluation.stats.tolist() == run.metrics["stats"]
    assert res.images == 1 and res.tta is None and res.files == {}
    assert res.model == str(run.out_dir) and res.data == "digits"
    printed = res.to_dict()
    assert list(printed) == ["model", "data", "tta", "images", "metrics", "stats"]
    # the model file itself, with the pictures written
    res2 = evaluate_run(str(run.out_dir / "model.pt"), "digits", **DATA, out_dir=tmp_path / "e")
    assert res2.model == str(run.out_dir / "model.pt")
    assert json.loads((tmp_path / "e" / "metrics.json").read_text()) == res2.metrics
    assert res2.files == {
        "metrics.json": tmp_path / "e" / "metrics.json",
        "pr_curves.png": tmp_path / "e" / "pr_curves.png",
    }
    assert (tmp_path / "e" / "pr_curves.png").is_file()


def test_evaluate_run_with_tta_equals_the_wrapper(run):
    from robopercept.nn.detection.tta import TestTimeAugmentation

    res = evaluate_run(run.out_dir, "digits", **DATA, tta="hflip")
    model, _ = load_detector(run.out_dir / "model.pt")
    val = load_detection_data("digits", **DATA)[1]
    ref = evaluate_detector(TestTimeAugmentation(model, "hflip"), val)
    assert res.tta == "hflip" and res.metrics["tta"] == "hflip"
    assert res.evaluation.stats.tolist() == ref.stats.tolist()


def test_evaluate_run_errors(run, tmp_path):
    with pytest.raises(ArgumentError, match=r"RUN_OR_MODEL: .* does not exist"):
        evaluate_run(tmp_path / "no_run", "digits", **DATA)
    with pytest.raises(ArgumentError, match="--data"):  # the data is checked first
        evaluate_run(tmp_path / "no_run", "foo")
    with pytest.raises(InputError, match="not among the model's classes"):
        evaluate_run(run.out_dir, "shapes", images=4, size=(64, 64))
    with pytest.raises(InputError, match="tta"):
        evaluate_run(run.out_dir, "digits", tta="rotations")
