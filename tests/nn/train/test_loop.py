"""The training loop: determinism, resume, early stopping, bad input (issue 23)."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402
from torch.utils.data import TensorDataset  # noqa: E402

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.train.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402
from robopercept.nn.train.fit import evaluate, fit  # noqa: E402
from robopercept.nn.train.loop import optimizer_step, step_optimizer  # noqa: E402


def _blobs(n: int = 240, seed: int = 0) -> TensorDataset:
    """Three classes of 1x6x6 images: a bright square in one of three places."""
    rng = np.random.default_rng(seed)
    y = np.arange(n) % 3
    x = rng.normal(0, 0.3, (n, 1, 6, 6)).astype(np.float32)
    for i, c in enumerate(y):
        x[i, 0, 2 * c : 2 * c + 2, 1:5] += 1.5
    return TensorDataset(torch.from_numpy(x), torch.from_numpy(y))


def _model(seed: int = 0) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(
        nn.Conv2d(1, 4, 3, padding=1), nn.ReLU(), nn.Dropout(0.2), nn.Flatten(), nn.Linear(144, 3)
    )


def _weights(m: nn.Module) -> list[np.ndarray]:
    return [v.detach().numpy().copy() for v in m.state_dict().values()]


CFG = dict(epochs=6, batch_size=32, lr=0.05, optimizer="sgd", schedule="step", step_size=3)


def test_learns_the_toy_problem() -> None:
    model = _model()
    hist = fit(model, _blobs(), _blobs(90, seed=1), TrainConfig(**CFG), progress=False)
    assert hist.epoch == [1, 2, 3, 4, 5, 6]
    assert hist.val_accuracy[-1] >= 0.95 and hist.train_loss[-1] < hist.train_loss[0]
    np.testing.assert_allclose(hist.lr, [0.05] * 3 + [0.005] * 3, rtol=1e-12)  # StepLR(3, 0.1)
    assert evaluate(model, _blobs(90, seed=1)).accuracy >= 0.95


def test_same_seed_same_weights() -> None:
    a, b = _model(), _model()
    fit(a, _blobs(), _blobs(60, 1), TrainConfig(**CFG, seed=3), progress=False)
    fit(b, _blobs(), _blobs(60, 1), TrainConfig(**CFG, seed=3), progress=False)
    for u, v in zip(_weights(a), _weights(b), strict=True):
        np.testing.assert_array_equal(u, v)
    c = _model()
    fit(c, _blobs(), _blobs(60, 1), TrainConfig(**CFG, seed=4), progress=False)
    assert any(not np.array_equal(u, v) for u, v in zip(_weights(a), _weights(c), strict=True))


class _InterruptAfter(torch.utils.data.Dataset):
    """``data``, with Ctrl-C on item access number ``after + 1`` (an interrupted run)."""

    def __init__(self, data, after: int) -> None:
        self.data, self.after, self.seen = data, after, 0

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, i):
        self.seen += 1
        if self.seen > self.after:
            raise KeyboardInterrupt
        return self.data[i]


def test_resumed_run_ends_as_the_uninterrupted_one(tmp_path) -> None:
    cfg = TrainConfig(**dict(CFG, patience=None, schedule="cosine"))
    whole = _model()
    fit(whole, _blobs(), _blobs(60, 1), cfg, progress=False)
    part = _model()
    ck = tmp_path / "run.pt"
    with pytest.raises(KeyboardInterrupt):  # Ctrl-C in epoch 4
        fit(
            part,
            _InterruptAfter(_blobs(), 3 * 240 + 50),
            _blobs(60, 1),
            cfg,
            checkpoint=ck,
            progress=False,
        )
    state = load_checkpoint(ck)  # the last complete epoch's checkpoint is readable
    assert state["epoch"] == 2 and state["history"]["epoch"] == [1, 2, 3]
    resumed = _model(seed=9)  # other initial weights: the checkpoint's replace them
    hist = fit(resumed, _blobs(), _blobs(60, 1), cfg, checkpoint=ck, resume=True, progress=False)
    assert hist.epoch == [1, 2, 3, 4, 5, 6]
    for u, v in zip(_weights(whole), _weights(resumed), strict=True):
        np.testing.assert_array_equal(u, v)


def test_early_stopping_restores_the_best_epoch(tmp_path) -> None:
    model = _model()
    cfg = TrainConfig(
        epochs=40, batch_size=32, lr=0.05, optimizer="sgd", patience=3, monitor="val_loss"
    )
    hist = fit(model, _blobs(), _blobs(60, 1), cfg, checkpoint=tmp_path / "r.pt", progress=False)
    assert hist.stopped.startswith("early stopping") and len(hist.epoch) < 40
    best = hist.best_epoch
    assert hist.val_loss[best - 1] == min(hist.val_loss)
    assert len(hist.epoch) - best == 3
    assert math.isclose(evaluate(model, _blobs(60, 1)).loss, hist.val_loss[best - 1], rel_tol=1e-5)
    best_file = load_checkpoint(tmp_path / "r.best.pt", _model())
    assert "model" in best_file


def test_nan_loss_names_the_learning_rate() -> None:
    with pytest.raises(InputError, match="lower the learning rate"):
        fit(
            _model(),
            _blobs(),
            None,
            TrainConfig(epochs=3, lr=1e12, optimizer="sgd"),
            progress=False,
        )


def test_bad_inputs() -> None:
    empty = TensorDataset(torch.zeros(0, 1, 6, 6), torch.zeros(0, dtype=torch.long))
    with pytest.raises(InputError, match="training set is empty"):
        fit(_model(), empty, progress=False)
    x = torch.zeros(10, 1, 6, 6)
    with pytest.raises(InputError, match=r"labels must be in 0\.\.2"):
        fit(_model(), TensorDataset(x, torch.full((10,), 7)), progress=False)
    last = TensorDataset(torch.zeros(10, 6, 6, 1), torch.zeros(10, dtype=torch.long))
    with pytest.raises((InputError, RuntimeError)):
        fit(_model(), last, progress=False)
    with pytest.raises(InputError, match="channels first"):
        fit(
            _model(),
            TensorDataset(torch.zeros(10, 6, 6), torch.zeros(10, dtype=torch.long)),
            progress=False,
        )
    with pytest.raises(InputError, match="learning rate"):
        TrainConfig(lr=0)


def test_checkpoint_of_another_architecture(tmp_path) -> None:
    ck = tmp_path / "a.pt"
    fit(
        _model(),
        _blobs(),
        None,
        TrainConfig(epochs=1),
        checkpoint=ck,
        architecture="toy-cnn",
        progress=False,
    )
    other = nn.Sequential(nn.Flatten(), nn.Linear(36, 3))
    with pytest.raises(FileFormatError, match="weights of toy-cnn"):
        load_checkpoint(ck, other)
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    with pytest.raises(FileFormatError, match="not a readable torch checkpoint"):
        load_checkpoint(junk)
    with pytest.raises(FileFormatError, match="no such file"):
        load_checkpoint(tmp_path / "none.pt")


def test_cosine_and_onecycle_schedules() -> None:
    cfg = TrainConfig(epochs=4, lr=0.1, optimizer="sgd", schedule="cosine", patience=None)
    hist = fit(_model(), _blobs(64), None, cfg, progress=False)
    want = [0.05 * (1 + math.cos(math.pi * e / 4)) for e in range(4)]  # lr (1 + cos) / 2
    np.testing.assert_allclose(hist.lr, want, rtol=1e-12)
    cfg = TrainConfig(epochs=3, lr=0.1, batch_size=32, schedule="onecycle", patience=None)
    hist = fit(_model(), _blobs(64), None, cfg, progress=False)
    ref_opt = torch.optim.AdamW([torch.zeros(1, requires_grad=True)], lr=0.1)
    ref = torch.optim.lr_scheduler.OneCycleLR(ref_opt, max_lr=0.1, epochs=3, steps_per_epoch=2)
    starts = []
    for _ in range(3):  # the rate at the start of each epoch, 2 batches per epoch
        starts.append(ref.get_last_lr()[0])
        for _ in range(2):
            ref_opt.step()
            ref.step()
    np.testing.assert_allclose(hist.lr, starts, rtol=1e-12)
    assert hist.lr[0] < hist.lr[1]  # warm-up


# issue 25: objects, paths and devices of the wrong kind are refused by name, before
# any work (no AttributeError from inside torch)
_DATA = _blobs(12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: TrainConfig(batch_size=1 + 1j), r"batch_size \(--batch-size\) must be an int"),
        (lambda: TrainConfig(epochs=2**40), r"epochs \(--epochs\) must be at most 100000"),
        (lambda: TrainConfig(lr=float("nan")), r"lr \(the learning rate, --lr\) must be finite"),
        (lambda: TrainConfig(momentum=2.0), r"momentum must be in \[0, 1\]"),
        (lambda: TrainConfig(nesterov="yes"), r"nesterov must be True or False"),
        (lambda: TrainConfig(amp="always"), r"amp \('auto', True or False\)"),
        (lambda: TrainConfig(seed=2**64), r"seed \(--seed\) must be below 2\*\*64"),
        (lambda: TrainConfig(device="gpu"), r"device \(--device\) must be 'auto', 'cpu', 'cuda'"),
        (lambda: TrainConfig(patience=0), r"patience \(or None\) must be >= 1"),
        (lambda: TrainConfig(lr_multipliers=[1]), r"lr_multipliers must be a dict"),
        (lambda: TrainConfig(unfreeze_at={1: "head"}), r"unfreeze_at must be a dict"),
        (lambda: evaluate(None, _DATA), r"model must be a torch.nn.Module"),
        (lambda: evaluate(_model(), None), r"data must be a data set of \(image, label\)"),
        (lambda: evaluate(_model(), "object"), r"data must be a data set"),
        (lambda: evaluate(_model(), np.zeros((3, 3))), r"data must be a data set"),
        (lambda: evaluate(_model(), [1, 2]), r"must give \(image, label\) pairs"),
        (lambda: evaluate(_model(), _DATA, batch_size=0), r"batch_size must be >= 1"),
        (lambda: evaluate(_model(), _DATA, device=float("nan")), r"device \(--device\) must be"),
        (lambda: fit(None, _DATA, progress=False), r"model must be a torch.nn.Module"),
        (lambda: fit(_model(), float("nan"), progress=False), r"the training set must be a"),
        (lambda: fit(_model(), _DATA, "object", progress=False), r"the validation set must be"),
        (lambda: fit(_model(), _DATA, config=3, progress=False), r"config must be a TrainConfig"),
        (
            lambda: fit(_model(), _DATA, checkpoint=float("nan"), progress=False),
            r"checkpoint must be a file or folder path",
        ),
        (lambda: load_checkpoint(3), r"the checkpoint path must be a file or folder path"),
        (lambda: load_checkpoint("x.pt", model=float("nan")), r"model must be a torch.nn"),
        (lambda: save_checkpoint("nul\x00name.pt", {}), r"contains a NUL byte"),
        (lambda: save_checkpoint(3, {}), r"the checkpoint path must be a file or folder"),
    ],
)
def test_issue25_bad_arguments_are_refused(call, match) -> None:
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_numpy_integers_and_defaults_still_work(tmp_path) -> None:
    cfg = TrainConfig(epochs=np.int64(1), batch_size=np.int64(4), device="cpu")
    assert cfg.batch_size == 4 and type(cfg.batch_size) is int
    assert cfg.lr_multipliers == {} and cfg.unfreeze_at == {}
    ev = evaluate(_model(), _DATA, batch_size=np.int64(3), device=torch.device("cpu"))
    assert len(ev.y_true) == 12
    p = save_checkpoint(tmp_path / "c.pt", {"model": _model().state_dict()})
    assert set(load_checkpoint(str(p).encode(), _model())) == {"model"}


def test_optimizer_step_by_hand():
    w = torch.nn.Parameter(torch.ones(2, dtype=torch.float64))
    cfg = TrainConfig(optimizer="sgd", lr=0.1, momentum=0.0, weight_decay=0.0, schedule="constant")
    opt, sched = step_optimizer([w], cfg, 1)
    optimizer_step((w * w).sum(), opt, sched, [w], cfg, "epoch 1")
    # gradient 2 w = 2: w = 1 - 0.1 * 2
    torch.testing.assert_close(w.detach(), torch.full((2,), 0.8, dtype=torch.float64))
    # clipped: the gradient (1.6, 1.6) of norm 2.26 scaled to norm 0.5
    clip = TrainConfig(
        optimizer="sgd",
        lr=0.1,
        momentum=0.0,
        weight_decay=0.0,
        schedule="constant",
        clip_grad_norm=0.5,
    )
    opt, sched = step_optimizer([w], clip, 1)
    optimizer_step((w * w).sum(), opt, sched, [w], clip, "epoch 2")
    torch.testing.assert_close(
        w.detach(), torch.full((2,), 0.8 - 0.1 * 0.5 / 2**0.5, dtype=torch.float64)
    )
    with pytest.raises(InputError, match="the loss became nan at epoch 3, batch 1: lower"):
        optimizer_step(w.sum() * float("nan"), opt, sched, [w], clip, "epoch 3, batch 1")


# ------------------------------------------------------------------ the one loop: resume
class _StopAfter:
    """A forward pre-hook that raises KeyboardInterrupt at the n-th training forward."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __call__(self, module: torch.nn.Module, args: object) -> None:
        if module.training:
            self.n -= 1
            if self.n < 0:
                raise KeyboardInterrupt


