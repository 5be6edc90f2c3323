"""matplotlib figures drawn off screen: the one place ``viz`` makes a figure and turns it
into an RGB array.

A figure is built on matplotlib's Agg canvas (no pyplot, no window, no global state), so
the pictures are the same with or without a display. matplotlib is imported when a
figure is made, never at ``import robopercept.viz``.

A figure of ``(width, height)`` pixels at ``dpi`` dots per inch measures
``width / dpi`` by ``height / dpi`` inches; a font of ``s`` points is ``s * dpi / 72``
pixels high. :func:`agg_figure` with ``reference_width`` picks
``dpi = 100 * width / reference_width``: the figure then keeps the inches (and so the
layout) of its reference size, and every font, marker and line scales with the picture
(at the reference width, 12 pt is 16.7 pixels: readable on a 1920 x 1080 screen).

:func:`readable_dpi` picks the resolution of a plot from its size alone: 100 dpi (12 pt
text 16.7 pixels high) for any picture that fits a 1920 x 1080 screen, more for a larger
picture (so its text reads the same once the picture is fitted to the screen), less for a
picture smaller than the plot's comfortable size (so its layout still fits).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from robopercept._checks import check_bool, check_int, check_real, check_text, plain_repr
from robopercept.errors import InputError
from robopercept.viz.draw import check_picture_size

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["SCREEN_SIZE", "agg_figure", "check_views", "figure_to_rgb", "readable_dpi"]

#: the screen a picture must read well on, ``(width, height)`` in pixels
SCREEN_SIZE = (1920, 1080)


def agg_figure(
    width: int,
    height: int,
    *,
    reference_width: int | None = None,
    layout: Literal["constrained", "tight"] | None = None,
    what: str = "picture",
    dpi: float | None = None,
) -> Figure:
    """A matplotlib figure of ``width`` x ``height`` pixels on an Agg canvas.

    Parameters
    ----------
    width, height : int
        The picture's size in pixels (at most 2**26 pixels in all).
    reference_width : int, optional
        Scale fonts, markers and lines with the picture: ``dpi = 100 * width /
        reference_width`` (a figure of the reference width has 100 dpi); default a
        fixed 100 dpi.
    layout : {None, "constrained", "tight"}
        matplotlib's layout engine (``"constrained"`` keeps titles, labels, legends and
        colour bars inside the picture).
    what : str
        The caller's name, in the message when matplotlib is missing.
    dpi : float, optional
        The resolution itself (e.g. :func:`readable_dpi`), in (0, 10000]; not with
        ``reference_width``.

    Returns
    -------
    matplotlib.figure.Figure
        With a ``FigureCanvasAgg`` attached; turn it into pixels with
        :func:`figure_to_rgb`.

    Raises
    ------
    InputError
        Bad sizes or layout, or matplotlib missing (``pip install matplotlib``).

    Examples
    --------
    >>> fig = agg_figure(320, 200)
    >>> figure_to_rgb(fig).shape
    (200, 320, 3)
    >>> agg_figure(320, 200, dpi=50.0).get_size_inches().tolist()
    [6.4, 4.0]
    """
    w, h = check_picture_size(width, height, check_text(what, "what"))
    ref = None if reference_width is None else check_int(reference_width, "reference_width", 1)
    if dpi is not None:
        if ref is not None:
            raise InputError("give dpi or reference_width, not both")
        dpi = check_real(dpi, "dpi", 0.0, 1e4, low_inclusive=False)
    if not (layout is None or (isinstance(layout, str) and layout in ("constrained", "tight"))):
        raise InputError(
            f"layout must be one of None, 'constrained', 'tight'; got {plain_repr(layout)}"
        )
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise InputError(f"{what} needs matplotlib: pip install matplotlib ({exc})") from exc
    if dpi is None:
        dpi = 100.0 if ref is None else 100.0 * w / ref
    fig = Figure(figsize=(w / dpi, h / dpi), dpi=dpi, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def figure_to_rgb(fig: Figure, *, quiet_layout: bool = False) -> np.ndarray:
    """Draw a matplotlib figure and return its pixels.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        Any figure (one without an Agg canvas gets one).
    quiet_layout : bool
        Silence the layout engine's warnings that a very small or very flat picture
        leaves no room ("constrained layout not applied", "axes sizes collapsed"): the
        picture is drawn as it falls.

    Returns
    -------
    (H, W, 3) uint8 ndarray
        ``H, W`` the figure's size in pixels (inches times dpi); the alpha channel is
        dropped (figures have an opaque background unless made otherwise).

    Raises
    ------
    InputError
        ``fig`` is not a matplotlib figure.

    Examples
    --------
    >>> fig = agg_figure(120, 80)
    >>> pic = figure_to_rgb(fig)
    >>> pic.dtype, pic[40, 60].tolist()
    (dtype('uint8'), [255, 255, 255])
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise InputError(f"figure_to_rgb needs matplotlib: pip install matplotlib ({exc})") from exc
    if not isinstance(fig, Figure):
        raise InputError(f"fig must be a matplotlib Figure; got {plain_repr(fig)}")
    quiet_layout = check_bool(quiet_layout, "quiet_layout")
    canvas: Any = fig.canvas
    if not isinstance(canvas, FigureCanvasAgg):
        canvas = FigureCanvasAgg(fig)
    with warnings.catch_warnings():
        if quiet_layout:
            warnings.filterwarnings("ignore", message=".*[Ll]ayout not applied.*")
            warnings.filterwarnings("ignore", message=".*axes sizes collapsed.*")
        canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[..., :3])


