"""Issue 28's accuracy figures for 2-D and 3-D pose, trained here on the CPU (run
``python -m benchmarks.pose_figures --only PART --seeds 0 1 2``; each run is merged
into ``benchmarks/results/pose_figures.json`` and the table printed).

Every run draws its weights from ``torch.manual_seed(seed)`` and trains with the
seed's data order; the epoch is picked on the validation split, nothing on the test
split.

Parts (single-person parts on :func:`~robopercept.nn.pose.data.pose_sets` ``"figures"``,
128 x 128, training seed ``seed``, validation ``1000 + seed``, test ``99``):

- ``hrnet``, ``heatmap``: the HRNet-style network and the SimpleBaseline network,
  Gaussian heatmaps (sigma 2 cells at stride 4), flip test, quadratic decoding.
- ``deeppose``: DeepPose's regression network, then one cascade stage trained on its
  estimates; PCK reported without (``PCK@0.1_stage1``) and with the stage.
- ``pictorial``: pictorial structures (HOG-like cell descriptors, a logistic
  appearance model per joint, Gaussian springs, exact inference by the generalized
  distance transform): the pre-deep-learning baseline.
- ``keypointrcnn``: Keypoint R-CNN on :func:`~robopercept.nn.pose.data.procedural_pose_scenes`
  (1-3 figures per 192 x 160 image): COCO keypoint AP with MPII's sigmas.
- ``lift3d``: 3-D pose from the *true* 2-D joints of the test figures, by matching
  against a library of projected 3-D poses, and by the lifting MLP: PA-MPJPE (mm).

PCK@alpha counts a joint found within alpha times the person's box diagonal (mmpose's
mean over joints); OKS AP is our COCO keypoint evaluation (equal to pycocotools) with
MPII's sigmas, one detection per test image scored by its mean joint score.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks._harness import figures_main, seeds_table, timing_row
from robopercept.nn.pose.data import pose_sets, procedural_pose_scenes
from robopercept.nn.pose.evaluate import PoseEvaluation, evaluate_pose, joint_threshold
from robopercept.nn.pose.inference import predict_keypoints
from robopercept.nn.pose.networks import DeepPoseRefiner, build_pose_model, save_pose_model
from robopercept.nn.pose.train import train_cascade, train_pose
from robopercept.nn.train.config import TrainConfig

NAME = "pose_figures"
SIZE = (128, 128)
#: single-person budget: training images, epochs, batch size, AdamW learning rate (a
#: trial of HRNet on 2,000 figures for 8 epochs reached validation PCK@0.1 0.871 in
#: 246 s; the softmax heatmap loss, as MSE stayed at PCK 0.19 after 8 epochs)
TRAIN = {"images": 3000, "epochs": 14, "batch_size": 32, "lr": 3e-3}
#: epochs of DeepPose's cascade stage (on the same images)
STAGE_EPOCHS = 8
#: the networks' settings
MODELS = {
    "hrnet": {"width": 16, "blocks": 2},
    "heatmap": {"width": 16},
    "deeppose": {"width": 16, "image_size": list(SIZE)},
}
#: test figures (seed 99) and validation figures (seed 1000 + seed)
N_TEST, N_VAL = 500, 200


def _sets(seed: int, images: int | None = None) -> Any:
    return pose_sets(
        "figures", images or TRAIN["images"], SIZE, seed, val_images=N_VAL, test_images=N_TEST
    )


def _cfg(seed: int, epochs: int | None = None) -> TrainConfig:
    return TrainConfig(
        epochs=epochs or TRAIN["epochs"],
        batch_size=TRAIN["batch_size"],
        lr=TRAIN["lr"],
        device="cpu",
        seed=seed,
    )


def _flops(model: torch.nn.Module, shape: tuple[int, ...]) -> int:
    from torch.utils.flop_counter import FlopCounterMode

    model.eval()
    with torch.no_grad(), FlopCounterMode(display=False) as counter:
        model(torch.zeros(shape))
    return int(counter.get_total_flops())


def _latency_ms(fn: Callable[[], object], repeats: int = 20) -> float:
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.no_grad():
            fn()
            times = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t0)
    finally:
        torch.set_num_threads(threads)
    return 1000 * statistics.median(times)


def _scores(ev: PoseEvaluation) -> dict[str, float]:
    return {
        "PCK@0.05": round(ev.pck[0.05], 4),
        "PCK@0.1": round(ev.pck[0.1], 4),
        "PCK@0.2": round(ev.pck[0.2], 4),
        "OKS_AP": round(float(ev.oks.stats[0]), 4),
        "OKS_AP50": round(float(ev.oks.stats[1]), 4),
    }


def network(part: str, seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """A single-person network (``hrnet``, ``heatmap`` or ``deeppose`` with one cascade
    stage) trained on the figures and scored on the test figures."""
    sets = _sets(seed)
    sk = sets.train.skeleton
    settings = MODELS[part]
    torch.manual_seed(seed)
    net = build_pose_model(part, sk.num_joints, **settings)
    t0 = time.perf_counter()
    hist = train_pose(net, sets.train, _cfg(seed), val=sets.val, skeleton=sk, progress=progress)
    refiners: list[DeepPoseRefiner] = []
    row: dict[str, Any] = {}  # DeepPose: the first stage alone, the cascade's validation
    if part == "deeppose":
        first = evaluate_pose(net, sets.test)
        row["stage1"] = _scores(first)
        refiners, (h2,) = train_cascade(
            net, sets.train, 1, _cfg(seed, STAGE_EPOCHS), val=sets.val, crop=32.0, width=16,
            progress=progress,
        )  # fmt: skip
        row["stage2_val"] = h2.val
    wall = time.perf_counter() - t0
    ev = evaluate_pose(net, sets.test, refiners=refiners)
    no_flip = evaluate_pose(net, sets.test, refiners=refiners, flip=False)
    x = torch.rand((1, 3, *SIZE[::-1]), generator=torch.Generator().manual_seed(0))
    if save is not None:
        save_pose_model(
            save / f"pose_{part}_figures.pt",
            net,
            part,
            settings,
            sk,
            refiners=refiners,
            seed=seed,
            calibration=joint_threshold(net, sets.val, refiners=refiners).to_dict(),
            built_by=f"python -m benchmarks.pose_figures --only {part} --seeds {seed} --save DIR",
            test=_scores(ev),
        )
    return {
        "model": part,
        "settings": settings,
        "train": TRAIN,
        "images": {"train": len(sets.train), "val": len(sets.val), "test": len(sets.test)},
        "parameters": sum(p.numel() for p in net.parameters())
        + sum(p.numel() for r in refiners for p in r.parameters()),
        "flops_128": _flops(net, (1, 3, *SIZE[::-1])),
        "latency_ms_128": round(
            _latency_ms(lambda: predict_keypoints(net, x, flip_permutation=None)), 2
        ),
        "train_seconds": round(wall, 1),
        "val": hist.val,
        "best_epoch": hist.best_epoch,
        "test": {**_scores(ev), "PCK@0.1_no_flip": round(no_flip.pck[0.1], 4)},
        **row,
    }


def pictorial(seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """Pictorial structures fitted on 1,000 training figures, scored on the test set."""
    from robopercept.nn.pose.metrics import bbox_diagonal, pck
    from robopercept.nn.pose.pictorial_learn import PictorialStructures

    del progress, save
    sets = _sets(seed, images=1000)
    sk = sets.train.skeleton
    model = PictorialStructures(sk, cell=4, random_state=seed)
    t0 = time.perf_counter()
    model.fit(sets.train.images, sets.train.keypoints)
    wall = time.perf_counter() - t0
    pred = model.predict(sets.test.images)
    diag = bbox_diagonal(sets.test.boxes, "xyxy")
    truth = sets.test.keypoints
    t1 = time.perf_counter()
    model.predict(sets.test.images[:20])
    per_image = (time.perf_counter() - t1) / 20
    return {
        "model": "pictorial",
        "images": {"train": len(sets.train), "test": len(sets.test)},
        "train_seconds": round(wall, 1),
        "latency_ms_128": round(1000 * per_image, 2),
        "test": {
            f"PCK@{a:g}": round(float(pck(pred, truth, None, a, diag).mean), 4)
            for a in (0.05, 0.1, 0.2)
        },
    }


#: the multi-person detector: settings and budget
KEYPOINT_RCNN = {
    "width": 16,
    "anchor_sizes": (24.0, 48.0, 96.0),
    "aspect_ratios": (1.0, 2.0, 3.0),
    "keypoint_channels": 64,
    "keypoint_convs": 4,
}
KEYPOINT_RCNN_TRAIN = {"images": 1200, "epochs": 12, "batch_size": 4, "lr": 1e-3}


def keypointrcnn(seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """Keypoint R-CNN on multi-person procedural scenes: keypoint AP (OKS, MPII sigmas)."""
    from robopercept.nn.detection.train import evaluate_detector, train_detector
    from robopercept.nn.detection.zoo import build_detector, save_detector
    from robopercept.nn.skeleton import MPII_16

    b = KEYPOINT_RCNN_TRAIN
    train = procedural_pose_scenes(b["images"], (192, 160), seed)
    val = procedural_pose_scenes(100, (192, 160), 1000 + seed)
    test = procedural_pose_scenes(200, (192, 160), 99)
    model = build_detector(
        "keypointrcnn", 1, seed=seed, num_keypoints=MPII_16.num_joints, **KEYPOINT_RCNN
    )
    cfg = TrainConfig(
        epochs=b["epochs"], batch_size=b["batch_size"], lr=b["lr"], device="cpu", seed=seed
    )
    t0 = time.perf_counter()
    hist = train_detector(
        model,
        train,
        cfg,
        progress=progress,
        val=val,
        val_every=max(1, b["epochs"] // 6),
        val_iou_type="keypoints",
        val_sigmas=MPII_16.sigmas,
    )
    wall = time.perf_counter() - t0
    kp = evaluate_detector(model, test, iou_type="keypoints", sigmas=MPII_16.sigmas)
    box = evaluate_detector(model, test)
    if save is not None:
        save_detector(
            save / "pose_keypointrcnn_scenes.pt",
            model,
            "keypointrcnn",
            {"num_keypoints": MPII_16.num_joints, **KEYPOINT_RCNN},
            ["person"],
            seed=seed,
            skeleton=MPII_16.to_dict(),
            built_by=f"python -m benchmarks.pose_figures --only keypointrcnn --seeds {seed} "
            "--save DIR",
        )
    return {
        "model": "keypointrcnn",
        "settings": KEYPOINT_RCNN,
        "train": b,
        "people": {"train": train.n_boxes, "test": test.n_boxes},
        "parameters": sum(p.numel() for p in model.parameters()),
        "train_seconds": round(wall, 1),
        "val": hist.val,
        "best_epoch": hist.best_epoch,
        "test": {
            "OKS_AP": round(float(kp.stats[0]), 4),
            "OKS_AP50": round(float(kp.stats[1]), 4),
            "box_AP50": round(float(box.stats[1]), 4),
        },
    }


#: the 3-D comparison: library poses (times 16 views) and the MLP's training
LIFT = {"poses": 2000, "views_per_pose": 16, "k": 5, "mlp_width": 256, "mlp_blocks": 2,
        "mlp_epochs": 10, "mlp_noise_px": 2.0}  # fmt: skip


def lift3d(seed: int, progress: bool, save: Path | None = None) -> dict[str, Any]:
    """3-D from the test figures' 2-D joints (true, and with 2 px noise): matching
    against a library of projected poses (the course's recipe) vs the lifting MLP
    trained on the same library's pairs; PA-MPJPE and MPJPE (root-relative) in mm."""
    from robopercept.nn.pose.data import random_poses_3d
    from robopercept.nn.pose.library import PoseLibrary
    from robopercept.nn.pose.lifting import LiftingMLP, mpjpe, pa_mpjpe, train_lifter
    from robopercept.nn.pose.views import PELVIS, random_views

    del progress, save
    test = _sets(seed, images=10).test
    truth = test.joints3d - test.joints3d[:, PELVIS : PELVIS + 1]
    clean = test.keypoints[..., :2]
    noisy = clean + np.random.default_rng(seed).normal(0.0, 2.0, clean.shape)
    library_poses = random_poses_3d(LIFT["poses"], rng=seed)
    t0 = time.perf_counter()
    library = PoseLibrary(
        library_poses, views_per_pose=LIFT["views_per_pose"], rng=seed, k=LIFT["k"]
    )
    t_lib = time.perf_counter() - t0
    pairs = random_views(library_poses, LIFT["views_per_pose"], rng=seed)
    # the MLP sees 2-D poses at the figures' pixel scale (100 px tall), with noise
    scale = 100.0 / np.ptp(pairs.keypoints2d[..., 1], axis=1)[:, None, None]
    mlp = LiftingMLP(16, width=LIFT["mlp_width"], blocks=LIFT["mlp_blocks"], random_state=seed)
    t0 = time.perf_counter()
    train_lifter(
        mlp,
        pairs.keypoints2d * scale,
        pairs.joints3d,
        epochs=LIFT["mlp_epochs"],
        random_state=seed,
        noise=LIFT["mlp_noise_px"],
    )
    t_mlp = time.perf_counter() - t0
    mean_pose = np.broadcast_to(library.joints3d.mean(0), truth.shape)
    out: dict[str, float] = {}
    for name, kp in (("", clean), ("_noisy", noisy)):
        for method, pred in (("matching", library.lift(kp)), ("mlp", mlp.lift(kp))):
            out[f"PA-MPJPE_mm_{method}{name}"] = round(1000 * pa_mpjpe(pred, truth), 1)
            out[f"MPJPE_mm_{method}{name}"] = round(1000 * mpjpe(pred, truth), 1)
    out["PA-MPJPE_mm_mean_pose"] = round(1000 * pa_mpjpe(mean_pose, truth), 1)
    return {
        "model": "lift3d",
        "settings": LIFT,
        "library_entries": len(library),
        "build_seconds": {"library": round(t_lib, 1), "mlp": round(t_mlp, 1)},
        "test": out,
    }


def time_part(part: str, epochs: int, threads: int) -> dict[str, Any]:
    """The training time of a single-person network, measured on ``epochs`` epochs of
    its seed-0 run plus one validation pass, extrapolated (run alone on the machine)."""
    if part not in MODELS:
        raise SystemExit(f"--time-epochs: times hrnet, heatmap and deeppose; got {part}")
    sets = _sets(0)
    sk = sets.train.skeleton
    torch.manual_seed(0)
    net = build_pose_model(part, sk.num_joints, **MODELS[part])
    t0 = time.perf_counter()
    train_pose(net, sets.train, _cfg(0, epochs), skeleton=sk, progress=False)
    per_epoch = (time.perf_counter() - t0) / epochs
    t0 = time.perf_counter()
    predict_keypoints(net, sets.val.images)
    per_val = time.perf_counter() - t0
    full = TRAIN["epochs"]
    return timing_row(part, threads, epochs, per_epoch, per_val, full, 1)


PARTS: dict[str, Callable[..., dict[str, Any]]] = {
    "hrnet": lambda seed, progress, save: network("hrnet", seed, progress, save),
    "heatmap": lambda seed, progress, save: network("heatmap", seed, progress, save),
    "deeppose": lambda seed, progress, save: network("deeppose", seed, progress, save),
    "pictorial": pictorial,
    "keypointrcnn": keypointrcnn,
    "lift3d": lift3d,
}


def _run(part: str, seed: int, progress: bool, save: Path | None) -> dict[str, Any]:
    row = {"part": part, "seed": seed, "threads": torch.get_num_threads()}
    row.update(PARTS[part](seed, progress, save))
    return row


def main(argv: list[str] | None = None) -> int:
    return figures_main(
        argv,
        name=NAME,
        description=__doc__.splitlines()[0],
        parts=list(PARTS),
        run=_run,
        time_part=time_part,
        table=seeds_table,
        save_help="write the networks to DIR/pose_PART_figures.pt (the shipped ones: "
        "--only hrnet --seeds 0 --save src/robopercept/data)",
    )


if __name__ == "__main__":
    raise SystemExit(main())
