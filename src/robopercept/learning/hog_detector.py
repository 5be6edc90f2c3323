r"""A sliding-window object detector: HOG features and a linear SVM (Dalal and Triggs).

Training: every example window (faces and non-faces) becomes a HOG descriptor
:math:`h(x)` and a linear SVM learns :math:`f(x) = w \cdot h(x) + b`, positive for the
object. Detection: the image is scanned by a window at every position of a grid
(``stride`` pixels) on every level of an image pyramid (each level ``scale_step``
times smaller, so objects larger than the window are found at a coarser level); every
window with :math:`f > ` ``threshold`` is a candidate box, mapped back to the
original image. Overlapping candidates of one object are then reduced by greedy
non-maximum suppression: the best box is kept and every box overlapping it by more
than ``nms_iou`` (intersection over union) is dropped, repeatedly.

The default ``threshold`` is part of the model: :func:`choose_threshold` picks it on
the precision/recall curve of the SVM score over *held-out* examples, never used in
training (the rule: the highest F1, :math:`F_1 = 2PR / (P + R)`, or the best recall
with precision at least ``min_precision``). The threshold is the midpoint between the
chosen score and the next lower one, since :meth:`HogDetector.detect` keeps scores
strictly above it.

The model (HOG settings, :math:`w`, :math:`b`, the threshold) is saved as an ``.npz``
of plain arrays and a JSON string; loading never unpickles. :func:`train_face_detector`
trains a face model on scikit-image's ``lfw_subset`` (100 faces, 100 non-faces, 25 x 25
pixels) with random and hard negatives from face-free scikit-image pictures, holding
out a quarter of the faces, non-faces and pictures for the threshold;
:func:`train_detector_from_folders` trains one on a folder of object crops and a
folder of pictures without the object.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import (
    check_bool,
    check_choice,
    check_file,
    check_int,
    check_positive,
    check_range,
    check_real,
)
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.features.hog import hog, hog_windows
from robopercept.geometry.boxes import box_iou_matrix, greedy_nms
from robopercept.imaging.color import rgb_to_gray
from robopercept.imaging.io import IMAGE_EXTENSIONS
from robopercept.learning._base import RandomStateLike, random_generator, renamed_rng
from robopercept.learning.persist import read_npz
from robopercept.learning.svm import LinearSVC
from robopercept.progress import progress_bar

__all__ = [
    "IMAGE_SUFFIXES",
    "Detections",
    "HogDetector",
    "ThresholdChoice",
    "choose_threshold",
    "default_face_detector",
    "face_training_data",
    "non_max_suppression",
    "train_detector_from_folders",
    "train_face_detector",
]

#: image files :func:`train_detector_from_folders` reads (other files are ignored)
IMAGE_SUFFIXES = IMAGE_EXTENSIONS

# scikit-image pictures without a human face: hard negatives for the face model
NEGATIVE_PICTURES = ("coffee", "rocket", "coins", "moon", "page", "text", "brick", "grass",
                     "gravel", "hubble_deep_field", "immunohistochemistry", "cell", "chelsea",
                     "clock", "horse", "retina", "checkerboard", "stereo_motorcycle")  # fmt: skip


@dataclass(frozen=True)
class Detections:
    """Boxes ``(x, y, w, h)`` in pixels with their SVM scores, best first."""

    boxes: np.ndarray
    scores: np.ndarray

    def __len__(self) -> int:
        return int(self.scores.size)


def box_iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """Intersection over union of one ``(x, y, w, h)`` box with each of ``boxes``."""
    return box_iou_matrix(box, boxes)[0]


def non_max_suppression(
    boxes: npt.ArrayLike, scores: npt.ArrayLike, iou: float = 0.3
) -> np.ndarray:
    """Indices of the boxes kept by greedy NMS, best score first: a box overlapping a
    better kept box by an IoU above ``iou`` is dropped
    (:func:`robopercept.geometry.boxes.greedy_nms` on ``(x, y, w, h)`` boxes)."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).ravel()
    if boxes.shape[0] != scores.size:
        raise InputError(f"{boxes.shape[0]} boxes but {scores.size} scores")
    return greedy_nms(boxes, scores, iou, fmt="xywh")


def _to_gray(image: np.ndarray) -> np.ndarray:
    # float64 gray; uint8 scaled to [0, 1] (other dtypes keep their scale)
    image = np.asarray(image)
    gray = rgb_to_gray(image, dtype=np.float64)  # validates
    return gray / 255.0 if image.dtype == np.uint8 else gray


def _rescale(image: np.ndarray, scale: float) -> np.ndarray:
    """``image`` resized by ``scale`` < 1 (Gaussian anti-aliasing, then bilinear)."""
    from robopercept.imaging.filters import gaussian_kernel, separable_filter_unchecked
    from robopercept.imaging.warp import warp_perspective

    h, w = image.shape
    size = (max(1, round(w * scale)), max(1, round(h * scale)))  # (width, height)
    sigma = 0.5 * (1.0 / scale - 1.0)
    if sigma > 0.1:  # gaussian_blur(image, sigma, ksize=n) of the image detect() validated
        # n = 2 ceil(3 sigma) + 1 (+-3 sigma), the size the bundled model was trained with;
        # gaussian_kernel's default is now OpenCV's 4-sigma float size (issue 22)
        k = gaussian_kernel(sigma, 2 * int(np.ceil(3.0 * sigma)) + 1)
        src = separable_filter_unchecked(image, k, k, "reflect101")
    else:
        src = image
    # pixel centres map as x' = s (x + 1/2) - 1/2
    H = np.array([[scale, 0, 0.5 * scale - 0.5], [0, scale, 0.5 * scale - 0.5], [0, 0, 1]])
    return warp_perspective(src, H, size)


