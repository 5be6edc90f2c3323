"""What every ``nn ... train`` command's tests check of its run folder (issue 45): a
second run into a folder holding one exits 2 naming ``--resume`` and ``--overwrite``;
Ctrl-C after the first epoch keeps that epoch and ``--resume`` ends with the weights
of an uninterrupted run."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.nn.train import loop  # noqa: E402


@contextlib.contextmanager
def ctrl_c_after_first_epoch() -> Iterator[list[int]]:
    """Raise KeyboardInterrupt (what Ctrl-C raises) right after the loop has written
    the first epoch's ``checkpoint.pt``: the moment a user's Ctrl-C during epoch 2
    finds. Yields a list holding the number of checkpoints written."""
    real = loop.save_checkpoint
    written = [0]

    def save_then_stop(path, state):  # type: ignore[no-untyped-def]
        out = real(path, state)
        if Path(path).name == "checkpoint.pt":
            written[0] += 1
            raise KeyboardInterrupt
        return out

    loop.save_checkpoint = save_then_stop  # type: ignore[assignment]
    try:
        yield written
    finally:
        loop.save_checkpoint = real  # type: ignore[assignment]


def weights(path: Path) -> dict[str, torch.Tensor]:
    """The ``model`` tensors of a saved model or checkpoint."""
    return torch.load(path, map_location="cpu", weights_only=True)["model"]


def check_run_folder_rules(
    argv: Sequence[str], tmp_path: Path, model_file: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """The three rules for one training command ``argv`` (without ``-o``; at least 2
    epochs): refusal of an existing run (exit 2, both flags named, nothing changed),
    ``--overwrite`` accepted, and Ctrl-C after epoch 1 then ``--resume`` giving the
    uninterrupted run's weights in ``model_file``."""
    whole = tmp_path / "whole"
    assert main([*argv, "-o", str(whole)]) == 0
    before = (whole / "checkpoint.pt").read_bytes()
    capsys.readouterr()
    assert main([*argv, "-o", str(whole)]) == 2
    err = capsys.readouterr().err
    assert "--resume" in err and "--overwrite" in err
    assert (whole / "checkpoint.pt").read_bytes() == before
    part = tmp_path / "part"
    with ctrl_c_after_first_epoch() as written:
        assert main([*argv, "-o", str(part)]) == 130
    assert written == [1] and (part / "checkpoint.pt").exists()
    assert main([*argv, "--resume", "-o", str(part)]) == 0
    a, b = weights(whole / model_file), weights(part / model_file)
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), f"{k} differs between the resumed and the whole run"
    assert main([*argv, "--overwrite", "-o", str(part)]) == 0
