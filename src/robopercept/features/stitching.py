r"""Two-image matching and stitching: SIFT features, ratio-test matches, a RANSAC
homography, and a panorama with a feathered blend.

:func:`match_images` finds :math:`H` with :math:`x_b \sim H x_a`. :func:`stitch` keeps
image A's frame: the panorama canvas is the bounding box of A and of B's corners mapped
by :math:`H^{-1}`, shifted by a translation :math:`T` to positive coordinates; A is
warped by :math:`T`, B by :math:`T H^{-1}`. Where both cover a pixel the blend is
:math:`(w_a a + w_b b) / (w_a + w_b)` with each image's weight growing linearly from its
border to its inside (``"feather"``; ``"average"`` uses equal weights, ``"none"`` lets B
cover A).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from robopercept._checks import check_choice, check_image
from robopercept.errors import DegenerateError, InputError
from robopercept.estimation.homography import HomographyFit, find_homography
from robopercept.features.matching import Matches, match_descriptors
from robopercept.features.sift import Features, sift
from robopercept.imaging.warp import transform_points, warp_perspective

__all__ = ["ImageMatch", "Panorama", "match_images", "stitch"]

# a panorama larger than this many times the two images together means a homography
# that flings B towards the horizon: refuse rather than allocate it
_MAX_GROWTH = 16.0


@dataclass(frozen=True)
class ImageMatch:
    """Result of :func:`match_images`.

    Attributes
    ----------
    features_a, features_b : Features
        SIFT keypoints and descriptors of each image.
    matches : Matches
        Ratio-test matches, ``query_idx`` into A, ``train_idx`` into B.
    fit : HomographyFit
        :math:`H` (A -> B), inlier mask over ``matches``, RMS transfer error.
    """

    features_a: Features
    features_b: Features
    matches: Matches
    fit: HomographyFit

    @property
    def xy_a(self) -> np.ndarray:
        """(M, 2) matched positions in A."""
        return self.features_a.keypoints.xy[self.matches.query_idx]

    @property
    def xy_b(self) -> np.ndarray:
        """(M, 2) matched positions in B."""
        return self.features_b.keypoints.xy[self.matches.train_idx]


@dataclass(frozen=True)
class Panorama:
    """Result of :func:`stitch`.

    Attributes
    ----------
    image : ndarray
        The panorama (dtype of the inputs).
    T_a, T_b : (3, 3) ndarray
        Homographies from A's and from B's pixels into the panorama.
    match : ImageMatch
        The matching that gave the homography.
    """

    image: np.ndarray
    T_a: np.ndarray
    T_b: np.ndarray
    match: ImageMatch


def match_images(
    image_a: np.ndarray,
    image_b: np.ndarray,
    *,
    ratio: float = 0.8,
    threshold: float = 3.0,
    rng: int | np.random.Generator | None = 0,
) -> ImageMatch:
    """SIFT in both images, Lowe's ratio test, RANSAC homography A -> B.

    Parameters
    ----------
    image_a, image_b : (H, W) or (H, W, 3) ndarray
    ratio : float
        Ratio-test bound (0.8 as Lowe).
    threshold : float
        RANSAC inlier threshold in pixels of B.
    rng : int, Generator or None
        RANSAC seed.

    Returns
    -------
    ImageMatch

    Raises
    ------
    DegenerateError
        Fewer than 4 matches (no homography is determined) or only degenerate samples.
    """
    fa = sift(image_a)
    fb = sift(image_b)
    m = match_descriptors(fa.descriptors, fb.descriptors, ratio=ratio)
    xa = fa.keypoints.xy[m.query_idx]
    xb = fb.keypoints.xy[m.train_idx]
    if xa.shape[0] < 4:
        raise DegenerateError(
            f"only {xa.shape[0]} SIFT matches pass the ratio test; a homography needs 4: "
            "do the images overlap? try a larger ratio"
        )
    fit = find_homography(xa, xb, threshold, rng=rng)
    return ImageMatch(fa, fb, m, fit)


def _weights(h: int, w: int) -> np.ndarray:
    # 1 at the border pixels rising linearly to the middle (feathering)
    y = np.minimum(np.arange(h), np.arange(h)[::-1]) + 1.0
    x = np.minimum(np.arange(w), np.arange(w)[::-1]) + 1.0
    return np.minimum(y[:, None], x[None, :])


def stitch(
    image_a: np.ndarray,
    image_b: np.ndarray,
    *,
    blend: Literal["feather", "average", "none"] = "feather",
    ratio: float = 0.8,
    threshold: float = 3.0,
    rng: int | np.random.Generator | None = 0,
) -> Panorama:
    """Stitch two overlapping images into a panorama in A's frame.

    Parameters
    ----------
    image_a, image_b : (H, W) or (H, W, 3) ndarray
        Both gray or both colour; the same dtype.
    blend : {"feather", "average", "none"}
        How overlapping pixels combine (module docstring).
    ratio, threshold, rng
        As in :func:`match_images`.

    Returns
    -------
    Panorama

    Raises
    ------
    DegenerateError
        Too few matches, or a homography that would make the panorama more than 16
        times the two images' area (a wrong or near-degenerate match).
    InputError
        Images of different channel counts or dtypes.
    """
    a = check_image(image_a, "image_a")
    b = check_image(image_b, "image_b")
    check_choice(blend, "blend", ("feather", "average", "none"))
    if a.ndim != b.ndim or a.dtype != b.dtype:
        raise InputError(
            f"image_a and image_b must both be gray or both colour, of one dtype; got "
            f"{a.shape} {a.dtype} and {b.shape} {b.dtype}"
        )
    match = match_images(a, b, ratio=ratio, threshold=threshold, rng=rng)
    h_ab = match.fit.H
    h_ba = np.linalg.inv(h_ab)
    ha, wa = a.shape[:2]
    hb, wb = b.shape[:2]
    corners_b = np.array([[0, 0], [wb - 1, 0], [wb - 1, hb - 1], [0, hb - 1]], float)
    mapped = transform_points(h_ba, corners_b)
    # B's corners must stay in front (positive w) or the bounding box is meaningless
    wz = corners_b @ h_ba[2, :2] + h_ba[2, 2]
    if not np.isfinite(mapped).all() or (wz <= 0).any():
        raise DegenerateError("the homography maps part of image B to infinity: no panorama")
    pts = np.vstack([[[0, 0], [wa - 1, ha - 1]], mapped])
    lo = np.floor(pts.min(axis=0))
    hi = np.ceil(pts.max(axis=0))
    width, height = int(hi[0] - lo[0]) + 1, int(hi[1] - lo[1]) + 1
    if width * height > _MAX_GROWTH * (ha * wa + hb * wb):
        raise DegenerateError(
            f"the panorama would be {width}x{height} pixels: the homography is implausible "
            "(too few true matches?)"
        )
    t = np.array([[1.0, 0.0, -lo[0]], [0.0, 1.0, -lo[1]], [0.0, 0.0, 1.0]])
    t_b = t @ h_ba
    size = (width, height)  # dsize, as OpenCV
    fa = warp_perspective(a.astype(np.float64), t, size)
    fb = warp_perspective(b.astype(np.float64), t_b, size)
    if blend == "feather":
        wa_ = warp_perspective(_weights(ha, wa), t, size)
        wb_ = warp_perspective(_weights(hb, wb), t_b, size)
    else:
        wa_ = warp_perspective(np.ones((ha, wa)), t, size)
        wb_ = warp_perspective(np.ones((hb, wb)), t_b, size)
    if blend == "none":
        wa_ = np.where(wb_ > 0.5, 0.0, wa_)
    if fa.ndim == 3:
        wa_, wb_ = wa_[..., None], wb_[..., None]
    total = wa_ + wb_
    with np.errstate(invalid="ignore", divide="ignore"):
        pano = np.where(total > 0, (wa_ * fa + wb_ * fb) / total, 0.0)
    if a.dtype.kind in "ui":
        pano = np.clip(np.rint(pano), 0, np.iinfo(a.dtype).max)
    return Panorama(pano.astype(a.dtype), t, t_b, match)
