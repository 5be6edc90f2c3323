r"""Interacting multiple model (IMM) estimator over a bank of linear Kalman filters.

Blom & Bar-Shalom (1988), "The interacting multiple model algorithm for systems with
Markovian switching coefficients", IEEE TAC 33(8); Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation* (2001), sec. 11.6.

The target follows one of :math:`r` linear-Gaussian models (one
:class:`~robopercept.tracking.kalman.KalmanFilter` each, all with the same state and
measurement) and switches between them as a Markov chain,
:math:`M_{ij} = P(\text{model } j \text{ at } k \mid \text{model } i \text{ at } k-1)`
(rows sum to 1). One cycle, from the mode probabilities :math:`\mu_i` and each
filter's estimate :math:`(\hat x_i, P_i)` at :math:`k-1`:

1. Mixing. Predicted mode probabilities and mixing probabilities

   .. math:: \bar c_j = \sum_i M_{ij} \mu_i, \qquad
             \omega_{ij} = \frac{M_{ij} \mu_i}{\bar c_j}

   and the mixed initial condition of filter :math:`j`

   .. math:: \hat x^0_j = \sum_i \omega_{ij} \hat x_i, \qquad
             P^0_j = \sum_i \omega_{ij} \left(P_i + (\hat x_i - \hat x^0_j)
             (\hat x_i - \hat x^0_j)^\top\right)

   (the second term is the spread of the means).
2. Mode-matched prediction: filter :math:`j` predicts from :math:`(\hat x^0_j, P^0_j)`
   with its own :math:`A_j, Q_j` (or this step's override, e.g. for a varying
   :math:`\Delta t`). The combined prior is the moment match of the predictions under
   the predicted mode probabilities :math:`\bar c_j` (step 4 with :math:`\bar c`).
3. Mode-matched update and mode probabilities: each filter updates with :math:`z`;
   with its innovation :math:`y_j` and innovation covariance :math:`S_j`, the mode
   likelihood and the new mode probabilities are

   .. math:: \Lambda_j = N(y_j; 0, S_j) = \frac{\exp(-\tfrac12 y_j^\top S_j^{-1} y_j)}
             {\sqrt{\det(2\pi S_j)}}, \qquad
             \mu_j = \frac{\bar c_j \Lambda_j}{\sum_l \bar c_l \Lambda_l}

   (computed from :math:`\log \Lambda_j` with a log-sum-exp, so that a measurement far
   from every model still ranks the models instead of underflowing to 0/0).
4. Combination (moment matching of the Gaussian mixture):

   .. math:: \hat x = \sum_j \mu_j \hat x_j, \qquad
             P = \sum_j \mu_j \left(P_j + (\hat x_j - \hat x)(\hat x_j - \hat x)^\top\right)

A step without a measurement (:meth:`IMMEstimator.skip`) is the IMM with a missed
detection: nothing discriminates the modes, so :math:`\mu_j = \bar c_j`, each filter
keeps its prediction and the combined estimate is the combined prior.

Parity with filterpy's ``IMMEstimator`` (same ``M`` convention, ``cbar = mu @ M``,
``omega[i, j] = M[i, j] mu[i] / cbar[j]``): ``x``, ``P``, ``mu``, ``cbar``, ``omega`` and
the likelihoods after each update agree to rounding. One deliberate difference: filterpy
weights its combined *prior* ``x_prior`` by the previous posterior ``mu``; here it is
weighted by :math:`\bar c`, the mode probabilities of the prediction, as the textbook
and :meth:`IMMEstimator.skip` require.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import check_magnitude, check_numeric, check_real, plain_repr
from robopercept.errors import DegenerateError, InputError
from robopercept.tracking.kalman import KalmanFilter, check_matrix, check_vector

__all__ = ["IMMEstimator"]

_SUM_TOL = 1e-8  # how far from 1 a probability vector (or a row of M) may sum
_NOT_PD = (
    "the innovation covariance H P H^T + R is not finite and positive definite: "
    "check that R is positive definite"
)


def _moments(weights: np.ndarray, xs: np.ndarray, Ps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a Gaussian mixture: ``x = sum w_j x_j``,
    ``P = sum w_j (P_j + (x_j - x)(x_j - x)^T)``; ``xs`` (r, n), ``Ps`` (r, n, n)."""
    x = weights @ xs
    d = xs - x
    return x, np.einsum("j,jab->ab", weights, Ps) + np.einsum("j,ja,jb->ab", weights, d, d)


