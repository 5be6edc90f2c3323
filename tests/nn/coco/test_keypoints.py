"""COCO keypoint data and evaluation (nn.coco.dataset, .results, .evaluate: iou_type="keypoints").

Parity: pycocotools' ``COCOeval(gt, dt, "keypoints")``, the evaluation practitioners
trust, on randomized results over the real COCO person-keypoints file that mmpose
ships for its tests (4 images, 14 persons, 2 of them without labelled keypoints) and
on small synthetic sets that hold what the real file lacks (crowd regions, another K,
more than 20 detections of one image). The tolerance is 1e-9 absolute on the
precision/recall/score arrays, the 10 summary numbers and the OKS matrices: both
sides do the OKS in float64 with the same operations in the same order, so they agree
to the last bit but for the order of the sum over keypoints (NumPy's pairwise sum of
a masked row against pycocotools' sum of the kept entries, a few ulps); 1e-9 leaves
room for that, nothing more.
"""

from __future__ import annotations

import contextlib
import copy
import io
import json

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco.dataset import (
    CocoCategory,
    CocoDataset,
    coco_from_dict,
    coco_to_dict,
    read_coco_json,
    write_coco_json,
)
from robopercept.nn.coco.evaluate import (
    KEYPOINT_SUMMARY_NAMES,
    SUMMARY_NAMES,
    evaluate_detections,
    keypoint_oks,
)
from robopercept.nn.coco.results import (
    CocoResults,
    read_coco_results,
    results_from_ground_truth,
    results_from_list,
    results_to_list,
    write_coco_results,
)
from robopercept.nn.coco.voc import voc_to_coco
from robopercept.nn.skeleton import COCO_17, skeleton_from_coco_category
from tests.conftest import data_path

pytest.importorskip("pycocotools")

TOL = 1e-9


