"""Splits, cross-validation, grid search and the scikit-learn estimator contract."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.learning import (
    LDA,
    PCA,
    GridSearch,
    KFold,
    StratifiedKFold,
    clone,
    cross_val_score,
    train_test_split,
)
from robopercept.learning.kmeans import KMeans


def test_train_test_split_sizes_stratified_and_seeded(iris):
    X, y = iris
    X_tr, X_te, _, y_te = train_test_split(X, y, test_size=0.2, stratify=y, random_state=0)
    assert len(X_te) == 30 and len(X_tr) == 120
    np.testing.assert_array_equal(np.bincount(y_te), [10, 10, 10])
    again = train_test_split(X, y, test_size=0.2, stratify=y, random_state=0)
    np.testing.assert_array_equal(again[3], y_te)
    parts = train_test_split(X, y, test_size=0.2, val_size=0.2, stratify=y, random_state=1)
    X_tr, X_va, X_te, _, y_va, _ = parts
    assert (len(X_tr), len(X_va), len(X_te)) == (90, 30, 30)
    np.testing.assert_array_equal(np.bincount(y_va), [10, 10, 10])
    rows = {tuple(r) for r in np.r_[X_tr, X_va, X_te]}
    assert len(rows) == len({tuple(r) for r in X})  # a partition (iris has duplicates)
    a, b = train_test_split(list(range(10)), test_size=3, shuffle=False)
    assert a == list(range(7)) and b == [7, 8, 9]


def test_split_bad_input():
    with pytest.raises(InputError, match="same number"):
        train_test_split(np.zeros(5), np.zeros(4))
    with pytest.raises(InputError, match=r"\(0, 1\)"):
        train_test_split(np.zeros(5), test_size=1.5)
    with pytest.raises(InputError, match="at least one"):
        train_test_split(np.zeros(2), test_size=0.5, val_size=0.5)


def test_kfold_partitions():
    folds = list(KFold(3).split(np.zeros(10)))
    assert [len(t) for _, t in folds] == [4, 3, 3]
    np.testing.assert_array_equal(np.sort(np.concatenate([t for _, t in folds])), np.arange(10))
    for train, test in folds:
        assert not set(train) & set(test)
    with pytest.raises(InputError, match="n_splits"):
        list(KFold(11).split(np.zeros(10)))


def test_stratified_kfold_keeps_class_shares(digits):
    _, y = digits
    for _, test in StratifiedKFold(5, shuffle=True, random_state=0).split(y, y):
        counts = np.bincount(y[test], minlength=10)
        full = np.bincount(y) / 5
        assert np.all(np.abs(counts - full) <= 1)
    with pytest.raises(InputError, match="labels"):
        list(StratifiedKFold(3).split(np.zeros(9)))


def test_cross_val_score_and_grid_search(iris):
    X, y = iris
    scores = cross_val_score(LDA(), X, y, cv=5)
    assert scores.shape == (5,) and scores.mean() > 0.95
    gs = GridSearch(PCA(), {"n_components": [1, 2, 3]}, cv=3, scoring=_explained)
    gs.fit(X)
    assert gs.best_params_ == {"n_components": 3}
    assert len(gs.results_) == 3 and hasattr(gs, "best_estimator_")
    with pytest.raises(InputError, match="unknown scoring"):
        cross_val_score(LDA(), X, y, scoring="magic")


def _explained(est, X, y):
    return float(est.explained_variance_ratio_.sum())


def test_params_and_own_clone():
    km = KMeans(4, tol=1e-3, random_state=5)
    assert km.get_params()["n_clusters"] == 4
    km.set_params(n_clusters=6)
    c = clone(km)
    assert c is not km and c.get_params() == km.get_params()
    assert "n_clusters=6" in repr(km)
    with pytest.raises(InputError, match="no parameter"):
        km.set_params(k=3)


def test_sklearn_clone_pipeline_cross_val_score(iris):
    """Our estimators work inside scikit-learn's clone, Pipeline, cross_val_score and
    GridSearchCV."""
    from sklearn.base import clone as sk_clone
    from sklearn.base import is_classifier
    from sklearn.model_selection import GridSearchCV
    from sklearn.model_selection import cross_val_score as sk_cross_val_score
    from sklearn.pipeline import make_pipeline

    X, y = iris
    for est in (PCA(2), LDA(), KMeans(3, random_state=0)):
        twin = sk_clone(est)
        assert twin.get_params() == est.get_params()
    assert is_classifier(LDA())
    pipe = make_pipeline(PCA(3), LDA())
    scores = sk_cross_val_score(pipe, X, y, cv=5)
    assert scores.mean() > 0.9
    ours = cross_val_score(pipe, X, y, cv=5)
    assert ours.mean() > 0.9
    gs = GridSearchCV(pipe, {"pca__n_components": [2, 3]}, cv=3).fit(X, y)
    assert gs.best_params_["pca__n_components"] in (2, 3)
