"""Lucas-Kanade flow: known shifts, OpenCV parity and ground truth on RubberWhale, the
pyramid on a large motion, the failure flags, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.imaging import gaussian_blur, warp_perspective
from robopercept.motion import FlowStatus, dense_flow, good_features_to_track, lucas_kanade
from tests.conftest import data_path


def _texture(seed: int = 0, shape=(260, 300)) -> np.ndarray:
    gen = np.random.default_rng(seed)
    tex = gaussian_blur(gen.uniform(0, 1, shape), 2.0)
    return (tex - tex.min()) / (tex.max() - tex.min())


def _inner(points: np.ndarray, shape, margin: int) -> np.ndarray:
    h, w = shape
    keep = (points[:, 0] > margin) & (points[:, 0] < w - margin)
    keep &= (points[:, 1] > margin) & (points[:, 1] < h - margin)
    return points[keep]


def test_subpixel_translation_is_recovered():
    """A texture moved by (1.3, -0.7) px (bilinear warp): every interior corner's flow
    is the shift within 0.03 px, with and without the pyramid."""
    a = _texture()
    H = np.array([[1, 0, 1.3], [0, 1, -0.7], [0, 0, 1.0]])
    b = warp_perspective(a, H, a.shape[::-1])
    pts = _inner(good_features_to_track(a, 100, 0.01, 8), a.shape, 30)
    assert len(pts) > 30
    for levels in (0, 3):
        res = lucas_kanade(a, b, pts, levels=levels)
        assert res.status.all()
        np.testing.assert_allclose(res.flow, np.tile([1.3, -0.7], (len(pts), 1)), atol=0.03)
        assert (res.residual < 0.2).all()


def test_large_translation_needs_the_pyramid():
    """20 px of motion with a 21 px window: the pyramid tracks every point to 0.05 px;
    one level cannot, and every point it cannot track is flagged, none is returned
    wrong with status True."""
    tex = _texture()
    a, b = tex[20:220, 40:280], tex[20:220, 20:260]  # the content moves +20 px in x
    pts = _inner(good_features_to_track(a, 200, 0.01, 8), a.shape, 30)
    pyramid = lucas_kanade(a, b, pts, levels=3)
    assert pyramid.status.all()
    np.testing.assert_allclose(pyramid.flow, np.tile([20.0, 0.0], (len(pts), 1)), atol=0.05)
    single = lucas_kanade(a, b, pts, levels=0)
    wrong = np.linalg.norm(single.flow - [20, 0], axis=1) > 0.5
    assert wrong.sum() > len(pts) // 2  # one level really fails here
    assert not (single.status & wrong).any()
    flagged = set(single.reason[wrong].tolist())
    assert flagged <= {FlowStatus.NOT_CONVERGED, FlowStatus.HIGH_RESIDUAL}


def test_aperture_and_leaving_the_image_are_flagged():
    # a vertical edge: gradient only in x, so S^T S is singular (the aperture problem)
    edge = np.zeros((100, 100))
    edge[:, 50:] = 1.0
    res = lucas_kanade(edge, edge, [[50.0, 50.0], [20.0, 20.0]], levels=0)
    assert res.reason.tolist() == [FlowStatus.APERTURE, FlowStatus.APERTURE]
    assert not res.status.any()
    # a point whose motion carries its window off the image
    a = _texture()
    b = np.roll(a, 45, axis=1)
    res = lucas_kanade(a, b, [[290.0, 100.0]], levels=3)
    assert not res.status[0]


def test_uint8_float_and_colour_inputs_agree():
    a = _texture()
    b = warp_perspective(a, np.array([[1, 0, 0.6], [0, 1, 0.4], [0, 0, 1.0]]), a.shape[::-1])
    pts = _inner(good_features_to_track(a, 50, 0.01, 8), a.shape, 30)
    f = lucas_kanade(a, b, pts)
    u8 = lucas_kanade((a * 255).round().astype(np.uint8), (b * 255).round().astype(np.uint8), pts)
    rgb = lucas_kanade(np.dstack([a] * 3), np.dstack([b] * 3), pts)
    np.testing.assert_allclose(rgb.end, f.end, atol=1e-4)
    np.testing.assert_allclose(u8.end, f.end, atol=0.02)  # 8-bit rounding of the images


def test_dense_flow_grid():
    a = _texture()
    b = warp_perspective(a, np.array([[1, 0, 2.0], [0, 1, 1.0], [0, 0, 1.0]]), a.shape[::-1])
    grid, flow, res = dense_flow(a, b, step=20)
    assert grid.shape == flow.shape == (13, 15, 2)
    assert grid[0, 0].tolist() == [10, 10] and grid[0, 1].tolist() == [30, 10]
    inner = flow[2:-2, 2:-2].reshape(-1, 2)
    inner = inner[np.isfinite(inner).all(1)]
    assert len(inner) > 50
    np.testing.assert_allclose(np.median(inner, axis=0), [2.0, 1.0], atol=0.02)
    assert np.isnan(flow[~res.status.reshape(13, 15)]).all()


def test_bad_input():
    a = _texture()
    with pytest.raises(InputError, match="same size"):
        lucas_kanade(a, a[:100], [[10.0, 10.0]])
    with pytest.raises(InputError, match="odd"):
        lucas_kanade(a, a, [[10.0, 10.0]], window=20)
    with pytest.raises(InputError, match=r"\(N, 2\)"):
        lucas_kanade(a, a, [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="NaN"):
        lucas_kanade(a, a, [[np.nan, 1.0]])
    with pytest.raises(InputError, match="levels"):
        lucas_kanade(a, a, [[10.0, 10.0]], levels=-1)
    assert len(lucas_kanade(a, a, np.zeros((0, 2)))) == 0


def _read_flo(path) -> np.ndarray:
    with open(path, "rb") as fh:
        assert fh.read(4) == b"PIEH"
        w, h = np.frombuffer(fh.read(8), np.int32)
        return np.frombuffer(fh.read(), np.float32).reshape(h, w, 2)


@pytest.mark.realdata
def test_rubberwhale_endpoint_error_matches_opencv():
    """Middlebury RubberWhale with ground truth: for Shi-Tomasi points, our median and
    mean endpoint errors are at most 1.2x OpenCV's (21 x 21, maxLevel 3; OpenCV: 0.043
    and 0.165 px), and our end points are OpenCV's to 0.01 px for most points (float
    arithmetic against OpenCV's 14-bit fixed point)."""
    cv2 = pytest.importorskip("cv2")
    from robopercept.imaging import read_image

    folder = data_path("flow/middlebury_rubberwhale")
    a = read_image(folder / "RubberWhale1.png", mode="gray")
    b = read_image(folder / "RubberWhale2.png", mode="gray")
    gt_flow = _read_flo(folder / "RubberWhale.flo")
    pts = good_features_to_track(a, 1000, 0.01, 5)
    ref_pts = cv2.goodFeaturesToTrack(a, 1000, 0.01, 5)[:, 0]
    np.testing.assert_array_equal(np.sort(pts, axis=0), np.sort(ref_pts, axis=0))
    ours = lucas_kanade(a, b, pts, window=21, levels=3)
    ref, st, _ = cv2.calcOpticalFlowPyrLK(
        a, b, pts.astype(np.float32)[:, None], None, winSize=(21, 21), maxLevel=3
    )
    ref, st = ref[:, 0].astype(np.float64), st[:, 0] == 1
    xi, yi = np.round(pts).astype(int).T
    gt = gt_flow[yi, xi]
    known = (np.abs(gt) < 1e9).all(axis=1)

    def epe(end, ok):
        e = np.linalg.norm(end - pts - gt, axis=1)[known & ok]
        return np.median(e), e.mean()

    (med, mean), (ref_med, ref_mean) = epe(ours.end, ours.status), epe(ref, st)
    assert med <= 1.2 * ref_med and mean <= 1.2 * ref_mean, (med, mean, ref_med, ref_mean)
    assert ours.status.sum() >= 0.99 * st.sum()
    both = ours.status & st
    assert np.median(np.abs(ours.end - ref)[both]) < 1e-3
    assert np.mean(np.abs(ours.end - ref)[both].max(axis=1) < 0.01) > 0.99


