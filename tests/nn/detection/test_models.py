"""Tests of robopercept.nn.detection.models: matching and sampling by hand, the focal loss by
its formula, shapes and losses of every detector in train and eval mode, gradients,
seeded determinism, overfitting tiny sets (losses and decoding agree) and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.data import digits_detection_set, single_digit_set  # noqa: E402
from robopercept.nn.detection.models import (  # noqa: E402
    FCOS,
    FPN,
    DetectionBackbone,
    FasterRCNN,
    FastRCNN,
    SingleObjectLocalizer,
    evaluate_detector,
    evaluate_localizer,
    match_boxes,
    sample_balanced,
    sigmoid_focal_loss,
    train_detector,
)
from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from robopercept.nn.train.loop import TrainConfig  # noqa: E402


def grid_proposals(image: torch.Tensor) -> torch.Tensor:
    """Sliding-window proposals (squares of 16, 24, 32 px every 8 px): a stand-in for
    selective search, so Fast R-CNN's tests do not depend on it."""
    h, w = image.shape[1:]
    rows = [
        [x, y, x + s, y + s]
        for s in (16, 24, 32)
        for y in range(0, h - s + 1, 8)
        for x in range(0, w - s + 1, 8)
    ]
    return torch.tensor(rows, dtype=torch.float32)


def build(kind: str, num_classes: int = 10, **kw):
    torch.manual_seed(0)
    if kind == "loc":
        return SingleObjectLocalizer(num_classes, width=8, **kw)
    if kind == "fast":
        kw = {"width": 8, "hidden": 64, "box_batch_size": 64, **kw}
        return FastRCNN(num_classes, grid_proposals, **kw)
    if kind == "faster":
        kw = {"width": 8, "hidden": 64, "box_batch_size": 64, "rpn_batch_size": 64, **kw}
        return FasterRCNN(num_classes, **kw)
    return FCOS(num_classes, width=8, head_channels=32, **kw)


pytestmark = pytest.mark.usefixtures("torch_one_thread")


LOSSES = {
    "loc": {"loss_classifier", "loss_box"},
    "fast": {"loss_classifier", "loss_box"},
    "faster": {"loss_rpn_objectness", "loss_rpn_box", "loss_classifier", "loss_box"},
    "fcos": {"classification", "bbox_regression", "bbox_ctrness"},
}
KINDS = tuple(LOSSES)


def tiny_batch(one_box: bool = False):
    g = torch.Generator().manual_seed(1)
    images = [torch.rand(3, 64, 64, generator=g), torch.rand(3, 48, 56, generator=g)]
    targets = [
        {"boxes": torch.tensor([[8.0, 10, 40, 50]]), "labels": torch.tensor([3])},
        {"boxes": torch.tensor([[20.0, 4, 50, 30]]), "labels": torch.tensor([7])},
    ]
    if not one_box:
        targets[0] = {
            "boxes": torch.tensor([[8.0, 10, 40, 50], [44, 40, 62, 62]]),
            "labels": torch.tensor([3, 1]),
        }
    return images, targets


