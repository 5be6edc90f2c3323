"""Predict images with a shipped or trained network: one path for every caller.

``robopercept nn detect IMAGE...``, ``nn segment IMAGE...``, ``nn pose IMAGE...`` and
the ``nn-*`` jobs of ``robopercept batch`` all do the same per image: load the model
once (:func:`load_image_predictor`), predict each image
(:meth:`ImagePredictor.predict_file`), and keep, print or draw the result
(:class:`ImagePrediction`: :meth:`~ImagePrediction.record`,
:meth:`~ImagePrediction.coco_results`, :meth:`~ImagePrediction.pictures`,
:meth:`~ImagePrediction.write`). The arithmetic is that of
:func:`~robopercept.nn.detection.zoo.detect_arrays`,
:func:`~robopercept.nn.segmentation.networks.segment_arrays` and
:func:`~robopercept.nn.pose.inference.pose_arrays`; this module only chains them, so a
prediction equals the direct call exactly.

The three kinds:

- ``"detect"``: boxes ``(K, 4)`` ``(x1, y1, x2, y2)`` pixels, labels ``(K,)``
  (1-based positions in ``classes``) and scores ``(K,)``, those with
  ``score >= score_thresh`` (default 0.3, as ``nn detect``);
- ``"segment"``: a semantic network's class map ``labels`` ``(H, W)`` (0 the
  background, ``k`` the class ``classes[k - 1]``), or a Mask R-CNN's instances
  (``masks`` ``(K, H, W)`` bool, ``labels``, ``scores``, ``boxes``, with
  ``score >= score_thresh``, default 0.5 as ``nn segment``);
- ``"pose"``: one person per image (top-down): ``keypoints`` ``(J, 2)`` pixels,
  ``scores`` ``(J,)``, optionally ``heatmaps`` ``(J, h, w)`` and ``joints3d`` ``(J, 3)``
  metres, root-relative (lifted by :class:`~robopercept.nn.pose.library.PoseLibrary`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import (
    check_bool,
    check_choice,
    check_image,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import InputError
from robopercept.fileio import strict_json
from robopercept.imaging import read_image, write_image
from robopercept.nn.detection.tta import TestTimeAugmentation
from robopercept.nn.detection.zoo import detect_arrays, load_detector
from robopercept.nn.pose.inference import pose_arrays
from robopercept.nn.pose.library import default_pose_library
from robopercept.nn.pose.networks import load_pose_model
from robopercept.nn.segmentation.networks import (
    coco_segmentation_results,
    load_segmenter,
    segment_arrays,
)
from robopercept.nn.shipped import resolve_model
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import resolve_device
from robopercept.viz import voc_palette
from robopercept.viz.detection import draw_detections
from robopercept.viz.pose import draw_skeleton, heatmap_grid, skeleton_3d_picture
from robopercept.viz.segmentation import class_overlay, instance_overlay

__all__ = [
    "IMAGE_KINDS",
    "ImagePrediction",
    "ImagePredictor",
    "load_image_predictor",
    "load_segment_model",
]

#: the kinds of image prediction
IMAGE_KINDS = ("detect", "segment", "pose")
#: the default ``score_thresh`` of each kind (those of the command-line forms)
_DEFAULT_SCORE = {"detect": 0.3, "segment": 0.5, "pose": 0.0}
#: the views of ``tta`` (:data:`robopercept.nn.detection.tta.TTA_VIEWS`)
_TTA = ("hflip", "flips", "dihedral")


def _class_name(classes: list[str], label: int) -> str:
    return classes[label - 1] if 1 <= label <= len(classes) else str(label)


def _xywh(b: np.ndarray) -> list[float]:
    return [float(b[0]), float(b[1]), float(b[2] - b[0]), float(b[3] - b[1])]


@dataclass
class ImagePrediction:
    """One image's prediction (what :meth:`ImagePredictor.predict` returns).

    Attributes
    ----------
    kind : {"detect", "segment", "pose"}
    image : (H, W, 3) uint8 ndarray
        The image, RGB, as read.
    classes : list of str
        The model's class names (label ``k`` is ``classes[k - 1]``); ``[]`` for pose.
    values : dict of str to ndarray
        detect: ``boxes`` (K, 4) xyxy, ``labels`` (K,), ``scores`` (K,); semantic
        segment: ``labels`` (H, W); instance segment: ``masks`` (K, H, W) bool,
        ``labels``, ``scores``, ``boxes``; pose: ``keypoints`` (J, 2), ``scores`` (J,),
        optionally ``heatmaps`` (J, h, w) and ``joints3d`` (J, 3) metres.
    joints : list of str
        Pose: the joint names; ``[]`` otherwise.
    skeleton : Skeleton, optional
        Pose: the :class:`~robopercept.nn.skeleton.Skeleton` (links and mirror pairs of
        the picture).

    Examples
    --------
    >>> import numpy as np
    >>> p = ImagePrediction(
    ...     "detect",
    ...     np.zeros((8, 8, 3), np.uint8),
    ...     ["circle", "square"],
    ...     {"boxes": np.array([[1.0, 2, 5, 6]]), "labels": np.array([2]),
    ...      "scores": np.array([0.75])},
    ... )
    >>> p.record()["detections"][0]["class"], p.record()["detections"][0]["bbox"]
    ('square', [1.0, 2.0, 4.0, 4.0])
    """

    kind: str
    image: np.ndarray
    classes: list[str]
    values: dict[str, np.ndarray]
    joints: list[str] = field(default_factory=list)
    skeleton: Any = None

    @property
    def instance(self) -> bool:
        """Whether this is an instance segmentation (Mask R-CNN: ``masks`` in values)."""
        return self.kind == "segment" and "masks" in self.values

    def record(self) -> dict[str, Any]:
        """The prediction as strict JSON (NaN and infinities become ``null``).

        detect: ``{"detections": [{"class", "category_id", "bbox": [x, y, w, h],
        "score"}]}``; semantic segment: ``{"pixels": {class: count}}`` for the classes
        present (``"background"`` for label 0); instance segment: ``{"instances":
        [{"class", "category_id", "bbox", "score", "area"}]}`` (``area`` the mask's
        pixels); pose: ``{"joints", "keypoints", "scores"[, "joints3d_m"]}``, the row of
        ``robopercept nn pose --json`` without ``"image"`` (pixels to 0.01, scores to
        1e-4, metres to 1e-4).

        Returns
        -------
        dict

        Examples
        --------
        >>> import numpy as np
        >>> p = ImagePrediction("segment", np.zeros((2, 2, 3), np.uint8), ["disc"],
        ...                     {"labels": np.array([[0, 1], [1, 1]])})
        >>> p.record()
        {'pixels': {'background': 1, 'disc': 3}}
        """
        v = self.values
        if self.kind == "detect":
            rows: list[dict[str, Any]] = [
                {
                    "class": _class_name(self.classes, int(lab)),
                    "category_id": int(lab),
                    "bbox": _xywh(b),
                    "score": float(s),
                }
                for b, lab, s in zip(v["boxes"], v["labels"], v["scores"], strict=True)
            ]
            return strict_json({"detections": rows})
        if self.kind == "segment" and self.instance:
            rows = [
                {
                    "class": _class_name(self.classes, int(lab)),
                    "category_id": int(lab),
                    "bbox": _xywh(b),
                    "score": float(s),
                    "area": int(np.count_nonzero(m)),
                }
                for b, lab, s, m in zip(
                    v["boxes"], v["labels"], v["scores"], v["masks"], strict=True
                )
            ]
            return strict_json({"instances": rows})
        if self.kind == "segment":
            ks, counts = np.unique(np.asarray(v["labels"]), return_counts=True)
            names = ["background", *self.classes]
            pixels = {
                (names[k] if 0 <= k < len(names) else str(int(k))): int(c)
                for k, c in zip(ks.tolist(), counts.tolist(), strict=True)
            }
            return {"pixels": pixels}
        row: dict[str, Any] = {
            "joints": list(self.joints),
            "keypoints": np.round(v["keypoints"], 2).tolist(),
            "scores": np.round(v["scores"], 4).tolist(),
        }
        if "joints3d" in v:
            row["joints3d_m"] = np.round(v["joints3d"], 4).tolist()
        return strict_json(row)

    def coco_results(self, image_id: int) -> list[dict[str, Any]]:
        """COCO result entries of this image (what ``nn detect --json`` and
        ``nn segment --json`` print for it).

        detect: ``{"image_id", "category_id", "bbox": [x, y, w, h], "score"}`` per box;
        segment: :func:`~robopercept.nn.segmentation.networks.coco_segmentation_results` (RLE
        masks: one entry per class present, or per instance).

        Parameters
        ----------
        image_id : int

        Returns
        -------
        list of dict

        Raises
        ------
        InputError
            A pose prediction (COCO keypoint results need a person box; use
            :meth:`record`).

        Examples
        --------
        >>> import numpy as np
        >>> p = ImagePrediction("detect", np.zeros((8, 8, 3), np.uint8), ["a"],
        ...     {"boxes": np.array([[0.0, 0, 2, 3]]), "labels": np.array([1]),
        ...      "scores": np.array([0.5])})
        >>> p.coco_results(7)
        [{'image_id': 7, 'category_id': 1, 'bbox': [0.0, 0.0, 2.0, 3.0], 'score': 0.5}]
        """

        image_id = check_int(image_id, "image_id")
        v = self.values
        if self.kind == "detect":
            return [
                {"image_id": image_id, "category_id": int(lab), "bbox": _xywh(b), "score": float(s)}
                for b, lab, s in zip(v["boxes"], v["labels"], v["scores"], strict=True)
            ]
        if self.kind == "segment":
            if self.instance:
                return coco_segmentation_results(image_id, detections=v)
            return coco_segmentation_results(image_id, labels=v["labels"])
        raise InputError(
            "coco_results: a pose prediction has no COCO results here; use record() "
            "(keypoints and scores) instead"
        )

    def _label_image(self) -> np.ndarray:
        """Class labels, or instance ids 1..N in score order, as one uint8 image."""
        v = self.values
        if not self.instance:
            return np.clip(v["labels"], 0, 255).astype(np.uint8)
        masks = np.asarray(v["masks"], bool)
        out = np.zeros(masks.shape[1:], np.uint8)
        for i in range(len(masks) - 1, -1, -1):  # the best instance on top
            out[masks[i]] = min(i + 1, 255)
        return out

    def pictures(self, stem: str) -> dict[str, np.ndarray]:
        """The pictures of this prediction by file name (those the command line writes).

        detect: ``STEM.png`` (boxes, class names and scores,
        :func:`~robopercept.viz.detection.draw_detections`); segment: ``STEM.png``
        (class or instance overlay, :mod:`robopercept.viz.segmentation`) and
        ``STEM_labels.png`` (the class labels, or instance ids 1..N in score order,
        best on top, as a uint8 map: write it with ``palette=voc_palette()``); pose:
        ``STEM.png`` (the skeleton with per-joint confidence), ``STEM_heatmaps.png``
        with heatmaps, ``STEM_3d.png`` with ``joints3d``.

        Parameters
        ----------
        stem : str
            The file name without extension (the image's, usually).

        Returns
        -------
        dict of str to ndarray

        Examples
        --------
        >>> import numpy as np
        >>> p = ImagePrediction("segment", np.zeros((4, 4, 3), np.uint8), ["disc"],
        ...                     {"labels": np.ones((4, 4), np.int64)})
        >>> {k: v.shape[:2] for k, v in p.pictures("a").items()}["a_labels.png"]
        (4, 4)
        """
        v: dict[str, Any] = self.values
        if self.kind == "detect":
            pic = draw_detections(
                self.image, v["boxes"], v["labels"], self.classes, scores=v["scores"]
            )
            return {f"{stem}.png": pic}
        if self.kind == "segment":
            if self.instance:
                overlay = instance_overlay(
                    self.image,
                    v["masks"],
                    labels=v["labels"],
                    classes=self.classes,
                    scores=v.get("scores"),
                )
            else:
                overlay = class_overlay(self.image, v["labels"], self.classes)
            return {f"{stem}.png": overlay, f"{stem}_labels.png": self._label_image()}

        sk = self.skeleton
        if sk is None:
            raise InputError("pictures: a pose prediction needs its skeleton (skeleton=...)")
        out = {
            f"{stem}.png": draw_skeleton(
                self.image,
                v["keypoints"],
                sk.links,
                confidence=v["scores"],
                flip_pairs=sk.flip_pairs,
                min_side=512,
            )
        }
        if "heatmaps" in v:
            out[f"{stem}_heatmaps.png"] = heatmap_grid(self.image, v["heatmaps"], list(sk.joints))
        if "joints3d" in v:
            out[f"{stem}_3d.png"] = skeleton_3d_picture(v["joints3d"], sk.links)
        return out

    def write(self, out_dir: str | os.PathLike[str], stem: str) -> list[Path]:
        """Write :meth:`pictures` into ``out_dir`` (made if missing); the labels PNG of
        a segmentation with the VOC palette.

        Parameters
        ----------
        out_dir : path-like
        stem : str

        Returns
        -------
        list of pathlib.Path
            The files written, in the order of :meth:`pictures`.

        Examples
        --------
        >>> import tempfile
        >>> import numpy as np
        >>> p = ImagePrediction("detect", np.zeros((8, 8, 3), np.uint8), ["a"],
        ...     {"boxes": np.zeros((0, 4)), "labels": np.zeros(0, int), "scores": np.zeros(0)})
        >>> with tempfile.TemporaryDirectory() as d:
        ...     [f.name for f in p.write(d, "x")]
        ['x.png']
        """

        out = Path(out_dir)
        written = []
        for name, pic in self.pictures(stem).items():
            palette = voc_palette() if name.endswith("_labels.png") else None
            written.append(write_image(out / name, pic, palette=palette))
        return written


@dataclass
class ImagePredictor:
    """A loaded image network with its settings (:func:`load_image_predictor`); call
    :meth:`predict` or :meth:`predict_file` on as many images as needed.

    Attributes
    ----------
    kind : {"detect", "segment", "pose"}
    path : pathlib.Path or None
        The checkpoint read (None for a model built in memory).
    model : torch.nn.Module
        On its device; a detector wrapped in
        :class:`~robopercept.nn.detection.tta.TestTimeAugmentation` with ``tta``.
    info : dict
        The checkpoint without the weights (``classes``, or ``skeleton`` and
        ``refiners`` for pose).
    instance : bool
        segment: a Mask R-CNN (instances) rather than a semantic network.
    score_thresh : float
        detect and instance segment: the smallest score kept.
    flip : bool
        pose: average with the mirrored image (the flip test).
    heatmaps : bool
        pose: keep the heatmaps (for ``STEM_heatmaps.png``).
    library : PoseLibrary or None
        pose: lifts the 2-D joints to 3-D when given.

    Examples
    --------
    >>> import numpy as np
    >>> p = load_image_predictor("detect", device="cpu")
    >>> p.predict(np.zeros((32, 32, 3), np.uint8)).values["boxes"].shape[1]
    4
    """

    kind: str
    path: Path | None
    model: Any
    info: dict[str, Any]
    instance: bool = False
    score_thresh: float = 0.5
    flip: bool = True
    heatmaps: bool = False
    library: Any = None

    @property
    def classes(self) -> list[str]:
        """The class names (``[]`` for pose)."""
        return [] if self.kind == "pose" else list(self.info["classes"])

    def predict(self, image: np.ndarray) -> ImagePrediction:
        """Predict one image.

        Parameters
        ----------
        image : (H, W, 3) ndarray
            RGB, ``uint8``, ``uint16`` or float in [0, 1] (what
            :func:`~robopercept.imaging.read_image` gives with ``mode="rgb"``); a
            semantic segmenter of grey images also takes ``(H, W)``.

        Returns
        -------
        ImagePrediction

        Raises
        ------
        InputError
            Not an image (NaN, channels-first, ...), or a grey one for a network that
            needs RGB.

        Examples
        --------
        >>> import numpy as np
        >>> p = load_image_predictor("segment", device="cpu")
        >>> p.predict(np.zeros((32, 32, 3), np.uint8)).values["labels"].shape
        (32, 32)
        """
        image = check_image(image)
        if self.kind == "detect" or (self.kind == "segment" and self.instance):
            d = detect_arrays(self.model, [image])[0]
            keep = d["scores"] >= self.score_thresh
            return ImagePrediction(
                self.kind, image, self.classes, {k: v[keep] for k, v in d.items()}
            )
        if self.kind == "segment":
            labels = segment_arrays(self.model, [image])[0]
            return ImagePrediction(self.kind, image, self.classes, {"labels": labels})

        sk = self.info["skeleton"]
        res = pose_arrays(
            self.model,
            [image],
            flip_permutation=sk.flip_permutation() if self.flip else None,
            refiners=self.info["refiners"],
        )[0]
        values: dict[str, np.ndarray] = {"keypoints": res.keypoints, "scores": res.scores}
        if self.heatmaps and res.heatmaps is not None:
            values["heatmaps"] = res.heatmaps
        if self.library is not None:
            values["joints3d"] = self.library.lift(res.keypoints[None])[0]
        return ImagePrediction(self.kind, image, [], values, list(sk.joints), sk)

    def predict_file(self, path: str | os.PathLike[str]) -> ImagePrediction:
        """Read an image file as RGB (:func:`~robopercept.imaging.read_image`) and
        :meth:`predict` it.

        Parameters
        ----------
        path : path-like

        Returns
        -------
        ImagePrediction

        Raises
        ------
        FileFormatError
            A missing or unreadable image.

        Examples
        --------
        >>> import tempfile, os
        >>> import numpy as np
        >>> from robopercept.imaging import write_image
        >>> p = load_image_predictor("detect", device="cpu")
        >>> with tempfile.TemporaryDirectory() as d:
        ...     f = write_image(os.path.join(d, "a.png"), np.zeros((32, 32, 3), np.uint8))
        ...     p.predict_file(f).image.shape
        (32, 32, 3)
        """

        return self.predict(read_image(path, mode="rgb"))


def load_segment_model(path: str | os.PathLike[str]) -> tuple[Any, dict[str, Any], bool]:
    """Load a segmentation checkpoint: a semantic network
    (:func:`~robopercept.nn.segmentation.networks.load_segmenter`) or a Mask R-CNN
    (:func:`~robopercept.nn.detection.zoo.load_detector`, told apart by the checkpoint's
    ``kind``).

    Parameters
    ----------
    path : path-like
        A ``model.pt``.

    Returns
    -------
    model : torch.nn.Module
        On the CPU.
    info : dict
        The checkpoint without the weights (``classes``, ``settings``, ...).
    instance : bool
        True for a Mask R-CNN.

    Raises
    ------
    FileFormatError
        Missing or unreadable file, or not a segmenter's checkpoint.

    Examples
    --------
    >>> from robopercept.nn.shipped import shipped_model_path
    >>> model, info, instance = load_segment_model(shipped_model_path("segment", "unet"))
    >>> (instance, info["classes"][:2])
    (False, ['circle', 'square'])
    """

    if load_checkpoint(path).get("kind") == "maskrcnn":
        model, info = load_detector(path)
        return model, info, True

    model, info = load_segmenter(path)
    return model, info, False


def load_image_predictor(
    kind: str,
    model: str | os.PathLike[str] | None = None,
    *,
    device: str | None = None,
    score_thresh: float | None = None,
    tta: str | None = None,
    flip: bool = True,
    heatmaps: bool = False,
    lift3d: bool = False,
) -> ImagePredictor:
    """Load an image network for :meth:`ImagePredictor.predict`.

    Parameters
    ----------
    kind : {"detect", "segment", "pose"}
    model : str or path-like, optional
        A shipped name (:data:`~robopercept.nn.shipped.SHIPPED`: ``fcos``/``faster``,
        ``unet``/``maskrcnn``, ``hrnet``/``deeppose``), a run folder or a ``model.pt``;
        default the kind's default shipped model
        (:func:`~robopercept.nn.shipped.resolve_model`).
    device : str, optional
        ``"cpu"``, ``"cuda"``, ...; default CUDA when available
        (:func:`~robopercept.nn.train.config.resolve_device`).
    score_thresh : float in [0, 1], optional
        detect and instance segment: keep detections with ``score >= score_thresh``;
        default 0.3 for detect, 0.5 for segment (the command line's defaults). Ignored
        for pose and semantic segmentation.
    tta : {"hflip", "flips", "dihedral"}, optional
        detect: test-time augmentation
        (:class:`~robopercept.nn.detection.tta.TestTimeAugmentation`); ignored for the other
        kinds.
    flip : bool
        pose: the flip test (average with the mirrored image); ignored otherwise.
    heatmaps : bool
        pose: keep the heatmaps (and draw ``STEM_heatmaps.png``); ignored otherwise.
    lift3d : bool
        pose: lift the 2-D joints to 3-D (root-relative metres) by matching against
        :func:`~robopercept.nn.pose.library.default_pose_library`; ignored otherwise.

    Returns
    -------
    ImagePredictor

    Raises
    ------
    InputError
        Unknown kind, shipped name or ``tta``, a missing model file, a bad threshold or
        an unknown device.
    FileFormatError
        A file that is not a checkpoint of the kind.

    Examples
    --------
    >>> p = load_image_predictor("pose", device="cpu")
    >>> (p.kind, p.path.name, len(p.info["skeleton"].joints))
    ('pose', 'pose_hrnet_figures.pt', 16)
    """
    check_choice(kind, "kind", IMAGE_KINDS)
    if score_thresh is None:
        score_thresh = _DEFAULT_SCORE[kind]
    score_thresh = check_real(score_thresh, "score_thresh", low=0.0, high=1.0)
    if tta is not None:
        check_choice(tta, "tta", _TTA)
    flip = check_bool(flip, "flip")
    heatmaps = check_bool(heatmaps, "heatmaps")
    lift3d = check_bool(lift3d, "lift3d")
    if device is not None and not isinstance(device, str):
        raise InputError(f"device must be a name such as 'cpu' or 'cuda'; got {plain_repr(device)}")
    path = resolve_model(kind, model)

    if kind == "detect":
        net, info = load_detector(path)
        net.to(resolve_device(device))
        if tta:
            net = TestTimeAugmentation(net, tta)
        return ImagePredictor(kind, path, net, info, score_thresh=score_thresh)
    if kind == "segment":
        net, info, instance = load_segment_model(path)
        net.to(resolve_device(device))
        return ImagePredictor(kind, path, net, info, instance=instance, score_thresh=score_thresh)

    net, info = load_pose_model(path)
    net.to(resolve_device(device))
    library = None
    if lift3d:
        library = default_pose_library(info["skeleton"])
    return ImagePredictor(
        kind,
        path,
        net,
        info,
        score_thresh=score_thresh,
        flip=flip,
        heatmaps=heatmaps,
        library=library,
    )
