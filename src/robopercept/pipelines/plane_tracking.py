r"""RGB-D plane tracking: find a coloured board in every frame and track its plane.

Per frame (:meth:`PlaneTracker.process`):

1. **Points.** Depth to points, :math:`p = s D\, r(u, v)` with the unit-depth ray
   :math:`r(u, v)` of each depth pixel (``deproject(pixel, 1)``, computed once per
   camera), for the pixels with depth.
2. **Colour.** Each point is projected into the colour image (through
   ``T_color_depth`` and the colour intrinsics) and takes the colour of its pixel,
   unless the z-buffer occlusion test of :func:`~robopercept.depth.texture_coordinates`
   says another point hides it there; a point is "green" when that colour's HSV
   (OpenCV scale, default H 45..65, S 35..255, V 35..255) is in the box. This is the
   library path ``depth_to_points`` -> ``texture_coordinates`` -> ``sample_colors`` ->
   ``rgb_to_hsv`` -> ``hsv_range_mask``, point for point, fused into three compiled
   passes (projection, z-buffer, selection) so that only the green points are stored.
3. **Plane.** RANSAC on the green points (:func:`~robopercept.estimation.ransac` with
   :class:`~robopercept.estimation.PlaneModel`: 3 points, normal by cross product):
   hypotheses are scored by MSAC, :math:`\sum_i \min(r_i^2, \tau^2)`, so that among
   planes with as many inliers the one nearer them wins (plain inlier counting lets a
   plane tilt toward the background points that the colour image's parallax paints
   green at the board's edges); the plane predicted by the tracker is scored first, the
   search stops early once a hypothesis has as large a share of inliers as the previous
   frame had, and the best hypothesis is refitted by total least squares on its
   inliers. The inlier threshold
   grows with the squared distance like stereo depth noise,
   :math:`\tau(z) = \max(\tau_{min}, \tau_1 z^2)` at the green points' median depth
   :math:`z` in metres. Optionally (``hue_tolerance``) hue is an extra feature in the
   scoring: a point counts as an inlier only if its hue is also within the tolerance of
   the hypothesis' sample hue.
4. **Tracking.** The plane in closest-point form :math:`\pi = d\, n` (the point of the
   plane nearest the camera, with :math:`n^\top x = d`, :math:`d \ge 0`) is the
   measurement of a constant-velocity Kalman filter on :math:`(\pi, \dot\pi)`.
   A measurement whose Mahalanobis distance
   :math:`y^\top S^{-1} y` exceeds the chi-square quantile (3 degrees of freedom,
   ``gate_probability``) is rejected; without an accepted measurement the track coasts
   on its prediction, and after ``max_coast`` such frames it is dropped, so that the
   next detection starts a new one (re-acquisition). A rejected measurement also feeds
   a tentative track (the same filter and gate); when ``reacquire_frames`` consecutive
   rejected measurements agree with it, it replaces the track, which had locked on to
   a wrong plane.

The tracked plane is :math:`n = \pi / \|\pi\|`, :math:`d = \|\pi\|`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit, prange
from scipy.stats import chi2

from robopercept.depth import pixel_rays
from robopercept.depth.rgbd import project_to_color
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import Plane, PlaneModel, ransac
from robopercept.estimation.least_squares import scatter_matrix
from robopercept.estimation.models import Model
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.camera import compiled_params
from robopercept.imaging.color import rgb_to_hsv_pixel
from robopercept.sources.frames import RGBDFrame
from robopercept.tracking import KalmanFilter, constant_velocity

__all__ = [
    "PlaneHueModel",
    "PlaneTrackResult",
    "PlaneTracker",
    "PlaneTrackerConfig",
    "plane_covariance",
    "plane_errors",
    "summarize",
]

STAGES = ("points", "color", "ransac", "kalman")


_CHUNKS = 64  # row blocks of the parallel per-pixel passes


@njit(cache=True, nogil=True, parallel=True)
def _project_kernel(
    depth, rays, scale, R, t, k, model, c, width, height, pix, zc
):  # pragma: no cover
    # For every depth pixel i with depth: the point p = s D r(u, v), its colour pixel
    # pix[i] = row * width + col (-1: no depth, behind the colour camera or outside its
    # image) and its depth zc[i] in the colour frame. Pixels are independent: parallel.
    n = depth.shape[0]
    for b in prange(_CHUNKS):
        for i in range(b * n // _CHUNKS, (b + 1) * n // _CHUNKS):
            z = depth[i] * scale
            u, v, zcol = project_to_color(
                rays[i, 0] * z, rays[i, 1] * z, rays[i, 2] * z, R, t, k, model, c
            )
            col = np.rint(u)
            row = np.rint(v)
            j = -1
            if depth[i] > 0 and zcol > 0 and col >= 0 and col < width and row >= 0 and row < height:
                j = int(row) * width + int(col)
            pix[i] = j
            zc[i] = zcol


@njit(cache=True, nogil=True)
def _zbuffer_kernel(pix, zc, zbuf):  # pragma: no cover - compiled
    # nearest colour-frame depth per colour pixel (serial: pixels collide)
    for i in range(pix.shape[0]):
        j = pix[i]
        if j >= 0 and zc[i] < zbuf[j]:
            zbuf[j] = zc[i]


@njit(cache=True, nogil=True, parallel=True)
def _select_kernel(
    depth, rays, scale, rgb, pix, zc, zbuf, tol, low, high, out, hue
):  # pragma: no cover - compiled
    # The points whose colour pixel is theirs (no other point nearer there by more than
    # tol; tol < 0: no test) and whose HSV (OpenCV's uint8 conversion, bit for bit) lies
    # in the box low..high (hue wraps around when low[0] > high[0]). Each row block
    # writes from its own first pixel on, then the blocks are packed in order, so the
    # result is in row-major order whatever the threads. Returns the number selected.
    n = pix.shape[0]
    counts = np.zeros(_CHUNKS, dtype=np.int64)
    wrap = low[0] > high[0]
    for b in prange(_CHUNKS):
        a = b * n // _CHUNKS
        g = a
        for i in range(a, (b + 1) * n // _CHUNKS):
            j = pix[i]
            if j < 0:
                continue
            if tol >= 0 and zc[i] > zbuf[j] + tol:
                continue
            h, s, v = rgb_to_hsv_pixel(
                np.int32(rgb[3 * j]), np.int32(rgb[3 * j + 1]), np.int32(rgb[3 * j + 2])
            )
            if s < low[1] or s > high[1] or v < low[2] or v > high[2]:
                continue
            if wrap:
                if h < low[0] and h > high[0]:
                    continue
            elif h < low[0] or h > high[0]:
                continue
            z = depth[i] * scale
            out[g, 0] = rays[i, 0] * z
            out[g, 1] = rays[i, 1] * z
            out[g, 2] = rays[i, 2] * z
            hue[g] = h
            g += 1
        counts[b] = g - a
    m = 0
    for b in range(_CHUNKS):
        a = b * n // _CHUNKS
        for g in range(a, a + counts[b]):
            out[m, 0] = out[g, 0]
            out[m, 1] = out[g, 1]
            out[m, 2] = out[g, 2]
            hue[m] = hue[g]
            m += 1
    return m


@njit(cache=True, nogil=True, parallel=True)
def _reset_kernel(pix, zbuf):  # pragma: no cover - compiled
    # back to +inf for the next frame (only the touched pixels; racing writes store the
    # same value)
    n = pix.shape[0]
    for b in prange(_CHUNKS):
        for i in range(b * n // _CHUNKS, (b + 1) * n // _CHUNKS):
            if pix[i] >= 0:
                zbuf[pix[i]] = np.inf


@dataclass(frozen=True)
class PlaneTrackerConfig:
    """Settings of :class:`PlaneTracker` (defaults suit a D435 and a green board).

    Attributes
    ----------
    hsv_low, hsv_high : (3,) tuple
        HSV box on the OpenCV scale (H 0..180, S and V 0..255), bounds inclusive.
    threshold_1m : float
        RANSAC inlier threshold at 1 m, metres; it grows with :math:`z^2`.
    threshold_min : float
        Lower bound of the threshold, metres.
    min_points : int
        Fewer green points (or inliers) than this: no detection.
    max_iterations : int
        RANSAC bound on hypotheses per frame.
    probability : float
        RANSAC confidence for the adaptive number of iterations.
    hue_tolerance : float or None
        Use hue as an extra RANSAC feature (OpenCV hue units); None: geometry only.
    process_noise : float
        Variance ``q`` of the white-noise acceleration of :math:`\\pi` in the
        constant-velocity model, (m/s^2)^2.
    measurement_noise : float
        Standard deviation of a measured :math:`\\pi` at 1 m, metres; it grows with
        :math:`d^2` like stereo depth noise and is added to the least-squares covariance
        of the fit (see :func:`plane_covariance`).
    gate_probability : float
        Chi-square gate; measurements outside are rejected.
    max_coast : int
        Frames a track survives without an accepted measurement.
    reacquire_frames : int or None
        A measurement the gate rejects starts a tentative track (the same filter, gated
        the same way); when this many consecutive rejected measurements agree with it,
        it replaces the track (the old one had followed a wrong plane). None: never.
    occlusion_tolerance : float
        Z-buffer tolerance of the colour lookup, metres.
    rng : int
        Seed of RANSAC's sampling (frame ``i`` uses ``(rng, i)``).
    """

    hsv_low: tuple[float, float, float] = (45.0, 35.0, 35.0)
    hsv_high: tuple[float, float, float] = (65.0, 255.0, 255.0)
    threshold_1m: float = 0.01
    threshold_min: float = 0.004
    min_points: int = 200
    max_iterations: int = 200
    probability: float = 0.999
    hue_tolerance: float | None = None
    process_noise: float = 4.0
    measurement_noise: float = 0.004
    gate_probability: float = 0.9999
    max_coast: int = 15
    reacquire_frames: int | None = 3
    occlusion_tolerance: float = 0.02
    rng: int = 0

    def __post_init__(self) -> None:
        lo = tuple(float(v) for v in self.hsv_low)
        hi = tuple(float(v) for v in self.hsv_high)
        if len(lo) != 3 or len(hi) != 3:
            raise InputError(f"hsv_low and hsv_high need 3 values (H, S, V); got {lo}, {hi}")
        if not (0 <= lo[0] <= 180 and 0 <= hi[0] <= 180) or not all(
            0 <= v <= 255 for v in lo[1:] + hi[1:]
        ):
            raise InputError(
                f"HSV bounds are on the OpenCV scale: H in 0..180, S and V in 0..255; "
                f"got low={lo}, high={hi}"
            )
        object.__setattr__(self, "hsv_low", lo)
        object.__setattr__(self, "hsv_high", hi)
        for name in ("threshold_1m", "threshold_min", "process_noise", "measurement_noise"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name} must be > 0; got {getattr(self, name)}")
        if not 0 < self.gate_probability < 1 or not 0 < self.probability < 1:
            raise InputError("gate_probability and probability must be in (0, 1)")
        if self.min_points < 3 or self.max_iterations < 1 or self.max_coast < 0:
            raise InputError("min_points >= 3, max_iterations >= 1 and max_coast >= 0 required")
        if self.reacquire_frames is not None and self.reacquire_frames < 2:
            raise InputError(
                f"reacquire_frames must be >= 2 or None (never); got {self.reacquire_frames}"
            )


@dataclass(frozen=True)
class PlaneTrackResult:
    """What :meth:`PlaneTracker.process` reports for one frame.

    Attributes
    ----------
    index : int
    timestamp : float
    detected : bool
        A plane was found on enough green points and accepted by the tracker's gate.
    normal, d : (3,) ndarray or None, float
        The raw RANSAC plane (``normal @ x = d``, ``d >= 0``) if one was found (also when
        the gate rejected it); NaN otherwise.
    inliers : int
    gated : bool
        A plane was found but rejected by the chi-square gate.
    track_normal, track_d : (3,) ndarray, float
        The tracked plane (NaN when there is no track).
    covariance_trace : float
        Trace of the position block of the track's covariance (NaN without a track).
    status : str
        ``"tracking"``, ``"coasting"``, ``"new"`` (a track started this frame) or ``"lost"``.
    n_points, n_green : int
        Valid depth points, and those with the board's colour.
    ms : dict
        Milliseconds per stage (``points``, ``color``, ``ransac``, ``kalman``, ``total``).
    inlier_points : (K, 3) ndarray
        The board's inlier points (depth frame), for drawing.
    """

    index: int
    timestamp: float
    detected: bool
    normal: np.ndarray
    d: float
    inliers: int
    gated: bool
    track_normal: np.ndarray
    track_d: float
    covariance_trace: float
    status: str
    n_points: int
    n_green: int
    ms: dict[str, float]
    inlier_points: np.ndarray = field(repr=False)


class PlaneHueModel(Model[Plane]):
    """A plane whose inliers must also match the hypothesis' hue.

    Data rows are ``(x, y, z, h)`` with h the OpenCV hue (0..180). The minimal sample is
    3 points; the hypothesis is the plane through them plus the circular mean hue of the
    sample, :math:`(n, d, \\bar h)`. A row's residual is its distance to the plane when
    its hue is within ``hue_tolerance`` of :math:`\\bar h` (on the 180-periodic circle),
    and infinity otherwise.
    """

    sample_size = 3
    dim = 4
    name = "plane with hue"

    def __init__(self, hue_tolerance: float) -> None:
        self.tol = float(hue_tolerance)
        self._plane = PlaneModel()

    def fit_minimal(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        params, valid = self._plane.fit_minimal(np.ascontiguousarray(samples[..., :3]))
        ang = samples[..., 3] * (2 * np.pi / 180.0)
        hue = np.arctan2(np.sin(ang).mean(1), np.cos(ang).mean(1)) * (180.0 / (2 * np.pi))
        return np.column_stack([params, np.mod(hue, 180.0)]), valid

    def fit(self, data: np.ndarray) -> np.ndarray:
        p = self._plane.fit(np.ascontiguousarray(data[:, :3]))
        ang = data[:, 3] * (2 * np.pi / 180.0)
        hue = math.atan2(np.sin(ang).mean(), np.cos(ang).mean()) * (180.0 / (2 * np.pi))
        return np.append(p, hue % 180.0)

    def residuals(self, params: np.ndarray, data: np.ndarray) -> np.ndarray:
        r = self._plane.residuals(params[:, :4], np.ascontiguousarray(data[:, :3]))
        dh = np.abs(data[None, :, 3] - params[:, 4:5]) % 180.0
        dh = np.minimum(dh, 180.0 - dh)
        r[dh > self.tol] = np.inf
        return r

    def check(self, data: np.ndarray) -> None:
        self._plane.check(np.ascontiguousarray(data[:, :3]))

    def result(self, params: np.ndarray) -> Plane:
        return self._plane.result(params[:4])


def plane_covariance(points: np.ndarray, normal: np.ndarray, d: float) -> np.ndarray:
    r"""Least-squares covariance of the closest point :math:`\pi = d n` of a plane fitted
    to ``points`` by total least squares.

    With the centroid :math:`c`, the scatter's eigenpairs :math:`(\lambda_k, e_k)` in the
    plane (k = 1, 2) and the residual variance
    :math:`\sigma^2 = \lambda_0 / (N - 3)`, the normal tilts by
    :math:`a_k \sim N(0, \sigma^2 / \lambda_k)` about each in-plane axis and the
    centroid moves along :math:`n` with variance :math:`\sigma^2 / N`; to first order
    :math:`\delta\pi = \sum_k a_k (d\, e_k + (e_k^\top c)\, n) + (n^\top \delta c)\, n`,
    so :math:`\Sigma_\pi = \sum_k \frac{\sigma^2}{\lambda_k} v_k v_k^\top +
    \frac{\sigma^2}{N} n n^\top` with :math:`v_k = d\, e_k + (e_k^\top c)\, n`.
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


