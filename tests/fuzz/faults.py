"""The faults campaign: the real commands, in child processes, under the faults of
issue 47, each checked against what the command promises.

Each :class:`Fault` runs a command (``robopercept nn train`` on the digits or a task
trainer on its tiny built-in set, ``robopercept batch`` on a few images), does
something to it while it works, and checks what it left:

* ``train-sigint`` / ``train-sigterm`` (per trainer): Ctrl-C or SIGTERM right after the
  first epoch's ``checkpoint.pt`` is on disk: the command exits 130 / 143, leaves
  ``checkpoint.pt`` (loadable, at least one epoch done) and the history the trainer
  writes, no temporary file, and ``--resume`` finishes the run (exit 0, every epoch in
  the history). SIGTERM must leave the files that Ctrl-C leaves (R54).
* ``train-full-disk``: ``nn train -o`` on a small tmpfs (mounted where the machine
  allows it: root and ``mount`` permitted; else the child's ``RLIMIT_FSIZE``, with
  SIGXFSZ ignored, stands in): the command exits 1 naming the file and the full disk
  (a :class:`~robopercept.fileio.WriteError`, not torch's RuntimeError: R55) and the
  last complete ``checkpoint.pt`` stays loadable.
* ``batch-killed-worker``: one Dask worker process of ``batch --workers 2`` SIGKILLed
  mid-run: exit 0, every item ``ok`` with its outputs.
* ``batch-scheduler-gone``: the external Dask scheduler of ``batch --scheduler tcp://``
  killed mid-run: a nonzero exit that is not 70, a manifest (valid JSON) in which no
  item that did not finish is ``ok`` and no error reads ``NoneType: None`` (R56).
* ``batch-sigint-startup``: Ctrl-C while the local cluster starts: exit 130 and every
  item ``cancelled`` in the manifest, none left ``pending`` (R57).
* ``batch-sigterm``: SIGTERM mid-run: exit 143, a valid manifest whose items are
  ``ok`` (with their outputs) or ``cancelled``.

A fault is counted like any other fuzz input (:class:`~tests.fuzz.report.Tally`, group
``faults``): ``ok`` when every promise held; ``untyped`` (a broken contract) with the
broken promises as its message otherwise; ``hang`` when the command did not end in
time. :func:`run_faults_campaign` repeats the faults round-robin with a seeded delay
before the signal until its budget is spent.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import random
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.fuzz.report import Tally
from tests.fuzz.sandbox import Outcome

__all__ = [
    "FAULTS",
    "TRAINERS",
    "Fault",
    "FaultTimeout",
    "Trainer",
    "disk_kind",
    "run_fault",
    "run_faults_campaign",
]

#: seconds a faulted command (or its --resume) may take before it counts as a hang
TIMEOUT = 240.0

#: the command line of the CLI in a child process; ``ROBOPERCEPT_FUZZ_DELAY`` makes
#: every batch item sleep that long on its worker first (run_batch's ``delay``), so that
#: a fault lands while items are still running
LAUNCHER = textwrap.dedent(
    """
    import functools, os, signal, sys
    if __name__ == "__main__":
        # Ctrl-C as from a terminal: a campaign started in the background (`&` in a
        # shell without job control) has SIGINT ignored, and its children inherit that
        signal.signal(signal.SIGINT, signal.default_int_handler)
        delay = float(os.environ.get("ROBOPERCEPT_FUZZ_DELAY") or 0)
        if delay:
            import robopercept.pipelines.batch as b
            b.run_batch = functools.partial(b.run_batch, delay=delay)
        from robopercept.cli.main import main
        sys.exit(main(sys.argv[1:]))
    """
)


class FaultTimeout(Exception):
    """A faulted command (or what the fault waited for) did not come in time."""


@dataclass(frozen=True)
class Trainer:
    """A training command of the faults: its command line (without ``-o``) and the
    history file it writes each epoch.

    Parameters
    ----------
    name : str
    argv : tuple of str
        ``robopercept`` arguments of a run of at least 3 epochs.
    history : str
        The history file in the run folder (``history.csv``, ``history.json``).
    epochs : int
        The run's epochs (what the resumed run must reach).
    final : tuple of str
        Files only a finished run writes (a signal that lands after the last epoch,
        while they are written, may leave some: they are not compared).
    """

    name: str
    argv: tuple[str, ...]
    history: str
    epochs: int
    final: tuple[str, ...] = ("model.pt", "metrics.json")


#: the trainers the signal faults stop: each a tiny run of a few seconds per epoch
TRAINERS: dict[str, Trainer] = {
    "classify": Trainer(
        "classify",
        ("nn", "train", "--data", "digits", "--model", "vgg_small", "--epochs", "4",
         "--patience", "100", "--quiet"),
        "history.csv",
        4,
    ),
    "detect": Trainer(
        "detect",
        ("nn", "detect", "train", "--data", "shapes", "--images", "8", "--size", "32x32",
         "--epochs", "3", "--batch-size", "4", "--width", "4", "--quiet"),
        "history.json",
        3,
    ),
    "segment": Trainer(
        "segment",
        ("nn", "segment", "train", "--data", "shapes", "--images", "8", "--size", "32x32",
         "--epochs", "3", "--batch-size", "4", "--width", "4", "--quiet"),
        "history.json",
        3,
    ),
    "pose": Trainer(
        "pose",
        ("nn", "pose", "train", "--data", "figures", "--images", "8", "--size", "32x32",
         "--epochs", "3", "--batch-size", "4", "--width", "2", "--quiet"),
        "history.json",
        3,
    ),
    "cloud": Trainer(
        "cloud",
        ("nn", "cloud", "train", "--data", "shapes", "--shapes", "1", "--points", "32",
         "--epochs", "3", "--batch-size", "4", "--width", "0.125", "--quiet"),
        "history.json",
        3,
    ),
}  # fmt: skip


@dataclass(frozen=True)
class Fault:
    """One faulted run and its promises.

    Parameters
    ----------
    name : str
        ``"train-sigterm:classify"``, ``"batch-killed-worker"``, ...
    check : callable
        ``check(workdir, rng) -> list of str``: runs the command in ``workdir`` under
        the fault and returns the promises it broke (empty: all held); raises
        :class:`FaultTimeout` when the command did not end in time.
    defect : str
        The issue-47 defect this fault showed (``"R54"``), or ``""``.
    tags : tuple of str
        ``"slow"``: left out of ``make test`` (run by ``make fuzz``).
    """

    name: str
    check: Callable[[Path, random.Random], list[str]]
    defect: str = ""
    tags: tuple[str, ...] = field(default=())


# --------------------------------------------------------------------------- helpers


def _env(**extra: str) -> dict[str, str]:
    src = str(Path(__file__).resolve().parents[2] / "src")
    return {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "PYTHONPATH": os.pathsep.join(p for p in (src, os.environ.get("PYTHONPATH")) if p),
        "ROBOPERCEPT_FUZZ_DELAY": "0",
        **extra,
    }


def _start(workdir: Path, argv: Sequence[str], **env: str) -> subprocess.Popen[str]:
    """``robopercept *argv`` in a child process of its own session (its group is
    killed as a whole when the fault is over)."""
    script = workdir / "launch.py"
    if not script.exists():
        script.write_text(LAUNCHER)
    return subprocess.Popen(
        [sys.executable, str(script), *argv],
        cwd=workdir,
        env=_env(**env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _finish(proc: subprocess.Popen[str], timeout: float = TIMEOUT) -> tuple[int, str]:
    """Wait for ``proc``: its exit status and stderr; its whole group is killed after."""
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        _kill_group(proc)
        raise FaultTimeout(f"the command did not end within {timeout:g} s") from None
    finally:
        _kill_group(proc)
    _NOTES.append(f"exit {proc.returncode}: {_last(err)}")
    return proc.returncode, err


#: what the commands of the fault in progress said (exit status, last line): the
#: message of an ``ok`` outcome, for the campaign's log
_NOTES: list[str] = []


def _kill_group(proc: subprocess.Popen[str]) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=10)


def _run(workdir: Path, argv: Sequence[str], timeout: float = TIMEOUT) -> tuple[int, str]:
    return _finish(_start(workdir, argv), timeout)


def _wait_for(pred: Callable[[], bool], proc: subprocess.Popen[str], what: str,
              timeout: float = TIMEOUT) -> None:  # fmt: skip
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return
        if proc.poll() is not None:
            _, err = proc.communicate()
            raise _Early(f"the command ended (exit {proc.returncode}) before {what}: "
                         f"{_last(err)}")  # fmt: skip
        time.sleep(0.02)
    _kill_group(proc)
    raise FaultTimeout(f"no {what} within {timeout:g} s")


class _Early(Exception):
    """The command ended before the fault could be made (a broken promise itself)."""


def _last(err: str) -> str:
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    return lines[-1][:200] if lines else "(no message)"


def _temporaries(folder: Path) -> list[str]:
    return sorted(
        p.name for p in folder.rglob("*") if ".tmp" in p.name or p.name.startswith(".tmp")
    )


def _epochs_done(path: Path) -> int | str:
    """``epochs_done`` of a checkpoint, or why it does not load."""
    try:
        import torch

        state = torch.load(path, map_location="cpu", weights_only=True)
        return int(state.get("epochs_done", state.get("epoch", -1)))
    except Exception as exc:  # any failure to load is the finding
        return f"{type(exc).__name__}: {str(exc)[:120]}"


def _history_epochs(path: Path) -> list[int] | str:
    """The epochs a history file lists (the CSV's ``epoch`` column; the JSON's
    ``losses``, one per epoch)."""
    try:
        if path.suffix == ".csv":
            with path.open() as fh:
                return [int(r["epoch"]) for r in csv.DictReader(fh)]
        data = json.loads(path.read_text())  # the task trainers': a loss per epoch
        data = data.get("network", data)  # pose: {"network": ..., "stages": [...]}
        return list(range(1, len(data["losses"]) + 1))
    except Exception as exc:  # unreadable: the finding
        return f"{type(exc).__name__}: {str(exc)[:120]}"


# --------------------------------------------------------------------------- nn train


def _signal_after_checkpoint(trainer: Trainer, sig: signal.Signals) -> Callable[..., list[str]]:
    code = {signal.SIGINT: 130, signal.SIGTERM: 143}[sig]

    def check(workdir: Path, rng: random.Random) -> list[str]:
        out = workdir / "run"
        proc = _start(workdir, [*trainer.argv, "-o", str(out)])
        try:
            _wait_for(lambda: (out / "checkpoint.pt").exists(), proc, "checkpoint.pt")
        except _Early as exc:
            return [str(exc)]
        time.sleep(rng.uniform(0.0, 0.3))  # somewhere in the next epoch
        proc.send_signal(sig)
        status, err = _finish(proc)
        broken = []
        if status != code:
            broken.append(f"{sig.name} gave exit {status}, not {code}: {_last(err)}")
        done = _epochs_done(out / "checkpoint.pt")
        if isinstance(done, str) or done < 1:
            broken.append(f"checkpoint.pt after {sig.name}: {done}")
        history = out / trainer.history
        if not history.exists():
            broken.append(f"no {trainer.history} after {sig.name}")
        elif isinstance(done, int):
            rows = _history_epochs(history)
            if isinstance(rows, str) or len(rows) != done:
                broken.append(f"{trainer.history} after {sig.name}: {rows} for {done} epochs")
        if _temporaries(out):
            broken.append(f"temporary files left: {_temporaries(out)}")
        (workdir / "files.json").write_text(json.dumps(sorted(p.name for p in out.iterdir())))
        if broken:
            return broken
        status, err = _run(workdir, [*trainer.argv, "--resume", "-o", str(out)])
        if status != 0:
            return [f"--resume after {sig.name} gave exit {status}: {_last(err)}"]
        rows = _history_epochs(history)
        if rows != list(range(1, trainer.epochs + 1)):
            return [f"{trainer.history} after --resume: {rows}"]
        return []

    return check


def _same_files_as_ctrl_c(trainer: Trainer) -> Callable[..., list[str]]:
    """SIGTERM and Ctrl-C, each after the first checkpoint: the same files (R54)."""
    sigint = _signal_after_checkpoint(trainer, signal.SIGINT)
    sigterm = _signal_after_checkpoint(trainer, signal.SIGTERM)

    def check(workdir: Path, rng: random.Random) -> list[str]:
        names = {}
        broken = []
        for label, fn in (("SIGINT", sigint), ("SIGTERM", sigterm)):
            sub = workdir / label
            sub.mkdir()
            broken += fn(sub, rng)
            if (sub / "files.json").exists():
                names[label] = set(json.loads((sub / "files.json").read_text()))
        kept = {k: {n for n in v if n not in trainer.final and not n.endswith(".png")}
                for k, v in names.items()}  # fmt: skip
        if len(kept) == 2 and kept["SIGINT"] != kept["SIGTERM"]:
            broken.append(
                f"SIGTERM left {sorted(kept['SIGTERM'])}, Ctrl-C {sorted(kept['SIGINT'])}"
            )
        return broken

    return check


def disk_kind() -> str:
    """How the full disk is made here: ``"tmpfs"`` when a small tmpfs can be mounted
    (root, and the container permits it), else ``"rlimit"`` (the child's
    ``RLIMIT_FSIZE``)."""
    if os.geteuid() != 0 or not shutil.which("mount"):
        return "rlimit"
    with tempfile.TemporaryDirectory() as d:
        ok = _mount(Path(d), "64k")
        if ok:
            _umount(Path(d))
        return "tmpfs" if ok else "rlimit"


def _mount(path: Path, size: str) -> bool:
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                              capture_output=True, timeout=20)  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def _umount(path: Path) -> None:
    with contextlib.suppress(OSError, subprocess.TimeoutExpired):
        subprocess.run(["umount", "-l", str(path)], capture_output=True, timeout=20)


#: the file-size limit that stands in for a full disk where no tmpfs can be mounted
FSIZE_LIMIT = 600_000


def _limit_file_size() -> None:  # pragma: no cover - runs in the child
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FSIZE_LIMIT, FSIZE_LIMIT))


def _train_full_disk(workdir: Path, rng: random.Random) -> list[str]:
    """``nn train`` (digits, vgg_small: a 0.9 MB checkpoint.pt, a 0.3 MB best) into a
    1.6 MB tmpfs: the first epoch's files fit, the second's checkpoint does not."""
    trainer = TRAINERS["classify"]
    disk = workdir / "disk"
    disk.mkdir()
    mounted = disk_kind() == "tmpfs" and _mount(disk, "1600k")
    out = disk / "run"
    try:
        argv = [*trainer.argv, "-o", str(out)]
        if mounted:
            proc = _start(workdir, argv)
        else:
            proc = subprocess.Popen(
                [sys.executable, str(workdir / "launch.py"), *argv], cwd=workdir, env=_env(),
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                start_new_session=True, preexec_fn=_limit_file_size,
            )  # fmt: skip
        status, err = _finish(proc)
        broken = []
        if status != 1:
            broken.append(f"a full disk gave exit {status}, not 1: {_last(err)}")
        low = err.lower()
        if "no space left" not in low and "file too large" not in low:
            broken.append(f"the message does not name the full disk: {_last(err)}")
        if (out / "checkpoint.pt").exists():
            done = _epochs_done(out / "checkpoint.pt")
            if isinstance(done, str):
                broken.append(f"checkpoint.pt after the full disk: {done}")
        if out.exists() and _temporaries(out):
            broken.append(f"temporary files left: {_temporaries(out)}")
        return broken
    finally:
        if mounted:
            _umount(disk)


# --------------------------------------------------------------------------- batch


def _images(workdir: Path, n: int) -> Path:
    from robopercept.imaging import sample_image_path

    folder = workdir / "in"
    folder.mkdir(exist_ok=True)
    for i in range(n):
        shutil.copy(sample_image_path(), folder / f"img{i}.png")
    return folder


def _manifest(out: Path) -> dict[str, Any] | str:
    try:
        return json.loads((out / "batch.json").read_text())
    except Exception as exc:  # missing or torn: the finding
        return f"{type(exc).__name__}: {str(exc)[:120]}"


def _statuses(out: Path) -> list[str]:
    m = _manifest(out)
    return [r.get("status", "") for r in m.get("items", [])] if isinstance(m, dict) else []


def _dask_workers(pid: int) -> list[int]:
    """The Dask worker processes under ``pid`` (multiprocessing's spawned children)."""
    import psutil

    try:
        kids = psutil.Process(pid).children(recursive=True)
    except psutil.Error:
        return []
    out = []
    for k in kids:
        with contextlib.suppress(psutil.Error):
            if "spawn_main" in " ".join(k.cmdline()):
                out.append(k.pid)
    return out


def _batch_killed_worker(workdir: Path, rng: random.Random) -> list[str]:
    folder, out = _images(workdir, 6), workdir / "out"
    argv = ["batch", "edges", str(folder), "-o", str(out), "--workers", "2", "--quiet"]
    proc = _start(workdir, argv, ROBOPERCEPT_FUZZ_DELAY="1.0")
    try:
        _wait_for(lambda: len(_dask_workers(proc.pid)) >= 2 and "ok" in _statuses(out), proc,
                  "two workers and a finished item")  # fmt: skip
    except _Early as exc:
        return [str(exc)]
    victims = _dask_workers(proc.pid)
    time.sleep(rng.uniform(0.0, 0.5))
    with contextlib.suppress(ProcessLookupError):
        os.kill(victims[0], signal.SIGKILL)
    status, err = _finish(proc)
    broken = []
    if status != 0:
        broken.append(f"a killed worker gave exit {status}, not 0: {_last(err)}")
    m = _manifest(out)
    if isinstance(m, str):
        return [*broken, f"batch.json: {m}"]
    for r in m.get("items", []):
        if r.get("status") != "ok":
            broken.append(f"item {r.get('item')}: {r.get('status')} ({r.get('error')})")
        elif not all((out / o).is_file() for o in r.get("outputs", [])):
            broken.append(f"item {r.get('item')}: ok but its outputs are missing")
    return broken


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _batch_scheduler_gone(workdir: Path, rng: random.Random) -> list[str]:
    """An external scheduler and one worker; the scheduler SIGKILLed after the first
    item finished."""
    folder, out = _images(workdir, 8), workdir / "out"
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = str(Path(sys.executable).with_name("dask"))
    cluster = [
        subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                          "--no-dashboard"], env=_env(), stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True),
    ]  # fmt: skip
    try:
        time.sleep(1.0)
        cluster.append(
            subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1",
                              "--no-dashboard"], env=_env(), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
        )  # fmt: skip
        argv = ["batch", "edges", str(folder), "-o", str(out), "--scheduler", address,
                "--connect-timeout", "60", "--quiet"]  # fmt: skip
        proc = _start(workdir, argv, ROBOPERCEPT_FUZZ_DELAY="1.0")
        try:
            _wait_for(lambda: "ok" in _statuses(out), proc, "a finished item")
        except _Early as exc:
            return [str(exc)]
        time.sleep(rng.uniform(0.0, 0.5))
        _kill_group(cluster[0])  # the scheduler is gone
        status, err = _finish(proc)
        broken = []
        if status in (0, 70) or status < 0:
            broken.append(f"the scheduler gone gave exit {status}: {_last(err)}")
        m = _manifest(out)
        if isinstance(m, str):
            return [*broken, f"batch.json: {m}"]
        for r in m.get("items", []):
            if r.get("status") == "ok" and not all(
                (out / o).is_file() for o in r.get("outputs", [])
            ):
                broken.append(f"item {r.get('item')}: ok but its outputs are missing")
            if "NoneType: None" in str(r.get("error")):
                broken.append(f"item {r.get('item')}: error {r.get('error')!r}")
        return broken
    finally:
        for p in cluster:
            _kill_group(p)  # type: ignore[arg-type]


