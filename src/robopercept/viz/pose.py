r"""Pictures of poses: skeletons drawn on images, keypoint heatmaps in a grid, and 3-D
skeletons from two viewpoints.

This module takes plain arrays (keypoints, links as ``(i, j)`` pairs, names), not a
:class:`robopercept.nn.skeleton.Skeleton`: ``viz`` sits below ``nn``. With a skeleton
``s``, call ``draw_skeleton(image, keypoints, s.links, flip_pairs=s.flip_pairs,
labels=s.joints)``.

Keypoints are ``(x, y)`` pixels (origin at the centre of the top-left pixel), with
COCO's visibility codes where a third column is given: ``v = 2`` labelled and visible
(a filled disc), ``v = 1`` labelled but occluded (a ring), ``v = 0`` not labelled (not
drawn); a joint with a NaN coordinate is not drawn either, nor any limb that ends at a
joint that is not drawn.

Sizes follow the picture so that it reads at 1080p: the disc radius is
``max(2, L / 200)`` and the limb width ``max(1, round(radius / 2))`` pixels for an image
whose longer side is ``L`` (9.6 and 5 pixels on a 1920 x 1080 frame, 3.2 and 2 on
640 x 480), text ``max(12, L / 80)`` pixels high.

Colours: with ``sides`` or ``flip_pairs``, left joints and the limbs between two left
joints are green, right ones orange, the rest blue (mmpose's colours,
:data:`SIDE_COLORS`); without, each person takes one colour, person ``p`` the
golden-ratio hue ``p + 1`` of :func:`~robopercept.viz.colormap.label_colors`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from robopercept._checks import (
    check_bool,
    check_finite,
    check_int,
    check_magnitude,
    check_ndim,
    check_numeric,
    check_real,
    check_size,
    check_text,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors, turbo
from robopercept.viz.draw import (
    check_color,
    check_picture_size,
    check_stroke,
    clip_segments,
    enlarge_picture,
    label_font,
    pil_canvas,
    to_rgb8,
)
from robopercept.viz.figure import agg_figure, check_views, figure_to_rgb

__all__ = [
    "DEFAULT_VIEWS",
    "SIDE_COLORS",
    "draw_skeleton",
    "heatmap_grid",
    "skeleton_3d_figure",
    "skeleton_3d_picture",
]

Color = tuple[int, int, int]

#: the colours of left, right and central joints and limbs (mmpose's pose palette)
SIDE_COLORS: dict[str, Color] = {
    "left": (0, 255, 0),
    "right": (255, 128, 0),
    "center": (51, 153, 255),
}
#: the two viewpoints of :func:`skeleton_3d_picture`, ``(elevation, azimuth)`` in
#: radians: matplotlib's default view (20 deg, -60 deg) and a view from the front,
#: along the y axis (0 deg, -90 deg)
DEFAULT_VIEWS = ((math.radians(20.0), math.radians(-60.0)), (0.0, math.radians(-90.0)))
#: the confidences shown in the legend of :func:`draw_skeleton`
_LEGEND_CONFIDENCES = (1.0, 0.6, 0.2)
#: the most people the legend of :func:`draw_skeleton` lists one by one
_LEGEND_PEOPLE = 12


def _sizes(width: int, height: int) -> tuple[float, int]:
    """Default disc radius and text height for a picture."""
    longer = max(width, height)
    return max(2.0, longer / 200.0), int(max(12, round(longer / 80)))


def _font(size: int) -> Any:
    """The house font (:func:`~robopercept.viz.draw.label_font`: DejaVu Sans)."""
    return label_font(size)


def _check_links(links: Any, joints: int) -> np.ndarray:
    """``links`` as an ``(L, 2)`` int64 array of distinct joint indices in 0..J-1."""
    if isinstance(links, (str, bytes)):
        raise InputError(f"links must be a sequence of (i, j) joint pairs; got {links!r}")
    try:
        arr = np.asarray(links)
    except (TypeError, ValueError):
        arr = np.zeros((0, 3))
    if arr.size == 0 and arr.ndim <= 2 and (arr.ndim < 2 or arr.shape[1] in (0, 2)):
        return np.zeros((0, 2), dtype=np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.dtype.kind not in "iu":
        raise InputError(
            f"links must be (i, j) pairs of integer joint indices, an (L, 2) array; got "
            f"{plain_repr(links)[:120]}"
        )
    if (arr < 0).any() or (arr >= joints).any() or (arr[:, 0] == arr[:, 1]).any():
        raise InputError(
            f"links must join two different joints among 0..{joints - 1}; got "
            f"{plain_repr(arr.tolist())[:120]}"
        )
    return arr.astype(np.int64)


def _per_joint(value: Any, people: int, joints: int, name: str) -> np.ndarray:
    """A per-joint value given as ``(J,)`` or ``(P, J)``, as a float64 ``(P, J)`` array."""
    arr = check_numeric(value, name)
    if arr.shape == (joints,):
        arr = np.broadcast_to(arr, (people, joints))
    if arr.shape != (people, joints):
        raise InputError(
            f"{name} must have one value per joint, (J,) = ({joints},) or (P, J) = "
            f"({people}, {joints}); got shape {arr.shape}"
        )
    return np.array(arr, dtype=np.float64)


def _names(names: Any, count: int, what: str, per: str = "joint") -> list[str]:
    if isinstance(names, (str, bytes)) or not isinstance(names, (Sequence, np.ndarray)):
        raise InputError(f"{what} must be a sequence of {count} names; got {plain_repr(names)}")
    if len(names) != count:
        raise InputError(f"{what} must have one name per {per} ({count}); got {len(names)}")
    return [check_text(n, f"{what}[{i}]") for i, n in enumerate(names)]


def _joint_sides(sides: Any, flip_pairs: Any, joints: int) -> list[str] | None:
    """Each joint's side (``left``, ``right``, ``center``), or None when neither is given."""
    if sides is not None and flip_pairs is not None:
        raise InputError("give sides or flip_pairs, not both: they say the same thing")
    if sides is not None:
        out = _names(sides, joints, "sides")
        bad = [s for s in out if s not in SIDE_COLORS]
        if bad:
            raise InputError(
                f"sides must be 'left', 'right' or 'center', one per joint; got {bad[0]!r}"
            )
        return out
    if flip_pairs is not None:
        pairs = _check_links(flip_pairs, joints)
        if len(set(pairs.ravel().tolist())) != pairs.size:
            raise InputError(
                f"flip_pairs must use each joint at most once; got {plain_repr(pairs.tolist())}"
            )
        out = ["center"] * joints
        for a, b in pairs:
            out[a], out[b] = "left", "right"
        return out
    return None


