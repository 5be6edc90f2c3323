"""classify_motion: translation, rotation and zoom told apart by a similarity fit."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.motion import classify_motion


def _points(n=150, seed=0):
    return np.random.default_rng(seed).uniform(20, 300, (n, 2))


def _similar(p, scale=1.0, angle=0.0, shift=(0.0, 0.0), centre=(160.0, 160.0)):
    c = np.asarray(centre)
    R = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    return scale * (p - c) @ R.T + c + np.asarray(shift) - p


@pytest.mark.parametrize(
    ("kwargs", "kind"),
    [
        ({"shift": (3.0, -2.0)}, "translation"),
        ({"angle": np.radians(2.0)}, "rotation"),
        ({"angle": np.radians(-2.0)}, "rotation"),
        ({"scale": 1.03}, "zoom"),
        ({"scale": 0.97}, "zoom"),
        ({}, "static"),
        ({"shift": (0.1, 0.1)}, "static"),
    ],
)
def test_each_motion_is_named(kwargs, kind):
    p = _points()
    noise = np.random.default_rng(1).normal(0, 0.05, p.shape)
    result = classify_motion(p, _similar(p, **kwargs) + noise)
    assert result.kind == kind
    assert result.residual < 0.1


def test_parameters_are_recovered():
    p = _points()
    flow = _similar(p, scale=1.02, angle=np.radians(1.5), shift=(4.0, 1.0))
    r = classify_motion(p, flow)
    assert r.scale == pytest.approx(1.02, abs=1e-12)
    assert r.rotation == pytest.approx(np.radians(1.5), abs=1e-12)
    # translation is that of the points' centroid
    assert np.allclose(r.translation, flow.mean(axis=0), atol=1e-12)
    rms = np.sqrt(((p - p.mean(axis=0)) ** 2).sum(axis=1).mean())
    assert r.displacement["zoom"] == pytest.approx(0.02 * rms)
    assert r.displacement["rotation"] == pytest.approx(2 * rms * np.sin(np.radians(0.75)))


def test_fit_equals_scikit_image_similarity():
    """The closed-form least-squares fit is Umeyama's (skimage's estimate) on noisy data."""
    transform = pytest.importorskip("skimage.transform")
    p = _points(seed=3)
    gen = np.random.default_rng(4)
    flow = _similar(p, scale=0.98, angle=0.03, shift=(-2, 5)) + gen.normal(0, 0.3, p.shape)
    r = classify_motion(p, flow, trim=1e9)  # no trimming: plain least squares
    ref = transform.SimilarityTransform.from_estimate(p, p + flow)
    assert r.scale == pytest.approx(ref.scale, rel=1e-9)
    assert r.rotation == pytest.approx(ref.rotation, abs=1e-9)
    centroid = p.mean(axis=0)
    assert np.allclose(r.translation, ref(centroid[None])[0] - centroid, atol=1e-9)


def test_outlying_vectors_do_not_decide():
    """A camera rotation with 15 % of the points on independently moving objects."""
    p = _points(300, seed=5)
    flow = _similar(p, angle=np.radians(3.0))
    true = flow.copy()
    gen = np.random.default_rng(6)
    bad = gen.choice(len(p), 45, replace=False)
    flow[bad] = gen.uniform(-25, 25, (45, 2))
    r = classify_motion(p, flow)
    assert r.kind == "rotation"
    assert r.rotation == pytest.approx(np.radians(3.0), abs=1e-3)
    off = bad[np.hypot(*(flow[bad] - true[bad]).T) > 2.0]  # a random vector may be right
    assert len(off) >= 40 and not r.inliers[off].any()
    assert r.inliers.sum() >= len(p) - 45


def test_independent_motions_are_complex():
    """Two halves moving in opposite directions are no single similarity."""
    p = _points(200, seed=7)
    flow = np.where(p[:, :1] < 160, [[6.0, 0.0]], [[-6.0, 0.0]]) + np.random.default_rng(8).normal(
        0, 0.5, p.shape
    )
    assert classify_motion(p, flow).kind == "complex"


def test_nan_rows_are_ignored():
    p = _points()
    flow = _similar(p, scale=1.05)
    flow[::3] = np.nan
    r = classify_motion(p, flow)
    assert r.kind == "zoom" and r.scale == pytest.approx(1.05)
    assert not r.inliers[::3].any()


def test_degenerate_and_bad_input():
    with pytest.raises(DegenerateError, match="at least 2"):
        classify_motion(np.zeros((1, 2)), np.ones((1, 2)))
    with pytest.raises(DegenerateError, match="at least 2"):
        classify_motion(np.zeros((3, 2)), np.full((3, 2), np.nan))
    with pytest.raises(DegenerateError, match="coincide"):
        classify_motion(np.ones((5, 2)), np.ones((5, 2)))
    with pytest.raises(InputError, match=r"\(N, 2\)"):
        classify_motion(np.zeros((5, 2)), np.zeros((4, 2)))


# issue 25: min_motion and trim reached comparisons and float() unchecked, and vectors
# near 1e300 overflowed the fit into NaN
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"min_motion": "3"}, "min_motion must be a real number"),
        ({"trim": 1 + 1j}, "trim must be a real number"),
        ({"trim": 0.0}, "trim must be in"),
        ({"points": _points() * 1e300}, "points has values up to"),
        ({"flow": np.full((150, 2), 1e200)}, "flow has values up to"),
        ({"points": "ab"}, "points must hold real numbers"),
    ],
)
def test_hostile_arguments_are_refused_by_name(kwargs, match):
    args = {"points": _points(), "flow": _similar(_points(), scale=1.05), **kwargs}
    with pytest.raises(InputError, match=match):
        classify_motion(**args)
