"""Segmentation data (issue 27): the real nuclei image split into quadrants, the
percentile normalisation, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import read_image, write_image
from robopercept.nn.segmentation.data import nuclei_quadrants, percentile_normalize
from tests.conftest import data_path


@pytest.mark.realdata
def test_real_nuclei_quadrants_hold_the_image_and_its_125_nuclei():
    folder = data_path("segmentation", "stardist_nuclei")
    image, labels = read_image(folder / "img2d.tif"), read_image(folder / "mask2d.tif")
    assert image.shape == labels.shape == (512, 512) and len(np.unique(labels)) == 126
    s = nuclei_quadrants(folder)
    assert s.quadrant == 3
    assert s.train_images.shape == (3, 256, 256, 1) and s.test_image.shape == (256, 256, 1)
    # the tiles are the quadrants: top left, top right, bottom left; bottom right held out
    np.testing.assert_array_equal(s.train_instances[1], labels[:256, 256:])
    np.testing.assert_array_equal(s.test_instances, labels[256:, 256:])
    # every nucleus is in some tile (those cut by a quadrant border in two)
    seen = set(np.unique(s.train_instances)) | set(np.unique(s.test_instances))
    assert seen == set(np.unique(labels))
    # normalised with the training tiles' 1st and 99.8th percentiles only
    train = np.stack([image[:256, :256], image[:256, 256:], image[256:, :256]])
    lo, hi = np.percentile(train, [1, 99.8])
    np.testing.assert_allclose(
        s.test_image[..., 0], (image[256:, 256:] - lo) / (hi - lo), rtol=1e-6, atol=1e-6
    )
    assert 0.1 < s.train_masks.mean() < 0.3 and s.test_mask.dtype == np.int64
    other = nuclei_quadrants(folder, test_quadrant=0)
    np.testing.assert_array_equal(other.test_instances, labels[:256, :256])


def test_percentile_normalize_hand_case_and_refusals(tmp_path):
    x = np.arange(101.0)
    np.testing.assert_allclose(percentile_normalize(x, 10, 90), (x - 10) / 80, rtol=1e-6)
    # percentiles of another array
    np.testing.assert_allclose(percentile_normalize([5.0], 0, 100, reference=x), [0.05])
    with pytest.raises(InputError, match="below high"):
        percentile_normalize(x, 50, 50)
    with pytest.raises(InputError, match="constant"):
        percentile_normalize(np.ones(10))
    with pytest.raises(InputError, match="finite"):
        percentile_normalize([np.nan, 1.0])
    with pytest.raises(InputError, match="does not exist"):
        nuclei_quadrants(tmp_path / "nope")
    with pytest.raises(InputError, match=r"0\.\.3"):
        nuclei_quadrants(tmp_path, test_quadrant=4)
    write_image(tmp_path / "img2d.tif", np.zeros((8, 8), np.uint16))
    write_image(tmp_path / "mask2d.tif", np.zeros((8, 6), np.uint16))
    with pytest.raises(FileFormatError, match="one size"):
        nuclei_quadrants(tmp_path)
    (tmp_path / "mask2d.tif").unlink()
    with pytest.raises(FileFormatError):
        nuclei_quadrants(tmp_path)


@pytest.mark.realdata
def test_real_nuclei_as_a_detection_set_with_exact_boxes_and_masks():
    # the held-out tile as Mask R-CNN's data: one object per nucleus id, its mask that
    # id's pixels, its box the tight box, the class maps the foreground
    from robopercept.nn.detection.data import DetectionDataset

    s = nuclei_quadrants(data_path("segmentation", "stardist_nuclei"))
    ds = DetectionDataset.from_instance_labels(
        [np.clip(s.test_image, 0, 1)], [s.test_instances], "nucleus"
    )
    ids = [i for i in np.unique(s.test_instances) if i]
    assert ds.classes == ("nucleus",) and len(ds.boxes[0]) == len(ids) == 29
    assert ds.images[0].shape == (256, 256, 3)
    for k, i in enumerate(ids):
        m = s.test_instances == i
        np.testing.assert_array_equal(ds.masks[0][k], m)
        rows, cols = np.nonzero(m)
        assert ds.boxes[0][k].tolist() == [cols.min(), rows.min(), cols.max() + 1, rows.max() + 1]
    np.testing.assert_array_equal(ds.class_maps()[0], s.test_mask)


def test_from_instance_labels_and_class_maps_refusals():
    from robopercept.nn.detection.data import DetectionDataset

    im = np.zeros((4, 5))
    with pytest.raises(InputError, match="image's size"):
        DetectionDataset.from_instance_labels([im], [np.zeros((4, 4), int)])
    with pytest.raises(InputError, match="image's size"):
        DetectionDataset.from_instance_labels([im], [np.zeros((4, 5))])  # floats
    with pytest.raises(InputError, match="negative ids"):
        DetectionDataset.from_instance_labels([im], [-np.ones((4, 5), int)])
    empty = DetectionDataset.from_instance_labels([im], [np.zeros((4, 5), int)])
    assert empty.boxes[0].shape == (0, 4) and empty.class_maps().sum() == 0
    no_masks = DetectionDataset([np.zeros((4, 5, 3))], [[[0, 0, 2, 2]]], [[1]], ["a"])
    with pytest.raises(InputError, match="no masks"):
        no_masks.class_maps()
    two = DetectionDataset.from_instance_labels(
        [im, np.zeros((3, 3))], [np.zeros((4, 5), int), np.zeros((3, 3), int)]
    )
    with pytest.raises(InputError, match="one size"):
        two.class_maps()
