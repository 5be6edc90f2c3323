"""Tracking metrics: VOT ground truth and the success curve, CLEAR-MOT and IDF1 on hand
cases, parity with py-motmetrics (its TUD data, random sequences, MOT17), bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.geometry import box_iou_matrix
from robopercept.tracking import MotRows, MultiObjectTracker, read_mot
from robopercept.tracking.metrics import (
    OTB_THRESHOLDS,
    MotAccumulator,
    evaluate_mot,
    evaluate_single_object,
    paired_iou,
    polygons_to_boxes,
    read_vot_groundtruth,
    select_ground_truth,
    success_plot,
)
from tests.conftest import data_path


@pytest.fixture(scope="module")
def mm():
    """py-motmetrics with its NumPy-2 shim: motmetrics 1.4.0 still calls np.asfarray,
    which NumPy 2 removed. The shim lives here, in the tests, never in src."""
    motmetrics = pytest.importorskip("motmetrics")
    if not hasattr(np, "asfarray"):
        np.asfarray = lambda a, dtype=np.float64: np.asarray(a, dtype=dtype)  # noqa: NPY201
    return motmetrics


def _tud(mm, name: str) -> Path:
    folder = Path(mm.__file__).parent / "data" / name
    if not (folder / "gt.txt").is_file():
        pytest.skip(f"motmetrics ships no {name} data here ({folder})")
    return folder


def _mm_summary(mm, acc) -> dict[str, float]:
    names = ["mota", "motp", "idf1", "idp", "idr", "precision", "recall", "num_switches"]
    names += ["num_false_positives", "num_misses", "num_matches", "num_objects"]
    names += ["num_predictions", "num_frames", "num_unique_objects", "idtp", "idfp", "idfn"]
    summary = mm.metrics.create().compute(acc, metrics=names)
    return {k: float(summary[k].iloc[0]) for k in names}


def _assert_same(ours: dict, theirs: dict) -> None:
    for key, want in theirs.items():
        got = ours[key]
        if key.startswith(("num_", "id")) and not key.startswith(("idf1", "idp", "idr")):
            assert got == int(want), key  # counts: exactly
        elif np.isnan(want):
            assert got is None, key
        else:
            # ratios of the same integer counts (MOTP: sums of the same IoUs, computed
            # from x+w corners by motmetrics, from w directly by box_iou_matrix): 1e-9
            assert got == pytest.approx(want, abs=1e-9), key


# ------------------------------------------------------------------- single object


def test_polygon_to_box_is_its_bounding_box():
    # the first line of VOT "bag": a rotated box given by its 4 corners
    poly = [334.02, 128.36, 438.19, 188.78, 396.39, 260.83, 292.23, 200.41]
    np.testing.assert_allclose(polygons_to_boxes(poly), [[292.23, 128.36, 145.96, 132.47]])
    # an axis-aligned rectangle as a polygon comes back as itself, in any vertex order
    square = [[10, 20, 40, 20, 40, 60, 10, 60], [40, 60, 10, 60, 10, 20, 40, 20]]
    np.testing.assert_allclose(polygons_to_boxes(square), [[10, 20, 30, 40]] * 2)
    assert np.isnan(polygons_to_boxes([np.nan] * 8)).all()
    with pytest.raises(InputError, match="k >= 3"):
        polygons_to_boxes([1, 2, 3, 4])


def test_read_vot_groundtruth_forms(tmp_path):
    p = tmp_path / "groundtruth.txt"
    p.write_text(
        "10,20,30,40\n"  # rectangle
        "0,0,10,0,10,10,0,10\n"  # polygon
        "nan,nan,nan,nan\n"  # absent (NaN)
        "0\n"  # absent (VOT's code)
        "5,5,0,0\n"  # absent (empty box)
        "1\t2\t3\t4\n"  # OTB: tabs
        "\n\n"  # trailing blank lines
    )
    boxes = read_vot_groundtruth(p)
    assert boxes.shape == (6, 4)
    np.testing.assert_array_equal(
        boxes[[0, 1, 5]], [[10, 20, 30, 40], [0, 0, 10, 10], [1, 2, 3, 4]]
    )
    assert np.isnan(boxes[2:5]).all()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("1,2,3,4\n1,2,3,4,5\n", "line 2 has 5 numbers; expected x,y,w,h or a polygon"),
        ("1,2,3,4\n1,2,3\n", "line 2 has 3 numbers"),
        ("1,2,3,4\nbag,1,2,3\n", "line 2 .* is not numbers"),
        ("1,2,3,4\n\n1,2,3,4\n", "line 2 is blank"),
        ("1,2,-3,4\n", "line 1 .*negative width"),
        ("1,2,inf,4\n", "line 1 .*finite"),
        ("\n", "no box"),
    ],
)
def test_read_vot_groundtruth_refuses_bad_lines(tmp_path, text, match):
    p = tmp_path / "groundtruth.txt"
    p.write_text(text)
    with pytest.raises(FileFormatError, match=match):
        read_vot_groundtruth(p)


def test_read_vot_groundtruth_missing_and_binary(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_vot_groundtruth(tmp_path / "nope.txt")
    (tmp_path / "b.txt").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(FileFormatError, match="not a text file"):
        read_vot_groundtruth(tmp_path / "b.txt")


def test_paired_iou_is_the_diagonal_of_the_matrix(rng):
    a = np.c_[rng.uniform(0, 50, (40, 2)), rng.uniform(1, 30, (40, 2))]
    b = np.abs(a + rng.normal(0, 8, a.shape))  # some overlap, some none
    np.testing.assert_allclose(paired_iou(a, b), np.diag(box_iou_matrix(a, b)), atol=1e-15)
    assert np.isnan(paired_iou([[np.nan] * 4], [[0, 0, 1, 1]]))[0]
    with pytest.raises(InputError, match="as many boxes"):
        paired_iou(a, b[:3])


def test_success_curve_hand_case():
    truth = [[0, 0, 10, 10]] * 4 + [[np.nan] * 4]
    pred = [[0, 0, 10, 10], [5, 0, 10, 10], [20, 20, 5, 5], [np.nan] * 4, [0, 0, 1, 1]]
    s = evaluate_single_object(pred, truth)
    # IoUs: 1, 50/150, 0 (disjoint), 0 (no prediction); frame 4 has no target
    np.testing.assert_allclose(s.ious[:4], [1, 1 / 3, 0, 0])
    assert np.isnan(s.ious[4]) and s.frames == 4 and s.absent == 1
    assert s.mean_iou == pytest.approx((1 + 1 / 3) / 4)
    assert s.success_50 == 0.25
    # success(t) = #(IoU > t) / 4: 2/4 for t < 1/3 (0, .05, ..., .30: 7), 1/4 up to 0.95
    # (13 thresholds), 0 at 1
    np.testing.assert_allclose(s.success, [0.5] * 7 + [0.25] * 13 + [0.0])
    assert s.auc == pytest.approx((7 * 0.5 + 13 * 0.25) / 21)
    np.testing.assert_array_equal(s.thresholds, OTB_THRESHOLDS)


def test_auc_tends_to_the_mean_iou(rng):
    truth = np.tile([10.0, 10.0, 20.0, 20.0], (300, 1))
    pred = truth + np.c_[rng.normal(0, 6, (300, 2)), np.zeros((300, 2))]
    s = evaluate_single_object(pred, truth, thresholds=np.linspace(0, 1, 2001))
    # a Riemann sum of the success curve over [0, 1], whose integral is the mean IoU:
    # within one threshold step (plus the strict > at the last threshold)
    assert abs(s.auc - s.mean_iou) < 2 / 2000


def test_success_with_frame_indices_and_bad_input():
    truth = np.array([[0, 0, 10, 10], [0, 0, 10, 10], [2, 0, 10, 10]], float)
    s = evaluate_single_object([[2, 0, 10, 10]], truth, frames=[2])
    assert s.mean_iou == 1.0 and s.frames == 1
    with pytest.raises(InputError, match=r"truth has 3 boxes .* reach frame 5"):
        evaluate_single_object([[0, 0, 1, 1]], truth, frames=[5])
    with pytest.raises(DegenerateError, match="no target"):
        evaluate_single_object([[0, 0, 1, 1]], [[np.nan] * 4])
    with pytest.raises(InputError, match="thresholds must be increasing"):
        evaluate_single_object([[0, 0, 1, 1]], truth[:1], thresholds=[0.5, 0.2])
    with pytest.raises(InputError, match="predicted must be \\(N, 4\\)"):
        evaluate_single_object([[0, 0, 1]], truth)


def test_success_plot_picture():
    s = evaluate_single_object([[0, 0, 10, 10], [3, 0, 10, 10]], [[0, 0, 10, 10]] * 2)
    pic = success_plot([s, s], ["a", "b"], size=(1920, 1080))
    assert pic.shape == (1080, 1920, 3) and pic.dtype == np.uint8
    assert (pic < 128).mean() > 0.005  # curve, axes, labels drawn
    with pytest.raises(InputError, match="labels must be one name per curve"):
        success_plot(s, ["a", "b"])
    with pytest.raises(InputError, match="scores must be a SuccessScores"):
        success_plot([1, 2])


# ------------------------------------------------------------------ multiple objects

A, B, C = [0, 0, 10, 10], [20, 0, 10, 10], [60, 0, 10, 10]


def test_hand_case_switch_fp_fn():
    acc = MotAccumulator()
    # frame 1: object 1 found by hypothesis 7, object 2 missed, hypothesis 8 on nothing
    e = acc.update([1, 2], [A, B], [7, 8], [A, C])
    assert e.matches == ((1, 7),) and e.misses == (2,) and e.false_positives == (8,)
    # frame 2: object 1 gone; frame 3: it is back, found by hypothesis 9: a switch
    # (motmetrics counts it against the last match, however long ago)
    acc.update([], np.zeros((0, 4)), [], np.zeros((0, 4)))
    e = acc.update([1], [A], [9], [A])
    assert e.switches == ((1, 9),) and e.matches == ()
    m = acc.metrics()
    assert (m.num_matches, m.num_switches, m.num_false_positives, m.num_misses) == (1, 1, 1, 1)
    assert m.num_objects == 3 and m.num_predictions == 3 and m.num_frames == 3
    assert m.mota == pytest.approx(1 - 3 / 3) and m.motp == 0.0
    # IDF1: object 1 pairs with 7 once and with 9 once; the best one-to-one pairing
    # keeps one of them: IDTP 1 of 3 true and 3 predicted boxes
    assert (m.idtp, m.idfp, m.idfn) == (1, 2, 2)
    assert m.idf1 == pytest.approx(2 / 6) and m.idp == m.idr == pytest.approx(1 / 3)


def test_a_kept_match_beats_a_closer_hypothesis():
    """Step 1 of CLEAR MOT: a pair of the last frame is kept while its IoU >= 0.5, even
    when the Hungarian algorithm would choose a better box."""
    acc = MotAccumulator()
    acc.update([1], [A], [7], [[2, 0, 10, 10]])  # IoU 8/12
    e = acc.update([1], [A], [7, 8], [[3, 0, 10, 10], A])  # 7 still valid (IoU 7/13)
    assert e.matches == ((1, 7),) and e.false_positives == (8,) and e.switches == ()
    e = acc.update([1], [A], [7, 8], [[6, 0, 10, 10], A])  # 7 too far now: 8 takes over
    assert e.switches == ((1, 8),) and e.false_positives == (7,)
    m = acc.metrics()
    assert m.motp == pytest.approx(((1 - 8 / 12) + (1 - 7 / 13) + 0) / 3)


def test_threshold_is_inclusive():
    # IoU exactly 0.5 is a match (motmetrics: distance 1 - IoU <= 0.5)
    acc = MotAccumulator()
    e = acc.update([1], [[0, 0, 30, 10]], [2], [[0, 0, 15, 10]])
    assert e.matches == ((1, 2),)
    e = MotAccumulator(0.6).update([1], [[0, 0, 30, 10]], [2], [[0, 0, 15, 10]])
    assert e.misses == (1,) and e.false_positives == (2,)


def test_empty_sequence_is_nan_not_an_error():
    m = MotAccumulator().metrics()
    assert np.isnan(m.mota) and np.isnan(m.idf1) and m.to_dict()["mota"] is None


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: MotAccumulator(iou_threshold=0.0), "iou_threshold must be in"),
        (lambda: MotAccumulator().update([1, 1], [A, B], [], []), "gt_ids holds id 1 twice"),
        (lambda: MotAccumulator().update([1], [A, B], [], []), "one id per box"),
        (lambda: MotAccumulator().update([1], [[0, 0, -1, 5]], [], []), "negative width"),
        (lambda: MotAccumulator().update([1], [[np.nan, 0, 1, 5]], [], []), "finite"),
        (lambda: MotAccumulator().update([1.5], [A], [], []), "whole numbers"),
        (lambda: evaluate_mot("gt.txt", "res.txt"), "ground_truth must be MotRows"),
    ],
)
def test_bad_mot_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_repeated_id_in_a_file_names_the_frame(tmp_path):
    (tmp_path / "gt.txt").write_text("1,1,0,0,9,9\n2,1,0,0,9,9\n2,1,5,5,9,9\n")
    gt = read_mot(tmp_path / "gt.txt")
    with pytest.raises(InputError, match="frame 2: gt_ids holds id 1 twice"):
        evaluate_mot(gt, gt)


def test_select_ground_truth_mot17_and_mot15(tmp_path):
    (tmp_path / "mot17.txt").write_text(
        "1,1,0,0,9,9,1,1,0.9\n"  # pedestrian, considered
        "1,2,0,0,9,9,0,1,0.9\n"  # flag 0: ignored
        "1,3,0,0,9,9,1,7,0.9\n"  # static person (class 7)
        "1,4,0,0,9,9,1,-1,1\n"  # no class
    )
    rows = read_mot(tmp_path / "mot17.txt")
    assert select_ground_truth(rows).id.tolist() == [1, 4]
    assert select_ground_truth(rows, classes=(1, 7)).id.tolist() == [1, 3, 4]
    assert select_ground_truth(rows, classes=None).id.tolist() == [1, 3, 4]
    # MOT15 / TUD: world coordinates in columns 8-10 are not classes
    (tmp_path / "mot15.txt").write_text("1,1,0,0,9,9,1,4.5,5.5,0\n1,2,0,0,9,9,1,12.6,10.6,0\n")
    assert select_ground_truth(read_mot(tmp_path / "mot15.txt")).id.tolist() == [1, 2]
    with pytest.raises(InputError, match="rows must be MotRows"):
        select_ground_truth("gt.txt")


@pytest.mark.filterwarnings("ignore:Operation with tuple is deprecated")  # motmetrics' loadtxt
@pytest.mark.parametrize("name", ["TUD-Campus", "TUD-Stadtmitte"])
def test_parity_with_motmetrics_on_tud(mm, name):
    folder = _tud(mm, name)
    acc = mm.utils.compare_to_groundtruth(
        mm.io.loadtxt(folder / "gt.txt"), mm.io.loadtxt(folder / "test.txt"), "iou", distth=0.5
    )
    ours = evaluate_mot(select_ground_truth(read_mot(folder / "gt.txt")),
                        read_mot(folder / "test.txt")).to_dict()  # fmt: skip
    _assert_same(ours, _mm_summary(mm, acc))
    # and the values motmetrics' own test expects (tests/test_metrics.py, 6 digits)
    published = {"TUD-Campus": (0.557659, 0.526462, 0.277201, 7),
                 "TUD-Stadtmitte": (0.644619, 0.564014, 0.345904, 7)}[name]  # fmt: skip
    got = (ours["idf1"], ours["mota"], ours["motp"], ours["num_switches"])
    assert got == pytest.approx(published, abs=1e-6)


def _random_sequence(seed: int) -> tuple[MotRows, MotRows]:
    """6 objects over 40 frames entering and leaving; hypotheses jitter around them,
    miss some, swap identities now and then and add clutter."""
    gen = np.random.default_rng(seed)
    g_rows, h_rows = [], []
    start = gen.uniform(0, 200, (6, 2))
    vel = gen.normal(0, 2, (6, 2))
    alive = gen.integers(1, 20, 6), gen.integers(20, 41, 6)
    hyp_of = np.arange(6) + 100
    for f in range(1, 41):
        if gen.uniform() < 0.15:  # an identity swap between two hypotheses
            i, j = gen.choice(6, 2, replace=False)
            hyp_of[[i, j]] = hyp_of[[j, i]]
        if gen.uniform() < 0.1:  # a fresh identity
            hyp_of[gen.integers(6)] = 200 + f
        for k in range(6):
            if not alive[0][k] <= f <= alive[1][k]:
                continue
            box = [*(start[k] + f * vel[k]), 30.0, 40.0]
            g_rows.append((f, k + 1, *box))
            if gen.uniform() < 0.85:
                h_rows.append((f, hyp_of[k], *(np.array(box) + gen.normal(0, 4, 4))))
        for c in range(gen.integers(0, 3)):
            h_rows.append((f, 900 + 10 * f + c, *gen.uniform(0, 250, 2), 20.0, 20.0))

    def rows(r):
        a = np.array(r, float)
        a[:, 4:] = np.abs(a[:, 4:])
        return MotRows(a[:, 0].astype(np.int64), a[:, 1].astype(np.int64), a[:, 2:6],
                       np.ones(len(a)), np.zeros((len(a), 0)))  # fmt: skip

    return rows(g_rows), rows(h_rows)


@pytest.mark.parametrize("seed", range(5))
def test_parity_with_motmetrics_on_random_sequences(mm, seed):
    gt, hyp = _random_sequence(seed)
    acc = mm.MOTAccumulator(auto_id=True)
    for f in range(1, 41):
        g, h = gt.at(f), hyp.at(f)
        acc.update(g.id, h.id, mm.distances.iou_matrix(g.boxes, h.boxes, max_iou=0.5))
    theirs = _mm_summary(mm, acc)
    assert theirs["num_switches"] > 0 and theirs["num_false_positives"] > 0
    _assert_same(evaluate_mot(gt, hyp, frames=range(1, 41)).to_dict(), theirs)


@pytest.mark.realdata
@pytest.mark.parametrize("sequence", ["MOT17-02-FRCNN", "MOT17-04-FRCNN"])
def test_parity_with_motmetrics_on_mot17(mm, sequence):
    """Our tracker on the MOT17 frames (public detections, confidence >= 0.5), scored
    by both against gt.txt (considered pedestrians)."""
    folder = data_path("video", "mot17_mini", sequence)
    det = read_mot(folder / "det" / "det.txt")
    gt = select_ground_truth(read_mot(folder / "gt" / "gt.txt"))
    frames = sorted(set(gt.frame.tolist()))
    trk = MultiObjectTracker(min_hits=3, max_age=5)
    acc = mm.MOTAccumulator(auto_id=True)
    ours = MotAccumulator()
    for f in frames:
        d = det.at(f)
        keep = d.conf >= 0.5
        out = trk.update(d.boxes[keep], scores=d.conf[keep])
        hyp = np.array([t.box for t in out]).reshape(-1, 4)
        g = gt.at(f)
        acc.update(g.id, [t.id for t in out], mm.distances.iou_matrix(g.boxes, hyp, 0.5))
        ours.update(g.id, g.boxes, [t.id for t in out], hyp)
    theirs = _mm_summary(mm, acc)
    _assert_same(ours.metrics().to_dict(), theirs)
    # measured (docs/tracking.md): MOTA 0.182 / IDF1 0.471 (02), 0.479 / 0.669 (04)
    assert theirs["mota"] > 0.15 and theirs["idf1"] > 0.45