@dataclass
class HogDetector:
    """HOG + linear SVM sliding-window detector.

    Parameters
    ----------
    window : (width, height)
        Detection window in pixels (as ``cv2.HOGDescriptor``'s ``winSize``); patches
        are ``(N, height, width)``.
    cell_size, block_size, orientations
        HOG settings (OpenCV convention, block stride one cell).
    C : float
        SVM box constraint.
    threshold : float
        Default lowest score of :meth:`detect` (saved with the model; trainers set it
        from a held-out precision/recall curve, :func:`choose_threshold`).
    """

    window: tuple[int, int] = (24, 24)
    cell_size: int = 6
    block_size: int = 2
    orientations: int = 9
    signed: bool = False
    C: float = 0.1
    threshold: float = 0.0
    coef_: np.ndarray | None = field(default=None, repr=False)
    intercept_: float = 0.0

    def _hog_args(self) -> dict[str, Any]:
        return {
            "cell_size": self.cell_size,
            "block_size": self.block_size,
            "block_stride": 1,
            "orientations": self.orientations,
            "signed": self.signed,
        }

    def describe(self, patches: np.ndarray) -> np.ndarray:
        """HOG descriptors of ``(N, h, w)`` window-sized gray patches, ``(N, D)``."""
        patches = np.asarray(patches)
        if patches.ndim != 3 or patches.shape[1:] != tuple(self.window)[::-1]:
            raise InputError(
                f"patches must be (N, {self.window[1]}, {self.window[0]}); got {patches.shape}"
            )
        return np.stack([hog(255.0 * p.astype(np.float32), **self._hog_args()) for p in patches])

    def fit(
        self,
        patches: np.ndarray,
        labels: np.ndarray,
        *,
        random_state: RandomStateLike = 0,
        rng: int | np.random.Generator | None = None,
    ) -> HogDetector:
        """Train the SVM on window-sized patches with labels 1 (object) / 0.

        Parameters
        ----------
        patches : (N, h, w) ndarray
            Window-sized gray patches.
        labels : (N,) array_like
            1 for the object, 0 for background.
        random_state : int, Generator, RandomState or None
            Seed of the SVM's coordinate order (scikit-learn's name).
        rng
            Deprecated alias of ``random_state`` (one release).

        Returns
        -------
        HogDetector
            ``self``, with ``coef_`` and ``intercept_``.
        """
        random_state = renamed_rng("HogDetector.fit", random_state, rng, default=0)
        X = self.describe(patches)
        svm = LinearSVC(C=self.C, random_state=random_state)
        svm.fit(X, np.asarray(labels).astype(int))
        self.coef_ = svm.coef_[0]
        self.intercept_ = float(svm.intercept_[0])
        return self

    def score_patches(self, patches: np.ndarray) -> np.ndarray:
        """SVM scores of window-sized patches."""
        self._need_model()
        return self.describe(patches) @ self.coef_ + self.intercept_

    def _need_model(self) -> None:
        if self.coef_ is None:
            from robopercept.errors import NotFittedError

            raise NotFittedError("the detector has no model: fit it or load one")

    def detect(
        self,
        image: np.ndarray,
        *,
        threshold: float | None = None,
        stride: int | None = None,
        scale_step: float = 1.15,
        min_size: int | None = None,
        max_size: int | None = None,
        nms_iou: float = 0.3,
        progress: bool = False,
    ) -> Detections:
        """Scan an image pyramid; boxes with score > ``threshold`` after NMS.

        Parameters
        ----------
        image : (H, W) or (H, W, 3) ndarray
        threshold : float, optional
            Lowest SVM score kept (strictly above); default the model's
            :attr:`threshold`.
        stride : int
            Window step in pixels at each level: a multiple of the cell size, or a
            divisor of it (then the level is scanned at each sub-cell shift); default
            half a cell.
        scale_step : float
            Ratio between pyramid levels (> 1).
        min_size, max_size : int
            Smallest and largest object size (window width) searched, in pixels;
            ``1 <= min_size <= max_size`` (a size below 1 never grows past ``max_size``
            by ``scale_step``).
        nms_iou : float
            Overlap above which the weaker of two boxes is dropped.
        """
        self._need_model()
        threshold = self.threshold if threshold is None else check_real(threshold, "threshold")
        gray = _to_gray(image)
        if scale_step <= 1.0:
            raise InputError(f"scale_step must be > 1; got {scale_step}")
        check_positive(nms_iou, "nms_iou")
        ww, wh = self.window
        stride = max(1, self.cell_size // 2) if stride is None else int(stride)
        if stride % self.cell_size == 0:  # whole cells: one dense pass per level
            step, offsets = stride, [(0, 0)]
        elif self.cell_size % stride == 0:  # a fraction of a cell: shifted passes
            step = self.cell_size
            shifts = range(0, self.cell_size, stride)
            offsets = [(oy, ox) for oy in shifts for ox in shifts]
        else:
            raise InputError(
                f"stride must divide or be a multiple of the cell size {self.cell_size}; "
                f"got {stride}"
            )
        lo = ww if min_size is None else check_range(min_size, "min_size", 1.0)
        hi = min(gray.shape) if max_size is None else check_range(max_size, "max_size", 1.0)
        sizes = []
        size = float(lo)
        while size <= hi + 1e-9:
            sizes.append(size)
            size *= scale_step
        boxes, scores = [], []
        for size in progress_bar(sizes, desc="hog pyramid", unit="scale", disable=not progress):
            scale = ww / size
            level = gray if abs(scale - 1.0) < 1e-9 else _rescale(gray, scale)
            if level.shape[0] < wh or level.shape[1] < ww:
                continue
            level = 255.0 * level.astype(np.float32)
            for oy, ox in offsets:
                part = level[oy:, ox:]
                if part.shape[0] < wh or part.shape[1] < ww:
                    continue
                s = hog_windows(part, (ww, wh), step, **self._hog_args()) @ self.coef_
                s += self.intercept_
                iy, ix = np.nonzero(s > threshold)
                for i, j in zip(iy, ix, strict=True):
                    x, y = j * step + ox, i * step + oy
                    boxes.append([x / scale, y / scale, ww / scale, wh / scale])
                    scores.append(s[i, j])
        if not boxes:
            return Detections(np.zeros((0, 4)), np.zeros(0))
        boxes_a, scores_a = np.asarray(boxes), np.asarray(scores)
        keep = non_max_suppression(boxes_a, scores_a, nms_iou)
        return Detections(boxes_a[keep], scores_a[keep])

    # -- persistence: plain arrays and JSON, never pickle -----------------------------
    def save(self, path: str | Path) -> None:
        """Write the model as ``.npz`` (weights) with a JSON header (settings)."""
        self._need_model()
        meta = {
            "kind": "robopercept.HogDetector",
            "window": list(self.window),
            "cell_size": self.cell_size,
            "block_size": self.block_size,
            "orientations": self.orientations,
            "signed": self.signed,
            "C": self.C,
            "intercept": self.intercept_,
            "threshold": self.threshold,
        }
        np.savez(path, coef=self.coef_, meta=np.array(json.dumps(meta)))

    @classmethod
    def load(cls, path: str | Path) -> HogDetector:
        """Read a model written by :meth:`save`.

        The file is read by :func:`robopercept.learning.persist.read_npz` (compressed
        members accepted): nothing in it is executed. Any other file (a CSV, a ``.npy``
        array, an archive without the model's arrays) is refused as not a model, without
        NumPy's advice to load pickles unsafely.

        Parameters
        ----------
        path : str or Path
            The ``.npz`` written by :meth:`save` (``robopercept train-hog``).

        Returns
        -------
        HogDetector
            Fitted (``coef_``, ``intercept_`` set).

        Raises
        ------
        FileFormatError
            Missing file, a folder, or not a robopercept HOG model file: a damaged
            archive (whatever zipfile, zlib or NumPy's header parser raise), members
            other than ``.npy`` arrays, no ``coef`` or ``meta`` array, an NPY header
            whose shape does not match its bytes, object arrays (pickles),
            settings out of range (window sides and cells 1 to 2048 px, 1 to 360
            orientations, ``C > 0``, a finite threshold), or weights that are not
            finite or do not fit the settings. The message names the file.
        """
        p = check_file(path, "a model file (.npz written by `robopercept train-hog`)")
        what = "a robopercept HOG model file (.npz written by `robopercept train-hog`)"
        not_model = f"{p} is not {what}"
        arrays = read_npz(p, what, compressed=True)
        for name in ("coef", "meta"):
            if name not in arrays:
                raise FileFormatError(f"{not_model}: it has no {name!r} array")
        coef, meta_array = arrays["coef"], arrays["meta"]
        if meta_array.ndim != 0 or meta_array.dtype.kind != "U":
            raise FileFormatError(f"{not_model}: its meta array is not a JSON string")
        try:
            meta = json.loads(str(meta_array))
        except (ValueError, RecursionError):
            raise FileFormatError(f"{not_model}: its meta array is not valid JSON") from None
        if not isinstance(meta, dict) or meta.get("kind") != "robopercept.HogDetector":
            kind = meta.get("kind") if isinstance(meta, dict) else None
            raise FileFormatError(f"{not_model}: its kind is {kind!r}")
        window = meta.get("window")
        if not (isinstance(window, list) and len(window) == 2):
            raise FileFormatError(f"{p}: window is {window!r}; expected [width, height]")
        det = cls(
            window=(
                _whole(window[0], "window width", 1, _MAX_WINDOW, p),
                _whole(window[1], "window height", 1, _MAX_WINDOW, p),
            ),
            cell_size=_whole(meta.get("cell_size"), "cell_size", 1, _MAX_WINDOW, p),
            block_size=_whole(meta.get("block_size"), "block_size", 1, _MAX_WINDOW, p),
            orientations=_whole(meta.get("orientations"), "orientations", 1, 360, p),
            signed=meta.get("signed", False),
            C=_real(meta.get("C"), "C", p, positive=True),
        )
        if not isinstance(det.signed, bool):
            raise FileFormatError(f"{p}: signed is {det.signed!r}; expected true or false")
        det.intercept_ = _real(meta.get("intercept"), "intercept", p, positive=False)
        # models written before issue 30 have no threshold: 0, their old default
        det.threshold = _real(meta.get("threshold", 0.0), "threshold", p, positive=False)
        if coef.dtype.kind not in "iuf" or not np.isfinite(coef).all():
            raise FileFormatError(f"{p}: the weights (coef) must be finite real numbers")
        det.coef_ = coef.astype(np.float64)
        try:
            expect = det.describe(np.zeros((1, *det.window[::-1]))).shape[1]
        except RoboperceptError as exc:
            raise FileFormatError(f"{p}: its HOG settings do not fit its window: {exc}") from None
        if coef.shape != (expect,):
            raise FileFormatError(f"{p}: weights have shape {coef.shape}, expected ({expect},)")
        return det


_MAX_WINDOW = 2048  # window sides and HOG cells in a model file, in pixels


def _whole(value: Any, name: str, lo: int, hi: int, p: Path) -> int:
    """A whole-number setting of a model file, in ``[lo, hi]``."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise FileFormatError(
            f"{p}: {name} is {value!r}; expected a whole number from {lo} to {hi} "
            "(retrain the model with `robopercept train-hog`)"
        )
    return value


def _real(value: Any, name: str, p: Path, positive: bool) -> float:
    """A real-number setting of a model file: finite (and > 0 if ``positive``)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or (positive and value <= 0)
    ):
        want = "a finite number > 0" if positive else "a finite number"
        raise FileFormatError(
            f"{p}: {name} is {value!r}; expected {want} "
            "(retrain the model with `robopercept train-hog`)"
        )
    return float(value)


