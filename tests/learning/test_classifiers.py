"""Decision trees, random forests and SVMs: hand cases, accuracy parity with
scikit-learn over 5 seeds, seeded determinism, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError, NotFittedError
from robopercept.learning.forest import RandomForestClassifier, RandomForestRegressor
from robopercept.learning.svm import SVC, LinearSVC
from robopercept.learning.tree import DecisionTreeClassifier, DecisionTreeRegressor


def _splits(X, y, n=5):
    from sklearn.model_selection import train_test_split

    for seed in range(n):
        yield seed, train_test_split(X, y, test_size=0.25, random_state=seed, stratify=y)


def _mean_accuracy_gap(X, y, ours, ref) -> tuple[float, float]:
    a, b = [], []
    for seed, (Xa, Xb, ya, yb) in _splits(X, y):
        a.append(ours(seed).fit(Xa, ya).score(Xb, yb))
        b.append(ref(seed).fit(Xa, ya).score(Xb, yb))
    return float(np.mean(a)), float(np.mean(b))


def test_tree_hand_case_information_gain():
    # x < 2.5 separates the classes; the y feature is noise
    X = np.array([[1.0, 5], [2, 1], [3, 5], [4, 1], [5, 3]])
    y = np.array([0, 0, 1, 1, 1])
    for criterion in ("entropy", "gini"):
        tree = DecisionTreeClassifier(criterion, random_state=0).fit(X, y)
        assert tree.tree_.feature[0] == 0 and tree.tree_.threshold[0] == 2.5
        assert tree.get_depth() == 1 and tree.get_n_leaves() == 2
        np.testing.assert_array_equal(tree.predict([[0.0, 0], [9, 9]]), [0, 1])
        np.testing.assert_allclose(tree.feature_importances_, [1, 0])
    # root impurity: entropy of (2/5, 3/5) in bits
    ent = DecisionTreeClassifier("entropy").fit(X, y).tree_.impurity[0]
    assert ent == pytest.approx(-(0.4 * np.log2(0.4) + 0.6 * np.log2(0.6)))


def test_tree_limits_and_proba(iris):
    X, y = iris
    stump = DecisionTreeClassifier(max_depth=1, random_state=0).fit(X, y)
    assert stump.get_depth() == 1
    proba = stump.predict_proba(X)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    leafy = DecisionTreeClassifier(min_samples_leaf=10, random_state=0).fit(X, y)
    assert np.bincount(leafy.apply(X)).max() >= 10
    assert np.bincount(leafy.apply(X))[np.bincount(leafy.apply(X)) > 0].min() >= 10
    full = DecisionTreeClassifier(random_state=0).fit(X, y)
    assert (
        full.score(X, y) >= 1 - 1 / 150
    )  # iris has one duplicated, differently labelled pair at most


def test_tree_same_seed_same_tree(digits):
    X, y = digits
    a = DecisionTreeClassifier(max_features="sqrt", random_state=4).fit(X, y)
    b = DecisionTreeClassifier(max_features="sqrt", random_state=4).fit(X, y)
    np.testing.assert_array_equal(a.tree_.threshold, b.tree_.threshold)


@pytest.mark.parametrize("criterion", ["gini", "entropy"])
def test_tree_accuracy_matches_sklearn(digits, criterion):
    """Mean test accuracy over 5 seeds within 1.5 points of sklearn's."""
    from sklearn.tree import DecisionTreeClassifier as SkTree

    X, y = digits
    ours, ref = _mean_accuracy_gap(
        X,
        y,
        lambda s: DecisionTreeClassifier(criterion, random_state=s),
        lambda s: SkTree(criterion=criterion, random_state=s),
    )
    assert abs(ours - ref) <= 0.015, (ours, ref)


