"""ONNX export: onnxruntime gives torch's outputs (issue 23)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
ort = pytest.importorskip("onnxruntime")

from torch import nn  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.export import export_onnx  # noqa: E402


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
    from robopercept.nn.models import build_model
    from robopercept.nn.training import Normalize

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
