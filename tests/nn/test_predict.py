"""One library path for predicting images (:mod:`robopercept.nn.predict`) and the
shipped-model tables (:mod:`robopercept.nn.shipped`).

Each kind runs its shipped model on the CPU on one procedural canvas (the data the
models were trained on, drawn with a test seed), and is checked against the direct
library call (:func:`~robopercept.nn.detection.zoo.detect_arrays`, ...: exactly equal, the
same arithmetic in the same order) and against what ``robopercept nn detect/segment/pose
IMAGE --json -o DIR`` prints and writes (equal JSON, byte-equal files).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.imaging import read_image, write_image  # noqa: E402
from robopercept.nn.detection.synthetic import procedural_detection_set  # noqa: E402
from robopercept.nn.detection.zoo import detect_arrays, load_detector  # noqa: E402
from robopercept.nn.pose.data import procedural_pose_set  # noqa: E402
from robopercept.nn.pose.inference import pose_arrays  # noqa: E402
from robopercept.nn.pose.networks import load_pose_model  # noqa: E402
from robopercept.nn.predict import (  # noqa: E402
    ImagePrediction,
    load_image_predictor,
    load_segment_model,
)
from robopercept.nn.segmentation.networks import segment_arrays  # noqa: E402
from robopercept.nn.shipped import (  # noqa: E402
    SHIPPED,
    resolve_model,
    shipped_model_path,
)
from tests.conftest import data_path  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def _as_png(tmp: Path, name: str, image: np.ndarray) -> Path:
    u8 = np.clip(np.round(np.asarray(image, np.float64) * 255), 0, 255).astype(np.uint8)
    return write_image(tmp / name, u8)


@pytest.fixture(scope="module")
def images(tmp_path_factory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("inputs")
    # the second test canvas: three shapes the shipped detectors find above their
    # stored thresholds (the first holds one small triangle that FCOS scores 0.51, under
    # its threshold 0.59)
    shapes = procedural_detection_set(2, (128, 128), rng=99).images[1]
    figure = procedural_pose_set(1, (128, 128), rng=99).images[0]
    return {
        "shapes": _as_png(tmp, "shapes.png", shapes),
        "figure": _as_png(tmp, "figure.png", figure),
    }


def _direct(kind: str, name: str, image: np.ndarray, thresh: float) -> dict[str, np.ndarray]:
    """The prediction by the plain library calls the command line made before."""
    path = shipped_model_path(kind, name)
    if kind == "detect":
        model, _ = load_detector(path)
        d = detect_arrays(model, [image])[0]
        keep = d["scores"] >= thresh
        return {k: v[keep] for k, v in d.items()}
    if kind == "segment":
        model, _, instance = load_segment_model(path)
        if instance:
            d = detect_arrays(model, [image])[0]
            keep = d["scores"] >= thresh
            return {k: v[keep] for k, v in d.items()}
        return {"labels": segment_arrays(model, [image])[0]}
    model, info = load_pose_model(path)
    sk = info["skeleton"]
    res = pose_arrays(
        model, [image], flip_permutation=sk.flip_permutation(), refiners=info["refiners"]
    )[0]
    return {"keypoints": res.keypoints, "scores": res.scores, "heatmaps": res.heatmaps}


CASES = [
    # kind, shipped name, input, command-line flags beyond the defaults
    ("detect", "fcos", "shapes", []),
    ("segment", "unet", "shapes", []),
    ("segment", "maskrcnn", "shapes", []),
    ("pose", "hrnet", "figure", ["--heatmaps", "--lift3d"]),
]


@pytest.mark.parametrize(("kind", "name", "which", "flags"), CASES)
def test_predictor_equals_the_library_call_and_the_command_line(
    kind, name, which, flags, images, tmp_path, capsys
):
    src = images[which]
    pose = kind == "pose"
    predictor = load_image_predictor(kind, name, device="cpu", heatmaps=pose, lift3d=pose)
    assert predictor.path == shipped_model_path(kind, name)
    pred = predictor.predict_file(src)
    image = read_image(src, mode="rgb")
    np.testing.assert_array_equal(pred.image, image)

    # the same arithmetic as the direct call, so exactly equal
    direct = _direct(kind, name, image, predictor.score_thresh)
    values = dict(pred.values)
    if pose:
        assert pred.joints == list(predictor.info["skeleton"].joints) and len(pred.joints) == 16
        assert values.pop("joints3d").shape == (16, 3)
    assert set(values) == set(direct)
    for key, v in direct.items():
        np.testing.assert_array_equal(values[key], v, err_msg=key)
    if kind == "detect" or "masks" in values:  # the shipped models find shapes on shapes
        assert len(values["boxes"]) >= 1

    # strict JSON, with the classes named
    rec = pred.record()
    json.dumps(rec, allow_nan=False)
    if kind == "detect":
        assert [r["category_id"] for r in rec["detections"]] == values["labels"].tolist()
        assert {r["class"] for r in rec["detections"]} <= set(pred.classes)
    elif "masks" in values:
        areas = [int(m.sum()) for m in values["masks"]]
        assert [r["area"] for r in rec["instances"]] == areas
    elif kind == "segment":
        assert sum(rec["pixels"].values()) == image.shape[0] * image.shape[1]
        assert len(rec["pixels"]) >= 2 and "background" in rec["pixels"]

    # what the command line prints and writes for the same image
    cli_out, lib_out = tmp_path / "cli", tmp_path / "lib"
    argv = ["nn", kind, str(src), "--model", name, "--device", "cpu", "--json"]
    assert main([*argv, *flags, "-o", str(cli_out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert (
        doc["model"].startswith(f"model: {name} (") and "trained on procedural data" in doc["model"]
    )
    printed = doc["results"]
    if pose:
        assert printed == [{"image": str(src), **rec}]
        with pytest.raises(InputError, match="use record"):
            pred.coco_results(1)
    else:
        assert printed == json.loads(json.dumps(pred.coco_results(1)))
    written = pred.write(lib_out, src.stem)
    pictures = pred.pictures(src.stem)
    assert [p.name for p in written] == list(pictures)
    assert sorted(p.name for p in cli_out.iterdir()) == sorted(pictures)
    for path in written:
        assert path.read_bytes() == (cli_out / path.name).read_bytes(), path.name
        mode = "index" if path.name.endswith("_labels.png") else None
        np.testing.assert_array_equal(read_image(path, mode=mode), pictures[path.name])


def test_semantic_record_counts_every_pixel_by_class_name():
    labels = np.array([[0, 0, 2], [2, 2, 2]])
    p = ImagePrediction(
        "segment", np.zeros((2, 3, 3), np.uint8), ["disc", "box"], {"labels": labels}
    )
    assert p.record() == {"pixels": {"background": 2, "box": 4}}
    lab = p.pictures("s")["s_labels.png"]
    assert lab.dtype == np.uint8 and lab.tolist() == labels.tolist()


def test_instance_label_image_puts_the_best_instance_on_top():
    masks = np.zeros((2, 2, 2), bool)
    masks[0, 0, :] = True  # best score, overlaps the second in (0, 1)
    masks[1, :, 1] = True
    values = {
        "masks": masks,
        "labels": np.array([1, 2]),
        "scores": np.array([0.9, 0.6]),
        "boxes": np.array([[0.0, 0, 1, 0], [1.0, 0, 1, 1]]),
    }
    p = ImagePrediction("segment", np.zeros((2, 2, 3), np.uint8), ["a", "b"], values)
    assert p.pictures("s")["s_labels.png"].tolist() == [[1, 1], [0, 2]]
    rows = p.record()["instances"]
    assert [(r["class"], r["area"], r["bbox"]) for r in rows] == [
        ("a", 2, [0.0, 0.0, 1.0, 0.0]),
        ("b", 2, [1.0, 0.0, 0.0, 1.0]),
    ]


def test_score_threshold_defaults_follow_the_commands():
    from robopercept.nn.train.checkpoint import load_checkpoint

    stored = load_checkpoint(shipped_model_path("detect", "fcos"))["calibration"]
    assert load_image_predictor("detect", device="cpu").score_thresh == stored["score_thresh"]
    seg = load_image_predictor("segment", "maskrcnn", device="cpu", score_thresh=0.8)
    assert seg.instance and seg.score_thresh == 0.8


def test_resolve_model_takes_run_folders_and_files(tmp_path):
    model = tmp_path / "run" / "model.pt"
    model.parent.mkdir()
    model.write_bytes(b"x")
    assert resolve_model("detect", tmp_path / "run") == model
    assert resolve_model("pose", str(model)) == model
    assert resolve_model("detect", "faster") == shipped_model_path("detect", "faster")
    for kind, table in SHIPPED.items():
        for name in table:
            assert shipped_model_path(kind, name).is_file(), (kind, name)


def test_bad_inputs_are_refused_with_the_fix(tmp_path):
    with pytest.raises(InputError, match="kind must be one of 'detect', 'segment', 'pose'"):
        load_image_predictor("classify")
    with pytest.raises(InputError, match="kind must be one of"):
        shipped_model_path("track")
    with pytest.raises(
        InputError, match="no shipped detect model 'yolo'; the shipped ones are trees, fcos, faster"
    ):
        shipped_model_path("detect", "yolo")
    with pytest.raises(InputError, match=r"MODEL: no such file: .*nope\.pt: give a run folder"):
        load_image_predictor("detect", tmp_path / "nope.pt")
    with pytest.raises(
        InputError,
        match=r"MODEL: no such file: .*model.pt.*\(nuclei, nuclei-maskrcnn, unet, maskrcnn\)",
    ):
        resolve_model("segment", tmp_path)  # a folder without model.pt
    with pytest.raises(InputError, match=r"tta \(--tta\) must be one of 'none', 'identity'"):
        load_image_predictor("detect", tta="rotate")
    with pytest.raises(InputError, match="--tta-scales"):
        load_image_predictor("detect", tta="hflip", tta_scales=[0.1])
    with pytest.raises(InputError, match="score_thresh"):
        load_image_predictor("detect", score_thresh=1.5)
    p = load_image_predictor("segment", device="cpu")
    with pytest.raises(InputError, match="channels-first"):
        p.predict(np.zeros((3, 32, 32), np.uint8))


def test_shipped_names_import_without_torch():
    code = "import robopercept.nn.shipped, sys; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.realdata
def test_real_photo_detections_equal_the_library_call():
    photo = data_path("detection", "imgaug_quokka", "quokka.jpg")
    predictor = load_image_predictor("detect", "fcos", device="cpu", score_thresh=0.0)
    pred = predictor.predict_file(photo)
    model, _ = load_detector(shipped_model_path("detect", "fcos"))
    direct = detect_arrays(model, [read_image(photo, mode="rgb")])[0]
    for key in ("boxes", "labels", "scores"):
        np.testing.assert_array_equal(pred.values[key], direct[key])
    json.dumps(pred.record(), allow_nan=False)


# ---------------------------------------------------------------- issue 46: one path
def test_a_predictor_is_called_on_a_path_string_an_array_or_a_list(images):
    from robopercept.nn import load_predictor

    p = load_predictor("fcos", device="cpu")
    path = str(images["shapes"])
    by_path = p(path)  # a str, as a user types it
    by_array = p.predict(read_image(path, mode="rgb"))
    both = p([path, Path(path)])
    assert isinstance(both, list) and len(both) == 2
    for pred in (by_array, *both):
        np.testing.assert_array_equal(pred.boxes, by_path.boxes)
        np.testing.assert_array_equal(pred.scores, by_path.scores)
    assert by_path.boxes.shape[1] == 4 and len(by_path.boxes) > 0
    assert by_path.class_names == [p.classes[k - 1] for k in by_path.labels]
    with pytest.raises(InputError, match="no masks"):
        _ = by_path.masks
    with pytest.raises(FileFormatError, match="no such file"):
        p(str(images["shapes"]) + ".missing")


def test_the_stored_threshold_is_the_default_and_all_scores_keeps_everything(images):
    from robopercept.nn.train.checkpoint import load_checkpoint

    stored = load_checkpoint(shipped_model_path("detect", "fcos"))["calibration"]
    p = load_image_predictor("detect", "fcos", device="cpu")
    assert p.score_thresh == stored["score_thresh"]
    every = load_image_predictor("detect", "fcos", device="cpu", all_scores=True)
    assert every.score_thresh == 0.0
    kept, allof = p(str(images["shapes"])), every(str(images["shapes"]))
    assert len(allof.scores) >= len(kept.scores)
    np.testing.assert_array_equal(allof.scores[allof.scores >= p.score_thresh], kept.scores)
    # an explicit threshold wins
    assert load_image_predictor("detect", "fcos", score_thresh=0.25).score_thresh == 0.25


def test_tiling_follows_the_model_and_can_be_turned_off():
    from robopercept.nn import load_predictor

    assert load_predictor("trees", device="cpu").tile == 400
    assert load_predictor("trees", device="cpu", tile=0).tile == 0
    assert load_predictor("fcos", device="cpu").tile == 0  # no window stored: whole images
    p = load_predictor("fcos", device="cpu", tile=64, overlap=16)
    assert (p.tile, p.overlap) == (64, 16)
    canvas = np.zeros((100, 150, 3), np.uint8)
    assert p(canvas).image.shape == (100, 150, 3)
    with pytest.raises(InputError, match="--tile"):
        load_predictor("fcos", tile=8)


def test_the_stored_tta_is_the_default_and_each_option_overrides_it():
    """The trees model ships the augmentation chosen on its validation tiles (its
    threshold was chosen through it); --tta none turns it off, --tta and --tta-scales
    replace one option each; a model without one runs plain unless asked."""
    from robopercept.nn import load_predictor
    from robopercept.nn.detection.tta import TestTimeAugmentation
    from robopercept.nn.train.checkpoint import load_checkpoint

    stored = load_checkpoint(shipped_model_path("detect", "trees"))["tta"]
    p = load_predictor("trees", device="cpu")
    assert isinstance(p.model, TestTimeAugmentation)
    assert p.tta == {**stored, "scales": tuple(stored["scales"])}
    assert (p.model.views, p.model.scales) == (stored["views"], tuple(stored["scales"]))
    off = load_predictor("trees", device="cpu", tta="none")
    assert off.tta is None and not isinstance(off.model, TestTimeAugmentation)
    assert load_predictor("trees", device="cpu", tta="hflip").tta["scales"] == p.tta["scales"]
    assert load_predictor("trees", device="cpu", tta_scales=[1]).tta["views"] == stored["views"]
    plain = load_predictor("fcos", device="cpu")
    assert plain.tta is None and not isinstance(plain.model, TestTimeAugmentation)
    assert load_predictor("fcos", device="cpu", tta_scales=[0.5, 1]).model.scales == (0.5, 1.0)
    # the same detections as the wrapper built by hand, tiled like the predictor
    image = np.random.default_rng(0).random((120, 90, 3))
    hand = detect_arrays(TestTimeAugmentation(off.model, "flips", scales=(0.9, 1.0)), [image])
    mine = load_predictor("trees", device="cpu", tta="flips", tta_scales=[0.9, 1], all_scores=True)
    assert mine.tta["iou_thresh"] == stored["iou_thresh"]
    if stored["iou_thresh"] is None:
        np.testing.assert_array_equal(mine(image).boxes, hand[0]["boxes"])


def test_load_predictor_reads_the_kind_of_every_model(tmp_path):
    from robopercept.nn import load_predictor

    assert load_predictor("digits").kind == "classify"
    assert load_predictor("pointnet").kind == "cloud"
    with pytest.raises(InputError, match="does not match"):
        load_predictor("trees", kind="segment")
    with pytest.raises(InputError, match="tile= is not an option of a classify model"):
        load_predictor("digits", tile=64)
    with pytest.raises(InputError, match="part segmentation network"):
        load_predictor("pointnet-parts")
    assert load_predictor(shipped_model_path("segment", "maskrcnn")).kind == "segment"
    assert load_predictor(shipped_model_path("pose", "hrnet")).kind == "pose"
    assert load_predictor(shipped_model_path("cloud", "dgcnn")).kind == "cloud"
    assert load_predictor(shipped_model_path("classify", "digits")).kind == "classify"


def test_device_auto_is_cuda_when_torch_sees_a_gpu_else_cpu(images, capsys):
    want = "cuda" if torch.cuda.is_available() else "cpu"
    p = load_image_predictor("detect", "fcos", device="auto")
    assert next(p.model.parameters()).device.type == want
    argv = ["nn", "detect", str(images["shapes"]), "--device", "auto", "--json"]
    assert main(argv) == 0
    assert json.loads(capsys.readouterr().out)["results"]
    with pytest.raises(InputError, match="'auto', 'cpu', 'cuda'"):
        load_image_predictor("detect", "fcos", device="gpu")
