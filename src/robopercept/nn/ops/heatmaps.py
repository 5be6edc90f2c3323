r"""The heatmap codec of keypoint networks, in torch: target heatmaps from keypoints,
keypoints back from heatmaps, the heatmap losses and the flip test's pieces (shared by
the pose wing's networks and detection's Keypoint R-CNN).

Coordinates
-----------
Keypoints are ``(x, y)`` pixels with the pixel-centre convention of
:mod:`robopercept.nn.ops.boxes`: pixel ``(c, r)`` covers ``[c, c + 1) x [r, r + 1)``. A
heatmap of stride :math:`s` has cell ``(i, j)`` centred on image point
:math:`((j + \tfrac12) s, (i + \tfrac12) s)`, so an image point ``x`` sits at the
continuous heatmap coordinate :math:`u = x / s - \tfrac12`. This makes a horizontal
flip of an image of width :math:`W = w s` the flip of its heatmap: :math:`x \mapsto W -
x` is :math:`u \mapsto (w - 1) - u`.

Targets and decoding
--------------------
:func:`gaussian_heatmaps` writes, for joint :math:`k` at :math:`(u_k, v_k)`, the
unnormalized Gaussian :math:`H_k(i, j) = \exp(-((j - u_k)^2 + (i - v_k)^2) / 2\sigma^2)`
centred at the exact sub-cell position (as mmpose's ``UDPHeatmap`` /
DARK, not rounded to a cell as the original ``MSRAHeatmap``), with weight 0 for joints
that are unlabelled (``v = 0``) or outside the image. :func:`decode_heatmaps` reads a
heatmap back three ways:

* ``"quarter"``: the argmax cell moved a quarter cell towards the higher neighbour,
  :math:`u = j + \tfrac14 \operatorname{sign}(H(i, j+1) - H(i, j-1))` (Newell et al.
  2016; SimpleBaseline), error up to a quarter cell;
* ``"quadratic"`` (default): the vertex of the parabola through the logarithms of the
  argmax and its two neighbours on each axis, :math:`u = j + \tfrac12 (L_{j-1} -
  L_{j+1}) / (L_{j-1} - 2 L_j + L_{j+1})`, exact for a Gaussian (its logarithm is a
  parabola): the one-dimensional form of DARK's Taylor step (Zhang et al. 2020);
* ``"soft-argmax"``: the expectation of the position under
  :math:`\operatorname{softmax}(\beta H)` (integral regression, Sun et al. 2018).

Flip test
---------
The flip test averages the heatmaps of the image and of its mirror image, the latter
flipped back and its left/right channels swapped (:func:`flip_heatmaps` with
:meth:`~robopercept.nn.skeleton.Skeleton.flip_permutation`, checked by
:func:`check_permutation`); a ``"softmax"`` network's maps are first turned into
distributions over the cells (:func:`heatmap_probabilities`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import torch

from robopercept._checks import check_choice, check_int, check_real, check_size, plain_repr
from robopercept.errors import InputError
from robopercept.fileio import nesting_depth
from robopercept.nn._guards import check_allocation

__all__ = [
    "DECODERS",
    "HEATMAP_LOSSES",
    "check_float_tensor",
    "check_image_size",
    "check_permutation",
    "decode_heatmaps",
    "flip_heatmaps",
    "gaussian_heatmaps",
    "heatmap_loss",
    "heatmap_probabilities",
    "keypoint_tensor",
]

#: the heatmap decoders of :func:`decode_heatmaps`
DECODERS = ("quadratic", "quarter", "soft-argmax")
#: the heatmap losses of :func:`heatmap_loss` (and the ``heatmap`` kinds of the networks)
HEATMAP_LOSSES = ("softmax", "mse")


# ----------------------------------------------------------------------------- checks
def keypoint_tensor(keypoints: Any, name: str = "keypoints") -> torch.Tensor:
    """Keypoints as a float32 ``(N, J, 3)`` tensor of ``(x, y, v)`` rows.

    Parameters
    ----------
    keypoints : (N, J, 3) or (N, J, 2) array_like
        ``(x, y, v)`` pixels, or ``(x, y)`` (then every joint gets ``v = 2``).
    name : str
        The argument's name in the error.

    Returns
    -------
    (N, J, 3) float32 tensor

    Raises
    ------
    InputError
        Any other shape, or values that are not numbers.

    Examples
    --------
    >>> keypoint_tensor([[[1.0, 2.0]]]).tolist()
    [[[1.0, 2.0, 2.0]]]
    """
    try:
        with np.errstate(over="ignore"):  # beyond float32: inf, a joint outside the image
            a = np.asarray(keypoints.detach().cpu() if torch.is_tensor(keypoints) else keypoints)
            if a.dtype.kind not in "biuf":
                raise TypeError(a.dtype)
            a = a.astype(np.float32)
    except (TypeError, ValueError, OverflowError, RuntimeError, RecursionError):
        raise InputError(
            f"{name} must be numbers, (N, J, 3) rows (x, y, v) or (N, J, 2); got "
            f"{_describe(keypoints)}"
        ) from None
    k = torch.as_tensor(a)
    if k.ndim != 3 or k.shape[-1] not in (2, 3) or k.shape[1] < 1:
        raise InputError(
            f"{name} must be (N, J, 3) rows (x, y, v) or (N, J, 2); got shape {tuple(k.shape)}"
        )
    if k.shape[-1] == 2:
        k = torch.cat([k, torch.full_like(k[..., :1], 2.0)], -1)
    return k


def check_image_size(image_size: Any, stride: int) -> tuple[int, int]:
    """An image size ``(width, height)`` that a network of ``stride`` divides.

    Parameters
    ----------
    image_size : (int, int)
        ``(width, height)`` pixels, 1 to 32768 each.
    stride : int
        Image pixels per heatmap cell, 1 to 32768.

    Returns
    -------
    (int, int)

    Raises
    ------
    InputError
        A size or stride out of range or not whole, or a side that is not a multiple of
        ``stride``.

    Examples
    --------
    >>> check_image_size((64, 32), 16)
    (64, 32)
    """
    stride = _check_stride(stride)
    w, h = check_size(image_size, "image_size", 1, 1 << 15)
    if w % stride or h % stride:
        raise InputError(
            f"image_size {(w, h)} must be a multiple of the stride {stride} in both sides"
        )
    return w, h


def check_float_tensor(value: Any, name: str, ndim: int, what: str) -> torch.Tensor:
    """``value`` if it is a floating-point tensor of ``ndim`` dimensions, else InputError.

    Parameters
    ----------
    value : Any
    name : str
        The argument's name in the error.
    ndim : int
    what : str
        The meaning of the dimensions, for the error (``"(N, C, H, W)"``).

    Returns
    -------
    torch.Tensor

    Examples
    --------
    >>> check_float_tensor(torch.zeros(2, 3), "x", 2, "(N, J)").shape
    torch.Size([2, 3])
    """
    if not torch.is_tensor(value) or not value.is_floating_point() or value.ndim != ndim:
        raise InputError(f"{name} must be a float torch.Tensor {what}; got {_describe(value)}")
    return value


def check_permutation(value: Any, j: int) -> np.ndarray:
    """A permutation of ``0..j-1`` (a skeleton's flip permutation), or InputError.

    Parameters
    ----------
    value : (J,) array_like of int
    j : int
        The number of joints.

    Returns
    -------
    (J,) int64 ndarray

    Examples
    --------
    >>> check_permutation([1, 0, 2], 3).tolist()
    [1, 0, 2]
    """
    j = check_int(j, "the number of joints", 0)
    try:
        perm = np.asarray(value, dtype=np.int64).reshape(-1)
    except (TypeError, ValueError, OverflowError, RecursionError):
        perm = np.zeros(0, np.int64)
    if perm.shape != (j,) or sorted(perm.tolist()) != list(range(j)):
        raise InputError(
            f"flip_permutation must be a permutation of the {j} joints (e.g. "
            f"skeleton.flip_permutation()); got {_describe(value)}"
        )
    return perm


def _check_stride(stride: Any) -> int:
    """``stride`` as an int in [1, 32768] (image pixels per heatmap cell), or InputError."""
    s = check_int(stride, "stride (image pixels per heatmap cell)", 1)
    if s > 1 << 15:
        raise InputError(f"stride must be at most 32768 pixels per heatmap cell; got {s}")
    return s


# ----------------------------------------------------------------------------- targets
def gaussian_heatmaps(
    keypoints: npt.ArrayLike,
    image_size: tuple[int, int],
    stride: int = 4,
    sigma: float = 2.0,
) -> tuple[torch.Tensor, torch.Tensor]:
    r"""Target heatmaps: an exact sub-cell Gaussian per labelled joint.

    :math:`H_k(i, j) = \exp(-((j - u_k)^2 + (i - v_k)^2) / 2\sigma^2)` with
    :math:`u_k = x_k / s - \tfrac12`, :math:`v_k = y_k / s - \tfrac12` (the module's
    convention), on a ``(H / s, W / s)`` grid.

    Parameters
    ----------
    keypoints : (N, J, 3) array_like
        ``(x, y, v)`` pixels; ``v = 0`` (or NaN coordinates) marks a joint without a label.
    image_size : (int, int)
        ``(width, height)``, multiples of ``stride``.
    stride : int
    sigma : float
        In heatmap cells.

    Returns
    -------
    heatmaps : (N, J, H / s, W / s) float32 tensor
    weights : (N, J) float32 tensor
        1 for a labelled joint inside the image, else 0 (its heatmap is all 0).

    Raises
    ------
    InputError
        Keypoints not ``(N, J, 3)`` or ``(N, J, 2)`` numbers; a stride that is not a whole
        number in [1, 32768] or does not divide ``image_size``; ``sigma`` not in
        (0, 1000]; heatmaps over 1 GiB.

    Examples
    --------
    >>> hm, w = gaussian_heatmaps([[[6.0, 2.0, 2]]], (8, 8), stride=4)
    >>> hm.shape, float(hm[0, 0, 0, 1]), w.tolist()
    (torch.Size([1, 1, 2, 2]), 1.0, [[1.0]])
    """
    stride = _check_stride(stride)
    k = keypoint_tensor(keypoints)
    w, h = check_image_size(image_size, stride)
    sigma = check_real(sigma, "sigma", 0.0, 1e3, low_inclusive=False)
    hw, hh = w // stride, h // stride
    check_allocation(
        k.shape[0] * k.shape[1] * hh * hw * 3,  # the map and the temporaries of its product
        4,
        f"({k.shape[0]}, {k.shape[1]}, {hh}, {hw}) heatmaps",
        "use fewer keypoint sets, a smaller image_size or a larger stride",
    )
    x, y, v = k[..., 0], k[..., 1], k[..., 2]
    ok = (v > 0) & torch.isfinite(x) & torch.isfinite(y) & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    u = torch.where(ok, x / stride - 0.5, torch.zeros_like(x))
    vv = torch.where(ok, y / stride - 0.5, torch.zeros_like(y))
    jj = torch.arange(hw, dtype=torch.float32)
    ii = torch.arange(hh, dtype=torch.float32)
    gx = torch.exp(-((jj[None, None, :] - u[..., None]) ** 2) / (2 * sigma**2))
    gy = torch.exp(-((ii[None, None, :] - vv[..., None]) ** 2) / (2 * sigma**2))
    hm = gy[..., :, None] * gx[..., None, :] * ok[..., None, None]
    return hm.float(), ok.float()


def decode_heatmaps(
    heatmaps: torch.Tensor | npt.ArrayLike,
    stride: int = 4,
    method: str = "quadratic",
    beta: float = 50.0,
) -> tuple[np.ndarray, np.ndarray]:
    r"""Keypoints from heatmaps (see the module docstring for the three methods).

    Parameters
    ----------
    heatmaps : (N, J, h, w) tensor or array
    stride : int
        Image pixels per heatmap cell.
    method : {"quadratic", "quarter", "soft-argmax"}
    beta : float
        The soft-argmax temperature (``softmax(beta H)``).

    Returns
    -------
    keypoints : (N, J, 2) float64 ndarray
        ``(x, y)`` pixels, :math:`x = s (u + \tfrac12)`; ``(0, J, 2)`` for an empty batch.
    scores : (N, J) float64 ndarray
        The heatmap maximum.

    Raises
    ------
    InputError
        Heatmaps that are not a real ``(N, J, h, w)`` array with ``h, w >= 1``, or not
        finite; a stride that is not a whole number in [1, 32768]; an unknown method; a
        ``beta`` not in (0, 1e6].

    Examples
    --------
    >>> hm, _ = gaussian_heatmaps([[[13.3, 6.9, 2]]], (32, 16), stride=4)
    >>> kp, score = decode_heatmaps(hm, stride=4)
    >>> np.round(kp, 6).tolist()
    [[[13.3, 6.9]]]
    """
    hm = _real_tensor(heatmaps, "heatmaps")
    if hm.ndim != 4 or hm.shape[-1] < 1 or hm.shape[-2] < 1:
        raise InputError(f"heatmaps must be (N, J, h, w); got shape {tuple(hm.shape)}")
    hm = hm.detach().to(torch.float64).cpu()
    if not torch.isfinite(hm).all():
        raise InputError("heatmaps must be finite; got NaN or inf (a diverged network?)")
    stride = _check_stride(stride)
    check_choice(method, "method", DECODERS)
    if method == "soft-argmax":
        beta = check_real(beta, "beta", 0.0, 1e6, low_inclusive=False)
    n, j, h, w = hm.shape
    if n * j == 0:  # an empty batch, or no joint (issue 47 R53)
        return np.zeros((n, j, 2)), np.zeros((n, j))
    flat = hm.reshape(n, j, h * w)
    score, idx = flat.max(-1)
    row = (idx // w).to(torch.float64)
    col = (idx % w).to(torch.float64)
    if method == "soft-argmax":
        p = torch.softmax(beta * flat, -1).reshape(n, j, h, w)
        col = (p.sum(-2) * torch.arange(w, dtype=torch.float64)).sum(-1)
        row = (p.sum(-1) * torch.arange(h, dtype=torch.float64)).sum(-1)
    else:
        r, c = row.long(), col.long()
        ni, ji = torch.meshgrid(torch.arange(n), torch.arange(j), indexing="ij")

        def at(rr: torch.Tensor, cc: torch.Tensor) -> torch.Tensor:
            return hm[ni, ji, rr.clamp(0, h - 1), cc.clamp(0, w - 1)]

        centre = at(r, c)
        offsets = []
        for dr, dc, size, pos in ((0, 1, w, c), (1, 0, h, r)):
            lo = at(r - dr, c - dc)
            hi = at(r + dr, c + dc)
            inner = (pos > 0) & (pos < size - 1)
            if method == "quarter":
                off = 0.25 * torch.sign(hi - lo)
            else:
                tiny = 1e-10
                l0, l1, l2 = (torch.log(t.clamp_min(tiny)) for t in (lo, centre, hi))
                den = l0 - 2 * l1 + l2
                off = torch.where(den < -1e-12, 0.5 * (l0 - l2) / den.clamp(max=-1e-12), 0 * den)
                off = off.clamp(-0.5, 0.5)
            offsets.append(torch.where(inner, off, torch.zeros_like(off)))
        col = col + offsets[0]
        row = row + offsets[1]
    kp = torch.stack([(col + 0.5) * stride, (row + 0.5) * stride], -1)
    return kp.numpy(), score.numpy()


def _describe(value: Any) -> str:
    """A short description of an unusable array-like for a message: its repr when short
    and flat enough to take, else its type (a deeply nested list has no repr)."""
    if isinstance(value, (list, tuple)) and nesting_depth(value, 8) >= 8:
        return f"a {type(value).__name__} nested more than 8 deep"
    text = plain_repr(value)
    return text if len(text) <= 80 else f"{text[:77]}..."


def _real_tensor(value: Any, name: str) -> torch.Tensor:
    """``value`` (a tensor or array_like of real numbers) as a tensor, or InputError."""
    if torch.is_tensor(value):
        t = value
    else:
        try:
            a = np.asarray(value)
        except (TypeError, ValueError, OverflowError, RecursionError):
            a = np.zeros(0, dtype=object)
        if a.dtype.kind not in "biuf":
            raise InputError(
                f"{name} must be a tensor or array of real numbers; got {_describe(value)}"
            )
        t = torch.as_tensor(a)
    if t.is_complex():
        raise InputError(f"{name} must be real; got {t.dtype}")
    return t


# ----------------------------------------------------------------------------- loss
def heatmap_loss(
    output: torch.Tensor, target: torch.Tensor, weight: torch.Tensor, kind: str = "softmax"
) -> torch.Tensor:
    r"""The loss of a heatmap network against :func:`gaussian_heatmaps` targets.

    * ``"mse"`` (SimpleBaseline, HRNet's papers): the network regresses the Gaussian map,
      :math:`\frac{1}{N J} \sum_{n,k} w_{nk} \frac{1}{h w} \lVert \hat H_{nk} - H_{nk}
      \rVert^2`.
    * ``"softmax"``: the map is the logits of a distribution over the cells, and the
      loss is the cross entropy to the target normalized into one,
      :math:`-\frac{1}{\sum w} \sum_{n,k} w_{nk} \sum_{ij} q_{nkij} \log
      \operatorname{softmax}(\hat H_{nk})_{ij}`, :math:`q = H / \sum H` (the
      one-hot cross entropy of Mask R-CNN's keypoint head, with Gaussian soft targets).
      On these small sets it trains in a fraction of the epochs MSE needs, as the
      background cells no longer dominate the loss.

    Parameters
    ----------
    output, target : (N, J, h, w) tensor
    weight : (N, J) tensor
        1 for joints that count, 0 for the others.
    kind : {"softmax", "mse"}

    Examples
    --------
    >>> t, w = gaussian_heatmaps([[[6.0, 6.0, 2]]], (16, 16), 4, 1.0)
    >>> float(heatmap_loss(t, t, w, "mse"))
    0.0
    """
    check_choice(kind, "kind", HEATMAP_LOSSES)
    check_float_tensor(output, "output", 4, "(N, J, h, w)")
    check_float_tensor(target, "target", 4, "(N, J, h, w)")
    check_float_tensor(weight, "weight", 2, "(N, J)")
    if (
        output.shape != target.shape
        or weight.shape != output.shape[:2]
        or min(output.shape[2:]) < 1
    ):
        raise InputError(
            f"output {tuple(output.shape)}, target {tuple(target.shape)} and weight "
            f"{tuple(weight.shape)} must be (N, J, h, w), (N, J, h, w) and (N, J), h, w >= 1"
        )
    if kind == "mse":
        if weight.numel() == 0:  # no joint to weigh: 0, not the NaN mean of nothing
            return (output * 0.0).sum()
        return (((output - target) ** 2).mean((-1, -2)) * weight).mean()
    q = target.flatten(2)
    q = q / q.sum(-1, keepdim=True).clamp_min(1e-12)
    ce = -(q * torch.log_softmax(output.flatten(2), -1)).sum(-1)
    return (ce * weight).sum() / weight.sum().clamp_min(1.0)


# ----------------------------------------------------------------------------- flip test
def heatmap_probabilities(maps: torch.Tensor, kind: str) -> torch.Tensor:
    """A ``"softmax"`` network's logits as the distribution over the cells (per joint);
    an ``"mse"`` network's maps (any other ``kind``) as they are.

    Parameters
    ----------
    maps : (N, J, h, w) tensor
    kind : str
        The network's ``heatmap`` attribute (:data:`HEATMAP_LOSSES`).

    Returns
    -------
    (N, J, h, w) tensor

    Examples
    --------
    >>> float(heatmap_probabilities(torch.zeros(1, 1, 2, 2), "softmax").sum())
    1.0
    """
    check_float_tensor(maps, "maps", 4, "(N, J, h, w)")
    if not isinstance(kind, str):
        raise InputError(f"kind must be a heatmap kind {HEATMAP_LOSSES}; got {_describe(kind)}")
    if kind != "softmax":
        return maps
    n, j, h, w = maps.shape
    if min(h, w) < 1:
        raise InputError(f"maps must have h, w >= 1; got shape {tuple(maps.shape)}")
    return torch.softmax(maps.reshape(n, j, h * w), -1).reshape(n, j, h, w)


def flip_heatmaps(maps: torch.Tensor, permutation: torch.Tensor) -> torch.Tensor:
    """The heatmaps of a mirrored image brought back: flipped left-right and their
    channels permuted (left and right joints swapped).

    Parameters
    ----------
    maps : (N, J, h, w) tensor
    permutation : (J,) int tensor
        :meth:`~robopercept.nn.skeleton.Skeleton.flip_permutation`.

    Returns
    -------
    (N, J, h, w) tensor

    Examples
    --------
    >>> m = torch.arange(4.0).reshape(1, 2, 1, 2)
    >>> flip_heatmaps(m, torch.tensor([1, 0])).tolist()
    [[[[3.0, 2.0]], [[1.0, 0.0]]]]
    """
    check_float_tensor(maps, "maps", 4, "(N, J, h, w)")
    if torch.is_tensor(permutation):
        permutation = permutation.detach().cpu()
    perm = torch.from_numpy(check_permutation(permutation, maps.shape[1])).to(maps.device)
    return maps.flip(-1)[:, perm]
