r"""Selective search region proposals (Uijlings, van de Sande, Gevers & Smeulders, IJCV 2013).

Starting from a Felzenszwalb-Huttenlocher over-segmentation
(:func:`robopercept.imaging.segmentation.felzenszwalb`), :func:`hierarchical_grouping`
merges the most similar pair of neighbouring regions, again and again, until one region
is left; every region ever formed gives a proposal, its bounding box. The similarity of
regions :math:`r_i, r_j` is the sum of the enabled terms, each in [0, 1]:

.. math::
    s_{colour} = \sum_k \min(c_i^k, c_j^k), \qquad
    s_{texture} = \sum_k \min(t_i^k, t_j^k),

    s_{size} = 1 - \frac{|r_i| + |r_j|}{|im|}, \qquad
    s_{fill} = 1 - \frac{|BB_{ij}| - |r_i| - |r_j|}{|im|}

with :math:`c` the L1-normalized colour histogram (25 bins per channel), :math:`t` the
L1-normalized texture histogram (10 bins for each of 8 orientations of the Gaussian
derivative, sigma = 1, per channel: the positive part of
:math:`\cos\theta\,\partial_x I + \sin\theta\,\partial_y I`, :math:`\theta = k\pi/4`) and
:math:`BB_{ij}` the bounding box of both. A merged region's histograms are the
size-weighted means :math:`(|r_i| c_i + |r_j| c_j) / (|r_i| + |r_j|)`. Regions are
neighbours when two of their pixels are 4-adjacent; ties in similarity go to the pair
with the smaller indices.

:func:`selective_search` diversifies as OpenCV's ``SelectiveSearchSegmentation``:

* ``"fast"`` (``switchToSelectiveSearchFast``): colour spaces HSV and Lab, ``k`` in
  {150, 300}, similarities colour+texture+size+fill and texture+size+fill (8 groupings);
* ``"quality"`` (``switchToSelectiveSearchQuality``): HSV, Lab, intensity, hue and Lab's
  L, ``k`` in {150, 300, 450, 600, 750}, the two above plus fill alone and size alone (100
  groupings);

Felzenszwalb runs with ``sigma = 0.8`` and ``min_size = 100`` (the defaults of OpenCV's
``GraphSegmentation``, which its selective search keeps). As in
the paper, the proposals are ranked by :math:`v = u \cdot l` with :math:`u \sim U(0, 1)`
from ``rng`` and :math:`l` the region's position in its hierarchy counted from the top
(the last merge, the whole image, has ``l = 1``; the initial regions the largest), sorted
by increasing ``v``, and duplicate boxes are dropped (the best-ranked kept). The same
``rng`` seed gives the same proposals in the same order.
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence
from typing import Literal

import numpy as np

from robopercept._checks import as_rng, check_choice, check_image, check_int, check_ndim
from robopercept.errors import InputError
from robopercept.imaging.color import rgb_to_gray, rgb_to_hsv
from robopercept.imaging.filters import gaussian_kernel, separable_filter_unchecked
from robopercept.imaging.segmentation import felzenszwalb
from robopercept.progress import progress_bar

__all__ = ["SIMILARITIES", "hierarchical_grouping", "selective_search"]

#: the similarity terms :func:`hierarchical_grouping` can sum
SIMILARITIES: tuple[str, ...] = ("color", "texture", "size", "fill")
COLOR_BINS = 25
TEXTURE_BINS = 10
ORIENTATIONS = 8
#: Felzenszwalb min_size of every segmentation (OpenCV GraphSegmentation default)
MIN_SIZE = 100

_STRATEGIES = {
    "fast": (("color", "texture", "size", "fill"), ("texture", "size", "fill")),
    "quality": (
        ("color", "texture", "size", "fill"),
        ("texture", "size", "fill"),
        ("fill",),
        ("size",),
    ),
}
_K = {"fast": (150, 300), "quality": (150, 300, 450, 600, 750)}
_SPACES = {"fast": ("hsv", "lab"), "quality": ("hsv", "lab", "gray", "hue", "lightness")}


# ------------------------------------------------------------------------ colour spaces


def _unit_rgb(image: np.ndarray) -> np.ndarray:
    # RGB (or gray) in [0, 1] as float64 (negative values of signed integer or float
    # images clipped to 0, as values above 1: the histograms' bins cover [0, 1])
    out = image.astype(np.float64)
    if image.dtype.kind in "ui":
        out /= float(np.iinfo(image.dtype).max)
    return np.clip(out, 0.0, 1.0)


def _rgb_to_lab_unit(rgb: np.ndarray) -> np.ndarray:
    # CIE L*a*b* (sRGB, D65 white) scaled to [0, 1]: L / 100, (a + 128) / 255, (b + 128) / 255
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    m = np.array(
        [
            [0.412453, 0.357580, 0.180423],
            [0.212671, 0.715160, 0.072169],
            [0.019334, 0.119193, 0.950227],
        ]
    )
    xyz = lin @ m.T / np.array([0.950456, 1.0, 1.088754])
    d = 6.0 / 29.0
    f = np.where(xyz > d**3, np.cbrt(xyz), xyz / (3 * d * d) + 4.0 / 29.0)
    lab = np.stack(
        [
            116.0 * f[..., 1] - 16.0,
            500.0 * (f[..., 0] - f[..., 1]),
            200.0 * (f[..., 1] - f[..., 2]),
        ],
        axis=-1,
    )
    offset, span = np.array([0.0, 128.0, 128.0]), np.array([100.0, 255.0, 255.0])
    return np.clip((lab + offset) / span, 0.0, 1.0)


def _color_space(rgb: np.ndarray, space: str) -> np.ndarray:
    """``rgb`` (float64 in [0, 1], (H, W, 3) or (H, W)) in ``space``, each channel in
    [0, 1], as (H, W, C) float64."""
    if rgb.ndim == 2:
        return rgb[:, :, None]
    if space in ("hsv", "hue"):
        hsv = rgb_to_hsv(rgb, scale="unit")
        return hsv if space == "hsv" else hsv[:, :, :1]
    if space in ("lab", "lightness"):
        lab = _rgb_to_lab_unit(rgb)
        return lab if space == "lab" else lab[:, :, :1]
    return rgb_to_gray(rgb).astype(np.float64)[:, :, None]


# ---------------------------------------------------------------------------- features


def _region_features(
    image: np.ndarray, labels: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sizes (n,), boxes (n, 4) as (x0, y0, x1, y1) inclusive, colour (n, 25 C) and
    texture (n, 80 C) histograms, both L1-normalized, of the regions ``labels`` of
    ``image`` ((H, W, C) float64 in [0, 1])."""
    h, w, nc = image.shape
    flat = labels.ravel()
    sizes = np.bincount(flat, minlength=n).astype(np.float64)
    ys, xs = np.divmod(np.arange(h * w), w)
    boxes = np.empty((n, 4), dtype=np.int64)
    boxes[:, 0] = np.full(n, w)
    boxes[:, 1] = np.full(n, h)
    np.minimum.at(boxes[:, 0], flat, xs)
    np.minimum.at(boxes[:, 1], flat, ys)
    boxes[:, 2] = -1
    boxes[:, 3] = -1
    np.maximum.at(boxes[:, 2], flat, xs)
    np.maximum.at(boxes[:, 3], flat, ys)

    color = np.zeros((n, COLOR_BINS * nc))
    for c in range(nc):
        b = np.minimum((image[:, :, c].ravel() * COLOR_BINS).astype(np.int64), COLOR_BINS - 1)
        color[:, c * COLOR_BINS : (c + 1) * COLOR_BINS] = np.bincount(
            flat * COLOR_BINS + b, minlength=n * COLOR_BINS
        ).reshape(n, COLOR_BINS)

    g = gaussian_kernel(1.0)
    x = np.arange(g.size) - g.size // 2
    dg = -x * g  # d/dx of the Gaussian of sigma 1 (x / sigma^2 with sigma = 1)
    nb = TEXTURE_BINS
    texture = np.zeros((n, nb * ORIENTATIONS * nc))
    for c in range(nc):
        ch = np.ascontiguousarray(image[:, :, c])
        # correlation with -dg gives +d/dx; the sign does not matter with 8 orientations
        gx = separable_filter_unchecked(ch, -dg, g).ravel()
        gy = separable_filter_unchecked(ch, g, -dg).ravel()
        for o in range(ORIENTATIONS):
            theta = o * np.pi / 4.0
            r = np.maximum(np.cos(theta) * gx + np.sin(theta) * gy, 0.0)
            top = r.max()
            b = np.minimum((r * (nb / top) if top > 0 else r).astype(np.int64), nb - 1)
            col = (c * ORIENTATIONS + o) * nb
            texture[:, col : col + nb] = np.bincount(flat * nb + b, minlength=n * nb).reshape(n, nb)
    color /= np.maximum(color.sum(1, keepdims=True), 1.0)
    texture /= np.maximum(texture.sum(1, keepdims=True), 1.0)
    return sizes, boxes, color, texture


