"""``--json`` on every command, against ``docs/cli_json.md``.

The page has one section per command (``## `robopercept COMMAND` ``) with a table
``key | type | meaning``; these tests read the tables, so the page and the code cannot
drift apart:

* every leaf command of the parser (``nn detect train|eval|IMAGE...`` forms included)
  has ``--json`` and a section on the page;
* the commands below run on tiny inputs with ``--json`` print exactly one JSON document
  on stdout whose keys (at every documented level) and value types are the page's.
"""

from __future__ import annotations

import argparse
import inspect
import json
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from robopercept.cli.main import build_parser, main

DOC = Path(__file__).resolve().parents[2] / "docs" / "cli_json.md"

_HEADING = re.compile(r"^## `robopercept ([^`]+)`\s*$")
_ROW = re.compile(r"^\|\s*`([^`]+)`\s*\|\s*([^|]+?)\s*\|")
_TYPES: dict[str, tuple[type, ...]] = {
    "str": (str,),
    "int": (int,),
    "float": (int, float),
    "bool": (bool,),
    "list": (list,),
    "object": (dict,),
    "null": (type(None),),
}


# --------------------------------------------------------------------------- the page
@dataclass(frozen=True)
class Key:
    """One row of a table: the key's path (``("workloads", "[]", "name")``), the type
    names it may have, and whether it may be absent (written ``key?``)."""

    path: tuple[str, ...]
    types: frozenset[str]
    optional: bool


def _path(text: str) -> tuple[str, ...]:
    """``a.b[].c`` -> ``("a", "b", "[]", "c")``; ``[].x`` -> ``("[]", "x")``."""
    out: list[str] = []
    for part in text.split("."):
        name = part.removesuffix("[]")
        if name:
            out.append(name)
        if part.endswith("[]"):
            out.append("[]")
    return tuple(out)


def _types(cell: str) -> frozenset[str]:
    """``"list of int or null"`` -> ``{"list", "null"}`` (the first word of each
    alternative)."""
    return frozenset(alt.split()[0] for alt in re.split(r"\s+or\s+", cell.strip()))


def parse_doc(text: str) -> dict[str, dict[tuple[str, ...], Key] | None]:
    """Section name (``"nn detect train"``) -> its keys by path, or None for a section
    marked ``TODO(schema)``."""
    sections: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in text.splitlines():
        m = _HEADING.match(line)
        if m:
            current = sections.setdefault(m.group(1).strip(), [])
        elif line.startswith("## "):
            current = None
        elif current is not None:
            current.append(line)
    out: dict[str, dict[tuple[str, ...], Key] | None] = {}
    for name, lines in sections.items():
        keys: dict[tuple[str, ...], Key] = {}
        for line in lines:
            m = _ROW.match(line)
            if not m or m.group(1) == "key":
                continue
            raw = m.group(1)
            key = Key(_path(raw.removesuffix("?")), _types(m.group(2)), raw.endswith("?"))
            keys[key.path] = key
        out[name] = None if not keys and any("TODO(schema)" in s for s in lines) else keys
    return out


@pytest.fixture(scope="module")
def doc() -> dict[str, dict[tuple[str, ...], Key] | None]:
    return parse_doc(DOC.read_text(encoding="utf-8"))


def _type_ok(value: object, types: frozenset[str]) -> bool:
    if isinstance(value, bool):  # a bool is an int to isinstance
        return "bool" in types
    return any(isinstance(value, _TYPES[t]) for t in types)


def check_against(value: object, keys: dict[tuple[str, ...], Key]) -> list[str]:
    """What in ``value`` (a command's parsed output) differs from the documented
    ``keys``: missing or undocumented keys at every documented level, and values of an
    undocumented type. Empty when they agree."""
    errors: list[str] = []

    def walk(v: object, path: tuple[str, ...]) -> None:
        where = ".".join(path).replace(".[]", "[]") or "(top level)"
        if path in keys and not _type_ok(v, keys[path].types):
            documented = " or ".join(sorted(keys[path].types))
            errors.append(f"{where}: {type(v).__name__} {v!r:.60}, documented {documented}")
            return
        if v is None:
            return
        kids = {p[len(path)] for p in keys if len(p) > len(path) and p[: len(path)] == path}
        if not kids:
            return
        if kids == {"[]"}:
            if not isinstance(v, list):
                errors.append(f"{where}: expected a list, got {type(v).__name__}")
                return
            for item in v:
                walk(item, (*path, "[]"))
            return
        if not isinstance(v, dict):
            errors.append(f"{where}: expected an object, got {type(v).__name__}")
            return
        required = {k for k in kids if not keys[(*path, k)].optional}
        if missing := required - v.keys():
            errors.append(f"{where}: documented but missing: {sorted(missing)}")
        if extra := v.keys() - kids:
            errors.append(f"{where}: printed but not documented: {sorted(extra)}")
        for k in sorted(kids & v.keys()):
            walk(v[k], (*path, k))

    walk(value, ())
    return errors


