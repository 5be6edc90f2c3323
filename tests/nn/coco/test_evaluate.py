"""The COCO evaluation (robopercept.nn.coco.evaluate) of boxes and masks, and its PR curves.

Parity: pycocotools' COCOeval (bbox), the evaluation practitioners trust, on seeded
synthetic detection sets that hold every case it treats apart. The tolerance is 1e-9
absolute on the precision/recall/score arrays and the 12 summary numbers: both sides do
the same float64 operations in the same order (the IoU as pycocotools' C bbIou, the
cumulative sums, the envelope), so the arrays agree to the last bit today; 1e-9 leaves
room for a summation order change in NumPy's ``mean``, nothing more. The keypoint
evaluation is tested in ``test_keypoints.py``.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from benchmarks.coco_eval import pycocotools_eval, synthetic_detections
from robopercept.errors import InputError
from robopercept.nn.coco.dataset import CocoDataset, coco_from_dict, coco_to_dict
from robopercept.nn.coco.evaluate import (
    SUMMARY_NAMES,
    evaluate_detections,
    pr_curves_picture,
    write_pr_curves,
)
from robopercept.nn.coco.results import (
    results_from_ground_truth,
    results_from_list,
    results_to_list,
)
from robopercept.nn.coco.rle import rle_counts, rle_encode

pytest.importorskip("pycocotools")
M = pytest.importorskip("pycocotools.mask")

TOL = 1e-9


def one_image(anns: list[dict], cats: tuple[int, ...] = (1,)) -> dict:
    return {
        "images": [{"id": 1, "file_name": "a.jpg", "width": 640, "height": 480}],
        "categories": [{"id": c, "name": f"c{c}"} for c in cats],
        "annotations": [
            {"id": k + 1, "image_id": 1, "category_id": 1, "iscrowd": 0} | a
            for k, a in enumerate(anns)
        ],
    }


def det(bbox: list[float], score: float, cat: int = 1, img: int = 1) -> dict:
    return {"image_id": img, "category_id": cat, "bbox": bbox, "score": score}


def assert_same_as_pycocotools(gt: dict, res: list[dict]) -> None:
    ours = evaluate_detections(gt, res)
    ref = pycocotools_eval(gt, res)
    assert ours.precision.shape == ref.eval["precision"].shape
    assert ours.recall.shape == ref.eval["recall"].shape
    np.testing.assert_allclose(ours.precision, ref.eval["precision"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.recall, ref.eval["recall"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.scores, ref.eval["scores"], rtol=0, atol=TOL)
    np.testing.assert_allclose(ours.stats, ref.stats, rtol=0, atol=TOL)


# ----------------------------------------------------------------------------- parity


class TestParityWithPycocotools:
    @pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
    def test_randomized_sets(self, seed):
        gt, res = synthetic_detections(seed)
        # the set holds what it promises (otherwise the parity proves less)
        gt_imgs = {a["image_id"] for a in gt["annotations"]}
        dt_imgs = {r["image_id"] for r in res}
        all_imgs = {i["id"] for i in gt["images"]}
        assert all_imgs - gt_imgs and all_imgs - dt_imgs  # images without gt / without dets
        assert any(a["iscrowd"] for a in gt["annotations"])
        cats = {c["id"] for c in gt["categories"]}
        assert cats - {r["category_id"] for r in res}  # a class without detections
        assert cats - {a["category_id"] for a in gt["annotations"]}  # a class without gt
        per_img = np.bincount([r["image_id"] for r in res])
        assert per_img.max() > 100
        areas = np.array([a["area"] for a in gt["annotations"]])
        assert (areas < 32**2).any() and ((areas > 32**2) & (areas < 96**2)).any()
        assert (areas > 96**2).any()
        scores = [r["score"] for r in res]
        assert len(set(scores)) < len(scores)  # duplicate scores
        assert_same_as_pycocotools(gt, res)

    def test_crowd_only_and_single_cases(self):
        crowd = one_image([{"bbox": [0, 0, 200, 200], "area": 40000.0, "iscrowd": 1}])
        assert_same_as_pycocotools(crowd, [det([10, 10, 50, 50], 0.9)])
        tie = one_image([{"bbox": [0, 0, 40, 40], "area": 1600.0}] * 2)
        tie["annotations"][1] = tie["annotations"][1] | {"id": 2}
        assert_same_as_pycocotools(tie, [det([0, 0, 40, 40], 0.5), det([0, 0, 40, 40], 0.5)])

    def test_zero_size_boxes(self):
        # degenerate boxes (zero width) have IoU 0 with everything, as in pycocotools:
        # the object counts, the detection is a false positive
        gt = one_image(
            [{"bbox": [5, 5, 0, 10], "area": 0.0}, {"bbox": [50, 50, 20, 20], "area": 400.0}]
        )
        dets = [det([5, 5, 0, 10], 0.9), det([50, 50, 20, 20], 0.8)]
        assert_same_as_pycocotools(gt, dets)
        assert evaluate_detections(gt, dets).summary()["AR100"] == pytest.approx(0.5)

    def test_compiled_kernel_equals_python_reference(self):
        gt, res = synthetic_detections(7, n_images=15)
        a = evaluate_detections(gt, res, use_jit=True)
        b = evaluate_detections(gt, res, use_jit=False)
        np.testing.assert_array_equal(a.precision, b.precision)
        np.testing.assert_array_equal(a.recall, b.recall)
        np.testing.assert_array_equal(a.stats, b.stats)


def synthetic_masks(seed: int) -> tuple[dict, list[dict]]:
    """A seeded ``segm`` set: 8 images of 20-90 px, 3 categories (one without ground
    truth), polygon ground truth with its mask area as ``area``, crowd regions as
    uncompressed RLE (as COCO stores them), an image without ground truth and one
    without results; results: each ground-truth mask grown, shrunk or moved, plus
    random blobs, scores drawn from a few values (ties)."""
    rng = np.random.default_rng(seed)
    images, anns, res = [], [], []
    for i in range(1, 9):
        h, w = (int(v) for v in rng.integers(20, 90, 2))
        images.append({"id": i, "file_name": f"{i}.png", "width": w, "height": h})
        n = 0 if i == 2 else int(rng.integers(1, 6))
        for _ in range(n):
            cat = int(rng.integers(1, 3))
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
            r = rng.uniform(2, min(h, w) / 2)
            t = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(3, 9))))
            poly = np.column_stack([cx + r * np.cos(t), cy + r * np.sin(t)]).ravel()
            crowd = rng.random() < 0.15
            m = M.decode(M.frPyObjects([poly.tolist()], h, w)[0])
            if crowd:
                seg = {"size": [h, w], "counts": rle_counts(rle_encode(m))[1].tolist()}
            else:
                seg = [poly.tolist()]
            x, y, bw, bh = M.toBbox(M.encode(np.asfortranarray(m))).tolist()
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i,
                    "category_id": cat,
                    "bbox": [x, y, bw, bh],
                    "area": float(m.sum()),
                    "iscrowd": int(crowd),
                    "segmentation": seg,
                }
            )
            if i == 3:
                continue
            for _ in range(int(rng.integers(0, 3))):
                mm = m.copy()
                op = rng.integers(0, 3)
                if op == 0:
                    mm = np.roll(mm, (int(rng.integers(-3, 4)), int(rng.integers(-3, 4))), (0, 1))
                elif op == 1:
                    mm[:: int(rng.integers(2, 4))] = 0
                else:
                    mm = np.maximum(mm, np.roll(mm, 2, 1))
                res.append(_mask_result(i, cat, mm, rng))
        if i != 3:
            for _ in range(int(rng.integers(0, 4))):
                blob = (rng.random((h, w)) < 0.02).astype(np.uint8)
                res.append(_mask_result(i, int(rng.integers(1, 4)), blob, rng))
    cats = [{"id": c, "name": f"c{c}"} for c in (1, 2, 3)]
    return {"images": images, "categories": cats, "annotations": anns}, res


def _mask_result(img: int, cat: int, m: np.ndarray, rng: np.random.Generator) -> dict:
    return {
        "image_id": img,
        "category_id": cat,
        "segmentation": rle_encode(m),
        "score": float(rng.choice([0.3, 0.5, 0.7, 0.9])),
    }


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pycocotools under NumPy 2
class TestSegmParity:
    @pytest.mark.parametrize("seed", [0, 1, 2])
    def test_randomized_mask_sets(self, seed):
        gt, res = synthetic_masks(seed)
        # what the set promises: crowd regions, an image without ground truth and one
        # without results, a category without ground truth that has detections
        assert any(a["iscrowd"] for a in gt["annotations"])
        assert 2 not in {a["image_id"] for a in gt["annotations"]}
        assert 3 not in {r["image_id"] for r in res}
        assert 3 in {r["category_id"] for r in res} - {a["category_id"] for a in gt["annotations"]}
        ours = evaluate_detections(gt, res, iou_type="segm")
        ref = pycocotools_eval(gt, res, iou_type="segm")
        np.testing.assert_allclose(ours.precision, ref.eval["precision"], rtol=0, atol=TOL)
        np.testing.assert_allclose(ours.recall, ref.eval["recall"], rtol=0, atol=TOL)
        np.testing.assert_allclose(ours.stats, ref.stats, rtol=0, atol=TOL)
        # the compiled matching equals its Python reference on given IoUs too
        py = evaluate_detections(gt, res, iou_type="segm", use_jit=False)
        np.testing.assert_array_equal(py.precision, ours.precision)

    def test_masks_change_the_figure_boxes_would_give(self):
        # an L-shaped ground truth and a detection filling its 8 x 8 box: box IoU 1,
        # mask IoU 48 / 64 = 0.75 (the L covers 48 of the 64 pixels)
        m = np.zeros((16, 16), np.uint8)
        m[4:12, 4:8] = 1
        m[8:12, 4:12] = 1
        full = np.zeros_like(m)
        full[4:12, 4:12] = 1
        seg = {"size": [16, 16], "counts": rle_counts(rle_encode(m))[1].tolist()}
        gt = one_image([{"bbox": [4, 4, 8, 8], "area": 48.0, "segmentation": seg}])
        gt["images"][0] |= {"width": 16, "height": 16}
        r = [{"image_id": 1, "category_id": 1, "segmentation": rle_encode(full), "score": 1.0}]
        box = evaluate_detections(gt, [r[0] | {"bbox": [4, 4, 8, 8]}]).summary()["AP"]
        segm = evaluate_detections(gt, r, iou_type="segm").summary()
        # thresholds .50 to .75 pass, 6 of 10
        assert box == pytest.approx(1.0) and segm["AP"] == pytest.approx(0.6)
        assert segm["AP50"] == pytest.approx(1.0)
        # a result's box is its mask's when no bbox is given (pycocotools' loadRes)
        assert results_from_list(r).boxes.tolist() == [[4.0, 4.0, 8.0, 8.0]]
        with pytest.raises(InputError, match=r"results\[0\] has no segmentation"):
            evaluate_detections(gt, [det([4, 4, 8, 8], 0.5)], iou_type="segm")
        with pytest.raises(InputError, match="must be an RLE dict"):
            results_from_list(
                [
                    {
                        "image_id": 1,
                        "category_id": 1,
                        "score": 1.0,
                        "segmentation": [[0, 0, 4, 0, 4, 4]],
                    }
                ]
            )
        wrong = dict(r[0], segmentation=rle_encode(np.ones((8, 8))))
        with pytest.raises(InputError, match="8 x 8 but the image is 16 x 16"):
            evaluate_detections(gt, [wrong], iou_type="segm")
        # segmentations survive the round trip through dicts
        back = coco_from_dict(coco_to_dict(coco_from_dict(gt)))
        assert back.segmentations[0] == seg
        assert results_to_list(results_from_list(r))[0]["segmentation"] == r[0]["segmentation"]


# ----------------------------------------------------------------------------- hand cases


class TestHandComputed:
    def test_iou_point_eight_passes_seven_thresholds(self):
        # inter 50x40 = 2000, union 2500: IoU 0.8 >= .50 ... .80 (7 of 10 thresholds)
        gt = one_image([{"bbox": [10, 10, 50, 50]}])
        ev = evaluate_detections(gt, [det([10, 10, 50, 40], 0.9)])
        s = ev.summary()
        assert s["AP50"] == pytest.approx(1.0, abs=TOL)
        assert s["AP"] == pytest.approx(0.7, abs=TOL)
        assert s["AR100"] == pytest.approx(0.7, abs=TOL)
        assert s["APm"] == pytest.approx(0.7, abs=TOL)  # area 2500 is medium
        assert s["APs"] == -1 and s["APl"] == -1  # no gt in those ranges

    def test_false_positive_first_halves_precision(self):
        # dets: FP (0.9) then TP (0.8): after the TP precision is 1/2 at recall 1, and
        # the envelope makes every one of the 101 recall points 1/2
        gt = one_image([{"bbox": [0, 0, 100, 100]}])
        ev = evaluate_detections(gt, [det([300, 300, 50, 50], 0.9), det([0, 0, 100, 100], 0.8)])
        assert ev.summary()["AP50"] == pytest.approx(0.5, abs=TOL)
        assert ev.summary()["AR1"] == 0.0  # the one kept detection per image is the FP
        assert ev.summary()["AR10"] == pytest.approx(1.0)

    def test_detection_on_crowd_is_ignored(self):
        gt = one_image([{"bbox": [0, 0, 100, 100]}, {"bbox": [200, 200, 200, 200], "iscrowd": 1}])
        # the crowd IoU divides by the detection's area: a small box inside is 1.0
        dets = [det([250, 250, 10, 10], 0.99), det([0, 0, 100, 100], 0.5)]
        assert evaluate_detections(gt, dets).summary()["AP"] == pytest.approx(1.0, abs=TOL)

    def test_categories_without_ground_truth_are_minus_one(self):
        gt = one_image([{"bbox": [0, 0, 10, 10]}], cats=(1, 2))
        ev = evaluate_detections(gt, [det([0, 0, 10, 10], 0.5, cat=2)])
        assert (ev.precision[:, :, 1] == -1).all()
        assert ev.per_category_ap()[2] == -1.0
        assert ev.per_category_ap()[1] == 0.0  # gt, no detection: AP 0, not -1
        assert list(ev.summary()) == list(SUMMARY_NAMES)

    def test_no_results_at_all(self):
        # pycocotools' loadRes fails on an empty list; here it is AP 0 (documented)
        gt = one_image([{"bbox": [0, 0, 10, 10]}])
        ev = evaluate_detections(gt, [])
        assert ev.summary()["AP"] == 0.0 and ev.summary()["APm"] == -1

    def test_max_dets_truncation_per_image(self):
        # 3 exact detections of 3 objects; max_dets (1, 2, 3): AR1 = 1/3, AR10(=2) = 2/3
        anns = [{"bbox": [100 * k, 0, 50, 50]} for k in range(3)]
        dets = [det([100 * k, 0, 50, 50], 0.9 - 0.1 * k) for k in range(3)]
        s = evaluate_detections(one_image(anns), dets, max_dets=(1, 2, 3)).summary()
        assert s["AR1"] == pytest.approx(1 / 3) and s["AR10"] == pytest.approx(2 / 3)
        assert s["AR100"] == pytest.approx(1.0)


class TestProperties:
    def test_image_and_category_order_does_not_matter(self, rng):
        gt, res = synthetic_detections(11, n_images=20)
        ev = evaluate_detections(gt, res)
        g2 = copy.deepcopy(gt)
        rng.shuffle(g2["images"])
        rng.shuffle(g2["categories"])
        ev2 = evaluate_detections(g2, res)
        np.testing.assert_array_equal(ev.precision, ev2.precision)

    def test_seeded_determinism(self):
        a = evaluate_detections(*synthetic_detections(5, n_images=20))
        b = evaluate_detections(*synthetic_detections(5, n_images=20))
        np.testing.assert_array_equal(a.stats, b.stats)
        c = evaluate_detections(*synthetic_detections(6, n_images=20))
        assert not np.array_equal(a.stats, c.stats)

    def test_shifting_everything_keeps_the_metrics(self):
        gt, res = synthetic_detections(8, n_images=10)
        for a in gt["annotations"]:
            a["bbox"][0] += 1000.0
        for r in res:
            r["bbox"][0] += 1000.0
        a, b = evaluate_detections(gt, res), evaluate_detections(*synthetic_detections(8, 10))
        np.testing.assert_allclose(a.stats, b.stats, atol=1e-6)  # rounding of x only


class TestBadInput:
    def test_evaluate_arguments(self):
        gt = one_image([{"bbox": [0, 0, 10, 10]}])
        with pytest.raises(InputError, match="iou_type"):
            evaluate_detections(gt, [], iou_type="keypoints")
        with pytest.raises(InputError, match="annotation id 1 has no segmentation"):
            evaluate_detections(gt, [], iou_type="segm")
        with pytest.raises(InputError, match="max_dets must be increasing"):
            evaluate_detections(gt, [], max_dets=(10, 1, 100))
        with pytest.raises(InputError, match="image_id 9, which the ground truth does not"):
            evaluate_detections(gt, [det([0, 0, 1, 1], 0.5, img=9)])
        with pytest.raises(InputError, match="category_id 3"):
            evaluate_detections(gt, [det([0, 0, 1, 1], 0.5, cat=3)])
        with pytest.raises(InputError, match="score is nan; scores must be finite"):
            evaluate_detections(gt, [det([0, 0, 1, 1], float("nan"))])
        with pytest.raises(InputError, match="gt must be a CocoDataset"):
            evaluate_detections([1, 2], [])

    def test_empty_dataset_is_undefined_not_an_error(self):
        ev = evaluate_detections({"images": [], "categories": [], "annotations": []}, [])
        assert ev.precision.shape == (10, 101, 0, 4, 3) and (ev.stats == -1).all()


# ----------------------------------------------------------------------------- pictures


def test_pr_curves_png(tmp_path):
    from robopercept.imaging import read_image

    gt, res = synthetic_detections(2, n_images=20)
    ev = evaluate_detections(gt, res)
    img = pr_curves_picture(ev, names=coco_from_dict(gt).category_names())
    assert img.shape == (1000, 1600, 3) and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 5  # curves in several colours
    path = write_pr_curves(ev, tmp_path / "pr.png", iou_threshold=0.75)
    np.testing.assert_array_equal(read_image(path).shape, (1000, 1600, 3))
    with pytest.raises(InputError, match="iou_threshold must be one of"):
        pr_curves_picture(ev, iou_threshold=0.52)
    with pytest.raises(InputError, match=r"ending in \.png"):
        write_pr_curves(ev, tmp_path / "pr.jpg")


# ----------------------------------------------------------------------------- real data


def assert_self_evaluation_perfect(ds: CocoDataset, with_pycocotools: bool = True) -> None:
    """Ground truth as detections of score 1: every AP and the AR at the largest
    max_dets (set above the most boxes of one image) are 1, or -1 where an area range
    has no ground truth; AR1 and AR10 are below 1 where images hold more boxes."""
    res = results_from_ground_truth(ds)
    most = int(np.bincount(ds.image_ids - ds.image_ids.min()).max())
    md = (1, 10, max(100, most))
    ours = evaluate_detections(ds, res, max_dets=md)
    for name, s in ours.summary().items():
        if name not in ("AR1", "AR10"):
            assert s == -1 or s == pytest.approx(1.0, abs=TOL), name
    if with_pycocotools:
        ref = pycocotools_eval(coco_to_dict(ds), results_to_list(res), max_dets=md)
        # pycocotools' summarize asks for maxDets=100 by value for its first number (AP),
        # so with other max_dets it gives -1 there; ours uses max_dets[-1] as its other
        # 11 numbers do (documented in evaluate_detections)
        start = 0 if md[-1] == 100 else 1
        np.testing.assert_allclose(ours.stats[start:], ref.stats[start:], rtol=0, atol=TOL)
        np.testing.assert_allclose(ours.precision, ref.eval["precision"], rtol=0, atol=TOL)
        np.testing.assert_allclose(ours.recall, ref.eval["recall"], rtol=0, atol=TOL)


def test_segm_with_no_result_scores_like_bbox_with_none():
    # a model that found nothing (one epoch on three photos): AP 0, not an error about
    # "results[0]" (issue 46); the same numbers as the box evaluation of no result
    gt = one_image([{"bbox": [1, 1, 4, 4], "segmentation": [[1, 1, 5, 1, 5, 5, 1, 5]]}])
    segm = evaluate_detections(coco_from_dict(gt), [], "segm").stats
    bbox = evaluate_detections(coco_from_dict(gt), [], "bbox").stats
    np.testing.assert_array_equal(segm, bbox)
    assert segm[1] in (0.0, -1.0)
