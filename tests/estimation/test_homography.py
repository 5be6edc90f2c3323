"""find_homography: exact recovery with outliers, parity with cv2.findHomography,
seeded determinism, degenerate input."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import find_homography
from robopercept.imaging import transform_points

H = np.array([[1.1, 0.05, 30.0], [-0.08, 0.95, -12.0], [2e-4, -1e-4, 1.0]])


def _matches(rng, n=300, outliers=0.4, noise=0.5):
    src = rng.uniform(0, 640, (n, 2))
    dst = transform_points(H, src) + rng.normal(0, noise, (n, 2))
    bad = rng.random(n) < outliers
    dst[bad] = rng.uniform(0, 640, (bad.sum(), 2))
    return src, dst, ~bad


def _corner_error(h1, h2, size=640):
    c = np.array([[0, 0], [size, 0], [size, size], [0, size]], float)
    return np.linalg.norm(transform_points(h1, c) - transform_points(h2, c), axis=1).max()


def test_exact_without_noise(rng):
    src, dst, good = _matches(rng, noise=0.0)
    fit = find_homography(src, dst, 1.0)
    np.testing.assert_allclose(fit.H, H, rtol=1e-6, atol=1e-9)
    np.testing.assert_array_equal(fit.inliers, good)
    assert fit.rms < 1e-6


def test_noise_outliers_and_opencv(rng):
    src, dst, good = _matches(rng)
    fit = find_homography(src, dst, 3.0)
    # every true match within 3 px of H is found (noise 0.5 px: all of them), and
    # the corners of a 640 px image move < 0.5 px from the truth
    assert fit.inliers[good].mean() > 0.99
    assert fit.inliers[~good].mean() < 0.02
    assert _corner_error(fit.H, H) < 0.5
    ref, mask = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)
    assert _corner_error(fit.H, ref) < 0.5
    assert np.mean(fit.inliers == mask.ravel().astype(bool)) > 0.98
    again = find_homography(src, dst, 3.0)
    np.testing.assert_array_equal(again.H, fit.H)


def test_degenerate_and_bad_input(rng):
    with pytest.raises(DegenerateError, match="at least 4 matches; got 3"):
        find_homography(np.zeros((3, 2)), np.zeros((3, 2)))
    line = np.stack([np.arange(10.0), 2 * np.arange(10.0)], axis=1)
    with pytest.raises(DegenerateError, match="collinear"):
        find_homography(line, line)
    with pytest.raises(InputError, match="same shape"):
        find_homography(np.zeros((5, 2)), np.zeros((6, 2)))


# issue 25: a threshold no match meets (every hypothesis has 0 inliers) used to overflow
# the adaptive iteration count (math.ceil(inf)); it now runs max_iterations and reports
# no inliers
def test_no_inliers_runs_max_iterations(rng):
    src, dst, _ = _matches(rng, n=50, noise=0.5)
    fit = find_homography(src, dst, 1e-300, max_iterations=30)
    # only points of a minimal sample, which the DLT fits exactly, can meet a 1e-300
    # threshold, and only where their residual rounds to exactly 0 (it depends on the
    # data's last bits): at most 4, never a noisy match
    assert fit.n_iterations == 30 and fit.n_inliers <= 4
    assert np.isnan(fit.rms) if fit.n_inliers == 0 else fit.rms < 1e-9
    assert fit.H.shape == (3, 3) and np.isfinite(fit.H).all()


# issue 25: scalar parameters are checked at the boundary
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"threshold": float("inf")}, "threshold must be finite"),
        ({"threshold": "3"}, "threshold must be a real number"),
        ({"max_iterations": 2.5}, "max_iterations must be an integer"),
        ({"refine": "no"}, "refine must be True or False"),
    ],
)
def test_scalar_parameters_are_checked(rng, kwargs, match):
    src, dst, _ = _matches(rng, n=20)
    with pytest.raises(InputError, match=match):
        find_homography(src, dst, **kwargs)
