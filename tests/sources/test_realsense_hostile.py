"""Issue 47 R59: an interrupted write_realsense_recording leaves no short recording at
its path (it is written under a temporary name and renamed once complete)."""

from __future__ import annotations

import time

import pytest

from robopercept.sources import SyntheticRGBDScene
from robopercept.sources.realsense import SourceError, write_realsense_recording

pytest.importorskip("pyrealsense2")


def _frames(n: int) -> list:
    return list(SyntheticRGBDScene(n_frames=n, depth_size=(64, 48), color_size=(80, 60)))


def _failing(frames, after, exc, folder):
    """Yield ``frames``; after ``after`` of them wait until the recorder has started its
    file (a truly partial recording on disk), then raise ``exc``."""
    before = set(folder.iterdir())
    for i, f in enumerate(frames):
        if i == after:
            deadline = time.monotonic() + 10.0
            while set(folder.iterdir()) <= before and time.monotonic() < deadline:
                time.sleep(0.02)
            assert set(folder.iterdir()) > before, "the recorder never started its file"
            raise exc
        yield f


@pytest.mark.parametrize("exc", [RuntimeError("camera unplugged"), KeyboardInterrupt()])
def test_interrupted_recording_leaves_no_file_at_its_path(tmp_path, exc):
    out = tmp_path / "rec"
    out.mkdir()
    with pytest.raises(type(exc)):
        write_realsense_recording(out / "s.db3", _failing(_frames(10), 6, exc, out), pace=0.0)
    # before the fix: a 6-frame s.db3 that read back as a complete recording
    assert not (out / "s.db3").exists()
    assert list(out.iterdir()) == []  # the partial temporary file is removed too


def test_interrupted_recording_keeps_the_previous_file(tmp_path):
    out = tmp_path / "rec"
    out.mkdir()
    previous = b"the previous recording"
    (out / "s.db3").write_bytes(previous)
    with pytest.raises(RuntimeError):
        frames = _failing(_frames(4), 2, RuntimeError("stop"), out)
        write_realsense_recording(out / "s.db3", frames, pace=0.0)
    assert (out / "s.db3").read_bytes() == previous
    assert [p.name for p in out.iterdir()] == ["s.db3"]


def test_recorder_dying_leaves_no_file(tmp_path, monkeypatch):
    from robopercept.sources import realsense

    # a recorder that writes part of a file and dies
    monkeypatch.setattr(
        realsense,
        "_RECORDER",
        "import sys, os; open(sys.argv[1], 'wb').write(b'partial'); os._exit(3)",
    )
    with pytest.raises(SourceError, match=r"died writing .*s\.db3"):
        write_realsense_recording(tmp_path / "s.db3", _frames(2), pace=0.0)
    assert list(tmp_path.iterdir()) == []


def test_recording_into_a_new_folder_is_complete(tmp_path):
    path = tmp_path / "new" / "s.db3"
    assert write_realsense_recording(path, _frames(3), pace=0.0) == 3
    assert path.stat().st_size > 0
    assert [p.name for p in path.parent.iterdir()] == ["s.db3"]
