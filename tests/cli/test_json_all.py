"""``--json`` on every command, against ``docs/cli_json.md``.

The page has one section per command (``## `robopercept COMMAND` ``) with a table
``key | type | meaning``; these tests read the tables, so the page and the code cannot
drift apart:

* every leaf command of the parser (``nn detect train|eval|IMAGE...`` forms included)
  has ``--json`` and a section on the page, in the parser's order;
* every command runs here on tiny generated or bundled inputs (the network commands
  with one-epoch runs on a few images) with ``--json`` and without ``--quiet``, and
  prints exactly one JSON document on stdout (no ``NaN``) whose keys (at every
  documented level), value types and list item types are the page's; the forms not
  run are in ``LEFT_OUT`` with the reason.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import io
import json
import re
from collections import defaultdict
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

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
    names it may have, whether it may be absent (written ``key?``), and what the items
    of a list are (``"int"`` for ``list of int``, ``"list of float"`` for ``list of
    list of float``; ``None`` for a bare ``list``)."""

    path: tuple[str, ...]
    types: frozenset[str]
    optional: bool
    items: str | None = None


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


def _types(cell: str) -> tuple[frozenset[str], str | None]:
    """``"list of int or null"`` -> ``({"list", "null"}, "int")``: the first word of
    each alternative (``or`` binds loosest: a list of ints, or null), and the items of
    the list alternative."""
    alternatives = re.split(r"\s+or\s+", cell.strip())
    items = next((a[len("list of ") :] for a in alternatives if a.startswith("list of ")), None)
    return frozenset(alt.split()[0] for alt in alternatives), items


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
            types, items = _types(m.group(2))
            key = Key(_path(raw.removesuffix("?")), types, raw.endswith("?"), items)
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


def _bad_item(items: list, spec: str) -> str | None:
    """The first item of ``items`` that is not a ``spec`` (``"int"``, ``"list of
    float"``), described, or None when all are."""
    for i, item in enumerate(items):
        if spec.startswith("list of "):
            if not isinstance(item, list):
                return f"[{i}] is {type(item).__name__} {item!r:.40}"
            if (inner := _bad_item(item, spec[len("list of ") :])) is not None:
                return f"[{i}]{inner}"
        elif not _type_ok(item, frozenset([spec.split()[0]])):
            return f"[{i}] is {type(item).__name__} {item!r:.40}"
    return None


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
        if path in keys and isinstance(v, list) and keys[path].items is not None:
            if (bad := _bad_item(v, keys[path].items)) is not None:
                errors.append(f"{where}: item {bad}, documented list of {keys[path].items}")
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
        "| `f?` | list of list of int or null | . |\n"
    )["x"]
    assert keys is not None
    assert check_against({"a": 1, "b": [{"c": None}, {"c": "s"}]}, keys) == []
    assert check_against({"a": 1, "b": [], "d": {"e": 2}, "f": [[1], []]}, keys) == []
    assert check_against({"a": 1, "b": [], "f": None}, keys) == []
    errors = check_against({"a": True, "b": [{"c": 1, "z": 0}], "d": {}, "q": 0}, keys)
    assert errors == [
        "(top level): printed but not documented: ['q']",
        "a: bool True, documented int",
        "b[]: printed but not documented: ['z']",
        "b[].c: int 1, documented null or str",
        "d: documented but missing: ['e']",
    ]
    assert check_against([], keys) == ["(top level): expected an object, got list"]
    assert check_against({"a": 1, "b": [], "f": [[1], [2.5]]}, keys) == [
        "f: item [1][0] is float 2.5, documented list of list of int"
    ]
    assert check_against({"a": 1, "b": [], "f": [3]}, keys) == [
        "f: item [0] is int 3, documented list of list of int"
    ]


# --------------------------------------------------------------------------- the parser
def _forms(func: Callable | None) -> dict[str, argparse.ArgumentParser]:
    """The parsers of a command of several forms (``nn detect``: ``train``, ``eval``
    and ``images``, built by ``cli.nn._forms.register_forms``), else ``{}``."""
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
        assert keys, f"section {name!r} has no key table (a TODO(schema) left?)"


