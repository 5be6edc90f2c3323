"""Mean-shift / CamShift tracking: a moving disc, OpenCV parity, VOT 'bag' against its
ground truth beside OpenCV, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.tracking import MeanShiftTracker
from tests.conftest import data_path


def _scene(centre, radius=15, shape=(120, 160)) -> np.ndarray:
    """A red disc on a green-gray textured background."""
    gen = np.random.default_rng(int(centre[0] * 7 + centre[1]))
    img = np.empty((*shape, 3), dtype=np.uint8)
    img[..., 0] = gen.integers(60, 90, shape)
    img[..., 1] = gen.integers(100, 140, shape)
    img[..., 2] = gen.integers(60, 90, shape)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    disc = (xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= radius**2
    img[disc] = (220, 30, 40)
    return img


@pytest.mark.parametrize("feature", ["hue", "rgb"])
def test_follows_a_moving_disc(feature):
    centre = np.array([40.0, 50.0])
    tracker = MeanShiftTracker(_scene(centre), (25, 35, 30, 30), feature=feature)
    for _ in range(12):
        centre += (4.0, 2.0)  # less than the window's half size per frame
        result = tracker.update(_scene(centre))
        x, y, w, h = result.box
        assert np.hypot(x + (w - 1) / 2 - centre[0], y + (h - 1) / 2 - centre[1]) <= 1.5
        assert result.similarity > 0.8 and result.converged


def test_camshift_adapts_the_size():
    # the first box is the square inscribed in the disc: only red in the model
    tracker = MeanShiftTracker(_scene((80, 60), 12), (72, 52, 17, 17), adaptive=True)
    for r in (14, 17, 20, 23):
        result = tracker.update(_scene((80, 60), r))
    # a disc's second moment gives 4 sqrt(r^2 / 4) = 2 r: the window spans the disc
    assert result.box[2] == pytest.approx(46, abs=3) and result.box[3] == pytest.approx(46, abs=3)


def test_same_windows_as_opencv_with_the_same_histogram():
    """Without background weighting the hue model is OpenCV's (16 bins, S >= 60,
    V >= 32): over a moving disc both put the window within a pixel of each other."""
    cv2 = pytest.importorskip("cv2")
    centre = np.array([40.0, 50.0])
    first = _scene(centre)
    box = (25, 35, 30, 30)
    ours = MeanShiftTracker(first, box, background_weighting=False)
    hsv = cv2.cvtColor(first, cv2.COLOR_RGB2HSV)
    mask = cv2.inRange(hsv, (0, 60, 32), (180, 255, 255))
    hist = cv2.calcHist([hsv[35:65, 25:55]], [0], mask[35:65, 25:55], [16], [0, 180])
    cv2.normalize(hist, hist, 0, 255, cv2.NORM_MINMAX)
    np.testing.assert_allclose(ours._lut, hist.ravel(), atol=0.5)
    window = box
    for _ in range(8):
        centre += (5.0, -3.0)
        frame = _scene(centre)
        hsv = cv2.cvtColor(frame, cv2.COLOR_RGB2HSV)
        bp = cv2.calcBackProject([hsv], [0], hist, [0, 180], 1)
        bp &= cv2.inRange(hsv, (0, 60, 32), (180, 255, 255))
        np.testing.assert_allclose(ours.backproject(frame), bp, atol=1)
        _, window = cv2.meanShift(
            bp, window, (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 10, 1)
        )
        np.testing.assert_allclose(ours.update(frame).box, window, atol=1)


@pytest.mark.realdata
def test_vot_bag_against_ground_truth_and_opencv():
    """VOT 'bag' (a white bag on gravel, 196 frames): mean IoU and centre error with the
    ground-truth boxes, ours beside cv2.meanShift and cv2.CamShift started from the same
    box with the same RGB histogram (8 bins a channel). Measured: ours 0.47 / 20 px
    (mean shift) and 0.55 / 22 px (CamShift) against OpenCV's 0.06 / 140 px and
    0.09 / 45 px; the loose first box teaches OpenCV's plain histogram the gravel, which
    our background weighting leaves out."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.imaging import read_image
    from robopercept.learning.hog_detector import box_iou

    folder = data_path("video", "vot_bag")
    files = sorted(folder.glob("*.jpg"))
    gt = np.loadtxt(folder / "groundtruth.txt", delimiter=",")
    xs, ys = gt[:, 0::2], gt[:, 1::2]
    truth = np.c_[xs.min(1), ys.min(1), np.ptp(xs, axis=1), np.ptp(ys, axis=1)]
    frames = [read_image(f, mode="rgb") for f in files]
    H, W = frames[0].shape[:2]
    x0, y0 = np.maximum(truth[0, :2], 0)
    box = np.round([x0, y0, min(truth[0, 2], W - x0), min(truth[0, 3], H - y0)]).astype(int)
    x, y, w, h = box
    hist = cv2.calcHist([frames[0][y : y + h, x : x + w]], [0, 1, 2], None, [8] * 3, [0, 256] * 3)
    cv2.normalize(hist, hist, 0, 255, cv2.NORM_MINMAX)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 10, 1)

    def scores(boxes):
        boxes = np.asarray(boxes, dtype=float)
        iou = np.array([box_iou(t, b[None])[0] for t, b in zip(truth[1:], boxes, strict=True)])
        centre = np.hypot(*(boxes[:, :2] + boxes[:, 2:] / 2 - truth[1:, :2] - truth[1:, 2:] / 2).T)
        return iou.mean(), centre.mean()

    for adaptive, cv_step in ((False, cv2.meanShift), (True, cv2.CamShift)):
        ours = MeanShiftTracker(frames[0], box, feature="rgb", adaptive=adaptive)
        window, ref = tuple(int(v) for v in box), []
        mine = []
        for frame in frames[1:]:
            mine.append(ours.update(frame).box)
            bp = cv2.calcBackProject([frame], [0, 1, 2], hist, [0, 256] * 3, 1)
            window = cv_step(bp, window, crit)[1]
            ref.append(window)
        (iou, err), (ref_iou, ref_err) = scores(mine), scores(ref)
        assert iou >= ref_iou and err <= ref_err, (adaptive, iou, err, ref_iou, ref_err)
        assert iou > 0.4


