r"""Running a pose network on images: batches of images to keypoints (with the flip
test and the DeepPose cascade), whole images of any size to poses
(:func:`pose_arrays`, letterboxed into the network's input) and a picture of the
results.

Heatmap networks are decoded by :func:`~robopercept.nn.ops.heatmaps.decode_heatmaps`.
The flip test averages the heatmaps of the image and of its mirror image, the latter
flipped back and its left/right channels swapped
(:func:`~robopercept.nn.ops.heatmaps.flip_heatmaps` with
:meth:`~robopercept.nn.skeleton.Skeleton.flip_permutation`); a DeepPose network's two
estimates are averaged instead. Cascade stages (:class:`~.networks.DeepPoseRefiner`)
each move every joint by the displacement they predict from a window around it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import torch
import torch.nn.functional as F
from torch import nn

from robopercept._checks import check_choice, check_int, check_numeric, plain_repr
from robopercept.errors import InputError
from robopercept.nn._guards import check_module
from robopercept.nn.data.datasets import to_unit_float
from robopercept.nn.ops.heatmaps import (
    DECODERS,
    check_image_size,
    check_permutation,
    decode_heatmaps,
    flip_heatmaps,
    heatmap_probabilities,
    keypoint_tensor,
)
from robopercept.nn.pose.networks import DeepPoseRefiner, crop_patches
from robopercept.nn.skeleton import Skeleton
from robopercept.viz.pose import draw_skeleton
from robopercept.viz.segmentation import panels_picture

__all__ = [
    "PoseResult",
    "check_input_size",
    "image_batch",
    "pose_arrays",
    "pose_data_arrays",
    "predict_heatmaps",
    "predict_keypoints",
    "refine_keypoints",
    "samples_picture",
]


# ----------------------------------------------------------------------------- inputs
def image_batch(images: Any, what: str = "images") -> torch.Tensor:
    """A batch of images as a float32 ``(N, C, H, W)`` tensor.

    Parameters
    ----------
    images : (N, H, W, 3) array in [0, 1] or (N, C, H, W) tensor
    what : str
        The argument's name in the error.

    Returns
    -------
    (N, C, H, W) float32 tensor

    Raises
    ------
    InputError
        Arrays that are not ``(N, H, W, 1 or 3)``, tensors that are not 4-D.

    Examples
    --------
    >>> image_batch(np.zeros((2, 8, 8, 3))).shape
    torch.Size([2, 3, 8, 8])
    """
    if torch.is_tensor(images):
        x = images.to(torch.float32)
    else:
        a = check_numeric(images, what)
        if a.ndim != 4 or a.shape[-1] not in (1, 3):
            raise InputError(
                f"{what} must be (N, H, W, 3) float in [0, 1]; got {plain_repr(images)}"
            )
        x = torch.from_numpy(np.ascontiguousarray(a.transpose(0, 3, 1, 2), dtype=np.float32))
    if x.ndim != 4:
        raise InputError(f"{what} must be a batch (N, C, H, W); got shape {tuple(x.shape)}")
    return x


def check_input_size(model: nn.Module, x: torch.Tensor) -> None:
    """Refuse images a pose network cannot take: not the size a DeepPose network was
    built for, or sides that are not a multiple of 16 (every network here downsamples by
    16 at its deepest).

    Parameters
    ----------
    model : nn.Module
    x : (N, C, H, W) tensor

    Raises
    ------
    InputError
        With the size the network needs.
    """
    h, w = x.shape[-2:]
    size = getattr(model, "image_size", None)
    if size is not None and (w, h) != tuple(size):
        raise InputError(
            f"the network was built for {size[0]} x {size[1]} images; got {w} x {h}: resize "
            "or crop the person to that size"
        )
    need = 16  # every network here downsamples by 16 at its deepest
    if w % need or h % need or w < need or h < need:
        raise InputError(
            f"images must be at least {need} px and a multiple of {need} in each side; got "
            f"{w} x {h}"
        )


def pose_data_arrays(data: Any, what: str) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """The images, keypoints and boxes of a
    :class:`~robopercept.nn.pose.data.PoseDataset`, checked.

    Parameters
    ----------
    data : PoseDataset
    what : str
        The argument's name in the error.

    Returns
    -------
    images : (N, C, H, W) float32 tensor
    keypoints : (N, J, 3) float32 tensor
    boxes : (N, 4) ndarray
        ``xyxy``.
    """
    images = getattr(data, "images", None)
    keypoints = getattr(data, "keypoints", None)
    boxes = getattr(data, "boxes", None)
    if images is None or keypoints is None or boxes is None:
        raise InputError(
            f"{what} must be a PoseDataset (procedural_pose_set, ...); got {plain_repr(data)}"
        )
    return image_batch(images, what), keypoint_tensor(keypoints), np.asarray(boxes)


# ----------------------------------------------------------------------------- inference
@torch.inference_mode()
def predict_keypoints(
    model: nn.Module,
    images: Any,
    *,
    flip_permutation: npt.ArrayLike | None = None,
    method: str = "quadratic",
    batch_size: int = 64,
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints of images through a pose network (eval mode).

    Heatmap networks are decoded by
    :func:`~robopercept.nn.ops.heatmaps.decode_heatmaps` (``method``), with the flip test
    when ``flip_permutation`` is given; a :class:`~robopercept.nn.pose.networks.DeepPose`
    network's normalized output is scaled back to pixels (score 1; with the flip test the
    two estimates are averaged).

    Parameters
    ----------
    model : nn.Module
    images : (N, H, W, 3) array or (N, 3, H, W) tensor
    flip_permutation : (J,) array_like, optional
    method : str
    batch_size : int

    Returns
    -------
    keypoints : (N, J, 2) ndarray
    scores : (N, J) ndarray
    """
    kp, sc, _ = predict_heatmaps(
        model, images, flip_permutation=flip_permutation, method=method, batch_size=batch_size
    )
    return kp, sc


