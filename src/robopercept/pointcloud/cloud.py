"""The :class:`PointCloud` container."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_int, check_points, plain_repr
from robopercept.errors import InputError

__all__ = ["PointCloud", "check_cloud"]


def _optional(value: npt.ArrayLike | None, name: str, n: int) -> np.ndarray | None:
    if value is None:
        return None
    arr = check_points(value, name, 3)
    if arr.shape[0] != n:
        raise InputError(f"{name} must have one row per point ({n}); got {arr.shape[0]} rows")
    return arr


def _colors(value: npt.ArrayLike | None, n: int) -> np.ndarray | None:
    """``(N, 3)`` float64 RGB in [0, 1]: uint8 arrays are divided by 255; anything else
    must already lie in [0, 1] (InputError with the fix otherwise)."""
    if value is None:
        return None
    eight_bit = isinstance(value, np.ndarray) and value.dtype == np.uint8
    arr = _optional(value, "colors", n)
    if arr is None:  # pragma: no cover - value is not None here
        return None
    if eight_bit:
        return arr / 255.0
    if arr.size == 0:
        return arr
    lo, hi = float(arr.min()), float(arr.max())  # NaN propagates into both
    if lo >= 0.0 and hi <= 1.0:
        return arr
    kind = value.dtype if isinstance(value, np.ndarray) else "values"
    if np.isnan(lo) or np.isnan(hi):
        fix = "colors must be finite RGB in [0, 1]; got NaN: give missing colours a value"
        raise InputError(f"{fix} (np.nan_to_num(colors)) or drop those points")
    if lo >= 0.0 and hi <= 255.0 and bool((arr == np.round(arr)).all()):
        raise InputError(
            f"colors must be RGB floats in [0, 1] or a uint8 array (0..255, divided by "
            f"255); got {kind} up to {hi:g}, 8-bit values: pass colors.astype(np.uint8) "
            "or colors / 255.0"
        )
    raise InputError(
        f"colors must be RGB floats in [0, 1] or a uint8 array (0..255); got {kind} from "
        f"{lo:g} to {hi:g}: scale them into [0, 1] (colors / 255.0 for 8-bit values, "
        "colors / 65535.0 for 16-bit ones)"
    )


_LABEL_RANGE = 2**63 - 1


def _labels(value: npt.ArrayLike | None, n: int) -> np.ndarray | None:
    """``(N,)`` int64 labels from integers (or floats holding whole numbers)."""
    if value is None:
        return None
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise InputError(
            f"labels must be integers, one per point; got dtype {arr.dtype}: "
            "give an (N,) integer array such as segment ids"
        )
    arr = arr.reshape(-1) if arr.ndim == 2 and 1 in arr.shape else arr
    if arr.shape != (n,):
        raise InputError(f"labels must have shape ({n},), one per point; got {arr.shape}")
    if arr.dtype.kind == "f":
        ok = np.isfinite(arr) & (arr == np.round(arr)) & (np.abs(arr) <= 2**53)
        if not ok.all():
            raise InputError(
                f"labels must be whole numbers; got {arr[~ok][0]!r}: round them or "
                "give an integer array"
            )
    elif arr.dtype == np.uint64 and arr.size and arr.max() > _LABEL_RANGE:
        raise InputError(f"labels must fit int64; got {int(arr.max())}")
    return arr.astype(np.int64)


@dataclass(frozen=True)
class PointCloud:
    """A set of 3-D points with optional per-point colours, normals and labels.

    Attributes
    ----------
    points : (N, 3) float64 ndarray
        Coordinates in metres (camera frame: x right, y down, z forward).
    colors : (N, 3) float64 ndarray or None
        RGB in [0, 1], as Open3D stores them. A ``uint8`` array (0..255, as images and
        ``cv2`` give them) is divided by 255 on the way in; any other array must already
        lie in [0, 1] (values up to 255, or NaN, are refused with the fix, so 8-bit
        colours given as floats never become 200.0 and a white PLY).
    normals : (N, 3) float64 ndarray or None
        Unit normals.
    shape : (H, W) or None
        For an organized cloud (one point per pixel of a depth image, NaN where there is
        no measurement), the image shape; ``N == H * W`` in row-major order. Any
        selection drops it.
    labels : (N,) int64 ndarray or None
        An integer per point (a segment, cluster or class id; PCL's ``label`` field,
        written and read as ``label`` in PLY and PCD by
        :func:`~robopercept.pointcloud.write_point_cloud`). :meth:`select`,
        :meth:`finite` and :meth:`concatenate` keep them; filters that merge points
        (the voxel grid) drop them.

    Examples
    --------
    >>> cloud = PointCloud(np.random.rand(100, 3))
    >>> near = cloud.select(cloud.points[:, 2] < 0.5)
    >>> tagged = PointCloud(np.zeros((3, 3)), labels=[0, 1, 1])
    >>> tagged.select([2, 0]).labels
    array([1, 0])
    >>> red = np.array([[255, 0, 0]], dtype=np.uint8)
    >>> PointCloud(np.zeros((1, 3)), colors=red).colors
    array([[1., 0., 0.]])
    """

    points: np.ndarray
    colors: np.ndarray | None = None
    normals: np.ndarray | None = None
    shape: tuple[int, int] | None = field(default=None)
    labels: np.ndarray | None = None

    def __post_init__(self) -> None:
        pts = check_points(self.points, "points", 3)
        object.__setattr__(self, "points", pts)
        n = pts.shape[0]
        object.__setattr__(self, "colors", _colors(self.colors, n))
        object.__setattr__(self, "normals", _optional(self.normals, "normals", n))
        object.__setattr__(self, "labels", _labels(self.labels, n))
        if self.shape is not None:
            if not (isinstance(self.shape, (tuple, list)) and len(self.shape) == 2):
                raise InputError(
                    f"shape must be (H, W), two integers, or None; got {plain_repr(self.shape)}"
                )
            h, w = (check_int(v, "shape (H, W)", 0) for v in self.shape)
            if h * w != n:
                raise InputError(f"shape {self.shape} must have H * W == N ({n}) points")
            object.__setattr__(self, "shape", (h, w))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def is_organized(self) -> bool:
        """True when the cloud keeps its ``(H, W)`` image layout."""
        return self.shape is not None

    def select(self, selection: np.ndarray | Sequence[int], invert: bool = False) -> PointCloud:
        """The points picked by a boolean mask ``(N,)`` or by indices (in their order).

        Parameters
        ----------
        selection : (N,) bool array_like or (M,) int array_like
        invert : bool
            Keep the points *not* selected (indices are then taken as a set).

        Returns
        -------
        PointCloud
            Not organized.
        """
        sel = np.asarray(selection)
        n = len(self)
        if sel.dtype == np.bool_:
            if sel.shape != (n,):
                raise InputError(f"a boolean mask must have shape ({n},); got {sel.shape}")
            idx = np.flatnonzero(~sel if invert else sel)
        elif sel.dtype.kind in "iu" or sel.size == 0:
            idx = sel.astype(np.int64).reshape(-1)
            if idx.size and (idx.min() < -n or idx.max() >= n):
                raise InputError(f"indices must be in [0, {n}); got {idx.min()}..{idx.max()}")
            if invert:
                keep = np.ones(n, dtype=bool)
                keep[idx] = False
                idx = np.flatnonzero(keep)
        else:
            raise InputError(
                f"selection must be a boolean mask or integer indices; got dtype {sel.dtype}"
            )
        return PointCloud(
            self.points[idx],
            None if self.colors is None else self.colors[idx],
            None if self.normals is None else self.normals[idx],
            labels=None if self.labels is None else self.labels[idx],
        )

    def finite(self) -> PointCloud:
        """The points whose three coordinates are finite (NaN/inf rows dropped).

        ``len(cloud) - len(cloud.finite())`` is the number dropped.
        """
        ok = self.finite_mask()
        if ok.all():
            return replace(self, shape=None) if self.shape is not None else self
        return self.select(ok)

    def finite_mask(self) -> np.ndarray:
        """(N,) bool: the points whose coordinates are all finite."""
        p = self.points
        # three column tests: ~10x faster than np.isfinite(p).all(axis=1)
        return np.isfinite(p[:, 0]) & np.isfinite(p[:, 1]) & np.isfinite(p[:, 2])

    def with_colors(self, colors: npt.ArrayLike | None) -> PointCloud:
        """A copy with ``colors`` replaced: RGB floats in [0, 1], or a uint8 array
        (0..255) which is divided by 255, as in the constructor."""
        return replace(self, colors=colors)  # type: ignore[arg-type]

    def with_normals(self, normals: np.ndarray | None) -> PointCloud:
        """A copy with ``normals`` replaced."""
        return replace(self, normals=normals)

    def with_labels(self, labels: npt.ArrayLike | None) -> PointCloud:
        """A copy with ``labels`` replaced (``(N,)`` integers, or None to drop them).

        Examples
        --------
        >>> PointCloud(np.zeros((2, 3))).with_labels([3, 4]).labels
        array([3, 4])
        """
        return replace(self, labels=None if labels is None else np.asarray(labels))

    @staticmethod
    def concatenate(clouds: Sequence[PointCloud]) -> PointCloud:
        """One cloud with the points of ``clouds`` in order.

        Colours (normals, labels) are kept only if every cloud has them.
        """
        clouds = list(clouds)
        if not clouds:
            return PointCloud(np.empty((0, 3)))
        pts = np.concatenate([c.points for c in clouds])
        cols = None
        if all(c.colors is not None for c in clouds):
            cols = np.concatenate([c.colors for c in clouds])  # type: ignore[misc]
        nrm = None
        if all(c.normals is not None for c in clouds):
            nrm = np.concatenate([c.normals for c in clouds])  # type: ignore[misc]
        lab = None
        if all(c.labels is not None for c in clouds):
            lab = np.concatenate([c.labels for c in clouds])  # type: ignore[misc]
        return PointCloud(pts, cols, nrm, labels=lab)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(3,) minimum and (3,) maximum of the finite points (NaN if there are none)."""
        p = self.points[self.finite_mask()]
        if p.shape[0] == 0:
            nan = np.full(3, np.nan)
            return nan, nan.copy()
        return p.min(axis=0), p.max(axis=0)

    def to_open3d(self) -> Any:
        """An ``open3d.geometry.PointCloud`` (needs open3d)."""
        try:
            import open3d as o3d
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("to_open3d needs open3d: pip install open3d") from exc
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points))
        if self.colors is not None:
            pc.colors = o3d.utility.Vector3dVector(self.colors)
        if self.normals is not None:
            pc.normals = o3d.utility.Vector3dVector(self.normals)
        return pc

    @staticmethod
    def from_open3d(pc: Any) -> PointCloud:
        """From an ``open3d.geometry.PointCloud``."""
        pts = np.asarray(pc.points, dtype=np.float64)
        cols = np.asarray(pc.colors, dtype=np.float64) if pc.has_colors() else None
        nrm = np.asarray(pc.normals, dtype=np.float64) if pc.has_normals() else None
        return PointCloud(pts, cols, nrm)


def check_cloud(cloud: object) -> PointCloud:
    """``cloud`` itself if it is a :class:`PointCloud`, else :class:`InputError` with the fix."""
    if not isinstance(cloud, PointCloud):
        raise InputError(
            f"cloud must be a PointCloud; got {type(cloud).__name__}: "
            "wrap an (N, 3) array with PointCloud(points)"
        )
    return cloud
