r"""Kalman filters: linear (:class:`KalmanFilter`), extended (:class:`ExtendedKalmanFilter`),
the pure :func:`kf_predict` / :func:`kf_update` steps, and motion-model builders.

Linear-Gaussian model: :math:`x_k = A x_{k-1} + B u_k + w_k`, :math:`w_k \sim N(0, Q)`;
:math:`z_k = H x_k + v_k`, :math:`v_k \sim N(0, R)`.

Predict:

.. math:: \hat x^- = A \hat x + B u, \qquad P^- = A P A^\top + Q

Update, with the innovation :math:`y = z - H \hat x^-` and its covariance
:math:`S = H P^- H^\top + R`:

.. math:: K = P^- H^\top S^{-1}, \qquad \hat x = \hat x^- + K y,

.. math:: P = (I - K H) P^- (I - K H)^\top + K R K^\top \quad\text{(Joseph form, default)}
          \qquad\text{or}\qquad P = (I - K H) P^-

The Joseph form keeps P symmetric positive semi-definite under rounding and is what
filterpy's ``KalmanFilter.update`` computes, which this matches step by step. The
squared Mahalanobis distance :math:`d^2 = y^\top S^{-1} y` follows a chi-square law with
``dim_z`` degrees of freedom for a consistent filter; :meth:`KalmanFilter.gate` accepts a
measurement when :math:`d^2` is below that law's ``probability`` quantile.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg.lapack import dpotrf, dpotrs
from scipy.stats import chi2

from robopercept._checks import (
    check_bool,
    check_int,
    check_magnitude,
    check_numeric,
    check_real,
    plain_repr,
)
from robopercept.errors import DegenerateError, InputError

__all__ = [
    "MAX_DIM",
    "ExtendedKalmanFilter",
    "KalmanFilter",
    "UpdateResult",
    "check_dim",
    "constant_acceleration",
    "constant_position",
    "constant_velocity",
    "kf_predict",
    "kf_update",
    "kinematic_matrices",
    "mahalanobis_logdet",
    "rts_smooth",
]


#: largest state or measurement size: a (dim, dim) float64 matrix of it takes 128 MiB,
#: and a filter keeps several (P, A, Q); beyond it a typo (2**40) would ask for EiB
MAX_DIM = 4096


#: arrays up to this size are checked in Python (:func:`_small_ok`): NumPy's reductions
#: cost microseconds each on the 3-vectors and 3x3 covariances of a per-frame track
_SMALL = 64


def _small_ok(a: np.ndarray) -> bool:
    """Whether a float64 array of at most :data:`_SMALL` values is finite and within
    1e150 (a NaN fails the comparison): one Python pass instead of three reductions."""
    return a.size <= _SMALL and all(-1e150 <= v <= 1e150 for v in a.ravel().tolist())


def check_matrix(value: object, name: str, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a finite float64 matrix of ``shape`` within 1e150 in magnitude.

    A scalar stands for that multiple of the identity (square shapes) or fills the
    shape. The filters' check of ``P``, ``A``, ``Q``, ``H``, ``R``, ``B``; a float64
    array of the right shape with at most 64 values is returned as it is after one
    Python pass.

    Raises
    ------
    InputError
        Wrong shape, non-numeric, non-finite or beyond 1e150.
    """
    if (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.shape == shape
        and _small_ok(value)
    ):
        return value  # (what the checks below return for it)
    a = check_numeric(value, name)
    if a.ndim == 0:
        a = a * np.eye(shape[0]) if shape[0] == shape[1] else np.full(shape, float(a))
    if a.shape != shape:
        raise InputError(f"{name} must have shape {shape}; got {a.shape}")
    if not np.isfinite(a).all():
        raise InputError(f"{name} must be finite")
    return check_magnitude(a, name, 1e150)  # squares beyond it overflow (S, y^T S^-1 y)