def test_regression_tree_and_forest():
    from sklearn.ensemble import RandomForestRegressor as SkForest

    gen = np.random.default_rng(0)
    X = gen.uniform(-3, 3, size=(1500, 4))
    y = np.sin(X[:, 0]) * 3 + X[:, 1] ** 2 + gen.normal(scale=0.1, size=1500)
    Xa, Xb, ya, yb = X[:1100], X[1100:], y[:1100], y[1100:]
    step = DecisionTreeRegressor(max_depth=1).fit(
        np.arange(10.0)[:, None], np.r_[np.zeros(5), np.ones(5)]
    )
    assert step.tree_.threshold[0] == 4.5
    assert DecisionTreeRegressor(random_state=0).fit(Xa, ya).score(Xb, yb) > 0.95
    ours = RandomForestRegressor(60, max_features=1.0, oob_score=True, random_state=0).fit(Xa, ya)
    ref = SkForest(60, random_state=0).fit(Xa, ya)
    assert abs(ours.score(Xb, yb) - ref.score(Xb, yb)) < 0.01
    assert abs(ours.oob_score_ - ours.score(Xb, yb)) < 0.03


def test_forest_accuracy_matches_sklearn(digits):
    """RandomForest(100): mean test accuracy over 5 seeds within 1.5 points of sklearn's."""
    from sklearn.ensemble import RandomForestClassifier as SkForest

    X, y = digits
    ours, ref = _mean_accuracy_gap(
        X,
        y,
        lambda s: RandomForestClassifier(100, random_state=s, n_jobs=-1),
        lambda s: SkForest(100, random_state=s),
    )
    assert abs(ours - ref) <= 0.015, (ours, ref)


def test_forest_oob_and_threads_do_not_change_the_forest(digits):
    X, y = digits
    a = RandomForestClassifier(30, oob_score=True, n_jobs=1, random_state=9).fit(X, y)
    b = RandomForestClassifier(30, oob_score=True, n_jobs=2, random_state=9).fit(X, y)
    np.testing.assert_array_equal(a.predict_proba(X), b.predict_proba(X))
    assert a.oob_score_ == b.oob_score_
    assert 0.9 < a.oob_score_ < 1.0  # honest: below the training accuracy of 1
    soft = RandomForestClassifier(30, voting="soft", random_state=9).fit(X, y)
    assert (soft.predict(X) == a.predict(X)).mean() > 0.99
    with pytest.raises(InputError, match="bootstrap"):
        RandomForestClassifier(5, bootstrap=False, oob_score=True).fit(X, y)


def test_svc_hand_case_margin():
    """Two points per class on either side of x = 0: w = (1, 0), b = 0 for large C,
    support vectors the two innermost points."""
    X = np.array([[-1.0, 0], [-2, 1], [1, 0], [2, -1]])
    y = np.array([0, 0, 1, 1])
    svc = SVC(C=1e3, kernel="linear", tol=1e-6).fit(X, y)
    np.testing.assert_allclose(svc.coef_[0], [1, 0], atol=1e-6)
    np.testing.assert_allclose(svc.intercept_, [0], atol=1e-6)
    np.testing.assert_array_equal(np.sort(svc.support_), [0, 2])
    np.testing.assert_allclose(svc.decision_function(X[[0, 2]]), [-1, 1], atol=1e-6)


@pytest.mark.parametrize("kernel", ["rbf", "linear", "poly"])
def test_svc_matches_sklearn_on_iris(iris, kernel):
    """The same dual and stopping rule: the same support vectors, and decision values
    within what the stopping rule leaves open (both stop once the optimality violation is
    below tol=1e-3, at slightly different points: 1e-2 absolute plus 0.5% relative on f,
    whose values reach 10 here)."""
    from sklearn.svm import SVC as SkSVC

    X, y = iris
    ours = SVC(kernel=kernel).fit(X, y)
    ref = SkSVC(kernel=kernel).fit(X, y)
    np.testing.assert_array_equal(ours.support_, ref.support_)
    np.testing.assert_array_equal(ours.n_support_, ref.n_support_)
    np.testing.assert_array_equal(ours.predict(X), ref.predict(X))
    np.testing.assert_allclose(
        ours.decision_function(X), ref.decision_function(X), rtol=5e-3, atol=1e-2
    )
    binary = (y == 2).astype(int)
    np.testing.assert_allclose(
        SVC(kernel=kernel).fit(X, binary).decision_function(X),
        SkSVC(kernel=kernel).fit(X, binary).decision_function(X),
        rtol=5e-3,
        atol=1e-2,
    )


