"""Frames of a video file or of a folder of images, for the 2-D commands and pipelines.

:class:`VideoSource` keeps the contract of the RGB-D sources
(:class:`~robopercept.sources.TUMFolderSource`,
:class:`~robopercept.sources.realsense.RealSenseSource`): ``len()`` gives the number of
frames it will yield, iterating yields them in order, and a frame that cannot be decoded
is skipped and recorded in :attr:`VideoSource.skipped` as ``(index, reason)``. Frames
are ``(index, image)`` pairs with the image as RGB uint8 ``(H, W, 3)``.

A video is decoded by :class:`~robopercept.imaging.VideoReader` (any file ffmpeg reads,
one frame per coded picture, as ``cv2.VideoCapture`` gives them); a folder's images are
read by :func:`~robopercept.imaging.read_image` in the order of their sorted names.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_int, check_real
from robopercept.errors import EmptyResultError, FileFormatError
from robopercept.imaging.io import VideoReader, read_image

__all__ = ["IMAGE_EXTENSIONS", "VideoSource"]

IMAGE_EXTENSIONS = frozenset(
    {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm", ".webp"}
)
"""File extensions (lower case) that make a folder's files frames."""


class VideoSource:
    """Frames of a video file or an image folder, as ``(index, RGB uint8 image)``.

    Unreadable images of a folder are skipped, and recorded in :attr:`skipped`; the
    index still advances, so frame numbers stay those of the files' order (frame ``i``
    is the ``i``-th file, 0-based). A video that ffmpeg cannot decode is refused when
    the source is made.

    Parameters
    ----------
    path : path-like
        A video file (MP4, AVI, MKV, ...) or a folder of images (extensions in
        :data:`IMAGE_EXTENSIONS`, in sorted name order).
    fps : float, optional
        Frame rate; default: the container's for a video, 25 for a folder.
    max_frames : int, optional
        Yield at most this many frames (the first ones).
    min_frames : int
        Refuse a source that would yield fewer frames than this (after ``max_frames``):
        a method that compares frames, such as ``robopercept flow``'s point tracks,
        passes 2, so a still image (ffmpeg reads a PNG as a one-frame video) or
        ``--max-frames 1`` is refused before any output is written.

    Attributes
    ----------
    path : Path
    fps : float
    total : int
        Frames the source will yield at most (``len(source)``).
    files : list of Path
        The folder's image files (empty for a video).
    skipped : list of (int, str)
        Index and reason (first line of the error) of every skipped frame.

    Raises
    ------
    FileFormatError
        No such file or folder, a folder without images, or a video with no decodable
        frame.
    InputError
        ``fps`` or ``max_frames`` not positive, ``min_frames`` not an integer >= 1.
    EmptyResultError
        Fewer than ``min_frames`` frames (an :class:`InputError` too).

    Examples
    --------
    >>> source = VideoSource("frames/")  # doctest: +SKIP
    >>> for index, image in source:  # doctest: +SKIP
    ...     ...
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        fps: float | None = None,
        max_frames: int | None = None,
        min_frames: int = 1,
    ) -> None:
        min_frames = check_int(min_frames, "min_frames", 1)
        if fps is not None:
            fps = check_real(fps, "fps (--fps)", 0.0, low_inclusive=False)
        if max_frames is not None:
            max_frames = check_int(max_frames, "max_frames (--max-frames)", 1)
        self.path = as_path(path, "the video or image folder")
        self.skipped: list[tuple[int, str]] = []
        self.max_frames = max_frames
        self.files: list[Path] = []
        self._video: Any = None
        if self.path.is_dir():
            self.files = sorted(
                p for p in self.path.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS
            )
            if not self.files:
                raise FileFormatError(
                    f"{self.path}: no images ({', '.join(sorted(IMAGE_EXTENSIONS))}) in this folder"
                )
            self.fps = float(fps or 25.0)
            total = len(self.files)
        elif self.path.is_file():
            self._video = VideoReader(self.path)
            self.fps = float(fps or self._video.fps or 25.0)
            total = self._video.frame_count
            if total == 0:
                raise FileFormatError(f"{self.path}: the video holds no frame ffmpeg can decode")
        else:
            raise FileFormatError(f"{self.path}: no such file or folder")
        self.total = total if max_frames is None else min(total, max_frames)
        if self.total < min_frames:
            if self.total == total:
                still = " (a still image?)" if total == 1 and self._video is not None else ""
                held = f"holds {total} frame{'s' if total != 1 else ''}{still}"
                fix = f"give a video or a folder of {min_frames} images or more"
            else:
                held = f"gives {self.total} frame{'s' if self.total != 1 else ''} with "
                held += f"max_frames (--max-frames) {max_frames}"
                fix = f"allow {min_frames} frames or more"
            raise EmptyResultError(f"{self.path} {held}; at least {min_frames} are needed: {fix}")

    def __len__(self) -> int:
        return self.total

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        if self._video is None:
            for i, f in enumerate(self.files[: self.total]):
                try:
                    img = read_image(f, mode="rgb")
                except FileFormatError as exc:
                    self.skipped.append((i, str(exc).splitlines()[0]))
                    continue
                yield i, img
        else:
            for i, frame in enumerate(self._video):  # frame_count is for progress bars
                if self.max_frames is not None and i >= self.max_frames:
                    self._video.close()
                    break
                yield i, frame
