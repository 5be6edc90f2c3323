"""KLTTracker: corners followed through frames with trails, identities and re-detection."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.imaging import gaussian_blur, rgb_to_gray
from robopercept.motion import KLTTracker, good_features_to_track, lucas_kanade


def _texture(shape=(200, 240), seed=0):
    noise = np.random.default_rng(seed).uniform(0, 1, shape)
    t = gaussian_blur(noise, 2.0)
    return np.round(255 * (t - t.min()) / np.ptp(t)).astype(np.uint8)


def _shifted(tex, n, step=(2, 1), size=(120, 160)):
    """Windows of ``tex`` moving by ``-step`` px per frame: the scene moves by ``+step``."""
    h, w = size
    return [tex[40 - step[1] * t : 40 - step[1] * t + h, 40 - step[0] * t : 40 - step[0] * t + w]
            for t in range(n)]  # fmt: skip


def test_first_frame_detects_the_shi_tomasi_corners():
    frame = _shifted(_texture(), 1)[0]
    step = KLTTracker(max_corners=80, min_distance=7.0).update(frame)
    expected = good_features_to_track(frame, 80, 0.01, 7.0)
    np.testing.assert_array_equal(step.points, expected)
    assert step.ids.tolist() == list(range(1, len(expected) + 1))
    assert step.motion is None and step.redetected and step.frame == 0


def test_second_frame_equals_lucas_kanade_and_keeps_tracked_points():
    a, b = _shifted(_texture(), 2)
    tracker = KLTTracker(max_corners=80, window=15, levels=2)
    first = tracker.update(a)
    second = tracker.update(b)
    res = lucas_kanade(a, b, first.points, window=15, levels=2)
    np.testing.assert_array_equal(second.ids, first.ids[res.status])
    np.testing.assert_array_equal(second.points, res.end[res.status])
    for trail, p0 in zip(second.trails, first.points[res.status], strict=True):
        assert trail.shape == (2, 2) and np.array_equal(trail[0], p0)


def test_translation_is_followed_and_trails_are_capped():
    frames = _shifted(_texture(), 8)
    tracker = KLTTracker(max_corners=60, trail=5)
    steps = [tracker.update(f) for f in frames]
    assert [s.motion for s in steps[1:]] == ["translation"] * 7
    last = steps[-1]
    assert all(len(t) <= 5 for t in last.trails) and max(len(t) for t in last.trails) == 5
    moves = np.diff(np.stack([t for t in last.trails if len(t) == 5]), axis=1)
    np.testing.assert_allclose(np.median(moves.reshape(-1, 2), axis=0), [2.0, 1.0], atol=0.05)
    assert tracker.redetections == 1 and tracker.frame_count == 8


def test_rgb_frames_are_tracked_as_their_gray():
    frames = _shifted(_texture(), 3)
    rgb = [np.repeat(f[..., None], 3, axis=2) for f in frames]
    t_gray, t_rgb = KLTTracker(max_corners=40), KLTTracker(max_corners=40)
    for g, c in zip(frames, rgb, strict=True):  # the same frames, gray and RGB
        assert np.array_equal(rgb_to_gray(c), g)
        a, b = t_gray.update(g), t_rgb.update(c)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.ids, b.ids)


def test_lost_points_are_replaced_with_new_identities():
    tex, other = _texture(seed=0), _texture(seed=1)
    tracker = KLTTracker(max_corners=50, min_distance=7.0)
    first = tracker.update(tex[:120, :160])
    second = tracker.update(other[:120, :160])  # another scene: most points are lost
    assert second.redetected and tracker.redetections == 2
    new = second.ids[second.ids > first.ids.max()]
    assert new.size > 0 and len(second) <= 50
    assert len(np.unique(second.ids)) == len(second)  # identities never repeat
    pts = second.points
    d = np.hypot(*(pts[:, None] - pts[None]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    kept = ~np.isin(second.ids, new)
    if kept.any():  # new corners keep min_distance from the kept points
        assert d[np.ix_(~kept, kept)].min() >= 7.0


def test_a_frame_of_another_size_is_refused_naming_it():
    frames = _shifted(_texture(), 2)
    tracker = KLTTracker()
    tracker.update(frames[0])
    with pytest.raises(InputError, match="frame 1 is 100x120, the previous one 160x120"):
        tracker.update(frames[1][:, :100])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"max_corners": 0}, "max_corners"),
        ({"quality": 0.0}, "quality"),
        ({"min_distance": -1.0}, "min_distance"),
        ({"window": 20}, "window"),
        ({"levels": -1}, "levels"),
        ({"trail": 0}, "trail"),
        # issue 25: strings were parsed as numbers
        ({"quality": "0.5"}, "quality must be a real number"),
        ({"min_distance": "7"}, "min_distance must be a real number"),
    ],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises(InputError, match=match):
        KLTTracker(**kwargs)


def test_not_an_image_is_refused():
    with pytest.raises(InputError):
        KLTTracker().update(np.zeros((3, 40, 50)))
