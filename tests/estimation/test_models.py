"""The building blocks of the homography model: Hartley normalization and the normalized
DLT (hand cases, exact recovery, parity with cv2.findHomography, batches)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from robopercept.errors import DegenerateError, InputError
from robopercept.estimation import AffineModel, HomographyModel
from robopercept.estimation.models import hartley_normalization, homography_dlt

H = np.array([[1.1, 0.05, 30.0], [-0.08, 0.95, -12.0], [2e-4, -1e-4, 1.0]])


def _map(h, xy):
    p = xy @ h[:2, :2].T + h[:2, 2]
    return p / (xy @ h[2, :2] + h[2, 2])[:, None]


class TestHartleyNormalization:
    def test_hand_case(self):
        # centroid (1, 2), mean distance 1: s = sqrt(2), t = -s c
        T = hartley_normalization(np.array([[[0.0, 2.0], [2.0, 2.0]]]))
        r2 = np.sqrt(2.0)
        np.testing.assert_allclose(T[0], [[r2, 0, -r2], [0, r2, -2 * r2], [0, 0, 1]])

    def test_centroid_and_mean_distance(self):
        rng = np.random.default_rng(0)
        xy = rng.uniform(0, 640, (3, 50, 2))
        T = hartley_normalization(xy)
        assert T.shape == (3, 3, 3)
        q = xy @ T[:, :2, :2].transpose(0, 2, 1) + T[:, None, :2, 2]
        np.testing.assert_allclose(q.mean(axis=1), 0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(q, axis=2).mean(axis=1), np.sqrt(2))


class TestHomographyDlt:
    def test_exact_recovery_minimal_and_overdetermined(self):
        rng = np.random.default_rng(1)
        for n in (4, 30):
            src = rng.uniform(0, 640, (n, 2))
            h = homography_dlt(src[None], _map(H, src)[None])
            assert h.shape == (1, 3, 3)
            np.testing.assert_allclose(h[0], H, rtol=1e-8, atol=1e-10)

    def test_batch_equals_one_at_a_time(self):
        rng = np.random.default_rng(2)
        src = rng.uniform(0, 640, (5, 8, 2))
        dst = np.stack([_map(H, s) for s in src]) + rng.normal(0, 0.5, src.shape)
        batch = homography_dlt(src, dst)
        for i in range(5):
            np.testing.assert_allclose(batch[i], homography_dlt(src[i : i + 1], dst[i : i + 1])[0])

    def test_matches_opencv_least_squares(self):
        # cv2.findHomography(method=0) polishes the same DLT by Levenberg-Marquardt on the
        # transfer error; with 0.3 px noise the two maps agree to ~0.1 px over the image
        rng = np.random.default_rng(3)
        src = rng.uniform(0, 640, (200, 2))
        dst = _map(H, src) + rng.normal(0, 0.3, src.shape)
        ours = homography_dlt(src[None], dst[None])[0]
        ref, _ = cv2.findHomography(src, dst, 0)
        corners = np.array([[0, 0], [640, 0], [640, 640], [0, 640]], float)
        assert np.abs(_map(ours, corners) - _map(ref, corners)).max() < 0.1
        assert abs(ours[2, 2] - 1.0) < 1e-12


# issue 25: Model.fit on hostile data (a list, one column, NaN, values near 1e300, too
# few rows) raised TypeError, IndexError, ValueError or LinAlgError; it now raises an
# InputError (or a DegenerateError for too few rows) and still fits valid data
@pytest.mark.parametrize("model", [AffineModel(), HomographyModel()])
@pytest.mark.parametrize(
    ("data", "error", "match"),
    [
        ([], InputError, r"data must have shape \(N, 4\)"),
        (np.ones((4, 1)), InputError, r"data must have shape \(N, 4\)"),
        (np.ones((20, 2)), InputError, r"data must have shape \(N, 4\)"),
        (np.full((10, 4), np.nan), InputError, "data must be finite"),
        (np.full((10, 4), 1e300), InputError, "data has values up to 1e\\+300"),
        (np.ones((2, 4)), DegenerateError, "needs [34] rows"),
    ],
)
def test_issue25_fit_refuses_hostile_data(model, data, error, match):
    with pytest.raises(error, match=match):
        model.fit(data)


def test_issue25_fit_takes_lists_and_still_fits():
    gen = np.random.default_rng(3)
    src = gen.uniform(0, 100, (12, 2))
    A = np.array([[1.1, 0.2, 3.0], [-0.1, 0.9, -2.0]])
    dst = src @ A[:, :2].T + A[:, 2]
    data = np.c_[src, dst].tolist()  # a plain list of rows
    np.testing.assert_allclose(AffineModel().fit(data).reshape(2, 3), A, atol=1e-9)
    H = HomographyModel().fit(np.asfortranarray(np.c_[src, dst].astype(np.float32)))
    np.testing.assert_allclose(H.reshape(3, 3)[:2], A, atol=1e-3)
