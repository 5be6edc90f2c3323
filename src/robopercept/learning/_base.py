"""The estimator contract shared by every learner: scikit-learn's, without scikit-learn.

An estimator stores its constructor arguments unchanged under the same names, learns in
``fit`` (which returns ``self``) and keeps what it learned in attributes ending in ``_``.
:meth:`Estimator.get_params` and :meth:`Estimator.set_params` read and write the
constructor arguments, so :func:`clone`, :class:`~robopercept.learning.GridSearch` and
scikit-learn's own ``clone``, ``Pipeline``, ``cross_val_score`` and ``GridSearchCV``
work with our estimators. scikit-learn is imported only inside
:meth:`Estimator.__sklearn_tags__`, which only scikit-learn calls; when scikit-learn is
already loaded, "not fitted" errors are also instances of its ``NotFittedError`` (see
:func:`not_fitted_error`), so code written for scikit-learn catches them.

Randomness: every learner takes ``random_state`` (scikit-learn's name and contract: an
int seed, ``None``, a ``numpy.random.Generator`` or a legacy ``RandomState``). The
former name ``rng=`` is still accepted for one release with a ``DeprecationWarning``
(:func:`renamed_rng`).

Input checks follow scikit-learn's wording where its ``check_estimator`` looks for it
("Reshape your data", "0 feature(s) (shape=...) while a minimum of 1 is required",
"Complex data not supported", "X has 1 features, but PCA is expecting 4 features as
input", "Unknown label type: continuous", "requires y to be passed"), and add the fix.
Sparse matrices are refused with a message that names ``X.toarray()``; ``object``
arrays are converted to float64 when every element is a number (pandas' mixed columns),
else a ``TypeError`` names the element type.
"""

from __future__ import annotations

import copy
import inspect
import sys
import warnings
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_choice, check_int, check_magnitude, plain_repr
from robopercept.errors import InputError, NotFittedError

__all__ = [
    "MAX_ITER",
    "ClassifierMixin",
    "DataConversionWarning",
    "Estimator",
    "RegressorMixin",
    "TransformerMixin",
    "check_max_iter",
    "check_option",
    "clone",
]

#: largest iteration count the compiled solvers take (they count in int64)
MAX_ITER = 2**62

RandomStateLike = int | np.integer | np.random.Generator | np.random.RandomState | None


class DataConversionWarning(UserWarning):
    """Input data were converted to the expected form (a column-vector ``y`` raveled);
    the name and message of scikit-learn's warning of the same name."""


