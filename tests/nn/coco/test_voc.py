"""Pascal VOC (robopercept.nn.coco.voc): XML files, their conversion to COCO, the VOC AP
and evaluation, the real DeepForest files."""

from __future__ import annotations

import numpy as np
import pytest

from robopercept.errors import FileFormatError, InputError
from robopercept.nn.coco.voc import (
    evaluate_voc,
    read_voc_xml,
    voc_average_precision,
    voc_to_coco,
)
from tests.conftest import data_path
from tests.nn.coco.test_evaluate import assert_self_evaluation_perfect, det, one_image


class TestXml:
    def test_bad_voc(self, tmp_path):
        p = tmp_path / "a.xml"
        body = "<size><width>9</width><height>9</height></size>"
        p.write_text(f"<annotation><filename>a</filename>{body}<object><name>t</name>"
                     "<bndbox><xmin>5</xmin><ymin>1</ymin><xmax>2</xmax><ymax>3</ymax>"
                     "</bndbox></object></annotation>")  # fmt: skip
        with pytest.raises(FileFormatError, match="xmax < xmin or ymax < ymin; swap them"):
            read_voc_xml(p)
        p.write_text(f'<!DOCTYPE x [<!ENTITY e "boom">]><annotation>{body}</annotation>')
        with pytest.raises(FileFormatError, match="DOCTYPE/ENTITY"):
            read_voc_xml(p)
        p.write_text(f"<annotation><filename>a</filename>{body}<object><name>t</name>"
                     "</object></annotation>")  # fmt: skip
        with pytest.raises(FileFormatError, match=r"\(t\) has no <bndbox>"):
            read_voc_xml(p)
        p.write_text("<annotation><filename>a</filename></annotation>")
        with pytest.raises(FileFormatError, match="has no <size>"):
            read_voc_xml(p)
        p.write_text("plain text")
        with pytest.raises(FileFormatError, match="not well-formed XML"):
            read_voc_xml(p)

    def test_voc_to_coco(self, tmp_path):
        p = tmp_path / "a.xml"
        p.write_text(
            "<annotation><filename>a.png</filename><size><width>50</width><height>40"
            "</height><depth>3</depth></size>"
            + "".join(
                f"<object><name>{n}</name><difficult>{d}</difficult><bndbox><xmin>{x}</xmin>"
                f"<ymin>2</ymin><xmax>{x + 10}</xmax><ymax>7</ymax></bndbox></object>"
                for n, d, x in (("b", 0, 1), ("a", 1, 20), ("b", 0, 30))
            )
            + "</annotation>"
        )
        voc = read_voc_xml(p)
        assert (voc.width, voc.height, voc.depth, voc.filename) == (50, 40, 3, "a.png")
        assert [o.difficult for o in voc.objects] == [False, True, False]
        ds = voc_to_coco([voc, voc])
        assert ds.category_names() == {1: "a", 2: "b"}
        assert ds.boxes[0].tolist() == [1.0, 2.0, 10.0, 5.0] and len(ds) == 6
        assert ds.image_ids.tolist() == [1, 1, 1, 2, 2, 2]
        assert len(voc_to_coco([voc], include_difficult=False)) == 2
        with pytest.raises(InputError, match="class 'a' is not in categories"):
            voc_to_coco([voc], categories=["b"])


# ----------------------------------------------------------------------------- VOC AP


class TestVocAP:
    def test_all_point_hand_case(self):
        # TP, FP, TP over 2 gt: recall .5 .5 1, precision 1 .5 2/3; envelope 1, 2/3, 2/3
        # AP = .5 * 1 + .5 * 2/3 = 5/6
        assert voc_average_precision([0.5, 0.5, 1.0], [1.0, 0.5, 2 / 3]) == pytest.approx(5 / 6)
        # recall never reaches 1: the last segment counts 0
        assert voc_average_precision([0.25, 0.5], [1.0, 1.0]) == pytest.approx(0.5)
        assert voc_average_precision([], []) == 0.0

    def test_evaluate_voc(self):
        gt = one_image(
            [
                {"bbox": [0, 0, 10, 10]},
                {"bbox": [50, 50, 10, 10]},
                {"bbox": [200, 200, 50, 50], "iscrowd": 1},  # VOC's "difficult"
            ],
            cats=(1, 2),
        )
        dets = [
            det([0, 0, 10, 10], 0.9),
            det([0, 0, 10, 10], 0.85),  # a duplicate: FP
            det([200, 200, 50, 50], 0.8),  # on the difficult box: neither TP nor FP
            det([50, 50, 10, 10], 0.7),
        ]
        ev = evaluate_voc(gt, dets)
        assert ev.ap[1] == pytest.approx(5 / 6) and np.isnan(ev.ap[2])
        assert ev.mean_ap == pytest.approx(5 / 6)
        # IoU 0.5 exactly is not above the threshold (VOC's strict >)
        half = evaluate_voc(gt, [det([0, 0, 10, 5], 0.9)], iou_threshold=0.5)
        assert half.ap[1] == 0.0

    def test_bad_input(self):
        with pytest.raises(InputError, match="non-decreasing"):
            voc_average_precision([0.5, 0.2], [1.0, 1.0])
        with pytest.raises(InputError, match="one length"):
            voc_average_precision([0.5], [1.0, 1.0])
        with pytest.raises(InputError, match=r"precision must hold finite values in \[0, 1\]"):
            voc_average_precision([0.5], [np.nan])


DEEPFOREST = {
    "OSBS_029": (400, 400, {"Tree": 61}),
    "SOAP_061": (400, 400, None),
    "2019_YELL_2_541000_4977000_image_crop": (1249, 1035, None),
    "2019_YELL_2_528000_4978000_image_crop2": (2299, 2472, None),
}
COUNTS = {"OSBS_029": 61, "SOAP_061": 37, "2019_YELL_2_541000_4977000_image_crop": 279,
          "2019_YELL_2_528000_4978000_image_crop2": 574}  # fmt: skip


@pytest.mark.realdata
def test_deepforest_voc_files():
    folder = data_path("detection", "deepforest_neon")
    vocs = []
    for stem, n in COUNTS.items():
        voc = read_voc_xml(folder / f"{stem}.xml")
        w, h, classes = DEEPFOREST[stem]
        assert (voc.width, voc.height) == (w, h) and len(voc.objects) == n
        if classes is not None:
            assert {o.name for o in voc.objects} == set(classes)
        vocs.append(voc)
    assert {o.name for o in vocs[1].objects} == {"Alive", "Dead"}  # SOAP_061, as SOURCES.md
    ds = voc_to_coco(vocs)
    assert len(ds) == 951  # SOURCES.md: 951 boxes over 4 images
    sides = ds.boxes[:, 2:]
    assert sides.min() >= 1 and sides.max() <= 107 + 1  # "box sides 8-107 px"
    assert_self_evaluation_perfect(ds)
