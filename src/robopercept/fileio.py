"""Reading and writing files safely: bounded structured text in, atomic files out,
with errors that name the file.

:func:`atomic_write` and :func:`atomic_path` write a file as a temporary file in the
same folder, flushed to the disk (``fsync``), then renamed over the target with
:func:`os.replace`, which POSIX and Windows make atomic within one file system: a
reader (or a run interrupted by a signal, a full disk or a crash) sees the old file or
the complete new one, never a truncated one. On an error the temporary file is removed
and :class:`WriteError` names the target file and what happened (``no space left on the
device`` for ``ENOSPC``/``EDQUOT``).

This is the one atomic writer of the package (checkpoints of ``nn.train.loop``, the
outputs of ``pipelines.plane_outputs``).

Reading, :func:`parse_json` / :func:`read_json`, :func:`parse_xml` and
:func:`check_nesting` are the one
policy for structured text (JSON, the OpenCV FileStorage YAML and XML, manifests,
annotation files): a document nested deeper than :data:`MAX_NESTING` levels, or one that
exhausts the parser's recursion, numbers with more digits than Python converts, invalid
UTF-8 or invalid JSON all give :class:`~robopercept.errors.FileFormatError` naming the
file, never ``RecursionError`` or ``ValueError`` from deep inside a reader. Real files
nest a handful of levels (a COCO file 4, a calibration file 3); 64 leaves room for any
hand-written configuration while every recursive walk of the value stays far from
Python's recursion limit. XML is parsed streaming and refused as soon as an element opens
deeper than the limit (before the rest of the tree is built), and a DOCTYPE or ENTITY
declaration is refused before parsing: no real file of these formats has one, and
entity expansion ("billion laughs") turns a few kilobytes into gigabytes.
"""

from __future__ import annotations

import errno
import json
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from robopercept._checks import check_file
from robopercept.errors import FileFormatError, RoboperceptError

if TYPE_CHECKING:
    import xml.etree.ElementTree as ET

__all__ = [
    "DISK_FULL_ERRNOS",
    "MAX_NESTING",
    "WriteError",
    "atomic_path",
    "atomic_write",
    "check_nesting",
    "describe_write_error",
    "nesting_depth",
    "nesting_error",
    "parse_json",
    "parse_xml",
    "read_json",
    "read_text",
    "strict_json",
    "write_error",
]

DISK_FULL_ERRNOS = frozenset(
    e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None), errno.EFBIG) if e is not None
)
"""``errno`` values that mean the disk (or the user's quota) is full."""


class WriteError(RoboperceptError, OSError):
    """An output file could not be written (a full disk, an I/O error, a read-only or
    vanished folder). The message starts with the file's path; ``errno`` and
    ``filename`` are those of the underlying :class:`OSError`.

    Parameters
    ----------
    message : str
        One line starting with the file's path (:func:`describe_write_error`).
    code : int, optional
        The ``errno`` of the underlying error.
    filename : str, optional
        The file being written.
    """

    def __init__(self, message: str, code: int | None = None, filename: str | None = None):
        super().__init__(message)
        self.errno = code
        self.filename = filename

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def _errno(exc: BaseException | None) -> int | None:
    """The first ``errno`` in ``exc`` and its causes (a writer may wrap the OSError)."""
    seen = 0
    while exc is not None and seen < 16:
        code = getattr(exc, "errno", None)
        if code is not None:
            return int(code)
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return None


def describe_write_error(path: str | os.PathLike[str], exc: BaseException) -> str:
    """One line naming ``path`` and what went wrong writing it.

    Parameters
    ----------
    path : str or path-like
        The file being written.
    exc : BaseException
        The error (an :class:`OSError` gives its ``errno``/``strerror``).

    Returns
    -------
    str
        ``"<path>: no space left on the device"`` for ``ENOSPC``, ``EDQUOT`` and
        ``EFBIG``; ``"<path>: <strerror>"`` for another :class:`OSError`;
        ``"<path>: <first line of exc>"`` otherwise.

    Examples
    --------
    >>> describe_write_error("out/summary.json", OSError(28, "No space left on device"))
    'out/summary.json: no space left on the device'
    """
    code = _errno(exc)
    if code in DISK_FULL_ERRNOS:
        what = "no space left on the device"
    elif isinstance(exc, OSError) and exc.strerror:
        what = exc.strerror
    else:
        lines = str(exc).strip().splitlines()
        what = lines[0] if lines else type(exc).__name__
    return f"{os.fspath(path)}: {what}"


