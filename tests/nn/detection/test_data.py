"""Tests of robopercept.nn.detection.data: the detection record, its COCO conversion,
batching and the samples picture."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.coco.evaluate import evaluate_detections  # noqa: E402
from robopercept.nn.coco.results import results_from_ground_truth  # noqa: E402
from robopercept.nn.detection.data import (  # noqa: E402
    DetectionDataset,
    check_classes,
    collate_detection,
    mask_to_box,
    samples_picture,
)
from robopercept.nn.detection.synthetic import (  # noqa: E402
    digits_detection_set,
    procedural_detection_set,
)


@pytest.fixture(scope="module")
def shapes_set() -> DetectionDataset:
    return procedural_detection_set(24, (96, 80), rng=7, objects_per_image=(2, 5))


@pytest.fixture(scope="module")
def digits_set() -> DetectionDataset:
    return digits_detection_set(20, (96, 96), (2, 6), rng=3)


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

    def test_check_classes(self):
        assert check_classes(["cat", "dog"]) == ("cat", "dog")
        for bad, msg in (([], "non-empty list"), (["a", ""], "non-empty strings"),
                         (("a", "a"), "distinct"), ("ab", "non-empty list")):  # fmt: skip
            with pytest.raises(InputError, match=msg):
                check_classes(bad)

    def test_to_coco_boxes_are_xywh(self):
        ds = DetectionDataset([np.zeros((9, 9, 3))], [[[1, 2, 4, 8]]], [[1]], ["a"])
        gt = ds.to_coco()
        assert gt.boxes.tolist() == [[1.0, 2.0, 3.0, 6.0]] and gt.areas.tolist() == [18.0]
        assert gt.category_names() == {1: "a"}


# --------------------------------------------------------------------------- pictures


def test_samples_picture(digits_set):
    pic = samples_picture(digits_set, [0, 1, 2], columns=2)
    assert pic.shape == (2 * 96 + 2, 2 * 96 + 2, 3)
    assert (pic[96:98] == 255).all()  # the white gap


# --------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: mask_to_box(np.zeros((3, 3))), r"mask is empty"),
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
        (lambda: samples_picture([1, 2]), r"dataset must be a DetectionDataset"),
    ],
)
def test_bad_input(call, message):
    with pytest.raises(InputError, match=message):
        call()


# --------------------------------------------------------------------------- from_coco


def _coco_folder(tmp_path, ds: DetectionDataset, images: bool = True):
    """``ds`` written as a COCO file ``gt.json`` with PNG images beside it."""
    from robopercept.imaging import write_image
    from robopercept.nn.coco.dataset import write_coco_json

    coco = ds.to_coco()
    if images:
        for im, rec in zip(ds.images, coco.images, strict=True):
            write_image(tmp_path / rec.file_name, (np.asarray(im) * 255).round().astype(np.uint8))
    return write_coco_json(coco, tmp_path / "gt.json")


def test_from_coco_round_trip(tmp_path, shapes_set):
    ds = shapes_set.subset([0, 1, 2])
    back = DetectionDataset.from_coco(_coco_folder(tmp_path, ds))
    assert back.classes == ds.classes and back.image_ids == ds.image_ids
    assert back.file_names == ds.file_names
    for a, b in zip(back.boxes, ds.boxes, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-9)
    for a, b in zip(back.labels, ds.labels, strict=True):
        assert a.tolist() == b.tolist()
    for a, b in zip(back.images, ds.images, strict=True):
        np.testing.assert_allclose(a, b, atol=0.5 / 255 + 1e-6)  # uint8 round trip


def test_from_coco_labels_are_category_positions_and_crowds_dropped(tmp_path):
    import json

    from robopercept.imaging import write_image

    write_image(tmp_path / "a.png", np.zeros((10, 12, 3), np.uint8))
    gt = {
        "images": [{"id": 5, "file_name": "a.png", "width": 12, "height": 10}],
        "categories": [{"id": 9, "name": "x"}, {"id": 2, "name": "y"}],
        "annotations": [
            {"id": 1, "image_id": 5, "category_id": 2, "bbox": [1, 1, 2, 3], "iscrowd": 0},
            {"id": 2, "image_id": 5, "category_id": 9, "bbox": [0, 0, 4, 4], "iscrowd": 1},
            {"id": 3, "image_id": 5, "category_id": 9, "bbox": [5, 2, 3, 3], "iscrowd": 0},
        ],
    }
    (tmp_path / "sub").mkdir()
    f = tmp_path / "sub" / "gt.json"
    f.write_text(json.dumps(gt))
    ds = DetectionDataset.from_coco(f, images_dir=tmp_path)
    assert ds.classes == ("x", "y") and ds.image_ids == (5,)
    assert ds.labels[0].tolist() == [2, 1]
    assert ds.boxes[0].tolist() == [[1, 1, 3, 4], [5, 2, 8, 5]]


def test_from_coco_errors_name_the_flags(tmp_path, shapes_set):
    import json

    with pytest.raises(InputError, match=r"--data: COCO file .* does not exist"):
        DetectionDataset.from_coco(tmp_path / "none.json")
    f = tmp_path / "empty.json"
    f.write_text(json.dumps({"images": [], "categories": [], "annotations": []}))
    with pytest.raises(InputError, match=r"--images-dir: .* is not a folder"):
        DetectionDataset.from_coco(f, images_dir=tmp_path / "no")
    with pytest.raises(InputError, match=r"--data .*: lists no images"):
        DetectionDataset.from_coco(f)
    g = _coco_folder(tmp_path, shapes_set.subset([0]), images=False)
    with pytest.raises(InputError, match=r"--images-dir: .*000001.png \(image 1 of .*\) does not"):
        DetectionDataset.from_coco(g)


def test_from_coco_masks_peak_about_what_it_returns(tmp_path):
    """E1-F1: the masks were decoded into a list, stacked, then copied to float64 by the
    constructor's check: a peak of several times the returned masks. They are now
    filled into one bool array that the set keeps."""
    import json
    import tracemalloc

    from robopercept.imaging import write_image

    h, w, k = 200, 300, 40
    write_image(tmp_path / "a.png", np.zeros((h, w, 3), np.uint8))
    anns = [
        {"id": j + 1, "image_id": 1, "category_id": 1, "bbox": [j, j, 100, 100], "iscrowd": 0,
         "area": 1e4, "segmentation": [[j, j, j + 100, j, j + 100, j + 100, j, j + 100]]}
        for j in range(k)
    ]  # fmt: skip
    gt = {
        "images": [{"id": 1, "file_name": "a.png", "width": w, "height": h}],
        "categories": [{"id": 1, "name": "x"}],
        "annotations": anns,
    }
    f = tmp_path / "gt.json"
    f.write_text(json.dumps(gt))
    tracemalloc.start()
    try:
        ds = DetectionDataset.from_coco(f, masks=True)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert ds.masks is not None and ds.masks[0].shape == (k, h, w)
    assert ds.masks[0].dtype == bool and ds.masks[0][:, 50, 50].all()
    returned = ds.masks[0].nbytes + ds.images[0].nbytes
    assert peak < returned + 2 * 2**20, (peak / 2**20, returned / 2**20)
