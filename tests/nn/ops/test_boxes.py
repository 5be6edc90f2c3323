"""Box operations (issue 26, item 1): formats, IoU vs pycocotools, GIoU and box coding
by hand, anchors, NMS vs onnxruntime and a brute-force oracle, RoI Align vs
onnxruntime, RoI pooling vs a NumPy oracle of its quantization, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.boxes import (  # noqa: E402
    AnchorGenerator,
    BoxCoder,
    RoIAlign,
    RoIPool,
    batched_nms,
    box_area,
    box_convert,
    box_iou,
    dihedral_boxes,
    generalized_box_iou,
    nms,
    non_max_suppression,
    roi_align,
    roi_pool,
)


def random_xyxy(rng: np.random.Generator, n: int, size: float = 100.0) -> np.ndarray:
    xy = rng.uniform(0, size, (n, 2))
    wh = rng.uniform(1, size / 3, (n, 2))
    return np.concatenate([xy, xy + wh], 1)


# ------------------------------------------------------------------ formats and IoU
class TestFormats:
    def test_hand_case(self):
        b = torch.tensor([[10.0, 20.0, 14.0, 26.0]])
        assert box_convert(b, "xyxy", "xywh").tolist() == [[10.0, 20.0, 4.0, 6.0]]
        assert box_convert(b, "xyxy", "cxcywh").tolist() == [[12.0, 23.0, 4.0, 6.0]]
        assert box_convert(torch.tensor([[12.0, 23, 4, 6]]), "cxcywh", "xyxy").tolist() == (
            b.tolist()
        )
        assert box_area(b).tolist() == [24.0]

    @pytest.mark.parametrize("a", ["xyxy", "xywh", "cxcywh"])
    @pytest.mark.parametrize("b", ["xyxy", "xywh", "cxcywh"])
    def test_round_trips(self, a, b):
        x = torch.from_numpy(random_xyxy(np.random.default_rng(0), 20))
        there = box_convert(box_convert(x, "xyxy", a), a, b)
        back = box_convert(box_convert(there, b, a), a, "xyxy")
        torch.testing.assert_close(back, x, rtol=0, atol=1e-12)


def coco_iou(a_xyxy: np.ndarray, b_xyxy: np.ndarray) -> np.ndarray:
    from pycocotools import mask

    def xywh(b):
        return np.concatenate([b[:, :2], b[:, 2:] - b[:, :2]], 1).tolist()

    return np.asarray(mask.iou(xywh(a_xyxy), xywh(b_xyxy), [0] * len(b_xyxy)))


class TestIoU:
    def test_equals_pycocotools(self):
        # pycocotools computes in double: the same arithmetic up to rounding (1e-9)
        rng = np.random.default_rng(1)
        a, b = random_xyxy(rng, 40), random_xyxy(rng, 30)
        b[:5] = a[:5] + rng.uniform(-3, 3, (5, 4)).clip(-0.5, 0.5)  # heavy overlaps
        ours = box_iou(torch.from_numpy(a), torch.from_numpy(b)).numpy()
        np.testing.assert_allclose(ours, coco_iou(a, b), rtol=0, atol=1e-9)
        assert (ours > 0.5).sum() >= 5  # the overlapping pairs are in the test

    def test_degenerate_boxes_give_zero(self):
        a = torch.tensor([[0.0, 0.0, 0.0, 10.0], [5.0, 5.0, 5.0, 5.0], [0.0, 0.0, 10.0, 10.0]])
        iou = box_iou(a, a)
        assert iou.tolist() == [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        assert box_iou(torch.zeros(0, 4), a).shape == (0, 3)

    def test_giou_hand_cases(self):
        a = torch.tensor([[0.0, 0.0, 1.0, 1.0]], dtype=torch.float64)
        b = torch.tensor(
            [[0.0, 0.0, 1.0, 1.0], [2.0, 0.0, 3.0, 1.0], [0.0, 0.0, 2.0, 2.0], [0.5, 0, 1.5, 1]],
            dtype=torch.float64,
        )
        # identical: 1; disjoint side by side: C = 3, U = 2 -> 0 - 1/3; inside a 2x2:
        # IoU 1/4, C = U; half overlap: IoU 0.5/1.5, C = 1.5 = U
        want = [[1.0, -1 / 3, 0.25, 1 / 3]]
        torch.testing.assert_close(generalized_box_iou(a, b), torch.tensor(want).double())
        pts = torch.tensor([[1.0, 1.0, 1.0, 1.0]])
        assert generalized_box_iou(pts, pts).tolist() == [[0.0]]  # C = 0: defined as 0

    def test_giou_properties(self):
        rng = np.random.default_rng(2)
        a = torch.from_numpy(random_xyxy(rng, 25))
        b = torch.from_numpy(random_xyxy(rng, 20))
        g, iou = generalized_box_iou(a, b), box_iou(a, b)
        assert bool((g <= iou + 1e-12).all()) and bool((g >= -1).all())
        torch.testing.assert_close(g, generalized_box_iou(b, a).T)


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


# ------------------------------------------------------------------ NMS
def oracle_nms(boxes, scores, thr, classes=None, score_threshold=None, top_k=None):
    """Plain-Python greedy NMS: sort by (-score, index), keep, drop IoU > thr, repeat."""
    n = len(scores)
    order = sorted(range(n), key=lambda i: (-scores[i], i))
    if score_threshold is not None:
        order = [i for i in order if scores[i] > score_threshold]

    def iou(p, q):
        iw = max(0.0, min(p[2], q[2]) - max(p[0], q[0]))
        ih = max(0.0, min(p[3], q[3]) - max(p[1], q[1]))
        inter = iw * ih
        union = (p[2] - p[0]) * (p[3] - p[1]) + (q[2] - q[0]) * (q[3] - q[1]) - inter
        return inter / union if union > 0 else 0.0

    keep = []
    for i in order:
        same = [k for k in keep if classes is None or classes[k] == classes[i]]
        if top_k is not None and len(same) >= top_k:
            continue
        if all(iou(boxes[i], boxes[k]) <= thr for k in same):
            keep.append(i)
    return keep


def ort_nms(boxes: np.ndarray, scores: np.ndarray, thr: float, score_thr=None, max_out=None):
    import onnx
    import onnxruntime as ort
    from onnx import TensorProto, helper

    inputs = ["boxes", "scores", "max_out", "iou", "score"]
    node = helper.make_node("NonMaxSuppression", inputs, ["sel"], center_point_box=0)
    graph = helper.make_graph(
        [node],
        "nms",
        [
            helper.make_tensor_value_info("boxes", TensorProto.FLOAT, [1, None, 4]),
            helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, 1, None]),
            helper.make_tensor_value_info("max_out", TensorProto.INT64, [1]),
            helper.make_tensor_value_info("iou", TensorProto.FLOAT, [1]),
            helper.make_tensor_value_info("score", TensorProto.FLOAT, [1]),
        ],
        [helper.make_tensor_value_info("sel", TensorProto.INT64, [None, 3])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 11)])
    model.ir_version = 7
    onnx.checker.check_model(model)
    sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    feeds = {
        "boxes": boxes[None].astype(np.float32),
        "scores": scores[None, None].astype(np.float32),
        "max_out": np.array([len(scores) if max_out is None else max_out], np.int64),
        "iou": np.array([thr], np.float32),
        "score": np.array([-1e30 if score_thr is None else score_thr], np.float32),
    }
    return sess.run(None, feeds)[0][:, 2].tolist()


def nms_case(seed: int, n: int, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (float32-exact) with distinct scores and no IoU within 1e-4 of ``thr``."""
    rng = np.random.default_rng(seed)
    while True:
        b = random_xyxy(rng, n, 60.0).astype(np.float32).astype(np.float64)
        s = rng.permutation(n).astype(np.float64) / n + 0.01  # distinct, float32-exact
        s = s.astype(np.float32).astype(np.float64)
        iou = box_iou(torch.from_numpy(b), torch.from_numpy(b)).numpy()
        if np.abs(iou - thr).min() > 1e-4:
            return b, s