# issue 25: iterations, step and the other settings reached int()/float() unchecked
# (TypeError on a list, ValueError on NaN), a window larger than the image padded it to
# any size, and NaN guesses reached the compiled tracker
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"iterations": [1, 2]}, "iterations must be an integer"),
        ({"iterations": 2**40}, "iterations must be in 1..1000"),
        ({"window": 2**40 + 1}, "window must be an odd integer in 3..300"),
        ({"levels": np.nan}, "levels must be an integer"),
        ({"eps": "0.01"}, "eps must be a real number"),
        ({"min_eigenvalue": -1.0}, "min_eigenvalue must be in"),
        ({"max_residual": 0.0}, "max_residual"),
        ({"initial": [[np.nan, 1.0]]}, "initial contains NaN"),
        ({"points": "ab"}, "points must hold real numbers"),
    ],
)
def test_hostile_settings_are_refused_by_name(kwargs, match):
    a = _texture()
    args = {"points": [[150.0, 130.0]], **kwargs}
    with pytest.raises(InputError, match=match):
        lucas_kanade(a, a, **args)


def test_dense_flow_step_and_far_points():
    a = _texture()
    with pytest.raises(InputError, match="step must be an integer"):
        dense_flow(a, a, step=np.nan)
    with pytest.raises(InputError, match=r"step must be in 1\.\.300"):
        dense_flow(a, a, step=2**63)
    # issue 25: a point far outside the image is flagged as leaving it, with its start kept
    res = lucas_kanade(a, a, [[1e300, -1e300], [150.0, 130.0]])
    assert res.start[0].tolist() == [1e300, -1e300]
    assert res.reason[0] == FlowStatus.LEFT_IMAGE and res.status[1]


