"""Middlebury .flo files and the endpoint error: the RubberWhale file against
cv2.readOpticalFlow and Middlebury's stated values, round trips, bad files, hand-computed
EPE, and LK's EPE on RubberWhale under a bound."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import DegenerateError, FileFormatError, InputError
from robopercept.motion import (
    endpoint_error,
    good_features_to_track,
    known_flow,
    lucas_kanade,
    read_flo,
    write_flo,
)
from tests.conftest import data_path


@pytest.fixture(scope="module")
def rubberwhale():
    return data_path("flow", "middlebury_rubberwhale")


@pytest.mark.realdata
def test_rubberwhale_flo_has_middleburys_values(rubberwhale):
    """SOURCES.md: tag PIEH, 584 x 388, 7,244 unknown values (3,622 pixels, both
    components); every value equals cv2.readOpticalFlow's (the reference reader:
    the same float32 bytes, so exactly)."""
    path = rubberwhale / "RubberWhale.flo"
    assert path.read_bytes()[:4] == b"PIEH"
    flow = read_flo(path)
    assert flow.shape == (388, 584, 2) and flow.dtype == np.float32
    assert int((np.abs(flow) >= 1e9).sum()) == 7244
    assert int((~known_flow(flow)).sum()) == 3622
    cv2 = pytest.importorskip("cv2")
    ref = cv2.readOpticalFlow(str(path))
    np.testing.assert_array_equal(flow, ref)
    for y, x in ((100, 200), (0, 0), (387, 583), (250, 400)):
        np.testing.assert_array_equal(flow[y, x], ref[y, x])
    assert flow[100, 200].tolist() == pytest.approx([0.5310312, -0.6516469], abs=1e-6)


@pytest.mark.realdata
def test_lucas_kanade_epe_on_rubberwhale_is_under_a_bound(rubberwhale):
    """Shi-Tomasi corners tracked by LK (21 x 21, 3 levels): mean EPE 0.17 px, median
    0.04 px (OpenCV's LK: 0.165 / 0.043, tests/motion/test_flow.py); bounds with room for
    float differences: mean < 0.3, median < 0.1, under 10 % above 1 px."""
    from robopercept.imaging import read_image

    a = read_image(rubberwhale / "RubberWhale1.png", mode="gray")
    b = read_image(rubberwhale / "RubberWhale2.png", mode="gray")
    truth = read_flo(rubberwhale / "RubberWhale.flo")
    res = lucas_kanade(a, b, good_features_to_track(a, 500, 0.01, 7))
    flow = np.where(res.status[:, None], res.flow, np.nan)
    e = endpoint_error(flow, truth, res.start)
    assert np.isfinite(e.mean) and e.mean < 0.3 and e.median < 0.1 and e.over_1 < 0.1
    assert e.evaluated + e.unknown_truth + e.no_estimate == len(res)
    assert e.unknown_truth > 0  # some corners sit on the unknown (occluded) pixels


def test_write_read_round_trip_and_cv2_bytes(tmp_path):
    """Our file is byte for byte cv2.writeOpticalFlow's; NaN is written as 1e10."""
    rng = np.random.default_rng(0)
    flow = rng.normal(0, 3, (5, 7, 2)).astype(np.float32)
    ours = write_flo(tmp_path / "a.flo", flow)
    assert ours.stat().st_size == 12 + 8 * 5 * 7
    np.testing.assert_array_equal(read_flo(ours), flow)
    cv2 = pytest.importorskip("cv2")
    cv2.writeOpticalFlow(str(tmp_path / "cv.flo"), flow)
    assert ours.read_bytes() == (tmp_path / "cv.flo").read_bytes()
    flow[1, 2, 0] = np.nan
    back = read_flo(write_flo(tmp_path / "b.flo", flow))
    assert back[1, 2, 0] == 1e10 and not known_flow(back)[1, 2]


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"PIE", "too short"),
        (b"XXXX" + np.array([2, 2], "<i4").tobytes() + bytes(32), "not a Middlebury .flo"),
        (b"PIEH" + np.array([0, 2], "<i4").tobytes(), "width and height in 1..99999"),
        (b"PIEH" + np.array([2, 2], "<i4").tobytes() + bytes(31), "truncated"),
        (b"PIEH" + np.array([2, 2], "<i4").tobytes() + bytes(40), "too long"),
        (b"PIEH" + np.array([2**30, 2**30], "<i4").tobytes(), "width and height"),
    ],
)
def test_bad_flo_files(tmp_path, data, match):
    path = tmp_path / "bad.flo"
    path.write_bytes(data)
    with pytest.raises(FileFormatError, match=match):
        read_flo(path)


