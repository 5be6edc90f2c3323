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

The model (HOG settings, :math:`w`, :math:`b`) is saved as an ``.npz`` of plain arrays
and a JSON string; loading never unpickles. :func:`train_face_detector` trains a face
model on scikit-image's ``lfw_subset`` (100 faces, 100 non-faces, 25 x 25 pixels) with
random and hard negatives from face-free scikit-image pictures.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_file, check_positive, check_range
from robopercept.errors import FileFormatError, InputError, RoboperceptError
from robopercept.features.hog import hog, hog_windows
from robopercept.geometry.boxes import box_iou_matrix
from robopercept.imaging.color import rgb_to_gray
from robopercept.learning._base import RandomStateLike, random_generator, renamed_rng
from robopercept.learning.svm import LinearSVC
from robopercept.progress import progress_bar

__all__ = [
    "Detections",
    "HogDetector",
    "default_face_detector",
    "face_training_data",
    "non_max_suppression",
    "train_face_detector",
]

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
    """Indices of the boxes kept by greedy NMS, best score first."""
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).ravel()
    if boxes.shape[0] != scores.size:
        raise InputError(f"{boxes.shape[0]} boxes but {scores.size} scores")
    order = np.argsort(-scores, kind="stable")
    keep = []
    while order.size:
        best = order[0]
        keep.append(best)
        rest = order[1:]
        order = rest[box_iou(boxes[best], boxes[rest]) <= iou]
    return np.asarray(keep, dtype=np.int64)


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
    """

    window: tuple[int, int] = (24, 24)
    cell_size: int = 6
    block_size: int = 2
    orientations: int = 9
    signed: bool = False
    C: float = 0.1
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
        threshold: float = 0.0,
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
        threshold : float
            Lowest SVM score kept.
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
        for size in progress_bar(sizes, desc="hog pyramid", disable=not progress):
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
        }
        np.savez(path, coef=self.coef_, meta=np.array(json.dumps(meta)))

    @classmethod
    def load(cls, path: str | Path) -> HogDetector:
        """Read a model written by :meth:`save`.

        The file is read with ``allow_pickle=False``: nothing in it is executed. Any
        other file (a CSV, a ``.npy`` array, an archive without the model's arrays) is
        refused as not a model, without NumPy's advice to load pickles unsafely.

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
            archive (whatever zipfile, zlib or NumPy's header parser raise), an NPY
            header whose shape does not match its bytes, object arrays (pickles),
            settings out of range (window sides and cells 1 to 2048 px, 1 to 360
            orientations, ``C > 0``), or weights that are not finite or do not fit
            the settings. The message names the file.
        """
        p = check_file(path, "a model file (.npz written by `robopercept train-hog`)")
        not_model = (
            f"{p} is not a robopercept HOG model file (.npz written by `robopercept train-hog`)"
        )
        arrays = _read_npz(p, ("coef", "meta"), not_model)
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
_MAX_MEMBER = 256 * 2**20  # bytes an array of a model file may unpack to


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


def _read_npz(p: Path, names: tuple[str, ...], not_model: str) -> dict[str, np.ndarray]:
    """The arrays ``names`` of the ``.npz`` archive ``p``, read without pickles and
    without trusting a length or shape the file states.

    Each member ``name.npy`` is unpacked (at most :data:`_MAX_MEMBER` bytes; the zip
    CRC is checked), its NPY header parsed, and the array built with
    ``np.frombuffer`` only when ``prod(shape) * itemsize`` equals the bytes that follow
    the header; object dtypes (pickles) are refused. This is ``np.load(p,
    allow_pickle=False)[name]`` for a sound file, and a :class:`FileFormatError` for
    any damaged one.
    """
    try:
        with p.open("rb") as f:
            head = f.read(6)
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot read the model file ({exc})") from None
    if head == b"\x93NUMPY":
        raise FileFormatError(f"{not_model}: it holds one array, not an archive")
    arrays: dict[str, np.ndarray] = {}
    try:
        size = p.stat().st_size
        with zipfile.ZipFile(p) as z:
            members = {i.filename: i for i in z.infolist()}
            for name in names:
                info = members.get(f"{name}.npy")
                if info is None:
                    raise FileFormatError(f"{not_model}: it has no {name!r} array")
                if info.file_size > _MAX_MEMBER or info.compress_size > size:
                    raise FileFormatError(
                        f"{not_model}: its {name!r} array claims {info.file_size} bytes "
                        f"({info.compress_size} stored) in a {size}-byte file"
                    )
                arrays[name] = _npy_from_bytes(_read_member(z, info), name, not_model)
    except FileFormatError:
        raise
    except Exception as exc:
        # untrusted bytes through zipfile, zlib/bz2/lzma and NumPy's header parser,
        # which raise BadZipFile, zlib.error, EOFError, NotImplementedError (an unknown
        # compression), RuntimeError (encryption), tokenize.TokenError, ValueError,
        # MemoryError...: every one of them means a damaged or foreign file
        raise FileFormatError(f"{not_model} ({type(exc).__name__}: {exc})") from None
    return arrays


def _read_member(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> bytes:
    """The unpacked bytes of ``info``, read in 1 MiB pieces: ``ZipFile.read`` asks the
    file for the whole stated compressed size at once, and Python allocates that much
    before the read comes back short (a 2 GiB length word cost 1 GiB on a 6 kB file)."""
    out = bytearray()
    with z.open(info) as f:
        while piece := f.read(1 << 20):
            out += piece
            if len(out) > info.file_size:
                break  # zipfile's CRC/size check raises at the end of a sound stream
    return bytes(out)


def _npy_from_bytes(raw: bytes, name: str, not_model: str) -> np.ndarray:
    """An array from the bytes of an ``.npy`` file (format 1.0 or 2.0), checked
    against its header; object dtypes (pickles) are refused, never loaded."""
    from numpy.lib import format as npy

    f = io.BytesIO(raw)
    version = npy.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = npy.read_array_header_1_0(f)
    elif version == (2, 0):
        shape, fortran, dtype = npy.read_array_header_2_0(f)
    else:
        raise FileFormatError(f"{not_model}: its {name!r} array has NPY version {version}")
    if dtype.hasobject:
        raise FileFormatError(
            f"{not_model}: its {name!r} array holds Python objects (pickles), which are "
            "never loaded"
        )
    count = math.prod(shape)
    if count * dtype.itemsize != len(raw) - f.tell():
        raise FileFormatError(
            f"{not_model}: its {name!r} array header says {count} x {dtype.itemsize} "
            f"bytes; {len(raw) - f.tell()} follow"
        )
    data = np.frombuffer(raw, dtype=dtype, count=count, offset=f.tell())
    return data.reshape(shape, order="F" if fortran else "C").copy()


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


def _negative_pictures() -> list[np.ndarray]:
    from skimage import data

    pictures = []
    for name in NEGATIVE_PICTURES:
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
    random_state: RandomStateLike = 0,
    progress: bool = False,
    rng: int | np.random.Generator | None = None,
) -> tuple[HogDetector, dict[str, float]]:
    """Train the face model: ``lfw_subset`` faces (jittered, mirrored) plus hard negatives.

    Positives: the four 24 x 24 crops of each 25 x 25 face, with ``augment`` also the
    face zoomed and turned by +-8 degrees, all mirrored too. Negatives: the 100
    non-faces (mirrored) and random windows of the face-free scikit-image pictures
    (:data:`NEGATIVE_PICTURES`). Each of ``mining_rounds`` then runs the detector over
    those pictures and adds the ``hard_per_picture`` best windows scoring above -0.5 of
    each (at most ``max_hard`` a round) to the non-faces, and retrains.

    The defaults are the shipped model's (:func:`default_face_detector`). Signed
    gradients (18 bins over 360 degrees) tell a face, darker eyes and mouth on lighter
    skin, from round textured things better than unsigned ones; with unsigned 9-bin
    HOG a mission patch on ``astronaut`` outscored the face.

    ``random_state`` (scikit-learn's name; ``rng=`` is its deprecated alias for one
    release) seeds the folds, the random negative windows and the SVM.

    Returns
    -------
    HogDetector, dict
        The detector and the 5-fold cross-validated accuracy, precision and recall of
        the SVM on ``lfw_subset`` alone (before mining).
    """
    seed = renamed_rng("train_face_detector", random_state, rng, default=0)
    from robopercept.learning.metrics import precision_score, recall_score
    from robopercept.learning.model_selection import StratifiedKFold

    full = _lfw_subset()
    patches = full[:, :24, :24]
    labels = np.r_[np.ones(100, dtype=int), np.zeros(100, dtype=int)]
    det = HogDetector(C=C, cell_size=cell_size, orientations=orientations, signed=signed)
    X = det.describe(patches)
    preds = np.empty_like(labels)
    for train, test in StratifiedKFold(5, shuffle=True, random_state=seed).split(X, labels):
        svm = LinearSVC(C=det.C, random_state=seed).fit(X[train], labels[train])
        preds[test] = svm.predict(X[test])
    cv = {
        "accuracy": float(np.mean(preds == labels)),
        "precision": float(precision_score(labels, preds)),
        "recall": float(recall_score(labels, preds)),
    }
    # positives: the four 24 x 24 crops of each 25 x 25 face, and their mirror images
    faces = np.concatenate(
        [full[:100, dy : dy + 24, dx : dx + 24] for dy in (0, 1) for dx in (0, 1)]
    )
    if augment:
        faces = np.r_[faces, _jitter_faces(full[:100])]
    pos = np.r_[faces, faces[:, :, ::-1]]
    neg = np.r_[patches[labels == 0], patches[labels == 0][:, :, ::-1]]
    gen = random_generator(seed)
    pictures = _negative_pictures()
    randoms = []
    for pic in pictures:  # random windows of random sizes
        for _ in range(40):
            size = int(gen.integers(24, min(pic.shape) // 2))
            y0 = int(gen.integers(0, pic.shape[0] - size))
            x0 = int(gen.integers(0, pic.shape[1] - size))
            crop = _rescale(pic[y0 : y0 + size, x0 : x0 + size], 24 / size)
            if crop.shape == (24, 24):
                randoms.append(crop)
    neg = np.r_[neg, np.stack(randoms)]
    det.fit(np.r_[pos, neg], np.r_[np.ones(len(pos)), np.zeros(len(neg))], random_state=seed)
    for _ in progress_bar(range(mining_rounds), desc="hard negatives", disable=not progress):
        hard = []
        for pic in pictures:
            found = det.detect(pic, threshold=-0.5, stride=det.cell_size, nms_iou=0.5, max_size=200)
            for x, y, w, h in found.boxes[:hard_per_picture]:
                x0, y0, x1, y1 = int(x), int(y), round(float(x + w)), round(float(y + h))
                crop = pic[y0:y1, x0:x1]
                if min(crop.shape) < 8:
                    continue
                hard.append(_rescale(crop, 24 / crop.shape[1])[:24, :24])
        hard = [h for h in hard if h.shape == (24, 24)][:max_hard]
        if not hard:
            break
        neg = np.r_[neg, np.stack(hard)]
        det.fit(np.r_[pos, neg], np.r_[np.ones(len(pos)), np.zeros(len(neg))], random_state=seed)
    return det, cv