FACE_MODEL = "face_hog_svm.npz"


def default_face_detector() -> HogDetector:
    """The bundled face model (trained by :func:`train_face_detector` with its defaults;
    ``robopercept train-hog`` rebuilds it)."""
    from importlib import resources

    return HogDetector.load(Path(str(resources.files("robopercept") / "data" / FACE_MODEL)))


def face_training_data() -> tuple[np.ndarray, np.ndarray]:
    """scikit-image's ``lfw_subset``: ``(200, 24, 24)`` patches (top-left crop of the
    25 x 25 images) and labels (the first 100 are faces). Needs scikit-image."""
    images = _lfw_subset()[:, :24, :24]
    labels = np.r_[np.ones(100, dtype=int), np.zeros(100, dtype=int)]
    return images, labels


def _lfw_subset() -> np.ndarray:
    """The 200 25 x 25 ``lfw_subset`` images (scikit-image's bundled data)."""
    try:
        from skimage import data
    except ImportError:
        raise InputError(
            "training the face model needs scikit-image: pip install scikit-image"
        ) from None
    return data.lfw_subset()


def _negative_pictures(names: tuple[str, ...] | list[str] = NEGATIVE_PICTURES) -> list[np.ndarray]:
    """The gray scikit-image pictures ``names`` (both views of the stereo pair)."""
    from skimage import data

    pictures = []
    for name in names:
        picture = getattr(data, name)()
        if isinstance(picture, np.ndarray) and picture.dtype == np.bool_:  # the horse
            picture = picture.astype(np.float64)
        if isinstance(picture, tuple):  # a stereo pair and its disparity: both views
            pictures.extend(_to_gray(p) for p in picture[:2])
        else:
            pictures.append(_to_gray(picture))
    return pictures


