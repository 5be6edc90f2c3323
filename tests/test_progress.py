"""Progress bars: tqdm on a terminal, a few summary lines in a log (issue 22)."""

from __future__ import annotations

import io

import pytest

from robopercept.progress import SummaryProgress, is_terminal, progress_bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_gets_quarter_lines_and_a_closing_line() -> None:
    log = io.StringIO()
    bar = progress_bar(total=300, desc="plane tracking", unit="frame", file=log)
    assert isinstance(bar, SummaryProgress)
    for _ in range(300):
        bar.update(1)
    bar.close()
    bar.close()  # once only
    lines = log.getvalue().splitlines()
    assert len(lines) == 4  # 25 %, 50 %, 75 %, done: not one line per update
    assert lines[0].startswith("plane tracking: 75/300 frame (25 %)")
    assert lines[1].startswith("plane tracking: 150/300 frame (50 %)")
    assert lines[2].startswith("plane tracking: 225/300 frame (75 %)")
    assert lines[3].startswith("plane tracking: 300 frame in ")


def test_iterating_counts_and_closes() -> None:
    log = io.StringIO()
    seen = list(progress_bar(range(10), desc="x", file=log))
    assert seen == list(range(10))
    assert log.getvalue().splitlines()[-1].startswith("x: 10 it in ")


def test_big_steps_print_one_line_each() -> None:
    log = io.StringIO()
    with progress_bar(total=4, desc="d", file=log) as bar:
        bar.update(3)  # passes 25 %, 50 % and 75 % at once: one line
        bar.set_postfix(detected=2)
        bar.update(1)
    lines = log.getvalue().splitlines()
    assert lines[0].startswith("d: 3/4 it (75 %)")
    assert lines[1].endswith("detected=2") and len(lines) == 2


def test_unknown_total_prints_every_interval() -> None:
    log = io.StringIO()
    bar = SummaryProgress(desc="d", file=log, every=0.0)
    bar.update(1)
    bar.update(1)
    bar.close()
    assert [ln.split(",")[0] for ln in log.getvalue().splitlines()[:2]] == ["d: 1 it", "d: 2 it"]


def test_disabled_prints_nothing() -> None:
    log = _Terminal()
    bar = progress_bar(total=5, file=log, disable=True)
    bar.update(5)
    bar.close()
    assert log.getvalue() == ""


def test_terminal_gets_tqdm() -> None:
    tqdm = pytest.importorskip("tqdm")
    term = _Terminal()
    bar = progress_bar(total=3, desc="t", file=term)
    assert isinstance(bar, tqdm.tqdm)
    bar.update(3)
    bar.close()
    assert "\r" in term.getvalue() and "3/3" in term.getvalue()


def test_is_terminal() -> None:
    assert is_terminal(_Terminal()) and not is_terminal(io.StringIO()) and not is_terminal(None)
    closed = io.StringIO()
    closed.close()
    assert not is_terminal(closed)


def test_iterating_without_iterable_is_an_error() -> None:
    with pytest.raises(TypeError, match="without an iterable"):
        list(SummaryProgress(total=2, file=io.StringIO()))
