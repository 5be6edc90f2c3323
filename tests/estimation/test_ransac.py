"""The RANSAC engine and its models: synthetic ground truth, OpenCV parity, determinism."""

from __future__ import annotations

import threading

import cv2
import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import (
    AffineModel,
    HomographyModel,
    LineModel,
    Plane,
    PlaneModel,
    find_homography,
    ransac,
    required_iterations,
)


def plane_data(rng, n=5000, outlier_ratio=0.7, noise=0.002):
    """Inliers on a known plane (Gaussian noise along the normal) and uniform outliers."""
    true = Plane.from_equation([0.3, -0.5, 1.0, -0.4])
    m = round(n * (1 - outlier_ratio))
    inl = true.project(rng.uniform(-1, 1, (m, 3))) + rng.normal(0, noise, (m, 1)) * true.normal
    out = rng.uniform(-1, 1, (n - m, 3))
    pts = np.vstack([inl, out])
    # ground truth inliers: the generated ones (outliers inside the band are rare)
    truth = np.r_[np.ones(m, bool), np.zeros(n - m, bool)]
    return pts, truth, true


def f1(a, b):
    return 2 * np.count_nonzero(a & b) / (np.count_nonzero(a) + np.count_nonzero(b))


@pytest.mark.parametrize("scoring", ["ransac", "msac"])
@pytest.mark.parametrize("lo", [False, True])
def test_plane_with_70_percent_outliers(rng, scoring, lo):
    pts, truth, true = plane_data(rng)
    res = ransac(pts, PlaneModel(), 0.008, scoring=scoring, local_optimization=lo, rng=7)
    assert np.degrees(res.model.angle_to(true)) < 0.5
    assert f1(res.inliers, truth) >= 0.99
    # adaptive stopping: far fewer than max_iterations for w = 0.3, n = 3
    assert res.n_iterations <= 3 * required_iterations(0.3, 3, 0.99)


def test_required_iterations_formula():
    # log(1 - p) / log(1 - w^n), hand-computed: w = 0.5, n = 3, p = 0.99 -> 34.5
    assert np.isclose(required_iterations(0.5, 3, 0.99), np.log(0.01) / np.log(1 - 0.125))
    assert required_iterations(1.0, 3, 0.99) == 0.0
    assert required_iterations(0.0, 3, 0.99) == np.inf


def test_line_and_min_inliers_stop(rng):
    t = rng.uniform(-1, 1, 200)
    pts = np.column_stack([t, -0.5 * t + 0.2])
    out = rng.uniform(-1, 1, (400, 2))
    # outliers clear of the line (distance > 0.05), so the inliers are exactly the line's
    far = np.abs(0.5 * out[:, 0] + out[:, 1] - 0.2) / np.hypot(0.5, 1.0) > 0.05
    pts[:60] = out[far][:60]
    res = ransac(pts, LineModel(), 0.01, rng=0)
    a, b, c = res.model.coefficients
    np.testing.assert_allclose([-a / b, -c / b], [-0.5, 0.2], atol=1e-9)
    assert res.inliers[60:].all()
    early = ransac(pts, LineModel(), 0.01, rng=0, min_inliers=100, batch_size=1)
    assert early.n_iterations <= res.n_iterations


def test_homography_matches_opencv(rng):
    h_true = np.array([[0.9, 0.1, 20.0], [-0.05, 1.1, -10.0], [2e-4, -1e-4, 1.0]])
    src = rng.uniform(0, 640, (300, 2))
    d = np.c_[src, np.ones(300)] @ h_true.T
    dst = d[:, :2] / d[:, 2:] + rng.normal(0, 0.3, (300, 2))
    dst[:120] = rng.uniform(0, 640, (120, 2))  # 40% outliers
    res = ransac(np.c_[src, dst], HomographyModel(), 2.0, rng=1)
    h_cv, mask = cv2.findHomography(src, dst, cv2.RANSAC, 2.0)
    # the same inliers (up to points near the threshold) and matrices that map the
    # image corners within a pixel of each other (both refit on their inliers)
    agree = np.mean(res.inliers == mask.ravel().astype(bool))
    assert agree > 0.98
    corners = np.array([[0, 0], [640, 0], [640, 640], [0, 640]], float)

    def warp(h):
        q = np.c_[corners, np.ones(4)] @ h.T
        return q[:, :2] / q[:, 2:]

    assert np.abs(warp(res.model) - warp(h_cv)).max() < 1.0
    assert np.abs(warp(res.model) - warp(h_true)).max() < 1.0


