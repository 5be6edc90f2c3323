"""VideoSource: frames of a video file or an image folder, skipped frames, and refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import VideoReader, VideoWriter, write_image
from robopercept.sources import IMAGE_EXTENSIONS, VideoSource
from tests.conftest import data_path


def _frames(n=5, shape=(24, 32)):
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, (*shape, 3), dtype=np.uint8) for _ in range(n)]


def _folder(path, frames, ext=".png"):
    path.mkdir()
    for i, f in enumerate(frames):
        write_image(path / f"{i:06d}{ext}", f)
    return path


def test_folder_yields_rgb_frames_in_name_order(tmp_path):
    frames = _frames()
    folder = _folder(tmp_path / "seq", frames)
    (folder / "notes.txt").write_text("not a frame")
    src = VideoSource(folder)
    assert len(src) == 5 and src.fps == 25.0 and src.skipped == []
    got = list(src)
    assert [i for i, _ in got] == [0, 1, 2, 3, 4]
    for (_, img), f in zip(got, frames, strict=True):
        assert img.dtype == np.uint8 and np.array_equal(img, f)  # PNG is lossless


def test_gray_images_come_as_rgb(tmp_path):
    folder = _folder(tmp_path / "seq", [np.full((8, 10), 7, np.uint8)] * 2)
    _, img = next(iter(VideoSource(folder)))
    assert img.shape == (8, 10, 3) and (img == 7).all()


def test_unreadable_image_is_skipped_and_its_index_kept(tmp_path):
    folder = _folder(tmp_path / "seq", _frames(4))
    (folder / "000002.png").write_bytes(b"not a png")
    src = VideoSource(folder)
    assert [i for i, _ in src] == [0, 1, 3]
    assert len(src.skipped) == 1 and src.skipped[0][0] == 2 and "000002.png" in src.skipped[0][1]


def test_max_frames_and_fps(tmp_path):
    folder = _folder(tmp_path / "seq", _frames(5))
    src = VideoSource(folder, fps=10, max_frames=3)
    assert len(src) == 3 and src.fps == 10.0
    assert [i for i, _ in src] == [0, 1, 2]
    assert len(VideoSource(folder, max_frames=50)) == 5


def test_video_file_equals_the_video_reader(tmp_path):
    path = tmp_path / "clip.mp4"
    with VideoWriter(path, fps=12) as w:
        for f in _frames(6, (48, 64)):
            w.write(f)
    src = VideoSource(path)
    assert len(src) == 6 and src.fps == pytest.approx(12.0)
    with VideoReader(path) as reader:
        expected = list(reader)
    got = list(src)
    assert [i for i, _ in got] == list(range(6))
    assert all(np.array_equal(g, e) for (_, g), e in zip(got, expected, strict=True))
    short = VideoSource(path, max_frames=2)
    assert len(short) == 2 and [i for i, _ in short] == [0, 1]


def test_refusals_name_the_problem(tmp_path):
    with pytest.raises(FileFormatError, match="no such file or folder"):
        VideoSource(tmp_path / "absent")
    (tmp_path / "empty").mkdir()
    with pytest.raises(FileFormatError, match="no images"):
        VideoSource(tmp_path / "empty")
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00\x01 this is not a video" * 100)
    with pytest.raises(FileFormatError, match=r"broken\.mp4"):
        VideoSource(bad)
    folder = _folder(tmp_path / "seq", _frames(2))
    with pytest.raises(InputError, match="max_frames"):
        VideoSource(folder, max_frames=0)
    with pytest.raises(InputError, match="fps"):
        VideoSource(folder, fps=-1)


def test_extensions_are_lower_case_suffixes():
    assert all(e.startswith(".") and e == e.lower() for e in IMAGE_EXTENSIONS)
    assert {".png", ".jpg"} <= IMAGE_EXTENSIONS


@pytest.mark.realdata
def test_real_video_frames():
    path = data_path("video", "pets2009_vtest", "vtest_480x360.avi")
    src = VideoSource(path, max_frames=3)
    frames = list(src)
    assert len(frames) == 3 and frames[0][1].shape == (360, 480, 3)


# issue 25: paths and scalars of the wrong type are InputErrors
@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"max_frames": 1 + 1j}, r"max_frames \(--max-frames\) must be an integer"),
        ({"max_frames": [1, 2]}, r"max_frames \(--max-frames\) must be an integer"),
        ({"fps": 1 + 1j}, r"fps \(--fps\) must be a real number"),
        ({"fps": np.nan}, r"fps \(--fps\) must be finite"),
    ],
)
def test_bad_scalars_give_input_errors(tmp_path, kwargs, words):
    folder = _folder(tmp_path / "seq", _frames(2))
    with pytest.raises(InputError, match=words):
        VideoSource(folder, **kwargs)
    assert len(VideoSource(folder, fps=np.float32(10), max_frames=np.int64(1))) == 1


@pytest.mark.parametrize("path", [3, None, "nul\x00name"])
def test_unusable_paths_give_input_errors(path):
    with pytest.raises(InputError, match="the video or image folder"):
        VideoSource(path)
