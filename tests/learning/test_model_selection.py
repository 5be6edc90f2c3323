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


# issue 25: estimators, X/y lengths, grids and flags were not checked: None.fit raised
# AttributeError, a y shorter than X an IndexError in the folds, a scalar grid value
# TypeError, and scoring=[...] an unhashable-type error
_G = np.random.default_rng(25)
_X = np.concatenate([_G.normal(c, 0.5, (20, 4)) for c in (0.0, 3.0, 6.0)])
_Y = np.repeat(np.arange(3), 20)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: cross_val_score(None, _X, _Y), "estimator must be an estimator instance"),
        (lambda: cross_val_score(np.eye(3), _X, _Y), "estimator must be an estimator"),
        (lambda: cross_val_score(LDA, _X, _Y), "estimator must be an estimator instance"),
        (lambda: cross_val_score(LDA(), _X[:3], _Y), "one value per sample of X \\(3\\)"),
        (lambda: cross_val_score(LDA(), _X, np.zeros((2, 60))), "y must be 1-D"),
        (lambda: cross_val_score(LDA(), _X, _Y, scoring=["accuracy"]), "scoring must be"),
        (lambda: cross_val_score(LDA(), _X, _Y, cv=True), "cv must be an int or a splitter"),
        (lambda: cross_val_score(LDA(), _X, _Y, cv="3"), "cv must be an int or a splitter"),
        (lambda: cross_val_score(LDA(), _X, _Y, progress="yes"), "progress must be True"),
        (lambda: GridSearch(LDA(), {"shrinkage": 0.1}), "must be a list of values to try"),
        (lambda: GridSearch(LDA(), 3), "param_grid must be a dict"),
        (lambda: GridSearch(LDA(), {"a": range(1000), "b": range(1000)}), "more than 100000"),
        (lambda: GridSearch(LDA(), {"shrinkage": [0.1]}, refit=None), "refit must be True"),
        (lambda: GridSearch(LDA(), {"shrinkage": [0.1]}).fit(_X, _Y[:59]), "one value per"),
        (lambda: KFold(n_splits=np.nan), "n_splits must be an integer"),
        (lambda: KFold(shuffle="yes"), "shuffle must be True or False"),
        (lambda: KFold(random_state="seed"), "random_state must be an int seed"),
        (lambda: list(KFold(2).split(3)), "X must be an array of samples"),
        (lambda: list(StratifiedKFold(2).split(_X[:10], _Y)), "X has 10 samples but y has 60"),
        (lambda: train_test_split(_X, 3), "arrays\\[1\\] must be an array of samples"),
        (lambda: train_test_split(_X, shuffle=None), "shuffle must be True or False"),
        (lambda: train_test_split(_X, _Y, stratify=np.eye(3)), "stratify must be a 1-D"),
    ],
)
def test_hostile_arguments_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_grid_search_of_one_candidate_and_a_column_y_still_work():
    gs = GridSearch(LDA(), {"shrinkage": [0.1]}, cv=3).fit(_X, _Y)
    assert gs.best_params_ == {"shrinkage": 0.1} and gs.best_score_ == 1.0
    np.testing.assert_array_equal(
        cross_val_score(LDA(), _X, _Y[:, None], cv=3), cross_val_score(LDA(), _X, _Y, cv=3)
    )
