"""Export a model to ONNX, for runtimes without PyTorch (onnxruntime, TensorRT, OpenCV's
dnn module).

:func:`export_onnx` traces the model in evaluation mode on a dummy batch of the given
shape, with a dynamic batch axis, through :func:`torch.onnx.export`. The tests check
that onnxruntime gives torch's outputs to 1e-4.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import torch
from torch import nn

from robopercept.errors import InputError

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
    """
    p = Path(path)
    if p.suffix.lower() != ".onnx":
        raise InputError(f"{p}: an ONNX model file needs the extension .onnx")
    if len(input_shape) != 3 or min(input_shape) < 1:
        raise InputError(f"input_shape must be (C, H, W); got {input_shape}")
    p.parent.mkdir(parents=True, exist_ok=True)
    was = model.training
    model.eval()
    device = next(model.parameters()).device
    dummy = torch.zeros(2, *input_shape, device=device)
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
