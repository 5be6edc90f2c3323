r"""Saving fitted classifiers to a file and loading them back: arrays and JSON, never pickle.

A model file (format version 1) is an *uncompressed* NumPy ``.npz`` archive: a zip of
``.npy`` arrays, readable by ``np.load(path, allow_pickle=False)`` and by any zip tool.
It holds

* ``meta``: a 0-d unicode array, the JSON header::

    {"format": "robopercept-model", "format_version": 1,
     "robopercept_version": "0.1.0", "kind": "RandomForestClassifier",
     "params": {...constructor arguments...}, "n_features": 4,
     "feature_names": ["sepal length", ...] or null,
     "class_names": ["setosa", ...] or null, "label_column": "species" or null,
     "standardized": false, "attributes": {...fitted scalars...}, "info": {...}}

* the fitted arrays of the model, float64 and int64, named by kind:

  ================================  ================================================
  kind                              arrays
  ================================  ================================================
  DecisionTree{Classifier,          ``tree_nodes`` (n_trees,) node counts; the node
  Regressor}, RandomForest{...}     arrays of every tree one after another:
                                    ``tree_feature``, ``tree_threshold``,
                                    ``tree_left``, ``tree_right`` (indices local to
                                    each tree), ``tree_value`` (nodes, outputs),
                                    ``tree_impurity``, ``tree_n_node_samples``;
                                    ``feature_importances`` (d,)
  SVC                               ``support``, ``support_vectors``, ``n_support``,
                                    ``machine_sizes``, ``machine_sv``,
                                    ``machine_coef`` (the one-vs-one machines one
                                    after another), ``intercept``, ``gamma``,
                                    ``n_iter``; ``prob_a``, ``prob_b`` (each
                                    pair's Platt sigmoid) with
                                    ``probability=True``
  LinearSVC                         ``coef``, ``intercept``
  LDA                               ``coef``, ``intercept``, ``means``, ``priors``,
                                    ``xbar``, ``scalings``,
                                    ``explained_variance_ratio``, ``shrinkage``
  ================================  ================================================

  plus ``classes`` (every classifier) and ``standardize_mean``, ``standardize_scale``
  when the rows are standardized before the model (``standardized: true``).

Why this format: floats are stored as their float64 bytes, so a loaded model predicts
*bit for bit* what the saved one did; the file holds data only, so loading it runs no
code (a pickle or joblib file runs whatever it names: never load one from a source you
do not trust); the header is plain JSON that a user can read with ``np.load`` and
``json.loads``; and the archive is the one the HOG detector's model already uses.
Members are stored uncompressed so that what a file unpacks to is bounded by its size.

:func:`load_model` trusts nothing in the file: each member's NPY header is checked
against its bytes (:func:`read_npz`), Python-object (pickle) arrays are refused unread,
and every array is checked for its dtype, shape, finiteness and index ranges (a tree's
children come after their parent and inside the tree, so prediction always ends) before
an estimator is built. A damaged, truncated or foreign file raises
:class:`~robopercept.errors.FileFormatError` naming the file and what is wrong.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept import __version__
from robopercept._checks import as_path, check_extension, check_file, check_text, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.learning._base import check_matrix, not_fitted_error
from robopercept.learning.forest import (
    MAX_ESTIMATORS,
    RandomForestClassifier,
    RandomForestRegressor,
)
from robopercept.learning.lda import LDA
from robopercept.learning.report import read_features, read_table
from robopercept.learning.svm import SVC, LinearSVC
from robopercept.learning.tree import DecisionTreeClassifier, DecisionTreeRegressor, Tree

__all__ = [
    "FORMAT_VERSION",
    "MODEL_KINDS",
    "SavedModel",
    "TablePrediction",
    "load_model",
    "predict_table",
    "read_npz",
    "save_model",
]

#: the version of the file layout this module writes (and the newest it reads)
FORMAT_VERSION = 1
_FORMAT = "robopercept-model"
#: most members of an archive, and bytes one member may hold
_MAX_MEMBERS = 64
_MAX_MEMBER = 1 << 30
#: most bytes the members of a compressed archive may unpack to, all together
_MAX_UNPACKED = 256 << 20
#: most feature columns a model file may state
_MAX_FEATURES = 10_000_000
_TREE_FIELDS = ("feature", "threshold", "left", "right", "value", "impurity", "n_node_samples")
_JSON_SCALARS = (type(None), bool, int, float, str)


# ----------------------------------------------------------------------- safe reading
def read_npz(
    path: str | os.PathLike[str], what: str = "an .npz archive", *, compressed: bool = False
) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` archive, read without pickles and without trusting a
    length or shape the file states.

    Each member ``name.npy`` must be stored uncompressed (what ``np.savez`` writes), so
    nothing unpacks to more than the file's size; with ``compressed=True`` compressed
    members (``np.savez_compressed``) are read too, and all of them together may unpack
    to at most 256 MiB. Each NPY header (format 1.0 or 2.0) is parsed and the array
    built only when ``prod(shape) * itemsize`` equals the bytes after the header; object
    dtypes (pickles) are refused, never read. For a sound file this is
    ``dict(np.load(path, allow_pickle=False))``. Used by :func:`load_model` and
    :meth:`robopercept.learning.hog_detector.HogDetector.load`.

    Parameters
    ----------
    path : path-like
    what : str
        What the file should be, with its article, for messages.
    compressed : bool
        Accept compressed members (bounded as above).

    Returns
    -------
    dict of str -> ndarray
        In archive order.

    Raises
    ------
    FileFormatError
        Missing file or a folder; a single ``.npy`` array; not a zip archive; a
        compressed, oversized or duplicated member or one that is not ``.npy``; more
        than 64 members; a damaged header or data. The message names the file.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.npz"
    >>> np.savez(p, x=np.arange(3), meta=np.array("{}"))
    >>> {k: v.tolist() for k, v in read_npz(p).items()}
    {'x': [0, 1, 2], 'meta': '{}'}
    """
    p = check_file(path, what)
    bad = f"{p} is not {what}"
    try:
        with p.open("rb") as f:
            head = f.read(6)
        size = p.stat().st_size
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot read it ({exc})") from None
    if head == b"\x93NUMPY":
        raise FileFormatError(f"{bad}: it holds one .npy array, not an archive")
    arrays: dict[str, np.ndarray] = {}
    # what the members may still unpack to: the file's size when they are stored
    budget = _MAX_UNPACKED if compressed else size
    try:
        with zipfile.ZipFile(p) as z:
            infos = z.infolist()
            if len(infos) > _MAX_MEMBERS:
                raise FileFormatError(f"{bad}: it has {len(infos)} members (at most 64)")
            for info in infos:
                name = info.filename.removesuffix(".npy")
                if name == info.filename or not name or name in arrays:
                    raise FileFormatError(
                        f"{bad}: member {info.filename[:80]!r} is not a (single) .npy array"
                    )
                if info.compress_type != zipfile.ZIP_STORED and not compressed:
                    raise FileFormatError(
                        f"{bad}: member {name[:80]!r} is compressed (save_model stores "
                        "arrays uncompressed)"
                    )
                if info.file_size > min(budget, _MAX_MEMBER) or info.compress_size > size:
                    raise FileFormatError(
                        f"{bad}: member {name[:80]!r} claims {info.file_size} bytes "
                        f"({info.compress_size} stored) in a {size}-byte file"
                    )
                if compressed:
                    budget -= info.file_size
                arrays[name] = _npy(_member_bytes(z, info), name, bad)
    except FileFormatError:
        raise
    except Exception as exc:
        # untrusted bytes through zipfile, zlib/bz2/lzma and NumPy's header parser, which
        # raise BadZipFile, zlib.error, EOFError, NotImplementedError (an unknown
        # compression), RuntimeError (encryption), tokenize.TokenError, ValueError,
        # SyntaxError, MemoryError...: each one means a damaged or foreign file
        raise FileFormatError(f"{bad} ({type(exc).__name__}: {str(exc)[:200]})") from None
    return arrays


