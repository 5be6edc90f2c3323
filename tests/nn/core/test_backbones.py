"""Tests of robopercept.nn.core.backbones: output shapes of the backbone and the FPN, and
the extra residual blocks per stage."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.core.backbones import FPN, DetectionBackbone  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_backbone_and_fpn_shapes():
    bb = DetectionBackbone(8, strides=(8, 16, 32))
    outs = bb(torch.zeros(2, 3, 64, 96))
    assert [tuple(o.shape) for o in outs] == [(2, 32, 8, 12), (2, 64, 4, 6), (2, 64, 2, 3)]
    assert bb.out_channels == [32, 64, 64]
    fpn = FPN([32, 64], 16)
    assert [tuple(o.shape) for o in fpn(outs[:2])] == [(2, 16, 8, 12), (2, 16, 4, 6)]
    with pytest.raises(InputError, match="strides"):
        DetectionBackbone(8, strides=(16, 8))
    with pytest.raises(InputError, match="features must be a list of 2"):
        fpn(outs)


def test_backbone_blocks_deepen_each_stage_and_keep_the_one_block_layout():
    one = DetectionBackbone(8, strides=(8, 16))
    two = DetectionBackbone(8, strides=(8, 16), blocks=2)
    x = torch.rand(1, 3, 64, 64)
    assert [o.shape for o in one(x)] == [o.shape for o in two(x)]
    # one block per stage: the layout (and so the state-dict keys) of the checkpoints
    # shipped before ``blocks`` existed
    assert "stages.0.conv1.conv.weight" in one.state_dict()
    assert "stages.0.1.conv1.conv.weight" in two.state_dict()
    # each extra block of stage k (c -> c channels): two 3 x 3 convolutions without
    # bias and two batch norms, 2 (9 c^2 + 2 c) parameters; stages of 16, 32, 64 channels
    extra = sum(2 * (9 * c * c + 2 * c) for c in (16, 32, 64))
    count = lambda m: sum(p.numel() for p in m.parameters())  # noqa: E731
    assert count(two) - count(one) == extra
    # the receptive field grows: the stride-8 output at (6, 6), centred on pixel 52,
    # sees columns 0-11 (40 px and more to its left) only through the deeper stages
    for m in (one, two):
        m.eval()
    probe = torch.zeros(1, 3, 96, 96, requires_grad=True)
    grads = []
    for m in (one, two):
        (g,) = torch.autograd.grad(m(probe)[0][0, :, 6, 6].sum(), probe)
        grads.append(g.abs().sum(dim=(0, 1)))
    far = lambda g: bool((g[:, :12] > 0).any())  # noqa: E731
    assert not far(grads[0]) and far(grads[1])
    with pytest.raises(InputError, match="blocks"):
        DetectionBackbone(8, blocks=0)
