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

from robopercept._checks import check_file, plain_repr
from robopercept.errors import FileFormatError

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
    (``frame,id,x,y,w,h,conf,-1,-1,-1``); returns the number of rows."""
    count = 0
    with Path(path).open("w") as fh:
        for frame, tid, box, conf in rows:
            x, y, w, h = (float(v) for v in box)
            c = float(conf) if np.isfinite(conf) else 1.0
            fh.write(f"{int(frame)},{int(tid)},{x:.2f},{y:.2f},{w:.2f},{h:.2f},{c:.4g},-1,-1,-1\n")
            count += 1
    return count
