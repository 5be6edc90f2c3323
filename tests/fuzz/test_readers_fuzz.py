"""Every reader against a fixed set of mutants of real files (issues 25 and 47).

Each reader gets 8 to 48 mutants (a fixed seed: the same inputs on every run), each
read in a :class:`~tests.fuzz.sandbox.Sandbox`; no mutant may crash the process, hang,
or allocate beyond ``4 x file size + decoded size + 8 MiB`` (a larger floor where a
reader says so), and none may raise an error that is not a ``RoboperceptError``. The
readers of issue 47 (annotations, calibration files, import folders, checkpoints, run
folders, batch manifests: :mod:`tests.fuzz.loaders`) get fewer mutants where a call
loads a network or resumes a run. ``python -m tests.fuzz`` runs the same fuzzer for
as long as its budget allows.
"""

from __future__ import annotations

import hashlib
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from tests.fuzz import readers as rf
from tests.fuzz.sandbox import Outcome, Sandbox

SEED = 25
#: mutants per reader: the whole file stays under about 3 minutes on 2 busy cores
COUNTS = {
    "pcd": 40,
    "ply": 40,
    "mesh": 40,
    "image": 48,
    "mot": 40,
    "vot": 40,
    "tum": 40,
    "calibration-json": 40,
    "calibration-yaml": 40,
    "hog-model": 40,
    "learn-model": 40,
    "realsense-bag": 30,
    "realsense-db3": 24,
    "flo": 32,
    # issue 47 (tests.fuzz.loaders): annotations, calibration and camera files, folders
    "coco-json": 24,
    "coco-data": 16,
    "coco-results": 24,
    "labelme-folder": 16,
    "voc-xml-folder": 16,
    "voc-mask-folder": 16,
    "voc-xml": 24,
    "mpii": 24,
    "imgaug": 24,
    "opencv-storage": 24,
    "calibration-cv2": 24,
    "ros-transform": 24,
    "camera-json": 24,
    "rgbd-import": 24,
    "modelnet-folder": 16,
    # checkpoints, run folders, batch manifests
    "detector-checkpoint": 8,
    "segmenter-checkpoint": 8,
    "pose-checkpoint": 8,
    "cloud-checkpoint": 8,
    "classifier-checkpoint": 8,
    "classify-run": 8,
    "batch-manifest": 12,
}
#: readers whose untyped errors are still being fixed (strict: an xpass fails, so the
#: mark must go when the reader is fixed)
UNTYPED_OPEN: dict[str, str] = {}
#: readers that still crash, hang or allocate over the bound on some mutant (strict, as
#: above)
CRASH_OPEN: dict[str, str] = {}
NAMES = [r.name for r in rf.READERS]


def _params(open_defects: dict[str, str]) -> list:
    return [
        pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=open_defects[n]))
        if n in open_defects
        else n
        for n in NAMES
    ]


@pytest.fixture(scope="module")
def box():
    with Sandbox(timeout=15.0, memory_mb=2048.0) as b:
        yield b


@pytest.fixture(scope="module")
def runs(box, tmp_path_factory):
    """The mutants of each reader, run once (lazily) and shared by the tests."""
    cache: dict[str, rf.ReaderRun] = {}

    def get(name: str) -> rf.ReaderRun:
        if name not in cache:
            if not rf.DATA.is_dir():
                pytest.skip(f"real data not available: {rf.DATA} (../shared/data is absent)")
            reader = next(r for r in rf.READERS if r.name == name)
            work = tmp_path_factory.mktemp(name)
            cache[name] = rf.fuzz_reader(reader, box, n=COUNTS[name], seed=SEED, workdir=work)
        run = cache[name]
        if not run.mutants and not run.seed_failures:
            pytest.skip(f"no seed files for {name}")
        return run

    return get


@pytest.mark.realdata
@pytest.mark.parametrize("name", _params(CRASH_OPEN))
def test_no_crash_hang_or_overallocation(runs, name):
    run = runs(name)
    assert not run.seed_failures, f"the unmutated seeds must read: {run.seed_failures}"
    assert len(run.mutants) == COUNTS[name]
    bad = run.bad(("crash", "hang", "memory"))
    assert not bad, "\n" + rf.describe(bad)