class Estimator:
    """Base class: parameters, cloning, representation and scikit-learn tags."""

    _estimator_type: str | None = None  # "classifier", "regressor", "clusterer", "transformer"

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return sorted(
            p.name
            for p in sig.parameters.values()
            if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
        )

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments by name (``deep``: also ``step__param`` of nested ones)."""
        out: dict[str, Any] = {}
        for name in self._param_names():
            value = getattr(self, name)
            if deep and hasattr(value, "get_params") and not isinstance(value, type):
                out.update((f"{name}__{k}", v) for k, v in value.get_params().items())
            out[name] = value
        return out

    def set_params(self, **params: Any) -> Estimator:
        """Set constructor arguments (``name=value`` or ``nested__name=value``); returns self."""
        valid = self._param_names()
        nested: dict[str, dict[str, Any]] = {}
        for key, value in params.items():
            name, _, sub = key.partition("__")
            if name not in valid:
                raise InputError(
                    f"{type(self).__name__} has no parameter {name!r}; valid ones: {valid}"
                )
            if sub:
                nested.setdefault(name, {})[sub] = value
            else:
                setattr(self, name, value)
        for name, sub_params in nested.items():
            getattr(self, name).set_params(**sub_params)
        return self

    def __repr__(self) -> str:
        sig = inspect.signature(type(self).__init__)
        shown = []
        for name in self._param_names():
            default = sig.parameters[name].default
            value = getattr(self, name)
            same = default is not inspect.Parameter.empty and _same(value, default)
            if not same:
                shown.append(f"{name}={value!r}")
        return f"{type(self).__name__}({', '.join(shown)})"

    def __sklearn_tags__(self) -> Any:
        """scikit-learn's tags (imported here: only scikit-learn calls this)."""
        from sklearn.utils import (
            ClassifierTags,
            InputTags,
            RegressorTags,
            Tags,
            TargetTags,
            TransformerTags,
        )

        kind = self._estimator_type
        supervised = kind in ("classifier", "regressor")
        return Tags(
            estimator_type=kind if kind in ("classifier", "regressor", "clusterer") else None,
            target_tags=TargetTags(required=supervised),
            transformer_tags=TransformerTags() if hasattr(self, "transform") else None,
            classifier_tags=ClassifierTags() if kind == "classifier" else None,
            regressor_tags=RegressorTags() if kind == "regressor" else None,
            input_tags=InputTags(),
        )

    # -- helpers for subclasses -------------------------------------------------------
    def _random_state(self, stacklevel: int = 4) -> Any:
        # random_state, or the deprecated rng parameter (warned here, at fit time, as
        # scikit-learn deprecates parameters: the constructor only stores them);
        # stacklevel 4 points the warning at the user's fit() call when fit calls this
        rs = getattr(self, "random_state", None)
        rng = getattr(self, "rng", None)
        return renamed_rng(type(self).__name__, rs, rng, stacklevel=stacklevel)

    def _check_fitted(self, attribute: str) -> None:
        if not hasattr(self, attribute):
            raise not_fitted_error(
                f"this {type(self).__name__} is not fitted yet; call fit(X, y) before "
                "predicting or transforming"
            )

    def _check_X(self, X: npt.ArrayLike, *, fitting: bool = False) -> npt.NDArray[np.float64]:
        X = check_matrix(X, "X")
        if fitting:
            self.n_features_in_ = X.shape[1]
        elif X.shape[1] != self.n_features_in_:
            raise InputError(
                f"X has {X.shape[1]} features, but {type(self).__name__} is expecting "
                f"{self.n_features_in_} features as input (as in fit); pass data with the "
                "same columns as in fit"
            )
        return X


def _same(a: object, b: object) -> bool:
    try:
        return bool(a is b or (type(a) is type(b) and a == b))
    except (ValueError, TypeError):  # arrays
        return False


class ClassifierMixin:
    """``score`` is the accuracy."""

    _estimator_type: str | None = "classifier"

    def score(self, X: npt.ArrayLike, y: npt.ArrayLike) -> float:
        """Mean accuracy of ``predict(X)`` against ``y`` (one label per row of ``X``)."""
        pred = np.asarray(self.predict(X))  # type: ignore[attr-defined]
        y = _target_vector(y, pred.shape[0], type(self).__name__, "labels of the rows of X")
        return float(np.mean(pred == y))

    def _encode_labels(self, y: npt.ArrayLike, n_samples: int) -> np.ndarray:
        y = _target_vector(y, n_samples, type(self).__name__, "labels")
        if y.dtype.kind == "c":
            raise InputError("y is complex: Complex data not supported; pass real class labels")
        if y.dtype.kind == "f":
            if not np.all(np.isfinite(y)):
                raise InputError("y contains NaN or inf; drop or relabel those samples")
            if not np.all(y == np.round(y)):
                raise InputError(
                    "Unknown label type: continuous. y holds non-integer numbers, a "
                    "regression target? Use a regressor, or pass class labels "
                    "(e.g. np.digitize(y, bins) or y.astype(int))"
                )
        try:
            classes, codes = np.unique(y, return_inverse=True)
        except TypeError as exc:  # object labels that cannot be ordered (mixed types)
            raise InputError(
                f"Unknown label type: y mixes types that cannot be sorted ({exc}); "
                "pass labels of one type (all str or all int)"
            ) from None
        if classes.size < 2:
            raise InputError(
                f"a classifier needs samples of at least 2 classes; y has only 1 class "
                f"({classes.tolist()}): add samples of another class"
            )
        self.classes_ = classes
        return codes.reshape(-1).astype(np.int64)


