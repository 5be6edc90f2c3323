"""Shared fixtures: real images and the ../shared/data folder."""

from __future__ import annotations

import multiprocessing
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

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


@pytest.fixture(scope="module")
def librealsense() -> Iterator[ProcessPoolExecutor]:
    """A spawned worker process for tests' direct librealsense work (software devices,
    recorders, pipelines): their threads never run in the test process, where their
    teardown can abort it later (CI died so while a RealSense recording was written in
    the test process). ``librealsense.submit(fn, *args).result(timeout=...)``; ``fn``
    must be importable (a module-level function of a test module)."""
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        yield pool
