"""Axis-aligned boxes ``(x, y, w, h)`` in pixels."""

from __future__ import annotations

import numpy as np

__all__ = ["box_iou_matrix"]


def box_iou_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    r"""Intersection over union of every box of ``a`` ``(M, 4)`` with every box of ``b``
    ``(N, 4)``: :math:`|A \cap B| / |A \cup B|`, 0 where the union is empty.

    Returns
    -------
    (M, N) ndarray
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 4)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 4)
    x0 = np.maximum(a[:, None, 0], b[None, :, 0])
    y0 = np.maximum(a[:, None, 1], b[None, :, 1])
    x1 = np.minimum(a[:, None, 0] + a[:, None, 2], b[None, :, 0] + b[None, :, 2])
    y1 = np.minimum(a[:, None, 1] + a[:, None, 3], b[None, :, 1] + b[None, :, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None, :] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)
