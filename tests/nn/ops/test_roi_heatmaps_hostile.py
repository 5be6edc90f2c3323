"""Issue 47 R50, R52, R53: roi_align with huge finite boxes, the heatmap codec's
arguments, decoding an empty batch."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.heatmaps import (  # noqa: E402
    check_image_size,
    check_permutation,
    decode_heatmaps,
    flip_heatmaps,
    gaussian_heatmaps,
    heatmap_loss,
    heatmap_probabilities,
    keypoint_tensor,
)
from robopercept.nn.ops.roi import RoIAlign, roi_align  # noqa: E402


# ------------------------------------------------------------------ R50 roi_align
def _features() -> torch.Tensor:
    return torch.from_numpy(np.random.default_rng(3).normal(size=(2, 3, 8, 9)))


@pytest.mark.parametrize("ratio", [-1, 0, 2])
@pytest.mark.parametrize("aligned", [False, True])
def test_roi_align_boxes_far_outside_give_zeros(ratio, aligned):
    # before: int64 overflow of the sample positions, torch "index ... out of bounds"
    x = _features()
    far = torch.tensor(
        [[0, 1e31, 1e31, 2e31, 2e31], [1, -2e31, 2.0, -1e31, 5.0], [0, 1.0, 1e30, 4.0, 3e30]],
        dtype=torch.float64,
    )
    out = roi_align(x, far, (2, 3), 1.0, ratio, aligned)
    assert out.shape == (3, 3, 2, 3)
    assert torch.equal(out, torch.zeros_like(out))


@pytest.mark.parametrize("aligned", [False, True])
def test_roi_align_huge_boxes_do_not_disturb_the_others(aligned):
    x = _features()
    normal = torch.tensor([[0, 1.0, 1.5, 6.0, 7.0], [1, 0.5, 0.0, 8.0, 5.0]], dtype=torch.float64)
    huge = torch.tensor(
        [[0, -1e31, -1e31, 1e31, 1e31], [1, 0.0, 0.0, 1e31, 1e31]], dtype=torch.float64
    )
    alone = roi_align(x, normal, 2, 0.5, 2, aligned)
    mixed = roi_align(
        x, torch.cat([huge[:1], normal[:1], huge[1:], normal[1:]]), 2, 0.5, 2, aligned
    )
    # the same samples and weights; torch's vectorized sums may group them by the batch's
    # size (on this AMD EPYC the RoIs alone and in the mixed batch differ by 1-2 units in
    # the last place, where an Intel machine gave equal bits): a huge box that disturbed
    # them would move them by far more than 1e-12
    torch.testing.assert_close(mixed[[1, 3]], alone, rtol=0, atol=1e-12)
    # samples at -0.5e31, +0.5e31 (and 2.5e30 ... 7.5e30): all beyond the map: 0, as
    # torchvision's bilinear_interpolate gives for y > height before any int conversion
    assert torch.equal(mixed[[0, 2]], torch.zeros_like(mixed[[0, 2]]))


def test_roi_align_huge_box_sampled_inside_the_map_by_hand():
    # a y-range of [-1e31, 1e31] with one bin and one sample: the sample is at exactly
    # y = -1e31 + 0.5 * 2e31 = 0; x-range [1, 3]: the sample at x = 2; so feature (0, 2)
    x = _features()
    box = torch.tensor([[1, 1.0, -1e31, 3.0, 1e31]], dtype=torch.float64)
    out = roi_align(x, box, 1, 1.0, 1, False)
    torch.testing.assert_close(out[0, :, 0, 0], x[1, :, 0, 2], rtol=0, atol=0)
    assert torch.equal(RoIAlign(1, 1.0, 1)(x, box), out)


def test_roi_align_huge_box_adaptive_sampling_and_overflow_are_input_errors():
    x = _features()
    huge = torch.tensor([[0, 0.0, 0.0, 1e31, 1e31]], dtype=torch.float64)
    with pytest.raises(InputError, match="positive sampling_ratio"):
        roi_align(x, huge, 2)  # adaptive: 5e30 samples per bin side
    # boxes whose scaled coordinates or sides would overflow float64
    for box in ([0, 0.0, 0.0, 1e308, 1e308], [0, -1.7e308, 0.0, 1.7e308, 4.0]):
        with pytest.raises(InputError, match=r"finite|overflow"):
            roi_align(x, torch.tensor([box], dtype=torch.float64), 2, 100.0, 2)


# ------------------------------------------------------------------ R52 heatmap arguments
@pytest.mark.parametrize(
    ("stride", "match"),
    [
        (0, r"stride .* must be >= 1; got 0"),
        (None, r"stride .* must be an integer; got None"),
        ("4", "must be an integer"),
        (2.5, "must be an integer"),
        (True, "must be an integer"),
        (1 << 16, "at most 32768"),
    ],
)
def test_gaussian_heatmaps_bad_stride(stride, match):
    # before: ZeroDivisionError (0) and TypeError (None, "4") in check_image_size
    with pytest.raises(InputError, match=match):
        gaussian_heatmaps([[[6.0, 2.0, 2]]], (8, 8), stride=stride)
    with pytest.raises(InputError, match=match):
        check_image_size((8, 8), stride)
    with pytest.raises(InputError, match=match):
        decode_heatmaps(torch.zeros(1, 1, 2, 2), stride=stride)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"keypoints": [[["a", 1, 2]]]}, "must be numbers"),
        ({"keypoints": [[[1.0, 2.0]], [[1.0]]]}, "must be numbers"),
        ({"keypoints": [[[None, 1.0, 2.0]]]}, "must be numbers"),
        ({"keypoints": np.zeros((2, 3))}, r"\(N, J, 3\)"),
        ({"image_size": 8}, "image_size must be"),
        ({"image_size": (8, 6)}, "multiple of the stride"),
        ({"sigma": 0.0}, "sigma"),
        ({"sigma": None}, "sigma"),
        ({"image_size": (32768, 32768), "stride": 1}, "heatmaps would take"),
    ],
)
def test_gaussian_heatmaps_bad_arguments(kwargs, match):
    args = {"keypoints": [[[6.0, 2.0, 2]]], "image_size": (8, 8), "stride": 4, "sigma": 2.0}
    with pytest.raises(InputError, match=match):
        gaussian_heatmaps(**{**args, **kwargs})


def test_heatmap_helpers_refuse_bad_arguments():
    maps = torch.rand(1, 2, 3, 4)
    with pytest.raises(InputError, match="must be numbers"):
        keypoint_tensor(object())
    with pytest.raises(InputError, match="permutation of the 2 joints"):
        check_permutation([float("inf"), 0], 2)
    with pytest.raises(InputError, match="permutation of the 2 joints"):
        check_permutation([2**70, 0], 2)
    with pytest.raises(InputError, match="number of joints"):
        check_permutation([1, 0], np.zeros(2))
    with pytest.raises(InputError, match="permutation of the 2 joints"):
        flip_heatmaps(maps, torch.tensor([0, 2]))
    with pytest.raises(InputError, match="maps must be a float"):
        flip_heatmaps(maps.numpy(), [1, 0])
    with pytest.raises(InputError, match="maps must be a float"):
        heatmap_probabilities([[1.0]], "softmax")
    with pytest.raises(InputError, match="kind must be"):
        heatmap_probabilities(maps, None)
    with pytest.raises(InputError, match="h, w >= 1"):
        heatmap_loss(torch.zeros(1, 2, 0, 4), torch.zeros(1, 2, 0, 4), torch.ones(1, 2))
    with pytest.raises(InputError, match="heatmaps must be a tensor or array of real"):
        decode_heatmaps([[["a"]]])
    with pytest.raises(InputError, match="must be real"):
        decode_heatmaps(torch.zeros(1, 1, 2, 2, dtype=torch.complex64))
    with pytest.raises(InputError, match="beta"):
        decode_heatmaps(maps, method="soft-argmax", beta=None)
    with pytest.raises(InputError, match="method"):
        decode_heatmaps(maps, method=["quadratic"])
    # what still works: the flip of a permutation given as a list, on any device
    assert torch.equal(flip_heatmaps(maps, [1, 0]), maps.flip(-1)[:, [1, 0]])


# ------------------------------------------------------------------ R53 empty batches
@pytest.mark.parametrize("method", ["quadratic", "quarter", "soft-argmax"])
@pytest.mark.parametrize("shape", [(0, 3, 4, 5), (2, 0, 4, 5), (0, 0, 1, 1)])
def test_decode_heatmaps_of_an_empty_batch(method, shape):
    # before: torch's "cannot reshape tensor of 0 elements" RuntimeError
    kp, score = decode_heatmaps(torch.zeros(shape), stride=4, method=method)
    assert kp.shape == (*shape[:2], 2) and score.shape == shape[:2]
    assert kp.dtype == np.float64 and score.dtype == np.float64
    kp2, _ = decode_heatmaps(np.zeros(shape, np.float32), stride=4, method=method)
    assert kp2.shape == (*shape[:2], 2)


def test_empty_batches_through_the_codec():
    hm, w = gaussian_heatmaps(np.zeros((0, 3, 3)), (16, 8), stride=4)
    assert hm.shape == (0, 3, 2, 4) and w.shape == (0, 3)
    assert heatmap_probabilities(torch.zeros(0, 3, 2, 4), "softmax").shape == (0, 3, 2, 4)
    for kind in ("mse", "softmax"):
        loss = heatmap_loss(hm, hm, w, kind)
        assert float(loss) == 0.0  # not NaN, the mean of nothing
    kp, score = decode_heatmaps(hm)
    assert kp.shape == (0, 3, 2) and score.shape == (0, 3)