def _neighbour_pairs(labels: np.ndarray) -> np.ndarray:
    # unique (i < j) pairs of labels that touch 4-adjacently
    a = np.concatenate([labels[:, :-1].ravel(), labels[:-1, :].ravel()])
    b = np.concatenate([labels[:, 1:].ravel(), labels[1:, :].ravel()])
    keep = a != b
    lo, hi = np.minimum(a[keep], b[keep]), np.maximum(a[keep], b[keep])
    return np.unique(np.stack([lo, hi], axis=1), axis=0)


def _group(image: np.ndarray, labels: np.ndarray, terms: Sequence[str]) -> tuple[np.ndarray, int]:
    """The merge loop: boxes (2n - 1 or fewer, 4) xyxy inclusive in creation order, and
    the number of initial regions."""
    n = int(labels.max()) + 1
    sizes0, boxes0, color0, texture0 = _region_features(image, labels, n)
    total = 2 * n - 1
    sizes = np.zeros(total)
    boxes = np.zeros((total, 4), dtype=np.int64)
    sizes[:n], boxes[:n] = sizes0, boxes0
    use_c, use_t = "color" in terms, "texture" in terms
    use_s, use_f = "size" in terms, "fill" in terms
    color = np.zeros((total, color0.shape[1])) if use_c else None
    texture = np.zeros((total, texture0.shape[1])) if use_t else None
    if color is not None:
        color[:n] = color0
    if texture is not None:
        texture[:n] = texture0
    im_size = float(labels.size)

    def sim(i: int, js: np.ndarray) -> np.ndarray:
        s = np.zeros(js.size)
        if color is not None:
            s += np.minimum(color[i], color[js]).sum(1)
        if texture is not None:
            s += np.minimum(texture[i], texture[js]).sum(1)
        if use_s:
            s += 1.0 - (sizes[i] + sizes[js]) / im_size
        if use_f:
            bw = np.maximum(boxes[i, 2], boxes[js, 2]) - np.minimum(boxes[i, 0], boxes[js, 0]) + 1
            bh = np.maximum(boxes[i, 3], boxes[js, 3]) - np.minimum(boxes[i, 1], boxes[js, 1]) + 1
            s += 1.0 - (bw * bh - sizes[i] - sizes[js]) / im_size
        return s

    neighbours: list[set[int]] = [set() for _ in range(total)]
    heap: list[tuple[float, int, int]] = []
    pairs = _neighbour_pairs(labels)
    for i in np.unique(pairs[:, 0]) if pairs.size else []:
        js = pairs[pairs[:, 0] == i, 1]
        for j, s in zip(js.tolist(), sim(int(i), js).tolist(), strict=True):
            neighbours[int(i)].add(j)
            neighbours[j].add(int(i))
            heap.append((-s, int(i), j))
    heapq.heapify(heap)
    alive = np.zeros(total, dtype=bool)
    alive[:n] = True
    t = n
    while heap:
        _, i, j = heapq.heappop(heap)
        if not (alive[i] and alive[j]):
            continue
        si, sj = sizes[i], sizes[j]
        sizes[t] = si + sj
        boxes[t, :2] = np.minimum(boxes[i, :2], boxes[j, :2])
        boxes[t, 2:] = np.maximum(boxes[i, 2:], boxes[j, 2:])
        if color is not None:
            color[t] = (si * color[i] + sj * color[j]) / (si + sj)
        if texture is not None:
            texture[t] = (si * texture[i] + sj * texture[j]) / (si + sj)
        alive[i] = alive[j] = False
        alive[t] = True
        nb = (neighbours[i] | neighbours[j]) - {i, j}
        for k in nb:
            neighbours[k].discard(i)
            neighbours[k].discard(j)
            neighbours[k].add(t)
        neighbours[t] = nb
        if nb:
            js = np.array(sorted(nb))
            for k, s in zip(js.tolist(), sim(t, js).tolist(), strict=True):
                heapq.heappush(heap, (-s, k, t))
        t += 1
    return boxes[:t], n