def test_bad_input():
    frame = _scene((40, 50))
    with pytest.raises(InputError, match="not inside"):
        MeanShiftTracker(frame, (150, 10, 30, 30))
    with pytest.raises(InputError, match="4 finite numbers"):
        MeanShiftTracker(frame, (1, 2, 3))
    with pytest.raises(InputError, match="RGB"):
        MeanShiftTracker(frame[..., 0], (10, 10, 20, 20))
    gray = np.full((50, 50, 3), 128, dtype=np.uint8)
    with pytest.raises(InputError, match="no usable colour"):
        MeanShiftTracker(gray, (10, 10, 20, 20))
    with pytest.raises(InputError, match="feature"):
        MeanShiftTracker(frame, (10, 10, 20, 20), feature="hog")


# issue 25: scalar parameters reached int()/float() unchecked (TypeError on a list,
# ValueError on NaN) and max_iter / bins had no upper bound
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"min_value": [1, 2]}, "min_value must be an integer"),
        ({"min_saturation": np.nan}, "min_saturation must be an integer"),
        ({"min_value": 300}, "min_value must be in 0..255"),
        ({"max_iter": 2**40}, "max_iter must be in 1..10000"),
        ({"bins": 2**40}, "bins must be in 1..256"),
        ({"eps": "3"}, "eps must be a real number"),
        ({"adaptive": "yes"}, "adaptive must be True or False"),
        ({"background_weighting": None}, "background_weighting must be True or False"),
        ({"feature": ["hue"]}, "feature must be one of"),
        ({"box": "abcd"}, "box must hold real numbers"),
    ],
)
def test_hostile_parameters_are_refused_by_name(kwargs, match):
    args = {"box": (10, 10, 20, 20), **kwargs}
    with pytest.raises(InputError, match=match):
        MeanShiftTracker(_scene((40, 50)), **args)
