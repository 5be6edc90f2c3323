r"""Fixed-point helpers for the uint8 kernels: 16-bit multiply-high in numba, and exact
rounded division by a constant with it.

numba types integer arithmetic at 64 bits, so ``(a * b) >> 16`` on two ``uint16`` values
compiles to 64-bit products that AVX2 cannot vectorize (it has no 64-bit multiply).
:func:`mulhi_u16` emits the 16 x 16 -> 32-bit product and its high half directly in
LLVM IR, the pattern LLVM's vectorizer turns into ``vpmulhuw``: sixteen lanes per
instruction, as OpenCV's uint8 kernels use.

A rounded mean :math:`\operatorname{round}(S / d)` of an integer sum :math:`S` over an
odd count :math:`d` is then one multiply-high and a shift (Granlund & Montgomery,
*Division by invariant integers using multiplication*, PLDI 1994):

.. math:: \operatorname{round}(S / d) = \left\lfloor \frac{S + (d - 1)/2}{d}
          \right\rfloor = \left\lfloor \frac{(S + (d - 1)/2)\, m}{2^{16 + k}}
          \right\rfloor, \qquad m = \lceil 2^{16 + k} / d \rceil < 2^{16}

(odd :math:`d` puts no sum on a rounding tie). :func:`rounding_divisor` picks the largest
:math:`k` that keeps :math:`m` in 16 bits and checks the identity on every sum up to the
caller's bound, so the kernels that use it give the same integers as an exact division.
"""

from __future__ import annotations

import functools

import numpy as np
from llvmlite import ir
from numba import types
from numba.core.extending import intrinsic, overload

__all__ = ["mulhi_u16", "rounding_divisor"]


def mulhi_u16(a: int, b: int, k: int) -> np.uint16:
    r"""``((a * b) >> 16) >> k`` for ``uint16`` ``a``, ``b``, ``k``, as ``uint16``.

    In numba kernels the product is formed in 32 bits and its high half taken in 16, so
    that a loop over arrays vectorizes to ``vpmulhuw`` and ``vpsrlw``; from Python (the
    kernels' reference path) it is this integer arithmetic.

    Examples
    --------
    >>> int(mulhi_u16(1000, 58255, 3))
    111
    """
    return np.uint16(((int(a) * int(b)) >> 16) >> int(k))


@intrinsic
def _mulhi_u16_ir(typingctx, a, b, k):  # pragma: no cover - compiled
    sig = types.uint16(types.uint16, types.uint16, types.uint16)

    def codegen(context, builder, signature, args):
        x, y, shift = args
        i32 = ir.IntType(32)
        product = builder.mul(builder.zext(x, i32), builder.zext(y, i32))
        high = builder.trunc(builder.lshr(product, ir.Constant(i32, 16)), ir.IntType(16))
        return builder.lshr(high, shift)

    return sig, codegen


@overload(mulhi_u16, jit_options={"nogil": True})
def _mulhi_u16_overload(a, b, k):  # pragma: no cover - compiled
    return lambda a, b, k: _mulhi_u16_ir(a, b, k)


@functools.lru_cache(maxsize=64)
def rounding_divisor(d: int, largest_sum: int) -> tuple[np.uint16, np.uint16, np.uint16] | None:
    r"""Constants for :math:`\operatorname{round}(S / d)` by :func:`mulhi_u16`, for every
    integer :math:`0 \le S \le` ``largest_sum``.

    Parameters
    ----------
    d : int
        The odd divisor (a window's pixel count), at least 3.
    largest_sum : int
        The largest sum to divide (``255 d`` for a uint8 window).

    Returns
    -------
    (bias, m, k) : tuple of numpy.uint16, or None
        ``mulhi_u16(S + bias, m, k) == round(S / d)`` for every such ``S`` (checked here on
        all of them); None when ``d`` is even or below 3, or the biased sums or ``m`` do
        not fit 16 bits.

    Examples
    --------
    >>> [int(c) for c in rounding_divisor(9, 255 * 9)]
    [4, 58255, 3]
    """
    if d < 3 or d % 2 == 0:
        return None
    bias = (d - 1) // 2
    if largest_sum + bias > 0xFFFF:
        return None
    k = 0
    while -(-(1 << (17 + k)) // d) <= 0xFFFF:
        k += 1
    m = -(-(1 << (16 + k)) // d)
    s = np.arange(largest_sum + 1, dtype=np.int64)
    if not np.array_equal(((s + bias) * m) >> (16 + k), (2 * s + d) // (2 * d)):
        return None
    return np.uint16(bias), np.uint16(m), np.uint16(k)