# issue 48: p1, st, err = lucas_kanade(...) and OpenCV's (N, 1, 2) point vectors
def _shifted_pair():
    a = _texture(3)
    b = np.roll(a, (1, 2), axis=(0, 1))  # content moves by (+2, +1) px
    pts = np.array([[60.0, 70.0], [150.0, 120.0], [200.0, 90.0], [5.0, 5.0]])
    return a, b, pts


def test_unpacks_as_calc_optical_flow_pyr_lk_with_its_shapes():
    """(N, 2) points: p1 (N, 2) float32, st (N, 1) uint8, err (N, 1) float32, as
    cv2.calcOpticalFlowPyrLK gives for (N, 2) input; attribute access unchanged."""
    a, b, pts = _shifted_pair()
    res = lucas_kanade(a, b, pts)
    p1, st, err = res
    assert (p1.shape, p1.dtype, st.shape, st.dtype, err.shape, err.dtype) == (
        (4, 2), np.float32, (4, 1), np.uint8, (4, 1), np.float32
    )  # fmt: skip
    np.testing.assert_array_equal(st[:, 0], res.status.astype(np.uint8))
    np.testing.assert_allclose(p1, res.end, atol=1e-4)  # float32 rounding
    np.testing.assert_allclose(err[:, 0], res.error, rtol=1e-6)
    assert res.end.shape == (4, 2) and res.end.dtype == np.float64 and res.status.dtype == bool


def test_opencv_point_vectors_are_accepted_and_kept_in_the_unpacked_result():
    """(N, 1, 2) float32 points (cv2.goodFeaturesToTrack's output) give the same
    tracks as (N, 2), p1 in the (N, 1, 2) layout, and OpenCV's tutorial idiom
    ``p1[st == 1]`` works."""
    a, b, pts = _shifted_pair()
    p0 = pts.astype(np.float32)[:, None, :]
    res = lucas_kanade(a, b, p0)
    flat = lucas_kanade(a, b, pts.astype(np.float32))
    np.testing.assert_array_equal(res.end, flat.end)
    np.testing.assert_array_equal(res.status, flat.status)
    assert res.start.shape == (4, 2)
    p1, st, err = res
    assert p1.shape == (4, 1, 2) and st.shape == (4, 1) and err.shape == (4, 1)
    good_new, good_old = p1[st == 1], p0[st == 1]
    assert good_new.shape == (int(st.sum()), 2) and st.sum() >= 3
    np.testing.assert_allclose(np.median(good_new - good_old, axis=0), [2.0, 1.0], atol=0.02)
    # initial guesses in OpenCV's layout too
    again = lucas_kanade(a, b, p0, initial=p0 + np.float32(1.5))
    np.testing.assert_allclose(again.end[again.status], res.end[again.status], atol=0.02)
    with pytest.raises(InputError, match=r"OpenCV's \(N, 1, 2\)"):
        lucas_kanade(a, b, np.zeros((4, 1, 3)))


def test_unpacked_result_matches_opencv_shapes_and_values():
    """Against cv2.calcOpticalFlowPyrLK on the same (N, 1, 2) input: the same shapes and
    dtypes, the same status, end points within 0.01 px (OpenCV's 14-bit fixed point)."""
    cv2 = pytest.importorskip("cv2")
    a, b, pts = _shifted_pair()
    a8, b8 = (np.round(v * 255).astype(np.uint8) for v in (a, b))
    p0 = pts.astype(np.float32)[:3, None, :]  # the interior points
    ref = cv2.calcOpticalFlowPyrLK(a8, b8, p0, None, winSize=(21, 21), maxLevel=3)
    ours = tuple(lucas_kanade(a8, b8, p0, window=21, levels=3))
    for o, r in zip(ours, ref, strict=True):
        assert o.shape == r.shape and o.dtype == r.dtype
    np.testing.assert_array_equal(ours[1], ref[1])
    np.testing.assert_allclose(ours[0], ref[0], atol=0.01)
