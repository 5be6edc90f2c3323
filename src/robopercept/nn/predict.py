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

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import (
    as_path,
    check_bool,
    check_choice,
    check_image,
    check_int,
    check_real,
    plain_repr,
)
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import strict_json
from robopercept.imaging import read_image, write_image
from robopercept.nn.cloud.train import CLOUD_MODELS
from robopercept.nn.data.datasets import to_unit_float
from robopercept.nn.detection.thresholds import domain_warning, input_warning
from robopercept.nn.detection.tiling import check_tiling, detect_tiled, segment_tiled
from robopercept.nn.detection.tta import (
    TTA_CHOICES,
    TTA_SCALE_RANGE,
    TTA_VIEWS,
    check_tta_config,
    resolve_tta,
    wrap_tta,
)
from robopercept.nn.detection.zoo import DETECTORS, detect_arrays, load_detector
from robopercept.nn.pose.inference import pose_arrays
from robopercept.nn.pose.library import default_pose_library
from robopercept.nn.pose.networks import POSE_MODELS, load_pose_model
from robopercept.nn.predict_class import CLASS_KINDS, ClassPredictor, load_class_predictor
from robopercept.nn.segmentation.data import percentile_normalize
from robopercept.nn.segmentation.networks import (
    SEGMENTERS,
    coco_segmentation_results,
    load_segmenter,
    segment_arrays,
)
from robopercept.nn.shipped import DEFAULT_SHIPPED, MODEL_CARDS, SHIPPED, resolve_model
from robopercept.nn.train.checkpoint import load_checkpoint
from robopercept.nn.train.config import resolve_device
from robopercept.nn.train.runs import BEST_CHECKPOINT
from robopercept.viz import voc_palette
from robopercept.viz.detection import draw_detections
from robopercept.viz.pose import draw_skeleton, heatmap_grid, skeleton_3d_picture
from robopercept.viz.segmentation import class_overlay, instance_overlay

__all__ = [
    "IMAGE_KINDS",
    "ImagePrediction",
    "ImagePredictor",
    "load_image_predictor",
    "load_predictor",
    "load_segment_model",
]

