"""Tests of robopercept.nn.detection.faster_rcnn: the region proposal network's sampling,
proposal counts and outputs inside the detector."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from tests.nn.detection.detectors import build, tiny_batch  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_faster_rcnn_rpn_sampling_and_proposal_counts():
    m = build("faster", post_nms_top_n=(40, 7)).train()
    images, targets = tiny_batch()
    torch.manual_seed(0)
    batch, sizes, _ = m._prepare(images, targets)
    feats = m.backbone(batch)[-1]
    obj, reg, anchors = m.rpn.anchor_outputs(feats, tuple(batch.shape[2:]))
    assert obj.shape == (2, 8 * 8 * 9) and reg.shape == (2, 8 * 8 * 9, 4)
    assert anchors.shape == (8 * 8 * 9, 4)
    props, _ = m.rpn.filter_proposals(obj, reg, anchors, sizes)
    assert [p.shape[0] <= 40 for p in props] == [True, True]
    for p, (h, w) in zip(props, sizes, strict=True):
        assert bool((p[:, 2] <= w).all() and (p[:, 3] <= h).all() and (p[:, 0] >= 0).all())
    m.eval()
    props, _ = m.rpn.filter_proposals(obj, reg, anchors, sizes)
    assert all(p.shape[0] <= 7 for p in props)


def test_rpn_outputs_agree_with_the_rpn_and_keep_the_mode():
    m = build("faster", post_nms_top_n=(40, 7)).train()
    images, _ = tiny_batch()
    out = m.rpn_outputs(images)
    assert m.training  # restored
    m.eval()
    batch, sizes, _ = m._prepare(images, None)
    obj, reg, anchors = m.rpn.anchor_outputs(m.backbone(batch)[-1], tuple(batch.shape[2:]))
    props, scores = m.rpn.filter_proposals(obj, reg, anchors, sizes)
    for i, o in enumerate(out):
        assert o["objectness"].shape == (8, 8, 9) and o["anchors"].shape == (8, 8, 9, 4)
        # cell (r, c), anchor a is flat index (r * 8 + c) * 9 + a, as AnchorGenerator
        assert torch.equal(o["objectness"][2, 5, 4], torch.sigmoid(obj[i, (2 * 8 + 5) * 9 + 4]))
        assert torch.equal(o["anchors"][2, 5, 4], anchors[(2 * 8 + 5) * 9 + 4])
        assert torch.equal(o["proposals"], props[i]) and len(o["proposals"]) <= 7
        assert torch.equal(o["proposal_scores"], scores[i])