def test_the_page_tables_are_well_formed(doc) -> None:
    for name, keys in doc.items():
        for path, key in (keys or {}).items():
            assert key.types <= set(_TYPES), f"{name}: {path}: unknown type {key.types}"
            if key.items is not None:
                words = key.items.replace("list of", "").split()
                assert len(words) == 1 and words[0] in _TYPES, f"{name}: {path}: {key.items!r}"
            if len(path) < 2:
                continue
            # a nested key's parent row is an object; the items of a list (``a[].b``)
            # need the list's row (``a``) unless the items have their own (``[]``)
            parent, want = path[:-1], "object"
            if parent[-1] == "[]" and parent not in keys:
                parent, want = parent[:-1], "list"
            assert parent in keys, f"{name}: {'.'.join(path)} has no parent row"
            assert want in keys[parent].types, f"{name}: parent of {'.'.join(path)} not {want}"


def test_the_page_follows_the_order_of_robopercept_help(doc) -> None:
    names = [name for name, _ in leaf_commands()]
    assert [n for n in doc if n in names] == names


# --------------------------------------------------------------------------- the runs
def _not_json(constant: str) -> NoReturn:
    raise ValueError(f"{constant} on stdout: not JSON (write null for a missing number)")


def check_printed(name: str, out: str, doc) -> object:
    """``out``, the whole of a run's stdout, parsed as one JSON document (``NaN`` and
    ``Infinity`` refused) and checked against the section of case ``name``
    (``"edges (log)"``: section ``edges``); returns the value."""
    value = json.loads(out, parse_constant=_not_json)
    section = name.split(" (")[0]
    keys = doc[section]
    assert keys, f"{DOC.name}: section {section!r} has no key table"
    errors = check_against(value, keys)
    assert not errors, f"robopercept {name} --json vs {DOC.name}:\n" + "\n".join(errors)
    return value


def _scene_image() -> np.ndarray:
    img = np.full((48, 64, 3), 30, np.uint8)
    img[10:30, 12:40] = (220, 40, 40)
    img[20:44, 44:60] = (40, 200, 60)
    return img


def _stereo_boards(folder: Path, board: tuple[int, int], baseline: float = 0.06) -> Path:
    """Three views (640x480, f 600 px) of a chessboard of 3 cm squares by a rectified
    pair of cameras ``baseline`` metres apart, as ``l{i}.png`` and ``r{i}.png`` (the
    views of ``pipelines.samples.chessboard_views``, seen by two cameras)."""
    from robopercept.geometry.transforms import rotation_from_rotvec
    from robopercept.imaging import write_image

    folder.mkdir()
    cols, rows = board
    square = 0.03
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    rays = np.stack([(u - 320) / 600, (v - 240) / 600, np.ones_like(u)], axis=-1)
    for i, rvec in enumerate(([0.2, 0.1, 0.0], [-0.15, 0.25, 0.1], [0.1, -0.3, -0.05])):
        r = rotation_from_rotvec(np.array(rvec))
        centre = np.array([(cols + 1) * square / 2, (rows + 1) * square / 2, 0.0])
        for side, dx in (("l", 0.0), ("r", baseline)):
            t = np.array([-dx, 0.0, 0.5]) - r @ centre
            s = (r[:, 2] @ t) / (rays @ r[:, 2])
            b = (rays * s[..., None] - t) @ r  # board-plane coordinates
            ix = np.floor(b[..., 0] / square).astype(int)
            iy = np.floor(b[..., 1] / square).astype(int)
            inside = (ix >= 0) & (ix <= cols) & (iy >= 0) & (iy <= rows)
            img = np.where(inside & ((ix + iy) % 2 == 0), 20, 235).astype(np.uint8)
            write_image(folder / f"{side}{i}.png", img)
    return folder


