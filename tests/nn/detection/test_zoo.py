"""Tests of robopercept.nn.detection.zoo: save_detector refuses bad settings and classes."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from tests.nn.detection.detectors import build  # noqa: E402

pytestmark = pytest.mark.usefixtures("torch_one_thread")


@pytest.mark.parametrize(
    ("settings", "classes", "msg"),
    [
        (3, ["a", "b"], "settings must be a dict"),
        (None, ["a", "b"], "settings must be a dict"),
        (np.eye(3), ["a", "b"], "settings must be a dict"),
        ({"width": 4}, 2, "classes must be a non-empty list"),
        ({"width": 4}, [1, 2], "classes must be a non-empty list"),
    ],
)
def test_save_detector_bad_settings_or_classes(tmp_path, settings, classes, msg):
    from robopercept.nn.detection.zoo import save_detector

    with pytest.raises(InputError, match=msg):
        save_detector(tmp_path / "d.pt", build("fcos", 2), "fcos", settings, classes)
    assert not (tmp_path / "d.pt").exists()
