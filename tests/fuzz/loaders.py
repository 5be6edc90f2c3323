"""The readers' fuzzer on the surfaces of issue 47: targets, seeds and format-aware mutations.

:mod:`tests.fuzz.readers` runs these as rows of its ``READERS`` table (same mutants,
sandbox, bound and report as the older readers); this module holds what is new:

- **annotation files and folders**: COCO JSON (:func:`read_coco_json`, and
  :meth:`DetectionDataset.from_annotations`, what ``nn detect|segment train --data``
  reads, on a COCO file beside its images), COCO results evaluated against their ground
  truth, labelme folders, Pascal-VOC XML folders and files, VOC segmentation folders,
  MPII and imgaug keypoint JSON;
- **calibration and camera files**: OpenCV ``FileStorage`` XML, YAML and JSON
  (:func:`read_opencv_storage`; :func:`load_calibration` on the XML and JSON that
  ``cv2.FileStorage`` writes), ROS transforms (:func:`read_transform`), a TUM
  ``camera.json`` (:func:`read_camera_json`);
- **folders**: the RGB-D importer's inputs (TUM association list, TUM lists, image
  pairs; :func:`import_rgbd_folder`), ModelNet class folders (:func:`read_cloud_folder`);
- **checkpoints and run folders**: the shipped ``.pt`` files of
  ``src/robopercept/data`` loaded and run the way ``nn detect|segment|pose|cloud|predict``
  do (:func:`load_image_predictor`, :func:`load_class_predictor`), and a classification
  run folder trained once for the campaign (prediction from it, and ``resume``);
- **batch manifests**: the ``OUT`` folder of a real two-item ``batch edges`` run, resumed
  (:func:`run_batch` with ``resume=True``).

Mutations that know the formats (each ``(data, rng, fmt) -> (data, description)``, as
in :mod:`tests.fuzz.readers`, falling back to a byte mutation when the input does not
parse):

- :func:`json_value`: one node of the parsed JSON replaced by a hostile value (null, a
  string, a list, ``2**63``, ``1e308``, NaN, Infinity, a lone surrogate, a number as a
  string ...), removed, doubled, given an unknown sibling, or nested 65 to 50,000 deep;
- :func:`xml_hostile`: elements nested 64 to 100,000 deep, an entity expansion bomb
  (the "billion laughs"), an external entity, an element's text or an attribute made
  hostile, an element removed or doubled, a mismatched closing tag;
- :func:`yaml_hostile`: flow collections nested deep, an alias bomb, a ``!!python``
  tag, hostile scalars, a doubled key, a tab indent, a block scalar, document markers;
- :func:`path_escape`: a file name in a list or an annotation pointed outside the
  dataset (``../sentinel_rgb.png``, an absolute path). Each such reader's seed folder
  has a sentinel image one and two levels up; a target that loads it (a constant image
  no real file holds) raises :class:`SilentWrongAnswer`: issue 47's R43;
- :func:`pt_content`: a checkpoint loaded (``weights_only``), one thing changed, saved
  again: a constructor setting made huge, negative, NaN, of another type, unknown or a
  duplicate of an argument; a top-level or nested field (calibration, skeleton,
  training state, the classifier's architecture JSON) of another type or removed; the
  ``kind`` of another model; a weight tensor filled with NaN or infinities, reshaped,
  retyped, removed or joined by an extra one; a normalisation std made zero; the
  ``model`` entry not a dict of tensors.

The checkpoint targets also check the prediction they make: a NaN or infinite score,
box, keypoint or probability is a silent wrong answer (R45).
"""

from __future__ import annotations

import fnmatch
import io
import json
import math
import re
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ALL_KINDS",
    "SENTINEL_DEPTH",
    "SENTINEL_RGB",
    "json_value",
    "matches",
    "member_format",
    "mutations",
    "path_escape",
    "pt_content",
    "xml_hostile",
    "yaml_hostile",
]

#: the real data folder and the package's files (as tests.fuzz.readers has them)
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
PACKAGE_DATA = Path(__file__).resolve().parents[2] / "src" / "robopercept" / "data"
#: the colour of the sentinel images that lie outside every seed folder (no real image
#: is this constant)
SENTINEL_RGB = (17, 34, 51)
SENTINEL_DEPTH = 4321
#: every model kind a checkpoint may name (the targets of "another kind")
ALL_KINDS = (
    "fcos", "faster", "maskrcnn", "keypointrcnn", "fast", "rcnn", "localizer",
    "naive", "fcn32s", "fcn8s", "unet", "deeppose", "heatmap", "hrnet", "pointnet",
    "dgcnn", "vgg_small", "resnet_small", "mlp", "", 3,
)  # fmt: skip
_NEST = "\x00NEST\x00"
_IMAGE_PATH = re.compile(
    rb"(?<![\w/.-])[\w.-]+(?:/[\w.-]+)*\.(?:png|jpe?g|pgm|ppm|tiff?|bmp|off|ply|pcd)\b", re.I
)


class _Hostile:
    """The hostile values the mutations draw from (JSON values, checkpoint settings, XML
    texts, YAML scalars)."""

    JSON: tuple[Any, ...] = (
        None, True, False, "", "x", -1, 0, 1, 0.5, -0.0, 2**31, 2**63, 2**64, 10**30,
        1e308, -1e308, math.nan, math.inf, -math.inf, [], {}, [1, 2, 3], [[0, 0]],
        {"a": 1}, "\udcff", "9" * 400, "12", "../x.png",
    )  # fmt: skip
    SETTINGS: tuple[Any, ...] = (
        2**31, 2**62, 10**9, 0, -1, 1.5, math.nan, math.inf, None, "x", True, [], {},
        [2**31, 2**31], [0, 8], 10**6,
    )  # fmt: skip
    TEXT: tuple[str, ...] = (
        "", "nan", "inf", "-1", "1e999", "99999999999999999999", "../../x.png", "\u202e",
        "a" * 10000, "0x10", "-0", "  ", "&amp;", "1 2 3 4 5 6 7 8 9",
    )  # fmt: skip
    YAML: tuple[str, ...] = (
        "9" * 5000, "1e99999", ".nan", "-.inf", "0x7fffffff", "~", "[]", "{}", "'x'",
        "!!binary AAAA", "&x 1", "*undefined", "!!opencv-matrix", "[1, [2, [3]]]",
        "{rows: 99999, cols: 99999, dt: d, data: [1]}", "!!int 1e3", "? complex",
    )  # fmt: skip


def _fallback(data: bytes, rng: np.random.Generator, fmt: str, why: str) -> tuple[bytes, str]:
    """A text or byte mutation of :mod:`tests.fuzz.readers` when the format-aware one
    cannot apply (the input does not parse: an earlier stacked mutation broke it)."""
    from tests.fuzz.readers import flip_bits, numeric_token

    out, desc = (numeric_token if rng.random() < 0.5 else flip_bits)(data, rng, fmt)
    return out, f"{why}, so {desc}"


# ----------------------------------------------------------------------------- JSON


