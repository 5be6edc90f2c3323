r"""Background subtraction: which pixels of a frame are not the (learned) background.

Every model keeps a background image :math:`B` and marks as foreground the pixels that
differ from it, then removes isolated noise from the mask:

- :class:`StaticBackground`: a given reference frame, :math:`|I - B| > \tau`.
- :class:`AveragedBackground`: the mean of the first ``n_frames`` frames,
  :math:`B = \frac1N \sum_i I_i`, then as above (a background seen with passers-by
  averages them away when they are brief).
- :class:`GaussianBackground`: per pixel a mean :math:`\mu` and variance
  :math:`\sigma^2`, started from the per-pixel median and median absolute deviation
  of the first ``init_frames`` frames (a temporal median ignores objects passing
  through, where a first frame would keep them as ghosts); foreground where
  :math:`|I - \mu| > k \sigma`. Background pixels update both by a running average
  with learning rate :math:`\alpha`,

  .. math::

      \mu \leftarrow (1 - \alpha) \mu + \alpha I, \qquad
      \sigma^2 \leftarrow (1 - \alpha) \sigma^2 + \alpha (I - \mu)^2,

  so slow illumination changes are followed while foreground objects do not leak into
  the background (they do once they stop and are relearned, which is the point of
  ``learning_rate``).

Colour frames are compared per channel and a pixel is foreground when any channel is.
Intensities are on the 0-255 scale (floats in [0, 1] are scaled), so thresholds read
the same for uint8 and float frames.

Noise removal (``noise``): ``"median"`` (a ``size`` x ``size`` majority vote, which is
the median filter of a binary mask), ``"open-close"`` (an opening removes specks, a
closing fills small holes, with a ``size`` square), or None.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from numba import njit

from robopercept._checks import (
    check_image,
    check_int,
    check_magnitude,
    check_ndim,
    check_odd_size,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError

__all__ = [
    "MAX_NOISE_SIZE",
    "AveragedBackground",
    "ForegroundModel",
    "GaussianBackground",
    "StaticBackground",
    "check_noise",
    "check_threshold",
    "clean_mask",
]

NOISE = ("median", "open-close", None)


def _as255(frame: npt.ArrayLike, name: str = "frame") -> np.ndarray:
    img = check_image(frame, name)
    check_magnitude(img, name, 1e30)  # times 255 in float32 (max 3.4e38)
    if img.dtype == np.uint8:
        return img.astype(np.float32)
    if img.dtype.kind == "f":
        return img.astype(np.float32) * np.float32(255.0)
    raise InputError(f"{name} must be uint8 or float in [0, 1]; got {img.dtype}")


#: largest noise window side: clean-up windows are a few pixels; beyond this a typo
#: (2**40) would build a structuring element of 2**80 bytes
MAX_NOISE_SIZE = 255


def check_noise(noise: Any, size: Any, size_name: str = "size") -> tuple[str | None, int]:
    """Return ``(noise, size)`` after checking the mask clean-up settings.

    Parameters
    ----------
    noise : {"median", "open-close", None}
    size : int
        An odd window side in ``1..MAX_NOISE_SIZE``.
    size_name : str
        The size's parameter name in the message (``noise_size`` on the models).

    Returns
    -------
    noise : str or None
    size : int

    Raises
    ------
    InputError
        Another ``noise``, or a ``size`` that is no odd integer in range.
    """
    if not (noise is None or isinstance(noise, str)) or noise not in NOISE:
        raise InputError(f"noise must be one of {NOISE}; got {plain_repr(noise)}")
    n = check_odd_size(size, size_name)
    if n > MAX_NOISE_SIZE:
        raise InputError(
            f"{size_name} must be an odd integer in 1..{MAX_NOISE_SIZE} (a clean-up window of "
            f"a few pixels); got {n}"
        )
    return noise, n


def clean_mask(mask: np.ndarray, noise: str | None = "median", size: int = 3) -> np.ndarray:
    """Remove isolated pixels (and fill pinholes) in a boolean mask.

    Parameters
    ----------
    mask : (H, W) bool ndarray
        Integer masks are read as ``mask != 0``.
    noise : {"median", "open-close", None}
        Majority vote over a ``size`` x ``size`` window, or an opening then a closing
        with a ``size`` square, or nothing.
    size : int
        Odd window side, at most :data:`MAX_NOISE_SIZE`.

    Returns
    -------
    (H, W) bool ndarray

    Raises
    ------
    InputError
        A mask that is not 2-D bool (or integer), a bad ``noise`` or ``size``.
    """
    noise, size = check_noise(noise, size)
    m = check_ndim(mask, "mask", (2,))
    if m.dtype.kind in "iu":
        m = m != 0
    elif m.dtype != np.bool_:
        raise InputError(
            f"mask must be a bool (H, W) array; got dtype {m.dtype}: pass mask > 0 "
            "(or mask.astype(bool))"
        )
    return _clean_mask(np.ascontiguousarray(m), noise, size)


def _clean_mask(mask: np.ndarray, noise: str | None, size: int) -> np.ndarray:
    """:func:`clean_mask` of a C-contiguous 2-D bool ``mask``, without the checks."""
    if noise is None or size == 1:
        return mask
    if noise == "median":
        out = np.empty_like(mask)
        _majority(mask.view(np.uint8), size, out.view(np.uint8))
        return out
    from robopercept.imaging.morphology import closing, opening, structuring_element

    se = structuring_element("rect", size)
    m = mask.view(np.uint8)
    return closing(opening(m, se), se).astype(bool)


@njit(cache=True, nogil=True)
def _majority(m, size, out):  # pragma: no cover - compiled
    # the median of a binary image: 1 where more than half the window is 1
    # (running column sums; border pixels vote with the part of the window inside)
    h, w = m.shape
    r = size // 2
    col = np.zeros(w, dtype=np.int32)
    for y in range(min(r, h)):
        for x in range(w):
            col[x] += m[y, x]
    for y in range(h):
        if y + r < h:
            for x in range(w):
                col[x] += m[y + r, x]
        if y - r - 1 >= 0:
            for x in range(w):
                col[x] -= m[y - r - 1, x]
        rows = min(y + r, h - 1) - max(y - r, 0) + 1
        s = 0
        for x in range(min(r, w)):
            s += col[x]
        for x in range(w):
            if x + r < w:
                s += col[x + r]
            if x - r - 1 >= 0:
                s -= col[x - r - 1]
            cols = min(x + r, w - 1) - max(x - r, 0) + 1
            out[y, x] = 1 if 2 * s > rows * cols else 0


def check_threshold(value: float, name: str = "threshold", unit: str = "0-255 scale") -> float:
    """Return ``value`` as a float after checking that it is a finite real number > 0.

    The error names the parameter and its ``unit`` (grey levels on the 0-255 scale for
    intensity thresholds, ``"standard deviations"`` for :class:`GaussianBackground`'s
    ``k``).
    """
    v = check_real(value, name)
    if v <= 0:
        raise InputError(f"{name} must be a positive number ({unit}); got {plain_repr(value)}")
    return v


class ForegroundModel:
    """Base class of the foreground detectors (background models and differencing).

    It holds the mask clean-up settings and checks the frames: every frame must have
    the first frame's shape. Subclasses convert each frame with :meth:`_frame` (to
    float64 on the 0-255 scale, counted) and finish each mask with :meth:`_clean`
    (channels OR-ed, then :func:`clean_mask`).

    Parameters
    ----------
    noise : {"median", "open-close", None}
        Mask clean-up (see :func:`clean_mask`).
    noise_size : int
        Its window size.
    """

    def __init__(self, noise: str | None, noise_size: int) -> None:
        self.noise, self.noise_size = check_noise(noise, noise_size, "noise_size")
        self.frame_count = 0
        self._shape: tuple[int, ...] | None = None

    def _frame(self, frame: npt.ArrayLike) -> np.ndarray:
        img = _as255(frame, f"frame {self.frame_count}")
        if self._shape is None:
            self._shape = img.shape
        elif img.shape != self._shape:
            raise InputError(
                f"frame {self.frame_count} has shape {img.shape}, the first had "
                f"{self._shape}: resize the frames, or start a new model"
            )
        self.frame_count += 1
        return img

    def _clean(self, mask: np.ndarray) -> np.ndarray:
        if mask.ndim == 3:
            mask = mask.any(axis=2)
        return _clean_mask(np.ascontiguousarray(mask), self.noise, self.noise_size)


class StaticBackground(ForegroundModel):
    """Foreground = pixels differing from a fixed reference frame by more than
    ``threshold`` (0-255 scale).

    Parameters
    ----------
    reference : (H, W) or (H, W, 3) ndarray
        The empty scene.
    threshold : float
    noise, noise_size
        Mask clean-up (see :func:`clean_mask`).
    """

    def __init__(
        self,
        reference: np.ndarray,
        threshold: float = 30.0,
        *,
        noise: str | None = "median",
        noise_size: int = 3,
    ) -> None:
        super().__init__(noise, noise_size)
        self.threshold = check_threshold(threshold)
        self.background = _as255(reference, "reference")
        self._shape = self.background.shape

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The ``(H, W)`` bool foreground mask of ``frame``."""
        img = self._frame(frame)
        return self._clean(np.abs(img - self.background) > self.threshold)


