"""Kalman filters: hand-computed steps, filterpy parity step by step, gating, builders."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import ExtendedKalmanFilter as FpEKF
from filterpy.kalman import KalmanFilter as FpKF
from scipy.stats import chi2

from robopercept.errors import DegenerateError, InputError
from robopercept.tracking import (
    ExtendedKalmanFilter,
    KalmanFilter,
    constant_acceleration,
    constant_position,
    constant_velocity,
    kf_predict,
    kf_update,
    rts_smooth,
)
from robopercept.tracking.kalman import kinematic_matrices, mahalanobis_logdet


def test_scalar_hand_case():
    # x0 = 0, P0 = 1, A = 1, Q = 1 -> P- = 2; z = 1, R = 2: S = 4, K = 0.5,
    # x = 0.5, P = (1 - 0.5)^2 2 + 0.25 2 = 1 (Joseph) = (1 - 0.5) 2 (simple)
    for joseph in (True, False):
        kf = KalmanFilter(1, 1, x=[0.0], P=1.0, A=1.0, Q=1.0, H=[[1.0]], R=2.0, joseph=joseph)
        _, P = kf.predict()
        assert P[0, 0] == 2.0
        res = kf.update([1.0])
        assert res.K[0, 0] == 0.5 and res.S[0, 0] == 4.0 and res.y[0] == 1.0
        assert kf.x[0] == 0.5 and np.isclose(kf.P[0, 0], 1.0)
        assert np.isclose(res.mahalanobis2, 0.25)


def test_matches_filterpy_step_by_step():
    rng = np.random.default_rng(0)
    dt = 0.1
    ours = constant_velocity(dim=2, dt=dt, q=0.5, r=0.04)
    ref = FpKF(dim_x=4, dim_z=2)
    # filterpy with the same model in our state order [px, py, vx, vy]
    ref.F = ours.A.copy()
    ref.Q = ours.Q.copy()
    ref.H = ours.H.copy()
    ref.R = ours.R.copy()
    ref.P = ours.P.copy()
    ref.x = ours.x.reshape(-1, 1).copy()
    truth = np.zeros(4)
    truth[2:] = [1.0, -0.5]
    for k in range(200):
        truth = ours.A @ truth
        z = truth[:2] + rng.normal(0, 0.2, 2)
        ours.predict()
        ref.predict()
        np.testing.assert_allclose(ours.x, ref.x.ravel(), rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.P, ref.P, rtol=0, atol=1e-9)
        if k % 7 == 3:  # missed detections: predict only
            continue
        ours.update(z)
        ref.update(z)
        np.testing.assert_allclose(ours.x, ref.x.ravel(), rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.P, ref.P, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.K, ref.K, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.S, ref.S, rtol=0, atol=1e-9)
    # the filter actually tracks: velocity estimate near the truth
    np.testing.assert_allclose(ours.x[2:], [1.0, -0.5], atol=0.2)


def test_builders_match_filterpy_noise_and_shapes():
    kf = constant_velocity(dim=1, dt=0.5, q=2.0, r=1.0)
    np.testing.assert_allclose(kf.Q, Q_discrete_white_noise(2, dt=0.5, var=2.0))
    np.testing.assert_allclose(kf.A, [[1, 0.5], [0, 1]])
    ca = constant_acceleration(dim=3, dt=0.1, q=1.0, r=1.0)
    assert ca.A.shape == (9, 9) and ca.H.shape == (3, 9)
    np.testing.assert_allclose(ca.A[:3, 6:], 0.005 * np.eye(3))
    np.testing.assert_allclose(
        ca.Q[::3, ::3], Q_discrete_white_noise(3, dt=0.1, var=1.0), rtol=1e-12
    )
    cp = constant_position(dim=2, dt=0.1, q=3.0, r=1.0)
    np.testing.assert_allclose(cp.Q, 0.3 * np.eye(2))


def test_overrides_control_and_pure_functions():
    kf = KalmanFilter(2, 1, dim_u=1, A=np.eye(2), B=[[1.0], [0.0]], H=[[1.0, 0.0]], Q=0.0)
    kf.predict(u=[2.0])
    assert kf.x.tolist() == [2.0, 0.0]
    kf.predict(A=[[1.0, 1.0], [0.0, 1.0]], Q=0.0)  # a one-off transition
    assert kf.x.tolist() == [2.0, 0.0]
    before = kf.P.copy()
    kf.update([2.0], R=1e12)  # a nearly useless measurement barely changes P
    np.testing.assert_allclose(kf.P, before, rtol=1e-9)
    x, P = kf_predict(np.ones(2), np.eye(2), np.eye(2), np.eye(2))
    assert P[0, 0] == 2.0
    res = kf_update(x, P, np.array([3.0]), np.array([[1.0, 0.0]]), np.eye(1))
    assert np.isclose(res.x[0], 1 + 2 / 3 * 2)


def test_gate_uses_the_chi_square_quantile():
    kf = KalmanFilter(2, 2, H=np.eye(2), P=np.zeros((2, 2)), R=np.eye(2))
    limit = np.sqrt(chi2.ppf(0.99, 2))
    assert kf.gate([0.99 * limit, 0.0]) and not kf.gate([1.01 * limit, 0.0])
    assert np.isclose(kf.mahalanobis([3.0, 4.0]), 5.0)
    y, S = kf.innovation([1.0, 2.0])
    assert y.tolist() == [1.0, 2.0] and np.allclose(S, np.eye(2))


def test_ekf_matches_filterpy_range_bearing():
    # a target moving at constant velocity, measured in range and bearing from the origin
    dt = 0.1
    A = np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def h(x):
        return np.array([np.hypot(x[0], x[1]), np.arctan2(x[1], x[0])])

    def H_jac(x):
        r2 = x[0] ** 2 + x[1] ** 2
        r = np.sqrt(r2)
        return np.array([[x[0] / r, x[1] / r, 0, 0], [-x[1] / r2, x[0] / r2, 0, 0]])

    x0 = np.array([10.0, 5.0, 1.0, 0.5])
    R = np.diag([0.1, 0.01])
    Q = 0.01 * np.eye(4)
    ours = ExtendedKalmanFilter(
        4, 2, h=h, H_jacobian=H_jac, f=lambda x, u: A @ x, F_jacobian=lambda x, u: A,
        x=x0, P=np.eye(4), Q=Q, R=R,
    )  # fmt: skip
    ref = FpEKF(4, 2)
    ref.x = x0.reshape(-1, 1).copy()
    ref.F, ref.P, ref.Q, ref.R = A, np.eye(4), Q, R
    rng = np.random.default_rng(1)
    truth = x0.copy()
    for _ in range(100):
        truth = A @ truth
        z = h(truth) + rng.normal(0, [0.3, 0.1])
        ours.predict()
        ref.predict()
        ours.update(z)
        ref.update(
            z.reshape(-1, 1), lambda x: H_jac(x.ravel()), lambda x: h(x.ravel()).reshape(-1, 1)
        )
        np.testing.assert_allclose(ours.x, ref.x.ravel(), atol=1e-9)
        np.testing.assert_allclose(ours.P, ref.P, atol=1e-9)


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: KalmanFilter(2, 1, A=np.eye(3)), InputError, "A must have shape"),
        (lambda: KalmanFilter(2, 1, x=[1, 2, 3]), InputError, "x must have 2"),
        (lambda: KalmanFilter(2, 1, A=np.eye(2), F=np.eye(2)), InputError, "not both"),
        (lambda: KalmanFilter(0, 1), InputError, "dim_x"),
        (lambda: KalmanFilter(2, 1).predict(u=[1.0]), InputError, "no control"),
        (lambda: KalmanFilter(2, 1).update([1.0, 2.0]), InputError, "z must have 1"),
        (lambda: KalmanFilter(2, 1).update([np.nan]), InputError, "finite"),
        (
            lambda: KalmanFilter(1, 1, H=[[0.0]], R=0.0).update([1.0]),
            DegenerateError,
            "positive definite",
        ),
        (lambda: constant_velocity(2, 0.0, 1.0, 1.0), InputError, "dt"),
        (lambda: KalmanFilter(1, 1).gate([0.0], probability=1.0), InputError, "probability"),
    ],
)
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


# issue 25: matrices and measurements near 1e300 overflowed S and the Mahalanobis
# distance (inf, a silent gate decision); they are refused by name with the fix
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: KalmanFilter(2, 2, P=1e300, H=np.eye(2)), "P has values up to 1e\\+300"),
        (lambda: KalmanFilter(2, 2, H=np.eye(2), R=np.eye(2) * 1e200), "R has values up to"),
        (lambda: KalmanFilter(2, 2, H=np.eye(2)).mahalanobis([1e300, 0.0]), "z has values"),
        (lambda: KalmanFilter(2, 2, H=np.eye(2)).update([1e300, 0.0]), "z has values"),
        (lambda: KalmanFilter(2, 2, H=np.eye(2)).predict(Q=1e300), "Q has values"),
    ],
)
def test_values_whose_squares_overflow_are_refused(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_tiny_covariances_stay_exact():
    # 1e-300 covariances: the gain is a ratio of them, so the update is exact
    kf = KalmanFilter(2, 2, P=1e-300, H=np.eye(2), R=1e-300, Q=1e-300)
    kf.predict()
    kf.update([1.0, 1.0])
    np.testing.assert_allclose(kf.x, [2 / 3, 2 / 3], rtol=1e-12)
    assert np.isfinite(kf.P).all()


# issue 25: sizes, scalar parameters and the pure steps' arrays were not checked: a
# dim_z of 1e9 asked for EiB, the pure functions raised NumPy's broadcasting errors,
# strings reached float() and any object passed as a flag or a callback
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: KalmanFilter(2**40, 1), "dim_x must be <= 4096"),
        (lambda: KalmanFilter(2, 1.5), "dim_z must be an integer"),
        (lambda: KalmanFilter(2, 1, A="abc"), "A must hold real numbers"),
        (lambda: KalmanFilter(2, 1, x=[1 + 1j, 0]), "x must hold real numbers"),
        (lambda: KalmanFilter(2, 1, P=[[1, 0], [0]]), "P must be a numeric array"),
        (lambda: KalmanFilter(2, 1, joseph=np.eye(2)), "joseph must be True or False"),
        (
            lambda: ExtendedKalmanFilter(1059262574, 1, h=np.sin, H_jacobian=np.cos),
            "dim_x must be <= 4096",
        ),
        (
            lambda: ExtendedKalmanFilter(2, 2**63, h=np.sin, H_jacobian=np.cos),
            "dim_z must be <= 4096",
        ),
        (lambda: ExtendedKalmanFilter(2, 1, h=3, H_jacobian=np.cos), "h must be a function"),
        (lambda: ExtendedKalmanFilter(2, 1, h=None, H_jacobian=None), "h and H_jacobian"),
        (lambda: kf_predict(np.zeros(2), np.eye(2), np.eye(2), np.zeros((0, 2))), "Q must"),
        (lambda: kf_predict(np.zeros(1), np.eye(2), np.eye(2), np.eye(2)), "P must have shape"),
        (lambda: kf_update(np.zeros(2), np.eye(2), np.zeros(0), np.eye(2), np.eye(2)), ">= 1"),
        (
            lambda: kf_update(np.zeros(2), np.eye(2), [1.0], np.ones((1, 2)), np.zeros((0, 1))),
            "R must have shape",
        ),
        (
            lambda: kf_update(np.zeros(3), np.eye(2), [1.0], np.ones((1, 2)), 1.0),
            "P must have shape \\(3, 3\\)",
        ),
        (
            lambda: kf_update(np.zeros(2), np.eye(2), [1.0], np.ones((1, 2)), 1.0, joseph="no"),
            "joseph must be True or False",
        ),
        (lambda: constant_velocity(2**40, 1.0, 1.0, 1.0), "dim must be <= 4096"),
        (lambda: constant_acceleration(2000, 1.0, 1.0, 1.0), "dim must be <= 1365"),
        (lambda: constant_velocity(2, 1e300, 1.0, 1.0), "dt must be in"),
        (lambda: constant_velocity(2, 1.0, "3", 1.0), "q must be a real number"),
        (lambda: constant_position(2, 1.0, 1.0, np.nan), "r must be finite"),
        (lambda: KalmanFilter(1, 1).gate([0.0], probability="0.5"), "probability must be a real"),
    ],
)
def test_bad_sizes_scalars_and_arrays_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_pure_steps_accept_scalars_and_agree_with_the_filter():
    # issue 25: the checked pure steps still take scalar covariances (multiples of I),
    # and tiny positive dt / noise give finite, exact results (no NaN)
    x, P = kf_predict([1.0, 2.0], 2.0, np.eye(2), 0.5)
    np.testing.assert_allclose(P, 2.5 * np.eye(2))
    res = kf_update(x, P, [3.0], [[1.0, 0.0]], 2.5)
    np.testing.assert_allclose(res.x, [2.0, 2.0])  # equal variances: the mean of 1 and 3
    kf = constant_velocity(1, 1e-162, 1.0, 1e-300)
    kf.predict()
    kf.update([1.0])
    assert np.isfinite(kf.x).all() and np.isfinite(kf.P).all()


def test_an_overflowed_covariance_is_a_degenerate_error_not_nan():
    # LAPACK's potrf is called without scipy's finiteness scan (issue 49: the scan cost
    # more than the 3x3 factorization): a covariance grown past float64 over many steps
    # must still stop with a typed error, not factor into NaN
    kf = KalmanFilter(1, 1, A=np.array([[1e100]]), Q=0.0, H=np.array([[1.0]]), R=1.0)
    with np.errstate(over="ignore"):
        for _ in range(4):
            kf.predict()
    assert not np.isfinite(kf.P).all()
    with pytest.raises(DegenerateError, match="finite and positive definite"):
        kf.update(np.array([0.0]))
    with pytest.raises(DegenerateError, match="finite and positive definite"):
        mahalanobis_logdet(np.array([[np.inf]]), np.array([1.0]))
    with pytest.raises(DegenerateError, match="finite and positive definite"):
        mahalanobis_logdet(np.array([[1.0, 2.0], [2.0, 1.0]]), np.array([1.0, 1.0]))
    # and the factorization is scipy's, to the last bit
    from scipy.linalg import cho_factor, cho_solve

    S = np.array([[2.0, 0.3, 0.1], [0.3, 1.5, 0.2], [0.1, 0.2, 1.0]])
    y = np.array([1.0, -2.0, 0.5])
    d2, logdet = mahalanobis_logdet(S, y)
    c = cho_factor(S)
    assert d2 == float(y @ cho_solve(c, y))
    assert logdet == 2.0 * float(np.log(np.diag(c[0])).sum())


def _filtered_track(seed, steps=40, missing=()):
    # a constant-velocity track in 2-D filtered by filterpy, with some steps unmeasured
    rng = np.random.default_rng(seed)
    fp = FpKF(dim_x=4, dim_z=2)
    dt = 1 / 30
    fp.F = constant_velocity(2, dt, 1.0, 1.0).A
    fp.Q = constant_velocity(2, dt, 50.0, 1.0).Q
    fp.H = np.hstack([np.eye(2), np.zeros((2, 2))])
    fp.R = np.eye(2) * 1e-4
    fp.P = np.eye(4)
    truth = np.cumsum(rng.normal(0, 0.01, (steps, 2)), axis=0)
    xs, Ps = [], []
    for k in range(steps):
        fp.predict()
        if k not in missing:
            fp.update(truth[k] + rng.normal(0, 1e-2, 2))
        xs.append(fp.x.ravel().copy())
        Ps.append(fp.P.copy())
    Fs = np.repeat(fp.F[None], steps, axis=0)
    Qs = np.repeat(fp.Q[None], steps, axis=0)
    return fp, np.array(xs), np.array(Ps), Fs, Qs, truth


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_rts_smooth_matches_filterpy(seed):
    # filterpy's rts_smoother inverts the predicted covariance where rts_smooth solves:
    # the same smoother, equal to rounding (1e-9 relative on states of 1e-2)
    fp, xs, Ps, Fs, Qs, _ = _filtered_track(seed, missing=(5, 6, 7))
    ref_x, ref_P, _, _ = fp.rts_smoother(xs, Ps, Fs, Qs)
    x, P = rts_smooth(xs, Ps, Fs, Qs)
    np.testing.assert_allclose(x, ref_x, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(P, ref_P, rtol=1e-9, atol=1e-15)


def test_rts_smooth_properties():
    _, xs, Ps, Fs, Qs, truth = _filtered_track(3, steps=200)
    x, P = rts_smooth(xs, Ps, Fs, Qs)
    # the last step has no later measurement: it stays the filter's
    assert np.array_equal(x[-1], xs[-1]) and np.array_equal(P[-1], Ps[-1])
    # more information: every smoothed variance is at most the filtered one
    assert (np.diagonal(P, axis1=1, axis2=2) <= np.diagonal(Ps, axis1=1, axis2=2) + 1e-18).all()
    # and the smoothed positions are closer to the truth than the filtered ones (mean
    # error ratio 0.78 to 0.90 over seeds 0-29 of this track)
    err_s = np.linalg.norm(x[:, :2] - truth, axis=1).mean()
    err_f = np.linalg.norm(xs[:, :2] - truth, axis=1).mean()
    assert err_s < 0.95 * err_f
    # one step: nothing to smooth
    x1, P1 = rts_smooth(xs[:1], Ps[:1], Fs[:1], Qs[:1])
    assert np.array_equal(x1, xs[:1]) and np.array_equal(P1, Ps[:1])


@pytest.mark.parametrize(
    "args, exc, match",
    [
        (
            (np.zeros(3), np.zeros((3, 1, 1)), np.zeros((3, 1, 1)), np.zeros((3, 1, 1))),
            InputError,
            "xs must be",
        ),
        (
            (np.zeros((3, 2)), np.zeros((2, 2, 2)), np.zeros((3, 2, 2)), np.zeros((3, 2, 2))),
            InputError,
            "Ps must have shape",
        ),
        (
            (np.full((2, 1), np.nan), np.ones((2, 1, 1)), np.ones((2, 1, 1)), np.ones((2, 1, 1))),
            InputError,
            "xs must be finite",
        ),
        (
            (np.zeros((2, 1)), np.zeros((2, 1, 1)), np.ones((2, 1, 1)), np.zeros((2, 1, 1))),
            DegenerateError,
            "singular",
        ),
    ],
)
def test_rts_smooth_bad_input(args, exc, match):
    with pytest.raises(exc, match=match):
        rts_smooth(*args)


def test_kinematic_matrices_are_the_models_own_and_filterpys():
    # the A and Q a running filter is given when its interval changes (GatedTrack): the
    # arrays the model constructors build, bit for bit, and filterpy's white-noise Q
    from robopercept.tracking import constant_acceleration, constant_position

    builders = {0: constant_position, 1: constant_velocity, 2: constant_acceleration}
    for order, build in builders.items():
        for dim, dt, q in ((1, 0.5, 4.0), (3, 1 / 30, 500.0), (2, 0.033334, 0.0), (4, 7.0, 1e-3)):
            A, Q = kinematic_matrices(order, dim, dt, q)
            kf = build(dim, dt, q, 1.0)
            assert A.shape == Q.shape == ((order + 1) * dim,) * 2
            np.testing.assert_array_equal(A, kf.A)
            np.testing.assert_array_equal(Q, kf.Q)
    # one dimension: filterpy's Q_discrete_white_noise (dt 0.1, variance 2)
    _, Q = kinematic_matrices(1, 1, 0.1, 2.0)
    np.testing.assert_allclose(Q, Q_discrete_white_noise(2, dt=0.1, var=2.0), rtol=1e-15)
    _, Q = kinematic_matrices(2, 1, 0.1, 2.0)
    np.testing.assert_allclose(Q, Q_discrete_white_noise(3, dt=0.1, var=2.0), rtol=1e-15)
    # the hand case: A = [[1, dt], [0, 1]], Q = q [dt^4/4, dt^3/2; dt^3/2, dt^2]
    A, Q = kinematic_matrices(1, 1, 0.5, 4.0)
    assert A.tolist() == [[1.0, 0.5], [0.0, 1.0]]
    assert Q.tolist() == [[0.0625, 0.25], [0.25, 1.0]]
    for call, match in (
        (lambda: kinematic_matrices(3, 1, 1.0, 1.0), "order must be 0, 1 or 2"),
        (lambda: kinematic_matrices(1, 1, 0.0, 1.0), "dt"),
        (lambda: kinematic_matrices(1, 1, 1.0, -1.0), "q"),
        (lambda: kinematic_matrices(1, 0, 1.0, 1.0), "dim"),
    ):
        with pytest.raises(InputError, match=match):
            call()
