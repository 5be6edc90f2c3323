"""MOTChallenge text files: ``frame,id,x,y,w,h,conf,...`` one box per line.

Detections (``det.txt``) have id -1; ground truth (``gt.txt``) adds ``flag`` (1:
considered), ``class`` and ``visibility``; results are written with ``conf`` and three
``-1`` world coordinates, as the MOTChallenge devkit expects. Frames count from 1.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robopercept._checks import as_path, check_file, plain_repr
from robopercept.errors import FileFormatError, InputError

__all__ = ["MotRows", "read_mot", "write_mot"]


@dataclass(frozen=True)
class MotRows:
    """The rows of a MOTChallenge file, column by column."""

    frame: np.ndarray
    id: np.ndarray
    boxes: np.ndarray  # (N, 4) x, y, w, h
    conf: np.ndarray
    extra: np.ndarray  # (N, k) the remaining columns (class, visibility, ...)

    def __len__(self) -> int:
        return int(self.frame.size)

    def at(self, frame: int) -> MotRows:
        """The rows of one frame."""
        sel = self.frame == frame
        return MotRows(self.frame[sel], self.id[sel], self.boxes[sel], self.conf[sel],
                       self.extra[sel])  # fmt: skip


#: frame and id numbers are read as float64: beyond 2^53 they are no longer exact
MOT_MAX_NUMBER = 2**53


def read_mot(path: str | Path) -> MotRows:
    """Read a MOTChallenge ``det.txt``, ``gt.txt`` or results file.

    Each non-blank line is ``frame,id,x,y,w,h[,conf[,...]]`` (at least 6 numbers, the
    same count on every line). As the MOTChallenge devkit requires, ``frame`` is a
    whole number >= 1 and ``id`` a whole number >= -1 (-1: a detection without an
    identity, as in ``det.txt``), both below :data:`MOT_MAX_NUMBER` (2^53, exact in
    float64); every number on the line (box, confidence, the extra columns) is
    finite. ``conf`` is 1 when the file has 6 columns.

    Parameters
    ----------
    path : str or Path
        The text file.

    Returns
    -------
    MotRows
        ``frame`` and ``id`` as int64, ``boxes`` ``(N, 4)`` float64 ``x, y, w, h``,
        ``conf`` ``(N,)``, ``extra`` ``(N, k)`` the columns after ``conf``.

    Raises
    ------
    FileFormatError
        A missing file or a folder (says which), not UTF-8 text, a line that is not
        comma-separated numbers, a short or ragged line, or a frame, id or value out of
        the rules above; the message names the file and the line.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = pathlib.Path(d) / "det.txt"
    ...     _ = p.write_text("1,-1,10,20,30,40,0.9\\n2,-1,12,20,30,40,0.8\\n")
    ...     rows = read_mot(p)
    >>> rows.frame.tolist(), rows.id.tolist(), rows.conf.tolist()
    ([1, 2], [-1, -1], [0.9, 0.8])
    """
    path = check_file(path, "a MOTChallenge text file (det.txt)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text file") from None
    rows = []
    lines: list[int] = []
    width = None
    for i, line in enumerate(text.splitlines(), start=1):
        line = line.strip()
        if not line:
            continue
        try:
            values = [float(v) for v in line.replace(" ", "").split(",")]
        except ValueError:
            raise FileFormatError(f"{path}: line {i} is not comma-separated numbers") from None
        if len(values) < 6:
            raise FileFormatError(
                f"{path}: line {i} has {len(values)} fields; MOTChallenge rows have at "
                "least frame,id,x,y,w,h"
            )
        width = len(values) if width is None else width
        if len(values) != width:
            raise FileFormatError(f"{path}: line {i} has {len(values)} fields, line 1 {width}")
        rows.append(values)
        lines.append(i)
    if not rows:
        z = np.zeros(0)
        return MotRows(
            z.astype(np.int64), z.astype(np.int64), np.zeros((0, 4)), z, np.zeros((0, 0))
        )
    a = np.asarray(rows)
    _check_rows(a, lines, path)
    conf = a[:, 6] if a.shape[1] > 6 else np.ones(len(a))
    return MotRows(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6].copy(),
                   conf, a[:, 7:].copy())  # fmt: skip


def _check_rows(a: np.ndarray, lines: list[int], path: Path) -> None:
    """Refuse the first row (by its line number) whose numbers break the rules of
    :func:`read_mot`: non-finite values, or a frame / id that is not a whole number in
    ``[1, 2^53)`` / ``[-1, 2^53)``."""
    limit = f"below 2^53 ({MOT_MAX_NUMBER})"
    with np.errstate(invalid="ignore"):
        frame, tid = a[:, 0], a[:, 1]
        rules = (
            (
                (frame != np.round(frame)) | (frame < 1) | (frame >= MOT_MAX_NUMBER),
                f"frames are whole numbers from 1 (the first frame) {limit}",
            ),
            (
                (tid != np.round(tid)) | (tid < -1) | (tid >= MOT_MAX_NUMBER),
                f"ids are whole numbers from -1 (a detection without identity) {limit}",
            ),
            (~np.isfinite(a).all(axis=1), "every value must be finite (no nan or inf)"),
        )
    for bad, rule in rules:
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise FileFormatError(
                f"{path}: line {lines[k]} ({plain_repr(a[k])[1:-1][:120]}): {rule}; "
                "fix or drop that line"
            )


def write_mot(path: str | Path, rows: Iterable[tuple[int, int, Iterable[float], float]]) -> int:
    """Write ``(frame, id, (x, y, w, h), conf)`` rows as a MOTChallenge results file
    (``frame,id,x,y,w,h,conf,-1,-1,-1``); returns the number of rows.

    Parameters
    ----------
    path : str or Path
        The text file (its folder must exist).
    rows : iterable of (frame, id, (x, y, w, h), conf)
        ``frame`` a whole number >= 1, ``id`` a whole number >= -1 (the rules of
        :func:`read_mot`), the box four finite numbers; a non-finite ``conf`` is
        written as 1.

    Returns
    -------
    int

    Raises
    ------
    InputError
        A path that cannot name a file, or a row that breaks the rules above (the
        message names the row); nothing is written then.
    FileFormatError
        The file cannot be written (a missing folder, no permission).
    """
    target = as_path(path, "path")
    if isinstance(rows, (str, bytes)) or not isinstance(rows, Iterable):
        raise InputError(
            "rows must be a list of (frame, id, (x, y, w, h), conf) tuples; got "
            f"{type(rows).__name__} {plain_repr(rows)[:60]}"
        )
    lines = [_mot_line(i, row) for i, row in enumerate(rows)]
    try:
        with target.open("w") as fh:
            fh.writelines(lines)
    except OSError as exc:
        raise FileFormatError(
            f"{target}: cannot write the results ({exc.strerror or exc}): check that its "
            "folder exists and is writable"
        ) from None
    return len(lines)


def _whole(value: object, low: int) -> int | None:
    """``value`` as an int when it is a whole real number in ``[low, 2^53)``, else None."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        return None
    v = float(value)
    return int(v) if np.isfinite(v) and v.is_integer() and low <= v < MOT_MAX_NUMBER else None