def _check_terms(similarity: object) -> tuple[str, ...]:
    if isinstance(similarity, str) or not isinstance(similarity, (tuple, list)):
        raise InputError(
            f"similarity must be a tuple of names from {SIMILARITIES}; got {similarity!r}: "
            "e.g. similarity=('color', 'size')"
        )
    if not similarity:
        raise InputError(f"similarity must name at least one of {SIMILARITIES}; got ()")
    for s in similarity:
        check_choice(s, "similarity term", SIMILARITIES)
    return tuple(similarity)


def _xyxy_to_xywh(boxes: np.ndarray) -> np.ndarray:
    out = boxes.copy()
    out[:, 2:] = boxes[:, 2:] - boxes[:, :2] + 1
    return out


def hierarchical_grouping(
    image: np.ndarray,
    labels: np.ndarray,
    similarity: Sequence[str] = SIMILARITIES,
) -> np.ndarray:
    r"""Greedy hierarchical grouping of the regions ``labels`` of ``image`` (Uijlings et al.).

    Repeatedly merges the most similar pair of 4-adjacent regions (similarity: the sum
    of the ``similarity`` terms, see the module docstring) until no two regions touch,
    and returns the bounding box of every region formed, in creation order.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        The image whose colour and texture describe the regions; uint8, uint16 or
        float in [0, 1] (clipped), used as given (no colour conversion).
    labels : (H, W) int ndarray
        Region labels ``0 .. n-1`` (e.g. from ``felzenszwalb``), each label used.
    similarity : sequence of {'color', 'texture', 'size', 'fill'}
        The terms summed.

    Returns
    -------
    (2n - 1, 4) int64 ndarray
        Boxes ``(x, y, w, h)`` (pixels, inclusive extents as OpenCV's ``Rect``): the ``n``
        initial regions, then one per merge; the last covers every region (the whole
        image when the labels form one connected area).

    Raises
    ------
    InputError
        A bad image, ``labels`` not an (H, W) integer array of the image's shape with
        labels ``0 .. n-1`` all present, or an unknown similarity term.

    Examples
    --------
    Four flat quadrants; the two black ones (identical colour histograms) merge first:

    >>> img = np.zeros((8, 8), np.uint8); img[:, 4:] = 200; img[4:, 4:] = 190
    >>> lab = np.zeros((8, 8), np.int64); lab[:, 4:] = 1; lab[4:, :4] = 2; lab[4:, 4:] = 3
    >>> hierarchical_grouping(img, lab, ("color",)).tolist()[4:]
    [[0, 0, 4, 8], [4, 0, 4, 8], [0, 0, 8, 8]]
    """
    image = check_image(image)
    lab = check_ndim(labels, "labels", (2,))
    if lab.dtype.kind not in "iu":
        raise InputError(f"labels must be an integer array; got dtype {lab.dtype}")
    if lab.shape != image.shape[:2]:
        raise InputError(f"labels must have the image's shape {image.shape[:2]}; got {lab.shape}")
    if lab.min() < 0:
        raise InputError(f"labels must be >= 0; got {lab.min()}: relabel with np.unique")
    if lab.max() >= lab.size:
        raise InputError(
            f"labels must be 0 .. n-1 with n <= the pixel count {lab.size}; got a label "
            f"{lab.max()}: relabel with np.unique(labels, return_inverse=True)[1]"
        )
    counts = np.bincount(lab.ravel().astype(np.int64))
    if (counts == 0).any():
        raise InputError(
            f"labels must use every value 0 .. {counts.size - 1}; {int((counts == 0).sum())} "
            "are missing: relabel with np.unique(labels, return_inverse=True)[1]"
        )
    terms = _check_terms(similarity)
    rgb = _unit_rgb(image)
    feat = rgb if rgb.ndim == 3 else rgb[:, :, None]
    boxes, _ = _group(feat, lab.astype(np.int64), terms)
    return _xyxy_to_xywh(boxes)