def _batch_sigint_startup(workdir: Path, rng: random.Random) -> list[str]:
    """Ctrl-C as soon as the manifest exists, while the local cluster starts (R57)."""
    folder, out = _images(workdir, 4), workdir / "out"
    argv = ["batch", "edges", str(folder), "-o", str(out), "--workers", "1", "--quiet"]
    proc = _start(workdir, argv)
    try:
        _wait_for(lambda: (out / "batch.json").exists() or bool(_dask_workers(proc.pid)), proc,
                  "the manifest or a worker")  # fmt: skip
    except _Early as exc:
        return [str(exc)]
    time.sleep(rng.uniform(0.0, 0.05))
    proc.send_signal(signal.SIGINT)
    status, err = _finish(proc)
    broken = []
    if status != 130:
        broken.append(f"Ctrl-C during start-up gave exit {status}, not 130: {_last(err)}")
    m = _manifest(out)
    if isinstance(m, str):
        return [*broken, f"batch.json: {m}"]
    left = sorted({r.get("status") for r in m.get("items", [])} - {"ok", "cancelled"})
    if left:
        broken.append(f"items left {left} after Ctrl-C (expected cancelled or ok)")
    return broken


def _batch_sigterm(workdir: Path, rng: random.Random) -> list[str]:
    folder, out = _images(workdir, 6), workdir / "out"
    argv = ["batch", "edges", str(folder), "-o", str(out), "--workers", "1", "--quiet"]
    proc = _start(workdir, argv, ROBOPERCEPT_FUZZ_DELAY="1.0")
    try:
        _wait_for(lambda: "ok" in _statuses(out), proc, "a finished item")
    except _Early as exc:
        return [str(exc)]
    time.sleep(rng.uniform(0.0, 0.5))
    proc.send_signal(signal.SIGTERM)
    status, err = _finish(proc)
    broken = []
    if status != 143:
        broken.append(f"SIGTERM gave exit {status}, not 143: {_last(err)}")
    m = _manifest(out)
    if isinstance(m, str):
        return [*broken, f"batch.json: {m}"]
    for r in m.get("items", []):
        if r.get("status") not in ("ok", "cancelled"):
            broken.append(f"item {r.get('item')}: {r.get('status')} after SIGTERM")
        elif r.get("status") == "ok" and not all((out / o).is_file() for o in r.get("outputs", [])):
            broken.append(f"item {r.get('item')}: ok but its outputs are missing")
    return broken


