r"""Corner detection: the structure tensor, the Harris and Shi-Tomasi responses, corner
selection and subpixel refinement.

With image derivatives :math:`I_x, I_y` (Sobel, aperture ``ksize``) and a window
:math:`w(r)` of ``block_size`` pixels, the structure tensor at each pixel is

.. math::
    M = \sum_{r \in W} w(r) \begin{bmatrix} I_x^2 & I_x I_y \\ I_x I_y & I_y^2 \end{bmatrix}
      = \begin{bmatrix} A & B \\ B & C \end{bmatrix}.

Its eigenvalues :math:`\lambda_1 \ge \lambda_2` say how the window's brightness changes
when it shifts: both small on a flat patch, one large along an edge, both large at a
corner. The **Harris** response avoids the eigen-decomposition,

.. math:: R = \det M - k\,(\operatorname{tr} M)^2 = AC - B^2 - k (A + C)^2,

positive at corners, negative along edges, near zero on flat patches; **Shi-Tomasi**
keeps the smaller eigenvalue,
:math:`\lambda_2 = \tfrac{A + C}{2} - \sqrt{(\tfrac{A - C}{2})^2 + B^2}`.

Invariances: both are **rotation**-invariant (a rotation of the image rotates
:math:`M` by :math:`R M R^\top`, which keeps its eigenvalues), but not invariant to an
**intensity** scaling (:math:`I \to a I` multiplies :math:`R` by :math:`a^4`, so a fixed
absolute threshold keeps different corners; the relative ``threshold`` of
:func:`harris_corners` keeps the same ones) and not to **scale** (a corner seen larger
than the window looks like an edge).

OpenCV conventions, matched exactly: the derivatives are scaled by
:math:`1 / (2^{k_{size}-1} \cdot b \cdot 255)` for uint8 input (without the 255 for float
input), the box window is an unnormalized ``block_size`` sum anchored at
``block_size // 2``, borders are reflected (``reflect101``), and the arithmetic is
float32; :func:`harris_response` equals ``cv2.cornerHarris``,
:func:`min_eigenvalue` equals ``cv2.cornerMinEigenVal``, :func:`harris_corners` selects
the corners of ``cv2.goodFeaturesToTrack`` and :func:`refine_corners` implements
``cv2.cornerSubPix``.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numba import njit

from robopercept._checks import (
    check_choice,
    check_int,
    check_magnitude,
    check_numeric,
    check_range,
)
from robopercept.errors import InputError
from robopercept.features.keypoints import Keypoints
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.filters import (
    BORDERS,
    border_indices,
    box_filter,
    derivative_kernel,
    gaussian_blur,
    sobel,
)

__all__ = [
    "good_features_to_track",
    "harris_corners",
    "harris_response",
    "min_eigenvalue",
    "refine_corners",
    "structure_tensor",
]

Window = Literal["box", "gaussian"]


def _checked(
    image: np.ndarray, block_size: int, ksize: int, window: str, border: str
) -> tuple[np.ndarray, int, float]:
    # the gray image, the block size and the derivative scale (_scale)
    gray = rgb_to_gray(image)  # validates; gray input passes through
    # the response is of 4th order in the image (det M): refuse values whose 4th power
    # overflows (float32 on the fast path), as a typed error rather than NaN/inf inside
    gray = check_magnitude(gray, "image", 1e8 if gray.dtype == np.float32 else 1e60)
    block_size = check_int(block_size, "block_size", 1)
    if block_size > max(gray.shape[:2]):  # beyond it the window only repeats the image
        raise InputError(
            f"block_size must be at most the image's larger side, {max(gray.shape[:2])} "
            f"pixels; got {block_size}: use a window smaller than the image"
        )
    check_choice(window, "window", ("box", "gaussian"))
    check_choice(border, "border", BORDERS)
    if (
        not isinstance(ksize, (int, np.integer))
        or isinstance(ksize, bool)
        or ksize
        not in (
            1,
            3,
            5,
            7,
        )
    ):
        raise InputError(f"ksize must be 1, 3, 5 or 7; got {ksize!r}")
    return gray, block_size, _scale(gray.dtype, ksize, block_size)


def _scale(dtype: np.dtype, ksize: int, block_size: int) -> float:
    # OpenCV's derivative scale 1 / (2^(ksize - 1) * block_size [* 255 for uint8])
    s = float(1 << (ksize - 1)) * block_size
    return 1.0 / (s * 255.0 if dtype == np.uint8 else s)


def _fast_path(
    image: np.ndarray, block_size: int, ksize: int, window: str, border: str
) -> np.ndarray | None:
    # the gray image when the fused float32 box-window kernel applies (OpenCV's case:
    # uint8 or float32 input, box window), else None (then the composed filters run)
    gray, _, _ = _checked(image, block_size, ksize, window, border)
    if window != "box" or gray.dtype not in (np.uint8, np.float32):
        return None
    return gray


@njit(cache=True, nogil=True)
def _product_row(img, ridx, cidx, kd, ks, scale, y, sm, dv, gx, gy, pa, pb, pc):  # pragma: no cover
    # row y of A = gx^2, B = gx gy, C = gy^2: the separable Sobel pair (down the padded
    # rows ridx the smoothing and derivative kernels, then along the columns, padded
    # through cidx; -1 means zero), scaled. Inner loops run along contiguous rows.
    w = img.shape[1]
    nk = kd.shape[0]
    r = nk // 2
    wp = w + 2 * r
    zero = np.float32(0.0)
    for x in range(wp):
        sm[x] = zero
        dv[x] = zero
    for t in range(nk):
        yy = ridx[y + t]
        if yy < 0:
            continue
        a = ks[t]
        b = kd[t]
        row = img[yy]
        for x in range(w):
            v = row[x]
            sm[r + x] += a * v
            dv[r + x] += b * v
    for q in range(wp):  # the padded columns
        if q < r or q >= r + w:
            x = cidx[q]
            sm[q] = sm[r + x] if x >= 0 else zero
            dv[q] = dv[r + x] if x >= 0 else zero
    for x in range(w):
        gx[x] = zero
        gy[x] = zero
    for t in range(nk):
        a = kd[t]
        b = ks[t]
        for x in range(w):
            gx[x] += a * sm[x + t]
            gy[x] += b * dv[x + t]
    for x in range(w):
        u = gx[x] * scale
        v = gy[x] * scale
        pa[x] = u * u
        pb[x] = u * v
        pc[x] = v * v


@njit(cache=True, nogil=True)
def _box_response_kernel(
    img, ridx, cidx, kd, ks, scale, block, bidx_r, bidx_c, k, mode, out
):  # pragma: no cover - compiled
    # The structure tensor with a box window and its response, streamed row by row
    # (float32 throughout, like OpenCV): product rows (_product_row) are kept in a ring
    # of 2 block + 1 rows, computed when first needed; output row y sums the block rows
    # bidx_r[y .. y + block - 1] (anchored at block // 2, borders as the derivatives),
    # then the block columns, then mode 0: A C - B^2 - k (A + C)^2, mode 1: the smaller
    # eigenvalue. No image-sized temporary: only the output is allocated.
    h, w = img.shape
    r = kd.shape[0] // 2
    sm = np.empty(w + 2 * r, dtype=np.float32)
    dv = np.empty(w + 2 * r, dtype=np.float32)
    gx = np.empty(w, dtype=np.float32)
    gy = np.empty(w, dtype=np.float32)
    ring = 2 * block + 1
    prod = np.empty((ring, 3, w), dtype=np.float32)
    tag = np.full(ring, -1, dtype=np.int64)
    anchor = block // 2
    bw = w + block - 1
    col = np.empty((3, bw), dtype=np.float32)
    sa = np.empty(w, dtype=np.float32)
    sb = np.empty(w, dtype=np.float32)
    sc = np.empty(w, dtype=np.float32)
    zero = np.float32(0.0)
    kk = np.float32(k)
    half = np.float32(0.5)
    for y in range(h):
        for c in range(3):
            for x in range(bw):
                col[c, x] = zero
        for t in range(block):
            yy = bidx_r[y + t]
            if yy < 0:
                continue
            slot = yy % ring
            if tag[slot] != yy:
                _product_row(
                    img,
                    ridx,
                    cidx,
                    kd,
                    ks,
                    scale,
                    yy,
                    sm,
                    dv,
                    gx,
                    gy,
                    prod[slot, 0],
                    prod[slot, 1],
                    prod[slot, 2],
                )
                tag[slot] = yy
            for c in range(3):
                src = prod[slot, c]
                cc = col[c]
                for x in range(w):
                    cc[anchor + x] += src[x]
        for c in range(3):
            cc = col[c]
            for q in range(bw):
                if q < anchor or q >= anchor + w:
                    x = bidx_c[q]
                    cc[q] = cc[anchor + x] if x >= 0 else zero
        for x in range(w):
            sa[x] = zero
            sb[x] = zero
            sc[x] = zero
        for t in range(block):
            for x in range(w):
                sa[x] += col[0, x + t]
                sb[x] += col[1, x + t]
                sc[x] += col[2, x + t]
        orow = out[y]
        if mode == 0:
            for x in range(w):
                a = sa[x]
                b = sb[x]
                c2 = sc[x]
                orow[x] = a * c2 - b * b - kk * (a + c2) * (a + c2)
        else:
            for x in range(w):
                a = sa[x] * half
                b = sb[x]
                c2 = sc[x] * half
                d = a - c2
                orow[x] = (a + c2) - np.sqrt(d * d + b * b)


def _fast_response(
    gray: np.ndarray, block_size: int, ksize: int, k: float, mode: int, border: str
) -> np.ndarray:
    scale = _scale(gray.dtype, ksize, block_size)
    img = np.ascontiguousarray(gray, dtype=np.float32)
    kd = derivative_kernel(1, ksize).astype(np.float32)
    ks = derivative_kernel(0, ksize).astype(np.float32)
    if ks.shape[0] != kd.shape[0]:  # ksize 1: [1] smoothing vs a 3-tap difference
        ks = np.array([0.0, 1.0, 0.0], dtype=np.float32)
    h, w = img.shape
    r = kd.shape[0] // 2
    anchor = block_size // 2
    out = np.empty((h, w), dtype=np.float32)
    _box_response_kernel(
        img,
        border_indices(h, r, r, border),
        border_indices(w, r, r, border),
        kd,
        ks,
        np.float32(scale),
        block_size,
        border_indices(h, anchor, block_size - 1 - anchor, border),
        border_indices(w, anchor, block_size - 1 - anchor, border),
        k,
        mode,
        out,
    )
    return out


def structure_tensor(
    image: np.ndarray,
    block_size: int = 3,
    ksize: int = 3,
    *,
    window: Window = "box",
    sigma: float | None = None,
    border: str = "reflect101",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    r"""Entries :math:`A = \sum w I_x^2`, :math:`B = \sum w I_x I_y`, :math:`C = \sum w I_y^2`.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Colour is converted to gray (BT.601 luma) first.
    block_size : int
        Window side, >= 1. With ``window="box"`` the unnormalized sum over the
        ``block_size x block_size`` square anchored at ``block_size // 2`` (OpenCV's);
        with ``"gaussian"`` a normalized Gaussian of ``sigma`` (default
        ``0.3 ((block_size - 1) / 2 - 1) + 0.8``, OpenCV's rule for a kernel of that
        size) over ``block_size`` (odd) pixels, times ``block_size^2`` so that both
        windows give the same values on a constant gradient.
    ksize : {1, 3, 5, 7}
        Sobel aperture.
    window : {'box', 'gaussian'}
    sigma : float, optional
        Gaussian window only.
    border : {'reflect101', 'reflect', 'replicate', 'constant'}

    Returns
    -------
    A, B, C : (H, W) float32 ndarray
        (float64 for float64 input). Derivatives scaled as OpenCV scales them (see the
        module docstring).
    """
    gray, block_size, scale = _checked(image, block_size, ksize, window, border)
    gx = sobel(gray, 1, 0, ksize, scale=scale, border=border)
    gy = sobel(gray, 0, 1, ksize, scale=scale, border=border)
    # the three products as one 3-channel image: one separable pass filters all three
    prod = np.empty((*gx.shape, 3), dtype=gx.dtype)
    np.multiply(gx, gx, out=prod[..., 0])
    np.multiply(gx, gy, out=prod[..., 1])
    np.multiply(gy, gy, out=prod[..., 2])
    if window == "box":
        summed = box_filter(prod, block_size, normalize=False, border=border)
    else:
        if block_size % 2 == 0:
            raise InputError(f"a Gaussian window needs an odd block_size; got {block_size}")
        s = (
            0.3 * ((block_size - 1) * 0.5 - 1) + 0.8
            if sigma is None
            else check_range(sigma, "sigma", 0.0, low_inclusive=False)
        )
        summed = gaussian_blur(prod, s, ksize=block_size, border=border)
        summed *= summed.dtype.type(block_size * block_size)
    return summed[..., 0], summed[..., 1], summed[..., 2]


def harris_response(
    image: np.ndarray,
    block_size: int = 2,
    ksize: int = 3,
    k: float = 0.04,
    *,
    window: Window = "box",
    sigma: float | None = None,
    border: str = "reflect101",
) -> np.ndarray:
    r"""Harris corner measure :math:`R = \det M - k\,(\operatorname{tr} M)^2`.

    Equals ``cv2.cornerHarris(image, block_size, ksize, k)`` (float32 arithmetic, same
    scaling and border) with the default box window.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    block_size, ksize, window, sigma, border
        See :func:`structure_tensor`.
    k : float
        Harris' sensitivity, typically 0.04 to 0.06.

    Returns
    -------
    (H, W) float32 ndarray
        (float64 for float64 input).
    """
    k = check_range(k, "k")
    fast = _fast_path(image, block_size, ksize, window, border)
    if fast is not None:
        return _fast_response(fast, block_size, ksize, k, 0, border)
    a, b, c = structure_tensor(image, block_size, ksize, window=window, sigma=sigma, border=border)
    kk = a.dtype.type(k)
    tr = a + c
    out = a * c
    out -= b * b
    out -= kk * tr * tr
    return out


def min_eigenvalue(
    image: np.ndarray,
    block_size: int = 3,
    ksize: int = 3,
    *,
    window: Window = "box",
    sigma: float | None = None,
    border: str = "reflect101",
) -> np.ndarray:
    r"""Shi-Tomasi measure: the smaller eigenvalue of :math:`M`,
    :math:`\tfrac{A + C}{2} - \sqrt{(\tfrac{A - C}{2})^2 + B^2}`.

    Equals ``cv2.cornerMinEigenVal(image, block_size, ksize)`` with the default box
    window. Parameters as :func:`harris_response`.
    """
    fast = _fast_path(image, block_size, ksize, window, border)
    if fast is not None:
        return _fast_response(fast, block_size, ksize, 0.0, 1, border)
    a, b, c = structure_tensor(image, block_size, ksize, window=window, sigma=sigma, border=border)
    half = a.dtype.type(0.5)
    a = a * half
    c = c * half
    d = a - c
    return (a + c) - np.sqrt(d * d + b * b)


@njit(cache=True, nogil=True)
def _local_maxima(resp, thr):  # pragma: no cover - compiled
    # pixels (1 px away from the border) whose response is > thr and the largest of
    # their 3x3 neighbourhood, responses at or below thr counting as 0 (OpenCV's
    # threshold-to-zero, then dilate, then "val != 0 and val == dilated")
    h, w = resp.shape
    ys = []
    xs = []
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            v = resp[y, x]
            if not v > thr:
                continue
            best = v
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    u = resp[y + dy, x + dx]
                    if u > thr and u > best:
                        best = u
            if best == v:
                ys.append(y)
                xs.append(x)
    return np.array(ys, dtype=np.int64), np.array(xs, dtype=np.int64)


@njit(cache=True, nogil=True)
def _min_distance(xs, ys, width, height, min_distance, max_corners):  # pragma: no cover
    # greedy in the given (strongest first) order: keep a corner unless a kept one lies
    # closer than min_distance; kept corners are binned in square cells of
    # round(min_distance) pixels and only the 3x3 cells around are searched (OpenCV's)
    cell = max(1, int(np.floor(min_distance + 0.5)))
    gw = (width + cell - 1) // cell
    gh = (height + cell - 1) // cell
    # per-cell linked lists of kept corners
    head = np.full(gw * gh, -1, dtype=np.int64)
    nxt = np.full(xs.shape[0], -1, dtype=np.int64)
    md2 = min_distance * min_distance
    keep = np.zeros(xs.shape[0], dtype=np.bool_)
    n = 0
    for i in range(xs.shape[0]):
        x = xs[i]
        y = ys[i]
        cx = x // cell
        cy = y // cell
        good = True
        for yy in range(max(0, cy - 1), min(gh - 1, cy + 1) + 1):
            for xx in range(max(0, cx - 1), min(gw - 1, cx + 1) + 1):
                j = head[yy * gw + xx]
                while j >= 0:
                    dx = np.float32(x - xs[j])
                    dy = np.float32(y - ys[j])
                    if dx * dx + dy * dy < md2:
                        good = False
                        break
                    j = nxt[j]
                if not good:
                    break
            if not good:
                break
        if good:
            c = cy * gw + cx
            nxt[i] = head[c]
            head[c] = i
            keep[i] = True
            n += 1
            if max_corners > 0 and n == max_corners:
                break
    return keep


def harris_corners(
    image: np.ndarray,
    *,
    method: Literal["harris", "shi-tomasi"] = "harris",
    block_size: int = 3,
    ksize: int = 3,
    k: float = 0.04,
    threshold: float = 0.01,
    min_distance: float = 10.0,
    max_corners: int | None = None,
    subpixel: bool = False,
    window: Window = "box",
    sigma: float | None = None,
) -> Keypoints:
    r"""Strongest corners: thresholded local maxima of the response, spaced apart.

    1. The response (:func:`harris_response` or :func:`min_eigenvalue`).
    2. Candidates: pixels whose response exceeds ``threshold`` times the strongest
       response and is the maximum of its 3x3 neighbourhood (the outermost pixel ring
       excluded).
    3. Non-maximum suppression by distance: candidates from the strongest down, each kept
       unless a kept corner lies closer than ``min_distance`` pixels; stop at
       ``max_corners``.
    4. Optionally :func:`refine_corners` to subpixel positions.

    Steps 1-3 select exactly the corners of ``cv2.goodFeaturesToTrack(image,
    max_corners, threshold, min_distance, blockSize=block_size, gradientSize=ksize,
    useHarrisDetector=method == "harris", k=k)``, in the same order.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    method : {'harris', 'shi-tomasi'}
    block_size, ksize, k, window, sigma
        See :func:`harris_response`.
    threshold : float
        Relative quality level in (0, 1].
    min_distance : float
        Minimum distance between corners, pixels (0: no spacing).
    max_corners : int, optional
        Keep at most this many (None: all).
    subpixel : bool
        Refine positions with :func:`refine_corners` (5x5 half-window).

    Returns
    -------
    Keypoints
        ``scale = block_size``, ``orientation`` NaN, ``response`` the measure,
        ``octave`` 0; strongest first. Empty when the image has no corner (a constant
        image), never an exception.

    Examples
    --------
    The four corners of a bright 10x10 square:

    >>> img = np.zeros((20, 20), np.uint8); img[5:15, 5:15] = 255
    >>> sorted(harris_corners(img, min_distance=3).xy.tolist())
    [[5.0, 5.0], [5.0, 14.0], [14.0, 5.0], [14.0, 14.0]]
    """
    check_choice(method, "method", ("harris", "shi-tomasi"))
    threshold = check_range(threshold, "threshold", 0.0, 1.0, low_inclusive=False)
    min_distance = check_range(min_distance, "min_distance", 0.0)
    if max_corners is not None:
        max_corners = check_int(max_corners, "max_corners", 1)
    if method == "harris":
        resp = harris_response(image, block_size, ksize, k, window=window, sigma=sigma)
    else:
        resp = min_eigenvalue(image, block_size, ksize, window=window, sigma=sigma)
    vmax = float(resp.max())
    if not vmax > 0:
        return Keypoints.empty()
    thr = resp.dtype.type(vmax * threshold)
    ys, xs = _local_maxima(resp, thr)
    if ys.size == 0:
        return Keypoints.empty()
    vals = resp[ys, xs]
    # strongest first; ties: later in raster order first (OpenCV sorts pointers so)
    order = np.lexsort((-(ys * resp.shape[1] + xs), -vals))
    ys, xs, vals = ys[order], xs[order], vals[order]
    if min_distance >= 1:
        # (more corners than pixels is no bound: clamp to fit the kernel's int64)
        cap = min(max_corners, resp.size) if max_corners is not None else 0
        keep = _min_distance(xs, ys, resp.shape[1], resp.shape[0], float(min_distance), cap)
        ys, xs, vals = ys[keep], xs[keep], vals[keep]
    elif max_corners is not None:
        ys, xs, vals = ys[:max_corners], xs[:max_corners], vals[:max_corners]
    xy = np.column_stack([xs, ys]).astype(np.float64)
    if subpixel:
        xy = refine_corners(image, xy)
    n = xy.shape[0]
    return Keypoints(
        xy,
        np.full(n, float(block_size)),
        np.full(n, np.nan),
        vals.astype(np.float64),
        np.zeros(n, dtype=np.int64),
    )


@njit(cache=True, nogil=True)
def _subpix_kernel(img, pts, hw, hh, mask, max_iter, eps2, out):  # pragma: no cover
    h, w = img.shape
    win_w = 2 * hw + 1
    win_h = 2 * hh + 1
    buf = np.empty((win_h + 2, win_w + 2))
    for n in range(pts.shape[0]):
        cx0 = pts[n, 0]
        cy0 = pts[n, 1]
        cx = cx0
        cy = cy0
        for _ in range(max_iter):
            # bilinear patch of (win_h + 2) x (win_w + 2) centred on (cx, cy), borders
            # replicated (cv2.getRectSubPix)
            ox = cx - (win_w + 1) * 0.5
            oy = cy - (win_h + 1) * 0.5
            for i in range(win_h + 2):
                sy = oy + i
                y0 = math.floor(sy)
                fy = sy - y0
                ya = min(max(y0, 0), h - 1)
                yb = min(max(y0 + 1, 0), h - 1)
                for j in range(win_w + 2):
                    sx = ox + j
                    x0 = math.floor(sx)
                    fx = sx - x0
                    xa = min(max(x0, 0), w - 1)
                    xb = min(max(x0 + 1, 0), w - 1)
                    top = img[ya, xa] * (1 - fx) + img[ya, xb] * fx
                    bot = img[yb, xa] * (1 - fx) + img[yb, xb] * fx
                    buf[i, j] = top * (1 - fy) + bot * fy
            a = 0.0
            b = 0.0
            c = 0.0
            b1 = 0.0
            b2 = 0.0
            for i in range(win_h):
                py = i - hh
                for j in range(win_w):
                    m = mask[i, j]
                    tgx = buf[i + 1, j + 2] - buf[i + 1, j]
                    tgy = buf[i + 2, j + 1] - buf[i, j + 1]
                    gxx = tgx * tgx * m
                    gxy = tgx * tgy * m
                    gyy = tgy * tgy * m
                    px = j - hw
                    a += gxx
                    b += gxy
                    c += gyy
                    b1 += gxx * px + gxy * py
                    b2 += gxy * px + gyy * py
            det = a * c - b * b
            if abs(det) <= 2.220446049250313e-16**2:
                break
            s = 1.0 / det
            nx = cx + c * s * b1 - b * s * b2
            ny = cy - b * s * b1 + a * s * b2
            err = (nx - cx) ** 2 + (ny - cy) ** 2
            cx = nx
            cy = ny
            if cx < 0 or cx >= w or cy < 0 or cy >= h or err <= eps2:
                break
        if abs(cx - cx0) > hw or abs(cy - cy0) > hh:
            cx = cx0  # moved out of the window: poor convergence, keep the input
            cy = cy0
        out[n, 0] = cx
        out[n, 1] = cy


def good_features_to_track(
    image: np.ndarray,
    max_corners: int = 1000,
    quality: float = 0.01,
    min_distance: float = 5.0,
    block_size: int = 3,
) -> np.ndarray:
    r"""Shi-Tomasi corners as an ``(N, 2)`` array of ``(x, y)``, strongest first: the
    points Lucas-Kanade tracks best (a large smallest eigenvalue of the structure tensor).

    :func:`harris_corners` with ``method="shi-tomasi"`` on the gray image
    ``rgb_to_gray(image, dtype=np.float32)`` (unrounded luma, the input's scale; the
    quality level is relative, so the scale does not matter): the corners of
    ``cv2.goodFeaturesToTrack(gray, max_corners, quality, min_distance,
    blockSize=block_size)``, in the same order. Also exported as
    ``robopercept.motion.good_features_to_track``.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Any supported dtype; colour is converted to gray.
    max_corners : int
        Keep at most this many.
    quality : float
        Relative quality level in (0, 1]: corners weaker than ``quality`` times the
        strongest are dropped.
    min_distance : float
        Minimum distance between corners, pixels.
    block_size : int
        Side of the window of the structure tensor.

    Returns
    -------
    (N, 2) float64 ndarray

    Examples
    --------
    >>> import numpy as np
    >>> img = np.zeros((20, 20), np.uint8); img[5:15, 5:15] = 255
    >>> good_features_to_track(img, 4, 0.1, 3).tolist()  # the square's 4 corners
    [[14.0, 14.0], [5.0, 14.0], [14.0, 5.0], [5.0, 5.0]]
    """
    gray = rgb_to_gray(image, dtype=np.float32)
    kp = harris_corners(
        gray,
        method="shi-tomasi",
        block_size=block_size,
        threshold=quality,
        min_distance=min_distance,
        max_corners=max_corners,
    )
    return kp.xy


def _pair(value: int | tuple[int, int], name: str, minimum: int) -> tuple[int, int]:
    """An int or a pair of ints ``(x, y)``, each >= ``minimum``."""
    items = value.tolist() if isinstance(value, np.ndarray) else value
    if isinstance(items, (tuple, list)):
        if len(items) != 2:
            raise InputError(f"{name} must be an int or a pair (x, y) of ints; got {items!r}")
        return check_int(items[0], name, minimum), check_int(items[1], name, minimum)
    v = check_int(items, name, minimum)
    return v, v


def refine_corners(
    image: np.ndarray,
    corners: np.ndarray,
    window: int | tuple[int, int] = 5,
    *,
    zero_zone: int | tuple[int, int] = -1,
    max_iter: int = 40,
    eps: float = 0.001,
) -> np.ndarray:
    r"""Subpixel corner positions (Foerstner; ``cv2.cornerSubPix``).

    At the true corner :math:`q` every image gradient :math:`g_p` in the window is
    orthogonal to :math:`p - q` (on an edge the gradient is normal to it, in a flat
    region it vanishes), so :math:`q` solves the weighted least squares

    .. math::
        \Big(\sum_p w_p\, g_p g_p^\top\Big)\, q = \sum_p w_p\, g_p g_p^\top p,

    with Gaussian weights :math:`w_p = e^{-(p_x / h_x)^2 - (p_y / h_y)^2}` over the
    ``(2 h_x + 1) x (2 h_y + 1)`` window (zero inside ``zero_zone``), on a bilinearly
    resampled window re-centred at each iterate, until the step is below ``eps`` or
    after ``max_iter`` steps. A corner that wanders farther than the half-window keeps
    its input position.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
    corners : (N, 2) array_like
        Initial ``(x, y)``.
    window : int or (hx, hy)
        Half-size of the search window (OpenCV's ``winSize``).
    zero_zone : int or (zx, zy)
        Half-size of a dead zone in the middle (-1: none).
    max_iter : int
    eps : float
        Step length at which to stop, pixels.

    Returns
    -------
    (N, 2) float64 ndarray
    """
    gray = rgb_to_gray(image).astype(np.float64)
    pts = check_numeric(corners, "corners")
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise InputError(f"corners must be (N, 2) (x, y); got shape {pts.shape}")
    if not np.isfinite(pts).all():
        raise InputError(
            "corners must be finite; drop NaN/inf rows first: corners[np.isfinite(corners).all(1)]"
        )
    hw, hh = _pair(window, "window", 1)
    zx, zy = _pair(zero_zone, "zero_zone", -1)
    if zx >= hw or zy >= hh:
        raise InputError(
            f"zero_zone must be smaller than the window ({hw}, {hh}); got ({zx}, {zy}): "
            "use -1 for no dead zone"
        )
    if 2 * hw + 5 > gray.shape[1] or 2 * hh + 5 > gray.shape[0]:
        raise InputError(
            f"the {2 * hw + 1}x{2 * hh + 1} window needs an image of at least "
            f"{2 * hw + 5}x{2 * hh + 5}; got {gray.shape[1]}x{gray.shape[0]}"
        )
    max_iter = check_int(max_iter, "max_iter", 1)
    if max_iter > 2**31 - 1:  # the kernel counts in int64; OpenCV's maxCount is an int
        raise InputError(f"max_iter must be at most 2**31 - 1; got {max_iter}")
    eps = check_range(eps, "eps", 0.0)
    ry = np.arange(-hh, hh + 1) / hh
    rx = np.arange(-hw, hw + 1) / hw
    mask = np.exp(-(ry[:, None] ** 2)) * np.exp(-(rx[None, :] ** 2))
    if zx >= 0 and zy >= 0:
        mask[hh - zy : hh + zy + 1, hw - zx : hw + zx + 1] = 0
    out = np.empty_like(pts)
    if pts.shape[0]:
        _subpix_kernel(gray, pts, hw, hh, mask, max_iter, eps * eps, out)
    return out