def test_affine_matches_opencv(rng):
    a_true = np.array([[1.2, -0.3, 5.0], [0.25, 0.9, -7.0]])
    src = rng.uniform(0, 100, (200, 2))
    dst = src @ a_true[:, :2].T + a_true[:, 2] + rng.normal(0, 0.1, (200, 2))
    dst[:50] += rng.uniform(10, 50, (50, 2))
    res = ransac(np.c_[src, dst], AffineModel(), 0.5, rng=2)
    a_cv, _ = cv2.estimateAffine2D(src, dst, ransacReprojThreshold=0.5)
    np.testing.assert_allclose(res.model[:2], a_true, atol=0.05)
    np.testing.assert_allclose(res.model[:2], a_cv, atol=0.05)
    assert res.inliers[50:].mean() > 0.99 and not res.inliers[:50].any()


def test_seeded_determinism_across_threads(rng):
    pts, _, _ = plane_data(rng, n=20000, outlier_ratio=0.6)
    ref = ransac(pts, PlaneModel(), 0.01, rng=42)
    again = ransac(pts, PlaneModel(), 0.01, rng=np.random.default_rng(42))
    assert np.array_equal(ref.inliers, again.inliers) and np.array_equal(ref.params, again.params)
    results = [None] * 4

    def work(i):
        results[i] = ransac(pts, PlaneModel(), 0.01, rng=42)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        assert np.array_equal(r.inliers, ref.inliers) and np.array_equal(r.params, ref.params)
    other = ransac(pts, PlaneModel(), 0.01, rng=43)
    assert other.n_iterations != ref.n_iterations or not np.array_equal(other.params, ref.params)


def test_degenerate_samples_are_redrawn(rng):
    # half the points are copies of one point: samples with repeats are degenerate
    pts, _truth, true = plane_data(rng, n=2000, outlier_ratio=0.2)
    pts[1000:] = pts[0]
    res = ransac(pts, PlaneModel(), 0.008, rng=3)
    assert np.degrees(res.model.angle_to(true)) < 0.5


def test_minimal_fits_flag_degenerate_samples():
    collinear = np.array([[[0, 0, 0], [1, 1, 1], [2, 2, 2.0]], [[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
    _, valid = PlaneModel().fit_minimal(collinear)
    assert valid.tolist() == [False, True]
    same = np.array([[[1.0, 1.0], [1.0, 1.0]]])
    assert not LineModel().fit_minimal(same)[1][0]
    corr = np.array([[[0, 0, 0, 0], [1, 1, 1, 1], [2, 2, 2, 2], [0, 1, 0, 1.0]]])
    assert not HomographyModel().fit_minimal(corr)[1][0]


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: ransac(np.zeros((2, 3)), PlaneModel(), 0.1), DegenerateError, "only 2"),
        (
            lambda: ransac(np.outer(np.arange(10.0), [1, 2, 3]), PlaneModel(), 0.1),
            DegenerateError,
            "collinear",
        ),
        (lambda: ransac(np.ones((10, 3)), PlaneModel(), 0.1), DegenerateError, "same point"),
        (lambda: ransac(np.ones((10, 2)), PlaneModel(), 0.1), InputError, "shape"),
        (lambda: ransac(np.full((10, 3), np.nan), PlaneModel(), 0.1), InputError, "finite"),
        (lambda: ransac(np.eye(3), PlaneModel(), 0.0), InputError, "threshold"),
        (lambda: ransac(np.eye(3), PlaneModel(), 0.1, probability=1.0), InputError, "probability"),
        (lambda: ransac(np.eye(3), PlaneModel(), 0.1, scoring="lmeds"), InputError, "scoring"),
        (lambda: ransac(np.eye(3), "plane", 0.1), InputError, "Model"),
        (lambda: ransac(np.eye(3), PlaneModel(), 0.1, rng="seed"), InputError, "rng"),
        (lambda: ransac(np.eye(3), PlaneModel(), 0.1, sample_size=2), InputError, "sample_size"),
    ],
)
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_initial_hypothesis_is_scored_first_and_can_end_the_search():
    # a tracker's predicted plane: exact, so it is the best hypothesis and with
    # min_inliers reached no random sample is drawn
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-1, 1, (300, 2)), np.full(300, 2.0)])
    pts = np.vstack([pts, rng.uniform(-1, 3, (100, 3))])
    init = np.array([[0.0, 0.0, 1.0, -2.0]])
    res = ransac(pts, PlaneModel(), 0.01, initial=init, min_inliers=300, rng=0)
    assert res.n_iterations == 1
    assert res.inliers[:300].all()
    # a wrong initial plane does not stop the search, which still finds the plane
    bad = np.array([[1.0, 0.0, 0.0, 5.0]])
    res = ransac(pts, PlaneModel(), 0.01, initial=bad, rng=0)
    assert res.n_iterations > 1 and res.inliers[:300].all()
    with pytest.raises(InputError, match="initial"):
        ransac(pts, PlaneModel(), 0.01, initial=np.array([[np.nan, 0, 1, 0]]))