def check_vector(value: object, name: str, n: int) -> np.ndarray:
    """``value`` flattened to a finite float64 vector of ``n`` elements within 1e150.

    The filters' check of ``x``, ``z`` and ``u``.

    Raises
    ------
    InputError
        Wrong size, non-numeric, non-finite or beyond 1e150.
    """
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (n,):
        if _small_ok(value):
            return value
    a = check_numeric(value, name).reshape(-1)
    if a.shape != (n,):
        raise InputError(f"{name} must have {n} elements; got shape {np.shape(value)}")
    if not np.isfinite(a).all():
        raise InputError(f"{name} must be finite; got {plain_repr(value)[:80]}")
    return check_magnitude(a, name, 1e150)


def check_dim(value: Any, name: str, minimum: int = 1) -> int:
    """A state or measurement size: an integer in ``[minimum, MAX_DIM]``.

    Parameters
    ----------
    value : int
    name : str
        The parameter named in the message.
    minimum : int

    Returns
    -------
    int

    Raises
    ------
    InputError
        Not an integer, below ``minimum``, or above :data:`MAX_DIM` (the ``(n, n)``
        covariance would take ``8 n^2`` bytes).
    """
    n = check_int(value, name, minimum)
    if n > MAX_DIM:
        raise InputError(
            f"{name} must be <= {MAX_DIM}; got {n}: a ({name}, {name}) float64 matrix "
            f"would take {8.0 * n * n / 2**30:.3g} GiB"
        )
    return n


@dataclass(frozen=True)
class UpdateResult:
    """Everything one update computed.

    Attributes
    ----------
    x, P : ndarray
        Posterior state and covariance.
    y : (dim_z,) ndarray
        Innovation :math:`z - H \\hat x^-`.
    S : (dim_z, dim_z) ndarray
        Innovation covariance.
    K : (dim_x, dim_z) ndarray
        Kalman gain.
    mahalanobis2 : float
        :math:`y^\\top S^{-1} y`.
    log_det_s : float
        :math:`\\log\\det S`, from the same Cholesky factor (the normalizer of the
        innovation's Gaussian likelihood, which an IMM needs).
    """

    x: np.ndarray
    P: np.ndarray
    y: np.ndarray
    S: np.ndarray
    K: np.ndarray
    mahalanobis2: float
    log_det_s: float = math.nan


