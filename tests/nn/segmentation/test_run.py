"""The segmentation run (issue 45): data by name with errors naming the flags, a tiny
train_run writing the run folder and refusing to replace it, Ctrl-C keeping the last
epoch, and evaluate_run scoring a saved model as the run did."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError, RunExistsError  # noqa: E402
from robopercept.nn.detection.zoo import build_detector  # noqa: E402
from robopercept.nn.segmentation.data import SegmentationSets, segmentation_sets  # noqa: E402
from robopercept.nn.segmentation.metrics import (  # noqa: E402
    segmentation_confusion,
    segmentation_scores,
)
from robopercept.nn.segmentation.networks import load_segmenter, segment_arrays  # noqa: E402
from robopercept.nn.segmentation.run import (  # noqa: E402
    RUN_FILES,
    TrainConfig,
    evaluate_run,
    load_segmentation_data,
    resolve_segment_model,
    score_segmentation,
    train_run,
)
from tests.cli.nn_runs import ctrl_c, ctrl_c_after_first_epoch, weights  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

DATA = {"images": 6, "size": (32, 32)}
CFG = TrainConfig(epochs=2, batch_size=4, lr=5e-3, device="cpu")
RUN = {"model": "naive", "config": CFG, "width": 4, "progress": False, **DATA}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("segrun") / "run"
    torch.set_num_threads(1)
    return train_run("shapes", out, **RUN)


# --------------------------------------------------------------------------- data
def test_load_segmentation_data_is_segmentation_sets_with_its_source():
    s = load_segmentation_data("shapes", images=6, size=(32, 32), seed=3)
    ref = segmentation_sets("shapes", 6, (32, 32), 3)
    assert isinstance(s, SegmentationSets) and s.classes == ref.classes
    np.testing.assert_array_equal(np.stack(s.val.images), np.stack(ref.val.images))
    assert s.source == {"data": "shapes", "images": 6, "size": [32, 32], "seed": 3}


@pytest.mark.parametrize(
    ("kwargs", "flag"),
    [
        ({"data": "coco"}, "--data"),
        ({"data": "nuclei"}, "--images-dir"),
        ({"data": "nuclei", "images_dir": "/nonexistent"}, "--images-dir"),
        ({"data": "shapes", "images": 1}, "--images: give at least 2"),
        ({"data": "shapes", "images": "10"}, "--images"),
    ],
)
def test_load_segmentation_data_errors_name_the_flag(kwargs, flag):
    with pytest.raises(InputError, match=flag):
        load_segmentation_data(**kwargs)


def test_resolve_segment_model_defaults_and_mismatch():
    assert resolve_segment_model() == "unet"
    assert resolve_segment_model("instance") == "maskrcnn"
    assert resolve_segment_model("semantic", "fcn8s") == "fcn8s"
    with pytest.raises(InputError, match="--model: maskrcnn does not do --task semantic"):
        resolve_segment_model("semantic", "maskrcnn")
    with pytest.raises(InputError, match="--task"):
        resolve_segment_model("panoptic")
    with pytest.raises(InputError, match="--model"):
        resolve_segment_model("semantic", "deeplab")


# --------------------------------------------------------------------------- train
def test_train_run_writes_the_run_folder_and_its_figures_are_the_librarys(run):
    out = run.out_dir
    assert set(RUN_FILES) == set(run.files) and all(p.is_file() for p in run.files.values())
    assert run.checkpoint == out / "checkpoint.pt" and (out / "checkpoint.best.pt").is_file()
    assert run.model == "naive" and run.task == "semantic" and run.seconds > 0
    model, info = load_segmenter(run.files["model.pt"])
    assert info["classes"] == ["circle", "square", "triangle", "cross"]
    assert (info["data"], info["images"], info["size"], info["seed"]) == ("shapes", 6, [32, 32], 0)
    val = segmentation_sets("shapes", 6, (32, 32), 0).val
    pred = np.stack(segment_arrays(model, list(val.images)))
    s = segmentation_scores(segmentation_confusion(val.class_maps(), pred, 5))
    assert run.metrics["metrics"]["mIoU"] == pytest.approx(s.miou, abs=1e-12)
    assert json.loads(run.files["metrics.json"].read_text()) == run.metrics
    hist = json.loads(run.files["history.json"].read_text())
    assert len(hist["losses"]) == 2 and hist["best_epoch"] == run.best_epoch
    assert str(run.best_epoch) in hist["val_mIoU"]
    printed = run.to_dict()
    assert printed["files"] == {n: str(out / n) for n in RUN_FILES}
    assert printed["split"] == "validation" and printed["data"] == "shapes"


def test_train_run_refuses_a_run_folder_and_checks_before_touching_it(run, tmp_path):
    before = run.checkpoint.read_bytes()
    with pytest.raises(RunExistsError, match=r"--resume.*--overwrite"):
        train_run("shapes", run.out_dir, **RUN)
    assert run.checkpoint.read_bytes() == before
    with pytest.raises(InputError, match="exclude each other"):
        train_run("shapes", tmp_path / "x", resume=True, overwrite=True, **RUN)
    for bad, match in [
        ({"data": "nuclei"}, "--images-dir"),
        ({"task": "instance"}, "--model: naive does not do --task instance"),
        ({"width": 0}, "width"),
        ({"config": {"epochs": 1}}, "TrainConfig"),
    ]:
        kwargs = {**RUN, **bad}
        data = kwargs.pop("data", "shapes")
        with pytest.raises(InputError, match=match):
            train_run(data, tmp_path / "never", **kwargs)
        assert not (tmp_path / "never").exists()


def test_train_run_ctrl_c_keeps_the_epoch_and_resume_ends_as_a_whole_run(run, tmp_path):
    part = tmp_path / "part"
    with ctrl_c_after_first_epoch() as written, pytest.raises(KeyboardInterrupt):
        train_run("shapes", part, **RUN)
    assert written == [1] and (part / "checkpoint.pt").is_file()
    assert len(json.loads((part / "history.json").read_text())["losses"]) == 1
    assert not (part / "model.pt").exists()
    resumed = train_run("shapes", part, resume=True, **RUN)
    a, b = weights(run.files["model.pt"]), weights(resumed.files["model.pt"])
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert resumed.metrics == run.metrics


def test_a_signal_while_the_model_is_saved_leaves_the_whole_history(run, tmp_path, monkeypatch):
    # the faults campaign's SIGTERM after the last epoch, while model.pt was written
    from robopercept.nn.segmentation import run as seg_run

    monkeypatch.setattr(seg_run, "save_segmenter", ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        train_run("shapes", tmp_path / "part", **RUN)
    history = json.loads((tmp_path / "part" / "history.json").read_text())
    assert history["losses"] == json.loads(run.files["history.json"].read_text())["losses"]


def test_train_run_takes_loaded_sets(tmp_path):
    sets = load_segmentation_data("shapes", **DATA)
    r = train_run(sets, tmp_path / "r", **{**RUN, "config": TrainConfig(epochs=1, device="cpu")})
    assert r.metrics["data"] == "shapes" and len(r.history["losses"]) == 1


# --------------------------------------------------------------------------- eval
def test_evaluate_run_scores_as_the_run_did_and_writes_metrics(run, tmp_path):
    ev = evaluate_run(run.out_dir, "shapes", **DATA, out_dir=tmp_path / "ev")
    assert ev.scores.to_dict() == {k: run.metrics[k] for k in ("metrics", "iou")}
    n_val = len(segmentation_sets("shapes", 6, (32, 32), 0).val)
    assert ev.images == n_val and ev.data == "shapes" and ev.model == str(run.out_dir)
    written = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert written == ev.to_dict() and list(written)[:3] == ["model", "data", "images"]
    same = evaluate_run(run.files["model.pt"], load_segmentation_data("shapes", **DATA))
    assert same.scores == ev.scores and same.files == {}


def test_evaluate_run_errors(run, tmp_path):
    with pytest.raises(InputError, match=r"RUN_OR_MODEL: .* does not exist"):
        evaluate_run(tmp_path / "none", "shapes")
    with pytest.raises(
        InputError, match=r"--data: its objects of class .* are not among the model.s classes"
    ):
        evaluate_run(run.out_dir, "digits", images=4, size=(64, 64))
    with pytest.raises(InputError, match="--images"):
        evaluate_run(run.out_dir, "shapes", images=1)


def test_score_segmentation_of_a_mask_rcnn_is_coco_segm():
    val = load_segmentation_data("shapes", images=4, size=(32, 32)).val
    net = build_detector("maskrcnn", 4, seed=0, width=4)
    s = score_segmentation(net, val, device="cpu")
    assert s.instance and len(s.stats) == 12 and next(iter(s.metrics)) == "AP"
    assert s.to_dict() == {"metrics": s.metrics, "stats": list(s.stats)}
    with pytest.raises(InputError, match="DetectionDataset"):
        score_segmentation(net, [np.zeros((8, 8, 3))])


def test_images_of_several_sizes_are_scored_each_at_its_own_size():
    """score_segmentation sums each image's confusion at its own size (a stack would
    refuse two sizes): equal to the confusion of the two images by hand; the padding a
    semantic network trains on is void (255), neither learnt nor scored."""
    import torch

    from robopercept.nn.detection.data import DetectionDataset
    from robopercept.nn.segmentation.networks import build_segmenter
    from robopercept.nn.segmentation.run import VOID, padded_class_maps

    rng = np.random.default_rng(0)
    images = [rng.random((16, 24, 3)), rng.random((32, 16, 3))]
    masks = [np.zeros((1, 16, 24), bool), np.zeros((1, 32, 16), bool)]
    masks[0][0, 2:9, 3:12] = True
    masks[1][0, 10:30, 1:8] = True
    ds = DetectionDataset(
        images,
        [[[3, 2, 12, 9]], [[1, 10, 8, 30]]],
        [[1], [1]],
        ["blob"],
        masks=masks,
    )
    torch.manual_seed(0)
    net = build_segmenter("naive", 2, width=4)
    got = score_segmentation(net, ds)
    pred = segment_arrays(net, images)
    conf = sum(
        segmentation_confusion(m[0].astype(np.int64), p, 2)
        for m, p in zip(masks, pred, strict=True)
    )
    ref = segmentation_scores(conf)
    assert got.metrics["pixel_accuracy"] == pytest.approx(ref.pixel_accuracy)
    assert got.metrics["mIoU"] == pytest.approx(ref.miou)
    x, y = padded_class_maps(ds)
    assert x.shape == (2, 32, 24, 3) and y.shape == (2, 32, 24)
    assert (y[0, 16:] == VOID).all() and (y[1, :, 16:] == VOID).all()
    assert (y[0, :16] != VOID).all() and y[1, 10:30, 1:8].min() == 1
    assert np.array_equal(x[1, :, :16], images[1].astype(np.float32)) and not x[1, :, 16:].any()
