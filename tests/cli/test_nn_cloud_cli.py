"""``robopercept nn cloud train|eval|CLOUD...`` (issue 29, item 4): a tiny run (a few
64-point procedural shapes, one epoch) so the file stays fast; the printed figures
equal the library's on the same split, the cloud form's prediction equals
:func:`~robopercept.nn.cloud.run.classify_cloud_file`'s, and bad arguments name their flag."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.nn.cloud.run import classify_cloud_file, cloud_sets  # noqa: E402
from robopercept.nn.cloud.train import evaluate_cloud_model, load_cloud_model  # noqa: E402
from robopercept.pointcloud import read_point_cloud  # noqa: E402
from tests.cli.nn_runs import check_run_folder_rules  # noqa: E402
from tests.conftest import data_path  # noqa: E402

DATA = ["--data", "shapes", "--shapes", "3", "--points", "64", "--seed", "0"]
FILES = {"model.pt", "history.json", "metrics.json", "confusion.png"}

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _run(args: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    return rc, buf.getvalue()


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("cloud") / "run"
    args = ["--width", "0.125", "--epochs", "1", "--batch-size", "8", "--json", "-o", str(out)]
    rc, text = _run(["nn", "cloud", "train", *DATA, *args])
    assert rc == 0
    return out, json.loads(text)


def test_train_writes_the_run_and_its_figures_are_the_librarys(run):
    out, printed = run
    assert {p.name for p in out.iterdir()} >= FILES
    assert set(printed["files"]) == FILES and printed["split"] == "test"
    model, info = load_cloud_model(out / "model.pt")
    assert info["n_points"] == 64 and len(info["class_names"]) == 12
    test = cloud_sets("shapes", shapes=3, n_points=64, seed=0).test
    ev = evaluate_cloud_model(model, test)
    assert printed["metrics"]["accuracy"] == pytest.approx(ev.accuracy, abs=1e-12)
    rc, text = _run(["nn", "cloud", "eval", str(out), *DATA, "--json"])
    assert rc == 0 and json.loads(text)["metrics"] == printed["metrics"]


def test_segment_training_reports_miou(tmp_path):
    out = tmp_path / "seg"
    args = ["--task", "segment", "--model", "dgcnn", "--k", "4", "--epochs", "1", "--json"]
    rc, text = _run(["nn", "cloud", "train", *DATA, *args, "-o", str(out)])
    printed = json.loads(text)
    assert rc == 0 and 0.0 <= printed["metrics"]["instance_miou"] <= 1.0
    model, info = load_cloud_model(out / "model.pt")
    assert model.task == "segment" and len(info["part_names"]) == model.num_outputs


@pytest.mark.realdata
def test_cloud_form_on_real_modelnet_meshes(run, tmp_path):
    out, _ = run
    meshes = sorted(data_path("pointcloud_cls", "ModelNet10").rglob("*.off"))[:2]
    rc, text = _run(["nn", "cloud", *map(str, meshes), "--model", str(out), "--json"])
    rows = json.loads(text)["results"]
    assert rc == 0 and len(rows) == 2
    model, info = load_cloud_model(out / "model.pt")
    for mesh, row in zip(meshes, rows, strict=True):
        ref = classify_cloud_file(mesh, model, info)
        assert row["class"] == ref.label and row["points"] == 64
        assert row["probabilities"] == pytest.approx(ref.probabilities, abs=1e-6)


def test_segment_form_writes_a_coloured_ply(run, tmp_path):
    out, _ = run
    seg_run = tmp_path / "seg"
    args = ["--task", "segment", "--width", "0.125", "--epochs", "1", "--quiet"]
    assert _run(["nn", "cloud", "train", *DATA, *args, "-o", str(seg_run)])[0] == 0
    sets = cloud_sets("shapes", shapes=3, n_points=64, seed=0)
    from robopercept.pointcloud import PointCloud, write_point_cloud

    src = write_point_cloud(tmp_path / "shape.pcd", PointCloud(sets.test.points[0].astype(float)))
    pics = tmp_path / "pics"
    rc, text = _run(
        ["nn", "cloud", str(src), "--model", str(out), "--segment", str(seg_run), "-o", str(pics)]
    )
    assert rc == 0 and "shape.pcd:" in text
    cloud = read_point_cloud(pics / "shape_parts.ply")
    assert len(cloud.points) == 64 and cloud.colors is not None
    # one colour per predicted part, and the picture
    assert 1 <= len(np.unique(cloud.colors, axis=0)) <= 4
    assert (pics / "shape.png").is_file()


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["train", "--data", "nowhere/"], "--data"),
        (["train", *DATA, "--model", "dgcnn", "--k", "65"], "--k"),
        (["train", *DATA, "--lr", "0"], "--lr"),
        (["eval", "missing_run", *DATA], "RUN_OR_MODEL"),
        (["missing.ply", "--json"], "CLOUD"),
    ],
)
def test_bad_arguments_name_their_flag(args, flag, capsys):
    assert main(["nn", "cloud", *args]) == 2
    assert flag in capsys.readouterr().err


def test_segment_needs_an_output_folder(run, tmp_path, capsys):
    out, _ = run
    src = tmp_path / "c.pcd"
    from robopercept.pointcloud import PointCloud, write_point_cloud

    write_point_cloud(src, PointCloud(np.random.default_rng(0).random((30, 3))))
    assert main(["nn", "cloud", str(src), "--model", str(out), "--segment", str(out)]) == 2
    assert "--segment" in capsys.readouterr().err


def test_run_folder_rules(tmp_path, capsys):
    # a second run into the folder is refused, Ctrl-C keeps epoch 1, --resume ends with the
    # uninterrupted run's weights, --overwrite starts afresh (issue 45)
    argv = ["nn", "cloud", "train", *DATA, "--width", "0.125", "--epochs", "2"]
    check_run_folder_rules([*argv, "--batch-size", "8", "--quiet"], tmp_path, "model.pt", capsys)


def test_resume_and_overwrite_exclude_each_other(tmp_path, capsys):
    argv = ["nn", "cloud", "train", *DATA, "--resume", "--overwrite", "-o", str(tmp_path)]
    assert main(argv) == 2
    assert "--resume and --overwrite exclude each other" in capsys.readouterr().err


@pytest.mark.realdata
def test_train_eval_predict_on_a_small_real_mesh_folder(tmp_path):
    # issue 46: nine ModelNet meshes in three class folders (1, 5 and 3) used to train,
    # write model.pt, then fail with "data is empty" (an empty test split)
    folder = data_path("pointcloud_cls", "ModelNet_samples_zeaggler")
    data = ["--data", str(folder), "--points", "128", "--seed", "0"]
    out = tmp_path / "run"
    rc, text = _run(["nn", "cloud", "train", *data, "--epochs", "2", "-o", str(out), "--quiet"])
    assert rc == 0 and {p.name for p in out.iterdir()} >= FILES
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["clouds"] >= 1  # a test split of its own, not empty
    rc, text = _run(["nn", "cloud", "eval", str(out), *data, "--json"])
    assert rc == 0 and json.loads(text)["clouds"] == metrics["clouds"]
    meshes = sorted(map(str, folder.rglob("*.off")))
    rc, text = _run(["nn", "cloud", *meshes, "--model", str(out), "--json"])
    rows = json.loads(text)["results"]
    assert rc == 0 and len(rows) == 9
    assert {r["class"] for r in rows} <= {"airplane", "bathtub", "bed"}


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["ModelNet10", "ModelNet40"])
def test_modelnet_folders_train_without_a_validation_split(name, tmp_path):
    """ModelNet's layout with one training mesh per class (2 classes): too few to hold
    a validation cloud of each class out and keep 2 to train on, so training runs on
    both without validation (the last epoch kept, validation_clouds 0); its test split
    scores it; the meshes are classified into its two classes."""
    folder = data_path("pointcloud_cls", name)
    data = ["--data", str(folder), "--points", "128", "--seed", "0"]
    out = tmp_path / "run"
    rc, _ = _run(["nn", "cloud", "train", *data, "--epochs", "2", "-o", str(out), "--quiet"])
    assert rc == 0 and {p.name for p in out.iterdir()} >= FILES
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["validation_clouds"] == 0 and metrics["best_epoch"] == 2
    assert metrics["clouds"] == 2  # ModelNet's own test split, one mesh per class
    rc, text = _run(["nn", "cloud", "eval", str(out), *data, "--json"])
    assert rc == 0 and json.loads(text)["clouds"] == 2
    meshes = sorted(map(str, folder.rglob("*.off")))
    rc, text = _run(["nn", "cloud", *meshes, "--model", str(out), "--json"])
    classes = {d.name for d in folder.iterdir() if d.is_dir()}
    assert rc == 0 and {r["class"] for r in json.loads(text)["results"]} <= classes


@pytest.mark.realdata
def test_a_mesh_folder_too_small_to_train_names_the_smallest_count(tmp_path, capsys):
    # two meshes in two class folders: the test split takes one, leaving one cloud to
    # train on, which batch norm cannot learn from
    src = data_path("pointcloud_cls", "ModelNet10")
    for c in ("sofa", "table"):
        (tmp_path / "d" / c).mkdir(parents=True)
        mesh = next((src / c / "train").glob("*.off"))
        (tmp_path / "d" / c / mesh.name).write_bytes(mesh.read_bytes())
    argv = ["nn", "cloud", "train", "--data", str(tmp_path / "d"), "-o", str(tmp_path / "r")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1 and "1 cloud left to train on" in errors[0]
    assert "training needs at least 2" in errors[0]
    assert not (tmp_path / "r" / "model.pt").exists()