@pytest.mark.realdata
@pytest.mark.parametrize("name", _params(UNTYPED_OPEN))
def test_no_untyped_errors(runs, name):
    run = runs(name)
    bad = run.bad(("untyped",))
    assert not bad, "\n" + rf.describe(bad)
    # the mutants reach past the first check: some are refused, and the tally adds up
    t = run.tally
    assert t.typed > 0 and t.inputs == len(run.mutants) + len(run.seed_failures)


# --------------------------------------------------------------- the fuzzer's own parts


def test_mutants_are_a_function_of_seed_reader_and_index():
    data = b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4 4\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n"
    for m in (*rf.TEXT, rf.png_ihdr, rf.png_chunk_len):
        a = m(data, np.random.default_rng([1, 2, 3]), "pcd")
        b = m(data, np.random.default_rng([1, 2, 3]), "pcd")
        assert a == b
    made = {rf.numeric_token(data, np.random.default_rng([0, k]), "pcd")[0] for k in range(40)}
    assert len(made) > 10


def test_text_region_and_numeric_tokens_stay_in_the_header():
    head = b"# .PCD v0.7\nFIELDS x\nSIZE 4\nTYPE F\nCOUNT 1\nPOINTS 1\nDATA binary\n"
    data = head + struct.pack("<f", 1.0) + b"123456"
    assert rf.text_region(data, "pcd") == len(head)
    assert rf.text_region(b"ply\nformat ascii 1.0\nend_header\n1 2 3\n", "ply") == 32
    assert rf.text_region(b"P5\n# c\n640 480\n65535\n\x00\x01", "pnm") == 21
    for k in range(30):
        out, desc = rf.numeric_token(data, np.random.default_rng(k), "pcd")
        assert out.endswith(struct.pack("<f", 1.0) + b"123456"), desc  # the body is intact
        assert out != data or desc.endswith("-> '1'")


def test_png_ihdr_keeps_the_crc_valid(tmp_path):
    from robopercept.imaging import write_image

    p = write_image(tmp_path / "a.png", np.zeros((4, 6), np.uint8))
    data = p.read_bytes()
    for k in range(20):
        out, desc = rf.png_ihdr(data, np.random.default_rng(k), "png")
        body = out[12:29]
        assert struct.unpack(">I", out[29:33])[0] == zlib.crc32(body), desc
        assert len(out) == len(data)


def test_bag_words_and_in_place_patches_are_restored(tmp_path):
    bag = rf.DATA / "rgbd/realsense_bag/single_depth_color_640x480.bag"
    if not bag.is_file():
        pytest.skip(f"real data not available: {bag}")
    data = bag.read_bytes()
    words = rf.bag_words(data)
    # rosbag 2.0: the magic line is 13 bytes, then the bag header record's header_len
    assert words[0] == (13, 4, "top record 0 header_len")
    op = next(w for w in words if w[2] == "top record 0 op")
    assert data[op[0]] == 0x03  # op 3 = bag header
    copy = tmp_path / "c.bag"
    copy.write_bytes(data)
    digest = hashlib.sha256(data).hexdigest()
    for k in range(6):
        patches, cut, name, desc = rf.bag_edit(data, np.random.default_rng(k))
        with rf.patched(copy, data, patches, cut):
            assert copy.read_bytes() != data or name == "bag_field_value", desc
        assert hashlib.sha256(copy.read_bytes()).hexdigest() == digest, desc
    with rf.patched(copy, data, [], 100):
        assert copy.stat().st_size == 100
    assert copy.read_bytes() == data


