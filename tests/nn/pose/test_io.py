"""Keypoint file readers (issue 28): mmpose's MPII JSON and its MPII-TRB variant, imgaug's
quokka annotation, and the real COCO keypoint file, each read, checked number by number
against its JSON, and drawn with :func:`robopercept.viz.draw_skeleton`; hand-made files
for the 1-based shift and mmpose's box; bad files refused with FileFormatError naming
the entry and field; mutated real files never give anything but FileFormatError."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from robopercept.errors import FileFormatError
from robopercept.imaging import read_image
from robopercept.nn.coco.dataset import read_coco_json
from robopercept.nn.pose.io import (
    MPII_TRB_40,
    read_imgaug_keypoints,
    read_mpii_json,
)
from robopercept.nn.skeleton import COCO_17, MPII_16, skeleton_from_coco_category
from robopercept.viz import draw_skeleton
from robopercept.viz.pose import SIDE_COLORS
from tests.conftest import data_path


def _write(tmp_path, data, name="a.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def _entry(**changes):
    e = {
        "image": "001.jpg",
        "joints": [[float(10 + i), float(20 + 2 * i)] for i in range(16)],
        "joints_vis": [1] * 16,
        "center": [51.0, 61.0],
        "scale": 0.5,
    }
    e.update(changes)
    return e


def _side_color(sides, j):
    return SIDE_COLORS[sides[j]]


def _sides(skeleton):
    out = ["center"] * skeleton.num_joints
    for a, b in skeleton.flip_pairs:
        out[a], out[b] = "left", "right"
    return out


def _check_drawn(img, pic, keypoints, skeleton, radius):
    """Every visible joint far enough from the other drawn joints has its side's colour
    at its (rounded) pixel, and that pixel changed unless the image had that colour."""
    sides = _sides(skeleton)
    kp = keypoints.reshape(-1, skeleton.num_joints, 3)
    pts = [(p, j) for p in range(len(kp)) for j in range(kp.shape[1]) if kp[p, j, 2] == 2]
    xy = np.array([kp[p, j, :2] for p, j in pts])
    checked = 0
    for k, (p, j) in enumerate(pts):
        d = np.hypot(*(xy - xy[k]).T)
        d[k] = np.inf
        if d.min() <= 2 * radius + 2:  # another joint's disc may cover this one
            continue
        x, y = np.round(xy[k]).astype(int)
        if not (0 <= x < pic.shape[1] and 0 <= y < pic.shape[0]):
            continue
        assert pic[y, x].tolist() == list(_side_color(sides, j)), (p, skeleton.joints[j])
        checked += 1
    assert checked >= 3
    assert pic.shape[:2] == img.shape[:2]
    assert (pic != img).any(axis=-1).sum() > checked * radius**2  # discs and limbs


# ----------------------------------------------------------------------------- MPII


@pytest.mark.realdata
def test_real_mpii_file_matches_its_json_minus_one():
    path = data_path("detection", "mpii_keypoints_mmpose", "test_mpii.json")
    raw = json.loads(path.read_text())
    ann = read_mpii_json(path)
    assert ann.layout == "mpii" and ann.skeleton is MPII_16 and len(ann) == len(raw) == 5
    assert ann.keypoints.shape == (5, 16, 3) and ann.boxes.shape == (5, 4)
    for k, (person, e) in enumerate(zip(ann.people, raw, strict=True)):
        assert person.image == e["image"] and person.id == k and person.headbox is None
        vis = np.array(e["joints_vis"]) > 0
        joints = np.array(e["joints"], dtype=float)
        # MATLAB's 1-based pixels to 0-based; unlabelled joints are COCO's (0, 0, 0)
        np.testing.assert_array_equal(person.keypoints[vis, :2], joints[vis] - 1)
        np.testing.assert_array_equal(person.keypoints[:, 2], np.where(vis, 2.0, 0.0))
        np.testing.assert_array_equal(person.keypoints[~vis], 0.0)
        np.testing.assert_array_equal(person.center, np.array(e["center"]) - 1)
        assert person.scale == e["scale"]
        # mmpose's box: 200 s square around the centre moved down by 15 s
        side = 200 * e["scale"]
        cx, cy = e["center"][0] - 1, e["center"][1] - 1 + 15 * e["scale"]
        np.testing.assert_allclose(
            person.box, [cx - side / 2, cy - side / 2, side, side], rtol=0, atol=1e-9
        )
        x, y, w, h = person.box
        lab = person.keypoints[vis, :2]
        assert (lab[:, 0] >= x).all() and (lab[:, 0] <= x + w).all()
        assert (lab[:, 1] >= y).all() and (lab[:, 1] <= y + h).all()
        assert not person.keypoints.flags.writeable and not person.box.flags.writeable
    assert sum((~(np.array(e["joints_vis"]) > 0)).sum() for e in raw) == 4  # two people x 2


@pytest.mark.realdata
def test_real_mpii_people_drawn_on_their_images():
    folder = data_path("detection", "mpii_keypoints_mmpose")
    ann = read_mpii_json(folder / "test_mpii.json")
    for person in ann.people[:3]:
        img = read_image(folder / person.image, mode="rgb")
        radius = 6.0
        pic = draw_skeleton(
            img,
            person.keypoints,
            ann.skeleton.links,
            flip_pairs=ann.skeleton.flip_pairs,
            radius=radius,
        )
        _check_drawn(img, pic, person.keypoints, ann.skeleton, radius)


@pytest.mark.realdata
def test_real_mpii_trb_file_matches_its_json_and_the_mpii_file():
    folder = data_path("detection", "mpii_keypoints_mmpose")
    raw = json.loads((folder / "test_mpii_trb.json").read_text())
    trb = read_mpii_json(folder / "test_mpii_trb.json")
    mpii = read_mpii_json(folder / "test_mpii.json")
    assert trb.layout == "mpii_trb" and trb.skeleton is MPII_TRB_40 and len(trb) == 5
    assert MPII_TRB_40.num_joints == 40 and len(MPII_TRB_40.links) == 27
    assert len(MPII_TRB_40.flip_pairs) == 19  # 6 limb pairs, the neck sides, 12 contours
    perm = MPII_TRB_40.flip_permutation()
    np.testing.assert_array_equal(perm[perm], np.arange(40))
    for a, b in MPII_TRB_40.flip_pairs:  # left first, and the names differ by left/right
        left, right = MPII_TRB_40.joints[a], MPII_TRB_40.joints[b]
        assert "left" in left.split("_") and right == left.replace("left", "right")
    files = {im["id"]: im["file_name"] for im in raw["images"]}
    by_image = {p.image: p for p in mpii.people}
    ratios = []
    for person, a in zip(trb.people, raw["annotations"], strict=True):
        assert person.image == files[a["image_id"]] and person.id == a["id"]
        kp = np.array(a["keypoints"], dtype=float).reshape(40, 3)
        on = kp[:, 2] > 0
        assert on.sum() == a["num_joints"]
        np.testing.assert_array_equal(person.keypoints[on, :2], kp[on, :2] - 1)
        np.testing.assert_array_equal(person.keypoints[:, 2], kp[:, 2])
        np.testing.assert_array_equal(person.keypoints[~on], 0.0)
        # the 12 limb joints are the MPII file's numbers for the same person
        other = by_image[person.image]
        for j, name in enumerate(MPII_TRB_40.joints[:12]):
            m = MPII_16.index(name)
            if on[j] and other.keypoints[m, 2] > 0:
                np.testing.assert_array_equal(person.keypoints[j, :2], other.keypoints[m, :2])
        # mmpose 0.x's box: 256 / scale around the centre, which holds every labelled point
        side = 256.0 / a["scale"]
        c = np.array(a["center"]) - 1
        np.testing.assert_allclose(person.box, [*(c - side / 2), side, side], atol=1e-9)
        x, y, w, h = person.box
        lab = person.keypoints[on, :2]
        assert (lab >= [x, y]).all() and (lab <= [x + w, y + h]).all()
        ratios.append(person.box[2] / other.box[2])
    # the same zoom for every person: 256 / s_trb = 1.5448 x 200 s_mpii (1e-4: the
    # files' scales are written to 7 to 10 digits)
    np.testing.assert_allclose(ratios, 1.5448, atol=1e-4)


@pytest.mark.realdata
def test_real_mpii_trb_drawn():
    folder = data_path("detection", "mpii_keypoints_mmpose")
    trb = read_mpii_json(folder / "test_mpii_trb.json")
    person = trb.people[0]
    img = read_image(folder / person.image, mode="rgb")
    pic = draw_skeleton(
        img, person.keypoints, trb.skeleton.links, flip_pairs=trb.skeleton.flip_pairs, radius=5
    )
    _check_drawn(img, pic, person.keypoints, trb.skeleton, 5.0)


def test_mpii_hand_case_shift_and_box(tmp_path):
    vis = [1] * 14 + [0, 1]
    joints = [[float(10 + i), float(20 + 2 * i)] for i in range(16)]
    joints[14] = [-1.0, -1.0]  # MPII's unlabelled joint
    p = _write(tmp_path, [_entry(joints=joints, joints_vis=vis), _entry(center=[-1, -1])])
    a, b = read_mpii_json(p).people
    np.testing.assert_array_equal(a.keypoints[0], [9.0, 19.0, 2.0])
    np.testing.assert_array_equal(a.keypoints[14], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(a.center, [50.0, 60.0])
    # side 200 * 0.5 = 100 around (50, 60 + 15 * 0.5)
    np.testing.assert_array_equal(a.box, [0.0, 17.5, 100.0, 100.0])
    # centre -1 (MPII's "no centre"): mmpose does not move it
    np.testing.assert_array_equal(b.box, [-52.0, -52.0, 100.0, 100.0])


def test_mpii_without_joints_is_all_unlabelled(tmp_path):
    e = _entry()
    del e["joints"], e["joints_vis"]  # mmpose's MPII test-set layout
    person = read_mpii_json(_write(tmp_path, [e])).people[0]
    np.testing.assert_array_equal(person.keypoints, np.zeros((16, 3)))


def test_trb_with_its_own_names_and_coco_links(tmp_path):
    data = {
        "images": [{"id": 7, "file_name": "x.jpg"}],
        "categories": [
            {"name": "arm", "keypoints": ["l_a", "left_hand", "right_hand"], "skeleton": [[1, 2]]}
        ],
        "annotations": [
            {
                "id": 3,
                "image_id": 7,
                "keypoints": [5, 6, 2, 0, 0, 0, 9, 9, 1],
                "center": [11, 11],
                "scale": 2.0,
                "headbox": [1, 2, 3, 4],
            }
        ],
    }
    ann = read_mpii_json(_write(tmp_path, data))
    s = ann.skeleton
    assert s.name == "arm" and s.links == ((0, 1),) and s.flip_pairs == ((1, 2),)
    person = ann.people[0]
    np.testing.assert_array_equal(person.keypoints, [[4, 5, 2], [0, 0, 0], [8, 8, 1]])
    np.testing.assert_array_equal(person.box, [-54.0, -54.0, 128.0, 128.0])
    np.testing.assert_array_equal(person.headbox, [0, 1, 2, 3])


# ----------------------------------------------------------------------------- imgaug


@pytest.mark.realdata
def test_real_quokka_annotation_matches_its_json_and_is_drawn():
    folder = data_path("detection", "imgaug_quokka")
    raw = json.loads((folder / "quokka_annotations.json").read_text())
    ann = read_imgaug_keypoints(folder / "quokka_annotations.json")
    b = raw["bounding_boxes"][0]
    np.testing.assert_array_equal(
        ann.boxes, [[b["x1"], b["y1"], b["x2"] - b["x1"], b["y2"] - b["y1"]]]
    )
    assert ann.box_labels == ("animal",)
    assert ann.names == tuple(k["label"] for k in raw["keypoints"])
    np.testing.assert_array_equal(ann.keypoints, [[k["x"], k["y"], 2.0] for k in raw["keypoints"]])
    assert len(ann.polygons) == 1 and ann.polygon_labels == ("",)
    np.testing.assert_array_equal(
        ann.polygons[0], [[v["x"], v["y"]] for v in raw["polygons"][0]["keypoints"]]
    )
    s = ann.skeleton
    assert s.joints == ann.names and s.links == ()
    pairs = [(s.joints[a], s.joints[b]) for a, b in s.flip_pairs]
    assert pairs == [
        ("ear_tip_left", "ear_tip_right"),
        ("eye_left", "eye_right"),
        ("paw_left", "paw_right"),
    ]
    img = read_image(folder / "quokka.jpg", mode="rgb")
    assert img.shape == (643, 960, 3)
    x, y, w, h = ann.boxes[0]
    assert ((ann.keypoints[:, :2] >= [x, y]) & (ann.keypoints[:, :2] <= [x + w, y + h])).all()
    pic = draw_skeleton(img, ann.keypoints, s.links, flip_pairs=s.flip_pairs, radius=4)
    _check_drawn(img, pic, ann.keypoints, s, 4.0)


def test_imgaug_without_labels_or_keypoints(tmp_path):
    ann = read_imgaug_keypoints(_write(tmp_path, {"keypoints": [{"x": 1, "y": 2}]}))
    assert ann.names == ("keypoint_0",) and ann.boxes.shape == (0, 4)
    ann = read_imgaug_keypoints(
        _write(tmp_path, {"bounding_boxes": [{"x1": 0, "y1": 0, "x2": 1, "y2": 1}]})
    )
    assert ann.skeleton is None and ann.keypoints.shape == (0, 3) and ann.box_labels == ("",)


# ----------------------------------------------------------------------------- COCO


@pytest.mark.realdata
def test_real_coco_keypoints_read_and_drawn():
    folder = data_path("detection", "coco_keypoints_mmpose")
    raw = json.loads((folder / "test_coco.json").read_text())
    ds = read_coco_json(folder / "test_coco.json")
    skeleton = skeleton_from_coco_category(raw["categories"][0])
    assert skeleton.joints == COCO_17.joints and skeleton.links == COCO_17.links
    by_id = {a["id"]: a for a in raw["annotations"]}
    np.testing.assert_array_equal(ds.boxes, [by_id[int(i)]["bbox"] for i in ds.ann_ids])
    kept = getattr(ds, "keypoints", None)  # (being added to CocoDataset; else the JSON's)
    if kept is not None and np.asarray(kept).size:
        kps = np.asarray(kept, dtype=float).reshape(len(ds), 17, 3)
    else:
        kps = np.array([by_id[int(i)]["keypoints"] for i in ds.ann_ids], float).reshape(-1, 17, 3)
    np.testing.assert_array_equal(
        kps, np.array([by_id[int(i)]["keypoints"] for i in ds.ann_ids], float).reshape(-1, 17, 3)
    )
    drawn_images = 0
    for im in ds.images:
        sel = ds.image_ids == im.id
        people = kps[sel]
        if not (people[..., 2] == 2).sum() >= 3:
            continue
        img = read_image(folder / im.file_name, mode="rgb")
        assert img.shape[:2] == (im.height, im.width)
        pic = draw_skeleton(
            img, people, skeleton.links, flip_pairs=skeleton.flip_pairs, radius=3
        )  # several people at once
        _check_drawn(img, pic, people, skeleton, 3.0)
        drawn_images += 1
    assert drawn_images >= 2


@pytest.mark.realdata
def test_coco_keypoint_file_is_not_an_mpii_file():
    path = data_path("detection", "coco_keypoints_mmpose", "test_coco.json")
    with pytest.raises(FileFormatError, match="read_coco_json"):
        read_mpii_json(path)


# ----------------------------------------------------------------------------- bad files


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ({"joints_vis": [1] * 15}, r"entry 0 \(001\.jpg\): joints_vis must be 16 flags"),
        ({"joints_vis": [1] * 15 + [3]}, "joints_vis must be 16 flags 0 or 1"),
        ({"joints": [[1, 2]] * 15}, r"joints must be 16 \[x, y\] pairs .* got 15"),
        ({"joints": [[1, 2, 3]] * 16}, "joints must be 16"),
        ({"joints": "x"}, "joints must be"),
        ({"center": ["a", 1]}, r"center must be \[x, y\]"),
        ({"center": [1, float("nan")]}, "all finite"),
        ({"scale": -1.0}, "scale must be a positive number"),
        ({"scale": True}, "scale must be a positive number"),
        ({"scale": 1e308}, "beyond the float range"),
        ({"image": 5}, "entry 0: image must be a non-empty string"),
    ],
)
def test_bad_mpii_entries(tmp_path, entry, match):
    p = _write(tmp_path, [_entry(), _entry(**entry)][1:])
    with pytest.raises(FileFormatError, match=match):
        read_mpii_json(p)


def test_bad_mpii_files(tmp_path):
    e = _entry()
    del e["joints_vis"]
    with pytest.raises(FileFormatError, match=r"entry 0 .*has no 'joints_vis' field"):
        read_mpii_json(_write(tmp_path, [e]))
    with pytest.raises(FileFormatError, match="entry 0 must be a JSON object"):
        read_mpii_json(_write(tmp_path, [[1, 2]]))
    with pytest.raises(FileFormatError, match="not an MPII annotation file"):
        read_mpii_json(_write(tmp_path, {"people": []}))
    bad = tmp_path / "b.json"
    bad.write_text("[{")
    with pytest.raises(FileFormatError, match="not valid JSON"):
        read_mpii_json(bad)
    with pytest.raises(FileFormatError, match="no such file"):
        read_mpii_json(tmp_path / "missing.json")
    with pytest.raises(FileFormatError, match="is a folder"):
        read_mpii_json(tmp_path)


def _trb_file(**ann):
    a = {"id": 1, "image_id": 1, "keypoints": [1, 2, 2] * 3, "center": [5, 5], "scale": 1.0}
    a.update(ann)
    return {
        "images": [{"id": 1, "file_name": "a.jpg"}],
        "categories": [{"keypoints": ["a", "b", "c"]}],
        "annotations": [a],
    }


@pytest.mark.parametrize(
    ("ann", "match"),
    [
        ({"image_id": 2}, r"annotations\[0\] \(id 1\): image_id 2 is not in images"),
        ({"image_id": [1]}, "image_id must be an integer or a string"),
        ({"keypoints": [1, 2, 2] * 2}, r"keypoints must be 3 x \[x, y, v\] = 9 numbers"),
        ({"keypoints": [1, 2, 5] * 3}, "visibilities must be 0, 1 or 2"),
        ({"scale": 0}, "scale must be a positive number"),
        ({"scale": 1e-320}, "beyond the float range"),
        ({"headbox": [1, 2]}, r"headbox must be \[x1, y1, x2, y2\]"),
        ({"id": "x"}, "id must be an integer"),
    ],
)
def test_bad_trb_annotations(tmp_path, ann, match):
    with pytest.raises(FileFormatError, match=match):
        read_mpii_json(_write(tmp_path, _trb_file(**ann)))


def test_bad_trb_categories(tmp_path):
    data = _trb_file()
    data["categories"] = [{"keypoints": ["a", "a", "c"]}]
    with pytest.raises(FileFormatError, match="distinct names"):
        read_mpii_json(_write(tmp_path, data))
    data["categories"] = [{"keypoints": ["a", "b", "c"], "skeleton": [[1, 4]]}]
    with pytest.raises(FileFormatError, match=r"skeleton\[0\] must join two of the keypoints"):
        read_mpii_json(_write(tmp_path, data))
    data["categories"] = []
    with pytest.raises(FileFormatError, match="the one person category"):
        read_mpii_json(_write(tmp_path, data))


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ([1, 2], "expected a JSON object with bounding_boxes, keypoints"),
        ({"other": 1}, "expected a JSON object with bounding_boxes"),
        ({"keypoints": {"x": 1}}, "keypoints must be a JSON list"),
        (
            {"bounding_boxes": [{"x1": 5, "y1": 0, "x2": 1, "y2": 1}]},
            r"bounding_boxes\[0\]: needs x1 <= x2",
        ),
        ({"bounding_boxes": [{"x1": 5, "y1": 0, "x2": 9}]}, "has no 'y2' field"),
        ({"keypoints": [{"x": 1}]}, r"keypoints\[0\] has no 'y' field"),
        ({"keypoints": [{"x": "1", "y": 2}]}, r"keypoints\[0\]: x must be a finite number"),
        ({"keypoints": [{"x": 1, "y": 2, "label": 3}]}, "label must be a string"),
        (
            {"keypoints": [{"x": 1, "y": 2, "label": "a"}, {"x": 1, "y": 2, "label": "a"}]},
            r"keypoints\[1\]: label 'a' repeats keypoints\[0\]'s",
        ),
        ({"polygons": [{"keypoints": [{"x": 1, "y": 1}] * 2}]}, "at least 3 vertices"),
        (
            {"polygons": [{"keypoints": [{"x": 1, "y": 1}] * 2 + [{"x": 1}]}]},
            r"polygons\[0\]\.keypoints\[2\] has no 'y'",
        ),
    ],
)
def test_bad_imgaug_files(tmp_path, data, match):
    with pytest.raises(FileFormatError, match=match):
        read_imgaug_keypoints(_write(tmp_path, data))


@pytest.mark.realdata
def test_mutated_real_files_give_only_file_format_errors(tmp_path):
    """Numeric tokens of the real files replaced by hostile ones (seeded): each mutant
    is read or refused with FileFormatError, never another exception."""
    rng = np.random.default_rng(28)
    hostile = ["0", "-1", "1e308", "-1e308", "NaN", "Infinity", "99999999999999999999999",
               "1e-320", '"x"', "null", "true", "[]", "{}"]  # fmt: skip
    cases = [
        (data_path("detection", "mpii_keypoints_mmpose", "test_mpii.json"), read_mpii_json),
        (data_path("detection", "mpii_keypoints_mmpose", "test_mpii_trb.json"), read_mpii_json),
        (
            data_path("detection", "imgaug_quokka", "quokka_annotations.json"),
            read_imgaug_keypoints,
        ),
    ]
    token = re.compile(r"-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?")
    for path, reader in cases:
        text = path.read_text()
        spans = [m.span() for m in token.finditer(text)]
        for k in range(60):
            a, b = spans[rng.integers(len(spans))]
            mutant = text[:a] + hostile[k % len(hostile)] + text[b:]
            p = tmp_path / f"m{k}.json"
            p.write_text(mutant)
            try:
                reader(p)
            except FileFormatError:
                pass
