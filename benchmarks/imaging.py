"""Imaging kernels against OpenCV on a 1280x720 image (cv2.setNumThreads(1))."""

from __future__ import annotations

import cv2
import numpy as np

from benchmarks._harness import Record, median_ms, paired_ms
from robopercept import imaging as im

TARGET = 2.0  # issue 2: at most 2x OpenCV's time
TARGET_50 = 1.0  # issue 50: Gaussian, Sobel, HSV, median and box at OpenCV's single-thread time


def test_image() -> tuple[np.ndarray, np.ndarray]:
    """A natural 1280x720 RGB image (skimage's astronaut, resized) and its gray version."""
    from skimage import data

    rgb = cv2.resize(data.astronaut(), (1280, 720), interpolation=cv2.INTER_LINEAR)
    return rgb, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


def _f1(a: np.ndarray, b: np.ndarray) -> float:
    tp = np.count_nonzero(a & b)
    return 2 * tp / max(np.count_nonzero(a) + np.count_nonzero(b), 1)


def run(repeats: int = 30) -> tuple[list[Record], dict]:
    cv2.setNumThreads(1)
    rgb, gray = test_image()
    gray_f = gray.astype(np.float32) / 255
    recs: list[Record] = []

    for case, img in (("uint8 RGB", rgb), ("uint8 gray", gray), ("float32 gray", gray_f)):
        ours = im.gaussian_blur(img, 2.0, ksize=13)
        ref = cv2.GaussianBlur(img, (13, 13), 2.0)
        recs.append(
            Record(
                "gaussian_blur",
                f"{case}, sigma 2, 13x13",
                *paired_ms(
                    lambda img=img: im.gaussian_blur(img, 2.0, ksize=13),
                    lambda img=img: cv2.GaussianBlur(img, (13, 13), 2.0),
                    repeats,
                ),
                "cv2.GaussianBlur",
                "max abs diff",
                float(np.abs(ours.astype(np.float64) - ref).max()),
                TARGET_50,
            )
        )

    for case, img in (("uint8 gray", gray), ("uint8 RGB", rgb)):
        ours = im.sobel(img, 1, 0, 3)
        ref = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3)
        recs.append(
            Record(
                "sobel",
                f"{case} -> float32, dx, 3x3",
                *paired_ms(
                    lambda img=img: im.sobel(img, 1, 0, 3),
                    lambda img=img: cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3),
                    repeats,
                ),
                "cv2.Sobel(CV_32F)",
                "max abs diff",
                float(np.abs(ours - ref).max()),
                TARGET_50,
            )
        )

    for case, img in (("uint8 gray", gray), ("uint8 RGB", rgb)):
        for k in (3, 5):
            same = np.array_equal(im.median_filter(img, k), cv2.medianBlur(img, k))
            recs.append(
                Record(
                    "median_filter",
                    f"{case}, {k}x{k}",
                    *paired_ms(
                        lambda img=img, k=k: im.median_filter(img, k),
                        lambda img=img, k=k: cv2.medianBlur(img, k),
                        repeats,
                    ),
                    "cv2.medianBlur",
                    "identical (1 = yes)",
                    float(same),
                    TARGET_50,
                )
            )
        for k in (3, 5):
            ours = im.box_filter(img, k)
            ref = cv2.blur(img, (k, k))
            recs.append(
                Record(
                    "box_filter",
                    f"{case}, {k}x{k}",
                    *paired_ms(
                        lambda img=img, k=k: im.box_filter(img, k),
                        lambda img=img, k=k: cv2.blur(img, (k, k)),
                        repeats,
                    ),
                    "cv2.blur",
                    "max abs diff",
                    float(np.abs(ours.astype(np.float64) - ref).max()),
                    TARGET_50,
                )
            )

    ours = im.canny(gray, 50, 150, sigma=0)
    ref = cv2.Canny(gray, 50, 150, L2gradient=True) > 0
    recs.append(
        Record(
            "canny",
            "uint8 gray, 50/150, L2, no pre-blur",
            *paired_ms(
                lambda: im.canny(gray, 50, 150, sigma=0),
                lambda: cv2.Canny(gray, 50, 150, L2gradient=True),
                repeats,
            ),
            "cv2.Canny(L2gradient=True)",
            "edge-pixel F1",
            _f1(ours, ref),
            TARGET,
        )
    )

    ours = im.rgb_to_hsv(rgb)
    ref = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    recs.append(
        Record(
            "rgb_to_hsv",
            "uint8 RGB -> uint8 HSV (OpenCV scale)",
            *paired_ms(
                lambda: im.rgb_to_hsv(rgb), lambda: cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV), repeats
            ),
            "cv2.cvtColor(RGB2HSV)",
            "max abs diff",
            float(np.abs(ours.astype(int) - ref).max()),
            TARGET_50,
        )
    )

    mask = gray > im.otsu_threshold(gray)
    mask8 = mask.astype(np.uint8)
    labels, n = im.label_components(mask)
    n_cv, ref_labels = cv2.connectedComponents(mask8, connectivity=8)
    pairs = np.unique(np.stack([labels.ravel(), ref_labels.ravel()]), axis=1)
    same = n == n_cv - 1 and pairs.shape[1] == n_cv
    recs.append(
        Record(
            "connected_components",
            f"Otsu mask, 8-connected, {n} blobs",
            *paired_ms(
                lambda: im.label_components(mask, 8),
                lambda: cv2.connectedComponents(mask8, connectivity=8),
                repeats,
            ),
            "cv2.connectedComponents",
            "identical partition (1 = yes)",
            float(same),
            TARGET,
        )
    )
    feats = im.blob_features(labels)
    recs.append(
        Record(
            "connected_components",
            "labels + stats (area, bbox, centroid, perimeter, holes)",
            median_ms(
                lambda: im.blob_features(im.label_components(mask, 8)[0]), max(5, repeats // 3)
            ),
            median_ms(lambda: cv2.connectedComponentsWithStats(mask8, connectivity=8), repeats),
            "cv2.connectedComponentsWithStats (no perimeter/holes)",
            "blobs measured",
            float(len(feats)),
            None,
        )
    )
    return recs, {
        "image": "skimage astronaut resized to 1280x720",
        "cv2_threads": 1,
        "repeats": repeats,
    }
