"""Pictorial structures (robopercept.nn.pose.pictorial): the generalized distance transform
against brute-force minimization and SciPy's Euclidean distance transform, and the tree
dynamic programme against enumeration of every pose."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.nn.pose.pictorial import (
    DistanceTransform,
    PictorialSolution,
    distance_transform_1d,
    generalized_distance_transform,
    pictorial_structures,
)
from robopercept.nn.skeleton import MPII_16

# float64 tolerance of the transforms: the envelope and the brute force pick the same q
# (up to ties) and then evaluate the same formula f(q) + w (p - q - d)^2; what is left
# is the rounding of that formula written in a different order, ~1e-15 relative
RTOL, ATOL = 1e-9, 1e-9


def brute_1d(f: np.ndarray, w: float, d: float) -> np.ndarray:
    """min_q f(q) + w (p - q - d)^2 by trying every q (independent of the module)."""
    n = f.shape[-1]
    p = np.arange(n)[:, None]
    q = np.arange(n)[None, :]
    return (f[..., None, :] + w * (p - q - d) ** 2).min(axis=-1)


def brute_2d(f: np.ndarray, w: tuple, d: tuple) -> np.ndarray:
    """min over every grid point q of f(q) + wx (px - qx - dx)^2 + wy (py - qy - dy)^2."""
    h, wd = f.shape
    yy, xx = np.mgrid[:h, :wd]
    cost = (
        f[None, None]
        + w[0] * (xx[:, :, None, None] - xx[None, None] - d[0]) ** 2
        + w[1] * (yy[:, :, None, None] - yy[None, None] - d[1]) ** 2
    )
    return cost.reshape(h, wd, -1).min(axis=-1)


def random_costs(rng: np.random.Generator, shape: tuple, inf_share: float) -> np.ndarray:
    f = rng.normal(size=shape) * rng.choice([0.01, 1.0, 100.0])
    f[rng.random(shape) < inf_share] = np.inf
    return f


def pose_energy(c, parents, mu, w, loc) -> float:
    """E(l) written out: unary costs plus the springs."""
    e = sum(c[i, y, x] for i, (x, y) in enumerate(loc))
    for i, p in enumerate(parents):
        if p >= 0:
            d = np.asarray(loc[i], float) - loc[p] - mu[i]
            e += w[i, 0] * d[0] ** 2 + w[i, 1] * d[1] ** 2
    return float(e)


# ==================================================================== 1-D transform


class TestDistanceTransform1D:
    def test_hand_computed(self):
        # D(p) = min(0 + p^2, 1 + (p - 4)^2, 9 + ...): q = 0 wins up to p = 2 (4 < 5),
        # q = 4 from p = 3 (2 < 9)
        dt = distance_transform_1d([0.0, 9.0, 9.0, 9.0, 1.0], weight=1.0)
        assert isinstance(dt, DistanceTransform)
        np.testing.assert_array_equal(dt.values, [0.0, 1.0, 4.0, 2.0, 1.0])
        np.testing.assert_array_equal(dt.argmin, [0, 0, 0, 4, 4])

    def test_hand_computed_weight_and_offset(self):
        # one allowed sample at q = 1: D(p) = 2 (p - 1 - 1)^2 = 8, 2, 0
        dt = distance_transform_1d([np.inf, 0.0, np.inf], 2.0, offset=1.0)
        np.testing.assert_array_equal(dt.values, [8.0, 2.0, 0.0])
        np.testing.assert_array_equal(dt.argmin, [1, 1, 1])
        # a fractional offset reads the envelope between samples: 0.5 (p - 1 + 0.5)^2
        dt = distance_transform_1d([np.inf, 0.0, np.inf], 0.5, offset=-0.5)
        np.testing.assert_allclose(dt.values, [0.125, 0.125, 1.125])

    @pytest.mark.parametrize("n", [1, 2, 3, 7, 40])
    @pytest.mark.parametrize("inf_share", [0.0, 0.3, 0.9])
    def test_equals_brute_force(self, n, inf_share):
        rng = np.random.default_rng(n + int(10 * inf_share))
        for _ in range(20):
            f = random_costs(rng, (5, n), inf_share)
            w = float(rng.choice([1e-3, 0.25, 1.0, 13.0]))
            d = float(rng.normal(0, 3))
            ref = brute_1d(f, w, d)
            for method in ("envelope", "brute"):
                dt = distance_transform_1d(f, w, d, method=method)
                np.testing.assert_array_equal(np.isinf(dt.values), np.isinf(ref))
                fin = np.isfinite(ref)
                np.testing.assert_allclose(dt.values[fin], ref[fin], rtol=RTOL, atol=ATOL)
                # the argmin attains the minimum; -1 exactly on all-inf lines
                q = dt.argmin
                assert np.all((q == -1) == np.isinf(ref))
                p = np.arange(n)
                got = np.take_along_axis(f, np.maximum(q, 0), 1) + w * (p - q - d) ** 2
                np.testing.assert_allclose(got[fin], ref[fin], rtol=RTOL, atol=ATOL)

    def test_axis(self):
        f = np.random.default_rng(1).normal(size=(4, 6, 5))
        a = distance_transform_1d(f, 0.7, 1.5, axis=1)
        b = distance_transform_1d(np.moveaxis(f, 1, -1), 0.7, 1.5)
        np.testing.assert_array_equal(a.values, np.moveaxis(b.values, -1, 1))
        np.testing.assert_array_equal(a.argmin, np.moveaxis(b.argmin, -1, 1))

    def test_all_inf_line(self):
        dt = distance_transform_1d([[np.inf, np.inf], [1.0, np.inf]])
        np.testing.assert_array_equal(dt.values, [[np.inf, np.inf], [1.0, 2.0]])
        np.testing.assert_array_equal(dt.argmin, [[-1, -1], [0, 0]])

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"f": [1.0, 2.0], "weight": 0.0}, "weight must be"),
            ({"f": [1.0, 2.0], "weight": -1.0}, "weight must be"),
            ({"f": [1.0, np.nan]}, "NaN entries"),
            ({"f": [1.0, -np.inf]}, "-inf entries"),
            ({"f": []}, "non-empty"),
            ({"f": [1.0, 1e200]}, "overflow"),
            ({"f": [1.0], "offset": np.inf}, "offset must be"),
            ({"f": [1.0], "axis": 1}, "axis must be"),
            ({"f": [1.0], "method": "fast"}, "method"),
            ({"f": np.zeros(2049), "method": "brute"}, "use method='envelope'"),
            ({"f": ["a"]}, "real numbers"),
        ],
    )
    def test_bad_inputs(self, kwargs, match):
        with pytest.raises(InputError, match=match):
            distance_transform_1d(**kwargs)


# ==================================================================== 2-D transform


class TestGeneralizedDistanceTransform:
    def test_hand_computed(self):
        f = np.full((3, 4), np.inf)
        f[0, 0] = 0.0
        dt = generalized_distance_transform(f, weights=(1.0, 2.0))
        yy, xx = np.mgrid[:3, :4]
        np.testing.assert_array_equal(dt.values, xx**2 + 2.0 * yy**2)
        assert dt.argmin.shape == (3, 4, 2)
        assert np.all(dt.argmin == 0)

    def test_squared_euclidean_distance_transform_matches_scipy(self):
        # f = 0 on the background, +inf on the object, w = 1: D is the squared
        # Euclidean distance to the nearest background pixel, which is what
        # scipy.ndimage.distance_transform_edt computes (exact integer arithmetic on
        # both sides, so the match is exact)
        ndimage = pytest.importorskip("scipy.ndimage")
        rng = np.random.default_rng(3)
        mask = rng.random((23, 31)) < 0.9  # object
        f = np.where(mask, np.inf, 0.0)
        dt = generalized_distance_transform(f)
        ref = ndimage.distance_transform_edt(mask)
        np.testing.assert_allclose(dt.values, ref**2, rtol=0, atol=1e-9)
        qx, qy = dt.argmin[..., 0], dt.argmin[..., 1]
        assert not mask[qy, qx].any()  # every argmin is a background pixel

    @pytest.mark.parametrize("shape", [(1, 1), (1, 6), (5, 1), (4, 7), (9, 8)])
    @pytest.mark.parametrize("inf_share", [0.0, 0.5, 0.95])
    def test_equals_brute_force(self, shape, inf_share):
        rng = np.random.default_rng(shape[0] * 10 + shape[1] + int(100 * inf_share))
        yy, xx = np.mgrid[: shape[0], : shape[1]]
        for _ in range(8):
            f = random_costs(rng, shape, inf_share)
            w = tuple(rng.choice([1e-3, 0.5, 1.0, 7.3], 2).tolist())
            d = tuple(rng.normal(0, 2, 2).tolist())
            ref = brute_2d(f, w, d)
            fin = np.isfinite(ref)
            for method in ("envelope", "brute"):
                dt = generalized_distance_transform(f, w, d, method=method)
                np.testing.assert_array_equal(np.isinf(dt.values), ~fin)
                np.testing.assert_allclose(dt.values[fin], ref[fin], rtol=RTOL, atol=ATOL)
                qx, qy = dt.argmin[..., 0], dt.argmin[..., 1]
                assert np.all((qx == -1) == ~fin) and np.all((qy == -1) == ~fin)
                got = (
                    f[qy[fin], qx[fin]]
                    + w[0] * (xx[fin] - qx[fin] - d[0]) ** 2
                    + w[1] * (yy[fin] - qy[fin] - d[1]) ** 2
                )
                np.testing.assert_allclose(got, ref[fin], rtol=RTOL, atol=ATOL)

    def test_integer_offset_shifts_the_transform(self):
        # D_d(p) = D_0(p - d): the offset moves the result by d cells
        f = np.random.default_rng(4).normal(size=(8, 9))
        d0 = generalized_distance_transform(f, (0.5, 2.0)).values
        d = generalized_distance_transform(f, (0.5, 2.0), (2, -1)).values
        np.testing.assert_allclose(d[:-1, 2:], d0[1:, :-2], rtol=RTOL, atol=ATOL)

    def test_envelope_kernel_matches_reference_on_a_large_grid(self):
        f = random_costs(np.random.default_rng(5), (60, 70), 0.2)
        a = generalized_distance_transform(f, (0.3, 1.7), (1.25, -2.5))
        b = generalized_distance_transform(f, (0.3, 1.7), (1.25, -2.5), method="brute")
        np.testing.assert_allclose(a.values, b.values, rtol=RTOL, atol=ATOL)

    @pytest.mark.parametrize(
        ("kwargs", "match"),
        [
            ({"f": np.zeros((2, 2)), "weights": (1.0, 0.0)}, r"weights\[1\] must be"),
            ({"f": np.zeros((2, 2)), "weights": (-1.0, 1.0)}, r"weights\[0\] must be"),
            ({"f": np.zeros((2, 2)), "weights": 1.0}, "weights must be a pair"),
            ({"f": np.zeros((2, 2)), "offset": (1.0, 2.0, 3.0)}, "offset must be a pair"),
            ({"f": np.zeros((2, 2)), "offset": (np.nan, 0.0)}, r"offset\[0\] must be"),
            ({"f": np.zeros(4)}, r"must be \(H, W\)"),
            ({"f": np.zeros((0, 3))}, "non-empty"),
            ({"f": np.array([[0.0, np.nan]])}, "NaN"),
        ],
    )
    def test_bad_inputs(self, kwargs, match):
        with pytest.raises(InputError, match=match):
            generalized_distance_transform(**kwargs)


# ==================================================================== the tree


def enumerate_poses(c, parents, mu, w):
    """Every pose's energy: (minimum, its pose, min-marginals) by brute force."""
    n, h, wd = c.shape
    cells = [(x, y) for y in range(h) for x in range(wd)]
    best, arg = np.inf, None
    marg = np.full(c.shape, np.inf)
    for loc in itertools.product(cells, repeat=n):
        e = pose_energy(c, parents, mu, w, loc)
        if e < best:
            best, arg = e, loc
        for i, (x, y) in enumerate(loc):
            marg[i, y, x] = min(marg[i, y, x], e)
    return best, np.array(arg), marg


