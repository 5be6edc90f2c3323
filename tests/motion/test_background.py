"""Background subtraction and differencing: synthetic ground truth, ghosts, the mask
clean-up, detections, bad input, and real videos."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.motion import (
    AveragedBackground,
    FrameDifference,
    GaussianBackground,
    StaticBackground,
    ThreeFrameDifference,
    clean_mask,
    detections_from_mask,
    moving_blobs,
)
from tests.conftest import data_path


def _f1(pred: np.ndarray, truth: np.ndarray) -> float:
    tp = np.sum(pred & truth)
    return 2 * tp / (2 * tp + np.sum(pred & ~truth) + np.sum(~pred & truth))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gaussian_background_f1_on_moving_blobs(seed):
    """Discs over a texture with noise (std 4) and a 25 % brightness ramp: after the
    20 initial frames every frame's foreground F1 is >= 0.9 (measured >= 0.99)."""
    frames, masks = moving_blobs(70, rng=seed)
    model = GaussianBackground(k=2.5, learning_rate=0.02, init_frames=20)
    scores = []
    for t, frame in enumerate(frames):
        mask = model.apply(frame)
        assert mask.shape == frame.shape and mask.dtype == bool
        if t < 20:
            assert not mask.any()  # still learning (the 20th frame completes it)
        else:
            scores.append(_f1(mask, masks[t]))
    assert min(scores) >= 0.9, min(scores)
    # the illumination ramp was followed as a running average follows it: on pixels
    # no disc ever covers, the background's mean is the scalar recursion
    # b <- b + alpha (m_t - b) of the frame means m_t, started at their median
    clear = ~masks.any(axis=0)
    means = [float(np.mean(f[clear])) for f in frames]
    expected = float(np.median(means[:20]))
    for m in means[20:]:
        expected += 0.02 * (m - expected)
    assert np.mean(model.background[clear]) == pytest.approx(expected, abs=1.0)
    assert expected > 1.1 * means[0]  # and it did brighten


def test_without_its_update_the_ramp_breaks_the_static_model():
    """The same scene against a fixed reference: the 25 % brightening turns background
    into foreground, which the running update of the Gaussian model avoids."""
    frames, masks = moving_blobs(70, rng=0)
    clear = np.median(frames[:20], axis=0).astype(np.uint8)  # an empty reference
    static = StaticBackground(clear, threshold=12)
    f1 = [_f1(static.apply(f), m) for f, m in zip(frames, masks, strict=True)]
    assert f1[20] > 0.9 and f1[-1] < 0.6


def test_averaged_background_is_the_mean():
    gen = np.random.default_rng(1)
    frames = gen.integers(0, 256, (5, 20, 30)).astype(np.uint8)
    model = AveragedBackground(n_frames=4, threshold=10, noise=None)
    for t in range(4):
        assert not model.apply(frames[t]).any() and model.ready == (t == 3)
    np.testing.assert_allclose(model.background, frames[:4].mean(axis=0), atol=1e-4)
    mask = model.apply(frames[4])
    np.testing.assert_array_equal(mask, np.abs(frames[4] - frames[:4].mean(0)) > 10)


def test_static_background_hand_case_and_colour():
    ref = np.full((10, 12, 3), 100, dtype=np.uint8)
    frame = ref.copy()
    frame[2:6, 3:8, 1] = 160  # one channel changes: the pixel is foreground
    frame[8, 10] = 200  # a single pixel: removed by the majority filter
    model = StaticBackground(ref, threshold=30)
    expected = np.zeros((10, 12), dtype=bool)
    expected[2:6, 3:8] = True
    mask = model.apply(frame)
    # the 3x3 majority vote keeps the rectangle (its corners see 4 of 9, but at an
    # image border... none here) except the four corner pixels
    expected_clean = expected.copy()
    for y, x in ((2, 3), (2, 7), (5, 3), (5, 7)):
        expected_clean[y, x] = False
    np.testing.assert_array_equal(mask, expected_clean)
    raw = StaticBackground(ref, threshold=30, noise=None).apply(frame)
    assert raw[8, 10] and raw[2:6, 3:8].all()
    float_mask = StaticBackground(ref / 255.0, threshold=30).apply(frame / 255.0)
    np.testing.assert_array_equal(float_mask, mask)


def test_clean_mask_majority_equals_median_filter():
    from scipy.ndimage import median_filter

    gen = np.random.default_rng(2)
    mask = gen.uniform(size=(40, 50)) < 0.4
    for size in (3, 5):
        ours = clean_mask(mask, "median", size)
        ref = median_filter(mask.astype(np.uint8), size, mode="constant", cval=0) > 0
        # inside the image the majority vote is the median; at the border ours votes
        # with the pixels inside, the reference pads zeros
        r = size // 2
        np.testing.assert_array_equal(ours[r:-r, r:-r], ref[r:-r, r:-r])
    speck = np.zeros((20, 20), dtype=bool)
    speck[5, 5] = True
    speck[10:15, 10:15] = True
    opened = clean_mask(speck, "open-close", 3)
    assert not opened[5, 5] and opened[10:15, 10:15].all()
    with pytest.raises(InputError, match="noise"):
        clean_mask(speck, "gaussian")


