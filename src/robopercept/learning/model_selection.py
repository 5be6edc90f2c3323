r"""Splits, cross-validation and a small grid search.

:math:`k`-fold cross-validation cuts the samples into :math:`k` folds of nearly equal
size (the first ``n % k`` folds one larger), fits on :math:`k-1` of them and scores on
the one left out; the :math:`k` scores estimate how the model does on unseen data.
Stratified splits keep every class's share in every fold and split: the samples of
each class are dealt to the folds in turn, so a class of :math:`n_c` samples puts
:math:`\lfloor n_c / k \rfloor` or :math:`\lceil n_c / k \rceil` into each fold.

Estimators are copied with :func:`~robopercept.learning.clone` before each fit, so the
one passed in is never changed. Everything random takes ``random_state``
(scikit-learn's name: an int seed, None, a Generator or a RandomState; ``rng=`` is a
deprecated alias for one release) and gives the same splits for the same seed.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence, Sized
from dataclasses import InitVar, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_bool, check_int, plain_repr
from robopercept.errors import InputError
from robopercept.learning import metrics
from robopercept.learning._base import RandomStateLike, clone, random_generator, renamed_rng
from robopercept.progress import progress_bar

__all__ = [
    "MAX_CANDIDATES",
    "GridSearch",
    "KFold",
    "StratifiedKFold",
    "cross_val_score",
    "get_scorer",
    "train_test_split",
]


#: most parameter combinations a GridSearch tries (each is a full cross-validation)
MAX_CANDIDATES = 100_000


def _length(a: Any, name: str) -> int:
    """Number of samples (rows) of ``a``: ``len(a)``, refused for scalars and None."""
    if isinstance(a, (str, bytes)) or not isinstance(a, Sized) or getattr(a, "ndim", 1) == 0:
        raise InputError(
            f"{name} must be an array of samples (rows); got {type(a).__name__} "
            f"{plain_repr(a)[:60]}"
        )
    return len(a)


def _check_estimator(estimator: Any, name: str = "estimator") -> None:
    """An estimator has ``fit`` and ``get_params`` (so that it can be cloned)."""
    missing = [m for m in ("fit", "get_params") if not hasattr(estimator, m)]
    if missing or isinstance(estimator, type):
        raise InputError(
            f"{name} must be an estimator instance (with fit and get_params, e.g. "
            f"DecisionTreeClassifier()); got {type(estimator).__name__} "
            f"{plain_repr(estimator)[:60]}"
        )


def _n_samples(arrays: Sequence[Any]) -> int:
    if not arrays:
        raise InputError("train_test_split needs at least one array")
    lengths = {_length(a, f"arrays[{i}]") for i, a in enumerate(arrays)}
    if len(lengths) != 1:
        raise InputError(f"all arrays must have the same number of samples; got {sorted(lengths)}")
    return lengths.pop()


def _count(size: float | int | None, n: int, name: str) -> int:
    if size is None:
        return 0
    if isinstance(size, (float, np.floating)):
        if not 0.0 < size < 1.0:
            raise InputError(f"{name} as a fraction must be in (0, 1); got {size}")
        return int(np.ceil(size * n))
    return check_int(size, name, 0)


def _stratified_pick(y: np.ndarray, counts: Sequence[int], gen: np.random.Generator) -> list:
    """Deal shuffled samples of each class to the parts so each part keeps class shares."""
    classes, codes = np.unique(y, return_inverse=True)
    n = y.size
    parts: list[list[np.ndarray]] = [[] for _ in counts]
    # per class, how many go to each part: proportional shares, rounding by largest
    # remainder so the part sizes add up exactly
    per_class = np.bincount(codes, minlength=classes.size)
    alloc = np.zeros((classes.size, len(counts)), dtype=np.int64)
    for j, c in enumerate(counts):
        exact = per_class * c / n
        base = np.floor(exact).astype(np.int64)
        short = c - base.sum()
        order = np.argsort(-(exact - base), kind="stable")
        base[order[:short]] += 1
        alloc[:, j] = base
    # a class cannot give more than it has (rounding on tiny classes): clip
    for k in range(classes.size):
        members = gen.permutation(np.flatnonzero(codes == k))
        start = 0
        for j in range(len(counts)):
            take = min(int(alloc[k, j]), members.size - start)
            parts[j].append(members[start : start + take])
            start += take
    return [gen.permutation(np.concatenate(p)) for p in parts]


def train_test_split(
    *arrays: Any,
    test_size: float | int = 0.25,
    val_size: float | int | None = None,
    stratify: npt.ArrayLike | None = None,
    shuffle: bool = True,
    random_state: RandomStateLike = None,
    rng: int | np.random.Generator | None = None,
) -> list[Any]:
    """Split arrays into train and test parts (and a validation part with ``val_size``).

    Parameters
    ----------
    *arrays : array_like, each with the same first dimension N
    test_size, val_size : float in (0, 1) or int
        A fraction of N (rounded up) or a count.
    stratify : (N,) array_like, optional
        Class labels whose shares every part keeps.
    shuffle : bool
        ``False`` keeps the order (train first, then validation, then test).
    random_state : int, Generator, RandomState or None
        Seed of the shuffle (scikit-learn's name); a Generator is advanced.
    rng
        Deprecated alias of ``random_state`` (one release).

    Returns
    -------
    list
        ``[a_train, a_test, b_train, b_test, ...]`` like scikit-learn, or
        ``[a_train, a_val, a_test, ...]`` when ``val_size`` is given.
    """
    random_state = renamed_rng("train_test_split", random_state, rng)
    shuffle = check_bool(shuffle, "shuffle")
    n = _n_samples(arrays)
    n_test = _count(test_size, n, "test_size")
    n_val = _count(val_size, n, "val_size")
    n_train = n - n_test - n_val
    if n_train < 1 or n_test < 1 or (val_size is not None and n_val < 1):
        raise InputError(
            f"cannot split {n} samples into train, validation ({n_val}) and test ({n_test}) "
            "parts with at least one sample each; lower test_size/val_size"
        )
    gen = random_generator(random_state)
    if stratify is not None:
        y = metrics.check_labels(stratify, "stratify")
        if y.shape[0] != n:
            raise InputError(f"stratify must have {n} labels; got {y.shape[0]}")
        if not shuffle:
            raise InputError("stratified splits are shuffled; pass shuffle=True")
        picks = _stratified_pick(y, [n_val, n_test] if n_val else [n_test], gen)
        test = picks[-1]
        val = picks[0] if n_val else np.empty(0, np.int64)
        mask = np.ones(n, bool)
        mask[val] = False
        mask[test] = False
        train = gen.permutation(np.flatnonzero(mask))
    else:
        order = gen.permutation(n) if shuffle else np.arange(n)
        train, val, test = (
            order[:n_train],
            order[n_train : n_train + n_val],
            order[n_train + n_val :],
        )
    out: list[Any] = []
    for a in arrays:
        pieces = (train, val, test) if val_size is not None else (train, test)
        out.extend(_take(a, idx) for idx in pieces)
    return out


def _take(a: Any, idx: np.ndarray) -> Any:
    if isinstance(a, np.ndarray):
        return a[idx]
    if hasattr(a, "iloc"):
        return a.iloc[idx]
    return [a[i] for i in idx]


@dataclass(frozen=True)
class KFold:
    """K consecutive folds (shuffled first with ``shuffle=True``).

    Parameters
    ----------
    n_splits : int
        Number of folds, >= 2.
    shuffle : bool
        Shuffle the samples before cutting the folds.
    random_state : int, Generator, RandomState or None
        Seed of the shuffle (scikit-learn's name); a Generator or RandomState is
        advanced by every ``split``. ``rng=`` is its deprecated alias (one release).
    """

    n_splits: int = 5
    shuffle: bool = False
    random_state: RandomStateLike = None
    rng: InitVar[int | np.random.Generator | None] = None

    def __post_init__(self, rng: int | np.random.Generator | None) -> None:
        if rng is not None:  # deprecated alias of random_state
            seed = renamed_rng(type(self).__name__, self.random_state, rng, stacklevel=4)
            object.__setattr__(self, "random_state", seed)
        check_int(self.n_splits, "n_splits", 2)
        check_bool(self.shuffle, "shuffle")
        rs = self.random_state
        if not (
            rs is None
            or isinstance(rs, (np.random.Generator, np.random.RandomState))
            or (isinstance(rs, (int, np.integer)) and not isinstance(rs, bool))
        ):
            raise InputError(
                "random_state must be an int seed, None, a numpy.random.Generator or a "
                f"RandomState; got {plain_repr(rs)[:60]}"
            )

    def _check(self, n: int) -> int:
        k = check_int(self.n_splits, "n_splits", 2)
        if k > n:
            raise InputError(f"n_splits={k} is more than the {n} samples; lower n_splits")
        return k

    def split(
        self, X: Sized, y: npt.ArrayLike | None = None, groups: npt.ArrayLike | None = None
    ) -> Iterator[tuple]:
        """Yield ``(train_indices, test_indices)`` for each fold."""
        n = _length(X, "X")
        k = self._check(n)
        order = random_generator(self.random_state).permutation(n) if self.shuffle else np.arange(n)
        sizes = np.full(k, n // k)
        sizes[: n % k] += 1
        start = 0
        for size in sizes:
            test = order[start : start + size]
            train = np.concatenate([order[:start], order[start + size :]])
            start += size
            yield train, test

    def get_n_splits(
        self,
        X: npt.ArrayLike | None = None,
        y: npt.ArrayLike | None = None,
        groups: npt.ArrayLike | None = None,
    ) -> int:
        """Number of train/test splits, ``n_splits`` (the arguments are ignored, as in
        scikit-learn)."""
        return int(self.n_splits)


@dataclass(frozen=True)
class StratifiedKFold(KFold):
    """K folds that keep every class's share (each class dealt to the folds in turn)."""

    def split(
        self, X: Sized, y: npt.ArrayLike | None = None, groups: npt.ArrayLike | None = None
    ) -> Iterator[tuple]:
        if y is None:
            raise InputError("StratifiedKFold needs the labels y")
        y = metrics.check_labels(y, "y")
        n = y.shape[0]
        if _length(X, "X") != n:
            raise InputError(f"X has {len(X)} samples but y has {n} labels: one label per sample")
        k = self._check(n)
        _, codes, counts = np.unique(y, return_inverse=True, return_counts=True)
        if counts.max() < k:
            raise InputError(
                f"n_splits={k} is more than the members of every class "
                f"(largest {counts.max()}); lower n_splits"
            )
        gen = random_generator(self.random_state) if self.shuffle else None
        fold = np.empty(n, dtype=np.int64)
        offset = 0
        for c in range(counts.size):
            members = np.flatnonzero(codes == c)
            if gen is not None:
                members = gen.permutation(members)
            # deal round-robin, continuing where the previous class stopped so that
            # fold sizes stay within one of each other
            fold[members] = (offset + np.arange(members.size)) % k
            offset = (offset + members.size) % k
        for f in range(k):
            yield np.flatnonzero(fold != f), np.flatnonzero(fold == f)


_SCORERS: dict[str, Callable[[Any, np.ndarray, np.ndarray], float]] = {}


def _decision(est: Any, X: np.ndarray) -> np.ndarray:
    if hasattr(est, "decision_function"):
        s = est.decision_function(X)
    else:
        s = est.predict_proba(X)[:, 1]
    return np.asarray(s).ravel()


def get_scorer(scoring: str | Callable | None) -> Callable[[Any, np.ndarray, np.ndarray], float]:
    """A scorer ``f(estimator, X, y) -> float`` (higher is better).

    ``None`` uses the estimator's ``score``; names: ``accuracy``, ``precision``,
    ``recall``, ``f1`` (binary, positive class = the larger label), ``f1_macro``,
    ``roc_auc``, ``average_precision``; a callable is used as it is.
    """
    if scoring is None:
        return lambda est, X, y: float(est.score(X, y))
    if callable(scoring):
        return scoring
    if not isinstance(scoring, str):
        raise InputError(
            f"scoring must be a scorer name, a callable or None; got {plain_repr(scoring)[:60]}"
        )

    def binary(fn: Callable) -> Callable:
        return lambda est, X, y: float(fn(y, est.predict(X), pos_label=np.max(y)))

    table: Mapping[str, Callable] = {
        "accuracy": lambda est, X, y: metrics.accuracy_score(y, est.predict(X)),
        "precision": binary(metrics.precision_score),
        "recall": binary(metrics.recall_score),
        "f1": binary(metrics.f1_score),
        "f1_macro": lambda est, X, y: float(metrics.f1_score(y, est.predict(X), average="macro")),
        "roc_auc": lambda est, X, y: metrics.roc_auc_score(
            y, _decision(est, X), pos_label=np.max(y)
        ),
        "average_precision": lambda est, X, y: metrics.average_precision_score(
            y, _decision(est, X), pos_label=np.max(y)
        ),
    }
    if scoring not in table:
        raise InputError(f"unknown scoring {scoring!r}; choose one of {sorted(table)}")
    return table[scoring]


def _cv(cv: Any, estimator: Any) -> Any:
    if isinstance(cv, (int, np.integer)) and not isinstance(cv, (bool, np.bool_)):
        classifier = getattr(estimator, "_estimator_type", None) == "classifier"
        return StratifiedKFold(int(cv)) if classifier else KFold(int(cv))
    if isinstance(cv, (str, bytes)) or not callable(getattr(cv, "split", None)):
        raise InputError(
            f"cv must be an int or a splitter with .split(X, y); got {plain_repr(cv)[:60]}"
        )
    return cv


def cross_val_score(
    estimator: Any,
    X: npt.ArrayLike,
    y: npt.ArrayLike | None = None,
    *,
    cv: int | Any = 5,
    scoring: str | Callable | None = None,
    progress: bool = False,
) -> np.ndarray:
    """Score a fresh clone of ``estimator`` on each held-out fold.

    ``cv`` is a number of folds (stratified for classifiers, like scikit-learn) or a
    splitter; returns the ``(k,)`` scores.
    """
    _check_estimator(estimator)
    progress = check_bool(progress, "progress")
    try:
        X = np.asarray(X)
    except (TypeError, ValueError) as exc:  # ragged
        raise InputError(f"X must be a (n_samples, n_features) array; {exc}") from None
    n = _length(X, "X")
    y_arr = None
    if y is not None:
        try:
            y_arr = np.asarray(y)
        except (TypeError, ValueError) as exc:  # ragged
            raise InputError(f"y must be a 1-D array of targets; {exc}") from None
        if y_arr.ndim == 2 and y_arr.shape[1] == 1:
            y_arr = y_arr.ravel()
        if y_arr.ndim != 1 or y_arr.shape[0] != n:
            raise InputError(
                f"y must be 1-D with one value per sample of X ({n}); got shape {y_arr.shape}"
            )
    scorer = get_scorer(scoring)
    splitter = _cv(cv, estimator)
    scores = []
    splits = list(splitter.split(X, y_arr))
    for train, test in progress_bar(
        splits, desc="cross-validation", unit="fold", disable=not progress
    ):
        est = clone(estimator)
        if y_arr is None:
            est.fit(X[train])
            scores.append(scorer(est, X[test], None))
        else:
            est.fit(X[train], y_arr[train])
            scores.append(scorer(est, X[test], y_arr[test]))
    return np.asarray(scores, dtype=np.float64)


class GridSearch:
    """Exhaustive search over a parameter grid, scored by cross-validation.

    Parameters
    ----------
    estimator : estimator
    param_grid : dict of name -> list of values (or a list of such dicts)
    cv, scoring : as in :func:`cross_val_score`
    refit : bool
        Fit the best parameters on all the data as ``best_estimator_``.

    Attributes
    ----------
    results_ : list of dict
        ``params``, ``mean_score``, ``std_score``, ``scores`` per candidate.
    best_params_, best_score_, best_estimator_
    """

    def __init__(
        self,
        estimator: Any,
        param_grid: Mapping[str, Sequence[Any]] | Sequence[Mapping[str, Sequence[Any]]],
        *,
        cv: int | Any = 5,
        scoring: str | Callable | None = None,
        refit: bool = True,
        progress: bool = False,
    ) -> None:
        _check_estimator(estimator)
        self.estimator = estimator
        self.param_grid = param_grid
        self._candidates()  # refuses a malformed grid now, not after the first fits
        _cv(cv, estimator)
        self.cv = cv
        get_scorer(scoring)
        self.scoring = scoring
        self.refit = check_bool(refit, "refit")
        self.progress = check_bool(progress, "progress")

    def _candidates(self) -> list[dict[str, Any]]:
        pg = self.param_grid
        grids = [pg] if isinstance(pg, Mapping) else pg
        if not isinstance(grids, (list, tuple)) or not all(isinstance(g, Mapping) for g in grids):
            raise InputError(
                "param_grid must be a dict of name -> list of values (or a list of such "
                f"dicts); got {plain_repr(pg)[:80]}"
            )
        out: list[dict[str, Any]] = []
        for grid in grids:
            names = sorted(grid)
            lists = []
            for k in names:
                v = grid[k]
                if isinstance(v, (str, bytes)) or not isinstance(v, Iterable):
                    raise InputError(
                        f"param_grid[{k!r}] must be a list of values to try; got "
                        f"{plain_repr(v)[:60]}: write [{plain_repr(v)[:30]}]"
                    )
                lists.append(list(v))
            if math.prod(len(v) for v in lists) + len(out) > MAX_CANDIDATES:
                raise InputError(
                    f"param_grid has more than {MAX_CANDIDATES} combinations (each one a "
                    "full cross-validation): give fewer values"
                )
            for values in itertools.product(*lists):
                out.append(dict(zip(names, values, strict=True)))
        if not out:
            raise InputError("param_grid is empty; give at least one value per parameter")
        return out

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> GridSearch:
        """Cross-validate every candidate; the best (first on ties) wins."""
        results = []
        for params in progress_bar(
            self._candidates(), desc="grid search", unit="candidate", disable=not self.progress
        ):
            est = clone(self.estimator).set_params(**params)
            scores = cross_val_score(est, X, y, cv=self.cv, scoring=self.scoring)
            results.append(
                {
                    "params": params,
                    "mean_score": float(scores.mean()),
                    "std_score": float(scores.std()),
                    "scores": scores,
                }
            )
        best = max(range(len(results)), key=lambda i: (results[i]["mean_score"], -i))
        self.results_ = results
        self.best_params_ = results[best]["params"]
        self.best_score_ = results[best]["mean_score"]
        if self.refit:
            est = clone(self.estimator).set_params(**self.best_params_)
            self.best_estimator_ = est.fit(X) if y is None else est.fit(X, y)
        return self

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Predict with ``best_estimator_``."""
        if not hasattr(self, "best_estimator_"):
            from robopercept.errors import NotFittedError

            raise NotFittedError("GridSearch is not fitted (or refit=False); call fit first")
        return self.best_estimator_.predict(X)