# -- the compiled bank steps ----------------------------------------------------------
# A cycle of a tracker's IMM is a few dozen products of small matrices; as NumPy calls
# each costs microseconds of dispatch, so the bank's prediction, update and gating
# distance run compiled, every filter in one call (the same equations as
# KalmanFilter.predict / update, Joseph form included, and the module docstring's
# mixing; tests/tracking/test_imm.py holds them to filterpy's IMMEstimator).


@njit(cache=True, nogil=True)
def _chol(S):  # pragma: no cover - compiled
    # lower Cholesky factor of a small symmetric S; ok False when S is not finite and
    # positive definite
    k = S.shape[0]
    L = np.zeros((k, k))
    for i in range(k):
        for j in range(i + 1):
            acc = S[i, j]
            for m in range(j):
                acc -= L[i, m] * L[j, m]
            if i == j:
                if not acc > 0.0 or not np.isfinite(acc):
                    return L, False
                L[i, i] = np.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    return L, True


@njit(cache=True, nogil=True)
def _chol_solve(L, b):  # pragma: no cover - compiled
    # S^-1 b for S = L L^T, b (k, m): forward then back substitution
    k, m = b.shape
    w = np.empty((k, m))
    for c in range(m):
        for i in range(k):
            acc = b[i, c]
            for j in range(i):
                acc -= L[i, j] * w[j, c]
            w[i, c] = acc / L[i, i]
        for i in range(k - 1, -1, -1):
            acc = w[i, c]
            for j in range(i + 1, k):
                acc -= L[j, i] * w[j, c]
            w[i, c] = acc / L[i, i]
    return w


@njit(cache=True, nogil=True)
def _predict_bank(omega, xs, Ps, As, Qs):  # pragma: no cover - compiled
    # mixed initial conditions x0_j = sum_i omega_ij x_i,
    # P0_j = sum_i omega_ij (P_i + (x_i - x0_j)(x_i - x0_j)^T), then each model's
    # prediction A_j x0_j, A_j P0_j A_j^T + Q_j
    r, n = xs.shape
    out_x = np.empty((r, n))
    out_P = np.empty((r, n, n))
    for j in range(r):
        x0 = np.zeros(n)
        for i in range(r):
            x0 += omega[i, j] * xs[i]
        P0 = np.zeros((n, n))
        for i in range(r):
            d = xs[i] - x0
            P0 += omega[i, j] * (Ps[i] + np.outer(d, d))
        A = np.ascontiguousarray(As[j])
        out_x[j] = A @ x0
        out_P[j] = A @ P0 @ np.ascontiguousarray(A.T) + Qs[j]
    return out_x, out_P


@njit(cache=True, nogil=True)
def _gate_bank(xs, Ps, z, Hs, Rs):  # pragma: no cover - compiled
    # every model's squared Mahalanobis distance y^T S^-1 y, y = z - H x,
    # S = H P H^T + R; ok False when an S is not positive definite
    r = xs.shape[0]
    k = z.shape[0]
    d2 = np.empty(r)
    for j in range(r):
        H = np.ascontiguousarray(Hs[j])
        y = z - H @ xs[j]
        # H (P H^T), grouped as the update groups it, so the two give the same bits
        S = H @ (np.ascontiguousarray(Ps[j]) @ np.ascontiguousarray(H.T)) + Rs[j]
        L, ok = _chol(S)
        if not ok:
            return d2, False
        d2[j] = (y.reshape(1, k) @ _chol_solve(L, y.reshape(k, 1)))[0, 0]
    return d2, True


