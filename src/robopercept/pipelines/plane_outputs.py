"""Outputs of a plane-tracking run, and the run itself.

:func:`run_plane_tracking` drives a :class:`~robopercept.pipelines.PlaneTracker` over a
frame source and writes, into one folder:

* ``plane.csv``: one row per input frame, flushed as it is written;
  columns :data:`CSV_COLUMNS`; ``status`` is the track's
  (:class:`~robopercept.tracking.TrackStatus`: ``new``, ``tracking``, ``gated``,
  ``coasting``, ``lost``), ``measured`` says a plane was fitted in the frame and
  ``accepted`` that the track used it (a ``gated`` row is measured and not accepted);
  ``nx, ny, nz, d`` are the measured plane and ``track_*`` the tracked one, with the
  unit normal ``n`` and the distance ``d`` in metres, ``n . x = d`` for points ``x`` of
  the plane in the depth camera frame; ``ms`` is the tracker's time on the frame;
* ``tracking.mp4``: the colour image with the board's inliers, the tracked plane's
  outline and normal, and a status line (optional);
* ``summary.json``: :func:`~robopercept.pipelines.summarize`'s figures
  (:class:`~robopercept.pipelines.PlaneTrackSummary`), with the count of each status;
* ``plane.png``: measured, tracked and (when known) true plane parameters against the
  frame (:func:`plane_parameters_figure`).

The run stops cleanly on Ctrl-C, on SIGTERM (``docker stop``, systemd), when the
source fails (a camera unplugged) or when an output cannot be written (a full disk):
the outputs written so far are finalized (the video closed, the summary and the plot
written) and the summary says why it stopped (``stopped``). Signals that arrive while
the outputs are being written or finalized are held back (:class:`StopSignals`), so a
second Ctrl-C never leaves a file half-written. ``summary.json`` and ``plane.png`` are
written atomically (:func:`robopercept.fileio.atomic_write`: complete or absent, never
truncated); ``plane.csv`` holds whole rows only (a row cut short by a full disk is
removed); the video is a fragmented MP4, playable up to the last fragment written even
when the encoder could not finish.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import os
import shutil
import signal
import threading
import time
import warnings
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from robopercept._checks import plain_repr
from robopercept.errors import InputError, RoboperceptError, RoboperceptWarning
from robopercept.fileio import WriteError, atomic_path, atomic_write, write_error
from robopercept.geometry import apply, project
from robopercept.imaging.io import VideoWriter
from robopercept.pipelines.plane_eval import PlaneTrackSummary, summarize
from robopercept.pipelines.plane_tracking import (
    PlaneTracker,
    PlaneTrackerConfig,
    PlaneTrackResult,
)
from robopercept.progress import progress_bar
from robopercept.sources.frames import RGBDFrame
from robopercept.viz import draw_lines, draw_text
from robopercept.viz.figure import figure_to_rgb
from robopercept.viz.plot import Panel, Series, series_figure

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "CSV_COLUMNS",
    "PlaneTrackOutputs",
    "StopSignals",
    "annotate_frame",
    "plane_parameters_figure",
    "run_plane_tracking",
]

CSV_COLUMNS = (
    "frame",
    "timestamp",
    "status",
    "measured",
    "accepted",
    "nx",
    "ny",
    "nz",
    "d",
    "inliers",
    "track_nx",
    "track_ny",
    "track_nz",
    "track_d",
    "ms",
)


_NO_POINTS = np.zeros((0, 3))


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.6f}"


def _plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1)


def annotate_frame(
    frame: RGBDFrame, result: PlaneTrackResult, extent: np.ndarray | None = None
) -> np.ndarray:
    """The colour image with the board's inliers (magenta), the tracked plane's outline
    (yellow) and normal (cyan) and a status line (with "no board found" when no plane
    was measured in the frame).

    Parameters
    ----------
    frame : RGBDFrame
    result : PlaneTrackResult
    extent : (4,) or (5,) ndarray, optional
        ``(c1, c2, h1, h2[, t])``: centre of the board in the tracked plane's basis
        ``(e1, e2)`` and half sizes of its rectangle along ``cos t e1 + sin t e2`` and
        ``-sin t e1 + cos t e2`` (``t`` = 0 when left out), for the outline; no outline
        when None.

    Returns
    -------
    (Hc, Wc, 3) uint8 ndarray
    """
    img = frame.color.copy()
    kc = frame.color_intrinsics
    T = frame.T_color_depth
    pts = result.inlier_points
    if pts.shape[0]:
        step = max(1, pts.shape[0] // 200000)
        pix = np.rint(project(apply(T, pts[::step]), kc))
        ok = np.isfinite(pix).all(1)
        pix = pix[ok].astype(np.int64)
        ok = (pix[:, 0] >= 0) & (pix[:, 0] < kc.width) & (pix[:, 1] >= 0) & (pix[:, 1] < kc.height)
        r, c = pix[ok, 1], pix[ok, 0]
        img[r, c] = (0.4 * img[r, c] + 0.6 * np.array([255, 0, 255])).astype(np.uint8)
    n, d = result.track_normal, result.track_d
    if np.isfinite(d) and extent is not None:
        e1, e2 = _plane_basis(n)
        c1, c2, h1, h2 = extent[:4]
        t = float(extent[4]) if len(extent) > 4 else 0.0
        u, v = np.cos(t) * e1 + np.sin(t) * e2, -np.sin(t) * e1 + np.cos(t) * e2
        center = d * n + c1 * e1 + c2 * e2
        corners = np.array(
            [center + s1 * h1 * u + s2 * h2 * v for s1, s2 in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        )
        cp = project(apply(T, corners), kc)
        seg = np.column_stack([cp, np.roll(cp, -1, axis=0)])
        img = draw_lines(img, seg, color=(255, 220, 0), width=3)
        arrow = project(apply(T, np.array([center, center - 0.2 * n])), kc)
        img = draw_lines(img, arrow.reshape(1, 4), color=(0, 220, 255), width=3)
    text = f"frame {result.index}  {result.status}  " + (
        f"inliers {result.inliers}" if result.measured else "no board found"
    )
    if np.isfinite(d):
        text += f"  n=({n[0]:+.3f}, {n[1]:+.3f}, {n[2]:+.3f})  d={d:.3f} m"
    text += f"  {result.ms['total']:.1f} ms"
    return draw_text(img, text, (8, 8), size=max(12, kc.height // 40))


class StopSignals:
    """Turn SIGINT (Ctrl-C) and SIGTERM into a request to stop, for a loop that must
    finish its outputs before it ends.

    Inside ``with StopSignals() as stop:`` the first signal only records itself in
    :attr:`received` (``"SIGINT"`` or ``"SIGTERM"``); the loop checks it between
    frames and stops. A further signal raises :class:`KeyboardInterrupt` (to break out
    of a source that blocks), except inside ``with stop.shield():`` (writing or
    finalizing the outputs), where it is only counted in :attr:`count`, so a file is
    never left half-written. On leaving, the previous handlers are restored.

    Handlers are installed only from the main thread (the only one Python delivers
    signals to); elsewhere the object is inert and Ctrl-C keeps raising
    :class:`KeyboardInterrupt`. A signal the process ignores (``SIG_IGN``, as under
    ``nohup``) stays ignored.

    Parameters
    ----------
    signals : tuple of signal.Signals
        Default ``(SIGINT, SIGTERM)``.

    Attributes
    ----------
    received : str or None
        Name of the first signal received.
    count : int
        Signals received so far.

    Examples
    --------
    >>> with StopSignals() as stop:  # doctest: +SKIP
    ...     for frame in frames:
    ...         with stop.shield():
    ...             write(frame)
    ...         if stop.received:
    ...             break
    """

    def __init__(
        self, signals: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)
    ) -> None:
        self.signals = tuple(signals)
        self.received: str | None = None
        self.count = 0
        self._shielded = 0
        self._previous: dict[signal.Signals, Any] = {}

    def _handle(self, signum: int, frame: object) -> None:
        self.count += 1
        if self.received is None:
            self.received = signal.Signals(signum).name
        elif not self._shielded:
            raise KeyboardInterrupt

    @contextmanager
    def shield(self) -> Iterator[None]:
        """Hold back further signals (only count them) while the block runs."""
        self._shielded += 1
        try:
            yield
        finally:
            self._shielded -= 1

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            for sig in self.signals:
                old = signal.getsignal(sig)
                if old is signal.SIG_IGN or old is None:
                    continue
                signal.signal(sig, self._handle)
                self._previous[sig] = old
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._previous.items():
            signal.signal(sig, old)
        self._previous.clear()


def _video_error(path: Path, exc: OSError) -> WriteError:
    """The :class:`WriteError` of a failed video write. The encoder's own error has no
    ``errno`` (imageio-ffmpeg reports a broken pipe), so a folder with under 1 MiB free
    is taken for a full disk."""
    if exc.errno is None:
        try:
            full = shutil.disk_usage(path.parent).free < 1 << 20
        except OSError:
            full = False
        if full:
            return write_error(path, OSError(28, "No space left on device"))
        lines = str(exc).strip().splitlines()
        return WriteError(
            f"{path}: the video encoder stopped ({lines[0] if lines else type(exc).__name__})",
            None,
            str(path),
        )
    return write_error(path, exc)


class PlaneTrackOutputs:
    """Writes ``plane.csv``, ``tracking.mp4``, ``summary.json`` and ``plane.png`` into
    ``out_dir`` (see the module docstring). Use as a context manager or call
    :meth:`close`; every row is written in one call and flushed.

    An output that cannot be written raises :class:`~robopercept.fileio.WriteError`
    naming the file (``no space left on the device`` for a full disk); ``plane.csv``
    then keeps its complete rows only.

    Attributes
    ----------
    written : list of str
        The outputs completed by :meth:`close`.
    errors : list of str
        What :meth:`close` could not write, one line per file.
    """

    def __init__(self, out_dir: str | os.PathLike[str], *, video: bool = True, fps: float = 30.0):
        self.out = Path(out_dir)
        self.out.mkdir(parents=True, exist_ok=True)
        self._csv_path = self.out / "plane.csv"
        self._csv_fh = self._csv_path.open("w", newline="", encoding="utf-8")
        self._csv_bytes = 0  # size of the complete rows written
        self._csv_row(CSV_COLUMNS)
        self.written: list[str] = []
        self.errors: list[str] = []
        self._video_on = video
        self._fps = fps
        self._video: VideoWriter | None = None
        self._rows: list[tuple[PlaneTrackResult, dict[str, Any]]] = []
        self._extent: np.ndarray | None = None
        self.closed = False

    def __enter__(self) -> PlaneTrackOutputs:
        return self

    def __exit__(self, *exc: object) -> None:
        if not self.closed:
            self.close(None)

    def _update_extent(self, result: PlaneTrackResult) -> None:
        pts = result.inlier_points
        n, d = result.track_normal, result.track_d
        if pts.shape[0] < 3 or not np.isfinite(d):
            return
        from robopercept.geometry import min_area_rectangle

        e1, e2 = _plane_basis(n)
        xy = np.column_stack([pts @ e1, pts @ e2])
        # the board's own rectangle (its sides, not the basis axes), without the 1 % of
        # inliers farthest from the median (stray board-coloured points on the plane)
        r = np.linalg.norm(xy - np.median(xy, axis=0), axis=1)
        center, half, angle = min_area_rectangle(xy[r <= np.percentile(r, 99)])
        self._extent = np.array([center[0], center[1], half[0], half[1], angle])

    def _csv_row(self, row: Iterable[object]) -> None:
        buf = io.StringIO()
        csv.writer(buf).writerow(row)
        line = buf.getvalue()
        try:  # one write, flushed: a full disk cuts at most this row, removed on close
            self._csv_fh.write(line)
            self._csv_fh.flush()
        except OSError as exc:
            raise write_error(self._csv_path, exc) from exc
        self._csv_bytes += len(line.encode("utf-8"))

    def add(self, frame: RGBDFrame, result: PlaneTrackResult) -> None:
        """Write the row (and the video frame) of one processed frame.

        Raises
        ------
        WriteError
            ``plane.csv`` or ``tracking.mp4`` could not be written (a full disk).
        """
        r = result
        self._csv_row(
            [
                r.index,
                f"{r.timestamp:.6f}",
                str(r.status),
                int(r.measured),
                int(r.accepted),
                *(_fmt(v) for v in r.normal),
                _fmt(r.d),
                r.inliers,
                *(_fmt(v) for v in r.track_normal),
                _fmt(r.track_d),
                f"{r.ms['total']:.3f}",
            ]
        )
        truth = {
            k: v for k, v in frame.ground_truth.items() if k in ("plane", "valid_board_pixels")
        }
        # kept for the summary and the plot without the inlier points (up to 7 MB a
        # frame at 1280x720: a long run would hold gigabytes); the summary counts the
        # rows plane.csv holds
        self._rows.append((dataclasses.replace(r, inlier_points=_NO_POINTS), truth))
        if self._video_on:
            if r.accepted:
                self._update_extent(r)
            elif not np.isfinite(r.track_d):
                self._extent = None
            if self._video is None:
                self._video = VideoWriter(
                    self.out / "tracking.mp4", fps=self._fps, quality=6, fragmented=True
                )
            picture = annotate_frame(frame, r, self._extent)
            try:
                self._video.write(picture)
            except OSError as exc:
                raise _video_error(self._video.path, exc) from exc

    @property
    def results(self) -> list[PlaneTrackResult]:
        """The per-frame tracking results added so far, in order (without their inlier
        points, which only the video needs)."""
        return [r for r, _ in self._rows]

    def summary(self, **extra: Any) -> PlaneTrackSummary:
        """The run's figures (with ground truth when every frame has a plane)."""
        results = self.results
        truths = [t for _, t in self._rows]
        has_truth = bool(truths) and all("plane" in t for t in truths)
        return summarize(results, truths if has_truth else None, **extra)

    def close(self, summary: PlaneTrackSummary | None) -> PlaneTrackSummary | None:
        """Finish ``plane.csv`` and the video, write ``plane.png`` and then (when given)
        ``summary.json``, both atomically, with ``outputs`` listing the files completed.

        Each output is finished on its own: one that fails (a full disk) is recorded in
        :attr:`errors` and the others are still written. ``plane.csv`` is cut back to
        its last complete row.

        Returns
        -------
        PlaneTrackSummary or None
            ``summary`` with ``outputs`` set to the files written (:attr:`written`).
        """
        if self.closed:
            return summary
        self.closed = True
        try:
            self._csv_fh.close()
        except OSError as exc:  # the buffered rest of a row cut short
            self.errors.append(str(write_error(self._csv_path, exc)))
        try:
            if self._csv_path.stat().st_size != self._csv_bytes:
                os.truncate(self._csv_path, self._csv_bytes)
            self.written.append("plane.csv")
        except OSError as exc:
            self.errors.append(str(write_error(self._csv_path, exc)))
        if self._video is not None:
            try:
                self._video.close()
                if self._video.frames_written:
                    self.written.append("tracking.mp4")
            except OSError as exc:
                self.errors.append(str(_video_error(self._video.path, exc)))
        if self._rows:
            from robopercept.imaging import write_image

            try:
                with atomic_path(self.out / "plane.png") as tmp:
                    write_image(tmp, self._plot())
                self.written.append("plane.png")
            except WriteError as exc:
                self.errors.append(str(exc))
        if summary is None:
            return None
        summary = self._with_errors(summary.replace(outputs=(*self.written, "summary.json")))
        try:
            atomic_write(
                self.out / "summary.json",
                json.dumps(summary.to_dict(), indent=2, default=float),
            )
            self.written.append("summary.json")
        except WriteError as exc:
            self.errors.append(str(exc))
            summary = self._with_errors(summary.replace(outputs=tuple(self.written)))
        return summary

    def _with_errors(self, summary: PlaneTrackSummary) -> PlaneTrackSummary:
        """``summary`` whose ``stopped`` names the first output that failed, if any."""
        if self.errors and not (summary.stopped or "").startswith("output failed"):
            return summary.replace(stopped=f"output failed: {self.errors[0]}")
        return summary

    def _plot(self) -> np.ndarray:
        """``plane.png``: :func:`plane_parameters_figure` of the run, rasterized."""
        res = self.results
        t = np.array([r.index for r in res], dtype=np.float64)
        raw = np.array([np.append(r.normal, r.d) if r.measured else [np.nan] * 4 for r in res])
        trk = np.array([np.append(r.track_normal, r.track_d) for r in res])
        truth = np.array(
            [np.append(*tr["plane"]) if "plane" in tr else [np.nan] * 4 for _, tr in self._rows]
        )
        return figure_to_rgb(plane_parameters_figure(t, raw, trk, truth), quiet_layout=True)


