"""OpenCV FileStorage read with PyYAML and defusedxml (issue 48, item 9): files that
cv2.FileStorage writes, YAML and XML, read equal to what cv2.FileStorage reads back;
both YAML parsers (libyaml's events and PyYAML's pure-Python scanner) give the same
values; the YAML features OpenCV never writes (anchors, aliases, custom tags, complex
keys) give a FileFormatError or their plain value, never another error."""

from __future__ import annotations

import time

import numpy as np
import pytest

import robopercept.calibration.filestorage as filestorage
from robopercept.calibration import read_opencv_storage
from robopercept.errors import FileFormatError
from tests.calibration.test_filestorage import _assert_same, _cv2_read

cv2 = pytest.importorskip("cv2")

LOADERS = {"libyaml": filestorage._LOADERS, "python": (filestorage._Loader,)}

STRINGS = {  # cv2 writes some quoted, some plain: "null", "yes" and "~" stay strings
    "s_quotes": 'say "hi" & <go>',
    "s_apostrophe": "it's #1",
    "s_backslash": "C:\\new\\dir",
    "s_colon": "a: b",
    "s_newline": "a\nb\tc",
    "s_unicode": "héllo wörld",
    "s_yes": "yes",
    "s_true": "true",
    "s_null": "null",
    "s_tilde": "~",
    "s_hex": "0x1F",
    "s_octal": "010",
    "s_date": "2020-01-01",
    "s_dots": "...",
    "s_dash": "- x",
    "s_lead": " x",
    "s_empty": "",
}
NUMBERS = {
    "n_zero": 0,
    "n_min32": -(2**31),
    "n_max32": 2**31 - 1,
    "n_big": 2**40,  # cv2 writes and reads it as an integer beyond int32
    "x_tenth": 0.1,
    "x_huge": 1e300,
    "x_subnormal": 5e-324,
    "x_negzero": -0.0,
    "x_inf": float("inf"),
    "x_ninf": float("-inf"),
    "x_nan": float("nan"),
}


