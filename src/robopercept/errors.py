"""Typed exceptions used across robopercept.

Every error raised at a public boundary is one of these, and its message says what was
expected, what came, and how to fix it.
"""

from __future__ import annotations

__all__ = [
    "ArgumentError",
    "DegenerateError",
    "EmptyResultError",
    "FileFormatError",
    "InputError",
    "NotFittedError",
    "RoboperceptError",
    "RoboperceptWarning",
    "RunExistsError",
]


class RoboperceptError(Exception):
    """Base class of every robopercept error."""


class InputError(RoboperceptError, ValueError):
    """An argument has the wrong shape, dtype, range or value.

    Subclasses :class:`ValueError` so that code written against NumPy or OpenCV
    conventions (``except ValueError``) keeps working.
    """


class EmptyResultError(InputError):
    """Valid arguments that leave nothing to return or write: a filter that removes
    every point of a cloud, a video too short for the method. Raised before anything is
    written, so no empty file is left behind; the command line reports it as an error
    (exit 1). An :class:`InputError`, since the fix is another argument (a wider range,
    a longer input)."""


class RoboperceptWarning(UserWarning):
    """A result was computed (and written) but looks implausible: a stereo pair that
    looks swapped, no board found in any frame, a requested snapshot beyond the last
    frame. The command line shows it as one line, ``robopercept: warning: ...``; in
    Python, ``warnings.simplefilter("error", RoboperceptWarning)`` turns these into
    errors."""


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
