r"""Pictures of optical flow: arrows for sparse tracks, the HSV colour wheel for dense
fields, and trails of points tracked over many frames.

The colour coding of a dense field :math:`(u, v)` is the usual HSV wheel: the hue is
the direction,

.. math::

    H = \operatorname{atan2}(v, u) \bmod 2\pi \quad (0 = \text{right}, \text{red}),

and the saturation the speed relative to a chosen top speed :math:`m`,
:math:`S = \min(\sqrt{u^2 + v^2} / m, 1)`, at full value :math:`V = 1`. So still
pixels are white and fast ones strongly coloured (the Middlebury look); pixels
without a flow vector (NaN) are black. Image ``y`` points down, so a flow toward
the bottom of the picture has the hue of 90 degrees (yellow-green).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from robopercept._checks import check_ndim
from robopercept.errors import InputError
from robopercept.viz.draw import check_color, pil_canvas, to_rgb8

__all__ = ["dense_flow_picture", "draw_flow", "draw_trails", "flow_to_color", "flow_wheel"]


def flow_to_color(flow: np.ndarray, max_magnitude: float | None = None) -> np.ndarray:
    """Colour a dense flow field with the HSV wheel (see the module docstring).

    Parameters
    ----------
    flow : (H, W, 2) array_like
        ``(u, v)`` per pixel, NaN where unknown.
    max_magnitude : float, optional
        Speed shown fully saturated (default: the 99th percentile of the finite
        speeds, so a few wild vectors do not wash the picture out).

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    from robopercept.imaging.color import hsv_to_rgb

    f = check_ndim(np.asarray(flow, dtype=np.float64), "flow", (3,))
    if f.shape[2] != 2:
        raise InputError(f"flow must be (H, W, 2); got shape {f.shape}")
    valid = np.isfinite(f).all(axis=2)
    mag = np.hypot(f[..., 0], f[..., 1])
    if max_magnitude is None:
        top = float(np.percentile(mag[valid], 99.0)) if valid.any() else 0.0
    else:
        top = float(max_magnitude)
        if not np.isfinite(top) or top <= 0:
            raise InputError(f"max_magnitude must be a positive number; got {max_magnitude}")
    hue = np.mod(np.arctan2(f[..., 1], f[..., 0]), 2 * np.pi) / (2 * np.pi)
    sat = np.zeros_like(mag) if top <= 0 else np.minimum(mag / top, 1.0)
    hsv = np.stack([hue, sat, np.ones_like(mag)], axis=-1)
    hsv[~valid] = 0.0
    rgb = hsv_to_rgb(hsv, scale="unit")
    return np.round(rgb * 255.0).astype(np.uint8)


def flow_wheel(size: int = 101) -> np.ndarray:
    """The legend of :func:`flow_to_color`: a disc whose pixel at offset ``(u, v)`` from
    the centre has the colour of the flow ``(u, v)``; outside the disc is black."""
    if int(size) != size or size < 3:
        raise InputError(f"size must be an integer >= 3; got {size}")
    r = (size - 1) / 2.0
    yy, xx = np.mgrid[:size, :size].astype(np.float64)
    f = np.stack([xx - r, yy - r], axis=-1)
    f[np.hypot(f[..., 0], f[..., 1]) > r] = np.nan
    return flow_to_color(f, max_magnitude=r)


