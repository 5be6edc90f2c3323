"""Run one call at a time in a disposable worker process, and say how it ended.

A fuzz campaign calls library code on hostile inputs; a segfault, an endless loop or a
runaway allocation there must be counted, not take the campaign down. :class:`Sandbox`
keeps one worker process (forked from a clean fork server that has imported
robopercept, see :class:`Sandbox`) and sends it one call at a time over a pipe:

- the call returns: ``"ok"``;
- it raises a :class:`robopercept.errors.RoboperceptError`: ``"typed"`` (the contract
  holds: a typed error whose message names the fix);
- it raises ``MemoryError`` (the worker's address space is capped with ``RLIMIT_AS`` at
  its size before the call plus ``memory_mb``): ``"memory"``;
- it raises anything else: ``"untyped"``;
- the worker dies (SIGSEGV, SIGABRT, ``os._exit``): ``"crash"``, and a new worker is
  forked for the next call;
- no answer within ``timeout`` seconds: ``"hang"``; the worker is killed (SIGKILL works
  even while native code holds the GIL) and replaced.

Memory is measured two ways for each call: ``peak_mb``, the :mod:`tracemalloc` peak
(Python objects and NumPy arrays, which NumPy reports to tracemalloc; not the private
buffers of native libraries such as Pillow's or librealsense's), and ``rss_mb``, the
growth of the worker's peak resident set (``VmHWM``, reset before the call through
``/proc/self/clear_refs``), which does see native buffers but also counts pages touched
by first-time imports.
"""

from __future__ import annotations

import contextlib
import dataclasses
import faulthandler
import importlib
import multiprocessing
import os
import pickle
import resource
import signal
import sys
import tempfile
import time
import traceback
import tracemalloc
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["KINDS", "Outcome", "Sandbox", "array_bytes"]

#: every value of :attr:`Outcome.kind`
KINDS = ("ok", "typed", "untyped", "crash", "hang", "memory")

_MIB = 1024.0 * 1024.0


@dataclass(frozen=True)
class Outcome:
    """How one sandboxed call ended.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`: ``"ok"``, ``"typed"``, ``"untyped"``, ``"crash"``,
        ``"hang"``, ``"memory"``.
    error : str
        The exception's type name (``"InputError"``, ``"ValueError"``), ``"MemoryError"``,
        the signal that killed the worker (``"SIGSEGV"``) or ``"exit N"``, ``"timeout"``;
        empty for ``"ok"``.
    message : str
        The first 300 characters of ``str(exc)``; for a crash, the worker's last words
        on stderr (the fatal-error line and the innermost frame of Python's
        faulthandler dump).
    seconds : float
        Wall time of the call in the worker (for a hang or a crash: as seen by the
        caller).
    peak_mb : float
        :mod:`tracemalloc` peak during the call, MiB (NumPy allocations included).
    rss_mb : float
        Growth of the worker's peak resident set during the call, MiB (native buffers
        included); 0 where ``/proc`` cannot tell.
    where : str
        ``file:line in function`` of the innermost frame that raised (for errors).
    result_bytes : int
        Bytes of the NumPy arrays in the returned value (see :func:`array_bytes`); 0
        unless ``kind == "ok"``.
    """

    kind: str
    error: str
    message: str
    seconds: float
    peak_mb: float
    rss_mb: float = 0.0
    where: str = ""
    result_bytes: int = 0


