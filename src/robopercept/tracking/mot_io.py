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

from robopercept._checks import check_file
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


def read_mot(path: str | Path) -> MotRows:
    """Read a MOTChallenge ``det.txt``, ``gt.txt`` or results file (a missing file or a
    folder is a :class:`~robopercept.errors.FileFormatError` that says which)."""
    path = check_file(path, "a MOTChallenge text file (det.txt)")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text file") from None
    rows = []
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
    if not rows:
        z = np.zeros(0)
        return MotRows(
            z.astype(np.int64), z.astype(np.int64), np.zeros((0, 4)), z, np.zeros((0, 0))
        )
    a = np.asarray(rows)
    conf = a[:, 6] if a.shape[1] > 6 else np.ones(len(a))
    return MotRows(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6].copy(),
                   conf, a[:, 7:].copy())  # fmt: skip


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