def test_the_checker_finds_missing_extra_and_mistyped_keys() -> None:
    keys = parse_doc(
        "## `robopercept x`\n\n| key | type | meaning |\n|---|---|---|\n"
        "| `a` | int | . |\n| `b` | list of object | . |\n| `b[].c` | str or null | . |\n"
        "| `d?` | object | . |\n| `d.e` | float | . |\n"
    )["x"]
    assert keys is not None
    assert check_against({"a": 1, "b": [{"c": None}, {"c": "s"}]}, keys) == []
    assert check_against({"a": 1, "b": [], "d": {"e": 2}}, keys) == []
    errors = check_against({"a": True, "b": [{"c": 1, "z": 0}], "d": {}, "q": 0}, keys)
    assert errors == [
        "(top level): printed but not documented: ['q']",
        "a: bool True, documented int",
        "b[]: printed but not documented: ['z']",
        "b[].c: int 1, documented null or str",
        "d: documented but missing: ['e']",
    ]
    assert check_against([], keys) == ["(top level): expected an object, got list"]


# --------------------------------------------------------------------------- the parser
def _forms(func: Callable | None) -> dict[str, argparse.ArgumentParser]:
    """The parsers of a command of several forms (``nn detect``: ``train``, ``eval``
    and ``images``, built by ``cli._args.register_forms``), else ``{}``."""
    if func is None:
        return {}
    make = inspect.getclosurevars(func).nonlocals.get("parsers")
    return make() if callable(make) else {}


def leaf_commands() -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``("nn detect train", parser)`` for every command a user can run; the images
    form of ``nn detect`` is ``"nn detect"``."""

    def walk(p: argparse.ArgumentParser, prefix: tuple[str, ...]) -> Iterator:
        subs = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        if subs:
            seen: set[int] = set()
            for name, child in subs[0].choices.items():
                if id(child) not in seen:  # aliases share a parser
                    seen.add(id(child))
                    yield from walk(child, (*prefix, name))
            return
        forms = _forms(p.get_default("func"))
        if forms:
            for form, fp in forms.items():
                yield " ".join(prefix if form == "images" else (*prefix, form)), fp
            return
        yield " ".join(prefix), p

    yield from walk(build_parser(), ())


def _has_json(p: argparse.ArgumentParser) -> bool:
    return any("--json" in a.option_strings for a in p._actions)


def test_every_command_has_json() -> None:
    commands = dict(leaf_commands())
    assert len(commands) > 30 and "nn detect train" in commands and "nn pose" in commands
    missing = sorted(name for name, p in commands.items() if not _has_json(p))
    assert not missing, f"commands without --json: {', '.join(missing)}"


def test_every_command_has_a_section_in_the_page(doc) -> None:
    names = [name for name, _ in leaf_commands()]
    missing = [n for n in names if n not in doc]
    assert not missing, f"{DOC.name} lacks a section for: {', '.join(missing)}"
    for name, keys in doc.items():
        assert keys is None or keys, f"section {name!r}: neither a key table nor TODO(schema)"


def test_the_page_tables_are_well_formed(doc) -> None:
    for name, keys in doc.items():
        for path, key in (keys or {}).items():
            assert key.types <= set(_TYPES), f"{name}: {path}: unknown type {key.types}"
            if len(path) < 2:
                continue
            # a nested key's parent row is an object; the items of a list (``a[].b``)
            # need the list's row (``a``) unless the items have their own (``[]``)
            parent, want = path[:-1], "object"
            if parent[-1] == "[]" and parent not in keys:
                parent, want = parent[:-1], "list"
            assert parent in keys, f"{name}: {'.'.join(path)} has no parent row"
            assert want in keys[parent].types, f"{name}: parent of {'.'.join(path)} not {want}"


# --------------------------------------------------------------------------- the runs
def _scene_image() -> np.ndarray:
    img = np.full((48, 64, 3), 30, np.uint8)
    img[10:30, 12:40] = (220, 40, 40)
    img[20:44, 44:60] = (40, 200, 60)
    return img


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Tiny inputs: an image, two overlapping views, an RGB-D pair and a 3-frame TUM
    folder with ground truth."""
    from robopercept.imaging import read_image, sample_image_path, write_image
    from robopercept.sources import SyntheticRGBDScene, write_tum_folder

    d = tmp_path_factory.mktemp("json_inputs")
    sample = read_image(sample_image_path(), mode="rgb")
    paths = {
        "image": write_image(d / "scene.png", _scene_image()),
        "a": write_image(d / "a.png", sample[:, :-40]),
        "b": write_image(d / "b.png", sample[:, 40:]),
    }
    rgbd = d / "rgbd"
    rgbd.mkdir()
    write_image(rgbd / "a_color.png", np.zeros((4, 5, 3), np.uint8))
    write_image(rgbd / "a_depth.png", np.full((4, 5), 2500, np.uint16))
    paths["rgbd"] = rgbd
    paths["tum"] = write_tum_folder(d / "tum", SyntheticRGBDScene(n_frames=3, seed=1))
    return paths


