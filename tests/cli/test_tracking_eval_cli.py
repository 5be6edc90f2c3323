"""``robopercept meanshift --truth`` and ``track --gt``: the scores against ground truth,
``--plot`` and ``--json`` (one JSON object on stdout), checked against the library on
synthetic sequences and measured on VOT "bag" and the MOT17 frames; bad ground truth
ends in one line on stderr naming the line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.imaging import read_image, write_image
from robopercept.tracking import read_mot, write_mot
from robopercept.tracking.metrics import evaluate_mot, select_ground_truth
from tests.conftest import data_path

CENTRES = [(40.0 + 4 * t, 50.0 + 2 * t) for t in range(8)]


@pytest.fixture
def disc_folder(tmp_path):
    """8 frames of a red disc (radius 15) moving on a green noisy background."""
    folder = tmp_path / "seq"
    folder.mkdir()
    yy, xx = np.mgrid[:120, :160]
    for t, (cx, cy) in enumerate(CENTRES):
        gen = np.random.default_rng(t)
        img = np.empty((120, 160, 3), dtype=np.uint8)
        img[..., 0] = gen.integers(60, 90, (120, 160))
        img[..., 1] = gen.integers(100, 140, (120, 160))
        img[..., 2] = gen.integers(60, 90, (120, 160))
        img[(xx - cx) ** 2 + (yy - cy) ** 2 <= 15**2] = (220, 30, 40)
        write_image(folder / f"{t:06d}.png", img)
    return folder


def _json(capsys) -> dict:
    out = capsys.readouterr().out
    return json.loads(out)  # the whole of stdout is one JSON object


def test_meanshift_truth_as_polygons_json_and_plot(tmp_path, capsys, disc_folder):
    # the truth as VOT polygons: the disc's box as a diamond of 4 corners (bounding box
    # 31 x 31 around the centre: the pixels of the disc), one frame without the target
    lines = []
    for t, (cx, cy) in enumerate(CENTRES):
        if t == 5:
            lines.append("nan,nan,nan,nan")
            continue
        lines.append(f"{cx},{cy - 15.5},{cx + 15.5},{cy},{cx},{cy + 15.5},{cx - 15.5},{cy}")
    truth = tmp_path / "groundtruth.txt"
    truth.write_text("\n".join(lines) + "\n")
    plot = tmp_path / "success.png"
    args = ["meanshift", str(disc_folder), "--truth", str(truth), "--plot", str(plot),
            "-o", str(tmp_path / "m.mp4"), "--results", str(tmp_path / "b.csv"), "--quiet",
            "--json"]  # fmt: skip
    assert main(args) == 0
    out = _json(capsys)
    assert out["command"] == "meanshift" and out["frames"] == 8 and out["skipped"] == 0
    np.testing.assert_allclose(out["box"], [CENTRES[0][0] - 15.5, CENTRES[0][1] - 15.5, 31, 31])
    ev = out["evaluation"]
    assert ev["frames"] == 7 and ev["absent"] == 1
    assert ev["mean_iou"] > 0.85 and ev["success_50"] == 1.0  # the disc is followed
    assert len(ev["thresholds"]) == len(ev["success"]) == 21
    assert ev["auc"] == pytest.approx(np.mean(ev["success"]))
    assert ev["plot"] == str(plot) and read_image(plot).shape == (720, 1280, 3)
    assert str(tmp_path / "b.csv") in out["outputs"]
    # the human form prints the same scores
    assert main(args[:-1]) == 0
    text = capsys.readouterr().out
    assert f"mean IoU {ev['mean_iou']:.3f}" in text and "1 without target" in text


def test_meanshift_json_without_truth(tmp_path, capsys, disc_folder):
    assert main(["meanshift", str(disc_folder), "--box", "25,35,30,30", "--quiet", "--json",
                 "-o", str(tmp_path / "m.mp4")]) == 0  # fmt: skip
    out = _json(capsys)
    assert out["evaluation"] is None and out["similarity_min"] > 0.8
    assert out["outputs"] == [str(tmp_path / "m.mp4")]


def test_meanshift_truth_errors(tmp_path, capsys, disc_folder):
    out = str(tmp_path / "m.mp4")
    assert main(["meanshift", str(disc_folder), "--plot", str(tmp_path / "p.png"),
                 "--box", "25,35,30,30", "-o", out]) == 2  # fmt: skip
    assert "--plot: the success curve needs --truth" in capsys.readouterr().err
    assert main(["meanshift", str(disc_folder), "-o", out]) == 2
    assert "--box: give the target" in capsys.readouterr().err
    short = tmp_path / "short.txt"
    short.write_text("25,35,30,30\n29,37,30,30\n")  # 2 boxes for 8 frames
    assert main(["meanshift", str(disc_folder), "--truth", str(short), "-o", out, "--quiet"]) == 1
    assert "--truth has 2 boxes" in capsys.readouterr().err
    bad = tmp_path / "bad.txt"
    bad.write_text("25,35,30,30\n29,37,30\n")
    assert main(["meanshift", str(disc_folder), "--truth", str(bad), "-o", out]) == 1
    assert "line 2 has 3 numbers" in capsys.readouterr().err


@pytest.mark.realdata
def test_meanshift_on_vot_bag(tmp_path, capsys):
    """CamShift on VOT "bag" (196 frames), started from the truth of frame 0.
    Measured: mean IoU 0.806, success (IoU > 0.5) 0.990, AUC 0.792 (hue with
    --min-saturation 20: the bag's hue at the default 60 is too grey to learn). The
    floors sit a little under, so a change that loses the bag for a few frames fails."""
    folder = data_path("video", "vot_bag")
    args = ["meanshift", str(folder), "--truth", str(folder / "groundtruth.txt"),
            "--camshift", "--min-saturation", "20", "-o", str(tmp_path / "m.mp4"), "--quiet",
            "--json"]  # fmt: skip
    assert main(args) == 0
    ev = _json(capsys)["evaluation"]
    assert ev["frames"] == 196 and ev["absent"] == 0
    assert ev["mean_iou"] > 0.78 and ev["success_50"] > 0.95 and ev["auc"] > 0.76


# ------------------------------------------------------------------------------ track


@pytest.fixture
def det_and_gt(tmp_path, disc_folder):
    """det.txt: the disc each frame but frame 5, with clutter; gt.txt: the disc (id 4) in
    MOT17's 9 columns, a flag-0 row and a class-7 row that must be left out."""
    det, gt = [], []
    for t, (cx, cy) in enumerate(CENTRES):
        box = (cx - 15, cy - 15, 31, 31)
        if t != 5:
            det.append((t + 1, -1, box, 0.9))
        det.append((t + 1, -1, (120, 90, 20, 20), 0.8))  # a static box: a false track
        gt.append(f"{t + 1},4,{box[0]},{box[1]},31,31,1,1,1")
        gt.append(f"{t + 1},5,0,0,10,10,0,1,1")  # flag 0: not considered
        gt.append(f"{t + 1},6,120,90,20,20,1,7,1")  # class 7 (static person)
    write_mot(tmp_path / "det.txt", det)
    (tmp_path / "gt.txt").write_text("\n".join(gt) + "\n")
    return disc_folder, tmp_path / "det.txt", tmp_path / "gt.txt"


def test_track_gt_json_equals_the_library(tmp_path, capsys, det_and_gt):
    seq, det, gt = det_and_gt
    results = tmp_path / "res.txt"
    args = ["track", str(seq), "--detections", str(det), "--gt", str(gt), "--min-hits", "1",
            "--results", str(results), "-o", str(tmp_path / "t.mp4"), "--quiet",
            "--json"]  # fmt: skip
    assert main(args) == 0
    out = _json(capsys)
    assert out["command"] == "track" and out["frames"] == 8
    assert out["identities"] >= 2 and out["results"] == str(results)
    ev = out["evaluation"]
    want = evaluate_mot(select_ground_truth(read_mot(gt)), read_mot(results), frames=range(1, 9))
    assert {k: ev[k] for k in want.to_dict()} == want.to_dict()
    # the disc: 8 true boxes; the static box is a class-7 row, so its track is false
    assert ev["num_objects"] == 8 and ev["num_switches"] == 0
    assert ev["num_false_positives"] >= 7 and ev["iou_threshold"] == 0.5
    # every class counted: the static box becomes a true object, found
    assert main([*args[:-1], "--gt-classes", "all"]) == 0
    text = capsys.readouterr().out
    assert "MOTA" in text and "16 true boxes in 8 frames" in text


def test_track_bad_gt(tmp_path, capsys, det_and_gt):
    seq, det, _ = det_and_gt
    base = ["track", str(seq), "--detections", str(det), "-o", str(tmp_path / "t.mp4"),
            "--results", str(tmp_path / "r.txt"), "--quiet"]  # fmt: skip
    bad = tmp_path / "bad_gt.txt"
    bad.write_text("1,4,10,20,31,31,1,1,1\n2,4,10,20\n")  # line 2: 4 columns
    assert main([*base, "--gt", str(bad)]) == 1
    err = capsys.readouterr().err
    assert "line 2 has 4 fields" in err and "frame,id,x,y,w,h" in err
    assert main([*base, "--gt", str(tmp_path / "none.txt")]) == 1
    assert "no such file" in capsys.readouterr().err
    assert main([*base, "--gt", str(bad), "--gt-classes", "people"]) == 2
    assert "--gt-classes" in capsys.readouterr().err
    assert main([*base, "--gt", str(bad), "--iou", "1.5"]) == 2


@pytest.mark.realdata
def test_track_gt_on_mot17(tmp_path, capsys):
    """The measured figures on MOT17-02 (public FRCNN detections, confidence >= 0.5; the
    same that motmetrics gives, tests/tracking/test_metrics.py, which also checks
    MOT17-04: MOTA 0.479, IDF1 0.669; left out here, its 8 full-HD frames are slow)."""
    seq = data_path("video", "mot17_mini", "MOT17-02-FRCNN")
    mota, idf1 = 0.182, 0.471
    assert main(["track", str(seq / "img1"), "--detections", str(seq / "det" / "det.txt"),
                 "--min-score", "0.5", "--gt", str(seq / "gt" / "gt.txt"), "--results",
                 str(tmp_path / "r.txt"), "-o", str(tmp_path / "t.mp4"), "--quiet",
                 "--json"]) == 0  # fmt: skip
    ev = _json(capsys)["evaluation"]
    assert ev["mota"] == pytest.approx(mota, abs=5e-4)
    assert ev["idf1"] == pytest.approx(idf1, abs=5e-4)
    assert ev["num_switches"] == 0
