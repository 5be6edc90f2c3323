"""``pipelines.batch`` and ``robopercept batch`` under hostile manifests, options and
scheduler addresses (issue 47, R34-R36, R58): a typed error naming the fix, never an
untyped one (exit 70), and ``--resume`` never keeping results of other options or
outputs outside an item's folder.

The batches that run items use one in-process Dask cluster on TCP (started once, well
under a second); a manifest written by hand stands for an earlier batch.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robopercept.cli.main import main
from robopercept.errors import ArgumentError, FileFormatError, InputError
from robopercept.imaging import sample_image_path
from robopercept.pipelines.batch import (
    MANIFEST,
    MAX_OUTPUTS,
    MAX_WORKERS,
    local_cluster,
    read_manifest,
    run_batch,
)

distributed = pytest.importorskip("distributed")

EDGES_OPTIONS = {"method": "canny", "sigma": 1.0}


@pytest.fixture(scope="module")
def address() -> Iterator[str]:
    """A scheduler and one worker thread in this process, reached over TCP."""
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tcp://",
        dashboard_address=None,
        silence_logs=40,
    ) as cluster:
        yield cluster.scheduler_address


def _inputs(tmp_path: Path, *names: str) -> list[Path]:
    (tmp_path / "in").mkdir(exist_ok=True)
    paths = []
    for n in names:
        paths.append(tmp_path / "in" / f"{n}.png")
        shutil.copy(sample_image_path(), paths[-1])
    return paths


def _record(name: str, src: Path, **over: Any) -> dict[str, Any]:
    rec = {"item": name, "input": str(src), "status": "ok", "attempts": 1, "seconds": 0.1,
           "worker": "", "error": "", "outputs": [f"{name}/edges.png"]}  # fmt: skip
    rec.update(over)
    return rec


def _earlier(out: Path, doc: Any, *done: str) -> bytes:
    """An earlier batch in ``out``: the manifest ``doc`` (a dict, or raw text or bytes)
    and ``edges.png`` of the items ``done``; returns the manifest's bytes."""
    out.mkdir(parents=True, exist_ok=True)
    for name in done:
        (out / name).mkdir(exist_ok=True)
        shutil.copy(sample_image_path(), out / name / "edges.png")
    raw = doc if isinstance(doc, str | bytes) else json.dumps(doc)
    raw = raw.encode() if isinstance(raw, str) else raw
    (out / MANIFEST).write_bytes(raw)
    return raw


# -- R34: a damaged manifest ---------------------------------------------------------------


def _damaged(src: str) -> dict[str, Any]:
    """Manifests whose every field in turn has the wrong type."""
    good = _record("a", Path(src))

    def items(**over: Any) -> dict[str, Any]:
        return {"job": "edges", "options": EDGES_OPTIONS, "items": [{**good, **over}]}

    return {
        "not JSON": "{",
        "not UTF-8": b"\xff\xfe{}",
        "nested 100000 deep": "[" * 100000 + "]" * 100000,
        "nested deep inside": json.dumps(items(summary=json.loads("[" * 100 + "]" * 100))),
        "a list": "[]",
        "job a number": {"job": 1, "options": EDGES_OPTIONS, "items": []},
        "no job": {"options": EDGES_OPTIONS, "items": []},
        "options a list": {"job": "edges", "options": ["canny"], "items": []},
        "items an object": {"job": "edges", "options": EDGES_OPTIONS, "items": {"a": 1}},
        "no items": {"job": "edges", "options": EDGES_OPTIONS},
        "a record a number": {"job": "edges", "options": EDGES_OPTIONS, "items": [1]},
        "item unhashable": items(item=["a"]),
        "item empty": items(item=""),
        "input an object": items(input={"x": 1}),
        "status unknown": items(status="done"),
        "status unhashable": items(status=["ok"]),
        "outputs numbers": items(outputs=[1, 2]),
        "outputs a string": items(outputs="a/edges.png"),
        "outputs nested": items(outputs=[["a/edges.png"]]),
        "attempts a string": items(attempts="1"),
        "attempts negative": items(attempts=-1),
        "attempts a bool": items(attempts=True),
        "seconds a string": items(seconds="fast"),
        "worker a number": items(worker=5),
        "error null": items(error=None),
    }


