"""2-D features against OpenCV (issue 5), single-threaded on both sides
(``cv2.setNumThreads(1)``; our kernels are serial), same inputs, one process."""

from __future__ import annotations

import cv2
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
    return recs, {"threads": "1 (cv2.setNumThreads(1); ours serial)", "repeats": repeats}
