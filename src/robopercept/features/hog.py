r"""Histograms of oriented gradients (Dalal and Triggs, 2005).

The image gradient is taken with the centred difference :math:`[-1, 0, 1]` in x and y;
each pixel has a magnitude :math:`m = \sqrt{I_x^2 + I_y^2}` and an unsigned orientation
:math:`\theta = \operatorname{atan2}(I_y, I_x) \bmod \pi` (``signed=True``: mod
:math:`2\pi`). On colour images each pixel keeps the channel with the largest
magnitude. The orientation range is cut into ``orientations`` bins and every pixel
votes its magnitude into the histogram of its cell (``cell_size`` pixels). Cells are
grouped into overlapping blocks of ``block_size`` cells, moved by ``block_stride``
cells; each block's concatenated histograms :math:`v` are normalized:

- ``"L2-Hys"``: :math:`v \leftarrow v / (\lVert v \rVert_2 + \epsilon)`, clipped at
  ``clip`` (0.2), renormalized;
- ``"L2"``: :math:`v / \sqrt{\lVert v \rVert_2^2 + \epsilon^2}`;
- ``"L1"``: :math:`v / (\lVert v \rVert_1 + \epsilon)`; ``"L1-sqrt"``: its square root.

The window's descriptor is all its blocks concatenated.

Two conventions, chosen with ``convention``, reproduce the two libraries people use:

``"opencv"`` (``cv2.HOGDescriptor``, the default; Dalal and Triggs' scheme)
    Every vote is split between the two nearest orientation bins (linear in angle, bin
    centres at :math:`(b + \tfrac12)\,\pi / n`; the angle from OpenCV's float32
    polynomial atan2, within 0.01 degrees of the exact one) and, inside each block, bilinearly
    between the four nearest cells (cell centres; pixels nearer a block edge than a cell
    centre vote into one or two cells), weighted by a Gaussian over the block
    (:math:`\sigma` = (block width + block height) / 8 pixels, centred on the block's
    middle; ``block_sigma=0`` turns it off). Image borders are reflected
    (``reflect101``). ``"L2-Hys"`` uses :math:`\epsilon = 0.1 \times` the block length on
    the first normalization and :math:`10^{-3}` on the second, with the gradients on the
    0..255 scale: uint8 images are used as they are, float images in [0, 1] are
    multiplied by 255 so both dtypes give the same descriptor. The layout is OpenCV's
    (blocks column by column, cells inside a block column by column, then bins), so
    OpenCV's trained linear SVMs (``HOGDescriptor_getDefaultPeopleDetector``) apply
    to our descriptors.

``"skimage"`` (``skimage.feature.hog``)
    Each pixel votes its whole magnitude into one orientation bin and one cell, the
    cell histogram is the mean over the cell, gradients on the first and last row and
    column are zero, blocks are not weighted, :math:`\epsilon = 10^{-5}`, pixel values
    are used unscaled, and the layout is row-major (block rows, block columns, cell
    rows, cell columns, bins).

All sizes are ``(height, width)`` like NumPy shapes; a single int means a square.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numba import njit, prange

from robopercept._checks import (
    check_bool,
    check_choice,
    check_image,
    check_int,
    check_magnitude,
    check_positive,
    check_real,
)
from robopercept.errors import InputError
from robopercept.features._atan import atan2_deg

__all__ = ["cell_histograms", "hog", "hog_windows"]

Convention = Literal["opencv", "skimage"]
Norm = Literal["L2-Hys", "L2", "L1", "L1-sqrt"]
NORMS = ("L2-Hys", "L2", "L1", "L1-sqrt")
_NORM_CODE = {n: i for i, n in enumerate(NORMS)}


_MAX_VALUE = 1e15  # |image| beyond it overflows the float32 block norms' sums of squares

_MAX_SIDE = 65536  # cell, block and stride sizes


def _pair(value: int | tuple[int, int], name: str) -> tuple[int, int]:
    # sizes in cells or pixels, each in [1, 65536] (an image side at most: larger ones
    # fit no block, and their products overflow the int64 grid arithmetic)
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        v = _side(value, name)
        return v, v
    try:
        a, b = value  # type: ignore[misc]
    except (TypeError, ValueError):
        msg = f"{name} must be an int or a (height, width) pair; got {value!r}"
        raise InputError(msg) from None
    return _side(a, f"{name}[0]"), _side(b, f"{name}[1]")


def _side(value: int, name: str) -> int:
    v = check_int(value, name, 1)
    if v > _MAX_SIDE:
        raise InputError(f"{name} must be at most {_MAX_SIDE}; got {v}")
    return v


# --------------------------------------------------------------------------- gradients


@njit(cache=True, nogil=True, parallel=True)
def _opencv_votes(img, gamma, nbins, signed, bins, votes):  # pragma: no cover - compiled
    # OpenCV's per-pixel votes: the centred differences (borders reflect101), the
    # channel of the largest magnitude (blue first on ties, as in OpenCV's BGR order),
    # the two nearest bins and the magnitude split between them linearly in angle
    # (bin centres at (b + 1/2) * range / nbins).
    h, w, c = img.shape
    ascale = nbins / (2.0 * math.pi) if signed else nbins / math.pi
    for y in prange(h):
        yp = y - 1 if y > 0 else (1 if h > 1 else 0)
        yn = y + 1 if y < h - 1 else (h - 2 if h > 1 else 0)
        for x in range(w):
            xp = x - 1 if x > 0 else (1 if w > 1 else 0)
            xn = x + 1 if x < w - 1 else (w - 2 if w > 1 else 0)
            best = np.float32(-1.0)
            bdx = np.float32(0.0)
            bdy = np.float32(0.0)
            for k in range(c):
                ch = c - 1 - k  # OpenCV's order on ties: blue, green, red
                a = img[y, xn, ch]
                b = img[y, xp, ch]
                d = img[yn, x, ch]
                e = img[yp, x, ch]
                if gamma:
                    a = np.float32(math.sqrt(a))
                    b = np.float32(math.sqrt(b))
                    d = np.float32(math.sqrt(d))
                    e = np.float32(math.sqrt(e))
                dx = np.float32(a - b)
                dy = np.float32(d - e)
                m2 = dx * dx + dy * dy
                if m2 > best:
                    best = m2
                    bdx = dx
                    bdy = dy
            mag = np.float32(math.sqrt(best))
            ang = atan2_deg(bdy, bdx) * np.float32(math.pi / 180.0)
            t = np.float32(ang * ascale) - np.float32(0.5)
            hidx = math.floor(t)
            t -= np.float32(hidx)
            votes[y, x, 0] = mag * (np.float32(1.0) - t)
            votes[y, x, 1] = mag * t
            if hidx < 0:
                hidx += nbins
            elif hidx >= nbins:
                hidx -= nbins
            bins[y, x, 0] = hidx
            hidx += 1
            bins[y, x, 1] = hidx if hidx < nbins else 0


def _votes(
    image: np.ndarray, nbins: int, gamma: bool, signed: bool
) -> tuple[np.ndarray, np.ndarray]:
    # (H, W, 2) bins and votes of every pixel (_opencv_votes) on the 0..255 scale:
    # uint8 as it is, float images in [0, 1] times 255
    img = image.astype(np.float32)
    if image.dtype != np.uint8:
        img *= np.float32(255.0)
    if img.ndim == 2:
        img = img[:, :, None]
    h, w = img.shape[:2]
    votes = np.empty((h, w, 2), np.float32)
    bins = np.empty((h, w, 2), np.uint8)
    _opencv_votes(np.ascontiguousarray(img), gamma, nbins, signed, bins, votes)
    return bins, votes


def _skimage_gradient(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # skimage's gradient: centred differences, zero on the outer rows/columns, the
    # channel of the largest magnitude (the first on ties); returns magnitude and
    # orientation in degrees
    img = image.astype(np.float64, copy=False)
    if img.ndim == 2:
        img = img[:, :, None]
    gr = np.zeros_like(img)
    gc = np.zeros_like(img)
    gr[1:-1] = img[2:] - img[:-2]
    gc[:, 1:-1] = img[:, 2:] - img[:, :-2]
    if img.shape[2] > 1:
        pick = np.hypot(gr, gc).argmax(axis=2)[..., None]
        gr = np.take_along_axis(gr, pick, 2)
        gc = np.take_along_axis(gc, pick, 2)
    gr, gc = gr[..., 0], gc[..., 0]
    return np.hypot(gc, gr), np.arctan2(gr, gc)


# ------------------------------------------------------------------------ block kernels


@njit(cache=True, nogil=True, parallel=True)
def _opencv_blocks(
    votes, bins, ys, xs, bh, bw, ncy, ncx, cidx, cw, nbins, norm, clip, out
):  # pragma: no cover - compiled
    # out[i, j] = the normalized histogram of the block with top-left (ys[i], xs[j]):
    # every pixel (r, c) of the block adds its two bin votes times cw[r, c, q] into the
    # cells cidx[r, c, q], q < 4 (OpenCV's layout: cell column-major, then bin).
    n = ncy * ncx * nbins
    for i in prange(ys.shape[0]):
        hist = np.zeros(n, np.float32)
        for j in range(xs.shape[0]):
            for t in range(n):
                hist[t] = 0.0
            y0 = ys[i]
            x0 = xs[j]
            for r in range(bh):
                for c in range(bw):
                    v0 = votes[y0 + r, x0 + c, 0]
                    v1 = votes[y0 + r, x0 + c, 1]
                    b0 = bins[y0 + r, x0 + c, 0]
                    b1 = bins[y0 + r, x0 + c, 1]
                    for q in range(4):
                        wq = cw[r, c, q]
                        if wq != 0.0:
                            off = cidx[r, c, q] * nbins
                            hist[off + b0] += v0 * wq
                            hist[off + b1] += v1 * wq
            _normalize(hist, norm, clip, True)
            for t in range(n):
                out[i, j, t] = hist[t]


@njit(cache=True, nogil=True)
def _normalize(v, norm, clip, opencv):  # pragma: no cover - compiled
    # the block normalizations in place (see the module docstring); opencv=True uses
    # OpenCV's L2-Hys epsilons (0.1 * length, then 1e-3), else skimage's 1e-5
    n = v.shape[0]
    eps = 1e-5
    if norm == 0:  # L2-Hys
        s = 0.0
        for t in range(n):
            s += v[t] * v[t]
        if opencv:
            scale = 1.0 / (math.sqrt(s) + n * 0.1)
        else:
            scale = 1.0 / math.sqrt(s + eps * eps)
        s = 0.0
        for t in range(n):
            a = min(v[t] * scale, clip)
            v[t] = a
            s += a * a
        scale = 1.0 / (math.sqrt(s) + 1e-3) if opencv else 1.0 / math.sqrt(s + eps * eps)
        for t in range(n):
            v[t] = v[t] * scale
    elif norm == 1:  # L2
        s = 0.0
        for t in range(n):
            s += v[t] * v[t]
        scale = 1.0 / math.sqrt(s + eps * eps)
        for t in range(n):
            v[t] = v[t] * scale
    else:  # L1, L1-sqrt
        s = 0.0
        for t in range(n):
            s += abs(v[t])
        scale = 1.0 / (s + eps)
        for t in range(n):
            v[t] = v[t] * scale
            if norm == 3:
                v[t] = math.sqrt(v[t])


@njit(cache=True, nogil=True)
def _skimage_blocks(cells, by, bx, nbins, norm, clip, out):  # pragma: no cover - compiled
    # out[i, j] = the normalized concatenation of cells[i:i+by, j:j+bx] (row-major)
    ny, nx = out.shape[0], out.shape[1]
    v = np.empty(by * bx * nbins, np.float64)
    for i in range(ny):
        for j in range(nx):
            t = 0
            for r in range(by):
                for c in range(bx):
                    for b in range(nbins):
                        v[t] = cells[i + r, j + c, b]
                        t += 1
            _normalize(v, norm, clip, False)
            for t in range(v.shape[0]):
                out[i, j, t] = v[t]


def _cell_weights(
    block_px: tuple[int, int], cell: tuple[int, int], ncells: tuple[int, int], sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    # for each pixel of a block, the (at most) four cells it votes into and the weights:
    # bilinear between cell centres, times the Gaussian over the block; cell index in
    # OpenCV's column-major order cx * ncy + cy; zero weight where a cell is outside
    bh, bw = block_px
    gy = (np.arange(bh) - bh * 0.5) ** 2
    gx = (np.arange(bw) - bw * 0.5) ** 2
    d2 = gy[:, None] + gx[None, :]
    if sigma > 0 and 2.0 * sigma * sigma > 0:
        with np.errstate(over="ignore"):  # exp(-inf) = 0 far from a tiny sigma's centre
            g = np.exp(-d2 / (2.0 * sigma * sigma))
    elif sigma > 0:  # sigma^2 underflows to 0 (0 / 0 = NaN at the centre): a delta
        g = (d2 == 0).astype(np.float64)
    else:
        g = np.ones((bh, bw))
    fy = (np.arange(bh) + 0.5) / cell[0] - 0.5
    fx = (np.arange(bw) + 0.5) / cell[1] - 0.5
    y0 = np.floor(fy).astype(np.int64)
    x0 = np.floor(fx).astype(np.int64)
    ty, tx = fy - y0, fx - x0
    idx = np.zeros((bh, bw, 4), np.int32)
    w = np.zeros((bh, bw, 4), np.float32)
    q = 0
    for dy in (0, 1):
        for dx in (0, 1):
            cy = y0[:, None] + dy
            cx = x0[None, :] + dx
            wy = np.where(dy, ty, 1.0 - ty)[:, None]
            wx = np.where(dx, tx, 1.0 - tx)[None, :]
            inside = (cy >= 0) & (cy < ncells[0]) & (cx >= 0) & (cx < ncells[1])
            idx[:, :, q] = np.where(inside, cx * ncells[0] + cy, 0)
            w[:, :, q] = np.where(inside, wy * wx * g, 0.0)
            q += 1
    return idx, w


# ----------------------------------------------------------------------------- public


_MAX_ORIENTATIONS = 360  # bins: half a degree each over [0, pi), a degree over [0, 2 pi)


def _orientations(value: int) -> int:
    n = check_int(value, "orientations", 1)
    if n > _MAX_ORIENTATIONS:
        raise InputError(
            f"orientations must be at most {_MAX_ORIENTATIONS} bins; got {n}: HOG uses 9 "
            "(Dalal and Triggs)"
        )
    return n


class _Params:
    # the checked parameters shared by hog and hog_windows
    def __init__(
        self,
        orientations: int,
        cell_size: int | tuple[int, int],
        block_size: int | tuple[int, int],
        block_stride: int | tuple[int, int],
        block_norm: str,
        clip: float,
        convention: str,
        block_sigma: float | None,
        signed: bool,
        gamma: bool,
    ) -> None:
        self.nbins = _orientations(orientations)
        self.cell = _pair(cell_size, "cell_size")
        self.block = _pair(block_size, "block_size")
        self.stride = _pair(block_stride, "block_stride")
        self.norm = _NORM_CODE[check_choice(block_norm, "block_norm", NORMS)]
        self.clip = check_positive(clip, "clip")
        self.convention = check_choice(convention, "convention", ("opencv", "skimage"))
        self.signed = check_bool(signed, "signed")
        self.gamma = check_bool(gamma, "gamma")
        bh, bw = self.block_px
        if self.convention == "opencv":
            if self.nbins > 255:
                raise InputError(f"orientations must be <= 255; got {self.nbins}")
            self.sigma = (
                (bh + bw) / 8.0
                if block_sigma is None
                else check_real(block_sigma, "block_sigma", 0.0)
            )
        else:
            if block_sigma is not None and check_real(block_sigma, "block_sigma") != 0.0:
                raise InputError("block_sigma applies to convention='opencv' only")
            if self.signed:
                raise InputError("signed orientations apply to convention='opencv' only")
            self.sigma = 0.0

    @property
    def block_px(self) -> tuple[int, int]:
        return self.block[0] * self.cell[0], self.block[1] * self.cell[1]

    @property
    def stride_px(self) -> tuple[int, int]:
        return self.stride[0] * self.cell[0], self.stride[1] * self.cell[1]

    @property
    def block_len(self) -> int:
        return self.block[0] * self.block[1] * self.nbins

    def grid(self, size: tuple[int, int]) -> tuple[int, int]:
        # blocks that fit into a (height, width) region along each axis
        (bh, bw), (sy, sx) = self.block_px, self.stride_px
        if size[0] < bh or size[1] < bw:
            raise InputError(
                f"image region of {size[0]}x{size[1]} pixels is smaller than one block: "
                f"HOG needs at least {bh}x{bw} (block_size x cell_size); use a larger "
                "image or smaller cells/blocks"
            )
        return (size[0] - bh) // sy + 1, (size[1] - bw) // sx + 1

    def blocks(self, image: np.ndarray, ny: int, nx: int) -> np.ndarray:
        # the normalized block histograms on the block grid, (ny, nx, block_len),
        # each in the convention's block layout
        if self.convention == "opencv":
            bins, votes = _votes(image, self.nbins, self.gamma, self.signed)
            idx, wts = _cell_weights(self.block_px, self.cell, self.block, self.sigma)
            out = np.empty((ny, nx, self.block_len), np.float32)
            sy, sx = self.stride_px
            _opencv_blocks(
                votes,
                bins,
                np.arange(ny, dtype=np.int64) * sy,
                np.arange(nx, dtype=np.int64) * sx,
                self.block_px[0],
                self.block_px[1],
                self.block[0],
                self.block[1],
                idx,
                wts,
                self.nbins,
                self.norm,
                self.clip,
                out,
            )
            return out
        cells = _skimage_cells(image, self.cell, self.nbins, self.gamma)
        by, bx = self.block
        sy, sx = self.stride
        full = np.empty(
            (cells.shape[0] - by + 1, cells.shape[1] - bx + 1, self.block_len), np.float64
        )
        _skimage_blocks(cells, by, bx, self.nbins, self.norm, self.clip, full)
        out = full[::sy, ::sx][:ny, :nx]
        dtype = np.float32 if image.dtype == np.float32 else np.float64
        return out.astype(dtype, copy=False)


def _skimage_cells(image: np.ndarray, cell: tuple[int, int], nbins: int, gamma: bool) -> np.ndarray:
    # mean magnitude per (cell, bin), whole magnitude into one bin, full cells only
    if gamma:
        image = np.sqrt(image.astype(np.float64))
    mag, ang = _skimage_gradient(image)
    deg = np.rad2deg(ang) % 180.0
    per = 180.0 / nbins
    edges = per * np.arange(1, nbins)
    b = np.searchsorted(edges, deg, side="right")
    ny, nx = image.shape[0] // cell[0], image.shape[1] // cell[1]
    hh, ww = ny * cell[0], nx * cell[1]
    cy = np.arange(hh) // cell[0]
    cx = np.arange(ww) // cell[1]
    flat = ((cy[:, None] * nx + cx[None, :]) * nbins + b[:hh, :ww]).ravel()
    hist = np.bincount(flat, weights=mag[:hh, :ww].ravel(), minlength=ny * nx * nbins)
    return hist.reshape(ny, nx, nbins) / (cell[0] * cell[1])


def _window_layout(blocks: np.ndarray, p: _Params) -> np.ndarray:
    # (..., nby, nbx, block_len) -> flat window descriptors in the convention's order:
    # OpenCV puts blocks column by column and cells inside a block column by column
    if p.convention == "opencv":
        blocks = np.swapaxes(blocks, -3, -2)
    return blocks.reshape(*blocks.shape[:-3], -1)


def hog(
    image: np.ndarray,
    *,
    orientations: int = 9,
    cell_size: int | tuple[int, int] = 8,
    block_size: int | tuple[int, int] = 2,
    block_stride: int | tuple[int, int] = 1,
    block_norm: Norm = "L2-Hys",
    clip: float = 0.2,
    convention: Convention = "opencv",
    block_sigma: float | None = None,
    signed: bool = False,
    gamma: bool = False,
) -> np.ndarray:
    """HOG descriptor of a whole image taken as one detection window.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8 or float image (colour: per pixel the channel with the largest gradient).
    orientations : int
        Number of orientation bins over [0, pi) (over [0, 2 pi) when ``signed``).
    cell_size : int or (int, int)
        Cell size in pixels, (height, width).
    block_size : int or (int, int)
        Block size in cells.
    block_stride : int or (int, int)
        Step between blocks in cells (1: blocks overlap by all but one cell).
    block_norm : {"L2-Hys", "L2", "L1", "L1-sqrt"}
        Block normalization (module docstring).
    clip : float
        L2-Hys clipping value.
    convention : {"opencv", "skimage"}
        Voting, border, epsilon and layout conventions (module docstring).
    block_sigma : float, optional
        Gaussian block weighting in pixels (``opencv`` only); default
        (block height + width in pixels) / 8 as OpenCV, 0 for none.
    signed : bool
        Signed orientations over [0, 2 pi) (``opencv`` only).
    gamma : bool
        Square-root gamma compression of the pixel values first (OpenCV's
        ``gammaCorrection``, skimage's ``transform_sqrt``).

    Returns
    -------
    (D,) ndarray
        float32 (float64 for float64 input under ``skimage``); D = blocks x
        ``block_size`` cells x ``orientations``. The blocks that fit from the top-left
        corner are used: the remainder that does not fill a block (``opencv``) or a
        cell (``skimage``) on the right and bottom is ignored.

    Raises
    ------
    InputError
        If the image is smaller than one block, or a parameter is invalid.

    Notes
    -----
    With the same window, block, stride, cell and bins this equals
    ``cv2.HOGDescriptor(...).compute(image)`` (``convention="opencv"``, uint8 gray or
    RGB images) and ``skimage.feature.hog(image, ...)`` (``convention="skimage"``,
    ``block_stride=1``) to float32 rounding.
    """
    # gradient magnitudes and block norms square sums of votes: refuse what overflows
    image = check_magnitude(check_image(image), "image", _MAX_VALUE)
    p = _Params(
        orientations,
        cell_size,
        block_size,
        block_stride,
        block_norm,
        clip,
        convention,
        block_sigma,
        signed,
        gamma,
    )
    region = image.shape[:2]
    if p.convention == "skimage":
        region = (region[0] // p.cell[0] * p.cell[0], region[1] // p.cell[1] * p.cell[1])
    ny, nx = p.grid(region)
    return _window_layout(p.blocks(image, ny, nx), p)


def hog_windows(
    image: np.ndarray,
    window: int | tuple[int, int] = (64, 128),
    stride: int | tuple[int, int] = 8,
    *,
    orientations: int = 9,
    cell_size: int | tuple[int, int] = 8,
    block_size: int | tuple[int, int] = 2,
    block_stride: int | tuple[int, int] = 1,
    block_norm: Norm = "L2-Hys",
    clip: float = 0.2,
    convention: Convention = "opencv",
    block_sigma: float | None = None,
    signed: bool = False,
    gamma: bool = False,
) -> np.ndarray:
    """Dense HOG: the descriptor of every detection window on a grid over the image.

    Block histograms are computed once on the block grid and shared by the windows
    that contain them, as a sliding-window detector wants.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        The image.
    window : int or (int, int)
        Detection window in pixels, (width, height) as ``cv2.HOGDescriptor``'s
        ``winSize``; default OpenCV's 64 x 128.
    stride : int or (int, int)
        Step between windows in pixels, (x, y) as ``winStride``; a multiple of the block
        stride in pixels.
    orientations, cell_size, block_size, block_stride, block_norm, clip, convention,
    block_sigma, signed, gamma
        As in :func:`hog`.

    Returns
    -------
    (NY, NX, D) ndarray
        Descriptor of the window with top-left corner ``(x, y) = (j * stride_x,
        i * stride_y)`` at ``[i, j]``; ``reshape(-1)`` gives
        ``cv2.HOGDescriptor.compute(image, winStride=stride)`` (windows row by row).

    Raises
    ------
    InputError
        If the image is smaller than the window, the window does not hold a whole
        number of block steps, or the stride is not a multiple of the block stride.
    """
    # gradient magnitudes and block norms square sums of votes: refuse what overflows
    image = check_magnitude(check_image(image), "image", _MAX_VALUE)
    p = _Params(
        orientations,
        cell_size,
        block_size,
        block_stride,
        block_norm,
        clip,
        convention,
        block_sigma,
        signed,
        gamma,
    )
    win = _pair(window, "window")[::-1]  # (width, height) -> (height, width) inside
    step = _pair(stride, "stride")[::-1]
    (bh, bw), (sy, sx) = p.block_px, p.stride_px
    for k, name in ((0, "height"), (1, "width")):
        if (win[k] - p.block_px[k]) % p.stride_px[k] or win[k] < p.block_px[k]:
            raise InputError(
                f"window {name} {win[k]} must be block size {p.block_px[k]} plus a multiple "
                f"of the block stride {p.stride_px[k]} pixels"
            )
        if step[k] % p.stride_px[k]:
            raise InputError(
                f"stride {name} {step[k]} must be a multiple of the block stride "
                f"{p.stride_px[k]} pixels"
            )
    h, w = image.shape[:2]
    if h < win[0] or w < win[1]:
        raise InputError(
            f"image of {h}x{w} pixels is smaller than the {win[0]}x{win[1]} window: "
            "use a larger image or a smaller window"
        )
    ny, nx = p.grid((h, w))
    blocks = p.blocks(image, ny, nx)
    nby, nbx = (win[0] - bh) // sy + 1, (win[1] - bw) // sx + 1
    ky, kx = step[0] // sy, step[1] // sx
    nwy, nwx = (h - win[0]) // step[0] + 1, (w - win[1]) // step[1] + 1
    view = np.lib.stride_tricks.sliding_window_view(blocks, (nby, nbx), axis=(0, 1))
    view = view[: (nwy - 1) * ky + 1 : ky, : (nwx - 1) * kx + 1 : kx]
    # view: (nwy, nwx, block_len, nby, nbx) -> (nwy, nwx, nby, nbx, block_len)
    view = np.moveaxis(view, 2, 4)
    return np.ascontiguousarray(_window_layout(view, p))


def cell_histograms(
    image: np.ndarray,
    cell_size: int | tuple[int, int] = 8,
    orientations: int = 9,
) -> np.ndarray:
    """Unnormalized orientation histograms per cell, for pictures and inspection.

    Each pixel votes its gradient magnitude, split linearly between the two nearest
    orientation bins, into its cell (no spatial interpolation); the histogram is the
    mean over the cell.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        The image.
    cell_size : int or (int, int)
        Cell size in pixels, (height, width).
    orientations : int
        Unsigned orientation bins over [0, pi); bin b is centred at (b + 1/2) pi / n.

    Returns
    -------
    (H // cell_h, W // cell_w, orientations) float64 ndarray

    Raises
    ------
    InputError
        If the image is smaller than one cell, or ``orientations`` is not an integer in
        [1, 360].
    """
    # gradient magnitudes and block norms square sums of votes: refuse what overflows
    image = check_magnitude(check_image(image), "image", _MAX_VALUE)
    cell = _pair(cell_size, "cell_size")
    nbins = _orientations(orientations)
    h, w = image.shape[:2]
    ny, nx = h // cell[0], w // cell[1]
    if ny == 0 or nx == 0:
        raise InputError(
            f"image of {h}x{w} pixels is smaller than one {cell[0]}x{cell[1]} cell: "
            "use a larger image or smaller cells"
        )
    bins, votes = _votes(image, nbins, False, False)
    hh, ww = ny * cell[0], nx * cell[1]
    cy = np.arange(hh) // cell[0]
    cx = np.arange(ww) // cell[1]
    base = (cy[:, None] * nx + cx[None, :]) * nbins
    hist = np.zeros(ny * nx * nbins)
    for k in (0, 1):
        flat = (base + bins[:hh, :ww, k]).ravel()
        hist += np.bincount(flat, weights=votes[:hh, :ww, k].ravel(), minlength=hist.size)
    return hist.reshape(ny, nx, nbins) / (cell[0] * cell[1])