def array_bytes(value: Any, _depth: int = 0, _seen: set[int] | None = None) -> int:
    """Total ``nbytes`` of the NumPy arrays reachable from ``value``.

    Walks arrays, lists, tuples, dicts, dataclasses and plain objects' ``__dict__``, four
    levels deep and at most 10,000 items per container; an array and its views are
    counted once (by their base buffer).

    Parameters
    ----------
    value : object

    Returns
    -------
    int
        Bytes; e.g. ``array_bytes([np.zeros(3), {"a": np.zeros((2, 2), np.uint8)}]) == 28``.
    """
    seen = set() if _seen is None else _seen
    if isinstance(value, np.ndarray):
        base = value
        while isinstance(base.base, np.ndarray):
            base = base.base
        if id(base) in seen:
            return 0
        seen.add(id(base))
        return int(base.nbytes)
    if _depth >= 4 or isinstance(value, str | bytes | int | float | complex | bool):
        return 0
    if isinstance(value, dict):
        items: Any = list(value.values())[:10_000]
    elif isinstance(value, list | tuple | set | frozenset):
        items = list(value)[:10_000]
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        items = [getattr(value, f.name, None) for f in dataclasses.fields(value)]
    elif hasattr(value, "__dict__") and not isinstance(value, type):
        items = list(vars(value).values())[:10_000]
    else:
        return 0
    return sum(array_bytes(v, _depth + 1, seen) for v in items)


def resolve(target: str | Callable[..., Any]) -> Callable[..., Any]:
    """The callable that ``target`` names.

    Parameters
    ----------
    target : str or callable
        ``"package.module:function"``, ``"package.module:Class"`` (the constructor) or
        ``"package.module:Class.method"`` (a static or class method); a callable is
        returned as is.

    Returns
    -------
    callable

    Raises
    ------
    ValueError
        A string without ``":"`` or naming nothing callable.
    """
    if callable(target):
        return target
    module, sep, attr = str(target).partition(":")
    if not sep or not module or not attr:
        raise ValueError(f"target must be 'module:name' or a callable; got {target!r}")
    obj: Any = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    if not callable(obj):
        raise ValueError(f"{target!r} is not callable")
    return obj


def _proc_status_kib(field: str) -> int | None:
    """A ``/proc/self/status`` field in KiB (``VmSize``, ``VmRSS``, ``VmHWM``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset ``VmHWM`` to the current RSS (Linux >= 4.0); False where refused."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _where(exc: BaseException) -> str:
    """``file:line in function`` of the innermost frame of ``exc``'s traceback."""
    tb = traceback.extract_tb(exc.__traceback__)
    if not tb:
        return ""
    f = tb[-1]
    return f"{f.filename}:{f.lineno} in {f.name}"


def _call(target: Any, args: tuple, kwargs: dict) -> Outcome:
    """Run one call in the worker and classify it (see the module docstring)."""
    from robopercept.errors import RoboperceptError

    rss_ok = _reset_peak_rss()
    rss0 = _proc_status_kib("VmRSS") if rss_ok else None
    tracemalloc.start()
    t0 = time.perf_counter()
    result: Any = None
    kind, error, message, where = "ok", "", "", ""
    try:
        result = resolve(target)(*args, **kwargs)
    except MemoryError as exc:
        kind, error, message, where = "memory", "MemoryError", str(exc)[:300], _where(exc)
    except BaseException as exc:  # SystemExit and KeyboardInterrupt too
        kind = "typed" if isinstance(exc, RoboperceptError) else "untyped"
        error, message, where = type(exc).__name__, str(exc)[:300], _where(exc)
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / _MIB
    tracemalloc.stop()
    hwm = _proc_status_kib("VmHWM") if rss0 is not None else None
    rss = max(0.0, (hwm - rss0) / 1024.0) if hwm is not None and rss0 is not None else 0.0
    nbytes = 0
    if kind == "ok":
        try:
            nbytes = array_bytes(result)
        except Exception:  # a property that raises: size unknown
            nbytes = 0
    del result
    return Outcome(kind, error, message, seconds, peak, rss, where, nbytes)


