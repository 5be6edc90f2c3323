"""Issue 47 R43 (rgbd-import part) and R48: lists that lead outside the source folder,
and lists that are not UTF-8."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.errors import FileFormatError, InputError
from robopercept.imaging.io import read_image, write_image
from robopercept.sources import import_rgbd_folder
from robopercept.sources.rgbd_import import find_rgbd_pairs

SECRET = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3) * 3


def _folders(tmp_path):
    """``src`` with one inside pair, and an image outside it that ``secret`` names."""
    src = tmp_path / "data" / "src"
    (src / "rgb").mkdir(parents=True)
    (src / "depth").mkdir()
    write_image(src / "rgb" / "1.png", np.zeros((4, 5, 3), np.uint8))
    write_image(src / "depth" / "1.png", np.full((4, 5), 5000, np.uint16))
    outside = tmp_path / "private"
    outside.mkdir()
    write_image(outside / "secret.png", SECRET)
    write_image(outside / "secret_depth.png", np.full((4, 5), 5000, np.uint16))
    return src, outside


OUTSIDE_NAMES = [
    "../../private/secret.png",  # '..' above the folder
    "rgb/../../../private/secret.png",
    "ABS",  # an absolute path, filled in below
]


@pytest.mark.parametrize("name", OUTSIDE_NAMES)
def test_association_list_entries_outside_the_folder_are_refused(tmp_path, name):
    src, outside = _folders(tmp_path)
    if name == "ABS":
        name = str(outside / "secret.png")
    (src / "associations.txt").write_text(
        f"1.0 rgb/1.png 1.0 depth/1.png\n2.0 {name} 2.0 depth/1.png\n"
    )
    out = tmp_path / "out"
    # before: rgbd-import copied the outside image into OUT
    with pytest.raises(FileFormatError, match=r"associations\.txt:2: file \(column 2\)") as e:
        import_rgbd_folder(src, out, intrinsics=(5, 5, 2, 1.5))
    assert "--allow-outside-paths" in str(e.value) and "allow_outside=True" in str(e.value)
    assert not out.exists()
    with pytest.raises(FileFormatError, match="leads outside"):
        find_rgbd_pairs(src)


def test_association_depth_column_outside_is_refused(tmp_path):
    src, _ = _folders(tmp_path)
    (src / "associate.txt").write_text("1.0 rgb/1.png 1.0 ../../private/secret_depth.png\n")
    with pytest.raises(FileFormatError, match=r"associate\.txt:1: file \(column 4\)"):
        find_rgbd_pairs(src)


def test_outside_entries_are_read_when_allowed(tmp_path, capsys):
    src, _ = _folders(tmp_path)
    (src / "associations.txt").write_text("1.0 ../../private/secret.png 1.0 depth/1.png\n")
    res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5), allow_outside=True)
    assert res.frames == 1
    [png] = (tmp_path / "out" / "rgb").iterdir()
    assert np.array_equal(read_image(png, mode="rgb"), SECRET)
    # the command: refused (exit 1, the line named), then taken with the flag
    args = ["rgbd-import", str(src), str(tmp_path / "o2"), "--intrinsics", "5,5,2,1.5", "-q"]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "associations.txt:1" in err and "--allow-outside-paths" in err
    assert not (tmp_path / "o2").exists()
    assert main([*args, "--allow-outside-paths"]) == 0
    assert len(list((tmp_path / "o2" / "rgb").iterdir())) == 1


def test_tum_lists_outside_the_folder_are_refused(tmp_path):
    src, outside = _folders(tmp_path)
    (src / "rgb.txt").write_text(f"1.0 {outside / 'secret.png'}\n")
    (src / "depth.txt").write_text("1.0 depth/1.png\n")
    with pytest.raises(FileFormatError, match=r"rgb\.txt:1: file .* leads outside"):
        import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
    assert not (tmp_path / "out").exists()
    layout, pairs = find_rgbd_pairs(src, allow_outside=True)
    assert layout == "tum-lists" and pairs[0].color == outside / "secret.png"


def test_inside_names_with_dots_are_taken(tmp_path):
    src, _ = _folders(tmp_path)
    (src / "associations.txt").write_text("1.0 ./rgb/../rgb/1.png 1.0 depth/./1.png\n")
    res = import_rgbd_folder(src, tmp_path / "out", intrinsics=(5, 5, 2, 1.5))
    assert res.frames == 1


def test_allow_outside_must_be_a_bool(tmp_path):
    src, _ = _folders(tmp_path)
    with pytest.raises(InputError, match="allow_outside"):
        find_rgbd_pairs(src, allow_outside="yes")


# ------------------------------------------------------------------ R48 encodings
@pytest.mark.parametrize(
    "data",
    [
        b"1.0 rgb/1.png 1.0 depth/1.png\n2.0 rgb/\xff\xfe.png 2.0 depth/1.png\n",  # Latin-1
        "1.0 rgb/1.png 1.0 depth/1.png\n".encode("utf-16"),
    ],
    ids=["latin-1", "utf-16"],
)
def test_association_list_not_utf8(tmp_path, capsys, data):
    src, _ = _folders(tmp_path)
    (src / "associations.txt").write_bytes(data)
    # before: UnicodeDecodeError, exit 70
    with pytest.raises(FileFormatError, match=r"associations\.txt: not UTF-8 text \(byte \d+\)"):
        find_rgbd_pairs(src)
    args = ["rgbd-import", str(src), str(tmp_path / "out"), "--intrinsics", "5,5,2,1.5", "-q"]
    assert main(args) == 1
    assert "not UTF-8 text" in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["nan rgb/1.png 1.0 depth/1.png", "1.0 rgb/1.png inf depth/1.png"])
def test_association_list_non_finite_timestamps(tmp_path, bad):
    src, _ = _folders(tmp_path)
    (src / "associations.txt").write_text(bad + "\n")
    with pytest.raises(FileFormatError, match=r"associations\.txt:1: timestamps must be finite"):
        find_rgbd_pairs(src)


def test_association_list_file_name_too_long(tmp_path):
    src, _ = _folders(tmp_path)
    (src / "associations.txt").write_text(f"1.0 rgb/{'x' * 300}.png 1.0 depth/1.png\n")
    with pytest.raises(FileFormatError, match=r"associations\.txt:1: .*not a usable file name"):
        find_rgbd_pairs(src)
