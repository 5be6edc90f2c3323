"""robopercept.nn.classification.run: the run's architecture record and the checks at its boundary
(the end-to-end runs are in tests/cli/test_nn_cli.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.classification.run import (  # noqa: E402
    evaluate_run,
    load_data,
    predict,
    train_ddp,
    train_run,
)
from robopercept.nn.classification.saved import Architecture, load_run  # noqa: E402
from robopercept.nn.train.config import TrainConfig  # noqa: E402

ARCH = Architecture(
    model="resnet_small",
    kwargs={"widths": [8, 16]},
    in_channels=3,
    num_classes=2,
    input_size=(12, 10),
    classes=("cat", "dog"),
    mode="rgb",
)


def test_architecture_round_trip_and_build() -> None:
    assert Architecture.from_json(ARCH.to_json()) == ARCH
    model = ARCH.build()
    torch.manual_seed(0)
    out = model(torch.rand(4, 3, 12, 10))
    assert out.shape == (4, 2)
    # the first layer is the identity Normalize until the run's statistics are loaded
    x = torch.rand(1, 3, 12, 10)
    assert torch.equal(model[0](x), x)


@pytest.mark.parametrize(
    "text",
    [
        None,
        "vgg",
        json.dumps({"model": "vgg_small"}),  # no run marker
        ARCH.to_json().replace("resnet_small", "alexnet"),  # unknown builder
        ARCH.to_json().replace('"dog"', '"dog", "cow"'),  # 3 names for 2 classes
    ],
)
def test_architecture_refuses_foreign_records(text) -> None:
    with pytest.raises(FileFormatError, match="architecture"):
        Architecture.from_json(text, "x.pt")


def test_load_data_names_and_folders(tmp_path) -> None:
    ds = load_data("digits")
    assert ds.image_shape == (1, 8, 8) and len(ds) == 1797
    with pytest.raises(InputError, match=r"no such folder.*'digits', 'lfw'"):
        load_data(tmp_path / "missing")


def test_train_run_refuses_before_any_work(tmp_path) -> None:
    with pytest.raises(InputError, match=r"unknown model 'alexnet'.*vgg_small"):
        train_run("digits", "alexnet", tmp_path / "r")
    with pytest.raises(InputError, match="fractions"):
        train_run("digits", "vgg_small", tmp_path / "r", fractions=(0.5, 0.5))
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match="is a file"):
        train_run("digits", "vgg_small", tmp_path / "file")
    assert not (tmp_path / "r").exists()


def test_predict_refuses_bad_arguments(tmp_path) -> None:
    with pytest.raises(InputError, match="no images"):
        predict(tmp_path / "c.pt", [])
    with pytest.raises(InputError, match="--top-k"):
        predict(tmp_path / "c.pt", ["a.png"], top_k=0)
    with pytest.raises(FileFormatError, match="no such checkpoint"):
        predict(tmp_path / "c.pt", ["a.png"])


def test_predict_resizes_to_the_input_size(tmp_path) -> None:
    """A checkpoint made by hand: the model sees the image resized to 12x10, so a
    constant image gives the same probabilities at any file size."""
    from robopercept.imaging import write_image
    from robopercept.nn.train.checkpoint import save_checkpoint

    torch.manual_seed(0)
    model = ARCH.build().eval()
    save_checkpoint(
        tmp_path / "c.pt", {"model": model.state_dict(), "architecture": ARCH.to_json()}
    )
    small, big = tmp_path / "small.png", tmp_path / "big.png"
    write_image(small, np.full((12, 10, 3), 128, np.uint8))
    write_image(big, np.full((48, 40, 3), 128, np.uint8))
    a, b = predict(tmp_path / "c.pt", [small, big], top_k=5)
    assert len(a.top) == 2  # at most the number of classes
    assert [c for c, _ in a.top] == [c for c, _ in b.top]
    np.testing.assert_allclose([p for _, p in a.top], [p for _, p in b.top], atol=1e-6)
    with torch.no_grad():
        ref = torch.softmax(model(torch.full((1, 3, 12, 10), 128 / 255)), 1)[0]
    np.testing.assert_allclose(sorted(ref.tolist(), reverse=True), [p for _, p in a.top], atol=1e-6)


def test_ctrl_c_keeps_the_checkpoint_and_writes_the_history(tmp_path, monkeypatch) -> None:
    """An interrupted run leaves its last complete checkpoint and history.csv readable."""
    import robopercept.nn.classification.run as run_module
    from robopercept.nn.train.checkpoint import save_checkpoint
    from robopercept.nn.train.config import History

    def interrupted_fit(model, train, val, config, *, checkpoint, **kwargs):
        hist = History(
            epoch=[1, 2],
            train_loss=[1.0, 0.5],
            train_accuracy=[0.5, 0.8],
            val_loss=[1.1, 0.6],
            val_accuracy=[0.4, 0.7],
            lr=[0.1, 0.1],
            seconds=[1.0, 1.0],
        )
        save_checkpoint(checkpoint, {"model": model.state_dict(), "history": hist.to_dict()})
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, "fit", interrupted_fit)
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        run_module.train_run("digits", "vgg_small", out, progress=False)
    lines = (out / "history.csv").read_text().splitlines()
    assert len(lines) == 3 and lines[2].startswith("2,0.5,")
    assert (out / "checkpoint.pt").exists()


# issue 25: devices torch does not know, paths of the wrong type, a bare string of paths
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda p: load_run(p, device="CPU"), r"device \(--device\) must be 'auto', 'cpu', 'cuda'"),
        (lambda p: load_run(p, device=" cpu "), r"got ' cpu '"),
        (lambda p: load_run(p, device=["cpu"]), r"device \(--device\) must be"),
        (lambda p: load_run(p, device=3), r"device \(--device\) must be"),
        (lambda p: load_run(3), r"the checkpoint .* must be a file or folder path"),
        (lambda p: load_run(p / ("n" * 300)), r"file name too long"),
        (lambda p: predict(p, ["a.png"], device=""), r"got ''"),
        (lambda p: predict(p, ["a.png"], device=float("nan")), r"device \(--device\)"),
        (lambda p: predict(p, ["a.png"], top_k=2.5), r"top_k \(--top-k\) must be an integer"),
        (lambda p: predict(p, 3), r"image_paths must be a list of image files"),
        (lambda p: predict(p, [None]), r"each image path must be a file or folder path"),
        (lambda p: evaluate_run(p, "digits", device="bogus"), r"got 'bogus'"),
        (lambda p: load_data(3), r"--data \(digits, lfw or an image folder\) must be a file"),
        (lambda p: load_data("digits", mode="grey"), r"mode must be one of 'rgb', 'gray'"),
        (lambda p: load_data(p, size=()), r"size must be \(width, height\)"),
    ],
)
def test_issue25_bad_arguments_are_refused(tmp_path, call, match) -> None:
    (tmp_path / "a").mkdir()
    with pytest.raises(InputError, match=match):
        call(tmp_path)


def test_issue25_bytes_names_the_built_in_set() -> None:
    assert load_data(b"digits").image_shape == (1, 8, 8)


def test_train_ddp_refuses_bad_process_counts(tmp_path) -> None:
    with pytest.raises(InputError, match=r"nproc \(--nproc\) must be >= 1"):
        train_ddp("digits", "vgg_small", tmp_path, nproc=0)
    with pytest.raises(InputError, match="--nproc 3 is larger than --batch-size 2"):
        train_ddp("digits", "vgg_small", tmp_path, nproc=3, config=TrainConfig(batch_size=2))
    with pytest.raises(InputError, match=r"--batch-size 63 .*multiple of --nproc 2"):
        train_ddp("digits", "vgg_small", tmp_path, nproc=2, config=TrainConfig(batch_size=63))


def test_rank_errors_come_back_from_train_ddp(tmp_path) -> None:
    # every rank refuses the unknown model; the launcher raises the error itself
    with pytest.raises(InputError, match="unknown model 'nope'"):
        train_ddp("digits", "nope", tmp_path, nproc=2, threads=1, timeout=120)
