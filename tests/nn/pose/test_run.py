"""The pose run (issue 45): :func:`~robopercept.nn.pose.run.load_pose_data` and its
errors naming the flags, :func:`~robopercept.nn.pose.run.train_run` writing the run
folder (tiny DeepPose runs with a cascade stage: a few 64 x 64 figures, 2 epochs),
resuming it to the uninterrupted run's model (stages included) after Ctrl-C in the
network's epochs or in the stages, and :func:`~robopercept.nn.pose.run.evaluate_run`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError, RunExistsError  # noqa: E402
from robopercept.nn.pose import run as pose_run  # noqa: E402
from robopercept.nn.pose.data import pose_sets  # noqa: E402
from robopercept.nn.pose.evaluate import evaluate_pose  # noqa: E402
from robopercept.nn.pose.networks import build_pose_model, load_pose_model, save_pose_model  # noqa: E402
from robopercept.nn.pose.run import (  # noqa: E402
    RUN_FILES,
    evaluate_run,
    load_pose_data,
    model_path,
    train_run,
)
from robopercept.nn.skeleton import COCO_17  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402
from tests.cli.nn_runs import ctrl_c, ctrl_c_after_first_epoch  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

DATA = {"images": 8, "size": (64, 64)}
CFG = TrainConfig(epochs=2, batch_size=4, lr=3e-3, seed=0, device="cpu")
DEEPPOSE = {"model": "deeppose", "width": 4, "stages": 1, "config": CFG, "progress": False}


def _state(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


def _same_model(a: Path, b: Path) -> None:
    """The network and the cascade stages of two model.pt files are equal."""
    sa, sb = _state(a), _state(b)
    assert sa["model"].keys() == sb["model"].keys()
    for k in sa["model"]:
        assert torch.equal(sa["model"][k], sb["model"][k]), k
    assert len(sa["refiners"]) == len(sb["refiners"]) == 1
    for ra, rb in zip(sa["refiners"], sb["refiners"], strict=True):
        assert ra["settings"] == rb["settings"]
        for k in ra["state"]:
            assert torch.equal(ra["state"][k], rb["state"][k]), k


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> tuple[Path, pose_run.PoseTrainResult]:
    out = tmp_path_factory.mktemp("pose_run") / "whole"
    torch.set_num_threads(1)
    return out, train_run("figures", out, **DATA, **DEEPPOSE)


# --------------------------------------------------------------------------- data


def test_load_pose_data_is_the_clis_split():
    train, val = load_pose_data("figures", images=4, size=(64, 64), seed=2)
    sets = pose_sets("figures", 4, (64, 64), 2, test_images=1)
    assert (len(train), len(val)) == (4, 1)
    np.testing.assert_array_equal(train.images, sets.train.images)
    np.testing.assert_array_equal(val.keypoints, sets.val.keypoints)


@pytest.mark.parametrize(
    ("kwargs", "flag"),
    [
        ({"data": "coco"}, "--data"),
        ({"images": 1}, "--images"),
        ({"images": 2.5}, "--images"),
        ({"size": (16, 16)}, "--size"),
        ({"size": 64}, "--size"),
        ({"seed": -1}, "--seed"),
    ],
)
def test_load_pose_data_errors_name_the_flag(kwargs, flag):
    args = {"data": "figures", "images": 2, "size": (32, 32), "seed": 0, **kwargs}
    data = args.pop("data")
    with pytest.raises(InputError, match=flag):
        load_pose_data(data, **args)


def test_model_path(whole, tmp_path):
    out, _ = whole
    assert model_path(out) == out / "model.pt"
    assert model_path(str(out / "model.pt")) == out / "model.pt"
    with pytest.raises(InputError, match="RUN_OR_MODEL"):
        model_path(tmp_path / "nothing")


# --------------------------------------------------------------------------- train


def test_train_run_writes_the_run_folder(whole):
    out, res = whole
    assert {p.name for p in out.iterdir()} >= {*RUN_FILES, "checkpoint.pt", "checkpoint.best.pt"}
    assert res.out_dir == out and res.checkpoint == out / "checkpoint.pt"
    assert res.files == {name: out / name for name in RUN_FILES}
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics == res.metrics and metrics["best_epoch"] == res.best_epoch
    assert res.to_dict() == {**metrics, "files": {n: str(out / n) for n in RUN_FILES}}
    assert json.loads((out / "history.json").read_text()) == res.history
    assert len(res.history["stages"]) == 1 and len(res.history["network"]["losses"]) == 2
    model, info = load_pose_model(out / "model.pt")
    assert type(model).__name__ == "DeepPose" and len(info["refiners"]) == 1
    assert (info["data"], info["images"], info["size"], info["seed"]) == ("figures", 8, [64, 64], 0)
    _, val = load_pose_data("figures", **DATA)
    ev = evaluate_pose(model, val, refiners=info["refiners"])
    assert res.evaluation.summary() == ev.summary() == metrics["metrics"]
    assert res.seconds > 0


@pytest.mark.parametrize(
    ("kwargs", "flag"),
    [
        ({"model": "resnet"}, "--model"),
        ({"size": (72, 64)}, "--size"),
        ({"stages": 9}, "--stages"),
        ({"width": 0}, "--width"),
        ({"images": 1}, "--images"),
        ({"config": {"epochs": 1}}, "TrainConfig"),
    ],
)
def test_train_run_refuses_bad_settings_before_any_work(kwargs, flag, tmp_path):
    args = {**DATA, **DEEPPOSE, **kwargs}
    with pytest.raises(InputError, match=flag):
        train_run("figures", tmp_path / "run", **args)
    assert not (tmp_path / "run").exists()


def test_train_run_refuses_an_existing_run(whole, tmp_path):
    out, _ = whole
    before = (out / "checkpoint.pt").read_bytes()
    with pytest.raises(RunExistsError, match="--overwrite"):
        train_run("figures", out, **DATA, **DEEPPOSE)
    assert (out / "checkpoint.pt").read_bytes() == before
    with pytest.raises(InputError, match="nothing to resume"):
        train_run("figures", tmp_path / "new", **DATA, **DEEPPOSE, resume=True)


def test_resume_after_ctrl_c_in_the_network_equals_the_whole_run(whole, tmp_path):
    out = tmp_path / "part"
    with ctrl_c_after_first_epoch() as written, pytest.raises(KeyboardInterrupt):
        train_run("figures", out, **DATA, **DEEPPOSE)
    assert written == [1] and not (out / "model.pt").exists()
    history = json.loads((out / "history.json").read_text())
    assert len(history["network"]["losses"]) == 1 and history["stages"] == []
    res = train_run("figures", out, **DATA, **DEEPPOSE, resume=True)
    _same_model(whole[0] / "model.pt", out / "model.pt")
    assert res.metrics == whole[1].metrics
    assert res.history["network"]["losses"] == whole[1].history["network"]["losses"]


def test_resume_after_ctrl_c_in_the_stages_retrains_them(whole, tmp_path, monkeypatch):
    out = tmp_path / "part"

    with monkeypatch.context() as m:
        m.setattr(pose_run, "train_cascade", ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            train_run("figures", out, **DATA, **DEEPPOSE)
    history = json.loads((out / "history.json").read_text())
    assert len(history["network"]["losses"]) == 2 and history["stages"] == []
    res = train_run("figures", out, **DATA, **DEEPPOSE, resume=True)
    _same_model(whole[0] / "model.pt", out / "model.pt")
    assert res.metrics == whole[1].metrics and len(res.history["stages"]) == 1


def test_a_signal_while_the_model_is_saved_leaves_the_whole_history(whole, tmp_path, monkeypatch):
    # the faults campaign's SIGTERM came after the last epoch, while model.pt was being
    # written, and left no history.json (Ctrl-C during training leaves it)
    out = tmp_path / "part"

    with monkeypatch.context() as m:
        m.setattr(pose_run, "save_pose_model", ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            train_run("figures", out, **DATA, **DEEPPOSE)
    history = json.loads((out / "history.json").read_text())
    want = whole[1].history
    assert history["network"]["losses"] == want["network"]["losses"]
    assert [h["losses"] for h in history["stages"]] == [h["losses"] for h in want["stages"]]


# --------------------------------------------------------------------------- eval


def test_evaluate_run_scores_the_validation_split(whole, tmp_path):
    out, res = whole
    ev = evaluate_run(str(out), "figures", **DATA, out_dir=tmp_path / "eval")
    assert ev.model == str(out) and ev.n == 1
    assert ev.metrics["metrics"] == res.metrics["metrics"]
    assert set(ev.metrics["pck_per_joint"]) == set(
        load_pose_model(out / "model.pt")[1]["skeleton"].joints
    )
    written = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert ev.files == {"metrics.json": tmp_path / "eval" / "metrics.json"}
    assert written == ev.to_dict() == json.loads(json.dumps(ev.to_dict()))
    plain = evaluate_run(out / "model.pt", "figures", **DATA, flip=False, device="cpu")
    model, info = load_pose_model(out / "model.pt")
    _, val = load_pose_data("figures", **DATA)
    expect = evaluate_pose(model, val, refiners=info["refiners"], flip=False)
    assert plain.metrics["metrics"] == expect.summary() and plain.metrics["flip_test"] is False
    assert plain.files == {}


def test_evaluate_run_refuses(tmp_path):
    with pytest.raises(InputError, match="RUN_OR_MODEL"):
        evaluate_run(tmp_path / "none", "figures", **DATA)
    path = tmp_path / "coco.pt"
    net = build_pose_model("heatmap", 17, width=2)
    save_pose_model(path, net, "heatmap", {"width": 2}, COCO_17)
    with pytest.raises(InputError, match="evaluate on the kind of data"):
        evaluate_run(path, "figures", **DATA)
    with pytest.raises(InputError, match="--images"):
        evaluate_run(path, "figures", images=1)