@pytest.mark.parametrize("msac", [False, True])
def test_plane_scoring_kernel_matches_numpy_on_any_thread_count(rng, msac):
    # the compiled, blocked plane scorer against the generic residual-matrix scorer, on a
    # ragged number of points (3 full blocks of 2048 and a partial one)
    import numba

    from robopercept.estimation.models import Model

    pts, _, _ = plane_data(rng, n=3 * 2048 + 77, outlier_ratio=0.5)
    model = PlaneModel()
    params, valid = model.fit_minimal(pts[rng.integers(0, len(pts), (16, 3))])
    params = params[valid]
    prepared = model.prepare(pts)
    ref_scores, ref_counts = Model.score(model, params, pts, 0.01, msac)
    scores, counts = model.score(params, prepared, 0.01, msac)
    assert np.array_equal(counts, ref_counts) and counts.min() > 0
    # MSAC losses: sums of the same terms in a different order (1e-12 relative)
    np.testing.assert_allclose(scores, ref_scores, rtol=1e-12)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = model.score(params, prepared, 0.01, msac)
    finally:
        numba.set_num_threads(before)
    assert np.array_equal(one[0], scores) and np.array_equal(one[1], counts)
    mask = model.inlier_mask(params[0], prepared, 0.01)
    assert np.array_equal(mask, np.abs(pts @ params[0, :3] + params[0, 3]) < 0.01)


class TestModelProtocol:
    """Every model of the house satisfies the ``Model`` protocol the engine relies on."""

    def models(self):
        from robopercept.geometry.epipolar import EssentialModel, FundamentalModel
        from robopercept.pipelines.plane_tracking import PlaneHueModel

        return [
            LineModel(),
            PlaneModel(),
            AffineModel(),
            HomographyModel(),
            FundamentalModel(),
            EssentialModel(),
            PlaneHueModel(10.0),
        ]

    def test_models_are_instances_of_the_runtime_checkable_protocol(self):
        from robopercept.estimation.models import Model

        for m in self.models():
            assert isinstance(m, Model), type(m).__name__
            assert m.sample_size >= 2 and m.dim >= 2 and m.name
        assert not isinstance(object(), Model)
        assert not isinstance(np.zeros(3), Model)

    def test_a_duck_typed_model_is_accepted_and_a_non_model_refused(self, rng):
        from robopercept.estimation.models import Model

        class Wrapped:  # every protocol member, borrowed; no inheritance
            sample_size, dim, name = 2, 2, "wrapped line"

        for name in ("fit_minimal", "fit", "residuals", "check", "result", "fit_inliers"):
            setattr(Wrapped, name, getattr(LineModel, name))
        for name in ("prepare", "score", "inlier_mask"):
            setattr(Wrapped, name, getattr(Model, name))
        pts = np.c_[np.linspace(0, 1, 50), 0.5 * np.linspace(0, 1, 50) + 0.1]
        assert isinstance(Wrapped(), Model)
        res = ransac(pts, Wrapped(), 1e-6, rng=0)
        assert res.n_inliers == 50
        np.testing.assert_allclose(res.params, ransac(pts, LineModel(), 1e-6, rng=0).params)
        with pytest.raises(InputError, match="Model"):
            ransac(pts, object(), 0.1)  # type: ignore[arg-type]

    def test_score_sign_convention(self, rng):
        # higher is better for both rules: the inlier count, or MINUS the truncated loss
        pts, _, _ = plane_data(rng, n=500)
        t = 0.01
        for scoring in ("ransac", "msac"):
            res = ransac(pts, PlaneModel(), t, scoring=scoring, rng=1)
            r = np.abs(pts @ res.params[:3] + res.params[3])
            if scoring == "ransac":
                assert res.score == res.n_inliers == np.count_nonzero(r < t)
            else:
                np.testing.assert_allclose(res.score, -np.minimum(r**2, t * t).sum(), rtol=1e-9)
                assert res.score <= 0.0
            model = PlaneModel()
            shifted = res.params[None] + [0, 0, 0, 0.05]
            worse, _ = model.score(shifted, model.prepare(pts), t, scoring == "msac")
            assert worse[0] < res.score


