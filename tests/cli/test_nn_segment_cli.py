"""``robopercept nn segment train|eval|IMAGE...`` (issue 27, item 6): tiny runs (a few
64 x 64 procedural canvases, a few epochs) so the file runs in well under a minute;
the printed figures equal the library's on the same split, the label PNGs and COCO
RLE results equal the predictions, and bad arguments name their flag."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.imaging import read_image, write_image  # noqa: E402
from robopercept.nn.coco.rle import rle_decode  # noqa: E402
from robopercept.nn.detection.zoo import load_detector  # noqa: E402
from robopercept.nn.segmentation.data import segmentation_sets  # noqa: E402
from robopercept.nn.segmentation.metrics import (  # noqa: E402
    segmentation_confusion,
    segmentation_scores,
)
from robopercept.nn.segmentation.networks import load_segmenter, segment_arrays  # noqa: E402
from tests.cli.nn_runs import check_run_folder_rules  # noqa: E402

DATA = ["--data", "shapes", "--images", "10", "--size", "64x64", "--seed", "0"]
FILES = {"model.pt", "history.json", "metrics.json", "samples.png"}

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _run(args: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    return rc, buf.getvalue()


@pytest.fixture(scope="module")
def semantic(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("seg") / "sem"
    torch.set_num_threads(1)
    args = ["--width", "4", "--epochs", "3", "--batch-size", "4", "--lr", "5e-3", "--json"]
    rc, text = _run(["nn", "segment", "train", *DATA, *args, "-o", str(out)])
    assert rc == 0
    return out, json.loads(text)


@pytest.fixture(scope="module")
def instance(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("seg") / "ins"
    torch.set_num_threads(1)
    args = ["--task", "instance", "--width", "4", "--epochs", "2", "--batch-size", "4", "--json"]
    rc, text = _run(["nn", "segment", "train", *DATA, *args, "-o", str(out)])
    assert rc == 0
    return out, json.loads(text)


def test_semantic_train_writes_the_run_and_its_figures_are_the_librarys(semantic):
    out, printed = semantic
    assert FILES <= {p.name for p in out.iterdir()}
    assert printed["task"] == "semantic" and printed["model"] == "unet"
    model, info = load_segmenter(out / "model.pt")
    assert info["classes"] == ["circle", "square", "triangle", "cross"]
    val = segmentation_sets("shapes", 10, (64, 64), 0).val
    pred = np.stack(segment_arrays(model, list(val.images)))
    s = segmentation_scores(segmentation_confusion(val.class_maps(), pred, 5))
    assert printed["metrics"]["mIoU"] == pytest.approx(s.miou, abs=1e-12)
    assert json.loads((out / "metrics.json").read_text())["metrics"] == printed["metrics"]
    hist = json.loads((out / "history.json").read_text())
    assert len(hist["losses"]) == 3 and str(hist["best_epoch"]) in hist["val_mIoU"]
    rc, text = _run(["nn", "segment", "eval", str(out), *DATA, "--json"])
    assert rc == 0 and json.loads(text)["metrics"] == printed["metrics"]


def test_instance_train_and_eval_agree(instance):
    out, printed = instance
    assert FILES <= {p.name for p in out.iterdir()}
    assert len(printed["stats"]) == 12 and printed["model"] == "maskrcnn"
    model, info = load_detector(out / "model.pt")
    assert type(model).__name__ == "MaskRCNN" and info["kind"] == "maskrcnn"
    rc, text = _run(["nn", "segment", "eval", str(out / "model.pt"), *DATA, "--json"])
    assert rc == 0 and json.loads(text)["stats"] == printed["stats"]


def test_images_form_writes_overlays_label_pngs_and_rle_results(semantic, instance, tmp_path):
    val = segmentation_sets("shapes", 10, (64, 64), 0).val
    paths = []
    for i, im in enumerate(val.images):
        paths.append(str(write_image(tmp_path / f"im{i}.png", (im * 255).round().astype(np.uint8))))
    model, _ = load_segmenter(semantic[0] / "model.pt")
    expect = segment_arrays(model, [read_image(p, mode="rgb") for p in paths])
    # outputs over the inputs are refused
    assert main(["nn", "segment", *paths, "--model", str(semantic[0]), "-o", str(tmp_path)]) == 2
    out = tmp_path / "out"
    rc, text = _run(["nn", "segment", *paths, "--model", str(semantic[0]), "-o", str(out)])
    assert rc == 0 and "labels ->" in text
    for p, lab in zip(paths, expect, strict=True):
        stem = Path(p).stem
        assert read_image(out / f"{stem}.png").shape[0] >= 512  # readable at 1080p
        np.testing.assert_array_equal(read_image(out / f"{stem}_labels.png", mode="index"), lab)
    rc, text = _run(["nn", "segment", paths[0], "--model", str(semantic[0]), "--json"])
    results = json.loads(text)["results"]
    rebuilt = np.zeros_like(expect[0])
    for r in results:
        assert r["image_id"] == 1
        rebuilt[rle_decode(r["segmentation"]).astype(bool)] = r["category_id"]
    np.testing.assert_array_equal(rebuilt, expect[0])
    rc, text = _run(
        ["nn", "segment", paths[0], "--model", str(instance[0]), "--json", "--score-thresh", "0"]
    )
    results = json.loads(text)["results"]
    assert rc == 0 and all({"bbox", "score", "segmentation"} <= set(r) for r in results)
    assert [r["score"] for r in results] == sorted((r["score"] for r in results), reverse=True)


@pytest.mark.parametrize(
    ("args", "msg"),
    [
        (["train", "--task", "instance", "--model", "unet", *DATA], "--model: unet does not"),
        (["train", "--data", "nuclei", "--images-dir", "/nonexistent"], "--images-dir"),
        (["train", "--data", "shapes", "--images", "1"], "--images"),
        (["train", "--data", "shapes", "--lr", "0"], "--lr"),
        (["train", *DATA, "--resume", "--overwrite"], "--resume and --overwrite exclude"),
        (["eval", "/nonexistent/run", *DATA], "RUN_OR_MODEL"),
        (["/nonexistent.png", "--model", "/nonexistent.pt", "-o", "x"], "--model"),
    ],
)
def test_bad_arguments_name_the_flag(args, msg, capsys):
    assert main(["nn", "segment", *args]) == 2
    assert msg in capsys.readouterr().err


def test_image_form_needs_an_output_and_existing_images(semantic, capsys):
    assert main(["nn", "segment", "/nonexistent.png", "--model", str(semantic[0])]) == 2
    assert "-o/--out" in capsys.readouterr().err
    assert main(["nn", "segment", "/nonexistent.png", "--model", str(semantic[0]), "--json"]) == 2
    assert "IMAGE: /nonexistent.png" in capsys.readouterr().err


def test_train_run_folder_refusal_ctrl_c_resume_and_overwrite(tmp_path, capsys):
    """Issue 45: an existing run is refused naming --resume and --overwrite; Ctrl-C
    after epoch 1 keeps its checkpoint and --resume ends with the uninterrupted run's
    weights; --overwrite is accepted (the fastest network, 2 epochs)."""
    argv = ["nn", "segment", "train", *DATA, "--model", "naive", "--width", "4"]
    argv += ["--epochs", "2", "--batch-size", "4", "--quiet"]
    check_run_folder_rules(argv, tmp_path, "model.pt", capsys)
    hist = json.loads((tmp_path / "part" / "history.json").read_text())
    assert len(hist["losses"]) == 2 and hist["best_epoch"] in (1, 2)


def test_train_model_names_match_the_library():
    from robopercept.cli.nn.segment import SEGMENT_MODELS
    from robopercept.nn.segmentation import run

    assert SEGMENT_MODELS == run.SEGMENT_MODELS
