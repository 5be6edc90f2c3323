"""The estimator contract shared by every learner: scikit-learn's, without scikit-learn.

An estimator stores its constructor arguments unchanged under the same names, learns in
``fit`` (which returns ``self``) and keeps what it learned in attributes ending in ``_``.
:meth:`Estimator.get_params` and :meth:`Estimator.set_params` read and write the
constructor arguments, so :func:`clone`, :class:`~robopercept.learning.GridSearch` and
scikit-learn's own ``clone``, ``Pipeline``, ``cross_val_score`` and ``GridSearchCV``
work with our estimators. scikit-learn is imported only inside
:meth:`Estimator.__sklearn_tags__`, which only scikit-learn calls.
"""

from __future__ import annotations

import copy
import inspect
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import as_rng
from robopercept.errors import InputError, NotFittedError

__all__ = ["ClassifierMixin", "Estimator", "RegressorMixin", "TransformerMixin", "clone"]


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
    def _check_fitted(self, attribute: str) -> None:
        if not hasattr(self, attribute):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet; call fit(X, y) before "
                "predicting or transforming"
            )

    def _check_X(self, X: npt.ArrayLike, *, fitting: bool = False) -> npt.NDArray[np.float64]:
        X = check_matrix(X, "X")
        if fitting:
            self.n_features_in_ = X.shape[1]
        elif X.shape[1] != self.n_features_in_:
            raise InputError(
                f"X has {X.shape[1]} features but {type(self).__name__} was fitted with "
                f"{self.n_features_in_}; pass data with the same columns as in fit"
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
        """Mean accuracy of ``predict(X)`` against ``y``."""
        return float(np.mean(self.predict(X) == np.asarray(y)))  # type: ignore[attr-defined]

    def _encode_labels(self, y: npt.ArrayLike, n_samples: int) -> np.ndarray:
        y = np.asarray(y)
        if y.ndim != 1 or y.shape[0] != n_samples:
            raise InputError(f"y must be a 1-D array of {n_samples} labels; got shape {y.shape}")
        if y.dtype.kind == "f" and not np.all(np.isfinite(y)):
            raise InputError("y contains NaN or inf; drop or relabel those samples")
        classes, codes = np.unique(y, return_inverse=True)
        if classes.size < 2:
            raise InputError(
                f"a classifier needs samples of at least 2 classes; y has only {classes.tolist()}"
            )
        self.classes_ = classes
        return codes.astype(np.int64)


class RegressorMixin:
    """``score`` is the coefficient of determination R^2."""

    _estimator_type: str | None = "regressor"

    def score(self, X: npt.ArrayLike, y: npt.ArrayLike) -> float:
        r"""R^2 = 1 - \sum (y - \hat y)^2 / \sum (y - \bar y)^2."""
        y = np.asarray(y, dtype=np.float64)
        pred = self.predict(X)  # type: ignore[attr-defined]
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
    """``X`` as a C-contiguous float64 ``(n_samples, n_features)`` array without NaN/inf."""
    try:
        arr = np.asarray(X)
    except Exception as exc:  # ragged lists
        raise InputError(f"{name} must be a 2-D numeric array; {exc}") from None
    if arr.ndim == 1:
        raise InputError(
            f"{name} must be 2-D (n_samples, n_features); got 1-D shape {arr.shape}: "
            f"one feature? use {name}.reshape(-1, 1); one sample? use {name}.reshape(1, -1)"
        )
    if arr.ndim != 2:
        raise InputError(f"{name} must be 2-D (n_samples, n_features); got shape {arr.shape}")
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name} must be numeric; got dtype {arr.dtype}")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise InputError(f"{name} is empty (shape {arr.shape}); give at least one sample")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise InputError(
            f"{name} contains NaN or inf in {bad} sample(s); drop or impute them before fitting"
        )
    return arr


def check_target(y: npt.ArrayLike, n_samples: int) -> np.ndarray:
    """Regression target as finite float64 of length ``n_samples``."""
    y = np.asarray(y)
    if y.ndim != 1 or y.shape[0] != n_samples:
        raise InputError(f"y must be a 1-D array of {n_samples} values; got shape {y.shape}")
    if y.dtype.kind not in "biuf":
        raise InputError(f"y must be numeric for a regressor; got dtype {y.dtype}")
    y = y.astype(np.float64)
    if not np.all(np.isfinite(y)):
        raise InputError("y contains NaN or inf; drop those samples")
    return y


def seed_from(rng: int | np.integer | np.random.Generator | None) -> np.random.Generator:
    """A fresh Generator from the estimator's ``rng`` parameter, without consuming it.

    An int seed gives the same stream on every ``fit``; a Generator is copied so that
    fitting twice gives the same model (and cloning keeps determinism).
    """
    if isinstance(rng, np.random.Generator):
        return copy.deepcopy(rng)
    return as_rng(rng)
