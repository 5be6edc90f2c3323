"""read_mot / write_mot: MOTChallenge text files, real MOT17 files and bad lines."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError
from robopercept.tracking.mot_io import MOT_MAX_NUMBER, read_mot, write_mot
from tests.conftest import data_path


def test_hand_written_detections_and_round_trip(tmp_path):
    path = tmp_path / "det.txt"
    path.write_text("1,-1,10,20,30,40,0.9\n\n2,-1,12.5,20,30,40,0.8\n2,7,1,2,3,4,0.5\n")
    rows = read_mot(path)
    assert rows.frame.tolist() == [1, 2, 2] and rows.id.tolist() == [-1, -1, 7]
    assert rows.frame.dtype == np.int64 and rows.id.dtype == np.int64
    np.testing.assert_array_equal(rows.boxes[1], [12.5, 20, 30, 40])
    assert rows.conf.tolist() == [0.9, 0.8, 0.5] and rows.extra.shape == (3, 0)
    assert len(rows.at(2)) == 2
    assert write_mot(tmp_path / "r.txt", [(3, 5, (1.0, 2.0, 3.0, 4.0), 0.25)]) == 1
    back = read_mot(tmp_path / "r.txt")
    assert back.frame.tolist() == [3] and back.id.tolist() == [5]
    assert back.extra.tolist() == [[-1.0, -1.0, -1.0]]


@pytest.mark.realdata
def test_mot17_ground_truth_and_detections():
    seq = data_path("video", "mot17_mini", "MOT17-02-FRCNN")
    gt = read_mot(seq / "gt" / "gt.txt")
    # the file's first line: 1,1,912,484,97,109,0,7,1.0 (flag 0, class 7, visibility 1)
    assert (gt.frame[0], gt.id[0]) == (1, 1)
    np.testing.assert_array_equal(gt.boxes[0], [912, 484, 97, 109])
    assert gt.conf[0] == 0 and gt.extra[0].tolist() == [7.0, 1.0]
    assert gt.frame.min() >= 1 and gt.id.min() >= 1
    det = read_mot(seq / "det" / "det.txt")
    assert (det.id == -1).all() and det.frame.min() >= 1


# issue 25: read_mot turned nan, inf or 1e30 frame and id numbers into -2**63; frame and
# id must now be whole numbers (frame >= 1, id >= -1) below 2^53, every value finite


@pytest.mark.parametrize(
    ("line", "rule"),
    [
        ("nan,1,1,2,3,4", "frames are whole"),
        ("inf,1,1,2,3,4", "frames are whole"),
        ("-inf,1,1,2,3,4", "frames are whole"),
        ("1e30,1,1,2,3,4", "frames are whole"),
        ("9007199254740992,1,1,2,3,4", "frames are whole"),
        ("0,1,1,2,3,4", "frames are whole"),
        ("2.5,1,1,2,3,4", "frames are whole"),
        ("1,nan,1,2,3,4", "ids are whole"),
        ("1,inf,1,2,3,4", "ids are whole"),
        ("1,1e30,1,2,3,4", "ids are whole"),
        ("1,-1e30,1,2,3,4", "ids are whole"),
        ("1,-2,1,2,3,4", "ids are whole"),
        ("1,3.5,1,2,3,4", "ids are whole"),
        ("1,1,nan,2,3,4", "every value must be finite"),
        ("1,1,1,2,inf,4", "every value must be finite"),
        ("1,1,1,2,3,4,-inf", "every value must be finite"),
        ("1,1,1,2,3,4,0.5,nan,1", "every value must be finite"),
    ],
)
def test_bad_numbers_are_refused_naming_the_line(tmp_path, line, rule):
    path = tmp_path / "gt.txt"
    width = len(line.split(","))
    good = ",".join(["1", "1"] + ["0"] * (width - 2))
    path.write_text(f"{good}\n\n{line}\n{good}\n")
    with pytest.raises(FileFormatError, match=rf"gt\.txt: line 3 \(.*\): {rule}"):
        read_mot(path)


def test_largest_exact_frame_and_id_are_read_exactly(tmp_path):
    path = tmp_path / "gt.txt"
    n = MOT_MAX_NUMBER - 1
    path.write_text(f"{n},{n},1,2,3,4\n1,-1,1,2,3,4\n")
    rows = read_mot(path)
    assert rows.frame.tolist() == [n, 1] and rows.id.tolist() == [n, -1]


def test_mutated_lines_are_read_exactly_or_refused(tmp_path):
    """Seeded mutants of a MOT17 gt line with hostile number tokens: every one is
    refused, or read with frame and id equal to the numbers the line states."""
    tokens = ["nan", "inf", "-inf", "1e30", "-1e30", "1e308", "2.5", "0", "-1", "-2", "7"]
    gen = np.random.default_rng(25)
    path = tmp_path / "gt.txt"
    for _ in range(300):
        fields = "1,1,912,484,97,109,0,7,1.0".split(",")
        for _ in range(int(gen.integers(1, 3))):
            fields[int(gen.integers(len(fields)))] = str(gen.choice(tokens))
        path.write_text(",".join(fields) + "\n")
        try:
            rows = read_mot(path)
        except FileFormatError as exc:
            assert "gt.txt: line 1" in str(exc)
            continue
        assert rows.frame[0] == float(fields[0]) >= 1
        assert rows.id[0] == float(fields[1]) >= -1
        assert np.isfinite(rows.boxes).all() and np.isfinite(rows.extra).all()


# issue 25: write_mot opened whatever came as a path (TypeError for 3, OSError for a long
# name or a missing folder) and unpacked rows unchecked, leaving a partial file
@pytest.mark.parametrize(
    ("path", "rows", "match"),
    [
        (3, [], "path must be a file or folder path"),
        ("n" * 300 + ".txt", [], "file name too long"),
        ("r.txt", None, "rows must be a list"),
        ("r.txt", "abc", "rows must be a list"),
        ("r.txt", [(1, 1, (1, 2, 3, 4), 1.0), {}], "rows\\[1\\] must be"),
        ("r.txt", [None], "rows\\[0\\] must be"),
        ("r.txt", [(np.nan, 1, (1, 2, 3, 4), 1.0)], "rows\\[0\\] must be"),
        ("r.txt", [(0, 1, (1, 2, 3, 4), 1.0)], "frame a whole number >= 1"),
        ("r.txt", [(1, 1, (1, 2, 3), 1.0)], "rows\\[0\\] must be"),
        ("r.txt", [(1, 1, (1, 2, 3, np.inf), 1.0)], "four finite box numbers"),
    ],
)
def test_write_mot_refuses_bad_paths_and_rows(tmp_path, monkeypatch, path, rows, match):
    from robopercept.errors import InputError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(InputError, match=match):
        write_mot(path, rows)
    assert not (tmp_path / "r.txt").exists()  # nothing written


def test_write_mot_folder_errors_are_typed_and_bytes_paths_work(tmp_path):
    with pytest.raises(FileFormatError, match="cannot write"):
        write_mot(tmp_path / "no" / "such" / "r.txt", [(1, 1, (1, 2, 3, 4), 1.0)])
    path = bytes(tmp_path / "r.txt")
    assert write_mot(path, [(np.int64(2), -1, np.array([1.0, 2, 3, 4]), np.nan)]) == 1
    back = read_mot(tmp_path / "r.txt")
    assert back.frame.tolist() == [2] and back.id.tolist() == [-1] and back.conf.tolist() == [1.0]
