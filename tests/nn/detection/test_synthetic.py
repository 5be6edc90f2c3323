"""Tests of robopercept.nn.detection.synthetic: the procedural shapes and the digit
sets, exact boxes and masks, seeded."""

from __future__ import annotations

import itertools
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.data.datasets import SHAPES, shape_masks  # noqa: E402
from robopercept.nn.data.textures import BACKGROUNDS  # noqa: E402
from robopercept.nn.detection.data import DetectionDataset, mask_to_box  # noqa: E402
from robopercept.nn.detection.synthetic import (  # noqa: E402
    digits_detection_set,
    procedural_detection_set,
    single_digit_set,
)


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


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call, message",
    [
        (
            lambda: shape_masks([4], [1], [1], [1], [0], (8, 8)),
            r"kinds must be integers in \[0, 3\]",
        ),
        (lambda: shape_masks([0, 1], [1], [1], [1], [0], (8, 8)), r"cx must have one value per"),
        (lambda: shape_masks([0], [1], [1], [0], [0], (8, 8)), r"r must be > 0"),
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
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()


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