def selective_search(
    image: np.ndarray,
    mode: Literal["fast", "quality"] = "fast",
    rng: int | np.random.Generator | None = None,
    max_proposals: int | None = None,
    *,
    progress: bool = False,
) -> np.ndarray:
    r"""Selective search object proposals, as OpenCV's ``SelectiveSearchSegmentation``.

    Runs :func:`hierarchical_grouping` on Felzenszwalb segmentations of the image in
    several colour spaces, with several ``k`` and several similarity combinations
    (``mode``, see the module docstring), and ranks the union of all boxes by
    :math:`u \cdot l` (random :math:`u \in [0, 1)`, hierarchy level :math:`l` from the
    top), best first, without duplicates.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) ndarray
        RGB (or gray: then only intensity is used), uint8, uint16 or float in [0, 1].
    mode : {'fast', 'quality'}
        The diversification of ``switchToSelectiveSearchFast`` (8 groupings) or
        ``switchToSelectiveSearchQuality`` (100 groupings, much slower).
    rng : int or numpy.random.Generator, optional
        Seed of the ranking; the same seed gives the same boxes in the same order.
    max_proposals : int, optional
        Keep only the best-ranked ``max_proposals`` (>= 1) boxes.
    progress : bool
        Show a progress bar on stderr (one step per segmentation).

    Returns
    -------
    (N, 4) int64 ndarray
        Boxes ``(x, y, w, h)`` in pixels, as OpenCV's ``process()``, best-ranked first;
        every box lies inside the image and the whole-image box is among them.

    Raises
    ------
    InputError
        A bad image, an unknown ``mode``, a bad ``rng`` or ``max_proposals`` < 1.

    Examples
    --------
    >>> img = np.zeros((32, 32, 3), np.uint8); img[8:20, 10:24] = (220, 40, 40)
    >>> boxes = selective_search(img, rng=0)
    >>> [10, 8, 14, 12] in boxes.tolist(), [0, 0, 32, 32] in boxes.tolist()
    (True, True)
    """
    image = check_image(image)
    check_choice(mode, "mode", ("fast", "quality"))
    gen = as_rng(rng)
    if max_proposals is not None:
        max_proposals = check_int(max_proposals, "max_proposals", 1)
    rgb = _unit_rgb(image)
    spaces = _SPACES[mode] if rgb.ndim == 3 else ("gray",)
    runs = [(s, k) for s in spaces for k in _K[mode]]
    all_boxes: list[np.ndarray] = []
    all_levels: list[np.ndarray] = []
    converted: dict[str, np.ndarray] = {}
    for space, k in progress_bar(
        runs, desc="selective search", unit="segmentation", disable=not progress
    ):
        if space not in converted:
            converted[space] = _color_space(rgb, space)
        img = converted[space]
        labels = felzenszwalb(img if img.shape[2] == 3 else img[:, :, 0], k, 0.8, MIN_SIZE)
        for terms in _STRATEGIES[mode]:
            boxes, _ = _group(img, labels, terms)
            all_boxes.append(boxes)
            all_levels.append(np.arange(boxes.shape[0], 0, -1, dtype=np.float64))
    boxes = np.concatenate(all_boxes)
    rank = gen.random(boxes.shape[0]) * np.concatenate(all_levels)
    boxes = boxes[np.argsort(rank, kind="stable")]
    _, first = np.unique(boxes, axis=0, return_index=True)
    boxes = boxes[np.sort(first)]
    if max_proposals is not None:
        boxes = boxes[:max_proposals]
    return _xyxy_to_xywh(boxes)
