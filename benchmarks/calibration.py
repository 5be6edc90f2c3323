"""Calibration: chessboard detection (our detector with its subpixel refinement)
against ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` (11 x 11) on the 13 OpenCV
sample images left01..14 (640 x 480); and Zhang calibration against
``cv2.calibrateCamera`` on the same corners (RMS compared, speed recorded).

The time per image is the mean over the 13 images; OpenCV runs single-threaded, as in
the issue's 9 ms figure.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks._harness import Record, paired_ms

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
VIEWS = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14]


def run(repeats: int) -> tuple[list[Record], dict]:
    import cv2

    from robopercept.calibration import calibrate_camera, chessboard_points, find_chessboard_corners
    from robopercept.imaging import read_image

    folder = DATA / "calibration" / "opencv_chessboard_stereo"
    images = [read_image(folder / f"left{i:02d}.jpg", mode="gray") for i in VIEWS]
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)

    def ours():
        return [find_chessboard_corners(g, (9, 6)) for g in images]

    def ref():
        out = []
        for g in images:
            ok, c = cv2.findChessboardCorners(g, (9, 6))
            out.append(cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit)[:, 0] if ok else None)
        return out

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    o_ms, r_ms = paired_ms(ours, ref, repeats=repeats, warmup=1)
    cv2.setNumThreads(threads)
    dets, refs = ours(), ref()
    err = np.concatenate(
        [np.linalg.norm(d.corners - r, axis=1) for d, r in zip(dets, refs, strict=True)]
    )
    n = len(images)
    records = [
        Record("find_chessboard_corners", "left01..14 640x480, 9x6, per image",
               o_ms / n, r_ms / n, "cv2.findChessboardCorners + cornerSubPix (1 thread)",
               "median corner distance to OpenCV (px)", float(np.median(err)), 2.0,
               {"found": sum(d.found for d in dets),
                "reference_found": sum(r is not None for r in refs),
                "max_corner_distance_px": float(err.max())}),
    ]  # fmt: skip
    obj = chessboard_points((9, 6), 0.025)
    corners = [d.corners for d in dets]
    o32 = [obj.astype(np.float32)] * n
    c32 = [r.astype(np.float32) for r in refs]
    o_ms, r_ms = paired_ms(
        lambda: calibrate_camera(obj, corners, (640, 480)),
        lambda: cv2.calibrateCamera(o32, c32, (640, 480), None, None),
        repeats=max(3, repeats // 5),
        warmup=1,
    )
    ours_cal = calibrate_camera(obj, corners, (640, 480))
    rms = cv2.calibrateCamera(o32, c32, (640, 480), None, None)[0]
    records.append(
        Record("calibrate_camera", "13 views x 54 corners, k1 k2 p1 p2 k3", o_ms, r_ms,
               "cv2.calibrateCamera", "RMS reprojection error (px)", ours_cal.rms, None,
               {"reference_rms": rms,
                "fx_fy_cx_cy": ours_cal.K[[0, 1, 0, 1], [0, 1, 2, 2]].tolist()})
    )  # fmt: skip
    return records, {"data": "OpenCV sample chessboards left01..14 (Apache-2.0)"}
