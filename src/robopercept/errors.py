"""Typed exceptions used across robopercept.

Every error raised at a public boundary is one of these, and its message says what was
expected, what came, and how to fix it.
"""

from __future__ import annotations

__all__ = [
    "ArgumentError",
    "DegenerateError",
    "FileFormatError",
    "InputError",
    "NotFittedError",
    "RoboperceptError",
    "RunExistsError",
]


class RoboperceptError(Exception):
    """Base class of every robopercept error."""


class InputError(RoboperceptError, ValueError):
    """An argument has the wrong shape, dtype, range or value.

    Subclasses :class:`ValueError` so that code written against NumPy or OpenCV
    conventions (``except ValueError``) keeps working.
    """


class ArgumentError(InputError):
    """A value given for a command-line flag names nothing usable (an unknown data
    set, a missing file or folder, too few images); the message names the flag
    (``--data``, ``--images-dir``, ``RUN_OR_MODEL``). The command line reports it as a
    usage error (exit 2); in Python it is an :class:`InputError` like any other."""


class RunExistsError(ArgumentError):
    """An output folder already holds a training run, and neither resuming it nor
    replacing it was asked for (the command line's ``--resume`` / ``--overwrite``): a
    usage error, exit 2 on the command line."""


class DegenerateError(RoboperceptError, ArithmeticError):
    """The data cannot determine the result (collinear samples, singular system, ...)."""


class FileFormatError(RoboperceptError, OSError):
    """A file is missing, truncated, corrupt or not of a supported format."""


class NotFittedError(RoboperceptError, ValueError, AttributeError):
    """An estimator was asked to predict or transform before ``fit`` was called.

    Subclasses :class:`ValueError` and :class:`AttributeError` like scikit-learn's
    ``NotFittedError``, so code written for scikit-learn catches it.
    """
