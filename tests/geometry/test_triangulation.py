"""triangulate: bad input named by argument, and inputs near the limits of float64
(issue 25). Parity with cv2.triangulatePoints and the truth is in test_epipolar.py."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.geometry.transforms import rotation_from_rotvec
from robopercept.geometry.triangulation import triangulate

K = np.array([[700.0, 0.0, 320.0], [0.0, 690.0, 240.0], [0.0, 0.0, 1.0]])


def _scene(n=30, seed=0):
    """Points 3-8 m in front of camera 1 and their images in two cameras."""
    gen = np.random.default_rng(seed)
    X = np.c_[gen.uniform(-2, 2, n), gen.uniform(-1.5, 1.5, n), gen.uniform(3, 8, n)]
    P1 = K @ np.c_[np.eye(3), np.zeros(3)]
    P2 = K @ np.c_[rotation_from_rotvec(np.array([0.05, -0.2, 0.03])), [-0.5, 0.05, 0.1]]
    return X, P1, P2, _image(P1, X), _image(P2, X)


def _image(P, X):
    h = np.c_[X, np.ones(len(X))] @ P.T
    return h[:, :2] / h[:, 2:]


# issue 25: NaN/inf points went into the SVD (LinAlgError "SVD did not converge");
# they are refused with an InputError naming the argument
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("which", ["x1", "x2"])
def test_non_finite_points_are_refused_by_name(bad, which):
    _, P1, P2, x1, x2 = _scene()
    pts = {"x1": x1.copy(), "x2": x2.copy()}
    pts[which][3, 1] = bad
    for method in ("dlt", "midpoint"):
        with pytest.raises(InputError, match=f"{which} must be finite"):
            triangulate(P1, P2, pts["x1"], pts["x2"], method=method)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "lmeds"}, "method must be one of"),
        ({"method": None}, "method must be one of"),
        ({"P1": np.full((3, 4), np.inf)}, "P1 must be a finite"),
        ({"P2": np.zeros((3, 4))}, "P2's left 3x3 block is singular"),
        ({"x1": np.array([["a", "b"]] * 30)}, "x1 must be numeric"),
    ],
)
def test_bad_input(kwargs, match):
    _, P1, P2, x1, x2 = _scene()
    args = {"P1": P1, "P2": P2, "x1": x1, "x2": x2, **kwargs}
    with pytest.raises(InputError, match=match):
        triangulate(**args)


# issue 25: finite values near 1e300 overflowed inside (matrix_rank called a finite
# camera "singular", squares of ray directions were inf). P is defined up to scale, each
# point's DLT system too, and a ray's direction has no length: dividing each by a power
# of two (exact) gives the same points as the unscaled arithmetic. Tolerance: 1e-9
# relative, the conditioning of the well-posed unscaled problem (errors ~1e-13 here)
@pytest.mark.parametrize("scale", [1e300, 1e-300, 2.0**1000, 1e-150])
@pytest.mark.parametrize("method", ["dlt", "midpoint"])
def test_projection_matrices_near_the_float_limits(scale, method):
    X, P1, P2, x1, x2 = _scene()
    ref = triangulate(P1, P2, x1, x2, method=method)
    np.testing.assert_allclose(ref, X, rtol=1e-9)
    out = triangulate(P1 * scale, P2 * scale, x1, x2, method=method)
    np.testing.assert_allclose(out, X, rtol=1e-9)


@pytest.mark.parametrize("method", ["dlt", "midpoint"])
def test_image_points_near_1e300_are_refused(method):
    # a point 1e-290 m in front of camera 1's principal plane images ~1e293 px away:
    # the DLT rows of camera 2 vanish in rounding next to camera 1's, so such input is
    # refused by name (values beyond 1e150) rather than answered wrongly
    X, P1, P2, _, _ = _scene(5)
    X[:, 2] = 1e-290
    x1, x2 = _image(P1, X), _image(P2, X)
    assert np.abs(x1).max() > 1e290
    with pytest.raises(InputError, match=r"x1 has values up to .*rescale"):
        triangulate(P1, P2, x1, x2, method=method)


def test_image_points_near_1e_minus_300():
    # tiny image coordinates (the optical axis of a normalized camera) are exact: P = [I|0]
    # and [I|t]; the point (1e-300, -1e-300, 2) projects to about (5e-301, -5e-301)
    P1 = np.c_[np.eye(3), np.zeros(3)]
    P2 = np.c_[np.eye(3), [1.0, 0.0, 0.0]]
    X = np.array([[1e-300, -1e-300, 2.0]])
    out = triangulate(P1, P2, _image(P1, X), _image(P2, X))
    np.testing.assert_allclose(out[:, 2], 2.0, rtol=1e-12)
    assert np.abs(out[:, :2]).max() < 1e-12
