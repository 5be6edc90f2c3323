"""Input guards shared by every public function.

Each guard raises :class:`~robopercept.errors.InputError` whose message names what was
expected, what came, and the fix. Guards return the (possibly converted) value so that
call sites read ``image = check_image(image)``.
"""

from __future__ import annotations

import os
import reprlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept.errors import FileFormatError, InputError

__all__ = [
    "as_float",
    "check_choice",
    "check_dtype",
    "check_extension",
    "check_file",
    "check_finite",
    "check_image",
    "check_kernel",
    "check_ndim",
    "check_nonempty",
    "check_odd_size",
    "check_positive",
    "check_range",
    "check_shape",
    "plain_repr",
    "resolve_alias",
    "squeeze_point_axis",
]

IMAGE_DTYPES = (np.uint8, np.uint16, np.int16, np.int32, np.float32, np.float64, np.bool_)
_IMAGE_DTYPE_SET = frozenset(np.dtype(d) for d in IMAGE_DTYPES)


def _as_array(value: npt.ArrayLike, name: str) -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - numpy raises many kinds
        raise InputError(f"{name} must be array-like; got {type(value).__name__}: {exc}") from exc
    if arr.dtype == object:
        raise InputError(
            f"{name} must be a numeric array; got {type(value).__name__} that NumPy reads "
            "as dtype=object: pass a rectangular list or a numpy array"
        )
    return arr


def check_ndim(value: npt.ArrayLike, name: str, ndims: Iterable[int]) -> np.ndarray:
    """Return ``value`` as an array whose number of dimensions is one of ``ndims``."""
    arr = _as_array(value, name)
    ndims = tuple(ndims)
    if arr.ndim not in ndims:
        expected = " or ".join(f"{d}-D" for d in ndims)
        raise InputError(
            f"{name} must be {expected}; got {arr.ndim}-D with shape {arr.shape}: "
            "reshape it or pass one item at a time"
        )
    return arr


