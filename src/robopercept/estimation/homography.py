r"""Homography from point matches: RANSAC on the normalized DLT, then a nonlinear
refinement of the transfer error.

Given matches :math:`x_i \leftrightarrow x'_i` (some wrong), :func:`find_homography`
runs the RANSAC engine with :class:`HomographyModel` (minimal samples of 4, MSAC scoring,
local optimization), refits on the inliers by the normalized DLT, and then minimizes
:math:`\sum_i \|\pi(H x_i) - x'_i\|^2` over the inliers with Levenberg-Marquardt
(``scipy.optimize.least_squares``), as ``cv2.findHomography(..., cv2.RANSAC)`` does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robopercept._checks import check_bool, check_points
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.models import HomographyModel
from robopercept.estimation.ransac import ransac

__all__ = ["HomographyFit", "find_homography"]


@dataclass(frozen=True)
class HomographyFit:
    """Result of :func:`find_homography`.

    Attributes
    ----------
    H : (3, 3) float64 ndarray
        Maps source points to destination points, :math:`h_{33} = 1`.
    inliers : (N,) bool ndarray
        Matches whose transfer error is below the threshold.
    rms : float
        Root-mean-square transfer error of the inliers, in pixels; NaN when no match is
        within the threshold (``n_inliers == 0``).
    n_iterations : int
        RANSAC samples drawn.
    """

    H: np.ndarray
    inliers: np.ndarray
    rms: float
    n_iterations: int

    @property
    def n_inliers(self) -> int:
        """Number of inliers."""
        return int(np.count_nonzero(self.inliers))


def _transfer(h: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    q = src @ h[:2, :2].T + h[:2, 2]
    w = src @ h[2, :2] + h[2, 2]
    return (q / w[:, None] - dst).ravel()


def find_homography(
    src: np.ndarray,
    dst: np.ndarray,
    threshold: float = 3.0,
    *,
    max_iterations: int = 2000,
    probability: float = 0.995,
    refine: bool = True,
    rng: int | np.random.Generator | None = 0,
) -> HomographyFit:
    """Robust homography from matched points.

    Parameters
    ----------
    src, dst : (N, 2) array_like
        Matched ``(x, y)`` positions, row i of ``src`` matching row i of ``dst``.
    threshold : float
        Inlier threshold on the transfer error :math:`\\|\\pi(H x) - x'\\|`, pixels.
    max_iterations : int
        Upper bound on RANSAC samples.
    probability : float
        Confidence of the adaptive stopping rule.
    refine : bool
        Levenberg-Marquardt refinement of the transfer error over the inliers.
    rng : int, Generator or None
        Seed (default 0: the same matches give the same H).

    Returns
    -------
    HomographyFit

    Raises
    ------
    DegenerateError
        Fewer than 4 matches, all points collinear, or no valid sample.
    InputError
        Mismatched or non-finite inputs, or a parameter of the wrong type or range.
    """
    a = check_points(src, "src", 2)
    b = check_points(dst, "dst", 2)
    if a.shape != b.shape:
        raise InputError(f"src and dst must have the same shape; got {a.shape} and {b.shape}")
    if a.shape[0] < 4:
        raise DegenerateError(
            f"a homography needs at least 4 matches; got {a.shape[0]}: "
            "relax the ratio test or use images that overlap more"
        )
    refine = check_bool(refine, "refine")
    data = np.concatenate([a, b], axis=1)
    if not np.isfinite(data).all():
        raise InputError("src and dst must be finite")
    res = ransac(
        data,
        HomographyModel(),
        threshold,
        max_iterations=max_iterations,
        probability=probability,
        scoring="msac",
        local_optimization=True,
        rng=rng,
    )
    h = res.model / res.model[2, 2]
    inl = res.inliers
    if refine and inl.sum() >= 5:
        from scipy.optimize import least_squares

        sa, sb = a[inl], b[inl]
        sol = least_squares(
            lambda p: _transfer(np.append(p, 1.0).reshape(3, 3), sa, sb),
            h.ravel()[:8],
            method="lm",
        )
        cand = np.append(sol.x, 1.0).reshape(3, 3)
        err_new = np.linalg.norm(_transfer(cand, sa, sb).reshape(-1, 2), axis=1)
        err_old = np.linalg.norm(_transfer(h, sa, sb).reshape(-1, 2), axis=1)
        if np.isfinite(err_new).all() and (err_new**2).sum() <= (err_old**2).sum():
            h = cand
            err = np.linalg.norm(_transfer(h, a, b).reshape(-1, 2), axis=1)
            inl = err < threshold
    err = np.linalg.norm(_transfer(h, a[inl], b[inl]).reshape(-1, 2), axis=1)
    rms = float(np.sqrt(np.mean(err**2))) if err.size else float("nan")
    return HomographyFit(h, inl, rms, res.n_iterations)
