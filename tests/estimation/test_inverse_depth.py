"""fit_plane_inverse_depth: parity with numpy's least squares on the same design, the
covariance against Monte Carlo, and the bias it removes against total least squares."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import fit_plane, fit_plane_inverse_depth


def _stereo_plane(rng, n, d, count, sigma_w, size=0.4):
    # points of n.x = d seen along rays (u, v, 1), noise added to inverse depth (what a
    # stereo camera's disparity noise is)
    uv = rng.uniform(-size, size, (count, 2)) + np.array([0.1, -0.05])
    r = np.column_stack([uv, np.ones(count)])
    w = (r @ n) / d + rng.normal(0.0, sigma_w, count)
    return r / w[:, None]


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def test_equals_numpy_lstsq_on_the_inverse_depth_design():
    rng = np.random.default_rng(0)
    pts = _stereo_plane(rng, _unit([0.3, -0.2, 0.9]), 1.7, 3000, 0.003)
    keep = rng.random(3000) < 0.7
    fit = fit_plane_inverse_depth(pts, keep)
    p = pts[keep]
    A = np.column_stack([p[:, 0] / p[:, 2], p[:, 1] / p[:, 2], np.ones(len(p))])
    c, rss, *_ = np.linalg.lstsq(A, 1.0 / p[:, 2], rcond=None)
    # normal equations against an SVD solve: agreement to rounding (1e-10 relative)
    np.testing.assert_allclose(fit.normal, c / np.linalg.norm(c), rtol=1e-10)
    assert fit.d == pytest.approx(1.0 / np.linalg.norm(c), rel=1e-10)
    np.testing.assert_allclose(fit.closest_point, fit.d * fit.normal, rtol=1e-12)
    assert fit.sigma == pytest.approx(np.sqrt(rss[0] / (len(p) - 3)), rel=1e-6)
    assert fit.count == int(keep.sum())
    # no mask: all rows
    assert fit_plane_inverse_depth(pts).count == 3000


def test_exact_plane_and_hand_case():
    # three points of z = 2 (n = (0, 0, 1), d = 2) and one more: exact recovery
    pts = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [0.0, 1.0, 2.0], [1.0, 1.0, 2.0]])
    fit = fit_plane_inverse_depth(pts)
    np.testing.assert_allclose(fit.normal, [0, 0, 1], atol=1e-12)
    assert fit.d == pytest.approx(2.0)
    assert fit.sigma == pytest.approx(0.0, abs=1e-9)


def test_covariance_matches_monte_carlo():
    rng = np.random.default_rng(1)
    n, d = _unit([0.25, 0.3, 0.92]), 2.1
    pis, covs = [], []
    for _ in range(300):
        fit = fit_plane_inverse_depth(_stereo_plane(rng, n, d, 800, 0.004))
        pis.append(fit.closest_point)
        covs.append(fit.covariance)
    emp = np.cov(np.array(pis).T)
    pred = np.mean(covs, axis=0)
    # 300 samples: the empirical covariance is good to about 2/sqrt(300) ~ 12 %
    np.testing.assert_allclose(np.trace(pred), np.trace(emp), rtol=0.2)
    np.testing.assert_allclose(pred, emp, atol=0.25 * np.abs(emp).max())


def test_unbiased_where_total_least_squares_tilts():
    # an oblique plane at 2 m with stereo noise: the inverse-depth fit is unbiased, total
    # least squares tilts the normal systematically (noise along the rays, not normal)
    rng = np.random.default_rng(2)
    n, d = _unit([0.5, -0.2, 0.84]), 2.0
    ours, tls = [], []
    for _ in range(40):
        pts = _stereo_plane(rng, n, d, 4000, 0.0075, size=0.25)
        ours.append(np.degrees(np.arccos(min(1.0, abs(fit_plane_inverse_depth(pts).normal @ n)))))
        t = fit_plane(pts).plane.normal
        tls.append(np.degrees(np.arccos(min(1.0, abs(t @ n)))))
    assert np.mean(ours) < 0.5 * np.mean(tls)


def test_bad_input():
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        fit_plane_inverse_depth(np.zeros((4, 2)))
    with pytest.raises(InputError, match="mask"):
        fit_plane_inverse_depth(np.ones((4, 3)), np.ones(3, bool))
    with pytest.raises(DegenerateError, match="at least 3"):
        fit_plane_inverse_depth(np.array([[0, 0, 1.0], [1, 0, 1.0], [0, 0, -1.0]]))
    with pytest.raises(DegenerateError, match="one line"):
        fit_plane_inverse_depth(np.array([[0, 0, 1.0], [1, 0, 1.0], [2, 0, 1.0], [3, 0, 1.0]]))


def test_issue25_non_finite_rows_are_input_errors():
    # an infinite x (or values whose ratios overflow) made the moments inf/NaN and
    # numpy's eigvalsh raised LinAlgError; rows with a NaN z are still skipped
    gen = np.random.default_rng(0)
    pts = np.c_[gen.uniform(-1, 1, (50, 2)), gen.uniform(1, 2, 50)].astype(np.float32)
    bad = pts.copy()
    bad[3, 0] = np.inf
    with pytest.raises(InputError, match="points must be finite"):
        fit_plane_inverse_depth(bad)
    mask = np.ones(50, bool)
    mask[3] = False
    fit_plane_inverse_depth(bad, mask)  # the row is not selected: no error
    nan_z = pts.astype(np.float64)
    nan_z[5, 2] = np.nan
    assert np.isfinite(fit_plane_inverse_depth(nan_z).normal).all()