def check_shape(value: npt.ArrayLike, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """Return ``value`` as an array of ``shape`` (``None`` matches any length)."""
    arr = _as_array(value, name)
    ok = arr.ndim == len(shape) and all(
        s is None or s == a for s, a in zip(shape, arr.shape, strict=False)
    )
    if not ok:
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(f"{name} must have shape {want}; got {arr.shape}")
    return arr


def check_dtype(
    value: npt.ArrayLike, name: str, dtypes: Iterable[Any] = IMAGE_DTYPES
) -> np.ndarray:
    """Return ``value`` as an array whose dtype is one of ``dtypes``."""
    arr = _as_array(value, name)
    if dtypes is IMAGE_DTYPES and arr.dtype in _IMAGE_DTYPE_SET:
        return arr  # (the common case, without building the dtypes each call)
    dtypes = tuple(np.dtype(d) for d in dtypes)
    if arr.dtype not in dtypes:
        names = ", ".join(d.name for d in dtypes)
        raise InputError(
            f"{name} must have dtype in ({names}); got {arr.dtype}: "
            f"convert with {name}.astype(np.float32) (values in [0, 1]) or np.uint8"
        )
    return arr


def check_finite(value: npt.ArrayLike, name: str) -> np.ndarray:
    """Return ``value`` as an array with no NaN or infinity."""
    arr = _as_array(value, name)
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        bad = int(arr.size - np.count_nonzero(np.isfinite(arr)))
        raise InputError(
            f"{name} must be finite; got {bad} NaN/inf value(s): "
            f"replace them first, e.g. np.nan_to_num({name})"
        )
    return arr


def check_nonempty(value: npt.ArrayLike, name: str) -> np.ndarray:
    """Return ``value`` as an array with at least one element along every axis."""
    arr = _as_array(value, name)
    if arr.size == 0:
        raise InputError(f"{name} must not be empty; got shape {arr.shape}")
    return arr


def check_range(
    value: float,
    name: str,
    low: float | None = None,
    high: float | None = None,
    *,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """Return the scalar ``value`` after checking ``low <= value <= high``."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be a number; got {plain_repr(value)}") from exc
    if not np.isfinite(v):
        raise InputError(f"{name} must be finite; got {plain_repr(value)}")
    too_low = low is not None and (v < low if low_inclusive else v <= low)
    too_high = high is not None and (v > high if high_inclusive else v >= high)
    if too_low or too_high:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        lb = "[" if low_inclusive else "("
        hb = "]" if high_inclusive else ")"
        raise InputError(f"{name} must be in {lb}{lo}, {hi}{hb}; got {plain_repr(value)}")
    return v


def check_positive(value: float, name: str) -> float:
    """Return the scalar ``value`` after checking that it is > 0."""
    return check_range(value, name, 0.0, None, low_inclusive=False)


def check_odd_size(value: npt.ArrayLike, name: str, minimum: int = 1) -> int:
    """Return ``value`` as an int after checking that it is odd and >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name} must be an odd integer; got {plain_repr(value)}")
    v = int(value)
    if v < minimum or v % 2 == 0:
        raise InputError(
            f"{name} must be an odd integer >= {minimum}; got {v}: try {max(minimum, v | 1)}"
        )
    return v


def check_choice(value: npt.ArrayLike, name: str, choices: Iterable[Any]) -> Any:
    """Return ``value`` after checking that it is one of ``choices``."""
    choices = tuple(choices)
    try:  # an array compares element-wise and has no single truth value
        known = not isinstance(value, np.ndarray) and value in choices
    except (TypeError, ValueError):
        known = False
    if not known:
        raise InputError(
            f"{name} must be one of {', '.join(map(plain_repr, choices))}; got {plain_repr(value)}"
        )
    return value


def check_image(
    image: npt.ArrayLike, name: str = "image", *, allow_color: bool = True, allow_bool: bool = False
) -> np.ndarray:
    """Return ``image`` as an ``(H, W)`` or ``(H, W, 3)`` array of a supported dtype.

    Refuses channels-first arrays, empty images, NaN/inf and unsupported dtypes with a
    message that names the fix.
    """
    arr = _as_array(image, name)
    if arr.ndim == 3 and arr.shape[2] != 3:
        hint = ""
        if arr.shape[0] in (1, 3, 4) and arr.shape[2] > 4:
            hint = f": channels-first? use {name}.transpose(1, 2, 0)"
        elif arr.shape[2] == 4:
            hint = f": RGBA? drop alpha with {name}[..., :3]"
        elif arr.shape[2] == 1:
            hint = f": use {name}[..., 0]"
        raise InputError(f"{name} must be (H, W) or (H, W, 3); got {arr.shape}{hint}")
    if arr.ndim == 3 and not allow_color:
        raise InputError(
            f"{name} must be a gray (H, W) image; got {arr.shape}: "
            "convert with robopercept.imaging.rgb_to_gray"
        )
    if arr.ndim not in (2, 3):
        raise InputError(
            f"{name} must be (H, W)"
            + (" or (H, W, 3)" if allow_color else "")
            + f"; got {arr.ndim}-D with shape {arr.shape}"
        )
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(f"{name} must not be empty; got shape {arr.shape}")
    if arr.dtype == np.bool_ and not allow_bool:
        raise InputError(f"{name} must be numeric; got dtype bool: use {name}.astype(np.uint8)")
    check_dtype(arr, name)
    return check_finite(arr, name)


def check_kernel(kernel: npt.ArrayLike, name: str = "kernel", ndim: int = 2) -> np.ndarray:
    """Return ``kernel`` as a finite, non-empty float64 array of ``ndim`` dimensions."""
    arr = check_ndim(kernel, name, (ndim,))
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name} must be numeric; got dtype {arr.dtype}")
    arr = check_nonempty(arr, name).astype(np.float64)
    return check_finite(arr, name)


def as_float(image: np.ndarray) -> np.ndarray:
    """Return a floating view/copy: float32 and float64 stay; integers become float32.

    Values are not rescaled: a uint8 255 becomes 255.0.
    """
    if image.dtype in (np.float32, np.float64):
        return image
    return image.astype(np.float32)


