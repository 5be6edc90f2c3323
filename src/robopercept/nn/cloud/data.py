r"""Point-cloud data for deep learning: the labelled data set (:class:`CloudDataset`),
folders of meshes and clouds (ModelNet's layout), and the augmentations of PointNet and
PointNet++ (:func:`augment_clouds`). The procedural shapes with part labels are in
:mod:`robopercept.nn.cloud.synthetic`.

Every cloud of a :class:`CloudDataset` holds the same number of points ``N``, float32,
centred on its centroid and scaled so that its farthest point lies at distance 1
(:func:`~robopercept.pointcloud.normalize_unit_sphere`, PointNet's ``pc_normalize``).
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
    farthest_point_sampling,
    normalize_unit_sphere,
    read_mesh,
    sample_surface,
)
from robopercept.progress import progress_bar

__all__ = [
    "CLOUD_EXTENSIONS",
    "MAX_POINTS",
    "CloudDataset",
    "augment_clouds",
    "check_n_points",
    "pick_points",
    "read_cloud_file",
    "read_cloud_folder",
    "sample_cloud",
]

#: file extensions :func:`read_cloud_folder` reads (any case)
CLOUD_EXTENSIONS: tuple[str, ...] = (".off", ".ply", ".pcd")

#: the most points per cloud
MAX_POINTS = 1 << 20
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
    >>> from robopercept.nn.cloud.synthetic import procedural_shapes
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
        >>> from robopercept.nn.cloud.synthetic import procedural_shapes
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
        >>> from robopercept.nn.cloud.synthetic import procedural_shapes
        >>> ds = procedural_shapes(10, 16, classes=("cone", "box"), rng=0)
        >>> [len(p) for p in ds.split((0.8, 0.2))]
        [16, 4]
        """
        return tuple(self.subset(p) for p in stratified_split(self.labels, fractions, rng))


# =========================================================================== sampling
def check_n_points(n_points: int) -> int:
    """``n_points``, the points per cloud, checked: an int in ``[2, MAX_POINTS]``.

    Raises
    ------
    InputError
        Not an int, or out of range.

    Examples
    --------
    >>> check_n_points(1024)
    1024
    """
    n = check_int(n_points, "n_points", 2)
    if n > MAX_POINTS:
        raise InputError(f"n_points must be at most {MAX_POINTS}; got {n}")
    return n


def _pick(points: np.ndarray, n: int, fps: bool, gen: np.random.Generator) -> np.ndarray:
    if fps:
        return farthest_point_sampling(points, n, start=None, rng=gen)
    return gen.choice(len(points), n, replace=False)


def pick_points(
    points: npt.ArrayLike,
    n: int,
    fps: bool = True,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """``n`` distinct indices into ``points``: farthest point sampling from a random
    start (:func:`~robopercept.pointcloud.farthest_point_sampling`), or, with
    ``fps=False``, a random draw without replacement (``rng.choice``).

    Parameters
    ----------
    points : (M, 3) array
        ``M >= n``.
    n : int
        In ``[1, M]``.
    fps : bool
    rng : int, numpy.random.Generator or None

    Returns
    -------
    (n,) int ndarray

    Raises
    ------
    InputError
        ``points`` not ``(M, 3)`` finite, or ``n`` out of range.

    Examples
    --------
    >>> pts = np.array([[0.0, 0, 0], [1, 0, 0], [0.01, 0, 0], [1.01, 0, 0]])
    >>> sorted(pts[pick_points(pts, 2, rng=0), 0].round().tolist())  # one of each pair
    [0.0, 1.0]
    """
    pts = check_numeric(points, "points")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InputError(f"points must be (M, 3); got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError("points must be finite; got NaN/inf: drop those points first")
    n = check_int(n, "n", 1)
    if n > len(pts):
        raise InputError(f"n must be at most the {len(pts)} points; got {n}")
    return _pick(pts.astype(np.float64), n, check_bool(fps, "fps"), as_rng(rng))


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
    up = int(check_choice(up_axis, "up_axis", (0, 1, 2)))
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
        try:
            return _thin(read_point_cloud(path).points, n, fps, gen)
        except DegenerateError as exc:
            raise DegenerateError(f"{path}: {exc}") from None
    return normalize_unit_sphere(pts)[0].astype(np.float32)


def _thin(pts: np.ndarray, n: int, fps: bool, gen: np.random.Generator) -> np.ndarray:
    """A cloud's finite points thinned (or filled) to ``n`` and normalized
    (:func:`sample_cloud`)."""
    pts = pts[np.isfinite(pts).all(1)]
    if len(pts) == 0:
        raise DegenerateError("no finite point")
    if len(pts) >= n:
        if fps and len(pts) > 8 * n:  # FPS from a random 8 n of them: O(8 n^2)
            pts = pts[gen.choice(len(pts), 8 * n, replace=False)]
        pts = pts[_pick(pts, n, fps, gen)]
    else:  # every point once, the rest drawn with replacement
        pts = pts[np.concatenate([np.arange(len(pts)), gen.choice(len(pts), n - len(pts))])]
    return normalize_unit_sphere(pts)[0].astype(np.float32)


def sample_cloud(
    points: npt.ArrayLike,
    n_points: int = 1024,
    rng: int | np.random.Generator | None = 0,
    *,
    fps: bool = True,
) -> np.ndarray:
    """A point cloud given as an array, made what a network sees, by
    :func:`read_cloud_file`'s rules for a cloud file: NaN/inf points dropped, thinned
    to ``n_points`` by farthest point sampling (``fps=False``: a random draw) or, with
    fewer, every point once and the rest drawn with replacement; normalized to the unit
    sphere.

    Parameters
    ----------
    points : (N, 3) array_like
    n_points, rng, fps
        As :func:`read_cloud_file`.

    Returns
    -------
    (n_points, 3) float32 ndarray

    Raises
    ------
    InputError
        Not an ``(N, 3)`` array of numbers.
    DegenerateError
        No finite point, or all points equal.

    Examples
    --------
    >>> sample_cloud(np.random.default_rng(0).normal(size=(100, 3)), 16).shape
    (16, 3)
    """
    a = check_numeric(points, "points")
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"points must be an (N, 3) array of x, y, z; got {plain_repr(points)}")
    return _thin(
        a.astype(np.float64), check_n_points(n_points), check_bool(fps, "fps"), as_rng(rng)
    )


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
    n = check_n_points(n_points)
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
    n = check_n_points(n_points)
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
