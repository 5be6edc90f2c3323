"""The pose networks shipped in ``robopercept/data`` (issue 28): they load, keep their
build command and skeleton, and still find the joints of the procedural figures they
were trained on, from the Python API and from ``robopercept nn pose IMAGE``."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.cli.main import main  # noqa: E402
from robopercept.imaging import write_image  # noqa: E402
from robopercept.nn.pose.data import procedural_pose_set  # noqa: E402
from robopercept.nn.pose.evaluate import evaluate_pose  # noqa: E402
from robopercept.nn.pose.networks import load_pose_model  # noqa: E402
from robopercept.nn.shipped import SHIPPED_POSE_MODELS  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.fixture(scope="module")
def test_set():
    # the first 40 figures of the benchmark's test split (seed 99), never trained on
    return procedural_pose_set(40, (128, 128), rng=99)


def _path(name: str) -> Path:
    return Path(str(files("robopercept"))) / SHIPPED_POSE_MODELS[name]


#: PCK@0.1 measured on these 40 figures (with the flip test) when the models were saved
MEASURED = {"hrnet": 0.933, "deeppose": 0.781}


@pytest.mark.parametrize("name", sorted(MEASURED))
def test_shipped_networks_still_find_the_joints(name, test_set):
    # the margin allows for a few joints flipping with another CPU's arithmetic; an
    # untrained or wrongly loaded network scores near 0.05
    path = _path(name)
    assert path.is_file(), f"{path} is not shipped (see robopercept/data/SOURCES.md)"
    model, info = load_pose_model(path)
    assert info["kind"] == name and info["seed"] == 0
    assert info["skeleton"].name == "mpii16" and f"--only {name}" in info["built_by"]
    ev = evaluate_pose(model, test_set, refiners=info["refiners"])
    assert ev.pck[0.1] >= MEASURED[name] - 0.04, ev.pck


def test_nn_pose_finds_a_figure_from_the_command_line(tmp_path, test_set, capsys):
    img = tmp_path / "figure.png"
    write_image(img, (test_set.images[0] * 255 + 0.5).astype(np.uint8))
    assert main(["nn", "pose", str(img), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)["results"][0]
    truth = test_set.keypoints[0]
    err = np.linalg.norm(np.asarray(row["keypoints"]) - truth[:, :2], axis=1)
    diag = np.hypot(*(test_set.boxes[0, 2:] - test_set.boxes[0, :2]))
    # most labelled joints within 10 % of the box diagonal (PCK@0.1 of one figure)
    assert (err[truth[:, 2] > 0] < 0.1 * diag).mean() >= 0.75
