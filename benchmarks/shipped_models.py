"""The shipped models that learnt from real data (issue 46), rebuilt with the figures of
their model cards (run ``python -m benchmarks.shipped_models --only PART --seeds 0
--save src/robopercept/data``; each run is merged into
``benchmarks/results/shipped_models.json``).

Parts (the card of each is :data:`robopercept.nn.shipped.MODEL_CARDS`):

- ``trees``: FCOS trained exactly as ``detection_figures``' ``trees-all`` (the
  DeepForest NEON tiles above the held-out strip of YELL crop2 and those of the YELL
  crop image, 85/15 train/validation by the seed); then its test-time augmentation
  chosen on the validation tiles (:func:`~robopercept.nn.detection.tta.choose_tta`:
  the best COCO AP of :data:`~robopercept.nn.detection.tta.TTA_GRID`, or none), and
  its score threshold on the same tiles through it
  (:func:`~robopercept.nn.detection.thresholds.choose_score_threshold`, F1 at IoU 0.5);
  then AP50 of the held-out strip run *as one image* (2299 x 495) through tiled
  inference (400 px windows, the training tile; overlap 100 px) and the augmentation,
  as ``nn detect STRIP.png --model trees --all-scores`` runs it, of the 12 held-out
  tiles and of the other sites' images (OSBS_029, SOAP_061), each whole; the same
  without augmentation as ``no_tta_*``. The strip holds 127 crowns, more than COCO's
  default 100 detections per image: ``strip_AP50`` keeps up to 300
  (``TREES_MAX_DETS``), ``strip_AP50_coco100`` is the figure under the default cap.
- ``nuclei``: the U-Net of ``segmentation_figures``' ``nuclei-unet`` (three quadrants
  of the StarDist image to train on, the fourth held out): foreground IoU and instance
  F1@0.5 of the held-out quadrant.
- ``nuclei-maskrcnn``: the Mask R-CNN of ``nuclei-maskrcnn`` on the same quadrants;
  its score threshold is chosen on the three training quadrants (the set is too small
  for a validation quadrant; stated on its card); mask AP50 of the held-out quadrant.
- ``digits``: ``resnet_small`` on scikit-learn's digits by ``robopercept nn train``'s
  own path (:func:`~robopercept.nn.classification.run.train_run`, stratified
  70/15/15 by the seed, best validation epoch kept), test accuracy.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks import detection_figures, segmentation_figures
from benchmarks._harness import figures_main, seeds_table
from robopercept.imaging import label_components
from robopercept.nn.classification.run import train_run
from robopercept.nn.coco.evaluate import evaluate_detections
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.detection.deepforest import deepforest_strip
from robopercept.nn.detection.tiling import detect_tiled
from robopercept.nn.detection.train import evaluate_detector
from robopercept.nn.detection.tta import choose_tta, wrap_tta
from robopercept.nn.detection.zoo import (
    calibrate_detector,
    detect_arrays,
    load_detector,
    save_detector,
)
from robopercept.nn.segmentation.data import nuclei_quadrants
from robopercept.nn.segmentation.metrics import match_instances
from robopercept.nn.segmentation.networks import predict_segmentation, save_segmenter
from robopercept.nn.train.checkpoint import load_checkpoint, save_checkpoint
from robopercept.nn.train.config import TrainConfig

NAME = "shipped_models"
TREES_PART = "trees-all"
#: tiled inference of the trees model: its training tile, a quarter of it shared
TREES_TILE, TREES_OVERLAP = 400, 100
#: the nuclei models' window: the quadrant side they were trained and scored on
NUCLEI_TILE = 256
#: the file each part writes in the --save folder (robopercept.nn.shipped's names)
FILES = {
    "trees": "detector_fcos_trees.pt",
    "nuclei": "segmenter_unet_nuclei.pt",
    "nuclei-maskrcnn": "segmenter_maskrcnn_nuclei.pt",
    "digits": "classifier_digits.pt",
}


def nuclei_inputs(clip: bool) -> dict[str, Any]:
    """What the nuclei models store about their inputs (the predictor applies it):
    their window, StarDist's per-image percentile normalisation of the grey image
    (clipped to [0, 1] where training clipped it), and that they learnt grey images."""
    return {
        "tile": NUCLEI_TILE,
        "input_normalize": {"percentile": [1.0, 99.8], "clip": clip},
        "input_colour": "grey",
    }


def built_by(part: str, seed: int) -> str:
    """The command that rebuilds ``part`` (stored in its checkpoint), with this
    process's torch threads (the arithmetic, so the weights, depend on them)."""
    return (
        f"python -m benchmarks.shipped_models --only {part} --seeds {seed} "
        f"--threads {torch.get_num_threads()} --save src/robopercept/data"
    )