def _write_matrix(path: Path, T: np.ndarray) -> None:
    path.write_text("\n".join(" ".join(f"{v:.17g}" for v in row) for row in T) + "\n")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """Tiny inputs for every command (no torch): warmup's sample inputs (an image and
    its shifted copy, a rectified pair, a short video, a cloud, a table, chessboard
    views), two overlapping views, an RGB-D pair, a 3-frame TUM folder, a .flo truth,
    frame folders of moving discs with detections and ground truth, HOG face and
    background folders, hand-eye pose files and a stereo rig's board views."""
    from skimage import data

    from robopercept.calibration import pose_from_xyz_rpy
    from robopercept.geometry import invert, rotation_from_rotvec, se3
    from robopercept.imaging import read_image, sample_image_path, write_image
    from robopercept.motion import moving_blobs, write_flo
    from robopercept.pipelines.samples import make_inputs
    from robopercept.sources import SyntheticRGBDScene, write_tum_folder
    from robopercept.tracking import write_mot

    d = tmp_path_factory.mktemp("json_inputs")
    paths = make_inputs(d / "samples")
    sample = read_image(sample_image_path(), mode="rgb")
    paths |= {
        "scene": write_image(d / "scene.png", _scene_image()),
        "a": write_image(d / "a.png", sample[:, :-40]),
        "b": write_image(d / "b.png", sample[:, 40:]),
    }
    rgbd = d / "rgbd"
    rgbd.mkdir()
    write_image(rgbd / "a_color.png", np.zeros((4, 5, 3), np.uint8))
    write_image(rgbd / "a_depth.png", np.full((4, 5), 2500, np.uint16))
    paths["rgbd"] = rgbd
    paths["tum"] = write_tum_folder(d / "tum", SyntheticRGBDScene(n_frames=3, seed=1))
    # image2 is image moved 6 px right and 3 px down (make_inputs)
    h, w = read_image(paths["image"]).shape[:2]
    paths["flo"] = write_flo(d / "truth.flo", np.broadcast_to([6.0, 3.0], (h, w, 2)))
    left = read_image(paths["left"])
    paths["disparity"] = write_image(d / "disp.png", np.full(left.shape[:2], 16, np.uint8))
    # two discs moving on a textured background: foreground for bgsub
    blobs = d / "blobs"
    blobs.mkdir()
    frames, _ = moving_blobs(8, (96, 72), n_blobs=2, radius=(8.0, 9.0), speed=5.0, rng=3)
    for i, f in enumerate(frames):
        write_image(blobs / f"{i:06d}.png", f)
    paths["blobs"] = blobs
    # a red disc moving on green noise, its VOT truth, MOT detections and ground truth
    disc = d / "disc"
    disc.mkdir()
    yy, xx = np.mgrid[:120, :160]
    vot, det, gt = [], [], []
    for t in range(6):
        cx, cy = 40.0 + 4 * t, 50.0 + 2 * t
        noise = np.random.default_rng(t).integers(60, 140, (120, 160, 3))
        img = noise.astype(np.uint8)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 <= 15**2] = (220, 30, 40)
        write_image(disc / f"{t:06d}.png", img)
        vot.append(f"{cx - 15.5},{cy - 15.5},31,31")
        det.append((t + 1, -1, (cx - 15, cy - 15, 31, 31), 0.9))
        gt.append(f"{t + 1},1,{cx - 15},{cy - 15},31,31,1,1,1")
    vot[3] = "nan,nan,nan,nan"  # a frame without the target
    (d / "groundtruth.txt").write_text("\n".join(vot) + "\n")
    (d / "gt.txt").write_text("\n".join(gt) + "\n")
    write_mot(d / "det.txt", det)
    paths |= {"disc": disc, "vot": d / "groundtruth.txt", "gt": d / "gt.txt", "det": d / "det.txt"}
    # HOG: 16 lfw_subset faces, 3 face-free pictures and an unreadable file
    pos, neg = d / "faces", d / "background"
    pos.mkdir()
    neg.mkdir()
    for i, f in enumerate(data.lfw_subset()[:16]):
        write_image(pos / f"face{i:02d}.png", (255 * f).astype(np.uint8))
    for name in ("coffee", "rocket", "brick"):
        write_image(neg / f"{name}.png", np.asarray(getattr(data, name)())[:96, :128])
    (neg / "broken.jpg").write_bytes(b"\xff\xd8 truncated")
    paths |= {"positives": pos, "negatives": neg}
    # hand-eye stations (millimetres): robot poses g*.txt, target poses c*.txt
    gen = np.random.default_rng(5)
    X = se3(rotation_from_rotvec([0.1, -0.2, 1.5]), [30.0, -10.0, 80.0])
    Y = se3(rotation_from_rotvec([3.0, 0.1, 0.0]), [600.0, 50.0, 0.0])
    stations = d / "handeye"
    stations.mkdir()
    for i in range(4):
        xyz = gen.normal(0, 100, 3) + np.array([500.0, 0, 400])
        g = pose_from_xyz_rpy(xyz, gen.normal(0, 20, 3) + np.array([180.0, 0, 0]))
        _write_matrix(stations / f"g{i}.txt", g)
        _write_matrix(stations / f"c{i}.txt", invert(g @ X) @ Y)
    paths["handeye"] = stations
    paths["rig"] = _stereo_boards(d / "rig", (6, 4))
    return paths