def _moving_square(n: int = 5, step: int = 20) -> tuple[np.ndarray, list[np.ndarray]]:
    """A bright 15-px square moving right by ``step`` px per frame on a flat background."""
    frames = np.full((n, 60, 160), 50, dtype=np.uint8)
    truth = []
    for t in range(n):
        frames[t, 20:35, 10 + step * t : 25 + step * t] = 200
        m = np.zeros((60, 160), dtype=bool)
        m[20:35, 10 + step * t : 25 + step * t] = True
        truth.append(m)
    return frames, truth


def test_three_frame_differencing_removes_the_ghost():
    """Two-frame differencing marks the square where it is and where it was (the
    ghost); three-frame differencing marks only where it is."""
    frames, truth = _moving_square()
    two = FrameDifference(n=1, noise=None)
    # gap 1 and no closing/filling: the plain three-frame AND of the textbook
    three = ThreeFrameDifference(25.0, gap=1, noise=None, closing=1, fill=False)
    masks2 = [two.apply(f) for f in frames]
    masks3 = [three.apply(f) for f in frames]
    assert not masks2[0].any() and not masks3[0].any() and not masks3[1].any()
    t = 3
    assert np.array_equal(masks2[t], truth[t] | truth[t - 1])  # object + ghost
    assert masks2[t][truth[t - 1]].all()  # the ghost is there
    # apply(frame t + 1) answers for frame t: exactly the square, no ghost
    assert np.array_equal(masks3[t + 1], truth[t])
    assert not masks3[t + 1][truth[t - 1]].any() and not masks3[t + 1][truth[t + 1]].any()


def test_frame_difference_n_steps_back():
    frames, truth = _moving_square(step=5)
    model = FrameDifference(n=2, noise=None)
    masks = [model.apply(f) for f in frames]
    assert not masks[1].any()
    # 10 px of motion for a 15 px square: only the non-overlapping strips change
    np.testing.assert_array_equal(masks[2], truth[2] ^ truth[0])
    np.testing.assert_array_equal(model.background, frames[3].astype(np.float32))


def test_detections_from_mask():
    mask = np.zeros((50, 60), dtype=bool)
    mask[5:15, 10:30] = True  # 200 px
    mask[30:34, 40:44] = True  # 16 px
    det = detections_from_mask(mask, min_area=10)
    assert len(det) == 2
    np.testing.assert_array_equal(det.boxes[0], [10, 5, 20, 10])
    np.testing.assert_allclose(det.centroids[0], [19.5, 9.5])
    assert det.areas.tolist() == [200, 16]
    assert len(detections_from_mask(mask, min_area=100)) == 1
    assert len(detections_from_mask(np.zeros((5, 5), bool))) == 0
    with pytest.raises(InputError):
        detections_from_mask(np.zeros((2, 2, 2)))


def test_bad_input():
    model = GaussianBackground(init_frames=1)
    model.apply(np.zeros((20, 30), np.uint8))
    with pytest.raises(InputError, match="frame 1 has shape"):
        model.apply(np.zeros((21, 30), np.uint8))
    with pytest.raises(InputError, match="learning_rate"):
        GaussianBackground(learning_rate=0.0)
    with pytest.raises(InputError, match="threshold"):
        StaticBackground(np.zeros((4, 4)), threshold=-1)
    with pytest.raises(InputError, match="n must"):
        FrameDifference(n=0)
    with pytest.raises(InputError, match="uint8 or float"):
        StaticBackground(np.zeros((4, 4), np.uint16))


@pytest.mark.realdata
@pytest.mark.parametrize(
    ("name", "frames"), [("pets2009_vtest/vtest_480x360.avi", 60), ("opencv_tree", 40)]
)
def test_models_run_on_real_videos(name, frames):
    """Every model runs on the real sequences and marks less than half the picture,
    and each finds some foreground (the walkers; the swaying tree: measured on the
    tree, Gaussian 7.2 %, average 3.1 %, two-frame 2.1 %, three-frame 0.3 %)."""
    from robopercept.imaging import VideoReader

    path = data_path("video", name)
    if path.is_dir():
        path = sorted(p for p in path.iterdir() if p.suffix in (".avi", ".mp4"))[0]
    models = [GaussianBackground(init_frames=10), AveragedBackground(10), FrameDifference(),
              ThreeFrameDifference()]  # fmt: skip
    shares = np.zeros(len(models))
    with VideoReader(path) as video:
        for t, frame in enumerate(video):
            if t == frames:
                break
            for k, m in enumerate(models):
                mask = m.apply(frame)
                if t >= 12:
                    shares[k] += mask.mean()
    shares /= frames - 12
    assert (shares > 0).all() and (shares < 0.5).all(), shares


