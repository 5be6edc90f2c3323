"""The keypoint heatmap codec (robopercept.nn.ops.heatmaps; issue 28): heatmap targets
and decoding, the flip convention, the flip-test pieces and the heatmap losses."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError
from robopercept.nn.ops.heatmaps import (
    check_permutation,
    decode_heatmaps,
    flip_heatmaps,
    gaussian_heatmaps,
    heatmap_loss,
    heatmap_probabilities,
    keypoint_tensor,
)
from robopercept.nn.skeleton import MPII_16


def _random_keypoints(n: int, j: int, w: int, h: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform([6.0, 6.0], [w - 6.0, h - 6.0], (n, j, 2))
    return np.concatenate([xy, np.full((n, j, 1), 2.0)], -1)


class TestHeatmaps:
    def test_hand_case_peak_at_the_cell_centre(self):
        # x = 6 at stride 4 is u = 6/4 - 1/2 = 1: the peak is cell 1 exactly
        hm, w = gaussian_heatmaps([[[6.0, 10.0, 2]]], (16, 16), stride=4, sigma=1.0)
        assert hm.shape == (1, 1, 4, 4) and w.tolist() == [[1.0]]
        assert float(hm[0, 0, 2, 1]) == 1.0  # y = 10 is v = 2
        assert float(hm[0, 0, 2, 2]) == pytest.approx(np.exp(-0.5))

    def test_unlabelled_and_outside_joints_have_zero_weight_and_map(self):
        kp = [[[5.0, 5.0, 0], [40.0, 5.0, 2], [np.nan, 3.0, 2], [5.0, 5.0, 1]]]
        hm, w = gaussian_heatmaps(kp, (32, 32), stride=4)
        assert w.tolist() == [[0.0, 0.0, 0.0, 1.0]]
        assert float(hm[0, :3].abs().max()) == 0.0

    def test_quadratic_decoding_round_trips_under_a_twentieth_of_a_pixel(self):
        kp = _random_keypoints(100, 16, 128, 96)
        for stride, sigma in ((4, 2.0), (4, 1.0), (2, 1.5), (1, 2.0)):
            hm, _ = gaussian_heatmaps(kp, (128, 96), stride, sigma)
            dec, score = decode_heatmaps(hm, stride, "quadratic")
            # exact for a Gaussian up to float32 rounding of the map
            assert np.abs(dec - kp[..., :2]).max() < 0.05
            # the peak cell is at most half a cell from the centre on each axis
            assert score.min() >= np.exp(-0.25 / sigma**2) - 1e-6

    def test_quarter_offset_error_is_at_most_a_quarter_cell_and_soft_argmax_is_unbiased(self):
        kp = _random_keypoints(100, 8, 128, 128, seed=1)
        hm, _ = gaussian_heatmaps(kp, (128, 128), 4, 2.0)
        quarter, _ = decode_heatmaps(hm, 4, "quarter")
        # argmax is within half a cell, the quarter step leaves at most 1/4 + ... per axis:
        # |u - (j + s/4)| <= 1/4 when the true offset lies in [-1/2, 1/2] (0.25 cell = 1 px)
        assert np.abs(quarter - kp[..., :2]).max() <= 1.0 + 1e-6
        soft, _ = decode_heatmaps(hm, 4, "soft-argmax", beta=200.0)
        # a sharp softmax is the argmax's neighbourhood mean: within half a cell (2 px)
        assert np.abs(soft - kp[..., :2]).max() < 2.0

    def test_flipping_the_keypoints_flips_the_heatmaps_and_swaps_the_channels(self):
        kp = _random_keypoints(5, 16, 128, 64, seed=2)
        perm = MPII_16.flip_permutation()
        flipped = kp[:, perm].copy()
        flipped[..., 0] = 128 - flipped[..., 0]
        a, _ = gaussian_heatmaps(kp, (128, 64), 4)
        b, _ = gaussian_heatmaps(flipped, (128, 64), 4)
        # the module's convention: x -> W - x is the cell flip u -> (w - 1) - u exactly
        torch.testing.assert_close(b, a.flip(-1)[:, perm], atol=1e-6, rtol=0)

    def test_refusals(self):
        with pytest.raises(InputError, match="multiple of the stride"):
            gaussian_heatmaps([[[1, 1, 2]]], (30, 32), stride=4)
        with pytest.raises(InputError, match=r"\(N, J, 3\)"):
            gaussian_heatmaps([[1, 1, 2]], (32, 32))
        with pytest.raises(InputError, match="finite"):
            decode_heatmaps(torch.full((1, 1, 4, 4), float("nan")))
        with pytest.raises(InputError, match="method"):
            decode_heatmaps(torch.zeros(1, 1, 4, 4), method="argmax")


def test_heatmap_losses_by_hand():
    target, weight = gaussian_heatmaps([[[6.0, 6.0, 2], [1.0, 1.0, 0]]], (16, 16), 4, 1.0)
    flat = torch.zeros(1, 2, 4, 4)
    # a flat map is the uniform distribution over 16 cells: cross entropy log 16 for the
    # one labelled joint, whatever the target's shape
    assert float(heatmap_loss(flat, target, weight, "softmax")) == pytest.approx(np.log(16))
    # MSE: the mean over cells of the target squared, averaged over the N J = 2 maps
    expected = float((target[0, 0] ** 2).mean()) / 2
    assert float(heatmap_loss(flat, target, weight, "mse")) == pytest.approx(expected)
    with pytest.raises(InputError, match=r"\(N, J, h, w\)"):
        heatmap_loss(flat, target[:, :1], weight)


def test_flip_heatmaps_is_the_flip_of_the_flipped_keypoints_maps():
    kp = _random_keypoints(3, 16, 64, 32, seed=4)
    perm = MPII_16.flip_permutation()
    flipped = kp[:, perm].copy()
    flipped[..., 0] = 64 - flipped[..., 0]
    a, _ = gaussian_heatmaps(kp, (64, 32), 4)
    b, _ = gaussian_heatmaps(flipped, (64, 32), 4)
    # flipping back the mirrored image's maps gives the image's maps (perm is an involution)
    torch.testing.assert_close(flip_heatmaps(b, torch.as_tensor(perm)), a, atol=1e-6, rtol=0)


def test_heatmap_probabilities_and_the_input_checks():
    logits = torch.randn(2, 3, 4, 5)
    probs = heatmap_probabilities(logits, "softmax")
    torch.testing.assert_close(probs.sum((-1, -2)), torch.ones(2, 3))
    assert heatmap_probabilities(logits, "mse") is logits
    assert keypoint_tensor([[[1.0, 2.0], [3.0, 4.0]]])[..., 2].tolist() == [[2.0, 2.0]]
    assert check_permutation([2, 0, 1], 3).tolist() == [2, 0, 1]
    with pytest.raises(InputError, match="permutation of the 3 joints"):
        check_permutation([0, 0, 1], 3)
