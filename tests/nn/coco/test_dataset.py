"""COCO ground truth and results files (robopercept.nn.coco.dataset, robopercept.nn.coco.results):
parsing with errors that name the annotation, round trips, defaults, real COCO files."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from benchmarks.coco_eval import synthetic_detections
from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco.dataset import (
    as_coco_dataset,
    coco_from_dict,
    coco_to_dict,
    read_coco_json,
    write_coco_json,
)
from robopercept.nn.coco.results import (
    read_coco_results,
    results_from_list,
    results_to_list,
    write_coco_results,
)
from tests.conftest import data_path
from tests.nn.coco.test_evaluate import assert_self_evaluation_perfect, one_image


class TestBadInput:
    def test_dataset_errors_name_the_annotation(self):
        d = one_image([{"bbox": [0, 0, 10, 10]}])
        bad = copy.deepcopy(d)
        del bad["annotations"][0]["bbox"]
        with pytest.raises(InputError, match="annotation id 1 has no 'bbox' field"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["annotations"][0]["category_id"] = 5
        with pytest.raises(InputError, match="category_id 5, which is not in the 'categories'"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["annotations"][0]["bbox"] = [0, 0, float("nan"), 1]
        with pytest.raises(InputError, match=r"annotation id 1: bbox .* is not finite"):
            coco_from_dict(bad)
        bad["annotations"][0]["bbox"] = [10, 10, 5, -5]
        with pytest.raises(InputError, match=r"negative width or height.*not \[x1, y1"):
            coco_from_dict(bad)
        bad["annotations"][0]["bbox"] = [10, 10, 5]
        with pytest.raises(InputError, match="bbox must be 4 numbers"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        del bad["images"]
        with pytest.raises(InputError, match="no 'images' list"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["annotations"].append(dict(bad["annotations"][0]))
        with pytest.raises(InputError, match="annotation id 1 appears more than once"):
            coco_from_dict(bad)

    def test_hostile_numbers(self):
        d = one_image([{"bbox": [0, 0, 10, 10]}])
        bad = copy.deepcopy(d)
        bad["annotations"][0]["bbox"] = [0, 0, 1e300, 1]
        with pytest.raises(InputError, match="beyond 1e15 pixels"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["annotations"][0]["id"] = 2**70
        with pytest.raises(InputError, match="must fit in 64 bits"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["annotations"][0]["iscrowd"] = [1]
        with pytest.raises(InputError, match="iscrowd must be 0 or 1"):
            coco_from_dict(bad)
        bad = copy.deepcopy(d)
        bad["images"][0]["id"] = "1"
        with pytest.raises(InputError, match=r"images\[0\]\.id must be an integer; got '1'"):
            coco_from_dict(bad)

    def test_bad_files(self, tmp_path):
        p = tmp_path / "gt.json"
        d = one_image([{"bbox": [0, 0, float("nan"), 10]}])
        p.write_text(json.dumps(d))  # json writes NaN, as Python's json reads it
        with pytest.raises(FileFormatError, match=r"gt\.json: annotation id 1: bbox"):
            read_coco_json(p)
        p.write_text("{not json")
        with pytest.raises(FileFormatError, match="not valid JSON"):
            read_coco_json(p)
        with pytest.raises(FileFormatError, match="no such file"):
            read_coco_json(tmp_path / "missing.json")
        p.write_text(json.dumps([{"image_id": 1, "category_id": 1, "bbox": [0, 0, 1, 1]}]))
        with pytest.raises(FileFormatError, match=r"results\[0\] has no 'score' field"):
            read_coco_results(p)


class TestFormats:
    def test_round_trip(self, tmp_path):
        gt, res = synthetic_detections(3, n_images=8)
        ds = coco_from_dict(gt)
        back = read_coco_json(write_coco_json(ds, tmp_path / "sub" / "gt.json"))
        for name in ("ann_ids", "image_ids", "category_ids", "boxes", "areas", "iscrowd"):
            np.testing.assert_array_equal(getattr(back, name), getattr(ds, name))
        assert back.images == ds.images and back.categories == ds.categories
        assert coco_to_dict(back)["annotations"] == coco_to_dict(ds)["annotations"]
        r = results_from_list(res)
        r2 = read_coco_results(write_coco_results(r, tmp_path / "res.json"))
        assert results_to_list(r2) == results_to_list(r)
        assert results_to_list(r2)[0] == res[0]  # the same numbers come back
        assert not ds.boxes.flags.writeable and not r.scores.flags.writeable

    def test_defaults_for_area_and_iscrowd(self):
        ds = coco_from_dict(one_image([{"bbox": [0, 0, 4, 5]}]))
        assert ds.areas.tolist() == [20.0] and ds.iscrowd.tolist() == [False]

    def test_as_coco_dataset(self):
        d = one_image([{"bbox": [0, 0, 4, 5]}])
        ds = as_coco_dataset(d)
        assert as_coco_dataset(ds) is ds and len(ds) == 1
        with pytest.raises(InputError, match="gt must be a CocoDataset or a COCO dict"):
            as_coco_dataset([1, 2])


@pytest.mark.realdata
def test_coco_json_files():
    kp = read_coco_json(data_path("detection", "coco_keypoints_mmpose", "test_coco.json"))
    assert len(kp.images) == 4 and len(kp) == 14 and kp.category_names() == {1: "person"}
    assert_self_evaluation_perfect(kp)
    lm = read_coco_json(data_path("detection", "labelme_voc_instances", "coco", "annotations.json"))
    assert len(lm.images) == 3 and len(lm) == 12 and len(lm.categories) == 21
    # labelme numbers annotations from 0, which pycocotools takes for "unmatched":
    # ours only (the difference the module docstring states)
    assert 0 in lm.ann_ids.tolist()
    assert_self_evaluation_perfect(lm, with_pycocotools=False)
