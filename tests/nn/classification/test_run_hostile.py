"""Hostile run checkpoints for ``nn eval`` / ``nn predict`` (issue 47: R37, R38, R39,
R45): every field of the architecture record is checked, and the weights and the
normalization statistics too, before a model is used; the errors are FileFormatError
naming the file."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.imaging import write_image  # noqa: E402
from robopercept.nn.classification.run import predict, train_run  # noqa: E402
from robopercept.nn.classification.saved import (  # noqa: E402
    MAX_INPUT_SIDE,
    Architecture,
    load_run,
)
from robopercept.nn.train.checkpoint import save_checkpoint  # noqa: E402

ARCH = Architecture(
    model="resnet_small",
    kwargs={"widths": [4, 8]},
    in_channels=1,
    num_classes=2,
    input_size=(8, 8),
    classes=("a", "b"),
    mode="gray",
)


def _record(**changes) -> str:
    d = json.loads(ARCH.to_json())
    for k, v in changes.items():
        if v is KeyError:
            del d[k]
        else:
            d[k] = v
    return json.dumps(d)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        # R37: Infinity gave OverflowError, deep nesting RecursionError
        (_record(in_channels=float("inf")), "in_channels"),
        (ARCH.to_json().replace('"in_channels": 1', '"in_channels": Infinity'), "in_channels"),
        (ARCH.to_json().replace('"in_channels": 1', '"in_channels": 1e400'), "in_channels"),
        ('{"robopercept_run": 1, "kwargs": ' + "[" * 100_000 + "]" * 100_000 + "}", "architecture"),
        ("[" * 100_000, "architecture"),
        (_record(in_channels=True), "in_channels"),
        (_record(in_channels=1.0), "in_channels"),
        (_record(in_channels=3), "in_channels"),  # a grey model has one channel
        (_record(in_channels=2**70), "in_channels"),
        (_record(num_classes=0, classes=[]), "num_classes"),
        (_record(num_classes=10**9), "num_classes"),
        (_record(classes=["a", 2]), "classes"),
        (_record(classes="ab"), "classes"),
        (_record(mode="cmyk"), "mode"),
        (_record(model=["resnet_small"]), "model"),
        (_record(kwargs=[1, 2]), "kwargs"),
        (_record(kwargs={"in_channels": 3}), "kwargs"),
        # R38: the input size, never checked, allocated 10 GB or crashed in torch
        (_record(input_size=[30000, 30000]), "input_size"),
        (_record(input_size=[MAX_INPUT_SIDE + 1, 8]), "input_size"),
        (_record(input_size=[0, 8]), "input_size"),
        (_record(input_size=[-8, 8]), "input_size"),
        (_record(input_size=[8]), "input_size"),
        (_record(input_size=[8, 8, 8]), "input_size"),
        (_record(input_size=[8.0, 8]), "input_size"),
        (_record(input_size="8x8"), "input_size"),
        (_record(input_size={"0": 8, "1": 8}), "input_size"),
        (_record(robopercept_run=True), "architecture"),
        (_record(robopercept_run=2), "architecture"),
        (_record(extra=1), "unknown fields"),
        (_record(mode=KeyError), "missing"),
        (b"\xff\xfe{", "architecture"),
        (12, "architecture"),
    ],
)
def test_from_json_checks_every_field(text, match) -> None:
    with pytest.raises(FileFormatError, match=match) as info:
        Architecture.from_json(text, "run/x.pt")
    assert str(info.value).startswith("run/x.pt")


def test_from_json_takes_its_own_records() -> None:
    assert Architecture.from_json(ARCH.to_json()) == ARCH
    assert Architecture.from_json(ARCH.to_json().encode()) == ARCH


def _save(path, arch_text=None, **entries):
    torch.manual_seed(0)
    model = ARCH.build()
    state = {"model": model.state_dict(), "architecture": arch_text or ARCH.to_json()}
    state.update(entries)
    save_checkpoint(path, state)
    return path


def test_a_good_checkpoint_loads(tmp_path) -> None:
    model, arch = load_run(_save(tmp_path / "c.pt"))
    assert arch == ARCH and not model.training


@pytest.mark.parametrize(
    "entry",
    [[1, 2], torch.zeros(3), "weights", {"0.mean": [0.0]}],
    ids=["list", "tensor", "str", "dict-of-lists"],
)
def test_a_model_entry_that_is_not_named_tensors(tmp_path, entry) -> None:
    # R39: a list or a tensor as "model" gave TypeError while sorting the keys
    path = _save(tmp_path / "c.pt", model=entry)
    with pytest.raises(FileFormatError, match=str(path)):
        load_run(path)


@pytest.mark.parametrize(
    ("std", "mean"),
    [(0.0, 0.5), (-1.0, 0.5), (float("nan"), 0.5), (float("inf"), 0.5), (1.0, float("nan"))],
)
def test_unusable_normalization_statistics(tmp_path, std, mean) -> None:
    # R45: a zero or NaN std loaded silently and nn predict printed probability nan
    torch.manual_seed(0)
    model = ARCH.build()
    weights = model.state_dict()
    weights["0.std"] = torch.full_like(weights["0.std"], std)
    weights["0.mean"] = torch.full_like(weights["0.mean"], mean)
    path = _save(tmp_path / "c.pt", model=weights)
    with pytest.raises(FileFormatError, match=rf"{path}.*(normalization|finite)"):
        load_run(path)


def test_nan_weights_are_refused(tmp_path) -> None:
    # R45: NaN weights (the finiteness check of nn.train.checkpoint.load_checkpoint)
    torch.manual_seed(0)
    weights = ARCH.build().state_dict()
    name = next(k for k, v in weights.items() if k.endswith("weight") and v.ndim == 4)
    weights[name][0, 0, 0, 0] = float("nan")
    path = _save(tmp_path / "c.pt", model=weights)
    with pytest.raises(FileFormatError, match=str(path)):
        load_run(path)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"bogus": 1}, "cannot be built"),
        ({"widths": [2**20, 2**20]}, "cannot be built"),
        ({"dropout": 2.0}, "cannot be built"),
    ],
)
def test_builder_arguments_the_builder_refuses(tmp_path, kwargs, match) -> None:
    path = _save(tmp_path / "c.pt", arch_text=_record(kwargs=kwargs))
    with pytest.raises(FileFormatError, match=match):
        load_run(path)


def test_an_input_size_the_model_cannot_take(tmp_path) -> None:
    # vgg_small pools 8 x 8 down: a 1 x 1 input gave torch's RuntimeError in predict
    text = _record(model="vgg_small", kwargs={}, input_size=[1, 1])
    path = _save(tmp_path / "c.pt", arch_text=text)
    with pytest.raises(FileFormatError, match="cannot take its recorded input size 1 x 1"):
        load_run(path)


def test_predict_refuses_a_huge_input_size_at_once(tmp_path) -> None:
    # R38: 30000 x 30000 made nn predict grow by 10 GB before anything was said
    path = _save(tmp_path / "c.pt", arch_text=_record(input_size=[30000, 30000]))
    img = tmp_path / "x.png"
    write_image(img, np.zeros((8, 8), np.uint8))
    t0 = time.perf_counter()
    with pytest.raises(FileFormatError, match="input_size"):
        predict(path, [img])
    assert time.perf_counter() - t0 < 5


def _folder(root, size=(6, 6)):
    for c in ("a", "b"):
        (root / c).mkdir(parents=True)
        for i in range(4):
            write_image(root / c / f"{i}.png", np.full((*size, 3), 40 * i, np.uint8))
    return root


def test_train_run_refuses_what_no_checkpoint_could_record(tmp_path) -> None:
    data = _folder(tmp_path / "data")
    with pytest.raises(InputError, match=rf"at most {MAX_INPUT_SIDE} pixels a side.*--size"):
        train_run(data, "vgg_small", tmp_path / "r1", size=(MAX_INPUT_SIDE + 1, 8))
    with pytest.raises(InputError, match=r"cannot take the 2 x 2 images.*--size"):
        train_run(data, "vgg_small", tmp_path / "r2", size=(2, 2))
    with pytest.raises(InputError, match="model_kwargs must be a dict"):
        train_run(data, "vgg_small", tmp_path / "r3", model_kwargs={"dropout": {1, 2}})
    with pytest.raises(InputError, match="fractions"):
        train_run(data, "vgg_small", tmp_path / "r4", fractions=None)
    assert not (tmp_path / "r1" / "checkpoint.pt").exists()