def plane_parameters_figure(
    frames: np.ndarray,
    measured: np.ndarray,
    tracked: np.ndarray,
    truth: np.ndarray | None = None,
) -> Figure:
    """The figure of ``plane.png``: the measured, tracked and (when known) true plane
    ``(n_x, n_y, n_z, d)`` against the frame index, ``n . x = d`` with ``n`` the unit
    normal and ``d`` the distance in metres (depth camera frame).

    A 2 x 2 grid of panels, 1600 x 900 pixels at 100 dpi (12 pt text, readable at
    1080p), one legend above the panels (the measured entry counts the frames with a
    plane), integer frame ticks, and in each panel the note "no board detected in N
    frames" when nothing was measured or tracked (:func:`robopercept.viz.plot_series`'s
    rules).

    Parameters
    ----------
    frames : (N,) array_like
        Frame indices.
    measured, tracked : (N, 4) array_like
        ``(n_x, n_y, n_z, d)`` per frame; NaN rows where there is none.
    truth : (N, 4) array_like, optional
        The ground truth (a synthetic scene's), NaN where unknown.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        Arrays of the wrong shapes or not real numbers.

    Examples
    --------
    >>> rows = np.tile([0.0, 0.0, 1.0, 0.8], (3, 1))
    >>> fig = plane_parameters_figure(np.arange(3), rows, rows)
    >>> [ax.get_ylabel() for ax in fig.axes][-1], fig.get_size_inches().tolist()
    ('d [m]', [16.0, 9.0])
    """
    t = np.asarray(frames)
    if t.ndim != 1 or t.dtype.kind not in "biuf":
        raise InputError(f"frames must be a 1-D array of frame indices; got {plain_repr(frames)}")
    t = t.astype(np.float64)
    n = len(t)
    arrays = {}
    for name, value in (("measured", measured), ("tracked", tracked), ("truth", truth)):
        if value is None:
            arrays[name] = np.full((n, 4), np.nan)
            continue
        v = np.asarray(value)
        if v.shape != (n, 4) or v.dtype.kind not in "biuf":
            raise InputError(
                f"{name} must be ({n}, 4) real numbers (n_x, n_y, n_z, d per frame); got "
                f"shape {v.shape} dtype {v.dtype}"
            )
        arrays[name] = v.astype(np.float64)
    raw, trk, true = arrays["measured"], arrays["tracked"], arrays["truth"]
    detected = int(np.isfinite(raw).all(axis=1).sum())
    raw_label = f"measured ({detected} of {n} frames)"
    panels = []
    quantities = (
        ("normal x", "n_x [unit normal]"),
        ("normal y", "n_y [unit normal]"),
        ("normal z", "n_z [unit normal]"),
        ("distance to the plane", "d [m]"),
    )
    for k, (title, ylabel) in enumerate(quantities):
        series = []
        if np.isfinite(true).any():
            series.append(Series(t, true[:, k], "truth", (0, 0, 0)))
        series.append(Series(t, raw[:, k], raw_label, (214, 39, 40), "dots"))
        series.append(Series(t, trk[:, k], "tracked", (31, 119, 180)))
        panels.append(Panel(title, series, ylabel))
    return series_figure(
        panels,
        width=1600,
        panel_height=435,
        columns=2,
        xlabel="frame",
        integer_x=True,
        legend="figure",
        empty_note=f"no board detected in {'1 frame' if n == 1 else f'{n} frames'}",
    )


