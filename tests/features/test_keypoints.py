"""The Keypoints record: column checks on construction (issue 25)."""

from __future__ import annotations

from dataclasses import FrozenInstanceError

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.features import Keypoints
from robopercept.features.keypoints import KeyPoint


def _cols(n: int) -> tuple[np.ndarray, ...]:
    return np.ones(n), np.zeros(n), np.ones(n), np.zeros(n, dtype=np.int64)


# issue 25: xy of shape (7, 3) reached NumPy's reshape (ValueError), a NaN octave its
# int conversion; both are InputErrors naming the column
@pytest.mark.parametrize(
    ("xy", "cols", "match"),
    [
        (np.ones((7, 3)), _cols(7), r"Keypoints.xy must be \(N, 2\)"),
        (np.ones((4,)), _cols(2), r"Keypoints.xy must be \(N, 2\)"),
        ([["a", "b"]], _cols(1), "Keypoints.xy must hold real numbers"),
        (np.ones((2, 2)), _cols(3), "Keypoints.scale has 3 entries for 2 points"),
        (np.ones((1, 2)), (*_cols(1)[:3], [np.nan]), "Keypoints.octave must hold integers"),
        (np.ones((1, 2)), (*_cols(1)[:3], [0.5]), "Keypoints.octave must hold integers"),
    ],
)
def test_issue25_bad_columns_are_input_errors(xy, cols, match):
    with pytest.raises(InputError, match=match):
        Keypoints(xy, *cols)


def test_valid_columns_are_kept():
    k = Keypoints([3.0, 4.0], [2.0], [np.nan], [0.5], [1.0])  # one keypoint as (2,)
    assert len(k) == 1 and k.xy.tolist() == [[3.0, 4.0]]
    assert k.octave.dtype == np.int64 and k.octave.tolist() == [1]
    assert np.isnan(k.orientation[0])  # NaN orientation: none assigned (corners)
    assert len(Keypoints.empty()) == 0 and len(k.select(np.array([True]))) == 1


# issue 48: keypoints index and iterate as OpenCV's tuple of cv2.KeyPoint
def _three() -> Keypoints:
    return Keypoints(
        [[3.0, 4.0], [5.5, 1.25], [7.0, 8.0]],
        [2.0, 3.0, 4.0],
        [np.pi / 2, np.nan, -np.pi / 4],
        [0.5, 0.25, 0.125],
        [-1, 0, 2],
    )


def test_index_gives_a_cv2_keypoint_like_record():
    kp = _three()
    k = kp[0]
    assert isinstance(k, KeyPoint)
    assert k.pt == (3.0, 4.0) and isinstance(k.pt[0], float)
    assert (k.size, k.response, k.octave) == (2.0, 0.5, -1)
    assert k.angle == pytest.approx(90.0)  # degrees, as cv2.KeyPoint.angle
    assert kp[1].angle == -1.0  # none assigned: OpenCV's "not applicable"
    assert kp[2].angle == pytest.approx(315.0)  # [0, 360) as OpenCV's
    assert kp[-1].pt == (7.0, 8.0)
    with pytest.raises(FrozenInstanceError):
        k.angle = 1.0  # type: ignore[misc]
    # the columns keep radians
    assert kp.orientation[0] == pytest.approx(np.pi / 2)


def test_iteration_slices_and_masks():
    kp = _three()
    assert [k.pt for k in kp] == [(3.0, 4.0), (5.5, 1.25), (7.0, 8.0)]
    assert len(list(kp)) == len(kp) == 3
    sub = kp[1:]
    assert isinstance(sub, Keypoints) and sub.xy.tolist() == [[5.5, 1.25], [7.0, 8.0]]
    assert kp[np.array([True, False, True])].scale.tolist() == [2.0, 4.0]
    assert kp[[2, 0]].octave.tolist() == [2, -1]
    assert len(Keypoints.empty()[:]) == 0 and list(Keypoints.empty()) == []


@pytest.mark.parametrize(
    ("index", "error", "match"),
    [
        (3, IndexError, "out of range"),
        (-4, IndexError, "out of range"),
        ("a", InputError, "index keypoints with an integer"),
        (1.5, InputError, "index keypoints with an integer"),
        (np.array([True, False]), InputError, "boolean mask of length 3"),
        ([5], InputError, r"keypoint indices must be in -3..2"),
    ],
)
def test_bad_indices(index, error, match):
    with pytest.raises(error, match=match):
        _three()[index]


def test_harris_corners_index_the_same_way():
    from robopercept.features import harris_corners

    img = np.zeros((40, 40), np.uint8)
    img[10:30, 10:30] = 200
    kp = harris_corners(img)
    assert len(kp) >= 4
    assert kp[0].pt == tuple(kp.xy[0].tolist()) and kp[0].angle == -1.0