# --------------------------------------------------------------------------- matching
class TestMatchBoxes:
    def test_anchor_equal_to_gt_is_positive(self):
        gt = torch.tensor([[10.0, 10, 30, 30]])
        anchors = torch.tensor([[10.0, 10, 30, 30], [0, 0, 8, 8], [12, 10, 32, 30]])
        labels, matched = match_boxes(box_iou(gt, anchors), 0.7, 0.3)
        # IoU 1, 0 and 18*20 / (20*20 + 2*20) = 0.818
        assert labels.tolist() == [1, 0, 1]
        assert matched.tolist() == [0, 0, 0]

    def test_best_anchor_per_gt_is_positive_below_threshold(self):
        gt = torch.tensor([[0.0, 0, 10, 10], [50, 50, 60, 60]])
        anchors = torch.tensor(
            [[0.0, 0, 20, 10], [0, 0, 40, 40], [50, 50, 70, 70], [80, 80, 90, 90]]
        )
        iou = box_iou(gt, anchors)  # [[0.5, 1/16, 0, 0], [0, 0, 0.25, 0]]
        labels, matched = match_boxes(iou, 0.7, 0.3, allow_low_quality=True)
        assert labels.tolist() == [1, 0, 1, 0]
        assert matched[2] == 1
        labels, _ = match_boxes(iou, 0.7, 0.3)
        assert labels.tolist() == [-1, 0, 0, 0]  # 0.5 in the ignored band

    def test_low_quality_needs_some_overlap(self):
        # a ground-truth box that overlaps no anchor promotes nothing
        iou = torch.tensor([[0.0, 0.0], [0.8, 0.1]])
        assert match_boxes(iou, 0.7, 0.3, allow_low_quality=True)[0].tolist() == [1, 0]

    def test_low_quality_ties_all_positive(self):
        iou = torch.tensor([[0.4, 0.4, 0.1]])
        assert match_boxes(iou, 0.7, 0.3, allow_low_quality=True)[0].tolist() == [1, 1, 0]

    def test_background_band_of_fast_rcnn(self):
        iou = torch.tensor([[0.05, 0.1, 0.49, 0.5]])
        assert match_boxes(iou, 0.5, 0.5, 0.1)[0].tolist() == [-1, 0, 0, 1]

    def test_no_ground_truth(self):
        labels, matched = match_boxes(torch.zeros(0, 3), 0.7, 0.3)
        assert labels.tolist() == [0, 0, 0] and matched.tolist() == [0, 0, 0]
        assert match_boxes(torch.zeros(0, 2), 0.5, 0.5, 0.1)[0].tolist() == [-1, -1]

    @pytest.mark.parametrize(
        ("args", "msg"),
        [
            ((torch.zeros(3), 0.7, 0.3), "iou must be a \\(G, N\\)"),
            ((torch.tensor([[math.nan]]), 0.7, 0.3), "finite"),
            ((torch.zeros(1, 1), 0.3, 0.7), "bg_threshold"),
            ((torch.zeros(1, 1), 1.5, 0.3), "fg_threshold"),
        ],
    )
    def test_bad_input(self, args, msg):
        with pytest.raises(InputError, match=msg):
            match_boxes(*args)


class TestSampleBalanced:
    def test_counts_and_fractions(self):
        torch.manual_seed(0)
        labels = torch.tensor([1] * 10 + [0] * 1000 + [-1] * 50)
        pos, neg = sample_balanced(labels, 256, 0.5)
        assert int(pos.sum()) == 10 and int(neg.sum()) == 246  # few positives: negatives fill
        assert not bool((pos | neg)[-50:].any())  # ignored never drawn
        assert bool((labels[pos] == 1).all()) and bool((labels[neg] == 0).all())
        labels = torch.tensor([1] * 300 + [0] * 1000)
        pos, neg = sample_balanced(labels, 256, 0.5)
        assert int(pos.sum()) == 128 and int(neg.sum()) == 128
        pos, neg = sample_balanced(labels, 512, 0.25)  # Fast R-CNN's 25 % foreground
        assert int(pos.sum()) == 128 and int(neg.sum()) == 384

    def test_few_candidates(self):
        pos, neg = sample_balanced(torch.tensor([1, 0, -1]), 256, 0.5)
        assert pos.tolist() == [True, False, False] and neg.tolist() == [False, True, False]

    def test_seeded(self):
        labels = torch.tensor([1] * 50 + [0] * 50)
        torch.manual_seed(3)
        a = sample_balanced(labels, 20, 0.5)
        torch.manual_seed(3)
        b = sample_balanced(labels, 20, 0.5)
        assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])

    def test_bad_input(self):
        with pytest.raises(InputError, match=r"integer torch\.Tensor"):
            sample_balanced(torch.zeros(3), 4, 0.5)
        with pytest.raises(InputError, match="batch_size"):
            sample_balanced(torch.zeros(3, dtype=torch.int64), 0, 0.5)
        with pytest.raises(InputError, match="positive_fraction"):
            sample_balanced(torch.zeros(3, dtype=torch.int64), 4, 2.0)


