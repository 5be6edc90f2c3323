"""The file-name rules of ``robopercept.imaging.io`` (issue 47): :func:`contained_path`
keeps the files an annotation or list names inside the data set's folder (R43), and
:func:`output_stems` gives inputs that share a name distinct outputs (R44)."""

from __future__ import annotations

import os

import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging.io import contained_path, output_stems


class TestContainedPath:
    @pytest.mark.parametrize(
        "name", ["a.png", "rgb/1.png", "a/../b.png", "./x/y.png", "..hidden.png", "a..b"]
    )
    def test_names_inside_are_joined_as_written(self, tmp_path, name):
        assert contained_path(tmp_path, name, "gt.json: images[0].file_name") == tmp_path / name

    @pytest.mark.parametrize(
        "name", ["../x.png", "../../etc/passwd", "a/../../x.png", "..", "/etc/passwd", "//x"]
    )
    def test_names_outside_are_refused_naming_the_entry_and_the_fix(self, tmp_path, name):
        with pytest.raises(FileFormatError) as err:
            contained_path(tmp_path, name, "gt.json: images[3].file_name")
        msg = str(err.value)
        assert msg.startswith(f"gt.json: images[3].file_name {name!r} leads outside")
        assert str(tmp_path) in msg
        assert "allow_outside=True" in msg and "--allow-outside-paths" in msg

    @pytest.mark.parametrize("name", ["../x.png", "/etc/passwd"])
    def test_allow_outside_takes_them(self, tmp_path, name):
        got = contained_path(tmp_path, name, "rgb.txt:3", allow_outside=True)
        assert got == tmp_path / name

    @pytest.mark.parametrize("name", [None, 3, "", "a\0b", "x" * 300])
    def test_unusable_names_are_a_file_format_error(self, tmp_path, name):
        with pytest.raises(FileFormatError, match=r"rgb\.txt:3: not a usable file name"):
            contained_path(tmp_path, name, "rgb.txt:3")

    def test_bad_arguments(self, tmp_path):
        with pytest.raises(InputError, match="allow_outside must be True or False"):
            contained_path(tmp_path, "a.png", "x", allow_outside="yes")
        with pytest.raises(InputError, match="root"):
            contained_path(None, "a.png", "x")


class TestOutputStems:
    def test_distinct_stems_are_kept(self):
        assert output_stems(["a/x.png", "b/y.jpg", "z.tif"]) == ["x", "y", "z"]
        assert output_stems([]) == []

    def test_a_shared_stem_takes_the_folders_that_tell_them_apart(self, tmp_path):
        assert output_stems(["a/x.png", "b/x.png", "b/y.png"]) == ["a_x", "b_x", "y"]
        assert output_stems(["a/c/x.png", "b/c/x.png"]) == ["a_c_x", "b_c_x"]
        assert output_stems(["a/x.png", "b/X.jpg"]) == ["a_x", "b_X"]  # no case
        # absolute and relative spellings of folders count by where they are
        assert output_stems([str(tmp_path / "p" / "x.png"), "q/x.png"]) == ["p_x", "q_x"]

    def test_still_alike_inputs_get_numbers_in_input_order(self):
        assert output_stems(["x.png", "x.png", "x.jpg"]) == ["x", "x-2", "x-3"]
        assert output_stems(["a/x.png", "a/x.jpg", "b/x.png"]) == ["a_x", "a_x-2", "b_x"]
        # the prefixed name meets another input's own stem
        assert output_stems(["a/x.png", "b/x.png", "a_x.png"]) == ["a_x", "b_x", "a_x-2"]

    def test_suffixes_keep_every_written_name_distinct(self):
        ends = (".png", "_labels.png")
        assert output_stems(["x.png", "x_labels.png"], ends) == ["x", "x_labels-2"]
        assert output_stems(["x_labels.png", "x.png"], ends) == ["x_labels", "x-2"]

    def test_every_output_name_is_distinct(self, tmp_path):
        names = ["a/x.png", "b/x.png", "x.png", "x.png", "a_x.png", "a/b/x.png", "c/b/x.png"]
        ends = (".png", "_labels.png")
        stems = output_stems(names, ends)
        written = [(s + e).casefold() for s in stems for e in ends]
        assert len(set(written)) == len(written)
        assert all(os.sep not in s for s in stems)

    @pytest.mark.parametrize(
        ("paths", "suffixes", "match"),
        [
            ("x.png", (".png",), "paths must be a list"),
            (None, (".png",), "paths must be a list"),
            ([None], (".png",), r"paths\[0\]"),
            (["a.png", "/"], (".png",), r"paths\[1\] must name a file; got '/'"),
            ([".."], (".png",), r"paths\[0\] must name a file"),
            (["x.png"], ".png", "suffixes must be a list of strings"),
            (["x.png"], [1], "suffixes must be a list of strings"),
        ],
    )
    def test_bad_arguments(self, paths, suffixes, match):
        with pytest.raises(InputError, match=match):
            output_stems(paths, suffixes)