def readable_dpi(
    width: int, height: int, *, comfortable: tuple[int, int] = (640, 400), floor: float = 0.3
) -> float:
    r"""The resolution at which a plot of ``width`` x ``height`` pixels reads well on a
    1920 x 1080 screen (:data:`SCREEN_SIZE`).

    .. math::

        \mathrm{dpi} = 100 \max\Big(f, \min\big(\max(1, W / 1920, H / 1080),
        W / W_c, H / H_c\big)\Big)

    with ``(W_c, H_c) = comfortable`` and ``f = floor``. At 100 dpi a 12 pt font is
    16.7 pixels high. A picture larger than the screen is shown shrunk by
    ``max(W / 1920, H / 1080)``, so its text grows by that factor; a picture smaller than
    the plot's comfortable size (where its labels, legend and title fit at 100 dpi)
    shrinks its text instead, down to ``floor`` times.

    Parameters
    ----------
    width, height : int
        The picture's size in pixels.
    comfortable : (int, int)
        The smallest ``(width, height)`` at which the plot's layout fits at 100 dpi.
    floor : float
        The smallest scale, in (0, 1].

    Returns
    -------
    float

    Examples
    --------
    >>> readable_dpi(1600, 900), readable_dpi(3840, 2160), readable_dpi(320, 400)
    (100.0, 200.0, 50.0)
    """
    w, h = check_picture_size(width, height)
    if not (isinstance(comfortable, (tuple, list)) and len(comfortable) == 2):
        raise InputError(f"comfortable must be (width, height); got {plain_repr(comfortable)}")
    cw = check_int(comfortable[0], "comfortable width", 1)
    ch = check_int(comfortable[1], "comfortable height", 1)
    floor = check_real(floor, "floor", 0.0, 1.0, low_inclusive=False)
    grow = max(1.0, w / SCREEN_SIZE[0], h / SCREEN_SIZE[1])
    return 100.0 * max(floor, min(grow, w / cw, h / ch))


def check_views(views: Any) -> list[tuple[float, float]]:
    """The 3-D viewpoints of a multi-view picture: 1 to 6 ``(elevation, azimuth)`` pairs
    in radians (elevation in [-pi, pi], azimuth in [-2 pi, 2 pi]), returned in degrees
    for matplotlib's ``view_init``.

    Raises
    ------
    InputError
        Not a sequence of pairs, too few or too many, or an angle out of range.

    Examples
    --------
    >>> check_views([(0.0, math.pi / 2)])
    [(0.0, 90.0)]
    """
    if isinstance(views, (str, bytes)) or not isinstance(views, (Sequence, np.ndarray)):
        raise InputError(f"views must be a sequence of (elevation, azimuth); got {views!r}")
    if not 1 <= len(views) <= 6:
        raise InputError(f"views must hold 1 to 6 (elevation, azimuth) pairs; got {len(views)}")
    angles = []
    for i, v in enumerate(views):
        if not isinstance(v, (Sequence, np.ndarray)) or isinstance(v, str) or len(v) != 2:
            raise InputError(f"views[{i}] must be (elevation, azimuth) in radians; got {v!r}")
        elev = check_real(v[0], f"views[{i}] elevation", -math.pi, math.pi)
        azim = check_real(v[1], f"views[{i}] azimuth", -2 * math.pi, 2 * math.pi)
        angles.append((math.degrees(elev), math.degrees(azim)))
    return angles
