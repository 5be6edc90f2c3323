"""robopercept.nn.cloud.train: building, training, scoring and the files of the
point-cloud networks (issue 29). Tiny networks and clouds keep the file fast; the
trained accuracy targets are measured by ``benchmarks/cloud_figures.py`` and the shipped
models are checked in ``test_shipped.py``."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.cloud.data import CloudDataset  # noqa: E402
from robopercept.nn.cloud.synthetic import procedural_shapes  # noqa: E402
from robopercept.nn.cloud.train import (  # noqa: E402
    build_cloud_model,
    cloud_model_spec,
    evaluate_cloud_model,
    load_cloud_model,
    part_ious,
    predict_clouds,
    save_cloud_model,
    train_cloud_model,
)
from robopercept.nn.train.config import TrainConfig  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

CLASSES = ("sphere", "plane", "l_shape")
TINY = {"width": 0.125}
DG = {"k": 4, "widths": [8, 8], "embedding": 16}


@pytest.fixture(scope="module")
def shapes() -> tuple[CloudDataset, CloudDataset]:
    train = procedural_shapes(12, 64, classes=CLASSES, rng=0)
    test = procedural_shapes(10, 64, classes=CLASSES, rng=1)
    return train, test


def _cfg(epochs: int = 12, seed: int = 0) -> TrainConfig:
    return TrainConfig(epochs=epochs, batch_size=8, lr=1e-2, seed=seed, device="cpu")


@pytest.fixture(scope="module")
def trained(shapes) -> torch.nn.Module:
    # one thread, set here: a module fixture runs before the per-test torch_one_thread,
    # and float sums (hence the trained weights) depend on the thread count
    train, _ = shapes
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        net = build_cloud_model("pointnet", 3, seed=0, **TINY)
        train_cloud_model(net, train, _cfg(16), progress=False)
    finally:
        torch.set_num_threads(before)
    return net


def test_training_learns_three_distinct_shapes(trained, shapes):
    # sphere, flat slab and L-prism differ at every scale: a tiny PointNet separates
    # them on 30 held-out shapes after 16 epochs of 36 clouds (the last epoch kept: no
    # selection on the test shapes)
    ev = evaluate_cloud_model(trained, shapes[1])
    assert ev.accuracy >= 0.9
    assert ev.confusion.sum() == len(shapes[1]) and ev.confusion.shape == (3, 3)
    assert ev.accuracy == pytest.approx(np.trace(ev.confusion) / ev.confusion.sum())


def test_training_is_seeded(shapes):
    train, _ = shapes
    states = []
    for _ in range(2):
        net = build_cloud_model("dgcnn", 3, seed=3, **DG)
        hist = train_cloud_model(net, train, _cfg(2, seed=3), progress=False)
        states.append(net.state_dict())
        assert len(hist.losses) == 2 and hist.best_epoch == 2
    for k, v in states[0].items():
        assert torch.equal(v, states[1][k]), k


def test_history_names_its_score(shapes):
    train, test = shapes
    net = build_cloud_model("pointnet", 3, seed=0, **TINY)
    hist = train_cloud_model(net, train, _cfg(1), val=test, progress=False)
    assert set(hist.to_dict()["val_accuracy"]) == {"1"}


def test_mean_class_accuracy_by_hand():
    # 4 clouds of class 0 (3 right), 1 of class 1 (right): overall 0.8, class mean 0.875
    class Fixed(torch.nn.Module):
        task, num_outputs, in_channels, config = "classify", 2, 3, {}

        def forward(self, x, mask=None, category=None):
            return torch.stack([x[:, 0, 0], 1 - x[:, 0, 0]], 1) * 10

    Fixed.__name__ = "PointNet"
    pts = np.zeros((5, 4, 3), np.float32)
    pts[[0, 1, 2], 0, 0] = 1.0  # predicted class 0
    data = CloudDataset(pts, np.array([0, 0, 0, 0, 1]), ("a", "b"))
    net = Fixed()
    net.register_parameter("w", torch.nn.Parameter(torch.zeros(1)))
    ev = evaluate_cloud_model(net, data)
    assert ev.accuracy == pytest.approx(0.8)
    assert ev.mean_class_accuracy == pytest.approx((0.75 + 1.0) / 2)
    assert ev.confusion.tolist() == [[3, 1], [0, 1]]


def test_part_ious_by_hand_and_limits():
    part_classes = np.array([0, 0, 1])
    truth = np.array([[0, 0, 0, 1]])
    # part 0: |{0,1}| / |{0,1,2}| = 2/3; part 1: |{3}| / |{2,3}| = 1/2 -> 7/12
    assert part_ious(np.array([[0, 0, 1, 1]]), truth, np.array([0]), part_classes)[0] == (
        pytest.approx(7 / 12)
    )
    assert part_ious(truth, truth, np.array([0]), part_classes)[0] == 1.0
    # a part absent from truth and prediction counts 1 (ShapeNet-part's rule)
    assert part_ious(np.zeros((1, 4), int), np.zeros((1, 4), int), np.array([0]), part_classes)[
        0
    ] == pytest.approx(1.0)
    with pytest.raises(InputError, match="pred and parts"):
        part_ious(np.zeros((1, 4)), np.zeros((1, 3)), np.array([0]), part_classes)


def test_segmenter_predicts_only_its_category_parts():
    train = procedural_shapes(4, 64, classes=("cylinder", "cone", "torus"), rng=0)
    net = build_cloud_model(
        "pointnet",
        train.num_parts,
        seed=0,
        task="segment",
        num_categories=train.num_classes,
        **TINY,
    )
    hist = train_cloud_model(net, train, _cfg(2), val=train, progress=False)
    ev = evaluate_cloud_model(net, train)
    assert hist.to_dict()["val_miou"]["2"] == pytest.approx(ev.instance_miou)
    pc = np.asarray(train.part_classes)
    assert (pc[ev.predictions] == train.labels[:, None]).all()
    assert 0.0 <= ev.instance_miou <= 1.0 and ev.per_class_miou is not None
    assert ev.class_miou == pytest.approx(np.mean(ev.per_class_miou))
    with pytest.raises(InputError, match="category"):
        predict_clouds(net, train.points[:2])


def test_predict_single_batch_and_mask(trained, shapes):
    pts = shapes[1].points
    batch = predict_clouds(trained, pts[:3])
    assert batch.shape == (3, 3) and np.allclose(batch.sum(1), 1, atol=1e-5)
    np.testing.assert_allclose(predict_clouds(trained, pts[1]), batch[1], atol=1e-6)
    # a cloud padded with junk under a mask gives its own prediction
    padded = np.concatenate([pts[:1], np.full((1, 16, 3), 5.0, np.float32)], axis=1)
    mask = np.r_[np.ones(64, bool), np.zeros(16, bool)][None]
    np.testing.assert_allclose(predict_clouds(trained, padded, mask=mask)[0], batch[0], atol=1e-5)


def test_save_and_load_round_trip(trained, shapes, tmp_path):
    p = save_cloud_model(tmp_path / "m.pt", trained, list(CLASSES), n_points=64, note="x")
    net, info = load_cloud_model(p)
    assert info["class_names"] == list(CLASSES) and info["n_points"] == 64
    assert info["note"] == "x" and info["kind"] == "pointnet"
    pts = shapes[1].points
    np.testing.assert_allclose(predict_clouds(net, pts), predict_clouds(trained, pts), atol=1e-6)
    with pytest.raises(InputError, match="3 outputs; got 2 class names"):
        save_cloud_model(tmp_path / "bad.pt", trained, ["a", "b"])
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(FileFormatError, match="not a readable"):
        load_cloud_model(tmp_path / "junk.pt")


def test_bad_inputs(trained, shapes):
    train, _ = shapes
    with pytest.raises(InputError, match="name"):
        build_cloud_model("pointnet++", 3)
    with pytest.raises(InputError, match="CloudDataset"):
        train_cloud_model(trained, train.points, _cfg(1), progress=False)
    with pytest.raises(InputError, match="PointNet or DGCNN"):
        train_cloud_model(torch.nn.Linear(3, 3), train, _cfg(1), progress=False)
    small = build_cloud_model("pointnet", 2, seed=0, **TINY)
    with pytest.raises(InputError, match="num_outputs >= 3"):
        train_cloud_model(small, train, _cfg(1), progress=False)
    seg = build_cloud_model("pointnet", 4, task="segment", **TINY)
    nopart = CloudDataset(train.points, train.labels, train.class_names)
    with pytest.raises(InputError, match="no part labels"):
        train_cloud_model(seg, nopart, _cfg(1), progress=False)
    with pytest.raises(InputError, match="rotate"):
        train_cloud_model(trained, train, _cfg(1), rotate="x", progress=False)
    with pytest.raises(InputError, match=r"\(B, N, C\)"):
        predict_clouds(trained, np.zeros(3))


def test_cloud_model_spec_reads_the_network():
    seg = build_cloud_model("dgcnn", 5, seed=0, task="segment", num_categories=2, **DG)
    spec = cloud_model_spec(seg)
    assert (spec.kind, spec.task, spec.num_outputs, spec.in_channels) == ("dgcnn", "segment", 5, 3)
    assert spec.config["num_categories"] == 2 and spec.config["k"] == 4
    with pytest.raises(InputError, match="PointNet or DGCNN"):
        cloud_model_spec(torch.nn.Linear(3, 3))
