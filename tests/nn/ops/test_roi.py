"""RoI Align vs onnxruntime, RoI pooling vs a NumPy oracle of its quantization,
the modules, bad input (issue 26, item 1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.roi import RoIAlign, RoIPool, roi_align, roi_pool  # noqa: E402
from tests.nn.ops.test_boxes import random_xyxy  # noqa: E402


# ------------------------------------------------------------------ RoI ops
def ort_roi_align(x, rois, bidx, out, scale, ratio, aligned):
    import onnxruntime as ort
    from onnx import TensorProto, helper

    node = helper.make_node(
        "RoiAlign",
        ["X", "rois", "bidx"],
        ["Y"],
        mode="avg",
        output_height=out[0],
        output_width=out[1],
        sampling_ratio=ratio,
        spatial_scale=scale,
        coordinate_transformation_mode="half_pixel" if aligned else "output_half_pixel",
    )
    graph = helper.make_graph(
        [node],
        "roi",
        [
            helper.make_tensor_value_info("X", TensorProto.FLOAT, list(x.shape)),
            helper.make_tensor_value_info("rois", TensorProto.FLOAT, [None, 4]),
            helper.make_tensor_value_info("bidx", TensorProto.INT64, [None]),
        ],
        [helper.make_tensor_value_info("Y", TensorProto.FLOAT, None)],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 16)])
    model.ir_version = 8
    sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    return sess.run(None, {"X": x, "rois": rois, "bidx": bidx})[0]


def random_rois(rng, k, n_images, size):
    b = random_xyxy(rng, k, size).astype(np.float32)
    b[: k // 4] -= size / 4  # some partly outside the map
    return b, rng.integers(0, n_images, k)


class TestRoIAlign:
    @pytest.mark.parametrize("aligned", [True, False])
    @pytest.mark.parametrize(("ratio", "scale"), [(0, 0.5), (2, 0.25), (-1, 1.0)])
    def test_equals_onnxruntime(self, aligned, ratio, scale):
        # float32 on both sides; sums of a few bilinear samples agree to ~1e-6
        rng = np.random.default_rng(7)
        x = rng.normal(size=(2, 3, 13, 11)).astype(np.float32)
        rois, bidx = random_rois(rng, 12, 2, 13 / scale)
        ref = ort_roi_align(x, rois, bidx, (3, 4), scale, max(ratio, 0), aligned)
        t = torch.cat([torch.from_numpy(bidx).float()[:, None], torch.from_numpy(rois)], 1)
        ours = roi_align(torch.from_numpy(x), t, (3, 4), scale, ratio, aligned).numpy()
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-5)

    def test_list_form_and_hand_case(self):
        x = torch.arange(16.0).reshape(1, 1, 4, 4)
        # x[r, c] = 4 r + c; the region spans feature coordinates [1, 3]: 2x2 samples at
        # 1.5 and 2.5, where bilinear interpolation of a linear map is exact: 4 * 2 + 2
        one = roi_align(x, [torch.tensor([[1.5, 1.5, 3.5, 3.5]])], 1, aligned=True)
        assert one.item() == 10.0
        # not aligned: the same box starts at 1.5; bins of 1 x 1 sampled at their centres
        two = roi_align(x, [torch.tensor([[0.0, 0.0, 2.0, 2.0]])], 2, sampling_ratio=1)
        assert two[0, 0].tolist() == [[2.5, 3.5], [6.5, 7.5]]
        rng = np.random.default_rng(8)
        xs = torch.from_numpy(rng.normal(size=(2, 2, 9, 9)))
        b0, b1 = torch.tensor([[1.0, 1, 6, 5]]), torch.tensor([[0.0, 2, 3, 8], [2, 2, 4, 4]])
        a = roi_align(xs, [b0.double(), b1.double()], 2, sampling_ratio=2)
        rows = torch.tensor([[0.0, 1, 1, 6, 5], [1, 0, 2, 3, 8], [1, 2, 2, 4, 4]]).double()
        torch.testing.assert_close(a, roi_align(xs, rows, 2, sampling_ratio=2))

    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    @pytest.mark.parametrize(("ratio", "aligned"), [(2, True), (0, False), (3, False)])
    def test_compiled_forward_equals_the_differentiable_one(self, dtype, ratio, aligned):
        # without a gradient to keep, roi_align runs a compiled kernel over each region's
        # window; with one, the dense products: the two agree to float rounding (sums of
        # the same weighted samples in another order, float64 accumulation in the kernel)
        rng = np.random.default_rng(11)
        x = torch.from_numpy(rng.normal(size=(2, 3, 17, 13))).to(dtype)
        rois, bidx = random_rois(rng, 40, 2, 17 / 0.5)
        rois[:3] *= 40  # far beyond the map: 0
        rows = np.concatenate([bidx[:, None], rois], axis=1)
        t = torch.from_numpy(rows).to(dtype)
        fast = roi_align(x, t, (3, 4), 0.5, ratio, aligned)
        slow = roi_align(x.clone().requires_grad_(True), t, (3, 4), 0.5, ratio, aligned)
        assert fast.dtype == dtype and not fast.requires_grad and slow.requires_grad
        tol = 1e-5 if dtype == torch.float32 else 1e-12
        torch.testing.assert_close(fast, slow.detach(), rtol=0, atol=tol)
        assert bool((fast[:3] == 0).all())

    def test_gradcheck(self):
        x = torch.randn(1, 2, 6, 5, dtype=torch.float64, requires_grad=True)
        rois = torch.tensor([[0.0, 0.3, 0.7, 4.1, 5.2], [0.0, 1.2, 0.1, 2.9, 3.3]]).double()
        assert torch.autograd.gradcheck(lambda t: roi_align(t, rois, 2, 1.0, 2, True), (x,))


def oracle_roi_pool(x, rois, bidx, out, scale):
    """Loops over every RoI, bin and pixel of torchvision's RoI pooling."""
    K = len(rois)
    _, C, H, W = x.shape
    res = np.zeros((K, C, *out))
    rnd = lambda v: math.floor(abs(v) + 0.5) * (1 if v >= 0 else -1)  # noqa: E731
    for k in range(K):
        x1, y1, x2, y2 = (rnd(v * scale) for v in rois[k])
        rw, rh = max(x2 - x1 + 1, 1), max(y2 - y1 + 1, 1)
        for ph in range(out[0]):
            for pw in range(out[1]):
                hs = min(max(math.floor(ph * rh / out[0]) + y1, 0), H)
                he = min(max(math.ceil((ph + 1) * rh / out[0]) + y1, 0), H)
                ws = min(max(math.floor(pw * rw / out[1]) + x1, 0), W)
                we = min(max(math.ceil((pw + 1) * rw / out[1]) + x1, 0), W)
                if he <= hs or we <= ws:
                    continue
                res[k, :, ph, pw] = x[bidx[k], :, hs:he, ws:we].max(axis=(1, 2))
    return res


