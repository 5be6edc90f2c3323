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

from robopercept._checks import check_int, check_ndim, check_real, check_size, plain_repr
from robopercept.errors import InputError
from robopercept.viz.draw import (
    check_color,
    check_picture_size,
    check_stroke,
    check_xy,
    clip_segments,
    pil_canvas,
    to_rgb8,
)

__all__ = [
    "ARROW_FRACTION",
    "MAX_ARROW_SCALE",
    "MAX_WHEEL_SIZE",
    "arrow_scale",
    "dense_flow_picture",
    "draw_flow",
    "draw_trails",
    "flow_to_color",
    "flow_wheel",
]

#: the largest :func:`flow_wheel` (a legend; 2049 px is 4 Mpx)
MAX_WHEEL_SIZE = 2049
#: :func:`arrow_scale`'s default: the median arrow at least this share of the diagonal
ARROW_FRACTION = 0.02
#: :func:`arrow_scale`'s default cap (beyond it, sub-pixel noise would fill the picture)
MAX_ARROW_SCALE = 100.0


def arrow_scale(
    flow: np.ndarray,
    size: tuple[int, int],
    *,
    fraction: float = ARROW_FRACTION,
    max_scale: float = MAX_ARROW_SCALE,
) -> float:
    r"""The arrow lengthening that makes flow arrows visible: :func:`draw_flow`'s
    ``scale``.

    With :math:`m` the median length of the finite vectors and :math:`D` the diagonal
    of the picture, the arrows need the factor :math:`s^* = f D / m` for the median
    arrow to be :math:`f D` pixels long (``fraction`` :math:`f`, 2 % of the diagonal by
    default: 14 px on a 584 x 388 image, 44 px at 1920 x 1080). The result is
    :math:`s^*` rounded up to 1, 2, 2.5 or 5 times a power of ten (a factor a reader
    can say: "arrows x 5"), at least 1 (long arrows are never shortened) and at most
    ``max_scale``. No finite vector, or a median of 0 (nothing moves), gives 1.

    Parameters
    ----------
    flow : (N, 2) array_like
        Displacements ``(u, v)`` in pixels; NaN rows (failed tracks) are ignored.
    size : (width, height)
        The picture's size in pixels.
    fraction : float
        Wanted median arrow length as a share of the diagonal, in (0, 1].
    max_scale : float
        Largest factor returned, >= 1.

    Returns
    -------
    float

    Raises
    ------
    InputError
        ``flow`` not ``(N, 2)`` real numbers, a bad size, fraction or cap.

    Examples
    --------
    Motions of about 1 px on a 584 x 388 image (diagonal 701 px): arrows need
    14 / 1.0 = 14x, rounded up to 20.

    >>> arrow_scale(np.array([[1.0, 0.0], [0.0, 1.0], [0.6, 0.8]]), (584, 388))
    20.0
    >>> arrow_scale(np.array([[30.0, 40.0]]), (584, 388))  # already long enough
    1.0
    """
    f = check_xy(flow, "flow")
    w, h = check_size(size, "size")
    fraction = check_real(fraction, "fraction", 0.0, 1.0, low_inclusive=False)
    max_scale = check_real(max_scale, "max_scale", 1.0)
    ok = np.isfinite(f).all(axis=1)
    if not ok.any():
        return 1.0
    with np.errstate(over="ignore"):
        m = float(np.median(np.hypot(f[ok, 0], f[ok, 1])))
    if not m > 0:
        return 1.0
    need = fraction * float(np.hypot(w, h)) / m
    if need <= 1.0:
        return 1.0
    if need >= max_scale:
        return float(max_scale)
    power = 10.0 ** np.floor(np.log10(need))
    nice = next(k * power for k in (1.0, 2.0, 2.5, 5.0, 10.0) if k * power >= need * (1 - 1e-12))
    return float(min(nice, max_scale))


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

    f = check_ndim(flow, "flow", (3,))
    if f.shape[2] != 2 or f.dtype.kind not in "biuf":
        raise InputError(f"flow must be a real (H, W, 2) array; got {f.shape} {f.dtype}")
    f = f.astype(np.float64)
    valid = np.isfinite(f).all(axis=2)
    mag = np.hypot(f[..., 0], f[..., 1])
    if max_magnitude is None:
        top = float(np.percentile(mag[valid], 99.0)) if valid.any() else 0.0
    else:
        top = check_real(max_magnitude, "max_magnitude", 0.0, low_inclusive=False)
    hue = np.mod(np.arctan2(f[..., 1], f[..., 0]), 2 * np.pi) / (2 * np.pi)
    sat = np.zeros_like(mag) if top <= 0 else np.minimum(mag / top, 1.0)
    hsv = np.stack([hue, sat, np.ones_like(mag)], axis=-1)
    hsv[~valid] = 0.0
    rgb = hsv_to_rgb(hsv, scale="unit")
    return np.round(rgb * 255.0).astype(np.uint8)


