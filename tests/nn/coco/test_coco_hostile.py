"""Hostile COCO files and arguments (issue 47): deeply nested JSON (R31), results with
a null or malformed ``bbox`` and other fields (R46), RLE sizes and counts of the wrong
type or range (R51), and annotation folders whose image paths lead outside them (R43)
give typed errors naming the entry, never numpy's ValueError or a RecursionError."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco.dataset import coco_from_dict, read_coco_json
from robopercept.nn.coco.folders import read_annotations
from robopercept.nn.coco.results import read_coco_results, results_from_list
from robopercept.nn.coco.rle import (
    annotation_to_rle,
    polygon_to_rle,
    rle_area,
    rle_counts,
    rle_decode,
    rle_from_counts,
    rle_to_bbox,
)

DEEP = '{"images": ' + "[" * 100_000 + "]" * 100_000 + "}"


def _result(**fields):
    return {"image_id": 1, "category_id": 1, "bbox": [0, 0, 2, 2], "score": 0.5, **fields}


# --------------------------------------------------------------------------- R31


@pytest.mark.parametrize("reader", [read_coco_json, read_coco_results])
@pytest.mark.parametrize(
    "text", [DEEP, "[" * 100_000, '[{"bbox": ' + "[" * 5000 + "]" * 5000 + "}]"]
)
def test_deeply_nested_files_are_refused(tmp_path, reader, text):
    p = tmp_path / "deep.json"
    p.write_text(text)
    with pytest.raises(FileFormatError, match=r"deep\.json: nested more than 64 levels"):
        reader(p)


def test_a_deep_labelme_file_is_refused(tmp_path):
    (tmp_path / "a.json").write_text(json.dumps(_labelme_doc("a.png")))
    (tmp_path / "b.json").write_text('{"shapes": ' + "[" * 50_000 + "]" * 50_000 + "}")
    with pytest.raises(FileFormatError, match=r"b\.json: nested more than"):
        read_annotations(tmp_path)


# --------------------------------------------------------------------------- R46


@pytest.mark.parametrize(
    "bbox",
    [
        None,
        "0 0 2 2",
        [0, 0, 2],
        [0, 0, 2, 2, 2],
        [[0, 0], [2, 2]],
        [[0, 0, 2, 2]],
        [0, 0, 2, [2]],
        [True, 0, 2, 2],
        ["0", 0, 2, 2],
        {"x": 0},
        5,
        np.zeros((2, 2)),
    ],
)
def test_a_malformed_bbox_names_the_result(bbox):
    with pytest.raises(InputError, match=r"results \[1\]: bbox must be 4 numbers"):
        results_from_list([_result(), _result(bbox=bbox)])


@pytest.mark.parametrize(
    ("bbox", "match"),
    [
        ([0, 0, float("nan"), 2], "not finite"),
        ([float("inf"), 0, 2, 2], "not finite"),
        ([10**400, 0, 2, 2], "beyond 1e15"),
        ([1e300, 0, 2, 2], "beyond 1e15"),
        ([0, 0, -1, 2], "negative width"),
    ],
)
def test_out_of_range_boxes_name_the_result(bbox, match):
    with pytest.raises(InputError, match=rf"results \[0\]: bbox .*{match}"):
        results_from_list([_result(bbox=bbox)])


def test_a_null_bbox_in_a_file_names_the_file_and_the_entry(tmp_path):
    """The issue's case: numpy's "zero-size array" ValueError before."""
    p = tmp_path / "res.json"
    p.write_text(json.dumps([_result(), _result(bbox=None)]))
    with pytest.raises(FileFormatError, match=r"res\.json: results \[1\]: bbox must be 4"):
        read_coco_results(p)


def test_a_keypoint_result_with_a_null_bbox_is_refused():
    """Only a keypoint result *without* a bbox gets its keypoints' box (pycocotools)."""
    kp = [1, 2, 1, 3, 4, 1]
    assert results_from_list([_result(keypoints=kp) | {"bbox": [0, 0, 1, 1]}])
    no_box = {k: v for k, v in _result(keypoints=kp).items() if k != "bbox"}
    assert results_from_list([no_box]).boxes.tolist() == [[1.0, 2.0, 2.0, 2.0]]
    with pytest.raises(InputError, match=r"results \[0\]: bbox must be 4 numbers .*; got None"):
        results_from_list([_result(keypoints=kp, bbox=None)])


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"score": None}, r"results\[0\]\.score must be a number"),
        ({"score": "0.5"}, r"results\[0\]\.score must be a number"),
        ({"score": True}, r"results\[0\]\.score must be a number"),
        ({"score": 10**400}, r"results\[0\]\.score .* beyond float64"),
        ({"score": float("nan")}, "scores must be finite"),
        ({"category_id": None}, r"results\[0\]\.category_id must be an integer"),
        ({"category_id": 1.5}, r"results\[0\]\.category_id must be an integer"),
        ({"image_id": 2**70}, r"results\[0\]\.image_id must fit in 64 bits"),
        ({"segmentation": [[0, 0, 1, 0, 1, 1]]}, "must be an RLE dict"),
        ({"segmentation": {"size": 5, "counts": "4"}}, "size must be"),
        ({"segmentation": {"size": [2, 2], "counts": None}}, "counts"),
        ({"keypoints": "1 2 1"}, "keypoints must be a flat list"),
        ({"keypoints": [[1, 2, 1]]}, "keypoints must be a flat list"),
        ({"keypoints": [1, 2]}, "keypoints must be a flat list"),
        ({"keypoints": [1, 2, float("nan")]}, "NaN or inf"),
        ({"keypoints": [10**400, 2, 1]}, "keypoints must be a flat list"),
    ],
)
def test_other_malformed_result_fields_name_the_result(fields, match):
    with pytest.raises(InputError, match=match):
        results_from_list([_result(**fields)])


