"""Pictures for docs/calibration.md from the OpenCV sample chessboards (Apache-2.0):
``python docs/make_calibration_pictures.py``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from robopercept.calibration import (
    calibrate_camera,
    chessboard_points,
    find_chessboard_corners,
    undistort,
)
from robopercept.imaging import read_image, write_image
from robopercept.viz import draw_chessboard

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
OUT = Path(__file__).resolve().parent / "img"


def main() -> None:
    folder = DATA / "calibration" / "opencv_chessboard_stereo"
    views = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14]
    grays = {i: read_image(folder / f"left{i:02d}.jpg", mode="gray") for i in views}
    dets = {i: find_chessboard_corners(g, (9, 6)) for i, g in grays.items()}
    res = calibrate_camera(
        chessboard_points((9, 6), 0.025), [d.corners for d in dets.values()], (640, 480)
    )
    # detection (with the background board on the monitor ignored) and undistortion
    i = 12
    shown = draw_chessboard(grays[i], dets[i].corners, (9, 6), True)
    flat = undistort(read_image(folder / f"left{i:02d}.jpg", mode="rgb"), res.K, res.dist)
    gap = np.full((480, 8, 3), 255, np.uint8)
    OUT.mkdir(exist_ok=True)
    write_image(OUT / "calibration_detect_undistort.jpg", np.hstack([shown, gap, flat]))


if __name__ == "__main__":
    main()
