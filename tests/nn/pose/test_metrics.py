"""2-D pose metrics (robopercept.nn.pose.metrics): PCK, PCKh and their normalizers.

Reference: mmpose's ``keypoint_pck_accuracy`` (mmpose/evaluation/functional/
keypoint_eval.py), which practitioners report PCK and PCKh with. mmpose is not a
dependency (it needs mmcv and mmengine), so :func:`mmpose_pck` below restates its
steps one by one: samples whose normalizer is 0 are masked out, the distance is
``|(pred - gt) / [L, L]|``, a joint is correct when that is strictly below the
threshold, the per-joint accuracy is -1 where no sample counts, and the average is the
mean of the others. mmpose keeps the distances in float32; the oracle keeps float64,
so the comparison is exact (inputs are drawn away from the threshold by more than
float32 rounding anyway).
"""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.coco.dataset import read_coco_json
from robopercept.nn.pose.metrics import (
    MPII_HEAD_SCALE,
    PckScores,
    bbox_diagonal,
    mpii_head_sizes,
    pck,
    pckh,
)
from robopercept.nn.skeleton import MPII_16
from tests.conftest import data_path


def mmpose_pck(pred, gt, mask, thr, norm):
    """mmpose's keypoint_pck_accuracy(pred, gt, mask, thr, norm_factor=[L, L] per
    sample), restated: returns (acc per joint with -1 for none, avg_acc, cnt)."""
    n, k, _ = pred.shape
    norm_factor = np.stack([norm, norm], axis=1).astype(np.float64)
    m = mask.copy() > 0
    m[np.where((norm_factor == 0).sum(1))[0], :] = False
    dist = np.full((n, k), -1.0)
    norm_factor[norm_factor <= 0] = 1e6
    dist[m] = np.linalg.norm(((pred - gt) / norm_factor[:, None, :])[m], axis=-1)
    acc = []
    for d in dist.T:
        valid = d != -1
        acc.append((d[valid] < thr).sum() / valid.sum() if valid.sum() else -1)
    acc = np.array(acc, dtype=np.float64)
    ok = acc[acc >= 0]
    return acc, (ok.mean() if ok.size else 0.0), ok.size


# ----------------------------------------------------------------------------- PCK


