"""Metrics: hand cases and equality with sklearn.metrics (to 1e-12) with tied scores."""

from __future__ import annotations

import numpy as np
import pytest
import sklearn.metrics as skm

from robopercept.errors import InputError
from robopercept.learning import metrics as m


def test_hand_computed_binary():
    y = [1, 1, 1, 0, 0, 0, 0, 1]
    p = [1, 0, 1, 0, 1, 0, 0, 1]  # TP 3, FN 1, FP 1, TN 3
    np.testing.assert_array_equal(m.confusion_matrix(y, p), [[3, 1], [1, 3]])
    assert m.precision_score(y, p) == 0.75
    assert m.recall_score(y, p) == 0.75
    assert m.f1_score(y, p) == 0.75
    assert m.accuracy_score(y, p) == 0.75


def test_hand_computed_curves():
    # scores 0.9(+) 0.8(-) 0.7(+) 0.6(-): one swapped pair of four -> AUC 3/4
    y = [1, 0, 1, 0]
    s = [0.9, 0.8, 0.7, 0.6]
    assert m.roc_auc_score(y, s) == 0.75
    # AP = 1/2 * 1 + 1/2 * 2/3
    assert m.average_precision_score(y, s) == pytest.approx(0.5 + 1 / 3, abs=1e-15)


@pytest.mark.parametrize("seed", range(5))
def test_ranking_metrics_equal_sklearn_with_ties(seed):
    gen = np.random.default_rng(seed)
    y = gen.integers(0, 2, 700)
    s = np.round(gen.normal(size=700) + y, 1)  # rounding makes many ties
    assert abs(m.roc_auc_score(y, s) - skm.roc_auc_score(y, s)) <= 1e-12
    assert abs(m.average_precision_score(y, s) - skm.average_precision_score(y, s)) <= 1e-12
    for ours, ref in zip(
        m.precision_recall_curve(y, s), skm.precision_recall_curve(y, s), strict=True
    ):
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)
    for ours, ref in zip(m.roc_curve(y, s), skm.roc_curve(y, s), strict=True):
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize("average", ["macro", "micro", "weighted", None])
def test_multiclass_scores_equal_sklearn(average):
    gen = np.random.default_rng(3)
    y, p = gen.integers(0, 4, 300), gen.integers(0, 4, 300)
    p[p == 3] = 2  # class 3 never predicted: precision 0 by convention
    for ours, ref in (
        (m.precision_score, skm.precision_score),
        (m.recall_score, skm.recall_score),
        (m.f1_score, skm.f1_score),
    ):
        kw = {"zero_division": 0} if ref is skm.precision_score else {}
        np.testing.assert_allclose(
            ours(y, p, average=average), ref(y, p, average=average, **kw), atol=1e-15
        )
    np.testing.assert_array_equal(m.confusion_matrix(y, p), skm.confusion_matrix(y, p))


def test_report_and_string_labels():
    y = np.array(["cat", "dog", "dog", "cat", "bird"])
    p = np.array(["cat", "dog", "cat", "cat", "dog"])
    rep = m.classification_report(y, p)
    assert rep.labels.tolist() == ["bird", "cat", "dog"]
    np.testing.assert_array_equal(rep.support, [1, 2, 2])
    assert "weighted avg" in rep.table()
    np.testing.assert_allclose(
        rep.precision, skm.precision_score(y, p, average=None, zero_division=0)
    )


def test_bad_input():
    with pytest.raises(InputError, match="same length"):
        m.accuracy_score([1, 0], [1])
    with pytest.raises(InputError, match="two classes"):
        m.f1_score([0, 1, 2], [0, 1, 2])
    with pytest.raises(InputError, match="positive and negative"):
        m.roc_auc_score([1, 1, 1], [0.1, 0.2, 0.3])
    with pytest.raises(InputError, match="pos_label"):
        m.roc_curve(["a", "b"], [0.1, 0.2])
    with pytest.raises(InputError, match="NaN"):
        m.roc_curve([0, 1], [0.1, np.nan])


