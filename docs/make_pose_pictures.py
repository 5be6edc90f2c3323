"""Make the pictures of docs/pose.md.

Run from the repository root (about two minutes on 2 cores; the networks are read from
MODELS)::

    python docs/make_pose_pictures.py [MODELS [DATA]]

MODELS is the folder of ``python -m benchmarks.pose_figures --only hrnet heatmap
deeppose keypointrcnn --seeds 0 --save MODELS`` (default ``src/robopercept/data``,
where the shipped networks are; panels whose files are absent are left out); DATA the
shared data folder (default ``../shared/data``). Writes to docs/img/:

- pose_figures.png: procedural figures with their ground truth (filled joints seen,
  rings hidden) and multi-person scenes with boxes;
- pose_real.png: the real COCO, MPII and imgaug keypoint files, read and drawn;
- pose_methods.png: pictorial structures, DeepPose, DeepPose with its cascade stage,
  SimpleBaseline and HRNet on the same test figures;
- pose_heatmaps.png: HRNet's heatmaps of one test figure;
- pose_3d.png: a test figure's 3-D pose by matching against the library, beside the
  truth (Procrustes-aligned), from two views;
- pose_keypointrcnn.png: Keypoint R-CNN on multi-person test scenes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from robopercept.imaging import read_image, write_image
from robopercept.nn.coco.dataset import read_coco_json
from robopercept.nn.pose.data import pose_sets, procedural_pose_scenes
from robopercept.nn.pose.inference import pose_arrays, predict_keypoints, refine_keypoints
from robopercept.nn.pose.io import read_imgaug_keypoints, read_mpii_json
from robopercept.nn.pose.library import default_pose_library
from robopercept.nn.pose.lifting import procrustes_align
from robopercept.nn.pose.networks import load_pose_model
from robopercept.nn.pose.pictorial_learn import PictorialStructures
from robopercept.nn.skeleton import COCO_17, MPII_16
from robopercept.viz.draw import draw_boxes
from robopercept.viz.pose import draw_skeleton, heatmap_grid, skeleton_3d_picture
from robopercept.viz.segmentation import panels_picture

OUT = Path("docs/img")
SK = MPII_16


def _draw(image: np.ndarray, keypoints: np.ndarray, **kw: object) -> np.ndarray:
    return draw_skeleton(image, keypoints, SK.links, flip_pairs=SK.flip_pairs, min_side=320, **kw)


def figures_picture() -> Path:
    sets = pose_sets("figures", 8, (128, 128), 5, test_images=8)
    pics = [_draw(sets.test.images[i], sets.test.keypoints[i]) for i in range(6)]
    scenes = procedural_pose_scenes(2, (192, 160), 3)
    for i in range(2):
        pic = draw_skeleton(
            scenes.images[i], scenes.keypoints[i], SK.links, flip_pairs=SK.flip_pairs, min_side=384
        )
        f = pic.shape[0] // scenes.images[i].shape[0]
        pics.append(draw_boxes(pic, _xywh(scenes.boxes[i] * f), color=(255, 255, 255)))
    titles = [f"figure {i + 1}" for i in range(6)] + ["scene 1", "scene 2"]
    top = panels_picture(pics[:4], titles[:4])
    bottom = panels_picture(pics[4:], titles[4:])
    return write_image(OUT / "pose_figures.png", _stack([top, bottom]))


def _xywh(boxes: np.ndarray) -> np.ndarray:
    b = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    return np.concatenate([b[:, :2], b[:, 2:] - b[:, :2]], 1)


def _stack(rows: list[np.ndarray]) -> np.ndarray:
    w = max(r.shape[1] for r in rows)
    padded = [np.pad(r, ((0, 8), (0, w - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    return np.concatenate(padded, 0)


def real_picture(data: Path) -> Path:
    pics, titles = [], []
    coco_dir = data / "detection" / "coco_keypoints_mmpose"
    coco = read_coco_json(coco_dir / "test_coco.json")
    for image in coco.images[:2]:
        sel = coco.image_ids == image.id
        im = read_image(coco_dir / image.file_name, mode="rgb")
        pics.append(
            draw_skeleton(im, coco.keypoints[sel], COCO_17.links, flip_pairs=COCO_17.flip_pairs)
        )
        titles.append(f"COCO {image.file_name}")
    mpii_dir = data / "detection" / "mpii_keypoints_mmpose"
    mpii = read_mpii_json(mpii_dir / "test_mpii.json")
    person = mpii.people[1]
    im = read_image(mpii_dir / person.image, mode="rgb")
    pics.append(draw_skeleton(im, person.keypoints, SK.links, flip_pairs=SK.flip_pairs))
    titles.append(f"MPII {person.image}")
    quokka_dir = data / "detection" / "imgaug_quokka"
    q = read_imgaug_keypoints(quokka_dir / "quokka_annotations.json")
    im = read_image(quokka_dir / "quokka.jpg", mode="rgb")
    pic = draw_skeleton(im, q.keypoints, [], labels=list(q.names), flip_pairs=q.skeleton.flip_pairs)
    pics.append(pic)
    titles.append("imgaug quokka")
    # one height per picture, two rows of two
    from skimage.transform import resize

    h = 420
    pics = [
        (resize(p, (h, round(p.shape[1] * h / p.shape[0])), anti_aliasing=True) * 255).astype(
            np.uint8
        )
        for p in pics
    ]
    rows = [panels_picture(pics[:2], titles[:2]), panels_picture(pics[2:], titles[2:])]
    return write_image(OUT / "pose_real.png", _stack(rows))


def methods_picture(models: Path) -> Path | None:
    sets = pose_sets("figures", 1000, (128, 128), 0, val_images=1, test_images=500)
    test = sets.test
    idx = [3, 11, 42]
    rows = []
    pictorial = PictorialStructures(SK, cell=4, random_state=0).fit(
        sets.train.images, sets.train.keypoints
    )
    methods: list[tuple[str, np.ndarray]] = [
        ("pictorial structures", pictorial.predict(test.images[idx]))
    ]
    for name, title in (
        ("deeppose", "DeepPose"),
        ("heatmap", "SimpleBaseline"),
        ("hrnet", "HRNet"),
    ):
        path = models / f"pose_{name}_figures.pt"
        if not path.is_file():
            continue
        net, info = load_pose_model(path)
        kp, _ = predict_keypoints(net, test.images[idx], flip_permutation=SK.flip_permutation())
        if info["refiners"]:
            methods.append((f"{title}, stage 1", kp))
            kp = refine_keypoints(test.images[idx], kp, info["refiners"])
            title = f"{title} + cascade"
        methods.append((title, kp))
    for k, i in enumerate(idx):
        pics = [_draw(test.images[i], m[k]) for _, m in methods]
        pics.append(_draw(test.images[i], test.keypoints[i]))
        rows.append(panels_picture(pics, [t for t, _ in methods] + ["ground truth"]))
    return write_image(OUT / "pose_methods.png", _stack(rows))


def heatmaps_and_3d(models: Path) -> list[Path]:
    path = models / "pose_hrnet_figures.pt"
    if not path.is_file():
        return []
    net, _ = load_pose_model(path)
    test = pose_sets("figures", 10, (128, 128), 0, test_images=20).test
    i = 7
    res = pose_arrays(net, [test.images[i]], flip_permutation=SK.flip_permutation())[0]
    grid = heatmap_grid(test.images[i], res.heatmaps, list(SK.joints), cols=8, tile_px=200)
    out = [write_image(OUT / "pose_heatmaps.png", grid)]
    library = default_pose_library(SK)
    lifted = library.lift(res.keypoints[None])[0]
    truth = test.joints3d[i] - test.joints3d[i][SK.index("pelvis")]
    aligned = procrustes_align(lifted, truth)
    assert isinstance(aligned, np.ndarray)
    # shown with up as up: the camera frame (x right, y down, z forward) as (x, z, -y)
    up = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    pic = skeleton_3d_picture(
        aligned @ up.T,
        SK.links,
        titles=("oblique", "from the camera"),
        reference=truth @ up.T,
        legend=("matched 3-D pose (aligned)", "ground truth"),
    )
    out.append(write_image(OUT / "pose_3d.png", pic))
    return out


def keypointrcnn_picture(models: Path) -> Path | None:
    from robopercept.nn.detection.zoo import detect_arrays, load_detector

    path = models / "pose_keypointrcnn_scenes.pt"
    if not path.is_file():
        return None
    model, _ = load_detector(path)
    scenes = procedural_pose_scenes(4, (192, 160), 99)
    pics = []
    for im in scenes.images:
        d = detect_arrays(model, [im])[0]
        keep = d["scores"] >= 0.5
        kp = d["keypoints"][keep]
        pic = draw_skeleton(
            im,
            kp[..., :2],
            SK.links,
            visible=np.full(kp.shape[:2], 2),
            flip_pairs=SK.flip_pairs,
            min_side=384,
        )
        f = pic.shape[0] // im.shape[0]
        pics.append(draw_boxes(pic, _xywh(d["boxes"][keep] * f), color=(255, 255, 255)))
    return write_image(
        OUT / "pose_keypointrcnn.png", panels_picture(pics, [f"scene {i + 1}" for i in range(4)])
    )


def main(argv: list[str]) -> int:
    models = Path(argv[0]) if argv else Path("src/robopercept/data")
    data = Path(argv[1]) if len(argv) > 1 else Path("../shared/data")
    OUT.mkdir(parents=True, exist_ok=True)
    written = [figures_picture()]
    if (data / "detection").is_dir():
        written.append(real_picture(data))
    written += [methods_picture(models), *heatmaps_and_3d(models), keypointrcnn_picture(models)]
    for p in written:
        if p is not None:
            print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
