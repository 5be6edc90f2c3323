"""track_objects / run_mot: the multi-object tracking loop equals the tracker driven by
hand, from a detection file or from background subtraction."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.motion import GaussianBackground, detections_from_mask, moving_blobs
from robopercept.pipelines import run_mot, track_objects
from robopercept.tracking import MotRows, MultiObjectTracker, read_mot, write_mot
from tests.conftest import data_path


def _blank(n, shape=(96, 128)):
    return [(i, np.zeros((*shape, 3), np.uint8)) for i in range(n)]


def _detections(n=12, seed=0):
    gen = np.random.default_rng(seed)
    rows = []
    for t in range(n):
        if t == 6:
            continue  # a missed detection
        x, y = 25 + 4 * t + gen.normal(0, 0.5), 35 + 2 * t + gen.normal(0, 0.5)
        rows.append((t + 1, -1, (x, y, 30.0, 30.0), 0.9))
        rows.append((t + 1, -1, (100.0, 70.0, 20.0, 20.0), 0.2))  # weak clutter
    frame = np.array([r[0] for r in rows])
    boxes = np.array([r[2] for r in rows])
    conf = np.array([r[3] for r in rows])
    return MotRows(frame, -np.ones(len(rows), int), boxes, conf, np.zeros((len(rows), 0)))


def test_rows_equal_the_tracker_driven_by_hand():
    det = _detections()
    got = run_mot(_blank(12), det, min_score=0.5)
    tracker = MultiObjectTracker()
    expected = []
    for number in range(1, 13):
        d = det.at(number)
        keep = d.conf >= 0.5
        for t in tracker.update(d.boxes[keep], d.conf[keep]):
            expected.append((number, t.id, t.box, t.score))
    assert len(got) == len(expected) > 0
    for g, e in zip(got, expected, strict=True):
        assert g[:2] == e[:2] and np.array_equal(g[2], e[2]) and g[3] == e[3]
    assert {r[1] for r in got} == {1}  # the clutter (score 0.2) never becomes a track


def test_frames_carry_their_detections_image_and_number():
    det = _detections(4)
    frames = _blank(4)
    steps = list(track_objects(frames, det))
    assert [s.number for s in steps] == [1, 2, 3, 4]
    assert [s.index for s in steps] == [0, 1, 2, 3]
    assert all(len(s.boxes) == 2 and s.image is frames[k][1] for k, s in enumerate(steps))
    assert steps[0].rows == [(1, t.id, t.box, t.score) for t in steps[0].tracks]


def test_a_given_tracker_is_driven():
    tracker = MultiObjectTracker(min_hits=1, max_age=0)
    list(track_objects(_blank(3), _detections(3), tracker=tracker))
    assert tracker.frame == 3


def test_background_subtraction_when_no_detections_are_given():
    frames, _ = moving_blobs(30, (128, 96), n_blobs=2, radius=(9.0, 11.0), speed=2.0,
                             illumination_drift=0.0, rng=3)  # fmt: skip
    rgb = [np.repeat(f[..., None], 3, axis=2) for f in frames]
    steps = list(track_objects(enumerate(rgb), min_area=50))
    background, tracker = GaussianBackground(), MultiObjectTracker()
    for f, step in zip(rgb, steps, strict=True):
        d = detections_from_mask(background.apply(f), 50)
        np.testing.assert_array_equal(step.boxes, d.boxes)
        assert (step.scores == 1).all()
        assert [t.id for t in step.tracks] == [t.id for t in tracker.update(d.boxes, step.scores)]
    ids = {r[1] for s in steps for r in s.rows}
    assert len(ids) >= 2 and min(s.number for s in steps if s.tracks) >= 21  # model learns


def test_bad_min_area():
    with pytest.raises(InputError, match="min_area"):
        next(track_objects(_blank(1), min_area=0))


@pytest.mark.realdata
def test_mot17_rows_round_trip_through_write_mot(tmp_path):
    seq = data_path("video", "mot17_mini", "MOT17-04-FRCNN")
    det = read_mot(seq / "det" / "det.txt")
    rows = run_mot(_blank(8, (1080, 1920)), det, min_score=0.5)
    assert write_mot(tmp_path / "r.txt", rows) == len(rows) > 100
    back = read_mot(tmp_path / "r.txt")
    np.testing.assert_allclose(back.boxes, np.array([r[2] for r in rows]), atol=0.006)


# issue 25: arguments of the wrong type are refused at the call, typed
@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"min_area": None}, "min_area must be an integer; got None"),
        ({"min_area": np.inf}, "min_area must be an integer; got inf"),
        ({"min_area": [1, 2]}, "min_area must be an integer"),
        ({"detections": np.nan}, "detections must be MotRows"),
        ({"detections": []}, "detections must be MotRows"),
        ({"tracker": 3}, "tracker must be a MultiObjectTracker or None; got int"),
        ({"tracker": {}}, "tracker must be a MultiObjectTracker or None; got dict"),
        ({"min_score": "0.5"}, "min_score must be a real number"),
    ],
)
def test_bad_arguments_are_refused_at_the_call(kwargs, words):
    with pytest.raises(InputError, match=words):
        track_objects(_blank(2), **kwargs)  # not even iterated: refused at once
    with pytest.raises(InputError, match=words):
        run_mot(_blank(2), **kwargs)


def test_bad_frames():
    with pytest.raises(InputError, match="frames must be an iterable of"):
        track_objects(None)
    with pytest.raises(InputError, match=r"each item of frames must be an \(index, image\) pair"):
        run_mot([np.zeros((4, 4, 3))], _detections())
    with pytest.raises(InputError, match="the frame index must be >= 0"):
        run_mot([(-1, np.zeros((4, 4, 3)))], _detections())
    # numpy scalars are numbers: the same rows as Python ones
    ref = run_mot(_blank(12), _detections(), min_score=0.5)
    got = run_mot(_blank(12), _detections(), min_score=np.float32(0.5), min_area=np.int64(7))
    assert [(n, i) for n, i, _, _ in got] == [(n, i) for n, i, _, _ in ref]
