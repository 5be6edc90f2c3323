"""The sandbox counts every way a call can end, and survives the bad ones."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from robopercept.errors import InputError
from tests.fuzz.sandbox import Outcome, Sandbox, array_bytes, resolve
from tests.fuzz.strategies import LAYOUTS, Layout, _cast


# module-level targets: the worker receives them pickled by reference
def segfault() -> None:
    """Read address 0: SIGSEGV."""
    import ctypes

    ctypes.string_at(0)


def sleep(seconds: float) -> None:
    import time

    time.sleep(seconds)


def allocate(megabytes: int) -> int:
    """Hold ``megabytes`` MiB of touched memory, return its size in bytes."""
    a = np.ones(megabytes * 1024 * 1024, np.uint8)
    return int(a.sum())


def raise_value_error() -> None:
    raise ValueError("plain ValueError")


def raise_input_error() -> None:
    raise InputError("sigma must be > 0; got -1: pass --sigma 1.5")


def raise_long(n: int) -> None:
    raise KeyError("k" * n)


def exit_now() -> None:
    import os

    os._exit(3)


@pytest.fixture(scope="module")
def box():
    with Sandbox(timeout=3.0, memory_mb=1024.0) as b:
        yield b


def test_ok_returns_time_and_array_bytes(box):
    out = box.run("numpy:zeros", ((10, 10),))
    assert out.kind == "ok" and out.error == "" and out.message == ""
    assert out.result_bytes == 800  # 100 float64
    assert 0 <= out.seconds < 3


def test_typed_and_untyped_errors(box):
    typed = box.run(raise_input_error)
    assert (typed.kind, typed.error) == ("typed", "InputError")
    assert typed.message == "sigma must be > 0; got -1: pass --sigma 1.5"
    assert typed.where.endswith("in raise_input_error")
    untyped = box.run(raise_value_error)
    assert (untyped.kind, untyped.error, untyped.message) == (
        "untyped",
        "ValueError",
        "plain ValueError",
    )
    # string targets: function, class method; a robopercept guard raises typed
    assert box.run("robopercept._checks:check_positive", (-1.0, "sigma")).kind == "typed"
    assert box.run("math:sqrt", (-1.0,)).kind == "untyped"


def test_message_is_cut_at_300_characters(box):
    out = box.run(functools.partial(raise_long, 1000))
    assert out.kind == "untyped" and out.error == "KeyError" and len(out.message) == 300


def test_segfault_is_a_crash_and_the_sandbox_goes_on(box):
    spawns = box.spawns
    out = box.run(segfault)
    assert (out.kind, out.error) == ("crash", "SIGSEGV")
    assert "Segmentation fault" in out.message  # faulthandler's last words
    assert box.run("math:sqrt", (9.0,)).kind == "ok"  # a fresh worker answers
    assert box.spawns == spawns + 1


def test_exit_is_a_crash(box):
    out = box.run(exit_now)
    assert (out.kind, out.error) == ("crash", "exit 3")
    assert box.run("math:sqrt", (9.0,)).kind == "ok"


def test_sleep_is_a_hang_killed_at_the_timeout(box):
    import time

    t0 = time.perf_counter()
    out = box.run(sleep, (60.0,))
    elapsed = time.perf_counter() - t0
    assert (out.kind, out.error) == ("hang", "timeout")
    assert 3.0 <= out.seconds and elapsed < 8.0  # killed at 3 s, not after 60
    assert box.run(sleep, (0.01,), timeout=1.0).kind == "ok"


def test_huge_allocation_is_memory(box):
    out = box.run(allocate, (4096,))  # 4 GiB, the worker may add 1 GiB
    assert (out.kind, out.error) == ("memory", "MemoryError")
    assert box.run("math:sqrt", (9.0,)).kind == "ok"  # the worker survived it


def test_peak_of_a_100_mb_allocation(box):
    out = box.run(allocate, (100,))
    assert out.kind == "ok"
    # 100 MiB of ones, plus the sum's temporaries (NumPy reduces in 8 KiB buffers)
    assert 99.5 <= out.peak_mb <= 102
    assert 90 <= out.rss_mb <= 110  # the pages were touched


def test_outcome_defaults_and_bad_targets(box):
    o = Outcome("ok", "", "", 0.1, 1.0)
    assert (o.rss_mb, o.where, o.result_bytes) == (0.0, "", 0)
    with pytest.raises(ValueError, match="module:name"):
        resolve("math.sqrt")
    assert resolve("math:sqrt")(4.0) == 2.0
    assert box.run("math:no_such_function").error == "AttributeError"
    with pytest.raises(ValueError, match="timeout"):
        Sandbox(timeout=0)


def test_array_bytes_counts_views_once():
    a = np.zeros(10)
    assert array_bytes([a, a[2:], {"k": np.zeros((2, 2), np.uint8)}, "text"]) == 84
    assert array_bytes(3.0) == 0


def note_pid(path: str) -> None:
    """Append this process's id to ``path``."""
    import os

    with open(path, "a") as fh:
        fh.write(f"{os.getpid()}\n")


def test_parallel_kernels_run_after_the_caller_used_openmp(box):
    # numba's OpenMP layer kills a child forked from a process that has run a parallel
    # region ("fork() called from a process already using GNU OpenMP"): the workers
    # come from a clean fork server, so this holds whatever the test session ran before
    from robopercept.depth.stereo import census_transform

    image = np.arange(256, dtype=np.uint8).reshape(16, 16)
    here = census_transform(image)  # a parallel kernel in this process
    # loading numba and the kernel in a fresh worker took over the module's 3 s on a
    # loaded CI machine: this test is about the worker surviving, not its speed
    out = box.run("robopercept.depth.stereo:census_transform", (image,), timeout=60.0)
    assert (out.kind, out.error) == ("ok", ""), out
    assert out.result_bytes == here.nbytes


def test_warm_calls_are_replayed_in_every_new_worker(tmp_path):
    log = tmp_path / "pids.txt"
    with Sandbox(timeout=5.0) as b:
        assert [o.kind for o in b.warm([(note_pid, (str(log),), {})])] == ["ok"]
        assert b.run(segfault).kind == "crash"
        assert b.run("math:sqrt", (4.0,)).kind == "ok"  # a new worker, warmed first
        pids = log.read_text().split()
        assert len(pids) == 2 and pids[0] != pids[1]
        b.warm([])
        assert b.run(segfault).kind == "crash" and b.run("math:sqrt", (4.0,)).kind == "ok"
        assert len(log.read_text().split()) == 2 and b.spawns == 3


@pytest.mark.parametrize("dtype", ["float64", "float32", "uint8", "int16", "bool"])
@pytest.mark.parametrize("layout", LAYOUTS)
def test_every_layout_of_a_0d_array_is_a_0d_array(dtype, layout):
    """A 0-d value in any layout materializes as a 0-d ndarray (a NumPy scalar from the
    integer cast once made "readonly" raise 'Cannot set flags on array scalars' in the
    harness, which the reports counted as the target's untyped error)."""
    a = Layout(_cast(np.array(3.7), dtype), layout).make()
    assert isinstance(a, np.ndarray) and a.shape == ()
    assert a.flags.writeable == (layout != "readonly")  # 0-d: nothing to broadcast
