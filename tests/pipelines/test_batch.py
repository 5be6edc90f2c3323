"""``pipelines.batch``: batch jobs on a real Dask cluster (a ``dask scheduler`` and
``dask worker`` processes on 127.0.0.1) and on a LocalCluster, on real point clouds
and images from ../shared/data."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from robopercept.errors import InputError
from robopercept.pipelines.batch import (
    BatchResult,
    find_inputs,
    item_names,
    local_cluster,
    read_manifest,
    run_batch,
    run_item,
    stereo_pair,
)
from tests.conftest import data_path

pytest.importorskip("distributed")

SRC = Path(__file__).resolve().parents[2] / "src"
BIN = Path(sys.executable).parent
CLOUDS = ("bun0.pcd", "bun4.pcd", "milk.pcd")
IMAGES = ("box.png", "box_in_scene.png")
PAIRS = ("tsukuba", "venus")  # Middlebury 2001: im2 left, im6 right


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Cluster:
    """A scheduler and ``n`` workers as subprocesses, each in its own process group."""

    def __init__(self, n: int) -> None:
        self.address = f"tcp://127.0.0.1:{_free_port()}"
        env = {**os.environ, "PYTHONPATH": f"{SRC}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        common = {"env": env, "start_new_session": True, "stdout": subprocess.DEVNULL,
                  "stderr": subprocess.DEVNULL}  # fmt: skip
        port = self.address.rsplit(":", 1)[1]
        dask = str(BIN / "dask")
        scheduler = [dask, "scheduler", "--host", "127.0.0.1", "--port", port, "--no-dashboard"]
        worker = [dask, "worker", self.address, "--nthreads", "1", "--nworkers", "1",
                  "--no-dashboard", "--host", "127.0.0.1"]  # fmt: skip
        self.procs: list[subprocess.Popen] = []
        self.workers: list[subprocess.Popen] = []
        try:
            self.procs.append(subprocess.Popen(scheduler, **common))
            for _ in range(n):
                self.workers.append(subprocess.Popen(worker, **common))
                self.procs.append(self.workers[-1])
            from distributed import Client

            with Client(self.address, timeout=120) as client:  # generous: a loaded machine
                client.wait_for_workers(n, timeout=180)
        except BaseException:
            self.close()
            raise

    def kill(self, proc: subprocess.Popen) -> None:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the nanny and its worker
        proc.wait(timeout=30)

    def close(self) -> None:
        for p in reversed(self.procs):
            try:
                self.kill(p)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                pass


@pytest.fixture(scope="module")
def cluster() -> Iterator[Cluster]:
    c = None
    try:
        c = Cluster(2)
        yield c
    finally:
        if c is not None:
            c.close()


def _clouds() -> list[Path]:
    return [data_path("pointcloud", "pcl", n) for n in CLOUDS]


def _images() -> list[Path]:
    return [data_path("features", "opencv_box", n) for n in IMAGES]


def _pairs() -> list[Path]:
    return [data_path("stereo", "middlebury_opencv_extra", n) for n in PAIRS]


def _same_outputs(job: str, res, inputs, options, tmp: Path) -> None:
    """Each item's files equal those of run_item in this process, byte for byte
    (``summary.json`` holds timings: its numbers but the ``ms`` are compared)."""
    for rec, src in zip(res.items, inputs, strict=True):
        assert rec["status"] == "ok", rec
        ref = run_item(job, src, tmp / "ref" / rec["item"], options)
        assert rec["outputs"] == [f"{rec['item']}/{o}" for o in ref["outputs"]]
        for name in ref["outputs"]:
            got = (res.out / rec["item"] / name).read_bytes()
            want = (tmp / "ref" / rec["item"] / name).read_bytes()
            if name == "summary.json":
                got_d, want_d = json.loads(got), json.loads(want)
                assert got_d["points"] == want_d["points"] and got_d["planes"] == want_d["planes"]
            else:
                assert got == want, name


@pytest.mark.realdata
def test_cluster_by_address_equals_single_process(cluster, tmp_path) -> None:
    clouds, images = _clouds(), _images()
    opts = {"voxel": 0.005, "planes": (1, 0.01)}
    # the fixture's `dask worker`s run with Dask's default MALLOC_TRIM_THRESHOLD_
    with pytest.warns(RuntimeWarning, match="2 of 2 workers run with MALLOC_TRIM_THRESHOLD_"):
        res = run_batch("cloud", clouds, tmp_path / "c", scheduler=cluster.address,
                        options=opts, progress=False)  # fmt: skip
    assert res.workers == 2 and res.count("ok") == len(CLOUDS)
    _same_outputs("cloud", res, clouds, opts, tmp_path / "rc")
    for job in ("edges", "features"):
        res = run_batch(job, images, tmp_path / job, scheduler=cluster.address, progress=False)
        _same_outputs(job, res, images, {}, tmp_path / f"r{job}")
    manifest = read_manifest(tmp_path / "features")
    assert [r["item"] for r in manifest["items"]] == ["box", "box_in_scene"]
    assert all(r["seconds"] >= 0 and r["error"] == "" for r in manifest["items"])
    assert all(r["attempts"] == 1 and r["worker"].startswith("tcp://127.0.0.1:")
               for r in manifest["items"])  # fmt: skip


@pytest.mark.realdata
def test_command_through_the_address_equals_single_process(cluster, tmp_path, capsys) -> None:
    from robopercept.cli.main import main

    clouds, out = _clouds(), tmp_path / "cli"
    argv = ["batch", "cloud", *map(str, clouds), "-o", str(out), "--scheduler", cluster.address,
            "--voxel", "0.005", "--quiet", "--json"]  # fmt: skip
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["scheduler"] == cluster.address and got["ok"] == len(CLOUDS)
    items = read_manifest(out)["items"]
    res = BatchResult("cloud", out, cluster.address, 2, got["seconds"], items)
    _same_outputs("cloud", res, clouds, {"voxel": 0.005}, tmp_path / "ref")
    images, out = _images(), tmp_path / "cli_images"  # and on images
    argv = ["batch", "features", *map(str, images), "-o", str(out), "--scheduler",
            cluster.address, "--quiet", "--json"]  # fmt: skip
    assert main(argv) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["scheduler"] == cluster.address and got["ok"] == len(IMAGES)
    items = read_manifest(out)["items"]
    res = BatchResult("features", out, cluster.address, 2, got["seconds"], items)
    _same_outputs("features", res, images, {}, tmp_path / "ref_images")


@pytest.mark.realdata
def test_stereo_batch_equals_single_process_matching(cluster, tmp_path) -> None:
    import numpy as np

    from robopercept.depth import semi_global_matching
    from robopercept.imaging import read_image

    pairs, opts = _pairs(), {"max_disparity": 32}
    res = run_batch("stereo", pairs, tmp_path / "s", scheduler=cluster.address, options=opts,
                    progress=False)  # fmt: skip
    assert [r["item"] for r in res.items] == list(PAIRS)
    _same_outputs("stereo", res, pairs, opts, tmp_path / "rs")
    left, right = (read_image(p, mode="rgb") for p in stereo_pair(pairs[0]))
    want = semi_global_matching(left, right, 32, lr_check=1.0)  # robopercept stereo's defaults
    got = np.load(res.out / "tsukuba" / "disparity.npy")
    np.testing.assert_array_equal(got, want.astype(np.float32))
    assert res.items[0]["summary"]["valid_percent"] == pytest.approx(
        100 * np.isfinite(want).mean(), abs=1e-3
    )


@pytest.mark.realdata
def test_failed_item_is_recorded_and_the_batch_goes_on(cluster, tmp_path) -> None:
    bad = tmp_path / "in" / "broken.pcd"
    bad.parent.mkdir()
    bad.write_bytes(b"# .PCD v0.7\nFIELDS x y z\nSIZE 4 4\nnonsense\n")
    good = _clouds()[1]
    res = run_batch("cloud", [bad, good], tmp_path / "o", scheduler=cluster.address,
                    retries=1, progress=False)  # fmt: skip
    by = {r["item"]: r for r in res.items}
    assert by["broken"]["status"] == "failed" and by["bun4"]["status"] == "ok"
    assert "FileFormatError" in by["broken"]["error"] and by["broken"]["outputs"] == []
    assert by["broken"]["attempts"] == 2 and by["bun4"]["attempts"] == 1  # retried once
    assert read_manifest(tmp_path / "o")["items"] == res.items
    assert bad.read_bytes().endswith(b"nonsense\n")  # inputs untouched


@pytest.mark.realdata
def test_existing_output_refused_then_resumed(cluster, tmp_path) -> None:
    images, out = _images(), tmp_path / "o"
    first = run_batch("edges", images, out, scheduler=cluster.address, progress=False)
    assert first.count("ok") == 2
    with pytest.raises(InputError, match=r"give resume .* or overwrite"):
        run_batch("edges", images, out, scheduler=cluster.address, progress=False)
    again = run_batch("edges", images, out, scheduler=cluster.address, resume=True,
                      progress=False)  # fmt: skip
    assert [r["status"] for r in again.items] == ["skipped", "skipped"]
    (out / "box" / "edges.png").unlink()  # an item whose output went missing runs again
    again = run_batch("edges", images, out, scheduler=cluster.address, resume=True,
                      progress=False)  # fmt: skip
    assert [r["status"] for r in again.items] == ["ok", "skipped"]
    assert (out / "box" / "edges.png").is_file()
    redo = run_batch("edges", images, out, scheduler=cluster.address, overwrite=True,
                     progress=False)  # fmt: skip
    assert redo.count("ok") == 2


def test_unreachable_scheduler_is_a_clear_error(tmp_path) -> None:
    img = tmp_path / "a.png"
    from robopercept.imaging import sample_image_path

    shutil.copy(sample_image_path(), img)
    address = f"tcp://127.0.0.1:{_free_port()}"  # nobody listens there
    with pytest.raises(InputError, match=rf"--scheduler {address}: no Dask scheduler.*1 s"):
        run_batch("edges", [img], tmp_path / "o", scheduler=address, connect_timeout=1.0,
                  progress=False)  # fmt: skip


@pytest.mark.realdata
def test_killed_worker_items_are_rescheduled(tmp_path) -> None:
    src = _images()[0]
    inputs = []
    for i in range(6):
        inputs.append(tmp_path / "in" / f"img{i}.png")
        inputs[-1].parent.mkdir(exist_ok=True)
        shutil.copy(src, inputs[-1])
    out = tmp_path / "o"
    c = None
    try:
        c = Cluster(2)
        box: dict[str, object] = {}

        def work() -> None:
            try:
                box["res"] = run_batch("edges", inputs, out, scheduler=c.address, retries=0,
                                       delay=1.5, progress=False)  # fmt: skip
            except BaseException as exc:  # reported below
                box["exc"] = exc

        t = threading.Thread(target=work)
        t.start()
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:  # both workers busy: the items are running
            m = read_manifest(out)
            if m and any(r["status"] == "ok" for r in m["items"]):
                break
            time.sleep(0.1)
        c.kill(c.workers[0])  # SIGKILL mid-batch: its running item moves to the other
        t.join(timeout=240)
        assert not t.is_alive() and "exc" not in box, box.get("exc")
        res = box["res"]
        assert [r["status"] for r in res.items] == ["ok"] * 6
        manifest = read_manifest(out)
        assert len(manifest["items"]) == 6 and manifest["ok"] == 6
        assert all((out / f"img{i}" / "edges.png").is_file() for i in range(6))
    finally:
        if c is not None:
            c.close()


@pytest.mark.realdata
def test_local_cluster_two_workers(tmp_path) -> None:
    clouds = _clouds()[:2]
    res = run_batch("cloud", clouds, tmp_path / "o", workers=2, options={"voxel": 0.01},
                    progress=False)  # fmt: skip
    assert res.scheduler == "local" and res.workers == 2 and res.count("ok") == 2
    _same_outputs("cloud", res, clouds, {"voxel": 0.01}, tmp_path)


def test_local_workers_get_the_worker_config() -> None:
    """Dask's nanny sets MALLOC_TRIM_THRESHOLD_ (plane-track 1.85x slower per item) and
    numba would start a thread per core in each worker: local_cluster's workers get
    neither (docs/scale.md has the measurements), and this process's environment is
    left alone (a NUMBA_NUM_THREADS changed here after numba started its threads makes
    every later parallel kernel here fail)."""
    from distributed import Client

    def env() -> tuple[str | None, str | None, int]:
        import numba

        got = (os.environ.get("MALLOC_TRIM_THRESHOLD_"), os.environ.get("NUMBA_NUM_THREADS"))
        return (*got, numba.config.NUMBA_NUM_THREADS)

    before = dict(os.environ)
    with local_cluster(1) as cluster, Client(cluster) as client:
        assert list(client.run(env).values()) == [(None, "1", 1)]
        assert len(client.scheduler_info()["workers"]) == 1
    changed = {k for k in set(before) | set(os.environ) if before.get(k) != os.environ.get(k)}
    assert not changed & {"MALLOC_TRIM_THRESHOLD_", "NUMBA_NUM_THREADS"}, changed
    with pytest.raises(InputError, match="workers must be >= 1"):
        local_cluster(0)
    # a whole batch leaves this process's environment as it found it (Dask's nannies
    # write OMP_NUM_THREADS=1 and the like into it)
    from robopercept.imaging import sample_image_path

    before = dict(os.environ)
    res = run_batch("edges", [sample_image_path()], Path(tempfile.mkdtemp()) / "o", workers=1,
                    progress=False)  # fmt: skip
    assert res.count("ok") == 1 and dict(os.environ) == before


def test_inputs_and_names(tmp_path) -> None:
    for n in ("a.pcd", "b.PLY", "c.txt"):
        (tmp_path / n).write_text("")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.pcd").write_text("")
    found = find_inputs("cloud", [tmp_path, str(tmp_path / "sub" / "*.pcd"), tmp_path / "a.pcd"])
    assert [p.name for p in found] == ["a.pcd", "b.PLY", "a.pcd"]
    assert item_names(found) == ["a", "b", "a_2"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no input for cloud"):
        find_inputs("cloud", [tmp_path / "empty"])
    with pytest.raises(InputError, match="matches no file"):
        find_inputs("cloud", [str(tmp_path / "nothing*.pcd")])
    with pytest.raises(InputError, match="no such file"):
        find_inputs("edges", [tmp_path / "missing.png"])
    with pytest.raises(InputError, match="job must be one of"):
        find_inputs("nope", [tmp_path])
    with pytest.raises(InputError, match="not a stereo pair folder"):
        find_inputs("stereo", [tmp_path / "a.pcd"])
    with pytest.raises(InputError, match="not a recording folder"):
        find_inputs("plane-track", [tmp_path / "a.pcd"])
    with pytest.raises(InputError, match="do not apply to edges"):
        run_batch("edges", [tmp_path / "a.pcd"], tmp_path / "o", options={"voxel": 0.1})
    with pytest.raises(InputError, match="scheduler must be 'local'"):
        run_batch("cloud", [tmp_path / "a.pcd"], tmp_path / "o", scheduler="127.0.0.1:8786")


def test_plane_track_item_equals_run_plane_tracking(tmp_path) -> None:
    from robopercept.pipelines.plane_outputs import run_plane_tracking
    from robopercept.sources import SyntheticRGBDScene, TUMFolderSource, write_tum_folder

    rec = write_tum_folder(tmp_path / "rec1", SyntheticRGBDScene(n_frames=3, seed=1))
    assert find_inputs("plane-track", [tmp_path]) == [rec]
    got = run_item("plane-track", rec, tmp_path / "o" / "rec1")
    want = run_plane_tracking(TUMFolderSource(rec), tmp_path / "ref", video=False,
                              progress=False)  # fmt: skip
    assert got["summary"]["frames"] == want.frames == 3
    assert got["outputs"] == sorted(want.outputs) or set(want.outputs) <= set(got["outputs"])


@pytest.mark.realdata
def test_plane_track_item_of_a_realsense_bag(tmp_path) -> None:
    from robopercept.pipelines.plane_outputs import run_plane_tracking
    from robopercept.sources.realsense import RealSenseSource

    pytest.importorskip("pyrealsense2")
    bag = data_path("rgbd", "realsense_bag", "single_depth_color_640x480.bag")
    assert find_inputs("plane-track", [bag.parent]) == [bag]
    got = run_item("plane-track", bag, tmp_path / "o")
    want = run_plane_tracking(RealSenseSource(bag), tmp_path / "ref", video=False,
                              progress=False)  # fmt: skip
    assert got["summary"]["frames"] == want.frames > 0

    def rows(folder: Path) -> list[list[str]]:  # plane.csv without its timing column (ms)
        return [line.split(",")[:-1] for line in (folder / "plane.csv").read_text().splitlines()]

    assert rows(tmp_path / "o") == rows(tmp_path / "ref") and len(rows(tmp_path / "o")) > 1


@pytest.mark.realdata
def test_nn_cloud_equals_classify_cloud_file(tmp_path) -> None:
    pytest.importorskip("torch")
    from robopercept.nn.cloud.run import classify_cloud_file, shipped_cloud_model
    from robopercept.nn.cloud.train import load_cloud_model

    clouds = [
        data_path("pointcloud_cls", "ModelNet40", "monitor", "test", "monitor_0466.off"),
        data_path("pointcloud_cls", "ModelNet10", "sofa", "test", "sofa_0681.off"),
    ]
    res = run_batch("nn-cloud", clouds, tmp_path / "o", workers=1, progress=False)
    assert [r["status"] for r in res.items] == ["ok", "ok"], res.items
    model, info = load_cloud_model(shipped_cloud_model("pointnet"))
    for rec, src in zip(res.items, clouds, strict=True):
        assert rec["outputs"] == [f"{rec['item']}/prediction.json"]
        got = json.loads((res.out / rec["outputs"][0]).read_text())
        want = classify_cloud_file(src, model, info).to_dict()
        assert got["class"] == want["class"] == rec["summary"]["class"]
        assert list(got["probabilities"]) == list(want["probabilities"])
        assert got["points"] == want["points"] and got["file"] == want["file"]
        # the same points (seed 0) and weights; another process may sum in another order
        # (thread count), so the probabilities (rounded to 1e-6) agree to 1e-5
        for k, v in want["probabilities"].items():
            assert got["probabilities"][k] == pytest.approx(v, abs=1e-5)
    assert find_inputs("nn-cloud", [clouds[0].parent]) == sorted(clouds[0].parent.glob("*.off"))


def test_stereo_pairs_and_options(tmp_path) -> None:
    for folder, names in {"p1": ("im2.png", "im6.png", "disp2.png"),
                          "p2": ("left.JPG", "right.jpg", "im0.png", "im1.png"),
                          "p3": ("im0.png", "view5.png")}.items():  # fmt: skip
        (tmp_path / folder).mkdir()
        for n in names:
            (tmp_path / folder / n).write_bytes(b"")
    assert [p.name for p in stereo_pair(tmp_path / "p1")] == ["im2.png", "im6.png"]
    assert [p.name for p in stereo_pair(tmp_path / "p2")] == ["left.JPG", "right.jpg"]
    assert stereo_pair(tmp_path / "p3") is None and stereo_pair(tmp_path / "p1" / "x") is None
    assert find_inputs("stereo", [tmp_path]) == [tmp_path / "p1", tmp_path / "p2"]
    assert find_inputs("stereo", [tmp_path / "p2"]) == [tmp_path / "p2"]
    bad = {
        "needs max_disparity": {},
        "must be below max_disparity": {"max_disparity": 8, "min_disparity": 8},
        "method must be one of": {"max_disparity": 8, "method": "canny"},
        "lr_check must be": {"max_disparity": 8, "lr_check": -1.0},
    }
    for message, opts in bad.items():
        with pytest.raises(InputError, match=message):
            run_batch("stereo", [tmp_path / "p1"], tmp_path / "o", options=opts)
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_nn_options_are_checked_before_the_cluster_starts(tmp_path) -> None:
    img = tmp_path / "a.png"
    img.write_bytes(b"")
    with pytest.raises(InputError, match="the nn-predict job needs model"):
        run_batch("nn-predict", [img], tmp_path / "o")
    with pytest.raises(InputError, match=r"model nowhere\.pt: no such file.*fcos"):
        run_batch("nn-detect", [img], tmp_path / "o", options={"model": "nowhere.pt"})
    with pytest.raises(InputError, match="top_k must be >= 1"):
        run_batch("nn-predict", [img], tmp_path / "o", options={"model": img, "top_k": 0})
    with pytest.raises(InputError, match="do not apply to nn-pose"):
        run_batch("nn-pose", [img], tmp_path / "o", options={"score_thresh": 0.5})
    assert not (tmp_path / "o").exists()


def test_nn_image_jobs_equal_the_library_predictor(tmp_path, torch_one_thread) -> None:
    """nn-detect, nn-segment (U-Net and Mask R-CNN), nn-pose on one LocalCluster worker
    write what :func:`~robopercept.nn.predict.load_image_predictor` gives in this
    process: the same record (JSON) and byte-equal pictures. This process predicts with
    one torch thread, as the worker does (OMP_NUM_THREADS=1): float sums, hence the last
    bits of a score, depend on the thread count (with two threads the test passed only
    when an earlier test had left one)."""
    pytest.importorskip("torch")
    import numpy as np

    from robopercept.imaging import write_image
    from robopercept.nn.detection.synthetic import procedural_detection_set
    from robopercept.nn.pose.data import procedural_pose_set
    from robopercept.nn.predict import load_image_predictor

    def png(name: str, image: np.ndarray) -> Path:
        return write_image(tmp_path / "in" / name, np.round(image * 255).astype(np.uint8))

    (tmp_path / "in").mkdir()
    shapes = [png(f"shapes{i}.png", im) for i, im in
              enumerate(procedural_detection_set(2, (96, 96), rng=5).images)]  # fmt: skip
    figure = [png("figure.png", procedural_pose_set(1, (128, 128), rng=5).images[0])]
    runs = [("nn-detect", None, shapes), ("nn-segment", None, shapes[:1]),
            ("nn-segment", "maskrcnn", shapes[:1]), ("nn-pose", None, figure)]  # fmt: skip
    for k, (job, model, inputs) in enumerate(runs):
        opts = {} if model is None else {"model": model}
        res = run_batch(job, inputs, tmp_path / f"o{k}", workers=1, options=opts,
                        progress=False)  # fmt: skip
        assert res.count("ok") == len(inputs), res.items
        predictor = load_image_predictor(job.removeprefix("nn-"), model)
        for rec, src in zip(res.items, inputs, strict=True):
            pred = predictor.predict_file(src)
            got = json.loads((res.out / rec["item"] / "prediction.json").read_text())
            assert got == json.loads(json.dumps({"file": str(src), **pred.record()}))
            want = pred.pictures("prediction")
            assert rec["outputs"] == [f"{rec['item']}/{n}" for n in
                                      sorted(["prediction.json", *want])]  # fmt: skip
            ref = pred.write(tmp_path / "ref" / f"{k}{rec['item']}", "prediction")
            for path in ref:
                assert (res.out / rec["item"] / path.name).read_bytes() == path.read_bytes()


def test_nn_predict_job_equals_nn_predict(tmp_path) -> None:
    pytest.importorskip("torch")
    from robopercept.imaging import write_image
    from robopercept.nn.classification.run import predict, train_run
    from robopercept.nn.data.datasets import load_digits
    from robopercept.nn.train.config import TrainConfig

    run = tmp_path / "run"
    train_run("digits", "vgg_small", run, config=TrainConfig(epochs=1, seed=0), progress=False)
    x = load_digits().images
    inputs = [write_image(tmp_path / "in" / f"d{i}.png", (x[i, 0] * 255).round().astype("uint8"))
              for i in range(3)]  # fmt: skip
    out = tmp_path / "o"
    res = run_batch("nn-predict", inputs, out, workers=1, options={"model": run, "top_k": 2},
                    progress=False)  # fmt: skip
    assert res.count("ok") == 3, res.items
    for rec, want in zip(res.items, predict(run, inputs, top_k=2), strict=True):
        got = json.loads((out / rec["item"] / "prediction.json").read_text())
        assert got["file"] == str(want.path)
        assert [t["class"] for t in got["top"]] == [c for c, _ in want.top]
        # another process, the same weights and input: the probabilities agree closely
        for t, (_, p) in zip(got["top"], want.top, strict=True):
            assert t["probability"] == pytest.approx(p, abs=1e-6)