#: detections per image the trees figures keep: the strip holds 127 crowns, more than
#: COCO's default cap of 100 (which would bound the recall at 100 / 127)
TREES_MAX_DETS = (1, 10, 300)


def coco_ap50(
    ds: DetectionDataset,
    detections: list[dict[str, np.ndarray]],
    max_dets: tuple[int, ...] = TREES_MAX_DETS,
) -> float:
    """COCO AP at IoU 0.5 (our evaluation, equal to pycocotools with
    ``params.maxDets = max_dets``) of per-image detections on ``ds``."""
    gt = ds.to_coco(masks=False)
    results = [
        {
            "image_id": int(gt.images[i].id),
            "category_id": int(lab),
            "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])],
            "score": float(s),
        }
        for i, d in enumerate(detections)
        for b, lab, s in zip(d["boxes"], d["labels"], d["scores"], strict=True)
    ]
    return float(evaluate_detections(gt, results, max_dets=max_dets).summary()["AP50"])


def calibrate_trees(path: Path, seed: int) -> dict[str, Any]:
    """Choose the trees model's score threshold on its validation tiles, measure the
    strip as one image and the other sites, and write them into the checkpoint at
    ``path`` (which holds the trained model of ``TREES_PART``, seed ``seed``)."""
    model, info = load_detector(path)
    model.eval()
    spec = detection_figures.PARTS[TREES_PART]
    _, val, tiles, cross = spec["data"](spec["n"], seed)
    # the test-time augmentation first (on the validation tiles), then the threshold
    # through it: fusion averages scores over the views, so it moves them
    tta, tta_table = choose_tta(model, val)
    net = wrap_tta(model, tta)
    cal = calibrate_detector(net, val)
    strip = deepforest_strip(detection_figures.TREES)
    nms = float(model.nms_thresh)
    others = {
        "tiles": tiles,  # the 12 held-out tiles of YELL crop2 and YELL crop
        **{k: v for k, v in cross.items() if k in ("OSBS_029", "SOAP_061")},
    }

    def figures(detector: torch.nn.Module, prefix: str = "") -> tuple[dict[str, float], float]:
        def tiled(image: np.ndarray) -> dict[str, np.ndarray]:
            return detect_tiled(
                lambda im: detect_arrays(detector, [im])[0], image, TREES_TILE, TREES_OVERLAP, nms
            )

        t0 = time.perf_counter()
        strip_dets = [tiled(strip.images[0])]
        seconds = time.perf_counter() - t0
        out = {
            f"{prefix}strip_AP50": round(coco_ap50(strip, strip_dets), 4),
            f"{prefix}strip_AP50_coco100": round(coco_ap50(strip, strip_dets, (1, 10, 100)), 4),
            **{
                f"{prefix}{name}_AP50": round(coco_ap50(ds, [tiled(im) for im in ds.images]), 4)
                for name, ds in others.items()
            },
        }
        return out, seconds

    test, seconds = figures(net)
    if tta is not None:  # the same model without it, for the record
        plain, plain_seconds = figures(model, "no_tta_")
        test.update(plain, no_tta_strip_seconds=round(plain_seconds, 1))
    extra = {k: v for k, v in info.items() if k not in ("kind", "settings", "classes")}
    extra.update(
        calibration=cal.to_dict(),
        tta=tta,
        tile=TREES_TILE,
        tile_overlap=TREES_OVERLAP,
        test={**info.get("test", {}), **test},
        built_by=built_by("trees", seed),
    )
    save_detector(path, model, info["kind"], info["settings"], info["classes"], **extra)
    return {  # (the row's "tta" is detection_figures' check of one view set)
        "shipped_tta": tta,
        "shipped_tta_table": tta_table[:6],
        "calibration": cal.to_dict(),
        "test": test,
        "strip_seconds": round(seconds, 1),
        "strip_truths": len(strip.boxes[0]),
    }