def test_svc_accuracy_matches_sklearn(digits):
    from sklearn.svm import SVC as SkSVC

    X, y = digits
    ours, ref = _mean_accuracy_gap(X, y, lambda s: SVC(), lambda s: SkSVC())
    assert abs(ours - ref) <= 0.015, (ours, ref)


def test_linear_svc(digits):
    from sklearn.svm import LinearSVC as SkLinear

    X, y = digits
    X = X / 16.0
    ours, ref = _mean_accuracy_gap(
        X, y, lambda s: LinearSVC(C=0.1, random_state=s), lambda s: SkLinear(C=0.1, random_state=s)
    )
    assert abs(ours - ref) <= 0.015, (ours, ref)
    binary = LinearSVC(C=1.0, loss="hinge", random_state=0).fit(X, y == 3)
    assert binary.decision_function(X).shape == (X.shape[0],)
    assert binary.score(X, y == 3) > 0.97


@pytest.mark.parametrize(
    "make",
    [DecisionTreeClassifier, RandomForestClassifier, SVC, LinearSVC],
    ids=lambda c: c.__name__,
)
def test_classifier_bad_input(iris, make):
    X, y = iris
    with pytest.raises(NotFittedError, match="fit"):
        make().predict(X)
    with pytest.raises(InputError, match="at least 2 classes"):
        make().fit(X, np.ones(len(y)))
    bad = X.copy()
    bad[0, 0] = np.inf
    with pytest.raises(InputError, match="NaN or inf"):
        make().fit(bad, y)
    est = make().fit(X, y)
    with pytest.raises(InputError, match="features"):
        est.predict(X[:, :3])


def test_sklearn_tools_accept_classifiers(iris):
    from sklearn.base import clone
    from sklearn.model_selection import cross_val_score
    from sklearn.pipeline import make_pipeline

    from robopercept.learning import PCA

    X, y = iris
    for est in (
        DecisionTreeClassifier(random_state=0),
        RandomForestClassifier(20, random_state=0),
        SVC(),
        LinearSVC(),
    ):
        assert clone(est).get_params() == est.get_params()
        assert cross_val_score(make_pipeline(PCA(3), est), X, y, cv=3).mean() > 0.85


