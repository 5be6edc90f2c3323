"""``robopercept batch`` on the terminal (issue 48, item 5): no Dask log line or
traceback there, one line per failed item, the Dask logs in ``OUT/batch.log``, and a
Ctrl-C at the terminal (SIGINT to the whole process group, workers included) that
ends with the one ``interrupted`` line.

Before: one unreadable input printed ``distributed.worker - ERROR - Compute Failed``
and its traceback (from the worker process), and a Ctrl-C printed a
``KeyboardInterrupt`` traceback from each worker process (and, while the cluster
started, exited 70 with ``Nanny failed to start``).

The batches run on real Dask clusters: a :func:`~robopercept.pipelines.batch.\
local_cluster` (worker processes, as ``--scheduler local``) and an in-process one on
TCP (worker threads, reached by address).
"""

from __future__ import annotations

import json
import logging
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from robopercept.errors import InputError
from robopercept.imaging import sample_image_path
from robopercept.pipelines import batch
from robopercept.pipelines.batch import LOG, MANIFEST, item_names, run_batch

distributed = pytest.importorskip("distributed")

SRC = Path(__file__).resolve().parents[2] / "src"
#: a line Dask's logging writes: ``2026-01-01 10:00:00,000 - distributed.x - LEVEL - ...``
DASK_LINE = re.compile(r"^\d{4}-\d\d-\d\d [\d:,]+ - (distributed|tornado|bokeh|asyncio)\b")


def _inputs(tmp_path: Path) -> list[Path]:
    """A readable image and one that is not an image (``bad.png``)."""
    (tmp_path / "in").mkdir()
    good, bad = tmp_path / "in" / "good.png", tmp_path / "in" / "bad.png"
    shutil.copy(sample_image_path(), good)
    bad.write_bytes(b"not a png")
    return [good, bad]


def _check_terminal(err: str, res, log: Path) -> None:
    """``err`` holds no Dask line or traceback and one line for the failed ``bad``
    (as the manifest records it); the log holds the worker's traceback."""
    assert "Traceback" not in err, err
    assert "distributed." not in err, err
    assert not [line for line in err.splitlines() if DASK_LINE.match(line)], err
    [failed] = [r for r in res.items if r["status"] == "failed"]
    assert failed["item"] == "bad" and failed["error"].startswith("FileFormatError: ")
    lines = [line for line in err.splitlines() if "failed:" in line]
    assert lines == [f"batch edges: bad ({failed['input']}) failed: {failed['error']}"], err
    text = log.read_text(encoding="utf-8")
    assert "distributed.worker - ERROR - Compute Failed" in text  # the worker's lines
    assert "Traceback" in text and "FileFormatError" in text
    assert re.search(r"bad \(.*bad\.png\): attempt 1 of 1 failed: FileFormatError", text)
    assert "robopercept batch edges started" in text and "robopercept batch edges done" in text


def test_a_failed_item_on_local_worker_processes(tmp_path, capfd) -> None:
    """Worker processes (capfd sees their stderr: they inherit this process's fd 2)."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    before = {name: list(logging.getLogger(name).handlers) for name in ("distributed", "")}
    res = run_batch("edges", inputs, out, workers=1, retries=0, progress=True)
    err = capfd.readouterr().err
    assert (res.count("ok"), res.count("failed")) == (1, 1)
    _check_terminal(err, res, out / LOG)
    text = (out / LOG).read_text(encoding="utf-8")
    # the workers' INFO lines reach the file though the cluster silences its consoles
    assert "distributed.worker - INFO - " in text and "distributed.scheduler - INFO" in text
    # this process's logging and environment are as they were
    assert {n: list(logging.getLogger(n).handlers) for n in before} == before
    assert batch._WORKER_LOGGING_ENV not in os.environ
    assert sorted(p.name for p in out.iterdir()) == sorted(["bad", LOG, MANIFEST, "good"])


def test_a_failed_item_on_worker_threads_of_a_cluster_by_address(tmp_path, capfd) -> None:
    """Worker threads in this process: their ``Compute Failed`` is logged here."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
        dashboard_address=None,
    ) as cluster:  # fmt: skip
        capfd.readouterr()  # the cluster's own start is not the batch's
        res = run_batch("edges", inputs, out, scheduler=cluster.scheduler_address, retries=0)
        err = capfd.readouterr().err
    _check_terminal(err, res, out / LOG)


