"""Digits rendered from TrueType fonts, made the way the UCI digits were (issue 23's
sim-to-real pretraining set; NumPy and Pillow, no torch, nothing downloaded).

scikit-learn's ``digits`` (the UCI "optical recognition of handwritten digits" set) are
32x32 binary bitmaps of handwritten digits, normalized in size, then divided into 4x4
blocks and the "on" pixels of each block counted: an 8x8 image of counts 0..16.
:func:`render_digits` makes the same kind of image from a font: the digit drawn large
with a random font, stroke width, rotation, slant, width and offset, cropped to its
bounding box, scaled to fill 32x32 (keeping its aspect ratio, as the UCI preprocessing
did), thresholded, a few pixels flipped, and block-counted to 8x8. The result, divided
by 16, is in [0, 1] like :func:`robopercept.nn.data.datasets.load_digits`' images.

Which fonts: by default the 22 text faces that matplotlib (a core dependency) ships in
``mpl-data/fonts/ttf`` (:data:`DEFAULT_FONTS`: DejaVu Sans, Sans Mono and Serif in four
weights and slants, STIX General in four, and six Computer Modern text faces), so the
rendered digits, and every model pretrained on them, depend only on the project and its
declared dependencies, not on what a machine happens to hold in ``/usr/share/fonts``.
The system's fonts are an explicit option (``fonts="system"``, :func:`find_fonts`).
Glyphs are laid out with Pillow's basic layout engine whatever the machine has (Raqm
needs the system's FriBiDi), for the same reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from robopercept._checks import check_int, check_real
from robopercept.errors import InputError

__all__ = [
    "DEFAULT_FONTS",
    "MAX_IMAGES",
    "SYSTEM_FONT_DIRS",
    "default_fonts",
    "find_fonts",
    "render_digits",
]

#: The most images one :func:`render_digits` call makes (64 MiB of float32 output).
MAX_IMAGES = 250_000

#: The system's font folders searched by :func:`find_fonts` (``fonts="system"``).
SYSTEM_FONT_DIRS: tuple[str, ...] = (
    "/usr/share/fonts",
    "/usr/local/share/fonts",
    "~/.fonts",
    "~/.local/share/fonts",
)

#: The default fonts: file names in matplotlib's ``mpl-data/fonts/ttf``. Every face there
#: whose ten digits are digits: not the Display faces, STIX NonUni and Size faces (no
#: digit glyphs), LastResort (one box for every glyph), cmex10 and cmsy10 (delimiters
#: and symbols in the digits' slots). cmmi10's digits are old-style figures.
DEFAULT_FONTS: tuple[str, ...] = (
    "DejaVuSans.ttf",
    "DejaVuSans-Bold.ttf",
    "DejaVuSans-Oblique.ttf",
    "DejaVuSans-BoldOblique.ttf",
    "DejaVuSansMono.ttf",
    "DejaVuSansMono-Bold.ttf",
    "DejaVuSansMono-Oblique.ttf",
    "DejaVuSansMono-BoldOblique.ttf",
    "DejaVuSerif.ttf",
    "DejaVuSerif-Bold.ttf",
    "DejaVuSerif-Italic.ttf",
    "DejaVuSerif-BoldItalic.ttf",
    "STIXGeneral.ttf",
    "STIXGeneralBol.ttf",
    "STIXGeneralItalic.ttf",
    "STIXGeneralBolIta.ttf",
    "cmr10.ttf",
    "cmb10.ttf",
    "cmti10.ttf",
    "cmss10.ttf",
    "cmtt10.ttf",
    "cmmi10.ttf",
)

_SKIP = ("math", "symbol", "emoji", "dingbat", "wingding", "lastresort")


def default_fonts() -> list[Path]:
    """The paths of :data:`DEFAULT_FONTS` in the installed matplotlib, in that order.

    Returns
    -------
    list of Path
        22 TrueType files.

    Raises
    ------
    InputError
        When this matplotlib lacks one of them (the rendered digits would change).

    Examples
    --------
    >>> [p.name for p in default_fonts()[:2]]
    ['DejaVuSans.ttf', 'DejaVuSans-Bold.ttf']
    """
    import matplotlib

    folder = Path(matplotlib.get_data_path()) / "fonts" / "ttf"
    paths = [folder / name for name in DEFAULT_FONTS]
    missing = [p.name for p in paths if not p.is_file()]
    if missing:
        raise InputError(
            f"matplotlib {matplotlib.__version__} lacks the default digit fonts "
            f"{', '.join(missing)} in {folder}: install matplotlib >= 3.8 or pass "
            "fonts='system' or a list of font files"
        )
    return paths


def find_fonts(folders: str | Path | Sequence[str | Path] | None = None) -> list[Path]:
    """The TrueType/OpenType fonts under ``folders``, sorted; empty when none.

    Symbol, math, emoji and LastResort fonts are skipped by name (their digit slots hold
    no digits). What this finds depends on the machine: :func:`render_digits` uses it
    only when asked (``fonts="system"``).

    Parameters
    ----------
    folders : str, Path or sequence of them, optional
        Folders searched recursively (``~`` expanded); default :data:`SYSTEM_FONT_DIRS`,
        read when called.

    Returns
    -------
    list of Path
    """
    if folders is None:
        roots: tuple[str | Path, ...] = SYSTEM_FONT_DIRS
    elif isinstance(folders, str | Path):  # one folder, not its characters
        roots = (folders,)
    elif isinstance(folders, Sequence) and all(isinstance(f, str | Path) for f in folders):
        roots = tuple(folders)
    else:
        raise InputError(f"folders must be a list of folder paths; got {folders!r}")
    found: set[Path] = set()
    for folder in roots:
        root = Path(folder).expanduser()
        if root.is_dir():
            for ext in ("*.ttf", "*.otf", "*.TTF", "*.OTF"):
                found.update(root.rglob(ext))
    return sorted(p for p in found if not any(s in p.name.lower() for s in _SKIP))


def _font_pool(fonts: Sequence[str | Path] | str | None) -> list[Path]:
    """The font files ``render_digits`` draws from (see its ``fonts``)."""
    if fonts is None or (isinstance(fonts, str) and fonts == "default"):
        return default_fonts()
    if isinstance(fonts, str) and fonts == "system":
        pool = find_fonts()
        if not pool:
            raise InputError(
                "no TrueType/OpenType fonts under "
                f"{', '.join(SYSTEM_FONT_DIRS)}: use fonts='default' (matplotlib's)"
            )
        return pool
    if (
        isinstance(fonts, str | Path)
        or not isinstance(fonts, Sequence)
        or not all(isinstance(f, str | Path) for f in fonts)
    ):
        raise InputError(
            f"fonts must be 'default', 'system' or a list of font files; got {fonts!r}"
        )
    pool = [Path(f) for f in fonts]
    if not pool:
        raise InputError("fonts is an empty list: pass font files, 'default' or 'system'")
    missing = [str(p) for p in pool if not p.is_file()]
    if missing:
        raise InputError(f"font files not found: {', '.join(missing)}")
    return pool


def _font(path: Path, size: int) -> Any:
    """Pillow's FreeType font of ``path`` at ``size`` px, basic layout (no Raqm)."""
    from PIL import ImageFont

    try:
        return ImageFont.truetype(str(path), size=size, layout_engine=ImageFont.Layout.BASIC)
    except OSError as exc:
        raise InputError(f"cannot read the font {path}: {exc}") from exc


