"""Image and video files.

Images go through imageio (Pillow for PNG/JPEG, tifffile for TIFF): a 16-bit PNG such as
a depth map stays uint16. Video goes through imageio-ffmpeg, which ships its own ffmpeg.
Arrays are RGB(A) or gray as stored; nothing is rescaled.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import check_image, check_positive
from robopercept.errors import FileFormatError, InputError

__all__ = [
    "SnapshotVideoWriter",
    "VideoReader",
    "VideoWriter",
    "read_image",
    "sample_image_path",
    "write_image",
]

_IMAGE_EXTS = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".ppm", ".pgm", ".pnm"}


def read_image(path: str | os.PathLike[str], *, mode: str | None = None) -> np.ndarray:
    """Read an image file.

    Parameters
    ----------
    path : path-like
        PNG, JPEG, TIFF, BMP or PNM.
    mode : {None, 'rgb', 'gray'}
        None keeps what the file stores (gray (H, W), RGB (H, W, 3), RGBA (H, W, 4),
        uint8 or uint16); 'rgb' gives (H, W, 3) (gray replicated, alpha dropped); 'gray'
        gives (H, W) (BT.601 luma of colour files).

    Returns
    -------
    ndarray

    Raises
    ------
    FileFormatError
        Missing, empty, truncated or undecodable file, naming the file.
    """
    import imageio.v3 as iio

    from robopercept.imaging.color import rgb_to_gray

    p = Path(path)
    if mode not in (None, "rgb", "gray"):
        raise InputError(f"mode must be None, 'rgb' or 'gray'; got {mode!r}")
    if not p.is_file():
        raise FileFormatError(f"{p}: no such file")
    if p.stat().st_size == 0:
        raise FileFormatError(f"{p}: the file is empty")
    try:
        img = np.asarray(iio.imread(p))
    except Exception as exc:  # decoders raise many kinds
        raise FileFormatError(
            f"{p}: cannot decode as an image ({type(exc).__name__}: {exc})"
        ) from exc
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3) or img.size == 0:
        raise FileFormatError(f"{p}: decoded to an array of shape {img.shape}, not an image")
    if img.dtype == np.bool_:
        img = img.astype(np.uint8) * 255
    if mode == "rgb":
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        img = np.ascontiguousarray(img[..., :3])
    elif mode == "gray" and img.ndim == 3:
        img = rgb_to_gray(np.ascontiguousarray(img[..., :3]))
    return img


def sample_image_path() -> Path:
    """Path of the sample image shipped with the package.

    It is OpenCV's ``box.png`` (324x223, 8-bit gray; see ``robopercept/data/SOURCES.md``),
    the picture the command-line tools use when no image is given.

    Returns
    -------
    Path

    Examples
    --------
    >>> read_image(sample_image_path()).shape
    (223, 324)
    """
    from importlib import resources

    return Path(str(resources.files("robopercept") / "data" / "box.png"))


def write_image(
    path: str | os.PathLike[str], image: np.ndarray, *, png_compression: int | None = None
) -> Path:
    """Write an image; the format follows the extension.

    uint16 is kept by PNG and TIFF (depth maps); JPEG takes uint8 only. Float images are
    refused rather than silently rescaled: convert with
    ``(np.clip(img, 0, 1) * 255).round().astype(np.uint8)``.

    Parameters
    ----------
    path : path-like
    image : (H, W), (H, W, 3) or (H, W, 4) ndarray, uint8 or uint16 (or bool: 0/255)
    png_compression : int, optional
        zlib level 0..9 for PNG (the writer's default when None; 1 is about 5x faster
        than the default for 20% larger files, what sequences of frames want).

    Returns
    -------
    Path
        The path written.
    """
    import imageio.v3 as iio

    p = Path(path)
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 4:
        check_image(arr[..., :3], "image")
    else:
        check_image(arr, "image", allow_bool=True)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8) * 255
    ext = p.suffix.lower()
    if ext not in _IMAGE_EXTS:
        raise InputError(f"{p}: unknown image extension {ext!r}; use one of {sorted(_IMAGE_EXTS)}")
    if arr.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"image must be uint8 or uint16 to write; got {arr.dtype}: convert with "
            "(np.clip(image, 0, 1) * 255).round().astype(np.uint8)"
        )
    if arr.dtype == np.uint16 and ext in (".jpg", ".jpeg", ".bmp"):
        raise InputError(f"{ext} cannot hold uint16; write a .png or .tiff")
    p.parent.mkdir(parents=True, exist_ok=True)
    extra = {}
    if png_compression is not None and ext == ".png":
        if not 0 <= int(png_compression) <= 9:
            raise InputError(f"png_compression must be in 0..9; got {png_compression}")
        extra["compress_level"] = int(png_compression)
    try:
        iio.imwrite(p, np.ascontiguousarray(arr), **extra)
    except Exception as exc:
        raise FileFormatError(f"{p}: cannot write ({type(exc).__name__}: {exc})") from exc
    return p


def _passthrough() -> list[str]:
    """ffmpeg options that hand over the decoded frames as they are.

    Without them ffmpeg resamples to the container's constant frame rate, repeating
    frames of a variable-rate file (``tree.avi``: 449 frames, of which 68 are distinct).
    ``-fps_mode`` is ffmpeg >= 5.1's name for the older ``-vsync``.
    """
    import imageio_ffmpeg

    try:
        major, minor = (
            int(v) for v in imageio_ffmpeg.get_ffmpeg_version().lstrip("n").split(".")[:2]
        )
    except ValueError:  # a build without a plain version number: assume a recent one
        major, minor = 99, 0
    if (major, minor) >= (5, 1):
        return ["-fps_mode", "passthrough"]
    return ["-vsync", "passthrough"]


class VideoReader:
    """Iterate over the frames of a video file as RGB uint8 arrays.

    Parameters
    ----------
    path : path-like
        Any container/codec that ffmpeg reads (MP4, AVI, MKV, ...).

    Attributes
    ----------
    fps : float
        Frames per second from the container.
    size : (int, int)
        ``(width, height)``.
    frame_count : int
        Number of frames; counted by decoding the file once on first access (exact, not
        the container's estimate).

    Frames come as decoded, one per coded picture, as ``cv2.VideoCapture`` gives
    them: a variable-frame-rate file is not padded with repeated frames.

    Examples
    --------
    >>> with VideoReader("clip.mp4") as video:  # doctest: +SKIP
    ...     for frame in video:
    ...         ...
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        import imageio_ffmpeg

        self.path = Path(path)
        if not self.path.is_file():
            raise FileFormatError(f"{self.path}: no such file")
        try:
            gen = imageio_ffmpeg.read_frames(str(self.path))
            meta: dict[str, Any] = gen.__next__()
            gen.close()
        except Exception as exc:
            raise FileFormatError(f"{self.path}: cannot open as video ({exc})") from exc
        self.fps = float(meta.get("fps") or 0.0)
        w, h = meta.get("size", (0, 0))
        self.size = (int(w), int(h))
        self.duration = float(meta.get("duration") or 0.0)
        self._frame_count: int | None = None
        self._gen: Any = None

    @property
    def frame_count(self) -> int:
        """Number of frames in the file, counted by decoding it once (then cached)."""
        if self._frame_count is None:
            import imageio_ffmpeg

            self._frame_count = int(imageio_ffmpeg.count_frames_and_secs(str(self.path))[0])
        return self._frame_count

    def __len__(self) -> int:
        return self.frame_count

    def __iter__(self) -> Iterator[np.ndarray]:
        import imageio_ffmpeg

        w, h = self.size
        self._gen = imageio_ffmpeg.read_frames(
            str(self.path), pix_fmt="rgb24", output_params=_passthrough()
        )
        self._gen.__next__()  # metadata
        try:
            for raw in self._gen:
                yield np.frombuffer(raw, dtype=np.uint8).reshape(h, w, 3)
        finally:
            self.close()

    def close(self) -> None:
        """Stop decoding and release the ffmpeg process (iterating again reopens it)."""
        if self._gen is not None:
            self._gen.close()
            self._gen = None

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class VideoWriter:
    """Write RGB uint8 frames to an H.264 MP4 (yuv420p, playable everywhere).

    Every frame must have the size of the first. The file is complete once
    :meth:`close` runs (also on leaving a ``with`` block after an error), so frames
    written before an interruption are kept.

    Parameters
    ----------
    path : path-like
    fps : float
    quality : float
        0..10 (imageio-ffmpeg's scale; higher is better).
    """

    def __init__(
        self, path: str | os.PathLike[str], fps: float = 30.0, quality: float = 7.0
    ) -> None:
        self.path = Path(path)
        self.fps = check_positive(fps, "fps")
        self.quality = float(quality)
        self._gen: Any = None
        self._size: tuple[int, int] | None = None
        self.frames_written = 0

    def write(self, frame: np.ndarray) -> None:
        """Append one (H, W, 3) uint8 RGB frame (a gray (H, W) frame is replicated)."""
        import imageio_ffmpeg

        frame = check_image(frame, "frame")
        if frame.dtype != np.uint8:
            raise InputError(f"frame must be uint8; got {frame.dtype}")
        if frame.ndim == 2:
            frame = np.repeat(frame[..., None], 3, axis=2)
        h, w = frame.shape[:2]
        if self._gen is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._size = (w, h)
            self._gen = imageio_ffmpeg.write_frames(
                str(self.path),
                (w, h),
                fps=self.fps,
                quality=self.quality,
                macro_block_size=1,
                pix_fmt_out="yuv420p" if w % 2 == 0 and h % 2 == 0 else "yuv444p",
            )
            self._gen.send(None)
        elif (w, h) != self._size:
            raise InputError(
                f"frame size {w}x{h} differs from the first frame's {self._size[0]}x{self._size[1]}"
            )
        self._gen.send(np.ascontiguousarray(frame))
        self.frames_written += 1

    def close(self) -> None:
        """Flush the encoder and finish the file (a later ``write`` starts it anew)."""
        if self._gen is not None:
            self._gen.close()
            self._gen = None

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class SnapshotVideoWriter:
    """A :class:`VideoWriter` that also saves chosen frames as PNG images.

    Frame ``index`` of :meth:`add` goes into the video; when ``index`` is one of
    ``snapshots`` it is also written to ``<stem>_<index:06d>.png`` beside the video
    (``out.mp4`` -> ``out_000025.png``). Closing (also on leaving a ``with`` block after
    an error) completes the video, so what was written before an interruption is kept.

    Parameters
    ----------
    path : path-like
        The MP4 to write.
    fps : float
    snapshots : iterable of int, optional
        Indices of the frames to save as PNG as well.

    Attributes
    ----------
    written : list of str
        Files written so far: the snapshots as they are written, and the video (first)
        once closed with at least one frame in it. Callers may append their own files.

    Examples
    --------
    >>> with SnapshotVideoWriter("out.mp4", 25.0, [0]) as out:  # doctest: +SKIP
    ...     out.add(0, np.zeros((48, 64, 3), np.uint8))
    >>> out.written  # doctest: +SKIP
    ['out.mp4', 'out_000000.png']
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        fps: float,
        snapshots: Iterable[int] | None = None,
    ) -> None:
        self.path = Path(path)
        self.writer = VideoWriter(self.path, fps=fps)
        self.snapshots = {int(i) for i in (snapshots or [])}
        self.written: list[str] = []

    def add(self, index: int, picture: np.ndarray) -> None:
        """Append ``picture`` (RGB uint8) to the video; save it too if ``index`` is a
        snapshot."""
        self.writer.write(picture)
        if index in self.snapshots:
            png = self.path.with_name(f"{self.path.stem}_{index:06d}.png")
            write_image(png, picture)
            self.written.append(str(png))

    def close(self) -> None:
        """Complete the video (and list it first in :attr:`written` if it has frames)."""
        self.writer.close()
        if self.writer.frames_written and str(self.path) not in self.written:
            self.written.insert(0, str(self.path))

    def __enter__(self) -> SnapshotVideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
