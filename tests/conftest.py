"""Shared fixtures: real images and the ../shared/data folder."""

from __future__ import annotations

import multiprocessing
import signal
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def data_path(*parts: str) -> Path:
    """Path into ../shared/data; skips the test (with the reason) if it is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data not available: {p} (the ../shared/data folder is absent)")
    return p


@pytest.fixture(scope="session")
def camera() -> np.ndarray:
    """skimage's 512x512 'camera' (uint8 gray), shipped inside scikit-image."""
    from skimage import data

    return data.camera()


@pytest.fixture(scope="session")
def astronaut() -> np.ndarray:
    """skimage's 512x512 'astronaut' (uint8 RGB)."""
    from skimage import data

    return data.astronaut()


@pytest.fixture(scope="session")
def graf() -> np.ndarray:
    """Oxford affine 'graf' img1 (real photo, RGB uint8) from ../shared/data."""
    from robopercept.imaging import read_image

    return read_image(data_path("features", "oxford_affine", "graf", "img1.png"), mode="rgb")


@pytest.fixture
def rng() -> np.random.Generator:
    """A fresh seeded generator per test, so no test's data depends on which tests ran
    before it."""
    return np.random.default_rng(12345)


# scikit-learn's bundled datasets (the learning reference), loaded once
@pytest.fixture(scope="session")
def iris() -> tuple[np.ndarray, np.ndarray]:
    from sklearn.datasets import load_iris

    return load_iris(return_X_y=True)


@pytest.fixture(scope="session")
def digits() -> tuple[np.ndarray, np.ndarray]:
    from sklearn.datasets import load_digits

    return load_digits(return_X_y=True)


@pytest.fixture
def torch_one_thread():
    """One torch intra-op thread for the test: the 2-core CI machine runs other jobs
    beside the tests, and two contending threads make training several times slower."""
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


class LibrealsenseWorker:
    """One spawned worker process for librealsense work, respawned when a call crashed
    it: librealsense itself can corrupt its heap and abort (CI once printed
    ``malloc_consolidate(): invalid chunk size`` from a pipeline on the real bag), and the
    test that made the call fails, but the tests after it get a fresh worker instead of
    all failing with ``BrokenProcessPool``."""

    def __init__(self) -> None:
        self._pool = self._spawn()

    @staticmethod
    def _spawn() -> ProcessPoolExecutor:
        return ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        """``fn(*args, **kwargs)`` in the worker (a new one if the last call crashed it)."""
        try:
            return self._pool.submit(fn, *args, **kwargs)
        except BrokenProcessPool:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = self._spawn()
            return self._pool.submit(fn, *args, **kwargs)

    def shutdown(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


@pytest.fixture(scope="module")
def librealsense() -> Iterator[LibrealsenseWorker]:
    """A spawned worker process for tests' direct librealsense work (software devices,
    recorders, pipelines): their threads never run in the test process, where their
    teardown can abort it later (CI died so while a RealSense recording was written in
    the test process). ``librealsense.submit(fn, *args).result(timeout=...)``; ``fn``
    must be importable (a module-level function of a test module)."""
    worker = LibrealsenseWorker()
    try:
        yield worker
    finally:
        worker.shutdown()


@pytest.fixture(autouse=True)
def python_sigint_handler():
    """Python's own SIGINT handler for each test, whatever pytest inherited: a shell
    starts background jobs with SIGINT ignored (``cmd &`` without job control), and
    StopSignals rightly leaves an ignored signal alone, as do children (plane-track,
    batch), which inherit SIG_IGN through exec: the Ctrl-C tests failed when the suite
    ran in the background. A Python handler is not inherited through exec: children
    start with SIGINT at its default and install their own."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)
