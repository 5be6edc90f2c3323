"""Region proposals: our selective search (fast mode) vs OpenCV-contrib's
``ximgproc.segmentation`` selective search (``switchToSelectiveSearchFast``) on the NEON
tree images of ``../shared/data/detection/deepforest_neon`` (the two 400x400 tiles and
the smaller YELL crop at half size), with the recall of the hand-drawn crowns at IoU 0.5;
and our Felzenszwalb segmentation vs ``skimage.segmentation.felzenszwalb`` on the
astronaut (labels asserted equal).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._harness import Record, paired_ms

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "detection"
IMAGES = (("OSBS_029", 1), ("SOAP_061", 1), ("2019_YELL_2_541000_4977000_image_crop", 2))


def recall(gt_xyxy: np.ndarray, boxes_xywh: np.ndarray, thr: float = 0.5) -> float:
    """Fraction of ground-truth boxes matched by a proposal at IoU >= ``thr``."""
    b = np.asarray(boxes_xywh, dtype=float)
    bx = np.c_[b[:, 0], b[:, 1], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]]
    lo = np.maximum(gt_xyxy[:, None, :2], bx[None, :, :2])
    hi = np.minimum(gt_xyxy[:, None, 2:], bx[None, :, 2:])
    inter = np.prod(np.clip(hi - lo, 0, None), axis=2)
    a = np.prod(gt_xyxy[:, 2:] - gt_xyxy[:, :2], axis=1)
    c = np.prod(bx[:, 2:] - bx[:, :2], axis=1)
    return float(((inter / (a[:, None] + c[None] - inter)).max(1) >= thr).mean())


def run(repeats: int) -> tuple[list[Record], dict[str, Any]]:
    import cv2
    from skimage import data
    from skimage.segmentation import felzenszwalb as sk_felzenszwalb

    from robopercept.features import selective_search
    from robopercept.imaging import felzenszwalb, read_image
    from robopercept.nn.coco.voc import read_voc_xml

    repeats = max(1, min(repeats, 3))
    records = []
    astro = data.astronaut()
    t_ours, t_ref = paired_ms(
        lambda: felzenszwalb(astro, 100, 0.8, 50),
        lambda: sk_felzenszwalb(astro, 100, 0.8, 50),
        repeats=max(repeats, 5),
        warmup=1,
    )
    same = np.array_equal(felzenszwalb(astro, 100, 0.8, 50), sk_felzenszwalb(astro, 100, 0.8, 50))
    assert same, "labels differ from scikit-image"
    records.append(
        Record("felzenszwalb", "astronaut 512x512, scale 100", t_ours, t_ref,
               "skimage 0.26 felzenszwalb", "labels equal (1 = yes)", float(same), 2.0)
    )  # fmt: skip
    for name, step in IMAGES:
        folder = DATA / "deepforest_neon"
        img = np.ascontiguousarray(read_image(folder / f"{name}.png")[::step, ::step, :3])
        gt = np.array([o.bbox for o in read_voc_xml(folder / f"{name}.xml").objects]) / step
        bgr = np.ascontiguousarray(img[..., ::-1])
        out: dict[str, Any] = {}

        def ours(img: np.ndarray = img, out: dict[str, Any] = out) -> None:
            out["ours"] = selective_search(img, "fast", rng=0)

        def ref(bgr: np.ndarray = bgr, out: dict[str, Any] = out) -> None:
            cv2.setNumThreads(1)
            ss = cv2.ximgproc.segmentation.createSelectiveSearchSegmentation()
            ss.setBaseImage(bgr)
            ss.switchToSelectiveSearchFast()
            out["ref"] = ss.process()

        t_ours, t_ref = paired_ms(ours, ref, repeats=repeats, warmup=0)
        r_ours, r_ref = recall(gt, out["ours"]), recall(gt, out["ref"])
        records.append(
            Record("selective_search", f"{name} {img.shape[1]}x{img.shape[0]}, {len(gt)} gt",
                   t_ours, t_ref, "OpenCV-contrib ximgproc fast (1 thread)",
                   "recall@IoU0.5 ours", r_ours, None,
                   {"recall_opencv": r_ref, "proposals_ours": len(out["ours"]),
                    "proposals_opencv": len(out["ref"])})
        )  # fmt: skip
    return records, {"repeats": repeats, "mode": "fast", "seed": 0}


if __name__ == "__main__":
    recs, settings = run(1)
    for r in recs:
        print(r.case, f"ours {r.ours_ms:.0f} ms, {r.reference} {r.ref_ms:.0f} ms, "
              f"ratio {r.ratio:.2f}, {r.accuracy} = {r.accuracy_value:.3g}, {r.extra}")  # fmt: skip
