r"""A gated track of one object measured by position: predict, gate, update, coast and
re-acquire, with a typed status per step.

The state is a position :math:`p \in \mathbb{R}^k` and its velocity, estimated by an
interacting-multiple-model filter (:class:`~robopercept.tracking.IMMEstimator`) of
constant-velocity models that differ only in their white-noise acceleration
:math:`q_j` (one quiet model for smooth motion, one agile model for manoeuvres; a single
:math:`q` gives a plain Kalman filter). Each model predicts over the time since the last
step, :math:`\Delta t` from the timestamps,

.. math:: A = \begin{bmatrix} I & \Delta t I \\ 0 & I \end{bmatrix}, \qquad
          Q_j = q_j\, G G^\top \otimes I, \quad G = [\Delta t^2/2, \ \Delta t]^\top,

and the IMM mixes them with the Markov switching probabilities
:math:`M_{ij} = P(\text{model } j \mid \text{model } i)` (``switch_probability`` off the
diagonal), so the estimate follows the board closely when it manoeuvres and averages
the measurements when it moves smoothly: the process noise adapts to the motion through
the mode probabilities :math:`\mu_j`, updated from each model's innovation likelihood.

Per step, given a measurement :math:`z` with covariance :math:`R` and its support
:math:`s` (e.g. the inlier count):

1. **Predict** every model to the step's time.
2. **Gate.** :math:`z` is accepted when the smallest squared Mahalanobis distance over
   the models, :math:`\min_j y_j^\top S_j^{-1} y_j` with :math:`S_j = H P_j^- H^\top +
   R`, is below the chi-square quantile (``gate_probability``, :math:`k` degrees of
   freedom): a measurement any model finds plausible is used.
3. **Overwhelming support overrides the gate.** A rejected :math:`z` whose support is at
   least ``support_ratio`` times the track's recent support (an exponential average of
   the accepted supports) and that the caller marks as dominant (its fit explains most
   of the candidate data) is not an outlier but a sign that the prediction is wrong: the
   track is restarted at :math:`z` at once (status ``new``) instead of coasting.
4. **Update** with an accepted :math:`z` (status ``tracking``), or **coast** on the
   prediction (status ``gated`` when a measurement was rejected, ``coasting`` when there
   was none); after ``max_coast`` frames without an accepted measurement the track is
   dropped (``lost``).
5. **Re-acquire.** Rejected measurements feed a tentative track (the same filter and
   gate); after ``reacquire_frames`` consecutive agreeing ones it replaces the track,
   which had locked on to something else.

**Measurement errors that neighbouring steps share.** The filter weighs each
measurement by :math:`R^{-1}` as if its error were independent of the previous one's.
Where the errors are correlated in time (a plane fitted to a board seen from nearly the
same pose keeps nearly the same bias: on the synthetic sequences the whitened errors of
consecutive frames correlate by 0.4 to 0.5, and still by 0.25 three frames apart),
averaging over neighbours removes less error than the filter believes, while the motion
model's own error (a manoeuvre, a tremor) is added in full. ``measurement_scale``
:math:`s < 1` uses :math:`sR` in the gate and the update, so each step's estimate
leans more on its own measurement: with an error correlation :math:`\rho` between
neighbours, :math:`m` averaged measurements carry the information of about
:math:`m / (1 + (m - 1)\rho)` independent ones, which a smaller :math:`R` in a
filter that assumes independence approximates. The value is an empirical choice (the
plane tracker uses 0.4: every value from 0.2 to 0.5 beat the raw fit on all five
synthetic motion profiles, two seeds each; 1 did not on hand-held tremor).

**Fixed-lag smoothing** (``smoothing_lag`` :math:`L > 0`): every model's state is
augmented with the last :math:`L` positions (:func:`lagged_model`), so the same IMM also
estimates :math:`p_{t-1}, \dots, p_{t-L}` from the measurements up to :math:`t`. A
causal filter must extrapolate, and lags a board that changes course; the smoothed
position of a frame interpolates between its neighbours' measurements instead, at the
cost of :math:`L` frames of latency (:attr:`TrackStep.lagged`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np
from scipy.stats import chi2

from robopercept._checks import (
    check_bool,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.tracking.imm import IMMEstimator
from robopercept.tracking.kalman import MAX_DIM, KalmanFilter, check_dim, kinematic_matrices

__all__ = ["GatedTrack", "GatedTrackConfig", "TrackStatus", "TrackStep", "lagged_model"]

#: most motion models of one track (each is a Kalman filter run every step)
MAX_MODELS = 16


class TrackStatus(str, Enum):
    """What happened to the track in one step."""

    NEW = "new"
    """A track started (first measurement, or re-acquired)."""
    TRACKING = "tracking"
    """The measurement was accepted into the track."""
    GATED = "gated"
    """A measurement came but the gate rejected it; the track coasted."""
    COASTING = "coasting"
    """No measurement; the track coasted on its prediction."""
    LOST = "lost"
    """There is no track after this step."""

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class GatedTrackConfig:
    r"""Settings of :class:`GatedTrack`.

    Attributes
    ----------
    process_noise : tuple of float
        White-noise acceleration variance :math:`q_j` of each constant-velocity model,
        (units/s^2)^2; two or more make an IMM, one a plain Kalman filter.
    switch_probability : float
        IMM probability of leaving a model per step (spread over the other models).
    gate_probability : float
        Chi-square gate; measurements outside are rejected (unless overwhelming).
    max_coast : int
        Steps a track survives without an accepted measurement.
    reacquire_frames : int or None
        Consecutive agreeing rejected measurements that replace the track; None: never.
    support_ratio : float or None
        A rejected, dominant measurement with at least this share of the recent support
        restarts the track at once; None: never.
    initial_velocity_std : float
        Standard deviation of the unknown velocity of a new track, units/s.
    smoothing_lag : int
        Past positions the filter keeps and refines with later measurements (fixed-lag
        smoothing, :func:`lagged_model`); 0: filtering only.
    measurement_scale : float
        Factor :math:`s` on every measurement covariance, :math:`R \leftarrow s R`, in
        the gate and the update (see the module docstring); 1 takes the stated
        covariances as they are, below 1 trusts each measurement more than the filter
        would if its errors were independent from step to step.
    """

    process_noise: tuple[float, ...] = (5.0, 500.0, 20000.0)
    switch_probability: float = 0.05
    gate_probability: float = 0.9999
    max_coast: int = 15
    reacquire_frames: int | None = 3
    support_ratio: float | None = 0.5
    initial_velocity_std: float = 1.0
    smoothing_lag: int = 0
    measurement_scale: float = 1.0

    def __post_init__(self) -> None:
        q = check_numeric(self.process_noise, "process_noise").reshape(-1)
        if not 1 <= q.size <= MAX_MODELS or not (np.isfinite(q) & (q > 0) & (q <= 1e100)).all():
            raise InputError(
                f"process_noise needs 1 to {MAX_MODELS} values in (0, 1e100]; got "
                f"{plain_repr(self.process_noise)[:80]}"
            )
        object.__setattr__(self, "process_noise", tuple(float(v) for v in q))
        for name, value in (
            ("switch_probability", self.switch_probability),
            ("gate_probability", self.gate_probability),
        ):
            check_real(value, name, 0.0, 1.0, low_inclusive=False, high_inclusive=False)
        check_int(self.max_coast, "max_coast", 0)
        if self.reacquire_frames is not None:
            check_int(self.reacquire_frames, "reacquire_frames (or None: never)", 2)
        if self.support_ratio is not None:
            check_real(
                self.support_ratio, "support_ratio (or None: never)", 0.0, low_inclusive=False
            )
        lag = check_int(self.smoothing_lag, "smoothing_lag", 0)
        if lag > 30:
            raise InputError(f"smoothing_lag must be in 0..30 frames; got {lag}")
        check_real(self.measurement_scale, "measurement_scale", 0.0, 1e6, low_inclusive=False)
        # its square is a variance of the filter, which refuses values beyond 1e150
        check_real(
            self.initial_velocity_std, "initial_velocity_std", 0.0, 1e75, low_inclusive=False
        )


@dataclass(frozen=True)
class TrackStep:
    """The outcome of :meth:`GatedTrack.step`.

    Attributes
    ----------
    status : TrackStatus
    accepted : bool
        The measurement was used (status ``new`` or ``tracking``).
    position : (k,) ndarray
        The track's position estimate after the step (NaN without a track).
    covariance : (k, k) ndarray
        Its covariance (NaN without a track).
    mahalanobis2 : float
        The gate's squared distance of the measurement (NaN when none was tested).
    mode_probabilities : (M,) ndarray
        The IMM's model probabilities after the step (empty without a track).
    lagged : (L, k) ndarray
        Fixed-lag smoothed positions of the previous ``L = smoothing_lag`` steps, one
        step back first (rows of NaN before the track began; empty when L = 0).
    """

    status: TrackStatus
    accepted: bool
    position: np.ndarray
    covariance: np.ndarray
    mahalanobis2: float
    mode_probabilities: np.ndarray
    lagged: np.ndarray


def lagged_model(A: np.ndarray, Q: np.ndarray, k: int, lag: int) -> tuple[np.ndarray, np.ndarray]:
    r"""The transition and process noise of a state augmented with its last ``lag``
    positions (fixed-lag smoothing by state augmentation).

    The state :math:`x = (p, v)` (position first, :math:`k` values) becomes
    :math:`(p_t, v_t, p_{t-1}, \dots, p_{t-L})`; the past positions are copied, not
    propagated:

    .. math:: A' = \begin{bmatrix} A & 0 \\ S & \text{shift} \end{bmatrix}, \qquad
              Q' = \begin{bmatrix} Q & 0 \\ 0 & 0 \end{bmatrix},

    so a Kalman filter (or an IMM of such filters) on the augmented state estimates
    :math:`p_{t-l}` from the measurements up to :math:`t`: the fixed-lag smoother
    (Anderson & Moore, Optimal Filtering, 1979, ch. 7).

    Parameters
    ----------
    A, Q : (n, n) ndarray
        The model of the un-augmented state, position in the first ``k`` entries.
    k : int
        Position size.
    lag : int
        Past positions kept (0: ``A``, ``Q`` unchanged).

    Returns
    -------
    A, Q : (n + lag k, n + lag k) ndarray

    Raises
    ------
    InputError
        ``A`` or ``Q`` not a finite square matrix of the same size, ``k`` not in
        ``1..n``, ``lag`` negative or an augmented state beyond
        :data:`~robopercept.tracking.kalman.MAX_DIM`.
    """
    A = check_numeric(A, "A")
    n = A.shape[0] if A.ndim == 2 else 0
    Q = check_numeric(Q, "Q")
    for name, a in (("A", A), ("Q", Q)):
        if a.shape != (n, n) or n == 0 or not np.isfinite(a).all():
            raise InputError(
                f"A and Q must be finite square matrices of one size (n, n), n >= 1; "
                f"got {name} of shape {a.shape} (A has shape {A.shape})"
            )
    k = check_int(k, "k", 1)
    if k > n:
        raise InputError(f"k (the position size) must be <= the state size {n}; got {k}")
    lag = check_int(lag, "lag", 0)
    if n + lag * k > MAX_DIM:
        raise InputError(
            f"lag must be <= {(MAX_DIM - n) // k} here: the augmented state n + lag k "
            f"would exceed {MAX_DIM}; got {lag}"
        )
    return _lagged(A, Q, k, lag)


def _lagged(A: np.ndarray, Q: np.ndarray, k: int, lag: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`lagged_model` without the checks."""
    n = A.shape[0]
    if lag == 0:
        return A, Q
    m = n + lag * k
    a = np.zeros((m, m))
    a[:n, :n] = A
    a[n : n + k, :k] = np.eye(k)  # p_{t-1} <- p_t
    for j in range(1, lag):
        a[n + j * k : n + (j + 1) * k, n + (j - 1) * k : n + j * k] = np.eye(k)
    q = np.zeros((m, m))
    q[:n, :n] = Q
    return a, q


