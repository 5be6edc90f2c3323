"""``robopercept features``: a picture, JSON equal to the library call, errors."""

from __future__ import annotations

import json

import numpy as np

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