@pytest.mark.parametrize("case", list(_damaged("x")))
def test_a_damaged_manifest_is_a_file_format_error_naming_overwrite(tmp_path, case) -> None:
    [src] = _inputs(tmp_path, "a")
    out = tmp_path / "out"
    raw = _earlier(out, _damaged(str(src))[case], "a")
    with pytest.raises(FileFormatError, match=r"batch\.json.*--overwrite") as info:
        run_batch("edges", [src], out, resume=True, progress=False)
    assert str(out / MANIFEST) in str(info.value)
    assert (out / MANIFEST).read_bytes() == raw  # left as it was
    with pytest.raises(FileFormatError):
        read_manifest(out)
    # --overwrite starts again without reading it (no cluster needed to check: the
    # refusal above came before any was started)


def test_a_manifest_that_is_a_folder(tmp_path) -> None:
    [src] = _inputs(tmp_path, "a")
    (tmp_path / "out" / MANIFEST).mkdir(parents=True)
    with pytest.raises(FileFormatError, match=r"is a folder.*--overwrite"):
        run_batch("edges", [src], tmp_path / "out", resume=True, progress=False)


@pytest.mark.parametrize("case", ["item unhashable", "nested 100000 deep", "outputs numbers"])
def test_the_command_exits_1_on_a_damaged_manifest(tmp_path, capsys, case) -> None:
    [src] = _inputs(tmp_path, "a")
    out = tmp_path / "out"
    _earlier(out, _damaged(str(src))[case], "a")
    assert main(["batch", "edges", str(src), "-o", str(out), "--resume", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert f"robopercept: error: {out / MANIFEST}" in err and "--overwrite" in err


# -- R36: --resume under other options --------------------------------------------------


def test_resume_under_other_options_is_refused_naming_overwrite(tmp_path) -> None:
    [src] = _inputs(tmp_path, "a")
    out = tmp_path / "out"
    doc = {"job": "edges", "options": EDGES_OPTIONS, "items": [_record("a", src)]}
    raw = _earlier(out, doc, "a")
    with pytest.raises(ArgumentError, match=r"method='sobel' \(the manifest has 'canny'\)"):
        run_batch("edges", [src], out, resume=True, options={"method": "sobel"}, progress=False)
    with pytest.raises(ArgumentError, match="--overwrite"):
        run_batch("edges", [src], out, resume=True, options={"sigma": 2.0}, progress=False)
    assert (out / MANIFEST).read_bytes() == raw  # not rewritten
    # the same options (defaults filled in) resume: every item done, no cluster needed
    res = run_batch("edges", [src], out, resume=True, options={"method": "canny"},
                    progress=False)  # fmt: skip
    assert [r["status"] for r in res.items] == ["skipped"]
    assert read_manifest(out)["options"] == EDGES_OPTIONS


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ({"job": "features", "options": {"detector": "harris", "max": 500}},
         r"the 'features' job, not edges.*--overwrite"),
        ({"job": "edges"}, r"records no options.*--overwrite"),  # an older manifest
        ({"job": "edges", "options": {**EDGES_OPTIONS, "voxel": 0.1}},
         r"'voxel' \(the manifest has it; edges takes no such option\)"),
        ({"job": "edges", "options": {"method": "canny"}}, r"sigma=1\.0 \(the manifest has no"),
    ],
)  # fmt: skip
def test_resume_of_another_job_or_unrecorded_options_is_refused(tmp_path, doc, message) -> None:
    [src] = _inputs(tmp_path, "a")
    out = tmp_path / "out"
    raw = _earlier(out, {**doc, "items": [_record("a", src)]}, "a")
    with pytest.raises(ArgumentError, match=message):
        run_batch("edges", [src], out, resume=True, progress=False)
    assert (out / MANIFEST).read_bytes() == raw


