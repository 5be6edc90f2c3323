r"""Felzenszwalb-Huttenlocher graph-based image segmentation.

:func:`felzenszwalb` builds the 8-connected grid graph of a Gaussian-smoothed image,
weights each edge by the Euclidean colour distance of its two pixels,

.. math:: w(p, q) = \lVert I_\sigma(p) - I_\sigma(q) \rVert_2 ,

visits the edges by increasing weight and merges the two components ``C1``, ``C2`` an
edge joins when the edge is lighter than both components' internal difference plus
their threshold,

.. math:: w < \min\bigl(\mathrm{Int}(C_1) + \tau(C_1),\; \mathrm{Int}(C_2) + \tau(C_2)\bigr),
          \qquad \tau(C) = k / |C| ,

where ``Int(C)`` is the weight of the edge that last merged ``C`` (the largest weight of
its minimum spanning tree, since edges come in increasing order). A second pass over the
same sorted edges then merges every pair of components of which one has fewer than
``min_size`` pixels (Felzenszwalb & Huttenlocher, IJCV 2004).

The semantics are those of ``skimage.segmentation.felzenszwalb`` (scikit-image 0.26):
the image is taken to [0, 1] as ``skimage.img_as_float`` does (uint8 / 255, uint16 /
65535, float kept, float32 staying float32), ``k = scale / 255`` (so ``scale`` is the
``k`` of the authors' code on 0..255 grey levels), the smoothing is that of SciPy's
``gaussian_filter`` per channel (+-4 sigma, ``reflect`` border, rows then columns, each
pass rounded to the image's float type; run by :mod:`robopercept.imaging.filters`), a
colour image is segmented jointly with the colour distance above, the edges are listed right, down,
down-right, up-right and sorted with NumPy's default ``argsort``, so ties are visited in
the same order. The result is the same partition, and the same labels (numbered in
raster order of each segment's first pixel), as scikit-image's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from robopercept._checks import check_image, check_int, check_real
from robopercept.errors import InputError
from robopercept.imaging.blobs import uf_find
from robopercept.imaging.filters import separable_filter_unchecked

__all__ = ["MAX_PIXELS", "felzenszwalb", "grid_edges"]

#: most pixels of the grid graph (its edges take 64 bytes a pixel: 1 GiB at the cap)
MAX_PIXELS = 2**24


def _scipy_gaussian_kernel(sigma: float) -> np.ndarray:
    # scipy.ndimage.gaussian_filter's 1-D kernel: radius int(4 sigma + 0.5)
    radius = int(4.0 * sigma + 0.5)
    if radius == 0:  # sigma < 1/8: one tap (sigma * sigma may underflow to 0)
        return np.ones(1)
    x = np.arange(-radius, radius + 1)
    w = np.exp(-0.5 / (sigma * sigma) * x**2)
    return w / w.sum()


def _to_unit_float(image: np.ndarray) -> np.ndarray:
    # skimage.img_as_float: integers to [0, 1] float64, float32/float64 kept
    if image.dtype.kind == "f":
        return image
    if image.dtype.kind == "u":
        return image.astype(np.float64) / float(np.iinfo(image.dtype).max)
    if image.dtype.kind == "i":  # img_as_float maps signed integers to [-1, 1]
        return image.astype(np.float64) / float(np.iinfo(image.dtype).max)
    return image.astype(np.float64)


def _smooth(image: np.ndarray, sigma: float) -> np.ndarray:
    """Per-channel Gaussian smoothing as ``scipy.ndimage.gaussian_filter(image, [sigma,
    sigma, 0])`` (scikit-image's call): SciPy's kernel (radius ``int(4 sigma + 0.5)``) and
    ``reflect`` border, rows first, each pass summed in float64 and stored in the
    image's dtype, run by the project's separable filter engine."""
    if sigma <= 0.0:
        return image
    k = _scipy_gaussian_kernel(sigma)
    one = np.ones(1)
    out = image.astype(np.float64)
    for kx, ky in ((one, k), (k, one)):  # along y, then along x, as SciPy's axis order
        out = separable_filter_unchecked(out, kx, ky, "reflect").astype(image.dtype)
        out = out.astype(np.float64)
    return out.astype(image.dtype)


def grid_edges(shape: tuple[int, int]) -> np.ndarray:
    """The 8-connected grid graph of an ``(H, W)`` image as pixel-index pairs.

    Edges are listed as scikit-image lists them: all right neighbours, then down,
    down-right and up-right, each block in raster order; pixel ``(y, x)`` has index
    ``y * W + x``.

    Parameters
    ----------
    shape : (H, W)
        Image shape.

    Returns
    -------
    (E, 2) int64 ndarray
        ``E = H(W-1) + (H-1)W + 2(H-1)(W-1)`` edges.

    Raises
    ------
    InputError
        ``shape`` not two positive ints, or more than :data:`MAX_PIXELS` pixels.

    Examples
    --------
    >>> grid_edges((2, 2)).tolist()
    [[1, 0], [3, 2], [2, 0], [3, 1], [3, 0], [1, 2]]
    """
    if (
        not isinstance(shape, tuple)
        or len(shape) != 2
        or not all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in shape)
    ):
        raise InputError(f"shape must be a tuple (H, W) of ints; got {shape!r}")
    h, w = check_int(shape[0], "H", 1), check_int(shape[1], "W", 1)
    if h * w > MAX_PIXELS:
        raise InputError(
            f"shape {shape} has {h * w} pixels, more than the {MAX_PIXELS} (2**24) the "
            "graph of grid_edges/felzenszwalb may take: downscale the image"
        )
    idx = np.arange(h * w, dtype=np.int64).reshape(h, w)
    pairs = [
        (idx[:, 1:], idx[:, :-1]),  # right
        (idx[1:, :], idx[:-1, :]),  # down
        (idx[1:, 1:], idx[:-1, :-1]),  # down-right
        (idx[:-1, 1:], idx[1:, :-1]),  # up-right
    ]
    return np.concatenate([np.stack([a.ravel(), b.ravel()], axis=1) for a, b in pairs])


def _edge_costs(smooth: np.ndarray) -> np.ndarray:
    # the colour distance of each edge, in grid_edges' order, in the image's float type
    # (float32 images give float32 distances, as scikit-image), then as float64
    h, w = smooth.shape[:2]
    d = [
        smooth[:, 1:] - smooth[:, : w - 1],
        smooth[1:, :] - smooth[: h - 1, :],
        smooth[1:, 1:] - smooth[: h - 1, : w - 1],
        smooth[: h - 1, 1:] - smooth[1:, : w - 1],
    ]
    return np.hstack([np.sqrt(np.sum(x * x, axis=-1)).ravel() for x in d]).astype(np.float64)


@njit(cache=True, nogil=True)
def _fh_merge(edges, costs, params):  # pragma: no cover - compiled
    """The two passes over the sorted edges; ``params = (n_pixels, k, min_size)``.
    Returns each pixel's root (the smallest pixel index of its segment)."""
    n = int(params[0])
    k = params[1]
    min_size = params[2]
    parent = np.arange(n)
    size = np.ones(n, dtype=np.float64)
    inner = np.zeros(n, dtype=np.float64)
    for e in range(costs.size):
        a = uf_find(parent, edges[e, 0])
        b = uf_find(parent, edges[e, 1])
        if a == b:
            continue
        c = costs[e]
        if c < min(inner[a] + k / size[a], inner[b] + k / size[b]):
            r, o = (a, b) if a < b else (b, a)
            parent[o] = r
            size[r] = size[a] + size[b]
            inner[r] = c
    for e in range(costs.size):
        a = uf_find(parent, edges[e, 0])
        b = uf_find(parent, edges[e, 1])
        if a == b:
            continue
        if size[a] < min_size or size[b] < min_size:
            r, o = (a, b) if a < b else (b, a)
            parent[o] = r
            size[r] = size[a] + size[b]
    for i in range(n):
        parent[i] = uf_find(parent, i)
    return parent


def felzenszwalb(
    image: np.ndarray, scale: float = 1.0, sigma: float = 0.8, min_size: int = 20
) -> np.ndarray:
    r"""Felzenszwalb-Huttenlocher graph segmentation, as ``skimage.segmentation.felzenszwalb``.

    See the module docstring for the algorithm: 8-connected grid graph of the
    Gaussian-smoothed image, edge weight :math:`\lVert I_\sigma(p) - I_\sigma(q)
    \rVert_2` (colour images jointly), Kruskal-order merging while
    :math:`w < \min(\mathrm{Int}(C_i) + \tau(C_i))` with :math:`\tau(C) = (\mathrm{scale}
    / 255) / |C|` on the image in [0, 1], then merging of segments below ``min_size``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8, uint16 or float in [0, 1] (converted as ``skimage.img_as_float``).
    scale : float
        The observation scale ``k`` (>= 0) on 0..255 grey levels: larger gives fewer,
        larger segments.
    sigma : float
        Standard deviation (pixels, >= 0) of the Gaussian smoothing; 0 skips it.
    min_size : int
        Smallest segment size in pixels (>= 0), enforced by the second pass.

    Returns
    -------
    (H, W) int64 ndarray
        Segment labels ``0 .. n-1``, numbered in raster order of each segment's first
        pixel; equal to scikit-image's labels.

    Raises
    ------
    InputError
        A bad image (see ``check_image``), ``scale`` or ``sigma`` negative or not finite,
        ``min_size`` not a non-negative integer, more than :data:`MAX_PIXELS` pixels.

    Examples
    --------
    Two flat halves are two segments:

    >>> img = np.zeros((6, 8), np.uint8); img[:, 4:] = 200
    >>> felzenszwalb(img, scale=10, sigma=0, min_size=2)[0].tolist()
    [0, 0, 0, 0, 1, 1, 1, 1]
    """
    image = check_image(image)
    scale = check_real(scale, "scale", 0.0)
    sigma = check_real(sigma, "sigma", 0.0)
    min_size = check_int(min_size, "min_size", 0)
    if sigma > 1e4:
        raise InputError(
            f"sigma={sigma:g} asks for a Gaussian kernel of about {8 * sigma:.3g} taps; "
            "at most sigma=10000 is supported: smooth a downsampled image"
        )
    img = _to_unit_float(image)
    if img.ndim == 2:
        img = img[:, :, None]
    smooth = _smooth(img, sigma)
    h, w = img.shape[:2]
    edges = grid_edges((h, w))
    costs = _edge_costs(smooth)
    order = np.argsort(costs)  # NumPy's default kind, as scikit-image (tie order)
    params = np.array([h * w, scale / 255.0, float(min_size)])
    roots = _fh_merge(np.ascontiguousarray(edges[order]), costs[order], params)
    return np.unique(roots, return_inverse=True)[1].reshape(h, w).astype(np.int64)
