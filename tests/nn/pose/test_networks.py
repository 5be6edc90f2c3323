"""Pose networks (issue 28): heatmap targets and decoding, the flip convention,
augmentation geometry, window crops, the three networks, training and refusals."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError
from robopercept.nn.ops.boxes import roi_align
from robopercept.nn.pose.data import procedural_pose_set
from robopercept.nn.pose.networks import (
    DeepPose,
    DeepPoseRefiner,
    HRNet,
    SimpleBaseline,
    augment_pose_batch,
    build_pose_model,
    crop_patches,
    decode_heatmaps,
    gaussian_heatmaps,
    heatmap_loss,
    pose_arrays,
    predict_keypoints,
    refine_keypoints,
    train_cascade,
    train_pose,
    train_refiner,
)
from robopercept.nn.skeleton import MPII_16
from robopercept.nn.train.loop import TrainConfig


def _random_keypoints(n: int, j: int, w: int, h: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform([6.0, 6.0], [w - 6.0, h - 6.0], (n, j, 2))
    return np.concatenate([xy, np.full((n, j, 1), 2.0)], -1)


class TestHeatmaps:
    def test_hand_case_peak_at_the_cell_centre(self):
        # x = 6 at stride 4 is u = 6/4 - 1/2 = 1: the peak is cell 1 exactly
        hm, w = gaussian_heatmaps([[[6.0, 10.0, 2]]], (16, 16), stride=4, sigma=1.0)
        assert hm.shape == (1, 1, 4, 4) and w.tolist() == [[1.0]]
        assert float(hm[0, 0, 2, 1]) == 1.0  # y = 10 is v = 2
        assert float(hm[0, 0, 2, 2]) == pytest.approx(np.exp(-0.5))

    def test_unlabelled_and_outside_joints_have_zero_weight_and_map(self):
        kp = [[[5.0, 5.0, 0], [40.0, 5.0, 2], [np.nan, 3.0, 2], [5.0, 5.0, 1]]]
        hm, w = gaussian_heatmaps(kp, (32, 32), stride=4)
        assert w.tolist() == [[0.0, 0.0, 0.0, 1.0]]
        assert float(hm[0, :3].abs().max()) == 0.0

    def test_quadratic_decoding_round_trips_under_a_twentieth_of_a_pixel(self):
        kp = _random_keypoints(100, 16, 128, 96)
        for stride, sigma in ((4, 2.0), (4, 1.0), (2, 1.5), (1, 2.0)):
            hm, _ = gaussian_heatmaps(kp, (128, 96), stride, sigma)
            dec, score = decode_heatmaps(hm, stride, "quadratic")
            # exact for a Gaussian up to float32 rounding of the map
            assert np.abs(dec - kp[..., :2]).max() < 0.05
            # the peak cell is at most half a cell from the centre on each axis
            assert score.min() >= np.exp(-0.25 / sigma**2) - 1e-6

    def test_quarter_offset_error_is_at_most_a_quarter_cell_and_soft_argmax_is_unbiased(self):
        kp = _random_keypoints(100, 8, 128, 128, seed=1)
        hm, _ = gaussian_heatmaps(kp, (128, 128), 4, 2.0)
        quarter, _ = decode_heatmaps(hm, 4, "quarter")
        # argmax is within half a cell, the quarter step leaves at most 1/4 + ... per axis:
        # |u - (j + s/4)| <= 1/4 when the true offset lies in [-1/2, 1/2] (0.25 cell = 1 px)
        assert np.abs(quarter - kp[..., :2]).max() <= 1.0 + 1e-6
        soft, _ = decode_heatmaps(hm, 4, "soft-argmax", beta=200.0)
        # a sharp softmax is the argmax's neighbourhood mean: within half a cell (2 px)
        assert np.abs(soft - kp[..., :2]).max() < 2.0

    def test_flipping_the_keypoints_flips_the_heatmaps_and_swaps_the_channels(self):
        kp = _random_keypoints(5, 16, 128, 64, seed=2)
        perm = MPII_16.flip_permutation()
        flipped = kp[:, perm].copy()
        flipped[..., 0] = 128 - flipped[..., 0]
        a, _ = gaussian_heatmaps(kp, (128, 64), 4)
        b, _ = gaussian_heatmaps(flipped, (128, 64), 4)
        # the module's convention: x -> W - x is the cell flip u -> (w - 1) - u exactly
        torch.testing.assert_close(b, a.flip(-1)[:, perm], atol=1e-6, rtol=0)

    def test_refusals(self):
        with pytest.raises(InputError, match="multiple of the stride"):
            gaussian_heatmaps([[[1, 1, 2]]], (30, 32), stride=4)
        with pytest.raises(InputError, match=r"\(N, J, 3\)"):
            gaussian_heatmaps([[1, 1, 2]], (32, 32))
        with pytest.raises(InputError, match="finite"):
            decode_heatmaps(torch.full((1, 1, 4, 4), float("nan")))
        with pytest.raises(InputError, match="method"):
            decode_heatmaps(torch.zeros(1, 1, 4, 4), method="argmax")


class TestGeometry:
    def test_crop_patches_equals_aligned_roi_align_with_one_sample(self):
        torch.manual_seed(0)
        im = torch.rand(2, 3, 40, 50)
        centres = torch.tensor([[[10.3, 12.7], [30.0, 20.5]], [[25.2, 5.1], [44.0, 33.3]]])
        crop, p = 9.0, 6
        ours = crop_patches(im, centres, crop, p)
        boxes = torch.cat([centres - crop / 2, centres + crop / 2], -1)
        ref = roi_align(im, [boxes[0], boxes[1]], p, sampling_ratio=1, aligned=True)
        # both are bilinear samples at the bin centres; they differ only near the image
        # border (grid_sample pads with 0, RoI Align clamps the border band): interior here
        torch.testing.assert_close(ours, ref, atol=1e-5, rtol=0)

    def test_augmentation_moves_the_image_and_the_keypoints_together(self):
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


class TestNetworks:
    def test_output_shapes_and_strides(self):
        x = torch.zeros(2, 3, 64, 96)
        assert SimpleBaseline(5, width=4)(x).shape == (2, 5, 16, 24)
        assert HRNet(5, width=4, blocks=1)(x).shape == (2, 5, 16, 24)
        assert DeepPose(5, image_size=(96, 64), width=4)(x).shape == (2, 5, 2)
        assert type(build_pose_model("deeppose", 3, (64, 64), width=4)).__name__ == "DeepPose"

    def test_hrnet_keeps_three_parallel_branches_and_fuses_them(self):
        net = HRNet(4, width=4, blocks=1, modules=(1, 2))
        seen: list[list[tuple[int, ...]]] = []
        for module in net.stages:
            for _branches, fuse in module:
                fuse.register_forward_hook(lambda m, i, o: seen.append([t.shape[-2:] for t in o]))
        net(torch.zeros(1, 3, 64, 64))
        assert len(seen) == 3  # one fusion in stage 2, two in stage 3
        assert [tuple(s) for s in seen[0]] == [(16, 16), (8, 8)]
        assert [tuple(s) for s in seen[-1]] == [(16, 16), (8, 8), (4, 4)]

    def test_hrnet_fusion_lets_the_low_branch_reach_the_output(self):
        torch.manual_seed(0)
        net = HRNet(2, width=4, blocks=1).eval()
        x = torch.rand(1, 3, 64, 64, requires_grad=True)
        net(x)[0, 0, 8, 8].backward()
        # the receptive field of one output cell spans far beyond a stride-4 3x3 stack
        rows = torch.nonzero(x.grad.abs().sum((0, 1)) > 0)[:, 0]
        assert int(rows.max() - rows.min()) > 40

    def test_refusals(self):
        with pytest.raises(InputError, match="name"):
            build_pose_model("openpose", 16)
        with pytest.raises(InputError, match="built for 64 x 64"):
            predict_keypoints(DeepPose(2, (64, 64), width=2), np.zeros((1, 32, 32, 3)))
        with pytest.raises(InputError, match="multiple of 16"):
            predict_keypoints(SimpleBaseline(2, width=2), np.zeros((1, 40, 40, 3)))
        with pytest.raises(InputError, match=r"\(N, H, W, 3\)"):
            predict_keypoints(SimpleBaseline(2, width=2), np.zeros((32, 32, 3)))


class _Blob(torch.nn.Module):
    """A flip-equivariant stand-in: stride-4 average of channel 0, one map per joint."""

    output = "heatmaps"
    stride = 4

    def __init__(self, j: int) -> None:
        super().__init__()
        self.j = j
        self.dummy = torch.nn.Parameter(torch.zeros(()))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.nn.functional.avg_pool2d(x[:, :1], 4).repeat(1, self.j, 1, 1)


def test_flip_test_on_a_flip_equivariant_model_gives_the_same_keypoints():
    kp = np.array([[[21.0, 37.0, 2.0], [21.0, 37.0, 2.0]]])
    hm, _ = gaussian_heatmaps(kp, (64, 64), stride=1, sigma=6.0)
    images = hm[:, :1].permute(0, 2, 3, 1).repeat(1, 1, 1, 3).numpy()
    plain, _ = predict_keypoints(_Blob(2), images)
    flip, _ = predict_keypoints(_Blob(2), images, flip_permutation=[1, 0])
    # the flipped-back heatmap lands on the same cells: no half-cell shift
    np.testing.assert_allclose(flip, plain, atol=1e-6)
    np.testing.assert_allclose(plain[0, 0], [21.0, 37.0], atol=0.5)


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


def test_pose_arrays_maps_keypoints_back_through_the_letterbox():
    # a 100 x 60 image with a bright blob at (70.5, 20.5): letterboxed into 64 x 64 (scale
    # 0.64, 19 px bars above and below) and mapped back, the stand-in finds the blob there
    image = np.zeros((60, 100, 3))
    yy, xx = np.mgrid[0:60, 0:100] + 0.5
    image[..., 0] = np.exp(-((xx - 70.5) ** 2 + (yy - 20.5) ** 2) / (2 * 6.0**2))
    (res,) = pose_arrays(_Blob(1), [image], input_size=(64, 64))
    np.testing.assert_allclose(res.keypoints[0], [70.5, 20.5], atol=1.5)
    # the heatmap is cut to the image's part of the letterbox: 16 cells wide, 10 high
    assert res.heatmaps is not None and res.heatmaps.shape == (1, 10, 16)
    with pytest.raises(InputError, match="at least 8 x 8"):
        pose_arrays(_Blob(1), [np.zeros((5, 40, 3))])
    with pytest.raises(InputError, match=r"\(H, W\) or \(H, W, 3\)"):
        pose_arrays(_Blob(1), [np.zeros((3, 40, 40))])


def test_no_labelled_joint_gives_a_zero_loss_and_no_pck():
    from robopercept.nn.pose.metrics import pck

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


def test_heatmap_losses_by_hand():
    target, weight = gaussian_heatmaps([[[6.0, 6.0, 2], [1.0, 1.0, 0]]], (16, 16), 4, 1.0)
    flat = torch.zeros(1, 2, 4, 4)
    # a flat map is the uniform distribution over 16 cells: cross entropy log 16 for the
    # one labelled joint, whatever the target's shape
    assert float(heatmap_loss(flat, target, weight, "softmax")) == pytest.approx(np.log(16))
    # MSE: the mean over cells of the target squared, averaged over the N J = 2 maps
    expected = float((target[0, 0] ** 2).mean()) / 2
    assert float(heatmap_loss(flat, target, weight, "mse")) == pytest.approx(expected)
    with pytest.raises(InputError, match=r"\(N, J, h, w\)"):
        heatmap_loss(flat, target[:, :1], weight)
