r"""Pictorial structures: the pre-deep-learning pose baseline, exact on a tree -- the
energy, the generalized distance transform and the max-sum (min-sum) on the tree.
Learning a model from images is :mod:`robopercept.nn.pose.pictorial_learn`.

NumPy only (no torch). A pose is the grid location :math:`l_i = (x_i, y_i)` of every
joint :math:`i` of a tree-shaped :class:`~robopercept.nn.skeleton.Skeleton`; the
model of Fischler and Elschlager (1973), made practical by Felzenszwalb and
Huttenlocher (2005), scores a pose by the energy

.. math::

    E(l) = \sum_i c_i(l_i)
         + \sum_{i \ne r} w_{x,i} (x_i - x_{p(i)} - \mu_{x,i})^2
                        + w_{y,i} (y_i - y_{p(i)} - \mu_{y,i})^2

with :math:`c_i` the appearance cost of joint :math:`i` at each location (lower is
better: a negative log-likelihood), :math:`p(i)` its parent, :math:`r` the root, and a
spring of rest offset :math:`\mu_i` and stiffness :math:`w_i` between a joint and its
parent. On a tree the minimum is found exactly by dynamic programming from the leaves
up: a joint sends its parent the message

.. math::

    m_i(l_p) = \min_{l_i} \, B_i(l_i) + w_i \cdot (l_i - l_p - \mu_i)^2, \qquad
    B_i = c_i + \sum_{k \in \mathrm{children}(i)} m_k ,

the root takes :math:`\arg\min B_r`, and every other joint is read back from the
argmin of its message at its parent's location. Each message is a *generalized
distance transform* (Felzenszwalb and Huttenlocher, 2012, "Distance Transforms of
Sampled Functions")

.. math::

    D(p) = \min_q f(q) + w_x (p_x - q_x - d_x)^2 + w_y (p_y - q_y - d_y)^2 ,

computed separably, one axis after the other, each 1-D transform in :math:`O(n)` with
the lower envelope of the parabolas :math:`f(q) + w (x - q)^2` rooted at the samples
(evaluated at :math:`x = p - d`, so the offset may be fractional). The whole pose
costs :math:`O(J H W)`. Entries :math:`+\infty` mark forbidden locations; they never
enter the envelope.

Examples
--------
>>> costs = np.full((2, 3, 4), 5.0)
>>> costs[0, 1, 1] = 0.0          # joint 0 (the root) likes (x=1, y=1)
>>> sol = pictorial_structures(costs, [-1, 0], [[0, 0], [2, 0]], [[1, 1], [1, 1]])
>>> sol.locations.tolist(), sol.energy  # joint 1 sits 2 cells right of its parent
([[1, 1], [3, 1]], 5.0)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_bool,
    check_choice,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import DegenerateError, InputError

__all__ = [
    "DistanceTransform",
    "PictorialSolution",
    "check_tree",
    "distance_transform_1d",
    "generalized_distance_transform",
    "pictorial_structures",
    "solve_tree",
]

Method = Literal["envelope", "brute"]
_METHODS = ("envelope", "brute")

#: largest |finite cost| accepted: squares of grid offsets times weights stay finite
MAX_COST = 1e100
#: largest spring weight accepted
MAX_WEIGHT = 1e100
#: largest |offset| accepted, in grid cells
MAX_OFFSET = 1e6
_BRUTE_CHUNK = 1 << 22  # elements of the brute-force (lines, n, n) block
_MAX_BRUTE = 2048  # longest line the brute force takes (its (n, n) table: 32 MiB)


# ============================================================================ results


@dataclass(frozen=True)
class DistanceTransform:
    """A (generalized) distance transform and where each minimum was found.

    Attributes
    ----------
    values : ndarray, float64
        :math:`D(p)`, the shape of the input; ``+inf`` where every :math:`f(q)` is.
    argmin : ndarray, int64
        The minimizing :math:`q` of every :math:`p`: for
        :func:`distance_transform_1d` the index along the transformed axis (the
        input's shape); for :func:`generalized_distance_transform` ``(H, W, 2)`` as
        ``(x, y)``. ``-1`` where ``values`` is ``+inf``.
    """

    values: np.ndarray
    argmin: np.ndarray


@dataclass(frozen=True)
class PictorialSolution:
    """The minimum-energy pose of :func:`pictorial_structures`.

    Attributes
    ----------
    locations : (J, 2) int64 ndarray
        Each joint's grid location as ``(x, y)`` = (column, row).
    energy : float
        :math:`E` at ``locations``, the minimum over all poses.
    min_marginals : (J, H, W) float64 ndarray or None
        With ``min_marginals=True``: :math:`\\min_{l : l_i = q} E(l)` for every joint
        :math:`i` and location :math:`q` (the energy of the best pose that puts joint
        :math:`i` at :math:`q`); each map's minimum is ``energy``.
    """

    locations: np.ndarray
    energy: float
    min_marginals: np.ndarray | None = None


# ============================================================================ kernels


@njit(cache=True, nogil=True)
def _envelope_lines(f, w, d, values, argmin):  # pragma: no cover - compiled
    # Felzenszwalb & Huttenlocher's lower envelope, one line (row of f) at a time:
    # D(p) = min_q f[q] + w (p - d - q)^2; v: the parabolas' roots on the envelope,
    # z: the boundaries between them (z[k] .. z[k+1] belongs to v[k]); +inf samples
    # are skipped, a line of them gives D = inf and argmin -1
    n_lines, n = f.shape
    v = np.empty(n, np.int64)
    z = np.empty(n + 1, np.float64)
    inf = np.inf
    for r in range(n_lines):
        k = -1
        for q in range(n):
            fq = f[r, q]
            if fq == inf:
                continue
            while k >= 0:
                vk = v[k]
                # intersection of the parabolas rooted at vk and q (q > vk); written
                # as a midpoint plus a correction so that w q^2 does not cancel
                s = 0.5 * (q + vk) + (fq - f[r, vk]) / (2.0 * w * (q - vk))
                if s <= z[k]:
                    k -= 1  # the parabola at vk is hidden by q's: drop it
                else:
                    k += 1
                    v[k] = q
                    z[k] = s
                    z[k + 1] = inf
                    break
            if k < 0:  # first finite sample (or one below every earlier parabola)
                k = 0
                v[0] = q
                z[0] = -inf
                z[1] = inf
        if k < 0:
            for p in range(n):
                values[r, p] = inf
                argmin[r, p] = -1
            continue
        j = 0
        for p in range(n):
            x = p - d
            while z[j + 1] < x:
                j += 1
            q = v[j]
            values[r, p] = f[r, q] + w * (x - q) * (x - q)
            argmin[r, p] = q


def _brute_lines(f: np.ndarray, w: float, d: float, values: np.ndarray, argmin: np.ndarray) -> None:
    # the O(n^2) reference: every (p, q) pair of every line, in chunks of lines
    n_lines, n = f.shape
    idx = np.arange(n, dtype=np.float64)
    spring = w * (idx[:, None] - d - idx[None, :]) ** 2  # (p, q)
    step = max(1, _BRUTE_CHUNK // max(n * n, 1))
    for a in range(0, n_lines, step):
        total = f[a : a + step, None, :] + spring[None]  # (lines, p, q)
        q = np.argmin(total, axis=2)
        best = np.take_along_axis(total, q[..., None], axis=2)[..., 0]
        values[a : a + step] = best
        argmin[a : a + step] = np.where(np.isinf(best), -1, q)


def _dt_lines(f: np.ndarray, w: float, d: float, method: str) -> tuple[np.ndarray, np.ndarray]:
    """The 1-D transform of every row of the C-contiguous float64 ``f`` (unchecked)."""
    if method == "brute" and f.shape[1] > _MAX_BRUTE:
        raise InputError(
            f"method='brute' is the O(n^2) reference for lines of at most {_MAX_BRUTE} "
            f"samples; got {f.shape[1]}: use method='envelope'"
        )
    values = np.empty(f.shape, np.float64)
    argmin = np.empty(f.shape, np.int64)
    if method == "brute":
        _brute_lines(f, w, d, values, argmin)
    else:
        _envelope_lines(f, float(w), float(d), values, argmin)
    return values, argmin


def _gdt(
    f: np.ndarray, wx: float, wy: float, dx: float, dy: float, method: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 2-D transform of ``f`` (H, W): values, argmin x, argmin y (unchecked)."""
    # along x on every row, then along y on every column of the result:
    # D(p) = min_qy wy (py - qy - dy)^2 + [min_qx f(qx, qy) + wx (px - qx - dx)^2]
    d1, ax = _dt_lines(np.ascontiguousarray(f, dtype=np.float64), wx, dx, method)
    d2t, ayt = _dt_lines(np.ascontiguousarray(d1.T), wy, dy, method)
    values, ay = d2t.T, ayt.T
    cols = np.broadcast_to(np.arange(f.shape[1]), f.shape)
    qx = np.where(ay >= 0, ax[np.maximum(ay, 0), cols], -1)
    return np.ascontiguousarray(values), qx, np.ascontiguousarray(ay)


# ============================================================================ checks


def _check_costs(value: npt.ArrayLike, name: str, ndim: int | None = None) -> np.ndarray:
    """float64 costs: finite (|c| <= MAX_COST) or +inf; NaN and -inf refused."""
    arr = check_numeric(value, name)
    if ndim is not None and arr.ndim != ndim:
        shape = {1: "(n,)", 2: "(H, W)", 3: "(J, H, W)"}[ndim]
        raise InputError(f"{name} must be {shape}; got shape {arr.shape}")
    if arr.ndim == 0 or arr.size == 0:
        raise InputError(f"{name} must be a non-empty array; got shape {arr.shape}")
    if np.isnan(arr).any():
        raise InputError(
            f"{name} has NaN entries: costs must be finite or +inf (+inf marks a forbidden "
            f"location); replace them, e.g. np.nan_to_num({name}, nan=np.inf)"
        )
    if (arr == -np.inf).any():
        raise InputError(
            f"{name} has -inf entries: costs must be finite or +inf; a location cannot be "
            "infinitely good: clip them"
        )
    finite = arr[np.isfinite(arr)]
    if finite.size and np.abs(finite).max() > MAX_COST:
        raise InputError(
            f"{name} has finite values up to {np.abs(finite).max():.3g}; values beyond "
            f"{MAX_COST:.0e} overflow the parabola arithmetic: rescale the costs"
        )
    return np.ascontiguousarray(arr, dtype=np.float64)


def _check_weight(value: Any, name: str) -> float:
    return check_real(value, name, 0.0, MAX_WEIGHT, low_inclusive=False)


def _check_offset(value: Any, name: str) -> float:
    return check_real(value, name, -MAX_OFFSET, MAX_OFFSET)


def _check_pair(value: Any, name: str, what: str) -> tuple[float, float]:
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"{name} must be a pair ({what}); got {plain_repr(value)}")
    return (value[0], value[1])


