"""Annotation files that name images outside the data set's folder (issue 47, R43):
``DetectionDataset.from_coco`` / ``from_annotations`` (``nn detect|segment train|eval
--data``) and ``pose_set_from_coco`` (``nn pose``) refuse a COCO ``file_name`` with
``..`` above the images' folder or an absolute path, naming the entry and the option
that allows it, and read it with ``allow_outside=True``."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import write_image
from robopercept.nn.detection.data import DetectionDataset
from robopercept.nn.pose.crops import pose_set_from_coco


def _coco(folder, file_name: str) -> None:
    doc = {
        "images": [{"id": 7, "file_name": file_name, "width": 10, "height": 8}],
        "categories": [{"id": 1, "name": "person", "keypoints": ["a", "b"]}],
        "annotations": [
            {"id": 1, "image_id": 7, "category_id": 1, "bbox": [1, 1, 6, 5],
             "keypoints": [2, 2, 2, 4, 4, 2], "segmentation": [[1, 1, 6, 1, 6, 5]]}
        ],
    }  # fmt: skip
    (folder / "gt.json").write_text(json.dumps(doc))


@pytest.fixture
def layout(tmp_path):
    """``data/gt.json`` and an image ``secret.png`` outside ``data/``."""
    data = tmp_path / "data"
    data.mkdir()
    secret = np.full((8, 10, 3), 200, np.uint8)
    write_image(tmp_path / "secret.png", secret)
    return data, tmp_path / "secret.png"


def _readers():
    return {
        "from_coco": lambda p, **kw: DetectionDataset.from_coco(p, **kw),
        "from_annotations": lambda p, **kw: DetectionDataset.from_annotations(p, **kw),
        "masks": lambda p, **kw: DetectionDataset.from_annotations(p, masks=True, **kw),
        "pose": lambda p, **kw: pose_set_from_coco(p, size=(32, 32), **kw),
    }


@pytest.mark.parametrize("reader", ["from_coco", "from_annotations", "masks", "pose"])
@pytest.mark.parametrize("where", ["../secret.png", "../data/../secret.png", "ABS"])
def test_a_file_name_outside_is_refused_and_allowed_on_request(layout, reader, where):
    data, secret = layout
    _coco(data, str(secret) if where == "ABS" else where)
    read = _readers()[reader]
    with pytest.raises(FileFormatError) as err:
        read(data / "gt.json")
    msg = str(err.value)
    assert "gt.json: image 7 file_name" in msg and "leads outside" in msg
    assert "--allow-outside-paths" in msg and "allow_outside=True" in msg
    got = read(data / "gt.json", allow_outside=True)
    assert len(got) == 1


def test_images_dir_is_the_folder_that_contains(layout, tmp_path):
    """With ``images_dir`` the names are relative to it, and must stay in it."""
    data, _ = layout
    write_image(data / "a.png", np.zeros((8, 10, 3), np.uint8))
    _coco(tmp_path, "a.png")  # gt.json beside secret.png, images in data/
    assert len(DetectionDataset.from_coco(tmp_path / "gt.json", images_dir=data)) == 1
    _coco(tmp_path, "../secret.png")
    with pytest.raises(FileFormatError, match="leads outside"):
        DetectionDataset.from_coco(tmp_path / "gt.json", images_dir=data)


def test_a_name_inside_reads_as_before(layout):
    data, _ = layout
    (data / "img").mkdir()
    write_image(data / "img" / "a.png", np.zeros((8, 10, 3), np.uint8))
    _coco(data, "img/../img/a.png")
    assert DetectionDataset.from_coco(data / "gt.json").file_names == ("img/../img/a.png",)


@pytest.mark.parametrize("reader", ["from_coco", "from_annotations", "pose"])
def test_allow_outside_must_be_a_bool(layout, reader):
    data, _ = layout
    _coco(data, "a.png")
    with pytest.raises(InputError, match="allow_outside"):
        _readers()[reader](data / "gt.json", allow_outside=1)
