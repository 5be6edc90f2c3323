"""The first-use compile notice and the parallel warmup runner (issue 22)."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest
from numba import njit

from robopercept.jit import CompileNotice, run_in_workers


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _fresh_kernel():
    @njit(cache=False)
    def total(x):  # pragma: no cover - compiled
        s = 0.0
        for v in x:
            s += v
        return s

    return total


def test_log_says_compiling_once_and_the_total() -> None:
    log = io.StringIO()
    kernel = _fresh_kernel()
    with CompileNotice("edges", 18.0, file=log) as notice:
        assert kernel(np.ones(4)) == 4.0  # compiles
        assert kernel(np.ones(5)) == 5.0  # same types: no second compilation
    assert notice.compiled == 1 and notice.seconds > 0
    lines = log.getvalue().splitlines()
    assert lines[0] == "robopercept: compiling kernels for edges (first use only, about 18 s) ..."
    assert lines[1].startswith("robopercept: compiled kernels in ")
    assert "robopercept warmup" in lines[1] and len(lines) == 2


def test_nothing_compiled_nothing_said() -> None:
    log = io.StringIO()
    kernel = _fresh_kernel()
    kernel(np.ones(2))  # compiled outside
    with CompileNotice("x", file=log) as notice:
        kernel(np.ones(3))
    assert notice.compiled == 0 and log.getvalue() == ""


def test_disabled_counts_but_prints_nothing() -> None:
    log = io.StringIO()
    with CompileNotice("x", file=log, enabled=False) as notice:
        _fresh_kernel()(np.ones(2))
    assert notice.compiled == 1 and log.getvalue() == ""


def test_listener_is_removed_on_exit() -> None:
    with CompileNotice("x", enabled=False) as notice:
        pass
    _fresh_kernel()(np.ones(2))
    assert notice.compiled == 0


def test_terminal_gets_a_spinner_that_is_cleared() -> None:
    term = _Terminal()
    with CompileNotice("stereo", 65.0, file=term) as notice:
        notice._on_start()  # a compilation as numba reports it (start ... end)
        deadline = time.monotonic() + 10.0
        while "compiling kernels for stereo" not in term.getvalue():
            assert time.monotonic() < deadline, "no spinner within 10 s"
            time.sleep(0.05)
        notice._on_end()
    out = term.getvalue()
    assert "\r" in out and "(first use only, about 65 s): " in out
    assert "\r\x1b[K" in out  # the spinner line was cleared before the closing line
    assert out.rsplit("\x1b[K", 1)[1].startswith("robopercept: compiled kernels in")


def test_message_without_estimate() -> None:
    assert CompileNotice("flow").message() == "compiling kernels for flow (first use only)"


def _square(x: int) -> int:
    print(f"squaring {x}")
    if x < 0:
        raise ValueError("negative\nsecond line")
    return x * x


@pytest.mark.parametrize("jobs", [1, 2])
def test_run_in_workers(jobs: int) -> None:
    tasks = [("a", _square, (3,)), ("b", _square, (-1,)), ("c", _square, (4,))]
    res = run_in_workers(tasks, jobs=jobs, progress=False)
    assert [r.name for r in res] == ["a", "b", "c"]  # the order of the tasks
    assert [r.result for r in res] == [9, None, 16]
    assert res[1].error == "ValueError: negative" and res[0].error == ""
    assert res[0].output == "squaring 3"
    assert all(r.seconds >= 0 and r.compiled >= 0 for r in res)
