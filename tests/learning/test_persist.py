"""Model files (robopercept.learning.persist): every classifier `learn classify` trains
round-trips bit for bit; damaged, foreign and pickle files are refused, never run."""

from __future__ import annotations

import io
import json
import pickle
import zipfile

import numpy as np
import pytest
from sklearn.datasets import load_wine

from robopercept.errors import FileFormatError, InputError, NotFittedError
from robopercept.learning import (
    LDA,
    SVC,
    DecisionTreeClassifier,
    DecisionTreeRegressor,
    LinearSVC,
    RandomForestClassifier,
    RandomForestRegressor,
    SavedModel,
    load_model,
    predict_table,
    read_features,
    read_npz,
    save_model,
    standard_scaling,
    standardize,
)
from robopercept.learning.persist import FORMAT_VERSION, MODEL_KINDS


@pytest.fixture(scope="module")
def wine():
    X, y = load_wine(return_X_y=True)
    return X, y


# (estimator, dataset): iris for the slow-to-compile SVC kernels, wine (13 features,
# 3 classes) and digits (64 features, 10 classes) for the rest
CASES = {
    "tree-digits": (lambda: DecisionTreeClassifier(random_state=0), "digits"),
    "forest-wine": (lambda: RandomForestClassifier(25, random_state=0, oob_score=True), "wine"),
    "forest-soft": (lambda: RandomForestClassifier(5, voting="soft", random_state=1), "iris"),
    "svm-rbf": (lambda: SVC(C=3.0), "iris"),
    "svm-linear": (lambda: SVC(kernel="linear"), "iris"),
    "svm-poly-ovo": (lambda: SVC(kernel="poly", decision_function_shape="ovo"), "iris"),
    "svm-probability": (lambda: SVC(probability=True, random_state=0), "iris"),
    "linear-svc": (lambda: LinearSVC(random_state=0, max_iter=200), "iris"),
    "lda-digits": (lambda: LDA(n_components=3, shrinkage=1e-3), "digits"),
    "tree-regressor": (lambda: DecisionTreeRegressor(max_depth=6, random_state=0), "wine"),
    "forest-regressor": (lambda: RandomForestRegressor(8, random_state=0), "wine"),
}


def _data(name, iris, digits, wine):
    X, y = {"iris": iris, "digits": digits, "wine": wine}[name]
    if name == "digits":  # 600 rows keep the tree and LDA fits quick
        X, y = X[:600], y[:600]
    return X, y


@pytest.mark.parametrize("case", list(CASES))
def test_round_trip_is_bit_identical(case, tmp_path, iris, digits, wine):
    make, data = CASES[case]
    X, y = _data(data, iris, digits, wine)
    model = make()
    if "regressor" in case:
        y = X[:, 0]
        X = X[:, 1:]
    model.fit(X, y)
    path = save_model(model, tmp_path / "m.npz")
    loaded = load_model(path).model
    assert type(loaded) is type(model) and loaded.get_params() == model.get_params()
    # exactly the same numbers, not merely close: the file holds the float64 bytes
    np.testing.assert_array_equal(loaded.predict(X), model.predict(X))
    for method in ("predict_proba", "decision_function", "transform"):
        if hasattr(model, method):
            np.testing.assert_array_equal(getattr(loaded, method)(X), getattr(model, method)(X))
    if hasattr(model, "classes_"):
        np.testing.assert_array_equal(loaded.classes_, model.classes_)
    if hasattr(model, "feature_importances_"):
        np.testing.assert_array_equal(loaded.feature_importances_, model.feature_importances_)
    if hasattr(model, "oob_score_"):
        assert loaded.oob_score_ == model.oob_score_
    if isinstance(model, SVC):
        np.testing.assert_array_equal(loaded.support_, model.support_)
        if model.kernel == "linear":
            np.testing.assert_array_equal(loaded.coef_, model.coef_)
    # a standard archive: NumPy reads it without pickle, the header is plain JSON
    with np.load(path, allow_pickle=False) as f:
        header = json.loads(str(f["meta"]))
    assert header["kind"] == type(model).__name__ in MODEL_KINDS
    assert header["format_version"] == FORMAT_VERSION


def test_saved_model_keeps_names_and_scaling(tmp_path, wine):
    X, y = wine
    mean, scale = standard_scaling(X[::2])
    np.testing.assert_array_equal((X[1::2] - mean) / scale, standardize(X[::2], X[1::2])[1])
    names = [f"f{i}" for i in range(X.shape[1])]
    classes = np.array(["barolo", "grignolino", "barbera"])
    model = SVC().fit((X[::2] - mean) / scale, y[::2])
    saved = SavedModel(model, names, list(classes), "cultivar", mean, scale, {"note": "wine"})
    loaded = load_model(save_model(saved, tmp_path / "wine.npz"))
    assert loaded.feature_names == tuple(names) and loaded.class_names == tuple(classes)
    assert loaded.label_column == "cultivar" and loaded.info == {"note": "wine"}
    assert loaded.header["robopercept_version"]
    np.testing.assert_array_equal(loaded.predict(X), classes[model.predict((X - mean) / scale)])
    assert np.mean(loaded.predict(X[1::2]) == classes[y[1::2]]) > 0.9