def _closest_point(normal: np.ndarray, offset: float) -> tuple[np.ndarray, float]:
    """From ``n.x + offset = 0`` to ``(n', d)`` with ``n'.x = d`` and ``d >= 0``."""
    n = np.asarray(normal, dtype=np.float64)
    d = -float(offset)
    if d < 0:
        n, d = -n, -d
    return n, d


class PlaneTracker:
    """Detect and track the plane of a coloured board in RGB-D frames.

    Parameters
    ----------
    config : PlaneTrackerConfig, optional

    Examples
    --------
    >>> from robopercept.sources import SyntheticRGBDScene
    >>> scene = SyntheticRGBDScene(n_frames=2, depth_size=(212, 120), color_size=(320, 180))
    >>> tracker = PlaneTracker()
    >>> [r.detected for r in map(tracker.process, scene)]
    [True, True]
    """

    def __init__(self, config: PlaneTrackerConfig | None = None) -> None:
        self.config = config or PlaneTrackerConfig()
        self._rays_key: tuple | None = None
        self._rays: np.ndarray | None = None
        self._zbuf = np.zeros(0)  # colour-image z-buffer, +inf between frames
        self.kf: KalmanFilter | None = None
        self._last_t: float | None = None
        self._coast = 0
        self._prev_ratio: float | None = None
        self._candidate: KalmanFilter | None = None  # tentative track (reacquire_frames)
        self._candidate_hits = 0
        # chi-square quantile of the gate, 3 degrees of freedom (computed once)
        self._gate = float(chi2.ppf(self.config.gate_probability, 3))

    def reset(self) -> None:
        """Forget the track."""
        self.kf = None
        self._last_t = None
        self._coast = 0
        self._prev_ratio = None
        self._candidate = None
        self._candidate_hits = 0

    # ---------------------------------------------------------------- stages
    def _unit_rays(self, k: CameraIntrinsics) -> np.ndarray:
        if self._rays_key != (k,):
            self._rays = pixel_rays(k)
            self._rays_key = (k,)
        assert self._rays is not None
        return self._rays

    def _project(self, frame: RGBDFrame) -> tuple[np.ndarray, np.ndarray, int]:
        # each depth pixel's colour pixel and colour-frame depth; the z-buffer filled
        rays = self._unit_rays(frame.depth_intrinsics)
        flat = np.ascontiguousarray(frame.depth).reshape(-1)
        kc = frame.color_intrinsics
        if self._zbuf.shape[0] != kc.width * kc.height:
            self._zbuf = np.full(kc.width * kc.height, np.inf)
        T = frame.T_color_depth
        k, model, coeffs = compiled_params(kc)
        pix = np.empty(flat.shape[0], dtype=np.int64)
        zc = np.empty(flat.shape[0])
        _project_kernel(
            flat,
            rays,
            float(frame.depth_scale),
            np.ascontiguousarray(T[:3, :3]),
            np.ascontiguousarray(T[:3, 3]),
            k,
            model,
            coeffs,
            kc.width,
            kc.height,
            pix,
            zc,
        )
        if self.config.occlusion_tolerance is not None:
            _zbuffer_kernel(pix, zc, self._zbuf)
        return pix, zc, int(np.count_nonzero(flat))

    def _green(
        self, frame: RGBDFrame, pix: np.ndarray, zc: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        # the colour of each point at its colour pixel, unless another point hides it
        # there (the z-buffer test of texture_coordinates), then the HSV box: the same
        # bit-exact conversion as rgb_to_hsv, on just those pixels; the green points
        c = self.config
        n = pix.shape[0]
        out = np.empty((n, 3))
        hue = np.empty(n)
        tol = c.occlusion_tolerance
        try:
            g = _select_kernel(
                np.ascontiguousarray(frame.depth).reshape(-1),
                self._unit_rays(frame.depth_intrinsics),
                float(frame.depth_scale),
                np.ascontiguousarray(frame.color).reshape(-1),
                pix,
                zc,
                self._zbuf,
                -1.0 if tol is None else float(tol),
                np.asarray(c.hsv_low, dtype=np.float64),
                np.asarray(c.hsv_high, dtype=np.float64),
                out,
                hue,
            )
        finally:
            if tol is not None:
                _reset_kernel(pix, self._zbuf)
        return out[:g], hue[:g]

    def _threshold(self, pts: np.ndarray) -> float:
        c = self.config
        z = float(np.median(pts[:: max(1, pts.shape[0] // 4096), 2]))  # a sample suffices
        return max(c.threshold_min, c.threshold_1m * z * z)

    def _new_filter(self, z: np.ndarray, R: np.ndarray) -> KalmanFilter:
        # a constant-velocity filter on pi started at the measurement z (covariance R)
        kf = constant_velocity(3, 1.0 / 30.0, self.config.process_noise, 1.0)
        kf.x[:3] = z
        kf.P = np.zeros((6, 6))
        kf.P[:3, :3] = R
        kf.P[3:, 3:] = np.eye(3)  # velocity unknown: 1 m/s standard deviation
        return kf

    def _reacquire(self, z: np.ndarray, R: np.ndarray) -> bool:
        # a measurement the track's gate rejected: feed the tentative track (or start
        # one); True when it has reacquire_frames consecutive agreeing measurements
        n = self.config.reacquire_frames
        if n is None:
            return False
        cand = self._candidate
        if cand is not None and cand.mahalanobis(z, R=R) ** 2 <= self._gate:
            cand.update(z, R=R)
            self._candidate_hits += 1
        else:
            self._candidate = self._new_filter(z, R)
            self._candidate_hits = 1
        return self._candidate_hits >= n

    # ---------------------------------------------------------------- per frame
    def process(self, frame: RGBDFrame) -> PlaneTrackResult:
        """Detect the board in ``frame`` and update the track (see the module docstring)."""
        if not isinstance(frame, RGBDFrame):
            raise InputError(f"frame must be an RGBDFrame; got {type(frame).__name__}")
        c = self.config
        ms: dict[str, float] = {}
        t0 = time.perf_counter()
        pix, zc, n_points = self._project(frame)
        t1 = time.perf_counter()
        ms["points"] = (t1 - t0) * 1e3
        green, hue = self._green(frame, pix, zc)
        t2 = time.perf_counter()
        ms["color"] = (t2 - t1) * 1e3

        # ---- predict
        dt = None
        if self.kf is not None and self._last_t is not None:
            dt = frame.timestamp - self._last_t
            if not dt > 0:
                dt = None
        predicted = None
        model = None if dt is None else constant_velocity(3, dt, c.process_noise, 1.0)
        for kf in (self.kf, self._candidate):
            if kf is not None:
                if model is None:
                    kf.predict()
                else:  # the model for this frame's time step
                    kf.predict(A=model.A, Q=model.Q)
        if self.kf is not None:
            predicted = self.kf.x[:3].copy()

        # ---- RANSAC
        normal = np.full(3, np.nan)
        d = math.nan
        n_in = 0
        inlier_points = np.zeros((0, 3))
        if green.shape[0] >= c.min_points:
            thr = self._threshold(green)
            initial = None
            if predicted is not None and np.linalg.norm(predicted) > 0:
                dp = float(np.linalg.norm(predicted))
                initial = np.append(predicted / dp, -dp)[None]
            min_inl = None
            if self._prev_ratio is not None:
                min_inl = max(c.min_points, int(self._prev_ratio * green.shape[0]))
            rng = np.random.default_rng([c.rng, frame.index])
            try:
                if c.hue_tolerance is None:
                    res = ransac(
                        green,
                        PlaneModel(),
                        thr,
                        max_iterations=c.max_iterations,
                        probability=c.probability,
                        scoring="msac",
                        min_inliers=min_inl,
                        initial=initial,
                        rng=rng,
                    )
                else:
                    data = np.column_stack([green, hue])
                    init = None
                    if initial is not None:
                        init = np.append(initial[0], float(np.median(hue)))[None]
                    res = ransac(
                        data,
                        PlaneHueModel(c.hue_tolerance),
                        thr,
                        max_iterations=c.max_iterations,
                        probability=c.probability,
                        scoring="msac",
                        min_inliers=min_inl,
                        initial=init,
                        rng=rng,
                    )
                n_in = int(res.inliers.sum())
                if n_in >= c.min_points:
                    normal, d = _closest_point(res.model.normal, res.model.offset)
                    inlier_points = green[res.inliers]
                    self._prev_ratio = n_in / green.shape[0]
            except DegenerateError:
                n_in = 0
        t3 = time.perf_counter()
        ms["ransac"] = (t3 - t2) * 1e3

        # ---- update
        found = bool(np.isfinite(d))
        accepted = False
        gated = False
        status = "lost"
        if found:
            z = d * normal
            R = plane_covariance(inlier_points, normal, d)
            R += np.eye(3) * (c.measurement_noise * max(d, 1.0) ** 2) ** 2
            if self.kf is None:
                self.kf = self._new_filter(z, R)
                accepted, status = True, "new"
            elif self.kf.mahalanobis(z, R=R) ** 2 <= self._gate:
                self.kf.update(z, R=R)
                accepted, status = True, "tracking"
            elif self._reacquire(z, R):
                self.kf, self._candidate = self._candidate, None
                accepted, status = True, "new"
            else:
                gated = True
        if not gated:
            self._candidate = None
        if not accepted:
            if not found:
                self._prev_ratio = None
            if self.kf is not None:
                self._coast += 1
                status = "coasting"
                if self._coast > c.max_coast:
                    self.kf = None
                    status = "lost"
        else:
            self._coast = 0
        if self.kf is not None:
            pi = self.kf.x[:3]
            track_d = float(np.linalg.norm(pi))
            track_n = pi / track_d if track_d > 0 else np.full(3, np.nan)
            cov = float(np.trace(self.kf.P[:3, :3]))
        else:
            track_n, track_d, cov = np.full(3, np.nan), math.nan, math.nan
        self._last_t = frame.timestamp
        t4 = time.perf_counter()
        ms["kalman"] = (t4 - t3) * 1e3
        ms["total"] = (t4 - t0) * 1e3
        return PlaneTrackResult(
            index=frame.index,
            timestamp=frame.timestamp,
            detected=accepted,
            normal=normal,
            d=d,
            inliers=n_in if found else 0,
            gated=gated,
            track_normal=track_n,
            track_d=track_d,
            covariance_trace=cov,
            status=status,
            n_points=n_points,
            n_green=int(green.shape[0]),
            ms=ms,
            inlier_points=inlier_points,
        )

    def run(self, frames: Iterable[RGBDFrame]) -> Iterator[PlaneTrackResult]:
        """:meth:`process` every frame of ``frames``."""
        for frame in frames:
            yield self.process(frame)


# -------------------------------------------------------------------- evaluation
def plane_errors(
    normal: np.ndarray, d: float, true_normal: np.ndarray, true_d: float
) -> tuple[float, float]:
    """Angle between the normals (degrees, sign ignored) and ``|d - d_true|`` (metres),
    with both planes in the ``n.x = d``, ``d >= 0`` form."""
    n = np.asarray(normal, dtype=np.float64)
    m = np.asarray(true_normal, dtype=np.float64)
    if not (np.isfinite(n).all() and np.isfinite(d)):
        return math.nan, math.nan
    c = abs(float(n @ m) / (np.linalg.norm(n) * np.linalg.norm(m)))
    return math.degrees(math.acos(min(c, 1.0))), abs(float(d) - float(true_d))


def _stats(values: list[float]) -> dict[str, float | None]:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=np.float64)
    if v.size == 0:
        return {"median": None, "p95": None, "n": 0}
    return {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)), "n": int(v.size)}


def _jitter(normals: np.ndarray) -> float | None:
    """RMS of the second difference of consecutive unit normals, degrees: smooth motion
    cancels, frame-to-frame noise does not."""
    if normals.shape[0] < 3:
        return None
    n = normals.copy()
    # sign-align consecutive normals
    for i in range(1, n.shape[0]):
        if np.isfinite(n[i]).all() and np.isfinite(n[i - 1]).all() and n[i] @ n[i - 1] < 0:
            n[i] = -n[i]
    dd = n[2:] - 2 * n[1:-1] + n[:-2]
    ok = np.isfinite(dd).all(axis=1)
    if not ok.any():
        return None
    return float(np.degrees(np.sqrt(np.mean(np.sum(dd[ok] ** 2, axis=1)))))


def summarize(
    results: list[PlaneTrackResult],
    truths: list[dict[str, Any]] | None = None,
    *,
    min_board_pixels: int = 500,
    skipped: int = 0,
    wall_seconds: float | None = None,
) -> dict[str, Any]:
    """Figures of a run: detection rate, errors against the truth, jitter, timing.

    Parameters
    ----------
    results : list of PlaneTrackResult
    truths : list of dict, optional
        Per result, the frame's ground truth: ``"plane": (n, d)`` and optionally
        ``"valid_board_pixels"`` (board pixels with valid depth). Frames with fewer than
        ``min_board_pixels`` such pixels are left out of the detection rate and the
        errors; so are all frames when no truth is given.
    skipped : int
        Frames the source skipped (corrupt files), reported as is.
    wall_seconds : float, optional
        Wall time of the run, for frames per second.
    """
    out: dict[str, Any] = {
        "frames": len(results),
        "skipped_frames": int(skipped),
        "detected_frames": int(sum(r.detected for r in results)),
    }
    ms = {s: [r.ms[s] for r in results] for s in (*STAGES, "total")}
    out["ms_per_stage_median"] = {s: float(np.median(v)) if v else None for s, v in ms.items()}
    if wall_seconds is not None and wall_seconds > 0:
        out["fps"] = len(results) / wall_seconds
    elif results:
        out["fps"] = 1000.0 / float(np.median(ms["total"]))
    raw_n = np.array([r.normal if r.detected else np.full(3, np.nan) for r in results])
    trk_n = np.array([r.track_normal for r in results])
    if results:
        out["jitter_deg"] = {"raw": _jitter(raw_n), "tracked": _jitter(trk_n)}
    if truths is None or not any("plane" in t for t in truths):
        return out
    if len(truths) != len(results):
        raise InputError(f"need one truth per result; got {len(truths)} for {len(results)}")
    visible = [
        "plane" in t and t.get("valid_board_pixels", min_board_pixels) >= min_board_pixels
        for t in truths
    ]
    ra, rd, ta, td = [], [], [], []
    for r, t, vis in zip(results, truths, visible, strict=False):
        if not vis:
            continue
        tn, tdist = t["plane"]
        if r.detected:
            a, e = plane_errors(r.normal, r.d, tn, tdist)
            ra.append(a)
            rd.append(e)
        a, e = plane_errors(r.track_normal, r.track_d, tn, tdist)
        ta.append(a)
        td.append(e)
    n_vis = int(sum(visible))
    n_det = int(sum(r.detected for r, v in zip(results, visible, strict=False) if v))
    out["evaluated_frames"] = n_vis
    out["detection_rate"] = n_det / n_vis if n_vis else None
    out["raw"] = {"angle_deg": _stats(ra), "offset_mm": _stats([1e3 * e for e in rd])}
    out["tracked"] = {"angle_deg": _stats(ta), "offset_mm": _stats([1e3 * e for e in td])}
    return out
