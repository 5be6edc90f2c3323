"""robopercept.nn.cloud.run: the data sets, the training run and its folder, the
evaluation of a saved network and single-file prediction (issues 29 and 45). Tiny
networks and clouds keep the file fast."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError, RunExistsError  # noqa: E402
from robopercept.nn.cloud.run import (  # noqa: E402
    CloudTrainResult,
    classify_cloud_file,
    cloud_sets,
    evaluate_run,
    train_run,
)
from robopercept.nn.cloud.synthetic import procedural_shapes  # noqa: E402
from robopercept.nn.cloud.train import (  # noqa: E402
    build_cloud_model,
    evaluate_cloud_model,
    load_cloud_model,
)
from robopercept.nn.train.config import TrainConfig  # noqa: E402
from robopercept.pointcloud import PointCloud, write_point_cloud  # noqa: E402
from tests.cli.nn_runs import ctrl_c, ctrl_c_after_first_epoch  # noqa: E402
from tests.conftest import data_path  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

CLASSES = ("sphere", "plane", "l_shape")
#: a tiny run: 3 procedural shapes per class (36 training clouds) of 64 points
TINY_RUN = {"shapes": 3, "n_points": 64, "width": 0.125, "progress": False}
FILES = {"model.pt", "history.json", "metrics.json", "confusion.png"}


def _cfg(epochs: int = 2) -> TrainConfig:
    return TrainConfig(epochs=epochs, batch_size=8, seed=0, device="cpu")


@pytest.fixture(scope="module")
def shapes():
    return procedural_shapes(10, 64, classes=CLASSES, rng=1)


@pytest.fixture(scope="module")
def net() -> torch.nn.Module:
    return build_cloud_model("pointnet", 3, seed=0, width=0.125)


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> CloudTrainResult:
    # one thread, set here: a module fixture runs before the per-test torch_one_thread
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        out = tmp_path_factory.mktemp("cloud") / "run"
        return train_run("shapes", out, config=_cfg(), **TINY_RUN)
    finally:
        torch.set_num_threads(before)


def _folder(root: Path, classes: tuple[str, ...] = ("a", "b")) -> Path:
    rng = np.random.default_rng(0)
    for c in classes:
        (root / c).mkdir(parents=True)
        for i in range(10):
            cloud = PointCloud(rng.random((50, 3)) * (1 if c == classes[0] else [1, 1, 0.01]))
            write_point_cloud(root / c / f"{i}.pcd", cloud)
    return root


def test_classify_a_file_and_its_count(net, shapes, tmp_path):
    trained = net
    path = write_point_cloud(tmp_path / "c.ply", PointCloud(shapes.points[0].astype(float)))
    info = {"class_names": list(CLASSES), "n_points": 64}
    res = classify_cloud_file(path, trained, info)
    assert res.points.shape == (64, 3) and next(iter(res.probabilities)) == res.label
    assert sum(res.probabilities.values()) == pytest.approx(1.0, abs=1e-5)
    assert res.to_dict()["class"] == res.label and res.parts is None
    assert classify_cloud_file(path, trained, info, n_points=32).points.shape == (32, 3)


def test_classify_refuses_a_classifier_as_segmenter(net, shapes, tmp_path):
    path = write_point_cloud(tmp_path / "c.ply", PointCloud(shapes.points[0].astype(float)))
    info = {"class_names": list(CLASSES), "n_points": 64}
    with pytest.raises(InputError, match="segmenter must be"):
        classify_cloud_file(path, net, info, segmenter=(net, info))
    with pytest.raises(InputError, match="PointNet or DGCNN"):
        classify_cloud_file(path, torch.nn.Linear(3, 3), info)


def test_cloud_sets_of_shapes_and_folders(tmp_path):
    sets = cloud_sets("shapes", shapes=10, n_points=32, seed=1)
    assert (len(sets.train), len(sets.val), len(sets.test)) == (120, 12, 12)
    assert sets.train.parts is not None
    _folder(tmp_path)
    sets = cloud_sets(str(tmp_path), n_points=16, seed=0)
    assert sets.train.class_names == ("a", "b")
    assert len(sets.train) + len(sets.val) + len(sets.test) == 20
    with pytest.raises(InputError, match="not a folder"):
        cloud_sets(str(tmp_path / "missing"))


def test_cloud_sets_test_only_makes_the_same_test_split_alone():
    full = cloud_sets("shapes-noisy", shapes=20, n_points=16, seed=3)
    alone = cloud_sets("shapes-noisy", shapes=20, n_points=16, seed=3, test_only=True)
    assert alone.train is None and alone.val is None
    assert np.array_equal(alone.test.points, full.test.points)
    assert np.array_equal(alone.test.labels, full.test.labels)
    with pytest.raises(InputError, match="test_only"):
        cloud_sets("shapes", shapes=1, n_points=8, test_only="yes")


@pytest.mark.realdata
def test_modelnet_layout_keeps_its_test_split():
    root = data_path("pointcloud_cls", "ModelNet10")
    sets = cloud_sets(str(root), n_points=64, seed=0)
    assert sets.test.class_names == ("sofa", "table")
    names = {Path(n).parent.name for n in sets.test.names}
    assert names == {"test"}


# ----------------------------------------------------------------------------- runs
def test_train_run_writes_the_run_folder(run):
    out = run.out_dir
    assert set(run.files) == FILES and all(p.parent == out for p in run.files.values())
    assert {p.name for p in out.iterdir()} == FILES | {"checkpoint.pt", "checkpoint.best.pt"}
    assert json.loads((out / "metrics.json").read_text()) == run.metrics
    assert json.loads((out / "history.json").read_text()) == run.history.to_dict()
    assert run.metrics["split"] == "test" and run.metrics["data"] == "shapes"
    assert run.metrics["best_epoch"] == run.best_epoch == run.history.best_epoch
    assert len(run.history.losses) == 2 and set(run.history.val) == {1, 2}
    assert run.to_dict()["files"] == {name: str(p) for name, p in run.files.items()}
    # the saved network is the kept one and records its data
    model, info = load_cloud_model(out / "model.pt")
    assert info["n_points"] == 64 and info["shapes"] == 3 and info["seed"] == 0
    assert info["data"] == "shapes" and info["settings"]["width"] == 0.125
    test = cloud_sets("shapes", shapes=3, n_points=64, seed=0).test
    assert evaluate_cloud_model(model, test).accuracy == run.test.accuracy
    assert run.metrics["metrics"] == run.test.summary() and run.seconds > 0


def test_train_run_refuses_an_existing_run(run):
    before = (run.out_dir / "checkpoint.pt").read_bytes()
    with pytest.raises(RunExistsError, match="--resume"):
        train_run("shapes", run.out_dir, config=_cfg(), **TINY_RUN)
    with pytest.raises(InputError, match="exclude each other"):
        train_run("shapes", run.out_dir, config=_cfg(), resume=True, overwrite=True, **TINY_RUN)
    assert (run.out_dir / "checkpoint.pt").read_bytes() == before


def test_interrupted_run_keeps_its_history_and_resumes(run, tmp_path):
    out = tmp_path / "part"
    with ctrl_c_after_first_epoch(), pytest.raises(KeyboardInterrupt):
        train_run("shapes", out, config=_cfg(), **TINY_RUN)
    assert (out / "checkpoint.pt").exists() and not (out / "model.pt").exists()
    assert len(json.loads((out / "history.json").read_text())["losses"]) == 1
    res = train_run("shapes", out, config=_cfg(), resume=True, **TINY_RUN)
    assert res.history.to_dict()["losses"] == run.history.to_dict()["losses"]
    a = torch.load(run.files["model.pt"], weights_only=True)["model"]
    b = torch.load(res.files["model.pt"], weights_only=True)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_signal_while_the_model_is_saved_leaves_the_whole_history(run, tmp_path, monkeypatch):
    # the faults campaign's SIGTERM after the last epoch, while model.pt was written
    from robopercept.nn.cloud import run as cloud_run

    monkeypatch.setattr(cloud_run, "save_cloud_model", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        train_run("shapes", tmp_path / "part", config=_cfg(), **TINY_RUN)
    history = json.loads((tmp_path / "part" / "history.json").read_text())
    assert history["losses"] == run.history.to_dict()["losses"]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"data": "nowhere/"}, r"^--data: .*not a folder"),
        ({"data": 3}, r"^--data must be"),
        ({"model": "pointnet++"}, "--model"),
        ({"task": "detect"}, "--task"),
        ({"width": 0.0}, "--width"),
        ({"model": "dgcnn", "k": 65}, r"--k: at most --points \(64\)"),
        ({"n_points": 0}, "--points"),
        ({"config": {"epochs": 1}}, "TrainConfig"),
    ],
)
def test_train_run_errors_name_their_flag(kwargs, match, tmp_path):
    args = {"data": "shapes", "config": _cfg(), **TINY_RUN, **kwargs}
    with pytest.raises(InputError, match=match):
        train_run(args.pop("data"), tmp_path / "run", **args)


def test_evaluate_run_scores_the_test_split(run, tmp_path):
    res = evaluate_run(run.out_dir, "shapes", shapes=3, n_points=64, progress=False)
    assert res.metrics["metrics"] == run.metrics["metrics"] and res.files == {}
    assert res.metrics["model"] == str(run.out_dir) and res.to_dict() == res.metrics
    assert res.metrics["title"] == "run on shapes: test" and res.metrics["clouds"] == 12
    out = tmp_path / "eval"
    res = evaluate_run(
        run.files["model.pt"], "shapes", shapes=3, n_points=64, out_dir=out, progress=False
    )
    assert set(res.files) == {"metrics.json", "confusion.png"}
    assert json.loads((out / "metrics.json").read_text()) == res.metrics
    assert res.evaluation.accuracy == run.test.accuracy


def test_evaluate_run_refuses_other_classes(run, tmp_path):
    folder = _folder(tmp_path / "clouds")
    with pytest.raises(InputError, match=r"^--data: its classes \['a', 'b'\] are not the model"):
        evaluate_run(run.out_dir, folder, n_points=64, progress=False)
    with pytest.raises(InputError, match=r"^--data: .*not a folder"):
        evaluate_run(run.out_dir, tmp_path / "missing", n_points=64, progress=False)