def _jitter_faces(faces: np.ndarray) -> np.ndarray:
    """Each 25 x 25 face zoomed by 1.12, and turned by +-8 degrees (zoomed by 1.15 so no
    corner leaves the picture), as 24 x 24 patches."""
    from robopercept.imaging.warp import warp_perspective

    out = []
    for angle, zoom in ((0.0, 1.12), (8.0, 1.15), (-8.0, 1.15)):
        a = np.deg2rad(angle)
        R = zoom * np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        # input centre (12, 12) maps to output centre (11.5, 11.5)
        H = np.eye(3)
        H[:2, :2] = R
        H[:2, 2] = np.array([11.5, 11.5]) - R @ np.array([12.0, 12.0])
        out.extend(warp_perspective(f, H, (24, 24)) for f in faces)
    return np.stack(out)


@dataclass(frozen=True)
class ThresholdChoice:
    """A threshold picked on a precision/recall curve (:func:`choose_threshold`).

    Attributes
    ----------
    threshold : float
        Keep scores strictly above this: the midpoint between the chosen score and the
        next lower score of the examples.
    score : float
        The chosen point's score (scores ``>= score`` are positive there).
    precision, recall, f1 : float
        At that point.
    rule : str
        ``"f1"`` or ``"precision"``.
    min_precision : float
        The precision floor of rule ``"precision"``.
    curve_precision, curve_recall : (K + 1,) ndarray
        The whole curve (:func:`robopercept.learning.metrics.precision_recall_curve`).
    curve_thresholds : (K,) ndarray
        Its scores, ascending.
    n_positive, n_negative : int
        Examples of each class.
    """

    threshold: float
    score: float
    precision: float
    recall: float
    f1: float
    rule: str
    min_precision: float
    curve_precision: np.ndarray = field(repr=False)
    curve_recall: np.ndarray = field(repr=False)
    curve_thresholds: np.ndarray = field(repr=False)
    n_positive: int = 0
    n_negative: int = 0


THRESHOLD_RULES = ("f1", "precision")


