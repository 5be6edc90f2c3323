r"""Image differencing: motion from the frames themselves, no background model.

- :class:`FrameDifference`: :math:`|I_t - I_{t-n}| > \tau`. It needs no empty scene
  and adapts at once to a moving camera's slow drift, lighting changes or a dynamic
  scene, but it marks an object twice, where it is and where it was ``n`` frames ago
  (the *ghost*), and misses the inside of a uniform object and anything that stops.
- :class:`ThreeFrameDifference`: the AND of two successive differences,
  :math:`|I_t - I_{t-1}| > \tau \wedge |I_{t+1} - I_t| > \tau`, is true only where the
  middle frame differs from both neighbours: where the object is at time :math:`t`,
  without the ghosts of :math:`t - 1` and :math:`t + 1`. The answer is for the
  previous frame, one frame late.

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

from robopercept._checks import check_int
from robopercept.errors import InputError
from robopercept.motion.background import ForegroundModel, check_threshold

__all__ = ["MAX_LAG", "FrameDifference", "ThreeFrameDifference"]

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


class ThreeFrameDifference(ForegroundModel):
    """Foreground of the *previous* frame: the AND of its differences with the frames
    before and after (no ghosts). Empty for the first two frames.

    Parameters
    ----------
    threshold : float
    noise, noise_size
        Mask clean-up (see :func:`robopercept.motion.background.clean_mask`).
    """

    delay = 1  # apply(frame t) returns the mask of frame t - 1

    def __init__(
        self, threshold: float = 25.0, *, noise: str | None = "median", noise_size: int = 3
    ) -> None:
        super().__init__(noise, noise_size)
        self.threshold = check_threshold(threshold)
        self._frames: deque[np.ndarray] = deque(maxlen=2)

    @property
    def background(self) -> np.ndarray | None:
        """The frame whose mask the next call returns (0-255 scale)."""
        return self._frames[-1] if self._frames else None

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The ``(H, W)`` bool mask of the previous frame's moving pixels."""
        img = self._frame(frame)
        if len(self._frames) < 2:
            self._frames.append(img)
            return np.zeros(img.shape[:2], dtype=bool)
        before, middle = self._frames
        self._frames.append(img)
        d1 = np.abs(middle - before) > self.threshold
        d2 = np.abs(img - middle) > self.threshold
        return self._clean(d1 & d2)
