"""Fine-tuning: freezing, a new head, frozen batch norm, discriminative rates (issue 23)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402
from torch.utils.data import TensorDataset  # noqa: E402

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.core.transfer import (  # noqa: E402
    freeze,
    keep_frozen_batchnorm_in_eval,
    replace_head,
    trainable_parameter_names,
    unfreeze,
)
from robopercept.nn.train.config import TrainConfig  # noqa: E402
from robopercept.nn.train.fit import fit  # noqa: E402


class _Net(nn.Module):
    def __init__(self, classes: int = 3) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.features = nn.Sequential(nn.Conv2d(1, 4, 3, padding=1), nn.BatchNorm2d(4), nn.ReLU())
        self.pool = nn.AdaptiveAvgPool2d(2)
        self.head = nn.Linear(16, classes)

    def forward(self, x):
        return self.head(self.pool(self.features(x)).flatten(1))


def _data(classes: int = 5, n: int = 100) -> TensorDataset:
    g = torch.Generator().manual_seed(0)
    y = torch.arange(n) % classes
    x = torch.randn(n, 1, 6, 6, generator=g) + y.view(-1, 1, 1, 1).float()
    return TensorDataset(x, y)


def test_freeze_and_replace_head_leaves_only_the_head_trainable() -> None:
    net = _Net()
    frozen = freeze(net)
    assert len(frozen) == 6  # conv, batch norm and head: weight and bias each
    head = replace_head(net, 5)
    assert trainable_parameter_names(net) == ["head.weight", "head.bias"]
    assert head.out_features == 5 and head.in_features == 16 and net.head is head


def test_training_the_head_keeps_the_trunk_and_its_batchnorm() -> None:
    net = _Net()
    freeze(net, ["features"])
    replace_head(net, 5)
    assert keep_frozen_batchnorm_in_eval(net) == 1
    before = {k: v.clone() for k, v in net.features.state_dict().items()}
    fit(net, _data(), None, TrainConfig(epochs=2, lr=0.05), progress=False)
    for k, v in net.features.state_dict().items():  # weights and running statistics
        torch.testing.assert_close(v, before[k], rtol=0, atol=0)


def test_unfreeze_at_and_lr_multipliers() -> None:
    net = _Net()
    freeze(net, ["features"])
    replace_head(net, 5)
    w0 = net.features[0].weight.detach().clone()
    cfg = TrainConfig(
        epochs=2,
        lr=0.05,
        optimizer="sgd",
        schedule="constant",
        lr_multipliers={"features": 0.1},
        unfreeze_at={2: ["features"]},
    )
    fit(net, _data(), None, cfg, progress=False)
    assert not torch.equal(net.features[0].weight, w0)  # trained in epoch 2
    assert "features.0.weight" in trainable_parameter_names(net)


def test_unfreeze_and_bad_names() -> None:
    net = _Net()
    freeze(net)
    assert unfreeze(net, ["head"]) == ["head.weight", "head.bias"]
    with pytest.raises(InputError, match="top-level parts are features, head"):
        freeze(net, ["trunk"])
    with pytest.raises(InputError, match="not a linear layer"):
        replace_head(net, 3, name="features.0")
    with pytest.raises(InputError, match="num_classes"):
        replace_head(net, 1)
    np.testing.assert_equal(len(list(net.parameters())), 6)


# issue 25: a model that is not a module, prefixes that are not names, a head of 2**40
@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: freeze(None), r"model must be a torch.nn.Module"),
        (lambda: unfreeze({}), r"model must be a torch.nn.Module"),
        (lambda: trainable_parameter_names([]), r"model must be a torch.nn.Module"),
        (lambda: keep_frozen_batchnorm_in_eval("object"), r"model must be a torch.nn.Module"),
        (lambda: replace_head(np.eye(3), 5), r"model must be a torch.nn.Module"),
        (lambda: freeze(_Net(), float("nan")), r"prefixes must be a list of parameter-name"),
        (lambda: unfreeze(_Net(), b"x"), r"prefixes must be a list"),
        (lambda: unfreeze(_Net(), [3]), r"prefixes must be a list"),
        (lambda: replace_head(_Net(), [1, 2]), r"num_classes must be an integer"),
        (lambda: replace_head(_Net(), 2**63), r"num_classes must be at most"),
        (lambda: replace_head(_Net(), 2**27), r"the new head .* would take 8 GiB"),
        (lambda: replace_head(_Net(), 5, name=["head"]), r"name must be the qualified name"),
    ],
)
def test_issue25_bad_arguments_are_refused(call, match) -> None:
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_a_single_prefix_string_is_one_prefix() -> None:
    net = _Net()
    assert freeze(net, "features") == freeze(net, ["features"])
    assert trainable_parameter_names(net) == ["head.weight", "head.bias"]
    assert replace_head(net, np.int64(4)).out_features == 4