class TestPck:
    def test_hand_case(self):
        # 2 samples, 3 joints, L = 10 and 20, alpha 0.1: within 1 px and 2 px
        truth = np.zeros((2, 3, 2))
        pred = np.array(
            [
                [[0.5, 0.0], [0.0, 1.5], [3.0, 4.0]],  # 0.5 | 1.5 | 5 px  (limit 1)
                [[1.0, 1.0], [0.0, 1.9], [0.0, 2.5]],  # 1.41 | 1.9 | 2.5 (limit 2)
            ]
        )
        s = pck(pred, truth, None, 0.1, [10.0, 20.0])
        assert s.per_joint.tolist() == [1.0, 0.5, 0.0]
        assert s.correct.tolist() == [2, 1, 0] and s.counts.tolist() == [2, 2, 2]
        assert s.mean == pytest.approx(0.5) and s.pooled == pytest.approx(0.5)
        assert s.threshold == 0.1

    def test_strict_at_the_threshold(self):
        # 2 / 10 == 0.2 exactly: not correct (mmpose's "<"); a hair inside is
        truth = np.zeros((1, 2, 2))
        pred = np.array([[[2.0, 0.0], [np.nextafter(2.0, 0.0), 0.0]]])
        assert pck(pred, truth, None, 0.2, [10.0]).per_joint.tolist() == [0.0, 1.0]

    def test_invisible_joints_do_not_count(self):
        truth = np.array([[[0, 0, 2], [5, 5, 0], [9, 9, 1]]], dtype=float)
        pred = np.array([[[0.0, 0.0], [50.0, 50.0], [90.0, 90.0]]])
        s = pck(pred, truth, None, 0.5, [4.0])  # v = 0: joint 1 left out
        assert s.counts.tolist() == [1, 0, 1]
        assert s.per_joint[0] == 1.0 and np.isnan(s.per_joint[1]) and s.per_joint[2] == 0
        assert s.mean == 0.5  # over the joints that count
        # an explicit mask overrides v; with two columns every joint counts
        s = pck(pred, truth, [[1, 1, 0]], 0.5, [4.0])
        assert s.counts.tolist() == [1, 1, 0]
        assert pck(pred, truth[:, :, :2], None, 0.5, [4.0]).counts.tolist() == [1, 1, 1]
        none = pck(pred, truth, np.zeros((1, 3)), 0.5, [4.0])
        assert np.isnan(none.mean) and np.isnan(none.pooled) and none.counts.sum() == 0

    def test_nan_predictions_are_misses(self):
        truth = np.zeros((2, 2, 2))
        pred = np.array([[[np.nan, np.nan], [0.0, 0.0]], [[0.0, np.inf], [0.0, 0.0]]])
        s = pck(pred, truth, None, 0.5, [1.0, 1.0])
        assert s.counts.tolist() == [2, 2] and s.per_joint.tolist() == [0.0, 1.0]
        # the truth of an invisible joint may be NaN (nothing to compare)
        t = np.array([[[np.nan, np.nan, 0.0], [0.0, 0.0, 2.0]]])
        assert pck(np.zeros((1, 2, 2)), t, None, 0.5, [1.0]).counts.tolist() == [0, 1]

    def test_zero_normalizer_drops_the_sample(self):
        truth = np.zeros((2, 1, 2))
        pred = np.zeros((2, 1, 2))
        s = pck(pred, truth, None, 0.5, [0.0, 3.0])
        assert s.counts.tolist() == [1] and s.per_joint.tolist() == [1.0]

    @pytest.mark.parametrize("seed", [0, 1, 2, 3])
    def test_equals_mmpose_keypoint_pck_accuracy(self, seed):
        rng = np.random.default_rng(seed)
        n, k = 40, 16
        gt = rng.uniform(0, 200, (n, k, 2))
        pred = gt + rng.normal(0, 8, (n, k, 2))
        mask = rng.random((n, k)) < 0.8
        mask[:, 3] = False  # a joint that no sample counts
        norm = rng.uniform(20, 60, n)
        norm[:3] = 0.0  # samples left out
        for thr in (0.05, 0.1, 0.2, 0.5):
            acc, avg, cnt = mmpose_pck(pred, gt, mask, thr, norm)
            s = pck(pred, gt, mask, thr, norm)
            np.testing.assert_array_equal(np.where(np.isnan(s.per_joint), -1, s.per_joint), acc)
            assert s.mean == pytest.approx(avg, abs=1e-15)
            assert int(np.count_nonzero(s.counts)) == cnt

    def test_properties(self):
        rng = np.random.default_rng(4)
        gt = rng.uniform(0, 100, (20, 5, 2))
        pred = gt + rng.normal(0, 5, gt.shape)
        norm = bbox_diagonal(gt)
        base = pck(pred, gt, None, 0.1, norm)
        # translation of both, a common scale of everything, a permutation of samples
        t = np.array([30.0, -12.0])
        assert pck(pred + t, gt + t, None, 0.1, norm).per_joint.tolist() == pytest.approx(
            base.per_joint.tolist()
        )
        scaled = pck(pred * 4, gt * 4, None, 0.1, norm * 4)
        np.testing.assert_array_equal(scaled.correct, base.correct)
        p = rng.permutation(20)
        np.testing.assert_array_equal(pck(pred[p], gt[p], None, 0.1, norm[p]).correct, base.correct)
        # a larger threshold never finds fewer
        assert (pck(pred, gt, None, 0.3, norm).correct >= base.correct).all()
        assert pck(gt, gt, None, 1e-9, norm).pooled == 1.0

    def test_weighted_mean_as_mpii(self):
        s = PckScores.from_counts([9, 1, 5], [10, 2, 5], 0.5)
        assert s.weighted() == pytest.approx(15 / 17)  # = pooled
        assert s.weighted([0, 2]) == pytest.approx(14 / 15)
        assert s.mean == pytest.approx((0.9 + 0.5 + 1.0) / 3)
        # MPII's mean leaves out pelvis and thorax (6, 7 in MPII_16's order)
        assert MPII_16.joints[6:8] == ("pelvis", "thorax")
        with pytest.raises(InputError, match=r"joints must be indices 0\.\.2"):
            s.weighted([3])
        with pytest.raises(InputError, match="0 <= correct <= counts"):
            PckScores.from_counts([3], [2], 0.5)

    def test_bad_input(self):
        truth = np.zeros((2, 3, 3))
        pred = np.zeros((2, 3, 2))
        with pytest.raises(InputError, match=r"drop the score column, pred\[\.\.\., :2\]"):
            pck(np.zeros((2, 3, 3)), truth, None, 0.1, [1, 1])
        with pytest.raises(InputError, match="pred has fewer joints than truth"):
            pck(np.zeros((2, 2, 2)), truth, None, 0.1, [1, 1])
        with pytest.raises(InputError, match="pred has more joints than truth"):
            pck(np.zeros((2, 4, 2)), truth, None, 0.1, [1, 1])
        with pytest.raises(InputError, match=r"same samples and joints; got pred \(1, 3\)"):
            pck(np.zeros((1, 3, 2)), truth, None, 0.1, [1, 1])
        with pytest.raises(InputError, match=r"one pose\? pass pred\[None\]"):
            pck(np.zeros((3, 2)), truth, None, 0.1, [1, 1])
        with pytest.raises(InputError, match=r"truth must be \(N, J, 2 or 3\)"):
            pck(pred, np.zeros((2, 3, 4)), None, 0.1, [1, 1])
        with pytest.raises(InputError, match=r"visible must be \(N, J\) = \(2, 3\)"):
            pck(pred, truth, np.ones((2, 2)), 0.1, [1, 1])
        with pytest.raises(InputError, match=r"normalizer must be \(N,\) = \(2,\)"):
            pck(pred, truth, None, 0.1, [1, 1, 1])
        with pytest.raises(InputError, match="normalizer must be finite lengths >= 0"):
            pck(pred, truth, None, 0.1, [1, -1])
        with pytest.raises(InputError, match="threshold must be in"):
            pck(pred, truth, None, 0.0, [1, 1])
        t = truth.copy()
        t[1, 2] = [np.nan, 0.0, 2.0]
        with pytest.raises(InputError, match="truth of sample 1, joint 2 is not finite"):
            pck(pred, t, None, 0.1, [1, 1])
        with pytest.raises(InputError, match="pred must hold real numbers"):
            pck(np.full((2, 3, 2), "a"), truth, None, 0.1, [1, 1])


