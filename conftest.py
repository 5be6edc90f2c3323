"""Repository-wide pytest hooks (tests/ and the doctests of src/robopercept).

Crash marker: the node id of the running test is written to ``.pytest-running`` before
it starts and the file is removed when the session ends. A process that dies inside a
test (a C-level ``abort()``, a segfault) runs no Python afterwards, so the file is what
says which test it was; ``.ci/run`` prints it after a failed ``make test``, at the end of
the log, where a truncated CI log still shows it.

Crash traceback: :mod:`faulthandler` writes the Python stacks of every thread at such a
crash to ``.pytest-crash.txt`` instead of stderr (where CPython 3.12+ follows them with
a list of extension modules that pushes them out of a log's tail); ``.ci/run`` prints
the stacks last, after the marker.

Under pytest-xdist (``make test`` runs two workers) every worker appends to the one
crash file the controller opened, and xdist itself names a test whose worker died
("worker 'gw0' crashed while running ...").
"""

from __future__ import annotations

import faulthandler
import os
from pathlib import Path
from typing import IO

import pytest

# Under pytest-xdist the two workers share the two cores: OpenMP threads (torch's) that
# wait by spinning steal the other worker's core, and a 2-thread training test then runs
# several times slower (393 s instead of 25 s for the digits ResNet in one CI run);
# waiting threads that sleep give the core back. Read by libgomp when torch loads, after
# this file; a policy set by the caller is kept.
if "PYTEST_XDIST_WORKER" in os.environ:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

_ROOT = Path(__file__).resolve().parent
_MARKER = _ROOT / ".pytest-running"
_CRASH = _ROOT / ".pytest-crash.txt"
_crash_file: IO[str] | None = None


#: the longest test files, longest first (seconds in a two-worker CI run, 2026-11-29):
#: collected first so that the workers, which take whole files in collection order, start
#: on them and finish together (the longest-first rule of scheduling)
HEAVY_FIRST = (
    "tests/fuzz/test_api_fuzz.py",  # ~330 s, nn alone ~200 s
    "tests/pipelines/test_plane_tracking.py",  # ~220 s
    "tests/pipelines/test_plane_tracking_motion.py",  # ~210 s
    "tests/calibration/test_handeye.py",
    "tests/nn/train/test_distributed.py",
    "tests/nn/classification/test_real_data.py",
    "tests/calibration/test_intrinsics.py",
    "tests/pipelines/test_batch.py",
    "tests/learning/test_hog_detector.py",
    "tests/calibration/test_circles.py",
    "tests/fuzz/test_readers_fuzz.py",
)


def pytest_collection_modifyitems(
    session: pytest.Session, config: pytest.Config, items: list[pytest.Item]
) -> None:
    """Under pytest-xdist, the files of :data:`HEAVY_FIRST` first, in that order; every
    file keeps its tests' order, and the rest keep theirs."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return
    rank = {name: k for k, name in enumerate(HEAVY_FIRST)}

    def key(item: pytest.Item) -> int:
        path = Path(str(item.path)).resolve()
        rel = path.relative_to(_ROOT).as_posix() if path.is_relative_to(_ROOT) else ""
        return rank.get(rel, len(rank))

    items.sort(key=key)  # stable: the order inside each rank is kept


@pytest.hookimpl(trylast=True)
def pytest_configure(config: pytest.Config) -> None:
    # trylast: after pytest's own faulthandler plugin, whose stderr target this replaces
    global _crash_file
    if _crash_file is None:
        worker = "PYTEST_XDIST_WORKER" in os.environ  # the controller opened it first
        _crash_file = _CRASH.open("a" if worker else "w", encoding="utf-8")
        faulthandler.enable(file=_crash_file, all_threads=True)


def pytest_runtest_logstart(nodeid: str, location: tuple[str, int | None, str]) -> None:
    _MARKER.write_text(nodeid + "\n", encoding="utf-8")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    _MARKER.unlink(missing_ok=True)


def pytest_unconfigure(config: pytest.Config) -> None:
    global _crash_file
    if _crash_file is not None:
        faulthandler.disable()
        _crash_file.close()
        _crash_file = None
        if _CRASH.exists() and _CRASH.stat().st_size == 0:
            _CRASH.unlink()