def _check_method(method: Any) -> str:
    return str(check_choice(method, "method", _METHODS))


# ============================================================================ transforms


def distance_transform_1d(
    f: npt.ArrayLike,
    weight: float = 1.0,
    offset: float = 0.0,
    *,
    axis: int = -1,
    method: Method = "envelope",
) -> DistanceTransform:
    r"""The 1-D generalized distance transform of sampled costs, along one axis.

    .. math::

        D(p) = \min_{q \in \{0, \dots, n-1\}} f(q) + w \, (p - q - d)^2 ,
        \qquad p = 0, \dots, n - 1,

    for every line of ``f`` along ``axis``. ``method="envelope"`` is Felzenszwalb and
    Huttenlocher's (2012) :math:`O(n)` algorithm: the lower envelope of the parabolas
    :math:`f(q) + w (x - q)^2`, built left to right, read at :math:`x = p - d`
    (compiled with numba). ``method="brute"`` is the :math:`O(n^2)` NumPy reference
    that tries every :math:`q`, for lines of at most 2048 samples; both agree to
    rounding (ties between equal minima may pick different :math:`q`).

    Parameters
    ----------
    f : (..., n, ...) array_like
        Costs, finite (at most :data:`MAX_COST` in magnitude) or ``+inf`` (a sample
        that may not be chosen).
    weight : float
        :math:`w > 0` (at most :data:`MAX_WEIGHT`).
    offset : float
        :math:`d`, in samples; fractional values are allowed (at most
        :data:`MAX_OFFSET` in magnitude).
    axis : int
        The axis transformed.
    method : {"envelope", "brute"}

    Returns
    -------
    DistanceTransform
        ``values`` (float64, the shape of ``f``) and ``argmin`` (int64, the same shape:
        the minimizing :math:`q`, ``-1`` on lines where every entry is ``+inf``).

    Raises
    ------
    InputError
        If ``f`` is empty or has NaN or ``-inf``, ``weight <= 0``, ``axis`` is out
        of range, or ``method="brute"`` is asked for lines longer than 2048.

    Examples
    --------
    >>> dt = distance_transform_1d([0.0, 9.0, 9.0, 9.0, 1.0], weight=1.0)
    >>> dt.values.tolist(), dt.argmin.tolist()
    ([0.0, 1.0, 4.0, 2.0, 1.0], [0, 0, 0, 4, 4])
    >>> distance_transform_1d([np.inf, 0.0, np.inf], 2.0, offset=1).values.tolist()
    [8.0, 2.0, 0.0]
    """
    arr = _check_costs(f, "f")
    w = _check_weight(weight, "weight")
    d = _check_offset(offset, "offset")
    m = _check_method(method)
    ax = check_int(axis, "axis")
    if not -arr.ndim <= ax < arr.ndim:
        raise InputError(f"axis must be in [{-arr.ndim}, {arr.ndim - 1}]; got {ax}")
    moved = np.moveaxis(arr, ax, -1)
    lines = np.ascontiguousarray(moved.reshape(-1, moved.shape[-1]))
    values, argmin = _dt_lines(lines, w, d, m)
    values = np.moveaxis(values.reshape(moved.shape), -1, ax)
    argmin = np.moveaxis(argmin.reshape(moved.shape), -1, ax)
    return DistanceTransform(np.ascontiguousarray(values), np.ascontiguousarray(argmin))


