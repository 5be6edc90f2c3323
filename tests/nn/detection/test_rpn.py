"""Tests of robopercept.nn.detection.rpn: the region proposal network alone (proposal
counts and shapes, boxes inside their image, anchor labelling by hand, losses that
fall), and the checkpoints with the keys of before the detectors were composed."""

from __future__ import annotations

import itertools
import math

import pytest

torch = pytest.importorskip("torch")

from torch.nn import functional as F  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.faster_rcnn import LEGACY_KEYS, FasterRCNN  # noqa: E402
from robopercept.nn.detection.rcnn import RCNN  # noqa: E402
from robopercept.nn.detection.rpn import RegionProposalNetwork  # noqa: E402
from robopercept.nn.detection.zoo import build_detector, load_detector  # noqa: E402
from robopercept.nn.ops.anchors import AnchorGenerator  # noqa: E402
from robopercept.nn.shipped import shipped_model_path  # noqa: E402
from robopercept.nn.train.checkpoint import load_checkpoint  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _rpn(**kw) -> RegionProposalNetwork:
    """8 channels, one 16 x 16 anchor per cell, centred on the cells of a stride-8 map."""
    torch.manual_seed(0)
    return RegionProposalNetwork(8, AnchorGenerator((16.0,), (1.0,), offset=0.5), **kw)


def test_proposal_counts_shapes_and_boxes_inside_each_image():
    rpn = _rpn(pre_nms_top_n=(40, 20), post_nms_top_n=(6, 3), nms_thresh=0.9).train()
    feats = torch.randn(2, 8, 8, 8)
    sizes = [(64, 64), (40, 52)]  # the second image is padded into the 64 x 64 batch
    targets = [
        {"boxes": torch.tensor([[8.0, 8, 40, 40]])},
        {"boxes": torch.tensor([[4.0, 4, 20, 30]])},
    ]
    boxes, losses = rpn(feats, (64, 64), sizes, targets)
    assert sorted(losses) == ["loss_rpn_box", "loss_rpn_objectness"]
    assert [b.shape[1] for b in boxes] == [4, 4] and all(1 <= len(b) <= 6 for b in boxes)
    for b, (h, w) in zip(boxes, sizes, strict=True):
        assert not b.requires_grad
        assert bool((b[:, 0] >= 0).all() and (b[:, 1] >= 0).all())
        assert bool((b[:, 2] <= w).all() and (b[:, 3] <= h).all())
        assert bool(((b[:, 2] - b[:, 0]) >= rpn.min_size).all())
    rpn.eval()
    boxes, losses = rpn(feats, (64, 64), sizes)
    assert losses == {} and all(1 <= len(b) <= 3 for b in boxes)
    # the eval count of the head's outputs, best first
    obj, reg, anchors = rpn.anchor_outputs(feats, (64, 64))
    assert obj.shape == (2, 64) and reg.shape == (2, 64, 4) and anchors.shape == (64, 4)
    props, scores = rpn.filter_proposals(obj, reg, anchors, sizes)
    for p, s, b in zip(props, scores, boxes, strict=True):
        assert torch.equal(p, b) and bool((s[:-1] >= s[1:]).all())


def test_anchors_are_labelled_as_documented():
    # 4 x 4 cells of 8 px, one 16 x 16 anchor centred on each: cell (r, c) is
    # [8c - 4, 8r - 4, 8c + 12, 8r + 12], row 4 r + c of the anchors
    rpn = _rpn(batch_size=64)  # every labelled anchor is sampled (16 < 64, 1 positive)
    feats = torch.randn(2, 8, 4, 4)
    obj, reg, anchors = rpn.anchor_outputs(feats, (32, 32))
    assert anchors[5].tolist() == [4.0, 4.0, 20.0, 20.0]
    # image 0: the box is anchor (1, 1) (IoU 1: positive); its 4-neighbours overlap it by
    # 1/3 (ignored, in [0.3, 0.7)); the others by 1/7 or 0 (negative)
    # image 1: a 10 x 10 box at the corner: its best anchor, (0, 0), has IoU 100 / 256
    # < 0.7 and is positive all the same (every box gets an anchor); the rest negative
    gt = [torch.tensor([[4.0, 4, 20, 20]]), torch.tensor([[0.0, 0, 10, 10]])]
    labels = [torch.zeros(16), torch.zeros(16)]
    labels[0][5] = 1.0
    labels[1][0] = 1.0
    ignored = [torch.zeros(16, dtype=torch.bool), torch.zeros(16, dtype=torch.bool)]
    ignored[0][[1, 4, 6, 9]] = True
    deltas = torch.zeros_like(reg)
    losses = rpn.losses(obj, deltas, anchors, [{"boxes": g} for g in gt])
    keep = [~i for i in ignored]
    logits = torch.cat([obj[i][keep[i]] for i in range(2)])
    target = torch.cat([labels[i][keep[i]] for i in range(2)])
    bce = F.binary_cross_entropy_with_logits(logits, target)
    torch.testing.assert_close(losses["loss_rpn_objectness"], bce, rtol=0, atol=0)
    # deltas of image 1's positive: anchor centre (4, 4), side 16 -> box centre (5, 5),
    # side 10; the box loss is their smooth-L1 (beta 1/9) over the 12 + 16 sampled
    d = [1 / 16, 1 / 16, math.log(10 / 16), math.log(10 / 16)]

    def smooth(x: float, beta: float = 1 / 9) -> float:
        return 0.5 * x * x / beta if abs(x) < beta else abs(x) - 0.5 * beta

    expected = sum(smooth(v) for v in d) / (12 + 16)
    assert float(losses["loss_rpn_box"]) == pytest.approx(expected, rel=1e-5)