def check_int(value: npt.ArrayLike, name: str, minimum: int | None = None) -> int:
    """Return ``value`` as an int after checking that it is an integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{name} must be an integer; got {plain_repr(value)}")
    v = int(value)
    if minimum is not None and v < minimum:
        raise InputError(f"{name} must be >= {minimum}; got {v}")
    return v


def squeeze_point_axis(arr: np.ndarray, dim: int | None) -> np.ndarray:
    """OpenCV's ``(N, 1, dim)`` point vectors as ``(N, dim)``; any other array unchanged.

    ``cv2.goodFeaturesToTrack``, ``cv2.findChessboardCorners``,
    ``cv2.calcOpticalFlowPyrLK`` and ``cv2.perspectiveTransform`` hold N points of
    ``dim`` coordinates as an ``(N, 1, dim)`` array (a column of 2- or 3-channel
    elements); this view drops the middle axis so that a guard written for ``(N, dim)``
    accepts them. ``dim=None`` squeezes any ``(N, 1, D)``. Returns a view, never a copy.

    Parameters
    ----------
    arr : ndarray
    dim : int or None
        Coordinates per point the caller wants.

    Returns
    -------
    ndarray
        ``arr.reshape(N, dim)`` for an ``(N, 1, dim)`` array, else ``arr``.

    Examples
    --------
    >>> squeeze_point_axis(np.zeros((5, 1, 2), np.float32), 2).shape
    (5, 2)
    >>> squeeze_point_axis(np.zeros((5, 2, 1)), 2).shape
    (5, 2, 1)
    """
    if arr.ndim == 3 and arr.shape[1] == 1 and (dim is None or arr.shape[2] == dim):
        return arr.reshape(arr.shape[0], arr.shape[2])
    return arr


def check_points(value: npt.ArrayLike, name: str = "points", dim: int | None = 3) -> np.ndarray:
    """Return ``value`` as a float64 ``(N, dim)`` array (NaN/inf allowed: callers decide).

    ``dim=None`` accepts any number of columns. OpenCV's ``(N, 1, dim)`` point vectors
    (``cv2.goodFeaturesToTrack``, ``cv2.findChessboardCorners``) are taken as
    ``(N, dim)`` (:func:`squeeze_point_axis`).
    """
    arr = squeeze_point_axis(_as_array(value, name), dim)
    if arr.ndim != 2 or (dim is not None and arr.shape[1] != dim):
        want = f"(N, {dim})" if dim is not None else "(N, D)"
        hint = ""
        if dim is not None and arr.ndim == 2 and arr.shape[0] == dim:
            hint = f": points as columns? use {name}.T"
        elif dim is not None and arr.ndim == 1 and arr.size == dim:
            hint = f": a single point? use {name}[None, :]"
        alt = f" (or OpenCV's (N, 1, {dim}))" if dim is not None else ""
        raise InputError(f"{name} must have shape {want}{alt}; got {arr.shape}{hint}")
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name} must be numeric; got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def as_rng(rng: int | np.integer | np.random.Generator | None) -> np.random.Generator:
    """``rng`` as a NumPy Generator: an int seed, a Generator, or None (fresh entropy)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None:
        return np.random.default_rng()
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        if rng < 0:  # NumPy's SeedSequence raises an untyped ValueError
            raise InputError(
                f"rng must be an int seed >= 0, a numpy.random.Generator or None; got {rng}"
            )
        return np.random.default_rng(int(rng))
    raise InputError(f"rng must be an int seed, a numpy.random.Generator or None; got {rng!r}")