@njit(cache=True, nogil=True)
def _update_bank(xs, Ps, z, Hs, Rs, joseph):  # pragma: no cover - compiled
    # every model's Kalman update with z: K = P H^T S^-1, x + K y, the Joseph-form (or
    # simple) covariance, and y^T S^-1 y and log det S for the likelihood
    r, n = xs.shape
    k = z.shape[0]
    out_x = np.empty((r, n))
    out_P = np.empty((r, n, n))
    ys = np.empty((r, k))
    Ss = np.empty((r, k, k))
    Ks = np.empty((r, n, k))
    d2 = np.empty(r)
    logdet = np.empty(r)
    eye = np.eye(n)
    for j in range(r):
        H = np.ascontiguousarray(Hs[j])
        Ht = np.ascontiguousarray(H.T)
        P = np.ascontiguousarray(Ps[j])
        y = z - H @ xs[j]
        PHt = P @ Ht
        S = H @ PHt + Rs[j]
        L, ok = _chol(S)
        if not ok:
            return out_x, out_P, ys, Ss, Ks, d2, logdet, False
        K = np.ascontiguousarray(_chol_solve(L, np.ascontiguousarray(PHt.T)).T)
        out_x[j] = xs[j] + K @ y
        ikh = eye - K @ H
        if joseph[j]:
            R = np.ascontiguousarray(Rs[j])
            out_P[j] = ikh @ P @ np.ascontiguousarray(ikh.T) + K @ R @ np.ascontiguousarray(K.T)
        else:
            out_P[j] = ikh @ P
        ys[j] = y
        Ss[j] = S
        Ks[j] = K
        d2[j] = (y.reshape(1, k) @ _chol_solve(L, y.reshape(k, 1)))[0, 0]
        logdet[j] = 2.0 * np.log(np.diag(L)).sum()
    return out_x, out_P, ys, Ss, Ks, d2, logdet, True


