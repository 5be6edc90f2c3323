r"""Top-down pose data from a user's COCO keypoint file: each annotated person cut out
of its photo around its box and resampled to the network's input (the top-down recipe of
Xiao et al., *Simple Baselines*, 2018, and mmpose's ``TopdownAffine``).

The window of a person with COCO box :math:`(x, y, w, h)` is centred on the box's centre
:math:`c`, widened on one side to the output's aspect :math:`W / H` and then scaled by
``padding`` (1.25, as mmpose): :math:`w' = \rho \max(w, h W / H)`, and the output pixel
scale is :math:`s = w' / W` image pixels per output pixel. A point :math:`p` of the
photo (continuous pixel coordinates) lands at

.. math:: q = (p - c) / s + (W / 2, H / 2)

in the crop: the keypoints and the box move so; the pixels are sampled bilinearly by
:func:`~robopercept.imaging.warp.warp_perspective` with the same map (in pixel-centre
coordinates, :math:`q - \tfrac12 = (p - \tfrac12 - c + \tfrac12) / s + \ldots`), black
outside the photo. Keypoints keep COCO's visibility ``v``; unlabelled ones (``v = 0``)
are ``(0, 0, 0)``. Persons without a labelled keypoint (``num_keypoints`` 0) and crowd
regions are not training samples (mmpose's COCO loader drops them too).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_bool, check_real, check_size, plain_repr
from robopercept.errors import InputError
from robopercept.imaging import read_image
from robopercept.imaging.io import contained_path
from robopercept.imaging.warp import warp_perspective
from robopercept.nn.coco.dataset import read_coco_json
from robopercept.nn.data.datasets import to_unit_float
from robopercept.nn.pose.data import PoseDataset
from robopercept.nn.skeleton import skeleton_from_coco_category

__all__ = ["crop_window", "pose_set_from_coco"]


def crop_window(box: Any, size: tuple[int, int], padding: float = 1.25) -> tuple[np.ndarray, float]:
    """The window of a person's box in a ``size`` crop: its centre ``c`` (x, y) and
    scale ``s`` (photo pixels per crop pixel), module docstring.

    Parameters
    ----------
    box : (4,) array_like
        COCO ``[x, y, w, h]``, w and h > 0.
    size : (width, height)
        The crop.
    padding : float
        The window's margin factor, >= 1.

    Returns
    -------
    centre : (2,) ndarray
    scale : float

    Examples
    --------
    >>> c, s = crop_window([10, 20, 40, 20], (64, 64), padding=1.0)
    >>> c.tolist(), s
    ([30.0, 30.0], 0.625)
    """
    b = np.asarray(box, dtype=np.float64)
    if b.shape != (4,) or not np.isfinite(b).all() or b[2] <= 0 or b[3] <= 0:
        raise InputError(f"box must be COCO [x, y, w, h] with w, h > 0; got {plain_repr(box)}")
    w_out, h_out = check_size(size, "size (--size)", 1, 4096)
    padding = check_real(padding, "padding", 1.0, 10.0)
    width = padding * max(b[2], b[3] * w_out / h_out)
    return b[:2] + b[2:] / 2, float(width / w_out)


def pose_set_from_coco(
    path: str | os.PathLike[str],
    images_dir: str | os.PathLike[str] | None = None,
    size: tuple[int, int] = (128, 128),
    padding: float = 1.25,
    *,
    allow_outside: bool = False,
) -> PoseDataset:
    """A COCO keypoint file's persons as top-down crops (module docstring): what
    ``robopercept nn pose train|eval --data FILE.json`` reads.

    Parameters
    ----------
    path : path
        COCO JSON with a keypoint category (``keypoints`` names, ``skeleton`` links;
        :func:`~robopercept.nn.skeleton.skeleton_from_coco_category`).
    images_dir : path, optional
        The images' folder (default: the file's folder).
    size : (width, height)
        The crops.
    padding : float
        The window's margin factor.
    allow_outside : bool, default False
        Read images whose ``file_name`` leads outside the images' folder
        (``../../x.png``, an absolute path), refused by default
        (:func:`~robopercept.imaging.io.contained_path`; ``--allow-outside-paths``).

    Returns
    -------
    PoseDataset
        One crop per person with labelled keypoints, in the file's order; the keypoints
        and boxes in crop pixels; no 3-D joints or cameras (NaN).

    Raises
    ------
    InputError
        No such file or folder, an image missing, no keypoint category, or no person
        with a labelled keypoint (the messages name ``--data`` and ``--images-dir``).
    FileFormatError
        Not COCO JSON, an unreadable image, a ``file_name`` outside the images' folder
        (without ``allow_outside``).

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> from robopercept.imaging import write_image
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> _ = write_image(d / "a.png", np.zeros((40, 60, 3), np.uint8))
    >>> _ = (d / "gt.json").write_text(json.dumps({
    ...     "images": [{"id": 1, "file_name": "a.png", "width": 60, "height": 40}],
    ...     "categories": [{"id": 1, "name": "person", "keypoints": ["a", "b"],
    ...                     "skeleton": [[1, 2]]}],
    ...     "annotations": [{"id": 1, "image_id": 1, "category_id": 1,
    ...                      "bbox": [10, 10, 20, 20], "keypoints": [20, 20, 2, 0, 0, 0]}]}))
    >>> ds = pose_set_from_coco(d / "gt.json", size=(32, 32), padding=1.0)
    >>> ds.keypoints[0].tolist()
    [[16.0, 16.0, 2.0], [0.0, 0.0, 0.0]]
    """
    p = as_path(path, "path (--data)")
    if not p.is_file():
        raise InputError(f"--data: COCO file {p} does not exist")
    root = p.parent if images_dir is None else as_path(images_dir, "images_dir (--images-dir)")
    if not root.is_dir():
        raise InputError(f"--images-dir: {root} is not a folder")
    w_out, h_out = check_size(size, "size (--size)", 1, 4096)
    allow_outside = check_bool(allow_outside, "allow_outside (--allow-outside-paths)")
    coco = read_coco_json(p)
    cats = [c for c in coco.categories if c.keypoints]
    if not cats:
        raise InputError(
            f"--data {p}: no category has 'keypoints': a pose network trains on a COCO "
            "person-keypoints file"
        )
    skeleton = skeleton_from_coco_category(cats[0].to_dict(), cats[0].name)
    keep = (~coco.iscrowd) & (coco.num_keypoints > 0) & (coco.category_ids == cats[0].id)
    if not keep.any():
        raise InputError(f"--data {p}: no person with a labelled keypoint")
    files = {im.id: im.file_name for im in coco.images}
    photos: dict[int, np.ndarray] = {}
    crops, kps, boxes = [], [], []
    for j in np.flatnonzero(keep):
        image_id = int(coco.image_ids[j])
        if image_id not in photos:
            what = f"{p}: image {image_id} file_name"
            f = contained_path(root, files[image_id], what, allow_outside)
            if not f.is_file():
                raise InputError(f"--images-dir: {f} (image {image_id} of {p}) does not exist")
            photos[image_id] = to_unit_float(read_image(f, mode="rgb"))
        c, s = crop_window(coco.boxes[j], (w_out, h_out), padding)
        half = np.array([w_out, h_out]) / 2
        shift = (0.5 - c) / s + half - 0.5  # pixel-centre coordinates, module docstring
        h = np.array([[1 / s, 0, shift[0]], [0, 1 / s, shift[1]], [0, 0, 1]])
        crops.append(warp_perspective(photos[image_id], h, (w_out, h_out)))
        kp = coco.keypoints[j].copy()
        labelled = kp[:, 2] > 0
        kp[labelled, :2] = (kp[labelled, :2] - c) / s + half
        kp[~labelled] = 0.0
        kps.append(kp)
        b = coco.boxes[j]
        corners = (np.array([b[:2], b[:2] + b[2:]]) - c) / s + half
        boxes.append(corners.ravel())
    n, k = len(crops), skeleton.num_joints
    return PoseDataset(
        np.stack(crops).astype(np.float32),
        np.stack(kps),
        np.stack(boxes),
        skeleton,
        np.full((n, k, 3), np.nan),
        np.full((n, 3, 3), np.nan),
    )
