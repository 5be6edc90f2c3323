"""``robopercept warmup`` and the first-use compile notice of every command (issue 22)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.cli.main import build_parser, main
from robopercept.cli.warmup import FIRST_USE_SECONDS, first_use_seconds, workloads
from robopercept.pipelines.samples import make_inputs

#: commands with no workload, and why: they compile nothing of their own (info, the
#: warmup itself), run a workload's code on other inputs (plane-track, synth-rgbd and
#: rgbd-import: the demo's renderer and tracker), or need data a user brings
#: (train-hog trains for minutes; handeye reads robot poses)
_INPUT_NAMES = ("image", "image2", "left", "right", "video", "cloud", "table")
_INPUT_NAMES += ("board0", "board1", "board2")
NO_WORKLOAD = {"info", "warmup", "plane-track", "synth-rgbd", "rgbd-import", "train-hog", "handeye"}
NO_WORKLOAD |= {"nn"}  # torch networks: no numba kernel to compile (issue 23)
NO_WORKLOAD |= {"stereo-calibrate"}  # the calibrate workload compiles its kernels
NO_WORKLOAD |= {"batch"}  # runs the other commands' jobs: their workloads compile them


def _commands() -> set[str]:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return set(sub.choices)  # type: ignore[attr-defined]


def test_every_command_has_a_workload_or_a_reason() -> None:
    lines = workloads(dict.fromkeys(_INPUT_NAMES, "x"), "out")
    covered = {argv[0] for argv in lines.values()}
    assert covered | NO_WORKLOAD == _commands()
    assert not covered & NO_WORKLOAD


_INPUT_NAMES = (
    "image",
    "image2",
    "left",
    "right",
    "video",
    "cloud",
    "table",
    "board0",
    "board1",
    "board2",
)


def test_estimates_name_real_commands() -> None:
    assert set(FIRST_USE_SECONDS) <= _commands()
    assert first_use_seconds("stereo") == FIRST_USE_SECONDS["stereo"]
    assert first_use_seconds("info") is None


def test_inputs_are_written_and_readable(tmp_path) -> None:
    from robopercept.imaging import VideoReader, read_image
    from robopercept.pointcloud import read_point_cloud

    paths = make_inputs(tmp_path)
    assert set(paths) == set(_INPUT_NAMES)
    a, b = read_image(paths["image"]), read_image(paths["image2"])
    assert a.ndim == 3 and np.array_equal(np.roll(a, (3, 6), axis=(0, 1)), b)
    left, right = read_image(paths["left"]), read_image(paths["right"])
    assert np.array_equal(np.roll(left, -4, axis=1), right)
    with VideoReader(paths["video"]) as video:
        assert len(list(video)) == 8
    assert len(read_point_cloud(paths["cloud"]).points) == 3800
    assert paths["table"].read_text().count("\n") == 91


def test_list_and_unknown_workload(capsys) -> None:
    assert main(["warmup", "--list"]) == 0
    names = capsys.readouterr().out.split("\n")
    assert "stereo sgm" in names and "demo" in names
    assert main(["warmup", "--only", "nope"]) == 2
    assert "unknown workload(s) nope (see --list)" in capsys.readouterr().err


def test_warmup_runs_workloads_and_reports(capsys) -> None:
    code = main(["warmup", "--only", "edges sobel", "learn kmeans", "--jobs", "1", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert [w["name"] for w in out["workloads"]] == ["edges sobel", "learn kmeans"]
    assert all(w["exit_code"] == 0 and w["error"] == "" for w in out["workloads"])


@pytest.mark.parametrize("name", ["calibrate", "demo"])
def test_heavier_workloads_succeed(name, capsys) -> None:
    assert main(["warmup", "--only", name, "--jobs", "1", "--quiet"]) == 0
    assert "1 workloads" in capsys.readouterr().out
