"""The frame every RGB-D source yields."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from robopercept.errors import InputError
from robopercept.geometry import CameraIntrinsics
from robopercept.geometry.transforms import check_transform

__all__ = ["RGBDFrame", "ReadAhead"]


@dataclass(frozen=True)
class RGBDFrame:
    """One depth image and one colour image with their calibration.

    Attributes
    ----------
    index : int
        Position in the sequence (0-based).
    timestamp : float
        Seconds.
    depth : (Hd, Wd) uint16 ndarray
        Raw depth; metres = ``depth * depth_scale``; 0 = no measurement.
    color : (Hc, Wc, 3) uint8 ndarray
        RGB.
    depth_intrinsics, color_intrinsics : CameraIntrinsics
    T_color_depth : (4, 4) ndarray
        Depth frame to colour frame.
    depth_scale : float
        Metres per depth unit.
    ground_truth : dict
        Optional per-frame truth, e.g. ``{"plane": (n, d), "board_mask": mask}``.
    """

    index: int
    timestamp: float
    depth: np.ndarray
    color: np.ndarray
    depth_intrinsics: CameraIntrinsics
    color_intrinsics: CameraIntrinsics
    T_color_depth: np.ndarray
    depth_scale: float
    ground_truth: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        kd, kc = self.depth_intrinsics, self.color_intrinsics
        if self.depth.ndim != 2 or self.depth.shape != (kd.height, kd.width):
            raise InputError(
                f"frame {self.index}: depth is {self.depth.shape[::-1]} but the depth "
                f"intrinsics say {kd.width}x{kd.height}: check camera.json"
            )
        if self.color.shape != (kc.height, kc.width, 3):
            raise InputError(
                f"frame {self.index}: colour is {self.color.shape[1::-1]} but the colour "
                f"intrinsics say {kc.width}x{kc.height}: check camera.json"
            )
        object.__setattr__(self, "T_color_depth", check_transform(self.T_color_depth))
        if not (self.depth_scale > 0):
            raise InputError(f"depth_scale must be > 0; got {self.depth_scale}")


class ReadAhead:
    """A frame source read in batches ahead of its consumer.

    Iterating takes ``batch`` frames from ``frames`` into memory, then yields them one
    by one, then takes the next batch. The source's own work (rendering a synthetic
    scene, decoding files) then runs between batches instead of between the consumer's
    steps, so the consumer's per-frame timings are its own: no source work interleaved
    with it, sharing its caches and its threads. Memory: ``batch`` frames.

    ``len()`` and ``skipped`` are the source's.

    Parameters
    ----------
    frames : iterable of RGBDFrame
    batch : int
        Frames per batch (>= 1).

    Examples
    --------
    >>> from robopercept.sources import SyntheticRGBDScene
    >>> scene = SyntheticRGBDScene(n_frames=3, depth_size=(212, 120), color_size=(320, 180))
    >>> [f.index for f in ReadAhead(scene, batch=2)], len(ReadAhead(scene))
    ([0, 1, 2], 3)
    """

    def __init__(self, frames: Any, batch: int = 30) -> None:
        if int(batch) < 1:
            raise InputError(f"batch must be >= 1; got {batch}")
        self.frames = frames
        self.batch = int(batch)

    def __len__(self) -> int:
        return len(self.frames)

    @property
    def skipped(self) -> Any:
        """The source's skipped frames (empty when it has none)."""
        return getattr(self.frames, "skipped", [])

    def __iter__(self) -> Iterator[RGBDFrame]:
        it = iter(self.frames)
        while True:
            # frames already read are yielded even when the source fails mid-batch
            chunk: list[RGBDFrame] = []
            error: BaseException | None = None
            try:
                for _ in range(self.batch):
                    chunk.append(next(it))
            except StopIteration:
                pass
            except Exception as exc:
                error = exc
            yield from chunk
            if error is not None:
                raise error
            if len(chunk) < self.batch:
                return
