"""2-D features against OpenCV (issue 5), single-threaded on both sides
(``cv2.setNumThreads(1)``; our kernels are serial), same inputs, one process."""

from __future__ import annotations

from pathlib import Path

import cv2
import numba
import numpy as np

from benchmarks._harness import Record, paired_ms
from benchmarks.imaging import test_image
from robopercept import features as ft
from robopercept.imaging import read_image, transform_points

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "features"
SETS = ("graf", "boat", "bikes", "leuven", "ubc", "bark")


def _h(name: str, n: int) -> np.ndarray:
    fs = cv2.FileStorage(
        str(DATA / "oxford_affine" / name / f"H1to{n}p.xml"), cv2.FILE_STORAGE_READ
    )
    return fs.getNode(f"H1{n}").mat()


def _repeatability(xy1: np.ndarray, xy2: np.ndarray, h: np.ndarray, shape2: tuple) -> float:
    # fraction of image-1 keypoints that land inside image 2 and have an image-2
    # keypoint within 3 px of their true position
    from scipy.spatial import cKDTree

    p = transform_points(h, xy1)
    inside = (p >= 0).all(axis=1) & (p[:, 0] <= shape2[1] - 1) & (p[:, 1] <= shape2[0] - 1)
    d, _ = cKDTree(xy2).query(p[inside])
    return float(np.mean(d < 3.0))


def oxford_table() -> list[dict]:
    """SIFT on the Oxford affine pairs 1->2 and 1->3: ratio-test (0.8) matches, correct
    ones (< 3 px under the true homography), precision and repeatability, ours beside
    cv2.SIFT (OpenCV's positions taken as it reports them)."""
    sc = cv2.SIFT_create()
    bf = cv2.BFMatcher()
    rows = []
    for name in SETS:
        g1 = read_image(DATA / "oxford_affine" / name / "img1.png", mode="gray")
        f1 = ft.sift(g1)
        k1, d1 = sc.detectAndCompute(g1, None)
        c1 = np.array([k.pt for k in k1])
        for n in (2, 3):
            g2 = read_image(DATA / "oxford_affine" / name / f"img{n}.png", mode="gray")
            f2 = ft.sift(g2)
            k2, d2 = sc.detectAndCompute(g2, None)
            c2 = np.array([k.pt for k in k2])
            h = _h(name, n)
            m = ft.match_descriptors(f1.descriptors, f2.descriptors, ratio=0.8)
            e = np.linalg.norm(
                transform_points(h, f1.keypoints.xy[m.query_idx]) - f2.keypoints.xy[m.train_idx],
                axis=1,
            )
            cm = [a for a, b in bf.knnMatch(d1, d2, k=2) if a.distance < 0.8 * b.distance]
            qi = np.array([a.queryIdx for a in cm])
            ti = np.array([a.trainIdx for a in cm])
            e2 = np.linalg.norm(transform_points(h, c1[qi]) - c2[ti], axis=1)
            rows.append(
                {
                    "pair": f"{name} 1->{n}",
                    "ours_matches": len(e),
                    "ours_correct": int((e < 3).sum()),
                    "ours_precision": round(float((e < 3).mean()), 4),
                    "cv_matches": len(e2),
                    "cv_correct": int((e2 < 3).sum()),
                    "cv_precision": round(float((e2 < 3).mean()), 4),
                    "ours_repeatability": round(
                        _repeatability(f1.keypoints.xy, f2.keypoints.xy, h, g2.shape), 4
                    ),
                    "cv_repeatability": round(_repeatability(c1, c2, h, g2.shape), 4),
                }
            )
    return rows


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
    ours = ft.hog_windows(img, window=(64, 128), stride=8)
    recs.append(
        Record(
            "hog_windows",
            f"640x480 uint8, 64x128 windows every 8 px -> {ours.shape[0] * ours.shape[1]} "
            "windows x 3780",
            *paired_ms(
                lambda: ft.hog_windows(img, window=(64, 128), stride=8),
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
    graf = read_image(DATA / "oxford_affine" / "graf" / "img1.png", mode="gray")
    sc = cv2.SIFT_create()
    ours_f = ft.sift(graf)
    ref_kp, _ = sc.detectAndCompute(graf, None)
    for threads in (numba.config.NUMBA_NUM_THREADS, 1):
        numba.set_num_threads(threads)
        recs.append(
            Record(
                "sift",
                f"graf img1 800x640 detect + describe, ours on {threads} thread(s)",
                *paired_ms(lambda: ft.sift(graf), lambda: sc.detectAndCompute(graf, None), 8, 1),
                "cv2.SIFT_create().detectAndCompute",
                "keypoints ours / OpenCV",
                len(ours_f) / len(ref_kp),
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
        "oxford_affine": oxford_table(),
        "threads": "OpenCV 1 (cv2.setNumThreads(1)); ours serial kernels (HOG's parallel "
        "kernels with numba.set_num_threads(1)), but knn_match's matrix product "
        "uses NumPy's BLAS with its default threads (2 cores)",
        "repeats": repeats,
    }
