"""Hostile TUM folders (issue 47): a deeply nested ``camera.json`` (R33) and ``rgb.txt`` /
``depth.txt`` entries that lead outside the folder (R43) give a FileFormatError naming
the file (and line), not a RecursionError or a read of the outside file."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.geometry import CameraIntrinsics, se3
from robopercept.imaging.io import write_image
from robopercept.sources import RGBDFrame, TUMFolderSource, read_camera_json, write_tum_folder
from robopercept.sources.tum import CAMERA_JSON_HELP, read_timestamp_list

K = CameraIntrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)


def _folder(tmp_path):
    frame = RGBDFrame(
        0,
        1000.0,
        np.full((24, 32), 1000, np.uint16),
        np.zeros((24, 32, 3), np.uint8),
        K,
        K,
        se3([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]),
        0.001,
        {},
    )
    return write_tum_folder(tmp_path / "seq", [frame])


@pytest.mark.parametrize(
    "text",
    [
        "[" * 100_000,
        '{"depth": ' + "[" * 100_000 + "]" * 100_000 + "}",
        '{"depth": {}, "T_color_depth": [1, ' + "[" * 3000 + "]" * 3000 + "]}",
    ],
)
def test_a_deeply_nested_camera_json_is_refused(tmp_path, text):
    p = tmp_path / "camera.json"
    p.write_text(text)
    with pytest.raises(FileFormatError) as err:
        read_camera_json(p)
    assert "camera.json: nested more than 64 levels" in str(err.value)
    assert str(err.value).endswith(CAMERA_JSON_HELP)


@pytest.mark.parametrize("name", ["rgb.txt", "depth.txt"])
@pytest.mark.parametrize("where", ["../secret.png", "rgb/../../secret.png", "ABS"])
def test_list_entries_outside_the_folder_are_refused(tmp_path, name, where):
    folder = _folder(tmp_path)
    secret = tmp_path / "secret.png"
    write_image(secret, np.zeros((24, 32), np.uint16))
    entry = str(secret) if where == "ABS" else where
    lines = (folder / name).read_text().splitlines()
    lines[-1] = f"{lines[-1].split()[0]} {entry}"
    (folder / name).write_text("\n".join(lines) + "\n")
    line = len(lines)
    with pytest.raises(FileFormatError) as err:
        TUMFolderSource(folder)
    msg = str(err.value)
    assert msg.startswith(f"{folder / name}:{line}: file {entry!r} leads outside")
    assert "allow_outside=True" in msg
    # on request it is taken (a list the user trusts)
    src = TUMFolderSource(folder, allow_outside=True)
    assert len(src) == 1
    rows = read_timestamp_list(folder / name, allow_outside=True)
    assert (folder / rows[-1][1]).resolve() == secret.resolve()


def test_entries_inside_are_read_as_before(tmp_path):
    folder = _folder(tmp_path)
    text = (folder / "rgb.txt").read_text().replace(" rgb/", " rgb/../rgb/")
    (folder / "rgb.txt").write_text(text)
    assert len(list(TUMFolderSource(folder))) == 1


def test_allow_outside_must_be_a_bool(tmp_path):
    folder = _folder(tmp_path)
    with pytest.raises(InputError, match="allow_outside must be True or False"):
        TUMFolderSource(folder, allow_outside="yes")
    with pytest.raises(InputError, match="allow_outside must be True or False"):
        read_timestamp_list(folder / "rgb.txt", allow_outside=None)