def kf_predict(
    x: np.ndarray,
    P: np.ndarray,
    A: np.ndarray,
    Q: np.ndarray,
    B: np.ndarray | None = None,
    u: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One prediction: ``x = A x + B u``, ``P = A P A^T + Q`` (pure function).

    Parameters
    ----------
    x : (n,) array_like
    P, A, Q : (n, n) array_like
        A scalar ``P`` or ``Q`` is that multiple of the identity.
    B : (n, m) array_like, optional
    u : (m,) array_like, optional
        The control term ``B u`` is added when both are given.

    Returns
    -------
    x : (n,) ndarray
    P : (n, n) ndarray

    Raises
    ------
    InputError
        Shapes that do not agree with ``x``, non-finite values, values beyond 1e150.
    """
    xx = check_numeric(x, "x").reshape(-1)
    n = check_dim(xx.size, "the state size len(x)")
    xx = check_vector(xx, "x", n)
    P = check_matrix(P, "P", (n, n))
    A = check_matrix(A, "A", (n, n))
    Q = check_matrix(Q, "Q", (n, n))
    if B is not None and u is not None:
        uu = check_numeric(u, "u").reshape(-1)
        uu = check_vector(uu, "u", uu.size)
        return _predict(xx, P, A, Q, check_matrix(B, "B", (n, uu.size)), uu)
    return _predict(xx, P, A, Q, None, None)


def _predict(
    x: np.ndarray,
    P: np.ndarray,
    A: np.ndarray,
    Q: np.ndarray,
    B: np.ndarray | None,
    u: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`kf_predict` without the checks."""
    x = A @ x
    if B is not None and u is not None:
        x = x + B @ u
    return x, A @ P @ A.T + Q


def _factor_s(S: np.ndarray) -> np.ndarray:
    # LAPACK's potrf directly: scipy's cho_factor / cho_solve wrappers (argument
    # conversion, finiteness scans) cost ten times the 3x3 factorization itself;
    # the same routine, so the same numbers
    c, info = (S, 1) if not np.isfinite(S).all() else dpotrf(S, lower=0, clean=0)
    if info != 0:  # not positive definite, or a covariance grown past float64
        raise DegenerateError(
            "the innovation covariance H P H^T + R is not finite and positive definite: "
            "check that R is positive definite"
        )
    return np.asarray(c)


def _solve_factored(c: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    return dpotrs(c, rhs, lower=0)[0]


def _solve_s(S: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    return _solve_factored(_factor_s(S), rhs)


def mahalanobis_logdet(S: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    r""":math:`(y^\top S^{-1} y, \log\det S)` through one Cholesky factorization
    :math:`S = U^\top U` (LAPACK ``dpotrf``/``dpotrs``, as ``scipy.linalg.cho_factor``
    and ``cho_solve``): the innovation's squared distance and the normalizer of its
    Gaussian likelihood.

    Parameters
    ----------
    S : (m, m) float64 ndarray
        An innovation covariance.
    y : (m,) float64 ndarray
        An innovation.

    Returns
    -------
    d2, logdet : float

    Raises
    ------
    DegenerateError
        ``S`` not finite or not positive definite.

    Examples
    --------
    >>> d2, logdet = mahalanobis_logdet(np.diag([4.0, 1.0]), np.array([2.0, 1.0]))
    >>> round(d2, 12), round(logdet, 12) == round(float(np.log(4.0)), 12)
    (2.0, True)
    """
    c = _factor_s(S)
    return float(y @ _solve_factored(c, y)), _log_det_factored(c)


def _log_det_factored(c: np.ndarray) -> float:
    """:math:`\\log\\det S = 2 \\sum_i \\log U_{ii}` from its Cholesky factor."""
    return 2.0 * float(np.log(c.diagonal()).sum())


def kf_update(
    x: np.ndarray,
    P: np.ndarray,
    z: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    joseph: bool = True,
) -> UpdateResult:
    """One measurement update (pure function); see the module docstring.

    Parameters
    ----------
    x : (n,) array_like
    P : (n, n) array_like
    z : (m,) array_like
    H : (m, n) array_like
    R : (m, m) array_like
        A scalar ``P`` or ``R`` is that multiple of the identity.
    joseph : bool
        Joseph-form covariance update.

    Returns
    -------
    UpdateResult

    Raises
    ------
    InputError
        Shapes that do not agree with ``x`` and ``z``, non-finite values, values beyond
        1e150.
    DegenerateError
        ``H P H^T + R`` is not positive definite.
    """
    xx = check_numeric(x, "x").reshape(-1)
    zz = check_numeric(z, "z").reshape(-1)
    n = check_dim(xx.size, "the state size len(x)")
    m = check_dim(zz.size, "the measurement size len(z)")
    return _update(
        check_vector(xx, "x", n),
        check_matrix(P, "P", (n, n)),
        check_vector(zz, "z", m),
        check_matrix(H, "H", (m, n)),
        check_matrix(R, "R", (m, m)),
        check_bool(joseph, "joseph"),
    )


def _update(
    x: np.ndarray, P: np.ndarray, z: np.ndarray, H: np.ndarray, R: np.ndarray, joseph: bool
) -> UpdateResult:
    """:func:`kf_update` without the checks."""
    y = z - H @ x
    PHt = P @ H.T
    S = H @ PHt + R
    c = _factor_s(S)  # one Cholesky factorization for the gain and the distance
    K = _solve_factored(c, PHt.T).T  # P H^T S^-1
    x = x + K @ y
    ikh = np.eye(P.shape[0]) - K @ H
    P = ikh @ P @ ikh.T + K @ R @ K.T if joseph else ikh @ P
    d2 = float(y @ _solve_factored(c, y))
    return UpdateResult(x, P, y, S, K, d2, _log_det_factored(c))


class KalmanFilter:
    """Linear Kalman filter (see the module docstring for the equations).

    Parameters
    ----------
    dim_x, dim_z : int
        State and measurement sizes.
    dim_u : int
        Control size (0: no control).
    x : (dim_x,) array_like, optional
        Initial state (zeros).
    P : (dim_x, dim_x) array_like or float, optional
        Initial covariance (identity); a scalar means that multiple of the identity.
    A, Q, H, R, B : array_like, optional
        Transition (identity), process noise (identity), measurement matrix (zeros),
        measurement noise (identity), control matrix (zeros). Scalars are multiples of the
        identity. ``F`` is accepted as filterpy's name for ``A``.
    joseph : bool
        Joseph-form covariance update (default, as filterpy).

    Attributes
    ----------
    x, P, A, Q, H, R, B : ndarray
        The current state, covariance and model (assignable).
    y, S, K : ndarray or None
        Innovation, its covariance and the gain of the last update.

    Examples
    --------
    >>> kf = constant_velocity(dim=1, dt=0.1, q=1.0, r=0.01)
    >>> x, P = kf.predict()
    >>> result = kf.update([0.5])
    """

    def __init__(
        self,
        dim_x: int,
        dim_z: int,
        dim_u: int = 0,
        *,
        x: np.ndarray | None = None,
        P: np.ndarray | float | None = None,
        A: np.ndarray | None = None,
        Q: np.ndarray | float | None = None,
        H: np.ndarray | None = None,
        R: np.ndarray | float | None = None,
        B: np.ndarray | None = None,
        F: np.ndarray | None = None,
        joseph: bool = True,
    ) -> None:
        self.dim_x = check_dim(dim_x, "dim_x")
        self.dim_z = check_dim(dim_z, "dim_z")
        self.dim_u = check_dim(dim_u, "dim_u", 0)
        if A is not None and F is not None:
            raise InputError("give A or F (the same matrix), not both")
        A = F if A is None else A
        nx, nz = self.dim_x, self.dim_z
        self.x = np.zeros(nx) if x is None else check_vector(x, "x", nx)
        self.P = np.eye(nx) if P is None else check_matrix(P, "P", (nx, nx))
        self.A = np.eye(nx) if A is None else check_matrix(A, "A", (nx, nx))
        self.Q = np.eye(nx) if Q is None else check_matrix(Q, "Q", (nx, nx))
        self.H = np.zeros((nz, nx)) if H is None else check_matrix(H, "H", (nz, nx))
        self.R = np.eye(nz) if R is None else check_matrix(R, "R", (nz, nz))
        self.B = None if B is None or self.dim_u == 0 else check_matrix(B, "B", (nx, self.dim_u))
        self.joseph = check_bool(joseph, "joseph")
        self.y: np.ndarray | None = None
        self.S: np.ndarray | None = None
        self.K: np.ndarray | None = None

    @property
    def F(self) -> np.ndarray:
        """filterpy's name for the transition matrix ``A``."""
        return self.A

    def predict(
        self,
        u: np.ndarray | None = None,
        *,
        A: np.ndarray | None = None,
        Q: np.ndarray | float | None = None,
        B: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Propagate the state one step; ``A``, ``Q``, ``B`` override the model for this
        call only. Returns the prior ``(x, P)``."""
        nx = self.dim_x
        a = self.A if A is None else check_matrix(A, "A", (nx, nx))
        q = self.Q if Q is None else check_matrix(Q, "Q", (nx, nx))
        b, uu = None, None
        if u is not None:
            if self.dim_u == 0 and B is None:
                raise InputError("this filter has no control input (dim_u=0)")
            uu = check_vector(u, "u", self.dim_u if self.dim_u else np.size(u))
            b = self.B if B is None else check_matrix(B, "B", (nx, uu.size))
            if b is None:
                raise InputError("a control input needs B (set it or pass B=...)")
        self.x, self.P = _predict(self.x, self.P, a, q, b, uu)
        return self.x, self.P

    def _parts(
        self, z: np.ndarray, R: np.ndarray | float | None, H: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        zz = check_vector(z, "z", self.dim_z)
        r = self.R if R is None else check_matrix(R, "R", (self.dim_z, self.dim_z))
        h = self.H if H is None else check_matrix(H, "H", (self.dim_z, self.dim_x))
        return zz, r, h

    def update(
        self,
        z: np.ndarray,
        *,
        R: np.ndarray | float | None = None,
        H: np.ndarray | None = None,
    ) -> UpdateResult:
        """Correct with the measurement ``z``; ``R``, ``H`` override the model for this
        call only."""
        zz, r, h = self._parts(z, R, H)
        res = _update(self.x, self.P, zz, h, r, self.joseph)
        self.x, self.P = res.x, res.P
        self.y, self.S, self.K = res.y, res.S, res.K
        return res

    def innovation(
        self, z: np.ndarray, *, R: np.ndarray | float | None = None, H: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(y, S)`` that :meth:`update` would use for ``z``, without updating."""
        zz, r, h = self._parts(z, R, H)
        return zz - h @ self.x, h @ self.P @ h.T + r

    def mahalanobis(self, z: np.ndarray, **overrides: np.ndarray) -> float:
        """Mahalanobis distance :math:`\\sqrt{y^\\top S^{-1} y}` of ``z`` from the prediction."""
        y, S = self.innovation(z, **overrides)
        return float(np.sqrt(y @ _solve_s(S, y)))

    def gate(self, z: np.ndarray, probability: float = 0.99, **overrides: np.ndarray) -> bool:
        """True if ``z`` passes the chi-square gate: :math:`d^2 \\le
        \\chi^2_{\\text{dim\\_z}}(\\text{probability})`."""
        p = check_real(
            probability, "probability", 0.0, 1.0, low_inclusive=False, high_inclusive=False
        )
        return self.mahalanobis(z, **overrides) ** 2 <= float(chi2.ppf(p, self.dim_z))


class ExtendedKalmanFilter:
    r"""Extended Kalman filter for :math:`x_k = f(x_{k-1}, u_k) + w_k`,
    :math:`z_k = h(x_k) + v_k`.

    The prediction propagates the mean through ``f`` and the covariance through its
    Jacobian :math:`F = \partial f / \partial x`: :math:`P^- = F P F^\top + Q`; the update
    linearizes ``h`` at the prior (:math:`H = \partial h / \partial x`) and applies the
    linear update with :math:`y = z - h(\hat x^-)`. Matches filterpy's
    ``ExtendedKalmanFilter`` (``predict_x`` through ``f``; Joseph-form update).

    Parameters
    ----------
    dim_x, dim_z : int
    f, F_jacobian : callable, optional
        ``f(x, u) -> x``; ``F_jacobian(x, u) -> (dim_x, dim_x)``. Default: identity.
    h, H_jacobian : callable
        ``h(x) -> z``; ``H_jacobian(x) -> (dim_z, dim_x)``.
    x, P, Q, R : array_like, optional
    """

    def __init__(
        self,
        dim_x: int,
        dim_z: int,
        *,
        h: Callable[[np.ndarray], np.ndarray],
        H_jacobian: Callable[[np.ndarray], np.ndarray],
        f: Callable[[np.ndarray, np.ndarray | None], np.ndarray] | None = None,
        F_jacobian: Callable[[np.ndarray, np.ndarray | None], np.ndarray] | None = None,
        x: np.ndarray | None = None,
        P: np.ndarray | float | None = None,
        Q: np.ndarray | float | None = None,
        R: np.ndarray | float | None = None,
        joseph: bool = True,
    ) -> None:
        if (f is None) != (F_jacobian is None):
            raise InputError("give both f and F_jacobian, or neither (identity motion)")
        self.dim_x = check_dim(dim_x, "dim_x")
        self.dim_z = check_dim(dim_z, "dim_z")
        for cname, fn in (
            ("h", h),
            ("H_jacobian", H_jacobian),
            ("f", f),
            ("F_jacobian", F_jacobian),
        ):
            if fn is not None and not callable(fn):
                raise InputError(
                    f"{cname} must be a function (callable); got {type(fn).__name__} "
                    f"{plain_repr(fn)[:60]}"
                )
        if h is None or H_jacobian is None:
            raise InputError(
                "h and H_jacobian are required: the measurement function and its Jacobian"
            )
        nx, nz = self.dim_x, self.dim_z
        self.f, self.F_jacobian, self.h, self.H_jacobian = f, F_jacobian, h, H_jacobian
        self.x = np.zeros(nx) if x is None else check_vector(x, "x", nx)
        self.P = np.eye(nx) if P is None else check_matrix(P, "P", (nx, nx))
        self.Q = np.eye(nx) if Q is None else check_matrix(Q, "Q", (nx, nx))
        self.R = np.eye(nz) if R is None else check_matrix(R, "R", (nz, nz))
        self.joseph = check_bool(joseph, "joseph")

    def predict(
        self, u: np.ndarray | None = None, *, Q: np.ndarray | float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Prior ``(x, P)``: ``x = f(x, u)``, ``P = F P F^T + Q`` (``Q`` for this call)."""
        q = self.Q if Q is None else check_matrix(Q, "Q", (self.dim_x, self.dim_x))
        if self.f is None:
            self.P = self.P + q
            return self.x, self.P
        nx = self.dim_x
        jac = check_matrix(self.F_jacobian(self.x, u), "F_jacobian(x, u)", (nx, nx))  # type: ignore[misc]
        self.x = check_vector(self.f(self.x, u), "f(x, u)", self.dim_x)
        self.P = jac @ self.P @ jac.T + q
        return self.x, self.P

    def update(self, z: np.ndarray, *, R: np.ndarray | float | None = None) -> UpdateResult:
        """Correct with ``z`` (``R`` for this call only)."""
        zz = check_vector(z, "z", self.dim_z)
        r = self.R if R is None else check_matrix(R, "R", (self.dim_z, self.dim_z))
        hj = check_matrix(self.H_jacobian(self.x), "H_jacobian(x)", (self.dim_z, self.dim_x))
        hx = check_vector(self.h(self.x), "h(x)", self.dim_z)
        # the linear update around the prior, with y = z - h(x) instead of z - H x
        res = _update(self.x, self.P, zz - hx + hj @ self.x, hj, r, self.joseph)
        self.x, self.P = res.x, res.P
        return res


# --------------------------------------------------------------------------- builders
def rts_smooth(
    xs: npt.ArrayLike, Ps: npt.ArrayLike, As: npt.ArrayLike, Qs: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    r"""Rauch-Tung-Striebel fixed-interval smoother: the estimates of every step from
    all the measurements, before and after it.

    From the filtered estimates :math:`(\hat x_k, P_k)` (after step :math:`k`'s update,
    or its prediction where it had no measurement), backwards from the last step
    (:math:`\hat x^s_T = \hat x_T`, :math:`P^s_T = P_T`):

    .. math:: P^-_{k+1} = A_{k+1} P_k A_{k+1}^\top + Q_{k+1}, \qquad
              C_k = P_k A_{k+1}^\top (P^-_{k+1})^{-1},

    .. math:: \hat x^s_k = \hat x_k + C_k (\hat x^s_{k+1} - A_{k+1} \hat x_k), \qquad
              P^s_k = P_k + C_k (P^s_{k+1} - P^-_{k+1}) C_k^\top.

    Matches filterpy's ``KalmanFilter.rts_smoother`` (the same convention: ``As[k]``
    and ``Qs[k]`` take step :math:`k - 1` to step :math:`k`, ``As[0]`` and ``Qs[0]`` are
    not used), with :math:`C_k` from a linear solve instead of an inverse.

    Parameters
    ----------
    xs : (T, n) array_like
        Filtered states.
    Ps : (T, n, n) array_like
        Their covariances.
    As, Qs : (T, n, n) array_like
        Transition and process noise into each step.

    Returns
    -------
    xs, Ps : (T, n) and (T, n, n) ndarray
        The smoothed states and covariances.

    Raises
    ------
    InputError
        Shapes that disagree, non-finite values or values beyond 1e150.
    DegenerateError
        A predicted covariance :math:`P^-_{k+1}` that is singular.
    """
    x = check_numeric(xs, "xs")
    if x.ndim != 2 or x.shape[0] < 1:
        raise InputError(f"xs must be (T, n) filtered states, T >= 1; got shape {x.shape}")
    t, n = x.shape
    n = check_dim(n, "the state size xs.shape[1]")
    mats = []
    for name, value in (("Ps", Ps), ("As", As), ("Qs", Qs)):
        a = check_numeric(value, name)
        if a.shape != (t, n, n):
            raise InputError(f"{name} must have shape {(t, n, n)} to match xs; got {a.shape}")
        mats.append(a)
    for name, a in (("xs", x), ("Ps", mats[0]), ("As", mats[1]), ("Qs", mats[2])):
        if not np.isfinite(a).all():
            raise InputError(f"{name} must be finite")
        check_magnitude(a, name, 1e150)
    P, A, Q = mats
    x, P = x.copy(), P.copy()
    for k in range(t - 2, -1, -1):
        a = A[k + 1]
        pp = a @ P[k] @ a.T + Q[k + 1]
        try:
            gain = np.linalg.solve(pp, a @ P[k]).T  # C = P A^T Pp^-1 (P, Pp symmetric)
        except np.linalg.LinAlgError as exc:
            raise DegenerateError(
                f"the predicted covariance of step {k + 1} is singular: give a positive Q or P"
            ) from exc
        x[k] = x[k] + gain @ (x[k + 1] - a @ x[k])
        P[k] = P[k] + gain @ (P[k + 1] - pp) @ gain.T
    return x, P


def kinematic_matrices(order: int, dim: int, dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    r"""The transition ``A`` and process noise ``Q`` of the kinematic models for one
    interval: what :func:`constant_position` (``order`` 0), :func:`constant_velocity`
    (1) and :func:`constant_acceleration` (2) build, without the filter around them (for
    a running filter whose interval changed; the same arrays, bit for bit).

    State ``[p, v, a]`` up to ``order``, each ``dim`` long:
    :math:`A = a_1 \otimes I`, :math:`(a_1)_{ij} = \Delta t^{j-i} / (j-i)!` for
    :math:`j \ge i`; :math:`Q = q\, G G^\top \otimes I`, :math:`G = [\Delta t^2 / 2,
    \Delta t]` (order 1) or :math:`[\Delta t^2 / 2, \Delta t, 1]` (order 2), the
    discrete white-noise acceleration models of Bar-Shalom (filterpy's
    ``Q_discrete_white_noise``); order 0 is the random walk :math:`Q = q \Delta t I`.

    Parameters
    ----------
    order : {0, 1, 2}
    dim : int
        Values per derivative (the measured position's size).
    dt : float
        The interval, > 0.
    q : float
        Process noise variance, >= 0.

    Returns
    -------
    A, Q : ((order + 1) dim, (order + 1) dim) ndarray

    Examples
    --------
    >>> A, Q = kinematic_matrices(1, 1, 0.5, 4.0)
    >>> A.tolist(), Q.tolist()
    ([[1.0, 0.5], [0.0, 1.0]], [[0.0625, 0.25], [0.25, 1.0]])
    """
    order = check_int(order, "order", 0)
    if order > 2:
        raise InputError(f"order must be 0, 1 or 2 (position, velocity, acceleration); got {order}")
    # bounds that keep A (dt^2 / 2), Q (q dt^4 / 4) and R below the 1e150 that
    # KalmanFilter accepts (their squares would overflow)
    dt = check_real(dt, "dt", 0.0, 1e12, low_inclusive=False)
    q = check_real(q, "q", 0.0, 1e100)
    n = order + 1
    dim = check_dim(dim, "dim")
    if n * dim > MAX_DIM:
        raise InputError(
            f"dim must be <= {MAX_DIM // n} for this model ({n} values per dimension); got {dim}"
        )
    # 1-D blocks: transition of a Taylor expansion, and the discrete white-noise
    # acceleration models of Bar-Shalom (Q = q G G^T with G = [dt^2/2, dt] for constant
    # velocity, [dt^2/2, dt, 1] for constant acceleration), as filterpy's
    # Q_discrete_white_noise
    a1 = np.zeros((n, n))
    for i in range(n):
        for j in range(i, n):
            a1[i, j] = dt ** (j - i) / float(math.factorial(j - i))
    if order == 0:
        q1 = np.array([[q * dt]])  # random walk: variance grows with time
    else:
        g = np.array([dt ** (2 - j) / (2.0 if j == 0 else 1.0) for j in range(n)])
        q1 = q * np.outer(g, g)
    # a1 (x) I and q1 (x) I (Kronecker products; every entry of a1 and q1 is >= 0, so
    # the blocks' off-diagonal zeros are +0.0 as np.kron gives them), written block
    # diagonal by block diagonal: a third of np.kron's time, called on every change of
    # a running filter's interval
    idx = np.arange(dim)
    A = np.zeros((n, dim, n, dim))
    Q = np.zeros((n, dim, n, dim))
    A[:, idx, :, idx] = a1
    Q[:, idx, :, idx] = q1
    return A.reshape(n * dim, n * dim), Q.reshape(n * dim, n * dim)


def _kinematic(order: int, dim: int, dt: float, q: float, r: float) -> KalmanFilter:
    """State ``[p (dim), v (dim), a (dim)]`` up to ``order``; position measured."""
    A, Q = kinematic_matrices(order, dim, dt, q)
    r = check_real(r, "r", 0.0, 1e150, low_inclusive=False)
    dim = A.shape[0] // (order + 1)
    n = order + 1
    eye = np.eye(dim)
    H = np.zeros((dim, n * dim))
    H[:, :dim] = eye
    return KalmanFilter(n * dim, dim, A=A, Q=Q, H=H, R=r * eye, P=np.eye(n * dim))


def constant_position(dim: int, dt: float, q: float, r: float) -> KalmanFilter:
    """Random-walk model: state ``p``, ``A = I``, ``Q = q dt I``, ``H = I``, ``R = r I``."""
    return _kinematic(0, dim, dt, q, r)


def constant_velocity(dim: int, dt: float, q: float, r: float) -> KalmanFilter:
    r"""Constant velocity: state ``[p, v]`` (each ``dim`` long),
    :math:`A = \begin{bmatrix} I & \Delta t I \\ 0 & I \end{bmatrix}`, white-noise
    acceleration of variance ``q``:
    :math:`Q = q\, G G^\top \otimes I`, :math:`G = [\Delta t^2 / 2, \Delta t]`;
    position measured with variance ``r``."""
    return _kinematic(1, dim, dt, q, r)


def constant_acceleration(dim: int, dt: float, q: float, r: float) -> KalmanFilter:
    r"""Constant acceleration: state ``[p, v, a]``, white acceleration increments of
    variance ``q`` (discrete Wiener-process acceleration):
    :math:`Q = q\, G G^\top \otimes I`, :math:`G = [\Delta t^2 / 2, \Delta t, 1]`."""
    return _kinematic(2, dim, dt, q, r)
