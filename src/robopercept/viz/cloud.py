"""Pictures of point clouds: a pinhole render with a z-buffer, and a legend naming
the colours (segments, planes, clusters) beside it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robopercept._checks import check_int, check_points, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.viz.draw import check_color, check_picture_size, legend_panel

__all__ = ["MAX_POINT_SIZE", "render_points"]

#: the largest ``point_size`` of :func:`render_points` (each point is drawn as a
#: ``point_size`` x ``point_size`` square, one pass per pixel of it)
MAX_POINT_SIZE = 64


def render_points(
    points: np.ndarray,
    colors: np.ndarray | None = None,
    *,
    size: tuple[int, int] = (640, 480),
    fov_deg: float = 60.0,
    point_size: int = 2,
    background: tuple[int, int, int] = (255, 255, 255),
    legend: Sequence[tuple[str, Sequence[int]]] | None = None,
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
        Positive integers, at most 2**26 pixels in all.
    fov_deg : float
        In (0, 180).
    point_size : int
        1 to :data:`MAX_POINT_SIZE`.
    background : RGB
        Three integers in 0..255.
    legend : sequence of (str, RGB), optional
        What the colours mean, e.g. ``[("unassigned", (128, 128, 128)), ("plane 1",
        (...)), ("cluster 1", (...))]``: listed with a swatch each in a white panel to
        the right of the render (:func:`~robopercept.viz.draw.legend_panel`), never
        over the points, as Open3D's and matplotlib's legends name segment colours.

    Returns
    -------
    (H, W, 3) uint8 ndarray
        ``(max(H, rows), W + panel, 3)`` with a legend.

    Examples
    --------
    >>> pts = np.array([[0.0, 0.0, 2.0], [0.1, 0.0, 2.0]])
    >>> render_points(pts, size=(64, 48)).shape
    (48, 64, 3)
    >>> pic = render_points(pts, size=(64, 48), legend=[("plane 1", (0, 0, 255))])
    >>> pic.shape[0], pic.shape[1] > 64
    (48, True)
    """
    p = check_points(points, "points", 3)
    if not isinstance(size, (tuple, list)) or len(size) != 2:
        raise InputError(f"size must be the image's (width, height); got {plain_repr(size)}")
    w, h = check_picture_size(size[0], size[1], "render (size)")
    fov_deg = check_real(fov_deg, "fov_deg", 0.0, 180.0, low_inclusive=False, high_inclusive=False)
    point_size = check_int(point_size, "point_size", 1)
    if point_size > MAX_POINT_SIZE:
        raise InputError(f"point_size must be at most {MAX_POINT_SIZE}; got {point_size}")
    bg = check_color(background, "background")
    if legend is not None:
        legend_panel(np.zeros((1, 1), np.uint8), legend)  # (checks it before the work)
    c = None
    if colors is not None:
        c = np.asarray(colors) if isinstance(colors, np.ndarray) else check_points(colors, "colors")
        if c.shape != p.shape:
            raise InputError(f"colors must have shape {p.shape}; got {c.shape}")
        if c.dtype.kind not in "biuf" or not np.isfinite(c).all():
            raise InputError("colors must be finite real numbers, RGB in [0, 1] (float) or uint8")
    img = np.empty((h, w, 3), dtype=np.uint8)
    img[:] = bg
    front = np.isfinite(p).all(axis=1) & (p[:, 2] > 1e-6)
    if not front.any():
        return img if legend is None else legend_panel(img, legend)
    if c is None:
        z = p[front, 2]
        # z is in (1e-6, 1.8e308]: halves keep the range finite
        span = max(float(z.max() * 0.5 - z.min() * 0.5), 1e-9)
        shade = 1.0 - 0.7 * (z * 0.5 - z.min() * 0.5) / span
        col8 = (np.outer(shade, [60, 110, 200])).astype(np.uint8)
    else:
        cf = c[front]
        col8 = cf if cf.dtype == np.uint8 else np.clip(np.rint(cf * 255), 0, 255).astype(np.uint8)
    f = (w / 2) / np.tan(np.radians(fov_deg) / 2)
    with np.errstate(over="ignore", invalid="ignore"):
        uf = np.floor(f * p[front, 0] / p[front, 2] + w / 2)
        vf = np.floor(f * p[front, 1] / p[front, 2] + h / 2)
    # (points that project far outside are dropped before the integer cast)
    ok = (uf > -point_size) & (uf < w) & (vf > -point_size) & (vf < h)
    col8 = col8[ok]
    q = p[front][ok]
    u = uf[ok].astype(np.int64)
    v = vf[ok].astype(np.int64)
    order = np.argsort(-q[:, 2], kind="stable")  # far first: near points overwrite
    u, v, col8 = u[order], v[order], col8[order]
    for du in range(point_size):
        for dv in range(point_size):
            uu, vv = u + du, v + dv
            inside = (uu >= 0) & (uu < w) & (vv >= 0) & (vv < h)
            img[vv[inside], uu[inside]] = col8[inside]
    return img if legend is None else legend_panel(img, legend)