def trees(seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        row = detection_figures.run_one(TREES_PART, seed, progress, Path(tmp))
        trained = Path(row.pop("saved"))
        out = (save or Path(tmp)) / FILES["trees"]
        if trained != out:
            shutil.copyfile(trained, out)
        row.update(calibrate_trees(out, seed))
    if save is not None:
        row["saved"] = str(out)
    return row


def nuclei(seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    net, _, wall = segmentation_figures.nuclei_unet_model(seed, progress)
    s = nuclei_quadrants(segmentation_figures.NUCLEI)
    pred = predict_segmentation(net, s.test_image[None])[0].numpy()
    truth = s.test_mask
    fg_iou = float(((pred == 1) & (truth == 1)).sum() / ((pred == 1) | (truth == 1)).sum())
    components, _ = label_components(pred == 1, connectivity=4)
    m = match_instances(s.test_instances, components, 0.5)
    test = {"foreground_iou": round(fg_iou, 4), "instance_f1": round(m.f1, 4)}
    row: dict[str, Any] = {"train_seconds": round(wall, 1), "test": test}
    if save is not None:
        path = save / FILES["nuclei"]
        save_segmenter(
            path,
            net,
            "unet",
            segmentation_figures.NUCLEI_UNET,
            ["nucleus"],
            seed=seed,
            data="stardist-nuclei",
            **nuclei_inputs(clip=False),
            built_by=built_by("nuclei", seed),
            test=test,
        )
        row["saved"] = str(path)
    return row


def nuclei_maskrcnn(seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    model, _, wall = segmentation_figures.nuclei_maskrcnn_model(seed, progress)
    model.eval()
    train, test_set = segmentation_figures.nuclei_sets()
    cal = calibrate_detector(model, train)
    segm = evaluate_detector(model, test_set, iou_type="segm").summary()
    test = {"mask_AP50": round(float(segm["AP50"]), 4), "mask_AP": round(float(segm["AP"]), 4)}
    row: dict[str, Any] = {
        "train_seconds": round(wall, 1),
        "calibration": cal.to_dict(),
        "test": test,
    }
    if save is not None:
        path = save / FILES["nuclei-maskrcnn"]
        save_detector(
            path,
            model,
            "maskrcnn",
            segmentation_figures.NUCLEI_MASKRCNN,
            ["nucleus"],
            seed=seed,
            data="stardist-nuclei",
            **nuclei_inputs(clip=True),
            calibration=cal.to_dict(),
            calibrated_on="the three training quadrants (no validation quadrant)",
            built_by=built_by("nuclei-maskrcnn", seed),
            test=test,
        )
        row["saved"] = str(path)
    return row


def digits(seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    cfg = TrainConfig(epochs=40, lr=3e-3, batch_size=64, seed=seed, device="cpu")
    with tempfile.TemporaryDirectory() as tmp:
        res = train_run("digits", "resnet_small", Path(tmp) / "run", config=cfg, progress=progress)
        row: dict[str, Any] = {
            "train_seconds": round(res.seconds, 1),
            "best_epoch": res.history.best_epoch,
            "parameters": res.parameters,
            "test": {"accuracy": round(res.test.accuracy, 4), "images": res.test.n},
        }
        if save is not None:
            path = save / FILES["digits"]
            state = load_checkpoint(Path(tmp) / "run" / "checkpoint.best.pt")
            keep = {k: state[k] for k in ("model", "architecture") if k in state}
            save_checkpoint(
                path,
                {
                    **keep,
                    "data": "digits",
                    "seed": seed,
                    "test": row["test"],
                    "built_by": built_by("digits", seed),
                },
            )
            row["saved"] = str(path)
    return row


PARTS = {"trees": trees, "nuclei": nuclei, "nuclei-maskrcnn": nuclei_maskrcnn, "digits": digits}


def _run(part: str, seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    return {"part": part, "seed": seed, **PARTS[part](seed, progress, save)}


def _no_timing(part: str, epochs: int, threads: int) -> dict[str, Any]:
    raise SystemExit("shipped_models has no --time-epochs: see the figures scripts")


def main(argv: list[str] | None = None) -> int:
    return figures_main(
        argv,
        name=NAME,
        description=__doc__.splitlines()[0],
        parts=list(PARTS),
        run=_run,
        time_part=_no_timing,
        table=seeds_table,
        save_help="write each model to DIR (the shipped ones: --seeds 0 --save "
        "src/robopercept/data)",
    )


if __name__ == "__main__":
    raise SystemExit(main())