def _argvs(p: dict[str, Path], out: Path) -> dict[str, list[str]]:
    """The command line of each case, by name (``"SECTION"`` or ``"SECTION (form)"``),
    on the inputs ``p``, writing under ``out``."""
    s = defaultdict(lambda: "x", {k: str(v) for k, v in p.items()})
    o = str(out)
    table = [s["table"], "--label", "label"]
    boards = [s["board0"], s["board1"], s["board2"], "--board", "6x4", "--square", "0.03"]
    robots = [str(f) for f in sorted(p["handeye"].glob("g*.txt"))]
    targets = [str(f) for f in sorted(p["handeye"].glob("c*.txt"))]
    handeye = ["handeye", "--robot-poses", *robots, "--pose-format", "matrix",
               "--target-poses", *targets, "--setup", "eye-in-hand", "--metres-per-unit",
               "0.001"]  # fmt: skip
    return {
        "info": ["info"],
        "edges": ["edges", s["image"], "-o", f"{o}/e.png"],
        "edges (sobel)": ["edges", s["image"], "--method", "sobel", "-o", f"{o}/e.png"],
        "blobs": ["blobs", s["scene"], "-o", f"{o}/b.png"],
        "features": ["features", s["image"], "--detector", "sift", "-o", f"{o}/f.png"],
        "features (harris)": ["features", s["image"], "-o", f"{o}/f.png"],
        "hog": ["hog", s["scene"], "-o", f"{o}/hog.png"],
        "match": ["match", s["image"], s["image2"], "-o", f"{o}/m.png"],
        "stitch": ["stitch", s["a"], s["b"], "-o", f"{o}/pano.png"],
        "cloud": ["cloud", s["cloud"], "--voxel", "0.02", "--sor", "8:2", "--planes", "1:0.01",
                  "--clusters", "0.05:10:100000", "-o", f"{o}/c.ply", "--image", f"{o}/c.png"],
        "detect-hog": ["detect-hog", s["image"], "--threshold", "0", "--max", "2",
                       "-o", f"{o}/dh.png"],
        "train-hog": ["train-hog", "--positives", s["positives"], "--negatives",
                      s["negatives"], "--rounds", "0", "-o", f"{o}/hog.npz"],
        "learn cluster": ["learn", "cluster", *table, "-o", f"{o}/k.png", "--labels-out",
                          f"{o}/labels.csv"],
        "learn cluster (meanshift)": ["learn", "cluster", *table, "--method", "meanshift",
                                      "-o", f"{o}/k.png"],
        "learn cluster (dbscan)": ["learn", "cluster", *table, "--method", "dbscan",
                                   "-o", f"{o}/k.png"],
        "learn classify": ["learn", "classify", *table, "--model", "tree", "--cv", "3",
                           "-o", f"{o}/cls", "--save", f"{o}/tree.npz"],
        "learn predict": ["learn", "predict", f"{o}/tree.npz", s["table"], "-o",
                          f"{o}/pred.csv"],
        "learn reduce": ["learn", "reduce", *table, "-o", f"{o}/r.png", "--transformed",
                         f"{o}/t.csv"],
        "plane-track": ["plane-track", "--source", s["tum"], "--out", f"{o}/pt",
                        "--max-frames", "2", "--no-video"],
        "synth-rgbd": ["synth-rgbd", f"{o}/seq", "--frames", "2"],
        "proposals": ["proposals", s["scene"], "--max", "5"],
        "rgbd-import": ["rgbd-import", s["rgbd"], f"{o}/imported", "--intrinsics",
                        "5,5,2,1.5"],
        "bgsub": ["bgsub", s["blobs"], "--method", "diff", "-o", f"{o}/bg.mp4"],
        "bgsub (diff3)": ["bgsub", s["blobs"], "--method", "diff3", "--gap", "1", "-o",
                          f"{o}/bg.mp4"],
        "flow": ["flow", s["image"], s["image2"], "--truth", s["flo"], "-o", f"{o}/fl.png"],
        "flow (dense)": ["flow", s["image"], s["image2"], "--dense", "-o", f"{o}/fl.png"],
        "flow VIDEO": ["flow", s["video"], "-o", f"{o}/fl.mp4"],
        "meanshift": ["meanshift", s["disc"], "--truth", s["vot"], "--plot", f"{o}/ok.png",
                      "--results", f"{o}/ms.csv", "-o", f"{o}/ms.mp4"],
        "meanshift (no truth)": ["meanshift", s["video"], "--box", "100,60,60,60", "-o",
                                 f"{o}/ms.mp4"],
        "track": ["track", s["disc"], "--detections", s["det"], "--gt", s["gt"],
                  "--min-hits", "1", "--results", f"{o}/t.txt", "-o", f"{o}/t.mp4"],
        "track (no gt)": ["track", s["video"], "--results", f"{o}/t.txt", "-o", f"{o}/t.mp4"],
        "stereo": ["stereo", s["left"], s["right"], "--max-disparity", "16", "--truth",
                   s["disparity"], "--truth-scale", "4", "--npy", f"{o}/d.npy", "--ply",
                   f"{o}/d.ply", "--focal", "500", "--baseline", "0.1", "-o", f"{o}/d.png"],
        "stereo (bm)": ["stereo", s["left"], s["right"], "--method", "bm", "--no-lr-check",
                        "--max-disparity", "16", "-o", f"{o}/d.png"],
        "calibrate": ["calibrate", *boards, "-o", f"{o}/cam.json"],
        "calibrate (ros)": ["calibrate", *boards, "-o", f"{o}/cam.yaml", "--format", "ros"],
        "stereo-calibrate": ["stereo-calibrate", "--left", f"{s['rig']}/l*.png", "--right",
                             f"{s['rig']}/r*.png", "--board", "6x4", "--square", "0.03",
                             "-o", f"{o}/stereo.yml"],
        "handeye": [*handeye, "-o", f"{o}/he.json"],
        "handeye (ros)": [*handeye, "-o", f"{o}/he.yaml", "--child-frame", "cam"],
        "warmup": ["warmup", "--only", "edges sobel", "--jobs", "1"],
        "warmup --list": ["warmup", "--list"],
        "batch": ["batch", "edges", s["image"], "-o", f"{o}/batch", "--workers", "1"],
    }  # fmt: skip