def test_losses_are_finite_and_fall_on_one_image():
    rpn = _rpn(batch_size=64).train()
    feats = torch.randn(1, 8, 4, 4)
    targets = [{"boxes": torch.tensor([[4.0, 4, 20, 20], [12.0, 10, 30, 30]])}]
    opt = torch.optim.SGD(rpn.parameters(), lr=0.5)
    totals = []
    for _ in range(15):
        _, losses = rpn(feats, (32, 32), [(32, 32)], targets)
        assert all(bool(torch.isfinite(v)) for v in losses.values())
        loss = sum(losses.values())
        opt.zero_grad()
        loss.backward()
        opt.step()
        totals.append(float(loss.detach()))
    assert totals[-1] < 0.5 * totals[0]
    assert all(b <= a + 1e-6 for a, b in itertools.pairwise(totals[:6]))


def test_refusals():
    ag = AnchorGenerator((16.0,), (1.0,))
    rpn = RegionProposalNetwork(8, ag).train()
    with pytest.raises(InputError, match="targets"):
        rpn(torch.zeros(1, 8, 4, 4), (32, 32), [(32, 32)])
    with pytest.raises(InputError, match="features"):
        rpn(torch.zeros(1, 3, 4, 4), (32, 32), [(32, 32)], [{"boxes": torch.zeros(0, 4)}])
    with pytest.raises(InputError, match="sizes"):
        rpn.eval()(torch.zeros(2, 8, 4, 4), (32, 32), [(32, 32)])
    with pytest.raises(InputError, match="image_shape"):
        rpn.eval()(torch.zeros(1, 8, 4, 4), (2, 2), [(2, 2)])
    with pytest.raises(InputError, match="one feature map"):
        RegionProposalNetwork(8, AnchorGenerator(((16.0,), (32.0,)), (1.0,)))
    with pytest.raises(InputError, match="AnchorGenerator"):
        RegionProposalNetwork(8, None)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="bg_iou"):
        RegionProposalNetwork(8, ag, fg_iou=0.5, bg_iou=0.6)
    with pytest.raises(InputError, match="rpn_bg_iou"):
        FasterRCNN(2, width=4, rpn_fg_iou=0.5, rpn_bg_iou=0.6)


# --------------------------------------------------------------------------- old keys
def _old_format(state: dict, renames: dict) -> dict:
    """``state`` with the key prefixes of before (the inverse of ``renames``)."""
    out = {}
    for k, v in state.items():
        for old, new in renames.items():
            if k.startswith(new):
                k = old + k[len(new) :]
                break
        out[k] = v
    return out


SETTINGS = {
    "faster": {"width": 4, "hidden": 8},
    "maskrcnn": {"width": 4, "hidden": 8, "mask_channels": 4, "mask_convs": 1},
    "keypointrcnn": {"width": 4, "hidden": 8, "num_keypoints": 2, "keypoint_convs": 1},
    "fast": {"width": 4, "hidden": 8},
    "rcnn": {"warp_size": 8, "width": 4, "hidden": 8},
}


@pytest.mark.parametrize("kind", sorted(SETTINGS))
def test_checkpoints_with_the_old_keys_load(kind, tmp_path):
    m = build_detector(kind, 2, seed=1, **SETTINGS[kind])
    renames = type(m).renamed_keys
    old = _old_format(m.state_dict(), renames)
    assert set(old) != set(m.state_dict())  # the layout did change
    torch.save(old, tmp_path / "old.pt")
    fresh = build_detector(kind, 2, seed=2, **SETTINGS[kind])
    fresh.load_state_dict(torch.load(tmp_path / "old.pt", weights_only=True))
    for k, v in m.state_dict().items():
        assert torch.equal(v, fresh.state_dict()[k]), k
    # through load_checkpoint too (what train_detector's resume uses), which compares the
    # key sets first: under the new names
    torch.save({"model": old}, tmp_path / "old_ckpt.pt")
    again = build_detector(kind, 2, seed=3, **SETTINGS[kind])
    load_checkpoint(tmp_path / "old_ckpt.pt", again)
    for k, v in m.state_dict().items():
        assert torch.equal(v, again.state_dict()[k]), k
    # new checkpoints load too, and strictness still holds
    fresh.load_state_dict(m.state_dict())
    with pytest.raises(RuntimeError, match="Unexpected"):
        fresh.load_state_dict({**m.state_dict(), "rpn_bogus.weight": torch.zeros(1)})


def test_the_legacy_table_names_every_moved_layer():
    assert LEGACY_KEYS["rpn_conv."] == "rpn.conv."
    assert LEGACY_KEYS["roi.fc.1."] == "roi_heads.box_head.fc6."
    assert set(RCNN.renamed_keys.values()) == {
        "roi_heads.box_head.",
        "roi_heads.box_predictor.cls_score.",
        "roi_heads.box_predictor.bbox_pred.",
    }


def test_the_shipped_detector_has_the_old_keys_and_loads_them():
    path = shipped_model_path("detect", "faster")
    raw = torch.load(path, map_location="cpu", weights_only=True)["model"]
    assert "rpn_conv.weight" in raw and "roi.fc.1.weight" in raw
    model, _ = load_detector(path)
    assert torch.equal(model.rpn.conv.weight, raw["rpn_conv.weight"])
    assert torch.equal(model.roi_heads.box_head.fc6.weight, raw["roi.fc.1.weight"])
    assert torch.equal(model.roi_heads.box_predictor.bbox_pred.bias, raw["roi.bbox_pred.bias"])