class TestNMS:
    @pytest.mark.parametrize(("seed", "thr"), [(0, 0.3), (1, 0.5), (2, 0.7)])
    def test_equals_onnxruntime_and_oracle(self, seed, thr):
        b, s = nms_case(seed, 150, thr)
        ours = nms(torch.from_numpy(b).float(), torch.from_numpy(s).float(), thr).tolist()
        assert ours == ort_nms(b, s, thr)
        assert ours == oracle_nms(b.tolist(), s.tolist(), thr)
        assert 10 < len(ours) < 150  # suppression did something, not everything

    def test_score_threshold_and_top_k_equal_onnxruntime(self):
        b, s = nms_case(4, 120, 0.4)
        tb, ts = torch.from_numpy(b), torch.from_numpy(s)
        for st, k in [(0.3, 7), (0.5, 100), (None, 3)]:
            ours = non_max_suppression(tb, ts, 0.4, score_threshold=st, top_k=k).tolist()
            assert ours == ort_nms(b, s, 0.4, st, k)
            assert ours == oracle_nms(b.tolist(), s.tolist(), 0.4, None, st, k)

    def test_batched_equals_oracle(self):
        b, s = nms_case(5, 100, 0.5)
        cls = np.random.default_rng(5).integers(0, 3, 100)
        tb, ts, tc = torch.from_numpy(b), torch.from_numpy(s), torch.from_numpy(cls)
        ours = batched_nms(tb, ts, tc, 0.5).tolist()
        assert ours == oracle_nms(b.tolist(), s.tolist(), 0.5, cls.tolist())
        assert len(ours) > len(nms(tb, ts, 0.5))
        per_class = non_max_suppression(tb, ts, 0.5, top_k=2, idxs=tc).tolist()
        assert per_class == oracle_nms(b.tolist(), s.tolist(), 0.5, cls.tolist(), None, 2)
        assert len(per_class) == 6

    def test_ties_by_index_and_threshold_not_strict(self):
        b = torch.tensor([[0.0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, 5], [50, 50, 60, 60]])
        s = torch.tensor([0.5, 0.5, 0.5, 0.5])
        # equal scores: index order; box 1 = box 0 goes; IoU(0, 2) = 0.5 exactly does not
        # suppress at 0.5 (strict >, as onnxruntime), does below it
        assert nms(b, s, 0.5).tolist() == [0, 2, 3]
        assert nms(b, s, 0.49).tolist() == [0, 3]
        assert nms(b, s, 0.99).tolist() == [0, 2, 3]
        # onnxruntime keeps the same rule (its documented order is by score only)
        for thr in (0.5, 0.49, 0.99):
            assert nms(b, s, thr).tolist() == ort_nms(b.numpy(), s.numpy(), thr)

    def test_degenerate_and_empty(self):
        b = torch.tensor([[0.0, 0, 0, 10], [0, 0, 0, 10], [0, 0, 10, 10]])
        assert nms(b, torch.tensor([0.9, 0.8, 0.7]), 0.0).tolist() == [0, 1, 2]
        assert nms(torch.zeros(0, 4), torch.zeros(0), 0.5).tolist() == []
        s = torch.tensor([0.9, -math.inf, 0.7])
        assert nms(b, s, 0.5).tolist() == [0, 2, 1]

    def test_kernel_equals_numpy_reference(self):
        from robopercept.nn.ops.boxes import _greedy_kernel, _greedy_reference

        rng = np.random.default_rng(10)
        b = random_xyxy(rng, 200, 50.0)
        b[:10, 2] = b[:10, 0]  # zero-width boxes
        for cls in (np.zeros(200, np.int64), rng.integers(0, 4, 200)):
            for thr in (0.0, 0.3, 0.6, 1.0):
                want = _greedy_reference(b, cls, thr)
                np.testing.assert_array_equal(_greedy_kernel(b, cls, thr), want)
                assert 0 < want.sum() < 200 or thr == 1.0

    def test_same_on_one_and_two_threads(self):
        b, s = nms_case(6, 300, 0.5)
        tb, ts = torch.from_numpy(b), torch.from_numpy(s)
        before = torch.get_num_threads()
        try:
            torch.set_num_threads(1)
            one = nms(tb, ts, 0.5)
            torch.set_num_threads(2)
            two = nms(tb, ts, 0.5)
        finally:
            torch.set_num_threads(before)
        assert torch.equal(one, two)


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


