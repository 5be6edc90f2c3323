"""ONNX export: onnxruntime gives torch's outputs (issue 23)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
ort = pytest.importorskip("onnxruntime")

from torch import nn  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.core.export import export_onnx  # noqa: E402


def _net() -> nn.Module:
    torch.manual_seed(0)
    net = nn.Sequential(
        nn.Conv2d(1, 8, 3, padding=1),
        nn.BatchNorm2d(8),
        nn.ReLU(),
        nn.MaxPool2d(2),
        nn.Conv2d(8, 8, 3, padding=1),
        nn.ReLU(),
        nn.AdaptiveAvgPool2d(1),
        nn.Flatten(),
        nn.Dropout(0.5),
        nn.Linear(8, 10),
    )
    net(torch.randn(16, 1, 8, 8))  # batch-norm statistics that are not the defaults
    return net.eval()


def test_onnxruntime_matches_torch(tmp_path) -> None:
    net = _net()
    path = export_onnx(net, tmp_path / "net.onnx", (1, 8, 8))
    x = np.random.default_rng(0).normal(size=(5, 1, 8, 8)).astype(np.float32)  # batch 5: dynamic
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (ours,) = sess.run(["logits"], {"images": x})
    with torch.no_grad():
        ref = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(ours, ref, atol=1e-4, rtol=1e-4)


def test_export_keeps_the_training_mode_and_checks_names(tmp_path) -> None:
    net = _net().train()
    export_onnx(net, tmp_path / "n.onnx", (1, 8, 8))
    assert net.training
    with pytest.raises(InputError, match=r"extension \.onnx"):
        export_onnx(net, tmp_path / "n.pt", (1, 8, 8))
    with pytest.raises(InputError, match=r"\(C, H, W\)"):
        export_onnx(net, tmp_path / "n.onnx", (8, 8))  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["vgg_small", "inception_small", "resnet_small"])
def test_every_model_of_the_family_exports(tmp_path, name) -> None:
    from robopercept.nn.classification.models import build_model
    from robopercept.nn.data.augment import Normalize

    torch.manual_seed(0)
    net = nn.Sequential(Normalize([0.3], [0.4]), build_model(name, in_channels=1, num_classes=10))
    net(torch.rand(8, 1, 8, 8))  # batch-norm running statistics off their defaults
    net.eval()
    path = export_onnx(net, tmp_path / f"{name}.onnx", (1, 8, 8))
    x = np.random.default_rng(1).random((3, 1, 8, 8)).astype(np.float32)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (ours,) = sess.run(["logits"], {"images": x})
    with torch.no_grad():
        ref = net(torch.from_numpy(x)).numpy()
    np.testing.assert_allclose(ours, ref, atol=1e-4, rtol=1e-4)


# issue 25: no model, bytes or int paths, shapes of bools, NaN or 2**40, opsets of 0.99
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"model": None}, r"model must be a torch.nn.Module"),
        ({"path": 3}, r"must be a file or folder path"),
        ({"path": "net.onx"}, r"needs the extension .onnx"),
        ({"input_shape": (1, 16, True)}, r"input_shape must be \(C, H, W\) of positive"),
        ({"input_shape": (float("nan"),) * 3}, r"input_shape must be \(C, H, W\)"),
        ({"input_shape": None}, r"input_shape must be \(C, H, W\)"),
        ({"input_shape": (1, 2**20, 2**20)}, r"at most 4,194,304"),
        ({"input_shape": (1, 1, 1)}, r"the model cannot run on input_shape \(1, 1, 1\)"),
        ({"input_shape": (3, 8, 8)}, r"the model cannot run on input_shape"),
        ({"opset": 0.99999}, r"opset must be an integer"),
        ({"opset": 99}, r"opset must be an ONNX operator set in 7 .. 23"),
    ],
)
def test_issue25_bad_arguments_are_refused(tmp_path, kwargs, match) -> None:
    args = {"model": _net(), "path": tmp_path / "net.onnx", "input_shape": (1, 8, 8), **kwargs}
    with pytest.raises(InputError, match=match):
        export_onnx(**args)
    assert not (tmp_path / "net.onnx").exists()


def test_issue25_bytes_path_and_numpy_shape_export(tmp_path) -> None:
    p = export_onnx(_net(), str(tmp_path / "net.onnx").encode(), (np.int64(1), 8, 8))
    assert p.exists() and p.stat().st_size > 0
