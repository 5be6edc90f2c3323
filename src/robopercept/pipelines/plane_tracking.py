r"""RGB-D plane tracking: find a coloured board in every frame and track its plane.

Per frame (:meth:`PlaneTracker.process`):

1. **Measure** the board's plane (:class:`~robopercept.pipelines.PlaneMeasurer`): depth
   to points, their colour through the colour camera and an HSV box, RANSAC (MSAC,
   seeded with the track's prediction) and a refit by least squares in inverse depth,
   the exact model of stereo depth noise; its covariance has a floor for the errors
   that thousands of inliers cannot average out (see :mod:`.plane_measure`).
2. **Track** the plane in closest-point form :math:`\pi = d\, n` (the point of the
   plane nearest the camera, with :math:`n^\top x = d`, :math:`d \ge 0`) with a gated
   track (:class:`~robopercept.tracking.GatedTrack`): an interacting-multiple-model
   filter of a quiet and an agile constant-velocity model on :math:`(\pi, \dot\pi)`,
   predicted over the time between the frames' timestamps; a chi-square gate on the
   innovation that a fit with overwhelming support overrides (the track restarts at
   it); coasting through frames without an accepted plane, and re-acquisition (see
   :mod:`robopercept.tracking.gated`).

The tracked plane is :math:`n = \pi / \|\pi\|`, :math:`d = \|\pi\|`. Each frame's
result says whether a plane was *measured* and whether the track *accepted* it, and the
track's :class:`~robopercept.tracking.TrackStatus`.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, fields

import numpy as np

from robopercept._checks import check_int
from robopercept.errors import InputError
from robopercept.estimation.least_squares import scatter_matrix
from robopercept.pipelines.plane_measure import (
    PlaneHueModel,
    PlaneMeasurement,
    PlaneMeasurer,
    PlaneMeasurerConfig,
)
from robopercept.sources.frames import RGBDFrame
from robopercept.tracking.gated import GatedTrack, GatedTrackConfig, TrackStatus

__all__ = [
    "STAGES",
    "PlaneHueModel",
    "PlaneTrackResult",
    "PlaneTracker",
    "PlaneTrackerConfig",
    "plane_covariance",
]

STAGES = ("points", "color", "ransac", "kalman")
"""The tracker's timed stages, in order (``PlaneTrackResult.ms`` also has ``total``)."""


@dataclass(frozen=True)
class PlaneTrackerConfig(PlaneMeasurerConfig, GatedTrackConfig):
    """Settings of :class:`PlaneTracker`: those of the measurement
    (:class:`~robopercept.pipelines.PlaneMeasurerConfig`: HSV box, RANSAC, refit,
    covariance floor) and of the track (:class:`~robopercept.tracking.GatedTrackConfig`:
    process noise of the IMM's models, gate, coasting, re-acquisition), in one flat
    object: ``PlaneTrackerConfig(hsv_low=(40, 50, 50), max_coast=30)``.

    The tracker smooths over two frames by default (``smoothing_lag=2``: each frame's
    plane also uses the next two frames' measurements, 67 ms of latency at 30 fps); 0
    gives the causal filter, and trusts each measurement more than white noise would
    (``measurement_scale=0.4``: the board's fit errors in consecutive frames are
    correlated, see :mod:`robopercept.tracking.gated`)."""

    smoothing_lag: int = 2
    measurement_scale: float = 0.4

    def __post_init__(self) -> None:
        PlaneMeasurerConfig.__post_init__(self)
        GatedTrackConfig.__post_init__(self)
        object.__setattr__(self, "smoothing_lag", check_int(self.smoothing_lag, "smoothing_lag", 0))

    @property
    def measurer(self) -> PlaneMeasurerConfig:
        """The measurement's settings."""
        return PlaneMeasurerConfig(
            **{f.name: getattr(self, f.name) for f in fields(PlaneMeasurerConfig)}
        )

    @property
    def track(self) -> GatedTrackConfig:
        """The track's settings."""
        return GatedTrackConfig(**{f.name: getattr(self, f.name) for f in fields(GatedTrackConfig)})