def generalized_distance_transform(
    f: npt.ArrayLike,
    weights: tuple[float, float] = (1.0, 1.0),
    offset: tuple[float, float] = (0.0, 0.0),
    *,
    method: Method = "envelope",
) -> DistanceTransform:
    r"""The 2-D generalized distance transform of a cost map (Felzenszwalb and
    Huttenlocher, 2012), with the location of every minimum.

    .. math::

        D(p) = \min_q f(q) + w_x (p_x - q_x - d_x)^2 + w_y (p_y - q_y - d_y)^2

    over the grid points :math:`q` of ``f``, for every grid point :math:`p`; computed
    separably (a 1-D transform of each row along x, then of each column of the result
    along y, :func:`distance_transform_1d`) in :math:`O(HW)`. ``argmin`` is the
    :math:`q` chosen for every :math:`p`: the backtracking table of
    :func:`pictorial_structures`. With ``f`` = 0 on a set and ``+inf`` elsewhere and
    ``w = 1``, ``values`` is the squared Euclidean distance transform of the set.

    Parameters
    ----------
    f : (H, W) array_like
        Costs, finite (at most :data:`MAX_COST` in magnitude) or ``+inf``.
    weights : (float, float)
        :math:`(w_x, w_y)`, each > 0 (at most :data:`MAX_WEIGHT`).
    offset : (float, float)
        :math:`(d_x, d_y)` in grid cells; fractional values are allowed.
    method : {"envelope", "brute"}
        The numba lower-envelope kernel, or the :math:`O(n^2)`-per-line NumPy
        reference (sides of at most 2048).

    Returns
    -------
    DistanceTransform
        ``values`` (H, W) float64 and ``argmin`` (H, W, 2) int64 ``(x, y)``, ``-1``
        where ``values`` is ``+inf`` (every entry of ``f`` is ``+inf``).

    Raises
    ------
    InputError
        If ``f`` is not a non-empty 2-D array of finite or ``+inf`` values, or a
        weight is not positive.

    Examples
    --------
    >>> f = np.full((3, 4), np.inf)
    >>> f[0, 0] = 0.0
    >>> dt = generalized_distance_transform(f, weights=(1.0, 2.0))
    >>> dt.values.tolist()
    [[0.0, 1.0, 4.0, 9.0], [2.0, 3.0, 6.0, 11.0], [8.0, 9.0, 12.0, 17.0]]
    >>> dt.argmin[2, 3].tolist()
    [0, 0]
    """
    arr = _check_costs(f, "f", ndim=2)
    wx, wy = _check_pair(weights, "weights", "w_x, w_y")
    dx, dy = _check_pair(offset, "offset", "d_x, d_y")
    wx, wy = _check_weight(wx, "weights[0]"), _check_weight(wy, "weights[1]")
    dx, dy = _check_offset(dx, "offset[0]"), _check_offset(dy, "offset[1]")
    m = _check_method(method)
    values, qx, qy = _gdt(arr, wx, wy, dx, dy, m)
    return DistanceTransform(values, np.stack([qx, qy], axis=-1))


