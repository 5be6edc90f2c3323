r"""KLT point tracking through a sequence: Shi-Tomasi corners followed frame to frame by
pyramidal Lucas-Kanade, with their trails, and lost corners replaced.

The Kanade-Lucas-Tomasi tracker (as OpenCV's ``samples/python/lk_track.py``):

1. in the first frame, detect up to ``max_corners`` Shi-Tomasi corners
   (:func:`~robopercept.motion.good_features_to_track`);
2. in every later frame, track each point from the previous frame with
   :func:`~robopercept.motion.lucas_kanade`; a point whose status is not
   :attr:`~robopercept.motion.FlowStatus.TRACKED` (aperture, left the image, not
   converged, high residual) is dropped with its trail; the motion of the frame pair is
   named by :func:`~robopercept.motion.classify_motion` from the tracked vectors;
3. when fewer than ``max_corners // 2`` points remain, detect corners again and add
   those at least ``min_distance`` pixels from every kept point
   (:math:`\min_j \|c - p_j\|^2 \ge d_{\min}^2`), up to ``max_corners`` points in all.

Every point has an identity (1, 2, ... in order of detection, never reused) and a trail
of its last ``trail`` positions. Frames are converted to gray (BT.601 luma,
:func:`~robopercept.imaging.rgb_to_gray`) before detection and tracking.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from robopercept._checks import check_image, check_int, check_odd_size, check_real
from robopercept.errors import DegenerateError, InputError
from robopercept.imaging.color import rgb_to_gray
from robopercept.motion.flow import classify_motion, good_features_to_track, lucas_kanade

__all__ = ["KLTTracker", "PointTracks"]


@dataclass(frozen=True)
class PointTracks:
    """The points of :class:`KLTTracker` after one frame.

    Attributes
    ----------
    frame : int
        Number of the frame (0-based count of :meth:`KLTTracker.update` calls).
    ids : (N,) int64 ndarray
        Identity of each point (from 1, never reused).
    trails : list of (k, 2) ndarray
        Each point's last ``k <= trail`` positions ``(x, y)``, oldest first; the last
        row is its position in this frame.
    motion : str or None
        :attr:`~robopercept.motion.MotionClass.kind` of the motion from the previous
        frame (``"unknown"`` when fewer than two points were tracked); None in the first
        frame or when there was no point to track.
    redetected : bool
        Whether corners were detected in this frame.
    """

    frame: int
    ids: np.ndarray
    trails: list[np.ndarray] = field(repr=False)
    motion: str | None
    redetected: bool

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def points(self) -> np.ndarray:
        """``(N, 2)`` current positions (the last row of every trail)."""
        if not self.trails:
            return np.zeros((0, 2))
        return np.array([t[-1] for t in self.trails], dtype=np.float64)


class KLTTracker:
    """Track corners through frames with their trails (see the module docstring).

    Parameters
    ----------
    max_corners : int
        Most points tracked at once; corners are detected again below half of it.
    quality : float
        Shi-Tomasi quality level: corners above this fraction of the strongest.
    min_distance : float
        Least distance between detected corners, and between a new corner and a kept
        point, in pixels.
    window : int
        Odd Lucas-Kanade window side in pixels.
    levels : int
        Pyramid levels above the image (0: single level).
    trail : int
        Positions kept per point.

    Attributes
    ----------
    frame_count : int
        Frames given to :meth:`update`.
    redetections : int
        Frames in which corners were detected (the first one included).

    Examples
    --------
    >>> import numpy as np
    >>> from robopercept.motion import KLTTracker
    >>> rng = np.random.default_rng(0)
    >>> texture = (rng.random((80, 100)) * 255).astype(np.uint8)
    >>> tracker = KLTTracker(max_corners=50)
    >>> first = tracker.update(texture[:, :90])
    >>> second = tracker.update(texture[:, 2:92])  # the scene moves 2 px left
    >>> second.motion
    'translation'
    """

    def __init__(
        self,
        max_corners: int = 500,
        quality: float = 0.01,
        min_distance: float = 7.0,
        *,
        window: int = 21,
        levels: int = 3,
        trail: int = 15,
    ) -> None:
        self.max_corners = check_int(max_corners, "max_corners", minimum=1)
        self.quality = check_real(quality, "quality", 0.0, 1.0, low_inclusive=False)
        self.min_distance = check_real(min_distance, "min_distance", 0.0)
        self.window = check_odd_size(window, "window", minimum=3)
        self.levels = check_int(levels, "levels", minimum=0)
        self.trail = check_int(trail, "trail", minimum=1)
        self.frame_count = 0
        self.redetections = 0
        self._trails: list[deque[np.ndarray]] = []
        self._ids = np.zeros(0, dtype=np.int64)
        self._next_id = 1
        self._prev: np.ndarray | None = None

    def update(self, image: np.ndarray) -> PointTracks:
        """Track the points into ``image`` (and detect new ones when too few remain).

        Parameters
        ----------
        image : (H, W) or (H, W, 3) ndarray
            The next frame, uint8 or float in [0, 1]; every frame must have the size
            of the first.

        Returns
        -------
        PointTracks

        Raises
        ------
        InputError
            The frame is no image, or its size differs from the previous frame's.
        """
        image = check_image(image, "image")
        gray = rgb_to_gray(image) if image.ndim == 3 else image
        prev, index = self._prev, self.frame_count
        if prev is not None and prev.shape != gray.shape:
            raise InputError(
                f"frame {index} is {gray.shape[1]}x{gray.shape[0]}, the previous one "
                f"{prev.shape[1]}x{prev.shape[0]}: every frame must have one size"
            )
        trails, ids = self._trails, self._ids
        kind = None
        if prev is not None and trails:
            pts = np.array([t[-1] for t in trails])
            res = lucas_kanade(prev, gray, pts, window=self.window, levels=self.levels)
            try:
                kind = classify_motion(res.start[res.status], res.flow[res.status]).kind
            except DegenerateError:
                kind = "unknown"
            keep = np.flatnonzero(res.status)
            trails = [trails[k] for k in keep]
            ids = ids[keep]
            for t, p in zip(trails, res.end[keep], strict=True):
                t.append(p)
        redetected = len(trails) < self.max_corners // 2
        if redetected:  # replace lost corners
            new = good_features_to_track(gray, self.max_corners, self.quality, self.min_distance)
            if trails:
                have = np.array([t[-1] for t in trails])
                d2 = ((new[:, None, :] - have[None, :, :]) ** 2).sum(axis=2).min(axis=1)
                new = new[d2 >= self.min_distance**2]
            new = new[: max(self.max_corners - len(trails), 0)]
            trails = trails + [deque([p], maxlen=self.trail) for p in new]
            ids = np.r_[ids, np.arange(self._next_id, self._next_id + len(new))]
            self._next_id += len(new)
            self.redetections += 1
        self._trails, self._ids, self._prev = trails, ids, gray
        self.frame_count += 1
        return PointTracks(index, ids.copy(), [np.array(t) for t in trails], kind, bool(redetected))
