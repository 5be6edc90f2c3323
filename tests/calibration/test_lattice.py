"""The compiled lattice grower shared by the chessboard and circle-grid detectors."""

from __future__ import annotations

import numpy as np

from robopercept.calibration._lattice import grow_lattice

W, H, SPACING = 7, 5, 20.0


def _project(u, v):
    # a mild perspective map of board coordinates (px) into the image
    den = 1 + 0.002 * u + 0.001 * v
    return np.column_stack([(100 + u + 0.1 * v) / den, (80 + v - 0.05 * u) / den])


def _scene(rng, clutter=40):
    """The 7 x 5 lattice shuffled among clutter points; clutter keeps 10 px (half the
    spacing) from every node of the lattice extended by two nodes on each side, so that
    nothing but lattice nodes lies where the grower looks. Returns the points, the
    lattice's edge directions per point (random for clutter) and node -> point index."""
    i, j = np.meshgrid(np.arange(W), np.arange(H), indexing="ij")
    i, j = i.ravel(), j.ravel()
    nodes = _project(i * SPACING, j * SPACING)
    ei, ej = np.meshgrid(np.arange(-2, W + 2), np.arange(-2, H + 2), indexing="ij")
    extended = _project(ei.ravel() * SPACING, ej.ravel() * SPACING)
    extra = rng.uniform(0, 300, (clutter * 10, 2))
    gap = np.linalg.norm(extra[:, None] - extended[None], axis=2).min(axis=1)
    extra = extra[gap > 10][:clutter]
    assert len(extra) == clutter
    pts = np.vstack([nodes, extra])
    dirs = np.zeros((len(pts), 2, 2))
    for axis, (du, dv) in enumerate(((1e-3, 0.0), (0.0, 1e-3))):
        step = _project(i * SPACING + du, j * SPACING + dv) - nodes
        dirs[: len(nodes), axis] = step / np.linalg.norm(step, axis=1, keepdims=True)
    angle = rng.uniform(0, np.pi, (clutter, 2))
    dirs[len(nodes) :] = np.stack([np.cos(angle), np.sin(angle)], axis=2)
    perm = rng.permutation(len(pts))
    where = np.argsort(perm)  # where[k]: the position of point k after shuffling
    node = {(int(a), int(b)): int(where[k]) for k, (a, b) in enumerate(zip(i, j, strict=True))}
    return pts[perm], dirs[perm], node


def test_grows_the_whole_lattice_through_clutter(rng):
    pts, _, node = _scene(rng)
    # start at lattice node (2, 1) with (3, 1) and (2, 2) as its neighbours
    grid = grow_lattice(pts, node[(2, 1)], node[(3, 1)], node[(2, 2)], limit=20)
    assert len(grid) == W * H
    assert all(node[(a + 2, b + 1)] == k for (a, b), k in grid.items())


def test_stops_at_the_limit(rng):
    pts, _, node = _scene(rng)
    grid = grow_lattice(pts, node[(0, 0)], node[(1, 0)], node[(0, 1)], limit=3)
    ii = [a for a, _ in grid]
    assert max(ii) - min(ii) >= 3 and len(grid) < W * H  # stopped early, still the lattice
    assert all(node[key] == k for key, k in grid.items())


def test_edge_directions_gate_the_growth(rng):
    pts, dirs, node = _scene(rng)
    seeds = node[(0, 0)], node[(1, 0)], node[(0, 1)]
    # the true edge directions: the whole lattice
    grid = grow_lattice(pts, *seeds, 20, dirs)
    assert len(grid) == W * H and all(node[key] == k for key, k in grid.items())
    # directions 45 degrees off every lattice step: nothing joins the three seeds
    turn = np.array([[1.0, -1.0], [1.0, 1.0]]) / np.sqrt(2)
    assert len(grow_lattice(pts, *seeds, 20, dirs @ turn.T)) == 3
