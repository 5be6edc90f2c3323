r"""Evaluating a classifier on a table: CSV tables in, a report out.

The pieces of ``robopercept learn classify``, usable on their own:

* :func:`read_table`: a CSV file with a header row as ``(X, y, feature names)``;
* :func:`standardize`: z-scores with the training rows' mean and standard deviation,
  :math:`x' = (x - \mu_{train}) / \sigma_{train}` (a constant column keeps
  :math:`\sigma = 1`, as scikit-learn's ``StandardScaler``);
* :func:`label_codes`: class names to integer codes, numeric names in numeric order;
* :func:`class_scores`: per-class scores for ROC and precision-recall curves;
* :func:`evaluate_classifier`: the classification report (precision, recall, F1,
  support, accuracy, confusion matrix) and one-vs-rest ROC and PR curves with their
  areas, as scikit-learn's ``classification_report``, ``roc_curve``,
  ``precision_recall_curve``, ``roc_auc_score`` and ``average_precision_score`` give;
* :func:`confusion_table`: the confusion matrix as a text table.
"""

from __future__ import annotations

import csv
import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import (
    check_file,
    check_int,
    check_magnitude,
    check_numeric,
    check_text,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.learning._base import check_matrix
from robopercept.learning.metrics import (
    ClassificationReport,
    average_precision_score,
    check_labels,
    classification_report,
    precision_recall_curve,
    roc_auc_score,
    roc_curve,
)

__all__ = [
    "ClassCurves",
    "ClassifierEvaluation",
    "class_scores",
    "confusion_table",
    "evaluate_classifier",
    "label_codes",
    "read_features",
    "read_table",
    "standard_scaling",
    "standardize",
]


def read_table(
    path: str | os.PathLike[str], label: str | None = None
) -> tuple[np.ndarray, np.ndarray | None, list[str]]:
    """A CSV file with a header row: ``(X, y, feature names)``.

    Every column but ``label`` must be numeric (empty cells become NaN, which the
    estimators refuse with the row named); ``y`` keeps the label column's text.

    Parameters
    ----------
    path : path-like
    label : str, optional
        The column of classes (left out of ``X``).

    Returns
    -------
    X : (N, d) float64 ndarray
    y : (N,) str ndarray or None
        None without ``label``.
    names : list of str
        The feature columns' names, in file order.

    Raises
    ------
    FileFormatError
        Missing file or a folder, not a text file, no data row, or a row with another
        number of fields than the header.
    InputError
        No column ``label``, no feature column, or a non-numeric feature column.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("a,b,kind\\n1,2,x\\n3,4,y\\n")
    >>> X, y, names = read_table(p, "kind")
    >>> X.tolist(), y.tolist(), names
    ([[1.0, 2.0], [3.0, 4.0]], ['x', 'y'], ['a', 'b'])
    """
    path = check_file(path, "a CSV file")
    if label is not None:
        label = check_text(label, "label (the --label column)")
    header, body = _read_csv(path)
    if label is not None and label not in header:
        raise InputError(f"{path}: no column {label!r}; columns are {', '.join(header)}")
    y = None
    if label is not None:
        j = header.index(label)
        y = np.array([row[j].strip() for row in body])
    names = [h for h in header if h != label]
    if not names:
        raise InputError(f"{path}: no feature columns besides the label")
    return _numeric_columns(path, header, body, names), y, names


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    """The header (stripped names) and the data rows of a CSV file, every row with as
    many fields as the header."""
    try:
        with path.open(newline="") as fh:
            rows = [row for row in csv.reader(fh) if row]
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text CSV file") from None
    except csv.Error as exc:
        raise FileFormatError(f"{path}: not a CSV file ({exc})") from None
    if len(rows) < 2:
        raise FileFormatError(f"{path}: needs a header row and at least one data row")
    header = [h.strip() for h in rows[0]]
    body = rows[1:]
    for i, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise FileFormatError(
                f"{path}: line {i} has {len(row)} fields, the header {len(header)}"
            )
    return header, body


def _numeric_columns(
    path: Path, header: list[str], body: list[list[str]], names: list[str]
) -> np.ndarray:
    """The columns ``names`` (present in ``header``) as float64; empty cells NaN."""
    X = np.empty((len(body), len(names)))
    for c, name in enumerate(names):
        j = header.index(name)
        try:
            X[:, c] = [float(row[j]) if row[j].strip() else np.nan for row in body]
        except ValueError:
            raise InputError(
                f"{path}: column {name!r} is not numeric; name it with --label if it "
                "holds the classes, or drop it"
            ) from None
    return X


def read_features(
    path: str | os.PathLike[str], names: list[str] | tuple[str, ...], label: str | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """The columns ``names`` of a CSV file with a header row, by name, and the ``label``
    column when the file has one.

    Other columns are ignored (they may hold text: row ids, notes), so a table written
    for one model can be fed to another that uses some of its columns.

    Parameters
    ----------
    path : path-like
    names : sequence of str
        The feature columns, in the order the model takes them.
    label : str, optional
        The column of true classes; read when present, else ``y`` is None.

    Returns
    -------
    X : (N, len(names)) float64 ndarray
        Empty cells are NaN (the estimators refuse them, naming the rows).
    y : (N,) str ndarray or None

    Raises
    ------
    FileFormatError
        As :func:`read_table`.
    InputError
        A column of ``names`` missing from the file (the message names it and lists the
        file's columns), or not numeric.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("id,b,a\\nr1,2,1\\nr2,4,3\\n")
    >>> X, y = read_features(p, ["a", "b"], label="kind")
    >>> X.tolist(), y
    ([[1.0, 2.0], [3.0, 4.0]], None)
    """
    path = check_file(path, "a CSV file")
    if not isinstance(names, (list, tuple)) or not names:
        raise InputError(f"names must be a non-empty list of column names; got {plain_repr(names)}")
    names = [check_text(n, "names[i] (a column name)") for n in names]
    if label is not None:
        label = check_text(label, "label (the --label column)")
    header, body = _read_csv(path)
    missing = [n for n in names if n not in header]
    if missing:
        raise InputError(
            f"{path}: no column {missing[0]!r}"
            + (f" (nor {', '.join(map(repr, missing[1:]))})" if len(missing) > 1 else "")
            + f", which the model was trained on; the file's columns are {', '.join(header)}:"
            " give a table with the training table's feature columns"
        )
    y = None
    if label is not None and label in header:
        j = header.index(label)
        y = np.array([row[j].strip() for row in body])
    return _numeric_columns(path, header, body, names), y


def standardize(train: np.ndarray, *others: np.ndarray) -> list[np.ndarray]:
    r"""Scale features to zero mean and unit variance with the training rows' figures.

    :math:`x' = (x - \mu) / \sigma` per column, :math:`\mu` and :math:`\sigma`
    (population standard deviation) from ``train``; a constant column keeps
    :math:`\sigma = 1`. Same values as scikit-learn's ``StandardScaler().fit(train)``.

    Parameters
    ----------
    train : (N, d) ndarray
    *others : (M, d) ndarray
        Further tables (test rows) scaled with ``train``'s figures.

    Returns
    -------
    list of ndarray
        ``train`` scaled, then every one of ``others``.

    Examples
    --------
    >>> train, test = np.array([[0.0, 5.0], [2.0, 5.0]]), np.array([[4.0, 6.0]])
    >>> [a.tolist() for a in standardize(train, test)]
    [[[-1.0, 0.0], [1.0, 0.0]], [[3.0, 1.0]]]
    """
    tables = [check_matrix(train, "train")]
    for i, a in enumerate(others):
        tables.append(check_matrix(a, f"others[{i}]"))
        if tables[-1].shape[1] != tables[0].shape[1]:
            raise InputError(
                f"others[{i}] has {tables[-1].shape[1]} columns, train "
                f"{tables[0].shape[1]}: every table needs train's features"
            )
    mean, std = _scaling(tables[0])
    return [(a - mean) / std for a in tables]


def _scaling(train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # squared in the standard deviation: beyond 1e150 it overflows
    check_magnitude(train, "train", 1e150)
    mean, std = train.mean(axis=0), train.std(axis=0)
    return mean, np.where(std > 0, std, 1.0)


def standard_scaling(train: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""The column means and standard deviations :func:`standardize` scales with.

    :math:`\mu_j = \frac1N \sum_i x_{ij}`,
    :math:`\sigma_j = \sqrt{\frac1N \sum_i (x_{ij} - \mu_j)^2}`, and
    :math:`\sigma_j = 1` for a constant column, so that ``(X - mean) / scale`` is
    exactly ``standardize(train, X)[1]`` (scikit-learn's ``StandardScaler().fit(train)``
    ``mean_`` and ``scale_``). Keep them with a model to scale new rows the same way.

    Parameters
    ----------
    train : (N, d) ndarray

    Returns
    -------
    mean, scale : (d,) float64 ndarray

    Examples
    --------
    >>> mean, scale = standard_scaling(np.array([[0.0, 5.0], [2.0, 5.0]]))
    >>> mean.tolist(), scale.tolist()
    ([1.0, 5.0], [1.0, 1.0])
    """
    return _scaling(check_matrix(train, "train"))


def label_codes(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Integer codes of class labels, and the class names in code order.

    The names are sorted numerically when they all are numbers (classes ``"2"`` and
    ``"10"`` come in that order), else as text.

    Parameters
    ----------
    y : (N,) array_like

    Returns
    -------
    codes : (N,) int64 ndarray
        ``names[codes] == y``.
    names : (c,) ndarray
        The distinct labels.

    Examples
    --------
    >>> codes, names = label_codes(np.array(["10", "2", "10"]))
    >>> codes.tolist(), names.tolist()
    ([1, 0, 1], ['2', '10'])
    """
    y = check_labels(y, "y")
    names = np.unique(y)
    try:
        names = names[np.argsort([float(v) for v in names], kind="stable")]
    except ValueError:
        pass
    lookup = {v: i for i, v in enumerate(names)}
    return np.array([lookup[v] for v in y], dtype=np.int64), names


def _model(model: Any, need: tuple[str, ...]) -> Any:
    """``model`` after checking that it has the methods in ``need``."""
    missing = [m for m in need if not hasattr(model, m)]
    if missing:
        raise InputError(
            f"model must be a fitted classifier (with {', '.join(need)}); got "
            f"{type(model).__name__} {plain_repr(model)[:60]}, which lacks {', '.join(missing)}"
        )
    return model


def class_scores(model: Any, X: np.ndarray, n_classes: int) -> np.ndarray:
    """Per-class scores ``(N, c)`` of a fitted classifier, for ROC and PR curves.

    ``predict_proba`` when the model has it, else ``decision_function``; a binary
    decision function ``f`` (one column, positive for the second class) becomes
    ``[-f, f]``.

    Parameters
    ----------
    model : fitted classifier
    X : (N, d) ndarray
    n_classes : int
        Number of classes the model knows (``model.classes_.size``).

    Returns
    -------
    (N, n_classes) ndarray
    """
    n_classes = check_int(n_classes, "n_classes", 2)
    X = check_matrix(X, "X")
    if not hasattr(model, "predict_proba"):
        _model(model, ("decision_function",))
    return _scores(model, X, n_classes)


def _scores(model: Any, X: np.ndarray, n_classes: int) -> np.ndarray:
    """:func:`class_scores` without the checks of its arguments (the scores are)."""
    if hasattr(model, "predict_proba"):
        out = np.asarray(model.predict_proba(X))
    else:
        f = np.asarray(model.decision_function(X))
        out = np.c_[-f, f] if n_classes == 2 and f.ndim == 1 else f
    if out.shape != (X.shape[0], n_classes):
        raise InputError(
            f"the model gives scores of shape {out.shape} for {X.shape[0]} rows; expected "
            f"({X.shape[0]}, {n_classes}): n_classes must be the model's number of classes"
        )
    return out


@dataclass(frozen=True)
class ClassCurves:
    """One class's one-vs-rest ROC and precision-recall curves.

    Attributes
    ----------
    fpr, tpr : (k,) ndarray
        ROC curve (:func:`~robopercept.learning.roc_curve`).
    precision, recall : (m,) ndarray
        Precision-recall curve (:func:`~robopercept.learning.precision_recall_curve`).
    roc_auc, average_precision : float
        Area under the ROC curve and average precision.
    """

    fpr: np.ndarray
    tpr: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    roc_auc: float
    average_precision: float


@dataclass(frozen=True)
class ClassifierEvaluation:
    """What :func:`evaluate_classifier` found.

    Attributes
    ----------
    report : ClassificationReport
        Per-class precision, recall, F1, support, the accuracy and the confusion matrix
        (rows true, columns predicted); ``labels`` are class names.
    curves : dict of str -> ClassCurves
        One-vs-rest curves per class name, in code order; with two classes only the
        second (the positive) one; a class absent from (or alone in) the test rows has
        none.
    predictions : (N,) int64 ndarray
        The model's predicted codes.
    """

    report: ClassificationReport
    curves: dict[str, ClassCurves]
    predictions: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """The figures as JSON-ready values (``accuracy``, ``classes``, ``precision``,
        ``recall``, ``f1``, ``support``, ``confusion``, ``curves``)."""
        rep = self.report
        return {
            "accuracy": rep.accuracy,
            "classes": [str(v) for v in rep.labels],
            "precision": rep.precision.tolist(),
            "recall": rep.recall.tolist(),
            "f1": rep.f1.tolist(),
            "support": rep.support.tolist(),
            "confusion": rep.confusion.tolist(),
            "curves": {
                n: {"roc_auc": c.roc_auc, "average_precision": c.average_precision}
                for n, c in self.curves.items()
            },
        }


def evaluate_classifier(
    model: Any, X: np.ndarray, codes: np.ndarray, classes: np.ndarray
) -> ClassifierEvaluation:
    """Evaluate a fitted classifier on test rows.

    Parameters
    ----------
    model : fitted classifier
        Trained on integer codes (see :func:`label_codes`); ``predict`` and
        ``predict_proba`` or ``decision_function``, ``classes_``.
    X : (N, d) ndarray
        Test rows.
    codes : (N,) int ndarray
        Their true codes.
    classes : (c,) ndarray
        Class names indexed by code.

    Returns
    -------
    ClassifierEvaluation
        The report covers the classes seen in the test rows or predicted; the curves
        cover the model's classes.

    Examples
    --------
    >>> from robopercept.learning import LDA
    >>> X = np.array([[0.0], [0.2], [1.0], [1.2], [0.1], [1.1]])
    >>> codes = np.array([0, 0, 1, 1, 0, 1])
    >>> ev = evaluate_classifier(LDA().fit(X, codes), X, codes, np.array(["a", "b"]))
    >>> ev.report.accuracy, list(ev.curves), ev.curves["b"].roc_auc
    (1.0, ['b'], 1.0)
    """
    _model(model, ("predict", "classes_"))
    if not hasattr(model, "predict_proba"):
        _model(model, ("predict", "classes_", "decision_function"))
    X = check_matrix(X, "X")
    classes = check_labels(classes, "classes")
    codes = check_numeric(codes, "codes")
    if codes.shape != (X.shape[0],):
        raise InputError(
            f"codes must hold one code per row of X ({X.shape[0]}); got shape {codes.shape}"
        )
    known = np.asarray(model.classes_)
    trained = check_numeric(known, "the model's classes_ (train it on codes)")
    for name, c in (("codes", codes), ("the model's classes_", trained)):
        if not ((c == np.round(c)) & (c >= 0) & (c < classes.size)).all():
            raise InputError(
                f"{name} must be whole numbers in 0..{classes.size - 1} (indices into "
                "classes, as label_codes gives); train the model on those codes"
            )
    codes = codes.astype(np.int64)
    pred = np.asarray(model.predict(X))
    rep = classification_report(codes, pred)  # codes: classes in numeric order
    rep = dataclasses.replace(rep, labels=classes[rep.labels])
    # the report's classes are the ones seen in test; the scores cover the model's
    scores = _scores(model, X, known.size)
    curves: dict[str, ClassCurves] = {}
    columns = list(enumerate(model.classes_))
    if len(columns) == 2:
        columns = columns[1:]  # one curve says it all: the second class is the positive
    for col, code in columns:
        truth = (codes == code).astype(int)
        if truth.min() == truth.max():
            continue  # the class is absent from (or alone in) the test rows
        fpr, tpr, _ = roc_curve(truth, scores[:, col])
        prec, rec, _ = precision_recall_curve(truth, scores[:, col])
        curves[str(classes[code])] = ClassCurves(
            fpr,
            tpr,
            prec,
            rec,
            roc_auc_score(truth, scores[:, col]),
            average_precision_score(truth, scores[:, col]),
        )
    return ClassifierEvaluation(rep, curves, np.asarray(pred))


def confusion_table(confusion: np.ndarray, names: list[str]) -> str:
    """A confusion matrix as a text table (rows: true, columns: predicted).

    Parameters
    ----------
    confusion : (c, c) int ndarray
    names : list of str
        Class names, in the matrix's order.

    Returns
    -------
    str
        A header line of names, then one line per true class; columns are right
        aligned to the longest name (at least 6 characters).

    Examples
    --------
    >>> print(confusion_table(np.array([[3, 1], [0, 4]]), ["cat", "dog"]))
              cat    dog
       cat      3      1
       dog      0      4
    """
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise InputError(f"names must be a list of class names (str); got {plain_repr(names)[:80]}")
    c = check_numeric(confusion, "confusion")
    if c.shape != (len(names), len(names)) or not names:
        raise InputError(
            f"confusion must be a square (c, c) matrix with one row per name ({len(names)}); "
            f"got shape {c.shape}"
        )
    if not (np.isfinite(c) & (c == np.round(c))).all():
        raise InputError("confusion must hold counts (whole numbers)")
    confusion = c.astype(np.int64) if np.abs(c).max() < 2**62 else c
    w = max(6, *(len(n) for n in names))
    lines = [" " * w + " " + " ".join(f"{n:>{w}}" for n in names)]
    for n, row in zip(names, np.asarray(confusion), strict=True):
        lines.append(f"{n:>{w}} " + " ".join(f"{v:>{w}.0f}" for v in row))
    return "\n".join(lines)
