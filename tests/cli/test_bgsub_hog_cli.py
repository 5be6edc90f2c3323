"""Issue 30: ``bgsub --json`` and ``--gap``, ``train-hog --positives DIR --negatives DIR``,
``--json`` on ``train-hog`` and ``detect-hog``, and detect-hog's default threshold
read from the model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.imaging import write_image
from robopercept.motion import ThreeFrameDifference, moving_blobs

BGSUB_KEYS = {"command", "video", "method", "settings", "min_area", "frames", "skipped",
              "skipped_frames", "seconds", "fps", "foreground_mean", "blobs_per_frame",
              "per_frame", "written"}  # fmt: skip


def _folder(path, frames):
    path.mkdir()
    for i, f in enumerate(frames):
        write_image(path / f"{i:06d}.png", f)
    return path


def test_bgsub_json_diff3_matches_the_library(tmp_path, capsys):
    frames, _ = moving_blobs(14, (128, 96), n_blobs=2, radius=(8.0, 9.0), speed=6.0, rng=2)
    seq = _folder(tmp_path / "seq", frames)
    code = main(["bgsub", str(seq), "--method", "diff3", "--gray", "--gap", "2", "--json",
                 "-o", str(tmp_path / "d.mp4"), "--quiet", "--min-area", "20"])  # fmt: skip
    assert code == 0
    out = capsys.readouterr().out
    report = json.loads(out)  # stdout is the one JSON object
    assert set(report) == BGSUB_KEYS
    assert report["command"] == "bgsub" and report["method"] == "diff3"
    assert report["settings"]["gap"] == 2 and report["settings"]["threshold"] == 15.0
    assert report["frames"] == 14 and len(report["per_frame"]) == 14 and report["skipped"] == 0
    # frame t's mask comes with frame t + 2; the last two frames have none
    model = ThreeFrameDifference(gap=2)
    masks = [model.apply(f) for f in frames]
    for t in range(12):
        row = report["per_frame"][t]
        assert row["frame"] == t
        assert row["foreground"] == pytest.approx(masks[t + 2].mean(), abs=1e-6)
    assert report["per_frame"][-1]["boxes"] == [] and report["per_frame"][-1]["foreground"] == 0
    assert any(r["boxes"] for r in report["per_frame"])
    box = next(r for r in report["per_frame"] if r["boxes"])["boxes"][0]
    assert len(box) == 4 and all(isinstance(v, int) for v in box)
    n_boxes = sum(len(r["boxes"]) for r in report["per_frame"])
    assert report["blobs_per_frame"] == pytest.approx(n_boxes / 14, abs=1e-4)
    assert report["written"] == [str(tmp_path / "d.mp4")]


def test_bgsub_json_other_method_and_bad_gap(tmp_path, capsys):
    frames, _ = moving_blobs(8, (64, 48), n_blobs=1, radius=(6.0, 7.0), speed=4.0, rng=3)
    seq = _folder(tmp_path / "seq", frames)
    assert main(["bgsub", str(seq), "--method", "diff", "--json", "--quiet",
                 "-o", str(tmp_path / "o.mp4")]) == 0  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert report["settings"] == {"threshold": 25.0, "n": 1, "noise": "median",
                                  "noise_size": 3, "gray": False}  # fmt: skip
    assert main(["bgsub", str(seq), "--method", "diff3", "--gap", "0"]) == 2
    assert "--gap" in capsys.readouterr().err


# -- train-hog / detect-hog ------------------------------------------------------------
@pytest.fixture(scope="module")
def face_folders(tmp_path_factory):
    """40 lfw_subset faces (25x25 PNGs) and 6 face-free scikit-image pictures, plus an
    unreadable file in each folder."""
    from skimage import data

    root = tmp_path_factory.mktemp("hog")
    pos, neg = root / "faces", root / "background"
    pos.mkdir()
    neg.mkdir()
    faces = data.lfw_subset()[:40]
    for i, f in enumerate(faces):
        write_image(pos / f"face{i:02d}.png", (255 * f).astype(np.uint8))
    for name in ("coffee", "rocket", "brick", "grass", "coins", "page"):  # 120 px crops
        write_image(neg / f"{name}.png", np.asarray(getattr(data, name)())[:120, :160])
    (pos / "notes.txt").write_text("not an image")
    (neg / "broken.jpg").write_bytes(b"\xff\xd8 truncated")
    return pos, neg


def test_train_hog_on_folders_then_detect_with_its_threshold(tmp_path, face_folders, capsys):
    from robopercept.learning.hog_detector import HogDetector

    pos, neg = face_folders
    model = tmp_path / "mine.npz"
    code = main(["train-hog", "--positives", str(pos), "--negatives", str(neg), "--rounds",
                 "0", "-o", str(model), "--json"])  # fmt: skip
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    assert report["command"] == "train-hog" and report["output"] == str(model)
    assert report["images"] == {"positives": 40, "negatives": 6}
    assert sorted(report["skipped"])[0].startswith("background/broken.jpg")
    assert any(s.startswith("faces/notes.txt") for s in report["skipped"])
    assert report["window"] == [24, 24] and report["weights"] == 648
    held = report["heldout"]
    assert held["positives"] == 20  # 10 of 40 faces held out, and their mirror images
    assert held["negatives"] > 0 and 0 < held["f1"] <= 1
    det = HogDetector.load(model)
    assert det.threshold == pytest.approx(report["threshold"], abs=1e-6)

    from skimage import data

    src = write_image(tmp_path / "astronaut.png", data.astronaut()[:240, 120:320])
    assert main(["detect-hog", str(src), "--model", str(model), "-o",
                 str(tmp_path / "d.png"), "--json", "--max-size", "120"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["threshold_source"] == "model"
    assert out["threshold"] == pytest.approx(det.threshold, abs=1e-6)
    assert all(d["score"] > det.threshold for d in out["detections"])
    assert set(out) == {"command", "image", "model", "threshold", "threshold_source", "found",
                        "ms", "detections", "output"}  # fmt: skip
    if out["detections"]:
        assert set(out["detections"][0]) == {"x", "y", "size", "w", "h", "score"}


def test_train_hog_bad_folders(tmp_path, face_folders, capsys):
    pos, neg = face_folders
    empty = tmp_path / "empty"
    empty.mkdir()
    out = str(tmp_path / "m.npz")
    assert main(["train-hog", "--positives", str(empty), "--negatives", str(neg), "-o", out]) == 1
    err = capsys.readouterr().err
    assert "positives folder" in err and "no readable image" in err
    junk = tmp_path / "junk"
    junk.mkdir()
    (junk / "a.png").write_bytes(b"nope")
    assert main(["train-hog", "--positives", str(pos), "--negatives", str(junk), "-o", out]) == 1
    err = capsys.readouterr().err
    assert "negatives folder" in err and "1 unreadable" in err and "a.png" in err
    missing = tmp_path / "absent"
    assert main(["train-hog", "--positives", str(missing), "--negatives", str(neg), "-o", out]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert main(["train-hog", "--positives", str(pos), "-o", out]) == 2
    assert "--negatives" in capsys.readouterr().err
    assert main(["train-hog", "--positives", str(pos), "--negatives", str(neg),
                 "--holdout", "0.9", "-o", out]) == 2  # fmt: skip
    assert "--holdout" in capsys.readouterr().err
    assert main(["train-hog", "--window", "30x30", "-o", out]) == 2  # face model: fixed window
    assert main(["train-hog", "--positives", str(pos), "--negatives", str(neg),
                 "--window", "28x28", "-o", out]) == 1  # fmt: skip
    assert "whole cells" in capsys.readouterr().err


def test_detect_hog_threshold_flag_overrides_the_model(tmp_path, capsys):
    from skimage import data

    src = write_image(tmp_path / "a.png", data.astronaut()[:200, 100:300])
    assert main(["detect-hog", str(src), "-o", str(tmp_path / "d.png"), "--json",
                 "--threshold", "-0.5"]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["threshold_source"] == "--threshold" and out["threshold"] == -0.5
    assert out["model"] == "bundled"
