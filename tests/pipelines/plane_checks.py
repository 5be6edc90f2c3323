"""The acceptance rule of the plane tracker's tests (tracked beats raw), shared by
``test_plane_tracking.py`` and ``test_plane_tracking_motion.py``."""

from __future__ import annotations

from robopercept.pipelines import PlaneTracker

__all__ = ["check_beats_raw", "no_worse", "track"]


def track(frames, config=None):
    # results in frame order (fixed-lag smoothed as the run writes them) and the truths
    results, truths = [], []
    for f, r in PlaneTracker(config).stream(frames):
        results.append(r)
        truths.append(f.ground_truth)
    return results, truths


def no_worse(tracked, raw, floor):
    # the rule: at most the raw fit's figure, or within 5 % of it where the raw
    # fit is already below the floor (0.1 deg, 1 mm)
    return tracked <= (1.05 * raw if raw < floor else raw)


def check_beats_raw(summary):
    """The issue's acceptance figures: tracked angle and offset errors, median and p95,
    at most the raw fit's; tracked jitter below raw; accepted fits on >= 99 % of the
    frames with >= 500 valid board pixels."""
    raw, trk = summary.raw, summary.tracked
    for name, floor in (("angle_deg", 0.1), ("offset_mm", 1.0)):
        r, t = getattr(raw, name), getattr(trk, name)
        assert no_worse(t.median, r.median, floor), (name, "median", t.median, r.median)
        assert no_worse(t.p95, r.p95, floor), (name, "p95", t.p95, r.p95)
    assert summary.jitter_tracked_deg < summary.jitter_raw_deg
    assert summary.detection_rate >= 0.99
    assert summary.evaluated_frames >= 0.9 * summary.frames
