"""Hypothesis strategies for hostile inputs: images, clouds, point sets, scalars.

Every strategy draws *descriptions* that pickle cheaply: arrays are drawn contiguous
and, where their memory layout is part of the attack (Fortran order, a non-contiguous
view, a read-only buffer, zero strides from :func:`numpy.broadcast_to`), wrapped in a
:class:`Layout` that :func:`materialize` applies in the worker process -- a pickled
view arrives as a fresh contiguous array, so the layout must be made on the far side.
Objects that only exist in the worker (a ``PointCloud`` of hostile points, a camera)
are :class:`Build` recipes, made there by calling ``target(*args, **kwargs)``.

Sizes stay small (images at most 64x64, at most 500 points) so that one call takes
milliseconds and a campaign tries thousands of inputs.

The hostile menu follows issue 25 (and the campaigns of NumPy, SciPy and scikit-image,
whose own fuzzers use the same families):

* images: shapes ``(0, 0)``, ``(1, 1)``, ``(H, W)``, ``(H, W, 1|3|4|5)``, 1-D, 4-D,
  channels-first; dtypes ``bool``, ``uint8``, ``int8``, ``uint16``, ``int32``,
  ``float16``, ``float32``, ``float64``, ``complex64``, ``object``; values NaN, +-inf,
  1e300, -0.0, denormals; Fortran order, non-contiguous views, read-only, zero strides;
* point sets and clouds: ``(0, 3)``, ``(1, 3)``, ``(N, 2)``, ``(N, 4)``, points as
  columns, identical points, collinear points, NaN rows, 1e300, integer dtype, lists
  of lists;
* scalars: nan, inf, -inf, -1, 0, 1e-162, 2**40, 2**63, True, None, ``"3"``,
  ``[1, 2]``, ``np.float32(2)``, ``np.int64(3)``, a complex number -- mixed with the
  valid value and its neighbours, so valid-but-extreme combinations are tried too;
* tensors (issue 47): the valid tensor with an empty leading dimension (a batch of 0),
  NaN, +-inf, huge finite values (boxes with corners at 1e31, beyond what int64 holds
  once scaled), another dtype (``int64``, ``bool``, ``float16``, ``bfloat16``,
  ``float64``, ``uint8``), one dimension more or fewer, a non-contiguous or expanded
  view, a tensor that requires grad, or a NumPy array, a list or None instead -- made
  in the worker by :class:`TensorOf` (torch is imported there only);
* meshes: a ``TriangleMesh`` built in the worker from hostile vertices or faces
  (indices out of range or negative, float indices, no faces, NaN vertices).
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from hypothesis import strategies as st

__all__ = [
    "HOSTILE_SCALARS",
    "IMAGE_DTYPES",
    "LAYOUTS",
    "TENSOR_DTYPES",
    "WORK_CAP",
    "Build",
    "Layout",
    "Recipe",
    "TensorOf",
    "cap_work",
    "hostile_arrays",
    "hostile_choices",
    "hostile_clouds",
    "hostile_flags",
    "hostile_images",
    "hostile_meshes",
    "hostile_objects",
    "hostile_paths",
    "hostile_points",
    "hostile_scalars",
    "hostile_sequences",
    "hostile_tensors",
    "hostile_tuples",
    "hostile_work_sizes",
    "materialize",
]

#: the dtypes an image may come in (issue 25's list)
IMAGE_DTYPES: tuple[str, ...] = (
    "bool",
    "uint8",
    "int8",
    "uint16",
    "int32",
    "float16",
    "float32",
    "float64",
    "complex64",
    "object",
)

#: memory layouts applied in the worker: C order, Fortran order, a strided view,
#: a read-only buffer, zero strides (np.broadcast_to)
LAYOUTS: tuple[str, ...] = ("c", "fortran", "strided", "readonly", "broadcast")

#: the special floating values injected into arrays
SPECIAL_VALUES: tuple[float, ...] = (
    math.nan,
    math.inf,
    -math.inf,
    1e300,
    -1e300,
    -0.0,
    5e-324,
    2.2250738585072014e-308 / 3,
)

#: issue 25's hostile scalars (each a parameter value that a guard must refuse or that
#: the function must handle)
HOSTILE_SCALARS: tuple[Any, ...] = (
    math.nan,
    math.inf,
    -math.inf,
    -1,
    0,
    1e-162,
    2**40,
    2**63,
    True,
    None,
    "3",
    [1, 2],
    np.float32(2),
    np.int64(3),
    complex(1, 1),
)


class Recipe:
    """Base of the values that :func:`materialize` makes in the worker."""

    def make(self) -> Any:
        """Return the object this recipe describes."""
        raise NotImplementedError


@dataclass(frozen=True)
class Layout(Recipe):
    """An array and the memory layout the worker gives it before the call.

    Parameters
    ----------
    array : numpy.ndarray
        The values, C-contiguous (as they pickle).
    layout : str
        One of :data:`LAYOUTS`: ``"c"`` (as is), ``"fortran"``
        (``np.asfortranarray``), ``"strided"`` (a view of every other element of a
        twice-as-large array along the first axis), ``"readonly"``
        (``writeable=False``), ``"broadcast"`` (``np.broadcast_to`` of the first
        element/row: zero strides, read-only).
    """

    array: np.ndarray
    layout: str = "c"

    def make(self) -> np.ndarray:
        """Return the array in its layout (called in the worker).

        Returns
        -------
        numpy.ndarray
            Same shape, dtype and values as :attr:`array` (``"broadcast"`` repeats the
            first row), with the requested strides and flags.
        """
        a = np.asarray(self.array)  # a 0-d cast may have come back a NumPy scalar
        if self.layout == "fortran" and a.ndim >= 1:  # asfortranarray makes 0-d 1-d
            return np.asfortranarray(a)
        if self.layout == "strided" and a.ndim >= 1:
            big = np.repeat(a, 2, axis=0)
            return big[::2]
        if self.layout == "readonly":
            b = np.array(a, copy=True)
            b.flags.writeable = False
            return b
        if self.layout == "broadcast" and a.ndim >= 1 and a.shape[0] > 0:
            return np.broadcast_to(a[:1], a.shape)
        return a

    def __repr__(self) -> str:
        return f"{_describe(self.array)}[{self.layout}]"


@dataclass(frozen=True)
class Build(Recipe):
    """A recipe for an object made in the worker: ``import target; target(*args, **kwargs)``.

    Parameters
    ----------
    target : str
        ``"module:qualname"`` of a callable.
    args, kwargs
        Its arguments, themselves materialized first (they may hold :class:`Layout`
        or :class:`Build` values).
    """

    target: str
    args: tuple[Any, ...] = ()
    kwargs: tuple[tuple[str, Any], ...] = ()

    def make(self) -> Any:
        """Materialize the arguments and call the target (in the worker).

        Returns
        -------
        object
            What the target returns.
        """
        fn = resolve(self.target)
        args = [materialize(a) for a in self.args]
        kwargs = {k: materialize(v) for k, v in self.kwargs}
        return fn(*args, **kwargs)

    def __repr__(self) -> str:
        parts = [repr(a) for a in self.args] + [f"{k}={v!r}" for k, v in self.kwargs]
        return f"{self.target.rsplit(':', 1)[-1]}({', '.join(parts)})"


#: the dtypes a tensor may come in (torch's names)
TENSOR_DTYPES: tuple[str, ...] = (
    "float32",
    "float64",
    "float16",
    "bfloat16",
    "int64",
    "int32",
    "uint8",
    "bool",
)

#: the views a tensor may come as: as made, a non-contiguous view, an expanded view of
#: its first row (zero strides), a leaf that requires grad
TENSOR_LAYOUTS: tuple[str, ...] = ("c", "strided", "expand", "grad")


@dataclass(frozen=True)
class TensorOf(Recipe):
    """A torch tensor made in the worker from an array (torch is imported there only).

    Parameters
    ----------
    array : numpy.ndarray
        The values (float64 for floating dtypes; NaN and inf are made 0 and the dtype's
        extremes for the integer dtypes, as a user's cast would).
    dtype : str
        One of :data:`TENSOR_DTYPES`.
    layout : str
        One of :data:`TENSOR_LAYOUTS`.
    """

    array: np.ndarray
    dtype: str = "float32"
    layout: str = "c"

    def make(self) -> Any:
        """Return the tensor (called in the worker).

        Returns
        -------
        torch.Tensor
            Of :attr:`array`'s shape and values, in :attr:`dtype` and :attr:`layout`.
        """
        import torch

        a = np.asarray(self.array)
        if self.dtype == "bfloat16":
            t = torch.from_numpy(_cast(a.astype(np.float64), "float32").copy()).to(torch.bfloat16)
        else:
            t = torch.from_numpy(_cast(a.astype(np.float64), self.dtype).copy())
        if self.layout == "strided" and t.ndim >= 1:
            t = t.repeat_interleave(2, dim=0)[::2]
        elif self.layout == "expand" and t.ndim >= 1 and t.shape[0] > 0:
            t = t[:1].expand(t.shape)
        elif self.layout == "grad" and t.is_floating_point():
            t = t.clone().requires_grad_(True)
        return t

    def __repr__(self) -> str:
        inner = _describe(np.asarray(self.array, np.float64)).removeprefix("array(float64, ")
        return f"tensor({self.dtype}, {inner}[{self.layout}]"


def resolve(target: str) -> Any:
    """Return the object that ``"module:qual.name"`` names.

    Parameters
    ----------
    target : str
        A module path and a dotted attribute path inside it, separated by ``:``.

    Returns
    -------
    object
    """
    module, _, qual = target.partition(":")
    obj: Any = importlib.import_module(module)
    for part in qual.split("."):
        obj = getattr(obj, part)
    return obj


def materialize(value: Any) -> Any:
    """Replace every :class:`Recipe` inside ``value`` by what it makes.

    Lists, tuples and dicts are walked (and rebuilt with their own type); anything else
    is returned as is.

    Parameters
    ----------
    value : object

    Returns
    -------
    object
    """
    if isinstance(value, Recipe):
        return value.make()
    if isinstance(value, list):
        return [materialize(v) for v in value]
    if isinstance(value, tuple) and type(value) is tuple:
        return tuple(materialize(v) for v in value)
    if isinstance(value, dict):
        return {k: materialize(v) for k, v in value.items()}
    return value


def _describe(a: np.ndarray) -> str:
    """A short description of an array for reports: dtype, shape and its specials."""
    tags = []
    if a.dtype.kind in "fc" and a.size:
        with np.errstate(all="ignore"):
            v = a.astype(np.complex128).real if a.dtype.kind == "c" else a.astype(np.float64)
        if np.isnan(v).any():
            tags.append("nan")
        if np.isinf(v).any():
            tags.append("inf")
        finite = v[np.isfinite(v)]
        if finite.size and np.abs(finite).max() > 1e100:
            tags.append("huge")
    extra = f" {'+'.join(tags)}" if tags else ""
    return f"array({a.dtype}, {a.shape}{extra})"


def describe(value: Any) -> str:
    """A one-line description of a fuzz value for tables and failure lists.

    Parameters
    ----------
    value : object
        A value drawn by a strategy of this module.

    Returns
    -------
    str
        Arrays as ``array(dtype, shape tags)[layout]``, long containers shortened.
    """
    if isinstance(value, np.ndarray):
        return _describe(value)
    if isinstance(value, (list, tuple)) and len(value) > 6:
        head = ", ".join(describe(v) for v in value[:3])
        return f"{type(value).__name__}[{head}, ... {len(value)} items]"
    if isinstance(value, (list, tuple)):
        inner = ", ".join(describe(v) for v in value)
        return (
            f"[{inner}]"
            if isinstance(value, list)
            else f"({inner}{',' if len(value) == 1 else ''})"
        )
    r = repr(value)
    return r if len(r) <= 80 else r[:77] + "..."


# --------------------------------------------------------------------------- arrays


def _cast(values: np.ndarray, dtype: str) -> np.ndarray:
    """``values`` (float64) cast to ``dtype`` the way a user's array would hold them."""
    with np.errstate(all="ignore"):
        if dtype == "bool":
            return np.asarray(values > 0.5)
        if dtype == "object":
            return np.asarray(values.astype(object))
        dt = np.dtype(dtype)
        if dt.kind in "iu":
            info = np.iinfo(dt)
            clean = np.nan_to_num(values, nan=0.0, posinf=info.max, neginf=info.min)
            return np.asarray(np.clip(clean, info.min, info.max).astype(dt))
        return np.asarray(values.astype(dt))


@st.composite
def _values(draw: st.DrawFn, shape: tuple[int, ...], scale: float = 255.0) -> np.ndarray:
    """Float64 values of ``shape``: noise, constant, a ramp, or extremes, with specials."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["noise", "constant", "ramp", "binary", "extreme"]))
    n = int(np.prod(shape)) if shape else 1
    if kind == "noise":
        v = rng.uniform(0, scale, n)
    elif kind == "constant":
        v = np.full(n, draw(st.sampled_from([0.0, 1.0, scale, -0.0, 0.5])))
    elif kind == "ramp":
        v = np.linspace(0, scale, n)
    elif kind == "binary":
        v = rng.integers(0, 2, n) * scale
    else:
        v = rng.choice(
            [0.0, scale, -scale, 1e300, -1e300, 5e-324, math.nan, math.inf, -math.inf], n
        )
    v = v.reshape(shape)
    if n and draw(st.booleans()):
        special = draw(st.sampled_from(SPECIAL_VALUES))
        count = draw(st.sampled_from([1, max(1, n // 10), n]))
        flat = v.reshape(-1)
        flat[rng.choice(n, size=min(count, n), replace=False)] = special
    return v


_IMAGE_SHAPES = st.one_of(
    st.sampled_from([(0, 0), (1, 1), (0, 5), (5, 0), (1, 64), (64, 1)]),
    st.tuples(st.integers(2, 64), st.integers(2, 64)),
    st.tuples(st.integers(2, 48), st.integers(2, 48), st.sampled_from([1, 3, 4, 5])),
    st.tuples(st.sampled_from([1, 3, 4]), st.integers(8, 32), st.integers(8, 32)),
    st.tuples(st.integers(0, 64)),
    st.tuples(st.integers(1, 3), st.integers(2, 16), st.integers(2, 16), st.sampled_from([1, 3])),
    st.just(()),
)


@st.composite
def hostile_images(draw: st.DrawFn, like: np.ndarray | None = None) -> Any:
    """Draw a hostile image: odd shape, dtype, values or memory layout.

    Half of the draws keep the shape of ``like`` (the valid image of the call) and
    change its dtype, values or layout, so that the attack reaches past the shape
    check; the other half draw any shape of the menu.

    Parameters
    ----------
    like : numpy.ndarray, optional
        The valid image of the call.

    Returns
    -------
    Layout
        A :class:`Layout` wrapping an array with at most 64x64 pixels (4-D: 3x16x16x3).
    """
    if like is not None and draw(st.booleans()):
        shape = tuple(like.shape)
        scale = 1.0 if like.dtype.kind == "f" else 255.0
    else:
        shape = draw(_IMAGE_SHAPES)
        scale = draw(st.sampled_from([1.0, 255.0, 65535.0]))
    dtype = draw(st.sampled_from(IMAGE_DTYPES))
    values = draw(_values(shape, scale))
    layout = draw(st.sampled_from(LAYOUTS))
    return Layout(_cast(values, dtype), layout)


# --------------------------------------------------------------------------- points


@st.composite
def hostile_points(draw: st.DrawFn, like: Any = None, dim: int | None = None) -> Any:
    """Draw a hostile point set.

    Parameters
    ----------
    like : numpy.ndarray, optional
        The valid ``(N, D)`` points of the call; sets the usual dimension.
    dim : int, optional
        The dimension when ``like`` is not given (default 3).

    Returns
    -------
    Layout or list
        ``(0, D)``, ``(1, D)``, ``(N, D +- 1)``, points as columns, identical points,
        collinear points, NaN rows, 1e300 coordinates, an integer dtype, or the same as
        a list of lists. At most 500 points.
    """
    if dim is None:
        dim = like.shape[1] if isinstance(like, np.ndarray) and like.ndim == 2 else 3
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n_like = like.shape[0] if isinstance(like, np.ndarray) and like.ndim == 2 else 50
    n = draw(st.sampled_from([0, 1, 2, 3, 4, 7, n_like, 100, 500]))
    d = draw(st.sampled_from([dim, dim, dim, 2, 3, 4, 1]))
    kind = draw(
        st.sampled_from(
            ["random", "identical", "collinear", "coplanar", "nan_rows", "huge", "tiny", "grid"]
        )
    )
    if kind == "identical":
        p = np.tile(rng.normal(size=d), (n, 1))
    elif kind == "collinear":
        p = np.outer(np.linspace(-1, 1, n), rng.normal(size=d)) + rng.normal(size=d)
    elif kind == "coplanar" and d >= 3:
        p = rng.normal(size=(n, d))
        p[:, 2:] = 0.0
    elif kind == "nan_rows":
        p = rng.normal(size=(n, d))
        if n:
            p[rng.choice(n, size=max(1, n // 5), replace=False)] = draw(
                st.sampled_from([math.nan, math.inf, -math.inf])
            )
    elif kind == "huge":
        p = rng.normal(size=(n, d)) * 1e300
    elif kind == "tiny":
        p = rng.normal(size=(n, d)) * 1e-300
    elif kind == "grid":
        p = np.round(rng.uniform(0, 4, size=(n, d)))
    else:
        p = rng.normal(size=(n, d)) * draw(st.sampled_from([1.0, 10.0, 1000.0]))
    form = draw(st.sampled_from(["array", "array", "int", "float32", "transposed", "list"]))
    if form == "int":
        with np.errstate(all="ignore"):
            p = np.nan_to_num(p, nan=0, posinf=2**62, neginf=-(2**62)).astype(np.int64)
    elif form == "float32":
        with np.errstate(all="ignore"):
            p = p.astype(np.float32)
    elif form == "transposed":
        p = p.T.copy()
    elif form == "list":
        return p.tolist()
    return Layout(p, draw(st.sampled_from(LAYOUTS)))


@st.composite
def hostile_clouds(draw: st.DrawFn, like: Any = None) -> Any:
    """Draw a hostile point cloud argument.

    Returns
    -------
    Build or object
        Mostly a ``PointCloud`` built in the worker from hostile points (identical,
        collinear, empty, one point, 1e300); sometimes a raw array, a list, or None
        where a ``PointCloud`` is expected.
    """
    pts = draw(hostile_points(dim=3))
    if draw(st.integers(0, 3)) == 0:
        return draw(st.sampled_from([None, 3, "cloud.ply"])) if draw(st.booleans()) else pts
    return Build("robopercept.pointcloud:PointCloud", (pts,))


# --------------------------------------------------------------------------- tensors

#: huge finite coordinates: beyond int64 once scaled (1e31: issue 47's R50), beyond the
#: squared range of float32 (4.7e18), float32's largest (3e38), float64 only (1e300)
HUGE_COORDINATES: tuple[float, ...] = (1e31, -1e31, 4.7e18, 3e38, 1e300)


@st.composite
def hostile_tensors(draw: st.DrawFn, like: Any = None, dtype: str = "float32") -> Any:
    """Draw a hostile tensor argument (made in the worker, see :class:`TensorOf`).

    Half of the draws keep the valid tensor's shape and change its values, dtype or
    view, so that the attack reaches past the shape check.

    Parameters
    ----------
    like : numpy.ndarray, optional
        The values of the valid tensor (float64); default a ``(3, 4)`` array of boxes.
    dtype : str
        The valid tensor's dtype (one of :data:`TENSOR_DTYPES`).

    Returns
    -------
    TensorOf or object
        The valid values with NaN, +-inf or huge finite entries (boxes: every corner
        scaled to one of :data:`HUGE_COORDINATES`, the batch-index column kept), an
        empty leading dimension (a batch of 0) or an empty last one, another dtype, a
        dimension more or fewer, a column more or fewer, a non-contiguous, expanded or
        grad-requiring view; or a NumPy array, a list, None, a number where the tensor
        goes.
    """
    base = (
        np.asarray(like, np.float64)
        if like is not None
        else np.array([[0.0, 0, 4, 4], [1, 1, 5, 6], [2, 0, 7, 3]])
    )
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    boxy = base.ndim == 2 and base.shape[-1] in (4, 5)
    kind = draw(
        st.sampled_from(
            ["values", "values", "huge", "empty", "dtype", "dtype", "ndim", "cols", "view", "not"]
        )
    )
    a, dt, layout = base.copy(), dtype, "c"
    if kind == "values" and a.size:
        how = draw(st.sampled_from(["nan", "inf", "-inf", "all_nan", "zeros", "negate", "swap"]))
        flat = a.reshape(-1)
        if how == "nan":
            flat[rng.integers(0, flat.size)] = math.nan
        elif how == "inf":
            flat[rng.integers(0, flat.size)] = math.inf
        elif how == "-inf":
            flat[rng.integers(0, flat.size)] = -math.inf
        elif how == "all_nan":
            flat[:] = math.nan
        elif how == "zeros":
            flat[:] = 0.0
        elif how == "negate":
            flat *= -1.0
        elif a.ndim >= 1 and a.shape[-1] >= 4:  # swap: corners out of order
            a[..., [-4, -3, -2, -1]] = a[..., [-2, -1, -4, -3]]
        if dt not in ("float32", "float64", "float16", "bfloat16"):
            dt = "float32"  # NaN survives only in a floating dtype
    elif kind == "huge":
        big = draw(st.sampled_from(HUGE_COORDINATES))
        dt = draw(st.sampled_from(["float64", "float64", "float32"]))
        if boxy:  # corners kept in order: the far corner huge, or the near one
            if big > 0:
                a[:, -2:] = big
            else:
                a[:, -4:-2] = big
            if draw(st.booleans()):  # one huge box among sane ones
                a[1:] = base[1:]
        elif a.size:
            a.reshape(-1)[rng.integers(0, a.size)] = big
    elif kind == "empty":
        if a.ndim == 0:
            a = np.zeros(0)
        elif draw(st.booleans()) or a.ndim == 1:
            a = np.zeros((0, *a.shape[1:]))
        else:
            a = np.zeros((*a.shape[:-1], 0))
    elif kind == "dtype":
        dt = draw(st.sampled_from([d for d in TENSOR_DTYPES if d != dtype]))
    elif kind == "ndim":
        pick = draw(st.sampled_from(["drop", "add", "scalar", "flat"]))
        if pick == "drop" and a.ndim >= 1 and a.shape[0]:
            a = a[0].copy()
        elif pick == "add":
            a = a[None].copy()
        elif pick == "scalar":
            a = np.asarray(a.reshape(-1)[0] if a.size else 1.0)
        else:
            a = a.reshape(-1).copy()
    elif kind == "cols" and a.ndim >= 1:
        if draw(st.booleans()) and a.shape[-1] > 1:
            a = a[..., :-1].copy()
        else:
            a = np.concatenate([a, a[..., :1]], axis=-1)
    elif kind == "view":
        layout = draw(st.sampled_from(TENSOR_LAYOUTS[1:]))
    elif kind == "not":
        return draw(
            st.sampled_from(
                [Layout(base), base.tolist(), None, 3, "tensor", math.nan, [base.tolist()]]
            )
        )
    return TensorOf(a, dt, layout)


@st.composite
def hostile_meshes(draw: st.DrawFn, vertices: Any = None, faces: Any = None) -> Any:
    """Draw a hostile mesh argument: a ``TriangleMesh`` built in the worker from
    hostile vertices or faces, or another object where the mesh goes.

    Parameters
    ----------
    vertices : (V, 3) numpy.ndarray, optional
        The valid mesh's vertices (default a tetrahedron).
    faces : (F, 3) numpy.ndarray, optional
        Its faces.

    Returns
    -------
    Build or object
        Faces with an index out of range (V, 2**40), negative, float indices, no
        faces, a fourth column, or hostile vertices (NaN, 1e300, identical: zero
        area); a point cloud, None or a list where the mesh goes.
    """
    v = (
        np.asarray(vertices, np.float64)
        if vertices is not None
        else np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    )
    f = (
        np.asarray(faces, np.int64)
        if faces is not None
        else np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    )
    target = "robopercept.pointcloud:TriangleMesh"
    pick = draw(st.sampled_from(["faces", "faces", "vertices", "vertices", "zero", "other"]))
    if pick == "faces":
        how = draw(st.sampled_from(["range", "huge", "negative", "float", "empty", "cols"]))
        bad = f.copy()
        if how == "range":
            bad[0, 0] = len(v)
        elif how == "huge":
            bad[0, 0] = 2**40
        elif how == "negative":
            bad[0, 0] = -1
        elif how == "float":
            return Build(target, (Layout(v), Layout(f.astype(np.float64) + 0.5)))
        elif how == "empty":
            bad = np.zeros((0, 3), np.int64)
        else:
            bad = np.concatenate([f, f[:, :1]], axis=1)
        return Build(target, (Layout(v), Layout(bad)))
    if pick == "vertices":
        return Build(target, (draw(hostile_points(like=v)), Layout(f)))
    if pick == "zero":  # every triangle of zero area
        return Build(target, (Layout(np.zeros_like(v)), Layout(f)))
    return draw(st.sampled_from([None, 3, [], Build("robopercept.pointcloud:PointCloud", (v,))]))


# --------------------------------------------------------------------------- scalars


def _neighbours(like: Any) -> list[Any]:
    """Valid-looking values near ``like``: the value, doubled, off by one, tiny, huge."""
    if isinstance(like, bool) or not isinstance(like, (int, float, np.integer, np.floating)):
        return []
    v = like
    if isinstance(v, (int, np.integer)):
        v = int(v)
        return [v, v + 1, max(v - 1, 0), 2 * v + 1, 1, 2, 3, 5]
    v = float(v)
    return [v, 2 * v, v / 2, -v, v * 1e6, v * 1e-6, 0.5, 1.0]


@st.composite
def hostile_scalars(draw: st.DrawFn, like: Any = None) -> Any:
    """Draw a hostile scalar parameter value.

    Parameters
    ----------
    like : int or float, optional
        The valid value of the parameter; its neighbours are drawn one time in four.

    Returns
    -------
    object
        One of :data:`HOSTILE_SCALARS`, a random float or int of any magnitude, or a
        valid-looking neighbour of ``like``.
    """
    pick = draw(st.integers(0, 7))
    near = _neighbours(like)
    if pick <= 1 and near:
        return draw(st.sampled_from(near))
    if pick == 2:
        return draw(st.floats(allow_nan=True, allow_infinity=True))
    if pick == 3:
        return draw(st.integers(-(2**64), 2**64))
    return draw(st.sampled_from(HOSTILE_SCALARS))


#: the largest amount of work a hostile value may ask of a work-size parameter (a count
#: of images or shapes a generator makes): a valid request for 10,000 images takes
#: minutes, which is the work asked for, not a hang
WORK_CAP = 64


def cap_work(value: Any) -> Any:
    """``value`` with a valid-looking count above :data:`WORK_CAP` (an integer, or an
    integral float, up to 2**32) brought down to :data:`WORK_CAP`; every other value
    (negative, zero, NaN, bools, strings, counts of 2**32 and more, which must be
    refused) unchanged.

    >>> cap_work(9803), cap_work(2**40) == 2**40, cap_work(-1), cap_work(True), cap_work(7.0)
    (64, True, -1, True, 7.0)
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        return value
    v = float(value)
    if math.isfinite(v) and v.is_integer() and WORK_CAP < v < 2**32:
        return type(value)(WORK_CAP)
    return value


def hostile_work_sizes(like: Any = None) -> st.SearchStrategy[Any]:
    """:func:`hostile_scalars` for a work-size parameter (``n_images`` of a data
    generator): the same values, with counts that are valid but large brought down to
    :data:`WORK_CAP` by :func:`cap_work`, so that a campaign's time limit judges the
    code rather than the amount of work requested."""
    return hostile_scalars(like=like).map(cap_work)


def hostile_flags(like: Any = None) -> st.SearchStrategy[Any]:
    """Values where a ``bool`` is expected: the other bool, and non-bools.

    Returns
    -------
    SearchStrategy
        ``not like``, ``None``, ``"yes"``, ``2``, ``nan``, ``np.bool_(True)``,
        ``[True]``.
    """
    other = not like if isinstance(like, bool) else True
    return st.sampled_from([other, None, "yes", "", 2, math.nan, np.bool_(True), [True]])


def hostile_choices(like: Any = None) -> st.SearchStrategy[Any]:
    """Values where a string choice (``method="ransac"``) is expected.

    Returns
    -------
    SearchStrategy
        The empty string, an unknown word, the valid word in upper case or padded,
        ``None``, a number, a list, bytes.
    """
    base = like if isinstance(like, str) else "x"
    return st.sampled_from(
        ["", "bogus", base.upper(), f" {base} ", None, 3, math.nan, [base], base.encode()]
    )


@st.composite
def hostile_tuples(draw: st.DrawFn, like: Any = None) -> Any:
    """Values where a small tuple of numbers (a size, a pattern, a window) is expected.

    Returns
    -------
    object
        Zeros, negatives, NaN, 2**40 entries, floats where ints go, strings, wrong
        lengths, None, a bare int, or ``like`` with one entry made hostile.
    """
    n = len(like) if isinstance(like, (tuple, list)) and like else 2
    fixed = [
        (0,) * n,
        (-1,) * n,
        (math.nan,) * n,
        (2**40,) * n,
        (1.5,) * n,
        ("3",) * n,
        (1,) * (n + 1),
        (1,),
        (),
        None,
        7,
        (math.inf,) * n,
    ]
    if isinstance(like, (tuple, list)) and like and draw(st.booleans()):
        i = draw(st.integers(0, len(like) - 1))
        out = list(like)
        out[i] = draw(hostile_scalars(like=like[i]))
        return tuple(out)
    return draw(st.sampled_from(fixed))


# --------------------------------------------------------------------------- other


@st.composite
def hostile_arrays(draw: st.DrawFn, like: Any = None) -> Any:
    """A hostile small array (a matrix such as K, H, T, F, or a vector).

    Half of the draws keep ``like``'s shape and poison its values (NaN, inf, 1e300,
    all zeros: singular, a dtype change, a layout); the rest change the shape
    (transposed, one row more or fewer, empty, a scalar, 3-D).

    Returns
    -------
    Layout or object
    """
    base = np.asarray(like, dtype=np.float64) if _numeric_array(like) else np.eye(3)
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    if draw(st.booleans()):
        a = base.copy()
        how = draw(st.sampled_from(["nan", "inf", "huge", "zeros", "tiny", "noise", "negate"]))
        if a.size:
            flat = a.reshape(-1)
            if how == "nan":
                flat[rng.integers(0, flat.size)] = math.nan
            elif how == "inf":
                flat[rng.integers(0, flat.size)] = math.inf
            elif how == "huge":
                flat *= 1e300
            elif how == "zeros":
                flat[:] = 0.0
            elif how == "tiny":
                flat *= 1e-300
            elif how == "noise":
                flat += rng.normal(size=flat.size) * 1e3
            else:
                flat *= -1
        dtype = draw(
            st.sampled_from(["float64", "float64", "float32", "int64", "complex64", "object"])
        )
        return Layout(_cast(a, dtype), draw(st.sampled_from(LAYOUTS)))
    shape_kind = draw(st.sampled_from(["T", "row+", "row-", "empty", "scalar", "3d", "list"]))
    if shape_kind == "T" and base.ndim == 2:
        return Layout(base.T.copy())
    if shape_kind == "row+":
        return Layout(
            np.concatenate([base, base[:1]]) if base.ndim and base.shape[0] else base[None]
        )
    if shape_kind == "row-" and base.ndim and base.shape[0]:
        return Layout(base[:-1].copy())
    if shape_kind == "empty":
        return Layout(np.zeros((0, *base.shape[1:])))
    if shape_kind == "scalar":
        return draw(st.sampled_from([np.float64(1.0), 0, math.nan]))
    if shape_kind == "3d":
        return Layout(np.stack([base, base]))
    return base.tolist()


def _numeric_array(like: Any) -> bool:
    if isinstance(like, np.ndarray):
        return like.dtype.kind in "biuf"
    return False


@st.composite
def hostile_sequences(
    draw: st.DrawFn, like: Any = None, item: st.SearchStrategy[Any] | None = None
) -> Any:
    """A hostile sequence where a list of arrays or records is expected.

    Parameters
    ----------
    like : sequence, optional
        The valid sequence.
    item : SearchStrategy, optional
        Hostile values of one item (tensors for a list of tensors); default chosen by
        the first item's type.

    Returns
    -------
    object
        ``[]``, ``None``, a bare number, ``like`` with its first item made hostile,
        ``like`` truncated to one item, or ``like`` doubled.
    """
    items = list(like) if isinstance(like, (list, tuple)) else []
    pick = draw(st.integers(0, 5))
    if pick == 0:
        return []
    if pick == 1:
        return draw(st.sampled_from([None, 3, "abc", math.nan]))
    if items and pick == 2:
        return items[:1]
    if items and pick == 3:
        return items + items
    if items:
        first = items[0]
        if item is not None:
            bad = draw(item)
        elif isinstance(first, np.ndarray) and first.ndim == 2 and first.shape[1] in (2, 3):
            bad = draw(hostile_points(like=first))
        elif isinstance(first, np.ndarray):
            bad = draw(hostile_arrays(like=first))
        elif isinstance(first, (int, float)) and not isinstance(first, bool):
            bad = draw(hostile_scalars(like=first))
        else:
            bad = draw(hostile_objects())
        return [bad, *items[1:]]
    return draw(st.sampled_from([[None], [math.nan], [[]]]))


def hostile_objects(like: Any = None) -> st.SearchStrategy[Any]:
    """Values where an object of a robopercept type (a camera, a filter, a config) goes.

    Returns
    -------
    SearchStrategy
        None, a number, a string, a dict, an empty list, a 3x3 matrix.
    """
    return st.sampled_from([None, 3, "object", {}, [], np.eye(3), math.nan])


def hostile_paths(workdir: str, like: Any = None) -> st.SearchStrategy[Any]:
    """Values where a file or folder path is expected.

    Parameters
    ----------
    workdir : str
        The campaign's scratch folder (``fuzz_inputs`` files prepared there).

    Returns
    -------
    SearchStrategy
        A missing file, a missing folder, the scratch folder itself, an empty file, a
        file of random bytes with the right extension, a name with a NUL byte, a
        300-character name, ``""``, ``None``, a number, bytes.
    """
    suffix = ""
    if like is not None:
        name = str(like)
        dot = name.rfind(".")
        suffix = name[dot:] if dot > name.rfind("/") else ""
    return st.sampled_from(
        [
            f"{workdir}/missing{suffix}",
            f"{workdir}/no/such/folder/file{suffix}",
            workdir,
            f"{workdir}/empty{suffix}",
            f"{workdir}/garbage{suffix}",
            f"{workdir}/nul\x00name{suffix}",
            f"{workdir}/{'n' * 300}{suffix}",
            "",
            None,
            3,
            f"{workdir}/garbage{suffix}".encode(),
        ]
    )