class RegressorMixin:
    """``score`` is the coefficient of determination R^2."""

    _estimator_type: str | None = "regressor"

    def score(self, X: npt.ArrayLike, y: npt.ArrayLike) -> float:
        r"""R^2 = 1 - \sum (y - \hat y)^2 / \sum (y - \bar y)^2 (one target per row of
        ``X``)."""
        pred = self.predict(X)  # type: ignore[attr-defined]
        y = check_target(y, pred.shape[0], type(self).__name__)
        check_magnitude(y, "y", 1e150)  # squared below
        ss_res = float(np.sum((y - pred) ** 2))
        ss_tot = float(np.sum((y - y.mean()) ** 2))
        return 1.0 - ss_res / ss_tot if ss_tot > 0 else 0.0


class TransformerMixin:
    """``fit_transform`` = ``fit`` then ``transform``."""

    def fit_transform(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> np.ndarray:
        return self.fit(X, y).transform(X)  # type: ignore[attr-defined]


class ClusterMixin:
    """``fit_predict`` returns ``labels_``."""

    _estimator_type: str | None = "clusterer"

    def fit_predict(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> np.ndarray:
        return self.fit(X).labels_  # type: ignore[attr-defined]


def clone(estimator: Any) -> Any:
    """A new unfitted estimator with the same parameters (nested estimators cloned too)."""
    if isinstance(estimator, (list, tuple)):
        return type(estimator)(clone(e) for e in estimator)
    if not hasattr(estimator, "get_params") or isinstance(estimator, type):
        return copy.deepcopy(estimator)
    params = {k: clone(v) for k, v in estimator.get_params(deep=False).items()}
    return type(estimator)(**params)


def check_matrix(X: npt.ArrayLike, name: str = "X") -> npt.NDArray[np.float64]:
    """``X`` as a C-contiguous float64 ``(n_samples, n_features)`` array without NaN/inf.

    Refused with the fix in the message: sparse matrices (``X.toarray()``), 1-D arrays
    (``reshape``), complex numbers, empty arrays, NaN/inf. ``object`` arrays holding
    numbers are converted; one holding anything else raises ``TypeError``.

    Parameters
    ----------
    X : (N, d) array_like
    name : str
        The argument's name in messages.

    Returns
    -------
    (N, d) float64 ndarray
    """
    if _is_sparse(X):
        raise InputError(
            f"{name} is a sparse {type(X).__name__}: robopercept learners take dense "
            f"arrays (sparse input is not supported); call {name}.toarray() first"
        )
    try:
        arr = np.asarray(X)
    except Exception as exc:  # ragged lists
        raise InputError(f"{name} must be a 2-D numeric array; {exc}") from None
    if arr.ndim == 1:
        raise InputError(
            f"{name} must be 2-D (n_samples, n_features); got 1-D shape {arr.shape}. "
            f"Reshape your data: {name}.reshape(-1, 1) if it is one feature, "
            f"{name}.reshape(1, -1) if it is one sample"
        )
    if arr.ndim != 2:
        raise InputError(f"{name} must be 2-D (n_samples, n_features); got shape {arr.shape}")
    if arr.dtype.kind == "O":
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise TypeError(
                f"{name} has dtype object with an element that is not a number ({exc}); "
                "convert the columns to numbers first (e.g. pandas.to_numeric, or "
                "one-hot encode text columns)"
            ) from None
    if arr.dtype.kind == "c":
        raise InputError(
            f"{name} has dtype {arr.dtype}: Complex data not supported; pass real "
            f"features, e.g. np.c_[{name}.real, {name}.imag] or np.abs({name})"
        )
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name} must be numeric; got dtype {arr.dtype}")
    if arr.shape[0] == 0:
        raise InputError(
            f"{name} is empty: 0 sample(s) (shape={arr.shape}) while a minimum of 1 is "
            "required; give at least one sample"
        )
    if arr.shape[1] == 0:
        raise InputError(
            f"{name} is empty: 0 feature(s) (shape={arr.shape}) while a minimum of 1 is "
            "required; give at least one feature column"
        )
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise InputError(
            f"{name} contains NaN or inf in {bad} sample(s); drop or impute them before fitting"
        )
    return arr


def _is_sparse(X: object) -> bool:
    # scipy.sparse matrices and arrays, without importing scipy.sparse
    sparse = sys.modules.get("scipy.sparse")
    return sparse is not None and bool(sparse.issparse(X))


def _target_vector(y: npt.ArrayLike | None, n_samples: int, owner: str, what: str) -> np.ndarray:
    # y as a 1-D array of n_samples; a column vector is raveled with scikit-learn's warning
    if y is None:
        raise InputError(
            f"{owner} requires y to be passed, but the target y is None: call fit(X, y) "
            f"with the {what}"
        )
    if _is_sparse(y):
        raise InputError("y is sparse: sparse input is not supported; call y.toarray().ravel()")
    try:
        arr = np.asarray(y)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise InputError(f"y must be a 1-D array of {n_samples} {what}; {exc}") from None
    if arr.ndim == 2 and arr.shape[1] == 1:
        warnings.warn(
            # no quotes in the text: scikit-learn's check reads the warning's repr
            "A column-vector y was passed when a 1d array was expected: y.ravel() is "
            "used; pass a 1-D y (y.ravel(); with pandas a Series, not a 1-column DataFrame)",
            sklearn_twin(DataConversionWarning, "DataConversionWarning"),
            stacklevel=4,
        )
        arr = arr.ravel()
    if arr.ndim != 1 or arr.shape[0] != n_samples:
        raise InputError(f"y must be a 1-D array of {n_samples} {what}; got shape {arr.shape}")
    return arr


def check_target(y: npt.ArrayLike, n_samples: int, owner: str = "this regressor") -> np.ndarray:
    """Regression target as finite float64 of length ``n_samples``.

    A ``(n_samples, 1)`` column is raveled with a :class:`DataConversionWarning`;
    ``object`` arrays of numbers are converted.

    Parameters
    ----------
    y : (N,) array_like
    n_samples : int
    owner : str
        The estimator's name in messages.

    Returns
    -------
    (N,) float64 ndarray
    """
    y = _target_vector(y, n_samples, owner, "target values")
    if y.dtype.kind == "O":
        try:
            y = y.astype(np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"Unknown label type: y of dtype object holds non-numbers ({exc}); a "
                "regressor needs numeric targets"
            ) from None
    if y.dtype.kind == "c":
        raise InputError("y is complex: Complex data not supported; pass real targets")
    if y.dtype.kind not in "biuf":
        raise InputError(f"y must be numeric for a regressor; got dtype {y.dtype}")
    y = y.astype(np.float64)
    if not np.all(np.isfinite(y)):
        raise InputError("y contains NaN or inf; drop those samples")
    return y


def random_generator(
    random_state: RandomStateLike, name: str = "random_state"
) -> np.random.Generator:
    """``random_state`` as a NumPy Generator (consumed, as scikit-learn consumes one).

    An int seed or None (fresh entropy) makes a new Generator; a Generator is returned
    as it is; a legacy ``RandomState`` seeds a new Generator from one draw of it.

    Parameters
    ----------
    random_state : int, Generator, RandomState or None
    name : str
        The parameter's name in messages.

    Returns
    -------
    numpy.random.Generator
    """
    if isinstance(random_state, np.random.Generator):
        return random_state
    if isinstance(random_state, np.random.RandomState):
        return np.random.default_rng(int(random_state.randint(0, 2**63 - 1, dtype=np.int64)))
    if random_state is None or (
        isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool)
    ):
        if random_state is not None and random_state < 0:
            raise InputError(f"{name} must be an int seed >= 0; got {random_state}")
        return np.random.default_rng(random_state)
    raise InputError(
        f"{name} must be an int seed, None, a numpy.random.Generator or a RandomState; "
        f"got {random_state!r}"
    )


