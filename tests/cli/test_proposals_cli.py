"""``robopercept proposals``: JSON equal to the library call, the picture, errors."""

from __future__ import annotations

import json

import numpy as np

from robopercept.cli.main import main
from robopercept.features import selective_search
from robopercept.imaging import read_image, write_image


def scene() -> np.ndarray:
    img = np.full((48, 64, 3), 30, np.uint8)
    img[10:30, 12:40] = (220, 40, 40)
    img[20:44, 44:60] = (40, 200, 60)
    return img


def test_json_equals_library_and_picture(tmp_path, capsys):
    src = write_image(tmp_path / "scene.png", scene())
    out = tmp_path / "proposals.png"
    code = main(["proposals", str(src), "-o", str(out), "--json", "--max", "5", "--quiet"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    expected = selective_search(scene(), "fast", rng=0, max_proposals=5)
    assert report["boxes_xywh"] == expected.tolist() and report["mode"] == "fast"
    pic = read_image(out)
    assert pic.shape == (48, 64, 3)
    # outlines drawn: pixels changed only on the borders of the proposals
    changed = np.any(pic != scene(), axis=2)
    assert changed.any()
    edge = np.zeros((48, 64), bool)
    for bx, by, bw, bh in expected:
        edge[by, bx : bx + bw] = edge[by + bh - 1, bx : bx + bw] = True
        edge[by : by + bh, bx] = edge[by : by + bh, bx + bw - 1] = True
    assert not (changed & ~edge).any()


def test_text_output_and_progress(tmp_path, capsys):
    src = write_image(tmp_path / "scene.png", scene())
    assert main(["proposals", str(src)]) == 0
    cap = capsys.readouterr()
    assert "proposals (fast mode" in cap.out
    assert "selective search" in cap.err  # progress lines off a terminal


def test_bad_arguments(tmp_path, capsys):
    src = write_image(tmp_path / "scene.png", scene())
    assert main(["proposals", str(src), "--max", "0"]) == 2
    assert "--max" in capsys.readouterr().err
    assert main(["proposals", str(src), "--mode", "slow"]) == 2
    assert main(["proposals", str(src), "-o", str(tmp_path / "x.txt")]) == 2
    assert main(["proposals", str(tmp_path / "missing.png")]) == 1
    assert "missing.png" in capsys.readouterr().err