class TestFocalLoss:
    def test_hand_value(self):
        # x = 0: p = 0.5, y = 1: 0.25 * 0.5^2 * log 2
        got = sigmoid_focal_loss(torch.tensor([0.0]), torch.tensor([1.0]))
        assert float(got) == pytest.approx(0.25 * 0.25 * math.log(2), rel=1e-6)
        # y = 0, x = 2: p = sigma(2), (1 - alpha) p^2 (-log(1 - p))
        p = 1 / (1 + math.exp(-2))
        got = sigmoid_focal_loss(torch.tensor([2.0]), torch.tensor([0.0]))
        assert float(got) == pytest.approx(0.75 * p**2 * -math.log(1 - p), rel=1e-6)

    def test_gamma_zero_no_alpha_is_bce(self):
        x, y = torch.randn(20), (torch.rand(20) > 0.5).float()
        bce = torch.nn.functional.binary_cross_entropy_with_logits(x, y, reduction="sum")
        got = sigmoid_focal_loss(x, y, alpha=-1, gamma=0, reduction="sum")
        assert float(got) == pytest.approx(float(bce), rel=1e-6)
        assert float(sigmoid_focal_loss(x, y, reduction="mean")) == pytest.approx(
            float(sigmoid_focal_loss(x, y).mean()), rel=1e-6
        )

    def test_bad_input(self):
        with pytest.raises(InputError, match="logits"):
            sigmoid_focal_loss(torch.zeros(2, dtype=torch.int64), torch.zeros(2))
        with pytest.raises(InputError, match="shape of inputs"):
            sigmoid_focal_loss(torch.zeros(2), torch.zeros(3))
        with pytest.raises(InputError, match="reduction"):
            sigmoid_focal_loss(torch.zeros(2), torch.zeros(2), reduction="max")


# --------------------------------------------------------------------------- backbone
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


# --------------------------------------------------------------------------- contract
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


def test_resolve_device_and_deterministic_algorithms():
    from robopercept.nn.train.loop import deterministic_algorithms, resolve_device

    assert resolve_device("cpu") == torch.device("cpu")
    with pytest.raises(InputError, match="device"):
        resolve_device("gpu7")
    before = torch.are_deterministic_algorithms_enabled()
    with deterministic_algorithms():
        assert torch.are_deterministic_algorithms_enabled()
    assert torch.are_deterministic_algorithms_enabled() == before


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


def test_fcos_untrained_on_blank_image_is_empty():
    # the classification prior (0.01) keeps every score below the 0.2 threshold
    o = build("fcos").eval()([torch.zeros(3, 32, 32)])[0]
    assert o["boxes"].shape == (0, 4)


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


def test_faster_rcnn_rpn_sampling_and_proposal_counts():
    m = build("faster", post_nms_top_n=(40, 7)).train()
    images, targets = tiny_batch()
    torch.manual_seed(0)
    batch, sizes, _ = m._prepare(images, targets)
    feats = m.backbone(batch)[-1]
    obj, reg, anchors = m.rpn(feats, tuple(batch.shape[2:]))
    assert obj.shape == (2, 8 * 8 * 9) and reg.shape == (2, 8 * 8 * 9, 4)
    assert anchors.shape == (8 * 8 * 9, 4)
    props, _ = m.proposals(obj, reg, anchors, sizes)
    assert [p.shape[0] <= 40 for p in props] == [True, True]
    for p, (h, w) in zip(props, sizes, strict=True):
        assert bool((p[:, 2] <= w).all() and (p[:, 3] <= h).all() and (p[:, 0] >= 0).all())
    m.eval()
    props, _ = m.proposals(obj, reg, anchors, sizes)
    assert all(p.shape[0] <= 7 for p in props)


def test_rpn_outputs_agree_with_the_rpn_and_keep_the_mode():
    m = build("faster", post_nms_top_n=(40, 7)).train()
    images, _ = tiny_batch()
    out = m.rpn_outputs(images)
    assert m.training  # restored
    m.eval()
    batch, sizes, _ = m._prepare(images, None)
    obj, reg, anchors = m.rpn(m.backbone(batch)[-1], tuple(batch.shape[2:]))
    props, scores = m.proposals(obj, reg, anchors, sizes)
    for i, o in enumerate(out):
        assert o["objectness"].shape == (8, 8, 9) and o["anchors"].shape == (8, 8, 9, 4)
        # cell (r, c), anchor a is flat index (r * 8 + c) * 9 + a, as AnchorGenerator
        assert torch.equal(o["objectness"][2, 5, 4], torch.sigmoid(obj[i, (2 * 8 + 5) * 9 + 4]))
        assert torch.equal(o["anchors"][2, 5, 4], anchors[(2 * 8 + 5) * 9 + 4])
        assert torch.equal(o["proposals"], props[i]) and len(o["proposals"]) <= 7
        assert torch.equal(o["proposal_scores"], scores[i])


