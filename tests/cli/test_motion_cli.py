"""``robopercept bgsub``, ``flow``, ``meanshift`` and ``track`` from the command line.

The commands are checked against the library calls they wrap, on image folders
(lossless, so the frames the command sees are the test's), and against ground truth
on synthetic sequences; bad input ends in one line on stderr and exit code 1 (a bad
file or frame) or 2 (a bad flag).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.imaging import VideoReader, VideoWriter, read_image, write_image
from robopercept.motion import GaussianBackground, ThreeFrameDifference, moving_blobs
from tests.conftest import data_path


def _folder(path, frames):
    path.mkdir()
    for i, f in enumerate(frames):
        write_image(path / f"{i:06d}.png", f)
    return path


def _masks(folder, n):
    return np.stack([read_image(folder / f"{i:06d}.png") > 127 for i in range(n)])


@pytest.fixture(scope="module")
def blobs():
    return moving_blobs(30, (128, 96), n_blobs=2, radius=(9.0, 12.0), speed=3.0, rng=1)


def test_bgsub_gaussian_equals_the_library_and_finds_the_blobs(tmp_path, capsys, blobs):
    frames, truth = blobs
    seq = _folder(tmp_path / "seq", frames)
    out = tmp_path / "bg.mp4"
    code = main(["bgsub", str(seq), "--method", "gaussian", "-o", str(out),
                 "--masks", str(tmp_path / "masks"), "--snapshot", "25", "--quiet"])  # fmt: skip
    assert code == 0
    text = capsys.readouterr().out
    assert "gaussian" in text and "frames            30" in text
    masks = _masks(tmp_path / "masks", 30)
    model = GaussianBackground()
    expected = np.stack([model.apply(np.repeat(f[..., None], 3, axis=2)) for f in frames])
    assert np.array_equal(masks, expected)
    tp = (masks[20:] & truth[20:]).sum()
    f1 = 2 * tp / (masks[20:].sum() + truth[20:].sum())
    assert f1 >= 0.9
    with VideoReader(out) as video:
        assert video.frame_count == 30 and video.size == (128, 96)
    assert read_image(tmp_path / "bg_000025.png").shape == (96, 128, 3)


def test_bgsub_three_frame_difference_is_one_frame_late(tmp_path):
    # discs faster than their diameter, so the three-frame AND holds the whole disc
    frames, _ = moving_blobs(10, (128, 96), n_blobs=2, radius=(8.0, 9.0), speed=20.0, rng=2)
    seq = _folder(tmp_path / "seq", frames[:10])
    code = main(["bgsub", str(seq), "--method", "diff3", "--gap", "1", "--gray", "-o",
                 str(tmp_path / "d.mp4"), "--masks", str(tmp_path / "m"), "--quiet",
                 "--layout", "panels"])  # fmt: skip
    assert code == 0
    masks = _masks(tmp_path / "m", 10)
    model = ThreeFrameDifference(gap=1)
    expected = [model.apply(f) for f in frames[:10]]
    # the mask returned with frame t belongs to frame t - 1; the last frame has none
    assert all(np.array_equal(masks[t - 1], expected[t]) for t in range(1, 10))
    assert not masks[9].any() and masks[5].any()
    with VideoReader(tmp_path / "d.mp4") as video:
        assert video.size == (3 * 128, 96)  # overlay | background | mask


@pytest.mark.parametrize("method", ["static", "average", "diff"])
def test_bgsub_other_methods_run(tmp_path, capsys, blobs, method):
    seq = _folder(tmp_path / "seq", blobs[0][:12])
    code = main(["bgsub", str(seq), "--method", method, "--init-frames", "4", "-o",
                 str(tmp_path / "o.mp4"), "--quiet"])  # fmt: skip
    assert code == 0
    assert "blobs" in capsys.readouterr().out


def test_undecodable_video_is_one_clear_error(tmp_path, capsys):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00\x01 this is not a video" * 100)
    for command in (["bgsub", str(bad)], ["track", str(bad)], ["flow", str(bad)],
                    ["meanshift", str(bad), "--box", "1,1,5,5"]):  # fmt: skip
        assert main([*command, "-o", str(tmp_path / "o.mp4"), "--quiet"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "broken.mp4" in err[0] and "Traceback" not in err[0]
    assert main(["bgsub", str(tmp_path / "absent.avi")]) == 1
    assert "no such file" in capsys.readouterr().err


def test_unreadable_frame_is_skipped_and_counted(tmp_path, capsys, blobs):
    seq = _folder(tmp_path / "seq", blobs[0][:8])
    (seq / "000003.png").write_bytes(b"not a png")
    code = main(["bgsub", str(seq), "--method", "diff", "-o", str(tmp_path / "o.mp4"),
                 "--quiet"])  # fmt: skip
    assert code == 0
    captured = capsys.readouterr()
    assert "skipped 1" in captured.out and "000003.png" in captured.err
    with VideoReader(tmp_path / "o.mp4") as video:
        assert video.frame_count == 7


def test_frame_of_another_size_names_the_frame_and_keeps_the_video(tmp_path, capsys, blobs):
    frames = list(blobs[0][:6])
    frames[4] = frames[4][:80]
    seq = _folder(tmp_path / "seq", frames)
    out = tmp_path / "o.mp4"
    assert main(["bgsub", str(seq), "--method", "diff", "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "frame 4" in err
    with VideoReader(out) as video:  # the frames before it were written
        assert video.frame_count == 4


def _texture(shape=(160, 200), seed=0):
    from robopercept.imaging.filters import gaussian_blur

    noise = np.random.default_rng(seed).uniform(0, 1, (shape[0] * 2, shape[1] * 2))
    t = gaussian_blur(noise, 2.0)
    return np.round(255 * (t - t.min()) / np.ptp(t)).astype(np.uint8)


def _warp(img, scale=1.0, angle=0.0, shift=(0.0, 0.0)):
    """The centre 160x200 of ``img`` seen after a similarity motion of the camera view."""
    from scipy.ndimage import map_coordinates

    h, w = 160, 200
    cy, cx = img.shape[0] / 2, img.shape[1] / 2
    yy, xx = np.mgrid[:h, :w].astype(float)
    x, y = xx - w / 2 - shift[0], yy - h / 2 - shift[1]
    c, s = np.cos(-angle), np.sin(-angle)
    sx, sy = (c * x - s * y) / scale + cx, (s * x + c * y) / scale + cy
    return np.round(map_coordinates(img.astype(float), [sy, sx], order=3)).astype(np.uint8)


@pytest.mark.parametrize(
    ("motion", "kind"),
    [
        ({"shift": (3.0, -2.0)}, "translation"),
        ({"angle": np.radians(3.0)}, "rotation"),
        ({"scale": 1.04}, "zoom"),
    ],
)
def test_flow_pair_classifies_the_motion(tmp_path, capsys, motion, kind):
    tex = _texture()
    write_image(tmp_path / "a.png", _warp(tex))
    write_image(tmp_path / "b.png", _warp(tex, **motion))
    out = tmp_path / "flow.png"
    code = main(["flow", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "-o", str(out),
                 "--json"])  # fmt: skip
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    assert result["motion"] == kind
    assert result["tracked"] >= 0.8 * result["points"] > 50  # zoom: borders leave, windows change
    if kind == "translation":
        assert np.allclose(result["translation"], motion["shift"], atol=0.05)
    if kind == "rotation":
        assert result["rotation_deg"] == pytest.approx(3.0, abs=0.05)
    if kind == "zoom":
        assert result["scale"] == pytest.approx(1.04, abs=0.002)
    assert read_image(out).shape == (160, 200, 3)


def test_flow_pair_dense_and_bad_pairs(tmp_path, capsys):
    tex = _texture()
    write_image(tmp_path / "a.png", _warp(tex))
    write_image(tmp_path / "b.png", _warp(tex, shift=(2.0, 0.0)))
    out = tmp_path / "dense.png"
    code = main(["flow", str(tmp_path / "a.png"), str(tmp_path / "b.png"), "-o", str(out),
                 "--dense", "--step", "8"])  # fmt: skip
    assert code == 0
    assert "translation" in capsys.readouterr().out
    picture = read_image(out)
    assert picture.shape == (160, 200, 3)
    # a uniform rightward flow is red everywhere the grid reaches (hue 0)
    centre = picture[40:100, 40:120].reshape(-1, 3)
    assert np.median(centre[:, 0]) == 255 and np.median(centre[:, 1]) < 40
    write_image(tmp_path / "small.png", tex[:50, :50])
    assert main(["flow", str(tmp_path / "a.png"), str(tmp_path / "small.png")]) == 1
    assert "same size" in capsys.readouterr().err
    assert main(["flow", "a", "b", "c"]) == 2


def test_flow_video_tracks_points_through_frames(tmp_path, capsys):
    tex = _texture()
    frames = [_warp(tex, shift=(2.0 * t, 1.0 * t)) for t in range(8)]
    seq = _folder(tmp_path / "seq", frames)
    out = tmp_path / "tracks.mp4"
    assert main(["flow", str(seq), "-o", str(out), "--max-corners", "100", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "translation 7" in text  # every frame pair named translation
    with VideoReader(out) as video:
        assert video.frame_count == 8


def _disc_frames(n=10):
    frames, centres = [], []
    for t in range(n):
        centre = (40.0 + 4 * t, 50.0 + 2 * t)
        gen = np.random.default_rng(t)
        img = np.empty((120, 160, 3), dtype=np.uint8)
        img[..., 0] = gen.integers(60, 90, (120, 160))
        img[..., 1] = gen.integers(100, 140, (120, 160))
        img[..., 2] = gen.integers(60, 90, (120, 160))
        yy, xx = np.mgrid[:120, :160]
        img[(xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= 15**2] = (220, 30, 40)
        frames.append(img)
        centres.append(centre)
    return frames, np.array(centres)


def test_meanshift_follows_the_disc(tmp_path, capsys):
    frames, centres = _disc_frames()
    seq = _folder(tmp_path / "seq", frames)
    csv = tmp_path / "boxes.csv"
    code = main(["meanshift", str(seq), "--box", "25,35,30,30", "-o", str(tmp_path / "m.mp4"),
                 "--results", str(csv), "--quiet"])  # fmt: skip
    assert code == 0
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert rows.shape == (10, 6)
    centre = rows[:, 1:3] + (rows[:, 3:5] - 1) / 2
    assert np.abs(centre - centres).max() <= 1.5
    assert (rows[1:, 5] > 0.8).all()
    assert "similarity" in capsys.readouterr().out


def test_meanshift_box_outside_the_image_is_refused(tmp_path, capsys):
    frames, _ = _disc_frames(2)
    seq = _folder(tmp_path / "seq", frames)
    code = main(["meanshift", str(seq), "--box", "150,10,30,30", "-o", str(tmp_path / "m.mp4")])
    assert code == 1
    assert "not inside" in capsys.readouterr().err
    assert main(["meanshift", str(seq), "--box", "1,2,3"]) == 2


def test_track_from_background_subtraction(tmp_path, capsys):
    """Two discs on the synthetic background: two long tracks, one per disc."""
    from robopercept.tracking import read_mot

    frames, _ = moving_blobs(40, (128, 96), n_blobs=2, radius=(9.0, 11.0), speed=2.0,
                                 illumination_drift=0.0, rng=3)  # fmt: skip
    seq = _folder(tmp_path / "seq", frames)
    results = tmp_path / "tracks.txt"
    code = main(["track", str(seq), "-o", str(tmp_path / "t.mp4"), "--results", str(results),
                 "--min-area", "50", "--quiet"])  # fmt: skip
    assert code == 0
    rows = read_mot(results)
    _, counts = np.unique(rows.id, return_counts=True)
    assert (counts >= 10).sum() == 2  # two long identities
    assert rows.frame.min() >= 21  # the Gaussian model learns during frames 1-20
    assert "identities" in capsys.readouterr().out


def test_track_with_detections_equals_the_library(tmp_path):
    from robopercept.tracking import MultiObjectTracker, read_mot, write_mot

    frames, _ = _disc_frames(12)
    seq = _folder(tmp_path / "seq", frames)
    gen = np.random.default_rng(0)
    det_rows = []
    for t in range(12):
        if t == 6:
            continue  # a missed detection
        x, y = 25 + 4 * t + gen.normal(0, 0.5), 35 + 2 * t + gen.normal(0, 0.5)
        det_rows.append((t + 1, -1, (x, y, 30, 30), 0.9))
        det_rows.append((t + 1, -1, (120, 90, 20, 20), 0.2))  # weak clutter
    write_mot(tmp_path / "det.txt", det_rows)
    results = tmp_path / "out.txt"
    code = main(["track", str(seq), "--detections", str(tmp_path / "det.txt"),
                 "--min-score", "0.5", "--results", str(results), "-o",
                 str(tmp_path / "t.mp4"), "--quiet"])  # fmt: skip
    assert code == 0
    got = read_mot(results)  # boxes written with 2 decimals: atol 0.006
    det = read_mot(tmp_path / "det.txt")
    tracker = MultiObjectTracker()
    expected = []
    for number in range(1, 13):
        d = det.at(number)
        keep = d.conf >= 0.5
        for track in tracker.update(d.boxes[keep], d.conf[keep]):
            expected.append((number, track.id, *track.box))
    assert np.allclose(np.c_[got.frame, got.id, got.boxes], np.array(expected), atol=0.006)
    assert set(got.id) == {1}


@pytest.mark.realdata
def test_track_mot17_equals_the_library(tmp_path):
    from robopercept.tracking import MultiObjectTracker, read_mot

    seq = data_path("video", "mot17_mini", "MOT17-04-FRCNN")
    results = tmp_path / "mot.txt"
    code = main(["track", str(seq / "img1"), "--detections", str(seq / "det" / "det.txt"),
                 "--min-score", "0.5", "--results", str(results), "-o",
                 str(tmp_path / "t.mp4"), "--quiet"])  # fmt: skip
    assert code == 0
    got = read_mot(results)  # boxes written with 2 decimals: atol 0.006
    det = read_mot(seq / "det" / "det.txt")
    tracker = MultiObjectTracker()
    n = 0
    for number in range(1, 9):
        d = det.at(number)
        keep = d.conf >= 0.5
        for track in tracker.update(d.boxes[keep], d.conf[keep]):
            row = np.flatnonzero((got.frame == number) & (got.id == track.id))
            assert len(row) == 1 and np.allclose(got.boxes[row[0]], track.box, atol=0.006)
            n += 1
    assert n == len(got) > 100


@pytest.mark.realdata
@pytest.mark.parametrize("video", [("pets2009_vtest", "vtest_480x360.avi"),
                                   ("opencv_tree", "tree.avi")])  # fmt: skip
def test_bgsub_runs_on_the_real_videos(tmp_path, capsys, video):
    path = data_path("video", *video)
    out = tmp_path / "o.mp4"
    assert main(["bgsub", str(path), "--max-frames", "40", "-o", str(out), "--quiet"]) == 0
    with VideoReader(out) as reader:
        assert reader.frame_count == 40


def test_video_file_input(tmp_path, capsys, blobs):
    """An MP4 (lossy) goes through the same path as a folder."""
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, fps=10) as writer:
        for f in blobs[0][:12]:
            writer.write(f)
    code = main(["bgsub", str(path), "--method", "diff", "-o", str(tmp_path / "o.mp4"),
                 "--max-frames", "10", "--quiet"])  # fmt: skip
    assert code == 0
    assert "frames            10" in capsys.readouterr().out
