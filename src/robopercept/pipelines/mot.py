"""Multi-object tracking of a frame sequence: detections in, MOTChallenge rows out.

:func:`track_objects` runs a :class:`~robopercept.tracking.MultiObjectTracker` (one
Kalman filter per track, Hungarian association, SORT's life cycle) over frames and
yields, per frame, its detections and the tracks reported for it. Detections come

* from a MOTChallenge ``det.txt`` (:func:`~robopercept.tracking.read_mot`), the rows
  of frame number ``index + 1`` (MOTChallenge counts frames from 1), optionally only
  those with ``conf >= min_score``; or
* without one, from background subtraction: a
  :class:`~robopercept.motion.GaussianBackground` with its defaults (it learns during
  the first 20 frames, which have no detections) and the blobs of at least
  ``min_area`` pixels of its mask (:func:`~robopercept.motion.detections_from_mask`),
  each with score 1.

:func:`run_mot` consumes the whole sequence and returns the rows that
:func:`~robopercept.tracking.write_mot` writes, ``(frame number, id, box, score)``.
It gives exactly what a loop of ``tracker.update(boxes, scores)`` over the frames gives
(the CLI's ``robopercept track`` is this function).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from robopercept._checks import check_int, check_real
from robopercept.errors import InputError
from robopercept.motion import GaussianBackground, detections_from_mask
from robopercept.tracking import MotRows, MultiObjectTracker, Track

__all__ = ["MotFrame", "run_mot", "track_objects"]

MotRow = tuple[int, int, np.ndarray, float]


@dataclass(frozen=True)
class MotFrame:
    """One frame of :func:`track_objects`.

    Attributes
    ----------
    index : int
        The source's frame index (0-based).
    number : int
        MOTChallenge frame number, ``index + 1``.
    image : (H, W, 3) ndarray
        The frame (for drawing).
    boxes : (N, 4) ndarray
        Detections ``x, y, w, h`` given to the tracker.
    scores : (N,) ndarray
        Their scores.
    tracks : list of Track
        The tracks :meth:`~robopercept.tracking.MultiObjectTracker.update` reported.
    """

    index: int
    number: int
    image: np.ndarray = field(repr=False)
    boxes: np.ndarray
    scores: np.ndarray
    tracks: list[Track]

    @property
    def rows(self) -> list[MotRow]:
        """``(number, id, box, score)`` per track, as :func:`write_mot` takes them."""
        return [(self.number, t.id, t.box, t.score) for t in self.tracks]


def track_objects(
    frames: Iterable[tuple[int, np.ndarray]],
    detections: MotRows | None = None,
    *,
    tracker: MultiObjectTracker | None = None,
    min_score: float | None = None,
    min_area: int = 100,
) -> Iterator[MotFrame]:
    """Track objects through ``frames``, one :class:`MotFrame` per frame.

    Parameters
    ----------
    frames : iterable of (int, (H, W, 3) ndarray)
        ``(index, image)`` pairs, as :class:`~robopercept.sources.VideoSource` yields.
    detections : MotRows, optional
        A MOTChallenge detection file's rows; None: detect moving blobs by background
        subtraction (see the module docstring).
    tracker : MultiObjectTracker, optional
        The tracker to drive (default: ``MultiObjectTracker()``).
    min_score : float, optional
        With ``detections``: drop rows with ``conf < min_score``.
    min_area : int
        Without ``detections``: the smallest blob, in pixels.

    Yields
    ------
    MotFrame

    Raises
    ------
    InputError
        At the call: ``frames`` not iterable, ``detections`` not MotRows, ``tracker``
        not a MultiObjectTracker, ``min_score`` not a number, ``min_area`` not a
        positive integer; while iterating: an item of ``frames`` that is not an
        ``(index, image)`` pair.
    """
    if isinstance(frames, (str, bytes)) or not isinstance(frames, Iterable):
        raise InputError(
            f"frames must be an iterable of (index, image) pairs (a VideoSource); got "
            f"{type(frames).__name__}"
        )
    if detections is not None and not isinstance(detections, MotRows):
        raise InputError(
            f"detections must be MotRows (robopercept.tracking.read_mot) or None; got "
            f"{type(detections).__name__}"
        )
    if tracker is not None and not isinstance(tracker, MultiObjectTracker):
        raise InputError(
            f"tracker must be a MultiObjectTracker or None; got {type(tracker).__name__}"
        )
    if min_score is not None:
        min_score = check_real(min_score, "min_score")
    min_area = check_int(min_area, "min_area", 1)
    return _track(
        frames, detections, MultiObjectTracker() if tracker is None else tracker, min_score,
        min_area,
    )  # fmt: skip


def _track(
    frames: Iterable[tuple[int, np.ndarray]],
    detections: MotRows | None,
    tracker: MultiObjectTracker,
    min_score: float | None,
    min_area: int,
) -> Iterator[MotFrame]:
    """The loop of :func:`track_objects`, on checked arguments."""
    background = None if detections is not None else GaussianBackground()
    for item in frames:
        if not (isinstance(item, tuple) and len(item) == 2):
            raise InputError(
                f"each item of frames must be an (index, image) pair; got {type(item).__name__}"
            )
        index, frame = check_int(item[0], "the frame index", 0), item[1]
        number = index + 1  # MOTChallenge frames count from 1
        if detections is not None:
            rows = detections.at(number)
            boxes, scores = rows.boxes, rows.conf
            if min_score is not None:
                keep = scores >= min_score
                boxes, scores = boxes[keep], scores[keep]
        else:
            assert background is not None
            det = detections_from_mask(background.apply(frame), min_area)
            boxes, scores = det.boxes, np.ones(len(det))
        tracks = tracker.update(boxes, scores)
        yield MotFrame(index, number, frame, boxes, scores, tracks)


def run_mot(
    frames: Iterable[tuple[int, np.ndarray]],
    detections: MotRows | None = None,
    *,
    tracker: MultiObjectTracker | None = None,
    min_score: float | None = None,
    min_area: int = 100,
) -> list[MotRow]:
    """Every row of :func:`track_objects` over the whole sequence.

    Parameters are :func:`track_objects`'s.

    Returns
    -------
    list of (int, int, (4,) ndarray, float)
        ``(frame number, id, box x, y, w, h, score)``, frame by frame, ready for
        :func:`~robopercept.tracking.write_mot`.

    Examples
    --------
    >>> import numpy as np
    >>> from robopercept.tracking import MotRows
    >>> boxes = np.array([[10.0 + 2 * t, 20.0, 8.0, 8.0] for t in range(4)])
    >>> det = MotRows(np.arange(1, 5), -np.ones(4, int), boxes, np.ones(4), np.zeros((4, 0)))
    >>> frames = ((i, np.zeros((48, 64, 3), np.uint8)) for i in range(4))
    >>> [(number, tid) for number, tid, _, _ in run_mot(frames, det)]
    [(1, 1), (2, 1), (3, 1), (4, 1)]
    """
    steps = track_objects(
        frames, detections, tracker=tracker, min_score=min_score, min_area=min_area
    )
    return [row for step in steps for row in step.rows]