#: the kinds of image prediction
IMAGE_KINDS = ("detect", "segment", "pose")
#: the default ``score_thresh`` of each kind (those of the command-line forms)
_DEFAULT_SCORE = {"detect": 0.3, "segment": 0.5, "pose": 0.0}
#: the largest tiling window a checkpoint may store
_MAX_TILE = 1 << 15


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
    warning : str or None
        The line saying the image looks outside the model's domain
        (:func:`~robopercept.nn.detection.thresholds.domain_warning`), else None.
    joint_thresh : float
        Pose: joints scoring under it are not drawn (nor the limbs they end).

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
    warning: str | None = None
    joint_thresh: float = 0.0

    @property
    def boxes(self) -> np.ndarray:
        """detect and instance segment: ``(K, 4)`` boxes ``(x1, y1, x2, y2)`` pixels."""
        return self._value("boxes")

    @property
    def labels(self) -> np.ndarray:
        """``(K,)`` labels (1-based positions in :attr:`classes`), or a semantic
        segmentation's ``(H, W)`` class map (0 the background)."""
        return self._value("labels")

    @property
    def scores(self) -> np.ndarray:
        """``(K,)`` detection scores, or pose's ``(J,)`` joint scores."""
        return self._value("scores")

    @property
    def masks(self) -> np.ndarray:
        """instance segment: ``(K, H, W)`` bool masks."""
        return self._value("masks")

    @property
    def keypoints(self) -> np.ndarray:
        """pose: ``(J, 2)`` joint positions, pixels."""
        return self._value("keypoints")

    @property
    def class_names(self) -> list[str]:
        """detect and instance segment: the class name of each box, in order."""
        return [_class_name(self.classes, int(k)) for k in self._value("labels")]

    def _value(self, name: str) -> np.ndarray:
        if name not in self.values or (name == "labels" and self.kind == "pose"):
            raise InputError(
                f"a {self.kind} prediction has no {name}; it holds {', '.join(self.values)}"
            )
        return self.values[name]

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
        shown = np.where(v["scores"] >= self.joint_thresh, v["scores"], np.nan)
        out = {
            f"{stem}.png": draw_skeleton(
                self.image,
                v["keypoints"],
                sk.links,
                confidence=shown,
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

        out = as_path(out_dir, "out_dir (-o/--out)")
        if not isinstance(stem, str) or not stem:
            raise InputError(f"stem must be a file name stem (str); got {plain_repr(stem)[:60]}")
        written = []
        for name, pic in self.pictures(stem).items():
            palette = voc_palette() if name.endswith("_labels.png") else None
            written.append(write_image(out / name, pic, palette=palette))
        return written


@dataclass
class ImagePredictor:
    """A loaded image network with its settings (:func:`load_image_predictor`); call it
    (or :meth:`predict`) on an image path, an array, or a list of them.

    Attributes
    ----------
    kind : {"detect", "segment", "pose"}
    path : pathlib.Path or None
        The checkpoint read (None for a model built in memory).
    model : torch.nn.Module
        On its device; a detector wrapped in
        :class:`~robopercept.nn.detection.tta.TestTimeAugmentation` when ``tta`` is
        not None.
    info : dict
        The checkpoint without the weights (``classes``, or ``skeleton`` and
        ``refiners`` for pose; ``calibration`` and ``tile`` where stored).
    instance : bool
        segment: a Mask R-CNN (instances) rather than a semantic network.
    score_thresh : float
        detect and instance segment: the smallest score kept; pose: the smallest joint
        score drawn.
    flip : bool
        pose: average with the mirrored image (the flip test).
    heatmaps : bool
        pose: keep the heatmaps (for ``STEM_heatmaps.png``).
    library : PoseLibrary or None
        pose: lifts the 2-D joints to 3-D when given.
    tile : int
        detect and segment: images larger than this (either side) are predicted in
        overlapping windows of this side (:mod:`robopercept.nn.detection.tiling`); 0
        never tiles.
    overlap : int
        Pixels shared by neighbouring windows.
    name : str
        The model's name (a shipped name, or the checkpoint's path).
    tta : dict or None
        detect: the test-time augmentation run (``{"views", "scales", "iou_thresh"}``,
        :func:`~robopercept.nn.detection.tta.resolve_tta`), None for none.
    trained_on : str
        What it learnt from (the shipped model's card; "your own data" otherwise).

    Examples
    --------
    >>> import numpy as np
    >>> p = load_image_predictor("detect", device="cpu")
    >>> p(np.zeros((32, 32, 3), np.uint8)).boxes.shape[1]
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
    tile: int = 0
    overlap: int = 0
    name: str = ""
    tta: dict[str, Any] | None = None
    trained_on: str = "your own data"

    @property
    def classes(self) -> list[str]:
        """The class names (``[]`` for pose)."""
        return [] if self.kind == "pose" else list(self.info["classes"])

    def __call__(self, image: Any) -> Any:
        """:meth:`predict`."""
        return self.predict(image)

    def predict(self, image: Any) -> Any:
        """Predict one image, or each of a list.

        Parameters
        ----------
        image : path-like, (H, W, 3) ndarray, or list of them
            A file (read as RGB by :func:`~robopercept.imaging.read_image`), or RGB
            ``uint8``, ``uint16`` or float in [0, 1]; a semantic segmenter of grey
            images also takes ``(H, W)``.

        Returns
        -------
        ImagePrediction, or a list of them for a list

        Raises
        ------
        InputError
            Not an image (NaN, channels-first, ...), or a grey one for a network that
            needs RGB.
        FileFormatError
            A missing or unreadable image file.

        Examples
        --------
        >>> import numpy as np
        >>> p = load_image_predictor("segment", device="cpu")
        >>> p.predict(np.zeros((32, 32, 3), np.uint8)).labels.shape
        (32, 32)
        >>> len(p.predict([np.zeros((16, 16, 3)), np.ones((16, 16, 3))]))
        2
        """
        if isinstance(image, (str, os.PathLike)):
            return self.predict_file(image)
        if isinstance(image, (list, tuple)):
            return [self.predict(im) for im in image]
        image = check_image(image)
        return self._predict_array(image)

    def _tiled(self, image: np.ndarray) -> bool:
        return bool(self.tile) and max(image.shape[:2]) > self.tile

    def _detections(self, image: np.ndarray) -> dict[str, np.ndarray]:
        def one(im: np.ndarray) -> dict[str, np.ndarray]:
            return detect_arrays(self.model, [im])[0]

        if not self._tiled(image):
            return one(image)
        base = getattr(self.model, "model", self.model)  # TestTimeAugmentation wraps
        nms = float(getattr(base, "nms_thresh", 0.5))
        return detect_tiled(one, image, self.tile, self.overlap, nms)

    def _warning(self, best: float) -> str | None:
        return domain_warning(best, self.info.get("calibration"), self.name, self.trained_on)

    def _network_input(self, image: np.ndarray) -> np.ndarray:
        """The image as the network was trained to see it: a model that stores
        ``input_normalize`` (the nuclei models) takes the grey image scaled by its own
        1st and 99.8th percentiles (StarDist's normalisation,
        :func:`~robopercept.nn.segmentation.data.percentile_normalize`), clipped to
        [0, 1] where training clipped it, in three channels for a detector."""
        norm = self.info.get("input_normalize")
        if not norm:
            return image
        grey = to_unit_float(image)
        grey = grey.mean(axis=2) if grey.ndim == 3 else grey
        lo, hi = norm["percentile"]
        x = percentile_normalize(grey, lo, hi)
        if norm.get("clip"):
            x = np.clip(x, 0.0, 1.0)
        if self.kind == "detect" or self.instance:
            x = np.repeat(x[..., None], 3, axis=2)
        return x

    def _predict_array(self, image: np.ndarray) -> ImagePrediction:
        shown = image
        seen = input_warning(image, self.info, self.name, self.trained_on)
        image = self._network_input(image)
        if self.kind == "detect" or (self.kind == "segment" and self.instance):
            d = self._detections(image)
            keep = d["scores"] >= self.score_thresh
            return ImagePrediction(
                self.kind,
                shown,
                self.classes,
                {k: v[keep] for k, v in d.items()},
                warning=seen or self._warning(float(d["scores"].max(initial=0.0))),
            )
        if self.kind == "segment":
            if self._tiled(image):
                labels = segment_tiled(
                    lambda im: segment_arrays(self.model, [im])[0], image, self.tile, self.overlap
                )
            else:
                labels = segment_arrays(self.model, [image])[0]
            return ImagePrediction(self.kind, shown, self.classes, {"labels": labels}, warning=seen)

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
        return ImagePrediction(
            self.kind,
            shown,
            [],
            values,
            list(sk.joints),
            sk,
            warning=seen or self._warning(float(np.median(res.scores))),
            joint_thresh=self.score_thresh,
        )

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

        return self._predict_array(check_image(read_image(path, mode="rgb")))


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
    tta_scales: Sequence[float] | None = None,
    flip: bool = True,
    heatmaps: bool = False,
    lift3d: bool = False,
    all_scores: bool = False,
    tile: int | None = None,
    overlap: int | float | None = None,
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
        default the threshold stored with the model (chosen on its validation images,
        :func:`~robopercept.nn.detection.thresholds.choose_score_threshold`), else 0.3
        for detect and 0.5 for segment. Ignored for pose and semantic segmentation.
    tta : {"none", "identity", "hflip", "flips", "dihedral"}, optional
        detect: the views of test-time augmentation
        (:class:`~robopercept.nn.detection.tta.TestTimeAugmentation`); default the
        augmentation the model ships with (the trees model's was chosen on its
        validation tiles, with its score threshold after it), else none; ``"none"``
        turns it off. Ignored for the other kinds.
    tta_scales : sequence of float, optional
        detect: the image scales of test-time augmentation (``--tta-scales``); default
        the model's, else ``(1.0,)``.
    flip : bool
        pose: the flip test (average with the mirrored image); ignored otherwise.
    heatmaps : bool
        pose: keep the heatmaps (and draw ``STEM_heatmaps.png``); ignored otherwise.
    lift3d : bool
        pose: lift the 2-D joints to 3-D (root-relative metres) by matching against
        :func:`~robopercept.nn.pose.library.default_pose_library`; ignored otherwise.
    all_scores : bool
        detect and instance segment: keep every output (``score_thresh`` 0).
    tile : int, optional
        detect and segment: predict images larger than ``tile`` in overlapping windows
        of that side (:mod:`~robopercept.nn.detection.tiling`); default the window the
        model was trained on where it stores one (the trees model: 400), else no
        tiling; 0 never tiles.
    overlap : int or float, optional
        Pixels shared by neighbouring windows, or a fraction of ``tile`` (default
        0.25).

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
    if score_thresh is not None:
        score_thresh = check_real(score_thresh, "score_thresh (--score-thresh)", 0.0, 1.0)
    if check_bool(all_scores, "all_scores"):
        score_thresh = 0.0
    if tile is not None:
        tile = 0 if tile == 0 else check_int(tile, "tile (--tile)", 16)
    if tta is not None:
        check_choice(tta, "tta (--tta)", TTA_CHOICES)
    flip = check_bool(flip, "flip")
    heatmaps = check_bool(heatmaps, "heatmaps")
    lift3d = check_bool(lift3d, "lift3d")
    if device is not None and not isinstance(device, str):
        raise InputError(f"device must be a name such as 'cpu' or 'cuda'; got {plain_repr(device)}")
    path = resolve_model(kind, model)
    name = DEFAULT_SHIPPED[kind] if model is None else model if isinstance(model, str) else None
    if name is not None and name not in SHIPPED[kind]:
        name = None
    common: dict[str, Any] = {
        "name": name or str(path),
        "trained_on": MODEL_CARDS[name].trained_on if name else "your own data",
    }

    def settle(info: dict[str, Any]) -> dict[str, Any]:
        """The threshold and tiling of a loaded model (its entries checked first)."""
        _check_image_info(info, path)
        cal = info.get("calibration") or {}
        window = int(info.get("tile") or 0) if tile is None else tile
        return {
            **common,
            "score_thresh": score_thresh
            if score_thresh is not None
            else float(cal.get("score_thresh", _DEFAULT_SCORE[kind])),
            "tile": window,
            "overlap": check_tiling(
                window, info.get("tile_overlap") if overlap is None else overlap
            )[1]
            if window
            else 0,
        }

    if kind == "detect":
        net, info = load_detector(path)
        net.to(resolve_device(device))
        settings = settle(info)  # the stored tta checked first
        config = resolve_tta(info.get("tta"), tta, tta_scales)
        return ImagePredictor(kind, path, wrap_tta(net, config), info, tta=config, **settings)
    if kind == "segment":
        net, info, instance = load_segment_model(path)
        net.to(resolve_device(device))
        return ImagePredictor(kind, path, net, info, instance=instance, **settle(info))

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
        flip=flip,
        heatmaps=heatmaps,
        library=library,
        **settle(info),
    )


def _real(value: Any, low: float, high: float) -> bool:
    """Whether ``value`` is a real number (not a bool) in ``[low, high]``."""
    return (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and math.isfinite(value)
        and low <= value <= high
    )


def _check_image_info(info: dict[str, Any], path: Path) -> None:
    """The entries a checkpoint stores for prediction, checked before any is used:
    ``calibration`` (``score_thresh``, ``match_median`` in [0, 1]), ``tile`` and
    ``tile_overlap`` (:func:`~robopercept.nn.detection.tiling.check_tiling`),
    ``tta`` (:func:`~robopercept.nn.detection.tta.resolve_tta`), ``input_normalize``
    (``percentile`` ``[lo, hi]`` in [0, 100], ``clip``), ``input_colour`` and ``canvas``
    ``(h, w)``.

    Raises
    ------
    FileFormatError
        The first damaged entry, named with the file.
    """

    def bad(entry: str, want: str) -> FileFormatError:
        got = info.get(entry)
        shown = plain_repr(got) if isinstance(got, int | float | str | type(None)) else ""
        return FileFormatError(
            f"{path}: its {entry!r} must be {want}; got "
            f"{shown[:60] or 'a ' + type(got).__name__}: the file is damaged"
        )

    cal = info.get("calibration")
    if cal is not None:
        if not isinstance(cal, dict):
            raise bad("calibration", "a dict with score_thresh")
        # an empty calibration is none; a stored one has its threshold
        needed = ("score_thresh",) if cal else ()
        for key in ("score_thresh", "match_median"):
            if (key in cal or key in needed) and not _real(cal.get(key), 0, 1):
                raise FileFormatError(
                    f"{path}: its calibration {key} must be a number in [0, 1]; got "
                    f"{plain_repr(cal.get(key))[:60]}: the file is damaged"
                )
    tile = info.get("tile")
    if tile is not None and tile != 0:
        if not isinstance(tile, int) or isinstance(tile, bool) or not 16 <= tile <= _MAX_TILE:
            raise bad("tile", f"a window side from 16 to {_MAX_TILE} pixels")
        try:
            check_tiling(tile, info.get("tile_overlap"))
        except InputError as exc:
            raise bad("tile_overlap", f"pixels or a fraction under the tile ({exc})") from None
    tta = info.get("tta")
    if tta is not None:
        lo, hi = TTA_SCALE_RANGE
        try:
            check_tta_config(tta)
        except InputError:
            raise bad(
                "tta",
                f"a test-time augmentation {{'views': one of {', '.join(TTA_VIEWS)}, "
                f"'scales': distinct factors in [{lo:g}, {hi:g}], 'iou_thresh': None or "
                "in [0, 1]}",
            ) from None
    norm = info.get("input_normalize")
    if norm:
        pct = norm.get("percentile") if isinstance(norm, dict) else None
        if (
            not isinstance(pct, list | tuple)
            or len(pct) != 2
            or not all(_real(v, 0, 100) for v in pct)
            or not pct[0] < pct[1]
            or not isinstance(norm.get("clip", False), bool)
        ):
            raise bad("input_normalize", "{'percentile': [lo, hi] with 0 <= lo < hi <= 100}")
    if not isinstance(info.get("input_colour"), str | type(None)):
        raise bad("input_colour", "a name ('grey')")
    canvas = info.get("canvas")
    if canvas is not None and (
        not isinstance(canvas, list | tuple)
        or len(canvas) != 2
        or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in canvas)
    ):
        raise bad("canvas", "the training images' size (h, w)")


def _checkpoint_kind(model: str | os.PathLike[str]) -> str:
    """The kind a run folder's or checkpoint's model predicts (its ``kind`` entry; a
    classifier's run keeps its recorded ``architecture`` in ``checkpoint.best.pt``)."""
    p = as_path(model, "model (a run folder or a checkpoint)")
    if p.is_dir() and not (p / "model.pt").is_file() and (p / BEST_CHECKPOINT).is_file():
        p = p / BEST_CHECKPOINT
    path = resolve_model("detect", p)
    state = load_checkpoint(path)
    name = state.get("kind")
    if not isinstance(name, str):
        name = None
    if name in POSE_MODELS or (name is None and "skeleton" in state):
        return "pose"  # (a Keypoint R-CNN also stores a skeleton: it is a detector)
    if name == "maskrcnn" or name in SEGMENTERS:
        return "segment"
    if name in DETECTORS:
        return "detect"
    if name in CLOUD_MODELS:
        return "cloud"
    if "architecture" in state and "kind" not in state:  # what robopercept nn train records
        return "classify"
    raise InputError(
        f"{path}: not a model robopercept saved (kind {plain_repr(name)}): give kind= one of "
        f"{', '.join(IMAGE_KINDS + CLASS_KINDS)}"
    )


def load_predictor(
    model: str | os.PathLike[str], *, kind: str | None = None, **options: Any
) -> ImagePredictor | ClassPredictor:
    """The one way into a model from Python: a shipped model by name (``robopercept nn
    models`` lists them) or a run folder / checkpoint, ready to call on a path, an array
    or a list of them.

    Parameters
    ----------
    model : str or path-like
        A shipped name (``"trees"``, ``"nuclei"``, ``"fcos"``, ``"hrnet"``, ...), a run
        folder or a checkpoint file.
    kind : {"detect", "segment", "pose", "classify", "cloud"}, optional
        Default: the shipped model's, or read from the checkpoint.
    **options
        The keywords of :func:`load_image_predictor` (``device``, ``score_thresh``,
        ``all_scores``, ``tile``, ``overlap``, ``tta``, ``tta_scales``, ``flip``, ``heatmaps``,
        ``lift3d``), or for a classifier or point-cloud network those of
        :func:`~robopercept.nn.predict_class.load_class_predictor` (``device``,
        ``n_points``, ``seed``).

    Returns
    -------
    ImagePredictor or ClassPredictor
        Call it: ``predictor("photo.png")`` gives an :class:`ImagePrediction` with
        ``boxes``, ``labels``, ``class_names``, ``scores``, ``masks`` or ``keypoints``,
        ``warning`` and ``pictures()``; a classifier or point-cloud network gives a
        :class:`~robopercept.nn.predict_class.ClassPrediction` with ``class_name``,
        ``score``, ``probabilities``, ``warning`` and ``picture()``.

    Raises
    ------
    InputError
        An unknown name, a missing file, a ``kind`` other than the shipped model's, a
        checkpoint that robopercept did not save, options of another kind.

    Examples
    --------
    >>> import numpy as np
    >>> shapes = load_predictor("fcos", device="cpu")
    >>> (shapes.kind, shapes.name, shapes.classes)
    ('detect', 'fcos', ['circle', 'square', 'triangle', 'cross'])
    >>> shapes(np.zeros((64, 64, 3), np.uint8)).class_names
    []
    >>> load_predictor("digits")(np.zeros((8, 8))).class_name in [str(d) for d in range(10)]
    True
    """
    if kind is not None:
        check_choice(kind, "kind", IMAGE_KINDS + CLASS_KINDS)
    if isinstance(model, str) and model in MODEL_CARDS:
        card_kind = MODEL_CARDS[model].kind
        if kind is not None and kind != card_kind:
            raise InputError(f"kind {kind!r} does not match {model!r}, a {card_kind} model")
        kind = card_kind
    elif kind is None:
        kind = _checkpoint_kind(model)
    if kind in CLASS_KINDS:
        extra = sorted(set(options) - {"device", "n_points", "seed"})
        if extra:
            raise InputError(
                f"{extra[0]}= is not an option of a {kind} model (device, n_points, seed)"
            )
        return load_class_predictor(kind, model, **options)
    return load_image_predictor(kind, model, **options)