#: the most frame intervals a track keeps models for: a recording's timestamps, written
#: to the microsecond (TUM), give a handful of distinct intervals (16 over 3,000 frames at
#: 30 fps), each of which would otherwise rebuild every model of the bank
_MODEL_CACHE = 64


class _Filter:
    """The motion filter of one track: an IMM of constant-velocity models (one Kalman
    filter when a single process noise is given), on the state augmented with the last
    ``smoothing_lag`` positions."""

    def __init__(self, config: GatedTrackConfig, z: np.ndarray, R: np.ndarray) -> None:
        k = z.shape[0]
        self.k = k
        self.lag = config.smoothing_lag
        self.qs = config.process_noise
        n = 2 * k + self.lag * k
        pos = [slice(0, k)] + [slice(2 * k + j * k, 3 * k + j * k) for j in range(self.lag)]
        filters = []
        for _ in self.qs:
            H = np.zeros((k, n))
            H[:, :k] = np.eye(k)
            x = np.zeros(n)
            P = np.zeros((n, n))
            for a in pos:  # every kept position starts at z, fully correlated
                x[a] = z
                for b in pos:
                    P[a, b] = R
            P[k : 2 * k, k : 2 * k] = np.eye(k) * config.initial_velocity_std**2
            filters.append(KalmanFilter(n, k, x=x, P=P, H=H, R=R))
        m = len(filters)
        self._dt = math.nan  # the interval the filters' A, Q are built for
        self._models: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}  # by interval
        self.imm: IMMEstimator | None = None
        self.kf: KalmanFilter | None = None
        if m == 1:
            self.kf = filters[0]
        else:
            p = config.switch_probability
            trans = np.full((m, m), p / (m - 1))
            np.fill_diagonal(trans, 1.0 - p)
            self.imm = IMMEstimator(filters, np.full(m, 1.0 / m), trans)

    def predict(self, dt: float) -> None:
        # the filters' own A, Q hold the models of the last dt, rebuilt only when the
        # frame interval changes by more than a nanosecond (timestamps i / fps differ in
        # their last bits from frame to frame)
        if not abs(dt - self._dt) <= 1e-9:
            filters = self.imm.filters if self.imm is not None else [self.kf]
            models = self._models.get(dt)
            if models is None:  # the intervals a recording's timestamps give are few
                if len(self._models) >= _MODEL_CACHE:
                    self._models.clear()
                models = [
                    _lagged(*kinematic_matrices(1, self.k, dt, q), self.k, self.lag)
                    for q in self.qs
                ]  # constant velocity, with the lagged positions
                for pair in models:  # shared by every later frame of this interval
                    for a in pair:
                        a.setflags(write=False)
                self._models[dt] = models
            for f, (A, Q) in zip(filters, models, strict=True):
                f.A, f.Q = A, Q  # type: ignore[union-attr]
            self._dt = dt
        if self.imm is not None:
            self.imm.predict()
        else:
            assert self.kf is not None
            self.kf.predict()

    def mahalanobis2(self, z: np.ndarray, R: np.ndarray) -> float:
        if self.imm is not None:
            return float(self.imm.mahalanobis2(z, R=R))
        assert self.kf is not None
        return float(self.kf.mahalanobis(z, R=R) ** 2)

    def update(self, z: np.ndarray, R: np.ndarray) -> None:
        if self.imm is not None:
            self.imm.update(z, R=R)
        else:
            assert self.kf is not None
            self.kf.update(z, R=R)

    def gated_update(self, z: np.ndarray, R: np.ndarray, gate: float) -> tuple[float, bool]:
        """The squared distance of ``z`` and whether it passed ``gate`` (and updated)."""
        if self.imm is not None:
            d2 = self.imm.update(z, R=R, gate=gate)
            return d2, d2 <= gate
        d2 = self.mahalanobis2(z, R)
        if d2 <= gate:
            self.update(z, R)
        return d2, d2 <= gate

    def skip(self) -> None:
        if self.imm is not None:
            self.imm.skip()

    @property
    def x(self) -> np.ndarray:
        return self.imm.x if self.imm is not None else self.kf.x  # type: ignore[union-attr]

    @property
    def P(self) -> np.ndarray:
        return self.imm.P if self.imm is not None else self.kf.P  # type: ignore[union-attr]

    @property
    def mu(self) -> np.ndarray:
        return self.imm.mu.copy() if self.imm is not None else np.ones(1)

    def lagged(self) -> np.ndarray:
        """``(lag, k)``: the smoothed positions one, two, ... steps back."""
        k, x = self.k, self.x
        return np.array([x[2 * k + j * k : 3 * k + j * k] for j in range(self.lag)]).reshape(
            self.lag, k
        )


