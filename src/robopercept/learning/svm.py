r"""Support vector machines: the kernel SVC (SMO) and a linear fast path.

A soft-margin SVM separates two classes :math:`y_i \in \{-1, +1\}` with the decision
function :math:`f(x) = \sum_i \alpha_i y_i K(x_i, x) + b`, where :math:`\alpha` solves
the dual quadratic programme

.. math::

    \min_\alpha \tfrac12 \alpha^\top Q \alpha - \mathbf 1^\top \alpha
    \quad \text{s.t.} \quad 0 \le \alpha_i \le C,\; y^\top \alpha = 0,
    \qquad Q_{ij} = y_i y_j K(x_i, x_j).

The samples with :math:`\alpha_i > 0` are the support vectors. Kernels:
``"linear"`` :math:`x \cdot z`; ``"rbf"`` :math:`\exp(-\gamma \lVert x - z \rVert^2)`;
``"poly"`` :math:`(\gamma\, x \cdot z + r)^d`. ``gamma="scale"`` is
:math:`1 / (M \operatorname{var}(X))`, ``"auto"`` is :math:`1 / M`.

:class:`SVC` solves the dual by sequential minimal optimization (Platt, 1998) with the
second-order working-set selection of Fan, Chen and Lin (2005), libsvm's algorithm:
each step picks the pair :math:`(i, j)` that violates the optimality conditions most,
:math:`i = \arg\max_{t \in I_{up}} -y_t \nabla_t` and :math:`j` the one whose
analytic two-variable update lowers the objective most, updates both in closed form
(clipped to the box), and stops when the violation
:math:`\max_{I_{up}} -y \nabla - \min_{I_{low}} -y \nabla` is below ``tol``. The
bias is the mean of :math:`y_i \nabla_i` over the free support vectors. Several
classes are handled one-vs-one (a machine per pair of classes, prediction by votes;
``decision_function`` gives scikit-learn's one-vs-rest shaped scores by default).

**Probabilities** (``SVC(probability=True)``, libsvm's and so scikit-learn's method).
For each one-vs-one machine (classes :math:`a < b`) the decision values of its training
samples are measured by 5-fold cross-validation (a machine trained on four fifths of
the pair's samples, with the same kernel and C, scores the fifth; the folds are a
random permutation drawn from ``random_state``), and Platt's sigmoid

.. math::

    r_{ab}(x) = P(a \mid a \text{ or } b, x) = \frac{1}{1 + \exp(A f_{ab}(x) + B)}

(:math:`f_{ab}` the machine's decision value, positive for :math:`a`: minus
``decision_function`` for two classes, the ``"ovo"`` column for more) is fitted to
them by Newton's method with backtracking on the regularized cross-entropy with
targets :math:`(N_+ + 1)/(N_+ + 2)` and :math:`1/(N_- + 2)` (Lin, Lin and Weng, 2007).
Cross-validated rather than training decision values, because the training values of
the support vectors sit at the margin by construction and would make the sigmoid
over-confident. Two classes: :math:`p = (r_{ab}, 1 - r_{ab})`. More: the pairwise
:math:`r_{ij}` (clipped to :math:`[10^{-7}, 1 - 10^{-7}]`) are coupled by Wu, Lin and
Weng's (2004) second method, :math:`\min_p p^\top Q p` subject to
:math:`\sum_i p_i = 1` with :math:`Q_{ii} = \sum_{j \ne i} r_{ji}^2`,
:math:`Q_{ij} = -r_{ji} r_{ij}`, solved exactly from its linear KKT system (libsvm
iterates to a tolerance of 0.005 / c). As in scikit-learn, the probabilities come from a
separate model and can disagree with ``predict`` near the boundary, and the random
folds make them depend on ``random_state``; ``decision_function`` and ``predict`` do
not.

:class:`LinearSVC` is the fast path for the linear kernel: dual coordinate descent
(Hsieh et al., 2008, liblinear's solver) on the primal weight vector :math:`w`,
one-vs-rest, with the hinge or squared hinge loss.

Matches ``sklearn.svm.SVC`` (same dual, same stopping rule) and ``LinearSVC``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import check_bool, check_int, check_magnitude, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.learning._base import (
    ClassifierMixin,
    Estimator,
    RandomStateLike,
    check_max_iter,
    check_option,
    not_fitted_error,
    seed_from,
)

__all__ = ["SVC", "LinearSVC", "kernel_matrix"]

_TAU = 1e-12


def kernel_matrix(
    A: np.ndarray, B: np.ndarray, kernel: str, gamma: float, degree: int, coef0: float
) -> np.ndarray:
    """:math:`K(a_i, b_j)` for all pairs, ``(len(A), len(B))``."""
    G = A @ B.T
    if kernel == "linear":
        return G
    if kernel == "poly":
        return (gamma * G + coef0) ** degree
    a2 = np.einsum("ij,ij->i", A, A)
    b2 = np.einsum("ij,ij->i", B, B)
    G *= -2.0
    G += a2[:, None]
    G += b2[None, :]
    np.maximum(G, 0.0, out=G)
    G *= -gamma
    return np.exp(G, out=G)


@njit(cache=True, nogil=True)
def _smo(K: np.ndarray, y: np.ndarray, C: float, tol: float, max_iter: int):
    """libsvm's solver on the kernel matrix ``K`` (n, n) and labels ``y`` in {-1, +1}.

    Returns (alpha, b, iterations)."""
    n = y.size
    alpha = np.zeros(n)
    G = -np.ones(n)  # gradient of the dual objective, Q alpha - 1
    QD = np.empty(n)
    for t in range(n):
        QD[t] = K[t, t]
    it = 0
    while it < max_iter:
        # select i: the most violating index in I_up
        gmax = -np.inf
        i = -1
        for t in range(n):
            if y[t] > 0:
                if alpha[t] < C and -G[t] >= gmax:
                    gmax = -G[t]
                    i = t
            else:
                if alpha[t] > 0 and G[t] >= gmax:
                    gmax = G[t]
                    i = t
        if i < 0:
            break
        # select j: the largest second-order decrease in I_low
        gmax2 = -np.inf
        j = -1
        best = np.inf
        for t in range(n):
            qit = y[i] * y[t] * K[i, t]
            if y[t] > 0:
                if alpha[t] > 0:
                    diff = gmax + G[t]
                    if G[t] >= gmax2:
                        gmax2 = G[t]
                    if diff > 0:
                        quad = QD[i] + QD[t] - 2.0 * y[i] * qit
                        obj = -(diff * diff) / (quad if quad > 0 else _TAU)
                        if obj <= best:
                            j = t
                            best = obj
            else:
                if alpha[t] < C:
                    diff = gmax - G[t]
                    if -G[t] >= gmax2:
                        gmax2 = -G[t]
                    if diff > 0:
                        quad = QD[i] + QD[t] + 2.0 * y[i] * qit
                        obj = -(diff * diff) / (quad if quad > 0 else _TAU)
                        if obj <= best:
                            j = t
                            best = obj
        if gmax + gmax2 < tol or j < 0:
            break
        it += 1
        qij = y[i] * y[j] * K[i, j]
        old_i = alpha[i]
        old_j = alpha[j]
        if y[i] != y[j]:
            quad = QD[i] + QD[j] + 2.0 * qij
            if quad <= 0:
                quad = _TAU
            delta = (-G[i] - G[j]) / quad
            diff = alpha[i] - alpha[j]
            alpha[i] += delta
            alpha[j] += delta
            if diff > 0:
                if alpha[j] < 0:
                    alpha[j] = 0.0
                    alpha[i] = diff
            else:
                if alpha[i] < 0:
                    alpha[i] = 0.0
                    alpha[j] = -diff
            if diff > 0:
                if alpha[i] > C:
                    alpha[i] = C
                    alpha[j] = C - diff
            else:
                if alpha[j] > C:
                    alpha[j] = C
                    alpha[i] = C + diff
        else:
            quad = QD[i] + QD[j] - 2.0 * qij
            if quad <= 0:
                quad = _TAU
            delta = (G[i] - G[j]) / quad
            total = alpha[i] + alpha[j]
            alpha[i] -= delta
            alpha[j] += delta
            if total > C:
                if alpha[i] > C:
                    alpha[i] = C
                    alpha[j] = total - C
            else:
                if alpha[j] < 0:
                    alpha[j] = 0.0
                    alpha[i] = total
            if total > C:
                if alpha[j] > C:
                    alpha[j] = C
                    alpha[i] = total - C
            else:
                if alpha[i] < 0:
                    alpha[i] = 0.0
                    alpha[j] = total
        di = (alpha[i] - old_i) * y[i]
        dj = (alpha[j] - old_j) * y[j]
        for t in range(n):
            G[t] += y[t] * (K[i, t] * di + K[j, t] * dj)
    # bias: -rho, rho the mean of y G over free vectors (else the middle of the bounds)
    n_free = 0
    s_free = 0.0
    ub = np.inf
    lb = -np.inf
    for t in range(n):
        yg = y[t] * G[t]
        if alpha[t] >= C:
            if y[t] < 0:
                ub = min(ub, yg)
            else:
                lb = max(lb, yg)
        elif alpha[t] <= 0:
            if y[t] > 0:
                ub = min(ub, yg)
            else:
                lb = max(lb, yg)
        else:
            n_free += 1
            s_free += yg
    rho = s_free / n_free if n_free > 0 else 0.5 * (ub + lb)
    return alpha, -rho, it


_FOLDS = 5  # libsvm's cross-validation folds for the probability model
_MIN_PROB = 1e-7  # libsvm's clip of the pairwise probabilities


def _machine(K: np.ndarray, y: np.ndarray, C: float, tol: float, max_iter: int) -> tuple:
    """Train one binary machine on the kernel matrix ``K``; returns (alpha y, bias)."""
    alpha, bias, _ = _smo(np.ascontiguousarray(K), y, C, tol, max_iter)
    return alpha * y, bias


def _cv_decisions(
    K: np.ndarray,
    y: np.ndarray,
    C: float,
    tol: float,
    max_iter: int,
    rng: np.random.Generator,
    folds: int = _FOLDS,
) -> np.ndarray:
    """Decision values of each sample from a machine that did not see it (libsvm's
    ``svm_binary_svc_probability``).

    The samples are shuffled by ``rng`` and cut into ``folds`` contiguous folds
    (``i N / folds`` to ``(i + 1) N / folds``); each fold is scored by a machine trained
    on the others. A fold whose training part holds one class only gets +1 or -1 (its
    class's sign), and 0 when it is empty, as libsvm does.

    Parameters
    ----------
    K : (N, N) ndarray
        Kernel matrix of the samples.
    y : (N,) ndarray
        Labels in {-1, +1}.
    C, tol, max_iter
        As :class:`SVC`.
    rng : numpy.random.Generator
    folds : int

    Returns
    -------
    (N,) ndarray
        Decision values, positive for the +1 class.
    """
    n = y.size
    perm = rng.permutation(n)
    out = np.zeros(n)
    for i in range(folds):
        test = perm[i * n // folds : (i + 1) * n // folds]
        train = np.setdiff1d(perm, test, assume_unique=True)
        pos = int((y[train] > 0).sum())
        neg = train.size - pos
        if pos == 0 or neg == 0:
            out[test] = 0.0 if train.size == 0 else (1.0 if neg == 0 else -1.0)
            continue
        coef, bias = _machine(K[np.ix_(train, train)], y[train], C, tol, max_iter)
        out[test] = K[np.ix_(test, train)] @ coef + bias
    return out


def _sigmoid_loss(dec: np.ndarray, t: np.ndarray, A: float, B: float) -> float:
    """Cross-entropy of targets ``t`` under :math:`p = 1 / (1 + e^{A f + B})`."""
    z = dec * A + B
    # t log(1 + e^-z) ... written stably for both signs of z: -t log p - (1-t) log(1-p)
    return float(np.sum(t * z + np.logaddexp(0.0, -z)))


def _platt_sigmoid(dec: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    r"""Fit Platt's sigmoid :math:`P(+1 \mid f) = 1 / (1 + \exp(A f + B))` to decision
    values (libsvm's ``sigmoid_train``: Lin, Lin and Weng, 2007).

    Minimizes the cross-entropy with the regularized targets
    :math:`t_+ = (N_+ + 1) / (N_+ + 2)`, :math:`t_- = 1 / (N_- + 2)` by Newton's method
    (Hessian plus :math:`10^{-12} I`) with a backtracking line search (sufficient
    decrease :math:`10^{-4}`), from :math:`A = 0`, :math:`B = \log((N_- + 1) / (N_+ + 1))`,
    stopping when both gradient entries are below :math:`10^{-5}` (100 steps at most).

    Parameters
    ----------
    dec : (N,) ndarray
        Decision values.
    y : (N,) ndarray
        Labels in {-1, +1}.

    Returns
    -------
    A, B : float
        ``A`` is negative when large decision values mean the +1 class.

    Examples
    --------
    >>> A, B = _platt_sigmoid(np.array([-2.0, -1.0, -0.5, 0.5, 1.0, 2.0]),
    ...                      np.array([-1, -1, 1, -1, 1, 1]))
    >>> bool(A < 0), round(float(1 / (1 + np.exp(A * 2.0 + B))), 2)
    (True, 0.78)
    """
    pos = float((y > 0).sum())
    neg = float(y.size) - pos
    t = np.where(y > 0, (pos + 1.0) / (pos + 2.0), 1.0 / (neg + 2.0))
    A, B = 0.0, float(np.log((neg + 1.0) / (pos + 1.0)))
    fval = _sigmoid_loss(dec, t, A, B)
    for _ in range(100):
        z = dec * A + B
        p = np.exp(-np.logaddexp(0.0, z))  # 1 / (1 + e^z), stably
        d2 = p * (1.0 - p)
        h11 = 1e-12 + float(np.sum(dec * dec * d2))
        h22 = 1e-12 + float(np.sum(d2))
        h21 = float(np.sum(dec * d2))
        d1 = t - p
        g1 = float(np.sum(dec * d1))
        g2 = float(np.sum(d1))
        if abs(g1) < 1e-5 and abs(g2) < 1e-5:
            break
        det = h11 * h22 - h21 * h21
        dA = -(h22 * g1 - h21 * g2) / det
        dB = -(-h21 * g1 + h11 * g2) / det
        gd = g1 * dA + g2 * dB
        step = 1.0
        while step >= 1e-10:
            new_a, new_b = A + step * dA, B + step * dB
            new_f = _sigmoid_loss(dec, t, new_a, new_b)
            if new_f < fval + 1e-4 * step * gd:
                A, B, fval = new_a, new_b, new_f
                break
            step /= 2.0
        else:  # the line search failed: keep the last good point, as libsvm
            break
    return A, B


def _couple_pairwise(r: np.ndarray) -> np.ndarray:
    r"""Class probabilities from pairwise ones (Wu, Lin and Weng, 2004, method 2;
    libsvm's ``multiclass_probability``).

    Solves :math:`\min_p p^\top Q p` subject to :math:`\sum_i p_i = 1`, with
    :math:`Q_{ii} = \sum_{j \ne i} r_{ji}^2` and :math:`Q_{ij} = -r_{ji} r_{ij}`, from
    the linear system :math:`\begin{pmatrix} Q & 1 \\ 1^\top & 0 \end{pmatrix}
    \binom{p}{b} = \binom{0}{1}` (its solution is non-negative; libsvm reaches it by
    an iteration stopped at a tolerance of 0.005 / c).

    Parameters
    ----------
    r : (N, c, c) ndarray
        :math:`r_{ij} = P(i \mid i \text{ or } j)`, with :math:`r_{ji} = 1 - r_{ij}`
        and entries in (0, 1); the diagonal is ignored.

    Returns
    -------
    (N, c) ndarray
        Rows sum to 1.

    Examples
    --------
    >>> r = np.array([[[0, 0.5, 0.5], [0.5, 0, 0.5], [0.5, 0.5, 0]]])
    >>> _couple_pairwise(r).round(6).tolist()
    [[0.333333, 0.333333, 0.333333]]
    """
    n, c, _ = r.shape
    off = ~np.eye(c, dtype=bool)
    rt = np.swapaxes(r, 1, 2)  # rt[:, i, j] = r[:, j, i]
    Q = np.where(off, -rt * r, 0.0)
    Q[:, np.arange(c), np.arange(c)] = np.where(off, rt**2, 0.0).sum(axis=2)
    M = np.zeros((n, c + 1, c + 1))
    M[:, :c, :c] = Q
    M[:, :c, c] = 1.0
    M[:, c, :c] = 1.0
    rhs = np.zeros((n, c + 1, 1))
    rhs[:, c] = 1.0
    p = np.linalg.solve(M, rhs)[:, :c, 0]
    p = np.clip(p, 0.0, None)  # rounding only: the exact solution is non-negative
    return p / p.sum(axis=1, keepdims=True)


class _IfProbability:
    """``predict_proba`` exists only on an :class:`SVC` with ``probability=True`` that is
    unfitted or fitted with its probability model (scikit-learn's ``available_if``):
    otherwise the attribute raises :class:`~robopercept.errors.NotFittedError`, an
    ``AttributeError``, so ``hasattr(svc, "predict_proba")`` is False and code that
    prefers probabilities falls back to ``decision_function``."""

    def __init__(self, fn: Callable[..., np.ndarray]) -> None:
        self.fn = fn
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self.fn
        # NotFittedError is an AttributeError (hasattr() is False) and a typed error
        p = getattr(obj, "probability", False)
        if not (isinstance(p, (bool, np.bool_)) and bool(p)):
            raise not_fitted_error(
                f"predict_proba is not available when probability={plain_repr(p)[:40]}: "
                "build SVC(probability=True) before fit, or use decision_function"
            )
        if hasattr(obj, "support_vectors_") and not hasattr(obj, "probA_"):
            raise not_fitted_error(
                "predict_proba is not available: this SVC was fitted without its probability "
                "model (probability=False at fit, or loaded from a file without it); fit "
                "it again with probability=True, or use decision_function"
            )
        return self.fn.__get__(obj, owner)


def _gamma(gamma: float | str, X: np.ndarray) -> float:
    if isinstance(gamma, str) and gamma == "scale":
        var = float(X.var())
        return 1.0 / (X.shape[1] * var) if var > 0 else 1.0
    if isinstance(gamma, str) and gamma == "auto":
        return 1.0 / X.shape[1]
    if isinstance(gamma, str):
        raise InputError(f"gamma must be 'scale', 'auto' or a positive number; got {gamma!r}")
    return check_real(gamma, "gamma (or 'scale', 'auto')", 0.0, low_inclusive=False)


class SVC(ClassifierMixin, Estimator):
    """Kernel support vector classifier (soft margin, SMO, one-vs-one).

    Parameters
    ----------
    C : float
        Box constraint: the price of a margin violation.
    kernel : {"rbf", "linear", "poly"}
    gamma : "scale", "auto" or float
    degree : int
        Degree of the polynomial kernel.
    coef0 : float
        :math:`r` of the polynomial kernel.
    tol : float
        Stop when the largest violation of the optimality conditions is below it.
    max_iter : int or None
        SMO steps per machine (None: ``max(10^7, 100 N)``, libsvm's bound).
    decision_function_shape : {"ovr", "ovo"}
    probability : bool
        Also fit the probability model (Platt scaling on 5-fold cross-validated
        decision values, coupled over the pairs; see the module docstring), which
        enables :meth:`predict_proba`, as ``sklearn.svm.SVC(probability=True)`` (which
        scikit-learn 1.9 deprecates for ``CalibratedClassifierCV(SVC(),
        ensemble=False)``; it stays here). Fitting trains 5 more machines per pair.
    random_state : int, Generator, RandomState or None
        Seed of the cross-validation folds of the probability model (unused without
        ``probability``), scikit-learn's name.

    Attributes
    ----------
    support_ : (S,) ndarray
        Indices of the support vectors in the training data (sorted by class).
    support_vectors_ : (S, d) ndarray
    n_support_ : (c,) ndarray
    dual_coef_ : list of (machine pairs) -> arrays of :math:`\\alpha_i y_i`
    machine_support_ : list of (machine pairs) -> int arrays
        Rows of ``support_vectors_`` that each one-vs-one machine's ``dual_coef_``
        weighs (pairs in ``itertools.combinations`` order of the classes).
    intercept_ : (c (c - 1) / 2,) ndarray
    gamma_ : float
        The kernel's :math:`\\gamma` as used (``"scale"``, ``"auto"`` resolved).
    coef_ : (c (c - 1) / 2, d) ndarray, linear kernel only
    classes_ : (c,) ndarray
    probA_, probB_ : (c (c - 1) / 2,) ndarray, with ``probability=True`` only
        The sigmoid :math:`1 / (1 + \\exp(A f_{ab} + B))` of each pair of classes
        (scikit-learn's names and orientation).

    Examples
    --------
    >>> X = np.array([[0.0], [0.3], [0.6], [0.9], [2.0], [2.3], [2.6], [2.9]] * 2)
    >>> y = np.array([0, 0, 0, 0, 1, 1, 1, 1] * 2)
    >>> svc = SVC(probability=True, random_state=0).fit(X, y)
    >>> p = svc.predict_proba([[0.0], [1.45], [3.0]])
    >>> p.shape, bool(p[0, 0] > 0.5 > p[2, 0]), np.allclose(p.sum(axis=1), 1.0)
    ((3, 2), True, True)
    """

    def __init__(
        self,
        C: float = 1.0,
        kernel: str = "rbf",
        gamma: str | float = "scale",
        degree: int = 3,
        coef0: float = 0.0,
        tol: float = 1e-3,
        max_iter: int | None = None,
        decision_function_shape: str = "ovr",
        probability: bool = False,
        random_state: RandomStateLike = None,
    ) -> None:
        self.C = C
        self.kernel = kernel
        self.gamma = gamma
        self.degree = degree
        self.coef0 = coef0
        self.tol = tol
        self.max_iter = max_iter
        self.decision_function_shape = decision_function_shape
        self.probability = probability
        self.random_state = random_state

    def _kernel(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        return kernel_matrix(A, B, self.kernel, self.gamma_, int(self.degree), float(self.coef0))

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> SVC:
        """Train one machine per pair of classes on ``X`` (N, d), ``y`` (N,)."""
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150, smallest=1e-150)
        codes = self._encode_labels(y, X.shape[0])
        C = check_real(self.C, "C", 0.0, low_inclusive=False)
        tol = check_real(self.tol, "tol", 0.0, low_inclusive=False)
        check_option(self.kernel, "kernel", ("rbf", "linear", "poly"))
        check_option(self.decision_function_shape, "decision_function_shape", ("ovr", "ovo"))
        check_int(self.degree, "degree", 1)
        check_real(self.coef0, "coef0")
        probability = check_bool(self.probability, "probability")
        rng = seed_from(self._random_state())
        n = X.shape[0]
        max_iter = max(10_000_000, 100 * n) if self.max_iter is None else self.max_iter
        max_iter = check_max_iter(max_iter)
        self.gamma_ = _gamma(self.gamma, X)
        with np.errstate(over="ignore", invalid="ignore"):  # refused just below
            K = self._kernel(X, X)
        if not np.isfinite(K).all():
            raise InputError(
                f"the {self.kernel} kernel of X overflows (values beyond 1e308): rescale X "
                "(e.g. StandardScaler) or lower gamma, coef0 or degree"
            )
        c = self.classes_.size
        pairs = list(itertools.combinations(range(c), 2))
        machines = []
        used = np.zeros(n, dtype=bool)
        self.n_iter_ = np.zeros(len(pairs), dtype=np.int64)
        sigmoids = []
        for k, (a, b) in enumerate(pairs):
            # binary: classes_[1] positive; one-vs-one: the first class of the pair
            pos = b if c == 2 else a
            idx = np.flatnonzero((codes == a) | (codes == b))
            yy = np.where(codes[idx] == pos, 1.0, -1.0)
            alpha, bias, iters = _smo(
                np.ascontiguousarray(K[np.ix_(idx, idx)]), yy, C, tol, max_iter
            )
            sv = alpha > 0
            machines.append((idx[sv], alpha[sv] * yy[sv], bias))
            used[idx[sv]] = True
            self.n_iter_[k] = iters
            if probability:  # libsvm's orientation: +1 is the pair's first class, a
                ya = np.where(codes[idx] == a, 1.0, -1.0)
                dec = _cv_decisions(K[np.ix_(idx, idx)], ya, C, tol, max_iter, rng)
                sigmoids.append(_platt_sigmoid(dec, ya))
        # support vectors sorted by class, then by index (scikit-learn's order)
        order = np.lexsort((np.arange(n), codes))
        self.support_ = order[used[order]]
        self.support_vectors_ = X[self.support_]
        self.n_support_ = np.bincount(codes[self.support_], minlength=c)
        position = np.full(n, -1, dtype=np.int64)
        position[self.support_] = np.arange(self.support_.size)
        self.machine_support_ = [position[i] for i, _, _ in machines]
        self.dual_coef_ = [coef for _, coef, _ in machines]
        self.intercept_ = np.array([b for _, _, b in machines])
        if probability:
            self.probA_ = np.array([s[0] for s in sigmoids])
            self.probB_ = np.array([s[1] for s in sigmoids])
        elif hasattr(self, "probA_"):  # refitted without: forget the old model
            del self.probA_, self.probB_
        if self.kernel == "linear":
            self.coef_ = np.array(
                [
                    coef @ self.support_vectors_[i]
                    for i, coef in zip(self.machine_support_, self.dual_coef_, strict=True)
                ]
            )
        return self

    def _ovo(self, X: npt.ArrayLike) -> np.ndarray:
        self._check_fitted("support_vectors_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        Ks = self._kernel(X, self.support_vectors_)
        machines = zip(self.machine_support_, self.dual_coef_, self.intercept_, strict=True)
        return np.stack([Ks[:, i] @ coef + b for i, coef, b in machines], axis=1)

    def decision_function(self, X: npt.ArrayLike) -> np.ndarray:
        """:math:`f(x)`: ``(N,)`` for two classes (positive: ``classes_[1]``); for more,
        ``(N, c)`` one-vs-rest scores (votes plus a confidence in (-1/3, 1/3), as
        scikit-learn) or ``(N, c (c-1) / 2)`` with ``decision_function_shape="ovo"``
        (positive: the first class of the pair)."""
        f = self._ovo(X)
        c = self.classes_.size
        if c == 2:
            return f[:, 0]
        if self.decision_function_shape == "ovo":
            return f
        votes = np.zeros((f.shape[0], c))
        conf = np.zeros((f.shape[0], c))
        for k, (a, b) in enumerate(itertools.combinations(range(c), 2)):
            conf[:, a] += f[:, k]
            conf[:, b] -= f[:, k]
            votes[f[:, k] > 0, a] += 1
            votes[f[:, k] <= 0, b] += 1
        return votes + conf / (3 * (np.abs(conf) + 1))

    @_IfProbability
    def predict_proba(self, X: npt.ArrayLike) -> np.ndarray:
        """Class probabilities ``(N, c)``, columns in the order of ``classes_``
        (``sklearn.svm.SVC(probability=True).predict_proba``).

        Each pair's sigmoid (``probA_``, ``probB_``) turns its decision value into
        :math:`r_{ab}`, clipped to :math:`[10^{-7}, 1 - 10^{-7}]`; two classes give
        :math:`(r_{01}, 1 - r_{01})`, more are coupled by Wu, Lin and Weng's method (see
        the module docstring). Only on an SVC built with ``probability=True``:
        otherwise the attribute does not exist, as in scikit-learn.

        Parameters
        ----------
        X : (N, d) array_like

        Returns
        -------
        (N, c) ndarray
            Rows sum to 1. The argmax can differ from :meth:`predict` near the
            boundary (a separate, cross-validated model), as in scikit-learn.

        Raises
        ------
        NotFittedError
            Before ``fit``.
        InputError
            ``X`` not a finite (N, d) matrix with the training's d.
        """
        if not hasattr(self, "probA_"):
            raise not_fitted_error(
                f"this {type(self).__name__} is not fitted yet; call fit(X, y) before predict_proba"
            )
        f = self._ovo(X)
        c = self.classes_.size
        dec = -f if c == 2 else f  # positive for the pair's first class (libsvm's sign)
        z = dec * self.probA_ + self.probB_
        r = np.clip(np.exp(-np.logaddexp(0.0, z)), _MIN_PROB, 1.0 - _MIN_PROB)
        if c == 2:
            return np.c_[r[:, 0], 1.0 - r[:, 0]]
        pair = np.full((f.shape[0], c, c), 0.5)
        for k, (a, b) in enumerate(itertools.combinations(range(c), 2)):
            pair[:, a, b] = r[:, k]
            pair[:, b, a] = 1.0 - r[:, k]
        return _couple_pairwise(pair)

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """The class with most one-vs-one votes (ties: the lower class)."""
        f = self._ovo(X)
        c = self.classes_.size
        if c == 2:
            return self.classes_[(f[:, 0] > 0).astype(np.int64)]
        votes = np.zeros((f.shape[0], c), dtype=np.int64)
        for k, (a, b) in enumerate(itertools.combinations(range(c), 2)):
            win = f[:, k] > 0
            votes[win, a] += 1
            votes[~win, b] += 1
        return self.classes_[np.argmax(votes, axis=1)]


@njit(cache=True, nogil=True)
def _dual_cd(
    X: np.ndarray, y: np.ndarray, C: float, squared: bool, tol: float, max_iter: int, seed: int
):
    """Dual coordinate descent for the L2-regularized (squared) hinge loss; the last
    column of X is the constant bias feature if one is wanted. Returns (w, epochs)."""
    n, d = X.shape
    w = np.zeros(d)
    alpha = np.zeros(n)
    diag = 0.5 / C if squared else 0.0
    upper = np.inf if squared else C
    qd = np.empty(n)
    for i in range(n):
        s = diag
        for k in range(d):
            s += X[i, k] * X[i, k]
        qd[i] = s
    order = np.arange(n)
    state = np.array([np.uint64(seed)], dtype=np.uint64)
    epoch = 0
    for epoch in range(1, max_iter + 1):  # noqa: B007 (returned)
        for i in range(n - 1, 0, -1):  # Fisher-Yates shuffle with splitmix64
            state[0] += np.uint64(0x9E3779B97F4A7C15)
            z = state[0]
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            z = z ^ (z >> np.uint64(31))
            j = np.int64(z % np.uint64(i + 1))
            order[i], order[j] = order[j], order[i]
        pg_max = -np.inf
        pg_min = np.inf
        for t in range(n):
            i = order[t]
            g = 0.0
            for k in range(d):
                g += w[k] * X[i, k]
            g = y[i] * g - 1.0 + diag * alpha[i]
            if alpha[i] <= 0:
                pg = min(g, 0.0)
            elif alpha[i] >= upper:
                pg = max(g, 0.0)
            else:
                pg = g
            pg_max = max(pg_max, pg)
            pg_min = min(pg_min, pg)
            if pg != 0.0 and qd[i] > 0:
                old = alpha[i]
                alpha[i] = min(max(old - g / qd[i], 0.0), upper)
                step = (alpha[i] - old) * y[i]
                for k in range(d):
                    w[k] += step * X[i, k]
        if pg_max - pg_min < tol:
            break
    return w, epoch


class LinearSVC(ClassifierMixin, Estimator):
    """Linear SVM by dual coordinate descent (liblinear's solver), one-vs-rest.

    Minimizes :math:`\\tfrac12 \\lVert w \\rVert^2 + C \\sum_i \\ell(y_i (w \\cdot x_i + b))`
    with :math:`\\ell(m) = \\max(0, 1 - m)` (``loss="hinge"``) or its square
    (``"squared_hinge"``, the default). The intercept is learned as the weight of a
    constant feature ``intercept_scaling`` (so it is regularized too, like liblinear).

    Parameters
    ----------
    C : float
        Price of a margin violation.
    loss : {"squared_hinge", "hinge"}
    fit_intercept : bool
    intercept_scaling : float
    tol : float
        Stop when the projected gradient's spread is below it.
    max_iter : int
        Epochs per one-vs-rest problem.
    random_state : int, Generator, RandomState or None
        Seed of the coordinate order (scikit-learn's name).
    rng : int, Generator or None
        Deprecated alias of ``random_state`` (one release): ``fit`` warns and uses it.

    Attributes
    ----------
    coef_ : (1, d) or (c, d) ndarray
    intercept_ : (1,) or (c,) ndarray
    n_iter_ : int
        Most epochs any one-vs-rest problem took.
    """

    def __init__(
        self,
        C: float = 1.0,
        loss: str = "squared_hinge",
        fit_intercept: bool = True,
        intercept_scaling: float = 1.0,
        tol: float = 1e-4,
        max_iter: int = 1000,
        random_state: RandomStateLike = None,
        rng: int | np.random.Generator | None = None,
    ) -> None:
        self.C = C
        self.loss = loss
        self.fit_intercept = fit_intercept
        self.intercept_scaling = intercept_scaling
        self.tol = tol
        self.max_iter = max_iter
        self.random_state = random_state
        self.rng = rng

    def fit(self, X: npt.ArrayLike, y: npt.ArrayLike) -> LinearSVC:
        """Train on ``X`` (N, d) and labels ``y`` (N,)."""
        X = check_magnitude(self._check_X(X, fitting=True), "X", 1e150, smallest=1e-150)
        codes = self._encode_labels(y, X.shape[0])
        C = check_real(self.C, "C", 0.0, low_inclusive=False)
        check_option(self.loss, "loss", ("hinge", "squared_hinge"))
        tol = check_real(self.tol, "tol", 0.0, low_inclusive=False)
        max_iter = check_max_iter(self.max_iter)
        fit_intercept = check_bool(self.fit_intercept, "fit_intercept")
        # an extra feature column of this value: squared like X
        scale = check_real(self.intercept_scaling, "intercept_scaling", -1e150, 1e150)
        Xa = np.c_[X, np.full(X.shape[0], scale)] if fit_intercept else X
        Xa = np.ascontiguousarray(Xa)
        c = self.classes_.size
        targets = [1] if c == 2 else list(range(c))
        seed = int(seed_from(self._random_state()).integers(0, 2**63))
        W = []
        epochs = 0
        for k in targets:
            yy = np.where(codes == k, 1.0, -1.0)
            w, e = _dual_cd(Xa, yy, C, self.loss == "squared_hinge", tol, max_iter, seed)
            W.append(w)
            epochs = max(epochs, e)
        W = np.array(W)
        if fit_intercept:
            self.coef_, self.intercept_ = W[:, :-1].copy(), W[:, -1] * scale
        else:
            self.coef_, self.intercept_ = W, np.zeros(W.shape[0])
        self.n_iter_ = epochs
        return self

    def decision_function(self, X: npt.ArrayLike) -> np.ndarray:
        """:math:`w \\cdot x + b`: ``(N,)`` for two classes, else ``(N, c)``."""
        self._check_fitted("coef_")
        X = check_magnitude(self._check_X(X), "X", 1e150)
        f = X @ self.coef_.T + self.intercept_
        return f[:, 0] if self.classes_.size == 2 else f

    def predict(self, X: npt.ArrayLike) -> np.ndarray:
        """Class labels ``(N,)``: the sign of the decision for two classes, else the
        class whose one-vs-rest decision is largest."""
        f = self.decision_function(X)
        if f.ndim == 1:
            return self.classes_[(f > 0).astype(np.int64)]
        return self.classes_[np.argmax(f, axis=1)]