def test_modules_equal_functions():
    x = torch.from_numpy(np.random.default_rng(11).normal(size=(2, 3, 9, 9)))
    rois = torch.tensor([[1.0, 0, 0, 6, 7], [0, 2, 1, 8, 8]]).double()
    layer = RoIAlign((2, 3), 0.5, 2, True)
    assert torch.equal(layer(x, rois), roi_align(x, rois, (2, 3), 0.5, 2, True))
    assert "aligned=True" in repr(layer)
    assert torch.equal(RoIPool(3, 0.5)(x, rois), roi_pool(x, rois, 3, 0.5))
    with pytest.raises(InputError, match="output_size must be"):
        RoIPool("7")


class TestRoIPool:
    @pytest.mark.parametrize("scale", [1.0, 0.5, 0.3])
    def test_equals_oracle(self, scale):
        rng = np.random.default_rng(9)
        x = rng.normal(size=(2, 3, 10, 12))
        rois, bidx = random_rois(rng, 15, 2, 11 / scale)
        rois = rois.astype(np.float64)
        rois[0] = [2.5, 1.5, 2.5, 1.5]  # a point box: a 1x1 region, rounding half away
        t = torch.cat([torch.from_numpy(bidx).double()[:, None], torch.from_numpy(rois)], 1)
        ours = roi_pool(torch.from_numpy(x), t, (3, 2), scale).numpy()
        np.testing.assert_array_equal(ours, oracle_roi_pool(x, rois, bidx, (3, 2), scale))

    def test_gradcheck(self):
        x = torch.randn(1, 2, 6, 5, dtype=torch.float64, requires_grad=True)
        rois = [torch.tensor([[0.0, 0.0, 4.0, 5.0], [1.0, 1.0, 2.0, 2.0]]).double()]
        assert torch.autograd.gradcheck(lambda t: roi_pool(t, rois, 2), (x,))

    @pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
    def test_compiled_forward_equals_the_differentiable_one(self, dtype):
        # without a gradient to keep, roi_pool runs a compiled kernel over each bin's
        # window; with one, the gathered windows: a maximum is exact, so they are equal,
        # NaN (propagated, as amax), infinities and empty bins (0) included
        rng = np.random.default_rng(12)
        x = torch.from_numpy(rng.normal(size=(2, 3, 17, 13))).to(dtype)
        x[0, 1, 4:6, 3] = float("nan")
        x[1, 0] = float("-inf")  # a whole map: its bins are -inf
        x[1, 2, 9, 2] = float("inf")
        rois, bidx = random_rois(rng, 60, 2, 17 / 0.5)
        rois[:3] *= 40  # far beyond the map: empty bins
        rows = torch.from_numpy(np.concatenate([bidx[:, None], rois], axis=1)).to(dtype)
        fast = roi_pool(x, rows, (3, 4), 0.5)
        slow = roi_pool(x.clone().requires_grad_(True), rows, (3, 4), 0.5)
        assert fast.dtype == dtype and not fast.requires_grad and slow.requires_grad
        torch.testing.assert_close(fast, slow.detach(), rtol=0, atol=0, equal_nan=True)
        assert bool(fast.isnan().any()) and bool((fast[:3] == 0).all())
        assert bool(fast.isneginf().any()) and bool(fast.isposinf().any())

    def test_equals_onnxruntime_max_roi_pool(self):
        ort = pytest.importorskip("onnxruntime")
        from onnx import TensorProto, helper

        rng = np.random.default_rng(13)
        x = rng.normal(size=(2, 4, 15, 19)).astype(np.float32)
        rois, bidx = random_rois(rng, 50, 2, 15 / 0.25)
        rows = np.concatenate([bidx[:, None], rois], axis=1).astype(np.float32)
        vi = helper.make_tensor_value_info
        node = helper.make_node(
            "MaxRoiPool", ["X", "r"], ["Y"], pooled_shape=[3, 2], spatial_scale=0.25
        )
        graph = helper.make_graph(
            [node], "g",
            [vi("X", TensorProto.FLOAT, list(x.shape)), vi("r", TensorProto.FLOAT, [None, 5])],
            [vi("Y", TensorProto.FLOAT, None)],
        )  # fmt: skip
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 16)])
        sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
        want = sess.run(None, {"X": x, "r": rows})[0]
        with torch.no_grad():
            got = roi_pool(torch.from_numpy(x), torch.from_numpy(rows), (3, 2), 0.25).numpy()
        np.testing.assert_array_equal(got, want)


# ------------------------------------------------------------------ bad input
T4 = torch.tensor([[0.0, 0.0, 1.0, 1.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: roi_align(torch.zeros(1, 4, 4), [T4], 2), "one image"),
        (lambda: roi_align(torch.zeros(1, 1, 4, 4), T4, 2), r"got a \(K, 4\) tensor"),
        (
            lambda: roi_align(torch.zeros(1, 1, 4, 4), torch.tensor([[1.0, 0, 0, 1, 1]]), 2),
            r"whole batch indices in \[0, 0\]",
        ),
        (lambda: roi_pool(torch.zeros(1, 1, 4, 4), [T4, T4], 2), "one \\(Ki, 4\\) tensor per"),
        (lambda: roi_pool(torch.zeros(1, 1, 4, 4), [T4], 0), "output_size must be >= 1"),
        (lambda: roi_align(torch.zeros(1, 1, 4, 4), [T4], 2, 0.0), "spatial_scale must be in"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
