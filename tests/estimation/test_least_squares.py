"""Least-squares lines and planes: hand cases, parity with NumPy, degenerate input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import Line, Plane, fit_line, fit_plane


def test_line_hand_case():
    # y = 2x + 1 exactly: both methods recover it, residuals zero
    x = np.arange(5.0)
    pts = np.column_stack([x, 2 * x + 1])
    for method in ("total", "ordinary"):
        fit = fit_line(pts, method)
        a, b, c = fit.line.coefficients
        assert np.isclose(a * a + b * b, 1.0)
        np.testing.assert_allclose([-a / b, -c / b], [2.0, 1.0], atol=1e-12)
        assert fit.rms < 1e-12
    # hand case: the corners of a 4 x 2 rectangle; the scatter is diag(16, 4) about the
    # centre (2, 0), so the TLS line is y = 0 with residuals +-1 and RMS 1
    fit = fit_line([[0, 1], [0, -1], [4, 1], [4, -1]], "total")
    np.testing.assert_allclose(np.abs(fit.line.distance([[5, 0], [7, 3]])), [0.0, 3.0], atol=1e-12)
    np.testing.assert_allclose(np.abs(fit.residuals), 1.0)
    assert np.isclose(fit.rms, 1.0)


def test_ordinary_line_matches_polyfit(rng):
    x = rng.uniform(-3, 3, 50)
    y = 0.7 * x - 2 + rng.normal(0, 0.1, 50)
    fit = fit_line(np.column_stack([x, y]), "ordinary")
    slope, icpt = np.polyfit(x, y, 1)
    a, b, c = fit.line.coefficients
    np.testing.assert_allclose([-a / b, -c / b], [slope, icpt], rtol=1e-10)
    np.testing.assert_allclose(fit.residuals, y - (slope * x + icpt), atol=1e-10)


def test_total_line_is_orthogonal_regression(rng):
    # points along a steep line: TLS finds it, OLS in y = f(x) is biased by x noise
    t = rng.uniform(-1, 1, 400)
    pts = np.column_stack([0.2 * t, 3 * t]) + rng.normal(0, 0.02, (400, 2))
    d = fit_line(pts, "total").line.direction
    true = np.array([0.2, 3.0]) / np.hypot(0.2, 3.0)
    assert abs(abs(d @ true) - 1) < 1e-4


def test_plane_hand_case_and_equation():
    pts = np.array([[0, 0, 1.0], [1, 0, 1], [0, 1, 1], [1, 1, 1]])
    fit = fit_plane(pts)
    np.testing.assert_allclose(np.abs(fit.plane.normal), [0, 0, 1], atol=1e-12)
    assert np.isclose(abs(fit.plane.offset), 1.0)
    eq = fit.plane.equation
    np.testing.assert_allclose(pts @ eq[:3] + eq[3], 0, atol=1e-12)
    # ordinary: z = 1 + 0 x + 0 y
    fo = fit_plane(pts, "ordinary")
    np.testing.assert_allclose(fo.residuals, 0, atol=1e-12)


def test_plane_recovers_noisy_plane(rng):
    true = Plane.from_equation([1.0, -2.0, 0.5, 3.0])
    p = true.project(rng.uniform(-5, 5, (2000, 3))) + rng.normal(0, 0.01, (2000, 1)) * true.normal
    fit = fit_plane(p)
    assert fit.plane.angle_to(true) < np.radians(0.05)
    assert abs(fit.rms - 0.01) < 0.001
    # weights: zero weight on a gross outlier removes its influence
    q = np.vstack([p, [[100.0, 100.0, 100.0]]])
    w = np.r_[np.ones(len(p)), 0.0]
    assert fit_plane(q, weights=w).plane.angle_to(true) < np.radians(0.05)


def test_plane_helpers():
    pl = Plane.from_point_normal([0, 0, 2], [0, 0, 3])
    np.testing.assert_allclose(pl.equation, [0, 0, 1, -2])
    np.testing.assert_allclose(pl.distance([[0, 0, 5]]), [3.0])
    np.testing.assert_allclose(pl.project([[1, 2, 5]]), [[1, 2, 2]])
    np.testing.assert_allclose(pl.point, [0, 0, 2])
    assert pl.angle_to(pl.flipped()) == 0.0
    assert np.isclose(pl.angle_to(Plane.from_equation([1, 0, 0, 0])), np.pi / 2)
    line = Line(np.array([0.0, 1.0, -1.0]))  # y = 1
    np.testing.assert_allclose(line.point, [0, 1])
    np.testing.assert_allclose(line.direction, [-1, 0])


@pytest.mark.parametrize(
    ("call", "exc", "match"),
    [
        (lambda: fit_line([[0, 0]]), DegenerateError, "at least 2"),
        (lambda: fit_line([[1, 1], [1, 1]]), DegenerateError, "same point"),
        (lambda: fit_line([[1, 0], [1, 5]], "ordinary"), DegenerateError, "vertical"),
        (lambda: fit_plane([[0, 0, 0], [1, 1, 1]]), DegenerateError, "at least 3"),
        (
            lambda: fit_plane([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]]),
            DegenerateError,
            "collinear",
        ),
        (lambda: fit_plane(np.ones((3, 2))), InputError, "shape"),
        (lambda: fit_plane([[0, 0, np.nan]] * 4), InputError, "finite"),
        (lambda: fit_plane(np.eye(3), method="robust"), InputError, "method"),
        (lambda: fit_plane(np.eye(3), weights=[1, -1, 1]), InputError, "weights"),
        (lambda: Plane.from_equation([0, 0, 0, 1]), DegenerateError, "zero normal"),
    ],
)
def test_bad_input(call, exc, match):
    with pytest.raises(exc, match=match):
        call()


def test_scatter_matrix_hand_case_and_mask(rng):
    from robopercept.estimation.least_squares import scatter_matrix

    # hand case: (0,0), (2,0), (0,2), (2,2): centroid (1,1), S = diag(4, 4)
    c, s = scatter_matrix(np.array([[0.0, 0], [2, 0], [0, 2], [2, 2]]))
    np.testing.assert_array_equal(c, [1, 1])
    np.testing.assert_array_equal(s, [[4, 0], [0, 4]])
    # far from the origin (a centroid of 1e4 m): two passes keep S exact to 1e-9 relative
    pts = rng.normal(0, 1, (5000, 3)) * [1, 2, 0.01] + 1e4
    mask = rng.random(5000) < 0.3
    c, s = scatter_matrix(pts, mask)
    sel = pts[mask]
    np.testing.assert_allclose(c, sel.mean(axis=0), rtol=1e-14)
    np.testing.assert_allclose(s, np.cov(sel.T) * (len(sel) - 1), rtol=1e-9)
    # integer input and an empty selection
    c, s = scatter_matrix(np.arange(6).reshape(3, 2), np.zeros(3, dtype=bool))
    assert np.array_equal(c, [0, 0]) and np.array_equal(s, np.zeros((2, 2)))


# issue 25: points near 1e300 overflowed the scatter matrix to inf and numpy's eigh
# raised LinAlgError; coordinates beyond 1e150 are refused with an InputError, and large
# coordinates within it still give the right plane
def test_issue25_huge_coordinates_are_refused_and_large_ones_fit():
    gen = np.random.default_rng(0)
    xy = gen.uniform(-1, 1, (500, 2))
    pts = np.c_[xy, 0.5 * xy[:, 0] - 0.25 * xy[:, 1] + 2.0]
    with pytest.raises(InputError, match=r"points has values up to 2\.7"):
        fit_plane(pts * 1e300)
    with pytest.raises(InputError, match="points has values up to"):
        fit_line(pts[:, :2] * 1e200)
    fit = fit_plane(pts * 1e140)  # within the bound: the same plane, scaled offset
    n = fit.plane.normal * np.sign(fit.plane.normal[2])
    np.testing.assert_allclose(n, np.array([-0.5, 0.25, 1.0]) / np.sqrt(1.3125), atol=1e-9)


# -- the one-pass slab fit (issue 49) -----------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_slab_fit_equals_selecting_then_fitting(seed):
    from robopercept.estimation import fit_plane_inverse_depth
    from robopercept.estimation.least_squares import fit_plane_inverse_depth_slab

    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:120, 0:160]
    u, v = (xx.ravel() - 80) / 150.0, (yy.ravel() - 60) / 150.0
    c = np.array([0.1, -0.2, 0.5]) * rng.uniform(0.8, 1.2, 3)  # 1/z = c.(u, v, 1)
    w = c[0] * u + c[1] * v + c[2] + rng.normal(0, 2e-3, u.size)
    z = 1.0 / w
    z[rng.random(z.size) < 0.2] += rng.uniform(-0.5, 0.5)  # outliers
    pts = np.column_stack([u * z, v * z, z])
    normal = c / np.linalg.norm(c)
    d = 1.0 / np.linalg.norm(c)
    within = rng.random(z.size) < 0.9
    for allowed in (None, within):
        fit, inl = fit_plane_inverse_depth_slab(pts, normal, d, 0.02, allowed)
        want = np.abs(pts @ normal - d) < 0.02
        if allowed is not None:
            want &= allowed
        # the same test up to the order of three products: equal but for ties at the
        # threshold's last bit (none here)
        np.testing.assert_array_equal(inl, want)
        ref = fit_plane_inverse_depth(pts, want)
        # the same sums added in another order (per block): equal to rounding
        np.testing.assert_allclose(fit.normal, ref.normal, rtol=0, atol=1e-12)
        assert fit.d == pytest.approx(ref.d, rel=1e-12)
        # the covariance's residual sum w'w - c'b cancels about six digits (its two
        # terms agree to 1e-6): rounding in the sums shows at 1e-9 relative there
        np.testing.assert_allclose(fit.covariance, ref.covariance, rtol=1e-6, atol=0)
        assert fit.count == ref.count == int(want.sum())


def test_slab_fit_with_too_few_inliers_is_degenerate():
    from robopercept.estimation.least_squares import fit_plane_inverse_depth_slab

    pts = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 3.0]])
    with pytest.raises(DegenerateError, match="at least 3"):
        fit_plane_inverse_depth_slab(pts, np.array([0.0, 0.0, 1.0]), 1.0, 0.01)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_slab_inliers_is_the_slab_fits_mask_to_the_bit(seed):
    # the refit loop of the plane measurement asks slab_inliers whether the inliers
    # change before it pays for the fit: the two tests must agree on every point, those
    # whose residual falls on the threshold's last bits included
    from robopercept.estimation.least_squares import fit_plane_inverse_depth_slab, slab_inliers

    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal[2] = abs(normal[2]) + 1.0
    normal /= np.linalg.norm(normal)
    d, thr = rng.uniform(1.0, 3.0), rng.uniform(0.005, 0.05)
    n = 20000
    uv = rng.uniform(-0.6, 0.6, (n, 2))
    on = d / (normal[0] * uv[:, 0] + normal[1] * uv[:, 1] + normal[2])  # z on the plane
    # residuals spread over the slab and packed within a few ulps of its edge
    edge_ulps = thr * (1 + rng.integers(-4, 5, n) * 2e-16)
    off = np.where(rng.random(n) < 0.5, rng.uniform(-2, 2, n) * thr, edge_ulps)
    off *= np.sign(rng.normal(size=n))
    pts = np.column_stack([uv * on[:, None], on]) + off[:, None] * normal  # along the normal
    within = rng.random(n) < 0.8
    for allowed in (None, within):
        _, inl = fit_plane_inverse_depth_slab(pts, normal, d, thr, allowed)
        np.testing.assert_array_equal(slab_inliers(pts, normal, d, thr, allowed), inl)
    edge = np.abs(np.abs(pts @ normal - d) - thr) < 1e-12
    assert edge.sum() > 100  # the case reaches the threshold's last bits


@pytest.mark.parametrize("n", [5, 1000, 130_001])
def test_slab_fit_on_one_thread_is_the_parallel_fit_to_the_bit(n):
    # fit_plane_inverse_depth_slab runs the serial twin below SLAB_PARALLEL_MIN points:
    # the same blocks summed in the same order, so the same bits whichever it picks
    from robopercept.estimation import least_squares as ls

    rng = np.random.default_rng(n)
    pts = rng.normal(size=(n, 3)) * [0.5, 0.5, 0.01] + [0.0, 0.0, 2.0]
    pts[::7, 2] += rng.uniform(-0.1, 0.1, pts[::7].shape[0])
    within = rng.random(n) < 0.9
    for allowed, use in ((np.zeros(1, dtype=bool), False), (within, True)):
        args = (pts, 0.01, -0.02, 0.9997, 2.0, 0.03, allowed, use)
        out_p, out_s = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        par = ls._slab_kernel(*args, out_p)
        ser = ls._slab_kernel_serial(*args, out_s)
        np.testing.assert_array_equal(out_p, out_s)
        for a, b in zip(par, ser, strict=True):
            np.testing.assert_array_equal(a, b)
        assert out_s.sum() > 0