# ----------------------------------------------------------------------------- PCKh


class TestPckh:
    def test_head_sizes_and_the_half_threshold(self):
        # a 30 x 40 head rectangle: diagonal 50, head size 0.6 * 50 = 30, limit 15 px
        heads = mpii_head_sizes([[100.0, 50.0, 130.0, 90.0], [0.0, 0.0, -30.0, -40.0]])
        assert heads.tolist() == pytest.approx([30.0, 30.0]) and MPII_HEAD_SCALE == 0.6
        truth = np.zeros((2, 2, 2))
        pred = np.array([[[14.9, 0.0], [15.1, 0.0]], [[0.0, 15.0], [0.0, 9.0]]])
        s = pckh(pred, truth, None, heads)
        assert s.per_joint.tolist() == [0.5, 0.5] and s.threshold == 0.5
        # pckh is pck with the head size as the normalizer
        np.testing.assert_array_equal(pck(pred, truth, None, 0.5, heads).correct, s.correct)
        assert pckh(pred, truth, None, heads, alpha=0.1).pooled == 0.0

    def test_mpii_sixteen_joints(self):
        rng = np.random.default_rng(5)
        truth = np.c_[rng.uniform(0, 300, (10 * 16, 2)), np.ones(160)].reshape(10, 16, 3)
        truth[0, 6, 2] = 0  # one unlabelled pelvis
        heads = mpii_head_sizes(np.c_[rng.uniform(0, 50, (10, 2)), rng.uniform(60, 90, (10, 2))])
        pred = truth[:, :, :2] + rng.normal(0, 10, (10, 16, 2))
        s = pckh(pred, truth, None, heads)
        acc, avg, _ = mmpose_pck(pred, truth[:, :, :2], truth[:, :, 2] > 0, 0.5, heads)
        np.testing.assert_array_equal(s.per_joint, acc)
        assert s.mean == pytest.approx(avg) and s.counts[6] == 9


