"""Repository-wide pytest hooks (tests/ and the doctests of src/robopercept).

Crash marker: the node id of the running test is written to ``.pytest-running`` before
it starts and the file is removed when the session ends. A process that dies inside a
test (a C-level ``abort()``, a segfault) runs no Python afterwards, so the file is what
says which test it was; ``.ci/run`` prints it after a failed ``make test``, at the end of
the log, where a truncated CI log still shows it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

_MARKER = Path(__file__).resolve().parent / ".pytest-running"


def pytest_runtest_logstart(nodeid: str, location: tuple[str, int | None, str]) -> None:
    _MARKER.write_text(nodeid + "\n", encoding="utf-8")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    _MARKER.unlink(missing_ok=True)