def _limit_address_space(memory_mb: float) -> None:
    """Cap the worker's address space at its size now plus ``memory_mb`` (set before
    every call: a long-lived worker's size grows with every kernel compiled and every
    module imported, and a cap set once at start left later calls too little headroom:
    a 24 MB array or LLVM's compile of a new signature then failed, and the campaign
    blamed the call)."""
    size_kib = _proc_status_kib("VmSize")
    if size_kib is None or memory_mb <= 0:
        return
    limit = int(size_kib * 1024 + memory_mb * _MIB)
    _, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def _worker(conn: Any, log_path: str, memory_mb: float) -> None:
    """The worker's loop: receive ``(target, args, kwargs)``, send an :class:`Outcome`;
    ``None`` ends it."""
    fd = os.open(log_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    log = os.fdopen(fd, "w", buffering=1)
    sys.stdout = sys.stderr = log
    faulthandler.enable(file=log)  # pytest's faulthandler writes to its own copy of fd 2
    warnings.simplefilter("ignore")  # a reader's warning is not an error here
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    while True:
        _limit_address_space(memory_mb)
        try:
            raw = conn.recv_bytes()
        except (EOFError, OSError):
            break
        try:
            msg = pickle.loads(raw)
        except Exception as exc:  # e.g. a function defined in __main__
            outcome = Outcome(
                "untyped", type(exc).__name__, f"cannot unpickle the call: {exc}"[:300], 0.0, 0.0
            )
        else:
            if msg is None:
                break
            outcome = _call(*msg)
        try:
            conn.send(outcome)
        except (OSError, ValueError):
            break
    conn.close()


def _last_words(log_path: str) -> str:
    """What a dead worker said last on stderr: the ``Fatal Python error`` line and the
    innermost frame of the faulthandler dump when there is one, else the last line."""
    try:
        with open(log_path, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            fh.seek(max(0, fh.tell() - 16384))
            lines = fh.read().decode("utf-8", "replace").splitlines()
    except OSError:
        return ""
    lines = [ln.strip() for ln in lines if ln.strip()]
    for i in range(len(lines) - 1, -1, -1):
        if lines[i].startswith("Fatal Python error"):
            frame = next((ln for ln in lines[i + 1 :] if ln.startswith("File ")), "")
            return f"{lines[i]}; {frame}".strip("; ")[:300]
    return lines[-1][:300] if lines else ""


class Sandbox:
    """A persistent worker process that runs one call at a time (see the module
    docstring for how each ending is classified).

    Parameters
    ----------
    timeout : float
        Seconds a call may take before it is killed and counted as ``"hang"``.
    memory_mb : float
        Address space one call may add to the worker's size (``RLIMIT_AS``), MiB;
        beyond it allocations fail with ``MemoryError`` (kind ``"memory"``).

    Attributes
    ----------
    spawns : int
        Workers started so far (1 + crashes + hangs, once the first call ran).

    Notes
    -----
    Workers are forked from a ``multiprocessing`` fork server, a fresh interpreter that
    has imported NumPy and robopercept and runs nothing else, not from the calling
    process: numba's OpenMP threading layer terminates a forked child that enters a
    parallel region once its parent has used OpenMP ("fork() called from a process
    already using GNU OpenMP"), and a test session or a campaign has usually run
    parallel kernels before. A new worker loads numba's cached kernels on first use;
    :meth:`warm` names calls that every new worker makes before its first measured
    call, so that imports and kernel loading are not counted as a call's time and
    memory.

    Examples
    --------
    >>> with Sandbox(timeout=5) as box:
    ...     box.run("math:sqrt", (4.0,)).kind, box.run("math:sqrt", (-1.0,)).error
    ('ok', 'ValueError')
    """

    def __init__(self, timeout: float = 20.0, memory_mb: float = 2048.0) -> None:
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds; got {timeout!r}")
        self.timeout = float(timeout)
        self.memory_mb = float(memory_mb)
        self.spawns = 0
        self._proc: Any = None
        self._conn: Any = None
        self._warm: list[tuple[Any, tuple, dict]] = []
        fd, self._log = tempfile.mkstemp(prefix="robopercept-sandbox-", suffix=".log")
        os.close(fd)

    # -- worker life ----------------------------------------------------------------
    def _spawn(self) -> None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["numpy", "robopercept", "robopercept.errors", __name__])
        parent, child = ctx.Pipe()
        with open(self._log, "wb"):
            pass  # a fresh log per worker: its last words are its own
        proc = ctx.Process(target=_worker, args=(child, self._log, self.memory_mb), daemon=True)
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent
        self.spawns += 1

    def _ensure(self) -> None:
        """A live worker, warmed with the :meth:`warm` calls if it is new."""
        if self._proc is not None and self._proc.is_alive():
            return
        if self._proc is not None:
            self._kill()
        self._spawn()
        for target, args, kwargs in self._warm:
            self._call(target, args, kwargs, self.timeout)
            if self._proc is None:  # the warm-up itself crashed or hung: go on cold
                self._spawn()
                break

    def restart(self) -> None:
        """Stop the worker; the next call starts a fresh one (warmed with the
        :meth:`warm` calls)."""
        self._kill()

    def _kill(self) -> None:
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if conn is not None:
            conn.close()
        if proc is not None:
            if proc.is_alive():
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGKILL)
            proc.join(5)

    def _death(self, seconds: float) -> Outcome:
        """Outcome of a call whose worker died; the worker is reaped."""
        proc = self._proc
        proc.join(5)
        code = proc.exitcode
        if code is not None and code < 0:
            try:
                error = signal.Signals(-code).name
            except ValueError:
                error = f"signal {-code}"
        else:
            error = f"exit {code}"
        message = _last_words(self._log)
        self._kill()
        return Outcome("crash", error, message, seconds, 0.0)

    def _call(self, target: Any, args: tuple, kwargs: dict, limit: float) -> Outcome:
        """Send one call to the live worker and wait for its outcome (or its end)."""
        t0 = time.perf_counter()
        try:
            self._conn.send((target, tuple(args), dict(kwargs or {})))
        except (BrokenPipeError, ConnectionResetError):
            return self._death(time.perf_counter() - t0)
        if not self._conn.poll(limit):
            seconds = time.perf_counter() - t0
            self._kill()
            return Outcome("hang", "timeout", f"no answer within {limit:g} s", seconds, 0.0)
        try:
            return self._conn.recv()
        except (EOFError, ConnectionResetError):
            return self._death(time.perf_counter() - t0)

    # -- the calls ------------------------------------------------------------------
    def warm(self, calls: Sequence[tuple[Any, tuple, dict]]) -> list[Outcome]:
        """Make ``calls`` now and in every worker started from now on, before its
        first measured call (their outcomes are not counted anywhere).

        Parameters
        ----------
        calls : sequence of (target, args, kwargs)
            As for :meth:`run`; an empty sequence clears the list.

        Returns
        -------
        list of Outcome
            The outcomes of the calls made now, in the current worker.
        """
        self._warm = [(t, tuple(a), dict(k or {})) for t, a, k in calls]
        outs = []
        for target, args, kwargs in self._warm:
            if self._proc is None or not self._proc.is_alive():
                if self._proc is not None:
                    self._kill()
                self._spawn()
            outs.append(self._call(target, args, kwargs, self.timeout))
        return outs

    def run(
        self,
        target: str | Callable[..., Any],
        args: tuple = (),
        kwargs: dict | None = None,
        *,
        timeout: float | None = None,
    ) -> Outcome:
        """Run ``target(*args, **kwargs)`` in the worker.

        Parameters
        ----------
        target : str or callable
            ``"module:function"``, ``"module:Class"``, ``"module:Class.method"``, or a
            picklable callable (a function defined at module level in an importable
            module, a ``functools.partial`` of one).
        args : tuple
            Positional arguments (pickled to the worker).
        kwargs : dict, optional
            Keyword arguments.
        timeout : float, optional
            This call's limit in seconds instead of the sandbox's.

        Returns
        -------
        Outcome
        """
        self._ensure()
        limit = self.timeout if timeout is None else float(timeout)
        return self._call(target, tuple(args), dict(kwargs or {}), limit)

    def close(self) -> None:
        """Stop the worker and remove its log."""
        if self._conn is not None:
            with contextlib.suppress(OSError, ValueError):
                self._conn.send(None)
            if self._proc is not None:
                self._proc.join(2)
        self._kill()
        with contextlib.suppress(OSError):
            os.unlink(self._log)

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
