"""Box operations (issue 26, item 1): formats, IoU vs pycocotools, GIoU by hand,
boxes under flips and quarter turns, and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from robopercept.errors import InputError  # noqa: E402
from robopercept.nn.ops.boxes import (  # noqa: E402
    box_area,
    box_convert,
    box_iou,
    dihedral_boxes,
    generalized_box_iou,
)


def random_xyxy(rng: np.random.Generator, n: int, size: float = 100.0) -> np.ndarray:
    xy = rng.uniform(0, size, (n, 2))
    wh = rng.uniform(1, size / 3, (n, 2))
    return np.concatenate([xy, xy + wh], 1)


# ------------------------------------------------------------------ formats and IoU
class TestFormats:
    def test_hand_case(self):
        b = torch.tensor([[10.0, 20.0, 14.0, 26.0]])
        assert box_convert(b, "xyxy", "xywh").tolist() == [[10.0, 20.0, 4.0, 6.0]]
        assert box_convert(b, "xyxy", "cxcywh").tolist() == [[12.0, 23.0, 4.0, 6.0]]
        assert box_convert(torch.tensor([[12.0, 23, 4, 6]]), "cxcywh", "xyxy").tolist() == (
            b.tolist()
        )
        assert box_area(b).tolist() == [24.0]

    @pytest.mark.parametrize("a", ["xyxy", "xywh", "cxcywh"])
    @pytest.mark.parametrize("b", ["xyxy", "xywh", "cxcywh"])
    def test_round_trips(self, a, b):
        x = torch.from_numpy(random_xyxy(np.random.default_rng(0), 20))
        there = box_convert(box_convert(x, "xyxy", a), a, b)
        back = box_convert(box_convert(there, b, a), a, "xyxy")
        torch.testing.assert_close(back, x, rtol=0, atol=1e-12)


def coco_iou(a_xyxy: np.ndarray, b_xyxy: np.ndarray) -> np.ndarray:
    from pycocotools import mask

    def xywh(b):
        return np.concatenate([b[:, :2], b[:, 2:] - b[:, :2]], 1).tolist()

    return np.asarray(mask.iou(xywh(a_xyxy), xywh(b_xyxy), [0] * len(b_xyxy)))


class TestIoU:
    def test_equals_pycocotools(self):
        # pycocotools computes in double: the same arithmetic up to rounding (1e-9)
        rng = np.random.default_rng(1)
        a, b = random_xyxy(rng, 40), random_xyxy(rng, 30)
        b[:5] = a[:5] + rng.uniform(-3, 3, (5, 4)).clip(-0.5, 0.5)  # heavy overlaps
        ours = box_iou(torch.from_numpy(a), torch.from_numpy(b)).numpy()
        np.testing.assert_allclose(ours, coco_iou(a, b), rtol=0, atol=1e-9)
        assert (ours > 0.5).sum() >= 5  # the overlapping pairs are in the test

    def test_degenerate_boxes_give_zero(self):
        a = torch.tensor([[0.0, 0.0, 0.0, 10.0], [5.0, 5.0, 5.0, 5.0], [0.0, 0.0, 10.0, 10.0]])
        iou = box_iou(a, a)
        assert iou.tolist() == [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        assert box_iou(torch.zeros(0, 4), a).shape == (0, 3)

    def test_giou_hand_cases(self):
        a = torch.tensor([[0.0, 0.0, 1.0, 1.0]], dtype=torch.float64)
        b = torch.tensor(
            [[0.0, 0.0, 1.0, 1.0], [2.0, 0.0, 3.0, 1.0], [0.0, 0.0, 2.0, 2.0], [0.5, 0, 1.5, 1]],
            dtype=torch.float64,
        )
        # identical: 1; disjoint side by side: C = 3, U = 2 -> 0 - 1/3; inside a 2x2:
        # IoU 1/4, C = U; half overlap: IoU 0.5/1.5, C = 1.5 = U
        want = [[1.0, -1 / 3, 0.25, 1 / 3]]
        torch.testing.assert_close(generalized_box_iou(a, b), torch.tensor(want).double())
        pts = torch.tensor([[1.0, 1.0, 1.0, 1.0]])
        assert generalized_box_iou(pts, pts).tolist() == [[0.0]]  # C = 0: defined as 0

    def test_giou_properties(self):
        rng = np.random.default_rng(2)
        a = torch.from_numpy(random_xyxy(rng, 25))
        b = torch.from_numpy(random_xyxy(rng, 20))
        g, iou = generalized_box_iou(a, b), box_iou(a, b)
        assert bool((g <= iou + 1e-12).all()) and bool((g >= -1).all())
        torch.testing.assert_close(g, generalized_box_iou(b, a).T)


# ------------------------------------------------------------------ bad input
T4 = torch.tensor([[0.0, 0.0, 1.0, 1.0]])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: box_iou(np.zeros((1, 4)), T4), r"boxes1 must be a torch.Tensor"),
        (lambda: box_iou(torch.zeros(4), T4), r"boxes1 must have shape \(N, 4\).*\[None\]"),
        (lambda: box_iou(torch.zeros(1, 4, dtype=torch.long), T4), "use boxes1.float"),
        (lambda: box_iou(torch.tensor([[0.0, math.nan, 1, 1]]), T4), "boxes1 must be finite"),
        (lambda: box_iou(torch.tensor([[0.0, 0, -1, 1]]), T4), "x1 <= x2 and y1 <= y2"),
        (lambda: box_area(torch.tensor([[0.0, 0, 1e30, 1e30]])), "overflow"),
        (lambda: box_convert(T4, "xyxy", "yxyx"), "out_fmt must be one of"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(InputError, match=match):
        call()


def _dihedral_image(image, hflip, vflip, k):
    dims = [d for d, on in ((-1, hflip), (-2, vflip)) if on]
    image = torch.flip(image, dims) if dims else image
    return torch.rot90(image, k, (-2, -1))


@pytest.mark.parametrize("hflip", [False, True])
@pytest.mark.parametrize("vflip", [False, True])
@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_dihedral_boxes_follow_the_pixels_and_invert(hflip, vflip, k):
    # a filled rectangle: its box after the image transform is read off the pixels
    h, w = 10, 17
    image = torch.zeros(1, h, w)
    image[0, 2:5, 3:9] = 1.0
    box = torch.tensor([[3.0, 2.0, 9.0, 5.0]])
    moved = _dihedral_image(image, hflip, vflip, k)[0]
    ys, xs = torch.nonzero(moved, as_tuple=True)
    seen = [[xs.min().item(), ys.min().item(), xs.max().item() + 1, ys.max().item() + 1]]
    t = {"hflip": hflip, "vflip": vflip, "quarter_turns": k}
    assert dihedral_boxes(box, (h, w), **t).tolist() == np.array(seen, float).tolist()
    rand = torch.rand(20, 2, generator=torch.Generator().manual_seed(k)) * torch.tensor([w, h])
    boxes = torch.cat([rand, rand + 2.5], 1)
    back = dihedral_boxes(dihedral_boxes(boxes, (h, w), **t), (h, w), **t, inverse=True)
    torch.testing.assert_close(back, boxes, rtol=0, atol=1e-5)  # float32 rounding of W - x


def test_dihedral_boxes_quarter_turns_modulo_four_and_bad_input():
    b = torch.tensor([[1.0, 2.0, 3.0, 4.0]])
    assert torch.equal(
        dihedral_boxes(b, (8, 6), quarter_turns=5), dihedral_boxes(b, (8, 6), quarter_turns=1)
    )
    assert dihedral_boxes(torch.zeros(0, 4), (8, 6), hflip=True).shape == (0, 4)
    with pytest.raises(InputError, match="size must be the image's"):
        dihedral_boxes(b, 8)
    with pytest.raises(InputError, match="x1 <= x2"):
        dihedral_boxes(torch.tensor([[3.0, 0, 1, 1]]), (8, 6))
