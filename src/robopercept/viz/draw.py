"""Draw points, lines, boxes, masks and text onto RGB images.

Every function returns a new RGB uint8 image (a gray input is expanded to RGB) and
leaves its input unchanged. Rasterization is Pillow's, which is not a perception method.

Text is set in DejaVu Sans, the TrueType font matplotlib ships (found at run time in
``matplotlib.get_data_path()``, nothing downloaded), or Pillow's built-in scalable font
where that file is missing; its size follows the picture's height
(:func:`label_size_for`: 24 px on a 1080p frame), so captions stay readable at any
resolution. :func:`draw_label` is the one way labels (track ids, detection scores, blob
ids) are written on images: on a filled box of the label's colour, in black or white,
whichever contrasts more, kept inside the picture; the captions of :func:`draw_boxes`
never overlap (:func:`caption_boxes`). :func:`legend_panel` names colours in a panel
beside a picture.
"""

from __future__ import annotations

import colorsys
import functools
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_bool,
    check_image,
    check_int,
    check_ndim,
    check_points,
    check_real,
    check_reals,
    check_text,
    plain_repr,
)

if TYPE_CHECKING:
    from PIL import Image, ImageDraw, ImageFont
from robopercept.errors import InputError

__all__ = [
    "MAX_PICTURE_PIXELS",
    "MAX_STROKE",
    "caption_boxes",
    "check_color",
    "check_picture_size",
    "check_stroke",
    "check_xy",
    "clip_segments",
    "draw_boxes",
    "draw_chessboard",
    "draw_label",
    "draw_lines",
    "draw_mask",
    "draw_points",
    "draw_text",
    "enlarge_picture",
    "label_font",
    "label_size_for",
    "legend_panel",
    "pil_canvas",
    "to_rgb8",
]

Color = tuple[int, int, int]

#: the largest picture a viz function makes, width x height: 2**26 pixels (64 Mpx,
#: 192 MiB as RGB; an 8K frame is 33 Mpx)
MAX_PICTURE_PIXELS = 2**26
#: the largest line width, circle radius or font size in pixels (Pillow takes about a
#: minute to rasterize a circle of radius 1e6)
MAX_STROKE = 10_000


