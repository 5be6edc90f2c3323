"""``robopercept features``: a picture, JSON equal to the library call, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import main
from robopercept.features import harris_corners
from robopercept.imaging import read_image, write_image


def test_features_writes_picture_and_json(tmp_path, capsys):
    img = np.zeros((60, 80), dtype=np.uint8)
    img[15:45, 20:60] = 220  # a rectangle: 4 corners
    src = write_image(tmp_path / "rect.png", img)
    out = tmp_path / "corners.png"
    args = ["features", str(src), "-o", str(out), "--json", "--quality", "0.1"]
    code = main([*args, "--min-distance", "5"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    expected = harris_corners(img, threshold=0.1, min_distance=5, max_corners=500)
    got = np.array([[k["x"], k["y"]] for k in report["keypoints"]])
    np.testing.assert_array_equal(got, expected.xy)
    assert len(got) == 4 and report["detector"] == "harris"
    pic = read_image(out)
    assert pic.shape == (60, 80, 3)
    # red circles drawn around each corner, nothing red elsewhere
    red = (pic[..., 0] == 255) & (pic[..., 1] == 0)
    assert red.any()
    ys, xs = np.nonzero(red)
    d = np.min(np.hypot(xs[:, None] - got[None, :, 0], ys[:, None] - got[None, :, 1]), axis=1)
    assert d.max() <= 4.5


def test_features_text_and_bad_arguments(tmp_path, capsys):
    code = main(["features", "--detector", "shi-tomasi", "-o", str(tmp_path / "f.png")])
    assert code == 0
    assert "shi-tomasi:" in capsys.readouterr().out
    assert main(["features", "--max", "0", "-o", str(tmp_path / "g.png")]) == 2
    assert "--max" in capsys.readouterr().err
    assert main(["features", str(tmp_path / "missing.png")]) == 1


def test_hog_picture_and_json(tmp_path, capsys):
    from robopercept.features import hog

    img = np.zeros((64, 48), dtype=np.uint8)
    img[:, 24:] = 200  # one vertical edge
    src = write_image(tmp_path / "edge.png", img)
    out = tmp_path / "hog.png"
    assert main(["hog", str(src), "-o", str(out), "--json", "--scale", "1"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["cells"] == [8, 6]
    assert report["descriptor_length"] == hog(img).shape[0] == 7 * 5 * 36
    pic = read_image(out)
    assert pic.shape == (64, 48, 3)
    # glyphs only in the two cell columns beside the edge (columns 16..31)
    lit = np.nonzero(pic.max(axis=(0, 2)))[0]
    assert lit.min() >= 16 and lit.max() <= 31
    assert main(["hog", str(src), "--cell", "100", "-o", str(out)]) == 1
    assert "smaller than one" in capsys.readouterr().err


def _crops(tmp_path):
    from skimage import data

    img = data.astronaut()
    a = write_image(tmp_path / "a.png", img[40:360, 0:330])
    b = write_image(tmp_path / "b.png", img[80:400, 150:480])
    return a, b


def test_sift_detector_json(tmp_path, capsys):
    from skimage import data

    from robopercept.features import sift

    src = write_image(tmp_path / "cam.png", data.camera()[100:300, 100:300])
    assert (
        main(["features", str(src), "--detector", "sift", "--json", "-o", str(tmp_path / "s.png")])
        == 0
    )
    report = json.loads(capsys.readouterr().out)
    kp = sift(read_image(src, mode="gray"), n_features=500).keypoints
    got = np.array([[k["x"], k["y"], k["size"]] for k in report["keypoints"]])
    np.testing.assert_allclose(got, np.c_[kp.xy, kp.scale])
    assert all(k["angle_deg"] is not None for k in report["keypoints"])


def test_match_prints_translation_and_draws(tmp_path, capsys):
    a, b = _crops(tmp_path)
    out = tmp_path / "m.png"
    assert main(["match", str(a), str(b), "-o", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    h = np.array(report["H"])
    # B is A shifted by (-150, -40): x_b = x_a - 150, y_b = y_a - 40
    from robopercept.imaging import transform_points

    grid = np.array([[x, y] for x in (160, 240, 320) for y in (60, 160, 300)], float)
    np.testing.assert_allclose(transform_points(h, grid), grid - [150, 40], atol=0.3)
    assert report["inliers"] > 100 and report["inliers"] <= report["matches"]
    pic = read_image(out)
    assert pic.shape == (320, 660, 3)
    assert main(["match", str(a), str(b), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "inliers" in text and "H (A -> B)" in text


def test_stitch_writes_panorama(tmp_path, capsys):
    a, b = _crops(tmp_path)
    out = tmp_path / "p.png"
    assert main(["stitch", str(a), str(b), "-o", str(out)]) == 0
    assert "panorama 480x360" in capsys.readouterr().out
    assert read_image(out).shape == (360, 480, 3)
    flat = write_image(tmp_path / "flat.png", np.full((100, 100, 3), 80, np.uint8))
    assert main(["stitch", str(a), str(flat), "-o", str(out)]) == 1
    assert "homography needs 4" in capsys.readouterr().err


# --------------------------------------------------------------------------- issue 30


def test_match_draws_the_best_n_and_the_outline(tmp_path, capsys):
    from robopercept.viz.features import OUTLINE_COLOR

    a, b = _crops(tmp_path)
    out = tmp_path / "m.png"
    assert main(["match", str(a), str(b), "-o", str(out), "--json", "--max-matches", "10"]) == 0
    report = json.loads(capsys.readouterr().out)  # one JSON object, nothing else
    assert report["drawn"] == 10 == report["drawn_inliers"] + report["drawn_outliers"]
    assert report["matches"] > 10 and report["max_matches"] == 10
    assert report["outliers"] == report["matches"] - report["inliers"]
    # A (320x330) shifted by (-150, -40): its border's pixel edges on B
    np.testing.assert_allclose(
        report["outline"],
        [[-150.5, -40.5], [179.5 - 0, -40.5], [179.5, 279.5], [-150.5, 279.5]],
        atol=0.5,
    )
    pic = read_image(out)
    ring = (pic == OUTLINE_COLOR).all(axis=2)
    assert ring[:, 330 + 175 : 330 + 185].any() and not ring[:, :330].any()
    assert main(["match", str(a), str(b), "-o", str(out), "--json", "--max-matches", "0"]) == 0
    every = json.loads(capsys.readouterr().out)
    assert every["drawn"] == every["matches"]
    assert main(["match", str(a), str(b), "-o", str(out), "--hide-outliers", "--json"]) == 0
    inliers_only = json.loads(capsys.readouterr().out)
    assert inliers_only["drawn_outliers"] == 0
    assert not (read_image(out) == (255, 0, 255)).all(axis=2).any()


def test_match_bad_max_matches(tmp_path, capsys):
    a, b = _crops(tmp_path)
    assert (
        main(["match", str(a), str(b), "--max-matches", "-1", "-o", str(tmp_path / "m.png")]) == 2
    )
    assert "--max-matches must be >= 0" in capsys.readouterr().err


@pytest.mark.realdata
def test_match_on_graf_draws_100_of_677(tmp_path, capsys):
    """Oxford graf 1 -> 3 (viewpoint change): all 677 ratio-test matches were drawn before
    issue 30; now the best 100, with the inlier share of all, and the outline of img1
    lands where the ground-truth homography puts it."""
    import re

    from tests.conftest import data_path

    graf = data_path("features", "oxford_affine", "graf")
    out = tmp_path / "graf.png"
    args = ["match", str(graf / "img1.png"), str(graf / "img3.png"), "-o", str(out), "--json"]
    assert main(args) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["drawn"] == 100 and report["matches"] > 500
    share = report["inliers"] / report["matches"]
    assert abs(report["drawn_inliers"] / 100 - share) <= 0.01
    text = (graf / "H1to3p.xml").read_text()
    truth = np.array(re.search(r"<data>(.*?)</data>", text, re.S).group(1).split(), float)
    corners = np.array([[-0.5, -0.5], [799.5, -0.5], [799.5, 639.5], [-0.5, 639.5]])
    p = np.c_[corners, np.ones(4)] @ truth.reshape(3, 3).T
    # the fitted H against the ground truth at the image corners (extrapolated: the
    # matches cover the middle): within 15 px on an 800x640 image
    np.testing.assert_allclose(report["outline"], p[:, :2] / p[:, 2:], atol=15)
    assert read_image(out).shape == (640, 1600, 3)


def test_stitch_json(tmp_path, capsys):
    a, b = _crops(tmp_path)
    out = tmp_path / "p.png"
    assert main(["stitch", str(a), str(b), "-o", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["size"] == [480, 360] and report["picture"] == str(out)
    assert report["inliers"] <= report["matches"] and len(report["H"]) == 3


def test_blobs_ids_are_1_to_n(tmp_path, capsys):
    """Blobs under --min-area used to leave gaps in the printed ids (1, 2, 5, 10, ... on
    the bundled sample); they are numbered 1..N in raster order, as drawn."""
    mask = np.zeros((60, 90), np.uint8)
    for k, x in enumerate(range(2, 88, 6)):  # alternating big (4x20) and tiny (1x1) blobs
        if k % 2:
            mask[5, x] = 255
        else:
            mask[10:30, x : x + 4] = 255
    src = write_image(tmp_path / "m.png", mask)
    overlay = tmp_path / "o.png"
    assert main(["blobs", str(src), "--json", "--min-area", "5", "-o", str(overlay)]) == 0
    data = json.loads(capsys.readouterr().out)
    ids = [b["label"] for b in data["blobs"]]
    assert ids == list(range(1, 9)) and data["count"] == 8
    assert [b["bbox"][0] for b in data["blobs"]] == list(range(2, 88, 12))  # raster order
    assert main(["blobs", "--json"]) == 0  # the bundled sample
    sample = json.loads(capsys.readouterr().out)
    assert [b["label"] for b in sample["blobs"]] == list(range(1, sample["count"] + 1))
    assert main(["blobs", str(src), "--min-area", "5"]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[2:]]
    assert [int(r[0]) for r in rows] == list(range(1, 9))
