"""Progress bars on stderr that become a few summary lines off a terminal.

:func:`progress_bar` is a tqdm bar on a terminal; piped into a log, a handful of lines
(at 25 %, 50 %, 75 % and the end, or every 30 s when the total is unknown) instead of one
line per update. tqdm is imported lazily, so importing this module stays cheap. (The
notice shown while numba compiles is :class:`robopercept.jit.CompileNotice`.)
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import IO, Any

__all__ = ["SummaryProgress", "is_terminal", "progress_bar"]


def is_terminal(stream: IO[str] | None) -> bool:
    """Whether ``stream`` is an interactive terminal (``isatty``); ``False`` for files,
    pipes, closed streams and ``None``."""
    try:
        return bool(stream is not None and stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


class SummaryProgress:
    """The progress of a loop as a few lines, for a log file or a pipe.

    Prints ``desc: n/total unit (p %), t s`` when the count passes 25 %, 50 % and 75 %
    of ``total`` (or every ``every`` seconds when ``total`` is unknown) and one closing
    line ``desc: n unit in t s (r unit/s)``. The subset of the tqdm interface the
    package uses: ``update``, ``set_postfix``, ``set_postfix_str``, ``close``,
    iteration and ``with``.

    Parameters
    ----------
    iterable : iterable, optional
        Iterated by ``for x in bar`` (each item counts one).
    total : int, optional
        Expected count; ``len(iterable)`` when it has one.
    desc, unit : str
        What is counted: ``plane tracking: 150/300 frame (50 %), 21.0 s``.
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
        unit: str = "it",
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
                    f"{self.n}/{self.total} {self.unit} ({pct:.0f} %), "
                    f"{now - self._start:.1f} s{self.postfix}"
                )
        elif now - self._last_line >= self.every:
            self._last_line = now
            self._say(f"{self.n} {self.unit}, {now - self._start:.1f} s{self.postfix}")

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
        rate = f" ({self.n / dt:.1f} {self.unit}/s)" if dt > 0 and self.n else ""
        self._say(f"{self.n} {self.unit} in {dt:.1f} s{rate}{self.postfix}")

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
    unit: str = "it",
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
    from tqdm import tqdm

    return tqdm(
        iterable, total=total, desc=desc, unit=unit, file=stream, dynamic_ncols=True, **tqdm_kwargs
    )
