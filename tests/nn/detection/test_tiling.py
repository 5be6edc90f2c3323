"""Tiled inference (issue 46): the windows cover the image and own disjoint parts of
it, a detector run window by window gives the whole image's boxes once each, and a
class map merged from windows equals the whole image's for a pixelwise rule."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.errors import InputError
from robopercept.nn.detection.tiling import (
    check_tiling,
    detect_tiled,
    segment_tiled,
    tile_origins,
    tile_windows,
)


@pytest.mark.parametrize(
    ("length", "tile", "overlap", "expected"),
    [
        (1000, 400, 100, [0, 300, 600]),  # 600 + 400 ends on the edge
        (1001, 400, 100, [0, 300, 600, 601]),  # the last window moved back to the edge
        (400, 400, 100, [0]),
        (120, 400, 100, [0]),  # shorter than a window: one window of the image's side
        (10, 4, 0, [0, 4, 6]),
    ],
)
def test_tile_origins_by_hand(length, tile, overlap, expected):
    assert tile_origins(length, tile, overlap) == expected


@pytest.mark.parametrize(
    ("h", "w", "tile", "overlap"),
    [(2472, 2299, 400, 100), (495, 2299, 400, 100), (10, 10, 400, 0), (333, 1000, 64, 63)],
)
def test_owned_regions_partition_the_image_inside_their_windows(h, w, tile, overlap):
    owners = np.zeros((h, w), int)
    for y0, x0, y1, x1, (ox0, oy0, ox1, oy1) in tile_windows(h, w, tile, overlap):
        assert 0 <= y0 < y1 <= h and 0 <= x0 < x1 <= w
        assert y1 - y0 == min(tile, h) and x1 - x0 == min(tile, w)
        assert y0 <= oy0 < oy1 <= y1 and x0 <= ox0 < ox1 <= x1
        # the pixels whose centres lie in the owned rectangle
        a0, a1 = int(np.ceil(oy0 - 0.5)), int(np.ceil(oy1 - 0.5))
        b0, b1 = int(np.ceil(ox0 - 0.5)), int(np.ceil(ox1 - 0.5))
        owners[a0:a1, b0:b1] += 1
    assert (owners == 1).all()


def _objects(rng: np.random.Generator, h: int, w: int, k: int, side: int) -> np.ndarray:
    x = rng.uniform(0, w - side, k)
    y = rng.uniform(0, h - side, k)
    s = rng.uniform(side / 2, side, k)
    return np.stack([x, y, x + s, y + s], 1)


def _seeing(objects: np.ndarray, offset: tuple[int, int] = (0, 0)):
    """A perfect detector of ``objects`` (image boxes): a window sees each object that
    meets it, clipped to the window (as a real detector reports a cut object), with a
    score falling as less of the object is visible."""

    def detect(window: np.ndarray) -> dict[str, np.ndarray]:
        h, w = window.shape[:2]
        y0, x0 = detect.origin  # type: ignore[attr-defined]
        b = objects - [x0, y0, x0, y0]
        c = b.copy()
        c[:, [0, 2]] = c[:, [0, 2]].clip(0, w)
        c[:, [1, 3]] = c[:, [1, 3]].clip(0, h)
        area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
        seen = (c[:, 2] - c[:, 0]) * (c[:, 3] - c[:, 1]) / area
        keep = seen > 0
        return {
            "boxes": c[keep],
            "labels": np.ones(int(keep.sum()), np.int64),
            "scores": 0.5 + 0.5 * seen[keep] - 1e-3 * np.arange(int(keep.sum())) / len(b),
        }

    detect.origin = offset  # type: ignore[attr-defined]
    return detect


class _Origins:
    """Feeds each window's origin to the fake detector (detect_tiled passes only the
    pixels): windows come in tile_windows' order."""

    def __init__(self, h: int, w: int, tile: int, overlap: int, detect) -> None:
        self.origins = [(y0, x0) for y0, x0, *_ in tile_windows(h, w, tile, overlap)]
        self.detect = detect

    def __call__(self, window: np.ndarray) -> dict[str, np.ndarray]:
        self.detect.origin = self.origins.pop(0)
        return self.detect(window)


