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


def ctrl_c(*args: object, **kwargs: object) -> None:
    """Stand-in for a step of a run (a save, the cascade): Ctrl-C as it starts."""
    raise KeyboardInterrupt


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


def stop_after_first_epoch(argv: Sequence[str], out: Path, sig: int, timeout: float = 300) -> int:
    """Run ``robopercept *argv -o out`` in a child process, send it ``sig`` as soon as
    its first ``checkpoint.pt`` is on disk, and return its exit status."""
    import os
    import subprocess
    import sys
    import time

    code = "import sys; from robopercept.cli.main import main; sys.exit(main(sys.argv[1:]))"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *argv, "-o", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
    )
    deadline = time.monotonic() + timeout
    while not (out / "checkpoint.pt").exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"no checkpoint.pt before the run ended: {proc.stderr.read()!r}")
        time.sleep(0.02)
    proc.send_signal(sig)
    try:
        return proc.wait(timeout=timeout)
    finally:
        if proc.stderr is not None:
            proc.stderr.close()


def run_cli(args: list[str]) -> tuple[int, str]:
    """``robopercept ARGS`` in this process: its exit status and its stdout."""
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(args)
    return rc, buf.getvalue()
