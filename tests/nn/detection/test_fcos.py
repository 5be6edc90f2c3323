"""Tests of robopercept.nn.detection.fcos: assignment, the box activation, the regression
and quality losses by hand, GroupNorm groups and the tower depth."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.fcos import FCOS  # noqa: E402
from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from tests.nn.detection.detectors import build, tiny_batch  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_fcos_untrained_on_blank_image_is_empty():
    # the classification prior (0.01) keeps every score below the 0.2 threshold
    o = build("fcos").eval()([torch.zeros(3, 32, 32)])[0]
    assert o["boxes"].shape == (0, 4)


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


def test_fcos_with_few_head_channels_runs_on_an_image_smaller_than_its_stride():
    # head_channels 8 made 8 GroupNorm groups of one channel: on the 1 x 1 map of a
    # 16 x 16 image a group held one value and torch raised a ValueError
    m = FCOS(2, width=4, head_channels=8, strides=(8, 16)).eval()
    out = m([torch.rand(3, 16, 16)])
    assert out[0]["boxes"].shape[1] == 4
    assert all(g.num_groups == 4 for g in m.modules() if isinstance(g, torch.nn.GroupNorm))


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
