r"""Decision trees for classification and regression (CART, Breiman et al., 1984).

A tree splits the samples of a node :math:`S` in two by one feature and a threshold,
:math:`S_L = \{x \in S : x_f \le t\}` and :math:`S_R = S \setminus S_L`, choosing the
split with the largest impurity decrease (the information gain)

.. math::

    \Delta = I(S) - \frac{|S_L|}{|S|} I(S_L) - \frac{|S_R|}{|S|} I(S_R),

where with class shares :math:`p_k` the impurity :math:`I` is the entropy
:math:`-\sum_k p_k \log_2 p_k` (``criterion="entropy"``) or the Gini index
:math:`1 - \sum_k p_k^2` (``"gini"``), and for regression the variance of the
targets (``"squared_error"``). Every threshold between two consecutive distinct values
of every examined feature is scored (the midpoint), each in :math:`O(1)` by sweeping
the sorted samples and updating running class counts (or sums). ``max_features``
features are examined per node, drawn at random; splitting stops at a pure node, at
``max_depth``, below ``min_samples_split`` samples, or where a child would have fewer
than ``min_samples_leaf``. A leaf predicts its class shares (``predict_proba``) and the
most frequent class, or its mean target.

The tree is grown depth-first by a numba kernel that releases the GIL, so a forest
grows its trees on several threads. Thresholds, the split rules and the tie handling
follow ``sklearn.tree.DecisionTreeClassifier``; the random draw of features differs,
so the trees are equivalent in accuracy, not identical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numba import njit, prange

from robopercept._checks import check_int
from robopercept.errors import InputError
from robopercept.learning._base import (
    ClassifierMixin,
    Estimator,
    RandomStateLike,
    RegressorMixin,
    check_option,
    check_target,
    seed_from,
)

__all__ = [
    "DecisionTreeClassifier",
    "DecisionTreeRegressor",
    "Tree",
    "TreeSettings",
    "grow_tree",
    "resolve_max_features",
    "tree_settings",
]

_CRITERIA = {"gini": 0, "entropy": 1, "squared_error": 2}
_FEATURE_EPS = 1e-7  # values closer than this are not split apart (as scikit-learn)
_NO_LIMIT = 2**62


@njit(cache=True, nogil=True)
def _next(state: np.ndarray) -> np.uint64:
    """splitmix64: a small, fast, well-mixed generator for the per-tree draws."""
    state[0] += np.uint64(0x9E3779B97F4A7C15)
    z = state[0]
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, nogil=True)
def _sort(keys: np.ndarray, pos: np.ndarray, lo: int, hi: int) -> None:
    """Sort ``keys[lo:hi]`` ascending, moving ``pos`` along: quicksort with a three-way
    partition (runs of equal values, common in image features, are done in one pass)
    and a median-of-three pivot; the larger part waits on an explicit stack (no
    recursion: numba's cache mishandles recursive kernels), so the stack stays below
    log2(n) entries; insertion sort below 16 elements."""
    stack = np.empty((128, 2), dtype=np.int64)
    top = 0
    stack[0, 0], stack[0, 1] = lo, hi
    top = 1
    while top > 0:
        top -= 1
        lo, hi = stack[top, 0], stack[top, 1]
        while hi - lo > 16:
            a, b, c = keys[lo], keys[(lo + hi) // 2], keys[hi - 1]
            pivot = max(min(a, b), min(max(a, b), c))
            lt, i, gt = lo, lo, hi - 1
            while i <= gt:
                v = keys[i]
                if v < pivot:
                    keys[i], keys[lt] = keys[lt], keys[i]
                    pos[i], pos[lt] = pos[lt], pos[i]
                    lt += 1
                    i += 1
                elif v > pivot:
                    keys[i], keys[gt] = keys[gt], keys[i]
                    pos[i], pos[gt] = pos[gt], pos[i]
                    gt -= 1
                else:
                    i += 1
            # push the larger part, go on with the smaller one
            if lt - lo < hi - gt - 1:
                stack[top, 0], stack[top, 1] = gt + 1, hi
                hi = lt
            else:
                stack[top, 0], stack[top, 1] = lo, lt
                lo = gt + 1
            top += 1
        for i in range(lo + 1, hi):
            k, p = keys[i], pos[i]
            j = i - 1
            while j >= lo and keys[j] > k:
                keys[j + 1] = keys[j]
                pos[j + 1] = pos[j]
                j -= 1
            keys[j + 1] = k
            pos[j + 1] = p


@njit(cache=True, nogil=True)
def _grow(
    XT: np.ndarray,
    y_class: np.ndarray,
    y_value: np.ndarray,
    samples: np.ndarray,
    n_classes: int,
    criterion: int,
    max_depth: int,
    min_split: int,
    min_leaf: int,
    max_features: int,
    seed: int,
):
    """Grow one tree on ``samples`` (indices into the columns of ``XT`` = X transposed,
    repeats allowed); see the module."""
    n = samples.size
    d = XT.shape[0]
    cap = 2 * n + 1
    n_out = n_classes if criterion < 2 else 1
    feature = np.full(cap, -1, dtype=np.int64)
    threshold = np.zeros(cap)
    left = np.full(cap, -1, dtype=np.int64)
    right = np.full(cap, -1, dtype=np.int64)
    value = np.zeros((cap, n_out))
    impurity = np.zeros(cap)
    n_node = np.zeros(cap, dtype=np.int64)
    idx = samples.copy()
    st_start = np.empty(cap, dtype=np.int64)
    st_end = np.empty(cap, dtype=np.int64)
    st_depth = np.empty(cap, dtype=np.int64)
    st_node = np.empty(cap, dtype=np.int64)
    feats = np.arange(d)
    xsorted = np.empty(n)
    order = np.empty(n, dtype=np.int64)
    ys = np.empty(n, dtype=np.int64)
    vs = np.empty(n)
    # x log x of every integer count a node can hold (entropy without log calls)
    table = np.zeros(n + 2)
    for c in range(1, n + 2):
        table[c] = c * math.log(c)
    counts = np.zeros(max(n_classes, 1))
    cl = np.zeros(max(n_classes, 1))
    cr = np.zeros(max(n_classes, 1))
    state = np.array([np.uint64(seed)], dtype=np.uint64)
    sp = 1
    st_start[0], st_end[0], st_depth[0], st_node[0] = 0, n, 0, 0
    n_nodes = 1
    while sp > 0:
        sp -= 1
        start, end, depth, node = st_start[sp], st_end[sp], st_depth[sp], st_node[sp]
        m = end - start
        n_node[node] = m
        # node statistics and impurity
        tot1 = 0.0
        if criterion < 2:
            counts[:] = 0.0
            for i in range(start, end):
                ys[i - start] = y_class[idx[i]]
                counts[ys[i - start]] += 1.0
            for k in range(n_classes):
                value[node, k] = counts[k] / m
            if criterion == 0:
                sq = 0.0
                for k in range(n_classes):
                    sq += counts[k] * counts[k]
                imp = 1.0 - sq / (m * m)
            else:
                s = 0.0
                for k in range(n_classes):
                    s += table[np.int64(counts[k])]
                imp = (math.log(m) - s / m) / math.log(2.0)
        else:
            s1 = 0.0
            s2 = 0.0
            for i in range(start, end):
                v = y_value[idx[i]]
                vs[i - start] = v
                s1 += v
                s2 += v * v
            mean = s1 / m
            value[node, 0] = mean
            imp = max(s2 / m - mean * mean, 0.0)
            tot1 = s1
        impurity[node] = imp
        if depth >= max_depth or m < min_split or m < 2 * min_leaf or imp <= 1e-12:
            continue
        best_f = -1
        best_score = -np.inf
        best_t = 0.0
        visited = 0
        f_left = d
        while f_left > 0 and visited < max_features:
            j = np.int64(_next(state) % np.uint64(f_left))
            f_left -= 1
            f = feats[j]
            feats[j] = feats[f_left]
            feats[f_left] = f
            row = XT[f]
            for i in range(m):
                xsorted[i] = row[idx[start + i]]
                order[i] = i
            _sort(xsorted, order, 0, m)
            if xsorted[m - 1] <= xsorted[0] + _FEATURE_EPS:
                continue  # constant here: does not count toward max_features
            visited += 1
            if criterion < 2:
                for k in range(n_classes):
                    cl[k] = 0.0
                    cr[k] = counts[k]
                sql = 0.0
                sqr = 0.0
                ent_l = 0.0
                ent_r = 0.0
                for k in range(n_classes):
                    sqr += counts[k] * counts[k]
                    ent_r += table[np.int64(counts[k])]
                for p in range(m - 1):
                    c = ys[order[p]]
                    if criterion == 0:
                        sql += 2.0 * cl[c] + 1.0
                        sqr -= 2.0 * cr[c] - 1.0
                    else:
                        a = np.int64(cl[c])
                        b = np.int64(cr[c])
                        ent_l += table[a + 1] - table[a]
                        ent_r += table[b - 1] - table[b]
                    cl[c] += 1.0
                    cr[c] -= 1.0
                    nl = p + 1
                    nr = m - nl
                    if nl < min_leaf:
                        continue
                    if nr < min_leaf:
                        break
                    xa = xsorted[p]
                    xb = xsorted[p + 1]
                    if xb <= xa + _FEATURE_EPS:
                        continue
                    if criterion == 0:
                        score = sql / nl + sqr / nr
                    else:
                        score = ent_l + ent_r - table[nl] - table[nr]
                    if score > best_score:
                        best_score = score
                        best_f = f
                        best_t = 0.5 * (xa + xb)
                        if best_t >= xb or best_t < xa:
                            best_t = xa
            else:
                sl = 0.0
                for p in range(m - 1):
                    sl += vs[order[p]]
                    nl = p + 1
                    nr = m - nl
                    if nl < min_leaf:
                        continue
                    if nr < min_leaf:
                        break
                    xa = xsorted[p]
                    xb = xsorted[p + 1]
                    if xb <= xa + _FEATURE_EPS:
                        continue
                    sr = tot1 - sl
                    score = sl * sl / nl + sr * sr / nr
                    if score > best_score:
                        best_score = score
                        best_f = f
                        best_t = 0.5 * (xa + xb)
                        if best_t >= xb or best_t < xa:
                            best_t = xa
        if best_f < 0:
            continue  # every feature constant here: a leaf
        # partition idx[start:end] by the split, in place
        i = start
        k = end - 1
        split_row = XT[best_f]
        while i <= k:
            if split_row[idx[i]] <= best_t:
                i += 1
            else:
                tmp = idx[i]
                idx[i] = idx[k]
                idx[k] = tmp
                k -= 1
        feature[node] = best_f
        threshold[node] = best_t
        left[node] = n_nodes
        right[node] = n_nodes + 1
        st_start[sp], st_end[sp], st_depth[sp], st_node[sp] = i, end, depth + 1, n_nodes + 1
        sp += 1
        st_start[sp], st_end[sp], st_depth[sp], st_node[sp] = start, i, depth + 1, n_nodes
        sp += 1
        n_nodes += 2
    return (
        feature[:n_nodes].copy(),
        threshold[:n_nodes].copy(),
        left[:n_nodes].copy(),
        right[:n_nodes].copy(),
        value[:n_nodes].copy(),
        impurity[:n_nodes].copy(),
        n_node[:n_nodes].copy(),
    )


@njit(cache=True, nogil=True, parallel=True)
def _apply(
    X: np.ndarray, feature: np.ndarray, threshold: np.ndarray, left: np.ndarray, right: np.ndarray
) -> np.ndarray:
    """Leaf index of every row of X."""
    out = np.empty(X.shape[0], dtype=np.int64)
    for i in prange(X.shape[0]):
        node = 0
        while left[node] >= 0:
            node = left[node] if X[i, feature[node]] <= threshold[node] else right[node]
        out[i] = node
    return out


def resolve_max_features(value: int | float | str | None, n_features: int) -> int:
    """``max_features`` as a count: None -> all, int, fraction, "sqrt", "log2"."""
    if value is None:
        return n_features
    if isinstance(value, str):
        check_option(value, "max_features", ("sqrt", "log2"))
        f = math.sqrt(n_features) if value == "sqrt" else math.log2(n_features)
        return max(1, int(f))
    if isinstance(value, (float, np.floating)):
        if not 0.0 < value <= 1.0:  # (False for NaN)
            raise InputError(f"max_features as a fraction must be in (0, 1]; got {value}")
        return max(1, int(value * n_features))
    k = check_int(value, "max_features", 1)
    if k > n_features:
        raise InputError(f"max_features={k} is more than the {n_features} features")
    return k


class Tree:
    """The arrays of a grown tree, in scikit-learn's ``tree_`` layout.

    Node ``i`` splits on ``X[:, feature[i]] <= threshold[i]`` (left) / ``>`` (right);
    a leaf has ``left[i] == right[i] == -1``. Children come after their parent.

    Attributes
    ----------
    feature, threshold : (n_nodes,) int64, float64
        Split feature and threshold of each inner node.
    left, right : (n_nodes,) int64
        Child indices (-1 at leaves).
    value : (n_nodes, n_outputs) float64
        Class fractions (classification) or the mean target (regression) of each node.
    impurity : (n_nodes,) float64
        Gini, entropy or squared error of each node's samples.
    n_node_samples : (n_nodes,) int64
        Number of (bootstrap) samples reaching each node.
    """

    def __init__(self, arrays: tuple) -> None:
        (
            self.feature,
            self.threshold,
            self.left,
            self.right,
            self.value,
            self.impurity,
            self.n_node_samples,
        ) = arrays

    @property
    def node_count(self) -> int:
        """Number of nodes (inner nodes and leaves)."""
        return int(self.feature.size)

    def apply(self, X: np.ndarray) -> np.ndarray:
        """Leaf index of every row of ``X`` ((n, d) float64, unchecked)."""
        return _apply(X, self.feature, self.threshold, self.left, self.right)

    def depth(self) -> int:
        """Length of the longest root-to-leaf path (a single leaf has depth 0)."""
        depth = np.zeros(self.node_count, dtype=np.int64)
        for node in range(self.node_count):  # children come after their parent
            if self.left[node] >= 0:
                depth[self.left[node]] = depth[self.right[node]] = depth[node] + 1
        return int(depth.max())

    def importances(self, n_features: int) -> np.ndarray:
        r"""Mean decrease in impurity per feature, normalized to sum 1.

        :math:`I_f = \sum_{t: f_t = f} N_t i_t - N_{l(t)} i_{l(t)} - N_{r(t)} i_{r(t)}`,
        divided by :math:`\sum_f I_f` (all zeros for a single leaf), as scikit-learn's
        ``feature_importances_``.
        """
        out = np.zeros(n_features)
        inner = np.flatnonzero(self.left >= 0)
        w = self.n_node_samples * self.impurity
        gain = w[inner] - w[self.left[inner]] - w[self.right[inner]]
        np.add.at(out, self.feature[inner], gain)
        total = out.sum()
        return out / total if total > 0 else out


@dataclass(frozen=True)
class TreeSettings:
    """Checked growth settings of a tree, as the compiled grower takes them.

    Attributes
    ----------
    criterion : int
        0 gini, 1 entropy, 2 squared error.
    max_depth, min_samples_split, min_samples_leaf, max_features : int
        As the estimators' parameters, resolved to counts (no depth limit is 2**62).
    """

    criterion: int
    max_depth: int
    min_samples_split: int
    min_samples_leaf: int
    max_features: int


def tree_settings(
    criterion: str,
    criteria: tuple[str, ...],
    max_depth: int | None,
    min_samples_split: int,
    min_samples_leaf: int,
    max_features: int | float | str | None,
    n_features: int,
) -> TreeSettings:
    """Check the tree parameters once and resolve them for :func:`grow_tree`.

    ``criterion`` must be one of ``criteria`` (the estimator's allowed ones);
    ``max_depth=None`` means no limit; ``max_features`` as :func:`resolve_max_features`.
    Raises :class:`~robopercept.errors.InputError` naming the parameter otherwise.
    """
    check_option(criterion, "criterion", criteria)
    # beyond 2^62 (int64 in the compiled tree) every limit is no limit
    depth = _NO_LIMIT if max_depth is None else check_int(max_depth, "max_depth", 1)
    return TreeSettings(
        _CRITERIA[criterion],
        min(depth, _NO_LIMIT),
        min(check_int(min_samples_split, "min_samples_split", 2), _NO_LIMIT),
        min(check_int(min_samples_leaf, "min_samples_leaf", 1), _NO_LIMIT),
        resolve_max_features(max_features, n_features),
    )


def grow_tree(
    XT: np.ndarray,
    y_class: np.ndarray,
    y_value: np.ndarray,
    samples: np.ndarray,
    n_classes: int,
    settings: TreeSettings,
    seed: int,
) -> Tree:
    """Grow one CART tree (unchecked; the estimators validate first).

    Parameters
    ----------
    XT : (d, n) float64, C-contiguous
        The training features transposed (one row per feature, for cache-friendly sorts).
    y_class : (n,) int64
        Class codes 0..n_classes-1 (classification; unused in regression).
    y_value : (n,) float64
        Targets (regression; unused in classification).
    samples : (m,) int64
        Indices of the rows to grow on, repeats allowed (bootstrap samples).
    n_classes : int
        Number of classes, 0 for regression.
    settings : TreeSettings
        From :func:`tree_settings`.
    seed : int
        Seed of the per-tree feature draws (splitmix64).

    Returns
    -------
    Tree
    """
    s = settings
    arrays = _grow(XT, y_class, y_value, samples, n_classes, s.criterion, s.max_depth,
                   s.min_samples_split, s.min_samples_leaf, s.max_features, seed)  # fmt: skip
    return Tree(arrays)


class _BaseTree(Estimator):
    _criteria: tuple[str, ...] = ()

    def __init__(
        self,
        *,
        criterion: str,
        max_depth: int | None = None,
        min_samples_split: int = 2,
        min_samples_leaf: int = 1,
        max_features: int | float | str | None = None,
        random_state: RandomStateLike = None,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        self.criterion = criterion
        self.max_depth = max_depth
        self.min_samples_split = min_samples_split
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.random_state = random_state
        self.rng = rng

    def _grow(
        self,
        X: np.ndarray,
        y_class: np.ndarray,
        y_value: np.ndarray,
        samples: np.ndarray,
        n_classes: int,
        seed: int,
    ) -> Tree:
        settings = tree_settings(
            self.criterion,
            self._criteria,
            self.max_depth,
            self.min_samples_split,
            self.min_samples_leaf,
            self.max_features,
            X.shape[1],
        )
        XT = np.ascontiguousarray(X.T)
        return grow_tree(XT, y_class, y_value, samples, n_classes, settings, seed)

    def _finish(self, tree: Tree) -> None:
        self.tree_ = tree
        self.feature_importances_ = tree.importances(self.n_features_in_)

    def apply(self, X: npt.ArrayLike) -> np.ndarray:
        """Index of the leaf each sample falls in."""
        self._check_fitted("tree_")
        return self.tree_.apply(self._check_X(X))

    def get_depth(self) -> int:
        """Depth of the fitted tree (a single leaf has depth 0)."""
        self._check_fitted("tree_")
        return self.tree_.depth()

    def get_n_leaves(self) -> int:
        self._check_fitted("tree_")
        return int(np.count_nonzero(self.tree_.left < 0))


class DecisionTreeClassifier(ClassifierMixin, _BaseTree):
    """A classification tree.

    Parameters
    ----------
    criterion : {"entropy", "gini"}
        Impurity whose decrease scores a split (entropy: the information gain).
    max_depth : int or None
        Deepest level (None: until pure or too small).
    min_samples_split : int
        Fewest samples a node needs to be split.
    min_samples_leaf : int
        Fewest samples each child must keep.
    max_features : int, float, "sqrt", "log2" or None
        Features examined per node (drawn at random); None: all.
    random_state : int, Generator, RandomState or None
        The order features are examined in (ties between equally good splits), and the
        features drawn with ``max_features`` (scikit-learn's name).
    rng : int, Generator or None
        Deprecated alias of ``random_state`` (one release): ``fit`` warns and uses it.

    Attributes
    ----------
    classes_ : (c,) ndarray
    tree_ : the node arrays (``feature``, ``threshold``, ``left``, ``right``,
        ``value`` = class shares, ``impurity``, ``n_node_samples``)
    feature_importances_ : (d,) ndarray
        Total impurity decrease per feature, normalized to sum 1.
    """

    _criteria = ("entropy", "gini")

    def __init__(
        self,
        criterion: str = "gini",
        max_depth: int | None = None,
        min_samples_split: int = 2,
        min_samples_leaf: int = 1,
        max_features: int | float | str | None = None,
        random_state: RandomStateLike = None,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        super().__init__(
            criterion=criterion,
            max_depth=max_depth,
            min_samples_split=min_samples_split,
            min_samples_leaf=min_samples_leaf,
            max_features=max_features,
            random_state=random_state,
            rng=rng,
        )

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> DecisionTreeClassifier:
        """Grow the tree on ``X`` (N, d) and labels ``y`` (N,)."""
        X = self._check_X(X, fitting=True)
        codes = self._encode_labels(y, X.shape[0])
        seed = int(seed_from(self._random_state()).integers(0, 2**63))
        samples = np.arange(X.shape[0], dtype=np.int64)
        tree = self._grow(X, codes, np.zeros(1), samples, self.classes_.size, seed)
        self._finish(tree)
        return self

    def predict_proba(self, X: npt.ArrayLike) -> np.ndarray:
        """Class shares of the leaf each sample falls in, ``(N, c)``."""
        leaves = self.apply(X)
        return self.tree_.value[leaves]

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """The most frequent class of each sample's leaf."""
        proba = self.predict_proba(X)
        return self.classes_[np.argmax(proba, axis=1)]


class DecisionTreeRegressor(RegressorMixin, _BaseTree):
    """A regression tree (variance reduction); parameters as the classifier's."""

    _criteria = ("squared_error",)

    def __init__(
        self,
        criterion: str = "squared_error",
        max_depth: int | None = None,
        min_samples_split: int = 2,
        min_samples_leaf: int = 1,
        max_features: int | float | str | None = None,
        random_state: RandomStateLike = None,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        super().__init__(
            criterion=criterion,
            max_depth=max_depth,
            min_samples_split=min_samples_split,
            min_samples_leaf=min_samples_leaf,
            max_features=max_features,
            random_state=random_state,
            rng=rng,
        )

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> DecisionTreeRegressor:
        """Grow the tree on ``X`` (N, d) and targets ``y`` (N,)."""
        X = self._check_X(X, fitting=True)
        y = check_target(y, X.shape[0], type(self).__name__)
        seed = int(seed_from(self._random_state()).integers(0, 2**63))
        samples = np.arange(X.shape[0], dtype=np.int64)
        tree = self._grow(X, np.zeros(1, dtype=np.int64), y, samples, 0, seed)
        self._finish(tree)
        return self

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Mean target of each sample's leaf."""
        leaves = self.apply(X)
        return self.tree_.value[leaves, 0]