def test_the_bound_turns_an_over_allocation_into_memory():
    ok = Outcome("ok", "", "", 0.1, peak_mb=20.0)
    judged, bound = rf.judge(ok, size=1000, decoded=2**20)
    assert judged.kind == "memory" and judged.error == "over bound"
    assert bound == pytest.approx((4000 + 2**20 + rf.FLOOR_BYTES) / 2**20)
    small = Outcome("typed", "FileFormatError", "bad", 0.1, peak_mb=8.5)
    assert rf.judge(small, size=1000, decoded=2**20)[0] is small


def test_json_text_is_bounded_by_the_stated_factor():
    """E1-F5: JSON text gets JSON_FACTOR x its size (Python's objects), other bytes 4 x."""
    ok = Outcome("ok", "", "", 0.1, peak_mb=20.0)
    judged, bound = rf.judge(ok, size=2**20, decoded=0, json_size=2**19)
    assert judged is ok
    assert bound == pytest.approx((4 * 2**19 + rf.JSON_FACTOR * 2**19 + rf.FLOOR_BYTES) / 2**20)
    assert rf.judge(ok, size=2**20, decoded=0)[0].kind == "memory"  # no JSON: 4 x


@pytest.mark.parametrize("item", ["[]", "{}", "[0]", "1.5", '"a"', '{"a":[]}'])
def test_the_json_factor_covers_pythons_objects(item):
    """The factor's measurement: the peak of parsing the smallest repeated values stays
    under JSON_FACTOR x the text (40 to 45 x for ``[]``, ``{}`` and ``[0]``)."""
    import tracemalloc

    from robopercept.fileio import parse_json

    text = "[" + ",".join([item] * 100_000) + "]"
    tracemalloc.start()
    try:
        parse_json(text, "x.json")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < rf.JSON_FACTOR * len(text), peak / len(text)


def _strict_int_reader(path: str) -> int:
    """A reader that lets ValueError through: the fuzzer must see it."""
    return int(Path(path).read_text().split()[0])


def test_the_fuzzer_finds_an_untyped_error(box, tmp_path):
    def seeds(work: Path) -> list[Path]:
        (work / "n.txt").write_text("12 34\n")
        return [work / "n.txt"]

    reader = rf.Reader("toy", _strict_int_reader, "text", seeds, rf.TEXT)
    run = rf.fuzz_reader(reader, box, n=len(rf.TEXT), seed=0, workdir=tmp_path)
    untyped = run.bad(("untyped",))
    assert untyped and {m.outcome.error for m in untyped} <= {
        "ValueError",
        "UnicodeDecodeError",
        "IndexError",
    }
    assert run.tally.untyped == len(untyped)
    assert [m.mutation for m in run.mutants] == [m.__name__ for m in rf.TEXT]


def _greedy_reader(path: str) -> None:
    """A reader that holds 32 MiB whatever the file: over any small file's bound."""
    block = np.ones(32 * 2**20, np.uint8)
    del block


def test_the_fuzzer_finds_an_over_allocation(box, tmp_path):
    def seeds(work: Path) -> list[Path]:
        (work / "n.txt").write_text("12 34\n")
        return [work / "n.txt"]

    reader = rf.Reader("greedy", _greedy_reader, "text", seeds, rf.TEXT)
    run = rf.fuzz_reader(reader, box, n=3, seed=0, workdir=tmp_path)
    assert [m.outcome.kind for m in run.mutants] == ["memory"] * 3
    assert all(m.outcome.error == "over bound" and m.bound_mb < 8.1 for m in run.mutants)
    assert run.tally.memory == 3  # each confirmed by a rerun in a fresh worker
    assert run.tally.unconfirmed == 0 and not any(m.unconfirmed for m in run.mutants)


def _once_greedy_reader(path: str) -> None:
    """Holds 32 MiB once: on the first mutant after ``once.flag`` is written beside
    the mutants' folder (the flag is removed), like a peak that is not the reader's."""
    flag = Path(path).parent.parent / "once.flag"
    if flag.exists():
        flag.unlink()
        block = np.ones(32 * 2**20, np.uint8)
        del block