class AveragedBackground(ForegroundModel):
    """The background is the mean of the first ``n_frames`` frames; until then the
    mask is empty (``ready`` is False).

    Parameters
    ----------
    n_frames : int
    threshold : float
    noise, noise_size
        Mask clean-up (see :func:`clean_mask`).
    """

    def __init__(
        self,
        n_frames: int = 30,
        threshold: float = 30.0,
        *,
        noise: str | None = "median",
        noise_size: int = 3,
    ) -> None:
        super().__init__(noise, noise_size)
        self.n_frames = check_int(n_frames, "n_frames", 1)
        self.threshold = check_threshold(threshold)
        self._sum: np.ndarray | None = None
        self.background: np.ndarray | None = None

    @property
    def ready(self) -> bool:
        """True once the background has been averaged."""
        return self.background is not None

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The foreground mask (empty while the first frames are averaged)."""
        img = self._frame(frame)
        if self.background is None:
            self._sum = img.astype(np.float64) if self._sum is None else self._sum + img
            if self.frame_count == self.n_frames:
                self.background = (self._sum / self.n_frames).astype(np.float32)
                self._sum = None
            return np.zeros(img.shape[:2], dtype=bool)
        return self._clean(np.abs(img - self.background) > self.threshold)


@njit(cache=True, nogil=True)
def _gaussian_step(img, mu, var, k2, alpha, min_var, fg):  # pragma: no cover - compiled
    # per pixel (all channels): foreground if any channel has d^2 > k^2 var; background
    # pixels update mean and variance by the running average
    h, w, c = img.shape
    for y in range(h):
        for x in range(w):
            f = False
            for ch in range(c):
                d = img[y, x, ch] - mu[y, x, ch]
                if d * d > k2 * var[y, x, ch]:
                    f = True
            fg[y, x] = f
            if not f:
                for ch in range(c):
                    d = img[y, x, ch] - mu[y, x, ch]
                    mu[y, x, ch] += alpha * d
                    v = (1.0 - alpha) * var[y, x, ch] + alpha * d * d
                    var[y, x, ch] = max(v, min_var)


class GaussianBackground(ForegroundModel):
    r"""Per-pixel running Gaussian: foreground where :math:`|I - \mu| > k \sigma`.

    Parameters
    ----------
    k : float
        Threshold in standard deviations.
    learning_rate : float
        :math:`\alpha` of the running averages, in (0, 1]; the background forgets
        with a time constant of about :math:`1 / \alpha` frames.
    init_frames : int
        Frames whose per-pixel median starts :math:`\mu` (and whose median absolute
        deviation, times 1.4826, starts :math:`\sigma`); the mask is empty meanwhile.
        1: the first frame is the background.
    initial_std : float
        :math:`\sigma` where the first frames give no spread (0-255 scale): used as a
        floor on the initial :math:`\sigma`.
    min_std : float
        Floor on :math:`\sigma`, so a perfectly still pixel does not flag tiny noise.
    noise, noise_size
        Mask clean-up (see :func:`clean_mask`).

    Attributes
    ----------
    background : (H, W) or (H, W, 3) float32 ndarray
        :math:`\mu` (0-255 scale).
    variance : same shape
        :math:`\sigma^2`.
    """

    def __init__(
        self,
        k: float = 2.5,
        learning_rate: float = 0.02,
        *,
        init_frames: int = 20,
        initial_std: float = 6.0,
        min_std: float = 4.0,
        noise: str | None = "median",
        noise_size: int = 3,
    ) -> None:
        super().__init__(noise, noise_size)
        self.k = check_threshold(k, "k", "standard deviations")
        self.learning_rate = check_real(
            learning_rate, "learning_rate", 0.0, 1.0, low_inclusive=False
        )
        self.init_frames = check_int(init_frames, "init_frames", 1)
        self._init: list[np.ndarray] = []
        # squared in float32 (max 3.4e38); a spread beyond 255 levels means nothing
        self.initial_std = check_threshold(initial_std, "initial_std")
        self.min_std = check_threshold(min_std, "min_std")
        for name, v in (("initial_std", self.initial_std), ("min_std", self.min_std)):
            if v > 1e6:
                raise InputError(
                    f"{name} must be at most 1e6 (0-255 scale: a few grey levels); got {v:g}"
                )
        self.background: np.ndarray | None = None
        self.variance: np.ndarray | None = None

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """The foreground mask of ``frame``; then the model learns from its background."""
        img = self._frame(frame)
        if self.background is None:  # still gathering the first frames
            self._init.append(img)
            if len(self._init) == self.init_frames:
                stack = np.stack(self._init)
                self._init = []
                mu = np.median(stack, axis=0)
                std = 1.4826 * np.median(np.abs(stack - mu), axis=0)
                self.background = mu.astype(np.float32)
                self.variance = np.maximum(std, self.initial_std).astype(np.float32) ** 2
            return np.zeros(img.shape[:2], dtype=bool)
        assert self.variance is not None
        img3 = img if img.ndim == 3 else img[:, :, None]
        mu3 = self.background if img.ndim == 3 else self.background[:, :, None]
        var3 = self.variance if img.ndim == 3 else self.variance[:, :, None]
        fg = np.empty(img.shape[:2], dtype=bool)
        _gaussian_step(
            img3,
            mu3,
            var3,
            np.float32(self.k**2),
            np.float32(self.learning_rate),
            np.float32(self.min_std**2),
            fg,
        )
        return self._clean(fg)
