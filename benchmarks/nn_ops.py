"""``python -m benchmarks nn_ops``: detection box operations, ours (torch,
:mod:`robopercept.nn.ops`) against onnxruntime's ``NonMaxSuppression`` and ``RoiAlign``
operators on the same input (issue 50): NMS of 1,000, 2,000 and 10,000 boxes, batched
(per-class) NMS of 2,000 and 10,000 boxes in 10 classes (onnxruntime's class axis), RoI
Align, and RoI max pooling against ``MaxRoiPool``; and one training epoch of our loops
against a plain torch loop (:func:`training_records`). Paired in one process
(``paired_ms``: the two alternate, median of the runs).

Both single-threaded. Batched NMS: onnxruntime takes a score per box and class, so
each box scores in its own class and 0 in the others, with ``score_threshold`` 0
(strict: the zeros never enter); the boxes' scores are all above 0.

The RoI Align difference (about 1.5e-5 on these 50 x 50 maps) is onnxruntime's float32
arithmetic of the sample coordinates (ours are float64): at
coordinates near 50 a float32 ulp is 4e-6 pixel, times feature gradients of order 3."""

from __future__ import annotations

import os

import numpy as np

from benchmarks._harness import Record, paired_ms


def _session(node, inputs, outputs, opset: int):  # type: ignore[no-untyped-def]
    import onnxruntime as ort
    from onnx import helper

    graph = helper.make_graph([node], "g", inputs, outputs)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)])
    model.ir_version = 8
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    return ort.InferenceSession(model.SerializeToString(), opts, providers=["CPUExecutionProvider"])