# ----------------------------------------------------------------------------- normalizers


class TestNormalizers:
    def test_bbox_diagonal(self):
        assert bbox_diagonal([[1, 2, 3, 4], [0, 0, 0, 0]]).tolist() == [5.0, 0.0]
        assert bbox_diagonal([[1, 2, 4, 6]], "xyxy").tolist() == [5.0]
        kp = np.array(
            [
                [[0, 0, 2], [3, 4, 1], [99, 99, 0]],  # v = 0 left out: 3 x 4 box
                [[5, 5, 0], [6, 6, 0], [7, 7, 0]],  # nothing labelled: 0
                [[2, 2, 2], [2, 2, 2], [np.nan, 1, 2]],  # one point (NaN left out): 0
            ]
        )
        assert bbox_diagonal(kp).tolist() == [5.0, 0.0, 0.0]
        assert bbox_diagonal(kp[:1, :2, :2]).tolist() == [5.0]  # (N, J, 2): all count
        assert bbox_diagonal(np.zeros((0, 4))).shape == (0,)

    def test_bad_input(self):
        with pytest.raises(InputError, match=r"boxes must be \(N, 4\) boxes or \(N, J, 2\|3\)"):
            bbox_diagonal([1, 2, 3, 4])
        with pytest.raises(InputError, match="negative w or h"):
            bbox_diagonal([[0, 0, -1, 2]])
        with pytest.raises(InputError, match="x2 < x1 or y2 < y1: swap them"):
            bbox_diagonal([[5, 0, 1, 2]], "xyxy")
        with pytest.raises(InputError, match="box_format must be one of"):
            bbox_diagonal([[5, 0, 1, 2]], "cxcywh")
        with pytest.raises(InputError, match="boxes hold NaN or inf"):
            bbox_diagonal([[0, 0, np.nan, 2]])
        with pytest.raises(InputError, match=r"head_boxes must be \(N, 4\) corners"):
            mpii_head_sizes([[0, 0, 1]])


@pytest.mark.realdata
def test_real_coco_persons():
    # the 12 labelled persons of mmpose's COCO test file: the truth scores 1; noise of
    # 2 % of each box diagonal is always within PCK@0.05, 20 % never within PCK@0.1
    ds = read_coco_json(data_path("detection", "coco_keypoints_mmpose", "test_coco.json"))
    keep = ds.num_keypoints > 0
    truth = ds.keypoints[keep]
    diag = bbox_diagonal(ds.boxes[keep])
    assert truth.shape == (12, 17, 3) and (diag > 0).all()
    xy = truth[:, :, :2]
    assert pck(xy, truth, None, 0.05, diag).pooled == 1.0
    rng = np.random.default_rng(0)
    angle = rng.uniform(0, 2 * np.pi, truth.shape[:2])
    unit = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    near = xy + 0.02 * diag[:, None, None] * unit
    far = xy + 0.2 * diag[:, None, None] * unit
    assert pck(near, truth, None, 0.05, diag).pooled == 1.0
    s = pck(far, truth, None, 0.1, diag)
    assert s.pooled == 0.0 and s.counts.sum() == int(ds.num_keypoints[keep].sum())
