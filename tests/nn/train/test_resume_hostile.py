"""Resuming a run (issue 47): under other options than the run's (R42) the resume is
refused with ArgumentError naming the differing options and ``--overwrite``; a damaged
training state in the checkpoint (R49) gives FileFormatError naming the file and the
entry, never TypeError, KeyError, ValueError or AttributeError from torch."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402
from torch.utils.data import TensorDataset  # noqa: E402

from robopercept.errors import ArgumentError, FileFormatError, InputError  # noqa: E402
from robopercept.nn.train.checkpoint import save_checkpoint  # noqa: E402
from robopercept.nn.train.config import History, TrainConfig  # noqa: E402
from robopercept.nn.train.fit import fit  # noqa: E402
from robopercept.nn.train.loop import EpochHistory, epoch_loop  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")

BASE = dict(epochs=2, batch_size=16, optimizer="adamw", schedule="step", step_size=1, lr=0.01)
OPTIONS = {"--data": "blobs", "--split": [0.5, 0.25, 0.25]}


def _blobs(n: int = 48, seed: int = 0) -> TensorDataset:
    rng = np.random.default_rng(seed)
    y = np.arange(n) % 3
    x = rng.normal(0, 0.3, (n, 1, 6, 6)).astype(np.float32)
    for i, c in enumerate(y):
        x[i, 0, 2 * c : 2 * c + 2, 1:5] += 1.5
    return TensorDataset(torch.from_numpy(x), torch.from_numpy(y))


def _model(seed: int = 0) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Conv2d(1, 2, 3, padding=1), nn.ReLU(), nn.Flatten(), nn.Linear(72, 3))


def _fit(ck, *, resume=False, options=OPTIONS, architecture="toy", **changes):
    cfg = TrainConfig(**{**BASE, **changes})
    return fit(
        _model(5),
        _blobs(),
        _blobs(24, 1),
        cfg,
        checkpoint=ck,
        resume=resume,
        architecture=architecture,
        run_options=options,
        progress=False,
    )


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A complete 2-epoch run (AdamW, step schedule): its folder."""
    out = tmp_path_factory.mktemp("resume") / "run"
    _fit(out / "checkpoint.pt")
    return out


@pytest.fixture
def ck(run, tmp_path):
    """A copy of the run's checkpoint (and its best weights) to damage."""
    for name in ("checkpoint.pt", "checkpoint.best.pt"):
        shutil.copy(run / name, tmp_path / name)
    return tmp_path / "checkpoint.pt"


def _edit(path, **entries) -> None:
    state = torch.load(path, weights_only=True)
    for key, value in entries.items():
        if value is KeyError:
            del state[key]
        else:
            state[key] = value
    save_checkpoint(path, state)


def test_resume_with_the_same_options(ck) -> None:
    hist = _fit(ck, resume=True)  # nothing left to train: every entry restored
    assert hist.epoch == [1, 2]
    # more epochs (a step schedule) and another device are allowed
    hist = _fit(ck, resume=True, epochs=3, device="cpu")
    assert hist.epoch == [1, 2, 3]


# ------------------------------------------------------------------ R42: other options
@pytest.mark.parametrize(
    ("changes", "names"),
    [
        ({"optimizer": "sgd"}, ["--optimizer"]),  # was KeyError from torch
        ({"schedule": "cosine"}, ["--schedule"]),  # was KeyError from torch
        ({"seed": 1}, ["--seed"]),  # was accepted silently (another split)
        ({"seed": 1, "lr": 0.1, "batch_size": 8}, ["--seed", "--lr", "--batch-size"]),
        ({"momentum": 0.5, "patience": 3}, ["momentum", "--patience"]),
        ({"options": {**OPTIONS, "--data": "other"}}, ["--data"]),
        ({"options": {**OPTIONS, "--augment": True}}, ["--augment"]),
        ({"architecture": "another"}, ["architecture"]),
    ],
)
def test_resume_under_other_options_is_refused(ck, changes, names) -> None:
    before = ck.read_bytes()
    with pytest.raises(ArgumentError, match="--overwrite") as info:
        _fit(ck, resume=True, **changes)
    for name in names:
        assert name in str(info.value)
    assert ck.read_bytes() == before