class IMMEstimator:
    r"""Interacting multiple model estimator (Blom & Bar-Shalom 1988; Bar-Shalom, Li &
    Kirubarajan, *Estimation with Applications to Tracking and Navigation*, sec. 11.6).

    The equations are in the module docstring. The filters are used in place (as
    filterpy does): after each step ``filters[j].x, filters[j].P`` are the mode-matched
    estimates.

    Parameters
    ----------
    filters : sequence of KalmanFilter, length r >= 2
        One filter per motion model, all with the same ``dim_x`` and ``dim_z`` (pad a
        smaller model's state, e.g. constant position as ``[p, v]`` with ``v`` reset to
        0 by ``A``, so that the states can be mixed).
    mu : (r,) array_like
        Initial mode probabilities: non-negative, summing to 1.
    M : (r, r) array_like
        Markov transition matrix, ``M[i, j] = P(model j at k | model i at k-1)``;
        non-negative rows summing to 1 (filterpy's convention).

    Attributes
    ----------
    filters : list of KalmanFilter
    mu : (r,) ndarray
        Mode probabilities (posterior after :meth:`update`; :math:`\bar c` after
        :meth:`skip`).
    M : (r, r) ndarray
    cbar : (r,) ndarray
        Predicted mode probabilities :math:`\bar c = M^\top \mu` for the next step.
    omega : (r, r) ndarray
        Mixing probabilities ``omega[i, j] = M[i, j] mu[i] / cbar[j]``.
    x, P : ndarray, (n,) and (n, n)
        Combined (moment-matched) estimate: the prior after :meth:`predict`, the
        posterior after :meth:`update` or :meth:`skip`.
    x_prior, P_prior : ndarray
        Combined prior of the last :meth:`predict`, weighted by :math:`\bar c`.
    likelihood, log_likelihood : (r,) ndarray
        :math:`\Lambda_j` and :math:`\log \Lambda_j` of the last update (1 and 0 before
        any).

    Examples
    --------
    >>> import numpy as np
    >>> from robopercept.tracking import IMMEstimator, constant_velocity
    >>> slow = constant_velocity(dim=1, dt=1.0, q=1e-4, r=1.0)
    >>> fast = constant_velocity(dim=1, dt=1.0, q=1.0, r=1.0)
    >>> imm = IMMEstimator([slow, fast], mu=[0.9, 0.1], M=[[0.95, 0.05], [0.05, 0.95]])
    >>> for z in [0.0, 1.0, 2.0, 3.0, 10.0]:  # a jump in speed after z = 3
    ...     imm.predict()
    ...     d2 = imm.update([z])  # the measurement's squared distance, as mahalanobis2
    >>> round(d2, 1)  # the jump is far from both models' predictions
    10.5
    >>> imm.mu.round(2)  # the manoeuvring model explains the jump
    array([0.02, 0.98])
    """

    def __init__(
        self,
        filters: Sequence[KalmanFilter],
        mu: npt.ArrayLike,
        M: npt.ArrayLike,
    ) -> None:
        if not isinstance(filters, (list, tuple)):
            raise InputError(
                "filters must be a list of KalmanFilter, one per motion model; got "
                f"{type(filters).__name__} {plain_repr(filters)[:60]}"
            )
        filters = list(filters)
        if len(filters) < 2:
            raise InputError(
                f"an IMM needs at least 2 filters (one per motion model); got {len(filters)}"
            )
        for j, f in enumerate(filters):
            if not isinstance(f, KalmanFilter):
                raise InputError(
                    f"filters[{j}] must be a robopercept KalmanFilter; got {type(f).__name__}"
                )
        nx, nz = filters[0].dim_x, filters[0].dim_z
        for j, f in enumerate(filters[1:], start=1):
            if (f.dim_x, f.dim_z) != (nx, nz):
                raise InputError(
                    f"all filters must share dim_x and dim_z so that their states can be "
                    f"mixed; filters[0] has (dim_x, dim_z) = ({nx}, {nz}), filters[{j}] has "
                    f"({f.dim_x}, {f.dim_z}): pad the smaller state (e.g. constant position "
                    "as [p, v] with A zeroing v)"
                )
        r = len(filters)
        mu_a = check_numeric(mu, "mu").reshape(-1)
        if mu_a.shape != (r,):
            raise InputError(f"mu must have one probability per filter ({r}); got {mu_a.size}")
        if not np.isfinite(mu_a).all() or (mu_a < 0).any() or abs(mu_a.sum() - 1) > _SUM_TOL:
            raise InputError(
                f"mu must be a probability vector (non-negative, summing to 1); got {mu_a} "
                f"(sum {mu_a.sum():.6g}): use mu / mu.sum()"
            )
        M_a = check_numeric(M, "M")
        if M_a.shape != (r, r):
            raise InputError(f"M must be ({r}, {r}), one row per filter; got {M_a.shape}")
        rows = M_a.sum(axis=1)
        if not np.isfinite(M_a).all() or (M_a < 0).any() or (abs(rows - 1) > _SUM_TOL).any():
            raise InputError(
                "M must be a Markov transition matrix, M[i, j] = P(model j | model i), "
                f"non-negative with rows summing to 1; row sums are {rows}: "
                "use M / M.sum(axis=1, keepdims=True) (or M.T if its columns sum to 1)"
            )
        self.filters = filters
        self._bank: tuple[np.ndarray, np.ndarray, list[np.ndarray], list[np.ndarray]] | None
        self._bank = None
        self.mu = mu_a / mu_a.sum()
        self.M = M_a
        self.cbar = np.zeros(r)
        self.omega = np.zeros((r, r))
        self._mixing()
        self.likelihood = np.ones(r)
        self.log_likelihood = np.zeros(r)
        self.x, self.P = self._combine(self.mu)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    # ------------------------------------------------------------------ internals
    def _mixing(self) -> None:
        """``cbar = mu @ M``, ``omega[i, j] = M[i, j] mu[i] / cbar[j]`` (a mode that
        cannot be reached, ``cbar[j] = 0``, mixes with ``mu``: its weight is 0 anyway)."""
        self.cbar = self.mu @ self.M
        num = self.M * self.mu[:, None]
        safe = self.cbar > 0
        self.omega = np.where(safe, num / np.where(safe, self.cbar, 1.0), self.mu[:, None])

    def _stack(self) -> tuple[np.ndarray, np.ndarray]:
        """Every filter's ``x`` and ``P`` stacked, (r, n) and (r, n, n): the arrays of
        the last compiled step when the filters still hold its rows (nothing reassigned
        their ``x`` or ``P`` since), else fresh stacks."""
        bank = self._bank
        if bank is not None and all(
            f.x is bx and f.P is bP
            for f, bx, bP in zip(self.filters, bank[2], bank[3], strict=True)
        ):
            return bank[0], bank[1]
        return (
            np.stack([f.x for f in self.filters]),
            np.stack([f.P for f in self.filters]),
        )

    def _hand_out(self, xs: np.ndarray, Ps: np.ndarray) -> None:
        """Give filter ``j`` rows ``xs[j]``, ``Ps[j]`` of a compiled step's output and
        keep the stacks for the next :meth:`_stack`."""
        rows_x, rows_P = list(xs), list(Ps)
        for f, x, P in zip(self.filters, rows_x, rows_P, strict=True):
            f.x, f.P = x, P
        self._bank = (xs, Ps, rows_x, rows_P)

    def _measurement(
        self, z: npt.ArrayLike, R: npt.ArrayLike | float | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``z`` checked, and every filter's ``H`` and ``R`` (or this step's ``R``, a
        scalar meaning that multiple of the identity) stacked: (k,), (r, k, n),
        (r, k, k)."""
        nz = self.filters[0].dim_z
        zz = check_vector(z, "z", nz)
        Hs = np.stack([f.H for f in self.filters])
        if R is None:
            return zz, Hs, np.stack([f.R for f in self.filters])
        rr = check_matrix(R, "R", (nz, nz))
        return zz, Hs, np.ascontiguousarray(np.broadcast_to(rr, (len(self.filters), nz, nz)))

    def _combine(self, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xs, Ps = self._stack()
        return _moments(weights, xs, Ps)

    # ------------------------------------------------------------------ the cycle
    def predict(
        self,
        models: Sequence[tuple[npt.ArrayLike, npt.ArrayLike] | None] | None = None,
        u: npt.ArrayLike | None = None,
    ) -> None:
        r"""Mix, then predict each filter from its mixed initial condition.

        Parameters
        ----------
        models : sequence of ``(A, Q)`` or None, one per filter, optional
            This step's transition and process noise for filter ``j`` (e.g. rebuilt for
            this step's :math:`\Delta t`); ``None`` (the whole argument or one entry)
            keeps that filter's own ``A, Q``. The filters' ``A, Q`` are not changed.
        u : (dim_u,) array_like, optional
            Control input passed to every filter's ``predict``.

        Notes
        -----
        Sets the filters to :math:`(\hat x_j^-, P_j^-)`, and ``x, P, x_prior, P_prior`` to
        their moment match under :math:`\bar c` (module docstring, steps 1-2).
        """
        r, nx = len(self.filters), self.filters[0].dim_x
        overrides: list[tuple[np.ndarray, np.ndarray] | None] = [None] * r
        if models is not None:
            if not isinstance(models, (list, tuple)):
                raise InputError(
                    f"models must be a list of one (A, Q) or None per filter ({r}); got "
                    f"{plain_repr(models)[:60]}"
                )
            models = list(models)
            if len(models) != r:
                raise InputError(
                    f"models must have one (A, Q) or None per filter ({r}); got {len(models)}"
                )
            for j, m in enumerate(models):
                if m is None:
                    continue
                if not isinstance(m, (tuple, list)) or len(m) != 2:
                    raise InputError(
                        f"models[{j}] must be a pair (A, Q) or None; got {plain_repr(m)[:60]}"
                    )
                A = check_numeric(m[0], f"models[{j}] A")
                Q = check_numeric(m[1], f"models[{j}] Q")
                for name, a in (("A", A), ("Q", Q)):
                    if a.shape != (nx, nx) or not np.isfinite(a).all():
                        raise InputError(
                            f"models[{j}] {name} must be a finite ({nx}, {nx}) matrix; "
                            f"got shape {a.shape}"
                        )
                    check_magnitude(a, f"models[{j}] {name}", 1e150)
                overrides[j] = (A, Q)
        uu = None if u is None else check_numeric(u, "u")
        if uu is not None and not np.isfinite(uu).all():
            raise InputError(f"u must be finite; got {plain_repr(u)[:80]}")
        xs, Ps = self._stack()
        if uu is None:  # every filter in one compiled call
            pairs = [
                (f.A, f.Q) if ov is None else ov
                for f, ov in zip(self.filters, overrides, strict=True)
            ]
            xs, Ps = _predict_bank(
                self.omega,
                xs,
                Ps,
                np.stack([a for a, _ in pairs]),
                np.stack([q for _, q in pairs]),
            )
            self._hand_out(xs, Ps)
        else:
            x0 = self.omega.T @ xs  # x0[j] = sum_i omega[i, j] x_i
            d = xs[:, None, :] - x0[None, :, :]  # d[i, j] = x_i - x0_j
            P0 = np.einsum("ij,iab->jab", self.omega, Ps) + np.einsum(
                "ij,ija,ijb->jab", self.omega, d, d
            )
            for j, f in enumerate(self.filters):
                f.x, f.P = x0[j].copy(), P0[j].copy()
                ov = overrides[j]
                if ov is None:
                    f.predict(uu)
                else:
                    f.predict(uu, A=ov[0], Q=ov[1])
            xs, Ps = self._stack()
        self.x, self.P = _moments(self.cbar, xs, Ps)
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()

    def update(
        self,
        z: npt.ArrayLike,
        R: npt.ArrayLike | float | None = None,
        *,
        gate: float | None = None,
    ) -> float:
        r"""Update every filter with ``z``, then the mode probabilities and the
        combined estimate; with ``gate``, only if ``z`` passes it.

        Parameters
        ----------
        z : (dim_z,) array_like
        R : (dim_z, dim_z) array_like or float, optional
            Measurement noise for this step, for every filter (a scalar is a multiple of
            the identity); default each filter's own ``R``.
        gate : float, optional
            Largest accepted :meth:`mahalanobis2` (e.g. a :math:`\chi^2_{d_z}` quantile).
            When the smallest distance exceeds it nothing changes: the estimator stays
            as :meth:`predict` left it (call :meth:`skip` to close the step as a miss).
            One pass computes the distances and the updates, instead of
            :meth:`mahalanobis2` then :meth:`update`.

        Returns
        -------
        float
            The smallest squared Mahalanobis distance of ``z``, as :meth:`mahalanobis2`.

        Notes
        -----
        :math:`\log\Lambda_j = -\tfrac12 (y_j^\top S_j^{-1} y_j + \log\det S_j +
        d_z \log 2\pi)`; :math:`\mu_j \propto \bar c_j \Lambda_j`, normalized in the log
        domain; if no mode has a finite weight (cannot happen with finite inputs),
        :math:`\mu = \bar c`. Then :math:`\bar c` and :math:`\omega` for the next step and
        the moment-matched ``x, P`` (module docstring, steps 3-4).
        """
        nz = self.filters[0].dim_z
        limit = None if gate is None else check_real(gate, "gate", 0.0)
        zz, Hs, Rs = self._measurement(z, R)
        xs, Ps = self._stack()
        joseph = np.array([f.joseph for f in self.filters])
        xs, Ps, ys, Ss, Ks, d2, logdet, ok = _update_bank(xs, Ps, zz, Hs, Rs, joseph)
        if not ok:
            raise DegenerateError(_NOT_PD)
        nearest = float(d2.min())
        if limit is not None and not nearest <= limit:
            return nearest
        self._hand_out(xs, Ps)
        for j, f in enumerate(self.filters):
            f.y, f.S, f.K = ys[j], Ss[j], Ks[j]
        logl = -0.5 * (d2 + logdet + nz * np.log(2.0 * np.pi))
        self.log_likelihood = logl
        self.likelihood = np.exp(logl)
        with np.errstate(divide="ignore"):
            w = np.log(self.cbar) + logl
        top = w.max()
        if np.isfinite(top):
            p = np.exp(w - top)
            self.mu = p / p.sum()
        else:
            self.mu = self.cbar.copy()
        self._mixing()
        self.x, self.P = self._combine(self.mu)
        return nearest

    def skip(self) -> None:
        r"""A step without a measurement (missed detection), after :meth:`predict`.

        Nothing discriminates the modes, so :math:`\mu = \bar c`; :math:`\bar c` and
        :math:`\omega` are recomputed from it for the next step; each filter keeps its
        prediction as its estimate and ``x, P`` are the combined prior.
        """
        self.mu = self.cbar.copy()
        self._mixing()
        self.x, self.P = self._combine(self.mu)

    # ------------------------------------------------------------------ gating
    def mahalanobis2(self, z: npt.ArrayLike, R: npt.ArrayLike | float | None = None) -> float:
        r"""Smallest squared Mahalanobis distance of ``z`` over the models' predictions,
        :math:`\min_j y_j^\top S_j^{-1} y_j` (call after :meth:`predict`).

        A measurement is plausible when any model finds it so. If model :math:`j` is
        the true one, :math:`y_j^\top S_j^{-1} y_j \sim \chi^2_{d_z}`, so the gate
        :math:`\min_j d_j^2 \le \chi^2_{d_z}(p)` keeps a true measurement with
        probability at least :math:`p` whatever the mode. Gating on the low-noise model,
        or on the dominant one, would reject exactly the measurements that reveal a
        manoeuvre, and the IMM could never switch modes; the moment-matched
        :meth:`innovation` approximates a multimodal mixture by one Gaussian and
        can be too tight or too loose in both directions.

        Parameters
        ----------
        z : (dim_z,) array_like
        R : (dim_z, dim_z) array_like or float, optional
            Measurement noise for this step (default each filter's own).

        Returns
        -------
        float
        """
        zz, Hs, Rs = self._measurement(z, R)
        xs, Ps = self._stack()
        d2, ok = _gate_bank(xs, Ps, zz, Hs, Rs)
        if not ok:
            raise DegenerateError(_NOT_PD)
        return float(d2.min())

    def innovation(
        self, z: npt.ArrayLike, R: npt.ArrayLike | float | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        r"""Innovation of ``z`` against the combined (moment-matched) predicted
        measurement (call after :meth:`predict`).

        With :math:`\hat z_j = H_j \hat x_j^-`, :math:`S_j = H_j P_j^- H_j^\top + R_j`
        and weights :math:`\bar c_j`:

        .. math:: \hat z = \sum_j \bar c_j \hat z_j, \quad y = z - \hat z, \quad
                  S = \sum_j \bar c_j \left(S_j + (\hat z_j - \hat z)
                  (\hat z_j - \hat z)^\top\right)

        (equal to ``z - H x_prior`` and ``H P_prior H^T + R`` when the filters share
        ``H`` and ``R``).

        Parameters
        ----------
        z : (dim_z,) array_like
        R : (dim_z, dim_z) array_like or float, optional

        Returns
        -------
        y : (dim_z,) ndarray
        S : (dim_z, dim_z) ndarray
        """
        nz = self.filters[0].dim_z
        zz = check_vector(z, "z", nz)
        rr = None if R is None else check_matrix(R, "R", (nz, nz))
        parts = [f.innovation(zz, R=rr) for f in self.filters]
        zhat = np.stack([zz - y for y, _ in parts])
        Ss = np.stack([S for _, S in parts])
        zc, S = _moments(self.cbar, zhat, Ss)
        return zz - zc, S