def run_plane_tracking(
    frames: Iterable[RGBDFrame],
    out_dir: str | os.PathLike[str],
    *,
    config: PlaneTrackerConfig | None = None,
    max_frames: int | None = None,
    video: bool = True,
    fps: float = 30.0,
    progress: bool = True,
) -> PlaneTrackSummary:
    """Track the board through ``frames`` and write the outputs into ``out_dir``.

    Parameters
    ----------
    frames : iterable of RGBDFrame
        Any source; its ``skipped`` attribute (if any) is reported.
    out_dir : path
    config : PlaneTrackerConfig, optional
    max_frames : int, optional
        Stop after this many frames.
    video : bool
        Write ``tracking.mp4``.
    fps : float
        Frame rate of the video.
    progress : bool
        Show progress on stderr (:func:`~robopercept.progress.progress_bar`: a bar on a
        terminal, a few lines otherwise), with the running count of accepted frames.

    Returns
    -------
    PlaneTrackSummary
        The summary also written to ``summary.json``; ``stopped`` says why a run ended
        early: ``"interrupted"`` (Ctrl-C), ``"stopped by SIGTERM"``, ``"source failed:
        <error>"`` or ``"output failed: <file>: <error>"`` (``no space left on the
        device`` for a full disk). ``outputs`` lists the files completed. Its stage
        timings are the tracker's own work per frame (:attr:`PlaneTrackResult.ms`); the
        wall time covers the source and the outputs too.

    Warns
    -----
    RoboperceptWarning
        No board was found in any frame of a run that was not stopped early: the
        outputs are written (every row unmeasured) and the warning says whether the
        board's colour was too rare or its pixels too scattered for a board
        (``min_points``, ``min_solidity`` of :class:`PlaneTrackerConfig`).

    Notes
    -----
    While it runs (from the main thread), SIGINT and SIGTERM are handled by
    :class:`StopSignals`: the first stops the run after the current frame, a second one
    while a frame is processed raises :class:`KeyboardInterrupt` (stop now), and any
    signal while the outputs are written or finalized waits until they are complete.
    The previous handlers are restored on return.
    """
    if max_frames is not None and max_frames < 1:
        raise InputError(f"max_frames must be >= 1; got {max_frames}")
    tracker = PlaneTracker(config)
    total = len(frames) if hasattr(frames, "__len__") else None  # type: ignore[arg-type]
    if total is not None and max_frames is not None:
        total = min(total, max_frames)
    stopped: str | None = None
    start = time.perf_counter()
    outputs = PlaneTrackOutputs(out_dir, video=video, fps=fps)
    bar = progress_bar(total=total, unit="frame", disable=not progress, desc="plane tracking")
    accepted = 0
    output_failed = False
    with StopSignals() as stop:
        try:
            it = iter(frames)
            count = 0
            while max_frames is None or count < max_frames:
                try:
                    frame = next(it)
                except StopIteration:
                    break
                except (RoboperceptError, RuntimeError, OSError) as exc:
                    stopped = f"source failed: {exc}"
                    warnings.warn(f"stopping: {stopped}", stacklevel=2)
                    break
                done_frames = tracker.push(frame)
                with stop.shield():
                    for done, result in done_frames:
                        outputs.add(done, result)
                count += 1
                accepted += tracker.last_accepted
                bar.set_postfix_str(f"detected {accepted}/{count}", refresh=False)
                bar.update(1)
                if stop.received:
                    break
        except KeyboardInterrupt:
            stopped = "interrupted"
        except WriteError as exc:  # a full disk: stop, keep what was written
            stopped = f"output failed: {exc}"
            output_failed = True
            warnings.warn(f"stopping: {stopped}", stacklevel=2)
        finally:
            with stop.shield():  # a second Ctrl-C waits until the outputs are complete
                if stop.received and stopped in (None, "interrupted"):
                    by_ctrl_c = stop.received == "SIGINT"
                    stopped = "interrupted" if by_ctrl_c else f"stopped by {stop.received}"
                summary = _finish(outputs, tracker, frames, start, stopped, output_failed)
                bar.close()
    return summary


