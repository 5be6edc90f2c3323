"""Tests of robopercept.nn.detection.train: seeded determinism, checkpoints, overfitting
tiny sets (losses and decoding agree), validation that keeps the best epoch,
augmentation and weight averaging."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.detection.synthetic import digits_detection_set  # noqa: E402
from robopercept.nn.detection.train import evaluate_detector, train_detector  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402
from tests.nn.detection.detectors import build, overfit  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


def test_resolve_device_and_deterministic_algorithms():
    from robopercept.nn.train.config import deterministic_algorithms, resolve_device

    assert resolve_device("cpu") == torch.device("cpu")
    with pytest.raises(InputError, match="device"):
        resolve_device("gpu7")
    import torch.utils.deterministic as torch_deterministic

    before = torch.are_deterministic_algorithms_enabled()
    with deterministic_algorithms():
        assert torch.are_deterministic_algorithms_enabled()
        assert torch.is_deterministic_algorithms_warn_only_enabled()
        # torch.empty's NaN fill is off in the block (it cost 2-3 % of an epoch)
        assert not torch_deterministic.fill_uninitialized_memory
    assert torch.are_deterministic_algorithms_enabled() == before
    assert torch_deterministic.fill_uninitialized_memory  # torch's default, restored
    # a caller's own settings come back as they were
    torch.use_deterministic_algorithms(True)
    try:
        with deterministic_algorithms():
            pass
        assert torch.are_deterministic_algorithms_enabled()
        assert not torch.is_deterministic_algorithms_warn_only_enabled()
    finally:
        torch.use_deterministic_algorithms(before)


def test_seeded_determinism():
    ds = digits_detection_set(2, (48, 48), (1, 2), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=2, batch_size=2, lr=1e-3, device="cpu", seed=5)
    runs = []
    for _ in range(2):
        m = build("faster")
        runs.append(train_detector(m, ds, cfg, progress=False).losses)
    assert runs[0] == runs[1]


def test_checkpoint_round_trip(tmp_path):
    from robopercept.nn.train.checkpoint import load_checkpoint

    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    m = build("fcos")
    cfg = TrainConfig(epochs=2, batch_size=1, device="cpu")
    hist = train_detector(m, ds, cfg, checkpoint=tmp_path / "det.pt", progress=False)
    other = build("fcos", num_classes=10)
    torch.nn.init.zeros_(other.cls_logits.weight)
    state = load_checkpoint(tmp_path / "det.pt", other)
    assert state["epoch"] == 2 and state["architecture"] == "FCOS"
    assert state["losses"] == hist.losses
    for a, b in zip(m.state_dict().values(), other.state_dict().values(), strict=True):
        assert torch.equal(a, b)


@pytest.mark.parametrize(
    ("kind", "epochs", "lr"), [("fcos", 60, 3e-3), ("faster", 60, 1e-3), ("fast", 60, 1e-3)]
)
def test_overfits_two_images(kind, epochs, lr):
    # two 64 x 64 canvases of one real digit each: a correct detector (losses and
    # decoding that agree) fits them to AP50 = 1 in 60 steps (measured with model seeds
    # 0-2 and 1 or 2 threads: AP50 1.0, AP 0.75-1.0); a wrong sign or scale in the box
    # decoding leaves AP50 near 0
    m, ds, hist = overfit(kind, epochs, lr)
    assert hist.losses[-1]["loss"] < 0.5 * hist.losses[0]["loss"]
    ev = evaluate_detector(m, ds)
    assert ev.stats[1] >= 0.9, ev.stats
    assert ev.stats[0] >= 0.6, ev.stats


def test_validation_keeps_the_best_evaluated_epoch(monkeypatch):
    # scripted validation figures (epochs 2, 4, 6 score 0.4, 0.9, 0.2): the model must
    # end with epoch 4's weights, i.e. equal to a run of the same seed stopped at 4
    import robopercept.nn.detection.train as det

    ds = digits_detection_set(2, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=6, batch_size=2, lr=3e-3, device="cpu", schedule="constant")
    scripted = iter([0.4, 0.9, 0.2])

    class Fake:
        def __init__(self) -> None:
            self.stats = np.full(12, next(scripted))

    monkeypatch.setattr(
        det, "evaluate_detector", lambda model, dataset, iou_type, sigmas=None: Fake()
    )
    m = build("fcos")
    hist = train_detector(m, ds, cfg, progress=False, val=ds, val_every=2)
    assert hist.val == {2: 0.4, 4: 0.9, 6: 0.2} and hist.best_epoch == 4
    assert hist.val_seconds >= 0
    monkeypatch.undo()
    ref = build("fcos")
    train_detector(ref, ds, TrainConfig(**{**cfg.__dict__, "epochs": 4}), progress=False)
    for (k, a), b in zip(m.state_dict().items(), ref.state_dict().values(), strict=True):
        assert torch.equal(a, b), k


def test_validation_figure_is_the_coco_number_of_the_kept_weights():
    ds = digits_detection_set(2, (64, 64), (1, 1), rng=0, scale=(16, 32))
    cfg = TrainConfig(epochs=6, batch_size=2, lr=3e-3, device="cpu", schedule="constant")
    m = build("fcos")
    hist = train_detector(m, ds, cfg, progress=False, val=ds, val_every=4, val_metric="AP50")
    assert sorted(hist.val) == [4, 6]  # every 4th epoch and the last
    assert evaluate_detector(m, ds).stats[1] == pytest.approx(hist.val[hist.best_epoch])


def test_without_validation_the_last_epoch_is_kept():
    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    hist = train_detector(
        build("fcos"), ds, TrainConfig(epochs=2, batch_size=1, device="cpu"), progress=False
    )
    assert hist.best_epoch == 2 and hist.val == {}


def test_augment_sees_every_training_sample_and_changes_the_run():
    from robopercept.nn.detection.augment import FlipRotate

    ds = digits_detection_set(3, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=2, batch_size=2, lr=1e-3, device="cpu")
    seen = []

    def spy(image, target):
        seen.append(int(target["image_id"]))
        return FlipRotate(1.0, 1.0, generator=0)(image, target)

    plain = train_detector(build("fcos"), ds, cfg, progress=False).losses
    flipped = train_detector(build("fcos"), ds, cfg, progress=False, augment=spy).losses
    assert sorted(seen) == sorted(ds.image_ids * 2)  # each image once per epoch
    assert flipped != plain


@pytest.mark.parametrize(
    ("kw", "msg"),
    [
        ({"val_metric": "mAP"}, "val_metric must be one of"),
        ({"val_every": 0}, "val_every"),
        ({"val": [1, 2]}, "dataset must be a DetectionDataset"),
        ({"augment": "flip"}, "augment must be a callable"),
    ],
)
def test_bad_validation_arguments(kw, msg):
    ds = digits_detection_set(1, (32, 32), (1, 1), rng=0, scale=(12, 16))
    with pytest.raises(InputError, match=msg):
        train_detector(build("fcos"), ds, TrainConfig(epochs=1, device="cpu"), progress=False, **kw)


def test_weight_average_follows_the_warmed_up_ema_formula():
    from robopercept.nn.detection.train import _weight_average

    lin = torch.nn.Linear(1, 1, bias=False)
    avg = _weight_average(lin, 0.2)
    seen = []
    for w in (1.0, 3.0, 5.0):
        with torch.no_grad():
            lin.weight.fill_(w)
        avg.update_parameters(lin)
        seen.append(float(avg.module.weight.detach()))
    # n = 0 copies; n = 1: d = min(0.2, 2 / 11); n = 2: d = min(0.2, 3 / 12) = 0.2
    second = 2 / 11 * 1.0 + 9 / 11 * 3.0
    assert seen == pytest.approx([1.0, second, 0.2 * second + 0.8 * 5.0])


def test_ema_keeps_the_averaged_weights_and_checks_its_value():
    ds = digits_detection_set(2, (48, 48), (1, 1), rng=0, scale=(12, 24))
    cfg = TrainConfig(epochs=3, batch_size=1, lr=3e-3, device="cpu", schedule="constant")
    plain, averaged = build("fcos"), build("fcos")
    train_detector(plain, ds, cfg, progress=False)
    hist = train_detector(averaged, ds, cfg, progress=False, val=ds, ema=0.9)
    # the raw weights of both runs are identical (same seed, the EMA does not feed
    # back); what comes back differs, and is what validation scored
    pairs = zip(plain.parameters(), averaged.parameters(), strict=True)
    differ = [not torch.equal(a, b) for a, b in pairs]
    assert any(differ)
    value = evaluate_detector(averaged, ds).stats[0]
    assert value == pytest.approx(hist.val[hist.best_epoch], abs=1e-12)
    for bad in (0.0, 1.0, float("nan")):
        with pytest.raises(InputError, match="--ema"):
            train_detector(build("fcos"), ds, cfg, progress=False, ema=bad)
