"""Keypoint R-CNN (issue 28): one-hot keypoint targets on regions, the loss rebuilt
from its parts, decoding back into the box, the multi-person procedural scenes."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from robopercept.errors import InputError
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.keypoint_rcnn import KeypointRCNN
from robopercept.nn.detection.zoo import detect_arrays
from robopercept.nn.pose.data import procedural_pose_scenes


def _model(j: int = 2) -> KeypointRCNN:
    torch.manual_seed(0)
    return KeypointRCNN(
        1, num_keypoints=j, width=8, hidden=32, keypoint_channels=8, keypoint_convs=1,
        keypoint_pool_size=4,
    )  # fmt: skip


def test_keypoint_targets_are_the_cells_that_contain_the_keypoints():
    m = _model()  # M = 8 cells over each region
    rois = torch.tensor([[10.0, 20.0, 26.0, 36.0]])  # 16 x 16: a cell is 2 px
    kp = torch.tensor([[[10.0, 20.0, 2], [25.9, 35.9, 1]]])
    index, valid = m.roi_heads.keypoint_head.keypoint_targets(rois, kp)
    assert index.tolist() == [[0, 63]] and valid.tolist() == [[True, True]]
    # x = 13.0 is (13 - 10) * 8 / 16 = 1.5 -> column 1; y = 27 -> row 3
    index, valid = m.roi_heads.keypoint_head.keypoint_targets(
        rois, torch.tensor([[[13.0, 27.0, 2], [5.0, 27.0, 2]]])
    )
    assert int(index[0, 0]) == 3 * 8 + 1 and valid.tolist() == [[True, False]]
    _, valid = m.roi_heads.keypoint_head.keypoint_targets(
        rois, torch.tensor([[[13.0, 27.0, 0], [26.0, 27.0, 2]]])
    )
    assert valid.tolist() == [[False, False]]  # unlabelled; x2 itself is outside


def test_the_keypoint_loss_is_the_cross_entropy_over_the_region_cells():
    m = _model().train()
    image = torch.rand(3, 48, 48)
    target = {
        "boxes": torch.tensor([[8.0, 8.0, 40.0, 40.0]]),
        "labels": torch.tensor([1]),
        "keypoints": torch.tensor([[[12.0, 14.0, 2], [30.0, 33.0, 2]]]),
    }
    captured = {}
    original = m.roi_heads.keypoint_head.keypoint_logits

    def spy(feats, rois):
        out = original(feats, rois)
        captured["z"], captured["rois"] = out, rois
        return out

    m.roi_heads.keypoint_head.keypoint_logits = spy  # type: ignore[method-assign]
    torch.manual_seed(1)
    losses = m([image], [target])
    rois = torch.cat(captured["rois"])
    index, valid = m.roi_heads.keypoint_head.keypoint_targets(
        rois, target["keypoints"].expand(len(rois), -1, -1)
    )
    z = captured["z"].flatten(2)
    expected = F.cross_entropy(z[valid], index[valid])
    torch.testing.assert_close(losses["loss_keypoint"], expected)
    assert set(losses) >= {"loss_classifier", "loss_box", "loss_keypoint"}


def test_decoding_puts_a_one_hot_cell_at_its_centre_in_the_box():
    m = _model().eval()
    mres = m.roi_heads.keypoint_head.keypoint_resolution  # 8

    def fixed(feats, rois):
        r = torch.cat(rois)
        z = torch.full((len(r), 2, mres, mres), -30.0)
        z[:, 0, 2, 5] = 30.0  # row 2, column 5
        z[:, 1, 7, 0] = 30.0
        return z

    m.roi_heads.keypoint_head.keypoint_logits = fixed  # type: ignore[method-assign]
    box = torch.tensor([[8.0, 4.0, 40.0, 20.0]])  # 32 x 16: cells 4 x 2 px
    dets = [{"boxes": box, "labels": torch.tensor([1]), "scores": torch.tensor([0.9])}]
    out = m.roi_heads.keypoint_head.outputs(torch.zeros(1, 8, 6, 6), [(48, 48)], dets)[0]
    # a one-hot peak has equal (zero-probability) neighbours: the cell centre exactly
    np.testing.assert_allclose(
        out["keypoints"][0].numpy(), [[8 + 5.5 * 4, 4 + 2.5 * 2, 1], [8 + 0.5 * 4, 4 + 7.5 * 2, 1]]
    )
    assert out["keypoints_scores"].shape == (1, 2)


def test_refusals_and_eval_outputs():
    m = _model().train()
    t = {"boxes": torch.tensor([[4.0, 4, 20, 28]]), "labels": torch.tensor([1])}
    with pytest.raises(InputError, match="has no 'keypoints'"):
        m([torch.rand(3, 32, 32)], [t])
    with pytest.raises(InputError, match=r"must be \(1, 2, 3\)"):
        m([torch.rand(3, 32, 32)], [{**t, "keypoints": torch.zeros(1, 3, 3)}])
    d = detect_arrays(m.eval(), [np.random.default_rng(0).random((32, 32, 3))])[0]
    assert d["keypoints"].shape[1:] == (2, 3)


def test_procedural_scenes_have_one_keypoint_set_per_person():
    ds = procedural_pose_scenes(6, (128, 96), rng=2, people=(2, 3))
    assert isinstance(ds, DetectionDataset) and ds.keypoints is not None
    for i in range(len(ds)):
        k = len(ds.boxes[i])
        assert ds.keypoints[i].shape == (k, 16, 3) and ds.masks[i].shape == (k, 96, 128)
        # masks are the visible silhouettes: disjoint
        assert ds.masks[i].sum(0).max() <= 1
        # a seen joint of a person lies on that person's silhouette
        for p in range(k):
            kp = ds.keypoints[i][p]
            seen = kp[:, 2] == 2
            c, r = kp[seen, 0].astype(int), kp[seen, 1].astype(int)
            assert ds.masks[i][p][r, c].mean() > 0.95
    assert sum(len(b) for b in ds.boxes) >= 10
    _image, target = ds[0]
    assert target["keypoints"].shape == (len(ds.boxes[0]), 16, 3)
    coco = ds.to_coco(masks=False)
    assert coco.keypoints.shape == (ds.n_boxes, 16, 3)
    with pytest.raises(InputError, match="people"):
        procedural_pose_scenes(1, people=(3, 2))