def plain_repr(value: Any) -> str:
    """``repr(value)`` with NumPy scalars and arrays written as the Python numbers and
    lists they hold, for error messages.

    ``repr((np.float64(1.5), 2))`` is ``(np.float64(1.5), 2)`` under NumPy 2; a message
    shows ``(1.5, 2)``. Tuples and lists are converted element by element; anything
    else is left to ``repr``. The text is bounded whatever the value (:data:`_REPR`):
    at most 30 items of a list and 6 levels of nesting are shown, strings and other
    objects are shortened to 240 characters, so a hostile argument (a list nested
    10,000 deep, an array of a million numbers) gives a short message, not a
    ``RecursionError`` or a megabyte of text.

    Parameters
    ----------
    value : object

    Returns
    -------
    str

    Examples
    --------
    >>> plain_repr((np.float64(1000.0), np.int64(3)))
    '(1000.0, 3)'
    >>> plain_repr(np.array([1.0, 2.5]))
    '[1.0, 2.5]'
    """

    def plain(v: Any, depth: int) -> Any:
        if isinstance(v, np.ndarray) and v.size > _REPR.maxlist:
            v = v.reshape(-1)[: _REPR.maxlist + 1]  # enough to show "..."
        if isinstance(v, (np.generic, np.ndarray)) and v.dtype != object:
            return v.tolist()
        if isinstance(v, (tuple, list)):
            if depth >= _REPR.maxlevel:
                return v  # reprlib writes [...] for it
            return type(v)(plain(x, depth + 1) for x in v[: _REPR.maxlist + 1])
        return v

    try:
        return _REPR.repr(plain(value, 0))
    except Exception:  # a __repr__ that fails
        return f"<{type(value).__name__}>"


_REPR = reprlib.Repr()
_REPR.maxlevel = 6
_REPR.maxlist = _REPR.maxtuple = _REPR.maxset = _REPR.maxdict = 30
_REPR.maxstring = _REPR.maxother = 240
_REPR.maxlong = 80


def as_path(value: Any, name: str = "path") -> Path:
    """Return ``value`` as a :class:`~pathlib.Path` after checking that it can name a
    file: a ``str``, ``bytes`` (decoded with :func:`os.fsdecode`) or ``os.PathLike``,
    without a NUL byte, no name in it longer than 255 bytes and at most 4095 bytes in
    all (Linux's ``NAME_MAX`` and ``PATH_MAX``, which the OS would refuse with
    ``OSError`` only once the file is opened).

    Parameters
    ----------
    value : str, bytes or path-like
    name : str
        The parameter's name (or the CLI flag) for the message.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Another type, an empty path, a NUL byte, or a name or path too long.

    Examples
    --------
    >>> as_path(b"out/plane.csv")
    PosixPath('out/plane.csv')
    >>> as_path(None, "out")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: out must be a file or folder path (str or pathlib.Path); got None
    """
    if isinstance(value, bytes):
        value = os.fsdecode(value)
    if not isinstance(value, (str, os.PathLike)):
        raise InputError(
            f"{name} must be a file or folder path (str or pathlib.Path); got {plain_repr(value)}"
        )
    text = os.fspath(value)
    if not isinstance(text, str):  # a PathLike that gives bytes
        text = os.fsdecode(text)
    if text == "":
        raise InputError(f"{name} must not be empty; give a file or folder path")
    if "\x00" in text:
        raise InputError(f"{name} contains a NUL byte; got {text!r}")
    encoded = os.fsencode(text)
    longest = max(len(part) for part in encoded.split(b"/"))
    if longest > 255 or len(encoded) > 4095:
        raise InputError(
            f"{name}: file name too long ({longest} bytes in one name, {len(encoded)} in all; "
            f"the limits are 255 and 4095): {text[:60]}..."
        )
    return Path(text)


def check_file(path: str | os.PathLike[str], what: str) -> Path:
    """Return ``path`` after checking that it names an existing file.

    Parameters
    ----------
    path : path-like
    what : str
        What the caller reads, with its article, for the message of a folder
        (``"an image file"``, ``"a point cloud (.ply or .pcd)"``).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Not a usable path (:func:`as_path`).
    FileFormatError
        ``"<path> is a folder; give <what>"`` for a folder, ``"<path>: no such file"``
        for a path that does not exist.

    Examples
    --------
    >>> check_file(".", "an image file")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: . is a folder; give an image file
    """
    p = as_path(path, f"the path of {what}")
    if p.is_dir():
        raise FileFormatError(f"{p} is a folder; give {what}")
    if not p.exists():
        raise FileFormatError(f"{p}: no such file")
    return p