def _argv(name: str, p: dict[str, Path], out: Path) -> list[str]:
    """The command line of case ``name`` on the inputs ``p``, writing under ``out``."""
    return {
        "info": ["info"],
        "demo": ["demo", "--max-frames", "3", "--out", str(out / "demo"), "--no-video"],
        "plane-track": [
            "plane-track", "--source", str(p["tum"]), "--out", str(out / "pt"),
            "--max-frames", "2", "--no-video",
        ],
        "synth-rgbd": ["synth-rgbd", str(out / "seq"), "--frames", "2"],
        "hog": ["hog", str(p["image"]), "-o", str(out / "hog.png")],
        "stitch": ["stitch", str(p["a"]), str(p["b"]), "-o", str(out / "pano.png")],
        "proposals": ["proposals", str(p["image"]), "--max", "5"],
        "rgbd-import": [
            "rgbd-import", str(p["rgbd"]), str(out / "imported"), "--intrinsics", "5,5,2,1.5",
        ],
        "warmup": ["warmup", "--only", "edges sobel", "--jobs", "1"],
        "warmup --list": ["warmup", "--list"],
    }[name]  # fmt: skip


_QUIET = {"demo", "plane-track", "synth-rgbd", "proposals", "rgbd-import", "warmup"}
CASES = [  # demo: test_demo_json_is_summary_json_and_progress_stays_off_stdout
    "info",
    "plane-track",
    "synth-rgbd",
    "hog",
    "stitch",
    "proposals",
    "rgbd-import",
    "warmup",
    "warmup --list",
]


@pytest.mark.parametrize("name", CASES)
def test_json_output_is_one_document_with_the_documented_keys(
    name, doc, inputs, tmp_path, capsys
) -> None:
    argv = [*_argv(name, inputs, tmp_path), "--json"]
    if name.split()[0] in _QUIET:  # without --quiet too, progress must not reach stdout
        argv.append("--quiet")
    assert main(argv) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    value = json.loads(out)  # the whole of stdout is one JSON document
    assert isinstance(value, dict)
    keys = doc[name]
    assert keys, f"{DOC.name}: section {name!r} has no key table"
    errors = check_against(value, keys)
    assert not errors, f"robopercept {name} --json vs {DOC.name}:\n" + "\n".join(errors)


def test_demo_json_is_summary_json_and_progress_stays_off_stdout(doc, tmp_path, capsys) -> None:
    out = tmp_path / "demo"
    argv = ["demo", "--max-frames", "3", "--out", str(out), "--no-video", "--json"]
    assert main(argv) == 0  # no --quiet: the progress goes to stderr
    printed = json.loads(capsys.readouterr().out)
    errors = check_against(printed, doc["demo"])
    assert not errors, f"robopercept demo --json vs {DOC.name}:\n" + "\n".join(errors)
    assert printed["summary"] == json.loads((out / "summary.json").read_text())
    assert printed["scene"]["frames"] == 3 and printed["config"]["smoothing_lag"] == 2


def test_a_run_that_tracked_nothing_prints_its_json_and_exits_1(inputs, tmp_path, capsys):
    import shutil

    seq = Path(shutil.copytree(inputs["tum"], tmp_path / "seq"))
    for depth in (seq / "depth").iterdir():
        depth.write_bytes(b"not a png")
    argv = ["plane-track", "--source", str(seq), "--out", str(tmp_path / "o"), "--no-video"]
    assert main([*argv, "--quiet", "--json"]) == 1
    captured = capsys.readouterr()
    printed = json.loads(captured.out)
    assert printed["summary"]["frames"] == 0 and printed["summary"]["skipped_frames"] == 3
    assert "no frame was tracked" in captured.err