@torch.inference_mode()
def predict_heatmaps(
    model: nn.Module,
    images: Any,
    *,
    flip_permutation: npt.ArrayLike | None = None,
    method: str = "quadratic",
    batch_size: int = 64,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """:func:`predict_keypoints` and the (flip-averaged) heatmaps ``(N, J, h, w)``
    float32 they were decoded from (None for DeepPose)."""
    model = check_module(model)
    x = image_batch(images)
    check_input_size(model, x)
    check_choice(method, "method", DECODERS)
    batch_size = check_int(batch_size, "batch_size", 1)
    model.eval()
    dev = next(model.parameters()).device
    kps, scores, hms = [], [], []
    j = int(getattr(model, "num_joints", 0))
    perm = None
    if flip_permutation is not None:
        size = j or int(np.asarray(flip_permutation).size)
        perm = torch.as_tensor(check_permutation(flip_permutation, size))
    regression = getattr(model, "output", "heatmaps") == "coordinates"
    # an empty batch still runs once (on 0 images), so that the empty results have the
    # network's shapes: (0, J, 2), (0, J) and (0, J, h, w)
    for i in range(0, max(len(x), 1), batch_size):
        xb = x[i : i + batch_size].to(dev)
        out = model(xb)
        if regression:
            h, w = xb.shape[-2:]
            scale = torch.tensor([w, h], dtype=out.dtype, device=out.device)
            kp = ((out + 0.5) * scale).cpu().double().numpy()
            if perm is not None:
                out_f = model(xb.flip(-1))[:, perm]
                kp_f = ((out_f + 0.5) * scale).cpu().double().numpy()
                kp_f[..., 0] = w - kp_f[..., 0]
                kp = 0.5 * (kp + kp_f)
            kps.append(kp)
            scores.append(np.ones(kp.shape[:2]))
            continue
        kind = getattr(model, "heatmap", "mse")
        if perm is not None:
            out_f = flip_heatmaps(model(xb.flip(-1)), perm)
            out = 0.5 * (heatmap_probabilities(out, kind) + heatmap_probabilities(out_f, kind))
        else:
            out = heatmap_probabilities(out, kind)
        kp, sc = decode_heatmaps(out, int(getattr(model, "stride", 4)), method)
        kps.append(kp)
        scores.append(sc)
        hms.append(out.cpu().float().numpy())
    return (
        np.concatenate(kps),
        np.concatenate(scores),
        None if regression else np.concatenate(hms),
    )


@torch.inference_mode()
def refine_keypoints(
    images: Any, keypoints: npt.ArrayLike, refiners: Sequence[DeepPoseRefiner]
) -> np.ndarray:
    """Run DeepPose cascade stages: each moves every joint by its predicted
    displacement, from windows around the previous stage's estimates.

    Parameters
    ----------
    images : (N, H, W, 3) array or (N, 3, H, W) tensor
    keypoints : (N, J, 2) array_like
        The first stage's estimates (pixels).
    refiners : sequence of DeepPoseRefiner

    Returns
    -------
    (N, J, 2) ndarray
    """
    x = image_batch(images)
    kp = torch.as_tensor(check_numeric(keypoints, "keypoints").astype(np.float32))
    if kp.ndim != 3 or kp.shape[0] != len(x) or kp.shape[-1] != 2:
        raise InputError(f"keypoints must be (N, J, 2) for the N images; got {tuple(kp.shape)}")
    if not bool(torch.isfinite(kp).all()):
        raise InputError("keypoints hold NaN or inf: give every joint a finite estimate")
    if not isinstance(refiners, (list, tuple)):
        raise InputError(
            "refiners must be a list of DeepPoseRefiner stages (one stage: [stage]); got "
            f"{plain_repr(refiners)[:60]}"
        )
    for stage in refiners:
        if not isinstance(stage, DeepPoseRefiner):
            raise InputError(f"refiners must be DeepPoseRefiner stages; got {plain_repr(stage)}")
        stage.eval()
        if stage.num_joints != kp.shape[1]:
            raise InputError(
                f"a refiner for {stage.num_joints} joints cannot refine {kp.shape[1]} joints"
            )
        out = []
        for i in range(0, len(x), 32):
            xb, kb = x[i : i + 32], kp[i : i + 32]
            n, j = kb.shape[:2]
            patches = crop_patches(xb, kb, stage.crop, stage.patch)
            joints = torch.arange(j).repeat(n)
            delta = stage(patches, joints).reshape(n, j, 2)
            out.append(kb + stage.crop * delta)
        kp = torch.cat(out)
    return kp.double().numpy()


# ----------------------------------------------------------------------------- any image
@dataclass(frozen=True)
class PoseResult:
    """Keypoints found on one image.

    Attributes
    ----------
    keypoints : (J, 2) float64 ndarray
        ``(x, y)`` pixels of the input image.
    scores : (J,) float64 ndarray
        Per-joint confidence (the heatmap peak; 1 for DeepPose).
    heatmaps : (J, h, w) float32 ndarray or None
        The network's heatmaps over the image's part of the letterboxed input (cells of
        ``stride`` input pixels; None for DeepPose).
    box : (4,) float64 ndarray
        The image region given to the network (``xyxy``).
    """

    keypoints: np.ndarray
    scores: np.ndarray
    heatmaps: np.ndarray | None
    box: np.ndarray


def pose_arrays(
    model: nn.Module,
    images: Sequence[Any],
    *,
    input_size: tuple[int, int] = (128, 128),
    flip_permutation: npt.ArrayLike | None = None,
    refiners: Sequence[DeepPoseRefiner] = (),
) -> list[PoseResult]:
    """Single-person (top-down) pose of whole NumPy images through a pose network.

    Each image, ``(H, W)`` or ``(H, W, 3)``, ``uint8``, ``uint16`` or float in [0, 1]
    (:func:`~robopercept.nn.data.datasets.to_unit_float`), is letterboxed into the network's
    ``input_size``: scaled by :math:`s = \\min(W_0 / W, H_0 / H)` (bilinear,
    antialiased), centred, padded with zeros; the keypoints are mapped back by the
    inverse of that map, so they are in the input image's pixels.

    Raises
    ------
    InputError
        Images that are not 2-D/3-channel arrays, or smaller than 8 x 8 pixels.
    """
    w0, h0 = check_image_size(getattr(model, "image_size", input_size), 16)
    stacked = isinstance(images, np.ndarray) and images.ndim >= 3  # (N, H, W[, 3])
    if not stacked and (isinstance(images, (str, bytes)) or not isinstance(images, Sequence)):
        raise InputError(f"images must be a list of (H, W[, 3]) arrays; got {plain_repr(images)}")
    batch, boxes, scales, offsets = [], [], [], []
    for i, im in enumerate(images):
        a = np.asarray(im)
        if a.ndim == 3 and a.shape[-1] == 1:
            a = a[..., 0]
        if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[-1] != 3):
            raise InputError(f"images[{i}] must be (H, W) or (H, W, 3); got {plain_repr(im)}")
        if min(a.shape[:2]) < 8:
            raise InputError(
                f"images[{i}] is {a.shape[1]} x {a.shape[0]} px; a person needs at least 8 x 8"
            )
        f = to_unit_float(a).astype(np.float32)
        if f.ndim == 2:
            f = np.repeat(f[..., None], 3, axis=2)
        h, w = f.shape[:2]
        s = min(w0 / w, h0 / h)
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        t = torch.from_numpy(np.ascontiguousarray(f.transpose(2, 0, 1)))[None]
        t = F.interpolate(t, size=(nh, nw), mode="bilinear", antialias=True, align_corners=False)
        ox, oy = (w0 - nw) // 2, (h0 - nh) // 2
        canvas = torch.zeros((3, h0, w0))
        canvas[:, oy : oy + nh, ox : ox + nw] = t[0].clamp(0, 1)
        batch.append(canvas)
        sx, sy = nw / w, nh / h
        scales.append((sx, sy))
        offsets.append((ox, oy))
        boxes.append(np.array([0.0, 0.0, w, h]))
    if not batch:
        return []
    x = torch.stack(batch)
    kp, sc, hm = predict_heatmaps(model, x, flip_permutation=flip_permutation)
    if refiners:
        kp = refine_keypoints(x, kp, refiners)
    results = []
    for i in range(len(batch)):
        (sx, sy), (ox, oy) = scales[i], offsets[i]
        k = np.stack([(kp[i, :, 0] - ox) / sx, (kp[i, :, 1] - oy) / sy], -1)
        heat = None
        if hm is not None:
            st = int(getattr(model, "stride", 4))
            nw, nh = round(sx * boxes[i][2]), round(sy * boxes[i][3])
            heat = hm[i][:, oy // st : -(-(oy + nh) // st), ox // st : -(-(ox + nw) // st)].copy()
        results.append(PoseResult(k, sc[i], heat, boxes[i]))
    return results


def samples_picture(
    model: nn.Module,
    data: Any,
    *,
    refiners: Sequence[DeepPoseRefiner] = (),
    count: int = 6,
) -> np.ndarray:
    """The first ``count`` images of a pose data set with the network's skeletons
    (flip test, ``refiners`` applied), in a roughly square grid (``ceil(sqrt(count))``
    columns) and enlarged to read at 1080p (six 128 x 128 images: a 1176 x 830 sheet):
    the ``samples.png`` of ``robopercept nn pose train``.

    Returns
    -------
    (H, W, 3) uint8 ndarray
    """
    sk = getattr(data, "skeleton", None)
    if not isinstance(sk, Skeleton):
        raise InputError(f"data must be a PoseDataset; got {plain_repr(data)}")
    n = min(check_int(count, "count", 1), len(data))
    images = list(data.images[:n])
    res = pose_arrays(model, images, flip_permutation=sk.flip_permutation(), refiners=refiners)
    pics = [
        draw_skeleton(im, r.keypoints, sk.links, flip_pairs=sk.flip_pairs, min_side=384)
        for im, r in zip(images, res, strict=True)
    ]
    titles = [f"image {i + 1}" for i in range(n)]
    return panels_picture(pics, titles, columns=math.ceil(math.sqrt(n)))