def test_bad_paths_and_flows(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_flo(tmp_path / "absent.flo")
    with pytest.raises(FileFormatError, match="is a folder"):
        read_flo(tmp_path)
    with pytest.raises(InputError, match=r"extension \.flo"):
        write_flo(tmp_path / "a.png", np.zeros((2, 2, 2)))
    with pytest.raises(InputError, match=r"\(H, W, 2\)"):
        write_flo(tmp_path / "a.flo", np.zeros((2, 2, 3)))


def test_endpoint_error_hand_case_dense():
    """Four pixels: errors 5 (3-4-5), 0, 2 and unknown truth (2e9), one with no
    estimate: mean (5 + 0 + 2) / 3, median 2, over 1 px 2/3, over 3 px 1/3."""
    truth = np.array([[[1.0, 0.0], [0.0, 0.0]], [[0.0, 2.0], [2e9, 2e9]]])
    flow = np.array([[[4.0, 4.0], [0.0, 0.0]], [[0.0, 0.0], [1.0, 1.0]]])
    e = endpoint_error(flow, truth)
    assert e.mean == pytest.approx(7 / 3) and e.median == pytest.approx(2.0)
    assert e.over_1 == pytest.approx(2 / 3) and e.over_3 == pytest.approx(1 / 3)
    assert (e.evaluated, e.unknown_truth, e.no_estimate) == (3, 1, 0)
    np.testing.assert_allclose(e.errors, [[5.0, 0.0], [2.0, np.nan]])
    flow[0, 1] = np.nan
    e = endpoint_error(flow, truth)
    assert (e.evaluated, e.no_estimate) == (2, 1) and e.mean == pytest.approx(3.5)
    assert set(e.to_dict()) == {
        "epe_mean", "epe_median", "over_1", "over_3", "evaluated", "unknown_truth",
        "no_estimate",
    }  # fmt: skip


def test_endpoint_error_sparse_takes_the_nearest_pixel():
    truth = np.zeros((3, 4, 2))
    truth[1, 2] = [1.0, 1.0]
    points = np.array([[2.4, 0.6], [0.0, 0.0], [9.0, 9.0]])  # (x, y): pixel (row 1, col 2)
    flow = np.array([[1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
    e = endpoint_error(flow, truth, points)
    assert e.errors[0] == 0.0 and e.errors[1] == 1.0 and np.isnan(e.errors[2])
    assert (e.evaluated, e.unknown_truth) == (2, 1)  # off the image: unknown truth


def test_endpoint_error_bad_input():
    truth = np.zeros((3, 4, 2))
    with pytest.raises(InputError, match="truth's shape"):
        endpoint_error(np.zeros((3, 5, 2)), truth)
    with pytest.raises(InputError, match="one \\(u, v\\) per point"):
        endpoint_error(np.zeros((2, 2)), truth, np.zeros((3, 2)))
    with pytest.raises(InputError, match="truth must be an \\(H, W, 2\\)"):
        endpoint_error(np.zeros((3, 4)), np.zeros((3, 4)))
    with pytest.raises(DegenerateError, match="no vector has both"):
        endpoint_error(np.full((3, 4, 2), np.nan), truth)