# issue 25: while no hypothesis has an inlier (w = 0) the adaptive bound
# log(1 - p) / log(1 - w^n) is infinite; it used to reach math.ceil(inf) (OverflowError)
def test_zero_inlier_hypotheses_keep_max_iterations():
    rng = np.random.default_rng(4)
    noise = rng.uniform(-1, 1, (100, 2))
    # least-squares fits of 5 noisy points pass through none of them within 1e-12
    res = ransac(noise, LineModel(), 1e-12, sample_size=5, max_iterations=40, rng=0)
    assert res.n_iterations == 40 and res.n_inliers == 0
    # a line among outliers: the first samples of 5 mix in outliers (0 inliers at 1e-9);
    # the first all-inlier sample fits the line exactly and the adaptive bound stops
    x = rng.uniform(-1, 1, 60)
    data = np.vstack([np.c_[x, 0.5 * x - 0.2], rng.uniform(-1, 1, (40, 2))])
    res = ransac(data, LineModel(), 1e-9, sample_size=5, batch_size=1, rng=0)
    assert res.inliers[:60].all() and not res.inliers[60:].any()
    assert 1 < res.n_iterations < 1000
    assert required_iterations(0.0, 4, 0.99) == float("inf")


# issue 25: scalar parameters are checked for type and size at the boundary
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_iterations": 10.5}, "max_iterations must be an integer"),
        ({"max_iterations": True}, "max_iterations must be an integer"),
        ({"batch_size": 2**40}, "batch_size must be in"),
        ({"probability": None}, "probability must be a real number"),
        ({"probability": [0.9]}, "probability must be a real number"),
        ({"threshold": float("nan")}, "threshold must be finite"),
        ({"threshold": True}, "threshold must be a real number"),
        ({"min_inliers": None, "sample_size": 3.0}, "sample_size must be an integer"),
        ({"local_optimization": "yes"}, "local_optimization must be True or False"),
    ],
)
def test_scalar_parameters_are_checked(kwargs, match):
    kw = {"threshold": 0.1, **kwargs}
    with pytest.raises(InputError, match=match):
        ransac(np.eye(3), PlaneModel(), **kw)


# issue 25: required_iterations compared complex, None or a string with floats (TypeError)
# and a negative seed reached NumPy's default_rng (ValueError); both are InputErrors
@pytest.mark.parametrize(
    ("args", "match"),
    [
        ((1 + 1j, 3, 0.99), "inlier_ratio must be a real number"),
        ((0.5, 1 + 1j, 0.99), "sample_size must be an integer"),
        ((0.5, 3, None), "probability must be a real number"),
        ((0.5, 3, "3"), "probability must be a real number"),
        ((1.5, 3, 0.99), r"inlier_ratio must be in \[0, 1\]"),
        ((0.5, 0, 0.99), "sample_size must be >= 1"),
    ],
)
def test_issue25_required_iterations_refuses_hostile_arguments(args, match):
    with pytest.raises(InputError, match=match):
        required_iterations(*args)


def test_issue25_negative_seed_is_an_input_error(rng):
    data = np.c_[np.arange(10.0), 2 * np.arange(10.0)]
    with pytest.raises(InputError, match="rng must be an int seed >= 0"):
        ransac(data, LineModel(), 0.1, rng=-1)
    with pytest.raises(InputError, match="rng must be an int seed >= 0"):
        find_homography(rng.uniform(0, 9, (8, 2)), rng.uniform(0, 9, (8, 2)), rng=-17125068)
    assert ransac(data, LineModel(), 0.1, rng=np.int64(7)).n_inliers == 10


def test_issue25_huge_data_is_refused():
    # points near 1e300 overflowed the plane model's scatter matrix (LinAlgError)
    gen = np.random.default_rng(0)
    data = gen.uniform(-1, 1, (500, 3)) * 1e300
    with pytest.raises(InputError, match="data has values up to"):
        ransac(data, PlaneModel(), 1.0)
    with pytest.raises(InputError, match="data has values up to"):
        PlaneModel().fit(data)


def test_issue25_initial_hypotheses_are_checked(rng):
    # a (3, 3) or (0, 3) initial for a plane (4 parameters) indexed past the end or took
    # the argmax of nothing; both are InputErrors, and a right one is still used
    pts, _, true = plane_data(rng, n=500)
    for bad in (np.zeros((3, 3)), np.zeros((0, 4)), [[0, 0, 1, np.nan]], "abcd"):
        with pytest.raises(InputError, match="initial must"):
            ransac(pts, PlaneModel(), 0.01, initial=bad, rng=0)
    res = ransac(pts, PlaneModel(), 0.01, initial=true.equation, min_inliers=100, rng=0)
    assert res.n_iterations == 1 and res.n_inliers > 100
