"""Digits rendered from TrueType fonts, made the way the UCI digits were (issue 23's
sim-to-real pretraining set; NumPy and Pillow, no torch, nothing downloaded).

scikit-learn's ``digits`` (the UCI "optical recognition of handwritten digits" set) are
32x32 binary bitmaps of handwritten digits, normalized in size, then divided into 4x4
blocks and the "on" pixels of each block counted: an 8x8 image of counts 0..16.
:func:`render_digits` makes the same kind of image from a font: the digit drawn large
with a random font, stroke width, rotation, slant and offset, cropped to its bounding box,
scaled to fit 32x32 (keeping its aspect ratio, as the UCI preprocessing did), thresholded,
a few pixels flipped, and block-counted to 8x8. The result, divided by 16, is in [0, 1]
like :func:`robopercept.nn.data.load_digits`' images.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from robopercept.errors import InputError

__all__ = ["find_fonts", "render_digits"]

_FONT_DIRS = ("/usr/share/fonts", "/usr/local/share/fonts", "~/.fonts", "~/.local/share/fonts")


def find_fonts(folders: tuple[str, ...] = _FONT_DIRS) -> list[Path]:
    """The TrueType/OpenType fonts under ``folders`` (sorted; empty when none), skipping
    symbol and math fonts, whose digits are not digits."""
    found: set[Path] = set()
    for folder in folders:
        root = Path(folder).expanduser()
        if root.is_dir():
            for ext in ("*.ttf", "*.otf", "*.TTF", "*.OTF"):
                found.update(root.rglob(ext))
    skip = ("math", "symbol", "emoji", "dingbat", "wingding")
    return sorted(p for p in found if not any(s in p.name.lower() for s in skip))


def _font(path: Path | None, size: int):
    from PIL import ImageFont

    if path is None:  # Pillow's own scalable font (needs FreeType)
        return ImageFont.load_default(size=size)
    return ImageFont.truetype(str(path), size=size)


def render_digits(
    n: int,
    *,
    seed: int = 0,
    fonts: list[Path] | None = None,
    noise: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` font-rendered digits as UCI-style 8x8 count images.

    Parameters
    ----------
    n : int
        Number of images; labels cycle 0..9 (balanced), then are shuffled.
    seed : int
        Everything random (font, stroke, rotation, slant, offset, flipped pixels).
    fonts : list of Path, optional
        Font files to draw from (default :func:`find_fonts`; Pillow's default font when
        the system has none).
    noise : float
        Fraction of the 32x32 bitmap's pixels flipped.

    Returns
    -------
    images : (n, 1, 8, 8) float32 ndarray
        Block counts / 16, in [0, 1].
    labels : (n,) int64 ndarray
    """
    from PIL import Image, ImageDraw

    if int(n) < 1:
        raise InputError(f"n must be >= 1; got {n}")
    rng = np.random.default_rng(seed)
    pool: list[Path | None] = list(fonts) if fonts is not None else list(find_fonts())
    if not pool:
        pool = [None]
    labels = np.tile(np.arange(10), n // 10 + 1)[:n]
    rng.shuffle(labels)
    out = np.empty((n, 1, 8, 8), np.float32)
    cache: dict[int, Any] = {}
    for i, digit in enumerate(labels):
        k = int(rng.integers(len(pool)))
        key = k
        if key not in cache:
            cache[key] = _font(pool[k], 72)
        font = cache[key]
        stroke = int(rng.integers(0, 5))
        canvas = Image.new("L", (160, 160), 0)
        ImageDraw.Draw(canvas).text(
            (80, 80),
            str(digit),
            fill=255,
            font=font,
            anchor="mm",
            stroke_width=stroke,
            stroke_fill=255,
        )
        shear = rng.uniform(-0.3, 0.3)
        canvas = canvas.transform(
            canvas.size,
            Image.Transform.AFFINE,
            (1, shear, -shear * 80, 0, 1, 0),
            Image.Resampling.BILINEAR,
        )
        canvas = canvas.rotate(rng.uniform(-15, 15), resample=Image.Resampling.BILINEAR)
        a = np.asarray(canvas) > 127
        ys, xs = np.nonzero(a)
        if ys.size == 0:  # a font without this glyph: a blank is still a valid sample
            out[i] = 0.0
            continue
        crop = Image.fromarray(
            a[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1].astype(np.uint8) * 255
        )
        h, w = crop.height, crop.width
        scale = rng.uniform(0.8, 1.0) * 32 / max(h, w)
        nh, nw = max(1, round(h * scale)), max(1, round(w * scale))
        crop = crop.resize((nw, nh), Image.Resampling.BILINEAR)
        bitmap = np.zeros((32, 32), bool)
        top = (32 - nh) // 2 + int(rng.integers(-1, 2))
        left = (32 - nw) // 2 + int(rng.integers(-2, 3))
        top, left = int(np.clip(top, 0, 32 - nh)), int(np.clip(left, 0, 32 - nw))
        bitmap[top : top + nh, left : left + nw] = np.asarray(crop) > 127
        bitmap ^= rng.random((32, 32)) < noise
        out[i, 0] = bitmap.reshape(8, 4, 8, 4).sum(axis=(1, 3)) / 16.0
    return out, labels.astype(np.int64)
