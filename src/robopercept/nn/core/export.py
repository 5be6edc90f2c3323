"""Export a model to ONNX, for runtimes without PyTorch (onnxruntime, TensorRT, OpenCV's
dnn module).

:func:`export_onnx` traces the model in evaluation mode on a dummy batch of the given
shape, with a dynamic batch axis, through :func:`torch.onnx.export`. The tests check
that onnxruntime gives torch's outputs to 1e-4.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np
import torch
from torch import nn

from robopercept._checks import check_extension, check_int
from robopercept.errors import InputError
from robopercept.nn._guards import check_module

#: the largest ``C * H * W`` of the traced dummy input (16 MiB of float32 per image)
MAX_INPUT_VALUES = 2**22

__all__ = ["export_onnx"]


def export_onnx(
    model: nn.Module,
    path: str | os.PathLike[str],
    input_shape: tuple[int, int, int],
    *,
    opset: int = 18,
) -> Path:
    """Write ``model`` as an ONNX graph with input ``"images"`` ``(N, C, H, W)`` float32
    (N dynamic) and output ``"logits"``.

    Parameters
    ----------
    model : torch.nn.Module
    path : path-like
        ``.onnx`` file.
    input_shape : (C, H, W)
    opset : int
        ONNX operator set.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        ``model`` not an ``nn.Module``, a path without the ``.onnx`` extension, an
        ``input_shape`` that is not three positive integers (or that the model cannot
        run on), or an ``opset`` outside 7 .. 23.
    """
    model = check_module(model)
    p = check_extension(path, {".onnx"}, "an ONNX model file")
    bad = InputError(
        f"input_shape must be (C, H, W) of positive integers, e.g. (1, 8, 8); got {input_shape!r}"
    )
    if not isinstance(input_shape, (tuple, list, torch.Size)) or len(input_shape) != 3:
        raise bad
    if any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in input_shape):
        raise bad
    shape = tuple(check_int(v, "input_shape", 1) for v in input_shape)
    if math.prod(shape) > MAX_INPUT_VALUES:
        raise InputError(
            f"input_shape {shape} has {math.prod(shape):,} values per image; the export "
            f"traces a dummy batch: at most {MAX_INPUT_VALUES:,} (the batch axis is dynamic; "
            "H and W are those the model was trained on)"
        )
    opset = check_int(opset, "opset", 7)
    if opset > 23:
        raise InputError(f"opset must be an ONNX operator set in 7 .. 23; got {opset}")
    p.parent.mkdir(parents=True, exist_ok=True)
    was = model.training
    model.eval()
    first = next(model.parameters(), None)
    device = first.device if first is not None else torch.device("cpu")
    dummy = torch.zeros(2, *shape, device=device)
    try:
        with torch.no_grad():
            model(dummy)  # a shape the model refuses fails here, not inside the tracer
    except RuntimeError as exc:
        model.train(was)
        raise InputError(
            f"the model cannot run on input_shape {shape} ({str(exc).splitlines()[0][:160]}): "
            "give the (C, H, W) of the images it was trained on"
        ) from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            torch.onnx.export(
                model,
                (dummy,),
                str(p),
                input_names=["images"],
                output_names=["logits"],
                dynamic_axes={"images": {0: "batch"}, "logits": {0: "batch"}},
                opset_version=opset,
                dynamo=False,
            )
    finally:
        model.train(was)
    return p
