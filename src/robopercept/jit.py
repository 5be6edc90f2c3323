"""numba's first-use compilation, made visible and done ahead of time.

robopercept's kernels are compiled by numba on first use and cached on disk
(``cache=True``), so only the first run of a command pays for compiling. This module
makes that wait visible and lets it be paid in advance:

* :class:`CompileNotice` listens to numba's ``"numba:compile"`` event
  (:mod:`numba.core.event`; loading a cached kernel raises none) and shows "compiling
  kernels for WHAT (first use only, about N s)": a spinner with the seconds so far on a
  terminal, one line when it starts off a terminal, and one closing line with the total.
* :func:`run_in_workers` runs tasks (for ``robopercept warmup``: commands on tiny
  inputs) in parallel worker processes, each counting the compilations it caused, so
  every kernel lands in numba's cache before a user needs it.

numba is imported lazily, so importing this module stays cheap.
"""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import sys
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import IO, Any

from robopercept.progress import is_terminal, progress_bar

__all__ = ["CompileNotice", "TaskResult", "call_by_name", "run_in_workers"]

_SPINNER = "|/-\\"


class CompileNotice:
    """Say so while numba compiles kernels (first use only: compiled kernels are cached).

    A context manager. Inside it, every numba compilation (the ``"numba:compile"``
    event; a kernel loaded from numba's cache raises none) is noticed: on a terminal a
    spinner line ``compiling kernels for edges (first use only, about 18 s): 7 s``
    shows while compiling and is cleared after it; off a terminal one line when the
    first compilation starts. On leaving, if anything was compiled, one line gives the
    total: ``compiled kernels in 17.2 s (cached for next time; robopercept warmup
    compiles them all ahead of time)``.

    Parameters
    ----------
    what : str
        What is compiled for (a command's name), shown in the message.
    estimate : float, optional
        Expected compile time in seconds (measured by ``benchmarks/first_use.py``).
    file : text stream, optional
        Default ``sys.stderr``.
    enabled : bool
        ``False`` makes it do nothing (``--quiet``).

    Attributes
    ----------
    compiled : int
        Number of kernel compilations seen (each specialization counts; nested ones too).
    seconds : float
        Wall time during which some compilation was running.
    """

    def __init__(
        self,
        what: str,
        estimate: float | None = None,
        *,
        file: IO[str] | None = None,
        enabled: bool = True,
    ) -> None:
        self.what = what
        self.estimate = estimate
        self.file = file if file is not None else sys.stderr
        self.enabled = enabled
        self.compiled = 0
        self.seconds = 0.0
        self._depth = 0
        self._since = 0.0  # start of the current compiling stretch
        self._first = 0.0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._listener: Any = None
        self._tty = is_terminal(self.file)
        self._shown = False

    def message(self) -> str:
        """``compiling kernels for WHAT (first use only, about N s)``."""
        about = f", about {self.estimate:.0f} s" if self.estimate else ""
        return f"compiling kernels for {self.what} (first use only{about})"

    # numba calls these from the compiling thread
    def _on_start(self) -> None:
        with self._lock:
            self.compiled += 1
            self._depth += 1
            if self._depth == 1:
                self._since = time.perf_counter()
                if not self._first:
                    self._first = self._since
                    if self.enabled and not self._tty:
                        print(f"robopercept: {self.message()} ...", file=self.file, flush=True)

    def _on_end(self) -> None:
        with self._lock:
            self._depth = max(0, self._depth - 1)
            if self._depth == 0:
                self.seconds += time.perf_counter() - self._since

    def _spin(self) -> None:
        i = 0
        while not self._stop.wait(0.1):
            with self._lock:
                busy = self._depth > 0
                first = self._first
            if busy:
                i += 1
                text = f"{_SPINNER[i % 4]} {self.message()}: {time.perf_counter() - first:.0f} s"
                self.file.write("\r" + text + "\x1b[K")
                self.file.flush()
                self._shown = True
            elif self._shown:
                self._clear()

    def _clear(self) -> None:
        self.file.write("\r\x1b[K")
        self.file.flush()
        self._shown = False

    def __enter__(self) -> CompileNotice:
        from numba.core import event

        notice = self

        class _Listener(event.Listener):  # type: ignore[misc]
            def on_start(self, ev: Any) -> None:
                notice._on_start()

            def on_end(self, ev: Any) -> None:
                notice._on_end()

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        if self.enabled and self._tty:
            self._thread = threading.Thread(target=self._spin, name="compile-notice", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        from numba.core import event

        event.unregister("numba:compile", self._listener)
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
            if self._shown:
                self._clear()
        if self.enabled and self.compiled:
            print(
                f"robopercept: compiled kernels in {self.seconds:.1f} s (cached for next "
                "time; `robopercept warmup` compiles them all ahead of time)",
                file=self.file,
                flush=True,
            )


@dataclass(frozen=True)
class TaskResult:
    """What one task of :func:`run_in_workers` did.

    Attributes
    ----------
    name : str
    result : object
        The task's return value (``None`` when it raised).
    error : str
        ``""``, or the exception's type and first line when it raised.
    compiled : int
        numba compilations it caused in its worker (kernels already compiled in that
        worker by an earlier task are not compiled again).
    compile_seconds, seconds : float
        Wall time spent compiling, and in all.
    output : str
        The last lines it printed (stdout and stderr), for a failed task's report.
    """

    name: str
    result: Any
    error: str
    compiled: int
    compile_seconds: float
    seconds: float
    output: str


def call_by_name(module: str, name: str, *args: Any) -> Any:
    """``module.name(*args)``, importing ``module`` first: a task for
    :func:`run_in_workers` that names its function instead of importing it (so the
    module handing out the tasks need not import it)."""
    import importlib

    return getattr(importlib.import_module(module), name)(*args)


def _run_task(name: str, func: Callable[..., Any], args: Sequence[Any]) -> TaskResult:
    """Run ``func(*args)`` with its output captured, counting numba compilations."""
    out = io.StringIO()
    start = time.perf_counter()
    result, error = None, ""
    with CompileNotice(name, enabled=False) as notice:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            try:
                result = func(*args)
            except Exception as exc:  # reported, not raised: the other tasks go on
                lines = str(exc).strip().splitlines()
                error = f"{type(exc).__name__}: {lines[0] if lines else ''}"
    tail = "\n".join(out.getvalue().strip().splitlines()[-5:])
    return TaskResult(
        name, result, error, notice.compiled, notice.seconds, time.perf_counter() - start, tail
    )


def run_in_workers(
    tasks: Iterable[tuple[str, Callable[..., Any], Sequence[Any]]],
    *,
    jobs: int | None = None,
    progress: bool = True,
    desc: str = "warming up",
) -> list[TaskResult]:
    """Run ``(name, func, args)`` tasks in ``jobs`` worker processes, each task with its
    output captured and its numba compilations counted.

    numba compiles while holding the GIL, so compiling in parallel takes processes, not
    threads; what each worker compiles goes to numba's on-disk cache (the kernels are
    ``cache=True``), where every later process finds it. Tasks are handed out in the
    order given (put the slowest first). A task that raises is reported in its
    :class:`TaskResult`, and the others go on.

    Parameters
    ----------
    tasks : iterable of (str, callable, sequence)
        Name, a picklable function (module level) and its arguments.
    jobs : int, optional
        Worker processes (default: the number of CPUs, at most the number of tasks).
        ``1`` runs the tasks in this process, one after another.
    progress : bool
        A progress bar on stderr (:func:`~robopercept.progress.progress_bar`).
    desc : str
        The bar's label.

    Returns
    -------
    list of TaskResult
        In the order of ``tasks``.
    """
    todo = list(tasks)
    if jobs is None:
        jobs = multiprocessing.cpu_count()
    jobs = max(1, min(int(jobs), len(todo) or 1))
    results: dict[str, TaskResult] = {}
    bar = progress_bar(total=len(todo), desc=desc, unit="task", disable=not progress)
    try:
        if jobs == 1:
            for name, func, args in todo:
                results[name] = _run_task(name, func, args)
                bar.update(1)
        else:  # spawn: a fresh interpreter per worker, no inherited threads or locks
            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
                futures = {pool.submit(_run_task, *task): task[0] for task in todo}
                for fut in as_completed(futures):
                    results[futures[fut]] = fut.result()
                    bar.update(1)
    finally:
        bar.close()
    return [results[name] for name, _, _ in todo if name in results]
