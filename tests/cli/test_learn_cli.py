"""``robopercept learn cluster|classify|reduce``, ``detect-hog`` and ``train-hog``:
reports equal to the library calls, pictures written, clear errors."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.imaging import read_image, write_image
from robopercept.learning import read_table

NAMES = np.array(["setosa", "versicolor", "virginica"])


@pytest.fixture
def iris_csv(tmp_path, iris):
    X, y = iris
    path = tmp_path / "iris.csv"
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["sepal length", "sepal width", "petal length", "petal width", "species"])
        for row, label in zip(X, y, strict=True):
            w.writerow([*row, NAMES[label]])
    return path


def test_read_table_and_its_errors(tmp_path, iris_csv, iris):
    X, y, names = read_table(iris_csv, "species")
    np.testing.assert_array_equal(X, iris[0])
    np.testing.assert_array_equal(y, NAMES[iris[1]])
    assert names == ["sepal length", "sepal width", "petal length", "petal width"]
    from robopercept.errors import FileFormatError, InputError

    with pytest.raises(InputError, match="'species' is not numeric"):
        read_table(iris_csv)
    with pytest.raises(InputError, match="no column 'kind'"):
        read_table(iris_csv, "kind")
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n3\n")
    with pytest.raises(FileFormatError, match="line 3 has 1 fields"):
        read_table(bad)
    (tmp_path / "empty.csv").write_text("a,b\n")
    with pytest.raises(FileFormatError, match="at least one data row"):
        read_table(tmp_path / "empty.csv")


def test_cluster_kmeans_matches_the_library_and_writes_labels(tmp_path, iris_csv, iris, capsys):
    from robopercept.learning import KMeans, adjusted_rand_score

    out, labels_csv = tmp_path / "c.png", tmp_path / "labels.csv"
    args = ["learn", "cluster", str(iris_csv), "--label", "species", "-k", "3"]
    assert main([*args, "-o", str(out), "--labels-out", str(labels_csv), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    ref = KMeans(3, random_state=0).fit(iris[0])
    assert report["inertia"] == pytest.approx(ref.inertia_, rel=1e-12)
    assert sorted(report["sizes"].values()) == sorted(np.bincount(ref.labels_).tolist())
    assert report["adjusted_rand_index"] == pytest.approx(adjusted_rand_score(iris[1], ref.labels_))
    with labels_csv.open() as fh:
        written = [int(r[0]) for r in list(csv.reader(fh))[1:]]
    np.testing.assert_array_equal(written, ref.labels_)
    pic = read_image(out)
    assert pic.ndim == 3 and pic.shape[1] == 800
    # one dot colour per cluster: at least 3 distinct saturated colours
    flat = pic.reshape(-1, 3).astype(int)
    vivid = flat[(flat.max(1) - flat.min(1)) > 100]
    assert len(np.unique(vivid, axis=0)) >= 3


def test_cluster_dbscan_reports_noise_and_meanshift_bandwidth(iris_csv, tmp_path, capsys):
    args = ["learn", "cluster", str(iris_csv), "--label", "species", "-o", str(tmp_path / "d.png")]
    assert main([*args, "--method", "dbscan", "--eps", "0.4", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["noise"] > 0 and report["clusters"] >= 2
    assert report["noise"] + sum(report["sizes"].values()) == 150
    assert main([*args, "--method", "meanshift"]) == 0
    text = capsys.readouterr().out
    assert "bandwidth" in text and "adjusted rand index" in text


def test_classify_report_equals_the_library_and_writes_pictures(tmp_path, iris_csv, capsys):
    from robopercept.learning import SVC, accuracy_score, roc_auc_score, train_test_split

    out = tmp_path / "cls"
    args = ["learn", "classify", str(iris_csv), "--label", "species", "--model", "svm"]
    assert main([*args, "-o", str(out), "--json", "--cv", "3"]) == 0
    report = json.loads(capsys.readouterr().out)
    X, y, _ = read_table(iris_csv, "species")
    Xtr, Xt, ytr, yt = train_test_split(X, y, test_size=0.25, stratify=y, random_state=0)
    codes = {n: i for i, n in enumerate(NAMES)}
    ctr, cte = np.array([codes[v] for v in ytr]), np.array([codes[v] for v in yt])
    model = SVC().fit(Xtr, ctr)
    assert report["accuracy"] == pytest.approx(accuracy_score(cte, model.predict(Xt)))
    auc = roc_auc_score((cte == 2).astype(int), model.decision_function(Xt)[:, 2])
    assert report["curves"]["virginica"]["roc_auc"] == pytest.approx(auc)
    assert report["classes"] == NAMES.tolist()
    assert np.sum(report["confusion"]) == len(yt) == report["test_rows"]
    assert 0.9 <= report["cv_accuracy"]["mean"] <= 1.0
    for name in ("confusion.png", "roc.png", "pr.png"):
        assert read_image(out / name).ndim == 3
    assert json.loads((out / "report.json").read_text())["accuracy"] == report["accuracy"]


@pytest.mark.parametrize("model", ["tree", "forest", "lda"])
def test_classify_with_a_test_file_and_two_classes(tmp_path, iris_csv, model, capsys):
    # versicolor vs virginica, train on even rows and test on odd ones
    with iris_csv.open() as fh:
        rows = list(csv.reader(fh))
    rows = [rows[0]] + [r for r in rows[1:] if r[-1] != "setosa"]
    train, test = tmp_path / "train.csv", tmp_path / "test.csv"
    for path, part in ((train, rows[1::2]), (test, rows[2::2])):
        with path.open("w", newline="") as fh:
            csv.writer(fh).writerows([rows[0], *part])
    out = tmp_path / "o"
    args = ["learn", "classify", str(train), str(test), "--label", "species"]
    assert main([*args, "--model", model, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "virginica: ROC AUC" in text and "versicolor: ROC AUC" not in text  # one curve
    report = json.loads((out / "report.json").read_text())
    assert report["train_rows"] == report["test_rows"] == 50
    assert report["accuracy"] >= 0.85


def test_reduce_pca_and_lda(tmp_path, iris_csv, iris, capsys):
    from robopercept.learning import PCA

    t = tmp_path / "t.csv"
    args = ["learn", "reduce", str(iris_csv), "--label", "species", "-o", str(tmp_path / "r.png")]
    assert main([*args, "--transformed", str(t), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    ref = PCA(2).fit(iris[0])
    np.testing.assert_allclose(report["explained_variance_ratio"], ref.explained_variance_ratio_)
    with t.open() as fh:
        got = np.array([[float(a), float(b)] for a, b, _ in list(csv.reader(fh))[1:]])
    np.testing.assert_allclose(got, ref.transform(iris[0]), rtol=1e-8, atol=1e-8)
    assert main([*args, "--method", "lda"]) == 0
    assert "between-class variance" in capsys.readouterr().out


def test_learn_errors_name_the_fix(tmp_path, iris_csv, capsys):
    assert main(["learn", "cluster", str(iris_csv)]) == 1  # a text column: bad data
    assert "--label" in capsys.readouterr().err
    assert main(["learn", "reduce", str(iris_csv), "--method", "lda"]) == 2
    assert "--label" in capsys.readouterr().err
    assert main(["learn", "classify", str(iris_csv)]) == 2  # --label is required
    args = ["learn", "classify", str(iris_csv), "--label", "species", "--test-size", "1.5"]
    assert main(args) == 2
    assert "--test-size" in capsys.readouterr().err
    assert main(["learn", "cluster", str(tmp_path / "missing.csv")]) == 1


def test_detect_hog_finds_the_astronaut_face(tmp_path, astronaut, capsys):
    src = write_image(tmp_path / "astronaut.png", astronaut)
    out = tmp_path / "faces.png"
    assert main(["detect-hog", str(src), "-o", str(out), "--json", "--max", "3"]) == 0
    report = json.loads(capsys.readouterr().out)
    # the face, x 165..265, y 70..190 (see tests/learning/test_hog_detector.py), among the
    # boxes kept at the model's own threshold (chosen on held-out faces: docs/detection.md);
    # the mission patch on her sleeve now scores above it, so the face is not always first
    assert report["threshold_source"] == "model" and report["found"] <= 3
    assert any(
        150 < d["x"] + d["size"] / 2 < 280 and 60 < d["y"] + d["size"] / 2 < 200
        for d in report["detections"]
    )
    pic = read_image(out)
    assert pic.shape == astronaut.shape and not np.array_equal(pic, astronaut)
    bad = tmp_path / "model.npz"
    bad.write_bytes(b"nope")
    assert main(["detect-hog", str(src), "--model", str(bad)]) == 1
    assert "HOG model" in capsys.readouterr().err


def test_train_hog_writes_a_loadable_model(tmp_path, capsys):
    from robopercept.learning.hog_detector import HogDetector

    out = tmp_path / "faces.npz"
    assert main(["train-hog", "-o", str(out), "--rounds", "0", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)  # progress went to stderr
    assert report["cv"]["accuracy"] >= 0.9 and report["output"] == str(out)
    assert report["weights"] == 648 and report["rounds"] == 0
    det = HogDetector.load(out)
    assert det.signed and det.orientations == 18 and det.coef_.size == 648
    assert main(["train-hog", "-o", str(out), "--rounds", "-1"]) == 2


@pytest.mark.parametrize("model", ["tree", "forest", "svm", "lda"])
def test_classify_save_then_predict(tmp_path, iris_csv, model, capsys):
    from robopercept.learning import load_model

    saved_path = tmp_path / f"{model}.npz"
    args = ["learn", "classify", str(iris_csv), "--label", "species", "--model", model]
    args += ["--standardize", "--trees", "10", "-o", str(tmp_path / "out")]
    assert main([*args, "--save", str(saved_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["model_file"] == str(saved_path)
    saved = load_model(saved_path)
    assert saved.feature_names == ("sepal length", "sepal width", "petal length", "petal width")
    assert saved.class_names == tuple(NAMES) and saved.label_column == "species"
    assert saved.mean is not None  # --standardize travels with the model
    # the saved model scores the held-out rows exactly as classify reported
    from robopercept.learning import train_test_split

    X, y, _ = read_table(iris_csv, "species")
    _, Xt, _, yt = train_test_split(X, y, test_size=0.25, stratify=y, random_state=0)
    assert np.mean(saved.predict(Xt) == yt) == report["accuracy"]
    pred_csv = tmp_path / "pred.csv"
    assert (
        main(["learn", "predict", str(saved_path), str(iris_csv), "-o", str(pred_csv), "--json"])
        == 0
    )
    out = json.loads(capsys.readouterr().out)  # stdout is one JSON object, nothing else
    assert out["predictions"] == saved.predict(X).tolist()
    assert out["accuracy"] == pytest.approx(np.mean(saved.predict(X) == y))
    assert out["label"] == "species" and out["rows"] == 150 and out["unknown_labels"] == 0
    assert out["kind"] and out["classes"] == NAMES.tolist() and out["output"] == str(pred_csv)
    with pred_csv.open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["prediction", "species", "correct"]
    assert [r[0] for r in rows[1:]] == out["predictions"]


def test_predict_text_output_and_errors(tmp_path, iris_csv, iris, capsys):
    saved_path = tmp_path / "m.npz"
    args = ["learn", "classify", str(iris_csv), "--label", "species", "--model", "lda"]
    assert main([*args, "-o", str(tmp_path / "o"), "--save", str(saved_path)]) == 0
    assert f"-> {saved_path}" in capsys.readouterr().out
    # a table without the label column: predictions, no accuracy
    X = iris[0]
    bare = tmp_path / "bare.csv"
    bare.write_text(
        "id,petal width,petal length,sepal width,sepal length\n"
        + "".join(f"r{i},{x[3]},{x[2]},{x[1]},{x[0]}\n" for i, x in enumerate(X))
    )
    out = tmp_path / "p.csv"
    assert main(["learn", "predict", str(saved_path), str(bare), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "150 rows" in text and "accuracy" not in text
    assert out.read_text().splitlines()[0] == "prediction"
    # a missing feature column is named
    (tmp_path / "short.csv").write_text("sepal length,sepal width,petal length\n1,2,3\n")
    assert main(["learn", "predict", str(saved_path), str(tmp_path / "short.csv")]) == 1
    assert "no column 'petal width'" in capsys.readouterr().err
    # not a model file (a CSV), and a pickle: refused, never run
    assert main(["learn", "predict", str(iris_csv), str(iris_csv)]) == 1
    assert "not a robopercept model file" in capsys.readouterr().err
    # --save needs .npz: a usage error before any training
    assert main([*args, "--save", str(tmp_path / "m.pkl")]) == 2
    assert "--save" in capsys.readouterr().err


@pytest.mark.parametrize("task", ["cluster", "classify", "reduce", "predict"])
def test_every_learn_task_prints_one_json_object(tmp_path, iris_csv, task, capsys):
    model = tmp_path / "m.npz"
    main(["learn", "classify", str(iris_csv), "--label", "species", "--model", "lda",
          "-o", str(tmp_path / "c"), "--save", str(model)])  # fmt: skip
    capsys.readouterr()
    tail = {
        "cluster": [str(iris_csv), "--label", "species", "-o", str(tmp_path / "c.png")],
        "classify": [str(iris_csv), "--label", "species", "--model", "lda", "-o", str(tmp_path)],
        "reduce": [str(iris_csv), "--label", "species", "-o", str(tmp_path / "r.png")],
        "predict": [str(model), str(iris_csv), "-o", str(tmp_path / "p.csv")],
    }[task]
    assert main(["learn", task, *tail, "--json"]) == 0
    out = capsys.readouterr().out
    assert isinstance(json.loads(out), dict) and out.count("\n") == 1