# --------------------------------------------------------------------------- the table

#: every fault, by name (the defect a fault shows while it is open, see :class:`Fault`)
FAULTS: dict[str, Fault] = {
    "train-sigint:classify": Fault(  # also the first half of train-sigterm:classify
        "train-sigint:classify",
        _signal_after_checkpoint(TRAINERS["classify"], signal.SIGINT),
        tags=("slow",),
    ),
    "train-sigterm:classify": Fault(
        "train-sigterm:classify", _same_files_as_ctrl_c(TRAINERS["classify"]), "R54"
    ),
    **{
        f"train-sigterm:{t}": Fault(
            f"train-sigterm:{t}", _same_files_as_ctrl_c(TRAINERS[t]), "R54", ("slow",)
        )
        for t in ("detect", "segment", "pose", "cloud")
    },
    "train-full-disk": Fault("train-full-disk", _train_full_disk, "R55"),
    "batch-killed-worker": Fault("batch-killed-worker", _batch_killed_worker),
    "batch-scheduler-gone": Fault("batch-scheduler-gone", _batch_scheduler_gone, "R56"),
    "batch-sigint-startup": Fault("batch-sigint-startup", _batch_sigint_startup, "R57"),
    "batch-sigterm": Fault("batch-sigterm", _batch_sigterm),
}


