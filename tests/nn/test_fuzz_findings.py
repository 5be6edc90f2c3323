"""Regression tests of the API fuzz campaign's nn findings (issue 47: N3-N6): hostile
arguments give typed robopercept errors, never torch's or numpy's own."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from robopercept.errors import InputError

BAD_DTYPES = [torch.int64, torch.bool, torch.float16, torch.float64]


@pytest.mark.parametrize("dtype", BAD_DTYPES)
def test_lifting_mlp_refuses_another_dtype(dtype):
    from robopercept.nn.pose.lifting import LiftingMLP

    net = LiftingMLP(num_joints=4, width=8, blocks=1, root=0)
    with pytest.raises(InputError, match=r"floating point|weights are torch.float32"):
        net(torch.zeros(2, 8, dtype=dtype))


@pytest.mark.parametrize("dtype", BAD_DTYPES)
def test_masked_batch_norm_refuses_another_dtype(dtype):
    from robopercept.nn.cloud.pointnet import MaskedBatchNorm

    with pytest.raises(InputError, match=r"floating point|weights are torch.float32"):
        MaskedBatchNorm(3)(torch.zeros(2, 5, 3, dtype=dtype))


@pytest.mark.parametrize("dtype", BAD_DTYPES)
def test_region_proposal_network_refuses_another_dtype(dtype):
    from robopercept.nn.detection.rpn import RegionProposalNetwork
    from robopercept.nn.ops.anchors import AnchorGenerator

    rpn = RegionProposalNetwork(4, AnchorGenerator(((8.0,),), ((1.0,),))).eval()
    with pytest.raises(InputError, match=r"float|weights are torch.float32"):
        rpn(torch.zeros(1, 4, 4, 4, dtype=dtype), (32, 32), [(32, 32)])


@pytest.mark.parametrize("name", ["UNet", "FCN", "NaiveFCN"])
@pytest.mark.parametrize("dtype", BAD_DTYPES)
def test_segmentation_networks_refuse_another_dtype(name, dtype):
    from robopercept.nn.segmentation import networks

    net = getattr(networks, name)(2)
    with pytest.raises(InputError, match=r"floating point|weights are torch.float32"):
        net(torch.zeros(1, 3, 32, 32, dtype=dtype))


def test_naive_fcn_refuses_one_pixel_training_batch_and_runs_it_in_eval():
    from robopercept.nn.segmentation.networks import NaiveFCN

    net = NaiveFCN(2, depth=1)
    with pytest.raises(InputError, match="too small to train on"):
        net(torch.zeros(1, 3, 1, 1))
    assert net.eval()(torch.zeros(1, 3, 1, 1)).shape == (1, 2, 1, 1)


def test_dice_loss_refuses_integer_logits():
    from robopercept.nn.segmentation.networks import dice_loss

    target = torch.zeros(1, 4, 4, dtype=torch.int64)
    with pytest.raises(InputError, match="logits must be floating point"):
        dice_loss(torch.zeros(1, 2, 4, 4, dtype=torch.int64), target)


@pytest.mark.parametrize("shape", [(1, 1, 1), (1, 5, 8), (3, 7, 7)])
def test_model_summary_refuses_an_image_too_small_for_the_pools(shape):
    from robopercept.nn.classification.run import model_summary

    with pytest.raises(InputError, match=r"--input .*at least 8 px per side"):
        model_summary("vgg_small", shape, 10)


@pytest.mark.parametrize("shape", [(1, 8), (1, 0, 8), (1.5, 8, 8), ("1", 8, 8), (True, 8, 8)])
def test_model_summary_refuses_a_shape_that_is_not_three_positive_ints(shape):
    from robopercept.nn.classification.run import model_summary

    with pytest.raises(InputError, match="three positive integers"):
        model_summary("vgg_small", shape, 10)


def test_nn_summary_too_small_input_exits_1_naming_the_flag(capsys):
    from robopercept.cli.main import main

    assert main(["nn", "summary", "vgg_small", "--input", "1,1,1"]) == 1
    assert "--input 1,8,8" in capsys.readouterr().err
    assert main(["nn", "summary", "resnet_small", "--input", "1,1,1"]) == 0


# ------------------------------------------------------------------------- N5: arguments


@pytest.mark.parametrize("root", [float("inf"), float("nan"), 1.5])
def test_skeleton_parents_refuses_a_non_integer_root(root):
    from robopercept.nn.skeleton import MPII_16

    with pytest.raises(InputError, match="root must be an integer"):
        MPII_16.parents(root=root)


def test_domain_line_refuses_a_number_for_the_model():
    from robopercept.nn.shipped import domain_line

    with pytest.raises(InputError, match="model must be a shipped name"):
        domain_line("detect", float("nan"))


@pytest.mark.parametrize("value", [np.zeros(3), {1, 2}, {"a": object()}])
def test_write_json_refuses_values_that_are_not_json_and_writes_nothing(tmp_path, value):
    from robopercept.nn.train.runs import write_json

    with pytest.raises(InputError, match="value must be JSON data"):
        write_json(tmp_path / "x.json", value)
    assert list(tmp_path.iterdir()) == []


def test_write_json_refuses_a_value_that_holds_itself(tmp_path):
    from robopercept.nn.train.runs import write_json

    loop: list = []
    loop.append(loop)
    with pytest.raises(InputError, match="levels deep"):
        write_json(tmp_path / "x.json", loop)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"device": "gpu"}, "device must be"),
        ({"device": -1}, "device must be"),
        ({"dtype": torch.int64}, "floating-point torch.dtype"),
        ({"dtype": "float32"}, "floating-point torch.dtype"),
        ({"num_features": float("nan")}, "num_features must be an integer"),
        ({"eps": -1.0}, "eps"),
        ({"momentum": 2.0}, "momentum"),
    ],
)
def test_sync_batch_norm_checks_its_arguments(kwargs, match):
    from robopercept.nn.train.distributed import SyncBatchNorm

    args = {"num_features": 3, **kwargs}
    with pytest.raises(InputError, match=match):
        SyncBatchNorm(**args)
    assert SyncBatchNorm(3, momentum=None, dtype=torch.float64).weight.dtype == torch.float64


def _cal():
    return {"score_thresh": 0.4, "match_median": 0.7}


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda th: th.f1_threshold(np.ones(2), np.ones(2, bool), None), "positives"),
        (lambda th: th.f1_threshold(["a", "b"], np.ones(2, bool), 2), "scores must hold"),
        (lambda th: th.f1_threshold([np.nan, 1.0], np.ones(2, bool), 2), "NaN"),
        (lambda th: th.domain_warning(None, _cal(), "m", "x"), "best must be a real"),
        (lambda th: th.domain_warning(0.3, {"score_thresh": None}, "m", "x"), "score_thresh"),
        (lambda th: th.domain_warning(0.3, {"match_median": 1.0}, "m", "x"), "score_thresh"),
        (lambda th: th.domain_warning(0.3, [1], "m", "x"), "calibration must be a dict"),
        (lambda th: th.choose_score_threshold(None, []), "detections must be a list"),
        (lambda th: th.choose_score_threshold([{}], [{}]), r"detections\[0\] must be a dict"),
        (
            lambda th: th.choose_score_threshold(
                [{"boxes": [[0, 0, 1, 1]], "labels": [1], "scores": [0.5, 0.2]}],
                [{"boxes": [[0, 0, 1, 1]], "labels": [1]}],
            ),
            "one label and one score per box",
        ),
        (
            lambda th: th.choose_score_threshold(
                [{"boxes": [[0, 0, 1]], "labels": [1], "scores": [0.5]}],
                [{"boxes": [[0, 0, 1, 1]], "labels": [1]}],
            ),
            r"must be \(D, 4\)",
        ),
    ],
)
def test_thresholds_refuse_hostile_arguments(call, match):
    from robopercept.nn.detection import thresholds

    with pytest.raises(InputError, match=match):
        call(thresholds)


def test_pose_dataset_split_refuses_complex_and_nan_fractions():
    from robopercept.nn.pose.data import procedural_pose_set

    ds = procedural_pose_set(2, (32, 32), rng=0)
    with pytest.raises(InputError, match="real numbers"):
        ds.split((0.5 + 1j, 0.5))
    with pytest.raises(InputError, match="sum to 1"):
        ds.split((np.nan, 1.0))


@pytest.mark.parametrize("refiners", [3, None, "stage"])
def test_refine_keypoints_refuses_refiners_that_are_not_a_list(refiners):
    from robopercept.nn.pose.inference import refine_keypoints

    with pytest.raises(InputError, match="refiners must be a list"):
        refine_keypoints(np.zeros((1, 32, 32, 3)), np.full((1, 16, 2), 16.0), refiners)


def test_part_ious_refuses_ragged_labels():
    from robopercept.nn.cloud.train import part_ious

    with pytest.raises(InputError, match="numeric array"):
        part_ious([[0, 1], [0]], [[0, 1], [0, 1]], [0, 0], [0, 0])


@pytest.mark.parametrize("data", [[1, 2], np.zeros(2), None])
def test_cloud_sets_refuses_data_that_is_neither_a_name_nor_a_folder(data):
    from robopercept.nn.cloud.run import cloud_sets

    with pytest.raises(InputError, match="data must be shapes"):
        cloud_sets(data, shapes=1, n_points=8)


# ------------------------------------------------------------------------- N6: sizes


@pytest.mark.parametrize("length", [2**40, 2**63])
def test_tile_origins_bounds_the_image_side(length):
    from robopercept.nn.detection.tiling import MAX_TILED_SIDE, tile_origins

    with pytest.raises(InputError, match=f"at most {MAX_TILED_SIDE}"):
        tile_origins(length, 400, 100)
    assert tile_origins(MAX_TILED_SIDE, MAX_TILED_SIDE, 0) == [0]


def test_default_pose_library_bounds_its_size():
    from robopercept.nn.pose.library import default_pose_library

    with pytest.raises(InputError, match="the limit is 1 GiB"):
        default_pose_library(poses=2**40)
    with pytest.raises(InputError, match="the limit is 1 GiB"):
        default_pose_library(poses=2000, views_per_pose=2**30)


def test_epoch_loop_bounds_the_sample_count():
    from robopercept.nn.train.config import TrainConfig
    from robopercept.nn.train.loop import epoch_loop

    net = torch.nn.Linear(2, 1)
    with pytest.raises(InputError, match="the limit is 1 GiB"):
        epoch_loop(
            net,
            300_000_000_000,
            TrainConfig(),
            torch.Generator(),
            lambda i: None,
            None,
            desc="x",
            progress=False,
        )


def test_padded_class_maps_bounds_the_canvas():
    from robopercept.nn.segmentation.data import segmentation_sets
    from robopercept.nn.segmentation.run import padded_class_maps

    ds = segmentation_sets("shapes", 3, (32, 32), 0).val
    with pytest.raises(InputError, match="the limit is 1 GiB: give a smaller canvas"):
        padded_class_maps(ds, (2**40, 2**40))
    assert padded_class_maps(ds, (40, 40))[1].shape == (len(ds), 40, 40)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"alpha": None}, "alpha must be a real"),
        ({"refiners": 3}, "refiners must be a list"),
        ({"refiners": [3]}, "refiners must be a list"),
    ],
)
def test_joint_threshold_refuses_hostile_arguments(kwargs, match):
    from robopercept.nn.pose.data import procedural_pose_set
    from robopercept.nn.pose.evaluate import joint_threshold
    from robopercept.nn.pose.networks import SimpleBaseline

    with pytest.raises(InputError, match=match):
        joint_threshold(SimpleBaseline(16, 2), procedural_pose_set(2, (32, 32), rng=0), **kwargs)


@pytest.mark.parametrize("skeleton", [float("nan"), "mpii16"])
def test_train_pose_refuses_a_skeleton_that_is_not_one(skeleton):
    from robopercept.nn.pose.data import procedural_pose_set
    from robopercept.nn.pose.networks import SimpleBaseline
    from robopercept.nn.pose.train import train_pose

    ds = procedural_pose_set(2, (32, 32), rng=0)
    with pytest.raises(InputError, match="skeleton must be a Skeleton"):
        train_pose(SimpleBaseline(16, 2), ds, skeleton=skeleton, progress=False)


def test_cloud_evaluate_run_refuses_an_out_dir_that_is_a_file(tmp_path):
    from robopercept.nn.cloud.run import evaluate_run

    out = tmp_path / "taken"
    out.write_text("x")
    with pytest.raises(InputError, match=r"-o/--out .* is a file; give a folder"):
        evaluate_run(tmp_path / "model.pt", "shapes", shapes=1, n_points=8, out_dir=out)


def test_rpn_refuses_a_feature_map_without_cells():
    # make fuzz (issue 47): a (2, 4, 2, 0) map reached torch's conv "kernel size can't
    # be greater than actual input size"
    from robopercept.nn.detection.rpn import RegionProposalNetwork
    from robopercept.nn.ops.anchors import AnchorGenerator

    rpn = RegionProposalNetwork(4, AnchorGenerator(((8.0,),), ((1.0,),))).eval()
    with pytest.raises(InputError, match="at least one cell"):
        rpn(torch.zeros(2, 4, 2, 0), (16, 16), [(16, 16), (16, 16)])


def test_hostile_titles_and_stereo_lists_are_input_errors():
    # make fuzz (issue 47): panels_picture(titles=None) and find_board_pairs(right=None)
    from robopercept.calibration import find_board_pairs
    from robopercept.viz.segmentation import panels_picture

    pic = np.zeros((8, 8, 3), np.uint8)
    for bad in (None, float("nan"), "ab"):
        with pytest.raises(InputError, match="titles must be a list"):
            panels_picture([pic, pic], bad)
    with pytest.raises(InputError, match="left and right must be sequences"):
        find_board_pairs([pic], None, (3, 4))


def test_disparity_picture_checks_its_numbers():
    # the API rerun after make fuzz (issue 47): min_disparity=[1, 2] raised TypeError
    from robopercept.viz import disparity_picture

    d = np.tile(np.linspace(0.0, 16.0, 40), (30, 1))
    for kw in ({"min_disparity": [1, 2]}, {"max_disparity": "x"}, {"lr_check": [1]}):
        with pytest.raises(InputError):
            disparity_picture(d, **kw)
    assert disparity_picture(d, max_disparity=16, lr_check=1.0).shape == (877, 1280, 3)


def test_class_overlay_and_panels_check_their_arguments():
    # the second API rerun (seed 1) after make fuzz (issue 47)
    from robopercept.viz.segmentation import class_overlay, panels_picture

    img = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(InputError, match="ignore_index"):
        class_overlay(img, np.zeros((8, 8), int), ["bg"], ignore_index=[1, 2])
    for bad in (None, 3, img):
        with pytest.raises(InputError, match="pictures must be a list"):
            panels_picture(bad, ["a"])


def test_nms_takes_bfloat16_boxes_as_the_float32_ones():
    # the fifth fuzz campaign: NumPy has no bfloat16, and nms raised torch's TypeError
    from robopercept.nn.ops.nms import batched_nms, nms

    b = torch.tensor([[0.0, 0, 10, 10], [1, 0, 11, 10], [20, 20, 30, 30]])
    s = torch.tensor([0.9, 0.95, 0.5])
    assert nms(b.bfloat16(), s, 0.5).tolist() == nms(b, s, 0.5).tolist() == [1, 2]
    ids = torch.tensor([0, 1, 0])
    assert batched_nms(b.bfloat16(), s, ids, 0.5).tolist() == [1, 0, 2]
