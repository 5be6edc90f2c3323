"""The one bounded reading policy for structured text (robopercept.fileio, issue 47)."""

from __future__ import annotations

import json
import sys

import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import (
    MAX_NESTING,
    check_nesting,
    nesting_depth,
    parse_json,
    read_json,
)


def nested(depth: int, opener: str = "[", closer: str = "]") -> str:
    return opener * depth + "1" + closer * depth


def test_nesting_depth_counts_levels_without_recursion():
    assert nesting_depth(1) == 0
    assert nesting_depth([]) == 1
    assert nesting_depth({"a": [1, {"b": (2,)}]}) == 4
    # far deeper than Python's recursion limit: counted by a stack, stops past the limit
    deep: list = []
    for _ in range(sys.getrecursionlimit() * 3):
        deep = [deep]
    assert nesting_depth(deep, limit=10) == 11


@pytest.mark.parametrize("depth", [MAX_NESTING - 1, MAX_NESTING])
def test_documents_up_to_the_limit_are_read(depth):
    value = parse_json(nested(depth), "a.json")
    assert nesting_depth(value) == depth


@pytest.mark.parametrize(
    "text",
    [
        nested(MAX_NESTING + 1),  # one level too deep
        nested(100_000),  # past the C parser's recursion limit
        '{"a":' * 5000 + "1" + "}" * 5000,
        "[1, " * 3000 + "2" + "]" * 3000,  # deep, but not at the start
        '{"k": ' + nested(MAX_NESTING) + "}",  # deep below the top
    ],
)
def test_too_deep_documents_are_a_file_format_error(text):
    with pytest.raises(FileFormatError, match=r"x\.json: nested more than 64 levels deep"):
        parse_json(text, "x.json")


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("{", "not valid JSON"),
        ("1" * 5000, "not valid JSON"),  # Python refuses ints of over 4300 digits
        (b"\xff\xfe[1]", "not UTF-8"),
        ("", "not valid JSON"),
    ],
)
def test_bad_text_is_a_file_format_error(text, fragment):
    with pytest.raises(FileFormatError, match=fragment):
        parse_json(text, "x.json")


def test_bytes_with_a_byte_order_mark_are_read():
    assert parse_json(b"\xef\xbb\xbf" + json.dumps({"a": 1}).encode(), "x.json") == {"a": 1}


def test_check_nesting_returns_the_value_or_names_the_source():
    assert check_nesting([[1]], "f", limit=2) == [[1]]
    with pytest.raises(FileFormatError, match=r"^f: nested more than 1 levels"):
        check_nesting([[1]], "f", limit=1)


def test_read_json_names_the_file(tmp_path):
    p = tmp_path / "a.json"
    p.write_text(nested(MAX_NESTING + 5))
    with pytest.raises(FileFormatError, match=str(p)):
        read_json(p, "a JSON file")
    with pytest.raises(FileFormatError, match="is a folder; give a JSON file"):
        read_json(tmp_path, "a JSON file")
    with pytest.raises(FileFormatError, match="no such file"):
        read_json(tmp_path / "missing.json", "a JSON file")
    with pytest.raises(InputError):
        read_json(3.5, "a JSON file")  # type: ignore[arg-type]
    p.write_text('{"ok": [1, 2]}')
    assert read_json(p, "a JSON file") == {"ok": [1, 2]}
