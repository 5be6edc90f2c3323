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
  included), an empty value None, anything else a string (``yes``, ``null`` and ``~``
  too, as ``cv2.FileStorage`` reads them).

YAML is parsed by PyYAML (a :class:`yaml.SafeLoader` subclass that blanks the
``%YAML:1.0`` line, constructs the two matrix tags and resolves plain scalars as OpenCV
does); XML by the standard library's ElementTree behind ``defusedxml``
(:func:`robopercept.fileio.parse_xml`: no DTD or entities); JSON by
:func:`robopercept.fileio.parse_json`. All three refuse a document nested deeper than
:data:`~robopercept.fileio.MAX_NESTING` while they parse it, and every malformed file is a
:class:`~robopercept.errors.FileFormatError` naming the file (and, for YAML, the line).
YAML anchors and aliases are refused: OpenCV never writes them, and an alias can make a
few lines stand for billions of values.

:func:`write_opencv_storage` writes the YAML form (``%YAML:1.0``, ``!!opencv-matrix``
nodes), which ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)`` and
:func:`read_opencv_storage` read back.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import yaml

from robopercept._checks import as_path, check_file, plain_repr
from robopercept.errors import FileFormatError, InputError
from robopercept.fileio import MAX_NESTING, check_nesting, nesting_error, parse_json, parse_xml

__all__ = ["read_opencv_storage", "write_opencv_storage"]

_DTYPES = {"u": np.uint8, "c": np.int8, "w": np.uint16, "s": np.int16, "i": np.int32,
           "f": np.float32, "d": np.float64, "h": np.float16}  # fmt: skip
_INT = re.compile(r"[-+]?(?:0[xX][0-9a-fA-F]+|\d+)\Z")  # C's strtol(text, &end, 0)
_BASED = re.compile(r"(?:^|\s)[-+]?0[0-9xX]")  # hex or octal among decimal numbers
_FLOAT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\Z")
_SPECIAL = {".inf": np.inf, "+.inf": np.inf, "-.inf": -np.inf, ".nan": np.nan}
_SPECIAL_TEXT = re.compile(r"([-+]?\.inf|\.nan)\Z", re.IGNORECASE)
_XML_TOKEN = re.compile(r'"([^"]*)"|(\S+)')  # XML strings have no backslash escapes


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
        nested mappings as dicts, sequences as lists, scalars as int, float or str (None
        for an empty value). A name repeated (or appended by ``FILE_STORAGE_APPEND``)
        keeps its first value, as ``cv2.FileStorage.getNode`` finds it.
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
    return _read_yaml(text, str(p))


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
    else:  # what overflows when cast (cv2 writes FLT_MAX as 3.40282347e+38, above it)
        with np.errstate(over="ignore"):
            bad = np.isfinite(data) & ~np.isfinite(data.astype(dtype))
    if bad.any():
        raise FileFormatError(
            f"{where}: matrix data {float(data[bad][0])!r} does not fit its element type "
            f"dt={node['dt']!r} ({dtype}); write the matrix with a wider dt (such as d)"
        )
    return data.reshape(shape).astype(dtype)


_MAX_CHANNELS = 512  # OpenCV's CV_CN_MAX
_MAX_DIGITS = 4300  # Python's default sys.get_int_max_str_digits()
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


# --------------------------------------------------------------------------- scalars


def _scalar(token: str, where: str) -> Any:
    """One XML token as ``cv2.FileStorage`` reads it: int (``0x1F`` hex and ``010``
    octal too), float (``1.``, ``.5``, ``4e1``, ``.Inf``, ``.Nan``), None for nothing,
    else str (``yes``, ``null`` and ``~`` included). An integer of more digits than
    Python converts (4300) is refused."""
    if not token:
        return None
    if _INT.match(token):
        return _integer(token, where)
    if _FLOAT.match(token):
        return float(token)
    return _SPECIAL.get(token.lower(), token)


def _integer(token: str, where: str) -> int:
    """An integer as ``cv2.FileStorage`` reads it (C's ``strtol`` with base 0): ``0x1F``
    is 31 and ``010`` is 8."""
    body = token.lstrip("+-")
    octal = body[:1] == "0" and len(body) > 1 and not body.strip("01234567")
    base = 16 if body[1:2] in ("x", "X") else 8 if octal else 10
    try:
        if len(body) > _MAX_DIGITS:  # Python's bound for decimal, for hex and octal too
            raise ValueError
        return int(token, base)
    except ValueError:  # over sys.get_int_max_str_digits()
        raise FileFormatError(
            f"{where}: an integer of {len(token)} digits; no value of a FileStorage "
            "file has that many (is it the right file?)"
        ) from None