def test_roi_sampling_fractions_and_bands():
    m = build("fast", box_batch_size=32).train()
    torch.manual_seed(0)
    gt = {"boxes": torch.tensor([[8.0, 8, 40, 40]]), "labels": torch.tensor([4])}
    props = [grid_proposals(torch.zeros(3, 64, 64))]
    rois, labels, deltas = m.select_training_samples(props, [gt])
    iou = box_iou(gt["boxes"], rois[0])[0]
    fg = labels[0] > 0
    assert rois[0].shape[0] == 32 and int(fg.sum()) == 8  # 25 % of 32
    assert bool((labels[0][fg] == 4).all()) and bool((iou[fg] >= 0.5).all())
    assert bool(((iou[~fg] >= 0.1) & (iou[~fg] < 0.5)).all())  # Fast R-CNN's background band
    assert bool((deltas[0][~fg] == 0).all())


def test_fcos_assignment_hand_case():
    m = build("fcos", num_classes=2)
    locs = torch.tensor([[20.0, 20.0], [4.0, 4.0], [30.0, 30.0]])
    strides = torch.full((3,), 8.0)
    gt = torch.tensor([[0.0, 0, 40, 40], [14, 14, 26, 26]])
    idx = m.assign(locs, strides, [3], gt)
    # (20, 20) lies in both centre regions: the smaller box wins; (4, 4) is outside the
    # big box's centre region (radius 12 around (20, 20)); (30, 30) is in it
    assert idx.tolist() == [1, -1, 0]


def test_fcos_exp_box_activation_starts_at_one_stride_and_cannot_die():
    # the paper's exp(s_l x): with the head's zero bias and N(0, 0.01^2) weights every
    # (l, t, r, b) starts near one stride (exactly one with zero weights), and a box
    # branch pushed far negative still passes gradient, where the ReLU passes none (the
    # FlipRotate failure of the shapes set, benchmarks/detection_figures.py)
    images, targets = tiny_batch()
    grads = {}
    for act in ("relu", "exp"):
        m = build("fcos", box_activation=act).train()
        torch.nn.init.zeros_(m.bbox_reg.weight)
        if act == "exp":
            feats = m.backbone(m._prepare(images, targets)[0])
            _, reg, _, _, strides, _ = m.head(feats)
            assert torch.allclose(
                reg * strides[None, :, None], strides[None, :, None].expand_as(reg)
            )
            assert m.scales.shape == (len(m.backbone.strides),)
        torch.nn.init.constant_(m.bbox_reg.bias, -5.0)
        m(images, targets)["bbox_regression"].backward()
        grads[act] = float(m.bbox_reg.bias.grad.abs().sum())
    assert grads["relu"] == 0.0 and grads["exp"] > 0.0
    with pytest.raises(InputError, match="box_activation"):
        build("fcos", box_activation="softplus")


@pytest.mark.parametrize("weighted", [False, True])
def test_fcos_regression_loss_hand_case(weighted):
    # box (0, 0, 30, 20) on a 32 x 32 image: the stride-8 locations in its centre region
    # (radius 12 around (15, 10)) and inside it are x in {4, 12, 20}, y in {4, 12}; with
    # zero box weights and exp every prediction is the 16 x 16 box around its location.
    # Uniform: the mean of 1 - GIoU; centerness_weighted (FCOS v2): weighted by each
    # location's centerness target
    from robopercept.nn.ops.boxes import generalized_box_iou

    m = build("fcos", num_classes=2, box_activation="exp", centerness_weighted=weighted)
    torch.nn.init.zeros_(m.bbox_reg.weight)
    torch.nn.init.zeros_(m.bbox_reg.bias)
    gt = torch.tensor([[0.0, 0, 30, 20]])
    loss = m([torch.rand(3, 32, 32)], [{"boxes": gt, "labels": torch.tensor([1])}])
    locs = torch.tensor([[x, y] for y in (4.0, 12.0) for x in (4.0, 12.0, 20.0)])
    pred = torch.cat((locs - 8, locs + 8), dim=1)
    g = torch.diagonal(generalized_box_iou(pred, gt.expand(6, 4)))
    lr = torch.stack((locs[:, 0], 30 - locs[:, 0]), 1)
    tb = torch.stack((locs[:, 1], 20 - locs[:, 1]), 1)
    c = torch.sqrt(lr.min(1).values / lr.max(1).values * tb.min(1).values / tb.max(1).values)
    want = ((1 - g) * c).sum() / c.sum() if weighted else (1 - g).mean()
    assert float(loss["bbox_regression"].detach()) == pytest.approx(float(want), rel=1e-5)


