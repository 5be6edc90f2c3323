"""Running pose networks on images (issue 28): the flip test and the letterbox of
whole images."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError
from robopercept.nn.ops.heatmaps import gaussian_heatmaps
from robopercept.nn.pose.inference import pose_arrays, predict_keypoints


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


def test_predict_heatmaps_on_no_images_gives_empty_results():
    # fuzz finding N1: a batch of 0 images gave numpy's "need at least one array"
    from robopercept.nn.pose.inference import predict_heatmaps

    kp, sc, hm = predict_heatmaps(_Blob(2), np.zeros((0, 32, 32, 3)))
    assert kp.shape == (0, 2, 2) and sc.shape == (0, 2)
    assert hm is not None and hm.shape == (0, 2, 8, 8)
    kp, sc = predict_keypoints(_Blob(2), np.zeros((0, 32, 32, 3)), flip_permutation=[1, 0])
    assert kp.shape == (0, 2, 2) and sc.shape == (0, 2)
