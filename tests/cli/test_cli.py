"""The robopercept command: outputs, JSON, and one-line errors with their exit codes
(1 a bad file or data, 2 a usage error, 70 an internal error)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from robopercept import __version__
from robopercept.cli.main import main
from robopercept.imaging import read_image, write_image


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "robopercept.cli.main", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_help_version_info(capsys):
    r = run_cli("--help")
    assert r.returncode == 0 and "edges" in r.stdout and "blobs" in r.stdout
    r = run_cli("--version")
    assert r.returncode == 0 and __version__ in r.stdout
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "numpy" in out and "torch" in out


@pytest.mark.parametrize("method", ["canny", "sobel", "log"])
def test_edges_writes_png(tmp_path, capsys, method):
    out = tmp_path / f"{method}.png"
    assert main(["edges", "-o", str(out), "--method", method]) == 0
    img = read_image(out)
    assert img.dtype == np.uint8 and img.ndim == 2 and img.max() == 255
    assert method in capsys.readouterr().out


def test_edges_sigma_0_l1_gradient_is_cv2_canny(tmp_path, capsys):
    """`--sigma 0 --l1-gradient` (as the help says) gives cv2.Canny's edges on the
    bundled sample (0.1% of pixels may differ: ties at the suppression's sector borders);
    the default smooths first and finds fewer edges."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.imaging.io import sample_image_path

    src = sample_image_path()
    gray = read_image(src, mode="gray")
    out = tmp_path / "e.png"
    args = ["edges", str(src), "-o", str(out), "--sigma", "0", "--l1-gradient", "--json"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["parameters"]["l2_gradient"] is False
    ours = read_image(out) > 0
    ref = cv2.Canny(gray, 50, 150) > 0
    assert np.mean(ours != ref) <= 1e-3
    assert main(["edges", str(src), "-o", str(out)]) == 0
    assert (read_image(out) > 0).sum() < ref.sum()


def test_blobs_table_json_and_overlay(tmp_path, capsys):
    mask = np.zeros((60, 80), np.uint8)
    mask[10:20, 10:30] = 255
    mask[40:50, 50:60] = 255
    mask[43:47, 53:57] = 0
    src = write_image(tmp_path / "m.png", mask)
    overlay = tmp_path / "o.png"
    assert main(["blobs", str(src), "--json", "-o", str(overlay), "--min-area", "1"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [b["area"] for b in data["blobs"]] == [200, 84]
    assert [b["holes"] for b in data["blobs"]] == [0, 1]
    assert read_image(overlay).shape == (60, 80, 3)
    assert main(["blobs", str(src), "--min-area", "1"]) == 0
    table = capsys.readouterr().out
    assert "2 blobs" in table and "circ" in table


@pytest.mark.parametrize(
    ("args", "needle", "code"),
    [
        (["edges", "nonexistent.png"], "no such file", 1),
        (["edges", "--method", "magic"], "invalid choice", 2),
        (["blobs", "--min-area", "-3"], "min-area", 2),
        (["edges", "--low", "200", "--high", "100"], "swap", 1),
        (["frobnicate"], "invalid choice", 2),
    ],
)
def test_errors_are_one_line_with_their_exit_code(args, needle, code):
    r = run_cli(*args)
    assert r.returncode == code
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_corrupt_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    r = run_cli("blobs", str(bad))
    assert r.returncode == 1 and "bad.png" in r.stderr and "Traceback" not in r.stderr


# ----------------------------------------------------------------------------- cloud
def _scene_ply(tmp_path, rng):
    """A floor plane z = 0 with two boxes of points above it, written as PLY."""
    from robopercept.pointcloud import PointCloud, write_point_cloud

    floor = np.column_stack([rng.uniform(-1, 1, (4000, 2)), rng.normal(0, 0.001, 4000)])
    box1 = rng.uniform([0.2, 0.2, 0.05], [0.4, 0.4, 0.25], (800, 3))
    box2 = rng.uniform([-0.6, -0.5, 0.05], [-0.4, -0.3, 0.2], (600, 3))
    path = tmp_path / "scene.ply"
    write_point_cloud(path, PointCloud(np.vstack([floor, box1, box2])))
    return path


def test_cloud_command_pipeline_and_json(tmp_path):
    rng = np.random.default_rng(0)
    src = _scene_ply(tmp_path, rng)
    out = tmp_path / "seg.ply"
    r = run_cli(
        "cloud", str(src), "-o", str(out), "--pass-through", "z:-0.5:1", "--voxel", "0.005",
        "--sor", "20:2.0", "--planes", "1:0.01", "--clusters", "0.05:50:100000", "--json",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    names = [s["step"].split()[0] for s in summary["steps"]]
    assert names == ["read", "pass-through", "voxel", "sor", "planes", "clusters"]
    plane = summary["steps"][4]["planes"][0]
    assert abs(abs(plane["equation"][2]) - 1) < 1e-3  # the floor z = 0
    assert len(summary["steps"][5]["cluster_sizes"]) == 2  # the two boxes
    from robopercept.pointcloud import read_point_cloud

    seg = read_point_cloud(out)
    assert seg.colors is not None and len(np.unique(seg.colors, axis=0)) == 3
    r = run_cli("cloud", str(src), "-o", str(tmp_path / "t.ply"), "--planes", "2:0.01")
    assert r.returncode == 0 and "plane 1:" in r.stdout and "wrote" in r.stdout


@pytest.mark.parametrize(
    ("args", "match", "code"),
    [
        (["cloud", "missing.pcd"], "missing.pcd: no such file", 1),
        (["cloud", "x.ply", "--planes", "1"], "N:THRESHOLD", 2),
        (["cloud", "x.ply", "--pass-through", "q:0:1"], "AXIS", 2),
        (["cloud", "x.ply", "-o", "out.txt"], "output must end", 2),
    ],
)
def test_cloud_command_errors(tmp_path, args, match, code):
    r = run_cli(*args)
    assert r.returncode == code and match in r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_exit_code_2_for_a_usage_error(capsys):
    assert main(["edges", "--method", "magic"]) == 2  # argparse
    assert main(["features", "--max", "0"]) == 2  # a bad flag value found by the command
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and err[1] == "robopercept: error: --max must be >= 1; got 0"


def test_exit_code_1_for_a_missing_file(tmp_path, capsys):
    assert main(["edges", str(tmp_path / "absent.png")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("robopercept: error: ") and "absent.png" in err[0]


def _boom(args):
    raise ZeroDivisionError("division by zero")


def test_exit_code_70_for_an_internal_error(monkeypatch, capsys):
    from robopercept.cli import edges

    monkeypatch.delenv("ROBOPERCEPT_DEBUG", raising=False)
    monkeypatch.setattr(edges, "run_edges", _boom)
    assert main(["edges"]) == 70
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "robopercept: internal error (this is a bug, please report it): ZeroDivisionError: "
        "division by zero; rerun with --debug for the traceback"
    ]


@pytest.mark.parametrize("argv", [["--debug", "edges"], ["edges", "--debug"]])
def test_debug_flag_reraises(monkeypatch, argv):
    from robopercept.cli import edges

    monkeypatch.delenv("ROBOPERCEPT_DEBUG", raising=False)
    monkeypatch.setattr(edges, "run_edges", _boom)
    with pytest.raises(ZeroDivisionError):
        main(argv)


def test_debug_environment_variable_reraises(monkeypatch, tmp_path):
    from robopercept.errors import FileFormatError

    monkeypatch.setenv("ROBOPERCEPT_DEBUG", "1")
    with pytest.raises(FileFormatError):
        main(["edges", str(tmp_path / "absent.png")])


def test_mistyped_command_gets_a_suggestion(capsys):
    assert main(["edgs", "x.png"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice: 'edgs'" in err[0]
    assert "did you mean 'edges'?" in err[0]
    assert main(["zzzzzz"]) == 2  # nothing close: no suggestion
    assert "did you mean" not in capsys.readouterr().err


def test_warnings_are_one_clean_line(monkeypatch, capsys):
    import warnings

    from robopercept.cli import edges

    def warn(args):
        warnings.warn("16-bit input: thresholds scaled", UserWarning, stacklevel=1)
        return 0

    monkeypatch.setattr(edges, "run_edges", warn)
    assert main(["edges", "x.png"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["robopercept: warning: 16-bit input: thresholds scaled"]


def test_edges_of_a_16bit_image_are_those_of_its_8bit_version(tmp_path, capsys):
    """Issue 22: the 16-bit image (the 8-bit sample * 257, as a 16-bit PNG) got 8-bit
    thresholds. The defaults are 8-bit grey levels, scaled by 257 for uint16 input with a
    one-line note: the edge map is the 8-bit one, pixel for pixel. Thresholds given on
    the command line are taken as given, with a warning when they look 8-bit."""
    import re

    from robopercept.imaging import sample_image_path

    img8 = read_image(sample_image_path())
    src8 = write_image(tmp_path / "box8.png", img8)
    src16 = write_image(tmp_path / "box16.png", img8.astype(np.uint16) * 257)
    assert read_image(src16).dtype == np.uint16
    assert main(["edges", str(src8), "-o", str(tmp_path / "e8.png")]) == 0
    out8 = capsys.readouterr().out
    assert main(["edges", str(src16), "-o", str(tmp_path / "e16.png")]) == 0
    out16 = capsys.readouterr().out.splitlines()
    assert len(out16) == 2 and "--low 12850 --high 38550" in out16[0]
    edges8 = read_image(tmp_path / "e8.png")
    np.testing.assert_array_equal(read_image(tmp_path / "e16.png"), edges8)
    share = re.search(r"edge pixels \(\d+\.\d%\)", out8)  # "12300 edge pixels (17.0%)"
    assert share and share.group() in out16[1]
    # explicit 8-bit thresholds on the 16-bit image: as given, with the fix in a warning
    noisy = ["edges", str(src16), "--low", "50", "--high", "150", "-o", str(tmp_path / "n.png")]
    assert main(noisy) == 0
    cap = capsys.readouterr()
    assert "12850 and 38550" in cap.err and cap.err.startswith("robopercept: warning:")
    assert (read_image(tmp_path / "n.png") > 0).mean() > 1.3 * (edges8 > 0).mean()
