"""Tests of robopercept.nn.ops.losses: the sigmoid focal loss by its formula."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.losses import sigmoid_focal_loss  # noqa: E402


class TestFocalLoss:
    def test_hand_value(self):
        # x = 0: p = 0.5, y = 1: 0.25 * 0.5^2 * log 2
        got = sigmoid_focal_loss(torch.tensor([0.0]), torch.tensor([1.0]))
        assert float(got) == pytest.approx(0.25 * 0.25 * math.log(2), rel=1e-6)
        # y = 0, x = 2: p = sigma(2), (1 - alpha) p^2 (-log(1 - p))
        p = 1 / (1 + math.exp(-2))
        got = sigmoid_focal_loss(torch.tensor([2.0]), torch.tensor([0.0]))
        assert float(got) == pytest.approx(0.75 * p**2 * -math.log(1 - p), rel=1e-6)

    def test_gamma_zero_no_alpha_is_bce(self):
        x, y = torch.randn(20), (torch.rand(20) > 0.5).float()
        bce = torch.nn.functional.binary_cross_entropy_with_logits(x, y, reduction="sum")
        got = sigmoid_focal_loss(x, y, alpha=-1, gamma=0, reduction="sum")
        assert float(got) == pytest.approx(float(bce), rel=1e-6)
        assert float(sigmoid_focal_loss(x, y, reduction="mean")) == pytest.approx(
            float(sigmoid_focal_loss(x, y).mean()), rel=1e-6
        )

    def test_bad_input(self):
        with pytest.raises(InputError, match="logits"):
            sigmoid_focal_loss(torch.zeros(2, dtype=torch.int64), torch.zeros(2))
        with pytest.raises(InputError, match="shape of inputs"):
            sigmoid_focal_loss(torch.zeros(2), torch.zeros(3))
        with pytest.raises(InputError, match="reduction"):
            sigmoid_focal_loss(torch.zeros(2), torch.zeros(2), reduction="max")
