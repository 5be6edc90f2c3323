"""``robopercept batch``: its flags, errors and JSON (a LocalCluster of one worker)."""

from __future__ import annotations

import json
import shutil
import socket

import pytest

from robopercept.cli.main import main
from robopercept.imaging import sample_image_path

pytest.importorskip("distributed")


def _images(tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    for n in ("a.png", "b.png"):
        shutil.copy(sample_image_path(), d / n)
    return d


def test_local_run_json_then_refused_then_resumed(tmp_path, capsys) -> None:
    d, out = _images(tmp_path), tmp_path / "out"
    argv = ["batch", "edges", str(d), "-o", str(out), "--workers", "1", "--json"]
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["ok"] == 2 and got["items"] == 2 and got["workers"] == 1
    assert [r["outputs"] for r in got["results"]] == [["a/edges.png"], ["b/edges.png"]]
    assert json.loads((out / "batch.json").read_text())["ok"] == 2
    assert main(argv) == 2  # the output exists
    err = capsys.readouterr().err
    assert "--resume" in err and "--overwrite" in err
    assert main([*argv, "--resume"]) == 0
    assert json.loads(capsys.readouterr().out)["skipped"] == 2


def test_every_item_failed_exits_1(tmp_path, capsys) -> None:
    bad = tmp_path / "broken.pcd"
    bad.write_bytes(b"not a point cloud")
    assert main(["batch", "cloud", str(bad), "-o", str(tmp_path / "o"), "--workers", "1"]) == 1
    captured = capsys.readouterr()
    assert "every item failed" in captured.err and "broken" in captured.out


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--scheduler", "somewhere:8786"], "--scheduler must be 'local' or tcp://"),
        (["--voxel", "0.1"], "--voxel does not apply to the edges job"),
        (["--retries", "-1"], "--retries must be >= 0"),
        (["--resume", "--overwrite"], "not allowed with argument"),
    ],
)
def test_bad_flags(tmp_path, capsys, extra, message) -> None:
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"), *extra]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_unreachable_scheduler(tmp_path, capsys) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"),
            "--scheduler", f"tcp://127.0.0.1:{port}", "--connect-timeout", "1"]  # fmt: skip
    assert main(argv) == 1
    assert f"--scheduler tcp://127.0.0.1:{port}: no Dask scheduler answered" in (
        capsys.readouterr().err
    )
