r"""The RANSAC engine (Fischler & Bolles 1981) with adaptive stopping, MSAC scoring,
LO-RANSAC and batched hypothesis scoring.

The loop:

1. draw ``B`` random minimal samples at once (a batch); samples with a repeated index or
   that the model calls degenerate (collinear, coincident points) are redrawn;
2. fit one hypothesis per sample;
3. score all hypotheses of the batch against the data in chunks of rows (so the
   ``B x chunk`` residual matrix stays small, whatever the number of points):

   - ``"ransac"``: the number of inliers :math:`|\{i : r_i < t\}|` (higher is better),
   - ``"msac"`` (Torr & Zisserman 2000): the truncated loss
     :math:`\sum_i \min(r_i^2, t^2)` (lower is better; scores are its negative, so that
     for both rules the engine keeps the highest score);

4. keep the best; with ``local_optimization`` (LO-RANSAC, Chum et al. 2003) every new
   best is refined by iterated least-squares fits on its inliers while that improves the
   score;
5. update the number of iterations needed to draw, with probability ``p``, at least one
   all-inlier sample, from the best inlier ratio ``w`` so far:

   .. math:: k = \frac{\log(1 - p)}{\log(1 - w^n)}

   (:math:`k = \infty` while no hypothesis has an inlier, :math:`w = 0`: the bound stays
   ``max_iterations``) and stop once ``k`` samples have been drawn, ``max_iterations``
   is reached, or the best hypothesis has ``min_inliers`` inliers;
6. refit the model by least squares on the inliers of the best hypothesis, and keep the
   refit if it scores at least as well.

Randomness comes only from ``rng``, drawn in a fixed order, and the scoring adds its
partial sums in a fixed order (NumPy arithmetic, or the plane model's compiled blocks
summed in block order), so a seed gives the same result on any number of threads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Generic, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    as_rng,
    check_bool,
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    check_points,
    check_real,
)
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.least_squares import MAX_COORDINATE
from robopercept.estimation.models import Model

__all__ = ["RansacResult", "ransac", "required_iterations"]

Scoring = Literal["ransac", "msac"]
ResultT = TypeVar("ResultT")  # the model's typed result: Line, Plane, a 3x3 ndarray

_MAX_REDRAWS = 100  # consecutive all-degenerate batches before giving up
_MAX_BATCH = 65536  # hypotheses per batch: bounds the (batch, rows) sample arrays


@dataclass(frozen=True)
class RansacResult(Generic[ResultT]):
    r"""Result of :func:`ransac`, generic over the type of the model's result
    (``RansacResult[Plane]`` for a :class:`~robopercept.estimation.PlaneModel`).

    Attributes
    ----------
    model : ResultT
        The model's typed result, ``model.result(params)``
        (:class:`~robopercept.estimation.Plane`, :class:`~robopercept.estimation.Line`, a
        3x3 ndarray).
    params : (P,) float ndarray
        The raw parameters.
    inliers : (N,) bool ndarray
        Rows whose residual is below the threshold.
    n_iterations : int
        Minimal samples drawn and scored (redrawn degenerate samples not counted).
    score : float
        Higher is better: the inlier count (``"ransac"``), or MINUS the truncated squared
        loss, :math:`-\sum_i \min(r_i^2, t^2) \le 0` (``"msac"``), of ``params``.
    """

    model: ResultT
    params: np.ndarray
    inliers: np.ndarray
    n_iterations: int
    score: float

    @property
    def n_inliers(self) -> int:
        """Number of inliers."""
        return int(np.count_nonzero(self.inliers))

    @property
    def inlier_ratio(self) -> float:
        """Inliers / rows."""
        return self.n_inliers / max(self.inliers.shape[0], 1)


def required_iterations(inlier_ratio: float, sample_size: int, probability: float) -> float:
    r"""Samples needed to draw one all-inlier sample with ``probability``:
    :math:`\log(1 - p) / \log(1 - w^n)` (``inf`` when ``w = 0``, ``0`` when ``w = 1``).

    Parameters
    ----------
    inlier_ratio : float
        :math:`w` in [0, 1].
    sample_size : int
        :math:`n \ge 1`.
    probability : float
        :math:`p` in [0, 1].

    Returns
    -------
    float

    Raises
    ------
    InputError
        A parameter of the wrong type or out of its range.

    Examples
    --------
    >>> round(required_iterations(0.5, 4, 0.99), 2)  # log(0.01) / log(1 - 1/16)
    71.36
    """
    inlier_ratio = check_real(inlier_ratio, "inlier_ratio", 0.0, 1.0)
    sample_size = check_int(sample_size, "sample_size", 1)
    probability = check_real(probability, "probability", 0.0, 1.0)
    good = inlier_ratio**sample_size
    if good <= 0.0:
        return math.inf
    if good >= 1.0 or probability <= 0.0:
        return 0.0
    if probability >= 1.0:
        return math.inf
    return math.log(1.0 - probability) / math.log1p(-good)


def _draw(rng: np.random.Generator, n: int, size: int, batch: int) -> np.ndarray:
    """(batch, size) row indices; rows with a repeated index are marked by -1 in col 0."""
    if n <= 64:  # small data: permutation prefixes, never a repeat
        return np.argsort(rng.random((batch, n)), axis=1)[:, :size]
    idx = rng.integers(0, n, size=(batch, size))
    s = np.sort(idx, axis=1)
    dup = (s[:, 1:] == s[:, :-1]).any(axis=1)
    idx[dup, 0] = -1
    return idx


def _refine(
    model: Model[Any],
    params: np.ndarray,
    x: np.ndarray,
    prepared: Any,
    threshold: float,
    msac: bool,
    rounds: int,
) -> tuple[np.ndarray, float, int]:
    """Iterated least-squares refits on the inliers while the score does not drop."""
    score, count = model.score(params[None], prepared, threshold, msac)
    best = (params, float(score[0]), int(count[0]))
    for _ in range(rounds):
        mask = model.inlier_mask(best[0], prepared, threshold)
        if np.count_nonzero(mask) <= model.sample_size:
            break
        try:
            cand = np.asarray(model.fit_inliers(x, mask), dtype=np.float64)
        except DegenerateError:
            break
        if not np.isfinite(cand).all():
            break
        s, c = model.score(cand[None], prepared, threshold, msac)
        if s[0] < best[1]:  # ties go to the least-squares fit
            break
        best = (cand, float(s[0]), int(c[0]))
    return best


def ransac(
    data: npt.ArrayLike,
    model: Model[ResultT],
    threshold: float,
    *,
    sample_size: int | None = None,
    max_iterations: int = 1000,
    probability: float = 0.99,
    min_inliers: int | None = None,
    scoring: Scoring = "ransac",
    local_optimization: bool = False,
    batch_size: int = 8,
    initial: npt.ArrayLike | None = None,
    rng: int | np.random.Generator | None = None,
) -> RansacResult[ResultT]:
    r"""Robustly fit ``model`` to ``data`` (see the module docstring for the algorithm).

    Parameters
    ----------
    data : (N, D) array_like
        One row per observation (points, or correspondences ``(x, y, x', y')``); finite,
        within 1e150 in magnitude.
    model : Model
        :class:`LineModel`, :class:`PlaneModel`, :class:`AffineModel`,
        :class:`HomographyModel` or any object satisfying the :class:`Model` protocol.
    threshold : float
        Inlier threshold on the model's residual (> 0), in data units.
    sample_size : int, optional
        Rows per minimal sample; default ``model.sample_size`` (a larger sample is fitted
        by least squares).
    max_iterations : int
        Upper bound on samples drawn.
    probability : float
        Desired probability ``p`` in [0, 1) of drawing one all-inlier sample (adaptive
        stopping).
    min_inliers : int, optional
        Stop as soon as a hypothesis has this many inliers.
    scoring : {'ransac', 'msac'}
    local_optimization : bool
        LO-RANSAC: refine each new best by iterated least squares on its inliers.
    batch_size : int
        Hypotheses drawn and scored together, 1 to 65536 (a bound on the memory of
        the batch's samples and residual blocks).
    initial : (K, P) array_like, optional
        Hypotheses in the model's parameter form (e.g. a plane predicted by a tracker)
        scored before any random sample; each counts as one iteration, and a good one
        stops the search at once through ``min_inliers`` or the adaptive bound.
    rng : int, Generator or None
        Seed or generator; the same seed gives the same result.

    Returns
    -------
    RansacResult[ResultT]
        ``model`` is ``model.result(params)``; ``score`` is higher-is-better (the inlier
        count, or minus the MSAC loss).

    Raises
    ------
    InputError
        Data that is not a finite ``(N, D)`` array within 1e150, a ``model`` that is not
        a :class:`Model`, a parameter of the wrong type or range (a negative ``rng``
        seed included).
    DegenerateError
        Fewer rows than ``sample_size``, data that cannot determine the model (e.g. all
        points collinear for a plane), or only degenerate samples drawn.

    Examples
    --------
    A line through 50 points, every tenth one moved off it:

    >>> from robopercept.estimation import LineModel
    >>> x = np.linspace(0.0, 1.0, 50)
    >>> data = np.column_stack([x, 2 * x + 1]); data[::10, 1] += 3.0
    >>> result = ransac(data, LineModel(), threshold=0.01, rng=0)
    >>> int(result.inliers.sum()), np.flatnonzero(~result.inliers).tolist()
    (45, [0, 10, 20, 30, 40])
    """
    # (a subclass of Model is one: the protocol's own isinstance walks every attribute,
    # 40 us a call)
    if Model not in type(model).__mro__ and not isinstance(model, Model):
        raise InputError(
            f"model must be a robopercept.estimation Model (e.g. PlaneModel()); got {model!r}"
        )
    x = check_points(data, "data", model.dim)
    if not np.isfinite(x).all():
        raise InputError(
            "data must be finite; drop NaN/inf rows first: data[np.isfinite(data).all(1)]"
        )
    check_magnitude(x, "data", MAX_COORDINATE)  # the models square coordinates
    threshold = check_real(threshold, "threshold", 0.0, None, low_inclusive=False)
    probability = check_real(probability, "probability", 0.0, 1.0, high_inclusive=False)
    check_choice(scoring, "scoring", ("ransac", "msac"))
    local_optimization = check_bool(local_optimization, "local_optimization")
    max_iterations = check_int(max_iterations, "max_iterations", 1)
    batch_size = check_int(batch_size, "batch_size", 1)
    check_real(batch_size, "batch_size", 1, _MAX_BATCH)
    n_sample = model.sample_size if sample_size is None else check_int(sample_size, "sample_size")
    if n_sample < model.sample_size:
        raise InputError(
            f"sample_size must be >= {model.sample_size} for a {model.name}; got {n_sample}"
        )
    if min_inliers is not None:
        min_inliers = check_int(min_inliers, "min_inliers", 1)
    n = x.shape[0]
    if n < n_sample:
        raise DegenerateError(
            f"a {model.name} needs samples of {n_sample} rows; the data has only {n}"
        )
    model.check(x)
    prepared = model.prepare(x)
    gen = as_rng(rng)
    msac = scoring == "msac"

    best_params: np.ndarray | None = None
    best_score = -math.inf
    best_count = -1
    needed = float(max_iterations)
    drawn = 0
    redraws = 0
    if initial is not None:
        init = np.atleast_2d(check_numeric(initial, "initial"))
        # P, the parameters of one hypothesis: the width of a minimal fit's output
        width = model.fit_minimal(x[None, : model.sample_size])[0].shape[1]
        if init.ndim != 2 or init.shape[0] < 1 or init.shape[1] != width:
            raise InputError(
                f"initial must be (K, {width}) {model.name} parameters, K >= 1; got shape "
                f"{init.shape}"
            )
        if not np.isfinite(init).all():
            raise InputError("initial must be finite; drop the hypotheses with NaN/inf")
        scores, counts = model.score(init, prepared, threshold, msac)
        k = int(np.argmax(scores))
        best_params, best_score, best_count = init[k], float(scores[k]), int(counts[k])
        drawn = init.shape[0]
        needed = min(
            required_iterations(best_count / n, model.sample_size, probability),
            float(max_iterations),
        )
        if min_inliers is not None and best_count >= min_inliers:
            needed = 0.0
    while drawn < min(needed, max_iterations):
        b = int(min(batch_size, max_iterations - drawn, max(math.ceil(needed) - drawn, 1)))
        idx = _draw(gen, n, n_sample, b)
        ok = idx[:, 0] >= 0
        samples = x[np.where(ok[:, None], idx, 0)]
        if n_sample == model.sample_size:
            params, valid = model.fit_minimal(samples)
        else:
            params, valid = _fit_each(model, samples)
        valid &= ok & np.isfinite(params).all(axis=1)
        if not valid.any():
            redraws += 1
            if redraws > _MAX_REDRAWS:
                raise DegenerateError(
                    f"{redraws * b} random samples were all degenerate: the data cannot "
                    f"determine a {model.name} (repeated or collinear points?)"
                )
            continue
        redraws = 0
        params = params[valid]
        drawn += params.shape[0]
        scores, counts = model.score(params, prepared, threshold, msac)
        k = int(np.argmax(scores))
        if scores[k] > best_score or (scores[k] == best_score and counts[k] > best_count):
            cand, score, count = params[k], float(scores[k]), int(counts[k])
            if local_optimization:
                cand, score, count = _refine(model, cand, x, prepared, threshold, msac, rounds=5)
            best_params, best_score, best_count = cand, score, count
            # w = 0 (no inliers yet) gives k = inf: keep max_iterations
            needed = min(
                required_iterations(best_count / n, model.sample_size, probability),
                float(max_iterations),
            )
        if min_inliers is not None and best_count >= min_inliers:
            break

    assert best_params is not None
    # final least-squares refit on the inliers, kept when it scores at least as well
    refit, score, _ = _refine(model, best_params, x, prepared, threshold, msac, rounds=1)
    inliers = model.inlier_mask(refit, prepared, threshold)
    return RansacResult(model.result(refit), refit, inliers, drawn, score)


def _fit_each(model: Model[Any], samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares fits of non-minimal samples, one at a time."""
    out: list[np.ndarray | None] = []
    valid = np.ones(samples.shape[0], dtype=bool)
    for i, s in enumerate(samples):
        try:
            out.append(np.asarray(model.fit(s), dtype=np.float64))
        except DegenerateError:
            valid[i] = False
            out.append(None)
    width = next((len(p) for p in out if p is not None), 1)
    params = np.array([p if p is not None else np.zeros(width) for p in out])
    return params, valid
