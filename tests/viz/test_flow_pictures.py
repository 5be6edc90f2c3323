"""Flow pictures: the HSV wheel coding, arrows and trails."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import (
    dense_flow_picture,
    draw_flow,
    draw_trails,
    flow_to_color,
    flow_wheel,
)


def test_wheel_colours_by_direction_and_speed():
    flow = np.array(
        [[[2.0, 0.0], [0.0, 2.0], [-2.0, 0.0], [0.0, -2.0], [0.0, 0.0], [1.0, 0.0], [np.nan, 0]]]
    )
    rgb = flow_to_color(flow, max_magnitude=2.0)[0]
    # hue = atan2(v, u): 0 red, 90 deg (down on screen) yellow-green, 180 cyan, 270 violet
    assert rgb[0].tolist() == [255, 0, 0]
    assert rgb[1].tolist() == [128, 255, 0]
    assert rgb[2].tolist() == [0, 255, 255]
    assert rgb[3].tolist() == [128, 0, 255]
    assert rgb[4].tolist() == [255, 255, 255]  # still: white
    assert rgb[5].tolist() == [255, 128, 128]  # half speed: half saturation
    assert rgb[6].tolist() == [0, 0, 0]  # unknown: black


def test_default_top_speed_is_the_99th_percentile():
    flow = np.zeros((20, 20, 2))
    flow[..., 0] = 1.0
    flow[0, 0, 0] = 100.0  # one wild vector does not wash out the rest
    rgb = flow_to_color(flow)
    assert rgb[5, 5].tolist() == [255, 0, 0]


def test_wheel_legend():
    wheel = flow_wheel(51)
    assert wheel.shape == (51, 51, 3)
    assert wheel[25, 25].tolist() == [255, 255, 255]
    assert wheel[0, 0].tolist() == [0, 0, 0]
    assert wheel[25, 50].tolist() == [255, 0, 0]
    with pytest.raises(InputError):
        flow_to_color(np.zeros((4, 4, 3)))
    with pytest.raises(InputError):
        flow_to_color(np.zeros((4, 4, 2)), max_magnitude=0)


def test_arrows_follow_the_vectors():
    img = np.zeros((40, 60), dtype=np.uint8)
    out = draw_flow(img, [[10, 20], [50, 5]], [[30, 20], [50, 5]], status=[True, False])
    assert out.shape == (40, 60, 3)
    row = out[20, 10:31]
    assert (row == [0, 255, 0]).all()  # the shaft, start to tip
    assert (out[17:24, 26:30] == [0, 255, 0]).all(axis=2).sum() >= 4  # barbs near the tip
    assert out[5, 50].tolist() == [255, 0, 0]  # a failed point: a red dot
    assert (out[:, 35:45] == 0).all()  # nothing else
    scaled = draw_flow(img, [[10, 20]], [[14, 20]], scale=5.0)
    assert (scaled[20, 10:31] == [0, 255, 0]).all()
    with pytest.raises(InputError, match="one entry per point"):
        draw_flow(img, [[1, 2]], [[2, 3]], status=[True, False])
    with pytest.raises(InputError, match="same shape"):
        draw_flow(img, [[1, 2]], [[2, 3], [4, 5]])


def test_trails():
    img = np.zeros((30, 30, 3), dtype=np.uint8)
    out = draw_trails(
        img, [np.array([[2, 2], [2, 20]]), np.zeros((0, 2))], colors=[[9, 8, 7], [1, 1, 1]]
    )
    assert (out[2:21, 2] == [9, 8, 7]).all()
    assert img.sum() == 0  # input untouched
    with pytest.raises(InputError, match="one row per trail"):
        draw_trails(img, [np.zeros((2, 2))], colors=np.zeros((2, 3)))


def test_dense_flow_picture_fills_cells_and_places_the_legend():
    from robopercept.viz import dense_flow_picture, flow_to_color, flow_wheel

    field = np.zeros((3, 4, 2))
    field[..., 0] = 1.0  # rightward everywhere
    field[0, 0] = np.nan  # untracked: black cell
    pic = dense_flow_picture(field, 5, (40, 30, 3))
    assert pic.shape == (40, 30, 3) and pic.dtype == np.uint8
    cell = flow_to_color(field)[1, 1]
    assert (pic[5:10, 5:10] == cell).all()  # cell (1, 1) fills its 5x5 block
    assert (pic[0:5, 0:5] == 0).all()
    wheel = flow_wheel(15)  # min(101, 40 // 4 * 2 + 1, 30 // 4 * 2 + 1)
    np.testing.assert_array_equal(pic[-15:, -15:], wheel)
    assert (pic[15:25, :15] == 0).all()  # beyond the 3x4 grid: black padding
    with pytest.raises(InputError, match="step"):
        dense_flow_picture(field, 0, (40, 30))


# issue 25: sizes, steps, shapes, widths and trails are checked ----------------------------
_RGB = np.zeros((32, 48, 3), np.uint8)
_P = np.array([[5.0, 5.0], [20.0, 10.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: flow_wheel(np.nan), "size must be an integer"),
        (lambda: flow_wheel(-np.inf), "size must be an integer"),
        (lambda: flow_wheel(None), "size must be an integer"),
        (lambda: flow_wheel(2**40), "size must be at most 2049"),
        (lambda: dense_flow_picture(np.zeros((4, 6, 2)), True, (32, 48)), "step must be an"),
        (lambda: dense_flow_picture(np.zeros((4, 6, 2)), 1.0, (32, 48)), "step must be an"),
        (lambda: dense_flow_picture(np.zeros((4, 6, 2)), 8, (48, np.float32(2))), "width"),
        (lambda: dense_flow_picture(np.zeros((4, 6, 2)), 8, (1,)), r"\(H, W\) or \(H, W, 3\)"),
        (lambda: dense_flow_picture(np.zeros((4, 6, 2)), 8, (2**40, 2**40)), "at most 67108864"),
        (lambda: flow_to_color(np.zeros((4, 4, 2)), max_magnitude=0), "max_magnitude must"),
        (lambda: flow_to_color(np.zeros((4, 4, 2), complex)), r"real \(H, W, 2\) array"),
        (lambda: draw_flow(_RGB, _P, _P + 1, color=(0, 255, np.inf)), "color must be three"),
        (lambda: draw_flow(_RGB, _P, _P + 1, head="3"), "head must be a real number"),
        (lambda: draw_flow(_RGB, _P, _P + 1, width=1e300), "width must be an integer"),
        (lambda: draw_trails(_RGB, [_P], radius=-1), r"radius must be in \[0, inf\]"),
        (lambda: draw_trails(_RGB, [_P], width=[1, 2]), "width must be an integer"),
        (lambda: draw_trails(_RGB, [_P], width=2**40), "width must be at most"),
        (lambda: draw_trails(_RGB, "abc"), "trails must be a list"),
        (lambda: draw_trails(_RGB, [_P], colors=[(0, 0, np.nan)]), r"colors\[0\] must be"),
    ],
)
def test_issue25_bad_arguments_raise_input_error(call, match):
    with pytest.raises(InputError, match=match):
        call()


def test_issue25_dense_flow_picture_fills_cells_and_any_step_works():
    """Each grid vector fills its step x step cell (the former np.kron construction),
    and a step as large as 2**63 (NumPy's int64 overflowed) draws the first vector
    over the whole picture instead of asking for a picture of 2**63 pixels."""
    rng = np.random.default_rng(0)
    field = rng.normal(size=(4, 6, 2))
    colors = flow_to_color(field)
    pic = dense_flow_picture(field, 8, (48, 64))
    ref = np.kron(colors, np.ones((8, 8, 1), np.uint8))
    np.testing.assert_array_equal(pic[:32, :36], ref[:32, :36])  # (the legend is lower right)
    assert (pic[32:, :20] == 0).all()  # beyond the grid: black
    huge = dense_flow_picture(field, 2**63, (48, 64))
    assert (huge[:10, :10] == colors[0, 0]).all()
    tiny = dense_flow_picture(field, 1, (3, 5))  # too small for a legend: no error
    np.testing.assert_array_equal(tiny, colors[:3, :5])


def test_issue25_far_flow_and_trails_draw_the_visible_part():
    start = np.array([[10.0, 10.0], [1e300, 5.0]])
    end = np.array([[1e300, 10.0], [1e300 + 1.0, 5.0]])
    out = draw_flow(_RGB, start, end, failed_color=None)
    assert (out[10, 10:, 1] == 255).all() and out[:, :, 1].sum() == 255 * 38
    trails = draw_trails(_RGB, [np.array([[0.0, 16.0], [-1e300, 16.0], [1e300, 16.0]])])
    assert (trails[16, :, 1] == 255).all()


# issue 30: arrows scaled automatically so that small motions are visible
def test_arrow_scale_makes_the_median_arrow_visible():
    """Property: for any motion size, the median arrow is drawn at least 2 % of the
    diagonal (unless capped) and the factor is a round number >= 1; long motions are
    never shortened; nothing tracked or nothing moving gives 1."""
    from robopercept.viz.flow import MAX_ARROW_SCALE, arrow_scale

    rng = np.random.default_rng(0)
    size = (584, 388)
    diag = np.hypot(*size)
    for m in (0.05, 0.3, 1.0, 1.28, 3.0, 7.0, 14.1, 50.0):
        flow = rng.normal(0, 1, (200, 2))
        flow *= m / np.median(np.hypot(*flow.T))
        s = arrow_scale(flow, size)
        mantissa = s / 10 ** np.floor(np.log10(s))
        assert s >= 1 and (s == MAX_ARROW_SCALE or round(mantissa, 9) in (1, 2, 2.5, 5))
        assert s * m >= 0.02 * diag - 1e-9 or s == MAX_ARROW_SCALE
        assert s * m < 2.0 * 0.02 * diag or s == 1.0  # rounding up at most doubles
    assert arrow_scale(np.full((3, 2), np.nan), size) == 1.0
    assert arrow_scale(np.zeros((3, 2)), size) == 1.0
    assert arrow_scale(np.array([[0.01, 0.0]]), size) == MAX_ARROW_SCALE
    assert arrow_scale(np.array([[1.0, 0.0]]), size, fraction=0.1, max_scale=1000) == 100.0
    with pytest.raises(InputError, match="fraction"):
        arrow_scale(np.ones((2, 2)), size, fraction=0.0)
    with pytest.raises(InputError, match="max_scale"):
        arrow_scale(np.ones((2, 2)), size, max_scale=0.5)
