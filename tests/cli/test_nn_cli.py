"""``robopercept nn train|eval|predict|summary`` (issue 23, item 7)."""

from __future__ import annotations

import csv
import importlib.util
import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.imaging import read_image, write_image  # noqa: E402
from tests.cli.nn_runs import check_run_folder_rules, stop_after_first_epoch  # noqa: E402

TRAIN = ["nn", "train", "--data", "digits", "--model", "vgg_small", "--quiet"]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """One short digits run (2 epochs of vgg_small, a few seconds) shared by the tests."""
    out = tmp_path_factory.mktemp("nn") / "run"
    assert main([*TRAIN, "--epochs", "2", "-o", str(out)]) == 0
    return out


def test_train_writes_the_run_folder(run_dir: Path) -> None:
    names = {p.name for p in run_dir.iterdir()}
    assert {"checkpoint.pt", "checkpoint.best.pt", "history.csv", "curves.png"} <= names
    assert {"metrics.json", "confusion.png"} <= names
    m = json.loads((run_dir / "metrics.json").read_text())
    for key in ("test_accuracy", "test", "parameters", "seconds", "config", "architecture"):
        assert key in m
    assert m["classes"] == [str(d) for d in range(10)]
    assert m["parameters"] == 72666  # vgg_small on 1x8x8 (Normalize holds buffers only)
    assert m["architecture"]["model"] == "vgg_small"
    assert m["architecture"]["input_size"] == [8, 8]
    assert m["config"]["epochs"] == 2 and m["seconds"] > 0
    # the split is stratified 0.7 / 0.15 / 0.15 of 1,797 digits
    assert sum(m["split"].values()) == 1797
    assert abs(m["split"]["test"] - 0.15 * 1797) <= 10
    cm = np.array(m["test"]["confusion"])
    assert cm.shape == (10, 10) and cm.sum() == m["split"]["test"]
    assert np.trace(cm) / cm.sum() == pytest.approx(m["test_accuracy"])
    assert m["test_accuracy"] > 0.8  # chance is 0.1; two epochs reach about 0.97
    recall = [m["test"]["per_class"][str(d)]["recall"] for d in range(10)]
    assert recall == pytest.approx(np.diag(cm) / cm.sum(axis=1))
    with (run_dir / "history.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["epoch"] for r in rows] == ["1", "2"]
    assert float(rows[1]["train_loss"]) < float(rows[0]["train_loss"])
    curves = read_image(run_dir / "curves.png")
    assert curves.shape[1] >= 1000 and curves.std() > 0
    assert read_image(run_dir / "confusion.png").ndim == 3


def test_eval_on_the_checkpoint(run_dir: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "cm.png"
    argv = ["nn", "eval", str(run_dir / "checkpoint.best.pt"), "--data", "digits"]
    assert main([*argv, "-o", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    cm = np.array(d["confusion"])
    assert d["n"] == 1797 == cm.sum()
    assert np.trace(cm) / 1797 == pytest.approx(d["accuracy"])
    assert d["accuracy"] > 0.8
    assert read_image(out).shape[1] >= 300
    # the folder stands for its best checkpoint: same figures
    assert main(["nn", "eval", str(run_dir), "--data", "digits", "-o", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["accuracy"] == d["accuracy"]


def test_predict_finds_the_labels_of_digit_pictures(run_dir: Path, tmp_path: Path, capsys):
    from robopercept.nn.data.datasets import load_digits, stratified_split

    ds = load_digits()
    test = stratified_split(ds.labels, (0.7, 0.15, 0.15), rng=0)[2]  # held out by the run
    picks = [int(test[np.argmax(ds.labels[test] == 3)]), int(test[np.argmax(ds.labels[test] == 7)])]
    paths = []
    for i in picks:
        p = tmp_path / f"digit{i}.png"
        write_image(p, np.round(ds.images[i, 0] * 255).astype(np.uint8))
        paths.append(str(p))
    assert main(["nn", "predict", str(run_dir / "checkpoint.best.pt"), *paths, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = doc["results"]
    assert doc["model"].endswith("(your own run; its training data is what you gave it)")
    assert doc["warnings"] == []  # 8 x 8 digits for an 8 x 8 model
    assert [r["image"] for r in rows] == paths
    for r, i in zip(rows, picks, strict=True):
        probs = [t["probability"] for t in r["top"]]
        assert len(probs) == 3 and probs == sorted(probs, reverse=True) and sum(probs) <= 1 + 1e-6
        assert str(ds.labels[i]) in [t["class"] for t in r["top"]]
    assert main(["nn", "predict", str(run_dir), paths[0], "--top-k", "2"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].startswith("model: ")
    assert table[1].split()[:3] == ["image", "rank", "class"] and len(table) == 4


def test_summary_totals_equal_the_parameter_count(capsys) -> None:
    from robopercept.nn.classification.models import build_model

    assert main(["nn", "summary", "resnet_small", "--input", "1,8,8", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    model = build_model("resnet_small", in_channels=1, num_classes=10)
    assert d["total_params"] == sum(p.numel() for p in model.parameters())
    assert d["total_params"] == sum(row["params"] for row in d["layers"])
    assert d["output_shape"] == [1, 10]
    assert main(["nn", "summary", "vgg_small"]) == 0
    assert "Total params: 72,666" in capsys.readouterr().out


def test_model_names_are_the_library_s() -> None:
    from robopercept.cli.nn.classify import MODEL_NAMES
    from robopercept.nn.classification.models import MODELS

    assert set(MODEL_NAMES) == set(MODELS)


# --------------------------------------------------------------------------- bad input


def test_unknown_model_is_a_usage_error_listing_the_choices(tmp_path: Path, capsys) -> None:
    argv = ["nn", "train", "--data", "digits", "--model", "alexnet", "-o", str(tmp_path / "r")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "alexnet" in err and "vgg_small" in err and "resnet_small" in err
    assert not (tmp_path / "r").exists()


def test_folder_with_a_non_image_file(tmp_path: Path, capsys) -> None:
    for name in ("a", "b"):
        (tmp_path / "data" / name).mkdir(parents=True)
        write_image(tmp_path / "data" / name / "x.png", np.zeros((8, 8), np.uint8))
    (tmp_path / "data" / "a" / "notes.txt").write_text("not a picture")
    argv = [*TRAIN, "--data", str(tmp_path / "data"), "-o", str(tmp_path / "r")]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "notes.txt" in err and "not an image file" in err
    assert not (tmp_path / "r" / "checkpoint.pt").exists()


def test_missing_data_folder(tmp_path: Path, capsys) -> None:
    assert main([*TRAIN, "--data", str(tmp_path / "nowhere"), "-o", str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert "--data" in err and "no such folder" in err and "digits" in err


def test_resume_without_a_checkpoint(tmp_path: Path, capsys) -> None:
    assert main([*TRAIN, "--resume", "-o", str(tmp_path / "r")]) == 1
    assert "nothing to resume" in capsys.readouterr().err


def test_an_existing_run_is_not_overwritten(run_dir: Path, capsys) -> None:
    before = (run_dir / "checkpoint.pt").read_bytes()
    # exit 2 (issue 45: the fix is a flag, --resume or --overwrite; it was 1 before)
    assert main([*TRAIN, "--epochs", "1", "-o", str(run_dir)]) == 2
    assert "--resume" in capsys.readouterr().err
    assert (run_dir / "checkpoint.pt").read_bytes() == before


def test_run_folder_rules(tmp_path: Path, capsys, torch_one_thread) -> None:
    # refusal (exit 2), Ctrl-C after epoch 1 (exit 130), --resume to the same weights
    check_run_folder_rules([*TRAIN, "--epochs", "2"], tmp_path, "checkpoint.best.pt", capsys)


@pytest.mark.parametrize(("sig", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_real_signal_keeps_the_last_epoch(sig, status, tmp_path: Path) -> None:
    # the real thing in a child process: Ctrl-C (SIGINT) or SIGTERM during epoch 2 exits
    # 130 / 143 and leaves epoch 1's checkpoint and history; --resume finishes the run
    argv = [*TRAIN, "--epochs", "3", "--patience", "100"]
    out = tmp_path / "run"
    assert stop_after_first_epoch(argv, out, sig) == status
    state = torch.load(out / "checkpoint.pt", weights_only=True)
    assert 1 <= state["epochs_done"] < 3
    with (out / "history.csv").open() as f:
        assert len(list(csv.DictReader(f))) == state["epochs_done"]
    assert main([*argv, "--resume", "-o", str(out)]) == 0
    with (out / "history.csv").open() as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2", "3"]


def test_resume_continues_the_run(run_dir: Path, tmp_path: Path) -> None:
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    assert main([*TRAIN, "--epochs", "3", "--resume", "-o", str(copy)]) == 0
    with (copy / "history.csv").open() as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2", "3"]


def test_checkpoint_of_another_architecture(run_dir: Path, tmp_path: Path, capsys) -> None:
    state = torch.load(run_dir / "checkpoint.best.pt", weights_only=True)
    arch = json.loads(state["architecture"])
    arch["model"] = "resnet_small"  # vgg_small weights labelled as a ResNet
    state["architecture"] = json.dumps(arch)
    bad = tmp_path / "other.pt"
    torch.save(state, bad)
    assert main(["nn", "eval", str(bad), "--data", "digits", "-o", str(tmp_path / "c.png")]) == 1
    err = capsys.readouterr().err
    assert "weights of" in err and "not of this model" in err
    assert not (tmp_path / "c.png").exists()
    # a checkpoint that records no architecture (written by fit alone)
    torch.save({"model": state["model"], "architecture": "vgg"}, bad)
    assert main(["nn", "predict", str(bad), str(tmp_path / "x.png")]) == 1
    assert "records no model architecture" in capsys.readouterr().err


def test_eval_on_data_of_other_classes(run_dir: Path, tmp_path: Path, capsys) -> None:
    argv = ["nn", "eval", str(run_dir), "--data", "lfw", "-o", str(tmp_path / "c.png")]
    assert main(argv) == 1
    assert "the model takes (1, 8, 8)" in capsys.readouterr().err


def test_without_torch_the_command_names_the_extra(monkeypatch, capsys) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "torch" else real(name, *a)
    )
    assert main(["nn", "summary", "vgg_small"]) == 1
    assert "needs the deep extra: pip install 'robopercept[deep]'" in capsys.readouterr().err


def test_the_parser_does_not_import_torch() -> None:
    code = (
        "import sys\nfrom robopercept.cli.main import build_parser\n"
        "build_parser().parse_args(['nn', 'summary', 'vgg_small'])\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
