r"""Homography from point matches: RANSAC on the normalized DLT, then a nonlinear
refinement of the transfer error.

Given matches :math:`x_i \leftrightarrow x'_i` (some wrong), :func:`find_homography`
runs the RANSAC engine with :class:`HomographyModel` (minimal samples of 4, MSAC scoring,
local optimization), refits on the inliers by the normalized DLT, and then minimizes
:math:`\sum_i \|\pi(H x_i) - x'_i\|^2` over the inliers with Levenberg-Marquardt
(``scipy.optimize.least_squares``), as ``cv2.findHomography(..., cv2.RANSAC)`` does.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from robopercept._checks import check_bool, check_points, resolve_alias
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.models import HomographyModel
from robopercept.estimation.ransac import ransac

__all__ = ["HomographyFit", "find_homography"]


@dataclass(frozen=True)
class HomographyFit:
    """Result of :func:`find_homography`.

    It unpacks as the tuple of ``H, mask = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)``:
    ``H, mask = find_homography(src, dst)`` gives ``H`` (3, 3) float64 and ``mask``
    (N, 1) uint8, 1 for the inliers and 0 for the rest (OpenCV's shape and values;
    :attr:`inliers` is the same as an (N,) bool array). The attributes stay the primary
    interface.

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

    @property
    def mask(self) -> np.ndarray:
        """:attr:`inliers` as OpenCV's inlier mask: (N, 1) uint8, 1 for an inlier."""
        return self.inliers.astype(np.uint8).reshape(-1, 1)

    def __iter__(self) -> Iterator[np.ndarray]:
        """``H, mask``, the order of ``cv2.findHomography``'s result."""
        return iter((self.H, self.mask))


def _transfer(h: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    q = src @ h[:2, :2].T + h[:2, 2]
    w = src @ h[2, :2] + h[2, 2]
    return (q / w[:, None] - dst).ravel()


def find_homography(
    src: np.ndarray,
    dst: np.ndarray,
    threshold: float | None = None,
    *,
    max_iterations: int | None = None,
    probability: float | None = None,
    refine: bool = True,
    rng: int | np.random.Generator | None = 0,
    ransacReprojThreshold: float | None = None,
    maxIters: int | None = None,
    confidence: float | None = None,
) -> HomographyFit:
    """Robust homography from matched points (``cv2.findHomography(src, dst, cv2.RANSAC,
    threshold)``).

    Parameters
    ----------
    src, dst : (N, 2) or (N, 1, 2) array_like
        Matched ``(x, y)`` positions, row i of ``src`` matching row i of ``dst``
        (OpenCV's ``(N, 1, 2)`` point vectors too).
    threshold : float, default 3.0
        Inlier threshold on the transfer error :math:`\\|\\pi(H x) - x'\\|`, pixels
        (OpenCV's ``ransacReprojThreshold``). The method is always RANSAC: an ``int``
        4, 8 or 16 here (``cv2.LMEDS``, ``cv2.RANSAC``, ``cv2.RHO`` in OpenCV's third
        place) is taken as pixels, with a warning naming the fix.
    max_iterations : int, default 2000
        Upper bound on RANSAC samples (OpenCV's ``maxIters``).
    probability : float, default 0.995
        Confidence of the adaptive stopping rule (OpenCV's ``confidence``).
    refine : bool
        Levenberg-Marquardt refinement of the transfer error over the inliers.
    rng : int, Generator or None
        Seed (default 0: the same matches give the same H).
    ransacReprojThreshold, maxIters, confidence
        Keyword-only aliases (OpenCV's names) of ``threshold``, ``max_iterations`` and
        ``probability``; giving both spellings of one is an InputError.

    Returns
    -------
    HomographyFit
        Unpacks as ``H, mask`` in the order of ``cv2.findHomography``.

    Raises
    ------
    DegenerateError
        Fewer than 4 matches, all points collinear, or no valid sample.
    InputError
        Mismatched or non-finite inputs, or a parameter of the wrong type or range.

    Examples
    --------
    >>> src = np.array([[0, 0], [10, 0], [10, 10], [0, 10], [5, 3]], float)
    >>> H, mask = find_homography(src, 2 * src + 1)
    >>> (np.round(H, 6) + 0.0).tolist(), mask.ravel().tolist()
    ([[2.0, 0.0, 1.0], [0.0, 2.0, 1.0], [0.0, 0.0, 1.0]], [1, 1, 1, 1, 1])
    """
    threshold = resolve_alias(
        threshold, "threshold", ransacReprojThreshold, "ransacReprojThreshold", "OpenCV"
    )
    if type(threshold) is int and threshold in (4, 8, 16):
        warnings.warn(
            f"find_homography's third argument is the inlier threshold in pixels, so "
            f"{threshold} is read as {threshold} px; if you meant OpenCV's method constant "
            "(cv2.RANSAC is 8), leave it out: the method is always RANSAC. Pass "
            "threshold=float (OpenCV's ransacReprojThreshold, default 3.0) to silence this",
            UserWarning,
            stacklevel=2,
        )
    threshold = 3.0 if threshold is None else threshold
    max_iterations = resolve_alias(max_iterations, "max_iterations", maxIters, "maxIters", "OpenCV")
    max_iterations = 2000 if max_iterations is None else max_iterations
    probability = resolve_alias(probability, "probability", confidence, "confidence", "OpenCV")
    probability = 0.995 if probability is None else probability
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