def pycocotools_keypoints(gt: dict, res: list[dict], sigmas: np.ndarray | None = None) -> object:
    """``COCOeval(..., "keypoints")`` on copies of the dicts, prints silenced; custom
    sigmas through ``params.kpt_oks_sigmas`` (pycocotools' own way)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with contextlib.redirect_stdout(io.StringIO()):
        g = COCO()
        g.dataset = copy.deepcopy(gt)
        g.createIndex()
        d = g.loadRes(copy.deepcopy(res))
        ev = COCOeval(g, d, "keypoints")
        if sigmas is not None:
            ev.params.kpt_oks_sigmas = np.asarray(sigmas, dtype=np.float64)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return ev


def assert_same_as_pycocotools(gt: dict, res: list[dict], sigmas=None) -> None:
    ours = evaluate_detections(gt, res, "keypoints", sigmas=sigmas)
    ref = pycocotools_keypoints(gt, res, sigmas)
    assert ours.precision.shape == ref.eval["precision"].shape  # (10, 101, K, 3, 1)
    np.testing.assert_allclose(ours.precision, ref.eval["precision"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.recall, ref.eval["recall"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.scores, ref.eval["scores"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.stats, ref.stats, rtol=0, atol=TOL)
    assert ours.summary_names == KEYPOINT_SUMMARY_NAMES and ours.stats.shape == (10,)


@pytest.fixture(scope="module")
def real_gt() -> dict:
    path = data_path("detection", "coco_keypoints_mmpose", "test_coco.json")
    return json.loads(path.read_text())


def perturbed_results(gt: dict, seed: int, extra_on_one: int = 0) -> list[dict]:
    """Seeded keypoint results: each labelled person found with probability 0.85, its
    keypoints moved by Gaussian noise of 0-8 % of the square root of its area and
    random per-keypoint scores; a random detection score, often a tied one (0.5, 0.7);
    5-30 false detections (keypoints scattered around random points of the image), and
    ``extra_on_one`` more on the first image; the list shuffled."""
    rng = np.random.default_rng(seed)
    k = len(gt["categories"][0]["keypoints"])
    res = []
    for a in gt["annotations"]:
        if rng.random() < 0.15:
            continue
        kp = np.array(a["keypoints"], dtype=np.float64).reshape(-1, 3)
        xy = kp[:, :2] + rng.normal(0, np.sqrt(a["area"]) * rng.uniform(0, 0.08), (k, 2))
        score = float(rng.choice([0.5, 0.7, rng.uniform()]))
        res.append(
            {
                "image_id": a["image_id"],
                "category_id": a["category_id"],
                "keypoints": np.c_[xy, rng.uniform(0, 1, k)].ravel().tolist(),
                "score": score,
            }
        )
    images = gt["images"]
    n_false = int(rng.integers(5, 30))
    for n in range(n_false + extra_on_one):
        im = images[0] if n >= n_false else images[int(rng.integers(len(images)))]
        centre = rng.uniform([0, 0], [im["width"], im["height"]])
        xy = centre + rng.normal(0, rng.uniform(5, 80), (k, 2))
        res.append(
            {
                "image_id": im["id"],
                "category_id": gt["categories"][0]["id"],
                "keypoints": np.c_[xy, np.ones(k)].ravel().tolist(),
                "score": float(rng.uniform()),
            }
        )
    order = rng.permutation(len(res))
    return [res[i] for i in order]


def one_image(anns: list[dict], k: int, size: tuple[int, int] = (400, 300)) -> dict:
    return {
        "images": [{"id": 1, "file_name": "a.jpg", "width": size[0], "height": size[1]}],
        "categories": [
            {"id": 1, "name": "p", "keypoints": [f"k{i}" for i in range(k)], "skeleton": []}
        ],
        "annotations": [
            {"id": j + 1, "image_id": 1, "category_id": 1, "iscrowd": 0} | a
            for j, a in enumerate(anns)
        ],
    }


def kp_det(xy, score: float, img: int = 1, **extra) -> dict:
    xy = np.asarray(xy, dtype=np.float64)
    pts = np.c_[xy, np.ones(len(xy))].ravel().tolist()
    return {"image_id": img, "category_id": 1, "keypoints": pts, "score": score} | extra


# ----------------------------------------------------------------------------- parity


@pytest.mark.realdata
class TestParityOnTheRealFile:
    @pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
    def test_randomized_results(self, real_gt, seed):
        res = perturbed_results(real_gt, seed, extra_on_one=25)
        # the set holds what it promises (otherwise the parity proves less)
        assert len(res) < len(real_gt["annotations"]) + 60
        per_img = np.bincount([r["image_id"] for r in res])
        assert per_img.max() > 20  # more than maxDets: the cut is exercised
        scores = [r["score"] for r in res]
        assert len(set(scores)) < len(scores)  # tied scores
        assert any(a["num_keypoints"] == 0 for a in real_gt["annotations"])
        areas = np.array([a["area"] for a in real_gt["annotations"]])
        assert (areas < 32**2).any() and ((areas > 32**2) & (areas < 96**2)).any()
        assert (areas > 96**2).any()
        assert_same_as_pycocotools(real_gt, res)
        ev = evaluate_detections(real_gt, res, "keypoints")
        assert 0.05 < ev.stats[0] < 0.95  # neither trivial nor hopeless

    @pytest.mark.parametrize("seed", [5, 6])
    def test_custom_sigmas(self, real_gt, seed):
        res = perturbed_results(real_gt, seed)
        sigmas = np.random.default_rng(seed).uniform(0.02, 0.12, 17)
        assert_same_as_pycocotools(real_gt, res, sigmas)
        default = evaluate_detections(real_gt, res, "keypoints")
        assert not np.array_equal(
            default.stats, evaluate_detections(real_gt, res, "keypoints", sigmas=sigmas).stats
        )

    def test_default_sigmas_are_cocos(self, real_gt):
        res = perturbed_results(real_gt, 7)
        a = evaluate_detections(real_gt, res, "keypoints")
        b = evaluate_detections(real_gt, res, "keypoints", sigmas=COCO_17.sigmas)
        np.testing.assert_array_equal(a.stats, b.stats)

    def test_oks_matrices_equal_compute_oks(self, real_gt):
        # pycocotools' ious[(image, category)]: dets sorted by score (mergesort), cut to 20
        res = perturbed_results(real_gt, 8)
        ref = pycocotools_keypoints(real_gt, res)
        gt = coco_from_dict(real_gt)
        dets = results_from_list(res)
        compared = 0
        for (img, cat), ious in ref.ious.items():
            if len(ious) == 0:
                continue
            g = np.flatnonzero((gt.image_ids == img) & (gt.category_ids == cat))
            d = np.flatnonzero((dets.image_ids == img) & (dets.category_ids == cat))
            d = d[np.argsort(-dets.scores[d], kind="mergesort")][:20]
            ours = keypoint_oks(
                dets.keypoints[d], gt.keypoints[g], gt.areas[g], gt.boxes[g], COCO_17.sigmas
            )
            np.testing.assert_allclose(ours, ious, rtol=0, atol=TOL)
            compared += ious.size
        assert compared > 20

    def test_ground_truth_as_results_scores_one(self, real_gt):
        # the labelled persons as detections, as a keypoint detector writes them
        res = [
            {"image_id": a["image_id"], "category_id": 1, "keypoints": a["keypoints"],
             "score": 1.0}
            for a in real_gt["annotations"] if a["num_keypoints"] > 0
        ]  # fmt: skip
        ev = evaluate_detections(real_gt, res, "keypoints")
        np.testing.assert_allclose(ev.stats, 1.0, rtol=0, atol=1e-12)
        assert_same_as_pycocotools(real_gt, res)
        perfect = results_from_ground_truth(
            read_coco_json(data_path("detection", "coco_keypoints_mmpose", "test_coco.json")),
            require_keypoints=True,
        )
        ev = evaluate_detections(real_gt, perfect, "keypoints")
        np.testing.assert_allclose(ev.stats, 1.0, rtol=0, atol=1e-12)
        # every person, labelled or not: the unlabelled ones are false positives, in
        # pycocotools as here (their OKS with themselves uses the tripled-box distance)
        every = results_to_list(results_from_ground_truth(coco_from_dict(real_gt)))
        assert evaluate_detections(real_gt, every, "keypoints").stats[0] < 1
        assert_same_as_pycocotools(real_gt, every)

    def test_results_with_a_bbox_keep_it(self, real_gt):
        # loadRes takes a result's bbox (and w h as its area) when it gives one
        res = perturbed_results(real_gt, 9)
        rng = np.random.default_rng(9)
        for r in res:
            r["bbox"] = rng.uniform([0, 0, 1, 1], [300, 300, 200, 200]).tolist()
        assert_same_as_pycocotools(real_gt, res)
        np.testing.assert_array_equal(
            results_from_list(res).boxes, np.array([r["bbox"] for r in res])
        )

    def test_compiled_kernel_equals_python_reference(self, real_gt):
        res = perturbed_results(real_gt, 10, extra_on_one=30)
        a = evaluate_detections(real_gt, res, "keypoints", use_jit=True)
        b = evaluate_detections(real_gt, res, "keypoints", use_jit=False)
        np.testing.assert_array_equal(a.precision, b.precision)
        np.testing.assert_array_equal(a.stats, b.stats)

    def test_order_of_the_results_does_not_matter(self, real_gt):
        # with distinct scores, any order of the list gives the same evaluation
        res = perturbed_results(real_gt, 11)
        for k, r in enumerate(res):
            r["score"] = 0.01 + k / (2 * len(res))
        shuffled = [res[i] for i in np.random.default_rng(0).permutation(len(res))]
        a = evaluate_detections(real_gt, res, "keypoints")
        b = evaluate_detections(real_gt, shuffled, "keypoints")
        np.testing.assert_array_equal(a.precision, b.precision)


class TestParitySynthetic:
    def test_crowd_unlabelled_and_tripled_box(self):
        # person 1 labelled; person 2 unlabelled (num_keypoints 0: ignored, OKS by the
        # distance to its tripled box); a crowd region; a detection inside person 2's
        # tripled box (OKS 1 with it: matched to ignored ground truth, so ignored), one
        # near person 1, one far from everything
        xy1 = [[100, 100, 2], [120, 100, 2], [110, 130, 1]]
        anns = [
            {"bbox": [90, 90, 40, 50], "area": 1500.0, "keypoints": np.ravel(xy1).tolist(),
             "num_keypoints": 3},
            {"bbox": [250, 50, 30, 60], "area": 1200.0, "keypoints": [0] * 9,
             "num_keypoints": 0},
            {"bbox": [0, 200, 200, 90], "area": 15000.0, "keypoints": [0] * 9,
             "num_keypoints": 0, "iscrowd": 1},
        ]  # fmt: skip
        gt = one_image(anns, 3)
        dets = [
            kp_det([[101, 99], [121, 102], [108, 128]], 0.9),
            kp_det([[230, 20], [300, 160], [250, 60]], 0.8),  # inside [220, 310] x [-10, 170]
            kp_det([[20, 250], [60, 260], [40, 280]], 0.7),  # on the crowd region
            kp_det([[380, 10], [390, 20], [385, 30]], 0.6),
        ]
        sig = [0.05, 0.06, 0.07]
        assert_same_as_pycocotools(gt, dets, sig)
        ev = evaluate_detections(gt, dets, "keypoints", sigmas=sig)
        ds = coco_from_dict(gt)
        oks = keypoint_oks(results_from_list(dets).keypoints, ds.keypoints, ds.areas, ds.boxes, sig)
        assert oks[1, 1] == 1.0  # inside the tripled box: distance 0 on every keypoint
        assert ev.summary()["AP50"] > 0.5

    def test_num_keypoints_field_rules_the_ignoring(self):
        # num_keypoints 0 with labelled v: ignored (the field), OKS over its v > 0
        # keypoints (the flags), as pycocotools does
        anns = [
            {"bbox": [10, 10, 60, 60], "area": 3600.0, "keypoints": [20, 20, 2, 50, 50, 2],
             "num_keypoints": 0},
            {"bbox": [110, 10, 60, 60], "area": 3600.0, "keypoints": [120, 20, 2, 150, 50, 2]},
        ]  # fmt: skip
        gt = one_image(anns, 2)
        dets = [kp_det([[20, 21], [50, 50]], 0.9), kp_det([[121, 20], [150, 52]], 0.8)]
        ds = coco_from_dict(gt)
        assert ds.num_keypoints.tolist() == [0, 2]  # the field, then the count of v > 0
        gt["annotations"][1]["num_keypoints"] = 2  # pycocotools needs the field
        assert_same_as_pycocotools(gt, dets, [0.1, 0.1])
        ev = evaluate_detections(gt, dets, "keypoints", sigmas=[0.1, 0.1])
        assert ev.summary()["AP"] == pytest.approx(1.0)  # the first det is ignored

    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_random_sets_of_five_keypoints(self, seed):
        # several images, K = 5, areas in every range, crowd, unlabelled persons,
        # images without ground truth, more than 20 detections on one image
        rng = np.random.default_rng(seed)
        images = [{"id": i + 1, "file_name": f"{i}.jpg", "width": 640, "height": 480}
                  for i in range(6)]  # fmt: skip
        anns, res = [], []
        for n in range(25):
            img = int(rng.integers(1, 5))
            w, h = rng.uniform(8, 200, 2)
            x, y = rng.uniform(0, 400), rng.uniform(0, 300)
            xy = np.c_[rng.uniform(x, x + w, 5), rng.uniform(y, y + h, 5)]
            v = rng.choice([0, 1, 2], 5, p=[0.3, 0.2, 0.5])
            if rng.random() < 0.15:
                v[:] = 0
            kp = np.c_[np.where(v[:, None] > 0, xy, 0), v]
            crowd = int(rng.random() < 0.1)
            anns.append({"id": n + 1, "image_id": img, "category_id": 1, "iscrowd": crowd,
                         "bbox": [x, y, w, h], "area": float(w * h * 0.8),
                         "keypoints": kp.ravel().tolist(),
                         "num_keypoints": int((v > 0).sum())})  # fmt: skip
            if rng.random() < 0.8:
                noisy = xy + rng.normal(0, np.sqrt(w * h) * 0.05, (5, 2))
                res.append(kp_det(noisy, float(rng.choice([0.3, rng.uniform()])), img))
        for _ in range(30):
            xy = rng.uniform(0, 480, (5, 2))
            img = 1 if _ < 22 else int(rng.integers(1, 7))
            res.append(kp_det(xy, float(rng.uniform()), img))
        gt = {"images": images, "annotations": anns,
              "categories": [{"id": 1, "name": "p", "keypoints": list("abcde")}]}  # fmt: skip
        sig = rng.uniform(0.03, 0.1, 5)
        assert_same_as_pycocotools(gt, res, sig)
        with pytest.raises(InputError, match="sigmas is needed: the keypoints have K = 5"):
            evaluate_detections(gt, res, "keypoints")


# ----------------------------------------------------------------------------- OKS by hand


class TestOksByHand:
    def test_one_pair(self):
        # K = 3, area 400, sigmas .1 .2 .3: variances (2 sigma)^2 = .04 .16 .36;
        # offsets (3, 4) -> d^2 25, (0, 2) -> 4, the third keypoint unlabelled
        gt = np.array([[[10.0, 10.0, 2.0], [30.0, 10.0, 1.0], [50.0, 50.0, 0.0]]])
        dt = np.array([[[13.0, 14.0, 0.9], [30.0, 12.0, 0.9], [0.0, 0.0, 0.1]]])
        oks = keypoint_oks(dt, gt, [400.0], [[0, 0, 60, 60]], [0.1, 0.2, 0.3])
        e = np.array([25 / 0.04 / 400 / 2, 4 / 0.16 / 400 / 2])  # 0.78125, 0.03125
        assert oks.shape == (1, 1)
        assert oks[0, 0] == pytest.approx(np.exp(-e).sum() / 2, abs=1e-15)
        assert oks[0, 0] == pytest.approx((np.exp(-0.78125) + np.exp(-0.03125)) / 2)

    def test_unlabelled_ground_truth_uses_the_tripled_box(self):
        # bbox (10, 20, 10, 10): the box [0, 30] x [10, 40]; a keypoint at (35, 5) is
        # 5 right of it and 5 above: d^2 = 50; one at (15, 25) is inside: 0
        gt = np.zeros((1, 2, 3))
        dt = np.array([[[35.0, 5.0], [15.0, 25.0]]])
        oks = keypoint_oks(dt, gt, [100.0], [[10, 20, 10, 10]], [0.25, 0.25])
        expected = (np.exp(-50 / 0.25 / (100 + np.spacing(1)) / 2) + 1.0) / 2
        assert oks[0, 0] == pytest.approx(expected, abs=1e-15)

    def test_matrix_shape_and_symmetries(self):
        rng = np.random.default_rng(0)
        gt = np.c_[rng.uniform(0, 100, (4 * 6, 2)), np.full(24, 2.0)].reshape(4, 6, 3)
        dt = rng.uniform(0, 100, (3, 6, 2))
        area, box, sig = np.full(4, 900.0), np.tile([0, 0, 30, 30], (4, 1)), np.full(6, 0.07)
        oks = keypoint_oks(dt, gt, area, box, sig)
        assert oks.shape == (3, 4) and ((oks >= 0) & (oks <= 1)).all()
        assert keypoint_oks(gt[:, :, :2], gt, area, box, sig).diagonal() == pytest.approx(1)
        shift = np.array([7.0, -3.0])  # translating both keeps the OKS
        moved = gt.copy()
        moved[:, :, :2] += shift
        np.testing.assert_allclose(
            keypoint_oks(dt + shift, moved, area, box + np.r_[shift, 0, 0], sig), oks, atol=1e-12
        )
        assert keypoint_oks(np.zeros((0, 6, 2)), gt, area, box, sig).shape == (0, 4)

    def test_bad_input(self):
        gt, box = np.zeros((1, 2, 3)), [[0, 0, 1, 1]]
        with pytest.raises(InputError, match=r"dt_keypoints must be \(D, 2, 2\)"):
            keypoint_oks(np.zeros((1, 3, 2)), gt, [1.0], box, [0.1, 0.1])
        with pytest.raises(InputError, match=r"gt_keypoints must be \(G, K, 3\)"):
            keypoint_oks(np.zeros((1, 2, 2)), np.zeros((1, 2, 2)), [1.0], box, [0.1, 0.1])
        with pytest.raises(InputError, match=r"gt_area must be \(1,\) and gt_box \(1, 4\)"):
            keypoint_oks(np.zeros((1, 2, 2)), gt, [1.0, 2.0], box, [0.1, 0.1])
        with pytest.raises(InputError, match="sigmas must be 2 positive numbers"):
            keypoint_oks(np.zeros((1, 2, 2)), gt, [1.0], box, [0.1, 0.0])
        with pytest.raises(InputError, match="dt_keypoints holds NaN"):
            keypoint_oks(np.full((1, 2, 2), np.nan), gt, [1.0], box, [0.1, 0.1])
        with pytest.raises(InputError, match="gt_area must be >= 0"):
            keypoint_oks(np.zeros((1, 2, 2)), gt, [-1.0], box, [0.1, 0.1])


# ----------------------------------------------------------------------------- formats


class TestKeypointFields:
    @pytest.mark.realdata
    def test_real_file_fields_and_round_trip(self, real_gt, tmp_path):
        path = data_path("detection", "coco_keypoints_mmpose", "test_coco.json")
        ds = read_coco_json(path)
        assert ds.keypoints.shape == (14, 17, 3) and ds.keypoints.dtype == np.float64
        ref = np.array([a["keypoints"] for a in real_gt["annotations"]], dtype=float)
        np.testing.assert_array_equal(ds.keypoints, ref.reshape(14, 17, 3))
        assert ds.num_keypoints.tolist() == [a["num_keypoints"] for a in real_gt["annotations"]]
        cat = ds.categories[0]
        assert cat.keypoints == COCO_17.joints
        assert cat.skeleton == tuple(map(tuple, real_gt["categories"][0]["skeleton"]))
        skel = skeleton_from_coco_category(cat.to_dict())
        assert skel.links == COCO_17.links and skel.flip_pairs == COCO_17.flip_pairs
        back = read_coco_json(write_coco_json(ds, tmp_path / "kp.json"))
        np.testing.assert_array_equal(back.keypoints, ds.keypoints)
        np.testing.assert_array_equal(back.num_keypoints, ds.num_keypoints)
        assert back.categories == ds.categories
        d = coco_to_dict(ds)
        for ours, theirs in zip(d["annotations"], real_gt["annotations"], strict=True):
            assert ours["keypoints"] == theirs["keypoints"]
            assert ours["num_keypoints"] == theirs["num_keypoints"]
        assert d["categories"][0]["keypoints"] == real_gt["categories"][0]["keypoints"]
        assert d["categories"][0]["skeleton"] == real_gt["categories"][0]["skeleton"]

    def test_results_round_trip_and_tight_box(self, tmp_path):
        res = [kp_det([[10, 20], [40, 25], [30, 60]], 0.9), kp_det([[5, 5], [6, 9], [7, 7]], 0.4)]
        r = results_from_list(res)
        assert r.keypoints.shape == (2, 3, 3)
        # loadRes: bbox [x0, y0, x1 - x0, y1 - y0] of all the keypoints
        np.testing.assert_array_equal(r.boxes, [[10, 20, 30, 40], [5, 5, 2, 4]])
        back = read_coco_results(write_coco_results(r, tmp_path / "res.json"))
        np.testing.assert_array_equal(back.keypoints, r.keypoints)
        np.testing.assert_array_equal(back.boxes, r.boxes)
        assert results_to_list(back)[0]["keypoints"] == res[0]["keypoints"]

    def test_annotations_without_keypoints_in_a_keypoint_set(self):
        gt = one_image([{"bbox": [0, 0, 5, 5], "keypoints": [1, 1, 2, 2, 2, 0]},
                        {"bbox": [9, 9, 5, 5]}], 2)  # fmt: skip
        ds = coco_from_dict(gt)
        assert ds.keypoints.shape == (2, 2, 3) and not ds.keypoints[1].any()
        assert ds.num_keypoints.tolist() == [1, 0]

    def test_box_sets_and_constructors_stay_as_they_were(self):
        # no keypoints anywhere: (N, 0, 3), nothing written; positional constructors
        # (voc_to_coco builds one) still work and fill the defaults
        gt = one_image([{"bbox": [0, 0, 5, 5]}], 0)
        gt["categories"] = [{"id": 1, "name": "p"}]
        ds = coco_from_dict(gt)
        assert ds.keypoints.shape == (1, 0, 3) and ds.num_keypoints.tolist() == [0]
        assert "keypoints" not in coco_to_dict(ds)["annotations"][0]
        assert "keypoints" not in coco_to_dict(ds)["categories"][0]
        assert CocoCategory(1, "p") == CocoCategory(1, "p", "", (), ())
        v = voc_to_coco([])
        assert v.keypoints.shape == (0, 0, 3)
        box = evaluate_detections(ds, [{"image_id": 1, "category_id": 1,
                                        "bbox": [0, 0, 5, 5], "score": 1.0}])  # fmt: skip
        assert box.summary_names == SUMMARY_NAMES and box.iou_type == "bbox"
        assert len(box.area_names) == 4
        r = results_from_list([{"image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1],
                                "score": 0.5}])  # fmt: skip
        assert r.keypoints.shape == (1, 0, 3)
        assert "keypoints" not in results_to_list(r)[0]

    def test_record_constructors_check_the_keypoints(self):
        z = np.zeros(2, dtype=np.int64)
        args = ((), (), z, z, z, np.zeros((2, 4)), np.zeros(2), np.zeros(2, bool), ())
        ds = CocoDataset(*args, np.zeros((2, 3, 3)))
        assert ds.num_keypoints.tolist() == [0, 0]
        with pytest.raises(InputError, match=r"CocoDataset.keypoints must be \(2, K, 3\)"):
            CocoDataset(*args, np.zeros((3, 3, 3)))
        with pytest.raises(InputError, match="num_keypoints must be 2 integers"):
            CocoDataset(*args, np.zeros((2, 3, 3)), [1.5, 0])
        with pytest.raises(InputError, match=r"CocoResults\.keypoints holds NaN"):
            CocoResults(z, z, np.zeros((2, 4)), np.zeros(2), (), np.full((2, 1, 3), np.nan))


# ----------------------------------------------------------------------------- refusals


class TestBadInput:
    def gt(self) -> dict:
        return one_image([{"bbox": [0, 0, 9, 9], "keypoints": [1, 1, 2, 3, 3, 2]}], 2)

    def test_evaluation_arguments(self):
        gt = self.gt()
        det = [kp_det([[1, 1], [3, 3]], 0.9)]
        with pytest.raises(InputError, match="sigmas must be 2 positive numbers"):
            evaluate_detections(gt, det, "keypoints", sigmas=[0.1, -0.1])
        with pytest.raises(InputError, match="sigmas must be 2 positive numbers"):
            evaluate_detections(gt, det, "keypoints", sigmas=[0.1, 0.1, 0.1])
        with pytest.raises(InputError, match="sigmas are the OKS constants of iou_type="):
            evaluate_detections(gt, det, "bbox", sigmas=[0.1, 0.1])
        with pytest.raises(InputError, match="sigmas is needed"):
            evaluate_detections(gt, det, "keypoints")
        with pytest.raises(InputError, match=r"'keypoints' \[x, y, s\] \* 2 .* K = 3"):
            evaluate_detections(gt, [kp_det([[1, 1], [3, 3], [4, 4]], 0.9)], "keypoints",
                                sigmas=[0.1, 0.1])  # fmt: skip
        boxes = [{"image_id": 1, "category_id": 1, "bbox": [0, 0, 9, 9], "score": 0.9}]
        with pytest.raises(InputError, match=r"got none \(box or mask results\)"):
            evaluate_detections(gt, boxes, "keypoints", sigmas=[0.1, 0.1])
        no_kp = one_image([{"bbox": [0, 0, 9, 9]}], 0)
        with pytest.raises(InputError, match="the ground truth has no keypoints: iou_type="):
            evaluate_detections(no_kp, det, "keypoints")
        with pytest.raises(InputError, match="max_dets for iou_type='keypoints'"):
            evaluate_detections(gt, det, "keypoints", sigmas=[0.1, 0.1], max_dets=())
        with pytest.raises(InputError, match="max_dets must be increasing"):
            evaluate_detections(gt, det, "keypoints", sigmas=[0.1, 0.1], max_dets=(20, 5))
        # an empty results list is an evaluation with no detection (AP 0)
        ev = evaluate_detections(gt, [], "keypoints", sigmas=[0.1, 0.1])
        assert ev.stats[0] == 0.0

    def test_ground_truth_keypoints(self):
        def bad(ann: dict, match: str, k: int = 2) -> None:
            gt = one_image([{"bbox": [0, 0, 9, 9]} | ann], k)
            with pytest.raises(InputError, match=match):
                coco_from_dict(gt)

        bad({"keypoints": [1, 1, 2, 3, 3]}, r"annotation id 1: keypoints must be a flat list")
        bad({"keypoints": [1, 1, "2", 3, 3, 2]}, "keypoints must be a flat list of numbers")
        bad({"keypoints": [1, float("nan"), 2, 3, 3, 2]}, "hold NaN or inf; write 0, 0, 0")
        bad({"keypoints": [1, 1, 2]}, "category id 1 names 2 keypoints but the annotations")
        bad({"num_keypoints": -1, "keypoints": [1, 1, 2, 3, 3, 2]}, "num_keypoints must be >= 0")
        gt = one_image([{"bbox": [0, 0, 9, 9], "keypoints": [1, 1, 2, 3, 3, 2]},
                        {"bbox": [0, 0, 9, 9], "keypoints": [1, 1, 2]}], 0)  # fmt: skip
        gt["categories"] = [{"id": 1, "name": "p"}]
        with pytest.raises(InputError, match="annotation id 2 has 1 keypoints but annotation"):
            coco_from_dict(gt)
        gt = self.gt()
        gt["categories"][0]["skeleton"] = [[1, 3]]
        with pytest.raises(InputError, match=r"skeleton link \[1, 3\] must join keypoints 1\.\.2"):
            coco_from_dict(gt)
        gt["categories"][0]["skeleton"] = [[1, "b"]]
        with pytest.raises(InputError, match="skeleton must be a list of \\[i, j\\] pairs"):
            coco_from_dict(gt)

    def test_result_keypoints(self, tmp_path):
        with pytest.raises(InputError, match=r"results\[1\] has no 'keypoints' unlike"):
            results_from_list(
                [
                    kp_det([[1, 1]], 0.5),
                    {"image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1], "score": 0.4},
                ]
            )
        with pytest.raises(InputError, match=r"results\[1\] has 1 keypoints but results\[0\]"):
            results_from_list([kp_det([[1, 1], [2, 2]], 0.5), kp_det([[1, 1]], 0.4)])
        with pytest.raises(InputError, match=r"results\[0\].keypoints is empty"):
            results_from_list([{"image_id": 1, "category_id": 1, "keypoints": [],
                                "score": 0.4}, kp_det([[1, 1]], 0.4)])  # fmt: skip
        p = tmp_path / "bad.json"
        p.write_text(json.dumps([kp_det([[1, 1]], 0.5) | {"keypoints": [1, 2]}]))
        with pytest.raises(FileFormatError, match=r"bad.json: results\[0\]: keypoints must"):
            read_coco_results(p)
