"""COCO run-length encoded masks (issue 27): equal to ``pycocotools.mask`` on random
masks and polygons (empty and full masks included), hand-computed cases, and refusals."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.nn.coco import rle as rle_module
from robopercept.nn.coco.rle import (
    annotation_to_rle,
    polygon_to_rle,
    rle_area,
    rle_counts,
    rle_decode,
    rle_encode,
    rle_from_counts,
    rle_iou,
    rle_merge,
    rle_to_bbox,
)

M = pytest.importorskip("pycocotools.mask")
# pycocotools' decode warns under NumPy 2 (its __array__ lacks the copy keyword)
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def _masks(rng: np.random.Generator, n: int):
    """Random masks of 1 to 60 px a side: noise of random density, empty, full, one
    rectangle (so long runs across columns) in turn."""
    for i in range(n):
        h, w = (int(v) for v in rng.integers(1, 60, 2))
        kind = i % 4
        if kind == 0:
            yield (rng.random((h, w)) < rng.random()).astype(np.uint8)
        elif kind == 1:
            yield np.zeros((h, w), np.uint8)
        elif kind == 2:
            yield np.ones((h, w), np.uint8)
        else:
            m = np.zeros((h, w), np.uint8)
            y, x = rng.integers(0, h), rng.integers(0, w)
            m[y : y + rng.integers(1, 20), x : x + rng.integers(1, 20)] = 1
            yield m


def test_hand_computed_runs_and_string():
    # column-major: the 2 x 2 mask [[0, 1], [1, 1]] reads 0, 1, 1, 1: runs 1, 3
    m = np.array([[0, 1], [1, 1]], np.uint8)
    assert rle_encode(m) == {"size": [2, 2], "counts": "13"}
    # a first pixel that is set starts with a zero-length run of zeros
    r = rle_encode(np.array([[1, 0], [1, 0]]))
    assert rle_counts(r)[1].tolist() == [0, 2, 2]
    # runs 0, 1, 4, 1, 4, 1, 1: from the 4th on, each is stored as the difference with
    # the one two before (0, 0, 0, 1 - 4 = -3); -3 is the 5-bit group 11101 (sign bit
    # 0x10 set) -> chr(48 + 29) = 'M'
    eye = np.eye(4, 3, dtype=np.uint8)
    assert rle_encode(eye)["counts"] == "014000M"
    assert rle_counts(rle_encode(eye))[1].tolist() == [0, 1, 4, 1, 4, 1, 1]
    # a count of 40 needs two groups: 40 = 0b01000_01000 -> (8 | 0x20) + 48 = 'X', 1 + 48
    assert rle_from_counts([40, 0], (40, 1))["counts"] == "X10"
    assert rle_area(rle_encode(eye)) == 3
    assert rle_to_bbox(rle_encode(eye)).tolist() == [0.0, 0.0, 3.0, 3.0]
    assert rle_to_bbox(rle_encode(np.zeros((3, 3)))).tolist() == [0.0, 0.0, 0.0, 0.0]


def test_encode_decode_area_bbox_equal_pycocotools():
    rng = np.random.default_rng(0)
    for m in _masks(rng, 200):
        ref = M.encode(np.asfortranarray(m))
        ours = rle_encode(m)
        assert ours["counts"] == ref["counts"].decode() and ours["size"] == ref["size"]
        assert np.array_equal(rle_decode(ours), m)
        assert np.array_equal(rle_decode(ref), M.decode(ref))  # reads their bytes too
        assert rle_area(ours) == M.area(ref)
        np.testing.assert_array_equal(rle_to_bbox(ours), M.toBbox(ref))
    # stacks (h, w, n) give lists, and lists decode to stacks
    stack = np.dstack([np.eye(3), np.ones((3, 3)), np.zeros((3, 3))]).astype(np.uint8)
    rles = rle_encode(stack)
    assert [r["counts"] for r in rles] == [
        r["counts"].decode() for r in M.encode(np.asfortranarray(stack))
    ]
    np.testing.assert_array_equal(rle_decode(rles), stack)
    assert rle_area([rle_encode(np.eye(3)), rle_encode(np.ones((3, 3)))]).tolist() == [3, 9]


def test_iou_and_merge_equal_pycocotools_with_crowds():
    rng = np.random.default_rng(1)
    for _ in range(40):
        h, w = (int(v) for v in rng.integers(1, 40, 2))
        ds = [(rng.random((h, w)) < 0.3).astype(np.uint8) for _ in range(3)]
        gs = [(rng.random((h, w)) < 0.5).astype(np.uint8) for _ in range(4)]
        gs[0][:] = 0  # an empty ground truth: IoU 0, not NaN
        crowd = rng.integers(0, 2, 4)
        rd = [M.encode(np.asfortranarray(d)) for d in ds]
        rg = [M.encode(np.asfortranarray(g)) for g in gs]
        ref = M.iou(rd, rg, crowd.astype(np.uint8).tolist())
        ours = rle_iou([rle_encode(d) for d in ds], [rle_encode(g) for g in gs], crowd)
        # both divide the same two integers: equal to the last bit
        np.testing.assert_array_equal(ours, ref)
        for inter in (False, True):
            a = M.merge(rd, intersect=int(inter))
            b = rle_merge([rle_encode(d) for d in ds], intersect=inter)
            assert b["counts"] == a["counts"].decode()
    assert rle_iou([], [rle_encode(np.eye(2))]).shape == (0, 1)


def _polygons(rng: np.random.Generator, n: int):
    for i in range(n):
        h, w = (int(v) for v in rng.integers(1, 120, 2))
        k = int(rng.integers(3, 20))
        mode = i % 4
        if mode == 0:  # anywhere, partly outside the image
            p = np.column_stack([rng.uniform(-10, w + 10, k), rng.uniform(-10, h + 10, k)])
        elif mode == 1:  # on pixel corners and half-pixels, where rounding ties
            p = np.column_stack([rng.integers(0, 2 * w + 1, k), rng.integers(0, 2 * h + 1, k)]) / 2
        elif mode == 2:  # a star-shaped outline
            t = np.sort(rng.uniform(0, 2 * np.pi, k))
            r = rng.uniform(0.2, 0.5) * min(h, w)
            p = np.column_stack([w / 2 + r * np.cos(t), h / 2 + r * np.sin(t)])
        else:  # repeated and collinear points
            p = np.array([[1.0, 1.0], [1.0, 1.0], [3.0, 3.0], [5.0, 5.0], [1.0, 4.0]])
        yield p.ravel(), h, w


def test_polygon_rasterization_equals_pycocotools():
    rng = np.random.default_rng(2)
    for poly, h, w in _polygons(rng, 400):
        ref = M.frPyObjects([poly.tolist()], h, w)[0]
        assert polygon_to_rle(poly, h, w)["counts"] == ref["counts"].decode()
    # a list of polygons is their union, as COCO's annToRLE
    a, b = [0.0, 0, 4, 0, 4, 4], [6.0, 6, 9, 6, 9, 9, 6, 9]
    ref = M.merge(M.frPyObjects([a, b], 10, 12))
    assert annotation_to_rle([a, b], 10, 12)["counts"] == ref["counts"].decode()
    # an uncompressed RLE in an annotation: compressed, same runs
    runs = [3, 4, 5, 108]
    ref = M.frPyObjects({"size": [10, 12], "counts": runs}, 10, 12)
    assert annotation_to_rle({"size": [10, 12], "counts": runs}, 10, 12)["counts"] == (
        ref["counts"].decode()
    )
    assert rle_from_counts(runs, (10, 12))["counts"] == ref["counts"].decode()


def test_edges_are_traced_in_pieces_with_the_same_result(monkeypatch):
    # pieces of 7 points put piece boundaries inside the image on every edge
    monkeypatch.setattr(rle_module, "_TRACE_PIECE", 7)
    rng = np.random.default_rng(3)
    for poly, h, w in _polygons(rng, 200):
        ref = M.frPyObjects([poly.tolist()], h, w)[0]
        assert polygon_to_rle(poly, h, w)["counts"] == ref["counts"].decode()


def test_points_far_outside_the_image_rasterize_in_bounded_memory():
    # fuzz finding: a duplicated byte range in a LabelMe file made one vertex x = 212,766
    # on a 500 px image; the 5x trace of its edges (2 M points, 16 bytes each, and
    # temporaries) took 150 MiB. Traced in pieces, memory stays near the piece size.
    rng = np.random.default_rng(4)
    for _ in range(6):
        h, w = (int(v) for v in rng.integers(20, 90, 2))
        p = np.column_stack([rng.uniform(0, w, 5), rng.uniform(0, h, 5)])
        p[rng.integers(5)] = rng.choice([-1, 1], 2) * rng.uniform(1e5, 2.5e5, 2)
        ref = M.frPyObjects([p.ravel().tolist()], h, w)[0]
        tracemalloc.start()
        try:
            ours = polygon_to_rle(p.ravel(), h, w)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert ours["counts"] == ref["counts"].decode()
        # a piece is 65,536 points: its int64 arrays and temporaries take ~5 MiB; the
        # whole trace (over 5e5 points per edge here) would take over 40 MiB
        assert peak < 12 * 2**20, peak / 2**20


def test_a_square_covers_the_pixels_whose_centres_it_holds():
    # the square (1, 1)-(4, 4) holds the centres (1.5 ... 3.5): pixels 1 to 3
    m = rle_decode(polygon_to_rle([1, 1, 4, 1, 4, 4, 1, 4], 6, 6))
    want = np.zeros((6, 6), np.uint8)
    want[1:4, 1:4] = 1
    np.testing.assert_array_equal(m, want)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: polygon_to_rle([0, 0, 1, 1], 4, 4), "at least 3 points"),
        (lambda: polygon_to_rle([0, 0, 1, 1, 2], 4, 4), "at least 3 points"),
        (lambda: polygon_to_rle([0, 0, 1, np.nan, 2, 2], 4, 4), "finite"),
        (lambda: polygon_to_rle("abc", 4, 4), "at least 3 points"),
        (lambda: polygon_to_rle([0, 0, 1e9, 0, 0, 1], 4, 4), "far outside"),
        (lambda: rle_decode({"size": [2, 2], "counts": [1, 2]}), "add up to"),
        (lambda: rle_decode({"size": [2, 2], "counts": [5, -1]}), ">= 0"),
        (lambda: rle_decode({"size": [2, 2], "counts": "1 "}), "not a character"),
        (lambda: rle_decode({"size": [2, 2], "counts": "X"}), "ends inside"),
        (lambda: rle_decode({"size": [2], "counts": "4"}), "size must be"),
        (lambda: rle_decode({"counts": "4"}), "'size'"),
        (lambda: rle_decode([]), "empty list"),
        (lambda: rle_encode(np.zeros(4)), r"\(h, w\)"),
        (lambda: rle_encode(np.array([[np.nan]])), "NaN"),
        (lambda: rle_iou([rle_encode(np.eye(2))], [rle_encode(np.eye(3))]), "3 x 3"),
        (lambda: rle_iou([rle_encode(np.eye(2))], [rle_encode(np.eye(2))], [1, 0]), "iscrowd"),
        (lambda: rle_merge([]), "at least one"),
        (lambda: rle_area(3), "list of COCO RLE"),
        (lambda: rle_iou({"size": [1, 1], "counts": "1"}, []), "dt must be a list"),
        (lambda: annotation_to_rle({"size": [2, 2], "counts": "4"}, 3, 3), "2 x 2"),
        (lambda: annotation_to_rle([], 3, 3), "list of polygons"),
    ],
)
def test_bad_input_is_refused_clearly(call, match):
    with pytest.raises(InputError, match=match):
        call()


@pytest.mark.realdata
def test_real_labelme_coco_polygons_match_pycocotools_and_the_voc_instance_pngs():
    import json

    from pycocotools.coco import COCO

    from robopercept.imaging import read_image
    from tests.conftest import data_path

    root = data_path("detection", "labelme_voc_instances")
    path = root / "coco" / "annotations.json"
    data = json.loads(path.read_text())
    ref = COCO(str(path))
    images = {i["id"]: i for i in data["images"]}
    assert len(data["annotations"]) == 12
    for ann in data["annotations"]:
        im = images[ann["image_id"]]
        ours = rle_decode(annotation_to_rle(ann["segmentation"], im["height"], im["width"]))
        # exactly pycocotools' rasterization (the one with four polygons included)
        np.testing.assert_array_equal(ours, ref.annToMask(ann))
        # labelme drew the same polygons into the VOC instance PNG with PIL's rule
        # (boundary pixels in): one instance there overlaps it at IoU >= 0.93
        png = im["file_name"].split("/")[-1].replace(".jpg", ".png")
        obj = read_image(root / "voc" / "SegmentationObject" / png, mode="index")
        m = ours > 0
        best = max(
            (m & (obj == k)).sum() / (m | (obj == k)).sum() for k in range(1, int(obj.max()) + 1)
        )
        assert best >= 0.93, (ann["id"], best)


def test_vectorized_counts_string_reading_equals_the_character_loop():
    """The numpy reading of a counts string gives the runs, or the error message, of
    the character-by-character reading (``rleFrString`` as written) on 6,000 strings:
    encodings of random runs up to 2^31 (7-character numbers), random characters of
    the alphabet, characters around it, and numbers of 11 to 14 groups (the longest
    the vectorized path takes is 11; longer ones and errors go to the loop)."""
    from robopercept.nn.coco.rle import _decompress, _decompress_loop

    def read(f, s):
        try:
            return f(s, "rle").tolist()
        except InputError as exc:
            return str(exc)

    rng = np.random.default_rng(5)
    for i in range(6000):
        kind = i % 4
        if kind == 0:
            n = int(rng.integers(0, 30))
            top = min(int(rng.choice([5, 300, 2**20, 2**31])), 2**32 // max(n, 1) - 1)
            runs = [int(v) for v in rng.integers(0, top, n)]
            s = rle_from_counts(runs, (1, sum(runs)))["counts"] if runs else ""
        elif kind == 1:
            s = "".join(chr(48 + int(c)) for c in rng.integers(0, 64, rng.integers(0, 40)))
        elif kind == 2:
            s = "".join(chr(int(c)) for c in rng.integers(40, 120, rng.integers(0, 20)))
        else:
            body = rng.choice([32, 33, 47, 63], rng.integers(10, 14))
            s = "".join(chr(48 + int(c)) for c in body) + chr(48 + int(rng.integers(0, 32)))
        assert read(_decompress, s) == read(_decompress_loop, s), s


def test_large_masks_decode_as_pycocotools_writes_them():
    """Long runs (a 1500 x 1200 mask of a few rectangles: numbers of 5 to 7
    characters) read back equal to pycocotools' own decoding of its bytes."""
    m = np.zeros((1500, 1200), np.uint8)
    m[100:1400, 50:60] = 1
    m[700:701, :] = 1
    m[1499, 1199] = 1
    ref = M.encode(np.asfortranarray(m))
    np.testing.assert_array_equal(rle_decode(ref), M.decode(ref))
    np.testing.assert_array_equal(
        rle_decode({"size": ref["size"], "counts": ref["counts"].decode()}), m
    )