def write_error(path: str | os.PathLike[str], exc: OSError) -> WriteError:
    """A :class:`WriteError` for ``exc`` raised while writing ``path`` (message from
    :func:`describe_write_error`, same ``errno``)."""
    return WriteError(describe_write_error(path, exc), _errno(exc), os.fspath(path))


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Give a temporary path beside ``path`` to write; on success rename it over
    ``path`` atomically.

    The temporary file is ``.<name>.<pid>.tmp<suffix>`` in the same folder (same file
    system, so the rename is atomic; the target's suffix is kept for writers that choose
    the format from it). When the block raises, the temporary file is removed and
    ``path`` is left as it was.

    Parameters
    ----------
    path : str or path-like
        The file to write; its folder is created if needed.

    Yields
    ------
    Path
        Where to write the content.

    Raises
    ------
    WriteError
        An :class:`OSError` while writing, flushing or renaming (the message names
        ``path``: ``no space left on the device`` for a full disk).

    Examples
    --------
    >>> with atomic_path("out/model.pt") as tmp:  # doctest: +SKIP
    ...     torch.save(state, tmp)
    """
    p = Path(path)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp{p.suffix}")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, p)
    except BaseException as exc:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        if isinstance(exc, OSError) and not isinstance(exc, WriteError):
            raise write_error(p, exc) from exc
        raise


def atomic_write(path: str | os.PathLike[str], data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`).

    Parameters
    ----------
    path : str or path-like
    data : bytes or str
        ``str`` is written as UTF-8.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    WriteError
        The file could not be written; ``path`` is left as it was.

    Examples
    --------
    >>> atomic_write("summary.json", '{"frames": 3}')  # doctest: +SKIP
    PosixPath('summary.json')
    """
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    p = Path(path)
    with atomic_path(p) as tmp, open(tmp, "wb") as fh:
        fh.write(raw)
    return p


def strict_json(value: Any) -> Any:
    """``value`` made strict JSON: NaN and infinities become None (``null``), in nested
    dicts, lists and tuples too (tuples become lists, keys strings).

    ``json.dumps`` writes ``NaN``, which ``jq``, JavaScript and most JSON parsers refuse;
    a figure that cannot be computed is ``null`` in robopercept's JSON
    (docs/cli_json.md).

    Parameters
    ----------
    value : any JSON-able value

    Returns
    -------
    any
        The same structure with every non-finite float replaced by None.

    Examples
    --------
    >>> strict_json({"a": float("nan"), "b": [1.0, float("inf")], "c": (2,)})
    {'a': None, 'b': [1.0, None], 'c': [2]}
    """
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [strict_json(v) for v in value]
    return value


# --------------------------------------------------------------------------- reading

MAX_NESTING = 64
"""The deepest nesting of lists and mappings (or XML elements) a structured file may
have (see the module docstring)."""


def nesting_depth(value: Any, limit: int = MAX_NESTING) -> int:
    """The nesting depth of ``value`` (0 for a scalar, 1 for a flat list or dict, ...),
    counted without recursion; the count stops at ``limit + 1``.

    Examples
    --------
    >>> nesting_depth({"a": [1, [2]]})
    3
    """
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            children: Any = node.values()
        elif isinstance(node, list | tuple):
            children = node
        else:
            continue
        depth += 1
        if depth > deepest:
            deepest = depth
            if deepest > limit:
                return deepest
        stack.extend((c, depth) for c in children)
    return deepest