def test_an_over_allocation_that_a_fresh_worker_does_not_repeat_is_unconfirmed(box, tmp_path):
    def seeds(work: Path) -> list[Path]:
        (work / "n.txt").write_text("12 34\n")
        (work / "once.flag").touch()
        return [work / "n.txt"]

    reader = rf.Reader("once", _once_greedy_reader, "text", seeds, rf.TEXT)
    spawns = box.spawns
    run = rf.fuzz_reader(reader, box, n=3, seed=0, workdir=tmp_path)
    assert [m.outcome.kind for m in run.mutants] == ["ok"] * 3
    first = run.mutants[0]
    assert "peak 32.0 MiB > bound" in first.unconfirmed
    assert "rerun in a fresh worker" in first.unconfirmed
    assert not run.mutants[1].unconfirmed and box.spawns == spawns + 1
    t = run.tally
    assert (t.memory, t.unconfirmed, t.as_dict()["unconfirmed_memory"]) == (0, 1, 1)
    assert [f.kind for f in t.findings] == ["unconfirmed memory"] and not t.bad


@pytest.mark.realdata
def test_bag_with_a_lying_chunk_size_is_refused(box, tmp_path):
    bag = rf.DATA / "rgbd/realsense_bag/single_depth_color_640x480.bag"
    if not bag.is_file():
        pytest.skip(f"real data not available: {bag}")
    data = bytearray(bag.read_bytes())
    off, size, _ = next(w for w in rf.bag_words(bytes(data)) if w[2] == "top record 1 size")
    assert (size, struct.unpack_from("<I", data, off)[0]) == (4, 1_578_062)  # the real size
    data[off : off + 4] = struct.pack("<I", 0xFFFFFFFF)
    path = tmp_path / "lying_chunk_size.bag"
    path.write_bytes(bytes(data))
    out = box.run(rf.read_realsense, (str(path),), timeout=15.0)
    assert (out.kind, out.error) == ("typed", "FileFormatError"), out


def test_bag_whose_index_pos_points_into_a_chunk_is_refused_before_allocating(box, tmp_path):
    """The third full campaign's mutant 324 flipped a bit of the bag header's index_pos:
    rosbags jumped into a chunk and read its bytes as a 1.8 GiB header length. An
    index_pos that is not a record's start is a FileFormatError, within the bound."""
    bag = rf.DATA / "rgbd/realsense_bag/single_depth_color_640x480.bag"
    if not bag.is_file():
        pytest.skip(f"real data not available: {bag}")
    data = bytearray(bag.read_bytes())
    at = data.index(b"index_pos=") + len(b"index_pos=")
    index_pos = struct.unpack_from("<Q", data, at)[0]
    struct.pack_into("<Q", data, at, index_pos - 4096)  # inside the last chunk
    path = tmp_path / "index_pos_in_a_chunk.bag"
    path.write_bytes(bytes(data))
    out = box.run(rf.read_realsense, (str(path),), timeout=15.0)
    assert (out.kind, out.error) == ("typed", "FileFormatError"), out
    assert out.peak_mb < 16 and "index starts at byte" in out.message


# ------------------------------------------------------- issue 47's format-aware mutations


def test_json_value_is_a_function_of_its_rng_and_keeps_json():
    import json

    from tests.fuzz import loaders as lf

    data = json.dumps(
        {"images": [{"id": 1, "file_name": "rgb/a.png", "width": 9}], "items": [1, 2, 3]}
    ).encode()
    made = set()
    for k in range(60):
        a = lf.json_value(data, np.random.default_rng([7, k]), "json")
        assert a == lf.json_value(data, np.random.default_rng([7, k]), "json")
        made.add(a[0])
        if b"[" * 200 not in a[0] and b'{"a": ' * 200 not in a[0]:  # past json's recursion
            json.loads(a[0])
    assert len(made) > 25
    deep = [m for m in made if b"[" * 65 in m or b'{"a": ' * 65 in m]
    assert deep, "some mutants nest past MAX_NESTING (64)"
    # an input that is not JSON falls back to a byte or token mutation
    _, desc = lf.json_value(b"\xff{", np.random.default_rng(0), "json")
    assert "not JSON" in desc


