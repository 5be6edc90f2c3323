"""Match pictures (issue 30): the best N matches, inliers and outliers in distinct
colours, and A's outline mapped through the homography onto B."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz.features import (
    OUTLINE_COLOR,
    draw_matches,
    matches_picture,
    project_outline,
    select_matches,
)

GREEN, MAGENTA = (0, 255, 0), (255, 0, 255)


def _scene(n: int = 200, seed: int = 0):
    """Two 120x160 grey images and ``n`` matches: a shift by (-20, -10) for the first
    70 %, random pairs for the rest (outliers)."""
    rng = np.random.default_rng(seed)
    a = np.full((120, 160), 100, np.uint8)
    b = np.full((120, 160), 100, np.uint8)
    xa = rng.uniform(25, 155, (n, 2)) * [1, 0.75]
    xb = xa - [20, 10]
    k = int(0.7 * n)
    xb[k:] = rng.uniform(0, 119, (n - k, 2))
    inl = np.arange(n) < k
    dist = rng.uniform(0, 1, n)
    h = np.array([[1.0, 0, -20], [0, 1, -10], [0, 0, 1]])
    return a, xa, b, xb, inl, dist, h


def test_select_matches_hand_computed():
    d = [0.5, 0.1, 0.4, 0.2, 0.3]
    assert select_matches(5, distance=d, max_matches=3).tolist() == [1, 3, 4]
    assert select_matches(5, distance=d, max_matches=None).tolist() == [1, 3, 4, 2, 0]
    inl = [1, 1, 0, 0, 1]  # 60 % inliers: 3 of 5 -> 2 inliers (1, 4) + 1 outlier (3) of 3
    assert select_matches(5, distance=d, inliers=inl, max_matches=3).tolist() == [1, 3, 4]
    assert select_matches(5, distance=d, inliers=inl, max_matches=1).tolist() == [1]
    hidden = select_matches(5, distance=d, inliers=inl, max_matches=2, show_outliers=False)
    assert hidden.tolist() == [1, 4]
    assert select_matches(5, max_matches=3).tolist() == [0, 2, 4]  # evenly spaced
    assert select_matches(0, max_matches=3).tolist() == []


def test_select_matches_keeps_the_inlier_fraction():
    *_, inl, dist, _h = _scene(677)
    rows = select_matches(677, distance=dist, inliers=inl, max_matches=100)
    assert rows.size == 100 and inl[rows].sum() == round(100 * inl.sum() / 677)
    # each part holds the best of its kind
    assert dist[rows[inl[rows]]].max() <= np.sort(dist[inl])[inl[rows].sum() - 1]
    assert dist[rows[~inl[rows]]].max() <= np.sort(dist[~inl])[(~inl[rows]).sum() - 1]
    assert np.all(np.diff(dist[rows]) >= 0)  # best first


def test_project_outline_matches_opencv():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(3)
    h = np.eye(3) + rng.normal(0, [[0.1, 0.1, 5], [0.1, 0.1, 5], [1e-4, 1e-4, 0]])
    ours = project_outline(h, (640, 480))
    corners = np.array([[-0.5, -0.5], [639.5, -0.5], [639.5, 479.5], [-0.5, 479.5]])
    ref = cv2.perspectiveTransform(corners[None].astype(np.float64), h)[0]
    np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-9)  # same formula, float64
    behind = np.array([[1.0, 0, 0], [0, 1, 0], [-0.01, 0, 1]])  # w < 0 at x > 100
    assert project_outline(behind, (640, 480)) is None


def test_picture_draws_what_it_says():
    a, xa, b, xb, inl, dist, h = _scene()
    pic = matches_picture(a, xa, b, xb, inliers=inl, distance=dist, homography=h, max_matches=20)
    assert pic.image.shape == (120, 320, 3) and pic.drawn.size == 20
    np.testing.assert_array_equal(
        pic.drawn, select_matches(200, distance=dist, inliers=inl, max_matches=20)
    )
    green = (pic.image == GREEN).all(axis=2)
    magenta = (pic.image == MAGENTA).all(axis=2)
    assert green.any() and magenta.any()
    # A's border (pixel edges) shifted by (-20, -10) onto B, which starts at x = 160
    np.testing.assert_allclose(pic.outline[2], [159.5 - 20, 119.5 - 10])
    ring = (pic.image == OUTLINE_COLOR).all(axis=2)
    assert ring[20:100, 160 + 138 : 160 + 142].any(axis=1).all()  # its right edge
    assert not ring[:, :160].any()  # nothing on A
    # the drawn end points in A are discs of their colour (a few covered by later ones)
    ends = np.round(xa[pic.drawn]).astype(int)
    shown = [
        tuple(pic.image[y, x]) == (GREEN if inl[i] else MAGENTA)
        for i, (x, y) in zip(pic.drawn, ends, strict=True)
    ]
    assert np.mean(shown) >= 0.8
    more = matches_picture(a, xa, b, xb, inliers=inl, distance=dist, max_matches=None)
    assert more.drawn.size == 200 and more.outline is None
    only = matches_picture(a, xa, b, xb, inliers=inl, distance=dist, show_outliers=False)
    assert inl[only.drawn].all() and not (only.image == MAGENTA).all(axis=2).any()
    assert np.array_equal(
        draw_matches(a, xa, b, xb, inliers=inl, distance=dist, max_lines=20, homography=h),
        pic.image,
    )


def test_line_width_follows_the_height():
    big = np.full((1080, 960), 100, np.uint8)
    xy = np.array([[100.0, 500.0]])
    pic = matches_picture(big, xy, big, xy, max_matches=None)  # a horizontal line
    col = (pic.image[:, 600] == GREEN).all(axis=1)  # a vertical cut through the line
    assert col.sum() == 3  # round(1080 / 400)
    rim = (pic.image[:, 600] == 0).all(axis=1)
    assert rim.sum() == 2  # one dark pixel each side


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: select_matches(3, distance=[1, 2]), "distance has 2 entries for 3"),
        (lambda: select_matches(3, inliers=[1, 0]), "inliers has 2 entries for 3"),
        (lambda: select_matches(3, max_matches=0), "max_matches must be"),
        (lambda: select_matches(3, distance=["a", "b", "c"]), "distance must be real"),
        (lambda: project_outline(np.eye(2), (4, 4)), "homography must be a finite 3x3"),
        (lambda: project_outline("H", (4, 4)), "homography must be a finite 3x3"),
        (lambda: project_outline(np.eye(3), (4,)), "size must be"),
        (
            lambda: matches_picture(
                np.zeros((4, 4)), [[1, 1]], np.zeros((4, 4)), [[1, 1]], width=0
            ),
            "width must be",
        ),
        (
            lambda: matches_picture(
                np.zeros((4, 4)), [[1, 1]], np.zeros((4, 4)), [[1, 1]], caption=3
            ),
            "caption must be a string",
        ),
    ],
)
def test_bad_inputs(call, match):
    with pytest.raises(InputError, match=match):
        call()
