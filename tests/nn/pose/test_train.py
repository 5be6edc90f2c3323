"""Training pose networks (issue 28): augmentation geometry, heatmap and DeepPose
training, the cascade, and refusals."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError
from robopercept.nn.ops.heatmaps import decode_heatmaps, gaussian_heatmaps, heatmap_loss
from robopercept.nn.pose.data import procedural_pose_set
from robopercept.nn.pose.inference import predict_keypoints, refine_keypoints
from robopercept.nn.pose.metrics import pck
from robopercept.nn.pose.networks import DeepPose, DeepPoseRefiner, HRNet
from robopercept.nn.pose.train import augment_pose_batch, train_cascade, train_pose, train_refiner
from robopercept.nn.skeleton import MPII_16
from robopercept.nn.train.config import TrainConfig


def _random_keypoints(n: int, j: int, w: int, h: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform([6.0, 6.0], [w - 6.0, h - 6.0], (n, j, 2))
    return np.concatenate([xy, np.full((n, j, 1), 2.0)], -1)


def test_augmentation_moves_the_image_and_the_keypoints_together():
    kp = _random_keypoints(6, 16, 96, 64, seed=3)
    kp[..., :2] = np.clip(kp[..., :2], 30, 60)  # stay inside after the warp
    # each joint drawn as its own Gaussian channel: after the warp, the peak of each
    # channel must sit at the warped keypoint
    hm, _ = gaussian_heatmaps(kp, (96, 64), stride=1, sigma=2.0)
    for perm in (None, MPII_16.flip_permutation()):
        gen = torch.Generator().manual_seed(5)
        kp_t = torch.from_numpy(kp).float()
        warped, kp2 = augment_pose_batch(hm, kp_t, None, gen, rotation=30, scale=(0.8, 1.2))
        ok = kp2[..., 2] > 0
        dec, _ = decode_heatmaps(warped, 1, "quadratic")
        err = np.linalg.norm(dec - kp2[..., :2].numpy(), axis=-1)[ok.numpy()]
        assert ok.float().mean() > 0.8 and np.median(err) < 0.3 and err.max() < 1.0
        del perm
    # with a flip permutation the joints swap sides with the mirror image
    gen = torch.Generator().manual_seed(0)
    img = torch.zeros(64, 3, 8, 8)
    kpf = torch.zeros(64, 16, 3)
    kpf[:, :, 0], kpf[:, :, 1], kpf[:, :, 2] = torch.arange(16.0) * 0.1 + 3, 4.0, 2.0
    _, out = augment_pose_batch(
        img, kpf, MPII_16.flip_permutation(), gen, rotation=0, scale=(1, 1), shift=0
    )
    flipped = torch.isclose(out[:, 0, 0], 8 - kpf[0, MPII_16.flip_permutation()[0], 0])
    kept = torch.isclose(out[:, 0, 0], kpf[0, 0, 0])
    assert bool((flipped | kept).all()) and 10 < int(flipped.sum()) < 54


@pytest.fixture(scope="module")
def tiny() -> tuple:
    data = procedural_pose_set(24, (64, 64), rng=3)
    return data.subset(range(16)), data.subset(range(16, 24))


def test_heatmap_training_lowers_the_loss_and_is_seeded(tiny):
    train, val = tiny
    cfg = TrainConfig(epochs=3, batch_size=8, lr=3e-3, device="cpu")
    runs = []
    for _ in range(2):
        torch.manual_seed(0)  # the initial weights; train_pose seeds the rest from cfg.seed
        net = HRNet(16, width=4, blocks=1)
        hist = train_pose(net, train, cfg, val=val, skeleton=MPII_16, progress=False)
        runs.append((net, hist))
    (a, ha), (b, hb) = runs
    assert ha.losses == hb.losses and ha.losses[-1] < ha.losses[0]
    for pa, pb in zip(a.parameters(), b.parameters(), strict=True):
        torch.testing.assert_close(pa, pb, atol=0, rtol=0)
    assert sorted(ha.val) == [1, 2, 3] and ha.best_epoch in ha.val


def test_deeppose_and_a_cascade_stage_train_and_refine(tiny):
    train, val = tiny
    cfg = TrainConfig(epochs=2, batch_size=8, lr=1e-3, device="cpu")
    net = DeepPose(16, (64, 64), width=4, hidden=32)
    hist = train_pose(net, train, cfg, skeleton=MPII_16, progress=False)
    assert len(hist.losses) == 2 and np.isfinite(hist.losses).all()
    est, score = predict_keypoints(net, train.images)
    assert est.shape == (16, 16, 2) and np.all(score == 1.0)
    stage = DeepPoseRefiner(16, crop=16, patch=16, width=4)
    vest, _ = predict_keypoints(net, val.images)
    h2 = train_refiner(stage, train, est, cfg, val=val, val_estimates=vest, progress=False)
    assert sorted(h2.val) == [1, 2]
    out = refine_keypoints(val.images, vest, [stage])
    assert out.shape == vest.shape and np.isfinite(out).all()
    with pytest.raises(InputError, match="val_estimates"):
        train_refiner(stage, train, est, cfg, val=val, progress=False)
    assert train_cascade(net, train, 0) == ([], [])
    with pytest.raises(InputError, match="0 to 8"):
        train_cascade(net, train, 9)
    with pytest.raises(InputError, match=r"estimates must be \(N, J, 2\)"):
        train_refiner(stage, train, est[:, :3], cfg, progress=False)


def test_training_refusals(tiny):
    train, _ = tiny
    with pytest.raises(InputError, match="predicts 3 joints"):
        train_pose(HRNet(3, width=2, blocks=1), train, progress=False)
    with pytest.raises(InputError, match="pose network"):
        train_pose(torch.nn.Linear(2, 2), train, progress=False)
    with pytest.raises(InputError, match="PoseDataset"):
        train_pose(HRNet(16, width=2, blocks=1), np.zeros((2, 64, 64, 3)), progress=False)
    stage = DeepPoseRefiner(16, crop=16, patch=16, width=2)
    with pytest.raises(InputError, match="TrainConfig"):
        train_refiner(stage, train, np.zeros((16, 16, 2)), 3, progress=False)


def test_no_labelled_joint_gives_a_zero_loss_and_no_pck():
    kp = np.zeros((2, 3, 3))  # every joint unlabelled (v = 0)
    target, weight = gaussian_heatmaps(kp, (16, 16), 4)
    out = torch.randn(2, 3, 4, 4, requires_grad=True)
    for kind in ("softmax", "mse"):
        loss = heatmap_loss(out, target, weight, kind)
        assert float(loss.detach()) == 0.0 and torch.isfinite(loss)
        loss.backward()  # a graph, zero gradients: a batch of such images is harmless
    scores = pck(np.ones((2, 3, 2)), kp, None, 0.1, np.ones(2))
    # nothing counts: NaN, documented (mmpose writes -1), not 0 or 1
    assert np.isnan(scores.mean) and np.isnan(scores.per_joint).all()