def _write_everything(path) -> None:
    """One file with what cv2.FileStorage writes: matrices of every dt (empty, 1 x 1,
    channels, a column, an n-d matrix), nested maps, sequences of numbers, strings,
    maps and sequences, a flow map and a flow sequence, strings and numbers."""
    rng = np.random.default_rng(48)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for dt in (np.uint8, np.int8, np.uint16, np.int16, np.int32, np.float32, np.float64):
        info = np.iinfo(dt) if np.dtype(dt).kind in "iu" else np.finfo(dt)
        m = np.array([[info.min, 0, 1], [info.max, -1 if info.min < 0 else 2, 7]], dtype=dt)
        fs.write(f"m_{np.dtype(dt).name}", m)
        fs.write(f"one_{np.dtype(dt).name}", np.array([[5]], dtype=dt))
    fs.write("m_float16", np.array([[0.5, -2.0, 65504.0]], dtype=np.float16))
    fs.write("m_random", rng.standard_normal((4, 5)))  # 17 significant digits each
    fs.write("empty", np.zeros((0, 0)))
    fs.write("column", np.arange(3.0))
    fs.write("rgb", rng.integers(0, 256, (2, 3, 3), dtype=np.uint8))
    fs.write("corners", rng.random((3, 2, 2)).astype(np.float32))
    fs.write("nd", np.arange(24, dtype=np.float32).reshape(2, 3, 4, 1))
    for key, value in {**STRINGS, **NUMBERS}.items():
        fs.write(key, value)
    fs.startWriteStruct("nested", cv2.FileNode_MAP)
    fs.write("a", 1)
    fs.startWriteStruct("inner", cv2.FileNode_MAP)
    fs.write("K", np.eye(3))
    fs.write("name", "cam 0")
    fs.startWriteStruct("deepest", cv2.FileNode_MAP)
    fs.write("v", 2.5)
    fs.endWriteStruct()
    fs.endWriteStruct()
    fs.endWriteStruct()
    fs.startWriteStruct("numbers", cv2.FileNode_SEQ)
    for v in (1, -2, 2.5, 1e-7):
        fs.write("", v)
    fs.endWriteStruct()
    fs.startWriteStruct("words", cv2.FileNode_SEQ)
    for v in ("one", "two words", "null", "3"):
        fs.write("", v)
    fs.endWriteStruct()
    fs.startWriteStruct("views", cv2.FileNode_SEQ)
    for k in range(2):
        fs.startWriteStruct("", cv2.FileNode_MAP)
        fs.write("id", k)
        fs.write("T", np.eye(2) * k)
        fs.endWriteStruct()
    fs.endWriteStruct()
    fs.startWriteStruct("seq_of_seq", cv2.FileNode_SEQ)
    fs.startWriteStruct("", cv2.FileNode_SEQ)
    fs.write("", 1)
    fs.write("", "a b")
    fs.endWriteStruct()
    fs.startWriteStruct("", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
    fs.write("", 2.5)
    fs.endWriteStruct()
    fs.endWriteStruct()
    # a flow map: cv2 writes "{ x:1, y:two words, q:"it\'s" }", no blank after a colon
    fs.startWriteStruct("flow", cv2.FileNode_MAP | cv2.FileNode_FLOW)
    fs.write("x", 1)
    fs.write("y", "two words")
    fs.write("q", "it's")
    fs.write("f", 2.5)
    fs.write("e", "")
    fs.startWriteStruct("s", cv2.FileNode_SEQ | cv2.FileNode_FLOW)
    fs.write("", 1)
    fs.write("", "w")
    fs.endWriteStruct()
    fs.startWriteStruct("m", cv2.FileNode_MAP | cv2.FileNode_FLOW)
    fs.write("a", 1)
    fs.endWriteStruct()
    fs.endWriteStruct()
    fs.startWriteStruct("empty_seq", cv2.FileNode_SEQ)
    fs.endWriteStruct()
    fs.startWriteStruct("empty_map", cv2.FileNode_MAP)
    fs.endWriteStruct()
    fs.release()


@pytest.mark.parametrize("loaders", sorted(LOADERS))
@pytest.mark.parametrize("ext", ["yml", "xml"])
def test_cv2_written_files_read_as_cv2_reads_them(tmp_path, monkeypatch, ext, loaders):
    """Exact equality with cv2.FileStorage's reading (types, dtypes, shapes, values; NaN
    equal to NaN): cv2 writes floats with 17 significant digits, so no tolerance."""
    monkeypatch.setattr(filestorage, "_LOADERS", LOADERS[loaders])
    path = tmp_path / f"all.{ext}"
    _write_everything(path)
    ours = read_opencv_storage(path)
    _assert_same(ours, _cv2_read(cv2, path))
    # and the values themselves, where a wrong reading could agree with nothing
    for key, value in STRINGS.items():
        assert ours[key] == value, key
    for key, value in NUMBERS.items():
        assert type(ours[key]) is type(value), key
        assert ours[key] == value or (np.isnan(value) and np.isnan(ours[key])), key
    assert ours["m_uint16"].dtype == np.uint16 and ours["m_uint16"][1, 0] == 65535
    assert ours["one_int8"].shape == (1, 1) and ours["one_int8"].dtype == np.int8
    assert ours["empty"].shape == (0, 0) and ours["nd"].shape == (2, 3, 4, 1)
    assert ours["rgb"].shape == (2, 3, 3) and ours["column"].shape == (3, 1)
    assert ours["nested"]["inner"]["deepest"] == {"v": 2.5}
    assert ours["words"] == ["one", "two words", "null", "3"]
    if ext == "yml":
        assert ours["flow"] == {
            "x": 1, "y": "two words", "q": "it's", "f": 2.5, "e": "", "s": [1, "w"],
            "m": {"a": 1},
        }  # fmt: skip


@pytest.mark.parametrize("ext", ["yml", "xml"])
def test_appended_documents_read_as_cv2_looks_names_up(tmp_path, ext):
    """FILE_STORAGE_APPEND adds a YAML document; cv2's getNode looks a name up in each
    document in turn, so the first of a repeated name wins."""
    path = tmp_path / f"a.{ext}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("a", 1)
    fs.write("K", np.eye(3))
    fs.release()
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_APPEND)
    fs.write("b", "two")
    fs.write("a", 3)
    fs.release()
    ours = read_opencv_storage(path)
    ref = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert ours["a"] == int(ref.getNode("a").real()) and ours["b"] == ref.getNode("b").string()
    assert np.array_equal(ours["K"], ref.getNode("K").mat()) and set(ours) == {"a", "b", "K"}


