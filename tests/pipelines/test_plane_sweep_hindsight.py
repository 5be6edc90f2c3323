"""The sweep's hindsight reference (``benchmarks.plane_sweep.hindsight_summary``): the
best smoother of a sequence's accepted fits, chosen knowing the truth."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.plane_sweep import hindsight_summary
from robopercept.pipelines import PlaneTrackResult, summarize
from robopercept.tracking import TrackStatus

MS = {"points": 1.0, "color": 1.0, "ransac": 1.0, "kalman": 1.0, "total": 4.0}


def _sequence(d_true: np.ndarray, seed: int, sigma_mm: float = 1.0):
    # a board facing the camera, tilting slowly; fits with sigma_mm of offset noise and
    # 0.05 deg of normal noise, the track's own output left as the raw fit
    rng = np.random.default_rng(seed)
    results, truths = [], []
    for i, d in enumerate(d_true):
        a = 0.2 * np.sin(i / 20)
        n_true = np.array([np.sin(a), 0.0, np.cos(a)])
        n = n_true + rng.normal(0, np.radians(0.05), 3)
        n /= np.linalg.norm(n)
        dm = d + rng.normal(0, sigma_mm * 1e-3)
        results.append(
            PlaneTrackResult(
                index=i,
                timestamp=i / 30,
                status=TrackStatus.TRACKING,
                measured=True,
                accepted=True,
                normal=n,
                d=dm,
                inliers=5000,
                track_normal=n,
                track_d=dm,
                covariance_trace=1e-6,
                mode_probabilities=np.ones(1),
                n_points=9000,
                n_green=6000,
                ms=MS,
                inlier_points=np.zeros((0, 3)),
            )
        )
        truths.append({"plane": (n_true, float(d)), "valid_board_pixels": 5000})
    return results, truths


@pytest.mark.parametrize("seed", [0, 1])
def test_smooth_motion_is_smoothed_well_below_the_raw_fit(seed):
    t = np.arange(60) / 30
    results, truths = _sequence(1.5 + 0.1 * np.sin(t), seed)
    raw = summarize(results, truths).raw
    best = hindsight_summary(results, truths).tracked
    # sixty fits of a slow sine: smoothing over many frames at least halves the errors
    assert best.offset_mm.median < 0.6 * raw.offset_mm.median
    assert best.angle_deg.median < 0.6 * raw.angle_deg.median


@pytest.mark.parametrize("seed", [0, 1])
def test_erratic_motion_leaves_nothing_to_smooth(seed):
    # steps of 20 mm a frame in random directions: no model predicts a frame from its
    # neighbours better than its own 1 mm fit, so the best smoother is the fit itself
    rng = np.random.default_rng(100 + seed)
    results, truths = _sequence(1.5 + np.cumsum(rng.normal(0, 0.02, 60)), seed)
    raw = summarize(results, truths).raw
    best = hindsight_summary(results, truths).tracked
    for q in ("median", "p95"):
        r, b = getattr(raw.offset_mm, q), getattr(best.offset_mm, q)
        assert r * 0.97 < b < r * 1.005, (q, b, r)
