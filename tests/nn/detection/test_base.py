"""Tests of the detector contract (robopercept.nn.detection.base) on every detector:
shapes and losses in train and eval mode, gradients, empty images and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.core.backbones import DetectionBackbone  # noqa: E402
from robopercept.nn.detection.fast_rcnn import FastRCNN  # noqa: E402
from robopercept.nn.detection.faster_rcnn import FasterRCNN  # noqa: E402
from robopercept.nn.detection.fcos import FCOS  # noqa: E402
from robopercept.nn.detection.synthetic import single_digit_set  # noqa: E402
from robopercept.nn.detection.train import evaluate_detector, train_detector  # noqa: E402
from tests.nn.detection.detectors import KINDS, LOSSES, build, tiny_batch  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.mark.parametrize("kind", KINDS)
def test_train_losses_finite_positive_and_gradients_flow(kind):
    m = build(kind).train()
    images, targets = tiny_batch(one_box=kind == "loc")
    losses = m(images, targets)
    assert set(losses) == LOSSES[kind]
    for name, v in losses.items():
        assert v.ndim == 0 and bool(torch.isfinite(v)), name
        assert float(v.detach()) > 0, name
    sum(losses.values()).backward()
    for name, p in m.named_parameters():
        assert p.grad is not None and bool(p.grad.abs().sum() > 0), name


@pytest.mark.parametrize("kind", KINDS)
def test_eval_output_shapes_on_images_of_different_sizes(kind):
    m = build(kind, score_thresh=0.0) if kind != "loc" else build(kind)
    images, _ = tiny_batch()
    out = m.predict(images)
    assert len(out) == 2 and m.training  # predict restores the mode
    for o, im in zip(out, images, strict=True):
        assert set(o) == {"boxes", "labels", "scores"}
        d = o["boxes"].shape[0]
        assert (
            o["boxes"].shape == (d, 4) and o["labels"].shape == (d,) and o["scores"].shape == (d,)
        )
        assert o["labels"].dtype == torch.int64 and d >= 1
        h, w = im.shape[1:]
        b = o["boxes"]
        assert bool((b[:, 0] >= 0).all() and (b[:, 2] <= w).all() and (b[:, 3] <= h).all())
        assert bool((o["labels"] >= 1).all() and (o["labels"] <= 10).all())
        assert bool((o["scores"][:-1] >= o["scores"][1:]).all())  # sorted by score
    if kind == "loc":
        assert all(o["boxes"].shape[0] == 1 for o in out)


@pytest.mark.parametrize("kind", KINDS)
def test_batch_tensor_equals_list_of_images(kind):
    m = build(kind, score_thresh=0.0) if kind != "loc" else build(kind)
    images = torch.rand(2, 3, 32, 40, generator=torch.Generator().manual_seed(2))
    a, b = m.predict(images), m.predict(list(images))
    for da, db in zip(a, b, strict=True):
        for k in ("boxes", "labels", "scores"):
            assert torch.equal(da[k], db[k])


@pytest.mark.parametrize("kind", ["fast", "faster", "fcos"])
def test_eval_empty_detections_have_right_shapes(kind):
    # nothing passes the score threshold (strictly above 1) or, for Fast R-CNN, no
    # proposals: empty tensors of the usual shapes and dtypes
    m = build(kind, score_thresh=1.0).eval()
    image = torch.zeros(3, 40, 40)
    out = m([image], proposals=[torch.zeros(0, 4)]) if kind == "fast" else m([image])
    o = out[0]
    assert o["boxes"].shape == (0, 4) and o["labels"].shape == (0,) and o["scores"].shape == (0,)
    assert o["labels"].dtype == torch.int64 and o["scores"].is_floating_point()


@pytest.mark.parametrize("kind", ["fast", "faster", "fcos"])
def test_image_without_objects_trains(kind):
    m = build(kind).train()
    losses = m(
        [torch.rand(3, 32, 32)],
        [{"boxes": torch.zeros(0, 4), "labels": torch.zeros(0, dtype=torch.int64)}],
    )
    assert all(bool(torch.isfinite(v)) for v in losses.values())
    box_loss = {"fast": "loss_box", "faster": "loss_rpn_box", "fcos": "bbox_regression"}[kind]
    assert float(losses[box_loss].detach()) == 0.0  # no positives: no box loss
    if kind == "faster":
        assert float(losses["loss_box"].detach()) == 0.0
    assert float(sum(losses.values()).detach()) > 0  # the classification terms still teach


def _t(boxes, labels, bdtype=torch.float32, ldtype=torch.int64):
    return [
        {"boxes": torch.tensor(boxes, dtype=bdtype), "labels": torch.tensor(labels, dtype=ldtype)}
    ]


@pytest.mark.parametrize(
    ("targets", "msg"),
    [
        (_t([[1.0, 2, math.nan, 9]], [1]), "NaN or inf"),
        (_t([[5.0, 2, 5, 9]], [1]), "degenerate box"),
        (_t([[1, 2, 8, 9]], [1], bdtype=torch.int64), "float torch.Tensor"),
        (_t([[1.0, 2, 8, 9]], [1], ldtype=torch.int32), "int64"),
        (_t([[1.0, 2, 8, 9]], [0]), "0 is the background"),
        (_t([[1.0, 2, 8, 9]], [11]), "in 1..10"),
        (None, "targets are required in train mode"),
        ([{"boxes": torch.zeros(0, 4)}], "'boxes' and 'labels'"),
        ([], "list of 1 dicts"),
    ],
)
@pytest.mark.parametrize("kind", ["faster", "fcos"])
def test_bad_targets(kind, targets, msg):
    m = build(kind).train()
    with pytest.raises(InputError, match=msg):
        m([torch.rand(3, 16, 16)], targets)


@pytest.mark.parametrize(
    ("images", "msg"),
    [
        ([torch.rand(16, 16, 3)], "channels-last"),
        ([torch.rand(1, 16, 16)], "must be \\(3, H, W\\)"),
        ([torch.zeros(3, 8, 8, dtype=torch.uint8)], "floating point"),
        ([np.zeros((3, 8, 8))], "torch.from_numpy"),
        ([torch.full((3, 8, 8), math.nan)], "NaN"),
        ([], "non-empty list"),
    ],
)
def test_bad_images(images, msg):
    m = build("fcos").eval()
    with pytest.raises(InputError, match=msg):
        m(images)


@pytest.mark.parametrize(
    ("call", "msg"),
    [
        # the fuzz campaign of issue 25 (run 3): an untyped error each before
        (lambda: DetectionBackbone(4, strides=(8,), fpn_channels=21313), "fpn_channels"),
        (lambda: FCOS(2, width=4, head_channels=5000), "head_channels"),
        (lambda: FasterRCNN(2, width=4, aspect_ratios=None), "aspect_ratios must be a non-empty"),
        (lambda: FasterRCNN(2, width=4, anchor_sizes=3.0), "anchor_sizes must be a non-empty"),
    ],
)
def test_issue25_run3_constructor_arguments(call, msg):
    with pytest.raises(InputError, match=msg):
        call()


def test_model_specific_errors():
    images, targets = tiny_batch()
    with pytest.raises(InputError, match="exactly one box"):
        build("loc").train()(images, targets)
    m = FastRCNN(3, width=8, hidden=16).eval()
    with pytest.raises(InputError, match="needs proposals"):
        m([torch.rand(3, 16, 16)])
    with pytest.raises(InputError, match=r"proposals\[0\]"):
        m([torch.rand(3, 16, 16)], proposals=[torch.zeros(3, 5)])
    with pytest.raises(InputError, match="num_classes"):
        FCOS(0)
    with pytest.raises(InputError, match="DetectionDataset"):
        train_detector(build("fcos"), [1, 2], progress=False)
    with pytest.raises(InputError, match="TrainConfig"):
        train_detector(build("fcos"), single_digit_set(1, rng=0), {"epochs": 1}, progress=False)
    with pytest.raises(InputError, match="DetectionDataset"):
        evaluate_detector(build("fcos"), "shapes")