# ------------------------------------------------------------------ bad input
T4 = torch.tensor([[0.0, 0.0, 1.0, 1.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: box_iou(np.zeros((1, 4)), T4), r"boxes1 must be a torch.Tensor"),
        (lambda: box_iou(torch.zeros(4), T4), r"boxes1 must have shape \(N, 4\).*\[None\]"),
        (lambda: box_iou(torch.zeros(1, 4, dtype=torch.long), T4), "use boxes1.float"),
        (lambda: box_iou(torch.tensor([[0.0, math.nan, 1, 1]]), T4), "boxes1 must be finite"),
        (lambda: box_iou(torch.tensor([[0.0, 0, -1, 1]]), T4), "x1 <= x2 and y1 <= y2"),
        (lambda: box_area(torch.tensor([[0.0, 0, 1e30, 1e30]])), "overflow"),
        (lambda: box_convert(T4, "xyxy", "yxyx"), "out_fmt must be one of"),
        (lambda: nms(T4, torch.tensor([math.nan]), 0.5), "scores must not hold NaN"),
        (lambda: nms(T4, torch.tensor([0.5, 0.2]), 0.5), r"scores must have shape \(1,\)"),
        (lambda: nms(T4, torch.tensor([0.5]), -0.1), r"iou_threshold must be in \[0, 1\]"),
        (lambda: nms(T4, torch.tensor([0.5]), math.nan), "iou_threshold must be finite"),
        (lambda: batched_nms(T4, torch.ones(1), torch.ones(1), 0.5), "idxs must hold integer"),
        (
            lambda: non_max_suppression(T4, torch.ones(1), top_k=-1),
            "top_k must be >= 0",
        ),
        (lambda: BoxCoder((1.0, 1.0, 0.0, 1.0)), r"weights must be in \(0"),
        (lambda: BoxCoder().decode(torch.zeros(1, 3), T4), r"deltas must be a \(N, 4 k\)"),
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


def _dihedral_image(image, hflip, vflip, k):
    dims = [d for d, on in ((-1, hflip), (-2, vflip)) if on]
    image = torch.flip(image, dims) if dims else image
    return torch.rot90(image, k, (-2, -1))


@pytest.mark.parametrize("hflip", [False, True])
@pytest.mark.parametrize("vflip", [False, True])
@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_dihedral_boxes_follow_the_pixels_and_invert(hflip, vflip, k):
    # a filled rectangle: its box after the image transform is read off the pixels
    h, w = 10, 17
    image = torch.zeros(1, h, w)
    image[0, 2:5, 3:9] = 1.0
    box = torch.tensor([[3.0, 2.0, 9.0, 5.0]])
    moved = _dihedral_image(image, hflip, vflip, k)[0]
    ys, xs = torch.nonzero(moved, as_tuple=True)
    seen = [[xs.min().item(), ys.min().item(), xs.max().item() + 1, ys.max().item() + 1]]
    t = {"hflip": hflip, "vflip": vflip, "quarter_turns": k}
    assert dihedral_boxes(box, (h, w), **t).tolist() == np.array(seen, float).tolist()
    rand = torch.rand(20, 2, generator=torch.Generator().manual_seed(k)) * torch.tensor([w, h])
    boxes = torch.cat([rand, rand + 2.5], 1)
    back = dihedral_boxes(dihedral_boxes(boxes, (h, w), **t), (h, w), **t, inverse=True)
    torch.testing.assert_close(back, boxes, rtol=0, atol=1e-5)  # float32 rounding of W - x


def test_dihedral_boxes_quarter_turns_modulo_four_and_bad_input():
    b = torch.tensor([[1.0, 2.0, 3.0, 4.0]])
    assert torch.equal(
        dihedral_boxes(b, (8, 6), quarter_turns=5), dihedral_boxes(b, (8, 6), quarter_turns=1)
    )
    assert dihedral_boxes(torch.zeros(0, 4), (8, 6), hflip=True).shape == (0, 4)
    with pytest.raises(InputError, match="size must be the image's"):
        dihedral_boxes(b, 8)
    with pytest.raises(InputError, match="x1 <= x2"):
        dihedral_boxes(torch.tensor([[3.0, 0, 1, 1]]), (8, 6))
