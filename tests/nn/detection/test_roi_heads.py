"""Tests of robopercept.nn.detection.roi_heads: region sampling fractions and IoU bands, and
the branches composed into the RoI heads."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from robopercept.nn.detection.faster_rcnn import FasterRCNN  # noqa: E402
from robopercept.nn.detection.keypoint_rcnn import KeypointHead, KeypointRCNN  # noqa: E402
from robopercept.nn.detection.mask_rcnn import MaskHead, MaskRCNN  # noqa: E402
from robopercept.nn.ops.boxes import box_iou  # noqa: E402
from tests.nn.detection.detectors import build, grid_proposals  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_roi_sampling_fractions_and_bands():
    m = build("fast", box_batch_size=32).train()
    torch.manual_seed(0)
    gt = {"boxes": torch.tensor([[8.0, 8, 40, 40]]), "labels": torch.tensor([4])}
    props = [grid_proposals(torch.zeros(3, 64, 64))]
    rois, labels, deltas = m.roi_heads.select_training_samples(props, [gt])
    iou = box_iou(gt["boxes"], rois[0])[0]
    fg = labels[0] > 0
    assert rois[0].shape[0] == 32 and int(fg.sum()) == 8  # 25 % of 32
    assert bool((labels[0][fg] == 4).all()) and bool((iou[fg] >= 0.5).all())
    assert bool(((iou[~fg] >= 0.1) & (iou[~fg] < 0.5)).all())  # Fast R-CNN's background band
    assert bool((deltas[0][~fg] == 0).all())


def test_mask_and_keypoint_rcnn_are_faster_rcnn_given_a_branch():
    # composed, not overridden: the subclasses only pass a branch to FasterRCNN.__init__
    for cls in (MaskRCNN, KeypointRCNN):
        assert [n for n, v in vars(cls).items() if callable(v)] == ["__init__"]
    m = MaskRCNN(2, width=4, hidden=8, mask_channels=4, mask_convs=1)
    assert isinstance(m.roi_heads.mask_head, MaskHead) and m.roi_heads.keypoint_head is None
    k = KeypointRCNN(1, width=4, hidden=8, num_keypoints=2, keypoint_convs=1)
    assert isinstance(k.roi_heads.keypoint_head, KeypointHead)
    # the same composition by hand
    torch.manual_seed(0)
    by_hand = FasterRCNN(
        2,
        width=4,
        hidden=8,
        mask_head=lambda c, s: MaskHead(c, 2, mask_channels=4, mask_convs=1, spatial_scale=s),
    )
    torch.manual_seed(0)
    m = MaskRCNN(2, width=4, hidden=8, mask_channels=4, mask_convs=1)
    for (a, x), (b, y) in zip(by_hand.state_dict().items(), m.state_dict().items(), strict=True):
        assert a == b and torch.equal(x, y)
