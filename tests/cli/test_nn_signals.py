"""SIGTERM during training leaves the files Ctrl-C leaves (issue 47, R54), for every
trainer: ``nn train`` (also on two processes, ``--nproc 2``, where the launcher's ranks
died on SIGTERM without writing ``history.csv``), ``nn detect|segment|pose|cloud
train``. ``nn train``'s single-process SIGINT and SIGTERM runs are in
tests/cli/test_nn_cli.py (test_a_real_signal_keeps_the_last_epoch)."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from tests.cli.nn_runs import ctrl_c_after_first_epoch  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

#: each trainer, long enough (50 epochs) that the signal finds it training
TRAINERS = {
    "detect": [
        *("detect", "train", "--data", "digits", "--images", "8", "--size", "64x64"),
        *("--model", "fcos", "--width", "4", "--batch-size", "4"),
    ],
    "segment": [
        *("segment", "train", "--data", "shapes", "--images", "10", "--size", "64x64"),
        *("--model", "naive", "--width", "4", "--batch-size", "4"),
    ],
    "pose": [
        *("pose", "train", "--data", "figures", "--images", "12", "--size", "64x64"),
        *("--model", "hrnet", "--width", "4", "--batch-size", "4"),
    ],
    "cloud": [
        *("cloud", "train", "--data", "shapes", "--shapes", "3", "--points", "64"),
        *("--width", "0.125", "--batch-size", "8"),
    ],
}
COMMON = ["--seed", "0", "--epochs", "50", "--quiet"]


def _stop(argv: list[str], out: Path, sig: int, timeout: float = 240) -> int:
    """``robopercept nn ARGV -o OUT`` in a child process (its own session, killed whole
    if the test fails), ``sig`` sent to it alone once its first checkpoint.pt is on
    disk; its exit status."""
    code = "import sys; from robopercept.cli.main import main; sys.exit(main(sys.argv[1:]))"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", code, "nn", *argv, "-o", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + timeout
        while not (out / "checkpoint.pt").exists():
            if proc.poll() is not None:
                assert proc.stderr is not None
                raise AssertionError(f"the run ended first: {proc.stderr.read()[-2000:]!r}")
            if time.monotonic() > deadline:
                raise AssertionError(f"no checkpoint.pt within {timeout} s")
            time.sleep(0.05)
        proc.send_signal(sig)
        return proc.wait(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        assert proc.stderr is not None
        proc.stderr.close()


def _names(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("trainer", list(TRAINERS))
def test_sigterm_keeps_what_ctrl_c_keeps(trainer: str, tmp_path: Path) -> None:
    argv = [*TRAINERS[trainer], *COMMON]
    with ctrl_c_after_first_epoch():  # what SIGINT raises, right after epoch 1
        assert main(["nn", *argv, "-o", str(tmp_path / "int")]) == 130
    assert _stop(argv, tmp_path / "term", signal.SIGTERM) == 143
    assert _names(tmp_path / "term") == _names(tmp_path / "int")
    assert {"checkpoint.pt", "history.json"} <= set(_names(tmp_path / "term"))


def test_sigterm_to_a_two_process_run_keeps_the_history(tmp_path: Path) -> None:
    # the launcher stops its ranks with SIGTERM; rank 0 now writes history.csv first
    argv = ["train", "--data", "digits", "--model", "vgg_small", "--nproc", "2", *COMMON]
    argv += ["--patience", "100"]
    out = tmp_path / "run"
    assert _stop(argv, out, signal.SIGTERM) == 143
    assert _names(out) == ["checkpoint.best.pt", "checkpoint.pt", "history.csv"]
    done = torch.load(out / "checkpoint.pt", weights_only=True)["epochs_done"]
    with (out / "history.csv").open() as f:
        assert len(list(csv.DictReader(f))) == done >= 1
