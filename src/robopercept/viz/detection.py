"""Pictures of detections: ``xyxy`` boxes (and instance masks) coloured and captioned
by class on an image (:func:`draw_detections`), and a grid of such images
(:func:`detections_grid`), from NumPy arrays and plain values.

Boxes are continuous ``xyxy`` in pixels, pixel ``(col, row)`` covering
``[col, col + 1) x [row, row + 1)`` (the torchvision and COCO convention), so a box is
outlined on the pixels it covers at its edges. Labels are 1-based (label ``k`` is
``classes[k - 1]``); class ``k`` takes colour ``k`` of
:func:`~robopercept.viz.colormap.label_colors`. The detection sets of
:mod:`robopercept.nn.detection.data` and the detectors' outputs are drawn with these.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from robopercept._checks import check_int, check_numeric, check_real, plain_repr
from robopercept.errors import InputError
from robopercept.viz.colormap import label_colors
from robopercept.viz.draw import (
    check_picture_size,
    draw_boxes,
    draw_mask,
    draw_text,
    enlarge_picture,
    label_font,
    label_size_for,
    to_rgb8,
)

__all__ = [
    "PREDICTION_COLOR",
    "TRUTH_COLOR",
    "detection_samples_picture",
    "detections_grid",
    "draw_detections",
]


def _classes(classes: Any) -> tuple[str, ...]:
    if not isinstance(classes, (list, tuple)) or not classes:
        raise InputError(
            f"classes must be a non-empty list of class names; got {plain_repr(classes)}"
        )
    if not all(isinstance(c, str) and c for c in classes):
        raise InputError(f"classes must be non-empty strings; got {plain_repr(classes)}")
    if len(set(classes)) != len(classes):
        raise InputError(f"classes must be distinct; got {plain_repr(classes)}")
    return tuple(classes)


def _labels(labels: Any, k: int, name: str = "labels") -> np.ndarray:
    y = check_numeric(labels, name).reshape(-1)
    if y.size != k:
        raise InputError(f"{name} must have one label per box ({k}); got {y.size}")
    if np.any(y != np.floor(y)) or np.any((y < 1) | (y > 1 << 30)):
        raise InputError(
            f"{name} must be integers in [1, {1 << 30}] (1-based; 0 is background); "
            f"got {plain_repr(labels)}"
        )
    return y.astype(np.int64)


def _masks(masks: Any, k: int, shape: tuple[int, ...], name: str = "masks") -> np.ndarray:
    m = check_numeric(masks, name)
    if m.size == 0:
        m = m.reshape(0, *shape)
    if m.shape != (k, *shape):
        raise InputError(f"{name} must be (K, H, W) = {(k, *shape)}; got {m.shape}")
    return m != 0


def draw_detections(
    image: np.ndarray,
    boxes: npt.ArrayLike,
    labels: npt.ArrayLike | None = None,
    classes: Sequence[str] | None = None,
    *,
    scores: npt.ArrayLike | None = None,
    masks: npt.ArrayLike | None = None,
    width: int = 1,
    label_size: int | None = None,
) -> np.ndarray:
    """Draw ``xyxy`` boxes (and masks), coloured and captioned by class.

    Box ``(x_1, y_1, x_2, y_2)`` is outlined on its edge pixels, columns ``x_1`` to
    ``x_2 - 1`` (:func:`~robopercept.viz.draw.draw_boxes` of ``(x_1, y_1, x_2 - x_1,
    y_2 - y_1)``); the caption is ``classes[label - 1]`` (or the label), followed by the
    score when given. Masks are blended at 40 % in the class colour
    (:func:`~robopercept.viz.colormap.label_colors`). Captions never overlap: they are
    placed by :func:`~robopercept.viz.draw.caption_boxes`, the best score first, and a
    caption with no free place left is left out.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1].
    boxes : (K, 4) array_like
    labels : (K,) int array_like, optional
        1-based (default: all 1).
    classes : sequence of str, optional
    scores : (K,) array_like, optional
    masks : (K, H, W) array_like, optional
    width : int
        Outline width.
    label_size : int, optional
        Caption font size in pixels (default
        :func:`~robopercept.viz.draw.label_size_for` of the image height).

    Returns
    -------
    (H, W, 3) uint8 ndarray

    Examples
    --------
    >>> out = draw_detections(np.zeros((32, 32)), [[4, 16, 12, 28]], [1], ["x"])
    >>> out.shape, bool(out[16, 4].any()), bool(out[27, 11].any()), bool(out[22, 8].any())
    ((32, 32, 3), True, True, False)
    """
    out = to_rgb8(image) if isinstance(image, np.ndarray) else None
    if out is None:
        raise InputError(f"image must be a numpy array; got {type(image).__name__}")
    b = check_numeric(boxes, "boxes")
    if b.size == 0:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError(f"boxes must be (K, 4) xyxy; got shape {b.shape}")
    k = len(b)
    if labels is None:
        lab = np.ones(k, dtype=np.int64)
    else:
        lab = _labels(labels, k)
    names = None if classes is None else _classes(classes)
    sc = None
    if scores is not None:
        sc = check_numeric(scores, "scores").reshape(-1)
        if sc.size != k:
            raise InputError(f"scores must have one value per box ({k}); got {sc.size}")
    if masks is not None:
        m = _masks(masks, k, out.shape[:2])
    colors = label_colors(lab)
    for j in range(k):
        if masks is not None:
            out = draw_mask(out, m[j], color=tuple(int(c) for c in colors[j]), alpha=0.4)
    captions = []
    for j in range(k):
        name = str(lab[j])
        if names is not None and lab[j] <= len(names):
            name = names[lab[j] - 1]
        captions.append(name if sc is None else f"{name} {sc[j]:.2f}")
    # the best-scored boxes first: their captions get the first places
    order = np.arange(k) if sc is None else np.argsort(-sc, kind="stable")
    xywh = np.column_stack([b[:, :2], b[:, 2:] - b[:, :2]])
    return draw_boxes(
        out,
        xywh[order],
        color=colors[order],
        width=width,
        labels=[captions[j] for j in order],
        label_size=label_size,
    )


def detections_grid(
    images: Sequence[np.ndarray],
    boxes: Sequence[npt.ArrayLike],
    labels: Sequence[npt.ArrayLike] | None = None,
    classes: Sequence[str] | None = None,
    *,
    masks: Sequence[npt.ArrayLike] | None = None,
    columns: int = 4,
) -> np.ndarray:
    """A grid of images, each with its boxes, labels (and masks) drawn by
    :func:`draw_detections`.

    Parameters
    ----------
    images : list of (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1]; sizes may differ.
    boxes : list of (K_i, 4) array_like
        ``xyxy`` boxes of each image.
    labels : list of (K_i,) int array_like, optional
        1-based labels of each image's boxes (default: all 1).
    classes : sequence of str, optional
    masks : list of (K_i, H, W) array_like, optional
        Instance masks of each image.
    columns : int
        Images per row (>= 1).

    Returns
    -------
    (rows * H_max + gaps, columns * W_max + gaps, 3) uint8 ndarray
        Images top-left aligned in cells of the largest size, 2-pixel white gaps.

    Raises
    ------
    InputError
        No images, lists of different lengths, or a bad image, box, label or mask.

    Examples
    --------
    >>> pic = detections_grid([np.zeros((32, 32))] * 3, [[[4, 4, 12, 12]]] * 3)
    >>> pic.shape
    (32, 100, 3)
    """
    if not isinstance(images, (list, tuple)) or not images:
        raise InputError(
            f"images must be a non-empty list of (H, W[, 3]) arrays; got {plain_repr(images)}"
        )
    n = len(images)
    for name, value in (("boxes", boxes), ("labels", labels), ("masks", masks)):
        if (value is not None or name == "boxes") and (
            not isinstance(value, (list, tuple)) or len(value) != n
        ):
            raise InputError(f"{name} must be a list with one entry per image ({n})")
    for i, im in enumerate(images):
        if not isinstance(im, np.ndarray) or im.ndim not in (2, 3):
            raise InputError(f"images[{i}] must be an (H, W[, 3]) numpy array")
    columns = check_int(columns, "columns", 1)
    hmax = max(im.shape[0] for im in images)
    wmax = max(im.shape[1] for im in images)
    cols = min(columns, n)
    rows = -(-n // cols)
    gap = 2
    pw, ph = check_picture_size(cols * (wmax + gap) - gap, rows * (hmax + gap) - gap)
    out = np.full((ph, pw, 3), 255, dtype=np.uint8)
    for i, im in enumerate(images):
        pic = draw_detections(
            im,
            boxes[i],
            None if labels is None else labels[i],
            classes,
            masks=None if masks is None else masks[i],
        )
        r, c = divmod(i, cols)
        y, x = r * (hmax + gap), c * (wmax + gap)
        out[y : y + im.shape[0], x : x + im.shape[1]] = pic
    return out


#: the colour of ground-truth boxes in :func:`detection_samples_picture` (Okabe-Ito
#: sky blue: apart from the prediction colour for every kind of colour vision)
TRUTH_COLOR = (86, 180, 233)
#: the colour of predicted boxes in :func:`detection_samples_picture` (Okabe-Ito orange)
PREDICTION_COLOR = (230, 159, 0)
#: the width a samples picture is enlarged towards (1080p: 1920)
_SHEET_WIDTH = 1600
#: the longest side an image is enlarged to in a samples picture
_CELL = 800


def _detection_set(value: Any, name: str, scores: bool) -> dict[str, np.ndarray]:
    """``{"boxes", "labels"[, "scores"]}`` of one image's detections (torchvision's
    output and target dictionaries)."""
    if not isinstance(value, Mapping) or "boxes" not in value:
        raise InputError(
            f"{name} must be a dict with 'boxes' (K, 4) xyxy, and 'labels' (K,)"
            f"{' and scores (K,)' if scores else ''} (torchvision's form); got "
            f"{plain_repr(value)}"
        )
    b = check_numeric(value["boxes"], f"{name}['boxes']")
    if b.size == 0:
        b = b.reshape(0, 4)
    if b.ndim != 2 or b.shape[1] != 4:
        raise InputError(f"{name}['boxes'] must be (K, 4) xyxy; got shape {b.shape}")
    k = len(b)
    raw = value.get("labels")
    lab = np.ones(k, np.int64) if raw is None else _labels(raw, k, f"{name}['labels']")
    out = {"boxes": b.astype(np.float64), "labels": lab}
    if scores:
        raw = value.get("scores")
        sc = np.ones(k) if raw is None else check_numeric(raw, f"{name}['scores']").reshape(-1)
        if sc.size != k:
            raise InputError(f"{name}['scores'] must have one value per box ({k}); got {sc.size}")
        out["scores"] = sc.astype(np.float64)
    return out


def detection_samples_picture(
    images: Sequence[np.ndarray],
    predictions: Sequence[Mapping[str, Any]],
    targets: Sequence[Mapping[str, Any]] | None = None,
    classes: Sequence[str] | None = None,
    *,
    threshold: float | None = None,
    columns: int | None = None,
) -> np.ndarray:
    """A sheet of images with their predicted boxes and their ground truth, told apart
    by colour and named in a legend, readable at 1080p: the ``samples.png`` of
    ``robopercept nn detect train``.

    The images are laid out in a roughly square grid (``ceil(sqrt(n))`` columns, as
    matplotlib's ``subplots`` sheets), each enlarged by a whole factor with
    nearest-neighbour sampling (pixels stay sharp) so that its longer side reaches
    ``min(800, 1600 / columns)`` pixels (a sheet 1000 to 1900 pixels wide for images
    of 100 to 500 pixels; larger images are kept as they are). Ground
    truth is outlined in :data:`TRUTH_COLOR` (sky blue), predictions in
    :data:`PREDICTION_COLOR` (orange), with their scores; captions never overlap (the
    best scores are placed first, :func:`~robopercept.viz.draw.caption_boxes`) and
    carry the class name when there is more than one class. Each image has a title
    (its number, the boxes predicted and true), and "nothing detected" is written on
    an image without predictions. The legend is a band above the grid.

    Parameters
    ----------
    images : list of (H, W) or (H, W, 3) ndarray
        uint8, or float in [0, 1]; sizes may differ.
    predictions : list of dict
        One per image, torchvision's detection output: ``"boxes"`` (K, 4) ``xyxy``
        in pixels, ``"labels"`` (K,) 1-based (default all 1), ``"scores"`` (K,).
    targets : list of dict, optional
        One per image, torchvision's target form: ``"boxes"``, ``"labels"``.
    classes : sequence of str, optional
        The names of labels 1..C.
    threshold : float, optional
        Predictions scored below this are left out (the legend says so).
    columns : int, optional
        Images per row (default ``ceil(sqrt(n))``).

    Returns
    -------
    (H', W', 3) uint8 ndarray

    Raises
    ------
    InputError
        No images, lists of different lengths, a bad image, box, label or score.

    Examples
    --------
    >>> im = np.zeros((128, 128, 3), np.uint8)
    >>> pred = {"boxes": [[10, 10, 60, 60]], "labels": [1], "scores": [0.9]}
    >>> true = {"boxes": [[12, 12, 62, 62]], "labels": [1]}
    >>> pic = detection_samples_picture([im] * 4, [pred] * 4, [true] * 4, ["shape"])
    >>> pic.shape[1]  # a 2 x 2 grid of 768 x 768 images (6 times 128), 8 pixels apart
    1544
    """
    if not isinstance(images, (list, tuple)) or not images:
        raise InputError(
            f"images must be a non-empty list of (H, W[, 3]) arrays; got {plain_repr(images)}"
        )
    n = len(images)
    for name, value in (("predictions", predictions), ("targets", targets)):
        if (value is not None or name == "predictions") and (
            not isinstance(value, (list, tuple)) or len(value) != n
        ):
            raise InputError(f"{name} must be a list with one dict per image ({n})")
    pics = []
    for i, im in enumerate(images):
        if not isinstance(im, np.ndarray) or im.ndim not in (2, 3):
            raise InputError(f"images[{i}] must be an (H, W[, 3]) numpy array")
        pics.append(to_rgb8(im))
    preds = [_detection_set(p, f"predictions[{i}]", True) for i, p in enumerate(predictions)]
    truths = (
        None
        if targets is None
        else [_detection_set(t, f"targets[{i}]", False) for i, t in enumerate(targets)]
    )
    names = None if classes is None else _classes(classes)
    thr = None if threshold is None else check_real(threshold, "threshold")
    cols = math.ceil(math.sqrt(n)) if columns is None else min(check_int(columns, "columns", 1), n)
    rows = -(-n // cols)
    side = min(_CELL, _SHEET_WIDTH // cols)
    big = [enlarge_picture(p, side) for p in pics]
    cell_w = max(b.shape[1] for b, _ in big)
    cell_h = max(b.shape[0] for b, _ in big)
    gap = 8
    grid_w, grid_h = cols * (cell_w + gap) - gap, rows * cell_h
    size = max(16, label_size_for(grid_h))
    title_h, band_h = int(size * 1.6), int(size * 2.2)
    width = max(2, round(size / 8))
    pw, ph = check_picture_size(grid_w, band_h + rows * (title_h + cell_h + gap), "samples picture")
    out = np.full((ph, pw, 3), 255, np.uint8)
    many = names is not None and len(names) > 1

    def caption(label: int, score: float | None) -> str:
        name = names[label - 1] if names is not None and label <= len(names) else str(label)
        if score is None:
            return name if many or names is None else ""
        return f"{name} {score:.2f}" if many else f"{score:.2f}"

    titles: list[tuple[str, int, int]] = []
    for i, ((pic, f), pred) in enumerate(zip(big, preds, strict=True)):
        keep = np.ones(len(pred["boxes"]), bool) if thr is None else pred["scores"] >= thr
        order = np.flatnonzero(keep)[np.argsort(-pred["scores"][keep], kind="stable")]
        boxes = [pred["boxes"][order]]
        texts = [caption(int(pred["labels"][j]), float(pred["scores"][j])) for j in order]
        colors = [PREDICTION_COLOR] * len(order)
        n_true = 0
        if truths is not None:
            t = truths[i]
            n_true = len(t["boxes"])
            boxes.append(t["boxes"])
            texts += [caption(int(v), None) for v in t["labels"]]
            colors += [TRUTH_COLOR] * n_true
        xyxy = np.concatenate(boxes) * f
        xywh = np.column_stack([xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]])
        drawn = draw_boxes(
            pic,
            xywh,
            color=np.array(colors, np.uint8).reshape(-1, 3),
            width=width,
            labels=texts,
            label_size=size,
        )
        if not len(order):
            drawn = draw_text(drawn, "nothing detected", (size // 2, size // 2), size=size)
        r, c = divmod(i, cols)
        x, y = c * (cell_w + gap), band_h + r * (title_h + cell_h + gap)
        out[y + title_h : y + title_h + drawn.shape[0], x : x + drawn.shape[1]] = drawn
        title = f"{i + 1}: {len(order)} detected" + ("" if truths is None else f", {n_true} true")
        titles.append((title, x + 2, y + 2))
    for title, tx, ty in titles:
        out = draw_text(out, title, (tx, ty), color=(0, 0, 0), size=size, background=None)
    # the legend band: a swatch and a name per colour
    what = "" if names is None or many else f" ({names[0]})"
    entries = [
        (PREDICTION_COLOR, "prediction" + what + ("" if thr is None else f", score >= {thr:.2f}"))
    ]
    if truths is not None:
        entries.append((TRUTH_COLOR, "ground truth" + what))
    out = np.array(out)  # (writable again)
    font = label_font(size)
    x, y = size // 2, (band_h - size) // 2
    spots = []
    for color, text in entries:
        out[y : y + size, x : x + size] = 0  # a swatch with a black frame
        out[y + 1 : y + size - 1, x + 1 : x + size - 1] = color
        spots.append((text, x + int(size * 1.4)))
        x += int(size * 1.4) + int(font.getlength(text)) + 2 * size
    for text, tx in spots:
        out = draw_text(out, text, (tx, y - 1), color=(0, 0, 0), size=size, background=None)
    return out
