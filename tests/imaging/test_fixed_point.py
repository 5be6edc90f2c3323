"""Multiply-high and rounded division by constants (robopercept.imaging.fixed_point)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from numba import njit

from robopercept.imaging.fixed_point import mulhi_u16, rounding_divisor


@njit(cache=False)
def _mulhi_rows(a, b, k, out):
    for i in range(a.shape[0]):
        out[i] = mulhi_u16(a[i], b[i], k[i])


def test_mulhi_compiled_equals_the_integer_definition() -> None:
    # the compiled 16-bit multiply-high against Python integers, on random operands
    # and the extremes (0, 1, 0xFFFF), every shift 0..15
    rng = np.random.default_rng(0)
    edge = np.array([0, 1, 2, 0x7FFF, 0x8000, 0xFFFE, 0xFFFF], np.uint16)
    a = np.concatenate([rng.integers(0, 1 << 16, 4000), np.repeat(edge, edge.size)])
    b = np.concatenate([rng.integers(0, 1 << 16, 4000), np.tile(edge, edge.size)])
    a, b = a.astype(np.uint16), b.astype(np.uint16)
    k = (np.arange(a.size) % 16).astype(np.uint16)
    got = np.empty_like(a)
    _mulhi_rows(a, b, k, got)
    want = [((int(x) * int(y)) >> 16) >> int(s) for x, y, s in zip(a, b, k, strict=True)]
    np.testing.assert_array_equal(got, np.array(want, np.uint16))
    head = zip(a[:50], b[:50], k[:50], want[:50], strict=True)
    assert all(int(mulhi_u16(x, y, s)) == w for x, y, s, w in head)


@pytest.mark.parametrize("kw, kh", list(itertools.product(range(1, 16, 2), repeat=2)))
def test_rounding_divisor_is_the_rounded_mean(kw: int, kh: int) -> None:
    # every sum of every odd window up to 15x15 of uint8 pixels: the multiply-high
    # gives round(S / d), which is also what float32 S * (1 / d) + 1/2 floors to
    d = kw * kh
    c = rounding_divisor(d, 255 * d)
    if d == 1:
        assert c is None  # m = 2^16 does not fit: the caller copies
        return
    assert c is not None
    bias, m, k = (int(v) for v in c)
    s = np.arange(255 * d + 1, dtype=np.int64)
    exact = np.array([round(v / d) for v in s.tolist()])  # no ties: d is odd
    np.testing.assert_array_equal(((s + bias) * m) >> 16 >> k, exact)
    f32 = np.floor(s.astype(np.float32) * np.float32(1.0 / d) + np.float32(0.5))
    np.testing.assert_array_equal(f32.astype(np.int64), exact)


def test_rounding_divisor_refuses_what_does_not_fit() -> None:
    assert rounding_divisor(4, 100) is None  # even: ties
    assert rounding_divisor(1, 255) is None
    assert rounding_divisor(257, 255 * 257) is None  # the biased sums pass 16 bits
    c = rounding_divisor(9, 255 * 9)
    assert c is not None and [int(v) for v in c] == [4, 58255, 3]
