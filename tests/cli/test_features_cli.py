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
    assert main(["features", str(tmp_path / "missing.png")]) == 2


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
    assert main(["hog", str(src), "--cell", "100", "-o", str(out)]) == 2
    assert "smaller than one" in capsys.readouterr().err