def check_extension(path: str | os.PathLike[str], extensions: Iterable[str], what: str) -> Path:
    """Return ``path`` after checking that its extension (any case) is one of
    ``extensions`` (lower case, with the dot).

    Parameters
    ----------
    path : path-like
    extensions : iterable of str
        ``{".png", ".jpg"}``.
    what : str
        What the file holds, for the message (``"a video"``).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        ``"<path>: <what> needs one of the extensions <extensions>; got '<ext>'"``, or
        not a usable path (:func:`as_path`).

    Examples
    --------
    >>> check_extension("clip.gif", {".mp4"}, "a video")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: clip.gif: a video needs the extension .mp4; got '.gif'
    """
    p = as_path(path, f"the path of {what}")
    allowed = sorted(extensions)
    if p.suffix.lower() not in allowed:
        got = repr(p.suffix) if p.suffix else "no extension"
        want = "the extension" if len(allowed) == 1 else "one of the extensions"
        raise InputError(f"{p}: {what} needs {want} {', '.join(allowed)}; got {got}")
    return p


def check_real(
    value: Any,
    name: str,
    low: float | None = None,
    high: float | None = None,
    *,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """:func:`check_range` for a parameter that must be one real number: also refuses
    ``bool``, ``None``, strings, lists and arrays of more than one value.

    Parameters
    ----------
    value : int or float
    name : str
        The parameter (or CLI flag) named in the message.
    low, high, low_inclusive, high_inclusive
        As in :func:`check_range`.

    Returns
    -------
    float

    Examples
    --------
    >>> check_real(2, "sigma", 0.0)
    2.0
    >>> check_real(True, "sigma")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: sigma must be a real number; got bool True: pass a float
    """
    scalar = isinstance(value, (int, float, np.integer, np.floating)) or (
        isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf"
    )
    if isinstance(value, (bool, np.bool_)) or not scalar:
        raise InputError(
            f"{name} must be a real number; got {type(value).__name__} {plain_repr(value)}: "
            "pass a float"
        )
    return check_range(
        value, name, low, high, low_inclusive=low_inclusive, high_inclusive=high_inclusive
    )


def check_bool(value: Any, name: str) -> bool:
    """Return ``value`` as a bool after checking that it is ``True`` or ``False``
    (a NumPy bool included); ``"yes"``, 1 or None are refused.

    Examples
    --------
    >>> check_bool(np.True_, "refine")
    True
    """
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be True or False; got {plain_repr(value)}")
    return bool(value)


def check_magnitude(
    value: npt.ArrayLike, name: str, limit: float = 1e150, smallest: float | None = None
) -> np.ndarray:
    """Return ``value`` as an array after checking that its finite values stay within
    ``limit`` in magnitude (and, with ``smallest``, that a non-zero array reaches it).

    Squares and products of values beyond about 1e154 overflow float64 (and of values
    below 1e-154 underflow to 0; for float32, beyond about 1e19), so variances,
    distances and covariances computed from such input are inf, NaN or 0. Functions
    whose arithmetic squares their input refuse it here rather than return NaN or raise
    a NumPy/SciPy error; each picks ``limit`` from the highest power of its input it
    computes and its working precision.

    Parameters
    ----------
    value : array_like
    name : str
        The argument named in the message.
    limit : float
        Largest allowed absolute value.
    smallest : float, optional
        When given, an array whose largest absolute value is non-zero but below it is
        refused too (all its squares underflow).

    Returns
    -------
    ndarray

    Raises
    ------
    InputError
        ``"<name> has values up to <m>; values beyond <limit> overflow ...: rescale your
        data"`` (integers are checked too).

    Examples
    --------
    >>> check_magnitude([1.0, -1e300], "X")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: X has values up to 1e+300; values beyond 1e+150 ...
    """
    arr = _as_array(value, name)
    if arr.size == 0 or arr.dtype.kind not in "iuf":
        return arr
    if arr.dtype.kind in "iu" and smallest is None and np.iinfo(arr.dtype).max <= limit:
        return arr  # (uint8, uint16 images: nothing to look at)
    if arr.dtype.kind == "f":
        # two reductions, no temporary, when every value is finite (the usual case);
        # gathering the finite values first cost 5 ms on 2 x 10^5 points. NaN or inf
        # makes the maximum not finite: then the largest of the finite values, as the
        # message needs
        hi, lo = float(arr.max()), float(arr.min())  # no |arr| temporary
        m = max(abs(hi), abs(lo))  # NaN when any value is NaN (max and min propagate it)
        if not np.isfinite(m):
            finite = np.abs(arr[np.isfinite(arr)])
            m = float(finite.max()) if finite.size else 0.0
    else:
        m = float(np.abs(arr.astype(np.float64)).max())
    if m > limit:
        raise InputError(
            f"{name} has values up to {m:.3g}; values beyond {limit:.3g} overflow the "
            "floating-point arithmetic: rescale your data (e.g. divide by its largest "
            "absolute value)"
        )
    if smallest is not None and 0.0 < m < smallest:
        raise InputError(
            f"{name} has values only up to {m:.3g}; values below {smallest:.3g} underflow "
            "the floating-point arithmetic: rescale your data (e.g. divide by its largest "
            "absolute value)"
        )
    return arr


def check_text(value: Any, name: str) -> str:
    """Return ``value`` after checking that it is a ``str`` (a title, a label, a caption);
    None, numbers, bytes and lists are refused rather than printed as their ``repr``.

    Examples
    --------
    >>> check_text(["x"], "xlabel")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: xlabel must be a string; got list ['x']: pass str(...) of it
    """
    if not isinstance(value, str):
        raise InputError(
            f"{name} must be a string; got {type(value).__name__} {plain_repr(value)}: "
            "pass str(...) of it"
        )
    return value


def check_reals(
    value: Any,
    name: str,
    length: int | None = None,
    low: float | None = None,
    high: float | None = None,
) -> np.ndarray:
    """Return ``value`` as a float64 1-D array of finite real numbers (a colour, a bound,
    a position): ``length`` of them when given, each in ``[low, high]`` when given.

    Bools, None, strings, complex numbers and ragged or nested sequences are refused
    (``(10, [1, 2], 20)`` would make NumPy raise ``ValueError``; ``("3", "3")`` would be
    parsed).

    Examples
    --------
    >>> check_reals((0, 255.0, 7), "color", 3, 0, 255)
    array([  0., 255.,   7.])
    >>> check_reals((0, float("inf"), 0), "color", 3)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: color must be 3 finite real numbers; got (0, inf, 0)
    """
    want = f"{length} finite real numbers" if length is not None else "finite real numbers"
    items = value.tolist() if isinstance(value, np.ndarray) and value.ndim == 1 else value
    real = (int, float, np.integer, np.floating)
    ok = isinstance(items, (tuple, list)) and all(
        isinstance(v, real) and not isinstance(v, (bool, np.bool_)) for v in items
    )
    if not ok or (length is not None and len(items) != length):
        raise InputError(f"{name} must be {want}; got {plain_repr(value)}")
    arr = np.array(items, dtype=np.float64).reshape(-1)
    if not np.isfinite(arr).all():
        raise InputError(f"{name} must be {want}; got {plain_repr(value)}")
    if (low is not None and (arr < low).any()) or (high is not None and (arr > high).any()):
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        raise InputError(f"{name} must be in [{lo}, {hi}]; got {plain_repr(value)}")
    return arr


def check_numeric(value: Any, name: str) -> np.ndarray:
    """Return ``value`` as a float64 array after checking that NumPy reads it as real
    numbers (bool, integer or floating point dtype).

    Strings, complex numbers (whose imaginary part ``astype(float)`` would drop
    silently), None, objects and ragged lists are refused with :class:`InputError`
    rather than surfacing as NumPy's ``ValueError``/``TypeError``. Shape and
    finiteness are the caller's to check.

    Examples
    --------
    >>> check_numeric([[1, 2], [3, 4]], "K").dtype
    dtype('float64')
    >>> check_numeric([1 + 2j], "t")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: t must hold real numbers; got dtype complex128: ...
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged or nested sequences
        raise InputError(
            f"{name} must be a numeric array; got {type(value).__name__} that NumPy cannot "
            f"read as one ({exc}): pass a rectangular list or a numpy array"
        ) from None
    if arr.dtype.kind not in "biuf":
        raise InputError(
            f"{name} must hold real numbers; got dtype {arr.dtype}: pass a float array"
        )
    return arr.astype(np.float64, copy=False)


def check_size(
    value: Any,
    name: str = "size",
    minimum: int = 1,
    maximum: int = 65536,
    max_pixels: int | None = None,
) -> tuple[int, int]:
    """Return an image size ``(width, height)`` as two ints after checking that each is
    a whole number in ``[minimum, maximum]`` and, with ``max_pixels``, that
    ``width * height`` does not exceed it (a bound on what the caller allocates).

    Integral floats (``640.0``) are accepted; None, strings, NaN/inf, fractions, bools
    and sequences of another length are refused.

    Examples
    --------
    >>> check_size((640.0, 480))
    (640, 480)
    >>> check_size(7)
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: size must be (width, height), two whole numbers of pixels; got 7
    """
    want = f"{name} must be (width, height), two whole numbers of pixels; got {plain_repr(value)}"
    items = value.tolist() if isinstance(value, np.ndarray) and value.ndim == 1 else value
    if not isinstance(items, (tuple, list)) or len(items) != 2:
        raise InputError(want)
    out = []
    for v in items:
        if isinstance(v, (bool, np.bool_)) or not isinstance(
            v, (int, float, np.integer, np.floating)
        ):
            raise InputError(want)
        if isinstance(v, (float, np.floating)) and not (np.isfinite(v) and float(v).is_integer()):
            raise InputError(want)
        out.append(int(v))
    w, h = out
    if min(w, h) < minimum or max(w, h) > maximum:
        raise InputError(
            f"{name} must be (width, height) with each side in [{minimum}, {maximum}] "
            f"pixels; got {plain_repr(value)}"
        )
    if max_pixels is not None and w * h > max_pixels:
        raise InputError(
            f"{name} {plain_repr(value)} has {w * h} pixels, more than the {max_pixels} "
            "allowed here (the arrays would take several GiB): use a smaller size"
        )
    return w, h


def resolve_alias(
    value: Any, name: str, alias_value: Any, alias_name: str, library: str = "Open3D"
) -> Any:
    """The value of a keyword given under its own ``name`` or under another library's
    spelling ``alias_name`` (Open3D's ``nb_neighbors`` for ``k``, ...); ``None`` stands
    for "not given".

    Parameters
    ----------
    value : object
        The value under ``name`` (None when not given).
    name : str
    alias_value : object
        The value under ``alias_name`` (None when not given).
    alias_name : str
    library : str
        Whose spelling the alias is (``"Open3D"``, ``"OpenCV"``), for the message.

    Returns
    -------
    object
        Whichever was given; None when neither was.

    Raises
    ------
    InputError
        Both were given, naming both spellings.

    Examples
    --------
    >>> resolve_alias(None, "k", 20, "nb_neighbors")
    20
    >>> resolve_alias(30, "k", 20, "nb_neighbors")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: give k or its Open3D spelling nb_neighbors, not both ...
    """
    if alias_value is None:
        return value
    if value is not None:
        raise InputError(
            f"give {name} or its {library} spelling {alias_name}, not both (got {name}="
            f"{plain_repr(value)} and {alias_name}={plain_repr(alias_value)}): drop one"
        )
    return alias_value