def _nms_case(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``n`` boxes in a 1000 x 1000 image, 10-100 px, clustered around 200 objects (as
    a detector's raw output), distinct scores."""
    centres = rng.uniform(50, 950, (200, 2))
    c = centres[rng.integers(0, 200, n)] + rng.normal(0, 8, (n, 2))
    wh = rng.uniform(10, 100, (n, 2))
    boxes = np.concatenate([c - wh / 2, c + wh / 2], 1).astype(np.float32)
    scores = (rng.permutation(n) / n).astype(np.float32)
    return boxes, scores


def run(repeats: int) -> tuple[list[Record], dict]:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import numba
    import torch
    from onnx import TensorProto, helper

    from robopercept.nn.ops.nms import batched_nms, nms
    from robopercept.nn.ops.roi import roi_align, roi_pool

    torch.set_num_threads(1)
    numba.set_num_threads(1)  # the compiled kernels single-threaded too
    rng = np.random.default_rng(0)
    records = []
    vi = helper.make_tensor_value_info
    nms_sess = _session(
        helper.make_node(
            "NonMaxSuppression", ["b", "s", "m", "i", "t"], ["sel"], center_point_box=0
        ),
        [
            vi("b", TensorProto.FLOAT, [1, None, 4]),
            vi("s", TensorProto.FLOAT, [1, None, None]),
            vi("m", TensorProto.INT64, [1]),
            vi("i", TensorProto.FLOAT, [1]),
            vi("t", TensorProto.FLOAT, [1]),
        ],
        [vi("sel", TensorProto.INT64, [None, 3])],
        11,
    )
    for n, classes in ((1000, 1), (2000, 1), (10000, 1), (2000, 10), (10000, 10)):
        boxes, scores = _nms_case(n, rng)
        scores = scores + np.float32(1.0 / n)  # all > 0: the batched case's threshold
        tb, ts = torch.from_numpy(boxes), torch.from_numpy(scores)
        cls = rng.integers(0, classes, n)
        per_class = np.zeros((1, classes, n), np.float32)
        per_class[0, cls, np.arange(n)] = scores
        feeds = {
            "b": boxes[None],
            "s": per_class,
            "m": np.array([n], np.int64),
            "i": np.array([0.5], np.float32),
            "t": np.array([0.0 if classes > 1 else -1.0], np.float32),
        }
        tc = torch.from_numpy(cls)

        def ours(tb=tb, ts=ts, tc=tc, classes=classes):  # type: ignore[no-untyped-def]
            return batched_nms(tb, ts, tc, 0.5) if classes > 1 else nms(tb, ts, 0.5)

        def ref(feeds=feeds):  # type: ignore[no-untyped-def]
            return nms_sess.run(None, feeds)[0]

        # onnxruntime lists the kept boxes class by class: compare as sets
        o, r = sorted(ours().tolist()), sorted(ref()[:, 2].tolist())
        reps = repeats if n <= 2000 else max(11, repeats // 3)  # the issue: at least 11
        ours_ms, ref_ms = paired_ms(ours, ref, repeats=reps, warmup=1)
        name = "batched_nms" if classes > 1 else "nms"
        what = f"{n} boxes in {classes} classes" if classes > 1 else f"{n} boxes"
        records.append(
            Record(name, f"{what}, IoU 0.5, {len(o)} kept", ours_ms, ref_ms,
                   "onnxruntime NonMaxSuppression", "same kept boxes (1 = yes)",
                   float(o == r), 1.0)
        )  # fmt: skip
    # RoI Align: 512 regions on a stride-16 feature map of a 800 x 800 image
    C, H, W, K = 64, 50, 50, 512
    x = rng.normal(size=(1, C, H, W)).astype(np.float32)
    xy = rng.uniform(0, 700, (K, 2))
    rois = np.concatenate([xy, xy + rng.uniform(16, 200, (K, 2))], 1).astype(np.float32)
    bidx = np.zeros(K, np.int64)
    for aligned in (True, False):
        sess = _session(
            helper.make_node(
                "RoiAlign", ["X", "r", "bi"], ["Y"], mode="avg", output_height=7,
                output_width=7, sampling_ratio=2, spatial_scale=1 / 16,
                coordinate_transformation_mode="half_pixel" if aligned else "output_half_pixel",
            ),
            [vi("X", TensorProto.FLOAT, list(x.shape)), vi("r", TensorProto.FLOAT, [None, 4]),
             vi("bi", TensorProto.INT64, [None])],
            [vi("Y", TensorProto.FLOAT, None)],
            16,
        )  # fmt: skip
        tx = torch.from_numpy(x)
        trois = torch.cat([torch.zeros(K, 1), torch.from_numpy(rois)], 1)

        def ours_ra(tx=tx, trois=trois, aligned=aligned):  # type: ignore[no-untyped-def]
            with torch.no_grad():
                return roi_align(tx, trois, 7, 1 / 16, 2, aligned)

        def ref_ra(sess=sess):  # type: ignore[no-untyped-def]
            return sess.run(None, {"X": x, "r": rois, "bi": bidx})[0]

        err = float(np.abs(ours_ra().numpy() - ref_ra()).max())
        ours_ms, ref_ms = paired_ms(ours_ra, ref_ra, repeats=repeats, warmup=1)
        records.append(
            Record("roi_align", f"{K} RoIs, 64x50x50, 7x7, ratio 2, aligned={aligned}",
                   ours_ms, ref_ms, "onnxruntime RoiAlign", "max |difference|", err, 1.0)
        )  # fmt: skip
    # RoI max pooling on the same map and regions, against onnxruntime's MaxRoiPool
    r5 = np.concatenate([bidx[:, None].astype(np.float32), rois], 1)
    pool_sess = _session(
        helper.make_node("MaxRoiPool", ["X", "r"], ["Y"], pooled_shape=[7, 7],
                         spatial_scale=1 / 16),
        [vi("X", TensorProto.FLOAT, list(x.shape)), vi("r", TensorProto.FLOAT, [None, 5])],
        [vi("Y", TensorProto.FLOAT, None)],
        16,
    )  # fmt: skip
    tx, tr5 = torch.from_numpy(x), torch.from_numpy(r5)

    def ours_rp():  # type: ignore[no-untyped-def]
        with torch.no_grad():
            return roi_pool(tx, tr5, 7, 1 / 16)

    def ref_rp():  # type: ignore[no-untyped-def]
        return pool_sess.run(None, {"X": x, "r": r5})[0]

    same = float(np.array_equal(ours_rp().numpy(), ref_rp()))
    ours_ms, ref_ms = paired_ms(ours_rp, ref_rp, repeats=repeats, warmup=1)
    records.append(
        Record("roi_pool", f"{K} RoIs, 64x50x50, 7x7", ours_ms, ref_ms,
               "onnxruntime MaxRoiPool", "identical (1 = yes)", same, 1.0)
    )  # fmt: skip
    records += training_records(max(11, repeats // 3))
    settings = {"threads": "torch 1, numba 1, onnxruntime intra-op 1", "float": "float32"}
    return records, settings


def training_records(repeats: int) -> list[Record]:
    """One training epoch by our loops (:func:`~robopercept.nn.train.fit.fit`,
        :func:`~robopercept.nn.detection.train.train_detector`) against a minimal loop of
        plain torch on the same model, data, batches and optimizer (zero_grad, forward,
        loss, backward, step; no checks, no figures, no progress), paired, each epoch from
        the same initial weights. The digits CNN: ``resnet_small`` on the 1,797 scikit-learn
        digits, batch 64, AdamW. FCOS (width 16) on 64 procedural 128 x 128 shapes
        canvases, batch 8, AdamW with the cosine schedule stepped per batch and clipping at
    10, as ``detection_figures``. The accuracy
        column is the largest difference of a weight after the epoch (the loops draw the
        same batches and take the same steps)."""
    import copy

    import torch
    from torch.nn import functional

    from robopercept.nn.classification.models import resnet_small
    from robopercept.nn.classification.run import load_data
    from robopercept.nn.detection.data import collate_detection
    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.nn.detection.train import train_detector
    from robopercept.nn.detection.zoo import build_detector
    from robopercept.nn.train.config import TrainConfig
    from robopercept.nn.train.fit import fit

    def weights_gap(a: torch.nn.Module, b: torch.nn.Module) -> float:
        pairs = zip(a.parameters(), b.parameters(), strict=True)
        return max(float((p - q).detach().abs().max()) for p, q in pairs)

    records = []
    # the digits CNN
    data = load_data("digits")
    cfg = TrainConfig(epochs=1, batch_size=64, lr=3e-3, seed=0, device="cpu", patience=None)
    torch.manual_seed(0)
    model = resnet_small()
    start = copy.deepcopy(model.state_dict())
    ours_model, ref_model = copy.deepcopy(model), copy.deepcopy(model)

    def ours_digits() -> None:
        ours_model.load_state_dict(start)
        fit(ours_model, data, None, cfg, progress=False)

    def ref_digits() -> None:
        ref_model.load_state_dict(start)
        torch.manual_seed(0)
        loader = torch.utils.data.DataLoader(
            data, batch_size=64, shuffle=True, generator=torch.Generator().manual_seed(0)
        )
        opt = torch.optim.AdamW(ref_model.parameters(), lr=3e-3, weight_decay=1e-4)
        ref_model.train()
        for x, y in loader:
            opt.zero_grad()
            functional.cross_entropy(ref_model(x.float()), y.long()).backward()
            opt.step()

    ours_ms, ref_ms = paired_ms(ours_digits, ref_digits, repeats=repeats, warmup=1)
    records.append(
        Record("train_epoch", "digits CNN (resnet_small), 1,797 images, batch 64", ours_ms,
               ref_ms, "a plain torch loop", "max |weight difference|",
               weights_gap(ours_model, ref_model), 1.05)
    )  # fmt: skip
    # FCOS on the shapes
    shapes = procedural_detection_set(64, (128, 128), rng=0)
    dcfg = TrainConfig(epochs=1, batch_size=8, lr=2e-3, seed=0, device="cpu", clip_grad_norm=10.0)
    det = build_detector("fcos", len(shapes.classes), seed=0, width=16, score_thresh=0.05)
    start = copy.deepcopy(det.state_dict())
    ours_det, ref_det = copy.deepcopy(det), copy.deepcopy(det)

    def ours_fcos() -> None:
        ours_det.load_state_dict(start)
        train_detector(ours_det, shapes, dcfg, progress=False)

    def ref_fcos() -> None:
        ref_det.load_state_dict(start)
        torch.manual_seed(0)
        order = torch.randperm(len(shapes), generator=torch.Generator().manual_seed(0))
        params = [p for p in ref_det.parameters() if p.requires_grad]
        opt = torch.optim.AdamW(params, lr=2e-3, weight_decay=1e-4)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=len(range(0, 64, 8)))
        ref_det.train()
        for b in range(0, len(shapes), 8):
            images, targets = collate_detection([shapes[int(j)] for j in order[b : b + 8]])
            opt.zero_grad()
            sum(ref_det(list(images), list(targets)).values()).backward()
            torch.nn.utils.clip_grad_norm_(params, 10.0)
            opt.step()
            sched.step()  # the detectors' schedule steps per batch

    ours_ms, ref_ms = paired_ms(ours_fcos, ref_fcos, repeats=repeats, warmup=1)
    records.append(
        Record("train_epoch", "FCOS (width 16), 64 shapes canvases, batch 8", ours_ms, ref_ms,
               "a plain torch loop", "max |weight difference|",
               weights_gap(ours_det, ref_det), 1.05)
    )  # fmt: skip
    return records
