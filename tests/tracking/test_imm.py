"""IMM estimator: filterpy parity step by step, per-step models, missed detections by the
equations, mode switching on a manoeuvre, accuracy against single filters, bad inputs."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from filterpy.kalman import IMMEstimator as FpIMM
from filterpy.kalman import KalmanFilter as FpKF

from robopercept.errors import InputError
from robopercept.tracking import IMMEstimator, KalmanFilter, constant_velocity

DT = 0.1
R_MEAS = 0.25  # measurement variance (sigma 0.5 m)
M2 = np.array([[0.97, 0.03], [0.05, 0.95]])


def manoeuvring_track(n: int = 200, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Truth positions (n, 2) and noisy measurements (n, 2): straight at 5 m/s for 60
    steps, a coordinated turn of 90 deg/s for 20 steps (180 deg), straight for 60, a
    -90 deg/s turn for 20, straight to the end."""
    rng = np.random.default_rng(seed)
    p, v = np.zeros(2), np.array([5.0, 0.0])
    truth = np.empty((n, 2))
    for k in range(n):
        rate = np.pi / 2 if 60 <= k < 80 else (-np.pi / 2 if 140 <= k < 160 else 0.0)
        c, s = np.cos(rate * DT), np.sin(rate * DT)
        v = np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
        p = p + v * DT
        truth[k] = p
    return truth, truth + rng.normal(0.0, np.sqrt(R_MEAS), (n, 2))


def cv_pair() -> list[KalmanFilter]:
    """Constant velocity, state [px, py, vx, vy]: quiet (q = 0.01) and manoeuvring (q = 50)."""
    return [
        constant_velocity(dim=2, dt=DT, q=0.01, r=R_MEAS),
        constant_velocity(dim=2, dt=DT, q=50.0, r=R_MEAS),
    ]


def cv_and_padded_cp() -> list[KalmanFilter]:
    """Constant velocity and constant position padded to [p, v] (A zeroes v), as in
    filterpy's own IMM example."""
    cv = constant_velocity(dim=2, dt=DT, q=1.0, r=R_MEAS)
    A = np.zeros((4, 4))
    A[:2, :2] = np.eye(2)
    Q = np.zeros((4, 4))
    Q[:2, :2] = 0.5 * np.eye(2)
    cp = KalmanFilter(4, 2, A=A, Q=Q, H=cv.H, R=cv.R, P=np.eye(4))
    return [cv, cp]


def to_filterpy(f: KalmanFilter) -> FpKF:
    ref = FpKF(dim_x=f.dim_x, dim_z=f.dim_z)
    ref.F, ref.Q, ref.H, ref.R = f.A.copy(), f.Q.copy(), f.H.copy(), f.R.copy()
    ref.x, ref.P = f.x.reshape(-1, 1).copy(), f.P.copy()
    return ref