def _finish(
    outputs: PlaneTrackOutputs,
    tracker: PlaneTracker,
    frames: Iterable[RGBDFrame],
    start: float,
    stopped: str | None,
    output_failed: bool,
) -> PlaneTrackSummary:
    """Add the frames the smoother still held (unless an output already failed), close
    the outputs and return the summary written (``stopped`` names a later failure)."""
    try:
        if not output_failed:
            for done, result in tracker.flush():
                outputs.add(done, result)
    except WriteError as exc:
        stopped = stopped or f"output failed: {exc}"
    except Exception as exc:
        if stopped != "interrupted":
            raise
        # a tracker cut short by a second Ctrl-C: its held frames are dropped
        warnings.warn(f"the last frames held by the smoother were dropped: {exc}", stacklevel=3)
    skipped = getattr(frames, "skipped", [])
    n_skipped = len(skipped) if not isinstance(skipped, int) else skipped
    wall = time.perf_counter() - start
    summary = outputs.summary(skipped=n_skipped, wall_seconds=round(wall, 3))
    final = outputs.close(summary.replace(stopped=stopped))
    assert final is not None
    if final.frames and not final.measured_frames and final.stopped is None:
        warnings.warn(_no_board_message(outputs.results, tracker.config), RoboperceptWarning,
                      stacklevel=3)  # fmt: skip
    return final