class GatedTrack:
    """One object's track (see the module docstring): call :meth:`predict` with the
    frame's time, then :meth:`step` with the frame's measurement (or None).

    Parameters
    ----------
    config : GatedTrackConfig, optional
    dim : int
        Size :math:`k` of the measured position.

    Examples
    --------
    >>> track = GatedTrack(GatedTrackConfig(), dim=1)
    >>> track.predict(0.0) is None
    True
    >>> str(track.step(np.array([1.0]), np.eye(1) * 1e-4).status)
    'new'
    >>> _ = track.predict(0.1)
    >>> str(track.step(np.array([1.01]), np.eye(1) * 1e-4).status)
    'tracking'
    """

    def __init__(self, config: GatedTrackConfig | None = None, dim: int = 3) -> None:
        if config is not None and not isinstance(config, GatedTrackConfig):
            raise InputError(
                f"config must be a GatedTrackConfig (or None: the defaults); got "
                f"{type(config).__name__} {plain_repr(config)[:60]}"
            )
        self.config = config or GatedTrackConfig()
        self.dim = check_dim(dim, "dim")
        per_dim = 2 + self.config.smoothing_lag  # state values per position coordinate
        if per_dim * self.dim > MAX_DIM:
            raise InputError(
                f"dim must be <= {MAX_DIM // per_dim} with smoothing_lag "
                f"{self.config.smoothing_lag}; got {self.dim}"
            )
        self._gate = float(chi2.ppf(self.config.gate_probability, self.dim))
        self.reset()

    def reset(self) -> None:
        """Forget the track."""
        self._filter: _Filter | None = None
        self._candidate: _Filter | None = None
        self._candidate_hits = 0
        self._coast = 0
        self._support: float | None = None
        self._t: float | None = None
        self._age = 0  # steps of the current track, this one included

    @property
    def active(self) -> bool:
        """Whether there is a track."""
        return self._filter is not None

    @property
    def recent_support(self) -> float | None:
        """Exponential average (weight 1/4) of the accepted measurements' supports."""
        return self._support

    def predict(self, t: float) -> np.ndarray | None:
        """Advance the track (and a tentative one) to time ``t`` (seconds) and return the
        predicted position, or None without a track. A time before the last one (a
        recording that restarted) drops the track."""
        t = check_real(t, "t")
        if self._t is not None:
            dt = t - self._t
            if dt < 0:
                self.reset()
            elif dt > 0:  # the same time again: nothing moves
                for f in (self._filter, self._candidate):
                    if f is not None:
                        f.predict(dt)
        self._t = t
        if self._filter is None:
            return None
        return self._filter.x[: self.dim].copy()

    def _reacquired(self, z: np.ndarray, R: np.ndarray) -> bool:
        n = self.config.reacquire_frames
        if n is None:
            return False
        cand = self._candidate
        if cand is not None and cand.gated_update(z, R, self._gate)[1]:
            self._candidate_hits += 1
        else:
            self._candidate = _Filter(self.config, z, R)
            self._candidate_hits = 1
        return self._candidate_hits >= n

    def _overwhelming(self, support: float, dominant: bool) -> bool:
        r = self.config.support_ratio
        return (
            r is not None
            and dominant
            and self._support is not None
            and support >= r * self._support
        )

    def step(
        self,
        z: np.ndarray | None,
        R: np.ndarray | None = None,
        *,
        support: float = 1.0,
        dominant: bool = False,
    ) -> TrackStep:
        """Use (or reject) this step's measurement; see the module docstring.

        Parameters
        ----------
        z : (k,) ndarray or None
            The measured position, or None when nothing was measured.
        R : (k, k) ndarray
            Its covariance (required with ``z``).
        support : float
            Evidence behind ``z`` (e.g. its inlier count), for the gate override.
        dominant : bool
            ``z`` explains most of the candidate data (e.g. most coloured points are its
            inliers); only a dominant measurement may override the gate.

        Returns
        -------
        TrackStep
        """
        c = self.config
        d2 = math.nan
        accepted = False
        support = check_real(support, "support")
        dominant = check_bool(dominant, "dominant")
        if z is not None:
            k = self.dim
            z = check_numeric(z, "z").reshape(-1)
            if z.shape != (k,) or R is None:
                raise InputError(f"z must have {k} values and R must be given")
            R = check_numeric(R, "R")
            if R.shape != (k, k):
                raise InputError(f"R must be the ({k}, {k}) covariance of z; got {R.shape}")
            for name, a in (("z", z), ("R", R)):
                if not np.isfinite(a).all():
                    raise InputError(f"{name} must be finite; got {plain_repr(a)[:80]}")
                check_magnitude(a, name, 1e150)
            R = R * c.measurement_scale
            if self._filter is None:
                self._filter, status, accepted = _Filter(self.config, z, R), TrackStatus.NEW, True
            else:
                d2, passed = self._filter.gated_update(z, R, self._gate)
                if passed:
                    status, accepted = TrackStatus.TRACKING, True
                elif self._overwhelming(support, dominant) or self._reacquired(z, R):
                    self._filter = _Filter(self.config, z, R)
                    status, accepted = TrackStatus.NEW, True
                else:
                    status = TrackStatus.GATED
            if status is not TrackStatus.GATED:
                self._candidate, self._candidate_hits = None, 0
        else:
            self._candidate, self._candidate_hits = None, 0
            status = TrackStatus.COASTING if self._filter is not None else TrackStatus.LOST
        if accepted:
            self._coast = 0
            s = support
            self._support = (
                s
                if self._support is None or status is TrackStatus.NEW
                else (0.75 * self._support + 0.25 * s)
            )
        elif self._filter is not None:
            self._filter.skip()
            self._coast += 1
            if self._coast > c.max_coast:
                self._filter, status = None, TrackStatus.LOST
                self._support = None
        k, lag = self.dim, c.smoothing_lag
        if self._filter is None:
            self._age = 0
            return TrackStep(
                status,
                accepted,
                np.full(k, np.nan),
                np.full((k, k), np.nan),
                d2,
                np.zeros(0),
                np.full((lag, k), np.nan),
            )
        self._age = 1 if status is TrackStatus.NEW else self._age + 1
        lagged = self._filter.lagged()
        lagged[self._age - 1 :] = np.nan  # steps before this track began
        x, P = self._filter.x, self._filter.P
        return TrackStep(
            status, accepted, x[:k].copy(), P[:k, :k].copy(), d2, self._filter.mu, lagged
        )