def seed_from(random_state: RandomStateLike) -> np.random.Generator:
    """A fresh Generator from an estimator's ``random_state``, without consuming it.

    An int seed gives the same stream on every ``fit``; a Generator or RandomState is
    copied first, so that fitting twice gives the same model (and cloning keeps
    determinism).

    Parameters
    ----------
    random_state : int, Generator, RandomState or None

    Returns
    -------
    numpy.random.Generator
    """
    if isinstance(random_state, (np.random.Generator, np.random.RandomState)):
        return random_generator(copy.deepcopy(random_state))
    return random_generator(random_state)


def renamed_rng(
    owner: str, random_state: Any, rng: Any, *, default: Any = None, stacklevel: int = 3
) -> Any:
    """``random_state``, or the value of the deprecated alias ``rng`` if one was given.

    ``rng=`` was the name of the seed before the learners took scikit-learn's
    ``random_state``; it still works for one release, with a ``DeprecationWarning``.
    Giving both (``random_state`` other than its ``default``) is an error.

    Parameters
    ----------
    owner : str
        The class or function, for messages.
    random_state, rng
        The two arguments as passed (``rng=None``: not given).
    default
        ``random_state``'s default.
    stacklevel : int
        For :func:`warnings.warn`, so that the warning points at the user's call.

    Returns
    -------
    object
        The seed to use.
    """
    if rng is None:
        return random_state
    warnings.warn(
        f"{owner}: rng= is deprecated and will be removed in the next release; use "
        "random_state= (scikit-learn's name for the seed)",
        DeprecationWarning,
        stacklevel=stacklevel,
    )
    if random_state is not default:
        raise InputError(f"{owner}: give random_state only (rng is its deprecated alias)")
    return rng


