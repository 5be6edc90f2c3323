r"""Procedural point-cloud shapes with part labels: twelve classes of labelled meshes
(:func:`shape_mesh`) and data sets of labelled clouds sampled from them
(:func:`procedural_shapes`, a :class:`~robopercept.nn.cloud.data.CloudDataset` with
per-point part labels).

Procedural shapes
-----------------
:func:`shape_mesh` builds one random instance of a class of :data:`SHAPE_CLASSES` as a
:class:`~robopercept.pointcloud.TriangleMesh` whose ``face_labels`` are part ids, in a
canonical frame with z up (sizes relative to the first dimension, which is 1; all
ranges uniform):

=========  =============================================================  ===========
class      proportions                                                    parts
=========  =============================================================  ===========
sphere     semi-axes each in [0.95, 1.05]                                 upper, lower
box        edges 1 x [0.4, 1] x [0.3, 1.5] (height)                       top, bottom,
                                                                          sides
cylinder   radius 1, height [0.6, 3]                                      side, top,
                                                                          bottom
cone       base radius 1, height [0.8, 2.5]                               side, base
torus      ring radius 1 (lying flat), tube radius [0.15, 0.45]           outer, inner
pyramid    rectangular base 1 x [0.7, 1], height [0.6, 1.6]               faces, base
plane      slab 1 x [0.6, 1], thickness [0.02, 0.05] (flat)               top, bottom
capsule    radius 1, straight length [1, 3] between two hemispheres       body, top,
           (upright)                                                      bottom
ellipsoid  semi-axes 1 x [0.35, 0.75] x [0.35, 0.75]; the long axis is    middle, ends
           vertical or horizontal (probability 1/2 each)
l_shape    an L-prism: arm 1 long, [0.15, 0.3] thick, a second arm        long_arm,
           [0.4, 0.8] high at one end, depth [0.15, 0.5]                  short_arm
table      top 1 x [0.5, 1] x [0.03, 0.08], 4 legs [0.4, 0.9] high with   top, legs
           square section [0.04, 0.1], inset [0, 0.1]
mug        open cylinder radius 1, height [1.2, 2.2] with a bottom, and   body, handle
           a half-torus handle (radius [0.25, 0.35] h, tube [0.06, 0.1] h)
=========  =============================================================  ===========

The ranges keep look-alike classes apart: a sphere's axes differ by at most 10 % but an
ellipsoid's short axes are at most 0.75 of its long one; a capsule has round caps and a
cylinder flat ones; a cone a round base and a pyramid a square one; a box is at least
0.3 thick and a plane at most 0.05. Part boundaries: ``upper``/``lower`` at the equator;
ellipsoid ``ends`` where ``|t| > a/2`` along the long axis (semi-axis ``a``);
torus ``outer`` where the surface is farther from the axis than the tube's centre;
plane ``top`` is the upper face and the upper half of the rim. Part ids are global
(:data:`SHAPE_PARTS` in class order: ``sphere/upper`` = 0, ``sphere/lower`` = 1,
``box/top`` = 2, ...), as in ShapeNet-part, whose mIoU only scores the parts of the
shape's own class (``part_classes``).

:func:`procedural_shapes` turns meshes into labelled clouds: ``n_points`` area-uniform
surface samples (:func:`~robopercept.pointcloud.sample_surface`; with ``fps=True``,
``4 n_points`` samples thinned by farthest point sampling, more even but about
15 ms a shape), each point labelled with its triangle's part, a random rotation about
the up axis, unit-sphere normalization, Gaussian jitter, normalization again. Variants:

* ``"clean"``: jitter sigma 0.005.
* ``"partial"``: a partial view: for a random direction ``d`` (azimuth ``U(0, 360)``
  degrees, elevation ``U(-20, 45)``) only the points whose ``p . d`` is above its
  ``q``-quantile, ``q ~ U(0.3, 0.5)``, are kept (the 50-70 % of the surface facing
  ``d``; no hidden-point removal), then ``n_points`` of them drawn without
  replacement (or by FPS); jitter 0.005.
* ``"noisy"``: jitter sigma 0.04 and 10 % of the points replaced by outliers uniform
  in the unit ball (not the cube: its corners would dominate the final
  normalization), each labelled with the part of its nearest surface point.

Everything is drawn from one ``numpy.random.Generator``: the same seed gives the same
data set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from robopercept._checks import as_rng, check_bool, check_choice, check_int, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.cloud.data import CloudDataset, check_n_points, pick_points
from robopercept.pointcloud.mesh import TriangleMesh, normalize_unit_sphere, sample_surface
from robopercept.progress import progress_bar

__all__ = [
    "SHAPE_CLASSES",
    "SHAPE_PARTS",
    "procedural_shapes",
    "shape_mesh",
]

#: the procedural shape classes, in label order
SHAPE_CLASSES: tuple[str, ...] = (
    "sphere",
    "box",
    "cylinder",
    "cone",
    "torus",
    "pyramid",
    "plane",
    "capsule",
    "ellipsoid",
    "l_shape",
    "table",
    "mug",
)

#: the parts of each class, in part-id order (global ids count through the classes)
SHAPE_PARTS: dict[str, tuple[str, ...]] = {
    "sphere": ("upper", "lower"),
    "box": ("top", "bottom", "sides"),
    "cylinder": ("side", "top", "bottom"),
    "cone": ("side", "base"),
    "torus": ("outer", "inner"),
    "pyramid": ("faces", "base"),
    "plane": ("top", "bottom"),
    "capsule": ("body", "top", "bottom"),
    "ellipsoid": ("middle", "ends"),
    "l_shape": ("long_arm", "short_arm"),
    "table": ("top", "legs"),
    "mug": ("body", "handle"),
}


_VARIANTS = ("clean", "partial", "noisy")
_PART_OFFSET = {
    c: sum(len(SHAPE_PARTS[d]) for d in SHAPE_CLASSES[:i]) for i, c in enumerate(SHAPE_CLASSES)
}
_N_PHI = 32  # segments around an axis of revolution


# =========================================================================== the meshes
Piece = tuple[np.ndarray, np.ndarray, np.ndarray]


def _revolve(r: np.ndarray, z: np.ndarray, labels: np.ndarray, n_phi: int = _N_PHI) -> Piece:
    """The surface of revolution about z of the profile ``(r(t), z(t))``; ``labels`` per
    profile segment. Triangles at ``r = 0`` have zero area (never sampled)."""
    phi = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
    t, w = len(r), n_phi + 1
    v = np.stack(
        [r[:, None] * np.cos(phi), r[:, None] * np.sin(phi), np.repeat(z[:, None], w, 1)], -1
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(t - 1), np.arange(n_phi), indexing="ij")
    a = (i * w + j).ravel()
    faces = np.concatenate([np.stack([a, a + 1, a + w + 1], 1), np.stack([a, a + w + 1, a + w], 1)])
    lab = np.tile(np.asarray(labels)[i.ravel()], 2)
    return v, faces, lab


def _disk(radius: float, z: float, label: int) -> Piece:
    return _revolve(np.array([0.0, radius]), np.array([z, z]), np.array([label]))


def _quad(p0: Sequence[float], e1: Sequence[float], e2: Sequence[float], label: int) -> Piece:
    p = np.asarray(p0, float)
    a, b = np.asarray(e1, float), np.asarray(e2, float)
    v = np.stack([p, p + a, p + a + b, p + b])
    return v, np.array([[0, 1, 2], [0, 2, 3]]), np.array([label, label])


def _box(
    lo: Sequence[float],
    hi: Sequence[float],
    top: int,
    bottom: int,
    sides: int,
    with_top: bool = True,
) -> list[Piece]:
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
    pieces = [
        _quad((x0, y0, z0), (dx, 0, 0), (0, dy, 0), bottom),
        _quad((x0, y0, z0), (dx, 0, 0), (0, 0, dz), sides),
        _quad((x0, y1, z0), (dx, 0, 0), (0, 0, dz), sides),
        _quad((x0, y0, z0), (0, dy, 0), (0, 0, dz), sides),
        _quad((x1, y0, z0), (0, dy, 0), (0, 0, dz), sides),
    ]
    if with_top:
        pieces.append(_quad((x0, y0, z1), (dx, 0, 0), (0, dy, 0), top))
    return pieces


def _join(pieces: list[Piece]) -> Piece:
    offsets = np.cumsum([0] + [len(p[0]) for p in pieces[:-1]])
    v = np.concatenate([p[0] for p in pieces])
    f = np.concatenate([p[1] + o for p, o in zip(pieces, offsets, strict=True)])
    lab = np.concatenate([p[2] for p in pieces])
    return v, f, lab


def _sphere(gen: np.random.Generator) -> Piece:
    th = np.linspace(0.0, np.pi, 17)
    v, f, lab = _revolve(np.sin(th), np.cos(th), (np.arange(16) >= 8).astype(int))
    return v * gen.uniform(0.95, 1.05, 3), f, lab


def _box_shape(gen: np.random.Generator) -> Piece:
    b, c = gen.uniform(0.4, 1.0), gen.uniform(0.3, 1.5)
    return _join(_box((-0.5, -b / 2, -c / 2), (0.5, b / 2, c / 2), 0, 1, 2))


def _cylinder(gen: np.random.Generator) -> Piece:
    h = gen.uniform(0.6, 3.0)
    side = _revolve(np.array([1.0, 1.0]), np.array([-h / 2, h / 2]), np.array([0]))
    return _join([side, _disk(1.0, h / 2, 1), _disk(1.0, -h / 2, 2)])


def _cone(gen: np.random.Generator) -> Piece:
    h = gen.uniform(0.8, 2.5)
    side = _revolve(np.array([1.0, 0.0]), np.array([0.0, h]), np.array([0]))
    return _join([side, _disk(1.0, 0.0, 1)])


def _torus(gen: np.random.Generator) -> Piece:
    rho = gen.uniform(0.15, 0.45)
    psi = np.linspace(-np.pi, np.pi, 25)
    mid = 0.5 * (psi[1:] + psi[:-1])
    return _revolve(1.0 + rho * np.cos(psi), rho * np.sin(psi), (np.cos(mid) < 0).astype(int))


def _pyramid(gen: np.random.Generator) -> Piece:
    b, h = gen.uniform(0.7, 1.0), gen.uniform(0.6, 1.6)
    c = np.array([[-0.5, -b / 2, 0], [0.5, -b / 2, 0], [0.5, b / 2, 0], [-0.5, b / 2, 0]])
    v = np.vstack([c, [[0.0, 0.0, h]]])
    f = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4], [0, 2, 1], [0, 3, 2]])
    return v, f, np.array([0, 0, 0, 0, 1, 1])


def _plane(gen: np.random.Generator) -> Piece:
    b, t = gen.uniform(0.6, 1.0), gen.uniform(0.02, 0.05)
    x0, y0, h = -0.5, -b / 2, t / 2
    pieces = [
        _quad((x0, y0, h), (1, 0, 0), (0, b, 0), 0),
        _quad((x0, y0, -h), (1, 0, 0), (0, b, 0), 1),
    ]
    for z0, lab in ((0.0, 0), (-h, 1)):  # the rim, upper and lower halves
        pieces += [
            _quad((x0, y0, z0), (1, 0, 0), (0, 0, h), lab),
            _quad((x0, -y0, z0), (1, 0, 0), (0, 0, h), lab),
            _quad((x0, y0, z0), (0, b, 0), (0, 0, h), lab),
            _quad((-x0, y0, z0), (0, b, 0), (0, 0, h), lab),
        ]
    return _join(pieces)


def _capsule(gen: np.random.Generator) -> Piece:
    half = gen.uniform(1.0, 3.0) / 2
    body = _revolve(np.array([1.0, 1.0]), np.array([-half, half]), np.array([0]))
    th = np.linspace(0.0, np.pi / 2, 9)
    top = _revolve(np.sin(th), half + np.cos(th), np.ones(8, int))
    th = np.linspace(np.pi / 2, np.pi, 9)
    bottom = _revolve(np.sin(th), -half + np.cos(th), np.full(8, 2))
    return _join([body, top, bottom])


def _ellipsoid(gen: np.random.Generator) -> Piece:
    b, c = gen.uniform(0.35, 0.75, 2)
    th = np.linspace(0.0, np.pi, 19)  # segments 6..11 lie where |cos| < 1/2
    seg = np.arange(18)
    v, f, lab = _revolve(np.sin(th), np.cos(th), ((seg < 6) | (seg >= 12)).astype(int))
    v = v * np.array([b, c, 1.0])
    if gen.random() < 0.5:  # the long axis horizontal
        v = v[:, [2, 1, 0]]
    return v, f, lab


def _l_shape(gen: np.random.Generator) -> Piece:
    w, arm, d = gen.uniform(0.15, 0.3), gen.uniform(0.4, 0.8), gen.uniform(0.15, 0.5)
    y0, ey = -d / 2, (0.0, d, 0.0)
    top = w + arm
    pieces = []
    for y in (y0, -y0):  # the two L-shaped ends, as two rectangles each
        pieces += [
            _quad((0, y, 0), (1, 0, 0), (0, 0, w), 0),
            _quad((0, y, w), (w, 0, 0), (0, 0, arm), 1),
        ]
    pieces += [
        _quad((0, y0, 0), (1, 0, 0), ey, 0),  # bottom
        _quad((1, y0, 0), (0, 0, w), ey, 0),  # far end
        _quad((w, y0, w), (1 - w, 0, 0), ey, 0),  # top of the long arm
        _quad((0, y0, 0), (0, 0, w), ey, 0),  # outer side, lower
        _quad((0, y0, w), (0, 0, arm), ey, 1),  # outer side, upper
        _quad((w, y0, w), (0, 0, arm), ey, 1),  # inner side of the short arm
        _quad((0, y0, top), (w, 0, 0), ey, 1),  # top of the short arm
    ]
    return _join(pieces)


def _table(gen: np.random.Generator) -> Piece:
    b, t = gen.uniform(0.5, 1.0), gen.uniform(0.03, 0.08)
    h, s, e = gen.uniform(0.4, 0.9), gen.uniform(0.04, 0.1), gen.uniform(0.0, 0.1)
    pieces = _box((-0.5, -b / 2, h), (0.5, b / 2, h + t), 0, 0, 0)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x = sx * (0.5 - e - s / 2)
            y = sy * (b / 2 - e - s / 2)
            lo, hi = (x - s / 2, y - s / 2, 0.0), (x + s / 2, y + s / 2, h)
            pieces += _box(lo, hi, 1, 1, 1, with_top=False)
    return _join(pieces)


def _mug(gen: np.random.Generator) -> Piece:
    h = gen.uniform(1.2, 2.2)
    big, tube = gen.uniform(0.25, 0.35) * h, gen.uniform(0.06, 0.1) * h
    body = _revolve(np.array([1.0, 1.0]), np.array([0.0, h]), np.array([0]))
    al = np.linspace(-np.pi / 2, np.pi / 2, 13)[:, None]
    ps = np.linspace(0.0, 2 * np.pi, 13)[None, :]
    ring = np.broadcast_to(big + tube * np.cos(ps), (13, 13))
    v = np.stack(
        [
            1.0 + ring * np.cos(al),
            np.broadcast_to(tube * np.sin(ps), ring.shape),
            h / 2 + ring * np.sin(al),
        ],
        -1,
    ).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(12), np.arange(12), indexing="ij")
    a = (i * 13 + j).ravel()
    f = np.concatenate([np.stack([a, a + 1, a + 14], 1), np.stack([a, a + 14, a + 13], 1)])
    handle = (v, f, np.ones(len(f), int))
    return _join([body, _disk(1.0, 0.0, 0), handle])


_BUILDERS = {
    "sphere": _sphere,
    "box": _box_shape,
    "cylinder": _cylinder,
    "cone": _cone,
    "torus": _torus,
    "pyramid": _pyramid,
    "plane": _plane,
    "capsule": _capsule,
    "ellipsoid": _ellipsoid,
    "l_shape": _l_shape,
    "table": _table,
    "mug": _mug,
}


def _check_class(name: Any) -> str:
    if not isinstance(name, str) or name not in SHAPE_CLASSES:
        raise InputError(
            f"unknown shape class {plain_repr(name)}: choose from {', '.join(SHAPE_CLASSES)}"
        )
    return name


def _build(name: str, gen: np.random.Generator) -> TriangleMesh:
    v, f, lab = _BUILDERS[name](gen)
    return TriangleMesh(v, f, lab + _PART_OFFSET[name])


def shape_mesh(name: str, rng: int | np.random.Generator | None = None) -> TriangleMesh:
    """One random instance of a procedural shape class, as a labelled triangle mesh.

    See the module docstring for the proportions and parts of each class. The mesh is
    in its canonical frame (z up, not normalized); curved surfaces have 32 segments
    around their axis.

    Parameters
    ----------
    name : str
        One of :data:`SHAPE_CLASSES`.
    rng : int, numpy.random.Generator or None
        Seed of the proportions.

    Returns
    -------
    TriangleMesh
        ``face_labels`` are global part ids (``SHAPE_PARTS`` counted through
        ``SHAPE_CLASSES``: sphere 0-1, box 2-4, ...).

    Raises
    ------
    InputError
        An unknown class name.

    Examples
    --------
    >>> m = shape_mesh("cone", rng=0)
    >>> sorted(set(m.face_labels.tolist()))  # cone/side, cone/base
    [8, 9]
    """
    return _build(_check_class(name), as_rng(rng))


# =========================================================================== clouds
def _rotate_up(p: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    out = p.copy()
    out[:, 0] = c * p[:, 0] - s * p[:, 1]
    out[:, 1] = s * p[:, 0] + c * p[:, 1]
    return out


def _unit_ball(gen: np.random.Generator, m: int) -> np.ndarray:
    d = gen.standard_normal((m, 3))
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    return d * gen.random((m, 1)) ** (1.0 / 3.0)


def _shape_cloud(
    mesh: TriangleMesh, n: int, variant: str, fps: bool, gen: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """One labelled cloud of ``mesh``: ``(n, 3)`` in the canonical frame, normalized."""
    labels = mesh.face_labels if mesh.face_labels is not None else np.zeros(len(mesh), np.int64)
    k = 4 * n if fps else n
    if variant == "partial":
        k = 2 * k + 2
    pts, faces = sample_surface(mesh, k, gen)
    parts = labels[faces]
    if variant == "partial":
        az, el = gen.uniform(0, 2 * np.pi), np.deg2rad(gen.uniform(-20, 45))
        d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        proj = pts @ d
        keep = np.flatnonzero(proj >= np.quantile(proj, gen.uniform(0.3, 0.5)))
        if len(keep) >= n:
            sel = keep[pick_points(pts[keep], n, fps, gen)]
        else:  # pragma: no cover - at least half the points pass the quantile
            sel = gen.choice(keep, n, replace=True)
        pts, parts = pts[sel], parts[sel]
    elif fps:
        sel = pick_points(pts, n, fps, gen)
        pts, parts = pts[sel], parts[sel]
    pts = _rotate_up(pts, gen.uniform(0, 2 * np.pi))
    pts = _normalized(pts)
    sigma = 0.04 if variant == "noisy" else 0.005
    pts = pts + sigma * gen.standard_normal(pts.shape)
    if variant == "noisy":
        m = max(1, round(0.1 * n))
        out = gen.choice(n, m, replace=False)
        inl = np.setdiff1d(np.arange(n), out)
        pts[out] = _unit_ball(gen, m)
        if len(inl):
            parts[out] = parts[inl[cKDTree(pts[inl]).query(pts[out])[1]]]
    return _normalized(pts), parts


def _normalized(pts: np.ndarray) -> np.ndarray:
    return normalize_unit_sphere(pts)[0]


def _to_up(pts: np.ndarray, up_axis: int) -> np.ndarray:
    """The canonical frame (z up) turned so that z goes to axis ``up_axis`` (a cyclic
    permutation of the axes: a rotation)."""
    return np.roll(pts, up_axis - 2, axis=-1) if up_axis != 2 else pts


def procedural_shapes(
    n_per_class: int,
    n_points: int = 1024,
    *,
    classes: Sequence[str] | None = None,
    variant: str = "clean",
    up_axis: int = 2,
    fps: bool = False,
    rng: int | np.random.Generator | None = None,
    progress: bool = False,
) -> CloudDataset:
    """A labelled data set of procedural shapes, with per-point part labels.

    See the module docstring for the classes, their parts, and the variants. Clouds
    are ordered class by class (``n_per_class`` of each, in the order of ``classes``).

    Parameters
    ----------
    n_per_class : int
        Shapes per class (>= 1).
    n_points : int
        Points per cloud, in ``[2, 2**20]``.
    classes : sequence of str, optional
        A subset of :data:`SHAPE_CLASSES` (default all), in label order; parts are
        renumbered to the parts of these classes only.
    variant : {'clean', 'partial', 'noisy'}
    up_axis : {0, 1, 2}
        The axis that points up (z by default; 1 for ShapeNet's y up). The canonical z
        is turned to it by a cyclic permutation of the axes (a rotation, no mirror).
    fps : bool
        Draw ``4 n_points`` surface samples and thin them by farthest point sampling
        (more even, about 15 ms a shape) instead of ``n_points`` samples.
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same data set.
    progress : bool
        Show a progress bar.

    Returns
    -------
    CloudDataset
        With ``parts``, ``part_names`` (``"class/part"``) and ``part_classes``.

    Raises
    ------
    InputError
        Unknown class or variant, counts out of range, more than 1 GiB of points.

    Examples
    --------
    >>> ds = procedural_shapes(1, 128, classes=("torus", "mug"), rng=0)
    >>> ds.labels.tolist(), ds.part_names
    ([0, 1], ('torus/outer', 'torus/inner', 'mug/body', 'mug/handle'))
    >>> bool(ds.part_classes[ds.parts[1]].tolist() == [1] * 128)
    True
    """
    per = check_int(n_per_class, "n_per_class", 1)
    n = check_n_points(n_points)
    if classes is None:
        names = SHAPE_CLASSES
    else:
        if isinstance(classes, str) or not isinstance(classes, (tuple, list)):
            raise InputError(
                f"classes must be a sequence of class names, e.g. ('sphere', 'box'); "
                f"got {plain_repr(classes)}"
            )
        names = tuple(_check_class(c) for c in classes)
        if not names or len(set(names)) != len(names):
            raise InputError(f"classes must name distinct classes, at least one; got {names}")
    variant = check_choice(variant, "variant", _VARIANTS)
    up = int(check_choice(up_axis, "up_axis", (0, 1, 2)))
    fps = check_bool(fps, "fps")
    progress = check_bool(progress, "progress")
    m = per * len(names)
    check_allocation(m * n * 3, 4, f"{m} clouds of {n} points", "lower n_per_class or n_points")
    gen = as_rng(rng)
    part_names: list[str] = []
    part_classes: list[int] = []
    remap = np.full(sum(len(p) for p in SHAPE_PARTS.values()), -1, np.int64)
    for k, c in enumerate(names):
        for j, part in enumerate(SHAPE_PARTS[c]):
            remap[_PART_OFFSET[c] + j] = len(part_names)
            part_names.append(f"{c}/{part}")
            part_classes.append(k)
    points = np.empty((m, n, 3), np.float32)
    parts = np.empty((m, n), np.int64)
    labels = np.repeat(np.arange(len(names)), per)
    bar = progress_bar(total=m, desc="procedural shapes", unit="shape", disable=not progress)
    with bar:
        for i in range(m):
            mesh = _build(names[labels[i]], gen)
            pts, lab = _shape_cloud(mesh, n, variant, fps, gen)
            points[i] = _to_up(pts, up)
            parts[i] = remap[lab]
            bar.update(1)
    return CloudDataset(
        points, labels, names, parts, tuple(part_names), np.array(part_classes, np.int64)
    )
