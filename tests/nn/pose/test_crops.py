"""Top-down crops of a COCO keypoint file (robopercept.nn.pose.crops): the window's
arithmetic by hand, keypoints landing on the pixels they marked, the real COCO persons."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("torch")

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import write_image
from robopercept.nn.pose.crops import crop_window, pose_set_from_coco
from robopercept.nn.skeleton import COCO_17
from tests.conftest import data_path


def _file(tmp_path, photo, anns, keypoints=("a", "b")):
    write_image(tmp_path / "a.png", photo)
    h, w = photo.shape[:2]
    doc = {
        "images": [{"id": 1, "file_name": "a.png", "width": w, "height": h}],
        "categories": [{"id": 1, "name": "person", "keypoints": list(keypoints),
                        "skeleton": [[1, 2]]}],
        "annotations": [{"id": k + 1, "image_id": 1, "category_id": 1, **a}
                        for k, a in enumerate(anns)],
    }  # fmt: skip
    (tmp_path / "gt.json").write_text(json.dumps(doc))
    return tmp_path / "gt.json"


def test_window_by_hand():
    # a 40 x 20 box into a 64 x 32 crop: already the crop's aspect 2:1, 1.25 margin
    c, s = crop_window([0, 0, 40, 20], (64, 32))
    assert c.tolist() == [20.0, 10.0] and s == pytest.approx(50 / 64)
    # a tall box widens to the crop's aspect: w' = h W / H = 30
    c, s = crop_window([5, 5, 10, 30], (32, 32), padding=1.0)
    assert c.tolist() == [10.0, 20.0] and s == pytest.approx(30 / 32)
    with pytest.raises(InputError, match="w, h > 0"):
        crop_window([0, 0, 0, 5], (32, 32))
    with pytest.raises(InputError, match="padding"):
        crop_window([0, 0, 5, 5], (32, 32), padding=0.5)


def test_keypoints_land_on_the_pixels_they_mark(tmp_path):
    """Two Gaussian dots (sigma 2.5 px) in a dark photo, labelled at their centres: in
    the crop (1.76 photo pixels per crop pixel) each keypoint lies within 0.15 crop pixel
    of its dot's intensity centroid (bilinear resampling keeps a smooth dot's centroid;
    a half-pixel slip of the map would move it by 0.3 to 0.5)."""
    yy, xx = np.mgrid[0:120, 0:160] + 0.5  # pixel centres, continuous coordinates
    dots = [(50.5, 40.5), (90.5, 95.5)]
    glow = sum(np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * 2.5**2)) for x, y in dots)
    photo = np.repeat((255 * glow)[..., None], 3, axis=2).astype(np.uint8)
    kp = [v for x, y in dots for v in (x, y, 2)]
    gt = _file(tmp_path, photo, [{"bbox": [30, 20, 80, 90], "keypoints": kp}])
    ds = pose_set_from_coco(gt, size=(64, 64))
    assert len(ds) == 1 and ds.images.shape == (1, 64, 64, 3)
    crop = ds.images[0].mean(2)
    for j in range(2):
        u, v = ds.keypoints[0, j, :2]
        y0, x0 = int(v) - 3, int(u) - 3
        patch = crop[y0 : y0 + 7, x0 : x0 + 7]
        yy, xx = np.mgrid[0:7, 0:7] + 0.5  # pixel centres, continuous
        cx = x0 + (patch * xx).sum() / patch.sum()
        cy = y0 + (patch * yy).sum() / patch.sum()
        assert abs(cx - u) < 0.15 and abs(cy - v) < 0.15
    # the box's corners move by the same map: its centre is the crop's
    b = ds.boxes[0]
    assert np.allclose([(b[0] + b[2]) / 2, (b[1] + b[3]) / 2], [32, 32])


def test_who_is_a_sample_and_bad_files(tmp_path):
    photo = np.zeros((40, 40, 3), np.uint8)
    anns = [
        {"bbox": [5, 5, 20, 20], "keypoints": [10, 10, 2, 0, 0, 0], "num_keypoints": 1},
        {"bbox": [5, 5, 20, 20], "keypoints": [0, 0, 0, 0, 0, 0], "num_keypoints": 0},
        {"bbox": [5, 5, 20, 20], "keypoints": [10, 10, 2, 0, 0, 0], "iscrowd": 1},
    ]
    ds = pose_set_from_coco(_file(tmp_path, photo, anns), size=(32, 32))
    assert len(ds) == 1 and ds.keypoints[0, 1].tolist() == [0.0, 0.0, 0.0]
    assert np.isnan(ds.joints3d).all()
    gt = _file(tmp_path, photo, anns[1:2])
    with pytest.raises(InputError, match="no person with a labelled keypoint"):
        pose_set_from_coco(gt)
    with pytest.raises(InputError, match="does not exist"):
        pose_set_from_coco(tmp_path / "none.json")
    (tmp_path / "a.png").unlink()
    gt = _file(tmp_path, photo, anns[:1])
    (tmp_path / "a.png").unlink()
    with pytest.raises(InputError, match=r"--images-dir: .*a\.png"):
        pose_set_from_coco(gt)
    doc = json.loads(gt.read_text())
    doc["categories"][0].pop("keypoints")
    gt.write_text(json.dumps(doc))
    with pytest.raises((InputError, FileFormatError), match="keypoints"):
        pose_set_from_coco(gt)


@pytest.mark.realdata
def test_the_coco_persons():
    """mmpose's COCO val2017 sample: 14 persons, 12 with labelled keypoints, COCO's 17
    joints with its sigmas and flip pairs; every labelled keypoint inside its crop
    (the 1.25 margin holds the box, and the keypoints lie in the box)."""
    gt = data_path("detection", "coco_keypoints_mmpose", "test_coco.json")
    ds = pose_set_from_coco(gt, size=(96, 128))
    assert len(ds) == 12 and ds.images.shape == (12, 128, 96, 3)
    assert ds.skeleton.joints == COCO_17.joints
    assert np.allclose(ds.skeleton.sigmas, COCO_17.sigmas)
    assert set(ds.skeleton.flip_pairs) == set(COCO_17.flip_pairs)
    lab = ds.keypoints[..., 2] > 0
    xy = ds.keypoints[..., :2][lab]
    assert (xy >= 0).all() and (xy[:, 0] <= 96).all() and (xy[:, 1] <= 128).all()
    assert lab.sum() == 17 + 14 + 15 + 15 + 15 + 12 + 17 + 16 + 16 + 15 + 16 + 13