# every case runs without --quiet: with --json the progress must stay off stdout anyway
_PLACEHOLDER = Path("x")
CASES = list(_argvs(defaultdict(lambda: _PLACEHOLDER), _PLACEHOLDER))
_SAVES = {"learn predict": "learn classify"}  # a case that reads what another one wrote

# demo: test_demo_json_is_summary_json_and_progress_stays_off_stdout
CHECKED_ELSEWHERE = {"demo"}

#: Forms of the commands that no test of this file runs, and why. Every command has at
#: least one form checked (test_every_command_is_run_here); these forms print the keys
#: of the form that is checked, except where said.
LEFT_OUT = {
    "train-hog (the face model, no --positives)": "23 s even with --rounds 0 (HOG of "
    "lfw_subset and a 5-fold CV); it prints `cv` where the --positives form, checked, "
    "prints `images` and `skipped`; tests/cli/test_learn_cli.py runs it",
    "plane-track --source realsense": "needs a RealSense camera",
    "handeye --images, calibrate and stereo-calibrate on photos": "real data (the same "
    "keys); tests/cli/test_calibration_cli.py runs them with the realdata marker",
    "nn * train|eval on real data (--data nuclei, trees, a COCO file or a folder)": "real "
    "data and minutes of training; the keys are those of the built-in sets'",
}


