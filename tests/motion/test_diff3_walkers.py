"""Three-frame differencing (issue 30): its defaults find the walkers of PETS 2009,
its hole filling matches SciPy, its gap and clean-up settings are checked.

How walkers are counted (PETS 2009 S2.L1 comes here without ground truth): the
walkers of frames 20, 40 and 60 were boxed by hand, one box per person (people in a
group split at the gap between them), from the frames and a temporal-median
background; the person standing behind the sign post at frame 20 (head and feet
only) is left out. A walker is *found* when at least a fifth of its box is covered
by blobs of at least ``MIN_AREA`` pixels (the ``bgsub --min-area`` default), and a
blob that touches no walker box is a false blob.
"""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.imaging.blobs import label_components
from robopercept.motion import ThreeFrameDifference, fill_holes
from tests.conftest import data_path

MIN_AREA = 100
COVER = 0.2
#: frame -> hand-drawn walker boxes (x, y, w, h) in the 480x360 video
WALKERS = {
    20: [(227, 121, 23, 53), (273, 145, 29, 55), (424, 170, 28, 66), (455, 173, 17, 59)],
    40: [(235, 111, 15, 54), (249, 111, 18, 54), (273, 121, 14, 50), (351, 147, 26, 60),
         (376, 147, 20, 60), (460, 176, 20, 71)],
    60: [(230, 106, 9, 60), (238, 106, 12, 60), (250, 106, 17, 60), (291, 127, 22, 56),
         (314, 127, 18, 56), (385, 148, 22, 66)],
}  # fmt: skip


def walkers_found(mask: np.ndarray, boxes, min_area: int = MIN_AREA, cover: float = COVER):
    """(walkers found, false blobs) of ``mask`` against the hand-drawn ``boxes``."""
    labels, n = label_components(mask, 8)
    areas = np.bincount(labels.ravel(), minlength=n + 1)
    areas[0] = 0
    kept = (areas >= min_area)[labels]
    found = sum(kept[y : y + h, x : x + w].mean() >= cover for x, y, w, h in boxes)
    inside = np.zeros(mask.shape, dtype=bool)
    for x, y, w, h in boxes:
        inside[y : y + h, x : x + w] = True
    touching = np.unique(labels[kept & inside])
    false = int(np.count_nonzero(areas >= min_area)) - touching.size
    return int(found), false


def test_walkers_found_counts_a_hand_case():
    mask = np.zeros((40, 60), dtype=bool)
    mask[5:15, 5:15] = True  # covers all of walker 1
    mask[30:32, 40:60] = True  # 40 px: too small to count
    mask[20:35, 0:10] = True  # 150 px, touches no walker: one false blob
    boxes = [(5, 5, 10, 10), (40, 28, 20, 10)]
    assert walkers_found(mask, boxes) == (1, 1)
    assert walkers_found(mask, boxes, min_area=10) == (2, 1)


@pytest.fixture(scope="module")
def pets_gray():
    """Frames 0..63 of PETS 2009 S2.L1 (gray uint8)."""
    from robopercept.imaging import VideoReader, rgb_to_gray

    path = data_path("video", "pets2009_vtest", "vtest_480x360.avi")
    frames = []
    with VideoReader(path) as video:
        for t, frame in enumerate(video):
            if t == 64:
                break
            frames.append(rgb_to_gray(frame))
    return frames


def _masks(model, frames, wanted):
    out = {}
    for t, frame in enumerate(frames):
        mask = model.apply(frame)
        if t - model.delay in wanted:
            out[t - model.delay] = mask
    return out


@pytest.mark.realdata
def test_diff3_defaults_find_the_walkers_of_pets(pets_gray):
    """Issue 30: `diff3` found 1 of about 8 walkers. With the old settings (gap 1,
    threshold 25, no closing or filling) 0 of the 16 hand-marked walkers are found;
    with the defaults (gap 3, threshold 15, 5x5 closing, holes filled) 15 of 16 (all 6
    at frame 40, 5 of 6 at frame 60, where one of the group stands still), with at
    most one false blob a frame."""
    new = _masks(ThreeFrameDifference(), pets_gray, WALKERS)
    old = _masks(ThreeFrameDifference(25.0, gap=1, closing=1, fill=False), pets_gray, WALKERS)
    found = {t: walkers_found(new[t], boxes) for t, boxes in WALKERS.items()}
    found_old = {t: walkers_found(old[t], boxes)[0] for t, boxes in WALKERS.items()}
    assert found[40][0] == 6 and found[60][0] >= 5 and found[20][0] == 4, found
    assert sum(f for f, _ in found.values()) >= 14
    assert all(false <= 1 for _, false in found.values()), found
    assert sum(found_old.values()) <= 2, found_old
    # the mask stays a small part of the picture (walkers, not the whole scene)
    assert all(m.mean() < 0.05 for m in new.values())