def run_fault(name: str, seed_: int = 0, workdir: Path | None = None) -> Outcome:
    """Run fault ``name`` once and classify it.

    Parameters
    ----------
    name : str
        A key of :data:`FAULTS`.
    seed_ : int
        Seeds the delay before the signal.
    workdir : Path, optional
        Where the command runs and writes (default: a temporary folder, removed after).

    Returns
    -------
    Outcome
        ``ok`` (every promise held), ``untyped`` (the broken promises in
        ``message``, the first in ``error``) or ``hang``.
    """
    fault = FAULTS[name]
    rng = random.Random(f"{seed_}:{name}")
    _NOTES.clear()
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="robopercept-fault-") as tmp:
        work = Path(workdir) if workdir is not None else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        (work / "launch.py").write_text(LAUNCHER)
        try:
            broken = fault.check(work, rng)
        except FaultTimeout as exc:
            return Outcome("hang", "timeout", str(exc), time.monotonic() - t0, 0.0)
    seconds = time.monotonic() - t0
    if not broken:
        return Outcome("ok", "", " | ".join(_NOTES)[:300], seconds, 0.0)
    return Outcome("untyped", "promise", "; ".join(broken)[:300], seconds, 0.0)


def run_faults_campaign(
    budget_s: float,
    seed_: int,
    *,
    names: Sequence[str] | None = None,
    log: Callable[[str], None] | None = None,
) -> list[Tally]:
    """Run the faults round-robin (each round with new delays) until ``budget_s``
    seconds have passed; every fault runs at least once.

    Parameters
    ----------
    budget_s : float
    seed_ : int
    names : sequence of str, optional
        Keys of :data:`FAULTS` (default all).
    log : callable, optional

    Returns
    -------
    list of Tally
        One per fault, group ``faults``.
    """
    start = time.monotonic()
    chosen = list(names or FAULTS)
    tallies = {n: Tally(f"fault: {n}", "faults") for n in chosen}
    round_ = 0
    while True:
        for n in chosen:
            if round_ and time.monotonic() - start >= budget_s:
                break
            outcome = run_fault(n, seed_ + round_)
            tallies[n].add(outcome, "", f"round {round_}")
            if log is not None:
                log(f"fault {n}: {outcome.kind} {outcome.message[:120]}")
        round_ += 1
        if time.monotonic() - start >= budget_s:
            break
    return list(tallies.values())
