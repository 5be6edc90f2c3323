"""The one XML reading policy, :func:`robopercept.fileio.parse_xml` (E1-F2, E1-F4): a
DOCTYPE/ENTITY declaration is refused before parsing (no entity expansion), and a
document nested deeper than MAX_NESTING is refused while it streams, before the rest of
the tree is built; both XML readers (OpenCV FileStorage, Pascal VOC) use it."""

from __future__ import annotations

import tracemalloc

import pytest

import robopercept.fileio as fileio
from robopercept.errors import FileFormatError
from robopercept.fileio import MAX_NESTING, parse_xml
from robopercept.nn.coco.voc import read_voc_xml

BOMB = (
    '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lololololololololololol">\n'
    + "".join(
        f' <!ENTITY lol{k} "{("&lol" + (str(k - 1) if k > 1 else "") + ";") * 10}">\n'
        for k in range(1, 8)
    )
    + "]>\n<opencv_storage><a>&lol7;</a></opencv_storage>\n"
)


def test_reads_a_plain_document() -> None:
    root = parse_xml(b"<a><b>1</b><b>2</b></a>", "a.xml")
    assert root.tag == "a" and [b.text for b in root] == ["1", "2"]


def test_exactly_the_limit_is_read_one_more_is_refused() -> None:
    """As the document's value nests: the root and MAX_NESTING elements below it."""
    ok = "<a>" * (MAX_NESTING + 1) + "</a>" * (MAX_NESTING + 1)
    assert parse_xml(ok, "ok.xml").tag == "a"
    deep = "<a>" * (MAX_NESTING + 2) + "</a>" * (MAX_NESTING + 2)
    with pytest.raises(FileFormatError, match=r"deep\.xml: nested more than 64 levels"):
        parse_xml(deep, "deep.xml")


def test_a_deep_document_stops_before_its_tree_is_built() -> None:
    """200,000 open elements: refused at level 65, with a small peak (the whole tree
    would be tens of MiB of Element objects)."""
    text = ("<a>" * 200_000).encode()
    tracemalloc.start()
    try:
        with pytest.raises(FileFormatError, match="nested more than"):
            parse_xml(text, "deep.xml")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20


@pytest.mark.parametrize(
    "text",
    [
        BOMB,
        BOMB.encode(),
        BOMB.replace('version="1.0"', 'version="1.0" encoding="utf-16"').encode("utf-16"),
        "<!DOCTYPE a SYSTEM 'http://example.com/a.dtd'><a/>",
    ],
    ids=["str", "utf-8", "utf-16", "external"],
)
def test_a_dtd_is_refused_before_parsing(text: str | bytes) -> None:
    with pytest.raises(FileFormatError, match=r"bomb\.xml: has a DOCTYPE/ENTITY declaration"):
        parse_xml(text, "bomb.xml")


def test_the_parser_refuses_a_dtd_the_byte_search_missed(monkeypatch) -> None:
    monkeypatch.setattr(fileio, "_DTD_MARKS", ())
    with pytest.raises(FileFormatError, match="DOCTYPE/ENTITY"):
        parse_xml(BOMB.encode(), "bomb.xml")


@pytest.mark.parametrize("text", [b"<a", b"", b"<a></b>", "<a>\x00</a>", 5])
def test_not_xml_is_a_file_format_error(text) -> None:
    with pytest.raises(FileFormatError, match=r"x\.xml"):
        parse_xml(text, "x.xml")


def test_voc_xml_refuses_deep_nesting(tmp_path) -> None:
    """E1-F4: read_voc_xml had no depth check (a 100,000-deep file was built whole)."""
    p = tmp_path / "deep.xml"
    p.write_text("<annotation>" + "<a>" * 100_000 + "</a>" * 100_000 + "</annotation>")
    with pytest.raises(FileFormatError, match="nested more than 64 levels"):
        read_voc_xml(p)
    p.write_text(BOMB.replace("opencv_storage", "annotation"))
    with pytest.raises(FileFormatError, match="DOCTYPE/ENTITY"):
        read_voc_xml(p)