def test_fill_holes_matches_scipy():
    """Parity with scipy.ndimage.binary_fill_holes (its default cross structure: the
    background 4-connected), exactly, on random masks and the edge cases."""
    from scipy import ndimage

    gen = np.random.default_rng(0)
    for density in (0.3, 0.5, 0.7):
        mask = gen.random((40, 50)) < density
        np.testing.assert_array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask))
    ring = np.zeros((7, 7), bool)
    ring[1:6, 1:6] = True
    ring[2:5, 2:5] = False
    assert fill_holes(ring)[1:6, 1:6].all() and fill_holes(ring).sum() == 25
    diagonal = np.eye(5, dtype=bool)  # no hole: the background is 4-connected round it
    np.testing.assert_array_equal(fill_holes(diagonal), ndimage.binary_fill_holes(diagonal))
    assert fill_holes(np.zeros((0, 3), bool)).shape == (0, 3)
    assert fill_holes(np.ones((3, 3), np.uint8)).all()
    with pytest.raises(InputError, match="bool"):
        fill_holes(np.zeros((3, 3), np.float32))
    with pytest.raises(InputError, match="mask"):
        fill_holes(np.zeros((3, 3, 3), bool))


def test_gap_delays_the_answer_and_keeps_no_ghost():
    """A square moving 4 px a frame: with gap g, apply(frame t) answers for frame
    t - g; the square there is found whole, and nothing where it was or will be."""
    frames = np.full((12, 20, 80), 40, np.uint8)
    truth = np.zeros(frames.shape, bool)
    for t in range(12):
        frames[t, 5:15, 4 * t : 4 * t + 10] = 220
        truth[t, 5:15, 4 * t : 4 * t + 10] = True
    for gap in (1, 2, 3):
        model = ThreeFrameDifference(gap=gap, noise=None, closing=1, fill=False)
        assert model.delay == gap
        masks = [model.apply(f) for f in frames]
        assert not any(m.any() for m in masks[: 2 * gap])
        t = 2 * gap + 2
        expected = truth[t - gap] & ~truth[t - 2 * gap] & ~truth[t]
        np.testing.assert_array_equal(masks[t], expected)
        # after the last frame (11), the next answer is for frame 12 - gap
        np.testing.assert_array_equal(model.background, frames[len(frames) - gap])


def test_closing_and_filling_make_a_body_whole():
    """A ring-shaped difference (a uniform body shows only its outline) is filled."""
    frames = np.zeros((3, 30, 30), np.uint8)
    frames[1, 5:25, 5:25] = 200
    frames[1, 8:22, 8:22] = 0  # only the 3-px outline differs from frames 0 and 2
    plain = ThreeFrameDifference(gap=1, closing=1, fill=False)
    whole = ThreeFrameDifference(gap=1)
    for f in frames:
        a, b = plain.apply(f), whole.apply(f)
    assert a.sum() < 300 and b[5:25, 5:25].sum() >= 400 - 4
    assert not b[:4].any() and not b[26:].any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gap": 0}, "gap must be"),
        ({"gap": 10_001}, r"gap must be in 1\.\.10000"),
        ({"gap": 2.5}, "gap must be an integer"),
        ({"closing": 4}, "closing must be an odd integer"),
        ({"closing": 0}, "closing must be"),
        ({"closing": 257}, "closing must be an odd integer in 1..255"),
        ({"fill": "yes"}, "fill must be"),
        ({"threshold": 0}, "threshold must be a positive number"),
    ],
)
def test_diff3_bad_settings(kwargs, match):
    with pytest.raises(InputError, match=match):
        ThreeFrameDifference(**kwargs)
