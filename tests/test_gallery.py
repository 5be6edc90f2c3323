"""docs/gallery.md and its table (docs/make_gallery.py) agree with the command line.

Fast (no command is run): every entry parses as a ``robopercept`` command line, every
top-level command (and every task of ``learn`` and ``nn``) has a picture or a stated
reason, the page is the one the table writes, and every picture it shows is in
docs/img/gallery, at most 1280 pixels wide, within the size budget.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest

from robopercept.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "gallery.md"
GALLERY = ROOT / "docs" / "img" / "gallery"


@pytest.fixture(scope="module")
def gallery() -> ModuleType:
    """docs/make_gallery.py, imported by path (docs/ is not a package)."""
    spec = importlib.util.spec_from_file_location("make_gallery", ROOT / "docs" / "make_gallery.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_gallery"] = module  # dataclasses look their module up
    try:
        spec.loader.exec_module(module)
    finally:
        del sys.modules["make_gallery"]
    return module


def _tasks(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices) if actions else {}


def test_every_entry_is_a_command_line_the_parser_takes(gallery: ModuleType) -> None:
    parser = build_parser()
    commands = _tasks(parser)
    names = [e.name for e in gallery.ENTRIES]
    assert len(names) == len(set(names)), "two entries with one name (one picture)"
    for entry in gallery.ENTRIES:
        assert entry.command in commands, f"{entry.name}: no command {entry.command!r}"
        args = parser.parse_args(entry.args)  # a bad flag raises the CLI's UsageError
        assert args.command == entry.command and callable(args.func), entry.name
        words = entry.name.split()
        if len(words) == 2:  # "learn classify": a task of the command
            assert words[1] in _tasks(commands[words[0]]), entry.name


def test_every_command_has_a_picture_or_a_reason(gallery: ModuleType) -> None:
    commands = _tasks(build_parser())
    shown = {e.name for e in gallery.ENTRIES} | {e.command for e in gallery.ENTRIES}
    reasons = gallery.NO_PICTURE
    for command, sub in commands.items():
        assert command in shown or command in reasons, f"{command}: no entry and no reason"
        if command in ("learn", "nn"):  # each task too
            for task in _tasks(sub):
                name = f"{command} {task}"
                assert name in shown or name in reasons, f"{name}: no entry and no reason"
    for name, why in reasons.items():
        assert name.split()[0] in commands, f"NO_PICTURE names no command: {name}"
        assert name not in {e.name for e in gallery.ENTRIES}, f"{name}: entry and reason"
        assert why.strip(), name


def test_the_page_is_the_one_the_table_writes(gallery: ModuleType) -> None:
    assert PAGE.read_text() == gallery.markdown(), (
        "docs/gallery.md is out of date: run python docs/make_gallery.py"
    )
    for entry in gallery.ENTRIES:
        assert f"robopercept {entry.line}\n" in PAGE.read_text(), entry.name


def test_every_picture_of_the_page_exists_and_fits(gallery: ModuleType) -> None:
    from PIL import Image

    pictures = re.findall(r"!\[[^\]]*\]\(img/gallery/([^)]+)\)", PAGE.read_text())
    assert sorted(pictures) == sorted(e.picture for e in gallery.ENTRIES)
    total = 0
    for name in pictures:
        path = GALLERY / name
        assert path.is_file(), f"{path} is missing: run python docs/make_gallery.py --only ..."
        with Image.open(path) as im:
            assert im.format == "PNG" and im.width <= gallery.MAX_WIDTH, name
        total += path.stat().st_size
    assert total <= 6.5e6, f"docs/img/gallery holds {total / 1e6:.1f} MB (budget ~6 MB)"