@pytest.mark.parametrize("loaders", sorted(LOADERS))
def test_hand_written_numbers_read_as_cv2_reads_them(tmp_path, monkeypatch, loaders):
    """cv2 reads integers with C's strtol(text, &end, 0): hex and octal; in a matrix's
    data too (read at once as float64 when all are decimal)."""
    monkeypatch.setattr(filestorage, "_LOADERS", LOADERS[loaders])
    path = tmp_path / "n.yml"
    path.write_text(
        "%YAML:1.0\n---\na: -0x10\nb: 0X1f\nc: 010\nd: -010\ne: 0\nf: 4e1\ng: 1.\nh: .5\n"
        "i: +5\nj: -.Inf\nk: .Nan\nm: !!opencv-matrix\n   rows: 1\n   cols: 3\n   dt: i\n"
        "   data: [ 010, 0x10, 10 ]\nn: !!opencv-matrix\n   rows: 1\n   cols: 2\n   dt: d\n"
        "   data: [ 4e1, -.Inf ]\n"
    )
    ours = read_opencv_storage(path)
    _assert_same(ours, _cv2_read(cv2, path))
    assert [ours[k] for k in "abcde"] == [-16, 31, 8, -8, 0]
    assert ours["m"].tolist() == [[8, 16, 10]] and ours["n"].tolist() == [[40.0, -np.inf]]


def _read(tmp_path, text: str, name: str = "h.yml"):
    path = tmp_path / name
    path.write_text(text)
    return read_opencv_storage(path)


@pytest.mark.parametrize("loaders", sorted(LOADERS))
@pytest.mark.parametrize(
    ("text", "match"),
    [
        # an alias bomb: 9 lines that stand for 10^9 values
        ("a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
         + "".join(f"{c}: &{c} [{', '.join(['*' + p] * 10)}]\n"
                   for p, c in zip("abcdefgh", "bcdefghi", strict=True)),
         r"h\.yml: line 1: anchors and aliases"),
        ("a: &x [*x]\n", "anchors and aliases"),
        ("a: 1\nb: *a\n", r"line 2: anchors and aliases"),
        ("a: !!int abc\n", r"line 1: !!int 'abc' is not an integer"),
        ("a: !!float x\n", "is not a number"),
        ("? [a, b]\n: 1\n", r"line 1: a key must be a name"),
        ("a: 1\x07\n", "not a YAML file"),
        ("- 1\n- 2\n", "expected a mapping .* found a list"),
        ("just text\n", "found a single value"),
        ("a: !!str [1]\n", "line 1"),
        ("a: !!opencv-matrix 5\n", "a matrix needs 'dt' and 'data'"),
        ("a: !!opencv-matrix\n  rows: 1\n  cols: 1\n  dt: d\n  data: [x]\n", "not numeric"),
        ("a: 0x" + "f" * 5000 + "\n", "an integer of 5002 digits"),
        ("%YAML:1.0\na: {b: 1\n", r"expected ',' or '}'"),
    ],
    ids=["alias-bomb", "recursive-alias", "undefined-alias", "int", "float", "complex-key",
         "control-char", "list", "scalar", "str-of-list", "matrix-scalar", "matrix-data",
         "hex-digits", "flow-map"],
)  # fmt: skip
def test_hostile_yaml_is_a_file_format_error(tmp_path, monkeypatch, loaders, text, match):
    monkeypatch.setattr(filestorage, "_LOADERS", LOADERS[loaders])
    start = time.perf_counter()
    with pytest.raises(FileFormatError, match=match):
        _read(tmp_path, text)
    assert time.perf_counter() - start < 5  # the bomb is refused, not expanded


@pytest.mark.parametrize("loaders", sorted(LOADERS))
def test_other_tags_keep_their_plain_value(tmp_path, monkeypatch, loaders):
    """Tags OpenCV does not write read as the untagged value: no Python objects (the
    loader is PyYAML's safe one), no dates, no booleans, no bytes."""
    monkeypatch.setattr(filestorage, "_LOADERS", LOADERS[loaders])
    out = _read(
        tmp_path,
        "a: !!python/object/apply:os.system [echo hi]\nb: !!timestamp 2020-01-01\n"
        "c: !!bool yes\nd: !custom {x: 1}\ne: !!str 5\nf: !!float 0x10\ng: !!null abc\n"
        "h: !!binary aGk=\ni: !!opencv-sparse-matrix\n  sizes: [2]\n",
    )
    assert out == {
        "a": ["echo hi"], "b": "2020-01-01", "c": "yes", "d": {"x": 1}, "e": "5",
        "f": 16.0, "g": None, "h": "aGk=", "i": {"sizes": [2]},
    }  # fmt: skip


def test_a_large_matrix_is_read_at_once(tmp_path):
    """A 200 x 300 float64 matrix (60,000 numbers) reads equal to cv2 (its data taken
    as one float64 vector, not 60,000 Python objects)."""
    m = np.random.default_rng(1).standard_normal((200, 300))
    path = tmp_path / "big.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("m", m)
    fs.release()
    assert np.array_equal(read_opencv_storage(path)["m"], m)
