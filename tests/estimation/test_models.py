"""The building blocks of the homography model: Hartley normalization and the normalized
DLT (hand cases, exact recovery, parity with cv2.findHomography, batches)."""

from __future__ import annotations

import cv2
import numpy as np

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