def test_save_refuses_what_it_cannot_store(tmp_path, iris):
    X, y = iris
    with pytest.raises(NotFittedError, match="not fitted"):
        save_model(SVC(), tmp_path / "m.npz")
    with pytest.raises(InputError, match=r"extension \.npz"):
        save_model(LDA().fit(X, y), tmp_path / "m.pkl")
    with pytest.raises(InputError, match="must be one of"):
        save_model(object(), tmp_path / "m.npz")
    with pytest.raises(InputError, match="class_names has 2 entries; the model has 3"):
        SavedModel(LDA().fit(X, y), class_names=["a", "b"])
    with pytest.raises(InputError, match="both mean and scale"):
        SavedModel(LDA().fit(X, y), mean=np.zeros(4))
    tree = DecisionTreeClassifier().fit(X, np.where(y == 0, "a", "b").astype(object))
    assert tree.classes_.dtype == object  # labels as Python objects: only pickle holds them
    with pytest.raises(InputError, match="without pickle"):
        save_model(tree, tmp_path / "m.npz")


@pytest.fixture
def forest_file(tmp_path, iris):
    X, y = iris
    return save_model(RandomForestClassifier(3, random_state=0).fit(X, y), tmp_path / "f.npz")


def _rewrite(path, out, **changes):
    """Copy the archive ``path`` to ``out`` with arrays replaced (None: removed)."""
    with np.load(path, allow_pickle=False) as f:
        arrays = {k: f[k] for k in f.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez(out, **arrays)
    return out


def test_truncated_files_are_refused_with_the_file_named(forest_file, tmp_path):
    data = forest_file.read_bytes()
    for cut in (0, 10, len(data) // 3, len(data) // 2, len(data) - 30, len(data) - 1):
        p = tmp_path / f"cut{cut}.npz"
        p.write_bytes(data[:cut])
        with pytest.raises(FileFormatError, match=f"cut{cut}.npz"):
            load_model(p)


def test_foreign_and_wrong_kind_files_are_refused(forest_file, tmp_path):
    from importlib import resources

    # the HOG detector's bundled model: a sound .npz with a meta header, not a classifier
    hog = str(resources.files("robopercept") / "data" / "face_hog_svm.npz")
    with pytest.raises(FileFormatError, match="format is None"):
        load_model(hog)
    npy = tmp_path / "a.npz"
    np.save(tmp_path / "a.npy", np.zeros(3))
    npy.write_bytes((tmp_path / "a.npy").read_bytes())
    with pytest.raises(FileFormatError, match=r"one \.npy array"):
        load_model(npy)
    with np.load(forest_file, allow_pickle=False) as f:
        meta = json.loads(str(f["meta"]))
    for change, match in (
        ({"kind": "KNeighborsClassifier"}, "its kind is 'KNeighborsClassifier'"),
        ({"format_version": FORMAT_VERSION + 1}, "newer robopercept.*upgrade"),
        ({"params": {"n_estimators": 3, "voting": "maybe"}}, "parameter voting"),
        ({"params": {"bogus": 1}}, "has no parameter 'bogus'"),
        ({"n_features": 2}, "tree_feature. array holds 3; expected below 2"),
        ({"feature_names": ["a"]}, "feature_names has 1 entries"),
    ):
        bad = _rewrite(forest_file, tmp_path / "bad.npz", meta=np.array(json.dumps(meta | change)))
        with pytest.raises(FileFormatError, match=match):
            load_model(bad)
    compressed = tmp_path / "z.npz"
    with np.load(forest_file, allow_pickle=False) as f:
        np.savez_compressed(compressed, **{k: f[k] for k in f.files})
    with pytest.raises(FileFormatError, match="compressed"):
        load_model(compressed)
    # read_npz(compressed=True) (what the HOG detector's loader uses) reads it, the same
    # arrays; members stating more than 256 MiB unpacked in all are refused unread
    with np.load(forest_file, allow_pickle=False) as f:
        want = {k: f[k] for k in f.files}
    got = read_npz(compressed, compressed=True)
    assert list(got) == list(want) and all(np.array_equal(got[k], want[k]) for k in want)
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        for k in ("a", "b"):  # 2 x 160 MiB of zeros in about 300 kB
            with z.open(f"{k}.npy", "w", force_zip64=True) as m:
                np.lib.format.write_array_header_1_0(
                    m, {"descr": "|u1", "fortran_order": False, "shape": (160 << 20,)}
                )
                for _ in range(160):
                    m.write(bytes(1 << 20))
    with pytest.raises(FileFormatError, match=r"bomb\.npz.*member 'b' claims 1677"):
        read_npz(bomb, compressed=True)


def test_damaged_arrays_are_refused_before_any_prediction(forest_file, tmp_path):
    with np.load(forest_file, allow_pickle=False) as f:
        left, value = f["tree_left"], f["tree_value"]
    loop = left.copy()
    loop[np.flatnonzero(loop > 0)[3]] = 0  # a child pointing back at the root: a cycle
    nan = value.copy()
    nan[2, 0] = np.nan
    for change, match in (
        ({"tree_left": loop}, "tree 0 has a node whose children"),
        ({"tree_value": nan}, "'tree_value' array holds NaN"),
        ({"tree_feature": None}, "no 'tree_feature' array"),
        ({"tree_threshold": np.zeros(3)}, "'tree_threshold' array has shape"),
        ({"classes": np.array([2, 1, 0])}, "not sorted and distinct"),
        ({"tree_left": left.astype(np.float64)}, "expected int64"),
    ):
        with pytest.raises(FileFormatError, match=match):
            load_model(_rewrite(forest_file, tmp_path / "bad.npz", **change))


class _Boom:
    """Unpickling this runs code: it would create the file named."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_pickles_are_never_loaded(forest_file, tmp_path):
    marker = tmp_path / "pwned"
    raw = tmp_path / "model.npz"
    raw.write_bytes(pickle.dumps(_Boom(str(marker))))
    with pytest.raises(FileFormatError, match=r"model\.npz is not a robopercept model file"):
        load_model(raw)
    # an object array inside the archive: NumPy would unpickle it with allow_pickle=True
    buf = io.BytesIO()
    np.save(buf, np.array([_Boom(str(marker))], dtype=object), allow_pickle=True)
    inside = tmp_path / "inside.npz"
    with zipfile.ZipFile(forest_file) as src, zipfile.ZipFile(inside, "w") as dst:
        for info in src.infolist():
            data = buf.getvalue() if info.filename == "classes.npy" else src.read(info)
            dst.writestr(info.filename, data)
    with pytest.raises(FileFormatError, match="'classes' array holds Python objects"):
        load_model(inside)
    assert not marker.exists()
    with pytest.raises(FileFormatError, match="no such file"):
        read_npz(tmp_path / "missing.npz")


def _table(path, X, y, names, label="kind", extra=True):
    rows = [",".join([*(["id"] if extra else []), *names, label])]
    for i, (x, c) in enumerate(zip(X, y, strict=True)):
        rows.append(",".join([*([f"row{i}"] if extra else []), *map(repr, x.tolist()), c]))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_predict_table_by_column_name(tmp_path, iris):
    X, y = iris
    classes = np.array(["setosa", "versicolor", "virginica"])
    names = ["sl", "sw", "pl", "pw"]
    saved = SavedModel(LDA().fit(X, y), names, list(classes), "kind")
    # columns in another order, a text id column, and one row relabelled wrong
    labels = classes[y].copy()
    labels[0] = "virginica"
    order = [3, 0, 2, 1]
    p = _table(tmp_path / "t.csv", X[:, order], labels, [names[i] for i in order])
    r = predict_table(saved, p)
    np.testing.assert_array_equal(r.predictions, saved.predict(X))
    expect = np.mean(saved.predict(X) == labels)
    assert r.accuracy == expect and r.correct == round(expect * 150) and r.unknown == 0
    d = r.to_dict()
    assert d["rows"] == 150 and sum(d["counts"].values()) == 150 and d["label"] == "kind"
    r.write_csv(tmp_path / "out.csv")
    lines = (tmp_path / "out.csv").read_text().splitlines()
    assert lines[0] == "prediction,kind,correct" and len(lines) == 151
    # without the label column: predictions only
    q = _table(tmp_path / "n.csv", X, classes[y], names, label="other", extra=False)
    r = predict_table(saved, q)
    assert r.accuracy is None and r.truth is None
    # a column the model needs is missing: named
    bad = tmp_path / "bad.csv"
    bad.write_text("sl,sw,pl,kind\n1,2,3,setosa\n")
    with pytest.raises(InputError, match="no column 'pw', which the model was trained on"):
        predict_table(saved, bad)
    with pytest.raises(InputError, match="no column 'species'"):
        predict_table(saved, p, label="species")  # asked for: must exist
    X2, y2 = read_features(p, ["pl", "sl"], "kind")
    np.testing.assert_array_equal(X2, X[:, [2, 0]])
    assert y2[0] == "virginica"


def test_predict_table_numeric_labels_without_names(tmp_path, iris):
    X, y = iris
    saved = SavedModel(DecisionTreeClassifier(max_depth=2, random_state=0).fit(X, y))
    p = _table(tmp_path / "t.csv", X, [f"{v}.0" for v in y], ["a", "b", "c", "d"], extra=False)
    r = predict_table(saved, p, label="kind")
    # "2.0" in the table equals class 2: compared as numbers
    assert r.accuracy == pytest.approx(np.mean(saved.predict(X) == y))
