"""GatedTrack: statuses, the gate and its override, coasting, timestamps driving the
model, and fixed-lag smoothing by state augmentation."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.tracking import (
    GatedTrack,
    GatedTrackConfig,
    TrackStatus,
    constant_velocity,
    lagged_model,
)

R = np.eye(3) * 1e-6


def test_statuses_gate_coast_and_loss():
    track = GatedTrack(GatedTrackConfig(max_coast=2, support_ratio=None, reacquire_frames=None))
    assert track.predict(0.0) is None
    assert track.step(None).status is TrackStatus.LOST
    assert track.step(np.array([1.0, 0, 2]), R).status is TrackStatus.NEW
    track.predict(1 / 30)
    s = track.step(np.array([1.001, 0, 2]), R)
    assert s.status is TrackStatus.TRACKING and s.accepted
    track.predict(2 / 30)
    s = track.step(np.array([9.0, 0, 2]), R, support=1e6, dominant=True)  # 8 m away: gated
    assert s.status is TrackStatus.GATED and not s.accepted and s.mahalanobis2 > 100
    track.predict(3 / 30)
    assert track.step(None).status is TrackStatus.COASTING
    track.predict(4 / 30)
    assert track.step(None).status is TrackStatus.LOST and not track.active


def test_overwhelming_dominant_support_restarts_at_once():
    track = GatedTrack(GatedTrackConfig(support_ratio=0.5, reacquire_frames=None))
    track.predict(0.0)
    track.step(np.array([1.0, 0, 2]), R, support=1000, dominant=True)
    track.predict(1 / 30)
    # a far plane with few inliers is gated; one as strong as the track's is taken
    far = np.array([9.0, 0, 2])
    assert track.step(far, R, support=100, dominant=True).status == "gated"
    track.predict(2 / 30)
    assert track.step(far, R, support=900, dominant=False).status == "gated"
    track.predict(3 / 30)
    s = track.step(far, R, support=900, dominant=True)
    assert s.status is TrackStatus.NEW and s.accepted
    np.testing.assert_allclose(s.position, far)


def test_one_model_is_the_kalman_filter_with_the_timestamps_dt():
    # a single process noise: the plain constant-velocity Kalman filter, with the model
    # of each step's dt (irregular timestamps)
    cfg = GatedTrackConfig(process_noise=(3.0,), initial_velocity_std=1.0)
    track = GatedTrack(cfg, dim=3)
    rng = np.random.default_rng(0)
    times = np.cumsum(rng.uniform(0.02, 0.05, 30))
    zs = [np.array([0.5 * t, 0.1, 1.0]) + rng.normal(0, 1e-3, 3) for t in times]
    track.predict(times[0])
    track.step(zs[0], R)
    kf = constant_velocity(3, 1.0, 3.0, 1.0)
    kf.x[:3] = zs[0]
    kf.P = np.zeros((6, 6))
    kf.P[:3, :3] = R
    kf.P[3:, 3:] = np.eye(3)
    for k in range(1, 30):
        dt = times[k] - times[k - 1]
        track.predict(times[k])
        s = track.step(zs[k], R)
        m = constant_velocity(3, dt, 3.0, 1.0)
        kf.predict(A=m.A, Q=m.Q)
        kf.update(zs[k], R=R)
        np.testing.assert_allclose(s.position, kf.x[:3], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(s.covariance, kf.P[:3, :3], rtol=1e-10, atol=1e-18)


def test_measurement_scale_is_the_covariance_scaled_in_gate_and_update():
    # measurement_scale s with R runs exactly as s = 1 with s R: the same positions,
    # covariances, gate distances and statuses (the far measurement is gated by both)
    rng = np.random.default_rng(1)
    zs = [np.array([0.3 * k / 30, 0.1, 1.0]) + rng.normal(0, 2e-3, 3) for k in range(20)]
    zs[12] = zs[12] + 0.5
    a = GatedTrack(GatedTrackConfig(measurement_scale=0.25, smoothing_lag=2))
    b = GatedTrack(GatedTrackConfig(measurement_scale=1.0, smoothing_lag=2))
    statuses = []
    for k, z in enumerate(zs):
        a.predict(k / 30)
        b.predict(k / 30)
        sa, sb = a.step(z, R * 4), b.step(z, R)
        statuses.append(str(sa.status))
        assert sa.status is sb.status
        np.testing.assert_allclose(sa.position, sb.position, rtol=1e-12)
        np.testing.assert_allclose(sa.covariance, sb.covariance, rtol=1e-10)
        np.testing.assert_allclose(sa.lagged, sb.lagged, rtol=1e-12)
        np.testing.assert_allclose(sa.mahalanobis2, sb.mahalanobis2, rtol=1e-10)
    assert statuses[12] == "gated" and statuses.count("tracking") == 18
    # and a smaller scale leans on each measurement: the estimate moves closer to it
    c = GatedTrack(GatedTrackConfig(measurement_scale=1.0, smoothing_lag=0))
    d = GatedTrack(GatedTrackConfig(measurement_scale=0.1, smoothing_lag=0))
    for k, z in enumerate(zs[:12]):
        c.predict(k / 30)
        d.predict(k / 30)
        sc, sd = c.step(z, R * 100), d.step(z, R * 100)
    assert np.linalg.norm(sd.position - zs[11]) < np.linalg.norm(sc.position - zs[11])


def test_lagged_model_shifts_the_positions():
    m = constant_velocity(2, 0.1, 1.0, 1.0)
    A, Q = lagged_model(m.A, m.Q, 2, 2)
    assert A.shape == Q.shape == (8, 8)
    x = np.array([1.0, 2.0, 10.0, 20.0, 7, 7, 8, 8])
    y = A @ x
    np.testing.assert_allclose(y[:4], m.A @ x[:4])
    np.testing.assert_allclose(y[4:6], [1.0, 2.0])  # p_{t-1} <- p_t
    np.testing.assert_allclose(y[6:8], [7.0, 7.0])  # p_{t-2} <- p_{t-1}
    assert np.all(Q[4:, :] == 0) and np.all(Q[:, 4:] == 0)
    assert lagged_model(m.A, m.Q, 2, 0)[0] is m.A


def test_smoothing_beats_filtering_on_a_noisy_manoeuvre():
    rng = np.random.default_rng(3)
    t = np.arange(200) / 30.0
    truth = np.column_stack([np.sin(2 * t), 0.3 * np.cos(3 * t), 1.5 + 0.2 * np.sin(t)])
    zs = truth + rng.normal(0, 3e-3, truth.shape)
    errs = {}
    for lag in (0, 2):
        track = GatedTrack(GatedTrackConfig(smoothing_lag=lag))
        est = np.full_like(truth, np.nan)
        for k in range(200):
            track.predict(t[k])
            s = track.step(zs[k], np.eye(3) * 9e-6)
            est[k] = s.position
            if lag and k >= lag:
                est[k - lag] = s.lagged[lag - 1]
        e = np.linalg.norm(est[5:-5] - truth[5:-5], axis=1)
        errs[lag] = float(np.median(e))
    raw = float(np.median(np.linalg.norm(zs[5:-5] - truth[5:-5], axis=1)))
    assert errs[0] < raw and errs[2] < errs[0]


def test_time_going_back_drops_the_track_and_bad_input():
    track = GatedTrack()
    track.predict(1.0)
    track.step(np.ones(3), R)
    assert track.predict(0.5) is None and not track.active
    with pytest.raises(InputError, match="3 values"):
        track.step(np.ones(2), R)
    with pytest.raises(InputError, match="process_noise"):
        GatedTrackConfig(process_noise=())
    with pytest.raises(InputError, match="smoothing_lag"):
        GatedTrackConfig(smoothing_lag=31)
    with pytest.raises(InputError, match="switch_probability"):
        GatedTrackConfig(switch_probability=1.0)


# issue 25: config, dim, the step's arguments and lagged_model's sizes were not checked
# (AttributeError on a float config, OverflowError on dim=inf, broadcasting errors)
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: GatedTrack(np.nan), "config must be a GatedTrackConfig"),
        (lambda: GatedTrack(np.eye(3)), "config must be a GatedTrackConfig"),
        (lambda: GatedTrack(dim=np.inf), "dim must be an integer"),
        (lambda: GatedTrack(dim=2**40), "dim must be <= 4096"),
        (lambda: GatedTrackConfig(process_noise="abc"), "process_noise must hold real"),
        (lambda: GatedTrackConfig(process_noise=(1.0,) * 17), "process_noise needs 1 to 16"),
        (lambda: GatedTrackConfig(switch_probability=[1, 2]), "switch_probability must be a real"),
        (lambda: GatedTrackConfig(max_coast=np.nan), "max_coast must be an integer"),
        (lambda: GatedTrackConfig(smoothing_lag=1.5), "smoothing_lag must be an integer"),
        (lambda: GatedTrackConfig(initial_velocity_std=1e300), "initial_velocity_std must be"),
        (
            lambda: GatedTrackConfig(measurement_scale=0.0),
            r"measurement_scale must be in \(0, 1e\+06\]",
        ),
        (lambda: GatedTrackConfig(measurement_scale=np.inf), "measurement_scale must be"),
        (lambda: GatedTrack(dim=2).step([0.0, 0.0], np.eye(2), support=None), "support must"),
        (lambda: GatedTrack(dim=2).step([0.0, 0.0], np.eye(2), dominant="yes"), "dominant must"),
        (lambda: GatedTrack(dim=2).step([0.0, 0.0], np.ones((3, 2))), "R must be the \\(2, 2\\)"),
        (lambda: GatedTrack(dim=2).step([0.0, 1e300], np.eye(2)), "z has values up to"),
        (lambda: GatedTrack(dim=2).predict("soon"), "t must be a real number"),
        (lambda: lagged_model(np.eye(4), np.eye(4), 3.3e16, 1), "k must be an integer"),
        (lambda: lagged_model(np.eye(4), np.eye(4), -1, 1), "k must be >= 1"),
        (lambda: lagged_model(np.eye(4), np.eye(4), 2, -1), "lag must be >= 0"),
        (lambda: lagged_model(np.eye(4), np.eye(4), 2, 2**40), "lag must be <= 2046"),
        (lambda: lagged_model(np.eye(2), np.zeros((0, 2)), 1, 1), "A and Q must be finite"),
        (lambda: lagged_model(np.eye(2), np.eye(2), None, 1), "k must be an integer"),
    ],
)
def test_hostile_arguments_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_lagged_model_edge_values_still_work():
    # issue 25: lag 0 keeps the model; the largest lag within the size bound builds it
    A, Q = np.eye(4), np.eye(4) * 2.0
    same = lagged_model(A, Q, 2, 0)
    assert same[0] is A and same[1] is Q
    a, q = lagged_model(A, Q, 2, 3)
    assert a.shape == q.shape == (10, 10)
    np.testing.assert_array_equal(a[4:6, :2], np.eye(2))  # p_{t-1} <- p_t
    assert q[4:, :].sum() == 0.0


def test_recorded_intervals_reuse_their_models_and_give_the_same_track(monkeypatch):
    # timestamps written to the microsecond (a TUM folder) make the interval flicker
    # between a few floats (0.033333, 0.033334, ...): the bank's models are kept per
    # interval, not rebuilt on every flicker, and the track is the one rebuilding gives
    import robopercept.tracking.gated as gated

    times = np.array([float(f"{i / 30:.6f}") for i in range(300)])
    assert 2 < len(np.unique(np.diff(times))) < 30  # a few distinct intervals
    rng = np.random.default_rng(3)
    zs = [np.array([0.2 * np.sin(t), 0.1, 1.0 + 0.1 * t]) + rng.normal(0, 1e-3, 3) for t in times]

    def run() -> tuple[list[np.ndarray], gated.GatedTrack]:
        track = gated.GatedTrack(GatedTrackConfig(smoothing_lag=2), dim=3)
        out = []
        for t, z in zip(times, zs, strict=True):
            track.predict(t)
            out.append(track.step(z, R).position)
        return out, track

    kept, track = run()
    models = track._filter._models  # the cache under test
    assert len(models) == len(np.unique(np.diff(times)))  # one entry per interval
    assert all(not a.flags.writeable for pair in next(iter(models.values())) for a in pair)
    monkeypatch.setattr(gated, "_MODEL_CACHE", 0)  # every change of interval rebuilds
    rebuilt, _ = run()
    for a, b in zip(kept, rebuilt, strict=True):
        np.testing.assert_array_equal(a, b)