# --------------------------------------------------------------------------- YAML

# a leading "%YAML:1.0" (OpenCV's spelling, which YAML readers refuse) or "%YAML 1.x"
# directive, after blank or comment lines; blanked so that line numbers stay
_DIRECTIVE = re.compile(r"\A((?:[ \t]*(?:#[^\n]*)?\r?\n)*)%YAML[: \t][^\n]*")
_YAML_TAG = "tag:yaml.org,2002:"


class _Dialect(  # type: ignore[misc]
    yaml.composer.Composer, yaml.constructor.SafeConstructor, yaml.resolver.Resolver
):
    """PyYAML's composer, constructor and resolver for OpenCV's YAML dialect, over
    either of PyYAML's parsers (:class:`_Loader`, :class:`_FastLoader`).

    - Plain scalars resolve as ``cv2.FileStorage`` reads them (:func:`_scalar`):
      integers (``0x1F`` hex, ``010`` octal, as C's ``strtol``), decimal floats and
      ``.Inf`` / ``.Nan``; an empty value is None; all else is a string (no YAML 1.1
      booleans, sexagesimal numbers or dates).
    - ``!!opencv-matrix`` and ``!!opencv-nd-matrix`` nodes become ndarrays
      (:func:`_matrix`); another tag keeps the value of its untagged node.
    - Keys are strings (the text of a scalar key).
    - Anchors and aliases are refused (an alias repeats a subtree: a few lines can
      stand for a value of billions of nodes), and so are lists and mappings nested
      deeper than :data:`~robopercept.fileio.MAX_NESTING` (plus one for a matrix's
      ``data``), as the composer meets them, before its recursion goes deep.
    """

    yaml_implicit_resolvers: ClassVar[dict[Any, Any]] = {}  # PyYAML's class registries
    yaml_constructors: ClassVar[dict[Any, Any]] = {}

    def __init__(self, name: str) -> None:
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self.name = name
        self.depth = 0

    def at(self, item: Any) -> str:
        """``"<file>: line N"`` of a node or an event."""
        return f"{self.name}: line {item.start_mark.line + 1}"

    def compose_node(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        if getattr(event, "anchor", None) is not None:
            raise FileFormatError(
                f"{self.at(event)}: anchors and aliases ('&' and '*') are not read in a "
                "FileStorage file; write the value out where it is used"
            )
        if type(event) is yaml.ScalarEvent:  # Composer.compose_scalar_node, inlined
            self.get_event()
            tag = event.tag
            if tag is None or tag == "!":
                tag = self.resolve(yaml.ScalarNode, event.value, event.implicit)
            return yaml.ScalarNode(tag, event.value, event.start_mark, event.end_mark, event.style)
        if not isinstance(event, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            return super().compose_node(parent, index)
        self.depth += 1
        try:
            if self.depth > MAX_NESTING + 1:
                raise nesting_error(self.at(event))
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1

    def entries(self, node: Any, deep: bool = False, numbers: str = "") -> dict[str, Any]:
        """The mapping ``node`` as a dict; the value of the key ``numbers``, when it is a
        list of plain numbers (a matrix's ``data``), is read at once as float64."""
        if not isinstance(node, yaml.MappingNode):
            raise FileFormatError(f"{self.at(node)}: expected a mapping (name: value)")
        out: dict[str, Any] = {}
        for key, value in node.value:
            if not isinstance(key, yaml.ScalarNode):
                raise FileFormatError(f"{self.at(key)}: a key must be a name, not a list or map")
            name = key.value
            if (
                node.flow_style
                and not key.style  # plain (None, or "" from libyaml)
                and ":" in name
                and isinstance(value, yaml.ScalarNode)
                and not value.style
                and not value.value
            ):
                name, value = self.split_entry(key)
            if name in out:
                continue  # cv2.FileNode[name] finds the first of a repeated name
            fast = _plain_numbers(value) if name == numbers else None
            out[name] = self.construct_object(value, deep=deep) if fast is None else fast
        return out

    def split_entry(self, key: Any) -> tuple[str, Any]:
        """``cv2.FileStorage`` writes a flow mapping with no blank after the colons,
        ``{ x:1, y:a b, q:"it\\'s" }``, which YAML reads as keys (``"x:1"``) without
        values: the name before the first colon and the scalar after it."""
        name, text = key.value.split(":", 1)
        if text[:1] in ("'", '"'):
            sub = _Loader(text, self.name)
            try:
                value = sub.get_single_node()
            finally:
                sub.dispose()
            if isinstance(value, yaml.ScalarNode):
                return name, value
        tag = self.resolve(yaml.ScalarNode, text, (True, False))
        return name, yaml.ScalarNode(tag, text, key.start_mark, key.end_mark)

    def make_map(self, node: Any) -> Iterator[dict[str, Any]]:
        data: dict[str, Any] = {}
        yield data  # PyYAML's two-step construction: no recursion per level
        data.update(self.entries(node))

    def make_seq(self, node: Any) -> Iterator[list[Any]]:
        data: list[Any] = []
        yield data
        data.extend(self.construct_sequence(node))

    def make_int(self, node: Any) -> int:
        text = self.construct_scalar(node)
        if not _INT.match(text):
            raise FileFormatError(f"{self.at(node)}: !!int {text!r} is not an integer")
        return _integer(text, self.at(node))

    def make_float(self, node: Any) -> float:
        text = self.construct_scalar(node)
        if text.lower() in _SPECIAL:
            return _SPECIAL[text.lower()]
        if _INT.match(text):
            value = _integer(text, self.at(node))
            try:
                return float(value)
            except OverflowError:  # as C's strtod: out of range is infinite
                return math.copysign(math.inf, value)
        if not _FLOAT.match(text):
            raise FileFormatError(f"{self.at(node)}: !!float {text!r} is not a number")
        return float(text)

    def make_null(self, node: Any) -> None:
        return None

    def make_matrix(self, node: Any, nd: bool = False) -> np.ndarray:
        mapping = isinstance(node, yaml.MappingNode)
        entries = self.entries(node, deep=True, numbers="data") if mapping else None
        return _matrix(entries, nd, self.at(node))

    def make_other(self, node: Any) -> Any:
        """Another tag (``!!opencv-sparse-matrix``, ``!!bool``, a local ``!tag``): the
        value of the untagged node."""
        if isinstance(node, yaml.SequenceNode):
            return self.make_seq(node)
        if isinstance(node, yaml.MappingNode):
            return self.make_map(node)
        tag = self.resolve(yaml.ScalarNode, node.value, (not node.style, False))
        return self.yaml_constructors[tag](self, node)


_Dialect.add_implicit_resolver(_YAML_TAG + "int", _INT, list("-+0123456789"))
_Dialect.add_implicit_resolver(_YAML_TAG + "float", _FLOAT, list("-+0123456789."))
_Dialect.add_implicit_resolver(_YAML_TAG + "float", _SPECIAL_TEXT, list("-+."))
_Dialect.add_implicit_resolver(_YAML_TAG + "null", re.compile(r"\Z"), [""])
for _tag, _make in (
    ("str", yaml.SafeLoader.construct_yaml_str),
    ("int", _Dialect.make_int),
    ("float", _Dialect.make_float),
    ("null", _Dialect.make_null),
    ("seq", _Dialect.make_seq),
    ("map", _Dialect.make_map),
    ("opencv-matrix", _Dialect.make_matrix),
    ("opencv-nd-matrix", lambda self, node: self.make_matrix(node, nd=True)),
):
    _Dialect.add_constructor(_YAML_TAG + _tag, _make)
_Dialect.add_constructor(None, _Dialect.make_other)


_NUMBER_TAGS = (_YAML_TAG + "int", _YAML_TAG + "float")


def _plain_numbers(node: Any) -> np.ndarray | None:
    """A sequence of plain decimal numbers as a float64 vector, in one pass (the bulk of
    a large matrix); None when it holds anything else (``.Inf``, a string, a list)."""
    if not isinstance(node, yaml.SequenceNode):
        return None
    items = node.value
    if not all(type(v) is yaml.ScalarNode and v.tag in _NUMBER_TAGS for v in items):
        return None
    texts = [v.value for v in items]
    if _BASED.search(" ".join(texts)):
        return None  # 0x1F, 010: read one by one (float() would take 010 for 10)
    try:
        return np.fromiter(map(float, texts), np.float64, len(texts))
    except ValueError:
        return None


class _Loader(  # type: ignore[misc]
    yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser, _Dialect
):
    """The dialect over PyYAML's pure-Python parser, where ``\\'`` in a double-quoted
    string is an apostrophe (OpenCV's writer escapes it: ``"it\\'s"``)."""

    ESCAPE_REPLACEMENTS: ClassVar[dict[str, str]] = {
        **yaml.scanner.Scanner.ESCAPE_REPLACEMENTS,
        "'": "'",
    }

    def __init__(self, text: str, name: str) -> None:
        yaml.reader.Reader.__init__(self, text)
        yaml.scanner.Scanner.__init__(self)
        yaml.parser.Parser.__init__(self)
        _Dialect.__init__(self, name)


if yaml.__with_libyaml__:
    from yaml.cyaml import CParser

    class _FastLoader(_Dialect, CParser):  # type: ignore[misc]
        """The dialect over libyaml's parser (PyYAML's C extension): the events come
        from C, several times faster on a large matrix; a file it refuses is read again
        by :class:`_Loader` (which also takes OpenCV's ``\\'`` escape)."""

        def __init__(self, text: str, name: str) -> None:
            CParser.__init__(self, text)
            _Dialect.__init__(self, name)

    _LOADERS: tuple[type[_Dialect], ...] = (_FastLoader, _Loader)
else:  # pragma: no cover (PyYAML built without libyaml)
    _LOADERS = (_Loader,)


def _read_yaml(text: str, name: str) -> dict[str, Any]:
    """The top-level mapping of a FileStorage YAML file. Several documents (what
    ``cv2.FILE_STORAGE_APPEND`` writes) merge, the first of a repeated name winning, as
    ``cv2.FileStorage.getNode`` looks names up in each document in turn."""
    text = _DIRECTIVE.sub(r"\1", text, count=1)
    for k, loader_class in enumerate(_LOADERS, 1):
        loader = None
        try:
            loader = loader_class(text, name)  # type: ignore[call-arg]
            return check_nesting(_documents(loader), name)
        except yaml.MarkedYAMLError as exc:
            if k == len(_LOADERS):
                raise FileFormatError(_yaml_message(exc, name)) from None
        except yaml.YAMLError as exc:  # a ReaderError: a character YAML does not allow
            if k == len(_LOADERS):
                what = f"{getattr(exc, 'reason', exc)} at character {getattr(exc, 'position', '?')}"
                raise FileFormatError(f"{name}: not a YAML file ({what})") from None
        except RecursionError:  # a safety net: compose_node bounds the recursion
            raise nesting_error(name) from None
        finally:
            if loader is not None:
                loader.dispose()
    raise AssertionError("unreachable")  # pragma: no cover


def _documents(loader: Any) -> dict[str, Any]:
    out: dict[str, Any] = {}
    while loader.check_node():
        node = loader.get_node()
        value = loader.construct_document(node)
        if value is None:  # an empty document
            continue
        if not isinstance(value, dict):
            raise FileFormatError(
                f"{loader.at(node)}: expected a mapping (name: value) at the top of the "
                f"file; found a {'list' if isinstance(value, list) else 'single value'}"
            )
        for key, item in value.items():
            out.setdefault(key, item)
    return out


def _yaml_message(exc: Any, name: str) -> str:
    """PyYAML's error as one line naming the file and the line: ``"cam.yml: line 3:
    mapping values are not allowed here"``."""
    mark = exc.problem_mark or exc.context_mark
    where = f"{name}: line {mark.line + 1}" if mark is not None else name
    text = f"{where}: {exc.problem or exc.context or 'not valid YAML'}"
    if exc.context and exc.problem:
        line = f" at line {exc.context_mark.line + 1}" if exc.context_mark else ""
        text += f" ({exc.context}{line})"
    if "'\\t'" in text:
        text += "; YAML indents with spaces, not tabs"
    return text


# --------------------------------------------------------------------------- XML


def _read_xml(text: str, name: str) -> dict[str, Any]:
    root = parse_xml(text, name)  # no DTD, nesting bounded while parsing
    if root.tag != "opencv_storage":
        raise FileFormatError(
            f"{name}: the XML root is <{root.tag}>; an OpenCV FileStorage file has <opencv_storage>"
        )
    return _xml_map(root, name)


def _xml_map(e: Any, name: str) -> dict[str, Any]:
    """Named children as a dict; the first of a repeated name wins, as in
    ``cv2.FileNode[name]`` (``FILE_STORAGE_APPEND`` adds names at the end)."""
    out: dict[str, Any] = {}
    for child in e:
        if child.tag not in out:
            out[child.tag] = _xml_node(child, name)
    return out


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
        return _xml_map(e, name)
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