def _colors(
    colors: Any, sides: list[str] | None, links: np.ndarray, people: int, joints: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(P, J, 3)`` joint colours and ``(P, L, 3)`` limb colours (uint8)."""
    if colors is not None:
        c = check_numeric(colors, "colors")
        if c.shape == (3,):
            c = np.broadcast_to(c, (joints, 3))
        if c.shape != (joints, 3):
            raise InputError(
                f"colors must be one colour (3,) or one per joint (J, 3) = ({joints}, 3); "
                f"got shape {c.shape}"
            )
        joint = np.array([check_color(row, f"colors[{i}]") for i, row in enumerate(c)])
        joint = joint.reshape(joints, 3)
        a, b = joint[links[:, 0]], joint[links[:, 1]]
        limb = np.where((a == b).all(axis=1, keepdims=True), a, (a.astype(int) + b) // 2)
        return (
            np.broadcast_to(joint, (people, joints, 3)).astype(np.uint8),
            np.broadcast_to(limb, (people, len(links), 3)).astype(np.uint8),
        )
    if sides is not None:
        joint = np.array([SIDE_COLORS[s] for s in sides], dtype=np.uint8).reshape(joints, 3)
        limb = np.array(
            [SIDE_COLORS[sides[i]] if sides[i] == sides[j] else SIDE_COLORS["center"]
             for i, j in links],
            dtype=np.uint8,
        ).reshape(-1, 3)  # fmt: skip
        return (
            np.broadcast_to(joint, (people, joints, 3)),
            np.broadcast_to(limb, (people, len(links), 3)),
        )
    person = label_colors(np.arange(1, people + 1)).reshape(people, 1, 3)
    return (
        np.broadcast_to(person, (people, joints, 3)),
        np.broadcast_to(person, (people, len(links), 3)),
    )


def draw_skeleton(
    image: np.ndarray,
    keypoints: np.ndarray,
    links: Sequence[tuple[int, int]] | np.ndarray,
    *,
    confidence: np.ndarray | None = None,
    visible: np.ndarray | None = None,
    colors: np.ndarray | Sequence[int] | None = None,
    radius: float | None = None,
    thickness: int | None = None,
    labels: Sequence[str] | None = None,
    sides: Sequence[str] | None = None,
    flip_pairs: Sequence[tuple[int, int]] | None = None,
    legend: bool | None = None,
    min_side: int = 1,
) -> np.ndarray:
    r"""Draw one or several poses: limbs as lines, joints as discs, optionally named.

    A joint is drawn where it is labelled (``v > 0``), its coordinates are finite and,
    with ``confidence``, its confidence is not NaN: a filled disc for ``v = 2``, a ring
    for ``v = 1``. A limb ``(i, j)`` is drawn where both its joints are, under them.
    With ``confidence`` :math:`c \in [0, 1]`, a disc's radius is
    :math:`r (0.4 + 0.6 c)` (a confident joint full size, an unsure one small) and a
    legend of three disc sizes is added in a panel to the right of the image.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    keypoints : (J, 2), (J, 3), (P, J, 2) or (P, J, 3) array_like
        ``x, y`` pixels, and COCO's visibility ``v`` in {0, 1, 2} (or NaN, unlabelled)
        in a third column; ``P`` people at once. Scores are not visibilities: pass
        ``keypoints[..., :2]`` and ``confidence=keypoints[..., 2]``.
    links : sequence of (int, int)
        Pairs of joint indices joined by a limb (a skeleton's ``links``).
    confidence : (J,) or (P, J) array_like, optional
        Scores in [0, 1] (NaN: the joint is not drawn).
    visible : (J,) or (P, J) array_like, optional
        Visibility codes 0, 1, 2 (``True`` is 2, ``False`` 0), instead of the third
        column.
    colors : (3,) or (J, 3) ints, optional
        One colour for everything or one per joint (a limb takes its joints' colour, or
        the mean of the two); overrides ``sides``.
    radius : float, optional
        Disc radius in pixels (default ``max(2, L / 200)``, ``L`` the longer side).
    thickness : int, optional
        Limb width in pixels (default ``max(1, round(radius / 2))``, of the radius
        given or the default one).
    labels : sequence of J str, optional
        Joint names, written beside each drawn joint.
    sides : sequence of J str, optional
        ``"left"``, ``"right"`` or ``"center"`` per joint: colours of :data:`SIDE_COLORS`.
    flip_pairs : sequence of (int, int), optional
        ``(left, right)`` joint pairs (a skeleton's ``flip_pairs``, left first); the
        joints in no pair are central. Give this or ``sides``.
    legend : bool, optional
        Add a panel to the right listing the colours (the sides, or each person's
        colour for up to 12 people; not ``colors``) and the disc sizes of three
        confidences (with ``confidence``); default: when ``confidence`` is given. With
        nothing to list there is no panel.
    min_side : int, default 1
        A smaller image is first enlarged by a whole factor towards this longer side
        (:func:`~robopercept.viz.draw.enlarge_picture`, keypoints scaled with it): 512
        makes a 64 x 64 crop readable at 1080p.

    Returns
    -------
    (H, W, 3) uint8 ndarray, or (H', W + legend width, 3) with the legend
        (``H' = H`` unless the legend needs more height).

    Raises
    ------
    InputError
        Keypoints of another shape, a third column that is not visibility codes, links
        outside the joints, per-joint values of another length, a confidence outside
        [0, 1], bad colours or sizes.

    Examples
    --------
    >>> img = np.zeros((40, 60, 3), np.uint8)
    >>> kp = np.array([[10.0, 10.0, 2], [30.0, 20.0, 2], [50.0, 30.0, 0]])
    >>> pic = draw_skeleton(img, kp, [(0, 1), (1, 2)], colors=(255, 0, 0))
    >>> pic[10, 10].tolist(), pic[30, 50].tolist(), pic[15, 20].tolist()
    ([255, 0, 0], [0, 0, 0], [255, 0, 0])
    """
    img = to_rgb8(image)
    side = check_int(min_side, "min_side", 1)
    if side > 1 << 14:
        raise InputError(f"min_side must be at most {1 << 14} pixels; got {side}")
    img, factor = enlarge_picture(img, side)
    h, w = img.shape[:2]
    kp = check_numeric(keypoints, "keypoints")
    if factor > 1:
        kp = kp.astype(np.float64, copy=True)
        kp[..., :2] *= factor
    if kp.ndim == 2:
        kp = kp[None]
    if kp.ndim != 3 or kp.shape[2] not in (2, 3):
        raise InputError(
            f"keypoints must be (J, 2|3) or (P, J, 2|3) (x, y and the visibility v); got "
            f"shape {kp.shape}"
        )
    people, joints = kp.shape[:2]
    link = _check_links(links, max(joints, 1))
    if visible is not None:
        as_bool = np.asarray(visible).dtype == np.bool_
        vis = _per_joint(visible, people, joints, "visible") * (2.0 if as_bool else 1.0)
    elif kp.shape[2] == 3:
        vis = np.where(np.isnan(kp[..., 2]), 0.0, kp[..., 2])
    else:
        vis = np.full((people, joints), 2.0)
    if not np.isin(vis, (0.0, 1.0, 2.0)).all():
        bad = vis[~np.isin(vis, (0.0, 1.0, 2.0))][0]
        raise InputError(
            f"visibilities must be COCO's codes 0, 1 or 2; got {float(bad)}: scores? pass "
            "keypoints[..., :2] and confidence=keypoints[..., 2]"
        )
    conf = None
    if confidence is not None:
        conf = _per_joint(confidence, people, joints, "confidence")
        finite = conf[~np.isnan(conf)]
        if ((finite < 0) | (finite > 1)).any():
            raise InputError(
                f"confidence must be in [0, 1] (NaN: not drawn); got values from "
                f"{finite.min():.3g} to {finite.max():.3g}: pass np.clip(confidence, 0, 1)"
            )
    joint_sides = _joint_sides(sides, flip_pairs, joints)
    joint_col, limb_col = _colors(colors, joint_sides, link, people, joints)
    r0, font_size = _sizes(w, h)
    r0 = r0 if radius is None else check_stroke(radius, "radius", integer=False, minimum=0)
    width = max(1, round(r0 / 2)) if thickness is None else check_stroke(thickness, "thickness")
    width = int(width)
    if labels is not None:
        labels = _names(labels, joints, "labels")
    show_legend = conf is not None if legend is None else check_bool(legend, "legend")

    xy = kp[..., :2]
    drawn = (vis > 0) & np.isfinite(xy).all(axis=-1)
    if conf is not None:
        drawn &= ~np.isnan(conf)
    rad = np.full((people, joints), float(r0))
    if conf is not None:
        rad = r0 * (0.4 + 0.6 * np.nan_to_num(conf))
    with np.errstate(invalid="ignore"):  # (NaN coordinates: not drawn anyway)
        near = (xy[..., 0] >= -rad - 1) & (xy[..., 0] <= w + rad)
        near &= (xy[..., 1] >= -rad - 1) & (xy[..., 1] <= h + rad)
    pil, draw = pil_canvas(img)
    for p in range(people):  # limbs first, under the joints
        ok = drawn[p, link[:, 0]] & drawn[p, link[:, 1]]
        for k in np.flatnonzero(ok):
            i, j = link[k]
            seg = clip_segments(np.r_[xy[p, i], xy[p, j]][None], w, h, width + 2.0)
            col = tuple(int(c) for c in limb_col[p, k])
            for x0, y0, x1, y1 in seg:
                draw.line([(x0, y0), (x1, y1)], fill=col, width=width)
    for p in range(people):
        for j in np.flatnonzero(drawn[p] & near[p]):
            x, y = xy[p, j]
            r = float(rad[p, j])
            col = tuple(int(c) for c in joint_col[p, j])
            box = (x - r, y - r, x + r, y + r)
            if vis[p, j] == 2:
                outline = (0, 0, 0) if r >= 4 else None  # a dark rim on bright images
                draw.ellipse(box, fill=col, outline=outline, width=1)
            else:
                draw.ellipse(box, outline=col, width=max(1, round(r / 3)))
    if labels is not None:
        font = _font(font_size)
        for p in range(people):
            for j in np.flatnonzero(drawn[p] & near[p]):
                x, y = xy[p, j]
                ox, oy = x + rad[p, j] + 2, y - font_size / 2
                left, top, right, bottom = draw.textbbox((ox, oy), labels[j], font=font)
                if right < 0 or bottom < 0 or left > w or top > h:
                    continue
                draw.rectangle([left - 2, top - 2, right + 2, bottom + 2], fill=(0, 0, 0))
                draw.text((ox, oy), labels[j], fill=(255, 255, 255), font=font)
    out = np.asarray(pil)
    if not show_legend:
        return out
    rows: list[tuple[str, Color, float]] = []  # (text, colour, disc radius or 0: a swatch)
    if colors is None and joint_sides is not None:
        rows += [(s, SIDE_COLORS[s], 0.0) for s in SIDE_COLORS if s in joint_sides]
    elif colors is None and 0 < people <= _LEGEND_PEOPLE:
        hues = label_colors(np.arange(1, people + 1))
        for p in range(people):
            r, g, b = (int(c) for c in hues[p])
            rows.append((f"person {p + 1}", (r, g, b), 0.0))
    if conf is not None:
        rows += [
            (f"confidence {c:.1f}", (90, 90, 90), r0 * (0.4 + 0.6 * c)) for c in _LEGEND_CONFIDENCES
        ]
    return _legend_panel(out, rows, font_size) if rows else out


def _legend_panel(pic: np.ndarray, rows: list[tuple[str, Color, float]], size: int) -> np.ndarray:
    """``pic`` with a white panel on its right listing ``rows`` (text, colour, disc
    radius): a disc of that radius, or a swatch where the radius is 0, and the text."""
    from PIL import Image, ImageDraw

    radius = max(r for _, _, r in rows)
    step = int(max(size * 1.6, 2 * radius + 6))
    mark = int(max(size, 2 * radius))
    longest = max(len(t) for t, _, _ in rows)
    width = int(mark + size * (1.5 + 0.62 * longest))
    height = max(pic.shape[0], size + len(rows) * step)
    check_picture_size(pic.shape[1] + width, height, "picture with its legend")
    canvas = Image.new("RGB", (pic.shape[1] + width, height), (255, 255, 255))
    canvas.paste(Image.fromarray(pic), (0, 0))
    draw = ImageDraw.Draw(canvas)
    font = _font(size)
    x0 = pic.shape[1] + size // 2
    for k, (text, col, r) in enumerate(rows):
        cy = size // 2 + k * step + step / 2
        cx = x0 + mark / 2
        if r > 0:
            draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=col)
        else:
            half = size / 2
            draw.rectangle((cx - half, cy - half, cx + half, cy + half), fill=col, outline=0)
        draw.text((x0 + mark + size // 2, cy - size / 2), text, fill=(0, 0, 0), font=font)
    return np.asarray(canvas)


def heatmap_grid(
    image: np.ndarray,
    heatmaps: np.ndarray,
    names: Sequence[str] | None = None,
    cols: int | None = None,
    *,
    tile_px: int = 256,
    alpha: float = 0.7,
) -> np.ndarray:
    r"""Each joint's heatmap over the image, one captioned tile per joint, in a grid.

    The image is resized (bilinear) so that its longer side is ``tile_px``:
    :math:`t_w \times t_h` = ``round(W s) x round(H s)`` with ``s = tile_px / max(H, W)``.
    Each heatmap is stretched over the whole image by bilinear interpolation with
    half-pixel alignment (heatmap pixel ``u`` is centred at image column
    :math:`(u + 0.5) W / w - 0.5`, as ``cv2.resize`` and mmpose's heatmap codecs),
    scaled to its own maximum, :math:`t = \max(h, 0) / \max h` (a heatmap with no
    positive value shows the plain image), and blended as
    :math:`(1 - a t)\, I + a t\, \mathrm{turbo}(t)` (Turbo sampled at 256 levels of
    :math:`t`): where the heatmap is 0 the image shows through, at its peak the Turbo
    red. Each tile's caption is the joint's name
    and the heatmap's maximum (the name alone, shortened with ``...``, where that is too
    wide for the tile).

    Layout: ``cols`` tiles per row (default :math:`\lceil \sqrt J \rceil`, at most J),
    ``g = max(4, tile_px // 40)`` white pixels around the tiles and a caption band of
    ``c = round(1.5 f)`` pixels above each one (``f = max(12, round(tile_px / 16))``,
    the text height): the picture is ``rows (t_h + c + g) + g`` by
    ``cols (t_w + g) + g`` pixels.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        The picture the heatmaps were computed from (the network's input crop).
    heatmaps : (J, h, w) array_like
        Finite real values (a network's output for one image).
    names : sequence of J str, optional
        Default ``"joint 0"``, ``"joint 1"``, ...
    cols : int, optional
        Tiles per row.
    tile_px : int
        The longer side of a tile, 8 to 2048 pixels.
    alpha : float
        Opacity of the heatmap colours at their peak, in [0, 1].

    Returns
    -------
    (H', W', 3) uint8 ndarray

    Raises
    ------
    InputError
        Heatmaps not (J, h, w), empty or not finite; names not one per heatmap; bad
        ``cols``, ``tile_px`` or ``alpha``.

    Examples
    --------
    >>> hm = np.zeros((3, 8, 8)); hm[0, 2, 2] = hm[1, 5, 5] = hm[2, 1, 6] = 1.0
    >>> heatmap_grid(np.zeros((32, 32)), hm, cols=3, tile_px=64).shape
    (90, 208, 3)
    """
    from PIL import Image, ImageDraw

    img = to_rgb8(image)
    hm = check_ndim(heatmaps, "heatmaps", (3,))
    if hm.dtype.kind not in "biuf":
        raise InputError(f"heatmaps must be real numbers; got dtype {hm.dtype}")
    if 0 in hm.shape:
        raise InputError(f"heatmaps must be (J, h, w) with J, h, w >= 1; got {hm.shape}")
    hm = check_finite(check_magnitude(hm.astype(np.float64), "heatmaps", 1e300), "heatmaps")
    joints = hm.shape[0]
    if names is None:
        captions = [f"joint {k}" for k in range(joints)]
    else:
        captions = _names(names, joints, "names")
    ncol = math.ceil(math.sqrt(joints)) if cols is None else check_int(cols, "cols", 1)
    ncol = min(ncol, joints)
    tile_px = check_int(tile_px, "tile_px", 8)
    if tile_px > 2048:
        raise InputError(f"tile_px must be at most 2048 pixels; got {tile_px}")
    a = check_real(alpha, "alpha", 0.0, 1.0)
    h, w = img.shape[:2]
    s = tile_px / max(h, w)
    tw, th = max(1, round(w * s)), max(1, round(h * s))
    font_size = int(max(12, round(tile_px / 16)))
    cap = round(1.5 * font_size)
    gap = max(4, tile_px // 40)
    nrow = math.ceil(joints / ncol)
    width, height = ncol * (tw + gap) + gap, nrow * (th + cap + gap) + gap
    check_picture_size(width, height, "heatmap grid")
    base = np.asarray(Image.fromarray(img).resize((tw, th), Image.Resampling.BILINEAR))
    base = base.astype(np.float32)
    lut = turbo(np.linspace(0.0, 1.0, 256)).astype(np.float32)  # (a 4 Mpx tile: 48 MB)
    out = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(out)
    font = _font(font_size)
    for k in range(joints):
        peak = float(hm[k].max())
        scaled = hm[k] / peak if peak > 0 else np.zeros_like(hm[k])  # (before float32)
        up = Image.fromarray(scaled.astype(np.float32))  # (mode "F")
        t = np.clip(np.asarray(up.resize((tw, th), Image.Resampling.BILINEAR)), 0.0, 1.0)
        wt = (np.float32(a) * t)[..., None]
        color = lut[np.round(t * 255).astype(np.intp)]
        tile = np.round((1 - wt) * base + wt * color).astype(np.uint8)
        r, c = divmod(k, ncol)
        x, y = gap + c * (tw + gap), gap + r * (th + cap + gap)
        out.paste(Image.fromarray(tile), (x, y + cap))
        text = _fit(draw, font, captions[k], f"  max {peak:.3g}", tw)
        draw.text((x, y + (cap - font_size) // 2), text, fill=(0, 0, 0), font=font)
    return np.asarray(out)


def _fit(draw: Any, font: Any, name: str, suffix: str, width: int) -> str:
    """``name + suffix`` shortened to fit ``width`` pixels: the suffix goes first, then
    the name's end (marked by ``...``)."""
    text = name + suffix
    if draw.textlength(text, font=font) <= width:
        return text
    text = name
    while len(text) > 1 and draw.textlength(text, font=font) > width:
        text = text[:-4] + "..." if len(text) > 4 else text[:-1]
    return text


def _check_pose3d(value: Any, name: str, joints: int | None) -> np.ndarray:
    arr = check_numeric(value, name)
    if arr.ndim != 2 or arr.shape[1] != 3 or (joints is not None and arr.shape[0] != joints):
        want = "(J, 3)" if joints is None else f"(J, 3) = ({joints}, 3)"
        raise InputError(f"{name} must be {want} joint positions in metres; got {arr.shape}")
    if np.isinf(arr).any():
        raise InputError(f"{name} must be finite (NaN: a joint not drawn); got inf")
    return check_magnitude(arr, name, 1e9)


#: an axis seen within this foreshortening (the sine of its angle to the line of
#: sight) has its tick labels hidden: they would pile up on one spot
_FORESHORTENED = 0.35
#: the pixels a tick label needs along its axis (a "-0.8" in matplotlib's 10 pt at
#: 100 dpi is about 30 px wide), so that neighbours keep a gap
_TICK_SPACING = 70.0


def _axis_ticks(ax: Any, elev: float, azim: float, panel_px: float) -> list[str]:
    """Give each axis of a 3-D panel seen from ``(elev, azim)`` (degrees) as many ticks
    as its drawn length leaves room for (matplotlib's ``MaxNLocator``), and hide the
    ticks and label of an axis seen nearly end-on; returns the hidden axes' names."""
    from matplotlib.ticker import MaxNLocator, NullLocator

    e, a = math.radians(elev), math.radians(azim)
    sight = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    hidden = []
    for k, (name, axis) in enumerate(zip("xyz", (ax.xaxis, ax.yaxis, ax.zaxis), strict=True)):
        shown = math.sqrt(max(0.0, 1.0 - float(sight[k]) ** 2))  # the drawn fraction
        if shown < _FORESHORTENED:
            axis.set_major_locator(NullLocator())
            axis.set_label_text("")
            hidden.append(name)
            continue
        bins = int(min(6, max(2, panel_px * shown / _TICK_SPACING)))
        axis.set_major_locator(MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]))
    return hidden


def skeleton_3d_figure(
    joints3d: np.ndarray,
    links: Sequence[tuple[int, int]] | np.ndarray,
    views: Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    titles: Sequence[str] | None = None,
    *,
    reference: np.ndarray | None = None,
    legend: tuple[str, str] = ("prediction", "ground truth"),
    size: tuple[int, int] = (1200, 560),
) -> Any:
    """The matplotlib figure of :func:`skeleton_3d_picture` (same parameters), for a
    caller who adds to it or saves it as a vector file (``fig.savefig("pose.svg")``).

    Returns
    -------
    matplotlib.figure.Figure
        On an Agg canvas, ``size`` pixels at its dpi.

    Examples
    --------
    >>> pose = np.array([[0.0, 0.0, 0.0], [0.0, -0.5, 0.0], [0.3, -0.9, 0.1]])
    >>> fig = skeleton_3d_figure(pose, [(0, 1), (1, 2)], size=(400, 200))
    >>> len(fig.axes)
    2
    """
    pose = _check_pose3d(joints3d, "joints3d", None)
    joints = pose.shape[0]
    link = _check_links(links, max(joints, 1))
    ref = None if reference is None else _check_pose3d(reference, "reference", joints)
    angles = check_views(views)
    if titles is None:
        heads = [f"elevation {e:.0f}°, azimuth {a:.0f}°" for e, a in angles]
    else:
        heads = _names(titles, len(angles), "titles", "view")
    if not isinstance(legend, (tuple, list)) or len(legend) != 2:
        raise InputError(f"legend must be two names (pose, reference); got {legend!r}")
    names = [check_text(n, f"legend[{i}]") for i, n in enumerate(legend)]
    width, height = check_size(size, "size", 150, 4000, 12_000_000)
    if width < 200:
        raise InputError(f"size must be at least 200 pixels wide; got {width}")
    fig = agg_figure(width, height, what="skeleton_3d_picture")
    from mpl_toolkits.mplot3d import Axes3D  # noqa: F401  (registers "3d")

    poses = [p for p in (ref, pose) if p is not None]
    pts = np.concatenate(poses)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mid, half = (lo + hi) / 2, max(float((hi - lo).max()) / 2 * 1.1, 1e-3)
    else:
        mid, half = np.zeros(3), 1.0
    fig.subplots_adjust(left=0.02, right=0.95, bottom=0.1, top=0.92, wspace=0.15)
    # the drawn length of a whole axis: about half the panel's smaller side, in pixels
    panel_px = 0.5 * min(width / len(angles), height)
    styles = [("#1f77b4", names[0], pose)]
    if ref is not None:
        styles.insert(0, ("#d62728", names[1], ref))
    for k, ((elev, azim), head) in enumerate(zip(angles, heads, strict=True)):
        ax = fig.add_subplot(1, len(angles), k + 1, projection="3d")
        for color, label, p in styles:
            ok = np.isfinite(p).all(axis=1)
            ax.scatter(*p[ok].T, color=color, s=12, depthshade=False, label=label)
            for i, j in link:
                if ok[i] and ok[j]:
                    ax.plot(*p[[i, j]].T, color=color, linewidth=2)
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
        ax.set_box_aspect((1.0, 1.0, 1.0))
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_zlabel("z (m)")
        ax.view_init(elev=elev, azim=azim)
        hidden = _axis_ticks(ax, elev, azim, panel_px)
        note = f"\n({', '.join(hidden)} along the line of sight)" if hidden else ""
        ax.set_title(head + note)
    if ref is not None:
        handles, texts = fig.axes[0].get_legend_handles_labels()
        fig.legend(handles[::-1], texts[::-1], loc="lower center", ncol=2)
    return fig


def skeleton_3d_picture(
    joints3d: np.ndarray,
    links: Sequence[tuple[int, int]] | np.ndarray,
    views: Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    titles: Sequence[str] | None = None,
    *,
    reference: np.ndarray | None = None,
    legend: tuple[str, str] = ("prediction", "ground truth"),
    size: tuple[int, int] = (1200, 560),
) -> np.ndarray:
    """A 3-D skeleton seen from several viewpoints side by side (matplotlib, Agg).

    Each panel draws the joints as dots and the links as lines, with the same scale on
    the three axes (a cube around all the joints, 10 % margin, drawn as a cube), axes
    labelled ``x (m)``, ``y (m)``, ``z (m)``; ``reference`` (the ground truth beside a
    prediction) is drawn in red under the pose in blue, with a legend. Joints with a
    NaN coordinate, and their links, are left out. Rendered off screen with
    matplotlib's Agg canvas (no pyplot, no window, no global state).

    Tick labels stay apart: each axis gets as many ticks as its drawn length leaves
    room for (matplotlib's ``MaxNLocator``, 2 to 6), and an axis seen nearly end-on
    (less than 35 % of its length drawn, as ``y`` in the default front view) shows no
    ticks or label, the panel's title naming it ("y along the line of sight").

    Parameters
    ----------
    joints3d : (J, 3) array_like
        Joint positions in metres (any frame: the camera's x right, y down, z forward,
        or a body frame).
    links : sequence of (int, int)
        Pairs of joint indices.
    views : sequence of (elevation, azimuth)
        One panel per view, 1 to 6 of them, angles in radians (matplotlib's
        ``view_init`` convention: elevation above the x-y plane, azimuth about z).
    titles : sequence of str, optional
        One per view; default the view's angles in degrees.
    reference : (J, 3) array_like, optional
        A second pose of the same joints.
    legend : (str, str)
        The names of the pose and the reference in the legend.
    size : (int, int)
        ``(width, height)`` of the picture, 200 x 150 to 4000 x 3000 pixels.

    Returns
    -------
    (height, width, 3) uint8 ndarray

    Raises
    ------
    InputError
        Joints not (J, 3), inf or beyond 1e9, a reference of another shape, bad
        links, views, titles or size, or matplotlib missing (``pip install
        matplotlib``).

    Examples
    --------
    >>> pose = np.array([[0.0, 0.0, 0.0], [0.0, -0.5, 0.0], [0.3, -0.9, 0.1]])
    >>> skeleton_3d_picture(pose, [(0, 1), (1, 2)], size=(400, 200)).shape
    (200, 400, 3)
    """
    fig = skeleton_3d_figure(
        joints3d, links, views, titles, reference=reference, legend=legend, size=size
    )
    return figure_to_rgb(fig)
