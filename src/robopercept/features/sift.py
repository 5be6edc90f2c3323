r"""Scale-invariant feature transform (Lowe, 2004).

The pipeline, with OpenCV's ``cv2.SIFT_create()`` defaults:

1. **Base image.** The gray image (values 0..255, float32) is doubled in size by
   bilinear interpolation (the camera blur of 0.5 px becomes 1 px) and blurred to
   :math:`\sigma_0 = 1.6`: :math:`\sqrt{1.6^2 - 1^2}` more.
2. **Scale space.** Octaves of :math:`s + 3` images (:math:`s = 3` scales per octave),
   image :math:`i` blurred to :math:`\sigma_0 k^i`, :math:`k = 2^{1/s}`, each from the
   previous one by :math:`\sqrt{(\sigma_0 k^i)^2 - (\sigma_0 k^{i-1})^2}`; the next octave
   starts from image :math:`s` (twice the base blur) taking every second pixel; as many
   octaves as leave an image of at least about 8 pixels.
3. **Difference of Gaussians** :math:`D_i = L_{i+1} - L_i`, an approximation of the
   scale-normalized Laplacian :math:`(k - 1)\sigma^2 \nabla^2 G`.
4. **Extrema** of :math:`D` among the 26 neighbours in space and scale (ties count),
   with :math:`|D| > 0.5 \cdot 0.04 / s \cdot 255`, 5 pixels from the border.
5. **Refinement.** A quadratic fit :math:`D(x) \approx D + \nabla D^\top x +
   \tfrac12 x^\top H x` gives the offset :math:`\hat x = -H^{-1} \nabla D`; while an
   offset exceeds 0.5 the sample moves (at most 5 times). Rejected: low contrast,
   :math:`|D(\hat x)| \cdot s < 0.04` (values on the 0..1 scale), and edges,
   :math:`\operatorname{tr}(H)^2 / \det H \ge (r + 1)^2 / r` with :math:`r = 10`
   (or :math:`\det H \le 0`).
6. **Orientation.** A 36-bin histogram of gradient orientations within
   :math:`3 \times 1.5\sigma` weighted by magnitude and a Gaussian of
   :math:`1.5\sigma`, smoothed by :math:`[1, 4, 6, 4, 1] / 16`; every peak above 80% of
   the highest gives a keypoint, its angle refined by a parabola through the peak.
7. **Descriptor.** Gradients within the rotated :math:`4 \times 4` grid of
   :math:`3\sigma`-wide cells, weighted by a Gaussian of half the grid width, each
   magnitude spread trilinearly over the two nearest cells in x, in y and the two
   nearest of 8 orientation bins; the 128 values are normalized, clamped at 0.2,
   renormalized and scaled by 512 (rounded to 0..255 as OpenCV does; float32 keeps
   those integers, ``descriptor_dtype=np.uint8`` stores them in bytes).

OpenCV's conventions are kept so the two can be swapped: positions on the input image
with pixel centres at integers (OpenCV's positions are 0.25 px too far right and down:
it halves the doubled image's coordinates although doubled pixel :math:`c` lies at
:math:`c/2 - 1/4`; ours are OpenCV's minus 0.25), ``scale`` = OpenCV's
``KeyPoint.size`` (the diameter :math:`2\sigma` in input pixels), ``orientation`` =
OpenCV's ``KeyPoint.angle`` converted to RADIANS (from +x towards +y, image down;
``Keypoints[i].angle``, the :class:`~robopercept.features.keypoints.KeyPoint` record,
gives it in degrees as OpenCV), ``response`` = :math:`|D(\hat x)|`, octave -1 for the
doubled image (OpenCV's packed ``KeyPoint.octave`` read as a signed byte).

The result unpacks as ``detectAndCompute``'s: ``kp, des = sift(img)`` as
``kp, des = cv2.SIFT_create().detectAndCompute(img, None)``, and ``kp[0].pt`` is
keypoint 0's ``(x, y)`` as ``cv2.KeyPoint.pt``.
Gradient angles use OpenCV's polynomial ``atan2``.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from robopercept._checks import check_bool, check_int, check_real
from robopercept.errors import InputError
from robopercept.features._atan import atan2_deg
from robopercept.features.keypoints import Keypoints
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.filters import gaussian_kernel, separable_filter_unchecked

__all__ = ["Features", "sift"]

_BORDER = 5  # SIFT_IMG_BORDER
_MAX_STEPS = 5  # refinement moves
_ORI_BINS = 36
_MAX_LAYERS = 32  # n_octave_layers: (layers + 3) Gaussian images per octave
_ORI_SIG = 1.5
_ORI_RADIUS = 3.0 * _ORI_SIG
_ORI_PEAK = 0.8
_D = 4  # descriptor grid
_N = 8  # descriptor orientation bins
_DESCR_SCL = 3.0
_DESCR_THR = 0.2
_DESCR_FCTR = 512.0
# the smallest image (the doubled base's shorter side) that gives one octave with a
# pixel inside the 5-pixel border
MIN_SIZE = 6


@dataclass(frozen=True)
class Features:
    """Keypoints and their descriptors, row i describing keypoint i.

    It unpacks as the tuple of ``kp, des = cv2.SIFT_create().detectAndCompute(img,
    None)``: ``kp, des = sift(img)`` gives the :class:`Keypoints` (``kp[0].pt``,
    ``kp[0].angle`` in degrees, ``for k in kp``, as OpenCV's tuple of ``cv2.KeyPoint``)
    and the ``(N, 128)`` descriptors. The attributes stay the primary interface;
    ``len(features)`` is the number of keypoints (OpenCV has no such call), while
    unpacking always gives the two parts. With no keypoint, ``des`` is an empty
    ``(0, 128)`` array where OpenCV returns None.

    Attributes
    ----------
    keypoints : Keypoints
    descriptors : (N, D) ndarray

    Examples
    --------
    >>> y, x = np.mgrid[0:64, 0:64]
    >>> img = (200 * np.exp(-((x - 32) ** 2 + (y - 30) ** 2) / 50.0)).astype(np.uint8)
    >>> kp, des = sift(img)
    >>> [round(v) for v in kp[0].pt], des.shape[1]
    ([32, 30], 128)
    """

    keypoints: Keypoints
    descriptors: np.ndarray

    def __len__(self) -> int:
        return len(self.keypoints)

    def __iter__(self) -> Iterator[Keypoints | np.ndarray]:
        """``keypoints, descriptors``: the order of ``cv2.Feature2D.detectAndCompute``."""
        return iter((self.keypoints, self.descriptors))


# ------------------------------------------------------------------------ scale space


@njit(cache=True, nogil=True, parallel=True)
def _upsample2(src, dst):  # pragma: no cover - compiled
    # bilinear doubling with pixel centres aligned (cv2.resize INTER_LINEAR, fx = fy =
    # 2): dst(2i) = 0.25 src(i-1) + 0.75 src(i), dst(2i+1) = 0.75 src(i) + 0.25 src(i+1),
    # edges replicated
    h, w = src.shape
    a = np.float32(0.25)
    b = np.float32(0.75)
    for yy in prange(2 * h):
        i = yy >> 1
        j = i - 1 if (yy & 1) == 0 else i + 1
        j = min(max(j, 0), h - 1)
        for xx in range(2 * w):
            k = xx >> 1
            m = k - 1 if (xx & 1) == 0 else k + 1
            m = min(max(m, 0), w - 1)
            top = b * src[i, k] + a * src[i, m]
            bot = b * src[j, k] + a * src[j, m]
            dst[yy, xx] = b * top + a * bot


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    # gaussian_blur(img, sigma, ksize=...) without re-validating img on every layer;
    # OpenCV's kernel size for float images: round(8 sigma + 1), made odd
    k = gaussian_kernel(sigma, round(sigma * 8 + 1) | 1)
    return separable_filter_unchecked(img, k, k, "reflect101")


def _pyramid(
    base: np.ndarray, n_octaves: int, layers: int, sigma: float
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    # Gaussian octaves (layers + 3, h, w) and their differences (layers + 2, h, w)
    k = 2.0 ** (1.0 / layers)
    steps = [sigma]
    for i in range(1, layers + 3):
        prev = sigma * k ** (i - 1)
        steps.append(math.sqrt((prev * k) ** 2 - prev**2))
    gauss, dogs = [], []
    for o in range(n_octaves):
        h, w = base.shape if o == 0 else gauss[o - 1][layers][::2, ::2].shape
        g = np.empty((layers + 3, h, w), np.float32)
        g[0] = base if o == 0 else gauss[o - 1][layers][::2, ::2]
        for i in range(1, layers + 3):
            g[i] = _blur(g[i - 1], steps[i])
        gauss.append(g)
        dogs.append(g[1:] - g[:-1])
    return gauss, dogs


# -------------------------------------------------------------------------- detection


@njit(cache=True, nogil=True)
def _solve3(h, g):  # pragma: no cover - compiled
    # x with h x = g by Cramer's rule; ok False when h is singular
    a, b, c = h[0, 0], h[0, 1], h[0, 2]
    d, e, f = h[1, 0], h[1, 1], h[1, 2]
    p, q, r = h[2, 0], h[2, 1], h[2, 2]
    det = a * (e * r - f * q) - b * (d * r - f * p) + c * (d * q - e * p)
    x = np.zeros(3)
    if det == 0.0 or not np.isfinite(det):
        return x, False
    x[0] = (g[0] * (e * r - f * q) - b * (g[1] * r - f * g[2]) + c * (g[1] * q - e * g[2])) / det
    x[1] = (a * (g[1] * r - f * g[2]) - g[0] * (d * r - f * p) + c * (d * g[2] - g[1] * p)) / det
    x[2] = (a * (e * g[2] - g[1] * q) - b * (d * g[2] - g[1] * p) + g[0] * (d * q - e * p)) / det
    return x, True


@njit(cache=True, nogil=True)
def _derivatives(dog, s, r, c, grad, hess):  # pragma: no cover - compiled
    # gradient and Hessian of D at (s, r, c) by central differences, values on 0..1
    img_scale = 1.0 / 255.0
    ds = img_scale * 0.5
    ss = img_scale
    cs = img_scale * 0.25
    cur = dog[s]
    prv = dog[s - 1]
    nxt = dog[s + 1]
    v2 = 2.0 * cur[r, c]
    grad[0] = (cur[r, c + 1] - cur[r, c - 1]) * ds
    grad[1] = (cur[r + 1, c] - cur[r - 1, c]) * ds
    grad[2] = (nxt[r, c] - prv[r, c]) * ds
    dxx = (cur[r, c + 1] + cur[r, c - 1] - v2) * ss
    dyy = (cur[r + 1, c] + cur[r - 1, c] - v2) * ss
    dss = (nxt[r, c] + prv[r, c] - v2) * ss
    dxy = (cur[r + 1, c + 1] - cur[r + 1, c - 1] - cur[r - 1, c + 1] + cur[r - 1, c - 1]) * cs
    dxs = (nxt[r, c + 1] - nxt[r, c - 1] - prv[r, c + 1] + prv[r, c - 1]) * cs
    dys = (nxt[r + 1, c] - nxt[r - 1, c] - prv[r + 1, c] + prv[r - 1, c]) * cs
    hess[0, 0] = dxx
    hess[0, 1] = dxy
    hess[0, 2] = dxs
    hess[1, 0] = dxy
    hess[1, 1] = dyy
    hess[1, 2] = dys
    hess[2, 0] = dxs
    hess[2, 1] = dys
    hess[2, 2] = dss


@njit(cache=True, nogil=True)
def _is_extremum(dog, s, r, c, val):  # pragma: no cover - compiled
    # val >= all 26 neighbours (val > 0) or <= all of them (val < 0); the same layer
    # first, where most candidates fail
    if val > 0:
        for ds in (0, -1, 1):
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dog[s + ds, r + dr, c + dc] > val:
                        return False
        return True
    for ds in (0, -1, 1):
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dog[s + ds, r + dr, c + dc] < val:
                    return False
    return True


@njit(cache=True, nogil=True)
def _refine(dog, layers, s, r, c, contrast, edge, out):  # pragma: no cover - compiled
    # Lowe's quadratic refinement; fills out = (r, c, layer, xr, xc, xi, |contrast|) and
    # returns True when the extremum survives the contrast and edge tests
    h, w = dog.shape[1], dog.shape[2]
    grad = np.empty(3)
    hess = np.empty((3, 3))
    xc = xr = xi = 0.0
    step = 0
    while step < _MAX_STEPS:
        _derivatives(dog, s, r, c, grad, hess)
        x, ok = _solve3(hess, grad)
        if not ok:
            return False
        xc, xr, xi = -x[0], -x[1], -x[2]
        if abs(xi) < 0.5 and abs(xr) < 0.5 and abs(xc) < 0.5:
            break
        if abs(xi) > 7e8 or abs(xr) > 7e8 or abs(xc) > 7e8:
            return False
        c += round(xc)
        r += round(xr)
        s += round(xi)
        if (
            s < 1
            or s > layers
            or c < _BORDER
            or c >= w - _BORDER
            or r < _BORDER
            or r >= h - _BORDER
        ):
            return False
        step += 1
    if step >= _MAX_STEPS:
        return False
    _derivatives(dog, s, r, c, grad, hess)
    t = grad[0] * xc + grad[1] * xr + grad[2] * xi
    contr = dog[s, r, c] / 255.0 + t * 0.5
    if abs(contr) * layers < contrast:
        return False
    tr = hess[0, 0] + hess[1, 1]
    det = hess[0, 0] * hess[1, 1] - hess[0, 1] * hess[0, 1]
    if det <= 0 or tr * tr * edge >= (edge + 1) * (edge + 1) * det:
        return False
    out[0] = r
    out[1] = c
    out[2] = s
    out[3] = xr
    out[4] = xc
    out[5] = xi
    out[6] = abs(contr)
    return True


@njit(cache=True, nogil=True)
def _scan_row(dog, layers, s, r, threshold, contrast, edge, out):  # pragma: no cover
    # the refined extrema of row r of DoG layer s, rows of (r, c, layer, xr, xc, xi,
    # response) written to out as far as it holds them; returns how many there are
    w = dog.shape[2]
    cur = dog[s, r]
    buf = np.empty(7)
    n = 0
    for c in range(_BORDER, w - _BORDER):
        val = cur[c]
        if abs(val) > threshold and _is_extremum(dog, s, r, c, val):
            if _refine(dog, layers, s, r, c, contrast, edge, buf):
                if n < out.shape[0]:
                    out[n] = buf
                n += 1
    return n


@njit(cache=True, nogil=True, parallel=True)
def _scan_rows(dog, layers, threshold, contrast, edge, store, counts):  # pragma: no cover
    # every scanned row (layers 1..s, rows inside the border) in parallel
    rows = dog.shape[1] - 2 * _BORDER
    for t in prange(counts.shape[0]):
        s = 1 + t // rows
        r = _BORDER + t % rows
        counts[t] = _scan_row(dog, layers, s, r, threshold, contrast, edge, store[t])


_ROW_CAP = 16  # extrema kept per row by the parallel scan; fuller rows are rescanned


def _find_extrema(
    dog: np.ndarray, layers: int, threshold: float, contrast: float, edge: float
) -> np.ndarray:
    # every refined extremum of one octave in (layer, row, column) order, (K, 7)
    rows = max(dog.shape[1] - 2 * _BORDER, 0)
    nscan = layers * rows
    store = np.empty((nscan, _ROW_CAP, 7))
    counts = np.zeros(nscan, np.int64)
    if nscan:
        _scan_rows(dog, layers, threshold, contrast, edge, store, counts)
    if (counts <= _ROW_CAP).all():
        t_idx = np.repeat(np.arange(nscan), counts)
        i_idx = np.arange(t_idx.size) - np.repeat(np.cumsum(counts) - counts, counts)
        return store[t_idx, i_idx]
    parts = []
    for t in np.flatnonzero(counts):
        if counts[t] <= _ROW_CAP:
            parts.append(store[t, : counts[t]])
        else:
            full = np.empty((counts[t], 7))
            s, r = 1 + t // rows, _BORDER + t % rows
            _scan_row(dog, layers, s, r, threshold, contrast, edge, full)
            parts.append(full)
    return np.concatenate(parts)


# ------------------------------------------------------------------------ orientation


@njit(cache=True, nogil=True)
def _orientation_hist(img, x, y, radius, sigma, hist, tmp):  # pragma: no cover
    # 36-bin histogram of gradient angles (up-positive y, degrees, OpenCV's atan2)
    # around integer (x, y), Gaussian-weighted, then smoothed by [1 4 6 4 1] / 16;
    # returns its maximum
    n = _ORI_BINS
    rows, cols = img.shape
    expf = -1.0 / (2.0 * sigma * sigma)
    for k in range(n):
        tmp[k] = 0.0
    for i in range(-radius, radius + 1):
        yy = y + i
        if yy <= 0 or yy >= rows - 1:
            continue
        for j in range(-radius, radius + 1):
            xx = x + j
            if xx <= 0 or xx >= cols - 1:
                continue
            dx = img[yy, xx + 1] - img[yy, xx - 1]
            dy = img[yy - 1, xx] - img[yy + 1, xx]
            wgt = math.exp((i * i + j * j) * expf)
            ori = atan2_deg(dy, dx)
            mag = math.sqrt(dx * dx + dy * dy)
            b = round(np.float32(n / 360.0) * ori)
            if b >= n:
                b -= n
            if b < 0:
                b += n
            tmp[b] += np.float32(wgt * mag)
    top = 0.0
    for k in range(n):
        v = (tmp[(k - 2) % n] + tmp[(k + 2) % n]) * (1.0 / 16.0)
        v += (tmp[(k - 1) % n] + tmp[(k + 1) % n]) * (4.0 / 16.0) + tmp[k] * (6.0 / 16.0)
        hist[k] = v
        top = max(top, v)
    return top


@njit(cache=True, nogil=True, parallel=True)
def _orientations(gauss, kp, sigma, layers, angles, counts):  # pragma: no cover
    # up to 36 orientations per refined extremum kp[i] = (r, c, layer, xr, xc, xi, resp):
    # every histogram peak above 80% of the highest, refined by a parabola; the angle
    # is OpenCV's KeyPoint.angle in degrees
    n = _ORI_BINS
    for i in prange(kp.shape[0]):
        r, c, s = int(kp[i, 0]), int(kp[i, 1]), int(kp[i, 2])
        scl = sigma * 2.0 ** ((s + kp[i, 5]) / layers)
        hist = np.empty(n)
        tmp = np.empty(n)
        top = _orientation_hist(gauss[s], c, r, round(_ORI_RADIUS * scl), _ORI_SIG * scl, hist, tmp)
        thr = top * _ORI_PEAK
        m = 0
        for j in range(n):
            left = hist[j - 1 if j > 0 else n - 1]
            right = hist[j + 1 if j < n - 1 else 0]
            if hist[j] > left and hist[j] > right and hist[j] >= thr:
                b = j + 0.5 * (left - right) / (left - 2.0 * hist[j] + right)
                if b < 0:
                    b += n
                elif b >= n:
                    b -= n
                a = 360.0 - (360.0 / n) * b
                if abs(a - 360.0) < 1.1920929e-07:
                    a = 0.0
                angles[i, m] = a
                m += 1
        counts[i] = m


# ------------------------------------------------------------------------- descriptor


@njit(cache=True, nogil=True)
def _descriptor(img, px, py, angle, scl, hist, dst):  # pragma: no cover - compiled
    # Lowe's 4x4x8 descriptor at (px, py) (octave pixels) for a keypoint of scale scl
    # and OpenCV angle `angle` (degrees): trilinear votes, normalize, clamp, scale
    d, n = _D, _N
    rows, cols = img.shape
    x0 = round(px)
    y0 = round(py)
    ori = np.float32(360.0) - np.float32(angle)
    if abs(ori - 360.0) < 1.1920929e-07:
        ori = np.float32(0.0)
    cos_t = np.float32(math.cos(ori * math.pi / 180.0))
    sin_t = np.float32(math.sin(ori * math.pi / 180.0))
    bins_per_deg = np.float32(n / 360.0)
    exp_scale = -1.0 / (d * d * 0.5)
    hist_width = np.float32(_DESCR_SCL * scl)
    radius = round(hist_width * 1.4142135623730951 * (d + 1) * 0.5)
    radius = min(radius, int(math.sqrt(float(cols) * cols + float(rows) * rows)))
    cos_t = cos_t / hist_width
    sin_t = sin_t / hist_width
    for k in range(hist.shape[0]):
        hist[k] = 0.0
    half = d // 2 - 0.5
    for i in range(-radius, radius + 1):
        r = y0 + i
        if r <= 0 or r >= rows - 1:
            continue
        for j in range(-radius, radius + 1):
            c_rot = j * cos_t - i * sin_t
            r_rot = j * sin_t + i * cos_t
            rbin = r_rot + half
            cbin = c_rot + half
            c = x0 + j
            if rbin <= -1 or rbin >= d or cbin <= -1 or cbin >= d or c <= 0 or c >= cols - 1:
                continue
            dx = img[r, c + 1] - img[r, c - 1]
            dy = img[r - 1, c] - img[r + 1, c]
            wgt = math.exp((c_rot * c_rot + r_rot * r_rot) * exp_scale)
            obin = (atan2_deg(dy, dx) - ori) * bins_per_deg
            mag = np.float32(math.sqrt(dx * dx + dy * dy) * wgt)
            r0 = math.floor(rbin)
            c0 = math.floor(cbin)
            o0 = math.floor(obin)
            rb = rbin - r0
            cb = cbin - c0
            ob = obin - o0
            if o0 < 0:
                o0 += n
            if o0 >= n:
                o0 -= n
            v_r1 = mag * rb
            v_r0 = mag - v_r1
            v_rc11 = v_r1 * cb
            v_rc10 = v_r1 - v_rc11
            v_rc01 = v_r0 * cb
            v_rc00 = v_r0 - v_rc01
            v111 = v_rc11 * ob
            v110 = v_rc11 - v111
            v101 = v_rc10 * ob
            v100 = v_rc10 - v101
            v011 = v_rc01 * ob
            v010 = v_rc01 - v011
            v001 = v_rc00 * ob
            v000 = v_rc00 - v001
            idx = ((r0 + 1) * (d + 2) + c0 + 1) * (n + 2) + o0
            hist[idx] += v000
            hist[idx + 1] += v001
            hist[idx + (n + 2)] += v010
            hist[idx + (n + 3)] += v011
            hist[idx + (d + 2) * (n + 2)] += v100
            hist[idx + (d + 2) * (n + 2) + 1] += v101
            hist[idx + (d + 3) * (n + 2)] += v110
            hist[idx + (d + 3) * (n + 2) + 1] += v111
    # fold the circular orientation overflow and drop the spatial padding
    nrm2 = 0.0
    for i in range(d):
        for j in range(d):
            idx = ((i + 1) * (d + 2) + (j + 1)) * (n + 2)
            hist[idx] += hist[idx + n]
            hist[idx + 1] += hist[idx + n + 1]
            for k in range(n):
                v = hist[idx + k]
                dst[(i * d + j) * n + k] = v
                nrm2 += v * v
    thr = np.float32(math.sqrt(nrm2) * _DESCR_THR)
    nrm2 = 0.0
    for k in range(d * d * n):
        v = min(dst[k], thr)
        dst[k] = v
        nrm2 += v * v
    scale = _DESCR_FCTR / max(math.sqrt(nrm2), 1.1920929e-07)
    for k in range(d * d * n):
        dst[k] = min(max(round(dst[k] * scale), 0.0), 255.0)


@njit(cache=True, nogil=True, parallel=True)
def _descriptors(gauss, layer, px, py, angle, scl, out):  # pragma: no cover - compiled
    hlen = (_D + 2) * (_D + 2) * (_N + 2)
    for i in prange(px.shape[0]):
        hist = np.empty(hlen, np.float32)
        _descriptor(gauss[layer[i]], px[i], py[i], angle[i], scl[i], hist, out[i])


# ----------------------------------------------------------------------------- public


def sift(
    image: np.ndarray,
    *,
    n_features: int = 0,
    n_octave_layers: int = 3,
    contrast_threshold: float = 0.04,
    edge_threshold: float = 10.0,
    sigma: float = 1.6,
    upsample: bool = True,
    descriptor_dtype: type = np.float32,
) -> Features:
    """Detect SIFT keypoints and compute their 128-D descriptors.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 image, uint16 (scaled by 255 / 65535) or float in [0, 1] (scaled by 255):
        the thresholds are written for the 0..255 scale; colour is converted to gray
        first.
    n_features : int
        Keep the strongest ``n_features`` (by response; ties with the last are kept, as
        OpenCV's ``retainBest``); 0 keeps all.
    n_octave_layers : int
        Scales per octave :math:`s` (3).
    contrast_threshold : float
        Minimum :math:`|D(\\hat x)| \\cdot s` on the 0..1 scale (0.04).
    edge_threshold : float
        Maximum principal-curvature ratio :math:`r` (10).
    sigma : float
        Blur of the base image (1.6).
    upsample : bool
        Double the image first (Lowe's and OpenCV's default; about 4x the keypoints
        at small scales).
    descriptor_dtype : {numpy.float32, numpy.uint8}
        Descriptor storage; the values are the same integers 0..255.

    Returns
    -------
    Features
        ``keypoints`` (strongest first; see the module docstring for the units:
        ``keypoints.orientation`` in radians, ``keypoints[i].angle`` in degrees as
        ``cv2.KeyPoint.angle``) and ``descriptors`` (N, 128). No keypoints give empty
        arrays. Unpacks as ``kp, des = sift(img)``, OpenCV's
        ``detectAndCompute`` order.

    Raises
    ------
    InputError
        If the image is smaller than 6x6 pixels (12x12 without ``upsample``): no octave
        would hold a pixel away from the 5-pixel border, or a parameter is invalid
        (not a number, out of range, ``n_octave_layers`` beyond 32, ``sigma`` beyond the
        image's larger side).

    Notes
    -----
    Follows ``cv2.SIFT_create()`` step by step (module docstring); on the Oxford
    affine sequences it finds about the same keypoints and matches (``docs/features.md``).
    """
    gray = rgb_to_gray(image)  # validates; gray input passes through
    n_features = check_int(n_features, "n_features", 0)
    layers = check_int(n_octave_layers, "n_octave_layers", 1)
    if layers > _MAX_LAYERS:  # each layer is two more images per octave
        raise InputError(
            f"n_octave_layers must be at most {_MAX_LAYERS}; got {layers}: SIFT uses 3"
        )
    contrast = check_real(contrast_threshold, "contrast_threshold", 0.0)
    edge = check_real(edge_threshold, "edge_threshold", 0.0, low_inclusive=False)
    sigma = check_real(sigma, "sigma", 0.0, low_inclusive=False)
    if sigma > max(gray.shape):  # the blur kernel (8 sigma + 1 taps) would exceed the image
        raise InputError(
            f"sigma must be at most the image's larger side, {max(gray.shape)} pixels; "
            f"got {sigma}: SIFT uses 1.6"
        )
    upsample = check_bool(upsample, "upsample")
    if np.dtype(descriptor_dtype) not in (np.dtype(np.float32), np.dtype(np.uint8)):
        raise InputError(
            f"descriptor_dtype must be np.float32 or np.uint8; got {descriptor_dtype!r}"
        )
    h, w = gray.shape
    need = MIN_SIZE if upsample else 2 * MIN_SIZE
    if min(h, w) < need:
        raise InputError(
            f"SIFT needs an image of at least {need}x{need} pixels"
            f"{'' if upsample else ' without upsample'}; got {h}x{w}"
        )
    img = gray.astype(np.float32)
    if gray.dtype.kind == "f":
        img *= np.float32(255.0)
    elif gray.dtype != np.uint8:
        img *= np.float32(255.0 / np.iinfo(gray.dtype).max)
    first = -1 if upsample else 0
    shift = 0.25 if upsample else 0.0
    if upsample:
        big = np.empty((2 * h, 2 * w), np.float32)
        _upsample2(np.ascontiguousarray(img), big)
        base = _blur(big, math.sqrt(max(sigma * sigma - 1.0, 0.01)))
    else:
        base = _blur(img, math.sqrt(max(sigma * sigma - 0.25, 0.01)))
    n_oct = max(round(math.log2(min(base.shape)) - 2) - first, 1)
    gauss, dogs = _pyramid(base, n_oct, layers, sigma)
    # (no |D| reaches a threshold beyond 2**53: any larger one keeps no keypoint)
    threshold = math.floor(min(0.5 * contrast / layers * 255.0, 2.0**53))

    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("x", "y", "size", "ang", "resp", "oct")}
    desc_parts: list[np.ndarray] = []
    for o in range(n_oct):
        kp = _find_extrema(dogs[o], layers, threshold, contrast, edge)
        if kp.shape[0] == 0:
            continue
        angles = np.zeros((kp.shape[0], _ORI_BINS))
        counts = np.zeros(kp.shape[0], np.int64)
        _orientations(gauss[o], kp, sigma, layers, angles, counts)
        rep = np.repeat(np.arange(kp.shape[0]), counts)
        ang = angles[np.arange(_ORI_BINS)[None, :] < counts[:, None]].astype(np.float32)
        kp = kp[rep]
        unit = np.float32(2.0**o)
        half = np.float32(2.0**first)
        x = (kp[:, 1] + kp[:, 4]).astype(np.float32) * unit * half
        y = (kp[:, 0] + kp[:, 3]).astype(np.float32) * unit * half
        size = (
            (
                np.float32(sigma)
                * np.float32(2.0) ** ((kp[:, 2] + kp[:, 5]) / layers).astype(np.float32)
            )
            * unit
            * np.float32(2.0)
            * half
        )
        # the descriptor works in this octave's pixels (OpenCV rescales the stored point)
        back = np.float32(2.0 ** (-(o + first)))
        desc = np.zeros((kp.shape[0], _D * _D * _N), np.float32)
        _descriptors(
            gauss[o],
            kp[:, 2].astype(np.int64),
            (x * back).astype(np.float64),
            (y * back).astype(np.float64),
            ang.astype(np.float64),
            (size * back * np.float32(0.5)).astype(np.float64),
            desc,
        )
        # OpenCV halves the doubled image's coordinates, which puts every keypoint a
        # quarter pixel right of and below its true position (doubled pixel c sits at
        # c / 2 - 1/4 of the input): report the true position
        cols["x"].append(x - np.float32(shift))
        cols["y"].append(y - np.float32(shift))
        cols["size"].append(size)
        cols["ang"].append(ang)
        cols["resp"].append(kp[:, 6].astype(np.float32))
        cols["oct"].append(np.full(kp.shape[0], o + first, np.int64))
        desc_parts.append(desc)
    if not desc_parts:
        return Features(Keypoints.empty(), np.zeros((0, _D * _D * _N), descriptor_dtype))
    x, y, size, ang, resp, octv = (
        np.concatenate(cols[k]) for k in ("x", "y", "size", "ang", "resp", "oct")
    )
    desc = np.concatenate(desc_parts)
    # drop exact duplicates (OpenCV's removeDuplicatedSorted), strongest first
    key = np.stack([x, y, size, ang], axis=1)
    _, first_idx = np.unique(key, axis=0, return_index=True)
    order = first_idx[np.argsort(-resp[first_idx], kind="stable")]
    if n_features and order.size > n_features:
        cut = resp[order[n_features - 1]]
        order = order[resp[order] >= cut]
    keypoints = Keypoints(
        np.stack([x[order], y[order]], axis=1),
        size[order],
        np.deg2rad(ang[order].astype(np.float64)),
        resp[order],
        octv[order],
    )
    return Features(keypoints, desc[order].astype(descriptor_dtype))