def test_adjusted_rand_score_equals_sklearn():
    """ARI is sklearn's to 1e-12 on random labelings, renamings and the edge cases."""
    from sklearn.metrics import adjusted_rand_score as ref

    from robopercept.learning.metrics import adjusted_rand_score

    gen = np.random.default_rng(3)
    for n, ka, kb in ((50, 3, 4), (500, 10, 7), (7, 2, 2)):
        a, b = gen.integers(0, ka, n), gen.integers(-1, kb, n)
        assert adjusted_rand_score(a, b) == pytest.approx(ref(a, b), abs=1e-12)
    a = gen.integers(0, 4, 100)
    assert adjusted_rand_score(a, (a + 1) * 7) == 1.0  # a renaming
    assert adjusted_rand_score([0, 0, 0], [1, 1, 1]) == ref([0, 0, 0], [1, 1, 1])
    assert adjusted_rand_score([0, 1, 2], [5, 6, 7]) == ref([0, 1, 2], [5, 6, 7])
    # class names against cluster numbers: a partition comparison, as in scikit-learn
    names, clusters = ["a", "a", "b", "b", "c"], [2, 2, 0, 1, 1]
    assert adjusted_rand_score(names, clusters) == pytest.approx(ref(names, clusters), abs=1e-12)
    with pytest.raises(InputError):
        adjusted_rand_score([0, 1], [0])


# issue 25: labels, pos_label and scores of the wrong shape or type raised NumPy's
# errors ("object too deep", broadcasting, unhashable), and adjusted_rand_score built a
# dense n x n table for n distinct labels
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: m.confusion_matrix([0, 1, 2], [0, 1, 1], labels=np.eye(3)), "labels must be"),
        (lambda: m.confusion_matrix([0, 1, 2], [0, 1, 1], labels=np.float64(1.0)), "1-D"),
        (lambda: m.confusion_matrix([0, 1, 2], [0, 1, 1], labels=[]), "at least one class"),
        (lambda: m.confusion_matrix([0, 1, 2], [0, 1, 1], labels=["a", "b"]), "mix labels"),
        (lambda: m.confusion_matrix(["a", "b"], [0, 1]), "mix labels"),
        (lambda: m.accuracy_score([0, np.nan], [0, 1]), "NaN or inf labels"),
        (lambda: m.accuracy_score([[0, 1]], [0, 1]), "y_true must be a 1-D array"),
        (lambda: m.precision_score([0, 1], [0, 1], pos_label=[1, 2]), "pos_label must be one"),
        (lambda: m.roc_curve([0, 1], [0.1, 0.9], pos_label=None, drop_intermediate=2), "drop"),
        (lambda: m.precision_recall_curve([0, 1], [0.1, 0.9], pos_label=[1, 2]), "pos_label"),
        (lambda: m.roc_curve([0, 1], ["a", "b"]), "y_score must hold real numbers"),
        (lambda: m.auc(["a", "b"], [0, 1]), "x must hold real numbers"),
        (lambda: m.auc([0, np.nan], [0, 1]), "auc needs finite x and y"),
    ],
)
def test_hostile_arguments_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_adjusted_rand_score_of_all_distinct_labels_needs_no_dense_table():
    import tracemalloc

    n = 5000  # a dense n x n table of int64 would take 200 MB
    a = np.arange(n)
    b = a.copy()
    b[:2] = 0  # two samples merged
    tracemalloc.start()
    try:
        same, merged = m.adjusted_rand_score(a, a), m.adjusted_rand_score(a, b)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20e6, f"{peak / 1e6:.0f} MB"
    # scikit-learn counts with a sparse table: the same values to rounding
    assert same == 1.0
    assert merged == pytest.approx(skm.adjusted_rand_score(a, b), abs=1e-12)