# ============================================================================ the tree


def check_tree(value: npt.ArrayLike, n: int) -> tuple[np.ndarray, list[int]]:
    """``parents`` as int64 ``(J,)`` forming a tree, and a root-first (breadth-first)
    order of the joints.

    Parameters
    ----------
    value : (J,) array_like of int
        Each joint's parent, ``-1`` at the root.
    n : int
        The number of joints ``J``.

    Returns
    -------
    parents : (J,) int64 ndarray
    order : list of int
        The root first, every joint after its parent.

    Raises
    ------
    InputError
        Not one root, an index out of range or a joint its own parent, or a cycle.

    Examples
    --------
    >>> par, order = check_tree([1, -1, 1], 3)
    >>> par.tolist(), order
    ([1, -1, 1], [1, 0, 2])
    """
    arr = check_numeric(value, "parents")
    if arr.shape != (n,):
        raise InputError(
            f"parents must have one entry per joint ({n},), matching unary_costs; got "
            f"shape {arr.shape}"
        )
    if not np.all(arr == np.round(arr)):
        raise InputError(f"parents must be joint indices (integers); got {plain_repr(value)}")
    par = arr.astype(np.int64)
    roots = np.flatnonzero(par == -1)
    bad = (par < -1) | (par >= n) | (par == np.arange(n))
    if roots.size != 1 or bad.any():
        raise InputError(
            f"parents must describe a tree: -1 at exactly one joint (the root) and a joint "
            f"index 0..{n - 1} (not itself) elsewhere; got {par.tolist()}: use "
            "Skeleton.parents(root)"
        )
    children: list[list[int]] = [[] for _ in range(n)]
    for i, p in enumerate(par):
        if p >= 0:
            children[p].append(i)
    order = [int(roots[0])]
    for u in order:  # grows while iterating: breadth first
        order.extend(children[u])
    if len(order) != n:
        cyc = sorted(set(range(n)) - set(order))
        raise InputError(
            f"parents must describe a tree; joints {cyc} do not lead to the root "
            f"{int(roots[0])} (a cycle): got {par.tolist()}"
        )
    return par, order


