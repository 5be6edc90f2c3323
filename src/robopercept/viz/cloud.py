"""Pictures of point clouds: a pinhole render with a z-buffer."""

from __future__ import annotations

import numpy as np

from robopercept._checks import check_points
from robopercept.errors import InputError

__all__ = ["render_points"]


def render_points(
    points: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    fov_deg: float = 60.0,
    point_size: int = 2,
    background: tuple[int, int, int] = (255, 255, 255),
) -> np.ndarray:
    r"""Render camera-frame points (x right, y down, z forward) as an RGB image.

    A pinhole camera at the origin looking along +z, with the focal length set by the
    horizontal field of view (:math:`f = \frac{W/2}{\tan(\mathrm{fov}/2)}`), projects
    :math:`u = f x / z + W/2`, :math:`v = f y / z + H/2`; each point is a square of
    ``point_size`` pixels and the nearest point wins each pixel (z-buffer). Points
    behind the camera or not finite are skipped.

    Parameters
    ----------
    points : (N, 3) array_like
    colors : (N, 3) array_like, optional
        RGB in [0, 1] (float) or uint8; default a depth shading.
    size : (W, H)
    fov_deg : float
    point_size : int
    background : RGB

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    p = check_points(points, "points", 3)
    w, h = (int(v) for v in size)
    if w < 1 or h < 1 or not 0 < fov_deg < 180 or point_size < 1:
        raise InputError(
            f"need size >= (1, 1), 0 < fov_deg < 180, point_size >= 1; got {size}, "
            f"{fov_deg}, {point_size}"
        )
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = background
    ok = np.isfinite(p).all(axis=1) & (p[:, 2] > 1e-6)
    if colors is None:
        z = p[ok, 2]
        shade = 1.0 - 0.7 * (z - z.min()) / max(float(np.ptp(z)) if z.size else 0.0, 1e-9)
        col8 = (np.outer(shade, [60, 110, 200])).astype(np.uint8)
    else:
        c = np.asarray(colors)
        if c.shape != p.shape:
            raise InputError(f"colors must have shape {p.shape}; got {c.shape}")
        c = c[ok]
        col8 = c if c.dtype == np.uint8 else np.clip(np.rint(c * 255), 0, 255).astype(np.uint8)
    q = p[ok]
    f = (w / 2) / np.tan(np.radians(fov_deg) / 2)
    u = np.floor(f * q[:, 0] / q[:, 2] + w / 2).astype(np.int64)
    v = np.floor(f * q[:, 1] / q[:, 2] + h / 2).astype(np.int64)
    order = np.argsort(-q[:, 2], kind="stable")  # far first: near points overwrite
    u, v, col8 = u[order], v[order], col8[order]
    for du in range(point_size):
        for dv in range(point_size):
            uu, vv = u + du, v + dv
            inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            img[vv[inside], uu[inside]] = col8[inside]
    return img