def close(ours: np.ndarray, ref: np.ndarray) -> None:
    # 1e-9 relative: both sides run the same equations in float64; they differ only in
    # summation order, inv(S) vs a Cholesky solve and scipy's logpdf vs our log-det,
    # i.e. ~1e-15 relative per step, and the filters are contractive so it does not
    # grow over the 200 steps. The absolute floor is relative to the array's scale so
    # that components crossing zero (and probabilities near 0) are compared sensibly.
    ref = np.asarray(ref, dtype=np.float64)
    scale = max(1.0, float(np.abs(ref).max()))
    np.testing.assert_allclose(ours, ref, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.parametrize("bank", [cv_pair, cv_and_padded_cp])
def test_matches_filterpy_step_by_step(bank):
    _, z = manoeuvring_track()
    ours = IMMEstimator(bank(), [0.8, 0.2], M2)
    ref = FpIMM([to_filterpy(f) for f in bank()], [0.8, 0.2], M2.copy())
    close(ours.cbar, ref.cbar)
    close(ours.omega, ref.omega)
    for k in range(len(z)):
        ours.predict()
        ref.predict()
        for fo, fr in zip(ours.filters, ref.filters, strict=True):
            close(fo.x, fr.x.ravel())
            close(fo.P, fr.P)
        # filterpy weights its combined prior by the previous mu, we by cbar (textbook)
        xr = sum(c * f.x.ravel() for c, f in zip(ref.cbar, ref.filters, strict=True))
        close(ours.x_prior, xr)
        ours.update(z[k])
        ref.update(z[k])
        close(ours.x, ref.x.ravel())
        close(ours.P, ref.P)
        close(ours.mu, ref.mu)
        close(ours.cbar, ref.cbar)
        close(ours.omega, ref.omega)
        close(ours.likelihood, ref.likelihood)
        close(ours.log_likelihood, [f.log_likelihood for f in ref.filters])


def test_per_step_models_equal_rebuilt_filters():
    rng = np.random.default_rng(1)
    _, z = manoeuvring_track(60)
    a = IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    b = IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    own = [(f.A.copy(), f.Q.copy()) for f in a.filters]
    for k in range(len(z)):
        dt = rng.uniform(0.03, 0.2)  # jittery frame times
        step = [constant_velocity(2, dt, q, R_MEAS) for q in (0.01, 50.0)]
        a.predict(models=[(s.A, s.Q) for s in step])
        for fb, s in zip(b.filters, step, strict=True):  # the same filters rebuilt for this dt
            fb.A, fb.Q = s.A, s.Q
        b.predict()
        a.update(z[k])
        b.update(z[k])
        for name in ("x", "P", "mu", "omega", "likelihood"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    # the override is for one step: the filters' own model is untouched
    for f, (A, Q) in zip(a.filters, own, strict=True):
        np.testing.assert_array_equal(f.A, A)
        np.testing.assert_array_equal(f.Q, Q)
    # a None entry keeps that filter's own model
    c, d = IMMEstimator(cv_pair(), [0.5, 0.5], M2), IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    s = constant_velocity(2, 0.3, 50.0, R_MEAS)
    c.predict(models=[None, (s.A, s.Q)])
    d.filters[1].A, d.filters[1].Q = s.A, s.Q
    d.predict()
    np.testing.assert_array_equal(c.x, d.x)
    np.testing.assert_array_equal(c.filters[0].P, d.filters[0].P)


def scalar_filters() -> list[KalmanFilter]:
    return [
        KalmanFilter(1, 1, x=[0.0], P=1.0, A=1.0, Q=0.1, H=[[1.0]], R=1.0),
        KalmanFilter(1, 1, x=[1.0], P=2.0, A=1.0, Q=2.0, H=[[1.0]], R=1.0),
    ]


def test_skip_by_hand():
    # 1-D, two random walks; mu = [0.7, 0.3], M = [[0.9, 0.1], [0.2, 0.8]],
    # filter 1: x = 0, P = 1, Q = 0.1; filter 2: x = 1, P = 2, Q = 2.
    F = Fraction
    mu = [F(7, 10), F(3, 10)]
    M = [[F(9, 10), F(1, 10)], [F(2, 10), F(8, 10)]]
    xs, Ps, Qs = [F(0), F(1)], [F(1), F(2)], [F(1, 10), F(2)]
    cbar = [mu[0] * M[0][j] + mu[1] * M[1][j] for j in range(2)]  # [0.69, 0.31]
    assert cbar == [F(69, 100), F(31, 100)]
    om = [[M[i][j] * mu[i] / cbar[j] for j in range(2)] for i in range(2)]
    x0 = [om[0][j] * xs[0] + om[1][j] * xs[1] for j in range(2)]  # [2/23, 24/31]
    assert x0 == [F(2, 23), F(24, 31)]
    P0 = [sum(om[i][j] * (Ps[i] + (xs[i] - x0[j]) ** 2) for i in range(2)) for j in range(2)]
    xp, Pp = x0, [P0[j] + Qs[j] for j in range(2)]  # A = 1
    x = sum(cbar[j] * xp[j] for j in range(2))
    P = sum(cbar[j] * (Pp[j] + (xp[j] - x) ** 2) for j in range(2))
    cbar2 = [cbar[0] * M[0][j] + cbar[1] * M[1][j] for j in range(2)]  # [0.683, 0.317]

    imm = IMMEstimator(scalar_filters(), [0.7, 0.3], [[0.9, 0.1], [0.2, 0.8]])
    imm.predict()
    imm.skip()
    f = np.float64
    np.testing.assert_allclose(imm.mu, [f(c) for c in cbar], rtol=1e-15)
    np.testing.assert_allclose(imm.cbar, [f(c) for c in cbar2], rtol=1e-15)
    np.testing.assert_allclose(
        imm.omega,
        [[f(cbar[i] * M[i][j] / cbar2[j]) for j in range(2)] for i in range(2)],
        rtol=1e-14,
    )
    for j in range(2):  # each filter keeps its prediction
        np.testing.assert_allclose(imm.filters[j].x, [f(xp[j])], rtol=1e-14)
        np.testing.assert_allclose(imm.filters[j].P, [[f(Pp[j])]], rtol=1e-14)
    np.testing.assert_allclose(imm.x, [f(x)], rtol=1e-14)
    np.testing.assert_allclose(imm.P, [[f(P)]], rtol=1e-14)
    np.testing.assert_array_equal(imm.x, imm.x_prior)
    np.testing.assert_array_equal(imm.P, imm.P_prior)


def test_skips_follow_the_markov_chain():
    # with no measurements mu_k = mu_0 M^k, which tends to the stationary law of M,
    # pi M = pi: pi = [2/3, 1/3] for M = [[0.9, 0.1], [0.2, 0.8]]
    M = np.array([[0.9, 0.1], [0.2, 0.8]])
    imm = IMMEstimator(scalar_filters(), [0.7, 0.3], M)
    var = [imm.P[0, 0]]
    for k in range(1, 101):
        imm.predict()
        imm.skip()
        var.append(imm.P[0, 0])
        if k == 3:
            np.testing.assert_allclose(imm.mu, [0.7, 0.3] @ np.linalg.matrix_power(M, 3))
    np.testing.assert_allclose(imm.mu, [2 / 3, 1 / 3], rtol=1e-12)
    # and the combined variance grows at every step without measurements
    assert (np.diff(var) > 0).all()


def run_filter(kf: KalmanFilter, z: np.ndarray) -> np.ndarray:
    out = np.empty((len(z), 2))
    for k in range(len(z)):
        kf.predict()
        kf.update(z[k])
        out[k] = kf.x[:2]
    return out


def run_imm(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    imm = IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    est, mu = np.empty((len(z), 2)), np.empty((len(z), 2))
    for k in range(len(z)):
        imm.predict()
        imm.update(z[k])
        est[k], mu[k] = imm.x[:2], imm.mu
    return est, mu


def test_manoeuvre_raises_the_manoeuvring_model():
    _, z = manoeuvring_track()
    _, mu = run_imm(z)
    quiet = mu[30:60, 1]  # straight flight, settled
    turn = mu[65:80, 1]  # inside the first turn, after a few steps of evidence
    after = mu[110:140, 1]  # straight again
    assert turn.mean() > 0.8 > 0.3 > quiet.mean()
    assert turn.mean() > quiet.max()
    assert after.mean() < 0.3  # and it falls back once the target goes straight


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_imm_beats_the_worst_single_filter_and_nears_the_best(seed):
    truth, z = manoeuvring_track(seed=seed)

    def rms(est: np.ndarray, s: slice = slice(10, None)) -> float:
        return float(np.sqrt(np.mean(np.sum((est[s] - truth[s]) ** 2, axis=1))))

    quiet, agile = cv_pair()
    e_quiet, e_agile, e_imm = run_filter(quiet, z), run_filter(agile, z), run_imm(z)[0]
    r_quiet, r_agile, r_imm = rms(e_quiet), rms(e_agile), rms(e_imm)
    assert r_imm < max(r_quiet, r_agile)
    assert r_imm < 1.1 * min(r_quiet, r_agile)  # (seeds 0-5: 0.91-0.95 of the best)
    # segment by segment: smoother than the agile filter in straight flight (where the
    # quiet one is best), and near the agile one in the turn (where the quiet one lags
    # by metres); seeds 0-5: straight 0.67-0.87 of agile, turn 1.0-1.12 of agile
    straight, turn = slice(20, 60), slice(60, 80)
    assert rms(e_imm, straight) < rms(e_agile, straight)
    assert rms(e_imm, turn) < 1.25 * rms(e_agile, turn) < rms(e_quiet, turn) / 4


def test_outlier_does_not_underflow():
    # every likelihood underflows to 0 in float64; in the log domain the wider model
    # (larger S) still explains the outlier better
    imm = IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    imm.predict()
    imm.update([1e6, -1e6])
    assert (imm.likelihood == 0).all()
    assert np.isfinite(imm.mu).all() and np.isclose(imm.mu.sum(), 1.0)
    assert imm.mu[1] > 0.99
    assert np.isfinite(imm.x).all()


def test_gating_and_innovation():
    # M = I: no mixing, so the two modes keep clearly different predictions
    imm = IMMEstimator(cv_pair(), [0.6, 0.4], np.eye(2))
    imm.filters[0].x, imm.filters[0].P = np.array([0.0, 0.0, 5.0, 0.0]), 0.1 * np.eye(4)
    imm.filters[1].x, imm.filters[1].P = np.array([1.0, 1.0, 3.0, 0.0]), 5.0 * np.eye(4)
    imm.predict()
    zk = np.array([2.0, -1.0])  # far from the quiet mode's tight prediction
    per_model = []
    for f in imm.filters:
        y = zk - f.H @ f.x
        S = f.H @ f.P @ f.H.T + f.R
        per_model.append(float(y @ np.linalg.solve(S, y)))
    assert np.isclose(imm.mahalanobis2(zk), min(per_model), rtol=1e-12)
    assert max(per_model) > 2 * min(per_model)  # the minimum is a real choice here
    R2 = 4.0 * np.eye(2)
    assert imm.mahalanobis2(zk, R=R2) < imm.mahalanobis2(zk)
    # shared H and R: the combined innovation is that of the combined prior
    H, R = imm.filters[0].H, imm.filters[0].R
    y, S = imm.innovation(zk)
    np.testing.assert_allclose(y, zk - H @ imm.x_prior, rtol=1e-12)
    np.testing.assert_allclose(S, H @ imm.P_prior @ H.T + R, rtol=1e-12)
    # update's R override reaches every filter
    a, b = IMMEstimator(cv_pair(), [0.5, 0.5], M2), IMMEstimator(cv_pair(), [0.5, 0.5], M2)
    for f in b.filters:
        f.R = R2
    for imm_ in (a, b):
        imm_.predict()
    a.update(zk, R=R2)
    b.update(zk)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.mu, b.mu)


def test_gated_update_is_mahalanobis2_then_update():
    # one pass: the distance returned is mahalanobis2's to the bit, a passing z updates
    # exactly as update does, and a rejected z leaves the predicted estimator untouched
    zk = np.array([2.0, -1.0])
    a, b, c = (IMMEstimator(cv_pair(), [0.5, 0.5], M2) for _ in range(3))
    for imm_ in (a, b, c):
        imm_.filters[1].x = np.array([1.0, 1.0, 3.0, 0.0])
        imm_.predict()
    d2 = a.mahalanobis2(zk)
    a.update(zk)
    assert b.update(zk, gate=d2) == d2
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    np.testing.assert_array_equal(a.mu, b.mu)
    x0, P0, mu0 = c.x.copy(), c.P.copy(), c.mu.copy()
    fx0 = [f.x.copy() for f in c.filters]
    assert c.update(zk, gate=0.5 * d2) == d2
    np.testing.assert_array_equal(c.x, x0)
    np.testing.assert_array_equal(c.P, P0)
    np.testing.assert_array_equal(c.mu, mu0)
    for f, x in zip(c.filters, fx0, strict=True):
        np.testing.assert_array_equal(f.x, x)
    with pytest.raises(InputError, match="gate"):
        c.update(zk, gate=-1.0)


def test_bad_inputs():
    f2 = cv_pair()
    with pytest.raises(InputError, match="at least 2 filters"):
        IMMEstimator(f2[:1], [1.0], [[1.0]])
    with pytest.raises(InputError, match="dim_x and dim_z"):
        IMMEstimator([f2[0], constant_velocity(3, DT, 1.0, R_MEAS)], [0.5, 0.5], M2)
    with pytest.raises(InputError, match="dim_x and dim_z"):
        other_z = KalmanFilter(4, 1, H=np.eye(4)[:1])
        IMMEstimator([f2[0], other_z], [0.5, 0.5], M2)
    with pytest.raises(InputError, match="KalmanFilter"):
        IMMEstimator([f2[0], object()], [0.5, 0.5], M2)  # type: ignore[list-item]
    with pytest.raises(InputError, match=r"probability vector.*mu / mu\.sum"):
        IMMEstimator(f2, [0.5, 0.6], M2)
    with pytest.raises(InputError, match="probability vector"):
        IMMEstimator(f2, [1.2, -0.2], M2)
    with pytest.raises(InputError, match="one probability per filter"):
        IMMEstimator(f2, [0.2, 0.3, 0.5], M2)
    with pytest.raises(InputError, match=r"rows summing to 1.*M\.T"):
        IMMEstimator(f2, [0.5, 0.5], [[0.9, 0.2], [0.1, 0.8]])  # columns sum to 1
    with pytest.raises(InputError, match="non-negative"):
        IMMEstimator(f2, [0.5, 0.5], [[1.1, -0.1], [0.0, 1.0]])
    with pytest.raises(InputError, match=r"\(2, 2\)"):
        IMMEstimator(f2, [0.5, 0.5], np.eye(3))
    imm = IMMEstimator(f2, [0.5, 0.5], M2)
    with pytest.raises(InputError, match="one \\(A, Q\\) or None per filter"):
        imm.predict(models=[None])
    with pytest.raises(InputError, match=r"A must be a finite \(4, 4\)"):
        imm.predict(models=[None, (np.eye(2), np.eye(4))])
    with pytest.raises(InputError, match="must have 2 elements"):
        imm.predict()
        imm.update([1.0, 2.0, 3.0])


# issue 25: filters, probabilities and per-step models of the wrong type raised
# TypeError/ValueError from list() and float()
@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda f: IMMEstimator(None, [0.5, 0.5], np.eye(2)), "filters must be a list"),
        (lambda f: IMMEstimator(3, [0.5, 0.5], np.eye(2)), "filters must be a list"),
        (lambda f: IMMEstimator(f, "ab", np.eye(2)), "mu must hold real numbers"),
        (lambda f: IMMEstimator(f, [0.5, 0.5], [[1, 0], [0]]), "M must be a numeric array"),
        (lambda f: IMMEstimator(f, [0.5, 0.5], np.eye(2)).predict(models=3), "models must"),
        (lambda f: IMMEstimator(f, [0.5, 0.5], np.eye(2)).predict(models=[3, None]), "pair"),
        (lambda f: IMMEstimator(f, [0.5, 0.5], np.eye(2)).update("a"), "z must hold real"),
    ],
)
def test_hostile_arguments_are_refused_by_name(make, match):
    filters = [constant_velocity(1, 1.0, q, 1.0) for q in (0.01, 1.0)]
    with pytest.raises(InputError, match=match):
        make(filters)


