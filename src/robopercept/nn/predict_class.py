"""Predict one class per input from Python: image classifiers and point-cloud networks,
the two kinds :func:`robopercept.nn.predict.load_predictor` hands here.

:func:`load_class_predictor` loads a shipped model by name or a run (an image
classifier's run folder or checkpoint, :func:`~robopercept.nn.classification.saved.load_run`;
a point-cloud network's ``model.pt``,
:func:`~robopercept.nn.cloud.train.load_cloud_model`) once; the
:class:`ClassPredictor` it returns is called on a file, an array or a list of them and
gives :class:`ClassPrediction` records: the classes by probability, the domain warning,
a picture. The arithmetic is that of
:func:`~robopercept.nn.classification.run.class_probabilities` (what ``robopercept nn
predict`` prints) and of :func:`~robopercept.nn.cloud.run.classify_cloud_file` with
:func:`~robopercept.nn.cloud.data.sample_cloud` for arrays (what ``robopercept nn cloud``
prints), so a prediction here equals the command's.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_choice, check_int
from robopercept.errors import InputError
from robopercept.imaging import read_image, write_image
from robopercept.nn._guards import check_device
from robopercept.nn.classification.run import class_probabilities
from robopercept.nn.classification.saved import Architecture, load_run
from robopercept.nn.cloud.data import sample_cloud
from robopercept.nn.cloud.run import classify_cloud_file, load_cloud_model
from robopercept.nn.cloud.train import cloud_model_spec, predict_clouds
from robopercept.nn.shipped import DEFAULT_SHIPPED, MODEL_CARDS, SHIPPED, resolve_model
from robopercept.nn.train.config import resolve_device
from robopercept.viz.cloud_dl import cloud_picture
from robopercept.viz.draw import draw_text

__all__ = ["CLASS_KINDS", "ClassPrediction", "ClassPredictor", "load_class_predictor"]

#: the kinds of one-class-per-input prediction
CLASS_KINDS = ("classify", "cloud")


@dataclass(frozen=True, eq=False)
class ClassPrediction:
    """What a :class:`ClassPredictor` found in one input.

    Attributes
    ----------
    source : str
        The file, or ``"<array>"``.
    probabilities : dict of str to float
        Every class's probability, most probable first.
    warning : str or None
        The input lies outside the model's domain (a classifier's image shrunk more
        than :data:`~robopercept.nn.classification.run.SHRINK_LIMIT` times).
    image : ndarray or None
        classify: the image as read (for :meth:`picture`).
    points : (n, 3) float32 ndarray or None
        cloud: the sampled, unit-sphere-normalized points the network saw.
    """

    source: str
    probabilities: dict[str, float]
    warning: str | None = None
    image: np.ndarray | None = None
    points: np.ndarray | None = None

    @property
    def class_name(self) -> str:
        """The most probable class."""
        return next(iter(self.probabilities))

    @property
    def score(self) -> float:
        """Its probability."""
        return next(iter(self.probabilities.values()))

    def top(self, k: int = 3) -> list[tuple[str, float]]:
        """The ``k`` most probable ``(class, probability)`` pairs."""
        return list(self.probabilities.items())[: check_int(k, "k", 1)]

    def record(self) -> dict[str, Any]:
        """JSON-ready: ``source``, ``class``, ``score``, ``probabilities``, ``warning``."""
        return {
            "source": self.source,
            "class": self.class_name,
            "score": round(self.score, 6),
            "probabilities": {k: round(v, 6) for k, v in self.probabilities.items()},
            "warning": self.warning,
        }

    def picture(self) -> np.ndarray:
        """The input with its top classes: the image with a caption (enlarged so the
        caption reads at 1080p), or the cloud's three views
        (:func:`~robopercept.viz.cloud_dl.cloud_picture`)."""
        caption = ", ".join(f"{c} {p:.2f}" for c, p in self.top(3))
        if self.points is not None:
            return cloud_picture(self.points, title=f"{Path(self.source).stem}: {caption}")
        assert self.image is not None
        img = self.image
        if img.dtype != np.uint8:
            scale = 255.0 if img.dtype.kind == "f" else 255.0 / np.iinfo(img.dtype).max
            img = np.clip(np.round(img.astype(np.float64) * scale), 0, 255).astype(np.uint8)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        k = max(1, int(np.ceil(720 / max(img.shape[:2]))))  # small inputs (8 x 8) enlarged
        img = np.repeat(np.repeat(img, k, axis=0), k, axis=1)
        return draw_text(img, caption, (4, 4))

    def write(self, out_dir: str | os.PathLike[str], stem: str) -> Path:
        """Write :meth:`picture` to ``out_dir/stem.png`` (folder created); its path."""
        out = as_path(out_dir, "out_dir (-o/--out)")
        out.mkdir(parents=True, exist_ok=True)
        return write_image(out / f"{stem}.png", self.picture())


@dataclass(frozen=True, eq=False)
class ClassPredictor:
    """A loaded classifier (``kind`` ``"classify"``) or point-cloud network
    (``"cloud"``) with its settings (:func:`load_class_predictor`); call it on a file,
    an array or a list of them.

    Attributes
    ----------
    kind : {"classify", "cloud"}
    name : str
        The shipped name or the checkpoint's path.
    model : torch.nn.Module
    info : Architecture or dict
        classify: the run's :class:`~robopercept.nn.classification.saved.Architecture`;
        cloud: :func:`~robopercept.nn.cloud.train.load_cloud_model`'s dict.
    trained_on : str
        What it learnt from (the shipped model's card; "your own data" otherwise).
    n_points : int
        cloud: points sampled from each input.
    seed : int
        cloud: the sampling's seed.

    Examples
    --------
    >>> import numpy as np
    >>> digits = load_class_predictor("classify", "digits")
    >>> p = digits(np.zeros((8, 8)))
    >>> p.class_name in digits.classes, round(sum(p.probabilities.values()), 6)
    (True, 1.0)
    """

    kind: str
    name: str
    model: Any
    info: Any
    trained_on: str = "your own data"
    n_points: int = 1024
    seed: int = 0

    @property
    def classes(self) -> list[str]:
        """The class names, in the network's order."""
        if isinstance(self.info, Architecture):
            return list(self.info.classes)
        return list(self.info["class_names"])

    def __call__(self, x: Any) -> Any:
        """:meth:`predict`."""
        return self.predict(x)

    def predict(self, x: Any) -> Any:
        """Predict one input, or each of a list.

        Parameters
        ----------
        x : path-like, ndarray, or list of them
            classify: an image file or an ``(H, W)`` / ``(H, W, 3)`` array (uint8,
            uint16 or float in [0, 1]); cloud: a mesh or cloud file (``.off``, ``.ply``,
            ``.pcd``) or an ``(N, 3)`` array of points.

        Returns
        -------
        ClassPrediction, or a list of them for a list

        Raises
        ------
        InputError
            Not an image or not an ``(N, 3)`` array.
        FileFormatError
            A missing or unreadable file.
        """
        if isinstance(x, (list, tuple)):
            return [self.predict(v) for v in x]
        source = os.fspath(x) if isinstance(x, (str, os.PathLike)) else "<array>"
        if self.kind == "cloud":
            if source != "<array>":
                res = classify_cloud_file(
                    source, self.model, self.info, n_points=self.n_points, rng=self.seed
                )
                return ClassPrediction(source, res.probabilities, points=res.points)
            pts = sample_cloud(x, self.n_points, self.seed)
            prob = predict_clouds(self.model, pts)
            return ClassPrediction(source, self._ranked(prob), points=pts)
        arch = self.info
        image = read_image(source, mode=arch.mode) if source != "<array>" else np.asarray(x)
        prob, warning = class_probabilities(self.model, arch, image)
        warn = None if warning is None else f"{source}: {warning}"
        return ClassPrediction(source, self._ranked(prob), warn, image=image)

    def _ranked(self, prob: np.ndarray) -> dict[str, float]:
        """``{class: probability}``, most probable first (ties in class order)."""
        names = self.classes
        return {names[int(i)]: float(prob[i]) for i in np.argsort(-prob, kind="stable")}


def load_class_predictor(
    kind: str,
    model: str | os.PathLike[str] | None = None,
    *,
    device: str | None = None,
    n_points: int | None = None,
    seed: int = 0,
) -> ClassPredictor:
    """Load a classifier or point-cloud network once, ready to call.

    Parameters
    ----------
    kind : {"classify", "cloud"}
    model : str or path-like, optional
        A shipped name (``"digits"``; ``"pointnet"``, ``"dgcnn"``), a run folder or a
        checkpoint (default: the kind's default shipped model).
    device : str, optional
        Where the network runs (default: the CPU).
    n_points : int, optional
        cloud: points sampled per input (default: the count it was trained on).
    seed : int
        cloud: the sampling's seed.

    Returns
    -------
    ClassPredictor

    Raises
    ------
    InputError
        An unknown kind or device, a segmentation point-cloud network (its per-point
        parts are ``robopercept nn cloud --segment``'s).
    FileFormatError
        A missing file, or one that is not a model of the kind.
    """
    kind = check_choice(kind, "kind", CLASS_KINDS)
    check_device(device, "device (--device)")
    seed = check_int(seed, "seed", 0)
    name = DEFAULT_SHIPPED[kind] if model is None else model
    label = os.fspath(as_path(name, "model (--model)"))
    card = MODEL_CARDS.get(label) if label in SHIPPED[kind] else None
    trained_on = card.trained_on if card is not None else "your own data"
    if kind == "classify":
        classifier, arch = load_run(name, device=device)
        return ClassPredictor(kind, label, classifier, arch, trained_on)
    net, info = load_cloud_model(resolve_model("cloud", name))
    if cloud_model_spec(net).task != "classify":
        raise InputError(
            f"{label} is a part segmentation network: load_predictor gives one class per "
            "cloud; segment with robopercept nn cloud --segment"
        )
    if device is not None:
        net.to(resolve_device(device))
    n = int(info.get("n_points", 1024)) if n_points is None else check_int(n_points, "n_points", 2)
    return ClassPredictor(kind, label, net, info, trained_on, n, seed)