def _check_springs(value: npt.ArrayLike, name: str, n: int) -> np.ndarray:
    arr = check_numeric(value, name)
    if arr.shape != (n, 2):
        raise InputError(
            f"{name} must be (J, 2) = ({n}, 2), one (x, y) row per joint; got shape {arr.shape}"
        )
    return np.ascontiguousarray(arr)


def solve_tree(
    costs: np.ndarray,
    par: np.ndarray,
    order: list[int],
    mu: np.ndarray,
    w: np.ndarray,
    want_marginals: bool,
    method: str,
) -> PictorialSolution:
    """The exact minimum of the tree energy for checked inputs: the unchecked arithmetic
    of :func:`pictorial_structures` (one upward pass of transforms, the argmins read
    back downwards, and a downward pass for the min-marginals).

    Parameters
    ----------
    costs : (J, H, W) float64 ndarray
    par : (J,) int64 ndarray
    order : list of int
        From :func:`check_tree`.
    mu, w : (J, 2) ndarray
        Spring offsets and weights (grid cells).
    want_marginals : bool
    method : {"envelope", "brute"}

    Returns
    -------
    PictorialSolution
    """
    n, _, wd = costs.shape
    belief = costs.copy()  # B_i = c_i + sum of the children's messages
    messages = np.zeros_like(costs)
    qx = np.zeros(costs.shape, np.int64)
    qy = np.zeros(costs.shape, np.int64)
    for i in reversed(order[1:]):
        # m_i(l_p) = min_{l_i} B_i(l_i) + w_i (l_p - l_i + mu_i)^2: offset -mu_i
        messages[i], qx[i], qy[i] = _gdt(belief[i], w[i, 0], w[i, 1], -mu[i, 0], -mu[i, 1], method)
        belief[par[i]] += messages[i]
    root = order[0]
    flat = int(np.argmin(belief[root]))
    energy = float(belief[root].flat[flat])
    if not np.isfinite(energy):
        raise DegenerateError(
            "every pose has infinite energy: some joint has +inf cost at every location "
            "(or its whole subtree cannot be placed); allow at least one location per joint"
        )
    loc = np.zeros((n, 2), np.int64)
    loc[root] = (flat % wd, flat // wd)
    for i in order[1:]:
        px, py = loc[par[i]]
        loc[i] = (qx[i, py, px], qy[i, py, px])
    marginals = None
    if want_marginals:
        # the message from the parent's side: down_i(l_i) = min_{l_p} O_p(l_p) +
        # w_i (l_i - l_p - mu_i)^2, O_p = c_p + down_p + the other children's messages
        down = np.zeros_like(costs)
        for i in order[1:]:
            p = par[i]
            outside = costs[p] + down[p]
            for k in order:
                if par[k] == p and k != i:
                    outside = outside + messages[k]
            down[i] = _gdt(outside, w[i, 0], w[i, 1], mu[i, 0], mu[i, 1], method)[0]
        marginals = belief + down
    return PictorialSolution(loc, energy, marginals)


def pictorial_structures(
    unary_costs: npt.ArrayLike,
    parents: npt.ArrayLike,
    offsets: npt.ArrayLike,
    weights: npt.ArrayLike,
    *,
    min_marginals: bool = False,
    method: Method = "envelope",
) -> PictorialSolution:
    r"""The minimum-energy pose of a tree-structured pictorial-structures model, exactly.

    Minimizes over the grid locations :math:`l_i = (x_i, y_i)` of the :math:`J` joints

    .. math::

        E(l) = \sum_i c_i(l_i)
             + \sum_{i \ne r} w_{x,i} (x_i - x_{p(i)} - \mu_{x,i})^2
                            + w_{y,i} (y_i - y_{p(i)} - \mu_{y,i})^2

    by dynamic programming from the leaves up (Felzenszwalb and Huttenlocher, 2005):
    each joint passes its parent the generalized distance transform
    (:func:`generalized_distance_transform`) of its cost plus its children's messages,
    the root takes the location of least total, and the joints are read back from the
    transforms' argmins. :math:`O(J H W)`; the same minimum as trying every pose
    (ties between equal energies may pick different poses).

    Parameters
    ----------
    unary_costs : (J, H, W) array_like
        :math:`c_i(x, y)` at ``[i, y, x]``: lower is better (e.g. a negative
        log-likelihood); ``+inf`` forbids a location. Finite values at most
        :data:`MAX_COST` in magnitude.
    parents : (J,) array_like of int
        Each joint's parent, ``-1`` at the root (``Skeleton.parents(root)``).
    offsets : (J, 2) array_like
        :math:`\mu_i = (\mu_x, \mu_y)`, the rest offset of joint :math:`i` from its
        parent in grid cells (fractional allowed); the root's row is ignored.
    weights : (J, 2) array_like
        :math:`(w_x, w_y)` of each spring, > 0; the root's row is ignored.
    min_marginals : bool
        Also return, for every joint and location, the least energy of a pose that
        puts the joint there (a second, downward pass of transforms).
    method : {"envelope", "brute"}
        The distance transform used (:func:`distance_transform_1d`).

    Returns
    -------
    PictorialSolution
        ``locations`` (J, 2) int64 ``(x, y)``, ``energy``, ``min_marginals``.

    Raises
    ------
    InputError
        If the shapes disagree, ``parents`` is not a tree, a cost is NaN or
        ``-inf``, or a weight is not positive.
    DegenerateError
        If every pose has infinite energy.

    Examples
    --------
    A chain of three joints with no appearance: each sits at its parent plus its offset
    from wherever the root lies; the flat costs leave the root at the first cell.

    >>> sol = pictorial_structures(np.zeros((3, 4, 5)), [-1, 0, 1],
    ...                            [[0, 0], [2, 1], [1, 2]], np.ones((3, 2)))
    >>> sol.locations.tolist(), sol.energy
    ([[0, 0], [2, 1], [3, 3]], 0.0)
    """
    costs = _check_costs(unary_costs, "unary_costs", ndim=3)
    n = costs.shape[0]
    par, order = check_tree(parents, n)
    mu = _check_springs(offsets, "offsets", n)
    w = _check_springs(weights, "weights", n)
    child = par >= 0
    if not np.all(np.isfinite(mu[child])) or np.abs(mu[child]).max(initial=0) > MAX_OFFSET:
        raise InputError(
            f"offsets must be finite and at most {MAX_OFFSET:.0e} cells; got "
            f"{plain_repr(mu[child])} for the non-root joints"
        )
    wc = w[child]
    if not np.all(np.isfinite(wc)) or np.any(wc <= 0) or np.any(wc > MAX_WEIGHT):
        raise InputError(
            f"weights must be > 0 (and at most {MAX_WEIGHT:.0e}) for every non-root joint; "
            f"got {plain_repr(wc)}: a spring weight is 1 / (2 variance)"
        )
    want = check_bool(min_marginals, "min_marginals")
    return solve_tree(costs, par, order, mu, w, want, _check_method(method))