@pytest.mark.parametrize("quality", ["centerness", "iou"])
def test_fcos_quality_target_hand_case(quality):
    # the same setting as above; the third branch outputs the logit 1 everywhere, so
    # its loss is the mean over the 6 locations of BCE(sigmoid(1), target), with the
    # centerness target, or the IoU of each location's 16 x 16 box with the truth
    m = build("fcos", num_classes=2, box_activation="exp", quality=quality)
    for layer in (m.bbox_reg, m.bbox_ctrness):
        torch.nn.init.zeros_(layer.weight)
        torch.nn.init.zeros_(layer.bias)
    torch.nn.init.constant_(m.bbox_ctrness.bias, 1.0)
    gt = torch.tensor([[0.0, 0, 30, 20]])
    loss = m([torch.rand(3, 32, 32)], [{"boxes": gt, "labels": torch.tensor([1])}])
    locs = torch.tensor([[x, y] for y in (4.0, 12.0) for x in (4.0, 12.0, 20.0)])
    pred = torch.cat((locs - 8, locs + 8), dim=1)
    if quality == "iou":
        target = torch.diagonal(box_iou(pred, gt.expand(6, 4)))
    else:
        lr = torch.stack((locs[:, 0], 30 - locs[:, 0]), 1)
        tb = torch.stack((locs[:, 1], 20 - locs[:, 1]), 1)
        target = torch.sqrt(
            lr.min(1).values / lr.max(1).values * tb.min(1).values / tb.max(1).values
        )
    # BCE with logit 1: -(t log sigmoid(1) + (1 - t) log(1 - sigmoid(1)))
    p1 = torch.sigmoid(torch.tensor(1.0))
    want = -(target * torch.log(p1) + (1 - target) * torch.log(1 - p1)).mean()
    assert float(loss["bbox_ctrness"].detach()) == pytest.approx(float(want), rel=1e-5)
    with pytest.raises(InputError, match="quality"):
        build("fcos", quality="giou")


# --------------------------------------------------------------------------- training
def test_seeded_determinism():
    ds = digits_detection_set(2, (48, 48), (1, 2), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=2, batch_size=2, lr=1e-3, device="cpu", seed=5)
    runs = []
    for _ in range(2):
        m = build("faster")
        runs.append(train_detector(m, ds, cfg, progress=False).losses)
    assert runs[0] == runs[1]