def test_xml_and_yaml_mutations_reach_their_hostile_forms():
    from tests.fuzz import loaders as lf

    xml = (
        b'<?xml version="1.0"?>\n<opencv_storage>\n<K type_id="opencv-matrix"><rows>3</rows>'
        b"<cols>3</cols><dt>d</dt><data>1 0 0 0 1 0 0 0 1</data></K>\n</opencv_storage>\n"
    )
    descs = [lf.xml_hostile(xml, np.random.default_rng(k), "xml")[1] for k in range(80)]
    assert any("entity bomb" in d for d in descs) and any("external entity" in d for d in descs)
    assert any("nested" in d for d in descs) and any("mismatch" in d for d in descs)
    bomb = next(
        o
        for o, d in (lf.xml_hostile(xml, np.random.default_rng(k), "xml") for k in range(80))
        if "entity bomb" in d
    )
    assert bomb.startswith(b'<?xml version="1.0"?>\n<!DOCTYPE opencv_storage [')
    yml = b"%YAML:1.0\nimage_width: 640\nK: !!opencv-matrix\n   rows: 3\n   data: [1, 2]\n"
    ydescs = [lf.yaml_hostile(yml, np.random.default_rng(k), "yaml")[1] for k in range(60)]
    assert any("alias bomb" in d for d in ydescs) and any("python tag" in d for d in ydescs)


def test_path_escape_points_at_the_sentinels():
    from tests.fuzz import loaders as lf

    text = b"1.0 rgb/1.0.png 1.01 depth/1.01.png\n"
    outs = {lf.path_escape(text, np.random.default_rng(k), "list")[0] for k in range(40)}
    assert any(b"../sentinel_rgb.png" in o for o in outs)
    assert any(b"../../sentinel_depth.png" in o for o in outs)
    assert any(b"/etc/hostname" in o for o in outs)
    rgb = np.full((4, 5, 3), lf.SENTINEL_RGB, np.uint8)
    assert lf.is_sentinel(rgb) and lf.is_sentinel(rgb / np.float32(255))
    assert lf.is_sentinel(np.full((4, 5), lf.SENTINEL_DEPTH, np.uint16))
    assert not lf.is_sentinel(np.zeros((4, 5, 3), np.uint8))


def test_pt_content_rewrites_a_checkpoint_it_can_read_back(tmp_path):
    import io

    torch = pytest.importorskip("torch")
    from tests.fuzz import loaders as lf

    state = {
        "model": {"0.std": torch.ones(3), "1.weight": torch.zeros(2, 3)},
        "kind": "fcos",
        "settings": {"width": 8},
        "classes": ["a", "b"],
        "calibration": {"score_thresh": 0.5},
    }
    buf = io.BytesIO()
    torch.save(state, buf)
    data = buf.getvalue()
    descs = []
    for k in range(60):
        out, desc = lf.pt_content(data, np.random.default_rng(k), "pt")
        back = torch.load(io.BytesIO(out), weights_only=True)  # still a torch file
        assert isinstance(back, dict), desc
        descs.append(desc)
    assert any(d.startswith("settings[") for d in descs)
    assert any(d.startswith("kind 'fcos' ->") for d in descs)
    assert any("model['0.std'] = 0" in d for d in descs)
    assert any("nan" in d for d in descs) and any("removed" in d for d in descs)


def test_db3_with_a_schema_that_is_not_utf8_is_a_file_format_error(box):
    """Mutant 157 of seed 5 (random bytes in the SQLite schema; found by a readers rerun)
    made SQLite's integrity check raise UnicodeDecodeError; it is a FileFormatError."""
    reader = next(r for r in rf.READERS if r.name == "realsense-db3")
    run = rf.fuzz_reader(reader, box, n=158, seed=5, campaign=True)
    hit = next(m for m in run.mutants if m.index == 157)
    assert hit.outcome.kind in ("ok", "typed"), hit.outcome
    assert run.tally.untyped == 0
