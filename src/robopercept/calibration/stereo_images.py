"""Chessboard corners in the image pairs of a stereo rig, ready for
:func:`~robopercept.calibration.stereo_calibrate` (the detection half of OpenCV's
``stereo_calib`` sample)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from robopercept.calibration.chessboard import find_chessboard_corners
from robopercept.errors import FileFormatError, InputError
from robopercept.imaging.io import read_image

__all__ = ["BoardPairs", "find_board_pairs"]


@dataclass(frozen=True)
class BoardPairs:
    """Result of :func:`find_board_pairs`.

    Attributes
    ----------
    corners1, corners2 : list of (w * h, 2) ndarray
        The corners of each used pair, left and right, in the same board order.
    used : list of int
        Indices of the pairs whose two images show the whole board.
    skipped : list of (int, str)
        The other pairs and why (which image, and the detector's reason).
    image_size : (int, int) or None
        ``(width, height)`` of the images (None when none could be read).
    flipped : list of int
        Pairs whose right-hand corners were reversed to match the left-hand order (the
        detector numbered the board from the other end in one image).
    """

    corners1: list[np.ndarray]
    corners2: list[np.ndarray]
    used: list[int]
    skipped: list[tuple[int, str]]
    image_size: tuple[int, int] | None
    flipped: list[int]


ImageInput = str | os.PathLike[str] | np.ndarray


def _gray(item: ImageInput) -> np.ndarray:
    if isinstance(item, np.ndarray):
        return item
    return read_image(item, mode="gray")


def find_board_pairs(
    left: Sequence[ImageInput], right: Sequence[ImageInput], pattern_size: tuple[int, int]
) -> BoardPairs:
    """Find the chessboard in every stereo pair; keep the pairs where both images show
    the whole board, with the corners in one order.

    Pair ``i`` is ``(left[i], right[i])``. Each image goes through
    :func:`~robopercept.calibration.find_chessboard_corners`. The detector numbers the
    corners from one end of the board; a board with an even side can be numbered from
    either end, so when the first-to-last corner directions of the two images point
    apart (negative dot product) the right-hand corners are reversed, which is the same
    board numbered from the other end (corner ``k`` becomes ``N - 1 - k``).

    Parameters
    ----------
    left, right : sequence of str, path or ndarray
        Image files (read as gray) or images, as many on each side.
    pattern_size : (int, int)
        Inner corners per row and per column, e.g. ``(9, 6)``.

    Returns
    -------
    BoardPairs

    Raises
    ------
    InputError
        Unequal numbers of left and right images, none at all, images of different
        sizes, or a ``pattern_size`` that the detector refuses.

    Examples
    --------
    >>> blank = np.full((40, 60), 128, np.uint8)
    >>> pairs = find_board_pairs([blank], [blank], (4, 3))
    >>> pairs.used, pairs.skipped[0][0], pairs.image_size
    ([], 0, (60, 40))
    """
    if isinstance(left, (str, os.PathLike, np.ndarray)) or isinstance(
        right, (str, os.PathLike, np.ndarray)
    ):
        raise InputError("left and right must be sequences of images or image files")
    try:
        left, right = list(left), list(right)
    except TypeError:
        raise InputError(
            "left and right must be sequences of images or image files; got "
            f"{type(left).__name__} and {type(right).__name__}"
        ) from None
    if len(left) != len(right):
        raise InputError(
            f"{len(left)} left images but {len(right)} right images: give one right image "
            "per left image, in the same order"
        )
    if not left:
        raise InputError("no image pairs given")
    size: tuple[int, int] | None = None
    c1: list[np.ndarray] = []
    c2: list[np.ndarray] = []
    used: list[int] = []
    skipped: list[tuple[int, str]] = []
    flipped: list[int] = []
    for i, pair in enumerate(zip(left, right, strict=True)):
        dets = []
        reason = ""
        for side, item in zip(("left", "right"), pair, strict=True):
            try:
                gray = _gray(item)
            except FileFormatError as exc:
                reason = f"{side} image unreadable ({exc})"
                break
            here = (int(gray.shape[1]), int(gray.shape[0]))
            if size is None:
                size = here
            elif here != size:
                name = item if not isinstance(item, np.ndarray) else f"{side} image {i}"
                raise InputError(
                    f"{name} is {here[0]}x{here[1]} but the first image is "
                    f"{size[0]}x{size[1]}: calibrate one resolution at a time"
                )
            det = find_chessboard_corners(gray, pattern_size)
            if not det.found:
                reason = f"{side} image: {det.reason}"
                break
            dets.append(det.corners)
        if len(dets) < 2:
            skipped.append((i, reason))
            continue
        a, b = dets
        if np.dot(a[-1] - a[0], b[-1] - b[0]) < 0:
            b = b[::-1].copy()
            flipped.append(i)
        c1.append(a)
        c2.append(b)
        used.append(i)
    return BoardPairs(c1, c2, used, skipped, size, flipped)