def check_nesting(value: Any, where: str, limit: int = MAX_NESTING) -> Any:
    """Return ``value`` (a parsed JSON or YAML document) after checking that its lists
    and mappings nest at most ``limit`` levels.

    Parameters
    ----------
    value : any
    where : str
        The file (or entry) it came from, for the message.
    limit : int, default MAX_NESTING

    Raises
    ------
    FileFormatError
        ``"<where>: nested more than <limit> levels deep ..."``.

    Examples
    --------
    >>> check_nesting([[[1]]], "a.json", limit=2)
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: a.json: nested more than 2 levels deep; no file \
this reader knows nests that deep (is it the right file?)
    """
    if nesting_depth(value, limit) > limit:
        raise nesting_error(where, limit)
    return value


def nesting_error(where: str, limit: int = MAX_NESTING) -> FileFormatError:
    """The :class:`FileFormatError` of a document nested too deep (for parsers that
    detect it themselves, such as an XML tree walk)."""
    return FileFormatError(
        f"{where}: nested more than {limit} levels deep; no file this reader knows nests "
        "that deep (is it the right file?)"
    )


def parse_json(text: str | bytes, where: str, limit: int = MAX_NESTING) -> Any:
    """The JSON value of ``text`` under the reading policy of the module docstring.

    Parameters
    ----------
    text : str or bytes
        JSON text (bytes are decoded as UTF-8, a byte-order mark allowed).
    where : str
        The file it came from, for messages.
    limit : int, default MAX_NESTING
        The deepest nesting allowed.

    Returns
    -------
    any
        ``json.loads(text)``; ``NaN`` and ``Infinity`` are read as Python reads them.

    Raises
    ------
    FileFormatError
        Not UTF-8, not JSON, a number Python refuses to convert (over 4300 digits), or
        nested deeper than ``limit``.

    Examples
    --------
    >>> parse_json('{"a": [1, 2]}', "a.json")
    {'a': [1, 2]}
    >>> parse_json("[" * 100000, "deep.json")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: deep.json: nested more than 64 levels deep; no \
file this reader knows nests that deep (is it the right file?)
    """
    if isinstance(text, bytes | bytearray):
        try:
            text = bytes(text).decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            raise FileFormatError(f"{where}: not UTF-8 text ({exc})") from None
    if not isinstance(text, str):
        raise FileFormatError(f"{where}: expected JSON text; got {type(text).__name__}")
    if _opens_deeper(text, limit):
        raise nesting_error(where, limit)
    try:
        value = json.loads(text)
    except RecursionError:
        raise nesting_error(where, limit) from None
    except ValueError as exc:  # JSONDecodeError, or an integer of over 4300 digits
        raise FileFormatError(f"{where}: not valid JSON ({exc})") from None
    return check_nesting(value, where, limit)


def _opens_deeper(text: str, limit: int) -> bool:
    """Whether ``text`` opens more than ``limit`` brackets in a row at its start (the
    usual shape of a nesting attack), checked before the parser recurses."""
    head = text[: 2 * limit + 2].lstrip()
    run = len(head) - len(head.lstrip("[{ \t\r\n"))
    return sum(c in "[{" for c in head[:run]) > limit


def read_json(path: str | os.PathLike[str], what: str, limit: int = MAX_NESTING) -> Any:
    """The JSON value of the file ``path`` under the reading policy of the module
    docstring.

    Parameters
    ----------
    path : path-like
    what : str
        What the caller reads, with its article (``"a COCO annotation file"``), for
        the message of a folder.
    limit : int, default MAX_NESTING

    Raises
    ------
    InputError
        Not a usable path.
    FileFormatError
        Missing, a folder, unreadable, not UTF-8 JSON, or nested deeper than ``limit``.
    """
    p = check_file(path, what)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    return parse_json(raw, str(p), limit)


_DTD_MARKS = tuple(
    mark.encode(enc)
    for mark in ("<!DOCTYPE", "<!ENTITY")
    for enc in ("utf-8", "utf-16-le", "utf-16-be")
)
_XML_CHUNK = 1 << 16


def _dtd_error(where: str) -> FileFormatError:
    return FileFormatError(
        f"{where}: has a DOCTYPE/ENTITY declaration; the files this reader knows have "
        "none and they are refused (entity expansion); remove the declaration"
    )


