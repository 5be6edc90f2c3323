"""The ``robopercept`` command.

Each command group lives in its own module and registers itself with :func:`register`.
Errors in arguments, missing or corrupt files, and bad values print one line on stderr
and exit with code 2; no traceback reaches the user (``ROBOPERCEPT_DEBUG=1`` shows it).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from robopercept import __version__
from robopercept.errors import RoboperceptError

__all__ = ["main"]

EXIT_USAGE = 2


class UsageError(Exception):
    """A command-line argument is wrong."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def build_parser() -> argparse.ArgumentParser:
    from robopercept.cli import (
        calibration,
        cloud,
        depth,
        features,
        imaging,
        info,
        learn,
        motion,
        tracking,
    )

    parser = _Parser(
        prog="robopercept",
        description="Robotic perception from the command line. Run a command with --help "
        "for its options.",
    )
    parser.add_argument("--version", action="version", version=f"robopercept {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    info.register(sub)
    imaging.register(sub)
    features.register(sub)
    cloud.register(sub)
    learn.register(sub)
    tracking.register(sub)
    motion.register(sub)
    depth.register(sub)
    calibration.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code (0 success, 2 usage or input error, 130 Ctrl-C)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 0
        return int(args.func(args) or 0)
    except BrokenPipeError:  # output piped into `head` and closed: not an error
        sys.stderr.close()
        return 0
    except UsageError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_USAGE
    except (RoboperceptError, OSError, ValueError) as exc:
        if os.environ.get("ROBOPERCEPT_DEBUG"):
            raise
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"robopercept: error: {msg}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("robopercept: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