def _no_board_message(results: list[PlaneTrackResult], config: PlaneTrackerConfig) -> str:
    """One line on a run in which no frame had a board: how many frames, and whether the
    board's colour was too rare (fewer than ``min_points`` pixels on a plane) or its
    pixels too scattered (solidity below ``min_solidity``), with the flags to check.

    Examples
    --------
    >>> from robopercept.pipelines.plane_tracking import PlaneTrackResult
    >>> from robopercept.tracking import TrackStatus
    >>> nan3 = np.full(3, np.nan)
    >>> r = PlaneTrackResult(0, 0.0, TrackStatus.LOST, False, False, nan3, np.nan, 0, nan3,
    ...     np.nan, np.nan, np.zeros(0), 1000, 548, {}, np.zeros((0, 3)), solidity=0.009)
    >>> print(_no_board_message([r, r], PlaneTrackerConfig()))  # doctest: +NORMALIZE_WHITESPACE
    no board found in any of the 2 frames: the board-coloured pixels are scattered specks
    (548 at most in a frame; the solidity of the best plane's inliers 0.009 at most, a
    board's is 0.15 or more); check that the board is in view and its colour box
    (hsv_low, hsv_high; --hsv-low, --hsv-high)
    """
    n = len(results)
    most = max((r.n_green for r in results), default=0)
    solid = [r.solidity for r in results if np.isfinite(r.solidity)]
    frames = "the 1 frame" if n == 1 else f"any of the {n} frames"
    if solid:
        why = (
            f"the board-coloured pixels are scattered specks ({most} at most in a frame; "
            f"the solidity of the best plane's inliers {max(solid):.3g} at most, a "
            f"board's is {config.min_solidity:g} or more)"
        )
    else:
        why = (
            f"too few board-coloured pixels ({most} at most in a frame; a board needs "
            f"{config.min_points} on one plane)"
        )
    return (
        f"no board found in {frames}: {why}; check that the board is in view and its "
        "colour box (hsv_low, hsv_high; --hsv-low, --hsv-high)"
    )