def parse_xml(text: str | bytes, where: str, limit: int = MAX_NESTING) -> ET.Element:
    """The root element of the XML document ``text`` under the reading policy of the
    module docstring.

    The document is parsed streaming, in chunks, by ``defusedxml``'s
    :class:`~defusedxml.ElementTree.DefusedXMLParser` (the standard library's
    :class:`xml.etree.ElementTree.XMLParser` over expat, with DTDs, entity declarations
    and external references forbidden) and a tree builder that counts the open
    elements: parsing stops at the first element more than ``limit`` levels below the
    root, before the rest of the tree is built. This counts as :func:`check_nesting`
    counts the document's value: the root is the document, an element with children one
    level of lists or mappings, a leaf a scalar. A DOCTYPE or ENTITY declaration is
    refused before parsing (a raw byte search, in UTF-8 and UTF-16) and again by
    ``defusedxml`` should the search miss one (another encoding).

    Parameters
    ----------
    text : str or bytes
        XML text; bytes are decoded as the XML declaration says (UTF-8 by default).
    where : str
        The file it came from, for messages.
    limit : int, default MAX_NESTING
        The deepest element nesting allowed below the root.

    Returns
    -------
    xml.etree.ElementTree.Element

    Raises
    ------
    FileFormatError
        A DOCTYPE/ENTITY declaration, not well-formed XML, or nested deeper than
        ``limit``.

    Examples
    --------
    >>> parse_xml("<a><b>1</b></a>", "a.xml")[0].text
    '1'
    >>> parse_xml("<a>" * 100, "deep.xml")
    Traceback (most recent call last):
    ...
    robopercept.errors.FileFormatError: deep.xml: nested more than 64 levels deep; no \
file this reader knows nests that deep (is it the right file?)
    """
    import xml.etree.ElementTree as ET

    import defusedxml
    from defusedxml.ElementTree import DefusedXMLParser

    if isinstance(text, str):
        if "<!DOCTYPE" in text or "<!ENTITY" in text:
            raise _dtd_error(where)
    elif isinstance(text, bytes | bytearray):
        if any(mark in text for mark in _DTD_MARKS):
            raise _dtd_error(where)
    else:
        raise FileFormatError(f"{where}: expected XML text; got {type(text).__name__}")

    class _Refused(Exception):
        pass

    class _Builder(ET.TreeBuilder):
        depth = 0
        refused: FileFormatError | None = None

        def start(self, tag: Any, attrs: Any) -> ET.Element:
            self.depth += 1
            if self.depth > limit + 1:  # the root is the document, at level 0
                self.refused = nesting_error(where, limit)
                raise _Refused
            return super().start(tag, attrs)

        def end(self, tag: Any) -> ET.Element:
            self.depth -= 1
            return super().end(tag)

    builder = _Builder()
    parser = DefusedXMLParser(target=builder, forbid_dtd=True)
    try:
        for k in range(0, len(text), _XML_CHUNK):
            parser.feed(text[k : k + _XML_CHUNK])
        root = parser.close()
    except _Refused:
        assert builder.refused is not None
        raise builder.refused from None
    except defusedxml.DefusedXmlException:  # a DTD, an entity, an external reference
        raise _dtd_error(where) from None
    except ET.ParseError as exc:
        raise FileFormatError(f"{where}: not well-formed XML ({exc})") from None
    except (RecursionError, MemoryError, ValueError) as exc:
        raise FileFormatError(f"{where}: not a readable XML document ({exc})") from None
    if builder.refused is not None:  # an exception the parser swallowed
        raise builder.refused
    return root


def read_text(path: str | os.PathLike[str], expected: str) -> str:
    """The UTF-8 text of the file ``path`` (a byte-order mark allowed), for readers of
    line-based lists (association lists, class-name files).

    Parameters
    ----------
    path : path-like
    expected : str
        What the file should hold, ending the message of a bad file
        (``"expected 'timestamp file' lines"``).

    Raises
    ------
    FileFormatError
        ``"<path>: not UTF-8 text (byte N): <expected>"``, or ``cannot read`` with the
        system's reason.
    """
    p = Path(path)
    try:
        return p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{p}: not UTF-8 text (byte {exc.start}): {expected}") from None
    except OSError as exc:
        raise FileFormatError(f"{p}: cannot read ({exc.strerror or exc})") from None
