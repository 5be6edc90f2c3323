r"""Principal component analysis.

With the samples :math:`x_i \in \mathbb{R}^d` centred by their mean :math:`\mu` (and,
with ``standardize=True``, divided by their standard deviation :math:`\sigma`), the
sample covariance is

.. math::

    C = \frac{1}{N-1} \sum_i (x_i - \mu)(x_i - \mu)^\top = V \Lambda V^\top ,

and the principal components are the eigenvectors :math:`v_k` (the columns of
:math:`V`) sorted by decreasing eigenvalue :math:`\lambda_k`, the variance of the data
along :math:`v_k`. ``transform`` projects, :math:`z = V_k^\top (x - \mu)`;
``inverse_transform`` maps back, :math:`\hat x = \mu + V_k z`, the closest point in the
span of the first :math:`k` components. The explained variance ratio is
:math:`\lambda_k / \sum_j \lambda_j`.

Matches ``sklearn.decomposition.PCA`` (which takes the SVD of the centred data; the
same :math:`V` and :math:`\lambda`), including its sign rule: each component is
flipped so that its largest-magnitude entry is positive.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_bool, check_magnitude
from robopercept.errors import InputError
from robopercept.learning._base import Estimator, TransformerMixin

__all__ = ["PCA"]


class PCA(TransformerMixin, Estimator):
    """Principal component analysis by eigendecomposition of the covariance.

    Parameters
    ----------
    n_components : int, float in (0, 1) or None
        Number of components; a fraction keeps the fewest components whose explained
        variance reaches it; ``None`` keeps ``min(N, d)``.
    standardize : bool
        Divide every feature by its standard deviation (population, ddof 0, like
        ``StandardScaler``) before the covariance, i.e. PCA of the correlation matrix.
        Constant features are left unscaled.

    Attributes
    ----------
    components_ : (k, d) ndarray
        Unit principal axes, rows, by decreasing variance.
    explained_variance_ : (k,) ndarray
        Eigenvalues :math:`\\lambda_k` of the covariance (ddof 1).
    explained_variance_ratio_ : (k,) ndarray
    mean_, scale_ : (d,) ndarray
    n_components_ : int
    """

    def __init__(self, n_components: int | float | None = None, standardize: bool = False) -> None:
        self.n_components = n_components
        self.standardize = standardize

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike | None = None) -> PCA:
        """Learn the mean, the scale and the components of ``X`` (N, d)."""
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150, smallest=1e-150)
        n, d = X.shape
        if n < 2:
            raise InputError(
                f"PCA needs at least 2 samples to estimate a covariance; got {n} sample(s)"
            )
        self.mean_ = X.mean(axis=0)
        Xc = X - self.mean_
        if check_bool(self.standardize, "standardize"):
            std = Xc.std(axis=0)
            self.scale_ = np.where(std > 0, std, 1.0)
            Xc = Xc / self.scale_
        else:
            self.scale_ = np.ones(d)
        cov = (Xc.T @ Xc) / (n - 1)
        evals, evecs = np.linalg.eigh(cov)
        evals, evecs = evals[::-1].clip(min=0.0), evecs[:, ::-1]
        total = evals.sum()
        ratio = evals / total if total > 0 else np.zeros_like(evals)
        k = self._count(ratio, min(n, d))
        comps = evecs[:, :k].T
        # sign rule (scikit-learn's svd_flip on Vt): the largest |entry| of each row > 0
        big = np.argmax(np.abs(comps), axis=1)
        signs = np.sign(comps[np.arange(k), big])
        comps = comps * np.where(signs == 0, 1.0, signs)[:, None]
        self.components_ = comps
        self.explained_variance_ = evals[:k]
        self.explained_variance_ratio_ = ratio[:k]
        self.n_components_ = k
        return self

    def _count(self, ratio: np.ndarray, limit: int) -> int:
        nc = self.n_components
        if nc is None:
            return limit
        if isinstance(nc, bool) or not isinstance(nc, (int, np.integer, float, np.floating)):
            raise InputError(f"n_components must be an int, a fraction or None; got {nc!r}")
        if isinstance(nc, (float, np.floating)) and not float(nc).is_integer():
            if not 0.0 < nc < 1.0:
                raise InputError(f"n_components as a variance fraction must be in (0, 1); got {nc}")
            return int(min(np.searchsorted(np.cumsum(ratio), nc, side="right") + 1, limit))
        k = int(nc)
        if not 1 <= k <= limit:
            raise InputError(
                f"n_components={k} must be between 1 and min(n_samples, n_features) = {limit}"
            )
        return k

    def transform(self, X: npt.ArrayLike) -> np.ndarray:
        """Coordinates of ``X`` along the components, ``(N, k)``."""
        self._check_fitted("components_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        return ((X - self.mean_) / self.scale_) @ self.components_.T

    def inverse_transform(self, Z: npt.ArrayLike) -> np.ndarray:
        """Points in the input space from component coordinates ``Z`` (N, k)."""
        self._check_fitted("components_")
        Z = np.asarray(Z, dtype=np.float64)
        if Z.ndim != 2 or Z.shape[1] != self.n_components_:
            raise InputError(f"Z must be (N, {self.n_components_}); got shape {Z.shape}")
        return (Z @ self.components_) * self.scale_ + self.mean_
