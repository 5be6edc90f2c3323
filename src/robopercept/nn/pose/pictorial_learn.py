r"""Learning a pictorial-structures pose model from images with keypoints: the part
appearance (grid descriptors and one logistic-regression part detector per joint) and
the deformation springs, under the scikit-learn estimator contract; the pose of least
energy is found exactly by :mod:`robopercept.nn.pose.pictorial`.

NumPy only (no torch).

:class:`PictorialStructures` learns a pictorial-structures model from images with
keypoints, with the scikit-learn contract: the springs from the mean and the (diagonal)
variance of :math:`l_i - l_{p(i)}` over labelled pairs (:math:`w = 1 / (2 \sigma^2)`,
the Gaussian's negative log-likelihood), and one linear appearance classifier per joint
(L2-regularized logistic regression, scikit-learn's ``LogisticRegression`` objective)
on :func:`grid_descriptors`: gradient-orientation histograms
(:func:`robopercept.features.cell_histograms`) and colour means of the cells around
each point of a coarse grid. The unary cost is :math:`c_i = -\log \sigma(s_i)` with
:math:`s_i` the classifier's score.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import minimize
from scipy.special import expit

from robopercept._checks import (
    as_rng,
    check_image,
    check_int,
    check_numeric,
    check_real,
)
from robopercept.errors import DegenerateError, InputError, NotFittedError
from robopercept.features import cell_histograms
from robopercept.nn.pose.pictorial import check_tree, solve_tree
from robopercept.nn.skeleton import Skeleton

__all__ = ["PictorialStructures", "grid_descriptors"]

_MAX_RADIUS = 8  # grid_descriptors neighbourhood (the descriptor grows as (2r+1)^2)
_MAX_CELL = 65536
_MAX_COORD = 1e9  # keypoint coordinates, pixels
_HIST_EPS = 1.0  # block normalization of the orientation histograms (0..255 scale)


# ============================================================================ descriptors


def _unit_image(image: npt.ArrayLike, name: str) -> np.ndarray:
    """``image`` as float64 (H, W, 3): uint8 / 255, uint16 / 65535, gray repeated."""
    img = check_image(image, name)
    if img.dtype == np.uint8:
        out = img / 255.0
    elif img.dtype == np.uint16:
        out = img / 65535.0
    else:
        out = img.astype(np.float64)
    if out.ndim == 2:
        out = np.repeat(out[:, :, None], 3, axis=2)
    return out


def _descriptors(img: np.ndarray, cell: int, radius: int, orientations: int) -> np.ndarray:
    """grid_descriptors of a checked float64 (H, W, 3) image."""
    h, w = img.shape[:2]
    gh, gw = h // cell, w // cell
    if gh == 0 or gw == 0:
        raise InputError(
            f"image of {h}x{w} pixels is smaller than one {cell}x{cell} cell: use a larger "
            "image or a smaller cell"
        )
    hist = cell_histograms(img, cell, orientations)  # (gh, gw, nb), 0..255 gradient scale
    colour = img[: gh * cell, : gw * cell].reshape(gh, cell, gw, cell, 3).mean(axis=(1, 3))
    k = 2 * radius + 1

    def neighbourhoods(a: np.ndarray) -> np.ndarray:
        # (gh, gw, c) -> (gh, gw, k * k * c): the k x k cells around each cell, edges
        # repeated, row by row
        padded = np.pad(a, ((radius, radius), (radius, radius), (0, 0)), mode="edge")
        win = np.lib.stride_tricks.sliding_window_view(padded, (k, k), axis=(0, 1))
        return np.moveaxis(win, 2, 4).reshape(gh, gw, -1)

    blocks = neighbourhoods(hist)
    blocks = blocks / np.sqrt((blocks**2).sum(axis=2, keepdims=True) + _HIST_EPS**2)
    return np.concatenate([blocks, neighbourhoods(colour)], axis=2)


def _check_descriptor_params(cell: Any, radius: Any, orientations: Any) -> tuple[int, int, int]:
    c = check_int(cell, "cell", 1)
    if c > _MAX_CELL:
        raise InputError(f"cell must be at most {_MAX_CELL} pixels; got {c}")
    r = check_int(radius, "radius", 0)
    if r > _MAX_RADIUS:
        raise InputError(
            f"radius must be at most {_MAX_RADIUS} cells (the descriptor grows as "
            f"(2 radius + 1)^2); got {r}"
        )
    o = check_int(orientations, "orientations", 1)
    if o > 360:
        raise InputError(f"orientations must be in [1, 360]; got {o}")
    return c, r, o


def grid_descriptors(
    image: npt.ArrayLike, cell: int = 4, radius: int = 1, orientations: int = 9
) -> np.ndarray:
    r"""Local appearance descriptors on a grid of ``cell``-pixel cells: the part
    detectors' input of :class:`PictorialStructures`.

    For every cell :math:`(g_y, g_x)` of the ``(H // cell, W // cell)`` grid, the
    :math:`k \times k` cells around it (:math:`k = 2\,\mathrm{radius} + 1`, image edges
    repeated) contribute

    * their gradient-orientation histograms (:func:`robopercept.features.cell_histograms`:
      unsigned orientations, votes split between the two nearest bins, gradients on the
      0..255 scale), concatenated into :math:`v` and normalized together as
      :math:`v / \sqrt{\lVert v \rVert^2 + 1}` (HOG's L2 block norm), and
    * their mean colours (R, G, B in [0, 1]).

    Layout: the :math:`k^2` histograms row by row, then the :math:`k^2` colours row by
    row.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 images are divided by 255 and uint16 by 65535; floating point images are
        used as they are (expected in [0, 1]); gray images count as R = G = B.
    cell : int
        Cell side in pixels; pixels beyond the last whole cell are left out.
    radius : int
        Neighbourhood radius in cells (at most 8).
    orientations : int
        Histogram bins over [0, pi).

    Returns
    -------
    (H // cell, W // cell, k * k * (orientations + 3)) float64 ndarray

    Raises
    ------
    InputError
        If the image is not an image or is smaller than one cell, or a parameter is out
        of range.

    Examples
    --------
    >>> img = np.zeros((16, 24, 3))
    >>> img[:, 12:] = (1.0, 0.0, 0.0)          # a red right half: a vertical edge
    >>> d = grid_descriptors(img, cell=4, radius=1, orientations=9)
    >>> d.shape
    (4, 6, 108)
    >>> d[0, 4, 81 + 12:81 + 15].tolist()     # the centre cell's mean colour
    [1.0, 0.0, 0.0]
    """
    c, r, o = _check_descriptor_params(cell, radius, orientations)
    return _descriptors(_unit_image(image, "image"), c, r, o)


# ============================================================================ the model


def _fit_logistic(X: np.ndarray, y: np.ndarray, C: float) -> tuple[np.ndarray, float]:
    """L2-regularized logistic regression, scikit-learn's objective (intercept free):
    min_w,b 1/2 |w|^2 + C sum_i log(1 + exp(-t_i (w . x_i + b))), t = 2 y - 1, by
    trust-region Newton-CG (liblinear's method) with exact Hessian-vector products."""
    t = np.where(y > 0, 1.0, -1.0)
    n, d = X.shape

    # everything divided by n: the gradient tolerance is then relative to the data
    def objective(theta: np.ndarray) -> tuple[float, np.ndarray]:
        w, b = theta[:d], theta[d]
        m = t * (X @ w + b)
        loss = C * np.logaddexp(0.0, -m).sum() + 0.5 * float(w @ w)
        g = -C * t * expit(-m)  # d loss / d (w . x + b)
        grad = np.empty(d + 1)
        grad[:d] = X.T @ g + w
        grad[d] = g.sum()
        return loss / n, grad / n

    def hessp(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
        m = t * (X @ theta[:d] + theta[d])
        u = C * expit(m) * expit(-m) * (X @ v[:d] + v[d])
        out = np.empty(d + 1)
        out[:d] = X.T @ u + v[:d]
        out[d] = u.sum()
        return out / n

    # (L-BFGS-B would do too, but its many tiny BLAS calls crawl on a busy machine)
    res = minimize(
        objective,
        np.zeros(d + 1),
        jac=True,
        hessp=hessp,
        method="trust-ncg",
        options={"gtol": 1e-10, "maxiter": 500},
    )
    return res.x[:d].copy(), float(res.x[d])


def _as_images(images: Any, name: str) -> list[np.ndarray]:
    """A batch (N, H, W[, 3]) array or a sequence of images, as float64 (H, W, 3)."""
    if isinstance(images, np.ndarray):
        if images.ndim == 3 and images.shape[2] == 3:
            raise InputError(
                f"{name} must be a batch (N, H, W, 3) or (N, H, W), or a list of images; got "
                f"shape {images.shape}: one colour image? wrap it in a list"
            )
        if images.ndim not in (3, 4):
            raise InputError(
                f"{name} must be a batch (N, H, W) or (N, H, W, 3), or a list of images; got "
                f"shape {images.shape}: wrap a single image in a list"
            )
        seq: Sequence[Any] = list(images)
    elif isinstance(images, (list, tuple)):
        seq = images
    else:
        raise InputError(
            f"{name} must be an (N, H, W, 3) array or a list of images; got {type(images).__name__}"
        )
    if len(seq) == 0:
        raise InputError(f"{name} must hold at least one image; got none")
    return [_unit_image(im, f"{name}[{i}]") for i, im in enumerate(seq)]


def _check_keypoints(value: Any, n_images: int, n_joints: int) -> tuple[np.ndarray, np.ndarray]:
    """(N, J, 2) coordinates (0 where unlabelled) and the (N, J) labelled mask."""
    arr = check_numeric(value, "keypoints")
    if arr.ndim != 3 or arr.shape[:2] != (n_images, n_joints) or arr.shape[2] not in (2, 3):
        raise InputError(
            f"keypoints must be (N, J, 3) = ({n_images}, {n_joints}, 3) as (x, y, v), or "
            f"(N, J, 2) with every joint labelled, for {n_images} images and "
            f"{n_joints} joints; got shape {arr.shape}"
        )
    if arr.shape[2] == 3:
        v = arr[..., 2]
        if not np.all(np.isfinite(v)):
            raise InputError("keypoints' visibility column v must be finite (0 = unlabelled)")
        labelled = v > 0
    else:
        labelled = np.ones(arr.shape[:2], bool)
    xy = np.where(labelled[..., None], arr[..., :2], 0.0)
    if not np.all(np.isfinite(xy)) or np.abs(xy).max(initial=0) > _MAX_COORD:
        raise InputError(
            f"labelled keypoints (v > 0) must have finite coordinates of at most "
            f"{_MAX_COORD:.0e} pixels; set v = 0 for joints without a location"
        )
    return xy, labelled


class PictorialStructures:
    r"""A pictorial-structures pose model learned from images with keypoints.

    The model of Felzenszwalb and Huttenlocher (2005) with linear part detectors: a
    joint's unary cost at grid cell :math:`q` is :math:`c_i(q) = -\log \sigma(a_i
    \cdot \phi(q) + b_i)` with :math:`\phi` the standardized :func:`grid_descriptors`
    and :math:`\sigma` the logistic function; a joint and its parent are held by a
    spring with the Gaussian negative log-likelihood :math:`\sum_{a \in \{x, y\}}
    (a_i - a_{p(i)} - \mu_{a,i})^2 / (2 \sigma_{a,i}^2)`. The pose of least energy is
    found exactly (:func:`~robopercept.nn.pose.pictorial.pictorial_structures`) and its
    grid cells are returned as their centre pixels.

    ``fit`` learns, over the labelled pairs (``v > 0`` for both joints) of the
    training poses, :math:`\mu_i` and :math:`\sigma_i^2` as the mean and the variance
    of :math:`l_i - l_{p(i)}` in pixels (the variance floored at ``min_std**2``), and
    per joint an L2-regularized logistic regression (scikit-learn's
    ``LogisticRegression(C=C)`` objective, solved by trust-region Newton-CG) on the cell of each
    labelled joint (positive) against ``n_negatives`` random cells per image that are
    more than one cell away from it (negatives, drawn with ``random_state``).

    Parameters
    ----------
    skeleton : Skeleton
        The joints; its links must form a tree.
    cell : int
        Grid cell side in pixels (a 128 x 128 image at cell 4 is a 32 x 32 grid).
    root : int, str or None
        The tree's root (``Skeleton.parents``; default the joint of most links).
    radius : int
        Descriptor neighbourhood radius in cells (:func:`grid_descriptors`).
    orientations : int
        Orientation bins of the descriptors.
    n_negatives : int
        Negative cells drawn per training image.
    C : float
        Inverse regularization strength of the part classifiers.
    min_std : float or None
        Floor of the spring standard deviations, pixels; default ``cell / 2``.
    random_state : int, numpy.random.Generator or None
        Seed of the negative sampling.

    Attributes
    ----------
    parents_ : (J,) int64 ndarray
        The tree, ``-1`` at the root.
    offsets_ : (J, 2) float64 ndarray
        :math:`\mu_i` in pixels, ``(x, y)``; 0 at the root.
    variances_ : (J, 2) float64 ndarray
        :math:`\sigma_i^2` in pixels squared; 0 at the root.
    coef_ : (J, D) float64 ndarray
        :math:`a_i`, on standardized descriptors.
    intercept_ : (J,) float64 ndarray
        :math:`b_i`.
    feature_mean_, feature_scale_ : (D,) float64 ndarray
        The standardization :math:`\phi = (d - \text{mean}) / \text{scale}`.

    Examples
    --------
    Two joints, a red and a blue disc 8 pixels apart, on noise:

    >>> from robopercept.nn.skeleton import Skeleton
    >>> rng = np.random.default_rng(0)
    >>> yy, xx = np.mgrid[:32, :32]
    >>> def picture(x, y):
    ...     img = rng.uniform(0.3, 0.7, (32, 32, 3))
    ...     img[(xx - x) ** 2 + (yy - y) ** 2 <= 6] = (1.0, 0.0, 0.0)
    ...     img[(xx - x - 8) ** 2 + (yy - y) ** 2 <= 6] = (0.0, 0.0, 1.0)
    ...     return img
    >>> pos = rng.integers(6, 18, (12, 2)).astype(float)
    >>> images = np.stack([picture(x, y) for x, y in pos])
    >>> v = np.full((12, 1), 2.0)
    >>> kp = np.stack([np.c_[pos, v], np.c_[pos + [8, 0], v]], axis=1)  # (12, 2, 3)
    >>> arm = Skeleton("arm", ["a", "b"], [(0, 1)], [])
    >>> model = PictorialStructures(arm, cell=2, random_state=0).fit(images[:10], kp[:10])
    >>> model.offsets_[1].tolist()
    [8.0, 0.0]
    >>> bool(np.abs(model.predict(images[10:]) - kp[10:, :, :2]).max() <= 1.0)
    True
    """

    def __init__(
        self,
        skeleton: Skeleton,
        cell: int = 4,
        *,
        root: int | str | None = None,
        radius: int = 1,
        orientations: int = 9,
        n_negatives: int = 32,
        C: float = 1.0,
        min_std: float | None = None,
        random_state: int | np.random.Generator | None = None,
    ) -> None:
        self.skeleton = skeleton
        self.cell = cell
        self.root = root
        self.radius = radius
        self.orientations = orientations
        self.n_negatives = n_negatives
        self.C = C
        self.min_std = min_std
        self.random_state = random_state

    # -- scikit-learn's parameter protocol ----------------------------------------------
    _PARAMS = (
        "skeleton",
        "cell",
        "root",
        "radius",
        "orientations",
        "n_negatives",
        "C",
        "min_std",
        "random_state",
    )

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor arguments by name (scikit-learn's ``clone`` uses them)."""
        return {name: getattr(self, name) for name in self._PARAMS}

    def set_params(self, **params: Any) -> PictorialStructures:
        """Set constructor arguments by name; returns self."""
        for key, value in params.items():
            if key not in self._PARAMS:
                raise InputError(
                    f"PictorialStructures has no parameter {key!r}; valid ones: "
                    f"{list(self._PARAMS)}"
                )
            setattr(self, key, value)
        return self

    def __repr__(self) -> str:
        shown = [repr(self.skeleton)] + [
            f"{k}={getattr(self, k)!r}" for k in self._PARAMS[1:] if getattr(self, k) is not None
        ]
        return f"PictorialStructures({', '.join(shown)})"

    # -- checks ---------------------------------------------------------------------------
    def _settings(self) -> tuple[int, int, int]:
        if not isinstance(self.skeleton, Skeleton):
            raise InputError(
                "skeleton must be a robopercept.nn.skeleton.Skeleton (e.g. MPII_16); got "
                f"{type(self.skeleton).__name__}"
            )
        return _check_descriptor_params(self.cell, self.radius, self.orientations)

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError(
                "this PictorialStructures is not fitted yet; call fit(images, keypoints) "
                "before predicting"
            )

    # -- learning -------------------------------------------------------------------------
    def fit(self, images: Any, keypoints: npt.ArrayLike) -> PictorialStructures:
        """Learn the springs and the part classifiers.

        Parameters
        ----------
        images : (N, H, W, 3) or (N, H, W) ndarray, or a list of images
            Images may differ in size when given as a list.
        keypoints : (N, J, 3) or (N, J, 2) array_like
            ``(x, y, v)`` in pixels; a joint counts where ``v > 0`` (without ``v``:
            every joint).

        Returns
        -------
        PictorialStructures
            ``self``.

        Raises
        ------
        InputError
            On malformed images, keypoints or parameters, or a skeleton that is not a
            tree.
        DegenerateError
            If some joint is never labelled inside the images, or some joint and its
            parent are never labelled together.
        """
        cell, radius, orientations = self._settings()
        n_neg = check_int(self.n_negatives, "n_negatives", 1)
        C = check_real(self.C, "C", 0.0, 1e10, low_inclusive=False)
        min_std = (
            cell / 2.0
            if self.min_std is None
            else check_real(self.min_std, "min_std", 0.0, 1e6, low_inclusive=False)
        )
        rng = as_rng(self.random_state)
        parents = self.skeleton.parents(self.root)
        imgs = _as_images(images, "images")
        J = self.skeleton.num_joints
        xy, labelled = _check_keypoints(keypoints, len(imgs), J)
        names = self.skeleton.joints

        offsets = np.zeros((J, 2))
        variances = np.zeros((J, 2))
        for i in np.flatnonzero(parents >= 0):
            p = parents[i]
            both = labelled[:, i] & labelled[:, p]
            if not both.any():
                raise DegenerateError(
                    f"joints {names[i]!r} and its parent {names[p]!r} are never labelled "
                    "together: cannot learn their spring; label them in some image"
                )
            d = xy[both, i] - xy[both, p]
            offsets[i] = d.mean(axis=0)
            variances[i] = np.maximum(d.var(axis=0), min_std**2)

        # samples: descriptors at the joints' cells (positives) and at random cells
        pos: list[list[np.ndarray]] = [[] for _ in range(J)]
        neg: list[list[np.ndarray]] = [[] for _ in range(J)]
        for img, pts, lab in zip(imgs, xy, labelled, strict=True):
            desc = _descriptors(img, cell, radius, orientations)
            gh, gw = desc.shape[:2]
            g = np.floor((pts + 0.5) / cell).astype(np.int64)  # (J, 2) grid (x, y)
            inside = lab & (g[:, 0] >= 0) & (g[:, 0] < gw) & (g[:, 1] >= 0) & (g[:, 1] < gh)
            cells = rng.choice(gh * gw, size=min(n_neg, gh * gw), replace=False)
            cy, cx = np.divmod(cells, gw)
            for j in range(J):
                far = np.ones(cells.size, bool)
                if inside[j]:
                    pos[j].append(desc[g[j, 1], g[j, 0]][None])
                    far = np.maximum(np.abs(cx - g[j, 0]), np.abs(cy - g[j, 1])) > 1
                neg[j].append(desc[cy[far], cx[far]])
        missing = [names[j] for j in range(J) if not pos[j]]
        if missing:
            raise DegenerateError(
                f"joints {missing} are never labelled inside the images: cannot learn what "
                "they look like; label them (v > 0) in some image"
            )
        every = np.concatenate([np.concatenate(pos[j] + neg[j]) for j in range(J)])
        mean = every.mean(axis=0)
        scale = every.std(axis=0)
        scale[scale < 1e-12] = 1.0
        coef = np.zeros((J, every.shape[1]))
        intercept = np.zeros(J)
        for j in range(J):
            P, N = np.concatenate(pos[j]), np.concatenate(neg[j])
            X = (np.concatenate([P, N]) - mean) / scale
            y = np.r_[np.ones(len(P)), np.zeros(len(N))]
            if len(N) == 0:
                raise DegenerateError(
                    f"no negative cells for joint {names[j]!r}: the images are too small "
                    "for their cell size; use larger images or a smaller cell"
                )
            coef[j], intercept[j] = _fit_logistic(X, y, C)

        self._fitted_settings = (cell, radius, orientations)
        self.parents_ = parents
        self.offsets_ = offsets
        self.variances_ = variances
        self.feature_mean_ = mean
        self.feature_scale_ = scale
        self.coef_ = coef
        self.intercept_ = intercept
        return self

    # -- inference ------------------------------------------------------------------------
    def _costs(self, img: np.ndarray) -> np.ndarray:
        # the descriptor settings of fit (set_params after fit takes effect at the next fit)
        desc = _descriptors(img, *self._fitted_settings)
        scores = ((desc - self.feature_mean_) / self.feature_scale_) @ self.coef_.T
        scores += self.intercept_
        return np.ascontiguousarray(np.moveaxis(np.logaddexp(0.0, -scores), 2, 0))

    def _grid_springs(self) -> tuple[np.ndarray, np.ndarray]:
        cell = float(self._fitted_settings[0])
        child = self.parents_ >= 0
        mu = np.where(child[:, None], self.offsets_ / cell, 0.0)
        var = np.where(child[:, None], self.variances_, 1.0)
        return mu, cell**2 / (2.0 * var)

    def predict_costs(self, image: npt.ArrayLike) -> np.ndarray:
        """The unary cost maps of one image: :math:`-\\log \\sigma(s_i)` per joint.

        Parameters
        ----------
        image : (H, W) or (H, W, 3) ndarray

        Returns
        -------
        (J, H // cell, W // cell) float64 ndarray
            Lower is more like the joint; cell :math:`(g_x, g_y)` is centred at pixel
            :math:`(g \\cdot \\mathrm{cell} + (\\mathrm{cell} - 1) / 2)`.
        """
        self._check_fitted()
        return self._costs(_unit_image(image, "image"))

    def predict(self, images: Any) -> np.ndarray:
        """The pose of least energy in every image.

        Parameters
        ----------
        images : (N, H, W, 3) or (N, H, W) ndarray, or a list of images

        Returns
        -------
        (N, J, 2) float64 ndarray
            Joint locations in pixels ``(x, y)``: the centres of the chosen grid cells.
        """
        self._check_fitted()
        imgs = _as_images(images, "images")
        parents, order = check_tree(self.parents_, len(self.parents_))
        mu, w = self._grid_springs()
        cell = self._fitted_settings[0]
        out = np.empty((len(imgs), len(parents), 2))
        for k, img in enumerate(imgs):
            sol = solve_tree(self._costs(img), parents, order, mu, w, False, "envelope")
            out[k] = sol.locations * cell + (cell - 1) / 2.0
        return out