def enlarge_picture(img: np.ndarray, min_side: int) -> tuple[np.ndarray, int]:
    """Enlarge a small picture by the whole factor ``f = max(1, min_side // L)`` (``L``
    its longer side) with nearest-neighbour sampling, so pixels stay sharp and labels
    exact; returns the picture and ``f``. A point ``(x, y)`` of the pixel-centre
    convention (pixel ``c`` covers ``[c, c + 1)``) is ``(f x, f y)`` on the result.

    Examples
    --------
    >>> big, f = enlarge_picture(np.arange(4, dtype=np.uint8).reshape(2, 2), 5)
    >>> f, big.shape, big[:, :2].tolist()
    (2, (4, 4), [[0, 0], [0, 0], [2, 2], [2, 2]])
    """
    if not isinstance(img, np.ndarray) or img.ndim not in (2, 3) or min(img.shape[:2]) < 1:
        raise InputError(
            f"img must be a non-empty (H, W) or (H, W, 3) array; got {plain_repr(img)}"
        )
    side = check_int(min_side, "min_side", 1)
    if side > 1 << 15:
        raise InputError(f"min_side must be at most {1 << 15} pixels; got {side}")
    f = max(1, side // max(img.shape[:2]))
    if f > 1:
        img = np.repeat(np.repeat(img, f, axis=0), f, axis=1)
    return img, f


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


def check_color(color: Sequence[int], name: str = "color") -> Color:
    """Return ``color`` as an ``(r, g, b)`` tuple of ints in 0..255, or raise
    :class:`~robopercept.errors.InputError` naming the expected form.

    Integer-valued floats (``255.0``) and NumPy integers (a row of
    :func:`~robopercept.viz.label_colors`) are accepted; fractions, NaN, inf, None,
    strings and other lengths are refused.

    Examples
    --------
    >>> check_color(np.array([255, 0, 7], np.uint8))
    (255, 0, 7)
    """
    message = f"{name} must be three integers in 0..255 (r, g, b); got {plain_repr(color)}"
    try:
        c = check_reals(color, name, 3, 0.0, 255.0)
    except InputError:
        raise InputError(message) from None
    if (c != np.round(c)).any():
        raise InputError(message)
    return int(c[0]), int(c[1]), int(c[2])


def check_picture_size(width: Any, height: Any, what: str = "picture") -> tuple[int, int]:
    """Return ``(width, height)`` as ints after checking that they are positive integers
    whose product is at most :data:`MAX_PICTURE_PIXELS`.

    Parameters
    ----------
    width, height : int
    what : str
        The picture's name in messages (the parameter names are ``width``, ``height``).

    Returns
    -------
    (int, int)

    Raises
    ------
    InputError
        Not integers, below 1, or a picture of more than 2**26 pixels.

    Examples
    --------
    >>> check_picture_size(640, 480)
    (640, 480)
    """
    w, h = check_int(width, "width", 1), check_int(height, "height", 1)
    if w * h > MAX_PICTURE_PIXELS:
        raise InputError(
            f"the {what} would be {w}x{h} = {w * h} pixels; at most {MAX_PICTURE_PIXELS} "
            "(64 Mpx) are made: pass a smaller size"
        )
    return w, h


def check_stroke(value: Any, name: str, *, integer: bool = True, minimum: float = 1) -> float:
    """Return a line width (``integer=True``) or a radius as a number in
    ``[minimum, MAX_STROKE]`` pixels.

    Examples
    --------
    >>> check_stroke(2, "width"), check_stroke(0.5, "radius", integer=False, minimum=0)
    (2, 0.5)
    """
    v: float = check_int(value, name, int(minimum)) if integer else check_real(value, name, minimum)
    if v > MAX_STROKE:
        raise InputError(f"{name} must be at most {MAX_STROKE} pixels; got {plain_repr(value)}")
    return v


def check_xy(value: Any, name: str, columns: int = 2) -> np.ndarray:
    """Return ``value`` as a float64 ``(N, columns)`` array: rows of coordinates, one row
    given as ``(columns,)``, or an empty list; NaN/inf rows are kept (the drawing
    functions skip them).

    Examples
    --------
    >>> check_xy([3, 4], "points")
    array([[3., 4.]])
    """
    if isinstance(value, (list, tuple)) and len(value) == 0:
        return np.zeros((0, columns))
    arr = check_ndim(value, name, (1, 2))
    if arr.ndim == 1 and arr.shape[0] == columns:
        arr = arr[None, :]
    if arr.ndim == 2 and arr.shape[0] == 0:
        return np.zeros((0, columns))
    return check_points(arr, name, columns)


def clip_segments(segments: np.ndarray, width: int, height: int, margin: float) -> np.ndarray:
    r"""Clip line segments to the canvas grown by ``margin`` (Liang-Barsky).

    Pillow rasterizes a segment pixel by pixel over its whole length (5 s for 1e9
    pixels) and overflows on coordinates beyond the C ``int`` range, so segments are
    cut to the box :math:`[-m, W - 1 + m] 	imes [-m, H - 1 + m]` first: the part
    inside is unchanged, segments wholly outside or with a NaN/inf end are dropped.
    Ends that are not cut are returned as given; segments with a coordinate beyond
    1e12 are clipped in exact rational arithmetic (``x0 + u (x1 - x0)`` in float64
    would lose the canvas beside ends near 1e300, or overflow).

    Parameters
    ----------
    segments : (N, 4) float ndarray
        ``x0, y0, x1, y1``.
    width, height : int
        The canvas.
    margin : float
        Pixels kept beyond each edge (half a line width or more).

    Returns
    -------
    (M, 4) float64 ndarray
        The visible parts, M <= N.

    Examples
    --------
    >>> clip_segments(np.array([[-10.0, 5.0, 1e300, 5.0]]), 10, 10, 1.0)
    array([[-1.,  5., 10.,  5.]])
    """
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    seg = seg[np.isfinite(seg).all(axis=1)]
    box = (-margin, width - 1 + margin, -margin, height - 1 + margin)
    lo_x, hi_x, lo_y, hi_y = box
    xs, ys = seg[:, 0::2], seg[:, 1::2]
    seg = seg[
        (xs.max(axis=1) >= lo_x)
        & (xs.min(axis=1) <= hi_x)
        & (ys.max(axis=1) >= lo_y)
        & (ys.min(axis=1) <= hi_y)
    ]  # (the bounding box misses the canvas: so does the segment)
    far = (np.abs(seg) > _FAR).any(axis=1)
    out = np.empty_like(seg)
    keep = np.zeros(len(seg), dtype=bool)
    near = np.flatnonzero(~far)
    if near.size:
        out[near], keep[near] = _clip_near(seg[near], box)
    for i in np.flatnonzero(far):  # rare: exact rational arithmetic, one by one
        clipped = _clip_exact(seg[i], box)
        if clipped is not None:
            out[i], keep[i] = clipped, True
    return out[keep]


#: coordinates beyond which a segment is clipped exactly (float64 spacing there is 1e-4
#: px; near 1e300 the canvas is far below the precision of ``x0 + u (x1 - x0)``)
_FAR = 1e12


def _clip_near(seg: np.ndarray, box: tuple[float, float, float, float]) -> tuple:
    """Liang-Barsky on (N, 4) segments of moderate coordinates: the clipped segments
    (unchanged ends where not cut) and which ones are visible."""
    x0, y0, x1, y1 = seg.T
    dx, dy = x1 - x0, y1 - y0
    lo_x, hi_x, lo_y, hi_y = box
    u0, u1 = np.zeros(len(seg)), np.ones(len(seg))
    keep = np.ones(len(seg), dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for p, q in ((-dx, x0 - lo_x), (dx, hi_x - x0), (-dy, y0 - lo_y), (dy, hi_y - y0)):
            r = q / p
            keep &= ~((p == 0) & (q < 0))
            u0 = np.where(p < 0, np.maximum(u0, r), u0)
            u1 = np.where(p > 0, np.minimum(u1, r), u1)
    keep &= u0 <= u1
    out = np.stack(
        [
            np.where(u0 > 0, x0 + u0 * dx, x0),
            np.where(u0 > 0, y0 + u0 * dy, y0),
            np.where(u1 < 1, x0 + u1 * dx, x1),
            np.where(u1 < 1, y0 + u1 * dy, y1),
        ],
        axis=1,
    )
    out[:, 0::2] = np.clip(out[:, 0::2], lo_x, hi_x)  # (rounding: a hair outside)
    out[:, 1::2] = np.clip(out[:, 1::2], lo_y, hi_y)
    return out, keep


def _clip_exact(row: np.ndarray, box: tuple[float, float, float, float]) -> np.ndarray | None:
    """Liang-Barsky on one segment in exact rationals (every float is one), or None
    when it misses the box."""
    from fractions import Fraction

    x0, y0, x1, y1 = (Fraction(float(v)) for v in row)
    lo_x, hi_x, lo_y, hi_y = (Fraction(float(v)) for v in box)
    dx, dy = x1 - x0, y1 - y0
    u0, u1 = Fraction(0), Fraction(1)
    for p, q in ((-dx, x0 - lo_x), (dx, hi_x - x0), (-dy, y0 - lo_y), (dy, hi_y - y0)):
        if p == 0:
            if q < 0:
                return None
        elif p < 0:
            u0 = max(u0, q / p)
        else:
            u1 = min(u1, q / p)
    if u0 > u1:
        return None
    return np.array(
        [float(x0 + u0 * dx), float(y0 + u0 * dy), float(x0 + u1 * dx), float(y0 + u1 * dy)]
    )


def _visible_circles(pts: np.ndarray, radius: float, width: int, height: int) -> np.ndarray:
    """The finite centres whose circle of ``radius`` can touch the canvas."""
    ok = np.isfinite(pts).all(axis=1)
    with np.errstate(invalid="ignore"):
        ok &= (pts[:, 0] >= -radius - 1) & (pts[:, 0] <= width + radius)
        ok &= (pts[:, 1] >= -radius - 1) & (pts[:, 1] <= height + radius)
    return pts[ok]


def pil_canvas(image: np.ndarray) -> tuple[Image.Image, ImageDraw.ImageDraw]:
    """A Pillow image of :func:`to_rgb8` ``(image)`` and a drawing context on it.

    The caller draws, then reads the result back with ``np.asarray(pil)``.
    """
    from PIL import Image, ImageDraw

    pil = Image.fromarray(to_rgb8(image))
    return pil, ImageDraw.Draw(pil)


#: the font file text is set in: DejaVu Sans as matplotlib ships it
_FONT_FILE = ("fonts", "ttf", "DejaVuSans.ttf")
#: the text whose ink spans a label's height: cap height above the baseline, descender below
_HEIGHT_PROBE = "Ag"
#: anchors of :func:`draw_label`: horizontal (left, middle, right) x vertical (top,
#: middle, bottom) of the label's box
_ANCHORS = tuple(h + v for h in "lmr" for v in "tmb")


def label_size_for(height: int) -> int:
    """The font size in pixels for text on a picture ``height`` pixels tall:
    ``max(12, round(height / 45))`` (12 px up to 562 rows, 16 px at 720p, 24 px at 1080p,
    48 px at 4K), so that a label keeps the same share of the picture at any resolution
    and never falls below a readable 12 px.

    Parameters
    ----------
    height : int
        Picture height in pixels (>= 1).

    Returns
    -------
    int

    Examples
    --------
    >>> label_size_for(480), label_size_for(720), label_size_for(1080)
    (12, 16, 24)
    """
    h = check_int(height, "height", 1)
    return int(min(max(12, round(h / 45)), MAX_STROKE))


@functools.lru_cache(maxsize=1)
def _font_file() -> str | None:
    """DejaVuSans.ttf from matplotlib's data folder, or None when it is not there."""
    try:
        import matplotlib
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        return None
    path = Path(matplotlib.get_data_path()).joinpath(*_FONT_FILE)
    return str(path) if path.is_file() else None


@functools.lru_cache(maxsize=64)
def _load_font(size: int) -> Any:
    from PIL import ImageFont

    path = _font_file()
    if path is not None:
        try:
            return ImageFont.truetype(path, size=size)
        except OSError:  # (an unreadable file, or Pillow without FreeType)
            pass
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # pragma: no cover - Pillow < 10.1: the fixed bitmap font
        return ImageFont.load_default()


def label_font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """The font text on images is set in, at ``size`` pixels (the em size).

    DejaVu Sans from matplotlib's data folder (``matplotlib.get_data_path()``, the file
    ``fonts/ttf/DejaVuSans.ttf``: no download, no system font needed); Pillow's built-in
    scalable font (``ImageFont.load_default(size=...)``) where that file is missing.
    Fonts are cached per size.

    Parameters
    ----------
    size : int
        In ``[1, MAX_STROKE]`` pixels.

    Returns
    -------
    PIL.ImageFont.FreeTypeFont
        (or Pillow's bitmap font on a Pillow built without FreeType).

    Examples
    --------
    >>> font = label_font(24)
    >>> left, top, right, bottom = font.getbbox("Ag", anchor="ls")
    >>> 18 <= bottom - top <= 30
    True
    """
    return _load_font(int(check_stroke(size, "size")))


def _contrast(color: Color) -> Color:
    """Black or white, whichever contrasts more with ``color`` (its luma
    ``0.299 R + 0.587 G + 0.114 B`` above or below 150)."""
    luma = 0.299 * color[0] + 0.587 * color[1] + 0.114 * color[2]
    return (0, 0, 0) if luma > 150 else (255, 255, 255)


def _label_box(
    text: str, font: Any, xy: tuple[float, float], anchor: str, canvas: tuple[int, int]
) -> tuple[int, int, int, int, int, int]:
    """Where a label goes: its box ``x0, y0, width, height`` (whole pixels, inside the
    ``canvas`` = (width, height) where it fits) and the baseline origin of its text."""
    left, _, right, _ = font.getbbox(text, anchor="ls")
    _, top, _, bottom = font.getbbox(_HEIGHT_PROBE, anchor="ls")
    size = max(1, int(getattr(font, "size", bottom - top)))
    pad = max(2, round(size / 8))
    left = min(left, 0)
    bw = int(right - left) + 2 * pad
    bh = int(bottom - top) + 2 * pad
    x0 = xy[0] - {"l": 0.0, "m": bw / 2, "r": float(bw)}[anchor[0]]
    y0 = xy[1] - {"t": 0.0, "m": bh / 2, "b": float(bh)}[anchor[1]]
    w, h = canvas
    x = round(min(max(x0, 0.0), float(max(w - bw, 0))))
    y = round(min(max(y0, 0.0), float(max(h - bh, 0))))
    return x, y, bw, bh, x + pad - int(left), y + pad - int(top)


def _put_label(
    draw: ImageDraw.ImageDraw,
    canvas: tuple[int, int],
    text: str,
    xy: tuple[float, float],
    font: Any,
    color: Color,
    text_color: Color | None,
    anchor: str,
) -> tuple[int, int, int, int]:
    """Draw one label on ``draw``; returns its box ``x0, y0, x1, y1`` (inclusive)."""
    x, y, bw, bh, tx, ty = _label_box(text, font, xy, anchor, canvas)
    draw.rectangle([x, y, x + bw - 1, y + bh - 1], fill=color)
    fill = _contrast(color) if text_color is None else text_color
    draw.text((tx, ty), text, fill=fill, font=font, anchor="ls")
    return x, y, x + bw - 1, y + bh - 1


def draw_label(
    image: np.ndarray,
    text: str,
    xy: tuple[float, float],
    *,
    color: Sequence[int] = (255, 255, 0),
    size: int | None = None,
    anchor: str = "lb",
    text_color: Sequence[int] | None = None,
) -> np.ndarray:
    """Write a one-line label on a filled box: a track id, a detection score, a blob id.

    The box is filled with ``color`` and the text written in black or white, whichever
    contrasts more (luma ``0.299 R + 0.587 G + 0.114 B`` above 150: black), as
    OpenCV-based and Ultralytics overlays caption boxes. Its height is the font's ink
    height from cap top to descender (about ``0.96 size``) plus a padding of
    ``max(2, size / 8)`` pixels above and below, whatever the text; the label is moved
    inside the picture where ``xy`` would put it (partly) outside.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    text : str
        One line.
    xy : (float, float)
        The point ``(x, y)`` the label's box is anchored at.
    color : (3,) ints
        The box's fill (the colour of the thing labelled).
    size : int, optional
        Font size in pixels (default :func:`label_size_for` of the picture's height:
        24 px at 1080p).
    anchor : str
        Which point of the box sits at ``xy``: a horizontal letter (``l`` left, ``m``
        middle, ``r`` right) then a vertical one (``t`` top, ``m`` middle, ``b``
        bottom). ``"lb"`` (default) puts the label above ``xy``, as a caption on a box's
        top-left corner; ``"mm"`` centres it on ``xy``.
    text_color : (3,) ints, optional
        Overrides the contrasting black or white.

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Raises
    ------
    InputError
        ``text`` not a one-line string, a bad colour, anchor, size or ``xy``.

    Examples
    --------
    >>> out = draw_label(np.zeros((1080, 1920), np.uint8), "ID 7", (100, 100))
    >>> rows = np.flatnonzero(out.any(axis=(1, 2)))
    >>> int(rows.min()), int(rows.max())  # a 29 px box above y = 100
    (71, 99)
    >>> out[80, 100].tolist()  # the yellow box (text in black)
    [255, 255, 0]
    """
    text = check_text(text, "text")
    if "\n" in text or "\r" in text:
        raise InputError(f"text must be one line; got {plain_repr(text)}: draw one label per line")
    x, y = check_reals(xy, "xy", 2)
    col = check_color(color)
    tcol = None if text_color is None else check_color(text_color, "text_color")
    if not isinstance(anchor, str) or anchor not in _ANCHORS:
        raise InputError(
            f"anchor must be one of {', '.join(_ANCHORS)} (horizontal l/m/r then vertical "
            f"t/m/b); got {plain_repr(anchor)}"
        )
    pil, draw = pil_canvas(image)
    font = label_font(label_size_for(pil.height) if size is None else size)
    _put_label(draw, (pil.width, pil.height), text, (float(x), float(y)), font, col, tcol, anchor)
    return np.asarray(pil)


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
        In ``[0, MAX_STROKE]`` pixels.
    filled : bool

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    pts = check_xy(points, "points")
    col = check_color(color)
    radius = check_stroke(radius, "radius", integer=False, minimum=0)
    filled = check_bool(filled, "filled")
    pil, draw = pil_canvas(image)
    for x, y in _visible_circles(pts, radius, pil.width, pil.height):
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
        Line width in ``[1, MAX_STROKE]`` pixels.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    seg = check_xy(segments, "segments", 4)
    col = check_color(color)
    width = int(check_stroke(width, "width"))
    pil, draw = pil_canvas(image)
    for x0, y0, x1, y1 in clip_segments(seg, pil.width, pil.height, width + 2):
        draw.line([(x0, y0), (x1, y1)], fill=col, width=width)
    return np.asarray(pil)


def _box_colors(color: Any, n: int) -> list[Color]:
    """One colour per box: ``color`` is one ``(r, g, b)`` or an ``(N, 3)`` array of them."""
    rows = None
    if isinstance(color, np.ndarray) and color.ndim == 2:
        rows = list(color)
    elif (
        isinstance(color, (list, tuple))
        and len(color) > 0
        and all(isinstance(c, (list, tuple, np.ndarray)) for c in color)
    ):
        rows = list(color)
    if rows is None:
        return [check_color(color)] * n
    if len(rows) != n:
        raise InputError(
            f"color must be one (r, g, b) or one row per box ({n}); got {len(rows)} rows"
        )
    return [check_color(c, f"color[{i}]") for i, c in enumerate(rows)]


def _overlaps(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> bool:
    """Whether two inclusive pixel rectangles ``x0, y0, x1, y1`` share a pixel."""
    return not (a[2] < b[0] or b[2] < a[0] or a[3] < b[1] or b[3] < a[1])


#: how many label heights a caption may be stacked above or below its box's corner
_STACK = 3


def _caption_candidates(
    box: tuple[float, float, float, float], bh: int
) -> list[tuple[tuple[float, float], str]]:
    """Where a caption of a box ``x0, y0, x1, y1`` (inclusive corners) may go, in order
    of preference: ``(xy, anchor)`` of :func:`_label_box`."""
    x0, y0, x1, y1 = box
    above = [((x0, y0), "lb")] if y0 >= bh else []
    first = [*above, ((x0, y0), "lt"), ((x0, y1 + 1), "lt"), ((x0, y1 + 1), "lb")]
    right = [((x1 + 1, y0), "rb"), ((x1 + 1, y0), "rt")]
    stacked = []
    for k in range(1, _STACK + 1):
        stacked += [((x0, y0 - k * bh), "lb"), ((x0, y1 + 1 + k * bh), "lt")]
    return first + right + stacked


def _place_captions(
    texts: Sequence[str],
    boxes: Sequence[tuple[float, float, float, float]],
    font: Any,
    canvas: tuple[int, int],
) -> list[tuple[int, int, int, int, int, int] | None]:
    """The :func:`_label_box` of each caption, placed so that no two overlap, or None
    where no free place is left."""
    placed: list[tuple[int, int, int, int]] = []
    out: list[tuple[int, int, int, int, int, int] | None] = []
    for text, box in zip(texts, boxes, strict=True):
        bh = _label_box(text, font, (box[0], box[1]), "lt", canvas)[3]
        found = None
        for xy, anchor in _caption_candidates(box, bh):
            spot = _label_box(text, font, xy, anchor, canvas)
            rect = (spot[0], spot[1], spot[0] + spot[2] - 1, spot[1] + spot[3] - 1)
            if not any(_overlaps(rect, r) for r in placed):
                found = spot
                placed.append(rect)
                break
        out.append(found)
    return out


def _drawn_corners(
    b: np.ndarray, canvas: tuple[int, int], width: int
) -> list[tuple[int, tuple[float, float, float, float]]]:
    """The boxes ``(x, y, w, h)`` that :func:`draw_boxes` outlines, as ``(index,
    (x0, y0, x1, y1))`` with inclusive corners, those far beyond the canvas moved onto
    its margin; empty, non-finite and wholly outside boxes are left out."""
    m = width + 2.0  # corners beyond the canvas by more than this are moved onto its margin
    w, h = canvas
    out = []
    for i, (x, y, bw, bh) in enumerate(b):
        x0, y0 = x, y
        x1, y1 = x + (bw - 1), y + (bh - 1)
        if not np.isfinite([x0, y0, x1, y1]).all():
            continue
        if x1 < x0 or y1 < y0 or x1 < -m or y1 < -m or x0 > w + m or y0 > h + m:
            continue  # empty, or wholly outside
        xs = np.clip([x0, x1], -m, w + m)
        ys = np.clip([y0, y1], -m, h + m)
        out.append((i, (float(xs[0]), float(ys[0]), float(xs[1]), float(ys[1]))))
    return out


def caption_boxes(
    texts: Sequence[str],
    boxes: npt.ArrayLike,
    canvas: tuple[int, int],
    *,
    size: int | None = None,
    width: int = 2,
) -> list[tuple[int, int, int, int] | None]:
    """Where :func:`draw_boxes` writes the captions of ``(x, y, w, h)`` boxes: each
    caption's rectangle ``x0, y0, x1, y1`` (inclusive pixels), or None for a caption
    left out.

    Captions are placed in the order given (put the most important first), each at the
    first of these places that no caption placed before it overlaps: above the box's
    top-left corner (when there is room above), inside below its top edge, below its
    bottom edge, inside above its bottom edge, above or inside its top-right corner,
    then stacked up to three label heights above or below the box. A caption that
    finds no free place is left out (the box is still drawn), so no two captions ever
    overlap; every rectangle lies inside the canvas where the label fits in it.

    Parameters
    ----------
    texts : sequence of str
        One caption per box (one line; runs of white space become one space; an empty
        one, or None, has no place).
    boxes : (N, 4) array_like
        ``x, y, width, height``.
    canvas : (int, int)
        The picture's ``(width, height)``.
    size : int, optional
        Font size in pixels (default :func:`label_size_for` of the canvas height).
    width : int
        The outline width (boxes far outside the canvas are moved onto a margin of
        ``width + 2`` pixels, as they are drawn).

    Returns
    -------
    list of (int, int, int, int) or None

    Examples
    --------
    >>> r = caption_boxes(["a 0.9", "b 0.8"], [[100, 100, 40, 40], [104, 100, 40, 40]],
    ...                   (640, 480))
    >>> r[0][3] < 100, r[1][1] >= r[0][3] or r[1][0] > r[0][2]  # above; the second apart
    (True, True)
    """
    b = check_xy(boxes, "boxes", 4)
    if isinstance(texts, (str, bytes)) or not isinstance(texts, Sequence) or len(texts) != len(b):
        raise InputError(
            f"texts must be a sequence of captions, one per box ({len(b)}); got {plain_repr(texts)}"
        )
    if not isinstance(canvas, (tuple, list)) or len(canvas) != 2:
        raise InputError(f"canvas must be the picture's (width, height); got {plain_repr(canvas)}")
    w, h = check_picture_size(canvas[0], canvas[1], "canvas")
    font = label_font(label_size_for(h) if size is None else int(check_stroke(size, "size")))
    width = int(check_stroke(width, "width"))
    words = ["" if t is None else " ".join(str(t).split()) for t in texts]
    drawn = [(i, c) for i, c in _drawn_corners(b, (w, h), width) if words[i]]
    keep = [i for i, _ in drawn]
    spots = _place_captions([words[i] for i in keep], [c for _, c in drawn], font, (w, h))
    out: list[tuple[int, int, int, int] | None] = [None] * len(b)
    for i, spot in zip(keep, spots, strict=True):
        if spot is not None:
            out[i] = (spot[0], spot[1], spot[0] + spot[2] - 1, spot[1] + spot[3] - 1)
    return out


def draw_boxes(
    image: np.ndarray,
    boxes: np.ndarray,
    *,
    color: Sequence[int] | np.ndarray = (255, 255, 0),
    width: int = 2,
    labels: Sequence[str] | None = None,
    label_size: int | None = None,
) -> np.ndarray:
    """Draw axis-aligned boxes ``(x, y, w, h)``, optionally captioned.

    Captions are :func:`draw_label` labels in the box's colour, drawn after all the
    boxes (so no outline crosses them) and placed by :func:`caption_boxes`: above the
    box's top-left corner, or just inside it where there is no room above, or, where
    another caption is already there, at the next free place around the box; no two
    captions overlap, and one that finds no free place is left out. Captions are
    placed in the order of the boxes.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    boxes : (N, 4) array_like
        ``x, y, width, height`` (OpenCV's ``Rect`` order).
    color : (3,) ints or (N, 3) ints
        One colour for all the boxes, or one per box.
    width : int
        Outline width in ``[1, MAX_STROKE]`` pixels.
    labels : sequence of str, optional
        One caption per box (an empty string or None: that box has none).
    label_size : int, optional
        Caption font size in pixels (default :func:`label_size_for` of the picture's
        height: 24 px at 1080p).

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Examples
    --------
    >>> out = draw_boxes(np.zeros((1080, 1920)), [[100, 200, 50, 40]], labels=["7"])
    >>> bool(out[199, 100:150].any()), bool(out[170:199, 100:110].any())  # box, caption
    (True, True)
    """
    b = check_xy(boxes, "boxes", 4)
    if labels is not None:
        if isinstance(labels, (str, bytes)) or not isinstance(labels, (Sequence, np.ndarray)):
            raise InputError(
                f"labels must be a sequence of captions, one per box; got {plain_repr(labels)}"
            )
        if len(labels) != len(b):
            raise InputError(f"labels must have one entry per box ({len(b)}); got {len(labels)}")
    cols = _box_colors(color, len(b))
    width = int(check_stroke(width, "width"))
    if label_size is not None:
        label_size = int(check_stroke(label_size, "label_size"))
    pil, draw = pil_canvas(image)
    captions: list[tuple[str, tuple[float, float, float, float], Color]] = []
    for i, corners in _drawn_corners(b, (pil.width, pil.height), width):
        draw.rectangle(list(corners), outline=cols[i], width=width)
        text = "" if labels is None or labels[i] is None else " ".join(str(labels[i]).split())
        if text:  # (one line; an empty caption is not drawn)
            captions.append((text, corners, cols[i]))
    if captions:
        font = label_font(label_size_for(pil.height) if label_size is None else label_size)
        canvas = (pil.width, pil.height)
        spots = _place_captions([c[0] for c in captions], [c[1] for c in captions], font, canvas)
        for (text, _, col), spot in zip(captions, spots, strict=True):
            if spot is None:
                continue
            x, y, bw, bh, tx, ty = spot
            draw.rectangle([x, y, x + bw - 1, y + bh - 1], fill=col)
            draw.text((tx, ty), text, fill=_contrast(col), font=font, anchor="ls")
    return np.asarray(pil)


def draw_text(
    image: np.ndarray,
    text: str,
    origin: tuple[float, float] = (5, 5),
    *,
    color: Sequence[int] = (255, 255, 255),
    size: int | None = None,
    background: Sequence[int] | None = (0, 0, 0),
) -> np.ndarray:
    """Write ``text`` (one or more lines) with its top-left corner at ``origin`` = (x, y).

    Set in :func:`label_font` (DejaVu Sans) at ``size`` pixels, on a filled background
    box unless ``background`` is None, so it stays readable on any image. Unlike
    :func:`draw_label`, the text stays where it is put (a title, a legend entry):
    text wholly outside the picture is not drawn.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    text : str
    origin : (float, float)
        ``(x, y)`` of the top-left corner; text wholly outside the image is not drawn.
    color : (3,) ints
    size : int, optional
        Font size in ``[1, MAX_STROKE]`` pixels (default :func:`label_size_for` of the
        picture's height: 24 px at 1080p).
    background : (3,) ints or None

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Examples
    --------
    >>> out = draw_text(np.zeros((1080, 1920)), "frame 12", (5, 5))
    >>> rows = np.flatnonzero(out[..., 0].max(axis=1) == 255)  # the white ink
    >>> 15 <= int(rows.max() - rows.min()) + 1 <= 24
    True
    """
    text = check_text(text, "text")
    ox, oy = check_reals(origin, "origin", 2)
    col = check_color(color)
    bg = None if background is None else check_color(background, "background")
    if size is not None:
        size = int(check_stroke(size, "size"))
    pil, draw = pil_canvas(image)
    font = label_font(label_size_for(pil.height) if size is None else size)
    pad = max(2, round(font.size / 8)) if hasattr(font, "size") else 2
    left, top, right, bottom = draw.multiline_textbbox((0, 0), text, font=font)
    if ox + right + pad < 0 or oy + bottom + pad < 0 or ox + left - pad > pil.width:
        return np.asarray(pil)  # wholly outside (and far coordinates overflow Pillow)
    if oy + top - pad > pil.height:
        return np.asarray(pil)
    if bg is not None:
        box = (ox + left - pad, oy + top - pad, ox + right + pad - 1, oy + bottom + pad - 1)
        draw.rectangle(box, fill=bg)
    draw.multiline_text((ox, oy), text, fill=col, font=font)
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
    m = check_ndim(mask, "mask", (2,))
    if m.dtype.kind not in "biuf":
        raise InputError(f"mask must be bool or numeric; got dtype {m.dtype}")
    m = m.astype(bool)
    if m.shape != img.shape[:2]:
        raise InputError(f"mask must have the image's shape {img.shape[:2]}; got {m.shape}")
    alpha = check_real(alpha, "alpha", 0.0, 1.0)
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
    pts = check_xy(corners, "corners")
    if not isinstance(pattern_size, (tuple, list)) or len(pattern_size) != 2:
        raise InputError(
            f"pattern_size must be (corners per row, corners per column); got "
            f"{plain_repr(pattern_size)}"
        )
    w = check_int(pattern_size[0], "pattern_size[0]", 1)
    check_int(pattern_size[1], "pattern_size[1]", 1)
    found = check_bool(found, "found")
    pil, draw = pil_canvas(image)
    r = max(3.0, pil.height / 120)
    for k, (x, y) in enumerate(pts):
        if found:
            hue = (k // w) / max(len(pts) // w, 1)
            col = tuple(int(255 * v) for v in colorsys.hsv_to_rgb(0.75 * hue, 1.0, 1.0))
            if k:
                seg = clip_segments(np.r_[pts[k - 1], x, y], pil.width, pil.height, 4.0)
                for x0, y0, x1, y1 in seg:
                    draw.line([(x0, y0), (x1, y1)], fill=col, width=2)
        else:
            col = (255, 0, 0)
        for cx, cy in _visible_circles(pts[k : k + 1], r, pil.width, pil.height):
            draw.ellipse((cx - r, cy - r, cx + r, cy + r), outline=col, width=2)
    return np.asarray(pil)


def legend_panel(
    picture: np.ndarray,
    entries: Sequence[tuple[str, Sequence[int]]],
    *,
    size: int | None = None,
    empty: str = "nothing shown",
) -> np.ndarray:
    """``picture`` with a white panel on its right listing ``entries``: per row a
    swatch of the colour (framed in black) and the name, in black; ``empty`` alone when
    there is no entry. The legend never covers the picture (as matplotlib's
    ``legend(loc="center left", bbox_to_anchor=(1, 0.5))``); the panel is as tall as
    the picture, or taller when the list needs it (the picture then sits at the top).

    Parameters
    ----------
    picture : (H, W) or (H, W, 3) ndarray
    entries : sequence of (str, (3,) ints)
        Name and colour of each row.
    size : int, optional
        Text height in pixels (default ``max(14, round(max(H, W) / 40))``: 48 px for a
        1920-pixel picture).
    empty : str
        The text when ``entries`` is empty.

    Returns
    -------
    (max(H, rows), W + panel width, 3) uint8 ndarray

    Raises
    ------
    InputError
        A bad picture, an entry that is not ``(name, colour)``, a bad size.

    Examples
    --------
    >>> pic = legend_panel(np.zeros((100, 120), np.uint8), [("plane 1", (0, 0, 255))])
    >>> pic.shape[0], pic.shape[1] > 120, pic[50, 60].tolist(), pic[5, -1].tolist()
    (100, True, [0, 0, 0], [255, 255, 255])
    """
    pic = to_rgb8(picture)
    if isinstance(entries, (str, bytes)) or not isinstance(entries, (Sequence, np.ndarray)):
        raise InputError(
            f"entries must be a list of (name, (r, g, b)) pairs; got {plain_repr(entries)}"
        )
    rows_in: list[tuple[str, Color]] = []
    for i, e in enumerate(entries):
        if not isinstance(e, (tuple, list)) or len(e) != 2:
            raise InputError(f"entries[{i}] must be a (name, (r, g, b)) pair; got {plain_repr(e)}")
        name = check_text(e[0], f"entries[{i}][0]")
        rows_in.append((" ".join(name.split()), check_color(e[1], f"entries[{i}][1]")))
    empty = check_text(empty, "empty")
    size = (
        int(max(14, round(max(pic.shape[:2]) / 40)))
        if size is None
        else int(check_stroke(size, "size"))
    )
    font = label_font(size)
    rows: list[tuple[str, Color]] = rows_in or [(empty, (255, 255, 255))]
    longest = max(len(n) for n, _ in rows)
    measured = max(int(font.getlength(n)) for n, _ in rows) + int(size * 1.4)
    width = max(int(size * (2 + 0.62 * longest)), measured + size // 2) + 2 * size
    h = max(pic.shape[0], (len(rows) + 1) * int(size * 1.6))
    check_picture_size(pic.shape[1] + width, h, "picture with its legend")
    out = np.full((h, pic.shape[1] + width, 3), 255, np.uint8)
    out[: pic.shape[0], : pic.shape[1]] = pic
    x0 = pic.shape[1] + size // 2
    tops = [size // 2 + int(i * size * 1.6) for i in range(len(rows))]
    for y, (_, color) in zip(tops, rows_in, strict=False):
        out[y : y + size, x0 : x0 + size] = 0  # a swatch with a black frame
        out[y + 1 : y + size - 1, x0 + 1 : x0 + size - 1] = color
    for y, (name, _) in zip(tops, rows, strict=True):
        out = draw_text(
            out,
            name,
            (x0 + (int(size * 1.4) if rows_in else 0), y - 1),
            color=(0, 0, 0),
            size=size,
            background=None,
        )
    return out