def test_check_threshold_names_the_unit():
    from robopercept.motion.background import check_threshold

    assert check_threshold(12) == 12.0
    with pytest.raises(InputError, match=r"threshold must be a positive number \(0-255 scale\)"):
        check_threshold(0)
    with pytest.raises(InputError, match=r"k must be .*\(standard deviations\); got -1"):
        check_threshold(-1, "k", "standard deviations")
    with pytest.raises(InputError, match="standard deviations"):
        GaussianBackground(k=-1)


def test_foreground_model_checks_frame_shapes():
    from robopercept.motion.background import ForegroundModel

    model = ForegroundModel("median", 3)
    first = model._frame(np.zeros((4, 5), np.uint8))
    assert first.shape == (4, 5) and model.frame_count == 1
    with pytest.raises(InputError, match=r"frame 1 has shape \(5, 4\), the first had \(4, 5\)"):
        model._frame(np.zeros((5, 4), np.uint8))
    with pytest.raises(InputError, match="noise must be one of"):
        ForegroundModel("blur", 3)


# issue 25: scalar settings reached int()/float()/np.isfinite unchecked (TypeError on
# None, ValueError on NaN or a list), noise sizes had no bound (a 2**40 structuring
# element) and masks of any dtype or rank reached the compiled vote
_MASK = np.zeros((12, 16), dtype=bool)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: AveragedBackground(n_frames=None), "n_frames must be an integer"),
        (lambda: FrameDifference(n=np.nan), "n must be an integer"),
        (lambda: FrameDifference(n=2**63), "n must be in 1..10000 frames"),
        (lambda: GaussianBackground(k=[1, 2]), "k must be a real number"),
        (lambda: GaussianBackground(learning_rate="0.5"), "learning_rate must be a real"),
        (lambda: GaussianBackground(min_std=1e30), "min_std must be at most 1e6"),
        (lambda: StaticBackground(_MASK.astype(np.uint8), threshold=[1, 2]), "threshold must"),
        (lambda: ThreeFrameDifference(noise_size=2**40 + 1), "noise_size must be an odd"),
        (lambda: ThreeFrameDifference(noise=b"median"), "noise must be one of"),
        (lambda: ThreeFrameDifference(noise_size=4), "noise_size must be an odd"),
        (lambda: clean_mask(_MASK, size=-np.inf), "size must be an odd integer"),
        (lambda: clean_mask(_MASK, "open-close", 2**40 + 1), "size must be an odd integer in"),
        (lambda: clean_mask(np.zeros((3, 9, 14, 1), np.float32)), "mask must be 2-D"),
        (lambda: clean_mask(np.zeros((9, 14), np.float16)), "mask must be a bool"),
        (lambda: detections_from_mask(_MASK, min_area=-np.inf), "min_area must be an integer"),
        (lambda: detections_from_mask(_MASK, connectivity=6), "connectivity must be one of"),
        (lambda: detections_from_mask(np.full((4, 4), "a")), "mask must be a bool"),
        (lambda: moving_blobs(3, (64, 48), noise_std=-723785), "noise_std must be in"),
        (lambda: moving_blobs(3, (3, 48)), "size must be"),
        (lambda: moving_blobs(3, (64, 48), radius=(4.0, 30.0)), "radius must be"),
        (lambda: moving_blobs(np.float32(2.0), (64, 48)), "n_frames must be an integer"),
        (lambda: moving_blobs(3, (64, 48), n_blobs=-1), "n_blobs must be >= 0"),
        (lambda: moving_blobs(2**20, (640, 480)), "n_frames x width x height"),
        (lambda: moving_blobs(3, (64, 48), rng=np.nan), "rng must be an int seed"),
        (lambda: moving_blobs(3, (64, 48), rng=-1), "rng must be an int seed >= 0"),
    ],
)
def test_hostile_settings_are_refused_by_name(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_integer_masks_and_size_one_still_clean():
    # issue 25: a 0/1 integer mask is read as mask != 0; size 1 leaves the mask as it is
    m = np.zeros((9, 9), dtype=bool)
    m[4, 4] = True  # an isolated pixel
    m[0:4, 0:4] = True
    np.testing.assert_array_equal(clean_mask(m, size=1), m)
    np.testing.assert_array_equal(clean_mask(m.astype(np.uint8) * 255), clean_mask(m))
    assert not clean_mask(m)[4, 4] and clean_mask(m)[1, 1]