def test_checkpoint_round_trip(tmp_path):
    from robopercept.nn.train.loop import load_checkpoint

    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    m = build("fcos")
    cfg = TrainConfig(epochs=2, batch_size=1, device="cpu")
    hist = train_detector(m, ds, cfg, checkpoint=tmp_path / "det.pt", progress=False)
    other = build("fcos", num_classes=10)
    torch.nn.init.zeros_(other.cls_logits.weight)
    state = load_checkpoint(tmp_path / "det.pt", other)
    assert state["epoch"] == 2 and state["architecture"] == "FCOS"
    assert state["losses"] == hist.losses
    for a, b in zip(m.state_dict().values(), other.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def _overfit(kind: str, epochs: int, lr: float):
    if kind == "loc":
        ds = single_digit_set(2, (64, 64), rng=0, scale=(20, 40))
    else:
        ds = digits_detection_set(2, (64, 64), (1, 1), rng=0, scale=(16, 32))
    m = build(kind)
    cfg = TrainConfig(
        epochs=epochs, batch_size=2, lr=lr, device="cpu", schedule="constant", weight_decay=0.0
    )
    hist = train_detector(m, ds, cfg, progress=False)
    return m, ds, hist


@pytest.mark.parametrize(
    ("kind", "epochs", "lr"), [("fcos", 60, 3e-3), ("faster", 60, 1e-3), ("fast", 60, 1e-3)]
)
def test_overfits_two_images(kind, epochs, lr):
    # two 64 x 64 canvases of one real digit each: a correct detector (losses and
    # decoding that agree) fits them to AP50 = 1 in 60 steps (measured with model seeds
    # 0-2 and 1 or 2 threads: AP50 1.0, AP 0.75-1.0); a wrong sign or scale in the box
    # decoding leaves AP50 near 0
    m, ds, hist = _overfit(kind, epochs, lr)
    assert hist.losses[-1]["loss"] < 0.5 * hist.losses[0]["loss"]
    ev = evaluate_detector(m, ds)
    assert ev.stats[1] >= 0.9, ev.stats
    assert ev.stats[0] >= 0.6, ev.stats


def test_localizer_overfits_to_high_iou():
    m, ds, _ = _overfit("loc", 60, 3e-3)
    out = m.predict([ds[i][0] for i in range(len(ds))])
    for i, o in enumerate(out):
        gt = torch.from_numpy(ds.boxes[i]).float()
        assert float(box_iou(o["boxes"], gt)[0, 0]) >= 0.8
        assert int(o["labels"][0]) == int(ds.labels[i][0])
    assert evaluate_detector(m, ds).stats[1] == pytest.approx(1.0)


def test_localizer_metric_equals_hand_iou_and_label_check():
    m, ds, _ = _overfit("loc", 60, 3e-3)
    res = evaluate_localizer(m, ds)
    out = m.predict([ds[i][0] for i in range(len(ds))])
    for i, o in enumerate(out):
        gt = torch.from_numpy(ds.boxes[i]).double()
        assert res.iou[i] == pytest.approx(float(box_iou(o["boxes"].double(), gt)[0, 0]), abs=1e-6)
        assert res.correct[i] == (int(o["labels"][0]) == int(ds.labels[i][0]))
    assert res.mean_iou == pytest.approx(res.iou.mean()) and res.mean_iou >= 0.8
    assert res.accuracy == 1.0


def test_localizer_metric_refuses_several_boxes_per_image():
    ds = digits_detection_set(2, (64, 64), (2, 2), rng=0, scale=(12, 16))
    with pytest.raises(InputError, match="exactly one box per image; image 0 has 2"):
        evaluate_localizer(build("loc"), ds)


def test_validation_keeps_the_best_evaluated_epoch(monkeypatch):
    # scripted validation figures (epochs 2, 4, 6 score 0.4, 0.9, 0.2): the model must
    # end with epoch 4's weights, i.e. equal to a run of the same seed stopped at 4
    import robopercept.nn.detection.models as det

    ds = digits_detection_set(2, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=6, batch_size=2, lr=3e-3, device="cpu", schedule="constant")
    scripted = iter([0.4, 0.9, 0.2])

    class Fake:
        def __init__(self) -> None:
            self.stats = np.full(12, next(scripted))

    monkeypatch.setattr(
        det, "evaluate_detector", lambda model, dataset, iou_type, sigmas=None: Fake()
    )
    m = build("fcos")
    hist = train_detector(m, ds, cfg, progress=False, val=ds, val_every=2)
    assert hist.val == {2: 0.4, 4: 0.9, 6: 0.2} and hist.best_epoch == 4
    assert hist.val_seconds >= 0
    monkeypatch.undo()
    ref = build("fcos")
    train_detector(ref, ds, TrainConfig(**{**cfg.__dict__, "epochs": 4}), progress=False)
    for (k, a), b in zip(m.state_dict().items(), ref.state_dict().values(), strict=True):
        assert torch.equal(a, b), k


def test_validation_figure_is_the_coco_number_of_the_kept_weights():
    ds = digits_detection_set(2, (64, 64), (1, 1), rng=0, scale=(16, 32))
    cfg = TrainConfig(epochs=6, batch_size=2, lr=3e-3, device="cpu", schedule="constant")
    m = build("fcos")
    hist = train_detector(m, ds, cfg, progress=False, val=ds, val_every=4, val_metric="AP50")
    assert sorted(hist.val) == [4, 6]  # every 4th epoch and the last
    assert evaluate_detector(m, ds).stats[1] == pytest.approx(hist.val[hist.best_epoch])


def test_without_validation_the_last_epoch_is_kept():
    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    hist = train_detector(
        build("fcos"), ds, TrainConfig(epochs=2, batch_size=1, device="cpu"), progress=False
    )
    assert hist.best_epoch == 2 and hist.val == {}


def test_augment_sees_every_training_sample_and_changes_the_run():
    from robopercept.nn.detection.data import FlipRotate

    ds = digits_detection_set(3, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=2, batch_size=2, lr=1e-3, device="cpu")
    seen = []

    def spy(image, target):
        seen.append(int(target["image_id"]))
        return FlipRotate(1.0, 1.0, generator=0)(image, target)

    plain = train_detector(build("fcos"), ds, cfg, progress=False).losses
    flipped = train_detector(build("fcos"), ds, cfg, progress=False, augment=spy).losses
    assert sorted(seen) == sorted(ds.image_ids * 2)  # each image once per epoch
    assert flipped != plain


@pytest.mark.parametrize(
    ("kw", "msg"),
    [
        ({"val_metric": "mAP"}, "val_metric must be one of"),
        ({"val_every": 0}, "val_every"),
        ({"val": [1, 2]}, "dataset must be a DetectionDataset"),
        ({"augment": "flip"}, "augment must be a callable"),
    ],
)
def test_bad_validation_arguments(kw, msg):
    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    with pytest.raises(InputError, match=msg):
        train_detector(build("fcos"), ds, TrainConfig(epochs=1, device="cpu"), progress=False, **kw)


# --------------------------------------------------------------------------- bad input
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


def test_fcos_with_few_head_channels_runs_on_an_image_smaller_than_its_stride():
    # head_channels 8 made 8 GroupNorm groups of one channel: on the 1 x 1 map of a
    # 16 x 16 image a group held one value and torch raised a ValueError
    m = FCOS(2, width=4, head_channels=8, strides=(8, 16)).eval()
    out = m([torch.rand(3, 16, 16)])
    assert out[0]["boxes"].shape[1] == 4
    assert all(g.num_groups == 4 for g in m.modules() if isinstance(g, torch.nn.GroupNorm))


@pytest.mark.parametrize(
    ("settings", "classes", "msg"),
    [
        (3, ["a", "b"], "settings must be a dict"),
        (None, ["a", "b"], "settings must be a dict"),
        (np.eye(3), ["a", "b"], "settings must be a dict"),
        ({"width": 4}, 2, "classes must be a non-empty list"),
        ({"width": 4}, [1, 2], "classes must be a non-empty list"),
    ],
)
def test_save_detector_bad_settings_or_classes(tmp_path, settings, classes, msg):
    from robopercept.nn.detection.models import save_detector

    with pytest.raises(InputError, match=msg):
        save_detector(tmp_path / "d.pt", build("fcos", 2), "fcos", settings, classes)
    assert not (tmp_path / "d.pt").exists()


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


class _BrightBox(torch.nn.Module):
    """A stand-in detector: the bounding box of the pixels above 0.5 (label 1, score
    0.9): exact in every view, so TTA must give back the box of the original image."""

    def forward(self, images):
        out = []
        for im in images:
            ys, xs = torch.nonzero(im[0] > 0.5, as_tuple=True)
            box = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
            out.append(
                {
                    "boxes": torch.stack(box).float()[None],
                    "labels": torch.tensor([1]),
                    "scores": torch.tensor([0.9]),
                }
            )
        return out


class _Scripted(torch.nn.Module):
    """Returns scripted detections per call (one call per view, one image)."""

    def __init__(self, per_view):
        super().__init__()
        self.per_view = iter(per_view)

    def forward(self, images):
        boxes, scores = next(self.per_view)
        n = len(scores)
        return [
            {
                "boxes": torch.tensor(boxes, dtype=torch.float32).reshape(n, 4),
                "labels": torch.ones(n, dtype=torch.int64),
                "scores": torch.tensor(scores),
            }
        ]


@pytest.mark.parametrize("views", ["hflip", "flips", "dihedral"])
def test_tta_maps_every_view_back_onto_the_original_box(views):
    from robopercept.nn.detection.models import TTA_VIEWS, TestTimeAugmentation

    image = torch.zeros(3, 20, 31)
    image[:, 3:11, 5:24] = 1.0  # box (5, 3, 24, 11), not symmetric in the image
    tta = TestTimeAugmentation(_BrightBox(), views).eval()
    out = tta([image])[0]
    assert len(TTA_VIEWS[views]) == {"hflip": 2, "flips": 4, "dihedral": 8}[views]
    # exact up to float32 rounding of the score-weighted mean (sum of 0.9 b / sum of 0.9)
    torch.testing.assert_close(out["boxes"], torch.tensor([[5.0, 3.0, 24.0, 11.0]]))
    assert out["scores"].tolist() == pytest.approx([0.9])  # seen in every view


def test_tta_fusion_hand_case():
    from robopercept.nn.detection.models import TestTimeAugmentation

    # 'hflip' on a 100-px-wide image: view 1's boxes are mirrored back (x -> 100 - x).
    # Cluster A: (10,10,20,20) s=0.8 in view 0, and view 1's (80,10,90,20) -> (10,10,20,20)
    #   shifted by 2 px: (78,10,88,20) -> (12,10,22,20), s=0.4.
    # Cluster B: (50,50,60,60) s=0.6 in view 0 only.
    per_view = [
        ([[10, 10, 20, 20], [50, 50, 60, 60]], [0.8, 0.6]),
        ([[78, 10, 88, 20]], [0.4]),
    ]
    tta = TestTimeAugmentation(_Scripted(per_view), "hflip", iou_thresh=0.5).eval()
    out = tta([torch.zeros(3, 100, 100)])[0]
    # A: box x1 (0.8 * 10 + 0.4 * 12) / 1.2 = 32 / 3, x2 (0.8 * 20 + 0.4 * 22) / 1.2
    #    = 62 / 3; score (0.8 + 0.4) / 2 = 0.6
    # B: score (0.6 + 0) / 2 = 0.3
    torch.testing.assert_close(
        out["boxes"], torch.tensor([[32 / 3, 10, 62 / 3, 20], [50.0, 50, 60, 60]])
    )
    torch.testing.assert_close(out["scores"], torch.tensor([0.6, 0.3]))
    assert out["labels"].tolist() == [1, 1]


def test_tta_with_an_untrained_fcos_shapes_and_refusals():
    from robopercept.nn.detection.models import TestTimeAugmentation

    model = build("fcos").eval()
    model.score_thresh = 0.0  # every location: many detections per view
    tta = TestTimeAugmentation(model, "dihedral", detections_per_img=7).eval()
    out = tta([torch.rand(3, 32, 48), torch.rand(3, 40, 24)])
    for det, (h, w) in zip(out, [(32, 48), (40, 24)], strict=True):
        assert det["boxes"].shape == (7, 4) and det["scores"].shape == (7,)
        assert bool((det["scores"][:-1] >= det["scores"][1:]).all())
        assert bool(
            (det["boxes"][:, 2] <= w + 1e-4).all() and (det["boxes"][:, 3] <= h + 1e-4).all()
        )
    model.score_thresh = 1.0  # nothing survives any view
    empty = tta([torch.rand(3, 32, 32)])[0]
    assert empty["boxes"].shape == (0, 4) and empty["scores"].shape == (0,)
    with pytest.raises(InputError, match="only predicts"):
        tta.train()([torch.rand(3, 32, 32)])
    with pytest.raises(InputError, match="views"):
        TestTimeAugmentation(model, "rotations")


def test_weight_average_follows_the_warmed_up_ema_formula():
    from robopercept.nn.detection.models import _weight_average

    lin = torch.nn.Linear(1, 1, bias=False)
    avg = _weight_average(lin, 0.2)
    seen = []
    for w in (1.0, 3.0, 5.0):
        with torch.no_grad():
            lin.weight.fill_(w)
        avg.update_parameters(lin)
        seen.append(float(avg.module.weight.detach()))
    # n = 0 copies; n = 1: d = min(0.2, 2 / 11); n = 2: d = min(0.2, 3 / 12) = 0.2
    second = 2 / 11 * 1.0 + 9 / 11 * 3.0
    assert seen == pytest.approx([1.0, second, 0.2 * second + 0.8 * 5.0])


def test_ema_keeps_the_averaged_weights_and_checks_its_value():
    ds = digits_detection_set(2, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=3, batch_size=1, lr=3e-3, device="cpu", schedule="constant")
    plain, averaged = build("fcos"), build("fcos")
    train_detector(plain, ds, cfg, progress=False)
    hist = train_detector(averaged, ds, cfg, progress=False, val=ds, ema=0.9)
    # the raw weights of both runs are identical (same seed, the EMA does not feed
    # back); what comes back differs, and is what validation scored
    pairs = zip(plain.parameters(), averaged.parameters(), strict=True)
    differ = [not torch.equal(a, b) for a, b in pairs]
    assert any(differ)
    value = evaluate_detector(averaged, ds).stats[0]
    assert value == pytest.approx(hist.val[hist.best_epoch], abs=1e-12)
    for bad in (0.0, 1.0, float("nan")):
        with pytest.raises(InputError, match="--ema"):
            train_detector(build("fcos"), ds, cfg, progress=False, ema=bad)


def test_fcos_num_convs_sets_the_tower_depth():
    deep = FCOS(3, width=8, head_channels=16, num_convs=4)
    for tower in (deep.cls_tower, deep.reg_tower):
        convs = [m for m in tower if isinstance(m, torch.nn.Conv2d)]
        assert len(convs) == 4
    # the default keeps the 2-layer towers (and so the shipped models' state dicts)
    assert sum(isinstance(m, torch.nn.Conv2d) for m in FCOS(3, width=8).cls_tower) == 2
    deep.eval()
    assert deep([torch.rand(3, 32, 32)])[0]["boxes"].shape[1] == 4
    with pytest.raises(InputError, match="num_convs"):
        FCOS(3, num_convs=0)