@pytest.mark.parametrize("name", CASES)
def test_json_output_is_one_document_with_the_documented_keys(
    name, doc, inputs, tmp_path_factory, capsys
) -> None:
    out = tmp_path_factory.getbasetemp() / "json_runs"  # shared: learn predict reads
    out.mkdir(exist_ok=True)
    if name in _SAVES:
        argv = _argvs(inputs, out)[_SAVES[name]]
        assert main([*argv, "--json"]) == 0, capsys.readouterr().err
        capsys.readouterr()
    argv = [*_argvs(inputs, out)[name], "--json"]
    assert main(argv) == 0, capsys.readouterr().err
    value = check_printed(name, capsys.readouterr().out, doc)
    if name == "detect-hog":  # the nested keys were checked
        assert value["detections"]
    if name in ("meanshift", "track", "flow"):
        assert value["evaluation" if name != "flow" else "truth"] is not None


# --------------------------------------------------------------------------- nn
def _run_quiet(argv: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue()


_NN_DATA = {
    "detect": ["--data", "digits", "--images", "8", "--size", "64x64", "--seed", "0"],
    "segment": ["--data", "shapes", "--images", "10", "--size", "64x64", "--seed", "0"],
    "pose": ["--data", "figures", "--images", "12", "--size", "64x64", "--seed", "0"],
    "cloud": ["--data", "shapes", "--shapes", "3", "--points", "64", "--seed", "0"],
}


def _nn_train(out: Path) -> dict[str, list[str]]:
    """The smallest training run of each network command (a second or a few each)."""
    small = ["--epochs", "1", "--batch-size", "4"]
    return {
        "nn train": ["nn", "train", "--data", "digits", "--model", "vgg_small", "--epochs",
                     "1", "-o", str(out / "nn")],
        "nn detect train": ["nn", "detect", "train", *_NN_DATA["detect"], "--model", "fcos",
                            "--width", "8", *small, "-o", str(out / "detect")],
        "nn segment train": ["nn", "segment", "train", *_NN_DATA["segment"], "--width", "4",
                             *small, "-o", str(out / "segment")],
        "nn segment train (instance)": ["nn", "segment", "train", *_NN_DATA["segment"],
                                        "--task", "instance", "--width", "4", *small,
                                        "-o", str(out / "instance")],
        "nn pose train": ["nn", "pose", "train", *_NN_DATA["pose"], "--width", "4", *small,
                          "-o", str(out / "pose")],
        "nn cloud train": ["nn", "cloud", "train", *_NN_DATA["cloud"], "--width", "0.125",
                           "--epochs", "1", "--batch-size", "8", "-o", str(out / "cloud")],
    }  # fmt: skip


def _nn_use(p: dict[str, Path], out: Path) -> dict[str, list[str]]:
    """eval of the runs of :func:`_nn_train`, and the image forms (shipped models)."""
    s = defaultdict(lambda: "x", {k: str(v) for k, v in p.items()})
    return {
        "nn eval": ["nn", "eval", str(out / "nn"), "--data", "digits", "-o",
                    str(out / "cm.png")],
        "nn predict": ["nn", "predict", str(out / "nn"), s["digit"]],
        "nn summary": ["nn", "summary", "vgg_small", "--input", "1,8,8"],
        "nn models": ["nn", "models"],
        "nn detect eval": ["nn", "detect", "eval", str(out / "detect"), *_NN_DATA["detect"]],
        "nn detect": ["nn", "detect", s["shapes"], "-o", str(out / "detected")],
        "nn segment eval": ["nn", "segment", "eval", str(out / "segment"),
                            *_NN_DATA["segment"]],
        "nn segment": ["nn", "segment", s["shapes"], "-o", str(out / "segmented")],
        "nn segment (maskrcnn)": ["nn", "segment", s["shapes"], "--model", "maskrcnn",
                                  "-o", str(out / "instances")],
        "nn pose eval": ["nn", "pose", "eval", str(out / "pose"), *_NN_DATA["pose"]],
        "nn pose": ["nn", "pose", s["shapes"], "--lift3d", "-o", str(out / "posed")],
        "nn cloud eval": ["nn", "cloud", "eval", str(out / "cloud"), *_NN_DATA["cloud"]],
        "nn cloud": ["nn", "cloud", s["cloud"], "--model", str(out / "cloud")],
        "nn cloud (parts)": ["nn", "cloud", s["cloud"], "--segment", "-o",
                             str(out / "parts")],
    }  # fmt: skip


NN_TRAIN = list(_nn_train(_PLACEHOLDER))
NN_USE = list(_nn_use(defaultdict(lambda: _PLACEHOLDER), _PLACEHOLDER))


@pytest.fixture(scope="module")
def nn_runs(tmp_path_factory) -> tuple[Path, dict[str, Path], dict[str, str]]:
    """The runs of :func:`_nn_train` (about 12 s in all on one thread), the inputs of
    the image forms (a digit picture, a procedural shapes canvas, a point cloud) and
    each training run's stdout."""
    torch = pytest.importorskip("torch")
    from robopercept.imaging import write_image
    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.pointcloud import PointCloud, write_point_cloud

    out = tmp_path_factory.mktemp("json_nn")
    canvas = procedural_detection_set(1, (128, 128), rng=0).images[0]
    rng = np.random.default_rng(0)
    write_point_cloud(out / "blob.ply", PointCloud(rng.normal(0, 1, (200, 3))))
    paths = {
        "digit": write_image(out / "digit.png", rng.integers(0, 256, (8, 8), dtype=np.uint8)),
        "shapes": write_image(
            out / "shapes.png", np.round(np.asarray(canvas) * 255).astype(np.uint8)
        ),
        "cloud": out / "blob.ply",
    }
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    printed = {}
    try:
        for name, argv in _nn_train(out).items():
            code, printed[name] = _run_quiet([*argv, "--json"])  # no --quiet: stderr only
            assert code == 0, name
    finally:
        torch.set_num_threads(threads)
    return out, paths, printed


@pytest.mark.parametrize("name", NN_TRAIN)
def test_nn_training_json_has_the_documented_keys(name, doc, nn_runs) -> None:
    check_printed(name, nn_runs[2][name], doc)


@pytest.mark.parametrize("name", NN_USE)
def test_nn_json_has_the_documented_keys(name, doc, nn_runs, torch_one_thread) -> None:
    out, paths, _ = nn_runs
    code, printed = _run_quiet([*_nn_use(paths, out)[name], "--json"])
    assert code == 0
    value = check_printed(name, printed, doc)
    assert isinstance(value, dict) or value, f"{name}: an empty array checks no item key"


def test_every_command_is_run_here() -> None:
    """Every command of the parser has a case above (or its own test), and the forms
    left out are listed with a reason (printed)."""
    run = {n.split(" (")[0] for n in [*CASES, *NN_TRAIN, *NN_USE]} | CHECKED_ELSEWHERE
    commands = [name for name, _ in leaf_commands()]
    assert not set(commands) - run, f"no --json run of: {sorted(set(commands) - run)}"
    assert all(reason.strip() for reason in LEFT_OUT.values())
    print("forms of commands not run by tests/cli/test_json_all.py (pytest -s shows this):")
    for form, reason in LEFT_OUT.items():
        print(f"  {form}: {reason}")


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
