"""One class per input from Python (robopercept.nn.predict_class, reached through
load_predictor): the shipped digits classifier and point-cloud networks, equal to the
commands' own arithmetic, on files, arrays and lists; run folders found by kind."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import write_image
from robopercept.nn import load_predictor
from robopercept.nn.classification.run import predict
from robopercept.nn.classification.saved import load_run
from robopercept.nn.cloud.data import read_cloud_file, sample_cloud
from robopercept.nn.cloud.run import classify_cloud_file
from robopercept.nn.cloud.train import load_cloud_model, predict_clouds
from robopercept.nn.data.datasets import load_digits
from robopercept.nn.predict_class import ClassPrediction
from robopercept.nn.shipped import shipped_model_path
from tests.conftest import data_path


@pytest.fixture(scope="module")
def digit_files(tmp_path_factory):
    """Ten digits of the data set, one per class, as 8-bit PNG files."""
    ds = load_digits()
    folder = tmp_path_factory.mktemp("digits")
    labels = np.asarray(ds.labels)
    files, truth = [], []
    for c in range(10):
        i = int(np.flatnonzero(labels == c)[0])
        img = np.asarray(ds.images[i]).squeeze()
        files.append(write_image(folder / f"{c}_{i}.png", np.round(img * 255).astype(np.uint8)))
        truth.append(ds.classes[c])
    return files, truth


def test_digits_from_python_equal_nn_predict(digit_files):
    """The predictor on a path gives what ``nn predict`` (classification.run.predict)
    gives, to float32 rounding; on the image as an array, the same."""
    files, truth = digit_files
    p = load_predictor("digits")
    assert p.kind == "classify" and p.classes == [str(d) for d in range(10)]
    assert p.trained_on.startswith("real data")
    got = p([str(f) for f in files])
    ref = predict("digits", files, top_k=10)
    for g, r in zip(got, ref, strict=True):
        assert isinstance(g, ClassPrediction) and g.class_name == r.top[0][0]
        for name, prob in r.top:
            assert g.probabilities[name] == pytest.approx(prob, abs=1e-6)
    # the training data's digits, one per class, are recognised
    assert sum(g.class_name == t for g, t in zip(got, truth, strict=True)) >= 9
    _, arch = load_run("digits")
    from robopercept.imaging import read_image

    arr = read_image(files[3], mode=arch.mode)
    assert p(arr).probabilities == pytest.approx(got[3].probabilities)
    rec = got[0].record()
    assert set(rec) == {"source", "class", "score", "probabilities", "warning"}
    assert abs(sum(rec["probabilities"].values()) - 1) < 1e-5


def test_a_photo_given_to_the_digits_model_is_warned_about(tmp_path):
    photo = write_image(tmp_path / "big.png", np.zeros((200, 300, 3), np.uint8))
    res = load_predictor("digits")(photo)
    assert res.warning is not None and "shrunk" in res.warning and "big.png" in res.warning
    pic = res.picture()
    assert pic.ndim == 3 and pic.shape[2] == 3


def test_clouds_from_python_equal_nn_cloud():
    mesh = data_path("pointcloud_cls", "ModelNet10", "sofa", "train", "sofa_0001.off")
    p = load_predictor("pointnet")
    model, info = load_cloud_model(shipped_model_path("cloud", "pointnet"))
    ref = classify_cloud_file(mesh, model, info)
    got = p(mesh)
    assert got.class_name == ref.label
    assert got.probabilities == pytest.approx(ref.probabilities)
    assert np.array_equal(got.points, ref.points)
    # an array of points: sample_cloud's rules, then the same network
    pts = read_cloud_file(mesh, 4096, rng=1)
    arr = p(pts)
    prob = predict_clouds(model, sample_cloud(pts, p.n_points, p.seed))
    assert arr.probabilities[arr.class_name] == pytest.approx(float(prob.max()))
    assert [r.class_name for r in p([mesh, pts])] == [got.class_name, arr.class_name]
    assert got.picture().shape[2] == 3


def test_run_folders_are_found_by_kind_and_bad_inputs_named(tmp_path):
    from robopercept.nn.classification.run import TrainConfig, train_run

    run = tmp_path / "digits_run"
    cfg = TrainConfig(epochs=1, batch_size=64, seed=0)
    train_run(
        "digits", "resnet_small", run, config=cfg, model_kwargs={"widths": [4, 8]}, progress=False
    )
    p = load_predictor(run)  # a classifier's run keeps its model in checkpoint.best.pt
    assert p.kind == "classify" and p.name == str(run) and p.trained_on == "your own data"
    assert len(p(np.zeros((8, 8))).probabilities) == 10
    with pytest.raises(InputError, match=r"an \(N, 3\) array"):
        load_predictor("pointnet")(np.zeros((4, 2)))
    with pytest.raises((InputError, FileFormatError)):
        load_predictor("digits")(np.zeros((3, 8, 8)))
    with pytest.raises(InputError, match="kind"):
        load_predictor("digits", kind="clouds")