@dataclass(frozen=True)
class PlaneTrackResult:
    """What :meth:`PlaneTracker.process` reports for one frame.

    Attributes
    ----------
    index : int
    timestamp : float
    status : TrackStatus
        ``new``, ``tracking``, ``gated`` (a plane was measured and rejected),
        ``coasting`` (none was measured) or ``lost`` (no track after this frame).
    measured : bool
        A plane was fitted on enough inliers (whether or not the track accepted it).
    accepted : bool
        The track used the measured plane (status ``new`` or ``tracking``).
    normal, d : (3,) ndarray, float
        The measured plane (``normal @ x = d``, ``d >= 0``); NaN when none was measured.
    inliers : int
    track_normal, track_d : (3,) ndarray, float
        The tracked plane (NaN when there is no track).
    covariance_trace : float
        Trace of the covariance of the tracked closest point (NaN without a track).
    mode_probabilities : (M,) ndarray
        Probabilities of the IMM's models (quiet first), empty without a track.
    n_points, n_green : int
        Valid depth points, and those with the board's colour.
    ms : dict
        Milliseconds per stage (:data:`STAGES`) and ``total``: the tracker's own work on
        this frame, not the source's.
    inlier_points : (K, 3) ndarray
        The board's inlier points (depth frame), for drawing.
    smoothed : bool
        ``track_normal`` and ``track_d`` are fixed-lag smoothed (:meth:`PlaneTracker.push`)
        rather than filtered from the frames up to this one.
    solidity : float
        Solidity of the best plane's inliers in the depth image
        (:attr:`PlaneMeasurement.solidity`; NaN when no plane had enough inliers): below
        ``min_solidity`` they were scattered specks and no board was found.
    """

    index: int
    timestamp: float
    status: TrackStatus
    measured: bool
    accepted: bool
    normal: np.ndarray
    d: float
    inliers: int
    track_normal: np.ndarray
    track_d: float
    covariance_trace: float
    mode_probabilities: np.ndarray
    n_points: int
    n_green: int
    ms: dict[str, float]
    inlier_points: np.ndarray = field(repr=False)
    smoothed: bool = False
    solidity: float = math.nan

    @property
    def detected(self) -> bool:
        """The measured plane was accepted (same as :attr:`accepted`)."""
        return self.accepted

    @property
    def gated(self) -> bool:
        """A plane was measured but the gate rejected it."""
        return self.status is TrackStatus.GATED


def plane_covariance(points: np.ndarray, normal: np.ndarray, d: float) -> np.ndarray:
    r"""Least-squares covariance of the closest point :math:`\pi = d n` of a plane fitted
    to ``points`` by total least squares (isotropic noise).

    With the centroid :math:`c`, the scatter's eigenpairs :math:`(\lambda_k, e_k)` in the
    plane (k = 1, 2) and the residual variance
    :math:`\sigma^2 = \lambda_0 / (N - 3)`, the normal tilts by
    :math:`a_k \sim N(0, \sigma^2 / \lambda_k)` about each in-plane axis and the
    centroid moves along :math:`n` with variance :math:`\sigma^2 / N`; to first order
    :math:`\delta\pi = \sum_k a_k (d\, e_k + (e_k^\top c)\, n) + (n^\top \delta c)\, n`,
    so :math:`\Sigma_\pi = \sum_k \frac{\sigma^2}{\lambda_k} v_k v_k^\top +
    \frac{\sigma^2}{N} n n^\top` with :math:`v_k = d\, e_k + (e_k^\top c)\, n`. (The
    tracker's measurements use the inverse-depth fit's covariance instead,
    :func:`~robopercept.estimation.fit_plane_inverse_depth`.)
    """
    c, S = scatter_matrix(points)
    n_pts = points.shape[0]
    lam, vec = np.linalg.eigh(S)
    sigma2 = max(lam[0], 0.0) / max(n_pts - 3, 1)
    n = np.asarray(normal, dtype=np.float64)
    cov = (sigma2 / n_pts) * np.outer(n, n)
    for k in (1, 2):
        e = vec[:, k]
        v = d * e + float(e @ c) * n
        cov += (sigma2 / max(lam[k], 1e-300)) * np.outer(v, v)
    return cov