_SKLEARN_TWINS: dict[tuple[type, type], type] = {}


def sklearn_twin(cls: type, name: str) -> type:
    """``cls``, or, when scikit-learn is loaded, a subclass of ``cls`` and of
    ``sklearn.exceptions.<name>`` (cached), so that code and warning filters written for
    scikit-learn's class catch ours. scikit-learn is never imported here.

    Parameters
    ----------
    cls : type
        Our exception or warning class.
    name : str
        The scikit-learn class of the same meaning in ``sklearn.exceptions``.

    Returns
    -------
    type
    """
    sk = sys.modules.get("sklearn.exceptions")
    base = getattr(sk, name, None) if sk is not None else None
    if not isinstance(base, type) or issubclass(cls, base):
        return cls
    twin = _SKLEARN_TWINS.get((cls, base))
    if twin is None:
        twin = type(
            cls.__name__,
            (cls, base),
            {
                "__doc__": cls.__doc__,
                "__module__": cls.__module__,
                # pickles (to worker processes) as our own class
                "__reduce__": lambda self: (cls, self.args),
            },
        )
        _SKLEARN_TWINS[(cls, base)] = twin
    return twin


def not_fitted_error(message: str) -> NotFittedError:
    """A :class:`~robopercept.errors.NotFittedError`; when scikit-learn is loaded, also an
    instance of ``sklearn.exceptions.NotFittedError`` (scikit-learn's ``check_estimator``
    and code that catches scikit-learn's class expect that one).

    Parameters
    ----------
    message : str

    Returns
    -------
    NotFittedError
    """
    error: NotFittedError = sklearn_twin(NotFittedError, "NotFittedError")(message)
    return error


def check_option(value: Any, name: str, choices: tuple[str, ...]) -> str:
    """Return the string option ``value`` after checking that it is one of ``choices``.

    :func:`~robopercept._checks.check_choice` after refusing anything that is not a
    ``str`` (an array would make ``value in choices`` ambiguous).

    Parameters
    ----------
    value : str
    name : str
        The parameter named in the message.
    choices : tuple of str

    Returns
    -------
    str

    Raises
    ------
    InputError
        Not one of ``choices``.
    """
    if not isinstance(value, str):
        raise InputError(
            f"{name} must be one of {', '.join(map(repr, choices))}; got "
            f"{type(value).__name__} {plain_repr(value)[:60]}"
        )
    return str(check_choice(value, name, choices))


def check_max_iter(value: Any, name: str = "max_iter") -> int:
    """Return an iteration limit: an integer in ``1..MAX_ITER``.

    Parameters
    ----------
    value : int
    name : str

    Returns
    -------
    int

    Raises
    ------
    InputError
        Not an integer, below 1 or beyond :data:`MAX_ITER`.
    """
    n = check_int(value, name, 1)
    if n > MAX_ITER:
        raise InputError(f"{name} must be in 1..2**62; got {n}")
    return n
