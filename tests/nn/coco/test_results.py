"""COCO results (robopercept.nn.coco.results): the check against the ground truth that
the evaluations use (round trips and parsing errors are in ``test_dataset.py``)."""

from __future__ import annotations

import pytest

from robopercept.errors import InputError
from robopercept.nn.coco.dataset import coco_from_dict
from robopercept.nn.coco.results import CocoResults, as_coco_results, results_from_list
from tests.nn.coco.test_evaluate import det, one_image


def test_as_coco_results_checks_ids_against_the_ground_truth():
    gt = coco_from_dict(one_image([{"bbox": [0, 0, 10, 10]}]))
    res = as_coco_results([det([0, 0, 1, 1], 0.5)], gt)
    assert isinstance(res, CocoResults) and res.scores.tolist() == [0.5]
    same = results_from_list([det([0, 0, 1, 1], 0.5)])
    assert as_coco_results(same, gt) is same
    with pytest.raises(InputError, match="image_id 9, which the ground truth does not"):
        as_coco_results([det([0, 0, 1, 1], 0.5, img=9)], gt)
    with pytest.raises(InputError, match="category_id 3"):
        as_coco_results([det([0, 0, 1, 1], 0.5, cat=3)], gt)
    with pytest.raises(InputError, match="results must be CocoResults"):
        as_coco_results("results.json", gt)
    with pytest.raises(InputError, match="gt must be a CocoDataset"):
        as_coco_results([], {"images": []})