def test_filters_changed_between_steps_are_used():
    # the IMM keeps the stacked states of its last step and hands each filter a row of
    # them; a filter whose x or P is reassigned, or changed in place, or whose A is
    # changed in place, between steps must be read afresh, exactly as a fresh IMM would
    z = [np.array([0.1 * k, 0.2 * k]) for k in range(6)]
    runs = []
    for how in ("reference", "reassign", "in place"):
        imm = IMMEstimator(cv_pair(), [0.5, 0.5], M2)
        for k in range(6):
            imm.predict()
            imm.update(z[k])
            if k == 2:
                f = imm.filters[0]
                if how == "reassign":
                    f.x = f.x + 0.05
                    f.P = f.P * 2.0
                    f.A = f.A.copy()
                    f.A[0, 2] *= 1.5
                elif how == "in place":
                    f.x += 0.05
                    f.P *= 2.0
                    f.A[0, 2] *= 1.5
                else:
                    f.x, f.P = f.x.copy() + 0.05, f.P.copy() * 2.0
                    f.A = f.A.copy()
                    f.A[0, 2] *= 1.5
        runs.append((imm.x.copy(), imm.P.copy(), imm.mu.copy()))
    for got in runs[1:]:
        for a, b in zip(got, runs[0], strict=True):
            np.testing.assert_array_equal(a, b)