def choose_threshold(
    labels: npt.ArrayLike,
    scores: npt.ArrayLike,
    *,
    rule: str = "f1",
    min_precision: float = 0.95,
) -> ThresholdChoice:
    r"""Pick a score threshold on the precision/recall curve of held-out examples.

    At each distinct score :math:`t` (ascending) the examples with score
    :math:`\ge t` are called positive: precision :math:`P(t) = TP / (TP + FP)`, recall
    :math:`R(t) = TP / (TP + FN)` (scikit-learn's ``precision_recall_curve``).
    Rule ``"f1"`` takes the point of highest :math:`F_1 = 2PR / (P + R)` (on a tie, the
    lower score: more recall); rule ``"precision"`` takes the point of highest recall
    among those with :math:`P \ge` ``min_precision`` (the lowest such score, since
    recall only falls as :math:`t` grows). The returned ``threshold`` is the midpoint
    between that score and the next lower one, so that "score > threshold" (as
    :meth:`HogDetector.detect` keeps boxes) selects exactly the same examples, with a
    margin on both sides.

    Parameters
    ----------
    labels : (N,) array_like
        1 (or True) for the object, 0 for background; both must occur.
    scores : (N,) array_like
        Finite scores, higher meaning more likely the object.
    rule : {"f1", "precision"}
    min_precision : float
        In (0, 1]; used by rule ``"precision"``.

    Returns
    -------
    ThresholdChoice

    Raises
    ------
    InputError
        Lengths differ, labels not 0/1, a class absent, non-finite scores, a bad rule or
        ``min_precision``.
    DegenerateError
        Rule ``"precision"`` and no point of the curve reaches ``min_precision``.

    Examples
    --------
    Five faces and five non-faces; the best F1 (0.909) keeps the scores >= 0.6 (all
    five faces and the non-face at 0.7); precision >= 0.95 needs scores >= 0.8 (four
    faces, none of the non-faces):

    >>> labels = [1, 1, 1, 1, 1, 0, 0, 0, 0, 0]
    >>> scores = [2.0, 1.5, 1.0, 0.8, 0.6, 0.7, 0.3, 0.1, -0.5, -1.0]
    >>> c = choose_threshold(labels, scores)
    >>> round(c.threshold, 3), round(c.precision, 3), c.recall, round(c.f1, 3)
    (0.45, 0.833, 1.0, 0.909)
    >>> c = choose_threshold(labels, scores, rule="precision", min_precision=0.95)
    >>> round(c.threshold, 3), c.precision, c.recall
    (0.75, 1.0, 0.8)
    """
    from robopercept.errors import DegenerateError
    from robopercept.learning.metrics import precision_recall_curve

    rule = check_choice(rule, "rule", THRESHOLD_RULES)
    min_precision = check_real(min_precision, "min_precision", 0.0, 1.0, low_inclusive=False)
    y = np.asarray(labels)
    s = np.asarray(scores)
    if y.ndim != 1 or s.ndim != 1 or y.size != s.size:
        raise InputError(
            f"labels and scores must be 1-D of one length; got shapes {y.shape} and {s.shape}"
        )
    if y.dtype.kind not in "biuf" or not np.isin(y, (0, 1)).all():
        raise InputError("labels must be 0 (background) or 1 (object)")
    if s.dtype.kind not in "iuf" or not np.isfinite(s).all():
        raise InputError("scores must be finite real numbers")
    y = y.astype(np.int64)
    if y.min(initial=1) != 0 or y.max(initial=0) != 1:
        raise InputError(
            f"labels must hold both classes (held-out objects and background); got "
            f"{int(y.sum())} positive(s) of {y.size}"
        )
    s = s.astype(np.float64)
    precision, recall, thresholds = precision_recall_curve(y, s)
    p, r = precision[:-1], recall[:-1]
    f1 = np.where(p + r > 0, 2 * p * r / np.maximum(p + r, 1e-300), 0.0)
    if rule == "f1":
        k = int(np.argmax(f1))
    else:
        ok = np.flatnonzero(p >= min_precision)
        if ok.size == 0:
            raise DegenerateError(
                f"no threshold reaches precision {min_precision} on these examples (best "
                f"{p.max():.3f}): lower min_precision, or use rule='f1'"
            )
        k = int(ok[0])
    chosen = float(thresholds[k])
    lower = s[s < chosen]
    threshold = 0.5 * (chosen + float(lower.max())) if lower.size else np.nextafter(chosen, -np.inf)
    return ThresholdChoice(
        threshold=float(threshold),
        score=chosen,
        precision=float(p[k]),
        recall=float(r[k]),
        f1=float(f1[k]),
        rule=rule,
        min_precision=min_precision,
        curve_precision=precision,
        curve_recall=recall,
        curve_thresholds=thresholds,
        n_positive=int(y.sum()),
        n_negative=int(y.size - y.sum()),
    )