def render_digits(
    n: int,
    *,
    seed: int = 0,
    fonts: Sequence[str | Path] | Literal["default", "system"] | None = "default",
    noise: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` font-rendered digits as UCI-style 8x8 count images.

    Each image is ``B(s)`` with ``B`` the 4x4 block sum of a 32x32 bitmap ``s`` (the UCI
    preprocessing; scikit-learn's ``load_digits`` holds ``B(s)`` of handwriting), divided
    by 16. ``s`` is the digit drawn at 72 px in a random font with a random stroke width
    (0-4 px), shear ``x' = x + a y`` (``a`` in [-0.3, 0.3]), rotation (+-15 degrees),
    cropped, narrowed to a width factor ``q`` in [0.6, 1] (handwritten digits are
    narrower than type), scaled so its longer side is 0.95-1 of 32 px (the UCI
    bitmaps are size-normalized: their digits fill the box's height), shifted by up to
    1 px vertically and 2 px horizontally, and with a fraction ``noise`` of pixels
    flipped.

    Parameters
    ----------
    n : int
        Number of images; labels cycle 0..9 (balanced), then are shuffled.
    seed : int
        Everything random (font, stroke, rotation, slant, offset, flipped pixels).
    fonts : {"default", "system"} or list of str or Path
        ``"default"`` (or None): :func:`default_fonts`, the same on every machine with
        the same matplotlib and Pillow. ``"system"``: :func:`find_fonts`, whatever this
        machine has installed (results then differ between machines). A list: these
        font files.
    noise : float
        Fraction of the 32x32 bitmap's pixels flipped.

    Returns
    -------
    images : (n, 1, 8, 8) float32 ndarray
        Block counts / 16, in [0, 1].
    labels : (n,) int64 ndarray

    Raises
    ------
    InputError
        ``n`` not in 1..:data:`MAX_IMAGES`; ``seed < 0``; ``noise`` outside [0, 1]; unknown
        ``fonts``; a missing or unreadable font file; no system fonts.

    Examples
    --------
    >>> images, labels = render_digits(20, seed=0)
    >>> images.shape, labels.dtype.name, sorted(set(labels.tolist())) == list(range(10))
    ((20, 1, 8, 8), 'int64', True)
    """
    from PIL import Image, ImageDraw

    n = check_int(n, "n", 1)
    if n > MAX_IMAGES:
        raise InputError(f"n must be <= {MAX_IMAGES:,}; got {n:,}: render in chunks")
    rng = np.random.default_rng(check_int(seed, "seed", 0))
    noise = check_real(noise, "noise", 0.0, 1.0)
    pool = _font_pool(fonts)
    labels = np.tile(np.arange(10), n // 10 + 1)[:n]
    rng.shuffle(labels)
    out = np.empty((n, 1, 8, 8), np.float32)
    cache: dict[int, Any] = {}
    for i, digit in enumerate(labels):
        k = int(rng.integers(len(pool)))
        if k not in cache:
            cache[k] = _font(pool[k], 72)
        font = cache[k]
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
        w_narrow = max(1.0, w * rng.uniform(0.6, 1.0))  # handwriting is narrower than type
        scale = rng.uniform(0.95, 1.0) * 32 / max(h, w_narrow)  # UCI: normalized size
        nh, nw = max(1, round(h * scale)), max(1, round(w_narrow * scale))
        crop = crop.resize((nw, nh), Image.Resampling.BILINEAR)
        bitmap = np.zeros((32, 32), bool)
        top = (32 - nh) // 2 + int(rng.integers(-1, 2))
        left = (32 - nw) // 2 + int(rng.integers(-2, 3))
        top, left = int(np.clip(top, 0, 32 - nh)), int(np.clip(left, 0, 32 - nw))
        bitmap[top : top + nh, left : left + nw] = np.asarray(crop) > 127
        bitmap ^= rng.random((32, 32)) < noise
        out[i, 0] = bitmap.reshape(8, 4, 8, 4).sum(axis=(1, 3)) / 16.0
    return out, labels.astype(np.int64)
