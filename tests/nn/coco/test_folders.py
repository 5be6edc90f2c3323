"""A user's annotated images (robopercept.nn.coco.folders): labelme files, VOC
segmentation folders, VOC XML folders and the dispatch between them; checked against
the labelme author's own COCO export of the same three PASCAL photos (masks against
pycocotools' ``annToMask``) and the DeepForest XML files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.imaging import write_image
from robopercept.nn.coco.folders import (
    VOC_CLASSES,
    LabelmeAnnotation,
    LabelmeShape,
    labelme_to_coco,
    read_annotations,
    read_labelme_json,
    read_voc_segmentation,
)
from robopercept.nn.coco.rle import annotation_to_rle, rle_decode
from robopercept.nn.coco.voc import read_voc_xml
from tests.conftest import data_path

SQ = np.array([[0.0, 0], [4, 0], [4, 4], [0, 4]])


def _labelme(folder, name="a", shapes=None, h=8, w=10):
    write_image(folder / f"{name}.png", np.zeros((h, w, 3), np.uint8))
    shapes = shapes or [{"label": "cat", "points": [[1, 2], [5, 6]], "shape_type": "rectangle"}]
    doc = {"imagePath": f"{name}.png", "imageHeight": h, "imageWidth": w, "shapes": shapes}
    (folder / f"{name}.json").write_text(json.dumps(doc))


def _masks(coco, image_id):
    im = next(i for i in coco.images if i.id == image_id)
    sel = np.flatnonzero(coco.image_ids == image_id)
    segs = [coco.segmentations[j] for j in sel]
    return sel, [rle_decode(annotation_to_rle(s, im.height, im.width)) for s in segs]


class TestLabelme:
    def test_groups_shapes_and_drops_underscore_labels(self):
        a = LabelmeAnnotation(
            "a.jpg",
            10,
            12,
            (
                LabelmeShape("cat", SQ, 1, "polygon"),
                LabelmeShape("dog", SQ + 6, None, "polygon"),
                LabelmeShape("cat", SQ + 5, 1, "polygon"),  # part 2 of cat 1
                LabelmeShape("cat", SQ, None, "polygon"),  # another cat
                LabelmeShape("__ignore__", SQ, None, "polygon"),
                LabelmeShape("_background_", SQ, None, "polygon"),
            ),
        )
        ds = labelme_to_coco([a])
        assert ds.category_names() == {1: "cat", 2: "dog"}
        assert ds.category_ids.tolist() == [1, 2, 1]
        assert len(ds.segmentations[0]) == 2  # the two parts of one instance
        # the union of the two 4 x 4 squares: box 0..9, area 2 * 16 (no overlap)
        assert ds.boxes[0].tolist() == [0.0, 0.0, 9.0, 9.0] and ds.areas[0] == 32
        assert ds.images[0].width == 10 and ds.images[0].height == 12

    def test_rectangle_and_circle(self):
        circle = LabelmeShape("ball", np.array([[10.0, 10], [14, 10]]), None, "circle")
        rect = LabelmeShape("box", np.array([[6.0, 5], [2, 1]]), None, "rectangle")
        ds = labelme_to_coco([LabelmeAnnotation("a.jpg", 30, 30, (circle, rect))])
        box = ds.boxes[0]  # a circle of radius 4 about (10, 10)
        assert np.allclose(box, [6, 6, 8, 8], atol=1)
        assert abs(ds.areas[0] - np.pi * 16) < 0.2 * np.pi * 16
        assert ds.boxes[1].tolist() == [2.0, 1.0, 4.0, 4.0]  # corners in either order

    def test_bad_shapes_name_the_fix(self, tmp_path):
        line = LabelmeShape("edge", np.array([[0.0, 0], [3, 3]]), None, "line")
        with pytest.raises(FileFormatError, match="'line' shape is not an object's area"):
            labelme_to_coco([LabelmeAnnotation("a.jpg", 9, 9, (line,))])
        two = LabelmeShape("x", np.array([[0.0, 0], [3, 3]]), None, "polygon")
        with pytest.raises(FileFormatError, match="a polygon needs 3 points"):
            labelme_to_coco([LabelmeAnnotation("a.jpg", 9, 9, (two,))])
        with pytest.raises(InputError, match="label 'dog' is not in categories"):
            labelme_to_coco(
                [LabelmeAnnotation("a", 9, 9, (LabelmeShape("dog", SQ, None, "polygon"),))], ["cat"]
            )
        with pytest.raises(InputError, match="list of LabelmeAnnotation"):
            labelme_to_coco(["a.json"])

    @pytest.mark.parametrize(
        ("doc", "match"),
        [
            ({"shapes": []}, "needs 'imagePath'"),
            ({"imagePath": "a.png", "imageHeight": 8, "imageWidth": 0, "shapes": []}, "positive"),
            ({"imagePath": "a.png", "imageHeight": 8, "imageWidth": 9, "shapes": [{}]}, "'label'"),
            (
                {"imagePath": "a", "imageHeight": 8, "imageWidth": 9,
                 "shapes": [{"label": "x", "points": [[1, 2, 3]]}]},
                r"'points' must be \[\[x, y\], ...\]",
            ),
            (
                {"imagePath": "a", "imageHeight": 8, "imageWidth": 9,
                 "shapes": [{"label": "x", "points": [[1, 2]], "group_id": True}]},
                "'group_id' must be null or an integer",
            ),
            ([1, 2], "not a labelme file"),
        ],
    )  # fmt: skip
    def test_bad_files(self, tmp_path, doc, match):
        p = tmp_path / "a.json"
        p.write_text(json.dumps(doc))
        with pytest.raises(FileFormatError, match=match):
            read_labelme_json(p)

    @pytest.mark.realdata
    def test_matches_the_labelme_authors_coco_export(self):
        """The labelme files against the COCO file labelme2coco wrote from them: the same
        12 instances with the same classes, each mask equal to pycocotools' ``annToMask``
        of the exported polygons (the same polygons under the same rasterization), each
        box within 1 px of the exported one (labelme2coco boxes PIL's drawing of the
        polygon, which takes boundary pixels the COCO polygon rule leaves out)."""
        from pycocotools.coco import COCO

        root = data_path("detection", "labelme_voc_instances")
        found = read_annotations(root / "data_annotated")
        assert found.form == "labelme" and len(found.coco) == 12
        ref = COCO(str(root / "coco" / "annotations.json"))
        ref_names = {c["id"]: c["name"] for c in ref.loadCats(ref.getCatIds())}
        for im in found.coco.images:
            rid = next(i for i, r in ref.imgs.items() if r["file_name"].endswith(im.file_name))
            anns = ref.loadAnns(ref.getAnnIds(imgIds=rid))
            sel, masks = _masks(found.coco, im.id)
            assert len(anns) == len(sel)
            names = found.coco.category_names()
            for j, m, a in zip(sel, masks, anns, strict=True):
                assert names[int(found.coco.category_ids[j])] == ref_names[a["category_id"]]
                assert np.array_equal(m.astype(bool), ref.annToMask(a).astype(bool))
                ours, theirs = found.coco.boxes[j], np.asarray(a["bbox"], float)
                corners = np.r_[
                    ours[:2] - theirs[:2], ours[:2] + ours[2:] - theirs[:2] - theirs[2:]
                ]
                assert np.abs(corners).max() <= 1.0 + 1e-9


class TestVocSegmentation:
    def _folder(self, tmp_path, names=None):
        for d in ("SegmentationObject", "SegmentationClass", "JPEGImages"):
            (tmp_path / d).mkdir()
        obj = np.zeros((6, 8), np.uint8)
        obj[1:3, 1:4] = 1
        obj[4:6, 5:8] = 2
        obj[0, :] = 255  # the void border belongs to nobody
        cls = np.where(obj == 1, 15, np.where(obj == 2, 9, obj)).astype(np.uint8)
        cls[1, 1] = 9  # a minority pixel: the instance's class is its majority
        write_image(tmp_path / "SegmentationObject" / "a.png", obj)
        write_image(tmp_path / "SegmentationClass" / "a.png", cls)
        write_image(tmp_path / "JPEGImages" / "a.jpg", np.zeros((6, 8, 3), np.uint8))
        if names:
            (tmp_path / "class_names.txt").write_text("\n".join(names))
        return tmp_path

    def test_hand_made(self, tmp_path):
        ds = read_voc_segmentation(self._folder(tmp_path))
        names = ds.category_names()
        assert [names[int(c)] for c in ds.category_ids] == ["person", "chair"]
        assert VOC_CLASSES[15] == "person"
        assert ds.boxes.tolist() == [[1.0, 1.0, 3.0, 2.0], [5.0, 4.0, 3.0, 2.0]]
        assert ds.areas.tolist() == [6.0, 6.0] and ds.images[0].file_name == "JPEGImages/a.jpg"
        found = read_annotations(tmp_path)
        assert found.form == "voc-masks" and len(found.coco) == 2

    def test_class_names_file_and_errors(self, tmp_path):
        ds = read_voc_segmentation(self._folder(tmp_path, ["bg"] + [f"c{i}" for i in range(1, 16)]))
        assert ds.category_names()[15] == "c15"
        (tmp_path / "class_names.txt").write_text("bg\nc1")
        with pytest.raises(InputError, match="class value 15 has no name"):
            read_voc_segmentation(tmp_path)
        (tmp_path / "SegmentationClass" / "a.png").unlink()
        with pytest.raises(InputError, match=r"SegmentationClass/a\.png is missing"):
            read_voc_segmentation(tmp_path)
        with pytest.raises(InputError, match="needs SegmentationObject/"):
            read_voc_segmentation(tmp_path / "JPEGImages")

    def test_class_names_not_utf8_is_a_file_format_error(self, tmp_path):
        """E1-F3: a non-UTF-8 class_names.txt was a UnicodeDecodeError."""
        self._folder(tmp_path)
        (tmp_path / "class_names.txt").write_bytes(b"bg\n\xff\xfe cat\n")
        with pytest.raises(FileFormatError, match=r"class_names\.txt: not UTF-8 text"):
            read_voc_segmentation(tmp_path)

    @pytest.mark.realdata
    def test_matches_the_coco_export(self):
        """labelme's VOC export against its COCO export of the same polygons: the same
        12 instances and classes; masks within IoU 0.9 (the PNGs are PIL's drawing of
        the polygons, COCO's rule rasterizes them about a pixel thinner at the edges:
        0.93 for the smallest, an 873-pixel bottle, 0.96 to 0.996 for the rest)."""
        from pycocotools.coco import COCO

        root = data_path("detection", "labelme_voc_instances")
        found = read_annotations(root / "voc")
        assert found.form == "voc-masks" and len(found.coco) == 12
        ref = COCO(str(root / "coco" / "annotations.json"))
        ref_names = {c["id"]: c["name"] for c in ref.loadCats(ref.getCatIds())}
        names = found.coco.category_names()
        for im in found.coco.images:
            rid = next(i for i, r in ref.imgs.items() if r["file_name"] == im.file_name)
            anns = ref.loadAnns(ref.getAnnIds(imgIds=rid))
            sel, masks = _masks(found.coco, im.id)
            assert len(anns) == len(sel)
            for j, m in zip(sel, masks, strict=True):
                ious = []
                for a in anns:
                    r = ref.annToMask(a).astype(bool)
                    ious.append((m & r).sum() / (m | r).sum())
                best = int(np.argmax(ious))
                assert ious[best] > 0.9
                assert (
                    names[int(found.coco.category_ids[j])] == ref_names[anns[best]["category_id"]]
                )


class TestDispatch:
    def test_voc_xml_folder_finds_images_by_stem(self, tmp_path):
        write_image(tmp_path / "a.png", np.zeros((8, 10, 3), np.uint8))
        (tmp_path / "a.xml").write_text(
            "<annotation><filename>a.tif</filename><size><width>10</width><height>8</height>"
            "</size><object><name>tree</name><bndbox><xmin>1</xmin><ymin>2</ymin>"
            "<xmax>5</xmax><ymax>6</ymax></bndbox></object></annotation>"
        )
        found = read_annotations(tmp_path)
        assert found.form == "voc-xml" and found.coco.images[0].file_name == "a.png"
        assert found.coco.boxes.tolist() == [[1.0, 2.0, 4.0, 4.0]]

    def test_labelme_folder_and_a_broken_file_among_them(self, tmp_path):
        _labelme(tmp_path)
        found = read_annotations(tmp_path)
        assert found.form == "labelme" and found.coco.boxes.tolist() == [[1.0, 2.0, 4.0, 4.0]]
        (tmp_path / "b.json").write_text("{not json")
        with pytest.raises(FileFormatError, match=r"b\.json: not valid JSON"):
            read_annotations(tmp_path)

    def test_nothing_there_lists_the_forms(self, tmp_path):
        with pytest.raises(InputError, match=r"labelme \.json files, of Pascal-VOC \.xml"):
            read_annotations(tmp_path)
        with pytest.raises(InputError, match="does not exist"):
            read_annotations(tmp_path / "nope")
        (tmp_path / "a.txt").write_text("x")
        with pytest.raises(InputError, match=r"not a COCO \.json file"):
            read_annotations(tmp_path / "a.txt")
        _labelme(tmp_path)
        (tmp_path / "a.png").unlink()
        with pytest.raises(InputError, match="no image for"):
            read_annotations(tmp_path)

    @pytest.mark.realdata
    def test_deepforest_xml_folder(self):
        root = data_path("detection", "deepforest_neon")
        found = read_annotations(root)
        assert found.form == "voc-xml"
        per_image = np.bincount(found.coco.image_ids)[1:].tolist()
        assert per_image == [len(read_voc_xml(x).objects) for x in sorted(root.glob("*.xml"))]
        assert per_image == [574, 279, 61, 37]  # SOURCES.md
        assert all(i.file_name.endswith(".png") for i in found.coco.images)  # the XML says .tif
