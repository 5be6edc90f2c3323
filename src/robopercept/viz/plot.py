"""Line plots as RGB images, without a plotting library (rasterization is Pillow's).

:func:`plot_series` stacks panels vertically; each panel has its own y range, ticks and
legend. Values that are NaN break a line, which is how gaps (frames without a
detection) show.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from robopercept._checks import check_int, check_magnitude, check_text
from robopercept.errors import InputError
from robopercept.viz.draw import check_color, check_picture_size

__all__ = ["MIN_PANEL_HEIGHT", "MIN_WIDTH", "Panel", "Series", "plot_series"]

#: the smallest plot width and panel height in pixels (the axes' margins and labels)
MIN_WIDTH, MIN_PANEL_HEIGHT = 100, 60
#: the largest magnitude of a plotted value: differences of values beyond it overflow
_MAX_VALUE = 1e300


@dataclass
class Series:
    """One curve: ``y`` against ``x``, drawn as a line or as dots."""

    x: np.ndarray
    y: np.ndarray
    label: str
    color: tuple[int, int, int] = (31, 119, 180)
    style: str = "line"  # "line" or "dots"


@dataclass
class Panel:
    """One plot area with a title, a y-axis label and its series."""

    title: str
    series: list[Series] = field(default_factory=list)
    ylabel: str = ""


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    span = hi - lo
    raw = span / max(n, 1)
    mag = 10 ** math.floor(math.log10(raw)) if raw > 0 else 1.0
    step = next((m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw), 10 * mag)
    if not step > 0:  # (a span of subnormal numbers)
        return [lo]
    start = math.ceil(lo / step) * step
    count = min(int((hi - start) / step + 1e-9) + 1, 4 * n + 1)
    return [start + i * step for i in range(max(count, 0))]


def _widen(lo: float, hi: float, pad: float) -> tuple[float, float]:
    """``(lo, hi)`` made a range of positive width: a single value ``v`` becomes
    ``v -+ max(pad, |v| 1e-9)`` (a fixed pad vanishes beside values near 1e300)."""
    if hi <= lo:
        d = max(pad, abs(lo) * 1e-9)
        return lo - d, hi + d
    return lo, hi


def plot_series(
    panels: Sequence[Panel], *, width: int = 1000, panel_height: int = 220, xlabel: str = ""
) -> np.ndarray:
    """Render ``panels`` one above the other and return the ``(H, W, 3)`` uint8 image.

    Parameters
    ----------
    panels : sequence of Panel
        At least one; titles, y labels and series labels are strings; values beyond
        1e300 in magnitude are refused (their differences overflow).
    width : int
        At least :data:`MIN_WIDTH` (100) pixels.
    panel_height : int
        At least :data:`MIN_PANEL_HEIGHT` (60) pixels.
    xlabel : str

    Returns
    -------
    (panel_height * len(panels) + 30, width, 3) uint8 ndarray
    """
    from PIL import Image, ImageDraw, ImageFont

    if not isinstance(panels, (list, tuple)) or not panels:
        raise InputError("plot_series needs at least one panel (a list of Panel)")
    xlabel = check_text(xlabel, "xlabel")
    width = check_int(width, "width", MIN_WIDTH)
    panel_height = check_int(panel_height, "height of a panel", MIN_PANEL_HEIGHT)
    check_picture_size(width, panel_height * len(panels) + 30, "plot")
    for panel in panels:
        if not isinstance(panel, Panel):
            raise InputError(f"panels must be Panel objects; got {type(panel).__name__}")
        check_text(panel.title, "title")
        check_text(panel.ylabel, "ylabel")
        for s in panel.series:
            if not isinstance(s, Series):
                raise InputError(f"a panel's series must be Series; got {type(s).__name__}")
            check_text(s.label, "a curve's label")
            check_color(s.color, "a curve's color")
            for axis, values in (("x", s.x), ("y", s.y)):
                v = np.asarray(values)
                if v.dtype.kind not in "biuf":
                    raise InputError(
                        f"series {s.label!r}: {axis} must be real numbers; got dtype {v.dtype}"
                    )
                check_magnitude(v, f"series {s.label!r}: {axis}", _MAX_VALUE)
    try:
        font = ImageFont.load_default(size=13)
    except TypeError:  # Pillow < 10.1
        font = ImageFont.load_default()
    height = panel_height * len(panels) + 30
    img = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    left, right, top_pad, bottom_pad = 70, 15, 24, 22
    for k, panel in enumerate(panels):
        y0 = k * panel_height + top_pad
        y1 = (k + 1) * panel_height - bottom_pad
        x0, x1 = left, width - right
        xs = [np.asarray(s.x, dtype=np.float64) for s in panel.series]
        ys = [np.asarray(s.y, dtype=np.float64) for s in panel.series]
        xv = np.concatenate([x[np.isfinite(x)] for x in xs]) if xs else np.zeros(0)
        yv = np.concatenate([y[np.isfinite(y)] for y in ys]) if ys else np.zeros(0)
        xmin, xmax = (float(xv.min()), float(xv.max())) if xv.size else (0.0, 1.0)
        ymin, ymax = (float(yv.min()), float(yv.max())) if yv.size else (0.0, 1.0)
        if xmax <= xmin:
            xmax = xmin + max(1.0, abs(xmin) * 1e-9)
        ymin, ymax = _widen(ymin, ymax, 0.5)
        pad = 0.05 * (ymax - ymin)
        ymin, ymax = ymin - pad, ymax + pad

        def px(x: np.ndarray, xmin=xmin, xmax=xmax, x0=x0, x1=x1) -> np.ndarray:
            return x0 + (x - xmin) / (xmax - xmin) * (x1 - x0)

        def py(y: np.ndarray, ymin=ymin, ymax=ymax, y0=y0, y1=y1) -> np.ndarray:
            return y1 - (y - ymin) / (ymax - ymin) * (y1 - y0)

        draw.rectangle([x0, y0, x1, y1], outline=(0, 0, 0))
        draw.text((x0, y0 - 16), panel.title, fill=(0, 0, 0), font=font)
        for t in _ticks(ymin, ymax):
            yy = float(py(np.float64(t)))
            draw.line([x0 - 4, yy, x0, yy], fill=(0, 0, 0))
            draw.line([x0 + 1, yy, x1 - 1, yy], fill=(235, 235, 235))
            draw.text((4, yy - 7), f"{t:.4g}", fill=(0, 0, 0), font=font)
        for t in _ticks(xmin, xmax, 10):
            xx = float(px(np.float64(t)))
            draw.line([xx, y1, xx, y1 + 4], fill=(0, 0, 0))
            draw.text((xx - 10, y1 + 5), f"{t:.4g}", fill=(0, 0, 0), font=font)
        if panel.ylabel:
            draw.text((4, y0 - 16), panel.ylabel, fill=(80, 80, 80), font=font)
        lx = x1 - 10
        for s, x, y in zip(panel.series, xs, ys, strict=False):
            if x.shape != y.shape:
                raise InputError(f"series {s.label!r}: x and y differ in shape")
            ok = np.isfinite(x) & np.isfinite(y)
            u, v = px(x), py(y)
            if s.style == "dots":
                for a, b in zip(u[ok], v[ok], strict=False):
                    draw.ellipse([a - 1.5, b - 1.5, a + 1.5, b + 1.5], fill=s.color)
            else:
                run: list[tuple[float, float]] = []
                for a, b, good in zip(u, v, ok, strict=False):
                    if good:
                        run.append((float(a), float(b)))
                    else:
                        if len(run) > 1:
                            draw.line(run, fill=s.color, width=2)
                        run = []
                if len(run) > 1:
                    draw.line(run, fill=s.color, width=2)
            box = draw.textbbox((0, 0), s.label, font=font)
            lx -= box[2] + 30
            draw.line([lx, y0 + 10, lx + 20, y0 + 10], fill=s.color, width=3)
            draw.text((lx + 24, y0 + 3), s.label, fill=(0, 0, 0), font=font)
    if xlabel:
        draw.text((width // 2 - 20, height - 18), xlabel, fill=(0, 0, 0), font=font)
    return np.asarray(img)
