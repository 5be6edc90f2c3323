"""Greedy NMS (issue 26, item 1) vs onnxruntime and a brute-force oracle: ties,
the strict threshold, per-class suppression, score threshold and cap, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from robopercept.nn.ops.nms import batched_nms, nms, non_max_suppression  # noqa: E402
from tests.nn.ops.test_boxes import random_xyxy  # noqa: E402


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


# ------------------------------------------------------------------ bad input
T4 = torch.tensor([[0.0, 0.0, 1.0, 1.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: nms(T4, torch.tensor([math.nan]), 0.5), "scores must not hold NaN"),
        (lambda: nms(T4, torch.tensor([0.5, 0.2]), 0.5), r"scores must have shape \(1,\)"),
        (lambda: nms(T4, torch.tensor([0.5]), -0.1), r"iou_threshold must be in \[0, 1\]"),
        (lambda: nms(T4, torch.tensor([0.5]), math.nan), "iou_threshold must be finite"),
        (lambda: batched_nms(T4, torch.ones(1), torch.ones(1), 0.5), "idxs must hold integer"),
        (
            lambda: non_max_suppression(T4, torch.ones(1), top_k=-1),
            "top_k must be >= 0",
        ),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()
