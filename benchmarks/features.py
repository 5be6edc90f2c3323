"""2-D features against OpenCV (issue 5), single-threaded on both sides
(``cv2.setNumThreads(1)``; our kernels are serial), same inputs, one process."""

from __future__ import annotations

import cv2
import numba
import numpy as np

from benchmarks._harness import Record, paired_ms
from benchmarks.imaging import test_image
from robopercept import features as ft


def run(repeats: int = 30) -> tuple[list[Record], dict]:
    cv2.setNumThreads(1)
    _, gray = test_image()  # 1280x720
    recs: list[Record] = []
    for block, ksize in ((2, 3), (3, 5)):
        ours = ft.harris_response(gray, block, ksize, 0.04)
        ref = cv2.cornerHarris(gray, block, ksize, 0.04)
        recs.append(
            Record(
                "harris_response",
                f"1280x720 uint8, block {block}, ksize {ksize}",
                *paired_ms(
                    lambda b=block, k=ksize: ft.harris_response(gray, b, k, 0.04),
                    lambda b=block, k=ksize: cv2.cornerHarris(gray, b, k, 0.04),
                    repeats,
                ),
                "cv2.cornerHarris",
                "max abs diff / max abs ref",
                float(np.abs(ours - ref).max() / np.abs(ref).max()),
                1.0,
            )
        )
    ours_kp = ft.harris_corners(gray, method="shi-tomasi", threshold=0.01, min_distance=10)
    ref_kp = cv2.goodFeaturesToTrack(gray, 0, 0.01, 10, mask=None, blockSize=3, gradientSize=3)
    same = ref_kp is not None and np.array_equal(ours_kp.xy, ref_kp[:, 0])
    recs.append(
        Record(
            "harris_corners",
            f"1280x720 Shi-Tomasi, quality 0.01, spacing 10 -> {len(ours_kp)} corners",
            *paired_ms(
                lambda: ft.harris_corners(gray, method="shi-tomasi", min_distance=10),
                lambda: cv2.goodFeaturesToTrack(
                    gray, 0, 0.01, 10, mask=None, blockSize=3, gradientSize=3
                ),
                repeats,
            ),
            "cv2.goodFeaturesToTrack",
            "identical corners (1 = yes)",
            float(same),
            None,
        )
    )
    img = np.ascontiguousarray(cv2.resize(gray, (640, 480), interpolation=cv2.INTER_AREA))
    desc = cv2.HOGDescriptor((64, 128), (16, 16), (8, 8), (8, 8), 9)
    ref = desc.compute(img)
    numba.set_num_threads(1)  # serial like OpenCV here
    ours = ft.hog_windows(img, window=(128, 64), stride=8)
    recs.append(
        Record(
            "hog_windows",
            f"640x480 uint8, 64x128 windows every 8 px -> {ours.shape[0] * ours.shape[1]} "
            "windows x 3780",
            *paired_ms(
                lambda: ft.hog_windows(img, window=(128, 64), stride=8),
                lambda: desc.compute(img),
                repeats,
            ),
            "cv2.HOGDescriptor.compute",
            "max abs diff",
            float(np.abs(ours.reshape(-1) - ref.reshape(-1)).max()),
            2.0,
        )
    )
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    rng = np.random.default_rng(0)
    q = rng.random((5000, 128), dtype=np.float32)
    t = rng.random((5000, 128), dtype=np.float32)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    idx, _ = ft.knn_match(q, t, 2)
    ref = np.array([[m.trainIdx for m in r] for r in bf.knnMatch(q, t, k=2)])
    few = max(3, repeats // 6)
    recs.append(
        Record(
            "knn_match",
            "5000 x 5000 float32 128-D, k = 2 (L2)",
            *paired_ms(lambda: ft.knn_match(q, t, 2), lambda: bf.knnMatch(q, t, k=2), few, 1),
            "cv2.BFMatcher(NORM_L2).knnMatch",
            "same neighbours (fraction)",
            float(np.mean(idx == ref)),
            2.0,
        )
    )
    return recs, {
        "threads": "OpenCV 1 (cv2.setNumThreads(1)); ours serial kernels (HOG's parallel "
        "kernels with numba.set_num_threads(1)), but knn_match's matrix product "
        "uses NumPy's BLAS with its default threads (2 cores)",
        "repeats": repeats,
    }
