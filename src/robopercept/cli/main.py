"""The ``robopercept`` command.

Each command lives in a module named after it (``edges``, ``bgsub``, ``plane_track``
for ``plane-track``, ...; ``features``, ``learn`` and ``calibrate`` hold their
related commands too) and registers itself with ``register(sub)``. The modules parse
arguments and print; the work is done by the library.

Errors print one line on stderr, never a traceback, and set the exit code:

* **0**: success (also when the output is piped into a command that closes it early);
* **2**: usage error: an unknown command or flag, a bad flag value or combination
  (argparse's message, or ``robopercept: error: ...`` for a
  :class:`~robopercept.cli._args.UsageError` raised by a command, or a library's
  :class:`~robopercept.errors.ArgumentError`: a flag's value names nothing usable, or
  ``-o`` holds a training run and neither ``--resume`` nor ``--overwrite`` was given);
* **1**: a failure the user can fix: a missing, unreadable or corrupt file, or data the
  method refuses (:class:`~robopercept.errors.RoboperceptError`, ``OSError``,
  ``ValueError``): ``robopercept: error: <message>``;
* **70** (``EX_SOFTWARE``): any other exception is a bug in robopercept:
  ``robopercept: internal error (this is a bug, please report it): <Type>: <message>;
  rerun with --debug for the traceback``;
* **130**: interrupted by Ctrl-C (SIGINT);
* **143**: stopped by SIGTERM (``docker stop``, systemd, ``kill``): handled like Ctrl-C,
  ``robopercept: stopped by SIGTERM``. ``plane-track`` and ``demo`` finish the frame
  at hand and write their outputs first (for both signals).

``robopercept --debug COMMAND ...`` (or the environment variable
``ROBOPERCEPT_DEBUG=1``) re-raises errors of kinds 1 and 70, so the traceback shows.
"""

from __future__ import annotations

import argparse
import difflib
import os
import re
import signal
import sys
import threading
import warnings
from collections.abc import Sequence
from typing import Any, NoReturn, TextIO

from robopercept import __version__
from robopercept.cli._args import DefaultsHelpFormatter, UsageError
from robopercept.errors import ArgumentError, RoboperceptError

__all__ = ["EXIT_ERROR", "EXIT_INTERNAL", "EXIT_USAGE", "build_parser", "main"]

EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INTERNAL = 70  # EX_SOFTWARE of sysexits.h
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143  # 128 + SIGTERM


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread as Ctrl-C raises KeyboardInterrupt (a
    BaseException, so ``except Exception`` clauses let it through and ``finally`` and
    ``with`` blocks close their files on the way out)."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise _Terminated


