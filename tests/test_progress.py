"""Progress bars: tqdm on a terminal, a few summary lines in a log (issue 22)."""

from __future__ import annotations

import io

import pytest

from robopercept.progress import (
    SummaryProgress,
    format_count,
    format_rate,
    is_terminal,
    progress_bar,
)


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
    assert lines[0].startswith("plane tracking: 75/300 frames (25 %)")
    assert lines[1].startswith("plane tracking: 150/300 frames (50 %)")
    assert lines[2].startswith("plane tracking: 225/300 frames (75 %)")
    assert lines[3].startswith("plane tracking: 300 frames in ")


def test_iterating_counts_and_closes() -> None:
    log = io.StringIO()
    seen = list(progress_bar(range(10), desc="x", file=log))
    assert seen == list(range(10))
    assert log.getvalue().splitlines()[-1].startswith("x: 10 items in ")


def test_big_steps_print_one_line_each() -> None:
    log = io.StringIO()
    with progress_bar(total=4, desc="d", file=log) as bar:
        bar.update(3)  # passes 25 %, 50 % and 75 % at once: one line
        bar.set_postfix(detected=2)
        bar.update(1)
    lines = log.getvalue().splitlines()
    assert lines[0].startswith("d: 3/4 items (75 %)")
    assert lines[1].endswith("detected=2") and len(lines) == 2


def test_unknown_total_prints_every_interval() -> None:
    log = io.StringIO()
    bar = SummaryProgress(desc="d", file=log, every=0.0)
    bar.update(1)
    bar.update(1)
    bar.close()
    assert [ln.split(",")[0] for ln in log.getvalue().splitlines()[:2]] == [
        "d: 1 item",
        "d: 2 items",
    ]


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


# ------------------------------------------------------------------ units that read well (issue 48)
@pytest.mark.parametrize(
    ("n", "seconds", "unit", "expected"),
    [
        (300, 9.55, "frame", "31.4 frame/s"),  # three significant figures
        (373203.96, 1.0, "item", "373204 item/s"),  # whole from 100 up, no .96
        (5, 2.0, "image", "2.50 image/s"),
        (3, 285.0, "epoch", "95.0 s/epoch"),  # slower than 1/s: seconds per unit
        (1, 1.0, "epoch", "1.00 epoch/s"),
        (2, 1000.0, "epoch", "500 s/epoch"),
        (0, 1.0, "item", ""),  # no rate: nothing counted
        (5, 0.0, "item", ""),  # no rate: no time passed
        (float("nan"), 1.0, "item", ""),
        (5, float("inf"), "item", ""),
    ],
)
def test_format_rate(n: float, seconds: float, unit: str, expected: str) -> None:
    assert format_rate(n, seconds, unit) == expected


def test_format_rate_never_reads_zero() -> None:
    """However slow, the rate shows a non-zero number (s/unit), never "0.0 epoch/s"."""
    for seconds in (1.5, 30.0, 600.0, 86400.0 * 365):
        text = format_rate(1, seconds, "epoch")
        assert text.endswith(" s/epoch") and float(text.split()[0]) > 0, text
    for n in (1, 7, 1e3, 1e6, 123456789):
        text = format_rate(n, 1.0, "item")
        head = text.split()[0]
        assert "e" not in head and ("." not in head or len(head.split(".")[1]) <= 2), text


def test_format_count_plurals() -> None:
    assert format_count(1, "epoch") == "1 epoch"
    assert format_count(0, "image") == "0 images"
    assert format_count(2, "frame") == "2 frames"
    assert format_count(1, "frame", 300) == "1/300 frames"
    assert format_count(1, "frame", 1) == "1/1 frame"
    assert format_count(3, "px") == "3 px"  # not a word: as given
    assert format_count(3, "pass") == "3 pass"  # ends in s: as given


def test_slow_loop_closing_line_reads_seconds_per_epoch(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = iter([0.0, 0.0, 90.0, 180.0, 270.0, 270.0])  # start, last line, 3 updates, close
    monkeypatch.setattr("robopercept.progress.time.perf_counter", lambda: next(clock))
    log = io.StringIO()
    bar = progress_bar(total=3, desc="train", unit="epoch", file=log)
    for _ in range(3):
        bar.update(1)
    bar.close()
    last = log.getvalue().splitlines()[-1]
    assert last == "train: 3 epochs in 270.0 s (90.0 s/epoch)", last
    assert "epoch/s" not in log.getvalue()


def test_default_unit_is_item() -> None:
    log = io.StringIO()
    list(progress_bar(range(3), file=log))
    assert log.getvalue().splitlines()[-1].startswith("3 items in ")


def test_terminal_bar_reads_seconds_per_epoch_and_plural_counts() -> None:
    pytest.importorskip("tqdm")
    bar = progress_bar(total=10, desc="train", unit="epoch", file=_Terminal(), smoothing=0)
    bar.update(3)
    bar.start_t -= 90  # 3 epochs in 90 s
    text = str(bar)
    bar.close()
    assert "3/10 epochs" in text and "30.0 s/epoch" in text, text
    assert "epoch/s" not in text


def test_terminal_bar_rate_has_sensible_precision() -> None:
    pytest.importorskip("tqdm")
    bar = progress_bar(total=10**6, desc="b", unit="item", file=_Terminal(), smoothing=0)
    bar.update(373204)
    bar.start_t -= 1.0
    text = str(bar)
    bar.close()
    rate = text.split(", ")[-1].rstrip("]")
    assert rate.endswith(" item/s") and "." not in rate, text  # whole number at this speed


def test_terminal_bar_without_total() -> None:
    pytest.importorskip("tqdm")
    term = _Terminal()
    for _ in progress_bar(iter(range(5)), desc="read", unit="frame", file=term):
        pass
    assert "read: 5 frames [" in term.getvalue(), term.getvalue()
    term = _Terminal()
    for _ in progress_bar(iter(range(2)), unit="frame", file=term):
        pass
    assert term.getvalue().split("\r")[-1].startswith("2 frames ["), term.getvalue()
