r"""Triangle meshes for point-cloud deep learning: reading, surface sampling, farthest
point sampling, normalization and the Chamfer distance.

* :class:`TriangleMesh`: vertices ``(V, 3)`` and triangles ``(F, 3)`` (plus optional
  per-face part labels), with :meth:`~TriangleMesh.areas`.
* :func:`read_mesh`: OFF (Princeton ModelNet's format, including its ``OFF490 518 0``
  quirk) and PLY meshes; polygons are fan-triangulated.
* :func:`sample_surface`: area-weighted uniform points on the surface (the method of
  Open3D's ``TriangleMesh.sample_points_uniformly``).
* :func:`farthest_point_sampling`: the iterative subsampling of PointNet++.
* :func:`normalize_unit_sphere`: PointNet's ``pc_normalize``.
* :func:`chamfer_distance`: the symmetric mean nearest-neighbour distance.

Every count a file's header claims is checked against the bytes in the file before
anything is allocated, so a corrupt or hostile header (say ``OFF`` with ``10**12``
vertices) is refused with :class:`~robopercept.errors.FileFormatError`.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from robopercept._checks import as_rng, check_file, check_int, check_points, plain_repr
from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.pointcloud.io import ply_element_counts

__all__ = [
    "TriangleMesh",
    "chamfer_distance",
    "farthest_point_sampling",
    "normalize_unit_sphere",
    "read_mesh",
    "sample_surface",
]

#: the most points :func:`sample_surface` draws in one call (2**26: 1.5 GiB of float64)
MAX_SAMPLES = 1 << 26
_MAX_HEADER = 1 << 16
#: at least this many bytes per vertex line ("0 0 0\n") and per triangle line ("3 0 0 0\n")
_MIN_VERTEX_BYTES = 6
_MIN_FACE_BYTES = 8
_OFF_MAGIC = re.compile(r"^(?:ST)?C?N?OFF(.*)$")
#: point coordinates beyond this overflow squared distances
_MAX_COORD = 1e150
#: mesh coordinates beyond this overflow the squared cross products of the areas
_MAX_VERTEX = 1e75


def _fail(path: Path, what: str) -> FileFormatError:
    return FileFormatError(f"{path}: {what}")


# --------------------------------------------------------------------------- the mesh
@dataclass(frozen=True)
class TriangleMesh:
    """A triangle mesh: vertices and the triangles that index them.

    Attributes
    ----------
    vertices : (V, 3) float64 ndarray
        Finite coordinates.
    faces : (F, 3) int64 ndarray
        Vertex indices of each triangle, in ``[0, V)``; ``F >= 1``.
    face_labels : (F,) int64 ndarray or None
        A non-negative label per triangle (part ids of the procedural shapes of
        :mod:`robopercept.nn.cloud.data`); ``None`` when unknown.

    ``len(mesh)`` is the number of triangles.

    Raises
    ------
    InputError
        Wrong shapes or dtypes (faces must be integers), NaN/inf vertices, coordinates
        beyond 1e75 (the squared cross products of the areas overflow), no faces, face
        indices out of range, negative labels.

    Examples
    --------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> m.areas().tolist()
    [0.5]
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        v = check_points(self.vertices, "vertices", 3)
        if not np.isfinite(v).all():
            bad = int((~np.isfinite(v).all(1)).sum())
            raise InputError(
                f"vertices must be finite; got {bad} vertex(es) with NaN/inf: "
                "drop them and re-index the faces"
            )
        if v.size and np.abs(v).max() > _MAX_VERTEX:
            raise InputError(
                f"vertices have coordinates up to {np.abs(v).max():.3g}; beyond "
                f"{_MAX_VERTEX:.0g} the triangle areas overflow: rescale the mesh"
            )
        f = _int_array(self.faces, "faces")
        if f.ndim != 2 or f.shape[1] != 3:
            hint = ": faces as columns? use faces.T" if f.ndim == 2 and f.shape[0] == 3 else ""
            raise InputError(f"faces must have shape (F, 3); got {f.shape}{hint}")
        if f.shape[0] == 0:
            raise InputError("faces must not be empty: a mesh needs at least one triangle")
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise InputError(
                f"face indices must lie in [0, {v.shape[0]}) (the vertices); got "
                f"{int(f.min())}..{int(f.max())}"
            )
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)
        if self.face_labels is not None:
            lab = _int_array(self.face_labels, "face_labels")
            if lab.shape != (f.shape[0],):
                raise InputError(
                    f"face_labels must have one label per face, shape ({f.shape[0]},); "
                    f"got {lab.shape}"
                )
            if lab.size and lab.min() < 0:
                raise InputError(f"face_labels must be >= 0; got {int(lab.min())}")
            object.__setattr__(self, "face_labels", lab)

    def __len__(self) -> int:
        return int(self.faces.shape[0])

    def areas(self) -> np.ndarray:
        r"""The area of each triangle, :math:`\frac12 \lVert (b - a) \times (c - a) \rVert`.

        Returns
        -------
        (F,) float64 ndarray

        Examples
        --------
        >>> TriangleMesh([[0, 0, 0], [2, 0, 0], [0, 3, 0]], [[0, 1, 2]]).areas().tolist()
        [3.0]
        """
        return _areas(self.vertices, self.faces)