def _nodes(root: Any, limit: int = 20000) -> list[tuple[Any, Any, Any, bool]]:
    """``(parent, key, value, numeric_in_list)`` of every node of a parsed JSON value
    (the root's parent is None), breadth first, at most ``limit``."""
    out: list[tuple[Any, Any, Any, bool]] = [(None, None, root, False)]
    i = 0
    while i < len(out) and len(out) < limit:
        _, _, value, _ = out[i]
        i += 1
        if isinstance(value, dict):
            items = list(value.items())
        elif isinstance(value, list):
            items = list(enumerate(value))
        else:
            continue
        for k, v in items:
            num = isinstance(value, list) and isinstance(v, int | float)
            out.append((value, k, v, num))
    return out


def _dump(doc: Any, nest: str | None = None) -> bytes:
    """JSON text of ``doc`` (NaN and Infinity as JavaScript writes them); the marker
    string, if any, replaced by ``nest`` (a structure too deep for ``json.dumps``)."""
    text = json.dumps(doc)
    if nest is not None:
        text = text.replace(json.dumps(_NEST), nest, 1)
    return text.encode("utf-8", "surrogatepass")


def json_value(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """One node of a JSON document made hostile (see the module docstring)."""
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return _fallback(data, rng, "json", "not JSON")
    nodes = _nodes(doc)
    plain = [n for n in nodes if not n[3]]
    pool = plain if plain and rng.random() < 0.75 else nodes
    parent, key, value, _ = pool[int(rng.integers(len(pool)))]
    op = int(rng.integers(7))
    where = "root" if parent is None else repr(key)

    def put(new: Any) -> None:
        nonlocal doc
        if parent is None:
            doc = new
        else:
            parent[key] = new

    nest = None
    if op == 0 or (op in (2, 3) and parent is None):
        new = _Hostile.JSON[int(rng.integers(len(_Hostile.JSON)))]
        put(new)
        desc = f"{where}: {type(value).__name__} -> {new!r}"[:120]
    elif op == 1:  # another type of the same meaning
        if isinstance(value, bool) or value is None:
            new = int(bool(value))
        elif isinstance(value, int | float):
            new = str(value)
        elif isinstance(value, str):
            new = [value]
        elif isinstance(value, list):
            new = value[0] if value else {}
        else:
            new = list(value.values())
        put(new)
        desc = f"{where}: {type(value).__name__} -> {type(new).__name__}"
    elif op == 2:  # removed
        if isinstance(parent, dict):
            del parent[key]
        else:
            parent.pop(key)
        desc = f"{where} removed"
    elif op == 3:  # an unknown sibling, or a doubled list item
        if isinstance(parent, dict):
            parent["robopercept_fuzz_" + str(key)] = value
            desc = f"unknown key beside {where}"
        else:
            parent.insert(key, value)
            desc = f"list item {where} doubled"
    elif op == 4:  # nested deep
        depth = int(rng.choice([65, 300, 3000, 50000]))
        put(_NEST)
        nest = (
            ('{"a": ' * depth + "0" + "}" * depth)
            if rng.random() < 0.3
            else ("[" * depth + "1" + "]" * depth)
        )
        desc = f"{where} nested {depth} deep"
    elif op == 5:  # a path string sent outside the folder
        strings = [n for n in nodes if isinstance(n[2], str) and "." in n[2] and n[0] is not None]
        if not strings:
            return _fallback(data, rng, "json", "no path string")
        parent, key, value, _ = strings[int(rng.integers(len(strings)))]
        new = _escape_name(value, rng)
        parent[key] = new
        desc = f"{key!r}: {value[:40]!r} -> {new!r}"
    else:  # a list made long (up to about 4 MB), else a hostile value
        if isinstance(value, list) and value:
            n = int(rng.choice([2, 1000, 100000]))
            n = max(2, min(n, 2**22 // len(json.dumps(value))))  # at most about 4 MB
            put(value * n)
            desc = f"{where}: list repeated {n} times"
        else:
            new = _Hostile.JSON[int(rng.integers(len(_Hostile.JSON)))]
            put(new)
            desc = f"{where}: {type(value).__name__} -> {new!r}"[:120]
    return _dump(doc, nest), desc


# ------------------------------------------------------------------------------ paths


def _escape_name(name: str, rng: np.random.Generator) -> str:
    """``name`` pointed outside its folder: at a sentinel image 1 to 3 levels up, an
    absolute path, a NUL byte, a Windows path."""
    kind = "depth" if "depth" in name.lower() else "rgb"
    choice = int(rng.integers(6))
    if choice < 3:
        return "../" * (choice + 1) + f"sentinel_{kind}.png"
    if choice == 3:
        return "/etc/hostname"
    if choice == 4:
        return str(Path("/") / name)
    return "C:\\\\" + name if rng.random() < 0.5 else name + "\x00.png"


def path_escape(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """A file name in the text (a list line, a COCO ``file_name``, a labelme
    ``imagePath``, a VOC ``<filename>``) pointed outside the dataset (see
    :func:`_escape_name`)."""
    names = list(_IMAGE_PATH.finditer(data))
    if not names:
        return _fallback(data, rng, fmt, "no file name")
    m = names[int(rng.integers(len(names)))]
    old = m.group().decode(errors="replace")
    new = _escape_name(old, rng)
    if fmt == "json":  # stay a JSON string
        new = json.dumps(new)[1:-1]
    return data[: m.start()] + new.encode("utf-8", "surrogatepass") + data[m.end() :], (
        f"{old!r} -> {new!r}"
    )


# ------------------------------------------------------------------------------- XML

_XML_START = re.compile(rb"<([A-Za-z_][\w.-]*)(?:\s[^>]*)?>")
_XML_LEAF = re.compile(rb"<([A-Za-z_][\w.-]*)(?:\s[^>]*)?>([^<]*)</\1\s*>")
_XML_ATTR = re.compile(rb'([A-Za-z_][\w.-]*)="([^"]*)"')


def _after_prolog(data: bytes) -> int:
    """Offset just after the XML declaration (0 without one)."""
    m = re.match(rb"\s*<\?xml[^>]*\?>", data)
    return m.end() if m else 0


def xml_hostile(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """One hostile change to an XML document (see the module docstring)."""
    root = _XML_START.search(data, _after_prolog(data))
    if root is None:
        return _fallback(data, rng, fmt, "no XML element")
    op = int(rng.integers(8))
    leaves = list(_XML_LEAF.finditer(data))
    if op == 0:  # deep nesting inside the root
        depth = int(rng.choice([64, 500, 5000, 100000]))
        inner = b"<n>" * depth + b"</n>" * depth
        return data[: root.end()] + inner + data[root.end() :], f"elements nested {depth} deep"
    if op in (1, 2):  # entities: an expansion bomb, or an external one
        head = _after_prolog(data)
        name = root.group(1)
        if op == 1:
            levels = int(rng.choice([3, 9]))
            ents = [b'<!ENTITY e0 "lollollollollollollollollollol">'] + [
                b'<!ENTITY e%d "%s">' % (k, b"&e%d;" % (k - 1) * 10) for k in range(1, levels + 1)
            ]
            ref, desc = b"&e%d;" % levels, f"entity bomb of 10^{levels} expansions"
        else:
            ents = [b'<!ENTITY ext SYSTEM "file:///etc/passwd">']
            ref, desc = b"&ext;", "external entity file:///etc/passwd"
        doctype = b"\n<!DOCTYPE " + name + b" [" + b"".join(ents) + b"]>\n"
        where = leaves[int(rng.integers(len(leaves)))].start(2) if leaves else root.end()
        where += len(doctype)
        out = data[:head] + doctype + data[head:]
        return out[:where] + ref + out[where:], desc
    if not leaves:
        return _fallback(data, rng, fmt, "no XML leaf element")
    leaf = leaves[int(rng.integers(len(leaves)))]
    tag = leaf.group(1).decode(errors="replace")
    if op == 3:  # the text made hostile
        new = _Hostile.TEXT[int(rng.integers(len(_Hostile.TEXT)))].encode("utf-8")
        return data[: leaf.start(2)] + new + data[leaf.end(2) :], (f"<{tag}> text -> {new[:30]!r}")
    if op == 4:
        return data[: leaf.start()] + data[leaf.end() :], f"<{tag}> removed"
    if op == 5:
        return data[: leaf.end()] + leaf.group() + data[leaf.end() :], f"<{tag}> doubled"
    if op == 6:  # an attribute
        attrs = list(_XML_ATTR.finditer(data))
        if not attrs:
            return data[: leaf.start(2)] + b"-1" + data[leaf.end(2) :], f"<{tag}> text -> -1"
        a = attrs[int(rng.integers(len(attrs)))]
        values = (b"", b"opencv-matrix", b"opencv-nd-matrix", b"x", b"-1", b"\xff")
        new = values[int(rng.integers(len(values)))]
        return data[: a.start(2)] + new + data[a.end(2) :], (
            f"attribute {a.group(1).decode(errors='replace')} -> {new!r}"
        )
    close = data.find(b"</" + leaf.group(1), leaf.start(2))
    return data[: close + 2] + b"mismatch" + data[close + 2 + len(leaf.group(1)) :], (
        f"</{tag}> -> </mismatch>"
    )


# ------------------------------------------------------------------------------ YAML

_YAML_PAIR = re.compile(rb"^([ \t]*(?:- )?[\w.-]+:)[ \t]*(\S[^\n]*)$", re.M)


def yaml_hostile(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """One hostile change to a YAML document (see the module docstring)."""
    pairs = list(_YAML_PAIR.finditer(data))
    if not pairs:
        return _fallback(data, rng, fmt, "no YAML key: value line")
    m = pairs[int(rng.integers(len(pairs)))]
    key = m.group(1).decode(errors="replace").strip()
    op = int(rng.integers(8))
    if op == 0:
        depth = int(rng.choice([64, 500, 5000, 50000]))
        value = b"[" * depth + b"1" + b"]" * depth
        desc = f"{key} nested {depth} deep"
    elif op == 1:  # an alias bomb
        lines = [b"a0: &a0 [x, x, x, x, x, x, x, x, x, x]"] + [
            b"a%d: &a%d [%s]" % (k, k, b", ".join([b"*a%d" % (k - 1)] * 10)) for k in range(1, 9)
        ]
        return data.rstrip(b"\n") + b"\n" + b"\n".join(lines) + b"\n", "alias bomb a0..a8"
    elif op == 2:
        value = b'!!python/object/apply:os.system ["true"]'
        desc = f"{key}: a !!python tag"
    elif op == 3:
        value = _Hostile.YAML[int(rng.integers(len(_Hostile.YAML)))].encode()
        desc = f"{key}: -> {value[:30]!r}"
    elif op == 4:
        line_end = data.find(b"\n", m.end())
        line_end = len(data) if line_end < 0 else line_end
        return data[: line_end + 1] + m.group() + b"\n" + data[line_end + 1 :], f"{key} doubled"
    elif op == 5:
        indent = re.match(rb"[ \t]*", m.group(1))
        n = indent.end() if indent else 0
        return data[: m.start()] + b"\t" + data[m.start() + n :], f"{key}: tab indent"
    elif op == 6:
        value = b"|\n  block scalar text"
        desc = f"{key}: a block scalar"
    else:
        markers = (b"---\n", b"...\n", b"%YAML 1.2\n", b"--- !!map\n")
        marker = markers[int(rng.integers(len(markers)))]
        return data[: m.start()] + marker + data[m.start() :], f"{marker!r} before {key}"
    return data[: m.start(2)] + value + data[m.end(2) :], desc


# ------------------------------------------------------------------------ checkpoints


def _tensors(state: dict[str, Any]) -> list[str]:
    weights = state.get("model")
    if not isinstance(weights, dict):
        return []
    import torch

    return [k for k, v in weights.items() if isinstance(v, torch.Tensor)]


def _hostile_tensor(t: Any, rng: np.random.Generator) -> tuple[Any, str]:
    """A weight tensor made hostile: NaN/inf values, another shape or dtype, a plain
    value instead."""
    import torch

    op = int(rng.integers(5))
    if op == 0 and t.is_floating_point() and t.numel():
        t = t.clone()
        value = float(rng.choice([math.nan, math.inf, -math.inf, 1e38]))
        if rng.random() < 0.5:
            t.view(-1)[int(rng.integers(t.numel()))] = value
            return t, f"one value {value}"
        return t.fill_(value), f"filled with {value}"
    if op == 1:
        shapes = [(0,), (1,), (*t.shape, 1), (max(t.numel() - 1, 0),), (t.numel(),), (2, 3)]
        shape = shapes[int(rng.integers(len(shapes)))]
        return torch.zeros(shape, dtype=t.dtype), f"shape {tuple(t.shape)} -> {shape}"
    if op == 2:
        dtype = [torch.float64, torch.int64, torch.bool, torch.float16, torch.complex64]
        dt = dtype[int(rng.integers(len(dtype)))]
        return torch.zeros(t.shape, dtype=dt), f"dtype -> {dt}"
    if op == 3:
        plain = [None, 1.0, [1.0, 2.0], "w", {}]
        v = plain[int(rng.integers(len(plain)))]
        return v, f"-> {v!r}"
    if t.ndim:
        return t.transpose(0, -1).contiguous(), "transposed"
    return torch.tensor([t.item(), t.item()]), "scalar -> 2 values"


def _set_nested(doc: Any, rng: np.random.Generator) -> str:
    """A leaf (or a tensor) anywhere under the non-weight entries of a checkpoint made
    hostile."""
    import torch

    top = {k: v for k, v in doc.items() if k != "model"}
    nodes = [n for n in _nodes(top) if n[0] is not None]
    if not nodes:
        return "nothing nested"
    parent, key, value, _ = nodes[int(rng.integers(len(nodes)))]
    if isinstance(value, torch.Tensor):
        new, what = _hostile_tensor(value, rng)
    else:
        new = _Hostile.SETTINGS[int(rng.integers(len(_Hostile.SETTINGS)))]
        what = f"-> {new!r}"
    (doc if parent is top else parent)[key] = new  # the walk copied the top level only
    return f"{key!r} ({type(value).__name__}) {what}"[:160]


def pt_content(data: bytes, rng: np.random.Generator, fmt: str) -> tuple[bytes, str]:
    """A checkpoint with one hostile entry (see the module docstring)."""
    import torch

    try:
        state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception:  # an earlier stacked mutation broke the file
        return _fallback(data, rng, "binary", "not a torch file")
    if not isinstance(state, dict):
        return _fallback(data, rng, "binary", "not a checkpoint dict")
    op = int(rng.integers(8))
    names = _tensors(state)
    if op == 0 and isinstance(state.get("settings"), dict):
        settings = state["settings"]
        keys = [*sorted(settings), "num_classes", "robopercept_fuzz", "in_channels"]
        key = keys[int(rng.integers(len(keys)))]
        value = _Hostile.SETTINGS[int(rng.integers(len(_Hostile.SETTINGS)))]
        if key == "num_classes" or (key == "in_channels" and key not in settings):
            value = 3
        settings[key] = value
        desc = f"settings[{key!r}] = {value!r}"
    elif op == 1:  # a top-level field of another type, or removed
        keys = sorted(k for k in state if k != "model")
        if not keys:
            return _fallback(data, rng, "binary", "no field")
        key = keys[int(rng.integers(len(keys)))]
        if rng.random() < 0.25:
            del state[key]
            desc = f"{key!r} removed"
        else:
            value = [*_Hostile.SETTINGS, "fcos", torch.tensor(1.0)][
                int(rng.integers(len(_Hostile.SETTINGS) + 2))
            ]
            state[key] = value
            desc = f"{key!r} = {value!r}"[:120]
    elif op == 2 and "kind" in state:
        kind = ALL_KINDS[int(rng.integers(len(ALL_KINDS)))]
        desc = f"kind {state['kind']!r} -> {kind!r}"
        state["kind"] = kind
    elif op == 2 and isinstance(state.get("architecture"), str):  # a classifier's JSON
        text, desc = json_value(state["architecture"].encode(), rng, "json")
        state["architecture"] = text.decode("utf-8", "surrogatepass")
        desc = f"architecture JSON: {desc}"
    elif op in (3, 4) and names:
        stds = [k for k in names if k.endswith("std")]  # a Normalize layer's (R45)
        key = stds[int(rng.integers(len(stds)))] if stds and op == 4 else None
        if key is not None:
            state["model"][key] = torch.zeros_like(state["model"][key])
            desc = f"model[{key!r}] = 0"
        else:
            key = names[int(rng.integers(len(names)))]
            new, what = _hostile_tensor(state["model"][key], rng)
            state["model"][key] = new
            desc = f"model[{key!r}] {what}"
    elif op == 5 and names:
        choice = int(rng.integers(3))
        key = names[int(rng.integers(len(names)))]
        if choice == 0:
            del state["model"][key]
            desc = f"model[{key!r}] removed"
        elif choice == 1:
            state["model"]["robopercept_fuzz.weight"] = torch.zeros(3)
            desc = "an extra tensor in model"
        else:
            state["model"] = {k: v for k, v in state["model"].items() if k != key}
            state["model"][key + "_renamed"] = torch.zeros(2)
            desc = f"model[{key!r}] renamed"
    elif op == 6:
        bad = [[], None, torch.zeros(3), {}, {"a": torch.zeros(1)}, "model", [torch.zeros(1)]]
        value = bad[int(rng.integers(len(bad)))]
        state["model"] = value
        desc = f"model = {type(value).__name__}"
    else:
        desc = _set_nested(state, rng)
    buf = io.BytesIO()
    try:
        torch.save(state, buf)
    except Exception as exc:  # a value torch cannot save: mutate bytes instead
        return _fallback(data, rng, "binary", f"torch.save refused ({type(exc).__name__})")
    return buf.getvalue(), desc


# ------------------------------------------------------------------------ mutation sets


def _sets() -> dict[str, tuple[Callable[..., tuple[bytes, str]], ...]]:
    from tests.fuzz.readers import BINARY, PNG, TEXT

    return {
        "json": (json_value, json_value, json_value, path_escape, *TEXT),
        "xml": (xml_hostile, xml_hostile, xml_hostile, path_escape, *TEXT),
        "yaml": (yaml_hostile, yaml_hostile, yaml_hostile, *TEXT),
        "pt": (pt_content, pt_content, pt_content, pt_content, *BINARY),
        "list": (path_escape, path_escape, *TEXT),
        "png": PNG,
        "text": TEXT,
        "binary": BINARY,
    }


def mutations(fmt: str) -> tuple[Callable[..., tuple[bytes, str]], ...]:
    """The mutations of a format family: ``json``, ``xml``, ``yaml``, ``pt``, ``list``
    (file lists: paths sent outside first), ``png``, ``text``, ``binary``."""
    return _sets()[fmt]


def member_format(name: str) -> str:
    """The format family of a folder member, by its name."""
    suffix = Path(name).suffix.lower()
    if name.endswith(("associations.txt", "rgb.txt", "depth.txt")):
        return "list"
    return {
        ".json": "json",
        ".xml": "xml",
        ".yml": "yaml",
        ".yaml": "yaml",
        ".dat": "yaml",  # OpenCV's corner files
        ".pt": "pt",
        ".png": "png",
    }.get(suffix, "text")


def matches(name: str, patterns: tuple[str, ...]) -> bool:
    """``name`` (a POSIX path relative to the folder) matches one of ``patterns``."""
    return not patterns or any(fnmatch.fnmatch(name, p) for p in patterns)


# ------------------------------------------------------------------------------ checks


def _silent(message: str) -> Exception:
    from tests.fuzz.readers import SilentWrongAnswer

    return SilentWrongAnswer(message)


def is_sentinel(image: Any) -> bool:
    """``image`` is one of the sentinels: constant :data:`SENTINEL_RGB` (uint8, or float
    in [0, 1]) or constant :data:`SENTINEL_DEPTH` (uint16)."""
    a = np.asarray(image)
    if a.size == 0 or a.dtype.kind not in "fiu":
        return False
    if a.ndim == 3 and a.shape[2] >= 3:
        rgb = np.asarray(SENTINEL_RGB, np.float64) / (255.0 if a.dtype.kind == "f" else 1.0)
        if not np.allclose(a[0, 0, :3], rgb, atol=0.004):  # the common case, at once
            return False
        return bool(np.allclose(a[..., :3], rgb, atol=0.004))
    return a.ndim == 2 and bool((a == SENTINEL_DEPTH).all())


def untraced(target: Any, args: tuple, kwargs: dict) -> None:
    """Call ``target(*args, **kwargs)`` with :mod:`tracemalloc` paused, its errors
    ignored: the sandbox's warm-up call of each seed. Importing torch and the networks
    while every allocation is traced took a minute in each new worker (26 s for torch
    alone), against seconds untraced; the measured calls that follow find them
    loaded."""
    import tracemalloc

    from tests.fuzz.sandbox import resolve

    tracing = tracemalloc.is_tracing()
    tracemalloc.stop()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            resolve(target)(*args, **kwargs)
    except Exception:  # the measured call reports it
        pass
    finally:
        if tracing:
            tracemalloc.start()


def _finite(values: dict[str, Any], where: str) -> None:
    for name, v in values.items():
        a = np.asarray(v)
        if a.dtype.kind in "fc" and a.size and not np.isfinite(a).all():
            raise _silent(f"{where}: the prediction's {name} holds NaN or infinite values")


def write_sentinels(folder: Path, size: tuple[int, int] = (96, 72)) -> None:
    """The sentinel colour and depth images (``sentinel_rgb.png``, ``sentinel_depth.png``)
    in ``folder`` and ``folder/mutants``, where the escaped names of :func:`path_escape`
    land."""
    from robopercept.imaging import write_image

    w, h = size
    for d in (folder, folder / "mutants"):
        d.mkdir(parents=True, exist_ok=True)
        write_image(d / "sentinel_rgb.png", np.full((h, w, 3), SENTINEL_RGB, np.uint8))
        write_image(d / "sentinel_depth.png", np.full((h, w), SENTINEL_DEPTH, np.uint16))


# ----------------------------------------------------------------------------- targets
# module-level: the sandbox pickles them by reference


def annotated_images(path: str, masks: bool = False) -> Any:
    """:meth:`DetectionDataset.from_annotations` (``nn detect|segment train --data``) on
    a COCO file or an annotation folder; an image loaded from outside it (a sentinel) is
    a silent wrong answer (R43)."""
    from robopercept.nn.detection.data import DetectionDataset

    ds = DetectionDataset.from_annotations(path, masks=masks)
    for k in range(len(ds)):
        if is_sentinel(ds.images[k]):
            raise _silent(f"image {k} was read from outside {path} (the sentinel)")
    return ds


def coco_results_evaluated(path: str) -> Any:
    """:func:`read_coco_results`, then :func:`evaluate_detections` against the ground
    truth ``gt.json`` beside it (``iou_type.txt`` says bbox, segm or keypoints)."""
    from robopercept.nn.coco.dataset import read_coco_json
    from robopercept.nn.coco.evaluate import evaluate_detections
    from robopercept.nn.coco.results import read_coco_results

    folder = Path(path).parent
    gt = read_coco_json(folder / "gt.json")
    results = read_coco_results(path)
    iou_type = (folder / "iou_type.txt").read_text().strip()
    return evaluate_detections(gt, results, iou_type).stats


#: the TUM fr1 camera of the 96 x 72 crops (:func:`_crops`): fx, fy, cx, cy
CROP_K = (520.9, 521.0, 325.1 - 280, 249.7 - 200)


def import_rgbd(src: str) -> Any:
    """:func:`import_rgbd_folder` (``rgbd-import SRC OUT --intrinsics ...``) into a fresh
    folder beside ``src``; an output frame copied from the sentinel outside ``src`` is
    a silent wrong answer (R43)."""
    from robopercept.imaging import read_image
    from robopercept.sources import import_rgbd_folder

    out = Path(src).with_name(Path(src).name + "_out")
    shutil.rmtree(out, ignore_errors=True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = import_rgbd_folder(src, out, intrinsics=CROP_K)
        for f in sorted(out.glob("*/*.png")):
            if is_sentinel(read_image(f)):
                raise _silent(f"{f.relative_to(out)} is the sentinel from outside {src}")
        return result
    finally:
        shutil.rmtree(out, ignore_errors=True)


def cloud_folder(root: str) -> Any:
    """:func:`read_cloud_folder` (``nn cloud train --data FOLDER``), 64 points a file,
    then each file it skipped read alone (:func:`read_cloud_file`, what ``nn cloud
    predict`` reads): its typed error is the outcome; a skipped file that reads alone
    is a silent wrong answer (a cloud lost from the data set)."""
    from robopercept.nn.cloud.data import read_cloud_file, read_cloud_folder

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unreadable files are skipped with a warning
        ds = read_cloud_folder(root, 64, progress=False)
    for f in ds.skipped:
        read_cloud_file(f, 64)
        raise _silent(f"read_cloud_folder skipped {f}, which read_cloud_file reads")
    return ds


def _image(kind: str) -> np.ndarray:
    """The fixed input a loaded network predicts on (noise: the weights, not the
    picture, are under test)."""
    rng = np.random.default_rng(47)
    if kind == "classify":
        return rng.integers(0, 256, (8, 8), dtype=np.uint8)
    if kind == "cloud":
        return rng.normal(size=(256, 3))
    return rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)


def network_prediction(path: str, kind: str) -> Any:
    """Load a checkpoint (or run folder) as ``robopercept nn detect|segment|pose|cloud|
    predict --model PATH`` does and predict one fixed input; NaN or infinite scores,
    boxes, keypoints or probabilities are a silent wrong answer (R45). ``kind="auto"``:
    :func:`load_predictor` tells the kind from the checkpoint."""
    if kind == "auto":
        from robopercept.nn.predict import load_predictor

        p = load_predictor(path, device="cpu")
        kind = p.kind
        out = p(_image(kind))
        values = getattr(out, "values", None)
        if values is None:
            values = {"probabilities": list(out.probabilities.values())}
        _finite(values, path)
        return values
    if kind in ("classify", "cloud"):
        from robopercept.nn.predict_class import load_class_predictor

        cp = load_class_predictor(kind, path, device="cpu")
        out = cp(_image(kind))
        _finite({"probabilities": list(out.probabilities.values())}, path)
        return out.probabilities
    from robopercept.nn.predict import load_image_predictor

    ip = load_image_predictor(kind, path, device="cpu")
    pred = ip(_image(kind))
    _finite(pred.values, path)
    return pred.values


#: the classification run of the campaign: model, its arguments and the training
RUN_MODEL = "vgg_small"
RUN_KWARGS = {"widths": [4, 8], "convs_per_stage": 1}
RUN_EPOCHS = 1


def _run_config() -> Any:
    from robopercept.nn.train.config import TrainConfig

    return TrainConfig(epochs=RUN_EPOCHS, batch_size=1024, seed=0, device="cpu", amp=False)


def train_classify_run(work: str) -> str:
    """Train the tiny run of the campaign into ``work/classify_run`` (once)."""
    from robopercept.nn.classification.run import train_run

    out = Path(work) / "classify_run"
    if not (out / "checkpoint.best.pt").is_file() and _installed("torch"):
        train_run(
            "digits", RUN_MODEL, out, config=_run_config(), model_kwargs=RUN_KWARGS,
            mode="gray", progress=False, overwrite=out.exists(),
        )  # fmt: skip
    return str(out)


def classify_run(folder: str, resume: bool = False) -> Any:
    """A classification run folder: ``nn train --resume`` (same options: a damaged
    training state must be refused, R49), or ``nn predict --model RUN`` on a fixed
    image."""
    if resume:
        from robopercept.nn.classification.run import train_run

        res = train_run(
            "digits", RUN_MODEL, folder, config=_run_config(), model_kwargs=RUN_KWARGS,
            mode="gray", resume=True, progress=False,
        )  # fmt: skip
        return res.metrics
    return network_prediction(folder, "classify")


def _batch_inputs() -> list[str]:
    return [str(DATA / "features/opencv_box/box.png"), str(DATA / "rgbd/tum_pair_slambook2/1.png")]


#: an address where no scheduler listens: an item left to do ends the call with a
#: typed error once the manifest has been read
NO_SCHEDULER = "tcp://127.0.0.1:9"


def make_batch(work: str) -> str:
    """A real two-item ``robopercept batch edges`` run into ``work/batch_out`` (once; a
    one-worker local cluster)."""
    from robopercept.pipelines.batch import run_batch

    out = Path(work) / "batch_out"
    if not (out / "batch.json").is_file() and _installed("distributed"):
        shutil.rmtree(out, ignore_errors=True)
        run_batch("edges", _batch_inputs(), out, workers=1, progress=False)
    return str(out)


def batch_resume(out: str) -> Any:
    """``robopercept batch edges ... --resume`` on a (mutated) ``OUT``: the manifest is
    read and every done item skipped before the scheduler (absent) is needed. An item
    skipped although its outputs are missing or outside its folder (R35), or skipped
    under options other than those the manifest records (R36), is a silent wrong
    answer."""
    import distributed  # noqa: F401  (imported in the warm-up: not a mutant's allocation)

    from robopercept.pipelines.batch import JOB_OPTIONS, MANIFEST, run_batch

    try:
        recorded = json.loads((Path(out) / MANIFEST).read_text())
    except (OSError, ValueError, RecursionError):
        recorded = None
    result = run_batch(
        "edges", _batch_inputs(), out, resume=True, scheduler=NO_SCHEDULER,
        connect_timeout=0.5, progress=False,
    )  # fmt: skip
    root = Path(out).resolve()
    skipped = [r for r in result.items if r.get("status") == "skipped"]
    for r in skipped:
        folder = (root / str(r.get("item"))).resolve()
        for o in set(map(str, r.get("outputs") or [])):
            f = (root / str(o)).resolve()
            if folder not in f.parents or not f.is_file():
                raise _silent(f"item {r.get('item')!r} skipped with output {o!r} (R35)")
    options = recorded.get("options") if isinstance(recorded, dict) else None
    if skipped and options != JOB_OPTIONS["edges"]:
        raise _silent(f"items skipped under options {JOB_OPTIONS['edges']}; ran with {options}")
    return result.to_dict()


# ------------------------------------------------------------------------------- seeds


def _real(*parts: str) -> list[Path]:
    return [p for p in (DATA / q for q in parts) if p.is_file()]


def _installed(*modules: str) -> bool:
    """The optional packages a target needs are installed (torch: the ``deep`` extra;
    distributed: ``scale``); without them the reader has no seeds and is skipped."""
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in modules)


def _copy(src: Path, dst: Path, patterns: tuple[str, ...] = ("*",)) -> Path:
    """Copy the files of ``src`` matching ``patterns`` (recursively) into ``dst``
    (plain copies, writable: the real data is read-only)."""
    for f in sorted(src.rglob("*")):
        rel = f.relative_to(src).as_posix()
        if f.is_file() and any(fnmatch.fnmatch(rel, p) for p in patterns):
            (dst / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(f, dst / rel)
    return dst


def coco_seeds(work: Path) -> list[Path]:
    """The two real COCO files: mmpose's keypoints subset (4 images, 14 people) and
    labelme's VOC instances (3 images, 12 polygons)."""
    del work
    return _real(
        "detection/coco_keypoints_mmpose/test_coco.json",
        "detection/labelme_voc_instances/coco/annotations.json",
    )


def coco_data_seeds(work: Path) -> list[Path]:
    """The two COCO files copied with their images (mutants are written beside them)."""
    if not _installed("torch"):
        return []
    seeds = []
    for src, name in (
        ("detection/coco_keypoints_mmpose", "test_coco.json"),
        ("detection/labelme_voc_instances/coco", "annotations.json"),
    ):
        if (DATA / src / name).is_file():
            folder = _copy(DATA / src, work / Path(src).name)
            seeds.append(folder / name)
    write_sentinels(work)
    return seeds


def coco_results_seeds(work: Path) -> list[Path]:
    """Results of a near-perfect detector written from the real ground truth (boxes
    moved by up to 3 px, seeded scores): boxes and keypoints for the mmpose file, boxes
    and RLE masks for labelme's; each in a folder with its ``gt.json``."""
    from robopercept.nn.coco.dataset import read_coco_json
    from robopercept.nn.coco.results import results_from_ground_truth, results_to_list
    from robopercept.nn.coco.rle import annotation_to_rle

    rng = np.random.default_rng(47)
    seeds = []
    for gt_path in coco_seeds(work):
        gt = read_coco_json(gt_path)
        raw = json.loads(gt_path.read_text())
        sizes = {im["id"]: (im["height"], im["width"]) for im in raw["images"]}
        kinds = ["bbox", "keypoints" if "keypoints" in gt_path.read_text() else "segm"]
        for iou_type in kinds:
            folder = work / f"{gt_path.stem}_{iou_type}"
            folder.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(gt_path, folder / "gt.json")
            (folder / "iou_type.txt").write_text(iou_type + "\n")
            if iou_type == "segm":
                rows = [
                    {
                        "image_id": a["image_id"],
                        "category_id": a["category_id"],
                        "segmentation": annotation_to_rle(a["segmentation"], *sizes[a["image_id"]]),
                        "score": round(float(rng.uniform(0.3, 1.0)), 4),
                    }
                    for a in raw["annotations"]
                    if not a.get("iscrowd")
                ]
            else:
                rows = results_to_list(
                    results_from_ground_truth(gt, require_keypoints=iou_type == "keypoints")
                )
                for r in rows:
                    r["bbox"] = [round(v + float(rng.uniform(-3, 3)), 2) for v in r["bbox"]]
                    r["score"] = round(float(rng.uniform(0.3, 1.0)), 4)
            (folder / "results.json").write_text(json.dumps(rows))
            seeds.append(folder / "results.json")
    return seeds


def labelme_seeds(work: Path) -> list[Path]:
    """labelme's three annotated VOC photos (JSON polygons beside the JPEGs)."""
    src = DATA / "detection/labelme_voc_instances/data_annotated"
    if not src.is_dir() or not _installed("torch"):
        return []
    write_sentinels(work)
    return [_copy(src, work / "labelme")]


def voc_xml_folder_seeds(work: Path) -> list[Path]:
    """DeepForest's two 400 x 400 NEON tiles with their Pascal-VOC XML boxes."""
    src = DATA / "detection/deepforest_neon"
    if not (src / "OSBS_029.xml").is_file() or not _installed("torch"):
        return []
    write_sentinels(work)
    return [_copy(src, work / "voc_xml", ("OSBS_029.*", "SOAP_061.*"))]


def voc_mask_seeds(work: Path) -> list[Path]:
    """labelme's VOC segmentation folder (JPEGImages, SegmentationObject,
    SegmentationClass, class_names.txt)."""
    src = DATA / "detection/labelme_voc_instances/voc"
    if not src.is_dir() or not _installed("torch"):
        return []
    write_sentinels(work)
    return [_copy(src, work / "voc_masks")]


def voc_xml_seeds(work: Path) -> list[Path]:
    """The four DeepForest XML files (37 to 574 boxes)."""
    del work
    d = "detection/deepforest_neon/"
    return _real(
        d + "SOAP_061.xml",
        d + "OSBS_029.xml",
        d + "2019_YELL_2_541000_4977000_image_crop.xml",
        d + "2019_YELL_2_528000_4978000_image_crop2.xml",
    )


def mpii_seeds(work: Path) -> list[Path]:
    del work
    return _real(
        "detection/mpii_keypoints_mmpose/test_mpii.json",
        "detection/mpii_keypoints_mmpose/test_mpii_trb.json",
    )


def imgaug_seeds(work: Path) -> list[Path]:
    del work
    return _real("detection/imgaug_quokka/quokka_annotations.json")


def opencv_storage_seeds(work: Path) -> list[Path]:
    """Real FileStorage files (an XML image list, an XML homography, Middlebury's XML
    table, a YAML corner matrix with ``dt: "2f"``, OpenCV's stereo YAML) and the
    reference result written as JSON by ``cv2.FileStorage`` itself."""
    seeds = _real(
        "calibration/opencv_chessboard_stereo/stereo_calib.xml",
        "features/oxford_affine/graf/H1to2p.xml",
        "stereo/middlebury_opencv_extra/datasets.xml",
        "calibration/opencv_extra_corners_gt/chessboard/chess_corners1.dat",
        "calibration/opencv_chessboard_stereo/intrinsics.yml",
    )
    seeds += [p for p in _cv2_calibrations(work) if p.suffix == ".json"]
    return seeds


def _cv2_calibrations(work: Path) -> list[Path]:
    """OpenCV's reference result ``left_intrinsics.yml`` written again by
    ``cv2.FileStorage`` as XML and JSON."""
    yml = DATA / "calibration/opencv_chessboard_stereo/left_intrinsics.yml"
    try:
        import cv2
    except ImportError:
        return []
    if not yml.is_file():
        return []
    out = []
    src = cv2.FileStorage(str(yml), cv2.FILE_STORAGE_READ)
    for suffix in (".xml", ".json"):
        path = work / f"left_intrinsics{suffix}"
        if not path.is_file():
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
            for name in ("image_width", "image_height", "board_width", "board_height"):
                fs.write(name, int(src.getNode(name).real()))
            fs.write("square_size", src.getNode("square_size").real())
            for name in ("camera_matrix", "distortion_coefficients", "extrinsic_parameters"):
                fs.write(name, src.getNode(name).mat())
            fs.write("avg_reprojection_error", src.getNode("avg_reprojection_error").real())
            fs.release()
        out.append(path)
    src.release()
    return out


def calibration_cv2_seeds(work: Path) -> list[Path]:
    return _cv2_calibrations(work)


def transform_seeds(work: Path) -> list[Path]:
    """The first pose of TUM's ground-truth trajectory as a ROS ``TransformStamped``
    YAML and JSON (:func:`write_ros_yaml`, :func:`transform_stamped`)."""
    from robopercept.calibration.ros import (
        rotation_from_quaternion,
        transform_stamped,
        write_ros_yaml,
    )

    gt = DATA / "rgbd/trajectory_eval_slambook2/groundtruth.txt"
    if not gt.is_file():
        return []
    row = next(line for line in gt.read_text().splitlines() if line and line[0] != "#")
    _, tx, ty, tz, qx, qy, qz, qw = (float(v) for v in row.split())
    T = np.eye(4)
    T[:3, :3] = rotation_from_quaternion([qx, qy, qz, qw])
    T[:3, 3] = tx, ty, tz
    doc = transform_stamped(T, "world", "camera")
    path = write_ros_yaml(work / "world_camera.yaml", doc)
    (work / "world_camera.json").write_text(json.dumps(doc, indent=2, default=float))
    return [path, work / "world_camera.json"]


def _crops(n: int = 2) -> list[tuple[np.ndarray, np.ndarray]]:
    """96 x 72 crops of slambook2's two real TUM frames (colour, 16-bit depth)."""
    from robopercept.imaging import read_image

    root = DATA / "rgbd/tum_pair_slambook2"
    out = []
    for i in range(1, n + 1):
        color = read_image(root / f"{i}.png", mode="rgb")[200:272, 280:376]
        depth = read_image(root / f"{i}_depth.png")[200:272, 280:376]
        out.append((np.ascontiguousarray(color), np.ascontiguousarray(depth)))
    return out


def camera_json_seeds(work: Path) -> list[Path]:
    """``camera.json`` of a TUM folder written by :func:`write_tum_folder` (the fr1
    camera of the slambook2 frames)."""
    from tests.fuzz.readers import _tum_seeds

    folders = _tum_seeds(work)
    return [f / "camera.json" for f in folders if (f / "camera.json").is_file()]


def rgbd_import_seeds(work: Path) -> list[Path]:
    """Three source folders of the importer's layouts from the real crops: a TUM folder
    with ``associations.txt`` (as ``associate.py`` writes it), one with ``rgb.txt`` and
    ``depth.txt``, and image pairs (``1.png``, ``1_depth.png``)."""
    from robopercept.imaging import write_image

    if not (DATA / "rgbd/tum_pair_slambook2/1.png").is_file():
        return []
    crops = _crops()
    write_sentinels(work)
    assoc, lists, pairs = work / "tum_assoc", work / "tum_lists", work / "pairs"
    rows, rgb_rows, depth_rows = [], ["# color images"], ["# depth maps"]
    for i, (color, depth) in enumerate(crops):
        t = 1305031102.175304 + i / 30
        for d in (assoc, lists):
            write_image(d / f"rgb/{t:.6f}.png", color)
            write_image(d / f"depth/{t + 0.01:.6f}.png", depth)
        rows.append(f"{t:.6f} rgb/{t:.6f}.png {t + 0.01:.6f} depth/{t + 0.01:.6f}.png")
        rgb_rows.append(f"{t:.6f} rgb/{t:.6f}.png")
        depth_rows.append(f"{t + 0.01:.6f} depth/{t + 0.01:.6f}.png")
        write_image(pairs / f"{i + 1}.png", color)
        write_image(pairs / f"{i + 1}_depth.png", depth)
    (assoc / "associations.txt").write_text("\n".join(rows) + "\n")
    (lists / "rgb.txt").write_text("\n".join(rgb_rows) + "\n")
    (lists / "depth.txt").write_text("\n".join(depth_rows) + "\n")
    return [assoc, lists, pairs]


def modelnet_seeds(work: Path) -> list[Path]:
    """A ModelNet folder of the four smallest real meshes: ``monitor/{train,test}``,
    ``sofa/test``, ``bed/train``."""
    files = {
        "monitor/train/monitor_0001.off": "ModelNet40/monitor/train/monitor_0001.off",
        "monitor/test/monitor_0466.off": "ModelNet40/monitor/test/monitor_0466.off",
        "sofa/test/sofa_0681.off": "ModelNet10/sofa/test/sofa_0681.off",
        "bed/train/bed_0001.off": "ModelNet_samples_zeaggler/bed/bed_0001.off",
    }
    root = work / "modelnet"
    if not _installed("torch"):
        return []
    for dst, src in files.items():
        if not (DATA / "pointcloud_cls" / src).is_file():
            return []
        (root / dst).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(DATA / "pointcloud_cls" / src, root / dst)
    return [root]


def _shipped(*names: str) -> list[Path]:
    if not _installed("torch"):
        return []
    return [p for p in (PACKAGE_DATA / n for n in names) if p.is_file()]


def detector_seeds(work: Path) -> list[Path]:
    del work
    return _shipped("detector_fcos_shapes.pt", "detector_faster_shapes.pt")


def segmenter_seeds(work: Path) -> list[Path]:
    del work
    return _shipped("segmenter_unet_nuclei.pt", "segmenter_maskrcnn_shapes.pt")


def pose_seeds(work: Path) -> list[Path]:
    del work
    return _shipped("pose_hrnet_figures.pt", "pose_deeppose_figures.pt")


def cloud_seeds(work: Path) -> list[Path]:
    del work
    return _shipped("cloud_pointnet_shapes.pt", "cloud_dgcnn_shapes.pt")


def classifier_seeds(work: Path) -> list[Path]:
    del work
    return _shipped("classifier_digits.pt")


def classify_run_seeds(work: Path) -> list[Path]:
    """The run trained by :func:`train_classify_run` (made in the sandbox first)."""
    run = work / "classify_run"
    return [run] if (run / "checkpoint.best.pt").is_file() else []


def batch_seeds(work: Path) -> list[Path]:
    """The ``OUT`` of :func:`make_batch` (made in the sandbox first)."""
    out = work / "batch_out"
    return [out] if (out / "batch.json").is_file() else []


# ----------------------------------------------------------------------------- readers

#: the readers of issue 47, as the keyword arguments of :class:`tests.fuzz.readers.Reader`
#: (``mutations`` names a family of :func:`mutations`; folder and ``"auto"`` readers
#: take each member's by its name)
READER_SPECS: tuple[dict[str, Any], ...] = (
    # annotations (nn detect|segment|pose train --data), calibration and camera files
    dict(name="coco-json", target="robopercept.nn.coco.dataset:read_coco_json", fmt="json",
         seeds=coco_seeds, mutations="json"),
    dict(name="coco-data", target=annotated_images, fmt="json", seeds=coco_data_seeds,
         mutations="json", kwargs=({}, {"masks": True}), timeout=20.0, beside=True),
    # the evaluation rasterizes masks at the images' size: 32 MiB whatever the file
    dict(name="coco-results", target=coco_results_evaluated, fmt="json",
         seeds=coco_results_seeds, mutations="json", beside=True, floor=32 * 2**20),
    dict(name="labelme-folder", target=annotated_images, fmt="folder", seeds=labelme_seeds,
         kwargs=({}, {"masks": True}), timeout=20.0, members=("*.json",)),
    dict(name="voc-xml-folder", target=annotated_images, fmt="folder",
         seeds=voc_xml_folder_seeds, timeout=20.0, members=("*.xml",)),
    dict(name="voc-mask-folder", target=annotated_images, fmt="folder", seeds=voc_mask_seeds,
         kwargs=({}, {"masks": True}), timeout=20.0,
         members=("Segmentation*/*.png", "class_names.txt")),
    dict(name="voc-xml", target="robopercept.nn.coco.voc:read_voc_xml", fmt="xml",
         seeds=voc_xml_seeds, mutations="xml"),
    dict(name="mpii", target="robopercept.nn.pose.io:read_mpii_json", fmt="json",
         seeds=mpii_seeds, mutations="json"),
    dict(name="imgaug", target="robopercept.nn.pose.io:read_imgaug_keypoints", fmt="json",
         seeds=imgaug_seeds, mutations="json"),
    dict(name="opencv-storage", target="robopercept.calibration.filestorage:read_opencv_storage",
         fmt="auto", seeds=opencv_storage_seeds),
    dict(name="calibration-cv2", target="robopercept.calibration.intrinsics:load_calibration",
         fmt="auto", seeds=calibration_cv2_seeds),
    dict(name="ros-transform", target="robopercept.calibration.ros:read_transform", fmt="auto",
         seeds=transform_seeds),
    dict(name="camera-json", target="robopercept.sources.tum:read_camera_json", fmt="json",
         seeds=camera_json_seeds, mutations="json"),
    # folders: rgbd-import SRC, nn cloud train --data
    dict(name="rgbd-import", target=import_rgbd, fmt="folder", seeds=rgbd_import_seeds,
         timeout=20.0, members=("*.txt", "depth/*.png", "*_depth.png")),
    dict(name="modelnet-folder", target=cloud_folder, fmt="folder", seeds=modelnet_seeds,
         members=("*/*/*.off",)),
    # checkpoints (nn detect|segment|pose|cloud|predict --model), by kind and told apart
    *(
        dict(name=f"{name}-checkpoint", target=network_prediction, fmt="pt", seeds=seeds,
             mutations="pt", kwargs=({"kind": kind}, {"kind": "auto"}), timeout=20.0)
        for kind, name, seeds in (
            ("detect", "detector", detector_seeds),
            ("segment", "segmenter", segmenter_seeds),
            ("pose", "pose", pose_seeds),
            ("cloud", "cloud", cloud_seeds),
            ("classify", "classifier", classifier_seeds),
        )
    ),
    # a run folder: in turn checkpoint.best.pt with predict, checkpoint.pt resumed (which
    # evaluates the test split and draws two pictures: 32 MiB whatever the file)
    dict(name="classify-run", target=classify_run, fmt="folder", seeds=classify_run_seeds,
         kwargs=({}, {"resume": True}), timeout=60.0, members=("checkpoint*.pt",),
         make=train_classify_run, floor=32 * 2**20),
    dict(name="batch-manifest", target=batch_resume, fmt="folder", seeds=batch_seeds,
         timeout=30.0, members=("batch.json",), make=make_batch),
)  # fmt: skip