def test_the_failed_line_is_printed_once_after_the_retries(tmp_path, capfd) -> None:
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
        dashboard_address=None, silence_logs=40,
    ) as cluster:  # fmt: skip
        capfd.readouterr()
        res = run_batch("edges", inputs, out, scheduler=cluster.scheduler_address, retries=2)
        err = capfd.readouterr().err
    assert [r["attempts"] for r in res.items] == [1, 3]
    assert len([line for line in err.splitlines() if "failed:" in line]) == 1, err
    assert "Traceback" not in err and "distributed." not in err
    text = (out / LOG).read_text(encoding="utf-8")
    assert [f"attempt {k} of 3 failed" in text for k in (1, 2, 3)] == [True] * 3


def test_quiet_prints_nothing_and_the_log_is_appended_to(tmp_path, capfd) -> None:
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
        dashboard_address=None, silence_logs=40,
    ) as cluster:  # fmt: skip
        capfd.readouterr()
        for again in (False, True):
            run_batch("edges", inputs, out, scheduler=cluster.scheduler_address, retries=0,
                      progress=False, resume=again)  # fmt: skip
            assert capfd.readouterr().err == ""
    text = (out / LOG).read_text(encoding="utf-8")
    assert text.count("robopercept batch edges started") == 2  # the resumed run appended


def test_item_names_leave_the_log_file_alone() -> None:
    assert item_names(["a/batch.log.png", "b/batch.json.png"]) == ["batch.log_2", "batch.json_2"]


def test_logs_to_restores_the_handlers_even_on_an_error(tmp_path) -> None:
    logger = logging.getLogger("distributed")
    console = logging.StreamHandler(sys.stderr)
    mine = logging.FileHandler(tmp_path / "mine.log", delay=True)  # a user's: it stays
    saved = list(logger.handlers), logger.propagate
    logger.handlers = [console, mine]
    try:
        with pytest.raises(KeyError), batch._logs_to(tmp_path / LOG):
            assert console not in logger.handlers and mine in logger.handlers
            assert logger.propagate is False
            logging.getLogger("distributed.worker").error("into the file")
            raise KeyError("x")
        assert logger.handlers == [console, mine]
    finally:
        logger.handlers, logger.propagate = saved
        mine.close()
    assert "distributed.worker - ERROR - into the file" in (tmp_path / LOG).read_text()


@pytest.mark.parametrize("name", ["tornado.application", "distributed.client"])
def test_a_line_of_a_logger_dask_stops_propagating_goes_to_the_file(tmp_path, capfd, name) -> None:
    """Dask's logging set-up gives each of its loggers a console handler and stops it
    propagating. Before: inside the block such a logger had no handler at all, and
    logging's last resort printed its bare line on the terminal (a Ctrl-C landing as a
    Dask call began: tornado's ``Exception in callback`` from ``distributed.utils.sync``).
    """
    logger = logging.getLogger(name)
    saved = list(logger.handlers), logger.propagate
    logger.handlers, logger.propagate = [logging.StreamHandler(sys.stderr)], False
    try:
        capfd.readouterr()
        with batch._logs_to(tmp_path / LOG):
            logger.error("Exception in callback functools.partial(cancel)")
            assert logger.propagate is True
        assert logger.propagate is False and len(logger.handlers) == 1  # put back
    finally:
        logger.handlers, logger.propagate = saved
    assert capfd.readouterr().err == ""
    text = (tmp_path / LOG).read_text(encoding="utf-8")
    assert f"{name} - ERROR - Exception in callback functools.partial(cancel)" in text


