"""Boundary guards shared by the modules of :mod:`robopercept.nn` (issue 25).

The generic guards (integers, reals, paths) are :mod:`robopercept._checks`'; these are
the ones that know torch's types: a model, a device, a dtype, a data set, and the size
bounds that keep a parameter from asking for an absurd allocation. torch is imported
inside the functions that need it, so :mod:`robopercept.nn.functional` (NumPy only)
can use :func:`check_allocation` without loading torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from robopercept._checks import check_int, plain_repr
from robopercept.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    import torch
    from torch import nn

__all__ = [
    "MAX_BYTES",
    "MAX_LAYERS",
    "MAX_PARAMETERS",
    "check_allocation",
    "check_count",
    "check_dataset",
    "check_device",
    "check_float_dtype",
    "check_module",
    "check_tensor_dtype",
]

#: the largest single array (bytes) a parameter may make a function build: 1 GiB
MAX_BYTES = 2**30
#: the most parameters a model builder makes (1 GiB of float32 weights)
MAX_PARAMETERS = 2**28
#: the most layers (blocks, convolutions) a count parameter may ask for
MAX_LAYERS = 1024


def check_allocation(elements: int, itemsize: int, what: str, fix: str) -> None:
    """Refuse an array of ``elements`` items of ``itemsize`` bytes beyond :data:`MAX_BYTES`.

    Parameters
    ----------
    elements : int
        Number of items (a Python int: products of huge sizes do not wrap around).
    itemsize : int
        Bytes per item.
    what : str
        What would be built, with its shape, for the message.
    fix : str
        The parameters to lower, in the user's terms.

    Raises
    ------
    InputError
        ``"<what> would take <size>; the limit is 1 GiB: <fix>"``.

    Examples
    --------
    >>> check_allocation(2**40, 8, "the padded input", "lower padding")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: the padded input would take 8 TiB; the limit is 1 GiB: ...
    """
    size = int(elements) * int(itemsize)
    if size > MAX_BYTES:
        raise InputError(f"{what} would take {_bytes(size)}; the limit is 1 GiB: {fix}")


def _bytes(n: int) -> str:
    for unit, shift in (("EiB", 60), ("PiB", 50), ("TiB", 40), ("GiB", 30)):
        if n >= 1 << shift:
            return f"{n / (1 << shift):.3g} {unit}"
    return f"{n / (1 << 20):.3g} MiB"


def check_count(value: Any, name: str, minimum: int = 1, maximum: int = MAX_LAYERS) -> int:
    """Return ``value`` as an int in ``[minimum, maximum]`` (a count of layers, blocks,
    classes, images ...).

    Parameters
    ----------
    value : int
        A Python or NumPy integer (``bool``, floats and strings are refused).
    name : str
        The parameter (with its CLI flag where it has one) for the message.
    minimum, maximum : int

    Returns
    -------
    int

    Raises
    ------
    InputError
        Not an integer, or out of range (the message names the range).

    Examples
    --------
    >>> check_count(3, "depth")
    3
    >>> check_count(2**63, "depth")
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: depth must be at most 1024; got 9223372036854775808
    """
    v = check_int(value, name, minimum)
    if v > maximum:
        raise InputError(f"{name} must be at most {maximum}; got {v}")
    return v


def check_module(model: Any, name: str = "model") -> nn.Module:
    """Return ``model`` after checking that it is a :class:`torch.nn.Module`.

    Parameters
    ----------
    model : torch.nn.Module
    name : str
        The parameter named in the message.

    Returns
    -------
    torch.nn.Module

    Raises
    ------
    InputError
        Anything else (a checkpoint path: load it with
        ``robopercept.nn.classification.saved.load_run``).
    """
    from torch import nn

    if not isinstance(model, nn.Module):
        raise InputError(
            f"{name} must be a torch.nn.Module "
            "(e.g. robopercept.nn.classification.models.build_model(...)); "
            f"got {type(model).__name__} {plain_repr(model)[:60]}: for a checkpoint file, "
            "load the model with robopercept.nn.classification.saved.load_run"
        )
    return model


def check_device(device: Any, name: str = "device") -> torch.device | None:
    """Return ``device`` as a :class:`torch.device` this machine has (``None`` stays
    ``None``: the caller picks its default).

    Parameters
    ----------
    device : str, torch.device or None
        ``"auto"`` (CUDA when torch sees a GPU, else the CPU), ``"cpu"``, ``"cuda"``,
        ``"cuda:1"``, ``"mps"``.
    name : str
        The parameter (and CLI flag) for the message.

    Returns
    -------
    torch.device or None

    Raises
    ------
    InputError
        Not a string or device, not a torch device name (``"CPU"``, ``""``), or a
        device this machine does not have (CUDA without a GPU, ``cuda:3`` with one GPU,
        ``xla``).

    Examples
    --------
    >>> check_device("cpu")
    device(type='cpu')
    >>> check_device("gpu")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: device must be 'auto', 'cpu', 'cuda', ... got 'gpu'
    >>> check_device("auto").type in ("cpu", "cuda")  # CUDA when torch sees a GPU
    True
    """
    import torch

    if device is None:
        return None
    if isinstance(device, str) and device == "auto":  # (an array's == is elementwise)
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    choices = "'auto', 'cpu', 'cuda', 'cuda:N' or 'mps'"
    if isinstance(device, torch.device):
        dev = device
    elif isinstance(device, str):
        try:
            dev = torch.device(device)
        except (RuntimeError, ValueError):
            raise InputError(f"{name} must be {choices}; got {device!r}") from None
    else:
        raise InputError(f"{name} must be {choices}; got {plain_repr(device)[:60]}")
    if dev.type == "cpu":
        return dev
    if dev.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            raise InputError(
                f"{name} {str(dev)!r} asked for, but torch sees no CUDA device: use 'cpu'"
            )
        if dev.index is not None and dev.index >= count:
            raise InputError(
                f"{name} {str(dev)!r}: torch sees {count} CUDA device(s), "
                f"cuda:0 .. cuda:{count - 1}"
            )
        return dev
    if dev.type == "mps" and torch.backends.mps.is_available():
        return dev
    raise InputError(f"{name} {str(dev)!r} is not available here: use 'cpu' (or 'cuda')")


def check_float_dtype(dtype: Any, name: str = "dtype") -> torch.dtype:
    """Return ``dtype`` after checking that it is a floating-point :class:`torch.dtype`.

    Parameters
    ----------
    dtype : torch.dtype
    name : str

    Returns
    -------
    torch.dtype

    Raises
    ------
    InputError
        Not a torch dtype (a NumPy dtype or a string), or not floating point.
    """
    import torch

    if not isinstance(dtype, torch.dtype) or not dtype.is_floating_point:
        raise InputError(
            f"{name} must be a floating-point torch.dtype (torch.float32, torch.float64); "
            f"got {plain_repr(dtype)[:60]}"
        )
    return dtype


def check_tensor_dtype(x: Any, module: nn.Module, name: str = "x") -> torch.Tensor:
    """Return ``x`` after checking that it is a floating-point tensor of the dtype of
    ``module``'s weights (torch's own layers raise RuntimeError on a mismatch).

    Parameters
    ----------
    x : torch.Tensor
        A network's input.
    module : torch.nn.Module
        The network; a module without parameters takes any floating dtype.
    name : str
        The argument named in the message.

    Returns
    -------
    torch.Tensor
        ``x`` itself.

    Raises
    ------
    InputError
        Not a tensor, not floating point (int64, bool, complex: ``x.float()``), another
        floating dtype than the weights (``x.to(dtype)`` or ``module.to(dtype)``), or on
        another device than the weights.

    Examples
    --------
    >>> import torch
    >>> check_tensor_dtype(torch.zeros(2, 3), torch.nn.Linear(3, 1)).dtype
    torch.float32
    >>> check_tensor_dtype(torch.zeros(2, 3).double(), torch.nn.Linear(3, 1))
    ... # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    robopercept.errors.InputError: x is torch.float64 but the network's weights are ...
    """
    import torch

    if not isinstance(x, torch.Tensor):
        raise InputError(
            f"{name} must be a torch.Tensor; got {type(x).__name__}: use "
            "torch.from_numpy(array).float()"
        )
    if not x.is_floating_point():
        raise InputError(f"{name} must be floating point; got {x.dtype}: use {name}.float()")
    weight = next(module.parameters(), None)
    if weight is not None and x.dtype != weight.dtype:
        raise InputError(
            f"{name} is {x.dtype} but the network's weights are {weight.dtype}: convert the "
            f"input ({name}.to({weight.dtype})) or the network (net.to({x.dtype}))"
        )
    if weight is not None and x.device != weight.device:
        raise InputError(
            f"{name} is on {x.device} but the network on {weight.device}: use "
            f"{name}.to('{weight.device}')"
        )
    return x


def check_dataset(data: Any, name: str) -> Any:
    """Return ``data`` after checking that it is a non-empty map-style data set whose
    items are ``(image, label)`` pairs.

    Parameters
    ----------
    data : Dataset
        ``len(data)`` and ``data[i] == (image (C, H, W), label)``, as
        :class:`~robopercept.nn.data.datasets.ArrayDataset`.
    name : str
        The parameter named in the message.

    Returns
    -------
    Dataset

    Raises
    ------
    InputError
        Not a data set (a string, a number, an array), empty, or items that are not
        ``(image, label)`` pairs.
    """
    import numpy as np
    import torch

    looks = hasattr(data, "__len__") and hasattr(data, "__getitem__")
    if not looks or isinstance(data, (str, bytes, dict, np.ndarray, torch.Tensor)):
        raise InputError(
            f"{name} must be a data set of (image, label) pairs (robopercept.nn.data.datasets."
            f"ArrayDataset, or any torch map-style Dataset); got {type(data).__name__}"
            f" {plain_repr(data)[:60]}"
        )
    if len(data) == 0:
        raise InputError(f"{name} is empty: give a data set with at least one image")
    first = data[0]
    if not isinstance(first, (tuple, list)) or len(first) != 2:
        raise InputError(
            f"{name} must give (image, label) pairs; its first item is "
            f"{type(first).__name__} {plain_repr(first)[:60]}"
        )
    return data
