"""``robopercept nn pose train|eval|IMAGE...`` (issue 28, item 7): tiny runs (a few 64 x
64 procedural figures, a few epochs) so the file runs in well under a minute; the
printed figures equal the library's on the same split, the image form's keypoints
equal :func:`~robopercept.nn.pose.inference.pose_arrays`', and bad arguments name their flag."""

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
from robopercept.nn.pose.data import pose_sets  # noqa: E402
from robopercept.nn.pose.evaluate import evaluate_pose  # noqa: E402
from robopercept.nn.pose.inference import pose_arrays  # noqa: E402
from robopercept.nn.pose.networks import load_pose_model  # noqa: E402
from tests.cli.nn_runs import check_run_folder_rules  # noqa: E402

DATA = ["--data", "figures", "--images", "12", "--size", "64x64", "--seed", "0"]
FILES = {"model.pt", "history.json", "metrics.json", "samples.png"}

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _run(args: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    return rc, buf.getvalue()


def _train(tmp_path_factory, model: str, *extra: str) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("pose") / model
    torch.set_num_threads(1)
    args = ["--model", model, "--width", "4", "--epochs", "2", "--batch-size", "4", "--json"]
    rc, text = _run(["nn", "pose", "train", *DATA, *args, *extra, "-o", str(out)])
    assert rc == 0
    return out, json.loads(text)


@pytest.fixture(scope="module")
def hrnet(tmp_path_factory) -> tuple[Path, dict]:
    return _train(tmp_path_factory, "hrnet")


@pytest.fixture(scope="module")
def deeppose(tmp_path_factory) -> tuple[Path, dict]:
    return _train(tmp_path_factory, "deeppose", "--stages", "1")


def test_train_writes_the_run_and_its_figures_are_the_librarys(hrnet):
    out, printed = hrnet
    assert {p.name for p in out.iterdir()} >= FILES
    assert set(printed["files"]) == FILES and printed["split"] == "validation"
    model, info = load_pose_model(out / "model.pt")
    assert info["skeleton"].name == "mpii16" and info["refiners"] == []
    val = pose_sets("figures", 12, (64, 64), 0, test_images=1).val
    ev = evaluate_pose(model, val)
    assert printed["metrics"]["PCK@0.1"] == pytest.approx(ev.pck[0.1], abs=1e-12)
    assert printed["metrics"]["OKS AP"] == pytest.approx(ev.oks.stats[0], abs=1e-12)
    rc, text = _run(["nn", "pose", "eval", str(out), *DATA, "--json"])
    assert rc == 0 and json.loads(text)["metrics"] == printed["metrics"]
    assert set(json.loads(text)["pck_per_joint"]) == set(info["skeleton"].joints)


def test_deeppose_keeps_its_cascade_stage(deeppose):
    out, printed = deeppose
    model, info = load_pose_model(out / "model.pt")
    assert type(model).__name__ == "DeepPose" and len(info["refiners"]) == 1
    history = json.loads((out / "history.json").read_text())
    assert len(history["stages"]) == 1 and "PCK@0.1" in printed["metrics"]


def test_images_form_writes_skeletons_heatmaps_and_3d(hrnet, tmp_path):
    figures = pose_sets("figures", 12, (64, 64), 0, test_images=1).train
    paths = [
        str(write_image(tmp_path / f"im{i}.png", (im * 255).round().astype(np.uint8)))
        for i, im in enumerate(figures.images[:2])
    ]
    model, info = load_pose_model(hrnet[0] / "model.pt")
    expect = pose_arrays(
        model,
        [read_image(p, mode="rgb") for p in paths],
        flip_permutation=info["skeleton"].flip_permutation(),
    )
    # outputs over the inputs are refused
    assert main(["nn", "pose", *paths, "--model", str(hrnet[0]), "-o", str(tmp_path)]) == 2
    out = tmp_path / "out"
    args = ["--model", str(hrnet[0]), "-o", str(out), "--heatmaps", "--lift3d"]
    rc, text = _run(["nn", "pose", *paths, *args])
    assert rc == 0 and "mean joint score" in text
    for p in paths:
        stem = Path(p).stem
        for name in (f"{stem}.png", f"{stem}_heatmaps.png", f"{stem}_3d.png"):
            assert read_image(out / name).shape[0] >= 256
    rc, text = _run(["nn", "pose", *paths, "--model", str(hrnet[0]), "--json", "--lift3d"])
    rows = json.loads(text)["results"]
    assert rc == 0 and len(rows) == 2
    for row, res in zip(rows, expect, strict=True):
        np.testing.assert_allclose(row["keypoints"], res.keypoints, atol=0.01)
        assert np.asarray(row["joints3d_m"]).shape == (16, 3)
        assert row["joints"][0] == "right_ankle"


def test_run_folder_rules(tmp_path, capsys):
    # refusal (exit 2), Ctrl-C after epoch 1 (exit 130), --resume to the same weights
    args = ["--model", "hrnet", "--width", "4", "--epochs", "2", "--batch-size", "4"]
    check_run_folder_rules(
        ["nn", "pose", "train", *DATA, *args, "--quiet"], tmp_path, "model.pt", capsys
    )


def test_resume_and_overwrite_exclude_each_other(tmp_path, capsys):
    args = ["train", *DATA, "--resume", "--overwrite", "-o", str(tmp_path / "run")]
    assert main(["nn", "pose", *args]) == 2
    assert "--resume and --overwrite" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    ("args", "msg"),
    [
        (["train", "--data", "figures", "--images", "1"], "--images"),
        (["train", "--data", "figures", "--lr", "0"], "--lr"),
        (["train", "--data", "figures", "--size", "60x64"], "--size"),
        (["train", "--data", "figures", "--stages", "9"], "--stages"),
        (["train", "--data", "coco"], "--data"),
        (["eval", "/nonexistent/run", *DATA], "RUN_OR_MODEL"),
        (["/nonexistent.png", "--model", "/nonexistent.pt", "-o", "x"], "--model"),
    ],
)
def test_bad_arguments_name_the_flag(args, msg, capsys):
    assert main(["nn", "pose", *args]) == 2
    assert msg in capsys.readouterr().err


def test_image_form_needs_an_output_and_existing_images(hrnet, capsys):
    assert main(["nn", "pose", "/nonexistent.png", "--model", str(hrnet[0])]) == 2
    assert "-o/--out" in capsys.readouterr().err
    assert main(["nn", "pose", "/nonexistent.png", "--model", str(hrnet[0]), "--json"]) == 2
    assert "IMAGE: /nonexistent.png" in capsys.readouterr().err
