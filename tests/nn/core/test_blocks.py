"""Blocks and the small model family: shapes, parameter counts, properties, bad input."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.classification.models import (  # noqa: E402
    MODELS,
    Classifier,
    build_model,
    inception_small,
    resnet_small,
    vgg_small,
)
from robopercept.nn.core.blocks import (  # noqa: E402
    Bottleneck,
    ConvBNAct,
    InceptionBlock,
    ResidualBlock,
    VGGStage,
    check_input,
    make_activation,
)

#: every model of the family at its defaults and notable variants
FAMILY = {
    "vgg_small": lambda **kw: vgg_small(**kw),
    "vgg_small_1conv": lambda **kw: vgg_small(convs_per_stage=1, **kw),
    "inception_small": lambda **kw: inception_small(**kw),
    "inception_small_factorized": lambda **kw: inception_small(factorize_5x5=True, **kw),
    "resnet_small": lambda **kw: resnet_small(**kw),
    "resnet_small_deep": lambda **kw: resnet_small(depth=(2, 2, 2), widths=(8, 16, 32), **kw),
    "resnet_small_bottleneck": lambda **kw: resnet_small(block="bottleneck", **kw),
}


def n_params(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


class TestConvBNAct:
    def test_no_bias_with_bn_and_bias_without(self) -> None:
        # BN(Wx + b) = BN(Wx): the conv bias is redundant when BN follows
        assert ConvBNAct(3, 8).conv.bias is None
        assert ConvBNAct(3, 8, bn=False).conv.bias is not None
        # hand count: 3*8*3*3 weights + 2*8 BN affine
        assert n_params(ConvBNAct(3, 8)) == 3 * 8 * 9 + 16
        assert n_params(ConvBNAct(3, 8, bn=False)) == 3 * 8 * 9 + 8

    @pytest.mark.parametrize(
        ("k", "stride", "dilation", "expected"),
        [(3, 1, 1, 9), (5, 2, 1, 5), (3, 1, 2, 9), (1, 2, 1, 5)],
    )
    def test_same_padding_output_size(
        self, k: int, stride: int, dilation: int, expected: int
    ) -> None:
        # floor((9 + 2p - d(k-1) - 1)/s) + 1 with p = d(k-1)//2
        y = ConvBNAct(2, 4, k, stride=stride, dilation=dilation)(torch.zeros(1, 2, 9, 9))
        assert y.shape == (1, 4, expected, expected)

    def test_activation_applied(self) -> None:
        y = ConvBNAct(1, 4).train()(torch.randn(4, 1, 6, 6))
        assert (y >= 0).all()
        z = ConvBNAct(1, 4, act=None).train()(torch.randn(4, 1, 6, 6))
        assert (z < 0).any()

    def test_bad_arguments(self) -> None:
        with pytest.raises(InputError, match="in_channels must be >= 1"):
            ConvBNAct(0, 4)
        with pytest.raises(InputError, match="activation must be one of relu"):
            make_activation("swish")


class TestVGGStage:
    def test_shape_and_params(self) -> None:
        stage = VGGStage(1, 16, n_convs=2)
        assert stage(torch.zeros(3, 1, 8, 8)).shape == (3, 16, 4, 4)
        # 1*16*9 + 16*16*9 conv weights, 2 * (2*16) BN
        assert n_params(stage) == 144 + 2304 + 64

    def test_two_3x3_cost_18_weights_per_pair_instead_of_25(self) -> None:
        two = VGGStage(4, 4, n_convs=2, pool=False)
        one = nn.Conv2d(4, 4, 5, padding=2, bias=False)
        conv_weights = sum(m.weight.numel() for m in two.modules() if isinstance(m, nn.Conv2d))
        assert conv_weights == 18 * 16 and one.weight.numel() == 25 * 16

    def test_no_pool_keeps_size(self) -> None:
        assert VGGStage(2, 5, n_convs=3, pool=False)(torch.zeros(1, 2, 7, 7)).shape == (1, 5, 7, 7)


class TestInceptionBlock:
    @pytest.mark.parametrize("factorize", [False, True])
    def test_out_channels_is_sum_of_branches(self, factorize: bool) -> None:
        block = InceptionBlock(10, 3, 4, 5, 2, 6, 7, factorize_5x5=factorize)
        assert block.out_channels == 3 + 5 + 6 + 7
        y = block(torch.randn(2, 10, 9, 9))
        assert y.shape == (2, 21, 9, 9)

    def test_branches_concatenated_in_order(self) -> None:
        block = InceptionBlock(4, 2, 2, 3, 1, 2, 5).eval()
        x = torch.randn(1, 4, 6, 6)
        y = block(x)
        torch.testing.assert_close(y[:, :2], block.branch1(x), rtol=0, atol=0)
        torch.testing.assert_close(y[:, 2:5], block.branch3(x), rtol=0, atol=0)
        torch.testing.assert_close(y[:, 5:7], block.branch5(x), rtol=0, atol=0)
        torch.testing.assert_close(y[:, 7:], block.branch_pool(x), rtol=0, atol=0)

    def test_factorized_5x5_is_two_3x3(self) -> None:
        block = InceptionBlock(4, 2, 2, 3, 1, 2, 5, factorize_5x5=True)
        kernels = [m.kernel_size for m in block.branch5.modules() if isinstance(m, nn.Conv2d)]
        assert kernels == [(1, 1), (3, 3), (3, 3)]
        plain = InceptionBlock(4, 2, 2, 3, 1, 2, 5)
        kernels = [m.kernel_size for m in plain.branch5.modules() if isinstance(m, nn.Conv2d)]
        assert kernels == [(1, 1), (5, 5)]


class TestResidual:
    def test_identity_skip_keeps_shape(self) -> None:
        block = ResidualBlock(8, 8)
        assert isinstance(block.shortcut, nn.Identity)
        assert block(torch.randn(2, 8, 6, 6)).shape == (2, 8, 6, 6)

    @pytest.mark.parametrize(("cin", "cout", "stride"), [(8, 16, 2), (8, 8, 2), (8, 16, 1)])
    def test_projection_when_stride_or_channels_change(
        self, cin: int, cout: int, stride: int
    ) -> None:
        block = ResidualBlock(cin, cout, stride=stride)
        assert isinstance(block.shortcut, ConvBNAct)
        assert block.shortcut.conv.kernel_size == (1, 1)
        assert block.shortcut.conv.stride == (stride, stride)
        side = 7 // stride + (7 % stride > 0)  # ceil(7 / stride) = floor((7 - 1)/s) + 1
        assert block(torch.randn(2, cin, 7, 7)).shape == (2, cout, side, side)

    @pytest.mark.parametrize("train", [False, True])
    def test_zero_gamma_basic_block_is_relu(self, train: bool) -> None:
        # He et al. 2016 + Goyal et al. 2017: last BN gamma = 0 -> F(x) = beta = 0
        torch.manual_seed(0)
        block = ResidualBlock(6, 6, zero_init_residual=True).train(train)
        for _ in range(3):
            x = torch.randn(4, 6, 5, 5)
            torch.testing.assert_close(block(x), torch.relu(x), rtol=0, atol=0)

    def test_zero_gamma_bottleneck_is_relu(self) -> None:
        torch.manual_seed(1)
        block = Bottleneck(16, 4, zero_init_residual=True)
        assert isinstance(block.shortcut, nn.Identity)
        x = torch.randn(3, 16, 5, 5)
        torch.testing.assert_close(block(x), torch.relu(x), rtol=0, atol=0)

    def test_nonzero_gamma_is_not_identity(self) -> None:
        # the property test above can fail: without zero init, the block changes x
        torch.manual_seed(0)
        x = torch.randn(4, 6, 5, 5)
        assert not torch.allclose(ResidualBlock(6, 6)(x), torch.relu(x))

    def test_bottleneck_expansion_and_params(self) -> None:
        block = Bottleneck(16, 8, stride=2)
        assert block.out_channels == 32
        assert block(torch.randn(1, 16, 8, 8)).shape == (1, 32, 4, 4)
        # 1x1 16->8, 3x3 8->8, 1x1 8->32, projection 16->32, BN 2*(8 + 8 + 32 + 32)
        assert n_params(block) == 128 + 576 + 256 + 512 + 160
        assert Bottleneck(32, 8).shortcut.__class__ is nn.Identity


class TestFamily:
    @pytest.mark.parametrize("name", sorted(FAMILY))
    @pytest.mark.parametrize("side", [8, 32])
    def test_logits_shape_and_budget(self, name: str, side: int) -> None:
        model = FAMILY[name]()
        assert isinstance(model, Classifier)
        assert n_params(model) <= 100_000
        assert model(torch.randn(3, 1, side, side)).shape == (3, 10)

    def test_documented_default_counts(self) -> None:
        assert n_params(vgg_small()) == 72_666
        assert n_params(inception_small()) == 29_554
        assert n_params(resnet_small()) == 77_754
        assert n_params(resnet_small(block="bottleneck")) == 33_090

    def test_rgb_and_classes(self) -> None:
        model = resnet_small(in_channels=3, num_classes=2)
        assert model(torch.randn(2, 3, 16, 16)).shape == (2, 2)

    def test_dropout_before_head(self) -> None:
        model = vgg_small(dropout=0.5)
        names = [n for n, _ in model.named_children()]
        assert names == ["features", "pool", "flatten", "dropout", "head"]
        assert model.dropout.p == 0.5

    def test_gradients_reach_first_layer(self) -> None:
        for name in MODELS:
            model = build_model(name)
            loss = model(torch.randn(4, 1, 8, 8)).logsumexp(1).sum()
            loss.backward()
            first = next(m for m in model.modules() if isinstance(m, nn.Conv2d))
            assert first.weight.grad is not None and first.weight.grad.abs().sum() > 0

    def test_build_model_by_name(self) -> None:
        assert set(MODELS) == {"vgg_small", "inception_small", "resnet_small"}
        model = build_model("resnet_small", num_classes=3, block="bottleneck")
        assert model.num_classes == 3
        assert isinstance(model.features[1][0], Bottleneck)

    def test_build_model_unknown_name_lists_choices(self) -> None:
        with pytest.raises(InputError, match="inception_small, resnet_small, vgg_small"):
            build_model("resnet50")
        with pytest.raises(InputError, match="bad argument for model 'vgg_small'"):
            build_model("vgg_small", depth=3)

    def test_bad_configuration(self) -> None:
        with pytest.raises(InputError, match="block must be 'basic' or 'bottleneck'"):
            resnet_small(block="wide")
        with pytest.raises(InputError, match="one number of blocks per stage"):
            resnet_small(depth=(1, 1))
        with pytest.raises(InputError, match="dropout must be in"):
            vgg_small(dropout=1.5)
        with pytest.raises(InputError, match="6-tuples"):
            inception_small(blocks=((1, 2, 3),))


class TestBadInput:
    def test_channels_last_names_permute(self) -> None:
        model = vgg_small(in_channels=3)
        with pytest.raises(InputError, match=r"x\.permute\(0, 3, 1, 2\)"):
            model(torch.zeros(2, 8, 8, 3))

    def test_wrong_channel_count_names_in_channels(self) -> None:
        model = resnet_small()
        with pytest.raises(InputError, match="in_channels=3"):
            model(torch.zeros(2, 3, 8, 8))

    def test_single_image_names_unsqueeze(self) -> None:
        with pytest.raises(InputError, match=r"x\.unsqueeze\(0\)"):
            inception_small()(torch.zeros(1, 8, 8))

    def test_integer_tensor_names_float(self) -> None:
        with pytest.raises(InputError, match=r"x\.float\(\)"):
            check_input(torch.zeros(1, 1, 8, 8, dtype=torch.uint8), 1)

    def test_numpy_names_from_numpy(self) -> None:
        import numpy as np

        with pytest.raises(InputError, match=r"torch\.from_numpy"):
            check_input(np.zeros((1, 1, 8, 8)), 1)

    def test_good_input_passes_unchanged(self) -> None:
        x = torch.zeros(2, 3, 4, 4).to(memory_format=torch.channels_last)
        assert check_input(x, 3) is x  # channels_last memory format is still NCHW


# issue 25: sizes that would allocate terabytes (or loop 2**40 times), lists where a
# name goes, floats and strings where an int or a probability goes
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: make_activation(["relu"]), r"activation must be one of .* got list"),
        (lambda: ResidualBlock(4, 4, act=["relu"]), r"activation must be one of"),
        (lambda: ConvBNAct(3, 4, groups=np.float32(2.0)), r"groups must be an integer"),
        (lambda: ConvBNAct(3, 4, groups=2), r"groups=2 must divide in_channels \(3\)"),
        (lambda: ConvBNAct(2**20, 2**20), r"3x3 convolution .* would take 36 TiB"),
        (lambda: ConvBNAct(3, 4, kernel_size=2**40), r"kernel_size must be at most 65536"),
        (lambda: ConvBNAct(3, 4, bn=1), r"bn must be True or False"),
        (lambda: Bottleneck(8, 4, expansion=2**63), r"expansion must be at most 1024"),
        (lambda: VGGStage(1, 4, n_convs=2**40), r"n_convs must be at most 1024"),
        (lambda: InceptionBlock(2**64 - 1, 4, 4, 4, 2, 2, 2), r"in_channels must be at most"),
        (lambda: Classifier(ConvBNAct(1, 4), 4, 10, 1, dropout=[1, 2]), r"dropout must be a real"),
        (lambda: Classifier(ConvBNAct(1, 4), -1, 10, 1), r"num_features must be >= 1"),
        (lambda: Classifier(None, 4, 10, 1), r"features must be a torch.nn.Module"),
        (lambda: Classifier(ConvBNAct(1, 4), 2**20, 2**20, 1), r"linear head .* would take"),
        (lambda: vgg_small(widths=None), r"widths must be a non-empty sequence"),
        (lambda: vgg_small(convs_per_stage=2**63), r"convs_per_stage must be at most 1024"),
        (lambda: vgg_small(num_classes=2**63), r"num_classes must be at most"),
        (lambda: vgg_small(dropout="3"), r"dropout must be a real number.*--dropout"),
        (lambda: vgg_small(widths=(2**40,)), r"widths must be .*\(at most 268435456"),
        (lambda: vgg_small(widths=(2**20,)), r"3x3 convolution from 1048576 to 1048576"),
        (lambda: resnet_small(depth=1.4e252), r"depth must be a non-empty sequence"),
        (lambda: resnet_small(num_classes=2**40), r"num_classes must be at most"),
        (lambda: resnet_small(num_classes=2**27), r"linear head \(134217728 classes"),
        (lambda: resnet_small(block=["basic"]), r"block must be 'basic' or 'bottleneck'"),
        (lambda: inception_small(in_channels=2**64 - 1), r"in_channels must be at most"),
        (lambda: inception_small(blocks=None), r"blocks must be a non-empty sequence"),
        # each layer is affordable, the whole is not: counted on the meta device
        (
            lambda: resnet_small(widths=(2048,) * 8, depth=8),
            r"resnet_small .* would have [\d,]+ parameters; the limit is 268,435,456",
        ),
        (lambda: build_model(["vgg_small"]), r"unknown model"),
    ],
)
def test_issue25_hostile_arguments_are_refused(call, match) -> None:
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_numpy_integers_and_bounds_still_build() -> None:
    torch.manual_seed(0)
    a = vgg_small(widths=(np.int64(4), 8), num_classes=np.int64(3), convs_per_stage=np.int64(1))
    torch.manual_seed(0)
    b = vgg_small(widths=(4, 8), num_classes=3, convs_per_stage=1)
    # the meta-device count draws no random numbers: same seed, same weights
    for p, q in zip(a.parameters(), b.parameters(), strict=True):
        assert torch.equal(p, q)
    assert isinstance(a.num_classes, int) and a(torch.zeros(1, 1, 8, 8)).shape == (1, 3)
    assert Bottleneck(8, 2, expansion=1024).out_channels == 2048
    assert ConvBNAct(4, 4, groups=np.int64(2)).conv.groups == 2
