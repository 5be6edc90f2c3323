"""Per-layer summary of a model: output shapes, parameters and receptive fields.

:func:`summary` runs one forward pass on zeros with forward hooks on every module and
records a row per call of a leaf module (one with no children), in execution order, as
``torchinfo.summary`` does: its rows, output shapes and parameter counts equal
torchinfo's ``summary_list`` leaf layers, ``total_params`` and ``trainable_params``.

Receptive fields follow the recurrence of Araujo et al. (2019), "Computing receptive
fields of convolutional neural networks", per spatial axis, through convolutions and
pools (kernel ``k``, stride ``s``, dilation ``d``):

    r_out = r_in + (k - 1) d j_in,    j_out = j_in s,

starting from ``r = j = 1`` at the input; element-wise layers (batch norm,
activations, dropout) keep them. Where branches merge (a residual sum, an Inception
concatenation) the field is the largest among the branches' tensors of that spatial
size, the union of centred windows. After a global pool, flatten or linear layer the
field is the whole input and is not reported (``None``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from robopercept.errors import InputError
from robopercept.nn._guards import check_device, check_float_dtype, check_module

#: the most values the dummy input of :func:`summary` may have (16 MiB of float32)
MAX_INPUT_VALUES = 2**22

__all__ = ["LayerRow", "ModelSummary", "summary"]

#: layers that change neither the receptive field nor the jump
_ELEMENTWISE = (
    nn.BatchNorm1d,
    nn.BatchNorm2d,
    nn.GroupNorm,
    nn.LayerNorm,
    nn.Identity,
    nn.Dropout,
    nn.Dropout2d,
    nn.ReLU,
    nn.ReLU6,
    nn.LeakyReLU,
    nn.GELU,
    nn.SiLU,
    nn.Sigmoid,
    nn.Tanh,
    nn.ELU,
    nn.Hardswish,
)

Field = tuple[tuple[int, int], tuple[int, int]]  # ((r_h, r_w), (j_h, j_w))


@dataclass(frozen=True)
class LayerRow:
    """One call of a leaf layer.

    Attributes
    ----------
    name : str
        Qualified module name (``features.0.conv1.conv``).
    type : str
        Class name (``Conv2d``).
    depth : int
        Nesting depth (1 for a child of the model).
    output_shape : tuple of int
        Shape of the output, batch included, as torchinfo's ``output_size``.
    params : int
        Parameters of the layer (counted once, even if called twice).
    trainable_params : int
        Those with ``requires_grad``.
    receptive_field : tuple of int or None
        ``(height, width)`` in input pixels of one output element; ``None`` where not
        defined (after a global pool or a linear layer).
    jump : tuple of int or None
        ``(height, width)`` distance in input pixels between adjacent outputs.
    """

    name: str
    type: str
    depth: int
    output_shape: tuple[int, ...]
    params: int
    trainable_params: int
    receptive_field: tuple[int, int] | None
    jump: tuple[int, int] | None

    @property
    def trainable(self) -> bool:
        """True when the layer has parameters and all of them are trainable."""
        return self.params > 0 and self.trainable_params == self.params


@dataclass(frozen=True)
class ModelSummary:
    """The result of :func:`summary`; ``str()`` gives the table.

    Attributes
    ----------
    model : str
        Class name of the model.
    input_shape : tuple of int
        ``(N, C, H, W)``.
    output_shape : tuple of int
    rows : tuple of LayerRow
        One per call of a leaf layer, in execution order.
    total_params, trainable_params : int
        Unique parameters of the model (``model.parameters()``).
    """

    model: str
    input_shape: tuple[int, ...]
    output_shape: tuple[int, ...]
    rows: tuple[LayerRow, ...]
    total_params: int
    trainable_params: int

    @property
    def non_trainable_params(self) -> int:
        """``total_params - trainable_params``."""
        return self.total_params - self.trainable_params

    def __str__(self) -> str:
        header = ("Layer", "Type", "Output shape", "Param #", "Train", "RF")
        lines = []
        for row in self.rows:
            rf = row.receptive_field
            lines.append(
                (
                    row.name,
                    row.type,
                    str(list(row.output_shape)),
                    f"{row.params:,}",
                    ("yes" if row.trainable else "no") if row.params else "",
                    "" if rf is None else f"{rf[0]}x{rf[1]}",
                )
            )
        widths = [max(len(r[i]) for r in [header, *lines]) for i in range(len(header))]

        def fmt(cells: Sequence[str]) -> str:
            return "  ".join(
                c.ljust(w) if i < 3 else c.rjust(w)
                for i, (c, w) in enumerate(zip(cells, widths, strict=True))
            ).rstrip()

        rule = "-" * len(fmt(header))
        out = [f"{self.model}  input {list(self.input_shape)}", rule, fmt(header), rule]
        out += [fmt(line) for line in lines]
        out += [
            rule,
            f"Total params: {self.total_params:,}",
            f"Trainable params: {self.trainable_params:,}",
            f"Non-trainable params: {self.non_trainable_params:,}",
            f"Output shape: {list(self.output_shape)}",
        ]
        return "\n".join(out)


def _pair(value: Any) -> tuple[int, int]:
    return (int(value[0]), int(value[1])) if isinstance(value, tuple) else (int(value),) * 2


def _spatial(t: torch.Tensor) -> tuple[int, ...]:
    return tuple(t.shape[2:]) if t.ndim == 4 else ()


def summary(
    model: nn.Module,
    input_shape: Sequence[int],
    *,
    device: str | torch.device | None = None,
    dtype: torch.dtype = torch.float32,
) -> ModelSummary:
    """Summarize ``model`` on an input of ``input_shape``: shapes, parameters, fields.

    Parameters
    ----------
    model : nn.Module
        Any module taking one ``(N, C, H, W)`` tensor. Its train/eval mode is kept; the
        forward pass runs under ``torch.no_grad`` in eval mode, so batch-norm running
        statistics are not changed.
    input_shape : sequence of int
        ``(N, C, H, W)``, or ``(C, H, W)`` for a batch of one.
    device : str or torch.device, optional
        Where to run; default the device of the model's first parameter (CPU if none).
    dtype : torch.dtype, default torch.float32

    Returns
    -------
    ModelSummary
        Rows per leaf-layer call; equal to ``torchinfo.summary(model,
        input_size=input_shape, verbose=0)``'s leaf rows (output size and parameter
        counts) and totals.

    Raises
    ------
    InputError
        A shape that is not 3 or 4 positive integers (or of more than
        :data:`MAX_INPUT_VALUES` values), one the model refuses (the model's own message
        is kept), a ``model`` that is not an ``nn.Module``, a device this machine does
        not have, or a ``dtype`` that is not a floating-point ``torch.dtype``.

    Examples
    --------
    >>> from robopercept.nn.classification.models import vgg_small
    >>> s = summary(vgg_small(), (1, 8, 8))
    >>> s.total_params, s.rows[-1].output_shape
    (72666, (1, 10))
    >>> s.rows[1].receptive_field  # the first 3x3 convolution's batch norm
    (3, 3)
    """
    model = check_module(model)
    bad_shape = InputError(
        f"input_shape must be (N, C, H, W) or (C, H, W) of positive integers; got "
        f"{input_shape!r} (e.g. (1, 8, 8) for 8x8 grey digits)"
    )
    if not isinstance(input_shape, (tuple, list, torch.Size)):
        raise bad_shape
    shape = tuple(input_shape)
    if len(shape) == 3:
        shape = (1, *shape)
    if len(shape) != 4 or any(
        isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1 for s in shape
    ):
        raise bad_shape
    shape = tuple(int(s) for s in shape)
    dtype = check_float_dtype(dtype)
    if math.prod(shape) > MAX_INPUT_VALUES:
        raise InputError(
            f"input_shape {shape} has {math.prod(shape):,} values; a summary runs one "
            f"small batch: at most {MAX_INPUT_VALUES:,} (e.g. (1, 3, 224, 224))"
        )
    device = check_device(device)
    first = next(model.parameters(), None)
    if first is not None and first.is_floating_point() and first.dtype != dtype:
        raise InputError(
            f"dtype {dtype} differs from the model's weights ({first.dtype}): pass "
            f"dtype={first.dtype} or convert the model (model.to({dtype}))"
        )
    if device is None:
        device = first.device if first is not None else torch.device("cpu")
    names = {m: n for n, m in model.named_modules()}
    counted: set[int] = set()
    rows: list[LayerRow] = []
    fields: dict[int, tuple[torch.Tensor, Field]] = {}  # id(tensor) -> (tensor, field)
    scopes: list[list[tuple[tuple[int, ...], Field]]] = []  # per open container

    def remember(t: torch.Tensor, field: Field) -> None:
        fields[id(t)] = (t, field)  # keep t alive so that its id is not reused
        for scope in scopes:
            scope.append((_spatial(t), field))

    def field_of(t: torch.Tensor) -> Field | None:
        if id(t) in fields and fields[id(t)][0] is t:
            return fields[id(t)][1]
        # a merge (sum, concatenation) made outside any leaf: largest field of this size
        if scopes:
            size = _spatial(t)
            found = [f for s, f in scopes[-1] if s == size]
            if found:
                return max(found, key=lambda f: f[0][0] * f[0][1])
        return None

    def pre_container(module: nn.Module, args: tuple[Any, ...]) -> None:
        scopes.append([])
        if args and isinstance(args[0], torch.Tensor):
            field = field_of(args[0])
            if field is not None:
                scopes[-1].append((_spatial(args[0]), field))

    def post_container(module: nn.Module, args: tuple[Any, ...], output: Any) -> None:
        scope = scopes[-1]
        if isinstance(output, torch.Tensor) and field_of(output) is None:
            size = _spatial(output)
            found = [f for s, f in scope if s == size]
            if found:
                remember(output, max(found, key=lambda f: f[0][0] * f[0][1]))
        scopes.pop()

    def leaf(module: nn.Module, args: tuple[Any, ...], output: Any) -> None:
        params = 0
        trainable = 0
        for p in module.parameters():
            if id(p) not in counted:
                counted.add(id(p))
                params += p.numel()
                trainable += p.numel() if p.requires_grad else 0
        field = None
        if args and isinstance(args[0], torch.Tensor) and isinstance(output, torch.Tensor):
            before = field_of(args[0])
            if before is not None and output.ndim == 4:
                if isinstance(module, (nn.Conv2d, nn.MaxPool2d, nn.AvgPool2d)):
                    k = _pair(module.kernel_size)
                    s = _pair(module.stride)
                    d = _pair(getattr(module, "dilation", 1))
                    (r, j) = before
                    field = (
                        (r[0] + (k[0] - 1) * d[0] * j[0], r[1] + (k[1] - 1) * d[1] * j[1]),
                        (j[0] * s[0], j[1] * s[1]),
                    )
                elif isinstance(module, _ELEMENTWISE):
                    field = before
            if field is not None:
                remember(output, field)
        name = names.get(module, type(module).__name__)
        out_shape = tuple(output.shape) if isinstance(output, torch.Tensor) else ()
        rows.append(
            LayerRow(
                name=name,
                type=type(module).__name__,
                depth=name.count(".") + 1,
                output_shape=out_shape,
                params=params,
                trainable_params=trainable,
                receptive_field=None if field is None else field[0],
                jump=None if field is None else field[1],
            )
        )

    handles = []
    for module in model.modules():
        if next(module.children(), None) is None:
            handles.append(module.register_forward_hook(leaf))
        else:
            handles.append(module.register_forward_pre_hook(pre_container))
            handles.append(module.register_forward_hook(post_container))
    was_training = model.training
    x = torch.zeros(shape, device=device, dtype=dtype)
    try:
        model.eval()
        remember(x, ((1, 1), (1, 1)))
        with torch.no_grad():
            output = model(x)
    finally:
        for h in handles:
            h.remove()
        model.train(was_training)
    params = list(model.parameters())
    return ModelSummary(
        model=type(model).__name__,
        input_shape=shape,
        output_shape=tuple(output.shape) if isinstance(output, torch.Tensor) else (),
        rows=tuple(rows),
        total_params=sum(p.numel() for p in params),
        trainable_params=sum(p.numel() for p in params if p.requires_grad),
    )
