r"""Convolution and pooling from the mathematics, in NumPy (no torch needed).

The layer arithmetic of a convolutional network, written so that each line is the
formula of the course and checked against :mod:`torch.nn.functional` to 1e-5:

- :func:`im2col` unrolls every receptive field of an ``(N, C, H, W)`` batch into a
  column, so that a convolution becomes one matrix product (``F.unfold``);
- :func:`conv2d` (stride, padding, dilation, groups) is that matrix product
  (``F.conv2d``), and :func:`conv_transpose2d` its adjoint, the scatter of each input
  pixel times the kernel into the output (``F.conv_transpose2d``);
- :func:`max_pool2d`, :func:`avg_pool2d` and :func:`sum_pool2d` reduce each window
  (``F.max_pool2d``, ``F.avg_pool2d``; sum pooling is average pooling times
  ``kh * kw``);
- :func:`conv_output_size`, :func:`receptive_field` and :func:`parameter_count` are the
  bookkeeping: how big the output is, what each output pixel sees, and what it costs.

Conventions are torch's: tensors are NCHW (channels first), weights of a convolution are
``(O, C / groups, kh, kw)`` and of a transposed convolution ``(C, O / groups, kh, kw)``;
a convolution is a cross-correlation (the kernel is not flipped). ``kernel_size``,
``stride``, ``padding`` and ``dilation`` are an int or an ``(h, w)`` pair. An unbatched
``(C, H, W)`` input gives an unbatched output, as in torch. Floating-point inputs keep
their dtype (float32 stays float32); integer inputs are computed in float64.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_magnitude, check_ndim
from robopercept.errors import InputError
from robopercept.nn._guards import check_allocation

__all__ = [
    "ConvSpec",
    "ReceptiveField",
    "avg_pool2d",
    "conv2d",
    "conv_output_size",
    "conv_transpose2d",
    "im2col",
    "max_pool2d",
    "parameter_count",
    "receptive_field",
    "sum_pool2d",
]

IntPair = int | tuple[int, int]


# --------------------------------------------------------------------------- checks


#: the largest size, kernel, stride, padding or dilation (NumPy strides are C longs)
MAX_GEOMETRY = 2**31 - 1


def _pair(
    value: object, name: str, minimum: int, maximum: int | None = MAX_GEOMETRY
) -> tuple[int, int]:
    """``value`` (an int or a pair of ints) as a pair, each in ``[minimum, maximum]``
    (``maximum=None``: pure arithmetic, no bound)."""
    items = tuple(value) if isinstance(value, (tuple, list)) else (value, value)
    if len(items) != 2 or not all(
        isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in items
    ):
        raise InputError(f"{name} must be an int or a pair of ints (h, w); got {value!r}")
    h, w = int(items[0]), int(items[1])
    if h < minimum or w < minimum:
        raise InputError(f"{name} must be >= {minimum}; got {value!r}")
    if maximum is not None and (h > maximum or w > maximum):
        raise InputError(f"{name} must be at most 2**31 - 1 (pixels); got {value!r}")
    return h, w


def _batch(x: npt.ArrayLike, name: str = "x") -> tuple[np.ndarray, bool]:
    """``x`` as a float ``(N, C, H, W)`` array and whether it came unbatched ``(C, H, W)``."""
    arr = check_ndim(x, name, (3, 4))
    if arr.dtype.kind not in "fiub":
        raise InputError(f"{name} must be a real numeric array; got dtype {arr.dtype}")
    if arr.dtype.kind != "f":
        arr = arr.astype(np.float64)
    unbatched = arr.ndim == 3
    return (arr[None] if unbatched else arr), unbatched


def _weights(w: npt.ArrayLike) -> np.ndarray:
    """``w`` as a real numeric 4-D array."""
    arr = check_ndim(w, "w", (4,))
    if arr.dtype.kind not in "fiub":
        raise InputError(f"w must be a real numeric array; got dtype {arr.dtype}")
    return arr


def _out_dtype(*arrays: np.ndarray) -> np.dtype:
    return np.result_type(*[a.dtype for a in arrays], np.float32)


def _check_products(dtype: np.dtype, **arrays: np.ndarray) -> None:
    """Refuse inputs whose products overflow ``dtype``: each value must stay within
    ``sqrt(max) / 1e4`` (about 1e150 in float64, 2e15 in float32), so that a product is
    below ``max / 1e8`` and a sum of up to 1e8 of them stays finite."""
    limit = float(np.sqrt(np.finfo(dtype).max)) / 1e4
    for name, arr in arrays.items():
        check_magnitude(arr, name, limit)


def _size(n: int, k: int, s: int, p: int, d: int, axis: str, flag: str) -> int:
    """``floor((n + 2p - d(k-1) - 1) / s) + 1``, refused when the window does not fit."""
    span = d * (k - 1) + 1
    if n + 2 * p < span:
        raise InputError(
            f"kernel (dilated extent {span}) is bigger than the padded input {axis} "
            f"{n} + 2*{p} = {n + 2 * p}: use a smaller {flag}kernel_size or dilation, "
            "more padding, or a larger input"
        )
    return (n + 2 * p - span) // s + 1


# --------------------------------------------------------------------------- im2col


def _windows(
    xp: np.ndarray, k: tuple[int, int], s: tuple[int, int], d: tuple[int, int], out: tuple[int, int]
) -> np.ndarray:
    """All windows of the padded ``xp`` as ``(N, C, kh, kw, Ho, Wo)`` (a strided view)."""
    n, c, _, _ = xp.shape
    sn, sc, sh, sw = xp.strides
    return np.lib.stride_tricks.as_strided(
        xp,
        shape=(n, c, k[0], k[1], out[0], out[1]),
        strides=(sn, sc, sh * d[0], sw * d[1], sh * s[0], sw * s[1]),
        writeable=False,
    )


def _padded_windows(
    x: np.ndarray,
    k: tuple[int, int],
    s: tuple[int, int],
    p: tuple[int, int],
    d: tuple[int, int],
    fill: float = 0.0,
) -> np.ndarray:
    ho = _size(x.shape[2], k[0], s[0], p[0], d[0], "height", "")
    wo = _size(x.shape[3], k[1], s[1], p[1], d[1], "width", "")
    n, c, h, w = x.shape
    check_allocation(
        n * c * (h + 2 * p[0]) * (w + 2 * p[1]),
        x.itemsize,
        f"the padded input ({n}, {c}, {h + 2 * p[0]}, {w + 2 * p[1]})",
        "lower padding",
    )
    check_allocation(
        n * c * k[0] * k[1] * ho * wo,
        x.itemsize,
        f"the unrolled windows ({n}, {c} * {k[0]} * {k[1]}, {ho} * {wo})",
        "lower kernel_size or padding, raise the stride, or pass fewer images at a time",
    )
    xp = np.pad(x, ((0, 0), (0, 0), (p[0], p[0]), (p[1], p[1])), constant_values=fill)
    return _windows(xp, k, s, d, (ho, wo))


def im2col(
    x: npt.ArrayLike,
    kernel_size: IntPair,
    stride: IntPair = 1,
    padding: IntPair = 0,
    dilation: IntPair = 1,
) -> np.ndarray:
    r"""Unroll every receptive field of a batch into a column (``torch.nn.functional.unfold``).

    Column ``l = i * W_out + j`` holds the input values that output pixel ``(i, j)`` sees:

    .. math::

        \mathrm{col}[n, (c, a, b), l] = x_p[n, c, i s_h + a d_h, j s_w + b d_w]

    for ``a < kh``, ``b < kw``, where ``x_p`` is ``x`` zero-padded by ``padding`` on each
    side. A convolution with weights ``w`` of shape ``(O, C, kh, kw)`` is then the matrix
    product ``w.reshape(O, -1) @ col``.

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    kernel_size, stride, padding, dilation : int or (int, int)
        Window geometry, as in ``F.unfold``.

    Returns
    -------
    (N, C * kh * kw, H_out * W_out) ndarray
        The columns (``(C * kh * kw, L)`` for an unbatched input), equal to
        ``F.unfold(x, kernel_size, dilation, padding, stride)``.

    Raises
    ------
    InputError
        If ``x`` is not 3-D or 4-D, or the dilated kernel is bigger than the padded input.

    Examples
    --------
    >>> x = np.arange(9.0).reshape(1, 1, 3, 3)
    >>> im2col(x, 2)[0]
    array([[0., 1., 3., 4.],
           [1., 2., 4., 5.],
           [3., 4., 6., 7.],
           [4., 5., 7., 8.]])
    """
    xb, unbatched = _batch(x)
    k = _pair(kernel_size, "kernel_size", 1)
    s = _pair(stride, "stride", 1)
    p = _pair(padding, "padding", 0)
    d = _pair(dilation, "dilation", 1)
    win = _padded_windows(xb, k, s, p, d)
    n, c, kh, kw, ho, wo = win.shape
    cols = win.reshape(n, c * kh * kw, ho * wo)
    return cols[0] if unbatched else cols


# --------------------------------------------------------------------------- convolution


def _check_groups(c_in: int, c_out: int, groups: int, what: str) -> None:
    if c_in % groups or c_out % groups:
        gcd = math.gcd(c_in, c_out)
        if gcd <= 4096:
            among = f"among the common divisors {[g for g in range(1, gcd + 1) if not gcd % g]}"
        else:
            among = f"a divisor of gcd({c_in}, {c_out}) = {gcd}"
        raise InputError(
            f"groups={groups} must divide both the input channels ({c_in}) and the "
            f"output channels ({c_out}) of the {what}: choose groups {among}"
        )


def _check_bias(b: npt.ArrayLike | None, c_out: int) -> np.ndarray | None:
    if b is None:
        return None
    arr = check_ndim(b, "bias", (0, 1, 2, 3, 4))
    if arr.shape != (c_out,):
        raise InputError(
            f"bias must have shape ({c_out},), one value per output channel; got {arr.shape}"
        )
    if arr.dtype.kind not in "fiub":
        raise InputError(f"bias must be a real numeric array; got dtype {arr.dtype}")
    return arr


def _channels_hint(x: np.ndarray, expected: int) -> str:
    if x.shape[-1] == expected:
        return ": channels-last (N, H, W, C)? use x.transpose(0, 3, 1, 2)"
    return ": pass an input with that many channels or weights made for this input"


def conv2d(
    x: npt.ArrayLike,
    w: npt.ArrayLike,
    b: npt.ArrayLike | None = None,
    stride: IntPair = 1,
    padding: IntPair = 0,
    dilation: IntPair = 1,
    groups: int = 1,
) -> np.ndarray:
    r"""2-D convolution (cross-correlation) by im2col, as ``torch.nn.functional.conv2d``.

    .. math::

        y[n, o, i, j] = b[o] + \sum_{c, a, b'} w[o, c, a, b']\,
            x_p[n, g(o) C_g + c, i s_h + a d_h, j s_w + b' d_w]

    where ``x_p`` is ``x`` zero-padded by ``padding``, ``C_g = C / groups`` and ``g(o)``
    is the group of output channel ``o`` (outputs ``O / groups`` per group). It is
    computed as one matrix product per group: ``W_g (O_g, C_g kh kw) @ im2col(x_g)``. The
    output size per axis is ``floor((n + 2p - d(k-1) - 1) / s) + 1``
    (:func:`conv_output_size`).

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    w : (O, C / groups, kh, kw) array_like
        Kernels, torch's layout.
    b : (O,) array_like, optional
        Bias per output channel.
    stride, padding, dilation : int or (int, int)
        As in ``F.conv2d`` (``padding`` is zeros on each side).
    groups : int
        Number of channel groups (``groups = C`` is a depthwise convolution).

    Returns
    -------
    (N, O, H_out, W_out) ndarray
        Equal to ``F.conv2d(x, w, b, stride, padding, dilation, groups)`` to float
        rounding (1e-5 in float32).

    Raises
    ------
    InputError
        Channel count of ``x`` not ``groups * w.shape[1]`` (channels-last input is
        recognized), ``groups`` not dividing the channels, a bias of the wrong length, or a
        kernel bigger than the padded input.

    Examples
    --------
    A 3x3 box filter on a 4x4 ramp, no padding:

    >>> x = np.arange(16.0).reshape(1, 1, 4, 4)
    >>> conv2d(x, np.ones((1, 1, 3, 3)))
    array([[[[45., 54.],
             [81., 90.]]]])
    >>> conv2d(x, np.ones((1, 1, 3, 3)), padding=1, stride=2).shape
    (1, 1, 2, 2)
    """
    xb, unbatched = _batch(x)
    wa = _weights(w)
    g = _pair(groups, "groups", 1)[0]
    o, cg, kh, kw = wa.shape
    c = xb.shape[1]
    _check_groups(c, o, g, "convolution")
    if c != cg * g:
        raise InputError(
            f"x has {c} channels but the weights expect groups * w.shape[1] = {g} * {cg} = "
            f"{cg * g}{_channels_hint(xb, cg * g)}"
        )
    bias = _check_bias(b, o)
    s = _pair(stride, "stride", 1)
    p = _pair(padding, "padding", 0)
    d = _pair(dilation, "dilation", 1)
    dtype = _out_dtype(xb, wa)
    _check_products(dtype, x=xb, w=wa)
    win = _padded_windows(xb.astype(dtype, copy=False), (kh, kw), s, p, d)
    n, _, _, _, ho, wo = win.shape
    cols = win.reshape(n, g, cg * kh * kw, ho * wo)  # copies the strided view once
    wg = wa.astype(dtype, copy=False).reshape(g, o // g, cg * kh * kw)
    y = np.einsum("gok,ngkl->ngol", wg, cols, optimize=True).reshape(n, o, ho, wo)
    if bias is not None:
        y = y + bias.astype(dtype, copy=False)[None, :, None, None]
    return y[0] if unbatched else y


def conv_transpose2d(
    x: npt.ArrayLike,
    w: npt.ArrayLike,
    b: npt.ArrayLike | None = None,
    stride: IntPair = 1,
    padding: IntPair = 0,
    output_padding: IntPair = 0,
    *,
    dilation: IntPair = 1,
    groups: int = 1,
) -> np.ndarray:
    r"""Transposed convolution, as ``torch.nn.functional.conv_transpose2d``.

    The adjoint of :func:`conv2d` with the same ``stride``, ``padding`` and ``dilation``:
    each input pixel scatters itself times the kernel into the output,

    .. math::

        y_{full}[n, g O_g + o, i s_h + a d_h, j s_w + b' d_w] \mathrel{+}=
            \sum_{c} w[g C_g + c, o, a, b']\, x[n, g C_g + c, i, j]

    and ``y = y_full[..., p_h : p_h + H_out, p_w : p_w + W_out] + b`` with
    ``H_out = (H - 1) s - 2p + d (k - 1) + output_padding + 1`` (col2im, the adjoint of
    :func:`im2col`). ``output_padding`` (``< max(stride, dilation)``, as torch requires)
    picks among the input sizes that a strided convolution maps to the same output size.

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    w : (C, O / groups, kh, kw) array_like
        Kernels in torch's transposed layout (input channels first).
    b : (O,) array_like, optional
        Bias per output channel.
    stride, padding, output_padding : int or (int, int)
        As in ``F.conv_transpose2d``.
    dilation : int or (int, int), keyword-only
        Kernel dilation.
    groups : int, keyword-only
        Number of channel groups. ``dilation`` and ``groups`` are keyword-only because
        torch's positional order (``groups`` before ``dilation``) differs from
        :func:`conv2d`'s; naming them avoids a silent swap.

    Returns
    -------
    (N, O, H_out, W_out) ndarray
        Equal to ``F.conv_transpose2d(x, w, b, stride, padding, output_padding, groups,
        dilation)`` to float rounding.

    Raises
    ------
    InputError
        Channel count of ``x`` not ``w.shape[0]``, ``groups`` not dividing it, a bias of
        the wrong length, ``output_padding`` too large, or an empty output.

    Examples
    --------
    A stride-2 transposed convolution with a 2x2 kernel of ones copies each pixel into a
    2x2 block (nearest-neighbour upsampling):

    >>> x = np.array([[[[1.0, 2.0], [3.0, 4.0]]]])
    >>> conv_transpose2d(x, np.ones((1, 1, 2, 2)), stride=2)[0, 0]
    array([[1., 1., 2., 2.],
           [1., 1., 2., 2.],
           [3., 3., 4., 4.],
           [3., 3., 4., 4.]])
    """
    xb, unbatched = _batch(x)
    wa = _weights(w)
    g = _pair(groups, "groups", 1)[0]
    cw, og, kh, kw = wa.shape
    n, c, h, wd = xb.shape
    if c != cw:
        raise InputError(
            f"x has {c} channels but the transposed-convolution weights (C, O / groups, kh, "
            f"kw) expect w.shape[0] = {cw}{_channels_hint(xb, cw)}"
        )
    o = og * g
    _check_groups(c, o, g, "transposed convolution")
    bias = _check_bias(b, o)
    s = _pair(stride, "stride", 1)
    p = _pair(padding, "padding", 0)
    op = _pair(output_padding, "output_padding", 0)
    d = _pair(dilation, "dilation", 1)
    for ax in range(2):
        if op[ax] >= max(s[ax], d[ax]):
            raise InputError(
                f"output_padding {op} must be smaller than stride {s} or dilation {d} on "
                "each axis: lower output_padding or raise the stride"
            )
    out = conv_output_size((h, wd), (kh, kw), s, p, d, transposed=True, output_padding=op)
    assert isinstance(out, tuple)  # pairs in, a pair out
    dtype = _out_dtype(xb, wa)
    _check_products(dtype, x=xb, w=wa)
    full_h = (h - 1) * s[0] + d[0] * (kh - 1) + 1 + op[0]
    full_w = (wd - 1) * s[1] + d[1] * (kw - 1) + 1 + op[1]
    itemsize = np.dtype(dtype).itemsize
    fix = "lower stride, dilation or output_padding, or pass fewer images at a time"
    check_allocation(
        n * o * full_h * full_w, itemsize, f"the output ({n}, {o}, {full_h}, {full_w})", fix
    )
    check_allocation(
        n * o * kh * kw * h * wd,
        itemsize,
        f"the scattered taps ({n}, {o}, {kh}, {kw}, {h}, {wd})",
        fix,
    )
    xg = xb.astype(dtype, copy=False).reshape(n, g, c // g, h * wd)
    wg = wa.astype(dtype, copy=False).reshape(g, c // g, og * kh * kw)
    cols = np.einsum("gck,ngcl->ngkl", wg, xg, optimize=True).reshape(n, o, kh, kw, h, wd)
    full = np.zeros((n, o, full_h, full_w), dtype=dtype)
    for a in range(kh):  # col2im: scatter-add each kernel tap (kh * kw vectorized adds)
        for bb in range(kw):
            r0, c0 = a * d[0], bb * d[1]
            full[
                :, :, r0 : r0 + s[0] * (h - 1) + 1 : s[0], c0 : c0 + s[1] * (wd - 1) + 1 : s[1]
            ] += cols[:, :, a, bb]
    y = full[:, :, p[0] : p[0] + out[0], p[1] : p[1] + out[1]]
    if bias is not None:
        y = y + bias.astype(dtype, copy=False)[None, :, None, None]
    y = np.ascontiguousarray(y)
    return y[0] if unbatched else y


# --------------------------------------------------------------------------- pooling


def _pool_args(
    kernel_size: IntPair, stride: IntPair | None, padding: IntPair, dilation: IntPair
) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int], tuple[int, int]]:
    k = _pair(kernel_size, "kernel_size", 1)
    s = k if stride is None else _pair(stride, "stride", 1)
    p = _pair(padding, "padding", 0)
    d = _pair(dilation, "dilation", 1)
    if p[0] > k[0] // 2 or p[1] > k[1] // 2:
        raise InputError(
            f"padding {p} must be at most half the kernel size {k} (torch's rule: a window "
            "must never lie entirely in the padding): lower padding or enlarge kernel_size"
        )
    return k, s, p, d


def max_pool2d(
    x: npt.ArrayLike,
    kernel_size: IntPair,
    stride: IntPair | None = None,
    padding: IntPair = 0,
    dilation: IntPair = 1,
) -> np.ndarray:
    r"""Max pooling, as ``torch.nn.functional.max_pool2d`` (``ceil_mode=False``).

    .. math::

        y[n, c, i, j] = \max_{a < k_h,\, b < k_w} x_p[n, c, i s_h + a d_h, j s_w + b d_w]

    where ``x_p`` is ``x`` padded with ``-inf`` (padding never wins). ``stride`` defaults
    to ``kernel_size``; output size per axis ``floor((n + 2p - d(k-1) - 1) / s) + 1``.

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    kernel_size, stride, padding, dilation : int or (int, int)
        As in ``F.max_pool2d``; ``padding <= kernel_size // 2``.

    Returns
    -------
    (N, C, H_out, W_out) ndarray
        Equal to ``F.max_pool2d(x, kernel_size, stride, padding, dilation)``.

    Raises
    ------
    InputError
        Padding above half the kernel, or a window bigger than the padded input.

    Examples
    --------
    >>> x = np.arange(16.0).reshape(1, 1, 4, 4)
    >>> max_pool2d(x, 2)[0, 0]
    array([[ 5.,  7.],
           [13., 15.]])
    """
    xb, unbatched = _batch(x)
    k, s, p, d = _pool_args(kernel_size, stride, padding, dilation)
    win = _padded_windows(xb, k, s, p, d, fill=-np.inf)
    y = win.max(axis=(2, 3))
    return y[0] if unbatched else y


def sum_pool2d(
    x: npt.ArrayLike,
    kernel_size: IntPair,
    stride: IntPair | None = None,
    padding: IntPair = 0,
) -> np.ndarray:
    r"""Sum pooling: the sum of each window of the zero-padded input.

    .. math::

        y[n, c, i, j] = \sum_{a < k_h,\, b < k_w} x_p[n, c, i s_h + a, j s_w + b]

    It is a depthwise convolution with a kernel of ones, and equals
    ``kh * kw * F.avg_pool2d(x, kernel_size, stride, padding)`` (torch has no sum pool).

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    kernel_size, stride, padding : int or (int, int)
        Window geometry; ``stride`` defaults to ``kernel_size``,
        ``padding <= kernel_size // 2``.

    Returns
    -------
    (N, C, H_out, W_out) ndarray
        Window sums.

    Raises
    ------
    InputError
        Padding above half the kernel, or a window bigger than the padded input.

    Examples
    --------
    >>> sum_pool2d(np.ones((1, 1, 4, 4)), 2, padding=1)[0, 0]
    array([[1., 2., 1.],
           [2., 4., 2.],
           [1., 2., 1.]])
    """
    xb, unbatched = _batch(x)
    k, s, p, d = _pool_args(kernel_size, stride, padding, 1)
    y = _padded_windows(xb, k, s, p, d).sum(axis=(2, 3))
    return y[0] if unbatched else y


def avg_pool2d(
    x: npt.ArrayLike,
    kernel_size: IntPair,
    stride: IntPair | None = None,
    padding: IntPair = 0,
    count_include_pad: bool = True,
) -> np.ndarray:
    r"""Average pooling, as ``torch.nn.functional.avg_pool2d`` (``ceil_mode=False``).

    .. math::

        y[n, c, i, j] = \frac{1}{|W_{ij}|} \sum_{(r, q) \in W_{ij}} x_p[n, c, r, q]

    with ``W_ij`` the ``kh x kw`` window of output ``(i, j)`` on the zero-padded input.
    With ``count_include_pad=True`` (torch's default) the divisor is ``kh * kw`` even
    where the window overlaps the padding; with ``False`` it counts only real pixels.

    Parameters
    ----------
    x : (N, C, H, W) or (C, H, W) array_like
        Input batch, channels first.
    kernel_size, stride, padding : int or (int, int)
        As in ``F.avg_pool2d``; ``stride`` defaults to ``kernel_size``.
    count_include_pad : bool
        Whether padded zeros count in the divisor.

    Returns
    -------
    (N, C, H_out, W_out) ndarray
        Equal to ``F.avg_pool2d(x, kernel_size, stride, padding,
        count_include_pad=count_include_pad)``.

    Raises
    ------
    InputError
        Padding above half the kernel, or a window bigger than the padded input.

    Examples
    --------
    >>> avg_pool2d(np.ones((1, 1, 2, 2)), 2, stride=1, padding=1)[0, 0]
    array([[0.25, 0.5 , 0.25],
           [0.5 , 1.  , 0.5 ],
           [0.25, 0.5 , 0.25]])
    >>> avg_pool2d(np.ones((1, 1, 2, 2)), 2, stride=1, padding=1, count_include_pad=False)[0, 0]
    array([[1., 1., 1.],
           [1., 1., 1.],
           [1., 1., 1.]])
    """
    xb, unbatched = _batch(x)
    k, s, p, _ = _pool_args(kernel_size, stride, padding, 1)
    total = sum_pool2d(xb, k, s, p)
    if count_include_pad:
        y = total / (k[0] * k[1])
    else:
        ones = np.ones((1, 1, *xb.shape[2:]), dtype=xb.dtype)
        y = total / sum_pool2d(ones, k, s, p)
    y = y.astype(xb.dtype, copy=False)
    return y[0] if unbatched else y


# --------------------------------------------------------------------------- bookkeeping


def conv_output_size(
    size: IntPair,
    kernel: IntPair,
    stride: IntPair = 1,
    padding: IntPair = 0,
    dilation: IntPair = 1,
    *,
    transposed: bool = False,
    output_padding: IntPair = 0,
) -> int | tuple[int, int]:
    r"""Output size of a convolution or pooling layer along each axis.

    .. math::

        n_{out} = \left\lfloor \frac{n + 2p - d(k-1) - 1}{s} \right\rfloor + 1

    and for a transposed convolution (``transposed=True``)

    .. math::

        n_{out} = (n - 1)s - 2p + d(k-1) + \mathrm{output\_padding} + 1

    the sizes of ``torch.nn.Conv2d`` / ``MaxPool2d`` (``ceil_mode=False``) and
    ``ConvTranspose2d`` documentation.

    Parameters
    ----------
    size : int or (int, int)
        Input size ``n`` (or ``(H, W)``).
    kernel, stride, padding, dilation : int or (int, int)
        Layer geometry.
    transposed : bool
        Use the transposed-convolution formula.
    output_padding : int or (int, int)
        Extra size on one side, transposed only.

    Returns
    -------
    int or (int, int)
        The output size: an int when every argument is an int, else an ``(h, w)`` pair.

    Raises
    ------
    InputError
        If the output would be empty (a kernel bigger than the padded input).

    Examples
    --------
    >>> conv_output_size(32, 3, stride=2, padding=1)
    16
    >>> conv_output_size((28, 28), 5)
    (24, 24)
    >>> conv_output_size(16, 4, stride=2, padding=1, transposed=True)
    32
    """
    args = (size, kernel, stride, padding, dilation, output_padding)
    scalar = all(not isinstance(a, (tuple, list)) for a in args)
    n = _pair(size, "size", 1)
    k = _pair(kernel, "kernel", 1)
    s = _pair(stride, "stride", 1)
    p = _pair(padding, "padding", 0)
    d = _pair(dilation, "dilation", 1)
    op = _pair(output_padding, "output_padding", 0)
    out = []
    for ax, axis in enumerate(("height", "width")):
        if transposed:
            m = (n[ax] - 1) * s[ax] - 2 * p[ax] + d[ax] * (k[ax] - 1) + op[ax] + 1
            if m < 1:
                raise InputError(
                    f"transposed convolution output {axis} would be {m}: lower the padding "
                    f"({p[ax]}) or raise the stride or kernel"
                )
        else:
            m = _size(n[ax], k[ax], s[ax], p[ax], d[ax], axis, "")
        out.append(m)
    return out[0] if scalar else (out[0], out[1])


@dataclass(frozen=True)
class ConvSpec:
    """The shape of one convolution layer, for :func:`parameter_count` and
    :func:`receptive_field` (the arguments of ``torch.nn.Conv2d``).

    Attributes
    ----------
    in_channels, out_channels : int
        Channels in and out.
    kernel_size : int or (int, int)
        Kernel size.
    stride, padding, dilation : int or (int, int)
        Geometry (used by :func:`receptive_field`).
    groups : int
        Channel groups.
    bias : bool
        Whether the layer has a bias per output channel.
    """

    in_channels: int
    out_channels: int
    kernel_size: IntPair
    stride: IntPair = 1
    padding: IntPair = 0
    dilation: IntPair = 1
    groups: int = 1
    bias: bool = True


@dataclass(frozen=True)
class ReceptiveField:
    """Receptive field after one layer of a stack, along one axis (:func:`receptive_field`).

    Attributes
    ----------
    kernel, stride, padding, dilation : int
        The layer.
    size : int
        ``r``: how many input pixels one output pixel sees.
    jump : int
        ``j``: distance in input pixels between two neighbouring outputs.
    start : float
        Input coordinate of the centre of the first output's field (pixel centres at
        integers, the first input pixel at 0; negative when it reaches into the padding).
    """

    kernel: int
    stride: int
    padding: int
    dilation: int
    size: int
    jump: int
    start: float

    def span(self, index: int) -> tuple[float, float]:
        """First and last input coordinate seen by output ``index`` (may reach padding).

        Parameters
        ----------
        index : int
            Output pixel index along the axis.

        Returns
        -------
        (float, float)
            ``start + index * jump -+ (size - 1) / 2``.
        """
        centre = self.start + index * self.jump
        half = (self.size - 1) / 2
        return centre - half, centre + half


LayerLike = ConvSpec | int | Sequence[int]


def _layer_geometry(layer: LayerLike, index: int) -> tuple[int, int, int, int]:
    if isinstance(layer, ConvSpec):
        pairs = [
            _pair(v, f"layers[{index}].{n}", m, None)
            for v, n, m in (
                (layer.kernel_size, "kernel_size", 1),
                (layer.stride, "stride", 1),
                (layer.padding, "padding", 0),
                (layer.dilation, "dilation", 1),
            )
        ]
        if any(a != b for a, b in pairs):
            raise InputError(
                f"layers[{index}] is not square; receptive_field works per axis: pass "
                "(kernel, stride, padding, dilation) tuples for one axis"
            )
        return pairs[0][0], pairs[1][0], pairs[2][0], pairs[3][0]
    items = (
        [layer]
        if isinstance(layer, (int, np.integer))
        else list(layer)
        if isinstance(layer, (tuple, list, np.ndarray))
        else []
    )
    if not 1 <= len(items) <= 4 or not all(
        isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in items
    ):
        raise InputError(
            f"layers[{index}] must be (kernel, stride, padding, dilation) ints (stride, "
            f"padding and dilation may be left off) or a ConvSpec; got {layer!r}"
        )
    k, s, p, d = (items + [1, 0, 1][len(items) - 1 :])[:4]
    if k < 1 or s < 1 or p < 0 or d < 1:
        raise InputError(
            f"layers[{index}] = {layer!r}: kernel, stride and dilation must be >= 1 and "
            "padding >= 0"
        )
    return int(k), int(s), int(p), int(d)


def receptive_field(layers: Iterable[LayerLike]) -> list[ReceptiveField]:
    r"""Receptive field size, jump and start after each layer of a stack (one axis).

    Starting from the input (``r_0 = 1``, ``j_0 = 1``, ``start_0 = 0``), each layer of
    kernel ``k``, stride ``s``, padding ``p`` and dilation ``d`` gives

    .. math::

        r_{out} = r_{in} + (k - 1) d\, j_{in}, \quad
        j_{out} = j_{in} s, \quad
        start_{out} = start_{in} + \left(\tfrac{k - 1}{2} d - p\right) j_{in}

    (Dumoulin & Visin, "A guide to convolution arithmetic"; Araujo et al., "Computing
    receptive fields of CNNs", Distill 2019). Pooling layers count as layers with their
    kernel and stride.

    Parameters
    ----------
    layers : iterable of ConvSpec or (kernel, stride, padding, dilation)
        The stack, first layer first. A tuple may stop early: ``(k,)``, ``(k, s)``,
        ``(k, s, p)`` default to stride 1, padding 0, dilation 1; a bare int is a kernel.

    Returns
    -------
    list of ReceptiveField
        One record per layer, the last one is the whole stack's.

    Raises
    ------
    InputError
        For a layer that is not such a tuple, or a non-square ConvSpec.

    Examples
    --------
    Two stacked 3x3 convolutions see 5x5, three see 7x7 (VGG):

    >>> [rf.size for rf in receptive_field([(3, 1, 1), (3, 1, 1), (3, 1, 1)])]
    [3, 5, 7]
    >>> receptive_field([(3, 2, 1), (3, 2, 1)])[-1]
    ReceptiveField(kernel=3, stride=2, padding=1, dilation=1, size=7, jump=4, start=0.0)
    """
    if isinstance(layers, (str, bytes)) or not isinstance(layers, Iterable):
        raise InputError(
            "layers must be a sequence of ConvSpec or (kernel, stride, padding, dilation) "
            f"tuples, e.g. [(3, 1, 1), (2, 2, 0)]; got {layers!r}"
        )
    r, j, start = 1, 1, 0.0
    out = []
    for i, layer in enumerate(layers):
        k, s, p, d = _layer_geometry(layer, i)
        r = r + (k - 1) * d * j
        start = start + ((k - 1) / 2 * d - p) * j
        j = j * s
        out.append(ReceptiveField(k, s, p, d, r, j, start))
    return out


def parameter_count(spec: ConvSpec | Iterable[ConvSpec]) -> int:
    r"""Number of learnable parameters of a convolution layer or a stack of them.

    .. math::

        P = O \cdot \frac{C}{g} \cdot k_h k_w + [\text{bias}]\, O

    the count of ``sum(p.numel() for p in torch.nn.Conv2d(C, O, k, groups=g).parameters())``.

    Parameters
    ----------
    spec : ConvSpec or iterable of ConvSpec
        One layer or a stack.

    Returns
    -------
    int
        Total number of parameters.

    Raises
    ------
    InputError
        If ``groups`` does not divide the channels, or a layer is not a ConvSpec.

    Examples
    --------
    Two 3x3 layers (18 weights per channel pair) against one 5x5 (25), same 5x5 field:

    >>> two_3x3 = [ConvSpec(64, 64, 3, bias=False)] * 2
    >>> parameter_count(two_3x3), parameter_count(ConvSpec(64, 64, 5, bias=False))
    (73728, 102400)
    """
    if isinstance(spec, ConvSpec):
        specs = [spec]
    elif isinstance(spec, Iterable) and not isinstance(spec, (str, bytes)):
        specs = list(spec)
    else:
        raise InputError(
            f"spec must be a ConvSpec or a sequence of them, e.g. ConvSpec(3, 16, 3); got {spec!r}"
        )
    total = 0
    for i, layer in enumerate(specs):
        if not isinstance(layer, ConvSpec):
            raise InputError(
                f"parameter_count takes ConvSpec layers; item {i} is {type(layer).__name__}: "
                "wrap it as ConvSpec(in_channels, out_channels, kernel_size, ...)"
            )
        c = _pair(layer.in_channels, "in_channels", 1, None)[0]
        o = _pair(layer.out_channels, "out_channels", 1, None)[0]
        g = _pair(layer.groups, "groups", 1, None)[0]
        _check_groups(c, o, g, f"layer {i}")
        kh, kw = _pair(layer.kernel_size, "kernel_size", 1, None)
        total += o * (c // g) * kh * kw + (o if layer.bias else 0)
    return total