def dense_flow_picture(field: np.ndarray, step: int, shape: tuple[int, ...]) -> np.ndarray:
    """A sparse-grid flow field as a full-size colour picture with its legend.

    Each grid vector's :func:`flow_to_color` colour fills its ``step`` x ``step`` cell;
    the picture is cropped or padded (black) to ``shape``, and the
    :func:`flow_wheel` legend (up to 101 px, a quarter of the smaller side) sits in the
    bottom-right corner.

    Parameters
    ----------
    field : (h, w, 2) ndarray
        Flow ``(u, v)`` at the grid points, as :func:`~robopercept.motion.dense_flow`
        returns it (NaN where untracked: black).
    step : int
        The grid spacing in pixels.
    shape : (H, W) or (H, W, 3)
        The image's shape.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    if int(step) != step or step < 1:
        raise InputError(f"step must be an integer >= 1; got {step}")
    color = flow_to_color(field)
    picture = np.kron(color, np.ones((step, step, 1), dtype=np.uint8))
    H, W = shape[:2]
    full = np.zeros((H, W, 3), dtype=np.uint8)
    h, w = min(picture.shape[0], H), min(picture.shape[1], W)
    full[:h, :w] = picture[:h, :w]
    wheel = flow_wheel(min(101, H // 4 * 2 + 1, W // 4 * 2 + 1))
    full[-wheel.shape[0] :, -wheel.shape[1] :] = wheel
    return full


def draw_flow(
    image: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    *,
    status: np.ndarray | None = None,
    color: Sequence[int] = (0, 255, 0),
    failed_color: Sequence[int] | None = (255, 0, 0),
    scale: float = 1.0,
    width: int = 1,
    head: float = 0.3,
) -> np.ndarray:
    """Draw flow vectors as arrows from ``start`` toward ``end``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    start, end : (N, 2) array_like
        ``(x, y)`` positions; the arrow is ``start -> start + scale * (end - start)``.
    status : (N,) bool array_like, optional
        Tracked points are drawn in ``color``; the others as a dot in ``failed_color``
        (not at all if it is None).
    scale : float
        Lengthening of the arrows (small motions are hard to see at 1).
    width : int
    head : float
        Arrowhead length as a fraction of the arrow (at least 2 px, at most 10 px).

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    p0 = check_ndim(np.asarray(start, dtype=np.float64).reshape(-1, 2), "start", (2,))
    p1 = np.asarray(end, dtype=np.float64).reshape(-1, 2)
    if p1.shape != p0.shape:
        raise InputError(f"start and end must have the same shape; got {p0.shape} and {p1.shape}")
    ok = np.ones(len(p0), dtype=bool) if status is None else np.asarray(status, dtype=bool)
    if ok.shape != (len(p0),):
        raise InputError(f"status must have one entry per point ({len(p0)}); got {ok.shape}")
    col = check_color(color)
    pil, draw = pil_canvas(image)
    tip = p0 + float(scale) * (p1 - p0)
    finite = np.isfinite(p0).all(axis=1) & np.isfinite(tip).all(axis=1)
    if failed_color is not None:
        bad = check_color(failed_color)
        for x, y in p0[~ok & np.isfinite(p0).all(axis=1)]:
            draw.ellipse((x - 1.5, y - 1.5, x + 1.5, y + 1.5), fill=bad)
    for (x0, y0), (x1, y1) in zip(p0[ok & finite], tip[ok & finite], strict=True):
        draw.line([(x0, y0), (x1, y1)], fill=col, width=int(width))
        length = np.hypot(x1 - x0, y1 - y0)
        if length < 1e-9:
            draw.point((x0, y0), fill=col)
            continue
        h = min(max(head * length, 2.0), 10.0)
        ux, uy = (x1 - x0) / length, (y1 - y0) / length
        for side in (1.0, -1.0):  # two barbs at +-30 degrees from the shaft
            c, s = np.cos(np.pi / 6), side * np.sin(np.pi / 6)
            bx, by = -(c * ux - s * uy), -(s * ux + c * uy)
            draw.line([(x1, y1), (x1 + h * bx, y1 + h * by)], fill=col, width=int(width))
    return np.asarray(pil)


def draw_trails(
    image: np.ndarray,
    trails: Sequence[np.ndarray],
    *,
    colors: np.ndarray | None = None,
    width: int = 1,
    radius: float = 2.0,
) -> np.ndarray:
    """Draw the recent positions of tracked points as polylines ending in a dot.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    trails : sequence of (K, 2) arrays
        Each one point's positions ``(x, y)``, oldest first.
    colors : (N, 3) uint8 array_like, optional
        One colour per trail (default green).
    width : int
    radius : float
        Radius of the dot at the newest position.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    if colors is not None and len(colors) != len(trails):
        raise InputError(f"colors must have one row per trail ({len(trails)}); got {len(colors)}")
    pil, draw = pil_canvas(to_rgb8(image))
    for i, trail in enumerate(trails):
        t = np.asarray(trail, dtype=np.float64).reshape(-1, 2)
        t = t[np.isfinite(t).all(axis=1)]
        if len(t) == 0:
            continue
        col = (0, 255, 0) if colors is None else check_color(colors[i])
        if len(t) > 1:
            draw.line([tuple(p) for p in t], fill=col, width=int(width))
        x, y = t[-1]
        draw.ellipse((x - radius, y - radius, x + radius, y + radius), fill=col)
    return np.asarray(pil)