def test_a_one_cycle_schedule_cannot_be_extended(ck) -> None:
    # its total steps are fixed: stepping past them was torch's ValueError mid-run
    _edit(ck, config={**torch.load(ck, weights_only=True)["config"], "schedule": "onecycle"})
    with pytest.raises(ArgumentError, match=r"--epochs \(2 in the run, 3 now; a one-cycle"):
        _fit(ck, resume=True, epochs=3, schedule="onecycle")


def test_fewer_epochs_than_done(ck) -> None:
    with pytest.raises(ArgumentError, match=r"--epochs 1 is fewer than the 2 epochs"):
        _fit(ck, resume=True, epochs=1)


def test_run_options_are_checked(tmp_path) -> None:
    for bad in ([1], {1: 2}, {"a": {1, 2}}, {"a": math.nan}):
        with pytest.raises(InputError, match="run_options"):
            _fit(tmp_path / "c.pt", options=bad)


# ------------------------------------------------------------------ R49: damaged state
def _adamw_state(ck, **group_or_state):
    opt = torch.load(ck, weights_only=True)["optimizer"]
    for k, v in group_or_state.items():
        if k.startswith("state_"):
            key = k[len("state_") :]
            if v is KeyError:
                del opt["state"][0][key]
            else:
                opt["state"][0][key] = v
        else:
            opt["param_groups"][0][k] = v
    return opt


DAMAGE = {
    "epochs_done": lambda ck: {"epochs_done": "2"},
    "epochs_done-negative": lambda ck: {"epochs_done": -1},
    "epochs_done-bool": lambda ck: {"epochs_done": True},
    "epochs_done-missing": lambda ck: {"epochs_done": KeyError},
    "best_epoch": lambda ck: {"best_epoch": 99},
    "best_epoch-none": lambda ck: {"best_epoch": None},
    "best_score": lambda ck: {"best_score": "high"},
    "best_score-nan": lambda ck: {"best_score": math.nan},
    "stopped": lambda ck: {"stopped": 3},
    "optimizer": lambda ck: {"optimizer": [1, 2]},
    "optimizer-empty": lambda ck: {"optimizer": {"state": {}, "param_groups": []}},
    "optimizer-lr": lambda ck: {"optimizer": _adamw_state(ck, lr="fast")},
    "optimizer-betas": lambda ck: {"optimizer": _adamw_state(ck, betas=0.9)},
    "optimizer-shape": lambda ck: {"optimizer": _adamw_state(ck, state_exp_avg=torch.zeros(7))},
    "optimizer-nan": lambda ck: {
        "optimizer": _adamw_state(ck, state_exp_avg_sq=torch.full((2, 1, 3, 3), math.nan))
    },
    "optimizer-missing": lambda ck: {"optimizer": _adamw_state(ck, state_exp_avg=KeyError)},
    "optimizer-list": lambda ck: {"optimizer": _adamw_state(ck, state_exp_avg=[0.0])},
    "scheduler": lambda ck: {"scheduler": [1]},
    "scheduler-field": lambda ck: {
        "scheduler": {**torch.load(ck, weights_only=True)["scheduler"], "last_epoch": "one"}
    },
    "scheduler-method": lambda ck: {
        "scheduler": {**torch.load(ck, weights_only=True)["scheduler"], "step": 5}
    },
    "generators": lambda ck: {"generators": None},
    "generators-empty": lambda ck: {"generators": {}},
    "generators-size": lambda ck: {"generators": {"shuffle": torch.zeros(3, dtype=torch.uint8)}},
    "torch_rng_state": lambda ck: {"torch_rng_state": "seed"},
    "torch_rng_state-size": lambda ck: {"torch_rng_state": torch.zeros(5, dtype=torch.uint8)},
    "torch_rng_state-missing": lambda ck: {"torch_rng_state": KeyError},
    "history": lambda ck: {"history": None},
    "history-column": lambda ck: {"history": {**History(epoch=[1, 2]).to_dict()}},
    "history-type": lambda ck: {
        "history": {**torch.load(ck, weights_only=True)["history"], "train_loss": "ab"}
    },
    "history-epochs": lambda ck: {"history": History().to_dict()},  # 0 of the 2 epochs
    "config": lambda ck: {"config": "adamw"},
    "run_options": lambda ck: {"run_options": [1]},
}


