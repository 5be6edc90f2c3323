"""Training on a user's own small data, end to end (issue 46, item 6): the labelme
VOC instances (3 PASCAL VOC photos, 12 polygon instances, exported as COCO JSON) through
``nn detect`` and ``nn segment`` train -> eval -> predict. One epoch of a narrow
network: the point is the path from a user's files to a prediction, not the figure."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("torch")

from robopercept.cli.main import main
from tests.cli.nn_runs import run_cli
from tests.conftest import data_path

pytestmark = [pytest.mark.realdata, pytest.mark.usefixtures("torch_one_thread")]


@pytest.fixture(scope="module")
def labelme():
    root = data_path("detection", "labelme_voc_instances", "coco")
    return root / "annotations.json", sorted(map(str, (root / "JPEGImages").glob("*.jpg")))


@pytest.mark.parametrize(
    ("task", "train_args"),
    [
        ("detect", ["--model", "faster", "--width", "4"]),
        ("segment", ["--task", "instance", "--width", "4"]),
    ],
)
def test_coco_file_train_eval_predict(task, train_args, labelme, tmp_path):
    coco, photos = labelme
    out = tmp_path / "run"
    argv = ["nn", task, "train", "--data", str(coco), *train_args, "--epochs", "1"]
    rc, _ = run_cli([*argv, "--batch-size", "2", "-o", str(out), "--quiet"])
    assert rc == 0 and (out / "model.pt").is_file() and (out / "metrics.json").is_file()
    info = json.loads((out / "metrics.json").read_text())
    assert info["data"] == str(coco)
    rc, text = run_cli(["nn", task, "eval", str(out), "--data", str(coco), "--json"])
    assert rc == 0 and json.loads(text)["images"] >= 1
    rc, text = run_cli(["nn", task, *photos, "--model", str(out), "-o", str(tmp_path / "o")])
    assert rc == 0 and text.splitlines()[0].startswith(f"model: {out}")
    assert len(list((tmp_path / "o").glob("*.png"))) >= len(photos)


def test_a_semantic_network_on_images_of_several_sizes_says_what_to_do(labelme, tmp_path, capsys):
    coco, _ = labelme
    argv = ["nn", "segment", "train", "--data", str(coco), "--epochs", "1"]
    assert main([*argv, "-o", str(tmp_path / "r"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "trains on images of one size" in err and "--task instance" in err
