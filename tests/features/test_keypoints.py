"""The Keypoints record: column checks on construction (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.features import Keypoints


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
