"""Gaussian image pyramids."""

from __future__ import annotations

import numpy as np

from robopercept._checks import check_image
from robopercept.errors import InputError
from robopercept.imaging.filters import separable_filter_unchecked

__all__ = ["gaussian_pyramid", "pyr_down", "pyr_down_unchecked"]

_BINOMIAL_5 = np.array([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0


def pyr_down(image: np.ndarray) -> np.ndarray:
    r"""Blur with the 5x5 binomial kernel :math:`\frac{1}{256} b b^T`, :math:`b = (1, 4, 6, 4, 1)`,
    then keep every second row and column.

    The border is ``reflect101`` and the output is ``((H + 1) // 2, (W + 1) // 2)``: exactly
    ``cv2.pyrDown(image)`` (also for uint8, where the sums are exact in float32).

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray

    Returns
    -------
    ndarray
        Half size, same dtype.
    """
    return pyr_down_unchecked(check_image(image))


def pyr_down_unchecked(image: np.ndarray) -> np.ndarray:
    """:func:`pyr_down` of an image its caller has validated: no checks (callers that
    reduce level after level validate the input once, as :func:`gaussian_pyramid` and
    Lucas-Kanade do)."""
    blurred = separable_filter_unchecked(image, _BINOMIAL_5, _BINOMIAL_5, "reflect101")
    return np.ascontiguousarray(blurred[::2, ::2])


def gaussian_pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """The image and ``levels - 1`` successive :func:`pyr_down` reductions.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    levels : int
        Number of levels including the input, >= 1; it must leave the smallest level
        at least 1x1.

    Returns
    -------
    list of ndarray
        ``levels`` images, from full size down.
    """
    image = check_image(image)
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or levels < 1:
        raise InputError(f"levels must be an integer >= 1; got {levels!r}")
    max_levels = 1 + int(np.floor(np.log2(max(min(image.shape[:2]), 1))))
    if levels > max_levels:
        raise InputError(
            f"levels={levels} is too many for a {image.shape[1]}x{image.shape[0]} image; "
            f"at most {max_levels} keep every level >= 1 pixel"
        )
    out = [image]
    for _ in range(int(levels) - 1):
        out.append(pyr_down_unchecked(out[-1]))
    return out