# acceptance of issue 47: `batch --resume` under changed options exits 2 naming --overwrite
def test_the_command_refuses_resume_under_changed_options_with_exit_2(
    tmp_path, capsys, address
) -> None:
    srcs = _inputs(tmp_path, "a", "b")
    out = tmp_path / "out"
    argv = ["batch", "edges", *map(str, srcs), "-o", str(out), "--scheduler", address, "--quiet"]
    assert main(argv) == 0  # canny
    capsys.readouterr()
    before = (out / MANIFEST).read_bytes()
    pictures = [(out / n / "edges.png").read_bytes() for n in ("a", "b")]
    assert main([*argv, "--resume", "--method", "sobel"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"robopercept: error: {out / MANIFEST}: --resume under other options")
    assert "--method sobel (the manifest has 'canny')" in err and "--overwrite" in err
    assert (out / MANIFEST).read_bytes() == before
    assert [(out / n / "edges.png").read_bytes() for n in ("a", "b")] == pictures
    assert main([*argv, "--overwrite", "--method", "sobel", "--json"]) == 0  # the fix works
    assert json.loads(capsys.readouterr().out)["ok"] == 2
    assert read_manifest(out)["options"]["method"] == "sobel"
    assert main([*argv, "--resume", "--method", "sobel", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["skipped"] == 2


def test_a_model_path_is_recorded_absolute(tmp_path, monkeypatch) -> None:
    """A model given by a relative path is the same model from another folder."""
    [src] = _inputs(tmp_path, "a")
    model = tmp_path / "m" / "model.pt"
    model.parent.mkdir()
    model.write_bytes(b"")
    out = tmp_path / "out"
    opts = {"model": str(model), "points": None, "seed": 0}
    _earlier(out, {"job": "nn-cloud", "options": opts, "items": [_record("a", src)]}, "a")
    monkeypatch.chdir(model.parent)
    res = run_batch("nn-cloud", [src], out, resume=True, options={"model": "model.pt"},
                    progress=False)  # fmt: skip
    assert [r["status"] for r in res.items] == ["skipped"]


# -- R35: outputs outside the item's folder ------------------------------------------------


def test_resume_redoes_items_whose_outputs_are_not_their_own(tmp_path, address) -> None:
    srcs = _inputs(tmp_path, "a", "b", "c", "d", "e", "f")
    out = tmp_path / "out"
    outside = tmp_path / "outside.png"
    shutil.copy(sample_image_path(), outside)
    (out / "e").mkdir(parents=True)
    os.symlink(outside, out / "e" / "edges.png")  # a link out of its folder
    items = [
        _record("a", srcs[0], outputs=["b/edges.png"]),  # another item's file
        _record("b", srcs[1]),  # done, its file there
        _record("c", srcs[2], outputs=["../outside.png"]),
        _record("d", srcs[3], outputs=[str(outside)]),  # absolute
        _record("e", srcs[4]),
        _record("f", srcs[5], outputs=["f/../b/edges.png"]),
    ]
    _earlier(out, {"job": "edges", "options": EDGES_OPTIONS, "items": items}, "b")
    res = run_batch("edges", srcs, out, resume=True, scheduler=address, progress=False)
    assert [r["status"] for r in res.items] == ["ok", "skipped", "ok", "ok", "ok", "ok"]
    for r in res.items:
        assert r["outputs"] == [f"{r['item']}/edges.png"]
        assert (out / r["item"] / "edges.png").is_file()
        assert not (out / r["item"] / "edges.png").is_symlink()
    assert outside.is_file()  # never touched


# -- R58: scheduler addresses -------------------------------------------------------------

BAD_SCHEDULERS = {
    "tls://127.0.0.1:8786": "tls:// protocol needs certificates",
    "ucx://127.0.0.1:8786": "ucx:// protocol needs UCX",
    "tcp://127.0.0.1": "the port is missing",
    "tcp://127.0.0.1:0": "port must be a number from 1 to 65535",
    "tcp://127.0.0.1:65536": "port must be a number from 1 to 65535",
    "tcp://127.0.0.1:http": "port must be a number from 1 to 65535",
    "tcp://127.0.0.1:8786/x": "port must be a number from 1 to 65535",
    "tcp://:8786": "is not a host name or address",
    "tcp://a b:8786": "is not a host name or address",
    "tcp://[::zz]:8786": "[IPv6] host or its :PORT",
    "tcp://[::1]": "[IPv6] host or its :PORT",
    "TCP://127.0.0.1:8786": "is written tcp:// (lower case)",
    "foo://127.0.0.1:8786": "foo:// protocol is not one a batch can use",
    "inproc://10.0.0.1/1/1": "inproc:// protocol reaches only a cluster inside this process",
    "127.0.0.1:8786": "write tcp://127.0.0.1:8786",
    "": "got ''",
    "\x00\xff garbage": "got ",
}


@pytest.mark.parametrize("scheduler", list(BAD_SCHEDULERS))
def test_unusable_scheduler_addresses_are_refused_before_connecting(
    tmp_path, monkeypatch, scheduler
) -> None:
    def no_client(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("connected")

    monkeypatch.setattr(distributed, "Client", no_client)
    [src] = _inputs(tmp_path, "a")
    with pytest.raises(ArgumentError, match="tcp://HOST:PORT") as info:
        run_batch("edges", [src], tmp_path / "o", scheduler=scheduler, progress=False)
    assert BAD_SCHEDULERS[scheduler] in str(info.value)
    assert str(info.value).startswith("scheduler must be 'local' or the address")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("scheduler", [8786, None, b"tcp://127.0.0.1:8786", ["local"]])
def test_a_scheduler_that_is_not_a_string(tmp_path, scheduler) -> None:
    [src] = _inputs(tmp_path, "a")
    with pytest.raises(ArgumentError, match=r"scheduler must be .*; got "):
        run_batch("edges", [src], tmp_path / "o", scheduler=scheduler, progress=False)


@pytest.mark.parametrize("scheduler", ["tls://127.0.0.1:8786", "ucx://h:1", "tcp://h", "tcp://h:0",
                                       "tcp://h:99999", "bogus://h:1", "no-scheme"])  # fmt: skip
def test_the_command_refuses_unusable_addresses_with_exit_2(tmp_path, capsys, scheduler) -> None:
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"),
            "--scheduler", scheduler]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("robopercept: error: --scheduler must be 'local' or the address")
    assert "tcp://HOST:PORT" in err and "internal error" not in err
    assert not (tmp_path / "o").exists()


def test_accepted_forms_reach_the_connection(tmp_path, monkeypatch) -> None:
    seen = []

    def client(address: str, **kwargs: Any) -> None:
        seen.append(address)
        raise OSError("nobody there")

    monkeypatch.setattr(distributed, "Client", client)
    [src] = _inputs(tmp_path, "a")
    for good in ("tcp://127.0.0.1:8786", "tcp://[::1]:8786", "tcp://node-1.cluster.local:1",
                 "tcp://worker_2:65535"):  # fmt: skip
        with pytest.raises(InputError, match="no Dask scheduler answered"):
            run_batch("edges", [src], tmp_path / "o", scheduler=good, overwrite=True,
                      progress=False)  # fmt: skip
    assert seen == ["tcp://127.0.0.1:8786", "tcp://[::1]:8786", "tcp://node-1.cluster.local:1",
                    "tcp://worker_2:65535"]  # fmt: skip


# -- E1-F6, N2: bounds on a manifest's outputs and on --workers ----------------------------


def test_a_record_listing_too_many_outputs_is_refused_quickly(tmp_path) -> None:
    """E1-F6: --resume checked each of 100,000 listed outputs (10 s)."""
    import time

    [src] = _inputs(tmp_path, "a")
    out = tmp_path / "out"
    many = [f"a/{k}.png" for k in range(MAX_OUTPUTS + 1)]
    doc = {"job": "edges", "options": EDGES_OPTIONS, "items": [_record("a", src, outputs=many)]}
    _earlier(out, doc, "a")
    start = time.perf_counter()
    with pytest.raises(FileFormatError, match=rf"items\[0\]\.outputs lists {MAX_OUTPUTS + 1} "):
        run_batch("edges", [src], out, resume=True, progress=False)
    assert time.perf_counter() - start < 2.0
    doc["items"][0]["outputs"] = many[:MAX_OUTPUTS]  # the bound itself is read
    _earlier(out, doc, "a")
    assert len(read_manifest(out)["items"][0]["outputs"]) == MAX_OUTPUTS


@pytest.mark.parametrize("workers", [MAX_WORKERS + 1, 2**63])
def test_too_many_workers_are_refused_before_any_start(tmp_path, workers) -> None:
    """N2: --workers had no upper bound (2**63 processes would be started)."""
    with pytest.raises(InputError, match=rf"workers must be at most {MAX_WORKERS}"):
        run_batch("edges", [sample_image_path()], tmp_path / "o", workers=workers, progress=False)
    with pytest.raises(InputError, match=rf"workers must be at most {MAX_WORKERS}"):
        local_cluster(workers)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("workers", [str(MAX_WORKERS + 1), "9" * 30, "9" * 5000])
def test_the_command_refuses_too_many_workers_with_exit_2(tmp_path, capsys, workers) -> None:
    argv = ["batch", "edges", str(sample_image_path()), "-o", str(tmp_path / "o"),
            "--workers", workers]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--workers" in err and "internal error" not in err
    assert not (tmp_path / "o").exists()
