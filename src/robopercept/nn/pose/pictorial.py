r"""Pictorial structures: the pre-deep-learning pose baseline, exact on a tree.

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

:class:`PictorialStructures` learns such a model from images with keypoints, with the
scikit-learn contract: the springs from the mean and the (diagonal) variance of
:math:`l_i - l_{p(i)}` over labelled pairs (:math:`w = 1 / (2 \sigma^2)`, the
Gaussian's negative log-likelihood), and one linear appearance classifier per joint
(L2-regularized logistic regression, scikit-learn's ``LogisticRegression`` objective)
on :func:`grid_descriptors`: gradient-orientation histograms
(:func:`robopercept.features.cell_histograms`) and colour means of the cells around
each point of a coarse grid. The unary cost is :math:`c_i = -\log \sigma(s_i)` with
:math:`s_i` the classifier's score.

Examples
--------
>>> costs = np.full((2, 3, 4), 5.0)
>>> costs[0, 1, 1] = 0.0          # joint 0 (the root) likes (x=1, y=1)
>>> sol = pictorial_structures(costs, [-1, 0], [[0, 0], [2, 0]], [[1, 1], [1, 1]])
>>> sol.locations.tolist(), sol.energy  # joint 1 sits 2 cells right of its parent
([[1, 1], [3, 1]], 5.0)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy.optimize import minimize
from scipy.special import expit

from robopercept._checks import (
    as_rng,
    check_bool,
    check_choice,
    check_image,
    check_int,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import DegenerateError, InputError, NotFittedError
from robopercept.features import cell_histograms
from robopercept.nn.skeleton import Skeleton

__all__ = [
    "DistanceTransform",
    "PictorialSolution",
    "PictorialStructures",
    "distance_transform_1d",
    "generalized_distance_transform",
    "grid_descriptors",
    "pictorial_structures",
]

Method = Literal["envelope", "brute"]
_METHODS = ("envelope", "brute")

#: largest |finite cost| accepted: squares of grid offsets times weights stay finite
MAX_COST = 1e100
#: largest spring weight accepted
MAX_WEIGHT = 1e100
#: largest |offset| accepted, in grid cells
MAX_OFFSET = 1e6
_MAX_RADIUS = 8  # grid_descriptors neighbourhood (the descriptor grows as (2r+1)^2)
_MAX_CELL = 65536
_MAX_COORD = 1e9  # keypoint coordinates, pixels
_BRUTE_CHUNK = 1 << 22  # elements of the brute-force (lines, n, n) block
_MAX_BRUTE = 2048  # longest line the brute force takes (its (n, n) table: 32 MiB)
_HIST_EPS = 1.0  # block normalization of the orientation histograms (0..255 scale)


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


def _check_parents(value: npt.ArrayLike, n: int) -> tuple[np.ndarray, list[int]]:
    """``parents`` as int64 (J,) forming a tree, and a root-first (BFS) order."""
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


def _solve(
    costs: np.ndarray,
    par: np.ndarray,
    order: list[int],
    mu: np.ndarray,
    w: np.ndarray,
    want_marginals: bool,
    method: str,
) -> PictorialSolution:
    """The exact minimum of the tree energy (checked inputs)."""
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
    par, order = _check_parents(parents, n)
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
    return _solve(costs, par, order, mu, w, want, _check_method(method))


# ============================================================================ descriptors


def _unit_image(image: npt.ArrayLike, name: str) -> np.ndarray:
    """``image`` as float64 (H, W, 3): uint8 / 255, uint16 / 65535, gray repeated."""
    img = check_image(image, name)
    if img.dtype == np.uint8:
        out = img / 255.0
    elif img.dtype == np.uint16:
        out = img / 65535.0
    else:
        out = img.astype(np.float64)
    if out.ndim == 2:
        out = np.repeat(out[:, :, None], 3, axis=2)
    return out


def _descriptors(img: np.ndarray, cell: int, radius: int, orientations: int) -> np.ndarray:
    """grid_descriptors of a checked float64 (H, W, 3) image."""
    h, w = img.shape[:2]
    gh, gw = h // cell, w // cell
    if gh == 0 or gw == 0:
        raise InputError(
            f"image of {h}x{w} pixels is smaller than one {cell}x{cell} cell: use a larger "
            "image or a smaller cell"
        )
    hist = cell_histograms(img, cell, orientations)  # (gh, gw, nb), 0..255 gradient scale
    colour = img[: gh * cell, : gw * cell].reshape(gh, cell, gw, cell, 3).mean(axis=(1, 3))
    k = 2 * radius + 1

    def neighbourhoods(a: np.ndarray) -> np.ndarray:
        # (gh, gw, c) -> (gh, gw, k * k * c): the k x k cells around each cell, edges
        # repeated, row by row
        padded = np.pad(a, ((radius, radius), (radius, radius), (0, 0)), mode="edge")
        win = np.lib.stride_tricks.sliding_window_view(padded, (k, k), axis=(0, 1))
        return np.moveaxis(win, 2, 4).reshape(gh, gw, -1)

    blocks = neighbourhoods(hist)
    blocks = blocks / np.sqrt((blocks**2).sum(axis=2, keepdims=True) + _HIST_EPS**2)
    return np.concatenate([blocks, neighbourhoods(colour)], axis=2)


def _check_descriptor_params(cell: Any, radius: Any, orientations: Any) -> tuple[int, int, int]:
    c = check_int(cell, "cell", 1)
    if c > _MAX_CELL:
        raise InputError(f"cell must be at most {_MAX_CELL} pixels; got {c}")
    r = check_int(radius, "radius", 0)
    if r > _MAX_RADIUS:
        raise InputError(
            f"radius must be at most {_MAX_RADIUS} cells (the descriptor grows as "
            f"(2 radius + 1)^2); got {r}"
        )
    o = check_int(orientations, "orientations", 1)
    if o > 360:
        raise InputError(f"orientations must be in [1, 360]; got {o}")
    return c, r, o


def grid_descriptors(
    image: npt.ArrayLike, cell: int = 4, radius: int = 1, orientations: int = 9
) -> np.ndarray:
    r"""Local appearance descriptors on a grid of ``cell``-pixel cells: the part
    detectors' input of :class:`PictorialStructures`.

    For every cell :math:`(g_y, g_x)` of the ``(H // cell, W // cell)`` grid, the
    :math:`k \times k` cells around it (:math:`k = 2\,\mathrm{radius} + 1`, image edges
    repeated) contribute

    * their gradient-orientation histograms (:func:`robopercept.features.cell_histograms`:
      unsigned orientations, votes split between the two nearest bins, gradients on the
      0..255 scale), concatenated into :math:`v` and normalized together as
      :math:`v / \sqrt{\lVert v \rVert^2 + 1}` (HOG's L2 block norm), and
    * their mean colours (R, G, B in [0, 1]).

    Layout: the :math:`k^2` histograms row by row, then the :math:`k^2` colours row by
    row.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 images are divided by 255 and uint16 by 65535; floating point images are
        used as they are (expected in [0, 1]); gray images count as R = G = B.
    cell : int
        Cell side in pixels; pixels beyond the last whole cell are left out.
    radius : int
        Neighbourhood radius in cells (at most 8).
    orientations : int
        Histogram bins over [0, pi).

    Returns
    -------
    (H // cell, W // cell, k * k * (orientations + 3)) float64 ndarray

    Raises
    ------
    InputError
        If the image is not an image or is smaller than one cell, or a parameter is out
        of range.

    Examples
    --------
    >>> img = np.zeros((16, 24, 3))
    >>> img[:, 12:] = (1.0, 0.0, 0.0)          # a red right half: a vertical edge
    >>> d = grid_descriptors(img, cell=4, radius=1, orientations=9)
    >>> d.shape
    (4, 6, 108)
    >>> d[0, 4, 81 + 12:81 + 15].tolist()     # the centre cell's mean colour
    [1.0, 0.0, 0.0]
    """
    c, r, o = _check_descriptor_params(cell, radius, orientations)
    return _descriptors(_unit_image(image, "image"), c, r, o)


# ============================================================================ the model


def _fit_logistic(X: np.ndarray, y: np.ndarray, C: float) -> tuple[np.ndarray, float]:
    """L2-regularized logistic regression, scikit-learn's objective (intercept free):
    min_w,b 1/2 |w|^2 + C sum_i log(1 + exp(-t_i (w . x_i + b))), t = 2 y - 1, by
    trust-region Newton-CG (liblinear's method) with exact Hessian-vector products."""
    t = np.where(y > 0, 1.0, -1.0)
    n, d = X.shape

    # everything divided by n: the gradient tolerance is then relative to the data
    def objective(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w, b = theta[:d], theta[d]
        m = t * (X @ w + b)
        loss = C * np.logaddexp(0.0, -m).sum() + 0.5 * float(w @ w)
        g = -C * t * expit(-m)  # d loss / d (w . x + b)
        grad = np.empty(d + 1)
        grad[:d] = X.T @ g + w
        grad[d] = g.sum()
        return loss / n, grad / n

    def hessp(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
        m = t * (X @ theta[:d] + theta[d])
        u = C * expit(m) * expit(-m) * (X @ v[:d] + v[d])
        out = np.empty(d + 1)
        out[:d] = X.T @ u + v[:d]
        out[d] = u.sum()
        return out / n

    # (L-BFGS-B would do too, but its many tiny BLAS calls crawl on a busy machine)
    res = minimize(
        objective,
        np.zeros(d + 1),
        jac=True,
        hessp=hessp,
        method="trust-ncg",
        options={"gtol": 1e-10, "maxiter": 500},
    )
    return res.x[:d].copy(), float(res.x[d])


def _as_images(images: Any, name: str) -> list[np.ndarray]:
    """A batch (N, H, W[, 3]) array or a sequence of images, as float64 (H, W, 3)."""
    if isinstance(images, np.ndarray):
        if images.ndim == 3 and images.shape[2] == 3:
            raise InputError(
                f"{name} must be a batch (N, H, W, 3) or (N, H, W), or a list of images; got "
                f"shape {images.shape}: one colour image? wrap it in a list"
            )
        if images.ndim not in (3, 4):
            raise InputError(
                f"{name} must be a batch (N, H, W) or (N, H, W, 3), or a list of images; got "
                f"shape {images.shape}: wrap a single image in a list"
            )
        seq: Sequence[Any] = list(images)
    elif isinstance(images, (list, tuple)):
        seq = images
    else:
        raise InputError(
            f"{name} must be an (N, H, W, 3) array or a list of images; got {type(images).__name__}"
        )
    if len(seq) == 0:
        raise InputError(f"{name} must hold at least one image; got none")
    return [_unit_image(im, f"{name}[{i}]") for i, im in enumerate(seq)]


def _check_keypoints(value: Any, n_images: int, n_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, J, 2) coordinates (0 where unlabelled) and the (N, J) labelled mask."""
    arr = check_numeric(value, "keypoints")
    if arr.ndim != 3 or arr.shape[:2] != (n_images, n_joints) or arr.shape[2] not in (2, 3):
        raise InputError(
            f"keypoints must be (N, J, 3) = ({n_images}, {n_joints}, 3) as (x, y, v), or "
            f"(N, J, 2) with every joint labelled, for {n_images} images and "
            f"{n_joints} joints; got shape {arr.shape}"
        )
    if arr.shape[2] == 3:
        v = arr[..., 2]
        if not np.all(np.isfinite(v)):
            raise InputError("keypoints' visibility column v must be finite (0 = unlabelled)")
        labelled = v > 0
    else:
        labelled = np.ones(arr.shape[:2], bool)
    xy = np.where(labelled[..., None], arr[..., :2], 0.0)
    if not np.all(np.isfinite(xy)) or np.abs(xy).max(initial=0) > _MAX_COORD:
        raise InputError(
            f"labelled keypoints (v > 0) must have finite coordinates of at most "
            f"{_MAX_COORD:.0e} pixels; set v = 0 for joints without a location"
        )
    return xy, labelled


class PictorialStructures:
    r"""A pictorial-structures pose model learned from images with keypoints.

    The model of Felzenszwalb and Huttenlocher (2005) with linear part detectors: a
    joint's unary cost at grid cell :math:`q` is :math:`c_i(q) = -\log \sigma(a_i
    \cdot \phi(q) + b_i)` with :math:`\phi` the standardized :func:`grid_descriptors`
    and :math:`\sigma` the logistic function; a joint and its parent are held by a
    spring with the Gaussian negative log-likelihood :math:`\sum_{a \in \{x, y\}}
    (a_i - a_{p(i)} - \mu_{a,i})^2 / (2 \sigma_{a,i}^2)`. The pose of least energy is
    found exactly (:func:`pictorial_structures`) and its grid cells are returned as
    their centre pixels.

    ``fit`` learns, over the labelled pairs (``v > 0`` for both joints) of the
    training poses, :math:`\mu_i` and :math:`\sigma_i^2` as the mean and the variance
    of :math:`l_i - l_{p(i)}` in pixels (the variance floored at ``min_std**2``), and
    per joint an L2-regularized logistic regression (scikit-learn's
    ``LogisticRegression(C=C)`` objective, solved by trust-region Newton-CG) on the cell of each
    labelled joint (positive) against ``n_negatives`` random cells per image that are
    more than one cell away from it (negatives, drawn with ``random_state``).

    Parameters
    ----------
    skeleton : Skeleton
        The joints; its links must form a tree.
    cell : int
        Grid cell side in pixels (a 128 x 128 image at cell 4 is a 32 x 32 grid).
    root : int, str or None
        The tree's root (``Skeleton.parents``; default the joint of most links).
    radius : int
        Descriptor neighbourhood radius in cells (:func:`grid_descriptors`).
    orientations : int
        Orientation bins of the descriptors.
    n_negatives : int
        Negative cells drawn per training image.
    C : float
        Inverse regularization strength of the part classifiers.
    min_std : float or None
        Floor of the spring standard deviations, pixels; default ``cell / 2``.
    random_state : int, numpy.random.Generator or None
        Seed of the negative sampling.

    Attributes
    ----------
    parents_ : (J,) int64 ndarray
        The tree, ``-1`` at the root.
    offsets_ : (J, 2) float64 ndarray
        :math:`\mu_i` in pixels, ``(x, y)``; 0 at the root.
    variances_ : (J, 2) float64 ndarray
        :math:`\sigma_i^2` in pixels squared; 0 at the root.
    coef_ : (J, D) float64 ndarray
        :math:`a_i`, on standardized descriptors.
    intercept_ : (J,) float64 ndarray
        :math:`b_i`.
    feature_mean_, feature_scale_ : (D,) float64 ndarray
        The standardization :math:`\phi = (d - \text{mean}) / \text{scale}`.

    Examples
    --------
    Two joints, a red and a blue disc 8 pixels apart, on noise:

    >>> from robopercept.nn.skeleton import Skeleton
    >>> rng = np.random.default_rng(0)
    >>> yy, xx = np.mgrid[:32, :32]
    >>> def picture(x, y):
    ...     img = rng.uniform(0.3, 0.7, (32, 32, 3))
    ...     img[(xx - x) ** 2 + (yy - y) ** 2 <= 6] = (1.0, 0.0, 0.0)
    ...     img[(xx - x - 8) ** 2 + (yy - y) ** 2 <= 6] = (0.0, 0.0, 1.0)
    ...     return img
    >>> pos = rng.integers(6, 18, (12, 2)).astype(float)
    >>> images = np.stack([picture(x, y) for x, y in pos])
    >>> v = np.full((12, 1), 2.0)
    >>> kp = np.stack([np.c_[pos, v], np.c_[pos + [8, 0], v]], axis=1)  # (12, 2, 3)
    >>> arm = Skeleton("arm", ["a", "b"], [(0, 1)], [])
    >>> model = PictorialStructures(arm, cell=2, random_state=0).fit(images[:10], kp[:10])
    >>> model.offsets_[1].tolist()
    [8.0, 0.0]
    >>> bool(np.abs(model.predict(images[10:]) - kp[10:, :, :2]).max() <= 1.0)
    True
    """

    def __init__(
        self,
        skeleton: Skeleton,
        cell: int = 4,
        *,
        root: int | str | None = None,
        radius: int = 1,
        orientations: int = 9,
        n_negatives: int = 32,
        C: float = 1.0,
        min_std: float | None = None,
        random_state: int | np.random.Generator | None = None,
    ) -> None:
        self.skeleton = skeleton
        self.cell = cell
        self.root = root
        self.radius = radius
        self.orientations = orientations
        self.n_negatives = n_negatives
        self.C = C
        self.min_std = min_std
        self.random_state = random_state

    # -- scikit-learn's parameter protocol ----------------------------------------------
    _PARAMS = (
        "skeleton",
        "cell",
        "root",
        "radius",
        "orientations",
        "n_negatives",
        "C",
        "min_std",
        "random_state",
    )

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments by name (scikit-learn's ``clone`` uses them)."""
        return {name: getattr(self, name) for name in self._PARAMS}

    def set_params(self, **params: Any) -> PictorialStructures:
        """Set constructor arguments by name; returns self."""
        for key, value in params.items():
            if key not in self._PARAMS:
                raise InputError(
                    f"PictorialStructures has no parameter {key!r}; valid ones: "
                    f"{list(self._PARAMS)}"
                )
            setattr(self, key, value)
        return self

    def __repr__(self) -> str:
        shown = [repr(self.skeleton)] + [
            f"{k}={getattr(self, k)!r}" for k in self._PARAMS[1:] if getattr(self, k) is not None
        ]
        return f"PictorialStructures({', '.join(shown)})"

    # -- checks ---------------------------------------------------------------------------
    def _settings(self) -> tuple[int, int, int]:
        if not isinstance(self.skeleton, Skeleton):
            raise InputError(
                "skeleton must be a robopercept.nn.skeleton.Skeleton (e.g. MPII_16); got "
                f"{type(self.skeleton).__name__}"
            )
        return _check_descriptor_params(self.cell, self.radius, self.orientations)

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError(
                "this PictorialStructures is not fitted yet; call fit(images, keypoints) "
                "before predicting"
            )

    # -- learning -------------------------------------------------------------------------
    def fit(self, images: Any, keypoints: npt.ArrayLike) -> PictorialStructures:
        """Learn the springs and the part classifiers.

        Parameters
        ----------
        images : (N, H, W, 3) or (N, H, W) ndarray, or a list of images
            Images may differ in size when given as a list.
        keypoints : (N, J, 3) or (N, J, 2) array_like
            ``(x, y, v)`` in pixels; a joint counts where ``v > 0`` (without ``v``:
            every joint).

        Returns
        -------
        PictorialStructures
            ``self``.

        Raises
        ------
        InputError
            On malformed images, keypoints or parameters, or a skeleton that is not a
            tree.
        DegenerateError
            If some joint is never labelled inside the images, or some joint and its
            parent are never labelled together.
        """
        cell, radius, orientations = self._settings()
        n_neg = check_int(self.n_negatives, "n_negatives", 1)
        C = check_real(self.C, "C", 0.0, 1e10, low_inclusive=False)
        min_std = (
            cell / 2.0
            if self.min_std is None
            else check_real(self.min_std, "min_std", 0.0, 1e6, low_inclusive=False)
        )
        rng = as_rng(self.random_state)
        parents = self.skeleton.parents(self.root)
        imgs = _as_images(images, "images")
        J = self.skeleton.num_joints
        xy, labelled = _check_keypoints(keypoints, len(imgs), J)
        names = self.skeleton.joints

        offsets = np.zeros((J, 2))
        variances = np.zeros((J, 2))
        for i in np.flatnonzero(parents >= 0):
            p = parents[i]
            both = labelled[:, i] & labelled[:, p]
            if not both.any():
                raise DegenerateError(
                    f"joints {names[i]!r} and its parent {names[p]!r} are never labelled "
                    "together: cannot learn their spring; label them in some image"
                )
            d = xy[both, i] - xy[both, p]
            offsets[i] = d.mean(axis=0)
            variances[i] = np.maximum(d.var(axis=0), min_std**2)

        # samples: descriptors at the joints' cells (positives) and at random cells
        pos: list[list[np.ndarray]] = [[] for _ in range(J)]
        neg: list[list[np.ndarray]] = [[] for _ in range(J)]
        for img, pts, lab in zip(imgs, xy, labelled, strict=True):
            desc = _descriptors(img, cell, radius, orientations)
            gh, gw = desc.shape[:2]
            g = np.floor((pts + 0.5) / cell).astype(np.int64)  # (J, 2) grid (x, y)
            inside = lab & (g[:, 0] >= 0) & (g[:, 0] < gw) & (g[:, 1] >= 0) & (g[:, 1] < gh)
            cells = rng.choice(gh * gw, size=min(n_neg, gh * gw), replace=False)
            cy, cx = np.divmod(cells, gw)
            for j in range(J):
                far = np.ones(cells.size, bool)
                if inside[j]:
                    pos[j].append(desc[g[j, 1], g[j, 0]][None])
                    far = np.maximum(np.abs(cx - g[j, 0]), np.abs(cy - g[j, 1])) > 1
                neg[j].append(desc[cy[far], cx[far]])
        missing = [names[j] for j in range(J) if not pos[j]]
        if missing:
            raise DegenerateError(
                f"joints {missing} are never labelled inside the images: cannot learn what "
                "they look like; label them (v > 0) in some image"
            )
        every = np.concatenate([np.concatenate(pos[j] + neg[j]) for j in range(J)])
        mean = every.mean(axis=0)
        scale = every.std(axis=0)
        scale[scale < 1e-12] = 1.0
        coef = np.zeros((J, every.shape[1]))
        intercept = np.zeros(J)
        for j in range(J):
            P, N = np.concatenate(pos[j]), np.concatenate(neg[j])
            X = (np.concatenate([P, N]) - mean) / scale
            y = np.r_[np.ones(len(P)), np.zeros(len(N))]
            if len(N) == 0:
                raise DegenerateError(
                    f"no negative cells for joint {names[j]!r}: the images are too small "
                    "for their cell size; use larger images or a smaller cell"
                )
            coef[j], intercept[j] = _fit_logistic(X, y, C)

        self._fitted_settings = (cell, radius, orientations)
        self.parents_ = parents
        self.offsets_ = offsets
        self.variances_ = variances
        self.feature_mean_ = mean
        self.feature_scale_ = scale
        self.coef_ = coef
        self.intercept_ = intercept
        return self

    # -- inference ------------------------------------------------------------------------
    def _costs(self, img: np.ndarray) -> np.ndarray:
        # the descriptor settings of fit (set_params after fit takes effect at the next fit)
        desc = _descriptors(img, *self._fitted_settings)
        scores = ((desc - self.feature_mean_) / self.feature_scale_) @ self.coef_.T
        scores += self.intercept_
        return np.ascontiguousarray(np.moveaxis(np.logaddexp(0.0, -scores), 2, 0))

    def _grid_springs(self) -> tuple[np.ndarray, np.ndarray]:
        cell = float(self._fitted_settings[0])
        child = self.parents_ >= 0
        mu = np.where(child[:, None], self.offsets_ / cell, 0.0)
        var = np.where(child[:, None], self.variances_, 1.0)
        return mu, cell**2 / (2.0 * var)

    def predict_costs(self, image: npt.ArrayLike) -> np.ndarray:
        """The unary cost maps of one image: :math:`-\\log \\sigma(s_i)` per joint.

        Parameters
        ----------
        image : (H, W) or (H, W, 3) ndarray

        Returns
        -------
        (J, H // cell, W // cell) float64 ndarray
            Lower is more like the joint; cell :math:`(g_x, g_y)` is centred at pixel
            :math:`(g \\cdot \\mathrm{cell} + (\\mathrm{cell} - 1) / 2)`.
        """
        self._check_fitted()
        return self._costs(_unit_image(image, "image"))

    def predict(self, images: Any) -> np.ndarray:
        """The pose of least energy in every image.

        Parameters
        ----------
        images : (N, H, W, 3) or (N, H, W) ndarray, or a list of images

        Returns
        -------
        (N, J, 2) float64 ndarray
            Joint locations in pixels ``(x, y)``: the centres of the chosen grid cells.
        """
        self._check_fitted()
        imgs = _as_images(images, "images")
        parents, order = _check_parents(self.parents_, len(self.parents_))
        mu, w = self._grid_springs()
        cell = self._fitted_settings[0]
        out = np.empty((len(imgs), len(parents), 2))
        for k, img in enumerate(imgs):
            sol = _solve(self._costs(img), parents, order, mu, w, False, "envelope")
            out[k] = sol.locations * cell + (cell - 1) / 2.0
        return out
