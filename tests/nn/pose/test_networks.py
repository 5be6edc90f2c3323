"""Pose networks (issue 28): window crops, the three networks and their refusals."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError
from robopercept.nn.ops.roi import roi_align
from robopercept.nn.pose.inference import predict_keypoints
from robopercept.nn.pose.networks import (
    DeepPose,
    HRNet,
    SimpleBaseline,
    build_pose_model,
    crop_patches,
)


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
