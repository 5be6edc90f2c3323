"""Make the pictures of docs/detection.md with the two shipped procedural-set models.

Run from the repository root (about a minute on 2 cores)::

    python docs/make_detection_pictures.py [../shared/data/detection/deepforest_neon [TREES_MODEL]]

Writes to docs/img/:

- detection_proposals.png: the 150 best-ranked selective-search proposals on a real
  NEON aerial image (OSBS_029), with its hand-drawn crowns beside them;
- detection_anchors.png: Faster R-CNN's 9 anchors (3 sizes x 3 aspect ratios) at three
  cells of its stride-8 feature map, the grid of cells drawn;
- detection_rpn.png: a test image, the RPN's objectness (the highest over the 9
  anchors of each cell, sigmoid) and the 30 best proposals after NMS;
- detection_nms.png: FCOS's scored candidates (score >= 0.2) before and after NMS;
- detection_pr_curves.png: precision-recall per class of FCOS on the 200 test images;
- detection_samples.png: FCOS and Faster R-CNN detections on test images;
- detection_trees.png, only with TREES_MODEL (a trees FCOS saved by
  ``python -m benchmarks.detection_figures --only trees-fcos-blocks2 --seeds 0 --save DIR``):
  two tiles of the held-out strip, the hand-drawn crowns and the detections with
  score >= 0.3.

Images of 128 x 128 are enlarged 4x (nearest neighbour) so that boxes and captions
read at 1080p.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from robopercept.features.selective_search import selective_search
from robopercept.imaging import read_image, write_image
from robopercept.nn.coco.evaluate import write_pr_curves
from robopercept.nn.coco.voc import read_voc_xml
from robopercept.nn.detection.synthetic import procedural_detection_set
from robopercept.nn.detection.train import evaluate_detector
from robopercept.nn.detection.zoo import load_detector
from robopercept.viz.colormap import turbo
from robopercept.viz.detection import draw_detections
from robopercept.viz.draw import draw_boxes, draw_lines, draw_text

IMG = Path(__file__).resolve().parent / "img"
DATA = Path(__file__).resolve().parents[1] / "src" / "robopercept" / "data"
SCALE = 4


def _big(image: np.ndarray, k: int = SCALE) -> np.ndarray:
    im = np.asarray(image)
    if im.dtype != np.uint8:
        im = (np.clip(im, 0, 1) * 255 + 0.5).astype(np.uint8)
    return np.repeat(np.repeat(im, k, 0), k, 1)


def _xywh(boxes: np.ndarray, k: float = 1.0) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4) * k
    return np.c_[b[:, :2], b[:, 2:] - b[:, :2]]


def _row(pics: list[np.ndarray], gap: int = 8) -> np.ndarray:
    h = max(p.shape[0] for p in pics)
    out = [np.pad(p, ((0, h - p.shape[0]), (0, gap), (0, 0)), constant_values=255) for p in pics]
    return np.concatenate(out, 1)[:, :-gap]


def _title(pic: np.ndarray, text: str) -> np.ndarray:
    return draw_text(pic, text, (6, 6), size=22)


def _detections(image: np.ndarray, det: dict, classes: list[str], thresh: float) -> np.ndarray:
    keep = det["scores"] >= thresh
    return draw_detections(
        _big(image),
        det["boxes"][keep] * SCALE,
        det["labels"][keep],
        classes,
        scores=det["scores"][keep],
        width=3,
    )


def _as_tensor(image: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(image.transpose(2, 0, 1))).float()


def proposals(neon: Path) -> None:
    image = read_image(neon / "OSBS_029.png", mode="rgb")
    voc = read_voc_xml(neon / "OSBS_029.xml")
    gt = np.array([o.bbox for o in voc.objects], dtype=np.float64)
    xywh = selective_search(image, "fast", rng=0, max_proposals=150)
    k = 2
    left = draw_boxes(_big(image, k), _xywh(gt, k), color=(255, 255, 0), width=2)
    right = draw_boxes(_big(image, k), xywh * k, color=(0, 255, 255), width=2)
    pic = _row(
        [
            _title(left, f"hand-drawn crowns ({len(gt)})"),
            _title(right, "selective search: best 150 proposals"),
        ]
    )
    write_image(IMG / "detection_proposals.png", pic)


def anchors(faster: torch.nn.Module, image: np.ndarray) -> None:
    a = faster.rpn_outputs([_as_tensor(image)])[0]["anchors"].numpy()
    fh, fw = a.shape[:2]
    stride = image.shape[0] // fh
    h, w = image.shape[:2]
    pic = (_big(image).astype(np.float64) * 0.6).astype(np.uint8)
    lines = [[x * stride * SCALE, 0, x * stride * SCALE, h * SCALE] for x in range(fw + 1)]
    lines += [[0, y * stride * SCALE, w * SCALE, y * stride * SCALE] for y in range(fh + 1)]
    pic = draw_lines(pic, np.array(lines, dtype=np.float64), color=(90, 90, 90), width=1)
    colors = [(255, 80, 80), (80, 255, 80), (80, 160, 255)]
    for cell, col in zip(((3, 3), (8, 7), (12, 12)), colors, strict=True):
        pic = draw_boxes(pic, _xywh(a[cell[0], cell[1]], SCALE), color=col, width=2)
    pic = _title(pic, f"9 anchors at 3 of {fh}x{fw} cells, stride {stride}")
    write_image(IMG / "detection_anchors.png", pic)


def rpn(faster: torch.nn.Module, image: np.ndarray) -> None:
    out = faster.rpn_outputs([_as_tensor(image)])[0]
    objmap = out["objectness"].amax(-1).numpy()
    fh, fw = objmap.shape
    heat = np.repeat(
        np.repeat(turbo(objmap), image.shape[0] * SCALE // fh, 0), image.shape[1] * SCALE // fw, 1
    )
    p = out["proposals"][:30].numpy()
    pic = _row(
        [
            _title(_big(image), "test image"),
            _title(heat, "RPN objectness (max over 9 anchors)"),
            _title(
                draw_boxes(_big(image), _xywh(p, SCALE), color=(0, 255, 255), width=2),
                "30 best proposals after NMS",
            ),
        ]
    )
    write_image(IMG / "detection_rpn.png", pic)


@torch.no_grad()
def nms_picture(fcos: torch.nn.Module, image: np.ndarray, classes: list[str]) -> None:
    before = fcos.nms_thresh
    fcos.nms_thresh = 1.0  # IoU never exceeds 1: every candidate kept
    raw = fcos([_as_tensor(image)])[0]
    fcos.nms_thresh = before
    final = fcos([_as_tensor(image)])[0]
    thresh = 0.2
    raw_np = {k: v.numpy() for k, v in raw.items()}
    fin_np = {k: v.numpy() for k, v in final.items()}
    n_raw = int((raw_np["scores"] >= thresh).sum())
    n_fin = int((fin_np["scores"] >= thresh).sum())
    left = draw_detections(
        _big(image),
        raw_np["boxes"][raw_np["scores"] >= thresh] * SCALE,
        raw_np["labels"][raw_np["scores"] >= thresh],
        None,
        width=1,
    )
    pic = _row(
        [
            _title(left, f"before NMS: {n_raw} candidates"),
            _title(_detections(image, fin_np, classes, thresh), f"after NMS: {n_fin}"),
        ]
    )
    write_image(IMG / "detection_nms.png", pic)


def trees_picture(neon: Path, model_path: Path) -> None:
    from robopercept.nn.detection.deepforest import deepforest_tiles

    model, info = load_detector(model_path)
    model.nms_thresh = info["settings"].get("nms_thresh", model.nms_thresh)
    test = deepforest_tiles(neon).test
    pics = []
    for i in (1, 4):
        image = test.images[i]
        with torch.no_grad():
            det = model([_as_tensor(image)])[0]
        keep = (det["scores"] >= 0.3).numpy()
        k = 2
        pic = draw_boxes(_big(image, k), _xywh(test.boxes[i], k), color=(255, 255, 0), width=3)
        pic = draw_boxes(pic, _xywh(det["boxes"].numpy()[keep], k), color=(0, 255, 255), width=2)
        pics.append(
            _title(
                pic,
                f"tile {i}: crowns (yellow) {len(test.boxes[i])}, "
                f"detections >= 0.3 (cyan) {int(keep.sum())}",
            )
        )
    write_image(IMG / "detection_trees.png", _row(pics))


def main() -> None:
    neon = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/detection/deepforest_neon")
    torch.set_num_threads(2)
    fcos, info = load_detector(DATA / "detector_fcos_shapes.pt")
    faster, _ = load_detector(DATA / "detector_faster_shapes.pt")
    classes = list(info["classes"])
    test = procedural_detection_set(200, (128, 128), rng=99)
    image = test.images[3]
    if neon.is_dir():
        proposals(neon)
    else:
        print(f"{neon} missing: detection_proposals.png not made")
    if len(sys.argv) > 2 and neon.is_dir():
        trees_picture(neon, Path(sys.argv[2]))
    anchors(faster, image)
    rpn(faster, image)
    nms_picture(fcos, image, classes)
    ev = evaluate_detector(fcos, test)
    write_pr_curves(ev, IMG / "detection_pr_curves.png", names=dict(enumerate(classes, 1)))
    rows = []
    for model, name in ((fcos, "FCOS"), (faster, "Faster R-CNN")):
        with torch.no_grad():
            out = model([_as_tensor(test.images[i]) for i in range(4)])
        dets = [{k: v.numpy() for k, v in d.items()} for d in out]
        pics = [_detections(test.images[i], dets[i], classes, 0.3) for i in range(4)]
        rows.append(_row([_title(pics[0], name), *pics[1:]]))
    write_image(IMG / "detection_samples.png", np.concatenate(rows, 0))
    print(f"FCOS test mAP@0.5 {ev.stats[1]:.3f}, mAP@[.5:.95] {ev.stats[0]:.3f}")


if __name__ == "__main__":
    main()
