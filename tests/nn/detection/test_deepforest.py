"""Tests of robopercept.nn.detection.deepforest: the DeepForest NEON tree crowns as
tiles with a held-out strip."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.coco.evaluate import evaluate_detections  # noqa: E402
from robopercept.nn.coco.results import results_from_ground_truth  # noqa: E402
from robopercept.nn.coco.voc import read_voc_xml  # noqa: E402
from robopercept.nn.detection.deepforest import DEEPFOREST_IMAGES, deepforest_tiles  # noqa: E402
from tests.conftest import data_path  # noqa: E402


@pytest.mark.realdata
def test_deepforest_tiles_counts_and_content():
    from PIL import Image

    folder = data_path("detection", "deepforest_neon")
    out = deepforest_tiles(folder, 400, test_fraction=0.2, min_area_fraction=0.5)
    stem = DEEPFOREST_IMAGES[0]
    full = np.asarray(Image.open(folder / f"{stem}.png").convert("RGB"))
    h, w = full.shape[:2]
    assert (w, h) == (2299, 2472) and out.strip_top == 2472 - 495
    src = [o.bbox for o in read_voc_xml(folder / f"{stem}.xml").objects]
    assert len(src) == out.n_source_boxes == 574
    # tiles: a partition of the image, train above the strip, test inside it, pixels as
    # in the file
    covered = np.zeros((h, w), np.int64)
    tiles = []
    for ds, is_test in ((out.train, False), (out.test, True)):
        for img, meta in zip(ds.images, ds.meta, strict=True):
            x, y = meta["origin"]
            th, tw = img.shape[:2]
            covered[y : y + th, x : x + tw] += 1
            assert (y >= out.strip_top) if is_test else (y + th <= out.strip_top)
            np.testing.assert_array_equal(np.round(img * 255), full[y : y + th, x : x + tw])
            tiles.append((x, y, tw, th))
    assert (covered == 1).all()
    # the clipping rule, computed box by box in plain Python
    expected = dropped = 0
    for x0, y0, x1, y1 in src:
        area = (x1 - x0) * (y1 - y0)
        for x, y, tw, th in tiles:
            iw = min(x1, x + tw) - max(x0, x)
            ih = min(y1, y + th) - max(y0, y)
            if iw > 0 and ih > 0:
                if iw * ih >= 0.5 * area:
                    expected += 1
                else:
                    dropped += 1
    assert out.train.n_boxes + out.test.n_boxes == expected
    assert out.n_dropped == dropped and 0 < dropped < 574
    assert out.test.n_boxes > 50 and out.train.n_boxes > 300
    for ds in (out.train, out.test):
        for img, b in zip(ds.images, ds.boxes, strict=True):
            assert (b[:, 2] > b[:, 0]).all() and (b[:, 3] > b[:, 1]).all()
            assert b[:, 2].max(initial=0) <= img.shape[1]
    counts = {k: v.n_boxes for k, v in out.cross.items()}
    assert counts == {DEEPFOREST_IMAGES[1]: 279, "OSBS_029": 61, "SOAP_061": 37}
    gt = out.test.to_coco()
    assert evaluate_detections(gt, results_from_ground_truth(gt)).stats[1] == pytest.approx(1)


def write_voc(path, w, h, boxes):
    objs = "".join(
        f"<object><name>Tree</name><bndbox><xmin>{a}</xmin><ymin>{b}</ymin><xmax>{c}</xmax>"
        f"<ymax>{d}</ymax></bndbox></object>"
        for a, b, c, d in boxes
    )
    path.write_text(
        f"<annotation><filename>{path.stem}.png</filename><size><width>{w}</width>"
        f"<height>{h}</height><depth>3</depth></size>{objs}</annotation>"
    )


def test_deepforest_tiles_hand_case(tmp_path):
    # a 200 x 100 image, tile 64, test_fraction 0.2: strip_top = 100 - 20 = 80; train
    # tiles in rows [0, 64) and [64, 80), test tiles in [80, 100); columns at 0, 64, 128, 192
    from robopercept.imaging import write_image

    rng = np.random.default_rng(0)
    big = rng.integers(0, 256, (100, 200, 3), dtype=np.uint8)
    boxes = [
        (50, 10, 90, 30),  # split at x = 64: 14 / 40 wide (dropped), 26 / 40 kept
        (130, 70, 150, 90),  # split at y = 80 (the strip): 10 / 20 each, both kept (>= 0.5)
        (0, 0, 10, 10),  # inside one tile
    ]
    for k, stem in enumerate(DEEPFOREST_IMAGES):
        write_image(tmp_path / f"{stem}.png", big if k == 0 else big[:40, :50])
        write_voc(tmp_path / f"{stem}.xml", *((200, 100) if k == 0 else (50, 40)), boxes[2:])
    write_voc(tmp_path / f"{DEEPFOREST_IMAGES[0]}.xml", 200, 100, boxes)
    out = deepforest_tiles(tmp_path, 64, test_fraction=0.2, min_area_fraction=0.5)
    assert out.strip_top == 80 and out.n_dropped == 1
    origins = {m["origin"]: (ds, i) for ds in (out.train, out.test) for i, m in enumerate(ds.meta)}
    assert sorted(origins) == sorted((x, y) for y in (0, 64, 80) for x in (0, 64, 128, 192))
    assert [m["origin"][1] for m in out.test.meta] == [80] * 4
    found = {o: ds.boxes[i].tolist() for o, (ds, i) in origins.items() if len(ds.boxes[i])}
    assert found == {
        (0, 0): [[0.0, 0.0, 10.0, 10.0]],
        (64, 0): [[0.0, 10.0, 26.0, 30.0]],
        (128, 64): [[2.0, 6.0, 22.0, 16.0]],
        (128, 80): [[2.0, 0.0, 22.0, 10.0]],
    }
    ds, i = origins[(128, 64)]
    np.testing.assert_array_equal(np.round(ds.images[i] * 255), big[64:80, 128:192])
    assert {k: len(v) for k, v in out.cross.items()} == {s: 1 for s in DEEPFOREST_IMAGES[1:]}
    # train_extra: the 50 x 40 YELL crop is cut into tiles 64 wide -> one tile (0, 0) of
    # 50 x 40 holding its box, appended to the training tiles and gone from the cross sets
    more = deepforest_tiles(tmp_path, 64, test_fraction=0.2, train_extra=(DEEPFOREST_IMAGES[1],))
    assert len(more.train) == len(out.train) + 1 and len(more.test) == len(out.test)
    assert sorted(more.cross) == sorted(DEEPFOREST_IMAGES[2:])
    assert more.train.meta[-1] == {"source": DEEPFOREST_IMAGES[1], "origin": (0, 0)}
    assert more.train.boxes[-1].tolist() == [[0.0, 0.0, 10.0, 10.0]]
    np.testing.assert_array_equal(np.round(more.train.images[-1] * 255), big[:40, :50])
    for ds, extra in ((more.train, out.train), (more.test, out.test)):
        for a, b in zip(ds.images[: len(extra)], extra.images, strict=True):
            np.testing.assert_array_equal(a, b)


def test_deepforest_missing_folder(tmp_path):
    with pytest.raises(InputError, match=r"DeepForest folder .*nowhere.* does not exist"):
        deepforest_tiles(tmp_path / "nowhere")
    with pytest.raises(FileFormatError):
        deepforest_tiles(tmp_path)  # exists but holds no files


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: deepforest_tiles(".", tile=10), r"tile must be >= 64"),
        (
            lambda: deepforest_tiles(".", train_extra=(DEEPFOREST_IMAGES[0],)),
            r"train_extra must name other DeepForest images",
        ),
        (
            lambda: deepforest_tiles(".", train_extra=("OSBS_029", "OSBS_029")),
            r"each once",
        ),
        (lambda: deepforest_tiles(".", train_extra="OSBS_029"), r"must be a tuple of"),
        (lambda: deepforest_tiles(".", train_extra=([1],)), r"must name other"),
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()
