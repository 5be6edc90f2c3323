r"""Reading OpenCV ``FileStorage`` files (YAML and XML) without OpenCV.

``cv2.FileStorage`` writes calibration results (``camera_matrix``,
``distortion_coefficients``, ...) in a YAML dialect that plain YAML readers refuse: a
``%YAML:1.0`` directive (with a colon) and ``!!opencv-matrix`` tags on matrices, each
a mapping of ``rows``, ``cols``, ``dt`` and the row-major ``data``. Its XML form has a
root ``<opencv_storage>``, matrices as elements with ``type_id="opencv-matrix"``,
sequences as ``<_>`` children (or space-separated scalars) and strings optionally in
double quotes. :func:`read_opencv_storage` reads both, and plain YAML of the same shape
(ROS ``camera_info`` files, hand-written ones), into Python values:

- a matrix becomes an ndarray of the stored type (``dt``: ``u`` uint8, ``c`` int8, ``w``
  uint16, ``s`` int16, ``i`` int32, ``f`` float32, ``d`` float64, ``h`` float16), shape
  ``(rows, cols)``, or ``(rows, cols, n)`` for an ``n``-channel ``dt`` such as ``"2f"``
  (what ``cv2.FileStorage.getNode(name).mat()`` returns); an ``!!opencv-nd-matrix``
  takes its ``sizes``;
- mappings become dicts, sequences lists, numbers int or float (``.Inf``, ``.Nan``
  included), anything else a string.

:func:`write_opencv_storage` writes the YAML form (``%YAML:1.0``, ``!!opencv-matrix``
nodes), which ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)`` and
:func:`read_opencv_storage` read back.

The YAML reader covers what ``cv2.FileStorage`` writes and common hand-written YAML:
block mappings and sequences by indentation (``- key: value`` items included), flow
``[...]`` and ``{...}`` collections over several lines, quoted and plain scalars, ``#``
comments and the ``---`` / ``...`` document markers. Anchors, aliases and block
scalars (``|``, ``>``) are refused with :class:`~robopercept.errors.FileFormatError`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from robopercept._checks import as_path, check_file, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import MAX_NESTING, check_nesting, nesting_error, parse_json, parse_xml

__all__ = ["read_opencv_storage", "write_opencv_storage"]

_DTYPES = {"u": np.uint8, "c": np.int8, "w": np.uint16, "s": np.int16, "i": np.int32,
           "f": np.float32, "d": np.float64, "h": np.float16}  # fmt: skip
_INT = re.compile(r"[-+]?\d+\Z")
_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\Z")
_SPECIAL = {".inf": np.inf, "+.inf": np.inf, "-.inf": -np.inf, ".nan": np.nan}
_XML_TOKEN = re.compile(r'"([^"]*)"|(\S+)')  # XML strings have no backslash escapes
_NOT_IN_KEY = re.compile(r"[\[\]{},#]")  # a plain block key holds none of these
_TAG = re.compile(r"!\S*")
_FLOW_KEY = re.compile(r"[^:,}\]]*")
_FLOW_SCALAR = re.compile(r"[^,\]}]*")


def read_opencv_storage(path: str | Path) -> dict[str, Any]:
    """Read an OpenCV ``FileStorage`` file (YAML, XML or JSON) into a dict.

    Parameters
    ----------
    path : str or Path
        A ``.yml`` / ``.yaml`` / ``.xml`` / ``.json`` file, as ``cv2.FileStorage``
        writes it (or plain YAML of the same shape). The format is told by the content:
        ``<`` starts XML, ``{`` JSON, anything else is YAML.

    Returns
    -------
    dict
        Top-level names to values: matrices as ndarrays (see the module docstring),
        nested mappings as dicts, sequences as lists, scalars as int, float or str.
        ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ).getNode(name)`` gives the same
        values (``.mat()``, ``.real()``, ``.string()``).

    Raises
    ------
    InputError
        ``path`` is not a usable path (None, a number, a NUL byte, a name too long).
    FileFormatError
        Missing, a folder, unreadable, not well-formed (the message gives the line),
        nested deeper than :data:`~robopercept.fileio.MAX_NESTING` levels (mappings,
        sequences, XML elements: the one reading policy of :mod:`robopercept.fileio`),
        or a matrix whose ``data`` does not hold ``rows x cols x channels`` numbers.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> text = '''%YAML:1.0
    ... ---
    ... camera_matrix: !!opencv-matrix
    ...    rows: 3
    ...    cols: 3
    ...    dt: d
    ...    data: [ 500., 0., 320., 0., 500.,
    ...        240., 0., 0., 1. ]
    ... image_width: 640
    ... '''
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = pathlib.Path(d) / "camera.yml"
    ...     _ = p.write_text(text)
    ...     fs = read_opencv_storage(p)
    >>> fs["camera_matrix"][1]
    array([  0., 500., 240.])
    >>> fs["image_width"]
    640
    """
    p = check_file(path, "an OpenCV FileStorage file (.yml, .yaml, .xml or .json)")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{p}: not a readable OpenCV FileStorage file ({exc})") from exc
    head = text.lstrip()
    if head.startswith("<"):
        return _read_xml(text, str(p))
    if head.startswith("{"):
        data = parse_json(text, str(p))  # bounded nesting; FileFormatError if not JSON
        if not isinstance(data, dict):
            raise FileFormatError(f"{p}: expected a JSON object at the top")
        return {k: _typed(v, str(p)) for k, v in data.items()}
    node = _read_yaml(text, str(p))
    if node is None:
        return {}
    if not isinstance(node, dict):
        raise FileFormatError(f"{p}: expected a mapping (name: value) at the top of the file")
    return node


# --------------------------------------------------------------------------- matrices


def _matrix(node: Any, nd: bool, where: str) -> np.ndarray:
    """ndarray of an ``opencv-matrix`` (``rows``, ``cols``) or ``opencv-nd-matrix``
    (``sizes``) node with its ``dt`` and row-major ``data``."""
    if not isinstance(node, dict) or "data" not in node or "dt" not in node:
        raise FileFormatError(f"{where}: a matrix needs 'dt' and 'data' entries")
    m = re.fullmatch(r"\s*(\d*)\s*([ucwsifdh])\s*", str(node["dt"]))
    if m is None:
        raise FileFormatError(f"{where}: unknown matrix element type dt={node['dt']!r}")
    channels = int(m.group(1) or 1)
    if not 1 <= channels <= _MAX_CHANNELS:
        raise FileFormatError(
            f"{where}: a matrix has 1 to {_MAX_CHANNELS} channels (OpenCV's CV_CN_MAX); "
            f"dt={node['dt']!r} asks for {channels}"
        )
    try:
        if nd:
            sizes = node["sizes"]
            sizes = sizes.tolist() if isinstance(sizes, np.ndarray) else sizes
            shape = [_extent(v, "sizes", where) for v in np.atleast_1d(sizes).tolist()]
        else:
            shape = [_extent(node["rows"], "rows", where), _extent(node["cols"], "cols", where)]
        data = np.asarray(node["data"] if node["data"] is not None else [], dtype=np.float64)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise FileFormatError(f"{where}: matrix size or data not numeric ({exc})") from exc
    if channels > 1:
        shape.append(channels)
    if data.size != math.prod(shape):
        raise FileFormatError(
            f"{where}: matrix of shape {tuple(shape)} needs {math.prod(shape)} numbers "
            f"in 'data'; found {data.size}"
        )
    dtype = np.dtype(_DTYPES[m.group(2)])
    if dtype.kind in "iu":
        info = np.iinfo(dtype.name)
        bad = ~np.isfinite(data) | (data != np.round(data)) | (data < info.min) | (data > info.max)
    else:
        bad = np.isfinite(data) & (np.abs(data) > np.finfo(dtype.name).max)
    if bad.any():
        raise FileFormatError(
            f"{where}: matrix data {float(data[bad][0])!r} does not fit its element type "
            f"dt={node['dt']!r} ({dtype}); write the matrix with a wider dt (such as d)"
        )
    return data.reshape(shape).astype(dtype)


_MAX_CHANNELS = 512  # OpenCV's CV_CN_MAX
_MAX_EXTENT = 2**31 - 1  # OpenCV's Mat sizes are int


def _extent(value: Any, name: str, where: str) -> int:
    """A matrix's ``rows``, ``cols`` or ``sizes`` entry: an integer in ``[0, 2^31 - 1]``
    (OpenCV's ``int`` sizes), as an int; ``640.0`` is read as 640, ``2.5``, ``.inf``,
    booleans and strings are refused."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise FileFormatError(f"{where}: matrix {name} must be an integer; got {value!r}")
    if not (math.isfinite(value) and value == int(value) and 0 <= value <= _MAX_EXTENT):
        raise FileFormatError(
            f"{where}: matrix {name} must be an integer from 0 to {_MAX_EXTENT}; got {value!r}"
        )
    return int(value)


def _typed(node: Any, where: str) -> Any:
    """JSON FileStorage: nodes with ``type_id`` opencv-matrix become ndarrays."""
    if isinstance(node, dict):
        kind = node.get("type_id")
        if kind in ("opencv-matrix", "opencv-nd-matrix"):
            return _matrix(node, kind == "opencv-nd-matrix", where)
        return {k: _typed(v, where) for k, v in node.items()}
    if isinstance(node, list):
        return [_typed(v, where) for v in node]
    return node


def _tagged(tag: str | None, node: Any, where: str) -> Any:
    if tag == "!!opencv-matrix":
        return _matrix(node, False, where)
    if tag == "!!opencv-nd-matrix":
        return _matrix(node, True, where)
    return node  # other tags (sparse matrices, !!str, ...) keep their plain value


# --------------------------------------------------------------------------- scalars


def _scalar(token: str, where: str) -> Any:
    """int, float (``.Inf``, ``.Nan``, ``1.``), None for ``~``, ``null`` or nothing,
    else str. An integer of more digits than Python converts (4300) is refused."""
    if not token:
        return None
    if _INT.match(token):
        try:
            return int(token)
        except ValueError:  # over sys.get_int_max_str_digits()
            raise FileFormatError(
                f"{where}: an integer of {len(token)} digits; no value of a FileStorage "
                "file has that many (is it the right file?)"
            ) from None
    if _FLOAT.match(token):
        return float(token)
    low = token.lower()
    if low in _SPECIAL:
        return _SPECIAL[low]
    if low in ("~", "null"):
        return None
    return token


def _unescape(body: str) -> str:
    """Body of a double-quoted string: backslash escapes resolved."""
    out, i = [], 0
    table = {"n": "\n", "t": "\t", "r": "\r", "0": "\0", '"': '"', "\\": "\\", "/": "/"}
    while i < len(body):
        c = body[i]
        if c == "\\" and i + 1 < len(body):
            nxt = body[i + 1]
            if nxt == "x" and i + 3 < len(body):
                out.append(chr(int(body[i + 2 : i + 4], 16)))
                i += 4
                continue
            out.append(table.get(nxt, nxt))
            i += 2
            continue
        out.append(c)
        i += 1
    return "".join(out)


# --------------------------------------------------------------------------- YAML


def _strip_comment(line: str) -> str:
    """The line without a ``#`` comment (one at the start or after a blank, outside
    quotes)."""
    quote, k = "", 0
    while k < len(line):
        c = line[k]
        if quote:
            if c == "\\" and quote == '"':
                k += 1
            elif c == quote:
                quote = ""
        elif c in "\"'" and (k == 0 or line[k - 1] in " \t[{,:-"):
            quote = c
        elif c == "#" and (k == 0 or line[k - 1] in " \t"):
            return line[:k]
        k += 1
    return line


def _brackets(text: str, depth: int = 0, quote: str = "") -> tuple[int, int, str]:
    """Flow brackets ``[`` / ``{`` left open at the end of ``text`` (outside quotes),
    the deepest they nest, and the quote left open; ``depth`` and ``quote`` continue
    the scan of an earlier piece (a flow collection over several lines)."""
    deepest, k = depth, 0
    while k < len(text):
        c = text[k]
        if quote:
            if c == "\\" and quote == '"':
                k += 1
            elif c == quote:
                quote = ""
        elif c in "\"'" and (k == 0 or text[k - 1] in " \t[{,:"):
            quote = c
        elif c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
        k += 1
    return depth, deepest, quote


def _read_yaml(text: str, name: str) -> Any:
    """Parse the YAML subset of the module docstring; None for an empty document."""
    lines: list[tuple[int, int, str]] = []  # (line number, indent, content)
    for no, raw in enumerate(text.splitlines(), 1):
        s = _strip_comment(raw).rstrip()
        body = s.lstrip(" ")
        if not body or (not lines and body.startswith("%")) or body in ("---", "..."):
            continue
        if body.startswith("\t"):
            raise FileFormatError(
                f"{name}: line {no}: indented with a tab; YAML indents with spaces"
            )
        lines.append((no, len(s) - len(body), body))
    logical: list[tuple[int, int, str]] = []
    k = 0
    while k < len(lines):  # a flow collection continues until its brackets close
        no, ind, body = lines[k]
        depth, deepest, quote = _brackets(body)
        pieces = [body]
        while depth > 0 and k + 1 < len(lines) and deepest <= MAX_NESTING:
            k += 1
            piece = " " + lines[k][2]
            depth, more, quote = _brackets(piece, depth, quote)
            deepest = max(deepest, more)
            pieces.append(piece)
        if deepest > MAX_NESTING:
            raise nesting_error(f"{name}: line {no}")
        if depth != 0:
            raise FileFormatError(f"{name}: line {no}: unbalanced brackets")
        logical.append((no, ind, "".join(pieces)))
        k += 1
    if not logical:
        return None
    _check_yaml_depth(logical, name)
    try:
        node, k = _block(logical, 0, name)
    except RecursionError:  # a safety net: _check_yaml_depth bounds the recursion
        raise nesting_error(name) from None
    if k != len(logical):
        raise FileFormatError(f"{name}: line {logical[k][0]}: unexpected indentation")
    return check_nesting(node, name)


def _check_yaml_depth(lines: list[tuple[int, int, str]], name: str) -> None:
    """Refuse, before the recursive parse, a document with a line nested past
    :data:`~robopercept.fileio.MAX_NESTING` by a cheap count: the indentations open
    above it and its own, plus its leading dashes (``- - x``), plus its flow brackets.
    The count is within a factor 2 of the true depth (a sequence at its key's own
    indentation adds a level without an indentation), so it bounds the parser's
    recursion far below Python's limit; the exact depth is checked on the parsed
    value (:func:`~robopercept.fileio.check_nesting`)."""
    open_indents: list[int] = []
    for no, ind, body in lines:
        while open_indents and open_indents[-1] >= ind:
            open_indents.pop()
        open_indents.append(ind)
        dashes = 0
        rest = body
        while _is_item(rest):
            dashes += 1
            rest = rest[1:].lstrip()
        if len(open_indents) + dashes + _brackets(rest)[1] > MAX_NESTING:
            raise nesting_error(f"{name}: line {no}")


def _is_item(body: str) -> bool:
    return body == "-" or body.startswith("- ")


def _key_split(body: str) -> tuple[str, str] | None:
    """``key: rest`` -> (key, rest), None when the line is no mapping entry."""
    if body[:1] in "\"'":
        close = body.find(body[0], 1)
        if close > 0 and body[close + 1 : close + 2] == ":":
            rest = body[close + 2 :]
            if not rest or rest[0] == " ":
                key = body[1:close]
                return (_unescape(key) if body[0] == '"' else key), rest.strip()
        return None
    # the key runs to the first ':' (a key holds none) followed by a blank or the end;
    # no brackets, commas or '#' before it (a scan, not a backtracking pattern)
    colon = body.find(":")
    after = body[colon + 1 : colon + 2]
    if colon < 1 or (after and not after.isspace()) or _NOT_IN_KEY.search(body, 0, colon):
        return None
    return body[:colon].rstrip(), body[colon + 1 :].strip()


def _block(lines: list[tuple[int, int, str]], k: int, name: str) -> tuple[Any, int]:
    """The block node starting at ``lines[k]`` (a sequence or a mapping, by its first
    line) and the index after it."""
    no, ind, body = lines[k]
    if _is_item(body):
        items: list[Any] = []
        while k < len(lines) and lines[k][1] == ind and _is_item(lines[k][2]):
            no, _, body = lines[k]
            rest = body[1:].strip()
            if rest and rest[0] not in "[{" and (_is_item(rest) or _key_split(rest) is not None):
                # "- key: value" or "- - item": a block whose lines line up after the dash
                lines[k] = (no, ind + len(body) - len(rest), rest)
                value, k = _block(lines, k, name)
            else:
                value, k = _value(lines, k + 1, ind, rest, no, name)
            items.append(value)
        return items, k
    out: dict[str, Any] = {}
    while k < len(lines) and lines[k][1] == ind:
        no, _, body = lines[k]
        if _is_item(body):
            raise FileFormatError(f"{name}: line {no}: a sequence item inside a mapping")
        split = _key_split(body)
        if split is None:
            raise FileFormatError(f"{name}: line {no}: expected 'name: value'; got {body!r}")
        key, rest = split
        value, k = _value(lines, k + 1, ind, rest, no, name, same_level_seq=True)
        out[key] = value
    return out, k


def _value(
    lines: list[tuple[int, int, str]],
    k: int,
    ind: int,
    rest: str,
    no: int,
    name: str,
    *,
    same_level_seq: bool = False,
) -> tuple[Any, int]:
    """The value of an entry whose text after the key (or dash) is ``rest``: inline, or
    the indented block from ``lines[k]`` on; returns it and the index after it."""
    where = f"{name}: line {no}"
    tag = None
    if rest.startswith("!"):
        tag, _, rest = rest.partition(" ")
        rest = rest.strip()
    if rest[:1] in ("&", "*", "|", ">"):
        raise FileFormatError(f"{where}: anchors, aliases and block scalars are not supported")
    if rest:
        if rest[0] in "[{":
            value, end = _flow(rest, 0, where)
            if rest[end:].strip():
                raise FileFormatError(f"{where}: text after a closed bracket: {rest[end:]!r}")
        elif rest[0] in "\"'":
            value, end = _quoted(rest, 0, where)
            if rest[end:].strip():
                raise FileFormatError(f"{where}: text after a quoted string: {rest[end:]!r}")
        else:
            value = _scalar(rest, where)
        return _tagged(tag, value, where), k
    if k < len(lines) and (
        lines[k][1] > ind or (same_level_seq and lines[k][1] == ind and _is_item(lines[k][2]))
    ):
        value, k = _block(lines, k, name)
        return _tagged(tag, value, where), k
    return _tagged(tag, None, where), k


def _quoted(text: str, k: int, where: str) -> tuple[str, int]:
    q = text[k]
    j = k + 1
    while j < len(text):
        if q == '"' and text[j] == "\\":
            j += 2
            continue
        if text[j] == q:
            if q == "'" and text[j + 1 : j + 2] == "'":
                j += 2
                continue
            body = text[k + 1 : j]
            return (_unescape(body) if q == '"' else body.replace("''", "'")), j + 1
        j += 1
    raise FileFormatError(f"{where}: unterminated quoted string")


def _skip(text: str, k: int) -> int:
    while k < len(text) and text[k] in " \t":
        k += 1
    return k


def _flow(text: str, k: int, where: str) -> tuple[Any, int]:
    """A flow node at ``text[k]``: ``[...]``, ``{...}``, a quoted or a plain scalar
    (which ends at ``,``, ``]`` or ``}``)."""
    k = _skip(text, k)
    if k >= len(text):
        raise FileFormatError(f"{where}: a value is missing")
    c = text[k]
    if c == "!":  # tags inside a flow collection, read in a loop (no recursion per tag)
        tags = []
        while k < len(text) and text[k] == "!":
            m = _TAG.match(text, k)
            assert m is not None
            tags.append(m.group(0))
            k = _skip(text, m.end())
        value, end = _flow(text, k, where)
        for tag in reversed(tags):
            value = _tagged(tag, value, where)
        return value, end
    if c in "\"'":
        return _quoted(text, k, where)
    if c in "[{":
        close = "]" if c == "[" else "}"
        seq: list[Any] = []
        mapping: dict[str, Any] = {}
        k = _skip(text, k + 1)
        while k < len(text) and text[k] != close:
            if c == "{":
                if text[k] in "\"'":
                    key, k = _quoted(text, k, where)
                else:
                    m = _FLOW_KEY.match(text, k)
                    assert m is not None
                    key, k = m.group(0).strip(), m.end()
                k = _skip(text, k)
                if k >= len(text) or text[k] != ":":
                    raise FileFormatError(f"{where}: expected ':' after {key!r} in {{...}}")
                mapping[key], k = _flow(text, k + 1, where)
            else:
                item, k = _flow(text, k, where)
                seq.append(item)
            k = _skip(text, k)
            if k < len(text) and text[k] == ",":
                k = _skip(text, k + 1)
            elif k < len(text) and text[k] != close:
                raise FileFormatError(f"{where}: expected ',' or {close!r}; got {text[k]!r}")
        if k >= len(text):
            raise FileFormatError(f"{where}: {close!r} missing")
        return (mapping if c == "{" else seq), k + 1
    m = _FLOW_SCALAR.match(text, k)  # at k: no copy of the rest of the text
    assert m is not None
    return _scalar(m.group(0).strip(), where), m.end()


# --------------------------------------------------------------------------- XML


def _read_xml(text: str, name: str) -> dict[str, Any]:
    root = parse_xml(text, name)  # no DTD, nesting bounded while parsing
    if root.tag != "opencv_storage":
        raise FileFormatError(
            f"{name}: the XML root is <{root.tag}>; an OpenCV FileStorage file has <opencv_storage>"
        )
    return {child.tag: _xml_node(child, name) for child in root}


def _xml_node(e: Any, name: str) -> Any:
    """Value of one element: a matrix (``type_id``), a sequence (``<_>`` children or
    several scalars in the text), a mapping (named children) or one scalar."""
    kind = e.get("type_id")
    kids = list(e)
    where = f"{name}: <{e.tag}>"
    if kind in ("opencv-matrix", "opencv-nd-matrix"):
        node = {k.tag: _xml_node(k, name) for k in kids}
        data = next((k for k in kids if k.tag == "data"), None)
        if data is not None:  # always a list, even of one number
            node["data"] = [_scalar(t, where) for t in (data.text or "").split()]
        return _matrix(node, kind == "opencv-nd-matrix", where)
    if kids:
        if all(k.tag == "_" for k in kids):
            return [_xml_node(k, name) for k in kids]
        return {k.tag: _xml_node(k, name) for k in kids}
    text = e.text or ""
    tokens: list[Any] = []
    for m in _XML_TOKEN.finditer(text):
        if m.group(1) is None:
            if '"' in m.group(2):
                break
            tokens.append(_scalar(m.group(2), where))
        elif text[m.end() : m.end() + 1].strip():
            break  # a quote inside a quoted string (&quot; in the file)
        else:
            tokens.append(m.group(1))
    else:
        if not tokens:
            return None
        return tokens[0] if len(tokens) == 1 else tokens
    whole = text.strip()  # one string with quotes inside: "say &quot;hi&quot;"
    if len(whole) >= 2 and whole[0] == whole[-1] == '"':
        return whole[1:-1]
    raise FileFormatError(f"{where}: unbalanced quotes in {whole!r}")


# --------------------------------------------------------------------------- writing

_DT_OF = {np.dtype(v): k for k, v in _DTYPES.items()}
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*\Z")
_INDENT = "   "  # cv2.FileStorage indents by three spaces


def write_opencv_storage(path: str | Path, data: Mapping[str, Any]) -> Path:
    """Write ``data`` as an OpenCV ``FileStorage`` YAML file (what ``cv2.FileStorage``
    writes with ``FILE_STORAGE_WRITE``), read back by ``cv2.FileStorage`` and
    :func:`read_opencv_storage`.

    The file starts with ``%YAML:1.0`` and ``---``; then one entry per key, in order:

    - an ndarray is an ``!!opencv-matrix`` with ``rows``, ``cols``, ``dt`` and the
      row-major ``data``: a ``(rows, cols)`` array as it is, a ``(n,)`` vector as an
      ``n x 1`` column (as ``cv::Mat`` stores a ``std::vector``), ``(rows, cols, c)`` with
      ``c`` channels (``dt`` ``"3d"``...). ``dt`` follows the dtype: ``u`` uint8, ``c``
      int8, ``w`` uint16, ``s`` int16, ``i`` int32, ``f`` float32, ``d`` float64, ``h``
      float16; booleans are written as ``u``, other integers as ``i`` when they fit
      int32, else ``d`` (exact up to :math:`2^{53}`);
    - int, float (``.Inf``, ``.Nan``), bool (as 0 / 1) and str (double-quoted, with
      backslash escapes) are scalars; floats are written in their shortest exact form
      (``repr``; NumPy's for float32), so they read back bit for bit;
    - a list or tuple of scalars is a flow sequence ``[ 1, 2 ]``; a list of mappings a
      block sequence of flow mappings; a mapping a nested block mapping.

    Parameters
    ----------
    path : str or Path
        The file to write (``.yml`` or ``.yaml``; replaced if it exists).
    data : mapping of str to value
        Keys are FileStorage names: a letter or ``_``, then letters, digits, ``_`` or
        ``-``.

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    InputError
        ``data`` not a mapping, a key that is not a FileStorage name, a value of another
        type (None, an object array, an integer beyond :math:`2^{53}`), ``path`` that is
        not a usable file path or a folder.
    FileFormatError
        The file cannot be written (no such folder, no permission).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    >>> with tempfile.TemporaryDirectory() as d:
    ...     p = write_opencv_storage(pathlib.Path(d) / "cam.yml",
    ...                              {"image_width": 640, "camera_matrix": K})
    ...     text = p.read_text()
    ...     back = read_opencv_storage(p)
    >>> print(text.splitlines()[0], text.splitlines()[3])
    %YAML:1.0 camera_matrix: !!opencv-matrix
    >>> bool((back["camera_matrix"] == K).all()), back["image_width"]
    (True, 640)
    """
    if not isinstance(data, Mapping):
        raise InputError(f"data must be a mapping of names to values; got {type(data).__name__}")
    p = as_path(path, "path")
    if p.is_dir():
        raise InputError(f"path {p} is a folder; give a file name such as {p / 'camera.yml'}")
    lines = ["%YAML:1.0", "---"]
    _write_mapping(lines, data, 0, "data")
    try:
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot write ({exc.strerror or exc})") from exc
    return p


def _key(key: Any, where: str) -> str:
    if not (isinstance(key, str) and _KEY.match(key)):
        raise InputError(
            f"{where}: FileStorage names start with a letter or '_' and hold letters, "
            f"digits, '_' and '-'; got {plain_repr(key)}"
        )
    return key


def _write_mapping(lines: list[str], data: Mapping[str, Any], depth: int, where: str) -> None:
    pad = _INDENT * depth
    for key, value in data.items():
        name = _key(key, where)
        at = f"{where}[{name!r}]"
        if isinstance(value, np.ndarray) and value.ndim > 0:
            lines.append(f"{pad}{name}: !!opencv-matrix")
            _write_matrix(lines, value, depth + 1, at)
        elif isinstance(value, Mapping):
            if not value:
                lines.append(f"{pad}{name}: {{}}")
            else:
                lines.append(f"{pad}{name}:")
                _write_mapping(lines, value, depth + 1, at)
        elif (
            isinstance(value, (list, tuple))
            and value
            and all(isinstance(v, Mapping) for v in value)
        ):
            lines.append(f"{pad}{name}:")
            for i, item in enumerate(value):
                body = ", ".join(
                    f"{_key(k, f'{at}[{i}]')}: {_scalar_text(v, f'{at}[{i}][{k!r}]')}"
                    for k, v in item.items()
                )
                lines.append(f"{pad}{_INDENT}- {{ {body} }}")
        elif isinstance(value, (list, tuple)):
            items = [_scalar_text(v, f"{at}[{i}]") for i, v in enumerate(value)]
            lines.append(f"{pad}{name}: [ {', '.join(items)} ]" if items else f"{pad}{name}: []")
        else:
            lines.append(f"{pad}{name}: {_scalar_text(value, at)}")


def _scalar_text(value: Any, where: str) -> str:
    """One scalar as FileStorage YAML writes it."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (bool, np.bool_)):
        return str(int(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return _float_text(float(value))
    if isinstance(value, str):
        body = value.replace("\\", "\\\\").replace('"', '\\"')
        body = body.replace("\n", "\\n").replace("\t", "\\t").replace("\r", "\\r")
        return f'"{body}"'
    raise InputError(
        f"{where}: FileStorage holds numbers, strings, arrays, lists and mappings; got "
        f"{type(value).__name__} {plain_repr(value)[:60]}"
    )


def _float_text(v: float | np.floating) -> str:
    """The shortest text that reads back to the same value of its type (``repr`` of a
    float64, NumPy's shortest form of a float32 / float16)."""
    if math.isnan(v):
        return ".Nan"
    if math.isinf(v):
        return ".Inf" if v > 0 else "-.Inf"
    return repr(float(v)) if isinstance(v, (float, np.float64)) else str(v)


def _write_matrix(lines: list[str], value: np.ndarray, depth: int, where: str) -> None:
    a = value
    if a.dtype.kind not in "biuf":
        raise InputError(f"{where}: a matrix holds numbers; got dtype {a.dtype}")
    if a.ndim > 3:
        raise InputError(f"{where}: a matrix is (rows, cols[, channels]); got shape {a.shape}")
    if a.ndim == 1:
        a = a.reshape(-1, 1)
    channels = a.shape[2] if a.ndim == 3 else 1
    if not 1 <= channels <= _MAX_CHANNELS:
        raise InputError(f"{where}: 1 to {_MAX_CHANNELS} channels; got {channels}")
    if a.dtype.kind == "b":
        a = a.astype(np.uint8)
    if a.dtype.newbyteorder("=") in _DT_OF:
        a = a.astype(a.dtype.newbyteorder("="))
    elif a.dtype.kind in "iu":
        fits32 = a.size == 0 or (a.min() >= -(2**31) and a.max() < 2**31)
        if not fits32 and a.size and np.abs(a.astype(np.float64)).max() > 2**53:
            raise InputError(
                f"{where}: integers beyond 2^53 cannot be stored exactly (FileStorage "
                "holds int32 or float64)"
            )
        a = a.astype(np.int32 if fits32 else np.float64)
    else:  # float128 and the like
        a = a.astype(np.float64)
    dt = _DT_OF[a.dtype]
    pad = _INDENT * depth
    lines += [f"{pad}rows: {a.shape[0]}", f"{pad}cols: {a.shape[1]}"]
    lines.append(f'{pad}dt: "{channels}{dt}"' if channels > 1 else f"{pad}dt: {dt}")
    flat = a.ravel()
    if a.dtype.kind == "f":
        items = [_float_text(v) for v in flat]
    else:
        items = [str(v) for v in flat.tolist()]
    if not items:
        lines.append(f"{pad}data: []")
        return
    rows = [", ".join(items[k : k + 4]) for k in range(0, len(items), 4)]
    lines.append(f"{pad}data: [ " + f",\n{pad}    ".join(rows) + " ]")
