"""Hostile arguments of the segmentation, pose, point-cloud and prediction functions that
the API fuzzer found giving torch's RuntimeError, NotImplementedError or a TypeError
(issue 47's campaign on the nn functions): each is now an InputError that says what to
pass."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.cloud.train import build_cloud_model, predict_clouds  # noqa: E402
from robopercept.nn.pose.networks import crop_patches  # noqa: E402
from robopercept.nn.predict import ImagePrediction  # noqa: E402
from robopercept.nn.segmentation.networks import (  # noqa: E402
    FCN,
    NaiveFCN,
    UNet,
    coco_segmentation_results,
    segmentation_cross_entropy,
)

pytestmark = pytest.mark.usefixtures("torch_one_thread")

NETS = {
    "naive": lambda: NaiveFCN(3, depth=1, width=4),
    "fcn": lambda: FCN(3, "8s", width=4),
    "unet": lambda: UNet(3, width=4, depth=2),
}


@pytest.mark.parametrize("name", sorted(NETS))
def test_segmenters_refuse_another_dtype(name):
    net = NETS[name]().eval()
    with pytest.raises(InputError, match=r"float64 but the network's weights are torch\.float32"):
        net(torch.zeros(1, 3, 8, 8, dtype=torch.float64))


@pytest.mark.parametrize("name", sorted(NETS))
def test_segmenters_refuse_images_without_pixels(name):
    net = NETS[name]().eval()
    with pytest.raises(InputError, match="at least 1 x 1"):
        net(torch.zeros(2, 3, 8, 0))


def test_segmenters_still_run_their_own_dtype():
    assert NETS["unet"]().eval()(torch.zeros(1, 3, 8, 8)).shape == (1, 3, 8, 8)


def test_cross_entropy_refuses_boolean_logits():
    with pytest.raises(InputError, match="floating point"):
        segmentation_cross_entropy(
            torch.zeros(1, 3, 2, 2, dtype=torch.bool), torch.zeros(1, 2, 2, dtype=torch.long)
        )


@pytest.mark.parametrize("image_id", [[1, 2], "x", None, 2.5])
def test_coco_results_refuse_an_image_id_that_is_not_an_int(image_id):
    with pytest.raises(InputError, match="image_id"):
        coco_segmentation_results(image_id, labels=np.ones((2, 2), np.int64))


def test_crop_patches_refuses_images_without_pixels():
    with pytest.raises(InputError, match="at least 1 x 1"):
        crop_patches(torch.zeros(1, 1, 6, 0), torch.zeros(1, 1, 2), 2.0, 2)


@pytest.mark.parametrize(
    "category",
    [np.array([[2**70] * 3] * 3, dtype=object), ["a", "b"], [1.5, 2.0], [[1], [1, 2]], []],
)
def test_predict_clouds_refuses_categories_that_are_not_indices(category):
    net = build_cloud_model("pointnet", 2, task="segment", num_categories=3, width=0.125, seed=0)
    with pytest.raises(InputError, match="category"):
        predict_clouds(net, np.zeros((2, 16, 3), np.float32), category=category)


@pytest.mark.parametrize("out_dir", [None, 3, ["out"]])
def test_prediction_write_refuses_an_out_dir_that_is_not_a_path(out_dir):
    p = ImagePrediction(
        "detect",
        np.zeros((8, 8, 3), np.uint8),
        ["a"],
        {"boxes": np.zeros((0, 4)), "labels": np.zeros(0, int), "scores": np.zeros(0)},
    )
    with pytest.raises(InputError, match="out_dir"):
        p.write(out_dir, "x")
    with pytest.raises(InputError, match="stem"):
        p.write("/tmp", 3)
