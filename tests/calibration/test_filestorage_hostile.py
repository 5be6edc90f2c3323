"""Deeply nested calibration files (issue 47, R32, R33): the OpenCV FileStorage reader
(YAML, XML, JSON), ``load_calibration`` and ``read_transform`` refuse a file nested
deeper than ``robopercept.fileio.MAX_NESTING`` with a FileFormatError naming it (before
the recursive parsers run), never RecursionError, and still read real nesting."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.calibration import load_calibration, read_opencv_storage
from robopercept.calibration.ros import read_transform
from robopercept.errors import FileFormatError
from robopercept.fileio import MAX_NESTING

N = 5000  # far past Python's recursion limit for the recursive readers (400 levels of
# indentation, 3 frames each, are past it too)


def _yaml_block(depth: int) -> str:
    return (
        "%YAML:1.0\n" + "".join(" " * i + f"k{i}:\n" for i in range(depth)) + " " * depth + "v: 1\n"
    )


DEEP = {
    "deep.json": '{"camera_matrix": ' + "[" * N + "]" * N + "}",
    "deep_list.json": '{"a": [1, ' + "[" * N + "]" * N + "]}",
    "deep.xml": "<opencv_storage>" + "<a>" * N + "1" + "</a>" * N + "</opencv_storage>",
    "deep_seq.xml": "<opencv_storage><x>" + "<_>" * N + "1" + "</_>" * N + "</x></opencv_storage>",
    "deep_flow.yml": "%YAML:1.0\na: " + "[" * N + "]" * N + "\n",
    "deep_flow_map.yml": "%YAML:1.0\na: {b: " + "[1, " * N + "]" * N + "}\n",
    "deep_flow_lines.yml": "%YAML:1.0\na: " + "[\n" * N + "]\n" * N,
    "deep_block.yml": _yaml_block(400),  # indented: the file grows as the square
    "deep_dashes.yml": "%YAML:1.0\na:\n  " + "- " * N + "1\n",
    "deep_items.yml": "%YAML:1.0\n" + "".join(" " * (2 * i) + "- k:\n" for i in range(400)),
    # just past the limit: each form alone, counted exactly on the parsed value
    "deep_65.yml": _yaml_block(MAX_NESTING),
    "deep_65.xml": "<opencv_storage>"
    + "<a>" * (MAX_NESTING + 1)
    + "1"
    + "</a>" * (MAX_NESTING + 1)
    + "</opencv_storage>",
}


@pytest.mark.parametrize("name", sorted(DEEP))
@pytest.mark.parametrize("reader", [read_opencv_storage, load_calibration, read_transform])
def test_deep_files_are_a_file_format_error(tmp_path, name, reader):
    p = tmp_path / name
    p.write_text(DEEP[name])
    with pytest.raises(FileFormatError, match=rf"{name}.*nested more than {MAX_NESTING} levels"):
        reader(p)


@pytest.mark.parametrize(
    "text",
    [
        _yaml_block(MAX_NESTING - 1),
        "<opencv_storage>" + "<a>" * MAX_NESTING + "1" + "</a>" * MAX_NESTING + "</opencv_storage>",
        "%YAML:1.0\na: " + "[" * (MAX_NESTING - 1) + "1" + "]" * (MAX_NESTING - 1) + "\n",
        '{"a": ' + "[" * (MAX_NESTING - 1) + "1" + "]" * (MAX_NESTING - 1) + "}",
    ],
)
def test_nesting_up_to_the_limit_is_read(tmp_path, text):
    p = tmp_path / "ok.yml"
    p.write_text(text)
    value = read_opencv_storage(p)
    depth = 0
    while isinstance(value, (dict, list)):
        value = next(iter(value.values())) if isinstance(value, dict) else value[0]
        depth += 1
    assert depth == MAX_NESTING and value == 1


def test_a_calibration_json_still_loads(tmp_path):
    p = tmp_path / "cam.json"
    p.write_text(
        '{"K": [[500, 0, 320], [0, 500, 240], [0, 0, 1]], "dist": [0, 0, 0, 0, 0], '
        '"image_size": [640, 480]}'
    )
    cam = load_calibration(p)
    assert cam["image_size"] == (640, 480) and np.array_equal(cam["K"][2], [0, 0, 1])
    p.write_text("{not json")
    with pytest.raises(FileFormatError, match=r"cam\.json: not valid JSON"):
        load_calibration(p)