def test_grow_tree_is_what_the_estimator_grows():
    from robopercept.learning.tree import Tree, grow_tree, tree_settings

    X = np.array([[0.0], [1.0], [2.0], [3.0], [4.0], [5.0]])
    y = np.array([0, 0, 0, 1, 1, 1])
    settings = tree_settings("gini", ("gini", "entropy"), None, 2, 1, None, 1)
    assert (settings.criterion, settings.max_features) == (0, 1)
    tree = grow_tree(np.ascontiguousarray(X.T), y, np.zeros(1), np.arange(6), 2, settings, 0)
    assert isinstance(tree, Tree)
    # one split at 2.5 separates the classes: a root and two pure leaves
    assert tree.node_count == 3 and tree.depth() == 1 and tree.threshold[0] == 2.5
    np.testing.assert_array_equal(tree.apply(X), [1, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(tree.importances(1), [1.0])
    fitted = DecisionTreeClassifier("gini").fit(X, y).tree_
    np.testing.assert_array_equal(fitted.threshold, tree.threshold)
    with pytest.raises(InputError, match="criterion"):
        tree_settings("squared_error", ("gini", "entropy"), None, 2, 1, None, 1)
    with pytest.raises(InputError, match="max_depth"):
        tree_settings("gini", ("gini",), 0, 2, 1, None, 1)


# issue 25: features near 1e300 (or 1e-300) overflowed (underflowed) gamma='scale' and
# the kernels: one class predicted for everything, silently. Refused with a typed error
@pytest.mark.parametrize("scale", [1e300, 1e-300])
@pytest.mark.parametrize("make", [lambda: SVC(), lambda: SVC(kernel="linear"), LinearSVC])
def test_svm_refuses_features_whose_squares_overflow(make, scale):
    rng = np.random.default_rng(0)
    X = rng.normal(size=(40, 3))
    y = (X[:, 0] > 0).astype(int)
    with pytest.raises(InputError, match="rescale your data"):
        make().fit(X * scale, y)
    model = make().fit(X, y)
    assert (model.predict(X) == y).mean() > 0.9
    with pytest.raises(InputError, match="X has values up to"):
        model.predict(X * 1e300)


# issue 25: hyperparameters of the wrong type reached float()/int() or a truth test
# (TypeError, ValueError, OverflowError at 2**63), a forest of 2**40 trees was allocated,
# and score() compared predictions with a y of another length by broadcasting
_G = np.random.default_rng(25)
_X = np.concatenate([_G.normal(c, 0.5, (20, 4)) for c in (0.0, 3.0, 6.0)])
_Y = np.repeat(np.arange(3), 20)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: SVC(coef0=None), "coef0 must be a real number"),
        (lambda: SVC(kernel=np.eye(3)), "kernel must be one of"),
        (lambda: SVC(gamma=np.eye(3)), "gamma"),
        (lambda: SVC(C="1"), "C must be a real number"),
        (lambda: SVC(max_iter=2**63), "max_iter must be in 1..2\\*\\*62"),
        (lambda: SVC(kernel="poly", degree=200, gamma=10.0), "kernel of X overflows"),
        (lambda: LinearSVC(intercept_scaling=[1, 2]), "intercept_scaling must be a real"),
        (lambda: LinearSVC(fit_intercept=np.eye(3)), "fit_intercept must be True or False"),
        (lambda: LinearSVC(random_state=-1), "random_state must be an int seed >= 0"),
        (lambda: DecisionTreeClassifier(criterion=np.eye(3)), "criterion must be one of"),
        (lambda: DecisionTreeClassifier(max_features=np.nan), "max_features as a fraction"),
        (lambda: RandomForestClassifier(n_estimators=2**40), "n_estimators must be in"),
        (lambda: RandomForestClassifier(n_estimators=3, bootstrap=np.eye(3)), "bootstrap"),
        (lambda: RandomForestClassifier(n_estimators=3, voting=np.eye(3)), "voting"),
        (lambda: RandomForestClassifier(n_estimators=3, progress="yes"), "progress"),
    ],
)
def test_hostile_hyperparameters_are_refused_at_fit(make, match):
    with pytest.raises(InputError, match=match):
        make().fit(_X, _Y)


def test_huge_limits_mean_no_limit_and_score_checks_y():
    # issue 25: max_depth and the sample limits beyond int64 are "no limit", not an
    # OverflowError; score() refuses a y that is not one label per row of X
    big = DecisionTreeClassifier(max_depth=2**63, random_state=0).fit(_X, _Y)
    ref = DecisionTreeClassifier(random_state=0).fit(_X, _Y)
    np.testing.assert_array_equal(big.predict(_X), ref.predict(_X))
    one_leaf = DecisionTreeRegressor(min_samples_split=2**63).fit(_X, _X[:, 0])
    np.testing.assert_allclose(one_leaf.predict(_X[:3]), _X[:, 0].mean())
    with pytest.raises(InputError, match="y must be a 1-D array of 60"):
        ref.score(_X, _Y[:59])
    with pytest.raises(InputError, match="y must be a 1-D array of 3"):
        ref.score(_X[:3], _Y)
    with pytest.raises(InputError, match="y must be a 1-D array of 60"):
        one_leaf.score(_X, np.zeros(0))
    with pytest.raises(InputError, match="y has values up to"):
        one_leaf.score(_X[:2], [1e300, 0.0])
    assert ref.score(_X, _Y) == 1.0
