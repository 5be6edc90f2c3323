"""Synthetic chessboard and circle-grid photographs with a known camera (for
calibration tests)."""

from __future__ import annotations

import numpy as np

from robopercept.geometry.camera import undistort
from robopercept.geometry.transforms import rotation_from_rotvec


def _board_coords(K, dist, rvec, tvec, size, ss):
    """Board-plane coordinates (metres) seen by each of the ss x ss subpixels."""
    w, h = size
    R = rotation_from_rotvec(np.asarray(rvec, float))
    t = np.asarray(tvec, float)
    off = (np.arange(ss) + 0.5) / ss - 0.5
    u = (np.arange(w)[:, None] + off[None, :]).ravel()
    v = (np.arange(h)[:, None] + off[None, :]).ravel()
    uu, vv = np.meshgrid(u, v)
    xd = (uu - K[0, 2]) / K[0, 0]
    yd = (vv - K[1, 2]) / K[1, 1]
    x, y = undistort(xd, yd, tuple(dist))
    for _ in range(3):  # a few more fixed-point rounds for strong distortion
        x, y = undistort(xd, yd, tuple(dist))
    ray = np.stack([x, y, np.ones_like(x)], axis=-1)
    # plane: n . X = d in camera frame, n = R[:, 2], d = n . t
    n = R[:, 2]
    s = (n @ t) / (ray @ n)
    P = ray * s[..., None] - t
    B = P @ R  # board coordinates (R^T (X - t))
    return B[..., 0], B[..., 1]


def _finish(img, size, ss):
    w, h = size
    img = img.reshape(h, ss, w, ss).mean(axis=(1, 3))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def render_board(K, dist, rvec, tvec, pattern=(9, 6), square=0.03, size=(640, 480), ss=3):
    """Gray uint8 image of a board of (w + 1) x (h + 1) squares with a white margin of
    one square, seen from pose (rvec, tvec) (board to camera), supersampled ss x ss.

    Board corner (0, 0) is the first inner corner; the square diagonal to it (towards
    negative x, y) is black, as OpenCV's ordering expects.
    """
    bx, by = _board_coords(K, dist, rvec, tvec, size, ss)
    bx, by = bx / square, by / square
    inside = (bx > -1) & (bx < pattern[0]) & (by > -1) & (by < pattern[1])
    black = (np.floor(bx) + np.floor(by)) % 2 == 0
    img = np.full(bx.shape, 235.0)
    img[inside & black] = 20.0
    margin = (bx > -2) & (bx < pattern[0] + 1) & (by > -2) & (by < pattern[1] + 1)
    img[~margin] = 90.0
    return _finish(img, size, ss)


def render_circles(K, dist, rvec, tvec, pattern=(4, 11), spacing=0.03, *, asymmetric=True,
                   radius=0.006, dark=True, size=(640, 480), ss=4):  # fmt: skip
    """Gray uint8 image of a circle grid (centres as ``circles_grid_points``: row i,
    column j at ((2j + i % 2) s/2, i s/2) asymmetric, (j s, i s) symmetric) on a
    board with a margin of one spacing, on a mid-grey background."""
    w, h = pattern
    bx, by = _board_coords(K, dist, rvec, tvec, size, ss)
    step = spacing / 2 if asymmetric else spacing
    i = np.clip(np.rint(by / step), 0, h - 1)
    if asymmetric:
        j = np.clip(np.rint((bx / step - i % 2) / 2), 0, w - 1)
        cx, cy = (2 * j + i % 2) * step, i * step
    else:
        j = np.clip(np.rint(bx / step), 0, w - 1)
        cx, cy = j * step, i * step
    disc = np.hypot(bx - cx, by - cy) < radius
    right = (2 * (w - 1) + 1) * step if asymmetric else (w - 1) * step
    board = (bx > -spacing) & (bx < right + spacing) & (by > -spacing)
    board &= by < (h - 1) * step + spacing
    paper, ink = (235.0, 25.0) if dark else (25.0, 235.0)
    img = np.full(bx.shape, 128.0)
    img[board] = paper
    img[board & disc] = ink
    return _finish(img, size, ss)
