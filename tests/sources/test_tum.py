"""TUM-layout folders: write and read back, association, and every documented failure."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.geometry import CameraIntrinsics, se3
from robopercept.imaging.io import write_image
from robopercept.sources import RGBDFrame, TUMFolderSource, read_camera_json, write_tum_folder

KD = CameraIntrinsics(32, 24, 30.0, 30.0, 15.5, 11.5, "brown_conrady", (0.01, 0, 0, 0, 0))
KC = CameraIntrinsics(40, 30, 36.0, 36.5, 19.5, 14.5)
T = se3([0.0, 0.01, 0.0], [-0.015, 0.0, 0.0])


def frames(n=4, seed=0):
    rng = np.random.default_rng(seed)
    for i in range(n):
        yield RGBDFrame(
            i,
            1000.0 + i / 30,
            rng.integers(0, 4000, (24, 32)).astype(np.uint16),
            rng.integers(0, 255, (30, 40, 3), dtype=np.uint8),
            KD,
            KC,
            T,
            0.001,
            {"plane": (np.array([0.0, 0.6, -0.8]), 1.25 + i)} if i != 2 else {},
        )


def test_round_trip(tmp_path):
    written = list(frames())
    folder = write_tum_folder(tmp_path / "seq", written)
    src = TUMFolderSource(folder)
    assert len(src) == 4
    back = list(src)
    for a, b in zip(written, back, strict=True):
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.color, b.color)
        assert abs(a.timestamp - b.timestamp) < 1e-6
        np.testing.assert_allclose(b.T_color_depth, T)
        assert b.depth_intrinsics == KD and b.color_intrinsics == KC and b.depth_scale == 0.001
    assert sorted(src.planes) == [0, 1, 3] and "plane" not in back[2].ground_truth
    np.testing.assert_allclose(back[3].ground_truth["plane"][0], [0, 0.6, -0.8])
    assert src.skipped == []
    cam = read_camera_json(folder / "camera.json")
    assert cam["depth"].model == "brown_conrady"


def test_stored_frames_read_back_the_same(tmp_path):
    # png_compression=0 (scratch folders: the plane sweep's) changes the files' size,
    # not what is read back
    written = list(frames())
    a = write_tum_folder(tmp_path / "a", written)
    b = write_tum_folder(tmp_path / "b", written, png_compression=0)
    for fa, fb in zip(TUMFolderSource(a), TUMFolderSource(b), strict=True):
        assert np.array_equal(fa.depth, fb.depth) and np.array_equal(fa.color, fb.color)
    # the depth maps (values < 4096) compress; the random colours do not
    size = {k: sum(f.stat().st_size for f in (tmp_path / k / "depth").iterdir()) for k in "ab"}
    assert size["b"] > size["a"]


def test_a_cut_sequence_keeps_each_frames_truth(tmp_path):
    """Frames 2 and 3 of a sequence (indices 2, 3) written alone read back as the
    folder's frames 0 and 1, each with its own plane (the truth was keyed by the
    scene's index, so a cut sequence read its frames against other frames' planes)."""
    written = list(frames())[2:]
    src = TUMFolderSource(write_tum_folder(tmp_path / "cut", written))
    back = list(src)
    assert sorted(src.planes) == [1]  # frame 2 has no plane
    assert "plane" not in back[0].ground_truth
    assert back[1].ground_truth["plane"][1] == pytest.approx(written[1].ground_truth["plane"][1])


def test_association_by_nearest_timestamp(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(3))
    # shift the colour timestamps by 10 ms and drop one colour image from the list
    lines = (folder / "rgb.txt").read_text().splitlines()
    shifted = [lines[0]] + [
        f"{float(ln.split()[0]) + 0.01:.6f} {ln.split()[1]}"
        for ln in lines[1:]
        if "1000.0333" not in ln
    ]
    (folder / "rgb.txt").write_text("\n".join(shifted) + "\n")
    src = TUMFolderSource(folder, max_difference=0.02)
    # depth 1000.0333 has no colour within 20 ms except its neighbours (23 ms away)
    assert len(src) == 2
    assert [round(t, 4) for t, _, _ in src.pairs] == [1000.0, 1000.0667]


def test_corrupt_frame_is_skipped_and_counted(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(3))
    bad = sorted((folder / "rgb").iterdir())[1]
    bad.write_bytes(b"\x89PNG\r\n\x1a\n not really a png")
    src = TUMFolderSource(folder)
    with pytest.warns(UserWarning, match="skipping frame 1"):
        got = [f.index for f in src]
    assert got == [0, 2] and [i for i, _ in src.skipped] == [1]


# issue 25: a missing file or a frame of the wrong size ended the run at that frame
# (plane-track then exited 0 with 50 of 60 frames unprocessed): now skipped and counted
# like a corrupt frame, with a warning naming the file
def test_missing_frame_file_is_skipped_counted_and_named(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(3))
    victim = sorted((folder / "depth").iterdir())[1]
    victim.unlink()
    src = TUMFolderSource(folder)
    with pytest.warns(UserWarning, match=rf"skipping frame 1: .*{re.escape(victim.name)}.*missing"):
        got = [f.index for f in src]
    assert got == [0, 2] and [i for i, _ in src.skipped] == [1]
    assert victim.name in src.skipped[0][1]


def test_frame_of_the_wrong_size_is_skipped_and_counted(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(3))
    victim = sorted((folder / "rgb").iterdir())[2]
    write_image(victim, np.zeros((20, 40, 3), np.uint8))  # 40x20, camera.json: 40x30
    src = TUMFolderSource(folder)
    with pytest.warns(UserWarning, match=r"skipping frame 2: .*camera\.json"):
        got = [f.index for f in src]
    assert got == [0, 1] and [i for i, _ in src.skipped] == [2]


def test_sizes_must_match_camera_json(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(2))
    cam = json.loads((folder / "camera.json").read_text())
    cam["depth"]["width"] = 64
    (folder / "camera.json").write_text(json.dumps(cam))
    src = TUMFolderSource(folder)
    with pytest.warns(UserWarning, match=r"depth is \(32, 24\) .* 64x24: check camera\.json"):
        assert list(src) == []
    assert [i for i, _ in src.skipped] == [0, 1]


# issue 25: a source error that cannot be skipped (the folder vanished) stops the run,
# naming the folder
def test_a_vanished_folder_is_named(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(3))
    src = TUMFolderSource(folder)
    it = iter(src)
    assert next(it).index == 0
    shutil.rmtree(folder)
    with pytest.raises(FileFormatError, match=rf"{re.escape(str(folder))}: the folder is gone"):
        next(it)


# issue 25: non-UTF-8 lists and camera.json, Infinity sizes and over-long names raised
# UnicodeDecodeError, OverflowError and OSError (ENAMETOOLONG) instead of FileFormatError
@pytest.mark.parametrize("name", ["rgb.txt", "depth.txt", "camera.json", "planes.csv"])
def test_non_utf8_files_are_named(tmp_path, name):
    folder = write_tum_folder(tmp_path / "seq", frames(1))
    (folder / name).write_bytes(b"\xff\xfe\x00garbage \xc3\x28\n")
    with pytest.raises(FileFormatError, match=rf"{re.escape(name)}: not UTF-8"):
        TUMFolderSource(folder)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda c: c["depth"].update(width=float("inf")), "bad 'depth' camera"),
        (lambda c: c["color"].update(height=float("-inf")), "bad 'color' camera"),
        (lambda c: c.update(depth_scale=float("inf")), "depth_scale a finite number"),
        (lambda c: c["T_color_depth"][0].__setitem__(3, float("nan")), "finite numbers"),
    ],
)
def test_infinite_sizes_in_camera_json_are_named(tmp_path, edit, match):
    folder = write_tum_folder(tmp_path / "seq", frames(1))
    cam = json.loads((folder / "camera.json").read_text())
    edit(cam)
    (folder / "camera.json").write_text(json.dumps(cam))  # writes Infinity / NaN
    with pytest.raises(FileFormatError, match=rf"camera\.json: .*{match}"):
        TUMFolderSource(folder)


def test_over_long_names_are_named(tmp_path):
    folder = write_tum_folder(tmp_path / "seq", frames(1))
    long_name = "rgb/" + "x" * 300 + ".png"
    (folder / "rgb.txt").write_text(f"1000.0 {long_name}\n")
    with pytest.raises(FileFormatError, match=r"rgb\.txt:1: file name too long"):
        TUMFolderSource(folder)
    # issue 25: a folder name the OS would refuse is a bad argument, refused before use
    with pytest.raises(InputError, match="file name too long"):
        TUMFolderSource(tmp_path / ("y" * 300))


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        (lambda f: (f / "depth.txt").unlink(), "depth.txt"),
        (lambda f: (f / "camera.json").write_text("{"), "JSON"),
        (lambda f: (f / "camera.json").write_text('{"depth": {}}'), "needs depth"),
        (lambda f: (f / "rgb.txt").write_text("oops\n"), "timestamp file"),
        (lambda f: (f / "planes.csv").write_text("frame,nx\n0,1\n"), "frame,nx,ny,nz,d"),
    ],
)
def test_bad_folders(tmp_path, damage, match):
    folder = write_tum_folder(tmp_path / "seq", frames(1))
    damage(folder)
    with pytest.raises(FileFormatError, match=match):
        TUMFolderSource(folder)
    with pytest.raises(FileFormatError, match="not a folder"):
        TUMFolderSource(tmp_path / "nothing")


# issue 25: paths, frames, cameras and scalars of the wrong type are InputErrors
@pytest.mark.parametrize(
    "call, words",
    [
        (lambda t: read_camera_json(None), "must be a file or folder path .* got None"),
        (lambda t: read_camera_json(3), "must be a file or folder path .* got 3"),
        (lambda t: TUMFolderSource(3), "must be a file or folder path"),
        (lambda t: TUMFolderSource(t, max_difference=[1, 2]), r"max_difference \(seconds\)"),
        (lambda t: write_tum_folder(None, frames(1)), "must be a file or folder path"),
        (lambda t: write_tum_folder(str(t / "nul\x00name"), frames(1)), "NUL byte"),
        (lambda t: write_tum_folder(t / ("n" * 300), frames(1)), "file name too long"),
        (lambda t: write_tum_folder(t / "o", 3), "frames must be an iterable of RGBDFrame"),
        (lambda t: write_tum_folder(t / "o", [3]), "frames must be RGBDFrame objects"),
        (
            lambda t: write_tum_folder(t / "o", frames(1), png_compression=10),
            "png_compression must be in 0..9",
        ),
        (
            lambda t: write_tum_folder(t / "o", frames(1), png_compression=1.5),
            "png_compression must be an integer",
        ),
    ],
)
def test_bad_arguments_give_input_errors(tmp_path, call, words):
    write_tum_folder(tmp_path / "seq", frames(1))
    with pytest.raises(InputError, match=words):
        call(tmp_path / "seq")


def test_bytes_paths_still_work(tmp_path):
    folder = write_tum_folder(str(tmp_path / "seq").encode(), frames(2))
    assert read_camera_json(bytes(folder / "camera.json"))["depth_scale"] == 0.001
    assert len(list(TUMFolderSource(bytes(folder), max_difference=np.float32(0.02)))) == 2


@pytest.mark.parametrize(
    "change, words",
    [
        ({"depth_intrinsics": np.nan}, "depth_intrinsics must be a CameraIntrinsics; got float"),
        ({"color_intrinsics": []}, "color_intrinsics must be a CameraIntrinsics; got list"),
        ({"depth": np.uint16(3)}, "depth must be a numpy array; got uint16"),
        ({"depth_scale": "0.001"}, r"depth_scale \(metres per unit\) must be a real number"),
    ],
)
def test_bad_frames(change, words):
    import dataclasses

    with pytest.raises(InputError, match=words):
        dataclasses.replace(next(frames(1)), **change)
