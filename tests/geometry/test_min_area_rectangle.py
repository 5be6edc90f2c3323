"""min_area_rectangle: the smallest rotated rectangle around 2-D points, against
cv2.minAreaRect and hand cases."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.geometry import min_area_rectangle


def _corners(center, half, t):
    u, v = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
    return np.array([center + a * half[0] * u + b * half[1] * v
                     for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])  # fmt: skip


def test_a_rotated_rectangle_is_found_exactly():
    rng = np.random.default_rng(0)
    for t in np.radians([0.0, 10.0, 33.0, 60.0, 89.0]):
        c0, h0 = np.array([3.0, -2.0]), np.array([2.0, 0.5])
        inside = rng.uniform(-1, 1, (200, 2)) * h0
        u, v = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
        pts = np.vstack([_corners(c0, h0, t), c0 + inside[:, :1] * u + inside[:, 1:] * v])
        c, h, a = min_area_rectangle(pts)
        np.testing.assert_allclose(c, c0, atol=1e-9)
        # the sides may come the other way round (t + 90 degrees, sizes swapped)
        np.testing.assert_allclose(sorted(h), sorted(h0), atol=1e-9)
        got = _corners(c, h, a)
        d = np.linalg.norm(got[:, None] - _corners(c0, h0, t)[None], axis=2)
        assert d.min(axis=1).max() < 1e-9  # the same four corners
        assert 0.0 <= a < np.pi / 2


def test_area_equals_opencv_on_random_clouds():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(1)
    for n in (3, 5, 50, 1000):
        pts = rng.normal(size=(n, 2)) * [3.0, 1.0] @ np.array([[0.8, 0.6], [-0.6, 0.8]])
        _, h, _ = min_area_rectangle(pts)
        (_, _), (w, hh), _ = cv2.minAreaRect(pts.astype(np.float32))
        # OpenCV works in float32: relative 1e-5
        assert 4 * h[0] * h[1] == pytest.approx(w * hh, rel=1e-5)
        # every point inside (float tolerance)
        c, h, a = min_area_rectangle(pts)
        u, v = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
        assert (np.abs((pts - c) @ u) <= h[0] + 1e-9).all()
        assert (np.abs((pts - c) @ v) <= h[1] + 1e-9).all()


def test_degenerate_sets():
    c, h, _ = min_area_rectangle([[1.0, 2.0]])
    assert c.tolist() == [1.0, 2.0] and h.tolist() == [0.0, 0.0]
    c, h, _ = min_area_rectangle([[0, 0], [1, 1], [2, 2], [3, 3]])  # collinear
    assert min(h) == pytest.approx(0.0, abs=1e-12)
    assert max(h) == pytest.approx(np.sqrt(18) / 2)
    np.testing.assert_allclose(c, [1.5, 1.5])


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (np.zeros((0, 2)), "N >= 1"),
        (np.zeros((3, 3)), r"\(N, 2\)"),
        ([[0.0, np.nan]], "finite"),
        ("points", "number"),
    ],
)
def test_bad_points(bad, match):
    with pytest.raises(InputError, match=match):
        min_area_rectangle(bad)
