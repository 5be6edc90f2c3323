"""COCO box evaluation on 5,000 images of synthetic detections: ours vs pycocotools vs
faster-coco-eval (``COCOeval_faster``), each from the same in-memory dicts (index
building and loading the results included), the 12 summary numbers asserted equal.

``synthetic_detections`` is also the generator of the parity tests
(``tests/nn/coco/test_evaluate.py``): it makes every case the COCO evaluation treats apart.
"""

from __future__ import annotations

import contextlib
import copy
import io
import time
from typing import Any

import numpy as np

from benchmarks._harness import Record


def synthetic_detections(
    seed: int, n_images: int = 60, n_categories: int = 5, crowded_image: bool = True
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A COCO ground-truth dict and a results list, seeded.

    Holds: images without ground truth and images without detections; crowd regions
    (about 5% of the ground truth, with detections on them); a category with no
    detections and one with no ground truth (non-consecutive category ids); box sides
    log-uniform over 3-400 px (small, medium and large, ``area`` below ``w h`` as for
    segmentations); scores rounded to 2 decimals (duplicates); false positives; and
    (``crowded_image``) one image with 150 detections.
    """
    gen = np.random.default_rng(seed)
    cat_ids = [1, 2, 4, 7, 9, 11, 15, 20][: max(n_categories, 2)]
    no_dets, no_gt = cat_ids[0], cat_ids[-1]
    images, anns, res = [], [], []
    aid = 1
    for img in range(1, n_images + 1):
        W, H = 640, 480
        images.append({"id": img, "file_name": f"{img:06d}.jpg", "width": W, "height": H})
        n_gt = 0 if gen.random() < 0.1 else int(gen.integers(1, 12))
        with_dets = gen.random() > 0.1 or (crowded_image and img == 3)
        for _ in range(n_gt):
            c = int(gen.choice(cat_ids[:-1]))
            w, h = np.exp(gen.uniform(np.log(3), np.log(400), 2))
            x, y = gen.uniform(0, W - w / 2), gen.uniform(0, H - h / 2)
            crowd = int(gen.random() < 0.05)
            box = [round(float(v), 2) for v in (x, y, w, h)]
            area = float(box[2] * box[3] * gen.uniform(0.5, 1.0))
            anns.append(
                {"id": aid, "image_id": img, "category_id": c, "bbox": box, "area": area,
                 "iscrowd": crowd}
            )  # fmt: skip
            aid += 1
            if c == no_dets or not with_dets:
                continue
            for _ in range(int(gen.integers(0, 3))):  # 0, 1 or 2 detections per object
                jit = gen.normal(0, 0.08, 4) * [w, h, w, h]
                if crowd:  # a part of the crowd region
                    jit = [gen.uniform(0, w / 2), gen.uniform(0, h / 2), -w / 2, -h / 2]
                b = [float(box[0] + jit[0]), float(box[1] + jit[1]),
                     float(max(box[2] + jit[2], 0.5)),
                     float(max(box[3] + jit[3], 0.5))]  # fmt: skip
                res.append({"image_id": img, "category_id": c, "bbox": b,
                            "score": round(float(gen.uniform(0.05, 1.0)), 2)})  # fmt: skip
        if not with_dets:
            continue
        n_fp = 150 if (crowded_image and img == 3) else int(gen.integers(0, 5))
        for _ in range(n_fp):
            w, h = np.exp(gen.uniform(np.log(3), np.log(300), 2))
            c = int(gen.choice(cat_ids[1:]))  # includes the category without ground truth
            res.append({"image_id": img, "category_id": c,
                        "bbox": [float(gen.uniform(0, W - w)), float(gen.uniform(0, H - h)),
                                 float(w), float(h)],
                        "score": round(float(gen.uniform(0.0, 0.9)), 2)})  # fmt: skip
    cats = [{"id": c, "name": f"class{c}", "supercategory": "thing"} for c in cat_ids]
    assert no_gt not in {a["category_id"] for a in anns}
    return {"images": images, "categories": cats, "annotations": anns}, res


def pycocotools_eval(
    gt: dict[str, Any],
    res: list[dict[str, Any]],
    faster: bool = False,
    max_dets: tuple[int, int, int] = (1, 10, 100),
    iou_type: str = "bbox",
) -> Any:
    """``COCOeval`` (or faster-coco-eval's ``COCOeval_faster``) on copies of the dicts,
    its prints silenced; returns the evaluator after summarize()."""
    with contextlib.redirect_stdout(io.StringIO()):
        if faster:
            from faster_coco_eval import COCO, COCOeval_faster

            g = COCO()
            g.dataset = copy.deepcopy(gt)
            g.createIndex()
            d = g.loadRes(copy.deepcopy(res))
            ev = COCOeval_faster(g, d, iou_type)
        else:
            from pycocotools.coco import COCO
            from pycocotools.cocoeval import COCOeval

            g = COCO()
            g.dataset = copy.deepcopy(gt)
            g.createIndex()
            d = g.loadRes(copy.deepcopy(res))
            ev = COCOeval(g, d, iou_type)
        ev.params.maxDets = list(max_dets)
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return ev


def _median_s(fn: Any, repeats: int) -> tuple[float, Any]:
    out = fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), out


def run(repeats: int) -> tuple[list[Record], dict[str, Any]]:
    from robopercept.nn.coco.evaluate import evaluate_detections

    repeats = max(1, min(repeats, 5))
    gt, res = synthetic_detections(0, n_images=5000, n_categories=8, crowded_image=True)
    # deep copies are made outside the timed region for every library
    copies = [(copy.deepcopy(gt), copy.deepcopy(res)) for _ in range(3)]

    def ours() -> Any:
        return evaluate_detections(*copies[0])

    def ref() -> Any:
        return pycocotools_eval(*copies[1])

    def fast() -> Any:
        return pycocotools_eval(*copies[2], faster=True)

    t_ours, e_ours = _median_s(ours, repeats)
    t_ref, e_ref = _median_s(ref, max(1, repeats // 2))
    t_fast, e_fast = _median_s(fast, repeats)
    d_ref = float(np.abs(e_ours.stats - np.asarray(e_ref.stats)).max())
    d_fast = float(np.abs(e_ours.stats - np.asarray(e_fast.stats)[:12]).max())
    assert d_ref < 1e-9, f"summary differs from pycocotools by {d_ref}"
    assert d_fast < 1e-9, f"summary differs from faster-coco-eval by {d_fast}"
    case = f"{len(gt['images'])} images, {len(gt['annotations'])} gt, {len(res)} dets"
    records = [
        Record("coco_eval", case, t_ours * 1e3, t_ref * 1e3, "pycocotools 2.x COCOeval",
               "max |stats difference| vs pycocotools", d_ref, 1.0,
               {"stats": e_ours.stats.tolist()}),
        Record("coco_eval", case, t_ours * 1e3, t_fast * 1e3, "faster-coco-eval COCOeval_faster",
               "max |stats difference| vs faster-coco-eval", d_fast, None),
    ]  # fmt: skip
    return records, {"repeats": repeats, "images": len(gt["images"]), "seed": 0}


if __name__ == "__main__":
    recs, settings = run(3)
    for r in recs:
        print(r.case, f"ours {r.ours_ms:.0f} ms, {r.reference} {r.ref_ms:.0f} ms, "
              f"ratio {r.ratio:.2f}, {r.accuracy} = {r.accuracy_value:.2g}")  # fmt: skip
