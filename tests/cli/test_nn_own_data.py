"""Training on a user's own small data, end to end (issue 46, item 6): the labelme
VOC instances (3 PASCAL VOC photos, 12 polygon instances, as labelme files, a VOC
segmentation folder and a COCO JSON export) through ``nn detect`` and ``nn segment``
train -> eval -> predict. One epoch of a narrow
network: the point is the path from a user's files to a prediction, not the figure."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.cli.main import main
from robopercept.imaging import write_image
from tests.cli.nn_runs import run_cli
from tests.conftest import data_path

pytestmark = [pytest.mark.realdata, pytest.mark.usefixtures("torch_one_thread")]


@pytest.fixture(scope="module")
def labelme():
    root = data_path("detection", "labelme_voc_instances")
    forms = {
        "coco": root / "coco" / "annotations.json",
        "labelme": root / "data_annotated",
        "voc": root / "voc",
    }
    return forms, sorted(map(str, (root / "coco" / "JPEGImages").glob("*.jpg")))


@pytest.mark.parametrize(
    ("task", "train_args", "train_on", "eval_on"),
    [
        ("detect", ["--model", "faster", "--width", "4"], "labelme", "coco"),
        ("segment", ["--task", "instance", "--width", "4"], "voc", "labelme"),
    ],
)
def test_train_eval_predict_on_each_form(task, train_args, train_on, eval_on, labelme, tmp_path):
    """Train on one form of the annotations, score on another (the classes matched by
    name: the COCO file and the VOC folder list all 20 VOC classes, the labelme files
    only the 6 they use), predict on the photos."""
    forms, photos = labelme
    out = tmp_path / "run"
    argv = ["nn", task, "train", "--data", str(forms[train_on]), *train_args, "--epochs", "1"]
    rc, _ = run_cli([*argv, "--batch-size", "2", "-o", str(out), "--quiet"])
    assert rc == 0 and (out / "model.pt").is_file() and (out / "metrics.json").is_file()
    info = json.loads((out / "metrics.json").read_text())
    assert info["data"] == str(forms[train_on])
    rc, text = run_cli(["nn", task, "eval", str(out), "--data", str(forms[eval_on]), "--json"])
    assert rc == 0 and json.loads(text)["images"] == 3  # the whole set, not a split
    rc, text = run_cli(["nn", task, *photos, "--model", str(out), "-o", str(tmp_path / "o")])
    assert rc == 0 and text.splitlines()[0].startswith(f"model: {out}")
    assert len(list((tmp_path / "o").glob("*.png"))) >= len(photos)


def test_boxes_cannot_train_a_segmenter(tmp_path, capsys):
    write_image(tmp_path / "a.png", np.zeros((8, 10, 3), np.uint8))
    (tmp_path / "a.xml").write_text(
        "<annotation><filename>a.png</filename><size><width>10</width><height>8</height>"
        "</size><object><name>t</name><bndbox><xmin>1</xmin><ymin>2</ymin><xmax>5</xmax>"
        "<ymax>6</ymax></bndbox></object></annotation>"
    )
    argv = ["nn", "segment", "train", "--data", str(tmp_path), "--task", "instance"]
    assert main([*argv, "-o", str(tmp_path / "r"), "--quiet"]) == 2
    assert "Pascal-VOC XML files hold boxes, not masks" in capsys.readouterr().err


def test_a_semantic_network_trains_on_images_of_several_sizes(labelme, tmp_path):
    """The VOC folder's photos are 500 x 338 and 500 x 375: a U-Net trains on them padded
    to 500 x 375 with the void label (no loss, no score), and scores every pixel of each
    image at its own size."""
    forms, _ = labelme
    out = tmp_path / "r"
    argv = ["nn", "segment", "train", "--data", str(forms["voc"]), "--epochs", "1"]
    rc, _ = run_cli([*argv, "--width", "4", "--batch-size", "2", "-o", str(out), "--quiet"])
    assert rc == 0 and (out / "model.pt").is_file()
    rc, text = run_cli(["nn", "segment", "eval", str(out), "--data", str(forms["coco"]), "--json"])
    ev = json.loads(text)
    assert rc == 0 and ev["images"] == 3 and set(ev["metrics"]) >= {"mIoU", "pixel_accuracy"}


def test_pose_on_a_coco_keypoints_file(tmp_path, capsys):
    """nn pose train -> eval -> predict on mmpose's COCO val2017 sample (12 persons with
    keypoints, cut out around their boxes): COCO's 17 joints end to end."""
    root = data_path("detection", "coco_keypoints_mmpose")
    coco = root / "test_coco.json"
    out = tmp_path / "run"
    argv = ["nn", "pose", "train", "--data", str(coco), "--width", "4", "--epochs", "1"]
    rc, _ = run_cli([*argv, "--batch-size", "4", "-o", str(out), "--quiet"])
    assert rc == 0 and (out / "model.pt").is_file()
    rc, text = run_cli(["nn", "pose", "eval", str(out), "--data", str(coco), "--json"])
    ev = json.loads(text)
    assert rc == 0 and ev["images"] == 12 and len(ev["pck_per_joint"]) == 17
    assert "left_ankle" in ev["pck_per_joint"]
    photos = sorted(map(str, root.glob("*.jpg")))[:2]
    rc, text = run_cli(["nn", "pose", *photos, "--model", str(out), "--json"])
    assert rc == 0 and len(json.loads(text)["results"]) == 2
    capsys.readouterr()
    rc, _ = run_cli(["nn", "pose", "eval", str(out), "--data", "figures", "--images", "4"])
    assert rc == 1 and "17 joints of person" in capsys.readouterr().err
