"""Box coding by hand and round trips, anchors in torchvision's order, bad input
(issue 26, item 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.anchors import AnchorGenerator, BoxCoder  # noqa: E402
from tests.nn.ops.test_boxes import random_xyxy  # noqa: E402


# ------------------------------------------------------------------ box coding
class TestBoxCoder:
    def test_hand_case(self):
        coder = BoxCoder((10.0, 10.0, 5.0, 5.0))
        p = torch.tensor([[0.0, 0.0, 10.0, 20.0]], dtype=torch.float64)
        g = torch.tensor([[2.0, 4.0, 22.0, 24.0]], dtype=torch.float64)
        # centres (5, 10) -> (12, 14); sizes (10, 20) -> (20, 20)
        want = [[10 * 7 / 10, 10 * 4 / 20, 5 * math.log(2), 0.0]]
        torch.testing.assert_close(coder.encode(g, p), torch.tensor(want).double())

    def test_round_trip(self):
        rng = np.random.default_rng(3)
        p = torch.from_numpy(random_xyxy(rng, 50))
        g = torch.from_numpy(random_xyxy(rng, 50))
        for w in [(1.0, 1.0, 1.0, 1.0), (10.0, 10.0, 5.0, 5.0)]:
            coder = BoxCoder(w)
            torch.testing.assert_close(coder.decode(coder.encode(g, p), p), g, rtol=0, atol=1e-9)

    def test_decode_clamps_log_scale(self):
        coder = BoxCoder((1.0, 1.0, 2.0, 2.0))
        p = torch.tensor([[0.0, 0.0, 16.0, 16.0]], dtype=torch.float64)
        d = torch.tensor([[0.0, 0.0, 100.0, 2 * math.log(2)]], dtype=torch.float64)
        out = coder.decode(d, p)[0]
        # dw / ww = 50 is clamped at log(1000/16): width 16 * 1000 / 16 = 1000
        assert out[2] - out[0] == pytest.approx(1000.0, rel=1e-12)
        assert out[3] - out[1] == pytest.approx(32.0, rel=1e-12)  # below the clip: exact
        assert bool(torch.isfinite(coder.decode(torch.full((1, 4), 1e30).double(), p)).all())

    def test_per_class_deltas(self):
        coder = BoxCoder()
        p = torch.tensor([[0.0, 0.0, 10.0, 10.0]])
        d = torch.tensor([[0.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0]])
        out = coder.decode(d, p)
        assert out.shape == (1, 8)
        torch.testing.assert_close(out[0, 4:], torch.tensor([1.0, 0.0, 11.0, 10.0]))

    def test_zero_size_refused(self):
        with pytest.raises(InputError, match="proposals must have positive widths"):
            BoxCoder().encode(torch.ones(1, 4) * torch.tensor([0, 0, 1, 1]), torch.zeros(1, 4))


# ------------------------------------------------------------------ anchors
class TestAnchors:
    def test_hand_case_and_order(self):
        gen = AnchorGenerator((16.0, 32.0), (0.25, 1.0))
        a = gen((8, 8), [(2, 2)])
        assert a.shape == (2 * 2 * 4, 4)
        # cell (0, 0): ratio 0.25 outer, sizes inner: 16 -> w 32, h 8
        assert a[0].tolist() == [-16.0, -4.0, 16.0, 4.0]
        assert a[2].tolist() == [-8.0, -8.0, 8.0, 8.0]  # ratio 1, size 16
        # the next cell is (row 0, column 1): shifted by the stride 4 in x
        torch.testing.assert_close(a[4:8] - a[0:4], torch.tensor([[4.0, 0, 4, 0]] * 4))
        torch.testing.assert_close(a[8:12] - a[0:4], torch.tensor([[0.0, 4, 0, 4]] * 4))
        wh = a[:, 2:] - a[:, :2]
        torch.testing.assert_close(wh[:, 0] * wh[:, 1], torch.tensor([256.0, 1024.0] * 8))

    def test_torchvision_rounding_and_offset(self):
        # torchvision, size 32 ratio 0.5: w = 32 * sqrt(2) = 45.25, h = 22.63, rounded
        gen = AnchorGenerator((32.0,), (0.5,), round_base=True)
        assert gen.base_anchors().tolist() == [[-23.0, -11.0, 23.0, 11.0]]
        centred = AnchorGenerator((32.0,), (1.0,), offset=0.5)((16, 16), [(2, 2)])
        assert centred[0].tolist() == [-12.0, -12.0, 20.0, 20.0]  # centre (4, 4)

    def test_several_feature_maps(self):
        gen = AnchorGenerator(((32.0,), (64.0, 128.0)), (1.0,))
        assert gen.num_anchors_per_location() == [1, 2]
        a = gen((64, 64), [(8, 8), (4, 4)])
        assert a.shape == (64 + 32, 4)
        assert a[64].tolist() == [-32.0, -32.0, 32.0, 32.0]
        assert a[66].tolist() == [-16.0, -32.0, 48.0, 32.0]  # stride 16 at level 1

    def test_bad_input(self):
        with pytest.raises(InputError, match="sizes must be in"):
            AnchorGenerator((-1.0,))
        with pytest.raises(InputError, match="feature_shapes must be 1"):
            AnchorGenerator()((64, 64), [(8, 8), (4, 4)])


# ------------------------------------------------------------------ bad input
T4 = torch.tensor([[0.0, 0.0, 1.0, 1.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: BoxCoder((1.0, 1.0, 0.0, 1.0)), r"weights must be in \(0"),
        (lambda: BoxCoder().decode(torch.zeros(1, 3), T4), r"deltas must be a \(N, 4 k\)"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
