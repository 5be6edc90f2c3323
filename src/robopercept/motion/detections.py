"""Foreground masks to object detections, and a synthetic moving-blob sequence with
ground-truth masks (for tests, benchmarks and demonstrations)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robopercept._checks import (
    as_rng,
    check_choice,
    check_int,
    check_ndim,
    check_real,
    check_reals,
    check_size,
    plain_repr,
)
from robopercept.errors import InputError

__all__ = ["MAX_BLOB_PIXELS", "MaskDetections", "detections_from_mask", "moving_blobs"]

#: most pixels :func:`moving_blobs` makes in all (n_frames x width x height)
MAX_BLOB_PIXELS = 2**28


@dataclass(frozen=True)
class MaskDetections:
    """Blobs of a foreground mask, largest first.

    Attributes
    ----------
    boxes : (N, 4) ndarray
        ``x, y, w, h`` of each blob's bounding box.
    centroids : (N, 2) ndarray
        ``(x, y)`` mean pixel position.
    areas : (N,) ndarray
        Pixel counts.
    """

    boxes: np.ndarray
    centroids: np.ndarray
    areas: np.ndarray

    def __len__(self) -> int:
        return int(self.areas.size)


def detections_from_mask(
    mask: np.ndarray, min_area: int = 50, *, connectivity: int = 8
) -> MaskDetections:
    """Connected blobs of ``mask`` with at least ``min_area`` pixels, as boxes and
    centroids (through :func:`robopercept.imaging.label_components` and
    :func:`robopercept.imaging.blob_features`)."""
    from robopercept.imaging.blobs import blob_features, label_components

    m = check_ndim(mask, "mask", (2,))
    if m.dtype.kind not in "biuf":
        raise InputError(f"mask must be a bool (H, W) array; got dtype {m.dtype}")
    if m.dtype.kind == "f" and not np.isfinite(m).all():
        raise InputError("mask has NaN or inf: pass a bool mask (e.g. mask > 0)")
    min_area = check_int(min_area, "min_area", 1)
    connectivity = check_choice(check_int(connectivity, "connectivity"), "connectivity", (4, 8))
    labels, n = label_components(m.astype(bool), connectivity)
    if n == 0:
        return MaskDetections(np.zeros((0, 4)), np.zeros((0, 2)), np.zeros(0, dtype=np.int64))
    feats = blob_features(labels)
    keep = feats.area >= min_area
    order = np.argsort(-feats.area[keep], kind="stable")
    return MaskDetections(
        feats.bbox[keep][order].astype(np.float64),
        feats.centroid[keep][order],
        feats.area[keep][order].astype(np.int64),
    )


def moving_blobs(
    n_frames: int = 60,
    size: tuple[int, int] = (320, 240),
    *,
    n_blobs: int = 3,
    radius: tuple[float, float] = (12.0, 22.0),
    speed: float = 5.0,
    noise_std: float = 4.0,
    illumination_drift: float = 0.25,
    rng: int | np.random.Generator | None = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """A textured background with discs moving across it, sensor noise and a slow
    illumination change, and the true foreground masks.

    Each disc has its own gray level and constant velocity (``speed`` px/frame, random
    direction); a disc that leaves the picture comes back on the opposite side, like
    a stream of passers-by. The background's brightness ramps by
    ``illumination_drift`` (a fraction, 0.25: 25 % brighter at the end); Gaussian
    noise of ``noise_std`` (0-255 scale) is added to every frame.

    Parameters
    ----------
    n_frames : int
    size : (width, height)
        Frame size, as OpenCV's sizes (the frames' shape is ``(height, width)``).

    Returns
    -------
    frames : (n_frames, H, W) uint8 ndarray
    masks : (n_frames, H, W) bool ndarray
    """
    n_frames = check_int(n_frames, "n_frames", 1)
    w, h = check_size(size, "size", minimum=8)
    if n_frames * w * h > MAX_BLOB_PIXELS:
        raise InputError(
            f"n_frames x width x height must be at most {MAX_BLOB_PIXELS} pixels (the "
            f"frames and masks take one byte each); got {n_frames} x {w} x {h}: use fewer "
            "or smaller frames"
        )
    n_blobs = check_int(n_blobs, "n_blobs", 0)
    if n_blobs > 1000:
        raise InputError(f"n_blobs must be in 0..1000; got {n_blobs}")
    r_low, r_high = check_reals(radius, "radius", 2, 0.0)
    if not 0 < r_low <= r_high or 2 * r_high + 2 >= min(w, h):
        raise InputError(
            f"radius must be (smallest, largest) with 0 < smallest <= largest and discs that "
            f"fit the {w}x{h} frame (largest < {(min(w, h) - 2) / 2:g}); got {plain_repr(radius)}"
        )
    speed = check_real(speed, "speed", 0.0)
    noise_std = check_real(noise_std, "noise_std", 0.0)
    illumination_drift = check_real(illumination_drift, "illumination_drift", -1.0)
    gen = as_rng(rng)
    from robopercept.imaging.filters import gaussian_blur

    texture = gaussian_blur(gen.uniform(0, 1, (h, w)), 3.0)
    texture = 60 + 80 * (texture - texture.min()) / np.ptp(texture)
    r = gen.uniform(r_low, r_high, n_blobs)
    pos = np.c_[gen.uniform(r + 1, w - r - 1), gen.uniform(r + 1, h - r - 1)]
    angle = gen.uniform(0, 2 * np.pi, n_blobs)
    vel = speed * np.c_[np.cos(angle), np.sin(angle)]
    level = gen.choice([20.0, 220.0, 200.0, 30.0], n_blobs)
    yy, xx = np.mgrid[:h, :w]
    frames = np.empty((n_frames, h, w), dtype=np.uint8)
    masks = np.zeros((n_frames, h, w), dtype=bool)
    for t in range(n_frames):
        gain = 1.0 + illumination_drift * t / max(n_frames - 1, 1)
        img = texture * gain
        for b in range(n_blobs):
            disc = (xx - pos[b, 0]) ** 2 + (yy - pos[b, 1]) ** 2 <= r[b] ** 2
            img = np.where(disc, level[b], img)
            masks[t] |= disc
        img = img + gen.normal(0, noise_std, (h, w))
        frames[t] = np.clip(np.round(img), 0, 255).astype(np.uint8)
        pos += vel
        for axis, lim in ((0, w), (1, h)):  # leave on one side, come back on the other
            pos[:, axis] = np.mod(pos[:, axis] + r, lim + 2 * r) - r
    return frames, masks