def _int_array(value: npt.ArrayLike, name: str) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name} must be an integer array; got {plain_repr(value)} ({exc})"
        ) from None
    if arr.dtype.kind not in "iu":
        raise InputError(
            f"{name} must hold integers; got dtype {arr.dtype}: use {name}.astype(np.int64)"
        )
    if arr.dtype == np.uint64 and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise InputError(f"{name} has values beyond int64")
    return arr.astype(np.int64)


def _areas(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    a = v[f[:, 0]]
    cross = np.cross(v[f[:, 1]] - a, v[f[:, 2]] - a)
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross))


def _check_mesh(mesh: object) -> TriangleMesh:
    if not isinstance(mesh, TriangleMesh):
        raise InputError(
            f"mesh must be a TriangleMesh; got {type(mesh).__name__}: build one with "
            "TriangleMesh(vertices, faces) or read_mesh(path)"
        )
    return mesh


def _fan(flat: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan-triangulate polygons given as their concatenated indices ``flat`` and their
    vertex counts ``sizes`` (each >= 3): polygon ``p0 p1 ... pk-1`` becomes the triangles
    ``(p0, pj, pj+1)`` for ``j = 1 .. k-2``, in order. Returns the triangles and the
    polygon each came from."""
    starts = np.cumsum(sizes) - sizes
    per = sizes - 2
    poly = np.repeat(np.arange(sizes.size), per)
    j = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
    s = starts[poly]
    tri = np.stack([flat[s], flat[s + j + 1], flat[s + j + 2]], axis=1)
    return tri, poly


# --------------------------------------------------------------------------- OFF
def _parse_counts(tokens: list[str], path: Path) -> tuple[int, int]:
    if len(tokens) < 2:
        raise _fail(path, f"the OFF header needs the vertex and face counts; got {tokens!r}")
    try:
        nv, nf = int(tokens[0]), int(tokens[1])
    except ValueError:
        raise _fail(path, f"OFF counts must be integers; got {' '.join(tokens[:3])!r}") from None
    if nv < 0 or nf < 0:
        raise _fail(path, f"OFF counts must be >= 0; got {nv} vertices and {nf} faces")
    return nv, nf


def _read_off(path: Path) -> TriangleMesh:
    size = path.stat().st_size
    try:
        text = path.read_bytes().decode("latin-1")
    except OSError as exc:
        raise _fail(path, f"cannot read ({exc.strerror or exc})") from exc
    lines = text.splitlines()
    if "#" in text:
        lines = [ln.split("#", 1)[0] for ln in lines]
    lines = [ln for ln in lines if ln.strip()]
    if not lines:
        raise _fail(path, "empty file: not an OFF mesh")
    first = lines[0].split()
    magic = _OFF_MAGIC.match(first[0])
    if magic is None:
        raise _fail(path, f"not an OFF file: the first word must be 'OFF'; got {first[0][:20]!r}")
    rest = ([magic.group(1)] if magic.group(1) else []) + first[1:]
    if rest and rest[0].upper() == "BINARY":
        raise _fail(path, "binary OFF is not supported: convert it to text OFF or PLY")
    body_start = 1
    if not rest:  # the counts on the next line
        if len(lines) < 2:
            raise _fail(path, "truncated: no vertex and face counts after 'OFF'")
        rest = lines[1].split()
        body_start = 2
    nv, nf = _parse_counts(rest, path)
    if nf == 0:
        raise _fail(path, "empty mesh: the header declares no faces (a point cloud? use .ply)")
    need = nv * _MIN_VERTEX_BYTES + nf * _MIN_FACE_BYTES
    if need > size:
        raise _fail(
            path,
            f"the header claims {nv} vertices and {nf} faces (at least {need} bytes); "
            f"the file has {size} bytes: corrupt or truncated",
        )
    body = lines[body_start:]
    if len(body) < nv + nf:
        raise _fail(
            path,
            f"truncated: the header claims {nv} vertex and {nf} face lines; "
            f"the file has {len(body)} lines after the header",
        )
    vertices = _off_vertices(body[:nv], path)
    faces, _ = _off_faces(body[nv : nv + nf], nv, path)
    return _mesh_of_file(vertices, faces, path)


def _mesh_of_file(vertices: np.ndarray, faces: np.ndarray, path: Path) -> TriangleMesh:
    try:
        return TriangleMesh(vertices, faces)
    except InputError as exc:  # coordinates beyond 1e75
        raise _fail(path, str(exc)) from None


def _off_vertices(lines: list[str], path: Path) -> np.ndarray:
    nv = len(lines)
    tokens = " ".join(lines).split()
    try:
        if len(tokens) == 3 * nv:
            v = np.array(tokens, dtype=np.float64).reshape(nv, 3)
        else:  # extra columns (colours, normals): the first three of each line
            rows = [ln.split() for ln in lines]
            short = next((i for i, r in enumerate(rows) if len(r) < 3), None)
            if short is not None:
                raise _fail(path, f"vertex {short} has fewer than 3 coordinates: {lines[short]!r}")
            v = np.array([r[:3] for r in rows], dtype=np.float64).reshape(nv, 3)
    except ValueError:
        raise _fail(path, "vertex lines hold something that is not a number") from None
    bad = ~np.isfinite(v).all(1)
    if bad.any():
        raise _fail(path, f"non-finite (NaN/inf) coordinates at vertex {int(np.argmax(bad))}")
    return v


def _off_faces(lines: list[str], nv: int, path: Path) -> tuple[np.ndarray, np.ndarray]:
    nf = len(lines)
    tokens = " ".join(lines).split()
    try:
        if len(tokens) == 4 * nf:
            arr = np.array(tokens, dtype=np.int64).reshape(nf, 4)
            if (arr[:, 0] == 3).all():
                flat, sizes = arr[:, 1:].ravel(), np.full(nf, 3)
                return _checked_fan(flat, sizes, nv, path)
        rows = [ln.split() for ln in lines]
        sizes = np.array([r[0] for r in rows], dtype=np.int64)
        if (sizes < 3).any():
            i = int(np.argmax(sizes < 3))
            raise _fail(path, f"face {i} has {sizes[i]} vertices; a face needs at least 3")
        lens = np.array([len(r) for r in rows])
        if (lens < sizes + 1).any():
            i = int(np.argmax(lens < sizes + 1))
            raise _fail(path, f"face {i} lists fewer indices than its count {sizes[i]}")
        flat = np.array(
            [t for r, k in zip(rows, sizes.tolist(), strict=True) for t in r[1 : k + 1]],
            dtype=np.int64,
        )
    except (ValueError, OverflowError):
        raise _fail(path, "face lines hold something that is not an integer") from None
    return _checked_fan(flat, sizes, nv, path)


def _checked_fan(
    flat: np.ndarray, sizes: np.ndarray, nv: int, path: Path
) -> tuple[np.ndarray, np.ndarray]:
    if flat.size and (flat.min() < 0 or flat.max() >= nv):
        raise _fail(
            path,
            f"face index out of range: indices must lie in [0, {nv}) (the vertices); "
            f"got {int(flat.min())}..{int(flat.max())}",
        )
    return _fan(flat, sizes)


# --------------------------------------------------------------------------- PLY


def _read_ply_mesh(path: Path) -> TriangleMesh:
    from plyfile import PlyData

    try:
        size = path.stat().st_size
        with path.open("rb") as fh:
            counts = ply_element_counts(fh.read(_MAX_HEADER), size, path)
        if counts.get("face", 0) == 0:
            raise _fail(
                path,
                "empty mesh: no faces (a point cloud? read it with read_point_cloud)",
            )
        ply = PlyData.read(str(path))
    except FileFormatError:
        raise
    except OSError as exc:
        raise _fail(path, f"cannot read ({exc.strerror or exc})") from exc
    except Exception as exc:  # plyfile raises several parse errors
        raise _fail(path, f"corrupt PLY ({type(exc).__name__}: {exc})") from None
    if "vertex" not in ply:
        raise _fail(path, "no 'vertex' element")
    v = ply["vertex"].data
    names = v.dtype.names or ()
    if not {"x", "y", "z"} <= set(names) or any(v.dtype[k].kind not in "biuf" for k in "xyz"):
        raise _fail(path, f"vertex element has no scalar x, y, z (properties: {', '.join(names)})")
    with np.errstate(invalid="ignore", over="ignore"):  # NaN/inf: refused just below
        vertices = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float64)
    bad = ~np.isfinite(vertices).all(1)
    if bad.any():
        raise _fail(path, f"non-finite (NaN/inf) coordinates at vertex {int(np.argmax(bad))}")
    f = ply["face"].data
    key = next((k for k in ("vertex_indices", "vertex_index") if k in (f.dtype.names or ())), None)
    if key is None:
        raise _fail(path, "the face element has no vertex_indices (or vertex_index) list")
    polys = f[key]
    try:
        sizes = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
        lists = [np.asarray(p).ravel() for p in polys]
        flat = np.concatenate(lists) if lists else np.zeros(0, np.int64)
        if flat.dtype.kind not in "iu":
            raise TypeError
        flat = flat.astype(np.int64)
    except (TypeError, ValueError, OverflowError):
        raise _fail(path, "face vertex_indices must be lists of integers") from None
    if (sizes < 3).any():
        i = int(np.argmax(sizes < 3))
        raise _fail(path, f"face {i} has {sizes[i]} vertices; a face needs at least 3")
    faces, _ = _checked_fan(flat, sizes, len(vertices), path)
    return _mesh_of_file(vertices, faces, path)


# --------------------------------------------------------------------------- public API
def read_mesh(path: str | os.PathLike[str]) -> TriangleMesh:
    """Read a triangle mesh from an OFF or PLY file.

    OFF: the magic word ``OFF`` (``COFF``, ``NOFF`` ... accepted, extra vertex and
    face columns such as colours ignored), the counts ``V F E`` (``E`` ignored), ``V``
    vertex lines ``x y z`` and ``F`` face lines ``k i1 ... ik``. Many Princeton ModelNet
    files glue the counts to the magic word (``OFF490 518 0``): read as well. Comments
    (``#`` to the end of the line) and blank lines are skipped. PLY (ascii or binary,
    through ``plyfile``): the ``vertex`` element's ``x y z`` and the ``face`` element's
    ``vertex_indices`` (or ``vertex_index``) lists. Polygons with ``k > 3`` vertices are
    fan-triangulated into ``(p0, pj, pj+1)``, ``j = 1 .. k-2`` (as Open3D and trimesh do).

    Parameters
    ----------
    path : str or path-like
        A ``.off`` or ``.ply`` file (any case).

    Returns
    -------
    TriangleMesh
        Without face labels.

    Raises
    ------
    FileFormatError
        Missing file, unknown extension, counts larger than the file can hold (checked
        before anything is allocated), truncated file, face indices out of range,
        faces with fewer than 3 vertices, non-finite or unparsable vertices, binary OFF,
        and an empty mesh (no faces: a point cloud; read it with
        :func:`~robopercept.pointcloud.read_point_cloud`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "quad.off"
    >>> _ = p.write_text("OFF\\n4 1 0\\n0 0 0\\n1 0 0\\n1 1 0\\n0 1 0\\n4 0 1 2 3\\n")
    >>> read_mesh(p).faces.tolist()
    [[0, 1, 2], [0, 2, 3]]
    """
    p = check_file(path, "a mesh file (.off or .ply)")
    suffix = p.suffix.lower()
    if suffix == ".off":
        return _read_off(p)
    if suffix == ".ply":
        return _read_ply_mesh(p)
    raise FileFormatError(f"{p}: unknown mesh extension {suffix!r}: use .off or .ply")


def sample_surface(
    mesh: TriangleMesh, n: int, rng: int | np.random.Generator | None = None
) -> tuple[np.ndarray, np.ndarray]:
    r"""Points drawn uniformly (by area) on the surface of a triangle mesh.

    Each point picks triangle ``t`` with probability :math:`A_t / \sum_s A_s` (i.i.d.,
    by inverting the cumulative areas), then a uniform point in it by the square-root
    trick: with :math:`r_1, r_2 \sim U(0, 1)`,

    .. math:: p = (1 - \sqrt{r_1})\, a + \sqrt{r_1}(1 - r_2)\, b + \sqrt{r_1}\, r_2\, c.

    This is the method of Open3D's ``TriangleMesh.sample_points_uniformly`` (0.10 and
    later: triangles drawn i.i.d. by area with ``std::discrete_distribution``, the same
    point formula), so the count of triangle ``t`` is binomial with mean
    :math:`n A_t / \sum_s A_s` in both; the random streams differ.
    Triangles of zero area are never picked.

    Parameters
    ----------
    mesh : TriangleMesh
    n : int
        Number of points, in ``[1, 2**26]``.
    rng : int, numpy.random.Generator or None
        Seed: the same seed gives the same points.

    Returns
    -------
    points : (n, 3) float64 ndarray
    faces : (n,) int64 ndarray
        The triangle each point lies on (to carry per-face labels to the points:
        ``mesh.face_labels[faces]``).

    Raises
    ------
    InputError
        Not a mesh, ``n`` out of range.
    DegenerateError
        Every triangle has zero area.

    Examples
    --------
    >>> m = TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    >>> pts, faces = sample_surface(m, 100, rng=0)
    >>> pts.shape, bool((pts[:, :2].sum(1) <= 1).all()), set(faces.tolist())
    ((100, 3), True, {0})
    """
    mesh = _check_mesh(mesh)
    n = check_int(n, "n", 1)
    if n > MAX_SAMPLES:
        raise InputError(f"n must be at most {MAX_SAMPLES} points; got {n}: draw fewer")
    gen = as_rng(rng)
    areas = mesh.areas()
    cdf = np.cumsum(areas)
    total = float(cdf[-1])
    if not total > 0 or not np.isfinite(total):
        raise DegenerateError(
            f"every one of the mesh's {len(areas)} triangles has zero area: "
            "nothing to sample (check the vertices)"
        )
    last = int(np.flatnonzero(areas > 0)[-1])
    face = np.searchsorted(cdf, gen.random(n) * total, side="right")
    face = np.minimum(face, last).astype(np.int64)
    r = gen.random((n, 2))
    s1 = np.sqrt(r[:, :1])
    tri = mesh.vertices[mesh.faces[face]]
    pts = (1.0 - s1) * tri[:, 0] + s1 * (1.0 - r[:, 1:]) * tri[:, 1] + s1 * r[:, 1:] * tri[:, 2]
    return pts, face


def _finite_points(points: npt.ArrayLike, name: str) -> np.ndarray:
    pts = check_points(points, name, 3)
    if pts.shape[0] == 0:
        raise InputError(f"{name} must not be empty; got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError(
            f"{name} must be finite; got NaN/inf: drop them first, "
            f"e.g. {name}[np.isfinite({name}).all(1)]"
        )
    if np.abs(pts).max() > _MAX_COORD:
        raise InputError(
            f"{name} has coordinates up to {np.abs(pts).max():.3g}; beyond {_MAX_COORD:.0g} "
            "squared distances overflow: rescale the points"
        )
    return pts


def farthest_point_sampling(
    points: npt.ArrayLike,
    n: int,
    start: int | None = 0,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    r"""Farthest point sampling: ``n`` indices that spread over the cloud.

    The iterative subsampling of PointNet++ (Qi et al. 2017, its
    ``farthest_point_sample``): the first index is ``start``; then each step picks

    .. math:: i_k = \arg\max_j \min_{l < k} \lVert x_j - x_{i_l} \rVert^2,

    keeping the running minimum :math:`d_j` (one vectorized update per step:
    :math:`O(N n)`). Ties go to the lowest index. Indices already picked are never picked
    again, so the ``n`` indices are distinct even when the cloud has fewer distinct points
    (duplicates are then taken in index order).

    Parameters
    ----------
    points : (N, 3) array_like
        Finite coordinates.
    n : int
        Number of indices, in ``[1, N]``.
    start : int or None
        The first index, in ``[0, N)``; ``None`` draws it uniformly from ``rng``.
    rng : int, numpy.random.Generator or None
        Used only when ``start`` is None.

    Returns
    -------
    (n,) int64 ndarray
        Indices into ``points``, in the order picked.

    Raises
    ------
    InputError
        Empty or non-finite points, ``n`` not in ``[1, N]``, ``start`` out of range.

    Examples
    --------
    >>> pts = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [4, 0, 0]]
    >>> farthest_point_sampling(pts, 3).tolist()  # the far end, then the middle
    [0, 4, 2]
    """
    pts = _finite_points(points, "points")
    count = pts.shape[0]
    n = check_int(n, "n", 1)
    if n > count:
        raise InputError(
            f"n must be at most the number of points ({count}); got {n}: ask for fewer, "
            "or resample with replacement (rng.choice(N, n)) to reach n"
        )
    if start is None:
        first = int(as_rng(rng).integers(count))
    else:
        first = check_int(start, "start", 0)
        if first >= count:
            raise InputError(f"start must be an index in [0, {count}); got {first}")
    x, y, z = (np.ascontiguousarray(pts[:, k]) for k in range(3))
    dist = np.full(count, np.inf)
    out = np.empty(n, dtype=np.int64)
    tmp = np.empty(count)
    d = np.empty(count)
    last = first
    for k in range(n):
        out[k] = last
        dist[last] = -1.0  # never picked again
        if k == n - 1:
            break
        np.subtract(x, x[last], out=d)
        np.multiply(d, d, out=d)
        np.subtract(y, y[last], out=tmp)
        np.multiply(tmp, tmp, out=tmp)
        np.add(d, tmp, out=d)
        np.subtract(z, z[last], out=tmp)
        np.multiply(tmp, tmp, out=tmp)
        np.add(d, tmp, out=d)
        np.minimum(dist, d, out=dist)
        last = int(np.argmax(dist))
    return out


def normalize_unit_sphere(points: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
    r"""Centre a cloud and scale it into the unit sphere (PointNet's ``pc_normalize``).

    :math:`c = \frac1N \sum_i x_i`, :math:`s = \max_i \lVert x_i - c \rVert`,
    :math:`x'_i = (x_i - c) / s`: the centroid goes to the origin and the farthest point
    to distance 1. Undo with ``x = x' s + c``.

    Parameters
    ----------
    points : (N, 3) array_like
        Finite coordinates.

    Returns
    -------
    points : (N, 3) float64 ndarray
        Centroid 0, largest norm 1.
    centroid : (3,) float64 ndarray
    scale : float

    Raises
    ------
    InputError
        Empty or non-finite points.
    DegenerateError
        All points equal (the scale would be 0).

    Examples
    --------
    >>> p, c, s = normalize_unit_sphere([[1, 1, 1], [3, 1, 1]])
    >>> p.tolist(), c.tolist(), s
    ([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [2.0, 1.0, 1.0], 1.0)
    """
    pts = _finite_points(points, "points")
    centroid = pts.mean(axis=0)
    centred = pts - centroid
    scale = float(np.sqrt(np.einsum("ij,ij->i", centred, centred).max()))
    if not scale > 0:
        raise DegenerateError(
            f"all {len(pts)} points are equal: the cloud has no extent to normalize"
        )
    return centred / scale, centroid, scale


def chamfer_distance(a: npt.ArrayLike, b: npt.ArrayLike) -> float:
    r"""The symmetric Chamfer distance between two clouds: the mean of the nearest
    distances both ways.

    .. math:: d(A, B) = \frac12 \Big( \frac1{|A|} \sum_{a \in A} \min_{b \in B}
              \lVert a - b \rVert + \frac1{|B|} \sum_{b \in B} \min_{a \in A}
              \lVert a - b \rVert \Big)

    in the units of the points (distances, not squared distances as in PyTorch3D's
    ``chamfer_distance``). Neighbours by ``scipy.spatial.cKDTree``.

    Parameters
    ----------
    a : (N, 3) array_like
    b : (M, 3) array_like
        Finite, non-empty.

    Returns
    -------
    float
        0 when each point of either cloud lies on a point of the other.

    Raises
    ------
    InputError
        Empty or non-finite clouds.

    Examples
    --------
    >>> chamfer_distance([[0, 0, 0]], [[0, 0, 1], [0, 0, 3]])  # (1 + (1 + 3) / 2) / 2
    1.5
    """
    pa = _finite_points(a, "a")
    pb = _finite_points(b, "b")
    dab = cKDTree(pb).query(pa)[0]
    dba = cKDTree(pa).query(pb)[0]
    return float(0.5 * (dab.mean() + dba.mean()))
