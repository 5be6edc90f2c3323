"""summary(): parity with torchinfo on the whole family, hand-computed receptive fields."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
torchinfo = pytest.importorskip("torchinfo")

from torch import nn  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.classification.models import inception_small, resnet_small, vgg_small  # noqa: E402
from robopercept.nn.core.blocks import InceptionBlock, ResidualBlock, VGGStage  # noqa: E402
from robopercept.nn.core.summary import ModelSummary, summary  # noqa: E402

FAMILY = {
    "vgg_small": lambda: vgg_small(),
    "vgg_small_rgb": lambda: vgg_small(in_channels=3, num_classes=4, widths=(8, 16)),
    "inception_small": lambda: inception_small(),
    "inception_small_factorized": lambda: inception_small(factorize_5x5=True),
    "resnet_small": lambda: resnet_small(),
    "resnet_small_deep": lambda: resnet_small(depth=(2, 2, 2), widths=(8, 16, 32)),
    "resnet_small_bottleneck": lambda: resnet_small(block="bottleneck"),
}


@pytest.mark.parametrize("name", sorted(FAMILY))
@pytest.mark.parametrize("side", [8, 32])
def test_equals_torchinfo(name: str, side: int) -> None:
    model = FAMILY[name]()
    channels = model.in_channels
    shape = (2, channels, side, side)
    ours = summary(model, shape)
    ref = torchinfo.summary(model, input_size=shape, verbose=0)
    leaves = [layer for layer in ref.summary_list if layer.is_leaf_layer]
    # exact: both count the same parameters and run the same forward pass
    assert [(r.type, list(r.output_shape), r.params, r.trainable_params) for r in ours.rows] == [
        (layer.class_name, list(layer.output_size), layer.num_params, layer.trainable_params)
        for layer in leaves
    ]
    assert ours.total_params == ref.total_params
    assert ours.trainable_params == ref.trainable_params
    assert ours.output_shape == (2, model.num_classes)


def test_frozen_layers_counted_as_non_trainable() -> None:
    model = vgg_small()
    for p in model.features.parameters():
        p.requires_grad_(False)
    ours = summary(model, (1, 8, 8))
    ref = torchinfo.summary(model, input_size=(1, 1, 8, 8), verbose=0)
    assert ours.trainable_params == ref.trainable_params == 650  # the 64 -> 10 head
    assert ours.non_trainable_params == ours.total_params - 650
    assert [r.trainable for r in ours.rows if r.params] == [False] * 12 + [True]


def test_receptive_field_vgg_by_hand() -> None:
    # two 3x3 convs: 3, 5; 2x2 pool: 5 + 1 = 6, jump 2; next 3x3s: 6 + 2*2 = 10, 14;
    # pool: 14 + 2 = 16, jump 4
    model = nn.Sequential(VGGStage(1, 2), VGGStage(2, 2))
    s = summary(model, (1, 1, 16, 16))
    convs = [r for r in s.rows if r.type == "Conv2d"]
    pools = [r for r in s.rows if r.type == "MaxPool2d"]
    assert [c.receptive_field for c in convs] == [(3, 3), (5, 5), (10, 10), (14, 14)]
    assert [p.receptive_field for p in pools] == [(6, 6), (16, 16)]
    assert [p.jump for p in pools] == [(2, 2), (4, 4)]


def test_receptive_field_strided_dilated_rectangular() -> None:
    model = nn.Sequential(
        nn.Conv2d(1, 1, (3, 5), stride=2), nn.Conv2d(1, 1, 3, dilation=2), nn.Flatten()
    )
    s = summary(model, (1, 1, 20, 20))
    # (3,5) stride 2: r=(3,5), j=2; dilated 3x3: r + 2*2*2 = (11, 13)
    assert s.rows[0].receptive_field == (3, 5) and s.rows[0].jump == (2, 2)
    assert s.rows[1].receptive_field == (11, 13)
    assert s.rows[2].receptive_field is None  # flatten: whole input


def test_receptive_field_through_merges() -> None:
    # residual: the main path (two 3x3) wins over the skip: after the sum, 5x5
    s = summary(nn.Sequential(ResidualBlock(2, 2)), (1, 2, 8, 8))
    assert s.rows[-1].type == "ReLU" and s.rows[-1].receptive_field == (5, 5)
    # inception: the 5x5 branch after a 1x1 gives the largest field, 5x5
    model = nn.Sequential(InceptionBlock(2, 1, 1, 1, 1, 1, 1), nn.MaxPool2d(2))
    s = summary(model, (1, 2, 8, 8))
    assert s.rows[-1].receptive_field == (6, 6) and s.rows[-1].jump == (2, 2)


def test_table_and_state() -> None:
    model = resnet_small().train()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    s = summary(model, (1, 8, 8))
    assert isinstance(s, ModelSummary) and s.input_shape == (1, 1, 8, 8)
    assert model.training  # mode restored
    for k, v in model.state_dict().items():  # BN running statistics untouched
        assert torch.equal(v, before[k]), k
    text = str(s)
    assert "Total params: 77,754" in text
    assert "features.3.0.conv2.conv" in text and "25x25" in text
    assert len(text.splitlines()) == len(s.rows) + 9


def test_bad_shape() -> None:
    with pytest.raises(InputError, match=r"\(N, C, H, W\) or \(C, H, W\)"):
        summary(vgg_small(), (8, 8))
    with pytest.raises(InputError, match="in_channels=3"):
        summary(vgg_small(), (3, 8, 8))


# issue 25: no model, a device or dtype torch does not know, an input of 2**40 values
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"model": None}, r"model must be a torch.nn.Module"),
        ({"device": ""}, r"device must be 'auto', 'cpu', 'cuda', 'cuda:N' or 'mps'; got ''"),
        ({"device": "CPU"}, r"device must be .* got 'CPU'"),
        ({"device": ["cpu"]}, r"device must be .* got \['cpu'\]"),
        ({"device": "xla"}, r"device 'xla' is not available here"),
        ({"dtype": np.float64}, r"dtype must be a floating-point torch.dtype"),
        ({"dtype": torch.int64}, r"dtype must be a floating-point torch.dtype"),
        ({"input_shape": None}, r"input_shape must be \(N, C, H, W\)"),
        ({"input_shape": (1, 1, 2**20, 2**20)}, r"a summary runs one small batch"),
        ({"input_shape": (1, True, 8, 8)}, r"input_shape must be"),
    ],
)
def test_issue25_bad_arguments(kwargs, match) -> None:
    args = {"model": vgg_small(), "input_shape": (1, 1, 8, 8), **kwargs}
    with pytest.raises(InputError, match=match):
        summary(**args)


def test_issue25_numpy_sizes_and_explicit_device() -> None:
    s = summary(vgg_small().double(), (np.int64(1), 8, 8), device="cpu", dtype=torch.float64)
    assert s.total_params == 72666 and s.output_shape == (1, 10)
    with pytest.raises(InputError, match=r"differs from the model's weights \(torch.float32\)"):
        summary(vgg_small(), (1, 8, 8), dtype=torch.float64)
