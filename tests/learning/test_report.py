"""learning.report: tables in, a classifier's evaluation out, against scikit-learn."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.learning import (
    LDA,
    SVC,
    RandomForestClassifier,
    class_scores,
    confusion_table,
    evaluate_classifier,
    label_codes,
    read_table,
    standardize,
    train_test_split,
)


def test_read_table_by_hand(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("a, b ,kind\n1,2.5,x\n\n-3,,y\n")
    X, y, names = read_table(p, "kind")
    assert names == ["a", "b"] and y.tolist() == ["x", "y"]
    np.testing.assert_array_equal(X[:, 0], [1.0, -3.0])
    assert X[0, 1] == 2.5 and np.isnan(X[1, 1])  # empty cell: NaN, refused by estimators
    (tmp_path / "n.csv").write_text("a,b\n1,2\n")
    X2, y2, names2 = read_table(tmp_path / "n.csv")
    assert y2 is None and names2 == ["a", "b"] and X2.tolist() == [[1.0, 2.0]]


def test_read_table_errors(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("a,kind\n1,x\n")
    with pytest.raises(InputError, match="'kind' is not numeric"):
        read_table(p)
    with pytest.raises(InputError, match="no column 'label'"):
        read_table(p, "label")
    (tmp_path / "one.csv").write_text("kind\nx\n")
    with pytest.raises(InputError, match="no feature columns"):
        read_table(tmp_path / "one.csv", "kind")
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n3\n")
    with pytest.raises(FileFormatError, match="line 3 has 1 fields"):
        read_table(tmp_path / "bad.csv")
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x81" * 10)
    with pytest.raises(FileFormatError, match="not a text CSV"):
        read_table(tmp_path / "bin.csv")


def test_standardize_equals_sklearn_standard_scaler(rng):
    from sklearn.preprocessing import StandardScaler

    train = rng.normal(3.0, 2.0, (50, 4))
    train[:, 2] = 7.0  # a constant column keeps scale 1, as StandardScaler
    test = rng.normal(3.0, 2.0, (10, 4))
    a, b = standardize(train, test)
    ref = StandardScaler().fit(train)
    np.testing.assert_allclose(a, ref.transform(train), atol=1e-12)
    np.testing.assert_allclose(b, ref.transform(test), atol=1e-12)
    (only,) = standardize(train)
    np.testing.assert_allclose(only.mean(axis=0), 0.0, atol=1e-12)


def test_label_codes_numeric_then_text_order():
    codes, names = label_codes(np.array(["10", "2", "10", "1.5"]))
    assert names.tolist() == ["1.5", "2", "10"] and codes.tolist() == [2, 1, 2, 0]
    codes, names = label_codes(np.array(["b", "a", "b"]))
    assert names.tolist() == ["a", "b"] and codes.tolist() == [1, 0, 1]
    np.testing.assert_array_equal(names[codes], ["b", "a", "b"])


def test_class_scores_probabilities_or_decision_values(iris):
    X, y = iris
    forest = RandomForestClassifier(n_estimators=10, random_state=0).fit(X, y)
    np.testing.assert_array_equal(class_scores(forest, X, 3), forest.predict_proba(X))
    binary = y < 2
    svm = SVC(kernel="linear").fit(X[binary], y[binary])
    f = svm.decision_function(X[binary])
    np.testing.assert_array_equal(class_scores(svm, X[binary], 2), np.c_[-f, f])


def test_evaluate_classifier_equals_sklearn_metrics(iris):
    from sklearn import metrics

    X, y = iris
    names = np.array(["setosa", "versicolor", "virginica"])
    Xtr, Xt, ytr, yt = train_test_split(X, y, test_size=0.3, stratify=y, random_state=0)
    model = SVC().fit(Xtr, ytr)
    ev = evaluate_classifier(model, Xt, yt, names)
    pred = model.predict(Xt)
    np.testing.assert_array_equal(ev.predictions, pred)
    rep = ev.report
    assert rep.labels.tolist() == names.tolist()
    assert rep.accuracy == pytest.approx(metrics.accuracy_score(yt, pred))
    p, r, f, s = metrics.precision_recall_fscore_support(yt, pred, zero_division=0)
    np.testing.assert_allclose(rep.precision, p)
    np.testing.assert_allclose(rep.recall, r)
    np.testing.assert_allclose(rep.f1, f)
    np.testing.assert_array_equal(rep.support, s)
    np.testing.assert_array_equal(rep.confusion, metrics.confusion_matrix(yt, pred))
    scores = model.decision_function(Xt)
    assert list(ev.curves) == names.tolist()
    for k, name in enumerate(names):
        c = ev.curves[name]
        truth = (yt == k).astype(int)
        assert c.roc_auc == pytest.approx(metrics.roc_auc_score(truth, scores[:, k]))
        assert c.average_precision == pytest.approx(
            metrics.average_precision_score(truth, scores[:, k])
        )
    d = ev.to_dict()
    assert d["classes"] == names.tolist() and d["accuracy"] == rep.accuracy
    assert set(d["curves"]["virginica"]) == {"roc_auc", "average_precision"}


def test_two_classes_give_one_curve_and_absent_classes_none():
    X = np.array([[0.0], [0.2], [1.0], [1.2], [0.1], [1.1], [2.0], [2.1]])
    codes = np.array([0, 0, 1, 1, 0, 1, 2, 2])
    names = np.array(["a", "b", "c"])
    two = codes < 2
    ev = evaluate_classifier(LDA().fit(X[two], codes[two]), X[two], codes[two], names)
    assert list(ev.curves) == ["b"] and ev.curves["b"].roc_auc == 1.0
    model = LDA().fit(X, codes)
    ev = evaluate_classifier(model, X[:6], codes[:6], names)  # "c" absent from the test rows
    assert "c" not in ev.curves and set(ev.curves) == {"a", "b"}


def test_confusion_table_by_hand():
    text = confusion_table(np.array([[3, 1], [0, 12]]), ["cat", "elephant"])
    assert text.splitlines() == [
        "         " + "     cat elephant",
        "     cat        3        1",
        "elephant        0       12",
    ]


# issue 25: the report helpers trusted their arguments: None as the model raised
# AttributeError, float codes an IndexError, a float confusion matrix a format error,
# a 2-D y "unhashable type", and standardize broadcast tables of other widths
_G = np.random.default_rng(25)
_X = np.concatenate([_G.normal(c, 0.5, (20, 4)) for c in (0.0, 3.0, 6.0)])
_C = np.repeat(np.arange(3), 20)
_NAMES = np.array(["a", "b", "c"])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda m: class_scores(None, _X, 3), "model must be a fitted classifier"),
        (lambda m: class_scores(m, _X, np.nan), "n_classes must be an integer"),
        (lambda m: class_scores(m, _X, 4), "n_classes must be the model's number"),
        (lambda m: evaluate_classifier(None, _X, _C, _NAMES), "model must be a fitted"),
        (lambda m: evaluate_classifier(m, _X, _C + 0.5, _NAMES), "codes must be whole"),
        (lambda m: evaluate_classifier(m, _X, _C[:59], _NAMES), "one code per row of X"),
        (lambda m: evaluate_classifier(m, _X, _C, _NAMES[:2]), "must be whole numbers in 0..1"),
        (lambda m: label_codes(np.eye(3)), "y must be a 1-D array of labels"),
        (lambda m: label_codes(np.float64(1.0)), "y must be a 1-D array of labels"),
        (lambda m: label_codes([1.0, np.nan]), "NaN or inf labels"),
        (lambda m: confusion_table(np.array([[5, 1], [2, 7]]), []), "confusion must be a square"),
        (lambda m: confusion_table(np.array([[5, 1], [2, 7]]), ["a"]), "one row per name"),
        (lambda m: confusion_table(np.array([[5, 1], [2, 7]]), [None, "b"]), "names must be"),
        (lambda m: confusion_table(np.array([[0.5, 1], [2, 7]]), ["a", "b"]), "counts"),
        (lambda m: standardize(_X, _X[:, :2]), "others\\[0\\] has 2 columns, train 4"),
        (lambda m: standardize([]), "train must be 2-D"),
        (lambda m: standardize(_X * 1e300), "train has values up to"),
        (lambda m: read_table("t.csv", label=3), "label \\(the --label column\\) must be"),
    ],
)
def test_hostile_arguments_are_refused_by_name(call, match, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "t.csv").write_text("a,b\n1,2\n")
    model = SVC().fit(_X, _C)
    with pytest.raises(InputError, match=match):
        call(model)


def test_float_counts_print_as_whole_numbers():
    # issue 25: a confusion matrix of whole floats (a sum of matrices) is printed
    table = confusion_table(np.array([[3.0, 1.0], [0.0, 4.0]]), ["cat", "dog"])
    assert table == confusion_table(np.array([[3, 1], [0, 4]]), ["cat", "dog"])
