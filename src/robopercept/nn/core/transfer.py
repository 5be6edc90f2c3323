"""Fine-tuning: the notes' three ways to reuse a trained network, made concrete.

1. **As is**: a pretrained network for its own classes (load its checkpoint).
2. **Transfer learning**: keep the learned features, :func:`replace_head` for the new
   classes, :func:`freeze` the trunk (or some stages) and train the head; batch-norm
   layers whose parameters are frozen stay in evaluation mode
   (:func:`keep_frozen_batchnorm_in_eval`: their running statistics are part of what was
   learned); optionally discriminative learning rates
   (:attr:`~robopercept.nn.train.config.TrainConfig.lr_multipliers`) and gradual unfreezing
   (:attr:`~robopercept.nn.train.config.TrainConfig.unfreeze_at`).
3. **From scratch**: the same architecture with fresh weights.

Layers are named by their qualified parameter-name prefixes (``"features.0"``,
``"head"``), as ``model.named_parameters()`` lists them.
"""

from __future__ import annotations

from collections.abc import Iterable

from torch import nn

from robopercept.errors import InputError
from robopercept.nn._guards import MAX_PARAMETERS, check_allocation, check_count, check_module

__all__ = [
    "freeze",
    "keep_frozen_batchnorm_in_eval",
    "replace_head",
    "trainable_parameter_names",
    "unfreeze",
]


def _matching(model: nn.Module, prefixes: Iterable[str] | None) -> list[tuple[str, nn.Parameter]]:
    named = list(check_module(model).named_parameters())
    if prefixes is None:
        return named
    if isinstance(prefixes, str):
        prefixes = [prefixes]
    if isinstance(prefixes, Iterable) and not isinstance(prefixes, (bytes, dict)):
        prefixes = list(prefixes)
    if not isinstance(prefixes, list) or not all(isinstance(pf, str) for pf in prefixes):
        raise InputError(
            "prefixes must be a list of parameter-name prefixes such as ['features.0', "
            f"'head'] (or None for all); got {prefixes!r}"
        )
    wanted = list(prefixes)
    out = [
        (n, p)
        for n, p in named
        if any(n == pf or n.startswith(pf + ".") or pf == "" for pf in wanted)
    ]
    unknown = [
        pf for pf in wanted if pf and not any(n == pf or n.startswith(pf + ".") for n, _ in named)
    ]
    if unknown:
        tops = sorted({n.split(".")[0] for n, _ in named})
        raise InputError(
            f"no parameters under {', '.join(map(repr, unknown))}; the model's top-level "
            f"parts are {', '.join(tops)}"
        )
    return out


def freeze(model: nn.Module, prefixes: Iterable[str] | None = None) -> list[str]:
    """Stop training the parameters under ``prefixes`` (all when None); return their
    names. Frozen parameters get no gradient, no optimizer step and no weight decay."""
    hit = _matching(model, prefixes)
    for _, p in hit:
        p.requires_grad_(False)
    return [n for n, _ in hit]


def unfreeze(model: nn.Module, prefixes: Iterable[str] | None = None) -> list[str]:
    """Train the parameters under ``prefixes`` again (all when None); return their names."""
    hit = _matching(model, prefixes)
    for _, p in hit:
        p.requires_grad_(True)
    return [n for n, _ in hit]


def trainable_parameter_names(model: nn.Module) -> list[str]:
    """Names of the parameters that will be trained (``requires_grad``)."""
    return [n for n, p in check_module(model).named_parameters() if p.requires_grad]


def replace_head(model: nn.Module, num_classes: int, name: str | None = None) -> nn.Linear:
    """Put a new, freshly initialized linear layer for ``num_classes`` classes in place
    of the classifier head and return it.

    Parameters
    ----------
    model : torch.nn.Module
    num_classes : int
    name : str, optional
        Qualified name of the head (``"head"``, ``"classifier.2"``); default: the last
        ``nn.Linear`` of the model.

    Returns
    -------
    torch.nn.Linear
        The new head (trainable), same input features as the old one.
    """
    model = check_module(model)
    num_classes = check_count(num_classes, "num_classes", 2, MAX_PARAMETERS)
    if name is not None and not isinstance(name, str):
        raise InputError(f"name must be the qualified name of a linear layer (str); got {name!r}")
    linears = [(n, m) for n, m in model.named_modules() if isinstance(m, nn.Linear)]
    if name is None:
        if not linears:
            raise InputError("the model has no nn.Linear head to replace; name it with name=")
        name, old = linears[-1]
    else:
        old = dict(model.named_modules()).get(name)  # type: ignore[assignment]
        if not isinstance(old, nn.Linear):
            raise InputError(
                f"{name!r} is not a linear layer of the model; its linear layers are "
                f"{', '.join(n for n, _ in linears) or 'none'}"
            )
    check_allocation(
        old.in_features * num_classes,
        old.weight.element_size(),
        f"the new head ({num_classes} classes x {old.in_features} features)",
        "lower num_classes",
    )
    new = nn.Linear(old.in_features, num_classes, bias=old.bias is not None)
    new.to(old.weight.device)
    parent_name, _, attr = name.rpartition(".")
    parent = model.get_submodule(parent_name) if parent_name else model
    setattr(parent, attr, new)
    return new


def keep_frozen_batchnorm_in_eval(model: nn.Module) -> int:
    """Make every batch-norm layer whose parameters are all frozen run in evaluation
    mode (its stored running mean and variance) even while the model trains; return
    how many layers it applies to now. A forward pre-hook checks at every call, so
    layers unfrozen later train normally again."""

    def hook(module: nn.Module, _args: object) -> None:
        params = list(module.parameters())
        if params and not any(p.requires_grad for p in params):
            module.eval()

    count = 0
    for m in check_module(model).modules():
        if isinstance(m, nn.modules.batchnorm._BatchNorm):
            if not getattr(m, "_robopercept_frozen_bn_hook", False):
                m.register_forward_pre_hook(hook)
                m._robopercept_frozen_bn_hook = True  # type: ignore[assignment]
            if not any(p.requires_grad for p in m.parameters()):
                count += 1
    return count
