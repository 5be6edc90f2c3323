r"""Point-cloud data for deep learning: procedural shapes with part labels, folders of
meshes and clouds (ModelNet's layout), and the augmentations of PointNet and PointNet++.

Every cloud of a :class:`CloudDataset` holds the same number of points ``N``, float32,
centred on its centroid and scaled so that its farthest point lies at distance 1
(:func:`~robopercept.pointcloud.normalize_unit_sphere`, PointNet's ``pc_normalize``).

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
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import torch
from scipy.spatial import cKDTree

from robopercept._checks import (
    as_path,
    as_rng,
    check_bool,
    check_choice,
    check_file,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.data.datasets import stratified_split
from robopercept.pointcloud import read_point_cloud
from robopercept.pointcloud.mesh import (
    TriangleMesh,
    farthest_point_sampling,
    normalize_unit_sphere,
    read_mesh,
    sample_surface,
)
from robopercept.progress import progress_bar

__all__ = [
    "CLOUD_EXTENSIONS",
    "SHAPE_CLASSES",
    "SHAPE_PARTS",
    "CloudDataset",
    "augment_clouds",
    "procedural_shapes",
    "read_cloud_file",
    "read_cloud_folder",
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

#: file extensions :func:`read_cloud_folder` reads (any case)
CLOUD_EXTENSIONS: tuple[str, ...] = (".off", ".ply", ".pcd")

_VARIANTS = ("clean", "partial", "noisy")
_PART_OFFSET = {
    c: sum(len(SHAPE_PARTS[d]) for d in SHAPE_CLASSES[:i]) for i, c in enumerate(SHAPE_CLASSES)
}
_N_PHI = 32  # segments around an axis of revolution
_MAX_POINTS = 1 << 20  # n_points per cloud
_MAX_HEADER = 1 << 16


# =========================================================================== the data set
def _int_labels(value: Any, name: str, shape: tuple[int, ...], count: int) -> np.ndarray:
    arr = check_numeric(value, name)
    if arr.shape != shape:
        raise InputError(f"{name} must have shape {shape}; got {arr.shape}")
    if arr.size and (not np.isfinite(arr).all() or np.any(arr != np.round(arr))):
        raise InputError(f"{name} must hold whole numbers (class or part ids)")
    if arr.size and (arr.min() < 0 or arr.max() >= count):
        raise InputError(f"{name} must lie in [0, {count}); got {int(arr.min())}..{int(arr.max())}")
    return arr.astype(np.int64)


def _names(value: Any, name: str) -> tuple[str, ...]:
    if isinstance(value, str) or not isinstance(value, (tuple, list)):
        raise InputError(f"{name} must be a tuple of strings; got {plain_repr(value)}")
    if not all(isinstance(v, str) for v in value):
        raise InputError(f"{name} must hold only strings; got {plain_repr(value)}")
    return tuple(value)


@dataclass(frozen=True)
class CloudDataset:
    """Labelled point clouds of ``N`` points each, normalized to the unit sphere.

    Attributes
    ----------
    points : (M, N, 3) float32 ndarray
        Each cloud centred on its centroid with largest norm 1.
    labels : (M,) int64 ndarray
        Class ids into ``class_names``.
    class_names : tuple of str
    parts : (M, N) int64 ndarray or None
        Global part ids into ``part_names`` (procedural shapes), or None.
    part_names : tuple of str
        ``"class/part"`` names.
    part_classes : (P,) int64 ndarray or None
        The class each part id belongs to (ShapeNet-part's mIoU scores only the parts
        of the shape's class).
    names : tuple of str
        The source file of each cloud (read from disk), else empty.
    skipped : tuple of str
        Files :func:`read_cloud_folder` could not read (each warned about).

    Raises
    ------
    InputError
        Shapes or dtypes that do not agree, NaN/inf points, ids out of range.

    Examples
    --------
    >>> ds = procedural_shapes(2, 64, classes=("sphere", "box"), rng=0)
    >>> len(ds), ds.points.shape, ds.num_classes, ds.num_parts
    (4, (4, 64, 3), 2, 5)
    """

    points: np.ndarray
    labels: np.ndarray
    class_names: tuple[str, ...]
    parts: np.ndarray | None = None
    part_names: tuple[str, ...] = ()
    part_classes: np.ndarray | None = None
    names: tuple[str, ...] = ()
    skipped: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        pts = check_numeric(self.points, "points")
        if pts.ndim != 3 or pts.shape[2] != 3:
            hint = ": one cloud? use points[None]" if pts.ndim == 2 and pts.shape[1] == 3 else ""
            raise InputError(f"points must be (M, N, 3); got shape {pts.shape}{hint}")
        if not np.isfinite(pts).all():
            raise InputError("points must be finite; got NaN/inf: drop those points first")
        if pts.size and np.abs(pts).max() > 1e30:
            raise InputError("points must be normalized (float32 range); rescale them")
        object.__setattr__(self, "points", pts.astype(np.float32))
        classes = _names(self.class_names, "class_names")
        if not classes:
            raise InputError("class_names must name at least one class")
        object.__setattr__(self, "class_names", classes)
        m, n = pts.shape[:2]
        object.__setattr__(self, "labels", _int_labels(self.labels, "labels", (m,), len(classes)))
        part_names = _names(self.part_names, "part_names")
        object.__setattr__(self, "part_names", part_names)
        if self.parts is not None:
            if not part_names:
                raise InputError("parts need part_names (one name per part id)")
            parts = _int_labels(self.parts, "parts", (m, n), len(part_names))
            object.__setattr__(self, "parts", parts)
        if self.part_classes is not None:
            pc = _int_labels(self.part_classes, "part_classes", (len(part_names),), len(classes))
            object.__setattr__(self, "part_classes", pc)
        names = _names(self.names, "names")
        if names and len(names) != m:
            raise InputError(f"names must name every cloud ({m}) or none; got {len(names)}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "skipped", _names(self.skipped, "skipped"))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def num_classes(self) -> int:
        """The number of classes, ``len(class_names)``."""
        return len(self.class_names)

    @property
    def num_parts(self) -> int:
        """The number of part ids, ``len(part_names)`` (0 without parts)."""
        return len(self.part_names)

    def subset(self, indices: npt.ArrayLike) -> CloudDataset:
        """The clouds at ``indices`` (integers, in that order), as a new data set.

        Examples
        --------
        >>> ds = procedural_shapes(2, 16, classes=("cone",), rng=0)
        >>> ds.subset([1]).points.shape
        (1, 16, 3)
        """
        raw = check_numeric(indices, "indices").ravel()
        if not np.all(np.isfinite(raw)) or np.any(raw != np.round(raw)):
            raise InputError(f"indices must be whole numbers; got {plain_repr(indices)}")
        idx = raw.astype(np.int64)
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise InputError(f"indices must lie in [0, {len(self)}); got {idx.tolist()[:8]}")
        return CloudDataset(
            self.points[idx],
            self.labels[idx],
            self.class_names,
            None if self.parts is None else self.parts[idx],
            self.part_names,
            self.part_classes,
            tuple(self.names[i] for i in idx) if self.names else (),
            self.skipped,
        )

    def split(
        self,
        fractions: Sequence[float] = (0.8, 0.1, 0.1),
        rng: int | np.random.Generator | None = 0,
    ) -> tuple[CloudDataset, ...]:
        """A seeded split stratified by label: each part holds about the fraction
        ``f_j`` of every class (:func:`~robopercept.nn.data.datasets.stratified_split`); the parts
        are disjoint and cover the set.

        Parameters
        ----------
        fractions : sequence of float
            Positive, summing to 1.
        rng : int, numpy.random.Generator or None

        Returns
        -------
        tuple of CloudDataset
            In the order of ``fractions``.

        Examples
        --------
        >>> ds = procedural_shapes(10, 16, classes=("cone", "box"), rng=0)
        >>> [len(p) for p in ds.split((0.8, 0.2))]
        [16, 4]
        """
        return tuple(self.subset(p) for p in stratified_split(self.labels, fractions, rng))


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


def _pick(points: np.ndarray, n: int, fps: bool, gen: np.random.Generator) -> np.ndarray:
    """``n`` indices of ``points`` (``len >= n``): FPS from a random start, or a random
    draw without replacement."""
    if fps:
        return farthest_point_sampling(points, n, start=None, rng=gen)
    return gen.choice(len(points), n, replace=False)


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
            sel = keep[_pick(pts[keep], n, fps, gen)]
        else:  # pragma: no cover - at least half the points pass the quantile
            sel = gen.choice(keep, n, replace=True)
        pts, parts = pts[sel], parts[sel]
    elif fps:
        sel = _pick(pts, n, fps, gen)
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


def _check_up(up_axis: Any) -> int:
    return int(check_choice(up_axis, "up_axis", (0, 1, 2)))


def _to_up(pts: np.ndarray, up_axis: int) -> np.ndarray:
    """The canonical frame (z up) turned so that z goes to axis ``up_axis`` (a cyclic
    permutation of the axes: a rotation)."""
    return np.roll(pts, up_axis - 2, axis=-1) if up_axis != 2 else pts


def _check_points_count(n_points: Any) -> int:
    n = check_int(n_points, "n_points", 2)
    if n > _MAX_POINTS:
        raise InputError(f"n_points must be at most {_MAX_POINTS}; got {n}")
    return n


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
    n = _check_points_count(n_points)
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
    up = _check_up(up_axis)
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


# =========================================================================== augmentation
def _generator(generator: Any) -> torch.Generator:
    if isinstance(generator, torch.Generator):
        return generator
    if generator is None:
        fresh = torch.Generator()
        fresh.seed()  # a non-deterministic seed, leaving torch's global generator alone
        return fresh
    if isinstance(generator, bool) or not isinstance(generator, (int, np.integer)):
        raise InputError(f"generator must be a torch.Generator or an int seed; got {generator!r}")
    if not -(2**63) <= int(generator) < 2**64:
        raise InputError(f"the seed (generator) must be in [-2**63, 2**64); got {generator}")
    return torch.Generator().manual_seed(int(generator))


def _range_pair(value: Any, name: str) -> tuple[float, float] | None:
    if value is None:
        return None
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"{name} must be (low, high) or None; got {plain_repr(value)}")
    lo = check_real(value[0], f"{name}[0]", 0.0, 1e6, low_inclusive=False)
    hi = check_real(value[1], f"{name}[1]", lo, 1e6)
    return lo, hi


def _quaternion_rotations(q: torch.Tensor) -> torch.Tensor:
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        -1,
    ).reshape(-1, 3, 3)


def augment_clouds(
    points: torch.Tensor,
    generator: torch.Generator | int | None = None,
    *,
    rotate: str | None = "up",
    up_axis: int = 2,
    scale: tuple[float, float] | None = (0.8, 1.25),
    jitter: float = 0.01,
    clip: float = 0.05,
    dropout: float = 0.0,
    shift: float = 0.1,
) -> torch.Tensor:
    r"""Random augmentations of a batch of clouds (those of PointNet and PointNet++).

    For each cloud ``b`` of the batch, in this order:

    1. dropout (PointNet++'s ``random_point_dropout``): a ratio
       :math:`\rho_b \sim U(0, \text{dropout})`; each point with :math:`u \le \rho_b`
       (:math:`u \sim U(0, 1)`) is replaced by the cloud's first point, so ``N`` stays.
    2. rotation: ``"up"``: by :math:`\theta_b \sim U(0, 2\pi)` about axis ``up_axis``
       (that coordinate is left untouched); ``"so3"``: by a uniformly random rotation,
       from a unit quaternion :math:`q = g / \lVert g \rVert`,
       :math:`g \sim \mathcal N(0, I_4)` (uniform on the 3-sphere, hence on SO(3));
       ``None``: none.
    3. anisotropic scale :math:`s_b \in \mathbb R^3`, each :math:`\sim U(\text{scale})`:
       :math:`x \leftarrow s_b \odot x`.
    4. shift :math:`t_b \sim U(-\text{shift}, \text{shift})^3`: :math:`x \leftarrow x + t_b`.
    5. jitter per point: :math:`x \leftarrow x + \text{clip}(\sigma \varepsilon, -c, c)`,
       :math:`\varepsilon \sim \mathcal N(0, I_3)` (PointNet's ``jitter_point_cloud``
       with :math:`\sigma` = ``jitter``, :math:`c` = ``clip``).

    So :math:`x' = s_b \odot (R_b x) + t_b + \text{clip}(\sigma\varepsilon, -c, c)`.
    Random numbers are drawn on the CPU from ``generator`` and moved to the points'
    device: the same seed gives the same result on any device.

    Parameters
    ----------
    points : (B, N, 3) or (N, 3) float torch.Tensor
    generator : torch.Generator, int or None
        The randomness (an int seeds a new generator; None: a fresh random seed).
    rotate : {'up', 'so3', None}
    up_axis : {0, 1, 2}
    scale : (float, float) or None
        ``0 < low <= high``.
    jitter : float
        :math:`\sigma` (>= 0; 0: none).
    clip : float
        :math:`c` (> 0).
    dropout : float
        Largest dropout ratio, in ``[0, 1)``.
    shift : float
        Largest shift per axis (>= 0).

    Returns
    -------
    torch.Tensor
        Same shape, dtype and device; the input is not modified.

    Raises
    ------
    InputError
        Not a float tensor of 3-D points, or a parameter out of range.

    Examples
    --------
    >>> x = torch.rand(2, 64, 3)
    >>> y = augment_clouds(x, 0, scale=None, jitter=0.0, shift=0.0)
    >>> bool(torch.equal(y[..., 2], x[..., 2]))  # rotation about z keeps z
    True
    """
    if not isinstance(points, torch.Tensor):
        raise InputError(
            f"points must be a torch tensor; got {type(points).__name__}: use torch.from_numpy"
        )
    if not points.is_floating_point():
        raise InputError(f"points must be floating point; got dtype {points.dtype}: use .float()")
    if points.ndim not in (2, 3) or points.shape[-1] != 3:
        raise InputError(f"points must be (B, N, 3) or (N, 3); got shape {tuple(points.shape)}")
    if points.shape[-2] == 0:
        raise InputError("points must hold at least one point per cloud")
    single = points.ndim == 2
    x = points[None] if single else points
    gen = _generator(generator)
    rotate = check_choice(cast(Any, rotate), "rotate", ("up", "so3", None))
    up = _check_up(up_axis)
    scl = _range_pair(scale, "scale")
    sigma = check_real(jitter, "jitter", 0.0, 1e6)
    c = check_real(clip, "clip", 0.0, 1e6, low_inclusive=False)
    drop = check_real(dropout, "dropout", 0.0, 1.0, high_inclusive=False)
    sh = check_real(shift, "shift", 0.0, 1e6)
    b, n = x.shape[:2]
    dev, dt = x.device, x.dtype

    def rand(*shape: int) -> torch.Tensor:
        return torch.rand(shape, generator=gen, dtype=torch.float64).to(dev, dt)

    x = x.clone()
    if drop > 0:
        ratio = rand(b) * drop
        mask = rand(b, n) <= ratio[:, None]
        x = torch.where(mask[..., None], x[:, :1].expand_as(x), x)
    if rotate == "up":
        theta = rand(b)[:, None] * (2 * math.pi)
        cos, sin = torch.cos(theta), torch.sin(theta)
        i, j = ((up + 1) % 3, (up + 2) % 3)
        cols = list(x.unbind(-1))
        cols[i], cols[j] = cos * cols[i] - sin * cols[j], sin * cols[i] + cos * cols[j]
        x = torch.stack(cols, -1)
    elif rotate == "so3":
        g = torch.randn((b, 4), generator=gen, dtype=torch.float64)
        q = g / g.norm(dim=1, keepdim=True).clamp_min(1e-12)
        r = _quaternion_rotations(q).to(dev, dt)
        x = x @ r.transpose(1, 2)
    if scl is not None:
        x = x * (scl[0] + (scl[1] - scl[0]) * rand(b, 3))[:, None]
    if sh > 0:
        x = x + ((2 * rand(b, 3) - 1) * sh)[:, None]
    if sigma > 0:
        eps = torch.randn((b, n, 3), generator=gen, dtype=torch.float64).to(dev, dt)
        x = x + (sigma * eps).clamp(-c, c)
    return x[0] if single else x


# =========================================================================== files
def _ply_has_faces(path: Path) -> bool:
    """Whether a PLY header declares a ``face`` element with at least one face."""
    try:
        with path.open("rb") as fh:
            head = fh.read(_MAX_HEADER).decode("ascii", errors="replace")
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    for line in head[: max(head.find("end_header"), 0)].splitlines():
        parts = line.split()
        if parts[:2] == ["element", "face"] and len(parts) > 2:
            return parts[2].isdigit() and int(parts[2]) > 0
    return False


def _file_cloud(path: Path, n: int, fps: bool, gen: np.random.Generator) -> np.ndarray:
    suffix = path.suffix.lower()
    if suffix not in CLOUD_EXTENSIONS:
        raise FileFormatError(
            f"{path}: unknown extension {suffix!r}: read {', '.join(CLOUD_EXTENSIONS)}"
        )
    if suffix == ".off" or (suffix == ".ply" and _ply_has_faces(path)):
        mesh = read_mesh(path)
        try:
            pts, _ = sample_surface(mesh, 4 * n if fps else n, gen)
        except DegenerateError as exc:
            raise DegenerateError(f"{path}: {exc}") from None
        if fps:
            pts = pts[farthest_point_sampling(pts, n, start=None, rng=gen)]
    else:
        pts = read_point_cloud(path).points
        pts = pts[np.isfinite(pts).all(1)]
        if len(pts) == 0:
            raise DegenerateError(f"{path}: no finite point")
        if len(pts) >= n:
            if fps and len(pts) > 8 * n:  # FPS from a random 8 n of them: O(8 n^2)
                pts = pts[gen.choice(len(pts), 8 * n, replace=False)]
            pts = pts[_pick(pts, n, fps, gen)]
        else:  # every point once, the rest drawn with replacement
            pts = pts[np.concatenate([np.arange(len(pts)), gen.choice(len(pts), n - len(pts))])]
    return normalize_unit_sphere(pts)[0].astype(np.float32)


def read_cloud_file(
    path: str | os.PathLike[str],
    n_points: int = 1024,
    rng: int | np.random.Generator | None = 0,
    *,
    fps: bool = True,
) -> np.ndarray:
    """One mesh or cloud file as ``n_points`` points normalized to the unit sphere.

    A mesh (``.off``, or ``.ply`` with faces) gets ``4 n_points`` area-uniform surface
    samples (:func:`~robopercept.pointcloud.sample_surface`) thinned to ``n_points``
    by farthest point sampling from a random start (``fps=False``: ``n_points``
    samples). A cloud (``.pcd``, ``.ply`` without faces) loses its NaN/inf points; with
    at least ``n_points`` left it is thinned by FPS (from a random ``8 n_points`` of
    them when it has more; ``fps=False``: a random draw without replacement); with
    fewer, every point is kept once and the rest are drawn with replacement. Then
    :func:`~robopercept.pointcloud.normalize_unit_sphere`.

    Parameters
    ----------
    path : str or path-like
    n_points : int
        In ``[2, 2**20]``.
    rng : int, numpy.random.Generator or None
        Seed of the sampling.
    fps : bool

    Returns
    -------
    (n_points, 3) float32 ndarray

    Raises
    ------
    FileFormatError
        Missing, unreadable or corrupt file, unknown extension.
    DegenerateError
        A mesh of zero area, a cloud with no finite point or all points equal.
    InputError
        ``n_points`` out of range.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "tri.off"
    >>> _ = p.write_text("OFF\\n3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> read_cloud_file(p, 32).shape
    (32, 3)
    """
    p = check_file(path, "a mesh or point cloud (.off, .ply or .pcd)")
    n = _check_points_count(n_points)
    fps = check_bool(fps, "fps")
    return _file_cloud(p, n, fps, as_rng(rng))


def read_cloud_folder(
    root: str | os.PathLike[str],
    n_points: int = 1024,
    *,
    split: str | None = None,
    fps: bool = True,
    rng: int | np.random.Generator | None = 0,
    progress: bool = True,
) -> CloudDataset:
    """A folder of meshes and clouds, one subfolder per class, as a :class:`CloudDataset`.

    Layouts: ``root/<class>/*.off|*.ply|*.pcd`` and ModelNet's
    ``root/<class>/{train,test}/*.off``. Every subfolder of ``root`` (not starting
    with ``.``) is a class; classes are sorted by name and numbered from 0, and a class
    keeps its number even when the chosen split has no file of it (so the train and
    test sets agree). ``split="train"`` (or ``"test"``) reads ``root/<class>/train/``
    only; ``None`` reads every file under ``root/<class>/``, subfolders included.
    Each file becomes ``n_points`` normalized points by :func:`read_cloud_file`'s rules,
    files in sorted order, all drawn from one generator seeded by ``rng``.

    Files that cannot be read (corrupt, empty mesh, zero area ...) are skipped: one
    warning names them and the data set's ``skipped`` lists them.

    Parameters
    ----------
    root : str or path-like
    n_points : int
        In ``[2, 2**20]``.
    split : {'train', 'test'} or None
    fps : bool
        See :func:`read_cloud_file`.
    rng : int, numpy.random.Generator or None
    progress : bool
        Show a progress bar.

    Returns
    -------
    CloudDataset
        Without parts; ``names`` holds each cloud's file.

    Raises
    ------
    InputError
        ``root`` is not a folder, has no class subfolder, or no readable file in the
        layout; bad ``n_points`` or ``split``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> root = pathlib.Path(tempfile.mkdtemp())
    >>> (root / "tri").mkdir()
    >>> _ = (root / "tri" / "a.off").write_text("OFF 3 1 0\\n0 0 0\\n1 0 0\\n0 1 0\\n3 0 1 2\\n")
    >>> ds = read_cloud_folder(root, 16, progress=False)
    >>> ds.class_names, ds.points.shape
    (('tri',), (1, 16, 3))
    """
    folder = as_path(root, "root (the cloud folder)")
    n = _check_points_count(n_points)
    split = check_choice(cast(Any, split), "split", (None, "train", "test"))
    fps = check_bool(fps, "fps")
    progress = check_bool(progress, "progress")
    gen = as_rng(rng)
    layout = "root/<class>/*.off|*.ply|*.pcd or ModelNet's root/<class>/{train,test}/*.off" + (
        f" (split={split!r} reads root/<class>/{split}/)" if split else ""
    )
    if not folder.is_dir():
        raise InputError(f"cloud folder {str(folder)!r} does not exist or is not a folder")
    class_dirs = sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))
    if not class_dirs:
        raise InputError(
            f"cloud folder {str(folder)!r} has no class subfolders: lay it out as {layout}"
        )
    files: list[tuple[Path, int]] = []
    for label, cdir in enumerate(class_dirs):
        base = cdir / split if split else cdir
        if not base.is_dir():
            continue
        found = base.iterdir() if split else base.rglob("*")
        for f in sorted(found):
            rel = f.relative_to(cdir).parts
            if (
                f.is_file()
                and f.suffix.lower() in CLOUD_EXTENSIONS
                and not any(r.startswith(".") for r in rel)
            ):
                files.append((f, label))
    check_allocation(len(files) * n * 3, 4, f"{len(files)} clouds of {n} points", "lower n_points")
    clouds: list[np.ndarray] = []
    labels: list[int] = []
    names: list[str] = []
    skipped: list[str] = []
    for f, label in progress_bar(files, desc="reading clouds", unit="file", disable=not progress):
        try:
            pts = _file_cloud(f, n, fps, gen)
        except (FileFormatError, DegenerateError, InputError, OSError):
            skipped.append(str(f))
            continue
        clouds.append(pts)
        labels.append(label)
        names.append(str(f))
    if skipped:
        shown = ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else "")
        warnings.warn(
            f"read_cloud_folder skipped {len(skipped)} unreadable file(s) in {str(folder)!r} "
            f"(see .skipped): {shown}",
            stacklevel=2,
        )
    if not clouds:
        raise InputError(
            f"cloud folder {str(folder)!r} has no readable mesh or cloud file"
            + (f" ({len(skipped)} could not be read)" if skipped else "")
            + f": expected {layout}"
        )
    return CloudDataset(
        np.stack(clouds),
        np.array(labels, np.int64),
        tuple(p.name for p in class_dirs),
        names=tuple(names),
        skipped=tuple(skipped),
    )