def _resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` (2-D float) resized to ``size`` = (width, height): Gaussian
    anti-aliasing along each axis that shrinks, then bilinear."""
    from robopercept.imaging.filters import gaussian_kernel, separable_filter_unchecked
    from robopercept.imaging.warp import warp_perspective

    h, w = image.shape
    sx, sy = size[0] / w, size[1] / h
    kx, ky = (
        gaussian_kernel(sig, 2 * int(np.ceil(3.0 * sig)) + 1) if sig > 0.1 else np.ones(1)
        for sig in (0.5 * (1.0 / sx - 1.0), 0.5 * (1.0 / sy - 1.0))
    )
    src = (
        image
        if kx.size == ky.size == 1
        else separable_filter_unchecked(image, kx, ky, "reflect101")
    )
    H = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1]])
    return warp_perspective(src, H, size)


def _random_windows(
    pictures: list[np.ndarray], window: tuple[int, int], per_picture: int, gen: np.random.Generator
) -> list[np.ndarray]:
    """``per_picture`` random windows of random sizes (from the window to half the
    picture) of each picture, resized to ``window``."""
    ww, wh = window
    out = []
    for pic in pictures:
        top = min(pic.shape[1] / ww, pic.shape[0] / wh) / 2  # largest zoom: half the picture
        if top <= 1.0:
            if pic.shape[1] >= ww and pic.shape[0] >= wh:
                out.append(pic[:wh, :ww])
            continue
        for _ in range(per_picture):
            z = float(gen.uniform(1.0, top))
            cw, ch = round(ww * z), round(wh * z)
            y0 = int(gen.integers(0, pic.shape[0] - ch + 1))
            x0 = int(gen.integers(0, pic.shape[1] - cw + 1))
            out.append(_resize(pic[y0 : y0 + ch, x0 : x0 + cw], window))
    return out


def _fit_and_mine(
    det: HogDetector,
    pos: np.ndarray,
    neg: np.ndarray,
    pictures: list[np.ndarray],
    *,
    rounds: int,
    hard_per_picture: int,
    max_hard: int,
    seed: Any,
    progress: bool,
) -> HogDetector:
    """Fit on ``pos`` and ``neg``, then ``rounds`` of hard-negative mining on
    ``pictures`` (the best windows above -0.5 of each, at most ``max_hard`` a round)."""
    ww, wh = det.window
    det.fit(np.r_[pos, neg], np.r_[np.ones(len(pos)), np.zeros(len(neg))], random_state=seed)
    for _ in progress_bar(range(rounds), desc="hard negatives", unit="round", disable=not progress):
        hard = []
        for pic in pictures:
            found = det.detect(pic, threshold=-0.5, stride=det.cell_size, nms_iou=0.5, max_size=200)
            for x, y, w, h in found.boxes[:hard_per_picture]:
                x0, y0, x1, y1 = int(x), int(y), round(float(x + w)), round(float(y + h))
                crop = pic[y0:y1, x0:x1]
                if min(crop.shape) < 8:
                    continue
                hard.append(_rescale(crop, ww / crop.shape[1])[:wh, :ww])
        hard = [h for h in hard if h.shape == (wh, ww)][:max_hard]
        if not hard:
            break
        neg = np.r_[neg, np.stack(hard)]
        det.fit(np.r_[pos, neg], np.r_[np.ones(len(pos)), np.zeros(len(neg))], random_state=seed)
    return det


#: held-out background windows per picture: the best boxes ``detect`` reports above -1
HELDOUT_PER_PICTURE = 60


def _heldout_scores(
    det: HogDetector, pos: np.ndarray, neg: np.ndarray, pictures: list[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Labels and scores of the held-out examples: the object patches ``pos``, the
    background patches ``neg``, and the boxes ``detect`` reports on the held-out
    background ``pictures`` (default stride and NMS, scores above -1, the best
    :data:`HELDOUT_PER_PICTURE` of each): the false positives it would show."""
    parts = [det.score_patches(pos)] if len(pos) else []
    labels = [np.ones(len(pos))]
    if len(neg):
        parts.append(det.score_patches(neg))
        labels.append(np.zeros(len(neg)))
    for pic in pictures:
        found = det.detect(pic, threshold=-1.0, max_size=200)
        parts.append(found.scores[:HELDOUT_PER_PICTURE])
        labels.append(np.zeros(len(parts[-1])))
    return np.concatenate(labels), np.concatenate(parts)


def _split(n: int, holdout: float, gen: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(train, held-out) index arrays of ``n`` items: ``round(holdout * n)`` held out
    (at least one when ``holdout > 0``), chosen by ``gen``."""
    k = 0 if holdout == 0 else min(n - 1, max(1, round(holdout * n)))
    order = gen.permutation(n)
    return np.sort(order[k:]), np.sort(order[:k])


def train_face_detector(
    *,
    mining_rounds: int = 4,
    C: float = 1.0,
    cell_size: int = 6,
    orientations: int = 18,
    signed: bool = True,
    hard_per_picture: int = 60,
    max_hard: int = 600,
    augment: bool = True,
    holdout: float = 0.25,
    rule: str = "f1",
    min_precision: float = 0.95,
    random_state: RandomStateLike = 0,
    progress: bool = False,
    rng: int | np.random.Generator | None = None,
) -> tuple[HogDetector, dict[str, Any]]:
    """Train the face model: ``lfw_subset`` faces (jittered, mirrored) plus hard negatives,
    with its default threshold from a held-out precision/recall curve.

    Held out first (``holdout`` of each, drawn by ``random_state``, never used in
    training): lfw faces, lfw non-faces and face-free pictures
    (:data:`NEGATIVE_PICTURES`; the stereo pair counts as one). Positives: the four
    24 x 24 crops of each training face, with ``augment`` also the face zoomed and
    turned by +-8 degrees, all mirrored too. Negatives: the training non-faces
    (mirrored) and 40 random windows of each training picture. Each of
    ``mining_rounds`` then runs the detector over the training pictures, adds the
    ``hard_per_picture`` best windows scoring above -0.5 of each (at most ``max_hard`` a
    round) to the non-faces, and retrains.

    The threshold (:attr:`HogDetector.threshold`) is then :func:`choose_threshold` with
    ``rule`` over the held-out examples: the four crops of each held-out face and their
    mirror images (positives); the held-out non-faces likewise, and the boxes the
    detector reports on the held-out pictures (negatives: see ``_heldout_scores``).

    The defaults are the shipped model's (:func:`default_face_detector`). Signed
    gradients (18 bins over 360 degrees) tell a face, darker eyes and mouth on lighter
    skin, from round textured things better than unsigned ones; with unsigned 9-bin
    HOG a mission patch on ``astronaut`` outscored the face.

    ``random_state`` (scikit-learn's name; ``rng=`` is its deprecated alias for one
    release) seeds the split, the folds, the random negative windows and the SVM.

    Returns
    -------
    HogDetector, dict
        The detector, and a report: ``accuracy``, ``precision``, ``recall`` (5-fold
        cross-validated, of the SVM on the training part of ``lfw_subset`` alone, before
        mining), ``threshold``, ``heldout_precision``, ``heldout_recall``,
        ``heldout_f1``, ``heldout_positives``, ``heldout_negatives`` and ``choice`` (the
        :class:`ThresholdChoice`, with the curve), or ``choice`` None and the threshold
        0 when ``holdout`` is 0.
    """
    seed = renamed_rng("train_face_detector", random_state, rng, default=0)
    from robopercept.learning.metrics import precision_score, recall_score
    from robopercept.learning.model_selection import StratifiedKFold

    holdout = check_real(holdout, "holdout", 0.0, 0.5)
    rule = check_choice(rule, "rule", THRESHOLD_RULES)
    gen = random_generator(seed)
    full = _lfw_subset()
    face_train, face_held = _split(100, holdout, gen)
    other_train, other_held = _split(100, holdout, gen)
    names = list(NEGATIVE_PICTURES)
    pic_train, pic_held = _split(len(names), holdout, gen)
    train_idx = np.r_[face_train, 100 + other_train]
    patches = full[train_idx, :24, :24]
    labels = np.r_[np.ones(face_train.size, dtype=int), np.zeros(other_train.size, dtype=int)]
    det = HogDetector(C=C, cell_size=cell_size, orientations=orientations, signed=signed)
    X = det.describe(patches)
    preds = np.empty_like(labels)
    for train, test in StratifiedKFold(5, shuffle=True, random_state=seed).split(X, labels):
        svm = LinearSVC(C=det.C, random_state=seed).fit(X[train], labels[train])
        preds[test] = svm.predict(X[test])
    report: dict[str, Any] = {
        "accuracy": float(np.mean(preds == labels)),
        "precision": float(precision_score(labels, preds)),
        "recall": float(recall_score(labels, preds)),
    }
    faces_full = full[face_train]
    faces = _four_crops(faces_full)
    if augment:
        faces = np.r_[faces, _jitter_faces(faces_full)]
    pos = np.r_[faces, faces[:, :, ::-1]]
    others = full[100 + other_train, :24, :24]
    neg = np.r_[others, others[:, :, ::-1]]
    pictures = _negative_pictures([names[i] for i in pic_train])
    neg = np.r_[neg, np.stack(_random_windows(pictures, (24, 24), 40, gen))]
    _fit_and_mine(
        det, pos, neg, pictures, rounds=mining_rounds, hard_per_picture=hard_per_picture,
        max_hard=max_hard, seed=seed, progress=progress,
    )  # fmt: skip
    if face_held.size == 0:
        report.update(threshold=det.threshold, choice=None)
        return det, report
    held_pos = _four_crops(full[face_held])
    held_neg = _four_crops(full[100 + other_held])
    y, scores = _heldout_scores(
        det,
        np.r_[held_pos, held_pos[:, :, ::-1]],
        np.r_[held_neg, held_neg[:, :, ::-1]],
        _negative_pictures([names[i] for i in pic_held]),
    )
    choice = choose_threshold(y, scores, rule=rule, min_precision=min_precision)
    det.threshold = choice.threshold
    report.update(_choice_report(choice))
    return det, report


def _choice_report(choice: ThresholdChoice) -> dict[str, Any]:
    return {
        "threshold": choice.threshold,
        "heldout_precision": choice.precision,
        "heldout_recall": choice.recall,
        "heldout_f1": choice.f1,
        "heldout_positives": choice.n_positive,
        "heldout_negatives": choice.n_negative,
        "choice": choice,
    }


def _four_crops(images: np.ndarray) -> np.ndarray:
    """The four 24 x 24 crops of each 25 x 25 image."""
    return np.concatenate([images[:, dy : dy + 24, dx : dx + 24] for dy in (0, 1) for dx in (0, 1)])


def _read_folder(folder: str | Path, what: str) -> tuple[list[np.ndarray], list[str], Path]:
    """The gray float images of ``folder`` (sorted by name; hidden files and
    sub-folders ignored) and the ``"name: reason"`` of each file that could not be read."""
    p = Path(folder)
    if not p.is_dir():
        raise InputError(
            f"{what} folder {p} does not exist or is not a folder: give a folder of images"
        )
    images, skipped = [], []
    for f in sorted(q for q in p.iterdir() if q.is_file() and not q.name.startswith(".")):
        try:
            from robopercept.imaging import read_image

            image = read_image(f, mode="gray")
        except (RoboperceptError, OSError, ValueError) as exc:
            why = (str(exc).splitlines() or [type(exc).__name__])[0].replace(f"{f}: ", "")
            skipped.append(f"{f.name}: {why}")
            continue
        images.append(image.astype(np.float64) / (65535.0 if image.dtype == np.uint16 else 255.0))
    if not images:
        extra = f" ({len(skipped)} unreadable, first {skipped[0]})" if skipped else ""
        raise InputError(f"{what} folder {p} holds no readable image{extra}: add images to it")
    return images, skipped, p


def train_detector_from_folders(
    positives: str | Path,
    negatives: str | Path,
    *,
    window: tuple[int, int] = (24, 24),
    cell_size: int = 6,
    orientations: int = 18,
    signed: bool = True,
    C: float = 1.0,
    mirror: bool = True,
    windows_per_picture: int = 40,
    mining_rounds: int = 2,
    hard_per_picture: int = 60,
    max_hard: int = 600,
    holdout: float = 0.25,
    rule: str = "f1",
    min_precision: float = 0.95,
    random_state: RandomStateLike = 0,
    progress: bool = False,
) -> tuple[HogDetector, dict[str, Any]]:
    """Train a HOG + linear SVM detector on a folder of object crops and a folder of
    pictures without the object (``robopercept train-hog --positives --negatives``).

    Every readable image of ``positives`` is one example, resized to ``window`` (as a
    whole: crop them to the object first) and, with ``mirror``, flipped left-right too.
    From each picture of ``negatives`` (any size; it must not show the object)
    ``windows_per_picture`` random windows are cut (sizes from the window to half the
    picture, resized to the window), then ``mining_rounds`` of hard-negative mining
    add the windows the detector wrongly scores above -0.5. Files that cannot be read
    are skipped and listed in the report. ``holdout`` of the positives and of the
    negative pictures (at least one of each) are set aside, never trained on, and the
    default threshold is :func:`choose_threshold` with ``rule`` on them (the held-out
    crops and their mirrors against random windows of the held-out pictures and the
    boxes the detector reports on them).

    Parameters
    ----------
    positives, negatives : str or Path
        Folders of images (PNG, JPEG, TIFF, BMP, PNM; colour read as gray).
    window : (width, height)
        Detection window in pixels (multiples of ``cell_size``).
    cell_size, orientations, signed, C
        HOG and SVM settings (:class:`HogDetector`).
    mirror : bool
        Also train on the positives flipped left-right.
    windows_per_picture, mining_rounds, hard_per_picture, max_hard : int
        Negative sampling and mining (as :func:`train_face_detector`).
    holdout : float
        Share held out for the threshold, in [0, 0.5]; 0 trains on everything and
        leaves the threshold at 0.
    rule, min_precision
        :func:`choose_threshold`'s.
    random_state : int, Generator, RandomState or None
        Seeds the split, the windows and the SVM.
    progress : bool
        Show progress on stderr.

    Returns
    -------
    HogDetector, dict
        The detector (threshold set) and a report: ``positives``, ``negatives``
        (images read), ``skipped`` (``"folder/name: reason"`` of each unreadable
        file), ``train_positives``, ``train_negatives`` (examples of the last fit),
        ``threshold``, ``heldout_precision``, ``heldout_recall``, ``heldout_f1``,
        ``heldout_positives``, ``heldout_negatives`` and ``choice``
        (:class:`ThresholdChoice`; None when ``holdout`` is 0).

    Raises
    ------
    InputError
        A folder missing or without a readable image; too few images to hold one of
        each out (2 positives and 2 negative pictures); a bad setting.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> from robopercept.imaging import write_image
    >>> gen = np.random.default_rng(0)
    >>> yy, xx = np.mgrid[:24, :24]
    >>> disc = ((yy - 11.5) ** 2 + (xx - 11.5) ** 2 < 64).astype(float)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     pos, neg = Path(d, "pos"), Path(d, "neg")
    ...     pos.mkdir(); neg.mkdir()
    ...     for i in range(8):
    ...         img = np.clip(0.2 + 0.6 * disc + gen.normal(0, 0.05, (24, 24)), 0, 1)
    ...         _ = write_image(pos / f"{i}.png", (255 * img).astype(np.uint8))
    ...         _ = write_image(neg / f"{i}.png", gen.integers(0, 255, (60, 80), np.uint8))
    ...     det, report = train_detector_from_folders(pos, neg, mining_rounds=0)
    >>> report["positives"], report["negatives"], report["skipped"]
    (8, 8, [])
    """
    seed = random_state
    window = (check_int(window[0], "window width", 1), check_int(window[1], "window height", 1))
    cell_size = check_int(cell_size, "cell_size", 1)
    if window[0] % cell_size or window[1] % cell_size:
        raise InputError(f"window {window} must be whole cells of {cell_size} px")
    holdout = check_real(holdout, "holdout", 0.0, 0.5)
    rule = check_choice(rule, "rule", THRESHOLD_RULES)
    mirror = check_bool(mirror, "mirror")
    windows_per_picture = check_int(windows_per_picture, "windows_per_picture", 1)
    mining_rounds = check_int(mining_rounds, "mining_rounds", 0)
    pos_images, pos_skipped, pos_dir = _read_folder(positives, "positives")
    neg_images, neg_skipped, neg_dir = _read_folder(negatives, "negatives")
    if holdout > 0 and (len(pos_images) < 2 or len(neg_images) < 2):
        raise InputError(
            f"holding out a share for the threshold needs at least 2 positives and 2 "
            f"negative pictures; got {len(pos_images)} and {len(neg_images)}: add images, "
            "or pass holdout=0 (--holdout 0: no threshold is chosen)"
        )
    gen = random_generator(seed)
    det = HogDetector(
        window=window, cell_size=cell_size, orientations=orientations, signed=signed, C=C
    )
    det.describe(np.zeros((1, window[1], window[0])))  # checks the HOG settings early
    crops = np.stack([_resize(im, window) for im in pos_images])
    p_train, p_held = _split(len(crops), holdout, gen)
    n_train, n_held = _split(len(neg_images), holdout, gen)
    pos = crops[p_train]
    if mirror:
        pos = np.r_[pos, pos[:, :, ::-1]]
    pictures = [neg_images[i] for i in n_train]
    randoms = _random_windows(pictures, window, windows_per_picture, gen)
    if not randoms:
        raise InputError(
            f"the negative pictures in {neg_dir} are all smaller than the window "
            f"{window[0]}x{window[1]}: give larger pictures"
        )
    neg = np.stack(randoms)
    _fit_and_mine(
        det, pos, neg, pictures, rounds=mining_rounds, hard_per_picture=hard_per_picture,
        max_hard=max_hard, seed=seed, progress=progress,
    )  # fmt: skip
    report: dict[str, Any] = {
        "positives": len(pos_images),
        "negatives": len(neg_images),
        "skipped": [f"{pos_dir.name}/{s}" for s in pos_skipped]
        + [f"{neg_dir.name}/{s}" for s in neg_skipped],
        "train_positives": len(pos),
        "train_negatives": len(neg),
    }
    if p_held.size == 0:
        report.update(threshold=det.threshold, choice=None)
        return det, report
    held = crops[p_held]
    if mirror:
        held = np.r_[held, held[:, :, ::-1]]
    held_pictures = [neg_images[i] for i in n_held]
    held_windows = _random_windows(held_pictures, window, windows_per_picture, gen)
    held_neg = np.stack(held_windows) if held_windows else np.zeros((0, *held.shape[1:]))
    y, scores = _heldout_scores(det, held, held_neg, held_pictures)
    choice = choose_threshold(y, scores, rule=rule, min_precision=min_precision)
    det.threshold = choice.threshold
    report.update(_choice_report(choice))
    return det, report
