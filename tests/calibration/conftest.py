"""Shared calibration inputs: the OpenCV stereo chessboard set, detected once."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import data_path

VIEWS = [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14]


@pytest.fixture(scope="session")
def opencv_corners():
    """cv2.findChessboardCorners + cornerSubPix (11, 11) on left/right01..14: the
    reference corners, {name: (54, 2) or None}, plus the gray images."""
    cv2 = pytest.importorskip("cv2")
    folder = data_path("calibration", "opencv_chessboard_stereo")
    out, images = {}, {}
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    for side in ("left", "right"):
        for i in VIEWS:
            name = f"{side}{i:02d}"
            g = cv2.imread(str(folder / f"{name}.jpg"), cv2.IMREAD_GRAYSCALE)
            ok, c = cv2.findChessboardCorners(g, (9, 6))
            if ok:
                c = cv2.cornerSubPix(g, c, (11, 11), (-1, -1), crit)[:, 0].astype(np.float64)
            out[name] = c if ok else None
            images[name] = g
    return out, images
