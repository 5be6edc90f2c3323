"""Tests of robopercept.nn.functional: the layer arithmetic in NumPy against torch.

Parity tolerance: 1e-5 (absolute and relative) in float32. Each output is a sum of at
most a few dozen products of standard-normal numbers, whose float32 rounding error is
~1e-6; the two implementations sum in different orders, so exact equality is not expected.
"""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.functional import (
    ConvSpec,
    ReceptiveField,
    avg_pool2d,
    conv2d,
    conv_output_size,
    conv_transpose2d,
    im2col,
    max_pool2d,
    parameter_count,
    receptive_field,
    sum_pool2d,
)

torch = pytest.importorskip("torch")
F = torch.nn.functional

TOL = {"rtol": 1e-5, "atol": 1e-5}
N_CASES = 30


def _t(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(a))


def _conv_cases(seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < N_CASES:
        g = int(rng.integers(1, 4))
        k = tuple(int(v) for v in rng.integers(1, 5, 2))
        s = tuple(int(v) for v in rng.integers(1, 4, 2))
        p = tuple(int(v) for v in rng.integers(0, 3, 2))
        d = tuple(int(v) for v in rng.integers(1, 3, 2))
        hw = tuple(
            max(d[i] * (k[i] - 1) + 1 - 2 * p[i], 1) + int(rng.integers(0, 6)) for i in range(2)
        )
        cases.append(
            {
                "n": int(rng.integers(1, 3)),
                "c": g * int(rng.integers(1, 4)),
                "o": g * int(rng.integers(1, 4)),
                "g": g,
                "k": k,
                "s": s,
                "p": p,
                "d": d,
                "hw": hw,
                "bias": bool(rng.integers(0, 2)),
                "rng": rng,
            }
        )
    return cases


class TestConv2d:
    @pytest.mark.parametrize("case", _conv_cases(), ids=lambda c: f"g{c['g']}k{c['k']}s{c['s']}")
    def test_parity_with_torch(self, case: dict) -> None:
        rng = case["rng"]
        x = rng.standard_normal((case["n"], case["c"], *case["hw"])).astype(np.float32)
        w = rng.standard_normal((case["o"], case["c"] // case["g"], *case["k"])).astype(np.float32)
        b = rng.standard_normal(case["o"]).astype(np.float32) if case["bias"] else None
        ours = conv2d(x, w, b, case["s"], case["p"], case["d"], case["g"])
        ref = F.conv2d(
            _t(x), _t(w), None if b is None else _t(b), case["s"], case["p"], case["d"], case["g"]
        ).numpy()
        assert ours.dtype == np.float32
        assert ours.shape == ref.shape
        np.testing.assert_allclose(ours, ref, **TOL)
        # the output-size formula predicts the real shape
        assert (
            conv_output_size(case["hw"], case["k"], case["s"], case["p"], case["d"])
            == (ref.shape[2:])
        )

    def test_impulse_gives_the_flipped_kernel(self) -> None:
        # cross-correlation: y[i, j] = sum w[a, b] x[i + a - 1, j + b - 1], so a unit
        # impulse at the centre comes out as the kernel rotated by 180 degrees
        x = np.zeros((1, 1, 3, 3))
        x[0, 0, 1, 1] = 1.0
        w = np.arange(9.0).reshape(1, 1, 3, 3)
        np.testing.assert_array_equal(conv2d(x, w, padding=1)[0, 0], w[0, 0, ::-1, ::-1])

    def test_hand_computed_stride_bias_and_unbatched(self) -> None:
        x = np.arange(16.0).reshape(1, 4, 4)  # unbatched (C, H, W)
        y = conv2d(x, np.ones((2, 1, 2, 2)), b=[0.0, 100.0], stride=2)
        # window sums of the 2x2 blocks of 0..15: 0+1+4+5 = 10, 2+3+6+7 = 18, ...
        np.testing.assert_array_equal(y[0], [[10.0, 18.0], [42.0, 50.0]])
        np.testing.assert_array_equal(y[1], y[0] + 100.0)

    def test_depthwise_is_per_channel(self) -> None:
        rng = np.random.default_rng(1)
        x = rng.standard_normal((1, 3, 5, 5))
        w = rng.standard_normal((3, 1, 3, 3))
        y = conv2d(x, w, groups=3)
        for c in range(3):
            np.testing.assert_allclose(y[:, c : c + 1], conv2d(x[:, c : c + 1], w[c : c + 1]))

    def test_integer_input_computes_in_float64(self) -> None:
        y = conv2d(np.ones((1, 1, 3, 3), dtype=np.uint8), np.ones((1, 1, 3, 3), dtype=np.int64))
        assert y.dtype == np.float64
        assert y.item() == 9.0


class TestIm2col:
    @pytest.mark.parametrize("seed", range(5))
    def test_parity_with_unfold(self, seed: int) -> None:
        case = _conv_cases(seed)[0]
        x = case["rng"].standard_normal((case["n"], case["c"], *case["hw"])).astype(np.float32)
        ours = im2col(x, case["k"], case["s"], case["p"], case["d"])
        ref = F.unfold(_t(x), case["k"], case["d"], case["p"], case["s"]).numpy()
        np.testing.assert_array_equal(ours, ref)  # a pure copy: exact


def _transpose_cases(seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    cases = []
    while len(cases) < N_CASES:
        g = int(rng.integers(1, 4))
        k = tuple(int(v) for v in rng.integers(1, 5, 2))
        s = tuple(int(v) for v in rng.integers(1, 4, 2))
        p = tuple(int(v) for v in rng.integers(0, 3, 2))
        d = tuple(int(v) for v in rng.integers(1, 3, 2))
        op = tuple(int(rng.integers(0, max(s[i], d[i]))) for i in range(2))
        hw = tuple(int(v) for v in rng.integers(1, 6, 2))
        out = [(hw[i] - 1) * s[i] - 2 * p[i] + d[i] * (k[i] - 1) + op[i] + 1 for i in range(2)]
        if min(out) < 1:
            continue
        cases.append(
            {
                "n": int(rng.integers(1, 3)),
                "c": g * int(rng.integers(1, 4)),
                "o": g * int(rng.integers(1, 4)),
                "g": g,
                "k": k,
                "s": s,
                "p": p,
                "d": d,
                "op": op,
                "hw": hw,
                "bias": bool(rng.integers(0, 2)),
                "rng": rng,
            }
        )
    return cases


class TestConvTranspose2d:
    @pytest.mark.parametrize(
        "case", _transpose_cases(), ids=lambda c: f"g{c['g']}k{c['k']}s{c['s']}op{c['op']}"
    )
    def test_parity_with_torch(self, case: dict) -> None:
        rng = case["rng"]
        x = rng.standard_normal((case["n"], case["c"], *case["hw"])).astype(np.float32)
        w = rng.standard_normal((case["c"], case["o"] // case["g"], *case["k"])).astype(np.float32)
        b = rng.standard_normal(case["o"]).astype(np.float32) if case["bias"] else None
        ours = conv_transpose2d(
            x, w, b, case["s"], case["p"], case["op"], dilation=case["d"], groups=case["g"]
        )
        ref = F.conv_transpose2d(
            _t(x),
            _t(w),
            None if b is None else _t(b),
            case["s"],
            case["p"],
            case["op"],
            case["g"],
            case["d"],
        ).numpy()
        assert ours.shape == ref.shape
        np.testing.assert_allclose(ours, ref, **TOL)
        expected = conv_output_size(
            case["hw"], case["k"], case["s"], case["p"], case["d"],
            transposed=True, output_padding=case["op"],
        )  # fmt: skip
        assert expected == ref.shape[2:]

    def test_is_the_adjoint_of_conv2d(self) -> None:
        # <conv2d(x, w), y> == <x, conv_transpose2d(y, w)> with the same geometry
        rng = np.random.default_rng(2)
        x = rng.standard_normal((2, 4, 9, 8))
        w = rng.standard_normal((6, 2, 3, 2))
        kw = {"stride": 2, "padding": 1, "dilation": (1, 2)}
        y = rng.standard_normal(conv2d(x, w, groups=2, **kw).shape)
        lhs = np.sum(conv2d(x, w, groups=2, **kw) * y)
        # y is (5, 4); transposed back: H = 4*2 - 2 + 2 + 1 = 9, W = 3*2 - 2 + 2 + 1 = 7,
        # one short of 8: output_padding=(0, 1) recovers x's size
        xt = conv_transpose2d(y, w, output_padding=(0, 1), groups=2, **kw)
        assert xt.shape == x.shape
        np.testing.assert_allclose(lhs, np.sum(x * xt), rtol=1e-12)


def _pool_cases(seed: int, dilation: bool) -> list[dict]:
    rng = np.random.default_rng(seed)
    cases = []
    for _ in range(N_CASES):
        k = tuple(int(v) for v in rng.integers(1, 5, 2))
        s = None if rng.integers(0, 4) == 0 else tuple(int(v) for v in rng.integers(1, 4, 2))
        p = tuple(int(rng.integers(0, k[i] // 2 + 1)) for i in range(2))
        d = tuple(int(v) for v in rng.integers(1, 3, 2)) if dilation else (1, 1)
        hw = tuple(
            max(d[i] * (k[i] - 1) + 1 - 2 * p[i], 1) + int(rng.integers(0, 6)) for i in range(2)
        )
        cases.append({"k": k, "s": s, "p": p, "d": d, "hw": hw, "rng": rng})
    return cases


class TestPooling:
    @pytest.mark.parametrize("case", _pool_cases(0, dilation=True))
    def test_max_pool_parity(self, case: dict) -> None:
        x = case["rng"].standard_normal((2, 3, *case["hw"])).astype(np.float32)
        ours = max_pool2d(x, case["k"], case["s"], case["p"], case["d"])
        ref = F.max_pool2d(_t(x), case["k"], case["s"], case["p"], case["d"]).numpy()
        np.testing.assert_array_equal(ours, ref)  # a max is exact

    @pytest.mark.parametrize("case", _pool_cases(1, dilation=False))
    def test_avg_and_sum_pool_parity(self, case: dict) -> None:
        x = case["rng"].standard_normal((2, 3, *case["hw"])).astype(np.float32)
        k, s, p = case["k"], case["s"], case["p"]
        for include in (True, False):
            ours = avg_pool2d(x, k, s, p, count_include_pad=include)
            ref = F.avg_pool2d(_t(x), k, s, p, count_include_pad=include).numpy()
            assert ours.dtype == np.float32
            np.testing.assert_allclose(ours, ref, **TOL)
        ref_avg = F.avg_pool2d(_t(x), k, s, p).numpy()
        np.testing.assert_allclose(sum_pool2d(x, k, s, p), ref_avg * k[0] * k[1], **TOL)

    def test_max_pool_ignores_padding(self) -> None:
        # all-negative input: -inf padding never wins, a zero padding would
        x = -np.ones((1, 1, 2, 2))
        np.testing.assert_array_equal(max_pool2d(x, 2, 1, 1), -np.ones((1, 1, 3, 3)))


class TestConvOutputSize:
    def test_known_values(self) -> None:
        assert conv_output_size(224, 7, 2, 3) == 112  # ResNet stem
        assert conv_output_size(112, 3, 2, 1) == 56  # its max pool
        assert conv_output_size(5, 3, dilation=2) == 1
        assert conv_output_size((7, 9), (3, 1), (2, 1)) == (3, 9)
        assert conv_output_size(4, 3, 2, 1, transposed=True, output_padding=1) == 8

    def test_empty_output_is_refused(self) -> None:
        with pytest.raises(InputError, match="bigger than the padded input"):
            conv_output_size(2, 5)
        with pytest.raises(InputError, match="lower the padding"):
            conv_output_size(1, 1, padding=1, transposed=True)


class TestReceptiveField:
    def test_vgg_claim(self) -> None:
        # two stacked 3x3 convolutions see 5x5, like one 5x5, with 2 * 9 = 18 weights per
        # (input, output) channel pair instead of 25; three see 7x7 with 27 instead of 49
        assert receptive_field([(3, 1, 1)] * 2)[-1].size == receptive_field([(5, 1, 2)])[0].size
        assert receptive_field([(3, 1, 1)] * 2)[-1].size == 5
        assert receptive_field([(3, 1, 1)] * 3)[-1].size == 7
        pair = ConvSpec(1, 1, 3, padding=1, bias=False)
        assert parameter_count([pair, pair]) == 18
        assert parameter_count(ConvSpec(1, 1, 5, padding=2, bias=False)) == 25
        assert parameter_count([pair] * 3) == 27 < parameter_count(ConvSpec(1, 1, 7, bias=False))
        c = 64
        assert parameter_count([ConvSpec(c, c, 3, bias=False)] * 2) == 18 * c * c

    def test_records(self) -> None:
        rfs = receptive_field([ConvSpec(3, 8, 7, stride=2, padding=3), (3, 2, 1), 3])
        assert rfs[0] == ReceptiveField(7, 2, 3, 1, 7, 2, 0.0)
        assert (rfs[1].size, rfs[1].jump, rfs[1].start) == (11, 4, 0.0)
        assert (rfs[2].size, rfs[2].jump, rfs[2].start) == (19, 4, 4.0)
        assert rfs[2].span(1) == (-1.0, 17.0)

    @pytest.mark.parametrize(
        "stack",
        [
            [(3, 2, 1), (3, 2, 1)],
            [(3, 1, 0, 2), ("avg", 2, 2, 0), (3, 2, 1)],
            [(5, 2, 2), (3, 1, 1, 2), ("avg", 3, 1, 1)],
        ],
    )
    def test_brute_force_by_perturbation(self, stack: list[tuple]) -> None:
        # run the stack with positive weights (no cancellation), perturb one input pixel at
        # a time, and compare the outputs that change with the predicted fields
        n = 14
        base = np.zeros((1, 1, n, n))

        def run(x: np.ndarray) -> np.ndarray:
            for layer in stack:
                if layer[0] == "avg":
                    x = avg_pool2d(x, layer[1], layer[2], layer[3])
                else:
                    k, s, p, *d = layer
                    x = conv2d(
                        x, np.ones((1, 1, k, k)), stride=s, padding=p, dilation=d[0] if d else 1
                    )
            return x[0, 0]

        layers = [layer[1:] if layer[0] == "avg" else layer for layer in stack]
        rf = receptive_field(layers)[-1]
        y0 = run(base)
        predicted = np.zeros((*y0.shape, n, n), dtype=bool)  # outputs x inputs
        for i in range(y0.shape[0]):
            lo_r, hi_r = rf.span(i)
            for j in range(y0.shape[1]):
                lo_c, hi_c = rf.span(j)
                rows = (np.arange(n) >= lo_r) & (np.arange(n) <= hi_r)
                cols = (np.arange(n) >= lo_c) & (np.arange(n) <= hi_c)
                predicted[i, j] = rows[:, None] & cols[None, :]
        for q in range(n):
            for r in range(n):
                x = base.copy()
                x[0, 0, q, r] = 1.0
                changed = run(x) != y0
                np.testing.assert_array_equal(changed, predicted[:, :, q, r])


class TestParameterCount:
    @pytest.mark.parametrize(
        "spec",
        [
            ConvSpec(3, 16, 3),
            ConvSpec(16, 32, (3, 5), groups=4, bias=False),
            ConvSpec(32, 32, 3, groups=32),  # depthwise
            ConvSpec(6, 9, 1, groups=3),
        ],
    )
    def test_equals_torch(self, spec: ConvSpec) -> None:
        layer = torch.nn.Conv2d(
            spec.in_channels,
            spec.out_channels,
            spec.kernel_size,
            groups=spec.groups,
            bias=spec.bias,
        )
        assert parameter_count(spec) == sum(p.numel() for p in layer.parameters())

    def test_bad_spec(self) -> None:
        with pytest.raises(InputError, match="groups=4 must divide"):
            parameter_count(ConvSpec(6, 8, 3, groups=4))
        with pytest.raises(InputError, match="wrap it as ConvSpec"):
            parameter_count([(3, 1, 1)])  # type: ignore[list-item]


class TestBadInput:
    def test_channel_mismatch(self) -> None:
        with pytest.raises(InputError, match=r"x has 4 channels .* expect .* = 3"):
            conv2d(np.zeros((1, 4, 5, 5)), np.zeros((2, 3, 3, 3)))

    def test_channels_last_is_recognized(self) -> None:
        with pytest.raises(InputError, match=r"channels-last .* x.transpose\(0, 3, 1, 2\)"):
            conv2d(np.zeros((1, 8, 8, 3)), np.zeros((2, 3, 3, 3)))
        with pytest.raises(InputError, match="channels-last"):
            conv_transpose2d(np.zeros((1, 8, 8, 3)), np.zeros((3, 2, 3, 3)))

    def test_groups_not_dividing(self) -> None:
        with pytest.raises(InputError, match=r"groups=3 must divide .* common divisors \[1, 2\]"):
            conv2d(np.zeros((1, 4, 5, 5)), np.zeros((2, 1, 3, 3)), groups=3)
        with pytest.raises(InputError, match="groups=2 must divide"):
            conv_transpose2d(np.zeros((1, 3, 5, 5)), np.zeros((3, 1, 3, 3)), groups=2)

    def test_kernel_bigger_than_padded_input(self) -> None:
        with pytest.raises(InputError, match=r"bigger than the padded input height .* padding"):
            conv2d(np.zeros((1, 1, 3, 8)), np.zeros((1, 1, 5, 3)))
        with pytest.raises(InputError, match="dilated extent 5"):
            conv2d(np.zeros((1, 1, 4, 4)), np.zeros((1, 1, 3, 3)), dilation=2)
        with pytest.raises(InputError, match="bigger than the padded input"):
            max_pool2d(np.zeros((1, 1, 2, 2)), 3)

    def test_bad_geometry(self) -> None:
        x = np.zeros((1, 1, 6, 6))
        with pytest.raises(InputError, match="stride must be >= 1"):
            conv2d(x, np.zeros((1, 1, 3, 3)), stride=0)
        with pytest.raises(InputError, match=r"int or a pair of ints"):
            conv2d(x, np.zeros((1, 1, 3, 3)), padding=1.5)  # type: ignore[arg-type]
        with pytest.raises(InputError, match="at most half the kernel"):
            avg_pool2d(x, 2, padding=2)
        with pytest.raises(InputError, match=r"output_padding .* must be smaller"):
            conv_transpose2d(x, np.zeros((1, 1, 3, 3)), stride=2, output_padding=2)
        with pytest.raises(InputError, match=r"bias must have shape \(2,\)"):
            conv2d(x, np.zeros((2, 1, 3, 3)), b=np.zeros(3))
        with pytest.raises(InputError, match="must be 3-D or 4-D"):
            conv2d(np.zeros((6, 6)), np.zeros((1, 1, 3, 3)))
        with pytest.raises(InputError, match=r"\(kernel, stride, padding, dilation\)"):
            receptive_field([(3, 1, 1, 1, 1)])
        with pytest.raises(InputError, match="works per axis"):
            receptive_field([ConvSpec(1, 1, (3, 5))])


# issue 25: sizes that would allocate terabytes, huge strides, non-iterable layer lists,
# values whose products overflow, and a groups message that enumerated 2**40 divisors
_X = np.random.default_rng(0).uniform(0, 1, (1, 1, 16, 16))
_W = np.ones((2, 1, 3, 3)) / 9


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: im2col(_X, 3, padding=2**63), r"at most 2\*\*31 - 1"),
        (lambda: im2col(_X, 3, padding=2**20), r"padded input .* would take .*TiB.*lower padding"),
        (lambda: conv2d(_X, _W, stride=2**63), r"stride must be at most"),
        (lambda: conv2d(_X, _W, padding=100_000), r"limit is 1 GiB"),
        (
            lambda: conv_transpose2d(_X, np.ones((1, 2, 3, 3)), dilation=2**30),
            r"the output .* would take .* GiB",
        ),
        (lambda: conv2d(_X * 1e300, _W), r"x has values up to .*e\+299.*rescale"),
        (lambda: conv_transpose2d(_X, np.ones((1, 2, 3, 3)) * 1e200), r"w has values up to"),
        (lambda: conv2d(_X.astype(np.float32) * 1e20, _W.astype(np.float32)), r"x has values"),
        (lambda: conv2d(_X, _W.astype(object)), r"w must be a real numeric array"),
        (lambda: conv2d(_X, _W, np.array(["a", "b"])), r"bias must be a real numeric"),
        (lambda: conv2d(_X, _W, [[1], [2, 3]]), r"bias must be array-like"),
        (lambda: parameter_count(None), r"spec must be a ConvSpec or a sequence"),
        (lambda: parameter_count(3), r"spec must be a ConvSpec"),
        (lambda: receptive_field(None), r"layers must be a sequence"),
        (lambda: receptive_field([float("nan"), (2, 2, 0)]), r"layers\[0\] must be"),
        (lambda: receptive_field([None]), r"layers\[0\] must be"),
        (
            lambda: parameter_count(ConvSpec(2**40, 2**41, 3, groups=3)),
            r"choose groups a divisor of gcd\(1099511627776, 2199023255552\)",
        ),
    ],
)
def test_issue25_hostile_parameters_are_refused(call, match) -> None:
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_valid_extremes_still_work() -> None:
    # a large but affordable padding and tiny values keep torch's answers
    x = _X * 1e-300
    np.testing.assert_allclose(
        conv2d(x, _W, padding=40) * 1e300,
        F.conv2d(_t(_X), _t(_W), padding=40).numpy(),
        **TOL,
    )
    assert im2col(_X, 3, padding=200).shape == (1, 9, 414 * 414)
    # x at the bound (1e150) is still computed, finite
    assert np.isfinite(conv2d(_X * 1e150, _W)).all()
    # a huge group count on a divisible layer is plain arithmetic
    assert parameter_count(ConvSpec(2**40, 2**40, 1, groups=2**40, bias=False)) == 2**40
    assert receptive_field([(3, 2**40, 0)])[-1].jump == 2**40