def _gt(**annotation):
    return {
        "images": [{"id": 1, "file_name": "a.png", "width": 8, "height": 8}],
        "categories": [{"id": 1, "name": "x"}],
        "annotations": [{"id": 1, "image_id": 1, "category_id": 1, "bbox": [0, 0, 2, 2]}]
        if not annotation
        else [{"id": 1, "image_id": 1, "category_id": 1, **annotation}],
    }


@pytest.mark.parametrize(
    ("annotation", "match"),
    [
        ({"bbox": None}, "annotation id 1: bbox must be 4 numbers"),
        ({"bbox": [[0, 0], [2, 2]]}, "annotation id 1: bbox must be 4 numbers"),
        ({"bbox": [0, 0, 2, 2], "area": 10**400}, "area must be a finite number"),
        ({"bbox": [0, 0, 2, 2], "iscrowd": 2}, "iscrowd must be 0 or 1"),
    ],
)
def test_malformed_ground_truth_names_the_annotation(annotation, match):
    with pytest.raises(InputError, match=match):
        coco_from_dict(_gt(**annotation))


def test_a_duplicate_id_among_many_is_named_quickly():
    gt = _gt()
    gt["images"] = [{"id": i, "file_name": "a", "width": 1, "height": 1} for i in range(50_000)]
    gt["images"].append({"id": 49_999, "file_name": "b", "width": 1, "height": 1})
    with pytest.raises(InputError, match="image id 49999 appears more than once"):
        coco_from_dict(gt)


# --------------------------------------------------------------------------- R51


@pytest.mark.parametrize(
    "size", [4, None, 1.5, True, "22", np.array(4), np.zeros((2, 2), int), [2], [2, 2, 1], {}]
)
def test_rle_from_counts_with_a_bad_size(size):
    with pytest.raises(InputError, match=r"counts: size must be \[height, width\]"):
        rle_from_counts([4], size)


def test_rle_from_counts_takes_a_tuple_list_or_array():
    for size in [(2, 2), [2, 2], np.array([2, 2])]:
        assert rle_from_counts([1, 3], size) == {"size": [2, 2], "counts": "13"}


@pytest.mark.parametrize(
    ("rle", "match"),
    [
        ({"size": np.array(3), "counts": [4]}, "size must be"),
        ({"size": [2, 2], "counts": "o" * 50}, "runs over 13 characters"),
        ({"size": [2, 2], "counts": "o" * 12 + "0"}, "a mask has at most 2\\^32 - 1 pixels"),
        # the int64 sum of these wraps round to 4: each run is checked first
        ({"size": [2, 2], "counts": [2**63 - 1, 2**63 - 1, 6]}, "one is 9223372036854775807"),
        ({"size": [2, 2], "counts": [2**62] * 4}, "must be >= 0 and add up to"),
        ({"size": [2, 2], "counts": [[1, 3]]}, "compressed string or a list of integers"),
        ({"size": [2, 2], "counts": [1.5, 2.5]}, "compressed string or a list of integers"),
        ({"size": [2, 2], "counts": {"a": 1}}, "compressed string or a list of integers"),
        ({"size": [2, 2], "counts": None}, "compressed string or a list of integers"),
        ({"size": [2, 2], "counts": b"\xff"}, "not a character"),
        ({"size": [2**40, 2**40], "counts": [1]}, "more than 2\\^32 - 1 pixels"),
    ],
)
@pytest.mark.parametrize("fn", [rle_counts, rle_decode, rle_area, rle_to_bbox])
def test_hostile_rles(fn, rle, match):
    with pytest.raises(InputError, match=match):
        fn(rle)