class PlaneTracker:
    """Detect and track the plane of a coloured board in RGB-D frames.

    Parameters
    ----------
    config : PlaneTrackerConfig, optional

    Attributes
    ----------
    measurer : PlaneMeasurer
    track : GatedTrack

    Examples
    --------
    >>> from robopercept.sources import SyntheticRGBDScene
    >>> scene = SyntheticRGBDScene(n_frames=2, depth_size=(212, 120), color_size=(320, 180))
    >>> tracker = PlaneTracker()
    >>> [str(r.status) for r in map(tracker.process, scene)]
    ['new', 'tracking']
    """

    def __init__(self, config: PlaneTrackerConfig | None = None) -> None:
        self.config = PlaneTrackerConfig() if config is None else config
        if not isinstance(self.config, PlaneTrackerConfig):
            raise InputError(
                f"config must be a PlaneTrackerConfig or None; got {type(self.config).__name__}"
            )
        self.measurer = PlaneMeasurer(self.config.measurer)
        self.track = GatedTrack(self.config.track, dim=3)
        self._pending: deque[tuple[RGBDFrame, PlaneTrackResult]] = deque()
        self._lagged = np.zeros((0, 3))
        self.last_accepted = False  # whether the last processed frame's plane was accepted

    def reset(self) -> None:
        """Forget the track (and the measurer's early-stop target, and frames waiting in
        :meth:`push`)."""
        self.track.reset()
        self.measurer.reset()
        self._pending.clear()

    def push(self, frame: RGBDFrame) -> list[tuple[RGBDFrame, PlaneTrackResult]]:
        """Process ``frame`` and return the frames whose results are final.

        With ``smoothing_lag`` :math:`L = 0` that is this frame, with the filtered plane
        of :meth:`process`. With :math:`L > 0` a frame's result is final :math:`L`
        frames later: its tracked plane is then the fixed-lag smoothed estimate from the
        measurements up to :math:`L` frames after it (``smoothed=True``), at the cost of
        :math:`L` frames of latency. :meth:`flush` returns the frames still waiting at
        the end of a sequence.

        Returns
        -------
        list of (RGBDFrame, PlaneTrackResult)
            Zero or one pair, in frame order.
        """
        result = self.process(frame)
        lag = self.config.smoothing_lag
        if lag == 0:
            return [(frame, result)]
        self._revise()
        self._pending.append((frame, result))
        if len(self._pending) > lag:
            return [self._pending.popleft()]
        return []

    def flush(self) -> list[tuple[RGBDFrame, PlaneTrackResult]]:
        """The frames :meth:`push` still holds, with the best estimates available."""
        out = list(self._pending)
        self._pending.clear()
        return out

    def _revise(self) -> None:
        # the frames waiting, newest first, take the track's smoothed lagged positions
        for j, pi in enumerate(self._lagged):
            if j >= len(self._pending):
                break
            if not np.isfinite(pi).all():
                continue  # before the current track began: keep what it had
            k = len(self._pending) - 1 - j
            frame, r = self._pending[k]
            d = float(np.linalg.norm(pi))
            if d > 0:
                self._pending[k] = (
                    frame,
                    dataclasses.replace(r, track_normal=pi / d, track_d=d, smoothed=True),
                )

    def stream(self, frames: Iterable[RGBDFrame]) -> Iterator[tuple[RGBDFrame, PlaneTrackResult]]:
        """:meth:`push` every frame of ``frames``, then :meth:`flush`: ``(frame, result)``
        pairs in order."""
        for frame in frames:
            yield from self.push(frame)
        yield from self.flush()

    def process(self, frame: RGBDFrame) -> PlaneTrackResult:
        """Measure the board in ``frame`` and update the track (module docstring)."""
        if not isinstance(frame, RGBDFrame):
            raise InputError(f"frame must be an RGBDFrame; got {type(frame).__name__}")
        t0 = time.perf_counter()
        predicted = self.track.predict(frame.timestamp)
        t1 = time.perf_counter()
        m: PlaneMeasurement = self.measurer.measure(frame, predicted)
        t2 = time.perf_counter()
        if m.found:
            step = self.track.step(
                m.closest_point, m.covariance, support=m.inliers, dominant=m.dominant
            )
        else:
            step = self.track.step(None)
        self._lagged = step.lagged
        self.last_accepted = step.accepted
        pi = step.position
        track_d = float(np.linalg.norm(pi)) if np.isfinite(pi).all() else math.nan
        track_n = pi / track_d if track_d > 0 else np.full(3, np.nan)
        t3 = time.perf_counter()
        ms = {
            "points": m.ms.get("points", 0.0),
            "color": m.ms.get("color", 0.0),
            "ransac": m.ms.get("ransac", 0.0),
            "kalman": (t1 - t0 + t3 - t2) * 1e3,
            "total": (t3 - t0) * 1e3,
        }
        return PlaneTrackResult(
            index=frame.index,
            timestamp=frame.timestamp,
            status=step.status,
            measured=m.found,
            accepted=step.accepted,
            normal=m.normal,
            d=m.d,
            inliers=m.inliers,
            track_normal=track_n,
            track_d=track_d,
            covariance_trace=float(np.trace(step.covariance)),
            mode_probabilities=step.mode_probabilities,
            n_points=m.n_points,
            n_green=m.n_colored,
            ms=ms,
            inlier_points=m.inlier_points,
            solidity=m.solidity,
        )

    def run(self, frames: Iterable[RGBDFrame]) -> Iterator[PlaneTrackResult]:
        """:meth:`process` every frame of ``frames`` (filtered, no smoothing)."""
        for frame in frames:
            yield self.process(frame)
