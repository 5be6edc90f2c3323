"""The messages about the real-data folders (StarDist nuclei, DeepForest NEON) say what
the folder is, what it must hold and where it comes from upstream, never a folder of
the development checkout (``../shared/data/...``)."""

from __future__ import annotations

from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import ArgumentError, InputError  # noqa: E402
from robopercept.nn.detection.deepforest import (  # noqa: E402
    DEEPFOREST_IMAGES,
    deepforest_strip,
    deepforest_tiles,
)
from robopercept.nn.detection.run import load_detection_data  # noqa: E402
from robopercept.nn.segmentation.data import nuclei_quadrants, segmentation_sets  # noqa: E402
from robopercept.nn.segmentation.run import load_segmentation_data  # noqa: E402

SRC = Path(__file__).resolve().parents[2] / "src" / "robopercept"
#: what names a development folder rather than a dataset
DEVELOPMENT = ("shared/data", "../shared", "stardist_nuclei", "deepforest_neon")


def _no_development_folder(msg: str) -> None:
    for word in DEVELOPMENT:
        assert word not in msg, (word, msg)


def _names_the_nuclei_sample(msg: str) -> None:
    for needle in ("StarDist nuclei sample", "img2d.tif", "mask2d.tif", "stardist/data/images/"):
        assert needle in msg, (needle, msg)
    _no_development_folder(msg)


def _names_the_deepforest_sample(msg: str) -> None:
    for needle in ("DeepForest NEON", "Pascal-VOC .xml", "deepforest/data/", *DEEPFOREST_IMAGES):
        assert needle in msg, (needle, msg)
    _no_development_folder(msg)


def test_nuclei_folder_messages_name_the_dataset(tmp_path):
    with pytest.raises(InputError, match=r"nuclei folder .*nowhere.* does not exist") as info:
        nuclei_quadrants(tmp_path / "nowhere")
    _names_the_nuclei_sample(str(info.value))
    with pytest.raises(InputError, match=r"needs its folder \(folder=\)") as info:
        segmentation_sets("nuclei")
    _names_the_nuclei_sample(str(info.value))


@pytest.mark.parametrize("images_dir", [None, "/nonexistent/nuclei"])
def test_nuclei_run_message_names_the_flag_and_the_dataset(images_dir):
    with pytest.raises(InputError, match=r"^--images-dir: --data nuclei needs") as info:
        load_segmentation_data("nuclei", images_dir=images_dir)
    _names_the_nuclei_sample(str(info.value))


def test_deepforest_folder_messages_name_the_dataset(tmp_path):
    for read in (deepforest_tiles, deepforest_strip):
        with pytest.raises(
            InputError, match=r"DeepForest folder .*nowhere.* does not exist"
        ) as info:
            read(tmp_path / "nowhere")
        _names_the_deepforest_sample(str(info.value))


@pytest.mark.parametrize("images_dir", [None, "no_such_folder"])
def test_trees_run_message_names_the_flag_and_the_dataset(images_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ArgumentError, match=r"^--images-dir: --data trees needs") as info:
        load_detection_data("trees", images_dir=images_dir)
    _names_the_deepforest_sample(str(info.value))


def test_no_library_text_names_the_development_data_folder():
    """No message or docstring of the package points at the checkout's shared data."""
    found = [
        f"{path.relative_to(SRC)}:{n}"
        for path in sorted(SRC.rglob("*.py"))
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if "shared/data" in line
    ]
    assert found == []
