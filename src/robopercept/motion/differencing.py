r"""Image differencing: motion from the frames themselves, no background model.

- :class:`FrameDifference`: :math:`|I_t - I_{t-n}| > \tau`. It needs no empty scene
  and adapts at once to a moving camera's slow drift, lighting changes or a dynamic
  scene, but it marks an object twice, where it is and where it was ``n`` frames ago
  (the *ghost*), and misses the inside of a uniform object and anything that stops.
- :class:`ThreeFrameDifference`: the AND of two differences ``gap`` frames apart,
  :math:`|I_t - I_{t-g}| > \tau \wedge |I_{t+g} - I_t| > \tau`, is true only where the
  middle frame differs from both neighbours: where the object is at time :math:`t`,
  without the ghosts of :math:`t - g` and :math:`t + g`. The answer is for the frame
  ``gap`` frames back, ``gap`` frames late. The mask is then cleaned (``noise``),
  closed with a ``closing`` x ``closing`` square (the edges of one walker join) and its
  holes are filled (:func:`fill_holes`: the uniform inside of a body, which no
  difference sees, becomes foreground).

Why a gap and a low threshold (issue 30): on PETS 2009 S2.L1 (480x360, 10 frames/s) a
walker moves 1-3 pixels a frame. With ``gap=1`` and :math:`\tau = 25` the middle frame
differs from both neighbours only on a few edge pixels of the leading limbs, and the
median clean-up removes most of them: 0 of 16 hand-marked walkers (frames 20, 40, 60)
had a fifth of their box covered by blobs of 100 pixels or more. With ``gap=3``,
:math:`\tau = 15`, a 5 x 5 closing and hole filling, 15 of 16 (the one missed stands
still behind the sign post). A threshold from the noise (``k`` times the median
absolute deviation of the difference) was tried and rejected: H.264 leaves most
static pixels bit-identical between frames, so that deviation is 0 on this video.

Background subtraction (:mod:`robopercept.motion.background`) suits a fixed camera over
a mostly static scene: it finds whole objects, also when they stop, but needs the
background (an empty frame, or time to learn it), and an object that was part of the
background when it was learned leaves a ghost when it moves away until the model
relearns. Differencing suits dynamic scenes and a camera that moves slowly; it finds
only what moves, and edges more than interiors.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from robopercept._checks import check_bool, check_int, check_ndim
from robopercept.errors import InputError
from robopercept.motion.background import MAX_NOISE_SIZE, ForegroundModel, check_threshold

__all__ = ["MAX_LAG", "FrameDifference", "ThreeFrameDifference", "fill_holes"]

#: most frames between the two that FrameDifference compares (it keeps them all)
MAX_LAG = 10_000


class FrameDifference(ForegroundModel):
    """Foreground = pixels that changed by more than ``threshold`` (0-255 scale) since
    the frame ``n`` steps back; empty for the first ``n`` frames.

    Parameters
    ----------
    n : int
        Frames between the two compared.
    threshold : float
    noise, noise_size
        Mask clean-up (see :func:`robopercept.motion.background.clean_mask`).
    """

    def __init__(
        self,
        n: int = 1,
        threshold: float = 25.0,
        *,
        noise: str | None = "median",
        noise_size: int = 3,
    ) -> None:
        super().__init__(noise, noise_size)
        self.n = check_int(n, "n", 1)
        if self.n > MAX_LAG:
            raise InputError(f"n must be in 1..{MAX_LAG} frames (each one is kept); got {n}")
        self.threshold = check_threshold(threshold)
        self._frames: deque[np.ndarray] = deque(maxlen=self.n)

    @property
    def background(self) -> np.ndarray | None:
        """The frame the next one is compared with (0-255 scale)."""
        return self._frames[0] if len(self._frames) == self.n else None

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The ``(H, W)`` bool mask of what changed since ``n`` frames ago."""
        img = self._frame(frame)
        old = self.background
        self._frames.append(img)
        if old is None:
            return np.zeros(img.shape[:2], dtype=bool)
        return self._clean(np.abs(img - old) > self.threshold)