@pytest.mark.parametrize(
    ("polygon", "match"),
    [
        ([1e300] * 6, "within 1e\\+15 pixels"),
        ([0, 0, 1e16, 0, 0, 1], "within 1e\\+15 pixels"),
        ([10**400, 0, 1, 0, 0, 1], "at least 3 points"),
        ([[0, 0], [1, 0], [1, 1]], None),  # nested pairs are flattened (as before)
    ],
)
def test_polygons_far_out_are_refused(polygon, match):
    if match is None:
        assert polygon_to_rle(polygon, 4, 4)["size"] == [4, 4]
        return
    with pytest.raises(InputError, match=match):
        polygon_to_rle(polygon, 4, 4)
    with pytest.raises(InputError, match=match):
        annotation_to_rle([polygon], 4, 4)


# --------------------------------------------------------------------------- R43


def _labelme_doc(image_path: str) -> dict:
    return {
        "imagePath": image_path,
        "imageHeight": 8,
        "imageWidth": 10,
        "shapes": [{"label": "cat", "points": [[1, 2], [5, 6]], "shape_type": "rectangle"}],
    }


def _voc_xml(filename: str) -> str:
    return (
        f"<annotation><filename>{filename}</filename><size><width>10</width>"
        "<height>8</height></size><object><name>tree</name><bndbox><xmin>1</xmin>"
        "<ymin>2</ymin><xmax>5</xmax><ymax>6</ymax></bndbox></object></annotation>"
    )


@pytest.fixture
def outside(tmp_path):
    """A data folder ``data/`` and a secret image beside it, outside."""
    from robopercept.imaging import write_image

    (tmp_path / "data").mkdir()
    write_image(tmp_path / "secret.png", np.zeros((8, 10, 3), np.uint8))
    write_image(tmp_path / "data" / "a.png", np.zeros((8, 10, 3), np.uint8))
    return tmp_path


@pytest.mark.parametrize("form", ["labelme", "voc"])
@pytest.mark.parametrize("where", ["../secret.png", "ABS"])
def test_image_paths_outside_the_folder_are_refused(outside, form, where):
    data = outside / "data"
    name = str(outside / "secret.png") if where == "ABS" else where
    if form == "labelme":
        (data / "a.json").write_text(json.dumps(_labelme_doc(name)))
        entry = r"a\.json: imagePath"
    else:
        (data / "a.xml").write_text(_voc_xml(name))
        entry = r"a\.xml: <filename>"
    with pytest.raises(FileFormatError, match=rf"{entry} .* leads outside .*--allow-outside"):
        read_annotations(data)
    found = read_annotations(data, allow_outside=True)  # the option reads it
    assert (data / found.coco.images[0].file_name).resolve() == (outside / "secret.png")


def test_image_paths_inside_are_read_as_before(outside):
    data = outside / "data"
    (data / "a.json").write_text(json.dumps(_labelme_doc("./sub/../a.png")))
    assert read_annotations(data).coco.images[0].file_name == "a.png"


def test_allow_outside_must_be_a_bool(outside):
    with pytest.raises(InputError, match="allow_outside"):
        read_annotations(outside / "data", allow_outside="yes")


@pytest.mark.parametrize("iscrowd", [[[1], [1, 2]], [2], [-1], ["1"], [None], [0.5]])
def test_rle_iou_with_a_bad_iscrowd(iscrowd):
    from robopercept.nn.coco.rle import rle_encode, rle_iou

    r = rle_encode(np.eye(2))
    with pytest.raises(InputError, match="iscrowd must hold one 0/1 flag per ground truth"):
        rle_iou([r], [r, r] if len(iscrowd) == 2 else [r], iscrowd)
