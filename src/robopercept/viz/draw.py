"""Draw points, lines, boxes, masks and text onto RGB images.

Every function returns a new RGB uint8 image (a gray input is expanded to RGB) and
leaves its input unchanged. Rasterization is Pillow's, which is not a perception method.
"""

from __future__ import annotations

import colorsys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from robopercept._checks import check_image, check_ndim

if TYPE_CHECKING:
    from PIL import Image, ImageDraw
from robopercept.errors import InputError

__all__ = [
    "check_color",
    "draw_boxes",
    "draw_chessboard",
    "draw_lines",
    "draw_mask",
    "draw_points",
    "draw_text",
    "pil_canvas",
    "to_rgb8",
]

Color = tuple[int, int, int]


def to_rgb8(image: np.ndarray) -> np.ndarray:
    """Return an RGB uint8 copy: gray is replicated; float in [0, 1] is scaled by 255.

    This is the one place where float images are scaled, because drawing needs bytes.
    """
    image = check_image(image, allow_bool=True)
    if image.dtype == np.bool_:
        img = image.astype(np.uint8) * 255
    elif image.dtype == np.uint8:
        img = image.copy()
    elif image.dtype.kind == "f":
        img = np.round(np.clip(image, 0.0, 1.0) * 255.0).astype(np.uint8)
    elif image.dtype == np.uint16:
        img = (image >> 8).astype(np.uint8)
    else:
        img = np.clip(image, 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return np.ascontiguousarray(img)


def check_color(color: Sequence[int]) -> Color:
    """Return ``color`` as an ``(r, g, b)`` tuple of ints in 0..255, or raise
    :class:`~robopercept.errors.InputError` naming the expected form."""
    c = tuple(int(v) for v in color)
    if len(c) != 3 or not all(0 <= v <= 255 for v in c):
        raise InputError(f"color must be three integers in 0..255; got {color!r}")
    return c  # type: ignore[return-value]


def pil_canvas(image: np.ndarray) -> tuple[Image.Image, ImageDraw.ImageDraw]:
    """A Pillow image of :func:`to_rgb8` ``(image)`` and a drawing context on it.

    The caller draws, then reads the result back with ``np.asarray(pil)``.
    """
    from PIL import Image, ImageDraw

    pil = Image.fromarray(to_rgb8(image))
    return pil, ImageDraw.Draw(pil)


def draw_points(
    image: np.ndarray,
    points: np.ndarray,
    *,
    color: Sequence[int] = (255, 0, 0),
    radius: float = 3.0,
    filled: bool = False,
) -> np.ndarray:
    """Draw circles of ``radius`` at ``(x, y)`` points.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    points : (N, 2) array_like
        ``(x, y)`` pixel coordinates.
    color : (3,) ints
    radius : float
    filled : bool

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    pts = check_ndim(np.asarray(points, dtype=np.float64).reshape(-1, 2), "points", (2,))
    col = check_color(color)
    pil, draw = pil_canvas(image)
    for x, y in pts[np.isfinite(pts).all(axis=1)]:
        box = (x - radius, y - radius, x + radius, y + radius)
        draw.ellipse(box, outline=col, fill=col if filled else None)
    return np.asarray(pil)


def draw_lines(
    image: np.ndarray, segments: np.ndarray, *, color: Sequence[int] = (0, 255, 0), width: int = 1
) -> np.ndarray:
    """Draw line segments.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    segments : (N, 4) array_like
        ``x0, y0, x1, y1`` per segment.
    color : (3,) ints
    width : int

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    col = check_color(color)
    pil, draw = pil_canvas(image)
    for x0, y0, x1, y1 in seg[np.isfinite(seg).all(axis=1)]:
        draw.line([(x0, y0), (x1, y1)], fill=col, width=int(width))
    return np.asarray(pil)


def draw_boxes(
    image: np.ndarray,
    boxes: np.ndarray,
    *,
    color: Sequence[int] = (255, 255, 0),
    width: int = 2,
    labels: Sequence[str] | None = None,
) -> np.ndarray:
    """Draw axis-aligned boxes ``(x, y, w, h)``, optionally captioned.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    boxes : (N, 4) array_like
        ``x, y, width, height`` (OpenCV's ``Rect`` order).
    color : (3,) ints
    width : int
    labels : sequence of str, optional
        One caption per box, drawn above its top-left corner.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    if labels is not None and len(labels) != len(b):
        raise InputError(f"labels must have one entry per box ({len(b)}); got {len(labels)}")
    col = check_color(color)
    pil, draw = pil_canvas(image)
    for i, (x, y, w, h) in enumerate(b):
        draw.rectangle([x, y, x + w - 1, y + h - 1], outline=col, width=int(width))
        if labels is not None:
            draw.text((x + 2, max(0.0, y - 12)), str(labels[i]), fill=col)
    return np.asarray(pil)


def draw_text(
    image: np.ndarray,
    text: str,
    origin: tuple[float, float] = (5, 5),
    *,
    color: Sequence[int] = (255, 255, 255),
    size: int = 14,
    background: Sequence[int] | None = (0, 0, 0),
) -> np.ndarray:
    """Write ``text`` with its top-left corner at ``origin`` = (x, y).

    Uses Pillow's built-in font at ``size`` pixels, on a filled background box unless
    ``background`` is None, so it stays readable on any image.
    """
    from PIL import ImageFont

    col = check_color(color)
    pil, draw = pil_canvas(image)
    try:
        font = ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    if background is not None:
        box = draw.textbbox(origin, text, font=font)
        draw.rectangle(
            [box[0] - 2, box[1] - 2, box[2] + 2, box[3] + 2], fill=check_color(background)
        )
    draw.text(origin, text, fill=col, font=font)
    return np.asarray(pil)


def draw_mask(
    image: np.ndarray, mask: np.ndarray, *, color: Sequence[int] = (0, 255, 0), alpha: float = 0.5
) -> np.ndarray:
    """Blend ``color`` over the pixels where ``mask`` is true: ``(1 - a) I + a c``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    mask : (H, W) bool array_like
    color : (3,) ints
    alpha : float in [0, 1]

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    img = to_rgb8(image)
    m = check_ndim(mask, "mask", (2,)).astype(bool)
    if m.shape != img.shape[:2]:
        raise InputError(f"mask must have the image's shape {img.shape[:2]}; got {m.shape}")
    if not 0.0 <= alpha <= 1.0:
        raise InputError(f"alpha must be in [0, 1]; got {alpha}")
    col = np.asarray(check_color(color), dtype=np.float64)
    blended = (1.0 - alpha) * img[m].astype(np.float64) + alpha * col
    img[m] = np.round(blended).astype(np.uint8)
    return img


def draw_chessboard(
    image: np.ndarray, corners: np.ndarray, pattern_size: tuple[int, int], found: bool = True
) -> np.ndarray:
    """Draw detected chessboard corners as ``cv2.drawChessboardCorners`` does: a found
    board as rows of coloured circles joined in detection order (row colours run through
    a rainbow, so the first corner and the order are visible), a partial one in red.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    corners : (N, 2) array_like
    pattern_size : (int, int)
        Corners per row and per column.
    found : bool

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    pil, draw = pil_canvas(image)
    r = max(3.0, image.shape[0] / 120)
    w = max(int(pattern_size[0]), 1)
    for k, (x, y) in enumerate(pts):
        if found:
            hue = (k // w) / max(len(pts) // w, 1)
            col = tuple(int(255 * v) for v in colorsys.hsv_to_rgb(0.75 * hue, 1.0, 1.0))
            if k:
                draw.line([tuple(pts[k - 1]), (x, y)], fill=col, width=2)
        else:
            col = (255, 0, 0)
        draw.ellipse((x - r, y - r, x + r, y + r), outline=col, width=2)
    return np.asarray(pil)