class TestPictorialStructures:
    @pytest.mark.parametrize("parents", [[-1, 0, 1], [1, -1, 1], [-1, 0, 0], [2, 0, -1]])
    def test_equals_enumeration_of_every_pose(self, parents):
        rng = np.random.default_rng(sum(p * 3**i for i, p in enumerate(parents)) + 10)
        for trial in range(4):
            c = rng.normal(size=(3, 4, 5))
            if trial == 3:
                c[rng.random(c.shape) < 0.4] = np.inf
            mu = rng.normal(0, 1.5, (3, 2))
            w = rng.uniform(0.05, 2.0, (3, 2))
            best, arg, marg = enumerate_poses(c, parents, mu, w)
            for method in ("envelope", "brute"):
                sol = pictorial_structures(c, parents, mu, w, min_marginals=True, method=method)
                assert isinstance(sol, PictorialSolution)
                assert sol.energy == pytest.approx(best, rel=RTOL, abs=ATOL)
                # random real costs: the minimum is unique, so is the pose
                np.testing.assert_array_equal(sol.locations, arg)
                assert pose_energy(c, parents, mu, w, sol.locations) == pytest.approx(
                    sol.energy, rel=RTOL, abs=ATOL
                )
                fin = np.isfinite(marg)
                np.testing.assert_array_equal(np.isfinite(sol.min_marginals), fin)
                np.testing.assert_allclose(sol.min_marginals[fin], marg[fin], rtol=RTOL, atol=ATOL)

    def test_four_joint_star_equals_enumeration(self):
        rng = np.random.default_rng(11)
        c = rng.normal(size=(4, 3, 4))
        parents = [1, -1, 1, 1]
        mu, w = rng.normal(0, 1, (4, 2)), rng.uniform(0.1, 1.5, (4, 2))
        best, arg, marg = enumerate_poses(c, parents, mu, w)
        sol = pictorial_structures(c, parents, mu, w, min_marginals=True)
        assert sol.energy == pytest.approx(best, rel=RTOL, abs=ATOL)
        np.testing.assert_array_equal(sol.locations, arg)
        np.testing.assert_allclose(sol.min_marginals, marg, rtol=RTOL, atol=ATOL)
        assert sol.min_marginals.min(axis=(1, 2)) == pytest.approx([sol.energy] * 4)

    def test_chain_without_appearance_follows_the_offsets(self):
        # zero unary costs: every pose whose springs are at rest has energy 0; the root
        # is placed where its costs are least (here it is pinned at (2, 3))
        c = np.zeros((4, 10, 12))
        c[0] = 1.0
        c[0, 3, 2] = 0.0
        offsets = np.array([[0, 0], [3, 1], [2, 2], [-4, 1]])
        sol = pictorial_structures(c, [-1, 0, 1, 2], offsets, np.ones((4, 2)))
        np.testing.assert_array_equal(sol.locations, [[2, 3], [5, 4], [7, 6], [3, 7]])
        assert sol.energy == 0.0
        assert sol.min_marginals is None

    def test_forbidden_locations_are_avoided(self):
        c = np.zeros((2, 5, 5))
        c[0] = np.inf
        c[0, 2, 2] = 0.0  # the root may only be at (2, 2)
        c[1, 2, 4] = np.inf  # its child may not be at rest, (4, 2)
        sol = pictorial_structures(c, [-1, 0], [[0, 0], [2, 0]], [[1, 1], [1, 2]])
        assert sol.locations[0].tolist() == [2, 2]
        # the nearest allowed cells to (4, 2) cost 1 (x +-1) or 2 (y +-1): x = 3
        assert sol.locations[1].tolist() == [3, 2] and sol.energy == 1.0

    def test_infeasible_is_degenerate(self):
        c = np.zeros((2, 3, 3))
        c[1] = np.inf
        with pytest.raises(DegenerateError, match="infinite energy"):
            pictorial_structures(c, [-1, 0], np.zeros((2, 2)), np.ones((2, 2)))

    def test_mpii_tree(self):
        rng = np.random.default_rng(12)
        c = rng.random((16, 32, 32))
        parents = MPII_16.parents("pelvis")
        mu, w = rng.normal(0, 3, (16, 2)), rng.uniform(0.05, 1, (16, 2))
        sol = pictorial_structures(c, parents, mu, w)
        assert sol.locations.shape == (16, 2)
        assert pose_energy(c, parents, mu, w, sol.locations) == pytest.approx(sol.energy)
        ref = pictorial_structures(c, parents, mu, w, method="brute")
        assert ref.energy == pytest.approx(sol.energy, rel=RTOL)

    def test_root_rows_are_ignored(self):
        c = np.random.default_rng(13).normal(size=(2, 4, 4))
        a = pictorial_structures(c, [-1, 0], [[0, 0], [1, 1]], [[1, 1], [1, 1]])
        b = pictorial_structures(c, [-1, 0], [[np.nan, 5], [1, 1]], [[-3, 0], [1, 1]])
        np.testing.assert_array_equal(a.locations, b.locations)

    @pytest.mark.parametrize(
        ("args", "match"),
        [
            (([-1, 0], [[0, 0], [1, 0]], [[1, 1], [-1, 1]]), "weights must be > 0"),
            (([-1, 0], [[0, 0], [1, 0]], [[1, 1], [0, 1]]), "weights must be > 0"),
            (([-1, 0], [[0, 0], [np.inf, 0]], np.ones((2, 2))), "offsets must be finite"),
            (([-1, -1], np.zeros((2, 2)), np.ones((2, 2))), "must describe a tree"),
            (([1, 0], np.zeros((2, 2)), np.ones((2, 2))), "must describe a tree"),
            (([-1, 1], np.zeros((2, 2)), np.ones((2, 2))), "must describe a tree"),
            (([-1, 5], np.zeros((2, 2)), np.ones((2, 2))), "must describe a tree"),
            (([-1, 0.5], np.zeros((2, 2)), np.ones((2, 2))), "integers"),
            (([-1, 0, 0], np.zeros((2, 2)), np.ones((2, 2))), "one entry per joint"),
            (([-1, 0], np.zeros((3, 2)), np.ones((2, 2))), r"offsets must be \(J, 2\)"),
            (([-1, 0], np.zeros((2, 2)), np.ones(2)), r"weights must be \(J, 2\)"),
        ],
    )
    def test_bad_inputs(self, args, match):
        with pytest.raises(InputError, match=match):
            pictorial_structures(np.zeros((2, 3, 3)), *args)

    def test_cycle_is_not_a_tree(self):
        with pytest.raises(InputError, match="a cycle"):
            pictorial_structures(
                np.zeros((4, 2, 2)), [-1, 2, 3, 1], np.zeros((4, 2)), np.ones((4, 2))
            )

    @pytest.mark.parametrize(
        ("costs", "match"),
        [
            (np.zeros((3, 3)), r"\(J, H, W\)"),
            (np.full((2, 3, 3), np.nan), "NaN"),
            (np.full((2, 3, 3), -np.inf), "-inf"),
        ],
    )
    def test_bad_costs(self, costs, match):
        with pytest.raises(InputError, match=match):
            pictorial_structures(costs, [-1, 0], np.zeros((2, 2)), np.ones((2, 2)))

    def test_bad_flags(self):
        args = (np.zeros((2, 3, 3)), [-1, 0], np.zeros((2, 2)), np.ones((2, 2)))
        with pytest.raises(InputError, match="min_marginals must be True or False"):
            pictorial_structures(*args, min_marginals=1)
        with pytest.raises(InputError, match="method"):
            pictorial_structures(*args, method="dp")