def test_the_worker_logging_configuration_sends_a_new_process_s_lines_to_the_file(
    tmp_path,
) -> None:
    """What a worker process does with the variable: Dask configures its logging from
    it when the process imports distributed."""
    [(key, value)] = batch._worker_log_config(tmp_path / LOG).items()
    assert key == f"distributed.nanny.pre-spawn-environ.{batch._WORKER_LOGGING_ENV}"
    code = (
        "import logging, distributed; "
        "logging.getLogger('distributed.worker').info('worker started'); "
        "logging.getLogger('distributed.worker').error('Compute Failed'); "
        "logging.getLogger('numba').warning('a library warning')"
    )
    env = {**os.environ, batch._WORKER_LOGGING_ENV: value}
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr
    text = (tmp_path / LOG).read_text(encoding="utf-8")
    for line in ("distributed.worker - INFO - worker started",
                 "distributed.worker - ERROR - Compute Failed",
                 "numba - WARNING - a library warning"):  # fmt: skip
        assert line in text


def test_a_users_own_worker_logging_is_kept(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv(batch._WORKER_LOGGING_ENV, "{'version': 1}")
    assert batch._worker_log_config(tmp_path / LOG) == {}


def _mask_of(pid: int) -> int:
    """The blocked-signal mask of process ``pid`` (Linux)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigBlk:"):
            return int(line.split()[1], 16)
    raise AssertionError("no SigBlk")


def _sleep() -> None:  # pragma: no cover - runs in the child
    time.sleep(30)


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="needs Linux /proc")
def test_processes_spawned_during_the_start_have_sigint_blocked() -> None:
    import multiprocessing

    sigint = 1 << (signal.SIGINT - 1)

    def start():
        # as the cluster's start: a queue (the resource tracker) and a thread that spawns
        ctx = multiprocessing.get_context("spawn")
        ctx.Queue().close()
        box = {}

        def spawn() -> None:
            box["p"] = ctx.Process(target=_sleep, daemon=True)
            box["p"].start()

        t = threading.Thread(target=spawn)
        t.start()
        t.join()
        return box["p"]

    proc = batch._without_sigint(start)
    try:
        deadline = time.monotonic() + 30
        while _mask_of(proc.pid) & sigint == 0 and time.monotonic() < deadline:
            time.sleep(0.01)  # the mask is set from the first instruction; be generous
        assert _mask_of(proc.pid) & sigint
        me = _mask_of(os.getpid())  # the main thread (the process line) keeps SIGINT
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
        assert me & sigint == 0
    finally:
        proc.kill()
        proc.join(timeout=30)
    with pytest.raises(ZeroDivisionError):  # the start's error reaches the caller
        batch._without_sigint(lambda: 1 / 0)


def _living(pgid: int) -> list[int]:
    """Processes of the group ``pgid`` that are not zombies (Linux)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            alive.append(int(stat.parent.name))
    return alive


#: ``robopercept batch`` with each item sleeping ``delay`` seconds on its worker
_DRIVER = (
    "import functools, sys\n"
    "import robopercept.pipelines.batch as b\n"
    "from robopercept.cli.main import main\n"
    "b.run_batch = functools.partial(b.run_batch, delay=float(sys.argv[1]))\n"
    "sys.exit(main(sys.argv[2:]))\n"
)


def _workers_spawned(pgid: int) -> bool:
    """Whether a worker process of the batch ``pgid`` exists (spawned, maybe starting)."""
    for pid in _living(pgid):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"spawn_main" in cmd:
            return True
    return False


def _in_log(out: Path, text: str) -> bool:
    try:
        return text in (out / LOG).read_text(encoding="utf-8")
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")
@pytest.mark.parametrize("when", ["starting", "running"])
def test_ctrl_c_at_the_terminal_prints_one_line(tmp_path, when) -> None:
    """SIGINT to the whole process group, as the terminal sends it: once a worker
    process is spawned (the cluster starting), and once the items run (the scheduler
    logged the client's connection)."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    argv = ["batch", "edges", *map(str, inputs), "-o", str(out), "--workers", "2", "--quiet"]
    child = subprocess.Popen(
        [sys.executable, "-c", _DRIVER, "30", *argv], env=env, start_new_session=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    ready = {
        "starting": lambda: _workers_spawned(child.pid),
        "running": lambda: _in_log(out, "Receive client connection"),
    }[when]
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and child.poll() is None and not ready():
            time.sleep(0.02)
        assert child.poll() is None, child.communicate()
        os.killpg(child.pid, signal.SIGINT)
        _, err = child.communicate(timeout=120)
        deadline = time.monotonic() + 60  # the cluster's processes go too
        while _living(child.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _living(child.pid), "processes of the batch were left behind"
    finally:
        if child.poll() is None or _living(child.pid):
            os.killpg(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
    assert err.strip().splitlines() == ["robopercept: interrupted"], err
    assert child.returncode == 130, err
    items = json.loads((out / MANIFEST).read_text())["items"]
    assert [r["status"] for r in items] == ["cancelled", "cancelled"]
    text = (out / LOG).read_text(encoding="utf-8")
    # "stopped (KeyboardInterrupt)" or "ended before it started: KeyboardInterrupt", and
    # no worker saw it (a worker's own traceback would be on stderr, checked above)
    mentions = [line for line in text.splitlines() if "KeyboardInterrupt" in line]
    assert mentions and all(" - robopercept.pipelines.batch - " in m for m in mentions), text


@pytest.mark.parametrize("where", ["connected", "progress bar"])
def test_a_ctrl_c_just_after_the_connection_closes_the_cluster_into_the_file(
    tmp_path, capfd, monkeypatch, where
) -> None:
    """A Ctrl-C that lands once the client has connected but before the items are
    submitted (as _connect returns, or while the progress bar is made) closes the
    client and the cluster before the logging is restored: their shutdown lines go to
    the log file. Before, the cluster was left to Dask's exit handler, whose lines
    (``Closing Nanny``, ``Closing scheduler``) reached the terminal after
    ``robopercept: interrupted`` (a flaky failure of the terminal test above)."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    made = []
    real_connect = batch._connect

    def connect(*args):
        client, cluster = real_connect(*args)
        made.append(cluster)
        if where == "connected":
            raise KeyboardInterrupt
        return client, cluster

    def bar(**kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(batch, "_connect", connect)
    if where == "progress bar":
        monkeypatch.setattr("robopercept.progress.progress_bar", bar)
    with pytest.raises(KeyboardInterrupt):
        run_batch("edges", inputs, out, workers=1, retries=0, progress=False)
    [cluster] = made
    assert cluster.status.name == "closed"
    err = capfd.readouterr().err
    assert not [line for line in err.splitlines() if DASK_LINE.match(line)], err
    text = (out / LOG).read_text(encoding="utf-8")
    assert "distributed.scheduler - INFO - Closing scheduler" in text, text
    items = json.loads((out / MANIFEST).read_text())["items"]
    assert [r["status"] for r in items] == ["cancelled", "cancelled"]
    assert batch._WORKER_LOGGING_ENV not in os.environ


@pytest.mark.parametrize("kind", ["folder", "link"])
def test_a_log_that_is_not_a_file_is_refused_before_anything_runs(tmp_path, kind) -> None:
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    out.mkdir()
    if kind == "folder":
        (out / LOG).mkdir()
    else:
        (out / LOG).symlink_to(tmp_path / "elsewhere.log")
    with pytest.raises(InputError, match=r"batch\.log: exists and is not a file.*remove it"):
        run_batch("edges", inputs, out, overwrite=True, progress=False)
    assert not (tmp_path / "elsewhere.log").exists() and not (out / MANIFEST).exists()
