"""Tests of robopercept.nn.detection.data: the detection record, the procedural, digit
and DeepForest sets, their COCO conversion and pictures."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError  # noqa: E402
from robopercept.nn.coco.formats import (  # noqa: E402
    evaluate_detections,
    read_voc_xml,
    results_from_ground_truth,
)
from robopercept.nn.data.datasets import SHAPES, shape_masks  # noqa: E402
from robopercept.nn.detection.data import (  # noqa: E402
    BACKGROUNDS,
    DEEPFOREST_IMAGES,
    DetectionDataset,
    FlipRotate,
    ScaleJitter,
    collate_detection,
    deepforest_tiles,
    digits_detection_set,
    draw_detections,
    mask_to_box,
    procedural_detection_set,
    samples_picture,
    single_digit_set,
)
from tests.conftest import data_path  # noqa: E402


@pytest.fixture(scope="module")
def shapes_set() -> DetectionDataset:
    return procedural_detection_set(24, (96, 80), rng=7, objects_per_image=(2, 5))


@pytest.fixture(scope="module")
def digits_set() -> DetectionDataset:
    return digits_detection_set(20, (96, 96), (2, 6), rng=3)


def tight_box(mask: np.ndarray) -> list[float]:
    """The oracle: the tight box by np.nonzero, edges on pixel borders."""
    rows, cols = np.nonzero(mask)
    return [cols.min(), rows.min(), cols.max() + 1.0, rows.max() + 1.0]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    iw = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    ih = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


# --------------------------------------------------------------------------- record


class TestRecord:
    def test_mask_to_box_hand_case(self):
        m = np.zeros((6, 7), bool)
        m[2, 3] = True  # one pixel: a 1 x 1 box
        assert mask_to_box(m).tolist() == [3.0, 2.0, 4.0, 3.0]
        m[4, 5] = True
        assert mask_to_box(m).tolist() == [3.0, 2.0, 6.0, 5.0]

    def test_item_matches_torchvision_layout(self):
        img = np.random.default_rng(0).uniform(0, 1, (5, 7, 3)).astype(np.float32)
        masks = np.zeros((2, 5, 7), bool)
        masks[0, 1:3, 1:4] = True
        masks[1, 4, 6] = True
        ds = DetectionDataset(
            [img], [[[1, 1, 4, 3], [6, 4, 7, 5]]], [[2, 1]], ["a", "b"], masks=[masks]
        )
        image, target = ds[0]
        assert image.dtype == torch.float32 and tuple(image.shape) == (3, 5, 7)
        assert torch.equal(image, torch.from_numpy(img).permute(2, 0, 1))
        assert target["boxes"].dtype == torch.float32
        assert target["boxes"].tolist() == [[1, 1, 4, 3], [6, 4, 7, 5]]
        assert target["labels"].dtype == torch.int64 and target["labels"].tolist() == [2, 1]
        assert target["masks"].dtype == torch.uint8 and tuple(target["masks"].shape) == (2, 5, 7)
        assert target["image_id"] == 1
        assert target["area"].tolist() == [6.0, 1.0]  # mask pixel counts
        assert target["iscrowd"].tolist() == [0, 0]
        assert ds[-1][1]["image_id"] == 1

    def test_without_masks_area_is_box_area_and_no_masks_key(self):
        ds = DetectionDataset([np.zeros((10, 10, 3))], [[[0, 0, 2, 5]]], [[1]], ["a"])
        _, target = ds[0]
        assert "masks" not in target and target["area"].tolist() == [10.0]

    def test_collate_and_dataloader(self, digits_set):
        loader = torch.utils.data.DataLoader(
            digits_set, batch_size=4, shuffle=False, collate_fn=collate_detection
        )
        images, targets = next(iter(loader))
        assert isinstance(images, list) and len(images) == 4 and len(targets) == 4
        for j in range(4):
            assert torch.equal(images[j], digits_set[j][0])
            assert torch.equal(targets[j]["boxes"], digits_set[j][1]["boxes"])

    def test_split_is_seeded_disjoint_and_covering(self, shapes_set):
        a = shapes_set.split((0.5, 0.25, 0.25), rng=1)
        b = shapes_set.split((0.5, 0.25, 0.25), rng=1)
        c = shapes_set.split((0.5, 0.25, 0.25), rng=2)
        ids = [p.image_ids for p in a]
        assert [len(p) for p in a] == [12, 6, 6]
        assert ids == [p.image_ids for p in b]
        assert ids != [p.image_ids for p in c]
        flat = sorted(itertools.chain.from_iterable(ids))
        assert flat == list(shapes_set.image_ids)
        # a subset keeps each image's boxes with it
        k = shapes_set.image_ids.index(ids[1][0])
        np.testing.assert_array_equal(a[1].boxes[0], shapes_set.boxes[k])

    def test_to_coco_self_evaluation_is_perfect(self, shapes_set, digits_set):
        for ds in (shapes_set, digits_set):
            gt = ds.to_coco()
            assert len(gt) == ds.n_boxes and len(gt.images) == len(ds)
            ev = evaluate_detections(gt, results_from_ground_truth(gt))
            assert ev.stats[0] == pytest.approx(1.0, abs=1e-12)  # AP
            assert ev.stats[1] == pytest.approx(1.0, abs=1e-12)  # AP50
            # and not trivially: shifting every box by half its width loses AP@.75
            res = results_from_ground_truth(gt)
            moved = res.boxes.copy()
            moved[:, 0] += moved[:, 2] / 2
            shifted = type(res)(res.image_ids, res.category_ids, moved, res.scores)
            assert evaluate_detections(gt, shifted).stats[2] < 0.2

    def test_to_coco_boxes_are_xywh(self):
        ds = DetectionDataset([np.zeros((9, 9, 3))], [[[1, 2, 4, 8]]], [[1]], ["a"])
        gt = ds.to_coco()
        assert gt.boxes.tolist() == [[1.0, 2.0, 3.0, 6.0]] and gt.areas.tolist() == [18.0]
        assert gt.category_names() == {1: "a"}


# --------------------------------------------------------------------------- procedural


class TestProcedural:
    def test_boxes_are_the_tight_boxes_of_the_masks(self, shapes_set):
        n = 0
        for boxes, masks in zip(shapes_set.boxes, shapes_set.masks, strict=True):
            for box, m in zip(boxes, masks, strict=True):
                assert m.any()
                assert box.tolist() == tight_box(m)  # exactly, no tolerance
                n += 1
        assert n == shapes_set.n_boxes > 48

    def test_visible_masks_are_disjoint_and_hold_the_object(self, shapes_set):
        for masks in shapes_set.masks:
            assert masks.sum(0).max() <= 1  # each pixel belongs to at most one object

    def test_classes_as_drawn(self, shapes_set):
        # each visible mask lies inside its labelled shape re-rendered from the recorded
        # geometry, covers >= min_visible (0.4) of it, and is not inside the other shapes
        seen = set()
        for labels, masks, meta, img in zip(
            shapes_set.labels, shapes_set.masks, shapes_set.meta, shapes_set.images, strict=True
        ):
            geo = meta["shapes"]
            h, w = img.shape[:2]
            for lab, m, (cx, cy, r, phi) in zip(labels, masks, geo, strict=True):
                kind = SHAPES.index(shapes_set.classes[lab - 1])
                full = shape_masks([0, 1, 2, 3], [cx] * 4, [cy] * 4, [r] * 4, [phi] * 4, (w, h))
                assert not (m & ~full[kind]).any()
                assert m.sum() >= 0.4 * full[kind].sum()
                # the labelled shape explains the mask better than any other shape
                fit = [(m & f).sum() / (m | f).sum() for f in full]
                if m.sum() == full[kind].sum():  # unoccluded: exactly its shape
                    assert np.array_equal(m, full[kind])
                    assert int(np.argmax(fit)) == kind
                seen.add(int(lab))
        assert seen == {1, 2, 3, 4}

    def test_occluded_boxes_shrink_to_the_visible_part(self, shapes_set):
        shrunk = 0
        for labels, boxes, masks, meta, img in zip(
            shapes_set.labels,
            shapes_set.boxes,
            shapes_set.masks,
            shapes_set.meta,
            shapes_set.images,
            strict=True,
        ):
            h, w = img.shape[:2]
            for lab, box, m, (cx, cy, r, phi) in zip(
                labels, boxes, masks, meta["shapes"], strict=True
            ):
                kind = SHAPES.index(shapes_set.classes[lab - 1])
                full = shape_masks([kind], [cx], [cy], [r], [phi], (w, h))[0]
                whole = np.array(tight_box(full))
                assert box[0] >= whole[0] and box[1] >= whole[1]
                assert box[2] <= whole[2] and box[3] <= whole[3]
                if not np.array_equal(box, whole):
                    shrunk += 1
                    assert box.tolist() == tight_box(m)
        assert shrunk >= 5  # occlusion happens, and boxes follow it

    def test_shape_masks_hand_cases(self):
        # a circle of radius 10 on pixel centres: its area is pi r^2 to within the
        # boundary pixels (2 pi r ~ 63); an axis-aligned square of half side 4 centred on
        # a pixel corner covers exactly 8 x 8 pixels; a cross of r = 8 is two 4 x 16 bars
        m = shape_masks(
            [0, 1, 3], [20.0] * 3, [20.0] * 3, [10.0, 4 * 2**0.5, 8.0], [0.0] * 3, (40, 40)
        )
        assert abs(int(m[0].sum()) - np.pi * 100) < 2 * np.pi * 10
        assert int(m[1].sum()) == 64 and m[1, 16:24, 16:24].all()
        assert int(m[2].sum()) == 2 * 4 * 16 - 4 * 4

    def test_hand_placed_occlusion(self):
        # a box of the visible part, not of the whole shape: the dataset's own record
        img = np.zeros((10, 10, 3))
        whole = np.zeros((10, 10), bool)
        whole[2:8, 2:8] = True
        visible = whole.copy()
        visible[:, 5:] = False  # the right half hidden by a later object
        assert mask_to_box(visible).tolist() == [2.0, 2.0, 5.0, 8.0]
        ds = DetectionDataset([img], [[mask_to_box(visible)]], [[1]], ["s"], masks=[[visible]])
        assert ds[0][1]["area"].tolist() == [18.0]

    def test_seeded_determinism(self):
        a = procedural_detection_set(4, (48, 48), rng=11)
        b = procedural_detection_set(4, (48, 48), rng=np.random.default_rng(11))
        c = procedural_detection_set(4, (48, 48), rng=12)
        for x, y in zip(a.images, b.images, strict=True):
            np.testing.assert_array_equal(x, y)
        for x, y in zip(a.boxes, b.boxes, strict=True):
            np.testing.assert_array_equal(x, y)
        assert not all(np.array_equal(x, y) for x, y in zip(a.images, c.images, strict=True))

    def test_backgrounds_are_bundled_photos(self):
        import skimage.data

        files = {
            "immunohistochemistry": "ihc.png",
            "hubble_deep_field": "hubble_deep_field.jpg",
            "rocket": "rocket.jpg",
        }
        folder = os.path.dirname(skimage.data.__file__)
        for name in BACKGROUNDS:
            assert os.path.isfile(os.path.join(folder, files.get(name, f"{name}.png"))), name
        # no objects, no clutter: the image is the contrast-reduced crop of the photo
        ds = procedural_detection_set(
            3, (40, 30), rng=0, objects_per_image=(0, 0), clutter=0, occlusion=0.0
        )
        for img, meta in zip(ds.images, ds.meta, strict=True):
            photo = np.asarray(getattr(skimage.data, meta["photo"])(), dtype=np.float64) / 255
            if photo.ndim == 2:
                photo = np.repeat(photo[..., None], 3, axis=2)
            x, y, w, h = meta["crop"]
            crop = photo[y : y + h, x : x + w]
            # a block mean of the crop down to 4 x 3 equals the image's (resizing is
            # linear and the 0.2 + 0.6 I map too; 0.03 covers the bilinear kernel's
            # leakage across block borders)
            bh, bw = crop.shape[0] // 3, crop.shape[1] // 4
            ih, iw = img.shape[0] // 3, img.shape[1] // 4
            for i in range(3):
                for j in range(4):
                    ref = 0.2 + 0.6 * crop[i * bh : (i + 1) * bh, j * bw : (j + 1) * bw].mean()
                    got = img[i * ih : (i + 1) * ih, j * iw : (j + 1) * iw].mean()
                    assert got == pytest.approx(ref, abs=0.03)

    def test_class_subset(self):
        ds = procedural_detection_set(6, (64, 64), ("triangle", "circle"), rng=0)
        assert ds.classes == ("triangle", "circle")
        assert set(np.concatenate(ds.labels).tolist()) <= {1, 2}


# --------------------------------------------------------------------------- digits


class TestDigits:
    def test_boxes_masks_labels_and_overlap(self, digits_set):
        from sklearn.datasets import load_digits

        target = load_digits().target
        for boxes, labels, masks, meta in zip(
            digits_set.boxes, digits_set.labels, digits_set.masks, digits_set.meta, strict=True
        ):
            assert 2 <= len(boxes) <= 6
            for box, m in zip(boxes, masks, strict=True):
                assert box.tolist() == tight_box(m)
            np.testing.assert_array_equal(labels, target[meta["digit_index"]] + 1)
            for a, b in itertools.combinations(boxes, 2):
                assert iou(a, b) <= 0.1 + 1e-12  # the stated max_iou

    def test_digits_are_real(self, digits_set):
        # the pixels of each digit's square, averaged down to 8 x 8, correlate with its
        # source digit: above 0.8 for every digit whose square meets no other square,
        # median above 0.9 over all (a neighbour's ink in the square lowers a few); and
        # much less with a random digit of another class (mean below 0.6)
        from skimage.transform import resize
        from sklearn.datasets import load_digits

        d = load_digits()
        rng = np.random.default_rng(0)
        own, clean, other = [], [], []
        for img, meta in zip(digits_set.images, digits_set.meta, strict=True):
            squares = [
                np.array([x, y, x + s, y + s], float)
                for s, (x, y) in zip(meta["side"], meta["origin"], strict=True)
            ]
            for k, (idx, sq) in enumerate(zip(meta["digit_index"], squares, strict=True)):
                x, y, x2, y2 = sq.astype(int)
                crop = img[y:y2, x:x2, 0].astype(np.float64)
                small = resize(crop, (8, 8), anti_aliasing=True).ravel()
                c = np.corrcoef(small, d.images[idx].ravel())[0, 1]
                own.append(c)
                if all(iou(sq, o) == 0 for j, o in enumerate(squares) if j != k):
                    clean.append(c)
                j = rng.choice(np.flatnonzero(d.target != d.target[idx]))
                other.append(np.corrcoef(small, d.images[j].ravel())[0, 1])
        assert len(clean) >= 20 and min(clean) > 0.8
        assert np.median(own) > 0.9
        assert np.mean(other) < 0.6

    def test_single_digit_set(self):
        ds = single_digit_set(10, (48, 48), rng=0, scale=(16, 40))
        assert [len(b) for b in ds.boxes] == [1] * 10
        sides = [m["side"][0] for m in ds.meta]
        assert min(sides) >= 16 and max(sides) <= 40
        for box, (x, y), s in zip(ds.boxes, (m["origin"][0] for m in ds.meta), sides, strict=True):
            assert x <= box[0, 0] and box[0, 2] <= x + s and y <= box[0, 1] and box[0, 3] <= y + s

    def test_seeded_determinism(self):
        a = digits_detection_set(5, (64, 64), rng=4)
        b = digits_detection_set(5, (64, 64), rng=4)
        c = digits_detection_set(5, (64, 64), rng=5)
        assert all(np.array_equal(x, y) for x, y in zip(a.images, b.images, strict=True))
        assert all(np.array_equal(x, y) for x, y in zip(a.boxes, b.boxes, strict=True))
        assert not all(np.array_equal(x, y) for x, y in zip(a.images, c.images, strict=True))


# --------------------------------------------------------------------------- DeepForest


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


def test_deepforest_missing_folder(tmp_path):
    with pytest.raises(InputError, match=r"DeepForest folder .*nowhere.* does not exist"):
        deepforest_tiles(tmp_path / "nowhere")
    with pytest.raises(FileFormatError):
        deepforest_tiles(tmp_path)  # exists but holds no files


# --------------------------------------------------------------------------- pictures


def test_draw_detections_and_samples_picture(digits_set):
    img = np.zeros((40, 40, 3), np.float32)
    out = draw_detections(img, [[5, 20, 15, 35]], [3], ["a", "b", "c"], scores=[0.5])
    from robopercept.viz.colormap import label_colors

    colour = label_colors(np.array([3]))[0]
    np.testing.assert_array_equal(out[34, 14], colour)  # the box's bottom-right pixel
    np.testing.assert_array_equal(out[27, 10], 0)  # inside: untouched
    pic = samples_picture(digits_set, [0, 1, 2], columns=2)
    assert pic.shape == (2 * 96 + 2, 2 * 96 + 2, 3)
    assert (pic[96:98] == 255).all()  # the white gap


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: mask_to_box(np.zeros((3, 3))), r"mask is empty"),
        (
            lambda: shape_masks([4], [1], [1], [1], [0], (8, 8)),
            r"kinds must be integers in \[0, 3\]",
        ),
        (lambda: shape_masks([0, 1], [1], [1], [1], [0], (8, 8)), r"cx must have one value per"),
        (lambda: shape_masks([0], [1], [1], [0], [0], (8, 8)), r"r must be > 0"),
        (lambda: mask_to_box(np.zeros(3)), r"mask must be \(H, W\)"),
        (
            lambda: DetectionDataset([np.zeros((3, 8, 8))], [[]], [[]], ["a"]),
            r"channels-first\? use image.transpose\(1, 2, 0\)",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3), np.uint8)], [[]], [[]], ["a"]),
            r"floating point in \[0, 1\].*to_unit_float",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3))], [[[0, 0, 9, 4]]], [[1]], ["a"]),
            r"inside the 8 x 8 image.*np.clip",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3))], [[[4, 0, 2, 4]]], [[1]], ["a"]),
            r"x1 <= x2",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3))], [[[0, 0, np.nan, 4]]], [[1]], ["a"]),
            r"must be finite",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3))], [[[0, 0, 2, 4]]], [[0]], ["a"]),
            r"integers in \[1, 1\] \(1-based; 0 is background\)",
        ),
        (
            lambda: DetectionDataset([np.zeros((8, 8, 3))], [[]], [[]], []),
            r"classes must be a non-empty list",
        ),
        (
            lambda: DetectionDataset(
                [np.zeros((8, 8, 3))], [[[0, 0, 2, 4]]], [[1]], ["a"], masks=[np.zeros((8, 8))]
            ),
            r"masks\[0\] must be \(K, H, W\)",
        ),
        (
            lambda: DetectionDataset(
                [np.zeros((8, 8, 3))] * 2, [[]] * 2, [[]] * 2, ["a"], image_ids=[3, 3]
            ),
            r"image_ids must be distinct",
        ),
        (lambda: DetectionDataset([np.zeros((8, 8, 3))], [[]], [[]], ["a"])[1], r"out of range"),
        (lambda: collate_detection([]), r"non-empty list of \(image, target\) pairs"),
        (lambda: collate_detection([(1, 2)]), r"batch\[0\] must be an \(image tensor"),
        (lambda: procedural_detection_set(0), r"n_images must be >= 1"),
        (lambda: procedural_detection_set(2, classes=("hexagon",)), r"names from \('circle'"),
        (lambda: procedural_detection_set(2, (8, 8)), r"size must be \(width, height\)"),
        (lambda: procedural_detection_set(2, rng=-1), r"rng must be an int seed >= 0"),
        (lambda: procedural_detection_set(2, min_visible=0.0), r"min_visible must be"),
        (lambda: procedural_detection_set(2, scale=(0.3, 0.1)), r"scale must be a \(low, high\)"),
        (lambda: procedural_detection_set(10**9), r"lower n_images"),
        (lambda: digits_detection_set(2, (32, 32)), r"scale must be a \(low, high\) pair"),
        (lambda: digits_detection_set(2, max_iou=2.0), r"max_iou must be"),
        (lambda: single_digit_set(1.5), r"n_images must be an integer"),
        (
            lambda: draw_detections(np.zeros((8, 8)), [[0, 0, 4, 4]], scores=[1, 2]),
            r"scores must have one value per box",
        ),
        (lambda: samples_picture([1, 2]), r"dataset must be a DetectionDataset"),
        (lambda: deepforest_tiles(".", tile=10), r"tile must be >= 64"),
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()


# --------------------------------------------------------------------------- FlipRotate
def _tight(mask: torch.Tensor) -> list[float]:
    ys, xs = torch.nonzero(mask, as_tuple=True)
    return [float(xs.min()), float(ys.min()), float(xs.max() + 1), float(ys.max() + 1)]


@pytest.mark.parametrize(
    ("kw", "seed"),
    [({"horizontal": 1.0}, 0), ({"horizontal": 0.0, "vertical": 1.0}, 0)]
    + [({"horizontal": 0.5, "vertical": 0.5, "rotate90": True}, s) for s in range(12)],
)
def test_flip_rotate_moves_boxes_and_masks_with_the_pixels(kw, seed):
    # a non-square image with two lit rectangles: after any transform, each box must be
    # the tight box of its lit pixels, and the mask must be those pixels
    h, w = 12, 20
    image = torch.zeros(3, h, w)
    rects = [(2, 1, 7, 4), (11, 5, 19, 12)]  # xyxy, pixel edges
    masks = torch.zeros(2, h, w, dtype=torch.uint8)
    for k, (x1, y1, x2, y2) in enumerate(rects):
        image[k, y1:y2, x1:x2] = 1.0
        masks[k, y1:y2, x1:x2] = 1
    target = {"boxes": torch.tensor(rects, dtype=torch.float32), "masks": masks, "labels": 7}
    out_im, out_t = FlipRotate(**kw, generator=seed)(image, target)
    assert out_t["labels"] == 7 and sorted(out_im.shape[1:]) == [h, w]
    for k in range(2):
        assert out_t["boxes"][k].tolist() == _tight(out_im[k] > 0)
        assert torch.equal(out_t["masks"][k].bool(), out_im[k] > 0)
    assert torch.equal(target["boxes"], torch.tensor(rects, dtype=torch.float32))  # not in place


def test_flip_rotate_is_seeded_and_draws_every_turn():
    image = torch.arange(12.0).reshape(1, 3, 4)
    t = {"boxes": torch.zeros(0, 4)}
    runs = []
    for _ in range(2):
        f = FlipRotate(0.5, 0.5, True, generator=3)
        runs.append([f(image, t)[0] for _ in range(40)])
    assert all(torch.equal(x, y) for x, y in zip(*runs, strict=True))
    # 8 distinct outcomes of the dihedral group on an asymmetric image
    assert len({tuple(x.flatten().tolist()) + tuple(x.shape) for x in runs[0]}) == 8


# --------------------------------------------------------------------------- ScaleJitter
def test_scale_jitter_hand_case_zoom_in_and_out():
    # scale exactly 2 on a 10x10 image: the box (4,4)-(6,6) becomes 4 px wide at
    # 2 * 4 - o; scale exactly 0.5 on 20x20: the box halves and moves by the pad offset
    box = {"boxes": torch.tensor([[4.0, 4, 6, 6]])}
    kept = []
    for seed in range(5):
        # min_visible 1: the box is kept only whole, then exactly 4 x 4
        im, t = ScaleJitter((2.0, 2.0), 1.0, generator=seed)(torch.zeros(3, 10, 10), box)
        assert im.shape == (3, 10, 10)
        for x1, y1, x2, y2 in t["boxes"].tolist():
            assert (x2 - x1, y2 - y1) == (4.0, 4.0)
            assert 0 <= 8 - x1 <= 10 and 0 <= 8 - y1 <= 10  # offsets within 0..sW - W
            kept.append(seed)
        big = {"boxes": torch.tensor([[4.0, 8, 12, 16]])}
        im, t = ScaleJitter((0.5, 0.5), fill=0.25, generator=seed)(torch.ones(1, 20, 20), big)
        x1, y1, x2, y2 = t["boxes"][0].tolist()
        assert (x2 - x1, y2 - y1) == (4.0, 4.0)
        ox, oy = x1 - 2.0, y1 - 4.0  # the pad offset: where the 10x10 image went
        assert im[0, int(oy) : int(oy) + 10, int(ox) : int(ox) + 10].eq(1).all()
        assert im.sum() == 100 + 0.25 * 300
    assert kept  # some offsets keep the whole box


@pytest.mark.parametrize("seed", range(10))
def test_scale_jitter_moves_boxes_and_masks_with_the_pixels(seed):
    # two lit rectangles; after the zoom each kept box must be the tight box of its
    # lit pixels within the bilinear resampling's one pixel, and its mask those pixels
    h, w = 40, 56
    image = torch.zeros(2, h, w)
    rects = [(6, 4, 22, 16), (30, 20, 50, 36)]
    masks = torch.zeros(2, h, w, dtype=torch.uint8)
    for k, (x1, y1, x2, y2) in enumerate(rects):
        image[k, y1:y2, x1:x2] = 1.0
        masks[k, y1:y2, x1:x2] = 1
    target = {
        "boxes": torch.tensor(rects, dtype=torch.float32),
        "labels": torch.tensor([3, 5]),
        "masks": masks,
        "image_id": 9,
    }
    out_im, out_t = ScaleJitter((0.6, 1.6), min_visible=0.0, generator=seed)(image, target)
    assert out_im.shape == image.shape and out_t["image_id"] == 9
    kept = out_t["labels"].tolist()
    assert len(out_t["boxes"]) == len(kept) == len(out_t["masks"])
    for j, label in enumerate(kept):
        k = [3, 5].index(label)
        lit = out_im[k] > 0.5
        got = out_t["boxes"][j]
        assert torch.allclose(got, torch.tensor(_tight(lit)), atol=1.0), (got, _tight(lit))
        # nearest-neighbour mask and bilinear image agree but on the edge pixels
        assert (out_t["masks"][j].bool() ^ lit).sum() <= 2 * (h + w)
    assert torch.equal(target["boxes"], torch.tensor(rects, dtype=torch.float32))


def test_scale_jitter_drops_boxes_that_leave_the_image_with_their_fields():
    # at 3x only a 1/9 of the image stays: a corner box in the far corner is cut off
    # whatever the offset, the per-box fields follow, and min_visible decides the rest
    image = torch.zeros(3, 30, 30)
    target = {"boxes": torch.tensor([[0.0, 0, 4, 4], [26.0, 26, 30, 30]]),
              "labels": torch.tensor([1, 2])}  # fmt: skip
    counts = set()
    for seed in range(20):
        _, t = ScaleJitter((3.0, 3.0), min_visible=0.5, generator=seed)(image, target)
        assert len(t["boxes"]) == len(t["labels"]) <= 1
        counts.add(len(t["boxes"]))
    assert counts <= {0, 1}
    _, t = ScaleJitter((3.0, 3.0), min_visible=1.0, generator=0)(image, target)
    area = (t["boxes"][:, 2] - t["boxes"][:, 0]) * (t["boxes"][:, 3] - t["boxes"][:, 1])
    assert torch.all(area == 144.0)  # only whole boxes: 12 x 12


def test_scale_jitter_is_seeded_and_log_uniform():
    image = torch.rand(3, 16, 16, generator=torch.Generator().manual_seed(0))
    t = {"boxes": torch.zeros(0, 4)}
    a = [ScaleJitter((0.5, 2.0), generator=4)(image, t)[0] for _ in range(1)]
    b = [ScaleJitter((0.5, 2.0), generator=4)(image, t)[0] for _ in range(1)]
    assert torch.equal(a[0], b[0])
    j = ScaleJitter((0.25, 4.0), generator=1)
    zoomed_in = sum(
        j(torch.ones(1, 8, 8), t)[0].gt(0.999).all().item() for _ in range(400)
    )  # s >= 1 leaves no padding: P = 1/2 when log-uniform
    assert 160 < zoomed_in < 240


@pytest.mark.parametrize(
    ("kw", "args", "msg"),
    [
        ({"scale": (0.0, 1.0)}, None, "scale low"),
        ({"scale": (1.5, 1.0)}, None, "scale high"),
        ({"scale": 1.2}, None, "pair"),
        ({"min_visible": 2.0}, None, "min_visible"),
        ({}, (torch.zeros(8, 8), {"boxes": torch.zeros(0, 4)}), "(C, H, W)"),
        ({}, (torch.zeros(3, 8, 8, dtype=torch.uint8), {"boxes": torch.zeros(0, 4)}), "floating"),
        ({}, (torch.zeros(3, 8, 8), {"labels": 1}), "'boxes'"),
    ],
)
def test_scale_jitter_bad_input(kw, args, msg):
    with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        ScaleJitter(**kw)(*args)


@pytest.mark.parametrize(
    ("kw", "args", "msg"),
    [
        ({"horizontal": 1.5}, None, "horizontal"),
        ({"rotate90": "yes"}, None, "rotate90"),
        ({}, (torch.zeros(8, 8), {"boxes": torch.zeros(0, 4)}), "(C, H, W)"),
        ({}, (torch.zeros(3, 8, 8), {"labels": 1}), "'boxes'"),
    ],
)
def test_flip_rotate_bad_input(kw, args, msg):
    with pytest.raises(InputError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        f = FlipRotate(**kw)
        f(*args)


def test_class_maps_of_the_procedural_set_label_each_visible_object():
    # the semantic ground truth of the shapes: pixel (r, c) has class k exactly where a
    # visible mask of a class-k object covers it (masks are the visible parts, so they
    # do not overlap), 0 elsewhere
    ds = procedural_detection_set(4, (64, 64), rng=3)
    maps = ds.class_maps()
    assert maps.shape == (4, 64, 64) and maps.dtype == np.int64
    for i in range(4):
        m, lab = ds.masks[i], ds.labels[i]
        assert int(m.sum(0).max()) <= 1  # no overlap
        expect = (m * lab[:, None, None]).sum(0)
        np.testing.assert_array_equal(maps[i], expect)
        assert set(np.unique(maps[i])) <= {0, *lab.tolist()}
