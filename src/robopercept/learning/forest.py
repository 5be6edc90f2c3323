r"""Random forests (Breiman, 2001) for classification and regression.

Each of ``n_estimators`` trees is grown on a bootstrap sample (:math:`N` draws with
replacement from the :math:`N` training samples) and examines only
:math:`m \ll M` randomly drawn features at every node (``max_features``; default
:math:`\sqrt M` for classification, :math:`M / 3` for regression, Breiman's choices);
the trees are not pruned. The forest predicts the majority vote of its trees
(``voting="hard"``; ``"soft"`` takes the class with the largest mean of the trees'
class shares, as scikit-learn does) or, for regression, their mean.

The samples a tree's bootstrap left out (about :math:`e^{-1} \approx 37\%`) are its
out-of-bag samples; predicting every training sample with only the trees that did not
see it gives an honest accuracy (``oob_score_``) without a held-out set.

Each tree gets its own seed drawn from ``random_state`` before any tree is grown, so the forest
is the same for any ``n_jobs``; trees grow on ``n_jobs`` threads (the tree kernel
releases the GIL).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_bool, check_int
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
from robopercept.learning.tree import Tree, grow_tree, tree_settings
from robopercept.progress import progress_bar

__all__ = ["MAX_ESTIMATORS", "RandomForestClassifier", "RandomForestRegressor"]

#: most trees in a forest (each one is grown and kept)
MAX_ESTIMATORS = 100_000


def _threads(n_jobs: int | None) -> int:
    if n_jobs is None:
        return 1
    n_jobs = check_int(n_jobs, "n_jobs")
    cores = os.cpu_count() or 1
    return cores if n_jobs < 0 else max(1, min(n_jobs, cores))


class _BaseForest(Estimator):
    _criteria: tuple[str, ...] = ()
    _default_features: int | float | str | None = "sqrt"
    # parameters that both forests' __init__ set, read by the shared fitting code
    n_estimators: int
    criterion: str
    max_depth: int | None
    min_samples_split: int
    min_samples_leaf: int
    max_features: int | float | str | None
    bootstrap: bool
    oob_score: bool
    n_jobs: int | None
    random_state: RandomStateLike
    rng: int | np.random.Generator | None
    progress: bool

    def _oob(self, X: np.ndarray, samples: list[np.ndarray], target: np.ndarray) -> None:
        raise NotImplementedError

    def _grow_all(
        self,
        X: np.ndarray,
        y_class: np.ndarray,
        y_value: np.ndarray,
        n_classes: int,
        target: np.ndarray,
    ) -> None:
        n, d = X.shape
        n_trees = check_int(self.n_estimators, "n_estimators", 1)
        if n_trees > MAX_ESTIMATORS:
            raise InputError(f"n_estimators must be in 1..{MAX_ESTIMATORS}; got {n_trees}")
        bootstrap = check_bool(self.bootstrap, "bootstrap")
        oob_score = check_bool(self.oob_score, "oob_score")
        progress = check_bool(self.progress, "progress")
        settings = tree_settings(
            self.criterion,
            self._criteria,
            self.max_depth,
            self.min_samples_split,
            self.min_samples_leaf,
            self.max_features,
            d,
        )
        if oob_score and not bootstrap:
            raise InputError("oob_score needs bootstrap=True (without it no sample is left out)")
        seeds = seed_from(self._random_state(stacklevel=5)).integers(0, 2**63, size=n_trees)
        XT = np.ascontiguousarray(X.T)

        def one(seed: int) -> tuple[Tree, np.ndarray]:
            if bootstrap:
                samples = np.random.default_rng(seed).integers(0, n, size=n)
            else:
                samples = np.arange(n, dtype=np.int64)
            return grow_tree(XT, y_class, y_value, samples, n_classes, settings, int(seed)), samples

        with ThreadPoolExecutor(_threads(self.n_jobs)) as pool:
            grown = list(
                progress_bar(
                    pool.map(one, seeds.tolist()),
                    total=n_trees,
                    desc="random forest",
                    unit="tree",
                    disable=not progress,
                )
            )
        self.estimators_ = [t for t, _ in grown]
        imp = np.mean([t.importances(d) for t in self.estimators_], axis=0)
        self.feature_importances_ = imp / imp.sum() if imp.sum() > 0 else imp
        if oob_score:
            self._oob(X, [s for _, s in grown], target)

    def _tree_outputs(self, X: np.ndarray) -> np.ndarray:
        """Leaf values of every tree, ``(n_trees, N, n_out)``."""
        return np.stack([t.value[t.apply(X)] for t in self.estimators_])

    def _oob_values(
        self, X: np.ndarray, samples: list[np.ndarray]
    ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
        """Sums of out-of-bag leaf values and of votes per sample, and how many trees
        left each sample out."""
        n = X.shape[0]
        n_out = self.estimators_[0].value.shape[1]
        total = np.zeros((n, n_out))
        votes = np.zeros((n, n_out))
        seen = np.zeros(n, dtype=np.int64)
        for tree, s in zip(self.estimators_, samples, strict=True):
            out = np.ones(n, dtype=bool)
            out[s] = False
            rows = np.flatnonzero(out)
            v = tree.value[tree.apply(X[rows])]
            total[rows] += v
            votes[rows, np.argmax(v, axis=1)] += 1.0
            seen[rows] += 1
        return (total, votes), seen


class RandomForestClassifier(ClassifierMixin, _BaseForest):
    """A random forest of classification trees.

    Parameters
    ----------
    n_estimators : int
        Number of trees.
    criterion : {"gini", "entropy"}
    max_depth, min_samples_split, min_samples_leaf
        As in :class:`~robopercept.learning.tree.DecisionTreeClassifier` (default:
        unpruned).
    max_features : int, float, "sqrt", "log2" or None
        Features drawn per node (default :math:`\\sqrt M`).
    bootstrap : bool
        Grow each tree on a bootstrap sample (else on all samples).
    oob_score : bool
        Compute ``oob_score_``, the out-of-bag accuracy.
    voting : {"hard", "soft"}
        Majority vote of the trees, or the largest mean class share.
    n_jobs : int or None
        Threads growing trees (None: 1, -1: all cores); the result does not depend on it.
    random_state : int, Generator, RandomState or None
        Seed of the bootstrap samples and feature draws (scikit-learn's name); the same
        seed gives the same forest.
    rng : int, Generator or None
        Deprecated alias of ``random_state`` (one release): ``fit`` warns and uses it.
    progress : bool

    Attributes
    ----------
    estimators_ : list of the trees' node arrays
    classes_ : (c,) ndarray
    feature_importances_ : (d,) ndarray
    oob_score_ : float
    oob_decision_function_ : (N, c) ndarray
    """

    _criteria = ("gini", "entropy")

    def __init__(
        self,
        n_estimators: int = 100,
        *,
        criterion: str = "gini",
        max_depth: int | None = None,
        min_samples_split: int = 2,
        min_samples_leaf: int = 1,
        max_features: int | float | str | None = "sqrt",
        bootstrap: bool = True,
        oob_score: bool = False,
        voting: str = "hard",
        n_jobs: int | None = None,
        random_state: RandomStateLike = None,
        progress: bool = False,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        self.n_estimators = n_estimators
        self.criterion = criterion
        self.max_depth = max_depth
        self.min_samples_split = min_samples_split
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.bootstrap = bootstrap
        self.oob_score = oob_score
        self.voting = voting
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.rng = rng
        self.progress = progress

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> RandomForestClassifier:
        """Grow the forest on ``X`` (N, d) and labels ``y`` (N,)."""
        X = self._check_X(X, fitting=True)
        check_option(self.voting, "voting", ("hard", "soft"))
        codes = self._encode_labels(y, X.shape[0])
        self._grow_all(X, codes, np.zeros(1), self.classes_.size, codes)
        return self

    def _oob(self, X: np.ndarray, samples: list[np.ndarray], codes: np.ndarray) -> None:
        (total, votes), seen = self._oob_values(X, samples)
        ok = seen > 0
        source = votes if self.voting == "hard" else total
        shares = np.zeros_like(total)
        shares[ok] = total[ok] / seen[ok, None]
        self.oob_decision_function_ = shares
        pred = np.argmax(source[ok], axis=1)
        self.oob_score_ = float(np.mean(pred == codes[ok]))

    def predict_proba(self, X: npt.ArrayLike) -> np.ndarray:
        """Mean of the trees' leaf class shares, ``(N, c)``."""
        self._check_fitted("estimators_")
        return self._tree_outputs(self._check_X(X)).mean(axis=0)

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Majority vote of the trees (``voting="soft"``: the largest mean share)."""
        self._check_fitted("estimators_")
        out = self._tree_outputs(self._check_X(X))
        if self.voting == "soft":
            return self.classes_[np.argmax(out.mean(axis=0), axis=1)]
        winners = np.argmax(out, axis=2)  # (n_trees, N)
        n_classes = self.classes_.size
        counts = np.zeros((winners.shape[1], n_classes), dtype=np.int64)
        for w in winners:
            counts[np.arange(w.size), w] += 1
        return self.classes_[np.argmax(counts, axis=1)]


class RandomForestRegressor(RegressorMixin, _BaseForest):
    """A random forest of regression trees: the mean of their predictions.

    Parameters as :class:`RandomForestClassifier` (criterion ``"squared_error"``;
    ``max_features`` default 1/3 of the features); ``oob_score_`` is the out-of-bag
    :math:`R^2` and ``oob_prediction_`` the out-of-bag predictions.
    """

    _criteria = ("squared_error",)

    def __init__(
        self,
        n_estimators: int = 100,
        *,
        criterion: str = "squared_error",
        max_depth: int | None = None,
        min_samples_split: int = 2,
        min_samples_leaf: int = 1,
        max_features: int | float | str | None = 1 / 3,
        bootstrap: bool = True,
        oob_score: bool = False,
        n_jobs: int | None = None,
        random_state: RandomStateLike = None,
        progress: bool = False,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        self.n_estimators = n_estimators
        self.criterion = criterion
        self.max_depth = max_depth
        self.min_samples_split = min_samples_split
        self.min_samples_leaf = min_samples_leaf
        self.max_features = max_features
        self.bootstrap = bootstrap
        self.oob_score = oob_score
        self.n_jobs = n_jobs
        self.random_state = random_state
        self.rng = rng
        self.progress = progress

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> RandomForestRegressor:
        """Grow the forest on ``X`` (N, d) and targets ``y`` (N,)."""
        X = self._check_X(X, fitting=True)
        y = check_target(y, X.shape[0], type(self).__name__)
        self._grow_all(X, np.zeros(1, dtype=np.int64), y, 0, y)
        return self

    def _oob(self, X: np.ndarray, samples: list[np.ndarray], y_all: np.ndarray) -> None:
        (total, _), seen = self._oob_values(X, samples)
        ok = seen > 0
        pred = np.full(X.shape[0], np.nan)
        pred[ok] = total[ok, 0] / seen[ok]
        self.oob_prediction_ = pred
        y = y_all[ok]
        ss_tot = float(np.sum((y - y.mean()) ** 2))
        self.oob_score_ = 1.0 - float(np.sum((y - pred[ok]) ** 2)) / ss_tot if ss_tot else 0.0

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Mean of the trees' predictions."""
        self._check_fitted("estimators_")
        return self._tree_outputs(self._check_X(X))[..., 0].mean(axis=0)