def flow_wheel(size: int = 101) -> np.ndarray:
    """The legend of :func:`flow_to_color`: a disc whose pixel at offset ``(u, v)`` from
    the centre has the colour of the flow ``(u, v)``; outside the disc is black.

    Parameters
    ----------
    size : int
        Side in pixels, 3 to :data:`MAX_WHEEL_SIZE`.

    Returns
    -------
    (size, size, 3) uint8 ndarray
    """
    size = check_int(size, "size", 3)
    if size > MAX_WHEEL_SIZE:
        raise InputError(f"size must be at most {MAX_WHEEL_SIZE} pixels; got {size}")
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
    step = check_int(step, "step", 1)
    if not isinstance(shape, (tuple, list)) or len(shape) not in (2, 3):
        raise InputError(f"shape must be the image's (H, W) or (H, W, 3); got {plain_repr(shape)}")
    W, H = check_picture_size(shape[1], shape[0], "flow picture (shape)")
    color = flow_to_color(field)
    step = min(step, max(H, W))  # (a step past the picture's size draws the same)
    # each grid vector fills its step x step cell: pixel (y, x) shows vector
    # (y // step, x // step), for the pixels the grid covers inside (H, W)
    h, w = min(color.shape[0] * step, H), min(color.shape[1] * step, W)
    full = np.zeros((H, W, 3), dtype=np.uint8)
    full[:h, :w] = color[np.arange(h)[:, None] // step, np.arange(w)[None, :] // step]
    side = min(101, H // 4 * 2 + 1, W // 4 * 2 + 1)
    if side >= 3:  # (no room for a legend in a picture under 12 pixels)
        wheel = flow_wheel(side)
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
    p0 = check_xy(start, "start")
    p1 = check_xy(end, "end")
    if p1.shape != p0.shape:
        raise InputError(f"start and end must have the same shape; got {p0.shape} and {p1.shape}")
    if status is None:
        ok = np.ones(len(p0), dtype=bool)
    else:
        ok = check_ndim(status, "status", (1,))
        if ok.dtype.kind not in "biuf":
            raise InputError(f"status must be bool (one per point); got dtype {ok.dtype}")
        ok = ok.astype(bool)
    if ok.shape != (len(p0),):
        raise InputError(f"status must have one entry per point ({len(p0)}); got {ok.shape}")
    col = check_color(color)
    bad = None if failed_color is None else check_color(failed_color, "failed_color")
    scale = check_real(scale, "scale")
    width = int(check_stroke(width, "width"))
    head = check_real(head, "head", 0.0)
    pil, draw = pil_canvas(image)
    W, H = pil.width, pil.height
    with np.errstate(over="ignore", invalid="ignore"):
        tip = p0 + scale * (p1 - p0)
    finite = np.isfinite(p0).all(axis=1) & np.isfinite(tip).all(axis=1)
    if bad is not None:
        for x, y in p0[~ok & np.isfinite(p0).all(axis=1)]:
            if -2 <= x <= W + 2 and -2 <= y <= H + 2:
                draw.ellipse((x - 1.5, y - 1.5, x + 1.5, y + 1.5), fill=bad)
    margin = width + 12.0  # (an arrowhead reaches 10 px beyond its tip)
    for (x0, y0), (x1, y1) in zip(p0[ok & finite], tip[ok & finite], strict=True):
        for sx0, sy0, sx1, sy1 in clip_segments(np.array([x0, y0, x1, y1]), W, H, margin):
            draw.line([(sx0, sy0), (sx1, sy1)], fill=col, width=width)
        if not (-margin <= x1 <= W + margin and -margin <= y1 <= H + margin):
            continue  # the head is off the picture
        length = np.hypot(0.5 * x1 - 0.5 * x0, 0.5 * y1 - 0.5 * y0) * 2.0
        if length < 1e-9:
            draw.point((x0, y0), fill=col)
            continue
        h = min(max(head * length, 2.0), 10.0)
        ux, uy = (x1 / length - x0 / length), (y1 / length - y0 / length)
        for side in (1.0, -1.0):  # two barbs at +-30 degrees from the shaft
            c, s = np.cos(np.pi / 6), side * np.sin(np.pi / 6)
            bx, by = -(c * ux - s * uy), -(s * ux + c * uy)
            draw.line([(x1, y1), (x1 + h * bx, y1 + h * by)], fill=col, width=width)
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
        Line width in ``[1, MAX_STROKE]`` pixels.
    radius : float
        Radius of the dot at the newest position, ``[0, MAX_STROKE]`` pixels.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    if isinstance(trails, np.ndarray) and trails.ndim == 3:
        trails = list(trails)
    if not isinstance(trails, (list, tuple)):
        raise InputError(
            f"trails must be a list of (K, 2) arrays, one per tracked point; got "
            f"{plain_repr(trails)}"
        )
    paths = [check_xy(t, f"trails[{i}]") for i, t in enumerate(trails)]
    cols = [(0, 255, 0)] * len(paths)
    if colors is not None:
        if isinstance(colors, (str, bytes)) or not hasattr(colors, "__len__"):
            raise InputError(f"colors must be (N, 3), one row per trail; got {plain_repr(colors)}")
        if len(colors) != len(paths):
            raise InputError(
                f"colors must have one row per trail ({len(paths)}); got {len(colors)}"
            )
        cols = [check_color(c, f"colors[{i}]") for i, c in enumerate(colors)]
    width = int(check_stroke(width, "width"))
    radius = check_stroke(radius, "radius", integer=False, minimum=0)
    pil, draw = pil_canvas(to_rgb8(image))
    W, H = pil.width, pil.height
    for t, col in zip(paths, cols, strict=True):
        t = t[np.isfinite(t).all(axis=1)]
        if len(t) == 0:
            continue
        if len(t) > 1:
            for x0, y0, x1, y1 in clip_segments(np.hstack([t[:-1], t[1:]]), W, H, width + 2):
                draw.line([(x0, y0), (x1, y1)], fill=col, width=width)
        x, y = t[-1]
        if -radius - 1 <= x <= W + radius and -radius - 1 <= y <= H + radius:
            draw.ellipse((x - radius, y - radius, x + radius, y + radius), fill=col)
    return np.asarray(pil)
