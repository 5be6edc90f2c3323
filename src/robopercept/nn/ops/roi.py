r"""Region-of-interest operations of the R-CNN family, in torch: RoI max pooling
(:func:`roi_pool`, Fast R-CNN), RoI Align (:func:`roi_align`, Mask R-CNN) and their
modules, and pasting per-box masks back into the image (:func:`paste_masks`, the
inverse of RoI Align).

Regions are ``"xyxy"`` image pixels (:mod:`robopercept.nn.ops.boxes`), given as a
``(K, 5)`` tensor of ``[batch_index, x1, y1, x2, y2]`` rows or a list of one
``(K_i, 4)`` tensor per image. References matched (tests pin each): onnxruntime's
``RoiAlign`` (opset 16) for RoI Align; torchvision's quantization for RoI pooling
(looked up, not imported: torchvision is not a dependency).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from numba import njit, prange

from robopercept._checks import check_bool, check_int, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation
from robopercept.nn.ops.boxes import check_boxes

__all__ = ["RoIAlign", "RoIPool", "paste_masks", "roi_align", "roi_pool"]


# --------------------------------------------------------------------------- RoI ops
def _check_feature(input: Any) -> torch.Tensor:
    if not isinstance(input, torch.Tensor):
        raise InputError(
            f"input must be a (N, C, H, W) torch.Tensor of features; got {type(input).__name__}: "
            "use torch.from_numpy(x).float()"
        )
    if input.ndim != 4:
        hint = ": one image? use input.unsqueeze(0)" if input.ndim == 3 else ""
        raise InputError(f"input must be 4-D (N, C, H, W); got shape {tuple(input.shape)}{hint}")
    if not input.is_floating_point():
        raise InputError(f"input must be floating point; got {input.dtype}: use input.float()")
    if min(input.shape[2:]) < 1:
        raise InputError(f"input must have H, W >= 1; got shape {tuple(input.shape)}")
    return input


def _check_rois(boxes: Any, n_images: int) -> tuple[torch.Tensor, torch.Tensor]:
    """``(batch_index (K,), boxes (K, 4))`` from a (K, 5) tensor or a list of (Ki, 4)."""
    if isinstance(boxes, (list, tuple)):
        if len(boxes) != n_images:
            raise InputError(
                f"boxes as a list must hold one (Ki, 4) tensor per image ({n_images}); got "
                f"{len(boxes)}"
            )
        parts = [check_boxes(b, f"boxes[{i}]", ordered=False) for i, b in enumerate(boxes)]
        dtype = parts[0].dtype if parts else torch.float32
        rois = torch.cat([p.to(dtype) for p in parts]) if parts else torch.zeros(0, 4, dtype=dtype)
        bidx = (
            torch.cat([torch.full((p.shape[0],), i, dtype=torch.long) for i, p in enumerate(parts)])
            if parts
            else torch.zeros(0, dtype=torch.long)
        )
        return bidx, rois
    if isinstance(boxes, torch.Tensor) and boxes.ndim == 2 and boxes.shape[1] == 4:
        raise InputError(
            "boxes must be a (K, 5) tensor [batch_index, x1, y1, x2, y2] or a list of (Ki, 4) "
            "tensors; got a (K, 4) tensor: pass [boxes] for a single image"
        )
    b = check_boxes(boxes, "boxes", 5, ordered=False)
    bi = b[:, 0]
    if b.numel() and bool(((bi != bi.round()) | (bi < 0) | (bi >= n_images)).any()):
        raise InputError(
            f"boxes[:, 0] must be whole batch indices in [0, {n_images - 1}]; got "
            f"{plain_repr(sorted(set(bi.tolist()))[:5])}"
        )
    return bi.long(), b[:, 1:]


def _output_size(value: Any) -> tuple[int, int]:
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value, value)
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise InputError(f"output_size must be an int or (height, width); got {plain_repr(value)}")
    ph, pw = (check_int(v, "output_size", 1) for v in value)
    if ph > 4096 or pw > 4096:
        raise InputError(f"output_size must be at most 4096 per side; got {plain_repr(value)}")
    return ph, pw


def _outside(start: torch.Tensor, size: torch.Tensor, length: int) -> torch.Tensor:
    """Whether every sample of regions ``[start, start + size]`` along one axis lies
    outside ``[-1, length]``, where RoI Align counts them as 0."""
    lo = torch.minimum(start, start + size)
    hi = torch.maximum(start, start + size)
    return (lo > length) | (hi < -1.0)


def _align_weights(
    start: torch.Tensor, size: torch.Tensor, bins: int, grid: torch.Tensor, length: int
) -> torch.Tensor:
    """``(K, bins, length)`` matrix whose row ``p`` averages the bilinear samples of bin
    ``p`` along one axis (torchvision's ``bilinear_interpolate``, one axis at a time)."""
    K = start.shape[0]
    gmax = max(int(grid.max()) if K else 1, 1)
    dt = start.dtype
    bin_size = size / bins
    p = torch.arange(bins, dtype=dt)
    s = torch.arange(gmax, dtype=dt)
    g = grid.to(dt).clamp(min=1)
    # sample positions (K, bins, gmax)
    y = (
        start[:, None, None]
        + p[None, :, None] * bin_size[:, None, None]
        + (s[None, None, :] + 0.5) * (bin_size / g)[:, None, None]
    )
    used = s[None, None, :] < grid[:, None, None]
    inside = (y >= -1.0) & (y <= length)
    # clamped before the conversion to integers: a sample beyond the map (weight 0, or
    # the last cell's) of a huge box would overflow int64 (issue 47 R50)
    y = y.clamp(0, length)
    low = y.floor().long()
    top = low >= length - 1
    low = torch.where(top, torch.full_like(low, length - 1), low)
    high = torch.where(top, low, low + 1)
    y = torch.where(top, low.to(dt), y)
    frac = y - low.to(dt)
    w = (used & inside).to(dt) / g[:, None, None]
    out = torch.zeros(K, bins, length, dtype=dt)
    out.scatter_add_(2, low, w * (1 - frac))
    out.scatter_add_(2, high, w * frac)
    return out


@njit(cache=True, nogil=True, inline="always")
def _axis_weights(start, size, bins, grid, length, a, lo, hi):  # pragma: no cover - compiled
    # _align_weights of one region into a (bins, length) row a (zeroed here), with the
    # first and last column each row touches in lo, hi: the same samples, clamps and
    # weights, in float64
    g = max(grid, 1)
    bin_size = size / bins
    for p in range(bins):
        lo[p], hi[p] = length, -1
        for c in range(length):
            a[p, c] = 0.0
        for s in range(grid):
            y = start + p * bin_size + (s + 0.5) * (bin_size / g)
            if not (y >= -1.0 and y <= length):
                continue
            y = min(max(y, 0.0), float(length))
            low = int(np.floor(y))
            if low >= length - 1:
                low = length - 1
                high = low
                y = float(low)
            else:
                high = low + 1
            frac = y - low
            a[p, low] += (1.0 / g) * (1.0 - frac)
            a[p, high] += (1.0 / g) * frac
            lo[p], hi[p] = min(lo[p], low), max(hi[p], high)


@njit(cache=True, nogil=True, parallel=True)
def _roi_align_kernel(xt, bidx, r, rw, rh, gh, gw, out):  # pragma: no cover - compiled
    # RoI Align forward of every region (parallel over regions) on the channels-last
    # map xt (N, H, W, C): the separable weights of the region (rows: P x H, columns:
    # Q x W), then the rows' weighted sums over the columns the region touches, then
    # the columns' (float64 sums), each step over the C channels of a cell as one
    # contiguous vector; per channel the same sums in the same order as channel by
    # channel, so the same bits
    _, H, W, C = xt.shape
    K, _, P, Q = out.shape
    for k in prange(K):
        n = bidx[k]
        ay, ylo, yhi = np.empty((P, H)), np.empty(P, np.int64), np.empty(P, np.int64)
        ax, xlo, xhi = np.empty((Q, W)), np.empty(Q, np.int64), np.empty(Q, np.int64)
        _axis_weights(r[k, 1], rh[k], P, gh[k], H, ay, ylo, yhi)
        _axis_weights(r[k, 0], rw[k], Q, gw[k], W, ax, xlo, xhi)
        c0, c1 = xlo.min(), xhi.max()
        tmp = np.zeros((P, max(c1 - c0 + 1, 1), C))  # the rows' sums, columns c0..c1
        acc = np.empty(C)
        for p in range(P):
            for row in range(ylo[p], yhi[p] + 1):
                w = ay[p, row]
                if w != 0.0:
                    for col in range(c0, c1 + 1):
                        src, t = xt[n, row, col], tmp[p, col - c0]
                        for c in range(C):
                            t[c] += w * src[c]
            for q in range(Q):
                acc[:] = 0.0
                for col in range(xlo[q], xhi[q] + 1):
                    a, t = ax[q, col], tmp[p, col - c0]
                    for c in range(C):
                        acc[c] += a * t[c]
                for c in range(C):
                    out[k, c, p, q] = acc[c]


def _compiled_forward(x: torch.Tensor) -> bool:
    """Whether a forward may run a compiled kernel instead of torch operations: a CPU
    float32/float64 input whose result keeps no gradient (none wanted: no
    ``requires_grad``, or ``torch.no_grad``/``inference_mode``), outside a trace or a
    ``torch.compile`` (which record torch operations)."""
    return (
        x.device.type == "cpu"
        and x.dtype in (torch.float32, torch.float64)
        and not (torch.is_grad_enabled() and x.requires_grad)
        and not torch.jit.is_tracing()
        and not torch.compiler.is_compiling()
    )


@njit(cache=True, nogil=True, parallel=True)
def _roi_pool_kernel(xt, bidx, hs, he, ws, we, out):  # pragma: no cover - compiled
    # RoI max pooling forward (parallel over regions) on the channels-last map xt
    # (N, H, W, C): each bin's window cell by cell, the C channels of a cell one
    # contiguous vector; an empty bin is 0; a NaN in the window gives NaN (as amax: the
    # select takes a NaN and keeps it)
    C = xt.shape[3]
    K, _, P, Q = out.shape
    for k in prange(K):
        n = bidx[k]
        row_out = np.empty((Q, C), xt.dtype)  # one row of bins, channels last
        for p in range(P):
            h0, h1 = hs[k, p], he[k, p]
            for q in range(Q):
                m = row_out[q]
                w0, w1 = ws[k, q], we[k, q]
                if h1 <= h0 or w1 <= w0:
                    m[:] = 0.0
                    continue
                m[:] = xt[n, h0, w0]
                for row in range(h0, h1):
                    for col in range(w0, w1):
                        cell = xt[n, row, col]
                        for c in range(C):
                            v = cell[c]
                            m[c] = v if (v > m[c] or v != v) else m[c]
            for c in range(C):
                o = out[k, c, p]
                for q in range(Q):
                    o[q] = row_out[q, c]


def roi_align(
    input: torch.Tensor,
    boxes: torch.Tensor | list[torch.Tensor],
    output_size: int | tuple[int, int],
    spatial_scale: float = 1.0,
    sampling_ratio: int = -1,
    aligned: bool = False,
) -> torch.Tensor:
    r"""RoI Align (He et al., Mask R-CNN 2017): average of bilinear samples on a regular
    grid in each of the ``output_size`` bins of each region, no quantization.

    A box :math:`(x_1, y_1, x_2, y_2)` in image pixels maps to the feature map as
    :math:`x s - o` with :math:`s` = ``spatial_scale`` and :math:`o = 0.5` when
    ``aligned`` (pixel centres at half-integers), else 0; without ``aligned`` a region
    is at least 1 x 1. Bin :math:`(p, q)` of a region of size :math:`h \times w`
    averages :math:`g_h g_w` samples at
    :math:`y = y_1 + p\,h/P + (i + \tfrac12)\,h/(P g_h)` (same in x), with
    :math:`g = ` ``sampling_ratio`` or, if it is <= 0, :math:`\lceil h / P \rceil`.
    A sample outside :math:`[-1, H] \times [-1, W]` counts as 0; one in the border
    band is clamped to the edge. This is torchvision's ``ops.roi_align`` and
    onnxruntime's ``RoiAlign`` (``coordinate_transformation_mode`` ``"half_pixel"`` =
    ``aligned=True``, ``"output_half_pixel"`` = ``aligned=False``, mode ``"avg"``;
    tested to 1e-5).

    The bilinear weights are separable, so each region is two small matrix products
    :math:`A_y F A_x^\top` (vectorized over regions, one loop over images);
    differentiable with respect to ``input``. Where no gradient is wanted (``input``
    without ``requires_grad``, or under ``torch.no_grad``/``inference_mode``, on the
    CPU, not while tracing) a compiled kernel computes the same sums over each
    region's window of the map only, in float64, parallel over regions, as
    onnxruntime's kernel does, on a channels-last copy of the map so that a cell's
    channels are one contiguous vector (512 regions of a 64 x 50 x 50 map: 95 -> 5 ms
    on one thread, about a third of onnxruntime's time; the two paths agree to float
    rounding, tested).

    Parameters
    ----------
    input : (N, C, H, W) torch.Tensor
    boxes : (K, 5) torch.Tensor or list of N (K_i, 4) torch.Tensor
        ``[batch_index, x1, y1, x2, y2]`` rows, or ``"xyxy"`` boxes per image.
    output_size : int or (P, Q)
    spatial_scale : float
        Feature-map pixels per image pixel (1/16 for a stride-16 backbone), > 0.
    sampling_ratio : int
        Samples per bin side; <= 0 for adaptive.
    aligned : bool

    Returns
    -------
    (K, C, P, Q) torch.Tensor
        A region whose samples all lie beyond the map is 0, however far (``1e31``).

    Raises
    ------
    InputError
        Bad features, boxes, sizes or parameters; adaptive sampling (``sampling_ratio``
        <= 0) of a box so large that a bin would take over :math:`2^{30}` samples per
        side (give a positive ``sampling_ratio``); a computation over 1 GiB.

    Examples
    --------
    >>> import torch
    >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> roi_align(x, torch.tensor([[0.0, 0.5, 0.5, 2.5, 2.5]]), 1, aligned=True).item()
    5.0
    """
    x = _check_feature(input)
    bidx, rois = _check_rois(boxes, x.shape[0])
    P, Q = _output_size(output_size)
    scale = check_real(spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False)
    ratio = check_int(sampling_ratio, "sampling_ratio")
    if ratio > 1024:
        raise InputError(
            f"sampling_ratio must be at most 1024 samples per bin side; got {ratio}: "
            "2 is the usual choice, <= 0 for adaptive"
        )
    ratio = max(ratio, 0)
    aligned = check_bool(aligned, "aligned")
    _, C, H, W = x.shape
    K = rois.shape[0]
    dt = x.dtype
    r = rois.detach().to(torch.float64) * scale - (0.5 if aligned else 0.0)
    rw = r[:, 2] - r[:, 0]
    rh = r[:, 3] - r[:, 1]
    if not aligned:
        rw, rh = rw.clamp(min=1.0), rh.clamp(min=1.0)
    if not bool(torch.isfinite(torch.stack([rw, rh])).all() and torch.isfinite(r).all()):
        raise InputError(
            "boxes times spatial_scale must be finite in float64; got coordinates beyond "
            f"1.8e308 (boxes up to {float(rois.detach().abs().max()):.3g}, spatial_scale "
            f"{scale:g}): drop those rows first"
        )
    if ratio > 0:
        gh = torch.full((K,), ratio, dtype=torch.long)
        gw = gh
    else:
        # a region whose samples all fall outside the map (beyond the -1 and H, W
        # margins) is 0 whatever its grid: one sample per bin says so
        out = _outside(r[:, 1], rh, H) | _outside(r[:, 0], rw, W)
        one = torch.ones_like(rh)
        # in float first: a huge box's grid overflows int64 (issue 47 R50)
        gh_f = torch.where(out, one, torch.ceil(rh / P))
        gw_f = torch.where(out, one, torch.ceil(rw / Q))
        most = max(float(gh_f.max()), float(gw_f.max())) if K else 1.0
        if most > 2**30:
            raise InputError(
                f"adaptive sampling (sampling_ratio <= 0) takes ceil(box side / output "
                f"size) = {most:.3g} samples per bin side for the largest box (in "
                "feature-map cells); give a positive sampling_ratio (2 is usual) or "
                "smaller boxes"
            )
        gh, gw = gh_f.long(), gw_f.long()
    gmax = max(int(gh.max()) if K else 1, int(gw.max()) if K else 1, 1)
    check_allocation(
        K * max(P * max(H, gmax), Q * max(W, gmax)) * 2 + K * C * P * W,
        8,
        f"the sampling of {K} regions",
        "use fewer or smaller boxes, a smaller spatial_scale, or a positive sampling_ratio",
    )
    if _compiled_forward(x):
        # no gradient wanted: the compiled forward (the regions' windows only, as
        # onnxruntime's kernel; the dense products below cost ten times the work)
        res = np.empty((K, C, P, Q), dtype=np.float32 if dt == torch.float32 else np.float64)
        # channels last, so that a cell's channels are one contiguous vector
        xt = np.ascontiguousarray(x.detach().numpy().transpose(0, 2, 3, 1))
        _roi_align_kernel(
            xt, bidx.cpu().numpy(), r.numpy(), rw.numpy(), rh.numpy(), gh.numpy(),
            gw.numpy(), res,
        )  # fmt: skip
        return torch.from_numpy(res)
    Ay = _align_weights(r[:, 1], rh, P, gh, H).to(dt)
    Ax = _align_weights(r[:, 0], rw, Q, gw, W).to(dt)
    parts, where = [], []
    for n in torch.unique(bidx).tolist():
        m = torch.nonzero(bidx == n)[:, 0]
        k = m.shape[0]
        # along y: one GEMM (k P, H) @ (H, C W); along x: k products (P C, W) @ (W, Q)
        t = Ay[m].reshape(k * P, H) @ x[n].transpose(0, 1).reshape(H, C * W)
        t = torch.bmm(t.reshape(k, P * C, W), Ax[m].transpose(1, 2))
        parts.append(t.reshape(k, P, C, Q).permute(0, 2, 1, 3))
        where.append(m)
    if not parts:
        return x.new_zeros((0, C, P, Q))
    order = torch.cat(where) if len(where) > 1 else where[0]
    out = torch.cat(parts) if len(parts) > 1 else parts[0]
    if bool((order != torch.arange(K)).any()):
        out = out[torch.argsort(order)]
    return out.contiguous()


def _round_half_away(v: torch.Tensor) -> torch.Tensor:
    return torch.sign(v) * torch.floor(v.abs() + 0.5)


def paste_masks(masks: torch.Tensor, boxes: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    r"""Paste ``M x M`` per-box masks (Mask R-CNN's 28 x 28 outputs) back into an image of
    ``size`` ``(H, W)``: the inverse of :func:`roi_align` with ``aligned=True``.

    Mask cell :math:`j` of a box :math:`(x_1, y_1, x_2, y_2)` is centred at
    :math:`x_1 + (j + \tfrac12)(x_2 - x_1)/M` (same in y). Image pixel :math:`(c, r)`,
    centred at :math:`(c + \tfrac12, r + \tfrac12)` in the same continuous coordinates,
    takes the bilinear interpolation of the mask at
    :math:`u = (c + \tfrac12 - x_1) M / (x_2 - x_1) - \tfrac12` (clamped to the edge
    cells) when its centre lies inside the box, and 0 outside it. torchvision's
    ``paste_masks_in_image`` resizes a zero-padded mask to the integer box instead, which
    spreads a mask half a cell beyond its box; here a mask of ones pastes exactly the
    pixels whose centres the box covers (tested).

    Parameters
    ----------
    masks : (D, M, M) or (D, 1, M, M) float torch.Tensor
        Probabilities (or logits) per box.
    boxes : (D, 4) float torch.Tensor
        ``"xyxy"`` pixels.
    size : (H, W)
        Image shape.

    Returns
    -------
    (D, H, W) torch.Tensor
        Of ``masks``' dtype.

    Raises
    ------
    InputError
        Masks not ``(D, M, M)`` floating point, boxes not ``(D, 4)`` ordered and finite,
        or a size that is not two positive ints.

    Examples
    --------
    >>> import torch
    >>> out = paste_masks(torch.ones(1, 4, 4), torch.tensor([[1.0, 0.5, 3.0, 2.4]]), (3, 4))
    >>> out[0].int().tolist()
    [[0, 1, 1, 0], [0, 1, 1, 0], [0, 0, 0, 0]]
    """
    if isinstance(masks, torch.Tensor) and masks.ndim == 4 and masks.shape[1] == 1:
        masks = masks[:, 0]
    if (
        not isinstance(masks, torch.Tensor)
        or masks.ndim != 3
        or masks.shape[1] < 1
        or masks.shape[2] < 1
        or not masks.is_floating_point()
    ):
        raise InputError(
            f"masks must be a (D, M, M) float torch.Tensor, one mask per box; got "
            f"{plain_repr(masks)}"
        )
    b = check_boxes(boxes, "boxes")
    if b.shape[0] != masks.shape[0]:
        raise InputError(
            f"masks and boxes must pair up: {masks.shape[0]} masks, {b.shape[0]} boxes"
        )
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
    ):
        raise InputError(f"size must be (H, W), two positive ints; got {plain_repr(size)}")
    h, w = int(size[0]), int(size[1])
    d = masks.shape[0]
    check_allocation(
        d * h * w,
        masks.element_size(),
        f"({d}, {h}, {w}) pasted masks",
        "use fewer boxes or a smaller image",
    )
    out = masks.new_zeros((d, h, w))
    mh, mw = masks.shape[1], masks.shape[2]
    bd = b.detach().to(torch.float64).cpu()
    for i in range(d):
        x1, y1, x2, y2 = (float(v) for v in bd[i])
        # pixels whose centres c + 1/2 lie in [x1, x2]
        c0, c1 = max(math.ceil(x1 - 0.5), 0), min(math.floor(x2 - 0.5), w - 1)
        r0, r1 = max(math.ceil(y1 - 0.5), 0), min(math.floor(y2 - 0.5), h - 1)
        if c1 < c0 or r1 < r0 or x2 <= x1 or y2 <= y1:
            continue
        dev = masks.device
        cx = torch.arange(c0, c1 + 1, dtype=torch.float64, device=dev) + 0.5
        cy = torch.arange(r0, r1 + 1, dtype=torch.float64, device=dev) + 0.5
        u = ((cx - x1) * mw / (x2 - x1) - 0.5).clamp(0, mw - 1)
        v = ((cy - y1) * mh / (y2 - y1) - 0.5).clamp(0, mh - 1)
        out[i, r0 : r1 + 1, c0 : c1 + 1] = _bilinear_grid(masks[i], v, u)
    return out


def _bilinear_grid(m: torch.Tensor, v: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    """``m`` (h, w) sampled bilinearly at rows ``v`` x columns ``u`` (both in range):
    the separable weights as two small matrix products ``A_v m A_u^T``."""

    def weights(t: torch.Tensor, n: int) -> torch.Tensor:
        lo = t.floor().long().clamp(max=n - 1)
        hi = (lo + 1).clamp(max=n - 1)
        f = t - lo.to(t.dtype)
        a = torch.zeros((t.shape[0], n), dtype=t.dtype, device=t.device)
        rows = torch.arange(t.shape[0], device=t.device)
        a.index_put_((rows, lo), 1.0 - f, accumulate=True)
        a.index_put_((rows, hi), f, accumulate=True)
        return a.to(m.dtype)

    return weights(v, m.shape[0]) @ m @ weights(u, m.shape[1]).T


def roi_pool(
    input: torch.Tensor,
    boxes: torch.Tensor | list[torch.Tensor],
    output_size: int | tuple[int, int],
    spatial_scale: float = 1.0,
) -> torch.Tensor:
    r"""RoI max pooling (Girshick, Fast R-CNN 2015) with torchvision's quantization.

    The box corners are scaled and rounded (half away from zero, C's ``round``):
    :math:`x_1' = \mathrm{round}(x_1 s)`, :math:`x_2' = \mathrm{round}(x_2 s)`, the
    region is :math:`w = \max(x_2' - x_1' + 1, 1)` cells wide; bin :math:`q` covers
    columns :math:`[\lfloor q w / Q \rfloor, \lceil (q + 1) w / Q \rceil)` offset by
    :math:`x_1'` and clipped to the map (same in y), and holds the maximum there, or 0
    for an empty bin. Differentiable with respect to ``input`` (the gradient of a max
    goes to the arg-max; ties share it, where torchvision gives it to the first).
    Without a gradient to keep, on a CPU float input, the forward is a compiled loop
    over each bin's window (onnxruntime's ``MaxRoiPool``, equal to it; tested), not the
    gathered windows the gradient needs: the map is copied channels last (one pass over
    it), so that each window cell's channels are one contiguous vector max (about four
    times onnxruntime's speed on 512 regions of a 64-channel map, ``python -m benchmarks
    nn_ops``).

    Parameters
    ----------
    input : (N, C, H, W) torch.Tensor
    boxes : (K, 5) torch.Tensor or list of N (K_i, 4) torch.Tensor
        As in :func:`roi_align`.
    output_size : int or (P, Q)
    spatial_scale : float
        > 0.

    Returns
    -------
    (K, C, P, Q) torch.Tensor

    Examples
    --------
    >>> import torch
    >>> x = torch.arange(16.0).reshape(1, 1, 4, 4)
    >>> roi_pool(x, [torch.tensor([[0.0, 0.0, 3.0, 3.0]])], 2)[0, 0].tolist()
    [[5.0, 7.0], [13.0, 15.0]]
    """
    x = _check_feature(input)
    bidx, rois = _check_rois(boxes, x.shape[0])
    P, Q = _output_size(output_size)
    scale = check_real(spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False)
    _, C, H, W = x.shape
    K = rois.shape[0]
    r = _round_half_away(rois.detach().to(torch.float64) * scale)

    def bands(
        lo: torch.Tensor, hi: torch.Tensor, bins: int, length: int
    ) -> tuple[torch.Tensor, torch.Tensor]:
        size = (hi - lo + 1).clamp(min=1)
        b = size / bins
        p = torch.arange(bins, dtype=torch.float64)
        start = torch.floor(p[None] * b[:, None]) + lo[:, None]
        end = torch.ceil((p[None] + 1) * b[:, None]) + lo[:, None]
        return start.clamp(0, length).long(), end.clamp(0, length).long()

    hs, he = bands(r[:, 1], r[:, 3], P, H)
    ws, we = bands(r[:, 0], r[:, 2], Q, W)
    if _compiled_forward(x):  # each bin's window only (as onnxruntime's MaxRoiPool)
        res = np.empty((K, C, P, Q), dtype=np.float32 if x.dtype == torch.float32 else np.float64)
        # channels last, so that a window cell's channels are one contiguous vector
        xt = np.ascontiguousarray(x.detach().numpy().transpose(0, 2, 3, 1))
        _roi_pool_kernel(
            xt, bidx.cpu().numpy(), hs.numpy(), he.numpy(), ws.numpy(), we.numpy(), res
        )
        return torch.from_numpy(res)
    hb = max(int((he - hs).max()) if K else 1, 1)
    wb = max(int((we - ws).max()) if K else 1, 1)
    check_allocation(
        K * C * P * hb * Q * wb,
        x.element_size(),
        f"the bins of {K} regions",
        "use fewer or smaller boxes or a smaller spatial_scale",
    )
    iy = hs[..., None] + torch.arange(hb)  # (K, P, hb)
    ix = ws[..., None] + torch.arange(wb)
    my = iy < he[..., None]
    mx = ix < we[..., None]
    iy = iy.clamp(max=H - 1)
    ix = ix.clamp(max=W - 1)
    out = x.new_zeros((K, C, P, Q))
    for n in torch.unique(bidx).tolist():
        m = torch.nonzero(bidx == n)[:, 0]
        # (C, k, P, hb, Q, wb)
        vals = x[n][:, iy[m][:, :, :, None, None], ix[m][:, None, None, :, :]]
        mask = my[m][:, :, :, None, None] & mx[m][:, None, None, :, :]
        vals = vals.masked_fill(~mask, float("-inf"))
        mx_ = vals.amax(dim=(3, 5))  # (C, k, P, Q)
        empty = ~mask.any(dim=4).any(dim=2)  # (k, P, Q)
        mx_ = mx_.masked_fill(empty[None], 0.0)
        out = out.index_copy(0, m, mx_.permute(1, 0, 2, 3))
    return out


class RoIAlign(torch.nn.Module):
    """:func:`roi_align` as a module (its parameters fixed at construction, checked then).

    Parameters
    ----------
    output_size : int or (P, Q)
    spatial_scale : float
    sampling_ratio : int
    aligned : bool

    Examples
    --------
    >>> import torch
    >>> layer = RoIAlign(2, spatial_scale=0.5, sampling_ratio=2, aligned=True)
    >>> layer(torch.zeros(1, 3, 8, 8), [torch.tensor([[0.0, 0.0, 8.0, 8.0]])]).shape
    torch.Size([1, 3, 2, 2])
    """

    def __init__(
        self,
        output_size: int | tuple[int, int],
        spatial_scale: float = 1.0,
        sampling_ratio: int = -1,
        aligned: bool = False,
    ) -> None:
        super().__init__()
        self.output_size = _output_size(output_size)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )
        self.sampling_ratio = check_int(sampling_ratio, "sampling_ratio")
        self.aligned = check_bool(aligned, "aligned")

    def forward(
        self, input: torch.Tensor, boxes: torch.Tensor | list[torch.Tensor]
    ) -> torch.Tensor:
        """:func:`roi_align` of ``input`` ``(N, C, H, W)`` over ``boxes``: ``(K, C, P, Q)``."""
        return roi_align(
            input, boxes, self.output_size, self.spatial_scale, self.sampling_ratio, self.aligned
        )

    def extra_repr(self) -> str:
        return (
            f"output_size={self.output_size}, spatial_scale={self.spatial_scale}, "
            f"sampling_ratio={self.sampling_ratio}, aligned={self.aligned}"
        )


class RoIPool(torch.nn.Module):
    """:func:`roi_pool` as a module.

    Parameters
    ----------
    output_size : int or (P, Q)
    spatial_scale : float

    Examples
    --------
    >>> import torch
    >>> RoIPool((2, 3))(torch.ones(1, 1, 6, 6), torch.tensor([[0.0, 0, 0, 5, 5]])).shape
    torch.Size([1, 1, 2, 3])
    """

    def __init__(self, output_size: int | tuple[int, int], spatial_scale: float = 1.0) -> None:
        super().__init__()
        self.output_size = _output_size(output_size)
        self.spatial_scale = check_real(
            spatial_scale, "spatial_scale", 0.0, 1e6, low_inclusive=False
        )

    def forward(
        self, input: torch.Tensor, boxes: torch.Tensor | list[torch.Tensor]
    ) -> torch.Tensor:
        """:func:`roi_pool` of ``input`` ``(N, C, H, W)`` over ``boxes``: ``(K, C, P, Q)``."""
        return roi_pool(input, boxes, self.output_size, self.spatial_scale)

    def extra_repr(self) -> str:
        return f"output_size={self.output_size}, spatial_scale={self.spatial_scale}"
