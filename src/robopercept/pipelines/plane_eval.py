r"""Figures of a plane-tracking run: errors against the ground truth, jitter, status
counts and timing, in a typed :class:`PlaneTrackSummary`.

Errors of a plane :math:`(n, d)` against the truth :math:`(n^*, d^*)` (both with
:math:`n^\top x = d`, :math:`d \ge 0`): the angle between the normals,
:math:`\arccos |n^\top n^*|` in degrees, and the offset :math:`|d - d^*|` in millimetres
(:func:`plane_errors`). The *raw* figures are those of every measured plane, accepted or
not (what the fit alone would give); the *tracked* figures those of the track's plane.
Both count only frames whose board has at least ``min_board_pixels`` pixels with depth.

Jitter is the RMS of the second difference of consecutive unit normals, in degrees:
smooth motion cancels in it, frame-to-frame noise does not.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept._checks import check_int, check_numeric, check_real, check_reals, plain_repr
from robopercept.errors import InputError
from robopercept.pipelines.plane_tracking import STAGES, PlaneTrackResult
from robopercept.tracking.gated import TrackStatus

__all__ = ["ErrorStats", "PlaneErrorStats", "PlaneTrackSummary", "plane_errors", "summarize"]


def plane_errors(
    normal: np.ndarray, d: float, true_normal: np.ndarray, true_d: float
) -> tuple[float, float]:
    """Angle between the normals (degrees, sign ignored) and ``|d - d_true|`` (metres),
    with both planes in the ``n.x = d``, ``d >= 0`` form; NaN for a missing plane
    (a non-finite ``normal`` or ``d``).

    The normals need not be unit vectors: each is divided by its largest component
    first, so any finite non-zero scale gives the same angle.

    Raises
    ------
    InputError
        A normal that is not 3 real numbers, a zero or non-finite ``true_normal``, a
        non-finite ``true_d``, or a ``d`` that is not a number.

    Examples
    --------
    >>> plane_errors(np.array([0.0, 0.0, 2.0]), 1.5, np.array([0.0, 0.0, 1.0]), 1.0)
    (0.0, 0.5)
    """
    n = check_numeric(normal, "normal")
    if n.shape != (3,):
        raise InputError(f"normal must be 3 numbers (nx, ny, nz); got shape {n.shape}")
    m = check_reals(true_normal, "true_normal", 3)
    true_d = check_real(true_d, "true_d")
    if isinstance(d, (bool, np.bool_)) or not isinstance(d, (int, float, np.integer, np.floating)):
        raise InputError(f"d must be a number (NaN for a missing plane); got {plain_repr(d)}")
    try:
        d = float(d)  # a Python int beyond float64 (2**1024) does not convert
    except OverflowError:
        raise InputError(f"d must be a number within float64's range; got {d}") from None
    if not (np.isfinite(n).all() and math.isfinite(d)):
        return math.nan, math.nan
    if not (np.abs(m).max() > 0 and np.abs(n).max() > 0):
        raise InputError(
            f"normals must be non-zero; got normal={n.tolist()}, true_normal={m.tolist()}"
        )
    n, m = n / np.abs(n).max(), m / np.abs(m).max()
    c = abs(float(n @ m) / (np.linalg.norm(n) * np.linalg.norm(m)))
    return math.degrees(math.acos(min(c, 1.0))), abs(float(d) - true_d)


@dataclass(frozen=True)
class ErrorStats:
    """Median and 95th percentile of a list of errors (None when empty)."""

    median: float | None
    p95: float | None
    n: int

    @classmethod
    def of(cls, values: Sequence[float]) -> ErrorStats:
        """The statistics of the finite ``values``."""
        v = np.asarray([x for x in values if np.isfinite(x)], dtype=np.float64)
        if v.size == 0:
            return cls(None, None, 0)
        return cls(float(np.median(v)), float(np.percentile(v, 95)), int(v.size))


@dataclass(frozen=True)
class PlaneErrorStats:
    """Angle (degrees) and offset (millimetres) error statistics of one plane series."""

    angle_deg: ErrorStats
    offset_mm: ErrorStats


@dataclass(frozen=True)
class PlaneTrackSummary:
    """The figures of a run (:func:`summarize`); ``to_dict()`` gives ``summary.json``.

    Attributes
    ----------
    frames, skipped_frames : int
        Frames processed; frames the source skipped (unreadable), reported as is.
    measured_frames, accepted_frames : int
        Frames where a plane was measured; where the track accepted it.
    status_counts : dict of str to int
        Frames per :class:`~robopercept.tracking.TrackStatus` value (every status
        present, zeros included).
    ms_per_stage_median : dict of str to float
        Median milliseconds of each stage (``points``, ``color``, ``ransac``,
        ``kalman``, ``total``): the tracker's own work per frame.
    fps : float or None
        ``1000 / median total ms``: the tracker's rate.
    jitter_raw_deg, jitter_tracked_deg : float or None
        Normal jitter (:func:`jitter`) of the accepted measurements and of the track,
        over the same frames: the second differences whose three frames all have an
        accepted measurement (a frame the gate rejected has no raw normal, and leaving
        only the track's hardest frames in would compare different motions).
    jitter_tracked_all_deg : float or None
        The track's jitter over every frame, coasting ones included.
    evaluated_frames : int or None
        Frames with a ground truth and at least ``min_board_pixels`` valid board pixels
        (None without ground truth).
    detection_rate : float or None
        Share of the evaluated frames with an accepted plane.
    raw, tracked : PlaneErrorStats or None
        Errors of the measured planes and of the track on the evaluated frames.
    wall_seconds, wall_fps : float or None
        Wall time of the whole run (source, tracker and outputs) and frames per second
        of it.
    stopped : str or None
        Why the run ended early (``"interrupted"``, or the source's error).
    outputs : tuple of str
        Files written.
    """

    frames: int
    skipped_frames: int
    measured_frames: int
    accepted_frames: int
    status_counts: dict[str, int]
    ms_per_stage_median: dict[str, float | None]
    fps: float | None
    jitter_raw_deg: float | None
    jitter_tracked_deg: float | None
    evaluated_frames: int | None = None
    detection_rate: float | None = None
    raw: PlaneErrorStats | None = None
    tracked: PlaneErrorStats | None = None
    jitter_tracked_all_deg: float | None = None
    wall_seconds: float | None = None
    wall_fps: float | None = None
    stopped: str | None = None
    outputs: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dictionary (nested dataclasses become dictionaries)."""
        out = dataclasses.asdict(self)
        out["outputs"] = list(self.outputs)
        return out

    def replace(self, **changes: Any) -> PlaneTrackSummary:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


def jitter(normals: np.ndarray) -> float | None:
    """RMS of the second difference of consecutive unit normals ``(T, 3)`` (rows may be
    NaN), degrees, after aligning each normal's sign with the previous one; None with
    fewer than three consecutive finite normals."""
    if normals.shape[0] < 3:
        return None
    n = normals.copy()
    for i in range(1, n.shape[0]):
        if np.isfinite(n[i]).all() and np.isfinite(n[i - 1]).all() and n[i] @ n[i - 1] < 0:
            n[i] = -n[i]
    dd = n[2:] - 2 * n[1:-1] + n[:-2]
    ok = np.isfinite(dd).all(axis=1)
    if not ok.any():
        return None
    return float(np.degrees(np.sqrt(np.mean(np.sum(dd[ok] ** 2, axis=1)))))


def summarize(
    results: Sequence[PlaneTrackResult],
    truths: Sequence[dict[str, Any]] | None = None,
    *,
    min_board_pixels: int = 500,
    skipped: int = 0,
    wall_seconds: float | None = None,
) -> PlaneTrackSummary:
    """Figures of a run: status counts, errors against the truth, jitter, timing.

    Parameters
    ----------
    results : sequence of PlaneTrackResult
    truths : sequence of dict, optional
        Per result, the frame's ground truth: ``"plane": (n, d)`` and optionally
        ``"valid_board_pixels"`` (board pixels with valid depth). Frames with fewer than
        ``min_board_pixels`` such pixels are left out of the detection rate and the
        errors; the errors are left out altogether without truths.
    min_board_pixels : int
    skipped : int
        Frames the source skipped (corrupt files), reported as is.
    wall_seconds : float, optional
        Wall time of the run, for ``wall_fps``.

    Returns
    -------
    PlaneTrackSummary

    Raises
    ------
    InputError
        ``results`` not a sequence of PlaneTrackResult, ``truths`` not None or a
        sequence of dicts (one per result), or a count or time of the wrong type.
    """
    if not isinstance(results, Sequence) or isinstance(results, (str, bytes)):
        raise InputError(
            f"results must be a list of PlaneTrackResult; got {type(results).__name__}"
        )
    bad = next((r for r in results if not isinstance(r, PlaneTrackResult)), None)
    if bad is not None:
        raise InputError(f"results must hold PlaneTrackResult objects; got {type(bad).__name__}")
    if truths is not None and (
        not isinstance(truths, Sequence) or not all(isinstance(t, dict) for t in truths)
    ):
        raise InputError("truths must be None or a list of dicts (one frame's ground truth each)")
    min_board_pixels = check_int(min_board_pixels, "min_board_pixels", 0)
    skipped = check_int(skipped, "skipped", 0)
    if wall_seconds is not None:
        wall_seconds = check_real(wall_seconds, "wall_seconds", 0.0)
    counts = {str(s): 0 for s in TrackStatus}
    for r in results:
        counts[str(r.status)] += 1
    ms = {s: [r.ms[s] for r in results] for s in (*STAGES, "total")}
    med = {s: float(np.median(v)) if v else None for s, v in ms.items()}
    total = med["total"]
    raw_n = np.array([r.normal if r.accepted else np.full(3, np.nan) for r in results])
    trk_n = np.array([r.track_normal for r in results])
    summary = PlaneTrackSummary(
        frames=len(results),
        skipped_frames=int(skipped),
        measured_frames=int(sum(r.measured for r in results)),
        accepted_frames=int(sum(r.accepted for r in results)),
        status_counts=counts,
        ms_per_stage_median=med,
        fps=1000.0 / total if total else None,
        jitter_raw_deg=jitter(raw_n.reshape(-1, 3)),
        jitter_tracked_deg=jitter(np.where(np.isfinite(raw_n), trk_n, np.nan).reshape(-1, 3)),
        jitter_tracked_all_deg=jitter(trk_n.reshape(-1, 3)),
        wall_seconds=wall_seconds,
        wall_fps=len(results) / wall_seconds if wall_seconds else None,
    )
    if truths is None or not any("plane" in t for t in truths):
        return summary
    if len(truths) != len(results):
        raise InputError(f"need one truth per result; got {len(truths)} for {len(results)}")
    ra, rd, ta, td = [], [], [], []
    n_vis = n_acc = 0
    for r, t in zip(results, truths, strict=True):
        if "plane" not in t or t.get("valid_board_pixels", min_board_pixels) < min_board_pixels:
            continue
        n_vis += 1
        n_acc += bool(r.accepted)
        tn, tdist = t["plane"]
        if r.measured:
            a, e = plane_errors(r.normal, r.d, tn, tdist)
            ra.append(a)
            rd.append(1e3 * e)
        a, e = plane_errors(r.track_normal, r.track_d, tn, tdist)
        ta.append(a)
        td.append(1e3 * e)
    return summary.replace(
        evaluated_frames=n_vis,
        detection_rate=n_acc / n_vis if n_vis else None,
        raw=PlaneErrorStats(ErrorStats.of(ra), ErrorStats.of(rd)),
        tracked=PlaneErrorStats(ErrorStats.of(ta), ErrorStats.of(td)),
    )
