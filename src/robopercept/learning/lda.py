r"""Fisher's linear discriminant analysis.

With classes :math:`C_i` of :math:`n_i` samples, class means :math:`m_i` and overall
mean :math:`m`, the within-class and between-class scatter matrices are

.. math::

    S_W = \sum_i \sum_{x \in C_i} (x - m_i)(x - m_i)^\top, \qquad
    S_B = \sum_i n_i (m_i - m)(m_i - m)^\top .

The projection :math:`W` maximizes :math:`|W^\top S_B W| / |W^\top S_W W|`; its columns
are the generalized eigenvectors :math:`S_B w = \lambda S_W w` with the largest
eigenvalues, normalized so that :math:`W^\top S_W W / N = I`. :math:`S_B` has rank at
most :math:`c - 1`, so at most :math:`c - 1` directions carry information. When
:math:`S_W` is singular (constant features, fewer samples than features) it is
shrunk toward a multiple of the identity,
:math:`S_W \leftarrow (1 - \alpha) S_W + \alpha \,\tfrac{\operatorname{tr} S_W}{d} I`.

``predict`` uses the Gaussian rule with a shared covariance
:math:`\Sigma = S_W / N` and class priors :math:`\pi_i = n_i / N`: the class maximizing
:math:`\delta_i(x) = x^\top \Sigma^{-1} m_i - \tfrac12 m_i^\top \Sigma^{-1} m_i +
\log \pi_i` (scikit-learn's rule; with equal priors it is the nearest class mean in
the Mahalanobis metric, i.e. in the full whitened discriminant space).

Matches ``sklearn.discriminant_analysis.LinearDiscriminantAnalysis(solver="eigen")``:
the same directions up to sign and scale per axis, and the same predictions.
``transform`` centres by the overall mean first (scikit-learn's eigen solver does not).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.linalg import eigh

from robopercept._checks import check_int, check_magnitude, check_real
from robopercept.errors import InputError
from robopercept.learning._base import ClassifierMixin, Estimator, TransformerMixin

__all__ = ["LDA"]


class LDA(ClassifierMixin, TransformerMixin, Estimator):
    """Linear discriminant analysis: projection and classifier.

    Parameters
    ----------
    n_components : int or None
        Dimensions kept by ``transform``, at most ``min(c - 1, d)`` (the default).
    shrinkage : float in [0, 1] or None
        :math:`\\alpha` above. ``None``: 0 when :math:`S_W` is well conditioned, else
        1e-6 (just enough to make it invertible); the value used is ``shrinkage_``.

    Attributes
    ----------
    scalings_ : (d, d') ndarray
        Discriminant directions as columns, by decreasing eigenvalue.
    n_components_ : int
        Directions ``transform`` keeps (``n_components`` resolved).
    explained_variance_ratio_ : (c - 1,) ndarray
        Each direction's share of the between-class variance.
    means_ : (c, d) ndarray
    priors_ : (c,) ndarray
    coef_ : (c, d) ndarray, intercept_ : (c,) ndarray
        The linear Gaussian rule.
    classes_ : (c,) ndarray
    """

    def __init__(self, n_components: int | None = None, shrinkage: float | None = None) -> None:
        self.n_components = n_components
        self.shrinkage = shrinkage

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> LDA:
        """Estimate the scatter matrices and solve the generalized eigenproblem."""
        # scatter matrices square X: beyond 1e150 they overflow, below 1e-150 vanish
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150, smallest=1e-150)
        if self.n_components is not None:
            check_int(self.n_components, "n_components (or None)", 1)
        if self.shrinkage is not None:
            check_real(self.shrinkage, "shrinkage (or None)", 0.0, 1.0)
        codes = self._encode_labels(y, X.shape[0])
        n, d = X.shape
        c = self.classes_.size
        counts = np.bincount(codes, minlength=c).astype(np.float64)
        means = np.zeros((c, d))
        np.add.at(means, codes, X)
        means /= counts[:, None]
        overall = X.mean(axis=0)
        within = X - means[codes]
        Sw = within.T @ within / n
        Sb = ((means - overall).T * counts) @ (means - overall) / n
        alpha = self._shrinkage(Sw)
        if alpha > 0:
            Sw = (1 - alpha) * Sw + alpha * np.trace(Sw) / d * np.eye(d)
        try:
            evals, evecs = eigh(Sb, Sw)
        except np.linalg.LinAlgError:
            raise InputError(
                "the within-class scatter is singular; pass shrinkage (e.g. 1e-4)"
            ) from None
        order = np.argsort(evals)[::-1]
        evals, evecs = evals[order], evecs[:, order]
        max_k = min(c - 1, d)
        k = max_k if self.n_components is None else int(self.n_components)
        if not 1 <= k <= max_k:
            raise InputError(
                f"n_components={self.n_components} must be between 1 and min(classes - 1, "
                f"features) = {max_k}"
            )
        self.shrinkage_ = alpha
        self.means_ = means
        self.priors_ = counts / n
        self.xbar_ = overall
        self.scalings_ = evecs
        pos = np.clip(evals[:max_k], 0, None)
        self.explained_variance_ratio_ = pos / pos.sum() if pos.sum() > 0 else pos
        self.coef_ = (means @ evecs) @ evecs.T
        self.intercept_ = -0.5 * np.sum(self.coef_ * means, axis=1) + np.log(self.priors_)
        self.n_components_ = k
        return self

    def _shrinkage(self, Sw: np.ndarray) -> float:
        if self.shrinkage is not None:
            a = float(self.shrinkage)
            if not 0.0 <= a <= 1.0:
                raise InputError(f"shrinkage must be in [0, 1]; got {a}")
            return a
        ev = np.linalg.eigvalsh(Sw)
        return 0.0 if ev[0] > 1e-12 * max(ev[-1], 1e-300) else 1e-6

    def transform(self, X: npt.ArrayLike) -> np.ndarray:
        """Project ``(X - mean)`` onto the first ``n_components`` directions."""
        self._check_fitted("scalings_")
        X = self._check_X(X)
        return (X - self.xbar_) @ self.scalings_[:, : self.n_components_]

    def decision_function(self, X: npt.ArrayLike) -> np.ndarray:
        """:math:`\\delta_i(x)` for every class, ``(N, c)`` (``(N,)`` for two classes)."""
        self._check_fitted("coef_")
        X = self._check_X(X)
        scores = X @ self.coef_.T + self.intercept_
        return scores[:, 1] - scores[:, 0] if self.classes_.size == 2 else scores

    def predict_proba(self, X: npt.ArrayLike) -> np.ndarray:
        """Posterior class probabilities under the Gaussian model, ``(N, c)``."""
        self._check_fitted("coef_")
        X = self._check_X(X)
        s = X @ self.coef_.T + self.intercept_
        s -= s.max(axis=1, keepdims=True)
        p = np.exp(s)
        return p / p.sum(axis=1, keepdims=True)

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """The class with the largest :math:`\\delta_i(x)`."""
        self._check_fitted("coef_")
        X = self._check_X(X)
        return self.classes_[np.argmax(X @ self.coef_.T + self.intercept_, axis=1)]