def _with_sigterm(run: Any) -> int:
    """``run()`` with SIGTERM raising :class:`_Terminated` (main thread only, and not
    when SIGTERM is ignored); the previous handler is restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        return int(run())
    previous = signal.getsignal(signal.SIGTERM)
    if previous is not signal.SIG_DFL:  # ignored, or someone else's handler: keep it
        return int(run())
    signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        return int(run())
    finally:
        signal.signal(signal.SIGTERM, previous)


class _ParserError(UsageError):
    """argparse's own message, already prefixed with the command's name."""


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", DefaultsHelpFormatter)  # every help shows defaults
        super().__init__(*args, **kwargs)
        if self.prog != "robopercept":  # also after the command: robopercept edges --debug
            self.add_argument(
                "--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
            )

    def error(self, message: str) -> NoReturn:  # one line, exit 2
        raise _ParserError(
            f"{self.prog}: {message}{_did_you_mean(message)} (see {self.prog} --help)"
        )


def _did_you_mean(message: str) -> str:
    """``; did you mean 'edges'?`` for argparse's "invalid choice: 'edgs' (choose from
    ...)" when one choice is close (difflib), else ``""``."""
    m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    if not m:
        return ""
    choices = re.findall(r"'([^']*)'", m.group(2)) or [c.strip() for c in m.group(2).split(",")]
    close = difflib.get_close_matches(m.group(1), choices, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def _one_line_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """Show a warning as one line, ``robopercept: warning: <message>`` (no source path
    or code line, which mean nothing to a command-line user)."""
    text = str(message).strip().splitlines()
    print(f"robopercept: warning: {text[0] if text else category.__name__}", file=sys.stderr)


def build_parser() -> argparse.ArgumentParser:
    """The parser of every command (each command module's ``register``)."""
    from robopercept.cli import (
        batch,
        bgsub,
        blobs,
        calibrate,
        cloud,
        edges,
        features,
        flow,
        info,
        learn,
        meanshift,
        nn,
        plane_track,
        proposals,
        rgbd_import,
        stereo,
        track,
        warmup,
    )

    parser = _Parser(
        prog="robopercept",
        description="Robotic perception from the command line. Run a command with --help "
        "for its options. Exit codes: 0 success, 1 error (missing or bad file or data), "
        "2 usage error, 70 internal error (a bug), 130 interrupted, 143 stopped by SIGTERM.",
    )
    parser.add_argument("--version", action="version", version=f"robopercept {__version__}")
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the traceback of an error (as ROBOPERCEPT_DEBUG=1)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for module in (
        info,
        edges,
        blobs,
        features,
        cloud,
        learn,
        nn,
        plane_track,
        proposals,
        rgbd_import,
        bgsub,
        flow,
        meanshift,
        track,
        stereo,
        calibrate,
        warmup,
        batch,
    ):
        module.register(sub)
    return parser


def _first_line(exc: BaseException) -> str:
    text = str(exc)
    return text.splitlines()[0] if text.strip() else type(exc).__name__


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``robopercept`` command on ``argv`` (default ``sys.argv[1:]``) and return
    its exit code: 0, 1, 2, 70, 130 or 143 as the module docstring lists them. With
    ``--debug`` (or ``ROBOPERCEPT_DEBUG=1``) the errors of codes 1 and 70 are re-raised."""
    parser = build_parser()
    debug = bool(os.environ.get("ROBOPERCEPT_DEBUG"))
    with warnings.catch_warnings():
        warnings.showwarning = _one_line_warning
        return _with_sigterm(lambda: _main(parser, argv, debug))


def _run_command(args: argparse.Namespace) -> int:
    """``args.func(args)``, saying so while numba compiles kernels on first use
    (:class:`~robopercept.jit.CompileNotice`; silent with ``--quiet``)."""
    from robopercept.cli.warmup import first_use_seconds
    from robopercept.jit import CompileNotice

    command = str(args.command)
    quiet = bool(getattr(args, "quiet", False))
    with CompileNotice(command, first_use_seconds(command), enabled=not quiet):
        return int(args.func(args) or 0)


def _main(parser: argparse.ArgumentParser, argv: Sequence[str] | None, debug: bool) -> int:
    try:
        args = parser.parse_args(argv)
        debug = debug or bool(getattr(args, "debug", False))
        if not getattr(args, "func", None):
            parser.print_help()
            return 0
        return _run_command(args)
    except BrokenPipeError:  # output piped into `head` and closed: not an error
        sys.stderr.close()
        return 0
    except _ParserError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_USAGE
    except (UsageError, ArgumentError) as exc:  # the fix is a flag (RunExistsError too)
        print(f"robopercept: error: {_first_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("robopercept: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except _Terminated:
        print("robopercept: stopped by SIGTERM", file=sys.stderr)
        return EXIT_TERMINATED
    except (RoboperceptError, OSError, ValueError) as exc:
        if debug:
            raise
        print(f"robopercept: error: {_first_line(exc)}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:
        if debug:
            raise
        lines = str(exc).strip().splitlines()
        print(
            "robopercept: internal error (this is a bug, please report it): "
            f"{type(exc).__name__}: {lines[0] if lines else '(no message)'}; rerun with "
            "--debug for the traceback",
            file=sys.stderr,
        )
        return EXIT_INTERNAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