@pytest.mark.parametrize("damage", DAMAGE, ids=list(DAMAGE))
def test_damaged_training_state(ck, damage) -> None:
    entry = damage.split("-")[0]
    _edit(ck, **DAMAGE[damage](ck))
    with pytest.raises(FileFormatError) as info:
        _fit(ck, resume=True)
    text = str(info.value)
    assert str(ck) in text and "--overwrite" in text
    assert f"'{entry}'" in text, text


def test_damaged_best_weights(ck) -> None:
    best = ck.with_name("checkpoint.best.pt")
    state = torch.load(best, weights_only=True)
    state["model"] = {k: v[:1] for k, v in state["model"].items()}  # reshaped
    save_checkpoint(best, state)
    with pytest.raises(FileFormatError, match=str(best)):
        _fit(ck, resume=True)


# ------------------------------------------------------------------ epoch_loop (pose, cloud)
def _epoch_loop(ck, resume=False):
    model = _model(3)
    data = _blobs(24)
    x, y = data.tensors

    def batch(idx):
        return nn.functional.cross_entropy(model(x[idx]), y[idx])

    cfg = TrainConfig(epochs=1, batch_size=8, device="cpu")
    gen = torch.Generator().manual_seed(0)
    return epoch_loop(
        model, len(y), cfg, gen, batch, lambda: 0.5, desc="t", progress=False,
        checkpoint=ck, resume=resume,
    )  # fmt: skip


@pytest.mark.parametrize(
    "history",
    [None, {"losses": "ab", "seconds": [], "val": {}, "best_epoch": 1}, {"losses": [1.0]}],
)
def test_epoch_loop_resume_with_a_damaged_history(tmp_path, history) -> None:
    ck = tmp_path / "c.pt"
    _epoch_loop(ck)
    _edit(ck, history=history)
    with pytest.raises(FileFormatError, match=r"'history'.*--overwrite"):
        _epoch_loop(ck, resume=True)


def test_history_records_are_checked() -> None:
    h = EpochHistory()
    h.load_dict({"losses": [1.0], "seconds": [0.5], "val": {"1": 0.25}, "best_epoch": 1})
    assert h.val == {1: 0.25} and h.best_epoch == 1
    for bad in (
        {"losses": [1.0], "seconds": [], "val": {}, "best_epoch": 1},
        {"losses": [1.0], "seconds": [0.5], "val": {"x": 1}, "best_epoch": 1},
        {"losses": [1.0], "seconds": [0.5], "val": {"1": "a"}, "best_epoch": 1},
        {"losses": [1.0], "seconds": [0.5], "val": {}, "best_epoch": 1.5},
        [1, 2],
    ):
        with pytest.raises(InputError, match="history"):
            h.load_dict(bad)
    assert h.val == {1: 0.25}  # unchanged
    whole = History([1], [1.0], [0.5], [math.nan], [math.nan], [0.1], [2.0], 1, "")
    assert repr(History.from_dict(whole.to_dict())) == repr(whole)  # NaN != NaN
    for bad in ({"epoch": [1.5]}, {"epoch": [1], "lr": []}, {"stopped": 1}, {"best_epoch": "1"}):
        with pytest.raises(InputError, match="history"):
            History.from_dict(bad)