def _mot_line(i: int, row: object) -> str:
    """One row of :func:`write_mot` as its text line, or an InputError naming it."""
    want = (
        f"rows[{i}] must be (frame, id, (x, y, w, h), conf) with frame a whole number >= 1, "
        f"id a whole number >= -1 and four finite box numbers; got {plain_repr(row)[:100]}"
    )
    if not isinstance(row, (tuple, list)) or len(row) != 4:
        raise InputError(want)
    frame, tid, box, conf = row
    f, t = _whole(frame, 1), _whole(tid, -1)
    if isinstance(box, np.ndarray):
        items = box.reshape(-1).tolist()
    else:
        items = list(box) if isinstance(box, (tuple, list)) else []
    ok_box = len(items) == 4 and all(
        isinstance(v, (int, float, np.integer, np.floating))
        and not isinstance(v, (bool, np.bool_))
        and np.isfinite(float(v))
        for v in items
    )
    ok_conf = isinstance(conf, (int, float, np.integer, np.floating)) and not isinstance(
        conf, (bool, np.bool_)
    )
    if f is None or t is None or not ok_box or not ok_conf:
        raise InputError(want)
    x, y, w, h = (float(v) for v in items)
    c = float(conf) if np.isfinite(float(conf)) else 1.0
    return f"{f},{t},{x:.2f},{y:.2f},{w:.2f},{h:.2f},{c:.4g},-1,-1,-1\n"