@pytest.mark.parametrize("seed", range(5))
def test_each_object_comes_back_once_and_whole(seed):
    # objects up to 60 px, windows of 200 px sharing 80 px: every object lies whole in
    # the window that owns its centre, so the merge returns every box exactly
    rng = np.random.default_rng(seed)
    h, w, tile, overlap = 450, 700, 200, 80
    objects = _objects(rng, h, w, 25, 60)
    image = np.zeros((h, w, 3), np.uint8)
    detect = _Origins(h, w, tile, overlap, _seeing(objects))
    d = detect_tiled(detect, image, tile, overlap, nms_thresh=0.7)
    found = sorted(map(tuple, np.round(d["boxes"], 6)))
    assert found == sorted(map(tuple, np.round(objects, 6)))
    assert np.all(np.diff(d["scores"]) <= 0)  # sorted by decreasing score


def test_small_image_is_one_window():
    calls = []

    def detect(window):
        calls.append(window.shape)
        return {"boxes": np.zeros((0, 4)), "labels": np.zeros(0, int), "scores": np.zeros(0)}

    d = detect_tiled(detect, np.zeros((100, 150, 3)), tile=400)
    assert calls == [(100, 150, 3)] and d["boxes"].shape == (0, 4)


def test_masks_are_placed_in_the_whole_image():
    def detect(window):
        m = np.zeros((1, *window.shape[:2]), bool)
        m[0, 40:60, 40:60] = True
        b = np.array([[40.0, 40, 60, 60]])
        return {"boxes": b, "labels": np.array([1]), "scores": np.array([0.9]), "masks": m}

    d = detect_tiled(detect, np.zeros((100, 190, 3)), tile=100, overlap=10)
    assert d["masks"].shape == (2, 100, 190)
    for b, m in zip(d["boxes"], d["masks"], strict=True):
        ys, xs = np.nonzero(m)
        assert (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1) == tuple(b.astype(int))


@pytest.mark.parametrize(("tile", "overlap"), [(32, 8), (64, 0), (50, 0.5)])
def test_segment_tiled_equals_the_whole_image_for_a_pixelwise_rule(tile, overlap):
    image = np.random.default_rng(0).random((90, 130))
    labels = segment_tiled(lambda im: (im > 0.5).astype(int), image, tile, overlap)
    assert (labels == (image > 0.5)).all()


def test_segment_tiled_takes_each_pixel_from_its_owner():
    # a rule that marks window borders: the owned cores never include another window's
    # first or last overlap/2 pixels, so no pixel away from the image edge is a border
    def border(im):
        out = np.zeros(im.shape[:2], int)
        out[:4], out[-4:], out[:, :4], out[:, -4:] = 1, 1, 1, 1
        return out

    labels = segment_tiled(border, np.zeros((200, 260)), tile=64, overlap=16)
    assert labels[4:-4, 4:-4].sum() == 0


@pytest.mark.parametrize(
    ("tile", "overlap", "match"),
    [
        (8, None, "tile"),
        (100, 100, "smaller than --tile"),
        (100, 0.95, "overlap"),
        (100, -1, "overlap"),
        ("100", None, "tile"),
    ],
)
def test_bad_tiling_names_the_flag(tile, overlap, match):
    with pytest.raises(InputError, match=match):
        check_tiling(tile, overlap)


def test_bad_images_and_windows():
    with pytest.raises(InputError, match="RGB"):
        detect_tiled(lambda im: {}, np.zeros((10, 10)), 64)
    with pytest.raises(InputError, match="shape"):
        segment_tiled(lambda im: np.zeros((3, 3)), np.zeros((40, 40)), 16, 0)