def fill_holes(mask: np.ndarray) -> np.ndarray:
    """Fill the holes of a boolean mask: background regions that do not reach the border.

    A hole is a 4-connected component of ``~mask`` with no pixel on the image border
    (so the foreground is taken 8-connected); the result is ``mask`` OR the holes. This
    is ``scipy.ndimage.binary_fill_holes`` with its default structure.

    Parameters
    ----------
    mask : (H, W) ndarray of bool
        Integer masks are read as ``mask != 0``.

    Returns
    -------
    (H, W) ndarray of bool

    Raises
    ------
    InputError
        A mask that is not 2-D bool or integer.

    Examples
    --------
    >>> ring = np.zeros((5, 5), bool); ring[1:4, 1:4] = True; ring[2, 2] = False
    >>> int(fill_holes(ring).sum()), bool(fill_holes(ring)[2, 2])
    (9, True)
    """
    m = check_ndim(mask, "mask", (2,))
    if m.dtype.kind in "iu":
        m = m != 0
    elif m.dtype != np.bool_:
        raise InputError(f"mask must be a bool (H, W) array; got dtype {m.dtype}: pass mask > 0")
    return _fill_holes(np.ascontiguousarray(m))


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """:func:`fill_holes` of a C-contiguous 2-D bool ``mask``, unchecked."""
    from robopercept.imaging.blobs import label_components

    if mask.size == 0:
        return mask.copy()
    labels, n = label_components(~mask, 4)
    if n == 0:
        return mask.copy()
    outside = np.zeros(n + 1, dtype=bool)
    for edge in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        outside[edge] = True
    outside[0] = True  # label 0 is the foreground itself
    return mask | ~outside[labels]


class ThreeFrameDifference(ForegroundModel):
    """Foreground of the frame ``gap`` steps back: the AND of its differences with the
    frames ``gap`` before and after it (no ghosts), cleaned, closed and hole-filled.
    Empty for the first ``2 * gap`` frames.

    Parameters
    ----------
    threshold : float
        Grey levels on the 0-255 scale (default 15).
    gap : int
        Frames between the three compared, 1 to :data:`MAX_LAG` (default 3: slow
        walkers at 10 frames/s move far enough to leave more than their edges).
    noise, noise_size
        Mask clean-up (see :func:`robopercept.motion.background.clean_mask`), applied
        first.
    closing : int
        Side of the square closing after the clean-up: 1 for none, else odd, at most
        :data:`~robopercept.motion.background.MAX_NOISE_SIZE` (default 5).
    fill : bool
        Fill the holes of the closed mask (:func:`fill_holes`; default True).

    Attributes
    ----------
    delay : int
        ``apply(frame t)`` returns the mask of frame ``t - delay`` (``delay == gap``).

    Examples
    --------
    A 10-px square moving 4 px a frame over a flat background: the mask returned with
    frame 6 is the square of frame 3 (less its 4 corner pixels, which the 3 x 3 median
    vote removes), with no ghost at frames 0 or 6.

    >>> frames = np.zeros((8, 20, 60), np.uint8)
    >>> for t in range(8):
    ...     frames[t, 5:15, 4 * t : 4 * t + 10] = 200
    >>> model = ThreeFrameDifference(gap=3)
    >>> masks = [model.apply(f) for f in frames]
    >>> m = masks[6]
    >>> int(m.sum()), bool(m[6:14, 12:22].all()), bool(m[:, :12].any() or m[:, 22:].any())
    (96, True, False)
    """

    def __init__(
        self,
        threshold: float = 15.0,
        gap: int = 3,
        *,
        noise: str | None = "median",
        noise_size: int = 3,
        closing: int = 5,
        fill: bool = True,
    ) -> None:
        super().__init__(noise, noise_size)
        self.threshold = check_threshold(threshold)
        self.gap = check_int(gap, "gap", 1)
        if self.gap > MAX_LAG:
            raise InputError(f"gap must be in 1..{MAX_LAG} frames (each one is kept); got {gap}")
        self.closing = check_int(closing, "closing", 1)
        if self.closing % 2 == 0 or self.closing > MAX_NOISE_SIZE:
            raise InputError(
                f"closing must be an odd integer in 1..{MAX_NOISE_SIZE} (1: no closing); "
                f"got {closing}"
            )
        self.fill = check_bool(fill, "fill")
        self.delay = self.gap
        self._frames: deque[np.ndarray] = deque(maxlen=2 * self.gap)

    @property
    def background(self) -> np.ndarray | None:
        """The frame whose mask the next call returns (0-255 scale), once ``2 * gap``
        frames have been seen."""
        return self._frames[self.gap] if len(self._frames) == 2 * self.gap else None

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The ``(H, W)`` bool mask of the moving pixels of the frame ``gap`` back."""
        img = self._frame(frame)
        if len(self._frames) < 2 * self.gap:
            self._frames.append(img)
            return np.zeros(img.shape[:2], dtype=bool)
        before, middle = self._frames[0], self._frames[self.gap]
        self._frames.append(img)
        d1 = np.abs(middle - before) > self.threshold
        d2 = np.abs(img - middle) > self.threshold
        mask = self._clean(d1 & d2)
        if self.closing > 1:
            from robopercept.imaging.morphology import closing, structuring_element

            se = structuring_element("rect", self.closing)
            mask = closing(mask, se)
        return _fill_holes(np.ascontiguousarray(mask)) if self.fill else mask
