"""Progress bars on stderr that become a few summary lines off a terminal.

:func:`progress_bar` is a tqdm bar on a terminal; piped into a log, a handful of lines
(at 25 %, 50 %, 75 % and the end, or every 30 s when the total is unknown) instead of one
line per update. tqdm is imported lazily, so importing this module stays cheap. (The
notice shown while numba compiles is :class:`robopercept.jit.CompileNotice`.)

Counts and rates read as a person writes them (:func:`format_count`,
:func:`format_rate`): ``150/300 frames``, ``31.4 frame/s``, ``2.5 s/epoch`` when one
unit takes longer than a second (as tqdm inverts a slow rate, never ``0.0 epoch/s``),
and three significant figures at most in the fraction (``373204 item/s``, not
``373203.96 items/s``). The default unit is ``"item"``.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Iterable, Iterator
from typing import IO, Any

__all__ = ["SummaryProgress", "format_count", "format_rate", "is_terminal", "progress_bar"]


def _plural(unit: str, n: float) -> str:
    """``unit`` with an ``s`` for any count but one: a lower-case word of three letters
    or more not already ending in s (``px``, ``MB``, ``it`` stay as they are)."""
    if n == 1 or len(unit) < 3 or not (unit.isalpha() and unit.islower()) or unit[-1] == "s":
        return unit
    return unit + "s"


def format_count(n: int, unit: str, total: int | None = None) -> str:
    """A count with its unit in the plural it needs: ``1 frame``, ``150/300 frames``.

    Parameters
    ----------
    n : int
        What was counted so far.
    unit : str
        The unit, singular (``"frame"``, ``"epoch"``); a word that ends in ``s``, is not
        lower-case letters or is shorter than three (``"px"``, ``"MB"``) stays as it is.
    total : int, optional
        The expected count: ``n/total`` with the unit in the plural of ``total``.

    Returns
    -------
    str

    Examples
    --------
    >>> format_count(1, "frame"), format_count(0, "epoch"), format_count(150, "frame", 300)
    ('1 frame', '0 epochs', '150/300 frames')
    """
    if total is None:
        return f"{n} {_plural(unit, n)}"
    return f"{n}/{total} {_plural(unit, total)}"


def _significant(x: float) -> str:
    """``x`` (> 0) with three significant figures, but never in exponent form and never
    rounding away integer digits: 0.0123, 1.23, 12.3, 123, 373204."""
    if x >= 100:
        return f"{x:.0f}"
    if x >= 10:
        return f"{x:.1f}"
    if x >= 1:
        return f"{x:.2f}"
    return f"{x:.3g}"


def format_rate(n: float, seconds: float, unit: str = "item") -> str:
    """The speed of ``n`` units in ``seconds``, as tqdm shows it but with sensible
    precision: ``unit/s`` when at least one unit passes per second (``31.4 frame/s``,
    ``373204 item/s``), else seconds per unit (``2.50 s/epoch``, ``95.0 s/epoch``),
    so a slow loop never reads ``0.0 epoch/s``; ``""`` when there is no rate (nothing
    counted or no time passed).

    Three significant figures (:func:`_significant`), whole numbers from 100 up.

    Parameters
    ----------
    n : float
        Units done.
    seconds : float
        Time they took.
    unit : str
        The unit, singular (as tqdm's ``unit``).

    Returns
    -------
    str

    Examples
    --------
    >>> format_rate(300, 9.55, "frame"), format_rate(3, 285.0, "epoch")
    ('31.4 frame/s', '95.0 s/epoch')
    >>> format_rate(373203.96, 1.0), format_rate(0, 1.0), format_rate(5, 0.0)
    ('373204 item/s', '', '')
    """
    if not (n > 0 and seconds > 0 and math.isfinite(n) and math.isfinite(seconds)):
        return ""
    rate = n / seconds
    if not 0 < rate < math.inf:  # under- or overflow
        return ""
    if rate >= 1:
        return f"{_significant(rate)} {unit}/s"
    return f"{_significant(seconds / n)} s/{unit}"


def is_terminal(stream: IO[str] | None) -> bool:
    """Whether ``stream`` is an interactive terminal (``isatty``); ``False`` for files,
    pipes, closed streams and ``None``."""
    try:
        return bool(stream is not None and stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


class SummaryProgress:
    """The progress of a loop as a few lines, for a log file or a pipe.

    Prints ``desc: n/total units (p %), t s`` when the count passes 25 %, 50 % and 75 %
    of ``total`` (or every ``every`` seconds when ``total`` is unknown) and one closing
    line ``desc: n units in t s (rate)``, the rate by :func:`format_rate` (``31.4
    frame/s``, or ``95.0 s/epoch`` for slow units). The subset of the tqdm interface the
    package uses: ``update``, ``set_postfix``, ``set_postfix_str``, ``close``,
    iteration and ``with``.

    Parameters
    ----------
    iterable : iterable, optional
        Iterated by ``for x in bar`` (each item counts one).
    total : int, optional
        Expected count; ``len(iterable)`` when it has one.
    desc, unit : str
        What is counted, the unit singular: ``plane tracking: 150/300 frames (50 %),
        21.0 s``.
    file : text stream
        Where the lines go (default ``sys.stderr``).
    disable : bool
        Print nothing.
    every : float
        Seconds between lines when ``total`` is unknown.
    """

    def __init__(
        self,
        iterable: Iterable[Any] | None = None,
        *,
        total: int | None = None,
        desc: str = "",
        unit: str = "item",
        file: IO[str] | None = None,
        disable: bool = False,
        every: float = 30.0,
    ) -> None:
        self.iterable = iterable
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            total = len(iterable)  # type: ignore[arg-type]
        self.total = total
        self.desc = desc
        self.unit = unit
        self.file = file if file is not None else sys.stderr
        self.disable = disable
        self.every = every
        self.n = 0
        self.postfix = ""
        self._start = time.perf_counter()
        self._last_line = self._start
        self._next_quarter = 1
        self._closed = False

    def _say(self, text: str) -> None:
        if not self.disable:
            print(f"{self.desc}: {text}" if self.desc else text, file=self.file, flush=True)

    def update(self, n: int = 1) -> None:
        """Count ``n`` more; print a line when a quarter of the total (or ``every``
        seconds) has passed."""
        self.n += n
        now = time.perf_counter()
        if self.total:
            passed = False
            while self._next_quarter < 4 and 4 * self.n >= self._next_quarter * self.total:
                self._next_quarter += 1
                passed = True
            if passed and self.n < self.total:
                pct = 100.0 * self.n / self.total
                self._say(
                    f"{format_count(self.n, self.unit, self.total)} ({pct:.0f} %), "
                    f"{now - self._start:.1f} s{self.postfix}"
                )
        elif now - self._last_line >= self.every:
            self._last_line = now
            self._say(f"{format_count(self.n, self.unit)}, {now - self._start:.1f} s{self.postfix}")

    def set_postfix(self, **values: Any) -> None:
        """Values shown after the count on the next line (as tqdm's ``set_postfix``)."""
        self.postfix = "".join(f", {k}={v}" for k, v in values.items())

    def set_postfix_str(self, text: str = "", refresh: bool = True) -> None:
        """Text shown after the count on the next line (as tqdm's ``set_postfix_str``)."""
        self.postfix = f", {text}" if text else ""

    def close(self) -> None:
        """Print the closing line (once)."""
        if self._closed:
            return
        self._closed = True
        dt = time.perf_counter() - self._start
        rate = format_rate(self.n, dt, self.unit)
        rate = f" ({rate})" if rate else ""
        self._say(f"{format_count(self.n, self.unit)} in {dt:.1f} s{rate}{self.postfix}")

    def __iter__(self) -> Iterator[Any]:
        if self.iterable is None:
            raise TypeError("SummaryProgress was made without an iterable")
        try:
            for item in self.iterable:
                yield item
                self.update(1)
        finally:
            self.close()

    def __enter__(self) -> SummaryProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_bar(
    iterable: Iterable[Any] | None = None,
    *,
    total: int | None = None,
    desc: str = "",
    unit: str = "item",
    disable: bool = False,
    file: IO[str] | None = None,
    **tqdm_kwargs: Any,
) -> Any:
    """A progress bar on ``file`` (default stderr): tqdm on a terminal, else a
    :class:`SummaryProgress` that prints a few lines.

    Parameters
    ----------
    iterable : iterable, optional
    total : int, optional
    desc, unit : str
        What is counted, the unit singular (``"frame"``, ``"epoch"``, ``"image"``;
        default ``"item"``). On a terminal tqdm shows ``frame/s``, or ``s/epoch`` when
        one unit takes longer than a second; off it, :func:`format_rate`.
    disable : bool
        No output at all (``--quiet``).
    file : text stream, optional
    **tqdm_kwargs
        Passed to tqdm on a terminal (``leave``, ``position``, ...), ignored otherwise.

    Returns
    -------
    tqdm.tqdm or SummaryProgress
        Both support ``update``, ``set_postfix``, ``close``, iteration and ``with``.
    """
    stream = file if file is not None else sys.stderr
    if disable or not is_terminal(stream):
        return SummaryProgress(
            iterable, total=total, desc=desc, unit=unit, file=stream, disable=disable
        )
    if total is None and iterable is not None and hasattr(iterable, "__len__"):
        total = len(iterable)  # type: ignore[arg-type]
    if "bar_format" not in tqdm_kwargs:  # tqdm's own layouts, counts and rates readable
        tqdm_kwargs["bar_format"] = _BAR_FORMAT if total else _COUNT_FORMAT
        if not total and not desc:
            tqdm_kwargs["bar_format"] = _COUNT_FORMAT.removeprefix("{desc}: ")
    return _tqdm_class()(
        iterable, total=total, desc=desc, unit=unit, file=stream, dynamic_ncols=True, **tqdm_kwargs
    )


#: tqdm's default layout (``{l_bar}{bar}{r_bar}``) with the count by :func:`format_count`
#: and the rate by :func:`format_rate`: ``train:  30%|###   | 3/10 epochs [01:30<03:30,
#: 30.0 s/epoch]``
_BAR_FORMAT = "{l_bar}{bar}| {count_text} [{elapsed}<{remaining}, {rate_text}{postfix}]"
#: tqdm's layout when the total is unknown, likewise: ``read: 5 frames [00:01, 4.87 frame/s]``
_COUNT_FORMAT = "{desc}: {count_text} [{elapsed}, {rate_text}{postfix}]"


@functools.cache
def _tqdm_class() -> type:
    """A :class:`tqdm.tqdm` whose ``format_dict`` also holds ``count_text`` (the count,
    ``n/total`` when the total is known, by :func:`format_count`) and ``rate_text`` (the
    speed by :func:`format_rate`: tqdm's smoothed rate when it has one, else the
    average), for :data:`_BAR_FORMAT` and :data:`_COUNT_FORMAT`. Made on first use, so
    that tqdm is imported only then."""
    from tqdm import tqdm

    class ReadableRateBar(tqdm):  # type: ignore[misc]
        @property
        def format_dict(self) -> dict[str, Any]:
            d = super().format_dict
            unit = d.get("unit") or "item"
            rate = d.get("rate")
            if rate:
                text = format_rate(rate, 1.0, unit)
            else:
                text = format_rate(d["n"] - (d.get("initial") or 0), d.get("elapsed") or 0, unit)
            d["rate_text"] = text or f"? {unit}/s"
            n, total = d["n"], d.get("total")
            n = int(n) if float(n).is_integer() else n
            total = int(total) if total and float(total).is_integer() else total
            d["count_text"] = format_count(n, unit, total or None)
            return d

    return ReadableRateBar
