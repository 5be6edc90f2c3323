"""The keypoint set every detector returns, and :class:`KeyPoint`, one of them shaped as
OpenCV's ``cv2.KeyPoint``."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import overload

import numpy as np

from robopercept._checks import check_numeric
from robopercept.errors import InputError

__all__ = ["KeyPoint", "Keypoints"]


@dataclass(frozen=True)
class KeyPoint:
    """One keypoint with the attributes of ``cv2.KeyPoint``, read-only.

    ``keypoints[i]`` (and iterating over a :class:`Keypoints`) gives these records, so
    that code written for the tuple of ``cv2.KeyPoint`` that ``cv2.SIFT_create()
    .detectAndCompute`` returns runs unchanged: ``kp[0].pt``, ``[k.pt for k in kp]``,
    ``k.angle``.

    Attributes
    ----------
    pt : (float, float)
        Position ``(x, y)`` (``Keypoints.xy[i]``). For :func:`~robopercept.features.sift`
        OpenCV's ``pt`` is this plus 0.25 in x and y (its quarter-pixel shift, see the
        ``sift`` module docstring).
    size : float
        ``Keypoints.scale[i]``: the diameter of the neighbourhood, as ``KeyPoint.size``.
    angle : float
        Orientation in DEGREES, in [0, 360), measured from +x towards +y (image down), as
        ``KeyPoint.angle``; -1 when the detector assigns none (corners), OpenCV's value
        for "not applicable". ``Keypoints.orientation`` holds the same angle in radians
        (NaN for none): the project's unit.
    response : float
        ``Keypoints.response[i]``.
    octave : int
        ``Keypoints.octave[i]``: the octave alone (-1 for SIFT's doubled image). OpenCV's
        SIFT packs octave, layer and sub-layer offset into ``KeyPoint.octave``; its
        octave is ``o & 255`` read as a signed byte, which is this value.
    """

    pt: tuple[float, float]
    size: float
    angle: float
    response: float
    octave: int


@dataclass(frozen=True)
class Keypoints:
    """Detected keypoints, one row per keypoint, strongest first.

    Attributes
    ----------
    xy : (N, 2) float64 ndarray
        Position ``(x, y)`` = (column, row), origin at the centre of the top-left pixel.
    scale : (N,) float64 ndarray
        Size of the neighbourhood that defines the keypoint, in pixels (the window of a
        corner detector, the diameter OpenCV's ``KeyPoint.size`` reports for SIFT).
    orientation : (N,) float64 ndarray
        Dominant orientation in radians, measured from +x towards +y (image down); NaN
        when the detector assigns none (corners).
    response : (N,) float64 ndarray
        Detector response (Harris measure, minimum eigenvalue, |DoG|).
    octave : (N,) int64 ndarray
        Pyramid octave the keypoint was found in (0 for single-scale detectors).

    Notes
    -----
    Indexing and iteration follow the tuple of ``cv2.KeyPoint`` that OpenCV's detectors
    return: ``kp[i]`` is keypoint ``i`` as a read-only :class:`KeyPoint` (``kp[0].pt``,
    ``kp[0].angle`` in degrees as OpenCV's), ``for k in kp`` yields them in order, and
    ``len(kp)`` counts them. A slice, an integer array or a boolean mask gives a
    :class:`Keypoints` (:meth:`select`). The columns above stay the fast interface.

    Examples
    --------
    >>> kp = Keypoints([[3.0, 4.0], [5.0, 1.0]], [2.0, 2.0], [np.pi / 2, np.nan],
    ...                [0.5, 0.25], [0, 0])
    >>> kp[0].pt, kp[0].angle, kp[1].angle
    ((3.0, 4.0), 90.0, -1.0)
    >>> [k.pt for k in kp]
    [(3.0, 4.0), (5.0, 1.0)]
    >>> len(kp[1:])
    1
    """

    xy: np.ndarray
    scale: np.ndarray
    orientation: np.ndarray
    response: np.ndarray
    octave: np.ndarray

    def __post_init__(self) -> None:
        xy = check_numeric(self.xy, "Keypoints.xy")
        if xy.shape == (2,) or xy.shape == (0,):
            xy = xy.reshape(-1, 2)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise InputError(f"Keypoints.xy must be (N, 2) positions (x, y); got shape {xy.shape}")
        n = xy.shape[0]
        cols = {"xy": xy}
        for name in ("scale", "orientation", "response", "octave"):
            arr = check_numeric(getattr(self, name), f"Keypoints.{name}").reshape(-1)
            if name == "octave":
                if not (np.isfinite(arr).all() and (arr == np.round(arr)).all()):
                    raise InputError(f"Keypoints.octave must hold integers; got {arr.tolist()[:5]}")
                arr = arr.astype(np.int64)
            if arr.shape[0] != n:
                raise InputError(f"Keypoints.{name} has {arr.shape[0]} entries for {n} points")
            cols[name] = arr
        for name, arr in cols.items():
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def _record(self, i: int) -> KeyPoint:
        angle = float(self.orientation[i])
        degrees = -1.0 if math.isnan(angle) else math.degrees(angle) % 360.0
        return KeyPoint(
            (float(self.xy[i, 0]), float(self.xy[i, 1])),
            float(self.scale[i]),
            degrees,
            float(self.response[i]),
            int(self.octave[i]),
        )

    @overload
    def __getitem__(self, index: int) -> KeyPoint: ...

    @overload
    def __getitem__(self, index: slice | np.ndarray | list[int] | list[bool]) -> Keypoints: ...

    def __getitem__(self, index: object) -> KeyPoint | Keypoints:
        """Keypoint ``index`` as a :class:`KeyPoint` (an integer, negative from the end),
        or the keypoints selected by a slice, integer array or boolean mask.

        Raises
        ------
        IndexError
            An integer out of range, as a tuple's.
        InputError
            Another kind of index (a string, a float, a mask of the wrong length).
        """
        if isinstance(index, (int, np.integer)) and not isinstance(index, (bool, np.bool_)):
            n = len(self)
            i = int(index)
            if not -n <= i < n:
                raise IndexError(f"keypoint index {i} out of range for {n} keypoints")
            return self._record(i % n)
        if isinstance(index, slice):
            return self.select(np.arange(len(self))[index])
        sel = np.asarray(index)
        if sel.dtype == np.bool_ and sel.shape == (len(self),):
            return self.select(sel)
        if sel.ndim == 1 and (sel.dtype.kind in "iu" or sel.size == 0):
            idx = sel.astype(np.int64)
            if idx.size and not ((idx >= -len(self)) & (idx < len(self))).all():
                raise InputError(
                    f"keypoint indices must be in -{len(self)}..{len(self) - 1}; got "
                    f"{idx.min()}..{idx.max()}"
                )
            return self.select(idx)
        raise InputError(
            "index keypoints with an integer (one KeyPoint), a slice, an integer array or "
            f"a boolean mask of length {len(self)}; got {type(index).__name__}"
            + (f" of dtype {sel.dtype} and shape {sel.shape}" if sel.ndim else "")
        )

    def __iter__(self) -> Iterator[KeyPoint]:
        """The keypoints as :class:`KeyPoint` records, in order (as OpenCV's tuple)."""
        return (self._record(i) for i in range(len(self)))

    @classmethod
    def empty(cls) -> Keypoints:
        """No keypoints."""
        z = np.zeros(0)
        return cls(np.zeros((0, 2)), z, z, z, np.zeros(0, dtype=np.int64))

    def select(self, index: np.ndarray) -> Keypoints:
        """The keypoints at ``index`` (integer positions or a boolean mask)."""
        return Keypoints(
            self.xy[index],
            self.scale[index],
            self.orientation[index],
            self.response[index],
            self.octave[index],
        )