def interrupted_then_resumed(build, train, steps_before_stop: int, tmp_path) -> tuple:
    """(uninterrupted model, resumed model): ``train(model, checkpoint, resume)`` runs
    the same training; the second run is stopped by Ctrl-C after ``steps_before_stop``
    training batches, then resumed from its checkpoint into a model with other weights."""
    whole = build(0)
    train(whole, None, False)
    part = build(0)
    first = next(
        m
        for m in part.modules()
        if isinstance(m, (torch.nn.Conv1d, torch.nn.Conv2d, torch.nn.Linear))
    )  # runs once per training batch
    hook = first.register_forward_pre_hook(_StopAfter(steps_before_stop))
    ck = tmp_path / "run.pt"
    with pytest.raises(KeyboardInterrupt):
        train(part, ck, False)
    hook.remove()
    assert ck.exists()
    resumed = build(7)  # other initial weights: the checkpoint's replace them
    hist = train(resumed, ck, True)
    return whole, resumed, hist


def test_train_loop_resumes_the_detector_segmenter_pose_and_cloud_trainers(tmp_path) -> None:
    from robopercept.nn.cloud.synthetic import procedural_shapes
    from robopercept.nn.cloud.train import build_cloud_model, train_cloud_model
    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.nn.detection.train import train_detector
    from robopercept.nn.detection.zoo import build_detector
    from robopercept.nn.pose.data import procedural_pose_set
    from robopercept.nn.pose.networks import HRNet
    from robopercept.nn.pose.train import train_pose
    from robopercept.nn.segmentation.networks import UNet, train_segmenter

    torch.set_num_threads(1)
    det = procedural_detection_set(6, (48, 48), rng=0)
    dtr, dva = det.split((0.67, 0.33), rng=0)
    rs = np.random.default_rng(0)
    x = rs.random((6, 24, 24, 1)).astype(np.float32)
    y = (x[..., 0] > 0.5).astype(np.int64)
    poses = procedural_pose_set(12, (64, 64), rng=3)
    ptr, pva = poses.subset(range(8)), poses.subset(range(8, 12))
    classes = ("sphere", "plane", "l_shape")
    ctr = procedural_shapes(4, 64, classes=classes, rng=0)  # 4 of each class: 6 batches
    cva = procedural_shapes(2, 64, classes=classes, rng=1)

    def seeded(make):
        def build(seed):
            torch.manual_seed(seed)
            return make()

        return build

    cfg = TrainConfig(epochs=3, batch_size=2, lr=1e-3, device="cpu", schedule="cosine")
    cases = {
        "detector (EMA, validation every 2)": (
            lambda s: build_detector("fcos", len(dtr.classes), seed=s, width=8),
            lambda m, ck, r: train_detector(
                m,
                dtr,
                cfg,
                val=dva,
                val_every=2,
                ema=0.9,
                checkpoint=ck,
                resume=r,
                progress=False,
            ),
            3,
        ),
        "segmenter": (
            seeded(lambda: UNet(2, in_channels=1, width=4, depth=2)),
            lambda m, ck, r: train_segmenter(
                m,
                x,
                y,
                cfg,
                val=(x[:2], y[:2]),
                crop=16,
                checkpoint=ck,
                resume=r,
                progress=False,
            ),
            4,
        ),
        "pose": (
            seeded(lambda: HRNet(16, width=4, blocks=1)),
            lambda m, ck, r: train_pose(
                m, ptr, cfg, val=pva, checkpoint=ck, resume=r, progress=False
            ),
            5,
        ),
        "cloud": (
            lambda s: build_cloud_model("pointnet", 3, seed=s, width=0.125),
            lambda m, ck, r: train_cloud_model(
                m, ctr, cfg, val=cva, checkpoint=ck, resume=r, progress=False
            ),
            8,
        ),
    }
    for name, (build, train, stop) in cases.items():
        whole, resumed, hist = interrupted_then_resumed(build, train, stop, tmp_path / name)
        for (k, u), v in zip(
            whole.state_dict().items(), resumed.state_dict().values(), strict=True
        ):
            assert torch.equal(u, v), f"{name}: {k} differs after resuming"
        assert len(hist.losses) == 3, name


@pytest.mark.parametrize(
    ("n", "batch_size", "sizes"), [(5, 2, [2, 3]), (7, 3, [3, 4]), (6, 4, [4, 2])]
)
def test_epoch_loop_never_draws_a_batch_of_one(n, batch_size, sizes):
    """A last batch of one sample joins the one before (batch norm in training mode
    cannot learn from one: torch raises); every sample is drawn once per epoch."""
    from robopercept.nn.train.loop import epoch_loop

    torch.manual_seed(0)
    model = nn.Sequential(nn.Linear(2, 4), nn.BatchNorm1d(4), nn.Linear(4, 1))
    x = torch.randn(n, 2)
    seen: list[list[int]] = []

    def batch(idx):
        seen.append(idx.tolist())
        return model(x[idx]).pow(2).mean()

    cfg = TrainConfig(epochs=2, batch_size=batch_size, lr=1e-2)
    gen = torch.Generator().manual_seed(0)
    epoch_loop(model, n, cfg, gen, batch, None, desc="t", progress=False)
    assert [len(b) for b in seen] == sizes * 2
    for epoch in (seen[: len(sizes)], seen[len(sizes) :]):
        assert sorted(i for b in epoch for i in b) == list(range(n))
