"""Pose pictures (issue 28): a joint drawn at (x, y) colours that pixel, unlabelled and
NaN joints (and their limbs) are left out, occluded joints are rings, several people at
once, side colours, sizes that grow with the image, confidence as disc size with a
legend, joint names; heatmap grids (layout sizes, a peak landing on its pixel, the image
under a zero heatmap); 3-D skeletons from two viewpoints; refusals."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import InputError
from robopercept.viz import draw_skeleton, heatmap_grid, label_colors, skeleton_3d_picture
from robopercept.viz.pose import SIDE_COLORS

RED = (255, 0, 0)


def _changed(pic, img):
    return (pic != img).any(axis=-1)


# ----------------------------------------------------------------------------- draw_skeleton


def test_a_joint_colours_its_pixel_and_nothing_far_from_it():
    img = np.zeros((60, 80, 3), np.uint8)
    pic = draw_skeleton(img, [[20.0, 30.0, 2.0]], [], colors=RED, radius=3)
    assert pic.shape == img.shape and pic.dtype == np.uint8
    assert pic[30, 20].tolist() == list(RED)
    yy, xx = np.nonzero(_changed(pic, img))
    assert len(yy) > 9 and (np.hypot(xx - 20, yy - 30) <= 3.5 + 1).all()
    assert (img == 0).all()  # the input is not drawn on


def test_unlabelled_and_nan_joints_and_their_limbs_are_not_drawn():
    img = np.full((50, 70, 3), 40, np.uint8)
    kp = np.array([[10, 10, 2], [40, 40, 0], [60, 20, 2], [np.nan, 5, 2], [30, 45, np.nan]])
    links = [(0, 1), (1, 2), (2, 3), (0, 2), (3, 4), (2, 4)]
    pic = draw_skeleton(img, kp, links, colors=RED)
    only = draw_skeleton(img, kp[[0, 2]], [(0, 1)], colors=RED)
    np.testing.assert_array_equal(pic, only)  # joints 1, 3, 4 and their five limbs: absent
    assert pic[40, 40].tolist() == [40, 40, 40] and pic[45, 30].tolist() == [40, 40, 40]
    assert pic[15, 35].tolist() == list(RED)  # the limb (0, 2) at its middle


def test_visible_codes_given_apart_and_nan_confidence():
    img = np.zeros((40, 40, 3), np.uint8)
    xy = np.array([[10.0, 10.0], [30.0, 30.0]])
    a = draw_skeleton(img, xy, [(0, 1)], visible=[True, False], colors=RED)
    b = draw_skeleton(img, np.c_[xy, [2, 0]], [(0, 1)], colors=RED)
    np.testing.assert_array_equal(a, b)
    c = draw_skeleton(img, xy, [(0, 1)], confidence=[1.0, np.nan], colors=RED, legend=False)
    assert c[10, 10].tolist() == list(RED) and not _changed(c, img)[25:, 25:].any()


def test_an_occluded_joint_is_a_ring():
    img = np.full((40, 40, 3), 100, np.uint8)
    pic = draw_skeleton(img, [[20.0, 20.0, 1.0]], [], colors=RED, radius=6)
    assert pic[20, 20].tolist() == [100, 100, 100]  # hollow
    ring = [pic[20, 20 + d].tolist() for d in (5, 6)] + [pic[20 - d, 20].tolist() for d in (5, 6)]
    assert list(RED) in ring
    filled = draw_skeleton(img, [[20.0, 20.0, 2.0]], [], colors=RED, radius=6)
    assert filled[20, 20].tolist() == list(RED)


def test_several_people_each_in_its_colour():
    img = np.zeros((60, 90, 3), np.uint8)
    kp = np.array(
        [[[10, 10, 2], [10, 40, 2], [25, 25, 2]], [[60, 10, 2], [60, 40, 2], [80, 25, 2]]],
        dtype=float,
    )
    pic = draw_skeleton(img, kp, [(0, 1), (1, 2)], radius=3)
    colors = label_colors(np.array([1, 2]))  # person p: hue p + 1
    for p in range(2):
        for x, y, _ in kp[p]:
            assert pic[int(y), int(x)].tolist() == colors[p].tolist()
        assert pic[25, int(kp[p, 0, 0])].tolist() == colors[p].tolist()  # limb (0, 1)


def test_left_right_and_centre_colours():
    img = np.zeros((60, 90, 3), np.uint8)
    kp = np.array([[10, 10, 2], [80, 10, 2], [45, 50, 2], [10, 50, 2]], dtype=float)
    links = [(0, 1), (0, 3), (1, 2)]
    pic = draw_skeleton(img, kp, links, sides=["left", "right", "center", "left"], radius=3)
    for j, side in enumerate(["left", "right", "center", "left"]):
        assert pic[int(kp[j, 1]), int(kp[j, 0])].tolist() == list(SIDE_COLORS[side])
    assert pic[30, 10].tolist() == list(SIDE_COLORS["left"])  # left to left: left
    assert pic[10, 45].tolist() == list(SIDE_COLORS["center"])  # left to right: centre
    assert pic[30, 62].tolist() == list(SIDE_COLORS["center"])  # right to centre: centre
    by_pairs = draw_skeleton(img, kp, links, flip_pairs=[(0, 1)], radius=3)
    by_sides = draw_skeleton(img, kp, links, sides=["left", "right", "center", "center"], radius=3)
    np.testing.assert_array_equal(by_pairs, by_sides)


def test_colours_per_joint_and_the_mean_on_limbs():
    img = np.zeros((20, 60, 3), np.uint8)
    kp = [[5.0, 10.0, 2.0], [55.0, 10.0, 2.0]]
    pic = draw_skeleton(img, kp, [(0, 1)], colors=[[200, 0, 0], [0, 0, 100]], radius=2)
    assert pic[10, 5].tolist() == [200, 0, 0] and pic[10, 55].tolist() == [0, 0, 100]
    assert pic[10, 30].tolist() == [100, 0, 50]


def _disc_area(shape, **kw):
    img = np.full((*shape, 3), 128, np.uint8)
    h, w = shape
    pic = draw_skeleton(img, [[w / 2, h / 2, 2.0]], [], colors=RED, **kw)
    return int(_changed(pic, img).sum())


def test_sizes_grow_with_the_image_so_that_1080p_reads():
    # radius max(2, L / 200): 3.2 px and 9.6 px; Pillow fills the 2r + 1 pixels of the
    # box, so the disc's area is about pi (r + 0.5)^2 (0.8 px of rasterization slack)
    for shape, r in (((360, 640), 3.2), ((1080, 1920), 9.6)):
        assert abs(np.sqrt(_disc_area(shape) / np.pi) - (r + 0.5)) < 0.8
    assert _disc_area((1080, 1920)) > 5 * _disc_area((360, 640))
    for shape, width in (((360, 640), 2), ((1080, 1920), 5)):  # round(radius / 2)
        img = np.full((*shape, 3), 128, np.uint8)
        y, w = shape[0] // 2, shape[1]
        pic = draw_skeleton(img, [[10.0, y, 2.0], [w - 10.0, y, 2.0]], [(0, 1)], colors=RED)
        column = _changed(pic, img)[:, w // 2]
        assert abs(int(column.sum()) - width) <= 1


def test_confidence_shrinks_the_discs_and_adds_a_legend():
    img = np.full((200, 200, 3), 128, np.uint8)
    kp = [[50.0, 100.0], [150.0, 100.0]]
    pic = draw_skeleton(img, kp, [], confidence=[1.0, 0.2], colors=RED, radius=10)
    assert pic.shape[0] == 200 and pic.shape[1] > 200  # the legend panel on the right
    changed = _changed(pic[:, :200], img)
    big, small = changed[:, :100].sum(), changed[:, 100:].sum()
    # radius r (0.4 + 0.6 c): 10 and 5.2 px, areas in the ratio 3.7
    assert 3.0 < big / small < 4.5
    panel = pic[:, 200:]
    assert (panel == 255).mean() > 0.5 and (panel < 128).any()  # white, with marks and text
    plain = draw_skeleton(img, kp, [], confidence=[1.0, 0.2], colors=RED, radius=10, legend=False)
    np.testing.assert_array_equal(plain, pic[:, :200])


def test_joint_names_are_written_beside_the_joints():
    img = np.full((120, 200, 3), 128, np.uint8)
    kp = [[40.0, 60.0, 2.0], [150.0, 60.0, 2.0]]
    plain = draw_skeleton(img, kp, [], colors=RED, radius=4)
    named = draw_skeleton(img, kp, [], colors=RED, radius=4, labels=["knee", "hip"])
    diff = _changed(named, plain)
    assert diff[45:75, 45:100].any() and diff[45:75, 155:200].any()
    assert not diff[:, :35].any()  # to the right of the joint, not to its left
    text = named[45:75, 45:100]
    assert (text == 255).all(-1).any() and (text == 0).all(-1).any()  # white on black


def test_gray_input_empty_poses_and_far_points():
    gray = np.full((30, 40), 7, np.uint8)
    pic = draw_skeleton(gray, np.zeros((0, 17, 3)), [(0, 1)])
    assert pic.shape == (30, 40, 3) and (pic == 7).all()
    far = np.array([[1e300, 5.0, 2.0], [-1e300, 1e300, 2.0], [5.0, 5.0, 2.0]])
    pic = draw_skeleton(gray, far, [(0, 1), (1, 2)], colors=RED, labels=["a", "b", "c"])
    assert pic[5, 5].tolist() == list(RED)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"keypoints": np.zeros((3, 4))}, r"keypoints must be \(J, 2\|3\)"),
        ({"keypoints": [[1.0, 2.0, 0.5]] * 3}, r"scores\? pass keypoints\[\.\.\., :2\]"),
        ({"links": [(0, 5)]}, r"links must join two different joints among 0\.\.2"),
        ({"links": [(0.0, 1.0)]}, "integer joint indices"),
        ({"links": [(1, 1)]}, "two different joints"),
        ({"sides": ["left"] * 3, "flip_pairs": [(0, 1)]}, "not both"),
        ({"sides": ["left", "up", "right"]}, "'left', 'right' or 'center'"),
        ({"flip_pairs": [(0, 1), (1, 2)]}, "each joint at most once"),
        ({"colors": np.zeros((2, 3))}, r"one colour \(3,\) or one per joint"),
        ({"colors": [300, 0, 0]}, "three integers in 0..255"),
        ({"confidence": [0.5, 1.5, 0.1]}, r"confidence must be in \[0, 1\]"),
        ({"visible": [1, 1]}, "visible must have one value per joint"),
        ({"labels": ["a"]}, "one name per joint"),
        ({"radius": -1}, "radius"),
        ({"thickness": 0}, "thickness"),
        ({"legend": "yes"}, "legend must be True or False"),
    ],
)
def test_draw_skeleton_refusals(kwargs, match):
    args = {"keypoints": [[1.0, 2.0, 2.0], [5.0, 6.0, 2.0], [9.0, 9.0, 1.0]], "links": [(0, 1)]}
    args.update(kwargs)
    kp, links = args.pop("keypoints"), args.pop("links")
    with pytest.raises(InputError, match=match):
        draw_skeleton(np.zeros((20, 20, 3), np.uint8), kp, links, **args)


# ----------------------------------------------------------------------------- heatmap_grid


@pytest.mark.parametrize(
    ("joints", "cols", "tile", "shape"),
    [
        (1, None, 64, (48, 64)),
        (5, None, 64, (64, 48)),
        (16, 3, 128, (48, 64)),
        (4, 9, 100, (30, 30)),
    ],
)
def test_heatmap_grid_layout_sizes(joints, cols, tile, shape):
    hm = np.random.default_rng(0).uniform(0, 1, (joints, 6, 8))
    pic = heatmap_grid(np.zeros(shape, np.uint8), hm, cols=cols, tile_px=tile)
    h, w = shape
    s = tile / max(h, w)
    tw, th = round(w * s), round(h * s)
    ncol = min(cols or int(np.ceil(np.sqrt(joints))), joints)
    nrow = int(np.ceil(joints / ncol))
    gap, cap = max(4, tile // 40), round(1.5 * max(12, round(tile / 16)))
    assert pic.shape == (nrow * (th + cap + gap) + gap, ncol * (tw + gap) + gap, 3)


def test_a_heatmap_peak_lands_on_its_pixel():
    hm = np.zeros((2, 16, 16))
    hm[0, 4, 10] = 1.0  # row v = 4, column u = 10
    hm[1, 12, 3] = 0.25
    pic = heatmap_grid(np.full((48, 48), 255, np.uint8), hm, tile_px=48)
    gap, cap = 4, 18
    for k, (v, u) in enumerate([(4, 10), (12, 3)]):
        x0 = gap + k * (48 + gap)
        tile = pic[gap + cap : gap + cap + 48, x0 : x0 + 48].astype(int)
        # heatmap pixel u is centred at image column (u + 0.5) 48 / 16 - 0.5 = 3 u + 1
        # (a whole pixel: the upsampled peak is exactly there, t = 1). On white, blue is
        # (1 - a t) 255 + a t turbo_b(t): lowest where t = 1 (Turbo(1) has no blue)
        y, x = np.unravel_index(np.argmin(tile[..., 2]), (48, 48))
        assert (x, y) == (3 * u + 1, 3 * v + 1)
        # each heatmap is scaled to its own peak: both peaks show the same colour,
        # alpha 0.7 of Turbo(1) = (144, 13, 0) over white (1: 76.5 rounds either way)
        np.testing.assert_allclose(tile[y, x], 0.3 * 255 + 0.7 * np.array([144, 13, 0]), atol=1)
    assert (pic[gap : gap + cap, gap : gap + 48] < 128).any()  # the caption


def test_a_zero_heatmap_shows_the_plain_image():
    img = np.random.default_rng(1).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    pic = heatmap_grid(img, np.zeros((1, 12, 16)), names=["nose"], tile_px=64)
    np.testing.assert_array_equal(pic[4 + 18 : 4 + 18 + 48, 4 : 4 + 64], img)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"heatmaps": np.zeros((8, 8))}, "heatmaps must be 3-D"),
        ({"heatmaps": np.full((2, 4, 4), np.nan)}, "heatmaps"),
        ({"heatmaps": np.zeros((0, 4, 4))}, r"J, h, w >= 1"),
        ({"names": ["a"]}, "one name per joint"),
        ({"cols": 0}, "cols must be >= 1"),
        ({"alpha": 2.0}, "alpha"),
        ({"tile_px": 4}, "tile_px must be >= 8"),
    ],
)
def test_heatmap_grid_refusals(kwargs, match):
    args = {"heatmaps": np.zeros((2, 4, 4))}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        heatmap_grid(np.zeros((16, 16), np.uint8), **args)


# ----------------------------------------------------------------------------- 3-D


def _near(pic, color, tol=40):
    return (np.abs(pic.astype(int) - color).max(axis=-1) <= tol).sum()


def test_3d_picture_two_panels_with_the_pose_and_the_reference():
    pose = np.array([[0, 0, 0], [0, 0, 0.5], [0.2, 0, 0.9], [-0.2, 0.1, 0.9], [np.nan, 0, 0]])
    links = [(0, 1), (1, 2), (1, 3), (3, 4)]
    pic = skeleton_3d_picture(pose, links, reference=pose + 0.05, size=(600, 300))
    assert pic.shape == (300, 600, 3) and pic.dtype == np.uint8
    assert (pic < 250).any(axis=-1).mean() > 0.02  # not empty
    blue, red = (31, 119, 180), (214, 39, 40)
    for half in (pic[:, :300], pic[:, 300:]):  # one view per panel, both poses in each
        assert _near(half, blue) > 20 and _near(half, red) > 20
    alone = skeleton_3d_picture(pose, links, [(0.3, 0.5)], titles=["side"], size=(300, 300))
    assert alone.shape == (300, 300, 3) and _near(alone, blue) > 20 and _near(alone, red) == 0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"joints3d": np.zeros((3, 2))}, r"joints3d must be \(J, 3\)"),
        ({"reference": np.zeros((4, 3))}, r"reference must be \(J, 3\) = \(3, 3\)"),
        ({"joints3d": np.array([[0, 0, np.inf]] * 3)}, "finite"),
        ({"views": [(0.0, 0.0)] * 7}, "1 to 6"),
        ({"views": [(0.0, 0.0, 1.0)]}, r"views\[0\] must be \(elevation, azimuth\)"),
        ({"views": [(10.0, 0.0)]}, "elevation"),
        ({"titles": ["only one"]}, "one name per view"),
        ({"size": (100, 100)}, "size"),
        ({"links": [(0, 3)]}, "links must join"),
    ],
)
def test_3d_picture_refusals(kwargs, match):
    args = {"joints3d": np.zeros((3, 3)), "links": [(0, 1)]}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        skeleton_3d_picture(args.pop("joints3d"), args.pop("links"), **args)


def test_the_legend_lists_sides_or_people():
    img = np.full((120, 160, 3), 128, np.uint8)
    kp = np.array([[[20, 20, 2], [60, 20, 2]], [[20, 80, 2], [60, 80, 2]]], dtype=float)
    by_person = draw_skeleton(img, kp, [(0, 1)], legend=True)
    panel = by_person[:, 160:]
    for color in label_colors(np.array([1, 2])):  # a swatch per person
        assert (panel == color).all(-1).sum() > 20
    by_side = draw_skeleton(img, kp, [(0, 1)], flip_pairs=[(0, 1)], legend=True)
    panel = by_side[:, 160:]
    assert (panel == SIDE_COLORS["left"]).all(-1).sum() > 20
    assert not (panel == SIDE_COLORS["center"]).all(-1).any()  # no central joint
    own = draw_skeleton(img, kp, [(0, 1)], colors=RED, legend=True)
    assert own.shape == img.shape  # nothing to list: no panel