def _member_bytes(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> bytes:
    """The unpacked bytes of a member, read in 1 MiB pieces, never more than it states
    (zipfile's CRC check at the end of the member catches a short or altered one).
    ``ZipFile.read`` would ask the file for the whole stated compressed size at once, and
    Python allocates that much before the read comes back short (a 2 GiB length word cost
    1 GiB on a 6 kB file)."""
    out = bytearray()
    with z.open(info) as f:
        while piece := f.read(1 << 20):
            out += piece
            if len(out) > info.file_size:
                break
    return bytes(out)


def _npy(raw: bytes, name: str, bad: str) -> np.ndarray:
    """An array from the bytes of a ``.npy`` file, checked against its header."""
    from numpy.lib import format as npy

    f = io.BytesIO(raw)
    version = npy.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = npy.read_array_header_1_0(f)
    elif version == (2, 0):
        shape, fortran, dtype = npy.read_array_header_2_0(f)
    else:
        raise FileFormatError(f"{bad}: its {name!r} array has NPY version {version}")
    if dtype.hasobject:
        raise FileFormatError(
            f"{bad}: its {name!r} array holds Python objects (pickles), which are never "
            "loaded: save the file again from number or string arrays"
        )
    count = math.prod(shape)
    left = len(raw) - f.tell()
    if count * dtype.itemsize != left:
        raise FileFormatError(
            f"{bad}: its {name!r} array header says {count} x {dtype.itemsize} bytes; "
            f"{left} follow (truncated or damaged)"
        )
    data = np.frombuffer(raw, dtype=dtype, count=count, offset=f.tell())
    return data.reshape(shape, order="F" if fortran else "C").copy(order="K")


class _Arrays:
    """The arrays of one model file, handed out checked (dtype, shape, values)."""

    def __init__(self, path: Path, arrays: dict[str, np.ndarray]) -> None:
        self.path = path
        self.arrays = arrays

    def fail(self, message: str) -> FileFormatError:
        return FileFormatError(f"{self.path}: {message} (not a sound robopercept model file)")

    def get(
        self,
        name: str,
        kind: str,
        shape: tuple[int | None, ...],
        low: float | None = None,
        high: float | None = None,
    ) -> np.ndarray:
        """Array ``name``: ``kind`` "f" float64 (finite), "i" int64, or "c" classes;
        ``shape`` with None for any length; values in ``[low, high)``."""
        a = self.arrays.get(name)
        if a is None:
            raise self.fail(f"it has no {name!r} array")
        if a.ndim != len(shape) or any(
            s is not None and s != n for s, n in zip(shape, a.shape, strict=True)
        ):
            want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
            raise self.fail(f"its {name!r} array has shape {a.shape}; expected {want}")
        if kind == "f":
            if a.dtype.kind not in "fiu" or a.dtype.itemsize > 8:
                raise self.fail(f"its {name!r} array is {a.dtype}; expected float64")
            a = a.astype(np.float64)
            if not np.isfinite(a).all():
                raise self.fail(f"its {name!r} array holds NaN or inf")
        elif kind == "i":
            if a.dtype.kind not in "iu" or a.dtype.itemsize > 8:
                raise self.fail(f"its {name!r} array is {a.dtype}; expected int64")
            if a.dtype == np.uint64 and a.size and a.max() >= 2**63:
                raise self.fail(f"its {name!r} array holds values beyond int64")
            a = a.astype(np.int64)
        else:  # classes: sorted distinct labels of a plain dtype
            if a.dtype.kind not in "biufU" or a.size < 2:
                raise self.fail(f"its {name!r} array ({a.dtype}, {a.size}) is not 2+ labels")
            if a.dtype.kind == "f" and not np.isfinite(a).all():
                raise self.fail(f"its {name!r} array holds NaN or inf")
            if not np.all(a[1:] > a[:-1]):
                raise self.fail(f"its {name!r} array is not sorted and distinct")
        if a.size and low is not None and a.min() < low:
            raise self.fail(f"its {name!r} array holds {a.min()}, below {low}")
        if a.size and high is not None and a.max() >= high:
            raise self.fail(f"its {name!r} array holds {a.max()}; expected below {high}")
        return a.copy(order="K")  # the saved memory order: BLAS rounds by layout

    def scalar(self, name: str, low: float | None = None) -> float:
        a = self.get(name, "f", (), low)
        return float(a)


# ------------------------------------------------------------------------ the kinds
def _put_trees(trees: list[Tree]) -> dict[str, np.ndarray]:
    out = {"tree_nodes": np.array([t.node_count for t in trees], dtype=np.int64)}
    for name in _TREE_FIELDS:
        out[f"tree_{name}"] = np.concatenate([getattr(t, name) for t in trees])
    return out


def _get_trees(a: _Arrays, d: int, n_out: int, n_trees_max: int) -> list[Tree]:
    """The trees of a file, each checked so that prediction is safe: children inside
    the tree and after their parent (every path ends at a leaf), split features in
    ``0..d-1``, finite thresholds and values."""
    feature = a.get("tree_feature", "i", (None,), -1, d)
    total = feature.size
    counts = a.get("tree_nodes", "i", (None,), 1, total + 1)
    if not 1 <= counts.size <= n_trees_max or sum(counts.tolist()) != total:
        raise a.fail(
            f"its {counts.size} trees (1 to {n_trees_max}) do not have the {total} nodes "
            "of its node arrays"
        )
    threshold = a.get("tree_threshold", "f", (total,))
    left = a.get("tree_left", "i", (total,), -1)
    right = a.get("tree_right", "i", (total,), -1)
    value = a.get("tree_value", "f", (total, n_out))
    impurity = a.get("tree_impurity", "f", (total,), 0.0)
    samples = a.get("tree_n_node_samples", "i", (total,), 0)
    trees = []
    start = 0
    for k, n in enumerate(counts.tolist()):
        part = slice(start, start + n)
        lf, rt, ft = left[part], right[part], feature[part]
        node = np.arange(n)
        leaf = lf < 0
        inner = ~leaf
        if (
            np.any(leaf != (rt < 0))
            or np.any(ft[inner] < 0)
            or np.any(lf[inner] <= node[inner])
            or np.any(rt[inner] <= node[inner])
            or np.any(lf[inner] >= n)
            or np.any(rt[inner] >= n)
        ):
            raise a.fail(
                f"tree {k} has a node whose children are missing, before it or outside "
                "the tree, or an inner node without a split feature"
            )
        arrays = (ft, threshold[part], lf, rt, value[part], impurity[part], samples[part])
        trees.append(Tree(tuple(np.ascontiguousarray(x) for x in arrays)))
        start += n
    return trees


def _encode(model: Any) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and fitted scalars of a fitted, supported model."""
    kind = type(model).__name__
    arrays: dict[str, np.ndarray] = {}
    attrs: dict[str, Any] = {}
    if isinstance(model, (DecisionTreeClassifier, DecisionTreeRegressor)):
        arrays.update(_put_trees([model.tree_]))
        arrays["feature_importances"] = model.feature_importances_
    elif isinstance(model, (RandomForestClassifier, RandomForestRegressor)):
        arrays.update(_put_trees(model.estimators_))
        arrays["feature_importances"] = model.feature_importances_
        if hasattr(model, "oob_score_"):
            attrs["oob_score_"] = float(model.oob_score_)
    elif kind == "SVC":
        arrays.update(
            support=model.support_,
            support_vectors=model.support_vectors_,
            n_support=model.n_support_,
            machine_sizes=np.array([i.size for i in model.machine_support_], dtype=np.int64),
            machine_sv=np.concatenate(model.machine_support_).astype(np.int64),
            machine_coef=np.concatenate(model.dual_coef_).astype(np.float64),
            intercept=model.intercept_,
            gamma=np.array(model.gamma_, dtype=np.float64),
            n_iter=model.n_iter_,
        )
        if hasattr(model, "probA_"):  # probability=True: each pair's Platt sigmoid
            arrays.update(prob_a=model.probA_, prob_b=model.probB_)
    elif kind == "LinearSVC":
        arrays.update(coef=model.coef_, intercept=model.intercept_)
        attrs["n_iter_"] = int(model.n_iter_)
    else:  # LDA
        for name in ("coef", "intercept", "means", "priors", "xbar", "scalings"):
            arrays[name] = getattr(model, f"{name}_")
        arrays["explained_variance_ratio"] = model.explained_variance_ratio_
        arrays["shrinkage"] = np.array(model.shrinkage_, dtype=np.float64)
        attrs["n_components_"] = int(model.n_components_)
    if hasattr(model, "classes_"):
        arrays["classes"] = np.asarray(model.classes_)
    return arrays, attrs


def _decode(kind: str, model: Any, a: _Arrays, d: int, attrs: dict[str, Any]) -> None:
    """Set the fitted attributes of the unfitted ``model`` from the file's arrays."""
    model.n_features_in_ = d
    c = 0
    if model._estimator_type == "classifier":
        model.classes_ = a.get("classes", "c", (None,))
        c = model.classes_.size
    if kind in ("DecisionTreeClassifier", "DecisionTreeRegressor"):
        (model.tree_,) = _get_trees(a, d, c or 1, 1)
        model.feature_importances_ = a.get("feature_importances", "f", (d,), 0.0)
    elif kind in ("RandomForestClassifier", "RandomForestRegressor"):
        model.estimators_ = _get_trees(a, d, c or 1, MAX_ESTIMATORS)
        model.feature_importances_ = a.get("feature_importances", "f", (d,), 0.0)
        if "oob_score_" in attrs:
            model.oob_score_ = _attr(a, attrs, "oob_score_", float)
    elif kind == "SVC":
        m = c * (c - 1) // 2
        sv = a.get("support_vectors", "f", (None, d))
        s = sv.shape[0]
        n_support = a.get("n_support", "i", (c,), 0, s + 1)
        if s < 1 or sum(n_support.tolist()) != s:
            raise a.fail(f"n_support does not sum to its {s} support vectors (1 or more)")
        index = a.get("machine_sv", "i", (None,), 0, s)
        total = index.size
        sizes = a.get("machine_sizes", "i", (m,), 0, total + 1)
        if sum(sizes.tolist()) != total:
            raise a.fail(f"machine_sizes do not add up to the {total} machine entries")
        coef = a.get("machine_coef", "f", (total,))
        intercept = a.get("intercept", "f", (m,))
        model.gamma_ = a.scalar("gamma", 0.0)
        model.support_ = a.get("support", "i", (s,), 0)
        model.support_vectors_ = sv
        model.n_support_ = n_support
        model.n_iter_ = a.get("n_iter", "i", (m,), 0)
        parts = [slice(e - n, e) for n, e in zip(sizes.tolist(), np.cumsum(sizes), strict=True)]
        model.machine_support_ = [index[q] for q in parts]
        model.dual_coef_ = [coef[q] for q in parts]
        model.intercept_ = intercept
        if "prob_a" in a.arrays or "prob_b" in a.arrays:
            model.probA_ = a.get("prob_a", "f", (m,))
            model.probB_ = a.get("prob_b", "f", (m,))
        if model.kernel == "linear":
            pairs = zip(model.machine_support_, model.dual_coef_, strict=True)
            model.coef_ = np.array([cf @ sv[i] for i, cf in pairs])
    elif kind == "LinearSVC":
        rows = 1 if c == 2 else c
        model.coef_ = a.get("coef", "f", (rows, d))
        model.intercept_ = a.get("intercept", "f", (rows,))
        model.n_iter_ = _attr(a, attrs, "n_iter_", int)
    else:  # LDA
        k_max = min(c - 1, d)
        model.coef_ = a.get("coef", "f", (c, d))
        model.intercept_ = a.get("intercept", "f", (c,))
        model.means_ = a.get("means", "f", (c, d))
        model.priors_ = a.get("priors", "f", (c,), 0.0)
        model.xbar_ = a.get("xbar", "f", (d,))
        model.scalings_ = a.get("scalings", "f", (d, None))
        model.explained_variance_ratio_ = a.get("explained_variance_ratio", "f", (k_max,))
        model.shrinkage_ = a.scalar("shrinkage", 0.0)
        k = _attr(a, attrs, "n_components_", int)
        if not 1 <= k <= min(k_max, model.scalings_.shape[1]):
            raise a.fail(f"it keeps {k} LDA components; expected 1 to {k_max}")
        model.n_components_ = k


def _attr(a: _Arrays, attrs: dict[str, Any], name: str, kind: type) -> Any:
    value = attrs.get(name)
    ok = isinstance(value, kind) and not isinstance(value, bool)
    if kind is float:
        ok = (
            isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        )
    if not ok:
        raise a.fail(f"its attribute {name} is {plain_repr(value)[:40]}; expected {kind.__name__}")
    return kind(value)


_KINDS: dict[str, type] = {
    cls.__name__: cls
    for cls in (
        DecisionTreeClassifier,
        DecisionTreeRegressor,
        RandomForestClassifier,
        RandomForestRegressor,
        SVC,
        LinearSVC,
        LDA,
    )
}
#: the estimators a model file can hold (class names)
MODEL_KINDS: tuple[str, ...] = tuple(_KINDS)
_FITTED = {
    "DecisionTreeClassifier": "tree_",
    "DecisionTreeRegressor": "tree_",
    "RandomForestClassifier": "estimators_",
    "RandomForestRegressor": "estimators_",
    "SVC": "support_vectors_",
    "LinearSVC": "coef_",
    "LDA": "coef_",
}
#: constructor arguments used when predicting, and what they may be
_PREDICT_PARAMS: dict[str, dict[str, Callable[[Any], bool]]] = {
    "SVC": {
        "kernel": lambda v: v in ("rbf", "linear", "poly"),
        "degree": lambda v: isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 1000,
        "coef0": lambda v: isinstance(v, (int, float)) and math.isfinite(v),
        "decision_function_shape": lambda v: v in ("ovr", "ovo"),
    },
    "RandomForestClassifier": {"voting": lambda v: v in ("hard", "soft")},
}


def _params(model: Any) -> dict[str, Any]:
    """The constructor arguments as JSON values; a Generator seed becomes null."""
    out: dict[str, Any] = {}
    for name, value in model.get_params(deep=False).items():
        if isinstance(value, (np.random.Generator, np.random.RandomState)):
            value = None  # a generator's state is not a setting: the fitted model is stored
        elif isinstance(value, np.integer):
            value = int(value)
        elif isinstance(value, np.floating):
            value = float(value)
        if not isinstance(value, _JSON_SCALARS) or (
            isinstance(value, float) and not math.isfinite(value)
        ):
            raise InputError(
                f"{type(model).__name__} parameter {name}={plain_repr(value)[:60]} cannot be "
                "saved: parameters must be None, bool, int, a finite float or str"
            )
        out[name] = value
    return out


# ---------------------------------------------------------------------- the bundle
@dataclass(frozen=True)
class SavedModel:
    r"""A fitted classifier (or regressor) with what it needs to be used on new tables.

    ``predict`` scales the rows as in training, :math:`x' = (x - \mu) / \sigma` when
    ``mean`` and ``scale`` are given, runs the model, and names the classes.

    Parameters
    ----------
    model : estimator
        Fitted; one of :data:`MODEL_KINDS` (:class:`DecisionTreeClassifier`,
        :class:`RandomForestClassifier`, :class:`SVC`, :class:`LinearSVC`,
        :class:`LDA`, and the two tree regressors).
    feature_names : sequence of str, optional
        The columns of a table the model takes, in order (distinct).
    class_names : sequence of str, optional
        Names of ``model.classes_`` in order (a model trained on integer codes);
        classifiers only.
    label_column : str, optional
        The column of the true classes in the training table.
    mean, scale : (d,) array_like, optional
        The standardization fitted on the training rows
        (:func:`~robopercept.learning.standard_scaling`); both or neither; scale > 0.
    info : dict, optional
        Anything JSON-serializable to keep with the model (the training file, a note).
    header : dict
        The JSON header it was loaded from (``robopercept_version``, ``format_version``;
        empty for a model that was not loaded).

    Examples
    --------
    >>> from robopercept.learning import LDA
    >>> X = np.array([[0.0], [0.2], [1.0], [1.2]])
    >>> saved = SavedModel(LDA().fit(X, [0, 0, 1, 1]), ["x"], ["small", "large"])
    >>> saved.predict(np.array([[0.1], [1.1]])).tolist()
    ['small', 'large']
    """

    model: Any
    feature_names: tuple[str, ...] | None = None
    class_names: tuple[str, ...] | None = None
    label_column: str | None = None
    mean: np.ndarray | None = None
    scale: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    header: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        model = self.model
        kind = type(model).__name__
        if _KINDS.get(kind) is not type(model):
            raise InputError(
                f"model must be one of {', '.join(MODEL_KINDS)} from robopercept.learning; "
                f"got {kind} {plain_repr(model)[:60]}"
            )
        if not hasattr(model, _FITTED[kind]) or not hasattr(model, "n_features_in_"):
            raise not_fitted_error(f"this {kind} is not fitted yet; call fit(X, y) before saving")
        d = int(model.n_features_in_)
        set_ = object.__setattr__
        if self.feature_names is not None:
            set_(self, "feature_names", _names(self.feature_names, "feature_names", d))
        if self.class_names is not None:
            if not hasattr(model, "classes_"):
                raise InputError(f"class_names are for classifiers; {kind} has no classes")
            c = int(np.asarray(model.classes_).size)
            set_(self, "class_names", _names(self.class_names, "class_names", c))
        if self.label_column is not None:
            check_text(self.label_column, "label_column")
        if (self.mean is None) != (self.scale is None):
            raise InputError("give both mean and scale (the standardization), or neither")
        if self.mean is not None and self.scale is not None:
            mean = check_matrix(np.reshape(self.mean, (1, -1)), "mean")[0]
            scale = check_matrix(np.reshape(self.scale, (1, -1)), "scale")[0]
            if mean.size != d or scale.size != d or not np.all(scale > 0):
                raise InputError(
                    f"mean and scale must be {d} numbers (one per feature), scale > 0; got "
                    f"{mean.size} and {scale.size}: use standard_scaling(X_train)"
                )
            set_(self, "mean", mean)
            set_(self, "scale", scale)
        if not isinstance(self.info, dict):
            raise InputError(f"info must be a dict; got {type(self.info).__name__}")
        try:
            json.dumps(self.info, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise InputError(f"info must be JSON-serializable: {exc}") from None

    @property
    def n_features(self) -> int:
        """Number of feature columns the model takes."""
        return int(self.model.n_features_in_)

    @property
    def labels(self) -> np.ndarray | None:
        """The class labels predictions are drawn from: ``class_names`` if given, else
        ``model.classes_``; None for a regressor."""
        if not hasattr(self.model, "classes_"):
            return None
        if self.class_names is not None:
            return np.array(self.class_names)
        return np.asarray(self.model.classes_)

    def transform(self, X: npt.ArrayLike) -> np.ndarray:
        """Rows ``X`` (N, d) as the model takes them: standardized when it was trained
        so."""
        X = check_matrix(X, "X")
        if X.shape[1] != self.n_features:
            raise InputError(
                f"X has {X.shape[1]} columns; the model takes {self.n_features}"
                + (f" ({', '.join(self.feature_names)})" if self.feature_names else "")
            )
        if self.mean is None or self.scale is None:
            return X
        return (X - self.mean) / self.scale

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Predicted labels of the rows ``X`` (N, d): class names when ``class_names``
        are known, else the model's own labels (targets for a regressor)."""
        pred = np.asarray(self.model.predict(self.transform(X)))
        if self.class_names is None:
            return pred
        return np.array(self.class_names)[np.searchsorted(self.model.classes_, pred)]


def _names(values: Any, name: str, count: int) -> tuple[str, ...]:
    if isinstance(values, str) or not isinstance(values, (list, tuple, np.ndarray)):
        raise InputError(f"{name} must be a list of str; got {plain_repr(values)[:60]}")
    out = tuple(values.tolist() if isinstance(values, np.ndarray) else values)
    if not all(isinstance(v, str) for v in out) or len(set(out)) != len(out):
        raise InputError(f"{name} must be distinct strings; got {plain_repr(values)[:60]}")
    if len(out) != count:
        raise InputError(f"{name} has {len(out)} entries; the model has {count}")
    return out


def save_model(model: Any, path: str | os.PathLike[str]) -> Path:
    """Write a fitted model to ``path`` (``.npz``): its arrays and a JSON header.

    The format is described in the module docstring; :func:`load_model` reads it
    back, and the loaded model predicts exactly (bit for bit) what ``model`` does.

    Parameters
    ----------
    model : SavedModel or estimator
        A :class:`SavedModel` (with feature and class names, the standardization), or a
        bare fitted estimator of :data:`MODEL_KINDS`.
    path : path-like
        Ends in ``.npz``; an existing file is replaced.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        Not a supported fitted estimator, ``path`` without the ``.npz`` extension, a
        parameter that JSON cannot hold, classes of dtype object.
    FileFormatError
        The file cannot be written (no such folder, no permission).
    NotFittedError
        ``model`` is not fitted.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.learning import DecisionTreeClassifier
    >>> X, y = np.array([[0.0], [1.0], [2.0], [3.0]]), np.array([0, 0, 1, 1])
    >>> tree = DecisionTreeClassifier().fit(X, y)
    >>> p = save_model(tree, pathlib.Path(tempfile.mkdtemp()) / "tree.npz")
    >>> load_model(p).model.predict(X).tolist()
    [0, 0, 1, 1]
    """
    saved = model if isinstance(model, SavedModel) else SavedModel(model)
    p = check_extension(path, {".npz"}, "a model file")
    if p.is_dir():
        raise InputError(f"{p} is a folder; give a file name ending in .npz")
    est = saved.model
    arrays, attrs = _encode(est)
    classes = arrays.get("classes")
    if classes is not None and classes.dtype.kind not in "biufU":
        raise InputError(
            f"the model's classes_ have dtype {classes.dtype}, which cannot be saved without "
            "pickle: train it on str or int labels (or on codes, with class_names)"
        )
    if saved.mean is not None and saved.scale is not None:
        arrays["standardize_mean"], arrays["standardize_scale"] = saved.mean, saved.scale
    header = {
        "format": _FORMAT,
        "format_version": FORMAT_VERSION,
        "robopercept_version": __version__,
        "kind": type(est).__name__,
        "params": _params(est),
        "n_features": saved.n_features,
        "feature_names": list(saved.feature_names) if saved.feature_names else None,
        "class_names": list(saved.class_names) if saved.class_names else None,
        "label_column": saved.label_column,
        "standardized": saved.mean is not None,
        "attributes": attrs,
        "info": saved.info,
    }
    meta = np.array(json.dumps(header, allow_nan=False))
    try:
        with p.open("wb") as fh:
            np.savez(fh, meta=meta, **arrays)  # type: ignore[arg-type]  # names are array keys
    except OSError as exc:
        raise FileFormatError(
            f"{p}: cannot write ({exc.strerror or exc}): check that its folder exists"
        ) from exc
    return p


def load_model(path: str | os.PathLike[str]) -> SavedModel:
    """Read a model written by :func:`save_model`; nothing in the file is executed.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    SavedModel
        ``.model`` is the fitted estimator; it predicts exactly what the saved one did.

    Raises
    ------
    FileFormatError
        Missing file or a folder; not a robopercept model file (another ``.npz``, a
        pickle, a CSV...); a file written by a newer robopercept (format version above
        :data:`FORMAT_VERSION`); a truncated or damaged file; an array of the wrong
        dtype or shape, with NaN/inf or an index out of range. The message names the file
        and the problem.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "junk.npz"
    >>> _ = p.write_bytes(b"not a model")
    >>> load_model(p)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: ...junk.npz is not a robopercept model file...
    """
    what = "a robopercept model file (.npz written by save_model or `learn classify --save`)"
    p = check_file(path, what)
    arrays = read_npz(p, what)
    a = _Arrays(p, arrays)
    meta = arrays.get("meta")
    if meta is None or meta.ndim != 0 or meta.dtype.kind != "U":
        raise FileFormatError(f"{p} is not {what}: it has no JSON header (meta)")
    try:
        header = json.loads(str(meta))
    except (ValueError, RecursionError):
        raise FileFormatError(f"{p} is not {what}: its header is not valid JSON") from None
    if not isinstance(header, dict) or header.get("format") != _FORMAT:
        got = header.get("format") if isinstance(header, dict) else None
        raise FileFormatError(f"{p} is not {what}: its format is {plain_repr(got)[:40]}")
    version = header.get("format_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise a.fail(f"format_version is {plain_repr(version)[:40]}")
    if version > FORMAT_VERSION:
        raise FileFormatError(
            f"{p}: written by a newer robopercept (model format {version}, robopercept "
            f"{plain_repr(header.get('robopercept_version'))[:20]}); this one ({__version__}) "
            f"reads format {FORMAT_VERSION}: upgrade robopercept"
        )
    kind = header.get("kind")
    cls = _KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None or not isinstance(kind, str):
        raise a.fail(
            f"its kind is {plain_repr(kind)[:40]}; expected one of {', '.join(MODEL_KINDS)}"
        )
    d = header.get("n_features")
    if not isinstance(d, int) or isinstance(d, bool) or not 1 <= d <= _MAX_FEATURES:
        raise a.fail(f"n_features is {plain_repr(d)[:40]}")
    model = cls(**_load_params(a, cls, kind, header.get("params")))
    attrs = header.get("attributes")
    if not isinstance(attrs, dict):
        raise a.fail("its attributes are not a JSON object")
    _decode(kind, model, a, d, attrs)
    mean = scale = None
    standardized = header.get("standardized")
    if not isinstance(standardized, bool):
        raise a.fail(f"standardized is {plain_repr(standardized)[:40]}; expected true or false")
    if standardized:
        mean = a.get("standardize_mean", "f", (d,))
        scale = a.get("standardize_scale", "f", (d,))
        if not np.all(scale > 0):
            raise a.fail("its standardize_scale holds values <= 0")
    label = header.get("label_column")
    if label is not None and not isinstance(label, str):
        raise a.fail(f"label_column is {plain_repr(label)[:40]}")
    info = header.get("info", {})
    if not isinstance(info, dict):
        raise a.fail("its info is not a JSON object")
    names: dict[str, tuple[str, ...] | None] = {}
    for key in ("feature_names", "class_names"):
        value = header.get(key)
        if value is not None and not isinstance(value, list):
            raise a.fail(f"{key} is {plain_repr(value)[:40]}; expected a list of names")
        names[key] = None if value is None else tuple(value)
    try:
        return SavedModel(model, label_column=label, mean=mean, scale=scale, info=info,
                          header=header, **names)  # fmt: skip
    except InputError as exc:  # names that do not fit the model
        raise a.fail(str(exc)) from None


def _load_params(a: _Arrays, cls: type, kind: str, params: Any) -> dict[str, Any]:
    if not isinstance(params, dict):
        raise a.fail("its params are not a JSON object")
    known = set(cls._param_names())  # type: ignore[attr-defined]
    for name, value in params.items():
        if name not in known:
            raise a.fail(f"{kind} has no parameter {name[:40]!r}")
        if not isinstance(value, _JSON_SCALARS):
            raise a.fail(f"parameter {name} is {plain_repr(value)[:40]}; expected a plain value")
    for name, ok in _PREDICT_PARAMS.get(kind, {}).items():
        if name in params and not ok(params[name]):
            raise a.fail(f"parameter {name} is {plain_repr(params[name])[:40]}")
    return params


# ------------------------------------------------------------------- predict a table
@dataclass(frozen=True)
class TablePrediction:
    """What :func:`predict_table` found.

    Attributes
    ----------
    predictions : (N,) ndarray
        One label per row of the table, in file order.
    truth : (N,) str ndarray or None
        The table's label column, when it has one.
    label : str or None
        Its name.
    hits : (N,) bool ndarray or None
        Whether each prediction equals the truth (None without truth, or for a
        regressor).
    unknown : int or None
        Rows whose true class the model does not know (always counted wrong).
    """

    predictions: np.ndarray
    truth: np.ndarray | None = None
    label: str | None = None
    hits: np.ndarray | None = None
    unknown: int | None = None

    @property
    def correct(self) -> int | None:
        """Number of rows predicted right (None without truth)."""
        return None if self.hits is None else int(np.count_nonzero(self.hits))

    @property
    def accuracy(self) -> float | None:
        """Share of rows predicted right, :math:`\\frac1N \\sum_i [\\hat y_i = y_i]`."""
        return None if self.hits is None else float(np.mean(self.hits))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures: ``rows``, ``counts`` (predictions per label), ``label``,
        ``accuracy``, ``correct``, ``unknown_labels`` and ``predictions``."""
        values, counts = np.unique(self.predictions, return_counts=True)
        return {
            "rows": int(self.predictions.size),
            "counts": {str(v): int(n) for v, n in zip(values.tolist(), counts, strict=True)},
            "label": self.label,
            "accuracy": self.accuracy,
            "correct": self.correct,
            "unknown_labels": self.unknown,
            "predictions": self.predictions.tolist(),
        }

    def write_csv(self, path: str | os.PathLike[str]) -> Path:
        """Write one ``prediction`` per row (in the table's order) to a CSV file; with
        the truth, also its column (named as in the table) and ``correct`` (1 or 0).

        Parameters
        ----------
        path : path-like

        Returns
        -------
        Path

        Raises
        ------
        FileFormatError
            The file cannot be written (no such folder, no permission).
        """
        p = as_path(path, "the path of the predictions CSV")
        rows: list[list[Any]] = [[v] for v in self.predictions.tolist()]
        head = ["prediction"]
        if self.hits is not None and self.truth is not None:
            head += [self.label or "label", "correct"]
            truth = self.truth.tolist()
            rows = [[r[0], t, int(h)] for r, t, h in zip(rows, truth, self.hits, strict=True)]
        try:
            with p.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(head)
                w.writerows(rows)
        except OSError as exc:
            raise FileFormatError(
                f"{p}: cannot write the predictions ({exc.strerror or exc}): check that its "
                "folder exists"
            ) from exc
        return p


def _comparable(values: np.ndarray, like: np.ndarray) -> np.ndarray:
    """Label text ``values`` as ``like``'s dtype when that is numeric and they parse,
    else both as text (so "2" equals class 2 and "2.0")."""
    if like.dtype.kind in "iuf":
        try:
            return values.astype(np.float64)
        except ValueError:
            pass
    return values.astype(str)


def predict_table(
    model: SavedModel, path: str | os.PathLike[str], label: str | None = None
) -> TablePrediction:
    """Predict every row of a CSV table, and score the predictions when the table has
    the true classes.

    The model's feature columns are taken by name (other columns are ignored; a
    missing one is an error naming it); a model saved without feature names takes
    every column but ``label``, which must then be as many as it has features.

    Parameters
    ----------
    model : SavedModel
        From :func:`load_model`.
    path : path-like
        CSV with a header row.
    label : str, optional
        The column of true classes, which must then exist; by default the model's
        ``label_column``, used when present. Accuracy :math:`= \\frac1N \\sum_i [\\hat y_i = y_i]`.

    Returns
    -------
    TablePrediction

    Raises
    ------
    InputError
        A feature column missing or not numeric, empty cells (NaN), a row count that
        does not fit.
    FileFormatError
        Not a CSV table (:func:`~robopercept.learning.read_table`).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from robopercept.learning import LDA
    >>> X = np.array([[0.0], [0.2], [1.0], [1.2]])
    >>> saved = SavedModel(LDA().fit(X, [0, 0, 1, 1]), ["x"], ["lo", "hi"], "kind")
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("x,kind\\n0.1,lo\\n1.1,lo\\n")
    >>> r = predict_table(saved, p)
    >>> r.predictions.tolist(), r.accuracy
    (['lo', 'hi'], 0.5)
    """
    if not isinstance(model, SavedModel):
        raise InputError(
            f"model must be a SavedModel (load_model's result); got {type(model).__name__}"
        )
    p = check_file(path, "a CSV file")
    if label is not None:
        label = check_text(label, "label (the --label column)")
        if label not in (header := _csv_header(p)):
            raise InputError(f"{p}: no column {label!r}; columns are {', '.join(header)}")
    label = label if label is not None else model.label_column
    if model.feature_names is not None:
        X, y = read_features(p, list(model.feature_names), label)
    else:
        has_label = label is not None and label in _csv_header(p)
        X, y, names = read_table(p, label if has_label else None)
        if X.shape[1] != model.n_features:
            raise InputError(
                f"{p} has {X.shape[1]} feature columns ({', '.join(names)}); the model "
                f"takes {model.n_features}"
            )
    pred = model.predict(X)
    if y is None:
        return TablePrediction(pred)
    labels = model.labels
    if labels is None:  # a regressor: no accuracy
        return TablePrediction(pred, y, label)
    truth = _comparable(y, labels)
    hits = truth == pred.astype(truth.dtype)
    unknown = int(np.count_nonzero(~np.isin(truth, labels.astype(truth.dtype))))
    return TablePrediction(pred, y, label, hits, unknown)


def _csv_header(p: Path) -> list[str]:
    """The column names of a CSV file (its first non-empty row, names stripped)."""
    try:
        with p.open(newline="") as fh:
            for row in csv.reader(fh):
                if row:
                    return [h.strip() for h in row]
    except (UnicodeDecodeError, csv.Error):
        raise FileFormatError(f"{p}: not a text CSV file") from None
    return []
