"""``robopercept batch``: its flags, errors and JSON (a LocalCluster of one worker)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robopercept.cli.main import main
from robopercept.imaging import sample_image_path

pytest.importorskip("distributed")

SRC = Path(__file__).resolve().parents[2] / "src"
# The CLI has no per-item delay flag: this runs `robopercept batch` (main) with
# run_batch's ``delay`` set, so the batch is slow enough to be interrupted mid-way
# (the guard: Dask's worker processes are spawned and import this script again).
_SLOW_CLI = """
import functools, sys
if __name__ == "__main__":
    import robopercept.pipelines.batch as b
    b.run_batch = functools.partial(b.run_batch, delay=float(sys.argv[1]))
    from robopercept.cli.main import main
    sys.exit(main(sys.argv[2:]))
"""


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
    assert main(argv) == 1  # the output exists
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
        (["--voxel", "0.1"], "--voxel does not apply to the edges job"),
        (["--retries", "-1"], "argument --retries: must be >= 0"),
        (["--connect-timeout", "0"], "argument --connect-timeout: must be > 0"),
        (["--points", "0"], "argument --points: must be >= 1"),
        (["--points", "64"], "--points does not apply to the edges job"),
        (["--max-disparity", "64"], "--max-disparity does not apply to the edges job"),
        (["--no-lr-check"], "--lr-check does not apply to the edges job"),
        (["--resume", "--overwrite"], "not allowed with argument"),
    ],
)
def test_bad_flags(tmp_path, capsys, extra, message) -> None:
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"), *extra]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["nn-cloud", "--model", "nowhere.pt"], "--model nowhere.pt: no such file or folder"),
        (["stereo"], "the stereo job needs --max-disparity"),
        (["stereo", "--max-disparity", "8", "--method", "sobel"], "--method must be one of"),
        (["nn-predict"], "the nn-predict job needs --model"),
    ],
)
def test_library_refusals_name_the_flags(tmp_path, capsys, argv, message) -> None:
    pair = tmp_path / "pair"
    pair.mkdir()
    for n in ("left.png", "right.png"):
        shutil.copy(sample_image_path(), pair / n)
    src = {"stereo": pair, "nn-cloud": tmp_path / "a.off"}.get(argv[0], sample_image_path())
    assert main(["batch", argv[0], str(src), "-o", str(tmp_path / "o"), *argv[1:]]) == 1
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# issue 47 (R58): an address Dask cannot use is a usage error naming --scheduler and the
# forms it takes (tests/pipelines/test_batch_hostile.py has each form)
def test_an_address_without_scheme_is_a_usage_error(tmp_path, capsys) -> None:
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"),
            "--scheduler", "somewhere:8786"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--scheduler must be 'local' or the address of a running Dask cluster" in err
    assert "write tcp://somewhere:8786" in err
    assert not (tmp_path / "o").exists()


def test_nn_cloud_flags_reach_run_batch(tmp_path, monkeypatch, capsys) -> None:
    import robopercept.pipelines.batch as batch

    seen: dict[str, object] = {}

    def fake(job, inputs, out, **kw):
        seen.update(job=job, **kw)
        return batch.BatchResult(job, Path(out), "local", 1, 1.0, [])

    monkeypatch.setattr(batch, "run_batch", fake)
    cloud = tmp_path / "a.off"
    cloud.write_text("OFF\n")
    argv = ["batch", "nn-cloud", str(cloud), "-o", str(tmp_path / "o"), "--model", "dgcnn",
            "--points", "256", "--json"]  # fmt: skip
    assert main(argv) == 0
    assert seen["job"] == "nn-cloud" and seen["options"] == {"model": "dgcnn", "points": 256}
    assert json.loads(capsys.readouterr().out)["job"] == "nn-cloud"
    argv = ["batch", "stereo", str(tmp_path), "-o", str(tmp_path / "o"), "--max-disparity", "64",
            "--method", "bm", "--no-lr-check"]  # fmt: skip
    assert main(argv) == 0
    assert seen["options"] == {"method": "bm", "max_disparity": 64, "lr_check": None}
    argv = ["batch", "nn-detect", str(tmp_path), "-o", str(tmp_path / "o"), "--model", "faster",
            "--score-thresh", "0.3", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    assert seen["options"] == {"model": "faster", "score_thresh": 0.3}


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


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - a reused id of someone else's group
        return True
    return True


def test_ctrl_c_cancels_then_resume_finishes(tmp_path, capsys) -> None:
    d, out = tmp_path / "in", tmp_path / "out"
    d.mkdir()
    names = [f"img{i}" for i in range(6)]
    for n in names:
        shutil.copy(sample_image_path(), d / f"{n}.png")
    script = tmp_path / "slow_cli.py"
    script.write_text(_SLOW_CLI)
    env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "OMP_NUM_THREADS": "1"}  # fmt: skip
    argv = ["batch", "edges", str(d), "-o", str(out), "--workers", "1", "--quiet"]
    child = subprocess.Popen(
        [sys.executable, str(script), "2.0", *argv], env=env, start_new_session=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 180  # generous: a loaded machine starts dask slowly
        manifest = None
        while time.monotonic() < deadline and child.poll() is None:
            manifest = json.loads((out / "batch.json").read_text()) if (
                out / "batch.json").is_file() else None  # fmt: skip
            if manifest and any(r["status"] == "ok" for r in manifest["items"]):
                break
            time.sleep(0.1)
        assert child.poll() is None, child.communicate()
        assert manifest and manifest["ok"] >= 1, "no item finished in time"
        child.send_signal(signal.SIGINT)  # Ctrl-C to the command (not to its workers)
        _, err = child.communicate(timeout=120)
        assert child.returncode == 130, err
        assert "robopercept: interrupted" in err
        deadline = time.monotonic() + 60  # the LocalCluster's workers go with it
        while _group_alive(child.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not _group_alive(child.pid), "processes of the batch were left behind"
    finally:
        if child.poll() is None or _group_alive(child.pid):
            try:
                os.killpg(child.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        child.wait(timeout=30)
    got = json.loads((out / "batch.json").read_text())  # valid JSON, every item in it
    assert [r["item"] for r in got["items"]] == names
    statuses = [r["status"] for r in got["items"]]
    assert set(statuses) <= {"ok", "cancelled"} and "cancelled" in statuses, statuses
    for r in got["items"]:
        if r["status"] == "ok":
            assert (out / r["outputs"][0]).is_file()
    assert got["ok"] == statuses.count("ok") and got["cancelled"] == statuses.count("cancelled")
    assert main([*argv, "--resume", "--json"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["ok"] == statuses.count("cancelled")
    assert again["skipped"] == statuses.count("ok")
    assert all((out / n / "edges.png").is_file() for n in names)
