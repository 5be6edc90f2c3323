"""The 3x3 and 5x5 median filters' min/max networks (``imaging.median_networks``):
every 0/1 window (the 0-1 principle makes that a proof for every input), a NumPy
sliding-window median on every dtype and border, and the written-out kernel body
against the network it was generated from."""

from __future__ import annotations

import inspect
import itertools

import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

import robopercept.imaging.median_networks as mn
from robopercept.imaging import median_filter
from robopercept.imaging.filters import border_indices


def _numpy_median(image: np.ndarray, k: int, border: str) -> np.ndarray:
    """The window median by NumPy: pad through ``border_indices``, sort each window."""
    h, w = image.shape[:2]
    r = k // 2
    padded = image[border_indices(h, r, r, border)][:, border_indices(w, r, r, border)]
    win = sliding_window_view(padded, (k, k), axis=(0, 1))  # (H, W, [C,] k, k)
    return np.median(win.reshape(*win.shape[:-2], k * k), axis=-1).astype(image.dtype)


@pytest.mark.parametrize("k", [3, 5])
def test_every_zero_one_window(k) -> None:
    """A min/max network that selects the median of every 0/1 window does so for every
    input (0-1 principle). The kernel sorts each column first, so a 0/1 window is known
    by its column counts: blocks of ``k x k``, one per count vector ``(k+1)^k``, the
    ones of each column in seeded random rows; each block's centre is the median."""
    rng = np.random.default_rng(k)
    counts = np.array(list(itertools.product(range(k + 1), repeat=k)))  # (B, k)
    cols = counts.reshape(-1)  # the ones in each column, block after block
    ranks = np.argsort(rng.random((k, cols.size)), axis=0)  # a random row order
    image = (ranks < cols).astype(np.uint8)  # column c: ones in cols[c] random rows
    assert (image.sum(axis=0) == cols).all()
    want = counts.sum(axis=1) >= (k * k + 1) // 2
    centres = (np.arange(len(counts)) * k + k // 2, k // 2)
    got = median_filter(image, k)[centres[1], centres[0]]
    np.testing.assert_array_equal(got, want.astype(np.uint8))
    # one row lower, and at the top row (replicate border: the first row repeated),
    # through the 3x3 kernel's other path (its first and last rows go row by row, the
    # rows between in one flat loop)
    below = np.vstack([np.zeros((1, image.shape[1]), np.uint8), image])
    got = median_filter(below, k)[centres[1] + 1, centres[0]]
    np.testing.assert_array_equal(got, want.astype(np.uint8))
    if k == 3:  # the top row's window is rows (0, 0, 1): column counts from 0, 2 or 3
        top = median_filter(image[1:], k)[0, centres[0]]
        doubled = image[1] * 2 + image[2]
        np.testing.assert_array_equal(
            top, (np.convolve(doubled, np.ones(3), "same")[centres[0]] >= 5)
        )
    # the same windows in each channel of an RGB image, shifted by one block
    rgb = np.stack([image, np.roll(image, k, axis=1), np.roll(image, -k, axis=1)], axis=-1)
    out = median_filter(rgb, k)[k // 2, centres[0]]
    for c, shift in enumerate((0, 1, -1)):
        np.testing.assert_array_equal(out[:, c], np.roll(want, shift).astype(np.uint8))


@pytest.mark.parametrize("k", [3, 5])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int16, np.float32, np.float64])
def test_equals_numpy_on_every_dtype_border_and_size(k, dtype) -> None:
    rng = np.random.default_rng(7)
    shapes = [(1, 1), (2, 3), (4, 1), (5, 4, 3), (9, 7), (17, 23, 3), (31, 40)]
    for shape, border in itertools.product(shapes, ("replicate", "reflect101", "reflect")):
        few = rng.integers(0, 4, shape)  # many ties
        wide = rng.normal(size=shape) * 1000
        for values in (few, wide):
            if np.dtype(dtype).kind in "iu":
                values = np.clip(values, np.iinfo(dtype).min, np.iinfo(dtype).max)
            image = values.astype(dtype)
            np.testing.assert_array_equal(
                median_filter(image, k, border=border), _numpy_median(image, k, border),
                err_msg=f"{shape} {border}",
            )  # fmt: skip


def test_the_kernel_body_is_the_generated_network() -> None:
    """The 5x5 kernel's straight-line body is ``median_network(5)`` written out, line
    for line (regenerate it from the function if the network changes)."""
    ops, out = mn.median_network(5)
    want = [f"{name} = {kind}({a}, {b})" for name, kind, a, b in ops] + [f"o[x] = {out}"]
    source = inspect.getsource(mn._make_median5)
    body = source.split("# median_network(5), written out\n", 1)[1]
    got = [line.strip() for line in body.splitlines()[: len(want)]]
    assert got == want
    assert len(ops) == 140  # the count the module docstring states


def test_the_5x5_network_on_every_column_count() -> None:
    """The network alone, evaluated in Python on every 0/1 input with sorted columns."""
    ops, out = mn.median_network(5)
    for counts in itertools.product(range(6), repeat=5):
        env = {f"c{j}{i}": int(i >= 5 - counts[j]) for j in range(5) for i in range(5)}
        for name, kind, a, b in ops:
            env[name] = (min if kind == "min" else max)(env[a], env[b])
        assert env[out] == int(sum(counts) >= 13), counts


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="5x5 network only"):
        mn.median_network(3)
    src = np.zeros((3, 8), np.uint8)
    idx = np.arange(10) - 1
    with pytest.raises(ValueError, match="k 3 or 5 and 1 or 3 channels"):
        mn.median_rows(src, idx.clip(0, 3), idx.clip(0, 2)[:5], 2, 3, src.copy())
    wide = np.zeros((3, 16), np.uint8)
    with pytest.raises(ValueError, match="C-contiguous"):
        mn.median_rows(wide[:, ::2], idx.clip(0, 7), idx.clip(0, 2)[:5], 1, 3, src.copy())
