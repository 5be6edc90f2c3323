"""``robopercept nn train --resume`` under other options or from a damaged checkpoint
(issue 47: R42, R49): exit 2 naming the differing flags and ``--overwrite``, or exit 1
naming the file and the damaged entry; never exit 70, never a silent other run."""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.nn.train.checkpoint import save_checkpoint  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

TRAIN = ["nn", "train", "--data", "digits", "--model", "vgg_small", "--quiet"]
TRAIN += ["--epochs", "1", "--batch-size", "128", "--patience", "5"]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("nn_resume") / "run"
    assert main([*TRAIN, "-o", str(out)]) == 0
    return out


@pytest.fixture
def copy(run: Path, tmp_path: Path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(run, out)
    return out


@pytest.mark.parametrize(
    ("flags", "named"),
    [
        (["--optimizer", "sgd"], ["--optimizer"]),  # R42: was KeyError, exit 70
        (["--schedule", "step"], ["--schedule"]),  # R42: was KeyError, exit 70
        (["--seed", "1"], ["--seed"]),  # R42: another split, accepted silently
        (["--seed", "2", "--lr", "0.01", "--augment"], ["--seed", "--lr", "--augment"]),
        (["--split", "0.6,0.2,0.2"], ["--split"]),
        (["--dropout", "0.5"], ["--dropout"]),
    ],
)
def test_resume_under_other_options_exits_2(copy: Path, capsys, flags, named) -> None:
    before = (copy / "checkpoint.pt").read_bytes()
    capsys.readouterr()
    assert main([*TRAIN, *flags, "--resume", "-o", str(copy)]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err
    for flag in named:
        assert flag in err, err
    assert (copy / "checkpoint.pt").read_bytes() == before


def test_resume_may_extend_and_move(copy: Path, capsys) -> None:
    # --epochs (more), --device and the output flags may change on resume
    argv = [a for a in TRAIN if a != "--quiet"]
    argv[argv.index("--epochs") + 1] = "2"
    assert main([*argv, "--device", "cpu", "--json", "--resume", "-o", str(copy)]) == 0
    with (copy / "history.csv").open() as f:
        assert [r["epoch"] for r in csv.DictReader(f)] == ["1", "2"]


@pytest.mark.parametrize(
    ("entry", "value"),
    [
        ("optimizer", "adamw"),
        ("scheduler", {"last_epoch": "x"}),
        ("epochs_done", 1.5),
        ("history", {"epoch": "1"}),
        ("torch_rng_state", [1, 2, 3]),
        ("generators", {"shuffle": "x"}),
    ],
)
def test_resume_from_a_damaged_checkpoint_exits_1(copy: Path, capsys, entry, value) -> None:
    # R49: TypeError, AttributeError, ValueError or KeyError (exit 70) before
    ck = copy / "checkpoint.pt"
    state = torch.load(ck, weights_only=True)
    state[entry] = value
    save_checkpoint(ck, state)
    capsys.readouterr()
    assert main([*TRAIN, "--epochs", "2", "--resume", "-o", str(copy)]) == 1
    err = capsys.readouterr().err
    assert str(ck) in err and f"'{entry}'" in err and "--overwrite" in err, err
    assert "internal error" not in err
