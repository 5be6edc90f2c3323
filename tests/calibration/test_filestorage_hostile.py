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


# -- E1-F2, E1-F7: entity bombs and numbers too long to convert ---------------------------


def _bomb(levels: int = 7) -> str:
    return (
        '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol0 "lololololololololololol">\n'
        + "".join(f' <!ENTITY lol{k} "{f"&lol{k - 1};" * 10}">\n' for k in range(1, levels + 1))
        + f"]>\n<opencv_storage><a>&lol{levels};</a></opencv_storage>\n"
    )


@pytest.mark.parametrize("reader", [read_opencv_storage, load_calibration])
def test_an_entity_bomb_is_refused_before_expansion(tmp_path, reader):
    """E1-F2: expat expanded the bomb to 20 MiB before its amplification limit refused
    it; the DOCTYPE is now refused before parsing, with a small peak."""
    import tracemalloc

    p = tmp_path / "bomb.xml"
    p.write_text(_bomb())
    tracemalloc.start()
    try:
        with pytest.raises(FileFormatError, match=r"bomb\.xml: has a DOCTYPE/ENTITY"):
            reader(p)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * 2**20


@pytest.mark.parametrize(
    "text",
    [
        "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: " + "9" * 5000 + "\n   cols: 1\n"
        "   dt: d\n   data: [1]\n",
        "%YAML:1.0\nn: " + "9" * 5000 + "\n",
        "%YAML:1.0\nn: [1, -" + "9" * 5000 + "]\n",
        '<?xml version="1.0"?><opencv_storage><n>' + "9" * 5000 + "</n></opencv_storage>",
    ],
    ids=["rows", "scalar", "flow", "xml"],
)
def test_an_integer_of_thousands_of_digits_is_a_file_format_error(tmp_path, text):
    """E1-F7: a 5,000-digit integer was Python's ValueError (int max str digits)."""
    p = tmp_path / "big.yml"
    p.write_text(text)
    with pytest.raises(FileFormatError, match=r"big\.yml.*an integer of 500\d digits"):
        read_opencv_storage(p)


def test_a_translation_too_large_for_a_float_is_a_file_format_error(tmp_path):
    """E1-F7: a 400-digit integer translation was OverflowError in read_transform."""
    p = tmp_path / "t.yaml"
    p.write_text(
        "header:\n  frame_id: a\nchild_frame_id: b\ntransform:\n  translation:\n"
        f"    x: {'9' * 400}\n    y: 0\n    z: 0\n  rotation:\n    x: 0\n    y: 0\n"
        "    z: 0\n    w: 1\n"
    )
    with pytest.raises(FileFormatError, match=r"t\.yaml: not a transform.*too large"):
        read_transform(p)
